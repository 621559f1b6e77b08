//! `occmask process` for one file: read an RGB-D MCAP, pair colour with depth, run a
//! [`FrameProcessor`] per pair, and write the annotated copy or sidecar.
//!
//! Three threads per file, so the pipeline (DVO + detector, itself row-parallel on rayon) is
//! the only serial part: a prefetch thread reads, decompresses and decodes the images; the
//! frame loop (the calling thread) pairs colour with depth and runs the pipeline; a writer
//! thread encodes the new messages (mask, outlines, poses, stats), copies the input messages
//! and compresses the chunks. The writer makes the same calls in the same order as one
//! thread would, so the output bytes do not depend on thread timing. [`LoopTimings`] in the
//! report says where the frame loop waited.
//!
//! Memory is bounded whatever the file length: messages stream through (indexed, log-time
//! order when the file has a summary) with at most [`PREFETCH_BYTES`] read ahead and
//! [`WRITE_QUEUE_BYTES`] queued for writing, at most [`MAX_QUEUED_IMAGES`] colour and depth
//! images wait for a partner, and input messages wait only until no new message can be written
//! before them (new messages take the colour message's log time, so the output stays in
//! log-time order). The estimated trajectory is not kept: each pose goes to
//! [`ProcessHooks::frame_done`]. What does grow with the file is what the MCAP format puts in
//! the summary (one chunk index per output chunk, written at the end) and, with
//! `--pose-topic`, the external pose stream, which is read whole before the first frame.

use std::collections::{BTreeMap, VecDeque};
use std::io::{Seek, Write};
use std::sync::mpsc::{Receiver, Sender};
use std::time::Instant;

use nalgebra::Isometry3;
use prost::bytes::Bytes;

use crate::error::{Error, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::{CameraModel, LensDistortion};
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask, Rgb8};
use crate::mcap_io::annotate::{
    moving_pixels, AnnotateOptions, AnnotatedWriter, FrameAnnotation, FrameStatsMsg, JsonTime,
    METADATA_ODOMETRY_ANCHOR, METADATA_PROCESS, METADATA_PROCESSOR_CONFIG,
};
use crate::mcap_io::input::decode::{
    decode_calibration, decode_image, decode_poses, depth_from_image_into, gray_from_image_into, read_poses,
    rgb_from_image_into, CalibrationMsg,
};
use crate::mcap_io::input::detect::{detect_topics, RgbdTopics, TopicOverrides};
use crate::mcap_io::input::{InputChannel, McapInput, RawMessage, Truncation};
use crate::mcap_io::DEPTH_UNITS_KEY;
use crate::pipeline::offline::OfflineProcessor;
use crate::pipeline::{
    FrameInput, FrameOutput, PoseFallback, PoseSource, ProcessingMode, Processor, ProcessorConfig,
};
use crate::point_cloud::{PointGrid, POINT_STRIDE_BYTES};
use crate::time::split_ns;
use crate::trajectory::{interpolate, StampedPose};

pub mod batch;
mod queue;
pub mod rectify;
use queue::{byte_queue, ByteReceiver, ByteSender};
use rectify::{plan_geometry, GeometryOptions, InputGeometry, Publisher, Rectifier, StreamInfo};

/// Where camera poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PoseMode {
    /// The paper's closed loop: DVO with the previous mask excluding moving pixels.
    Dvo,
    /// The same DVO without the mask feedback (the paper's "Robust DVO" baseline).
    DvoUnmasked,
    /// Poses from a topic of the input, interpolated to each frame.
    External,
}

impl PoseMode {
    /// The name used on the command line and in `/occmask/stats`.
    pub fn as_str(self) -> &'static str {
        match self {
            PoseMode::Dvo => "dvo",
            PoseMode::DvoUnmasked => "dvo-unmasked",
            PoseMode::External => "external",
        }
    }
}

/// One RGB-D pair handed to a [`FrameProcessor`].
#[derive(Debug, Clone, Copy)]
pub struct RgbdFrame<'a> {
    /// The colour image's stamp.
    pub timestamp_ns: u64,
    /// Intensity, 0..1.
    pub gray: &'a GrayF32,
    /// Depth in metres, 0 = invalid.
    pub depth_m: &'a DepthMeters,
    /// The external pose at this frame ([`PoseMode::External`] only).
    pub world_from_camera: Option<Isometry3<f64>>,
}

/// What a [`FrameProcessor`] returns per frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessedFrame {
    /// Moving-object mask, 255 = moving.
    pub mask: Mask,
    /// Camera pose (first frame = identity for DVO modes).
    pub world_from_camera: Isometry3<f64>,
    /// The accumulation map, if the processor exposes it.
    pub accumulation: Option<Image<f32>>,
    /// Odometry outcome ([`crate::pipeline::PoseOutcome::as_str`]: `converged`, `first_frame`, `external`,
    /// `failed_*`, `rejected_*`, `no_depth`).
    pub dvo_status: String,
    /// Gauss–Newton iterations.
    pub dvo_iterations: u32,
    /// Final cost.
    pub dvo_cost: f64,
    /// How the pipeline handled the frame's failure modes.
    pub health: FrameHealth,
}

/// How the pipeline handled a frame's failure modes (see [`crate::pipeline`]): written to
/// `/occmask/stats`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameHealth {
    /// The fallback used for the motion.
    pub pose_fallback: PoseFallback,
    /// Frames in a row (this one included) whose motion was a fallback.
    pub consecutive_failures: u32,
    /// The detector's accumulation was discarded at this frame.
    pub detector_reset: bool,
    /// Fraction of pixels with valid depth.
    pub valid_depth_fraction: f64,
}

impl Default for FrameHealth {
    /// A healthy frame with full depth.
    fn default() -> Self {
        Self {
            pose_fallback: PoseFallback::None,
            consecutive_failures: 0,
            detector_reset: false,
            valid_depth_fraction: 1.0,
        }
    }
}

/// The per-sequence algorithm (DVO + detector) behind a small boundary, so reading and
/// writing can be tested with any implementation.
pub trait FrameProcessor {
    /// Adds the next frame (frames come in time order) and returns the results that are final
    /// now, oldest first: one per frame for a causal processor, none and then a block of them
    /// for one that looks ahead.
    ///
    /// # Errors
    /// Whatever the algorithm reports (e.g. size mismatches).
    fn push(&mut self, frame: &RgbdFrame<'_>) -> Result<Vec<ProcessedFrame>>;

    /// The results still pending at the end of the input, oldest first.
    ///
    /// # Errors
    /// As [`Self::push`].
    fn finish(&mut self) -> Result<Vec<ProcessedFrame>> {
        Ok(Vec::new())
    }
}

/// Builds the processor once intrinsics and image size are known, from the file's pose mode and
/// [`ProcessConfig::processor`].
pub type ProcessorFactory<'a> = dyn FnMut(PinholeIntrinsics, ImageSize, PoseMode, &ProcessorConfig) -> Result<Box<dyn FrameProcessor>>
    + 'a;

/// Colour–depth pairing tolerance by default: TUM's `associate.py` uses 20 ms; Kinect
/// colour and depth are at most half a 30 Hz frame (16.7 ms) apart.
pub const DEFAULT_PAIR_TOLERANCE_NS: u64 = 20_000_000;
/// External poses further apart than this around a frame are not interpolated (the frame is
/// reported as outside the pose stream): 10 frames at 30 Hz.
pub const DEFAULT_MAX_POSE_GAP_NS: u64 = 333_000_000;
/// Images waiting for a partner, per stream; beyond this the oldest is counted unpaired.
/// 64 frames is 2 s at 30 Hz, far more than any real colour/depth skew.
pub const MAX_QUEUED_IMAGES: usize = 64;
/// Depth units per metre when neither the flag nor channel metadata says: millimetres (ROS
/// REP 118 for `16UC1`).
pub const DEFAULT_DEPTH_UNITS_PER_METER: f64 = 1000.0;

/// Which frame the estimated trajectory (`/occmask/odometry`, `/tf`, `/occmask/path`, the
/// exported trajectory) is expressed in, for the DVO pose modes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OdometryAnchor {
    /// `world` is the first processed camera (its pose is the identity).
    FirstCamera,
    /// The frame of this pose channel when the file has it (default: `/groundtruth/pose`): the
    /// estimated pose of the first frame the channel covers (interpolated, samples at most
    /// [`ProcessConfig::max_pose_gap_ns`] apart) is set to the channel's pose there, so the
    /// estimated and ground-truth cameras coincide in Foxglove's 3D panel from that frame on and
    /// `world` means one frame in the whole file. A pose stream that starts a little after the
    /// images is normal: earlier frames are written once the anchor frame is known, in the same
    /// frame ([`ProcessReport::anchor_frame_ns`] says which frame anchored). Without the
    /// channel (or with no poses on it), as [`OdometryAnchor::FirstCamera`]; a channel that
    /// does not decode or covers no frame is not used either (the reason goes to
    /// [`ProcessReport::anchor_skipped`]: ground truth is not this command's input, and its
    /// messages are copied unchanged).
    IfPresent(String),
    /// Like [`OdometryAnchor::IfPresent`], but a missing or undecodable channel is an error
    /// too (`--anchor-topic`).
    Required(String),
}

