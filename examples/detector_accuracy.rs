//! Per-frame accuracy of the occlusion detector, for diagnosis.
//!
//! Synthetic scenarios (640×480, seed 1), true pose or DVO closed loop:
//! `cargo run --release --example detector_accuracy -- synthetic <scenario|all> <true|dvo> [--frames]`
//! prints mean F1 / precision / recall per scenario and, with `--frames`, every frame's TP, FP,
//! FN, precision, recall, F1 and the detector's counts (predicted, pruned, thin-erased pixels).
//!
//! Real static sequences (TUM layout, depth factor 5000, ground-truth poses):
//! `cargo run --release --example detector_accuracy -- real <dir> <fx> <fy> <cx> <cy> [--frames] [--dump DIR]`
//! prints the false-positive fraction per frame after 5 warm-up frames; `--dump` writes, per
//! frame with false positives, a PNG of the depth (gray) with the mask in red (outside the repo:
//! 7-Scenes frames must not be copied into it).
//!
//! The same sequences with the DVO closed loop, offline (the default) and causal:
//! `cargo run --release --example detector_accuracy -- real-dvo <dir> <fx> <fy> <cx> <cy> [--config FILE] [--dump DIR]
//! [--modes offline,causal] [--frames]`
//! prints each mode's false positives and DVO's RPE against the ground truth; `--config` overlays
//! a partial JSON config on the defaults (as the CLI's), `--frames` prints every frame's fraction.
//!
//! The offline mode's colour/depth registration score (docs/method.md D18) of every third of the
//! first 90 frames of each folder:
//! `cargo run --release --example detector_accuracy -- registration <dir>...`

// A diagnosis tool: a failing setup is a bug worth a panic.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "../tests/integration/common/tum.rs"]
mod tum;

#[path = "shared/overlay.rs"]
mod overlay;

use std::path::{Path, PathBuf};

use nalgebra::Isometry3;
use occmask::dataset::DecodedPair;
use occmask::dvo::DvoStatus;
use occmask::geometry::PinholeIntrinsics;
use occmask::image_buf::{DepthMeters, Image, ImageSize, Mask};
use occmask::metrics::{ate, rpe, FrameCounts, SegmentationTally};
use occmask::occlusion::consistency::depth_consistency;
use occmask::occlusion::{AppearanceGrowthConfig, OcclusionConfig, OcclusionDetector, OcclusionStats};
use occmask::pipeline::offline::registration::RegistrationProfile;
use occmask::pipeline::{
    FrameInput, FrameOutput, PoseSource, ProcessingMode, Processor, ProcessorConfig, SequenceProcessor,
};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};
use occmask::trajectory::interpolate;
use tum::TumSequence;

/// The default detector config with overrides from the environment (for experiments):
/// OCC_EXIT_MARGIN, OCC_THIN_RADIUS, OCC_THIN_MARGIN, OCC_THIN_RECONNECT, OCC_MOTION_CHECK=0
/// (off), OCC_GROWTH=0/1 (appearance growth off/on; the default is off), OCC_GROWTH_PHOTO,
/// OCC_GROWTH_DEPTH, OCC_GROWTH_RINGS, OCC_GROWTH_MARGIN, OCC_GROWTH_RADIUS,
/// OCC_GROWTH_INHERIT=0/1, OCC_GROWTH_SEEDS=0/1 (its parameters).
fn detector_config() -> OcclusionConfig {
    detector_config_from(OcclusionConfig::default())
}

