//! ROS 1 message layouts as serde structs, read with the bounded ROS 1 reader of `cdr_read`
//! (little-endian, packed, `u32`-length-prefixed strings and variable arrays, fixed arrays
//! without a length), as ROS 1 bags converted to MCAP hold them (`ros1` message encoding,
//! `ros1msg` schemas). Field order is the wire order. Only the header differs from ROS 2
//! (a sequence number, an unsigned `time`), so every message is [`super::ros2`]'s struct with
//! this module's [`Header`].

use serde::{Deserialize, Serialize};

use super::ros2;

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
pub type Image = ros2::Image<Header>;
/// `sensor_msgs/CompressedImage`.
pub type CompressedImage = ros2::CompressedImage<Header>;
/// `sensor_msgs/CameraInfo` (ROS 1 names the matrices upper-case `D`, `K`, `R`, `P`; the
/// wire layout is ROS 2's).
pub type CameraInfo = ros2::CameraInfo<Header>;
/// `geometry_msgs/PoseStamped`.
pub type PoseStamped = ros2::PoseStamped<Header>;
/// `geometry_msgs/TransformStamped`.
pub type TransformStamped = ros2::TransformStamped<Header>;
/// `tf2_msgs/TFMessage` and `tf/tfMessage` (same layout).
pub type TfMessage = ros2::TfMessage<Header>;

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
