//! ARCHITECTURE.md against the tree: its map must name every Rust file and every folder
//! under `src/`, and every Rust path it names (`src/sim/grid.rs`, `tests/schema.rs`,
//! `run/summary.rs` for `src/run/summary.rs`) must exist.

use std::collections::BTreeSet;
use std::path::Path;

const DOC: &str = "ARCHITECTURE.md";

/// The paths under `dir` (relative to the crate root, with `/`): folders end in `/`.
fn tree(root: &Path, dir: &str, found: &mut BTreeSet<String>) {
    let mut entries: Vec<_> = std::fs::read_dir(root.join(dir))
        .unwrap_or_else(|e| panic!("{dir}: {e}"))
        .map(|entry| entry.unwrap())
        .collect();
    entries.sort_by_key(|entry| entry.file_name());
    for entry in entries {
        let name = entry.file_name().to_string_lossy().into_owned();
        let path = format!("{dir}/{name}");
        if entry.file_type().unwrap().is_dir() {
            found.insert(format!("{path}/"));
            tree(root, &path, found);
        } else if name.ends_with(".rs") {
            found.insert(path);
        }
    }
}

/// Every path-like word of `text`: a run of letters, digits and `_ . / -` that holds a
/// `/`, with the punctuation that may end a sentence taken off.
fn paths(text: &str) -> BTreeSet<String> {
    let is_path_char = |c: char| c.is_ascii_alphanumeric() || "_./-".contains(c);
    text.split(|c: char| !is_path_char(c))
        .map(|word| word.trim_end_matches(['.', '-']))
        .filter(|word| word.contains('/'))
        .map(str::to_owned)
        .collect()
}

#[test]
fn the_map_names_every_file_under_src_and_only_files_that_exist() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join(DOC)).unwrap();
    let named = paths(&text);
    let mut on_disk = BTreeSet::new();
    tree(root, "src", &mut on_disk);

    let missing: Vec<&String> = on_disk.iter().filter(|p| !named.contains(*p)).collect();
    let stale: Vec<&String> = named
        .iter()
        .filter(|p| p.ends_with(".rs"))
        .filter(|p| !root.join(p).is_file() && !root.join("src").join(p).is_file())
        .collect();
    let stale_folders: Vec<&String> = named
        .iter()
        .filter(|p| p.starts_with("src/") && p.ends_with('/'))
        .filter(|p| !root.join(p).is_dir())
        .collect();
    assert!(
        missing.is_empty() && stale.is_empty() && stale_folders.is_empty(),
        "{DOC} disagrees with the tree.\n\
         Add a line to its map for each of these (what the file or folder owns): {missing:?}\n\
         These Rust paths it names do not exist (as given, or under src/): {stale:?}\n\
         These folders it names do not exist: {stale_folders:?}"
    );
}

#[test]
fn paths_are_read_as_words_without_their_sentence_punctuation() {
    let found = paths("See `src/sim/grid.rs`. Then src/run/ (and run/summary.rs, here).");
    let expected = ["run/summary.rs", "src/run/", "src/sim/grid.rs"].map(str::to_owned);
    assert_eq!(found, BTreeSet::from(expected));
}
