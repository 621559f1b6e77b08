//! The arguments of `occmask process` (clap definitions and their value parsers).

use super::*;

pub(super) const AFTER_HELP: &str = "\
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
// One destination (or --print-config) is required: a missing one is reported with both flags.
#[command(group = clap::ArgGroup::new("destination")
    .args(["output", "out_dir", "print_config"])
    .required(true))]
pub struct ProcessArgs {
    /// Input MCAP files (never modified).
    #[arg(required_unless_present = "print_config")]
    pub inputs: Vec<PathBuf>,

    /// Output file (one input only).
    #[arg(short, long)]
    pub output: Option<PathBuf>,

    /// Output folder: each input X.mcap becomes DIR/X.occmask.mcap.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,

    /// Pose source when no --pose-topic is given.
    #[arg(long, value_enum, default_value_t = PoseArg::Dvo, conflicts_with = "pose_topic")]
    pub pose: PoseArg,

    /// Use poses from this topic (Foxglove PoseInFrame/FrameTransform(s); ROS 1 or ROS 2
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

    /// Offline processing at the input's own resolution. By default the offline mode halves
    /// frames while their short side stays at least 240 px (VGA runs at 320×240, masks enlarged
    /// back): on VGA 1.7× the frames/s, the closed loop as accurate, the masks a little less
    /// complete (docs/accuracy.md, docs/method.md D24). The causal mode always runs at full
    /// resolution.
    #[arg(long, conflicts_with = "causal")]
    pub full_resolution: bool,

    /// DVO, detector and failure-policy parameters from a JSON file: any subset of the fields
    /// `--print-config` prints (the others keep their defaults). Flags such as
    /// --appearance-growth, --no-slow-evidence, --causal and --full-resolution apply on top. Recorded in the output's occmask.process metadata.
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

    /// The paper's accumulation alone: no slow-change evidence (on by default; it finds objects
    /// approaching head-on or moving just in front of the surface behind them).
    #[arg(long)]
    pub no_slow_evidence: bool,

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

    /// Stop at this many seconds after the first colour image (an annotated copy still copies
    /// the rest of the input; a sidecar stops reading there).
    #[arg(long, value_parser = parse_seconds)]
    pub end: Option<u64>,

    /// Largest colour/depth stamp difference of a pair, milliseconds.
    #[arg(long, value_parser = parse_pair_gap_ms, default_value_t = DEFAULT_PAIR_TOLERANCE_NS as f64 / 1e6)]
    pub max_pair_gap_ms: f64,

    /// Write only the new channels (open it together with the input in Foxglove).
    #[arg(long)]
    pub sidecar: bool,

    /// Process an input that an earlier run annotated (it has /occmask/ channels): leave out
    /// that run's channels, its world -> camera_estimated transforms on /tf and its
    /// occmask.process metadata, so this run's take their place (without it, such an input
    /// fails: the two runs would mix on the same channels).
    #[arg(long)]
    pub replace_annotations: bool,

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

    /// Keep an existing output and leave its input out, when it is a finished run of the same
    /// input (message count and time span) with the same topics, pose source, --start/--end
    /// and detector/DVO parameters (outputs get their final name only when complete): resumes
    /// an interrupted or partly failed batch. An existing output that is not one (incomplete,
    /// not written by process, another input, other choices) fails that input. Calibration and
    /// registration flags and the output format are not compared: after changing them, use
    /// --force.
    #[arg(long, conflicts_with_all = ["force", "export_trajectory", "export_masks"])]
    pub skip_existing: bool,

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

pub(super) fn parse_seconds(text: &str) -> Result<u64, String> {
    parse_seconds_to_ns(text).map_err(|e| e.to_string())
}
