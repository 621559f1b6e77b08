//! Channel classification by schema and decoding of the supported message types into
//! flavour-independent structs ([`ImageMsg`], [`CalibrationMsg`], [`PoseSample`]), plus the
//! pixel conversions to the pipeline's [`GrayF32`] and [`DepthMeters`].

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use crate::error::{Error, Result};
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

pub(crate) fn decode_error(topic: &str, message: impl Into<String>) -> Error {
    Error::Decode {
        topic: topic.to_owned(),
        message: message.into(),
    }
}

fn proto<T: prost::Message + Default>(data: &[u8], topic: &str, what: &str) -> Result<T> {
    T::decode(data).map_err(|e| decode_error(topic, format!("expected a protobuf {what}: {e}")))
}

fn from_json<'a, T: serde::Deserialize<'a>>(data: &'a [u8], topic: &str, what: &str) -> Result<T> {
    serde_json::from_slice(data).map_err(|e| decode_error(topic, format!("expected a JSON {what}: {e}")))
}

fn from_cdr<T: serde::de::DeserializeOwned>(data: &[u8], topic: &str, what: &str) -> Result<T> {
    // Reads the 4-byte encapsulation header (little- or big-endian XCDR1), then the fields,
    // checking declared lengths against the message before allocating (cdr_read.rs).
    super::cdr_read::from_bytes::<T>(data)
        .map_err(|e| decode_error(topic, format!("expected a CDR {what}: {e}")))
}

fn from_ros1<T: serde::de::DeserializeOwned>(data: &[u8], topic: &str, what: &str) -> Result<T> {
    super::cdr_read::from_ros1_bytes::<T>(data)
        .map_err(|e| decode_error(topic, format!("expected a ROS 1 {what}: {e}")))
}

