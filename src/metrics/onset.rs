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

/// Per-object recall that ends a run's onset: half of the object is in the mask.
pub const ONSET_RECALL: f64 = 0.5;

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
}
