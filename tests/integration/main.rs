//! The integration tests: one test binary with a module per topic, so the crate is linked
//! once for all of them. Shared helpers live in [`common`]. `cargo test --test integration
//! TOPIC::` runs one topic (e.g. `dvo_tum::`).
//!
//! `tests/detector_alloc.rs` stays a binary of its own: it installs a counting global
//! allocator, which would count the allocations of every test running beside it.

mod common;

mod bad_inputs;
mod cli_demo;
mod convert_cli;
mod convert_roundtrip;
mod detector_closed_loop;
mod detector_real;
mod detector_synthetic;
mod dvo_synthetic;
mod dvo_tum;
mod foxglove_check;
mod fuzz_regressions;
mod mcap_input;
mod pipeline_failures;
mod process_batch;
mod process_cli;
mod process_eval;
mod process_flavours;
mod process_layout;
mod python_validators;
