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
#![deny(missing_docs)]

pub mod contour;
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
pub mod synthetic;
pub mod time;
pub mod trajectory;

pub use error::{Error, Result};