impl Default for OdometryAnchor {
    fn default() -> Self {
        OdometryAnchor::IfPresent(crate::mcap_io::TOPIC_GROUNDTRUTH_POSE.to_owned())
    }
}

/// Options of [`process_file`].
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessConfig {
    /// Topics from the command line.
    pub topics: TopicOverrides,
    /// `--camera`: overrides the calibration topic.
    pub intrinsics: Option<PinholeIntrinsics>,
    /// With [`Self::intrinsics`]: the lens distortion of the `--camera` value.
    pub camera_distortion: Option<LensDistortion>,
    /// Depth registration and undistortion choices ([`rectify`]).
    pub geometry: GeometryOptions,
    /// `--depth-units-per-meter`: overrides channel metadata and the millimetre default.
    pub depth_units_per_meter: Option<f64>,
    /// Pose source.
    pub pose_mode: PoseMode,
    /// With [`PoseMode::External`] and transform topics: the child frame to follow
    /// (default: the first child frame on the topic).
    pub pose_child_frame: Option<String>,
    /// Max colour–depth stamp difference.
    pub pair_tolerance_ns: u64,
    /// Max gap between external poses around a frame.
    pub max_pose_gap_ns: u64,
    /// The frame of the estimated trajectory (DVO pose modes; external poses keep their own).
    pub anchor: OdometryAnchor,
    /// Only frames with colour stamps at or after this many ns after the first colour image.
    pub start_offset_ns: Option<u64>,
    /// Only frames before this many ns after the first colour image.
    pub end_offset_ns: Option<u64>,
    /// Measure decode/process times into `/occmask/stats` (makes output bytes
    /// non-deterministic).
    pub timings: bool,
    /// Output options.
    pub annotate: AnnotateOptions,
    /// DVO, detector and failure-policy parameters (`--config`; the pose source in it is
    /// ignored: [`Self::pose_mode`] decides). Recorded in the `occmask.process` metadata.
    pub processor: ProcessorConfig,
}

impl Default for ProcessConfig {
    fn default() -> Self {
        Self {
            topics: TopicOverrides::default(),
            intrinsics: None,
            camera_distortion: None,
            geometry: GeometryOptions::default(),
            depth_units_per_meter: None,
            pose_mode: PoseMode::Dvo,
            pose_child_frame: None,
            pair_tolerance_ns: DEFAULT_PAIR_TOLERANCE_NS,
            max_pose_gap_ns: DEFAULT_MAX_POSE_GAP_NS,
            anchor: OdometryAnchor::default(),
            start_offset_ns: None,
            end_offset_ns: None,
            timings: false,
            annotate: AnnotateOptions::default(),
            processor: ProcessorConfig::default(),
        }
    }
}

/// Counts and results of one file.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessReport {
    /// The channels used.
    pub topics: RgbdTopics,
    /// Intrinsics of the images the pipeline saw (the colour camera's K, magnified when its
    /// lens was undistorted; see [`rectify::InputGeometry::pipeline`]).
    pub intrinsics: PinholeIntrinsics,
    /// What was done to the images before the pipeline (registration, undistortion).
    pub geometry: InputGeometry,
    /// Depth units per metre used for 16-bit depth.
    pub depth_units_per_meter: f64,
    /// Colour messages read.
    pub color_messages: u64,
    /// Depth messages read.
    pub depth_messages: u64,
    /// Frames processed and written.
    pub frames: u64,
    /// Colour images without a depth partner within the tolerance.
    pub unpaired_color: u64,
    /// Depth images without a colour partner.
    pub unpaired_depth: u64,
    /// Pairs outside `--start`/`--end`.
    pub outside_time_range: u64,
    /// Pairs outside the external pose stream (not processed).
    pub outside_pose_stream: u64,
    /// Input messages copied.
    pub copied_messages: u64,
    /// New messages written.
    pub new_messages: u64,
    /// The input ended early (unfinished recording); everything readable was used.
    pub input_truncated: bool,
    /// Where a truncated input was cut and what was lost.
    pub input_truncation: Option<Truncation>,
    /// Colour/depth pairs whose stamp is not after the previous processed frame's (stamps
    /// going backwards or duplicated): skipped, since odometry and the detector need time
    /// order.
    pub out_of_order_frames: u64,
    /// Colour stamp of the last processed frame (frames must come after it). The trajectory
    /// itself is not kept, so memory stays flat however long the input is: it goes to
    /// [`ProcessHooks::frame_done`] frame by frame (e.g. `--export-trajectory` streams it).
    pub last_timestamp_ns: Option<u64>,
    /// Where the frame loop's wall-clock time went (never written to the output, so the
    /// output bytes stay deterministic).
    pub timings: LoopTimings,
    /// Why the [`OdometryAnchor`] channel was present but not used (it did not decode, or it
    /// covers no processed frame); `None` when anchored or when there was nothing to anchor to.
    pub anchor_skipped: Option<String>,
    /// The frame the odometry was anchored at: the first processed frame the anchor channel
    /// covers (`None` when not anchored).
    pub anchor_frame: Option<AnchorFrame>,
}

/// Which frame anchored the odometry ([`ProcessReport::anchor_frame`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnchorFrame {
    /// Its index among the processed frames (0 = the first).
    pub index: u64,
    /// Its colour stamp.
    pub timestamp_ns: u64,
}

/// Results held while no frame is covered by the anchor channel, at most (10 s at 30 Hz): a
/// pose stream that starts later than this is not used as the anchor (the first camera is
/// `world`, and the report says why), so memory stays bounded.
const MAX_UNANCHORED_FRAMES: usize = 300;

/// Where the frame loop's wall-clock time went, in seconds. The frame loop runs the pipeline;
/// a prefetch thread reads and decodes the input and a writer thread encodes, copies and
/// compresses the output, so `pipeline_s` close to `loop_s` means the pipeline is the only
/// serial part.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LoopTimings {
    /// From the start of reading to the last frame queued for writing.
    pub loop_s: f64,
    /// In the pipeline ([`FrameProcessor::process`]: DVO + detector).
    pub pipeline_s: f64,
    /// Undistorting and registering the images of the processed frames ([`rectify::Rectifier`],
    /// on the prefetch thread, beside the pipeline) and mapping their masks back (on the frame
    /// loop's thread, after the pipeline).
    pub rectify_s: f64,
    /// Waiting for the prefetch thread (reading, decompression, image decoding).
    pub input_wait_s: f64,
    /// Waiting for room in the writer thread's queue (encoding, compression, disk).
    pub output_wait_s: f64,
    /// The writer thread finishing what was queued after the loop ended.
    pub writer_tail_s: f64,
}

/// Callbacks during [`process_file`].
pub trait ProcessHooks {
    /// Called after each input message is read, with the count so far; `Break` stops
    /// processing with [`Error::Interrupted`] (e.g. Ctrl-C).
    fn messages_read(&mut self, _count: u64) -> std::ops::ControlFlow<()> {
        std::ops::ControlFlow::Continue(())
    }
    /// Called after each processed frame with its estimated pose (colour stamp) and mask
    /// (e.g. `--export-trajectory`, `--export-masks`).
    ///
    /// # Errors
    /// Stops processing with this error.
    fn frame_done(&mut self, _pose: &StampedPose, _mask: &Mask) -> Result<()> {
        Ok(())
    }
}

/// Hooks that do nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoHooks;
impl ProcessHooks for NoHooks {}

/// Decoded pixels of a queued image.
enum Pixels {
    Gray(GrayF32),
    Depth(DepthMeters),
}

