//! `occmask process`: annotate RGB-D MCAP files with mask and odometry channels, several
//! files in parallel.

use std::io::{BufWriter, Write};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context};
use clap::{Args as ClapArgs, ValueEnum};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

use occmask::dataset;
use occmask::image_buf::Mask;
use occmask::mcap_io::annotate::AnnotateOptions;
use occmask::mcap_io::input::detect::TopicOverrides;
use occmask::mcap_io::input::McapInput;
use occmask::mcap_io::{AtomicOutput, OutputFile};
use occmask::occlusion::AppearanceGrowthConfig;
use occmask::pipeline::{PoseSource, ProcessingMode, ProcessorConfig};
use occmask::point_cloud::DEFAULT_POINT_STRIDE_PX;
use occmask::process::batch::{available_cores, run_batch, ThreadBudget};
use occmask::process::rectify::GeometryOptions;
use occmask::process::{
    check_existing_output, process_file, OdometryAnchor, PipelineOptions, ProcessConfig, ProcessHooks,
    ProcessReport, DEFAULT_MAX_POSE_GAP_NS, DEFAULT_PAIR_TOLERANCE_NS,
};
use occmask::time::{format_ns_as_seconds, parse_seconds_to_ns};
use occmask::trajectory::{tum_line, StampedPose, TUM_HEADER};

use super::options::{
    parse_at_least_one, parse_camera_arg, parse_pair_gap_ms, parse_pose, parse_positive, WriteArgs,
};
use super::{Globals, Outcome};

mod args;
mod report;

pub use args::{PoseArg, ProcessArgs};
use report::{lost_input, print_summary, print_timings, report_warnings};

/// One input's plan.
struct Job {
    input: PathBuf,
    output: PathBuf,
}

/// What became of one input.
enum FileOutcome {
    /// Processed: its report (boxed: the other outcomes are small) and wall time (s).
    Done(Box<ProcessReport>, f64),
    /// Its existing output was kept (`--skip-existing`).
    Kept,
    /// Failed: the message to print.
    Failed(String),
}

/// One input's result.
struct JobResult {
    input: PathBuf,
    outcome: FileOutcome,
}

/// `error` as printed: its chain, and the flag that fixes it.
fn failure_text(error: anyhow::Error) -> String {
    format!("{:#}", super::hints::with_hint(error))
}

/// What `process --out-dir` appends to an input's stem.
pub(super) const OUTPUT_SUFFIX: &str = ".occmask.mcap";

fn output_name(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    PathBuf::from(format!("{stem}{OUTPUT_SUFFIX}"))
}

/// The name of the `.mcap` input that `process --out-dir` named `output` after (`X.occmask.mcap`
/// → `X.mcap`); `None` for another name.
pub(super) fn input_name(output: &Path) -> Option<PathBuf> {
    let name = output.file_name()?.to_str()?;
    let stem = name.strip_suffix(OUTPUT_SUFFIX).filter(|s| !s.is_empty())?;
    Some(PathBuf::from(format!("{stem}.mcap")))
}

fn plan(args: &ProcessArgs) -> anyhow::Result<Vec<Job>> {
    let mut jobs = Vec::new();
    match (&args.output, &args.out_dir) {
        (Some(out), None) => {
            if args.inputs.len() != 1 {
                bail!(
                    "-o/--output takes one input, found {}; use --out-dir DIR for several",
                    args.inputs.len()
                );
            }
            let input = &args.inputs[0];
            if occmask::mcap_io::names_folder(out) {
                bail!(
                    "-o/--output {} is a folder: -o takes the output file's name; pass --out-dir {} \
                     to write {} in it{}",
                    out.display(),
                    out.display(),
                    output_name(input).display(),
                    if out.is_dir() { "" } else { " (create it first)" }
                );
            }
            jobs.push(Job {
                input: input.clone(),
                output: out.clone(),
            });
        }
        (None, Some(dir)) => {
            if !dir.is_dir() {
                let found = if dir.exists() {
                    "is a file, not a folder"
                } else {
                    "does not exist (create it first)"
                };
                bail!("--out-dir {} {found}", dir.display());
            }
            for input in &args.inputs {
                jobs.push(Job {
                    input: input.clone(),
                    output: dir.join(output_name(input)),
                });
            }
        }
        _ => bail!("give either -o/--output or --out-dir"),
    }
    for (i, a) in jobs.iter().enumerate() {
        if jobs[..i].iter().any(|b| b.output == a.output) {
            bail!(
                "two inputs would both write {} (same file name): process them separately",
                a.output.display()
            );
        }
    }
    if args.inputs.len() > 1 && (args.export_trajectory.is_some() || args.export_masks.is_some()) {
        bail!(
            "--export-trajectory and --export-masks take one input, found {}",
            args.inputs.len()
        );
    }
    Ok(jobs)
}

