//! Recorded units against the DATA-FORMAT columns' units (the column name's suffix:
//! `p_supply_MPa`, `lift_mm`, `t_s`): which spellings mean the column's own unit, and which
//! other units a bench or logger records the same quantity in, with the exact conversion.
//!
//! Used for a CSV units row and an MF4 channel's unit (`hil-host/src/mf4.rs`). A column read
//! under a name of the bench's own (renamed by a channel map) or from a logger's channel takes
//! its values in the unit that was recorded, converted here; a column whose own name already
//! says its unit and whose recorded unit says another is a contradiction the reader refuses
//! (which of the two is right the file does not say), and an unknown spelling under it is
//! read as the name says. A channel map's `[units]` state the unit where the file records
//! none or a wrong one. Tests: each conversion against a physical identity (below),
//! `hil-host/tests/reader_dialects.rs` and `hil-host/tests/mf4.rs` through the readers.

use super::FLAGS;

/// `v · num / den + offset`: the column's value of a recorded value `v`. A ratio of two
/// numbers so that a decimal prefix divides (`v / 1000` is the correctly rounded value of a
/// millisecond count in seconds; `v · 0.001` is not always).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conversion {
    num: f64,
    den: f64,
    offset: f64,
}

impl Conversion {
    const fn times(num: f64) -> Self {
        Self {
            num,
            den: 1.0,
            offset: 0.0,
        }
    }
    const fn per(den: f64) -> Self {
        Self {
            num: 1.0,
            den,
            offset: 0.0,
        }
    }

    /// The column's value of the recorded value `v`.
    pub fn apply(&self, v: f64) -> f64 {
        v * self.num / self.den + self.offset
    }

    /// How a notice writes it: `× 0.1`, `÷ 1000`, `− 273.15`.
    pub fn describe(&self) -> String {
        let mut s = Vec::new();
        if self.num != 1.0 {
            s.push(format!("× {}", self.num));
        }
        if self.den != 1.0 {
            s.push(format!("÷ {}", self.den));
        }
        if self.offset != 0.0 {
            s.push(format!(
                "{} {}",
                if self.offset < 0.0 { "−" } else { "+" },
                self.offset.abs()
            ));
        }
        s.join(" ")
    }
}

/// What a recorded unit means for a column.
#[derive(Clone, Copy, Debug, PartialEq)]
enum UnitFit {
    /// The column's own unit (or no unit recorded).
    Same,
    /// Another unit of the same quantity: the values are converted.
    Convert(Conversion),
    /// A unit of another quantity (`mm` under `x_pct`): not readable as the column.
    Foreign,
    /// A spelling no table knows (`kpa`, `percent`).
    Unknown,
}

/// How a column's values are read, given the unit recorded for them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reading {
    /// In the column's own unit (also where none was recorded).
    Own,
    /// Converted from another unit of the quantity.
    Convert(Conversion),
    /// An unrecognised spelling under the column's own name, which states the unit: read in
    /// that unit, with a notice.
    Assumed,
}

/// How `column` recorded in `unit` is read. Another unit of the quantity converts only where
/// the column is read under a name of the bench's or logger's own (`renamed`); under its
/// DATA-FORMAT name, whose suffix states the unit, another known unit contradicts it, and an
/// unknown spelling is taken to mean what the name says. A unit of another quantity, or an
/// unknown one on a renamed column (whose scale nothing states), is an error.
pub fn reading(column: &str, unit: &str, renamed: bool) -> Result<Reading, String> {
    // A clock format (`hh:mm:ss.ms`, `dd.mm.yyyy hh:mm:ss`) under the time column: its cells
    // are clock time stamps, which the CSV reader reads as the seconds since the first.
    if column == "t_s" && is_clock_format(unit) {
        return Ok(Reading::Own);
    }
    match fit(column, unit) {
        UnitFit::Same => Ok(Reading::Own),
        UnitFit::Convert(c) if renamed => Ok(Reading::Convert(c)),
        UnitFit::Unknown if !renamed => Ok(Reading::Assumed),
        UnitFit::Convert(_) => Err(format!(
            "unit `{unit}`, but the column's name says {} (a column the channel map renames from the bench's own name is converted from the unit it was recorded in)",
            own_units(column)
        )),
        UnitFit::Foreign => Err(format!(
            "unit `{unit}` is not a unit of `{column}` (it takes {})",
            accepted(column)
        )),
        UnitFit::Unknown => Err(format!(
            "unit `{unit}` of the renamed column `{column}` is not one the reader knows (it takes {})",
            accepted(column)
        )),
    }
}

