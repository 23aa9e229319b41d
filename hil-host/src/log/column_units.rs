//! The units of a CSV log's columns: in a bench's own column names (`Zeit [ms]`), in the
//! DATA-FORMAT names (`t_s [s]`), in the channel map's `[units]` and in a units row, and the
//! conversions they imply (the unit table is [`super::units`]).

use super::units::{reading, Conversion, Reading, UnitNotes};
use super::{LogError, Plant};

/// The unit a bench writes into its own column name, `Zeit [ms]` or `p_Rail (bar)`: the
/// text of a trailing bracket pair, if any.
pub(super) fn unit_in_name(name: &str) -> Option<&str> {
    split_unit(name).map(|(_, unit)| unit)
}

/// A name with a unit in a trailing bracket pair split into (the name before it, the unit).
fn split_unit(name: &str) -> Option<(&str, &str)> {
    let s = name.trim_end();
    let (open, close) = match s.chars().last()? {
        ']' => ('[', ']'),
        ')' => ('(', ')'),
        _ => return None,
    };
    let at = s.rfind(open)?;
    let inner = s[at + open.len_utf8()..s.len() - close.len_utf8()].trim();
    Some((s[..at].trim_end(), inner)).filter(|(_, u)| !u.is_empty())
}

/// Columns whose names carry their unit, `t_s [s]`, `lift_mm (mm)`: the DATA-FORMAT name with
/// the unit taken off (where the header has not that name already), and the units, per header
/// column.
pub(super) fn units_off_names(plant: Plant, mut names: Vec<String>) -> (Vec<String>, Vec<Option<String>>) {
    let known: Vec<&str> = plant.column_names().collect();
    let mut unit_named: Vec<Option<String>> = vec![None; names.len()];
    for i in 0..names.len() {
        let Some((bare, unit)) =
            split_unit(&names[i]).filter(|(b, _)| !known.contains(&names[i].as_str()) && known.contains(b))
        else {
            continue;
        };
        if names.iter().any(|n| n == bare) {
            continue;
        }
        let (bare, unit) = (bare.to_string(), unit.to_string());
        unit_named[i] = Some(unit);
        names[i] = bare;
    }
    (names, unit_named)
}

/// How each kept column's recorded values become the column's, per slot of the selection:
/// from a unit in the column's name, the channel map's `[units]` (which win) and the units
/// row, whichever the file and the map give.
pub(super) struct ColumnUnits {
    pub(super) conversions: Vec<Option<Conversion>>,
    /// The unit the header or the map states for the slot: a units row is checked against it.
    recorded: Vec<Option<String>>,
    /// Whether the map states it (a units row that says otherwise is overruled, with a notice).
    stated: Vec<bool>,
    pub(super) notes: UnitNotes,
}

impl ColumnUnits {
    /// From the header: `original` and `renamed` per header column (the file's names, and
    /// whether the channel map renamed them), `unit_named` from [`units_off_names`], `map_units`
    /// the map's `[units]`. `err` names a column's error.
    pub(super) fn from_header(
        sel: &super::check::Selection,
        original: &[String],
        renamed: &[bool],
        unit_named: &[Option<String>],
        map_units: &[(String, String)],
        err: impl Fn(&str, String) -> LogError,
    ) -> Result<Self, LogError> {
        let n = sel.order.len();
        let mut u = ColumnUnits {
            conversions: vec![None; n],
            recorded: vec![None; n],
            stated: vec![false; n],
            notes: UnitNotes::default(),
        };
        for (i, slot) in sel.keep.iter().enumerate() {
            let Some(slot) = *slot else { continue };
            let column = &sel.order[slot];
            let (unit, renamed) = match (&unit_named[i], renamed[i]) {
                // The DATA-FORMAT name with its unit: the name states the unit, as without it.
                (Some(unit), _) => (unit.as_str(), false),
                // Renamed by the map from the bench's own name, which may carry the unit.
                (None, true) => match unit_in_name(&original[i]) {
                    Some(unit) => (unit, true),
                    None => continue,
                },
                (None, false) => continue,
            };
            match reading(column, unit, renamed).map_err(|m| err(column, format!("column `{}`: {m}", original[i])))? {
                Reading::Own => {}
                Reading::Convert(c) => {
                    u.conversions[slot] = Some(c);
                    u.notes.converted(&format!("`{column}`"), unit, &c, "");
                }
                Reading::Assumed => u.notes.assumed(column, unit),
            }
            u.recorded[slot] = Some(unit.to_string());
        }
        for (column, unit) in map_units {
            let Some(slot) = sel.order.iter().position(|c| c == column) else {
                continue;
            };
            u.notes.forget(column);
            // Checked when the map was read.
            u.conversions[slot] = match reading(column, unit, true) {
                Ok(Reading::Convert(c)) => {
                    u.notes
                        .converted(&format!("`{column}`"), unit, &c, ", as the channel map states");
                    Some(c)
                }
                _ => None,
            };
            u.recorded[slot] = Some(unit.clone());
            u.stated[slot] = true;
        }
        Ok(u)
    }

    /// A units row's (on `line`) `unit` under the column `name` (slot `slot`, the header's
    /// `original` name, renamed by the map or not): checked against what the header or the map
    /// state, else read. A notice where the map overrules it.
    pub(super) fn units_row_cell(
        &mut self,
        (slot, name, original): (usize, &str, &str),
        unit: &str,
        renamed: bool,
        line: usize,
    ) -> Result<Option<String>, String> {
        if let Some(recorded) = &self.recorded[slot] {
            return match (self.stated[slot], recorded == unit) {
                (_, true) => Ok(None),
                (true, false) => Ok(Some(format!(
                    "`{name}` read in {recorded} as the channel map states; the units row (line {line}) says {unit}"
                ))),
                (false, false) => Err(format!(
                    "unit `{unit}` in the units row, but the column's name `{original}` says `{recorded}`"
                )),
            };
        }
        match reading(name, unit, renamed).map_err(|m| format!("units row: {m}"))? {
            Reading::Own => {}
            Reading::Convert(c) => {
                self.conversions[slot] = Some(c);
                self.notes.converted(&format!("`{name}`"), unit, &c, "");
            }
            Reading::Assumed => self.notes.assumed(name, unit),
        }
        Ok(None)
    }
}
