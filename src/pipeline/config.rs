//! What a [`Processor`](super::Processor) is configured with: the pose source, the failure
//! policy and its defaults, the processing mode, and [`ProcessorConfig`] holding them with the
//! DVO, detector and offline parameters (what `occmask process --config` reads).

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use super::offline::OfflineConfig;
use crate::dvo::completion::IgnoreCompletionConfig;
use crate::dvo::DvoConfig;
use crate::error::{Error, Result};
use crate::occlusion::bodies::BodyCompletionConfig;
use crate::occlusion::OcclusionConfig;

#[cfg(doc)]
use super::{offline, Processor};

/// Where the camera motion comes from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum PoseSource {
    /// DVO ([`ProcessorConfig::dvo`]) with the previous mask as its ignore mask (the paper's
    /// closed loop).
    #[default]
    DvoClosedLoop,
    /// DVO without mask feedback.
    DvoUnmasked,
    /// An external `world_from_marker` pose given with every frame.
    External {
        /// Fixed pose of the marker in the camera frame (`None` = the marker is the camera).
        camera_from_marker: Option<Isometry3<f64>>,
    },
}

impl PoseSource {
    /// The name on the command line (`--pose`), in `/occmask/stats` and in the `occmask.process`
    /// metadata: `dvo`, `dvo-unmasked` or `external`.
    pub fn as_str(&self) -> &'static str {
        match self {
            PoseSource::DvoClosedLoop => "dvo",
            PoseSource::DvoUnmasked => "dvo-unmasked",
            PoseSource::External { .. } => "external",
        }
    }

    /// Whether the poses come with the frames (no DVO runs).
    pub fn is_external(&self) -> bool {
        matches!(self, PoseSource::External { .. })
    }
}

/// Below this fraction of pixels with valid depth a frame is treated as a sensor blackout:
/// neither DVO nor the detector sees it. 2 % of 640×480 is 6 100 pixels, six times DVO's
/// default `min_usable_pixels` (1 000 at the finest level), so a frame that passes can still
/// be tracked; a covered lens or a saturated depth sensor leaves well under 1 %.
pub const DEFAULT_MIN_VALID_DEPTH_FRACTION: f64 = 0.02;
/// Consecutive frames without a trusted motion that are bridged with the last trusted
/// motion (constant velocity); after that the camera is held still (identity). 5 frames is
/// 1/6 s at 30 Hz: long enough to bridge a dropped or textureless frame or two, short enough
/// that a stale velocity cannot carry the trajectory far (a 1 m/s camera drifts ≤ 17 cm).
pub const DEFAULT_MAX_CONSTANT_VELOCITY_FRAMES: u32 = 5;
/// Fastest plausible camera translation: 3 m/s (a brisk walk with a hand-held camera; TUM
/// RGB-D's fastest hand-held sequences stay under 1 m/s). At 30 Hz: 10 cm per frame.
pub const DEFAULT_MAX_SPEED_MPS: f64 = 3.0;
/// Fastest plausible camera rotation: 270 °/s (TUM fr1/360 peaks near 100 °/s; a quick
/// head turn is ~200 °/s). At 30 Hz: 9° per frame, about DVO's basin with 4 pyramid levels.
pub const DEFAULT_MAX_ANGULAR_SPEED_RADPS: f64 = 270.0 * std::f64::consts::PI / 180.0;
/// Smallest fraction of DVO's reference points that must still carry weight at the final pose.
pub const DEFAULT_MIN_INLIER_FRACTION: f64 = 0.25;
/// A converged cost this many times the median of the recent accepted costs is rejected.
/// Measured on the synthetic scenarios at 640×480: legitimate frames reach 4.3 (the dominant
/// object growing to cover 92 % of the view raises the cost smoothly, 1.8e-4 → 9.5e-4 in 12
/// frames); a teleport gives ≈ 70, structureless noisy gray ≈ 80. 10 sits between them (a
/// false rejection is expensive: it resets the detector).
pub const DEFAULT_MAX_COST_RATIO: f64 = 10.0;
/// A gray image with less contrast than 4 gray levels (of 255) has no texture DVO could use
/// (its default gradient threshold is 4/255 per pixel): black, saturated or covered.
pub const DEFAULT_MIN_GRAY_RANGE: f32 = 4.0 / 255.0;

/// What the pipeline does when a frame's motion cannot be trusted (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FailurePolicy {
    /// Frames with less valid depth than this fraction are skipped as a blackout.
    pub min_valid_depth_fraction: f64,
    /// Consecutive untrusted frames bridged with constant velocity before holding still.
    pub max_constant_velocity_frames: u32,
    /// Fastest plausible camera translation (m/s).
    pub max_speed_mps: f64,
    /// Fastest plausible camera rotation (rad/s).
    pub max_angular_speed_radps: f64,
    /// Smallest plausible fraction of DVO reference points used at the final pose.
    pub min_inlier_fraction: f64,
    /// Largest plausible ratio of the final cost to the median recent accepted cost.
    pub max_cost_ratio: f64,
    /// Gray images whose max − min is below this are flat (black, saturated, covered lens):
    /// DVO skips them.
    pub min_gray_range: f32,
    /// Reset the detector when tracking resumes after skipped (blackout) frames, even when
    /// DVO bridges the gap.
    pub reset_detector_after_gap: bool,
}

