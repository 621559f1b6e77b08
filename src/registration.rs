//! Putting depth and colour into one pinhole camera before odometry and detection (pure: no
//! files, no MCAP): lens undistortion by remap tables, depth registration from another camera
//! by z-buffered reprojection, and the way back for masks.
//!
//! Everything is built once per sequence as a table; applying it per frame is a table walk.
//!
//! - [`BilinearMap`]: each output pixel samples the source bilinearly (grey images);
//! - [`NearestMap`]: each output pixel copies one source pixel or is left at the default value
//!   (depth aligned to a distorted colour image, masks mapped back to the published pixels):
//!   depth is never interpolated, so no value is invented across a depth edge;
//! - [`DepthRegistration`]: every depth pixel is lifted to 3D with its own depth, moved into
//!   the colour camera (`color_from_depth`) and splatted over the colour pixels its footprint
//!   covers, the nearest surface winning (z-buffer). Colour pixels no depth pixel covers stay
//!   invalid (0): holes are never filled by interpolation.
//!
//! Every optimised kernel has a scalar reference (`*_reference`) and a test that they agree.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::CameraModel;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize};

/// Output rows per rayon task: a 640-px row of a remap costs ≈ 1–2 µs, so 16 rows amortise
/// the task overhead and still leave 30 tasks per VGA frame.
const ROWS_PER_TASK: usize = 16;

/// Marks a [`NearestMap`] entry with no source pixel.
const NO_SOURCE: u32 = u32::MAX;

/// Largest image a table indexes: pixel indices are `u32`.
const MAX_TABLE_PIXELS: usize = u32::MAX as usize - 1;

fn check_table_size(what: &str, size: ImageSize) -> Result<()> {
    if size.width < 2 || size.height < 2 || size.area() > MAX_TABLE_PIXELS {
        return Err(Error::InvalidParameter {
            name: "image size",
            value: format!("{size} ({what})"),
            expected: format!("at least 2x2 and at most {MAX_TABLE_PIXELS} pixels"),
        });
    }
    Ok(())
}

fn check_sizes(what: &str, expected: ImageSize, found: ImageSize) -> Result<()> {
    if expected != found {
        return Err(Error::SizeMismatch {
            what: what.into(),
            expected,
            found,
        });
    }
    Ok(())
}

/// A source position `(x, y)` in pixels is inside the source image's area (pixel centres at
/// integers, so the area reaches half a pixel beyond the outer centres).
fn inside(size: ImageSize, x: f64, y: f64) -> bool {
    x >= -0.5 && y >= -0.5 && x <= size.width as f64 - 0.5 && y <= size.height as f64 - 0.5
}

/// One output pixel of a [`BilinearMap`]: the top-left source pixel of the 2×2 neighbourhood
/// and the weights of its right and lower neighbours.
#[derive(Debug, Clone, Copy, PartialEq)]
struct BilinearEntry {
    top_left: u32,
    wx: f32,
    wy: f32,
}

/// Bilinear resampling table: output pixel (u, v) takes the source value at a fixed position.
/// Positions outside the source are clamped to its border, so the output has no holes; the
/// table remembers those pixels ([`Self::clear_outside`]) so depth there can be invalidated.
#[derive(Debug, Clone, PartialEq)]
pub struct BilinearMap {
    source_size: ImageSize,
    output_size: ImageSize,
    entries: Vec<BilinearEntry>,
    /// Output pixels whose position lies outside the source image (or has none).
    outside: Vec<u32>,
}

