//! [`RgbdMcapWriter`]: registers each schema and channel once and writes Foxglove messages.
//!
//! The writer writes messages in the order it is called; MCAP readers and doctors expect
//! log-time order, so callers merge their streams by timestamp first. Output is
//! deterministic: fixed `library` string ([`super::LIBRARY`]), no wall-clock times, channel
//! IDs in order of first registration (callers register in a fixed order with
//! [`RgbdMcapWriter::register_channel`]).

use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};

use foxglove::Encode;
use mcap::records::MessageHeader;
use nalgebra::Isometry3;
use prost::bytes::Bytes;

use crate::error::{Error, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::LensDistortion;
use crate::image_buf::{ImageSize, Mask, Rgb8};

use super::codec::{self, ColorFormat};
use super::{DEPTH_UNITS_KEY, FRAME_CAMERA_OPTICAL, FRAME_WORLD, LIBRARY, TOPIC_TF};

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// zstd (default): best size; colour PNGs barely compress, depth shrinks to about half.
    #[default]
    Zstd,
    /// lz4: faster, larger.
    Lz4,
    /// No compression.
    None,
}

/// Uncompressed bytes per chunk. A 640×480 frame pair is ~1.2 MB, so 4 MiB holds a few
/// frames: enough context for zstd, small enough for seeking.
pub const DEFAULT_CHUNK_SIZE_BYTES: u64 = 4 * 1024 * 1024;

/// zstd worker threads. One: the converter decodes depth on the rayon pool at the same
/// time, and the default (all physical cores) would oversubscribe the machine.
pub const DEFAULT_COMPRESSION_THREADS: u32 = 1;

/// zstd level: -1, zstd's first fast level (`zstd --fast=1`), rather than its default 3:
/// colour PNG/JPEG bytes do not compress further, so slower levels only cost time. Measured on
/// the Bonn window (200 VGA frames; interleaved runs of one binary): `process` 2.33–2.42 s at
/// -1 against 2.41–2.53 s at 1, output 112.1 against 111.1 MB; `convert` 0.59–0.62 s against
/// 0.68 s, 110.6 against 109.9 MB. Level 3 on tum_fr2_desk_50 took 1.4× level 1's time for
/// 1 % less. For lz4, -1 is its acceleration 2 (levels 0–2 are acceleration 1).
pub const DEFAULT_COMPRESSION_LEVEL: i32 = -1;

/// How to write the MCAP file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct McapWriteOptions {
    /// Chunk compression.
    pub compression: Compression,
    /// Compression level (`0` = codec default; negative = the codecs' fast levels: `-N` is
    /// `zstd --fast=N`, and lz4's acceleration N + 1).
    pub compression_level: i32,
    /// Target uncompressed bytes per chunk.
    pub chunk_size_bytes: u64,
    /// zstd worker threads (0 = compress on the calling thread).
    pub compression_threads: u32,
}

impl McapWriteOptions {
    /// The `mcap` writer's options (every writer of this crate starts from these).
    pub(crate) fn mcap_options(&self) -> mcap::WriteOptions {
        let compression = match self.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        };
        mcap::WriteOptions::new()
            .library(LIBRARY)
            .compression(compression)
            // `mcap` takes the level as u32 and hands it to zstd as `level as i32` and to
            // liblz4 as its C `int`, so a negative level passes through as its two's
            // complement (tested: `negative_levels_reach_the_codec`).
            .compression_level(self.compression_level as u32)
            .chunk_size(Some(self.chunk_size_bytes))
            .compression_threads(self.compression_threads)
    }
}

impl Default for McapWriteOptions {
    fn default() -> Self {
        Self {
            compression: Compression::Zstd,
            compression_level: DEFAULT_COMPRESSION_LEVEL,
            chunk_size_bytes: DEFAULT_CHUNK_SIZE_BYTES,
            compression_threads: DEFAULT_COMPRESSION_THREADS,
        }
    }
}

/// The kinds of message [`RgbdMcapWriter`] can write; each maps to one Foxglove schema.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageKind {
    /// `foxglove.CompressedImage`.
    CompressedImage,
    /// `foxglove.RawImage`.
    RawImage,
    /// `foxglove.CameraCalibration`.
    CameraCalibration,
    /// `foxglove.PoseInFrame`.
    PoseInFrame,
    /// `foxglove.FrameTransform`.
    FrameTransform,
}

impl MessageKind {
    fn schema(self) -> Option<foxglove::Schema> {
        use foxglove::messages as m;
        match self {
            MessageKind::CompressedImage => m::CompressedImage::get_schema(),
            MessageKind::RawImage => m::RawImage::get_schema(),
            MessageKind::CameraCalibration => m::CameraCalibration::get_schema(),
            MessageKind::PoseInFrame => m::PoseInFrame::get_schema(),
            MessageKind::FrameTransform => m::FrameTransform::get_schema(),
        }
    }
}

