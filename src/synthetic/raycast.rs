//! The ray caster and sensor model behind [`super::SyntheticSequence`]: camera rays, box and
//! room intersection, procedural textures, the counter-based hash behind every random number,
//! and the Kinect-style depth noise. Kernels only; the scenes and their motion are the parent's.

use super::*;

/// Per-frame geometry of one box, expressed for rays given in the camera frame.
pub(super) struct BoxInCamera {
    /// object_from_camera rotation.
    pub(super) rotation: nalgebra::Matrix3<f64>,
    /// Camera centre in the object frame.
    pub(super) origin: Vector3<f64>,
    pub(super) half: Vector3<f64>,
    pub(super) moving: bool,
    /// Texture of each face, indexed by `2 · axis + (max side)`.
    pub(super) faces: [Surface; 6],
}

/// The camera-frame rays (x, y, 1) of a view's pixels and sub-pixel samples, computed once per
/// frame.
pub(super) enum Rays {
    /// A pinhole camera: the ray's x depends on the column only, y on the row only.
    Pinhole {
        /// (x − cx) / fx of each column.
        ray_x: Vec<f64>,
        /// (y − cy) / fy of each row.
        ray_y: Vec<f64>,
        intrinsics: PinholeIntrinsics,
    },
    /// A distorted camera: the undistorted ray of every pixel centre and every pixel corner
    /// ((width + 1) × (height + 1), corner (i, j) at pixel position (i − ½, j − ½)); sub-pixel
    /// rays interpolate the corners (the lens bends a ray by far less than a pixel's width
    /// within one pixel).
    Distorted {
        centres: Vec<Option<(f64, f64)>>,
        corners: Vec<Option<(f64, f64)>>,
        width: usize,
    },
}

impl Rays {
    pub(super) fn new(camera: &CameraModel) -> Self {
        let (w, h) = (camera.size.width, camera.size.height);
        let k = camera.intrinsics;
        if camera.distortion.is_none() {
            return Rays::Pinhole {
                ray_x: (0..w).map(|x| (x as f64 - k.cx) / k.fx).collect(),
                ray_y: (0..h).map(|y| (y as f64 - k.cy) / k.fy).collect(),
                intrinsics: k,
            };
        }
        let grid = |cols: usize, rows: usize, offset: f64| -> Vec<Option<(f64, f64)>> {
            (0..rows)
                .into_par_iter()
                .flat_map_iter(|y| (0..cols).map(move |x| (x, y)))
                .map(|(x, y)| camera.ray(x as f64 + offset, y as f64 + offset))
                .collect()
        };
        Rays::Distorted {
            centres: grid(w, h, 0.0),
            corners: grid(w + 1, h + 1, -0.5),
            width: w,
        }
    }

    /// The ray of pixel (x, y)'s centre.
    #[inline]
    pub(super) fn centre(&self, x: usize, y: usize) -> Option<(f64, f64)> {
        match self {
            Rays::Pinhole { ray_x, ray_y, .. } => Some((ray_x[x], ray_y[y])),
            Rays::Distorted { centres, width, .. } => centres[y * width + x],
        }
    }

    /// The ray through pixel position (x − ½ + s, y − ½ + t), s, t ∈ [0, 1].
    #[inline]
    pub(super) fn sample(&self, x: usize, y: usize, s: f64, t: f64) -> Option<(f64, f64)> {
        match self {
            Rays::Pinhole { intrinsics: k, .. } => {
                let (px, py) = (x as f64 - 0.5 + s, y as f64 - 0.5 + t);
                Some(((px - k.cx) / k.fx, (py - k.cy) / k.fy))
            }
            Rays::Distorted { corners, width, .. } => {
                let cw = width + 1;
                let at = |i: usize, j: usize| corners[j * cw + i];
                let (a, b, c, d) = (at(x, y)?, at(x + 1, y)?, at(x, y + 1)?, at(x + 1, y + 1)?);
                let lerp = |p: f64, q: f64, f: f64| p + (q - p) * f;
                let top = (lerp(a.0, b.0, s), lerp(a.1, b.1, s));
                let bottom = (lerp(c.0, d.0, s), lerp(c.1, d.1, s));
                Some((lerp(top.0, bottom.0, t), lerp(top.1, bottom.1, t)))
            }
        }
    }
}

pub(super) struct ViewSetup {
    pub(super) rays: Rays,
    pub(super) world_rotation: nalgebra::Matrix3<f64>,
    pub(super) world_origin: Vector3<f64>,
    pub(super) room: Room,
    /// Texture of each room face, indexed by `2 · axis + (max side)`.
    pub(super) room_faces: [Surface; 6],
    pub(super) boxes: Vec<BoxInCamera>,
}

