#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| occmask_fuzz::ros1_messages(data));
