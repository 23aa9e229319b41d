//! The bench-tool dialects of `shared/DATA-FORMAT.md` (issue #15.2): each reads to the same
//! numbers as the plain CSV, the reader says what it normalised, and errors name the file's
//! own line and the column.

use hil_host::log::{parse_log, Log, LogError};

/// A plain vacuum log: metadata, header, 6 rows with values that print differently in every
/// dialect (decimals, negative, exponent).
fn plain() -> String {
    let mut s = String::from(
        "# plant: vacuum\n# source: dialect test\nt_s,duty_pct,u_batt_V,p_amb_kPa,p_tank_kPa,x_pct,u_pilot_extra\n",
    );
    for i in 0..6 {
        let t = i as f64 * 0.002;
        s.push_str(&format!(
            "{t},{},{},101.325,{},{},x\n",
            10.0 + 7.25 * i as f64,
            13.5 - 0.125 * i as f64,
            35.0 + 1e-3 * i as f64,
            -0.5 + 12.75 * i as f64
        ));
    }
    s
}

/// Rewrites the plain log's header and data lines (metadata stays) cell by cell.
fn dialect(sep: &str, decimal_comma: bool, quote: bool, units: Option<&str>, crlf: bool, bom: bool) -> String {
    let plain = plain();
    let mut out = String::new();
    if bom {
        out.push('\u{feff}');
    }
    let eol = if crlf { "\r\n" } else { "\n" };
    for (k, line) in plain.lines().enumerate() {
        if line.starts_with('#') {
            out.push_str(line);
        } else {
            let cells: Vec<String> = line
                .split(',')
                .map(|c| {
                    let c = if decimal_comma {
                        c.replace('.', ",")
                    } else {
                        c.to_string()
                    };
                    if quote {
                        format!("\"{c}\"")
                    } else {
                        c
                    }
                })
                .collect();
            out.push_str(&cells.join(sep));
            if k == 2 {
                if let Some(u) = units {
                    out.push_str(eol);
                    out.push_str(&u.replace(',', sep));
                }
            }
        }
        out.push_str(eol);
    }
    out
}

fn read(name: &str, text: &str) -> Log {
    parse_log(name, text, None).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn same_numbers(a: &Log, b: &Log) {
    assert_eq!(a.order, b.order);
    for name in &a.order {
        let (x, y) = (a.col(name).unwrap(), b.col(name).unwrap());
        assert_eq!(x.len(), y.len(), "{name}");
        for (p, q) in x.iter().zip(y) {
            assert_eq!(p.to_bits(), q.to_bits(), "{}: {name} {p} vs {q}", b.file);
        }
    }
    assert_eq!(a.dt_s.to_bits(), b.dt_s.to_bits());
    assert_eq!(a.meta, b.meta);
}

fn normalised(log: &Log) -> &str {
    log.notices
        .iter()
        .find(|n| n.starts_with("dialect normalised"))
        .map_or("", String::as_str)
}

#[test]
fn every_dialect_reads_to_the_plain_numbers_and_says_what_it_normalised() {
    let base = read("plain.csv", &plain());
    assert_eq!(base.len(), 6);
    assert_eq!(normalised(&base), "", "{:?}", base.notices);
    let cases: [(&str, String, &[&str]); 10] = [
        (
            "bom.csv",
            dialect(",", false, false, None, false, true),
            &["byte-order mark"],
        ),
        ("crlf.csv", dialect(",", false, false, None, true, false), &["CRLF"]),
        (
            "semicolon.csv",
            dialect(";", true, false, None, false, false),
            &["`;` separator with `,` as decimal mark"],
        ),
        (
            "semicolon-dot.csv",
            dialect(";", false, false, None, false, false),
            &["`;` separator"],
        ),
        (
            "tab.csv",
            dialect("\t", false, false, None, false, false),
            &["tab separator"],
        ),
        (
            "tab-comma.csv",
            dialect("\t", true, false, None, false, false),
            &["tab separator with `,` as decimal mark"],
        ),
        (
            "units.csv",
            dialect(",", false, false, Some("s,%,V,kPa,kPa,%,"), false, false),
            &["units row on line 4"],
        ),
        (
            "units-brackets.csv",
            dialect(",", false, false, Some("[s],[%],[V],[kPa],[kPa],[%],[-]"), false, false),
            &["units row on line 4"],
        ),
        (
            "quoted.csv",
            dialect(",", false, true, None, false, false),
            &["quoted cells"],
        ),
        (
            // Excel's separator line; the header alone would be taken for `;` separated (an
            // ignored column's name holds a `;`).
            "excel-sep.csv",
            format!(
                "\"sep=,\"\n{}",
                dialect(",", false, false, None, false, false).replacen("u_pilot_extra", "note;s", 1)
            ),
            &["Excel's separator line (line 1) read"],
        ),
    ];
    for (name, text, says) in cases {
        let log = read(name, &text);
        same_numbers(&base, &log);
        for s in says {
            assert!(normalised(&log).contains(s), "{name}: {:?}", log.notices);
        }
    }
    // All at once: a German Excel export.
    let text = dialect(
        ";",
        true,
        true,
        Some("\"[s]\";\"[%]\";\"[V]\";\"[kPa]\";\"[kPa]\";\"[%]\";\"\""),
        true,
        true,
    );
    let log = read("excel.csv", &text);
    same_numbers(&base, &log);
    let n = normalised(&log);
    for s in [
        "byte-order mark",
        "CRLF",
        "`;` separator with `,` as decimal mark",
        "units row on line 4",
        "quoted",
    ] {
        assert!(n.contains(s), "{n}");
    }
}

/// The plain log with its time column written by `stamp` (the sample's index to its cell)
/// and its separator and decimal mark as `dialect(sep, decimal_comma, ..)` writes them.
fn with_clock(sep: &str, decimal_comma: bool, stamp: impl Fn(usize) -> String) -> String {
    let text = dialect(sep, decimal_comma, false, None, false, false);
    let mut row = 0;
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(k, line)| {
            if line.starts_with('#') || k == 2 {
                return line.to_string();
            }
            let (_, rest) = line.split_once(sep).unwrap();
            row += 1;
            format!("{}{sep}{rest}", stamp(row - 1))
        })
        .collect();
    lines.join("\n") + "\n"
}