/// Whether `unit` spells a clock time's format: `hh:mm:ss`, `HH:MM:SS.mmm`, `yyyy-mm-dd
/// hh:mm:ss`, `dd.mm.yyyy` (any case).
fn is_clock_format(unit: &str) -> bool {
    let u = unit.to_ascii_lowercase();
    u.contains("hh:mm") || u.contains("yyyy")
}

/// The units a column with this unit suffix is read in: the spellings of its own unit, and
/// the other units of the quantity with their conversions. `None` for a name without a
/// known suffix (nothing is checked).
struct UnitTable {
    same: &'static [&'static str],
    other: &'static [(&'static str, Conversion)],
}

const PSI_IN_KPA: f64 = 6.894_757_293_168_361;
const KELVIN: Conversion = Conversion {
    num: 1.0,
    den: 1.0,
    offset: -273.15,
};
const FAHRENHEIT: Conversion = Conversion {
    num: 5.0,
    den: 9.0,
    offset: -160.0 / 9.0,
};

/// Per unit suffix of a column name: its own unit's spellings, other units with conversions.
const TABLES: &[(&str, UnitTable)] = &[
    (
        "s",
        UnitTable {
            same: &["s", "sec"],
            other: &[
                ("ms", Conversion::per(1e3)),
                ("us", Conversion::per(1e6)),
                ("µs", Conversion::per(1e6)),
                ("ns", Conversion::per(1e9)),
            ],
        },
    ),
    (
        "pct",
        UnitTable {
            same: &["%", "pct", "percent"],
            other: &[],
        },
    ),
    (
        "V",
        UnitTable {
            same: &["V"],
            other: &[("mV", Conversion::per(1e3))],
        },
    ),
    (
        "kPa",
        UnitTable {
            same: &["kPa"],
            other: &[
                ("Pa", Conversion::per(1e3)),
                ("hPa", Conversion::per(10.0)),
                ("mbar", Conversion::per(10.0)),
                ("bar", Conversion::times(100.0)),
                ("MPa", Conversion::times(1e3)),
                ("psi", Conversion::times(PSI_IN_KPA)),
            ],
        },
    ),
    (
        "MPa",
        UnitTable {
            same: &["MPa"],
            other: &[
                ("bar", Conversion::per(10.0)),
                ("kPa", Conversion::per(1e3)),
                ("Pa", Conversion::per(1e6)),
                ("mbar", Conversion::per(1e4)),
                (
                    "psi",
                    Conversion {
                        num: PSI_IN_KPA,
                        den: 1e3,
                        offset: 0.0,
                    },
                ),
            ],
        },
    ),
    (
        "C",
        UnitTable {
            same: &["C", "°C", "℃", "degC", "deg C"],
            other: &[("K", KELVIN), ("°F", FAHRENHEIT), ("degF", FAHRENHEIT)],
        },
    ),
    (
        "mm",
        UnitTable {
            same: &["mm"],
            other: &[
                ("m", Conversion::times(1e3)),
                ("cm", Conversion::times(10.0)),
                ("um", Conversion::per(1e3)),
                ("µm", Conversion::per(1e3)),
            ],
        },
    ),
    (
        "m",
        UnitTable {
            same: &["m"],
            other: &[
                ("mm", Conversion::per(1e3)),
                ("cm", Conversion::per(100.0)),
                ("um", Conversion::per(1e6)),
                ("µm", Conversion::per(1e6)),
            ],
        },
    ),
    (
        "deg",
        UnitTable {
            same: &["deg", "°", "°CA", "degCA", "deg CA", "°KW"],
            other: &[(
                "rad",
                Conversion {
                    num: 180.0,
                    den: core::f64::consts::PI,
                    offset: 0.0,
                },
            )],
        },
    ),
    (
        "rpm",
        UnitTable {
            same: &["rpm", "1/min", "min^-1", "min-1", "U/min", "r/min", "rev/min"],
            other: &[(
                "rad/s",
                Conversion {
                    num: 30.0,
                    den: core::f64::consts::PI,
                    offset: 0.0,
                },
            )],
        },
    ),
    (
        "N",
        UnitTable {
            same: &["N"],
            other: &[("kN", Conversion::times(1e3))],
        },
    ),
];

const FLAG_UNITS: UnitTable = UnitTable {
    same: &["-", "1", "0/1", "bool", "flag"],
    other: &[],
};

fn table(column: &str) -> Option<&'static UnitTable> {
    if FLAGS.contains(&column) {
        return Some(&FLAG_UNITS);
    }
    let (_, suffix) = column.rsplit_once('_')?;
    TABLES.iter().find(|(s, _)| *s == suffix).map(|(_, t)| t)
}

