//! The per-sequence algorithm behind a small boundary ([`FrameProcessor`]), so reading and
//! writing can be tested with any implementation, and the production implementation over the
//! pipeline ([`PipelineProcessor`]: causal or offline).

use crate::error::Result;
use crate::geometry::camera::PinholeIntrinsics;
use crate::image_buf::ImageSize;
use crate::pipeline::offline::ColourRegistration;
use crate::pipeline::{FrameInput, FrameResult, ProcessorConfig, SequenceProcessor};

#[cfg(doc)]
use super::ProcessConfig;

/// The per-sequence algorithm (DVO + detector) as [`super::process_file`] drives it.
pub trait FrameProcessor {
    /// Adds the next frame (frames come in time order) and returns the results that are final
    /// now, oldest first: one per frame for a causal processor, none and then a block of them
    /// for one that looks ahead.
    ///
    /// # Errors
    /// Whatever the algorithm reports (e.g. size mismatches).
    fn push(&mut self, frame: &FrameInput<'_>) -> Result<Vec<FrameResult>>;

    /// Hands the results still pending at the end of the input to `sink`, oldest first, each
    /// as soon as it is final (so writing them overlaps the work on the later ones).
    ///
    /// # Errors
    /// As [`Self::push`], and whatever `sink` returns.
    fn finish(&mut self, _sink: &mut FrameSink<'_>) -> Result<()> {
        Ok(())
    }

    /// What the offline mode's colour/depth registration check decided (`None` where it did
    /// not run).
    fn colour_registration(&self) -> Option<ColourRegistration> {
        None
    }
}

/// Takes the results of [`FrameProcessor::finish`] one at a time.
pub type FrameSink<'a> = dyn FnMut(FrameResult) -> Result<()> + 'a;

/// Builds the processor once intrinsics and image size are known, from
/// [`ProcessConfig::processor`] (pose source included).
pub type ProcessorFactory<'a> =
    dyn FnMut(PinholeIntrinsics, ImageSize, &ProcessorConfig) -> Result<Box<dyn FrameProcessor>> + 'a;

/// The per-sequence pipeline (DVO + detector, causal or offline, at the working resolution:
/// [`SequenceProcessor`]) behind [`FrameProcessor`].
pub struct PipelineProcessor {
    pipeline: SequenceProcessor,
    keep_accumulation: bool,
}

/// Choices of [`PipelineProcessor`] beyond the processor configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PipelineOptions {
    /// Copy the accumulation map into every [`FrameResult`] (`--accumulation`).
    pub keep_accumulation: bool,
}

impl PipelineProcessor {
    /// A pipeline with the pose source, DVO, detector and failure parameters of `config`
    /// ([`ProcessorConfig::mode`] picks causal or offline).
    ///
    /// # Errors
    /// Invalid intrinsics, image size or parameters, as [`SequenceProcessor::new`].
    pub fn new(
        intrinsics: PinholeIntrinsics,
        size: ImageSize,
        config: &ProcessorConfig,
        options: PipelineOptions,
    ) -> Result<Self> {
        Ok(Self {
            pipeline: SequenceProcessor::new(size, intrinsics, *config)?,
            keep_accumulation: options.keep_accumulation,
        })
    }
}

impl FrameProcessor for PipelineProcessor {
    fn push(&mut self, frame: &FrameInput<'_>) -> Result<Vec<FrameResult>> {
        let keep_accumulation = self.keep_accumulation;
        let mut done = Vec::new();
        self.pipeline.push(frame, &mut |out| {
            done.push(out.to_result(keep_accumulation));
            Ok(())
        })?;
        Ok(done)
    }

    fn finish(&mut self, sink: &mut FrameSink<'_>) -> Result<()> {
        let keep_accumulation = self.keep_accumulation;
        self.pipeline
            .finish(&mut |out| sink(out.to_result(keep_accumulation)))
    }

    fn colour_registration(&self) -> Option<ColourRegistration> {
        self.pipeline.colour_registration()
    }
}

/// The production [`ProcessorFactory`]: a [`PipelineProcessor`] per file.
pub fn pipeline_factory(
    options: PipelineOptions,
) -> impl FnMut(PinholeIntrinsics, ImageSize, &ProcessorConfig) -> Result<Box<dyn FrameProcessor>> {
    move |intrinsics, size, config| {
        Ok(Box::new(PipelineProcessor::new(intrinsics, size, config, options)?) as Box<dyn FrameProcessor>)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_buf::Mask;
    use crate::mcap_io::annotate::moving_pixels;
    use crate::pipeline::{PoseSource, ProcessingMode};
    use crate::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

    /// `--appearance-growth` reaches the detector: on a box that starts moving, the pipeline
    /// with the completion marks more of the box than the paper's.
    #[test]
    fn appearance_growth_option_switches_the_detector_stage() -> Result<()> {
        let config = SequenceConfig {
            size: ImageSize::new(320, 240),
            ..SequenceConfig::default()
        };
        let sequence = SyntheticSequence::new(Scenario::StillThenMoving, config);
        let run = |appearance_growth: bool| -> Result<u64> {
            let mut processor_config = ProcessorConfig {
                mode: ProcessingMode::Causal,
                pose_source: PoseSource::External {
                    camera_from_marker: None,
                },
                ..ProcessorConfig::default()
            };
            processor_config.occlusion.appearance_growth =
                appearance_growth.then(crate::occlusion::AppearanceGrowthConfig::default);
            let mut pipeline = PipelineProcessor::new(
                config.intrinsics(),
                config.size,
                &processor_config,
                PipelineOptions::default(),
            )?;
            let mut last_mask = 0;
            for i in 26..38 {
                let frame = sequence.frame(i);
                let world_from_camera = sequence.world_from_camera(i);
                for out in pipeline.push(&FrameInput {
                    timestamp_ns: frame.timestamp_ns,
                    gray: &frame.gray,
                    depth_m: &frame.depth_m,
                    world_from_marker: Some(&world_from_camera),
                    ignore_in_previous: None::<&Mask>,
                })? {
                    last_mask = moving_pixels(&out.mask);
                }
            }
            Ok(last_mask)
        };
        let (with_growth, paper) = (run(true)?, run(false)?);
        assert!(with_growth > paper, "{with_growth} vs {paper}");
        Ok(())
    }
}
