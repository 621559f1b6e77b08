//! DVO accuracy on synthetic RGB-D pairs with exact ground truth (crate::synthetic), the moving
//! box masked and unmasked, and failure behaviour on frames that carry no motion information.
#![allow(clippy::unwrap_used)] // test helpers: a panic is the failure report

use nalgebra::Isometry3;
use occmask::dvo::{DvoConfig, DvoFailure, DvoStatus, DvoTracker, KeyframeConfig, MotionPriorConfig};
use occmask::geometry::{se3_exp, Twist};
use occmask::image_buf::{DepthMeters, GrayF32, ImageSize, Mask};
use occmask::synthetic::{motion_pair, CameraPath, SequenceConfig, SyntheticSequence};

/// The targets: 1 mm and 0.05° per frame pair. With pixel-area-integrated colour
/// (`SequenceConfig::colour_samples_per_axis`, jittered 2 × 2) the 144 cases of the multi-seed
/// test end within 0.82 mm / 0.011° (static) and 0.58 mm / 0.008° (masked). The point-sampled
/// renderer it replaced aliased the texture on the grazing floor and ceiling (the scene's
/// only parallax) and biased translation by up to 2.45 mm; see docs/accuracy.md.
const MAX_TRANS_ERR_MM: f64 = 1.0;
const MAX_ROT_ERR_DEG: f64 = 0.05;

/// Motions up to 5 cm and 3° per frame, mixing all six directions.
fn motions() -> Vec<Twist> {
    let deg = std::f64::consts::PI / 180.0;
    vec![
        Twist::new(0.05, 0.0, 0.0, 0.0, 0.0, 0.0),
        Twist::new(0.0, 0.0, 0.05, 0.0, 0.0, 0.0),
        Twist::new(0.0, 0.0, 0.0, 0.0, 3.0 * deg, 0.0),
        Twist::new(0.0, 0.0, 0.0, 3.0 * deg, 0.0, 0.0),
        Twist::new(0.02, -0.02, 0.03, deg, -1.5 * deg, 2.0 * deg),
        Twist::new(-0.03, 0.01, -0.02, -2.0 * deg, deg, -deg),
    ]
}

/// (translation error mm, rotation error deg) of an estimate against the truth.
fn error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> (f64, f64) {
    let e = estimate.inverse() * truth;
    (e.translation.vector.norm() * 1e3, e.rotation.angle().to_degrees())
}

/// Seeds of the multi-seed test: each one is a different room texture, box texture and noise.
const SEEDS: std::ops::RangeInclusive<u64> = 1..=8;

