//! Detector accuracy on every synthetic scenario at 640×480 with the true (external) camera
//! motion (targets: mean F1 ≥ 0.90 per scenario; static control false-positive
//! fraction ≤ 0.5 % per frame after the first 5 frames). Default `OcclusionConfig`.
//!
//! One scenario (still, then moving) reaches the 0.90 target with the causal detector only with
//! appearance-gated object completion, which its test switches on (the default leaves it off,
//! see docs/method.md, "Deviations").
//!
//! The failure-class scenarios (`Scenario::FAILURE_CLASSES`, `Scenario::HELD_OUT`) run through
//! the whole pipeline instead: the default `ProcessorConfig` in the default mode (offline, DVO
//! closed loop) at 320×240, against the targets F1 ≥ 0.85 with DVO over all frames, onset ≤ 5
//! frames (`occmask::metrics::onset`) and static controls ≤ 0.5 % false positives. Where a
//! class does not meet them yet, its test holds the figure the code meets (with the measured
//! value and the margin stated) and an ignored test states the target. The head-on approach and
//! the box sliding on a desk are found by the slow-change evidence (`OcclusionConfig::slow_evidence`,
//! docs/method.md D16).
#![allow(clippy::unwrap_used)]

use occmask::image_buf::ImageSize;
use occmask::metrics::onset::ONSET_TARGET_FRAMES;
use occmask::metrics::{FrameCounts, SegmentationSummary, SegmentationTally};
use occmask::occlusion::{AppearanceGrowthConfig, OcclusionConfig, OcclusionDetector};
use occmask::pipeline::ProcessorConfig;
use occmask::scenario_eval::{evaluate, EvalMode, RenderedSequence, ScenarioScore};
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

/// Measured F1 0.978 (margin 0.078); bound: the target 0.90.
#[test]
fn small_object_crossing() {
    assert_f1(Scenario::SmallObjectCrossing, F1_TARGET);
}

/// Measured F1 0.983 (margin 0.083); bound: the target 0.90.
#[test]
fn dominant_object() {
    assert_f1(Scenario::DominantObject, F1_TARGET);
}

/// Measured F1 0.939 (margin 0.039); bound: the target 0.90.
#[test]
fn two_objects_crossing() {
    assert_f1(Scenario::TwoObjectsCrossing, F1_TARGET);
}

/// Measured F1 0.936 (margin 0.036); bound: the target 0.90.
#[test]
fn slow_approach() {
    assert_f1(Scenario::SlowApproach, F1_TARGET);
}

/// Measured F1 0.978 (margin 0.078); bound: the target 0.90.
#[test]
fn entering_while_panning() {
    assert_f1(Scenario::EnteringWhilePanning, F1_TARGET);
}

/// A box that stood still is background; when it starts moving only the parts leaving its old
/// footprint occlude anything (the paper's method alone: frames 31–47 ramp recall 0.04 → 0.91,
/// mean F1 0.839, docs/accuracy.md). Appearance-gated object completion
/// (`OcclusionConfig::appearance_growth`) grows the detected strip over the rest of the moving,
/// textured box (measured 0.901: 0.001 above the target bound). While it leaves the view at the right border (frames 85–87)
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

/// Resolution of the failure-class tests: a quarter of VGA renders and processes a 100-frame
/// scenario in ≈ 10 s on the 2-core machine (640×480: ≈ 1 min).
const CLASS_SIZE: ImageSize = ImageSize::new(320, 240);
/// The target for the failure classes: mean F1 with DVO over all frames with an object.
const CLASS_F1_TARGET: f64 = 0.85;

/// `scenario` at [`CLASS_SIZE`] through the default configuration in the default mode (offline,
/// DVO closed loop).
fn default_mode(scenario: Scenario) -> ScenarioScore {
    offline_mode(scenario, &ProcessorConfig::default(), "")
}

