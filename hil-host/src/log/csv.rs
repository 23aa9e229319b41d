//! The CSV reader: streams a log line by line (no whole-file string), accepts the bench-tool
//! dialects of `shared/DATA-FORMAT.md` and says what it normalised, and hands the columns to
//! the same checks every log goes through ([`super::check`]) with each sample's file line.
//!
//! Bounds (each an error naming the line when crossed, so no input can take unbounded memory):
//! [`MAX_LINE_BYTES`] per line, [`MAX_META_LINES`] lines before the header,
//! [`super::check::MAX_COLUMNS`] columns, [`MAX_ROWS`] data rows.

use std::io::BufRead;

use super::check::{check_meta, finish, select_columns, MetaEntry, RowLines};
use super::clock::{clock_ns, ClockColumn};
use super::column_units::{units_off_names, ColumnUnits};
use super::lines::Lines;
use super::sparse::{fill_blanks, is_blank, BLANK_BITS};
use super::units;
use super::{Log, LogError, Plant};

/// Longest accepted line (bytes, without its line end).
pub const MAX_LINE_BYTES: usize = 1 << 20;
/// Most lines (metadata, comments, blank) before the header.
pub const MAX_META_LINES: usize = 10_000;
/// Most data rows (a 20 kHz log of 40 min; an EHVVA log of this length takes 3.2 GB).
pub const MAX_ROWS: usize = 50_000_000;

/// A cell of a split line: a byte range of the line (inside the quotes for a quoted cell).
#[derive(Clone, Copy, Debug)]
struct Cell {
    start: usize,
    end: usize,
    quoted: bool,
    /// A quoted cell with `""` inside (an escaped quote).
    escaped: bool,
}

impl Cell {
    fn text(self, line: &str) -> &str {
        &line[self.start..self.end]
    }
}

/// The separator and the decimal mark, found from the header.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Dialect {
    sep: u8,
    /// `,` accepted as decimal mark (when `;` or tab separates).
    decimal_comma: bool,
}

impl Dialect {
    /// The dialect of a file that names its separator (Excel's `sep=` line): `,` as decimal
    /// mark where the separator is not `,`.
    fn with_sep(sep: u8) -> Dialect {
        Dialect {
            sep,
            decimal_comma: sep != b',',
        }
    }

    /// `;` if the header has one outside quotes, else tab if it has one, else `,`.
    fn detect(header: &str) -> Dialect {
        let (mut semicolons, mut tabs, mut quoted) = (0, 0, false);
        for b in header.bytes() {
            match b {
                b'"' => quoted = !quoted,
                b';' if !quoted => semicolons += 1,
                b'\t' if !quoted => tabs += 1,
                _ => {}
            }
        }
        match (semicolons, tabs) {
            (s, _) if s > 0 => Dialect {
                sep: b';',
                decimal_comma: true,
            },
            (_, t) if t > 0 => Dialect {
                sep: b'\t',
                decimal_comma: true,
            },
            _ => Dialect {
                sep: b',',
                decimal_comma: false,
            },
        }
    }
}

/// What a data row's cells hold beyond plain numbers, for the values and the notices: the
/// time column in clock time stamps, flags written as words, a sparse export's blanks.
#[derive(Default)]
struct CellKinds {
    clock: Option<ClockColumn>,
    /// The flag columns where words were read.
    flag_words: Vec<String>,
    blanks: bool,
}

