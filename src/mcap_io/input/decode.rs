//! Channel classification by schema and decoding of the supported message types into
//! flavour-independent structs ([`ImageMsg`], [`CalibrationMsg`], [`PoseSample`]), plus the
//! pixel conversions to the pipeline's [`GrayF32`] and [`DepthMeters`].

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use rayon::prelude::*;

use crate::error::{DecodeProblem, Error, ImageKind, Mismatch, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::{CameraModel, LensDistortion};
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Rgb8, LUMA_WEIGHTS_BT601};
use crate::mcap_io::codec::decode_compressed_pixels;
use crate::mcap_io::encoding::{
    ColorEncoding, ColorFormat, CompressedDepthFormat, DepthCodec, DepthEncoding,
};
pub use crate::mcap_io::encoding::{SUPPORTED_COLOR_ENCODINGS, SUPPORTED_DEPTH_ENCODINGS};
use crate::time::{checked_join_ns, join_ns};

use super::{json, pixels, ros1, ros2};

mod image_pixels;
#[cfg(test)]
mod tests;

pub use image_pixels::{depth_from_image_into, gray_from_image_into, rgb_from_image_into};

/// How a channel's messages are serialised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Flavor {
    /// Foxglove well-known schema, protobuf.
    FoxgloveProtobuf,
    /// Foxglove well-known schema, JSON.
    FoxgloveJson,
    /// ROS 2 message, CDR.
    Ros2Cdr,
    /// ROS 1 message (`ros1` encoding, `ros1msg` schema).
    Ros1,
}

/// What a channel carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MessageType {
    /// Uncompressed image (`foxglove.RawImage`, `sensor_msgs/msg/Image`).
    RawImage,
    /// Compressed image (`foxglove.CompressedImage`, `sensor_msgs/msg/CompressedImage`).
    CompressedImage,
    /// Calibration (`foxglove.CameraCalibration`, `sensor_msgs/msg/CameraInfo`).
    Calibration,
    /// `foxglove.PoseInFrame` / `geometry_msgs/msg/PoseStamped`.
    PoseInFrame,
    /// `foxglove.FrameTransform` / `geometry_msgs/msg/TransformStamped`.
    FrameTransform,
    /// `foxglove.FrameTransforms` / `tf2_msgs/msg/TFMessage`.
    FrameTransforms,
}

/// A supported channel type: flavour and message type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ChannelType {
    /// Serialisation.
    pub flavor: Flavor,
    /// Message type.
    pub message: MessageType,
}

impl ChannelType {
    /// Classifies a channel by schema name and message encoding; `None` when unsupported.
    pub fn classify(schema_name: &str, message_encoding: &str) -> Option<Self> {
        use MessageType as T;
        let (flavor, message) = match (message_encoding, schema_name) {
            ("protobuf" | "json", name) => {
                let flavor = if message_encoding == "json" {
                    Flavor::FoxgloveJson
                } else {
                    Flavor::FoxgloveProtobuf
                };
                let message = match name {
                    "foxglove.RawImage" => T::RawImage,
                    "foxglove.CompressedImage" => T::CompressedImage,
                    "foxglove.CameraCalibration" => T::Calibration,
                    "foxglove.PoseInFrame" => T::PoseInFrame,
                    "foxglove.FrameTransform" => T::FrameTransform,
                    "foxglove.FrameTransforms" => T::FrameTransforms,
                    _ => return None,
                };
                (flavor, message)
            }
            ("cdr", name) => {
                let message = match name {
                    ros2::names::IMAGE => T::RawImage,
                    ros2::names::COMPRESSED_IMAGE => T::CompressedImage,
                    ros2::names::CAMERA_INFO => T::Calibration,
                    ros2::names::POSE_STAMPED => T::PoseInFrame,
                    ros2::names::TRANSFORM_STAMPED => T::FrameTransform,
                    ros2::names::TF_MESSAGE => T::FrameTransforms,
                    _ => return None,
                };
                (Flavor::Ros2Cdr, message)
            }
            ("ros1", name) => {
                let message = match name {
                    ros1::names::IMAGE => T::RawImage,
                    ros1::names::COMPRESSED_IMAGE => T::CompressedImage,
                    ros1::names::CAMERA_INFO => T::Calibration,
                    ros1::names::POSE_STAMPED => T::PoseInFrame,
                    ros1::names::TRANSFORM_STAMPED => T::FrameTransform,
                    ros1::names::TF_MESSAGE | ros1::names::TF_MESSAGE_LEGACY => T::FrameTransforms,
                    _ => return None,
                };
                (Flavor::Ros1, message)
            }
            _ => return None,
        };
        Some(Self { flavor, message })
    }

