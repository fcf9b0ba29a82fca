//! Progress on long runs: an indicatif bar or spinner on standard error, shown only when
//! standard error is a terminal (and the user did not ask for quiet), hidden otherwise so
//! scripts and logs never see control sequences.

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};

/// True when progress should be drawn.
fn visible(quiet: bool) -> bool {
    !quiet && std::io::stderr().is_terminal()
}

/// A bar to `total` with indicatif's `template` (e.g. `"{pos}/{len} packets [{bar:30}] {eta}"`).
pub fn bar(quiet: bool, total: u64, template: &str) -> ProgressBar {
    if !visible(quiet) {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(total);
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// A progress callback `(done, known)` for runs whose length grows as they go: sets `bar`'s
/// length to what is known so far and its position to what is done.
pub fn follow(bar: &ProgressBar) -> impl FnMut(u64, u64) + '_ {
    move |done, known| {
        bar.set_length(known);
        bar.set_position(done);
    }
}

/// A spinner for runs of unknown length, with indicatif's `template`.
pub fn spinner(quiet: bool, template: &str) -> ProgressBar {
    if !visible(quiet) {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new_spinner();
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style);
    }
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    bar
}
