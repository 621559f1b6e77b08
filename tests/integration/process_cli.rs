//! `occmask process` through the binary, with the real pipeline: batches where one file fails,
//! overwrite and input-as-output refusals, resuming with `--skip-existing`, exports, determinism
//! and external poses.

#![allow(clippy::unwrap_used)] // helpers outside #[test] fns: a panic is the failure report

use crate::common::mcap_fixture as process_support;
use crate::common::{convert, occmask, stderr};

use std::path::{Path, PathBuf};

use occmask::image_buf::ImageSize;
use process_support::*;

/// Big enough for the DVO pyramid, small enough to be quick.
fn spec() -> FixtureSpec {
    FixtureSpec {
        size: ImageSize::new(160, 120),
        frames: 8,
        ..Default::default()
    }
}

fn fixture(dir: &Path, name: &str, flavor: Flavor) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, fixture_bytes(flavor, &spec())).unwrap();
    path
}

/// The TUM excerpt converted into `dir` (`desk.mcap`).
fn converted_tum_fixture(dir: &Path) -> PathBuf {
    let desk = dir.join("desk.mcap");
    let out = convert("tum", &crate::common::data::tum_fixture(), &desk, &["-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    desk
}

/// The processor configuration `process` recorded in `output`'s metadata.
fn recorded_processor_config(output: &Path) -> occmask::pipeline::ProcessorConfig {
    use occmask::mcap_io::annotate::{METADATA_PROCESS, METADATA_PROCESSOR_CONFIG};
    let written = occmask::McapInput::open(output).unwrap();
    let process = crate::common::recording::metadata(&written)
        .into_iter()
        .find(|m| m.name == METADATA_PROCESS)
        .unwrap();
    serde_json::from_str(&process.metadata[METADATA_PROCESSOR_CONFIG]).unwrap()
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn one_failing_file_does_not_stop_the_others() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Protobuf);
    let b = fixture(dir.path(), "b.mcap", Flavor::Ros2);
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").unwrap();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let out = occmask(&[
        "process".as_ref(),
        a.as_os_str(),
        junk.as_os_str(),
        b.as_os_str(),
        "--out-dir".as_ref(),
        out_dir.as_os_str(),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("1 of 3 files failed"), "{err}");
    assert!(
        err.contains("junk.mcap") && err.contains("not an MCAP file"),
        "{err}"
    );
    assert!(err.contains("frames"), "summary table missing: {err}");
    assert_eq!(files_in(&out_dir), vec!["a.occmask.mcap", "b.occmask.mcap"]);
    let eval = occmask(&["eval".as_ref(), out_dir.join("b.occmask.mcap").as_os_str()]);
    assert!(eval.status.success(), "{}", stderr(&eval));
}

#[test]
fn a_time_range_without_frames_fails_naming_the_input_once() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Protobuf);
    let out_path = dir.path().join("out.mcap");
    let out = crate::common::process(&a, &out_path, &["--start", "1000"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("no colour/depth pair was processed"))
        .unwrap_or_else(|| panic!("no failure line: {err}"));
    assert!(
        line.starts_with("error: ") && line.contains("outside --start/--end"),
        "{line}"
    );
    assert_eq!(line.matches("a.mcap").count(), 1, "{line}");
    assert!(
        files_in(dir.path()).iter().all(|f| f == "a.mcap"),
        "{:?}",
        files_in(dir.path())
    );
}

