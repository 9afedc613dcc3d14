//! docs/records.md against the code: the Parquet columns `records::to_frame` writes and
//! the fields of `collide simulate --json` must be exactly those its tables document.

use std::collections::BTreeMap;

use polars::prelude::DataType;

use crate::util::json_summary;

const DOC: &str = "docs/records.md";

/// The tables of the section of docs/records.md whose heading starts with `heading`:
/// every backticked name in a row's first cell, with its type from the second cell.
fn documented(heading: &str) -> BTreeMap<String, String> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(DOC);
    let text = std::fs::read_to_string(&path).unwrap();
    let section = text
        .split("\n## ")
        .find(|s| s.starts_with(heading))
        .unwrap_or_else(|| panic!("{DOC} has no section `## {heading}`"));
    let mut names = BTreeMap::new();
    for row in section.lines().filter(|l| l.starts_with("| `")) {
        let cells: Vec<&str> = row.split(" | ").collect();
        let in_row: Vec<&str> = cells[0].split('`').skip(1).step_by(2).collect();
        for (index, name) in in_row.iter().enumerate() {
            let ty = type_of(cells.get(1).copied().unwrap_or(""), index, in_row.len());
            names.insert((*name).to_owned(), ty.to_owned());
        }
    }
    names
}

/// The documented type of the `index`th of `count` names sharing a row: one type for
/// all of them, or one per name ("u64, str, ..."), each possibly followed by a note.
fn type_of(cell: &str, index: usize, count: usize) -> &str {
    let types: Vec<&str> = cell.split(", ").collect();
    let one = if types.len() == count {
        types[index]
    } else {
        types[0]
    };
    one.split_whitespace().next().unwrap_or("")
}

fn doc_type(dtype: &DataType) -> &'static str {
    match dtype {
        DataType::String => "str",
        DataType::UInt64 => "u64",
        DataType::UInt32 => "u32",
        DataType::Float64 => "f64",
        DataType::Boolean => "bool",
        other => panic!("a column of type {other} has no name in {DOC}; add one to this test"),
    }
}

#[test]
fn the_parquet_columns_are_those_documented() {
    let heading = "The Parquet records";
    let frame = collide::study::records::to_frame(&[]).unwrap();
    let written: BTreeMap<String, &str> = frame
        .columns()
        .iter()
        .map(|c| (c.name().to_string(), doc_type(c.dtype())))
        .collect();
    let rows = documented(heading);
    let missing: Vec<String> = written
        .iter()
        .filter(|(name, _)| !rows.contains_key(*name))
        .map(|(name, ty)| {
            format!("| `{name}` | {ty} | what it means, its unit (added in version N) |")
        })
        .collect();
    let stale: Vec<&String> = rows.keys().filter(|n| !written.contains_key(*n)).collect();
    let mistyped: Vec<String> = written
        .iter()
        .filter_map(|(name, ty)| {
            let doc = rows.get(name.as_str())?;
            (doc != ty).then(|| format!("`{name}` is documented as {doc} but written as {ty}"))
        })
        .collect();
    assert!(
        missing.is_empty() && stale.is_empty() && mistyped.is_empty(),
        "{DOC}, section `{heading}`, disagrees with records::to_frame.\n\
         Add these rows to its table:\n{}\n\
         Remove these names (the code writes no such column): {stale:?}\n\
         Fix these types: {mistyped:?}",
        missing.join("\n")
    );
}

#[test]
fn the_json_summary_fields_are_those_documented() {
    let heading = "The JSON summary";
    let json = json_summary(&[
        "simulate",
        "experiments/scenes/seed-1000.toml",
        "--steps",
        "2",
    ]);
    let fields: Vec<&String> = json.as_object().unwrap().keys().collect();
    let rows = documented(heading);
    let missing: Vec<String> = fields
        .iter()
        .filter(|f| !rows.contains_key(f.as_str()))
        .map(|f| format!("| `{f}` | what it means, its unit |"))
        .collect();
    let stale: Vec<&String> = rows.keys().filter(|name| !fields.contains(name)).collect();
    assert!(
        missing.is_empty() && stale.is_empty(),
        "{DOC}, section `{heading}`, disagrees with `collide simulate --json`.\n\
         Add these rows to one of its tables:\n{}\n\
         Remove these names (the summary has no such field): {stale:?}",
        missing.join("\n")
    );
}