/// `scenario` at [`CLASS_SIZE`] through `config` in the offline mode with the DVO closed loop;
/// `label` names a configuration other than the default in the printed line.
fn offline_mode(scenario: Scenario, config: &ProcessorConfig, label: &str) -> ScenarioScore {
    run_mode(scenario, EvalMode::DvoOffline, config, label)
}

/// `scenario` at [`CLASS_SIZE`] through `config` in `mode`; `label` names a configuration or
/// mode other than the default in the printed line.
fn run_mode(scenario: Scenario, mode: EvalMode, config: &ProcessorConfig, label: &str) -> ScenarioScore {
    let sequence_config = SequenceConfig {
        size: CLASS_SIZE,
        ..SequenceConfig::default()
    };
    let rendered = RenderedSequence::render(&SyntheticSequence::new(scenario, sequence_config));
    let score = evaluate(&rendered, mode, config).unwrap();
    let s = &score.segmentation;
    println!(
        "{}{}{label}: F1 {:.3} (P {:.3}, R {:.3}) over {} frames, onset {} [{}], max FP without objects {:.3} %, ATE {:.3} m",
        if scenario.is_held_out() { "held out: " } else { "" },
        scenario.name(),
        s.mean_f1,
        s.mean_precision,
        s.mean_recall,
        s.frames_with_truth,
        onset_text(&score),
        score
            .onset_runs
            .iter()
            .map(|r| format!("{}:{:?}", r.first_frame, r.onset_frames))
            .collect::<Vec<_>>()
            .join(" "),
        100.0 * score.max_fp_fraction_without_objects,
        score.ate_m
    );
    score
}

fn onset_text(score: &ScenarioScore) -> String {
    match (score.worst_onset_frames, score.onset_never) {
        (_, true) => "never".into(),
        (Some(d), false) => format!("{d} frames"),
        (None, false) => "–".into(),
    }
}

/// Mean F1 ≥ `f1_at_least` and every run's onset ≤ `onset_at_most` frames.
fn assert_class(score: &ScenarioScore, name: &str, f1_at_least: f64, onset_at_most: usize) {
    assert!(
        score.segmentation.mean_f1 >= f1_at_least,
        "{name}: F1 {:.3} < {f1_at_least}",
        score.segmentation.mean_f1
    );
    assert!(
        !score.onset_never && score.worst_onset_frames.is_some_and(|d| d <= onset_at_most),
        "{name}: onset {} > {onset_at_most} frames",
        onset_text(score)
    );
}

/// Late onset, an object moving at the first frame: the backward pass finds it from frame 0.
/// Measured F1 0.984, onset 0 (the causal mode: [`causal_mode_finds_an_object_in_view_at_start_at_once`]);
/// bounds: the targets.
#[test]
fn failure_class_in_view_at_start() {
    let score = default_mode(Scenario::InViewAtStart);
    assert_class(&score, "in_view_at_start", CLASS_F1_TARGET, ONSET_TARGET_FRAMES);
}

/// The causal mode, with no backward pass, finds the object moving at the first frame at once
/// too: the strip along its leading edge is completed to the depth-connected box
/// (docs/method.md D26). Measured F1 0.981, onset 1 (without the completion 0.806, 21);
/// bounds: the targets.
#[test]
fn causal_mode_finds_an_object_in_view_at_start_at_once() {
    let score = run_mode(
        Scenario::InViewAtStart,
        EvalMode::DvoCausal,
        &ProcessorConfig::default(),
        " (causal)",
    );
    assert_class(&score, "in_view_at_start", CLASS_F1_TARGET, ONSET_TARGET_FRAMES);
}

/// Late onset, an object that stops and moves again: both starts found at once.
/// Measured F1 0.981, onsets 0 and 0; bounds: the targets.
#[test]
fn failure_class_stop_and_go() {
    let score = default_mode(Scenario::StopAndGo);
    assert_class(&score, "stop_and_go", CLASS_F1_TARGET, ONSET_TARGET_FRAMES);
}

