//! Tests of the residuals and normal equations: the AVX2 kernel against the scalar reference, Jacobians against finite differences.

use super::*;
use crate::geometry::{camera::presets, se3_exp, Twist};
use crate::image_buf::{DepthMeters, GrayF32};
use crate::pyramid::ImagePyramid;

/// A smooth textured slanted scene, so finite differences are meaningful.
fn smooth_level() -> ImagePyramid {
    let size = ImageSize::new(160, 120);
    let gray = GrayF32::from_fn(size, |x, y| {
        let (x, y) = (x as f32, y as f32);
        0.5 + 0.2 * (x * 0.05).sin() * (y * 0.035).cos() + 0.1 * ((x + 2.0 * y) * 0.025).sin()
    });
    let depth = DepthMeters::from_fn(size, |x, y| 1.5 + 0.004 * x as f32 + 0.002 * y as f32);
    let k = presets::TUM_FR2.at_level(2);
    let mut p = ImagePyramid::new(size, k, 1, 0).unwrap();
    p.build(&gray, &depth).unwrap();
    p
}

fn points_of(p: &ImagePyramid) -> Vec<ReferencePoint> {
    let lv = p.level(0).unwrap();
    let mut out = Vec::new();
    for y in 0..lv.size().height {
        for x in 0..lv.size().width {
            let z = lv.depth_m.get(x, y);
            // Off the pixel grid by a quarter pixel so no point projects exactly onto the
            // border of the bilinear domain, where f32 and f64 may decide differently.
            let q = lv
                .intrinsics
                .back_project(x as f64 + 0.25, y as f64 + 0.25, f64::from(z));
            // Reference intensity slightly perturbed so residuals are non-zero.
            let i = lv.gray.get(x, y) + 0.02 * ((x * 7 + y * 3) % 5) as f32 / 5.0;
            out.push(ReferencePoint {
                point_m: [q.x as f32, q.y as f32, q.z as f32],
                intensity: i,
            });
        }
    }
    out
}

fn view(p: &ImagePyramid) -> TargetView<'_> {
    let lv = p.level(0).unwrap();
    TargetView {
        samples: &lv.samples,
        size: lv.size(),
        intrinsics: lv.intrinsics,
    }
}

const COST: CostParams = CostParams {
    k_intensity: 48.0 / 255.0,
    k_depth_m: 0.5,
    depth_weight: 0.001,
};

#[test]
fn jacobians_match_finite_differences() {
    let pyr = smooth_level();
    let target = view(&pyr);
    let points = points_of(&pyr);
    let t = se3_exp(&Twist::new(0.01, -0.005, 0.02, 0.004, -0.006, 0.002));
    let eps = 1e-5;
    let mut checked = 0;
    let mut errors = Vec::new();
    for p in points.iter().step_by(97) {
        let Some(lin) = linearize_point(p, &target, &t) else {
            continue;
        };
        let Some((_, jz)) = lin.depth else { continue };
        let mut ok = true;
        let (mut num_i, mut num_z) = (Vector6::zeros(), Vector6::zeros());
        for k in 0..6 {
            let mut d = Twist::zeros();
            d[k] = eps;
            let (Some(lp), Some(lm)) = (
                linearize_point(p, &target, &(se3_exp(&d) * t)),
                linearize_point(p, &target, &(se3_exp(&(-d)) * t)),
            ) else {
                ok = false;
                break;
            };
            num_i[k] = (lp.residual_intensity - lm.residual_intensity) / (2.0 * eps);
            match (lp.depth, lm.depth) {
                (Some((a, _)), Some((b, _))) => num_z[k] = (a - b) / (2.0 * eps),
                _ => ok = false,
            }
        }
        if !ok {
            continue;
        }
        errors.push((
            (num_i - lin.jacobian_intensity).norm(),
            lin.jacobian_intensity.norm(),
            (num_z - jz).norm(),
            jz.norm(),
        ));
        checked += 1;
    }
    // Bilinear values have piecewise-linear slopes while the gradients are bilinearly
    // interpolated central differences: they differ by up to ½·|f''| per pixel, about 2 %
    // of a typical gradient on this texture (wavelength ≥ 125 px), so the error is measured
    // against the largest Jacobian (a point near a gradient extremum has a tiny Jacobian).
    let max_i = errors.iter().fold(0.0f64, |m, e| m.max(e.1));
    let max_z = errors.iter().fold(0.0f64, |m, e| m.max(e.3));
    for &(ei, ni, ez, nz) in &errors {
        assert!(
            ei / max_i < 0.03,
            "intensity Jacobian error {ei} (norm {ni}, max {max_i})"
        );
        assert!(
            ez / max_z < 0.01,
            "depth Jacobian error {ez} (norm {nz}, max {max_z})"
        );
    }
    assert!(checked > 50, "only {checked} points checked");
}

