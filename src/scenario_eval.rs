//! Scores the per-sequence pipeline on synthetic scenarios: per-frame masks against the exact
//! ground truth, the onset of each object's detection and the odometry's error.
//!
//! A scenario is rendered once into a [`RenderedSequence`] (rendering a 640×480 frame costs
//! far more than processing it), then run in any [`EvalMode`] with any [`ProcessorConfig`]
//! ([`evaluate`]). What a [`ScenarioScore`] reports:
//!
//! - **F1, precision, recall**: per frame over the whole mask, averaged over the frames whose
//!   ground truth is non-empty ([`crate::metrics::segmentation`]);
//! - **onset** ([`crate::metrics::onset`]): for every run of frames in which an object is seen
//!   and moving, the frames from the run's first frame (the object starts to move or enters the
//!   view) until the object's own recall first reaches 0.5; the worst run is the scenario's
//!   onset, `None` ("never") when a run never reaches it;
//! - **false positives without objects**: the largest false-positive fraction of the image on
//!   a frame whose ground truth is empty, from frame [`WARM_UP_FRAMES`] on (the static
//!   controls' figure; on other scenarios the frames where every object rests);
//! - **odometry**: RPE over 1 and 30 frames and ATE of the output poses against the true ones.

use std::time::Instant;

use nalgebra::Isometry3;
use serde::Serialize;

use crate::dvo::DvoStatus;
use crate::error::Result;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask};
use crate::metrics::onset::{worst_onset, OnsetRun, OnsetTracker};
use crate::metrics::{ate, rpe, FrameCounts, SegmentationSummary, SegmentationTally};
#[cfg(doc)]
use crate::pipeline::{offline::OfflineProcessor, Processor};
use crate::pipeline::{
    FrameInput, FrameOutput, PoseSource, ProcessingMode, ProcessorConfig, SequenceProcessor,
};
use crate::synthetic::{Scenario, SyntheticFrame, SyntheticSequence};

/// Frames excluded from the false-positive figure: the static control's warm-up.
pub const WARM_UP_FRAMES: usize = 5;

/// Long RPE interval (1 s at 30 Hz).
pub const LONG_RPE_DELTA_FRAMES: usize = 30;

/// What the pipeline sees of one rendered frame, and its ground truth.
#[derive(Debug, Clone)]
pub struct RenderedFrame {
    /// Capture time (ns).
    pub timestamp_ns: u64,
    /// Gray image in [0, 1].
    pub gray: GrayF32,
    /// Measured depth (m, 0 = invalid).
    pub depth_m: DepthMeters,
    /// Ground-truth moving-object mask.
    pub gt_mask: Mask,
    /// 1 + the box seen first at each pixel, 0 for the room ([`SyntheticFrame::object_index`]).
    pub object_index: Image<u8>,
    /// True camera pose.
    pub world_from_camera: Isometry3<f64>,
}

/// A scenario rendered once for any number of runs.
#[derive(Debug, Clone)]
pub struct RenderedSequence {
    /// The scenario (`None` for a hand-built sequence).
    pub scenario: Option<Scenario>,
    /// Image size.
    pub size: ImageSize,
    /// Camera intrinsics.
    pub intrinsics: PinholeIntrinsics,
    /// Number of boxes in the world (moving or not).
    pub boxes: usize,
    /// The frames, in order.
    pub frames: Vec<RenderedFrame>,
}

impl RenderedSequence {
    /// Renders every frame of `sequence` (colour, raw and true depth are dropped).
    pub fn render(sequence: &SyntheticSequence) -> Self {
        let size = sequence.config.size;
        let mut frame = SyntheticFrame::empty(size);
        let frames = (0..sequence.len())
            .map(|i| {
                sequence.render_into(i, &mut frame);
                RenderedFrame {
                    timestamp_ns: frame.timestamp_ns,
                    gray: frame.gray.clone(),
                    depth_m: frame.depth_m.clone(),
                    gt_mask: frame.gt_mask.clone(),
                    object_index: frame.object_index.clone(),
                    world_from_camera: frame.world_from_camera,
                }
            })
            .collect();
        Self {
            scenario: sequence.scenario,
            size,
            intrinsics: sequence.config.intrinsics(),
            boxes: sequence.boxes.len(),
            frames,
        }
    }
}

