//! Per-frame precision / recall / F1 of a moving-object mask, averaged over a sequence.
//!
//! As docs/method.md, "Evaluation": F1 = 2TP / (2TP + FP + FN) per frame (an empty prediction on
//! a non-empty ground truth scores 0, never NaN), averaged over the frames whose ground truth
//! is non-empty; frames with an empty ground truth contribute their false-positive pixel
//! fraction FP / (W·H) instead.

use crate::error::{Error, Result};
use crate::image_buf::{DepthMeters, Mask};

/// Pixel counts of one frame (a pixel is "set" when its mask value is non-zero).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameCounts {
    /// Set in both.
    pub true_positives: usize,
    /// Set in the prediction only.
    pub false_positives: usize,
    /// Set in the ground truth only.
    pub false_negatives: usize,
    /// Pixels in the frame.
    pub pixels: usize,
}

impl FrameCounts {
    /// Counts `predicted` against `truth`.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the masks differ in size.
    pub fn of(predicted: &Mask, truth: &Mask) -> Result<Self> {
        Self::count(predicted, truth, None)
    }

    /// Counts `predicted` against `truth` on the pixels where `depth_m` is valid (> 0) only:
    /// for a reference built from depth, which says nothing where the sensor saw none.
    /// `pixels` is then the number of such pixels.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the masks or the depth image differ in size.
    pub fn of_where_depth_valid(predicted: &Mask, truth: &Mask, depth_m: &DepthMeters) -> Result<Self> {
        Self::count(predicted, truth, Some(depth_m))
    }

    fn count(predicted: &Mask, truth: &Mask, depth_m: Option<&DepthMeters>) -> Result<Self> {
        for (what, found) in [
            ("predicted mask vs ground-truth mask", Some(predicted.size())),
            ("depth image vs ground-truth mask", depth_m.map(DepthMeters::size)),
        ] {
            if let Some(found) = found.filter(|&f| f != truth.size()) {
                return Err(Error::SizeMismatch {
                    what: what.into(),
                    expected: truth.size(),
                    found,
                });
            }
        }
        let mut counts = Self::default();
        let scored = |i: usize| depth_m.is_none_or(|d| d.as_slice()[i] > 0.0);
        for (i, (&p, &t)) in predicted.as_slice().iter().zip(truth.as_slice()).enumerate() {
            if !scored(i) {
                continue;
            }
            counts.pixels += 1;
            match (p != 0, t != 0) {
                (true, true) => counts.true_positives += 1,
                (true, false) => counts.false_positives += 1,
                (false, true) => counts.false_negatives += 1,
                (false, false) => {}
            }
        }
        Ok(counts)
    }

    /// True when the ground truth has no set pixel.
    pub fn truth_is_empty(&self) -> bool {
        self.true_positives + self.false_negatives == 0
    }

    /// 2TP / (2TP + FP + FN); 1 when both masks are empty.
    pub fn f1(&self) -> f64 {
        let denominator = 2 * self.true_positives + self.false_positives + self.false_negatives;
        if denominator == 0 {
            1.0
        } else {
            2.0 * self.true_positives as f64 / denominator as f64
        }
    }

    /// TP / (TP + FP); 1 when nothing is predicted.
    pub fn precision(&self) -> f64 {
        ratio_or_one(self.true_positives, self.true_positives + self.false_positives)
    }

    /// TP / (TP + FN); 1 when the ground truth is empty.
    pub fn recall(&self) -> f64 {
        ratio_or_one(self.true_positives, self.true_positives + self.false_negatives)
    }

    /// FP / pixels.
    pub fn false_positive_fraction(&self) -> f64 {
        self.false_positives as f64 / self.pixels.max(1) as f64
    }
}

fn ratio_or_one(numerator: usize, denominator: usize) -> f64 {
    if denominator == 0 {
        1.0
    } else {
        numerator as f64 / denominator as f64
    }
}

/// Running sums over a sequence.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SegmentationTally {
    frames_with_truth: usize,
    f1_sum: f64,
    precision_sum: f64,
    recall_sum: f64,
    empty_truth_frames: usize,
    empty_truth_fp_sum: f64,
    empty_truth_fp_max: f64,
    empty_truth_frames_with_fp: usize,
}

/// Sequence averages (NaN-free: means over zero frames are 0 and flagged by the counts).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SegmentationSummary {
    /// Frames with a non-empty ground truth (the F1 average's frames).
    pub frames_with_truth: usize,
    /// Mean per-frame F1 over those frames.
    pub mean_f1: f64,
    /// Mean per-frame precision over those frames.
    pub mean_precision: f64,
    /// Mean per-frame recall over those frames.
    pub mean_recall: f64,
    /// Frames with an empty ground truth.
    pub empty_truth_frames: usize,
    /// Mean false-positive pixel fraction over the empty-truth frames.
    pub empty_truth_mean_fp_fraction: f64,
    /// Largest false-positive pixel fraction on an empty-truth frame.
    pub empty_truth_max_fp_fraction: f64,
    /// Empty-truth frames with at least one false positive.
    pub empty_truth_frames_with_fp: usize,
}

impl SegmentationTally {
    /// Adds one frame.
    pub fn add(&mut self, counts: &FrameCounts) {
        if counts.truth_is_empty() {
            let fp = counts.false_positive_fraction();
            self.empty_truth_frames += 1;
            self.empty_truth_fp_sum += fp;
            self.empty_truth_fp_max = self.empty_truth_fp_max.max(fp);
            self.empty_truth_frames_with_fp += usize::from(counts.false_positives > 0);
        } else {
            self.frames_with_truth += 1;
            self.f1_sum += counts.f1();
            self.precision_sum += counts.precision();
            self.recall_sum += counts.recall();
        }
    }

