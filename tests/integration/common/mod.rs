//! Helpers shared by the integration tests: run the binary, build dataset folders, find the
//! real data ([`data`]), build in-memory MCAP recordings ([`mcap_fixture`]), read MCAP files
//! back ([`recording`]), read TUM sequences through the library's dataset reader ([`tum`]).
#![allow(dead_code)] // not every helper is used by a test in every configuration
#![allow(clippy::unwrap_used)] // test helpers: a panic is the failure report

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub mod data;
pub mod mcap_fixture;
pub mod recording;
pub mod tum;

pub use data::*;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The configuration preset `tools/detector_configs/NAME`, as `occmask process --config` reads it.
pub fn detector_preset(name: &str) -> occmask::pipeline::ProcessorConfig {
    let path = repo().join("tools/detector_configs").join(name);
    occmask::pipeline::ProcessorConfig::from_json(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

/// The LARR fixture folder.
pub fn larr_fixture() -> PathBuf {
    repo().join("fixtures/larr_fr2_desk_mini")
}

/// TUM fr2 intrinsics at pyramid level 2, matching the 160×120 fixture.
pub const FIXTURE_CAMERA: &str = "130.225,130.25,80.9,62.05";

/// Runs `occmask` with `args`.
pub fn occmask<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_occmask"))
        .args(args)
        .output()
        .expect("cannot start the occmask binary")
}

/// Runs `occmask convert KIND DIR -o OUT` with `extra` arguments after them.
pub fn convert(kind: &str, dir: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "convert".as_ref(),
        kind.as_ref(),
        dir.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ];
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    occmask(&args)
}

/// Runs `occmask process INPUT -o OUT -q` with `extra` arguments after them.
pub fn process(input: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "process".as_ref(),
        input.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
        "-q".as_ref(),
    ];
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    occmask(&args)
}

/// Runs `occmask args` with stdout a pipe whose reader is already gone (`occmask … | head` once
/// head has exited) and asserts that the process ended on SIGPIPE, as a Unix filter does, with
/// no panic message; `what` names the case in the assertion messages.
#[cfg(unix)]
pub fn assert_ends_quietly_on_a_closed_pipe<S: AsRef<std::ffi::OsStr>>(args: &[S], what: &str) {
    use std::os::unix::process::ExitStatusExt;
    let mut child = Command::new(env!("CARGO_BIN_EXE_occmask"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("cannot start the occmask binary");
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(!err.contains("panicked"), "{what}: {err}");
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGPIPE),
        "{what}: {:?}: {err}",
        out.status
    );
}

/// stderr as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Copies a directory tree.
pub fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for entry in std::fs::read_dir(src).unwrap() {
        let entry = entry.unwrap();
        let target = dst.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// Builds a TUM-layout folder `<parent>/<name>` from the LARR fixture's frames:
/// rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt. Returns its path.
pub fn tum_from_fixture(parent: &Path, name: &str) -> PathBuf {
    let dir = parent.join(name);
    let src = larr_fixture();
    copy_dir(&src.join("rgb"), &dir.join("rgb"));
    copy_dir(&src.join("depth"), &dir.join("depth"));
    std::fs::copy(src.join("groundtruth.txt"), dir.join("groundtruth.txt")).unwrap();
    for (sub, list) in [("rgb", "rgb.txt"), ("depth", "depth.txt")] {
        let mut names: Vec<String> = std::fs::read_dir(dir.join(sub))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        let mut text = format!("# {sub} images\n# timestamp filename\n");
        for n in names {
            text.push_str(&format!("{} {sub}/{n}\n", n.trim_end_matches(".png")));
        }
        std::fs::write(dir.join(list), text).unwrap();
    }
    dir
}

/// Names of the entries of a directory, sorted.
pub fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}