    /// True for image channels.
    pub fn is_image(self) -> bool {
        matches!(self.message, MessageType::RawImage | MessageType::CompressedImage)
    }

    /// True for pose-carrying channels.
    pub fn is_pose(self) -> bool {
        matches!(
            self.message,
            MessageType::PoseInFrame | MessageType::FrameTransform | MessageType::FrameTransforms
        )
    }
}

/// Pixels of an image message.
#[derive(Debug, Clone, PartialEq)]
pub enum ImagePayload {
    /// Uncompressed rows.
    Raw {
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
        /// Pixel encoding (`rgb8`, `16UC1`, ...).
        encoding: String,
        /// Bytes per row.
        step: u32,
        /// Multi-byte pixels are big-endian (ROS `is_bigendian`).
        big_endian: bool,
        /// The bytes.
        data: Vec<u8>,
    },
    /// A compressed image.
    Compressed {
        /// The format string (`png`, `jpeg`, `16UC1; compressedDepth png`, ...).
        format: String,
        /// The bytes.
        data: Vec<u8>,
    },
}

/// An image message of any flavour.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageMsg {
    /// The message's own stamp (header stamp), nanoseconds.
    pub timestamp_ns: u64,
    /// Coordinate frame.
    pub frame_id: String,
    /// Pixels.
    pub payload: ImagePayload,
}

impl ImageMsg {
    /// The encoding (raw) or format (compressed) string, for messages and detection.
    pub fn encoding(&self) -> &str {
        match &self.payload {
            ImagePayload::Raw { encoding, .. } => encoding,
            ImagePayload::Compressed { format, .. } => format,
        }
    }

    /// True when the encoding is a depth encoding (`16UC1`, `mono16`, `32FC1`, compressedDepth).
    pub fn is_depth(&self) -> bool {
        match &self.payload {
            ImagePayload::Raw { encoding, .. } => encoding.parse::<DepthEncoding>().is_ok(),
            ImagePayload::Compressed { format, .. } => CompressedDepthFormat::is_compressed_depth(format),
        }
    }
}

/// A calibration of any flavour.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationMsg {
    /// Stamp, nanoseconds.
    pub timestamp_ns: u64,
    /// Frame.
    pub frame_id: String,
    /// Image size the calibration is for.
    pub size: ImageSize,
    /// K, row-major (9 numbers when well-formed).
    pub k: Vec<f64>,
    /// Distortion model name (`plumb_bob`, `rational_polynomial`, ...; may be empty).
    pub distortion_model: String,
    /// Distortion coefficients in the model's order (ROS / Foxglove `D`).
    pub d: Vec<f64>,
}

impl CalibrationMsg {
    /// Pinhole intrinsics from K.
    ///
    /// # Errors
    /// [`Error::BadIntrinsics`] naming `topic` when K is not a 3×3 pinhole matrix with positive
    /// focal lengths (a zero K means "uncalibrated" in ROS).
    pub fn intrinsics(&self, topic: &str) -> Result<PinholeIntrinsics> {
        crate::mcap_io::codec::intrinsics_from_k(&self.k, topic)
    }

