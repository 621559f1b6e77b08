//! Robust dense visual odometry (DVO) between consecutive RGB-D frames that ignores masked
//! (moving) pixels of the reference frame: the "Robust DVO" of Kim, Kim & Kim (ICRA 2020)
//! without the authors' release's bugs (docs/method.md, "Dense visual odometry").
//!
//! - Cost: Σ ρ_{k_I}(r_I) + γ·Σ ρ_{k_Z}(r_Z) over reference pixels with valid depth that are not
//!   ignored; r_I photometric, r_Z = Z_cur(w) − z′ against the transformed depth; ρ bi-square
//!   (paper Eq. 11–13). See `residuals.rs` for the residuals and Jacobians.
//! - Solver: IRLS inside a true Levenberg–Marquardt with accept/revert on the robust cost,
//!   coarse to fine over an image pyramid ([`crate::pyramid`]), see `solver.rs`.
//! - Motion convention (crate-wide, [`crate::geometry`]): the estimate is
//!   `current_from_reference`, mapping reference-camera points into the current camera;
//!   chain it into poses with [`crate::trajectory::chain`].
//!
//! Use [`DvoTracker`] per sequence (it keeps the previous frame as the reference and allocates
//! its pyramids and scratch once; `track` still allocates now and then, as
//! `tests/detector_alloc.rs` notes), or [`DvoEstimator`] on two explicitly built pyramids.
//!
//! # Example
//! ```
//! use occmask::dvo::{DvoConfig, DvoTracker};
//! use occmask::geometry::{se3_exp, Twist};
//! use occmask::image_buf::ImageSize;
//! use occmask::synthetic::{motion_pair, SequenceConfig};
//!
//! let config = SequenceConfig { size: ImageSize::new(320, 240), ..SequenceConfig::default() };
//! let truth = se3_exp(&Twist::new(0.01, 0.0, 0.0, 0.0, 0.0, 0.0)); // 1 cm to the right
//! let (reference, current) = motion_pair(config, &truth, false);
//! let mut tracker = DvoTracker::new(config.size, reference.intrinsics, DvoConfig::paper())?;
//! assert!(tracker.track(&reference.gray, &reference.depth_m, None, None)?.is_none()); // first frame
//! let estimate = tracker.track(&current.gray, &current.depth_m, None, None)?.expect("second frame");
//! assert!(estimate.is_converged());
//! let error = estimate.current_from_reference.inverse() * truth;
//! assert!(error.translation.vector.norm() < 0.003); // metres
//! # Ok::<(), occmask::Error>(())
//! ```

// Kernels are crate-private. The DVO benchmark and the profiling example time the normal
// equations and the LM solve on their own: they reach them through `bench_api`, which is not
// part of the documented API.
pub(crate) mod completion;
mod config;
pub(crate) mod mask;
pub(crate) mod residuals;
pub(crate) mod solver;
pub(crate) mod weights;

pub use residuals::{CostParams, ReferencePoint};
pub use solver::LevelStop;

/// The DVO kernels for benchmarks and profiling tools (`benches/dvo.rs`,
/// `examples/pipeline_profile.rs`), which time one level's normal equations and LM solve on
/// their own. Not a stable API: it follows the kernels' signatures.
#[doc(hidden)]
pub mod bench_api {
    pub use super::residuals::{
        accumulate_normal_equations, accumulate_normal_equations_scalar, NormalEquations, TargetView,
    };
    pub use super::solver::{damped_step, optimize_level, LevelError, LevelResult, LmSchedule, MotionPrior};
}

pub use completion::{IgnoreCompletion, IgnoreCompletionConfig};
pub use config::{
    DvoConfig, IntensityThreshold, KeyframeConfig, MotionPriorConfig, CLOSED_LOOP_DEPTH_WEIGHT,
    CLOSED_LOOP_K_DEPTH_M, DEFAULT_KEYFRAME_MAX_FRAMES, DEFAULT_KEYFRAME_MAX_MOVING_FRACTION,
    DEFAULT_KEYFRAME_MAX_ROTATION_RAD, DEFAULT_KEYFRAME_MAX_TRANSLATION_M,
    DEFAULT_KEYFRAME_MIN_USED_FRACTION, DEFAULT_LEVELS, DEFAULT_PRIOR_FULL_WEIGHT_IGNORED_FRACTION,
    DEFAULT_PRIOR_ROTATION_SIGMA_RAD, DEFAULT_PRIOR_TRANSLATION_SIGMA_M, DEFAULT_PRIOR_WEIGHT,
    LM_LAMBDA_INITIAL, MAX_DVO_LEVELS, MAX_FINAL_COST_FRACTION, MIN_GRADIENT_PER_PX, STEP_TOLERANCE,
};

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::se3::is_finite_pose;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Mask};
use crate::pyramid::{level_size, ImagePyramid, TargetSample};
use crate::simd::{simd_kernel, Simd};
use residuals::TargetView;
use solver::{LevelError, LmSchedule};