impl CellKinds {
    /// A data cell's value (`text` trimmed, `escaped` when it held a quote), in column `name`:
    /// a number; in the time column (`at`: whether it is the time column, the first data row,
    /// the file's line) a clock time stamp where the first row's is one; a flag's word; or, for
    /// an empty cell outside the time column, the blank placeholder ([`BLANK_BITS`]). An error
    /// says what the cell is not.
    fn read(
        &mut self,
        text: &str,
        escaped: bool,
        (is_time, first_row, line): (bool, bool, usize),
        name: &str,
        decimal_comma: bool,
    ) -> Result<f64, String> {
        if escaped {
            return Err(format!("`{}` is not a number", truncate(text, 40)));
        }
        if let (Some(clock), true) = (self.clock.as_mut(), is_time) {
            return clock.seconds(text, decimal_comma);
        }
        if let Some(v) = number(text, decimal_comma) {
            return Ok(v);
        }
        if is_time && first_row {
            if let Some((ns, dated)) = clock_ns(text, decimal_comma) {
                // The column is read as clock time stamps from here on.
                self.clock = Some(ClockColumn::new(ns, dated, line, text));
                return Ok(0.0);
            }
        }
        if let Some(v) = super::flag_word(text).filter(|_| super::FLAGS.contains(&name)) {
            // LabVIEW's booleans, a bench's switch states.
            if !self.flag_words.iter().any(|f| f == name) {
                self.flag_words.push(name.to_string());
            }
            return Ok(v);
        }
        match (text.is_empty(), is_time) {
            (true, true) => Err("empty cell, a time is needed".into()),
            (true, false) => {
                // A sparse export's slower channel: filled once every row is read.
                self.blanks = true;
                Ok(f64::from_bits(BLANK_BITS))
            }
            (false, _) => Err(format!("`{}` is not a number", truncate(text, 40))),
        }
    }
}

/// Excel's separator line, `sep=;` (also quoted, `"sep=;"`), which it writes first and
/// reads as the file's separator: the separator, `None` when `line` is no such line; an error
/// for a separator that is not one of DATA-FORMAT's (`,`, `;`, tab).
fn excel_sep_line(line: &str) -> Result<Option<u8>, String> {
    let l = line.trim_matches(|c| c == ' ' || c == '\r');
    let l = l.strip_prefix('"').and_then(|l| l.strip_suffix('"')).unwrap_or(l);
    let Some(sep) = l.get(..4).filter(|p| p.eq_ignore_ascii_case("sep=")).map(|_| &l[4..]) else {
        return Ok(None);
    };
    match sep.as_bytes() {
        [b @ (b',' | b';' | b'\t')] => Ok(Some(*b)),
        _ => Err(format!(
            "separator line `{}`: the separator must be `,`, `;` or a tab",
            truncate(l, 20)
        )),
    }
}

/// Splits a line into cells (RFC 4180 quoting within the line; a quote cannot span lines, so
/// line numbers stay the file's). An error gives the byte (1-based) and what is wrong.
fn split(line: &str, sep: u8, cells: &mut Vec<Cell>) -> Result<(), (usize, &'static str)> {
    cells.clear();
    let b = line.as_bytes();
    let blank = |c: u8| c == b' ' || (c == b'\t' && sep != b'\t');
    let mut i = 0;
    loop {
        let mut j = i;
        while j < b.len() && blank(b[j]) {
            j += 1;
        }
        if j < b.len() && b[j] == b'"' {
            let start = j + 1;
            let mut k = start;
            let mut escaped = false;
            loop {
                match b.get(k) {
                    None => return Err((j + 1, "quote not closed on this line")),
                    Some(b'"') if b.get(k + 1) == Some(&b'"') => {
                        escaped = true;
                        k += 2;
                    }
                    Some(b'"') => break,
                    Some(_) => k += 1,
                }
            }
            let end = k;
            k += 1;
            while k < b.len() && blank(b[k]) {
                k += 1;
            }
            cells.push(Cell {
                start,
                end,
                quoted: true,
                escaped,
            });
            if k == b.len() {
                return Ok(());
            }
            if b[k] != sep {
                return Err((k + 1, "text after a closing quote"));
            }
            i = k + 1;
        } else {
            let end = b[i..].iter().position(|&c| c == sep).map_or(b.len(), |p| i + p);
            cells.push(Cell {
                start: i,
                end,
                quoted: false,
                escaped: false,
            });
            if end == b.len() {
                return Ok(());
            }
            i = end + 1;
        }
    }
}

/// A cell's number: `.` or (in a decimal-comma dialect) `,` as decimal mark. `None` when it
/// is not a number; NaN and infinity parse (the samples' check names them).
fn number(cell: &str, decimal_comma: bool) -> Option<f64> {
    let s = cell.trim();
    if decimal_comma && s.contains(',') {
        // Bounded copy on the stack: a number has no business being longer.
        let mut buf = [0u8; 64];
        if s.len() > buf.len() || s.matches(',').count() > 1 || s.contains('.') {
            return None;
        }
        for (d, c) in buf.iter_mut().zip(s.bytes()) {
            *d = if c == b',' { b'.' } else { c };
        }
        return std::str::from_utf8(&buf[..s.len()]).ok()?.parse().ok();
    }
    s.parse().ok()
}

