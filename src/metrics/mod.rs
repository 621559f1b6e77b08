//! Evaluation metrics (pure): segmentation scores of masks against ground truth
//! and trajectory errors (RPE with TUM `evaluate_rpe` semantics, ATE after rigid alignment);
//! definitions in docs/method.md, "Evaluation".

pub mod free_space;
pub mod segmentation;
pub mod trajectory;

pub use segmentation::{FrameCounts, SegmentationSummary, SegmentationTally};
pub use trajectory::{ate, rpe, rpe_stamped, AteStats, RpeStats};