fn ros1_ns(t: ros1::Time, topic: &str) -> Result<u64> {
    if t.nsecs >= 1_000_000_000 {
        return Err(decode_error(
            topic,
            format!("expected stamp nsecs < 1e9, found {}", t.nsecs),
        ));
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
        .ok_or_else(|| decode_error(topic, format!("expected timestamp nsec < 1e9, found {}", t.nsec)))?;
    // JSON seconds are 64-bit: 2^64 ns is only ~584 years, so a corrupt stamp must not wrap.
    checked_join_ns(t.sec, nsec).ok_or_else(|| {
        decode_error(
            topic,
            format!(
                "expected a timestamp below 2^64 ns (about 1.8e10 s), found sec = {}",
                t.sec
            ),
        )
    })
}

fn ros_ns(t: ros2::Time, topic: &str) -> Result<u64> {
    let sec = u64::try_from(t.sec).map_err(|_| {
        decode_error(
            topic,
            format!("expected a non-negative stamp, found sec = {}", t.sec),
        )
    })?;
    if t.nanosec >= 1_000_000_000 {
        return Err(decode_error(
            topic,
            format!("expected stamp nanosec < 1e9, found {}", t.nanosec),
        ));
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
        _ => Err(decode_error(
            topic,
            format!("expected an image channel, found {:?}", ct.message),
        )),
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
        _ => Err(decode_error(
            topic,
            format!("expected a calibration channel, found {:?}", ct.message),
        )),
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
        return Err(decode_error(
            topic,
            format!(
                "expected a finite translation and a unit quaternion, found t = {t:?}, q (x,y,z,w) = {q:?}"
            ),
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
        _ => Err(decode_error(
            topic,
            format!("expected a pose or transform channel, found {:?}", ct.message),
        )),
    }
}

/// Header bytes `compressed_depth_image_transport` puts before the PNG of a 16-bit depth
/// image (format enum + two float quantisation parameters).
const COMPRESSED_DEPTH_HEADER_BYTES: usize = 12;

fn unsupported(topic: &str, what: &str, found: &str, supported: &str) -> Error {
    decode_error(
        topic,
        format!("unsupported {what} encoding {found:?}: supported are {supported}"),
    )
}

/// Checks row step and data length of a raw image; returns its size.
fn raw_rows(topic: &str, width: u32, height: u32, step: u32, bpp: usize, len: usize) -> Result<ImageSize> {
    let size = ImageSize::new(width as usize, height as usize);
    if size.area() == 0 {
        // A 0×N image would pass the length checks with no data and loop over N empty rows.
        return Err(decode_error(
            topic,
            format!("image is {size}: expected at least one pixel"),
        ));
    }
    let row_bytes = size.width * bpp;
    let step = step as usize;
    if step < row_bytes {
        return Err(decode_error(
            topic,
            format!(
                "image step {step} is shorter than a {}-pixel row of {row_bytes} bytes",
                size.width
            ),
        ));
    }
    let needed = if size.height == 0 {
        0
    } else {
        step * (size.height - 1) + row_bytes
    };
    // The data is `height` rows of `step` bytes; writers that trim the last row's padding are
    // accepted too. Anything else means width, height, step or encoding disagree with the data
    // (e.g. 32-bit float depth declared as 16UC1).
    let full = step * size.height;
    if len != needed && len != full {
        let expected = if needed == full {
            format!("{needed}")
        } else {
            format!("{needed} or {full}")
        };
        return Err(decode_error(
            topic,
            format!(
                "image {size} with step {step} and {bpp} bytes per pixel needs {expected} bytes, found {len} \
                 (width, height, step or encoding disagree with the data)"
            ),
        ));
    }
    if size.area() == 0 {
        return Err(decode_error(
            topic,
            format!("expected an image with at least one pixel, found {size}"),
        ));
    }
    Ok(size)
}

fn resize_for<T: Copy + Default>(image: &mut crate::image_buf::Image<T>, size: ImageSize) {
    if image.size() != size {
        *image = crate::image_buf::Image::filled(size, T::default());
    }
}

/// Decodes a colour (or grey) image into `gray` (0..1, BT.601 luma, the same weights as
/// [`crate::image_buf::gray_from_rgb8`]), resizing `gray` when the size differs.
///
/// # Errors
/// [`Error::Decode`] naming `topic` for unsupported encodings (listing the supported ones),
/// short buffers or undecodable PNG/JPEG.
pub fn gray_from_image_into(msg: &ImageMsg, topic: &str, gray: &mut GrayF32) -> Result<()> {
    let [wr, wg, wb] = LUMA_WEIGHTS_BT601.map(|w| w / 255.0);
    match &msg.payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            step,
            data,
            ..
        } => {
            let (color, size) = raw_color(topic, *width, *height, encoding, *step, data)?;
            let bpp = color.bytes_per_pixel();
            resize_for(gray, size);
            let step = *step as usize;
            let row = |y: usize| &data[y * step..y * step + size.width * bpp];
            // Offsets of r, g, b in an interleaved pixel.
            let rgb_offsets = match color {
                ColorEncoding::Uyvy | ColorEncoding::Yuyv => {
                    // Packed 4:2:2: two bytes per pixel, the luma is the grey.
                    let uyvy = color == ColorEncoding::Uyvy;
                    for y in 0..size.height {
                        let row = row(y);
                        for (x, out) in gray.row_mut(y).iter_mut().enumerate() {
                            *out = pixels::gray_from_video_luma(row[pixels::yuv422_luma_offset(x, uyvy)]);
                        }
                    }
                    return Ok(());
                }
                ColorEncoding::Bayer8(filter) => {
                    let pattern = pixels::BayerPattern::from(filter);
                    let rows: Vec<&[u8]> = (0..size.height).map(row).collect();
                    for y in 0..size.height {
                        for (x, out) in gray.row_mut(y).iter_mut().enumerate() {
                            let [pr, pg, pb] = pixels::demosaic_pixel(&rows, pattern, x, y);
                            *out = wr * f32::from(pr) + wg * f32::from(pg) + wb * f32::from(pb);
                        }
                    }
                    return Ok(());
                }
                interleaved => interleaved_rgb_offsets(interleaved).unwrap_or([0, 0, 0]),
            };
            let [r, g, b] = rgb_offsets;
            for y in 0..size.height {
                for (out, px) in gray.row_mut(y).iter_mut().zip(row(y).chunks_exact(bpp)) {
                    *out = if bpp == 1 {
                        f32::from(px[0]) / 255.0
                    } else {
                        wr * f32::from(px[r]) + wg * f32::from(px[g]) + wb * f32::from(px[b])
                    };
                }
            }
            Ok(())
        }
        ImagePayload::Compressed { format, data } => {
            let image_format = color_image_format(topic, format)?;
            let decoded = decode_compressed_pixels(data, image_format, topic, &format!("{format} image"))?;
            let size = ImageSize::new(decoded.width() as usize, decoded.height() as usize);
            resize_for(gray, size);
            if decoded.color().channel_count() <= 2 {
                let luma = decoded.into_luma8();
                for (out, v) in gray.as_mut_slice().iter_mut().zip(luma.as_raw()) {
                    *out = f32::from(*v) / 255.0;
                }
            } else {
                let rgb = decoded.into_rgb8();
                for (out, px) in gray.as_mut_slice().iter_mut().zip(rgb.as_raw().chunks_exact(3)) {
                    *out = wr * f32::from(px[0]) + wg * f32::from(px[1]) + wb * f32::from(px[2]);
                }
            }
            Ok(())
        }
    }
}

/// A raw colour image's encoding and size, checked against its row length and bytes.
fn raw_color(
    topic: &str,
    width: u32,
    height: u32,
    encoding: &str,
    step: u32,
    data: &[u8],
) -> Result<(ColorEncoding, ImageSize)> {
    let color: ColorEncoding = encoding
        .parse()
        .map_err(|_| unsupported(topic, "colour", encoding, SUPPORTED_COLOR_ENCODINGS))?;
    let size = raw_rows(topic, width, height, step, color.bytes_per_pixel(), data.len())?;
    Ok((color, size))
}

/// The PNG or JPEG format of a compressed colour image's `format` string.
fn color_image_format(topic: &str, format: &str) -> Result<image::ImageFormat> {
    ColorFormat::from_transport_format(format)
        .map(ColorFormat::image_format)
        .ok_or_else(|| unsupported(topic, "colour", format, SUPPORTED_COLOR_ENCODINGS))
}

/// Offsets of red, green and blue in an interleaved pixel of `color` (`None` for the packed
/// and mosaic encodings); grey images use their one channel three times.
fn interleaved_rgb_offsets(color: ColorEncoding) -> Option<[usize; 3]> {
    match color {
        ColorEncoding::Rgb8 | ColorEncoding::Rgba8 => Some([0, 1, 2]),
        ColorEncoding::Bgr8 | ColorEncoding::Bgra8 => Some([2, 1, 0]),
        ColorEncoding::Mono8 => Some([0, 0, 0]),
        ColorEncoding::Uyvy | ColorEncoding::Yuyv | ColorEncoding::Bayer8(_) => None,
    }
}

/// Decodes a colour (or grey) image into `rgb` (grey repeated in the three channels; YUV
/// 4:2:2 through BT.601; Bayer mosaics demosaiced as for grey), resizing `rgb` when the size
/// differs. The same encodings as [`gray_from_image_into`].
///
/// # Errors
/// As [`gray_from_image_into`].
pub fn rgb_from_image_into(msg: &ImageMsg, topic: &str, rgb: &mut Rgb8) -> Result<()> {
    match &msg.payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            step,
            data,
            ..
        } => {
            let (color, size) = raw_color(topic, *width, *height, encoding, *step, data)?;
            let yuv = match color {
                ColorEncoding::Uyvy => Some(true),
                ColorEncoding::Yuyv => Some(false),
                _ => None,
            };
            let bayer = match color {
                ColorEncoding::Bayer8(filter) => Some(pixels::BayerPattern::from(filter)),
                _ => None,
            };
            let bpp = color.bytes_per_pixel();
            let [r, g, b] = interleaved_rgb_offsets(color).unwrap_or([0, 0, 0]);
            resize_for(rgb, size);
            let step = *step as usize;
            let rows: Vec<&[u8]> = (0..size.height)
                .map(|y| &data[y * step..y * step + size.width * bpp])
                .collect();
            for (y, row) in rows.iter().enumerate() {
                for (x, out) in rgb.row_mut(y).iter_mut().enumerate() {
                    *out = match (yuv, bayer) {
                        (Some(uyvy), _) => {
                            let (u, v) = pixels::yuv422_chroma_offsets(x, uyvy);
                            // The last pixel of an odd-width row has no complete pair: its
                            // missing chroma is neutral (grey at its luma).
                            let chroma = |i: usize| row.get(i).copied().unwrap_or(pixels::NEUTRAL_CHROMA);
                            pixels::rgb_from_video_yuv(
                                row[pixels::yuv422_luma_offset(x, uyvy)],
                                chroma(u),
                                chroma(v),
                            )
                        }
                        (None, Some(pattern)) => pixels::demosaic_pixel(&rows, pattern, x, y),
                        (None, None) => {
                            let px = &row[x * bpp..x * bpp + bpp];
                            [px[r], px[g], px[b]]
                        }
                    };
                }
            }
            Ok(())
        }
        ImagePayload::Compressed { format, data } => {
            let image_format = color_image_format(topic, format)?;
            let decoded = decode_compressed_pixels(data, image_format, topic, &format!("{format} image"))?;
            let size = ImageSize::new(decoded.width() as usize, decoded.height() as usize);
            resize_for(rgb, size);
            let decoded = decoded.into_rgb8();
            for (out, px) in rgb
                .as_mut_slice()
                .iter_mut()
                .zip(decoded.as_raw().chunks_exact(3))
            {
                *out = [px[0], px[1], px[2]];
            }
            Ok(())
        }
    }
}