/// The first surface hit by a ray.
pub(super) struct Hit<'a> {
    /// Depth along the optical axis (m).
    pub(super) depth_m: f64,
    /// Texture of the surface hit, and the texture coordinates (m) of the hit point.
    pub(super) surface: &'a Surface,
    pub(super) u_m: f64,
    pub(super) v_m: f64,
    pub(super) moving: bool,
    /// 1 + the box's index, 0 for the room ([`SyntheticFrame::object_index`]).
    pub(super) object: u8,
}

impl ViewSetup {
    /// Linear colour of pixel (x, y): the mean over an n × n grid of cells covering the pixel
    /// of one sample per cell at a position jittered by `jitter_key` (stratified sampling, an
    /// unbiased estimate of the pixel's integral whose error is noise, not the view-dependent
    /// moiré of a regular grid).
    pub(super) fn pixel_colour(&self, x: usize, y: usize, n: usize, jitter_key: u64) -> [f32; 3] {
        let step = 1.0 / n as f64;
        let mut sum = [0.0f32; 3];
        let mut samples = 0;
        for sy in 0..n {
            for sx in 0..n {
                let h = hash3(jitter_key, (sy * n + sx) as u64, 0x51);
                // Two independent 24-bit uniforms from one hash (`unit` reads bits 40..64).
                let (jx, jy) = (f64::from(unit(h)), f64::from(unit(h << 24)));
                let Some((ray_x, ray_y)) =
                    self.rays
                        .sample(x, y, (sx as f64 + jx) * step, (sy as f64 + jy) * step)
                else {
                    continue;
                };
                let hit = self.cast(ray_x, ray_y);
                let rgb = shade(hit.surface, hit.u_m, hit.v_m);
                for (s, c) in sum.iter_mut().zip(rgb) {
                    *s += c;
                }
                samples += 1;
            }
        }
        let inv = 1.0 / samples.max(1) as f32;
        sum.map(|s| s * inv)
    }

    /// Casts the camera ray (ray_x, ray_y, 1). Its z is 1, so the ray parameter is the depth.
    pub(super) fn cast(&self, ray_x: f64, ray_y: f64) -> Hit<'_> {
        let ray_in_camera = Vector3::new(ray_x, ray_y, 1.0);
        let mut best: Option<(f64, usize, usize, Vector3<f64>)> = None;
        for (index, b) in self.boxes.iter().enumerate() {
            let direction = b.rotation * ray_in_camera;
            if let Some((t, axis)) = slab_entry(&b.origin, &direction, &b.half) {
                if best.is_none_or(|(best_t, ..)| t < best_t) {
                    best = Some((t, index, axis, b.origin + direction * t));
                }
            }
        }
        if let Some((t, index, axis, point)) = best {
            let b = &self.boxes[index];
            let (u, v) = face_coordinates(&point, axis);
            let face = axis * 2 + usize::from(point[axis] > 0.0);
            return Hit {
                depth_m: t,
                surface: &b.faces[face],
                u_m: u,
                v_m: v,
                moving: b.moving,
                object: u8::try_from(index + 1).unwrap_or(u8::MAX),
            };
        }
        let direction = self.world_rotation * ray_in_camera;
        let (t, axis, positive) = slab_exit(&self.world_origin, &direction, &self.room);
        let point = self.world_origin + direction * t;
        let (u, v) = face_coordinates(&point, axis);
        Hit {
            depth_m: t,
            surface: &self.room_faces[axis * 2 + usize::from(positive)],
            u_m: u,
            v_m: v,
            moving: false,
            object: 0,
        }
    }
}

/// Entry parameter and axis of a ray into the centred box `[−half, half]`; `None` when the ray
/// misses it or starts inside it.
pub(super) fn slab_entry(
    origin: &Vector3<f64>,
    direction: &Vector3<f64>,
    half: &Vector3<f64>,
) -> Option<(f64, usize)> {
    let mut t_enter = f64::NEG_INFINITY;
    let mut t_leave = f64::INFINITY;
    let mut axis_enter = 0;
    for axis in 0..3 {
        let (o, d, h) = (origin[axis], direction[axis], half[axis]);
        if d.abs() < 1e-12 {
            if o.abs() > h {
                return None;
            }
            continue;
        }
        let (t1, t2) = ((-h - o) / d, (h - o) / d);
        let (near, far) = if t1 < t2 { (t1, t2) } else { (t2, t1) };
        if near > t_enter {
            t_enter = near;
            axis_enter = axis;
        }
        t_leave = t_leave.min(far);
    }
    (t_enter <= t_leave && t_enter > 1e-9).then_some((t_enter, axis_enter))
}

