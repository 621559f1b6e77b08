#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| occmask_fuzz::mcap_file(data));
