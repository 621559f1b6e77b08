//! Reference moving-object masks for real recordings without ground-truth masks, from
//! multi-view free-space checks with external (motion-capture) camera poses.
//!
//! A surface point seen at time i occupies its place at time i. If another view j, looking
//! along the ray through that place, measures a surface clearly *farther* away, the place was
//! empty at time j: the point was not there then, so it belongs to something that moves. A
//! static point is never seen through: other views find it at its depth, or something in front
//! of it. The check runs against views up to [`FreeSpaceConfig::max_offset_frames`] before and
//! after, with the external poses (not the odometry under test), so it is independent of the
//! method it is used to score.
//!
//! Per frame:
//! 1. every pixel with depth is projected into each other view j (every
//!    [`FreeSpaceConfig::offset_step_frames`]-th frame at least
//!    [`FreeSpaceConfig::min_offset_frames`] away); where j has depth there, the view counts as
//!    *tested*; it *sees through* the point when the nearest depth of j within
//!    [`FreeSpaceConfig::neighbourhood_px`] is farther than the point's depth in j plus the
//!    margin a + b·z (depth noise, calibration, depth-to-colour timing), and *agrees* when j's
//!    depth is within the margin;
//! 2. seeds: pixels seen through by ≥ `min_see_through` views making ≥ `min_see_through_ratio`
//!    of the views that see through or agree; opened by a (2r+1)² square and kept in components
//!    of ≥ `min_seed_pixels`;
//! 3. static pixels: agreed with by ≥ `min_static_agreements` views, seen through by at most
//!    `max_static_see_through_ratio` of them;
//! 4. the seeds grow over 8-neighbours that are not static and whose depth continues the
//!    region's (within `growth_step_fraction`·z + `growth_step_m` of the mean depth of their
//!    neighbours in the region), for at most `growth_iterations` rings: a moving body is seen
//!    through where it moved, not everywhere on it;
//! 5. components smaller than `min_component_pixels` are dropped.
//!
//! A person who stands still for the whole window is not moving by this definition; one who
//! moves at any time within the window is marked at every frame (the check looks forward and
//! back). docs/accuracy.md says how the reference for the Bonn "crowd" window was checked.

use nalgebra::Isometry3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, ImageSize, Mask, MASK_SET, NEIGHBOURS_8};
use crate::occlusion::runs::RunLabelling;

/// Parameters of [`free_space_reference`] (defaults: the reference used for the Bonn "crowd"
/// window, 640×480 at 30 Hz).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreeSpaceConfig {
    /// Views up to this many frames before and after are checked.
    pub max_offset_frames: usize,
    /// Views nearer than this are not used (too small a baseline to see through anything).
    pub min_offset_frames: usize,
    /// Every this many frames within the range.
    pub offset_step_frames: usize,
    /// Half-width of the square in which the nearest depth of the other view is taken.
    pub neighbourhood_px: usize,
    /// Constant part of the margin, metres.
    pub margin_m: f32,
    /// Depth-proportional part of the margin (m per m).
    pub margin_per_m: f32,
    /// Fewest views that see through a seed pixel.
    pub min_see_through: u16,
    /// Least fraction of see-through among see-through + agreeing views for a seed.
    pub min_see_through_ratio: f32,
    /// Half-width r of the opening of the seeds.
    pub seed_opening_px: usize,
    /// Smallest seed component kept (8-connected), pixels at 640×480 (scaled by area).
    pub min_seed_pixels: usize,
    /// Fewest agreeing views of a static pixel.
    pub min_static_agreements: u16,
    /// Largest see-through fraction of a static pixel.
    pub max_static_see_through_ratio: f32,
    /// Growth: relative depth step to the region.
    pub growth_step_fraction: f32,
    /// Growth: constant depth step, metres.
    pub growth_step_m: f32,
    /// Growth rings at most.
    pub growth_iterations: usize,
    /// Smallest final component (8-connected), pixels at 640×480 (scaled by area).
    pub min_component_pixels: usize,
}