/// Why an estimate failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DvoFailure {
    /// Too few reference pixels were usable on the finest level (no depth, everything
    /// masked, out of view, or all residuals beyond the robust thresholds).
    TooFewPixels {
        /// Usable pixels found.
        found: usize,
        /// Pixels required ([`DvoConfig::min_usable_pixels`]).
        required: usize,
    },
    /// Some motion direction is unconstrained (textureless or planar scene) on `level`.
    Degenerate {
        /// The pyramid level.
        level: usize,
    },
    /// A step or the cost became non-finite on `level`.
    NonFinite {
        /// The pyramid level.
        level: usize,
    },
    /// The solver ended far from any pose that explains the images: the final robust cost per
    /// point is `cost_permille` ‰ of the saturated loss (a point that matches nowhere), above
    /// the limit [`DvoConfig::max_final_cost_fraction`] (`limit_permille` ‰). Typically a wrong
    /// local minimum (motion too large for the coarsest level, a moving object not masked).
    PoorFit {
        /// Final cost per point, ‰ of the saturated loss.
        cost_permille: u32,
        /// The configured limit, ‰.
        limit_permille: u32,
    },
}

/// Outcome of an estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DvoStatus {
    /// A usable motion estimate.
    Converged,
    /// No usable estimate: [`DvoEstimate::current_from_reference`] is the initial guess.
    Failed(DvoFailure),
}

/// The motion between a reference and a current frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvoEstimate {
    /// Maps reference-camera points into the current camera (finite even on failure: then it
    /// is the initial guess).
    pub current_from_reference: Isometry3<f64>,
    /// Whether the estimate is usable.
    pub status: DvoStatus,
    /// LM candidate evaluations on each pyramid level (index = level, 0 = full resolution;
    /// 0 for levels not run).
    pub iterations_per_level: [u32; MAX_DVO_LEVELS],
    /// Why each level ended (`None` = not run or skipped for too few pixels).
    pub stop_per_level: [Option<LevelStop>; MAX_DVO_LEVELS],
    /// Robust cost per reference point at the final pose on the finest level.
    pub final_cost: f64,
    /// Reference points with a non-zero robust weight at the final pose on the finest level.
    pub pixels_used: usize,
    /// Reference points (valid depth, not ignored) on the finest level.
    pub reference_pixels: usize,
}

impl DvoEstimate {
    /// True for [`DvoStatus::Converged`].
    pub fn is_converged(&self) -> bool {
        self.status == DvoStatus::Converged
    }

    /// Total LM iterations over all levels.
    pub fn total_iterations(&self) -> u32 {
        self.iterations_per_level.iter().sum()
    }
}

/// Preallocated scratch for estimating the motion between two [`ImagePyramid`]s: reference
/// point lists and ignore masks per level.
#[derive(Debug, Clone)]
pub struct DvoEstimator {
    config: DvoConfig,
    size: ImageSize,
    /// Reference points per level (empty below the finest level).
    points: Vec<Vec<ReferencePoint>>,
    /// Ignore mask per level, 0/1 (level 0 only allocated when it is used).
    ignore: Vec<Vec<u8>>,
    column_scratch: Vec<u32>,
    /// Scratch of [`push_row_points`]: one row's kept flags.
    row_keep: Vec<u8>,
    /// The build of the row selection that runs (the widest the CPU has).
    simd: Simd,
    /// Of the finest level's usable reference pixels, the fraction the ignore mask removed
    /// (set by [`Self::prepare_reference`]).
    ignored_fraction: f64,
}

