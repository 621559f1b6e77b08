//! What [`super::process_file`] reports about one file: counts, the anchor, where the time went,
//! and the metadata that describes a damaged input.

use crate::geometry::camera::PinholeIntrinsics;
use crate::mcap_io::input::detect::RgbdTopics;
use crate::mcap_io::input::Truncation;
use crate::pipeline::offline::ColourRegistration;

use super::rectify::InputGeometry;
#[cfg(doc)]
use super::{rectify, FrameProcessor, OdometryAnchor, ProcessHooks};

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
    /// Input messages of an earlier run left out, its channels replaced by this run's
    /// ([`crate::mcap_io::annotate::AnnotateOptions::replace_earlier`]).
    pub replaced_messages: u64,
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
    /// Messages of an optional [`OdometryAnchor`] channel that did not decode after its first
    /// did: left out of the anchor, whose other samples are used.
    pub anchor_unreadable: Option<UnreadablePoses>,
    /// What the offline mode's colour/depth registration check decided (`None` in the causal
    /// mode, with external poses, or with the check off).
    pub colour_registration: Option<ColourRegistration>,
}

/// Pose messages left out because they did not decode ([`ProcessReport::anchor_unreadable`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnreadablePoses {
    /// How many.
    pub messages: u64,
    /// Why the first of them did not decode.
    pub first_error: String,
}

/// Which frame anchored the odometry ([`ProcessReport::anchor_frame`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnchorFrame {
    /// Its index among the processed frames (0 = the first).
    pub index: u64,
    /// Its colour stamp.
    pub timestamp_ns: u64,
}

/// Where the frame loop's wall-clock time went, in seconds. The frame loop runs the pipeline;
/// a prefetch thread reads and decodes the input and a writer thread encodes, copies and
/// compresses the output, so `pipeline_s` close to `loop_s` means the pipeline is the only
/// serial part.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LoopTimings {
    /// From the start of reading to the last frame queued for writing.
    pub loop_s: f64,
    /// In the pipeline ([`FrameProcessor::push`]: DVO + detector).
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