/// Late onset, an object that rests for 1.5 s and then slides slowly (its own width in 43
/// frames), at its targets: while it rests, the first pass tracks against keyframes
/// (docs/method.md D19), and the backward pass, on those poses, masks the box from its first
/// frame of motion. Measured F1 0.993, onset 0 (0.943 without the body completion of
/// docs/method.md D26; frame to frame, `dvo.keyframe` null, before D26: 0.828, 19; the paper's
/// accumulation alone: 0.778, 24); bounds: the targets. Its frames before the
/// motion are marked too (up to 11.3 % of the image, the box itself: it is about to move).
#[test]
fn failure_class_rests_then_moves_slowly() {
    let score = default_mode(Scenario::RestsThenMovesSlowly);
    assert_class(
        &score,
        "rests_then_moves_slowly",
        CLASS_F1_TARGET,
        ONSET_TARGET_FRAMES,
    );
}

/// Head-on approach, at its targets: the slow-change evidence confirms it 8 frames after the
/// box starts (it has come 0.19 m closer, 5 % of its depth; the evidence threshold is 4 %), and
/// the offline temporal hysteresis carries that back to the frames where its evidence was
/// above half the threshold; the paper's accumulation alone never finds it. Measured F1 0.957,
/// onset 4 (without the body completion, D26: 0.946, 3; without the hysteresis 0.866, 8). The approaching box does not drag the odometry
/// (measured ATE 2.7 cm over 105 frames; bound 4 cm) and little else is flagged (measured
/// 0.100 % of the image at most on the 15 frames before it moves; limit 0.5 %).
#[test]
fn failure_class_head_on_approach() {
    let score = default_mode(Scenario::HeadOnApproach);
    assert_class(&score, "head_on_approach", CLASS_F1_TARGET, ONSET_TARGET_FRAMES);
    assert!(score.ate_m <= 0.04, "ATE {:.3} m", score.ate_m);
    assert!(
        score.max_fp_fraction_without_objects <= STATIC_FP_LIMIT,
        "{:.3} % false positives before it moves",
        100.0 * score.max_fp_fraction_without_objects
    );
}

/// Near background, a box sliding on a desk: the sub-threshold steps with which it covers the
/// desk add up in the slow-change evidence (the paper's accumulation alone finds it only where
/// it passes in front of the far wall: F1 0.615, onset 39). Measured F1 0.900, onset 7 (0.892
/// before the body completion kept growths without their support plane, docs/method.md D27; 0.882,
/// 9 while a leaving object's remainder needed the full object size, docs/method.md D23; 0.880
/// before occlusion events entered the evidence, D22; with the offline passes' DVO at 80×60
/// and 160×120: 0.859, 12; without the temporal hysteresis 0.822, 13; true pose 0.831, 11);
/// bounds F1 0.85 (the target), onset 9.
/// Onset: the box enters at the image corner (1 px at frame 2) through the sensor's invalid
/// border ring: at frame 7 (onset 5) 84 of its 105 px have no depth, and on its 21 measured
/// pixels the depth fell by at most 0.23 m since frame 6 (true poses; τ_α there is 0.24 m). Its visible part reaches the
/// object threshold (125 px at 320×240) at frame 8 and is half found at frame 9.
#[test]
fn failure_class_sliding_on_desk() {
    let score = default_mode(Scenario::SlidingOnDesk);
    assert_class(&score, "sliding_on_desk", CLASS_F1_TARGET, 9);
}

/// The target for [`failure_class_sliding_on_desk`] (F1 met, onset not: F1 0.900, onset 7).
#[test]
#[ignore = "not met by the default: F1 0.900, onset 7 frames"]
fn failure_class_sliding_on_desk_target() {
    let score = default_mode(Scenario::SlidingOnDesk);
    assert_class(&score, "sliding_on_desk", CLASS_F1_TARGET, ONSET_TARGET_FRAMES);
}

