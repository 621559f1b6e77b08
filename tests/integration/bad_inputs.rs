//! The bad-input corpus (docs/errors.md): damaged MCAP files and dataset folders, generated in code,
//! run through the real binary (`process`, `eval`, `convert`). Every case checks the exit
//! code, a one-line message naming the file, the topic or frame and what was expected, that
//! nothing panicked, that no output (or temporary file) is left behind, and that the input
//! bytes are unchanged. Cases already covered by `convert_cli.rs` / `process_cli.rs` are not
//! repeated here.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns: a panic is the failure report

use crate::common;
use crate::common::mcap_fixture as process_support;

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::process::Output;

use foxglove::messages as fm;
use mcap::records::MessageHeader;
use occmask::image_buf::ImageSize;
use process_support::{fixture_bytes, FixtureSpec, Flavor, FRAME_NS, T0_NS};
use prost::Message as _;

#[cfg(unix)]
use common::assert_ends_quietly_on_a_closed_pipe;
use common::{entries, occmask, stderr, tum_from_fixture};

/// Big enough for the DVO pyramid, small enough to be quick (8 frames).
fn spec() -> FixtureSpec {
    FixtureSpec {
        size: ImageSize::new(160, 120),
        frames: 8,
        ..Default::default()
    }
}

fn good() -> Vec<u8> {
    fixture_bytes(Flavor::Protobuf, &spec())
}

/// Frame index of a fixture stamp.
fn frame_of(stamp_ns: u64) -> u64 {
    stamp_ns.saturating_sub(T0_NS) / FRAME_NS
}

/// Copies every message of `bytes` into a new indexed MCAP, letting `f` rewrite (or drop, with
/// `None`) each payload by topic.
fn rewrite(bytes: &[u8], f: impl FnMut(&str, &mut MessageHeader, Vec<u8>) -> Option<Vec<u8>>) -> Vec<u8> {
    rewrite_with(bytes, Some(mcap::Compression::Lz4), f)
}

fn rewrite_with(
    bytes: &[u8],
    compression: Option<mcap::Compression>,
    mut f: impl FnMut(&str, &mut MessageHeader, Vec<u8>) -> Option<Vec<u8>>,
) -> Vec<u8> {
    let mut w = mcap::WriteOptions::new()
        .library("bad-input corpus")
        .chunk_size(Some(256 * 1024))
        .compression(compression)
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let mut ids: BTreeMap<u16, u16> = BTreeMap::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let id = *ids.entry(m.channel.id).or_insert_with(|| {
            let sid = match &m.channel.schema {
                Some(s) => w.add_schema(&s.name, &s.encoding, &s.data).unwrap(),
                None => 0,
            };
            w.add_channel(
                sid,
                &m.channel.topic,
                &m.channel.message_encoding,
                &m.channel.metadata,
            )
            .unwrap()
        });
        let mut header = MessageHeader {
            channel_id: id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        if let Some(data) = f(&m.channel.topic, &mut header, m.data.into_owned()) {
            w.write_to_known_channel(&header, &data).unwrap();
        }
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

/// Rewrites the RawImage messages on `topic` of frame `frame` (all frames when `None`).
fn edit_raw(topic: &'static str, frame: Option<u64>, edit: impl Fn(&mut fm::RawImage)) -> Vec<u8> {
    rewrite(&good(), |t, _, data| {
        if t != topic {
            return Some(data);
        }
        let mut img = fm::RawImage::decode(data.as_slice()).unwrap();
        let stamp = occmask::mcap_io::codec::timestamp_ns(img.timestamp.as_ref());
        if frame.is_none_or(|f| frame_of(stamp) == f) {
            edit(&mut img);
        }
        Some(img.encode_to_vec())
    })
}

/// Sets the stamps (message stamp and log time) of frame `from` to those of frame `to`, on
/// colour, depth and calibration.
fn restamp(from: u64, to: u64) -> Vec<u8> {
    use process_support::{COLOR_TOPIC, DEPTH_TOPIC, INFO_TOPIC};
    let shift = (from as i64 - to as i64) * FRAME_NS as i64;
    rewrite(&good(), |t, header, data| {
        let fix = |stamp: &mut Option<fm::Timestamp>, header: &mut MessageHeader| {
            let ns = occmask::mcap_io::codec::timestamp_ns(stamp.as_ref());
            if frame_of(ns) == from {
                *stamp = Some(occmask::mcap_io::codec::timestamp((ns as i64 - shift) as u64));
                header.log_time = (header.log_time as i64 - shift) as u64;
                header.publish_time = (header.publish_time as i64 - shift) as u64;
            }
        };
        if t == COLOR_TOPIC || t == DEPTH_TOPIC {
            let mut img = fm::RawImage::decode(data.as_slice()).unwrap();
            fix(&mut img.timestamp, header);
            Some(img.encode_to_vec())
        } else if t == INFO_TOPIC {
            let mut cal = fm::CameraCalibration::decode(data.as_slice()).unwrap();
            fix(&mut cal.timestamp, header);
            Some(cal.encode_to_vec())
        } else {
            Some(data)
        }
    })
}

/// Rewrites the ground-truth pose of frame 3.
fn edit_pose(edit: impl Fn(&mut fm::Pose)) -> Vec<u8> {
    edit_pose_at(3, edit)
}

/// [`good`] with the ground-truth pose of frame `frame` edited.
fn edit_pose_at(frame: u64, edit: impl Fn(&mut fm::Pose)) -> Vec<u8> {
    rewrite(&good(), |t, _, data| {
        if t != process_support::GT_TOPIC {
            return Some(data);
        }
        let mut p = fm::PoseInFrame::decode(data.as_slice()).unwrap();
        if frame_of(occmask::mcap_io::codec::timestamp_ns(p.timestamp.as_ref())) == frame {
            edit(p.pose.as_mut().unwrap());
        }
        Some(p.encode_to_vec())
    })
}

/// Byte offsets of an MCAP file's chunks (start, length) and summary start, from its summary.
fn layout(bytes: &[u8]) -> (Vec<(u64, u64)>, u64) {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let chunks = summary
        .chunk_indexes
        .iter()
        .map(|c| (c.chunk_start_offset, c.chunk_length))
        .collect();
    // Footer: opcode, length, summary_start, summary_offset_start, crc, then 8 magic bytes.
    const FOOTER_FROM_END: usize = 8 + 4 + 8 + 8 + 8 + 1;
    let f = bytes.len() - FOOTER_FROM_END + 9;
    let summary_start = u64::from_le_bytes(bytes[f..f + 8].try_into().unwrap());
    (chunks, summary_start)
}

/// What a case must produce.
enum Expect {
    /// Exit 1, every needle on one `error:` line, no output left.
    Fails(&'static [&'static str]),
    /// Exit 0, output written, every needle in a `warning:` line.
    Warns(&'static [&'static str]),
    /// Exit 3 (finished, but input was lost), output written, every needle in a `warning:` line.
    LosesInput(&'static [&'static str]),
    /// Exit 0, output written, no warning.
    Ok,
}

