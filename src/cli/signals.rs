//! Ctrl-C / SIGTERM: the first signal asks long-running commands to stop cleanly (so the
//! temporary output file is removed); a second one kills the process as usual. SIGPIPE gets its
//! default action back, so `occmask eval … | head` ends quietly like any Unix filter once the
//! reader is gone, instead of panicking in `println!`.

use std::sync::atomic::{AtomicBool, Ordering};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// True once SIGINT or SIGTERM has been received.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::Relaxed)
}

#[cfg(unix)]
extern "C" fn on_signal(signal: libc::c_int) {
    INTERRUPTED.store(true, Ordering::Relaxed);
    // SAFETY: signal() is async-signal-safe; restoring the default makes a second Ctrl-C fatal.
    unsafe {
        libc::signal(signal, libc::SIG_DFL);
    }
}

/// Installs the handlers (Unix; elsewhere the default behaviour stays).
pub fn install() {
    #[cfg(unix)]
    // SAFETY: the handler only stores to an atomic and calls signal(), both async-signal-safe;
    // SIG_DFL for SIGPIPE undoes the Rust runtime's SIG_IGN (outputs are written under a
    // temporary name and renamed on success, so ending on SIGPIPE never leaves a half-written
    // file under an output's name).
    unsafe {
        let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
        libc::signal(libc::SIGINT, handler);
        libc::signal(libc::SIGTERM, handler);
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
