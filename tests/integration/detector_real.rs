//! The detector on real static sequences (nothing moves): the false-positive pixel fraction with
//! ground-truth poses must stay ≤ 1 % per frame after a warm-up.
//!
//! Data: the real-data folder (`OCCMASK_DATA`, default `../shared/data` beside the repository:
//! TUM fr2_desk 50 frames, 7-Scenes redkitchen 300 frames). Tests skip with a notice when the
//! data is absent (and fail when `OCCMASK_DATA` names a folder without it). 7-Scenes colour and
//! depth are not registered, so only its depth is used.
//!
//! Each ground truth has one frame whose motion disagrees with the depth (TUM frame 5,
//! 7-Scenes frame 122: the depth fits no motion better than the ground-truth one); the
//! detector's motion check (`OcclusionConfig::motion_check_margin`) must reject exactly those
//! and restart there, instead of keeping the misregistered depth edges as false positives.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use nalgebra::Isometry3;
use occmask::geometry::PinholeIntrinsics;
use occmask::image_buf::ImageSize;
use occmask::occlusion::{OcclusionConfig, OcclusionDetector};
use occmask::pipeline::offline::ColourRegistration;
use occmask::pipeline::{FrameInput, FrameOutput, ProcessingMode, ProcessorConfig, SequenceProcessor};
use occmask::trajectory::interpolate;

/// Frames ignored at the start: the first frame only initialises the detector, and a few more
/// let the compensated depth settle.
const WARM_UP_FRAMES: usize = 5;
/// Largest gap between bracketing ground-truth poses for interpolation (TUM mocap is ~100 Hz).
const MAX_GT_GAP_NS: u64 = 50_000_000;

use crate::common::{data, tum::TumSequence};

/// Runs the detector with ground-truth poses; returns the per-frame false-positive fractions and
/// the frames whose motion the detector rejected.
fn false_positive_fractions(dir: &Path, intrinsics: PinholeIntrinsics) -> (Vec<f64>, Vec<usize>) {
    let config = OcclusionConfig::default();
    let sequence = TumSequence::load(dir).unwrap();
    let truth = sequence.groundtruth();
    let size = ImageSize::new(640, 480);
    let mut detector = OcclusionDetector::new(size, intrinsics, config).unwrap();
    let mut previous: Option<Isometry3<f64>> = None;
    let mut fractions = Vec::new();
    let mut rejected = Vec::new();
    // Each depth frame with the nearest colour image, for the default appearance growth
    // (7-Scenes: colour is not registered to depth, which the growth's gates must tolerate).
    for pair in sequence.depth_with_nearest_color() {
        let t = sequence.sequence.depth[pair.depth].timestamp_ns;
        let Some(world_from_camera) = interpolate(truth, t, MAX_GT_GAP_NS) else {
            continue;
        };
        let frame = sequence.decode(&pair).unwrap();
        let motion = previous.map_or_else(Isometry3::identity, |p| world_from_camera.inverse() * p);
        previous = Some(world_from_camera);
        let mask = detector
            .update_with_gray(&frame.depth_m, Some(&frame.gray), &motion)
            .unwrap();
        let set = mask.as_slice().iter().filter(|&&m| m != 0).count();
        if detector.stats().motion_rejected {
            rejected.push(fractions.len());
        }
        fractions.push(set as f64 / size.area() as f64);
    }
    (fractions, rejected)
}

/// Prints the figures; returns (mean, max, frames above `limit`) after the warm-up.
fn summarise(name: &str, fractions: &[f64], limit: f64) -> (f64, f64, usize) {
    let after = &fractions[WARM_UP_FRAMES..];
    let worst = after.iter().copied().fold(0.0, f64::max);
    let mean = after.iter().sum::<f64>() / after.len() as f64;
    let above = after.iter().filter(|&&f| f > limit).count();
    println!(
        "{name}: {} frames, FP fraction after warm-up: mean {:.4} %, max {:.4} %, {above} frames above {} %",
        fractions.len(),
        100.0 * mean,
        100.0 * worst,
        100.0 * limit
    );
    (mean, worst, above)
}

