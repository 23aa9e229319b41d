//! ASAM MDF 4 (`.mf4`) logs, as loggers (ETAS, Vector, CSS, IPEtronik) record them and asammdf
//! exports them, read into the same [`Log`] as a DATA-FORMAT CSV file.
//!
//! The file format itself (blocks ID, HD, DG, CG, CN, CC, TX/MD, DT, DL, DZ, HL; deflate and
//! transposed deflate) is decoded by the `falcon_mdf` crate, which is made for reading MF4,
//! checked by its authors against asammdf, and returns an error rather than partial data on a
//! malformed file (docs/data-format.md says why it was chosen). This module maps what the
//! file holds onto the log contract:
//!
//! - Channels are found by their DATA-FORMAT names (`phase_deg`), or renamed from the logger's
//!   names by a [`ChannelMap`] (`"ECU.PhaseCam_deg" = "phase_deg"`).
//! - Metadata (`plant`, bench constants such as `kp`) come from the header comment: `key: value`
//!   lines of its text (a leading `#` allowed, as in the CSV), or `<common_properties>` entries
//!   `<e name="kp">25</e>`; the map file's `[meta]` adds to them and wins over them.
//! - Units: a channel's unit (its CN block's) is checked against the column's and converted
//!   where the channel is the logger's own (`crate::log::units`); the map's `[units]` win.
//! - The time base is the master channel of the channel group that holds the primary output.
//!   Columns recorded in other channel groups (other rates) are resampled onto it: linearly for
//!   continuous signals, by zero-order hold (the last value at or before each instant) for 0/1
//!   flags; a notice says which columns, from which rate, and how.
//! - Samples the logger marked invalid (invalidation bits) are filled from the channel's valid
//!   ones; a flag recorded with a value-to-text conversion (`OFF`/`ON`) reads as 0/1.
//! - The columns then go through the CSV reader's checks (`crate::log::log_from_columns`:
//!   typed metadata, ranges, flags, uniform and increasing time, required columns), so an MF4
//!   log and a CSV log of the same samples give the same [`Log`], bit for bit. Errors name the
//!   file and the channel (and the sample index where one sample is at fault).

use std::collections::BTreeMap;
use std::path::Path;

use falcon_mdf::{Channel, Mf4File, SignalValues};

use crate::log::units::{self, reading, Reading, UnitNotes};
use crate::log::{log_from_columns, Log, LogError, Plant, FLAGS};
use crate::signal::{fill_gaps, resample};

/// True when `path` names an MF4 file: the `.mf4`/`.mdf` extension, or the MDF identification
/// block's signature at the start of the file (a logger's file renamed to `.dat`).
pub fn is_mf4(path: &Path) -> bool {
    let by_name = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("mf4") || e.eq_ignore_ascii_case("mdf"));
    by_name || has_mdf_signature(path)
}

fn has_mdf_signature(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && (&head == b"MDF     " || &head == b"UnFinMF ")
}

/// A channel map: the logger's channel names renamed to DATA-FORMAT column names, and metadata
/// and units the file does not carry. Read from a small TOML file (`--channel-map FILE`):
///
/// ```toml
/// [channels]
/// "ECU.PhaseCam_deg" = "phase_deg"
/// "ECU.CamCmd" = "motor_cmd_rpm"
///
/// [meta]
/// plant = "evvt"
/// kp = 25
///
/// [units]
/// phase_deg = "rad"
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChannelMap {
    /// The map file, for messages.
    pub file: String,
    /// (logger channel name, DATA-FORMAT column name), sorted by channel name.
    pub channels: Vec<(String, String)>,
    /// Metadata `key = value` (numbers and booleans as their text), sorted by key.
    pub meta: Vec<(String, String)>,
    /// (DATA-FORMAT column name, the unit its values were recorded in), sorted by column: for
    /// a log that records no units, or wrong ones. Stated here, a unit wins over the file's.
    pub units: Vec<(String, String)>,
}

