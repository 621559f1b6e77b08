//! [`AnnotatedWriter`]: the output of `occmask process`, an annotated copy of an input file
//! (or a sidecar with only the new channels).
//!
//! Copy mode registers every input schema and channel under its own ID first
//! (`add_schema_with_id`/`add_channel_with_id`: registering new channels before them makes
//! mcap 0.26 panic on ID collisions), then the new schemas and channels get
//! the next free IDs. Input messages are written with their original header (channel,
//! sequence, log and publish time) and bytes.
//!
//! Metadata and attachments (the input's and our own) are held back and written after the
//! last message, in [`AnnotatedWriter::finish`]: mcap 0.26 closes the open chunk before each
//! metadata or attachment record, so writing them up front left chunks holding only schemas
//! and channels, with no message index. Foxglove's and Lichtblick's MCAP reader (`@mcap/core`
//! `McapIndexedReader`) refuses such a chunk ("Chunks without message indexes are not
//! currently supported") whenever its (0, 0) time range overlaps the playback range, i.e. for
//! every file whose messages start at log time 0, such as `occmask demo`'s.
//!
//! New channels (all protobuf Foxglove schemas except the stats):
//!
//! | topic | schema |
//! |---|---|
//! | [`TOPIC_MASK`] | `foxglove.RawImage` `mono8`, 255 = moving, colour image's stamp and frame |
//! | [`TOPIC_MASK_ANNOTATIONS`] | `foxglove.ImageAnnotations`, outlines with translucent fill |
//! | [`TOPIC_ODOMETRY`] | `foxglove.PoseInFrame` in [`FRAME_WORLD`] |
//! | `/tf` (or [`TOPIC_TF_FALLBACK`]) | `foxglove.FrameTransform` world → [`FRAME_CAMERA_ESTIMATED`] |
//! | [`TOPIC_PATH`] | `foxglove.PosesInFrame`, throttled trajectory so far, and at the last frame |
//! | [`TOPIC_ANCHOR_PATH`] | `foxglove.PosesInFrame`, the anchor pose channel's trajectory at the frames, throttled (when anchored) |
//! | [`TOPIC_ACCUMULATION`] | `foxglove.RawImage` `32FC1` accumulation map (opt-in) |
//! | [`TOPIC_POINTS`] | `foxglove.PointCloud` in [`FRAME_CAMERA_ESTIMATED`], moving points tinted (opt-in; [`crate::point_cloud`]) |
//! | [`TOPIC_STATS`] | JSON, schema `schemas/occmask.FrameStats.json` |

use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};

use foxglove::messages::{
    packed_element_field::NumericType, points_annotation, Color, ImageAnnotations, PackedElementField,
    Point2, PointCloud, PointsAnnotation, PosesInFrame, RawImage,
};
use foxglove::Encode;
use mcap::records::MessageHeader;
use nalgebra::Isometry3;
use prost::bytes::Bytes;
use serde::Serialize;

use crate::contour::{outer_contours, ContourOptions};
use crate::error::{Error, Result};
use crate::image_buf::{Image, Mask, MASK_SET};
use crate::point_cloud::{OFFSET_RED, OFFSET_X, OFFSET_Y, OFFSET_Z, POINT_STRIDE_BYTES};
use crate::simd::{simd_kernel, Simd};

use super::codec;
use super::encoding::DepthEncoding;
use super::input::{ExtraRecord, McapInput};
use super::writer::McapWriteOptions;
use super::{ENCODING_PROTOBUF, FRAME_WORLD, SCHEMA_FRAME_TRANSFORM, TOPIC_TF};