/// A bench's time column in clock time stamps (its wall clock: a time of day, or a date and
/// time) reads as the seconds since the first row's stamp, the other columns as the plain
/// log's, across midnight too; a cell of another kind in that column is named by its line.
#[test]
fn a_time_column_in_clock_time_stamps_reads_as_the_seconds_since_the_first() {
    let base = read("plain.csv", &plain());
    // The plain log's rows are 2 ms apart; the time of day starts 3 ms before midnight.
    let time_of_day = |i: usize| {
        let ms = (86_399_997 + 2 * i as u64) % 86_400_000;
        let (h, m, s) = (ms / 3_600_000, ms / 60_000 % 60, ms / 1000 % 60);
        format!("{h:02}:{m:02}:{s:02}.{:03}", ms % 1000)
    };
    let cases = [
        (
            "time-of-day.csv",
            with_clock(",", false, time_of_day),
            "across midnight",
        ),
        (
            "iso.csv",
            with_clock(",", false, |i| format!("2026-11-29T10:15:30.{:06}Z", 2000 * i)),
            "line 4's `2026-11-29T10:15:30.000000Z`",
        ),
        (
            "german.csv",
            with_clock(";", true, |i| format!("29.11.2026 10:15:30,{:03}", 2 * i)),
            "line 4's `29.11.2026 10:15:30,000`",
        ),
    ];
    for (name, text, says) in cases {
        let log = read(name, &text);
        assert!(
            normalised(&log).contains("time column in clock time stamps"),
            "{name}: {:?}",
            log.notices
        );
        assert!(normalised(&log).contains(says), "{name}: {:?}", log.notices);
        assert_eq!(log.order, base.order);
        for col in &base.order {
            let (x, y) = (base.col(col).unwrap(), log.col(col).unwrap());
            for (p, q) in x.iter().zip(y) {
                if col == "t_s" {
                    assert!((p - q).abs() < 1e-12, "{name}: t_s {p} vs {q}");
                } else {
                    assert_eq!(p.to_bits(), q.to_bits(), "{name}: {col} {p} vs {q}");
                }
            }
        }
        assert!((log.dt_s - 0.002).abs() < 1e-12, "{name}: {}", log.dt_s);
    }
    // A bench's own time column with the stamps' format in its units row, renamed by a map.
    let text = with_clock(";", true, |i| format!("29.11.2026 10:15:30,{:03}", 2 * i))
        .replacen("t_s;", "Zeit;", 1)
        .replacen("u_pilot_extra\n", "u_pilot_extra\nhh:mm:ss,ms;%;V;kPa;kPa;%;-\n", 1);
    let log = read_mapped("zeit.csv", &text, "[channels]\n\"Zeit\" = \"t_s\"\n").unwrap_or_else(|e| panic!("{e}"));
    for (p, q) in base.col("t_s").unwrap().iter().zip(log.col("t_s").unwrap()) {
        assert!((p - q).abs() < 1e-12, "zeit.csv: t_s {p} vs {q}");
    }
    assert!(normalised(&log).contains("units row on line 4"), "{:?}", log.notices);
    // A number among the stamps, and a time of day among dated stamps: line and column.
    let text = with_clock(",", false, |i| {
        if i == 3 {
            "0.006".into()
        } else {
            format!("10:15:30.{:03}", 2 * i)
        }
    });
    let e = error("mixed.csv", &text);
    assert_eq!((e.line, e.column.as_deref()), (Some(7), Some("t_s")), "{e}");
    assert!(
        e.message
            .contains("`0.006` is not a clock time like line 4's `10:15:30.000`"),
        "{e}"
    );
    let text = with_clock(",", false, |i| {
        if i == 2 {
            "10:15:30.004".into()
        } else {
            format!("2026-11-29 10:15:30.{:03}", 2 * i)
        }
    });
    let e = error("undated.csv", &text);
    assert_eq!((e.line, e.column.as_deref()), (Some(6), Some("t_s")), "{e}");
}

