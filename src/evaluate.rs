//! `occmask eval`: scores an output of `occmask process` against the ground truth in the same
//! file (docs/method.md, "Evaluation").
//!
//! - Segmentation: each `/occmask/mask` is compared with the `/groundtruth/mask` of the same
//!   stamp; F1, precision and recall are averaged over frames with a non-empty ground truth
//!   ([`crate::metrics::segmentation`]), frames with an empty ground truth report their
//!   false-positive fraction instead.
//! - Odometry: `/occmask/odometry` against `/groundtruth/pose`: RPE with Δ = 1 frame and
//!   Δ = 150 frames (or the longest the sequence allows), `evaluate_rpe.py` semantics, and ATE
//!   after rigid alignment, with ground truth interpolated to the estimated stamps.
//!
//! The ground truth is the evaluated file's own, or another file's ([`evaluate_against`]): an
//! MCAP with the same channels (the input of a `--sidecar` run, which holds only the new
//! channels), or a TUM trajectory for the poses.
//!
//! Masks stream through with bounded memory (from another file on a second thread, paired by
//! stamp); poses are kept whole (64 bytes each).

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use nalgebra::Isometry3;
use serde::Serialize;

use crate::error::{DecodeProblem, Error, ImageKind, PoseRole, Result};
use crate::image_buf::{ImageSize, Mask, MASK_SET};
use crate::mcap_io::annotate::{TOPIC_MASK, TOPIC_ODOMETRY};
use crate::mcap_io::encoding::ColorEncoding;
use crate::mcap_io::input::decode::{
    decode_image, read_poses, unsupported_schema, ImagePayload, IMAGE_SCHEMA,
};
use crate::mcap_io::input::{McapInput, Truncation};
use crate::mcap_io::{TOPIC_GROUNDTRUTH_MASK, TOPIC_GROUNDTRUTH_POSE};
use crate::metrics::segmentation::{SegmentationSummary, SegmentationTally};
use crate::metrics::trajectory::{ate, rpe_stamped, AteStats, RpeStats};
use crate::process::{recorded_input_difference, InputDifference};
use crate::trajectory::{interpolate, StampedPose};

/// The paper's long RPE interval: 150 frames, "drift per 5 s at 30 Hz".
pub const LONG_RPE_DELTA_FRAMES: usize = 150;
/// Masks waiting for their partner are dropped once the newest stamp is this far ahead: the
/// two topics are written together, so partners are never further apart in a file.
const MASK_MATCH_WINDOW_NS: u64 = 2_000_000_000;
/// Ground-truth masks read ahead from another file (0.3 MB each at 640×480).
const GROUNDTRUTH_MASKS_AHEAD: usize = 8;

/// Segmentation scores.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SegmentationReport {
    /// Estimated masks compared with a ground-truth mask of the same stamp.
    pub matched_frames: usize,
    /// Scores over the matched frames (flattened into the JSON report).
    #[serde(flatten)]
    pub scores: SegmentationSummary,
}

/// RPE for one interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RpeReport {
    /// Interval in frames.
    pub delta_frames: usize,
    /// Pairs evaluated.
    pub pairs: usize,
    /// Translational RMSE, metres.
    pub translation_rmse_m: f64,
    /// Rotational RMSE, degrees.
    pub rotation_rmse_deg: f64,
}

/// ATE after rigid alignment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AteReport {
    /// Poses compared.
    pub poses: usize,
    /// RMSE, metres.
    pub rmse_m: f64,
    /// Maximum, metres.
    pub max_m: f64,
}

/// Odometry scores.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OdometryReport {
    /// Estimated poses.
    pub estimated_poses: usize,
    /// Ground-truth poses.
    pub groundtruth_poses: usize,
    /// RPE, Δ = 1 and the long interval.
    pub rpe: Vec<RpeReport>,
    /// ATE, when at least 3 estimated poses have ground truth.
    pub ate: Option<AteReport>,
}

/// Everything `eval` measured; `None` parts had no ground truth in the file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    /// The file.
    pub path: String,
    /// Estimated masks in the file.
    pub estimated_masks: usize,
    /// Segmentation, when the ground truth has `/groundtruth/mask`.
    pub segmentation: Option<SegmentationReport>,
    /// Odometry, when the ground truth has poses ([`GroundTruthReport::pose_topic`]).
    pub odometry: Option<OdometryReport>,
    /// Set when the file ends early: the scores cover its complete records only.
    pub truncation: Option<Truncation>,
    /// Where the ground truth was read.
    pub groundtruth: GroundTruthReport,
}

