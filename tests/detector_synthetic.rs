//! Detector accuracy on every synthetic scenario at 640×480 with the true (external) camera
//! motion (targets: mean F1 ≥ 0.90 per scenario; static control false-positive
//! fraction ≤ 0.5 % per frame after the first 5 frames). Default `OcclusionConfig`.
//!
//! One scenario (still, then moving) reaches the 0.90 target with the causal detector only with
//! appearance-gated object completion, which its test switches on (the default leaves it off,
//! see docs/method.md, "Deviations").
#![allow(clippy::unwrap_used)]

use occmask::image_buf::ImageSize;
use occmask::metrics::{FrameCounts, SegmentationSummary, SegmentationTally};
use occmask::occlusion::{AppearanceGrowthConfig, OcclusionConfig, OcclusionDetector};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

const SIZE: ImageSize = ImageSize::new(640, 480);
/// The F1 target with the true pose.
const F1_TARGET: f64 = 0.90;
/// Frames excluded from the static-control false-positive check.
const STATIC_WARM_UP_FRAMES: usize = 5;
/// The static-control limit: 0.5 % of the pixels per frame.
const STATIC_FP_LIMIT: f64 = 0.005;

/// Runs the default detector with the true motion; returns the summary and every frame's counts.
fn run(scenario: Scenario) -> (SegmentationSummary, Vec<FrameCounts>) {
    run_with(scenario, OcclusionConfig::default())
}

/// [`run`] with `detector` instead of the default config.
fn run_with(scenario: Scenario, detector_config: OcclusionConfig) -> (SegmentationSummary, Vec<FrameCounts>) {
    let config = SequenceConfig {
        size: SIZE,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(scenario, config);
    let mut detector = OcclusionDetector::new(SIZE, config.intrinsics(), detector_config).unwrap();
    let mut tally = SegmentationTally::default();
    let mut counts = Vec::new();
    let mut frame = sequence.frame(0);
    for i in 0..sequence.len() {
        sequence.render_into(i, &mut frame);
        let mask = detector
            .update_with_gray(
                &frame.depth_m,
                Some(&frame.gray),
                &sequence.current_from_previous(i),
            )
            .unwrap();
        counts.push(tally.add_masks(mask, &frame.gt_mask).unwrap());
    }
    let summary = tally.summary();
    println!(
        "{}: mean F1 {:.3} (precision {:.3}, recall {:.3}) over {} frames with objects",
        scenario.name(),
        summary.mean_f1,
        summary.mean_precision,
        summary.mean_recall,
        summary.frames_with_truth
    );
    (summary, counts)
}

fn assert_f1(scenario: Scenario, at_least: f64) {
    let (summary, _) = run(scenario);
    assert!(summary.frames_with_truth >= 40);
    assert!(
        summary.mean_f1 >= at_least,
        "{}: mean F1 {:.3} < {at_least}",
        scenario.name(),
        summary.mean_f1
    );
    // Whatever the recall, the detector must not invent objects.
    assert!(
        summary.mean_precision >= 0.95,
        "{}: precision {:.3}",
        scenario.name(),
        summary.mean_precision
    );
}

#[test]
fn small_object_crossing() {
    assert_f1(Scenario::SmallObjectCrossing, F1_TARGET);
}

#[test]
fn dominant_object() {
    assert_f1(Scenario::DominantObject, F1_TARGET);
}

#[test]
fn two_objects_crossing() {
    assert_f1(Scenario::TwoObjectsCrossing, F1_TARGET);
}

#[test]
fn slow_approach() {
    assert_f1(Scenario::SlowApproach, F1_TARGET);
}

#[test]
fn entering_while_panning() {
    assert_f1(Scenario::EnteringWhilePanning, F1_TARGET);
}

/// A box that stood still is background; when it starts moving only the parts leaving its old
/// footprint occlude anything (the paper's method alone: frames 31–47 ramp recall 0.04 → 0.91,
/// mean F1 0.839, docs/accuracy.md). Appearance-gated object completion
/// (`OcclusionConfig::appearance_growth`) grows the detected strip over the rest of the moving,
/// textured box (measured 0.901). While it leaves the view at the right border (frames 85–87)
/// its visible remainder lies entirely in once-predicted area: it must stay detected
/// (`OcclusionConfig::prune_exit_margin_px`), until it is smaller than the object threshold
/// (frame 88, 636 px).
#[test]
fn still_then_moving() {
    let (summary, counts) = run_with(
        Scenario::StillThenMoving,
        OcclusionConfig {
            appearance_growth: Some(AppearanceGrowthConfig::default()),
            ..OcclusionConfig::default()
        },
    );
    assert!(summary.mean_f1 >= F1_TARGET, "mean F1 {:.3}", summary.mean_f1);
    // The growth completes the box within a few frames of its start (from frame 32, the second
    // frame the strip is detected; measured F1 0.948 at frame 39): the paper's method alone is
    // at 0.620 there.
    assert!(counts[39].f1() >= 0.9, "frame 39: F1 {:.3}", counts[39].f1());
    assert!(summary.mean_precision >= 0.95);
    for (i, c) in counts.iter().enumerate().take(88).skip(85) {
        assert!(
            c.recall() >= 0.6,
            "frame {i}: recall {:.3} while leaving the view",
            c.recall()
        );
    }
}

#[test]
fn static_control_has_almost_no_false_positives() {
    let (summary, counts) = run(Scenario::StaticScene);
    assert_eq!(summary.frames_with_truth, 0);
    for (i, c) in counts.iter().enumerate().skip(STATIC_WARM_UP_FRAMES) {
        assert!(
            c.false_positive_fraction() <= STATIC_FP_LIMIT,
            "frame {i}: {:.3} % false positives",
            100.0 * c.false_positive_fraction()
        );
    }
}