fn check(name: &str, fractions: &[f64], limit: f64) {
    let (_, worst, _) = summarise(name, fractions, limit);
    assert!(
        worst <= limit,
        "{name}: {:.3} % of pixels flagged as moving on some frame",
        100.0 * worst
    );
}

#[test]
fn tum_fr2_desk_static_with_ground_truth_poses_has_few_false_positives() {
    let Some(dir) = data::real_data(
        "tum_fr2_desk_50",
        "detector_real::tum_fr2_desk_static_with_ground_truth_poses_has_few_false_positives",
    ) else {
        return;
    };
    let (fractions, rejected) =
        false_positive_fractions(&dir, PinholeIntrinsics::new(520.9, 521.0, 325.1, 249.7));
    assert!(fractions.len() >= 45);
    assert_eq!(rejected, vec![5], "frames whose ground-truth motion was rejected");
    check("tum_fr2_desk_50", &fractions, 0.01);
}

/// Measured max 0.626 % (the slow-change evidence; the paper's accumulation alone flags nothing;
/// 2.23 % max on 24 frames before the motion check: bands along every depth edge left by frame
/// 122's ground-truth motion, which fits the depth worse than no motion at all,
/// docs/accuracy.md). Bound: the 1 % limit.
#[test]
fn seven_scenes_redkitchen_static_with_ground_truth_poses_has_few_false_positives() {
    let Some(dir) = data::real_data(
        "7scenes_redkitchen_300",
        "detector_real::seven_scenes_redkitchen_static_with_ground_truth_poses_has_few_false_positives",
    ) else {
        return;
    };
    let (fractions, rejected) =
        false_positive_fractions(&dir, PinholeIntrinsics::new(585.0, 585.0, 320.0, 240.0));
    assert!(fractions.len() >= 290);
    assert_eq!(
        rejected,
        vec![122],
        "frames whose ground-truth motion was rejected"
    );
    check("7scenes_redkitchen_300", &fractions, 0.01);
}

/// The closed loop (DVO poses, mask fed back; `ProcessorConfig::default()` in `mode`, as
/// `occmask process` runs it) over a TUM-layout folder: each frame's false-positive fraction (a
/// static scene), how many DVO estimates did not converge, and the offline mode's registration
/// decision.
fn closed_loop_fractions(
    dir: &Path,
    intrinsics: PinholeIntrinsics,
    mode: ProcessingMode,
) -> (Vec<f64>, usize, Option<ColourRegistration>) {
    let sequence = TumSequence::load(dir).unwrap();
    let size = ImageSize::new(640, 480);
    let config = ProcessorConfig {
        mode,
        ..ProcessorConfig::default()
    };
    let mut processor = SequenceProcessor::new(size, intrinsics, config).unwrap();
    let mut fractions = Vec::new();
    let mut failures = 0;
    let mut keep = |out: FrameOutput<'_>| {
        failures += usize::from(
            out.stats
                .dvo
                .is_some_and(|d| d.status != occmask::dvo::DvoStatus::Converged),
        );
        fractions.push(out.stats.moving_fraction);
        Ok(())
    };
    for pair in sequence.depth_with_nearest_color() {
        let frame = sequence.decode(&pair).unwrap();
        let input = FrameInput {
            timestamp_ns: frame.depth_timestamp_ns,
            gray: &frame.gray,
            depth_m: &frame.depth_m,
            world_from_marker: None,
            ignore_in_previous: None,
        };
        processor.push(&input, &mut keep).unwrap();
    }
    processor.finish(&mut keep).unwrap();
    (fractions, failures, processor.colour_registration())
}

