use nalgebra::{Isometry3, Vector3};

use super::transport::{transport, transport_scalar, TransportInputs, TransportOutputs};
use super::*;
use crate::synthetic::{DepthSensorModel, Scenario, SequenceConfig, SyntheticSequence};

const SIZE: ImageSize = ImageSize::new(160, 120);

fn intrinsics() -> PinholeIntrinsics {
    PinholeIntrinsics::new(131.25, 131.25, 79.5, 59.5)
}

fn wall(depth_m: f32) -> DepthMeters {
    Image::filled(SIZE, depth_m)
}

/// A wall at 3 m with a fronto-parallel rectangle at `box_depth_m` covering [x0, x1) × [y0, y1).
fn wall_with_box(x0: usize, x1: usize, y0: usize, y1: usize, box_depth_m: f32) -> DepthMeters {
    Image::from_fn(SIZE, |x, y| {
        if (x0..x1).contains(&x) && (y0..y1).contains(&y) {
            box_depth_m
        } else {
            3.0
        }
    })
}

fn count(mask: &Mask) -> usize {
    mask.as_slice().iter().filter(|&&m| m != 0).count()
}

#[test]
fn fused_transport_matches_the_scalar_reference() {
    let config = SequenceConfig {
        size: ImageSize::new(160, 120),
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::TwoObjectsCrossing, config);
    let k = config.intrinsics();
    let mut detector = OcclusionDetector::new(config.size, k, OcclusionConfig::default()).unwrap();
    for i in 0..30 {
        let frame = sequence.frame(i);
        detector
            .update(&frame.depth_m, &sequence.current_from_previous(i))
            .unwrap();
    }
    // Use the detector's real state (non-zero A and P) as the previous frame.
    let next = sequence.frame(30);
    let motion = sequence.current_from_previous(30)
        * Isometry3::new(Vector3::new(0.01, 0.0, -0.02), Vector3::new(0.0, 0.02, 0.01));
    let previous_from_current = motion.inverse();
    let mut predicted_previous = detector.predicted_area().clone();
    predicted_previous.as_mut_slice()[500] = 1;
    let inputs = TransportInputs {
        ray_x: &detector.ray_x,
        ray_y: &detector.ray_y,
        intrinsics: &k,
        previous_from_current: &previous_from_current,
        config: &detector.config,
        depth_m: &next.depth_m,
        compensated_previous_m: &detector.compensated_m,
        accumulation_previous_m: &detector.accumulation_m,
        predicted_previous: &predicted_previous,
    };
    let blank = || {
        (
            Image::filled(config.size, 0.0f32),
            Image::filled(config.size, 0.0f32),
            Image::filled(config.size, 0u8),
            Image::filled(config.size, 0.0f32),
            Image::filled(config.size, 0u8),
        )
    };
    let (mut zc1, mut a1, mut p1, mut dz1, mut n1) = blank();
    let (mut zc2, mut a2, mut p2, mut dz2, mut n2) = blank();
    let fast = transport(
        &inputs,
        TransportOutputs {
            compensated_m: &mut zc1,
            accumulation_m: &mut a1,
            predicted_carried: &mut p1,
            delta_z_m: &mut dz1,
            newly_discovered: &mut n1,
        },
    );
    let slow = transport_scalar(
        &inputs,
        TransportOutputs {
            compensated_m: &mut zc2,
            accumulation_m: &mut a2,
            predicted_carried: &mut p2,
            delta_z_m: &mut dz2,
            newly_discovered: &mut n2,
        },
    );
    assert!(fast.warped > config.size.area() / 2);
    // Different floating-point evaluation orders may round a warp that lands within ~1e-12 px of a
    // pixel boundary differently; allow at most 0.05 % of pixels to differ.
    let differing = (0..config.size.area())
        .filter(|&i| {
            zc1.as_slice()[i] != zc2.as_slice()[i]
                || a1.as_slice()[i] != a2.as_slice()[i]
                || p1.as_slice()[i] != p2.as_slice()[i]
                || dz1.as_slice()[i] != dz2.as_slice()[i]
                || n1.as_slice()[i] != n2.as_slice()[i]
        })
        .count();
    assert!(
        differing * 2000 <= config.size.area(),
        "{differing} pixels differ"
    );
    assert!(fast.warped.abs_diff(slow.warped) <= differing);
    assert!(
        a1.as_slice().iter().any(|&a| a > 0.0),
        "the test must exercise non-zero accumulation"
    );
}