/// Every seed × every motion × {static scene, 30 % box masked, box not masked}: the static and
/// masked estimates must converge within the bounds; the unmasked ones are reported (the box
/// drags them several centimetres) and must never be a `Failed` without reason. This is the
/// regression test for the wrong-minimum bug of the 4-level pyramid: with it, 3° pitch with
/// the box masked ended 43–310 mm off for seeds 3, 4, 5 and 8 and still said `Converged`.
#[test]
fn every_seed_and_motion_converges_within_the_bounds() {
    let config = DvoConfig::paper();
    let mut worst = [(0.0f64, 0.0f64); 3];
    let mut cases = 0;
    let mut failures = Vec::new();
    for seed in SEEDS {
        let seq = SequenceConfig {
            seed,
            ..SequenceConfig::default()
        };
        for xi in motions() {
            let truth = se3_exp(&xi);
            for with_box in [false, true] {
                let (reference, current) = motion_pair(seq, &truth, with_box);
                let masks: &[Option<&Mask>] = if with_box {
                    &[Some(&reference.gt_mask), None]
                } else {
                    &[None]
                };
                for &mask in masks {
                    let mode = match (with_box, mask.is_some()) {
                        (false, _) => 0,
                        (true, true) => 1,
                        (true, false) => 2,
                    };
                    let mut tracker = DvoTracker::new(seq.size, reference.intrinsics, config).unwrap();
                    let est = tracker
                        .estimate_between(
                            (&reference.gray, &reference.depth_m),
                            (&current.gray, &current.depth_m),
                            mask,
                            None,
                        )
                        .unwrap();
                    let (et, er) = error(&est.current_from_reference, &truth);
                    cases += 1;
                    let name = ["static", "masked", "unmasked"][mode];
                    if mode < 2 {
                        if est.status != DvoStatus::Converged
                            || et >= MAX_TRANS_ERR_MM
                            || er >= MAX_ROT_ERR_DEG
                        {
                            failures.push(format!(
                                "seed {seed} {xi:?} {name}: {et:.3} mm {er:.4} deg {:?}",
                                est.status
                            ));
                        }
                        worst[mode] = (worst[mode].0.max(et), worst[mode].1.max(er));
                    } else if est.is_converged() {
                        worst[mode] = (worst[mode].0.max(et), worst[mode].1.max(er));
                    }
                }
            }
        }
    }
    println!(
        "{cases} cases ({} seeds × {} motions × static/masked/unmasked): worst static {:.3} mm {:.4} deg, \
         masked {:.3} mm {:.4} deg, unmasked (converged ones) {:.1} mm {:.3} deg",
        SEEDS.count(),
        motions().len(),
        worst[0].0,
        worst[0].1,
        worst[1].0,
        worst[1].1,
        worst[2].0,
        worst[2].1
    );
    assert!(
        failures.is_empty(),
        "{} of {cases} cases:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// The plausibility check: an estimate that ended in a wrong minimum must not say `Converged`.
/// With only 4 pyramid levels a 3° pitch is too large for the coarsest level on some seeds;
/// whatever the solver finds, a converged result must be accurate (the rest must be reported
/// as failures), and two unrelated views must fail as `PoorFit`.
#[test]
fn wrong_minima_are_reported_as_poor_fit_not_converged() {
    let deg = std::f64::consts::PI / 180.0;
    let truth = se3_exp(&Twist::new(0.0, 0.0, 0.0, 3.0 * deg, 0.0, 0.0));
    let four_levels = DvoConfig {
        levels: 4,
        ..DvoConfig::paper()
    };
    let mut poor = 0;
    for seed in SEEDS {
        let seq = SequenceConfig {
            seed,
            ..SequenceConfig::default()
        };
        let (reference, current) = motion_pair(seq, &truth, true);
        let mut tracker = DvoTracker::new(seq.size, reference.intrinsics, four_levels).unwrap();
        let est = tracker
            .estimate_between(
                (&reference.gray, &reference.depth_m),
                (&current.gray, &current.depth_m),
                Some(&reference.gt_mask),
                None,
            )
            .unwrap();
        let (et, er) = error(&est.current_from_reference, &truth);
        println!("4 levels, seed {seed}: {et:.3} mm {er:.4} deg {:?}", est.status);
        match est.status {
            DvoStatus::Converged => assert!(
                et < MAX_TRANS_ERR_MM && er < MAX_ROT_ERR_DEG,
                "seed {seed}: converged but {et:.3} mm {er:.4} deg off"
            ),
            DvoStatus::Failed(DvoFailure::PoorFit {
                cost_permille,
                limit_permille,
            }) => {
                assert!(cost_permille > limit_permille);
                assert_eq!(est.current_from_reference, Isometry3::identity());
                poor += 1;
            }
            other => panic!("seed {seed}: {other:?}"),
        }
    }
    println!("4 levels: {poor} of {} seeds reported as PoorFit", SEEDS.count());
    // Two different rooms (different textures) seen from the same place: nothing matches.
    let seq = SequenceConfig::default();
    let (reference, _) = motion_pair(seq, &Isometry3::identity(), false);
    let (other, _) = motion_pair(
        SequenceConfig { seed: 1000, ..seq },
        &Isometry3::identity(),
        false,
    );
    let mut tracker = DvoTracker::new(seq.size, reference.intrinsics, DvoConfig::paper()).unwrap();
    let est = tracker
        .estimate_between(
            (&reference.gray, &reference.depth_m),
            (&other.gray, &other.depth_m),
            None,
            None,
        )
        .unwrap();
    assert!(
        matches!(est.status, DvoStatus::Failed(DvoFailure::PoorFit { .. })),
        "{:?} (cost {})",
        est.status,
        est.final_cost
    );
    assert_finite(&est.current_from_reference);
}

fn run(xi: &Twist, with_box: bool, use_mask: bool, config: DvoConfig) -> (f64, f64, DvoStatus) {
    let truth = se3_exp(xi);
    let seq = SequenceConfig::default();
    let (reference, current) = motion_pair(seq, &truth, with_box);
    let mut tracker = DvoTracker::new(seq.size, reference.intrinsics, config).unwrap();
    let mask = use_mask.then_some(&reference.gt_mask);
    let est = tracker
        .estimate_between(
            (&reference.gray, &reference.depth_m),
            (&current.gray, &current.depth_m),
            mask,
            None,
        )
        .unwrap();
    let (et, er) = error(&est.current_from_reference, &truth);
    (et, er, est.status)
}

#[test]
fn static_scene_motions_are_recovered_within_the_bounds() {
    for xi in motions() {
        let (et, er, status) = run(&xi, false, false, DvoConfig::paper());
        println!("static {xi:?}: {et:.3} mm {er:.4} deg {status:?}");
        assert_eq!(status, DvoStatus::Converged);
        assert!(
            et < MAX_TRANS_ERR_MM && er < MAX_ROT_ERR_DEG,
            "{xi:?}: {et:.3} mm, {er:.4} deg"
        );
    }
}

#[test]
fn masked_moving_box_does_not_disturb_the_estimate() {
    let seq = SequenceConfig::default();
    let (reference, _) = motion_pair(seq, &Isometry3::identity(), true);
    let covered =
        reference.gt_mask.as_slice().iter().filter(|&&v| v != 0).count() as f64 / seq.size.area() as f64;
    assert!(
        covered > 0.25,
        "the box covers only {:.0} % of the view",
        covered * 100.0
    );
    let (mut worst_masked, mut worst_unmasked) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
    for xi in motions() {
        let (et, er, status) = run(&xi, true, true, DvoConfig::paper());
        let (ut, ur, _) = run(&xi, true, false, DvoConfig::paper());
        println!("box {xi:?}: masked {et:.3} mm {er:.4} deg; unmasked {ut:.3} mm {ur:.4} deg");
        assert_eq!(status, DvoStatus::Converged);
        assert!(
            et < MAX_TRANS_ERR_MM && er < MAX_ROT_ERR_DEG,
            "{xi:?}: {et:.3} mm, {er:.4} deg"
        );
        worst_masked = (worst_masked.0.max(et), worst_masked.1.max(er));
        worst_unmasked = (worst_unmasked.0.max(ut), worst_unmasked.1.max(ur));
    }
    println!(
        "box covering {:.0} %: worst masked {:.3} mm {:.4} deg, worst unmasked {:.3} mm {:.4} deg",
        covered * 100.0,
        worst_masked.0,
        worst_masked.1,
        worst_unmasked.0,
        worst_unmasked.1
    );
}

fn assert_finite(t: &Isometry3<f64>) {
    assert!(t.translation.vector.iter().all(|v| v.is_finite()));
    assert!(t.rotation.coords.iter().all(|v| v.is_finite()));
}

#[test]
fn textureless_planar_frames_fail_without_nan() {
    let size = ImageSize::new(320, 240);
    let k = SequenceConfig {
        size,
        ..SequenceConfig::default()
    }
    .intrinsics();
    let gray = GrayF32::filled(size, 0.5);
    let depth = DepthMeters::filled(size, 2.0);
    // Default config: the gradient threshold leaves no reference pixel at all.
    let mut tracker = DvoTracker::new(size, k, DvoConfig::paper()).unwrap();
    let est = tracker
        .estimate_between((&gray, &depth), (&gray, &depth), None, None)
        .unwrap();
    assert!(
        matches!(
            est.status,
            DvoStatus::Failed(DvoFailure::TooFewPixels { found: 0, .. })
        ),
        "{:?}",
        est.status
    );
    assert_finite(&est.current_from_reference);
    // Every pixel used: the depth of one plane constrains only 3 of the 6 directions.
    let all_pixels = DvoConfig {
        min_gradient_per_px: 0.0,
        ..DvoConfig::paper()
    };
    let mut tracker = DvoTracker::new(size, k, all_pixels).unwrap();
    let est = tracker
        .estimate_between((&gray, &depth), (&gray, &depth), None, None)
        .unwrap();
    assert!(
        matches!(est.status, DvoStatus::Failed(DvoFailure::Degenerate { .. })),
        "{:?}",
        est.status
    );
    assert_finite(&est.current_from_reference);
    assert!(est.final_cost.is_finite());
}

#[test]
fn frames_without_depth_or_fully_masked_fail_with_too_few_pixels() {
    let seq = SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    };
    let (reference, current) = motion_pair(seq, &Isometry3::identity(), false);
    let no_depth = DepthMeters::filled(seq.size, 0.0);
    let mut tracker = DvoTracker::new(seq.size, reference.intrinsics, DvoConfig::paper()).unwrap();
    let est = tracker
        .estimate_between(
            (&reference.gray, &no_depth),
            (&current.gray, &current.depth_m),
            None,
            None,
        )
        .unwrap();
    assert!(
        matches!(
            est.status,
            DvoStatus::Failed(DvoFailure::TooFewPixels { found: 0, .. })
        ),
        "{:?}",
        est.status
    );
    assert_finite(&est.current_from_reference);
    // Everything ignored.
    let all = Mask::filled(seq.size, 255);
    let est = tracker
        .estimate_between(
            (&reference.gray, &reference.depth_m),
            (&current.gray, &current.depth_m),
            Some(&all),
            None,
        )
        .unwrap();
    assert!(
        matches!(est.status, DvoStatus::Failed(DvoFailure::TooFewPixels { .. })),
        "{:?}",
        est.status
    );
    // A failed estimate returns the initial guess.
    let guess = se3_exp(&Twist::new(0.01, 0.0, 0.0, 0.0, 0.0, 0.0));
    let est = tracker
        .estimate_between(
            (&reference.gray, &no_depth),
            (&current.gray, &current.depth_m),
            None,
            Some(&guess),
        )
        .unwrap();
    assert_eq!(est.current_from_reference, guess);
}

#[test]
fn tracker_returns_none_first_then_chains_and_checks_sizes() {
    let seq = SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    };
    let truth = se3_exp(&Twist::new(0.01, 0.0, 0.0, 0.0, 0.0, 0.0));
    let (reference, current) = motion_pair(seq, &truth, false);
    let mut tracker = DvoTracker::new(seq.size, reference.intrinsics, DvoConfig::paper()).unwrap();
    assert!(tracker
        .track(&reference.gray, &reference.depth_m, None, None)
        .unwrap()
        .is_none());
    let bad = GrayF32::filled(ImageSize::new(10, 10), 0.0);
    assert!(tracker.track(&bad, &reference.depth_m, None, None).is_err());
    let bad_mask = Mask::filled(ImageSize::new(10, 10), 0);
    assert!(tracker
        .track(&current.gray, &current.depth_m, Some(&bad_mask), None)
        .is_err());
    // The errors above left the reference untouched.
    let est = tracker
        .track(&current.gray, &current.depth_m, None, None)
        .unwrap()
        .unwrap();
    let (et, er) = error(&est.current_from_reference, &truth);
    assert!(et < 2.0 && er < 0.1, "{et} mm {er} deg");
    // The current frame is now the reference: the same frame again means no motion.
    let est = tracker
        .track(&current.gray, &current.depth_m, None, None)
        .unwrap()
        .unwrap();
    let (et, er) = error(&est.current_from_reference, &Isometry3::identity());
    assert!(et < 0.1 && er < 0.01, "{et} mm {er} deg");
}