/// A sparse export (CANape's, INCA's multi-rate CSV: a channel slower than the rows leaves its
/// cell empty between its samples) reads as the plain log: the blank cells filled at each row's
/// time from the column's own samples (linearly; flags held), rows without the primary output
/// left out (its samples are the time base, as for an MF4 logger's channel groups), errors
/// still named by the file's line; a column with no value at all is named.
#[test]
fn a_sparse_exports_blank_cells_are_filled_from_the_slower_channels_samples() {
    let base = read("plain.csv", &plain());
    let rows: Vec<Vec<String>> = plain()
        .lines()
        .skip(3)
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    let head =
        "# plant: vacuum\n# source: dialect test\nt_s,duty_pct,u_batt_V,p_amb_kPa,p_tank_kPa,x_pct,u_pilot_extra\n";
    // The supply voltage at rows 0, 2, 4 and 5, the tank pressure at the first and last row
    // only (both linear in time, so the interpolation gives the plain values).
    let mut text = head.to_string();
    for (i, r) in rows.iter().enumerate() {
        let mut r = r.clone();
        if i == 1 || i == 3 {
            r[2].clear();
        }
        if i != 0 && i != 5 {
            r[4].clear();
        }
        text.push_str(&(r.join(",") + "\n"));
    }
    let log = read("sparse.csv", &text);
    for name in &base.order {
        for (p, q) in base.col(name).unwrap().iter().zip(log.col(name).unwrap()) {
            assert!((p - q).abs() <= 1e-12 * p.abs().max(1.0), "{name}: {p} vs {q}");
        }
    }
    let note = log.notices.iter().find(|n| n.starts_with("sparse export")).unwrap();
    assert!(
        note.contains("`u_batt_V` (4 of 6 rows, interpolated)") && note.contains("`p_tank_kPa` (2 of 6 rows"),
        "{note}"
    );

    // Rows of a faster channel (the duty) between the primary output's: left out, the rest
    // as in the plain log; a bad cell after them is named by its own line of the file.
    let mut text = head.to_string();
    for r in &rows {
        text.push_str(&(r.join(",") + "\n"));
        text.push_str(&format!("{},50,,,,,\n", r[0].parse::<f64>().unwrap() + 0.001));
    }
    let log = read("fast.csv", &text);
    same_numbers(&base, &log);
    assert!(
        log.notices
            .iter()
            .any(|n| n.contains("6 of 12 rows without `x_pct` (the primary output) left out")),
        "{:?}",
        log.notices
    );
    let bad = text.replacen(",101.325,", ",NaN,", 3).replacen(",NaN,", ",101.325,", 2);
    let e = error("fast-bad.csv", &bad);
    assert_eq!((e.line, e.column.as_deref()), (Some(8), Some("p_amb_kPa")), "{e}");

    // A flag recorded at two rows only: held from each sample on.
    let mut text =
        String::from("# plant: ehvva\nt_s,u_pilot,p_supply_MPa,p_back_MPa,temp_C,lift_high,snubber_on,lift_mm\n");
    for i in 0..6 {
        let u = match i {
            0 => "0",
            3 => "1",
            _ => "",
        };
        text.push_str(&format!("{},{u},7,1,22,1,0,{}\n", i as f64 * 5e-5, 0.1 * i as f64));
    }
    let log = read("flag.csv", &text);
    assert_eq!(log.col("u_pilot").unwrap(), &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
    // The same flags as words (LabVIEW writes its booleans so): the same log, said once.
    let words = text.replace("\n0,0,", "\n0,FALSE,").replace(",1,7,", ",True,7,");
    assert_ne!(words, text);
    let worded = read("words.csv", &words);
    assert_eq!(worded.col("u_pilot"), log.col("u_pilot"));
    assert!(
        normalised(&worded).contains("read as 1/0 in `u_pilot`"),
        "{:?}",
        worded.notices
    );
    // Not in a signal's column.
    let e = error("word.csv", &words.replacen(",7,", ",on,", 1));
    assert_eq!((e.line, e.column.as_deref()), (Some(3), Some("p_supply_MPa")), "{e}");
    assert!(
        log.notices.iter().any(|n| n.contains("`u_pilot` (2 of 6 rows, held)")),
        "{:?}",
        log.notices
    );

    // A column with values only in rows without the primary output.
    let text_vacuum = "# plant: vacuum\nt_s,duty_pct,u_batt_V,p_amb_kPa,p_tank_kPa,x_pct\n0,1,13,101,35,\n0.001,1,,101,35,0\n0.002,1,,101,35,1\n";
    let e = error("only-between.csv", text_vacuum);
    assert_eq!((e.line, e.column.as_deref()), (Some(2), Some("u_batt_V")), "{e}");
    assert!(e.message.contains("no value in any row that holds `x_pct`"), "{e}");
    // A column with no value in any row.
    let text = text.replace(",22,", ",,");
    let e = error("empty.csv", &text);
    assert_eq!((e.line, e.column.as_deref()), (Some(2), Some("temp_C")), "{e}");
    assert!(e.message.contains("no value in any row"), "{e}");
}

fn error(name: &str, text: &str) -> LogError {
    match parse_log(name, text, None) {
        Ok(_) => panic!("{name} was accepted"),
        Err(e) => e,
    }
}

#[test]
fn errors_name_the_files_own_line_and_the_column_in_every_dialect() {
    // Line 8 of the file is the 4th data row with a units row (line 4) and a blank line (6).
    for (name, sep, comma) in [("c.csv", ",", false), ("s.csv", ";", true), ("t.csv", "\t", false)] {
        let mut text = dialect(sep, comma, false, Some("s,%,V,kPa,kPa,%,-"), true, true);
        let lines: Vec<&str> = text.split("\r\n").collect();
        let mut l: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
        l.insert(5, String::new());
        // Line 8: x_pct unreadable.
        let cells: Vec<&str> = l[7].split(sep).collect();
        let mut bad: Vec<String> = cells.iter().map(|s| s.to_string()).collect();
        bad[5] = "12..5".into();
        l[7] = bad.join(sep);
        text = l.join("\r\n");
        let e = error(name, &text);
        assert_eq!((e.line, e.column.as_deref()), (Some(8), Some("x_pct")), "{name}: {e}");
        assert!(e.to_string().starts_with(&format!("{name}:8, column x_pct:")), "{e}");

        // A non-finite value, found by the shared samples' check, is named by its line too.
        let text = text.replace("12..5", "NaN");
        let e = error(name, &text);
        assert_eq!((e.line, e.column.as_deref()), (Some(8), Some("x_pct")), "{name}: {e}");
    }
}

#[test]
fn a_units_row_that_contradicts_a_column_name_is_an_error_and_an_unknown_spelling_a_notice() {
    let text = dialect(",", false, false, Some("s,%,V,kPa,MPa,%,"), false, false);
    let e = error("u.csv", &text);
    assert_eq!((e.line, e.column.as_deref()), (Some(4), Some("p_tank_kPa")), "{e}");
    assert!(e.message.contains("`MPa`"), "{e}");
    // A unit of another quantity.
    let text = dialect(",", false, false, Some("s,%,V,kPa,kPa,mm,"), false, false);
    let e = error("u.csv", &text);
    assert_eq!((e.line, e.column.as_deref()), (Some(4), Some("x_pct")), "{e}");
    assert!(e.message.contains("`mm` is not a unit of `x_pct`"), "{e}");
    // A spelling no table knows (no case folding: `mpa` could be milli-): under the column's
    // own name, which states the unit, it is read in that unit and named in a notice.
    let text = dialect(",", false, false, Some("s,%,V,kpa,kPa,%,"), false, false);
    let log = read("u.csv", &text);
    same_numbers(&read("plain.csv", &plain()), &log);
    assert!(
        log.notices
            .iter()
            .any(|n| n.contains("not recognised") && n.contains("`kpa` under `p_amb_kPa`")),
        "{:?}",
        log.notices
    );
}

#[test]
fn broken_quoting_and_ragged_rows_name_the_line() {
    let text = dialect(",", false, true, None, false, false);
    let mut l: Vec<String> = text.lines().map(String::from).collect();
    l[4] = l[4].replacen("\",\"", ",\"", 1);
    let e = error("q.csv", &(l.join("\n") + "\n"));
    assert_eq!(e.line, Some(5), "{e}");
    let text = plain().replace("0.002,17.25", "0.002,17.25,1");
    let e = error("r.csv", &text);
    assert_eq!(e.line, Some(5), "{e}");
    assert!(e.message.contains("8 cells, header has 7"), "{e}");
    // A separator line naming a separator no dialect uses.
    let e = error("p.csv", &format!("sep=|\n{}", plain()));
    assert_eq!(e.line, Some(1), "{e}");
    assert!(e.message.contains("`sep=|`"), "{e}");
}

/// The bench's own column names in the `;` dialect with decimal commas and a units row, and
/// the channel map (the same TOML file as for MF4 loggers) that renames them.
const BENCH_HEADER: &str = "Zeit;PWM Tastgrad;U_Batt;p_Umgebung;p_Tank;Position";
const BENCH_MAP: &str = "[channels]\n\"Zeit\" = \"t_s\"\n\"PWM Tastgrad\" = \"duty_pct\"\n\"U_Batt\" = \"u_batt_V\"\n\"p_Umgebung\" = \"p_amb_kPa\"\n\"p_Tank\" = \"p_tank_kPa\"\n\"Position\" = \"x_pct\"\n";

fn bench_csv() -> String {
    dialect(";", true, false, Some("s,%,V,kPa,kPa,%,-"), false, false).replacen(
        "t_s;duty_pct;u_batt_V;p_amb_kPa;p_tank_kPa;x_pct",
        BENCH_HEADER,
        1,
    )
}

/// Reads `text` as the file `name` in a scratch directory through `map`.
fn read_mapped(name: &str, text: &str, map: &str) -> Result<Log, LogError> {
    read_mapped_bytes(name, text.as_bytes(), map)
}

/// [`read_mapped`] of a file's bytes (another encoding than UTF-8).
fn read_mapped_bytes(name: &str, bytes: &[u8], map: &str) -> Result<Log, LogError> {
    use hil_host::log::read_log_mapped;
    use hil_host::mf4::ChannelMap;
    let dir = std::env::temp_dir().join(format!("hil-dialect-map-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let map = ChannelMap::parse("bench.toml", map).unwrap();
    let r = read_log_mapped(&path, None, Some(&map));
    std::fs::remove_file(&path).ok();
    r
}

#[test]
fn a_channel_map_renames_a_bench_csvs_own_column_names() {
    let base = read("plain.csv", &plain());
    let log = read_mapped("bench.csv", &bench_csv(), BENCH_MAP).unwrap();
    same_numbers(&base, &log);
    let renamed = log
        .notices
        .iter()
        .find(|n| n.starts_with("channel map bench.toml: columns renamed"))
        .unwrap_or_else(|| panic!("{:?}", log.notices));
    assert!(
        renamed.contains("`Zeit` → `t_s`") && renamed.contains("`Position` → `x_pct`"),
        "{renamed}"
    );
    // The units row is checked against the DATA-FORMAT name the column was renamed to.
    let text = bench_csv().replacen("s;%;V;kPa;kPa;%", "s;%;V;kPa;kPa;mm", 1);
    let e = read_mapped("units.csv", &text, BENCH_MAP).unwrap_err();
    assert_eq!((e.line, e.column.as_deref()), (Some(4), Some("x_pct")), "{e}");
    // A bad cell in a renamed column: the file's line, the column it is read as.
    let text = bench_csv().replacen(";37,75;", ";37..75;", 1);
    assert_ne!(text, bench_csv());
    let e = read_mapped("cell.csv", &text, BENCH_MAP).unwrap_err();
    assert_eq!((e.line, e.column.as_deref()), (Some(8), Some("x_pct")), "{e}");
}

/// A bench CSV exported on Windows in its code page, Windows-1252 (umlauts in the column names
/// and the metadata, `°C`: one byte each there, which UTF-8 does not allow alone), reads as
/// its UTF-8 twin: the same numbers and metadata, the channel map (UTF-8 TOML) renaming the
/// decoded names, and a notice naming the first such byte. A file that is UTF-8 in one line
/// and Windows-1252 in a later one is refused at that line.
#[test]
fn a_windows_1252_export_reads_as_its_utf8_twin() {
    let header = "Zeit;PWM Tastverhältnis;U_Batt;p_Umgebung;p_Tank;Position";
    let map = BENCH_MAP.replace("\"PWM Tastgrad\"", "\"PWM Tastverhältnis\"");
    let utf8 = bench_csv().replacen(BENCH_HEADER, header, 1).replacen(
        "# source: dialect test",
        "# source: Prüfstand 3, Öl 90 °C",
        1,
    );
    let twin = read_mapped("utf8.csv", &utf8, &map).unwrap();
    assert!(
        twin.meta
            .iter()
            .any(|(k, v)| k == "source" && v == "Prüfstand 3, Öl 90 °C"),
        "{:?}",
        twin.meta
    );
    let (cp1252, _, unmappable) = encoding_rs::WINDOWS_1252.encode(&utf8);
    assert!(!unmappable && cp1252.len() + 4 == utf8.len() && std::str::from_utf8(&cp1252).is_err());
    let log = read_mapped_bytes("cp1252.csv", &cp1252, &map).unwrap_or_else(|e| panic!("{e}"));
    same_numbers(&twin, &log);
    assert!(
        normalised(&log).contains("read as Windows-1252, not UTF-8 (line 2 has byte 0xFC"),
        "{:?}",
        log.notices
    );
    assert!(!normalised(&twin).contains("Windows-1252"), "{:?}", twin.notices);

    // UTF-8 up to the metadata, Windows-1252 from the header on: refused there, by line.
    let (meta, rest) = utf8.split_at(utf8.find(header).unwrap());
    let mut mixed = meta.as_bytes().to_vec();
    mixed.extend_from_slice(&encoding_rs::WINDOWS_1252.encode(rest).0);
    let e = read_mapped_bytes("mixed.csv", &mixed, &map).unwrap_err();
    assert_eq!(e.line, Some(3), "{e}");
    assert!(
        e.message.contains("byte 0xE4") && e.message.contains("mixes encodings"),
        "{e}"
    );
}

#[test]
fn a_channel_map_that_does_not_fit_the_header_is_named() {
    // The header has the renamed column's new name too: two sources for one column.
    let text = bench_csv().replacen(BENCH_HEADER, &BENCH_HEADER.replace("p_Tank", "x_pct"), 1);
    let e = read_mapped("twice.csv", &text, BENCH_MAP).unwrap_err();
    assert_eq!((e.line, e.column.as_deref()), (Some(3), Some("x_pct")), "{e}");
    assert!(
        e.message
            .contains("`Position` is renamed to `x_pct` by the channel map bench.toml"),
        "{e}"
    );
    // The map's source name is not in the header, nor the column itself: both are named.
    let map = BENCH_MAP.replace("\"Position\"", "\"Hub\"");
    let e = read_mapped("missing.csv", &bench_csv(), &map).unwrap_err();
    assert_eq!(e.column.as_deref(), Some("x_pct"), "{e}");
    assert!(
        e.message
            .contains("no column `Hub` (channel map bench.toml) or `x_pct`")
            && e.message.contains("Position"),
        "{e}"
    );
}

/// A bench's own column names carry the bench's units: in the name (`Zeit [ms]`) or in the
/// units row. Renamed by the channel map, each column is converted to the DATA-FORMAT unit:
/// the same log as the plain file's, within rounding, and a notice names each conversion.
#[test]
fn a_bench_csvs_own_units_are_converted_to_the_columns_units() {
    let base = read("plain.csv", &plain());
    let map = "[channels]\n\"Zeit [ms]\" = \"t_s\"\n\"PWM\" = \"duty_pct\"\n\"U_Batt\" = \"u_batt_V\"\n\"p_Umgebung\" = \"p_amb_kPa\"\n\"p_Tank (bar)\" = \"p_tank_kPa\"\n\"Position\" = \"x_pct\"\n";
    let mut text =
        String::from("# plant: vacuum\nZeit [ms];PWM;U_Batt;p_Umgebung;p_Tank (bar);Position\nms;%;mV;mbar;;%\n");
    for i in 0..6 {
        let i = i as f64;
        text.push_str(
            &format!(
                "{};{};{};1013.25;{};{}\n",
                2.0 * i,
                10.0 + 7.25 * i,
                13_500.0 - 125.0 * i,
                (35.0 + 1e-3 * i) / 100.0,
                -0.5 + 12.75 * i
            )
            .replace('.', ","),
        );
    }
    let log = read_mapped("bench-units.csv", &text, map).unwrap_or_else(|e| panic!("{e}"));
    for name in &base.order {
        let (a, b) = (base.col(name).unwrap(), log.col(name).unwrap());
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1e-3), "{name}: {x} vs {y}");
        }
    }
    assert!((base.dt_s - log.dt_s).abs() < 1e-15, "{} vs {}", base.dt_s, log.dt_s);
    let notice = log
        .notices
        .iter()
        .find(|n| n.starts_with("units converted"))
        .unwrap_or_else(|| panic!("{:?}", log.notices));
    for part in [
        "`t_s` from ms (÷ 1000)",
        "`p_tank_kPa` from bar (× 100)",
        "`u_batt_V` from mV (÷ 1000)",
        "`p_amb_kPa` from mbar (÷ 10)",
    ] {
        assert!(notice.contains(part), "{part}: {notice}");
    }

    // A unit of another quantity, named by its line and column.
    let bad = text.replacen("ms;%;mV;mbar;;%", "ms;%;mV;mbar;;mm", 1);
    let e = read_mapped("bad-unit.csv", &bad, map).unwrap_err();
    assert_eq!((e.line, e.column.as_deref()), (Some(3), Some("x_pct")), "{e}");
    assert!(e.message.contains("`mm` is not a unit of `x_pct`"), "{e}");
    // The name's unit and the units row disagree: which one is right the file does not say.
    let both = text.replacen("ms;%;mV;mbar;;%", "s;%;mV;mbar;;%", 1);
    let e = read_mapped("two-units.csv", &both, map).unwrap_err();
    assert_eq!((e.line, e.column.as_deref()), (Some(3), Some("t_s")), "{e}");
    assert!(e.message.contains("`Zeit [ms]` says `ms`"), "{e}");
}

