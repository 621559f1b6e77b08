//! Checks a motion-capture marker's calibration against the data: the depth of frame i is
//! warped into frame i + k with the camera poses the ground truth gives under each hypothesis,
//! and the fraction of pixels whose predicted depth agrees with the depth measured there is
//! reported. The right calibration makes the static scene agree; moving people disagree
//! under every hypothesis alike.
//!
//! usage: cargo run --release --example marker_check -- TUM_FOLDER
//!
//! Hypotheses (the Bonn RGB-D Dynamic Dataset's published conversion is
//! `T_cam = T_ros · T_gt · T_ros · T_m`, `T_m` a rotation times 1.0593; `occmask::dataset::bonn`):
//! - `raw`: the marker's pose is the camera's;
//! - `rigid`: `world_from_camera = T_gt · marker_from_camera` ([`bonn::marker_from_camera`]):
//!   what `process --camera-from-marker bonn` expresses;
//! - `rigid+scale`: the same with the ground truth's translations divided by
//!   [`bonn::GROUND_TRUTH_SCALE`], the published formula ([`bonn::camera_poses`]; a scale no
//!   rigid transform expresses).
//!
//! Pixels are counted by the depth band they fall in (in both frames): the far band (walls and
//! desks behind the walking people) is the static scene; nearer bands also hold the people.

use std::path::PathBuf;

use anyhow::{bail, Context};
use nalgebra::{Isometry3, Point3};
use occmask::dataset::{self, bonn, DatasetKind};
use occmask::geometry::distortion::CameraModel;
use occmask::image_buf::ImageSize;
use occmask::trajectory::{interpolate, StampedPose};

/// A predicted depth agrees with the measured one within this fraction.
const AGREEMENT_RELATIVE: f32 = 0.03;
/// Frame gaps checked (30 Hz: 0.17 s, 0.5 s, 1 s).
const GAPS: [usize; 3] = [5, 15, 30];
/// Depth bands (m): near (people, desks), middle, far (walls).
const BANDS_M: [(f32, f32); 3] = [(0.3, 2.0), (2.0, 3.5), (3.5, 10.0)];
/// Pairs start every this many frames.
const START_STEP: usize = 10;
/// Ground-truth samples further apart around a frame are not interpolated.
const MAX_POSE_GAP_NS: u64 = 100_000_000;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let folder = PathBuf::from(args.next().context("usage: TUM_FOLDER")?);
    if let Some(other) = args.next() {
        bail!("unknown argument {other}");
    }
    let seq = dataset::tum::load(&folder, DatasetKind::Tum)?;
    let spec = dataset::parse_camera("bonn")?;
    let camera = CameraModel {
        size: ImageSize::new(640, 480),
        intrinsics: spec.intrinsics,
        distortion: spec.distortion,
    };
    let marker_from_camera = bonn::marker_from_camera();
    let preset = dataset::camera_from_marker_preset("bonn").context("bonn preset")?;
    println!(
        "--camera-from-marker bonn = {}",
        preset.map(|v| format!("{v:.9}")).join(",")
    );
    let scaled: Vec<StampedPose> = seq
        .groundtruth
        .iter()
        .map(|p| {
            let mut w = p.world_from_camera;
            w.translation.vector /= bonn::GROUND_TRUTH_SCALE;
            StampedPose {
                timestamp_ns: p.timestamp_ns,
                world_from_camera: w,
            }
        })
        .collect();
    let hypotheses: [(&str, &[StampedPose], Isometry3<f64>); 3] = [
        ("raw", &seq.groundtruth, Isometry3::identity()),
        ("rigid", &seq.groundtruth, marker_from_camera),
        ("rigid+scale", &scaled, marker_from_camera),
    ];
    let depth: Vec<_> = seq
        .depth
        .iter()
        .map(|r| dataset::read_depth(&r.path).map(|d| (r.timestamp_ns, d)))
        .collect::<occmask::Result<_>>()?;
    let rays: Vec<Option<(f64, f64)>> = (0..camera.size.area())
        .map(|i| camera.ray((i % 640) as f64, (i / 640) as f64))
        .collect();
    println!(
        "agreeing pixels per depth band and frame gap k\n{:<12} {}",
        "hypothesis",
        BANDS_M
            .iter()
            .flat_map(|(lo, hi)| GAPS.map(move |k| format!("{lo}-{hi} m k={k}")))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    for (name, poses, marker_from_camera) in hypotheses {
        let mut line = format!("{name:<12}");
        for (lo, hi) in BANDS_M {
            for k in GAPS {
                let (mut agree, mut total) = (0u64, 0u64);
                for i in (0..depth.len().saturating_sub(k)).step_by(START_STEP) {
                    let (ta, a) = &depth[i];
                    let (tb, b) = &depth[i + k];
                    let (Some(wa), Some(wb)) = (
                        interpolate(poses, *ta, MAX_POSE_GAP_NS),
                        interpolate(poses, *tb, MAX_POSE_GAP_NS),
                    ) else {
                        continue;
                    };
                    let b_from_a = (wb * marker_from_camera).inverse() * (wa * marker_from_camera);
                    for (idx, raw) in a.data.iter().enumerate() {
                        let za = f32::from(*raw) / bonn::DEPTH_UNITS_PER_METER as f32;
                        let Some((x, y)) = rays[idx] else { continue };
                        if !(lo..hi).contains(&za) {
                            continue;
                        }
                        let p = b_from_a * Point3::new(x * f64::from(za), y * f64::from(za), f64::from(za));
                        if p.z <= 0.0 {
                            continue;
                        }
                        let (u, v) = camera.pixel(p.x / p.z, p.y / p.z);
                        let (u, v) = (u.round(), v.round());
                        if u < 0.0 || v < 0.0 || u > 639.0 || v > 479.0 {
                            continue;
                        }
                        let zb = f32::from(b.data[v as usize * 640 + u as usize])
                            / bonn::DEPTH_UNITS_PER_METER as f32;
                        if !(lo..hi).contains(&zb) {
                            continue;
                        }
                        total += 1;
                        if (p.z as f32 - zb).abs() <= AGREEMENT_RELATIVE * zb {
                            agree += 1;
                        }
                    }
                }
                line += &format!(
                    " | {:>5.1} % of {:>8}",
                    100.0 * agree as f64 / total.max(1) as f64,
                    total
                );
            }
        }
        println!("{line}");
    }
    Ok(())
}
