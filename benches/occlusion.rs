//! Occlusion-accumulation detector alone (one `update_with_gray` per frame, true camera motion)
//! on the synthetic dominant-object sequence at 640×480 and 320×240, with the default config
//! (slow-change evidence on). At 640×480 `occlusion_update_paper` runs the same frames with the
//! paper's accumulation alone (no slow-change evidence), `occlusion_update_growth` with
//! appearance-gated object completion added: the differences are those stages' costs.
//! `occlusion_update_starting_object` runs the still-then-moving frames where the completion
//! grows the most (frames 31–46: a box starting to move); `occlusion_update_head_on` the
//! head-on approach (frames 40–69), where the slow-change evidence marks the box. Target:
//! ≤ 3 ms per 640×480 frame. Run: `cargo bench --bench occlusion` (add `-- --quick` for a short
//! run).

// A benchmark's setup failing is a bug in the benchmark: panicking is the right report.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::Isometry3;
use occmask::image_buf::{DepthMeters, GrayF32, ImageSize};
use occmask::occlusion::{AppearanceGrowthConfig, OcclusionConfig, OcclusionDetector};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

/// Frames cycled through (a window where the object covers much of the view).
const FRAMES: std::ops::Range<usize> = 40..70;
/// Still-then-moving frames where the box starts to move (frame 30 is the last still one).
const STARTING_FRAMES: std::ops::Range<usize> = 30..47;

type Frame = (DepthMeters, GrayF32, Isometry3<f64>);

fn frames(
    scenario: Scenario,
    size: ImageSize,
    range: std::ops::Range<usize>,
) -> (SequenceConfig, Vec<Frame>) {
    let config = SequenceConfig {
        size,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(scenario, config);
    let frames = range
        .map(|i| {
            let frame = sequence.frame(i);
            (frame.depth_m, frame.gray, sequence.current_from_previous(i))
        })
        .collect();
    (config, frames)
}

/// Benchmarks one `update_with_gray` per iteration, cycling through `frames` (reset at the
/// first so the state is that of the sequence).
fn bench(
    c: &mut Criterion,
    group: &str,
    name: String,
    config: &SequenceConfig,
    frames: &[Frame],
    detector_config: OcclusionConfig,
) {
    let size = config.size;
    let mut group = c.benchmark_group(group);
    let mut detector = OcclusionDetector::new(size, config.intrinsics(), detector_config).unwrap();
    for (depth, gray, motion) in frames {
        detector.update_with_gray(depth, Some(gray), motion).unwrap();
    }
    let mut k = 0;
    group.throughput(Throughput::Elements(size.area() as u64));
    group.bench_function(name, |b| {
        b.iter(|| {
            k = (k + 1) % frames.len();
            if k == 0 {
                detector.reset();
            }
            let (depth, gray, motion) = &frames[k];
            black_box(
                detector
                    .update_with_gray(black_box(depth), Some(black_box(gray)), motion)
                    .unwrap(),
            );
        })
    });
    group.finish();
}

fn detector(c: &mut Criterion) {
    let default = OcclusionConfig::default();
    let paper = OcclusionConfig {
        slow_evidence: None,
        appearance_growth: None,
        ..default
    };
    let growth = OcclusionConfig {
        appearance_growth: Some(AppearanceGrowthConfig::default()),
        ..default
    };
    for size in [ImageSize::new(640, 480), ImageSize::new(320, 240)] {
        let (config, frames) = frames(Scenario::DominantObject, size, FRAMES);
        bench(
            c,
            "occlusion_update",
            format!("{size}"),
            &config,
            &frames,
            default,
        );
        if size.width == 640 {
            bench(
                c,
                "occlusion_update_paper",
                format!("{size}"),
                &config,
                &frames,
                paper,
            );
            bench(
                c,
                "occlusion_update_growth",
                format!("{size}"),
                &config,
                &frames,
                growth,
            );
        }
    }
    let size = ImageSize::new(640, 480);
    let (config, frames_starting) = frames(Scenario::StillThenMoving, size, STARTING_FRAMES);
    for (name, detector_config) in [("growth", growth), ("default", default)] {
        bench(
            c,
            "occlusion_update_starting_object",
            format!("{size} {name}"),
            &config,
            &frames_starting,
            detector_config,
        );
    }
    let (config, frames_head_on) = frames(Scenario::HeadOnApproach, size, FRAMES);
    for (name, detector_config) in [("paper", paper), ("default", default)] {
        bench(
            c,
            "occlusion_update_head_on",
            format!("{size} {name}"),
            &config,
            &frames_head_on,
            detector_config,
        );
    }
}

criterion_group!(benches, detector);
criterion_main!(benches);