/// Decodes a depth image into metres (0 = invalid), resizing `depth_m` when needed.
/// `units_per_meter` scales 16-bit encodings; `32FC1` is metres already (NaN, ±inf and
/// negative values become 0).
///
/// # Errors
/// [`Error::Decode`] naming `topic` for unsupported encodings (listing the supported ones),
/// short buffers or an undecodable compressedDepth PNG.
pub fn depth_from_image_into(
    msg: &ImageMsg,
    topic: &str,
    units_per_meter: f64,
    depth_m: &mut DepthMeters,
) -> Result<()> {
    // The same scaling as `image_buf::depth_m_from_u16_into`, so decoded MCAP depth equals
    // depth read from dataset files bit for bit.
    let scale = 1.0 / units_per_meter as f32;
    match &msg.payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            step,
            big_endian,
            data,
        } => {
            let depth_encoding: DepthEncoding = encoding
                .parse()
                .map_err(|_| unsupported(topic, "depth", encoding, SUPPORTED_DEPTH_ENCODINGS))?;
            let bpp = depth_encoding.bytes_per_pixel();
            let size = raw_rows(topic, *width, *height, *step, bpp, data.len())?;
            resize_for(depth_m, size);
            let step = *step as usize;
            for y in 0..size.height {
                let row = &data[y * step..y * step + size.width * bpp];
                let out = depth_m.row_mut(y);
                if depth_encoding == DepthEncoding::U16 {
                    for (o, b) in out.iter_mut().zip(row.chunks_exact(2)) {
                        let raw = if *big_endian {
                            u16::from_be_bytes([b[0], b[1]])
                        } else {
                            u16::from_le_bytes([b[0], b[1]])
                        };
                        *o = f32::from(raw) * scale;
                    }
                } else {
                    for (o, b) in out.iter_mut().zip(row.chunks_exact(4)) {
                        let bytes = [b[0], b[1], b[2], b[3]];
                        let v = if *big_endian {
                            f32::from_be_bytes(bytes)
                        } else {
                            f32::from_le_bytes(bytes)
                        };
                        *o = if v.is_finite() && v > 0.0 { v } else { 0.0 };
                    }
                }
            }
            Ok(())
        }
        ImagePayload::Compressed { format, data } => {
            let compressed: CompressedDepthFormat = format
                .parse()
                .map_err(|_| unsupported(topic, "depth", format, SUPPORTED_DEPTH_ENCODINGS))?;
            let raw = compressed.depth == DepthEncoding::U16;
            let Some((header, payload)) = data.split_at_checked(COMPRESSED_DEPTH_HEADER_BYTES) else {
                return Err(decode_error(
                    topic,
                    format!(
                        "{format}: {} bytes, expected a {COMPRESSED_DEPTH_HEADER_BYTES}-byte header and \
                         the compressed image",
                        data.len()
                    ),
                ));
            };
            let (size, values) = if compressed.codec == DepthCodec::Rvl {
                rvl_values(payload, topic, format)?
            } else {
                let what = format!("{format} depth PNG");
                let decoded =
                    decode_compressed_pixels(payload, image::ImageFormat::Png, topic, &what)?.into_luma16();
                let size = ImageSize::new(decoded.width() as usize, decoded.height() as usize);
                (size, decoded.into_raw())
            };
            resize_for(depth_m, size);
            if raw {
                for (o, v) in depth_m.as_mut_slice().iter_mut().zip(&values) {
                    *o = f32::from(*v) * scale;
                }
            } else {
                // 32FC1 is stored as quantised inverse depth q: depth = a / (q − b), q = 0
                // invalid, with a and b the two floats after the format enum of the header.
                let param = |i: usize| {
                    let at = 4 + 4 * i;
                    f32::from_le_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
                };
                let (a, b) = (param(0), param(1));
                for (o, v) in depth_m.as_mut_slice().iter_mut().zip(&values) {
                    let d = if *v == 0 { 0.0 } else { a / (f32::from(*v) - b) };
                    *o = if d.is_finite() && d > 0.0 { d } else { 0.0 };
                }
            }
            Ok(())
        }
    }
}