/// The closed loop on TUM fr2_desk: colour and depth are registered, so DVO can run. Reported
/// alongside the ground-truth-pose figure.
#[test]
fn tum_fr2_desk_static_with_dvo_poses_has_few_false_positives() {
    let Some(dir) = data::real_data(
        "tum_fr2_desk_50",
        "detector_real::tum_fr2_desk_static_with_dvo_poses_has_few_false_positives",
    ) else {
        return;
    };
    let (fractions, failures, _) = closed_loop_fractions(
        &dir,
        PinholeIntrinsics::new(520.9, 521.0, 325.1, 249.7),
        ProcessingMode::Causal,
    );
    assert_eq!(failures, 0);
    check("tum_fr2_desk_50 (DVO closed loop)", &fractions, 0.01);
}

/// The causal closed loop on 7-Scenes' static kitchen: DVO tracks against keyframes while
/// nothing moves (docs/method.md D19), so the pose errors that frame-to-frame tracking adds up
/// (and the detector then marks) stay small. Measured: mean 0.032 %, max 0.448 %, no frame above
/// 1 % (0.028 % before the occlusion events of D22); frame to frame mean 0.524 %, max 3.906 %, 38
/// frames (before D22). Bounds: 4.7× the mean, the 1 % limit per frame.
#[test]
fn seven_scenes_redkitchen_causal_closed_loop_with_keyframes_has_few_false_positives() {
    const MAX_MEAN: f64 = 0.0015;
    let Some(dir) = data::real_data(
        "7scenes_redkitchen_300",
        "detector_real::seven_scenes_redkitchen_causal_closed_loop_with_keyframes_has_few_false_positives",
    ) else {
        return;
    };
    let (fractions, failures, _) = closed_loop_fractions(
        &dir,
        PinholeIntrinsics::new(585.0, 585.0, 320.0, 240.0),
        ProcessingMode::Causal,
    );
    assert_eq!(failures, 0);
    let (mean, worst, _) = summarise(
        "7scenes_redkitchen_300 (DVO closed loop, causal)",
        &fractions,
        0.01,
    );
    assert!(mean <= MAX_MEAN, "mean {:.3} %", 100.0 * mean);
    assert!(worst <= 0.01, "max {:.3} %", 100.0 * worst);
}

/// The offline closed loop (the default mode) on 7-Scenes, whose colour is not registered to its
/// depth: the registration check (docs/method.md D18) must find that and refine with the causal
/// closed loop's DVO (depth term weighted, keyframes), or the photometric refinement's pose
/// errors mark the static kitchen. Measured: mean 0.049 %, max 0.574 %, no frame above 1 %
/// (registration score 0.87; at full resolution 0.078 %, max 0.599 %); without the check
/// mean 1.347 %, 182 frames; with the check's first refinement (γ 10, frame to frame) 0.391 %,
/// 33 frames. Bounds: 4.5× the mean, the 1 % limit per frame.
#[test]
fn seven_scenes_redkitchen_offline_closed_loop_finds_the_colour_unregistered() {
    const MAX_MEAN: f64 = 0.0035;
    let Some(dir) = data::real_data(
        "7scenes_redkitchen_300",
        "detector_real::seven_scenes_redkitchen_offline_closed_loop_finds_the_colour_unregistered",
    ) else {
        return;
    };
    let (fractions, _, registration) = closed_loop_fractions(
        &dir,
        PinholeIntrinsics::new(585.0, 585.0, 320.0, 240.0),
        ProcessingMode::Offline,
    );
    assert_eq!(
        registration.map(|r| r.registered),
        Some(false),
        "{registration:?}"
    );
    let (mean, worst, _) = summarise(
        "7scenes_redkitchen_300 (DVO closed loop, offline)",
        &fractions,
        0.01,
    );
    assert!(mean <= MAX_MEAN, "mean {:.3} %", 100.0 * mean);
    assert!(worst <= 0.01, "max {:.3} %", 100.0 * worst);
}