    /// The lens distortion (`None` for zero coefficients).
    ///
    /// # Errors
    /// [`Error::UnsupportedDistortion`] naming `topic` for unsupported models (fisheye) with
    /// non-zero coefficients.
    pub fn distortion(&self, topic: &str) -> Result<Option<LensDistortion>> {
        LensDistortion::from_ros(&self.distortion_model, &self.d).map_err(|reason| {
            Error::UnsupportedDistortion {
                topic: topic.to_owned(),
                reason,
            }
        })
    }

    /// The camera model: size, intrinsics and distortion.
    ///
    /// # Errors
    /// As [`Self::intrinsics`] and [`Self::distortion`].
    pub fn camera_model(&self, topic: &str) -> Result<CameraModel> {
        Ok(CameraModel {
            size: self.size,
            intrinsics: self.intrinsics(topic)?,
            distortion: self.distortion(topic)?,
        })
    }
}

/// One pose sample: `parent_from_child` at a time.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseSample {
    /// Stamp, nanoseconds.
    pub timestamp_ns: u64,
    /// Frame the pose is expressed in.
    pub parent_frame: String,
    /// The frame being placed (transforms only; `None` for PoseInFrame/PoseStamped).
    pub child_frame: Option<String>,
    /// The pose.
    pub parent_from_child: Isometry3<f64>,
}

impl PoseSample {
    /// Whether the sample is of the child frame a pose stream follows: `child`, or when that is
    /// `None` the first child frame seen (which it becomes); never occmask's own estimated
    /// camera ([`crate::mcap_io::annotate::FRAME_CAMERA_ESTIMATED`]). A pose without a child
    /// frame (`PoseInFrame`, `PoseStamped`) always is.
    pub fn follows(&self, child: &mut Option<String>) -> bool {
        let Some(c) = &self.child_frame else {
            return true;
        };
        if c == crate::mcap_io::annotate::FRAME_CAMERA_ESTIMATED {
            return false;
        }
        child.get_or_insert_with(|| c.clone()) == c
    }
}

/// [`Error::Decode`] for `topic`: `expected` and `found` as a [`DecodeProblem::Value`].
pub(crate) fn bad_value(topic: &str, expected: impl Into<String>, found: impl Into<String>) -> Error {
    Error::decode(topic, DecodeProblem::Value(Mismatch::new(expected, found)))
}

/// [`Error::Decode`] for bytes that are not a `serialization` `message_type`.
fn malformed(
    topic: &str,
    serialization: &'static str,
    message_type: &'static str,
    reason: impl ToString,
) -> Error {
    Error::decode(
        topic,
        DecodeProblem::Malformed {
            serialization,
            message_type,
            reason: reason.to_string(),
        },
    )
}

fn proto<T: prost::Message + Default>(data: &[u8], topic: &str, what: &'static str) -> Result<T> {
    T::decode(data).map_err(|e| malformed(topic, "protobuf", what, e))
}

fn from_json<'a, T: serde::Deserialize<'a>>(data: &'a [u8], topic: &str, what: &'static str) -> Result<T> {
    serde_json::from_slice(data).map_err(|e| malformed(topic, "JSON", what, e))
}

fn from_cdr<T: serde::de::DeserializeOwned>(data: &[u8], topic: &str, what: &'static str) -> Result<T> {
    // Reads the 4-byte encapsulation header (little- or big-endian XCDR1), then the fields,
    // checking declared lengths against the message before allocating (cdr_read.rs).
    super::cdr_read::from_bytes::<T>(data).map_err(|e| malformed(topic, "CDR", what, e))
}

fn from_ros1<T: serde::de::DeserializeOwned>(data: &[u8], topic: &str, what: &'static str) -> Result<T> {
    super::cdr_read::from_ros1_bytes::<T>(data).map_err(|e| malformed(topic, "ROS 1", what, e))
}