/// Runs `occmask args` and checks the universal properties: no panic, inputs unchanged, and
/// for failures no file (final or temporary) in `out_dir` besides `keep`.
fn check(
    name: &str,
    args: &[OsString],
    inputs: &[&Path],
    out_dir: &Path,
    keep: &[&str],
    expect: &Expect,
) -> Output {
    let before: Vec<Option<Vec<u8>>> = inputs.iter().map(|p| std::fs::read(p).ok()).collect();
    let out = occmask(args);
    let err = stderr(&out);
    assert!(!err.contains("panicked"), "{name}: panic: {err}");
    assert_ne!(out.status.code(), Some(101), "{name}: {err}");
    for (p, b) in inputs.iter().zip(&before) {
        assert_eq!(&std::fs::read(p).ok(), b, "{name}: input {} changed", p.display());
    }
    if std::env::var_os("BAD_INPUTS_PRINT").is_some() {
        let line = err
            .lines()
            .find(|l| l.starts_with("error: ") || l.starts_with("warning: "))
            .unwrap_or("");
        eprintln!("| {name} | {:?} | {line} |", out.status.code());
    }
    let left: Vec<String> = entries(out_dir)
        .into_iter()
        .filter(|e| !keep.contains(&e.as_str()))
        .collect();
    match expect {
        Expect::Fails(needles) => {
            assert_eq!(out.status.code(), Some(1), "{name}: expected exit 1: {err}");
            assert!(
                has_line(&err, "error: ", needles),
                "{name}: expected one error line with {needles:?}: {err}"
            );
            // A temporary output (`OUT.<pid>.tmp`) is named only when it is what could not be
            // made (the test's own folders are `.tmpXXXXXX`).
            assert!(
                err.lines()
                    .filter(|l| names_temporary_output(l))
                    .all(|l| l.contains("cannot create temporary output file")),
                "{name}: names a temporary file: {err}"
            );
            assert!(left.is_empty(), "{name}: left behind {left:?}: {err}");
        }
        Expect::Warns(needles) | Expect::LosesInput(needles) => {
            let code = if matches!(expect, Expect::Warns(_)) { 0 } else { 3 };
            assert_eq!(
                out.status.code(),
                Some(code),
                "{name}: expected exit {code}: {err}"
            );
            assert!(
                has_line(&err, "warning: ", needles),
                "{name}: expected one warning line with {needles:?}: {err}"
            );
            assert!(!left.iter().any(|e| e.ends_with(".tmp")), "{name}: {left:?}");
        }
        Expect::Ok => {
            assert_eq!(out.status.code(), Some(0), "{name}: expected exit 0: {err}");
            assert!(!err.contains("warning:"), "{name}: unexpected warning: {err}");
            assert!(!left.iter().any(|e| e.ends_with(".tmp")), "{name}: {left:?}");
        }
    }
    out
}

/// Whether `line` names a file ending in `.tmp` (not a folder `.tmpXXXXXX`).
fn names_temporary_output(line: &str) -> bool {
    line.match_indices(".tmp").any(|(i, m)| {
        !line[i + m.len()..]
            .chars()
            .next()
            .is_some_and(char::is_alphanumeric)
    })
}

/// Whether one line of `text` starts with `prefix` and contains every needle.
fn has_line(text: &str, prefix: &str, needles: &[&str]) -> bool {
    text.lines()
        .any(|l| l.starts_with(prefix) && needles.iter().all(|n| l.contains(n)))
}

fn os(v: &[&dyn AsRef<std::ffi::OsStr>]) -> Vec<OsString> {
    v.iter().map(|s| s.as_ref().to_owned()).collect()
}

/// A damaged input for `process`.
struct ProcessCase {
    name: &'static str,
    bytes: fn() -> Vec<u8>,
    extra: &'static [&'static str],
    expect: Expect,
}

