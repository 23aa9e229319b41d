//! The progress of a diagnosis on stderr. On a terminal: one line redrawn in place with `\r`
//! (which fit, its position among all fits, the solver iteration, the elapsed time), cleared
//! when the diagnosis ends. Elsewhere (CI, pipes, files): one plain line per fit, since
//! carriage returns would pile up in a log file.

use std::io::IsTerminal;

use super::Progress;

/// Iteration redraws closer together than this are skipped (a new fit always draws).
const REDRAW_EVERY_S: f64 = 0.1;

/// Turns [`Progress`] updates into the text to write to stderr.
#[derive(Debug)]
pub struct ProgressLine {
    terminal: bool,
    /// The fit last shown (its index), 0 before the first.
    shown_index: usize,
    last_draw_s: f64,
    /// Characters of the line on screen, to blank out when a shorter one replaces it.
    width: usize,
    elapsed_s: f64,
    total: usize,
}

impl ProgressLine {
    /// `terminal`: redraw one line in place; otherwise plain lines.
    pub fn new(terminal: bool) -> Self {
        Self {
            terminal,
            shown_index: 0,
            last_draw_s: f64::NEG_INFINITY,
            width: 0,
            elapsed_s: 0.0,
            total: 0,
        }
    }

    /// For stderr as it is: a terminal or not.
    pub fn for_stderr() -> Self {
        Self::new(std::io::stderr().is_terminal())
    }

    /// The text to write for this update, or `None` when nothing changes on screen.
    pub fn render(&mut self, p: &Progress) -> Option<String> {
        let new_fit = p.index != self.shown_index;
        self.elapsed_s = p.elapsed_s;
        self.total = p.total;
        if !self.terminal {
            self.shown_index = p.index;
            return new_fit.then(|| format!("fitting {} ({}/{}) ...\n", p.fit, p.index, p.total));
        }
        if !new_fit && p.elapsed_s - self.last_draw_s < REDRAW_EVERY_S {
            return None;
        }
        self.shown_index = p.index;
        self.last_draw_s = p.elapsed_s;
        // Fits done so far, as a bar.
        let done = p.index.saturating_sub(1).min(p.total);
        let bar: String = "#".repeat(done) + &"-".repeat(p.total - done);
        let line = format!(
            "diagnose [{bar}] {}/{} {:<20} solver iteration {:>3}  {:6.1} s",
            p.index, p.total, p.fit, p.iteration, p.elapsed_s
        );
        Some(self.redraw(line))
    }

    /// The text that ends the display: on a terminal the bar gives way to a final line with the
    /// total time; plain output needs nothing more.
    pub fn finish(&mut self) -> Option<String> {
        if !self.terminal || self.shown_index == 0 {
            return None;
        }
        let line = format!("diagnose: {} fits in {:.1} s", self.total, self.elapsed_s);
        self.shown_index = 0;
        Some(self.redraw(line) + "\n")
    }

    /// `\r`, the line, and blanks over what is left of a longer previous line.
    fn redraw(&mut self, line: String) -> String {
        let len = line.chars().count();
        let pad = self.width.saturating_sub(len);
        self.width = len;
        format!("\r{line}{}", " ".repeat(pad))
    }
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
    fn terminal_redraws_one_line_in_place() {
        let mut line = ProgressLine::new(true);
        let first = line.render(&at("baseline", 1, 0, 0.0)).unwrap();
        assert!(first.starts_with('\r') && !first.contains('\n'), "{first:?}");
        assert!(
            first.contains("[-----] 1/5 baseline") && first.contains("solver iteration   0"),
            "{first:?}"
        );
        // Iterations closer than the redraw interval are skipped, later ones shown.
        assert_eq!(line.render(&at("baseline", 1, 1, 0.05)), None);
        let later = line.render(&at("baseline", 1, 7, 0.35)).unwrap();
        assert!(
            later.contains("solver iteration   7") && later.contains("0.3 s"),
            "{later:?}"
        );
        // A new fit always draws, the bar advances, and a longer line is fully blanked after.
        let long = line.render(&at("pressure-direction", 3, 0, 0.36)).unwrap();
        assert!(long.contains("[##---] 3/5 pressure-direction"), "{long:?}");
        let width = long.chars().count();
        let short = line.render(&at("x", 4, 0, 0.37)).unwrap();
        assert!(
            short.chars().count() >= width,
            "{short:?} leaves characters of {long:?}"
        );
        let end = line.finish().unwrap();
        assert!(
            end.starts_with('\r') && end.ends_with('\n') && end.contains("5 fits in 0.4 s"),
            "{end:?}"
        );
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
