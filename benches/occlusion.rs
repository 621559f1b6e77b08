//! Occlusion-accumulation detector alone (one `update` per frame, true camera motion) on the
//! synthetic dominant-object sequence at 640×480 and 320×240; the transport kernel fused vs its
//! scalar reference. Target (issue 4): ≤ 3 ms per 640×480 frame.
//! Run: `cargo bench --bench occlusion` (add `-- --quick` for a short run).

// A benchmark's setup failing is a bug in the benchmark: panicking is the right report.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::Isometry3;
use occmask::image_buf::{DepthMeters, ImageSize};
use occmask::occlusion::{OcclusionConfig, OcclusionDetector};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

/// Frames cycled through (a window where the object covers much of the view).
const FRAMES: std::ops::Range<usize> = 40..70;

fn detector(c: &mut Criterion) {
    let mut group = c.benchmark_group("occlusion_update");
    for size in [ImageSize::new(640, 480), ImageSize::new(320, 240)] {
        let config = SequenceConfig {
            size,
            ..SequenceConfig::default()
        };
        let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
        let frames: Vec<(DepthMeters, Isometry3<f64>)> = FRAMES
            .map(|i| (sequence.frame(i).depth_m, sequence.current_from_previous(i)))
            .collect();
        let mut detector =
            OcclusionDetector::new(size, config.intrinsics(), OcclusionConfig::default()).unwrap();
        for (depth, motion) in &frames {
            detector.update(depth, motion).unwrap();
        }
        let mut k = 0;
        group.throughput(Throughput::Elements(size.area() as u64));
        group.bench_function(format!("{size}"), |b| {
            b.iter(|| {
                k = (k + 1) % frames.len();
                if k == 0 {
                    detector.reset();
                }
                let (depth, motion) = &frames[k];
                black_box(detector.update(black_box(depth), motion).unwrap());
            })
        });
    }
    group.finish();
}

criterion_group!(benches, detector);
criterion_main!(benches);
