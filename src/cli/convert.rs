//! `occmask convert`: dataset folder → MCAP.

use std::io::{BufWriter, IsTerminal};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::{Args as ClapArgs, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use occmask::convert::{
    convert_sequence, resolve_intrinsics, ConvertConfig, ConvertReport, DEFAULT_BATCH_EVENTS,
};
use occmask::dataset::{self, DatasetKind, DEFAULT_MAX_PAIR_GAP_NS};
use occmask::mcap_io::AtomicOutput;
use occmask::time::format_ns_as_seconds;

use super::options::{parse_camera_arg, parse_pair_gap_ms, parse_positive, WriteArgs};
use super::{command_line, Globals, Outcome};

const CONVERT_EXAMPLES: &str = "\
Examples:
  occmask convert tum fixtures/tum_fr2_desk_10 -o desk.mcap
  occmask convert tum rgbd_dataset_freiburg3_walking_xyz -o walking.mcap --compression lz4
  occmask convert icsl icsl_seq1 -o icsl.mcap
  occmask convert bonn rgbd_bonn_crowd -o crowd.mcap
  occmask convert larr dynamic_board -o board.mcap --force";

const TUM_EXAMPLES: &str = "\
Examples:
  occmask convert tum fixtures/tum_fr2_desk_10 -o desk.mcap
  occmask convert tum my_kinect_seq -o seq.mcap --camera 525,525,319.5,239.5
  occmask convert tum 7scenes_seq -o s.mcap --camera kinect-default --max-pair-gap-ms 5

Intrinsics: --camera, else freiburg1/2/3 (or fr1/fr2/fr3) in the folder name, else the Kinect
default (525, 525, 319.5, 239.5) with a warning.";

const ICSL_EXAMPLES: &str = "\
Examples:
  occmask convert icsl icsl_seq1 -o icsl.mcap

Same layout as TUM (rgb.txt, depth.txt, groundtruth.txt); depth in millimetres (1000 units per
metre) and the ICSL camera (537.6, 539.0, 316.1, 245.5) unless overridden.";

const BONN_EXAMPLES: &str = "\
Examples:
  occmask convert bonn rgbd_bonn_crowd -o crowd.mcap
  occmask convert bonn rgbd_bonn_crowd -o crowd.mcap --camera bonn

Same layout as TUM (rgb.txt, depth.txt, groundtruth.txt; depth 5000 units per metre). The
dataset's camera (542.82, 542.58, 315.59, 237.76) as a pinhole unless overridden (--camera bonn
adds its lens distortion, which process then undistorts). Its groundtruth.txt holds the poses
of a motion-capture marker: /groundtruth/pose gets the camera's, converted as the dataset's own
code does (the marker-to-camera transform, translations divided by 1.0593), so that process
anchors the odometry and eval scores it against the camera.";

const LARR_EXAMPLES: &str = "\
Examples:
  occmask convert larr dynamic_board -o board.mcap
  occmask convert larr fixtures/larr_fr2_desk_mini -o mini.mcap --camera 130.225,130.25,80.9,62.05

Layout: rgb/<time>.png, depth/<time>.png (millimetres), optional 'groundtruth mask/<time>.png'
(white = moving object; also groundtruth_mask/), association.txt (else nearest-time pairing),
groundtruth.txt (VICON, TUM pose format).";

/// `occmask convert <dataset> ...`.
#[derive(Debug, ClapArgs)]
#[command(after_help = CONVERT_EXAMPLES)]
pub struct ConvertArgs {
    /// The dataset family.
    #[command(subcommand)]
    pub dataset: Dataset,
}

/// Dataset families.
#[derive(Debug, Subcommand)]
pub enum Dataset {
    /// TUM RGB-D layout: rgb.txt, depth.txt, optional groundtruth.txt; depth 5000 units/m.
    #[command(after_help = TUM_EXAMPLES)]
    Tum(TumArgs),
    /// ICSL sequences: TUM layout, depth 1000 units/m, ICSL camera.
    #[command(after_help = ICSL_EXAMPLES)]
    Icsl(TumArgs),
    /// Bonn RGB-D Dynamic: TUM layout, Bonn camera, marker ground truth converted to the camera.
    #[command(after_help = BONN_EXAMPLES)]
    Bonn(TumArgs),
    /// LARR RGB-D layout (Kim et al.): rgb/, depth/, groundtruth mask/ named by time.
    #[command(after_help = LARR_EXAMPLES)]
    Larr(LarrArgs),
}