/// Dominant from the first frame, at its targets: with the first pass's DVO at 160×120 the
/// odometry follows the background (and, over the detector's first 30 frames, frame to frame:
/// D19), but the passes mark only the strip along the board's leading edge, and the board's
/// interior, sliding along its own plane, looks static frame to frame. The strip, completed to
/// the depth-connected body it belongs to (docs/method.md D26), is the whole board: measured F1
/// 0.998, onset 0, ATE 0.056 m (without the completion, `body_completion` null: 0.581,
/// onset 77; with the offline passes' DVO at 80×60 and 160×120 the odometry followed the board:
/// F1 0.035, ATE 0.286 m). Bounds: the targets, ATE 0.08 m.
#[test]
fn failure_class_dominant_from_start() {
    let score = default_mode(Scenario::DominantFromStart);
    assert_class(
        &score,
        "dominant_from_start",
        CLASS_F1_TARGET,
        ONSET_TARGET_FRAMES,
    );
    assert!(score.ate_m <= 0.08, "ATE {:.3} m", score.ate_m);
}

/// The causal mode on the same board: DVO follows the board until the detector first masks it
/// (frame 22), and the motion prior then no longer predicts from the board's motion
/// (`MotionPriorConfig::max_ignored_fraction_increase`, docs/method.md D13). Measured F1 0.807,
/// onset 22, ATE 0.082 m (predicting from it: F1 0.131, ATE 0.272 m); bounds F1 0.75, ATE
/// 0.12 m.
#[test]
fn causal_mode_stops_following_the_dominant_board_once_it_is_masked() {
    let score = run_mode(
        Scenario::DominantFromStart,
        EvalMode::DvoCausal,
        &ProcessorConfig::default(),
        " (causal)",
    );
    assert!(
        score.segmentation.mean_f1 >= 0.75,
        "F1 {:.3}",
        score.segmentation.mean_f1
    );
    assert!(score.ate_m <= 0.12, "ATE {:.3} m", score.ate_m);
}

/// `tools/detector_configs/far_layer.json`, the opt-in first pass that tracks only the far
/// background (docs/method.md D21), as `--config` reads it.
fn far_layer_preset() -> ProcessorConfig {
    let config = crate::common::detector_preset("far_layer.json");
    assert!(config.offline.first_pass_ignore_nearer_than.is_some());
    config
}

/// With the far-layer preset the first pass does not follow the board that fills the near view
/// from the first frame, and the board is found from frame 0. Measured F1 0.998, onset 0, ATE
/// 0.056 m (0.932 before the body completion of D26, which alone now gives the default 0.990);
/// bounds: the targets. The static desk stays without false positives (measured 0 %).
#[test]
fn far_layer_preset_finds_the_dominant_board_from_the_first_frame() {
    let config = far_layer_preset();
    let score = offline_mode(Scenario::DominantFromStart, &config, " (far_layer.json)");
    assert_class(
        &score,
        "dominant_from_start",
        CLASS_F1_TARGET,
        ONSET_TARGET_FRAMES,
    );
    assert!(score.ate_m <= 0.08, "ATE {:.3} m", score.ate_m);
    let score = offline_mode(Scenario::StaticDesk, &config, " (far_layer.json)");
    assert!(
        score.max_fp_fraction_without_objects <= STATIC_FP_LIMIT,
        "{:.3} %",
        100.0 * score.max_fp_fraction_without_objects
    );
}

/// The static control with a desk in view. Measured 0 false positives on every frame, ATE
/// 0.8 mm (4.9 mm with the refinement pass's DVO at 160×120, `offline.refinement_min_side_px`
/// 0); bound 2.5 mm.
#[test]
fn failure_class_static_desk() {
    let score = default_mode(Scenario::StaticDesk);
    assert_eq!(score.segmentation.frames_with_truth, 0);
    assert!(score.ate_m <= 0.0025, "ATE {:.4} m", score.ate_m);
    assert!(
        score.max_fp_fraction_without_objects <= STATIC_FP_LIMIT,
        "{:.3} %",
        100.0 * score.max_fp_fraction_without_objects
    );
}