impl Default for FailurePolicy {
    fn default() -> Self {
        Self {
            min_valid_depth_fraction: DEFAULT_MIN_VALID_DEPTH_FRACTION,
            max_constant_velocity_frames: DEFAULT_MAX_CONSTANT_VELOCITY_FRAMES,
            max_speed_mps: DEFAULT_MAX_SPEED_MPS,
            max_angular_speed_radps: DEFAULT_MAX_ANGULAR_SPEED_RADPS,
            min_inlier_fraction: DEFAULT_MIN_INLIER_FRACTION,
            max_cost_ratio: DEFAULT_MAX_COST_RATIO,
            min_gray_range: DEFAULT_MIN_GRAY_RANGE,
            reset_detector_after_gap: false,
        }
    }
}

impl FailurePolicy {
    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad field.
    pub fn validate(&self) -> Result<()> {
        let checks: [(&'static str, f64, bool, &str); 5] = [
            (
                "min_valid_depth_fraction",
                self.min_valid_depth_fraction,
                (0.0..=1.0).contains(&self.min_valid_depth_fraction),
                "a fraction in [0, 1]",
            ),
            (
                "max_speed_mps",
                self.max_speed_mps,
                self.max_speed_mps > 0.0,
                "a positive speed",
            ),
            (
                "max_angular_speed_radps",
                self.max_angular_speed_radps,
                self.max_angular_speed_radps > 0.0,
                "a positive angular speed",
            ),
            (
                "min_inlier_fraction",
                self.min_inlier_fraction,
                (0.0..=1.0).contains(&self.min_inlier_fraction),
                "a fraction in [0, 1]",
            ),
            (
                "max_cost_ratio",
                self.max_cost_ratio,
                self.max_cost_ratio >= 1.0,
                "a ratio ≥ 1",
            ),
        ];
        for (name, value, ok, expected) in checks {
            if !ok {
                return Err(Error::InvalidParameter {
                    name,
                    value: value.to_string(),
                    expected: expected.into(),
                });
            }
        }
        Ok(())
    }
}

/// Configuration of a [`Processor`].
///
/// Serialised (the `--config` JSON file of `occmask process`) as `{"dvo": …, "occlusion": …,
/// "failure": …}`, each field by field; missing fields take the default, unknown ones are an
/// error. The pose source is not part of the file: it comes from the caller (`--pose`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProcessorConfig {
    /// Pose source (not serialised).
    #[serde(skip)]
    pub pose_source: PoseSource,
    /// DVO parameters (used by the DVO pose sources).
    pub dvo: DvoConfig,
    /// Detector parameters.
    pub occlusion: OcclusionConfig,
    /// Failure handling.
    pub failure: FailurePolicy,
    /// Depth-connected completion of DVO's ignore mask (the closed loop's previous mask grown
    /// over the rest of each object's depth-continuous surface, see
    /// [`crate::dvo::IgnoreCompletion`]); `None` = the detector's mask as it is (the paper).
    pub ignore_completion: Option<IgnoreCompletionConfig>,
    /// Each large enough object of the published mask completed to the depth-connected body it
    /// belongs to when depth edges bound that body ([`crate::occlusion::bodies`], docs/method.md
    /// D26); `None` = the detector's mask as it is (the paper). DVO's ignore mask is unchanged.
    pub body_completion: Option<BodyCompletionConfig>,
    /// Causal or offline processing (chooses between [`Processor`] and
    /// [`offline::OfflineProcessor`] where a caller offers both, as `occmask process` does).
    pub mode: ProcessingMode,
    /// The offline mode's parameters ([`offline::OfflineProcessor`]; unused by [`Processor`]).
    pub offline: OfflineConfig,
}

/// How a recording is processed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProcessingMode {
    /// Forward, backward and refinement passes with a bounded look-ahead
    /// ([`offline::OfflineProcessor`]): the default for recordings.
    #[default]
    Offline,
    /// One forward pass, each frame's result from it and the frames before ([`Processor`]):
    /// what an online user gets.
    Causal,
}

impl ProcessingMode {
    /// `offline` or `causal`.
    pub fn as_str(self) -> &'static str {
        match self {
            ProcessingMode::Offline => "offline",
            ProcessingMode::Causal => "causal",
        }
    }
}

impl Default for ProcessorConfig {
    /// The closed loop with [`DvoConfig::closed_loop`], the default detector, failure policy,
    /// ignore-mask completion and body completion.
    fn default() -> Self {
        Self {
            pose_source: PoseSource::default(),
            dvo: DvoConfig::closed_loop(),
            occlusion: OcclusionConfig::default(),
            failure: FailurePolicy::default(),
            ignore_completion: Some(IgnoreCompletionConfig::default()),
            body_completion: Some(BodyCompletionConfig::default()),
            mode: ProcessingMode::default(),
            offline: OfflineConfig::default(),
        }
    }
}