fn config(args: &ProcessArgs) -> anyhow::Result<ProcessConfig> {
    let camera = args
        .camera
        .as_deref()
        .map(dataset::parse_camera)
        .transpose()
        .context("--camera")?;
    let pose_source = match (&args.pose_topic, args.pose) {
        (Some(_), _) => PoseSource::External {
            camera_from_marker: args.camera_from_marker,
        },
        (None, PoseArg::Dvo) => PoseSource::DvoClosedLoop,
        (None, PoseArg::DvoUnmasked) => PoseSource::DvoUnmasked,
    };
    if let (Some(s), Some(e)) = (args.start, args.end) {
        if e <= s {
            bail!("--end must be after --start");
        }
    }
    let mut processor = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read --config {}", path.display()))?;
            ProcessorConfig::from_json(&text).with_context(|| {
                format!(
                    "--config {}: not a valid configuration (`occmask process --print-config` \
                     prints every field with its default)",
                    path.display()
                )
            })?
        }
        None => ProcessorConfig::default(),
    };
    processor.pose_source = pose_source;
    if args.appearance_growth {
        processor
            .occlusion
            .appearance_growth
            .get_or_insert_with(AppearanceGrowthConfig::default);
    } else if args.no_appearance_growth {
        processor.occlusion.appearance_growth = None;
    }
    if args.no_slow_evidence {
        processor.occlusion.slow_evidence = None;
    }
    if args.causal {
        processor.mode = ProcessingMode::Causal;
    }
    if args.full_resolution {
        processor.offline.min_working_side_px = 0;
    }
    processor.validate().with_context(|| match &args.config {
        Some(path) => format!("--config {}", path.display()),
        None => "the detector and DVO parameters".to_owned(),
    })?;
    Ok(ProcessConfig {
        topics: TopicOverrides {
            rgb: args.rgb_topic.clone(),
            depth: args.depth_topic.clone(),
            camera_info: args.camera_info_topic.clone(),
            depth_camera_info: args.depth_camera_info_topic.clone(),
            pose: args.pose_topic.clone(),
        },
        intrinsics: camera.map(|c| c.intrinsics),
        camera_distortion: camera.and_then(|c| c.distortion),
        geometry: GeometryOptions {
            depth_aligned: args.depth_aligned,
            color_from_depth: args.depth_to_color,
            no_undistort: args.no_undistort,
        },
        depth_units_per_meter: args.depth_units_per_meter,
        pose_child_frame: args.pose_frame.clone(),
        pair_tolerance_ns: (args.max_pair_gap_ms * 1e6).round() as u64,
        max_pose_gap_ns: DEFAULT_MAX_POSE_GAP_NS,
        anchor: match (&args.anchor_topic, args.no_anchor) {
            (Some(topic), _) => OdometryAnchor::Required(topic.clone()),
            (None, true) => OdometryAnchor::FirstCamera,
            (None, false) => OdometryAnchor::default(),
        },
        start_offset_ns: args.start,
        end_offset_ns: args.end,
        timings: args.timings,
        annotate: AnnotateOptions {
            copy_input: !args.sidecar,
            accumulation: args.accumulation,
            points_stride_px: args.points.then_some(args.point_stride),
            write: args.write.options(),
            replace_earlier: args.replace_annotations,
            ..Default::default()
        },
        processor,
    })
}

/// Progress, `--export-trajectory` (streamed: the trajectory is never held in memory) and
/// `--export-masks`.
struct Hooks<'a> {
    bar: &'a ProgressBar,
    total: &'a ProgressBar,
    reported: u64,
    masks_dir: Option<&'a Path>,
    trajectory: Option<TrajectoryExport>,
}

/// `--export-trajectory`: TUM lines written as frames finish, to a temporary file that is
/// renamed into place only when the whole input succeeded.
struct TrajectoryExport {
    path: PathBuf,
    output: AtomicOutput,
    file: BufWriter<OutputFile>,
}

impl TrajectoryExport {
    fn create(path: &Path, force: bool, inputs: &[&Path]) -> anyhow::Result<Self> {
        let (output, file) = AtomicOutput::create(path, force, inputs).context("--export-trajectory")?;
        let mut export = Self {
            path: path.to_path_buf(),
            output,
            file: BufWriter::new(file),
        };
        export.write_line(TUM_HEADER)?;
        Ok(export)
    }

