//! Detection onset: how many frames after an object starts to move or enters the view a mask
//! first covers half of it.
//!
//! Per object, the frames in which it has ground-truth pixels (it is seen and moved since the
//! previous frame) fall into **runs** of consecutive frames: an object that stops leaves the
//! ground truth and starts a new run when it moves again, an object that leaves the view (or is
//! hidden behind another) starts a new run when it is seen again. For the run that starts at
//! frame `s`, the **onset** is `d = f − s` for the first frame `f ≥ s` of the run whose
//! per-object recall (the object's ground-truth pixels set in the mask, over its ground-truth
//! pixels) reaches [`ONSET_RECALL`]: 0 when the mask covers half the object in the very frame
//! it starts moving or enters, `None` when no frame of the run reaches it. An entering object's
//! first frames, when only a sliver of it is in view, count like any other.

use crate::error::{Error, Result};
use crate::image_buf::{ImageSize, Mask};
use crate::occlusion::runs::RunLabelling;

/// Per-object recall that ends a run's onset: half of the object is in the mask.
pub const ONSET_RECALL: f64 = 0.5;

/// The onset target: an object is half masked within this many frames of starting to move or
/// entering the view (the synthetic failure classes' bound, and what the real recordings'
/// reports count as prompt).
pub const ONSET_TARGET_FRAMES: usize = 5;

/// One run of an object's ground truth (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct OnsetRun {
    /// Index of the object.
    pub object: usize,
    /// First frame of the run (the object starts to move or enters the view).
    pub first_frame: usize,
    /// Last frame of the run.
    pub last_frame: usize,
    /// Frames from `first_frame` to the first frame whose recall reaches [`ONSET_RECALL`];
    /// `None` when no frame of the run reaches it.
    pub onset_frames: Option<usize>,
}

/// Collects the runs of every object frame by frame.
#[derive(Debug, Clone, Default)]
pub struct OnsetTracker {
    /// Per object: the open run, if the object had ground truth in the latest frame.
    open: Vec<Option<OnsetRun>>,
    finished: Vec<OnsetRun>,
    next_frame: usize,
}

impl OnsetTracker {
    /// A tracker with no frame yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the next frame: per object, its ground-truth pixel count and how many of those
    /// pixels the mask covers (`(truth, detected)`, `detected ≤ truth`). Objects beyond the
    /// slice's length have no ground truth in this frame.
    pub fn add_frame(&mut self, per_object: &[(usize, usize)]) {
        let frame = self.next_frame;
        self.next_frame += 1;
        if self.open.len() < per_object.len() {
            self.open.resize(per_object.len(), None);
        }
        for (object, open) in self.open.iter_mut().enumerate() {
            let (truth, detected) = per_object.get(object).copied().unwrap_or((0, 0));
            if truth == 0 {
                if let Some(run) = open.take() {
                    self.finished.push(run);
                }
                continue;
            }
            let run = open.get_or_insert(OnsetRun {
                object,
                first_frame: frame,
                last_frame: frame,
                onset_frames: None,
            });
            run.last_frame = frame;
            let recall = detected as f64 / truth as f64;
            if run.onset_frames.is_none() && recall >= ONSET_RECALL {
                run.onset_frames = Some(frame - run.first_frame);
            }
        }
    }

    /// Every run, closed and still open, by first frame then object.
    pub fn runs(&self) -> Vec<OnsetRun> {
        let mut runs: Vec<OnsetRun> = self
            .finished
            .iter()
            .chain(self.open.iter().flatten())
            .copied()
            .collect();
        runs.sort_by_key(|r| (r.first_frame, r.object));
        runs
    }
}

/// The largest onset over `runs`: `Some(None)` when a run never reaches [`ONSET_RECALL`],
/// `None` when there is no run.
pub fn worst_onset(runs: &[OnsetRun]) -> Option<Option<usize>> {
    runs.iter()
        .map(|r| r.onset_frames)
        .reduce(|worst, onset| match (worst, onset) {
            (Some(a), Some(b)) => Some(a.max(b)),
            _ => None,
        })
}

/// What a set of runs adds up to, for a report: how many runs there are, how many are half
/// covered in their first frame and within `prompt_frames` of it, and the others (displayed
/// as `runs N, onset 0 in A, ≤ P frames in B; late: F–L never, …`, a late run by its first and
/// last frame and its onset).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct OnsetSummary {
    /// Runs.
    pub runs: usize,
    /// Runs with onset 0.
    pub immediate: usize,
    /// The onset that still counts as prompt.
    pub prompt_frames: usize,
    /// Runs with onset at most `prompt_frames`.
    pub prompt: usize,
    /// The other runs, by first frame.
    pub late: Vec<OnsetRun>,
}