/// A colour or depth image, decoded by the prefetch thread, waiting for its partner.
struct Queued {
    log_time_ns: u64,
    timestamp_ns: u64,
    frame_id: String,
    pixels: Pixels,
    decode_ms: f64,
    /// Seconds of it spent undistorting and registering.
    rectify_s: f64,
    /// A colour image's colours at the [`PointGrid`] samples (`--points`).
    point_colors: Option<Vec<[u8; 3]>>,
}

/// Processed image buffers on their way back to the prefetch thread.
struct BufferPool {
    gray: Receiver<GrayF32>,
    depth: Receiver<DepthMeters>,
    point_colors: Receiver<Vec<[u8; 3]>>,
}

/// What the prefetch thread hands over per input message.
struct Prefetched {
    /// The message (copied to the output in copy mode).
    message: RawMessage,
    /// The decoded image when the message is on the colour (`true`) or depth topic.
    image: Option<(bool, Queued)>,
}

/// Bytes (messages plus decoded pixels) the prefetch thread may read ahead of processing:
/// two VGA frames (1.5 MB of messages and 2.5 MB of decoded grey and depth each), so the next
/// frame is decoded while the current one is processed even with many small messages (pose
/// streams) between images, while memory stays flat. (It was 8 messages: less than one
/// TUM frame, whose 100 Hz motion capture puts ~36 messages between images, so decoding
/// stalled until the pipeline had finished the frame before.)
pub const PREFETCH_BYTES: usize = 8 << 20;
/// Messages the prefetch thread may read ahead, whatever their size.
pub const PREFETCH_MAX_MESSAGES: usize = 4096;

/// Bytes (copied messages, masks) the frame loop may queue ahead of the writer thread: about
/// four VGA frames (1.5 MB of copied messages and a 0.3 MB mask each), so a chunk flush does
/// not stall the pipeline.
pub const WRITE_QUEUE_BYTES: usize = 8 << 20;
/// Output operations queued ahead of the writer thread, whatever their size.
pub const WRITE_QUEUE_MAX_OPS: usize = 4096;

/// What the frame loop hands to the writer thread, in output order.
enum WriteOp {
    /// An input message, copied unchanged (annotated copy).
    Copy(RawMessage),
    /// One processed frame's new messages.
    Frame(Box<FrameWrite>),
}

/// Owned [`FrameAnnotation`]: everything the writer thread needs to encode one frame.
struct FrameWrite {
    log_time_ns: u64,
    timestamp_ns: u64,
    frame_id: String,
    mask: Mask,
    world_from_camera: Isometry3<f64>,
    accumulation: Option<Image<f32>>,
    points: Option<Bytes>,
    stats: FrameStatsMsg,
}

impl WriteOp {
    /// What the op holds in memory, for the queue's budget.
    fn bytes(&self) -> usize {
        match self {
            WriteOp::Copy(m) => m.data.len(),
            WriteOp::Frame(f) => {
                f.mask.as_slice().len()
                    + f.accumulation
                        .as_ref()
                        .map_or(0, |a| std::mem::size_of_val(a.as_slice()))
                    + f.points.as_ref().map_or(0, Bytes::len)
            }
        }
    }
}

/// The frame loop's end of the writer thread's queue.
struct OutputQueue {
    ops: ByteSender<WriteOp>,
    /// Time spent waiting for room in the queue.
    waited: std::cell::Cell<std::time::Duration>,
}

impl OutputQueue {
    /// Queues `op`. Fails only when the writer thread has stopped on an error, which
    /// [`process_file`] then reports instead of this placeholder.
    fn send(&self, op: WriteOp) -> Result<()> {
        let wait_start = Instant::now();
        let bytes = op.bytes();
        let sent = self.ops.send(op, bytes);
        self.waited.set(self.waited.get() + wait_start.elapsed());
        sent.map_err(|_| Error::Decode {
            topic: String::new(),
            message: "the output writer stopped".into(),
        })
    }
}

/// The writer thread: encodes the new messages (mask, contours, poses, path, stats),
/// copies input messages and compresses chunks, in queue order, so the frame loop only runs
/// the pipeline. Same calls in the same order as on one thread: the output bytes do not
/// change.
fn write_ops<W: Write + Seek>(
    mut writer: AnnotatedWriter<W>,
    ops: ByteReceiver<WriteOp>,
) -> Result<AnnotatedWriter<W>> {
    for op in ops {
        match op {
            WriteOp::Copy(m) => writer.copy_message(&m.header, &m.data)?,
            WriteOp::Frame(f) => writer.write_frame(&FrameAnnotation {
                log_time_ns: f.log_time_ns,
                timestamp_ns: f.timestamp_ns,
                frame_id: &f.frame_id,
                mask: &f.mask,
                world_from_camera: &f.world_from_camera,
                accumulation: f.accumulation.as_ref(),
                points: f.points.as_ref(),
                stats: &f.stats,
            })?,
        }
    }
    Ok(writer)
}

enum Pairing {
    Pair(Box<(Queued, Queued)>),
    UnpairedColor,
    UnpairedDepth,
}

impl Prefetched {
    /// What the item holds in memory, for the prefetch queue's budget.
    fn bytes(&self) -> usize {
        let pixels = match &self.image {
            Some((
                _,
                Queued {
                    pixels: Pixels::Gray(g),
                    ..
                },
            )) => std::mem::size_of_val(g.as_slice()),
            Some((
                _,
                Queued {
                    pixels: Pixels::Depth(d),
                    ..
                },
            )) => std::mem::size_of_val(d.as_slice()),
            None => 0,
        };
        let colors = match &self.image {
            Some((_, q)) => q
                .point_colors
                .as_ref()
                .map_or(0, |c| std::mem::size_of_val(c.as_slice())),
            None => 0,
        };
        self.message.data.len() + pixels + colors
    }
}

/// Greedy nearest-stamp pairing over two streams in time order.
struct Pairer {
    color: VecDeque<Queued>,
    depth: VecDeque<Queued>,
    tolerance_ns: u64,
}

impl Pairer {
    fn next(&mut self, end_of_stream: bool) -> Option<Pairing> {
        let tol = self.tolerance_ns;
        let (Some(c), Some(d)) = (self.color.front(), self.depth.front()) else {
            if (end_of_stream || self.color.len() > MAX_QUEUED_IMAGES) && self.color.pop_front().is_some() {
                return Some(Pairing::UnpairedColor);
            }
            if (end_of_stream || self.depth.len() > MAX_QUEUED_IMAGES) && self.depth.pop_front().is_some() {
                return Some(Pairing::UnpairedDepth);
            }
            return None;
        };
        let (tc, td) = (c.timestamp_ns, d.timestamp_ns);
        if td.saturating_add(tol) < tc {
            self.depth.pop_front();
            return Some(Pairing::UnpairedDepth);
        }
        if tc.saturating_add(tol) < td {
            self.color.pop_front();
            return Some(Pairing::UnpairedColor);
        }
        let ready = match self.depth.get(1) {
            Some(d2) => {
                if tc.abs_diff(d2.timestamp_ns) < tc.abs_diff(td) {
                    self.depth.pop_front();
                    return Some(Pairing::UnpairedDepth);
                }
                true
            }
            // A later depth could only be closer if this one is earlier than the colour.
            None => end_of_stream || td >= tc || self.color.len() > MAX_QUEUED_IMAGES,
        };
        if !ready {
            return None;
        }
        let c = self.color.pop_front()?;
        let d = self.depth.pop_front()?;
        Some(Pairing::Pair(Box::new((c, d))))
    }

    fn oldest_color_log_time(&self) -> Option<u64> {
        self.color.iter().map(|q| q.log_time_ns).min()
    }
}

/// Metadata keys describing a truncated input (`input_truncated`, `input_intact_bytes`,
/// `input_lost_bytes`, `input_messages_lost`, and `input_lost_log_time` when known).
pub fn truncation_metadata(t: &Truncation) -> Vec<(String, String)> {
    let mut v = vec![
        ("input_truncated".to_owned(), "true".to_owned()),
        ("input_intact_bytes".to_owned(), t.intact_bytes.to_string()),
        ("input_lost_bytes".to_owned(), t.lost_bytes.to_string()),
        ("input_messages_lost".to_owned(), (!t.messages_intact).to_string()),
        (
            "input_salvaged_messages".to_owned(),
            t.salvaged_messages.to_string(),
        ),
    ];
    if let Some((a, b)) = t.lost_log_time_range {
        v.push((
            "input_lost_log_time".to_owned(),
            format!(
                "{}..{}",
                crate::time::format_ns_as_seconds(a, 6),
                crate::time::format_ns_as_seconds(b, 6)
            ),
        ));
    }
    v
}