/// Pose source and processing of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EvalMode {
    /// The true camera poses, causal ([`Processor`] with [`PoseSource::External`]).
    TruePoseCausal,
    /// The true camera poses, offline ([`OfflineProcessor`] with [`PoseSource::External`]).
    TruePoseOffline,
    /// The DVO closed loop, causal ([`Processor`]).
    DvoCausal,
    /// The DVO closed loop, offline ([`OfflineProcessor`]: the default mode).
    DvoOffline,
}

impl EvalMode {
    /// Every mode.
    pub const ALL: [EvalMode; 4] = [
        EvalMode::TruePoseCausal,
        EvalMode::TruePoseOffline,
        EvalMode::DvoCausal,
        EvalMode::DvoOffline,
    ];

    /// The snake_case name (as serialised).
    pub fn name(self) -> &'static str {
        match self {
            EvalMode::TruePoseCausal => "true_pose_causal",
            EvalMode::TruePoseOffline => "true_pose_offline",
            EvalMode::DvoCausal => "dvo_causal",
            EvalMode::DvoOffline => "dvo_offline",
        }
    }

    /// The mode called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    fn pose_source(self) -> PoseSource {
        match self {
            EvalMode::TruePoseCausal | EvalMode::TruePoseOffline => PoseSource::External {
                camera_from_marker: None,
            },
            EvalMode::DvoCausal | EvalMode::DvoOffline => PoseSource::DvoClosedLoop,
        }
    }

    fn offline(self) -> bool {
        matches!(self, EvalMode::TruePoseOffline | EvalMode::DvoOffline)
    }
}

/// One frame's scores.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrameScore {
    /// Ground-truth pixels.
    pub truth_pixels: usize,
    /// Ground-truth pixels without a depth measurement (the sensor's invalid border ring, the
    /// projector's shadow, dropouts): a depth-based detector sees them only through their
    /// neighbours.
    pub truth_pixels_without_depth: usize,
    /// Mask pixels.
    pub mask_pixels: usize,
    /// Per-frame F1 (1 when both are empty).
    pub f1: f64,
    /// Per-frame precision (1 when the mask is empty).
    pub precision: f64,
    /// Per-frame recall (1 when the ground truth is empty).
    pub recall: f64,
    /// False-positive pixels over all pixels.
    pub false_positive_fraction: f64,
}

/// The scores of one run ([`evaluate`]; the module docs define them).
#[derive(Debug, Clone, Serialize)]
pub struct ScenarioScore {
    /// The mode of the run.
    pub mode: EvalMode,
    /// Frames processed.
    pub frames: usize,
    /// Mean F1 / precision / recall over frames with objects, and the empty-truth frames' false
    /// positives (all frames).
    pub segmentation: SegmentationSummary,
    /// Every object's ground-truth runs with their onsets.
    pub onset_runs: Vec<OnsetRun>,
    /// The worst run's onset in frames: `None` when there is no run or a run never reaches
    /// half recall (then `onset_never` is true).
    pub worst_onset_frames: Option<usize>,
    /// Some run never reaches half recall.
    pub onset_never: bool,
    /// Largest false-positive fraction on an empty-truth frame from frame
    /// [`WARM_UP_FRAMES`] on (0 when there is none).
    pub max_fp_fraction_without_objects: f64,
    /// Empty-truth frames from frame [`WARM_UP_FRAMES`] on.
    pub frames_without_objects: usize,
    /// RPE over 1 frame, translational RMSE (m).
    pub rpe_1_m: f64,
    /// RPE over [`LONG_RPE_DELTA_FRAMES`] frames, translational RMSE (m; 0 when the sequence is
    /// shorter).
    pub rpe_30_m: f64,
    /// ATE after rigid alignment, RMSE (m).
    pub ate_m: f64,
    /// Frames whose DVO did not converge (the output's DVO report; 0 with true poses).
    pub dvo_not_converged: usize,
    /// Frames at which the pipeline reset its detector.
    pub detector_resets: usize,
    /// Processing time per frame (ms, wall clock, rendering excluded).
    pub ms_per_frame: f64,
    /// Every frame's scores.
    pub per_frame: Vec<FrameScore>,
}

