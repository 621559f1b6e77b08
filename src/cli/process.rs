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
use occmask::mcap_io::AtomicOutput;
use occmask::occlusion::AppearanceGrowthConfig;
use occmask::pipeline::{PoseSource, ProcessingMode, ProcessorConfig};
use occmask::point_cloud::DEFAULT_POINT_STRIDE_PX;
use occmask::process::batch::{available_cores, run_batch, ThreadBudget};
use occmask::process::rectify::GeometryOptions;
use occmask::process::{
    process_file, OdometryAnchor, PipelineOptions, ProcessConfig, ProcessHooks, ProcessReport,
    DEFAULT_MAX_POSE_GAP_NS, DEFAULT_PAIR_TOLERANCE_NS,
};
use occmask::time::{format_ns_as_seconds, parse_seconds_to_ns};
use occmask::trajectory::{tum_line, StampedPose, TUM_HEADER};

use super::options::{
    parse_at_least_one, parse_camera_arg, parse_pair_gap_ms, parse_pose, parse_positive, WriteArgs,
};
use super::{Globals, Outcome};

const AFTER_HELP: &str = "\
Examples:
  occmask process run.mcap -o run.occmask.mcap
  occmask process a.mcap b.mcap c.mcap --out-dir annotated/ --sidecar
  occmask process bag.mcap -o out.mcap --rgb-topic /camera/camera/color/image_raw \\
      --depth-topic /camera/camera/aligned_depth_to_color/image_raw
  occmask process tum.mcap -o ext.mcap --pose-topic /groundtruth/pose --export-masks masks/

Topics are found by schema (foxglove.RawImage/CompressedImage/CameraCalibration in protobuf
or JSON, sensor_msgs/msg/Image/CompressedImage/CameraInfo in CDR) unless given. Depth units:
--depth-units-per-meter, else the channel metadata depth_units_per_meter, else millimetres
(ROS REP 118); 32FC1 depth is metres. Exit code 1 when any file failed.";

/// Pose source choices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PoseArg {
    /// DVO with the mask fed back (the paper's closed loop).
    Dvo,
    /// DVO without the mask feedback (the paper's "Robust DVO" baseline).
    DvoUnmasked,
}

/// Arguments of `occmask process`.
#[derive(Debug, ClapArgs)]
#[command(after_help = AFTER_HELP)]
pub struct ProcessArgs {
    /// Input MCAP files (never modified).
    #[arg(required_unless_present = "print_config")]
    pub inputs: Vec<PathBuf>,