/// What the ground truth's file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GroundTruthKind {
    /// An MCAP file: [`TOPIC_GROUNDTRUTH_MASK`] and a pose channel.
    Mcap,
    /// A TUM trajectory (`timestamp tx ty tz qx qy qz qw`): poses only.
    Trajectory,
}

/// Where `eval` reads the ground truth ([`evaluate_against`]); the default is the evaluated
/// file's [`TOPIC_GROUNDTRUTH_MASK`] and [`TOPIC_GROUNDTRUTH_POSE`].
#[derive(Debug, Clone, Copy, Default)]
pub struct GroundTruthSource<'a> {
    /// Another file: an MCAP file, or a TUM trajectory (`timestamp tx ty tz qx qy qz qw` per
    /// line, seconds and metres) whose poses are the ground truth.
    pub file: Option<&'a Path>,
    /// The pose channel of the MCAP file (any pose schema `process --pose-topic` reads), instead
    /// of [`TOPIC_GROUNDTRUTH_POSE`]: named, it must be there and hold poses.
    pub pose_topic: Option<&'a str>,
    /// The ground-truth poses are a marker's (motion capture), and this is the marker's pose in
    /// the camera frame: the camera's pose is the marker's · the inverse of this, as with
    /// `process --camera-from-marker`. `None`: they are the camera's.
    pub camera_from_marker: Option<Isometry3<f64>>,
}

/// Where the ground truth was read.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroundTruthReport {
    /// The file, when not the evaluated one.
    pub file: Option<String>,
    /// Its kind.
    pub kind: GroundTruthKind,
    /// The pose channel read (`None` for a trajectory).
    pub pose_topic: Option<String>,
    /// Set when the ground truth is another MCAP file that is not the input the evaluated file
    /// was made from: the first field of the input's identity (message count, log-time span)
    /// that the evaluated file's `occmask.process` record holds otherwise. The scores are still
    /// computed, by stamp.
    pub other_input: Option<InputDifference>,
    /// [`GroundTruthSource::camera_from_marker`], as `[x, y, z, qx, qy, qz, qw]` (metres, unit
    /// quaternion).
    pub camera_from_marker: Option<[f64; 7]>,
}

/// Where the ground truth is read from.
enum GroundTruth {
    /// The evaluated file.
    SameFile,
    /// Another MCAP file.
    Mcap(Box<McapInput>),
    /// A TUM trajectory's poses.
    Trajectory(Vec<StampedPose>),
}

impl GroundTruth {
    /// Opens `path`: an MCAP file when it starts with the MCAP magic bytes, else a TUM
    /// trajectory.
    fn open(path: &Path) -> Result<Self> {
        let mut magic = Vec::with_capacity(mcap::MAGIC.len());
        std::fs::File::open(path)
            .and_then(|f| f.take(mcap::MAGIC.len() as u64).read_to_end(&mut magic))
            .map_err(|e| Error::io("cannot read", path, e))?;
        if magic == mcap::MAGIC {
            Ok(Self::Mcap(Box::new(McapInput::open(path)?)))
        } else {
            Ok(Self::Trajectory(crate::dataset::read_groundtruth(path)?))
        }
    }
}

/// Estimated (side 0) and ground-truth (side 1) masks paired by stamp as they stream in, and the
/// pairs' scores.
#[derive(Default)]
struct MaskPairing {
    tally: SegmentationTally,
    matched: usize,
    /// Masks waiting for their partner, per side, by stamp.
    pending: [BTreeMap<u64, Mask>; 2],
}

impl MaskPairing {
    fn add(&mut self, side: usize, stamp: u64, mask: Mask) -> Result<()> {
        if let Some(other) = self.pending[1 - side].remove(&stamp) {
            let (est, gt) = if side == 0 {
                (&mask, &other)
            } else {
                (&other, &mask)
            };
            self.tally.add_masks(est, gt)?;
            self.matched += 1;
        } else {
            self.pending[side].insert(stamp, mask);
        }
        let horizon = stamp.saturating_sub(MASK_MATCH_WINDOW_NS);
        for p in &mut self.pending {
            *p = p.split_off(&horizon);
        }
        Ok(())
    }

    fn report(self) -> SegmentationReport {
        SegmentationReport {
            matched_frames: self.matched,
            scores: self.tally.summary(),
        }
    }
}

