//! Evaluation metrics (pure): segmentation scores of masks against ground truth
//! (algorithm.md §7.1, §9-Q11) and trajectory errors (RPE with TUM `evaluate_rpe` semantics,
//! ATE after rigid alignment, §7.2).

pub mod free_space;
pub mod segmentation;
pub mod trajectory;

pub use segmentation::{FrameCounts, SegmentationSummary, SegmentationTally};
pub use trajectory::{ate, rpe, rpe_stamped, AteStats, RpeStats};