/// The image size and values of a `compressedDepth rvl` payload (after the config header):
/// width and height (`u32` each), then the RVL stream.
fn rvl_values(payload: &[u8], topic: &str, format: &str) -> Result<(ImageSize, Vec<u16>)> {
    let bad = |what: String| decode_error(topic, format!("{format}: {what}"));
    let Some((dims, stream)) = payload.split_at_checked(pixels::RVL_SIZE_HEADER_BYTES) else {
        return Err(bad(format!(
            "{} bytes after the header, expected the {}-byte RVL size and the stream",
            payload.len(),
            pixels::RVL_SIZE_HEADER_BYTES
        )));
    };
    let dim = |at: usize| u32::from_le_bytes([dims[at], dims[at + 1], dims[at + 2], dims[at + 3]]);
    let size = ImageSize::new(dim(0) as usize, dim(4) as usize);
    let pixels_declared = size.area() as u64;
    let most = (stream.len() as u64)
        .saturating_mul(pixels::RVL_MAX_PIXELS_PER_BYTE)
        .min(crate::mcap_io::codec::MAX_COMPRESSED_IMAGE_PIXELS);
    if pixels_declared == 0 || pixels_declared > most {
        return Err(bad(format!(
            "RVL image of {size} from {} bytes: expected at least one pixel and at most {most} \
             (5 pixels per byte, {} in all)",
            stream.len(),
            crate::mcap_io::codec::MAX_COMPRESSED_IMAGE_PIXELS
        )));
    }
    let mut values = vec![0u16; size.area()];
    pixels::decode_rvl(stream, &mut values).map_err(bad)?;
    Ok((size, values))
}

/// Encodes a message to protobuf bytes (helper for fixtures and tests).
pub fn protobuf_bytes<M: prost::Message>(msg: &M) -> Vec<u8> {
    msg.encode_to_vec()
}

