//! Per-frame cost of the input geometry tables (src/registration.rs) at RealSense-like sizes:
//! depth 848×480 registered into a 640×480 colour camera 15 mm away, colour undistortion
//! (bilinear) and masks mapped back (nearest), each against its scalar reference; then
//! `frame_loop_share`: what `process` does per frame to such a recording, in the same rounds on
//! the same frames — the rectification of `process::rectify` (registration, undistortion, masks
//! mapped back: what `--timings` reports as `rectify`) beside the rest of the frame loop (the
//! default pipeline, DVO + detector) — and prints their ratio.
//! Run: `cargo bench --bench registration` (add `-- --quick` for a short run;
//! `SHARE_ROUNDS=N` sets the rounds of `frame_loop_share`, default 5).

// A benchmark's setup failing is a bug in the benchmark: panicking is the right report.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occmask::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask};
use occmask::pipeline::ProcessorConfig;
use occmask::pipeline::{FrameInput, FrameResult};
use occmask::process::rectify::{DepthGeometry, InputGeometry, Rectifier};
use occmask::process::{pipeline_factory, PipelineOptions};
use occmask::registration::{distortion_map, inscribed_pinhole, undistortion_map, DepthRegistration};
use occmask::synthetic::{RgbdRig, Scenario, SequenceConfig, SyntheticFrame, SyntheticSequence};

fn geometry(c: &mut Criterion) {
    let config = SequenceConfig::default();
    let rig = RgbdRig::realsense_like(&config);
    let sequence = SyntheticSequence::new(Scenario::SmallObjectCrossing, config);
    let mut color = SyntheticFrame::empty(rig.color.size);
    let mut depth = SyntheticFrame::empty(rig.depth.size);
    sequence.render_rig_into(30, &rig, &mut color, &mut depth);

    let mut group = c.benchmark_group("registration");
    let pinhole = inscribed_pinhole(&rig.color);
    let mut registered = DepthMeters::filled(rig.color.size, 0.0);
    group.throughput(Throughput::Elements(rig.depth.size.area() as u64));
    let threads = rayon::current_num_threads();
    for bands in [1, threads] {
        let mut registration =
            DepthRegistration::new(&rig.depth, &pinhole, &rig.color_from_depth, bands).unwrap();
        group.bench_function(format!("register_depth_{bands}_bands/{}", rig.depth.size), |b| {
            b.iter(|| {
                registration
                    .register_into(black_box(&depth.depth_m), &mut registered)
                    .unwrap()
            })
        });
    }
    let registration = DepthRegistration::new(&rig.depth, &pinhole, &rig.color_from_depth, 1).unwrap();
    group.bench_function(format!("register_depth_reference/{}", rig.depth.size), |b| {
        b.iter(|| {
            registration
                .register_reference(black_box(&depth.depth_m), &mut registered)
                .unwrap()
        })
    });

    let bilinear = undistortion_map(&rig.color, &pinhole).unwrap();
    let back = distortion_map(&rig.color, &pinhole).unwrap();
    let mut gray = GrayF32::filled(rig.color.size, 0.0);
    group.throughput(Throughput::Elements(rig.color.size.area() as u64));
    group.bench_function(format!("undistort_gray/{}", rig.color.size), |b| {
        b.iter(|| bilinear.apply_into(black_box(&color.gray), &mut gray).unwrap())
    });
    group.bench_function(format!("undistort_gray_serial/{}", rig.color.size), |b| {
        b.iter(|| bilinear.apply_serial(black_box(&color.gray), &mut gray).unwrap())
    });
    let mut undistorted_depth = DepthMeters::filled(rig.color.size, 0.0);
    group.bench_function(format!("undistort_depth/{}", rig.color.size), |b| {
        b.iter(|| {
            bilinear
                .apply_depth_into(black_box(&color.depth_m), &mut undistorted_depth)
                .unwrap()
        })
    });
    let mut mask = Mask::filled(rig.color.size, 0);
    group.bench_function(format!("mask_to_published/{}", rig.color.size), |b| {
        b.iter(|| back.apply_into(black_box(&color.gt_mask), &mut mask).unwrap())
    });
    group.finish();
}

/// Frames of one `frame_loop_share` round: the default offline pipeline's block (60) is
/// processed whole, so the round holds every pass the pipeline makes.
const SHARE_FRAMES: usize = 60;
/// Rounds of `frame_loop_share` when `SHARE_ROUNDS` is not set.
const DEFAULT_SHARE_ROUNDS: usize = 5;

