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

use super::{OfflineConfig, Sink};
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
    /// Where each candidate lands in the next held frame (filled when that frame is the newest).
    landing: Vec<[i32; 2]>,
    /// The pixels the running sweep added to this frame.
    fresh: Vec<u32>,
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
    /// Scratch of the sweep: the seeds it added to the frame it tests against (else 0).
    fresh_seeds: Mask,
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
            fresh_seeds: Mask::filled(size, 0),
        })
    }

    /// The low threshold as a fraction of the slow-change evidence's α (what
    /// [`Self::settle`] hands its `candidates`).
    pub fn low_fraction(&self) -> f32 {
        self.low_fraction
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
            landing: Vec::new(),
            fresh: Vec::new(),
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
        held.landing.clear();
        self.held.push_back(held);
    }

    /// Completes the frame held last with its `candidates`: the pixels above the low threshold
    /// ([`Self::low_fraction`]) with their depth (m), as
    /// [`crate::occlusion::OcclusionDetector::slow_candidates`] lists them; it takes the list
    /// (leaving an empty one) and keeps those off its mask. Then sweeps the frame's mask back
    /// over the held frames and emits those more than `frames` behind.
    pub fn settle(&mut self, candidates: &mut Vec<(u32, f32)>, emit: &mut Sink<'_>) -> Result<()> {
        self.settle_with(candidates, emit, Self::sweep)
    }

    /// [`Self::settle`] with the given sweep.
    fn settle_with(
        &mut self,
        candidates: &mut Vec<(u32, f32)>,
        emit: &mut Sink<'_>,
        sweep: fn(&mut Self),
    ) -> Result<()> {
        if let Some(held) = self.held.back_mut() {
            std::mem::swap(&mut held.candidates, candidates);
            let mask = held.mask.as_slice();
            held.candidates.retain(|&(i, _)| mask[i as usize] == 0);
        }
        sweep(self);
        while self.held.len() > self.frames {
            self.emit_oldest(emit)?;
        }
        Ok(())
    }

    /// Emits every held frame (the end of the sequence).
    pub fn flush(&mut self, emit: &mut Sink<'_>) -> Result<()> {
        while !self.held.is_empty() {
            self.emit_oldest(emit)?;
        }
        Ok(())
    }

    fn emit_oldest(&mut self, emit: &mut Sink<'_>) -> Result<()> {
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
    /// seed of the frame after it; stops at a frame that gains nothing, or across a detector
    /// restart (a jump between the frames).
    ///
    /// Incremental: a frame's candidates are tested against all of the next frame's seeds once,
    /// when that frame is the newest, and then only against the seeds a later sweep adds to it.
    /// Seeds only grow, and a frame's successor never changes, so a candidate that missed the
    /// seeds it was tested against can only hit the ones added since: the marks are those of
    /// re-testing every candidate against every seed each sweep.
    fn sweep(&mut self) {
        let size = self.size;
        let r = self.radius_px as i64;
        let held = self.held.make_contiguous();
        for frame in held.iter_mut() {
            frame.fresh.clear();
        }
        for later in (1..held.len()).rev() {
            let (earlier, rest) = held.split_at_mut(later);
            let (before, after) = (&mut earlier[later - 1], &mut rest[0]);
            if after.stats.detector_reset {
                return;
            }
            let first_test = before.landing.len() != before.candidates.len();
            if first_test {
                let rigid = after_from_before(before, after);
                before.landing.clear();
                before.landing.extend(
                    before
                        .candidates
                        .iter()
                        .map(|&(i, z)| landing(&self.intrinsics, size, &rigid, i, z)),
                );
            } else {
                if after.fresh.is_empty() {
                    return;
                }
                for &i in &after.fresh {
                    self.fresh_seeds.as_mut_slice()[i as usize] = u8::MAX;
                }
            }
            let target = if first_test {
                after.seeds.as_slice()
            } else {
                self.fresh_seeds.as_slice()
            };
            let (mask, seeds) = (before.mask.as_mut_slice(), before.seeds.as_mut_slice());
            for (&(i, _), &at) in before.candidates.iter().zip(&before.landing) {
                let index = i as usize;
                if mask[index] == 0 && window_hits(target, size, at, r) {
                    mask[index] = u8::MAX;
                    seeds[index] = u8::MAX;
                    before.fresh.push(i);
                }
            }
            if !first_test {
                for &i in &after.fresh {
                    self.fresh_seeds.as_mut_slice()[i as usize] = 0;
                }
            }
            if before.fresh.is_empty() {
                return;
            }
        }
    }

    /// The reference of [`Self::sweep`]: every sweep tests every unmarked candidate against all
    /// of the next frame's seeds.
    #[cfg(test)]
    fn sweep_reference(&mut self) {
        let size = self.size;
        let r = self.radius_px as i64;
        let held = self.held.make_contiguous();
        for later in (1..held.len()).rev() {
            let (earlier, rest) = held.split_at_mut(later);
            let (before, after) = (&mut earlier[later - 1], &rest[0]);
            if after.stats.detector_reset {
                return;
            }
            let rigid = after_from_before(before, after);
            let mut added = 0usize;
            let (mask, seeds) = (before.mask.as_mut_slice(), before.seeds.as_mut_slice());
            for &(i, z) in &before.candidates {
                let index = i as usize;
                if mask[index] == 0
                    && window_hits(
                        after.seeds.as_slice(),
                        size,
                        landing(&self.intrinsics, size, &rigid, i, z),
                        r,
                    )
                {
                    mask[index] = u8::MAX;
                    seeds[index] = u8::MAX;
                    added += 1;
                }
            }
            if added == 0 {
                return;
            }
        }
    }
}