/// `base` with the environment's overrides ([`detector_config`]).
fn detector_config_from(base: OcclusionConfig) -> OcclusionConfig {
    let mut config = base;
    let get = |name: &str| std::env::var(name).ok().map(|v| v.parse::<usize>().unwrap());
    if let Some(v) = get("OCC_EXIT_MARGIN") {
        config.prune_exit_margin_px = v;
    }
    if let Some(v) = get("OCC_THIN_RADIUS") {
        config.thin_structure_radius_px = v;
    }
    if get("OCC_MOTION_CHECK") == Some(0) {
        config.motion_check_margin = None;
    }
    if let Some(v) = get("OCC_THIN_MARGIN") {
        config.thin_structure_border_margin_px = v;
    }
    if let Some(v) = get("OCC_THIN_RECONNECT") {
        config.thin_structure_reconnect_px = v;
    }
    match get("OCC_GROWTH") {
        Some(0) => config.appearance_growth = None,
        Some(_) => config.appearance_growth = Some(AppearanceGrowthConfig::default()),
        None => {}
    }
    let get_f32 = |name: &str| std::env::var(name).ok().map(|v| v.parse::<f32>().unwrap());
    if let Some(growth) = config.appearance_growth.as_mut() {
        if let Some(v) = get_f32("OCC_GROWTH_PHOTO") {
            growth.photometric_threshold = v;
        }
        if let Some(v) = get_f32("OCC_GROWTH_DEPTH") {
            growth.depth_tolerance = v;
        }
        if let Some(v) = get("OCC_GROWTH_RINGS") {
            growth.max_rings = v;
        }
        if let Some(v) = get_f32("OCC_GROWTH_MARGIN") {
            growth.accumulation_margin = v;
        }
        if let Some(v) = get("OCC_GROWTH_RADIUS") {
            growth.photometric_search_radius_px = v;
        }
        if let Some(v) = get("OCC_GROWTH_SEEDS") {
            growth.persistent_seeds_only = v != 0;
        }
        if let Some(v) = get("OCC_GROWTH_INHERIT") {
            growth.inherit_accumulation = v != 0;
        }
    }
    config
}

const SIZE: ImageSize = ImageSize::new(640, 480);
const WARM_UP_FRAMES: usize = 5;
/// Largest gap between bracketing ground-truth poses (TUM mocap ≈ 100 Hz, 7-Scenes 30 Hz).
const MAX_GT_GAP_NS: u64 = 50_000_000;

fn print_frame(i: usize, c: &FrameCounts, s: &OcclusionStats) {
    println!(
        "{i:4} tp {:6} fp {:6} fn {:6}  P {:.3} R {:.3} F1 {:.3}  predicted {:5} pruned {:5} thin {:5} small {:3} grown {:5} growth_us {:5} prune_us {:5}{}",
        c.true_positives,
        c.false_positives,
        c.false_negatives,
        c.precision(),
        c.recall(),
        c.f1(),
        s.predicted_pixels,
        s.pruned_pixels,
        s.thin_pixels_erased,
        s.small_components_erased,
        s.grown_pixels,
        s.growth_us,
        s.prune_us,
        if s.motion_rejected { "  MOTION REJECTED" } else { "" }
    );
}

/// Depth in gray, true positives green, false positives red, false negatives blue; without
/// `truth` (real data: nothing moves) every mask pixel is a false positive.
fn dump_errors(path: &Path, depth: &DepthMeters, mask: &Mask, truth: Option<&Mask>) {
    let mut out = image::RgbImage::new(depth.width() as u32, depth.height() as u32);
    for y in 0..depth.height() {
        for x in 0..depth.width() {
            let z = depth.get(x, y);
            let g = if z > 0.0 {
                (255.0 * (1.0 - (z / 5.0).min(1.0))) as u8
            } else {
                0
            };
            let p = overlay::error_colour(g, mask.get(x, y) != 0, truth.is_some_and(|t| t.get(x, y) != 0));
            out.put_pixel(x as u32, y as u32, image::Rgb(p));
        }
    }
    out.save(path).unwrap();
}