/// Exit parameter, axis and side (true = max face) of a ray leaving the room from inside.
pub(super) fn slab_exit(origin: &Vector3<f64>, direction: &Vector3<f64>, room: &Room) -> (f64, usize, bool) {
    let mut best = (f64::INFINITY, 0, false);
    for axis in 0..3 {
        let d = direction[axis];
        if d.abs() < 1e-12 {
            continue;
        }
        let positive = d > 0.0;
        let plane = if positive {
            room.max_m[axis]
        } else {
            room.min_m[axis]
        };
        let t = (plane - origin[axis]) / d;
        if t < best.0 {
            best = (t, axis, positive);
        }
    }
    best
}

pub(super) fn face_coordinates(point: &Vector3<f64>, axis: usize) -> (f64, f64) {
    match axis {
        0 => (point.z, point.y),
        1 => (point.x, point.z),
        _ => (point.x, point.y),
    }
}

/// Feature sizes of the texture octaves (m) and their weights: coarse blotches for large-scale
/// structure, fine detail (≈ 5 px at 4.5 m for VGA) so DVO has gradients at every pyramid level.
pub(super) const TEXTURE_OCTAVES: [(f64, f32); 3] = [(0.45, 0.4), (0.15, 0.35), (0.05, 0.25)];
/// Contrast gain applied around mid-gray (value noise sums are concentrated near 0.5).
pub(super) const TEXTURE_CONTRAST: f32 = 2.2;

/// Texture of one flat surface (a room or box face), hashed once per frame instead of per
/// pixel: per-octave lattice seeds and the colour tint.
pub(super) struct Surface {
    pub(super) octave_seeds: [u64; TEXTURE_OCTAVES.len()],
    pub(super) tint: [f32; 3],
}

impl Surface {
    pub(super) fn new(seed: u64) -> Self {
        Self {
            octave_seeds: std::array::from_fn(|octave| seed.wrapping_add(octave as u64)),
            tint: surface_tint(seed),
        }
    }
}

/// Colour of a surface point with texture coordinates (u, v) in metres.
pub(super) fn shade(surface: &Surface, u: f64, v: f64) -> [f32; 3] {
    let mut intensity = 0.0;
    for (&seed, &(scale_m, weight)) in surface.octave_seeds.iter().zip(&TEXTURE_OCTAVES) {
        intensity += weight * value_noise(seed, u / scale_m, v / scale_m);
    }
    let intensity = (0.5 + TEXTURE_CONTRAST * (intensity - 0.5)).clamp(0.03, 0.97);
    let tint = surface.tint;
    [intensity * tint[0], intensity * tint[1], intensity * tint[2]]
}

/// Per-surface colour tint in [0.55, 1] per channel (one hash for all three channels).
pub(super) fn surface_tint(seed: u64) -> [f32; 3] {
    let h = hash3(seed, 1, 0);
    let channel = |i: u32| 0.55 + 0.45 * ((h >> (16 * i)) & 0xffff) as f32 / 65535.0;
    [channel(0), channel(1), channel(2)]
}

/// Smooth value noise in [0, 1] on the integer lattice (smoothstep interpolation).
pub(super) fn value_noise(seed: u64, u: f64, v: f64) -> f32 {
    // `floor` is a libm call on baseline x86-64; truncate and correct for negatives instead.
    let floor = |t: f64| {
        let i = t as i64;
        if (i as f64) > t {
            i - 1
        } else {
            i
        }
    };
    let (iu, iv) = (floor(u), floor(v));
    let (fu, fv) = (iu as f64, iv as f64);
    let (iu, iv) = (iu as u64, iv as u64);
    let (su, sv) = ((u - fu) as f32, (v - fv) as f32);
    let (su, sv) = (su * su * (3.0 - 2.0 * su), sv * sv * (3.0 - 2.0 * sv));
    let corner = |du: u64, dv: u64| unit(hash3(seed, iu.wrapping_add(du), iv.wrapping_add(dv)));
    let top = corner(0, 0) + (corner(1, 0) - corner(0, 0)) * su;
    let bottom = corner(0, 1) + (corner(1, 1) - corner(0, 1)) * su;
    top + (bottom - top) * sv
}

