//! ROS 1 message layouts as serde structs, read with the bounded ROS 1 reader of `cdr_read`
//! (little-endian, packed, `u32`-length-prefixed strings and variable arrays, fixed arrays
//! without a length), as ROS 1 bags converted to MCAP hold them (`ros1` message encoding,
//! `ros1msg` schemas). Field order is the wire order. Geometry messages (points, quaternions,
//! poses, transforms) have the same layout as in ROS 2 and reuse [`super::ros2`]'s structs.

use serde::{Deserialize, Serialize};

use super::ros2::{Pose, Transform};

/// ROS 1 `time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds (unsigned in ROS 1).
    pub secs: u32,
    /// Nanoseconds, < 1e9.
    pub nsecs: u32,
}

/// `std_msgs/Header` (ROS 1: with a sequence number).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Sequence number.
    pub seq: u32,
    /// Acquisition time.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding.
    pub encoding: String,
    /// 1 when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// Pixels.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/CompressedImage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Header.
    pub header: Header,
    /// `jpeg`, `png`, `16UC1; compressedDepth`, ...
    pub format: String,
    /// The compressed bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/CameraInfo` (ROS 1 field names: upper-case `D`, `K`, `R`, `P`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Distortion model name.
    pub distortion_model: String,
    /// Distortion coefficients.
    #[serde(rename = "D")]
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major.
    #[serde(rename = "K")]
    pub k: [f64; 9],
    /// Rectification rotation, row-major.
    #[serde(rename = "R")]
    pub r: [f64; 9],
    /// Projection matrix, row-major 3×4.
    #[serde(rename = "P")]
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// Region of interest (same layout as ROS 2).
    pub roi: super::ros2::RegionOfInterest,
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Header.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Header (frame = parent).
    pub header: Header,
    /// Child frame.
    pub child_frame_id: String,
    /// parent_from_child.
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage` and `tf/tfMessage` (same layout).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// ROS 1 type names (schema names in MCAP files converted from ROS 1 bags).
pub mod names {
    /// `sensor_msgs/Image`.
    pub const IMAGE: &str = "sensor_msgs/Image";
    /// `sensor_msgs/CompressedImage`.
    pub const COMPRESSED_IMAGE: &str = "sensor_msgs/CompressedImage";
    /// `sensor_msgs/CameraInfo`.
    pub const CAMERA_INFO: &str = "sensor_msgs/CameraInfo";
    /// `geometry_msgs/PoseStamped`.
    pub const POSE_STAMPED: &str = "geometry_msgs/PoseStamped";
    /// `geometry_msgs/TransformStamped`.
    pub const TRANSFORM_STAMPED: &str = "geometry_msgs/TransformStamped";
    /// `tf2_msgs/TFMessage`.
    pub const TF_MESSAGE: &str = "tf2_msgs/TFMessage";
    /// `tf/tfMessage` (the older tf package; same layout).
    pub const TF_MESSAGE_LEGACY: &str = "tf/tfMessage";
}

/// `.msg` definitions as ROS 1 bags store them (top-level text, then each dependency after a
/// line of `=` and `MSG: pkg/Type`), for fixtures and the recordings occmask writes.
pub mod schema_text {
    const SEP: &str = "================================================================================\n";
    const HEADER: &str = "MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n";
    const POINT: &str = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
    const VECTOR3: &str = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
    const QUATERNION: &str = "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n";

    /// `sensor_msgs/Image`.
    pub fn image() -> String {
        format!(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n\
             uint32 step\nuint8[] data\n{SEP}{HEADER}"
        )
    }

    /// `sensor_msgs/CompressedImage`.
    pub fn compressed_image() -> String {
        format!("std_msgs/Header header\nstring format\nuint8[] data\n{SEP}{HEADER}")
    }

    /// `sensor_msgs/CameraInfo`.
    pub fn camera_info() -> String {
        format!(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] D\n\
             float64[9] K\nfloat64[9] R\nfloat64[12] P\nuint32 binning_x\nuint32 binning_y\n\
             sensor_msgs/RegionOfInterest roi\n{SEP}{HEADER}{SEP}MSG: sensor_msgs/RegionOfInterest\n\
             uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
        )
    }

    /// `geometry_msgs/PoseStamped`.
    pub fn pose_stamped() -> String {
        format!(
            "std_msgs/Header header\ngeometry_msgs/Pose pose\n{SEP}{HEADER}{SEP}MSG: geometry_msgs/Pose\n\
             geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n{SEP}{POINT}{SEP}{QUATERNION}"
        )
    }

    /// `tf2_msgs/TFMessage`.
    pub fn tf_message() -> String {
        format!(
            "geometry_msgs/TransformStamped[] transforms\n{SEP}MSG: geometry_msgs/TransformStamped\n\
             std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n{SEP}{HEADER}\
             {SEP}MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\n\
             geometry_msgs/Quaternion rotation\n{SEP}{VECTOR3}{SEP}{QUATERNION}"
        )
    }
}