/// Held out (no default was tuned on these; the slow-change evidence's parameters were chosen
/// on the failure classes and the Bonn window, and these were run afterwards; reported apart,
/// bounds looser): measured at 320×240 F1 / onset: in view at start 0.954 / 0, rests then
/// moves 0.984 / 0, head-on 0.962 / 2, sliding on the floor 0.912 / 4 (0.821 before the
/// support plane of docs/method.md D27, whose tolerance was chosen before it ran), dominant from start
/// 0.987 / 0 (ATE 0.037 m; 0.235 / never before the body completion of docs/method.md D26,
/// whose gates were chosen with this board in view, so it is no longer held out for D26);
/// static 0 % false positives; a block standing on the floor, the floor in view, that fills
/// more than half the view from the first frame (added after D26, run once as defined: F1
/// 0.734, onset 2, its leading half; its own face was the largest plane of its growth, so the
/// completion dropped it): 0.903 (P 1.000, R 0.842), onset 0, ATE 0.034 m now that D27 passes
/// over a body's own faces, a rule built on it (so it is held out no longer for that rule); a
/// nearer, narrower block on the floor that turns as it moves off (added after that rule, run
/// once as defined): 0.993, onset 0, ATE 0.022 m, the same without the rule. Bounds: the targets (dominant boards and
/// blocks: ATE 0.10 m). A low, wide block on the floor that moves slowly sideways (added
/// after that, run once as defined: F1 0.012, never half found; the thin-structure filter's
/// advance rule was then built on it, so it is held out no longer for that rule) misses the
/// onset target: [`a_slowly_advancing_edge_is_found_by_the_advance_rule`] holds it; this test
/// holds the other held-out scenarios to the targets. A slow cart (added after the advance
/// rule, run once as defined) misses the F1 target: [`a_slow_cart_is_lost_in_the_last_frames`].
#[test]
fn held_out_scenarios() {
    let diagnosed = [Scenario::HeldOutWideOnFloor, Scenario::HeldOutSlowCart];
    for scenario in Scenario::HELD_OUT.into_iter().filter(|s| !diagnosed.contains(s)) {
        let score = default_mode(scenario);
        let name = scenario.name();
        match scenario {
            Scenario::HeldOutInViewAtStart
            | Scenario::HeldOutRestsThenMoves
            | Scenario::HeldOutHeadOnApproach
            | Scenario::HeldOutSlidingOnFloor => {
                assert_class(&score, name, CLASS_F1_TARGET, ONSET_TARGET_FRAMES)
            }
            Scenario::HeldOutDominantFromStart
            | Scenario::HeldOutDominantOnFloor
            | Scenario::HeldOutCloseOnFloor => {
                assert_class(&score, name, CLASS_F1_TARGET, ONSET_TARGET_FRAMES);
                assert!(score.ate_m <= 0.10, "{name}: ATE {:.3} m", score.ate_m);
            }
            Scenario::HeldOutStatic => {
                assert!(
                    score.max_fp_fraction_without_objects <= STATIC_FP_LIMIT,
                    "{name}: {:.3} %",
                    100.0 * score.max_fp_fraction_without_objects
                );
            }
            _ => unreachable!("{name} is not held out"),
        }
    }
}

/// `scenario` offline with DVO and the plain thin-structure opening (no advance rule) scores an
/// F1 below `f1_below`.
fn assert_plain_opening_misses(scenario: Scenario, f1_below: f64) {
    let mut plain_opening = ProcessorConfig::default();
    plain_opening.occlusion.thin_structure_advance = false;
    let plain = offline_mode(scenario, &plain_opening, " with the plain thin-structure opening");
    let f1 = plain.segmentation.mean_f1;
    assert!(
        f1 < f1_below,
        "{}: F1 {f1:.3} with the plain opening",
        scenario.name()
    );
}