/// A bench that records no units (or wrong ones): the channel map's `[units]` states them,
/// for renamed columns and DATA-FORMAT names alike, and wins over a units row (with a
/// notice). A unit that does not fit its column is refused when the map is read.
#[test]
fn a_channel_maps_units_state_what_the_file_does_not() {
    use hil_host::mf4::ChannelMap;
    let base = read("plain.csv", &plain());
    // No units row; time in ms, the tank in bar, the rest as DATA-FORMAT has them.
    let mut text = String::from("# plant: vacuum\nZeit,duty_pct,u_batt_V,p_amb_kPa,p_tank_kPa,x_pct\n");
    for i in 0..6 {
        let i = i as f64;
        text.push_str(&format!(
            "{},{},{},101.325,{},{}\n",
            2.0 * i,
            10.0 + 7.25 * i,
            13.5 - 0.125 * i,
            (35.0 + 1e-3 * i) / 100.0,
            -0.5 + 12.75 * i
        ));
    }
    let map = "[channels]\n\"Zeit\" = \"t_s\"\n\n[units]\nt_s = \"ms\"\np_tank_kPa = \"bar\"\n";
    let log = read_mapped("no-units.csv", &text, map).unwrap_or_else(|e| panic!("{e}"));
    for name in &base.order {
        for (x, y) in base.col(name).unwrap().iter().zip(log.col(name).unwrap()) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1e-3), "{name}: {x} vs {y}");
        }
    }
    let notice = log.notices.iter().find(|n| n.starts_with("units converted")).unwrap();
    assert!(
        notice.contains("`t_s` from ms (÷ 1000, as the channel map states)")
            && notice.contains("`p_tank_kPa` from bar (× 100, as the channel map states)"),
        "{notice}"
    );
    // A units row that says otherwise is overruled, and named.
    let with_row = text.replacen("x_pct\n", "x_pct\ns,%,V,kPa,kPa,%\n", 1);
    let log = read_mapped("row.csv", &with_row, map).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        log.notices
            .iter()
            .any(|n| n.contains("`p_tank_kPa` read in bar as the channel map states; the units row (line 3) says kPa")),
        "{:?}",
        log.notices
    );
    assert!((log.col("p_tank_kPa").unwrap()[0] - 35.0).abs() < 1e-12);
    // The map is checked on its own: a unit of another quantity, a column no plant has.
    let e = ChannelMap::parse("m.toml", "[units]\np_tank_kPa = \"mm\"\n").unwrap_err();
    assert_eq!(e.column.as_deref(), Some("units.p_tank_kPa"), "{e}");
    assert!(e.message.contains("`mm` is not a unit of `p_tank_kPa`"), "{e}");
    let e = ChannelMap::parse("m.toml", "[units]\nZeit = \"ms\"\n").unwrap_err();
    assert!(e.message.contains("not a DATA-FORMAT column"), "{e}");
}