/// Adds which message failed (log time and sequence number, as a player shows them) to a
/// decode error, so the user can find the frame.
fn at_message(error: Error, header: &mcap::records::MessageHeader) -> Error {
    match error {
        Error::Decode { topic, message } => Error::Decode {
            topic,
            message: format!(
                "message at log time {} s (sequence {}): {message}",
                crate::time::format_ns_as_seconds(header.log_time, 6),
                header.sequence
            ),
        },
        other => other,
    }
}

fn missing_calibration(input: &McapInput, topics: &RgbdTopics, why: &str) -> Error {
    Error::Dataset {
        path: input.path().to_owned(),
        message: format!(
            "no camera calibration for {}: {why}; pass --camera FX,FY,CX,CY (or a preset such as fr2) \
             or --camera-info-topic TOPIC",
            topics.color.topic
        ),
    }
}

/// The first message of a calibration channel, decoded.
fn first_calibration(
    input: &McapInput,
    topics: &RgbdTopics,
    channel: &InputChannel,
) -> Result<CalibrationMsg> {
    let first = input
        .first_message(channel.id)?
        .ok_or_else(|| missing_calibration(input, topics, &format!("{} has no messages", channel.topic)))?;
    let ct = channel
        .channel_type
        .ok_or_else(|| missing_calibration(input, topics, "unsupported schema"))?;
    decode_calibration(ct, &channel.topic, &first.data).map_err(|e| at_message(e, &first.header))
}

/// `frame_id` and size of the first image of a colour (`is_color`) or depth channel: what
/// [`plan_geometry`] needs before the first frame.
fn first_image_info(
    input: &McapInput,
    channel: &InputChannel,
    is_color: bool,
    depth_units_per_meter: f64,
) -> Result<StreamInfo> {
    let ct = channel.channel_type.ok_or_else(|| Error::Decode {
        topic: channel.topic.clone(),
        message: "unsupported schema".into(),
    })?;
    let Some(first) = input.first_message(channel.id)? else {
        return Ok(StreamInfo {
            frame_id: String::new(),
            size: ImageSize::default(),
        });
    };
    let decode = || -> Result<StreamInfo> {
        let msg = decode_image(ct, &channel.topic, &first.data)?;
        let size = if is_color {
            let mut gray = GrayF32::filled(ImageSize::default(), 0.0);
            gray_from_image_into(&msg, &channel.topic, &mut gray)?;
            gray.size()
        } else {
            let mut depth = DepthMeters::filled(ImageSize::default(), 0.0);
            depth_from_image_into(&msg, &channel.topic, depth_units_per_meter, &mut depth)?;
            depth.size()
        };
        Ok(StreamInfo {
            frame_id: msg.frame_id,
            size,
        })
    };
    decode().map_err(|e| at_message(e, &first.header))
}

fn load_external_poses(
    input: &McapInput,
    topics: &RgbdTopics,
    config: &ProcessConfig,
) -> Result<Vec<StampedPose>> {
    let Some(channel) = &topics.pose else {
        return Err(Error::InvalidParameter {
            name: "--pose",
            value: "external".into(),
            expected: "a --pose-topic to read the poses from".into(),
        });
    };
    let ct = channel.channel_type.ok_or_else(|| Error::Decode {
        topic: channel.topic.clone(),
        message: "unsupported pose schema".into(),
    })?;
    let mut child = config.pose_child_frame.clone();
    let mut poses = Vec::new();
    input.for_each_message(Some(std::slice::from_ref(&channel.topic)), None, |m| {
        for sample in decode_poses(ct, &channel.topic, &m.data)? {
            if let Some(c) = &sample.child_frame {
                if c == crate::mcap_io::annotate::FRAME_CAMERA_ESTIMATED {
                    continue;
                }
                match &child {
                    None => child = Some(c.clone()),
                    Some(wanted) if wanted != c => continue,
                    Some(_) => {}
                }
            }
            poses.push(StampedPose {
                timestamp_ns: sample.timestamp_ns,
                world_from_camera: sample.parent_from_child,
            });
        }
        Ok(true)
    })?;
    poses.sort_by_key(|p| p.timestamp_ns);
    poses.dedup_by_key(|p| p.timestamp_ns);
    if poses.is_empty() {
        return Err(Error::Dataset {
            path: input.path().to_owned(),
            message: format!(
                "--pose-topic {}: no poses{}",
                channel.topic,
                child
                    .map(|c| format!(" with child frame {c}"))
                    .unwrap_or_default()
            ),
        });
    }
    Ok(poses)
}