/// The camera motion from held frame `before` to `after` as (rotation, translation).
fn after_from_before(before: &Held, after: &Held) -> (nalgebra::Matrix3<f32>, nalgebra::Vector3<f32>) {
    let motion = (after.world_from_camera.inverse() * before.world_from_camera).cast::<f32>();
    (
        motion.rotation.to_rotation_matrix().into_inner(),
        motion.translation.vector,
    )
}

/// Where the point of pixel `i` at depth `z_m` lands in the next frame, moved by
/// `next_from_this` (rotation, translation): the rounded pixel, or [`NOWHERE`] behind the
/// camera or off any finite pixel.
fn landing(
    intrinsics: &PinholeIntrinsics,
    size: ImageSize,
    (rotation, translation): &(nalgebra::Matrix3<f32>, nalgebra::Vector3<f32>),
    i: u32,
    z_m: f32,
) -> [i32; 2] {
    let (fx, fy, cx, cy) = (
        intrinsics.fx as f32,
        intrinsics.fy as f32,
        intrinsics.cx as f32,
        intrinsics.cy as f32,
    );
    let i = i as usize;
    let (x, y) = ((i % size.width) as f32, (i / size.width) as f32);
    let p = nalgebra::Vector3::new(z_m * (x - cx) / fx, z_m * (y - cy) / fy, z_m);
    let q = rotation * p + translation;
    if q.z <= 0.0 {
        return NOWHERE;
    }
    let u = (fx * q.x / q.z + cx).round();
    let v = (fy * q.y / q.z + cy).round();
    if !(u.is_finite() && v.is_finite()) {
        return NOWHERE;
    }
    // Saturating: a point far off the image stays far off it.
    [u as i32, v as i32]
}

/// A candidate that lands nowhere.
const NOWHERE: [i32; 2] = [i32::MIN, i32::MIN];

