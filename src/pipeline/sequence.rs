//! A recording's processor as `occmask process` runs it: causal ([`Processor`]) or offline
//! ([`OfflineProcessor`]) by [`ProcessorConfig::mode`], the offline mode at its working
//! resolution ([`OfflineConfig::min_working_side_px`]), with results at the input's size.
//!
//! Frames larger than the working resolution are halved (gray by 2×2 box means, depth by the
//! edge-aware reduction of the pyramid, a given ignore mask by keeping every marked pixel) and
//! seen through the intrinsics of the halved image; the masks and the accumulation map come
//! back enlarged to the input's size (nearest pixel). Poses need no conversion. The detector's
//! pixel counts in [`FrameStats`](super::FrameStats) are working-resolution pixels; its
//! fractions and every parameter given in pixels refer to the working resolution too (except
//! the object sizes, which are given at VGA and scale by themselves).

#[cfg(doc)]
use super::offline::OfflineConfig;
use super::offline::{ColourRegistration, Emit, OfflineProcessor, Sink};
use super::reduce::{copy_or_enlarge, halvings_keeping_side, FrameReduction};
use super::{check_size, FrameInput, FrameOutput, ProcessingMode, Processor, ProcessorConfig};
use crate::error::Result;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, ImageSize, Mask};
use crate::pyramid::level_size;

/// The causal or offline processor of a recording at its working resolution (see the module
/// docs).
pub struct SequenceProcessor {
    pipeline: Pipeline,
    size: ImageSize,
    /// `None` when the frames are processed at their own size.
    working: Option<WorkingResolution>,
}

enum Pipeline {
    Causal(Box<Processor>),
    Offline(Box<OfflineProcessor>),
}

/// Buffers of the reduction and the enlargement.
struct WorkingResolution {
    reduction: FrameReduction,
    mask: Mask,
    odometry_mask: Mask,
    accumulation_m: DepthMeters,
}

impl SequenceProcessor {
    /// A processor for `size` frames seen through `intrinsics`, with every part of `config`.
    ///
    /// # Errors
    /// [`crate::Error::InvalidParameter`] for invalid parameters, intrinsics or size.
    pub fn new(size: ImageSize, intrinsics: PinholeIntrinsics, config: ProcessorConfig) -> Result<Self> {
        config.validate()?;
        let halvings = match config.mode {
            ProcessingMode::Causal => 0,
            ProcessingMode::Offline => working_halvings(size, config.offline.min_working_side_px),
        };
        let working_size = level_size(size, halvings);
        let working_intrinsics = intrinsics.at_level(halvings as u32);
        let pipeline = match config.mode {
            ProcessingMode::Causal => Pipeline::Causal(Box::new(Processor::new(
                working_size,
                working_intrinsics,
                config,
            )?)),
            ProcessingMode::Offline => Pipeline::Offline(Box::new(OfflineProcessor::new(
                working_size,
                working_intrinsics,
                config,
            )?)),
        };
        Ok(Self {
            pipeline,
            size,
            working: FrameReduction::new(size, halvings).map(|reduction| WorkingResolution {
                reduction,
                mask: Mask::filled(size, 0),
                odometry_mask: Mask::filled(size, 0),
                accumulation_m: DepthMeters::filled(size, 0.0),
            }),
        })
    }

    /// The size the frames are processed at.
    pub fn working_size(&self) -> ImageSize {
        match &self.working {
            Some(working) => working.reduction.size(),
            None => self.size,
        }
    }

    /// Adds the next frame (frames come in time order) and hands `emit` the results that are
    /// final now, oldest first, at the input's size: one per frame in the causal mode, none and
    /// then a block of them in the offline one.
    ///
    /// # Errors
    /// [`crate::Error::SizeMismatch`] for images of another size, whatever the processor reports,
    /// and `emit`'s errors.
    pub fn push(&mut self, frame: &FrameInput<'_>, emit: &mut Emit<'_>) -> Result<()> {
        check_size("gray image", frame.gray.size(), self.size)?;
        check_size("depth image", frame.depth_m.size(), self.size)?;
        if let Some(ignore) = frame.ignore_in_previous {
            check_size("ignore mask", ignore.size(), self.size)?;
        }
        let Some(working) = &mut self.working else {
            return self.pipeline.push(frame, emit);
        };
        let WorkingResolution {
            reduction,
            mask,
            odometry_mask,
            accumulation_m,
        } = working;
        let mut enlarged = Enlarged {
            mask,
            odometry_mask,
            accumulation_m,
        };
        let emit: &mut Emit<'_> = &mut |out| emit(enlarged.output(out));
        match &mut self.pipeline {
            // The offline processor reduces the frame beside its later passes.
            Pipeline::Offline(processor) => processor.push_reducing(frame, Some(reduction), emit),
            Pipeline::Causal(_) => {
                reduction.reduce(frame)?;
                self.pipeline.push(&reduction.view(frame), emit)
            }
        }
    }

