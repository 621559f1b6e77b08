//! The Bonn RGB-D Dynamic dataset (Palazzolo, Behley, Lottes, Giguère, Stachniss, IROS 2019):
//! TUM layout, one Kinect-class calibration, and motion-capture poses of a marker body rather
//! than of the camera.
//!
//! The code published with the dataset converts a ground-truth pose T_gt into the camera's as
//! T_ros · T_gt · T_ros · T_m, with T_ros a fixed change of axes and T_m a rotation times 1.0593
//! plus a lever arm of about 2 cm. As a rigid transform that is `world_from_marker ·
//! marker_from_camera` ([`marker_from_camera`], the rotation part of T_ros · T_m) with every
//! translation divided by [`GROUND_TRUTH_SCALE`] (the motion capture's metres are 6 % larger than
//! the camera's). Checked on the "crowd" window used by the tests (people in view) by warping
//! each depth image into the frames 5 and 15 later: 41 % of the pixels land within 3 cm of the
//! depth measured there with the conversion, 25 % with the raw poses taken as the camera's.

use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use super::{DatasetKind, Sequence, TUM_DEPTH_UNITS_PER_METER};
use crate::error::Result;
use crate::geometry::PinholeIntrinsics;
use crate::trajectory::StampedPose;

/// The dataset's colour (and registered depth) intrinsics, 640×480.
/// Its lens distortion is [`crate::geometry::distortion::presets::BONN`] (`--camera bonn`).
pub const INTRINSICS: PinholeIntrinsics = crate::geometry::camera::presets::BONN;

/// Depth PNG units per metre (as TUM).
pub const DEPTH_UNITS_PER_METER: f64 = TUM_DEPTH_UNITS_PER_METER;

/// The scale of the motion capture's translations relative to the camera's (the determinant's
/// cube root of the published T_m).
pub const GROUND_TRUTH_SCALE: f64 = 1.059_290_452;

/// The camera's pose in the marker's frame: translation (m) and rotation quaternion (w, x, y, z).
const MARKER_FROM_CAMERA_T_M: [f64; 3] = [-0.0113, 0.0111, -0.0098];
const MARKER_FROM_CAMERA_Q_WXYZ: [f64; 4] = [0.063_361_38, -0.128_746_89, 0.886_642_02, -0.439_631_10];

/// The camera's pose in the marker body's frame.
pub fn marker_from_camera() -> Isometry3<f64> {
    let [w, x, y, z] = MARKER_FROM_CAMERA_Q_WXYZ;
    let [tx, ty, tz] = MARKER_FROM_CAMERA_T_M;
    Isometry3::from_parts(
        Translation3::new(tx, ty, tz),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    )
}

/// Camera poses from the dataset's ground truth (see the module docs).
pub fn camera_poses(ground_truth: &[StampedPose]) -> Vec<StampedPose> {
    let marker_from_camera = marker_from_camera();
    ground_truth
        .iter()
        .map(|p| {
            let mut world_from_camera = p.world_from_camera * marker_from_camera;
            world_from_camera.translation.vector /= GROUND_TRUTH_SCALE;
            StampedPose {
                timestamp_ns: p.timestamp_ns,
                world_from_camera,
            }
        })
        .collect()
}

/// Lists a sequence folder of the dataset (TUM layout, see [`super::tum::load`]), its ground
/// truth converted to the camera's poses ([`camera_poses`]), as [`Sequence::groundtruth`]
/// holds them for every dataset.
///
/// # Errors
/// Those of [`super::tum::load`].
pub fn load(root: &Path) -> Result<Sequence> {
    let mut sequence = super::tum::load(root, DatasetKind::Bonn)?;
    sequence.groundtruth = camera_poses(&sequence.groundtruth);
    Ok(sequence)
}

/// How [`load`] converts the ground truth, in words (for the metadata of a converted file).
pub fn groundtruth_conversion() -> String {
    format!(
        "groundtruth.txt holds the motion-capture marker's poses; /groundtruth/pose holds the camera's: \
         world_from_marker · marker_from_camera, translations divided by {GROUND_TRUTH_SCALE} (the \
         conversion published with the dataset, occmask::dataset::bonn)"
    )
}

/// Whether a folder name looks like one of the dataset's sequences (`rgbd_bonn_crowd`): a
/// `bonn` token, told apart by anything not a letter or digit.
pub fn named_like_bonn(folder_name: &str) -> bool {
    folder_name
        .split(|c: char| !c.is_ascii_alphanumeric())
        .any(|token| token.eq_ignore_ascii_case("bonn"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_conversion_is_rigid_per_pose_and_scales_the_path() {
        let a = StampedPose {
            timestamp_ns: 0,
            world_from_camera: Isometry3::translation(1.0, 2.0, 3.0),
        };
        let b = StampedPose {
            timestamp_ns: 1,
            world_from_camera: Isometry3::translation(1.0, 2.0, 3.0 + GROUND_TRUTH_SCALE),
        };
        let c = camera_poses(&[a, b]);
        // The camera moved 1 m where the motion capture says 1.0593 m (same orientation).
        let step =
            (c[1].world_from_camera.translation.vector - c[0].world_from_camera.translation.vector).norm();
        assert!((step - 1.0).abs() < 1e-9, "{step}");
        assert!((marker_from_camera().rotation.norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn folder_names_of_the_dataset_are_recognised_by_their_bonn_token() {
        for name in ["rgbd_bonn_crowd", "rgbd_bonn_balloon2", "Bonn-crowd", "bonn"] {
            assert!(named_like_bonn(name), "{name}");
        }
        for name in ["bonnet_desk", "rgbd_dataset_freiburg3_walking_xyz", "carbonn", ""] {
            assert!(!named_like_bonn(name), "{name}");
        }
    }
}