/// A recorded unit without its brackets and blanks: `[kPa]` and `(kPa)` are `kPa`.
pub fn bare(cell: &str) -> &str {
    let s = cell.trim();
    for (open, close) in [('[', ']'), ('(', ')')] {
        if let Some(inner) = s.strip_prefix(open).and_then(|r| r.strip_suffix(close)) {
            return inner.trim();
        }
    }
    s
}

/// What the recorded `unit` (brackets and blanks already removed) means for `column`. An
/// empty unit, or a column without a known unit suffix, is [`UnitFit::Same`].
fn fit(column: &str, unit: &str) -> UnitFit {
    let Some(t) = table(column) else {
        return UnitFit::Same;
    };
    if unit.is_empty() || t.same.contains(&unit) {
        return UnitFit::Same;
    }
    if let Some((_, c)) = t.other.iter().find(|(u, _)| *u == unit) {
        return UnitFit::Convert(*c);
    }
    let known = |t: &UnitTable| t.same.contains(&unit) || t.other.iter().any(|(u, _)| *u == unit);
    if known(&FLAG_UNITS) || TABLES.iter().any(|(_, t)| known(t)) {
        UnitFit::Foreign
    } else {
        UnitFit::Unknown
    }
}

/// What a reader did with the recorded units, for its notices: the columns it converted and
/// the unknown spellings it read as their columns' names say.
#[derive(Debug, Default)]
pub struct UnitNotes {
    converted: Vec<String>,
    assumed: Vec<String>,
}

impl UnitNotes {
    /// `what` (`` `t_s` ``, a master channel) was converted from `unit` by `c`; `why` is added
    /// to the conversion's description (`, as the channel map states`).
    pub fn converted(&mut self, what: &str, unit: &str, c: &Conversion, why: &str) {
        self.converted
            .push(format!("{what} from {unit} ({}{why})", c.describe()));
    }

    /// `column`'s unknown unit `unit` was read as its name says.
    pub fn assumed(&mut self, column: &str, unit: &str) {
        self.assumed.push(format!("`{unit}` under `{column}`"));
    }

    /// Forgets what was noted of `column` (a unit the channel map states replaces it).
    pub fn forget(&mut self, column: &str) {
        let head = format!("`{column}` from ");
        self.converted.retain(|c| !c.starts_with(&head));
    }

    /// The notices: one for the conversions, one for the assumed units, each if any.
    pub fn into_notices(self) -> impl Iterator<Item = String> {
        let converted = (!self.converted.is_empty()).then(|| {
            format!(
                "units converted to the DATA-FORMAT columns' units: {}",
                self.converted.join(", ")
            )
        });
        let assumed = (!self.assumed.is_empty()).then(|| {
            format!(
                "unit(s) not recognised, read in the unit the column's name states: {}",
                self.assumed.join(", ")
            )
        });
        converted.into_iter().chain(assumed)
    }
}

/// The column's own unit spellings, for messages.
fn own_units(column: &str) -> String {
    table(column).map_or_else(|| "any unit".into(), |t| format!("`{}`", t.same.join("` or `")))
}