/// Every pose of a pose channel (`PoseInFrame`, `PoseStamped`, transforms: each sample's
/// `parent_from_child` as `world_from_camera`), sorted by time, one per timestamp; empty when
/// the file has no channel `topic`.
///
/// # Errors
/// [`Error::Decode`] when the channel's schema is not a pose schema or a message does not decode.
pub fn read_poses(input: &super::McapInput, topic: &str) -> Result<Vec<crate::trajectory::StampedPose>> {
    let Some(channel) = input.channel_by_topic(topic) else {
        return Ok(Vec::new());
    };
    let Some(ct) = channel.channel_type.filter(|ct| ct.is_pose()) else {
        return Err(Error::Decode {
            topic: topic.into(),
            message: format!("expected a pose schema, found {:?}", channel.schema_name),
        });
    };
    let mut poses = Vec::new();
    input.for_each_message(Some(&[topic.to_owned()]), None, |m| {
        for s in decode_poses(ct, topic, &m.data)? {
            poses.push(crate::trajectory::StampedPose {
                timestamp_ns: s.timestamp_ns,
                world_from_camera: s.parent_from_child,
            });
        }
        Ok(true)
    })?;
    poses.sort_by_key(|p| p.timestamp_ns);
    poses.dedup_by_key(|p| p.timestamp_ns);
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(encoding: &str, width: u32, bpp: u32, data: Vec<u8>) -> ImageMsg {
        ImageMsg {
            timestamp_ns: 1,
            frame_id: "cam".into(),
            payload: ImagePayload::Raw {
                width,
                height: 1,
                encoding: encoding.into(),
                step: width * bpp,
                big_endian: false,
                data,
            },
        }
    }

    #[test]
    fn colour_orders_give_the_same_gray() {
        let rgb = raw("rgb8", 2, 3, vec![10, 200, 30, 255, 0, 128]);
        let bgr = raw("bgr8", 2, 3, vec![30, 200, 10, 128, 0, 255]);
        let bgra = raw("bgra8", 2, 4, vec![30, 200, 10, 9, 128, 0, 255, 9]);
        let mut a = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        let mut b = a.clone();
        let mut c = a.clone();
        gray_from_image_into(&rgb, "/c", &mut a).unwrap();
        gray_from_image_into(&bgr, "/c", &mut b).unwrap();
        gray_from_image_into(&bgra, "/c", &mut c).unwrap();
        assert_eq!(a, b);
        assert_eq!(a, c);
        let reference = crate::image_buf::gray_from_rgb8(&crate::image_buf::Rgb8::from_fn(
            ImageSize::new(2, 1),
            |x, _| if x == 0 { [10, 200, 30] } else { [255, 0, 128] },
        ));
        assert_eq!(a, reference);
    }

    #[test]
    fn rgb_decoding_agrees_with_the_grey_one_in_every_encoding() {
        let mut rgb = Rgb8::filled(ImageSize::new(1, 1), [0; 3]);
        for msg in [
            raw("rgb8", 2, 3, vec![10, 200, 30, 255, 0, 128]),
            raw("bgr8", 2, 3, vec![30, 200, 10, 128, 0, 255]),
            raw("bgra8", 2, 4, vec![30, 200, 10, 9, 128, 0, 255, 9]),
        ] {
            rgb_from_image_into(&msg, "/c", &mut rgb).unwrap();
            assert_eq!(rgb.as_slice(), &[[10, 200, 30], [255, 0, 128]]);
        }
        rgb_from_image_into(&raw("mono8", 2, 1, vec![7, 250]), "/c", &mut rgb).unwrap();
        assert_eq!(rgb.as_slice(), &[[7; 3], [250; 3]]);
        // UYVY: grey (chroma 128) decodes to grey with the luma's video-range level, red to red.
        rgb_from_image_into(&raw("uyvy", 2, 2, vec![128, 235, 128, 16]), "/c", &mut rgb).unwrap();
        assert_eq!(rgb.as_slice(), &[[255; 3], [0; 3]]);
        rgb_from_image_into(&raw("yuyv", 2, 2, vec![82, 90, 82, 240]), "/c", &mut rgb).unwrap();
        assert!(
            rgb.as_slice()
                .iter()
                .all(|&[r, g, b]| r > 240 && g < 10 && b < 10),
            "{rgb:?}"
        );
        // Every encoding the grey decoder takes, the colour one takes; the same errors.
        let mut gray = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        for encoding in ["bayer_rggb8", "rgba8", "8UC3", "nv12"] {
            let msg = raw(encoding, 2, 1, vec![50, 60, 70, 80, 90, 100, 110, 120]);
            assert_eq!(
                gray_from_image_into(&msg, "/c", &mut gray).is_ok(),
                rgb_from_image_into(&msg, "/c", &mut rgb).is_ok(),
                "{encoding}"
            );
        }
        assert!(rgb_from_image_into(&raw("rgb8", 2, 3, vec![0; 5]), "/c", &mut rgb).is_err());
        // An odd width: the last pixel's pair is cut short (a fuzzing finding: it indexed past
        // the row); its chroma is neutral.
        rgb_from_image_into(
            &raw("uyvy", 3, 2, vec![128, 235, 128, 235, 128, 235]),
            "/c",
            &mut rgb,
        )
        .unwrap();
        assert_eq!(rgb.as_slice()[2], [255; 3]);
    }

    #[test]
    fn depth_encodings_agree_in_metres() {
        let mm: Vec<u8> = [1500u16, 0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let m: Vec<u8> = [1.5f32, f32::NAN].iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut a = DepthMeters::filled(ImageSize::new(2, 1), 9.0);
        let mut b = a.clone();
        depth_from_image_into(&raw("16UC1", 2, 2, mm), "/d", 1000.0, &mut a).unwrap();
        depth_from_image_into(&raw("32FC1", 2, 4, m), "/d", 1000.0, &mut b).unwrap();
        let mut reference = DepthMeters::filled(ImageSize::new(2, 1), 0.0);
        crate::image_buf::depth_m_from_u16_into(&[1500, 0], 1000.0, &mut reference).unwrap();
        assert_eq!(
            a, reference,
            "16UC1 must match the dataset reader's scaling exactly"
        );
        assert!((a.get(0, 0) - 1.5).abs() < 1e-6 && a.get(1, 0) == 0.0);
        assert_eq!(b.as_slice(), &[1.5, 0.0]);
    }

    #[test]
    fn packed_yuv_and_bayer_colour_give_the_gray_of_the_same_colour() {
        // A uniform colour: BT.601 video-range Y of (200, 120, 40) is 16 + 219 · luma.
        let (r, g, b) = (200u8, 120u8, 40u8);
        let rgb = raw("rgb8", 4, 3, [r, g, b].repeat(4));
        let mut expected = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        gray_from_image_into(&rgb, "/c", &mut expected).unwrap();
        let luma = 16.0 + 219.0 * expected.get(0, 0);
        let y = luma.round() as u8;
        let mut gray = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        for (encoding, quad) in [("yuv422", [128, y, 128, y]), ("yuv422_yuy2", [y, 128, y, 128])] {
            gray_from_image_into(&raw(encoding, 4, 2, quad.repeat(2)), "/c", &mut gray).unwrap();
            assert!(
                gray.as_slice()
                    .iter()
                    .all(|v| (v - expected.get(0, 0)).abs() < 0.5 / 219.0),
                "{encoding}"
            );
        }
        // Bayer RGGB mosaic of the colour, 4×4: demosaiced to the colour everywhere.
        let mosaic: Vec<u8> = (0..16)
            .map(|i| match ((i / 4) % 2, i % 2) {
                (0, 0) => r,
                (1, 1) => b,
                _ => g,
            })
            .collect();
        let msg = ImageMsg {
            payload: ImagePayload::Raw {
                width: 4,
                height: 4,
                encoding: "bayer_rggb8".into(),
                step: 4,
                big_endian: false,
                data: mosaic,
            },
            ..raw("bayer_rggb8", 4, 1, vec![])
        };
        gray_from_image_into(&msg, "/c", &mut gray).unwrap();
        assert_eq!(gray.size(), ImageSize::new(4, 4));
        assert!(gray
            .as_slice()
            .iter()
            .all(|v| (v - expected.get(0, 0)).abs() < 1e-6));
    }

    fn compressed_depth(format: &str, header: [f32; 2], payload: Vec<u8>) -> ImageMsg {
        let mut data = vec![0u8; 4];
        data.extend_from_slice(&header[0].to_le_bytes());
        data.extend_from_slice(&header[1].to_le_bytes());
        data.extend(payload);
        ImageMsg {
            timestamp_ns: 1,
            frame_id: "cam".into(),
            payload: ImagePayload::Compressed {
                format: format.into(),
                data,
            },
        }
    }

    #[test]
    fn compressed_depth_rvl_and_inverse_depth_decode() {
        let values: Vec<u16> = vec![1500, 0, 1502, 1498, 0, 0];
        let mut payload = Vec::new();
        payload.extend_from_slice(&3u32.to_le_bytes());
        payload.extend_from_slice(&2u32.to_le_bytes());
        payload.extend(pixels::encode_rvl(&values));
        let msg = compressed_depth("16UC1; compressedDepth rvl", [0.0, 0.0], payload.clone());
        assert!(msg.is_depth());
        let mut d = DepthMeters::filled(ImageSize::new(1, 1), 9.0);
        depth_from_image_into(&msg, "/d", 1000.0, &mut d).unwrap();
        let mut reference = DepthMeters::filled(ImageSize::new(3, 2), 0.0);
        crate::image_buf::depth_m_from_u16_into(&values, 1000.0, &mut reference).unwrap();
        assert_eq!(d, reference);
        // 32FC1: quantised inverse depth, depth = a / (q − b); q = 0 is invalid.
        let msg = compressed_depth("32FC1; compressedDepth rvl", [3000.0, -0.5], payload);
        depth_from_image_into(&msg, "/d", 1000.0, &mut d).unwrap();
        assert!((d.get(0, 0) - 3000.0 / 1500.5).abs() < 1e-5 && d.get(1, 0) == 0.0);
        // A size the stream cannot hold is refused before allocating.
        let mut huge = Vec::new();
        huge.extend_from_slice(&100_000u32.to_le_bytes());
        huge.extend_from_slice(&100_000u32.to_le_bytes());
        huge.extend_from_slice(&[0; 8]);
        let err = depth_from_image_into(
            &compressed_depth("16UC1; compressedDepth rvl", [0.0; 2], huge),
            "/d",
            1.0,
            &mut d,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("100000x100000") && err.contains("/d"), "{err}");
        let short = compressed_depth("16UC1; compressedDepth rvl", [0.0; 2], vec![1, 2]);
        assert!(depth_from_image_into(&short, "/d", 1.0, &mut d).is_err());
    }

    #[test]
    fn compressed_depth_png_skips_its_config_header() {
        let raw = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(2, 1, vec![1500, 0]).unwrap();
        let mut png = std::io::Cursor::new(Vec::new());
        raw.write_to(&mut png, image::ImageFormat::Png).unwrap();
        let mut data = vec![0u8; COMPRESSED_DEPTH_HEADER_BYTES];
        data.extend_from_slice(png.get_ref());
        let msg = ImageMsg {
            timestamp_ns: 1,
            frame_id: "cam".into(),
            payload: ImagePayload::Compressed {
                format: "16UC1; compressedDepth png".into(),
                data,
            },
        };
        assert!(msg.is_depth());
        let mut d = DepthMeters::filled(ImageSize::new(1, 1), 9.0);
        depth_from_image_into(&msg, "/d", 1000.0, &mut d).unwrap();
        let mut reference = DepthMeters::filled(ImageSize::new(2, 1), 0.0);
        crate::image_buf::depth_m_from_u16_into(&[1500, 0], 1000.0, &mut reference).unwrap();
        assert_eq!(d, reference);
    }

    /// `32FC1; compressedDepth png` (compressed_depth_image_transport's float depth): a 16-bit
    /// PNG of quantised inverse depth q = a / d + b, with ROS's defaults (quantisation 100,
    /// 10 m range: a = 100 · 101, b = 1 − a / 10); q = 0 marks invalid depth.
    #[test]
    fn compressed_depth_png_32fc1_is_inverse_depth() {
        let a = 100.0f32 * 101.0;
        let b = 1.0 - a / 10.0;
        let depth_m = [0.6f32, 1.5, 4.25, 9.5, f32::NAN, 0.0];
        let q: Vec<u16> = depth_m
            .iter()
            .map(|&d| {
                if d.is_finite() && d > 0.0 {
                    (a / d + b).round() as u16
                } else {
                    0
                }
            })
            .collect();
        let png_image = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(3, 2, q).unwrap();
        let mut png = std::io::Cursor::new(Vec::new());
        png_image.write_to(&mut png, image::ImageFormat::Png).unwrap();
        let msg = compressed_depth("32FC1; compressedDepth png", [a, b], png.into_inner());
        assert!(msg.is_depth());
        let mut d = DepthMeters::filled(ImageSize::new(1, 1), 9.0);
        // Metres already: the units flag does not scale float depth.
        depth_from_image_into(&msg, "/d", 5000.0, &mut d).unwrap();
        assert_eq!(d.size(), ImageSize::new(3, 2));
        for (i, (&got, &want)) in d.as_slice().iter().zip(&depth_m).enumerate() {
            if want.is_finite() && want > 0.0 {
                // Half a quantisation step of inverse depth: d² / (2a), 4.5 mm at 9.5 m.
                let bound = want * want / (2.0 * a) + 1e-6;
                assert!(
                    (got - want).abs() <= bound,
                    "pixel {i}: {got} vs {want} (bound {bound})"
                );
            } else {
                assert_eq!(got, 0.0, "pixel {i}");
            }
        }
        // The 16-bit reading of the same bytes is raw units, not inverse depth.
        let mut raw_units = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
        let as_16 = ImageMsg {
            payload: match &msg.payload {
                ImagePayload::Compressed { data, .. } => ImagePayload::Compressed {
                    format: "16UC1; compressedDepth png".into(),
                    data: data.clone(),
                },
                ImagePayload::Raw { .. } => unreachable!(),
            },
            ..msg.clone()
        };
        depth_from_image_into(&as_16, "/d", 1000.0, &mut raw_units).unwrap();
        assert!((raw_units.get(1, 0) - d.get(1, 0)).abs() > 1.0);
    }

    #[test]
    fn unsupported_encodings_are_named() {
        let mut g = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        let err = gray_from_image_into(&raw("nv12", 2, 2, vec![0; 4]), "/c", &mut g)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("nv12") && err.contains("rgb8") && err.contains("/c"),
            "{err}"
        );
        let mut d = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
        let err = depth_from_image_into(&raw("8UC1", 2, 1, vec![0; 2]), "/d", 1.0, &mut d)
            .unwrap_err()
            .to_string();
        assert!(err.contains("8UC1") && err.contains("32FC1"), "{err}");
    }

    #[test]
    fn zero_sized_raw_images_are_rejected_before_any_row_loop() {
        // 0 × u32::MAX passed every length check with no data and then looped over 4 billion
        // empty rows (fuzz/regressions/*/slow-zero-width-4g-rows).
        let msg = ImageMsg {
            timestamp_ns: 1,
            frame_id: "cam".into(),
            payload: ImagePayload::Raw {
                width: 0,
                height: u32::MAX,
                encoding: "mono8".into(),
                step: 0,
                big_endian: false,
                data: Vec::new(),
            },
        };
        let mut g = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        let err = gray_from_image_into(&msg, "/c", &mut g).unwrap_err().to_string();
        assert!(
            err.contains("/c") && err.contains("0x4294967295") && err.contains("at least one pixel"),
            "{err}"
        );
    }

    #[test]
    fn compressed_images_declaring_huge_sizes_are_rejected_before_decoding() {
        // A PNG header declaring 20000×20000 made the decoder allocate 400 MB for a 60-byte
        // message before failing on the missing pixel data.
        let header = |w: u32, h: u32| {
            let buf = image::GrayImage::new(1, 1);
            let mut png = std::io::Cursor::new(Vec::new());
            buf.write_to(&mut png, image::ImageFormat::Png).unwrap();
            let mut png = png.into_inner();
            // IHDR data starts after the signature (8), length (4) and type (4).
            png[16..20].copy_from_slice(&w.to_be_bytes());
            png[20..24].copy_from_slice(&h.to_be_bytes());
            let crc = crc32(&png[12..29]);
            png[29..33].copy_from_slice(&crc.to_be_bytes());
            png
        };
        let msg = |data| ImageMsg {
            timestamp_ns: 1,
            frame_id: "cam".into(),
            payload: ImagePayload::Compressed {
                format: "png".into(),
                data,
            },
        };
        let mut g = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        let err = gray_from_image_into(&msg(header(20_000, 20_000)), "/c", &mut g)
            .unwrap_err()
            .to_string();
        assert!(err.contains("20000x20000") && err.contains("/c"), "{err}");
        // The same header with the real 1×1 size still decodes.
        gray_from_image_into(&msg(header(1, 1)), "/c", &mut g).unwrap();
        assert_eq!(g.size(), ImageSize::new(1, 1));
    }

    /// CRC-32 (PNG chunk checksum), bitwise.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn ros2_image_decodes_from_cdr() {
        let msg = ros2::Image {
            header: ros2::Header {
                stamp: ros2::Time {
                    sec: 12,
                    nanosec: 345,
                },
                frame_id: "cam".into(),
            },
            height: 1,
            width: 2,
            encoding: "16UC1".into(),
            is_bigendian: 0,
            step: 4,
            data: vec![1, 0, 2, 0],
        };
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&msg, cdr::Infinite).unwrap();
        assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
        let ct = ChannelType::classify(ros2::names::IMAGE, "cdr").unwrap();
        let img = decode_image(ct, "/d", &bytes).unwrap();
        assert_eq!(img.timestamp_ns, 12_000_000_345);
        assert!(img.is_depth());
        let mut d = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
        depth_from_image_into(&img, "/d", 1.0, &mut d).unwrap();
        assert_eq!(d.as_slice(), &[1.0, 2.0]);
    }

    #[test]
    fn json_stamps_beyond_u64_nanoseconds_are_errors_not_wrapped() {
        let ct = ChannelType::classify("foxglove.PoseInFrame", "json").unwrap();
        let text = br#"{"timestamp":{"sec":18446744073709551615,"nsec":0},"frame_id":"w",
            "pose":{"position":{"x":0,"y":0,"z":0},"orientation":{"x":0,"y":0,"z":0,"w":1}}}"#;
        let err = decode_poses(ct, "/p", text).unwrap_err().to_string();
        assert!(
            err.contains("18446744073709551615") && err.contains("/p"),
            "{err}"
        );
    }

    #[test]
    fn json_calibration_uses_upper_case_fields() {
        let text = br#"{"timestamp":{"sec":1,"nsec":2},"frame_id":"c","width":4,"height":3,
            "distortion_model":"plumb_bob","D":[],"K":[500,0,2,0,501,1.5,0,0,1],"R":[],"P":[]}"#;
        let ct = ChannelType::classify("foxglove.CameraCalibration", "json").unwrap();
        let c = decode_calibration(ct, "/ci", text).unwrap();
        assert_eq!(c.timestamp_ns, 1_000_000_002);
        let k = c.intrinsics("/ci").unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (500.0, 501.0, 2.0, 1.5));
        let zero = CalibrationMsg { k: vec![0.0; 9], ..c };
        let error = zero.intrinsics("/ci").unwrap_err();
        assert!(error.to_string().contains("uncalibrated"), "{error}");
        assert!(matches!(error, Error::BadIntrinsics { ref topic, .. } if topic == "/ci"));
    }

    #[test]
    fn tf_message_yields_every_transform() {
        let tf = |child: &str, x: f64| ros2::TransformStamped {
            header: ros2::Header {
                stamp: ros2::Time { sec: 1, nanosec: 0 },
                frame_id: "world".into(),
            },
            child_frame_id: child.into(),
            transform: ros2::Transform {
                translation: ros2::Point { x, y: 0.0, z: 0.0 },
                rotation: ros2::Quaternion {
                    w: 1.0,
                    ..Default::default()
                },
            },
        };
        let msg = ros2::TfMessage {
            transforms: vec![tf("a", 1.0), tf("b", 2.0)],
        };
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&msg, cdr::Infinite).unwrap();
        let ct = ChannelType::classify(ros2::names::TF_MESSAGE, "cdr").unwrap();
        let poses = decode_poses(ct, "/tf", &bytes).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[1].child_frame.as_deref(), Some("b"));
        assert_eq!(poses[1].parent_from_child.translation.vector.x, 2.0);
    }
}