#[test]
fn an_annotated_input_needs_replace_annotations_and_then_gets_one_run_of_each_channel() {
    use crate::common::recording::{messages, metadata, open};
    use std::collections::BTreeMap;
    let dir = tempfile::tempdir().unwrap();
    let desk = converted_tum_fixture(dir.path());
    let first = dir.path().join("first.mcap");
    let out = crate::common::process(&desk, &first, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));

    // Processing the annotated file again would mix two runs on the same channels.
    let second = dir.path().join("second.mcap");
    let out = crate::common::process(&first, &second, &[]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("earlier occmask run (/occmask/anchor_path, /occmask/mask, /occmask/mask_annotations,")
            && err.contains("--replace-annotations"),
        "{err}"
    );
    assert_eq!(files_in(dir.path()), vec!["desk.mcap", "first.mcap"]);

    let out = occmask(&[
        "process".as_ref(),
        first.as_os_str(),
        "-o".as_ref(),
        second.as_os_str(),
        "--replace-annotations".as_ref(),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("first.mcap: the earlier run's "), "{err}");
    // The same input images and parameters: the second run writes what the first did, once.
    let by_topic = |path: &Path| {
        let mut topics: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
        for m in messages(&open(path)) {
            topics.entry(m.topic).or_default().push(m.data);
        }
        topics
    };
    let (once, again) = (by_topic(&first), by_topic(&second));
    assert!(once.contains_key("/tf") && once.contains_key("/occmask/mask"));
    assert_eq!(once.keys().collect::<Vec<_>>(), again.keys().collect::<Vec<_>>());
    for (topic, data) in &once {
        assert!(
            again[topic] == *data,
            "{topic}: {} against {} messages",
            again[topic].len(),
            data.len()
        );
    }
    let runs = metadata(&open(&second))
        .iter()
        .filter(|m| m.name == occmask::mcap_io::annotate::METADATA_PROCESS)
        .count();
    assert_eq!(runs, 1);
}