/// Moving-object mask, `mono8`.
pub const TOPIC_MASK: &str = "/occmask/mask";
/// Outlines of the moving regions for the Image panel.
pub const TOPIC_MASK_ANNOTATIONS: &str = "/occmask/mask_annotations";
/// Estimated camera pose.
pub const TOPIC_ODOMETRY: &str = "/occmask/odometry";
/// Estimated trajectory so far (throttled).
pub const TOPIC_PATH: &str = "/occmask/path";
/// The anchor pose channel's trajectory (the ground truth of a converted dataset) at the
/// processed frames, so far (throttled): drawn beside [`TOPIC_PATH`] in the same frame.
pub const TOPIC_ANCHOR_PATH: &str = "/occmask/anchor_path";
/// Accumulation map (opt-in).
pub const TOPIC_ACCUMULATION: &str = "/occmask/accumulation";
/// Downsampled coloured points of each frame (opt-in).
pub const TOPIC_POINTS: &str = "/occmask/points";
/// Per-frame statistics (JSON).
pub const TOPIC_STATS: &str = "/occmask/stats";
/// Transform topic used instead of `/tf` when the input's `/tf` has another schema (e.g. ROS 2
/// `tf2_msgs/msg/TFMessage`), so one topic never carries two schemas.
pub const TOPIC_TF_FALLBACK: &str = "/occmask/tf";
/// The prefix of every topic occmask writes, but the transforms on `/tf`.
pub const TOPIC_PREFIX: &str = "/occmask/";
/// The estimated camera frame (child of [`FRAME_WORLD`]).
pub const FRAME_CAMERA_ESTIMATED: &str = "camera_estimated";
/// Schema name of the stats messages.
pub const SCHEMA_FRAME_STATS: &str = "occmask.FrameStats";
/// The JSON Schema of [`TOPIC_STATS`] (also in `schemas/` for other tools).
pub const FRAME_STATS_JSON_SCHEMA: &str = include_str!("../../schemas/occmask.FrameStats.json");
/// Name of the metadata record describing the run.
pub const METADATA_PROCESS: &str = "occmask.process";
/// Key in [`METADATA_PROCESS`]: the pose channel whose frame `world` is (the odometry starts at
/// that channel's pose); absent when `world` is the first processed camera.
pub const METADATA_ODOMETRY_ANCHOR: &str = "odometry_anchor_topic";
/// Key in [`METADATA_PROCESS`]: the DVO, detector and failure-policy parameters used, as the
/// JSON that `occmask process --config` reads.
pub const METADATA_PROCESSOR_CONFIG: &str = "processor_config";

/// The path is published at most this often (data time): enough for a live-looking
/// trajectory without one message per frame. The last frame's path is published too
/// ([`AnnotatedWriter::end_paths`]), so the path reaches the camera at the end.
pub const PATH_PUBLISH_INTERVAL_NS: u64 = 1_000_000_000;
/// At most this many poses per path message: when the trajectory grows beyond it, every other
/// pose is dropped (the stride doubles), so messages stay small and the file grows linearly.
pub const MAX_PATH_POSES: usize = 512;

/// Annotation fill: translucent red, so the colour image stays visible underneath.
const FILL_COLOR: Color = Color {
    r: 1.0,
    g: 0.1,
    b: 0.1,
    a: 0.35,
};
/// Outline: opaque red.
const OUTLINE_COLOR: Color = Color {
    r: 1.0,
    g: 0.1,
    b: 0.1,
    a: 1.0,
};
/// Outline thickness in pixels.
const OUTLINE_THICKNESS_PX: f64 = 2.0;

/// What to write.
#[derive(Debug, Clone, PartialEq)]
pub struct AnnotateOptions {
    /// Copy every input schema, channel, message, metadata record and attachment (annotated
    /// copy); `false` writes only the new channels (sidecar).
    pub copy_input: bool,
    /// Write [`TOPIC_ACCUMULATION`].
    pub accumulation: bool,
    /// Write [`TOPIC_POINTS`], sampling every this many pixels per axis (`None`: not written;
    /// [`crate::point_cloud::DEFAULT_POINT_STRIDE_PX`] is the command line's default).
    pub points_stride_px: Option<usize>,
    /// Compression and chunking.
    pub write: McapWriteOptions,
    /// Outline extraction.
    pub contours: ContourOptions,
    /// When copying an input that an earlier run annotated ([`earlier_annotation_topics`]),
    /// leave out that run's channels, its [`FRAME_WORLD`] → [`FRAME_CAMERA_ESTIMATED`]
    /// transforms on `/tf` and its [`METADATA_PROCESS`] records, so that this run's take their
    /// place instead of mixing with them on the same channels.
    pub replace_earlier: bool,
}

impl Default for AnnotateOptions {
    fn default() -> Self {
        Self {
            copy_input: true,
            accumulation: false,
            points_stride_px: None,
            write: McapWriteOptions::default(),
            contours: ContourOptions::default(),
            replace_earlier: false,
        }
    }
}

/// JSON `{"sec", "nsec"}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct JsonTime {
    /// Seconds.
    pub sec: u64,
    /// Nanoseconds.
    pub nsec: u32,
}