#[test]
fn first_frame_gives_an_empty_mask_and_static_scene_stays_empty() {
    let mut detector = OcclusionDetector::new(SIZE, intrinsics(), OcclusionConfig::default()).unwrap();
    let depth = wall(2.0);
    for _ in 0..5 {
        let mask = detector.update(&depth, &Isometry3::identity()).unwrap();
        assert_eq!(count(mask), 0);
    }
    assert!(detector.accumulation_m().as_slice().iter().all(|&a| a == 0.0));
}

#[test]
fn an_object_appearing_in_front_of_a_wall_is_detected_with_its_depth_gap() {
    let mut detector = OcclusionDetector::new(SIZE, intrinsics(), OcclusionConfig::default()).unwrap();
    detector.update(&wall(3.0), &Isometry3::identity()).unwrap();
    let depth = wall_with_box(40, 80, 30, 70, 1.5);
    let mask = detector.update(&depth, &Isometry3::identity()).unwrap().clone();
    assert_eq!(count(&mask), 40 * 40);
    assert_eq!(mask.get(40, 30), MASK_SET);
    assert_eq!(mask.get(39, 30), 0);
    assert!((detector.accumulation_m().get(60, 50) - 1.5).abs() < 1e-6);
    // It stays detected while it stands still (A is carried)...
    let mask = detector.update(&depth, &Isometry3::identity()).unwrap();
    assert_eq!(count(mask), 40 * 40);
    // ...and disappears when the wall reappears (ΔZ ≤ −τ_β resets A).
    let mask = detector.update(&wall(3.0), &Isometry3::identity()).unwrap();
    assert_eq!(count(mask), 0);
}

#[test]
fn small_components_are_erased_with_a_threshold_scaled_by_area() {
    let config = OcclusionConfig::default();
    // 500 px at VGA → 500 / 16 ≈ 31 px at 160 × 120.
    assert_eq!(config.min_object_pixels(SIZE), 31);
    let mut detector = OcclusionDetector::new(SIZE, intrinsics(), config).unwrap();
    detector.update(&wall(3.0), &Isometry3::identity()).unwrap();
    let mask = detector
        .update(&wall_with_box(10, 15, 10, 16, 1.0), &Isometry3::identity())
        .unwrap();
    assert_eq!(count(mask), 0, "a 30-px object is below the threshold");
    assert_eq!(detector.stats().small_components_erased, 1);
    let mut detector = OcclusionDetector::new(SIZE, intrinsics(), config).unwrap();
    detector.update(&wall(3.0), &Isometry3::identity()).unwrap();
    let mask = detector
        .update(&wall_with_box(10, 15, 10, 17, 1.0), &Isometry3::identity())
        .unwrap();
    assert_eq!(count(mask), 35);
}

#[test]
fn thresholds_follow_the_configured_form() {
    let linear = OcclusionConfig::default();
    let quadratic = OcclusionConfig {
        threshold_form: ThresholdForm::Quadratic,
        ..linear
    };
    assert_eq!(linear.threshold(0.15, 2.0), 0.3);
    assert_eq!(quadratic.threshold(0.15, 2.0), 0.6);
    // A 0.4 m step at 2.5 m: above α·Z = 0.375, below α·Z² = 0.94.
    for (config, expected) in [(linear, 400), (quadratic, 0)] {
        let mut detector = OcclusionDetector::new(SIZE, intrinsics(), config).unwrap();
        detector.update(&wall(2.9), &Isometry3::identity()).unwrap();
        let mask = detector
            .update(&wall_with_box(20, 40, 20, 40, 2.5), &Isometry3::identity())
            .unwrap();
        assert_eq!(count(mask), expected);
    }
}