/// Accumulates the scores of the emitted frames.
struct Scorer<'a> {
    sequence: &'a RenderedSequence,
    tally: SegmentationTally,
    onsets: OnsetTracker,
    per_frame: Vec<FrameScore>,
    estimated: Vec<Isometry3<f64>>,
    max_fp_without_objects: f64,
    frames_without_objects: usize,
    dvo_not_converged: usize,
    detector_resets: usize,
    objects: Vec<(usize, usize)>,
}

impl Scorer<'_> {
    fn add(&mut self, out: &FrameOutput<'_>) -> Result<()> {
        let i = self.per_frame.len();
        let truth = &self.sequence.frames[i];
        let counts: FrameCounts = self.tally.add_masks(out.mask, &truth.gt_mask)?;
        if i >= WARM_UP_FRAMES && counts.truth_is_empty() {
            self.frames_without_objects += 1;
            self.max_fp_without_objects = self.max_fp_without_objects.max(counts.false_positive_fraction());
        }
        object_counts(&truth.gt_mask, &truth.object_index, out.mask, &mut self.objects);
        self.onsets.add_frame(&self.objects);
        self.per_frame.push(FrameScore {
            truth_pixels: counts.true_positives + counts.false_negatives,
            truth_pixels_without_depth: truth
                .gt_mask
                .as_slice()
                .iter()
                .zip(truth.depth_m.as_slice())
                .filter(|&(&moving, &depth_m)| moving != 0 && depth_m <= 0.0)
                .count(),
            mask_pixels: counts.true_positives + counts.false_positives,
            f1: counts.f1(),
            precision: counts.precision(),
            recall: counts.recall(),
            false_positive_fraction: counts.false_positive_fraction(),
        });
        self.estimated.push(out.world_from_camera);
        self.dvo_not_converged +=
            usize::from(out.stats.dvo.is_some_and(|d| d.status != DvoStatus::Converged));
        self.detector_resets += usize::from(out.stats.detector_reset);
        Ok(())
    }
}

/// Per box: its ground-truth pixels (set in `gt_mask` where `object_index` names the box) and
/// how many of them `mask` has set, into `out` (index = box; grown to the largest box seen).
pub fn object_counts(gt_mask: &Mask, object_index: &Image<u8>, mask: &Mask, out: &mut Vec<(usize, usize)>) {
    out.iter_mut().for_each(|c| *c = (0, 0));
    let pixels = gt_mask
        .as_slice()
        .iter()
        .zip(object_index.as_slice())
        .zip(mask.as_slice());
    for ((&truth, &object), &m) in pixels {
        if truth != 0 && object > 0 {
            let k = usize::from(object) - 1;
            if out.len() <= k {
                out.resize(k + 1, (0, 0));
            }
            out[k].0 += 1;
            out[k].1 += usize::from(m != 0);
        }
    }
}

/// The pipeline's input for `frame`, with its true pose when the pose source is external.
fn input(frame: &RenderedFrame, external: bool) -> FrameInput<'_> {
    FrameInput {
        timestamp_ns: frame.timestamp_ns,
        gray: &frame.gray,
        depth_m: &frame.depth_m,
        world_from_marker: external.then_some(&frame.world_from_camera),
        ignore_in_previous: None,
    }
}

/// Runs `sequence` in `mode` with `config` (its pose source and mode are replaced by the
/// mode's) and scores every frame.
///
/// # Errors
/// Whatever the pipeline returns (invalid parameters).
pub fn evaluate(
    sequence: &RenderedSequence,
    mode: EvalMode,
    config: &ProcessorConfig,
) -> Result<ScenarioScore> {
    evaluate_observed(sequence, mode, config, &mut |_, _| {})
}