fn synthetic(scenario: Scenario, dvo: bool, frames: bool, dump_dir: Option<&Path>) {
    let config = SequenceConfig {
        size: SIZE,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(scenario, config);
    let mut detector = OcclusionDetector::new(SIZE, config.intrinsics(), detector_config()).unwrap();
    let mut processor = Processor::new(
        SIZE,
        config.intrinsics(),
        ProcessorConfig {
            pose_source: PoseSource::DvoClosedLoop,
            occlusion: detector_config(),
            ..ProcessorConfig::default()
        },
    )
    .unwrap();
    let mut tally = SegmentationTally::default();
    let mut rejected = Vec::new();
    let mut max_empty_fp: f64 = 0.0;
    let mut frame = sequence.frame(0);
    let mut previous_depth = frame.depth_m.clone();
    let mut previous_mask = frame.gt_mask.clone();
    let mut min_consistency: f64 = 1.0;
    for i in 0..sequence.len() {
        sequence.render_into(i, &mut frame);
        let mut motion = sequence.current_from_previous(i);
        let (mask, stats): (&Mask, OcclusionStats) = if dvo {
            let out = processor
                .process(&FrameInput {
                    timestamp_ns: frame.timestamp_ns,
                    gray: &frame.gray,
                    depth_m: &frame.depth_m,
                    world_from_marker: None,
                    ignore_in_previous: None,
                })
                .unwrap();
            motion = out.current_from_previous;
            (out.mask, out.stats.detector)
        } else {
            detector
                .update_with_gray(
                    &frame.depth_m,
                    Some(&frame.gray),
                    &sequence.current_from_previous(i),
                )
                .unwrap();
            (detector.mask(), *detector.stats())
        };
        let consistency = depth_consistency(
            &config.intrinsics(),
            &previous_depth,
            Some(&previous_mask),
            &frame.depth_m,
            &motion,
            4,
        )
        .map(|c| c.agreeing_fraction)
        .unwrap_or(1.0)
            - depth_consistency(
                &config.intrinsics(),
                &previous_depth,
                Some(&previous_mask),
                &frame.depth_m,
                &Isometry3::identity(),
                4,
            )
            .map(|c| c.agreeing_fraction)
            .unwrap_or(1.0);
        if i > 0 {
            min_consistency = min_consistency.min(consistency);
        }
        previous_depth.copy_from(&frame.depth_m).unwrap();
        previous_mask.copy_from(mask).unwrap();
        if stats.motion_rejected {
            rejected.push(i);
        }
        let counts = tally.add_masks(mask, &frame.gt_mask).unwrap();
        if i >= WARM_UP_FRAMES && counts.truth_is_empty() {
            max_empty_fp = max_empty_fp.max(counts.false_positive_fraction());
        }
        if frames {
            print_frame(i, &counts, &stats);
            println!("     consistency {consistency:.3}");
        }
        if let Some(d) = dump_dir {
            dump_errors(
                &d.join(format!("{}_{i:03}.png", scenario.name())),
                &frame.depth_m,
                mask,
                Some(&frame.gt_mask),
            );
        }
    }
    let s = tally.summary();
    println!(
        "{:24} {}: F1 {:.3} P {:.3} R {:.3} ({} frames with objects), max FP on empty frames after {WARM_UP_FRAMES}: {:.3} %, min motion consistency {min_consistency:.3}, motion rejected at {rejected:?}",
        scenario.name(),
        if dvo { "closed loop" } else { "true pose  " },
        s.mean_f1,
        s.mean_precision,
        s.mean_recall,
        s.frames_with_truth,
        100.0 * max_empty_fp
    );
}

fn real(dir: &Path, intrinsics: PinholeIntrinsics, frames: bool, dump_dir: Option<&Path>) {
    let sequence = TumSequence::load(dir).unwrap();
    let truth = sequence.groundtruth();
    let mut detector = OcclusionDetector::new(SIZE, intrinsics, detector_config()).unwrap();
    let mut previous: Option<Isometry3<f64>> = None;
    let mut previous_depth = Image::filled(SIZE, 0.0f32);
    let mut min_consistency: f64 = 1.0;
    let mut fractions = Vec::new();
    let mut rejected = Vec::new();
    // Each depth frame with the nearest colour image (7-Scenes: not registered to the depth; a
    // gate only).
    for pair in sequence.depth_with_nearest_color() {
        let t = sequence.sequence.depth[pair.depth].timestamp_ns;
        let Some(world_from_camera) = interpolate(truth, t, MAX_GT_GAP_NS) else {
            continue;
        };
        let frame = sequence.decode(&pair).unwrap();
        let (gray, depth) = (frame.gray, frame.depth_m);
        let motion = previous.map_or_else(Isometry3::identity, |p| world_from_camera.inverse() * p);
        previous = Some(world_from_camera);
        let consistency = depth_consistency(&intrinsics, &previous_depth, None, &depth, &motion, 4)
            .map(|c| c.agreeing_fraction)
            .unwrap_or(1.0)
            - depth_consistency(
                &intrinsics,
                &previous_depth,
                None,
                &depth,
                &Isometry3::identity(),
                4,
            )
            .map(|c| c.agreeing_fraction)
            .unwrap_or(1.0);
        if previous.is_some() && previous_depth.as_slice().iter().any(|&z| z > 0.0) {
            min_consistency = min_consistency.min(consistency);
        }
        previous_depth.copy_from(&depth).unwrap();
        let mask = detector.update_with_gray(&depth, Some(&gray), &motion).unwrap();
        let set = mask.as_slice().iter().filter(|&&m| m != 0).count();
        let fraction = set as f64 / SIZE.area() as f64;
        let i = fractions.len();
        if detector.stats().motion_rejected {
            rejected.push(i);
        }
        if frames {
            let s = detector.stats();
            println!(
                "{i:4} consistency {consistency:.3} FP {:.3} %  predicted {:5} pruned {:5} thin {:5} small {:3} components {:3}",
                100.0 * fraction,
                s.predicted_pixels,
                s.pruned_pixels,
                s.thin_pixels_erased,
                s.small_components_erased,
                s.components
            );
        }
        if let Some(d) = dump_dir {
            if set > 0 && i >= WARM_UP_FRAMES {
                dump_errors(&d.join(format!("{i:04}.png")), &depth, detector.mask(), None);
            }
        }
        fractions.push(fraction);
    }
    let (mean, worst, above) = false_positives_after_warm_up(&fractions);
    println!(
        "{}: {} frames, FP after warm-up: mean {:.3} %, max {:.3} %, {above} frames above 1 %, min consistency {min_consistency:.3}, motion rejected at {rejected:?}",
        dir.display(),
        fractions.len(),
        100.0 * mean,
        100.0 * worst
    );
}

fn inlier_fraction(
    intrinsics: &PinholeIntrinsics,
    previous: &DepthMeters,
    current: &DepthMeters,
    previous_from_current: &Isometry3<f64>,
) -> f64 {
    depth_consistency(
        intrinsics,
        previous,
        None,
        current,
        &previous_from_current.inverse(),
        1,
    )
    .map(|c| c.agreeing_fraction)
    .unwrap_or(0.0)
}

/// For frames `first..=last`: the inlier fraction of the ground-truth motion, of identity, of
/// the motion interpolated halfway between the neighbours' poses, and of scaled translations.
fn probe(dir: &Path, intrinsics: PinholeIntrinsics, first: usize, last: usize) {
    let sequence = TumSequence::load(dir).unwrap();
    let truth = sequence.groundtruth();
    let files = sequence.depth_with_nearest_color();
    let load = |i: usize| sequence.decode(&files[i]).unwrap().depth_m;
    let pose = |i: usize| interpolate(truth, sequence.sequence.depth[i].timestamp_ns, MAX_GT_GAP_NS).unwrap();
    for k in first..=last {
        let (previous, current) = (load(k - 1), load(k));
        let gt = pose(k - 1).inverse() * pose(k);
        let mut line = format!(
            "{k:4} gt {:.3} id {:.3}",
            inlier_fraction(&intrinsics, &previous, &current, &gt),
            inlier_fraction(&intrinsics, &previous, &current, &Isometry3::identity())
        );
        for s in [0.0, 0.5, 1.5] {
            let mut m = gt;
            m.translation.vector *= s;
            line += &format!(
                " t×{s} {:.3}",
                inlier_fraction(&intrinsics, &previous, &current, &m)
            );
        }
        if k + 1 < files.len() {
            // Halfway between k−1 and k+1 (as if frame k's pose were interpolated).
            let mid = pose(k - 1).lerp_slerp(&pose(k + 1), 0.5);
            let m = pose(k - 1).inverse() * mid;
            line += &format!(
                " mid {:.3}",
                inlier_fraction(&intrinsics, &previous, &current, &m)
            );
        }
        println!("{line}");
    }
}

/// The DVO closed loop on a real static sequence (gray from the nearest colour image): the
/// false-positive fraction per frame after the warm-up.
fn real_dvo(
    dir: &Path,
    intrinsics: PinholeIntrinsics,
    base: &ProcessorConfig,
    modes: &str,
    per_frame: bool,
    dump_dir: Option<&Path>,
) {
    let sequence = TumSequence::load(dir).unwrap();
    for (mode, label) in [
        (ProcessingMode::Offline, "offline"),
        (ProcessingMode::Causal, "causal"),
    ] {
        if !modes.split(',').any(|m| m == label) {
            continue;
        }
        let config = ProcessorConfig {
            occlusion: detector_config_from(base.occlusion),
            mode,
            ..*base
        };
        let mut fractions = Vec::new();
        let mut masks = Vec::new();
        let (mut not_converged, mut resets, mut rejected) = (0, 0, 0);
        let truth = sequence.groundtruth();
        let (mut estimated, mut reference) = (Vec::new(), Vec::new());
        let mut keep = |out: FrameOutput<'_>| {
            not_converged += usize::from(out.stats.dvo.is_some_and(|d| d.status != DvoStatus::Converged));
            resets += usize::from(out.stats.detector_reset);
            rejected += usize::from(out.stats.detector.motion_rejected);
            fractions.push(out.stats.moving_fraction);
            if dump_dir.is_some() {
                masks.push(out.mask.clone());
            }
            if let Some(pose) = interpolate(truth, out.timestamp_ns, MAX_GT_GAP_NS) {
                estimated.push(out.world_from_camera);
                reference.push(pose);
            }
            Ok(())
        };
        let frames = sequence
            .depth_with_nearest_color()
            .into_iter()
            .map(|pair| sequence.decode(&pair).unwrap());
        let mut processor = SequenceProcessor::new(SIZE, intrinsics, config).unwrap();
        for frame in frames {
            processor.push(&input(&frame), &mut keep).unwrap();
        }
        processor.finish(&mut keep).unwrap();
        if let Some(registration) = processor.colour_registration() {
            println!(
                "colour registered: {} (score {:?})",
                registration.registered, registration.score
            );
        }
        if let Some(d) = dump_dir {
            for (i, (pair, mask)) in sequence.depth_with_nearest_color().iter().zip(&masks).enumerate() {
                let frame = sequence.decode(pair).unwrap();
                dump_errors(&d.join(format!("{label}_{i:04}.png")), &frame.depth_m, mask, None);
            }
        }
        let rpe_1 = rpe(&estimated, &reference, 1).unwrap();
        let ate_m = ate(&estimated, &reference).unwrap().rmse_m;
        if per_frame {
            for (i, f) in fractions.iter().enumerate() {
                println!("{label} frame {i:4} FP {:.3} %", 100.0 * f);
            }
        }
        let (mean, worst, above) = false_positives_after_warm_up(&fractions);
        println!(
            "{} (DVO closed loop, {label}): {} frames, FP after warm-up: mean {:.3} %, max {:.3} %, {above} frames above 1 %; \
             DVO RPE Δ=1 vs ground truth {:.4} m, {:.3}° ({} pairs), ATE {ate_m:.4} m; DVO not converged {not_converged}, pipeline resets {resets}, \
             motion check rejections {rejected}",
            dir.display(),
            fractions.len(),
            100.0 * mean,
            100.0 * worst,
            rpe_1.translation_rmse_m,
            rpe_1.rotation_rmse_deg,
            rpe_1.pairs
        );
    }
}

