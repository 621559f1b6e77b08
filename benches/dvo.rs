//! DVO stages at 640×480: pyramid build, one LM iteration per level (normal equations at a pose
//! + the damped 6×6 solve), and a whole frame pair with the default config.
//!
//! Uses two consecutive frames of the TUM fr2_desk excerpt in `fixtures/` (realistic depth holes
//! and iteration counts), else a generated textured scene.
//! Run: `cargo bench --bench dvo` (add `-- --quick` for a short run).

// A benchmark's setup failing is a bug in the benchmark: panicking is the right report.
#![allow(clippy::unwrap_used)]

#[path = "../tests/integration/common/tum.rs"]
mod tum;

#[path = "../tests/integration/common/data.rs"]
mod data;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::Isometry3;
use occmask::dvo::bench_api as kernels;
use occmask::dvo::{DvoConfig, DvoEstimator, DvoTracker};
use occmask::geometry::camera::presets;
use occmask::image_buf::{DepthMeters, GrayF32, ImageSize};
use occmask::pyramid::ImagePyramid;

fn frames() -> [(GrayF32, DepthMeters); 2] {
    if let Ok(sequence) = tum::TumSequence::load(&data::tum_fixture()) {
        if let (Ok(a), Ok(b)) = (sequence.frame(8), sequence.frame(9)) {
            return [(a.gray, a.depth_m), (b.gray, b.depth_m)];
        }
    }
    eprintln!("fixtures/tum_fr2_desk_10 not found: benchmarking a generated scene");
    let size = ImageSize::new(640, 480);
    let make = |shift: f32| {
        let gray = GrayF32::from_fn(size, |x, y| {
            let (x, y) = (x as f32 + shift, y as f32);
            0.5 + 0.25 * (x * 0.07).sin() * (y * 0.05).cos()
                + 0.2 * ((x * 0.31 + y * 0.17).sin() * 3.0).tanh()
        });
        let depth = DepthMeters::from_fn(size, |x, y| 1.5 + 0.002 * x as f32 + 0.001 * y as f32);
        (gray, depth)
    };
    [make(0.0), make(1.5)]
}

fn bench(c: &mut Criterion) {
    let [(g0, d0), (g1, d1)] = frames();
    let size = g0.size();
    let config = DvoConfig::paper();
    let k = presets::TUM_FR2;

    let mut group = c.benchmark_group("dvo_640x480");
    group.throughput(Throughput::Elements(1));
    let mut pyr = ImagePyramid::new(size, k, config.levels, config.finest_level).unwrap();
    group.bench_function("pyramid_build", |b| {
        b.iter(|| pyr.build(black_box(&g0), black_box(&d0)).unwrap())
    });

    let mut reference = ImagePyramid::new(size, k, config.levels, config.finest_level).unwrap();
    let mut current = reference.clone();
    reference.build(&g0, &d0).unwrap();
    current.build(&g1, &d1).unwrap();
    let mut estimator = DvoEstimator::new(size, config).unwrap();
    estimator.prepare_reference(&reference, None).unwrap();
    let pose = Isometry3::identity();
    for level in config.finest_level..config.levels {
        let lv = current.level(level).unwrap();
        let target = kernels::TargetView {
            samples: &lv.samples,
            size: lv.size(),
            intrinsics: lv.intrinsics,
        };
        let cost = config.cost_at_level(level);
        let points = estimator.reference_points(level);
        group.bench_function(format!("lm_iteration_level{level}_{}pts", points.len()), |b| {
            b.iter(|| {
                let ne = kernels::accumulate_normal_equations(points, lv.size().width, &target, &pose, &cost);
                black_box(kernels::damped_step(&ne, 0.1))
            })
        });
        if level == config.finest_level {
            group.bench_function(format!("normal_equations_scalar_reference_level{level}"), |b| {
                b.iter(|| {
                    black_box(kernels::accumulate_normal_equations_scalar(
                        points, &target, &pose, &cost,
                    ))
                })
            });
        }
    }

    let mut tracker = DvoTracker::new(size, k, config).unwrap();
    let est = tracker
        .estimate_between((&g0, &d0), (&g1, &d1), None, None)
        .unwrap();
    eprintln!(
        "whole pair: {:?} iterations per level, status {:?}",
        est.iterations_per_level, est.status
    );
    // What a sequence pays per frame: the new frame's pyramid + the estimate against the
    // previous frame. Frames alternate, so every call is a real pair (motions of either sign).
    let mut next_is_second = false;
    group.bench_function("whole_pair_default", |b| {
        b.iter(|| {
            let (g, d) = if next_is_second { (&g1, &d1) } else { (&g0, &d0) };
            next_is_second = !next_is_second;
            black_box(tracker.track(g, d, None, None).unwrap())
        })
    });
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
