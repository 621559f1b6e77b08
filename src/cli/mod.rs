//! Command-line interface: clap definitions and dispatch. The only code that prints.
//!
//! To add a subcommand: add a variant to [`Command`] holding its clap `Args` struct, a
//! module `cli/<name>.rs` with `pub fn run(args, &Globals) -> anyhow::Result<Outcome>`, and
//! one match arm in [`run`].

pub mod convert;
pub mod demo;
pub mod eval;
pub mod hints;
pub mod options;
pub mod process;
pub mod signals;

use clap::{Parser, Subcommand};

/// occmask: RGB-D datasets to MCAP, dense visual odometry and moving-object masks.
#[derive(Debug, Parser)]
#[command(name = "occmask", version, about, propagate_version = true)]
pub struct Args {
    /// Print nothing but errors (no progress bar, no summary, no warnings).
    #[arg(short, long, global = true)]
    pub quiet: bool,

    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Convert an RGB-D dataset folder (TUM, ICSL, Bonn, LARR) into an MCAP file for Foxglove.
    Convert(convert::ConvertArgs),
    /// Annotate RGB-D MCAP files with moving-object masks and odometry (several in parallel).
    Process(Box<process::ProcessArgs>),
    /// Score an annotated file against its ground-truth masks and poses (F1, RPE, ATE).
    Eval(eval::EvalArgs),
    /// Generate a synthetic sequence with a dominant moving object, run the closed loop (DVO +
    /// occlusion accumulation), print mask F1 and RPE against ground truth, and write demo.mcap.
    Demo(demo::DemoArgs),
}

/// Options every subcommand sees.
#[derive(Debug, Clone, Copy)]
pub struct Globals {
    /// `--quiet`.
    pub quiet: bool,
}

/// How a command finished (errors are the `Err` side of [`run`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Everything asked for was done (exit code 0).
    Success,
    /// The output was written, but some input could not be used (exit code 3): `process` or
    /// `eval` read a truncated file whose last messages were lost.
    DataLoss,
}

impl Outcome {
    /// The process exit code.
    pub fn exit_code(self) -> u8 {
        match self {
            Outcome::Success => 0,
            Outcome::DataLoss => 3,
        }
    }
}

/// A batch stopped by SIGINT or SIGTERM, with what it finished: exits with
/// [`EXIT_INTERRUPTED`] like a single file's `occmask::Error::Interrupted`.
#[derive(Debug, thiserror::Error)]
#[error("stopped by a signal: {finished} of {total} files were finished and kept{resume}")]
pub struct StoppedBySignal {
    /// Files written and kept.
    pub finished: usize,
    /// Files in the batch.
    pub total: usize,
    /// How to go on, if some are left ("; run …").
    pub resume: &'static str,
}

/// True when `error` (anywhere in its chain) says the run was stopped by a signal.
pub fn interrupted(error: &anyhow::Error) -> bool {
    error.chain().any(|e| {
        e.is::<StoppedBySignal>() || matches!(e.downcast_ref(), Some(occmask::Error::Interrupted { .. }))
    })
}

/// Exit code for errors.
pub const EXIT_ERROR: u8 = 1;
/// Exit code for command-line usage errors (clap's convention).
pub const EXIT_USAGE: u8 = 2;
/// Exit code after Ctrl-C / SIGTERM (128 + SIGINT, the shell convention).
pub const EXIT_INTERRUPTED: u8 = 130;

/// Runs the parsed command.
///
/// # Errors
/// Any error, with the context needed to fix it.
pub fn run(args: Args) -> anyhow::Result<Outcome> {
    let globals = Globals { quiet: args.quiet };
    // A misspelt cap would otherwise run the widest build without a word.
    occmask::simd::Simd::cap_from_env()?;
    signals::install();
    match args.command {
        Command::Convert(a) => convert::run(a, &globals),
        Command::Process(a) => process::run(*a, &globals),
        Command::Eval(a) => eval::run(a, &globals),
        Command::Demo(a) => demo::run(a, &globals),
    }
    .map_err(hints::with_hint)
}

/// The command line as one string (arguments with spaces or quotes are single-quoted), for
/// the metadata of output files.
pub fn command_line() -> String {
    std::env::args_os()
        .map(|a| {
            let a = a.to_string_lossy().into_owned();
            if a.is_empty() || a.contains([' ', '\'', '"', '\t']) {
                format!("'{}'", a.replace('\'', r"'\''"))
            } else {
                a
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn clap_definition_is_consistent() {
        Args::command().debug_assert();
    }

    #[test]
    fn parses_convert_tum_with_options() {
        let args = Args::try_parse_from([
            "occmask",
            "convert",
            "tum",
            "data/x",
            "-o",
            "out.mcap",
            "--camera",
            "fr2",
            "--depth-units-per-meter",
            "5000",
            "--compression",
            "lz4",
            "-q",
        ])
        .unwrap();
        assert!(args.quiet);
        let Command::Convert(c) = args.command else {
            panic!("expected convert")
        };
        let convert::Dataset::Tum(t) = c.dataset else {
            panic!("expected tum")
        };
        assert_eq!(t.common.output.to_str(), Some("out.mcap"));
        assert_eq!(t.camera.as_deref(), Some("fr2"));
    }

    #[test]
    fn demo_arguments_parse_with_defaults() {
        let args = Args::try_parse_from(["occmask", "demo", "--width", "320"]).unwrap();
        let Command::Demo(d) = args.command else {
            panic!("expected demo")
        };
        assert_eq!((d.width, d.seed, d.force), (320, 1, false));
        assert_eq!(d.output.to_str(), Some("demo.mcap"));
        assert!(Args::try_parse_from(["occmask", "demo", "--width", "100"]).is_err());
    }

    #[test]
    fn usage_errors_are_rejected_by_clap() {
        for argv in [
            vec!["occmask", "convert", "tum", "d"],
            vec!["occmask", "convert", "tum", "d", "-o", "x", "--camera", "fr9"],
            vec![
                "occmask",
                "convert",
                "tum",
                "d",
                "-o",
                "x",
                "--compression",
                "gzip",
            ],
            vec![
                "occmask",
                "convert",
                "tum",
                "d",
                "-o",
                "x",
                "--max-pair-gap-ms",
                "-1",
            ],
            vec![
                "occmask",
                "convert",
                "tum",
                "d",
                "-o",
                "x",
                "--depth-units-per-meter",
                "0",
            ],
            vec!["occmask", "convert", "nope", "d", "-o", "x"],
        ] {
            assert!(Args::try_parse_from(&argv).is_err(), "{argv:?}");
        }
    }
}
