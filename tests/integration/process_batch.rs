//! Several files at once with per-file compute pools (`process::batch`): the output bytes of
//! every file are identical to a sequential one-thread run, whatever the split of the cores,
//! on real VGA frames (the TUM fr2_desk excerpt in `fixtures/`, where DVO's finest levels have
//! enough points for its parallel reduction and the detector's rows split into many tasks).

#![allow(clippy::unwrap_used)] // helpers outside #[test] fns: a panic is the failure report

use std::io::Cursor;
use std::path::{Path, PathBuf};

use crate::common::data;

use occmask::convert::{convert_sequence, resolve_intrinsics, ConvertConfig, DEFAULT_BATCH_EVENTS};
use occmask::dataset::{self, DatasetKind, DEFAULT_MAX_PAIR_GAP_NS};
use occmask::mcap_io::input::McapInput;
use occmask::mcap_io::McapWriteOptions;
use occmask::pipeline::{PoseSource, ProcessorConfig};
use occmask::process::batch::{run_batch, ThreadBudget};
use occmask::process::{pipeline_factory, process_file, NoHooks, PipelineOptions, ProcessConfig};

fn desk_mcap(dir: &Path) -> PathBuf {
    let seq = dataset::tum::load(&data::tum_fixture(), DatasetKind::Tum).unwrap();
    let config = ConvertConfig {
        intrinsics: resolve_intrinsics(DatasetKind::Tum, &seq.name, None).unwrap(),
        depth_units_per_meter: dataset::TUM_DEPTH_UNITS_PER_METER,
        max_pair_gap_ns: DEFAULT_MAX_PAIR_GAP_NS,
        keep_unpaired: false,
        write: McapWriteOptions::default(),
        batch_events: DEFAULT_BATCH_EVENTS,
        command_line: "test".into(),
    };
    let (cursor, _) = convert_sequence(&seq, &config, Cursor::new(Vec::new()), &mut |_, _| {
        std::ops::ControlFlow::Continue(())
    })
    .unwrap();
    let path = dir.join("desk.mcap");
    std::fs::write(&path, cursor.into_inner()).unwrap();
    path
}

fn process(path: &Path, mode: PoseSource) -> (Vec<u8>, u64) {
    let input = McapInput::open(path).unwrap();
    let config = ProcessConfig {
        processor: ProcessorConfig {
            pose_source: mode,
            ..ProcessorConfig::default()
        },
        ..ProcessConfig::default()
    };
    let (cursor, report) = process_file(
        &input,
        Cursor::new(Vec::new()),
        &config,
        &mut pipeline_factory(PipelineOptions::default()),
        &mut NoHooks,
    )
    .unwrap();
    (cursor.into_inner(), report.frames)
}

#[test]
fn files_processed_concurrently_in_their_own_pools_match_sequential_one_thread_runs() {
    let dir = tempfile::tempdir().unwrap();
    let path = desk_mcap(dir.path());
    let modes = [PoseSource::DvoClosedLoop, PoseSource::DvoUnmasked];
    // The sequential reference: one file at a time on one thread.
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let reference: Vec<(Vec<u8>, u64)> = modes
        .iter()
        .map(|&mode| one_thread.install(|| process(&path, mode)))
        .collect();
    for (bytes, frames) in &reference {
        // Ten frames: enough for DVO, the detector's accumulation and its prediction to act.
        assert_eq!(*frames, data::TUM_FIXTURE_FRAMES as u64);
        assert!(bytes.len() > 1 << 20);
    }
    assert!(
        reference[0].0 != reference[1].0,
        "the two modes must differ for the test to mean anything"
    );
    // Two files at a time with one thread each (the default on 2 cores), with 2 threads each
    // (the default on 4 cores), with uneven slots (2 and 1 threads on 3 cores), and one file at
    // a time with 3 threads.
    for (cores, jobs) in [(2, None), (4, None), (3, None), (3, Some(1))] {
        let budget = ThreadBudget::new(cores, 2, jobs, None).unwrap();
        let outputs = run_batch(2, &budget, |i| process(&path, modes[i])).unwrap();
        for (i, (bytes, frames)) in outputs.iter().enumerate() {
            assert_eq!(*frames, reference[i].1);
            assert!(
                *bytes == reference[i].0,
                "file {i} ({:?}) differs from the one-thread run with {budget:?}",
                modes[i]
            );
        }
    }
}