impl ChannelMap {
    /// Reads a map file; errors name the file, line and column (or key).
    pub fn read(path: &Path) -> Result<ChannelMap, LogError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| LogError {
            file: file.clone(),
            line: None,
            column: None,
            message: format!("cannot read the channel map: {e}"),
        })?;
        ChannelMap::parse(&file, &text)
    }

    /// Parses map text; `file` names it in errors.
    pub fn parse(file: &str, text: &str) -> Result<ChannelMap, LogError> {
        let err = |line: Option<usize>, column: Option<String>, message: String| LogError {
            file: file.to_string(),
            line,
            column,
            message,
        };
        let table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
            let (line, col) = e
                .span()
                .map(|s| line_col(text, s.start))
                .map_or((None, None), |(l, c)| (Some(l), Some(format!("{c}"))));
            err(line, col, format!("not valid TOML: {}", e.message()))
        })?;
        let mut map = ChannelMap {
            file: file.to_string(),
            ..ChannelMap::default()
        };
        // `t_s` too: a bench's CSV names its time column its own way (an MF4 file's time is
        // its master channel's, whatever the map says).
        let known_columns: Vec<&str> = Plant::ALL.iter().flat_map(|p| p.column_names()).collect();
        for (section, value) in &table {
            let toml::Value::Table(entries) = value else {
                return Err(err(
                    None,
                    Some(section.clone()),
                    format!("`{section}` must be a table ([channels], [meta] or [units])"),
                ));
            };
            match section.as_str() {
                "channels" => {
                    for (from, to) in entries {
                        let toml::Value::String(to) = to else {
                            return Err(err(
                                None,
                                Some(format!("channels.\"{from}\"")),
                                "the column name must be a string".into(),
                            ));
                        };
                        if !known_columns.contains(&to.as_str()) {
                            return Err(err(
                                None,
                                Some(format!("channels.\"{from}\"")),
                                format!("`{to}` is not a DATA-FORMAT column of any plant"),
                            ));
                        }
                        if let Some((other, _)) = map.channels.iter().find(|(_, t)| t == to) {
                            return Err(err(
                                None,
                                Some(format!("channels.\"{from}\"")),
                                format!("column `{to}` is already mapped from channel `{other}`"),
                            ));
                        }
                        map.channels.push((from.clone(), to.clone()));
                    }
                }
                "meta" => {
                    for (key, v) in entries {
                        let v = match v {
                            toml::Value::String(s) => s.clone(),
                            toml::Value::Integer(i) => i.to_string(),
                            toml::Value::Float(f) => f.to_string(),
                            toml::Value::Boolean(b) => b.to_string(),
                            _ => {
                                return Err(err(
                                    None,
                                    Some(format!("meta.{key}")),
                                    "a metadata value must be a string, number or boolean".into(),
                                ))
                            }
                        };
                        map.meta.push((key.clone(), v));
                    }
                }
                "units" => {
                    for (column, unit) in entries {
                        let key = Some(format!("units.{column}"));
                        let toml::Value::String(unit) = unit else {
                            return Err(err(None, key, "the unit must be a string".into()));
                        };
                        if !known_columns.contains(&column.as_str()) {
                            return Err(err(
                                None,
                                key,
                                format!("`{column}` is not a DATA-FORMAT column of any plant"),
                            ));
                        }
                        reading(column, units::bare(unit), true).map_err(|m| err(None, key, m))?;
                        map.units.push((column.clone(), units::bare(unit).to_string()));
                    }
                }
                _ => {
                    return Err(err(
                        None,
                        Some(section.clone()),
                        format!("unknown section `[{section}]` (known: [channels], [meta], [units])"),
                    ))
                }
            }
        }
        Ok(map)
    }

    /// The unit the map states for `column`'s recorded values, if any.
    pub fn unit_of(&self, column: &str) -> Option<&str> {
        self.units.iter().find(|(c, _)| c == column).map(|(_, u)| u.as_str())
    }

    /// The column a logger channel is read as: its mapped name, else its own name.
    fn column_of<'a>(&'a self, channel: &'a str) -> &'a str {
        self.channels
            .iter()
            .find(|(from, _)| from == channel)
            .map_or(channel, |(_, to)| to.as_str())
    }
}

