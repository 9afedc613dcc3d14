//! The configurations' table that `collide results` and `collide run` print: one row per
//! configuration with its median time, interval, spread and counts. Its setting columns
//! come from the configurations' keys: a setting that varies within the records gets a
//! column, one that does not goes in the line above the table. Printed as text or
//! markdown, exported as CSV or JSON (every setting, constant or not, in every row).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde_json::{Map, Value};

use crate::report::analysis::{TIMING_CONFIDENCE, TIMING_SEED, TOO_SHORT_S};
use crate::report::units::{TimeUnit, significant};
use crate::stats::{median, median_interval};
use crate::study::manifest::PLACEMENT_KEYS;
use crate::study::records::{Record, STATUS_OK};

/// How `collide results` prints its tables.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Aligned columns for the terminal, with the hash check and the scaling tables.
    #[default]
    Text,
    /// Comma-separated values, one header line; times in seconds.
    Csv,
    /// A JSON array of objects, one per configuration; times in seconds.
    Json,
    /// Markdown tables, to paste into a report or an issue.
    Markdown,
}

/// The settings every table has, whatever its configurations' keys name: what its rows
/// are grouped by (several studies may share a folder).
const GROUPED: [&str; 5] = ["study", "scene", "backend", "workers", "n"];

/// What else tells rows apart besides a configuration's key: the scene's contents (a
/// scene edited between two results files) and the side of an A/B check.
const CONTEXT: [&str; 2] = ["scene_hash", "ab_side"];

/// The settings whose column every row holds, a failed run's too (its configuration
/// placed it): read from the column first, since the key's `workers=` counts an MPI
/// configuration's ranks and the column its ranks × threads.
const PLACED: [&str; 2] = ["workers", "threads"];

/// Significant digits of a setting's number (dt, packing, tc).
const SETTING_DIGITS: usize = 4;

/// The configurations of some records, each with its timings.
#[derive(Clone, Debug)]
pub struct Table {
    /// Every setting, in column order, and whether it varies from row to row.
    settings: Vec<(String, bool)>,
    rows: Vec<Row>,
    /// Whether any run drew every step offscreen: frames/s with drawing are shown.
    drawn: bool,
}

/// One configuration (one side of an A/B check): its settings and what its runs measured.
#[derive(Clone, Debug)]
struct Row {
    /// In the order of [`Table::settings`]; null where not set.
    values: Vec<Value>,
    median_s: f64,
    ci_s: [f64; 2],
    min_max_s: [f64; 2],
    reps: usize,
    failed: usize,
    /// Median steps per second and frames per second with drawing.
    fps: f64,
    fps_with_drawing: f64,
    oversubscribed: bool,
}

impl Row {
    fn too_short(&self) -> bool {
        self.median_s < TOO_SHORT_S
    }
}

impl Table {
    /// The table of `records`, one row per configuration in first-seen order.
    pub fn of(records: &[Record]) -> Table {
        let mut order: Vec<String> = Vec::new();
        let mut groups: BTreeMap<String, Vec<&Record>> = BTreeMap::new();
        for record in records {
            // What was computed (the configuration, and n and the scene's contents, which
            // its key may leave to the scene), where, and by which side of an A/B check:
            // never pooled.
            let key = format!(
                "{}|{}|{}|{}x{}|{}",
                record.study,
                record.config_key,
                record.setup_key(),
                record.ranks,
                record.threads,
                record.ab_side
            );
            let group = groups.entry(key.clone()).or_default();
            if group.is_empty() {
                order.push(key);
            }
            group.push(record);
        }
        let names = setting_names(records);
        let rows: Vec<Row> = order.iter().map(|key| row(&groups[key], &names)).collect();
        let settings = names
            .into_iter()
            .enumerate()
            .map(|(i, name)| {
                let varies = rows.iter().any(|row| row.values[i] != rows[0].values[i]);
                (name, varies)
            })
            .collect();
        Table {
            settings,
            rows,
            drawn: records.iter().any(Record::drew),
        }
    }