    /// Output file (one input only).
    #[arg(
        short,
        long,
        conflicts_with = "out_dir",
        required_unless_present_any = ["out_dir", "print_config"]
    )]
    pub output: Option<PathBuf>,

    /// Output folder: each input X.mcap becomes DIR/X.occmask.mcap.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,

    /// Pose source when no --pose-topic is given.
    #[arg(long, value_enum, default_value_t = PoseArg::Dvo, conflicts_with = "pose_topic")]
    pub pose: PoseArg,

    /// Use poses from this topic (foxglove PoseInFrame/FrameTransform(s), ROS 2
    /// PoseStamped/TransformStamped/TFMessage) instead of DVO, interpolated to each frame.
    #[arg(long)]
    pub pose_topic: Option<String>,

    /// With a transform --pose-topic: the child frame to follow (default: the first one seen).
    #[arg(long, requires = "pose_topic")]
    pub pose_frame: Option<String>,

    /// Start the estimated trajectory at this pose channel's pose at the first frame, so that
    /// `world` is that channel's frame (default: /groundtruth/pose when the file has it, as
    /// `occmask convert` writes it; then estimated and ground-truth cameras overlap in Foxglove).
    #[arg(long, conflicts_with_all = ["no_anchor", "pose_topic"])]
    pub anchor_topic: Option<String>,

    /// `world` is the first processed camera, even when the file has /groundtruth/pose.
    #[arg(long)]
    pub no_anchor: bool,

    /// Causal processing: one forward pass, each frame's result from it and the frames before
    /// (what an online system gets). The default offline mode adds a backward pass and a
    /// refinement pass over a look-ahead of 90 frames, and finds moving objects earlier and
    /// more completely.
    #[arg(long)]
    pub causal: bool,

    /// DVO, detector and failure-policy parameters from a JSON file: any subset of the fields
    /// `--print-config` prints (the others keep their defaults). Flags such as
    /// --appearance-growth and --causal apply on top. Recorded in the output's occmask.process metadata.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,

    /// Print every DVO, detector and failure-policy parameter with its default value, as the
    /// JSON that --config reads, and exit.
    #[arg(long, exclusive = true)]
    pub print_config: bool,

    /// Appearance-gated object completion: objects also grow into neighbouring pixels of
    /// continuous depth whose intensity changed (completes textured objects that start moving;
    /// on people standing on a floor it leaks onto the floor, so it is off by default).
    #[arg(long)]
    pub appearance_growth: bool,

    /// The default (kept for scripts written when completion was on by default).
    #[arg(long, hide = true, conflicts_with = "appearance_growth")]
    pub no_appearance_growth: bool,

    /// Colour image topic (default: detected by schema).
    #[arg(long)]
    pub rgb_topic: Option<String>,

    /// Depth image topic (default: detected by schema and encoding).
    #[arg(long)]
    pub depth_topic: Option<String>,

    /// Calibration topic (default: the one beside the colour or depth topic).
    #[arg(long)]
    pub camera_info_topic: Option<String>,

    /// Intrinsics instead of a calibration topic: fr1, fr2, fr3, icsl, larr, kinect-default,
    /// bonn, fr1-distorted, fr2-distorted, or FX,FY,CX,CY in pixels, optionally followed by
    /// distortion K1,K2,P1,P2[,K3] (plumb_bob) or K1,K2,P1,P2,K3,K4,K5,K6 (rational_polynomial).
    #[arg(long, value_parser = parse_camera_arg)]
    pub camera: Option<String>,

    /// Calibration topic of the depth camera, for depth from another camera than colour
    /// (default: the one beside the depth topic).
    #[arg(long)]
    pub depth_camera_info_topic: Option<String>,

    /// The depth is registered to colour already (same pixels), whatever its frame_id and
    /// calibration say: no registration.
    #[arg(long, conflicts_with = "depth_to_color")]
    pub depth_aligned: bool,

    /// The depth camera's pose in the colour camera's frame, X,Y,Z,QX,QY,QZ,QW (metres, unit
    /// quaternion), instead of the file's transforms (/tf_static, /tf); registers depth.
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true)]
    pub depth_to_color: Option<nalgebra::Isometry3<f64>>,

    /// Treat the colour camera as a pinhole: lens distortion in the calibration is ignored.
    #[arg(long)]
    pub no_undistort: bool,

    /// With --pose-topic: the marker's pose in the camera frame, X,Y,Z,QX,QY,QZ,QW, or `bonn`
    /// (the topic gives the marker's pose; the camera's is marker · inverse of this).
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true, requires = "pose_topic")]
    pub camera_from_marker: Option<nalgebra::Isometry3<f64>>,

    /// Raw 16-bit depth units per metre (overrides channel metadata; default 1000 = mm).
    #[arg(long, value_parser = parse_positive)]
    pub depth_units_per_meter: Option<f64>,

    /// Skip frames before this many seconds after the first colour image.
    #[arg(long, value_parser = parse_seconds)]
    pub start: Option<u64>,

    /// Stop at this many seconds after the first colour image.
    #[arg(long, value_parser = parse_seconds)]
    pub end: Option<u64>,

    /// Largest colour/depth stamp difference of a pair, milliseconds.
    #[arg(long, value_parser = parse_pair_gap_ms, default_value_t = DEFAULT_PAIR_TOLERANCE_NS as f64 / 1e6)]
    pub max_pair_gap_ms: f64,

    /// Write only the new channels (open it together with the input in Foxglove).
    #[arg(long)]
    pub sidecar: bool,

    /// Also write the accumulation map as /occmask/accumulation (32FC1, for debugging).
    #[arg(long)]
    pub accumulation: bool,

    /// Also write /occmask/points: a foxglove.PointCloud per frame from the depth the detector
    /// used, in the estimated camera's frame, coloured from the colour image, moving points red
    /// (for Foxglove's 3D panel).
    #[arg(long)]
    pub points: bool,

    /// With --points: sample every this many pixels per axis.
    #[arg(long, value_name = "PX", default_value_t = DEFAULT_POINT_STRIDE_PX, requires = "points")]
    pub point_stride: usize,

    /// Measure per-frame decode/processing times into /occmask/stats (output bytes then
    /// differ between runs), and print where each file's frame loop spent its time.
    #[arg(long)]
    pub timings: bool,

    /// Write the estimated trajectory in TUM format (one input only).
    #[arg(long)]
    pub export_trajectory: Option<PathBuf>,

    /// Write one PNG mask per frame, named <timestamp>.png (one input only).
    #[arg(long)]
    pub export_masks: Option<PathBuf>,

    /// Replace existing output files.
    #[arg(short, long)]
    pub force: bool,

    /// Files processed at the same time (default: the number of cores, at most the number of
    /// inputs). More than the cores only time-slices them.
    #[arg(short, long, value_parser = parse_at_least_one)]
    pub jobs: Option<usize>,

    /// Compute threads of each file's pipeline (default: the cores split between the files in
    /// flight, so one file uses every core and, with as many files as cores, each file runs
    /// sequentially on its own core). Reading and writing run on their own threads besides.
    #[arg(long, value_parser = parse_at_least_one)]
    pub threads_per_file: Option<usize>,

    /// Compression and chunking of the output.
    #[command(flatten)]
    pub write: WriteArgs,
}

