//! End-to-end `process` throughput, MCAP in → MCAP out with DVO (closed loop) + detector at
//! 640×480, on the TUM fr2_desk excerpt in fixtures/ converted to MCAP in memory first, through the
//! same batch runner as `occmask process a b …` (`process::batch`: each file in flight on its
//! own rayon pool with its share of the cores): one file with all cores and with one thread,
//! two files one after the other and side by side, four files side by side.
//!
//! `cargo bench --bench process`; throughput is in frames (elements/s = total frames per
//! second). tools/bench_process.sh measures the binary end to end (scaling table on longer
//! files, CPU per frame, peak RSS on a generated ≥ 2 GB file).

use std::io::{Cursor, Write};
use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occmask::convert::{convert_sequence, resolve_intrinsics, ConvertConfig, DEFAULT_BATCH_EVENTS};
use occmask::dataset::{self, DatasetKind, DEFAULT_MAX_PAIR_GAP_NS};
use occmask::mcap_io::input::McapInput;
use occmask::mcap_io::McapWriteOptions;
use occmask::process::batch::{available_cores, run_batch, ThreadBudget};
use occmask::process::{pipeline_factory, process_file, NoHooks, PipelineOptions, ProcessConfig};

/// Criterion's minimum sample count: one iteration processes the excerpt's 10 VGA frames.
const SAMPLES: usize = 10;

fn process_once(input: &McapInput) -> u64 {
    let mut factory = pipeline_factory(PipelineOptions::default());
    let (_, report) = process_file(
        input,
        Cursor::new(Vec::with_capacity(64 << 20)),
        &ProcessConfig::default(),
        &mut factory,
        &mut NoHooks,
    )
    .expect("process must succeed");
    report.frames
}

fn bench_process(c: &mut Criterion) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures/tum_fr2_desk_10");
    let seq = dataset::tum::load(&root, DatasetKind::Tum).expect("the fixture must load");
    let config = ConvertConfig {
        intrinsics: resolve_intrinsics(DatasetKind::Tum, &seq.name, None).expect("fr2 preset"),
        depth_units_per_meter: dataset::TUM_DEPTH_UNITS_PER_METER,
        max_pair_gap_ns: DEFAULT_MAX_PAIR_GAP_NS,
        keep_unpaired: false,
        write: McapWriteOptions::default(),
        batch_events: DEFAULT_BATCH_EVENTS,
        command_line: "bench".into(),
    };
    let (cursor, _) = convert_sequence(&seq, &config, Cursor::new(Vec::new()), &mut |_, _| {
        std::ops::ControlFlow::Continue(())
    })
    .expect("convert");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("desk.mcap");
    std::fs::File::create(&path)
        .and_then(|mut f| f.write_all(cursor.get_ref()))
        .expect("write the converted file");
    let input = McapInput::open(&path).expect("open");
    let frames = process_once(&input);

    let cores = available_cores();
    let mut group = c.benchmark_group("process_tum_fr2_desk_10");
    group.sample_size(SAMPLES);
    // name, files, --jobs, --threads-per-file (None = the default split of the cores)
    let cases: [(&str, usize, Option<usize>, Option<usize>); 5] = [
        ("one_file", 1, None, None),
        ("one_file_one_thread", 1, None, Some(1)),
        ("two_files_one_after_the_other", 2, Some(1), None),
        ("two_files_side_by_side", 2, None, None),
        ("four_files_side_by_side", 4, None, None),
    ];
    for (name, files, jobs, threads) in cases {
        let budget = ThreadBudget::new(cores, files, jobs, threads).expect("valid budget");
        group.throughput(Throughput::Elements(files as u64 * frames));
        group.bench_function(name, |b| {
            b.iter(|| run_batch(files, &budget, |_| process_once(&input)).expect("thread pools"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_process);
criterion_main!(benches);
