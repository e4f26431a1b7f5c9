//! SIGINT, SIGTERM and SIGHUP (Ctrl-C, `timeout` and farm managers, a closed terminal) cancel
//! the running solve through its progress (`StderrProgress`), so that it stops at its next
//! read of the cancel flag and everything it made is dropped (scratch files, temporaries);
//! the CLI then exits with 128 + the signal's number, as shells report a process the signal
//! ended. A second signal while the first is handled ends the process at once.

use std::sync::atomic::{AtomicI32, Ordering};

/// The first signal received (0: none).
static RECEIVED: AtomicI32 = AtomicI32::new(0);

/// The signal that asked the CLI to stop, if one did.
pub fn received() -> Option<i32> {
    match RECEIVED.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// The exit status for a process stopped by `signal` (128 + its number).
pub fn exit_status(signal: i32) -> i32 {
    128 + signal
}

/// The signal's name, for the message.
pub fn name(signal: i32) -> &'static str {
    match signal {
        1 => "SIGHUP",
        2 => "SIGINT",
        15 => "SIGTERM",
        _ => "a signal",
    }
}

/// Starts listening (a thread that only records what arrives). Failing to install the
/// handlers leaves the default behaviour (the signal ends the process), with nothing to tell.
#[cfg(unix)]
pub fn install() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else { return };
    let _ = std::thread::Builder::new().name("volscatter-signals".into()).spawn(move || {
        for sig in signals.forever() {
            if RECEIVED.compare_exchange(0, sig, Ordering::SeqCst, Ordering::SeqCst).is_err() {
                std::process::exit(exit_status(sig));
            }
        }
    });
}

#[cfg(not(unix))]
pub fn install() {}