fn mask_from_message(input: &McapInput, channel_id: u16, data: &[u8]) -> Result<(u64, Mask)> {
    let channel = &input.channels()[&channel_id];
    let ct = channel
        .channel_type
        .ok_or_else(|| unsupported_schema(channel, IMAGE_SCHEMA))?;
    let msg = decode_image(ct, &channel.topic, data)?;
    let unsupported = |found: &str| {
        Error::decode(
            channel.topic.clone(),
            DecodeProblem::UnsupportedEncoding {
                image: ImageKind::Mask,
                found: found.to_owned(),
                supported: "mono8 (uncompressed)",
            },
        )
    };
    let (width, height, encoding, step, data) = match &msg.payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            step,
            data,
            ..
        } => (width, height, encoding, step, data),
        ImagePayload::Compressed { format, .. } => return Err(unsupported(format)),
    };
    if encoding.parse::<ColorEncoding>() != Ok(ColorEncoding::Mono8) {
        return Err(unsupported(encoding));
    }
    let size = ImageSize::new(*width as usize, *height as usize);
    let step = *step as usize;
    if step < size.width {
        return Err(Error::decode(
            channel.topic.clone(),
            DecodeProblem::RowStep {
                size,
                step,
                row_bytes: size.width,
            },
        ));
    }
    let needed = step * size.height.saturating_sub(1) + size.width;
    if data.len() < needed {
        return Err(Error::decode(
            channel.topic.clone(),
            DecodeProblem::ImageLength {
                size,
                step,
                bytes_per_pixel: 1,
                needed,
                full: step * size.height,
                found: data.len(),
            },
        ));
    }
    let mask = Mask::from_fn(size, |x, y| if data[y * step + x] != 0 { MASK_SET } else { 0 });
    Ok((msg.timestamp_ns, mask))
}

fn rpe_report(delta_frames: usize, s: &RpeStats) -> RpeReport {
    RpeReport {
        delta_frames,
        pairs: s.pairs,
        translation_rmse_m: s.translation_rmse_m,
        rotation_rmse_deg: s.rotation_rmse_deg,
    }
}

fn odometry(estimated: &[StampedPose], truth: &[StampedPose]) -> Result<OdometryReport> {
    let mut rpe = Vec::new();
    if estimated.len() >= 3 && truth.len() >= 2 {
        // rpe_stamped drops pairs whose second frame is the last one (evaluate_rpe.py), so
        // the longest usable interval is n − 2.
        let long = LONG_RPE_DELTA_FRAMES.min(estimated.len() - 2);
        for delta in [1, long] {
            if rpe.iter().any(|r: &RpeReport| r.delta_frames == delta) {
                continue;
            }
            rpe.push(rpe_report(delta, &rpe_stamped(estimated, truth, delta)?));
        }
    }
    let mut ate_report = None;
    if truth.len() >= 2 {
        let mut intervals: Vec<u64> = truth
            .windows(2)
            .map(|w| w[1].timestamp_ns - w[0].timestamp_ns)
            .collect();
        intervals.sort_unstable();
        let max_gap_ns = 2 * intervals[intervals.len() / 2];
        let (est, gt): (Vec<_>, Vec<_>) = estimated
            .iter()
            .filter_map(|e| interpolate(truth, e.timestamp_ns, max_gap_ns).map(|g| (e.world_from_camera, g)))
            .unzip();
        if est.len() >= 3 {
            let a: AteStats = ate(&est, &gt)?;
            ate_report = Some(AteReport {
                poses: a.poses,
                rmse_m: a.rmse_m,
                max_m: a.max_m,
            });
        }
    }
    Ok(OdometryReport {
        estimated_poses: estimated.len(),
        groundtruth_poses: truth.len(),
        rpe,
        ate: ate_report,
    })
}