fn ros1_ns(t: ros1::Time, topic: &str) -> Result<u64> {
    if t.nsecs >= 1_000_000_000 {
        return Err(bad_value(topic, "stamp nsecs < 1e9", t.nsecs.to_string()));
    }
    Ok(join_ns(u64::from(t.secs), t.nsecs))
}

fn proto_ns(stamp: Option<&foxglove::messages::Timestamp>) -> u64 {
    stamp.map_or(0, |t| join_ns(u64::from(t.sec()), t.nsec()))
}

fn json_ns(t: json::Time, topic: &str) -> Result<u64> {
    let nsec = u32::try_from(t.nsec)
        .ok()
        .filter(|&n| n < 1_000_000_000)
        .ok_or_else(|| bad_value(topic, "timestamp nsec < 1e9", t.nsec.to_string()))?;
    // JSON seconds are 64-bit: 2^64 ns is only ~584 years, so a corrupt stamp must not wrap.
    checked_join_ns(t.sec, nsec).ok_or_else(|| {
        bad_value(
            topic,
            "a timestamp below 2^64 ns (about 1.8e10 s)",
            format!("sec = {}", t.sec),
        )
    })
}

fn ros_ns(t: ros2::Time, topic: &str) -> Result<u64> {
    let sec = u64::try_from(t.sec)
        .map_err(|_| bad_value(topic, "a non-negative stamp", format!("sec = {}", t.sec)))?;
    if t.nanosec >= 1_000_000_000 {
        return Err(bad_value(topic, "stamp nanosec < 1e9", t.nanosec.to_string()));
    }
    Ok(join_ns(sec, t.nanosec))
}

/// The one part in which ROS 1 and ROS 2 messages differ: the header (ROS 1 has a sequence
/// number and an unsigned `time`). Every ROS message struct is generic over it.
trait RosHeader {
    /// The stamp in nanoseconds, checked.
    fn stamp_ns(&self, topic: &str) -> Result<u64>;
    /// The coordinate frame.
    fn into_frame_id(self) -> String;
}

impl RosHeader for ros2::Header {
    fn stamp_ns(&self, topic: &str) -> Result<u64> {
        ros_ns(self.stamp, topic)
    }
    fn into_frame_id(self) -> String {
        self.frame_id
    }
}

impl RosHeader for ros1::Header {
    fn stamp_ns(&self, topic: &str) -> Result<u64> {
        ros1_ns(self.stamp, topic)
    }
    fn into_frame_id(self) -> String {
        self.frame_id
    }
}

fn ros_image<H: RosHeader>(m: ros2::Image<H>, topic: &str) -> Result<ImageMsg> {
    Ok(ImageMsg {
        timestamp_ns: m.header.stamp_ns(topic)?,
        frame_id: m.header.into_frame_id(),
        payload: ImagePayload::Raw {
            width: m.width,
            height: m.height,
            encoding: m.encoding,
            step: m.step,
            big_endian: m.is_bigendian != 0,
            data: m.data,
        },
    })
}

fn ros_compressed_image<H: RosHeader>(m: ros2::CompressedImage<H>, topic: &str) -> Result<ImageMsg> {
    Ok(ImageMsg {
        timestamp_ns: m.header.stamp_ns(topic)?,
        frame_id: m.header.into_frame_id(),
        payload: ImagePayload::Compressed {
            format: m.format,
            data: m.data,
        },
    })
}

fn ros_calibration<H: RosHeader>(m: ros2::CameraInfo<H>, topic: &str) -> Result<CalibrationMsg> {
    Ok(CalibrationMsg {
        timestamp_ns: m.header.stamp_ns(topic)?,
        frame_id: m.header.into_frame_id(),
        size: ImageSize::new(m.width as usize, m.height as usize),
        k: m.k.to_vec(),
        distortion_model: m.distortion_model,
        d: m.d,
    })
}

