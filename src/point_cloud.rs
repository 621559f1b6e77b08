//! Downsampled, coloured 3D points of an RGB-D frame for a 3D view (pure: no files, no MCAP).
//!
//! A [`PointGrid`] samples every `stride`-th pixel per axis of the pipeline's pinhole camera,
//! i.e. the undistorted and registered depth the detector used, and lifts each sample with
//! valid depth into that camera's frame (x right, y down, z forward, metres). A sample's colour
//! is the published colour image's pixel that sees the same ray (the lens distortion applied),
//! so colour is never resampled. The grid and its colour table are built once per sequence;
//! per frame, [`PointGrid::sample_colors_into`] (decode side), [`PointGrid::sample_depth_into`]
//! (beside the pipeline) and [`PointGrid::write_points`] (once the frame's mask is known) fill
//! caller-owned buffers.
//!
//! Each point is [`POINT_STRIDE_BYTES`] bytes, little-endian: `x`, `y`, `z` as `f32` at
//! [`OFFSET_X`], [`OFFSET_Y`], [`OFFSET_Z`], then `red`, `green`, `blue`, `alpha` as `u8` at
//! [`OFFSET_RED`].. (Foxglove's "RGBA (separate fields)" colour mode). Moving points (mask set)
//! are blended towards [`MOVING_TINT`].

use crate::error::{Error, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::CameraModel;
use crate::image_buf::{DepthMeters, ImageSize, Mask, Rgb8, MASK_SET};

/// Default sampling stride (pixels per axis): every 4th pixel of a 640×480 frame gives at most
/// 19 200 points (307 KB per message), dense enough to read the scene in a 3D view at a
/// sixteenth of the full cloud's bytes.
pub const DEFAULT_POINT_STRIDE_PX: usize = 4;
/// Bytes per point: three `f32` coordinates and four `u8` colour channels.
pub const POINT_STRIDE_BYTES: usize = 16;
/// Byte offset of `x` (m) in a point.
pub const OFFSET_X: usize = 0;
/// Byte offset of `y` (m).
pub const OFFSET_Y: usize = 4;
/// Byte offset of `z` (m).
pub const OFFSET_Z: usize = 8;
/// Byte offset of `red`; `green`, `blue` and `alpha` follow.
pub const OFFSET_RED: usize = 12;
/// Colour moving points are blended towards: the red of the mask outlines.
pub const MOVING_TINT: [u8; 3] = [255, 26, 26];
/// How far a moving point's colour moves towards [`MOVING_TINT`] (0 = not at all, 1 = pure
/// tint): enough to read as red from any viewpoint, with the texture still faintly visible.
pub const MOVING_TINT_FRACTION: f32 = 0.75;

/// A colour-table entry with no published pixel (its sample is never a point).
const NO_COLOR: u32 = u32::MAX;

/// The sampling grid of one sequence; see the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct PointGrid {
    size: ImageSize,
    stride: usize,
    intrinsics: PinholeIntrinsics,
    published_size: ImageSize,
    /// Pixel index (in the pipeline image) of each sample, row by row.
    samples: Vec<u32>,
    /// Pixel index in the published colour image of each sample, or [`NO_COLOR`].
    color_index: Vec<u32>,
}

fn check_size(what: &str, expected: ImageSize, found: ImageSize) -> Result<()> {
    if expected != found {
        return Err(Error::SizeMismatch {
            what: what.into(),
            expected,
            found,
        });
    }
    Ok(())
}

fn check_len(what: &'static str, expected: usize, found: usize) -> Result<()> {
    if expected != found {
        return Err(Error::InvalidParameter {
            name: what,
            value: format!("{found} samples"),
            expected: format!("{expected} samples (one per grid cell)"),
        });
    }
    Ok(())
}

