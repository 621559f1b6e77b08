//! Whether a recording's colour is registered to its depth, measured from its frames.
//!
//! Where colour and depth come from one registered sensor (TUM, Bonn, the synthetic scenes) the
//! gray image's edges lie on the depth image's edges; where the colour camera's image was not
//! mapped onto the depth camera's (7-Scenes) they lie a few pixels beside them, by an offset that
//! changes over the image. The profile here is the mean gray gradient across the depth edges,
//! sampled at the edge and at pixels shifted along the gradient; registered colour has its peak
//! at the edge.

use crate::image_buf::{DepthMeters, GrayF32};

/// A depth edge: the depths either side of a pixel (two pixels apart) differ by more than this
/// fraction of the nearer one (10 %: a table's edge against the floor behind it, not the
/// sensor's noise on a slanted wall, about 1 % of the depth at 3 m).
pub const DEPTH_EDGE_RELATIVE_JUMP: f32 = 0.1;
/// The profile's shifts, −this..=this pixels along the edge's gradient.
pub const MAX_SHIFT_PX: usize = 8;
/// Shifts up to this many pixels count as "at the edge": registered sensors put the gray edge
/// within a few pixels of the depth edge (measured: TUM fr2_desk peaks 2–3 px off, Bonn within
/// 1 px), and the peak is a few pixels wide (the depth edge's fattening, the colour's blur).
pub const NEAR_SHIFT_PX: usize = 3;
/// Shifts from this many pixels on are "beside the edge": the gray gradient of the surfaces
/// either side.
pub const FAR_SHIFT_PX: usize = 6;
/// Fewer depth-edge pixels than this give no profile (a frame facing a wall).
pub const MIN_EDGE_PIXELS: usize = 500;

/// Shifts in the profile.
pub const PROFILE_LEN: usize = 2 * MAX_SHIFT_PX + 1;

/// Mean gray gradient across the depth edges at each shift −[`MAX_SHIFT_PX`]..=[`MAX_SHIFT_PX`]
/// (index `MAX_SHIFT_PX` is the edge itself), and the number of edge pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationProfile {
    /// Mean |gray(p + d + 1) − gray(p + d − 1)| along the edge's axis, per shift d.
    pub gradient: [f32; PROFILE_LEN],
    /// Depth-edge pixels measured.
    pub edge_pixels: usize,
}

impl RegistrationProfile {
    /// The profile of one frame, `None` where it has too few depth edges
    /// ([`MIN_EDGE_PIXELS`]) or the sizes differ.
    pub fn measure(gray: &GrayF32, depth_m: &DepthMeters) -> Option<Self> {
        Self::measure_with_floor(gray, depth_m, MIN_EDGE_PIXELS)
    }

    fn measure_with_floor(gray: &GrayF32, depth_m: &DepthMeters, min_edge_pixels: usize) -> Option<Self> {
        if gray.size() != depth_m.size() {
            return None;
        }
        let (w, h) = (gray.width(), gray.height());
        let margin = MAX_SHIFT_PX + 1;
        if w <= 2 * margin || h <= 2 * margin {
            return None;
        }
        let (g, z) = (gray.as_slice(), depth_m.as_slice());
        let mut sums = [0f64; PROFILE_LEN];
        let mut edge_pixels = 0usize;
        let is_edge = |a: f32, b: f32| {
            let near = a.min(b);
            near > 0.0 && a.is_finite() && b.is_finite() && (a - b).abs() > DEPTH_EDGE_RELATIVE_JUMP * near
        };
        for y in margin..h - margin {
            for x in margin..w - margin {
                let i = y * w + x;
                // Along x, then along y (a pixel on a corner counts for both).
                for step in [1, w] {
                    if !is_edge(z[i - step], z[i + step]) {
                        continue;
                    }
                    edge_pixels += 1;
                    for (k, sum) in sums.iter_mut().enumerate() {
                        let c = (i + k * step) - MAX_SHIFT_PX * step;
                        *sum += f64::from((g[c + step] - g[c - step]).abs());
                    }
                }
            }
        }
        (edge_pixels >= min_edge_pixels.max(1)).then(|| Self {
            gradient: sums.map(|s| (s / edge_pixels as f64) as f32),
            edge_pixels,
        })
    }

    /// The peak at the edge (largest mean over shifts up to [`NEAR_SHIFT_PX`]) over the level
    /// beside it (the mean over shifts from [`FAR_SHIFT_PX`] on): well above 1 where the gray
    /// edges lie on the depth edges, about 1 where they do not.
    pub fn score(&self) -> f32 {
        let mut near = 0f32;
        let (mut far, mut n) = (0f32, 0usize);
        for (k, &v) in self.gradient.iter().enumerate() {
            let shift = k.abs_diff(MAX_SHIFT_PX);
            if shift <= NEAR_SHIFT_PX {
                near = near.max(v);
            } else if shift >= FAR_SHIFT_PX {
                far += v;
                n += 1;
            }
        }
        if far > 0.0 {
            near * n as f32 / far
        } else {
            f32::INFINITY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_buf::ImageSize;

    const SIZE: ImageSize = ImageSize::new(64, 48);

    /// A box at 1 m in front of a wall at 2 m, and gray with the box's edges `offset_px` right
    /// of and below the depth's.
    fn scene(offset_px: usize) -> (GrayF32, DepthMeters) {
        let inside = |x: usize, y: usize| (20..44).contains(&x) && (14..34).contains(&y);
        let depth = DepthMeters::from_fn(SIZE, |x, y| if inside(x, y) { 1.0 } else { 2.0 });
        let gray = GrayF32::from_fn(SIZE, |x, y| {
            if x >= offset_px && y >= offset_px && inside(x - offset_px, y - offset_px) {
                0.8
            } else {
                0.2
            }
        });
        (gray, depth)
    }

    #[test]
    fn registered_colour_peaks_at_the_depth_edges_and_shifted_colour_does_not() {
        let (gray, depth) = scene(0);
        // The test scene has fewer edges than a real frame needs.
        assert!(RegistrationProfile::measure(&gray, &depth).is_none());
        let measure = |offset| {
            let (gray, depth) = scene(offset);
            RegistrationProfile::measure_with_floor(&gray, &depth, 1)
                .expect("edges")
                .score()
        };
        assert!(measure(0) > 1.5, "registered {}", measure(0));
        assert!(measure(6) < 1.0, "shifted {}", measure(6));
    }
}