fn ros_pose_stamped<H: RosHeader>(m: ros2::PoseStamped<H>, topic: &str) -> Result<PoseSample> {
    let (t, q) = (m.pose.position, m.pose.orientation);
    let iso = isometry(topic, [t.x, t.y, t.z], [q.x, q.y, q.z, q.w])?;
    Ok(PoseSample {
        timestamp_ns: m.header.stamp_ns(topic)?,
        parent_frame: m.header.into_frame_id(),
        child_frame: None,
        parent_from_child: iso,
    })
}

fn ros_transform<H: RosHeader>(m: ros2::TransformStamped<H>, topic: &str) -> Result<PoseSample> {
    let (t, q) = (m.transform.translation, m.transform.rotation);
    let iso = isometry(topic, [t.x, t.y, t.z], [q.x, q.y, q.z, q.w])?;
    Ok(PoseSample {
        timestamp_ns: m.header.stamp_ns(topic)?,
        parent_frame: m.header.into_frame_id(),
        child_frame: Some(m.child_frame_id),
        parent_from_child: iso,
    })
}

/// Decodes an image message.
///
/// # Errors
/// [`Error::Decode`] naming `topic` when the bytes are not a valid message of the type.
pub fn decode_image(ct: ChannelType, topic: &str, data: &[u8]) -> Result<ImageMsg> {
    use foxglove::messages as fm;
    match (ct.flavor, ct.message) {
        (Flavor::FoxgloveProtobuf, MessageType::RawImage) => {
            let m: fm::RawImage = proto(data, topic, "foxglove.RawImage")?;
            Ok(ImageMsg {
                timestamp_ns: proto_ns(m.timestamp.as_ref()),
                frame_id: m.frame_id,
                payload: ImagePayload::Raw {
                    width: m.width,
                    height: m.height,
                    encoding: m.encoding,
                    step: m.step,
                    big_endian: false,
                    data: m.data.to_vec(),
                },
            })
        }
        (Flavor::FoxgloveProtobuf, MessageType::CompressedImage) => {
            let m: fm::CompressedImage = proto(data, topic, "foxglove.CompressedImage")?;
            Ok(ImageMsg {
                timestamp_ns: proto_ns(m.timestamp.as_ref()),
                frame_id: m.frame_id,
                payload: ImagePayload::Compressed {
                    format: m.format,
                    data: m.data.to_vec(),
                },
            })
        }
        (Flavor::FoxgloveJson, MessageType::RawImage) => {
            let m: json::RawImage = from_json(data, topic, "foxglove.RawImage")?;
            Ok(ImageMsg {
                timestamp_ns: json_ns(m.timestamp, topic)?,
                frame_id: m.frame_id,
                payload: ImagePayload::Raw {
                    width: m.width,
                    height: m.height,
                    encoding: m.encoding,
                    step: m.step,
                    big_endian: false,
                    data: m.data.0,
                },
            })
        }
        (Flavor::FoxgloveJson, MessageType::CompressedImage) => {
            let m: json::CompressedImage = from_json(data, topic, "foxglove.CompressedImage")?;
            Ok(ImageMsg {
                timestamp_ns: json_ns(m.timestamp, topic)?,
                frame_id: m.frame_id,
                payload: ImagePayload::Compressed {
                    format: m.format,
                    data: m.data.0,
                },
            })
        }
        (Flavor::Ros2Cdr, MessageType::RawImage) => {
            ros_image(from_cdr::<ros2::Image>(data, topic, ros2::names::IMAGE)?, topic)
        }
        (Flavor::Ros2Cdr, MessageType::CompressedImage) => ros_compressed_image(
            from_cdr::<ros2::CompressedImage>(data, topic, ros2::names::COMPRESSED_IMAGE)?,
            topic,
        ),
        (Flavor::Ros1, MessageType::RawImage) => {
            ros_image(from_ros1::<ros1::Image>(data, topic, ros1::names::IMAGE)?, topic)
        }
        (Flavor::Ros1, MessageType::CompressedImage) => ros_compressed_image(
            from_ros1::<ros1::CompressedImage>(data, topic, ros1::names::COMPRESSED_IMAGE)?,
            topic,
        ),
        _ => Err(wrong_channel(topic, "an image channel", ct)),
    }
}

