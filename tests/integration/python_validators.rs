//! Files written by `convert` and `process` must pass real MCAP clients:
//! `pymcap-cli doctor --strict-message-order`, and the Python `mcap` reader decoding every
//! message with the schemas embedded in the file (protobuf, ROS 2 CDR, JSON):
//! tests/validate_mcap.py for converted files, tests/process_validate.py for `process`
//! outputs of every input flavour, annotated copies and sidecars.
//!
//! Needs `OCCMASK_PYTHON` (a Python with mcap, mcap-protobuf-support, mcap-ros2-support and
//! pymcap-cli; `.ci/run` creates `.venv-ci` and sets it). Without it the tests fail under CI
//! (`CI` set) and are skipped with a notice otherwise.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns: a panic is the failure report

use crate::common;
use crate::common::mcap_fixture as process_support;

use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::*;
use occmask::mcap_io::annotate::AnnotateOptions;
use occmask::mcap_io::input::McapInput;
use occmask::process::{process_file, NoHooks, ProcessConfig};
use process_support::{fixture_bytes, test_factory, FixtureSpec, ALL_FLAVORS};

fn python() -> Option<PathBuf> {
    match std::env::var_os("OCCMASK_PYTHON") {
        Some(p) => Some(PathBuf::from(p)),
        None if std::env::var_os("CI").is_some() => {
            panic!("OCCMASK_PYTHON is not set but CI is: run the tests through `bash .ci/run`")
        }
        None => {
            // Written to the stderr handle directly so the test harness does not capture it.
            use std::io::Write;
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED python_validators: set OCCMASK_PYTHON to a Python with the MCAP validators \
                 (bash .ci/run does)"
            );
            None
        }
    }
}

/// `pymcap-cli` beside the Python interpreter (same venv), else on PATH.
fn pymcap_cli(python: &Path) -> PathBuf {
    let sibling = python.with_file_name("pymcap-cli");
    if sibling.is_file() {
        sibling
    } else {
        PathBuf::from("pymcap-cli")
    }
}

/// `pymcap-cli doctor` finds no error and no warning, then `script` (a validator in tests/,
/// run with `args` after the file) exits 0.
fn validate(python: &Path, file: &Path, script: &str, args: &[&str]) {
    let doctor = Command::new(pymcap_cli(python))
        .args(["doctor", "--strict-message-order", "--format", "jsonl"])
        .arg(file)
        .output()
        .expect("cannot run pymcap-cli");
    let report = String::from_utf8_lossy(&doctor.stdout);
    assert!(
        doctor.status.success(),
        "pymcap-cli doctor failed on {}:\n{report}\n{}",
        file.display(),
        String::from_utf8_lossy(&doctor.stderr)
    );
    assert!(
        report.contains("\"errors\":0") && report.contains("\"warnings\":0"),
        "{report}"
    );

    let read = Command::new(python)
        .arg(repo().join("tests").join(script))
        .arg(file)
        .args(args)
        .output()
        .expect("cannot run the Python validator");
    assert!(
        read.status.success(),
        "Python mcap reader rejected {}:\n{}{}",
        file.display(),
        String::from_utf8_lossy(&read.stdout),
        String::from_utf8_lossy(&read.stderr)
    );
}

#[test]
fn converted_files_pass_doctor_and_the_python_reader() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();

    let desk = tmp.path().join("desk.mcap");
    let src = tum_fixture();
    let out = convert("tum", &src, &desk, &["-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    validate(
        &python,
        &desk,
        "validate_mcap.py",
        &[
            "/camera/rgb/image=10",
            "/camera/rgb/camera_info=10",
            "/camera/depth/image=10",
            "/camera/depth/camera_info=10",
            "/groundtruth/pose=154",
            "/tf=154",
        ],
    );

    for compression in ["lz4", "none"] {
        let larr = tmp.path().join(format!("larr-{compression}.mcap"));
        let fixture = larr_fixture();
        let out = convert(
            "larr",
            &fixture,
            &larr,
            &["--camera", FIXTURE_CAMERA, "--compression", compression, "-q"],
        );
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        validate(
            &python,
            &larr,
            "validate_mcap.py",
            &["/camera/rgb/image=4", "/groundtruth/mask=4", "/tf=59"],
        );
    }
}

#[test]
fn process_outputs_of_every_flavour_pass_doctor_and_the_python_readers() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    for flavor in ALL_FLAVORS {
        for sidecar in [false, true] {
            let input_path = dir.path().join(format!("{flavor:?}.mcap"));
            std::fs::write(&input_path, fixture_bytes(flavor, &FixtureSpec::default())).unwrap();
            let input = McapInput::open(&input_path).unwrap();
            let out = dir.path().join(format!("{flavor:?}-{sidecar}.out.mcap"));
            let config = ProcessConfig {
                annotate: AnnotateOptions {
                    copy_input: !sidecar,
                    accumulation: true,
                    points_stride_px: Some(4),
                    ..Default::default()
                },
                ..Default::default()
            };
            let file = BufWriter::new(std::fs::File::create(&out).unwrap());
            let (sink, _) = process_file(&input, file, &config, &mut test_factory, &mut NoHooks).unwrap();
            sink.into_inner().unwrap().sync_all().unwrap();
            // 12 frames in the default fixture.
            validate(&python, &out, "process_validate.py", &["12"]);
        }
    }
}

