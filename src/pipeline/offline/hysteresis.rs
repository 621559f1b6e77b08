//! Temporal hysteresis of the offline mode's published mask ("confirm later, mark earlier").
//!
//! The slow-change evidence W (docs/method.md, D16) of a surface that starts to move grows
//! over several frames before it crosses α·Z; until then the refinement pass misses the object.
//! In a recording the frames before the confirmation are still at hand: the refinement pass's
//! results are held back [`OfflineConfig::hysteresis_frames`] frames, and the pixels of frame j
//! whose W (less the camera motion's error, as for the evidence itself) exceeds the *low*
//! threshold `hysteresis_low_fraction`·α·Z and whose point lands, moved by the refinement pass's
//! camera motion from j to j + 1, within [`HYSTERESIS_RADIUS_PX`] of a seed pixel of frame j + 1 join
//! frame j's mask (and its seeds), and so on backwards: Canny's hysteresis along time. The
//! seeds are the pixels the slow-change evidence confirmed (the refinement pass's mask less its
//! odometry mask): the low threshold is one of W, so only W's own confirmations extend it.
//! Seeded by the whole published mask (the accumulation's and the backward pass's objects too)
//! the sweep cost the Bonn crowd's offline F1 0.879 → 0.866–0.878 (precision) in every variant
//! tried; seeded by the evidence, 0.879.
//!
//! Only the published mask changes: the refinement pass's odometry never sees these pixels.
//! The candidates are kept as a sparse list per held frame (pixel and depth), so the sweep
//! costs in proportion to them; it stops at the first frame it adds nothing to.

use std::collections::VecDeque;

use nalgebra::Isometry3;

use super::{Emit, OfflineConfig};
use crate::error::Result;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, ImageSize, Mask};
use crate::pipeline::{FrameOutput, FrameStats};

/// How far (px) a seed pixel of the next frame may lie from where a candidate's point lands
/// there: the object's own motion in one frame, which the camera motion does not account for.
/// Every held frame the marks may spread this far over candidates, so it is kept small.
/// Measured (low fraction 0.5): on the synthetic failure classes at 320 × 240, 0 px gave the
/// sliding box F1 0.840 and the late-onset box onset 21 frames, 1 px 0.859 and 17; on the Bonn
/// crowd (640 × 480, offline F1 0.879 without the hysteresis) 0 px 0.880, 1 px 0.879, 2 px 0.878.
pub const HYSTERESIS_RADIUS_PX: usize = 1;

/// A refined frame held back for the sweep.
#[derive(Debug, Clone)]
pub(super) struct Held {
    index: u64,
    timestamp_ns: u64,
    current_from_previous: Isometry3<f64>,
    world_from_camera: Isometry3<f64>,
    stats: FrameStats,
    /// The published mask (refinement ∪ backward ∪ what the sweep added).
    mask: Mask,
    odometry_mask: Mask,
    /// The pixels that seed the sweep: the refinement pass's slow-change evidence (its mask
    /// less its odometry mask) and what the sweep added.
    seeds: Mask,
    accumulation_m: DepthMeters,
    /// Pixels off the mask with W above the low threshold: (pixel index, depth in m).
    candidates: Vec<(u32, f32)>,
}

/// The held frames and the sweep's parameters.
pub(super) struct Hysteresis {
    frames: usize,
    low_fraction: f32,
    radius_px: usize,
    intrinsics: PinholeIntrinsics,
    size: ImageSize,
    held: VecDeque<Held>,
    spare: Vec<Held>,
    /// Scratch of the candidates (one image row).
    row: Vec<u8>,
}

impl Hysteresis {
    /// `None` when `config` turns the hysteresis off.
    pub fn new(config: &OfflineConfig, size: ImageSize, intrinsics: PinholeIntrinsics) -> Option<Self> {
        (config.hysteresis_frames > 0).then(|| Self {
            frames: config.hysteresis_frames,
            low_fraction: config.hysteresis_low_fraction,
            radius_px: HYSTERESIS_RADIUS_PX,
            intrinsics,
            size,
            held: VecDeque::with_capacity(config.hysteresis_frames + 1),
            spare: Vec::new(),
            row: Vec::with_capacity(size.width),
        })
    }