/// One `/occmask/stats` message (see `schemas/occmask.FrameStats.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameStatsMsg {
    /// Colour image stamp.
    pub timestamp: JsonTime,
    /// 0-based index of the processed pair.
    pub frame_index: u64,
    /// `dvo`, `dvo-unmasked` or `external`.
    pub pose_source: String,
    /// Outcome of the frame's odometry.
    pub dvo_status: String,
    /// Gauss–Newton iterations.
    pub dvo_iterations: u32,
    /// Final cost.
    pub dvo_cost: f64,
    /// The motion fallback used: `none`, `constant_velocity` or `hold`.
    pub pose_fallback: String,
    /// Frames in a row (this one included) whose motion was a fallback.
    pub consecutive_failures: u32,
    /// The detector's accumulation was discarded at this frame.
    pub detector_reset: bool,
    /// Fraction of pixels with valid depth.
    pub valid_depth_fraction: f64,
    /// Fraction of pixels marked moving.
    pub moving_fraction: f64,
    /// Pixels marked moving.
    pub moving_pixels: u64,
    /// Decode time, ms (0 unless timings are requested).
    pub decode_ms: f64,
    /// Processing time, ms (0 unless timings are requested).
    pub process_ms: f64,
}

/// Everything written for one processed frame.
#[derive(Debug, Clone, Copy)]
pub struct FrameAnnotation<'a> {
    /// MCAP log time of the new messages: the colour message's log time.
    pub log_time_ns: u64,
    /// The colour image's own stamp (Foxglove matches annotations by it).
    pub timestamp_ns: u64,
    /// The colour image's frame.
    pub frame_id: &'a str,
    /// Moving mask (0 / 255).
    pub mask: &'a Mask,
    /// Estimated pose.
    pub world_from_camera: &'a Isometry3<f64>,
    /// The anchor channel's pose at this frame, when the trajectory is anchored and the channel
    /// covers the frame (written with [`AnnotatedWriter::add_anchor_path`]).
    pub anchor_pose: Option<&'a Isometry3<f64>>,
    /// Accumulation map, written when enabled.
    pub accumulation: Option<&'a Image<f32>>,
    /// Packed points ([`crate::point_cloud`]'s layout) in the camera's frame, written when
    /// enabled.
    pub points: Option<&'a Bytes>,
    /// Statistics.
    pub stats: &'a FrameStatsMsg,
}

struct NewChannels {
    mask: u16,
    annotations: u16,
    odometry: u16,
    tf: u16,
    path: u16,
    anchor_path: Option<u16>,
    accumulation: Option<u16>,
    points: Option<u16>,
    stats: u16,
}

/// Writes an annotated copy or a sidecar; see the module documentation.
pub struct AnnotatedWriter<W: Write + Seek> {
    writer: mcap::Writer<W>,
    channels: NewChannels,
    sequences: HashMap<u16, u32>,
    contours: ContourOptions,
    path: PathTrail,
    anchor_path: PathTrail,
    /// The latest log time written so far ([`Self::end_paths`] writes at it, so log times
    /// never go backwards).
    latest_log_time_ns: u64,
    copied_messages: u64,
    new_messages: u64,
    /// The input channels of an earlier run, left out ([`AnnotateOptions::replace_earlier`]).
    replaced_channels: Vec<u16>,
    /// The input's `/tf` channel, whose earlier-run transforms are left out.
    replaced_tf_channel: Option<u16>,
    replaced_messages: u64,
    scratch: Vec<u8>,
    /// Metadata and attachments written by [`Self::finish`], after the last message (see the
    /// module documentation for why not earlier).
    deferred: Vec<ExtraRecord>,
}

/// A trajectory published as a growing [`PosesInFrame`] at most every
/// [`PATH_PUBLISH_INTERVAL_NS`] (data time), thinned to at most [`MAX_PATH_POSES`] poses.
#[derive(Debug)]
struct PathTrail {
    poses: Vec<foxglove::messages::Pose>,
    stride: usize,
    frames_seen: usize,
    last_publish_ns: Option<u64>,
    /// The last frame's stamp and pose, when its path is not published yet.
    unpublished: Option<(u64, foxglove::messages::Pose)>,
}

impl Default for PathTrail {
    fn default() -> Self {
        Self {
            poses: Vec::new(),
            stride: 1,
            frames_seen: 0,
            last_publish_ns: None,
            unpublished: None,
        }
    }
}

