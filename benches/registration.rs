//! Per-frame cost of the input geometry tables (src/registration.rs) at RealSense-like sizes:
//! depth 848×480 registered into a 640×480 colour camera 15 mm away, colour undistortion
//! (bilinear) and masks mapped back (nearest), each against its scalar reference.
//! Run: `cargo bench --bench registration` (add `-- --quick` for a short run).

// A benchmark's setup failing is a bug in the benchmark: panicking is the right report.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occmask::image_buf::{DepthMeters, GrayF32, Mask};
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

criterion_group!(benches, geometry);
criterion_main!(benches);