#[test]
fn wide_simd_build_is_bit_identical_to_the_baseline_build() {
    let pyr = smooth_level();
    let target = view(&pyr);
    let points = points_of(&pyr);
    let t = se3_exp(&Twist::new(0.02, -0.01, 0.03, 0.01, -0.02, 0.005));
    let kc = KernelConstants::new(&target, &t, &COST);
    let baseline = accumulate_chunk(&points, target.samples, &kc);
    let dispatched = accumulate_chunk_dispatch(&points, target.samples, &kc);
    assert_eq!(baseline, dispatched);
    assert!(baseline.inliers > points.len() / 2);
}

/// The sum over tasks is formed in point order whatever the pool size, so the estimate (and
/// `occmask process`'s output bytes) do not depend on how many threads run it: bit-identical
/// to the one-thread sum in pools of 1 to 7 threads, with tasks stolen at random. Every
/// other task's points are pushed a million times further along their rays (same pixels,
/// translation Jacobians 10⁶ smaller, H entries 10¹² smaller), so the partial sums span
/// more than f64's 53 bits and a different grouping of the tasks would change the result.
#[test]
fn parallel_kernel_is_bit_identical_for_any_thread_count() {
    let pyr = smooth_level();
    let target = view(&pyr);
    let row_width = 16;
    let mut points = points_of(&pyr);
    for (i, task) in points.chunks_mut(ROWS_PER_TASK * row_width).enumerate() {
        if i % 2 == 1 {
            for p in task {
                p.point_m = p.point_m.map(|c| c * 1e6);
            }
        }
    }
    assert!(points.len() >= 2 * MIN_POINTS_FOR_PARALLEL, "{}", points.len());
    let t = se3_exp(&Twist::new(0.02, -0.01, 0.03, 0.01, -0.02, 0.005));
    // Width 16: 128-point tasks, 150 of them, so the splits differ between pool sizes.
    let kc = KernelConstants::new(&target, &t, &COST);
    let one_by_one = points
        .chunks(ROWS_PER_TASK * row_width)
        .fold(NormalEquations::default(), |acc, c| {
            acc.merged(&accumulate_chunk_dispatch(c, target.samples, &kc))
        });
    for threads in 1..=7 {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for _ in 0..3 {
            let ne = pool.install(|| accumulate_normal_equations(&points, row_width, &target, &t, &COST));
            assert_eq!(ne, one_by_one, "{threads} threads");
        }
    }
}

#[test]
fn sequential_small_calls_agree_with_scalar_reference() {
    let pyr = smooth_level();
    let target = view(&pyr);
    let points = &points_of(&pyr)[..MIN_POINTS_FOR_PARALLEL / 2];
    let t = se3_exp(&Twist::new(0.02, -0.01, 0.03, 0.01, -0.02, 0.005));
    let a = accumulate_normal_equations_scalar(points, &target, &t, &COST);
    let b = accumulate_normal_equations(points, 160, &target, &t, &COST);
    assert_eq!(a.total, b.total);
    assert!(a.inliers.abs_diff(b.inliers) <= 2);
    let scale = a.hessian_upper.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (x, y) in a.hessian_upper.iter().zip(&b.hessian_upper) {
        assert!((x - y).abs() <= 1e-4 * scale, "{x} vs {y}");
    }
    assert!((a.cost - b.cost).abs() <= 1e-4 * a.cost);
}

#[test]
fn parallel_kernel_agrees_with_scalar_reference() {
    let pyr = smooth_level();
    let target = view(&pyr);
    let points = points_of(&pyr);
    for xi in [
        Twist::zeros(),
        Twist::new(0.02, -0.01, 0.03, 0.01, -0.02, 0.005),
        Twist::new(-0.3, 0.0, 0.0, 0.0, 0.2, 0.0), // most points leave the view
    ] {
        let t = se3_exp(&xi);
        let a = accumulate_normal_equations_scalar(&points, &target, &t, &COST);
        let b = accumulate_normal_equations(&points, 160, &target, &t, &COST);
        assert_eq!(a.total, b.total);
        assert!(a.valid.abs_diff(b.valid) <= 2, "{} vs {}", a.valid, b.valid);
        assert!(a.inliers.abs_diff(b.inliers) <= 2);
        let rel = |x: f64, y: f64, scale: f64| (x - y).abs() / scale.max(1e-12);
        assert!(
            rel(a.cost, b.cost, a.cost) < 1e-4,
            "cost {} vs {}",
            a.cost,
            b.cost
        );
        let hmax = a.hessian_upper.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (x, y) in a.hessian_upper.iter().zip(&b.hessian_upper) {
            assert!(rel(*x, *y, hmax) < 1e-4, "H {x} vs {y}");
        }
        let gmax = a.gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (x, y) in a.gradient.iter().zip(&b.gradient) {
            assert!(rel(*x, *y, gmax) < 1e-3, "g {x} vs {y}");
        }
    }
}