#[test]
fn release_profile_and_full_resolution_also_meet_the_targets() {
    let xi = motions()[4];
    for (name, config) in [
        ("release", DvoConfig::release()),
        (
            "full resolution",
            DvoConfig {
                finest_level: 0,
                ..DvoConfig::paper()
            },
        ),
        (
            "init from previous",
            DvoConfig {
                init_from_previous_motion: true,
                ..DvoConfig::paper()
            },
        ),
    ] {
        let (et, er, status) = run(&xi, false, false, config);
        println!("{name}: {et:.3} mm {er:.4} deg");
        assert_eq!(status, DvoStatus::Converged, "{name}");
        assert!(
            et < MAX_TRANS_ERR_MM && er < MAX_ROT_ERR_DEG,
            "{name}: {et:.3} mm, {er:.4} deg"
        );
    }
}

#[test]
fn nan_intensities_fail_as_non_finite_and_never_leak() {
    let seq = SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    };
    let (reference, current) = motion_pair(seq, &Isometry3::identity(), false);
    let mut poisoned = current.gray.clone();
    poisoned.set(100, 100, f32::NAN);
    let mut tracker = DvoTracker::new(seq.size, reference.intrinsics, DvoConfig::paper()).unwrap();
    let est = tracker
        .estimate_between(
            (&reference.gray, &reference.depth_m),
            (&poisoned, &current.depth_m),
            None,
            None,
        )
        .unwrap();
    assert!(
        matches!(est.status, DvoStatus::Failed(DvoFailure::NonFinite { .. })),
        "{:?}",
        est.status
    );
    assert_finite(&est.current_from_reference);
    // A non-finite initial guess is a caller error, reported as such.
    let bad = se3_exp(&Twist::new(f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0));
    assert!(tracker
        .estimate_between(
            (&reference.gray, &reference.depth_m),
            (&current.gray, &current.depth_m),
            None,
            Some(&bad)
        )
        .is_err());
}

