//! `occmask demo`: the main job end to end on built-in data. The dominant-object synthetic
//! scenario (exact ground-truth masks and poses) is written in `convert`'s layout to an MCAP
//! recording in memory, annotated by the same code as `occmask process` (DVO closed loop), and
//! scored by the same code as `occmask eval`. The result has exactly the channels `process`
//! writes, so it opens in Foxglove with `foxglove/occmask-layout.json`.

use std::io::{BufWriter, Cursor};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context as _};
use clap::Args;
use occmask::convert::write_synthetic_sequence;
use occmask::evaluate::{evaluate, format_report};
use occmask::image_buf::ImageSize;
use occmask::mcap_io::annotate::AnnotateOptions;
use occmask::mcap_io::input::McapInput;
use occmask::mcap_io::{AtomicOutput, McapWriteOptions};
use occmask::point_cloud::DEFAULT_POINT_STRIDE_PX;
use occmask::process::{pipeline_factory, process_file, PipelineOptions, ProcessConfig, ProcessHooks};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

use super::{Globals, Outcome};

/// The name the in-memory input recording goes by in messages.
const DEMO_INPUT_NAME: &str = "<demo recording>";

/// `occmask demo` options.
#[derive(Debug, Args)]
#[command(after_help = "Examples:\n  occmask demo\n  occmask demo -o /tmp/demo.mcap --force --width 320")]
pub struct DemoArgs {
    /// Output MCAP file (the annotated synthetic recording).
    #[arg(short, long, default_value = "demo.mcap")]
    pub output: PathBuf,
    /// Overwrite the output file if it exists.
    #[arg(long)]
    pub force: bool,
    /// Image width in pixels (height = 3/4 of it); intrinsics scale with it.
    #[arg(long, default_value_t = 640, value_parser = clap::value_parser!(u32).range(160..=1280))]
    pub width: u32,
    /// Random seed of textures and sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write /occmask/points (as `process --points`).
    #[arg(long)]
    pub points: bool,
}

/// Stops processing on Ctrl-C / SIGTERM.
struct StopOnSignal;

impl ProcessHooks for StopOnSignal {
    fn messages_read(&mut self, _count: u64) -> ControlFlow<()> {
        if super::signals::interrupted() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
}

/// Runs the demo.
///
/// # Errors
/// The output cannot be created or written, or the run was interrupted.
pub fn run(args: DemoArgs, globals: &Globals) -> anyhow::Result<Outcome> {
    let width = args.width as usize;
    let size = ImageSize::new(width, width * 3 / 4);
    let sequence = SyntheticSequence::new(
        Scenario::DominantObject,
        SequenceConfig {
            size,
            seed: args.seed,
            ..SequenceConfig::default()
        },
    );
    // Claim the output first, so a refused overwrite costs nothing.
    let (output, file) = AtomicOutput::create(&args.output, args.force, &[])
        .with_context(|| format!("cannot write {}", args.output.display()))?;

    // 1. The synthetic recording, as `occmask convert` would write a dataset, in memory.
    let recording = write_synthetic_sequence(
        &sequence,
        Cursor::new(Vec::new()),
        &McapWriteOptions::default(),
        &mut |_| {
            if super::signals::interrupted() {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )?;

    // 2. `occmask process` on it: DVO closed loop + occlusion accumulation.
    let input = McapInput::from_bytes(recording.into_inner(), Path::new(DEMO_INPUT_NAME))?;
    let mut factory = pipeline_factory(PipelineOptions::default());
    let (sink, report) = process_file(
        &input,
        BufWriter::new(file),
        &ProcessConfig {
            annotate: AnnotateOptions {
                points_stride_px: args.points.then_some(DEFAULT_POINT_STRIDE_PX),
                ..Default::default()
            },
            ..Default::default()
        },
        &mut factory,
        &mut StopOnSignal,
    )?;
    let file = sink
        .into_inner()
        .map_err(|e| anyhow!("cannot write {}: {}", args.output.display(), e.error()))?;
    output.commit(file)?;
    drop(input);

    // 3. `occmask eval` of the result against the exact ground truth.
    let scores = evaluate(&args.output).with_context(|| format!("evaluating {}", args.output.display()))?;
    if !globals.quiet {
        println!(
            "dominant-object scenario: {} frames at {size}, DVO closed loop + occlusion accumulation",
            report.frames
        );
        print!("{}", format_report(&scores));
        println!(
            "wrote {} (open it in Foxglove with foxglove/occmask-layout.json)",
            args.output.display()
        );
    }
    Ok(Outcome::Success)
}
