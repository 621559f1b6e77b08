//! Masks and odometry of the pipeline on the synthetic scenarios, per scenario × mode × config.
//!
//! ```text
//! cargo run --release --example scenario_accuracy -- [--size WxH] [--seed N]
//!     [--scenarios SET|NAME[,SET|NAME…]]   (SET: original, failure, held_out, every)
//!     [--modes true_pose_causal,true_pose_offline,dvo_causal,dvo_offline]
//!     [--config LABEL=FILE]… [--no-default] [--json FILE] [--colour-shift PX] [--dump DIR]
//! ```
//!
//! Each scenario is rendered once (at 640×480 about a second per frame) and kept in memory;
//! every mode then runs with the default `ProcessorConfig` (label `default`, unless
//! `--no-default`) and with every `--config`: a JSON object merged field by field into the
//! default configuration as `occmask process --print-config` prints it (a partial nested
//! object keeps the other fields of that default). Defaults: 640×480, seed 1, every scenario,
//! every mode. `tools/detector_configs/` holds the overrides the scenario tables were measured
//! with (appearance-gated completion on; sub-threshold retention 0.9; both; without the
//! slow-change evidence of docs/method.md D16, the paper's accumulation alone).
//! `--colour-shift PX` moves every gray image PX pixels to the right (the left columns repeat
//! the first one): colour that is not registered to its depth (docs/method.md D18).
//! `--dump DIR` writes every frame of every run as `DIR/<scenario>_<mode>_<config>_<frame>.png`:
//! gray, true positives green, false positives red, misses blue.
//!
//! Per run it prints (and with `--json` writes, with every frame's scores and every onset run,
//! as `occmask::scenario_eval::ScenarioScore`):
//! - **F1 / P / R**: means of the per-frame F1, precision and recall over the frames with a
//!   moving object;
//! - **onset**: per object and run of frames in which the object is seen and moving (it starts
//!   to move, or enters the view), the frames from the run's first frame until the object's
//!   own recall first reaches 0.5; the worst run is printed (`never` when a run never reaches
//!   it), with every run's onset in brackets (`first_frame:onset`);
//! - **FP∅**: the largest false-positive fraction of the image on a frame without moving
//!   objects from frame 5 on (the static controls' figure; elsewhere the frames where every
//!   object rests; `–` when there is none);
//! - RPE over 1 frame (mm) and 30 frames (cm), ATE (cm), DVO frames not converged, detector
//!   resets, processing ms per frame.

// A measurement tool: a failing setup is a bug worth a panic.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "shared/overlay.rs"]
mod overlay;

use std::path::PathBuf;

use occmask::image_buf::{GrayF32, ImageSize, Mask};
use occmask::pipeline::ProcessorConfig;
use occmask::scenario_eval::{evaluate_observed, EvalMode, RenderedFrame, RenderedSequence, ScenarioScore};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};
use serde::Serialize;

/// The default config with the JSON file's fields merged in.
fn load_config(path: &PathBuf) -> ProcessorConfig {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let config = ProcessorConfig::from_json(&text)
        .unwrap_or_else(|e| panic!("{}: not a configuration: {e}", path.display()));
    config.validate().unwrap();
    config
}

/// The scenarios of a comma-separated list of set names and scenario names, in order.
fn scenarios(which: &str) -> Vec<Scenario> {
    which
        .split(',')
        .flat_map(|n| match n {
            "original" => Scenario::ALL.to_vec(),
            "failure" => Scenario::FAILURE_CLASSES.to_vec(),
            "held_out" => Scenario::HELD_OUT.to_vec(),
            "every" => Scenario::EVERY.to_vec(),
            name => vec![Scenario::from_name(name).unwrap_or_else(|| panic!("unknown scenario {name}"))],
        })
        .collect()
}

/// Moves `gray` `shift_px` pixels to the right, repeating its first column on the left.
fn shift_right(gray: &mut GrayF32, shift_px: usize) {
    let width = gray.width();
    for y in 0..gray.height() {
        for x in (0..width).rev() {
            let from = x.saturating_sub(shift_px);
            gray.set(x, y, gray.get(from, y));
        }
    }
}

/// The frame's gray with the mask's true positives green, false positives red and misses blue.
fn write_overlay(path: &std::path::Path, frame: &RenderedFrame, mask: &Mask) {
    let (width, height) = (frame.gray.width(), frame.gray.height());
    let mut out = image::RgbImage::new(width as u32, height as u32);
    for y in 0..height {
        for x in 0..width {
            let g = (255.0 * frame.gray.get(x, y).clamp(0.0, 1.0)) as u8;
            let p = overlay::error_colour(g, mask.get(x, y) != 0, frame.gt_mask.get(x, y) != 0);
            out.put_pixel(x as u32, y as u32, image::Rgb(p));
        }
    }
    out.save(path).unwrap();
}

fn set_name(scenario: Scenario) -> &'static str {
    if scenario.is_held_out() {
        "held_out"
    } else if scenario.failure_class().is_some() {
        "failure"
    } else {
        "original"
    }
}

#[derive(Serialize)]
struct Run<'a> {
    scenario: &'static str,
    set: &'static str,
    failure_class: Option<&'static str>,
    config: &'a str,
    #[serde(flatten)]
    score: &'a ScenarioScore,
}

#[derive(Serialize)]
struct Report<'a> {
    width: usize,
    height: usize,
    seed: u64,
    onset_definition: &'static str,
    fp_definition: &'static str,
    configs: Vec<(&'a str, &'a ProcessorConfig)>,
    runs: Vec<Run<'a>>,
}

