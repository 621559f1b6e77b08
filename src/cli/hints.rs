//! The command-line flag that fixes a library error. The library's messages state what was
//! expected and found without naming flags; the CLI appends the flag from the error's variant.

use std::borrow::Cow;

use occmask::error::{McapProblem, PoseRole, RegistrationNeed, TopicRole};
use occmask::Error;

/// What to pass (or check) on the command line for `error`, if a flag fixes it.
pub fn flag_hint(error: &Error) -> Option<Cow<'static, str>> {
    Some(Cow::Borrowed(match error {
        Error::MissingCalibration { .. } => {
            "pass --camera FX,FY,CX,CY (or a preset such as fr2) or --camera-info-topic TOPIC"
        }
        Error::CalibrationSize { .. } => "pass --camera FX,FY,CX,CY for the image size",
        Error::BadDepthUnits { .. } => "pass --depth-units-per-meter",
        Error::BadIntrinsics { .. } => "pass --camera FX,FY,CX,CY",
        Error::UnsupportedDistortion { .. } => {
            "pass --camera FX,FY,CX,CY[,K1,K2,P1,P2,K3] to give the camera, or --no-undistort to \
             treat the images as pinhole"
        }
        Error::NoPairs { .. } => "raise --max-pair-gap-ms or check the timestamps",
        Error::NoTopic { role, .. } => return Some(format!("pass {}", topic_flag(*role)).into()),
        Error::AmbiguousTopic { role, .. } => {
            return Some(format!("choose one with {}", topic_flag(*role)).into())
        }
        Error::UnknownTopic { role, .. } | Error::UnsupportedTopic { role, .. } => {
            return Some(format!("check {}", topic_flag(*role)).into())
        }
        Error::MissingPoseTopic => "pass --pose-topic",
        Error::NoPoses {
            role: PoseRole::External,
            ..
        } => "check --pose-topic and --pose-frame",
        Error::NoPoses {
            role: PoseRole::Anchor,
            ..
        } => "check --anchor-topic, or pass --no-anchor",
        Error::NoPoses {
            role: PoseRole::GroundTruth,
            ..
        } => "check --groundtruth-topic and --groundtruth",
        Error::AnchorPoses { .. } => "pass --no-anchor to ignore the channel",
        Error::AlreadyAnnotated { .. } => {
            "process the recording it was made from, or pass --replace-annotations to write this \
             run's channels in place of the earlier run's"
        }
        Error::OutputExists { .. } => "pass --force to overwrite it",
        Error::ExistingOutputNotReusable { .. } => "pass --force to replace it",
        Error::DepthNotRegistered { needed, .. } => match needed.as_ref() {
            RegistrationNeed::AlignedSameSize { .. } => {
                "pass --depth-camera-info-topic TOPIC with the depth camera's calibration to register it"
            }
            RegistrationNeed::DepthCalibration => {
                "pass --depth-camera-info-topic TOPIC, or --depth-aligned if the depth is already \
                 registered to colour"
            }
            RegistrationNeed::DepthCalibrationSize { .. } => {
                "pass --depth-camera-info-topic with the calibration of these images"
            }
        },
        Error::BadMcap {
            path,
            problem: McapProblem::Directory,
        } => return Some(format!("pass the files in it ({}/*.mcap)", path.display()).into()),
        Error::MissingTransform { .. } => {
            "pass --depth-to-color X,Y,Z,QX,QY,QZ,QW (the depth camera's pose in the colour \
             camera's frame: translation in metres, then the rotation quaternion), or \
             --depth-aligned if the depth is already registered to colour"
        }
        _ => return None,
    }))
}

/// The flag that names the topic for `role`.
fn topic_flag(role: TopicRole) -> &'static str {
    match role {
        TopicRole::Color => "--rgb-topic",
        TopicRole::Depth => "--depth-topic",
        TopicRole::Calibration => "--camera-info-topic",
        TopicRole::DepthCalibration => "--depth-camera-info-topic",
        TopicRole::Poses => "--pose-topic",
    }
}

/// `error` with the flag that fixes it appended to its message (`error: … ; pass --…`), when
/// the library error in its chain has one; else `error` unchanged.
pub fn with_hint(error: anyhow::Error) -> anyhow::Error {
    let hint = error
        .chain()
        .find_map(|e| e.downcast_ref::<Error>())
        .and_then(flag_hint);
    match hint {
        Some(hint) => anyhow::anyhow!("{error:#}; {hint}"),
        None => error,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;

    #[test]
    fn hints_follow_the_whole_chain_and_leave_other_errors_alone() {
        let error = Err::<(), _>(Error::MissingPoseTopic)
            .context("processing a.mcap")
            .unwrap_err();
        assert_eq!(
            format!("{:#}", with_hint(error)),
            "processing a.mcap: external poses need a pose topic to read them from; pass --pose-topic"
        );
        let error = anyhow::Error::new(Error::Interrupted { done: 1, total: 2 });
        let kept = with_hint(error);
        assert!(kept.downcast_ref::<Error>().is_some());
    }
}
