//! Detector + DVO per frame (the closed loop of `pipeline::Processor`) on the synthetic
//! dominant-object sequence at 640×480. Target: ≥ 50 frames per second.
//! Run: `cargo bench --bench pipeline` (add `-- --quick` for a short run).

// A benchmark's setup failing is a bug in the benchmark: panicking is the right report.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use occmask::image_buf::ImageSize;
use occmask::pipeline::{FrameInput, PoseSource, Processor, ProcessorConfig};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticFrame, SyntheticSequence};

fn closed_loop(c: &mut Criterion) {
    let size = ImageSize::new(640, 480);
    let config = SequenceConfig {
        size,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
    let frames: Vec<SyntheticFrame> = (40..70).map(|i| sequence.frame(i)).collect();
    let mut group = c.benchmark_group("pipeline_frame");
    for (name, source) in [
        ("dvo_closed_loop", PoseSource::DvoClosedLoop),
        (
            "external_pose",
            PoseSource::External {
                camera_from_marker: None,
            },
        ),
    ] {
        let processor_config = ProcessorConfig {
            pose_source: source,
            ..ProcessorConfig::default()
        };
        let mut processor = Processor::new(size, config.intrinsics(), processor_config).unwrap();
        let mut k = 0;
        group.bench_function(format!("{name}/{size}"), |b| {
            b.iter(|| {
                k = (k + 1) % frames.len();
                if k == 0 {
                    processor.reset();
                }
                let f = &frames[k];
                let out = processor
                    .process(&FrameInput {
                        timestamp_ns: f.timestamp_ns,
                        gray: &f.gray,
                        depth_m: &f.depth_m,
                        world_from_marker: Some(&f.world_from_camera),
                        ignore_in_previous: None,
                    })
                    .unwrap();
                black_box(out.stats.moving_fraction);
            })
        });
    }
    group.finish();
}

criterion_group!(benches, closed_loop);
criterion_main!(benches);
