//! `occmask demo`: the dominant-object synthetic sequence through the closed loop, scored
//! against its exact ground truth and written to an MCAP file for Foxglove.

use std::collections::BTreeMap;
use std::io::{BufWriter, Cursor};
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use occmask::dvo::DvoStatus;
use occmask::image_buf::ImageSize;
use occmask::mcap_io::codec::ColorFormat;
use occmask::mcap_io::writer::MessageKind;
use occmask::mcap_io::{
    AtomicOutput, McapWriteOptions, RgbdMcapWriter, FRAME_CAMERA_GROUNDTRUTH, FRAME_WORLD,
    TOPIC_COLOR_CAMERA_INFO, TOPIC_COLOR_IMAGE, TOPIC_DEPTH_CAMERA_INFO, TOPIC_DEPTH_IMAGE,
    TOPIC_GROUNDTRUTH_MASK, TOPIC_GROUNDTRUTH_POSE, TOPIC_TF,
};
use occmask::metrics::{rpe, SegmentationTally};
use occmask::pipeline::{FrameInput, Processor, ProcessorConfig};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence, DEPTH_UNITS_PER_M};

use super::{Globals, Outcome};

/// Topic of the detector's moving-object mask (`foxglove.RawImage`, mono8, 255 = moving).
pub const TOPIC_MASK: &str = "/occmask/mask";
/// Topic of the estimated camera pose (`foxglove.PoseInFrame`, world_from_camera).
pub const TOPIC_ODOMETRY_POSE: &str = "/occmask/odometry/pose";
/// Frame id of the estimated camera in `/tf`.
pub const FRAME_CAMERA_ODOMETRY: &str = "camera_odometry";
/// RPE window of the second printed figure (1 s at 30 Hz).
const RPE_LONG_DELTA_FRAMES: usize = 30;

/// `occmask demo` options.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Output MCAP file.
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
}