    /// Frames held back.
    pub fn len(&self) -> usize {
        self.held.len()
    }

    /// Holds a copy of `out` (its mask the published one; `refinement_mask` the refinement
    /// pass's own); [`Self::settle`] completes it.
    pub fn hold(&mut self, out: &FrameOutput<'_>, refinement_mask: &Mask) {
        let size = self.size;
        let mut held = self.spare.pop().unwrap_or_else(|| Held {
            index: 0,
            timestamp_ns: 0,
            current_from_previous: Isometry3::identity(),
            world_from_camera: Isometry3::identity(),
            stats: FrameStats::default(),
            mask: Mask::filled(size, 0),
            odometry_mask: Mask::filled(size, 0),
            seeds: Mask::filled(size, 0),
            accumulation_m: DepthMeters::filled(size, 0.0),
            candidates: Vec::new(),
        });
        held.index = out.index;
        held.timestamp_ns = out.timestamp_ns;
        held.current_from_previous = out.current_from_previous;
        held.world_from_camera = out.world_from_camera;
        held.stats = out.stats;
        held.mask.as_mut_slice().copy_from_slice(out.mask.as_slice());
        held.odometry_mask
            .as_mut_slice()
            .copy_from_slice(out.odometry_mask.as_slice());
        held.accumulation_m
            .as_mut_slice()
            .copy_from_slice(out.accumulation_m.as_slice());
        for ((s, &r), &o) in held
            .seeds
            .as_mut_slice()
            .iter_mut()
            .zip(refinement_mask.as_slice())
            .zip(out.odometry_mask.as_slice())
        {
            *s = r & !o;
        }
        held.candidates.clear();
        self.held.push_back(held);
    }

    /// Completes the frame held last: `candidates(low_fraction, row scratch, list)` appends
    /// the pixels above the low threshold with their depth (m)
    /// ([`crate::occlusion::OcclusionDetector::slow_candidates`]); those off the mask are kept.
    /// Then sweeps the frame's mask back over the held frames and emits those more than
    /// `frames` behind.
    pub fn settle(
        &mut self,
        candidates: impl FnOnce(f32, &mut Vec<u8>, &mut Vec<(u32, f32)>),
        emit: &mut Emit<'_>,
    ) -> Result<()> {
        if let Some(held) = self.held.back_mut() {
            candidates(self.low_fraction, &mut self.row, &mut held.candidates);
            let mask = held.mask.as_slice();
            held.candidates.retain(|&(i, _)| mask[i as usize] == 0);
        }
        self.sweep();
        while self.held.len() > self.frames {
            self.emit_oldest(emit)?;
        }
        Ok(())
    }

    /// Emits every held frame (the end of the sequence).
    pub fn flush(&mut self, emit: &mut Emit<'_>) -> Result<()> {
        while !self.held.is_empty() {
            self.emit_oldest(emit)?;
        }
        Ok(())
    }

    fn emit_oldest(&mut self, emit: &mut Emit<'_>) -> Result<()> {
        let Some(held) = self.held.pop_front() else {
            return Ok(());
        };
        let moving = held.mask.as_slice().iter().filter(|&&m| m != 0).count();
        let mut stats = held.stats;
        stats.detector.mask_pixels = moving;
        stats.moving_fraction = moving as f64 / self.size.area().max(1) as f64;
        let result = emit(FrameOutput {
            index: held.index,
            timestamp_ns: held.timestamp_ns,
            mask: &held.mask,
            odometry_mask: &held.odometry_mask,
            current_from_previous: held.current_from_previous,
            world_from_camera: held.world_from_camera,
            accumulation_m: &held.accumulation_m,
            stats,
        });
        self.spare.push(held);
        result
    }

