//! Trajectory errors of estimated camera-to-world poses against ground truth.
//!
//! * [`rpe`] / [`rpe_stamped`]: relative pose error with the semantics of TUM's
//!   `evaluate_rpe.py --fixed_delta --delta_unit f` (docs/method.md, "Evaluation"): for frame pairs
//!   (i, j = i + Δ) with j < N − 1 (the script drops pairs ending on the last frame),
//!   a = P_j⁻¹·P_i, b = Q_j⁻¹·Q_i, E = a⁻¹·b; translational error ‖t(E)‖ (m), rotational error
//!   arccos(clamp((tr R(E) − 1)/2)) in degrees; RMSE over the pairs.
//! * [`ate`]: absolute trajectory error of the positions after the rigid (rotation +
//!   translation, no scale) least-squares alignment of the estimate onto the ground truth
//!   (Horn / Umeyama), RMSE in metres.

use nalgebra::{Isometry3, Matrix3, Vector3};

use crate::error::{Error, Result};
use crate::trajectory::StampedPose;

/// Relative pose error over a trajectory.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RpeStats {
    /// Number of pose pairs evaluated.
    pub pairs: usize,
    /// Root mean square translational error (m).
    pub translation_rmse_m: f64,
    /// Mean translational error (m).
    pub translation_mean_m: f64,
    /// Largest translational error (m).
    pub translation_max_m: f64,
    /// Root mean square rotational error (degrees).
    pub rotation_rmse_deg: f64,
    /// Mean rotational error (degrees).
    pub rotation_mean_deg: f64,
}

/// Absolute trajectory error after rigid alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AteStats {
    /// Number of poses.
    pub poses: usize,
    /// Root mean square position error after alignment (m).
    pub rmse_m: f64,
    /// Largest position error after alignment (m).
    pub max_m: f64,
    /// The alignment: `ground_truth_world_from_estimated_world`.
    pub alignment: Isometry3<f64>,
}