struct ChannelState {
    id: u16,
    kind: MessageKind,
    metadata: BTreeMap<String, String>,
    sequence: u32,
}

/// Writes RGB-D channels as Foxglove protobuf messages into an MCAP file.
///
/// Every `write_*` method takes the message time in nanoseconds; it is used as MCAP log
/// time, publish time and the message's own `timestamp`.
pub struct RgbdMcapWriter<W: Write + Seek> {
    writer: mcap::Writer<W>,
    schemas: HashMap<MessageKind, u16>,
    channels: HashMap<String, ChannelState>,
    last_log_time_ns: u64,
    message_count: u64,
    scratch: Vec<u8>,
}

fn channel_conflict(topic: &str, found: impl std::fmt::Debug, wanted: impl std::fmt::Debug) -> Error {
    Error::InvalidParameter {
        name: "channel",
        value: format!("{topic} with {wanted:?}"),
        expected: format!("the same kind and metadata as its first registration ({found:?})"),
    }
}

impl<W: Write + Seek> RgbdMcapWriter<W> {
    /// Starts an MCAP file on `sink` (writes the header).
    ///
    /// # Errors
    /// [`Error::Mcap`] when the header cannot be written.
    pub fn new(sink: W, options: &McapWriteOptions) -> Result<Self> {
        let writer = options.mcap_options().create(sink)?;
        Ok(Self {
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            last_log_time_ns: 0,
            message_count: 0,
            scratch: Vec::new(),
        })
    }