/// Runs the demo.
///
/// # Errors
/// The output cannot be created or written, or a processing error (a bug).
pub fn run(args: DemoArgs, globals: &Globals) -> anyhow::Result<Outcome> {
    let width = args.width as usize;
    let size = ImageSize::new(width, width * 3 / 4);
    let config = SequenceConfig {
        size,
        seed: args.seed,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
    let intrinsics = config.intrinsics();
    let mut processor = Processor::new(size, intrinsics, ProcessorConfig::default())?;

    let (output, file) = AtomicOutput::create(&args.output, args.force, &[])
        .with_context(|| format!("cannot write {}", args.output.display()))?;
    let mut writer = RgbdMcapWriter::new(BufWriter::new(file), &McapWriteOptions::default())?;
    // Same channels and order as `occmask convert`, then the outputs.
    writer.register_channel(TOPIC_COLOR_IMAGE, MessageKind::CompressedImage, BTreeMap::new())?;
    writer.register_channel(
        TOPIC_COLOR_CAMERA_INFO,
        MessageKind::CameraCalibration,
        BTreeMap::new(),
    )?;
    let depth_meta = BTreeMap::from([(
        occmask::mcap_io::DEPTH_UNITS_KEY.to_owned(),
        f64::from(DEPTH_UNITS_PER_M).to_string(),
    )]);
    writer.register_channel(TOPIC_DEPTH_IMAGE, MessageKind::RawImage, depth_meta)?;
    writer.register_channel(
        TOPIC_DEPTH_CAMERA_INFO,
        MessageKind::CameraCalibration,
        BTreeMap::new(),
    )?;
    writer.register_channel(TOPIC_GROUNDTRUTH_POSE, MessageKind::PoseInFrame, BTreeMap::new())?;
    writer.register_channel(TOPIC_TF, MessageKind::FrameTransform, BTreeMap::new())?;
    writer.register_channel(TOPIC_GROUNDTRUTH_MASK, MessageKind::RawImage, BTreeMap::new())?;
    writer.register_channel(TOPIC_MASK, MessageKind::RawImage, BTreeMap::new())?;
    writer.register_channel(TOPIC_ODOMETRY_POSE, MessageKind::PoseInFrame, BTreeMap::new())?;

    let mut tally = SegmentationTally::default();
    let mut estimated = Vec::with_capacity(sequence.len());
    let mut truth = Vec::with_capacity(sequence.len());
    let mut dvo_failures = 0;
    let mut png = Vec::new();
    let mut frame = sequence.frame(0);
    // The ground-truth first pose anchors the estimated trajectory so both overlay in Foxglove.
    let world_from_first = sequence.world_from_camera(0);
    for i in 0..sequence.len() {
        if super::signals::interrupted() {
            // Dropping `output` without commit removes the temporary file.
            anyhow::bail!("interrupted: {} not written", args.output.display());
        }
        sequence.render_into(i, &mut frame);
        let t = frame.timestamp_ns;
        let out = processor.process(&FrameInput {
            timestamp_ns: t,
            gray: &frame.gray,
            depth_m: &frame.depth_m,
            world_from_marker: None,
        })?;
        dvo_failures += usize::from(out.stats.dvo.is_some_and(|d| d.status != DvoStatus::Converged));
        tally.add_masks(out.mask, &frame.gt_mask)?;
        let world_from_camera = world_from_first * out.world_from_camera;
        estimated.push(world_from_camera);
        truth.push(frame.world_from_camera);

        png.clear();
        let rgb_bytes: Vec<u8> = frame.rgb.as_slice().iter().flatten().copied().collect();
        image::write_buffer_with_format(
            &mut Cursor::new(&mut png),
            &rgb_bytes,
            size.width as u32,
            size.height as u32,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .context("cannot encode the colour image as PNG")?;
        writer.write_pose(TOPIC_GROUNDTRUTH_POSE, t, &frame.world_from_camera)?;
        writer.write_tf(t, FRAME_WORLD, FRAME_CAMERA_GROUNDTRUTH, &frame.world_from_camera)?;
        writer.write_tf(t, FRAME_WORLD, FRAME_CAMERA_ODOMETRY, &world_from_camera)?;
        writer.write_color_compressed(TOPIC_COLOR_IMAGE, t, png.clone().into(), ColorFormat::Png)?;
        writer.write_camera_info(TOPIC_COLOR_CAMERA_INFO, t, &intrinsics, size)?;
        writer.write_mask(TOPIC_GROUNDTRUTH_MASK, t, &frame.gt_mask)?;
        writer.write_depth_u16(
            TOPIC_DEPTH_IMAGE,
            t,
            frame.depth_raw.as_slice(),
            size,
            f64::from(DEPTH_UNITS_PER_M),
        )?;
        writer.write_camera_info(TOPIC_DEPTH_CAMERA_INFO, t, &intrinsics, size)?;
        writer.write_mask(TOPIC_MASK, t, out.mask)?;
        writer.write_pose(TOPIC_ODOMETRY_POSE, t, &world_from_camera)?;
    }
    let sink = writer.finish()?;
    let file = sink
        .into_inner()
        .map_err(|e| e.into_error())
        .with_context(|| format!("cannot write {}", output.temp_path().display()))?;
    output.commit(file)?;

    let segmentation = tally.summary();
    let short = rpe(&estimated, &truth, 1)?;
    let long = rpe(&estimated, &truth, RPE_LONG_DELTA_FRAMES)?;
    if !globals.quiet {
        println!(
            "dominant-object scenario, {} frames at {size}, closed loop (DVO + occlusion accumulation)",
            sequence.len()
        );
        println!(
            "mask:     mean F1 {:.3} (precision {:.3}, recall {:.3}) over {} frames with a moving object",
            segmentation.mean_f1,
            segmentation.mean_precision,
            segmentation.mean_recall,
            segmentation.frames_with_truth
        );
        println!(
            "odometry: RPE over 1 frame {:.4} m / {:.3} deg, over {RPE_LONG_DELTA_FRAMES} frames {:.4} m / {:.3} deg (RMSE); DVO failures {dvo_failures}",
            short.translation_rmse_m, short.rotation_rmse_deg, long.translation_rmse_m, long.rotation_rmse_deg
        );
        println!("wrote {}", args.output.display());
    }
    Ok(Outcome::Success)
}
