//! Does a camera motion agree with the depth of two frames? A cheap check run before the
//! detector accumulates a frame: with the right motion, a true backward warp of the current depth
//! lands on the previous depth almost everywhere (only moving objects and their edges disagree);
//! with a wrong motion (a glitch in a ground-truth trajectory, a wrong DVO minimum) every depth
//! edge is misregistered, and occlusion accumulation would turn those misregistered edges into
//! static false positives that stay in A until they leave the view.

use nalgebra::{Isometry3, Point3};

use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, Mask};

/// Two depths agree when they differ by at most this fraction of the depth (Kinect v1 noise is
/// σ ≈ 1.4e-3·Z², i.e. 0.6 % of Z at 4 m: 2 % is more than 3σ up to the sensor's 4.5 m range).
const RELATIVE_TOLERANCE: f64 = 0.02;
/// ... and at least this much (m): disparity quantisation and rounding to the nearest pixel.
const MIN_TOLERANCE_M: f64 = 0.02;

/// What [`depth_consistency`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Consistency {
    /// Fraction of the compared samples whose depths agree.
    pub agreeing_fraction: f64,
    /// Samples compared (valid current depth, landing on a valid, unmasked previous depth).
    pub compared: usize,
    /// Samples taken (every `stride`-th row and column), compared or not.
    pub sampled: usize,
}

/// Fraction of the sampled current pixels (every `stride`-th row and column, valid depth) whose
/// true backward warp with `current_from_previous` lands inside the previous image on a valid
/// previous depth that agrees with the warped point's depth. Samples landing on a set pixel of
/// `previous_mask` (known moving objects) are not counted; the result also says how many samples
/// were compared. `None` when no sample lands on a valid previous depth (or the sizes differ).
pub fn depth_consistency(
    intrinsics: &PinholeIntrinsics,
    previous_depth_m: &DepthMeters,
    previous_mask: Option<&Mask>,
    current_depth_m: &DepthMeters,
    current_from_previous: &Isometry3<f64>,
    stride: usize,
) -> Option<Consistency> {
    let Warp {
        rotation,
        translation,
        width,
        height,
        stride,
    } = Warp::new(
        previous_depth_m,
        previous_mask,
        current_depth_m,
        current_from_previous,
        stride,
    )?;
    let (mut agreeing, mut compared) = (0usize, 0usize);
    for y in (0..height).step_by(stride) {
        let row = current_depth_m.row(y);
        for x in (0..width).step_by(stride) {
            let z = f64::from(row[x]);
            if z <= 0.0 {
                continue;
            }
            let q =
                Point3::from(rotation * intrinsics.back_project(x as f64, y as f64, z).coords + translation);
            let Some((u, v)) = nearest_pixel(intrinsics, &q, width, height) else {
                continue;
            };
            let z_previous = f64::from(previous_depth_m.row(v)[u]);
            if z_previous <= 0.0 || previous_mask.is_some_and(|m| m.row(v)[u] != 0) {
                continue;
            }
            compared += 1;
            let tolerance = (RELATIVE_TOLERANCE * q.z).max(MIN_TOLERANCE_M);
            agreeing += usize::from((z_previous - q.z).abs() <= tolerance);
        }
    }
    Consistency::from_counts(
        agreeing,
        compared,
        height.div_ceil(stride) * width.div_ceil(stride),
    )
}