/// The pipeline's input for a decoded frame (its depth time).
fn input(frame: &DecodedPair) -> FrameInput<'_> {
    FrameInput {
        timestamp_ns: frame.depth_timestamp_ns,
        gray: &frame.gray,
        depth_m: &frame.depth_m,
        world_from_marker: None,
        ignore_in_previous: None,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let frames = args.iter().any(|a| a == "--frames");
    match args.first().map(String::as_str) {
        Some("synthetic") => {
            let which = args.get(1).map_or("all", String::as_str);
            let dump_dir = args
                .iter()
                .position(|a| a == "--dump")
                .map(|i| PathBuf::from(&args[i + 1]));
            if let Some(d) = &dump_dir {
                std::fs::create_dir_all(d).unwrap();
            }
            let dvo = args.get(2).is_some_and(|m| m == "dvo");
            for scenario in Scenario::ALL {
                if which == "all" || which == scenario.name() {
                    synthetic(scenario, dvo, frames, dump_dir.as_deref());
                }
            }
        }
        Some("real") => {
            let dir = PathBuf::from(&args[1]);
            let k: Vec<f64> = args[2..6].iter().map(|s| s.parse().unwrap()).collect();
            let dump_dir = args
                .iter()
                .position(|a| a == "--dump")
                .map(|i| PathBuf::from(&args[i + 1]));
            if let Some(d) = &dump_dir {
                std::fs::create_dir_all(d).unwrap();
            }
            real(&dir, PinholeIntrinsics::new(k[0], k[1], k[2], k[3]), frames, dump_dir.as_deref());
        }
        Some("real-dvo") => {
            let k: Vec<f64> = args[2..6].iter().map(|s| s.parse().unwrap()).collect();
            let option = |name: &str| args.iter().position(|a| a == name).map(|i| args[i + 1].clone());
            let base = option("--config").map_or_else(ProcessorConfig::default, |file| {
                ProcessorConfig::from_json(&std::fs::read_to_string(file).unwrap()).unwrap()
            });
            let modes = option("--modes").unwrap_or_else(|| "offline,causal".into());
            let dump_dir = option("--dump").map(PathBuf::from);
            if let Some(d) = &dump_dir {
                std::fs::create_dir_all(d).unwrap();
            }
            real_dvo(
                Path::new(&args[1]),
                PinholeIntrinsics::new(k[0], k[1], k[2], k[3]),
                &base,
                &modes,
                frames,
                dump_dir.as_deref(),
            );
        }
        Some("registration") => {
            // The colour/depth registration profile of every 25th frame of each folder.
            for dir in &args[1..] {
                let sequence = TumSequence::load(Path::new(dir)).unwrap();
                let pairs = sequence.depth_with_nearest_color();
                for pair in pairs.iter().take(90).step_by(3) {
                    let frame = sequence.decode(pair).unwrap();
                    match RegistrationProfile::measure(&frame.gray, &frame.depth_m) {
                        Some(p) => println!(
                            "{dir} depth {:4}: score {:.3}, {} edge px, profile {:?}",
                            pair.depth,
                            p.score(),
                            p.edge_pixels,
                            p.gradient.map(|g| (g * 1000.0).round() / 1000.0)
                        ),
                        None => println!("{dir} depth {:4}: too few edges", pair.depth),
                    }
                }
            }
        }
        Some("bench-check") => {
            // Time of one motion check (two consistency passes at stride 8) at 640×480.
            let config = SequenceConfig {
                size: SIZE,
                ..SequenceConfig::default()
            };
            let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
            let (a, b) = (sequence.frame(40).depth_m, sequence.frame(41).depth_m);
            let motion = sequence.current_from_previous(41);
            let rounds = 200;
            let started = std::time::Instant::now();
            let mut sum = 0.0;
            for _ in 0..rounds {
                sum += depth_consistency(&config.intrinsics(), &a, None, &b, &motion, 8).map(|c| c.agreeing_fraction).unwrap();
                sum += depth_consistency(&config.intrinsics(), &a, None, &b, &Isometry3::identity(), 8).map(|c| c.agreeing_fraction).unwrap();
            }
            println!("motion check: {:.3} ms per frame ({sum:.1})", started.elapsed().as_secs_f64() * 1e3 / rounds as f64);
        }
        Some("probe") => {
            let k: Vec<f64> = args[2..6].iter().map(|s| s.parse().unwrap()).collect();
            probe(
                Path::new(&args[1]),
                PinholeIntrinsics::new(k[0], k[1], k[2], k[3]),
                args[6].parse().unwrap(),
                args[7].parse().unwrap(),
            );
        }
        _ => eprintln!("usage: detector_accuracy synthetic <scenario|all> <true|dvo> [--frames] | real <dir> fx fy cx cy [--frames] [--dump DIR]"),
    }
}

/// Mean and largest false-positive fraction after the warm-up frames, and how many frames are
/// above 1 %.
fn false_positives_after_warm_up(fractions: &[f64]) -> (f64, f64, usize) {
    let after = &fractions[WARM_UP_FRAMES.min(fractions.len())..];
    let worst = after.iter().copied().fold(0.0, f64::max);
    let mean = after.iter().sum::<f64>() / after.len().max(1) as f64;
    let above = after.iter().filter(|&&f| f > 0.01).count();
    (mean, worst, above)
}