impl ProcessorConfig {
    /// A configuration from JSON holding any subset of the fields [`Self::default`] serialises
    /// to (what `occmask process --print-config` prints), at any depth: every field the JSON
    /// leaves out keeps its default in its own place. (Deserialising the struct directly would
    /// fill a partly given nested object from its type's default instead: a partial
    /// `offline.refinement_dvo` would lose the refinement's weights and motion prior, a partial
    /// `dvo` the closed loop's.) Unknown fields are an error; a value of another shape (a
    /// `null`, another enum variant) replaces the default whole. Not validated.
    ///
    /// # Errors
    /// Invalid JSON, an unknown field, or a value of the wrong type.
    pub fn from_json(text: &str) -> serde_json::Result<Self> {
        let patch: serde_json::Value = serde_json::from_str(text)?;
        let mut value = serde_json::to_value(Self::default())?;
        overlay(&mut value, patch);
        serde_json::from_value(value)
    }

    /// Checks the DVO, detector, failure-policy and completion parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad field.
    pub fn validate(&self) -> Result<()> {
        self.dvo.validate()?;
        self.occlusion.validate()?;
        if let Some(completion) = &self.ignore_completion {
            completion.validate()?;
        }
        if let Some(completion) = &self.body_completion {
            completion.validate()?;
        }
        self.offline.validate()?;
        self.failure.validate()
    }
}

/// `patch` over `base`: an object whose fields all exist in the base object (a struct, or the
/// same enum variant) field by field, anything else in its place.
fn overlay(base: &mut serde_json::Value, patch: serde_json::Value) {
    use serde_json::Value;
    match (base, patch) {
        (Value::Object(base), Value::Object(patch)) if patch.keys().all(|k| base.contains_key(k)) => {
            for (key, value) in patch {
                if let Some(slot) = base.get_mut(&key) {
                    overlay(slot, value);
                }
            }
        }
        (slot, patch) => *slot = patch,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dvo::IntensityThreshold;

    #[test]
    fn json_with_every_field_gives_the_same_config() {
        let defaults = ProcessorConfig::default();
        let text = serde_json::to_string(&defaults).unwrap();
        assert_eq!(ProcessorConfig::from_json(&text).unwrap(), defaults);
        assert_eq!(ProcessorConfig::from_json("{}").unwrap(), defaults);
    }

    /// A field of a nested object changes that field only: the rest keeps the default of its
    /// place, not of its type (the refinement's DVO is not `DvoConfig::default()`).
    #[test]
    fn partial_nested_objects_keep_the_defaults_of_their_place() {
        let config = ProcessorConfig::from_json(
            r#"{"offline": {"refinement_dvo": {"depth_weight_gamma": 10.0}}, "dvo": {"levels": 4}}"#,
        )
        .unwrap();
        let mut expected = ProcessorConfig::default();
        expected.offline.refinement_dvo.depth_weight_gamma = 10.0;
        expected.dvo.levels = 4;
        assert_eq!(config, expected);
        assert_ne!(
            expected.offline.refinement_dvo,
            DvoConfig {
                depth_weight_gamma: 10.0,
                ..DvoConfig::default()
            }
        );
        assert_ne!(
            expected.dvo,
            DvoConfig {
                levels: 4,
                ..DvoConfig::default()
            }
        );
    }

    #[test]
    fn nulls_and_other_variants_replace_the_default_and_unknown_fields_fail() {
        let config = ProcessorConfig::from_json(
            r#"{"occlusion": {"slow_evidence": null}, "dvo": {"k_intensity": "release_schedule"}}"#,
        )
        .unwrap();
        assert_eq!(config.occlusion.slow_evidence, None);
        assert_eq!(config.dvo.k_intensity, IntensityThreshold::ReleaseSchedule);
        let config = ProcessorConfig::from_json(r#"{"dvo": {"k_intensity": {"constant": 0.25}}}"#).unwrap();
        assert_eq!(config.dvo.k_intensity, IntensityThreshold::Constant(0.25));
        for bad in [
            r#"{"dvo": {"max_iterations": 3}}"#,
            r#"{"offline": {"lookahead": 3}}"#,
            r#"{"dvo": {"levels": "five"}}"#,
        ] {
            assert!(ProcessorConfig::from_json(bad).is_err(), "{bad}");
        }
    }

    /// Every preset the docs point `--config` at reads and validates, and changes something.
    #[test]
    fn the_presets_in_tools_detector_configs_are_valid() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/detector_configs");
        let mut presets = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "json") {
                let text = std::fs::read_to_string(&path).unwrap();
                let config =
                    ProcessorConfig::from_json(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                config
                    .validate()
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                assert_ne!(config, ProcessorConfig::default(), "{}", path.display());
                presets += 1;
            }
        }
        assert!(presets >= 8, "{presets} presets in {}", dir.display());
    }
}