const ONSET_DEFINITION: &str = "per object and run of frames in which it is seen and moving: frames from the run's first frame until the object's recall first reaches 0.5; worst run; null with onset_never = true when a run never reaches it";
const FP_DEFINITION: &str =
    "largest false-positive fraction of the image on a frame with an empty ground truth, from frame 5 on";

fn print_run(scenario: Scenario, label: &str, s: &ScenarioScore) {
    let onset = match (s.worst_onset_frames, s.onset_never) {
        (_, true) => "never".to_string(),
        (Some(d), false) => d.to_string(),
        (None, false) => "–".to_string(),
    };
    let runs: Vec<String> = s
        .onset_runs
        .iter()
        .map(|r| {
            format!(
                "{}:{}",
                r.first_frame,
                r.onset_frames.map_or("never".to_string(), |d| d.to_string())
            )
        })
        .collect();
    let fp = if s.frames_without_objects > 0 {
        format!("{:.3} %", 100.0 * s.max_fp_fraction_without_objects)
    } else {
        "–".to_string()
    };
    let seg = &s.segmentation;
    println!(
        "{:30} {:8} {:18} {:14} F1 {:.3} P {:.3} R {:.3} ({:3} fr)  onset {:>5} [{}]  FP∅ {:>8}  RPE1 {:5.2} mm RPE30 {:5.2} cm ATE {:5.2} cm  nc {} resets {}  {:.1} ms/fr",
        scenario.name(),
        set_name(scenario),
        s.mode.name(),
        label,
        seg.mean_f1,
        seg.mean_precision,
        seg.mean_recall,
        seg.frames_with_truth,
        onset,
        runs.join(" "),
        fp,
        1e3 * s.rpe_1_m,
        1e2 * s.rpe_30_m,
        1e2 * s.ate_m,
        s.dvo_not_converged,
        s.detector_resets,
        s.ms_per_frame
    );
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| args.iter().position(|a| a == flag).map(|i| args[i + 1].clone());
    let size = value("--size").map_or(ImageSize::new(640, 480), |s| {
        let (w, h) = s.split_once('x').expect("--size WxH");
        ImageSize::new(w.parse().unwrap(), h.parse().unwrap())
    });
    let seed: u64 = value("--seed").map_or(1, |s| s.parse().unwrap());
    let which = scenarios(&value("--scenarios").unwrap_or_else(|| "every".into()));
    let modes: Vec<EvalMode> = value("--modes").map_or(EvalMode::ALL.to_vec(), |m| {
        m.split(',')
            .map(|n| EvalMode::from_name(n).unwrap_or_else(|| panic!("unknown mode {n}")))
            .collect()
    });
    let mut configs: Vec<(String, ProcessorConfig)> = Vec::new();
    if !args.iter().any(|a| a == "--no-default") {
        configs.push(("default".into(), ProcessorConfig::default()));
    }
    for (i, a) in args.iter().enumerate() {
        if a == "--config" {
            let (label, path) = args[i + 1].split_once('=').expect("--config LABEL=FILE");
            configs.push((label.into(), load_config(&PathBuf::from(path))));
        }
    }
    let json = value("--json").map(PathBuf::from);
    let colour_shift_px: Option<usize> = value("--colour-shift").map(|s| s.parse().unwrap());
    let dump_dir = value("--dump").map(PathBuf::from);
    if let Some(dir) = &dump_dir {
        std::fs::create_dir_all(dir).unwrap();
    }
    println!(
        "# {}×{}, seed {seed}. F1/P/R: means over frames with a moving object. onset: worst over objects and runs (frames from a run's first frame until the object's recall first reaches 0.5) [first_frame:onset per run]. FP∅: largest false-positive fraction on a frame without moving objects from frame 5 on.",
        size.width, size.height
    );
    let mut scores: Vec<(Scenario, usize, ScenarioScore)> = Vec::new();
    for scenario in which {
        let config = SequenceConfig {
            size,
            seed,
            ..SequenceConfig::default()
        };
        let started = std::time::Instant::now();
        let mut rendered = RenderedSequence::render(&SyntheticSequence::new(scenario, config));
        if let Some(shift_px) = colour_shift_px {
            for frame in &mut rendered.frames {
                shift_right(&mut frame.gray, shift_px);
            }
        }
        eprintln!(
            "{}: {} frames rendered in {:.0} s",
            scenario.name(),
            rendered.frames.len(),
            started.elapsed().as_secs_f64()
        );
        for &mode in &modes {
            for (c, (label, processor_config)) in configs.iter().enumerate() {
                let mut observe = |i: usize, mask: &Mask| {
                    if let Some(dir) = &dump_dir {
                        let name = format!("{}_{}_{label}_{i:04}.png", scenario.name(), mode.name());
                        write_overlay(&dir.join(name), &rendered.frames[i], mask);
                    }
                };
                let score = evaluate_observed(&rendered, mode, processor_config, &mut observe).unwrap();
                print_run(scenario, label, &score);
                scores.push((scenario, c, score));
            }
        }
    }
    if let Some(path) = json {
        let report = Report {
            width: size.width,
            height: size.height,
            seed,
            onset_definition: ONSET_DEFINITION,
            fp_definition: FP_DEFINITION,
            configs: configs.iter().map(|(l, c)| (l.as_str(), c)).collect(),
            runs: scores
                .iter()
                .map(|(scenario, c, score)| Run {
                    scenario: scenario.name(),
                    set: set_name(*scenario),
                    failure_class: scenario.failure_class().map(|f| f.name()),
                    config: &configs[*c].0,
                    score,
                })
                .collect(),
        };
        std::fs::write(&path, serde_json::to_string_pretty(&report).unwrap()).unwrap();
        eprintln!("wrote {}", path.display());
    }
}