    fn write_line(&mut self, line: &str) -> occmask::Result<()> {
        writeln!(self.file, "{line}")
            .map_err(|e| occmask::Error::io("cannot write --export-trajectory", &self.path, e))
    }

    fn commit(self) -> anyhow::Result<()> {
        let file = self
            .file
            .into_inner()
            .map_err(|e| anyhow!("cannot write {}: {}", self.path.display(), e.error()))?;
        self.output.commit(file)?;
        Ok(())
    }
}

/// Progress is drawn every this many messages: cheap, and still smooth at 100 messages/s.
const PROGRESS_STEP_MESSAGES: u64 = 32;

impl ProcessHooks for Hooks<'_> {
    fn messages_read(&mut self, count: u64) -> ControlFlow<()> {
        if count - self.reported >= PROGRESS_STEP_MESSAGES {
            self.bar.inc(count - self.reported);
            self.total.inc(count - self.reported);
            self.reported = count;
        }
        if super::signals::interrupted() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    fn frame_done(&mut self, pose: &StampedPose, mask: &Mask) -> occmask::Result<()> {
        if let Some(export) = &mut self.trajectory {
            export.write_line(&tum_line(pose))?;
        }
        let Some(dir) = self.masks_dir else {
            return Ok(());
        };
        let path = dir.join(format!("{}.png", format_ns_as_seconds(pose.timestamp_ns, 6)));
        let img = image::GrayImage::from_raw(
            mask.width() as u32,
            mask.height() as u32,
            mask.as_slice().to_vec(),
        )
        .ok_or_else(|| occmask::Error::BufferLength {
            expected: mask.size().area(),
            found: mask.as_slice().len(),
            size: mask.size(),
        })?;
        img.save_with_format(&path, image::ImageFormat::Png)
            .map_err(|e| occmask::Error::io("cannot write mask PNG", &path, std::io::Error::other(e)))
    }
}

fn run_one(
    job: &Job,
    args: &ProcessArgs,
    config: &ProcessConfig,
    all_inputs: &[&Path],
    bar: &ProgressBar,
    total: &ProgressBar,
) -> anyhow::Result<ProcessReport> {
    // The failure line starts with the input's path (`error: IN:`), so no context repeats it.
    let input = McapInput::open(&job.input)?;
    if let Some(n) = input.message_count() {
        bar.set_length(n);
    }
    let (output, file) = AtomicOutput::create(&job.output, args.force, all_inputs)?;
    let trajectory = match &args.export_trajectory {
        Some(path) => Some(TrajectoryExport::create(path, args.force, all_inputs)?),
        None => None,
    };
    let mut hooks = Hooks {
        bar,
        total,
        reported: 0,
        masks_dir: args.export_masks.as_deref(),
        trajectory,
    };
    if let Some(dir) = &args.export_masks {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create --export-masks {}", dir.display()))?;
    }
    let mut factory = occmask::process::pipeline_factory(PipelineOptions {
        keep_accumulation: args.accumulation,
    });
    let (sink, report) = process_file(&input, BufWriter::new(file), config, &mut factory, &mut hooks)
        .with_context(|| format!("output {} not written", job.output.display()))?;
    let file = sink
        .into_inner()
        .map_err(|e| anyhow!("output {} not written: {}", job.output.display(), e.error()))?;
    if report.frames == 0 {
        bail!(
            "no colour/depth pair was processed ({} colour, {} depth messages, {} unpaired colour, \
             {} outside --start/--end, {} outside the pose stream); check the topics, --max-pair-gap-ms \
             and the time range",
            report.color_messages,
            report.depth_messages,
            report.unpaired_color,
            report.outside_time_range,
            report.outside_pose_stream
        );
    }
    output.commit(file)?;
    if let Some(export) = hooks.trajectory {
        export.commit()?;
    }
    bar.set_position(bar.length().unwrap_or(0));
    Ok(report)
}

fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar())
}