fn parse_seconds(text: &str) -> Result<u64, String> {
    parse_seconds_to_ns(text).map_err(|e| e.to_string())
}

/// One input's plan.
struct Job {
    input: PathBuf,
    output: PathBuf,
}

/// One input's result.
struct JobResult {
    input: PathBuf,
    outcome: Result<(ProcessReport, f64), String>,
}

fn output_name(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    PathBuf::from(format!("{stem}.occmask.mcap"))
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
            jobs.push(Job {
                input: args.inputs[0].clone(),
                output: out.clone(),
            });
        }
        (None, Some(dir)) => {
            if !dir.is_dir() {
                bail!("--out-dir {}: not an existing folder", dir.display());
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
            serde_json::from_str::<ProcessorConfig>(&text).with_context(|| {
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
    if args.causal {
        processor.mode = ProcessingMode::Causal;
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
    file: BufWriter<std::fs::File>,
}

impl TrajectoryExport {
    fn create(path: &Path, force: bool, inputs: &[&Path]) -> anyhow::Result<Self> {
        let (output, file) = AtomicOutput::create(path, force, inputs)?;
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
    let input = McapInput::open(&job.input).with_context(|| format!("reading {}", job.input.display()))?;
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
        .with_context(|| {
            format!(
                "processing {} into {}",
                job.input.display(),
                output.temp_path().display()
            )
        })?;
    let file = sink
        .into_inner()
        .map_err(|e| anyhow!("cannot write {}: {}", output.temp_path().display(), e.error()))?;
    if report.frames == 0 {
        bail!(
            "{}: no colour/depth pair was processed ({} colour, {} depth messages, {} unpaired colour, \
             {} outside --start/--end, {} outside the pose stream); check the topics, --max-pair-gap-ms \
             and the time range",
            job.input.display(),
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
    for job in &jobs {
        if let Ok(input) = McapInput::open(&job.input) {
            total.inc_length(input.message_count().unwrap_or(0));
        }
    }

    // Each file in flight runs its pipeline on a rayon pool of its own share of the cores (so
    // with as many files as cores each file runs sequentially inside); the output bytes do not
    // depend on the split.
    let budget = ThreadBudget::new(available_cores(), jobs.len(), args.jobs, args.threads_per_file)
        .context("--jobs/--threads-per-file")?;
    let results = run_batch(jobs.len(), &budget, |i| {
        let (job, bar) = (&jobs[i], &bars[i]);
        let start = Instant::now();
        let outcome = run_one(job, &args, &config, &all_inputs, bar, &total)
            .map(|r| (r, start.elapsed().as_secs_f64()))
            .map_err(|e| format!("{:#}", super::hints::with_hint(e)));
        match &outcome {
            Ok(_) => bar.finish_with_message("done"),
            Err(_) => bar.abandon_with_message("FAILED"),
        }
        JobResult {
            input: job.input.clone(),
            outcome,
        }
    })?;
    total.finish();

    let failed = results.iter().filter(|r| r.outcome.is_err()).count();
    if !globals.quiet {
        print_summary(&results, &jobs, &budget);
        if args.timings {
            print_timings(&results);
        }
    }
    for r in &results {
        match &r.outcome {
            Err(e) => eprintln!("error: {}: {e}", r.input.display()),
            Ok((rep, _)) if !globals.quiet => {
                for w in report_warnings(&r.input, rep) {
                    eprintln!("warning: {w}");
                }
            }
            Ok(_) => {}
        }
    }
    if super::signals::interrupted() {
        // Exit code 130 (main looks for Error::Interrupted): files finished before the signal
        // are complete; the unfinished ones removed their temporary output.
        let done = results.len() - failed;
        return Err(anyhow::Error::new(occmask::Error::Interrupted {
            done,
            total: results.len(),
        }))
        .context(format!(
            "stopped by a signal: {done} of {} files were finished and kept",
            results.len()
        ));
    }
    if failed > 0 {
        bail!("{failed} of {} files failed", results.len());
    }
    // A truncated input whose messages (not only its index) were cut off: every file was
    // written from what could be read, and exit code 3 says that input was lost.
    if results
        .iter()
        .any(|r| matches!(&r.outcome, Ok((rep, _)) if lost_input(rep)))
    {
        return Ok(Outcome::DataLoss);
    }
    // Unpaired frames and frames outside the pose stream are reported in the summary, not an
    // error: colour and depth often run at different rates, and every input message is copied.
    Ok(Outcome::Success)
}

/// True when the input was truncated inside its messages (a cut after the data section loses
/// only the index, which the reader rebuilds).
fn lost_input(rep: &ProcessReport) -> bool {
    rep.input_truncated && !rep.input_truncation.is_some_and(|t| t.messages_intact)
}

/// One line per problem of a file that was still processed: a truncated input (what was
/// lost) and frames skipped for their timestamps.
fn report_warnings(input: &Path, rep: &ProcessReport) -> Vec<String> {
    let mut out = Vec::new();
    if rep.input_truncated {
        let lost = match &rep.input_truncation {
            Some(t) if t.messages_intact => {
                "no message lost (only the summary/index after the data is missing)".to_owned()
            }
            Some(t) => format!(
                "the last {} bytes (an incomplete record at byte {}{}) are lost{}",
                t.lost_bytes,
                t.intact_bytes,
                if t.salvaged_messages > 0 {
                    format!(
                        ", whose first {} complete messages were read",
                        t.salvaged_messages
                    )
                } else {
                    String::new()
                },
                t.lost_log_time_range
                    .map(|(a, b)| format!(
                        ", with the messages logged from {} to {} s",
                        format_ns_as_seconds(a, 6),
                        format_ns_as_seconds(b, 6)
                    ))
                    .unwrap_or_default()
            ),
            None => "its last record is incomplete".to_owned(),
        };
        out.push(format!(
            "{} ends early (unfinished recording): {lost}; processed and copied every complete \
             message ({} frames); the output's occmask.process metadata records the loss; \
             `mcap recover` can rebuild the input's index",
            input.display(),
            rep.frames
        ));
    }
    if let Some(anchor) = rep.anchor_frame.filter(|a| a.index > 0) {
        out.push(format!(
            "{}: the odometry is anchored at frame {} (t = {} s), the first the ground truth \
             covers; the {} frames before it are in the same frame",
            input.display(),
            anchor.index,
            format_ns_as_seconds(anchor.timestamp_ns, 6),
            anchor.index
        ));
    }
    if let Some(why) = &rep.anchor_skipped {
        out.push(format!(
            "{}: the odometry starts at the first camera, not at the ground truth: {why}",
            input.display()
        ));
    }
    if rep.out_of_order_frames > 0 {
        out.push(format!(
            "{}: skipped {} frame(s) whose colour stamp is not after the previous frame's \
             (timestamps going backwards or duplicated on {})",
            input.display(),
            rep.out_of_order_frames,
            rep.topics.color.topic
        ));
    }
    out
}

/// `--timings`: where each file's frame loop spent its time (the pipeline should dominate).
fn print_timings(results: &[JobResult]) {
    let mut out = std::io::stderr().lock();
    let _ = writeln!(
        out,
        "{:<32} {:>7} {:>9} {:>8} {:>11} {:>12} {:>12}",
        "frame loop (s)", "loop", "pipeline", "rectify", "input wait", "output wait", "writer tail"
    );
    for r in results {
        if let Ok((rep, _)) = &r.outcome {
            let t = &rep.timings;
            let name = r
                .input
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let _ = writeln!(
                out,
                "{name:<32} {:>7.3} {:>9.3} {:>8.3} {:>11.3} {:>12.3} {:>12.3}",
                t.loop_s, t.pipeline_s, t.rectify_s, t.input_wait_s, t.output_wait_s, t.writer_tail_s
            );
        }
    }
}

fn print_summary(results: &[JobResult], jobs: &[Job], budget: &ThreadBudget) {
    let mut out = std::io::stderr().lock();
    let _ = writeln!(
        out,
        "{} file(s), {} at a time, {} compute thread(s) each ({} cores)",
        results.len(),
        budget.files_in_flight(),
        budget.threads_per_file_text(),
        available_cores()
    );
    let _ = writeln!(
        out,
        "{:<32} {:>7} {:>9} {:>9} {:>8} {:>7} {:>7}  output",
        "input", "frames", "unp.col", "unp.dep", "no pose", "s", "fps"
    );
    for r in results {
        let name = r
            .input
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let output = jobs
            .iter()
            .find(|j| j.input == r.input)
            .map(|j| j.output.display().to_string())
            .unwrap_or_default();
        match &r.outcome {
            Ok((rep, secs)) => {
                let _ = writeln!(
                    out,
                    "{:<32} {:>7} {:>9} {:>9} {:>8} {:>7.1} {:>7.1}  {output}{}",
                    name,
                    rep.frames,
                    rep.unpaired_color,
                    rep.unpaired_depth,
                    rep.outside_pose_stream,
                    secs,
                    rep.frames as f64 / secs.max(1e-9),
                    match &rep.input_truncation {
                        Some(t) if t.messages_intact => "  (input truncated, no message lost)".to_owned(),
                        Some(t) => format!("  (input truncated: last {} bytes lost)", t.lost_bytes),
                        None => String::new(),
                    }
                );
            }
            Err(_) => {
                let _ = writeln!(out, "{name:<32} FAILED (see below)");
            }
        }
    }
    // What was done to the images: registration and undistortion change what the pipeline
    // saw, so they are never silent.
    for r in results {
        if let Ok((rep, _)) = &r.outcome {
            if !rep.geometry.is_identity() {
                let name = r
                    .input
                    .file_name()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let _ = writeln!(out, "{name}: {}", rep.geometry.describe());
            }
        }
    }
}