/// `dst` = `src`, resizing `dst` (the decode step `process` runs before rectifying).
fn decode_into(src: &Image<f32>, dst: &mut Image<f32>) -> occmask::Result<()> {
    if dst.size() != src.size() {
        *dst = Image::filled(src.size(), 0.0);
    }
    dst.copy_from(src)
}

/// Per frame, in the same rounds on the same frames: the rectification `process` runs on a
/// RealSense-like recording (colour undistorted, depth registered, masks mapped back; timed by
/// `Rectifier` itself as for `--timings`) and the rest of its frame loop (the default pipeline).
fn frame_loop_share(_c: &mut Criterion) {
    let rounds = std::env::var("SHARE_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_SHARE_ROUNDS);
    let config = SequenceConfig::default();
    let rig = RgbdRig::realsense_like(&config);
    let sequence = SyntheticSequence::new(Scenario::TwoObjectsCrossing, config);
    let frames: Vec<(SyntheticFrame, SyntheticFrame)> = (0..SHARE_FRAMES)
        .map(|i| {
            let mut color = SyntheticFrame::empty(rig.color.size);
            let mut depth = SyntheticFrame::empty(rig.depth.size);
            sequence.render_rig_into(i, &rig, &mut color, &mut depth);
            (color, depth)
        })
        .collect();
    let geometry = InputGeometry {
        color: rig.color,
        color_frame: "color".into(),
        depth_frame: "depth".into(),
        undistort_color: true,
        pipeline: inscribed_pinhole(&rig.color),
        depth: DepthGeometry::Registered {
            depth: rig.depth,
            color_from_depth: rig.color_from_depth,
            transform_source: "bench".into(),
        },
    };
    let mut factory = pipeline_factory(PipelineOptions::default());
    let mut ratios = Vec::new();
    for round in 0..rounds {
        let (mut rectifier, publisher) = Rectifier::new(&geometry).unwrap();
        let mut processor = factory(
            geometry.pipeline.intrinsics,
            geometry.pipeline.size,
            &ProcessorConfig::default(),
        )
        .unwrap();
        let mut gray = GrayF32::filled(ImageSize::new(0, 0), 0.0);
        let mut depth_m = DepthMeters::filled(ImageSize::new(0, 0), 0.0);
        let (mut rectify, mut pipeline) = (0.0, Duration::ZERO);
        let map_back = |results: Vec<FrameResult>| -> f64 {
            let start = Instant::now();
            for r in results {
                black_box(publisher.to_published(r.mask).unwrap());
            }
            start.elapsed().as_secs_f64()
        };
        for (color, depth) in &frames {
            rectify += rectifier
                .color("color", &mut gray, |g| decode_into(&color.gray, g))
                .unwrap();
            rectify += rectifier
                .depth("depth", &mut depth_m, |d| decode_into(&depth.depth_m, d))
                .unwrap();
            let start = Instant::now();
            let results = processor
                .push(&FrameInput {
                    timestamp_ns: color.timestamp_ns,
                    gray: &gray,
                    depth_m: &depth_m,
                    world_from_marker: None,
                    ignore_in_previous: None,
                })
                .unwrap();
            pipeline += start.elapsed();
            rectify += map_back(results);
        }
        let start = Instant::now();
        let mut results = Vec::new();
        processor
            .finish(&mut |r| {
                results.push(r);
                Ok(())
            })
            .unwrap();
        pipeline += start.elapsed();
        rectify += map_back(results);
        let n = frames.len() as f64;
        let (rectify_ms, pipeline_ms) = (rectify * 1e3 / n, pipeline.as_secs_f64() * 1e3 / n);
        ratios.push(rectify_ms / pipeline_ms);
        println!(
            "frame_loop_share round {round}: rectify {rectify_ms:.3} ms/frame, pipeline {pipeline_ms:.3} ms/frame, \
             rectify / pipeline {:.1} %",
            100.0 * rectify_ms / pipeline_ms
        );
    }
    ratios.sort_by(f64::total_cmp);
    if let Some(median) = ratios.get(ratios.len() / 2) {
        println!(
            "frame_loop_share (realsense_like {}x{} colour, {}x{} depth, {rounds} rounds of {SHARE_FRAMES} frames): \
             median rectify / pipeline {:.1} % (range {:.1}-{:.1} %)",
            rig.color.size.width,
            rig.color.size.height,
            rig.depth.size.width,
            rig.depth.size.height,
            100.0 * median,
            100.0 * ratios[0],
            100.0 * ratios[ratios.len() - 1]
        );
    }
}

criterion_group!(benches, geometry, frame_loop_share);
criterion_main!(benches);