impl BilinearMap {
    /// The table of `source_at(u, v)`, the source position (pixels) of output pixel (u, v);
    /// `None` or a non-finite position reads the source's centre and counts as outside.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for images smaller than 2×2 or too large to index.
    pub fn from_fn(
        source_size: ImageSize,
        output_size: ImageSize,
        source_at: impl Fn(f64, f64) -> Option<(f64, f64)> + Sync,
    ) -> Result<Self> {
        check_table_size("remap source", source_size)?;
        check_table_size("remap output", output_size)?;
        let (w, h) = (source_size.width, source_size.height);
        let entry = |u: usize, v: usize| {
            let position = source_at(u as f64, v as f64).filter(|(x, y)| x.is_finite() && y.is_finite());
            let is_inside = position.is_some_and(|(x, y)| inside(source_size, x, y));
            let (x, y) = position.unwrap_or(((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5));
            let x = x.clamp(0.0, w as f64 - 1.0);
            let y = y.clamp(0.0, h as f64 - 1.0);
            let ix = (x.floor() as usize).min(w - 2);
            let iy = (y.floor() as usize).min(h - 2);
            let entry = BilinearEntry {
                top_left: (iy * w + ix) as u32,
                wx: (x - ix as f64) as f32,
                wy: (y - iy as f64) as f32,
            };
            (entry, is_inside)
        };
        let (entries, is_inside): (Vec<_>, Vec<_>) = table(output_size, entry).into_iter().unzip();
        let outside = (0..is_inside.len() as u32)
            .filter(|&i| !is_inside[i as usize])
            .collect();
        Ok(Self {
            source_size,
            output_size,
            entries,
            outside,
        })
    }

    /// Sets `value` at every output pixel whose position lay outside the source image (e.g.
    /// 0 in the depth that goes with a remapped grey image: the grey value there is only the
    /// clamped border).
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when `image` does not have the output size.
    pub fn clear_outside<T: Copy>(&self, image: &mut Image<T>, value: T) -> Result<()> {
        check_sizes("remap output", self.output_size, image.size())?;
        let data = image.as_mut_slice();
        for &i in &self.outside {
            data[i as usize] = value;
        }
        Ok(())
    }

    /// Fraction of output pixels whose position lies inside the source image.
    pub fn covered_fraction(&self) -> f64 {
        1.0 - self.outside.len() as f64 / self.entries.len().max(1) as f64
    }

    /// Size of the images the table reads.
    pub fn source_size(&self) -> ImageSize {
        self.source_size
    }

    /// Size of the images the table writes.
    pub fn output_size(&self) -> ImageSize {
        self.output_size
    }

    /// Resamples `source` into `output` (caller-owned), row-parallel.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image does not have the table's size.
    pub fn apply_into(&self, source: &GrayF32, output: &mut GrayF32) -> Result<()> {
        self.check(source, output)?;
        let (src, w) = (source.as_slice(), self.source_size.width);
        let ow = self.output_size.width;
        output
            .as_mut_slice()
            .par_chunks_mut(ow * ROWS_PER_TASK)
            .zip(self.entries.par_chunks(ow * ROWS_PER_TASK))
            .for_each(|(out, entries)| {
                for (o, e) in out.iter_mut().zip(entries) {
                    *o = bilinear(src, w, e);
                }
            });
        Ok(())
    }

    /// [`Self::apply_into`] on the calling thread (its scalar reference, and the kernel for
    /// threads outside a rayon pool, which would otherwise hand the work to the global pool).
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_serial(&self, source: &GrayF32, output: &mut GrayF32) -> Result<()> {
        self.check(source, output)?;
        for (o, e) in output.as_mut_slice().iter_mut().zip(&self.entries) {
            *o = bilinear(source.as_slice(), self.source_size.width, e);
        }
        Ok(())
    }

    /// Resamples depth (m, 0 = invalid) into `output`: bilinear between neighbours on one
    /// surface ([`MAX_INTERPOLATED_DEPTH_STEP`]), else the nearest neighbour; positions
    /// outside the source are 0. Row-parallel.
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_depth_into(&self, source: &DepthMeters, output: &mut DepthMeters) -> Result<()> {
        self.check(source, output)?;
        let (src, w) = (source.as_slice(), self.source_size.width);
        let ow = self.output_size.width;
        output
            .as_mut_slice()
            .par_chunks_mut(ow * ROWS_PER_TASK)
            .zip(self.entries.par_chunks(ow * ROWS_PER_TASK))
            .for_each(|(out, entries)| {
                for (o, e) in out.iter_mut().zip(entries) {
                    *o = depth_bilinear(src, w, e);
                }
            });
        self.clear_outside(output, 0.0)
    }

    /// [`Self::apply_depth_into`] on the calling thread (its scalar reference, and the kernel
    /// for threads outside a rayon pool).
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_depth_serial(&self, source: &DepthMeters, output: &mut DepthMeters) -> Result<()> {
        self.check(source, output)?;
        for (o, e) in output.as_mut_slice().iter_mut().zip(&self.entries) {
            *o = depth_bilinear(source.as_slice(), self.source_size.width, e);
        }
        self.clear_outside(output, 0.0)
    }

    fn check(&self, source: &GrayF32, output: &GrayF32) -> Result<()> {
        check_sizes("remap source", self.source_size, source.size())?;
        check_sizes("remap output", self.output_size, output.size())
    }
}

/// Depths of the four neighbours of a resampling position are interpolated when they differ by
/// at most this fraction of the nearest: one surface (a floor seen at 75° from its normal at
/// 5 m changes by 3 % per VGA pixel; Kinect-class noise is below 1 % at 4 m), while the
/// silhouette of one object against another is a larger step. Across a larger step the
/// nearest neighbour is taken, so no depth between two surfaces is invented.
pub const MAX_INTERPOLATED_DEPTH_STEP: f32 = 0.05;

/// Depth at a resampling position: bilinear on one surface, else the nearest neighbour
/// (which may be a hole, 0).
#[inline]
fn depth_bilinear(src: &[f32], width: usize, e: &BilinearEntry) -> f32 {
    let i = e.top_left as usize;
    let (a, b) = (src[i], src[i + 1]);
    let (c, d) = (src[i + width], src[i + width + 1]);
    let lo = a.min(b).min(c).min(d);
    let hi = a.max(b).max(c).max(d);
    if lo > 0.0 && hi <= lo * (1.0 + MAX_INTERPOLATED_DEPTH_STEP) {
        let top = a + (b - a) * e.wx;
        let bottom = c + (d - c) * e.wx;
        top + (bottom - top) * e.wy
    } else {
        src[i + usize::from(e.wx >= 0.5) + usize::from(e.wy >= 0.5) * width]
    }
}

#[inline]
fn bilinear(src: &[f32], width: usize, e: &BilinearEntry) -> f32 {
    let i = e.top_left as usize;
    let (a, b) = (src[i], src[i + 1]);
    let (c, d) = (src[i + width], src[i + width + 1]);
    let top = a + (b - a) * e.wx;
    let bottom = c + (d - c) * e.wx;
    top + (bottom - top) * e.wy
}

/// Builds a per-output-pixel table row-parallel.
fn table<E: Send>(size: ImageSize, entry: impl Fn(usize, usize) -> E + Sync) -> Vec<E> {
    (0..size.height)
        .into_par_iter()
        .flat_map_iter(|v| (0..size.width).map(move |u| (u, v)))
        .map(|(u, v)| entry(u, v))
        .collect()
}

/// Nearest-pixel table: output pixel (u, v) copies one source pixel, or is set to
/// `T::default()` (0: invalid depth, not moving) where no source pixel maps to it.
#[derive(Debug, Clone, PartialEq)]
pub struct NearestMap {
    source_size: ImageSize,
    output_size: ImageSize,
    source_index: Vec<u32>,
}

impl NearestMap {
    /// The table of `source_at(u, v)` (source position in pixels, rounded to the nearest
    /// pixel); `None` or a position outside the source image leaves the output pixel empty.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for images smaller than 2×2 or too large to index.
    pub fn from_fn(
        source_size: ImageSize,
        output_size: ImageSize,
        source_at: impl Fn(f64, f64) -> Option<(f64, f64)> + Sync,
    ) -> Result<Self> {
        check_table_size("remap source", source_size)?;
        check_table_size("remap output", output_size)?;
        let w = source_size.width;
        let entry = |u: usize, v: usize| match source_at(u as f64, v as f64) {
            Some((x, y)) if inside(source_size, x, y) => {
                // Inside the area, so rounding lands on a pixel (the clamp only catches the
                // outer half-pixel edge, which rounds to w or h).
                let ix = (x.round().max(0.0) as usize).min(w - 1);
                let iy = (y.round().max(0.0) as usize).min(source_size.height - 1);
                (iy * w + ix) as u32
            }
            _ => NO_SOURCE,
        };
        Ok(Self {
            source_size,
            output_size,
            source_index: table(output_size, entry),
        })
    }

    /// Size of the images the table reads.
    pub fn source_size(&self) -> ImageSize {
        self.source_size
    }

    /// Size of the images the table writes.
    pub fn output_size(&self) -> ImageSize {
        self.output_size
    }