#[test]
fn a_missing_or_double_destination_is_a_usage_error_naming_both_flags() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Json);
    let out = occmask(&["process".as_ref(), a.as_os_str()]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("<--output <OUTPUT>|--out-dir <OUT_DIR>|--print-config>"),
        "{err}"
    );
    let o = dir.path().join("o.mcap");
    let both = [
        "process".as_ref(),
        a.as_os_str(),
        "-o".as_ref(),
        o.as_os_str(),
        "--out-dir".as_ref(),
        dir.path().as_os_str(),
    ];
    let out = occmask(&both);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("cannot be used with"), "{}", stderr(&out));
    let out = occmask(&["process", "--print-config"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(files_in(dir.path()), vec!["a.mcap"]);
}

#[test]
fn refuses_overwrite_and_writing_over_an_input() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Json);
    let out_path = dir.path().join("out.mcap");
    std::fs::write(&out_path, b"precious").unwrap();
    let run = |extra: &[&str], output: &Path| {
        let mut args: Vec<std::ffi::OsString> =
            vec!["process".into(), a.clone().into(), "-o".into(), output.into()];
        args.extend(extra.iter().map(|s| s.into()));
        args.push("-q".into());
        occmask(&args)
    };
    let out = run(&[], &out_path);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--force"), "{}", stderr(&out));
    assert_eq!(std::fs::read(&out_path).unwrap(), b"precious");

    let out = run(&["--force"], &a);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("different from the input"),
        "{}",
        stderr(&out)
    );

    let out = run(&["--force"], &out_path);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_ne!(std::fs::read(&out_path).unwrap(), b"precious");
    // No temporary files left behind.
    assert_eq!(files_in(dir.path()), vec!["a.mcap", "out.mcap"]);

    // -o with several inputs is a usage error.
    let out = occmask(&[
        "process".as_ref(),
        a.as_os_str(),
        a.as_os_str(),
        "-o".as_ref(),
        out_path.as_os_str(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--out-dir"), "{}", stderr(&out));
}

#[test]
fn exports_are_written_and_output_bytes_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Protobuf);
    let masks = dir.path().join("masks");
    let traj = dir.path().join("traj.txt");
    let x = dir.path().join("x.mcap");
    let y = dir.path().join("y.mcap");
    let out = occmask(&[
        "process".as_ref(),
        a.as_os_str(),
        "-o".as_ref(),
        x.as_os_str(),
        "--export-trajectory".as_ref(),
        traj.as_os_str(),
        "--export-masks".as_ref(),
        masks.as_os_str(),
        "-q".as_ref(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let text = std::fs::read_to_string(&traj).unwrap();
    let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(lines.len(), 8);
    for l in &lines {
        assert!(occmask::trajectory::parse_tum_line(l).is_ok(), "{l}");
    }
    let pngs = files_in(&masks);
    assert_eq!(pngs.len(), 8);
    assert_eq!(pngs[0], "1700000000.000000.png");
    assert_eq!(pngs[1], "1700000000.033333333.png");
    let png = image::open(masks.join(&pngs[3])).unwrap().into_luma8();
    assert_eq!((png.width(), png.height()), (160, 120));

    let out = occmask(&[
        "process".as_ref(),
        a.as_os_str(),
        "-o".as_ref(),
        y.as_os_str(),
        "-q".as_ref(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        std::fs::read(&x).unwrap() == std::fs::read(&y).unwrap(),
        "two runs differ"
    );
}

#[test]
fn per_file_thread_pools_do_not_change_the_output_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Protobuf);
    let b = fixture(dir.path(), "b.mcap", Flavor::Ros2);
    let mut outputs = Vec::new();
    // Two files side by side with one compute thread each, then one after the other with three.
    for (name, jobs, threads, says) in [
        (
            "par",
            "2",
            "1",
            "2 file(s), 2 at a time, 1 compute thread(s) each",
        ),
        (
            "seq",
            "1",
            "3",
            "2 file(s), 1 at a time, 3 compute thread(s) each",
        ),
    ] {
        let out_dir = dir.path().join(name);
        std::fs::create_dir(&out_dir).unwrap();
        let out = occmask(&[
            "process".as_ref(),
            a.as_os_str(),
            b.as_os_str(),
            "--out-dir".as_ref(),
            out_dir.as_os_str(),
            "--jobs".as_ref(),
            jobs.as_ref(),
            "--threads-per-file".as_ref(),
            threads.as_ref(),
        ]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(0), "{err}");
        assert!(err.contains(says), "{err}");
        // The summary table lists both files with their frame counts.
        for file in ["a.mcap", "b.mcap"] {
            let row = err
                .lines()
                .find(|l| l.starts_with(file))
                .unwrap_or_else(|| panic!("{err}"));
            assert_eq!(row.split_whitespace().nth(1), Some("8"), "{row}");
        }
        outputs.push(["a.occmask.mcap", "b.occmask.mcap"].map(|f| std::fs::read(out_dir.join(f)).unwrap()));
    }
    assert!(
        outputs[0][0] == outputs[1][0],
        "a differs between the thread splits"
    );
    assert!(
        outputs[0][1] == outputs[1][1],
        "b differs between the thread splits"
    );
    // Out-of-range numbers are usage errors naming the range, never silently clamped or wrapped.
    for (flag, value, range) in [
        ("--jobs", "0", "from 1 to 1024"),
        ("--threads-per-file", "0", "from 1 to 1024"),
        ("--threads-per-file", "1000000", "from 1 to 1024"),
        ("--max-pair-gap-ms", "1e300", "from 0 to 60000"),
        ("--max-pair-gap-ms", "60001", "from 0 to 60000"),
        ("--chunk-size-mib", "1e300", "at most 1024"),
    ] {
        let out = occmask(&[
            "process".as_ref(),
            a.as_os_str(),
            "--out-dir".as_ref(),
            dir.path().as_os_str(),
            flag.as_ref(),
            value.as_ref(),
        ]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(err.contains(flag) && err.contains(range), "{flag} {value}: {err}");
    }
}

#[test]
fn external_poses_give_zero_odometry_error() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Ros2);
    let x = dir.path().join("x.mcap");
    let out = occmask(&[
        "process".as_ref(),
        a.as_os_str(),
        "-o".as_ref(),
        x.as_os_str(),
        "--pose-topic".as_ref(),
        GT_TOPIC.as_ref(),
        "-q".as_ref(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let eval = occmask(&["eval".as_ref(), "--json".as_ref(), x.as_os_str()]);
    let v: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    let rmse = v["odometry"]["rpe"][0]["translation_rmse_m"].as_f64().unwrap();
    assert!(rmse < 1e-9, "{v}");
}

#[test]
fn camera_from_marker_moves_external_poses_to_the_camera() {
    use prost::Message as _;
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Ros1);
    let x = dir.path().join("x.mcap");
    // The marker 10 cm to the camera's right and turned 90° about its z axis.
    let out = occmask(&[
        "process".as_ref(),
        a.as_os_str(),
        "-o".as_ref(),
        x.as_os_str(),
        "--pose-topic".as_ref(),
        GT_TOPIC.as_ref(),
        "--camera-from-marker".as_ref(),
        "0.1,0,0,0,0,0.70710678,0.70710678".as_ref(),
        "-q".as_ref(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let bytes = std::fs::read(&x).unwrap();
    let first = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .find(|m| m.channel.topic == occmask::mcap_io::annotate::TOPIC_ODOMETRY)
        .unwrap();
    let pose = foxglove::messages::PoseInFrame::decode(first.data.as_ref()).unwrap();
    let p = pose.pose.unwrap();
    let (t, q) = (p.position.unwrap(), p.orientation.unwrap());
    let odometry = nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(t.x, t.y, t.z),
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
    );
    let camera_from_marker = nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(0.1, 0.0, 0.0),
        nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
    );
    let expected = gt_pose(0) * camera_from_marker.inverse();
    assert!(
        (odometry.to_homogeneous() - expected.to_homogeneous()).norm() < 1e-6,
        "{odometry} vs {expected}"
    );
    // Without --pose-topic the flag is refused.
    let out = occmask(&[
        "process".as_ref(),
        a.as_os_str(),
        "-o".as_ref(),
        dir.path().join("y.mcap").as_os_str(),
        "--camera-from-marker".as_ref(),
        "bonn".as_ref(),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

/// `--config` with part of a nested object changes those fields only: the rest of the offline
/// refinement's DVO keeps the refinement's defaults (its weights and motion prior), as the
/// `processor_config` metadata of the output shows; an unknown field is refused by name.
#[test]
fn partial_config_keeps_the_defaults_of_each_place_and_unknown_fields_fail() {
    use occmask::pipeline::ProcessorConfig;
    let dir = tempfile::tempdir().unwrap();
    let input = fixture(dir.path(), "in.mcap", Flavor::Protobuf);
    let config = dir.path().join("config.json");
    // `process` with `json` as its --config, into `name`.
    let process_with = |json: &str, name: &str| {
        std::fs::write(&config, json).unwrap();
        let output = dir.path().join(name);
        let out = occmask(&[
            "process".as_ref(),
            input.as_os_str(),
            "-o".as_ref(),
            output.as_os_str(),
            "-q".as_ref(),
            "--config".as_ref(),
            config.as_os_str(),
        ]);
        (out, output)
    };
    let (out, output) = process_with(
        r#"{"offline": {"refinement_dvo": {"max_iterations_per_level": 7}}}"#,
        "out.mcap",
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let recorded = recorded_processor_config(&output);
    let mut expected = ProcessorConfig::default();
    expected.offline.refinement_dvo.max_iterations_per_level = 7;
    assert_eq!(recorded, expected);

    let (out, output) = process_with(
        r#"{"offline": {"refinement_dvo": {"max_iterations": 7}}}"#,
        "bad.mcap",
    );
    assert!(!out.status.success());
    assert!(stderr(&out).contains("max_iterations"), "{}", stderr(&out));
    assert!(!output.exists());
}

/// `--skip-existing` resumes a batch: an output that is a finished run of the same input and
/// parameters is kept as it is (not rewritten) and its input left out; an output that exists
/// but is not one fails its input with what it is and the flag that replaces it, and is not
/// touched.
#[cfg(unix)]
#[test]
fn skip_existing_keeps_finished_outputs_and_names_what_differs_in_the_others() {
    use std::os::unix::fs::MetadataExt;
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.mcap", Flavor::Protobuf);
    let b = fixture(dir.path(), "b.mcap", Flavor::Ros2);
    let c = fixture(dir.path(), "c.mcap", Flavor::Json);
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let output = |name: &str| out_dir.join(format!("{name}.occmask.mcap"));
    let process = |inputs: &[&Path], extra: &[&str]| {
        let mut args: Vec<std::ffi::OsString> = vec!["process".into()];
        args.extend(inputs.iter().map(|p| p.as_os_str().to_owned()));
        args.extend(["--out-dir".into(), out_dir.clone().into_os_string()]);
        args.extend(extra.iter().map(|s| s.into()));
        occmask(&args)
    };
    // The file as it stands: its bytes, inode and modification time (a rewrite renames a new
    // file into place).
    let identity = |path: &Path| {
        let m = std::fs::metadata(path).unwrap();
        (std::fs::read(path).unwrap(), m.ino(), m.modified().unwrap())
    };

    let first = process(&[&a], &["-q"]);
    assert!(first.status.success(), "{}", stderr(&first));
    let finished = identity(&output("a"));
    // c's output: a file that `process` did not write (a copy of an input).
    std::fs::copy(&c, output("c")).unwrap();
    let foreign = identity(&output("c"));

    let out = process(&[&a, &b, &c], &["--skip-existing"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("a.mcap") && err.contains("kept:"), "{err}");
    assert!(err.contains("1 of 3 files failed"), "{err}");
    assert!(
        err.contains("c.occmask.mcap exists but was not written by occmask process")
            && err.contains("pass --force to replace it"),
        "{err}"
    );
    assert_eq!(identity(&output("a")), finished);
    assert_eq!(identity(&output("c")), foreign);
    assert!(occmask(&["eval".as_ref(), output("b").as_os_str()])
        .status
        .success());

    // Other parameters: the first field that differs, with both values.
    let config = dir.path().join("alpha.json");
    std::fs::write(&config, r#"{"occlusion": {"alpha": 0.1}}"#).unwrap();
    let out = process(
        &[&a],
        &["--skip-existing", "-q", "--config", config.to_str().unwrap()],
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("was made with other parameters: occlusion.alpha is 0.15 there and 0.1 here"),
        "{err}"
    );
    let out = process(&[&a], &["--skip-existing", "-q", "--pose", "dvo-unmasked"]);
    assert!(
        stderr(&out).contains(r#"pose_source is "dvo" there and "dvo-unmasked" here"#),
        "{}",
        stderr(&out)
    );
    let out = process(&[&a], &["--skip-existing", "-q", "--end", "0.1"]);
    assert!(
        stderr(&out).contains(r#"end_offset_ns is absent there and "100000000" here"#),
        "{}",
        stderr(&out)
    );
    assert_eq!(identity(&output("a")), finished);

    // A recording of the same name from another folder (one frame longer) is another input.
    let elsewhere = dir.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let other_a = elsewhere.join("a.mcap");
    let longer = FixtureSpec {
        frames: spec().frames + 1,
        ..spec()
    };
    std::fs::write(&other_a, fixture_bytes(Flavor::Protobuf, &longer)).unwrap();
    let out = process(&[&other_a], &["--skip-existing", "-q"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("a.occmask.mcap exists but was made from another input: its input_log_time_span_ns is"),
        "{err}"
    );
    assert_eq!(identity(&output("a")), finished);

    // A cut copy of a finished output is not one.
    let b_bytes = std::fs::read(output("b")).unwrap();
    std::fs::write(output("c"), &b_bytes[..b_bytes.len() / 2]).unwrap();
    let out = process(&[&c], &["--skip-existing", "-q"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("exists but is incomplete"),
        "{}",
        stderr(&out)
    );

    // With every output finished, the batch succeeds and writes nothing.
    std::fs::remove_file(output("c")).unwrap();
    let out = process(&[&c], &["-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let before: Vec<_> = ["a", "b", "c"].iter().map(|n| identity(&output(n))).collect();
    let out = process(&[&a, &b, &c], &["--skip-existing", "-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let after: Vec<_> = ["a", "b", "c"].iter().map(|n| identity(&output(n))).collect();
    assert_eq!(after, before);
    assert_eq!(
        files_in(&out_dir),
        vec!["a.occmask.mcap", "b.occmask.mcap", "c.occmask.mcap"]
    );

    // Replacing and keeping exclude each other (a usage error).
    let out = process(&[&a], &["--skip-existing", "--force"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

/// The offline mode processes VGA at 320×240 and writes masks at the input's size;
/// `--full-resolution` processes it as it is (recorded in the output's `processor_config`); it
/// is refused beside `--causal`, which always runs at full resolution.
#[test]
fn full_resolution_is_recorded_and_both_write_masks_at_the_input_size() {
    let tmp = tempfile::tempdir().unwrap();
    let desk = converted_tum_fixture(tmp.path());
    let run = |name: &str, extra: &[&str]| {
        let output = tmp.path().join(format!("{name}.mcap"));
        let masks = tmp.path().join(name);
        let mut args = vec![
            "process".as_ref(),
            desk.as_os_str(),
            "-o".as_ref(),
            output.as_os_str(),
            "-q".as_ref(),
            "--export-masks".as_ref(),
            masks.as_os_str(),
        ];
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        let out = occmask(&args);
        (out, output, masks)
    };
    for (name, extra, working_side) in [("default", &[][..], 240), ("full", &["--full-resolution"][..], 0)] {
        let (out, output, masks) = run(name, extra);
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        let recorded = recorded_processor_config(&output);
        assert_eq!(recorded.offline.min_working_side_px, working_side, "{name}");
        let pngs = files_in(&masks);
        assert_eq!(pngs.len(), 10, "{name}");
        for png in &pngs {
            let png = image::open(masks.join(png)).unwrap().into_luma8();
            assert_eq!((png.width(), png.height()), (640, 480), "{name}");
        }
    }

    let (out, output, _) = run("causal", &["--full-resolution", "--causal"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--causal"), "{}", stderr(&out));
    assert!(!output.exists());
}

/// The offline mode's colour/depth registration check (docs/method.md D18) reports what it
/// decided: 7-Scenes (colour not registered to depth; its first 3.5 s) gets a warning naming the
/// score and the flag that turns the check off, the registered TUM excerpt none.
#[test]
fn an_unregistered_recording_is_reported_and_a_registered_one_is_not() {
    let tmp = tempfile::tempdir().unwrap();
    let desk = converted_tum_fixture(tmp.path());
    let annotated = tmp.path().join("desk.out.mcap");
    let out = occmask(&[
        "process".as_ref(),
        desk.as_os_str(),
        "-o".as_ref(),
        annotated.as_os_str(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(!stderr(&out).contains("not registered"), "{}", stderr(&out));

    let Some(src) = crate::common::data::real_data(
        "7scenes_redkitchen_300",
        "process_cli::an_unregistered_recording_is_reported_and_a_registered_one_is_not",
    ) else {
        return;
    };
    let kitchen = tmp.path().join("kitchen.mcap");
    let out = convert("tum", &src, &kitchen, &["--camera", "585,585,320,240", "-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let annotated = tmp.path().join("kitchen.out.mcap");
    let out = occmask(&[
        "process".as_ref(),
        kitchen.as_os_str(),
        "--end".as_ref(),
        "3.5".as_ref(),
        "-o".as_ref(),
        annotated.as_os_str(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("colour not registered to depth (registration score 0.")
            && err.contains("no_registration_check.json"),
        "{err}"
    );
}

/// Every kernel build (`OCCMASK_SIMD` caps the one that runs; a cap above the CPU's widest runs
/// its widest) writes the same output bytes on the TUM excerpt, whose real VGA frames run every
/// kernel of the offline closed loop; a value that names no build is an error naming the
/// variable and the values it takes.
#[test]
fn every_kernel_build_writes_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("tum.mcap");
    let out = convert("tum", &crate::common::tum_fixture(), &input, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let run = |build: &str| {
        let output = dir.path().join(format!("out_{build}.mcap"));
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_occmask"))
            .env("OCCMASK_SIMD", build)
            .args([
                "process".as_ref(),
                input.as_os_str(),
                "-o".as_ref(),
                output.as_os_str(),
                "-q".as_ref(),
            ])
            .output()
            .unwrap();
        (out, output)
    };
    let (out, widest) = run("");
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let widest = std::fs::read(widest).unwrap();
    for build in ["baseline", "avx2", "avx512"] {
        let (out, output) = run(build);
        assert_eq!(out.status.code(), Some(0), "{build}: {}", stderr(&out));
        assert!(std::fs::read(output).unwrap() == widest, "{build}: other bytes");
    }
    let (out, output) = run("sse4");
    assert_eq!(out.status.code(), Some(1));
    let message = stderr(&out);
    assert!(
        message.contains("OCCMASK_SIMD = sse4") && message.contains("baseline, avx2 or avx512"),
        "{message}"
    );
    assert!(!output.exists());
}