impl Default for FreeSpaceConfig {
    fn default() -> Self {
        Self {
            max_offset_frames: 96,
            min_offset_frames: 4,
            offset_step_frames: 4,
            neighbourhood_px: 2,
            margin_m: 0.10,
            margin_per_m: 0.05,
            min_see_through: 3,
            min_see_through_ratio: 0.3,
            seed_opening_px: 2,
            min_seed_pixels: 150,
            min_static_agreements: 5,
            max_static_see_through_ratio: 0.05,
            growth_step_fraction: 0.03,
            growth_step_m: 0.02,
            growth_iterations: 60,
            min_component_pixels: 400,
        }
    }
}

/// One view of the sequence.
#[derive(Debug, Clone, Copy)]
pub struct FreeSpaceView<'a> {
    /// Depth (m, 0 = invalid).
    pub depth_m: &'a DepthMeters,
    /// The camera's pose when the depth was taken.
    pub world_from_camera: Isometry3<f64>,
}

/// The view counts of every pixel of one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Counts {
    see_through: u16,
    agree: u16,
}

/// Reference masks for every view (see the module docs).
///
/// # Errors
/// [`Error::SizeMismatch`] when the views differ in size, [`Error::InvalidParameter`] for an
/// empty sequence or a zero step.
pub fn free_space_reference(
    views: &[FreeSpaceView<'_>],
    intrinsics: &PinholeIntrinsics,
    config: &FreeSpaceConfig,
) -> Result<Vec<Mask>> {
    let Some(first) = views.first() else {
        return Err(Error::InvalidParameter {
            name: "views",
            value: "none".into(),
            expected: "at least one view".into(),
        });
    };
    if config.offset_step_frames == 0 {
        return Err(Error::InvalidParameter {
            name: "offset_step_frames",
            value: "0".into(),
            expected: "at least 1".into(),
        });
    }
    let size = first.depth_m.size();
    for v in views {
        if v.depth_m.size() != size {
            return Err(Error::SizeMismatch {
                what: "free-space reference views".into(),
                expected: size,
                found: v.depth_m.size(),
            });
        }
    }
    let nearest: Vec<DepthMeters> = views
        .par_iter()
        .map(|v| nearest_depth(v.depth_m, config.neighbourhood_px))
        .collect();
    let area_scale = size.area() as f64 / (640.0 * 480.0);
    let scaled = |px: usize| ((px as f64 * area_scale).round() as usize).max(1);
    let (min_seed, min_component) = (
        scaled(config.min_seed_pixels),
        scaled(config.min_component_pixels),
    );
    (0..views.len())
        .into_par_iter()
        .map(|i| {
            let counts = count_views(views, &nearest, i, intrinsics, config);
            let depth = views[i].depth_m;
            let mut mask = seeds(&counts, depth, config);
            open_square(&mut mask, size, config.seed_opening_px);
            drop_small_components(&mut mask, size, min_seed);
            grow(&mut mask, &counts, depth, config);
            drop_small_components(&mut mask, size, min_component);
            Mask::from_vec(
                size,
                mask.into_iter().map(|m| if m { MASK_SET } else { 0 }).collect(),
            )
        })
        .collect()
}

/// The nearest valid depth within a (2r+1)² square (0 where none), separably.
fn nearest_depth(depth: &DepthMeters, radius: usize) -> DepthMeters {
    let size = depth.size();
    let (w, h) = (size.width, size.height);
    let valid_or_inf = |z: f32| if z > 0.0 { z } else { f32::INFINITY };
    let mut rows = vec![f32::INFINITY; w * h];
    for y in 0..h {
        let row = depth.row(y);
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(radius), (x + radius).min(w - 1));
            rows[y * w + x] = row[x0..=x1]
                .iter()
                .fold(f32::INFINITY, |m, &z| m.min(valid_or_inf(z)));
        }
    }
    DepthMeters::from_fn(size, |x, y| {
        let (y0, y1) = (y.saturating_sub(radius), (y + radius).min(h - 1));
        let m = (y0..=y1).fold(f32::INFINITY, |m, yy| m.min(rows[yy * w + x]));
        if m.is_finite() {
            m
        } else {
            0.0
        }
    })
}