    /// The settings every row shares, as `name = value`, leaving out those not set and
    /// the [`CONTEXT`] (a column only where it tells rows apart).
    pub fn constants(&self) -> String {
        let Some(first) = self.rows.first() else {
            return String::new();
        };
        let shared: Vec<String> = (self.settings.iter().enumerate())
            .filter(|(_, (name, varies))| !varies && !CONTEXT.contains(&name.as_str()))
            .filter(|(i, _)| is_set(&first.values[*i]))
            .map(|(i, (name, _))| format!("{name} = {}", shown(&first.values[i])))
            .collect();
        shared.join(", ")
    }

    /// The columns the text and markdown tables show: the varying settings, then the
    /// timings (in the unit that fits each column), with a header.
    fn columns(&self) -> (Vec<String>, Vec<Vec<String>>) {
        let varying: Vec<usize> = (self.settings.iter().enumerate())
            .filter(|(_, (_, varies))| *varies)
            .map(|(i, _)| i)
            .collect();
        let median_unit = TimeUnit::for_column(self.rows.iter().map(|r| r.median_s));
        let ci_unit = TimeUnit::for_column(self.rows.iter().map(|r| r.ci_s[0]));
        let spread_unit = TimeUnit::for_column(self.rows.iter().map(|r| r.min_max_s[0]));
        let mut header: Vec<String> = varying
            .iter()
            .map(|&i| self.settings[i].0.clone())
            .collect();
        header.extend(["median", "95% CI", "min–max"].map(str::to_owned));
        if self.drawn {
            header.extend(["steps/s", "frames/s with drawing"].map(str::to_owned));
        }
        header.extend(["reps", "failed"].map(str::to_owned));
        let cells = self
            .rows
            .iter()
            .map(|row| {
                let mut cells: Vec<String> =
                    varying.iter().map(|&i| shown(&row.values[i])).collect();
                let short = if row.reps > 0 && row.too_short() {
                    " ⏱"
                } else {
                    ""
                };
                let oversubscribed = if row.oversubscribed { " ⚠" } else { "" };
                cells.push(format!(
                    "{}{short}{oversubscribed}",
                    median_unit.format(row.median_s)
                ));
                cells.push(ci_unit.range(row.ci_s));
                cells.push(spread_unit.range(row.min_max_s));
                if self.drawn {
                    cells.push(significant(row.fps, SETTING_DIGITS));
                    cells.push(significant(row.fps_with_drawing, SETTING_DIGITS));
                }
                cells.push(row.reps.to_string());
                cells.push(row.failed.to_string());
                cells
            })
            .collect();
        (header, cells)
    }

    /// What the marks in the median column mean, for the rows that have them.
    fn legend(&self) -> String {
        let mut out = String::new();
        if self.rows.iter().any(|r| r.reps > 0 && r.too_short()) {
            let _ = writeln!(
                out,
                "⏱ a median under {:.0} ms of stepping: too short to time well; run more steps.",
                1e3 * TOO_SHORT_S
            );
        }
        if self.rows.iter().any(|r| r.oversubscribed) {
            let _ = writeln!(
                out,
                "⚠ more workers than usable CPUs: the time measures contention, not scaling."
            );
        }
        out
    }

