//! The stop flag: SIGINT, SIGTERM and SIGHUP ask a run to stop at its next event.
//!
//! [`install`] registers the three signals once per process. The first signal sets
//! [`flag`] (library loops poll it between events) and remembers which signal it was; a second
//! signal of any of the three ends the process at once with the conventional code (130, 143 or
//! 129), for a run that does not stop soon enough. A simulation that stopped early exits with
//! [`code_or`]'s code; a live capture, for which Ctrl-C is the normal end, keeps exit 0.
//!
//! Everything here goes through `signal-hook`'s safe flag API: the handlers only store to
//! atomics.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

/// Set by the first signal; what library loops poll.
static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();
/// The number of the first signal (0 before any).
static WHICH: OnceLock<Arc<AtomicUsize>> = OnceLock::new();
/// A flag that is never set, for runs without handlers (tests, library callers).
static NEVER: AtomicBool = AtomicBool::new(false);

const SIGNALS: [(i32, &str, u8); 3] = [
    (SIGINT, "SIGINT", 130),
    (SIGTERM, "SIGTERM", 143),
    (SIGHUP, "SIGHUP", 129),
];

/// Registers the handlers (idempotent). Fails only if the OS refuses a handler.
pub fn install() -> std::io::Result<()> {
    if STOP.get().is_some() {
        return Ok(());
    }
    let stop = Arc::new(AtomicBool::new(false));
    let which = Arc::new(AtomicUsize::new(0));
    for (signal, _, code) in SIGNALS {
        // Registered first, so it sees the flag as the previous signal left it: a second
        // signal ends the process; the first only sets the flag (registered next).
        signal_hook::flag::register_conditional_shutdown(signal, i32::from(code), stop.clone())?;
        signal_hook::flag::register_usize(signal, which.clone(), signal as usize)?;
        signal_hook::flag::register(signal, stop.clone())?;
    }
    // A race between two installers leaves the first pair; both sets of handlers stay
    // registered, so either pair sees the signal.
    let _ = STOP.set(stop);
    let _ = WHICH.set(which);
    Ok(())
}

/// The flag library loops poll: set once a stop was asked for (never set before [`install`]).
pub fn flag() -> &'static AtomicBool {
    match STOP.get() {
        Some(flag) => flag,
        None => &NEVER,
    }
}

/// True once a signal asked the run to stop.
pub fn requested() -> bool {
    flag().load(Ordering::SeqCst)
}

fn first_signal() -> Option<(&'static str, u8)> {
    let number = WHICH.get()?.load(Ordering::SeqCst);
    SIGNALS
        .iter()
        .find(|(signal, _, _)| *signal as usize == number)
        .map(|&(_, name, code)| (name, code))
        .or_else(|| requested().then_some(("a signal", 130)))
}

/// The name of the signal that stopped the run (`"SIGTERM"`), if one did.
pub fn signal_name() -> Option<&'static str> {
    first_signal().map(|(name, _)| name)
}

/// 130 (SIGINT), 143 (SIGTERM) or 129 (SIGHUP) if a signal stopped the run, else `code`.
pub fn code_or(code: u8) -> u8 {
    first_signal().map_or(code, |(_, c)| c)
}

/// `"interrupted by SIGTERM"` for summaries, if a signal stopped the run.
pub fn note() -> Option<String> {
    signal_name().map(|name| format!("interrupted by {name}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_handlers_nothing_is_requested() {
        assert!(!NEVER.load(Ordering::SeqCst));
        assert_eq!(
            SIGNALS.iter().map(|s| s.2).collect::<Vec<_>>(),
            [130, 143, 129]
        );
    }
}