/// Reads a CSV log from `input`, checking it whole; `source` names it in errors.
/// `plant_override` (from `--plant`) wins over `# plant:`.
pub fn read_csv(source: &str, input: impl BufRead, plant_override: Option<Plant>) -> Result<Log, LogError> {
    read_csv_sized(source, input, plant_override, None, None)
}

/// Header renames from a channel map's `[channels]` (a bench tool's column names to
/// DATA-FORMAT's), applied before the header is checked.
#[derive(Clone, Copy, Debug)]
pub struct Renames<'a> {
    /// The map file, for messages.
    pub map_file: &'a str,
    /// (the file's column name, the DATA-FORMAT column name).
    pub columns: &'a [(String, String)],
    /// (DATA-FORMAT column name, the unit its values were recorded in): the map's `[units]`,
    /// which win over the file's own.
    pub units: &'a [(String, String)],
}

/// The header's names with `renames` applied; a notice lists what was renamed. A renamed
/// column whose new name the header also has is an error naming both; a required column
/// that the map's source name would have given, found under neither name, names both.
fn rename_header(
    source: &str,
    plant: Plant,
    header_line: usize,
    mut names: Vec<String>,
    renames: Renames<'_>,
    notices: &mut Vec<String>,
) -> Result<Vec<String>, LogError> {
    let err = |column: &str, message: String| LogError {
        file: source.to_string(),
        line: Some(header_line),
        column: Some(column.to_string()),
        message,
    };
    let mut renamed = Vec::new();
    let mut absent = Vec::new();
    for (from, to) in renames.columns {
        let Some(i) = names.iter().position(|n| n == from) else {
            if !names.contains(to) {
                absent.push(format!("`{from}` (for `{to}`)"));
            }
            continue;
        };
        if let Some(j) = names.iter().position(|n| n == to).filter(|&j| j != i) {
            return Err(err(
                to,
                format!(
                    "column #{} `{from}` is renamed to `{to}` by the channel map {}, and the header has `{to}` too (column #{})",
                    i + 1,
                    renames.map_file,
                    j + 1
                ),
            ));
        }
        if from != to {
            renamed.push(format!("`{from}` → `{to}`"));
            names[i] = to.clone();
        }
    }
    for column in std::iter::once("t_s").chain(plant.required_columns()) {
        if names.iter().any(|n| n == column) {
            continue;
        }
        if let Some((from, _)) = renames.columns.iter().find(|(_, to)| to == column) {
            const SHOWN: usize = 20;
            let more = if names.len() > SHOWN {
                format!(", ... ({} columns)", names.len())
            } else {
                String::new()
            };
            return Err(err(
                column,
                format!(
                    "required `{plant}` column `{column}` is missing: no column `{from}` (channel map {}) or `{column}` in the header (its columns: {}{more})",
                    renames.map_file,
                    names[..names.len().min(SHOWN)].join(", ")
                ),
            ));
        }
    }
    if !renamed.is_empty() {
        notices.push(format!(
            "channel map {}: column{} renamed: {}",
            renames.map_file,
            if renamed.len() == 1 { "" } else { "s" },
            renamed.join(", ")
        ));
    }
    if !absent.is_empty() {
        notices.push(format!(
            "channel map {}: not in the header: {}",
            renames.map_file,
            absent.join(", ")
        ));
    }
    Ok(names)
}

/// Data rows read before the columns are sized from the file's length.
const SIZING_ROWS: usize = 512;

