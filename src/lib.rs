//! occmask: RGB-D datasets to MCAP, dense visual odometry and occlusion-accumulation
//! moving-object masks (Kim, Kim & Kim, ICRA 2020).
//!
//! Layers, each depending only on those above it in this list:
//! 1. core types and math: [`error`], [`image_buf`], [`time`], [`geometry`], [`trajectory`];
//! 2. pure algorithms (no files, no MCAP, no printing): pyramid, dvo, occlusion, metrics,
//!    registration (undistortion and depth registration), point_cloud, synthetic;
//! 3. I/O adapters: dataset readers, MCAP reading and writing;
//! 4. the per-sequence pipeline, and its scoring on synthetic scenarios ([`scenario_eval`]);
//! 5. the command-line interface (in the binary).
//!
//! # Embedding
//!
//! The entry types are re-exported here: a per-sequence [`Processor`] (configured by
//! [`ProcessorConfig`]: pose source, [`DvoTracker`] and [`OcclusionDetector`] parameters) for
//! frames you already have in memory (see [`pipeline`]); [`process_file`] for an RGB-D MCAP
//! file read through [`McapInput`]; [`convert_sequence`] for a dataset folder read by
//! [`dataset::tum::load`] or [`dataset::larr::load`]; [`evaluate()`] to score an annotated file.
//! A whole round trip on a tiny synthetic recording:
//!
//! ```
//! use occmask::image_buf::ImageSize;
//! use occmask::mcap_io::McapWriteOptions;
//! use occmask::process::{pipeline_factory, NoHooks, PipelineOptions};
//! use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};
//! use occmask::{evaluate, process_file, McapInput, ProcessConfig};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let (input_path, output_path) = (dir.path().join("in.mcap"), dir.path().join("out.mcap"));
//! let sequence = SyntheticSequence::new(
//!     Scenario::SmallObjectCrossing,
//!     SequenceConfig { size: ImageSize::new(80, 60), frame_count: Some(4), ..SequenceConfig::default() },
//! );
//! let file = std::fs::File::create(&input_path).unwrap();
//! occmask::convert::write_synthetic_sequence(&sequence, file, &McapWriteOptions::default(), &mut |_| {
//!     std::ops::ControlFlow::Continue(())
//! })?;
//!
//! let input = McapInput::open(&input_path)?;
//! let (_, report) = process_file(
//!     &input,
//!     std::fs::File::create(&output_path).unwrap(),
//!     &ProcessConfig::default(),
//!     &mut pipeline_factory(PipelineOptions::default()),
//!     &mut NoHooks,
//! )?;
//! assert_eq!(report.frames, 4);
//! let scores = evaluate(&output_path)?;
//! assert_eq!(scores.estimated_masks, 4);
//! # Ok::<(), occmask::Error>(())
//! ```
//!
//! Each entry type has its own example: [`Processor`] in [`pipeline`], [`DvoTracker`] in
//! [`dvo`], [`convert_sequence`] (with [`McapInput::from_bytes`]) on its page, the dataset
//! readers on [`dataset::tum::load`] and [`dataset::larr::load`], [`evaluate()`] on its page.
//! [`OcclusionDetector`] alone, fed ground-truth motion:
//!
//! ```
//! use occmask::image_buf::ImageSize;
//! use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};
//! use occmask::{OcclusionConfig, OcclusionDetector};
//!
//! let config = SequenceConfig { size: ImageSize::new(160, 120), ..SequenceConfig::default() };
//! let sequence = SyntheticSequence::new(Scenario::SmallObjectCrossing, config);
//! let mut detector = OcclusionDetector::new(config.size, config.intrinsics(), OcclusionConfig::default())?;
//! for i in 0..6 {
//!     let frame = sequence.frame(i);
//!     let mask = detector.update(&frame.depth_m, &sequence.current_from_previous(i))?;
//!     assert_eq!(mask.size(), config.size);
//!     if i == 0 {
//!         // The first frame only initialises the state.
//!         assert!(mask.as_slice().iter().all(|&m| m == 0));
//!     }
//! }
//! assert_eq!(detector.frames_processed(), 6);
//! # Ok::<(), occmask::Error>(())
//! ```
#![deny(missing_docs)]

pub(crate) mod contour;
pub mod convert;
pub mod dataset;
pub mod dvo;
pub mod error;
pub mod evaluate;
pub mod geometry;
pub mod image_buf;
pub mod mcap_io;
pub mod metrics;
pub mod occlusion;
pub mod pipeline;
pub mod point_cloud;
pub mod process;
pub mod pyramid;
pub mod registration;
pub mod scenario_eval;
pub(crate) mod serde_util;
pub mod simd;
pub mod synthetic;
pub mod time;
pub mod trajectory;
pub(crate) mod xorshift;

pub use convert::{convert_sequence, ConvertConfig, ConvertReport};
pub use dataset::{DatasetKind, Sequence};
pub use dvo::{DvoConfig, DvoTracker};
pub use error::{Error, Result};
pub use evaluate::{evaluate, EvalReport};
pub use mcap_io::input::McapInput;
pub use occlusion::{OcclusionConfig, OcclusionDetector};
pub use pipeline::{FrameInput, FrameOutput, FrameResult, PoseSource, Processor, ProcessorConfig};
pub use process::{process_file, ProcessConfig, ProcessReport};
