//! `occmask eval`: F1 against `/groundtruth/mask`, RPE and ATE against `/groundtruth/pose` (or
//! `--groundtruth-topic`, a marker's poses with `--camera-from-marker`), of each file or of
//! `--groundtruth FILE` (an MCAP file or a TUM trajectory; a folder: each output's input).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args as ClapArgs;

use occmask::evaluate::{evaluate_against, format_report, GroundTruthSource};

use super::options::parse_pose;
use super::process::{input_name, OUTPUT_SUFFIX};
use super::{Globals, Outcome};

const AFTER_HELP: &str = "\
Examples:
  occmask eval run.occmask.mcap
  occmask eval a.occmask.mcap b.occmask.mcap --json > scores.jsonl
  occmask eval run.sidecar.mcap --groundtruth run.mcap
  occmask eval out/*.occmask.mcap --groundtruth recordings/   (out/X.occmask.mcap vs recordings/X.mcap)
  occmask eval run.occmask.mcap --groundtruth mocap.txt
  occmask eval run.occmask.mcap --groundtruth-topic /vicon/camera/pose
  occmask eval run.occmask.mcap --groundtruth mocap.txt --camera-from-marker 0.01,0,0.05,0,0,0,1

F1 is computed per frame against /groundtruth/mask of the same stamp and averaged over frames
with moving objects; RPE uses delta = 1 frame and 150 frames (or the longest the sequence
allows), as TUM's evaluate_rpe.py; ATE after a rigid alignment. A `process --sidecar` output holds
no ground truth: pass its input with --groundtruth.";

/// Arguments of `occmask eval`.
#[derive(Debug, ClapArgs)]
#[command(after_help = AFTER_HELP)]
pub struct EvalArgs {
    /// Outputs of `occmask process` (annotated copies that still hold the ground truth, or
    /// sidecars with --groundtruth).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,

    /// Print one JSON object per file instead of a table.
    #[arg(long)]
    pub json: bool,

    /// Read the ground truth from FILE instead of from each input: an MCAP file with
    /// /groundtruth/mask and /groundtruth/pose (the input of a `process --sidecar` run), or a
    /// TUM trajectory of the camera (`timestamp tx ty tz qx qy qz qw` per line, seconds and
    /// metres; poses only). Matched by stamp. A folder: each input X.occmask.mcap (as `process
    /// --out-dir` names its outputs) against the folder's X.mcap.
    #[arg(long, value_name = "FILE")]
    pub groundtruth: Option<PathBuf>,

    /// The ground-truth poses are those of this channel (of each input, or of --groundtruth)
    /// instead of /groundtruth/pose: a pose, pose-in-frame or transform channel, as `process
    /// --pose-topic` reads (of a transform channel, the first child frame other than
    /// camera_estimated). The poses must be the camera's.
    #[arg(long, value_name = "TOPIC")]
    pub groundtruth_topic: Option<String>,

    /// The ground-truth poses are a motion-capture marker's: its pose in the camera frame,
    /// X,Y,Z,QX,QY,QZ,QW, or `bonn` (the camera's pose is the marker's · inverse of this, as
    /// `process --camera-from-marker` reads).
    #[arg(long, value_name = "POSE", value_parser = parse_pose, allow_hyphen_values = true)]
    pub camera_from_marker: Option<nalgebra::Isometry3<f64>>,
}

/// The input in `folder` that `output` was made from, by the name `process --out-dir` gave it.
fn input_in(folder: &Path, output: &Path) -> anyhow::Result<PathBuf> {
    let Some(name) = input_name(output) else {
        bail!(
            "{}: --groundtruth {} is a folder, which pairs each X{OUTPUT_SUFFIX} (the name `process \
             --out-dir` gives) with the folder's X.mcap, and this name does not end in {OUTPUT_SUFFIX}; \
             pass its input with --groundtruth FILE",
            output.display(),
            folder.display()
        );
    };
    let input = folder.join(name);
    if !input.is_file() {
        bail!(
            "{}: its input {} is not there (--groundtruth {} pairs X{OUTPUT_SUFFIX} with the folder's \
             X.mcap); pass its input with --groundtruth FILE",
            output.display(),
            input.display(),
            folder.display()
        );
    }
    Ok(input)
}

/// Runs `occmask eval`.
///
/// # Errors
/// The first file that cannot be read, has no occmask channels, or whose input a
/// `--groundtruth` folder does not hold.
pub fn run(args: EvalArgs, globals: &Globals) -> anyhow::Result<Outcome> {
    let mut outcome = Outcome::Success;
    let folder = args.groundtruth.as_deref().filter(|p| p.is_dir());
    for path in &args.inputs {
        let truth = match folder {
            Some(folder) => Some(input_in(folder, path)?),
            None => args.groundtruth.clone(),
        };
        let source = GroundTruthSource {
            file: truth.as_deref(),
            pose_topic: args.groundtruth_topic.as_deref(),
            camera_from_marker: args.camera_from_marker,
        };
        let report = evaluate_against(path, &source).with_context(|| match &truth {
            None => format!("evaluating {}", path.display()),
            Some(truth) => format!("evaluating {} against {}", path.display(), truth.display()),
        })?;
        if let (Some(d), Some(truth), false) = (&report.groundtruth.other_input, &truth, globals.quiet) {
            eprintln!(
                "warning: {} was not made from {}: the input it records has {} {}, that file {}; \
                 scored against that file's ground truth by stamp anyway",
                path.display(),
                truth.display(),
                d.field,
                d.recorded,
                d.found
            );
        }
        if let Some(t) = &report.truncation {
            if !t.messages_intact {
                // Scored, but on fewer frames than the file was written with: exit code 3.
                outcome = Outcome::DataLoss;
            }
            if !globals.quiet {
                eprintln!(
                    "warning: {} ends early: {}; scored the {} complete frames before the cut",
                    path.display(),
                    if t.messages_intact {
                        "no message lost (only the summary/index is missing)".to_owned()
                    } else {
                        format!("the last {} bytes are lost", t.lost_bytes)
                    },
                    report.estimated_masks
                );
            }
        }
        if args.json {
            println!("{}", serde_json::to_string(&report)?);
        } else {
            print!("{}", format_report(&report));
        }
    }
    Ok(outcome)
}
