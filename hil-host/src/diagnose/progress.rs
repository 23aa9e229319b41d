//! The progress of a diagnosis on stderr, fed by the solver's iteration observer through
//! [`super::diagnose`]'s `progress` callback. On a terminal: an indicatif bar of the fits done,
//! with the current fit, its position among all fits and its solver iteration, redrawn in place
//! and cleared when the diagnosis ends. Elsewhere (CI, pipes, files): one plain line per fit,
//! since carriage returns would pile up in a log file.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::Progress;

/// Turns [`Progress`] updates into a bar (terminal) or plain lines.
#[derive(Debug)]
pub struct ProgressLine {
    bar: Option<ProgressBar>,
    /// The fit last shown (its index), 0 before the first.
    shown_index: usize,
    elapsed_s: f64,
    total: usize,
}

impl ProgressLine {
    /// `terminal`: a bar drawn in place on stderr; otherwise plain lines.
    pub fn new(terminal: bool) -> Self {
        Self::with_bar(terminal.then(|| ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr())))
    }

    /// For stderr as it is: a terminal or not.
    pub fn for_stderr() -> Self {
        Self::new(std::io::stderr().is_terminal())
    }

    fn with_bar(bar: Option<ProgressBar>) -> Self {
        if let Some(b) = &bar {
            if let Ok(style) = ProgressStyle::with_template("diagnose [{bar:20}] {msg} [{elapsed}]") {
                b.set_style(style.progress_chars("#>-"));
            }
            b.enable_steady_tick(Duration::from_millis(200));
        }
        ProgressLine {
            bar,
            shown_index: 0,
            elapsed_s: 0.0,
            total: 0,
        }
    }

    /// Shows this update; returns the plain line to write when stderr is not a terminal (one
    /// per fit), `None` otherwise.
    pub fn render(&mut self, p: &Progress) -> Option<String> {
        let new_fit = p.index != self.shown_index;
        self.shown_index = p.index;
        self.elapsed_s = p.elapsed_s;
        self.total = p.total;
        match &self.bar {
            Some(b) => {
                if new_fit {
                    b.set_length(p.total as u64);
                    b.set_position(p.index.saturating_sub(1) as u64);
                }
                b.set_message(message(p));
                None
            }
            None => new_fit.then(|| format!("fitting {} ({}/{}) ...\n", p.fit, p.index, p.total)),
        }
    }

    /// Ends the display: on a terminal the bar is cleared and a final line with the fits and
    /// the total time is returned; plain output needs nothing more.
    pub fn finish(&mut self) -> Option<String> {
        let b = self.bar.as_ref()?;
        b.finish_and_clear();
        if self.shown_index == 0 {
            return None;
        }
        self.shown_index = 0;
        Some(format!("diagnose: {} fits in {:.1} s\n", self.total, self.elapsed_s))
    }
}

impl Drop for ProgressLine {
    fn drop(&mut self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// The bar's message: the fit, its place among all fits, the solver iteration.
pub fn message(p: &Progress) -> String {
    format!(
        "{}/{} {:<20} solver iteration {:>3}",
        p.index, p.total, p.fit, p.iteration
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at<'a>(fit: &'a str, index: usize, iteration: usize, elapsed_s: f64) -> Progress<'a> {
        Progress {
            fit,
            index,
            total: 5,
            iteration,
            elapsed_s,
        }
    }

    #[test]
    fn terminal_bar_follows_the_fits_and_ends_with_the_total_time() {
        let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::hidden());
        let mut line = ProgressLine::with_bar(Some(bar.clone()));
        assert_eq!(line.render(&at("baseline", 1, 0, 0.0)), None);
        assert_eq!((bar.position(), bar.length()), (0, Some(5)));
        assert_eq!(line.render(&at("baseline", 1, 7, 0.35)), None);
        assert!(bar.message().contains("1/5 baseline") && bar.message().contains("solver iteration   7"));
        line.render(&at("pressure-direction", 3, 0, 0.36));
        assert_eq!(bar.position(), 2, "two fits done");
        let end = line.finish().unwrap();
        assert_eq!(end, "diagnose: 5 fits in 0.4 s\n");
        assert!(bar.is_finished());
        assert_eq!(line.finish(), None);
    }

    #[test]
    fn plain_output_is_one_line_per_fit() {
        let mut line = ProgressLine::new(false);
        let mut text = String::new();
        for (fit, index) in [("baseline", 1), ("a", 2), ("b", 3)] {
            for iteration in 0..4 {
                text.extend(line.render(&at(fit, index, iteration, iteration as f64)));
            }
        }
        assert_eq!(
            text,
            "fitting baseline (1/5) ...\nfitting a (2/5) ...\nfitting b (3/5) ...\n"
        );
        assert!(!text.contains('\r'));
        assert_eq!(line.finish(), None);
    }
}
