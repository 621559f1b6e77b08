//! ROS 2 message layouts as serde structs, (de)serialised with the `cdr` crate (plain XCDR1,
//! what rosbag2 MCAP files hold). Field order is the wire order.

use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds (signed in ROS 2).
    pub sec: i32,
    /// Nanoseconds, < 1e9.
    pub nanosec: u32,
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Acquisition time.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Image<H = Header> {
    /// Header; the ROS 1 layout differs only here ([`super::ros1::Header`]).
    pub header: H,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`rgb8`, `16UC1`, ...).
    pub encoding: String,
    /// 1 when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// Pixels.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage<H = Header> {
    /// Header; the ROS 1 layout differs only here ([`super::ros1::Header`]).
    pub header: H,
    /// `jpeg`, `png`, `rgb8; jpeg compressed bgr8`, `16UC1; compressedDepth png`, ...
    pub format: String,
    /// The compressed bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Left column.
    pub x_offset: u32,
    /// Top row.
    pub y_offset: u32,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Whether to rectify.
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo<H = Header> {
    /// Header; the ROS 1 layout differs only here ([`super::ros1::Header`]).
    pub header: H,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Distortion model name.
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major.
    pub k: [f64; 9],
    /// Rectification rotation, row-major.
    pub r: [f64; 9],
    /// Projection matrix, row-major 3×4.
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// Region of interest.
    pub roi: RegionOfInterest,
}

/// `geometry_msgs/msg/Point` and `Vector3` (same layout).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
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

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped<H = Header> {
    /// Header (frame = the frame the pose is expressed in); the ROS 1 layout differs only here ([`super::ros1::Header`]).
    pub header: H,
    /// The pose.
    pub pose: Pose,
}

/// `geometry_msgs/msg/Transform`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Child origin in the parent frame.
    pub translation: Point,
    /// Child orientation in the parent frame.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped<H = Header> {
    /// Header (frame = parent); the ROS 1 layout differs only here ([`super::ros1::Header`]).
    pub header: H,
    /// Child frame.
    pub child_frame_id: String,
    /// parent_from_child.
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage<H = Header> {
    /// The transforms.
    pub transforms: Vec<TransformStamped<H>>,
}

/// ROS 2 type names (schema names in rosbag2 MCAP files).
pub mod names {
    /// `sensor_msgs/msg/Image`.
    pub const IMAGE: &str = "sensor_msgs/msg/Image";
    /// `sensor_msgs/msg/CompressedImage`.
    pub const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
    /// `sensor_msgs/msg/CameraInfo`.
    pub const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
    /// `geometry_msgs/msg/PoseStamped`.
    pub const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";
    /// `geometry_msgs/msg/TransformStamped`.
    pub const TRANSFORM_STAMPED: &str = "geometry_msgs/msg/TransformStamped";
    /// `tf2_msgs/msg/TFMessage`.
    pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
}

/// `.msg` schema texts (top-level definition, then each dependency after a line of `=`), as
/// rosbag2 writes them; used by tests and fixtures to build realistic files.
pub mod schema_text {
    const SEP: &str = "================================================================================\n";
    const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
    const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

    /// `sensor_msgs/msg/Image`.
    pub fn image() -> String {
        format!(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n\
             uint32 step\nuint8[] data\n{SEP}{HEADER}{SEP}{TIME}"
        )
    }

    /// `sensor_msgs/msg/CompressedImage`.
    pub fn compressed_image() -> String {
        format!("std_msgs/Header header\nstring format\nuint8[] data\n{SEP}{HEADER}{SEP}{TIME}")
    }

    /// `sensor_msgs/msg/CameraInfo`.
    pub fn camera_info() -> String {
        format!(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n\
             float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n\
             sensor_msgs/RegionOfInterest roi\n{SEP}{HEADER}{SEP}{TIME}{SEP}MSG: sensor_msgs/RegionOfInterest\n\
             uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
        )
    }

    /// `geometry_msgs/msg/PoseStamped`.
    pub fn pose_stamped() -> String {
        format!(
            "std_msgs/Header header\ngeometry_msgs/Pose pose\n{SEP}{HEADER}{SEP}{TIME}{SEP}\
             MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n\
             {SEP}MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n{SEP}\
             MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
        )
    }

    /// `tf2_msgs/msg/TFMessage`.
    pub fn tf_message() -> String {
        format!(
            "geometry_msgs/TransformStamped[] transforms\n{SEP}MSG: geometry_msgs/TransformStamped\n\
             std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n{SEP}{HEADER}\
             {SEP}{TIME}{SEP}MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\n\
             geometry_msgs/Quaternion rotation\n{SEP}MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\n\
             float64 z\n{SEP}MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
        )
    }
}
