//! What the caller gives [`super::process_file`]: the options ([`ProcessConfig`], the odometry's
//! frame [`OdometryAnchor`]) and the callbacks ([`ProcessHooks`]).

use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::LensDistortion;
use crate::image_buf::Mask;
use crate::mcap_io::annotate::AnnotateOptions;
use crate::mcap_io::input::detect::TopicOverrides;
use crate::pipeline::ProcessorConfig;
use crate::trajectory::StampedPose;
use crate::Result;

use super::rectify::GeometryOptions;
#[cfg(doc)]
use super::{process_file, ProcessReport};
#[cfg(doc)]
use crate::pipeline::PoseSource;
#[cfg(doc)]
use crate::Error;

/// Colour–depth pairing tolerance by default: TUM's `associate.py` uses 20 ms; Kinect
/// colour and depth are at most half a 30 Hz frame (16.7 ms) apart.
pub const DEFAULT_PAIR_TOLERANCE_NS: u64 = 20_000_000;
/// External poses further apart than this around a frame are not interpolated (the frame is
/// reported as outside the pose stream): 10 frames at 30 Hz.
pub const DEFAULT_MAX_POSE_GAP_NS: u64 = 333_000_000;
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
    /// frame ([`ProcessReport::anchor_frame`] says which frame anchored). Without the
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
    /// Depth registration and undistortion choices ([`super::rectify`]).
    pub geometry: GeometryOptions,
    /// `--depth-units-per-meter`: overrides channel metadata and the millimetre default.
    pub depth_units_per_meter: Option<f64>,
    /// With [`PoseSource::External`] (in [`Self::processor`]) and transform topics: the child
    /// frame to follow (default: the first child frame on the topic).
    pub pose_child_frame: Option<String>,
    /// Max colour–depth stamp difference.
    pub pair_tolerance_ns: u64,
    /// Max gap between external poses around a frame.
    pub max_pose_gap_ns: u64,
    /// The frame of the estimated trajectory (DVO pose modes; external poses keep their own).
    pub anchor: OdometryAnchor,
    /// Only frames with colour stamps at or after this many ns after the first colour image.
    pub start_offset_ns: Option<u64>,
    /// Only frames before this many ns after the first colour image. Without a copy of the
    /// input ([`AnnotateOptions::copy_input`] off), the input is read only up to the first
    /// frame past it (once a frame was processed).
    pub end_offset_ns: Option<u64>,
    /// Measure decode/process times into `/occmask/stats` (makes output bytes
    /// non-deterministic).
    pub timings: bool,
    /// Output options.
    pub annotate: AnnotateOptions,
    /// The pose source ([`ProcessorConfig::pose_source`]: DVO, or poses from
    /// [`TopicOverrides::pose`]) and the DVO, detector and failure-policy parameters. Recorded
    /// in the `occmask.process` metadata (all but the pose source, which is recorded as
    /// `pose_source`).
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