/// Evaluates one output file.
///
/// # Errors
/// [`Error::NotProcessed`] when the file has no `/occmask/mask` or `/occmask/odometry` (not an
/// output of `occmask process`); decode, I/O and MCAP errors.
///
/// # Example
/// The crate-level example scores a processed file; a recording that was never processed is
/// refused:
/// ```
/// use occmask::image_buf::ImageSize;
/// use occmask::mcap_io::McapWriteOptions;
/// use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("raw.mcap");
/// let sequence = SyntheticSequence::new(
///     Scenario::SmallObjectCrossing,
///     SequenceConfig { size: ImageSize::new(80, 60), frame_count: Some(2), ..SequenceConfig::default() },
/// );
/// let file = std::fs::File::create(&path).unwrap();
/// occmask::convert::write_synthetic_sequence(&sequence, file, &McapWriteOptions::default(), &mut |_| {
///     std::ops::ControlFlow::Continue(())
/// })?;
/// let error = occmask::evaluate(&path).unwrap_err();
/// assert!(matches!(error, occmask::Error::NotProcessed { .. }), "{error}");
/// # Ok::<(), occmask::Error>(())
/// ```
pub fn evaluate(path: &Path) -> Result<EvalReport> {
    evaluate_against(path, &GroundTruthSource::default())
}

