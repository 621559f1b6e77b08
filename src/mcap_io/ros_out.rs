//! Writing recordings as ROS drivers record them: ROS 2 (rosbag2 MCAP: `ros2` profile, `cdr`
//! messages, `ros2msg` schemas) or ROS 1 bags converted to MCAP (`ros1` profile, `ros1`
//! messages, `ros1msg` schemas). Used for synthetic recordings with exact ground truth and for
//! test fixtures; `process` reads such files through [`super::input`].
//!
//! ROS 2 messages are serialised with the `cdr` crate and the structs of
//! [`super::input::ros2`]; ROS 1 messages are written field by field here (little-endian,
//! packed, `u32` lengths before strings and variable arrays), independently of the serde
//! reader that decodes them, so a round trip checks both.

use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};

use mcap::records::MessageHeader;
use nalgebra::Isometry3;

use crate::error::{Error, Result};
use crate::geometry::distortion::CameraModel;
use crate::image_buf::ImageSize;
use crate::time::split_ns;

use super::input::{ros1, ros2};
use super::writer::McapWriteOptions;

/// Which ROS generation's conventions to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RosVersion {
    /// ROS 1 (`ros1` profile).
    Ros1,
    /// ROS 2 (`ros2` profile).
    Ros2,
}

impl RosVersion {
    fn profile(self) -> &'static str {
        match self {
            RosVersion::Ros1 => "ros1",
            RosVersion::Ros2 => "ros2",
        }
    }

    fn message_encoding(self) -> &'static str {
        match self {
            RosVersion::Ros1 => "ros1",
            RosVersion::Ros2 => "cdr",
        }
    }

    fn schema_encoding(self) -> &'static str {
        match self {
            RosVersion::Ros1 => "ros1msg",
            RosVersion::Ros2 => "ros2msg",
        }
    }
}

/// The message types written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum RosType {
    Image,
    CameraInfo,
    PoseStamped,
    TfMessage,
}

impl RosType {
    fn schema(self, version: RosVersion) -> (&'static str, String) {
        match (version, self) {
            (RosVersion::Ros1, RosType::Image) => (ros1::names::IMAGE, ros1::schema_text::image()),
            (RosVersion::Ros1, RosType::CameraInfo) => {
                (ros1::names::CAMERA_INFO, ros1::schema_text::camera_info())
            }
            (RosVersion::Ros1, RosType::PoseStamped) => {
                (ros1::names::POSE_STAMPED, ros1::schema_text::pose_stamped())
            }
            (RosVersion::Ros1, RosType::TfMessage) => {
                (ros1::names::TF_MESSAGE, ros1::schema_text::tf_message())
            }
            (RosVersion::Ros2, RosType::Image) => (ros2::names::IMAGE, ros2::schema_text::image()),
            (RosVersion::Ros2, RosType::CameraInfo) => {
                (ros2::names::CAMERA_INFO, ros2::schema_text::camera_info())
            }
            (RosVersion::Ros2, RosType::PoseStamped) => {
                (ros2::names::POSE_STAMPED, ros2::schema_text::pose_stamped())
            }
            (RosVersion::Ros2, RosType::TfMessage) => {
                (ros2::names::TF_MESSAGE, ros2::schema_text::tf_message())
            }
        }
    }
}

/// ROS 1 wire format, written field by field.
#[derive(Default)]
struct Ros1Bytes(Vec<u8>);

impl Ros1Bytes {
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn len(&mut self, n: usize) -> Result<()> {
        let n = u32::try_from(n).map_err(|_| Error::InvalidParameter {
            name: "ROS 1 field length",
            value: n.to_string(),
            expected: "at most u32::MAX bytes or elements".into(),
        })?;
        self.u32(n);
        Ok(())
    }
    fn bytes(&mut self, v: &[u8]) -> Result<()> {
        self.len(v.len())?;
        self.0.extend_from_slice(v);
        Ok(())
    }
    fn string(&mut self, v: &str) -> Result<()> {
        self.bytes(v.as_bytes())
    }
    fn header(&mut self, seq: u32, stamp_ns: u64, frame_id: &str) -> Result<()> {
        let (sec, nsec) = split_ns(stamp_ns);
        if u64::from(sec) * 1_000_000_000 + u64::from(nsec) != stamp_ns {
            return Err(stamp_error(stamp_ns));
        }
        self.u32(seq);
        self.u32(sec);
        self.u32(nsec);
        self.string(frame_id)
    }
    fn pose(&mut self, iso: &Isometry3<f64>) {
        let t = iso.translation.vector;
        let q = iso.rotation;
        for v in [t.x, t.y, t.z, q.i, q.j, q.k, q.w] {
            self.f64(v);
        }
    }
}