    /// Hands `emit` the results still pending at the end of the input, oldest first.
    ///
    /// # Errors
    /// Whatever the processor reports, and `emit`'s errors.
    pub fn finish(&mut self, emit: &mut Sink<'_>) -> Result<()> {
        let Some(working) = &mut self.working else {
            return self.pipeline.finish(emit);
        };
        let mut enlarged = Enlarged {
            mask: &mut working.mask,
            odometry_mask: &mut working.odometry_mask,
            accumulation_m: &mut working.accumulation_m,
        };
        self.pipeline.finish(&mut |out| emit(enlarged.output(out)))
    }

    /// What the offline mode's colour/depth registration check decided (`None` in the causal
    /// mode and before the check has decided).
    pub fn colour_registration(&self) -> Option<ColourRegistration> {
        match &self.pipeline {
            Pipeline::Causal(_) => None,
            Pipeline::Offline(processor) => processor.colour_registration(),
        }
    }
}

impl Pipeline {
    fn push(&mut self, frame: &FrameInput<'_>, emit: &mut Emit<'_>) -> Result<()> {
        match self {
            Pipeline::Causal(processor) => emit(processor.process(frame)?),
            Pipeline::Offline(processor) => processor.push(frame, emit),
        }
    }

    fn finish(&mut self, emit: &mut Sink<'_>) -> Result<()> {
        match self {
            Pipeline::Causal(_) => Ok(()),
            Pipeline::Offline(processor) => processor.finish(emit),
        }
    }
}

/// The input-size images of a result from the working resolution.
struct Enlarged<'a> {
    mask: &'a mut Mask,
    odometry_mask: &'a mut Mask,
    accumulation_m: &'a mut DepthMeters,
}

impl Enlarged<'_> {
    fn output<'s>(&'s mut self, out: FrameOutput<'_>) -> FrameOutput<'s> {
        copy_or_enlarge(out.mask, self.mask);
        copy_or_enlarge(out.odometry_mask, self.odometry_mask);
        copy_or_enlarge(out.accumulation_m, self.accumulation_m);
        FrameOutput {
            mask: self.mask,
            odometry_mask: self.odometry_mask,
            accumulation_m: self.accumulation_m,
            ..out
        }
    }
}