/// Runs `occmask process`.
///
/// # Errors
/// Usage errors before anything runs; "N of M files failed" after the summary when any
/// file failed (the others are still written).
pub fn run(args: ProcessArgs, globals: &Globals) -> anyhow::Result<Outcome> {
    if args.print_config {
        let text = serde_json::to_string_pretty(&ProcessorConfig::default())?;
        println!("{text}");
        return Ok(Outcome::Success);
    }
    let jobs = plan(&args)?;
    let config = config(&args)?;
    let all_inputs: Vec<&Path> = args.inputs.iter().map(PathBuf::as_path).collect();

    let multi = MultiProgress::with_draw_target(if globals.quiet {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    });
    let total = multi.add(ProgressBar::new(0));
    total.set_style(style("total {bar:30} {pos}/{len} messages {elapsed_precise}"));
    let bars: Vec<ProgressBar> = jobs
        .iter()
        .map(|job| {
            let bar = multi.add(ProgressBar::new(0));
            bar.set_style(style("{prefix:30!} {bar:30} {pos}/{len} msgs {per_sec} {msg}"));
            bar.set_prefix(
                job.input
                    .file_name()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            );
            bar
        })
        .collect();
    // --skip-existing: an input whose output is a finished run of it with these parameters is
    // left out; one whose output exists but is not fails.
    let settled: Vec<Option<FileOutcome>> = jobs
        .iter()
        .zip(&bars)
        .map(|(job, bar)| {
            if !(args.skip_existing && job.output.exists()) {
                return None;
            }
            let checked = McapInput::open(&job.input)
                .and_then(|input| check_existing_output(&job.output, &input, &config));
            Some(match checked {
                Ok(()) => {
                    bar.finish_with_message("kept: its output exists");
                    FileOutcome::Kept
                }
                Err(e) => {
                    bar.abandon_with_message("FAILED");
                    FileOutcome::Failed(failure_text(anyhow::Error::new(e)))
                }
            })
        })
        .collect();
    let pending: Vec<usize> = (0..jobs.len()).filter(|&i| settled[i].is_none()).collect();
    for &i in &pending {
        if let Ok(input) = McapInput::open(&jobs[i].input) {
            total.inc_length(input.message_count().unwrap_or(0));
        }
    }

    // Each file in flight runs its pipeline on a rayon pool of its own share of the cores (so
    // with as many files as cores each file runs sequentially inside); the output bytes do not
    // depend on the split.
    let budget = ThreadBudget::new(available_cores(), pending.len(), args.jobs, args.threads_per_file)
        .context("--jobs/--threads-per-file")?;
    let processed = run_batch(pending.len(), &budget, |k| {
        let i = pending[k];
        let (job, bar) = (&jobs[i], &bars[i]);
        let start = Instant::now();
        match run_one(job, &args, &config, &all_inputs, bar, &total) {
            Ok(report) => {
                bar.finish_with_message("done");
                FileOutcome::Done(Box::new(report), start.elapsed().as_secs_f64())
            }
            Err(e) => {
                bar.abandon_with_message("FAILED");
                FileOutcome::Failed(failure_text(e))
            }
        }
    })?;
    total.finish();
    // `run_batch` returns the pending inputs' outcomes in their order.
    let mut processed = processed.into_iter();
    let results: Vec<JobResult> = jobs
        .iter()
        .zip(settled)
        .map(|(job, settled)| JobResult {
            input: job.input.clone(),
            outcome: settled.or_else(|| processed.next()).unwrap_or_else(|| {
                FileOutcome::Failed("internal error: the batch returned no outcome".to_owned())
            }),
        })
        .collect();

    let failed = results
        .iter()
        .filter(|r| matches!(r.outcome, FileOutcome::Failed(_)))
        .count();
    if !globals.quiet {
        print_summary(&results, &jobs, &budget);
        if args.timings {
            print_timings(&results);
        }
    }
    for r in &results {
        match &r.outcome {
            FileOutcome::Failed(e) => eprintln!("error: {}: {e}", r.input.display()),
            FileOutcome::Done(rep, _) if !globals.quiet => {
                for w in report_warnings(&r.input, rep) {
                    eprintln!("warning: {w}");
                }
            }
            FileOutcome::Done(..) | FileOutcome::Kept => {}
        }
    }
    if super::signals::interrupted() {
        // Exit code 130: files finished before the signal are complete; the unfinished ones
        // removed their temporary output.
        let finished = results.len() - failed;
        let resume = if results.len() > 1 && finished < results.len() {
            "; run the same command with --skip-existing to process the others"
        } else {
            ""
        };
        return Err(super::StoppedBySignal {
            finished,
            total: results.len(),
            resume,
        }
        .into());
    }
    if failed > 0 {
        bail!("{failed} of {} files failed", results.len());
    }
    // A truncated input whose messages (not only its index) were cut off: every file was
    // written from what could be read, and exit code 3 says that input was lost.
    if results
        .iter()
        .any(|r| matches!(&r.outcome, FileOutcome::Done(rep, _) if lost_input(rep)))
    {
        return Ok(Outcome::DataLoss);
    }
    // Unpaired frames and frames outside the pose stream are reported in the summary, not an
    // error: colour and depth often run at different rates, and every input message is copied.
    Ok(Outcome::Success)
}
