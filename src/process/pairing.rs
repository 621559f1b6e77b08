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
    /// Not decoded: the image lies outside the time range, so no frame that is processed can
    /// use it ([`TimeRange::may_use`]); it is still paired and counted.
    Skipped,
}

/// The frames `process` keeps (`--start`, `--end`): colour stamps in
/// `[first + start, first + end)`, `first` being the first colour image's stamp.
#[derive(Debug, Clone, Copy)]
pub(super) struct TimeRange {
    pub(super) start_offset_ns: Option<u64>,
    pub(super) end_offset_ns: Option<u64>,
    /// Colour and depth pair within this; a depth image this close to the range may be used.
    pub(super) pair_tolerance_ns: u64,
}

impl TimeRange {
    /// The range `config` asks for.
    pub(super) fn of(config: &super::ProcessConfig) -> Self {
        Self {
            start_offset_ns: config.start_offset_ns,
            end_offset_ns: config.end_offset_ns,
            pair_tolerance_ns: config.pair_tolerance_ns,
        }
    }

    /// Whether a frame whose colour image is stamped `stamp_ns` is processed.
    pub(super) fn keeps(&self, stamp_ns: u64, first_color_ns: u64) -> bool {
        let offset = stamp_ns.saturating_sub(first_color_ns);
        !(self.start_offset_ns.is_some_and(|s| offset < s) || self.is_past_end(stamp_ns, first_color_ns))
    }

    /// Whether a colour image stamped `stamp_ns` is at or past the end of the range.
    pub(super) fn is_past_end(&self, stamp_ns: u64, first_color_ns: u64) -> bool {
        self.end_offset_ns
            .is_some_and(|e| stamp_ns.saturating_sub(first_color_ns) >= e)
    }

    /// Whether an image stamped `stamp_ns` may be part of a processed frame: a colour image
    /// that [`Self::keeps`]; a depth image within the pairing tolerance of one that it keeps; any
    /// image while the first colour stamp is unknown.
    pub(super) fn may_use(&self, is_color: bool, stamp_ns: u64, first_color_ns: Option<u64>) -> bool {
        let Some(first) = first_color_ns else {
            return true;
        };
        if is_color {
            return self.keeps(stamp_ns, first);
        }
        let earliest = stamp_ns.saturating_sub(self.pair_tolerance_ns);
        let latest = stamp_ns.saturating_add(self.pair_tolerance_ns);
        // Kept colour stamps form one interval: a depth image may be used when the stamps its
        // partner can have meet it. (With a start of 0, colour stamped before the first colour
        // image is kept too, at offset 0.)
        let before_start = self
            .start_offset_ns
            .is_some_and(|s| s > 0 && latest < first.saturating_add(s));
        let after_end = self
            .end_offset_ns
            .is_some_and(|e| earliest >= first && earliest - first >= e);
        !(before_start || after_end)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;
    const FIRST: u64 = 1_000 * MS;

    fn range(start_ms: Option<u64>, end_ms: Option<u64>) -> TimeRange {
        TimeRange {
            start_offset_ns: start_ms.map(|s| s * MS),
            end_offset_ns: end_ms.map(|e| e * MS),
            pair_tolerance_ns: 20 * MS,
        }
    }

    #[test]
    fn colour_images_are_kept_from_the_start_up_to_the_end() {
        let r = range(Some(100), Some(200));
        let kept: Vec<u64> = (0..30)
            .map(|k| k * 10)
            .filter(|&ms| r.keeps(FIRST + ms * MS, FIRST))
            .collect();
        assert_eq!(kept, (10..20).map(|k| k * 10).collect::<Vec<_>>());
        assert!(!r.is_past_end(FIRST + 199 * MS, FIRST) && r.is_past_end(FIRST + 200 * MS, FIRST));
        for (is_color, ms) in [(true, 100), (true, 199), (false, 100)] {
            assert!(
                r.may_use(is_color, FIRST + ms * MS, Some(FIRST)),
                "{is_color} {ms}"
            );
        }
        assert!(!r.may_use(true, FIRST + 200 * MS, Some(FIRST)));
        assert!(range(None, None).keeps(FIRST + 99_000 * MS, FIRST));
    }

    #[test]
    fn a_depth_image_is_used_when_a_kept_colour_image_can_pair_with_it() {
        let r = range(Some(100), Some(200));
        // Within the tolerance (20 ms) of the kept stamps [100, 200) ms.
        for ms in [80, 100, 199, 219] {
            assert!(r.may_use(false, FIRST + ms * MS, Some(FIRST)), "{ms} ms");
        }
        for ms in [0, 79, 220, 5_000] {
            assert!(!r.may_use(false, FIRST + ms * MS, Some(FIRST)), "{ms} ms");
        }
        // Before the first colour image is known, every image is decoded.
        assert!(r.may_use(false, 0, None) && r.may_use(true, 0, None));
        // A start of 0 keeps colour stamped before the first one (offset 0): no depth before it
        // is skipped for being early.
        assert!(range(Some(0), None).may_use(false, FIRST - 500 * MS, Some(FIRST)));
        // Stamps near 0 do not wrap.
        assert!(range(None, Some(200)).may_use(false, 5 * MS, Some(10 * MS)));
    }
}