    /// The table as aligned text: the constants' line, the header, a line per row, the
    /// marks' legend.
    pub fn text(&self) -> String {
        let (header, cells) = self.columns();
        let numeric: Vec<bool> = (0..header.len())
            .map(|c| cells.iter().all(|row| looks_numeric(&row[c])))
            .collect();
        let widths: Vec<usize> = (0..header.len())
            .map(|c| {
                let cell_widths = cells.iter().map(|row| row[c].chars().count());
                cell_widths
                    .chain([header[c].chars().count()])
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        let line = |row: &[String]| {
            let padded: Vec<String> = row
                .iter()
                .enumerate()
                .map(|(c, cell)| {
                    let pad = " ".repeat(widths[c] - cell.chars().count());
                    match numeric[c] {
                        true => format!("{pad}{cell}"),
                        false => format!("{cell}{pad}"),
                    }
                })
                .collect();
            padded.join("  ").trim_end().to_owned()
        };
        let mut out = String::new();
        let constants = self.constants();
        if !constants.is_empty() {
            let _ = writeln!(out, "Every run: {constants}");
        }
        let _ = writeln!(out, "{}", line(&header));
        for row in &cells {
            let _ = writeln!(out, "{}", line(row));
        }
        out.push_str(&self.legend());
        out
    }

    /// The table in markdown: the constants' line as a paragraph, then the table.
    pub fn markdown(&self) -> String {
        let (header, cells) = self.columns();
        let mut out = String::new();
        let constants = self.constants();
        if !constants.is_empty() {
            let _ = writeln!(out, "Every run: {constants}.\n");
        }
        let _ = writeln!(out, "| {} |", header.join(" | "));
        let rule: Vec<&str> = (0..header.len())
            .map(|c| match cells.iter().all(|row| looks_numeric(&row[c])) {
                true => "---:",
                false => "---",
            })
            .collect();
        let _ = writeln!(out, "| {} |", rule.join(" | "));
        for row in &cells {
            let escaped: Vec<String> = row.iter().map(|cell| cell.replace('|', "\\|")).collect();
            let _ = writeln!(out, "| {} |", escaped.join(" | "));
        }
        let legend = self.legend();
        if !legend.is_empty() {
            let _ = write!(out, "\n{legend}");
        }
        out
    }

    /// Every row as named values: every setting, then the timings with their units in
    /// their names (null where not measured). CSV and JSON both use these names.
    fn fields(&self) -> Vec<Vec<(String, Value)>> {
        let number = |x: f64| serde_json::Number::from_f64(x).map_or(Value::Null, Value::Number);
        self.rows
            .iter()
            .map(|row| {
                let settings = (self.settings.iter().zip(&row.values))
                    .map(|((name, _), value)| (name.clone(), value.clone()));
                let measures = [
                    ("median_s", number(row.median_s)),
                    ("median_ci_low_s", number(row.ci_s[0])),
                    ("median_ci_high_s", number(row.ci_s[1])),
                    ("min_s", number(row.min_max_s[0])),
                    ("max_s", number(row.min_max_s[1])),
                    ("steps_per_s", number(row.fps)),
                    ("fps_with_drawing", number(row.fps_with_drawing)),
                    ("repetitions", Value::from(row.reps)),
                    ("failed", Value::from(row.failed)),
                    ("oversubscribed", Value::from(row.oversubscribed)),
                ];
                let measures = measures
                    .into_iter()
                    .map(|(name, value)| (name.to_owned(), value));
                settings.chain(measures).collect()
            })
            .collect()
    }

    /// The rows as a JSON array of objects, one per configuration.
    pub fn json(&self) -> String {
        let array: Vec<Value> = (self.fields().into_iter())
            .map(|fields| Value::Object(fields.into_iter().collect::<Map<String, Value>>()))
            .collect();
        serde_json::to_string_pretty(&array).expect("JSON values always serialize") + "\n"
    }

    /// The rows as CSV: a header line of the names JSON uses, a line per row; a value
    /// not measured is empty.
    pub fn csv(&self) -> String {
        let rows = self.fields();
        let Some(first) = rows.first() else {
            return String::new();
        };
        let mut out = csv_line(first.iter().map(|(name, _)| name.as_str()));
        for fields in &rows {
            let cells: Vec<String> = fields
                .iter()
                .map(|(_, value)| match value {
                    Value::Null => String::new(),
                    Value::String(text) => text.clone(),
                    value => value.to_string(),
                })
                .collect();
            out.push_str(&csv_line(cells.iter().map(String::as_str)));
        }
        out
    }
}

/// One CSV line: a field with a comma, a quote or a line break quoted, its quotes doubled.
fn csv_line<'a>(fields: impl Iterator<Item = &'a str>) -> String {
    let quoted: Vec<String> = fields
        .map(|field| match field.contains([',', '"', '\n', '\r']) {
            true => format!("\"{}\"", field.replace('"', "\"\"")),
            false => field.to_owned(),
        })
        .collect();
    quoted.join(",") + "\n"
}

/// The settings of the records' rows, each once: [`GROUPED`] and those the
/// configuration keys name, the study, the scene and the placement first, then the others
/// in key order, then [`CONTEXT`].
fn setting_names(records: &[Record]) -> Vec<String> {
    let mut names: Vec<String> = GROUPED.map(str::to_owned).to_vec();
    for record in records {
        for entry in record.config_key.split(';') {
            let name = entry.split('=').next().unwrap_or_default();
            if !name.is_empty() && !names.iter().any(|known| known == name) {
                names.push(name.to_owned());
            }
        }
    }
    let is_placement = |name: &String| {
        PLACEMENT_KEYS
            .iter()
            .any(|key| key.trim_end_matches('=') == name)
    };
    let front = |name: &String| GROUPED[..2].contains(&name.as_str()) || is_placement(name);
    let (mut first, rest): (Vec<String>, Vec<String>) = names.into_iter().partition(front);
    first.extend(rest);
    first.extend(CONTEXT.map(str::to_owned));
    first
}

/// A row of a configuration's runs (`group`, all of one configuration), its settings
/// in the order of `names`.
fn row(group: &[&Record], names: &[String]) -> Row {
    let ok: Vec<&Record> = group
        .iter()
        .copied()
        .filter(|r| r.status == STATUS_OK)
        .collect();
    let values = names
        .iter()
        .map(|name| setting(ok.first().copied().unwrap_or(group[0]), name))
        .collect();
    let mut times: Vec<f64> = ok.iter().map(|r| r.wall_s).collect();
    let (median_s, ci_s, min_max_s) = match times.is_empty() {
        true => (f64::NAN, [f64::NAN; 2], [f64::NAN; 2]),
        false => {
            let median_s = median(&mut times);
            let ci = median_interval(&times, TIMING_CONFIDENCE, TIMING_SEED);
            (
                median_s,
                [ci.lower, ci.upper],
                [times[0], times[times.len() - 1]],
            )
        }
    };
    let median_of = |value: fn(&Record) -> f64| {
        let mut values: Vec<f64> = ok
            .iter()
            .map(|r| value(r))
            .filter(|v| v.is_finite())
            .collect();
        match values.is_empty() {
            true => f64::NAN,
            false => median(&mut values),
        }
    };
    Row {
        values,
        median_s,
        ci_s,
        min_max_s,
        reps: ok.len(),
        failed: group.len() - ok.len(),
        fps: median_of(|r| r.fps),
        fps_with_drawing: median_of(|r| r.fps_with_drawing),
        oversubscribed: ok.first().is_some_and(|r| r.oversubscribed),
    }
}

/// The setting `name` of `record`'s configuration: for a run that succeeded, and for
/// the [`PLACED`] settings, the record's column of that name (the value the run
/// resolved, such as the scene's n or an automatic dt); for one that failed (its run's
/// columns hold nothing), the configuration key's entry (a number, true or false, or text; null where the key leaves it to the
/// scene). The other source where one has no such name.
fn setting(record: &Record, name: &str) -> Value {
    let keyed = record
        .config_key
        .split(';')
        .find_map(|entry| entry.strip_prefix(name)?.strip_prefix('='))
        .map(|text| match text {
            "-" => Value::Null,
            text => serde_json::from_str(text).unwrap_or_else(|_| Value::from(text)),
        });
    let column = record.value(name);
    let found = match record.status == STATUS_OK || PLACED.contains(&name) {
        true => column.or(keyed),
        false => keyed.or(column),
    };
    found.unwrap_or(Value::Null)
}

/// Whether a value says something: not null, not empty text.
fn is_set(value: &Value) -> bool {
    match value {
        Value::Null => false,
        Value::String(text) => !text.is_empty(),
        _ => true,
    }
}

/// A setting's value as a table shows it: numbers to [`SETTING_DIGITS`] significant
/// digits, a dash where not set.
fn shown(value: &Value) -> String {
    match value {
        Value::Null => "—".to_owned(),
        Value::String(text) if text.is_empty() => "—".to_owned(),
        Value::String(text) => text.clone(),
        Value::Number(number) => match number.as_u64() {
            Some(count) => count.to_string(),
            None => significant(number.as_f64().unwrap_or(f64::NAN), SETTING_DIGITS),
        },
        other => other.to_string(),
    }
}

/// Whether a cell is a number or a time (right-aligned): it starts with a digit, a
/// sign or a dash.
fn looks_numeric(cell: &str) -> bool {
    cell.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '—')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_with_commas_or_quotes_are_quoted() {
        assert_eq!(
            csv_line(["a", "b,c", "d\"e"].into_iter()),
            "a,\"b,c\",\"d\"\"e\"\n"
        );
    }
}