impl PathTrail {
    /// Adds the pose of the frame at `timestamp_ns`; the message to publish when one is due.
    fn update(&mut self, timestamp_ns: u64, pose: foxglove::messages::Pose) -> Option<PosesInFrame> {
        if self.frames_seen.is_multiple_of(self.stride) {
            self.poses.push(pose);
            if self.poses.len() > MAX_PATH_POSES {
                // Keep every other pose; the first (index 0) stays so the path starts right.
                let mut i = 0;
                self.poses.retain(|_| {
                    i += 1;
                    (i - 1) % 2 == 0
                });
                self.stride *= 2;
            }
        }
        self.frames_seen += 1;
        let due = self
            .last_publish_ns
            .is_none_or(|last| timestamp_ns >= last.saturating_add(PATH_PUBLISH_INTERVAL_NS));
        if !due {
            self.unpublished = Some((timestamp_ns, pose));
            return None;
        }
        Some(self.publish(timestamp_ns, pose))
    }

    /// The path up to the last frame, when it was not published with that frame.
    fn end(&mut self) -> Option<PosesInFrame> {
        let (timestamp_ns, pose) = self.unpublished.take()?;
        Some(self.publish(timestamp_ns, pose))
    }

    fn publish(&mut self, timestamp_ns: u64, pose: foxglove::messages::Pose) -> PosesInFrame {
        let mut poses = self.poses.clone();
        // Always end at the current pose, even when the stride skipped it.
        if poses.last() != Some(&pose) {
            poses.push(pose);
        }
        self.last_publish_ns = Some(timestamp_ns);
        self.unpublished = None;
        PosesInFrame {
            timestamp: Some(codec::timestamp(timestamp_ns)),
            frame_id: FRAME_WORLD.into(),
            poses,
        }
    }
}

/// The topics of `input`'s channels that an earlier `occmask process` run wrote (those under
/// [`TOPIC_PREFIX`]), sorted: a new run's channels would share them.
pub fn earlier_annotation_topics(input: &McapInput) -> Vec<String> {
    let mut topics: Vec<String> = input
        .channels()
        .values()
        .filter(|c| written_by_occmask(&c.topic))
        .map(|c| c.topic.clone())
        .collect();
    topics.sort_unstable();
    topics.dedup();
    topics
}

/// True for a topic an occmask run writes, but `/tf`: one that [`earlier_annotation_topics`]
/// reports and [`AnnotateOptions::replace_earlier`] leaves out.
fn written_by_occmask(topic: &str) -> bool {
    topic.starts_with(TOPIC_PREFIX)
}

/// True for a protobuf `foxglove.FrameTransform` that an occmask run wrote.
fn is_estimated_camera_transform(data: &[u8]) -> bool {
    use prost::Message as _;
    foxglove::messages::FrameTransform::decode(data)
        .is_ok_and(|t| t.parent_frame_id == FRAME_WORLD && t.child_frame_id == FRAME_CAMERA_ESTIMATED)
}

/// The transform topic to write for `input`: `/tf` unless the input has a `/tf` channel with
/// another schema than protobuf `foxglove.FrameTransform`.
pub fn tf_topic_for(input: &McapInput) -> &'static str {
    let clash = input.channels().values().any(|c| {
        c.topic == TOPIC_TF
            && (c.schema_name != SCHEMA_FRAME_TRANSFORM || c.message_encoding != ENCODING_PROTOBUF)
    });
    if clash {
        TOPIC_TF_FALLBACK
    } else {
        TOPIC_TF
    }
}

fn schema_of<T: Encode>() -> Result<foxglove::Schema> {
    T::get_schema().ok_or_else(|| Error::InvalidParameter {
        name: "schema",
        value: std::any::type_name::<T>().into(),
        expected: "a Foxglove message type with an embedded schema".into(),
    })
}