    /// Fraction of output pixels that have a source pixel.
    pub fn covered_fraction(&self) -> f64 {
        let covered = self.source_index.iter().filter(|&&i| i != NO_SOURCE).count();
        covered as f64 / self.source_index.len().max(1) as f64
    }

    /// Copies `source` into `output` (caller-owned) through the table, row-parallel.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image does not have the table's size.
    pub fn apply_into<T: Copy + Default + Send + Sync>(
        &self,
        source: &Image<T>,
        output: &mut Image<T>,
    ) -> Result<()> {
        self.check(source.size(), output.size())?;
        let src = source.as_slice();
        let ow = self.output_size.width;
        output
            .as_mut_slice()
            .par_chunks_mut(ow * ROWS_PER_TASK)
            .zip(self.source_index.par_chunks(ow * ROWS_PER_TASK))
            .for_each(|(out, index)| {
                for (o, &i) in out.iter_mut().zip(index) {
                    *o = nearest(src, i);
                }
            });
        Ok(())
    }

    /// [`Self::apply_into`] on the calling thread (its scalar reference, and the kernel for
    /// threads outside a rayon pool).
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_serial<T: Copy + Default>(&self, source: &Image<T>, output: &mut Image<T>) -> Result<()> {
        self.check(source.size(), output.size())?;
        for (o, &i) in output.as_mut_slice().iter_mut().zip(&self.source_index) {
            *o = nearest(source.as_slice(), i);
        }
        Ok(())
    }

