//! Evaluation metrics (pure): segmentation scores of masks against ground truth,
//! trajectory errors (RPE with TUM `evaluate_rpe` semantics, ATE after rigid alignment) and the
//! onset of a detection ([`onset`]); definitions in docs/method.md, "Evaluation".

pub mod free_space;
pub mod onset;
pub mod segmentation;
pub mod trajectory;

pub use segmentation::{FrameCounts, SegmentationSummary, SegmentationTally};
pub use trajectory::{ate, rpe, rpe_stamped, AteStats, RpeStats};
