//! Replays the fuzzing regressions (`fuzz/regressions/<target>/`: every input that once made a
//! target panic, abort or hang) and the committed minimized corpora (`fuzz/corpus-min/<target>/`)
//! through the very same harness functions the cargo-fuzz targets call (fuzz/src/lib.rs), so
//! the findings stay fixed in a plain `cargo test` on stable. Errors are fine; a panic fails.

#[path = "../../fuzz/src/lib.rs"]
#[allow(dead_code)]
mod harness;

use std::path::{Path, PathBuf};

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz")
}

/// Every file under `fuzz/<kind>/<target>/`, sorted (missing directories give none).
fn inputs(kind: &str, target: &str) -> Vec<PathBuf> {
    let dir = fuzz_dir().join(kind).join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|entries| entries.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.retain(|p| p.is_file());
    files.sort();
    files
}

/// Feeds every regression and corpus file of `target` to `run`; returns how many ran.
fn replay(target: &str, mut run: impl FnMut(&[u8])) -> usize {
    let mut count = 0;
    for path in inputs("regressions", target)
        .into_iter()
        .chain(inputs("corpus-min", target))
    {
        let data = std::fs::read(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        eprintln!("{target}: {}", path.display());
        run(&data);
        count += 1;
    }
    count
}

#[test]
fn proto_image_inputs_never_panic() {
    assert!(replay("proto_image", harness::proto_image) > 0);
}

#[test]
fn proto_calibration_inputs_never_panic() {
    assert!(replay("proto_calibration", harness::proto_calibration) > 0);
}

#[test]
fn json_message_inputs_never_panic() {
    assert!(replay("json_messages", harness::json_messages) > 0);
}

#[test]
fn ros2_image_inputs_never_panic() {
    assert!(replay("ros2_image", harness::ros2_image) > 0);
}

#[test]
fn ros2_camera_info_inputs_never_panic() {
    assert!(replay("ros2_camera_info", harness::ros2_camera_info) > 0);
}

#[test]
fn ros1_message_inputs_never_panic() {
    assert!(replay("ros1_messages", harness::ros1_messages) > 0);
}

#[test]
fn field_pixel_inputs_never_panic() {
    assert!(replay("field_pixels", harness::field_pixels) > 0);
}

#[test]
fn pose_inputs_never_panic() {
    assert!(replay("poses", harness::poses) > 0);
}

#[test]
fn text_parser_inputs_never_panic() {
    assert!(replay("text_parsers", harness::text_parsers) > 0);
}

#[test]
fn mcap_file_inputs_never_panic() {
    assert!(replay("mcap_file", harness::mcap_file) > 0);
}