/// Step 1 for frame `i`.
fn count_views(
    views: &[FreeSpaceView<'_>],
    nearest: &[DepthMeters],
    i: usize,
    k: &PinholeIntrinsics,
    config: &FreeSpaceConfig,
) -> Vec<Counts> {
    let depth = views[i].depth_m;
    let size = depth.size();
    let (w, h) = (size.width, size.height);
    let mut counts = vec![Counts::default(); size.area()];
    let max = config.max_offset_frames as isize;
    let offsets = (-max..=max)
        .step_by(config.offset_step_frames)
        .filter(|k| k.unsigned_abs() >= config.min_offset_frames);
    for offset in offsets {
        let Some(j) = i.checked_add_signed(offset).filter(|&j| j < views.len()) else {
            continue;
        };
        let other_from_this = views[j].world_from_camera.inverse() * views[i].world_from_camera;
        let r = other_from_this
            .rotation
            .to_rotation_matrix()
            .into_inner()
            .cast::<f32>();
        let t = other_from_this.translation.vector.cast::<f32>();
        let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
        let (other, other_nearest) = (views[j].depth_m.as_slice(), nearest[j].as_slice());
        // The rotated ray of pixel (x, y) is R·((x − cx)/fx, (y − cy)/fy, 1): a column term plus
        // a row term.
        let column_terms: Vec<[f32; 3]> = (0..w)
            .map(|x| {
                let ray_x = (x as f32 - cx) / fx;
                [r[(0, 0)] * ray_x, r[(1, 0)] * ray_x, r[(2, 0)] * ray_x]
            })
            .collect();
        let (u_max, v_max) = (w as f32 - 0.5, h as f32 - 0.5);
        for y in 0..h {
            let ray_y = (y as f32 - cy) / fy;
            let row_term = [0, 1, 2].map(|a| r[(a, 1)] * ray_y + r[(a, 2)]);
            let depth_row = &depth.as_slice()[y * w..(y + 1) * w];
            let counts_row = &mut counts[y * w..(y + 1) * w];
            for ((&z, c), column) in depth_row.iter().zip(counts_row.iter_mut()).zip(&column_terms) {
                if z <= 0.0 {
                    continue;
                }
                let qx = z * (column[0] + row_term[0]) + t.x;
                let qy = z * (column[1] + row_term[1]) + t.y;
                let qz = z * (column[2] + row_term[2]) + t.z;
                if qz <= MIN_PROJECTED_DEPTH_M {
                    continue;
                }
                let inverse_z = 1.0 / qz;
                let u = fx * qx * inverse_z + cx;
                let v = fy * qy * inverse_z + cy;
                // Nearest pixel: u rounds into [0, w) exactly when −0.5 ≤ u < w − 0.5.
                if !(u >= -0.5 && v >= -0.5 && u < u_max && v < v_max) {
                    continue;
                }
                let at = (v + 0.5) as usize * w + (u + 0.5) as usize;
                let measured = other[at];
                if measured <= 0.0 {
                    continue;
                }
                let margin = config.margin_m + config.margin_per_m * qz;
                if other_nearest[at] > qz + margin {
                    c.see_through += 1;
                }
                if (measured - qz).abs() < margin {
                    c.agree += 1;
                }
            }
        }
    }
    counts
}

/// Points closer than this to the other camera are not projected.
const MIN_PROJECTED_DEPTH_M: f32 = 0.2;

/// Step 2's raw seeds.
fn seeds(counts: &[Counts], depth: &DepthMeters, config: &FreeSpaceConfig) -> Vec<bool> {
    counts
        .iter()
        .zip(depth.as_slice())
        .map(|(c, &z)| {
            let (s, a) = (f32::from(c.see_through), f32::from(c.agree));
            z > 0.0 && c.see_through >= config.min_see_through && s >= config.min_see_through_ratio * (s + a)
        })
        .collect()
}

/// Step 3.
fn is_static(c: &Counts, config: &FreeSpaceConfig) -> bool {
    let (s, a) = (f32::from(c.see_through), f32::from(c.agree));
    c.agree >= config.min_static_agreements && s <= config.max_static_see_through_ratio * (s + a)
}

/// Erosion then dilation by a (2r+1)² square (pixels outside the image count as unset).
fn open_square(mask: &mut Vec<bool>, size: ImageSize, radius: usize) {
    if radius == 0 {
        return;
    }
    let eroded = square_filter(mask, size, radius, true);
    *mask = square_filter(&eroded, size, radius, false);
}

/// AND (`all`) or OR of every (2r+1)² square, separably. With `all`, a square reaching
/// outside the image is unset.
fn square_filter(mask: &[bool], size: ImageSize, radius: usize, all: bool) -> Vec<bool> {
    let (w, h) = (size.width, size.height);
    let reduce = |range: std::ops::RangeInclusive<isize>, limit: usize, at: &dyn Fn(usize) -> bool| {
        let (start, end) = (*range.start(), *range.end());
        let clipped = start.max(0) as usize..=(end as usize).min(limit - 1);
        if all {
            start >= 0 && (end as usize) < limit && clipped.into_iter().all(at)
        } else {
            clipped.into_iter().any(at)
        }
    };
    let r = radius as isize;
    let mut rows = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let xi = x as isize;
            rows[y * w + x] = reduce(xi - r..=xi + r, w, &|xx| mask[y * w + xx]);
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let yi = y as isize;
            out[y * w + x] = reduce(yi - r..=yi + r, h, &|yy| rows[yy * w + x]);
        }
    }
    out
}