/// Translational (m) and rotational (degrees) error of one pair, TUM composition order.
fn pair_error(
    estimated_i: &Isometry3<f64>,
    estimated_j: &Isometry3<f64>,
    truth_i: &Isometry3<f64>,
    truth_j: &Isometry3<f64>,
) -> (f64, f64) {
    let a = estimated_j.inverse() * estimated_i;
    let b = truth_j.inverse() * truth_i;
    let error = a.inverse() * b;
    let rotation = error.rotation.to_rotation_matrix();
    let cos = ((rotation.matrix().trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    (error.translation.vector.norm(), cos.acos().to_degrees())
}

fn summarise(errors: &[(f64, f64)]) -> RpeStats {
    let n = errors.len().max(1) as f64;
    RpeStats {
        pairs: errors.len(),
        translation_rmse_m: (errors.iter().map(|e| e.0 * e.0).sum::<f64>() / n).sqrt(),
        translation_mean_m: errors.iter().map(|e| e.0).sum::<f64>() / n,
        translation_max_m: errors.iter().map(|e| e.0).fold(0.0, f64::max),
        rotation_rmse_deg: (errors.iter().map(|e| e.1 * e.1).sum::<f64>() / n).sqrt(),
        rotation_mean_deg: errors.iter().map(|e| e.1).sum::<f64>() / n,
    }
}

/// RPE of frame-aligned trajectories (`estimated[k]` and `truth[k]` are the same frame).
///
/// # Errors
/// [`Error::InvalidParameter`] when the lengths differ or `delta_frames` is 0.
pub fn rpe(estimated: &[Isometry3<f64>], truth: &[Isometry3<f64>], delta_frames: usize) -> Result<RpeStats> {
    if estimated.len() != truth.len() {
        return Err(Error::InvalidParameter {
            name: "trajectory lengths",
            value: format!("{} estimated vs {} ground truth", estimated.len(), truth.len()),
            expected: "one ground-truth pose per estimated pose".into(),
        });
    }
    check_delta(delta_frames)?;
    let n = estimated.len();
    let errors: Vec<(f64, f64)> = (0..n)
        .filter(|&i| i + delta_frames + 1 < n)
        .map(|i| {
            let j = i + delta_frames;
            pair_error(&estimated[i], &estimated[j], &truth[i], &truth[j])
        })
        .collect();
    Ok(summarise(&errors))
}

fn check_delta(delta_frames: usize) -> Result<()> {
    if delta_frames == 0 {
        return Err(Error::InvalidParameter {
            name: "delta_frames",
            value: "0".into(),
            expected: "at least 1 frame".into(),
        });
    }
    Ok(())
}

/// RPE of an estimated trajectory against a (possibly differently sampled) ground truth, as
/// `evaluate_rpe.py`: Δ counts estimated frames; each estimated stamp is matched to the nearest
/// ground-truth stamp, and pairs whose match is further than twice the median ground-truth
/// interval are skipped. `truth` must be sorted by time.
///
/// # Errors
/// [`Error::InvalidParameter`] when `delta_frames` is 0 or `truth` has fewer than 2 poses.
pub fn rpe_stamped(
    estimated: &[StampedPose],
    truth: &[StampedPose],
    delta_frames: usize,
) -> Result<RpeStats> {
    check_delta(delta_frames)?;
    if truth.len() < 2 {
        return Err(Error::InvalidParameter {
            name: "ground truth",
            value: format!("{} poses", truth.len()),
            expected: "at least 2 time-sorted poses".into(),
        });
    }
    let mut intervals: Vec<u64> = truth
        .windows(2)
        .map(|w| w[1].timestamp_ns.saturating_sub(w[0].timestamp_ns))
        .collect();
    intervals.sort_unstable();
    let max_gap_ns = 2 * intervals[intervals.len() / 2];
    let nearest = |t: u64| -> Option<&Isometry3<f64>> {
        let k = truth.partition_point(|p| p.timestamp_ns < t);
        let candidates = [k.checked_sub(1), (k < truth.len()).then_some(k)];
        let best = candidates
            .into_iter()
            .flatten()
            .min_by_key(|&c| truth[c].timestamp_ns.abs_diff(t))?;
        (truth[best].timestamp_ns.abs_diff(t) <= max_gap_ns).then_some(&truth[best].world_from_camera)
    };
    let n = estimated.len();
    let errors: Vec<(f64, f64)> = (0..n)
        .filter(|&i| i + delta_frames + 1 < n)
        .filter_map(|i| {
            let j = i + delta_frames;
            let truth_i = nearest(estimated[i].timestamp_ns)?;
            let truth_j = nearest(estimated[j].timestamp_ns)?;
            Some(pair_error(
                &estimated[i].world_from_camera,
                &estimated[j].world_from_camera,
                truth_i,
                truth_j,
            ))
        })
        .collect();
    Ok(summarise(&errors))
}

/// ATE of frame-aligned trajectories after rigid alignment of the estimate onto the truth.
///
/// # Errors
/// [`Error::InvalidParameter`] when the lengths differ or there are fewer than 3 poses.
pub fn ate(estimated: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Result<AteStats> {
    if estimated.len() != truth.len() || estimated.len() < 3 {
        return Err(Error::InvalidParameter {
            name: "trajectory lengths",
            value: format!("{} estimated vs {} ground truth", estimated.len(), truth.len()),
            expected: "equal lengths of at least 3 poses".into(),
        });
    }
    let n = estimated.len() as f64;
    let e: Vec<Vector3<f64>> = estimated.iter().map(|p| p.translation.vector).collect();
    let g: Vec<Vector3<f64>> = truth.iter().map(|p| p.translation.vector).collect();
    let mean_e = e.iter().sum::<Vector3<f64>>() / n;
    let mean_g = g.iter().sum::<Vector3<f64>>() / n;
    let mut covariance = Matrix3::zeros();
    for (pe, pg) in e.iter().zip(&g) {
        covariance += (pg - mean_g) * (pe - mean_e).transpose();
    }
    let svd = covariance.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(Error::InvalidParameter {
            name: "trajectory",
            value: "degenerate".into(),
            expected: "positions whose cross-covariance has an SVD".into(),
        });
    };
    // Umeyama: R = U·diag(1, 1, sign det(U Vᵀ))·Vᵀ avoids reflections.
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rotation = nalgebra::Rotation3::from_matrix_unchecked(u * d * v_t);
    let translation = mean_g - rotation * mean_e;
    let alignment = Isometry3::from_parts(
        translation.into(),
        nalgebra::UnitQuaternion::from_rotation_matrix(&rotation),
    );
    let residuals: Vec<f64> = e
        .iter()
        .zip(&g)
        .map(|(pe, pg)| (rotation * pe + translation - pg).norm())
        .collect();
    Ok(AteStats {
        poses: residuals.len(),
        rmse_m: (residuals.iter().map(|r| r * r).sum::<f64>() / n).sqrt(),
        max_m: residuals.iter().copied().fold(0.0, f64::max),
        alignment,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn circle(n: usize) -> Vec<Isometry3<f64>> {
        (0..n)
            .map(|k| {
                let t = k as f64 * 0.1;
                Isometry3::new(
                    Vector3::new(t.cos(), 0.2 * t, t.sin()),
                    Vector3::new(0.0, t * 0.3, 0.05 * t),
                )
            })
            .collect()
    }

    #[test]
    fn identical_trajectories_have_zero_error_and_rpe_is_global_frame_invariant() {
        let truth = circle(40);
        let stats = rpe(&truth, &truth, 5).unwrap();
        assert_eq!(stats.pairs, 40 - 5 - 1);
        assert!(stats.translation_rmse_m < 1e-12 && stats.rotation_rmse_deg < 1e-5);
        let moved: Vec<_> = truth
            .iter()
            .map(|p| Isometry3::new(Vector3::new(3.0, -1.0, 2.0), Vector3::new(0.3, 1.0, -0.2)) * p)
            .collect();
        let stats = rpe(&moved, &truth, 5).unwrap();
        assert!(stats.translation_rmse_m < 1e-9 && stats.rotation_rmse_deg < 1e-5);
        let ate_stats = ate(&moved, &truth).unwrap();
        assert!(ate_stats.rmse_m < 1e-9, "{ate_stats:?}");
    }

    #[test]
    fn a_constant_per_frame_drift_gives_the_expected_rpe() {
        // Estimated = truth with an extra 1 cm/frame along each frame's x axis and 0.1°/frame yaw.
        let truth = circle(30);
        let mut estimated = vec![truth[0]];
        let drift = Isometry3::new(
            Vector3::new(0.01, 0.0, 0.0),
            Vector3::new(0.0, 0.1f64.to_radians(), 0.0),
        );
        for k in 1..truth.len() {
            let step = truth[k - 1].inverse() * truth[k];
            let next = estimated[k - 1] * step * drift;
            estimated.push(next);
        }
        let stats = rpe(&estimated, &truth, 1).unwrap();
        assert!((stats.rotation_rmse_deg - 0.1).abs() < 1e-6, "{stats:?}");
        // E = a⁻¹·b = step·drift·step⁻¹ is the drift conjugated by the true step, so its
        // translation also picks up (I − R_drift)·t_step terms: ≈ 1 cm up to the step's 0.1 rad turn.
        assert!((stats.translation_rmse_m - 0.01).abs() < 5e-4, "{stats:?}");
        let ten = rpe(&estimated, &truth, 10).unwrap();
        // Ten interleaved drifts compose to ≈ 1° (the true steps rotate their axes slightly).
        assert!((ten.rotation_rmse_deg - 1.0).abs() < 1e-3, "{ten:?}");
    }

    #[test]
    fn stamped_rpe_matches_frame_rpe_and_skips_far_matches() {
        let truth = circle(30);
        let stamped = |poses: &[Isometry3<f64>]| -> Vec<StampedPose> {
            poses
                .iter()
                .enumerate()
                .map(|(k, p)| StampedPose {
                    timestamp_ns: k as u64 * 33_000_000,
                    world_from_camera: *p,
                })
                .collect()
        };
        let mut estimated = truth.clone();
        estimated[20] *= Isometry3::translation(0.05, 0.0, 0.0);
        let a = rpe(&estimated, &truth, 3).unwrap();
        let b = rpe_stamped(&stamped(&estimated), &stamped(&truth), 3).unwrap();
        assert_eq!(a.pairs, b.pairs);
        assert!((a.translation_rmse_m - b.translation_rmse_m).abs() < 1e-12);
        // Remove the ground truth around frames 10..15: pairs touching them are skipped.
        let gappy: Vec<StampedPose> = stamped(&truth)
            .into_iter()
            .enumerate()
            .filter(|(k, _)| !(10..15).contains(k))
            .map(|(_, p)| p)
            .collect();
        let c = rpe_stamped(&stamped(&estimated), &gappy, 3).unwrap();
        assert!(c.pairs < b.pairs);
        assert!(rpe(&estimated, &truth[1..], 3).is_err());
    }

    #[test]
    fn ate_undoes_a_rigid_transform_but_not_scale() {
        let truth = circle(50);
        let offset = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.5, -0.2, 0.9));
        let scaled: Vec<_> = truth
            .iter()
            .map(|p| {
                let mut q = offset * p;
                q.translation.vector *= 1.1;
                q
            })
            .collect();
        let stats = ate(&scaled, &truth).unwrap();
        assert!(stats.rmse_m > 0.01, "scale is not aligned away: {stats:?}");
        let rigid: Vec<_> = truth.iter().map(|p| offset * p).collect();
        let stats = ate(&rigid, &truth).unwrap();
        assert!(stats.rmse_m < 1e-9);
        let recovered = stats.alignment * offset;
        assert!(recovered.translation.vector.norm() < 1e-9 && recovered.rotation.angle() < 1e-9);
    }
}