/// Two more spreadsheet habits: a separator after the last column on every line, and each
/// column's unit written into its name (`t_s [s]`). Both read to the plain numbers and are
/// said; a unit in a DATA-FORMAT name that contradicts the name's suffix is refused.
#[test]
fn a_trailing_separator_and_units_in_the_column_names_read_to_the_plain_numbers() {
    let base = read("plain.csv", &plain());
    let trailing: String = plain()
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                format!("{l}\n")
            } else {
                format!("{l},\n")
            }
        })
        .collect();
    let log = read("trailing.csv", &trailing);
    same_numbers(&base, &log);
    assert!(
        normalised(&log).contains("a separator after the last column"),
        "{:?}",
        log.notices
    );

    let named = plain().replacen(
        "t_s,duty_pct,u_batt_V,p_amb_kPa,p_tank_kPa,x_pct",
        "t_s [s],duty_pct [%],u_batt_V (V),p_amb_kPa [kPa],p_tank_kPa,x_pct [%]",
        1,
    );
    let log = read("named.csv", &named);
    same_numbers(&base, &log);
    let n = normalised(&log);
    assert!(
        n.contains("units taken off the column names (`t_s [s]`, `duty_pct [%]`, `u_batt_V (V)`"),
        "{n}"
    );
    let wrong = named.replacen("p_amb_kPa [kPa]", "p_amb_kPa [bar]", 1);
    let e = error("wrong.csv", &wrong);
    assert_eq!((e.line, e.column.as_deref()), (Some(3), Some("p_amb_kPa")), "{e}");
    assert!(
        e.message.contains("`p_amb_kPa [bar]`") && e.message.contains("unit `bar`"),
        "{e}"
    );
}