/// A static room seen along `camera` at 320×240: (gray, depth) per frame and the true
/// motion of each frame from the one before it.
fn room_frames(camera: CameraPath, frames: usize) -> (Vec<(GrayF32, DepthMeters)>, Vec<Isometry3<f64>>) {
    let config = SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::custom(config, camera, Vec::new(), frames);
    let images = (0..frames)
        .map(|i| {
            let f = sequence.frame(i);
            (f.gray, f.depth_m)
        })
        .collect();
    let truth = (0..frames).map(|i| sequence.current_from_previous(i)).collect();
    (images, truth)
}

/// Tracks every frame; returns each frame's motion from the one before it (identity for the
/// first) and how many times the tracker asked for the previous frame's ignore mask.
fn track_all(config: DvoConfig, images: &[(GrayF32, DepthMeters)]) -> (Vec<Isometry3<f64>>, usize) {
    let intrinsics = SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    }
    .intrinsics();
    let mut tracker = DvoTracker::new(images[0].0.size(), intrinsics, config).unwrap();
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let motions = images
        .iter()
        .map(|(gray, depth_m)| {
            let ask = || {
                calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                Ok(None)
            };
            tracker
                .track_with(gray, depth_m, ask, None)
                .unwrap()
                .map_or_else(Isometry3::identity, |e| {
                    assert!(e.is_converged(), "{:?}", e.status);
                    e.current_from_reference
                })
        })
        .collect();
    (motions, calls.into_inner())
}

