//! Free-space reference masks for a TUM-layout recording with motion-capture poses, and the
//! scores of `occmask process --export-masks` masks against them.
//!
//! ```sh
//! occmask convert bonn DATA/bonn_crowd_200 -o crowd.mcap
//! occmask process crowd.mcap -o crowd.occmask.mcap --export-masks /tmp/masks
//! cargo run --release --example reference_masks -- DATA/bonn_crowd_200 --bonn \
//!     --score /tmp/masks [--write /tmp/reference] [--overlay /tmp/overlay]
//! ```
//! `--bonn` converts the Bonn dataset's marker poses to camera poses
//! ([`occmask::dataset::bonn`]) and uses its intrinsics; otherwise the ground truth is taken as
//! the camera's and `--camera FX,FY,CX,CY` (default TUM fr2) gives the intrinsics. `--score`
//! reads `<colour time in seconds, 6 decimals>.png` masks and prints mean F1, precision and
//! recall over frames whose reference is not empty (and the false-positive fraction of the
//! others), then how soon each person is masked (the reference's regions linked from frame to
//! frame, [`occmask::metrics::onset::RegionTracker`]); `--write` writes the reference as
//! `<time>.png`; `--overlay` writes colour images with true positives green, false positives
//! red and misses blue. The overlays and reference images of a dataset carry its licence: keep
//! them out of the repository.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use rayon::prelude::*;

use occmask::dataset::{self, bonn, DatasetKind};
use occmask::geometry::camera::presets;
use occmask::image_buf::Mask;
use occmask::metrics::free_space::{free_space_reference, FreeSpaceConfig, FreeSpaceView};
use occmask::metrics::onset::{
    OnsetSummary, OnsetTracker, RegionTracker, ONSET_TARGET_FRAMES, REFERENCE_REGION_MIN_IMAGE_FRACTION,
};
use occmask::metrics::SegmentationTally;
use occmask::time::format_ns_as_seconds;
use occmask::trajectory::interpolate;