/// The poses of the [`OdometryAnchor`] channel, with its topic; `None` when not anchoring.
fn load_anchor_poses(
    input: &McapInput,
    config: &ProcessConfig,
) -> Result<Option<(String, Vec<StampedPose>)>> {
    if config.pose_mode == PoseMode::External {
        return Ok(None); // external poses are already in their own world frame
    }
    let (topic, required) = match &config.anchor {
        OdometryAnchor::FirstCamera => return Ok(None),
        OdometryAnchor::IfPresent(t) => (t, false),
        OdometryAnchor::Required(t) => (t, true),
    };
    let poses = read_poses(input, topic).map_err(|e| match e {
        Error::Decode { topic, message } if required => Error::Decode {
            topic,
            message: format!("{message} (anchor poses: pass --no-anchor to ignore the channel)"),
        },
        other => other,
    })?;
    match (poses.is_empty(), required) {
        (false, _) => Ok(Some((topic.clone(), poses))),
        (true, false) => Ok(None),
        (true, true) => Err(Error::Dataset {
            path: input.path().to_owned(),
            message: format!(
                "--anchor-topic {topic}: no poses in the file (channels: {})",
                input
                    .channels()
                    .values()
                    .map(|c| c.topic.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }),
    }
}

/// `world_from_odometry` for the whole file, from the first processed frame: the anchor pose
/// at that frame times the inverse of the processor's pose there; identity without an anchor.
/// `world_from_odometry` from the anchor channel's pose at `stamp`: `None` when the channel
/// does not cover `stamp`.
fn anchor_at(
    poses: &[StampedPose],
    max_gap_ns: u64,
    stamp: u64,
    odometry_from_camera: &Isometry3<f64>,
) -> Option<Isometry3<f64>> {
    interpolate(poses, stamp, max_gap_ns)
        .map(|world_from_camera| world_from_camera * odometry_from_camera.inverse())
}

/// Processes one input file into `sink`; see the module documentation.
///
/// # Errors
/// [`Error::Dataset`] for missing channels or calibration (naming the flag that fixes it);
/// [`Error::Decode`] for undecodable or unsupported messages; [`Error::SizeMismatch`] when
/// colour and depth (or the calibration) differ in size; I/O and MCAP errors.
pub fn process_file<W: Write + Seek + Send>(
    input: &McapInput,
    sink: W,
    config: &ProcessConfig,
    make_processor: &mut ProcessorFactory<'_>,
    hooks: &mut dyn ProcessHooks,
) -> Result<(W, ProcessReport)> {
    let mut topics_override = config.topics.clone();
    if config.pose_mode != PoseMode::External {
        topics_override.pose = None;
    }
    let topics = detect_topics(input, &topics_override)?;

    // Calibration: the flag, else the first message of the calibration channel.
    let color_calibration = match &topics.calibration {
        Some(channel) => Some(first_calibration(input, &topics, channel)?),
        None => None,
    };
    let (intrinsics, distortion, calibration_size) = match (config.intrinsics, &color_calibration) {
        (Some(k), _) => (k, config.camera_distortion, None),
        (None, Some(calibration)) => {
            let topic = topics.calibration.as_ref().map_or("", |c| c.topic.as_str());
            let distortion = if config.geometry.no_undistort {
                // Reported, not used: an unsupported model is no error then.
                calibration.distortion(topic).ok().flatten()
            } else {
                calibration.distortion(topic)?
            };
            (calibration.intrinsics(topic)?, distortion, Some(calibration.size))
        }
        (None, None) => {
            return Err(missing_calibration(
                input,
                &topics,
                "the file has no CameraCalibration/CameraInfo channel",
            ))
        }
    };
    let depth_calibration = match &topics.depth_calibration {
        Some(channel) => Some(first_calibration(input, &topics, channel)?),
        None => None,
    };
    let depth_units_per_meter = match config.depth_units_per_meter {
        Some(u) => u,
        None => match topics.depth.metadata.get(DEPTH_UNITS_KEY) {
            Some(text) => text
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|u| u.is_finite() && *u > 0.0)
                .ok_or_else(|| Error::Decode {
                    topic: topics.depth.topic.clone(),
                    message: format!(
                        "channel metadata {DEPTH_UNITS_KEY} = {text:?} is not a positive number; \
                         pass --depth-units-per-meter"
                    ),
                })?,
            None => DEFAULT_DEPTH_UNITS_PER_METER,
        },
    };
    let color_stream = first_image_info(input, &topics.color, true, depth_units_per_meter)?;
    let depth_stream = first_image_info(input, &topics.depth, false, depth_units_per_meter)?;
    let geometry = plan_geometry(
        input,
        &topics,
        &color_stream,
        &depth_stream,
        CameraModel {
            size: color_stream.size,
            intrinsics,
            distortion,
        },
        color_calibration.as_ref(),
        depth_calibration.as_ref(),
        &config.geometry,
    )?;
    let (rectifier, publisher) = Rectifier::new(&geometry)?;
    // Points come from the pipeline's (undistorted, registered) depth, their colours from the
    // published colour image through the lens.
    let point_grid = config
        .annotate
        .points_stride_px
        .map(|stride| {
            PointGrid::new(
                &geometry.pipeline,
                geometry.undistort_color.then_some(&geometry.color),
                stride,
            )
        })
        .transpose()?;
    let external_poses = if config.pose_mode == PoseMode::External {
        load_external_poses(input, &topics, config)?
    } else {
        Vec::new()
    };
    let (anchor_poses, anchor_skipped) = match load_anchor_poses(input, config) {
        Ok(poses) => (poses, None),
        Err(e) if matches!(config.anchor, OdometryAnchor::IfPresent(_)) => (None, Some(e.to_string())),
        Err(e) => return Err(e),
    };

    let mut writer = AnnotatedWriter::new(sink, input, &config.annotate)?;
    let mut metadata = BTreeMap::from([
        ("tool".to_owned(), crate::mcap_io::LIBRARY.to_owned()),
        ("pose_source".to_owned(), config.pose_mode.as_str().to_owned()),
        ("color_topic".to_owned(), topics.color.topic.clone()),
        ("depth_topic".to_owned(), topics.depth.topic.clone()),
        (
            "intrinsics".to_owned(),
            format!(
                "{},{},{},{}",
                intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
            ),
        ),
        (DEPTH_UNITS_KEY.to_owned(), depth_units_per_meter.to_string()),
        (
            METADATA_PROCESSOR_CONFIG.to_owned(),
            serde_json::to_string(&config.processor).map_err(|e| Error::InvalidParameter {
                name: "processor config",
                value: e.to_string(),
                expected: "a configuration that serialises to JSON".into(),
            })?,
        ),
    ]);
    metadata.extend(geometry.metadata());
    if let Some(grid) = &point_grid {
        metadata.insert("points_stride_px".to_owned(), grid.stride_px().to_string());
    }
    if let Some((topic, _)) = &anchor_poses {
        metadata.insert(METADATA_ODOMETRY_ANCHOR.to_owned(), topic.clone());
    }
    if let Some(t) = input.truncation() {
        // Recorded only for damaged inputs, so complete inputs keep their exact bytes.
        metadata.extend(truncation_metadata(t));
    }
    writer.write_metadata(METADATA_PROCESS, metadata)?;

    let color_ct = topics.color.channel_type.ok_or_else(|| Error::Decode {
        topic: topics.color.topic.clone(),
        message: "unsupported schema".into(),
    })?;
    let depth_ct = topics.depth.channel_type.ok_or_else(|| Error::Decode {
        topic: topics.depth.topic.clone(),
        message: "unsupported schema".into(),
    })?;
    let copy = config.annotate.copy_input;
    let read_topics: Option<Vec<String>> = if copy {
        None
    } else {
        Some(vec![topics.color.topic.clone(), topics.depth.topic.clone()])
    };

    // Image buffers go back from the frame loop to the prefetch thread once processed, so
    // decoding reuses them instead of allocating and zero-filling 2.4 MB per VGA frame.
    let (gray_tx, gray_rx) = std::sync::mpsc::channel();
    let (depth_tx, depth_rx) = std::sync::mpsc::channel();
    let (colors_tx, colors_rx) = std::sync::mpsc::channel();
    let pool_rx = BufferPool {
        gray: gray_rx,
        depth: depth_rx,
        point_colors: colors_rx,
    };
    let mut state = FrameLoop {
        pairer: Pairer {
            color: VecDeque::new(),
            depth: VecDeque::new(),
            tolerance_ns: config.pair_tolerance_ns,
        },
        pending: VecDeque::new(),
        in_flight: VecDeque::new(),
        unanchored: Vec::new(),
        gray: GrayF32::filled(ImageSize::new(0, 0), 0.0),
        depth_m: DepthMeters::filled(ImageSize::new(0, 0), 0.0),
        recycle: (gray_tx, depth_tx),
        recycle_point_colors: colors_tx,
        spare_point_depth: Vec::new(),
        publisher,
        processor: None,
        world_from_odometry: None,
        first_color_ns: None,
        report: ProcessReport {
            topics: topics.clone(),
            intrinsics: geometry.pipeline.intrinsics,
            geometry: geometry.clone(),
            depth_units_per_meter,
            color_messages: 0,
            depth_messages: 0,
            frames: 0,
            unpaired_color: 0,
            unpaired_depth: 0,
            outside_time_range: 0,
            outside_pose_stream: 0,
            copied_messages: 0,
            new_messages: 0,
            input_truncated: input.is_truncated(),
            input_truncation: input.truncation().copied(),
            out_of_order_frames: 0,
            last_timestamp_ns: None,
            timings: LoopTimings::default(),
            anchor_skipped,
            anchor_frame: None,
        },
    };
    let ctx = FrameContext {
        config,
        topics: &topics,
        // The pipeline sees the undistorted pinhole camera (its K when the lens was undistorted
        // into a magnified K; see rectify::inscribed_pinhole).
        intrinsics: geometry.pipeline.intrinsics,
        calibration_size,
        external_poses: &external_poses,
        anchor_poses: anchor_poses.as_ref().map(|(t, p)| (t.as_str(), p.as_slice())),
        point_grid: point_grid.as_ref(),
    };
    // A prefetch thread reads and decodes (PNG/JPEG, depth scaling) while this thread runs the
    // pipeline and writes: decoding then overlaps with processing.
    let point_grid = point_grid.as_ref();
    let decode = |m: &RawMessage,
                  pool: &BufferPool,
                  rectifier: &mut Rectifier,
                  rgb: &mut Rgb8|
     -> Result<Option<(bool, Queued)>> {
        let id = m.header.channel_id;
        if id != topics.color.id && id != topics.depth.id {
            return Ok(None);
        }
        let is_color = id == topics.color.id;
        let start = config.timings.then(Instant::now);
        let (ct, topic) = if is_color {
            (color_ct, &topics.color.topic)
        } else {
            (depth_ct, &topics.depth.topic)
        };
        let decoded = decode_image(ct, topic, &m.data).and_then(|msg| {
            // Decoded, then undistorted and registered for the pipeline.
            let mut point_colors = None;
            let (pixels, rectify_s) = if is_color {
                let mut gray = pool
                    .gray
                    .try_recv()
                    .unwrap_or_else(|_| GrayF32::filled(ImageSize::new(0, 0), 0.0));
                let s = rectifier.color(topic, &mut gray, |g| gray_from_image_into(&msg, topic, g))?;
                if let Some(grid) = point_grid {
                    // A second decode, into RGB (the grey one keeps its own conversion, so
                    // the masks do not depend on --points); only the samples are kept.
                    rgb_from_image_into(&msg, topic, rgb)?;
                    let mut colors = pool.point_colors.try_recv().unwrap_or_default();
                    grid.sample_colors_into(rgb, &mut colors)?;
                    point_colors = Some(colors);
                }
                (Pixels::Gray(gray), s)
            } else {
                let mut depth = pool
                    .depth
                    .try_recv()
                    .unwrap_or_else(|_| DepthMeters::filled(ImageSize::new(0, 0), 0.0));
                let s = rectifier.depth(topic, &mut depth, |d| {
                    depth_from_image_into(&msg, topic, depth_units_per_meter, d)
                })?;
                (Pixels::Depth(depth), s)
            };
            Ok((msg, pixels, rectify_s, point_colors))
        });
        let (msg, pixels, rectify_s, point_colors) = decoded.map_err(|e| at_message(e, &m.header))?;
        Ok(Some((
            is_color,
            Queued {
                log_time_ns: m.header.log_time,
                timestamp_ns: msg.timestamp_ns,
                frame_id: msg.frame_id,
                pixels,
                decode_ms: start.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3),
                rectify_s,
                point_colors,
            },
        )))
    };
    let loop_start = Instant::now();
    let mut output_wait = std::time::Duration::ZERO;
    let (mut loop_s, mut writer_tail_s) = (0.0, 0.0);
    let (loop_result, writer_result) = std::thread::scope(|scope| {
        let (write_tx, write_rx) = byte_queue::<WriteOp>(WRITE_QUEUE_BYTES, WRITE_QUEUE_MAX_OPS);
        let writer_thread = scope.spawn(move || write_ops(writer, write_rx));
        let output = OutputQueue {
            ops: write_tx,
            waited: std::cell::Cell::new(std::time::Duration::ZERO),
        };
        let (tx, rx) = byte_queue::<Result<Prefetched>>(PREFETCH_BYTES, PREFETCH_MAX_MESSAGES);
        let read_topics = read_topics.as_deref();
        let decode = &decode;
        let mut rectifier = rectifier;
        scope.spawn(move || {
            let mut rgb = Rgb8::filled(ImageSize::new(0, 0), [0; 3]);
            let result = input.for_each_message(read_topics, None, |message| {
                let item = decode(&message, &pool_rx, &mut rectifier, &mut rgb)
                    .map(|image| Prefetched { message, image });
                let bytes = item.as_ref().map_or(0, Prefetched::bytes);
                let failed = item.is_err();
                // A closed channel means the consumer stopped (error or Ctrl-C): stop reading.
                Ok(tx.send(item, bytes).is_ok() && !failed)
            });
            if let Err(e) = result {
                let _ = tx.send(Err(e), 0);
            }
        });
        let frame_loop = || -> Result<()> {
            let mut read = 0u64;
            // `rx` moves into the loop and is dropped on any early return, which stops the
            // prefetch thread.
            let mut rx = rx;
            loop {
                let wait_start = Instant::now();
                let Some(item) = rx.next() else { break };
                state.report.timings.input_wait_s += wait_start.elapsed().as_secs_f64();
                let Prefetched { message, image } = item?;
                read += 1;
                if hooks.messages_read(read).is_break() {
                    return Err(Error::Interrupted {
                        done: read as usize,
                        total: input.message_count().unwrap_or(read) as usize,
                    });
                }
                match image {
                    Some((true, queued)) => {
                        state.report.color_messages += 1;
                        state.first_color_ns.get_or_insert(queued.timestamp_ns);
                        state.pairer.color.push_back(queued);
                    }
                    Some((false, queued)) => {
                        state.report.depth_messages += 1;
                        state.pairer.depth.push_back(queued);
                    }
                    None => {}
                }
                if copy {
                    state.pending.push_back(message);
                }
                state.drain(&ctx, &output, make_processor, hooks, false)?;
            }
            state.drain(&ctx, &output, make_processor, hooks, true)
        };
        let loop_result = frame_loop();
        loop_s = loop_start.elapsed().as_secs_f64();
        output_wait = output.waited.get();
        // Closing the queue ends the writer thread once it has written everything queued.
        drop(output);
        let writer_result = writer_thread
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        writer_tail_s = loop_start.elapsed().as_secs_f64() - loop_s;
        (loop_result, writer_result)
    });
    // A writer error (e.g. a full disk) is the cause when both failed: the frame loop only
    // saw the closed queue.
    let writer = writer_result?;
    loop_result?;
    state.report.timings.output_wait_s = output_wait.as_secs_f64();
    state.report.timings.loop_s = loop_s;
    state.report.timings.writer_tail_s = writer_tail_s;
    state.report.copied_messages = writer.copied_messages();
    state.report.new_messages = writer.new_messages();
    let sink = writer.finish()?;
    Ok((sink, state.report))
}