/// Removes 8-connected components smaller than `min_pixels` (the detector's run labelling).
fn drop_small_components(mask: &mut [bool], size: ImageSize, min_pixels: usize) {
    let set: Vec<u8> = mask.iter().map(|&m| u8::from(m)).collect();
    let mut labelling = RunLabelling::new(size.width, size.height);
    let components = labelling.label(&set, size.width, size.width, size.height, (0, 0));
    for k in (0..components).filter(|&k| labelling.pixels(k) < min_pixels) {
        for run in labelling.runs(k) {
            mask[run.pixels(size.width)].fill(false);
        }
    }
}

/// Step 4: synchronous rings (each ring decides from the region as it was before the ring),
/// visiting only the unset neighbours of the previous ring.
fn grow(mask: &mut [bool], counts: &[Counts], depth: &DepthMeters, config: &FreeSpaceConfig) {
    let size = depth.size();
    let (w, h) = (size.width, size.height);
    let z = depth.as_slice();
    let neighbours = |i: usize| {
        let (x, y) = ((i % w) as isize, (i / w) as isize);
        NEIGHBOURS_8.iter().filter_map(move |&(dx, dy)| {
            let (nx, ny) = (x + dx, y + dy);
            (nx >= 0 && ny >= 0 && nx < w as isize && ny < h as isize).then(|| ny as usize * w + nx as usize)
        })
    };
    let mut ring: Vec<usize> = (0..mask.len()).filter(|&i| mask[i]).collect();
    // The ring in which a pixel was last a candidate (so each is tested once per ring).
    let mut candidate_in = vec![usize::MAX; mask.len()];
    let (mut candidates, mut added) = (Vec::new(), Vec::new());
    for iteration in 0..config.growth_iterations {
        candidates.clear();
        for &f in &ring {
            for n in neighbours(f) {
                if !mask[n] && candidate_in[n] != iteration {
                    candidate_in[n] = iteration;
                    candidates.push(n);
                }
            }
        }
        added.clear();
        for &i in &candidates {
            if z[i] <= 0.0 || is_static(&counts[i], config) {
                continue;
            }
            let (mut sum, mut n) = (0.0f32, 0u32);
            for j in neighbours(i) {
                if mask[j] && z[j] > 0.0 {
                    sum += z[j];
                    n += 1;
                }
            }
            if n == 0 {
                continue;
            }
            let region = sum / n as f32;
            if (z[i] - region).abs() < config.growth_step_fraction * region + config.growth_step_m {
                added.push(i);
            }
        }
        if added.is_empty() {
            break;
        }
        for &i in &added {
            mask[i] = true;
        }
        std::mem::swap(&mut ring, &mut added);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::camera::presets;

    /// A wall at 3 m seen by a still camera; a 0.6 m wide slab at 1.5 m moves sideways by
    /// 5 cm per frame in front of it.
    fn sequence(frames: usize) -> (ImageSize, PinholeIntrinsics, Vec<DepthMeters>) {
        let size = ImageSize::new(160, 120);
        let k = presets::TUM_FR2.at_level(2);
        let mut depths = Vec::new();
        for f in 0..frames {
            let left_m = -1.0 + 0.05 * f as f64;
            let column = |x_m: f64| (k.fx * x_m / 1.5 + k.cx).round().max(0.0) as usize;
            let (c0, c1) = (column(left_m), column(left_m + 0.6));
            depths.push(DepthMeters::from_fn(size, |x, y| {
                if (c0..c1).contains(&x) && (20..100).contains(&y) {
                    1.5
                } else {
                    3.0
                }
            }));
        }
        (size, k, depths)
    }

    #[test]
    fn marks_the_moving_slab_and_nothing_static() {
        let (size, k, depths) = sequence(40);
        let views: Vec<_> = depths
            .iter()
            .map(|d| FreeSpaceView {
                depth_m: d,
                world_from_camera: Isometry3::identity(),
            })
            .collect();
        let config = FreeSpaceConfig {
            max_offset_frames: 20,
            ..FreeSpaceConfig::default()
        };
        let masks = free_space_reference(&views, &k, &config).unwrap();
        for (f, (mask, depth)) in masks.iter().zip(&depths).enumerate() {
            let (mut on_slab, mut slab, mut wall_marked) = (0, 0, 0);
            for y in 0..size.height {
                for x in 0..size.width {
                    let moving = mask.get(x, y) != 0;
                    if depth.get(x, y) < 2.0 {
                        slab += 1;
                        on_slab += usize::from(moving);
                    } else {
                        wall_marked += usize::from(moving);
                    }
                }
            }
            assert_eq!(wall_marked, 0, "frame {f}: static wall marked");
            // Where the slab is wholly in view (frames 2–26), 90 % of it is marked. (A sliver
            // at the border is thinner than the seeds' opening.)
            if (2..=26).contains(&f) {
                assert!(
                    on_slab * 10 >= slab * 9,
                    "frame {f}: {on_slab} of {slab} slab pixels"
                );
            }
        }
    }

    #[test]
    fn a_still_scene_has_an_empty_reference_even_with_camera_motion() {
        let size = ImageSize::new(160, 120);
        let k = presets::TUM_FR2.at_level(2);
        // A room corner: a slanted wall, seen from a camera moving 2 cm per frame sideways.
        let poses: Vec<Isometry3<f64>> = (0..30)
            .map(|f| Isometry3::translation(0.02 * f as f64, 0.0, 0.0))
            .collect();
        let depths: Vec<DepthMeters> = poses
            .iter()
            .map(|p| {
                let cx = p.translation.vector.x;
                DepthMeters::from_fn(size, |x, _| {
                    // The plane z = 2.5 + 0.3·X_world, seen from the camera at X = cx.
                    let ray = (x as f64 - k.cx) / k.fx;
                    ((2.5 + 0.3 * cx) / (1.0 - 0.3 * ray)) as f32
                })
            })
            .collect();
        let views: Vec<_> = depths
            .iter()
            .zip(&poses)
            .map(|(d, p)| FreeSpaceView {
                depth_m: d,
                world_from_camera: *p,
            })
            .collect();
        let masks = free_space_reference(&views, &k, &FreeSpaceConfig::default()).unwrap();
        assert!(masks.iter().all(|m| m.as_slice().iter().all(|&v| v == 0)));
    }
}
