//! `McapInput` reads the same recording the same way from a path, from bytes in memory and from
//! any seekable reader: channels, every message (header and bytes), metadata and attachments,
//! and where a truncated recording was cut.
#![allow(clippy::unwrap_used)] // helpers outside #[test] fns: a panic is the failure report

use std::io::Cursor;
use std::path::Path;

use occmask::error::McapProblem;
use occmask::mcap_io::input::{ExtraRecord, McapInput, RawMessage};
use occmask::Error;

use crate::common::mcap_fixture::{fixture_bytes, FixtureSpec, ALL_FLAVORS};

/// Everything a reader reports about its input.
#[derive(Debug, PartialEq)]
struct Seen {
    indexed: bool,
    truncated_at: Option<u64>,
    channels: Vec<(u16, String, String)>,
    messages: Vec<RawMessage>,
    extras: Vec<ExtraRecord>,
}

fn seen(input: &McapInput) -> Seen {
    let mut messages = Vec::new();
    input
        .for_each_message(None, None, |m| {
            messages.push(m);
            Ok(true)
        })
        .unwrap();
    Seen {
        indexed: input.is_indexed(),
        truncated_at: input.truncation().map(|t| t.intact_bytes),
        channels: input
            .channels()
            .values()
            .map(|c| (c.id, c.topic.clone(), c.schema_name.clone()))
            .collect(),
        messages,
        extras: input.extras().unwrap(),
    }
}

/// The three ways in agree on `bytes`; returns what they saw.
fn agree(bytes: &[u8], dir: &Path) -> Seen {
    let path = dir.join("input.mcap");
    std::fs::write(&path, bytes).unwrap();
    let from_path = seen(&McapInput::open(&path).unwrap());
    let from_bytes = seen(&McapInput::from_bytes(bytes, Path::new("in memory")).unwrap());
    let from_reader = seen(&McapInput::from_reader(std::fs::File::open(&path).unwrap(), &path).unwrap());
    assert_eq!(from_bytes, from_path);
    assert_eq!(from_reader, from_path);
    from_path
}

#[test]
fn path_bytes_and_reader_read_the_same() {
    let dir = tempfile::tempdir().unwrap();
    for flavor in ALL_FLAVORS {
        for indexed in [true, false] {
            let spec = FixtureSpec {
                indexed,
                ..FixtureSpec::default()
            };
            let bytes = fixture_bytes(flavor, &spec);
            let whole = agree(&bytes, dir.path());
            assert!(!whole.messages.is_empty(), "{flavor:?}");
            assert_eq!(whole.truncated_at, None, "{flavor:?}");
            // Cut mid-way: read linearly up to the last complete record, the same way by all.
            let cut = agree(&bytes[..bytes.len() / 2], dir.path());
            assert!(!cut.indexed && cut.truncated_at.is_some(), "{flavor:?}");
            assert!(cut.messages.len() < whole.messages.len(), "{flavor:?}");
        }
    }
}

#[test]
fn errors_name_the_given_name() {
    let err = McapInput::from_bytes(b"not an mcap file".to_vec(), Path::new("<recording>"))
        .err()
        .unwrap();
    assert!(
        matches!(&err, Error::BadMcap { path, problem: McapProblem::NoMagic } if path == Path::new("<recording>")),
        "{err}"
    );
    assert!(err.to_string().contains("<recording>"), "{err}");
    let err = McapInput::from_reader(Cursor::new(Vec::new()), Path::new("empty"))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("empty"), "{err}");
}

/// The message count and log-time span (what `process` records of its input) are the messages'
/// own, however the file is read: from the summary's statistics, from its chunk indexes when it
/// has no statistics, or by the linear scan (no index, or cut short).
#[test]
fn message_count_and_log_time_span_are_those_of_the_messages_read() {
    let dir = tempfile::tempdir().unwrap();
    let expect_own = |bytes: &[u8], what: &str| {
        let input = McapInput::from_bytes(bytes, Path::new(what)).unwrap();
        let messages = seen(&input).messages;
        let times = messages.iter().map(|m| m.header.log_time);
        let span = times.clone().min().zip(times.max());
        assert!(span.is_some(), "{what}");
        assert_eq!(input.message_count(), Some(messages.len() as u64), "{what}");
        assert_eq!(input.log_time_span(), span, "{what}");
    };
    for flavor in ALL_FLAVORS {
        for indexed in [true, false] {
            let bytes = fixture_bytes(
                flavor,
                &FixtureSpec {
                    indexed,
                    ..FixtureSpec::default()
                },
            );
            expect_own(&bytes, &format!("{flavor:?}, indexed {indexed}"));
            expect_own(&bytes[..bytes.len() / 2], &format!("{flavor:?}, cut"));
        }
    }
    // A summary without statistics: the span from the chunk indexes, no count.
    let path = dir.path().join("no_stats.mcap");
    let mut writer = mcap::WriteOptions::new()
        .emit_statistics(false)
        .chunk_size(Some(64))
        .create(std::io::BufWriter::new(std::fs::File::create(&path).unwrap()))
        .unwrap();
    let channel = writer
        .add_channel(0, "/t", "json", &std::collections::BTreeMap::new())
        .unwrap();
    for (sequence, log_time) in [(0, 30), (1, 10), (2, 50), (3, 20)] {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence,
            log_time,
            publish_time: log_time,
        };
        writer.write_to_known_channel(&header, b"{}").unwrap();
    }
    writer.finish().unwrap();
    drop(writer);
    let input = McapInput::open(&path).unwrap();
    assert!(input.is_indexed());
    assert_eq!(input.message_count(), None);
    assert_eq!(input.log_time_span(), Some((10, 50)));
}