/// ROS 1 and ROS 2 recordings from `ros_out` (the synthetic RealSense-like rig) decode with
/// the Python ROS decoders to what occmask itself reads from them: images, calibrations
/// (distortion included) and the /tf_static chain from depth to colour.
#[test]
fn ros_recordings_decode_alike_in_python_and_occmask() {
    use occmask::convert::{rig_names, write_synthetic_rig_recording};
    use occmask::image_buf::ImageSize;
    use occmask::mcap_io::input::decode::decode_calibration;
    use occmask::mcap_io::input::transforms::find_transform;
    use occmask::mcap_io::ros_out::RosVersion;
    use occmask::synthetic::{RgbdRig, Scenario, SequenceConfig, SyntheticSequence};

    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let config = SequenceConfig {
        size: ImageSize::new(160, 120),
        frame_count: Some(2),
        ..SequenceConfig::default()
    };
    let rig = RgbdRig::realsense_like(&config);
    let sequence = SyntheticSequence::new(Scenario::SmallObjectCrossing, config);
    for version in [RosVersion::Ros1, RosVersion::Ros2] {
        let path = dir.path().join(format!("{version:?}.mcap"));
        let file = BufWriter::new(std::fs::File::create(&path).unwrap());
        write_synthetic_rig_recording(&sequence, &rig, version, file, &Default::default(), &mut |_| {
            std::ops::ControlFlow::Continue(())
        })
        .unwrap();
        let out = Command::new(&python)
            .arg(repo().join("tests").join("validate_ros_recording.py"))
            .arg(&path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{version:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let py: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(py["counts"][rig_names::COLOR_IMAGE], 2, "{py}");
        assert_eq!(py["counts"][rig_names::TF_STATIC], 1, "{py}");
        assert_eq!(
            py["images"][rig_names::DEPTH_IMAGE],
            serde_json::json!(["16UC1", 212, 120, rig_names::DEPTH_FRAME])
        );
        assert_eq!(
            py["images"][rig_names::COLOR_IMAGE],
            serde_json::json!(["rgb8", 160, 120, rig_names::COLOR_FRAME])
        );

        // occmask's view of the same calibration.
        let input = McapInput::open(&path).unwrap();
        let channel = input.channel_by_topic(rig_names::COLOR_INFO).unwrap();
        let first = input.first_message(channel.id).unwrap().unwrap();
        let calibration =
            decode_calibration(channel.channel_type.unwrap(), rig_names::COLOR_INFO, &first.data).unwrap();
        let py_cal = &py["calibrations"][rig_names::COLOR_INFO];
        assert_eq!(py_cal["model"], calibration.distortion_model.as_str());
        assert_eq!(py_cal["d"], serde_json::json!(calibration.d));
        assert_eq!(py_cal["k"], serde_json::json!(calibration.k));
        assert_eq!(
            calibration.distortion(rig_names::COLOR_INFO).unwrap(),
            rig.color.distortion
        );

        // The chain composed from Python's edges equals occmask's lookup and the rig.
        let edges = py["transforms"].as_array().unwrap();
        let edge = |parent: &str, child: &str| -> nalgebra::Isometry3<f64> {
            let e = edges
                .iter()
                .find(|e| e[0] == parent && e[1] == child)
                .unwrap_or_else(|| panic!("no edge {parent} -> {child} in {edges:?}"));
            let v = |i: usize, j: usize| e[i][j].as_f64().unwrap();
            nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::new(v(2, 0), v(2, 1), v(2, 2)),
                nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    v(3, 3),
                    v(3, 0),
                    v(3, 1),
                    v(3, 2),
                )),
            )
        };
        let link_from_color =
            edge("camera_link", "camera_color_frame") * edge("camera_color_frame", rig_names::COLOR_FRAME);
        let link_from_depth =
            edge("camera_link", "camera_depth_frame") * edge("camera_depth_frame", rig_names::DEPTH_FRAME);
        let python_chain = link_from_color.inverse() * link_from_depth;
        let (chain, _) = find_transform(&input, rig_names::COLOR_FRAME, rig_names::DEPTH_FRAME).unwrap();
        let ours = chain.unwrap().target_from_source;
        let gap = |a: &nalgebra::Isometry3<f64>, b: &nalgebra::Isometry3<f64>| {
            (a.to_homogeneous() - b.to_homogeneous()).norm()
        };
        assert!(gap(&python_chain, &ours) < 1e-12, "{version:?}");
        assert!(gap(&ours, &rig.color_from_depth) < 1e-12, "{version:?}");
    }
}