impl OnsetSummary {
    /// The summary of `runs`.
    pub fn new(runs: &[OnsetRun], prompt_frames: usize) -> Self {
        let onset_within = |frames: usize| {
            runs.iter()
                .filter(|r| r.onset_frames.is_some_and(|d| d <= frames))
                .count()
        };
        Self {
            runs: runs.len(),
            immediate: onset_within(0),
            prompt_frames,
            prompt: onset_within(prompt_frames),
            late: runs
                .iter()
                .filter(|r| r.onset_frames.is_none_or(|d| d > prompt_frames))
                .copied()
                .collect(),
        }
    }
}

impl std::fmt::Display for OnsetSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "runs {}, onset 0 in {}, ≤ {} frames in {}; late:",
            self.runs, self.immediate, self.prompt_frames, self.prompt
        )?;
        if self.late.is_empty() {
            return write!(f, " none");
        }
        for (i, run) in self.late.iter().enumerate() {
            let separator = if i == 0 { " " } else { ", " };
            let onset = run.onset_frames.map_or("never".to_owned(), |d| d.to_string());
            write!(f, "{separator}{}–{} {onset}", run.first_frame, run.last_frame)?;
        }
        Ok(())
    }
}

/// The smallest region of a real recording's reference that [`RegionTracker::for_reference`]
/// counts as a person, as a share of the image (1 536 pixels at 640×480): a person's torso at
/// 5 m; smaller regions are slivers at the border or limbs cut off from their body.
pub const REFERENCE_REGION_MIN_IMAGE_FRACTION: f64 = 0.005;

/// Objects for [`OnsetTracker`] from masks without object identities (the free-space reference
/// of a real recording, [`super::free_space`]): each 8-connected region of the reference mask
/// with at least `min_region_pixels` pixels is an object, and it keeps the object of the
/// previous frame's region it shares the most pixels with when those are at least half of the
/// smaller of the two. Pairs are taken greedily by shared pixels, so when a region splits, the
/// part sharing the most keeps the object and the other starts a new one; when two merge, the
/// object sharing the most goes on and the other's run ends. A region with no such
/// predecessor (it enters the view, starts to move, or grows past the size) starts a new object.
/// Smaller regions (slivers at the border, a limb cut off from its body) are no object: a
/// person's run starts once their region reaches the size.
#[derive(Debug, Clone)]
pub struct RegionTracker {
    size: ImageSize,
    min_region_pixels: usize,
    labelling: RunLabelling,
    /// Per pixel, 1 + the object of the region covering it (0: none), previous frame and this.
    previous_objects: Vec<u32>,
    current_objects: Vec<u32>,
    /// Pixels of each object's region in the previous frame (0 when it had none).
    previous_pixels: Vec<usize>,
}

impl RegionTracker {
    /// A tracker for `size` masks; regions under `min_region_pixels` are no object.
    pub fn new(size: ImageSize, min_region_pixels: usize) -> Self {
        Self {
            size,
            min_region_pixels,
            labelling: RunLabelling::new(size.width, size.height),
            previous_objects: vec![0; size.area()],
            current_objects: vec![0; size.area()],
            previous_pixels: Vec::new(),
        }
    }

    /// A tracker of a reference's people: regions of at least
    /// [`REFERENCE_REGION_MIN_IMAGE_FRACTION`] of the image.
    pub fn for_reference(size: ImageSize) -> Self {
        let min_pixels = (REFERENCE_REGION_MIN_IMAGE_FRACTION * size.area() as f64).round() as usize;
        Self::new(size, min_pixels)
    }

    /// Objects so far.
    pub fn objects(&self) -> usize {
        self.previous_pixels.len()
    }