/// [`evaluate`], handing every frame's output mask to `observe` (with the frame's index) as it
/// is scored.
///
/// # Errors
/// Whatever the pipeline returns (invalid parameters).
pub fn evaluate_observed(
    sequence: &RenderedSequence,
    mode: EvalMode,
    config: &ProcessorConfig,
    observe: &mut (dyn FnMut(usize, &Mask) + Send),
) -> Result<ScenarioScore> {
    let config = ProcessorConfig {
        pose_source: mode.pose_source(),
        mode: if mode.offline() {
            ProcessingMode::Offline
        } else {
            ProcessingMode::Causal
        },
        ..*config
    };
    let mut scorer = Scorer {
        sequence,
        tally: SegmentationTally::default(),
        onsets: OnsetTracker::new(),
        per_frame: Vec::with_capacity(sequence.frames.len()),
        estimated: Vec::with_capacity(sequence.frames.len()),
        max_fp_without_objects: 0.0,
        frames_without_objects: 0,
        dvo_not_converged: 0,
        detector_resets: 0,
        objects: vec![(0, 0); sequence.boxes],
    };
    let external = matches!(config.pose_source, PoseSource::External { .. });
    let started = Instant::now();
    let mut processor = SequenceProcessor::new(sequence.size, sequence.intrinsics, config)?;
    let mut emit = |out: FrameOutput<'_>| {
        observe(scorer.per_frame.len(), out.mask);
        scorer.add(&out)
    };
    for f in &sequence.frames {
        processor.push(&input(f, external), &mut emit)?;
    }
    processor.finish(&mut emit)?;
    let elapsed_s = started.elapsed().as_secs_f64();
    let truth: Vec<Isometry3<f64>> = sequence.frames.iter().map(|f| f.world_from_camera).collect();
    let n = scorer.estimated.len();
    let rpe_1_m = if n > 1 {
        rpe(&scorer.estimated, &truth, 1)?.translation_rmse_m
    } else {
        0.0
    };
    let rpe_30_m = if n > LONG_RPE_DELTA_FRAMES {
        rpe(&scorer.estimated, &truth, LONG_RPE_DELTA_FRAMES)?.translation_rmse_m
    } else {
        0.0
    };
    let ate_m = if n > 2 {
        ate(&scorer.estimated, &truth)?.rmse_m
    } else {
        0.0
    };
    let onset_runs = scorer.onsets.runs();
    let worst = worst_onset(&onset_runs);
    Ok(ScenarioScore {
        mode,
        frames: n,
        segmentation: scorer.tally.summary(),
        worst_onset_frames: worst.flatten(),
        onset_never: worst == Some(None),
        onset_runs,
        max_fp_fraction_without_objects: scorer.max_fp_without_objects,
        frames_without_objects: scorer.frames_without_objects,
        rpe_1_m,
        rpe_30_m,
        ate_m,
        dvo_not_converged: scorer.dvo_not_converged,
        detector_resets: scorer.detector_resets,
        ms_per_frame: 1e3 * elapsed_s / n.max(1) as f64,
        per_frame: scorer.per_frame,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::SequenceConfig;

    /// The per-frame count of ground-truth pixels without depth is the rendered frames' own:
    /// the box that enters the desk scene at the image corner does so through the sensor's
    /// invalid border ring, so most of its first pixels have none.
    #[test]
    fn truth_pixels_without_depth_count_the_moving_pixels_the_sensor_left_empty() {
        let sequence = SyntheticSequence::new(
            Scenario::SlidingOnDesk,
            SequenceConfig {
                size: ImageSize::new(320, 240),
                frame_count: Some(8),
                ..SequenceConfig::default()
            },
        );
        let rendered = RenderedSequence::render(&sequence);
        let score = evaluate(&rendered, EvalMode::TruePoseCausal, &ProcessorConfig::default()).unwrap();
        assert_eq!(score.per_frame.len(), rendered.frames.len());
        for (frame, scored) in rendered.frames.iter().zip(&score.per_frame) {
            let expected = frame
                .gt_mask
                .as_slice()
                .iter()
                .zip(frame.depth_m.as_slice())
                .filter(|&(&m, &z)| m != 0 && z <= 0.0)
                .count();
            assert_eq!(scored.truth_pixels_without_depth, expected);
            assert!(scored.truth_pixels_without_depth <= scored.truth_pixels);
        }
        let last = score.per_frame.last().unwrap();
        assert!(
            2 * last.truth_pixels_without_depth > last.truth_pixels,
            "{} of {} without depth",
            last.truth_pixels_without_depth,
            last.truth_pixels
        );
    }
}