/// The same agreement on a rendered frame pair (texture, depth edges, invalid depth, the
/// moving box masked), with the reference points the estimator selects, at the true motion
/// and 2 cm / 1° away from it.
#[test]
fn parallel_kernel_agrees_with_scalar_reference_on_rendered_frames() {
    use crate::dvo::{DvoConfig, DvoEstimator};
    use crate::synthetic::{motion_pair, SequenceConfig};
    let seq = SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    };
    let truth = se3_exp(&Twist::new(0.02, -0.01, 0.01, 0.01, -0.02, 0.005));
    let (reference, current) = motion_pair(seq, &truth, true);
    let config = DvoConfig {
        levels: 2,
        finest_level: 0,
        ..DvoConfig::paper()
    };
    let build = |f: &crate::synthetic::SyntheticFrame| {
        let mut p = ImagePyramid::new(seq.size, f.intrinsics, 2, 0).unwrap();
        p.build(&f.gray, &f.depth_m).unwrap();
        p
    };
    let (pr, pc) = (build(&reference), build(&current));
    let mut est = DvoEstimator::new(seq.size, config).unwrap();
    est.prepare_reference(&pr, Some(&reference.gt_mask)).unwrap();
    let points = est.reference_points(0);
    assert!(points.len() > 10_000, "{}", points.len());
    let target = view(&pc);
    let off = se3_exp(&Twist::new(0.02, 0.0, 0.0, 0.0, 0.017, 0.0)) * truth;
    for t in [truth, off, Isometry3::identity()] {
        let a = accumulate_normal_equations_scalar(points, &target, &t, &COST);
        let b = accumulate_normal_equations(points, 320, &target, &t, &COST);
        assert_eq!(a.total, b.total);
        // f32 and f64 may decide differently for a point exactly on a domain border.
        let slack = points.len() / 1000;
        assert!(a.valid.abs_diff(b.valid) <= slack, "{} vs {}", a.valid, b.valid);
        // Open discrepancy: at identity (the box region seen through the wrong pose) the
        // inlier counts differ by 57 of 41.8 k points (0.14 %) and the cost by 1e-4
        // relative, while H and g agree within 1e-3 — most likely points next to depth
        // edges whose depth term one kernel keeps and the other drops (not yet resolved).
        assert!(
            a.inliers.abs_diff(b.inliers) <= 5 * slack,
            "{} vs {}",
            a.inliers,
            b.inliers
        );
        let rel = |x: f64, y: f64, scale: f64| (x - y).abs() / scale.max(1e-12);
        assert!(
            rel(a.cost, b.cost, a.cost) < 1e-3,
            "cost {} vs {}",
            a.cost,
            b.cost
        );
        let hmax = a.hessian_upper.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (x, y) in a.hessian_upper.iter().zip(&b.hessian_upper) {
            assert!(rel(*x, *y, hmax) < 1e-3, "H {x} vs {y}");
        }
        let gmax = a.gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (x, y) in a.gradient.iter().zip(&b.gradient) {
            assert!(rel(*x, *y, gmax) < 1e-2, "g {x} vs {y}");
        }
    }
}

#[test]
fn unusable_points_pay_the_saturated_cost() {
    let pyr = smooth_level();
    let target = view(&pyr);
    let points = points_of(&pyr);
    // Move everything behind the camera.
    let t = se3_exp(&Twist::new(0.0, 0.0, -10.0, 0.0, 0.0, 0.0));
    let ne = accumulate_normal_equations(&points, 160, &target, &t, &COST);
    assert_eq!(ne.valid, 0);
    let expected = points.len() as f64 * f64::from(COST.saturated_point());
    assert!((ne.cost - expected).abs() < 1e-3 * expected);
    assert!(ne.hessian_upper.iter().all(|&v| v == 0.0));
}