fn stamp_error(stamp_ns: u64) -> Error {
    Error::InvalidParameter {
        name: "timestamp",
        value: stamp_ns.to_string(),
        expected: "seconds that fit the ROS time (u32 for ROS 1, i32 for ROS 2)".into(),
    }
}

fn ros2_time(stamp_ns: u64) -> Result<ros2::Time> {
    let (sec, nanosec) = split_ns(stamp_ns);
    Ok(ros2::Time {
        sec: i32::try_from(sec).map_err(|_| stamp_error(stamp_ns))?,
        nanosec,
    })
}

fn ros2_header(stamp_ns: u64, frame_id: &str) -> Result<ros2::Header> {
    Ok(ros2::Header {
        stamp: ros2_time(stamp_ns)?,
        frame_id: frame_id.to_owned(),
    })
}

fn dimension(n: usize, what: &'static str) -> Result<u32> {
    u32::try_from(n).map_err(|_| Error::InvalidParameter {
        name: what,
        value: n.to_string(),
        expected: "at most u32::MAX".into(),
    })
}

fn cdr_bytes<T: serde::Serialize>(msg: &T) -> Result<Vec<u8>> {
    cdr::serialize::<_, _, cdr::CdrLe>(msg, cdr::Infinite).map_err(|e| Error::InvalidParameter {
        name: "ROS 2 message",
        value: e.to_string(),
        expected: "a message the CDR serialiser accepts".into(),
    })
}

fn ros2_transform(iso: &Isometry3<f64>) -> ros2::Transform {
    let t = iso.translation.vector;
    let q = iso.rotation;
    ros2::Transform {
        translation: ros2::Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        rotation: ros2::Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// An uncompressed image to write.
#[derive(Debug, Clone, Copy)]
pub struct RosImage<'a> {
    /// `frame_id`.
    pub frame_id: &'a str,
    /// Pixel encoding (`rgb8`, `16UC1`, `mono8`, ...).
    pub encoding: &'a str,
    /// Size.
    pub size: ImageSize,
    /// Bytes per row.
    pub step: usize,
    /// Rows of `step` bytes.
    pub data: &'a [u8],
}

/// A transform `parent → child` (`parent_from_child`).
#[derive(Debug, Clone, Copy)]
pub struct RosTransform<'a> {
    /// Parent frame.
    pub parent: &'a str,
    /// Child frame.
    pub child: &'a str,
    /// `parent_from_child`.
    pub parent_from_child: Isometry3<f64>,
}

/// Writes ROS messages into an MCAP file; channels are created on first use. Every message's
/// log and publish time is its stamp, so the caller writes in time order.
pub struct RosMcapWriter<W: Write + Seek> {
    writer: mcap::Writer<W>,
    version: RosVersion,
    channels: BTreeMap<String, u16>,
    schemas: HashMap<RosType, u16>,
    sequences: HashMap<u16, u32>,
}

impl<W: Write + Seek> RosMcapWriter<W> {
    /// Starts a file on `sink`.
    ///
    /// # Errors
    /// [`Error::Mcap`] when the header cannot be written.
    pub fn new(sink: W, version: RosVersion, options: &McapWriteOptions) -> Result<Self> {
        let writer = options.mcap_options().profile(version.profile()).create(sink)?;
        Ok(Self {
            writer,
            version,
            channels: BTreeMap::new(),
            schemas: HashMap::new(),
            sequences: HashMap::new(),
        })
    }