/// 1-based line and column of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Metadata from the header comment: `key: value` lines of its text and `<common_properties>`.
fn header_meta(mdf: &Mf4File) -> Vec<(String, String)> {
    let mut meta: Vec<(String, String)> = Vec::new();
    let mut put = |k: &str, v: &str| {
        let k = k.trim();
        // A key is one word (the CSV's keys are identifiers); prose with a colon is not metadata.
        if !k.is_empty() && !k.contains(char::is_whitespace) && !meta.iter().any(|(m, _)| m == k) {
            meta.push((k.to_string(), v.trim().replace(['\n', '\r'], " ")));
        }
    };
    let text = if mdf.metadata().text().is_empty() {
        mdf.comment()
    } else {
        mdf.metadata().text()
    };
    for line in text.lines() {
        if let Some((k, v)) = line.trim().trim_start_matches('#').split_once(':') {
            put(k, v);
        }
    }
    for (k, v) in mdf.metadata().properties() {
        put(k, v);
    }
    meta
}

/// The time stamps of `ch`'s channel group in seconds: its master channel's values, converted
/// from the master's unit (`s`, or `ms`, `us`, `ns` as some loggers record it; a note of the
/// conversion goes to `notes`; a `t_s` unit in the channel `map` wins). The error
/// completes "time base ...".
fn timestamps(mdf: &Mf4File, ch: &Channel, map: &ChannelMap, notes: &mut UnitNotes) -> Result<Vec<f64>, String> {
    let mut t = mdf.channel_timestamps(ch).map_err(|e| format!("unreadable: {e}"))?;
    let Some(master) = mdf.master_channel(ch.data_group_index, ch.channel_group_index) else {
        return Ok(t);
    };
    // The map's `t_s` unit wins over the master's own.
    let unit = map.unit_of("t_s").unwrap_or(units::bare(&master.unit));
    let read = reading("t_s", unit, true).map_err(|m| format!("(master channel `{}`): {m}", master.name))?;
    if let Reading::Convert(c) = read {
        t.iter_mut().for_each(|v| *v = c.apply(*v));
        notes.converted(&format!("time (master channel `{}`)", master.name), unit, &c, "");
    }
    Ok(t)
}

