//! Reading and writing occmask's MCAP files.
//!
//! Every message uses a Foxglove well-known schema with protobuf encoding (the message structs
//! and embedded descriptors of the `foxglove` crate), written through [`mcap::Writer`].
//! The topic and frame names below are the contract between
//! `occmask convert`, `occmask process` and the viewer; docs/channels.md lists them.
//!
//! - [`codec`]: sans-IO conversion between library types and Foxglove messages;
//! - [`encoding`]: the image encodings ([`encoding::ColorEncoding`], [`encoding::DepthEncoding`],
//!   compressed formats) parsed from and written as their ROS / Foxglove strings;
//! - [`writer`]: [`RgbdMcapWriter`], which registers schemas and channels once and writes
//!   messages in the order it is given (callers merge their streams by time);
//! - [`input`]: [`input::McapInput`], the one reader, for any RGB-D MCAP file (occmask's own
//!   included);
//! - [`output`]: [`AtomicOutput`], the temporary-file-then-rename helper every command uses;
//! - [`ros_out`]: [`ros_out::RosMcapWriter`], recordings in ROS 1 / ROS 2 conventions (synthetic
//!   recordings and fixtures).

pub mod annotate;
pub mod codec;
pub mod encoding;
pub mod input;
pub mod output;
pub mod ros_out;
pub mod writer;

pub use crate::contour::ContourOptions;
pub use codec::ColorFormat;
pub use output::{names_folder, AtomicOutput, OutputFile};
pub use writer::{Compression, McapWriteOptions, RgbdMcapWriter};

/// Colour images as the original PNG/JPEG bytes (`foxglove.CompressedImage`) or decoded `rgb8`
/// (`foxglove.RawImage`).
pub const TOPIC_COLOR_IMAGE: &str = "/camera/rgb/image";
/// Calibration of the colour camera, one per colour image with the same timestamp.
pub const TOPIC_COLOR_CAMERA_INFO: &str = "/camera/rgb/camera_info";
/// Depth images, `foxglove.RawImage` `16UC1` in native sensor units (see [`DEPTH_UNITS_KEY`]).
pub const TOPIC_DEPTH_IMAGE: &str = "/camera/depth/image";
/// Calibration of the depth image, one per depth image with the same timestamp.
pub const TOPIC_DEPTH_CAMERA_INFO: &str = "/camera/depth/camera_info";
/// Ground-truth camera poses (`foxglove.PoseInFrame`, frame [`FRAME_WORLD`]).
pub const TOPIC_GROUNDTRUTH_POSE: &str = "/groundtruth/pose";
/// Transforms (`foxglove.FrameTransform`), e.g. [`FRAME_WORLD`] → [`FRAME_CAMERA_GROUNDTRUTH`].
pub const TOPIC_TF: &str = "/tf";
/// Ground-truth moving-object masks (`foxglove.RawImage` `mono8`, 255 = moving), LARR only.
pub const TOPIC_GROUNDTRUTH_MASK: &str = "/groundtruth/mask";

/// Optical frame of the colour camera (+x right, +y down, +z forward). TUM and LARR depth is
/// registered to colour, so depth images use this frame too.
pub const FRAME_CAMERA_OPTICAL: &str = "camera_rgb_optical";
/// The ground-truth (motion-capture) world frame.
pub const FRAME_WORLD: &str = "world";
/// The camera as placed by the ground-truth trajectory.
pub const FRAME_CAMERA_GROUNDTRUTH: &str = "camera_groundtruth";

/// Schema name of `foxglove.CompressedImage`.
pub const SCHEMA_COMPRESSED_IMAGE: &str = "foxglove.CompressedImage";
/// Schema name of `foxglove.RawImage`.
pub const SCHEMA_RAW_IMAGE: &str = "foxglove.RawImage";
/// Schema name of `foxglove.CameraCalibration`.
pub const SCHEMA_CAMERA_CALIBRATION: &str = "foxglove.CameraCalibration";
/// Schema name of `foxglove.PoseInFrame`.
pub const SCHEMA_POSE_IN_FRAME: &str = "foxglove.PoseInFrame";
/// Schema name of `foxglove.FrameTransform`.
pub const SCHEMA_FRAME_TRANSFORM: &str = "foxglove.FrameTransform";
/// Message and schema encoding of every channel we write.
pub const ENCODING_PROTOBUF: &str = "protobuf";

/// Channel-metadata key on depth channels: raw depth units per metre, as decimal text
/// (`"5000"` for TUM, `"1000"` for LARR/ICSL millimetres).
pub const DEPTH_UNITS_KEY: &str = "depth_units_per_meter";

/// Name of the metadata record `occmask convert` writes (dataset, intrinsics, options).
pub const METADATA_CONVERT: &str = "occmask.convert";

/// The `library` string written into the MCAP header: fixed (no build date, no host) so the
/// same input and options give byte-identical files.
pub const LIBRARY: &str = concat!("occmask/", env!("CARGO_PKG_VERSION"));

#[cfg(test)]
mod tests {
    use super::*;
    use foxglove::messages::{CameraCalibration, CompressedImage, FrameTransform, PoseInFrame, RawImage};
    use foxglove::Encode;

    fn schema_name<T: Encode>() -> String {
        T::get_schema().map(|s| s.name).unwrap_or_default()
    }

    #[test]
    fn schema_consts_match_the_foxglove_crate() {
        assert_eq!(schema_name::<CompressedImage>(), SCHEMA_COMPRESSED_IMAGE);
        assert_eq!(schema_name::<RawImage>(), SCHEMA_RAW_IMAGE);
        assert_eq!(schema_name::<CameraCalibration>(), SCHEMA_CAMERA_CALIBRATION);
        assert_eq!(schema_name::<PoseInFrame>(), SCHEMA_POSE_IN_FRAME);
        assert_eq!(schema_name::<FrameTransform>(), SCHEMA_FRAME_TRANSFORM);
        assert_eq!(RawImage::get_message_encoding(), ENCODING_PROTOBUF);
    }
}
