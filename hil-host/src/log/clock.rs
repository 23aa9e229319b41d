//! A CSV time column in clock time stamps, as a bench PC's wall clock writes them: a time of
//! day (`10:15:30.125`) or a date and time (ISO 8601, `29.11.2026 10:15:30,125`), parsed by
//! `chrono`, read as the seconds since the first row's stamp (docs/data-format.md).

use super::csv::truncate;

/// One day, ns.
const DAY_NS: i64 = 86_400_000_000_000;

/// A clock time stamp in ns and whether it has a date: a time of day (`10:15:30.125`) since
/// midnight, a date and time (`2026-11-29 10:15:30.125`, ISO 8601's `T` and `Z`, or
/// `29.11.2026 10:15:30.125`) since 1970. The seconds' fraction may take `,` in a
/// decimal-comma dialect (`10:15:30,125`). `None` when `cell` is none of these.
pub(super) fn clock_ns(cell: &str, decimal_comma: bool) -> Option<(i64, bool)> {
    use chrono::{NaiveDateTime, NaiveTime, Timelike};
    if !cell.contains(':') {
        return None;
    }
    let s = cell.trim();
    let s = s.strip_suffix('Z').unwrap_or(s);
    let dotted;
    let s = if decimal_comma && s.contains(',') {
        dotted = s.replace(',', ".");
        &dotted
    } else {
        s
    };
    if let Ok(t) = NaiveTime::parse_from_str(s, "%H:%M:%S%.f") {
        let ns = i64::from(t.num_seconds_from_midnight()) * 1_000_000_000 + i64::from(t.nanosecond());
        return Some((ns, false));
    }
    ["%Y-%m-%d %H:%M:%S%.f", "%Y-%m-%dT%H:%M:%S%.f", "%d.%m.%Y %H:%M:%S%.f"]
        .iter()
        .find_map(|f| NaiveDateTime::parse_from_str(s, f).ok())
        .and_then(|t| t.and_utc().timestamp_nanos_opt())
        .map(|ns| (ns, true))
}

/// A time column in clock time stamps (a bench's wall clock): each row's time since the first
/// row's stamp, s. The differences are taken in whole ns, so a 20 kHz record keeps its period
/// exactly however late in the day or the century it was taken.
pub(super) struct ClockColumn {
    origin_ns: i64,
    /// The first stamp's line and text, for the notice and the errors.
    pub(super) line: usize,
    pub(super) text: String,
    dated: bool,
    /// Days added to times of day for the midnights passed, ns.
    days_ns: i64,
    last_ns: i64,
    /// The midnights the time of day passed.
    pub(super) midnights: usize,
}

impl ClockColumn {
    pub(super) fn new(ns: i64, dated: bool, line: usize, text: &str) -> Self {
        ClockColumn {
            origin_ns: ns,
            line,
            text: truncate(text, 40),
            dated,
            days_ns: 0,
            last_ns: ns,
            midnights: 0,
        }
    }

    /// The time since the first stamp of the stamp `text`, s; an error for a cell that is
    /// not a clock time of the first one's kind.
    pub(super) fn seconds(&mut self, text: &str, decimal_comma: bool) -> Result<f64, String> {
        let ns = match clock_ns(text, decimal_comma) {
            Some((ns, dated)) if dated == self.dated => ns,
            _ => {
                return Err(format!(
                    "`{}` is not a clock time like line {}'s `{}`",
                    truncate(text, 40),
                    self.line,
                    self.text
                ))
            }
        };
        let mut ns = ns + self.days_ns;
        // A time of day that falls by more than half a day: the clock passed midnight.
        if !self.dated && ns < self.last_ns - DAY_NS / 2 {
            self.days_ns += DAY_NS;
            self.midnights += 1;
            ns += DAY_NS;
        }
        self.last_ns = ns;
        // In i128: dated stamps centuries apart would overflow i64's difference.
        Ok((i128::from(ns) - i128::from(self.origin_ns)) as f64 * 1e-9)
    }
}
