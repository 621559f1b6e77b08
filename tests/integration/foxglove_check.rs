//! Outputs read the way Foxglove reads them: tools/foxglove_check/check.js opens the file with
//! `@mcap/core`'s indexed reader (Foxglove's and Lichtblick's MCAP data source), decodes every
//! message as their `parseChannel` does, compares each foxglove.* schema with
//! `@foxglove/schemas`, and checks what each panel of foxglove/occmask-layout.json needs
//! (image sizes and encodings, annotation stamps and points, the transform tree, pose frames,
//! the depth colour-map range, the plotted fields, the timeline Foxglove derives from the chunk
//! indexes). The Python validators (tests/integration/python_validators.rs) check MCAP conformance and
//! decoding with the file's own schemas; this checks what Foxglove shows.
//!
//! Needs `node` and `npm ci --prefix tools/foxglove_check` (`.ci/run` does it). Without them the
//! tests fail under CI (`CI` set) and are skipped with a notice otherwise.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns: a panic is the failure report

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::*;

fn check_script() -> Option<PathBuf> {
    let dir = repo().join("tools/foxglove_check");
    let ready = dir.join("node_modules/@mcap/core").is_dir()
        && Command::new("node")
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
    if ready {
        return Some(dir.join("check.js"));
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "node or tools/foxglove_check/node_modules is missing but CI is set: run the tests through \
         `bash .ci/run` (it runs `npm ci --prefix tools/foxglove_check`)"
    );
    // Written to the stderr handle directly so the test harness does not capture it.
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "skipped foxglove_check: needs node and `npm ci --prefix tools/foxglove_check` (bash .ci/run does)"
    );
    None
}

fn run_check(script: &Path, file: &Path, layout: Option<&Path>) -> Output {
    let mut cmd = Command::new("node");
    cmd.arg(script).arg(file);
    if let Some(layout) = layout {
        cmd.arg("--layout").arg(layout);
    }
    cmd.output().unwrap()
}

fn assert_passes(script: &Path, file: &Path) -> String {
    let out = run_check(script, file, None);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{}\n{stdout}\n{}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// The demo: moving objects (annotations with outlines), ground truth, log times from 0.
#[test]
fn demo_output_passes_the_foxglove_check_and_a_wrong_layout_fails_it() {
    let Some(script) = check_script() else { return };
    let dir = tempfile::tempdir().unwrap();
    let output = dir.path().join("demo.mcap");
    let run = occmask(&[
        "demo".as_ref(),
        "--width".as_ref(),
        "320".as_ref(),
        "--output".as_ref(),
        output.as_os_str(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let stdout = assert_passes(&script, &output);
    // Outlines were really checked, not vacuously: the demo has a moving object in most frames.
    let outlines: usize = stdout
        .lines()
        .find(|l| l.contains("/occmask/mask_annotations: one per colour image"))
        .and_then(|l| l.split(" messages, ").nth(1))
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert!(outlines >= 100, "{stdout}");

    // The checks can fail: the layouts this tool caught (Foxglove's default 0-65535 depth range,
    // synchronized annotations with empty messages on static frames) must be refused.
    let mut layout: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(repo().join("foxglove/occmask-layout.json")).unwrap())
            .unwrap();
    layout["configById"]["Image!occmask-depth"]["imageMode"]["maxValue"] = 65535.into();
    layout["configById"]["Image!occmask-color"]["imageMode"]["synchronize"] = true.into();
    let bad_layout = dir.path().join("bad-layout.json");
    std::fs::write(&bad_layout, layout.to_string()).unwrap();
    let out = run_check(&script, &output, Some(&bad_layout));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    for expected in [
        "FAIL Image!occmask-depth: colour-map range",
        "FAIL Image!occmask-color: synchronize",
    ] {
        assert!(stdout.contains(expected), "{expected}\n{stdout}");
    }
}

/// Real data through `convert` and `process --points`: a static scene (empty annotations), real
/// stamps, the point clouds in the 3D panel in their own colours; a layout without the clouds'
/// colour field (Foxglove then replaces the colour mode) fails.
#[test]
fn processed_tum_output_passes_the_foxglove_check() {
    let Some(script) = check_script() else { return };
    let dir = tempfile::tempdir().unwrap();
    let converted = dir.path().join("desk.mcap");
    let processed = dir.path().join("desk.out.mcap");
    let data = tum_fixture();
    let run = convert("tum", &data, &converted, &["--quiet"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let run = occmask(&[
        "process".as_ref(),
        converted.as_os_str(),
        "-o".as_ref(),
        processed.as_os_str(),
        "--quiet".as_ref(),
        "--points".as_ref(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let stdout = assert_passes(&script, &processed);
    for expected in [
        "ok   timeline from the chunk indexes equals the messages' time range",
        "ok   /occmask/points: PointCloud per colour image",
        "ok   3D!occmask-scene: topic /occmask/points is in the file",
        "ok   3D!occmask-scene: /occmask/points colour mode rgba-fields beside a colorField",
    ] {
        assert!(stdout.contains(expected), "{expected}\n{stdout}");
    }

    let mut layout: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(repo().join("foxglove/occmask-layout.json")).unwrap())
            .unwrap();
    let points = &mut layout["configById"]["3D!occmask-scene"]["topics"]["/occmask/points"];
    points.as_object_mut().unwrap().remove("colorField");
    let bad_layout = dir.path().join("bad-layout.json");
    std::fs::write(&bad_layout, layout.to_string()).unwrap();
    let out = run_check(&script, &processed, Some(&bad_layout));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    assert!(
        stdout.contains("FAIL 3D!occmask-scene: /occmask/points colour mode rgba-fields"),
        "{stdout}"
    );
}