/// Arguments of `convert tum`, `convert icsl` and `convert bonn`.
#[derive(Debug, ClapArgs)]
pub struct TumArgs {
    #[command(flatten)]
    pub common: CommonArgs,

    /// Camera: fr1, fr2, fr3, fr1-distorted, fr2-distorted, icsl, larr, bonn, kinect-default, or
    /// FX,FY,CX,CY in pixels, optionally followed by distortion K1,K2,P1,P2[,K3] (plumb_bob) or
    /// K1,K2,P1,P2,K3,K4,K5,K6 (rational_polynomial), written into the calibration messages.
    #[arg(long, value_parser = parse_camera_arg)]
    pub camera: Option<String>,

    /// Raw depth units per metre [default: 5000 for tum and bonn, 1000 for icsl].
    #[arg(long, value_parser = parse_positive)]
    pub depth_units_per_meter: Option<f64>,
}

/// Arguments of `convert larr`.
#[derive(Debug, ClapArgs)]
pub struct LarrArgs {
    #[command(flatten)]
    pub common: CommonArgs,

    /// Camera intrinsics (default: the LARR calibration): a preset name or FX,FY,CX,CY.
    #[arg(long, value_parser = parse_camera_arg)]
    pub camera: Option<String>,

    /// Raw depth units per metre.
    #[arg(long, value_parser = parse_positive, default_value_t = dataset::MILLIMETER_DEPTH_UNITS_PER_METER)]
    pub depth_units_per_meter: f64,
}

/// Options shared by every dataset family.
#[derive(Debug, ClapArgs)]
pub struct CommonArgs {
    /// The dataset folder (never modified).
    pub dir: PathBuf,

    /// The MCAP file to write (written to a temporary file first, renamed on success).
    #[arg(short, long)]
    pub output: PathBuf,

    /// Replace the output file if it exists.
    #[arg(short, long)]
    pub force: bool,

    /// Largest colour/depth time gap of a pair, milliseconds.
    #[arg(long, value_parser = parse_pair_gap_ms, default_value_t = DEFAULT_MAX_PAIR_GAP_NS as f64 / 1e6)]
    pub max_pair_gap_ms: f64,

    /// Also write colour and depth frames that have no partner (skipped and reported by default).
    #[arg(long)]
    pub keep_unpaired: bool,

    /// Compression and chunking.
    #[command(flatten)]
    pub write: WriteArgs,
}

