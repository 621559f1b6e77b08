//! Colour–depth pairing of `occmask process`: greedy nearest-stamp matching of two streams in
//! time order, within a tolerance, with a bounded wait for a partner.
//!
//! Not the rule of the dataset readers ([`crate::dataset::associate`], as TUM's `associate.py`,
//! sees both whole lists and repeatedly takes the globally closest free pair): here the streams
//! arrive message by message, so the oldest colour image is paired with the nearest depth image
//! as soon as no later one can be closer.

use std::collections::VecDeque;

use crate::image_buf::{DepthMeters, GrayF32};

/// Images waiting for a partner, per stream; beyond this the oldest is counted unpaired.
/// 64 frames is 2 s at 30 Hz, far more than any real colour/depth skew.
pub const MAX_QUEUED_IMAGES: usize = 64;

/// Decoded pixels of a queued image.
pub(super) enum Pixels {
    Gray(GrayF32),
    Depth(DepthMeters),
}

#[cfg(doc)]
use crate::point_cloud::PointGrid;

/// A colour or depth image, decoded by the prefetch thread, waiting for its partner.
pub(super) struct Queued {
    pub(super) log_time_ns: u64,
    pub(super) timestamp_ns: u64,
    pub(super) frame_id: String,
    pub(super) pixels: Pixels,
    pub(super) decode_ms: f64,
    /// Seconds of it spent undistorting and registering.
    pub(super) rectify_s: f64,
    /// A colour image's colours at the [`PointGrid`] samples (`--points`).
    pub(super) point_colors: Option<Vec<[u8; 3]>>,
}

/// What [`Pairer::next`] decided about the oldest waiting image(s).
pub(super) enum Pairing {
    Pair(Box<(Queued, Queued)>),
    UnpairedColor,
    UnpairedDepth,
}

/// Greedy nearest-stamp pairing over two streams in time order.
pub(super) struct Pairer {
    pub(super) color: VecDeque<Queued>,
    pub(super) depth: VecDeque<Queued>,
    pub(super) tolerance_ns: u64,
}

impl Pairer {
    /// Empty queues; colour and depth pair when their stamps are at most `tolerance_ns` apart.
    pub(super) fn new(tolerance_ns: u64) -> Self {
        Self {
            color: VecDeque::new(),
            depth: VecDeque::new(),
            tolerance_ns,
        }
    }

    /// The next decision, `None` while a later image could still change it (`end_of_stream`:
    /// none will come).
    pub(super) fn next(&mut self, end_of_stream: bool) -> Option<Pairing> {
        let tol = self.tolerance_ns;
        let (Some(c), Some(d)) = (self.color.front(), self.depth.front()) else {
            if (end_of_stream || self.color.len() > MAX_QUEUED_IMAGES) && self.color.pop_front().is_some() {
                return Some(Pairing::UnpairedColor);
            }
            if (end_of_stream || self.depth.len() > MAX_QUEUED_IMAGES) && self.depth.pop_front().is_some() {
                return Some(Pairing::UnpairedDepth);
            }
            return None;
        };
        let (tc, td) = (c.timestamp_ns, d.timestamp_ns);
        if td.saturating_add(tol) < tc {
            self.depth.pop_front();
            return Some(Pairing::UnpairedDepth);
        }
        if tc.saturating_add(tol) < td {
            self.color.pop_front();
            return Some(Pairing::UnpairedColor);
        }
        let ready = match self.depth.get(1) {
            Some(d2) => {
                if tc.abs_diff(d2.timestamp_ns) < tc.abs_diff(td) {
                    self.depth.pop_front();
                    return Some(Pairing::UnpairedDepth);
                }
                true
            }
            // A later depth could only be closer if this one is earlier than the colour.
            None => end_of_stream || td >= tc || self.color.len() > MAX_QUEUED_IMAGES,
        };
        if !ready {
            return None;
        }
        let c = self.color.pop_front()?;
        let d = self.depth.pop_front()?;
        Some(Pairing::Pair(Box::new((c, d))))
    }

    /// Log time of the oldest colour image still waiting (new messages will be written then).
    pub(super) fn oldest_color_log_time(&self) -> Option<u64> {
        self.color.iter().map(|q| q.log_time_ns).min()
    }
}