/// [`depth_consistency`] of `current_from_previous` and of the identity (no motion) in one pass
/// over the samples, with the same results bit for bit (tested): `(motion, identity)`.
///
/// No motion needs no projection: the identity moves the back-projected point by exactly nothing
/// (the rotation matrix holds exact 1s and 0s), so the point's depth is the sample's own and its
/// projection rounds back to the sample's pixel (the round trip is off by ≈ 1e-12 px). The
/// motion's warp takes the per-column and per-row ray factors (x − cx)/fx and (y − cy)/fy from
/// tables (`column_rays`, `row_rays`: scratch, resized here) instead of dividing per sample; the
/// arithmetic is otherwise [`depth_consistency`]'s.
#[allow(clippy::too_many_arguments)]
pub fn depth_consistency_with_identity(
    intrinsics: &PinholeIntrinsics,
    previous_depth_m: &DepthMeters,
    previous_mask: Option<&Mask>,
    current_depth_m: &DepthMeters,
    current_from_previous: &Isometry3<f64>,
    stride: usize,
    column_rays: &mut Vec<f64>,
    row_rays: &mut Vec<f64>,
) -> (Option<Consistency>, Option<Consistency>) {
    let Some(Warp {
        rotation,
        translation,
        width,
        height,
        stride,
    }) = Warp::new(
        previous_depth_m,
        previous_mask,
        current_depth_m,
        current_from_previous,
        stride,
    )
    else {
        return (None, None);
    };
    column_rays.clear();
    column_rays.extend(
        (0..width)
            .step_by(stride)
            .map(|x| (x as f64 - intrinsics.cx) / intrinsics.fx),
    );
    row_rays.clear();
    row_rays.extend(
        (0..height)
            .step_by(stride)
            .map(|y| (y as f64 - intrinsics.cy) / intrinsics.fy),
    );
    let (max_x, max_y) = ((width - 1) as f64, (height - 1) as f64);
    let agree = |z_previous: f64, z: f64| {
        let tolerance = (RELATIVE_TOLERANCE * z).max(MIN_TOLERANCE_M);
        (z_previous - z).abs() <= tolerance
    };
    let (mut agreeing, mut compared) = (0usize, 0usize);
    let (mut agreeing_still, mut compared_still) = (0usize, 0usize);
    for (y, &ray_y) in (0..height).step_by(stride).zip(row_rays.iter()) {
        let row = current_depth_m.row(y);
        let previous_row = previous_depth_m.row(y);
        let mask_row = previous_mask.map(|m| m.row(y));
        for (x, &ray_x) in (0..width).step_by(stride).zip(column_rays.iter()) {
            let z = f64::from(row[x]);
            if z <= 0.0 {
                continue;
            }
            // No motion: the sample's own pixel (the warp of a non-finite depth is NaN, never
            // inside the image).
            let z_previous = f64::from(previous_row[x]);
            if z.is_finite() && z_previous > 0.0 && mask_row.is_none_or(|m| m[x] == 0) {
                compared_still += 1;
                agreeing_still += usize::from(agree(z_previous, z));
            }
            // The motion: `intrinsics.back_project(x, y, z)` with the tabulated factors.
            let point = nalgebra::Vector3::new(ray_x * z, ray_y * z, z);
            let q = rotation * point + translation;
            if q.z <= 0.0 {
                continue;
            }
            // `nearest_pixel`, i.e. `intrinsics.project` rounded.
            let u = (intrinsics.fx * q.x / q.z + intrinsics.cx).round();
            let v = (intrinsics.fy * q.y / q.z + intrinsics.cy).round();
            if !(u >= 0.0 && v >= 0.0 && u <= max_x && v <= max_y) {
                continue;
            }
            let (u, v) = (u as usize, v as usize);
            let z_previous = f64::from(previous_depth_m.row(v)[u]);
            if z_previous <= 0.0 || previous_mask.is_some_and(|m| m.row(v)[u] != 0) {
                continue;
            }
            compared += 1;
            agreeing += usize::from(agree(z_previous, q.z));
        }
    }
    let sampled = height.div_ceil(stride) * width.div_ceil(stride);
    (
        Consistency::from_counts(agreeing, compared, sampled),
        Consistency::from_counts(agreeing_still, compared_still, sampled),
    )
}

impl Consistency {
    /// `None` when nothing was compared.
    fn from_counts(agreeing: usize, compared: usize, sampled: usize) -> Option<Self> {
        (compared > 0).then(|| Consistency {
            agreeing_fraction: agreeing as f64 / compared as f64,
            compared,
            sampled,
        })
    }
}

/// The backward warp both checks share, and their size checks.
struct Warp {
    /// `previous_from_current` as a matrix: 9 multiply-adds per point instead of a quaternion
    /// product.
    rotation: nalgebra::Matrix3<f64>,
    translation: nalgebra::Vector3<f64>,
    width: usize,
    height: usize,
    /// At least 1.
    stride: usize,
}

impl Warp {
    /// `None` for empty images or when the previous depth or mask differs in size.
    fn new(
        previous_depth_m: &DepthMeters,
        previous_mask: Option<&Mask>,
        current_depth_m: &DepthMeters,
        current_from_previous: &Isometry3<f64>,
        stride: usize,
    ) -> Option<Self> {
        let (width, height) = (current_depth_m.width(), current_depth_m.height());
        let mask_size_differs = previous_mask.is_some_and(|m| m.size() != current_depth_m.size());
        if width == 0 || height == 0 || previous_depth_m.size() != current_depth_m.size() || mask_size_differs
        {
            return None;
        }
        let previous_from_current = current_from_previous.inverse();
        Some(Self {
            rotation: previous_from_current.rotation.to_rotation_matrix().into_inner(),
            translation: previous_from_current.translation.vector,
            width,
            height,
            stride: stride.max(1),
        })
    }
}

/// The pixel nearest to the projection of `point`, if it is in front of the camera and inside
/// [0, W−1] × [0, H−1].
fn nearest_pixel(
    intrinsics: &PinholeIntrinsics,
    point: &Point3<f64>,
    width: usize,
    height: usize,
) -> Option<(usize, usize)> {
    let p = intrinsics.project(point)?;
    let (u, v) = (p.x.round(), p.y.round());
    let inside = u >= 0.0 && v >= 0.0 && u <= (width - 1) as f64 && v <= (height - 1) as f64;
    inside.then_some((u as usize, v as usize))
}