/// Ground-truth samples further apart than this around a frame are not interpolated.
const MAX_POSE_GAP_NS: u64 = 100_000_000;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let (mut dir, mut is_bonn, mut camera) = (None, false, None);
    let (mut score, mut write, mut overlay) = (None::<PathBuf>, None::<PathBuf>, None::<PathBuf>);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--bonn" => is_bonn = true,
            "--camera" => {
                camera = Some(dataset::parse_camera(
                    &args.next().context("--camera FX,FY,CX,CY")?,
                )?)
            }
            "--score" => score = Some(args.next().context("--score DIR")?.into()),
            "--write" => write = Some(args.next().context("--write DIR")?.into()),
            "--overlay" => overlay = Some(args.next().context("--overlay DIR")?.into()),
            _ if dir.is_none() => dir = Some(PathBuf::from(a)),
            other => bail!("unexpected argument {other:?}"),
        }
    }
    let dir = dir.context("usage: reference_masks DIR [--bonn] [--camera FX,FY,CX,CY] [--score DIR] [--write DIR] [--overlay DIR]")?;
    // A Bonn sequence's ground truth is converted from its marker's poses to the camera's.
    let sequence = if is_bonn {
        bonn::load(&dir)?
    } else {
        dataset::tum::load(&dir, DatasetKind::Tum)?
    };
    let intrinsics = camera.map(|c| c.intrinsics).unwrap_or(if is_bonn {
        bonn::INTRINSICS
    } else {
        presets::TUM_FR2
    });
    let truth = &sequence.groundtruth;
    let pairs = sequence.association(20_000_000).pairs;
    let frames = pairs
        .par_iter()
        .map(|p| dataset::decode_pair(&sequence, p, sequence.kind.default_depth_units_per_meter()))
        .collect::<occmask::Result<Vec<_>>>()?;
    // Frames the ground truth covers, with the camera pose when the depth was taken.
    let covered: Vec<usize> = (0..frames.len())
        .filter(|&i| interpolate(truth, frames[i].depth_timestamp_ns, MAX_POSE_GAP_NS).is_some())
        .collect();
    let views: Vec<FreeSpaceView> = covered
        .iter()
        .filter_map(|&i| {
            let f = &frames[i];
            interpolate(truth, f.depth_timestamp_ns, MAX_POSE_GAP_NS).map(|world_from_camera| FreeSpaceView {
                depth_m: &f.depth_m,
                world_from_camera,
            })
        })
        .collect();
    let started = std::time::Instant::now();
    let reference = free_space_reference(&views, &intrinsics, &FreeSpaceConfig::default())?;
    eprintln!(
        "reference for {} of {} frames in {:.1} s",
        reference.len(),
        frames.len(),
        started.elapsed().as_secs_f64()
    );
    let name = |i: usize| format!("{}.png", format_ns_as_seconds(frames[i].timestamp_ns, 6));
    if let Some(out) = &write {
        std::fs::create_dir_all(out)?;
        for (&i, mask) in covered.iter().zip(&reference) {
            save_gray(mask, &out.join(name(i)))?;
        }
    }
    if let Some(predicted) = &score {
        let mut tally = SegmentationTally::default();
        let mut regions = None;
        let mut onsets = OnsetTracker::new();
        if let Some(out) = &overlay {
            std::fs::create_dir_all(out)?;
        }
        for (&i, truth_mask) in covered.iter().zip(&reference) {
            let path = predicted.join(name(i));
            let mask =
                dataset::read_mask(&path).with_context(|| format!("predicted mask {}", path.display()))?;
            // The reference says nothing where the sensor saw no depth.
            tally.add_masks_where_depth_valid(&mask, truth_mask, &frames[i].depth_m)?;
            let regions = regions.get_or_insert_with(|| RegionTracker::for_reference(truth_mask.size()));
            onsets.add_frame(&regions.add_frame(truth_mask, &mask)?);
            if let Some(out) = &overlay {
                let color = &sequence.color[pairs[i].color];
                write_overlay(&color.path, &mask, truth_mask, &out.join(name(i)))?;
            }
        }
        let s = tally.summary();
        println!(
            "F1 {:.3}  precision {:.3}  recall {:.3}  ({} frames with moving objects; {} without, mean false-positive fraction {:.4})",
            s.mean_f1, s.mean_precision, s.mean_recall, s.frames_with_truth, s.empty_truth_frames, s.empty_truth_mean_fp_fraction
        );
        println!(
            "people (reference regions of at least {} % of the image, linked frame to frame): {}",
            100.0 * REFERENCE_REGION_MIN_IMAGE_FRACTION,
            OnsetSummary::new(&onsets.runs(), ONSET_TARGET_FRAMES)
        );
    }
    Ok(())
}

fn save_gray(mask: &Mask, path: &std::path::Path) -> Result<()> {
    let image = image::GrayImage::from_raw(
        mask.width() as u32,
        mask.height() as u32,
        mask.as_slice().to_vec(),
    )
    .context("mask buffer")?;
    image
        .save(path)
        .with_context(|| format!("writing {}", path.display()))
}

/// The colour image with true positives tinted green, false positives red, misses blue.
fn write_overlay(
    color: &std::path::Path,
    predicted: &Mask,
    truth: &Mask,
    out: &std::path::Path,
) -> Result<()> {
    let mut rgb = image::open(color)?.to_rgb8();
    for (i, pixel) in rgb.pixels_mut().enumerate() {
        let (p, t) = (predicted.as_slice()[i] != 0, truth.as_slice()[i] != 0);
        let tint = match (p, t) {
            (true, true) => [0u8, 255, 0],
            (true, false) => [255, 0, 0],
            (false, true) => [0, 0, 255],
            (false, false) => continue,
        };
        for (c, t) in pixel.0.iter_mut().zip(tint) {
            *c = ((f32::from(*c) * 0.4) + f32::from(t) * 0.6) as u8;
        }
    }
    rgb.save(out)
        .with_context(|| format!("writing {}", out.display()))
}