/// Decodes a calibration message.
///
/// # Errors
/// [`Error::Decode`] naming `topic` when the bytes are not a valid calibration.
pub fn decode_calibration(ct: ChannelType, topic: &str, data: &[u8]) -> Result<CalibrationMsg> {
    match (ct.flavor, ct.message) {
        (Flavor::FoxgloveProtobuf, MessageType::Calibration) => {
            let m: foxglove::messages::CameraCalibration = proto(data, topic, "foxglove.CameraCalibration")?;
            Ok(CalibrationMsg {
                timestamp_ns: proto_ns(m.timestamp.as_ref()),
                frame_id: m.frame_id,
                size: ImageSize::new(m.width as usize, m.height as usize),
                k: m.k,
                distortion_model: m.distortion_model,
                d: m.d,
            })
        }
        (Flavor::FoxgloveJson, MessageType::Calibration) => {
            let m: json::CameraCalibration = from_json(data, topic, "foxglove.CameraCalibration")?;
            Ok(CalibrationMsg {
                timestamp_ns: json_ns(m.timestamp, topic)?,
                frame_id: m.frame_id,
                size: ImageSize::new(m.width as usize, m.height as usize),
                k: m.k,
                distortion_model: m.distortion_model,
                d: m.d,
            })
        }
        (Flavor::Ros2Cdr, MessageType::Calibration) => ros_calibration(
            from_cdr::<ros2::CameraInfo>(data, topic, ros2::names::CAMERA_INFO)?,
            topic,
        ),
        (Flavor::Ros1, MessageType::Calibration) => ros_calibration(
            from_ros1::<ros1::CameraInfo>(data, topic, ros1::names::CAMERA_INFO)?,
            topic,
        ),
        _ => Err(wrong_channel(topic, "a calibration channel", ct)),
    }
}