/// As [`read_csv`]; with the input's length in bytes (`size_hint`), the columns are sized
/// once from the length of the first rows instead of growing by doubling, which may hold up
/// to twice the log while it is read; `renames` (a channel map's) apply to the header.
pub fn read_csv_sized(
    source: &str,
    input: impl BufRead,
    plant_override: Option<Plant>,
    size_hint: Option<u64>,
    renames: Option<Renames<'_>>,
) -> Result<Log, LogError> {
    let mut lines = Lines::new(source, input);
    let err = |line: usize, column: Option<&str>, message: String| LogError {
        file: source.to_string(),
        line: Some(line),
        column: column.map(str::to_string),
        message,
    };

    // Metadata, then the header.
    let mut entries: Vec<MetaEntry> = Vec::new();
    let mut notices: Vec<String> = Vec::new();
    let mut comments = Vec::new();
    let mut sep_line = None;
    let header = loop {
        let Some((number, l)) = lines.next_line()? else {
            return Err(LogError {
                file: source.to_string(),
                line: None,
                column: None,
                message: "no header row (file is empty or only metadata)".into(),
            });
        };
        if number > MAX_META_LINES {
            return Err(err(
                number,
                None,
                format!("no header row within the first {MAX_META_LINES} lines"),
            ));
        }
        if l.trim().is_empty() {
            continue;
        }
        if number == 1 {
            if let Some(sep) = excel_sep_line(l).map_err(|m| err(number, None, m))? {
                sep_line = Some(sep);
                continue;
            }
        }
        if let Some(body) = l.strip_prefix('#') {
            match body.trim_start_matches('#').split_once(':') {
                Some((k, v)) if !k.trim().is_empty() => entries.push(MetaEntry {
                    key: k.trim().to_string(),
                    value: v.trim().to_string(),
                    line: Some(number),
                }),
                _ => comments.push(number),
            }
            continue;
        }
        break l.to_string();
    };
    let header_line = lines.number;
    if !comments.is_empty() {
        notices.push(format!(
            "{} comment line(s) without `key: value` ignored (first: line {})",
            comments.len(),
            comments[0]
        ));
    }
    let (plant, meta, meta_notices) = check_meta(source, &entries, plant_override)?;
    drop(entries);

    let dialect = sep_line.map_or_else(|| Dialect::detect(&header), Dialect::with_sep);
    let mut cells: Vec<Cell> = Vec::new();
    let mut quoted_seen = false;
    split(&header, dialect.sep, &mut cells)
        .map_err(|(at, what)| err(header_line, None, format!("{what} (byte {at})")))?;
    // A separator after the last column on every line (some spreadsheet exports): an empty
    // last header cell, and rows one empty cell longer.
    let trailing_sep = cells.len() > 1
        && cells
            .last()
            .is_some_and(|c| !c.quoted && c.text(&header).trim().is_empty());
    if trailing_sep {
        cells.pop();
    }
    let names: Vec<String> = cells
        .iter()
        .map(|c| {
            quoted_seen |= c.quoted;
            let t = c.text(&header).trim();
            if c.escaped {
                t.replace("\"\"", "\"")
            } else {
                t.to_string()
            }
        })
        .collect();
    // A column renamed by the channel map is the bench's own: its values are in the unit it
    // was recorded in (its name's bracket or the units row), converted to the column's.
    let original = names.clone();
    let names = match renames {
        Some(r) => rename_header(source, plant, header_line, names, r, &mut notices)?,
        None => names,
    };
    let renamed: Vec<bool> = original.iter().zip(&names).map(|(o, n)| o != n).collect();
    let (names, unit_named) = units_off_names(plant, names);
    let sel = select_columns(source, plant, &names, Some(header_line))?;
    let header_err = |column: &str, m: String| err(header_line, Some(column), m);
    let mut units = ColumnUnits::from_header(
        &sel,
        &original,
        &renamed,
        &unit_named,
        renames.map_or(&[], |r| r.units),
        header_err,
    )?;
    lines.sep = Some(dialect.sep);
    lines.names = names;
    let width = sel.keep.len();
    let t_index = sel.keep.iter().position(|s| s.is_some_and(|s| sel.order[s] == "t_s"));

    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); sel.order.len()];
    let mut rows = RowLines::default();
    let mut n_rows = 0usize;
    let mut units_line = None;
    let mut comma_decimals = false;
    let mut first_data = true;
    let mut sizing_bytes = 0usize;
    let mut kinds = CellKinds::default();
    while let Some((n, l)) = lines.next_line()? {
        if l.trim().is_empty() {
            continue;
        }
        if l.starts_with('#') {
            return Err(err(n, None, "metadata line after the header".into()));
        }
        if let Some(total) = size_hint {
            if n_rows < SIZING_ROWS {
                sizing_bytes += l.len() + 1;
            } else if n_rows == SIZING_ROWS {
                // Later rows are rarely shorter (the time stamps grow): a small margin.
                let rows = (total as f64 / (sizing_bytes as f64 / SIZING_ROWS as f64) * 1.02) as usize;
                for c in columns.iter_mut() {
                    c.reserve_exact(rows.saturating_sub(c.len()));
                }
            }
            // Past the estimate: grow by a tenth, not by doubling.
            if n_rows > SIZING_ROWS {
                for c in columns.iter_mut().filter(|c| c.len() == c.capacity()) {
                    c.reserve_exact(c.len() / 10 + 1);
                }
            }
        }
        split(l, dialect.sep, &mut cells).map_err(|(at, what)| err(n, None, format!("{what} (byte {at})")))?;
        if trailing_sep && cells.len() == width + 1 && cells.last().is_some_and(|c| c.text(l).trim().is_empty()) {
            cells.pop();
        }
        if cells.len() != width {
            return Err(err(n, None, format!("{} cells, header has {width}", cells.len())));
        }
        if std::mem::take(&mut first_data) {
            // A units row: right under the header, its time cell no number, no cell a number.
            let is_units = t_index.is_some_and(|i| {
                let t = cells[i].text(l).trim();
                !t.is_empty() && number(t, dialect.decimal_comma).is_none()
            }) && cells.iter().all(|c| number(c.text(l), dialect.decimal_comma).is_none());
            if is_units {
                for (i, (c, slot)) in cells.iter().zip(&sel.keep).enumerate() {
                    let Some(slot) = slot else { continue };
                    quoted_seen |= c.quoted;
                    let name = &sel.order[*slot];
                    let unit = units::bare(c.text(l));
                    if unit.is_empty() {
                        continue;
                    }
                    if let Some(notice) = units
                        .units_row_cell((*slot, name, &original[i]), unit, renamed[i], n)
                        .map_err(|m| err(n, Some(name), m))?
                    {
                        notices.push(notice);
                    }
                }
                units_line = Some(n);
                continue;
            }
        }
        if n_rows == MAX_ROWS {
            return Err(err(n, None, format!("more than {MAX_ROWS} data rows")));
        }
        for (i, (c, slot)) in cells.iter().zip(&sel.keep).enumerate() {
            let Some(slot) = slot else { continue };
            quoted_seen |= c.quoted;
            let text = c.text(l).trim();
            let name = &sel.order[*slot];
            let is_time = Some(i) == t_index;
            let v = kinds
                .read(text, c.escaped, (is_time, n_rows == 0, n), name, dialect.decimal_comma)
                .map_err(|m| err(n, Some(name), m))?;
            comma_decimals |= dialect.decimal_comma && text.contains(',');
            // A blank stays the placeholder; a clock's stamps are read in seconds, whatever unit
            // the column's name states.
            let as_read = is_blank(v) || (is_time && kinds.clock.is_some());
            columns[*slot].push(match units.conversions[*slot] {
                Some(c) if !as_read => c.apply(v),
                _ => v,
            });
        }
        rows.push(n_rows, n);
        n_rows += 1;
    }

    // What was normalised, in the order a reader meets it.
    let mut normalised = Vec::new();
    if sep_line.is_some() {
        normalised.push("Excel's separator line (line 1) read".to_string());
    }
    if lines.bom {
        normalised.push("UTF-8 byte-order mark removed".to_string());
    }
    if let Some((line, byte)) = lines.windows_1252 {
        normalised.push(format!(
            "read as Windows-1252, not UTF-8 (line {line} has byte 0x{byte:02X}, which UTF-8 does not allow there)"
        ));
    }
    if lines.crlf {
        normalised.push("CRLF line ends".to_string());
    }
    if let Some(c) = &kinds.clock {
        normalised.push(format!(
            "time column in clock time stamps read as the time since line {}'s `{}` (t_s = 0){}",
            c.line,
            c.text,
            match c.midnights {
                0 => String::new(),
                1 => ", across midnight".to_string(),
                k => format!(", across {k} midnights"),
            }
        ));
    }
    match dialect.sep {
        b';' => normalised.push(format!(
            "`;` separator{}",
            if comma_decimals {
                " with `,` as decimal mark"
            } else {
                ""
            }
        )),
        b'\t' => normalised.push(format!(
            "tab separator{}",
            if comma_decimals {
                " with `,` as decimal mark"
            } else {
                ""
            }
        )),
        _ => {}
    }
    if trailing_sep {
        normalised.push("a separator after the last column".to_string());
    }
    if !kinds.flag_words.is_empty() {
        normalised.push(format!(
            "flags written as words (`TRUE`/`FALSE`, `on`/`off`, `high`/`low`) read as 1/0 in {}",
            kinds
                .flag_words
                .iter()
                .map(|f| format!("`{f}`"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if unit_named.iter().any(Option::is_some) {
        normalised.push(format!(
            "units taken off the column names ({})",
            original
                .iter()
                .zip(&unit_named)
                .filter(|(_, u)| u.is_some())
                .map(|(o, _)| format!("`{o}`"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if let Some(u) = units_line {
        normalised.push(format!(
            "units row on line {u} checked against the column names and skipped"
        ));
    }
    if quoted_seen {
        normalised.push("quoted cells unquoted".to_string());
    }
    if kinds.blanks {
        notices.extend(fill_blanks(
            source,
            plant,
            &sel.order,
            &mut columns,
            &mut rows,
            header_line,
        )?);
    }
    let mut all_notices = Vec::new();
    if !normalised.is_empty() {
        all_notices.push(format!("dialect normalised: {}", normalised.join("; ")));
    }
    all_notices.extend(units.notes.into_notices());
    all_notices.extend(meta_notices);
    all_notices.extend(notices);
    all_notices.extend(sel.notices);
    // The columns grew by doubling: give back the unused capacity (up to half of each) before
    // the log is used, since it is held for the whole of a diagnosis.
    let columns: Vec<(String, Vec<f64>)> = sel
        .order
        .into_iter()
        .zip(columns)
        .map(|(name, mut c)| {
            c.shrink_to_fit();
            (name, c)
        })
        .collect();
    finish(source, plant, meta, columns, &rows, all_notices)
}

/// At most `max` characters of `s` (on a character boundary), with `…` when cut.
pub(super) fn truncate(s: &str, max: usize) -> String {
    match s.char_indices().nth(max) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cells_of(line: &str, sep: u8) -> Result<Vec<String>, (usize, &'static str)> {
        let mut cells = Vec::new();
        split(line, sep, &mut cells)?;
        Ok(cells.iter().map(|c| c.text(line).to_string()).collect())
    }

    #[test]
    fn split_handles_quotes_empty_cells_and_bad_quoting() {
        assert_eq!(
            cells_of("a,b,,c,", b','),
            Ok(vec!["a", "b", "", "c", ""].into_iter().map(String::from).collect())
        );
        assert_eq!(cells_of(r#""a;b" ; "1,5";x"#, b';').unwrap(), ["a;b", "1,5", "x"]);
        assert_eq!(cells_of(r#""say ""hi""",2"#, b',').unwrap(), [r#"say ""hi"""#, "2"]);
        assert_eq!(cells_of(r#"1,"2"#, b','), Err((3, "quote not closed on this line")));
        assert_eq!(cells_of(r#""1"x,2"#, b','), Err((4, "text after a closing quote")));
        assert_eq!(cells_of("", b',').unwrap(), [""]);
    }

    #[test]
    fn numbers_with_decimal_comma() {
        assert_eq!(number(" 1,5 ", true), Some(1.5));
        assert_eq!(number("1.5", true), Some(1.5));
        assert_eq!(number("-2,5e-3", true), Some(-2.5e-3));
        assert_eq!(number("1.234,5", true), None);
        assert_eq!(number("1,5", false), None);
        assert_eq!(number(&"1".repeat(60), true), "1".repeat(60).parse().ok());
        assert_eq!(number(&format!("{},5", "1".repeat(100)), true), None);
    }

    #[test]
    fn dialect_from_the_header() {
        assert_eq!(Dialect::detect("t_s;x_pct").sep, b';');
        assert_eq!(Dialect::detect("t_s\tx_pct").sep, b'\t');
        assert_eq!(Dialect::detect("\"a;b\",x_pct").sep, b',');
    }
}