    fn check(&self, source: ImageSize, output: ImageSize) -> Result<()> {
        check_sizes("remap source", self.source_size, source)?;
        check_sizes("remap output", self.output_size, output)
    }
}

#[inline]
fn nearest<T: Copy + Default>(src: &[T], index: u32) -> T {
    if index == NO_SOURCE {
        T::default()
    } else {
        src[index as usize]
    }
}

/// Largest focal-length scale [`inscribed_pinhole`] considers: a lens whose undistorted image
/// would have to be magnified more than this to leave no pixel without data keeps its K (and
/// the pixels without data are marked).
const MAX_INSCRIBED_SCALE: f64 = 2.0;
/// Bisection steps of [`inscribed_pinhole`]: 2^-30 of the scale range, far below a pixel.
const INSCRIBED_SCALE_STEPS: usize = 30;

/// The pinhole camera to undistort `camera` into: its size, principal point and the smallest
/// focal lengths at or above its own (the same factor for x and y) for which every pixel
/// sees a ray the distorted image recorded (OpenCV's `getOptimalNewCameraMatrix` with
/// α = 0, the principal point kept). Lenses whose pinhole image with the same K lies inside
/// the recorded one (barrel distortion) keep K. With K itself the corners of a Kinect's
/// pinhole image (TUM freiburg1: 5 % of the pixels) would only hold the clamped image border,
/// and odometry near that edge drifts (measured: ATE +60 % on synthetic sequences).
///
/// Only the image border is checked: radial distortion moves points monotonically, so the
/// border's pixels reach farthest out.
pub fn inscribed_pinhole(camera: &CameraModel) -> CameraModel {
    let pinhole = camera.undistorted();
    if camera.distortion.is_none() {
        return pinhole;
    }
    let (w, h) = (camera.size.width, camera.size.height);
    let k = camera.intrinsics;
    let fits = |scale: f64| {
        let border = (0..w)
            .flat_map(|u| [(u, 0), (u, h - 1)])
            .chain((0..h).flat_map(|v| [(0, v), (w - 1, v)]));
        border.into_iter().all(|(u, v)| {
            let (x, y) = camera.pixel(
                (u as f64 - k.cx) / (scale * k.fx),
                (v as f64 - k.cy) / (scale * k.fy),
            );
            inside(camera.size, x, y)
        })
    };
    if fits(1.0) || !fits(MAX_INSCRIBED_SCALE) {
        return pinhole;
    }
    let (mut lo, mut hi) = (1.0, MAX_INSCRIBED_SCALE);
    for _ in 0..INSCRIBED_SCALE_STEPS {
        let mid = 0.5 * (lo + hi);
        if fits(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    CameraModel::pinhole(
        camera.size,
        PinholeIntrinsics::new(k.fx * hi, k.fy * hi, k.cx, k.cy),
    )
}

/// The table that undistorts an image of `camera` into the pinhole camera `pinhole` (its
/// size and K; e.g. [`inscribed_pinhole`]): [`BilinearMap::apply_into`] for grey,
/// [`BilinearMap::apply_depth_into`] for depth registered to the distorted pixels.
///
/// # Errors
/// As [`BilinearMap::from_fn`].
pub fn undistortion_map(camera: &CameraModel, pinhole: &CameraModel) -> Result<BilinearMap> {
    let k = pinhole.intrinsics;
    BilinearMap::from_fn(camera.size, pinhole.size, |u, v| {
        Some(camera.pixel((u - k.cx) / k.fx, (v - k.cy) / k.fy))
    })
}

/// The table that maps an image of the pinhole camera `pinhole` back to the pixels of
/// `camera` (masks computed on undistorted images, published on the original ones).
///
/// # Errors
/// As [`NearestMap::from_fn`].
pub fn distortion_map(camera: &CameraModel, pinhole: &CameraModel) -> Result<NearestMap> {
    NearestMap::from_fn(pinhole.size, camera.size, |u, v| {
        camera.ray(u, v).map(|(x, y)| pinhole.pixel(x, y))
    })
}

/// Depth nearer than this in the colour camera is not registered (m): no RGB-D sensor
/// measures closer than a few centimetres, and the projection divides by it.
const MIN_REGISTERED_DEPTH_M: f32 = 0.01;
/// Each depth pixel's footprint is widened by this much on every side (colour pixels): the
/// footprints of neighbouring depth pixels share their edges only up to the parallax of the
/// cameras' baseline over their depth difference (≈ 0.02 px for 15 mm at 2 m and 1 cm steps),
/// so without a margin a colour pixel centre on a shared edge could fall between them.
const SPLAT_MARGIN_PX: f32 = 0.05;
/// Largest half-size of a footprint (colour pixels): a depth pixel of a 320×240 sensor seen by
/// a 1280×720 colour camera covers ≈ 4 px; larger footprints only come from grazing surfaces
/// and rays almost parallel to the image plane, which are cut to this.
const MAX_SPLAT_HALF_PX: f32 = 8.0;
/// Z-buffers of [`DepthRegistration`] are merged from at most this many bands of depth rows
/// (one per thread): each band costs a colour-sized buffer to clear and merge per frame.
const MAX_REGISTRATION_BANDS: usize = 4;

/// The precomputed geometry of every depth pixel, one array per quantity (row-major, so a
/// row's projection is a loop over plain slices that the compiler vectorises): its ray
/// rotated into the colour camera (`R · (x, y, 1)` for the undistorted normalised ray (x, y)),
/// and the half-size of its footprint in colour pixels for points at infinity. `ray_z` is NaN
/// for pixels whose ray cannot be computed.
#[derive(Debug, Clone, Default, PartialEq)]
struct RayTable {
    ray_x: Vec<f32>,
    ray_y: Vec<f32>,
    ray_z: Vec<f32>,
    half_u: Vec<f32>,
    half_v: Vec<f32>,
}

/// The colour pixels one depth pixel covers, `[x0, x1) × [y0, y1)` (whole numbers in
/// `[0, side]`, kept as f32: converting them in the projection loop with `as i32` kept it from
/// vectorising and took 1.5× the time of [`whole_to_index`] in the splat loop), and its colour
/// depth; one array per quantity, one entry per depth pixel of a row.
#[derive(Debug, Clone, Default)]
struct RowFootprints {
    x0: Vec<f32>,
    x1: Vec<f32>,
    y0: Vec<f32>,
    y1: Vec<f32>,
    z: Vec<f32>,
}

impl RowFootprints {
    fn new(width: usize) -> Self {
        Self {
            x0: vec![0.0; width],
            x1: vec![0.0; width],
            y0: vec![0.0; width],
            y1: vec![0.0; width],
            z: vec![0.0; width],
        }
    }
}

/// Depth registration into another camera; see the module documentation.
#[derive(Debug, Clone)]
pub struct DepthRegistration {
    depth_size: ImageSize,
    color_size: ImageSize,
    projection: Projection,
    rays: RayTable,
    /// One z-buffer (colour-sized, +∞ = empty) and one row of footprints per band of depth
    /// rows.
    bands: Vec<(Vec<f32>, RowFootprints)>,
}

impl DepthRegistration {
    /// The tables for registering images of `depth_camera` (with its distortion) into the
    /// pinhole `color_camera` (its distortion is ignored: registration produces depth for the
    /// undistorted colour image), `color_from_depth` placing the depth camera in the colour
    /// camera's frame.
    ///
    /// `threads` bands of depth rows are splatted in parallel (at most
    /// [`MAX_REGISTRATION_BANDS`]); with 1, [`Self::register_into`] runs on the calling thread
    /// without rayon and splats straight into its output.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for images smaller than 2×2, too large to index, or a
    /// transform that is not finite.
    pub fn new(
        depth_camera: &CameraModel,
        color_camera: &CameraModel,
        color_from_depth: &Isometry3<f64>,
        threads: usize,
    ) -> Result<Self> {
        check_table_size("depth", depth_camera.size)?;
        check_table_size("colour", color_camera.size)?;
        if color_camera.size.width.max(color_camera.size.height) > MAX_EXACT_SIDE {
            return Err(Error::InvalidParameter {
                name: "image size",
                value: color_camera.size.to_string(),
                expected: format!("sides of at most {MAX_EXACT_SIDE} pixels"),
            });
        }
        let t = color_from_depth.translation.vector;
        let q = color_from_depth.rotation;
        if !(t.iter().all(|v| v.is_finite()) && q.coords.iter().all(|v| v.is_finite())) {
            return Err(Error::InvalidParameter {
                name: "color_from_depth",
                value: format!("{color_from_depth:?}"),
                expected: "a finite rigid transform".into(),
            });
        }
        let rotation = color_from_depth.rotation;
        let k = color_camera.intrinsics;
        let project_at_infinity = |x: f64, y: f64| -> Option<(f64, f64)> {
            let r = rotation * Point3::new(x, y, 1.0);
            (r.z > 0.0).then(|| (k.fx * r.x / r.z + k.cx, k.fy * r.y / r.z + k.cy))
        };
        // (ray x, y, z, half u, half v) of depth pixel (u, v).
        let entry = |u: usize, v: usize| -> [f32; 5] {
            let invalid = [0.0, 0.0, f32::NAN, 0.0, 0.0];
            let (u, v) = (u as f64, v as f64);
            let Some((x, y)) = depth_camera.ray(u, v) else {
                return invalid;
            };
            let r = rotation * Point3::new(x, y, 1.0);
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for (du, dv) in [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)] {
                let Some((cu, cv)) = depth_camera
                    .ray(u + du, v + dv)
                    .and_then(|(cx, cy)| project_at_infinity(cx, cy))
                else {
                    return invalid;
                };
                lo = [lo[0].min(cu), lo[1].min(cv)];
                hi = [hi[0].max(cu), hi[1].max(cv)];
            }
            let half = |i: usize| (((hi[i] - lo[i]) * 0.5) as f32).min(MAX_SPLAT_HALF_PX);
            [r.x as f32, r.y as f32, r.z as f32, half(0), half(1)]
        };
        let entries = table(depth_camera.size, entry);
        let column = |i: usize| entries.iter().map(|e| e[i]).collect::<Vec<f32>>();
        let rays = RayTable {
            ray_x: column(0),
            ray_y: column(1),
            ray_z: column(2),
            half_u: column(3),
            half_v: column(4),
        };
        let bands = threads.clamp(1, MAX_REGISTRATION_BANDS);
        // One band splats into the caller's output: it needs no z-buffer of its own.
        let zbuffer_pixels = if bands == 1 { 0 } else { color_camera.size.area() };
        Ok(Self {
            depth_size: depth_camera.size,
            color_size: color_camera.size,
            projection: Projection {
                k: [k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32],
                t: [t.x as f32, t.y as f32, t.z as f32],
                width: color_camera.size.width as f32,
                height: color_camera.size.height as f32,
            },
            rays,
            bands: (0..bands)
                .map(|_| {
                    (
                        vec![f32::INFINITY; zbuffer_pixels],
                        RowFootprints::new(depth_camera.size.width),
                    )
                })
                .collect(),
        })
    }

    /// Size of the depth images registered.
    pub fn depth_size(&self) -> ImageSize {
        self.depth_size
    }

    /// Size of the registered depth (the colour image's).
    pub fn color_size(&self) -> ImageSize {
        self.color_size
    }

    /// Registers `depth_m` (depth camera, m, 0 = invalid) into `registered_m` (colour camera,
    /// caller-owned, m along the colour camera's z, 0 where no depth pixel lands). Each depth
    /// row is projected in one pass, then splatted. With several bands, bands of depth rows are
    /// splatted in parallel into z-buffers of their own, which are then merged by taking the
    /// nearest: the result does not depend on the number of bands.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image does not have the table's size.
    pub fn register_into(&mut self, depth_m: &DepthMeters, registered_m: &mut DepthMeters) -> Result<()> {
        self.check(depth_m, registered_m)?;
        let (dw, dh) = (self.depth_size.width, self.depth_size.height);
        let rows_per_band = dh.div_ceil(self.bands.len());
        let (projection, rays, depth) = (&self.projection, &self.rays, depth_m.as_slice());
        let cw = self.color_size.width;
        if let [(_, footprints)] = self.bands.as_mut_slice() {
            let out = registered_m.as_mut_slice();
            out.fill(f32::INFINITY);
            for y in 0..dh {
                let row = y * dw..(y + 1) * dw;
                projection.row(&depth[row.clone()], rays, row, footprints);
                splat_row(footprints, out, cw);
            }
            for o in out.iter_mut() {
                if *o == f32::INFINITY {
                    *o = 0.0;
                }
            }
            return Ok(());
        }
        self.bands
            .par_iter_mut()
            .enumerate()
            .for_each(|(band, (zbuffer, footprints))| {
                zbuffer.fill(f32::INFINITY);
                for y in band * rows_per_band..((band + 1) * rows_per_band).min(dh) {
                    let row = y * dw..(y + 1) * dw;
                    projection.row(&depth[row.clone()], rays, row, footprints);
                    splat_row(footprints, zbuffer, cw);
                }
            });
        let bands = &self.bands;
        registered_m
            .as_mut_slice()
            .par_chunks_mut(cw * ROWS_PER_TASK)
            .enumerate()
            .for_each(|(chunk, out)| {
                let range = chunk * cw * ROWS_PER_TASK..chunk * cw * ROWS_PER_TASK + out.len();
                // Plain slice loops (a copy, element-wise minima, one select) vectorise; the
                // same merge written as a fold over the bands per pixel took 70 % of the
                // registration's time.
                out.copy_from_slice(&bands[0].0[range.clone()]);
                for (zbuffer, _) in &bands[1..] {
                    for (o, &z) in out.iter_mut().zip(&zbuffer[range.clone()]) {
                        if z < *o {
                            *o = z;
                        }
                    }
                }
                for o in out.iter_mut() {
                    if *o == f32::INFINITY {
                        *o = 0.0;
                    }
                }
            });
        Ok(())
    }

    /// Scalar reference of [`Self::register_into`]: one z-buffer, one depth pixel at a time.
    ///
    /// # Errors
    /// As [`Self::register_into`].
    pub fn register_reference(&self, depth_m: &DepthMeters, registered_m: &mut DepthMeters) -> Result<()> {
        self.check(depth_m, registered_m)?;
        let mut zbuffer = vec![f32::INFINITY; self.color_size.area()];
        let cw = self.color_size.width;
        let r = &self.rays;
        for (i, &d) in depth_m.as_slice().iter().enumerate() {
            let [x0, x1, y0, y1] =
                self.projection
                    .footprint(d, r.ray_x[i], r.ray_y[i], r.ray_z[i], r.half_u[i], r.half_v[i]);
            let z = self.projection.depth(d, r.ray_z[i]);
            for y in y0 as usize..y1 as usize {
                for x in x0 as usize..x1 as usize {
                    let cell = &mut zbuffer[y * cw + x];
                    if z < *cell {
                        *cell = z;
                    }
                }
            }
        }
        for (o, z) in registered_m.as_mut_slice().iter_mut().zip(zbuffer) {
            *o = if z == f32::INFINITY { 0.0 } else { z };
        }
        Ok(())
    }

    fn check(&self, depth_m: &DepthMeters, registered_m: &DepthMeters) -> Result<()> {
        check_sizes("depth to register", self.depth_size, depth_m.size())?;
        check_sizes("registered depth", self.color_size, registered_m.size())
    }
}

/// Writes each footprint's depth into the colour pixels it covers, keeping the nearer value.
#[inline]
fn splat_row(footprints: &RowFootprints, zbuffer: &mut [f32], width: usize) {
    let f = footprints;
    for i in 0..f.z.len() {
        let (y0, y1) = (whole_to_index(f.y0[i]), whole_to_index(f.y1[i]));
        // Empty ranges have y1 = y0, so x0 and x1 are read only for footprints on the image.
        if y0 >= y1 {
            continue;
        }
        let (x0, x1, z) = (whole_to_index(f.x0[i]), whole_to_index(f.x1[i]), f.z[i]);
        for row in zbuffer[y0 * width..y1 * width].chunks_exact_mut(width) {
            for cell in &mut row[x0..x1] {
                if z < *cell {
                    *cell = z;
                }
            }
        }
    }
}

/// A whole number `0 ≤ x < 2^23` as an index, without the saturating float-to-int cast (a
/// dozen instructions each, 23 % of the registration's time for its four casts per depth
/// pixel): `x + 2^23` has exponent 23, so its mantissa bits are `x`.
#[inline(always)]
fn whole_to_index(x: f32) -> usize {
    const TWO_POW_23: f32 = 8_388_608.0;
    const MANTISSA: u32 = (1 << 23) - 1;
    ((x + TWO_POW_23).to_bits() & MANTISSA) as usize
}

/// Largest image side [`DepthRegistration`] accepts: [`ceil_f32`] is exact below 2^22.
const MAX_EXACT_SIDE: usize = 1 << 22;

/// `x.ceil()` in plain f32 arithmetic, exact for |x| < 2^22 (larger values come out within 1
/// of x, beyond any image, and the caller clamps them). `ceil` itself is a libm call on
/// baseline x86-64 (no SSE4.1 rounding) and float-to-int casts saturate with extra code:
/// either kept the projection loop from vectorising, and the clamped cast took 30 % of the
/// registration's time (`benches/registration.rs`, perf).
#[inline(always)]
fn ceil_f32(x: f32) -> f32 {
    /// 1.5 · 2^23: adding and subtracting it rounds an f32 of magnitude < 2^22 to an integer.
    const ROUND: f32 = 12_582_912.0;
    let r = (x + ROUND) - ROUND;
    if r < x {
        r + 1.0
    } else {
        r
    }
}

/// The colour camera's projection and `color_from_depth`'s translation, shared by the
/// parallel kernel and its reference (same arithmetic, so both give identical bits).
#[derive(Debug, Clone, Copy)]
struct Projection {
    /// fx, fy, cx, cy of the colour camera.
    k: [f32; 4],
    /// Translation of `color_from_depth` (m).
    t: [f32; 3],
    width: f32,
    height: f32,
}

impl Projection {
    /// The point's depth along the colour camera's axis.
    #[inline(always)]
    fn depth(&self, d: f32, ray_z: f32) -> f32 {
        d * ray_z + self.t[2]
    }

    /// The colour pixels `[x0, x1) × [y0, y1)` whose centres the footprint of a depth pixel
    /// with depth `d` (m) covers; empty for invalid depth, invalid rays and points nearer than
    /// [`MIN_REGISTERED_DEPTH_M`]. Branch-free, so a row of them vectorises.
    #[inline(always)]
    fn footprint(&self, d: f32, ray_x: f32, ray_y: f32, ray_z: f32, half_u: f32, half_v: f32) -> [f32; 4] {
        let [fx, fy, cx, cy] = self.k;
        let [tx, ty, _] = self.t;
        let z = self.depth(d, ray_z);
        // `>=`/`>` are false for NaN (invalid rays, NaN depth); `&` does not branch.
        let valid = (d > 0.0) & (z >= MIN_REGISTERED_DEPTH_M);
        let inv_z = 1.0 / z;
        let u = fx * (d * ray_x + tx) * inv_z + cx;
        let v = fy * (d * ray_y + ty) * inv_z + cy;
        // The footprint at infinity scales with the depth along the colour camera's axis
        // over the point's colour depth (only the translation's z changes it).
        let scale = d * ray_z * inv_z;
        let hu = half_u * scale + SPLAT_MARGIN_PX;
        let hv = half_v * scale + SPLAT_MARGIN_PX;
        // Colour pixel centres c with u − hu ≤ c < u + hu (half-open, so footprints that share
        // an edge never both claim a centre on it).
        // Selects rather than `f32::max`/`min`, whose NaN handling costs instructions: NaN
        // only comes with `valid == false`.
        let at_least_0 = |x: f32| if x > 0.0 { x } else { 0.0 };
        let x0 = at_least_0(ceil_f32(u - hu));
        let y0 = at_least_0(ceil_f32(v - hv));
        let x1 = ceil_f32(u + hu);
        let x1 = if x1 < self.width { x1 } else { self.width };
        let y1 = ceil_f32(v + hv);
        let y1 = if y1 < self.height { y1 } else { self.height };
        // Invalid or off-image footprints become empty row ranges (y1 = y0).
        let on_image = valid & (x0 < x1) & (y0 < y1);
        [x0, x1, y0, if on_image { y1 } else { y0 }]
    }

    /// [`Self::footprint`] and [`Self::depth`] of every pixel of one depth row.
    fn row(&self, depth: &[f32], rays: &RayTable, range: std::ops::Range<usize>, out: &mut RowFootprints) {
        let r = range;
        let (rx, ry, rz) = (
            &rays.ray_x[r.clone()],
            &rays.ray_y[r.clone()],
            &rays.ray_z[r.clone()],
        );
        let (hu, hv) = (&rays.half_u[r.clone()], &rays.half_v[r]);
        let n = depth.len();
        let (x0, x1, y0, y1, z) = (
            &mut out.x0[..n],
            &mut out.x1[..n],
            &mut out.y0[..n],
            &mut out.y1[..n],
            &mut out.z[..n],
        );
        for i in 0..n {
            // Whole numbers in [0, side], or NaN (x0, x1 of empty ranges) which casts to 0.
            let [a, b, c, e] = self.footprint(depth[i], rx[i], ry[i], rz[i], hu[i], hv[i]);
            x0[i] = a;
            x1[i] = b;
            y0[i] = c;
            y1[i] = e;
            z[i] = self.depth(depth[i], rz[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::camera::PinholeIntrinsics;
    use crate::geometry::distortion::{presets, LensDistortion};
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn realsense_like() -> (CameraModel, CameraModel, Isometry3<f64>) {
        let depth = CameraModel {
            size: ImageSize::new(212, 120),
            intrinsics: PinholeIntrinsics::new(106.0, 106.0, 105.7, 59.6),
            distortion: Some(LensDistortion::plumb_bob(-0.02, 0.01, 0.0, 0.0, 0.0)),
        };
        let color = CameraModel::pinhole(
            ImageSize::new(160, 120),
            PinholeIntrinsics::new(131.0, 131.0, 79.5, 59.5),
        );
        let color_from_depth = Isometry3::from_parts(
            Translation3::new(0.015, 0.0002, -0.0004),
            UnitQuaternion::from_euler_angles(0.004, -0.003, 0.002),
        );
        (depth, color, color_from_depth)
    }

    /// Depth of the plane n·p = offset seen by `camera` (exact ray–plane intersection).
    fn plane_depth(
        camera: &CameraModel,
        normal: Vector3<f64>,
        offset: f64,
        camera_from_world: &Isometry3<f64>,
    ) -> DepthMeters {
        let world_from_camera = camera_from_world.inverse();
        DepthMeters::from_fn(camera.size, |u, v| {
            let Some((x, y)) = camera.ray(u as f64, v as f64) else {
                return 0.0;
            };
            let o = world_from_camera.translation.vector;
            let dir = world_from_camera.rotation * Vector3::new(x, y, 1.0);
            let s = (offset - normal.dot(&o)) / normal.dot(&dir);
            if s > 0.0 {
                s as f32
            } else {
                0.0
            }
        })
    }

    #[test]
    fn registering_a_plane_gives_the_plane_seen_from_colour() {
        // The law "register, then project back = identity" on a slanted plane: the registered
        // depth at every covered colour pixel is that pixel's own ray hitting the plane.
        let (depth_camera, color_camera, color_from_depth) = realsense_like();
        let normal = Vector3::new(0.2, -0.1, 1.0).normalize();
        let offset = 2.0;
        // World = colour camera.
        let depth_from_color = color_from_depth.inverse();
        let depth = plane_depth(&depth_camera, normal, offset, &depth_from_color);
        let expected = plane_depth(&color_camera, normal, offset, &Isometry3::identity());
        let mut registration =
            DepthRegistration::new(&depth_camera, &color_camera, &color_from_depth, 2).unwrap();
        let mut registered = DepthMeters::filled(color_camera.size, -1.0);
        registration.register_into(&depth, &mut registered).unwrap();
        let mut covered = 0;
        let mut worst = 0.0f32;
        for (r, e) in registered.as_slice().iter().zip(expected.as_slice()) {
            if *r > 0.0 {
                covered += 1;
                worst = worst.max((r - e).abs() / e);
            }
        }
        // The depth camera is wider than the colour camera: everything is covered, and each
        // value is the depth of a point within the depth pixel's footprint, never an
        // interpolation: 0.18 % of the depth at worst on this slant (bound 0.5 %).
        assert_eq!(covered, color_camera.size.area(), "holes on a plane");
        assert!(worst < 5e-3, "worst relative depth error {worst}");
    }

    #[test]
    fn nearer_surfaces_win_and_disocclusions_stay_holes() {
        // A near box in front of a far wall: the colour camera, 15 mm to the side, sees wall
        // that the depth camera cannot: those pixels must stay 0, not take either depth.
        let (depth_camera, color_camera, _) = realsense_like();
        let color_from_depth = Isometry3::translation(-0.05, 0.0, 0.0);
        let depth = DepthMeters::from_fn(depth_camera.size, |u, v| {
            if (90..120).contains(&u) && (40..80).contains(&v) {
                0.5
            } else {
                3.0
            }
        });
        let mut registration =
            DepthRegistration::new(&depth_camera, &color_camera, &color_from_depth, 2).unwrap();
        let mut registered = DepthMeters::filled(color_camera.size, -1.0);
        registration.register_into(&depth, &mut registered).unwrap();
        let row = registered.row(60);
        let values: Vec<f32> = row.to_vec();
        let holes = values.iter().filter(|&&z| z == 0.0).count();
        // Parallax of the box against the wall: 131 px · 0.05 m · (1/0.5 − 1/3) m⁻¹ ≈ 10.9 px.
        assert!((9..=12).contains(&holes), "{holes} holes in {values:?}");
        assert!(values
            .iter()
            .all(|&z| z == 0.0 || (z - 0.5).abs() < 0.01 || (z - 3.0).abs() < 0.03));
        // The box keeps its depth where both see it.
        assert!(values.iter().filter(|&&z| (z - 0.5).abs() < 0.01).count() > 10);
    }

    #[test]
    fn parallel_registration_matches_the_reference_bit_for_bit() {
        let (depth_camera, color_camera, color_from_depth) = realsense_like();
        let depth = DepthMeters::from_fn(depth_camera.size, |u, v| {
            // Noisy steps, holes and NaN-free garbage values the kernel must skip.
            let base = 1.0 + ((u * 7 + v * 13) % 17) as f32 * 0.13;
            if (u + 3 * v) % 11 == 0 {
                0.0
            } else if (u * v) % 29 == 1 {
                -1.0
            } else {
                base
            }
        });
        let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let mut reference = DepthMeters::filled(color_camera.size, -2.0);
        for bands in [3, 1] {
            let mut registration =
                DepthRegistration::new(&depth_camera, &color_camera, &color_from_depth, bands).unwrap();
            assert_eq!(registration.bands.len(), bands);
            let mut fast = DepthMeters::filled(color_camera.size, -1.0);
            pool.install(|| registration.register_into(&depth, &mut fast))
                .unwrap();
            registration.register_reference(&depth, &mut reference).unwrap();
            assert_eq!(fast, reference, "{bands} bands");
            assert!(fast.as_slice().iter().any(|&z| z > 0.0));
        }
    }

    #[test]
    fn remaps_match_their_references_and_check_sizes() {
        let camera = CameraModel {
            size: ImageSize::new(96, 64),
            intrinsics: PinholeIntrinsics::new(80.0, 80.0, 47.5, 31.5),
            distortion: Some(presets::TUM_FR1),
        };
        let bilinear = undistortion_map(&camera, &inscribed_pinhole(&camera)).unwrap();
        let nearest = NearestMap::from_fn(camera.size, camera.size, |u, v| {
            Some((u * 0.9 + 3.0, v * 1.1 - 2.0))
        })
        .unwrap();
        let gray = GrayF32::from_fn(camera.size, |x, y| ((x * 3 + y * 5) % 23) as f32 / 23.0);
        let mut a = GrayF32::filled(camera.size, 0.0);
        let mut b = GrayF32::filled(camera.size, 1.0);
        bilinear.apply_into(&gray, &mut a).unwrap();
        bilinear.apply_serial(&gray, &mut b).unwrap();
        assert_eq!(a, b);
        let depth = DepthMeters::from_fn(camera.size, |x, y| (x + y) as f32 * 0.01);
        let mut c = DepthMeters::filled(camera.size, 5.0);
        let mut d = DepthMeters::filled(camera.size, 6.0);
        nearest.apply_into(&depth, &mut c).unwrap();
        nearest.apply_serial(&depth, &mut d).unwrap();
        assert_eq!(c, d);
        bilinear.apply_depth_into(&depth, &mut c).unwrap();
        bilinear.apply_depth_serial(&depth, &mut d).unwrap();
        assert_eq!(c, d);
        let wrong = GrayF32::filled(ImageSize::new(10, 10), 0.0);
        assert!(matches!(
            bilinear.apply_into(&wrong, &mut a),
            Err(Error::SizeMismatch { .. })
        ));
        assert!(BilinearMap::from_fn(ImageSize::new(1, 5), camera.size, |u, v| Some((u, v))).is_err());
    }

    #[test]
    fn undistorting_then_distorting_a_mask_returns_it() {
        // undistort ∘ distort ≈ identity on images: a blob mapped to the pinhole image and
        // back covers the same pixels, except a few outline pixels where the two
        // nearest-pixel roundings disagree.
        let camera = CameraModel {
            size: ImageSize::new(160, 120),
            intrinsics: PinholeIntrinsics::new(131.0, 131.0, 79.5, 59.5),
            distortion: Some(presets::TUM_FR1),
        };
        let pinhole = camera.intrinsics;
        let to_pinhole = NearestMap::from_fn(camera.size, camera.size, |u, v| {
            Some(camera.pixel((u - pinhole.cx) / pinhole.fx, (v - pinhole.cy) / pinhole.fy))
        })
        .unwrap();
        let back = distortion_map(&camera, &camera.undistorted()).unwrap();
        let blob = Image::from_fn(camera.size, |x, y| {
            let (dx, dy) = (x as f64 - 110.0, y as f64 - 30.0);
            u8::from(dx * dx + dy * dy < 400.0) * 255
        });
        let mut pinhole = Image::filled(camera.size, 0u8);
        let mut round_trip = Image::filled(camera.size, 0u8);
        to_pinhole.apply_into(&blob, &mut pinhole).unwrap();
        back.apply_into(&pinhole, &mut round_trip).unwrap();
        let set = blob.as_slice().iter().filter(|&&m| m != 0).count();
        let differ = blob
            .as_slice()
            .iter()
            .zip(round_trip.as_slice())
            .filter(|(a, b)| a != b)
            .count();
        assert!(set > 1000);
        // Measured: 8 of 1245 pixels; the bound allows 3×.
        assert!(differ * 50 < set, "{differ} of {set} pixels changed");
        // The distortion is not a no-op: the pinhole blob sits elsewhere.
        assert!(pinhole.as_slice() != blob.as_slice());
        assert!(back.covered_fraction() > 0.99);
    }

    #[test]
    fn whole_numbers_become_indices() {
        for i in [0usize, 1, 2, 639, 640, 1 << 22, (1 << 23) - 1] {
            assert_eq!(whole_to_index(i as f32), i);
        }
    }

    #[test]
    fn arithmetic_ceil_matches_ceil() {
        for x in [
            -2.5f32, -1.0, -0.3, -0.0, 0.0, 0.2, 0.5, 1.0, 1.0001, 2.5, 639.5, 639.99997, 1e6, 4194303.5,
        ] {
            assert_eq!(ceil_f32(x), x.ceil(), "{x}");
        }
        assert!(ceil_f32(f32::NAN).is_nan());
        assert!((ceil_f32(1e20) - 1e20).abs() <= 1e20 * 1e-6);
    }

    #[test]
    fn the_inscribed_pinhole_image_has_data_everywhere() {
        let camera = CameraModel {
            size: ImageSize::new(160, 120),
            intrinsics: PinholeIntrinsics::new(131.0, 131.0, 79.5, 59.5),
            distortion: Some(presets::TUM_FR1),
        };
        // With K, the corners lack data (the lens pushes them out by ≈ 4.5 px here).
        let same_k = undistortion_map(&camera, &camera.undistorted()).unwrap();
        assert!(same_k.covered_fraction() < 0.97, "{}", same_k.covered_fraction());
        let inscribed = inscribed_pinhole(&camera);
        let scale = inscribed.intrinsics.fx / camera.intrinsics.fx;
        assert!(scale > 1.0 && scale < 1.1, "{scale}");
        assert_eq!(inscribed.intrinsics.cx, camera.intrinsics.cx);
        assert!((inscribed.intrinsics.fy / camera.intrinsics.fy - scale).abs() < 1e-12);
        assert_eq!(
            undistortion_map(&camera, &inscribed).unwrap().covered_fraction(),
            1.0
        );
        // The smallest such scale: 1 % less leaves pixels without data.
        let smaller = CameraModel::pinhole(
            camera.size,
            PinholeIntrinsics::new(131.0 * (scale - 0.01), 131.0 * (scale - 0.01), 79.5, 59.5),
        );
        assert!(undistortion_map(&camera, &smaller).unwrap().covered_fraction() < 1.0);
        // Barrel distortion: the pinhole image with K lies inside the recorded one.
        let barrel = CameraModel {
            distortion: Some(LensDistortion::plumb_bob(-0.2, 0.0, 0.0, 0.0, 0.0)),
            ..camera
        };
        assert_eq!(inscribed_pinhole(&barrel), barrel.undistorted());
    }

    #[test]
    fn depth_is_interpolated_on_a_surface_but_never_across_an_edge() {
        let size = ImageSize::new(6, 4);
        // A slanted plane (2 % per pixel) left of x = 3, a surface 1 m behind it on the right,
        // and a hole at (1, 3).
        let depth = DepthMeters::from_fn(size, |x, y| match (x, y) {
            (1, 3) => 0.0,
            (x, _) if x < 3 => 2.0 * (1.0 + 0.02 * x as f32),
            _ => 3.0,
        });
        let half = BilinearMap::from_fn(size, size, |u, v| Some((u + 0.5, v + 0.25))).unwrap();
        let mut out = DepthMeters::filled(size, -1.0);
        half.apply_depth_into(&depth, &mut out).unwrap();
        // On the plane: interpolated, halfway between columns 0 and 1.
        assert!((out.get(0, 0) - 2.0 * 1.01).abs() < 1e-6, "{}", out.get(0, 0));
        // Straddling the edge (columns 2 and 3): one of the two depths, never between.
        let edge = out.get(2, 0);
        assert!(edge == depth.get(2, 0) || edge == 3.0, "{edge}");
        // Next to the hole: the nearest neighbour, not an average with 0.
        let near_hole = out.get(0, 2);
        assert!(near_hole == depth.get(1, 3) || near_hole == depth.get(0, 2) || near_hole == depth.get(1, 2));
        assert!(out.get(0, 2) == 0.0 || out.get(0, 2) >= 2.0);
    }

    #[test]
    fn bilinear_map_of_the_identity_copies_and_interpolates() {
        let size = ImageSize::new(8, 6);
        let gray = GrayF32::from_fn(size, |x, y| (x + 10 * y) as f32);
        let identity = BilinearMap::from_fn(size, size, |u, v| Some((u, v))).unwrap();
        let mut out = GrayF32::filled(size, 0.0);
        identity.apply_into(&gray, &mut out).unwrap();
        assert_eq!(out, gray);
        let shifted = BilinearMap::from_fn(size, size, |u, v| Some((u + 0.25, v + 0.5))).unwrap();
        shifted.apply_into(&gray, &mut out).unwrap();
        assert!((out.get(2, 2) - (2.25 + 25.0)).abs() < 1e-5);
        // Outside positions clamp to the border.
        assert_eq!(out.get(7, 5), gray.get(7, 5));
    }
}
