//! Regenerates `fixtures/larr_fr2_desk_mini` from the first frames of TUM fr2_desk
//! (CC BY 4.0; see fixtures/README.md). Run from the repository root:
//!
//! ```sh
//! cargo run --example make_larr_fixture -- fixtures/tum_fr2_desk_10 fixtures/larr_fr2_desk_mini
//! ```
//!
//! Colour is box-averaged 4×4 (640×480 → 160×120), depth is subsampled (top-left pixel of each
//! 4×4 block, so no invalid/valid mixing) and rescaled from TUM units (5000/m) to LARR
//! millimetres, and the hand-made mask marks the white mug on the desk (polygon below, in
//! full-resolution pixels) as the "moving object".

use std::path::{Path, PathBuf};

use image::{GrayImage, ImageBuffer, Luma, Rgb, RgbImage};
use occmask::dataset::{read_groundtruth, read_image_list};
use occmask::time::format_ns_as_seconds;

/// Frames kept: enough to exercise pairing and masks, small enough for a < 300 kB fixture.
const FRAMES: usize = 4;
/// Downscale factor per axis.
const SCALE: u32 = 4;
/// TUM depth units per millimetre (5000 per metre / 1000).
const TUM_UNITS_PER_MM: f64 = 5.0;
/// Hand-drawn outline of the white mug (x, y) in the 640×480 colour image of frame 0.
const MUG_POLYGON: [(f64, f64); 8] = [
    (446.0, 292.0),
    (486.0, 290.0),
    (489.0, 305.0),
    (487.0, 345.0),
    (470.0, 353.0),
    (452.0, 351.0),
    (445.0, 340.0),
    (444.0, 300.0),
];
/// Ground truth kept beyond the first/last frame, nanoseconds.
const GT_MARGIN_NS: u64 = 50_000_000;

fn inside(polygon: &[(f64, f64)], x: f64, y: f64) -> bool {
    let mut inside = false;
    let mut j = polygon.len() - 1;
    for i in 0..polygon.len() {
        let (xi, yi) = polygon[i];
        let (xj, yj) = polygon[j];
        if (yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi {
            inside = !inside;
        }
        j = i;
    }
    inside
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, src, dst] = &args[..] else {
        return Err(
            "usage: make_larr_fixture <TUM fr2_desk dir, e.g. fixtures/tum_fr2_desk_10> <output dir>".into(),
        );
    };
    let (src, dst) = (Path::new(src), PathBuf::from(dst));
    let color = read_image_list(&src.join("rgb.txt"), src)?;
    let depth = read_image_list(&src.join("depth.txt"), src)?;
    let gt = read_groundtruth(&src.join("groundtruth.txt"))?;
    for d in ["rgb", "depth", "groundtruth mask"] {
        std::fs::create_dir_all(dst.join(d))?;
    }
    let mut association = String::new();
    for i in 0..FRAMES {
        let (c, d) = (&color[i], &depth[i]);
        let tc = format_ns_as_seconds(c.timestamp_ns, 6);
        let td = format_ns_as_seconds(d.timestamp_ns, 6);

        let rgb = image::open(&c.path)?.into_rgb8();
        let (w, h) = (rgb.width() / SCALE, rgb.height() / SCALE);
        let small: RgbImage = ImageBuffer::from_fn(w, h, |x, y| {
            let mut sum = [0u32; 3];
            for dy in 0..SCALE {
                for dx in 0..SCALE {
                    let p = rgb.get_pixel(x * SCALE + dx, y * SCALE + dy);
                    for k in 0..3 {
                        sum[k] += u32::from(p[k]);
                    }
                }
            }
            let n = SCALE * SCALE;
            Rgb(sum.map(|s| ((s + n / 2) / n) as u8))
        });
        small.save(dst.join("rgb").join(format!("{tc}.png")))?;

        let raw = image::open(&d.path)?.into_luma16();
        let depth_mm: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_fn(w, h, |x, y| {
            let v = f64::from(raw.get_pixel(x * SCALE, y * SCALE)[0]);
            Luma([(v / TUM_UNITS_PER_MM).round() as u16])
        });
        depth_mm.save(dst.join("depth").join(format!("{td}.png")))?;

        let mask: GrayImage = ImageBuffer::from_fn(w, h, |x, y| {
            let centre = |v: u32| f64::from(v * SCALE) + f64::from(SCALE) / 2.0 - 0.5;
            Luma([if inside(&MUG_POLYGON, centre(x), centre(y)) {
                255
            } else {
                0
            }])
        });
        mask.save(dst.join("groundtruth mask").join(format!("{tc}.png")))?;
        association.push_str(&format!("{tc} rgb/{tc}.png {td} depth/{td}.png\n"));
    }
    std::fs::write(dst.join("association.txt"), association)?;

    let (t0, t1) = (color[0].timestamp_ns, color[FRAMES - 1].timestamp_ns);
    let mut gt_text =
        String::from("# ground truth trajectory (TUM fr2_desk, cropped)\n# timestamp tx ty tz qx qy qz qw\n");
    let src_gt = std::fs::read_to_string(src.join("groundtruth.txt"))?;
    let kept: Vec<&str> = src_gt
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .zip(&gt)
        .filter(|(_, p)| p.timestamp_ns + GT_MARGIN_NS >= t0 && p.timestamp_ns <= t1 + GT_MARGIN_NS)
        .map(|(l, _)| l)
        .collect();
    for l in kept {
        gt_text.push_str(l);
        gt_text.push('\n');
    }
    std::fs::write(dst.join("groundtruth.txt"), gt_text)?;
    Ok(())
}