impl<W: Write + Seek> AnnotatedWriter<W> {
    /// Starts the output on `sink`: header, input schemas/channels, metadata and attachments
    /// (copy mode), then the new schemas and channels.
    ///
    /// # Errors
    /// [`Error::Mcap`] when a record cannot be written; I/O errors reading the input's extras.
    pub fn new(sink: W, input: &McapInput, options: &AnnotateOptions) -> Result<Self> {
        let profile = if options.copy_input { input.profile() } else { "" };
        let mut writer = options.write.mcap_options().profile(profile).create(sink)?;
        let mut deferred = Vec::new();
        let (mut replaced_channels, mut replaced_tf_channel) = (Vec::new(), None);
        if options.copy_input {
            for s in input.schemas().values() {
                writer.add_schema_with_id(s.id, &s.name, &s.encoding, &s.data)?;
            }
            for c in input.channels().values() {
                if options.replace_earlier && written_by_occmask(&c.topic) {
                    replaced_channels.push(c.id);
                    continue;
                }
                if options.replace_earlier
                    && c.topic == TOPIC_TF
                    && c.schema_name == SCHEMA_FRAME_TRANSFORM
                    && c.message_encoding == ENCODING_PROTOBUF
                {
                    replaced_tf_channel = Some(c.id);
                }
                writer.add_channel_with_id(c.id, c.schema_id, &c.topic, &c.message_encoding, &c.metadata)?;
            }
            deferred = input.extras()?;
            if options.replace_earlier {
                deferred.retain(|r| !matches!(r, ExtraRecord::Metadata(m) if m.name == METADATA_PROCESS));
            }
        }
        let mut add = |topic: &str, schema: foxglove::Schema| -> Result<u16> {
            let schema_id = writer.add_schema(&schema.name, &schema.encoding, &schema.data)?;
            Ok(writer.add_channel(schema_id, topic, ENCODING_PROTOBUF, &BTreeMap::new())?)
        };
        let raw_image = schema_of::<RawImage>()?;
        let mask = add(TOPIC_MASK, raw_image.clone())?;
        let annotations = add(TOPIC_MASK_ANNOTATIONS, schema_of::<ImageAnnotations>()?)?;
        let odometry = add(TOPIC_ODOMETRY, schema_of::<foxglove::messages::PoseInFrame>()?)?;
        let tf = add(
            tf_topic_for(input),
            schema_of::<foxglove::messages::FrameTransform>()?,
        )?;
        let path = add(TOPIC_PATH, schema_of::<PosesInFrame>()?)?;
        let accumulation = if options.accumulation {
            Some(add(TOPIC_ACCUMULATION, raw_image)?)
        } else {
            None
        };
        let points = match options.points_stride_px {
            Some(_) => Some(add(TOPIC_POINTS, schema_of::<PointCloud>()?)?),
            None => None,
        };
        let stats_schema = writer.add_schema(
            SCHEMA_FRAME_STATS,
            "jsonschema",
            FRAME_STATS_JSON_SCHEMA.as_bytes(),
        )?;
        let stats = writer.add_channel(stats_schema, TOPIC_STATS, "json", &BTreeMap::new())?;
        Ok(Self {
            writer,
            channels: NewChannels {
                mask,
                annotations,
                odometry,
                tf,
                path,
                anchor_path: None,
                accumulation,
                points,
                stats,
            },
            sequences: HashMap::new(),
            contours: options.contours,
            path: PathTrail::default(),
            anchor_path: PathTrail::default(),
            latest_log_time_ns: 0,
            copied_messages: 0,
            new_messages: 0,
            replaced_channels,
            replaced_tf_channel,
            replaced_messages: 0,
            scratch: Vec::new(),
            deferred,
        })
    }

    /// Copies an input message unchanged (header and bytes), unless it is an earlier run's
    /// ([`AnnotateOptions::replace_earlier`]).
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure or an unknown channel (sidecar mode).
    pub fn copy_message(&mut self, header: &MessageHeader, data: &[u8]) -> Result<()> {
        let channel = header.channel_id;
        if self.replaced_channels.contains(&channel)
            || (self.replaced_tf_channel == Some(channel) && is_estimated_camera_transform(data))
        {
            self.replaced_messages += 1;
            return Ok(());
        }
        self.writer.write_to_known_channel(header, data)?;
        self.latest_log_time_ns = self.latest_log_time_ns.max(header.log_time);
        self.copied_messages += 1;
        Ok(())
    }

