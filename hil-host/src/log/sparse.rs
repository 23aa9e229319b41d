//! The blank cells of a sparse CSV export (CANape's and INCA's multi-rate CSV), filled as the
//! MF4 reader resamples a logger's slower channel group (docs/data-format.md).

use super::check::RowLines;
use super::{LogError, Plant};

/// A blank cell of a sparse export, held as this NaN until [`fill_blanks`] fills it: a NaN
/// written in the file parses to another (the log's check refuses that one by its line).
pub(super) const BLANK_BITS: u64 = 0x7FF8_0000_0000_0B1A;

/// Whether `v` is a blank cell's placeholder.
pub(super) fn is_blank(v: f64) -> bool {
    v.to_bits() == BLANK_BITS
}

/// Fills the blank cells of a sparse export (CANape's and INCA's multi-rate CSV: a channel
/// slower than the rows has an empty cell between its samples), as the MF4 reader resamples a
/// logger's slower channel group: the rows without the primary output are left out (its
/// samples are the log's time base), and every other column with blanks is resampled at the
/// rows' times from the rows that hold it (linearly, flags by zero-order hold; rows before
/// its first or after its last sample take that value). The notices say what was done.
pub(super) fn fill_blanks(
    source: &str,
    plant: Plant,
    order: &[String],
    columns: &mut [Vec<f64>],
    rows: &mut RowLines,
    header_line: usize,
) -> Result<Vec<String>, LogError> {
    let err = |line: Option<usize>, column: &str, message: String| LogError {
        file: source.to_string(),
        line,
        column: Some(column.to_string()),
        message,
    };
    let at = |name: &str| order.iter().position(|o| o == name);
    let (Some(p), Some(t)) = (at(plant.primary_output()), at("t_s")) else {
        return Ok(Vec::new());
    };
    let mut notices = Vec::new();
    let primary = &order[p];
    let n = columns[p].len();
    let recorded = columns[p].iter().filter(|v| !is_blank(**v)).count();
    if recorded == 0 {
        return Err(err(Some(header_line), primary, "no value in any row".into()));
    }
    if recorded < n {
        let keep: Vec<bool> = columns[p].iter().map(|v| !is_blank(*v)).collect();
        for c in columns.iter_mut() {
            let mut k = 0;
            c.retain(|_| {
                k += 1;
                keep[k - 1]
            });
        }
        let mut kept = RowLines::default();
        for (new, old) in (0..n).filter(|&i| keep[i]).enumerate() {
            if let Some(line) = rows.line_of(old) {
                kept.push(new, line);
            }
        }
        *rows = kept;
        notices.push(format!(
            "{} of {n} rows without `{primary}` (the primary output) left out: its samples are the log's time base",
            n - recorded
        ));
    }
    let time = std::mem::take(&mut columns[t]);
    if let Some(k) = time.windows(2).position(|w| !(w[1] > w[0])) {
        return Err(err(
            rows.line_of(k + 1),
            "t_s",
            format!(
                "time does not increase ({} then {}), so the blank cells between a column's samples cannot be placed",
                time[k],
                time[k + 1]
            ),
        ));
    }
    let mut filled = Vec::new();
    let mut outside_total = 0;
    for (name, c) in order.iter().zip(columns.iter_mut()) {
        let samples = c.iter().filter(|v| !is_blank(**v)).count();
        if samples == c.len() || c.is_empty() {
            continue;
        }
        if samples == 0 {
            let which = if recorded < n {
                format!("no value in any row that holds `{primary}`")
            } else {
                "no value in any row".to_string()
            };
            return Err(err(Some(header_line), name, which));
        }
        let flag = super::FLAGS.contains(&name.as_str());
        let (out, outside) = crate::signal::fill_gaps(&time, c, |i| !is_blank(c[i]), flag)
            .map_err(|m| err(Some(header_line), name, m))?;
        *c = out;
        outside_total += outside;
        filled.push(format!(
            "`{name}` ({samples} of {} rows, {})",
            time.len(),
            if flag { "held" } else { "interpolated" }
        ));
    }
    columns[t] = time;
    if !filled.is_empty() {
        let mut note = format!(
            "sparse export: blank cells between a slower channel's samples filled at each row's time: {}",
            filled.join(", ")
        );
        if outside_total > 0 {
            note.push_str(&format!(
                "; {outside_total} cell(s) before a column's first or after its last sample take that value"
            ));
        }
        notices.push(note);
    }
    Ok(notices)
}
