//! Minimal TUM RGB-D folder reader for the DVO tests and the `dvo_tum` example (the full
//! dataset adapter lives in the library's I/O layer; this one only needs rgb.txt, depth.txt,
//! groundtruth.txt and PNG decoding).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use occmask::image_buf::{depth_m_from_u16_into, gray_from_rgb8, DepthMeters, GrayF32, ImageSize, Rgb8};
use occmask::time::parse_seconds_to_ns;
use occmask::trajectory::{parse_tum_line, StampedPose};

/// TUM depth PNG units per metre.
pub const TUM_DEPTH_UNITS_PER_M: f32 = 5000.0;

/// One colour frame paired with the depth frame nearest in time.
#[derive(Debug, Clone)]
pub struct FramePaths {
    pub timestamp_ns: u64,
    pub rgb: PathBuf,
    pub depth: PathBuf,
}

fn read_list(dir: &Path, name: &str) -> Result<Vec<(u64, PathBuf)>, String> {
    let path = dir.join(name);
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut f = line.split_whitespace();
        let (Some(t), Some(file)) = (f.next(), f.next()) else {
            return Err(format!("{}:{}: expected 'timestamp file'", path.display(), i + 1));
        };
        let t = parse_seconds_to_ns(t).map_err(|e| format!("{}:{}: {e}", path.display(), i + 1))?;
        out.push((t, dir.join(file)));
    }
    Ok(out)
}

/// Colour frames with their nearest depth frame, and the ground-truth poses.
pub fn load_sequence(dir: &Path) -> Result<(Vec<FramePaths>, Vec<StampedPose>), String> {
    let rgb = read_list(dir, "rgb.txt")?;
    let depth = read_list(dir, "depth.txt")?;
    if depth.is_empty() {
        return Err(format!("{}: no depth frames", dir.display()));
    }
    let frames = rgb
        .into_iter()
        .map(|(t, rgb)| {
            let nearest = depth
                .iter()
                .min_by_key(|(td, _)| td.abs_diff(t))
                .map(|(_, p)| p.clone())
                .unwrap_or_default();
            FramePaths {
                timestamp_ns: t,
                rgb,
                depth: nearest,
            }
        })
        .collect();
    let gt_path = dir.join("groundtruth.txt");
    let text = std::fs::read_to_string(&gt_path).map_err(|e| format!("{}: {e}", gt_path.display()))?;
    let mut gt = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        gt.push(parse_tum_line(line).map_err(|e| format!("{}:{}: {e}", gt_path.display(), i + 1))?);
    }
    Ok((frames, gt))
}

/// Decodes one frame into gray [0, 1] and depth in metres.
pub fn load_frame(frame: &FramePaths) -> Result<(GrayF32, DepthMeters), String> {
    let rgb = image::open(&frame.rgb)
        .map_err(|e| format!("{}: {e}", frame.rgb.display()))?
        .into_rgb8();
    let size = ImageSize::new(rgb.width() as usize, rgb.height() as usize);
    let pixels: Vec<[u8; 3]> = rgb.pixels().map(|p| p.0).collect();
    let rgb = Rgb8::from_vec(size, pixels).map_err(|e| e.to_string())?;
    let gray = gray_from_rgb8(&rgb);
    let raw = image::open(&frame.depth)
        .map_err(|e| format!("{}: {e}", frame.depth.display()))?
        .into_luma16();
    if (raw.width() as usize, raw.height() as usize) != (size.width, size.height) {
        return Err(format!(
            "{}: depth size differs from colour",
            frame.depth.display()
        ));
    }
    let mut depth = DepthMeters::filled(size, 0.0);
    depth_m_from_u16_into(raw.as_raw(), TUM_DEPTH_UNITS_PER_M, &mut depth).map_err(|e| e.to_string())?;
    Ok((gray, depth))
}

/// Largest gap between ground-truth samples to interpolate across (TUM mocap runs at
/// ≈ 100 Hz, so 50 ms tolerates a few dropped samples).
pub const GT_MAX_GAP_NS: u64 = 50_000_000;

/// Relative pose error of one estimated motion `current_from_reference` against the ground
/// truth b = Q_cur⁻¹·Q_ref, composed as TUM's evaluate_rpe (docs/method.md, "Evaluation"):
/// E = a⁻¹·b; returns (‖t(E)‖ in mm, angle(E) in degrees).
pub fn rpe(
    estimated_current_from_reference: &nalgebra::Isometry3<f64>,
    gt_current_from_reference: &nalgebra::Isometry3<f64>,
) -> (f64, f64) {
    let e = estimated_current_from_reference.inverse() * gt_current_from_reference;
    (
        e.translation.vector.norm() * 1000.0,
        e.rotation.angle().to_degrees(),
    )
}

/// Ground-truth motion between two frame times, or `None` when not covered.
pub fn gt_motion(gt: &[StampedPose], t_ref_ns: u64, t_cur_ns: u64) -> Option<nalgebra::Isometry3<f64>> {
    let a = occmask::trajectory::interpolate(gt, t_ref_ns, GT_MAX_GAP_NS)?;
    let b = occmask::trajectory::interpolate(gt, t_cur_ns, GT_MAX_GAP_NS)?;
    Some(occmask::trajectory::motion_between(&a, &b))
}

/// Root mean square.
pub fn rms(values: impl IntoIterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in values {
        s += v * v;
        n += 1;
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}