struct FrameContext<'a> {
    config: &'a ProcessConfig,
    topics: &'a RgbdTopics,
    intrinsics: PinholeIntrinsics,
    calibration_size: Option<ImageSize>,
    external_poses: &'a [StampedPose],
    /// [`OdometryAnchor`]: the channel and its poses, when the trajectory is anchored.
    anchor_poses: Option<(&'a str, &'a [StampedPose])>,
    /// The samples of `--points`.
    point_grid: Option<&'a PointGrid>,
}

struct FrameLoop {
    pairer: Pairer,
    pending: VecDeque<RawMessage>,
    /// Frames given to the processor whose results have not come back yet (oldest first).
    in_flight: VecDeque<InFlight>,
    /// Results waiting for the first frame the anchor channel covers (oldest first).
    unanchored: Vec<(InFlight, ProcessedFrame)>,
    gray: GrayF32,
    depth_m: DepthMeters,
    /// Maps masks back to the published colour pixels (the input side of the registration
    /// and undistortion runs on the prefetch thread).
    publisher: Publisher,
    processor: Option<Box<dyn FrameProcessor>>,
    /// Maps the processor's `world` (its first camera) into the output's `world`; set at the
    /// first processed frame ([`OdometryAnchor`]).
    world_from_odometry: Option<Isometry3<f64>>,
    first_color_ns: Option<u64>,
    report: ProcessReport,
    /// Returns processed image buffers to the prefetch thread.
    recycle: (Sender<GrayF32>, Sender<DepthMeters>),
    /// Returns the point colour samples to the prefetch thread.
    recycle_point_colors: Sender<Vec<[u8; 3]>>,
    /// Depth sample buffers of `--points` not in use.
    spare_point_depth: Vec<Vec<f32>>,
}

/// What the frame loop keeps of a frame while the processor works on it.
struct InFlight {
    log_time_ns: u64,
    timestamp_ns: u64,
    frame_id: String,
    decode_ms: f64,
    process_ms: f64,
    /// `--points`: the frame's samples until its mask is known, then its packed points.
    points: Option<PointSamples>,
    cloud: Option<Bytes>,
}

/// The depth and colour of a frame at the [`PointGrid`] samples.
struct PointSamples {
    depth_m: Vec<f32>,
    colors: Vec<[u8; 3]>,
}

impl FrameLoop {
    /// Pairs what can be paired, processes the pairs, and copies input messages that can no
    /// longer have new messages written before them.
    fn drain(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        make_processor: &mut ProcessorFactory<'_>,
        hooks: &mut dyn ProcessHooks,
        end_of_stream: bool,
    ) -> Result<()> {
        while let Some(p) = self.pairer.next(end_of_stream) {
            match p {
                Pairing::UnpairedColor => self.report.unpaired_color += 1,
                Pairing::UnpairedDepth => self.report.unpaired_depth += 1,
                Pairing::Pair(pair) => {
                    let (c, d) = *pair;
                    self.frame(ctx, output, make_processor, hooks, c, d)?
                }
            }
        }
        if end_of_stream {
            if let Some(processor) = &mut self.processor {
                let pipeline_start = Instant::now();
                let results = processor.finish()?;
                self.report.timings.pipeline_s += pipeline_start.elapsed().as_secs_f64();
                for result in results {
                    self.write_result(ctx, output, hooks, result)?;
                }
            }
            if !self.unanchored.is_empty() {
                self.give_up_anchor(ctx);
                self.flush_unanchored(ctx, output, hooks)?;
            }
        }
        // New messages are still to come for frames being paired or processed: input messages
        // after the oldest of them wait.
        let limit = if end_of_stream {
            u64::MAX
        } else {
            let pairing = self.pairer.oldest_color_log_time().unwrap_or(u64::MAX);
            let held = self.unanchored.first().map(|(f, _)| f.log_time_ns);
            let processing = held
                .or(self.in_flight.front().map(|f| f.log_time_ns))
                .unwrap_or(u64::MAX);
            pairing.min(processing)
        };
        while self.pending.front().is_some_and(|m| m.header.log_time <= limit) {
            if let Some(m) = self.pending.pop_front() {
                output.send(WriteOp::Copy(m))?;
            }
        }
        Ok(())
    }

