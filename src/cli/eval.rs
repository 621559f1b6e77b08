//! `occmask eval`: F1 against `/groundtruth/mask`, RPE and ATE against `/groundtruth/pose`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;

use occmask::evaluate::{evaluate, format_report};

use super::{Globals, Outcome};

const AFTER_HELP: &str = "\
Examples:
  occmask eval run.occmask.mcap
  occmask eval a.occmask.mcap b.occmask.mcap --json > scores.jsonl

F1 is computed per frame against /groundtruth/mask of the same stamp and averaged over frames
with moving objects; RPE uses delta = 1 frame and 150 frames (or the longest the sequence
allows), as TUM's evaluate_rpe.py; ATE after a rigid alignment.";

/// Arguments of `occmask eval`.
#[derive(Debug, ClapArgs)]
#[command(after_help = AFTER_HELP)]
pub struct EvalArgs {
    /// Outputs of `occmask process` (annotated copies that still hold the ground truth).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,

    /// Print one JSON object per file instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs `occmask eval`.
///
/// # Errors
/// The first file that cannot be read or has no occmask channels.
pub fn run(args: EvalArgs, globals: &Globals) -> anyhow::Result<Outcome> {
    let mut outcome = Outcome::Success;
    for path in &args.inputs {
        let report = evaluate(path).with_context(|| format!("evaluating {}", path.display()))?;
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
