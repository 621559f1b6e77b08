//! TUM RGB-D sequences for the DVO and detector tests, read by the library's dataset reader
//! ([`occmask::dataset::tum`]: lists, ground truth, colour/depth pairing, decoding), plus the
//! relative-pose-error helpers the tests score with.

#![allow(dead_code)] // the benchmarks and examples that include this file use a subset

use std::path::Path;

use occmask::dataset::{
    self, DatasetKind, DecodedPair, FramePair, Sequence, DEFAULT_MAX_PAIR_GAP_NS, TUM_DEPTH_UNITS_PER_METER,
};
use occmask::trajectory::StampedPose;

/// A TUM-layout folder listed by the library, with its colour/depth pairs as `convert` pairs
/// them ([`Sequence::association`] at [`DEFAULT_MAX_PAIR_GAP_NS`]).
pub struct TumSequence {
    /// The listed folder (lists, ground truth).
    pub sequence: Sequence,
    /// Colour frames with their depth partners, in colour order.
    pub pairs: Vec<FramePair>,
}

impl TumSequence {
    /// Lists `dir` with [`dataset::tum::load`].
    pub fn load(dir: &Path) -> occmask::Result<Self> {
        let sequence = dataset::tum::load(dir, DatasetKind::Tum)?;
        let pairs = sequence.association(DEFAULT_MAX_PAIR_GAP_NS).pairs;
        Ok(Self { sequence, pairs })
    }

    /// The ground-truth trajectory.
    pub fn groundtruth(&self) -> &[StampedPose] {
        &self.sequence.groundtruth
    }

    /// Decodes pair `index` (gray in [0, 1], depth in metres at TUM's 5000 units per metre).
    pub fn frame(&self, index: usize) -> occmask::Result<DecodedPair> {
        self.decode(&self.pairs[index])
    }

    /// Decodes any colour/depth pair of the sequence at TUM's depth scale.
    pub fn decode(&self, pair: &FramePair) -> occmask::Result<DecodedPair> {
        dataset::decode_pair(&self.sequence, pair, TUM_DEPTH_UNITS_PER_METER)
    }

    /// Every depth frame with the colour frame nearest in time (colour may repeat): for
    /// sequences whose colour is not registered to depth (7-Scenes), where the depth drives.
    pub fn depth_with_nearest_color(&self) -> Vec<FramePair> {
        let color = &self.sequence.color;
        (0..self.sequence.depth.len())
            .filter_map(|depth| {
                let t = self.sequence.depth[depth].timestamp_ns;
                let nearest = (0..color.len()).min_by_key(|&c| color[c].timestamp_ns.abs_diff(t))?;
                Some(FramePair {
                    color: nearest,
                    depth,
                })
            })
            .collect()
    }
}

/// Largest gap between ground-truth samples to interpolate across (TUM mocap runs at
/// ≈ 100 Hz, so 50 ms tolerates a few dropped samples).
pub const GT_MAX_GAP_NS: u64 = 50_000_000;

/// Relative pose error of one estimated motion `current_from_reference` against the ground
/// truth b = Q_cur⁻¹·Q_ref, composed as TUM's evaluate_rpe (docs/method.md, "Evaluation"):
/// E = a⁻¹·b; returns (‖t(E)‖ in mm, angle(E) in degrees).
pub fn rpe(
    estimated_current_from_reference: &nalgebra::Isometry3<f64>,
    gt_current_from_reference: &nalgebra::Isometry3<f64>,
) -> (f64, f64) {
    let e = estimated_current_from_reference.inverse() * gt_current_from_reference;
    (
        e.translation.vector.norm() * 1000.0,
        e.rotation.angle().to_degrees(),
    )
}

/// Ground-truth motion between two frame times, or `None` when not covered.
pub fn gt_motion(gt: &[StampedPose], t_ref_ns: u64, t_cur_ns: u64) -> Option<nalgebra::Isometry3<f64>> {
    let a = occmask::trajectory::interpolate(gt, t_ref_ns, GT_MAX_GAP_NS)?;
    let b = occmask::trajectory::interpolate(gt, t_cur_ns, GT_MAX_GAP_NS)?;
    Some(occmask::trajectory::motion_between(&a, &b))
}

/// Root mean square.
pub fn rms(values: impl IntoIterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in values {
        s += v * v;
        n += 1;
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}
