//! Cameras named on the command line or recognised from a dataset: presets, the
//! `FX,FY,CX,CY[,distortion]` form, marker offsets and folder names.

use super::*;

/// A camera given on the command line: pinhole intrinsics and, for presets and the long
/// numeric form, the lens distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSpec {
    /// Pinhole intrinsics.
    pub intrinsics: PinholeIntrinsics,
    /// Lens distortion; `None` = pinhole.
    pub distortion: Option<LensDistortion>,
}

impl CameraSpec {
    pub(super) const fn pinhole(intrinsics: PinholeIntrinsics) -> Self {
        Self {
            intrinsics,
            distortion: None,
        }
    }
}

/// Accepted `--camera` forms, for error messages.
const CAMERA_FORMS: &str = "fr1, fr2, fr3, icsl, larr, kinect-default, bonn, fr1-distorted, fr2-distorted, \
    FX,FY,CX,CY in pixels (e.g. 520.9,521.0,325.1,249.7), or FX,FY,CX,CY followed by the \
    plumb_bob distortion K1,K2,P1,P2[,K3] or rational_polynomial K1,K2,P1,P2,K3,K4,K5,K6";

/// Parses `--camera`: a preset name ([`camera_preset`]) or `FX,FY,CX,CY` in pixels, optionally
/// followed by distortion coefficients in ROS order (4 or 5 for `plumb_bob`, 8 for
/// `rational_polynomial`).
///
/// # Errors
/// [`Error::InvalidParameter`] naming the accepted forms.
pub fn parse_camera(text: &str) -> Result<CameraSpec> {
    if let Some(preset) = camera_preset(text) {
        return Ok(preset);
    }
    let bad = || Error::InvalidParameter {
        name: "camera",
        value: text.to_owned(),
        expected: CAMERA_FORMS.into(),
    };
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    let (k, d) = values.split_at_checked(4).ok_or_else(bad)?;
    let intrinsics = PinholeIntrinsics::new(k[0], k[1], k[2], k[3]);
    if !intrinsics.is_valid() {
        return Err(bad());
    }
    let model = match d.len() {
        0 | 4 | 5 => "plumb_bob",
        8 => "rational_polynomial",
        _ => return Err(bad()),
    };
    let distortion = LensDistortion::from_ros(model, d).map_err(|_| bad())?;
    Ok(CameraSpec {
        intrinsics,
        distortion,
    })
}

/// The camera preset called `name` (case-insensitive, `freiburgN` = `frN`). `fr1` and `fr2`
/// are pinhole, as the reference implementations use TUM's images; `fr1-distorted` and
/// `fr2-distorted` add TUM's published distortion (its fr1/fr2 images are not undistorted;
/// fr3's are). `bonn` is the Bonn RGB-D Dynamic Dataset's calibration with its distortion.
pub fn camera_preset(name: &str) -> Option<CameraSpec> {
    use crate::geometry::distortion::presets as lens;
    let distorted = |intrinsics, distortion| CameraSpec {
        intrinsics,
        distortion: Some(distortion),
    };
    match name.to_ascii_lowercase().as_str() {
        "fr1" | "freiburg1" => Some(CameraSpec::pinhole(presets::TUM_FR1)),
        "fr2" | "freiburg2" => Some(CameraSpec::pinhole(presets::TUM_FR2)),
        "fr3" | "freiburg3" => Some(CameraSpec::pinhole(presets::TUM_FR3)),
        "fr1-distorted" => Some(distorted(presets::TUM_FR1, lens::TUM_FR1)),
        "fr2-distorted" => Some(distorted(presets::TUM_FR2, lens::TUM_FR2)),
        "icsl" => Some(CameraSpec::pinhole(presets::ICSL)),
        "larr" => Some(CameraSpec::pinhole(presets::LARR)),
        "bonn" => Some(distorted(presets::BONN, lens::BONN)),
        "kinect-default" | "kinect" | "default" => Some(CameraSpec::pinhole(presets::KINECT_DEFAULT)),
        _ => None,
    }
}

/// The `--camera-from-marker` preset called `name` (`bonn`), as X, Y, Z, QX, QY, QZ, QW.
/// `bonn` is [`bonn::marker_from_camera`] inverted: the rigid part of the dataset's published
/// conversion (its 6 % ground-truth scale is no rigid transform and stays out; see
/// `examples/marker_check.rs` and docs/inputs.md).
pub fn camera_from_marker_preset(name: &str) -> Option<[f64; 7]> {
    match name.to_ascii_lowercase().as_str() {
        "bonn" => {
            let camera_from_marker = bonn::marker_from_camera().inverse();
            let (t, q) = (camera_from_marker.translation.vector, camera_from_marker.rotation);
            Some([t.x, t.y, t.z, q.i, q.j, q.k, q.w])
        }
        _ => None,
    }
}

/// The TUM camera named in a folder name: `freiburgN` or an `frN` token
/// (`rgbd_dataset_freiburg2_desk`, `tum_fr2_desk_50`). Returns the preset name.
pub fn camera_from_folder_name(name: &str) -> Option<&'static str> {
    let lower = name.to_ascii_lowercase();
    for (needle, preset) in [("freiburg1", "fr1"), ("freiburg2", "fr2"), ("freiburg3", "fr3")] {
        if lower.contains(needle) {
            return Some(preset);
        }
    }
    let tokens = lower.split(|c: char| !c.is_ascii_alphanumeric());
    for token in tokens {
        match token {
            "fr1" => return Some("fr1"),
            "fr2" => return Some("fr2"),
            "fr3" => return Some("fr3"),
            _ => {}
        }
    }
    None
}