    /// Registers `topic` for messages of `kind` with channel `metadata` and returns its ID.
    /// Registering again with the same kind and metadata returns the same ID; IDs follow the
    /// order of first registration, so register in a fixed order for reproducible files.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when the topic exists with another kind or metadata;
    /// [`Error::Mcap`] when the record cannot be written.
    pub fn register_channel(
        &mut self,
        topic: &str,
        kind: MessageKind,
        metadata: BTreeMap<String, String>,
    ) -> Result<u16> {
        if let Some(existing) = self.channels.get(topic) {
            if existing.kind != kind || existing.metadata != metadata {
                return Err(channel_conflict(
                    topic,
                    (existing.kind, &existing.metadata),
                    (kind, &metadata),
                ));
            }
            return Ok(existing.id);
        }
        let schema_id = match self.schemas.get(&kind) {
            Some(&id) => id,
            None => {
                let schema = kind.schema().ok_or_else(|| Error::InvalidParameter {
                    name: "schema",
                    value: format!("{kind:?}"),
                    expected: "a Foxglove message type with an embedded schema".into(),
                })?;
                let id = self
                    .writer
                    .add_schema(&schema.name, &schema.encoding, &schema.data)?;
                self.schemas.insert(kind, id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, super::ENCODING_PROTOBUF, &metadata)?;
        self.channels.insert(
            topic.to_owned(),
            ChannelState {
                id,
                kind,
                metadata,
                sequence: 0,
            },
        );
        Ok(id)
    }

    fn channel_for(&mut self, topic: &str, kind: MessageKind) -> Result<&mut ChannelState> {
        if !self.channels.contains_key(topic) {
            self.register_channel(topic, kind, BTreeMap::new())?;
        }
        let state = self
            .channels
            .get_mut(topic)
            .ok_or_else(|| channel_conflict(topic, "missing", kind))?;
        if state.kind != kind {
            return Err(channel_conflict(topic, state.kind, kind));
        }
        Ok(state)
    }

    fn write_message<M: Encode>(
        &mut self,
        topic: &str,
        kind: MessageKind,
        timestamp_ns: u64,
        msg: &M,
    ) -> Result<()> {
        self.scratch.clear();
        msg.encode(&mut self.scratch).map_err(|e| Error::Encode {
            topic: topic.to_owned(),
            what: "message",
            reason: e.to_string(),
        })?;
        let state = self.channel_for(topic, kind)?;
        let header = MessageHeader {
            channel_id: state.id,
            sequence: state.sequence,
            log_time: timestamp_ns,
            publish_time: timestamp_ns,
        };
        state.sequence = state.sequence.wrapping_add(1);
        self.writer.write_to_known_channel(&header, &self.scratch)?;
        self.last_log_time_ns = self.last_log_time_ns.max(timestamp_ns);
        self.message_count += 1;
        Ok(())
    }

    /// Writes compressed colour bytes unchanged as `foxglove.CompressedImage` on `topic`,
    /// frame [`FRAME_CAMERA_OPTICAL`].
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure; [`Error::InvalidParameter`] on a topic kind conflict.
    pub fn write_color_compressed(
        &mut self,
        topic: &str,
        timestamp_ns: u64,
        data: Bytes,
        format: ColorFormat,
    ) -> Result<()> {
        let msg = codec::compressed_image(timestamp_ns, FRAME_CAMERA_OPTICAL, data, format);
        self.write_message(topic, MessageKind::CompressedImage, timestamp_ns, &msg)
    }

    /// Writes a decoded colour image as `foxglove.RawImage` `rgb8`.
    ///
    /// # Errors
    /// As [`Self::write_color_compressed`].
    pub fn write_color_raw(&mut self, topic: &str, timestamp_ns: u64, rgb: &Rgb8) -> Result<()> {
        let msg = codec::rgb8_image(timestamp_ns, FRAME_CAMERA_OPTICAL, rgb)?;
        self.write_message(topic, MessageKind::RawImage, timestamp_ns, &msg)
    }

    /// Writes raw depth units as `foxglove.RawImage` `16UC1`. The channel carries
    /// `units_per_meter` as metadata [`DEPTH_UNITS_KEY`]; the first call registers it.
    ///
    /// # Errors
    /// [`Error::BufferLength`] when `depth` does not match `size`;
    /// [`Error::InvalidParameter`] when the channel exists with other units.
    pub fn write_depth_u16(
        &mut self,
        topic: &str,
        timestamp_ns: u64,
        depth: &[u16],
        size: ImageSize,
        units_per_meter: f64,
    ) -> Result<()> {
        let metadata = BTreeMap::from([(DEPTH_UNITS_KEY.to_owned(), units_per_meter.to_string())]);
        self.register_channel(topic, MessageKind::RawImage, metadata)?;
        let msg = codec::depth_u16_image(timestamp_ns, FRAME_CAMERA_OPTICAL, depth, size)?;
        self.write_message(topic, MessageKind::RawImage, timestamp_ns, &msg)
    }

    /// Writes a calibration for images of `size` (zero distortion without `distortion`).
    ///
    /// # Errors
    /// As [`Self::write_color_compressed`].
    pub fn write_camera_info(
        &mut self,
        topic: &str,
        timestamp_ns: u64,
        intrinsics: &PinholeIntrinsics,
        size: ImageSize,
        distortion: Option<&LensDistortion>,
    ) -> Result<()> {
        let msg =
            codec::camera_calibration(timestamp_ns, FRAME_CAMERA_OPTICAL, intrinsics, size, distortion)?;
        self.write_message(topic, MessageKind::CameraCalibration, timestamp_ns, &msg)
    }

    /// Writes `world_from_camera` as `foxglove.PoseInFrame` in frame [`FRAME_WORLD`].
    ///
    /// # Errors
    /// As [`Self::write_color_compressed`].
    pub fn write_pose(
        &mut self,
        topic: &str,
        timestamp_ns: u64,
        world_from_camera: &Isometry3<f64>,
    ) -> Result<()> {
        self.write_pose_in_frame(topic, timestamp_ns, FRAME_WORLD, world_from_camera)
    }

    /// Writes `frame_from_body` as `foxglove.PoseInFrame` in `frame_id` (e.g. an odometry frame).
    ///
    /// # Errors
    /// As [`Self::write_color_compressed`].
    pub fn write_pose_in_frame(
        &mut self,
        topic: &str,
        timestamp_ns: u64,
        frame_id: &str,
        frame_from_body: &Isometry3<f64>,
    ) -> Result<()> {
        let msg = codec::pose_in_frame(timestamp_ns, frame_id, frame_from_body);
        self.write_message(topic, MessageKind::PoseInFrame, timestamp_ns, &msg)
    }

    /// Writes `parent_from_child` as a `foxglove.FrameTransform` on [`TOPIC_TF`].
    ///
    /// # Errors
    /// As [`Self::write_color_compressed`].
    pub fn write_tf(
        &mut self,
        timestamp_ns: u64,
        parent: &str,
        child: &str,
        parent_from_child: &Isometry3<f64>,
    ) -> Result<()> {
        let msg = codec::frame_transform(timestamp_ns, parent, child, parent_from_child);
        self.write_message(TOPIC_TF, MessageKind::FrameTransform, timestamp_ns, &msg)
    }

    /// Writes a mask (0 / 255) as `foxglove.RawImage` `mono8`.
    ///
    /// # Errors
    /// As [`Self::write_color_compressed`].
    pub fn write_mask(&mut self, topic: &str, timestamp_ns: u64, mask: &Mask) -> Result<()> {
        let msg = codec::mask_image(timestamp_ns, FRAME_CAMERA_OPTICAL, mask)?;
        self.write_message(topic, MessageKind::RawImage, timestamp_ns, &msg)
    }

    /// Writes a metadata record.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure.
    pub fn write_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        self.writer.write_metadata(&mcap::records::Metadata {
            name: name.to_owned(),
            metadata,
        })?;
        Ok(())
    }

    /// Attaches a file's bytes. `log_time_ns` places it on the timeline; the creation time is
    /// written as 0 so files stay reproducible.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure.
    pub fn attach(&mut self, name: &str, media_type: &str, log_time_ns: u64, data: &[u8]) -> Result<()> {
        self.writer.attach(&mcap::Attachment {
            log_time: log_time_ns,
            create_time: 0,
            name: name.to_owned(),
            media_type: media_type.to_owned(),
            data: std::borrow::Cow::Borrowed(data),
        })?;
        Ok(())
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.message_count
    }

    /// Writes the summary and footer and returns the sink. Always call this: dropping the
    /// writer finishes the file too, but discards any error.
    ///
    /// # Errors
    /// [`Error::Mcap`] when the summary or footer cannot be written.
    pub fn finish(mut self) -> Result<W> {
        self.writer.finish()?;
        Ok(self.writer.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mcap_io::{TOPIC_COLOR_IMAGE, TOPIC_DEPTH_IMAGE};
    use std::io::Cursor;

    #[test]
    fn depth_channel_refuses_changing_units() {
        let mut w = RgbdMcapWriter::new(Cursor::new(Vec::new()), &McapWriteOptions::default()).unwrap();
        let size = ImageSize::new(2, 1);
        w.write_depth_u16(TOPIC_DEPTH_IMAGE, 1, &[1, 2], size, 5000.0)
            .unwrap();
        w.write_depth_u16(TOPIC_DEPTH_IMAGE, 2, &[1, 2], size, 5000.0)
            .unwrap();
        let err = w
            .write_depth_u16(TOPIC_DEPTH_IMAGE, 3, &[1, 2], size, 1000.0)
            .unwrap_err();
        assert!(err.to_string().contains(TOPIC_DEPTH_IMAGE), "{err}");
    }

    #[test]
    fn topic_kind_conflict_is_an_error() {
        let mut w = RgbdMcapWriter::new(Cursor::new(Vec::new()), &McapWriteOptions::default()).unwrap();
        w.write_color_compressed(TOPIC_COLOR_IMAGE, 1, Bytes::from_static(b"x"), ColorFormat::Png)
            .unwrap();
        let rgb = Rgb8::filled(ImageSize::new(1, 1), [0, 0, 0]);
        assert!(w.write_color_raw(TOPIC_COLOR_IMAGE, 2, &rgb).is_err());
        assert_eq!(w.message_count(), 1);
        let bytes = w.finish().unwrap().into_inner();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.stats.unwrap().message_count, 1);
    }

    #[test]
    fn negative_levels_reach_the_codec() {
        // Depth with steps and sensor noise: compressible, so the level shows in the size.
        let size = ImageSize::new(160, 120);
        let mut rng = crate::xorshift::XorShift64::new(7);
        let frames: Vec<Vec<u16>> = (0..6)
            .map(|f| {
                (0..size.area())
                    .map(|i| (5000 + 40 * (i % 160) + 7 * f) as u16 + rng.below(16) as u16)
                    .collect()
            })
            .collect();
        let written = |compression: Compression, level: i32| {
            let options = McapWriteOptions {
                compression,
                compression_level: level,
                ..Default::default()
            };
            let mut w = RgbdMcapWriter::new(Cursor::new(Vec::new()), &options).unwrap();
            for (t, depth) in frames.iter().enumerate() {
                w.write_depth_u16(TOPIC_DEPTH_IMAGE, t as u64, depth, size, 5000.0)
                    .unwrap();
            }
            let bytes = w.finish().unwrap().into_inner();
            let messages: Vec<Vec<u8>> = mcap::MessageStream::new(&bytes)
                .unwrap()
                .map(|m| m.unwrap().data.into_owned())
                .collect();
            (bytes.len(), messages)
        };
        for compression in [Compression::Zstd, Compression::Lz4] {
            let (level_1, messages) = written(compression, 1);
            let (fast_5, fast_messages) = written(compression, -5);
            assert_eq!(messages.len(), frames.len());
            assert_eq!(fast_messages, messages);
            // A level clamped or wrapped to a positive one would compress at least as well.
            assert!(
                fast_5 > level_1,
                "{compression:?}: level -5 {fast_5} B, level 1 {level_1} B"
            );
        }
    }
}