    /// Counts `predicted` against `truth` and adds the frame.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the masks differ in size.
    pub fn add_masks(&mut self, predicted: &Mask, truth: &Mask) -> Result<FrameCounts> {
        let counts = FrameCounts::of(predicted, truth)?;
        self.add(&counts);
        Ok(counts)
    }

    /// As [`Self::add_masks`], on the pixels where `depth_m` is valid only
    /// ([`FrameCounts::of_where_depth_valid`]).
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the masks or the depth image differ in size.
    pub fn add_masks_where_depth_valid(
        &mut self,
        predicted: &Mask,
        truth: &Mask,
        depth_m: &DepthMeters,
    ) -> Result<FrameCounts> {
        let counts = FrameCounts::of_where_depth_valid(predicted, truth, depth_m)?;
        self.add(&counts);
        Ok(counts)
    }

    /// The averages so far.
    pub fn summary(&self) -> SegmentationSummary {
        let n = self.frames_with_truth.max(1) as f64;
        SegmentationSummary {
            frames_with_truth: self.frames_with_truth,
            mean_f1: self.f1_sum / n,
            mean_precision: self.precision_sum / n,
            mean_recall: self.recall_sum / n,
            empty_truth_frames: self.empty_truth_frames,
            empty_truth_mean_fp_fraction: self.empty_truth_fp_sum / self.empty_truth_frames.max(1) as f64,
            empty_truth_max_fp_fraction: self.empty_truth_fp_max,
            empty_truth_frames_with_fp: self.empty_truth_frames_with_fp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_buf::{Image, ImageSize, MASK_SET};

    fn mask(bits: &[u8]) -> Mask {
        Image::from_vec(
            ImageSize::new(bits.len(), 1),
            bits.iter().map(|&b| b * MASK_SET).collect(),
        )
        .unwrap()
    }

    #[test]
    fn counts_and_scores_match_hand_computation() {
        let counts = FrameCounts::of(&mask(&[1, 1, 1, 0, 0, 1]), &mask(&[1, 1, 0, 1, 0, 0])).unwrap();
        assert_eq!(
            (
                counts.true_positives,
                counts.false_positives,
                counts.false_negatives
            ),
            (2, 2, 1)
        );
        assert!((counts.f1() - 4.0 / 7.0).abs() < 1e-12);
        assert!((counts.precision() - 0.5).abs() < 1e-12);
        assert!((counts.recall() - 2.0 / 3.0).abs() < 1e-12);
        // F1 is the harmonic mean of precision and recall.
        let harmonic = 2.0 * counts.precision() * counts.recall() / (counts.precision() + counts.recall());
        assert!((counts.f1() - harmonic).abs() < 1e-12);
    }

    #[test]
    fn pixels_without_depth_are_not_scored() {
        let depth =
            DepthMeters::from_vec(ImageSize::new(6, 1), vec![1.0, 0.0, 1.0, f32::NAN, 1.0, 0.0]).unwrap();
        let (predicted, truth) = (mask(&[1, 1, 1, 0, 0, 1]), mask(&[1, 1, 0, 1, 0, 0]));
        let counts = FrameCounts::of_where_depth_valid(&predicted, &truth, &depth).unwrap();
        // Pixels 1, 3 and 5 have no depth: TP at 0, FP at 2, pixel 4 agrees.
        assert_eq!(
            (
                counts.true_positives,
                counts.false_positives,
                counts.false_negatives,
                counts.pixels
            ),
            (1, 1, 0, 3)
        );
        let all = FrameCounts::of(&predicted, &truth).unwrap();
        assert_eq!(all.pixels, 6);
    }

    #[test]
    fn empty_prediction_on_non_empty_truth_scores_zero_and_empty_truth_frames_count_fp() {
        let mut tally = SegmentationTally::default();
        tally
            .add_masks(&mask(&[0, 0, 0, 0]), &mask(&[1, 1, 0, 0]))
            .unwrap();
        tally
            .add_masks(&mask(&[1, 1, 0, 0]), &mask(&[1, 1, 0, 0]))
            .unwrap();
        tally
            .add_masks(&mask(&[1, 0, 0, 0]), &mask(&[0, 0, 0, 0]))
            .unwrap();
        tally
            .add_masks(&mask(&[0, 0, 0, 0]), &mask(&[0, 0, 0, 0]))
            .unwrap();
        let s = tally.summary();
        assert_eq!(s.frames_with_truth, 2);
        assert!((s.mean_f1 - 0.5).abs() < 1e-12);
        assert_eq!(s.empty_truth_frames, 2);
        assert!((s.empty_truth_mean_fp_fraction - 0.125).abs() < 1e-12);
        assert!((s.empty_truth_max_fp_fraction - 0.25).abs() < 1e-12);
        assert_eq!(s.empty_truth_frames_with_fp, 1);
        assert!(FrameCounts::of(&mask(&[0]), &mask(&[0, 0])).is_err());
        let depth = DepthMeters::filled(ImageSize::new(1, 1), 1.0);
        assert!(FrameCounts::of_where_depth_valid(&mask(&[0, 0]), &mask(&[0, 0]), &depth).is_err());
    }
}
