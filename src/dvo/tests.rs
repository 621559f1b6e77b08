//! Tests of the DVO configuration, estimator and tracker.

use super::*;

#[test]
fn profiles_validate_and_differ_where_documented() {
    DvoConfig::paper().validate().unwrap();
    DvoConfig::release().validate().unwrap();
    DvoConfig::closed_loop().validate().unwrap();
    assert_eq!(DvoConfig::default(), DvoConfig::paper());
    let r = DvoConfig::release();
    assert!((r.k_intensity.at_level(3) - 16.0 / 255.0).abs() < 1e-6);
    assert!((r.k_intensity.at_level(0) - 61.61 / 255.0).abs() < 1e-4);
    assert_eq!(r.k_intensity.at_level(4), r.k_intensity.at_level(3));
    // Too small for 5 levels: as many as fit (40×30 → 40, 20, 10 px wide).
    assert_eq!(DvoConfig::paper().levels_for(ImageSize::new(640, 480)), 5);
    assert_eq!(DvoConfig::paper().levels_for(ImageSize::new(40, 30)), 2);
}

#[test]
fn ignored_pixels_are_dropped_with_at_least_the_dilation_radius() {
    use crate::geometry::camera::presets;
    let size = ImageSize::new(128, 96);
    let config = DvoConfig {
        levels: 3,
        finest_level: 1,
        min_gradient_per_px: 0.0,
        ..DvoConfig::paper()
    };
    let gray = GrayF32::from_fn(size, |x, y| ((x * 7 + y * 3) % 11) as f32 / 11.0);
    let mut depth = DepthMeters::filled(size, 2.0);
    depth.set(100, 80, 0.0); // one invalid pixel: its coarse pixel keeps the other children
    let mut pyr = ImagePyramid::new(size, presets::TUM_FR2, 3, 1).unwrap();
    pyr.build(&gray, &depth).unwrap();
    let mut est = DvoEstimator::new(size, config).unwrap();
    est.prepare_reference(&pyr, None).unwrap();
    assert_eq!(est.reference_points(1).len(), 64 * 48);
    assert_eq!(est.reference_points(2).len(), 32 * 24);
    // Ignore full-resolution columns 40..=59 (255 = set, as in a Mask).
    let mask = Mask::from_fn(size, |x, _| if (40..60).contains(&x) { 255 } else { 0 });
    est.prepare_reference(&pyr, Some(&mask)).unwrap();
    let k1 = presets::TUM_FR2.at_level(1);
    for p in est.reference_points(1) {
        // Back to the level-1 column, then to full-resolution coordinates of its children.
        let x1 = (f64::from(p.point_m[0]) / f64::from(p.point_m[2]) * k1.fx + k1.cx).round() as i64;
        let (c0, c1) = (2 * x1, 2 * x1 + 1);
        let gap = (40 - c1).max(c0 - 59);
        assert!(
            gap > 4,
            "level-1 column {x1} is within {gap} px of the ignored band"
        );
    }
    let kept = est.reference_points(1).len();
    assert!(kept < 64 * 48 - 10 * 48, "{kept}");
    assert!(est.reference_points(2).len() < 32 * 24 - 5 * 24);
}

