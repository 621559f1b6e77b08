//! DVO on real Kinect data: TUM RGB-D fr2_desk, 50 frames with motion-capture ground truth
//! (`../shared/data/tum_fr2_desk_50`, CC BY 4.0). Relative pose error per consecutive pair
//! against the interpolated mocap poses, TUM evaluate_rpe composition (algorithm.md §7.2).
//!
//! The thresholds are regression bounds a little above what the default config measures
//! (README "Dense visual odometry": 2.60 mm / 0.265° RMSE; Open3D's hybrid odometry on the same
//! pairs: 2.84 mm / 0.285°). The rotation floor is the ground truth's: both methods agree with
//! each other far better than with the mocap.
#![allow(clippy::unwrap_used)] // test helpers: a panic is the failure report

#[path = "common/tum.rs"]
mod tum;

use occmask::dvo::{DvoConfig, DvoTracker};
use occmask::geometry::camera::presets;
use occmask::trajectory::{chain, to_tum_text, StampedPose};

/// RPE RMSE bounds over the window (measured 2.60 mm, 0.265°).
const MAX_RMSE_TRANS_MM: f64 = 3.0;
const MAX_RMSE_ROT_DEG: f64 = 0.30;
/// No single pair may be worse than this (measured worst 5.7 mm, 0.83°).
const MAX_PAIR_TRANS_MM: f64 = 8.0;
const MAX_PAIR_ROT_DEG: f64 = 1.0;

#[test]
fn fr2_desk_relative_pose_error_is_bounded() {
    let dir = tum::shared_data("tum_fr2_desk_50");
    let (frames, gt) = match tum::load_sequence(&dir) {
        Ok(x) => x,
        Err(e) => {
            panic!("the real-data test needs ../shared/data/tum_fr2_desk_50 beside the repository: {e}")
        }
    };
    assert_eq!(frames.len(), 50);
    let mut tracker = None;
    let (mut errs_t, mut errs_r) = (Vec::new(), Vec::new());
    let mut poses = Vec::new();
    let mut worst_cost_fraction = 0.0f64;
    for (i, f) in frames.iter().enumerate() {
        let (gray, depth) = tum::load_frame(f).unwrap();
        let tracker = tracker.get_or_insert_with(|| {
            DvoTracker::new(gray.size(), presets::TUM_FR2, DvoConfig::paper()).unwrap()
        });
        let Some(est) = tracker.track(&gray, &depth, None, None).unwrap() else {
            poses.push(StampedPose {
                timestamp_ns: f.timestamp_ns,
                world_from_camera: nalgebra::Isometry3::identity(),
            });
            continue;
        };
        assert!(est.is_converged(), "pair {}: {:?}", i - 1, est.status);
        // Final cost per point as a fraction of the saturated bi-square loss (the PoorFit check).
        let cfg = tracker.config();
        let k = cfg.k_intensity.at_level(cfg.finest_level);
        let saturated = f64::from(k * k / 6.0 + cfg.depth_weight_gamma * cfg.k_depth_m * cfg.k_depth_m / 6.0);
        worst_cost_fraction = worst_cost_fraction.max(est.final_cost / saturated);
        let last = poses[poses.len() - 1].world_from_camera;
        poses.push(StampedPose {
            timestamp_ns: f.timestamp_ns,
            world_from_camera: chain(&last, &est.current_from_reference),
        });
        let truth =
            tum::gt_motion(&gt, frames[i - 1].timestamp_ns, f.timestamp_ns).expect("GT covers the window");
        let (et, er) = tum::rpe(&est.current_from_reference, &truth);
        assert!(
            et < MAX_PAIR_TRANS_MM && er < MAX_PAIR_ROT_DEG,
            "pair {}: {et:.2} mm {er:.3} deg",
            i - 1
        );
        errs_t.push(et);
        errs_r.push(er);
    }
    let (rt, rr) = (tum::rms(errs_t.iter().copied()), tum::rms(errs_r.iter().copied()));
    println!(
        "fr2_desk_50: {} pairs, RPE RMSE {rt:.2} mm {rr:.3} deg, worst final cost {:.3} of saturated",
        errs_t.len(),
        worst_cost_fraction
    );
    assert_eq!(errs_t.len(), 49);
    assert!(rt < MAX_RMSE_TRANS_MM, "RPE translation RMSE {rt:.2} mm");
    assert!(rr < MAX_RMSE_ROT_DEG, "RPE rotation RMSE {rr:.3} deg");
    // The chained trajectory is valid TUM text with one line per frame.
    let text = to_tum_text(&poses);
    assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 50);
}