impl DvoEstimator {
    /// Allocates scratch for images of `size`. The stored config ([`Self::config`]) has
    /// `levels` reduced to [`DvoConfig::levels_for`] `size`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an invalid config or a size too small for its levels.
    pub fn new(size: ImageSize, config: DvoConfig) -> Result<Self> {
        config.validate()?;
        let config = DvoConfig {
            levels: config.levels_for(size).max(config.finest_level + 1),
            ..config
        };
        let coarsest = level_size(size, config.levels - 1);
        if coarsest.width < crate::pyramid::MIN_LEVEL_SIDE_PX
            || coarsest.height < crate::pyramid::MIN_LEVEL_SIDE_PX
        {
            return Err(Error::InvalidParameter {
                name: "levels",
                value: config.levels.to_string(),
                expected: format!("few enough levels for {size} (the coarsest would be {coarsest})"),
            });
        }
        let points = (0..config.levels)
            .map(|l| {
                if l >= config.finest_level {
                    Vec::with_capacity(level_size(size, l).area())
                } else {
                    Vec::new()
                }
            })
            .collect();
        let ignore = (0..config.levels)
            .map(|l| {
                if l == 0 && config.finest_level > 0 {
                    Vec::new()
                } else {
                    vec![0u8; level_size(size, l).area()]
                }
            })
            .collect();
        Ok(Self {
            config,
            size,
            points,
            ignore,
            column_scratch: Vec::with_capacity(size.width),
            row_keep: Vec::with_capacity(size.width),
            simd: Simd::detect(),
            ignored_fraction: 0.0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DvoConfig {
        &self.config
    }

    /// Reference points of `level` prepared by the last [`Self::prepare_reference`].
    pub fn reference_points(&self, level: usize) -> &[ReferencePoint] {
        self.points.get(level).map_or(&[], |p| p.as_slice())
    }

    /// Builds the per-level ignore masks and reference point lists of `reference`.
    ///
    /// The ignore mask (nonzero = ignore, reference pixel grid) is OR-pooled to the finest
    /// level, dilated there by ⌈radius / 2^finest⌉ pixels (≥ `ignore_dilation_radius_px` at
    /// full resolution), and OR-pooled to coarser levels. Pixels with invalid depth or depth
    /// outside [min_depth_m, max_depth_m] are excluded as well.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the pyramid or mask size differs from the estimator's, or
    /// [`Error::InvalidParameter`] when the pyramid lacks a level the config uses.
    pub fn prepare_reference(
        &mut self,
        reference: &ImagePyramid,
        ignore_in_reference: Option<&Mask>,
    ) -> Result<()> {
        self.check_pyramid("reference pyramid", reference)?;
        let cfg = self.config;
        let finest = cfg.finest_level;
        let have_mask = match ignore_in_reference {
            Some(m) => {
                if m.size() != self.size {
                    return Err(Error::SizeMismatch {
                        what: "ignore mask vs frame".into(),
                        expected: self.size,
                        found: m.size(),
                    });
                }
                // Pool the full-resolution mask down to the finest level.
                let mut src_size = self.size;
                if finest == 0 {
                    for (d, &s) in self.ignore[0].iter_mut().zip(m.as_slice()) {
                        *d = u8::from(s != 0);
                    }
                } else {
                    for l in 1..=finest {
                        let dst_size = level_size(self.size, l);
                        let (before, after) = self.ignore.split_at_mut(l);
                        let src: &[u8] = if l == 1 { m.as_slice() } else { &before[l - 1] };
                        // Raw masks use 255; pooling only tests nonzero and writes 0/1.
                        mask::pool_or_into(src, src_size, &mut after[0], dst_size);
                        src_size = dst_size;
                    }
                }
                let radius = cfg.ignore_dilation_radius_px.div_ceil(1 << finest);
                mask::dilate_square(
                    &mut self.ignore[finest],
                    level_size(self.size, finest),
                    radius,
                    &mut self.column_scratch,
                );
                for l in finest + 1..cfg.levels {
                    let (before, after) = self.ignore.split_at_mut(l);
                    mask::pool_or_into(
                        &before[l - 1],
                        level_size(self.size, l - 1),
                        &mut after[0],
                        level_size(self.size, l),
                    );
                }
                true
            }
            None => false,
        };
        for l in finest..cfg.levels {
            let Some(level) = reference.level(l) else {
                return Err(missing_level(l));
            };
            let pts = &mut self.points[l];
            pts.clear();
            let mut ignored = 0usize;
            let k = level.intrinsics;
            let (fx_inv, fy_inv) = (1.0 / k.fx as f32, 1.0 / k.fy as f32);
            let (cx, cy) = (k.cx as f32, k.cy as f32);
            let w = level.size().width;
            let depth = level.depth_m.as_slice();
            let gray = level.gray.as_slice();
            let ignore = &self.ignore[l];
            let tests = PointTests {
                min_depth_m: cfg.min_depth_m,
                max_depth_m: cfg.max_depth_m,
                min_grad_sq: cfg.min_gradient_per_px * cfg.min_gradient_per_px,
            };
            // Row by row (no division per pixel); the tests are the same for every pixel.
            let simd = self.simd;
            for (y, ((depth_row, gray_row), sample_row)) in depth
                .chunks_exact(w)
                .zip(gray.chunks_exact(w))
                .zip(level.samples.chunks_exact(w))
                .enumerate()
            {
                let row = PointRow {
                    depth_m: depth_row,
                    gray: gray_row,
                    samples: sample_row,
                    ignore: if have_mask {
                        &ignore[y * w..(y + 1) * w]
                    } else {
                        &[][..]
                    },
                    ray_y: (y as f32 - cy) * fy_inv,
                    cx,
                    fx_inv,
                };
                ignored += push_row_points(simd, &row, &tests, &mut self.row_keep, pts);
            }
            if l == finest {
                self.ignored_fraction = ignored as f64 / (ignored + pts.len()).max(1) as f64;
            }
        }
        Ok(())
    }

    fn check_pyramid(&self, what: &str, p: &ImagePyramid) -> Result<()> {
        if p.size() != self.size {
            return Err(Error::SizeMismatch {
                what: what.into(),
                expected: self.size,
                found: p.size(),
            });
        }
        if p.num_levels() < self.config.levels || p.finest_level() > self.config.finest_level {
            return Err(missing_level(self.config.finest_level));
        }
        Ok(())
    }

    /// Estimates `current_from_reference` between two built pyramids, coarse to fine.
    /// `initial_current_from_reference` defaults to identity.
    ///
    /// # Errors
    /// Size or level mismatches between the pyramids, mask and estimator. A motion that
    /// cannot be estimated is not an error: it is a [`DvoStatus::Failed`] estimate.
    pub fn estimate(
        &mut self,
        reference: &ImagePyramid,
        current: &ImagePyramid,
        ignore_in_reference: Option<&Mask>,
        initial_current_from_reference: Option<&Isometry3<f64>>,
    ) -> Result<DvoEstimate> {
        self.prepare_reference(reference, ignore_in_reference)?;
        self.estimate_prepared(current, initial_current_from_reference, None)
    }

    /// [`Self::estimate`] with the reference already prepared by [`Self::prepare_reference`],
    /// and the predicted motion for [`DvoConfig::motion_prior`] (ignored when the prior is off;
    /// no prediction, no prior).
    ///
    /// # Errors
    /// As [`Self::estimate`].
    // `!(a <= b)` is deliberate: a NaN cost fraction must fail the plausibility check.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn estimate_prepared(
        &mut self,
        current: &ImagePyramid,
        initial_current_from_reference: Option<&Isometry3<f64>>,
        prior: Option<&Isometry3<f64>>,
    ) -> Result<DvoEstimate> {
        self.check_pyramid("current pyramid", current)?;
        let cfg = self.config;
        let initial = initial_current_from_reference
            .copied()
            .unwrap_or_else(Isometry3::identity);
        if !is_finite_pose(&initial) {
            return Err(Error::InvalidParameter {
                name: "initial_current_from_reference",
                value: format!("{initial:?}"),
                expected: "a finite transform".into(),
            });
        }
        let mut estimate = DvoEstimate {
            current_from_reference: initial,
            status: DvoStatus::Converged,
            iterations_per_level: [0; MAX_DVO_LEVELS],
            stop_per_level: [None; MAX_DVO_LEVELS],
            final_cost: 0.0,
            pixels_used: 0,
            reference_pixels: self.points[cfg.finest_level].len(),
        };
        let schedule = cfg.schedule();
        let mut pose = initial;
        for l in (cfg.finest_level..cfg.levels).rev() {
            let Some(level) = current.level(l) else {
                return Err(missing_level(l));
            };
            let points = &self.points[l];
            let required = cfg.required_pixels(l);
            let is_finest = l == cfg.finest_level;
            if points.len() < required {
                if is_finest {
                    return Ok(failed(
                        estimate,
                        initial,
                        DvoFailure::TooFewPixels {
                            found: points.len(),
                            required,
                        },
                    ));
                }
                continue; // a coarse level without enough pixels is skipped
            }
            let target = TargetView {
                samples: &level.samples,
                size: level.size(),
                intrinsics: level.intrinsics,
            };
            let cost = cfg.cost_at_level(l);
            let mut level_pose = pose;
            // A coarse level only has to bring the pose into the next level's basin, and its
            // pixels are 2^(l − finest) times larger: its step tolerance is that much looser.
            let level_schedule = LmSchedule {
                step_tolerance: schedule.step_tolerance * f64::from(1u32 << (l - cfg.finest_level)),
                ..schedule
            };
            let level_prior = match (cfg.motion_prior, prior) {
                (Some(p), Some(motion)) => {
                    let ramp = if p.full_weight_ignored_fraction > 0.0 {
                        (self.ignored_fraction / p.full_weight_ignored_fraction).min(1.0)
                    } else {
                        1.0
                    };
                    let scale = ramp * p.weight * points.len() as f64 * f64::from(cost.saturated_point());
                    let t = scale / (p.translation_sigma_m * p.translation_sigma_m);
                    let r = scale / (p.rotation_sigma_rad * p.rotation_sigma_rad);
                    Some(solver::MotionPrior {
                        current_from_reference: *motion,
                        information: [t, t, t, r, r, r],
                    })
                }
                _ => None,
            };
            match solver::optimize_level(
                points,
                level.size().width,
                &target,
                &cost,
                &level_schedule,
                level_prior.as_ref(),
                &mut level_pose,
            ) {
                Ok(res) => {
                    estimate.iterations_per_level[l] = res.iterations as u32;
                    estimate.stop_per_level[l] = Some(res.stop);
                    let ne = res.normal_equations;
                    if ne.inliers < required {
                        if is_finest {
                            return Ok(failed(
                                estimate,
                                initial,
                                DvoFailure::TooFewPixels {
                                    found: ne.inliers,
                                    required,
                                },
                            ));
                        }
                        continue; // keep the pose from the coarser level
                    }
                    pose = level_pose;
                    if is_finest {
                        estimate.final_cost = ne.mean_cost();
                        estimate.pixels_used = ne.inliers;
                    }
                }
                // A coarse level can be degenerate when a moving object leaves only a few
                // background pixels there (4^l fewer than at full resolution): it is skipped
                // like a coarse level without enough pixels. Only the finest level decides.
                Err(LevelError::Degenerate) if !is_finest => continue,
                Err(LevelError::Degenerate) => {
                    return Ok(failed(estimate, initial, DvoFailure::Degenerate { level: l }));
                }
                Err(LevelError::NonFinite) => {
                    return Ok(failed(estimate, initial, DvoFailure::NonFinite { level: l }));
                }
            }
        }
        if !is_finite_pose(&pose) {
            return Ok(failed(
                estimate,
                initial,
                DvoFailure::NonFinite {
                    level: cfg.finest_level,
                },
            ));
        }
        // A wrong minimum looks converged to the solver (small steps, cost no longer
        // decreasing) but leaves most points near the saturated loss.
        let saturated = f64::from(cfg.cost_at_level(cfg.finest_level).saturated_point());
        let fraction = estimate.final_cost / saturated;
        if !(fraction <= cfg.max_final_cost_fraction) {
            let permille = |f: f64| (f * 1000.0).round().clamp(0.0, f64::from(u32::MAX)) as u32;
            return Ok(failed(
                estimate,
                initial,
                DvoFailure::PoorFit {
                    cost_permille: permille(fraction),
                    limit_permille: permille(cfg.max_final_cost_fraction),
                },
            ));
        }
        estimate.current_from_reference = pose;
        Ok(estimate)
    }
}

fn failed(mut estimate: DvoEstimate, initial: Isometry3<f64>, reason: DvoFailure) -> DvoEstimate {
    estimate.current_from_reference = initial;
    estimate.status = DvoStatus::Failed(reason);
    estimate
}

fn missing_level(level: usize) -> Error {
    Error::InvalidParameter {
        name: "pyramid",
        value: format!("without level {level}"),
        expected: "a pyramid built with the estimator's levels and finest level".into(),
    }
}

/// DVO over a sequence: each frame is tracked against a reference frame, the previous one
/// (frame to frame) or, with [`DvoConfig::keyframe`], a keyframe that is kept while the camera
/// stays near it, so that the error of each step does not add up.
///
/// The pyramids and scratch are allocated in [`DvoTracker::new`]; [`DvoTracker::track`] builds
/// the new frame's pyramid once and estimates its motion against the reference, whose point
/// lists are prepared once per reference frame; pyramids change roles by swapping (no copy).
/// `track` is not free of allocations: it makes a few now and then (counted in
/// `tests/detector_alloc.rs`).
#[derive(Debug, Clone)]
pub struct DvoTracker {
    estimator: DvoEstimator,
    /// The reference frame (the previous frame, or the keyframe).
    reference: ImagePyramid,
    current: ImagePyramid,
    /// With keyframes: the previous frame, once it is not the keyframe.
    previous: Option<ImagePyramid>,
    has_reference: bool,
    /// The last converged motion from one frame to the next.
    previous_motion: Option<Isometry3<f64>>,
    /// The fraction of its reference's usable pixels the ignore mask removed when
    /// `previous_motion` was estimated.
    previous_motion_ignored_fraction: f64,
    /// Motions estimated since the tracker was created or reset.
    motions_since_start: usize,
    /// With keyframes: the previous frame's pose in the keyframe's camera (identity when the
    /// previous frame is the keyframe), and the frames tracked against the keyframe.
    previous_from_keyframe: Isometry3<f64>,
    frames_on_keyframe: usize,
    /// The reference must be prepared from the previous frame (always frame to frame; with
    /// keyframes, the previous frame becomes the keyframe).
    new_reference: bool,
}

impl DvoTracker {
    /// A tracker for frames of `size` seen through `intrinsics` (level-0 values).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an invalid config, invalid intrinsics, or a size too
    /// small for the requested levels.
    pub fn new(size: ImageSize, intrinsics: PinholeIntrinsics, config: DvoConfig) -> Result<Self> {
        let estimator = DvoEstimator::new(size, config)?;
        let config = *estimator.config();
        let reference = ImagePyramid::new(size, intrinsics, config.levels, config.finest_level)?;
        let current = reference.clone();
        // Frame to frame needs no third pyramid.
        let previous = config.keyframe.is_some().then(|| reference.clone());
        Ok(Self {
            estimator,
            reference,
            current,
            previous,
            has_reference: false,
            previous_motion: None,
            previous_motion_ignored_fraction: 0.0,
            motions_since_start: 0,
            previous_from_keyframe: Isometry3::identity(),
            frames_on_keyframe: 0,
            new_reference: true,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DvoConfig {
        self.estimator.config()
    }

    /// Forgets the last motion, so the next [`Self::track`] has no constant-velocity prediction
    /// (no [`DvoConfig::motion_prior`], no [`DvoConfig::init_from_previous_motion`]): for the
    /// caller to call when that motion was not trusted or the next estimate spans more than
    /// one frame interval (frames skipped in between). With keyframes, the last tracked frame
    /// also becomes the keyframe: its pose relative to the old one is not trusted either.
    pub fn forget_motion(&mut self) {
        self.previous_motion = None;
        self.new_reference = true;
    }

    /// With keyframes: the last tracked frame becomes the keyframe for the next one (the caller
    /// saw something that the old keyframe's ignore mask does not cover). Frame to frame, a
    /// no-op.
    pub fn end_keyframe(&mut self) {
        self.new_reference = true;
    }

    /// Forgets the reference frame (the next [`Self::track`] returns `None`) and the motion prior.
    pub fn reset(&mut self) {
        self.has_reference = false;
        self.previous_motion = None;
        self.motions_since_start = 0;
    }

    /// Adds a frame: returns the motion from the previous frame to this one (`None` for the
    /// first frame after creation or [`Self::reset`]); this frame is then the next one's
    /// reference, or with keyframes the previous frame for the next one.
    ///
    /// `ignore_in_reference` (nonzero = ignore) lives on the *previous* frame's pixel grid
    /// (the moving objects detected there); it is dilated per the config. The initial guess
    /// (of the motion from the previous frame) is `initial_current_from_reference`, else the
    /// previous converged motion when [`DvoConfig::init_from_previous_motion`] is set, else
    /// identity.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image or the mask is not the tracker's size (the
    /// tracker's state is then unchanged, except that with keyframes the next frame is tracked
    /// against the previous frame), [`Error::InvalidParameter`] for a non-finite initial guess.
    pub fn track(
        &mut self,
        gray: &GrayF32,
        depth_m: &DepthMeters,
        ignore_in_reference: Option<&Mask>,
        initial_current_from_reference: Option<&Isometry3<f64>>,
    ) -> Result<Option<DvoEstimate>> {
        self.track_with(
            gray,
            depth_m,
            || Ok(ignore_in_reference),
            initial_current_from_reference,
        )
    }

    /// [`Self::track`] with the previous frame's ignore mask made by `ignore_in_reference`,
    /// which runs beside the new frame's pyramid (the caller's mask work then overlaps it).
    /// With keyframes, it is called only when the previous frame becomes the keyframe (the
    /// mask is a keyframe's, kept with it).
    ///
    /// # Errors
    /// As [`Self::track`], and what `ignore_in_reference` returns.
    pub fn track_with<'m>(
        &mut self,
        gray: &GrayF32,
        depth_m: &DepthMeters,
        ignore_in_reference: impl FnOnce() -> Result<Option<&'m Mask>> + Send,
        initial_current_from_reference: Option<&Isometry3<f64>>,
    ) -> Result<Option<DvoEstimate>> {
        if !self.has_reference {
            self.current.build(gray, depth_m)?;
            std::mem::swap(&mut self.reference, &mut self.current);
            self.has_reference = true;
            self.new_reference = true;
            self.frames_on_keyframe = 0;
            return Ok(None);
        }
        let keyframes = self.config().keyframe;
        if keyframes.is_none() || self.new_reference {
            // The previous frame is the new reference (with keyframes, it is in `previous`
            // unless it is the keyframe already).
            if let Some(previous) = self.previous.as_mut().filter(|_| self.frames_on_keyframe > 0) {
                std::mem::swap(&mut self.reference, previous);
            }
            self.previous_from_keyframe = Isometry3::identity();
            self.frames_on_keyframe = 0;
            // The new frame's pyramid and the reference's ignore mask and point lists are
            // independent: build them side by side (the mask and the point lists are serial
            // passes; the pyramid is row-parallel).
            let (current, estimator, reference) = (&mut self.current, &mut self.estimator, &self.reference);
            let (built, prepared) = rayon::join(
                || current.build(gray, depth_m),
                || {
                    let ignore = ignore_in_reference()?;
                    if let Some(m) = ignore {
                        if m.size() != reference.size() {
                            return Err(Error::SizeMismatch {
                                what: "ignore mask vs frame".into(),
                                expected: reference.size(),
                                found: m.size(),
                            });
                        }
                    }
                    estimator.prepare_reference(reference, ignore)
                },
            );
            // After an error the reference (the previous frame) is prepared again next time.
            built?;
            prepared?;
            self.new_reference = false;
        } else {
            self.current.build(gray, depth_m)?;
        }
        if let Some(p) = self.config().motion_prior {
            // Far more ignored now than then, early on: the objects now masked pulled the last
            // motion.
            if self.motions_since_start <= p.startup_frames
                && self.estimator.ignored_fraction - self.previous_motion_ignored_fraction
                    > p.max_ignored_fraction_increase
            {
                self.previous_motion = None;
            }
        }
        self.motions_since_start += 1;
        let prior = if self.config().init_from_previous_motion {
            self.previous_motion
        } else {
            None
        };
        let initial = initial_current_from_reference.copied().or(prior);
        let estimate = match keyframes {
            None => self.estimator.estimate_prepared(
                &self.current,
                initial.as_ref(),
                self.previous_motion.as_ref(),
            )?,
            Some(limits) => {
                // Motions from the previous frame, carried to motions from the keyframe.
                let from_keyframe = |m: Isometry3<f64>| m * self.previous_from_keyframe;
                let mut estimate = self.estimator.estimate_prepared(
                    &self.current,
                    initial.map(from_keyframe).as_ref(),
                    self.previous_motion.map(from_keyframe).as_ref(),
                )?;
                let current_from_keyframe = estimate.current_from_reference;
                estimate.current_from_reference =
                    current_from_keyframe * self.previous_from_keyframe.inverse();
                self.previous_from_keyframe = current_from_keyframe;
                self.frames_on_keyframe += 1;
                let used = estimate.pixels_used as f64 / estimate.reference_pixels.max(1) as f64;
                self.new_reference = !estimate.is_converged()
                    || self.frames_on_keyframe >= limits.max_frames
                    || current_from_keyframe.translation.vector.norm() > limits.max_translation_m
                    || current_from_keyframe.rotation.angle() > limits.max_rotation_rad
                    || used < limits.min_used_fraction;
                estimate
            }
        };
        match &mut self.previous {
            None => std::mem::swap(&mut self.reference, &mut self.current),
            Some(previous) => std::mem::swap(previous, &mut self.current),
        }
        self.previous_motion = estimate.is_converged().then_some(estimate.current_from_reference);
        self.previous_motion_ignored_fraction = self.estimator.ignored_fraction;
        Ok(Some(estimate))
    }

    /// Estimates the motion between two explicitly given frames with the tracker's buffers
    /// (for tests and benchmarks); afterwards `current` is the tracker's reference.
    ///
    /// # Errors
    /// As [`Self::track`].
    pub fn estimate_between(
        &mut self,
        reference: (&GrayF32, &DepthMeters),
        current: (&GrayF32, &DepthMeters),
        ignore_in_reference: Option<&Mask>,
        initial_current_from_reference: Option<&Isometry3<f64>>,
    ) -> Result<DvoEstimate> {
        self.reset();
        self.track(reference.0, reference.1, None, None)?;
        let est = self.track(
            current.0,
            current.1,
            ignore_in_reference,
            initial_current_from_reference,
        )?;
        est.ok_or_else(|| Error::InvalidParameter {
            name: "reference",
            value: "missing".into(),
            expected: "a reference frame (internal error)".into(),
        })
    }
}

/// The tests a reference pixel passes to become a point (the same for every pixel of a level).
#[derive(Debug, Clone, Copy)]
struct PointTests {
    min_depth_m: f32,
    max_depth_m: f32,
    /// The squared minimum intensity gradient per pixel.
    min_grad_sq: f32,
}

impl PointTests {
    /// Depth in range and a gradient at the minimum or above (a NaN gradient passes: any
    /// gradient passes a threshold of 0).
    #[inline]
    fn usable(&self, z: f32, sample: &TargetSample) -> bool {
        let (gx, gy) = (sample.0[TargetSample::GRAD_X], sample.0[TargetSample::GRAD_Y]);
        let grad_sq = gx * gx + gy * gy;
        (z > 0.0)
            & (z >= self.min_depth_m)
            & (z <= self.max_depth_m)
            & ((grad_sq >= self.min_grad_sq) | grad_sq.is_nan())
    }
}

/// One row of a pyramid level as the point selection reads it.
struct PointRow<'a> {
    depth_m: &'a [f32],
    gray: &'a [f32],
    samples: &'a [TargetSample],
    /// Nonzero = ignored; empty = nothing ignored.
    ignore: &'a [u8],
    /// The row's ray slope (y − cy) / fy, and the level's cx and 1 / fx.
    ray_y: f32,
    cx: f32,
    fx_inv: f32,
}

/// Appends the reference points of `row` to `points` in column order: the pixels that pass
/// `tests` and that `row.ignore` does not mark. Returns how many passing pixels it marks.
///
/// Two passes: the flags of every pixel (branch-free), then the points of the flagged pixels,
/// eight flags at a time (whether a pixel is kept is as good as random on textured depth, so a
/// branch per pixel mispredicts, and writing every pixel's point at the next free slot wrote
/// twice as much as is kept). `keep` is scratch.
#[inline(always)]
fn push_row_points_generic(
    row: &PointRow<'_>,
    tests: &PointTests,
    keep: &mut Vec<u8>,
    points: &mut Vec<ReferencePoint>,
) -> usize {
    let width = row.depth_m.len();
    // Every flag is written below: only a change of width (a new level) resizes.
    keep.resize(width, 0);
    let mut ignored = 0usize;
    if row.ignore.is_empty() {
        for ((k, &z), sample) in keep.iter_mut().zip(row.depth_m).zip(row.samples) {
            *k = u8::from(tests.usable(z, sample));
        }
    } else {
        for (((k, &z), sample), &m) in keep.iter_mut().zip(row.depth_m).zip(row.samples).zip(row.ignore) {
            let usable = tests.usable(z, sample);
            let masked = m != 0;
            *k = u8::from(usable & !masked);
            ignored += usize::from(usable & masked);
        }
    }
    points.reserve(width);
    for (chunk_index, chunk) in keep.chunks(8).enumerate() {
        let mut bytes = [0u8; 8];
        bytes[..chunk.len()].copy_from_slice(chunk);
        // Each kept pixel is one set bit, the lowest of its byte.
        let mut flags = u64::from_le_bytes(bytes);
        while flags != 0 {
            let x = chunk_index * 8 + (flags.trailing_zeros() / 8) as usize;
            let z = row.depth_m[x];
            points.push(ReferencePoint {
                point_m: [(x as f32 - row.cx) * row.fx_inv * z, row.ray_y * z, z],
                intensity: row.gray[x],
            });
            flags &= flags - 1;
        }
    }
    ignored
}

simd_kernel!(
    push_row_points,
    push_row_points_avx2,
    push_row_points_generic,
    (row: &PointRow<'_>, tests: &PointTests, keep: &mut Vec<u8>, points: &mut Vec<ReferencePoint>) -> usize
);

#[cfg(test)]
mod tests;