/// For messages: the column's own unit spellings, and the units it converts from.
pub fn accepted(column: &str) -> String {
    match table(column) {
        None => "any unit".into(),
        Some(t) => {
            let same = own_units(column);
            if t.other.is_empty() {
                same
            } else {
                let mut other: Vec<&str> = t.other.iter().map(|(u, _)| *u).collect();
                other.dedup();
                format!("{same}, or converted from `{}`", other.join("`, `"))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn convert(column: &str, unit: &str, v: f64) -> f64 {
        match fit(column, unit) {
            UnitFit::Convert(c) => c.apply(v),
            other => panic!("{column} in {unit}: {other:?}"),
        }
    }

    #[test]
    fn each_conversion_gives_the_columns_unit() {
        // Physical identities, not the table's numbers read back.
        let cases = [
            ("p_supply_MPa", "bar", 72.0, 7.2),
            ("p_supply_MPa", "kPa", 7200.0, 7.2),
            ("p_supply_MPa", "Pa", 7.2e6, 7.2),
            ("p_supply_MPa", "psi", 1000.0, 6.894_757_293),
            ("p_amb_kPa", "bar", 1.013, 101.3),
            ("p_amb_kPa", "mbar", 1013.0, 101.3),
            ("p_amb_kPa", "hPa", 1013.0, 101.3),
            ("p_amb_kPa", "MPa", 0.1013, 101.3),
            ("p_amb_kPa", "psi", 14.695_948_775_5, 101.325),
            ("t_s", "ms", 2.5, 0.0025),
            ("t_s", "µs", 50.0, 5e-5),
            ("lift_mm", "m", 0.0075, 7.5),
            ("lift_mm", "µm", 7500.0, 7.5),
            ("pos_m", "mm", 12.5, 0.0125),
            ("phase_deg", "rad", core::f64::consts::FRAC_PI_2, 90.0),
            ("motor_cmd_rpm", "rad/s", 2.0 * core::f64::consts::PI, 60.0),
            ("temp_C", "K", 373.15, 100.0),
            ("temp_C", "°F", 212.0, 100.0),
            ("temp_C", "degF", -40.0, -40.0),
            ("u_batt_V", "mV", 13_500.0, 13.5),
            ("force_N", "kN", 0.25, 250.0),
        ];
        for (column, unit, recorded, want) in cases {
            let got = convert(column, unit, recorded);
            assert!(
                (got - want).abs() <= 1e-9 * want.abs(),
                "{column} from {recorded} {unit}: {got}"
            );
        }
    }

    #[test]
    fn a_decimal_prefix_divides_exactly() {
        // 1 ms steps in ms are the same numbers as the seconds a DATA-FORMAT log writes.
        for k in 0..10_000 {
            let ms = k as f64;
            assert_eq!(convert("t_s", "ms", ms), ms / 1000.0);
        }
    }

    #[test]
    fn own_spellings_are_the_same_and_strangers_are_foreign() {
        assert_eq!(fit("p_supply_MPa", "MPa"), UnitFit::Same);
        assert_eq!(fit("p_supply_MPa", ""), UnitFit::Same);
        assert_eq!(fit("temp_C", "°C"), UnitFit::Same);
        assert_eq!(fit("u_pilot", "-"), UnitFit::Same);
        // SI prefixes are case-sensitive: millipascal is not megapascal.
        assert_eq!(fit("p_supply_MPa", "mpa"), UnitFit::Unknown);
        assert_eq!(fit("p_amb_kPa", "kpa"), UnitFit::Unknown);
        assert_eq!(fit("lift_mm", "V"), UnitFit::Foreign);
        assert_eq!(fit("u_pilot", "V"), UnitFit::Foreign);
        // A percentage is not guessed from a ratio ("1" or "-" could be either).
        assert_eq!(fit("x_pct", "1"), UnitFit::Foreign);
        // Under the column's own name an unknown spelling means what the name says; renamed,
        // nothing states the scale.
        assert_eq!(reading("p_amb_kPa", "kpa", false), Ok(Reading::Assumed));
        assert!(reading("p_amb_kPa", "kpa", true)
            .unwrap_err()
            .contains("not one the reader knows"));
        assert!(reading("p_amb_kPa", "bar", false)
            .unwrap_err()
            .contains("name says `kPa`"));
        assert_eq!(
            reading("p_amb_kPa", "bar", true),
            Ok(Reading::Convert(Conversion::times(100.0)))
        );
        assert!(reading("lift_mm", "V", false)
            .unwrap_err()
            .contains("not a unit of `lift_mm`"));
        // A name without a unit suffix checks nothing.
        assert_eq!(fit("whatever", "furlong"), UnitFit::Same);
        let a = accepted("p_supply_MPa");
        assert!(a.starts_with("`MPa`, or converted from `bar`"), "{a}");
    }

    #[test]
    fn a_clock_format_under_the_time_column_is_read_as_its_stamps() {
        for (unit, renamed) in [
            ("hh:mm:ss.ms", true),
            ("DD.MM.YYYY hh:mm:ss,sss", false),
            ("[HH:MM:SS]", true),
        ] {
            assert!(
                matches!(reading("t_s", bare(unit), renamed), Ok(Reading::Own)),
                "{unit}"
            );
        }
        assert!(reading("p_supply_MPa", "hh:mm:ss", true).is_err());
        assert!(reading("t_s", "hh", true).is_err());
    }

    #[test]
    fn a_conversion_says_what_it_does() {
        let d = |c: &str, u: &str| match fit(c, u) {
            UnitFit::Convert(c) => c.describe(),
            other => panic!("{other:?}"),
        };
        assert_eq!(d("p_supply_MPa", "bar"), "÷ 10");
        assert_eq!(d("p_amb_kPa", "bar"), "× 100");
        assert_eq!(d("temp_C", "K"), "− 273.15");
    }
}
