//! The paper's closed loop on the synthetic scenarios at 640×480: DVO estimates the motion with
//! the previous mask as its ignore mask, the detector uses that motion (targets:
//! mean F1 ≥ 0.85 per scenario; static control ≤ 0.5 % false positives per frame after 5
//! frames; on the dominant-object scenario the closed loop has ≥ 2× lower RPE than unmasked DVO).
//!
//! One scenario (still, then moving) needs appearance-gated object completion (off by default)
//! for the target in one causal pass, for the reason given in `detector_synthetic.rs`.
#![allow(clippy::unwrap_used)]

use nalgebra::Isometry3;
use occmask::dvo::DvoStatus;
use occmask::image_buf::ImageSize;
use occmask::metrics::{rpe, RpeStats, SegmentationSummary, SegmentationTally};
use occmask::occlusion::AppearanceGrowthConfig;
use occmask::pipeline::{FrameInput, PoseSource, Processor, ProcessorConfig};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

const SIZE: ImageSize = ImageSize::new(640, 480);
/// The closed-loop F1 target.
const F1_TARGET: f64 = 0.85;

struct Run {
    segmentation: SegmentationSummary,
    max_empty_fp_after_warm_up: f64,
    rpe_1: RpeStats,
    rpe_30: RpeStats,
    failures: usize,
}

fn run(scenario: Scenario, pose_source: PoseSource) -> Run {
    run_with(
        scenario,
        ProcessorConfig {
            pose_source,
            ..ProcessorConfig::default()
        },
    )
}

/// `scenario` through the causal pipeline with `config`.
fn run_with(scenario: Scenario, config: ProcessorConfig) -> Run {
    let pose_source = config.pose_source;
    let sequence_config = SequenceConfig {
        size: SIZE,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(scenario, sequence_config);
    let mut processor = Processor::new(SIZE, sequence_config.intrinsics(), config).unwrap();
    let mut tally = SegmentationTally::default();
    let mut estimated = Vec::new();
    let mut truth: Vec<Isometry3<f64>> = Vec::new();
    let mut failures = 0;
    let mut max_empty_fp_after_warm_up: f64 = 0.0;
    let mut frame = sequence.frame(0);
    for i in 0..sequence.len() {
        sequence.render_into(i, &mut frame);
        let out = processor
            .process(&FrameInput {
                timestamp_ns: frame.timestamp_ns,
                gray: &frame.gray,
                depth_m: &frame.depth_m,
                world_from_marker: None,
                ignore_in_previous: None,
            })
            .unwrap();
        failures += usize::from(out.stats.dvo.is_some_and(|d| d.status != DvoStatus::Converged));
        let counts = tally.add_masks(out.mask, &frame.gt_mask).unwrap();
        if i >= 5 && counts.truth_is_empty() {
            max_empty_fp_after_warm_up = max_empty_fp_after_warm_up.max(counts.false_positive_fraction());
        }
        estimated.push(out.world_from_camera);
        truth.push(frame.world_from_camera);
    }
    let run = Run {
        segmentation: tally.summary(),
        max_empty_fp_after_warm_up,
        rpe_1: rpe(&estimated, &truth, 1).unwrap(),
        rpe_30: rpe(&estimated, &truth, 30).unwrap(),
        failures,
    };
    let s = &run.segmentation;
    println!(
        "{} {}: F1 {:.3} (P {:.3}, R {:.3}), RPE(1) {:.4} m {:.3}°, RPE(30) {:.4} m {:.3}°, DVO failures {}",
        scenario.name(),
        if matches!(pose_source, PoseSource::DvoUnmasked) {
            "unmasked DVO"
        } else {
            "closed loop"
        },
        s.mean_f1,
        s.mean_precision,
        s.mean_recall,
        run.rpe_1.translation_rmse_m,
        run.rpe_1.rotation_rmse_deg,
        run.rpe_30.translation_rmse_m,
        run.rpe_30.rotation_rmse_deg,
        run.failures
    );
    run
}

fn closed_loop() -> PoseSource {
    PoseSource::DvoClosedLoop
}

fn assert_f1(scenario: Scenario, at_least: f64) {
    assert_run_f1(scenario, &run(scenario, closed_loop()), at_least);
}

fn assert_run_f1(scenario: Scenario, run: &Run, at_least: f64) {
    assert!(
        run.segmentation.mean_f1 >= at_least,
        "{}: F1 {:.3} < {at_least}",
        scenario.name(),
        run.segmentation.mean_f1
    );
    assert!(run.segmentation.mean_precision >= 0.95);
    assert_eq!(run.failures, 0);
}

/// Measured F1 0.978; bound: the target (0.85).
#[test]
fn small_object_crossing() {
    assert_f1(Scenario::SmallObjectCrossing, F1_TARGET);
}

/// Measured F1 0.937; bound: the target (0.85).
#[test]
fn two_objects_crossing() {
    assert_f1(Scenario::TwoObjectsCrossing, F1_TARGET);
}

/// Measured F1 0.934; bound: the target (0.85).
#[test]
fn slow_approach() {
    assert_f1(Scenario::SlowApproach, F1_TARGET);
}

/// Measured F1 0.977; bound: the target (0.85).
#[test]
fn entering_while_panning() {
    assert_f1(Scenario::EnteringWhilePanning, F1_TARGET);
}

/// One pass cannot reach the target on this scenario without appearance-gated object completion
/// (off by default): measured 0.888 with it, 0.828 without (see `detector_synthetic.rs`);
/// bound: the target (0.85).
#[test]
fn still_then_moving_with_appearance_growth() {
    let mut config = ProcessorConfig::default();
    config.occlusion.appearance_growth = Some(AppearanceGrowthConfig::default());
    let run = run_with(Scenario::StillThenMoving, config);
    assert_run_f1(Scenario::StillThenMoving, &run, F1_TARGET);
}

/// The causal default (no appearance growth) on the same scenario: measured 0.828; bound 0.80.
#[test]
fn still_then_moving_causal_default() {
    assert_f1(Scenario::StillThenMoving, 0.80);
}

#[test]
fn static_control_has_almost_no_false_positives() {
    let run = run(Scenario::StaticScene, closed_loop());
    assert!(
        run.max_empty_fp_after_warm_up <= 0.005,
        "{:.3} %",
        100.0 * run.max_empty_fp_after_warm_up
    );
}

/// The paper's central claim: with a dominant moving object, feeding the mask back into DVO
/// keeps the pose right, while unmasked DVO is dragged along by the object. Measured closed
/// loop F1 0.982, RPE(1) 4.0 mm, RPE(30) 81 mm; unmasked RPE(1) 15.6 mm, RPE(30) 485 mm
/// (bound: at most half the unmasked error).
#[test]
fn dominant_object_closed_loop_beats_unmasked_dvo() {
    let closed = run(Scenario::DominantObject, closed_loop());
    let unmasked = run(Scenario::DominantObject, PoseSource::DvoUnmasked);
    assert!(
        closed.segmentation.mean_f1 >= F1_TARGET,
        "closed-loop F1 {:.3}",
        closed.segmentation.mean_f1
    );
    for (what, c, u) in [
        (
            "RPE(1 frame)",
            closed.rpe_1.translation_rmse_m,
            unmasked.rpe_1.translation_rmse_m,
        ),
        (
            "RPE(30 frames)",
            closed.rpe_30.translation_rmse_m,
            unmasked.rpe_30.translation_rmse_m,
        ),
    ] {
        assert!(2.0 * c <= u, "{what}: closed loop {c:.4} m vs unmasked {u:.4} m");
    }
}
