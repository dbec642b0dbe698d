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

/// The command line's [`Progress`](crate::command::Progress): a spinner for stages without a
/// count, a bar for counted ones; cleared when dropped, so that the summary (or the error)
/// printed after it stands alone.
#[derive(Debug)]
pub struct Terminal {
    bar: ProgressBar,
}

impl Terminal {
    /// A hidden bar until the first stage.
    #[must_use]
    pub fn new() -> Self {
        let bar = ProgressBar::new_spinner();
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        Self { bar }
    }
}

impl Default for Terminal {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for Terminal {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}

impl crate::command::Progress for Terminal {
    fn stage(&self, message: &str, steps: Option<u64>) {
        match steps {
            Some(length) => {
                let counted = progress_bar(length, "");
                self.bar.set_style(counted.style());
                self.bar.set_length(length);
                self.bar.set_position(0);
            }
            None => self.bar.set_style(ProgressStyle::default_spinner()),
        }
        self.bar.set_message(message.to_owned());
    }

    fn step(&self) {
        self.bar.inc(1);
    }
}
