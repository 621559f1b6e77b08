#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

/// One scratch file per fuzzing process, on tmpfs (McapInput and McapFileReader open paths).
fn scratch() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let dir = if std::path::Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        dir.join(format!("occmask-fuzz-{}.mcap", std::process::id()))
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| occmask_fuzz::mcap_file(data, scratch()));