/// Reads an MF4 log. `plant` overrides the file's `plant` metadata; `map` renames channels and
/// adds metadata.
pub fn read_mf4(path: &Path, plant: Option<Plant>, map: Option<&ChannelMap>) -> Result<Log, LogError> {
    let file = path.display().to_string();
    let err = |column: Option<String>, message: String| LogError {
        file: file.clone(),
        line: None,
        column,
        message,
    };
    let bytes = std::fs::read(path).map_err(|e| err(None, format!("cannot read: {e}")))?;
    let mdf = Mf4File::from_bytes(bytes).map_err(|e| err(None, format!("not a readable MF4 file: {e}")))?;
    let empty = ChannelMap::default();
    let map = map.unwrap_or(&empty);
    let mut notices = Vec::new();

    // Metadata: the header comment, then the map file's (which wins).
    let mut meta = header_meta(&mdf);
    for (k, v) in &map.meta {
        match meta.iter_mut().find(|(m, _)| m == k) {
            Some(slot) if slot.1 != *v => {
                notices.push(format!(
                    "metadata `{k}`: the channel map's `{v}` replaces the file's `{}`",
                    slot.1
                ));
                slot.1 = v.clone();
            }
            Some(_) => {}
            None => meta.push((k.clone(), v.clone())),
        }
    }
    let plant = match plant {
        Some(p) => p,
        None => {
            let name = meta
                .iter()
                .find(|(k, _)| k == "plant")
                .map(|(_, v)| v.clone())
                .ok_or_else(|| {
                    err(
                        None,
                        "no `plant` in the header comment or the channel map's [meta], and no plant given (--plant)"
                            .into(),
                    )
                })?;
            Plant::from_name(&name).ok_or_else(|| {
                err(
                    None,
                    format!("unknown plant `{name}` in metadata (known: vacuum, ehvva, evvt, positioner)"),
                )
            })?
        }
    };

    // Every non-master channel under the column name it is read as.
    let mut by_column: BTreeMap<&str, Vec<&Channel>> = BTreeMap::new();
    let mut ignored: Vec<&str> = Vec::new();
    let wanted: Vec<&str> = plant.columns().iter().map(|(n, _)| *n).collect();
    let mut device_suffixed: Vec<String> = Vec::new();
    for ch in mdf.channels().filter(|c| !c.is_master()) {
        let mut column = map.column_of(&ch.name);
        if !wanted.contains(&column) {
            // ETK/XCP measurement tools (INCA, CANape) name a signal after the device that
            // measured it, `Name\Device` (`lift_mm\ETKC:1`): the name before the backslash.
            if let Some((bare, _)) = ch.name.split_once('\\') {
                let c = map.column_of(bare);
                if wanted.contains(&c) {
                    column = c;
                    device_suffixed.push(format!("`{}` as `{c}`", ch.name));
                }
            }
        }
        if wanted.contains(&column) {
            by_column.entry(column).or_default().push(ch);
        } else {
            ignored.push(&ch.name);
        }
    }
    if !device_suffixed.is_empty() {
        notices.push(format!(
            "channel(s) read by their name before the measuring device's `\\` suffix: {}",
            device_suffixed.join(", ")
        ));
    }
    if !ignored.is_empty() {
        notices.push(format!(
            "channel(s) {} are not `{plant}` columns; ignored",
            ignored.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", ")
        ));
    }
    for (from, to) in &map.channels {
        if wanted.contains(&to.as_str()) && !mdf.channels().any(|c| c.name == *from) {
            notices.push(format!(
                "channel map {}: channel `{from}` (for `{to}`) is not in the file",
                map.file
            ));
        }
    }
    let describe = |column: &str, ch: &Channel| {
        if ch.name == column {
            format!("channel `{}`", ch.name)
        } else {
            format!("channel `{}` (mapped to `{column}`)", ch.name)
        }
    };

    // The time base: the master of the primary output's channel group.
    let primary = plant.primary_output();
    let primary_ch = match by_column.get(primary).map(Vec::as_slice) {
        Some([ch]) => *ch,
        Some(several) => {
            return Err(err(
                Some(primary.into()),
                format!(
                "the primary output is in {} channel groups ({}); keep one, or rename the others in the channel map",
                several.len(),
                several
                    .iter()
                    .map(|c| describe(primary, c))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            ))
        }
        None => return Err(missing(&file, &mdf, map, primary, plant)),
    };
    let group = (primary_ch.data_group_index, primary_ch.channel_group_index);
    let mut unit_notes = UnitNotes::default();
    let t_s = timestamps(&mdf, primary_ch, map, &mut unit_notes).map_err(|m| {
        err(
            Some(primary.into()),
            format!("{}: time base {m}", describe(primary, primary_ch)),
        )
    })?;
    if mdf.data_groups()[group.0].channel_groups[group.1]
        .master_channel()
        .is_none()
    {
        return Err(err(
            Some(primary.into()),
            format!(
                "{}: its channel group has no master (time) channel",
                describe(primary, primary_ch)
            ),
        ));
    }

    // A logger's time stamps jitter (event-driven rasters, bus timing): the columns go onto a
    // uniform grid, as DATA-FORMAT's log is sampled; a gap the grid would bridge is left to the
    // uniformity check below, which names it.
    let uniform = uniform_grid(&t_s);
    if let Some((grid, jitter)) = &uniform {
        notices.push(format!(
            "`{primary}`'s channel group is not uniformly sampled: {jitter}; every column resampled onto a uniform {} Hz grid from its first time stamp ({} samples), signals by linear interpolation, flags by zero-order hold",
            fmt_hz(rate_hz(grid)),
            grid.len()
        ));
    }
    let base: &[f64] = uniform.as_ref().map_or(&t_s, |(grid, _)| grid);
    let mut columns: Vec<(String, Vec<f64>)> = vec![("t_s".into(), base.to_vec())];
    let mut resampled: Vec<String> = Vec::new();
    let mut channel_notes: Vec<String> = Vec::new();
    for (column, _) in plant.columns() {
        let Some(found) = by_column.get(column) else {
            continue; // A missing required column is the CSV check's error below.
        };
        // One channel per column: the one in the primary group when the name is in several.
        let ch = match found.as_slice() {
            [ch] => *ch,
            several => match several
                .iter()
                .find(|c| (c.data_group_index, c.channel_group_index) == group)
            {
                Some(ch) => {
                    notices.push(format!(
                        "column `{column}` is in {} channel groups; the one in the primary output's group is read",
                        several.len()
                    ));
                    *ch
                }
                None => {
                    return Err(err(
                        Some((*column).into()),
                        format!(
                        "in {} channel groups, none the primary output's ({}); rename all but one in the channel map",
                        several.len(),
                        several
                            .iter()
                            .map(|c| describe(column, c))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                    ))
                }
            },
        };
        // An error of this channel: the column, the channel (and its mapping), what is wrong.
        let channel_err = |m: String| err(Some((*column).into()), format!("{}: {m}", describe(column, ch)));
        let unreadable = |e: falcon_mdf::Mf4Error| channel_err(format!("unreadable: {e}"));
        let signal = mdf.signal(ch).map_err(unreadable)?;
        let mut values = match signal.values().map_err(unreadable)? {
            SignalValues::F64(v) => v,
            // A value-to-text conversion (a logger's `ON`/`OFF` states).
            SignalValues::Str(texts) => {
                let (v, note) =
                    text_flag(column, &texts, || signal.raw_values().map(|r| r.to_f64())).map_err(channel_err)?;
                channel_notes.push(format!("`{column}` ({}) {note}", describe(column, ch)));
                v
            }
            other => other.to_f64(),
        };
        let flag = FLAGS.contains(column);
        // Samples the logger marked invalid (invalidation bits: a sensor's dropout, a bus
        // timeout) hold no measurement: filled from the channel's valid ones at their times.
        if let Some(valid) = signal.validity().filter(|v| v.iter().any(|ok| !ok)) {
            let same_group = (ch.data_group_index, ch.channel_group_index) == group;
            let t_ch = if same_group {
                t_s.clone()
            } else {
                timestamps(&mdf, ch, map, &mut UnitNotes::default())
                    .map_err(|m| channel_err(format!("time base {m}")))?
            };
            let invalid = valid.iter().filter(|ok| !**ok).count();
            if invalid == valid.len() {
                return Err(channel_err("every sample is marked invalid by the logger".into()));
            }
            if valid.len() != values.len() {
                return Err(channel_err(format!(
                    "{} validity flags for {} samples",
                    valid.len(),
                    values.len()
                )));
            }
            (values, _) = fill_gaps(&t_ch, &values, |i| valid[i], flag).map_err(channel_err)?;
            channel_notes.push(format!(
                "`{column}` ({}): {invalid} of {} samples marked invalid by the logger, filled from its valid samples ({})",
                describe(column, ch),
                valid.len(),
                if flag { "held" } else { "interpolated" }
            ));
        }
        // A logger's channel is in the unit it recorded; one named as the column (before a
        // measuring device's suffix) states the column's unit already.
        let renamed = ch.name.split('\\').next() != Some(*column);
        let (unit, renamed) = match map.unit_of(column) {
            Some(stated) => {
                if !units::bare(&ch.unit).is_empty() && units::bare(&ch.unit) != stated {
                    notices.push(format!(
                        "channel map {}: `{column}` read in {stated} as it states; the file records {}",
                        map.file,
                        units::bare(&ch.unit)
                    ));
                }
                (stated, true)
            }
            None => (units::bare(&ch.unit), renamed),
        };
        match reading(column, unit, renamed).map_err(channel_err)? {
            Reading::Own => {}
            Reading::Convert(c) => {
                values.iter_mut().for_each(|v| *v = c.apply(*v));
                unit_notes.converted(&format!("`{column}`"), unit, &c, "");
            }
            Reading::Assumed => unit_notes.assumed(column, unit),
        }
        let values = if (ch.data_group_index, ch.channel_group_index) == group {
            if values.len() != t_s.len() {
                return Err(err(
                    Some((*column).into()),
                    format!(
                        "{} has {} samples, its time channel {}",
                        describe(column, ch),
                        values.len(),
                        t_s.len()
                    ),
                ));
            }
            match &uniform {
                Some((grid, _)) => resample(&t_s, &values, grid, flag).map_err(channel_err)?.0,
                None => values,
            }
        } else {
            let t_ch = timestamps(&mdf, ch, map, &mut UnitNotes::default())
                .map_err(|m| channel_err(format!("time base {m}")))?;
            let (out, outside) = resample(&t_ch, &values, base, flag).map_err(channel_err)?;
            let rate = rate_hz(&t_ch);
            let mut note = format!(
                "`{column}` ({}) is in another channel group at {} Hz: resampled onto `{primary}`'s {} Hz time base by {}",
                describe(column, ch),
                fmt_hz(rate),
                fmt_hz(rate_hz(base)),
                if flag {
                    "zero-order hold (the last value at or before each instant)"
                } else {
                    "linear interpolation"
                }
            );
            if outside > 0 {
                note.push_str(&format!(
                    "; {outside} sample(s) outside its recorded span take its first or last value"
                ));
            }
            resampled.push(note);
            out
        };
        columns.push(((*column).to_string(), values));
    }
    notices.extend(channel_notes);
    notices.extend(resampled);
    notices.extend(unit_notes.into_notices());

    let names: BTreeMap<&str, String> = by_column
        .iter()
        .filter_map(|(col, chs)| chs.first().map(|c| (*col, describe(col, c))))
        .collect();
    // The same checks as a CSV file (crate::log::check): errors name the column and the
    // sample; here they also name the logger's channel.
    let mut log = log_from_columns(&file, meta, columns, Some(plant)).map_err(|mut e| {
        if let Some(c) = e.column.as_deref().and_then(|c| names.get(c)) {
            e.message = format!("{c}: {}", e.message);
        }
        // A sample's time helps find it in the logger's tool.
        if let Some((head, tail)) = e.message.split_once(" (0-based)") {
            let k = head.rsplit(' ').next().and_then(|k| k.parse::<usize>().ok());
            if let Some(t) = k.and_then(|k| base.get(k)) {
                e.message = format!("{head} (0-based, t = {t} s){tail}");
            }
        }
        if e.message.contains("is missing") {
            return missing(&file, &mdf, map, e.column.as_deref().unwrap_or(""), plant);
        }
        e
    })?;
    log.notices.splice(0..0, notices);
    Ok(log)
}

/// The error for a required column that no channel provides, with what the file has.
fn missing(file: &str, mdf: &Mf4File, map: &ChannelMap, column: &str, plant: Plant) -> LogError {
    let looked = match map.channels.iter().find(|(_, to)| to == column) {
        Some((from, _)) => format!("channel `{from}` (channel map {}) or `{column}`", map.file),
        None => format!("channel `{column}`"),
    };
    let mut have: Vec<&str> = mdf
        .channels()
        .filter(|c| !c.is_master())
        .map(|c| c.name.as_str())
        .collect();
    have.sort_unstable();
    have.dedup();
    LogError {
        file: file.to_string(),
        line: None,
        column: Some(column.to_string()),
        message: format!(
            "required `{plant}` column `{column}` is missing: no {looked} in the file (its channels: {}); \
             rename the logger's channel with --channel-map",
            have.join(", ")
        ),
    }
}

/// A flag channel recorded with a value-to-text conversion, as loggers record a digital
/// state: its texts read as 1/0 where each is a flag's word ([`crate::log::flag_word`]: `ON`,
/// `OFF`, `TRUE`, ...), else its raw (unconverted) values, which the log's check then holds
/// to 0/1; with what was done, for the notice. A text channel under a signal's column is an
/// error naming a text.
fn text_flag(
    column: &str,
    texts: &[String],
    raw: impl FnOnce() -> Result<Vec<f64>, falcon_mdf::Mf4Error>,
) -> Result<(Vec<f64>, String), String> {
    let first = texts.first().map_or("", String::as_str);
    if !FLAGS.contains(&column) {
        return Err(format!(
            "holds text (`{first}`), not numbers: a value-to-text conversion on a signal"
        ));
    }
    let words: Option<Vec<f64>> = texts.iter().map(|t| crate::log::flag_word(t)).collect();
    if let Some(v) = words {
        return Ok((
            v,
            "recorded as words (`ON`/`OFF`, `TRUE`/`FALSE`, `HIGH`/`LOW`): read as 1/0".into(),
        ));
    }
    let v = raw().map_err(|e| format!("unreadable raw values: {e}"))?;
    let other = texts
        .iter()
        .find(|t| crate::log::flag_word(t).is_none())
        .map_or("", String::as_str);
    Ok((
        v,
        format!("recorded as text (`{other}` is no flag's word): its raw values read"),
    ))
}

/// Steps up to this many median steps are bridged by [`uniform_grid`] (up to two samples a
/// logger lost in a row, with its jitter); a longer gap is an error of the log's uniformity
/// check.
const MAX_BRIDGED_PERIODS: f64 = 3.5;

/// A uniform grid for time stamps `t` that jitter beyond DATA-FORMAT's 1 % (some step more than
/// 1 % off the mean step), with what the jitter is, for the notice: the grid's step is the
/// logger's period (below), the grid starts at the first time stamp and ends at or before the
/// last. `None` for a uniform time base, and where
/// a step is not positive or longer than [`MAX_BRIDGED_PERIODS`] medians (the log's check names
/// it).
fn uniform_grid(t: &[f64]) -> Option<(Vec<f64>, String)> {
    let n = t.len();
    if n < 3 {
        return None;
    }
    let span = t[n - 1] - t[0];
    let mean = span / (n - 1) as f64;
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if steps.iter().all(|&s| (s - mean).abs() <= 0.01 * mean) || steps.iter().any(|&s| !(s > 0.0)) {
        return None;
    }
    steps.sort_by(f64::total_cmp);
    let (shortest, median, longest) = (steps[0], steps[steps.len() / 2], steps[steps.len() - 1]);
    if !(longest <= MAX_BRIDGED_PERIODS * median) {
        return None;
    }
    // The logger's period: the span over the nominal intervals it holds, each step counted as
    // the whole number of medians nearest to it (1 for a jittered step, 2 or 3 across lost
    // samples). The median alone is off by the jitter's skew; the span is not.
    let intervals: f64 = t.windows(2).map(|w| ((w[1] - w[0]) / median).round().max(1.0)).sum();
    let dt = span / intervals;
    let count = (span / dt * (1.0 + 1e-12)).floor() as usize + 1;
    let grid: Vec<f64> = (0..count)
        .map(|k| t[0] + k as f64 * dt)
        .filter(|&g| g <= t[n - 1])
        .collect();
    let what =
        format!("its steps range {shortest:.4e}..{longest:.4e} s around a median of {median:.4e} s (1 % accepted)");
    Some((grid, what))
}

fn rate_hz(t: &[f64]) -> f64 {
    match (t.first(), t.last()) {
        (Some(a), Some(b)) if t.len() > 1 && b > a => (t.len() - 1) as f64 / (b - a),
        _ => f64::NAN,
    }
}

fn fmt_hz(hz: f64) -> String {
    if hz >= 100.0 {
        format!("{hz:.0}")
    } else {
        format!("{hz:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_jittered_time_base_gets_a_uniform_grid_and_a_gap_does_not() {
        let dt = 1e-3;
        let uniform: Vec<f64> = (0..1000).map(|k| k as f64 * dt).collect();
        assert!(uniform_grid(&uniform).is_none());
        // ±20 % jitter, first and last kept: the grid is the nominal one.
        let jittered: Vec<f64> = uniform
            .iter()
            .enumerate()
            .map(|(k, &t)| {
                if k == 0 || k == 999 {
                    t
                } else {
                    t + 0.2 * dt * ((k * 7919 % 100) as f64 / 50.0 - 1.0)
                }
            })
            .collect();
        let (grid, what) = uniform_grid(&jittered).unwrap();
        assert_eq!(grid.len(), 1000, "{what}");
        for (g, t) in grid.iter().zip(&uniform) {
            assert!((g - t).abs() < 1e-12, "{g} vs {t}");
        }
        // Two samples lost: bridged at the median step. Ten lost: left to the log's check.
        let mut lost: Vec<f64> = jittered.clone();
        lost.drain(500..502);
        let (grid, _) = uniform_grid(&lost).unwrap();
        assert_eq!(grid.len(), 1000);
        assert!((grid[1] - grid[0] - dt).abs() < 1e-12 && *grid.last().unwrap() <= 0.999 + 1e-12);
        let mut gap: Vec<f64> = jittered.clone();
        gap.drain(500..510);
        assert!(uniform_grid(&gap).is_none());
    }

    #[test]
    fn resampling_is_linear_for_signals_and_holds_flags() {
        let t_from = [0.0, 1.0, 2.0];
        let v = [0.0, 10.0, 0.0];
        let t_to = [-0.5, 0.0, 0.25, 1.0, 1.5, 2.0, 2.5];
        let (lin, outside) = resample(&t_from, &v, &t_to, false).unwrap();
        assert_eq!(lin, [0.0, 0.0, 2.5, 10.0, 5.0, 0.0, 0.0]);
        assert_eq!(outside, 2);
        let (zoh, _) = resample(&t_from, &[0.0, 1.0, 0.0], &t_to, true).unwrap();
        assert_eq!(zoh, [0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0]);
        assert!(resample(&[0.0, 0.0], &[1.0, 2.0], &t_to, false)
            .unwrap_err()
            .contains("do not increase"));
    }

    #[test]
    fn channel_maps_are_checked_by_name() {
        let m = ChannelMap::parse(
            "m.toml",
            "[channels]\n\"ECU.PhaseCam_deg\" = \"phase_deg\"\n[meta]\nplant = \"evvt\"\nkp = 25\n",
        )
        .unwrap();
        assert_eq!(m.column_of("ECU.PhaseCam_deg"), "phase_deg");
        assert_eq!(m.column_of("engine_rpm"), "engine_rpm");
        assert_eq!(m.meta, [("kp".into(), "25".into()), ("plant".into(), "evvt".into())]);

        let e = ChannelMap::parse("m.toml", "[channels]\n\"A\" = \"phase\"\n").unwrap_err();
        assert_eq!(e.column.as_deref(), Some("channels.\"A\""));
        assert!(e.message.contains("`phase` is not a DATA-FORMAT column"), "{e}");
        let e = ChannelMap::parse("m.toml", "[channels]\n\"A\" = \"phase_deg\"\n\"B\" = \"phase_deg\"\n").unwrap_err();
        assert!(e.message.contains("already mapped from channel `A`"), "{e}");
        let e = ChannelMap::parse("m.toml", "[channels]\n\"A\" = phase_deg\n").unwrap_err();
        assert_eq!(e.line, Some(2), "{e}");
        let e = ChannelMap::parse("m.toml", "[chanels]\n").unwrap_err();
        assert!(e.message.contains("unknown section `[chanels]`"), "{e}");
    }
}
