//! DVO on real Kinect data: TUM RGB-D fr2_desk with motion-capture ground truth (CC BY 4.0).
//! Relative pose error per consecutive pair against the interpolated mocap poses, composed as
//! TUM's `evaluate_rpe` (docs/method.md, "Evaluation").
//!
//! Two sequences: the 10-frame excerpt committed in `fixtures/` (always run) and the 50-frame
//! window of the real-data folder (`OCCMASK_DATA`, skipped with a notice when absent). The
//! bounds are regression bounds a stated margin above what the default config measures (the
//! figures are in docs/accuracy.md, made by tools/accuracy.sh). The rotation floor is the
//! ground truth's: DVO and Open3D agree with each other far better than with the mocap.
#![allow(clippy::unwrap_used)] // test helpers: a panic is the failure report

use crate::common::tum;

use crate::common::data;

use std::path::Path;

use occmask::dvo::{DvoConfig, DvoTracker};
use occmask::geometry::camera::presets;
use occmask::trajectory::{chain, to_tum_text, StampedPose};

/// Regression bounds of one sequence.
struct Bounds {
    frames: usize,
    /// RPE RMSE over the sequence.
    rmse_trans_mm: f64,
    rmse_rot_deg: f64,
    /// No single pair may be worse than this.
    pair_trans_mm: f64,
    pair_rot_deg: f64,
}

/// The 50-frame window: measured 2.60 mm, 0.265° RMSE, worst pair 5.7 mm, 0.83°.
const DESK_50: Bounds = Bounds {
    frames: 50,
    rmse_trans_mm: 3.0,
    rmse_rot_deg: 0.30,
    pair_trans_mm: 8.0,
    pair_rot_deg: 1.0,
};

/// The 10-frame excerpt (the first 10 frames of the window): measured 1.93 mm, 0.368° RMSE,
/// worst pair 2.88 mm, 0.828° (its rotation RMSE is above the window's: 9 pairs, one of them
/// the ground truth's glitch at frame 5). Bounds 20–30 % above.
const DESK_10: Bounds = Bounds {
    frames: data::TUM_FIXTURE_FRAMES,
    rmse_trans_mm: 2.5,
    rmse_rot_deg: 0.45,
    pair_trans_mm: 3.5,
    pair_rot_deg: 1.0,
};

#[test]
fn fr2_desk_excerpt_relative_pose_error_is_bounded() {
    check_sequence("tum_fr2_desk_10", &data::tum_fixture(), &DESK_10);
}

#[test]
fn fr2_desk_50_relative_pose_error_is_bounded() {
    let Some(dir) = data::real_data(
        "tum_fr2_desk_50",
        "dvo_tum::fr2_desk_50_relative_pose_error_is_bounded",
    ) else {
        return;
    };
    check_sequence("tum_fr2_desk_50", &dir, &DESK_50);
}

fn check_sequence(name: &str, dir: &Path, bounds: &Bounds) {
    let sequence = tum::TumSequence::load(dir).unwrap_or_else(|e| panic!("{name}: {e}"));
    let gt = sequence.groundtruth();
    assert_eq!(sequence.pairs.len(), bounds.frames);
    let mut tracker = None;
    let (mut errs_t, mut errs_r) = (Vec::new(), Vec::new());
    let mut poses = Vec::new();
    let mut worst_cost_fraction = 0.0f64;
    let mut worst_pair = (0.0f64, 0.0f64);
    let mut previous_ns = 0;
    for i in 0..sequence.pairs.len() {
        let f = sequence.frame(i).unwrap();
        let reference_ns = std::mem::replace(&mut previous_ns, f.timestamp_ns);
        let tracker = tracker.get_or_insert_with(|| {
            DvoTracker::new(f.gray.size(), presets::TUM_FR2, DvoConfig::paper()).unwrap()
        });
        let Some(est) = tracker.track(&f.gray, &f.depth_m, None, None).unwrap() else {
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
        let truth = tum::gt_motion(gt, reference_ns, f.timestamp_ns).expect("GT covers the window");
        let (et, er) = tum::rpe(&est.current_from_reference, &truth);
        assert!(
            et < bounds.pair_trans_mm && er < bounds.pair_rot_deg,
            "{name} pair {}: {et:.2} mm {er:.3} deg",
            i - 1
        );
        errs_t.push(et);
        errs_r.push(er);
        worst_pair = (worst_pair.0.max(et), worst_pair.1.max(er));
    }
    let (rt, rr) = (tum::rms(errs_t.iter().copied()), tum::rms(errs_r.iter().copied()));
    println!(
        "{name}: {} pairs, RPE RMSE {rt:.2} mm {rr:.3} deg, worst pair {:.2} mm {:.3} deg, worst final cost {:.3} of saturated",
        errs_t.len(),
        worst_pair.0,
        worst_pair.1,
        worst_cost_fraction
    );
    assert_eq!(errs_t.len(), bounds.frames - 1);
    assert!(
        rt < bounds.rmse_trans_mm,
        "{name}: RPE translation RMSE {rt:.2} mm"
    );
    assert!(rr < bounds.rmse_rot_deg, "{name}: RPE rotation RMSE {rr:.3} deg");
    // The chained trajectory is valid TUM text with one line per frame.
    let text = to_tum_text(&poses);
    assert_eq!(
        text.lines().filter(|l| !l.starts_with('#')).count(),
        bounds.frames
    );
}