/// The held-out wide block on the floor (see [`held_out_scenarios`]): its edges advance about
/// 1.5 px a frame at 320×240, and the thin-structure opening (docs/method.md D6) erased each
/// frame's leading strip with its accumulation: F1 0.012, never half found. The advance rule
/// (`OcclusionConfig::thin_structure_advance`) finds it. Measured at 320×240, offline: with
/// the true poses F1 0.991, onset 0; with the closed loop F1 0.781, onset 19, ATE 0.048 m (the
/// block pulls the first pass's DVO before any of it is masked, and on those poses the backward
/// pass marks too little of it to seed the body completion until frame 19); the plain opening
/// (`thin_structure_advance` false) F1 0.012. Bounds: the plain opening below 0.1; the true
/// poses the class targets; the closed loop F1 ≥ 0.70 and, while it misses the onset target,
/// an onset above it (when a change meets the targets this fails, so that the limitation in
/// README.md and docs/accuracy.md is updated and the scenario joins [`held_out_scenarios`]).
#[test]
fn a_slowly_advancing_edge_is_found_by_the_advance_rule() {
    let scenario = Scenario::HeldOutWideOnFloor;
    let name = scenario.name();
    assert_plain_opening_misses(scenario, 0.1);
    let true_pose = run_mode(
        scenario,
        EvalMode::TruePoseOffline,
        &ProcessorConfig::default(),
        " with the true poses",
    );
    assert_class(&true_pose, name, CLASS_F1_TARGET, ONSET_TARGET_FRAMES);
    let closed_loop = default_mode(scenario);
    assert!(
        closed_loop.segmentation.mean_f1 >= 0.70,
        "{name}: F1 {:.3}",
        closed_loop.segmentation.mean_f1
    );
    assert!(
        closed_loop.onset_never
            || closed_loop
                .worst_onset_frames
                .is_some_and(|d| d > ONSET_TARGET_FRAMES),
        "{name}: onset {}: meets the target now; update the limitation in README.md and \
         docs/accuracy.md and hold it in held_out_scenarios",
        onset_text(&closed_loop)
    );
}

/// The held-out slow cart (added after the advance rule, run once as defined): a cart 2.2 m away
/// rolls sideways at 0.3 m/s, its leading edge advancing about 1 px a frame at 320×240, against
/// the far wall for a few dozen rows and against the floor just behind it below. Measured at
/// 320×240, offline with DVO: F1 0.807 (P 0.955, R 0.787), onset 0, ATE 0.040 m; with the
/// plain opening (`thin_structure_advance` false) 0.062, never. The recall is 0.96 up to frame
/// 72 and 0.02–0.06 over the last 17 frames (the true poses the same): there the backward
/// pass, which starts at the file's last frame, has marked only a strip of the cart (200–640
/// px), which the body completion does not complete, and the forward pass hardly finds it
/// (causal with the true poses: F1 0.029): a strip of 1 px a frame is thin together with the one
/// erased a frame before too. Bounds: the default F1 ≥ 0.75 and onset ≤ 5; the plain opening
/// below 0.15; while it misses the F1 target, an F1 below it (when a change meets the target
/// this fails, so that docs/accuracy.md is updated and the scenario joins
/// [`held_out_scenarios`]).
#[test]
fn a_slow_cart_is_lost_in_the_last_frames() {
    let scenario = Scenario::HeldOutSlowCart;
    let name = scenario.name();
    assert_plain_opening_misses(scenario, 0.15);
    let score = default_mode(scenario);
    assert_class(&score, name, 0.75, ONSET_TARGET_FRAMES);
    assert!(
        score.segmentation.mean_f1 < CLASS_F1_TARGET,
        "{name}: F1 {:.3}: meets the target now; update docs/accuracy.md and hold it in \
         held_out_scenarios",
        score.segmentation.mean_f1
    );
}
