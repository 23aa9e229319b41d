//! Progress on stderr for the steps that can take more than a second (reading a big log, a run,
//! a PIL run, identification). On a terminal: an indicatif spinner or bar, cleared when the step
//! ends. Elsewhere (CI, pipes, files): one plain line per step, no carriage returns.

use std::io::IsTerminal;
use std::path::Path;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// Whether stderr is a terminal (then progress is drawn in place).
pub fn terminal() -> bool {
    std::io::stderr().is_terminal()
}

/// A step of unknown length: a spinner with the elapsed time on a terminal, one line otherwise.
pub struct Spinner {
    bar: Option<ProgressBar>,
}

impl Spinner {
    /// Starts the step; `plain` says whether to print the plain line when stderr is not a
    /// terminal (short steps say nothing there).
    pub fn start(label: &str, plain: bool) -> Self {
        if terminal() {
            let bar = ProgressBar::new_spinner().with_message(label.to_string());
            if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} [{elapsed}]") {
                bar.set_style(style);
            }
            bar.enable_steady_tick(Duration::from_millis(100));
            Spinner { bar: Some(bar) }
        } else {
            if plain {
                eprintln!("{label} ...");
            }
            Spinner { bar: None }
        }
    }
}

impl Drop for Spinner {
    fn drop(&mut self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// Logs at least this large get a "reading" line on plain stderr (smaller ones read in well
/// under a second).
const BIG_LOG_BYTES: u64 = 8 << 20;

/// The spinner for reading `path`.
pub fn reading(path: &Path) -> Spinner {
    let big = std::fs::metadata(path).is_ok_and(|m| m.len() >= BIG_LOG_BYTES);
    Spinner::start(&format!("reading {}", path.display()), big)
}

/// Steps of known number (`k` of `n`): a bar on a terminal, one line per step otherwise.
pub struct Counter {
    bar: Option<ProgressBar>,
    label: String,
}

impl Counter {
    pub fn new(label: &str, total: u64) -> Self {
        let bar = terminal().then(|| {
            let bar = ProgressBar::new(total);
            if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} [{elapsed}]") {
                bar.set_style(style.progress_chars("#>-"));
            }
            bar.set_message(label.to_string());
            bar.enable_steady_tick(Duration::from_millis(200));
            bar
        });
        Counter {
            bar,
            label: label.to_string(),
        }
    }

    /// Step `k` (1-based) of `n` begins.
    pub fn step(&self, k: u64, n: u64) {
        match &self.bar {
            Some(b) => {
                b.set_length(n);
                b.set_position(k.saturating_sub(1));
            }
            None => eprintln!("{} {k}/{n} ...", self.label),
        }
    }
}

impl Drop for Counter {
    fn drop(&mut self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
