//! `occmask demo` at the process boundary: exit code, printed scores, and an MCAP file with the
//! convert channels plus every channel `occmask process` adds; no temporary file left behind.
#![allow(clippy::unwrap_used)]

use crate::common;

use std::collections::BTreeMap;
use std::process::Command;

#[test]
fn demo_writes_an_mcap_with_masks_and_poses_and_prints_scores() {
    let dir = tempfile::tempdir().unwrap();
    let output = dir.path().join("demo.mcap");
    let run = Command::new(env!("CARGO_BIN_EXE_occmask"))
        .args(["demo", "--width", "320", "--output"])
        .arg(&output)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("F1 / precision / recall") && stdout.contains("RPE Δ=1"),
        "{stdout}"
    );
    // The RPE over the whole run has one pair; its columns line up with the others'.
    let rpe_rows: Vec<&str> = stdout.lines().filter(|l| l.contains("RPE Δ=")).collect();
    assert!(rpe_rows.iter().any(|l| l.contains("(    1 pair)  ")), "{stdout}");
    let metres_column = |l: &&str| l.find(" m ");
    assert!(
        rpe_rows
            .windows(2)
            .all(|w| metres_column(&w[0]) == metres_column(&w[1])),
        "{stdout}"
    );
    // The closed loop on the dominant object: the bar is F1 >= 0.85.
    let f1: f64 = stdout
        .lines()
        .find_map(|l| l.trim().strip_prefix("F1 / precision / recall"))
        .and_then(|rest| rest.split('/').next())
        .and_then(|v| v.trim().parse().ok())
        .unwrap();
    assert!(f1 >= 0.85, "F1 {f1}\n{stdout}");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers, vec![std::ffi::OsString::from("demo.mcap")]);
    let bytes = std::fs::read(&output).unwrap();
    let mut per_topic: BTreeMap<String, usize> = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        *per_topic
            .entry(message.unwrap().channel.topic.clone())
            .or_default() += 1;
    }
    for topic in [
        "/camera/rgb/image",
        "/camera/rgb/camera_info",
        "/camera/depth/image",
        "/camera/depth/camera_info",
        "/groundtruth/pose",
        "/groundtruth/mask",
        "/occmask/mask",
        "/occmask/mask_annotations",
        "/occmask/odometry",
        "/occmask/stats",
    ] {
        assert_eq!(per_topic.get(topic), Some(&150), "{topic}: {per_topic:?}");
    }
    // Ground truth and estimate share the input's /tf channel.
    assert_eq!(per_topic.get("/tf"), Some(&300));
    assert!(
        per_topic.get("/occmask/path").is_some_and(|&n| n > 0),
        "{per_topic:?}"
    );
    // Real MCAP clients, when `bash .ci/run` provides them (see tests/integration/python_validators.rs).
    if let Some(python) = std::env::var_os("OCCMASK_PYTHON").map(std::path::PathBuf::from) {
        let cli = python.with_file_name("pymcap-cli");
        let doctor = Command::new(&cli)
            .args(["doctor", "--strict-message-order", "--format", "jsonl"])
            .arg(&output)
            .output()
            .unwrap();
        let report = String::from_utf8_lossy(&doctor.stdout);
        assert!(
            doctor.status.success() && report.contains("\"errors\":0") && report.contains("\"warnings\":0"),
            "{report}"
        );
        // The demo's output is a `process` output: check it with the process validator.
        let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/process_validate.py");
        let read = Command::new(&python)
            .arg(script)
            .arg(&output)
            .arg("150")
            .output()
            .unwrap();
        assert!(read.status.success(), "{}", String::from_utf8_lossy(&read.stderr));
    }
    // A second run without --force refuses to overwrite.
    let again = Command::new(env!("CARGO_BIN_EXE_occmask"))
        .args(["demo", "--width", "320", "--output"])
        .arg(&output)
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(1));
}

/// `occmask demo | head` with the reader already gone: the demo still writes its file, then
/// ends on SIGPIPE like any filter when it prints, with no panic message.
#[cfg(unix)]
#[test]
fn demo_into_a_closed_pipe_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let output = dir.path().join("demo.mcap");
    let args = [
        "demo".as_ref(),
        "--width".as_ref(),
        "160".as_ref(),
        "--output".as_ref(),
        output.as_os_str(),
    ];
    common::assert_ends_quietly_on_a_closed_pipe(&args, "demo");
    assert!(
        output.is_file(),
        "the demo's file is written before anything is printed"
    );
}