fn with_keyframes(keyframe: KeyframeConfig) -> DvoConfig {
    DvoConfig {
        keyframe: Some(keyframe),
        ..DvoConfig::paper()
    }
}

#[test]
fn a_new_keyframe_at_every_frame_is_frame_to_frame_bit_for_bit() {
    let (images, _) = room_frames(CameraPath::handheld(), 12);
    let (frame_to_frame, asked) = track_all(DvoConfig::paper(), &images);
    assert_eq!(asked, images.len() - 1);
    let one = KeyframeConfig {
        max_frames: 1,
        ..KeyframeConfig::default()
    };
    let (keyframes, asked) = track_all(with_keyframes(one), &images);
    assert_eq!(asked, images.len() - 1);
    assert_eq!(frame_to_frame, keyframes);
}

#[test]
fn a_keyframe_is_prepared_once_and_tracked_against_until_a_limit() {
    // A camera at rest: only the frame limit ends a keyframe. 12 tracked frames, 4 per keyframe.
    let (images, _) = room_frames(CameraPath::fixed(), 13);
    let four = KeyframeConfig {
        max_frames: 4,
        ..KeyframeConfig::default()
    };
    let (motions, asked) = track_all(with_keyframes(four), &images);
    assert_eq!(asked, 3);
    // The chained poses stay at rest: each is one estimate against its keyframe after the
    // keyframes' own, so within one per-pair bound per keyframe so far (every frame has its
    // own sensor noise; measured at most 1.71 mm, 0.021°, on the third keyframe).
    let mut world_from_camera = Isometry3::identity();
    for (i, m) in motions.iter().enumerate() {
        world_from_camera *= m.inverse();
        let (et, er) = error(&world_from_camera, &Isometry3::identity());
        let keyframes = 1 + i.saturating_sub(1) / 4;
        let k = keyframes as f64;
        assert!(
            et < k * MAX_TRANS_ERR_MM && er < k * MAX_ROT_ERR_DEG,
            "frame {i}: {et} mm {er} deg"
        );
    }
    // Moving 2 cm per frame (30 Hz), the 5 cm limit ends each keyframe after 3 frames (6 cm),
    // before the frame limit.
    let walk = CameraPath {
        velocity_mps: nalgebra::Vector3::new(0.0, 0.0, 0.6),
        ..CameraPath::fixed()
    };
    let (images, _) = room_frames(walk, 13);
    let (_, asked) = track_all(with_keyframes(KeyframeConfig::default()), &images);
    assert_eq!(asked, 4);
}