/// SplitMix64 finaliser: a well-mixed 64-bit hash.
pub(super) fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of three words: one SplitMix64 round over odd-multiplier products (distinct large odd
/// constants keep (a, b, c) permutations apart). One round is enough for texture and noise
/// and keeps the render at a few ms per VGA frame.
pub(super) fn hash3(a: u64, b: u64, c: u64) -> u64 {
    mix64(
        a.wrapping_mul(0xd6e8_feb8_6659_fd93)
            ^ b.wrapping_mul(0xa076_1d64_78bd_642f)
            ^ c.wrapping_mul(0xe703_7ed1_a0b4_28db),
    )
}

/// Uniform in [0, 1) from a hash.
pub(super) fn unit(h: u64) -> f32 {
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Approximately standard-normal sample keyed by (seed, key): the Irwin–Hall sum of four
/// 16-bit uniforms from one hash, rescaled to unit variance (exact mean and variance, tails cut
/// at ±3.46σ; 5× cheaper than Box–Muller, which dominated the render time).
pub(super) fn gaussian(seed: u64, key: u64) -> f32 {
    let h = hash3(seed, key, 0x6a55);
    let sum: u32 = (0..4).map(|i| ((h >> (16 * i)) & 0xffff) as u32).sum();
    // Each uniform is (k + 0.5) / 65536: mean 0.5, variance 1/12 (to 1e-9).
    let centred = (sum as f32 + 2.0) / 65536.0 - 2.0;
    centred * 3.0f32.sqrt()
}

/// Applies the sensor model to the true depth: edge and border invalidation, range limits,
/// random dropout, noise, disparity quantisation and 1/5000 m storage quantisation.
pub(super) fn apply_sensor_model(
    sensor: &DepthSensorModel,
    fx: f32,
    noise_seed: u64,
    depth_true_m: &DepthMeters,
    depth_raw: &mut Image<u16>,
    depth_m: &mut DepthMeters,
) {
    let size = depth_true_m.size();
    let (width, height) = (size.width, size.height);
    let focal_baseline = fx * sensor.baseline_m;
    depth_raw
        .as_mut_slice()
        .par_chunks_mut(ROWS_PER_TASK * width)
        .zip(depth_m.as_mut_slice().par_chunks_mut(ROWS_PER_TASK * width))
        .enumerate()
        .for_each(|(chunk, (raw_rows, depth_rows))| {
            let rows = raw_rows
                .chunks_exact_mut(width)
                .zip(depth_rows.chunks_exact_mut(width));
            for (row, (raw_row, depth_row)) in rows.enumerate() {
                let y = chunk * ROWS_PER_TASK + row;
                let true_row = depth_true_m.row(y);
                let above = (y > 0).then(|| depth_true_m.row(y - 1));
                let below = (y + 1 < height).then(|| depth_true_m.row(y + 1));
                for x in 0..width {
                    let z = true_row[x];
                    let border = sensor.border_px;
                    let on_border = x < border || y < border || x + border >= width || y + border >= height;
                    // Only the far side of a depth edge loses its measurement (the projector's
                    // shadow on the background); the near surface's edge pixels stay measured.
                    let jump = |other: f32| z - other > sensor.edge_jump_m;
                    let edge = (x > 0 && jump(true_row[x - 1]))
                        || (x + 1 < width && jump(true_row[x + 1]))
                        || above.is_some_and(|r| jump(r[x]))
                        || below.is_some_and(|r| jump(r[x]));
                    let pixel_key = (y * width + x) as u64;
                    let dropped = sensor.dropout_probability > 0.0
                        && unit(hash3(noise_seed, pixel_key, 0xd409)) < sensor.dropout_probability;
                    if on_border || edge || dropped || z < sensor.min_depth_m || z > sensor.max_depth_m {
                        raw_row[x] = 0;
                        depth_row[x] = 0.0;
                        continue;
                    }
                    let mut measured = z + sensor.noise_coeff_per_m * z * z * gaussian(noise_seed, pixel_key);
                    if sensor.disparity_step_px > 0.0 && measured > 0.0 {
                        let disparity = focal_baseline / measured;
                        let quantised =
                            (disparity / sensor.disparity_step_px).round() * sensor.disparity_step_px;
                        measured = if quantised > 0.0 {
                            focal_baseline / quantised
                        } else {
                            0.0
                        };
                    }
                    let units = (measured * DEPTH_UNITS_PER_M + 0.5).floor();
                    let raw = if (1.0..=u16::MAX as f32).contains(&units) {
                        units as u16
                    } else {
                        0
                    };
                    raw_row[x] = raw;
                    depth_row[x] = raw as f32 / DEPTH_UNITS_PER_M;
                }
            }
        });
}
