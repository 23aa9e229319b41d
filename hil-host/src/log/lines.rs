//! A CSV log's lines as text: bounded length, line ends, a byte-order mark, and the encoding
//! (UTF-8, or Windows-1252 as bench PCs export), each line with its number in the file.

use std::io::{BufRead, Read};

use super::csv::MAX_LINE_BYTES;
use super::LogError;

/// Reads the file's lines: bounded length, line ends (`\n`, `\r\n`) and a leading UTF-8
/// byte-order mark removed, UTF-8 checked, blank lines counted. A file whose first line outside
/// ASCII is not UTF-8 is read as Windows-1252, the code page bench tools and spreadsheets
/// export in on Windows (`°C` is one byte there, 0xB0, which UTF-8 does not allow alone).
pub(super) struct Lines<R: BufRead> {
    pub(super) input: R,
    pub(super) buf: Vec<u8>,
    /// The 1-based number of the line in `buf`.
    pub(super) number: usize,
    pub(super) source: String,
    pub(super) crlf: bool,
    pub(super) bom: bool,
    /// A line with bytes outside ASCII that are valid UTF-8 was read (or a byte-order mark):
    /// the file is UTF-8, and a later invalid byte is an error, not another encoding.
    pub(super) utf8_seen: bool,
    /// The file is read as Windows-1252: the line and byte that UTF-8 does not allow.
    pub(super) windows_1252: Option<(usize, u8)>,
    /// A Windows-1252 line decoded.
    pub(super) decoded: String,
    /// Set once the header is known, so that a bad byte is named by its column.
    pub(super) sep: Option<u8>,
    pub(super) names: Vec<String>,
}

impl<R: BufRead> Lines<R> {
    /// The lines of `input`, named `source` in errors.
    pub(super) fn new(source: &str, input: R) -> Self {
        Lines {
            input,
            buf: Vec::new(),
            number: 0,
            source: source.to_string(),
            crlf: false,
            bom: false,
            utf8_seen: false,
            windows_1252: None,
            decoded: String::new(),
            sep: None,
            names: Vec::new(),
        }
    }

    fn error(&self, column: Option<String>, message: String) -> LogError {
        LogError {
            file: self.source.clone(),
            line: Some(self.number),
            column,
            message,
        }
    }

    /// The next line, `None` at the end of the input.
    pub(super) fn next_line(&mut self) -> Result<Option<(usize, &str)>, LogError> {
        self.buf.clear();
        let limit = MAX_LINE_BYTES as u64 + 1;
        let got = (&mut self.input).take(limit).read_until(b'\n', &mut self.buf);
        self.number += 1;
        match got {
            Err(e) => return Err(self.error(None, format!("cannot read: {e}"))),
            Ok(0) => return Ok(None),
            Ok(_) => {}
        }
        if self.buf.last() == Some(&b'\n') {
            self.buf.pop();
        } else if self.buf.len() > MAX_LINE_BYTES {
            return Err(self.error(
                None,
                format!("line longer than {MAX_LINE_BYTES} bytes (not a log, or a line end is missing)"),
            ));
        }
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
            self.crlf = true;
        }
        let mut start = 0;
        if self.number == 1 {
            if self.buf.starts_with(&[0xEF, 0xBB, 0xBF]) {
                start = 3;
                self.bom = true;
            } else if self.buf.starts_with(&[0xFF, 0xFE]) || self.buf.starts_with(&[0xFE, 0xFF]) {
                return Err(self.error(
                    None,
                    "UTF-16 text (byte-order mark at the start); save the log as UTF-8".into(),
                ));
            }
        }
        if self.bom {
            self.utf8_seen = true;
        }
        if !self.buf[start..].is_ascii() {
            match (std::str::from_utf8(&self.buf[start..]), self.windows_1252) {
                (Ok(_), None) => self.utf8_seen = true,
                (Err(e), None) if !self.utf8_seen => {
                    self.windows_1252 = Some((self.number, self.buf[start + e.valid_up_to()]));
                }
                _ => {}
            }
            if self.windows_1252.is_some() {
                // Control bytes and the five bytes Windows-1252 leaves undefined are binary
                // data, not a bench's text in either encoding.
                let binary =
                    |b: u8| matches!(b, 0..=8 | 0x0B | 0x0C | 0x0E..=0x1F | 0x7F | 0x81 | 0x8D | 0x8F | 0x90 | 0x9D);
                if let Some(at) = self.buf[start..].iter().position(|&b| binary(b)) {
                    return Err(self.error(
                        None,
                        format!(
                            "not text: byte 0x{:02X} at byte {} of the line is neither UTF-8 nor Windows-1252 text",
                            self.buf[start + at],
                            start + at + 1
                        ),
                    ));
                }
                let (text, _) = encoding_rs::WINDOWS_1252.decode_without_bom_handling(&self.buf[start..]);
                self.decoded.clear();
                self.decoded.push_str(&text);
                return Ok(Some((self.number, &self.decoded)));
            }
        }
        match std::str::from_utf8(&self.buf[start..]) {
            Ok(s) => Ok(Some((self.number, s))),
            Err(e) => {
                let at = start + e.valid_up_to();
                let column = self.sep.and_then(|sep| {
                    let cell = self.buf[start..at].iter().filter(|&&b| b == sep).count();
                    self.names.get(cell).cloned()
                });
                Err(self.error(
                    column,
                    format!(
                        "not valid UTF-8 (byte 0x{:02X} at byte {} of the line) in a file that is UTF-8 (its \
                         byte-order mark or an earlier line): it mixes encodings",
                        self.buf[at],
                        at + 1
                    ),
                ))
            }
        }
    }
}
