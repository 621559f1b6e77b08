//! [`DepthRegistration`]: depth from another camera moved into the colour camera by
//! z-buffered reprojection (see the parent module's documentation).

use super::*;

/// Depth nearer than this in the colour camera is not registered (m): no RGB-D sensor
/// measures closer than a few centimetres, and the projection divides by it.
pub(super) const MIN_REGISTERED_DEPTH_M: f32 = 0.01;
/// Each depth pixel's footprint is widened by this much on every side (colour pixels): the
/// footprints of neighbouring depth pixels share their edges only up to the parallax of the
/// cameras' baseline over their depth difference (≈ 0.02 px for 15 mm at 2 m and 1 cm steps),
/// so without a margin a colour pixel centre on a shared edge could fall between them.
pub(super) const SPLAT_MARGIN_PX: f32 = 0.05;
/// Largest half-size of a footprint (colour pixels): a depth pixel of a 320×240 sensor seen by
/// a 1280×720 colour camera covers ≈ 4 px; larger footprints only come from grazing surfaces
/// and rays almost parallel to the image plane, which are cut to this.
pub(super) const MAX_SPLAT_HALF_PX: f32 = 8.0;
/// Z-buffers of [`DepthRegistration`] are merged from at most this many bands of depth rows
/// (one per thread): each band costs a colour-sized buffer to clear and merge per frame.
pub(super) const MAX_REGISTRATION_BANDS: usize = 4;

/// The precomputed geometry of every depth pixel, one array per quantity (row-major, so a
/// row's projection is a loop over plain slices that the compiler vectorises): its ray
/// rotated into the colour camera (`R · (x, y, 1)` for the undistorted normalised ray (x, y)),
/// and the half-size of its footprint in colour pixels for points at infinity. `ray_z` is NaN
/// for pixels whose ray cannot be computed.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct RayTable {
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
pub(super) struct RowFootprints {
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
    pub(super) bands: Vec<(Vec<f32>, RowFootprints)>,
}

impl DepthRegistration {
    /// The tables for registering images of `depth_camera` (with its distortion) into the
    /// pinhole `color_camera` (its distortion is ignored: registration produces depth for the
    /// undistorted colour image), `color_from_depth` placing the depth camera in the colour
    /// camera's frame.
    ///
    /// `threads` bands of depth rows are splatted in parallel (at most
    /// `MAX_REGISTRATION_BANDS`); with 1, [`Self::register_into`] runs on the calling thread
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
pub(super) fn splat_row(footprints: &RowFootprints, zbuffer: &mut [f32], width: usize) {
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
pub(super) fn whole_to_index(x: f32) -> usize {
    const TWO_POW_23: f32 = 8_388_608.0;
    const MANTISSA: u32 = (1 << 23) - 1;
    ((x + TWO_POW_23).to_bits() & MANTISSA) as usize
}

/// Largest image side [`DepthRegistration`] accepts: [`ceil_f32`] is exact below 2^22.
pub(super) const MAX_EXACT_SIDE: usize = 1 << 22;

/// `x.ceil()` in plain f32 arithmetic, exact for |x| < 2^22 (larger values come out within 1
/// of x, beyond any image, and the caller clamps them). `ceil` itself is a libm call on
/// baseline x86-64 (no SSE4.1 rounding) and float-to-int casts saturate with extra code:
/// either kept the projection loop from vectorising, and the clamped cast took 30 % of the
/// registration's time (`benches/registration.rs`, perf).
#[inline(always)]
pub(super) fn ceil_f32(x: f32) -> f32 {
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
pub(super) struct Projection {
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