    fn frame(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        make_processor: &mut ProcessorFactory<'_>,
        hooks: &mut dyn ProcessHooks,
        color: Queued,
        depth: Queued,
    ) -> Result<()> {
        let stamp = color.timestamp_ns;
        let offset = stamp.saturating_sub(self.first_color_ns.unwrap_or(stamp));
        let before_start = ctx.config.start_offset_ns.is_some_and(|s| offset < s);
        let after_end = ctx.config.end_offset_ns.is_some_and(|e| offset >= e);
        if before_start || after_end {
            self.report.outside_time_range += 1;
            return Ok(());
        }
        if self.report.last_timestamp_ns.is_some_and(|last| stamp <= last) {
            self.report.out_of_order_frames += 1;
            return Ok(());
        }
        let external = if ctx.config.pose_mode == PoseMode::External {
            match interpolate(ctx.external_poses, stamp, ctx.config.max_pose_gap_ns) {
                Some(p) => Some(p),
                None => {
                    self.report.outside_pose_stream += 1;
                    return Ok(());
                }
            }
        } else {
            None
        };
        let decode_ms = color.decode_ms + depth.decode_ms;
        let rectify_s = color.rectify_s + depth.rectify_s;
        let point_colors = color.point_colors;
        if let (Pixels::Gray(gray), Pixels::Depth(depth_m)) = (color.pixels, depth.pixels) {
            // The receiver is gone once the prefetch thread has finished: nothing to recycle.
            let _ = self.recycle.0.send(std::mem::replace(&mut self.gray, gray));
            let _ = self.recycle.1.send(std::mem::replace(&mut self.depth_m, depth_m));
        }
        // The prefetch thread checked both sizes against the first images and rectified depth
        // into the colour camera.
        let size = self.gray.size();
        if let Some(cal) = ctx.calibration_size.filter(|c| c.area() > 0 && *c != size) {
            return Err(Error::SizeMismatch {
                what: format!(
                    "calibration vs colour {} (pass --camera FX,FY,CX,CY for the image size)",
                    ctx.topics.color.topic
                ),
                expected: size,
                found: cal,
            });
        }
        // The depth the pipeline sees, sampled before its buffer goes back to the prefetch thread.
        let points = match (ctx.point_grid, point_colors) {
            (Some(grid), Some(colors)) => {
                let mut depth_m = self.spare_point_depth.pop().unwrap_or_default();
                grid.sample_depth_into(&self.depth_m, &mut depth_m)?;
                Some(PointSamples { depth_m, colors })
            }
            _ => None,
        };
        let processor = match &mut self.processor {
            Some(p) => p,
            None => self.processor.insert(make_processor(
                ctx.intrinsics,
                size,
                ctx.config.pose_mode,
                &ctx.config.processor,
            )?),
        };
        let pipeline_start = Instant::now();
        let results = processor.push(&RgbdFrame {
            timestamp_ns: stamp,
            gray: &self.gray,
            depth_m: &self.depth_m,
            world_from_camera: external,
        })?;
        let pipeline_s = pipeline_start.elapsed().as_secs_f64();
        self.report.timings.pipeline_s += pipeline_s;
        self.report.timings.rectify_s += rectify_s;
        self.report.last_timestamp_ns = Some(stamp);
        self.in_flight.push_back(InFlight {
            log_time_ns: color.log_time_ns,
            timestamp_ns: stamp,
            frame_id: color.frame_id,
            decode_ms,
            // Measured always (the report), written only with --timings (output bytes).
            process_ms: if ctx.config.timings { pipeline_s * 1e3 } else { 0.0 },
            points,
            cloud: None,
        });
        for result in results {
            self.write_result(ctx, output, hooks, result)?;
        }
        Ok(())
    }

    /// Takes the oldest in-flight frame's result: written at once when the odometry's frame is
    /// known, else held until the first frame the anchor channel covers.
    fn write_result(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
        mut result: ProcessedFrame,
    ) -> Result<()> {
        let mut frame = self
            .in_flight
            .pop_front()
            .ok_or_else(|| Error::InvalidParameter {
                name: "frame processor",
                value: "a result for a frame it was not given".into(),
                expected: "one result per frame pushed (internal error)".into(),
            })?;
        if let (Some(grid), Some(samples)) = (ctx.point_grid, frame.points.take()) {
            // Tinted by the mask in the pipeline's pixels, before it is mapped back.
            let mut data = Vec::with_capacity(grid.samples() * POINT_STRIDE_BYTES);
            grid.write_points(&samples.depth_m, &samples.colors, &result.mask, &mut data)?;
            frame.cloud = Some(Bytes::from(data));
            self.spare_point_depth.push(samples.depth_m);
            // The receiver is gone once the prefetch thread has finished: nothing to recycle.
            let _ = self.recycle_point_colors.send(samples.colors);
        }
        if !self.publisher.is_identity() {
            // Back from the pipeline's undistorted pixels to the published colour image's.
            let back_start = Instant::now();
            result.mask = self.publisher.to_published(result.mask)?;
            result.accumulation = result
                .accumulation
                .map(|a| self.publisher.to_published(a))
                .transpose()?;
            self.report.timings.rectify_s += back_start.elapsed().as_secs_f64();
        }
        if self.world_from_odometry.is_none() {
            match ctx.anchor_poses {
                None => self.world_from_odometry = Some(Isometry3::identity()),
                Some((_, poses)) => {
                    match anchor_at(
                        poses,
                        ctx.config.max_pose_gap_ns,
                        frame.timestamp_ns,
                        &result.world_from_camera,
                    ) {
                        Some(anchor) => {
                            self.world_from_odometry = Some(anchor);
                            self.report.anchor_frame = Some(AnchorFrame {
                                index: self.report.frames + self.unanchored.len() as u64,
                                timestamp_ns: frame.timestamp_ns,
                            });
                            self.flush_unanchored(ctx, output, hooks)?;
                        }
                        None if self.unanchored.len() < MAX_UNANCHORED_FRAMES => {
                            self.unanchored.push((frame, result));
                            return Ok(());
                        }
                        None => {
                            self.give_up_anchor(ctx);
                            self.flush_unanchored(ctx, output, hooks)?;
                        }
                    }
                }
            }
        }
        self.emit(ctx, output, hooks, frame, result)
    }

    /// No frame is covered by the anchor channel (within [`MAX_UNANCHORED_FRAMES`]): the first
    /// camera is `world`.
    fn give_up_anchor(&mut self, ctx: &FrameContext<'_>) {
        if let Some((topic, _)) = ctx.anchor_poses {
            self.report.anchor_skipped = Some(format!(
                "{topic} has no pose within {} ms of the first {} processed frames",
                ctx.config.max_pose_gap_ns / 1_000_000,
                self.unanchored.len()
            ));
        }
        self.world_from_odometry = Some(Isometry3::identity());
    }

    /// Writes the held results, now that the odometry's frame is known.
    fn flush_unanchored(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
    ) -> Result<()> {
        for (frame, result) in std::mem::take(&mut self.unanchored) {
            self.emit(ctx, output, hooks, frame, result)?;
        }
        Ok(())
    }