impl PointGrid {
    /// The grid of every `stride_px`-th pixel of `pipeline` (a pinhole camera). `published` is
    /// the camera of the colour images the colours are read from, when it differs from
    /// `pipeline` (a distorted lens the pipeline sees undistorted); `None` when the pipeline's
    /// pixels are the published ones.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a zero stride, an empty image or one too large to index.
    pub fn new(pipeline: &CameraModel, published: Option<&CameraModel>, stride_px: usize) -> Result<Self> {
        let size = pipeline.size;
        let published_size = published.map_or(size, |p| p.size);
        if stride_px == 0 {
            return Err(Error::InvalidParameter {
                name: "point stride",
                value: "0".into(),
                expected: "at least 1 pixel".into(),
            });
        }
        if size.area() == 0 || size.area().max(published_size.area()) >= NO_COLOR as usize {
            return Err(Error::InvalidParameter {
                name: "image size",
                value: format!("{size} (point grid)"),
                expected: format!("at least one and fewer than {NO_COLOR} pixels"),
            });
        }
        let k = pipeline.intrinsics;
        let mut samples = Vec::new();
        let mut color_index = Vec::new();
        for v in (0..size.height).step_by(stride_px) {
            for u in (0..size.width).step_by(stride_px) {
                samples.push((v * size.width + u) as u32);
                let color = match published {
                    None => Some((u, v)),
                    Some(camera) => {
                        let (x, y) = camera.pixel((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy);
                        let (x, y) = (x.round(), y.round());
                        let inside = x >= 0.0
                            && y >= 0.0
                            && x < published_size.width as f64
                            && y < published_size.height as f64;
                        inside.then_some((x as usize, y as usize))
                    }
                };
                color_index.push(color.map_or(NO_COLOR, |(x, y)| (y * published_size.width + x) as u32));
            }
        }
        Ok(Self {
            size,
            stride: stride_px,
            intrinsics: k,
            published_size,
            samples,
            color_index,
        })
    }

    /// Samples per frame (the most points a frame can have).
    pub fn samples(&self) -> usize {
        self.samples.len()
    }

    /// The sampling stride, pixels per axis.
    pub fn stride_px(&self) -> usize {
        self.stride
    }

    /// The colour of each sample from the published colour image `rgb` into `colors`
    /// (caller-owned; cleared first, so a reused buffer does not grow).
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when `rgb` is not the published image's size.
    pub fn sample_colors_into(&self, rgb: &Rgb8, colors: &mut Vec<[u8; 3]>) -> Result<()> {
        check_size("point colours", self.published_size, rgb.size())?;
        let pixels = rgb.as_slice();
        colors.clear();
        colors.extend(self.color_index.iter().map(
            |&i| {
                if i == NO_COLOR {
                    [0; 3]
                } else {
                    pixels[i as usize]
                }
            },
        ));
        Ok(())
    }

    /// The depth (m, 0 = invalid) of each sample from the pipeline's depth image into `depth`
    /// (caller-owned, cleared first). Samples without a published colour are invalid.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when `depth_m` is not the pipeline image's size.
    pub fn sample_depth_into(&self, depth_m: &DepthMeters, depth: &mut Vec<f32>) -> Result<()> {
        check_size("point depth", self.size, depth_m.size())?;
        let pixels = depth_m.as_slice();
        depth.clear();
        depth.extend(self.samples.iter().zip(&self.color_index).map(|(&i, &c)| {
            let d = pixels[i as usize];
            if c == NO_COLOR || !d.is_finite() || d <= 0.0 {
                0.0
            } else {
                d
            }
        }));
        Ok(())
    }

    /// Writes the packed points of the samples with valid depth into `out` (cleared first),
    /// in grid order, tinting those whose pixel is set in `mask` (the pipeline's pixels), and
    /// returns how many were written.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when `depth` or `colors` do not hold one value per sample;
    /// [`Error::SizeMismatch`] when `mask` is not the pipeline image's size.
    pub fn write_points(
        &self,
        depth: &[f32],
        colors: &[[u8; 3]],
        mask: &Mask,
        out: &mut Vec<u8>,
    ) -> Result<usize> {
        check_len("point depth", self.samples.len(), depth.len())?;
        check_len("point colours", self.samples.len(), colors.len())?;
        check_size("point mask", self.size, mask.size())?;
        let (k, w) = (self.intrinsics, self.size.width);
        let moving = mask.as_slice();
        out.clear();
        let mut count = 0;
        for ((&i, &z), &color) in self.samples.iter().zip(depth).zip(colors) {
            if z <= 0.0 {
                continue;
            }
            let (u, v) = ((i as usize % w) as f64, (i as usize / w) as f64);
            let z64 = f64::from(z);
            let x = ((u - k.cx) / k.fx * z64) as f32;
            let y = ((v - k.cy) / k.fy * z64) as f32;
            let [r, g, b] = if moving[i as usize] == MASK_SET {
                tint(color)
            } else {
                color
            };
            for value in [x, y, z] {
                out.extend_from_slice(&value.to_le_bytes());
            }
            out.extend_from_slice(&[r, g, b, u8::MAX]);
            count += 1;
        }
        Ok(count)
    }
}

/// `color` blended [`MOVING_TINT_FRACTION`] of the way towards [`MOVING_TINT`].
pub fn tint(color: [u8; 3]) -> [u8; 3] {
    let mut out = [0; 3];
    for ((o, c), t) in out.iter_mut().zip(color).zip(MOVING_TINT) {
        let (c, t) = (f32::from(c), f32::from(t));
        *o = (c + (t - c) * MOVING_TINT_FRACTION).round().clamp(0.0, 255.0) as u8;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::distortion::LensDistortion;
    use crate::image_buf::Image;

    fn point(bytes: &[u8]) -> ([f32; 3], [u8; 4]) {
        let f = |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
        let c = &bytes[OFFSET_RED..OFFSET_RED + 4];
        ([f(OFFSET_X), f(OFFSET_Y), f(OFFSET_Z)], [c[0], c[1], c[2], c[3]])
    }

    fn camera(size: ImageSize) -> CameraModel {
        CameraModel::pinhole(size, PinholeIntrinsics::new(50.0, 52.0, 19.5, 14.5))
    }

    #[test]
    fn points_lift_valid_samples_with_their_colour_and_tint_moving_ones() {
        let size = ImageSize::new(40, 30);
        let grid = PointGrid::new(&camera(size), None, 4).unwrap();
        assert_eq!(grid.samples(), 10 * 8);
        // Depth 1 + x/100 m, invalid in the left quarter; colour encodes the pixel.
        let depth_m = Image::from_fn(size, |x, _| if x < 10 { 0.0 } else { 1.0 + x as f32 / 100.0 });
        let rgb = Image::from_fn(size, |x, y| [x as u8 * 6, y as u8 * 8, 7]);
        let mask = Image::from_fn(size, |x, y| if x >= 20 && y < 12 { MASK_SET } else { 0 });
        let (mut depth, mut colors, mut out) = (Vec::new(), Vec::new(), Vec::new());
        grid.sample_depth_into(&depth_m, &mut depth).unwrap();
        grid.sample_colors_into(&rgb, &mut colors).unwrap();
        let count = grid.write_points(&depth, &colors, &mask, &mut out).unwrap();
        // Columns 12, 16, ..., 36 (7 of 10) in all 8 rows.
        assert_eq!(count, 7 * 8);
        assert_eq!(out.len(), count * POINT_STRIDE_BYTES);
        let k = camera(size).intrinsics;
        let (mut tinted, mut plain) = (0, 0);
        for p in out.chunks_exact(POINT_STRIDE_BYTES) {
            let ([x, y, z], [r, g, b, a]) = point(p);
            // Back to its pixel: on the grid, with the depth and colour of that pixel.
            let u = (f64::from(x) / f64::from(z) * k.fx + k.cx).round() as usize;
            let v = (f64::from(y) / f64::from(z) * k.fy + k.cy).round() as usize;
            assert!(
                u.is_multiple_of(4) && v.is_multiple_of(4) && u >= 12,
                "({u}, {v})"
            );
            assert!((z - depth_m.get(u, v)).abs() < 1e-6);
            assert_eq!(a, 255);
            let expected = if mask.get(u, v) == MASK_SET {
                tinted += 1;
                tint(rgb.get(u, v))
            } else {
                plain += 1;
                rgb.get(u, v)
            };
            assert_eq!([r, g, b], expected, "({u}, {v})");
        }
        // Columns 20..36 (5) in rows 0, 4, 8 (3) are moving.
        assert_eq!((tinted, plain), (15, count - 15));
        // Tinted means red: a grey point becomes clearly red.
        let [r, g, b] = tint([100, 100, 100]);
        assert!(r > 200 && g < 60 && b < 60, "{r} {g} {b}");
        // Reused buffers do not grow.
        let capacity = out.capacity();
        grid.write_points(&depth, &colors, &mask, &mut out).unwrap();
        assert_eq!(out.capacity(), capacity);
    }

    #[test]
    fn colours_come_from_the_distorted_pixel_of_the_same_ray() {
        let size = ImageSize::new(64, 48);
        let k = PinholeIntrinsics::new(60.0, 60.0, 31.5, 23.5);
        let published = CameraModel {
            size,
            intrinsics: k,
            distortion: LensDistortion::from_ros("plumb_bob", &[-0.2, 0.05, 0.001, -0.001, 0.0]).unwrap(),
        };
        let pipeline = CameraModel::pinhole(size, PinholeIntrinsics::new(66.0, 66.0, 31.5, 23.5));
        let grid = PointGrid::new(&pipeline, Some(&published), 8).unwrap();
        let rgb = Image::from_fn(size, |x, y| [x as u8, y as u8, 0]);
        let mut colors = Vec::new();
        grid.sample_colors_into(&rgb, &mut colors).unwrap();
        let pk = pipeline.intrinsics;
        let mut i = 0;
        for v in (0..48).step_by(8) {
            for u in (0..64).step_by(8) {
                let (x, y) = published.pixel((u as f64 - pk.cx) / pk.fx, (v as f64 - pk.cy) / pk.fy);
                assert_eq!(colors[i], [x.round() as u8, y.round() as u8, 0], "({u}, {v})");
                i += 1;
            }
        }
        // The corner of the undistorted view has moved inwards in the distorted image.
        assert_ne!(colors[0], [0, 0, 0]);
    }

    #[test]
    fn wrong_sizes_and_a_zero_stride_are_errors() {
        let size = ImageSize::new(16, 12);
        assert!(PointGrid::new(&camera(size), None, 0).is_err());
        let grid = PointGrid::new(&camera(size), None, 3).unwrap();
        let other = ImageSize::new(12, 16);
        let (mut depth, mut colors, mut out) = (Vec::new(), Vec::new(), Vec::new());
        assert!(grid
            .sample_depth_into(&Image::filled(other, 1.0), &mut depth)
            .is_err());
        assert!(grid
            .sample_colors_into(&Image::filled(other, [0; 3]), &mut colors)
            .is_err());
        grid.sample_depth_into(&Image::filled(size, 1.0), &mut depth)
            .unwrap();
        grid.sample_colors_into(&Image::filled(size, [9; 3]), &mut colors)
            .unwrap();
        assert!(grid
            .write_points(&depth, &colors, &Image::filled(other, 0), &mut out)
            .is_err());
        assert!(grid
            .write_points(&depth[1..], &colors, &Image::filled(size, 0), &mut out)
            .is_err());
        assert_eq!(
            grid.write_points(&depth, &colors, &Image::filled(size, 0), &mut out)
                .unwrap(),
            6 * 4
        );
    }
}