fn isometry(topic: &str, t: [f64; 3], q: [f64; 4]) -> Result<Isometry3<f64>> {
    let [x, y, z, w] = q;
    let quaternion = nalgebra::Quaternion::new(w, x, y, z);
    let norm = quaternion.norm();
    // Recorders write quaternions normalised to f32 or f64 precision; anything further off
    // than this is a wrong field, not rounding.
    const MAX_QUATERNION_NORM_ERROR: f64 = 1e-3;
    if !t.iter().all(|v| v.is_finite()) || !norm.is_finite() || (norm - 1.0).abs() > MAX_QUATERNION_NORM_ERROR
    {
        return Err(bad_value(
            topic,
            "a finite translation and a unit quaternion",
            format!("t = {t:?}, q (x,y,z,w) = {q:?}"),
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_quaternion(quaternion),
    ))
}

fn proto_pose(
    topic: &str,
    p: Option<&foxglove::messages::Vector3>,
    q: Option<&foxglove::messages::Quaternion>,
) -> Result<Isometry3<f64>> {
    let t = p.map_or([0.0; 3], |p| [p.x, p.y, p.z]);
    let q = q.map_or([0.0, 0.0, 0.0, 1.0], |q| [q.x, q.y, q.z, q.w]);
    isometry(topic, t, q)
}

/// Decodes a pose-carrying message into its samples (one, or several for transform lists).
///
/// # Errors
/// [`Error::Decode`] naming `topic` for invalid bytes, non-finite values or non-unit quaternions.
pub fn decode_poses(ct: ChannelType, topic: &str, data: &[u8]) -> Result<Vec<PoseSample>> {
    use foxglove::messages as fm;
    let sample = |timestamp_ns, parent: String, child: Option<String>, iso| PoseSample {
        timestamp_ns,
        parent_frame: parent,
        child_frame: child,
        parent_from_child: iso,
    };
    let proto_tf = |m: fm::FrameTransform| -> Result<PoseSample> {
        let iso = proto_pose(topic, m.translation.as_ref(), m.rotation.as_ref())?;
        Ok(sample(
            proto_ns(m.timestamp.as_ref()),
            m.parent_frame_id,
            Some(m.child_frame_id),
            iso,
        ))
    };
    let json_tf = |m: json::FrameTransform| -> Result<PoseSample> {
        let (t, q) = (m.translation, m.rotation);
        let iso = isometry(topic, [t.x, t.y, t.z], [q.x, q.y, q.z, q.w])?;
        Ok(sample(
            json_ns(m.timestamp, topic)?,
            m.parent_frame_id,
            Some(m.child_frame_id),
            iso,
        ))
    };
    match (ct.flavor, ct.message) {
        (Flavor::Ros1, MessageType::PoseInFrame) => Ok(vec![ros_pose_stamped(
            from_ros1::<ros1::PoseStamped>(data, topic, ros1::names::POSE_STAMPED)?,
            topic,
        )?]),
        (Flavor::Ros1, MessageType::FrameTransform) => Ok(vec![ros_transform(
            from_ros1::<ros1::TransformStamped>(data, topic, ros1::names::TRANSFORM_STAMPED)?,
            topic,
        )?]),
        (Flavor::Ros1, MessageType::FrameTransforms) => {
            let m: ros1::TfMessage = from_ros1(data, topic, ros1::names::TF_MESSAGE)?;
            m.transforms
                .into_iter()
                .map(|t| ros_transform(t, topic))
                .collect()
        }
        (Flavor::FoxgloveProtobuf, MessageType::PoseInFrame) => {
            let m: fm::PoseInFrame = proto(data, topic, "foxglove.PoseInFrame")?;
            let pose = m.pose.unwrap_or_default();
            let iso = proto_pose(topic, pose.position.as_ref(), pose.orientation.as_ref())?;
            Ok(vec![sample(
                proto_ns(m.timestamp.as_ref()),
                m.frame_id,
                None,
                iso,
            )])
        }
        (Flavor::FoxgloveProtobuf, MessageType::FrameTransform) => {
            Ok(vec![proto_tf(proto(data, topic, "foxglove.FrameTransform")?)?])
        }
        (Flavor::FoxgloveProtobuf, MessageType::FrameTransforms) => {
            let m: fm::FrameTransforms = proto(data, topic, "foxglove.FrameTransforms")?;
            m.transforms.into_iter().map(proto_tf).collect()
        }
        (Flavor::FoxgloveJson, MessageType::PoseInFrame) => {
            let m: json::PoseInFrame = from_json(data, topic, "foxglove.PoseInFrame")?;
            let (t, q) = (m.pose.position, m.pose.orientation);
            let iso = isometry(topic, [t.x, t.y, t.z], [q.x, q.y, q.z, q.w])?;
            Ok(vec![sample(json_ns(m.timestamp, topic)?, m.frame_id, None, iso)])
        }
        (Flavor::FoxgloveJson, MessageType::FrameTransform) => {
            Ok(vec![json_tf(from_json(data, topic, "foxglove.FrameTransform")?)?])
        }
        (Flavor::FoxgloveJson, MessageType::FrameTransforms) => {
            let m: json::FrameTransforms = from_json(data, topic, "foxglove.FrameTransforms")?;
            m.transforms.into_iter().map(json_tf).collect()
        }
        (Flavor::Ros2Cdr, MessageType::PoseInFrame) => Ok(vec![ros_pose_stamped(
            from_cdr::<ros2::PoseStamped>(data, topic, ros2::names::POSE_STAMPED)?,
            topic,
        )?]),
        (Flavor::Ros2Cdr, MessageType::FrameTransform) => Ok(vec![ros_transform(
            from_cdr::<ros2::TransformStamped>(data, topic, ros2::names::TRANSFORM_STAMPED)?,
            topic,
        )?]),
        (Flavor::Ros2Cdr, MessageType::FrameTransforms) => {
            let m: ros2::TfMessage = from_cdr(data, topic, ros2::names::TF_MESSAGE)?;
            m.transforms
                .into_iter()
                .map(|t| ros_transform(t, topic))
                .collect()
        }
        _ => Err(wrong_channel(topic, "a pose or transform channel", ct)),
    }
}

/// [`Error::Decode`] for a channel whose message type is not the `expected` one.
fn wrong_channel(topic: &str, expected: &str, ct: ChannelType) -> Error {
    Error::decode(
        topic,
        DecodeProblem::Schema(Mismatch::new(expected, format!("{:?}", ct.message))),
    )
}

/// What [`unsupported_schema`] says an image channel needs.
pub(crate) const IMAGE_SCHEMA: &str = "an image schema";
/// What [`unsupported_schema`] says a pose channel needs.
pub(crate) const POSE_SCHEMA: &str = "a pose schema";

/// [`Error::Decode`] for a channel whose schema cannot be decoded as `expected` at all.
pub(crate) fn unsupported_schema(channel: &super::InputChannel, expected: &str) -> Error {
    Error::decode(
        channel.topic.clone(),
        DecodeProblem::Schema(Mismatch::new(
            expected,
            format!("schema {:?}", channel.schema_name),
        )),
    )
}

fn unsupported(topic: &str, image: ImageKind, found: &str, supported: &'static str) -> Error {
    Error::decode(
        topic,
        DecodeProblem::UnsupportedEncoding {
            image,
            found: found.to_owned(),
            supported,
        },
    )
}

/// Encodes a message to protobuf bytes (helper for fixtures and tests).
pub fn protobuf_bytes<M: prost::Message>(msg: &M) -> Vec<u8> {
    msg.encode_to_vec()
}

/// Every pose of a pose channel (`PoseInFrame`, `PoseStamped`, transforms: each sample's
/// `parent_from_child` as `world_from_camera`), sorted by time, one per timestamp; empty when
/// the file has no channel `topic`. Of a transform channel, the poses of one child frame
/// ([`PoseSample::follows`]), as `process --pose-topic` takes them.
///
/// # Errors
/// [`Error::Decode`] when the channel's schema is not a pose schema or a message does not decode.
pub fn read_poses(input: &super::McapInput, topic: &str) -> Result<Vec<crate::trajectory::StampedPose>> {
    let Some(channel) = input.channel_by_topic(topic) else {
        return Ok(Vec::new());
    };
    let Some(ct) = channel.channel_type.filter(|ct| ct.is_pose()) else {
        return Err(unsupported_schema(channel, POSE_SCHEMA));
    };
    let topics = [topic.to_owned()];
    let read = |time_range| {
        let mut samples = Vec::new();
        input.for_each_message(Some(&topics), time_range, |m| {
            samples.extend(decode_poses(ct, topic, &m.data)?);
            Ok(true)
        })?;
        Ok(samples)
    };
    // A pose stream is spread over the whole file: every chunk is decompressed for it. The
    // parts of the file are read side by side (on the caller's rayon pool) and joined in order.
    let parts: Vec<Result<Vec<PoseSample>>> = input
        .log_time_parts(rayon::current_num_threads())
        .into_par_iter()
        .map(read)
        .collect();
    let mut samples = Vec::new();
    for part in parts {
        samples.extend(part?);
    }
    let mut child = None;
    let mut poses: Vec<_> = samples
        .into_iter()
        .filter(|s| s.follows(&mut child))
        .map(|s| crate::trajectory::StampedPose {
            timestamp_ns: s.timestamp_ns,
            world_from_camera: s.parent_from_child,
        })
        .collect();
    poses.sort_by_key(|p| p.timestamp_ns);
    poses.dedup_by_key(|p| p.timestamp_ns);
    Ok(poses)
}