    fn channel(&mut self, topic: &str, ty: RosType) -> Result<u16> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match self.schemas.get(&ty) {
            Some(&id) => id,
            None => {
                let (name, text) = ty.schema(self.version);
                let id = self
                    .writer
                    .add_schema(name, self.version.schema_encoding(), text.as_bytes())?;
                self.schemas.insert(ty, id);
                id
            }
        };
        // The ros2 profile requires the QoS key (empty: the recorder's defaults).
        let metadata = match self.version {
            RosVersion::Ros2 => BTreeMap::from([("offered_qos_profiles".to_owned(), String::new())]),
            RosVersion::Ros1 => BTreeMap::new(),
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, self.version.message_encoding(), &metadata)?;
        self.channels.insert(topic.to_owned(), id);
        Ok(id)
    }

    fn write(&mut self, channel_id: u16, stamp_ns: u64, data: &[u8]) -> Result<()> {
        let sequence = self.sequences.entry(channel_id).or_insert(0);
        let header = MessageHeader {
            channel_id,
            sequence: *sequence,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        *sequence = sequence.wrapping_add(1);
        self.writer.write_to_known_channel(&header, data)?;
        Ok(())
    }

    /// The next ROS 1 header sequence number of `channel_id` (what a ROS 1 publisher counts).
    fn header_seq(&self, channel_id: u16) -> u32 {
        self.sequences.get(&channel_id).copied().unwrap_or(0)
    }

    /// Writes a `sensor_msgs/Image`.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure; [`Error::InvalidParameter`] for sizes beyond `u32`.
    pub fn image(&mut self, topic: &str, stamp_ns: u64, image: &RosImage<'_>) -> Result<()> {
        let id = self.channel(topic, RosType::Image)?;
        let data = encode_image(self.version, self.header_seq(id), stamp_ns, image)?;
        self.write(id, stamp_ns, &data)
    }

    /// Writes a `sensor_msgs/CameraInfo` for `camera` ([`encode_camera_info`]).
    ///
    /// # Errors
    /// As [`Self::image`].
    pub fn camera_info(
        &mut self,
        topic: &str,
        stamp_ns: u64,
        frame_id: &str,
        camera: &CameraModel,
    ) -> Result<()> {
        let id = self.channel(topic, RosType::CameraInfo)?;
        let data = encode_camera_info(self.version, self.header_seq(id), stamp_ns, frame_id, camera)?;
        self.write(id, stamp_ns, &data)
    }

    /// Writes a `tf2_msgs/TFMessage` with `transforms`, all stamped `stamp_ns`.
    ///
    /// # Errors
    /// As [`Self::image`].
    pub fn transforms(&mut self, topic: &str, stamp_ns: u64, transforms: &[RosTransform<'_>]) -> Result<()> {
        let id = self.channel(topic, RosType::TfMessage)?;
        let data = encode_transforms(self.version, stamp_ns, transforms)?;
        self.write(id, stamp_ns, &data)
    }

    /// Writes a `geometry_msgs/PoseStamped` (`frame_from_body` in `frame_id`).
    ///
    /// # Errors
    /// As [`Self::image`].
    pub fn pose(
        &mut self,
        topic: &str,
        stamp_ns: u64,
        frame_id: &str,
        frame_from_body: &Isometry3<f64>,
    ) -> Result<()> {
        let id = self.channel(topic, RosType::PoseStamped)?;
        let data = encode_pose(
            self.version,
            self.header_seq(id),
            stamp_ns,
            frame_id,
            frame_from_body,
        )?;
        self.write(id, stamp_ns, &data)
    }

    /// Adds a metadata record.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure.
    pub fn metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        self.writer.write_metadata(&mcap::records::Metadata {
            name: name.to_owned(),
            metadata,
        })?;
        Ok(())
    }

    /// Writes the summary and footer and returns the sink.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure.
    pub fn finish(mut self) -> Result<W> {
        self.writer.finish()?;
        Ok(self.writer.into_inner())
    }
}

/// The serialised `sensor_msgs/Image` (`seq` is the ROS 1 header's sequence number).
///
/// # Errors
/// [`Error::InvalidParameter`] for sizes beyond `u32` or stamps beyond the ROS time range.
pub fn encode_image(version: RosVersion, seq: u32, stamp_ns: u64, image: &RosImage<'_>) -> Result<Vec<u8>> {
    let (width, height) = (
        dimension(image.size.width, "width")?,
        dimension(image.size.height, "height")?,
    );
    let step = dimension(image.step, "step")?;
    match version {
        RosVersion::Ros1 => {
            let mut b = Ros1Bytes::default();
            b.header(seq, stamp_ns, image.frame_id)?;
            b.u32(height);
            b.u32(width);
            b.string(image.encoding)?;
            b.u8(0);
            b.u32(step);
            b.bytes(image.data)?;
            Ok(b.0)
        }
        RosVersion::Ros2 => cdr_bytes(&ros2::Image {
            header: ros2_header(stamp_ns, image.frame_id)?,
            height,
            width,
            encoding: image.encoding.to_owned(),
            is_bigendian: 0,
            step,
            data: image.data.to_vec(),
        }),
    }
}

