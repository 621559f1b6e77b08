//! Process-boundary tests of `occmask convert`: exit codes, messages, outputs.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns: a panic is the failure report

use crate::common;

use std::path::{Path, PathBuf};

use common::recording;
use common::*;
use foxglove::messages as fm;
use occmask::mcap_io::codec::timestamp_ns;
use occmask::mcap_io::{
    SCHEMA_COMPRESSED_IMAGE, TOPIC_COLOR_IMAGE, TOPIC_DEPTH_IMAGE, TOPIC_GROUNDTRUTH_MASK,
    TOPIC_GROUNDTRUTH_POSE,
};

/// Asserts a failed conversion: exit code 1, `needles` all in stderr, and no output or
/// temporary file left in the output's directory.
fn assert_fails(out: &std::process::Output, output: &Path, needles: &[&str]) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "expected exit 1, stderr: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr should mention {n:?}: {err}");
    }
    assert!(err.starts_with("error: "), "{err}");
    let dir = output.parent().unwrap();
    let left: Vec<String> = entries(dir)
        .into_iter()
        .filter(|e| e.contains("out.mcap"))
        .collect();
    assert!(left.is_empty(), "output files left behind: {left:?}");
}

struct Case {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
    out: PathBuf,
}

/// A TUM-layout copy of the fixture in a fresh temp dir, output beside it.
fn tum_case() -> Case {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tum_from_fixture(tmp.path(), "tum_fr2_mini");
    let out = tmp.path().join("out.mcap");
    Case { _tmp: tmp, dir, out }
}

fn first_file(dir: &Path) -> PathBuf {
    dir.join(&entries(dir)[0])
}

