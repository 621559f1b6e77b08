//! Conversion throughput on the TUM fr2_desk excerpt in fixtures/ (10 VGA RGB-D pairs, 154 poses):
//! the whole converter into memory with each compression, against reading the same files
//! (the in-process equivalent of `cat`) and decoding the depth PNGs alone.
//!
//! `cargo bench --bench convert`; throughput is in bytes of image files read, so MB/s is
//! comparable with `cat`; frames/s = 10 / time. tools/bench_convert.sh measures the binary
//! end to end (peak RSS, ratio to `cat`).

use std::io::Cursor;
use std::ops::ControlFlow;
use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occmask::convert::{convert_sequence, resolve_intrinsics, ConvertConfig, DEFAULT_BATCH_EVENTS};
use occmask::dataset::{self, DatasetKind, Sequence, DEFAULT_MAX_PAIR_GAP_NS};
use occmask::mcap_io::{Compression, McapWriteOptions};
use rayon::prelude::*;

/// Criterion's minimum sample count: one iteration reads ~6.5 MB, so keep runs short.
const SAMPLES: usize = 10;

fn image_paths(seq: &Sequence) -> Vec<PathBuf> {
    seq.color
        .iter()
        .chain(&seq.depth)
        .map(|r| r.path.clone())
        .collect()
}

fn bench_convert(c: &mut Criterion) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures/tum_fr2_desk_10");
    let seq = dataset::tum::load(&root, DatasetKind::Tum).expect("the fixture must load");
    let paths = image_paths(&seq);
    let input_bytes: u64 = paths
        .iter()
        .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
        .sum();
    let config = |compression| ConvertConfig {
        intrinsics: resolve_intrinsics(DatasetKind::Tum, &seq.name, None).expect("fr2 preset"),
        depth_units_per_meter: dataset::TUM_DEPTH_UNITS_PER_METER,
        max_pair_gap_ns: DEFAULT_MAX_PAIR_GAP_NS,
        keep_unpaired: false,
        write: McapWriteOptions {
            compression,
            ..McapWriteOptions::default()
        },
        batch_events: DEFAULT_BATCH_EVENTS,
        command_line: "bench".into(),
    };

    let mut group = c.benchmark_group("convert_tum_fr2_desk_10");
    group.sample_size(SAMPLES);
    group.throughput(Throughput::Bytes(input_bytes));
    group.bench_function("read_files_only (cat)", |b| {
        b.iter(|| {
            paths
                .iter()
                .map(|p| std::fs::read(p).map_or(0, |v| v.len()))
                .sum::<usize>()
        })
    });
    group.bench_function("decode_depth_only (rayon)", |b| {
        b.iter(|| {
            seq.depth
                .par_iter()
                .map(|r| dataset::read_depth(&r.path).map_or(0, |d| d.data.len()))
                .sum::<usize>()
        })
    });
    for (name, compression) in [
        ("convert_zstd", Compression::Zstd),
        ("convert_lz4", Compression::Lz4),
        ("convert_none", Compression::None),
    ] {
        let cfg = config(compression);
        group.bench_function(name, |b| {
            b.iter(|| {
                let sink = Cursor::new(Vec::with_capacity(64 << 20));
                convert_sequence(&seq, &cfg, sink, &mut |_, _| ControlFlow::Continue(()))
                    .expect("conversion must succeed")
                    .1
                    .messages
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_convert);
criterion_main!(benches);