/// Evaluates one output file against the ground truth that `source` names: the file's own, or
/// another MCAP file's (the input of a `--sidecar` run, or any recording of the same stamps), or
/// a TUM trajectory's poses; the poses of [`TOPIC_GROUNDTRUTH_POSE`] or of another channel.
/// Masks are paired by stamp, poses interpolated to the estimated stamps, as within one file.
/// When the other MCAP is not the input the evaluated file was made from (as its
/// `occmask.process` record says), [`GroundTruthReport::other_input`] says where they differ.
///
/// # Errors
/// Those of [`evaluate`]; for the ground-truth file, I/O and MCAP errors, and
/// [`Error::Parse`] with the line for a malformed trajectory; [`Error::NoPoses`] when a named
/// pose topic is absent or empty; [`Error::InvalidParameter`] for a pose topic with a
/// trajectory.
pub fn evaluate_against(path: &Path, source: &GroundTruthSource<'_>) -> Result<EvalReport> {
    let input = McapInput::open(path)?;
    let mask_channel = input.channel_by_topic(TOPIC_MASK).map(|c| c.id);
    let odometry_present = input.channel_by_topic(TOPIC_ODOMETRY).is_some();
    if mask_channel.is_none() && !odometry_present {
        return Err(Error::NotProcessed {
            path: path.to_owned(),
            mask_topic: TOPIC_MASK,
            odometry_topic: TOPIC_ODOMETRY,
        });
    }
    let truth_source = source
        .file
        .map(GroundTruth::open)
        .transpose()?
        .unwrap_or(GroundTruth::SameFile);
    let pose_topic = source.pose_topic.unwrap_or(TOPIC_GROUNDTRUTH_POSE);
    let groundtruth = GroundTruthReport {
        file: source.file.map(|f| f.display().to_string()),
        kind: match truth_source {
            GroundTruth::Trajectory(_) => GroundTruthKind::Trajectory,
            _ => GroundTruthKind::Mcap,
        },
        pose_topic: match truth_source {
            GroundTruth::Trajectory(_) => None,
            _ => Some(pose_topic.to_owned()),
        },
        other_input: match &truth_source {
            GroundTruth::Mcap(truth) => recorded_input_difference(&input, truth)?,
            _ => None,
        },
        camera_from_marker: source.camera_from_marker.map(|c| {
            let (t, q) = (c.translation.vector, c.rotation.quaternion());
            [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
        }),
    };

    let (estimated_masks, segmentation) = match mask_channel {
        None => (0, None),
        Some(est_id) => match &truth_source {
            GroundTruth::SameFile => score_masks_in_file(&input, est_id)?,
            GroundTruth::Mcap(truth) => score_masks_against(&input, est_id, truth)?,
            GroundTruth::Trajectory(_) => (count_messages(&input, TOPIC_MASK)?, None),
        },
    };

    let mut truth = match truth_source {
        GroundTruth::SameFile => read_truth_poses(&input, pose_topic, source.pose_topic.is_some())?,
        GroundTruth::Mcap(truth) => read_truth_poses(&truth, pose_topic, source.pose_topic.is_some())?,
        GroundTruth::Trajectory(poses) => match source.pose_topic {
            None => poses,
            Some(topic) => {
                return Err(Error::InvalidParameter {
                    name: "ground-truth pose topic",
                    value: topic.to_owned(),
                    expected: "an MCAP ground truth (a trajectory file has no topics)".into(),
                })
            }
        },
    };
    if let Some(camera_from_marker) = source.camera_from_marker {
        let marker_from_camera = camera_from_marker.inverse();
        for pose in &mut truth {
            pose.world_from_camera *= marker_from_camera;
        }
    }
    let odometry = if truth.is_empty() || !odometry_present {
        None
    } else {
        Some(odometry(&read_poses(&input, TOPIC_ODOMETRY)?, &truth)?)
    };
    Ok(EvalReport {
        path: path.display().to_string(),
        estimated_masks,
        segmentation,
        odometry,
        truncation: input.truncation().copied(),
        groundtruth,
    })
}

/// The ground-truth poses of `topic` in `input` ([`read_poses`]); `named` (asked for by name):
/// an absent or empty channel is an error rather than no ground truth.
fn read_truth_poses(input: &McapInput, topic: &str, named: bool) -> Result<Vec<StampedPose>> {
    let poses = read_poses(input, topic)?;
    if named && poses.is_empty() {
        let absent = input.channel_by_topic(topic).is_none();
        return Err(Error::NoPoses {
            path: input.path().to_owned(),
            role: PoseRole::GroundTruth,
            topic: topic.to_owned(),
            child_frame: None,
            channels: if absent {
                input.channels().values().map(|c| c.topic.clone()).collect()
            } else {
                Vec::new()
            },
        });
    }
    Ok(poses)
}

/// Messages on `topic`.
fn count_messages(input: &McapInput, topic: &str) -> Result<usize> {
    let mut count = 0;
    input.for_each_message(Some(&[topic.to_owned()]), None, |_| {
        count += 1;
        Ok(true)
    })?;
    Ok(count)
}

/// The estimated masks (channel `est_id`) counted, and scored against the file's own
/// [`TOPIC_GROUNDTRUTH_MASK`] when it has one, in one pass.
fn score_masks_in_file(input: &McapInput, est_id: u16) -> Result<(usize, Option<SegmentationReport>)> {
    if input.channel_by_topic(TOPIC_GROUNDTRUTH_MASK).is_none() {
        return Ok((count_messages(input, TOPIC_MASK)?, None));
    }
    let mut estimated = 0usize;
    let mut pairing = MaskPairing::default();
    let topics = [TOPIC_MASK.to_owned(), TOPIC_GROUNDTRUTH_MASK.to_owned()];
    input.for_each_message(Some(&topics), None, |m| {
        let id = m.header.channel_id;
        let side = usize::from(id != est_id);
        if side == 0 {
            estimated += 1;
        }
        let (stamp, mask) = mask_from_message(input, id, &m.data)?;
        pairing.add(side, stamp, mask)?;
        Ok(true)
    })?;
    Ok((estimated, Some(pairing.report())))
}

/// The estimated masks (channel `est_id`) counted, and scored against `truth`'s
/// [`TOPIC_GROUNDTRUTH_MASK`] when it has one: that file is read on a second thread, at most
/// [`GROUNDTRUTH_MASKS_AHEAD`] masks ahead, up to the stamp of each estimated mask.
fn score_masks_against(
    input: &McapInput,
    est_id: u16,
    truth: &McapInput,
) -> Result<(usize, Option<SegmentationReport>)> {
    let Some(gt_id) = truth.channel_by_topic(TOPIC_GROUNDTRUTH_MASK).map(|c| c.id) else {
        return Ok((count_messages(input, TOPIC_MASK)?, None));
    };
    std::thread::scope(|scope| {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Result<(u64, Mask)>>(GROUNDTRUTH_MASKS_AHEAD);
        scope.spawn(move || {
            let read = truth.for_each_message(Some(&[TOPIC_GROUNDTRUTH_MASK.to_owned()]), None, |m| {
                let item = mask_from_message(truth, gt_id, &m.data);
                let failed = item.is_err();
                // A closed channel: the estimated masks are done (or failed); stop reading.
                Ok(tx.send(item).is_ok() && !failed)
            });
            if let Err(e) = read {
                let _ = tx.send(Err(e));
            }
        });
        let mut estimated = 0usize;
        let mut pairing = MaskPairing::default();
        // The newest ground-truth stamp read; `None` once that file is read to its end.
        let mut truth_stamp = Some(0u64);
        input.for_each_message(Some(&[TOPIC_MASK.to_owned()]), None, |m| {
            let (stamp, mask) = mask_from_message(input, est_id, &m.data)?;
            while let Some(read_to) = truth_stamp.filter(|&t| t < stamp) {
                truth_stamp = match rx.recv() {
                    Ok(item) => {
                        let (gt_stamp, gt_mask) = item?;
                        pairing.add(1, gt_stamp, gt_mask)?;
                        Some(gt_stamp.max(read_to))
                    }
                    Err(_) => None,
                };
            }
            estimated += 1;
            pairing.add(0, stamp, mask)?;
            Ok(true)
        })?;
        // `rx` drops here, which stops the reading thread before the scope joins it.
        Ok((estimated, Some(pairing.report())))
    })
}

/// The report as a readable table.
pub fn format_report(report: &EvalReport) -> String {
    let mut out = format!("{}\n", report.path);
    let g = &report.groundtruth;
    let place = g.file.as_deref().unwrap_or("the file");
    // Where a missing ground truth was looked for.
    let missing = |topic: Option<&str>| match (g.kind, topic) {
        (GroundTruthKind::Mcap, Some(topic)) if g.file.is_none() => {
            format!("no {topic} in the file (--groundtruth FILE reads another)")
        }
        (GroundTruthKind::Mcap, Some(topic)) => format!("no {topic} in {place}"),
        (_, None) => format!("no poses in {place}"),
        (GroundTruthKind::Trajectory, Some(_)) => format!("none: {place} is a trajectory (poses only)"),
    };
    let pose_topic = g.pose_topic.as_deref().unwrap_or(TOPIC_GROUNDTRUTH_POSE);
    if g.file.is_some() || pose_topic != TOPIC_GROUNDTRUTH_POSE || g.camera_from_marker.is_some() {
        out.push_str(&format!("  ground truth           {place}"));
        if pose_topic != TOPIC_GROUNDTRUTH_POSE {
            out.push_str(&format!(", poses of {pose_topic}"));
        }
        if let Some(c) = g.camera_from_marker {
            let numbers: Vec<String> = c.iter().map(|v| format!("{v:.6}")).collect();
            out.push_str(&format!(
                ", a marker's: camera = marker · inverse({})",
                numbers.join(",")
            ));
        }
        out.push('\n');
    }
    out.push_str(&format!("  estimated masks        {}\n", report.estimated_masks));
    match &report.segmentation {
        Some(report) => {
            let s = &report.scores;
            out.push_str(&format!(
                "  segmentation           {} frames matched, {} with moving objects\n",
                report.matched_frames, s.frames_with_truth
            ));
            if s.frames_with_truth > 0 {
                out.push_str(&format!(
                    "    F1 / precision / recall   {:.3} / {:.3} / {:.3}\n",
                    s.mean_f1, s.mean_precision, s.mean_recall
                ));
            } else {
                out.push_str("    F1                         n/a: no frame with moving objects\n");
            }
            if s.empty_truth_frames > 0 {
                out.push_str(&format!(
                    "    static frames              {} (false-positive fraction mean {:.4}, max {:.4})\n",
                    s.empty_truth_frames, s.empty_truth_mean_fp_fraction, s.empty_truth_max_fp_fraction
                ));
            }
        }
        None => out.push_str(&format!(
            "  segmentation           {}\n",
            missing(Some(TOPIC_GROUNDTRUTH_MASK))
        )),
    }
    match &report.odometry {
        Some(o) => {
            out.push_str(&format!(
                "  odometry               {} estimated poses, {} ground-truth poses\n",
                o.estimated_poses, o.groundtruth_poses
            ));
            for r in &o.rpe {
                if r.pairs == 0 {
                    out.push_str(&format!(
                        "    RPE Δ={:<4}                no pair of frames with ground truth at both\n",
                        r.delta_frames
                    ));
                    continue;
                }
                // "pair) " and "pairs)" are as wide, so the columns stay aligned.
                let pairs = if r.pairs == 1 { "pair) " } else { "pairs)" };
                out.push_str(&format!(
                    "    RPE Δ={:<4} ({:>5} {pairs}  {:.4} m  {:.3}°\n",
                    r.delta_frames, r.pairs, r.translation_rmse_m, r.rotation_rmse_deg
                ));
            }
            match &o.ate {
                Some(a) => out.push_str(&format!(
                    "    ATE ({} poses)            RMSE {:.4} m, max {:.4} m\n",
                    a.poses, a.rmse_m, a.max_m
                )),
                None => out.push_str("    ATE                        fewer than 3 poses with ground truth\n"),
            }
        }
        None => out.push_str(&format!(
            "  odometry               {}\n",
            missing(g.pose_topic.as_deref())
        )),
    }
    out
}
