//! Where the tests, benchmarks and examples find real RGB-D data.
//!
//! - [`tum_fixture`]: ten frames of TUM RGB-D fr2_desk committed in `fixtures/` (CC BY 4.0),
//!   always there, so `cargo test` passes on a fresh clone.
//! - [`real_data`]: the larger sequences (7-Scenes, TUM fr2_desk 50 frames, Bonn), which may
//!   not be copied into the repository. They are read from `$OCCMASK_DATA`, else from
//!   `../shared/data` beside the crate. Without them a test prints one line saying it was
//!   skipped and why, and returns; with `OCCMASK_DATA` set (as `.ci/run` does) a missing
//!   sequence fails the test instead, so CI never skips.
#![allow(dead_code)] // the benchmarks and examples that include this file use a subset

use std::io::Write;
use std::path::{Path, PathBuf};

/// The environment variable naming the folder of the larger real sequences.
pub const DATA_ENV: &str = "OCCMASK_DATA";

/// The committed TUM fr2_desk excerpt: 10 colour/depth pairs at 640×480 with their
/// motion-capture ground truth, in the TUM layout (see `fixtures/README.md`).
pub fn tum_fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/tum_fr2_desk_10")
}

/// Number of colour (and depth) frames in [`tum_fixture`].
pub const TUM_FIXTURE_FRAMES: usize = 10;

/// The folder of the larger sequences and whether `OCCMASK_DATA` named it.
pub fn real_data_root() -> (PathBuf, bool) {
    match std::env::var_os(DATA_ENV) {
        Some(dir) if !dir.is_empty() => (PathBuf::from(dir), true),
        _ => (
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
            false,
        ),
    }
}

/// The larger real sequence `name` (a folder under [`real_data_root`]), or `None` after one
/// line on stderr naming `test`, the missing folder and how to provide it.
///
/// # Panics
/// When `OCCMASK_DATA` is set but the sequence is not in it: a run that asked for the real
/// data must not pass by skipping.
pub fn real_data(name: &str, test: &str) -> Option<PathBuf> {
    let (root, explicit) = real_data_root();
    let dir = root.join(name);
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        !explicit,
        "{test}: {} is missing, but {DATA_ENV}={} asks for the real data",
        dir.display(),
        root.display()
    );
    // Written to the stderr handle, not with eprintln!: the test harness captures the macros'
    // output of passing tests, and this line is meant to be seen.
    let _ = writeln!(
        std::io::stderr().lock(),
        "skipped {test}: needs the real sequence {name}, not found in {} (set {DATA_ENV} to the folder that holds it)",
        root.display()
    );
    None
}