/// The serialised `sensor_msgs/CameraInfo` of `camera`: K, D in ROS order (`plumb_bob` zeros
/// for a pinhole), R = I, P = [K | 0].
///
/// # Errors
/// As [`encode_image`].
pub fn encode_camera_info(
    version: RosVersion,
    seq: u32,
    stamp_ns: u64,
    frame_id: &str,
    camera: &CameraModel,
) -> Result<Vec<u8>> {
    let k = camera.intrinsics;
    let (model, d) = camera
        .distortion
        .map_or_else(|| ("plumb_bob", vec![0.0; 5]), |d| d.to_ros());
    let k9 = k.k_row_major();
    let r9 = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let p12 = [k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0];
    let (width, height) = (
        dimension(camera.size.width, "width")?,
        dimension(camera.size.height, "height")?,
    );
    match version {
        RosVersion::Ros1 => {
            let mut b = Ros1Bytes::default();
            b.header(seq, stamp_ns, frame_id)?;
            b.u32(height);
            b.u32(width);
            b.string(model)?;
            b.len(d.len())?;
            for v in d.iter().chain(&k9).chain(&r9).chain(&p12) {
                b.f64(*v);
            }
            // binning_x, binning_y, roi (x_offset, y_offset, height, width, do_rectify).
            for _ in 0..6 {
                b.u32(0);
            }
            b.u8(0);
            Ok(b.0)
        }
        RosVersion::Ros2 => cdr_bytes(&ros2::CameraInfo {
            header: ros2_header(stamp_ns, frame_id)?,
            height,
            width,
            distortion_model: model.to_owned(),
            d,
            k: k9,
            r: r9,
            p: p12,
            ..Default::default()
        }),
    }
}

/// The serialised `tf2_msgs/TFMessage` of `transforms`, all stamped `stamp_ns`.
///
/// # Errors
/// As [`encode_image`].
pub fn encode_transforms(
    version: RosVersion,
    stamp_ns: u64,
    transforms: &[RosTransform<'_>],
) -> Result<Vec<u8>> {
    match version {
        RosVersion::Ros1 => {
            let mut b = Ros1Bytes::default();
            b.len(transforms.len())?;
            for t in transforms {
                b.header(0, stamp_ns, t.parent)?;
                b.string(t.child)?;
                b.pose(&t.parent_from_child);
            }
            Ok(b.0)
        }
        RosVersion::Ros2 => {
            let transforms = transforms
                .iter()
                .map(|t| {
                    Ok(ros2::TransformStamped {
                        header: ros2_header(stamp_ns, t.parent)?,
                        child_frame_id: t.child.to_owned(),
                        transform: ros2_transform(&t.parent_from_child),
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            cdr_bytes(&ros2::TfMessage { transforms })
        }
    }
}

/// The serialised `geometry_msgs/PoseStamped` of `frame_from_body` in `frame_id`.
///
/// # Errors
/// As [`encode_image`].
pub fn encode_pose(
    version: RosVersion,
    seq: u32,
    stamp_ns: u64,
    frame_id: &str,
    frame_from_body: &Isometry3<f64>,
) -> Result<Vec<u8>> {
    match version {
        RosVersion::Ros1 => {
            let mut b = Ros1Bytes::default();
            b.header(seq, stamp_ns, frame_id)?;
            b.pose(frame_from_body);
            Ok(b.0)
        }
        RosVersion::Ros2 => {
            let t = ros2_transform(frame_from_body);
            cdr_bytes(&ros2::PoseStamped {
                header: ros2_header(stamp_ns, frame_id)?,
                pose: ros2::Pose {
                    position: t.translation,
                    orientation: t.rotation,
                },
            })
        }
    }
}
