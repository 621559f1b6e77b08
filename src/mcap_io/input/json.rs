//! Foxglove well-known messages in JSON encoding (`message_encoding = "json"`, schema encoding
//! `jsonschema`): bytes as base64 strings, times as `{"sec", "nsec"}`.
//! Missing fields take their defaults, as Foxglove's own JSON reader does.

use base64::Engine as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// `{"sec": n, "nsec": n}`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct Time {
    /// Seconds.
    pub sec: u64,
    /// Nanoseconds.
    pub nsec: u64,
}

/// Bytes as a base64 string.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Base64Bytes(pub Vec<u8>);

impl Serialize for Base64Bytes {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&base64::engine::general_purpose::STANDARD.encode(&self.0))
    }
}

impl<'de> Deserialize<'de> for Base64Bytes {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        base64::engine::general_purpose::STANDARD
            .decode(text.as_bytes())
            .map(Base64Bytes)
            .map_err(|e| serde::de::Error::custom(format!("data is not valid base64: {e}")))
    }
}

/// `foxglove.RawImage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RawImage {
    /// Timestamp.
    pub timestamp: Time,
    /// Frame.
    pub frame_id: String,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Pixel encoding.
    pub encoding: String,
    /// Bytes per row.
    pub step: u32,
    /// Pixels.
    pub data: Base64Bytes,
}

/// `foxglove.CompressedImage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CompressedImage {
    /// Timestamp.
    pub timestamp: Time,
    /// Frame.
    pub frame_id: String,
    /// Compressed bytes.
    pub data: Base64Bytes,
    /// `png`, `jpeg`, ...
    pub format: String,
}

/// `foxglove.CameraCalibration` (the JSON field names are upper-case `D`, `K`, `R`, `P`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CameraCalibration {
    /// Timestamp.
    pub timestamp: Time,
    /// Frame.
    pub frame_id: String,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Distortion model.
    pub distortion_model: String,
    /// Distortion coefficients.
    #[serde(rename = "D")]
    pub d: Vec<f64>,
    /// Intrinsics, row-major.
    #[serde(rename = "K")]
    pub k: Vec<f64>,
    /// Rectification, row-major.
    #[serde(rename = "R")]
    pub r: Vec<f64>,
    /// Projection, row-major 3×4.
    #[serde(rename = "P")]
    pub p: Vec<f64>,
}

/// `foxglove.Vector3`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `foxglove.Quaternion`. A missing `w` defaults to 1 (identity), as in the schema.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Quaternion {
    /// i.
    pub x: f64,
    /// j.
    pub y: f64,
    /// k.
    pub z: f64,
    /// Real part.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `foxglove.Pose`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Pose {
    /// Position.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `foxglove.PoseInFrame`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PoseInFrame {
    /// Timestamp.
    pub timestamp: Time,
    /// Frame the pose is expressed in.
    pub frame_id: String,
    /// The pose.
    pub pose: Pose,
}

/// `foxglove.FrameTransform`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FrameTransform {
    /// Timestamp.
    pub timestamp: Time,
    /// Parent frame.
    pub parent_frame_id: String,
    /// Child frame.
    pub child_frame_id: String,
    /// Child origin in the parent.
    pub translation: Vector3,
    /// Child orientation in the parent.
    pub rotation: Quaternion,
}

/// `foxglove.FrameTransforms`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FrameTransforms {
    /// The transforms.
    pub transforms: Vec<FrameTransform>,
}