/// The Bonn RGB-D Dynamic "crowd" window (200 frames, three people walking past a hand-held
/// camera), scored against free-space reference masks made with the motion capture
/// (`occmask::metrics::free_space`) and the camera path from the same motion capture
/// (`occmask::dataset::bonn`).
mod bonn_crowd {
    use super::*;
    use occmask::dataset::{self, bonn, DecodedPair};
    use occmask::image_buf::Mask;
    use occmask::metrics::free_space::{free_space_reference, FreeSpaceConfig, FreeSpaceView};
    use occmask::metrics::onset::{OnsetSummary, OnsetTracker, RegionTracker, ONSET_TARGET_FRAMES};
    use occmask::metrics::{ate, rpe, SegmentationSummary, SegmentationTally};
    use occmask::pipeline::PoseSource;
    use rayon::prelude::*;

    /// Motion-capture samples further apart than this around a frame are not interpolated.
    const MAX_POSE_GAP_NS: u64 = 100_000_000;

    struct Sequence {
        frames: Vec<DecodedPair>,
        /// Camera poses from the motion capture at each frame's colour time.
        truth_at_color: Vec<Isometry3<f64>>,
        reference: Vec<Mask>,
    }

    /// The window, loaded and its reference built once for every test of this module.
    fn loaded(dir: &Path) -> &'static Sequence {
        static SEQUENCE: std::sync::OnceLock<Sequence> = std::sync::OnceLock::new();
        SEQUENCE.get_or_init(|| load(dir))
    }

    fn load(dir: &Path) -> Sequence {
        let sequence = bonn::load(dir).unwrap();
        let truth = &sequence.groundtruth;
        let frames: Vec<DecodedPair> = sequence
            .association(20_000_000)
            .pairs
            .par_iter()
            .map(|p| dataset::decode_pair(&sequence, p, bonn::DEPTH_UNITS_PER_METER).unwrap())
            .collect();
        let at =
            |t: u64| interpolate(truth, t, MAX_POSE_GAP_NS).expect("the window is inside the motion capture");
        let views: Vec<FreeSpaceView> = frames
            .iter()
            .map(|f| FreeSpaceView {
                depth_m: &f.depth_m,
                world_from_camera: at(f.depth_timestamp_ns),
            })
            .collect();
        let reference = free_space_reference(&views, &bonn::INTRINSICS, &FreeSpaceConfig::default()).unwrap();
        let truth_at_color = frames.iter().map(|f| at(f.timestamp_ns)).collect();
        Sequence {
            frames,
            truth_at_color,
            reference,
        }
    }

    struct Run {
        poses: Vec<Isometry3<f64>>,
        masks: SegmentationSummary,
        ate_m: f64,
        rotation_rpe_30_deg: f64,
        /// The people's runs in the reference and their onsets.
        people: OnsetSummary,
    }

    impl Run {
        /// The offline closed loop's pose bounds, `min_f1` on the masks, and at most
        /// `max_late_runs` people's runs masked later than [`ONSET_TARGET_FRAMES`] or never.
        fn assert_offline_bounds(&self, what: &str, min_f1: f64, max_late_runs: usize) {
            assert!(
                self.ate_m <= OFFLINE_ATE_BOUND_M,
                "{what} ATE {:.4} m",
                self.ate_m
            );
            assert!(
                self.rotation_rpe_30_deg <= OFFLINE_ROTATION_RPE_BOUND_DEG,
                "{what} rotation RPE {:.2}°",
                self.rotation_rpe_30_deg
            );
            assert!(
                self.masks.mean_f1 >= min_f1,
                "{what} F1 {:.3}",
                self.masks.mean_f1
            );
            assert!(
                self.people.late.len() <= max_late_runs,
                "{what} people: {}",
                self.people
            );
        }
    }

    fn run(sequence: &Sequence, source: PoseSource, mode: ProcessingMode) -> Run {
        run_with(sequence, source, mode, ProcessorConfig::default(), "")
    }

    /// [`run`] with `base` for everything but the pose source and the mode; `label` (`,NAME`)
    /// names it in the printed line.
    fn run_with(
        sequence: &Sequence,
        source: PoseSource,
        mode: ProcessingMode,
        base: ProcessorConfig,
        label: &str,
    ) -> Run {
        let config = ProcessorConfig {
            pose_source: source,
            mode,
            ..base
        };
        let size = sequence.frames[0].gray.size();
        let (mut poses, mut frame_masks) = (Vec::new(), Vec::new());
        let mut keep = |out: FrameOutput<'_>| {
            poses.push(out.world_from_camera);
            frame_masks.push(out.mask.clone());
            Ok(())
        };
        let inputs = sequence.frames.iter().map(|f| FrameInput {
            timestamp_ns: f.timestamp_ns,
            gray: &f.gray,
            depth_m: &f.depth_m,
            world_from_marker: None,
            ignore_in_previous: None,
        });
        let mut processor = SequenceProcessor::new(size, bonn::INTRINSICS, config).unwrap();
        for input in inputs {
            processor.push(&input, &mut keep).unwrap();
        }
        processor.finish(&mut keep).unwrap();
        if mode == ProcessingMode::Offline && source == PoseSource::DvoClosedLoop {
            // D18: Bonn's colour is registered to its depth; the paper's refinement runs.
            let registration = processor.colour_registration();
            assert_eq!(registration.map(|r| r.registered), Some(true), "{registration:?}");
        }
        let mut tally = SegmentationTally::default();
        // Scored where the frame has depth: the reference, built from depth, says nothing
        // elsewhere.
        for ((mask, reference), frame) in frame_masks.iter().zip(&sequence.reference).zip(&sequence.frames) {
            tally
                .add_masks_where_depth_valid(mask, reference, &frame.depth_m)
                .unwrap();
        }
        let ate_m = ate(&poses, &sequence.truth_at_color).unwrap().rmse_m;
        let rotation_rpe_30_deg = rpe(&poses, &sequence.truth_at_color, 30)
            .unwrap()
            .rotation_rmse_deg;
        let masks = tally.summary();
        let mut regions = RegionTracker::for_reference(size);
        let mut onsets = OnsetTracker::new();
        for (mask, reference) in frame_masks.iter().zip(&sequence.reference) {
            onsets.add_frame(&regions.add_frame(reference, mask).unwrap());
        }
        let people = OnsetSummary::new(&onsets.runs(), ONSET_TARGET_FRAMES);
        println!(
            "bonn_crowd_200 {source:?} {mode:?}{label}: ATE {ate_m:.4} m, rotation RPE (30 frames) {rotation_rpe_30_deg:.2}°, \
             masks F1 {:.3} P {:.3} R {:.3}",
            masks.mean_f1, masks.mean_precision, masks.mean_recall
        );
        println!("bonn_crowd_200 people {source:?} {mode:?}{label}: {people}");
        Run {
            poses,
            masks,
            ate_m,
            rotation_rpe_30_deg,
            people,
        }
    }

    #[test]
    fn offline_closed_loop_holds_the_camera_and_masks_the_people() {
        let Some(dir) = data::real_data(
            "bonn_crowd_200",
            "detector_real::bonn_crowd::offline_closed_loop_holds_the_camera_and_masks_the_people",
        ) else {
            return;
        };
        let sequence = loaded(&dir);
        assert_eq!(sequence.frames.len(), 200);
        let closed = run(sequence, PoseSource::DvoClosedLoop, ProcessingMode::Offline);
        let unmasked = run(sequence, PoseSource::DvoUnmasked, ProcessingMode::Offline);
        let causal = run(sequence, PoseSource::DvoClosedLoop, ProcessingMode::Causal);
        assert_eq!(closed.poses.len(), 200);
        // Bounds: measured values in docs/accuracy.md ("Bonn crowd"), each with its margin.
        closed.assert_offline_bounds("offline", OFFLINE_F1_BOUND, OFFLINE_MAX_LATE_RUNS);
        assert!(
            closed.ate_m <= unmasked.ate_m / 3.0,
            "offline ATE {:.4} m vs unmasked {:.4} m",
            closed.ate_m,
            unmasked.ate_m
        );
        assert!(
            causal.ate_m <= CAUSAL_ATE_BOUND_M,
            "causal ATE {:.4} m",
            causal.ate_m
        );
        assert!(
            causal.masks.mean_f1 >= CAUSAL_F1_BOUND,
            "causal F1 {:.3}",
            causal.masks.mean_f1
        );
        assert!(
            causal.people.late.len() <= CAUSAL_MAX_LATE_RUNS,
            "causal people: {}",
            causal.people
        );
    }

    /// The opt-in far-layer preset (docs/method.md D21) on real people: measured ATE 0.0464 m,
    /// F1 0.950 (the default: 0.0421 m, 0.952); held to the default's bounds.
    #[test]
    fn offline_closed_loop_with_the_far_layer_preset_keeps_the_default_bounds() {
        let Some(dir) = data::real_data(
            "bonn_crowd_200",
            "detector_real::bonn_crowd::offline_closed_loop_with_the_far_layer_preset_keeps_the_default_bounds",
        ) else {
            return;
        };
        let preset = crate::common::detector_preset("far_layer.json");
        let sequence = loaded(&dir);
        let far = run_with(
            sequence,
            PoseSource::DvoClosedLoop,
            ProcessingMode::Offline,
            preset,
            ",far_layer.json",
        );
        far.assert_offline_bounds("far_layer.json", OFFLINE_F1_BOUND, FAR_LAYER_MAX_LATE_RUNS);
    }

    /// The offline mode at full resolution (`--full-resolution`, docs/method.md D24): measured
    /// ATE 0.0475 m, F1 0.958 (the default working resolution: 0.0421 m, 0.952). Its masks stay
    /// the more complete: held to the default's pose bounds and a higher F1 bound.
    #[test]
    fn offline_closed_loop_without_halving_masks_more_of_the_people() {
        let Some(dir) = data::real_data(
            "bonn_crowd_200",
            "detector_real::bonn_crowd::offline_closed_loop_without_halving_masks_more_of_the_people",
        ) else {
            return;
        };
        let mut config = ProcessorConfig::default();
        config.offline.min_working_side_px = 0;
        let full = run_with(
            loaded(&dir),
            PoseSource::DvoClosedLoop,
            ProcessingMode::Offline,
            config,
            ",full_resolution",
        );
        full.assert_offline_bounds(
            "--full-resolution",
            FULL_RESOLUTION_F1_BOUND,
            OFFLINE_MAX_LATE_RUNS,
        );
    }

    // Measured (docs/accuracy.md): offline ATE 0.0421 m, rotation RPE 1.18°, F1 0.952 (far-layer
    // preset 0.0464 m, 1.25°, 0.950; full resolution 0.0475 m, 1.31°, 0.958); causal ATE
    // 0.0668 m, F1 0.924. Bounds 35–55 % above (ATE, RPE) or 0.05 below (F1): DVO's result
    // moved by several millimetres with small changes elsewhere in the pipeline.
    const OFFLINE_ATE_BOUND_M: f64 = 0.065;
    const OFFLINE_ROTATION_RPE_BOUND_DEG: f64 = 1.8;
    const OFFLINE_F1_BOUND: f64 = 0.89;
    const FULL_RESOLUTION_F1_BOUND: f64 = 0.90;
    const CAUSAL_ATE_BOUND_M: f64 = 0.09;
    const CAUSAL_F1_BOUND: f64 = 0.87;
    // Measured (docs/accuracy.md), of the reference's 20 people's runs: masked later than 5
    // frames or never, offline 1 (also at full resolution), far-layer preset 3, causal 4.
    // Bounds 2 or 3 runs above.
    const OFFLINE_MAX_LATE_RUNS: usize = 3;
    const FAR_LAYER_MAX_LATE_RUNS: usize = 5;
    const CAUSAL_MAX_LATE_RUNS: usize = 7;
}