    /// From the newest frame back: marks the candidates of each held frame that land near a
    /// marked pixel of the frame after it; stops at a frame that gains nothing, or across a
    /// detector restart (a jump between the frames).
    fn sweep(&mut self) {
        let (width, height) = (self.size.width, self.size.height);
        let (fx, fy, cx, cy) = (
            self.intrinsics.fx as f32,
            self.intrinsics.fy as f32,
            self.intrinsics.cx as f32,
            self.intrinsics.cy as f32,
        );
        let r = self.radius_px as isize;
        let held = self.held.make_contiguous();
        for later in (1..held.len()).rev() {
            let (earlier, rest) = held.split_at_mut(later);
            let (before, after) = (&mut earlier[later - 1], &rest[0]);
            if after.stats.detector_reset {
                return;
            }
            let motion = (after.world_from_camera.inverse() * before.world_from_camera).cast::<f32>();
            let rotation = motion.rotation.to_rotation_matrix().into_inner();
            let translation = motion.translation.vector;
            let target = after.seeds.as_slice();
            let mut added = 0usize;
            let (candidates, mask, seeds) = (
                &before.candidates,
                before.mask.as_mut_slice(),
                before.seeds.as_mut_slice(),
            );
            for &(i, z) in candidates {
                let i = i as usize;
                if mask[i] != 0 {
                    continue;
                }
                let (x, y) = ((i % width) as f32, (i / width) as f32);
                let p = nalgebra::Vector3::new(z * (x - cx) / fx, z * (y - cy) / fy, z);
                let q = rotation * p + translation;
                if q.z <= 0.0 {
                    continue;
                }
                let u = (fx * q.x / q.z + cx).round();
                let v = (fy * q.y / q.z + cy).round();
                if !(u.is_finite() && v.is_finite()) {
                    continue;
                }
                let (u, v) = (u as isize, v as isize);
                let x0 = (u - r).max(0);
                let x1 = (u + r).min(width as isize - 1);
                let y0 = (v - r).max(0);
                let y1 = (v + r).min(height as isize - 1);
                if x0 > x1 || y0 > y1 {
                    continue;
                }
                let hit = (y0..=y1).any(|yy| {
                    let row = yy as usize * width;
                    target[row + x0 as usize..=row + x1 as usize]
                        .iter()
                        .any(|&m| m != 0)
                });
                if hit {
                    mask[i] = u8::MAX;
                    seeds[i] = u8::MAX;
                    added += 1;
                }
            }
            if added == 0 {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: ImageSize = ImageSize::new(32, 24);
    /// Pixel (x, y) of the test image.
    const fn at(x: usize, y: usize) -> usize {
        y * SIZE.width + x
    }

    fn intrinsics() -> PinholeIntrinsics {
        PinholeIntrinsics {
            fx: 30.0,
            fy: 30.0,
            cx: 15.5,
            cy: 11.5,
        }
    }

    /// The evidence's α and the scene's depth (a wall facing the camera).
    const ALPHA: f32 = 0.04;
    const DEPTH_M: f32 = 2.0;

    /// Pushes a frame with `mask` (published) and evidence W = `w_m` at the pixels `evidence`
    /// (the detector's candidates), a static camera; collects what is emitted, as the masked
    /// pixels.
    fn push(
        hysteresis: &mut Hysteresis,
        index: u64,
        mask_pixels: &[usize],
        evidence: &[usize],
        w_m: f32,
        reset: bool,
        emitted: &mut Vec<(u64, Vec<usize>)>,
    ) {
        let mut mask = Mask::filled(SIZE, 0);
        for &i in mask_pixels {
            mask.as_mut_slice()[i] = u8::MAX;
        }
        let zero = DepthMeters::filled(SIZE, 0.0);
        // Confirmed by the slow-change evidence: not in the odometry mask.
        let none = Mask::filled(SIZE, 0);
        let stats = FrameStats {
            detector_reset: reset,
            ..FrameStats::default()
        };
        hysteresis.hold(
            &FrameOutput {
                index,
                timestamp_ns: index,
                mask: &mask,
                odometry_mask: &none,
                current_from_previous: Isometry3::identity(),
                world_from_camera: Isometry3::identity(),
                accumulation_m: &zero,
                stats,
            },
            &mask,
        );
        let mut keep = |out: FrameOutput<'_>| record(&out, emitted);
        hysteresis
            .settle(
                |fraction, _, out| {
                    if w_m > fraction * ALPHA * DEPTH_M {
                        out.extend(evidence.iter().map(|&i| (i as u32, DEPTH_M)));
                    }
                },
                &mut keep,
            )
            .expect("emit");
    }

    /// Keeps an emitted frame's index and marked pixels.
    fn record(out: &FrameOutput<'_>, emitted: &mut Vec<(u64, Vec<usize>)>) -> Result<()> {
        let marked = (0..SIZE.area())
            .filter(|&i| out.mask.as_slice()[i] != 0)
            .collect();
        emitted.push((out.index, marked));
        Ok(())
    }

    fn hysteresis(frames: usize) -> Hysteresis {
        let config = OfflineConfig {
            hysteresis_frames: frames,
            hysteresis_low_fraction: 0.5,
            ..OfflineConfig::default()
        };
        Hysteresis::new(&config, SIZE, intrinsics()).expect("on")
    }

    /// An object confirmed at frame 3 whose evidence was above the low threshold (0.5 · 0.04 ·
    /// 2 m = 4 cm) from frame 1 on is marked from frame 1; frame 0's evidence is below it, and a
    /// candidate far from the object is never marked.
    #[test]
    fn a_confirmation_marks_the_earlier_frames_of_the_same_surface() {
        let mut h = hysteresis(5);
        let object = [at(10, 10), at(11, 10), at(10, 11), at(11, 11)];
        let far = at(25, 3);
        let mut emitted = Vec::new();
        let mut with_far = object.to_vec();
        with_far.push(far);
        push(&mut h, 0, &[], &object, 0.03, false, &mut emitted);
        push(&mut h, 1, &[], &with_far, 0.05, false, &mut emitted);
        push(&mut h, 2, &[], &with_far, 0.07, false, &mut emitted);
        push(&mut h, 3, &object, &with_far, 0.09, false, &mut emitted);
        assert!(emitted.is_empty(), "held back");
        let mut keep = |out: FrameOutput<'_>| record(&out, &mut emitted);
        h.flush(&mut keep).expect("emit");
        assert_eq!(h.len(), 0);
        let marked: Vec<_> = emitted.iter().map(|(i, m)| (*i, m.clone())).collect();
        assert_eq!(marked[0], (0, vec![]));
        for (index, mask) in &marked[1..] {
            assert_eq!(mask, &object.to_vec(), "frame {index}");
        }
    }

    /// A frame emitted before the confirmation is not changed (the hold is `frames` long), and a
    /// detector
    /// restart stops the sweep.
    #[test]
    fn the_sweep_reaches_back_only_over_held_frames_and_not_across_a_restart() {
        let object = [at(10, 10), at(11, 10)];
        let mut emitted = Vec::new();
        let mut h = hysteresis(2);
        for index in 0..4 {
            let confirmed: &[usize] = if index == 3 { &object } else { &[] };
            push(&mut h, index, confirmed, &object, 0.05, false, &mut emitted);
        }
        // Frame 0 left before the confirmation at frame 3; frame 1, two frames back, is marked.
        let first_two: Vec<_> = emitted.iter().map(|(_, m)| m.len()).collect();
        assert_eq!(first_two, [0, object.len()]);
        let mut h = hysteresis(5);
        let mut emitted = Vec::new();
        push(&mut h, 0, &[], &object, 0.05, false, &mut emitted);
        push(&mut h, 1, &object, &object, 0.05, true, &mut emitted);
        let mut keep = |out: FrameOutput<'_>| record(&out, &mut emitted);
        h.flush(&mut keep).expect("emit");
        assert!(emitted[0].1.is_empty(), "marked across a restart");
    }
}