fn process_cases() -> Vec<ProcessCase> {
    use process_support::{COLOR_TOPIC, DEPTH_TOPIC, INFO_TOPIC};
    vec![
        ProcessCase {
            name: "zero-length file",
            bytes: Vec::new,
            extra: &[],
            expect: Expect::Fails(&["in.mcap", "not an MCAP file", "magic"]),
        },
        ProcessCase {
            name: "wrong magic",
            bytes: || {
                let mut b = good();
                b[1] = b'X';
                b
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", "not an MCAP file", "magic"]),
        },
        ProcessCase {
            name: "no summary section (recorder killed before the index)",
            bytes: || {
                fixture_bytes(
                    Flavor::Protobuf,
                    &FixtureSpec {
                        indexed: false,
                        ..spec()
                    },
                )
            },
            extra: &[],
            expect: Expect::Ok,
        },
        ProcessCase {
            name: "truncated inside the summary",
            bytes: || {
                let b = good();
                let (_, summary_start) = layout(&b);
                b[..summary_start as usize + 20].to_vec()
            },
            extra: &[],
            expect: Expect::Warns(&["in.mcap", "ends early", "no message lost"]),
        },
        ProcessCase {
            name: "truncated inside a chunk",
            bytes: || {
                let b = good();
                let (chunks, _) = layout(&b);
                let (start, len) = *chunks.last().unwrap();
                b[..(start + len / 2) as usize].to_vec()
            },
            extra: &[],
            expect: Expect::LosesInput(&[
                "in.mcap",
                "ends early",
                "bytes (an incomplete record at byte",
                "messages logged from",
            ]),
        },
        ProcessCase {
            name: "truncated inside an uncompressed chunk",
            bytes: || {
                let b = rewrite_with(&good(), None, |_, _, d| Some(d));
                let (chunks, _) = layout(&b);
                let &(start, len) = chunks.iter().max_by_key(|c| c.1).unwrap();
                b[..(start + len / 2) as usize].to_vec()
            },
            extra: &[],
            expect: Expect::LosesInput(&["in.mcap", "ends early", "complete messages were read"]),
        },
        ProcessCase {
            name: "chunk CRC mismatch",
            bytes: || {
                let mut b = good();
                let (chunks, _) = layout(&b);
                let (start, len) = chunks[0];
                let at = (start + len / 2) as usize;
                b[at] ^= 0x55;
                b
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", "damaged chunk at byte", "lz4", "mcap recover"]),
        },
        ProcessCase {
            name: "chunk CRC mismatch (zstd chunk that still decompresses)",
            bytes: || {
                let mut b = rewrite_with(&good(), Some(mcap::Compression::Zstd), |_, _, d| Some(d));
                let (chunks, _) = layout(&b);
                // The CRC field of the chunk header: opcode, length, start, end, size.
                let at = chunks[0].0 as usize + 1 + 8 + 8 + 8 + 8;
                b[at] ^= 0x01;
                b
            },
            extra: &[],
            expect: Expect::Fails(&[
                "in.mcap",
                "damaged chunk at byte",
                "holding",
                "messages",
                "zstd",
                "CRC mismatch",
            ]),
        },
        ProcessCase {
            name: "chunk CRC mismatch (uncompressed chunk)",
            bytes: || {
                let mut b = rewrite_with(&good(), None, |_, _, d| Some(d));
                let (chunks, _) = layout(&b);
                let (start, len) = chunks[0];
                let at = (start + len / 2) as usize;
                b[at] ^= 0x55;
                b
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", "damaged chunk at byte", "CRC mismatch"]),
        },
        ProcessCase {
            name: "unknown chunk compression",
            bytes: || {
                let mut b = good();
                // Every "lz4" compression string (chunk records and chunk indexes) becomes "xz9".
                let mut i = 0;
                while i + 3 <= b.len() {
                    if &b[i..i + 3] == b"lz4" && b[i - 4..i] == 3u32.to_le_bytes() {
                        b[i..i + 3].copy_from_slice(b"xz9");
                    }
                    i += 1;
                }
                b
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", "xz9"]),
        },
        ProcessCase {
            name: "depth width disagrees with its data",
            bytes: || edit_raw(DEPTH_TOPIC, Some(3), |m| m.width += 1),
            extra: &[],
            expect: Expect::Fails(&["in.mcap", DEPTH_TOPIC, "log time", "sequence", "step"]),
        },
        ProcessCase {
            name: "depth step shorter than a row",
            bytes: || edit_raw(DEPTH_TOPIC, Some(3), |m| m.step -= 2),
            extra: &[],
            // The output that was not written, by its own name.
            expect: Expect::Fails(&["in.mcap: output ", "out.mcap not written: ", DEPTH_TOPIC, "step"]),
        },
        ProcessCase {
            name: "8-bit depth data declared 16UC1",
            bytes: || {
                edit_raw(DEPTH_TOPIC, Some(3), |m| {
                    let half: Vec<u8> = m.data.iter().step_by(2).copied().collect();
                    m.data = half.into();
                })
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", DEPTH_TOPIC, "needs", "bytes"]),
        },
        ProcessCase {
            name: "float depth data declared 16UC1",
            bytes: || {
                edit_raw(DEPTH_TOPIC, Some(3), |m| {
                    let n = (m.width * m.height) as usize;
                    m.data = 1.5f32.to_le_bytes().repeat(n).into();
                })
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", DEPTH_TOPIC, "bytes"]),
        },
        ProcessCase {
            name: "8-bit depth encoding",
            bytes: || {
                edit_raw(DEPTH_TOPIC, None, |m| {
                    m.encoding = "8UC1".into();
                    m.step = m.width;
                    let half: Vec<u8> = m.data.iter().step_by(2).copied().collect();
                    m.data = half.into();
                })
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", DEPTH_TOPIC, "8UC1"]),
        },
        ProcessCase {
            name: "colour height disagrees with its data",
            bytes: || edit_raw(COLOR_TOPIC, Some(2), |m| m.height += 3),
            extra: &[],
            expect: Expect::Fails(&["in.mcap", COLOR_TOPIC, "needs"]),
        },
        ProcessCase {
            name: "colour encoding unknown",
            bytes: || edit_raw(COLOR_TOPIC, Some(4), |m| m.encoding = "nv12".into()),
            extra: &[],
            expect: Expect::Fails(&["in.mcap", COLOR_TOPIC, "nv12"]),
        },
        ProcessCase {
            name: "depth size differs from colour",
            bytes: || {
                edit_raw(DEPTH_TOPIC, None, |m| {
                    m.width = 80;
                    m.height = 60;
                    m.step = 160;
                    m.data = vec![0x10; 80 * 60 * 2].into();
                })
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", DEPTH_TOPIC, COLOR_TOPIC, "registered"]),
        },
        ProcessCase {
            name: "all-zero depth (DVO fails, frames still written)",
            bytes: || edit_raw(DEPTH_TOPIC, None, |m| m.data = vec![0; m.data.len()].into()),
            extra: &[],
            expect: Expect::Ok,
        },
        ProcessCase {
            name: "calibration with zero focal length",
            bytes: || {
                rewrite(&good(), |t, _, data| {
                    if t != INFO_TOPIC {
                        return Some(data);
                    }
                    let mut c = fm::CameraCalibration::decode(data.as_slice()).unwrap();
                    c.k[0] = 0.0;
                    Some(c.encode_to_vec())
                })
            },
            extra: &[],
            expect: Expect::Fails(&["in.mcap", INFO_TOPIC, "fx, fy > 0"]),
        },
        ProcessCase {
            name: "pose with NaN translation (--pose-topic)",
            bytes: || edit_pose(|p| p.position.as_mut().unwrap().x = f64::NAN),
            extra: &["--pose-topic", "/groundtruth/pose"],
            expect: Expect::Fails(&["in.mcap", "/groundtruth/pose", "finite"]),
        },
        ProcessCase {
            name: "pose with Inf translation (--pose-topic)",
            bytes: || edit_pose(|p| p.position.as_mut().unwrap().z = f64::INFINITY),
            extra: &["--pose-topic", "/groundtruth/pose"],
            expect: Expect::Fails(&["in.mcap", "/groundtruth/pose", "finite"]),
        },
        ProcessCase {
            name: "pose with a non-unit quaternion (--pose-topic)",
            bytes: || edit_pose(|p| p.orientation.as_mut().unwrap().w = 3.0),
            extra: &["--pose-topic", "/groundtruth/pose"],
            expect: Expect::Fails(&["in.mcap", "/groundtruth/pose", "unit quaternion"]),
        },
        ProcessCase {
            name: "ground-truth pose with NaN (--anchor-topic)",
            bytes: || edit_pose(|p| p.position.as_mut().unwrap().y = f64::NAN),
            extra: &["--anchor-topic", "/groundtruth/pose"],
            expect: Expect::Fails(&["in.mcap", "/groundtruth/pose", "NaN", "--no-anchor"]),
        },
        ProcessCase {
            name: "colour/depth timestamps going backwards",
            bytes: || restamp(5, 2),
            extra: &[],
            expect: Expect::Warns(&["in.mcap", "skipped 1 frame", "not after", "/camera/color/image"]),
        },
        ProcessCase {
            name: "duplicate colour/depth timestamps",
            bytes: || restamp(5, 4),
            extra: &[],
            expect: Expect::Warns(&["in.mcap", "skipped 1 frame", "not after", "/camera/color/image"]),
        },
    ]
}

/// Runs every case, collecting failures so one run reports all of them.
fn run_all<C>(cases: Vec<C>, name: impl Fn(&C) -> &'static str, run: impl Fn(&C)) {
    let mut failures = Vec::new();
    for case in &cases {
        if let Err(e) = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(case))) {
            let msg = e
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            failures.push(format!("[{}] {msg}", name(case)));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

#[test]
fn process_bad_input_corpus() {
    run_all(
        process_cases(),
        |c| c.name,
        |case| {
            let tmp = tempfile::tempdir().unwrap();
            let input = tmp.path().join("in.mcap");
            std::fs::write(&input, (case.bytes)()).unwrap();
            let out_dir = tmp.path().join("out");
            std::fs::create_dir(&out_dir).unwrap();
            let output = out_dir.join("out.mcap");
            let mut args = os(&[&"process", &input, &"-o", &output]);
            args.extend(case.extra.iter().map(OsString::from));
            let out = check(case.name, &args, &[&input], &out_dir, &[], &case.expect);
            if !matches!(case.expect, Expect::Fails(_)) {
                assert!(output.is_file(), "{}: no output", case.name);
                if case.name.starts_with("truncated inside") && case.name.ends_with("chunk") {
                    let err = stderr(&out);
                    assert!(err.contains("(input truncated: last "), "summary line: {err}");
                    // Salvaged messages are not read twice (no frame out of order).
                    assert!(!err.contains("skipped"), "{err}");
                }
                // A truncated input leaves its trace in the output's metadata record.
                let meta = process_metadata(&output);
                let truncated = case.name.starts_with("truncated");
                assert_eq!(
                    meta.contains_key("input_truncated"),
                    truncated,
                    "{}: {meta:?}",
                    case.name
                );
                if case.name == "truncated inside a chunk" {
                    assert_eq!(meta["input_messages_lost"], "true", "{meta:?}");
                    let lost: u64 = meta["input_lost_bytes"].parse().unwrap();
                    assert!(lost > 0, "{meta:?}");
                    assert!(meta.contains_key("input_lost_log_time"), "{meta:?}");
                }
                if case.name == "truncated inside the summary" {
                    assert_eq!(meta["input_messages_lost"], "false", "{meta:?}");
                }
                let eval = occmask(&os(&[&"eval", &output]));
                assert_eq!(
                    eval.status.code(),
                    Some(0),
                    "{}: eval: {}",
                    case.name,
                    stderr(&eval)
                );
            }
        },
    );
}

/// The `occmask.process` metadata record of an output file.
fn process_metadata(path: &Path) -> BTreeMap<String, String> {
    use occmask::mcap_io::input::{ExtraRecord, McapInput};
    let input = McapInput::open(path).unwrap();
    input
        .extras()
        .unwrap()
        .into_iter()
        .find_map(|e| match e {
            ExtraRecord::Metadata(m) if m.name == occmask::mcap_io::annotate::METADATA_PROCESS => {
                Some(m.metadata)
            }
            _ => None,
        })
        .unwrap()
}

/// Runs a command with the file size limited to `max_bytes` (SIGXFSZ ignored, so writes past it
/// fail with EFBIG, as on a full disk).
#[cfg(unix)]
fn occmask_with_file_limit(args: &[OsString], max_bytes: u64) -> Output {
    use std::os::unix::process::CommandExt;
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_occmask"));
    cmd.args(args);
    // SAFETY: only async-signal-safe calls (signal, setrlimit) between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit {
                rlim_cur: max_bytes as libc::rlim_t,
                rlim_max: max_bytes as libc::rlim_t,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.output().unwrap()
}

/// A small tmpfs, mounted only when the tests run as root and mounting works (unmounted on
/// drop); `None` elsewhere.
struct SmallTmpfs {
    dir: tempfile::TempDir,
}

impl SmallTmpfs {
    fn mount(bytes: u64) -> Option<Self> {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            return None;
        }
        let dir = tempfile::tempdir().ok()?;
        let ok = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={bytes}"), "tmpfs"])
            .arg(dir.path())
            .output()
            .is_ok_and(|o| o.status.success());
        ok.then_some(Self { dir })
    }
}

impl Drop for SmallTmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(self.dir.path()).output();
    }
}

#[test]
fn process_output_and_path_problems() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in.mcap");
    std::fs::write(&input, good()).unwrap();
    let out_dir = tmp.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let keep: &[&str] = &[];

    // A directory where the input file was expected.
    let in_dir = tmp.path().join("dir.mcap");
    std::fs::create_dir(&in_dir).unwrap();
    let args = os(&[&"process", &in_dir, &"-o", &out_dir.join("o.mcap")]);
    let e = Expect::Fails(&[
        "dir.mcap",
        "expected an MCAP file, found a directory",
        "pass the files in it (",
        "dir.mcap/*.mcap)",
    ]);
    check("input is a directory", &args, &[&input], &out_dir, keep, &e);

    // The output is a symbolic link to the input (writing over an input, even with --force).
    let link = out_dir.join("link.mcap");
    std::os::unix::fs::symlink(&input, &link).unwrap();
    let args = os(&[&"process", &input, &"-o", &link, &"--force"]);
    let e = Expect::Fails(&["link.mcap", "different from the input"]);
    check(
        "output is a link to the input",
        &args,
        &[&input],
        &out_dir,
        &["link.mcap"],
        &e,
    );
    std::fs::remove_file(&link).unwrap();

    // An output directory that cannot hold files: its parent is a regular file.
    let args = os(&[&"process", &input, &"-o", &input.join("o.mcap")]);
    let e = Expect::Fails(&["in.mcap/o.mcap", "in.mcap is not a folder"]);
    check(
        "output under a regular file",
        &args,
        &[&input],
        &out_dir,
        keep,
        &e,
    );

    // --out-dir that does not exist, or is a file.
    let args = os(&[&"process", &input, &"--out-dir", &out_dir.join("none")]);
    let e = Expect::Fails(&["--out-dir", "none does not exist (create it first)"]);
    check("--out-dir missing", &args, &[&input], &out_dir, keep, &e);
    let args = os(&[&"process", &input, &"--out-dir", &input]);
    let e = Expect::Fails(&["--out-dir", "in.mcap is a file, not a folder"]);
    check("--out-dir is a file", &args, &[&input], &out_dir, keep, &e);

    // An output in a folder that does not exist.
    let args = os(&[&"process", &input, &"-o", &out_dir.join("none/o.mcap")]);
    let e = Expect::Fails(&["none/o.mcap", "none does not exist"]);
    check("output folder missing", &args, &[&input], &out_dir, keep, &e);

    // `-o new/`: a folder's name, which -o does not take. Once the work was done and only the
    // rename failed, so the message names the flag that writes into a folder.
    let folder_name = format!("{}/", out_dir.join("new").display());
    let args = os(&[&"process", &input, &"-o", &folder_name]);
    let e = Expect::Fails(&[
        "new/ is a folder",
        "--out-dir",
        "in.occmask.mcap",
        "create it first",
    ]);
    check("output is a folder's name", &args, &[&input], &out_dir, keep, &e);

    // A read-only output directory (permissions do not stop root, so only as a normal user).
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        use std::os::unix::fs::PermissionsExt;
        let ro = tmp.path().join("ro");
        std::fs::create_dir(&ro).unwrap();
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        let args = os(&[&"process", &input, &"-o", &ro.join("o.mcap")]);
        let e = Expect::Fails(&["ro/o.mcap", "cannot create temporary output file", "ermission"]);
        check("read-only output directory", &args, &[&input], &ro, keep, &e);
    }

    // A device as the output: refused, and never replaced by a regular file.
    let args = os(&[&"process", &input, &"-o", &"/dev/full", &"--force"]);
    let e = Expect::Fails(&["/dev/full", "a regular file"]);
    check("/dev/full as output", &args, &[&input], &out_dir, keep, &e);
    {
        use std::os::unix::fs::FileTypeExt;
        let meta = std::fs::metadata("/dev/full").unwrap();
        assert!(meta.file_type().is_char_device());
    }

    // The disk fills up while writing (file size limit: writes fail with EFBIG).
    let out = occmask_with_file_limit(
        &os(&[&"process", &input, &"-o", &out_dir.join("o.mcap")]),
        64 * 1024,
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        err.lines()
            .any(|l| l.starts_with("error: ") && l.contains("o.mcap") && l.contains("too large")),
        "{err}"
    );
    assert!(entries(&out_dir).is_empty(), "{:?}", entries(&out_dir));

    // A really full (small tmpfs) disk, where the environment allows mounting one.
    if let Some(fs) = SmallTmpfs::mount(64 * 1024) {
        let target = fs.dir.path().join("o.mcap");
        let args = os(&[&"process", &input, &"-o", &target]);
        let e = Expect::Fails(&["o.mcap", "No space left on device"]);
        check("full tmpfs", &args, &[&input], fs.dir.path(), keep, &e);
    }
}

#[test]
fn eval_bad_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let raw = dir.join("raw.mcap");
    std::fs::write(&raw, good()).unwrap();
    let empty = dir.join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let magic = dir.join("magic.mcap");
    let mut b = good();
    b[0] = 0;
    std::fs::write(&magic, b).unwrap();
    let folder = dir.join("folder.mcap");
    std::fs::create_dir(&folder).unwrap();
    // A processed file whose ground-truth pose has a NaN (process copies it untouched).
    let nan_in = dir.join("nan_in.mcap");
    std::fs::write(&nan_in, edit_pose(|p| p.position.as_mut().unwrap().y = f64::NAN)).unwrap();
    let nan_out = dir.join("nan_out.mcap");
    let out = occmask(&os(&[&"process", &nan_in, &"-o", &nan_out]));
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    // The unreadable sample is left out of the anchor, the others anchor the odometry, and
    // the warning says which message and why (named with --anchor-topic, the channel is
    // required, and the same message fails the file: a case of `process_bad_input_corpus`).
    let needles = [
        "1 ground-truth message(s) did not decode",
        "/groundtruth/pose",
        "NaN",
    ];
    assert!(has_line(&stderr(&out), "warning: ", &needles), "{}", stderr(&out));
    assert!(!stderr(&out).contains("the odometry starts at the first camera"));
    // A ground truth whose first message does not decode is not used at all.
    let first_nan = dir.join("first_nan.mcap");
    std::fs::write(
        &first_nan,
        edit_pose_at(0, |p| p.position.as_mut().unwrap().y = f64::NAN),
    )
    .unwrap();
    let first_nan_out = dir.join("first_nan_out.mcap");
    let out = occmask(&os(&[&"process", &first_nan, &"-o", &first_nan_out]));
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let needles = [
        "the odometry starts at the first camera",
        "/groundtruth/pose",
        "NaN",
    ];
    assert!(has_line(&stderr(&out), "warning: ", &needles), "{}", stderr(&out));
    std::fs::remove_file(&first_nan).unwrap();
    std::fs::remove_file(&first_nan_out).unwrap();
    // A processed file cut inside its summary (a copy interrupted near the end).
    let full = dir.join("full.mcap");
    let out = occmask(&os(&[&"process", &raw, &"-o", &full, &"-q"]));
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let cut = dir.join("cut.mcap");
    let bytes = std::fs::read(&full).unwrap();
    let (_, summary_start) = layout(&bytes);
    std::fs::write(&cut, &bytes[..summary_start as usize + 30]).unwrap();
    // ...and one cut inside its last chunk (small chunks, so the channels come before the cut):
    // messages lost, exit 3.
    let chunked = dir.join("chunked.mcap");
    let out = occmask(&os(&[
        &"process",
        &raw,
        &"-o",
        &chunked,
        &"--chunk-size-mib",
        &"0.05",
        &"-q",
    ]));
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let bytes = std::fs::read(&chunked).unwrap();
    let (chunks, _) = layout(&bytes);
    assert!(chunks.len() > 2, "{} chunks", chunks.len());
    let (start, len) = *chunks.last().unwrap();
    let cut_chunk = dir.join("cut_chunk.mcap");
    std::fs::write(&cut_chunk, &bytes[..(start + len / 2) as usize]).unwrap();
    // Ground-truth trajectories (`--groundtruth`): one pose, and one with a short line.
    let truth = dir.join("truth.txt");
    std::fs::write(&truth, "# timestamp tx ty tz qx qy qz qw\n1.0 0 0 0 0 0 0 1\n").unwrap();
    let bad_truth = dir.join("bad_truth.txt");
    std::fs::write(&bad_truth, "# timestamp tx ty tz qx qy qz qw\n1.0 0 0 0 0 0 1\n").unwrap();

    let keep: Vec<String> = entries(dir);
    let keep: Vec<&str> = keep.iter().map(String::as_str).collect();
    let inputs: Vec<PathBuf> = keep.iter().map(|k| dir.join(k)).collect();
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    let cases: [(&str, &Path, Expect); 7] = [
        (
            "zero-length",
            &empty,
            Expect::Fails(&["empty.mcap", "not an MCAP file"]),
        ),
        (
            "wrong magic",
            &magic,
            Expect::Fails(&["magic.mcap", "not an MCAP file"]),
        ),
        (
            "directory",
            &folder,
            Expect::Fails(&["folder.mcap", "found a directory", "folder.mcap/*.mcap)"]),
        ),
        (
            "not processed",
            &raw,
            Expect::Fails(&["raw.mcap", "/occmask/mask", "occmask process"]),
        ),
        (
            "NaN ground-truth pose",
            &nan_out,
            Expect::Fails(&["nan_out.mcap", "/groundtruth/pose", "finite"]),
        ),
        (
            "truncated output",
            &cut,
            Expect::Warns(&[
                "cut.mcap",
                "ends early",
                "no message lost",
                "scored the 8 complete frames",
            ]),
        ),
        (
            "output truncated inside a chunk",
            &cut_chunk,
            Expect::LosesInput(&[
                "cut_chunk.mcap",
                "ends early",
                "bytes are lost",
                "complete frames",
            ]),
        ),
    ];
    for (name, path, expect) in cases {
        let args = os(&[&"eval", &path]);
        check(name, &args, &inputs, dir, &keep, &expect);
    }
    // The ground truth from elsewhere: a malformed trajectory, a file that is not there, a
    // recording that is not the evaluated file's input (chunked.mcap holds the same ground truth,
    // but more messages than raw.mcap, from which full.mcap was made), a pose topic that is not
    // there, and one for a trajectory.
    let missing = dir.join("missing.txt");
    let groundtruth_cases: [(&str, Vec<&dyn AsRef<std::ffi::OsStr>>, Expect); 5] = [
        (
            "malformed ground-truth trajectory",
            vec![&"--groundtruth", &bad_truth],
            Expect::Fails(&["full.mcap", "bad_truth.txt", "line 2", "expected 8 fields"]),
        ),
        (
            "missing ground-truth file",
            vec![&"--groundtruth", &missing],
            Expect::Fails(&["full.mcap", "missing.txt", "cannot read"]),
        ),
        (
            "ground truth of another recording",
            vec![&"--groundtruth", &chunked],
            Expect::Warns(&["full.mcap", "was not made from", "chunked.mcap", "input_messages"]),
        ),
        (
            "ground-truth topic not in the file",
            vec![&"--groundtruth-topic", &"/vicon/pose"],
            Expect::Fails(&[
                "full.mcap",
                "ground-truth topic /vicon/pose: no poses",
                "--groundtruth-topic",
            ]),
        ),
        (
            "ground-truth topic with a trajectory",
            vec![&"--groundtruth-topic", &"/tf", &"--groundtruth", &truth],
            Expect::Fails(&["full.mcap", "truth.txt", "a trajectory file has no topics"]),
        ),
    ];
    for (name, extra, expect) in groundtruth_cases {
        let mut args = os(&[&"eval", &full]);
        args.extend(extra.iter().map(|a| a.as_ref().to_owned()));
        check(name, &args, &inputs, dir, &keep, &expect);
    }
    // `occmask eval … | head` with the reader already gone: ended by SIGPIPE like any filter,
    // no panic message. Also as --json.
    #[cfg(unix)]
    for json in [false, true] {
        let mut args = os(&[&"eval", &full, &full, &full]);
        args.extend(json.then(|| OsString::from("--json")));
        assert_ends_quietly_on_a_closed_pipe(&args, &format!("eval, json {json}"));
    }
}

/// A damaged TUM folder for `convert`.
struct ConvertCase {
    name: &'static str,
    damage: fn(&Path),
    expect: Expect,
}

fn first_entry(dir: &Path) -> PathBuf {
    dir.join(&entries(dir)[0])
}

fn convert_cases() -> Vec<ConvertCase> {
    fn edit_gt(dir: &Path, field: usize, value: &str) {
        let gt = dir.join("groundtruth.txt");
        let text = std::fs::read_to_string(&gt).unwrap();
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        let i = lines.iter().position(|l| !l.starts_with('#')).unwrap();
        let mut fields: Vec<&str> = lines[i].split_whitespace().collect();
        fields[field] = value;
        lines[i] = fields.join(" ");
        std::fs::write(&gt, lines.join("\n")).unwrap();
    }
    vec![
        ConvertCase {
            name: "ground-truth pose with NaN",
            damage: |d| edit_gt(d, 1, "nan"),
            expect: Expect::Fails(&["groundtruth.txt", "line", "finite"]),
        },
        ConvertCase {
            name: "ground-truth pose with Inf",
            damage: |d| edit_gt(d, 3, "inf"),
            expect: Expect::Fails(&["groundtruth.txt", "line", "finite"]),
        },
        ConvertCase {
            name: "zero-length colour image",
            damage: |d| std::fs::write(first_entry(&d.join("rgb")), b"").unwrap(),
            expect: Expect::Fails(&["rgb/", ".png", "expected a PNG or JPEG colour image"]),
        },
        ConvertCase {
            name: "zero-length depth image",
            damage: |d| std::fs::write(first_entry(&d.join("depth")), b"").unwrap(),
            expect: Expect::Fails(&["depth/", ".png", "no PNG signature"]),
        },
        ConvertCase {
            name: "zero-length depth.txt",
            damage: |d| std::fs::write(d.join("depth.txt"), b"").unwrap(),
            expect: Expect::Fails(&["depth.txt", "empty sequence"]),
        },
        ConvertCase {
            name: "directory where rgb.txt was expected",
            damage: |d| {
                std::fs::remove_file(d.join("rgb.txt")).unwrap();
                std::fs::create_dir(d.join("rgb.txt")).unwrap();
            },
            expect: Expect::Fails(&["rgb.txt", "found a directory"]),
        },
        ConvertCase {
            name: "directory where groundtruth.txt was expected",
            damage: |d| {
                std::fs::remove_file(d.join("groundtruth.txt")).unwrap();
                std::fs::create_dir(d.join("groundtruth.txt")).unwrap();
            },
            expect: Expect::Fails(&["groundtruth.txt", "found a directory"]),
        },
        ConvertCase {
            name: "directory where a colour image was expected",
            damage: |d| {
                let f = first_entry(&d.join("rgb"));
                std::fs::remove_file(&f).unwrap();
                std::fs::create_dir(&f).unwrap();
            },
            expect: Expect::Fails(&["rgb/", ".png", "to be an image file, found a directory", "line 3"]),
        },
    ]
}

#[test]
fn convert_bad_input_corpus() {
    run_all(
        convert_cases(),
        |c| c.name,
        |case| {
            let tmp = tempfile::tempdir().unwrap();
            let dir = tum_from_fixture(tmp.path(), "tum_fr2_mini");
            (case.damage)(&dir);
            let inputs: Vec<PathBuf> = walk(&dir);
            let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
            let out_dir = tmp.path().join("out");
            std::fs::create_dir(&out_dir).unwrap();
            let args = os(&[&"convert", &"tum", &dir, &"-o", &out_dir.join("out.mcap")]);
            check(case.name, &args, &inputs, &out_dir, &[], &case.expect);
        },
    );
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

#[test]
fn convert_output_problems() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tum_from_fixture(tmp.path(), "tum_fr2_mini");
    let inputs: Vec<PathBuf> = walk(&dir);
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    let out_dir = tmp.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let rgb_txt = dir.join("rgb.txt");

    let args = os(&[&"convert", &"tum", &dir, &"-o", &"/dev/full", &"--force"]);
    let e = Expect::Fails(&["/dev/full", "a regular file"]);
    check("/dev/full as output", &args, &inputs, &out_dir, &[], &e);

    let args = os(&[&"convert", &"tum", &dir, &"-o", &rgb_txt.join("o.mcap")]);
    let e = Expect::Fails(&["rgb.txt/o.mcap", "rgb.txt is not a folder"]);
    check("output under a regular file", &args, &inputs, &out_dir, &[], &e);

    let folder_name = format!("{}/", out_dir.join("new").display());
    let args = os(&[&"convert", &"tum", &dir, &"-o", &folder_name]);
    let e = Expect::Fails(&["new/", "found a directory name"]);
    check("output is a folder's name", &args, &inputs, &out_dir, &[], &e);

    // An existing file (here one of the inputs) is only replaced with --force.
    let args = os(&[&"convert", &"tum", &dir, &"-o", &rgb_txt]);
    let e = Expect::Fails(&["rgb.txt", "--force"]);
    check(
        "output is an existing input file",
        &args,
        &inputs,
        &out_dir,
        &[],
        &e,
    );

    let out = occmask_with_file_limit(
        &os(&[&"convert", &"tum", &dir, &"-o", &out_dir.join("o.mcap")]),
        32 * 1024,
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        err.lines()
            .any(|l| l.starts_with("error: ") && l.contains("o.mcap") && l.contains("too large")),
        "{err}"
    );
    assert!(entries(&out_dir).is_empty(), "{:?}", entries(&out_dir));

    // Zero focal length is a usage error (exit 2) naming the option.
    let out = occmask(&os(&[
        &"convert",
        &"tum",
        &dir,
        &"-o",
        &out_dir.join("o.mcap"),
        &"--camera",
        &"0,525,319.5,239.5",
    ]));
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--camera") && err.contains("0,525,319.5,239.5"),
        "{err}"
    );
    assert!(entries(&out_dir).is_empty());
}

/// Starts `occmask args` in `cwd`, waits until its temporary output appears in `cwd` (so it
/// is writing), lets it run `after` more, sends `signal`, and returns its output.
#[cfg(unix)]
fn interrupt(args: &[OsString], cwd: &Path, signal: libc::c_int, after: std::time::Duration) -> Output {
    interrupt_when(args, cwd, signal, after, |_| true)
}

/// [`interrupt`], waiting also until `ready` holds for the names in `cwd`.
#[cfg(unix)]
fn interrupt_when(
    args: &[OsString],
    cwd: &Path,
    signal: libc::c_int,
    after: std::time::Duration,
    ready: impl Fn(&[String]) -> bool,
) -> Output {
    use std::time::{Duration, Instant};
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_occmask"))
        .args(args)
        .current_dir(cwd)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while !{
        let names = entries(cwd);
        names.iter().any(|e| e.ends_with(".tmp")) && ready(&names)
    } {
        assert!(
            child.try_wait().unwrap().is_none(),
            "finished before it could be interrupted"
        );
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no temporary file appeared"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    std::thread::sleep(after);
    assert!(
        child.try_wait().unwrap().is_none(),
        "finished before it could be interrupted"
    );
    let pid = libc::pid_t::try_from(child.id()).unwrap();
    // SAFETY: sending a signal to our own running child.
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
    child.wait_with_output().unwrap()
}

#[cfg(unix)]
fn assert_interrupted(name: &str, out: &Output, cwd: &Path, keep: &[&str]) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(130), "{name}: {err}");
    assert!(!err.contains("panicked"), "{name}: {err}");
    assert!(
        err.lines()
            .any(|l| l.starts_with("error: ") && l.contains("interrupted")),
        "{name}: {err}"
    );
    let left: Vec<String> = entries(cwd)
        .into_iter()
        .filter(|e| !keep.contains(&e.as_str()))
        .collect();
    assert!(left.is_empty(), "{name}: left behind {left:?}");
}

/// SIGINT and SIGTERM during `process` and `convert`: exit 130, nothing left behind, and a
/// re-run writes the same bytes as a run that was never interrupted.
#[cfg(unix)]
#[test]
fn interrupted_runs_leave_nothing_and_rerun_identically() {
    use std::time::Duration;
    let Some(desk) = common::real_data(
        "tum_fr2_desk_50",
        "bad_inputs::interrupted_runs_leave_nothing_and_rerun_identically",
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // Each run happens in its own directory with the same relative output name, so the
    // command lines (recorded in convert's metadata) are identical.
    let reference = tmp.path().join("reference");
    let work = tmp.path().join("work");
    std::fs::create_dir(&reference).unwrap();
    std::fs::create_dir(&work).unwrap();
    let convert = os(&[&"convert", &"tum", &desk, &"-o", &"desk.mcap", &"-q"]);

    // convert: SIGTERM mid-run (SIGINT is covered by convert_cli.rs), then re-run.
    let out = occmask_in(&convert, &reference);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let out = interrupt(&convert, &work, libc::SIGTERM, Duration::from_millis(20));
    assert_interrupted("convert SIGTERM", &out, &work, &[]);
    let out = occmask_in(&convert, &work);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let desk_mcap = std::fs::read(work.join("desk.mcap")).unwrap();
    assert!(
        desk_mcap == std::fs::read(reference.join("desk.mcap")).unwrap(),
        "convert re-run differs"
    );

    // process: the first second of the recording (30 frames) keeps this quick. The trajectory
    // export is streamed while frames finish, so its temporary file must go too.
    let input = tmp.path().join("desk.mcap");
    std::fs::write(&input, &desk_mcap).unwrap();
    let process = os(&[
        &"process",
        &input,
        &"-o",
        &"out.mcap",
        &"--export-trajectory",
        &"traj.txt",
        &"--end",
        &"1",
        &"-q",
    ]);
    let out = occmask_in(&process, &reference);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    // The signal must come while the frames are read: the run takes about 0.4 s after its
    // temporary files appear, and a signal after the last message is read lets the file finish
    // (it is then kept, and the exit code is still 130). 300 ms here lost that race under load.
    for (name, signal) in [
        ("process SIGINT", libc::SIGINT),
        ("process SIGTERM", libc::SIGTERM),
    ] {
        let out = interrupt(&process, &work, signal, Duration::from_millis(30));
        assert_interrupted(name, &out, &work, &["desk.mcap"]);
    }
    assert_eq!(std::fs::read(&input).unwrap(), desk_mcap, "input changed");
    let out = occmask_in(&process, &work);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        std::fs::read(work.join("out.mcap")).unwrap() == std::fs::read(reference.join("out.mcap")).unwrap(),
        "process re-run differs"
    );
    let trajectory = std::fs::read_to_string(work.join("traj.txt")).unwrap();
    // A header and one pose per frame of the first second (TUM stamps are not exactly 30 Hz).
    assert!((29..=33).contains(&trajectory.lines().count()), "{trajectory}");
    assert!(
        trajectory == std::fs::read_to_string(reference.join("traj.txt")).unwrap(),
        "trajectory re-run differs"
    );
}

/// A batch stopped by a signal keeps its finished files and says how to go on; run again with
/// `--skip-existing`, it keeps them (not rewritten) and writes the others as an uninterrupted
/// run does.
#[cfg(unix)]
#[test]
fn an_interrupted_batch_resumes_with_skip_existing() {
    use std::os::unix::fs::MetadataExt;
    use std::time::Duration;
    let Some(desk) = common::real_data(
        "tum_fr2_desk_50",
        "bad_inputs::an_interrupted_batch_resumes_with_skip_existing",
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (reference, work) = (tmp.path().join("reference"), tmp.path().join("work"));
    std::fs::create_dir(&reference).unwrap();
    std::fs::create_dir(&work).unwrap();
    let input = tmp.path().join("desk.mcap");
    let out = occmask_in(
        &os(&[&"convert", &"tum", &desk, &"-o", &input, &"-q"]),
        tmp.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let second = tmp.path().join("desk2.mcap");
    std::fs::copy(&input, &second).unwrap();
    // One file at a time, so the first is finished while the second is being written; the
    // first second of each (30 frames) keeps this quick.
    let batch = |extra: &[&str]| {
        let mut args = os(&[
            &"process",
            &input,
            &second,
            &"--out-dir",
            &".",
            &"-j",
            &"1",
            &"--end",
            &"1",
        ]);
        args.extend(extra.iter().map(OsString::from));
        args
    };
    let out = occmask_in(&batch(&["-q"]), &reference);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));

    let out = interrupt_when(&batch(&[]), &work, libc::SIGINT, Duration::ZERO, |names| {
        names.iter().any(|n| n == "desk.occmask.mcap")
    });
    assert_interrupted("batch SIGINT", &out, &work, &["desk.occmask.mcap"]);
    let err = stderr(&out);
    let line = err
        .lines()
        .find(|l| l.starts_with("error: stopped by a signal: "))
        .unwrap_or_else(|| panic!("no batch line: {err}"));
    assert!(
        line.ends_with(
            "1 of 2 files were finished and kept; run the same command with --skip-existing to \
             process the others"
        ),
        "{err}"
    );
    let first = work.join("desk.occmask.mcap");
    let kept = std::fs::metadata(&first).unwrap();
    let out = occmask_in(&batch(&["--skip-existing"]), &work);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(stderr(&out).contains("kept:"), "{}", stderr(&out));
    let now = std::fs::metadata(&first).unwrap();
    assert_eq!(
        (now.ino(), now.modified().unwrap()),
        (kept.ino(), kept.modified().unwrap())
    );
    for name in ["desk.occmask.mcap", "desk2.occmask.mcap"] {
        assert!(
            std::fs::read(work.join(name)).unwrap() == std::fs::read(reference.join(name)).unwrap(),
            "{name} differs from the uninterrupted batch's"
        );
    }
}

fn occmask_in(args: &[OsString], cwd: &Path) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_occmask"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// `--start`/`--end`: images outside the range are not decoded, so broken ones there (the
/// colour of the second and of the last frame; the first image of each stream is decoded for
/// its size whatever the range) do not stop the run, while the depth image just
/// past the end that pairs with the last colour image inside it is decoded; the passes finish
/// at the first frame past the end, and the paths end there, before the input logged after it
/// rather than at the end of the file (offline and causal).
#[test]
fn a_sidecar_stops_reading_the_input_after_the_range() {
    // Ten frames in several chunks; the last chunk (frames 8 and 9) is damaged.
    let spec = FixtureSpec { frames: 10, ..spec() };
    let mut bytes = fixture_bytes(Flavor::Protobuf, &spec);
    let (chunks, _) = layout(&bytes);
    assert!(chunks.len() >= 3, "{} chunks", chunks.len());
    let (start, len) = *chunks.last().unwrap();
    bytes[(start + len / 2) as usize] ^= 0x55;
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in.mcap");
    std::fs::write(&input, &bytes).unwrap();
    // Frames 0 to 2.
    let end_s = format!("{}", (2 * FRAME_NS + 1_000_000) as f64 / 1e9);
    for mode in [None, Some("--causal")] {
        let run = |output: &Path, extra: &[&str]| {
            let mut args = os(&[&"process", &input, &"-o", &output, &"--end", &end_s, &"-f"]);
            args.extend(mode.into_iter().chain(extra.iter().copied()).map(OsString::from));
            occmask(&args)
        };
        // The annotated copy needs every message: it reads the damaged chunk and fails.
        let out = run(&tmp.path().join("out.mcap"), &[]);
        assert_ne!(out.status.code(), Some(0), "{mode:?}");
        assert!(
            stderr(&out).contains("damaged chunk"),
            "{mode:?}: {}",
            stderr(&out)
        );
        // A sidecar stops at the first frame past the end, long before it.
        let sidecar = tmp.path().join("side.mcap");
        let out = run(&sidecar, &["--sidecar"]);
        assert_eq!(out.status.code(), Some(0), "{mode:?}: {}", stderr(&out));
        let written = std::fs::read(&sidecar).unwrap();
        let masks = mcap::MessageStream::new(&written)
            .unwrap()
            .filter(|m| m.as_ref().unwrap().channel.topic == "/occmask/mask")
            .count();
        assert_eq!(masks, 3, "{mode:?}: frames 0 to 2");
    }
}

#[test]
fn images_outside_the_time_range_are_not_decoded_and_the_paths_end_at_its_last_frame() {
    use process_support::COLOR_TOPIC;
    // Ten frames: three past the end.
    let spec = FixtureSpec { frames: 10, ..spec() };
    let bytes = rewrite(&fixture_bytes(Flavor::Protobuf, &spec), |topic, _, data| {
        if topic != COLOR_TOPIC {
            return Some(data);
        }
        let mut img = fm::RawImage::decode(data.as_slice()).unwrap();
        let frame = frame_of(occmask::mcap_io::codec::timestamp_ns(img.timestamp.as_ref()));
        if frame == 1 || frame == 9 {
            img.data.truncate(10);
        }
        Some(img.encode_to_vec())
    });
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in.mcap");
    std::fs::write(&input, &bytes).unwrap();
    // Kept: colour offsets in [50 ms, 6 frames + 1 ms), frames 2 to 6; frame 6's depth, 3 ms
    // after its colour, lies past the end.
    let end_s = format!("{}", (6 * FRAME_NS + 1_000_000) as f64 / 1e9);
    for mode in [None, Some("--causal")] {
        let output = tmp.path().join("out.mcap");
        let mut args = os(&[
            &"process", &input, &"-o", &output, &"--start", &"0.05", &"--end", &end_s, &"-f",
        ]);
        args.extend(mode.map(OsString::from));
        let out = occmask(&args);
        assert_eq!(out.status.code(), Some(0), "{mode:?}: {}", stderr(&out));
        let summary = stderr(&out);
        let row = summary
            .lines()
            .find(|l| l.starts_with("in.mcap"))
            .unwrap_or_default();
        assert_eq!(row.split_whitespace().nth(1), Some("5"), "{mode:?}: {summary}");

        let written = std::fs::read(&output).unwrap();
        let messages: Vec<(String, u64)> = mcap::MessageStream::new(&written)
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                (m.channel.topic.clone(), m.log_time)
            })
            .collect();
        assert!(
            messages.windows(2).all(|w| w[0].1 <= w[1].1),
            "{mode:?}: out of log-time order"
        );
        let masks: Vec<u64> = messages
            .iter()
            .filter(|(t, _)| t == "/occmask/mask")
            .map(|(_, log_time)| *log_time)
            .collect();
        assert_eq!(masks.len(), 5, "{mode:?}");
        let (path_at, (_, path_log_time)) = messages
            .iter()
            .enumerate()
            .rfind(|(_, (t, _))| t == "/occmask/path")
            .unwrap();
        // Logged at the latest log time written (the last frame's, or a message copied since).
        assert!(Some(path_log_time) >= masks.last(), "{mode:?}: the last path");
        assert!(
            messages[path_at + 1..].iter().any(|(t, _)| t == COLOR_TOPIC),
            "{mode:?}: the input after the last frame comes after the paths"
        );
    }
}
