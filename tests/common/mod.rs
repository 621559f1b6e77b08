//! Helpers shared by the integration tests: run the binary, build dataset folders.
#![allow(dead_code)] // each test crate uses a different subset
#![allow(clippy::unwrap_used)] // test helpers: a panic is the failure report

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod data;
pub use data::*;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
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