/// Whether `target` has a marked pixel within `r` (Chebyshev) of `at`, inside the image.
fn window_hits(target: &[u8], size: ImageSize, at: [i32; 2], r: i64) -> bool {
    if at == NOWHERE {
        return false;
    }
    let (u, v) = (i64::from(at[0]), i64::from(at[1]));
    let x0 = (u - r).max(0);
    let x1 = (u + r).min(size.width as i64 - 1);
    let y0 = (v - r).max(0);
    let y1 = (v + r).min(size.height as i64 - 1);
    if x0 > x1 || y0 > y1 {
        return false;
    }
    (y0..=y1).any(|y| {
        let row = y as usize * size.width;
        target[row + x0 as usize..=row + x1 as usize]
            .iter()
            .any(|&m| m != 0)
    })
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
        hold(hysteresis, index, Isometry3::identity(), mask_pixels, reset);
        let mut keep = |out: FrameOutput<'_>| record(&out, emitted);
        let mut candidates = Vec::new();
        if w_m > hysteresis.low_fraction() * ALPHA * DEPTH_M {
            candidates.extend(evidence.iter().map(|&i| (i as u32, DEPTH_M)));
        }
        hysteresis.settle(&mut candidates, &mut keep).expect("emit");
    }

    /// Holds frame `index` seen from `world_from_camera`, its published mask the pixels
    /// `mask_pixels`, all of them confirmed by the slow-change evidence (none in the odometry
    /// mask).
    fn hold(
        hysteresis: &mut Hysteresis,
        index: u64,
        world_from_camera: Isometry3<f64>,
        mask_pixels: &[usize],
        reset: bool,
    ) {
        let mut mask = Mask::filled(SIZE, 0);
        for &i in mask_pixels {
            mask.as_mut_slice()[i] = u8::MAX;
        }
        let zero = DepthMeters::filled(SIZE, 0.0);
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
                world_from_camera,
                accumulation_m: &zero,
                stats,
            },
            &mask,
        );
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

    /// The incremental sweep marks what re-testing every candidate against every seed at each
    /// sweep marks: a moving camera, an object wandering over a textured wall, dense
    /// candidates, a restart halfway.
    #[test]
    fn the_incremental_sweep_matches_the_reference() {
        let mut rng = crate::xorshift::XorShift64::new(0x2545_f491_4f6c_dd1d);
        let mut next = move |n: u64| rng.next_u64() % n;
        let frames = 40;
        let scenes: Vec<_> = (0..frames)
            .map(|index| {
                let world_from_camera =
                    Isometry3::translation(0.01 * index as f64, 0.002 * index as f64, 0.0)
                        * nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.003 * index as f64, 0.0);
                let (ox, oy) = (4 + (index as usize % 20), 6 + (index as usize / 3) % 10);
                let mask: Vec<usize> = (0..SIZE.area())
                    .filter(|&i| (i % SIZE.width).abs_diff(ox) <= 2 && (i / SIZE.width).abs_diff(oy) <= 2)
                    .filter(|_| next(4) != 0)
                    .collect();
                let mut candidates = Vec::new();
                for i in 0..SIZE.area() as u32 {
                    if next(5) < 2 {
                        candidates.push((i, 1.5 + next(100) as f32 * 0.01));
                    }
                }
                (index, world_from_camera, mask, candidates, index == 23)
            })
            .collect();
        let run = |sweep: fn(&mut Hysteresis)| {
            let mut h = hysteresis(6);
            let mut emitted = Vec::new();
            for (index, world_from_camera, marked, candidates, reset) in &scenes {
                hold(&mut h, *index, *world_from_camera, marked, *reset);
                let mut keep = |out: FrameOutput<'_>| record(&out, &mut emitted);
                h.settle_with(&mut candidates.clone(), &mut keep, sweep)
                    .expect("emit");
            }
            let mut keep = |out: FrameOutput<'_>| record(&out, &mut emitted);
            h.flush(&mut keep).expect("emit");
            emitted
        };
        let incremental = run(Hysteresis::sweep);
        let reference = run(Hysteresis::sweep_reference);
        let added: usize = incremental
            .iter()
            .zip(&scenes)
            .map(|((_, marked), scene)| marked.len() - scene.2.len())
            .sum();
        assert!(
            added > 200,
            "the sweep marked only {added} pixels: the scene does not exercise it"
        );
        assert_eq!(incremental, reference);
    }
}