#[test]
fn tum_converts_and_summarises() {
    let c = tum_case();
    let out = convert("tum", &c.dir, &c.out, &["--camera", FIXTURE_CAMERA]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(err.contains("4 colour + 4 depth frames (4 pairs)"), "{err}");
    assert!(err.contains("ground-truth poses"), "{err}");
    assert_eq!(entries(c.out.parent().unwrap()), vec!["out.mcap", "tum_fr2_mini"]);
}

#[test]
fn quiet_prints_nothing() {
    let c = tum_case();
    let out = convert("tum", &c.dir, &c.out, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(out.stderr.is_empty() && out.stdout.is_empty(), "{}", stderr(&out));
}

#[test]
fn unknown_camera_falls_back_to_kinect_default_with_a_warning() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tum_from_fixture(tmp.path(), "office");
    let out = convert("tum", &dir, &tmp.path().join("out.mcap"), &[]);
    assert_eq!(out.status.code(), Some(0));
    assert!(stderr(&out).contains("Kinect default"), "{}", stderr(&out));
}

#[test]
fn same_input_gives_identical_bytes() {
    // The command line (with the output path) is part of the metadata, so run the very same
    // command twice, moving the first result aside.
    let c = tum_case();
    let first = c.out.with_file_name("first.mcap");
    assert_eq!(convert("tum", &c.dir, &c.out, &["-q"]).status.code(), Some(0));
    std::fs::rename(&c.out, &first).unwrap();
    assert_eq!(convert("tum", &c.dir, &c.out, &["-q"]).status.code(), Some(0));
    let (a, b) = (std::fs::read(&first).unwrap(), std::fs::read(&c.out).unwrap());
    assert!(a == b, "outputs differ ({} vs {} bytes)", a.len(), b.len());
}

#[test]
fn refuses_to_overwrite_without_force() {
    let c = tum_case();
    std::fs::write(&c.out, b"precious").unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--force"), "{}", stderr(&out));
    assert_eq!(std::fs::read(&c.out).unwrap(), b"precious");
    let out = convert("tum", &c.dir, &c.out, &["--force"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(std::fs::read(&c.out).unwrap().starts_with(b"\x89MCAP0\r\n"));
}

#[test]
fn output_may_not_be_a_directory_or_the_input() {
    let c = tum_case();
    let out = convert("tum", &c.dir, &c.dir, &["--force"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("found a directory"), "{}", stderr(&out));
}

#[test]
fn usage_errors_exit_2() {
    let c = tum_case();
    for extra in [&["--camera", "fr9"][..], &["--compression", "gzip"], &["--bogus"]] {
        let out = convert("tum", &c.dir, &c.out, extra);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {}", stderr(&out));
    }
    // Numbers out of range name the flag and the range (1e300 ms once saturated silently).
    for (extra, range) in [
        (["--max-pair-gap-ms", "1e300"], "from 0 to 60000"),
        (["--max-pair-gap-ms", "inf"], "from 0 to 60000"),
        (["--chunk-size-mib", "1e300"], "at most 1024"),
    ] {
        let out = convert("tum", &c.dir, &c.out, &extra);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(extra[0]) && err.contains(range), "{extra:?}: {err}");
    }
    assert_eq!(occmask(&["convert", "tum"]).status.code(), Some(2));
    assert!(!c.out.exists());
}

#[test]
fn help_has_examples() {
    for args in [
        &["convert", "--help"][..],
        &["convert", "tum", "--help"],
        &["convert", "larr", "--help"],
        &["convert", "bonn", "--help"],
    ] {
        let out = occmask(args);
        assert_eq!(out.status.code(), Some(0));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains("Examples:") && text.contains("occmask convert"),
            "{text}"
        );
    }
}

// ---- one test per bad-input class ------------------------------------------------------

#[test]
fn bad_missing_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let out_path = tmp.path().join("out.mcap");
    let out = convert("tum", &tmp.path().join("nope"), &out_path, &[]);
    assert_fails(
        &out,
        &out_path,
        &["expected a TUM RGB-D dataset directory, found nothing", "nope"],
    );
    let out = convert("larr", &tmp.path().join("nope"), &out_path, &[]);
    assert_fails(&out, &out_path, &["LARR", "nope"]);
}

#[test]
fn bad_missing_list_file_or_directory() {
    let c = tum_case();
    std::fs::remove_file(c.dir.join("depth.txt")).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(
        &out,
        &c.out,
        &["expected depth.txt", "depth.txt", "use `occmask convert larr`"],
    );

    let tmp = tempfile::tempdir().unwrap();
    let larr = tmp.path().join("larr");
    copy_dir(&larr_fixture(), &larr);
    std::fs::remove_dir_all(larr.join("depth")).unwrap();
    let out_path = tmp.path().join("out.mcap");
    let out = convert("larr", &larr, &out_path, &[]);
    assert_fails(&out, &out_path, &["expected a 'depth/' directory"]);
}

#[test]
fn bad_listed_image_missing() {
    let c = tum_case();
    let victim = first_file(&c.dir.join("rgb"));
    std::fs::remove_file(&victim).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(&out, &c.out, &["line 3", "does not exist", "rgb.txt"]);
}

#[test]
fn bad_truncated_colour_image() {
    let c = tum_case();
    let victim = first_file(&c.dir.join("rgb"));
    let bytes = std::fs::read(&victim).unwrap();
    std::fs::write(&victim, &bytes[..bytes.len() / 2]).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    let name = victim.file_name().unwrap().to_string_lossy().into_owned();
    assert_fails(&out, &c.out, &["truncated PNG colour image", &name]);
}

#[test]
fn bad_truncated_or_garbage_depth_image() {
    let c = tum_case();
    let victim = first_file(&c.dir.join("depth"));
    let bytes = std::fs::read(&victim).unwrap();
    std::fs::write(&victim, &bytes[..bytes.len() - 40]).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    let name = victim.file_name().unwrap().to_string_lossy().into_owned();
    assert_fails(&out, &c.out, &["corrupt or truncated depth PNG", &name]);

    std::fs::write(&victim, b"not an image at all").unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(&out, &c.out, &["no PNG signature", &name]);
}

#[test]
fn bad_size_mismatch() {
    let c = tum_case();
    let victim = first_file(&c.dir.join("depth"));
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(80, 60, image::Luma([1000]))
        .save(&victim)
        .unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(
        &out,
        &c.out,
        &[
            "image size 80x60 does not match the expected 160x120",
            "depth image",
        ],
    );
}

#[test]
fn bad_8bit_depth() {
    let c = tum_case();
    let victim = first_file(&c.dir.join("depth"));
    image::GrayImage::from_pixel(160, 120, image::Luma([7]))
        .save(&victim)
        .unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(
        &out,
        &c.out,
        &[
            "expected a 16-bit single-channel depth PNG, found L8",
            "8-bit depth",
        ],
    );
}

#[test]
fn bad_malformed_lines() {
    let c = tum_case();
    let list = c.dir.join("rgb.txt");
    let mut text = std::fs::read_to_string(&list).unwrap();
    text.push_str("1311868165.0 rgb/extra.png trailing\n");
    std::fs::write(&list, text).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(
        &out,
        &c.out,
        &["line 7", "expected 2 fields 'timestamp path', found 3", "rgb.txt"],
    );

    let c = tum_case();
    let gt = c.dir.join("groundtruth.txt");
    let text = std::fs::read_to_string(&gt).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    // Line 3 is the first pose: make its quaternion non-unit by setting qw = 3.
    let mut fields: Vec<&str> = lines[2].split_whitespace().collect();
    fields[7] = "3.0";
    lines[2] = fields.join(" ");
    std::fs::write(&gt, lines.join("\n")).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(&out, &c.out, &["line 3", "unit quaternion", "groundtruth.txt"]);

    let c = tum_case();
    std::fs::write(c.dir.join("depth.txt"), "12:30 depth/x.png\n").unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(&out, &c.out, &["line 1", "decimal seconds", "depth.txt"]);
}

#[test]
fn bad_non_monotonic_timestamps_are_rejected() {
    let c = tum_case();
    let list = c.dir.join("rgb.txt");
    let text = std::fs::read_to_string(&list).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.swap(3, 4);
    std::fs::write(&list, lines.join("\n")).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(
        &out,
        &c.out,
        &["line 5", "increase strictly", "is earlier than", "rgb.txt"],
    );
}

#[test]
fn bad_duplicate_timestamps_are_rejected() {
    let c = tum_case();
    let list = c.dir.join("depth.txt");
    let text = std::fs::read_to_string(&list).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let dup = lines[2].clone();
    lines.insert(3, dup);
    std::fs::write(&list, lines.join("\n")).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(&out, &c.out, &["line 4", "duplicates", "depth.txt"]);
}

#[test]
fn bad_empty_sequence() {
    let c = tum_case();
    std::fs::write(c.dir.join("rgb.txt"), "# color images\n# timestamp filename\n").unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_fails(&out, &c.out, &["empty sequence", "rgb.txt"]);

    let tmp = tempfile::tempdir().unwrap();
    let larr = tmp.path().join("larr");
    copy_dir(&larr_fixture(), &larr);
    for f in entries(&larr.join("rgb")) {
        std::fs::remove_file(larr.join("rgb").join(f)).unwrap();
    }
    let out_path = tmp.path().join("out.mcap");
    let out = convert("larr", &larr, &out_path, &[]);
    assert_fails(&out, &out_path, &["empty sequence"]);
}

#[test]
fn bad_no_pairs_within_tolerance() {
    let c = tum_case();
    let out = convert("tum", &c.dir, &c.out, &["--max-pair-gap-ms", "1"]);
    assert_fails(
        &out,
        &c.out,
        &[
            "no colour frame has a depth frame within 1.0 ms",
            "--max-pair-gap-ms",
        ],
    );
}

// ---- pairing and LARR ------------------------------------------------------------------

#[test]
fn unpaired_frames_are_reported_and_kept_on_request() {
    let c = tum_case();
    // Drop the second depth frame: colour frame 2 loses its partner (next depth is > 20 ms away).
    let list = c.dir.join("depth.txt");
    let text = std::fs::read_to_string(&list).unwrap();
    let lines: Vec<&str> = text
        .lines()
        .enumerate()
        .filter(|(i, _)| *i != 3)
        .map(|(_, l)| l)
        .collect();
    std::fs::write(&list, lines.join("\n")).unwrap();
    let out = convert("tum", &c.dir, &c.out, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("skipped 1 colour frames with no depth frame within 20 ms (at 1311868164.399026)"),
        "{err}"
    );
    assert!(err.contains("3 colour + 3 depth frames (3 pairs)"), "{err}");

    let kept = c.out.with_file_name("kept.mcap");
    let out = convert("tum", &c.dir, &kept, &["--keep-unpaired"]);
    assert!(
        stderr(&out).contains("4 colour + 3 depth frames (3 pairs)"),
        "{}",
        stderr(&out)
    );
}

fn read_topic_stamps(path: &Path, topic: &str) -> Vec<u64> {
    recording::messages(&recording::open(path))
        .into_iter()
        .filter(|m| m.topic == topic)
        .map(|m| m.log_time_ns)
        .collect()
}

#[test]
fn larr_fixture_converts_with_masks() {
    let tmp = tempfile::tempdir().unwrap();
    let out_path = tmp.path().join("out.mcap");
    let out = convert("larr", &larr_fixture(), &out_path, &["--camera", FIXTURE_CAMERA]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(stderr(&out).contains("4 masks"), "{}", stderr(&out));

    let input = recording::open(&out_path);
    let depth = input.channel_by_topic(TOPIC_DEPTH_IMAGE).unwrap();
    assert_eq!(
        depth.metadata.get("depth_units_per_meter").map(String::as_str),
        Some("1000")
    );
    let color_stamps = read_topic_stamps(&out_path, TOPIC_COLOR_IMAGE);
    let mut mask_stamps = Vec::new();
    for m in recording::messages(&input) {
        if m.topic != TOPIC_GROUNDTRUTH_MASK {
            continue;
        }
        let raw: fm::RawImage = m.decode();
        assert_eq!(raw.encoding, "mono8");
        assert_eq!(timestamp_ns(raw.timestamp.as_ref()), m.log_time_ns);
        assert_eq!((raw.width, raw.height, raw.step), (160, 120, 160));
        assert_eq!(raw.data.len(), 160 * 120);
        let set = raw.data.iter().filter(|&&v| v == 255).count();
        assert!(raw.data.iter().all(|&v| v == 0 || v == 255));
        // The mug polygon covers ~2200 px at full resolution, ~140 px at 1/16 area.
        assert!((100..200).contains(&set), "{set} mask pixels");
        mask_stamps.push(m.log_time_ns);
    }
    assert_eq!(mask_stamps, color_stamps);
    assert_eq!(mask_stamps.len(), 4);
}

#[test]
fn larr_variants_underscore_dir_and_no_association() {
    let tmp = tempfile::tempdir().unwrap();
    let larr = tmp.path().join("larr");
    copy_dir(&larr_fixture(), &larr);
    std::fs::rename(larr.join("groundtruth mask"), larr.join("groundtruth_mask")).unwrap();
    std::fs::remove_file(larr.join("association.txt")).unwrap();
    let out_path = tmp.path().join("out.mcap");
    let out = convert("larr", &larr, &out_path, &["-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(read_topic_stamps(&out_path, TOPIC_GROUNDTRUTH_MASK).len(), 4);
    assert_eq!(read_topic_stamps(&out_path, TOPIC_DEPTH_IMAGE).len(), 4);
}

#[test]
fn jpeg_colour_passes_through_unchanged() {
    let Some(src) = real_data(
        "7scenes_redkitchen_300",
        "convert_cli::jpeg_colour_passes_through_unchanged",
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // A 5-frame TUM-layout view of the (non-redistributable) sequence, built in the temp dir.
    let dir = tmp.path().join("kitchen");
    for list in ["rgb.txt", "depth.txt"] {
        let text = std::fs::read_to_string(src.join(list)).unwrap();
        let kept: Vec<String> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .take(5)
            .map(|l| {
                let (t, p) = l.split_once(' ').unwrap();
                format!("{t} {}", src.join(p).display())
            })
            .collect();
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(list), kept.join("\n")).unwrap();
    }
    let out_path = tmp.path().join("out.mcap");
    let out = convert("tum", &dir, &out_path, &["--camera", "kinect-default", "-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let rgb_list = std::fs::read_to_string(dir.join("rgb.txt")).unwrap();
    let mut files = rgb_list.lines().map(|l| l.split_once(' ').unwrap().1.to_owned());
    let mut n = 0;
    for m in recording::messages(&recording::open(&out_path)) {
        if m.schema_name == SCHEMA_COMPRESSED_IMAGE {
            let img: fm::CompressedImage = m.decode();
            assert_eq!(img.format, "jpeg");
            assert_eq!(
                img.data.as_ref(),
                std::fs::read(files.next().unwrap()).unwrap().as_slice()
            );
            n += 1;
        }
    }
    assert_eq!(n, 5);
}

#[test]
fn icsl_uses_millimetres_and_the_icsl_camera() {
    let c = tum_case();
    let out = convert("icsl", &c.dir, &c.out, &["-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let input = recording::open(&c.out);
    let md = &recording::metadata(&input)[0].metadata;
    assert_eq!(md["dataset_kind"], "icsl");
    assert_eq!(md["depth_units_per_meter"], "1000");
    assert_eq!(md["intrinsics_fx_fy_cx_cy"], "537.6,539,316.1,245.5");
    let depth = input.channel_by_topic(TOPIC_DEPTH_IMAGE).unwrap();
    assert_eq!(depth.metadata["depth_units_per_meter"], "1000");
}

/// The `/groundtruth/pose` messages of a converted file: stamp and pose.
fn groundtruth_poses(path: &Path) -> Vec<(u64, nalgebra::Isometry3<f64>)> {
    let input = recording::open(path);
    recording::messages(&input)
        .iter()
        .filter(|m| m.topic == TOPIC_GROUNDTRUTH_POSE)
        .map(|m| {
            let message: fm::PoseInFrame = m.decode();
            let pose = message.pose.unwrap();
            let (t, q) = (pose.position.unwrap(), pose.orientation.unwrap());
            let world_from_camera = nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::new(t.x, t.y, t.z),
                nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
            );
            (timestamp_ns(message.timestamp.as_ref()), world_from_camera)
        })
        .collect()
}

/// `convert bonn` writes the camera's ground truth (the marker poses of groundtruth.txt through
/// `dataset::bonn::camera_poses`) and the dataset's camera as a pinhole (`--camera bonn`: with
/// its distortion); `convert tum` on a folder so named writes the marker's poses as they are and
/// says that `convert bonn` converts them.
#[test]
fn bonn_writes_the_camera_ground_truth_and_the_bonn_camera() {
    use occmask::dataset::{bonn, read_groundtruth};
    let tmp = tempfile::tempdir().unwrap();
    let dir = tum_from_fixture(tmp.path(), "rgbd_bonn_mini");
    let marker = read_groundtruth(&dir.join("groundtruth.txt")).unwrap();
    let output = tmp.path().join("out.mcap");
    let out = convert("bonn", &dir, &output, &["-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let md = &recording::metadata(&recording::open(&output))[0].metadata;
    assert_eq!(md["dataset_kind"], "bonn");
    assert_eq!(md["depth_units_per_meter"], "5000");
    assert_eq!(
        md["intrinsics_fx_fy_cx_cy"],
        "542.822841,542.57687,315.59352,237.756098"
    );
    assert_eq!(md["distortion"], "none");
    assert!(md["groundtruth_conversion"].contains("marker"), "{md:?}");

    let written = groundtruth_poses(&output);
    let expected = bonn::camera_poses(&marker);
    assert_eq!(written.len(), marker.len());
    for ((t, pose), truth) in written.iter().zip(&expected) {
        assert_eq!(*t, truth.timestamp_ns);
        let error = (pose.to_homogeneous() - truth.world_from_camera.to_homogeneous()).norm();
        assert!(error < 1e-9, "{t}: {pose} against {}", truth.world_from_camera);
    }
    // The conversion moved the poses: the marker sits centimetres from the camera, turned.
    let moved = (written[0].1.inverse() * marker[0].world_from_camera)
        .rotation
        .angle();
    assert!(moved > 0.5, "{moved} rad");

    let out = convert("bonn", &dir, &output, &["-q", "--force", "--camera", "bonn"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let md = &recording::metadata(&recording::open(&output))[0].metadata;
    assert!(md["distortion"].starts_with("plumb_bob"), "{md:?}");

    let as_tum = tmp.path().join("tum.mcap");
    let out = convert("tum", &dir, &as_tum, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("`occmask convert bonn` converts them"),
        "{}",
        stderr(&out)
    );
    let written = groundtruth_poses(&as_tum);
    assert!(written
        .iter()
        .zip(&marker)
        .all(
            |((_, pose), truth)| (pose.to_homogeneous() - truth.world_from_camera.to_homogeneous()).norm()
                < 1e-9
        ));
}

#[cfg(unix)]
#[test]
fn ctrl_c_stops_cleanly_without_leaving_files() {
    use std::time::{Duration, Instant};
    let Some(src) = real_data(
        "7scenes_redkitchen_300",
        "convert_cli::ctrl_c_stops_cleanly_without_leaving_files",
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out_path = tmp.path().join("out.mcap");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_occmask"))
        .args(["convert", "tum"])
        .arg(&src)
        .arg("-o")
        .arg(&out_path)
        .args(["--camera", "kinect-default", "-q"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The temporary file appears after the signal handler is installed and the lists are read;
    // converting 300 frames then takes over a second.
    let started = Instant::now();
    while !entries(tmp.path()).iter().any(|e| e.ends_with(".tmp")) {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "no temporary file appeared"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let pid = libc::pid_t::try_from(child.id()).unwrap();
    // SAFETY: sending a signal to our own child process.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGINT) }, 0);
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted after"), "{err}");
    assert!(
        entries(tmp.path()).is_empty(),
        "left behind: {:?}",
        entries(tmp.path())
    );
}