/// Runs `occmask convert`.
///
/// # Errors
/// Any dataset, image or output error, naming the file.
pub fn run(args: ConvertArgs, globals: &Globals) -> anyhow::Result<Outcome> {
    let (kind, common, camera, depth_units) = match args.dataset {
        Dataset::Tum(a) => (DatasetKind::Tum, a.common, a.camera, a.depth_units_per_meter),
        Dataset::Icsl(a) => (DatasetKind::Icsl, a.common, a.camera, a.depth_units_per_meter),
        Dataset::Bonn(a) => (DatasetKind::Bonn, a.common, a.camera, a.depth_units_per_meter),
        Dataset::Larr(a) => (
            DatasetKind::Larr,
            a.common,
            a.camera,
            Some(a.depth_units_per_meter),
        ),
    };
    let warn = |msg: String| {
        if !globals.quiet {
            eprintln!("warning: {msg}");
        }
    };
    let started = Instant::now();
    let seq = match kind {
        DatasetKind::Tum | DatasetKind::Icsl => dataset::tum::load(&common.dir, kind),
        DatasetKind::Bonn => dataset::bonn::load(&common.dir),
        DatasetKind::Larr => dataset::larr::load(&common.dir),
    }
    .with_context(|| format!("cannot read {kind} dataset {}", common.dir.display()))?;
    if kind == DatasetKind::Tum && dataset::bonn::named_like_bonn(&seq.name) && !seq.groundtruth.is_empty() {
        warn(format!(
            "{:?} looks like a Bonn RGB-D Dynamic sequence, whose groundtruth.txt holds a motion-capture \
             marker's poses, not the camera's: written as they are; `occmask convert bonn` converts them \
             and uses the dataset's camera",
            seq.name
        ));
    }

    let intrinsics = resolve_intrinsics(kind, &seq.name, camera.as_deref())?;
    if intrinsics.is_fallback {
        warn(format!(
            "no camera identified for {:?} (no freiburg1/2/3 or fr1/fr2/fr3 in the folder name); using the \
             Kinect default intrinsics; pass --camera to choose",
            seq.name
        ));
    }
    let config = ConvertConfig {
        intrinsics,
        depth_units_per_meter: depth_units.unwrap_or(kind.default_depth_units_per_meter()),
        max_pair_gap_ns: (common.max_pair_gap_ms * 1e6).round() as u64,
        keep_unpaired: common.keep_unpaired,
        write: common.write.options(),
        batch_events: DEFAULT_BATCH_EVENTS,
        command_line: command_line(),
    };

    let (output, file) = AtomicOutput::create(&common.output, common.force, &[common.dir.as_path()])
        .with_context(|| format!("cannot write {}", common.output.display()))?;
    let bar = progress_bar(globals.quiet);
    let mut progress = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
        if super::signals::interrupted() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    };
    let result = convert_sequence(&seq, &config, BufWriter::new(file), &mut progress);
    bar.finish_and_clear();
    let (sink, report) = result.with_context(|| {
        format!(
            "cannot convert {} into {}",
            common.dir.display(),
            common.output.display()
        )
    })?;
    let file = sink
        .into_inner()
        .map_err(|e| e.into_error())
        .with_context(|| format!("cannot write {}", common.output.display()))?;
    output.commit(file)?;

    if !globals.quiet {
        report_warnings(&report, &config, &warn);
        let out_bytes = std::fs::metadata(&common.output).map_or(0, |m| m.len());
        eprintln!(
            "{}",
            summary_line(
                &report,
                &common.output,
                out_bytes,
                started.elapsed().as_secs_f64()
            )
        );
    }
    Ok(Outcome::Success)
}

fn progress_bar(quiet: bool) -> ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
    if let Ok(style) =
        ProgressStyle::with_template("{spinner} converting [{bar:40}] {pos}/{len} images and poses ({eta})")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

fn first_stamps(stamps: &[u64]) -> String {
    const SHOWN: usize = 3;
    let mut s: Vec<String> = stamps
        .iter()
        .take(SHOWN)
        .map(|&t| format_ns_as_seconds(t, 6))
        .collect();
    if stamps.len() > SHOWN {
        s.push("...".into());
    }
    s.join(", ")
}

fn report_warnings(report: &ConvertReport, config: &ConvertConfig, warn: &dyn Fn(String)) {
    let gap_ms = config.max_pair_gap_ns as f64 / 1e6;
    if !report.unpaired_color_ns.is_empty() {
        warn(format!(
            "skipped {} colour frames with no depth frame within {gap_ms} ms (at {}); pass --keep-unpaired to write them",
            report.unpaired_color_ns.len(),
            first_stamps(&report.unpaired_color_ns)
        ));
    }
    if !report.unpaired_depth_ns.is_empty() {
        warn(format!(
            "skipped {} depth frames with no colour frame within {gap_ms} ms (at {}); pass --keep-unpaired to write them",
            report.unpaired_depth_ns.len(),
            first_stamps(&report.unpaired_depth_ns)
        ));
    }
    if !report.unmatched_masks.is_empty() {
        warn(format!(
            "ignored {} mask files whose time matches no colour frame (first: {})",
            report.unmatched_masks.len(),
            report.unmatched_masks[0].display()
        ));
    }
}

fn summary_line(report: &ConvertReport, output: &Path, out_bytes: u64, seconds: f64) -> String {
    const MB: f64 = 1e6;
    format!(
        "wrote {}: {} colour + {} depth frames ({} pairs), {} ground-truth poses, {} masks, {} messages, \
         {:.1} MB from {:.1} MB of images in {:.2} s ({:.1} frames/s)",
        output.display(),
        report.color_frames,
        report.depth_frames,
        report.pairs,
        report.groundtruth_poses,
        report.masks,
        report.messages,
        out_bytes as f64 / MB,
        report.input_image_bytes as f64 / MB,
        seconds,
        report.pairs as f64 / seconds.max(1e-9),
    )
}