    /// Writes one frame's result (and the input messages before it) in the anchored frame.
    fn emit(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
        frame: InFlight,
        result: ProcessedFrame,
    ) -> Result<()> {
        let stamp = frame.timestamp_ns;
        let size = result.mask.size();
        // Copy everything that precedes this frame's new messages.
        while self
            .pending
            .front()
            .is_some_and(|m| m.header.log_time <= frame.log_time_ns)
        {
            if let Some(m) = self.pending.pop_front() {
                output.send(WriteOp::Copy(m))?;
            }
        }
        let moving = moving_pixels(&result.mask);
        let (sec, nsec) = split_ns(stamp);
        let stats = FrameStatsMsg {
            timestamp: JsonTime {
                sec: sec.into(),
                nsec,
            },
            frame_index: self.report.frames,
            pose_source: ctx.config.pose_mode.as_str().into(),
            dvo_status: result.dvo_status.clone(),
            dvo_iterations: result.dvo_iterations,
            dvo_cost: finite_or_zero(result.dvo_cost),
            pose_fallback: result.health.pose_fallback.as_str().into(),
            consecutive_failures: result.health.consecutive_failures,
            detector_reset: result.health.detector_reset,
            valid_depth_fraction: finite_or_zero(result.health.valid_depth_fraction),
            moving_fraction: moving as f64 / size.area().max(1) as f64,
            moving_pixels: moving,
            decode_ms: finite_or_zero(frame.decode_ms),
            process_ms: finite_or_zero(frame.process_ms),
        };
        let world_from_odometry = self.world_from_odometry.unwrap_or_else(Isometry3::identity);
        let pose = StampedPose {
            timestamp_ns: stamp,
            world_from_camera: world_from_odometry * result.world_from_camera,
        };
        hooks.frame_done(&pose, &result.mask)?;
        output.send(WriteOp::Frame(Box::new(FrameWrite {
            log_time_ns: frame.log_time_ns,
            timestamp_ns: stamp,
            frame_id: frame.frame_id,
            mask: result.mask,
            world_from_camera: pose.world_from_camera,
            accumulation: result.accumulation,
            points: frame.cloud,
            stats,
        })))?;
        self.report.frames += 1;
        Ok(())
    }
}

/// The per-sequence pipeline (DVO + detector: [`crate::pipeline::Processor`] in the causal
/// mode, [`crate::pipeline::offline::OfflineProcessor`] in the offline one) behind
/// [`FrameProcessor`].
pub struct PipelineProcessor {
    pipeline: Pipeline,
    mode: PoseMode,
    keep_accumulation: bool,
}

enum Pipeline {
    Causal(Box<Processor>),
    Offline(Box<OfflineProcessor>),
}

/// Choices of [`PipelineProcessor`] beyond the pose mode and the processor configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PipelineOptions {
    /// Copy the accumulation map into every [`ProcessedFrame`] (`--accumulation`).
    pub keep_accumulation: bool,
    /// [`PoseMode::External`]: the marker's pose in the camera frame, for poses of a
    /// motion-capture marker that is not at the optical centre (`--camera-from-marker`).
    pub camera_from_marker: Option<Isometry3<f64>>,
}

impl PipelineProcessor {
    /// A pipeline for `mode` with the DVO, detector and failure parameters of `config` (its
    /// pose source is replaced by `mode`'s; [`ProcessorConfig::mode`] picks causal or offline).
    ///
    /// # Errors
    /// Invalid intrinsics, image size or parameters, as [`Processor::new`].
    pub fn new(
        intrinsics: PinholeIntrinsics,
        size: ImageSize,
        mode: PoseMode,
        config: &ProcessorConfig,
        options: PipelineOptions,
    ) -> Result<Self> {
        let pose_source = match mode {
            PoseMode::Dvo => PoseSource::DvoClosedLoop,
            PoseMode::DvoUnmasked => PoseSource::DvoUnmasked,
            PoseMode::External => PoseSource::External {
                camera_from_marker: options.camera_from_marker,
            },
        };
        let config = ProcessorConfig {
            pose_source,
            ..*config
        };
        let pipeline = match config.mode {
            ProcessingMode::Causal => Pipeline::Causal(Box::new(Processor::new(size, intrinsics, config)?)),
            ProcessingMode::Offline => {
                Pipeline::Offline(Box::new(OfflineProcessor::new(size, intrinsics, config)?))
            }
        };
        Ok(Self {
            pipeline,
            mode,
            keep_accumulation: options.keep_accumulation,
        })
    }

    fn processed_with(out: &FrameOutput<'_>, mode: PoseMode, keep_accumulation: bool) -> ProcessedFrame {
        let stats = &out.stats;
        let (dvo_iterations, dvo_cost) = match (&stats.dvo, mode) {
            (Some(d), PoseMode::Dvo | PoseMode::DvoUnmasked) => {
                (d.iterations_per_level.iter().sum(), d.final_cost)
            }
            _ => (0, 0.0),
        };
        ProcessedFrame {
            mask: out.mask.clone(),
            world_from_camera: out.world_from_camera,
            accumulation: keep_accumulation.then(|| out.accumulation_m.clone()),
            dvo_status: stats.outcome.as_str().to_owned(),
            dvo_iterations,
            dvo_cost,
            health: FrameHealth {
                pose_fallback: stats.pose_fallback,
                consecutive_failures: stats.consecutive_failures,
                detector_reset: stats.detector_reset,
                valid_depth_fraction: stats.valid_depth_fraction,
            },
        }
    }
}

impl FrameProcessor for PipelineProcessor {
    fn push(&mut self, frame: &RgbdFrame<'_>) -> Result<Vec<ProcessedFrame>> {
        let input = FrameInput {
            timestamp_ns: frame.timestamp_ns,
            gray: frame.gray,
            depth_m: frame.depth_m,
            world_from_marker: frame.world_from_camera.as_ref(),
            ignore_in_previous: None,
        };
        let mut done = Vec::new();
        let (keep_accumulation, mode) = (self.keep_accumulation, self.mode);
        let convert = |out: &FrameOutput<'_>| PipelineProcessor::processed_with(out, mode, keep_accumulation);
        match &mut self.pipeline {
            Pipeline::Causal(processor) => done.push(convert(&processor.process(&input)?)),
            Pipeline::Offline(processor) => processor.push(&input, &mut |out| {
                done.push(convert(&out));
                Ok(())
            })?,
        }
        Ok(done)
    }

    fn finish(&mut self) -> Result<Vec<ProcessedFrame>> {
        let mut done = Vec::new();
        let (keep_accumulation, mode) = (self.keep_accumulation, self.mode);
        if let Pipeline::Offline(processor) = &mut self.pipeline {
            processor.finish(&mut |out| {
                done.push(PipelineProcessor::processed_with(&out, mode, keep_accumulation));
                Ok(())
            })?;
        }
        Ok(done)
    }
}

/// `value`, or 0 when it is NaN or infinite (JSON has no NaN: serde_json would write `null`,
/// which the schema's `number` fields reject).
fn finite_or_zero(value: f64) -> f64 {
    if value.is_finite() {
        value
    } else {
        0.0
    }
}

/// The production [`ProcessorFactory`]: a [`PipelineProcessor`] per file.
pub fn pipeline_factory(
    options: PipelineOptions,
) -> impl FnMut(PinholeIntrinsics, ImageSize, PoseMode, &ProcessorConfig) -> Result<Box<dyn FrameProcessor>> {
    move |intrinsics, size, mode, config| {
        Ok(
            Box::new(PipelineProcessor::new(intrinsics, size, mode, config, options)?)
                as Box<dyn FrameProcessor>,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

    /// `--appearance-growth` reaches the detector: on a box that starts moving, the pipeline
    /// with the completion marks more of the box than the paper's.
    #[test]
    fn appearance_growth_option_switches_the_detector_stage() -> Result<()> {
        let config = SequenceConfig {
            size: ImageSize::new(320, 240),
            ..SequenceConfig::default()
        };
        let sequence = SyntheticSequence::new(Scenario::StillThenMoving, config);
        let run = |appearance_growth: bool| -> Result<u64> {
            let mut processor_config = ProcessorConfig {
                mode: ProcessingMode::Causal,
                ..ProcessorConfig::default()
            };
            processor_config.occlusion.appearance_growth =
                appearance_growth.then(crate::occlusion::AppearanceGrowthConfig::default);
            let mut pipeline = PipelineProcessor::new(
                config.intrinsics(),
                config.size,
                PoseMode::External,
                &processor_config,
                PipelineOptions::default(),
            )?;
            let mut last_mask = 0;
            for i in 26..38 {
                let frame = sequence.frame(i);
                for out in pipeline.push(&RgbdFrame {
                    timestamp_ns: frame.timestamp_ns,
                    gray: &frame.gray,
                    depth_m: &frame.depth_m,
                    world_from_camera: Some(sequence.world_from_camera(i)),
                })? {
                    last_mask = moving_pixels(&out.mask);
                }
            }
            Ok(last_mask)
        };
        let (with_growth, paper) = (run(true)?, run(false)?);
        assert!(with_growth > paper, "{with_growth} vs {paper}");
        Ok(())
    }
}