#[test]
fn translation_of_the_camera_compensates_static_geometry() {
    // Camera moves 5 cm right in front of a wall with a static box: nothing is detected, and
    // the newly discovered strip on the right is found.
    let k = intrinsics();
    let mut detector = OcclusionDetector::new(SIZE, k, OcclusionConfig::default()).unwrap();
    let render = |camera_x: f64| {
        Image::from_fn(SIZE, |x, y| {
            let box_x = (x as f64 - k.cx) / k.fx * 1.5 + camera_x;
            let box_y = (y as f64 - k.cy) / k.fy * 1.5;
            if (-0.2..0.2).contains(&box_x) && (-0.2..0.2).contains(&box_y) {
                1.5
            } else {
                3.0
            }
        })
    };
    detector.update(&render(0.0), &Isometry3::identity()).unwrap();
    // Camera moves by +x: points move by −x in the new camera.
    let current_from_previous = Isometry3::translation(-0.05, 0.0, 0.0);
    let current = render(0.05);
    let mask = detector.update(&current, &current_from_previous).unwrap().clone();
    // The release warp back-projects with the *previous* depth at the same pixel (§1 step 2), so
    // where the near box now covers pixels that were wall, the wall's (smaller) image motion is
    // used: a strip as wide as the difference of the two parallaxes (4.4 − 2.2 px) left of the
    // box's new left edge is flagged. Nothing else may be.
    let left_edge = (0..SIZE.width).find(|&x| current.get(x, 60) < 2.0).unwrap();
    for y in 0..SIZE.height {
        for x in 0..SIZE.width {
            if mask.get(x, y) != 0 {
                assert!(
                    (left_edge..left_edge + 3).contains(&x),
                    "false positive at ({x}, {y})"
                );
            }
        }
    }
    // 5 cm at 3 m is 2.2 px: the right-most 2-3 columns are newly discovered.
    let newly = detector
        .newly_discovered()
        .as_slice()
        .iter()
        .filter(|&&n| n != 0)
        .count();
    assert!(
        (2 * 120..=3 * 120 + 40).contains(&newly),
        "newly discovered {newly}"
    );
    // A wrong motion (the opposite direction) makes the box's edge look like motion.
    let mut detector = OcclusionDetector::new(SIZE, k, OcclusionConfig::default()).unwrap();
    detector.update(&render(0.0), &Isometry3::identity()).unwrap();
    detector
        .update(&render(0.05), &Isometry3::translation(0.05, 0.0, 0.0))
        .unwrap();
    assert!(detector.stats().components > 0);
}

#[test]
fn prediction_fills_newly_discovered_object_area_and_pruning_removes_islands() {
    // Frame 1: wall. Frame 2: the camera moved right by one object-free step and a large box
    // appeared that also covers the newly discovered strip at the right border: the box part
    // in the strip has no previous depth, so only prediction can mark it.
    let k = intrinsics();
    let config = OcclusionConfig::default();
    let mut detector = OcclusionDetector::new(SIZE, k, config).unwrap();
    let wall_at = |camera_x: f64, with_box: bool| {
        Image::from_fn(SIZE, |x, y| {
            let wx = (x as f64 - k.cx) / k.fx * 1.0 + camera_x;
            if with_box && wx > 0.0 && (20..100).contains(&y) {
                1.0f32
            } else {
                // Wall at 3 m.
                3.0
            }
        })
    };
    detector
        .update(&wall_at(0.0, false), &Isometry3::identity())
        .unwrap();
    let current_from_previous = Isometry3::translation(-0.1, 0.0, 0.0);
    let mask = detector
        .update(&wall_at(0.1, true), &current_from_previous)
        .unwrap()
        .clone();
    let stats = *detector.stats();
    assert!(stats.predicted_pixels > 0, "{stats:?}");
    // The right-most interior columns of the box rows are object although never seen before.
    assert_eq!(mask.get(SIZE.width - 2, 60), MASK_SET);
    // Border ring is never predicted into.
    assert_eq!(mask.get(SIZE.width - 1, 60), 0);
    // Without prediction the strip stays background.
    let mut plain = OcclusionDetector::new(
        SIZE,
        k,
        OcclusionConfig {
            predict_newly_discovered: false,
            ..config
        },
    )
    .unwrap();
    plain
        .update(&wall_at(0.0, false), &Isometry3::identity())
        .unwrap();
    let plain_mask = plain.update(&wall_at(0.1, true), &current_from_previous).unwrap();
    assert_eq!(plain_mask.get(SIZE.width - 2, 60), 0);
    assert!(count(&mask) > count(plain_mask));
}

#[test]
fn wrong_sizes_are_rejected() {
    let mut detector = OcclusionDetector::new(SIZE, intrinsics(), OcclusionConfig::default()).unwrap();
    let err = detector
        .update(
            &Image::filled(ImageSize::new(10, 10), 1.0),
            &Isometry3::identity(),
        )
        .unwrap_err();
    assert!(matches!(err, Error::SizeMismatch { .. }));
    let bad = OcclusionConfig {
        alpha: -1.0,
        ..OcclusionConfig::default()
    };
    assert!(matches!(
        OcclusionDetector::new(SIZE, intrinsics(), bad),
        Err(Error::InvalidParameter { name: "alpha", .. })
    ));
}

#[test]
fn ideal_sensor_static_sequence_with_true_poses_has_no_false_positives() {
    let config = SequenceConfig {
        size: SIZE,
        sensor: DepthSensorModel::ideal(),
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::StaticScene, config);
    let mut detector = OcclusionDetector::new(SIZE, config.intrinsics(), OcclusionConfig::default()).unwrap();
    for i in 0..sequence.len() {
        let frame = sequence.frame(i);
        let mask = detector
            .update(&frame.depth_m, &sequence.current_from_previous(i))
            .unwrap();
        assert_eq!(count(mask), 0, "frame {i}");
    }
}
