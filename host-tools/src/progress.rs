//! Progress bars and spinners on stderr, for the command line and the developer tasks.

use indicatif::{ProgressBar, ProgressStyle};

/// A spinner that ticks by itself, with `message`.
#[must_use]
pub fn spinner(message: String) -> ProgressBar {
    let spinner = ProgressBar::new_spinner();
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    spinner.set_message(message);
    spinner
}

/// A bar of `length` steps with `message`.
#[must_use]
pub fn progress_bar(length: u64, message: &'static str) -> ProgressBar {
    let bar = ProgressBar::new(length);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{bar:30}] {pos}/{len} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(message);
    bar
}