/// On a hand-held path through the static room, chaining estimates against keyframes ends
/// nearer the true pose than chaining frame-to-frame ones: each keyframe's error enters once,
/// not once per frame.
#[test]
fn keyframes_drift_less_than_frame_to_frame() {
    let (images, truth) = room_frames(CameraPath::handheld(), 60);
    let end_error = |motions: &[Isometry3<f64>]| {
        let chain = |m: &[Isometry3<f64>]| m.iter().fold(Isometry3::identity(), |acc, step| step * acc);
        error(&chain(motions), &chain(&truth))
    };
    let (frame_to_frame, _) = track_all(DvoConfig::paper(), &images);
    let (keyframes, asked) = track_all(with_keyframes(KeyframeConfig::default()), &images);
    let (ft, fr) = end_error(&frame_to_frame);
    let (kt, kr) = end_error(&keyframes);
    println!("end error over 60 frames: frame to frame {ft:.2} mm {fr:.3} deg; keyframes {kt:.2} mm {kr:.3} deg ({asked} keyframes)");
    assert!(asked < 59 / 2, "{asked} keyframes");
    assert!(kt < ft, "{kt} mm vs {ft} mm");
}

/// The motion prior's prediction is the last motion only when that motion was estimated with
/// about as much of its reference ignored as the next estimate ignores: the camera moves 3 cm
/// and stops, and the stop is tracked with half of the view ignored under a prior heavy enough
/// to hold any estimate it is given. When the move was estimated with nothing ignored, the
/// default drops its prediction (the stop is found), and `max_ignored_fraction_increase` 1
/// keeps it (the stop is held at the move), and so does the default when the move was
/// estimated with the same half ignored, or after `startup_frames`. Measured at 320×240: the
/// stop 1.2 mm off with the prediction dropped, 29–32 mm kept (bounds 3 and 20 mm); the move
/// itself 1.8 mm.
#[test]
fn a_motion_estimated_with_far_less_ignored_does_not_predict_the_next() {
    let config = SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::custom(config, CameraPath::fixed(), Vec::new(), 3);
    let moved = Isometry3::translation(0.03, 0.0, 0.0);
    let frames: Vec<_> = [Isometry3::identity(), moved, moved]
        .iter()
        .enumerate()
        .map(|(i, world_from_camera)| {
            let mut frame = occmask::synthetic::SyntheticFrame::empty(config.size);
            sequence.render_view_into(i, i as f64 / config.fps, world_from_camera, &mut frame);
            frame
        })
        .collect();
    let mut left_half = Mask::filled(config.size, 0);
    for row in left_half.as_mut_slice().chunks_exact_mut(config.size.width) {
        row[..config.size.width / 2].fill(255);
    }
    // The stop's error (mm) when the move was tracked ignoring `move_ignore`.
    let stop_error_mm =
        |max_ignored_fraction_increase: f64, startup_frames: usize, move_ignore: Option<&Mask>| {
            let dvo = DvoConfig {
                motion_prior: Some(MotionPriorConfig {
                    translation_sigma_m: 0.001,
                    weight: 1.0,
                    full_weight_ignored_fraction: 0.0,
                    max_ignored_fraction_increase,
                    startup_frames,
                    ..MotionPriorConfig::default()
                }),
                ..DvoConfig::paper()
            };
            let mut tracker = DvoTracker::new(config.size, config.intrinsics(), dvo).unwrap();
            let estimates: Vec<_> = [None, move_ignore, Some(&left_half)]
                .into_iter()
                .zip(&frames)
                .map(|(ignore, f)| {
                    tracker
                        .track(&f.gray, &f.depth_m, ignore, None)
                        .unwrap()
                        .map(|e| e.current_from_reference)
                })
                .collect();
            assert!(estimates[0].is_none());
            let (move_mm, _) = error(&estimates[1].unwrap(), &moved.inverse());
            assert!(move_mm < 3.0, "the move: {move_mm:.2} mm off");
            error(&estimates[2].unwrap(), &Isometry3::identity()).0
        };
    let MotionPriorConfig {
        max_ignored_fraction_increase: increase,
        startup_frames: startup,
        ..
    } = MotionPriorConfig::default();
    let dropped = stop_error_mm(increase, startup, None);
    let kept = stop_error_mm(1.0, startup, None);
    let same_ignored = stop_error_mm(increase, startup, Some(&left_half));
    let after_startup = stop_error_mm(increase, 0, None);
    println!(
        "stop error: prediction dropped {dropped:.2} mm, kept {kept:.2} mm, kept (same half ignored) \
         {same_ignored:.2} mm, kept (after the startup frames) {after_startup:.2} mm"
    );
    assert!(dropped < 3.0, "{dropped:.2} mm");
    assert!(
        kept > 20.0 && same_ignored > 20.0,
        "{kept:.2} / {same_ignored:.2} mm"
    );
}