/// Halvings of `size` to the working resolution: as many as keep the short side at least
/// `min_side_px` pixels; none for 0.
fn working_halvings(size: ImageSize, min_side_px: usize) -> usize {
    if min_side_px == 0 {
        0
    } else {
        halvings_keeping_side(size, min_side_px, usize::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::pipeline::offline::MIN_WORKING_SIDE_PX;
    use crate::pipeline::reduce::Reduced;
    use crate::pipeline::PoseSource;
    use crate::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

    const FRAMES: usize = 24;

    fn vga_sequence() -> SyntheticSequence {
        SyntheticSequence::new(
            Scenario::EnteringWhilePanning,
            SequenceConfig {
                size: ImageSize::new(640, 480),
                ..SequenceConfig::default()
            },
        )
    }

    fn external(mode: ProcessingMode) -> ProcessorConfig {
        ProcessorConfig {
            pose_source: PoseSource::External {
                camera_from_marker: None,
            },
            mode,
            ..ProcessorConfig::default()
        }
    }

    /// Hands `push` the first [`FRAMES`] frames of `sequence` with their true poses, halved
    /// `halvings` times.
    fn feed(sequence: &SyntheticSequence, halvings: usize, push: &mut dyn FnMut(&FrameInput<'_>)) {
        let size = sequence.config.size;
        let mut reduced = Reduced::new(size, halvings);
        for i in 0..FRAMES {
            let frame = sequence.frame(i);
            let pose = sequence.world_from_camera(i);
            let (gray, depth_m) = match &mut reduced {
                Some(r) => r.reduce(&frame.gray, &frame.depth_m).unwrap(),
                None => (&frame.gray, &frame.depth_m),
            };
            let input = FrameInput {
                timestamp_ns: frame.timestamp_ns,
                gray,
                depth_m,
                world_from_marker: Some(&pose),
                ignore_in_previous: None,
            };
            push(&input);
        }
    }

    /// The offline mode on VGA is the offline processor on the halved frames through the halved
    /// intrinsics, its masks enlarged: the same masks pixel for pixel, at the input's size.
    /// Checked with the colour registration check deciding after [`FRAMES`] (every frame is
    /// reduced before the passes start), after 6 frames (later ones are reduced beside the
    /// later passes) and off (every frame so).
    #[test]
    fn offline_vga_is_the_halved_sequence_with_its_masks_enlarged() {
        let sequence = vga_sequence();
        let (size, intrinsics) = (sequence.config.size, sequence.config.intrinsics());
        let default = external(ProcessingMode::Offline);
        let mut early_check = default;
        if let Some(check) = &mut early_check.offline.unregistered_colour {
            check.frames = 6;
        }
        let mut no_check = default;
        no_check.offline.unregistered_colour = None;
        assert!(default
            .offline
            .unregistered_colour
            .is_some_and(|c| c.frames > FRAMES));
        for config in [default, early_check, no_check] {
            let mut processor = SequenceProcessor::new(size, intrinsics, config).unwrap();
            assert_eq!(processor.working_size(), ImageSize::new(320, 240));
            let mut got = Vec::new();
            let mut keep = |out: FrameOutput<'_>| {
                got.push(out.mask.clone());
                Ok(())
            };
            feed(&sequence, 0, &mut |input| {
                processor.push(input, &mut keep).unwrap()
            });
            processor.finish(&mut keep).unwrap();

            let mut reference =
                OfflineProcessor::new(ImageSize::new(320, 240), intrinsics.at_level(1), config).unwrap();
            let mut expected = Vec::new();
            let mut keep = |out: FrameOutput<'_>| {
                let mut full = Mask::filled(size, 0);
                copy_or_enlarge(out.mask, &mut full);
                expected.push(full);
                Ok(())
            };
            feed(&sequence, 1, &mut |input| {
                reference.push(input, &mut keep).unwrap()
            });
            reference.finish(&mut keep).unwrap();

            let check = config.offline.unregistered_colour.map(|c| c.frames);
            assert_eq!(got.len(), FRAMES, "check after {check:?} frames");
            assert!(got.iter().all(|m| m.size() == size));
            assert!(
                got.iter().any(|m| m.as_slice().iter().any(|&v| v != 0)),
                "nothing marked (check after {check:?} frames)"
            );
            assert!(
                got == expected,
                "masks differ from the halved sequence's (check after {check:?} frames)"
            );
        }
    }

    #[test]
    fn full_resolution_and_the_causal_mode_keep_the_input_size() {
        let sequence = vga_sequence();
        let (size, intrinsics) = (sequence.config.size, sequence.config.intrinsics());
        let mut full = external(ProcessingMode::Offline);
        full.offline.min_working_side_px = 0;
        for config in [full, external(ProcessingMode::Causal)] {
            let processor = SequenceProcessor::new(size, intrinsics, config).unwrap();
            assert_eq!(processor.working_size(), size, "{:?}", config.mode);
        }
        let small = ImageSize::new(320, 240);
        let processor =
            SequenceProcessor::new(small, intrinsics.at_level(1), external(ProcessingMode::Offline)).unwrap();
        assert_eq!(processor.working_size(), small);
    }

    #[test]
    fn frames_of_another_size_and_a_tiny_working_side_are_refused() {
        let sequence = vga_sequence();
        let (size, intrinsics) = (sequence.config.size, sequence.config.intrinsics());
        let mut processor =
            SequenceProcessor::new(size, intrinsics, external(ProcessingMode::Offline)).unwrap();
        let frame = SyntheticSequence::new(
            Scenario::EnteringWhilePanning,
            SequenceConfig {
                size: ImageSize::new(320, 240),
                ..SequenceConfig::default()
            },
        )
        .frame(0);
        let pose = sequence.world_from_camera(0);
        let input = FrameInput {
            timestamp_ns: frame.timestamp_ns,
            gray: &frame.gray,
            depth_m: &frame.depth_m,
            world_from_marker: Some(&pose),
            ignore_in_previous: None,
        };
        let err = processor.push(&input, &mut |_| Ok(())).unwrap_err();
        assert!(matches!(err, Error::SizeMismatch { .. }), "{err}");

        let mut config = external(ProcessingMode::Offline);
        config.offline.min_working_side_px = MIN_WORKING_SIDE_PX - 1;
        let err = SequenceProcessor::new(size, intrinsics, config).err().unwrap();
        assert!(
            matches!(
                err,
                Error::InvalidParameter {
                    name: "offline.min_working_side_px",
                    ..
                }
            ),
            "{err}"
        );
    }
}