    /// Adds the next frame's `reference` (nonzero = moving) and the `mask` scored against it;
    /// returns, per object so far, its reference pixels in this frame and how many of them
    /// `mask` sets (`(0, 0)` for an object not in this frame), as [`OnsetTracker::add_frame`]
    /// takes them.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when a mask is not of the tracker's size.
    pub fn add_frame(&mut self, reference: &Mask, mask: &Mask) -> Result<Vec<(usize, usize)>> {
        for (what, found) in [("onset reference", reference.size()), ("onset mask", mask.size())] {
            if found != self.size {
                return Err(Error::SizeMismatch {
                    what: what.into(),
                    expected: self.size,
                    found,
                });
            }
        }
        let width = self.size.width;
        let regions = self
            .labelling
            .label(reference.as_slice(), width, width, self.size.height, (0, 0));
        let counted: Vec<usize> = (0..regions)
            .filter(|&k| self.labelling.pixels(k) >= self.min_region_pixels)
            .collect();
        // Candidate links (shared pixels, region, object): the pixels each counted region
        // shares with each previous object.
        let mut links = Vec::new();
        let mut shared: Vec<(u32, usize)> = Vec::new();
        for (r, &k) in counted.iter().enumerate() {
            shared.clear();
            for run in self.labelling.runs(k) {
                for &o in &self.previous_objects[run.pixels(width)] {
                    if o == 0 {
                        continue;
                    }
                    match shared.iter_mut().find(|(object, _)| *object == o - 1) {
                        Some((_, n)) => *n += 1,
                        None => shared.push((o - 1, 1)),
                    }
                }
            }
            let pixels = self.labelling.pixels(k);
            for &(object, n) in &shared {
                if 2 * n >= pixels.min(self.previous_pixels[object as usize]) {
                    links.push((n, r, object));
                }
            }
        }
        // Greedy by shared pixels (ties: the earlier region, then the older object).
        links.sort_by_key(|&(n, r, object)| (std::cmp::Reverse(n), r, object));
        let mut object_of = vec![None; counted.len()];
        let mut taken = vec![false; self.previous_pixels.len()];
        for &(_, r, object) in &links {
            if object_of[r].is_none() && !taken[object as usize] {
                object_of[r] = Some(object);
                taken[object as usize] = true;
            }
        }
        let mut counts = vec![(0, 0); self.previous_pixels.len()];
        self.current_objects.fill(0);
        let (set, current) = (mask.as_slice(), &mut self.current_objects);
        for (r, &k) in counted.iter().enumerate() {
            let object = *object_of[r].get_or_insert_with(|| {
                counts.push((0, 0));
                (counts.len() - 1) as u32
            });
            let count = &mut counts[object as usize];
            for run in self.labelling.runs(k) {
                let pixels = run.pixels(width);
                count.0 += pixels.len();
                count.1 += set[pixels.clone()].iter().filter(|&&v| v != 0).count();
                current[pixels].fill(object + 1);
            }
        }
        std::mem::swap(&mut self.previous_objects, &mut self.current_objects);
        self.previous_pixels.clear();
        self.previous_pixels
            .extend(counts.iter().map(|&(truth, _)| truth));
        Ok(counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_split_where_the_ground_truth_is_empty_and_onset_counts_from_each_start() {
        let mut tracker = OnsetTracker::new();
        // Object 0: frames 1–4 (recall 0, 0.2, 0.5, 1), gone in frame 5, back in 6–7 (0.4, 0.6).
        // Object 1: frames 2–7, never half covered.
        let frames: [&[(usize, usize)]; 8] = [
            &[(0, 0)],
            &[(10, 0)],
            &[(10, 2), (4, 1)],
            &[(10, 5), (4, 1)],
            &[(10, 10), (4, 1)],
            &[(0, 0), (4, 1)],
            &[(10, 4), (4, 1)],
            &[(10, 6), (4, 1)],
        ];
        for f in frames {
            tracker.add_frame(f);
        }
        let runs = tracker.runs();
        assert_eq!(
            runs,
            vec![
                OnsetRun {
                    object: 0,
                    first_frame: 1,
                    last_frame: 4,
                    onset_frames: Some(2)
                },
                OnsetRun {
                    object: 1,
                    first_frame: 2,
                    last_frame: 7,
                    onset_frames: None
                },
                OnsetRun {
                    object: 0,
                    first_frame: 6,
                    last_frame: 7,
                    onset_frames: Some(1)
                },
            ]
        );
        assert_eq!(worst_onset(&runs), Some(None));
        assert_eq!(worst_onset(&runs[..1]), Some(Some(2)));
        assert_eq!(worst_onset(&[runs[0], runs[2]]), Some(Some(2)));
        assert_eq!(worst_onset(&[]), None);
    }

    #[test]
    fn an_object_covered_in_its_first_frame_has_onset_zero() {
        let mut tracker = OnsetTracker::new();
        tracker.add_frame(&[(8, 4)]);
        assert_eq!(tracker.runs()[0].onset_frames, Some(0));
    }

    /// A `size` mask with the given rectangles (x0, y0, x1, y1; ends exclusive) set.
    fn rects(size: ImageSize, rects: &[(usize, usize, usize, usize)]) -> Mask {
        let mut mask = Mask::filled(size, 0);
        for &(x0, y0, x1, y1) in rects {
            for y in y0..y1 {
                mask.row_mut(y)[x0..x1].fill(255);
            }
        }
        mask
    }

    #[test]
    fn a_moving_region_stays_one_object_and_its_onset_is_counted_from_its_first_frame() {
        let size = ImageSize::new(64, 32);
        let mut regions = RegionTracker::new(size, 20);
        let mut onsets = OnsetTracker::new();
        for frame in 0..8 {
            // A 10×10 square moving 3 px a frame; the mask covers it from frame 3 on.
            let x = 2 + 3 * frame;
            let reference = rects(size, &[(x, 5, x + 10, 15)]);
            let mask = if frame >= 3 {
                reference.clone()
            } else {
                Mask::filled(size, 0)
            };
            let counts = regions.add_frame(&reference, &mask).unwrap();
            assert_eq!(counts, vec![(100, if frame >= 3 { 100 } else { 0 })]);
            onsets.add_frame(&counts);
        }
        assert_eq!(regions.objects(), 1);
        let runs = onsets.runs();
        assert_eq!(
            (runs.len(), runs[0].first_frame, runs[0].onset_frames),
            (1, 0, Some(3))
        );
    }

    #[test]
    fn small_regions_are_no_object_and_a_region_that_jumps_is_a_new_one() {
        let size = ImageSize::new(64, 32);
        let mut regions = RegionTracker::new(size, 20);
        let none = Mask::filled(size, 0);
        // Frame 0: a 4×4 sliver (under the size) and a 6×6 square; frame 1: the sliver grown to
        // 5×5, the square gone and a square far from it.
        let counts = regions
            .add_frame(&rects(size, &[(0, 0, 4, 4), (30, 10, 36, 16)]), &none)
            .unwrap();
        assert_eq!(counts, vec![(36, 0)]);
        let counts = regions
            .add_frame(&rects(size, &[(0, 0, 5, 5), (50, 20, 56, 26)]), &none)
            .unwrap();
        assert_eq!(counts, vec![(0, 0), (25, 0), (36, 0)]);
        assert_eq!(regions.objects(), 3);
    }

    #[test]
    fn a_split_region_keeps_its_object_in_the_larger_part_and_merging_ends_the_smaller_object() {
        let size = ImageSize::new(64, 32);
        let mut regions = RegionTracker::new(size, 4);
        let none = Mask::filled(size, 0);
        // One 20×4 bar, then its two halves apart (12 and 6 columns kept of it), then both
        // halves joined again with the right part's columns.
        let counts = regions
            .add_frame(&rects(size, &[(10, 10, 30, 14)]), &none)
            .unwrap();
        assert_eq!(counts, vec![(80, 0)]);
        let split = rects(size, &[(10, 10, 22, 14), (24, 10, 30, 14)]);
        let counts = regions.add_frame(&split, &split).unwrap();
        assert_eq!(counts, vec![(48, 48), (24, 24)]);
        let counts = regions
            .add_frame(&rects(size, &[(10, 10, 30, 14)]), &none)
            .unwrap();
        assert_eq!(counts, vec![(80, 0), (0, 0)]);
    }

    #[test]
    fn masks_of_another_size_are_errors() {
        let mut regions = RegionTracker::new(ImageSize::new(8, 8), 1);
        let small = Mask::filled(ImageSize::new(4, 4), 0);
        let right = Mask::filled(ImageSize::new(8, 8), 0);
        assert!(matches!(
            regions.add_frame(&small, &right),
            Err(Error::SizeMismatch { .. })
        ));
        assert!(matches!(
            regions.add_frame(&right, &small),
            Err(Error::SizeMismatch { .. })
        ));
    }

    #[test]
    fn the_summary_counts_prompt_runs_and_lists_the_late_ones() {
        let run = |first_frame, last_frame, onset_frames| OnsetRun {
            object: 0,
            first_frame,
            last_frame,
            onset_frames,
        };
        let runs = [
            run(0, 9, Some(0)),
            run(3, 8, Some(5)),
            run(4, 4, None),
            run(6, 20, Some(6)),
        ];
        let summary = OnsetSummary::new(&runs, 5);
        assert_eq!((summary.runs, summary.immediate, summary.prompt), (4, 1, 2));
        assert_eq!(summary.late, vec![runs[2], runs[3]]);
        assert_eq!(
            summary.to_string(),
            "runs 4, onset 0 in 1, ≤ 5 frames in 2; late: 4–4 never, 6–20 6"
        );
        assert_eq!(
            OnsetSummary::new(&runs[..1], 5).to_string(),
            "runs 1, onset 0 in 1, ≤ 5 frames in 1; late: none"
        );
    }
}