#[test]
fn validation_names_the_bad_field() {
    let cases: Vec<(DvoConfig, &str)> = vec![
        (
            DvoConfig {
                levels: 0,
                ..DvoConfig::paper()
            },
            "levels",
        ),
        (
            DvoConfig {
                finest_level: DEFAULT_LEVELS,
                ..DvoConfig::paper()
            },
            "finest_level",
        ),
        (
            DvoConfig {
                lm_lambda_up: 1.0,
                ..DvoConfig::paper()
            },
            "lm_lambda_up",
        ),
        (
            DvoConfig {
                k_depth_m: f32::NAN,
                ..DvoConfig::paper()
            },
            "k_depth_m",
        ),
        (
            DvoConfig {
                k_intensity: IntensityThreshold::Constant(0.0),
                ..DvoConfig::paper()
            },
            "k_intensity",
        ),
        (
            DvoConfig {
                step_tolerance: -1.0,
                ..DvoConfig::paper()
            },
            "step_tolerance",
        ),
        (
            DvoConfig {
                max_depth_m: 0.0,
                ..DvoConfig::paper()
            },
            "max_depth_m",
        ),
        (
            DvoConfig {
                keyframe: Some(KeyframeConfig {
                    max_frames: 0,
                    ..KeyframeConfig::default()
                }),
                ..DvoConfig::paper()
            },
            "keyframe.max_frames",
        ),
        (
            DvoConfig {
                keyframe: Some(KeyframeConfig {
                    max_rotation_rad: f64::NAN,
                    ..KeyframeConfig::default()
                }),
                ..DvoConfig::paper()
            },
            "keyframe.max_rotation_rad",
        ),
        (
            DvoConfig {
                keyframe: Some(KeyframeConfig {
                    max_moving_fraction: 1.5,
                    ..KeyframeConfig::default()
                }),
                ..DvoConfig::paper()
            },
            "keyframe.max_moving_fraction",
        ),
        (
            DvoConfig {
                max_final_cost_fraction: 0.0,
                ..DvoConfig::paper()
            },
            "max_final_cost_fraction",
        ),
        (
            DvoConfig {
                min_usable_pixels: 2,
                ..DvoConfig::paper()
            },
            "min_usable_pixels",
        ),
    ];
    for (cfg, name) in cases {
        match cfg.validate() {
            Err(Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
            other => panic!("{name}: {other:?}"),
        }
    }
}

/// The reference points of every level against their per-pixel definition, in row order:
/// depth within the configured range, gradient not below the threshold (a NaN gradient
/// passes), not ignored; and the ignored fraction at the finest level counts the ignored
/// pixels that would otherwise be kept. Widths that are and are not multiples of 8 (the
/// selection reads its flags eight at a time), with and without an ignore mask.
#[test]
fn reference_points_are_the_usable_unignored_pixels_in_row_order() {
    for (size, with_mask) in [
        (ImageSize::new(96, 72), true),
        (ImageSize::new(101, 75), true),
        (ImageSize::new(101, 75), false),
    ] {
        check_reference_points(size, with_mask);
    }
}

fn check_reference_points(size: ImageSize, with_mask: bool) {
    use crate::geometry::camera::presets;
    let config = DvoConfig {
        levels: 3,
        finest_level: 0,
        min_gradient_per_px: 0.02,
        min_depth_m: 0.5,
        max_depth_m: 3.0,
        ..DvoConfig::paper()
    };
    let mut rng = crate::xorshift::XorShift64::new(0x9e37_79b9_7f4a_7c15);
    let mut next = move |n: u64| rng.next_u64() % n;
    let gray = GrayF32::from_fn(size, |x, y| match next(40) {
        0 if x > 0 && y > 0 => f32::NAN,
        k => ((x * 5 + y * 3) % 13) as f32 / 13.0 * 0.3 + k as f32 * 0.001,
    });
    let depth = DepthMeters::from_fn(size, |_, _| match next(10) {
        0 => 0.0,
        1 => 0.2,
        2 => 4.0,
        k => 1.0 + 0.1 * k as f32,
    });
    let mask = Mask::from_fn(size, |x, y| if (x / 8 + y / 8) % 3 == 0 { 255 } else { 0 });
    let mut pyr = ImagePyramid::new(size, presets::TUM_FR2, 3, 0).unwrap();
    pyr.build(&gray, &depth).unwrap();
    // Every build of the row selection the CPU runs.
    for simd in Simd::available() {
        let mut est = DvoEstimator::new(size, config).unwrap();
        est.simd = simd;
        est.prepare_reference(&pyr, with_mask.then_some(&mask)).unwrap();
        let min_grad_sq = config.min_gradient_per_px * config.min_gradient_per_px;
        for l in 0..config.levels {
            let level = pyr.level(l).unwrap();
            let k = level.intrinsics;
            let w = level.size().width;
            let ignore = &est.ignore[l];
            let (mut expected, mut ignored) = (Vec::new(), 0usize);
            for (i, s) in level.samples.iter().enumerate() {
                let z = level.depth_m.as_slice()[i];
                let (gx, gy) = (s.0[TargetSample::GRAD_X], s.0[TargetSample::GRAD_Y]);
                let grad_sq = gx * gx + gy * gy;
                let usable = z > 0.0
                    && z >= config.min_depth_m
                    && z <= config.max_depth_m
                    && (grad_sq >= min_grad_sq || grad_sq.is_nan());
                if !usable {
                    continue;
                }
                if with_mask && ignore[i] != 0 {
                    ignored += 1;
                    continue;
                }
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                expected.push(ReferencePoint {
                    point_m: [
                        (x - k.cx as f32) * (1.0 / k.fx as f32) * z,
                        (y - k.cy as f32) * (1.0 / k.fy as f32) * z,
                        z,
                    ],
                    intensity: level.gray.as_slice()[i],
                });
            }
            let bits = |p: &[ReferencePoint]| -> Vec<[u32; 4]> {
                p.iter()
                    .map(|p| [p.point_m[0], p.point_m[1], p.point_m[2], p.intensity].map(f32::to_bits))
                    .collect()
            };
            assert_eq!(
                bits(est.reference_points(l)),
                bits(&expected),
                "{simd:?} {size} level {l}"
            );
            assert!(!expected.is_empty(), "{simd:?} {size} level {l}: no point kept");
            if l == 0 {
                assert!(
                    expected.len() > 100 && (ignored > 100 || !with_mask),
                    "{} kept, {ignored} ignored",
                    expected.len()
                );
                assert_eq!(
                    est.ignored_fraction,
                    ignored as f64 / (ignored + expected.len()) as f64
                );
                let nan_kept = est
                    .reference_points(0)
                    .iter()
                    .filter(|p| p.intensity.is_nan())
                    .count();
                assert!(
                    nan_kept > 0,
                    "no NaN-gradient pixel kept: the case is not exercised"
                );
            }
        }
    }
}