    fn write_new(&mut self, channel_id: u16, log_time_ns: u64, encoded: Option<&[u8]>) -> Result<()> {
        let sequence = self.sequences.entry(channel_id).or_insert(0);
        let header = MessageHeader {
            channel_id,
            sequence: *sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        *sequence = sequence.wrapping_add(1);
        let data = encoded.unwrap_or(&self.scratch);
        self.writer.write_to_known_channel(&header, data)?;
        self.latest_log_time_ns = self.latest_log_time_ns.max(log_time_ns);
        self.new_messages += 1;
        Ok(())
    }

    fn write_proto<M: Encode>(&mut self, channel_id: u16, log_time_ns: u64, msg: &M) -> Result<()> {
        self.scratch.clear();
        msg.encode(&mut self.scratch).map_err(|e| Error::Encode {
            topic: format!("channel {channel_id}"),
            what: "message",
            reason: e.to_string(),
        })?;
        self.write_new(channel_id, log_time_ns, None)
    }

    /// Writes the new messages of one frame.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure.
    pub fn write_frame(&mut self, frame: &FrameAnnotation<'_>) -> Result<()> {
        let t = frame.log_time_ns;
        let stamp = codec::timestamp(frame.timestamp_ns);
        let mask_msg = codec::mask_image(frame.timestamp_ns, frame.frame_id, frame.mask)?;
        self.write_proto(self.channels.mask, t, &mask_msg)?;

        let annotations = ImageAnnotations {
            timestamp: Some(stamp),
            points: outer_contours(frame.mask, &self.contours)
                .into_iter()
                .map(|polygon| PointsAnnotation {
                    timestamp: Some(stamp),
                    r#type: points_annotation::Type::LineLoop as i32,
                    points: polygon.into_iter().map(|[x, y]| Point2 { x, y }).collect(),
                    outline_color: Some(OUTLINE_COLOR),
                    outline_colors: Vec::new(),
                    fill_color: Some(FILL_COLOR),
                    thickness: OUTLINE_THICKNESS_PX,
                    metadata: Vec::new(),
                })
                .collect(),
            ..Default::default()
        };
        self.write_proto(self.channels.annotations, t, &annotations)?;

        let pose = codec::pose_in_frame(frame.timestamp_ns, FRAME_WORLD, frame.world_from_camera);
        self.write_proto(self.channels.odometry, t, &pose)?;
        let tf = codec::frame_transform(
            frame.timestamp_ns,
            FRAME_WORLD,
            FRAME_CAMERA_ESTIMATED,
            frame.world_from_camera,
        );
        self.write_proto(self.channels.tf, t, &tf)?;

        if let Some(msg) = self
            .path
            .update(frame.timestamp_ns, pose.pose.unwrap_or_default())
        {
            self.write_proto(self.channels.path, t, &msg)?;
        }
        if let (Some(id), Some(anchor)) = (self.channels.anchor_path, frame.anchor_pose) {
            let anchor = codec::pose_in_frame(frame.timestamp_ns, FRAME_WORLD, anchor);
            if let Some(msg) = self
                .anchor_path
                .update(frame.timestamp_ns, anchor.pose.unwrap_or_default())
            {
                self.write_proto(id, t, &msg)?;
            }
        }

        if let (Some(id), Some(acc)) = (self.channels.accumulation, frame.accumulation) {
            let data: Vec<u8> = acc.as_slice().iter().flat_map(|v| v.to_le_bytes()).collect();
            let msg = RawImage {
                timestamp: Some(stamp),
                frame_id: frame.frame_id.to_owned(),
                width: acc.width() as u32,
                height: acc.height() as u32,
                // One f32 per pixel, the same layout as float depth.
                encoding: DepthEncoding::F32.as_str().into(),
                step: (acc.width() * 4) as u32,
                data: Bytes::from(data),
            };
            self.write_proto(id, t, &msg)?;
        }

        if let (Some(id), Some(data)) = (self.channels.points, frame.points) {
            let field = |name: &str, offset: usize, numeric: NumericType| PackedElementField {
                name: name.into(),
                offset: offset as u32,
                r#type: numeric as i32,
            };
            let msg = PointCloud {
                timestamp: Some(stamp),
                // The points are in the camera's optical frame, whose pose is the odometry's
                // transform world -> camera_estimated.
                frame_id: FRAME_CAMERA_ESTIMATED.into(),
                pose: codec::pose_in_frame(0, "", &Isometry3::identity()).pose,
                point_stride: POINT_STRIDE_BYTES as u32,
                fields: vec![
                    field("x", OFFSET_X, NumericType::Float32),
                    field("y", OFFSET_Y, NumericType::Float32),
                    field("z", OFFSET_Z, NumericType::Float32),
                    field("red", OFFSET_RED, NumericType::Uint8),
                    field("green", OFFSET_RED + 1, NumericType::Uint8),
                    field("blue", OFFSET_RED + 2, NumericType::Uint8),
                    field("alpha", OFFSET_RED + 3, NumericType::Uint8),
                ],
                data: data.clone(),
            };
            self.write_proto(id, t, &msg)?;
        }

        let json = serde_json::to_vec(frame.stats).map_err(|e| Error::Encode {
            topic: TOPIC_STATS.into(),
            what: "stats",
            reason: e.to_string(),
        })?;
        self.write_new(self.channels.stats, t, Some(&json))?;
        Ok(())
    }

    /// Adds [`TOPIC_ANCHOR_PATH`]; call before the first frame, when the trajectory is
    /// anchored to a pose channel.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure.
    pub fn add_anchor_path(&mut self) -> Result<()> {
        let schema = schema_of::<PosesInFrame>()?;
        let schema_id = self
            .writer
            .add_schema(&schema.name, &schema.encoding, &schema.data)?;
        let id =
            self.writer
                .add_channel(schema_id, TOPIC_ANCHOR_PATH, ENCODING_PROTOBUF, &BTreeMap::new())?;
        self.channels.anchor_path = Some(id);
        Ok(())
    }

    /// Adds a metadata record; it is written by [`Self::finish`], after the last message.
    ///
    /// # Errors
    /// None today; kept fallible so callers need not change if it writes at once again.
    pub fn write_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        self.deferred.push(ExtraRecord::Metadata(mcap::records::Metadata {
            name: name.into(),
            metadata,
        }));
        Ok(())
    }

    /// Input messages copied so far.
    pub fn copied_messages(&self) -> u64 {
        self.copied_messages
    }

    /// Input messages of an earlier run left out so far ([`AnnotateOptions::replace_earlier`]).
    pub fn replaced_messages(&self) -> u64 {
        self.replaced_messages
    }

    /// New messages written so far.
    pub fn new_messages(&self) -> u64 {
        self.new_messages
    }

    /// Publishes the paths up to the last frame written, where that frame did not publish
    /// them (they are published at most every [`PATH_PUBLISH_INTERVAL_NS`]): stamped with that
    /// frame's time and logged at the latest log time written. Call it after the last frame.
    ///
    /// # Errors
    /// [`Error::Mcap`] on write failure.
    pub fn end_paths(&mut self) -> Result<()> {
        let t = self.latest_log_time_ns;
        if let Some(msg) = self.path.end() {
            self.write_proto(self.channels.path, t, &msg)?;
        }
        if let (Some(id), Some(msg)) = (self.channels.anchor_path, self.anchor_path.end()) {
            self.write_proto(id, t, &msg)?;
        }
        Ok(())
    }

    /// Writes the held-back metadata and attachments (input's first, then ours), the summary
    /// and the footer, and returns the sink.
    ///
    /// # Errors
    /// [`Error::Mcap`] when a record, the summary or the footer cannot be written.
    pub fn finish(mut self) -> Result<W> {
        for extra in std::mem::take(&mut self.deferred) {
            match extra {
                ExtraRecord::Metadata(m) => self.writer.write_metadata(&m)?,
                ExtraRecord::Attachment {
                    log_time,
                    create_time,
                    name,
                    media_type,
                    data,
                } => self.writer.attach(&mcap::Attachment {
                    log_time,
                    create_time,
                    name,
                    media_type,
                    data: std::borrow::Cow::Owned(data),
                })?,
            }
        }
        self.writer.finish()?;
        Ok(self.writer.into_inner())
    }
}

/// Number of pixels set in `mask`.
pub fn moving_pixels(mask: &Mask) -> u64 {
    count_set(Simd::detect(), mask.as_slice()) as u64
}

#[inline(always)]
fn count_set_generic(mask: &[u8]) -> usize {
    mask.iter().filter(|&&v| v == MASK_SET).count()
}

simd_kernel!(count_set, count_set_avx2, count_set_generic, (mask: &[u8]) -> usize);

#[cfg(test)]
mod tests {
    use super::*;

    /// Every build counts the set pixels only (not other nonzero values), as a per-pixel loop.
    #[test]
    fn every_build_counts_the_set_pixels() {
        let mask: Vec<u8> = (0..1001u32)
            .map(|i| [0, MASK_SET, 1, 254, MASK_SET][(i % 5) as usize])
            .collect();
        let mut set = 0;
        for &v in &mask {
            if v == MASK_SET {
                set += 1;
            }
        }
        for simd in Simd::available() {
            assert_eq!(count_set(simd, &mask), set, "{simd:?}");
        }
    }
}
