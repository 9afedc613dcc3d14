//! Golden outputs: `collide simulate --json` on the shipped scenes and the records of two
//! tiny studies, compared with snapshots in `tests/golden/` taken from an earlier build.
//! Everything a run decides is compared (field names and their order, column names,
//! order and types, every physical value and every state hash); only what the clock and
//! the machine decide is masked (timings, timestamps, host facts).
//!
//! A change that moves a snapshot changes what users and scripts read: accept it
//! (`INSTA_UPDATE=always cargo test --release golden`) only when that is the intent.

use std::path::Path;

use polars::prelude::{ParquetReader, SerReader};

use crate::util::{collide, scene_file};

/// Fields of the JSON summary, and columns of the records, that the clock decides.
const TIMINGS: &[&str] = &[
    "wall_s",
    "cpu_s",
    "setup_s",
    "fps",
    "draw_s",
    "fps_with_drawing",
    "particle_steps_per_s",
    "integration_s",
    "broad_phase_s",
    "collision_s",
    "communication_s",
    "events_per_s",
    // Workers against this machine's CPUs.
    "oversubscribed",
];

/// Columns of the records that the machine, the build or the date decide.
const ENVIRONMENT: &[&str] = &[
    "build_id",
    "hostname",
    "cpu_model",
    "logical_cores",
    "physical_cores",
    "usable_cpus",
    "cpu_affinity",
    // Where each MPI rank ran: hosts and CPU lists.
    "rank_cpus",
    "memory_bytes",
    "os",
    "rustc",
    "profile",
    "features",
    "git_commit",
    "git_dirty",
    "mpi_library",
    "load_average_start",
    "load_average",
    "load_average_end",
    "study_started_utc",
    "finished_utc",
];

fn golden(name: &str, text: &str) {
    insta::with_settings!({ snapshot_path => "golden", prepend_module_to_snapshot => false }, {
        insta::assert_snapshot!(name, text);
    });
}

/// The JSON line exactly as printed, one field per line, with the timing values masked.
fn masked_json(line: &str) -> String {
    let object: serde_json::Value = serde_json::from_str(line).unwrap();
    assert!(object.is_object(), "{line}");
    let body = line.strip_prefix('{').unwrap().strip_suffix('}').unwrap();
    body.split(",\"")
        .enumerate()
        .map(|(i, field)| {
            let field = if i == 0 {
                field.to_owned()
            } else {
                format!("\"{field}")
            };
            let (key, value) = field.split_once(':').unwrap();
            let masked = TIMINGS.contains(&key.trim_matches('"')) && value != "null";
            if masked {
                format!("{key}:<timing>")
            } else {
                field
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn simulate_json(args: &[&str]) -> String {
    let out = collide(&[&["simulate"], args, &["--json"]].concat());
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    masked_json(stdout.lines().last().unwrap())
}

#[test]
fn simulate_json_is_unchanged() {
    let cases: &[(&str, &[&str])] = &[
        (
            "seed-serial",
            &["experiments/scenes/seed-1000.toml", "--steps", "40"],
        ),
        (
            "seed-rayon",
            &[
                "experiments/scenes/seed-1000.toml",
                "--steps",
                "40",
                "--backend",
                "rayon",
                "--threads",
                "2",
            ],
        ),
        (
            "seed-accuracy-allpairs",
            &[
                "experiments/scenes/seed-1000.toml",
                "--n",
                "300",
                "--steps",
                "30",
                "--observe",
                "accuracy",
                "--broadphase",
                "allpairs",
            ],
        ),
        (
            "cooling-event",
            &[
                "experiments/scenes/cooling-gas.toml",
                "--n",
                "300",
                "--steps",
                "10",
            ],
        ),
        (
            "pile",
            &["experiments/scenes/granular-pile.toml", "--steps", "300"],
        ),
        (
            "head-on-event",
            &[
                "experiments/scenes/two-disks-head-on.toml",
                "--method",
                "event",
                "--steps",
                "12",
                "--dt",
                "1",
            ],
        ),
    ];
    for (name, args) in cases {
        golden(&format!("simulate-{name}"), &simulate_json(args));
    }
}

const SCENE: &str = "[scene]\nn = 200\npacking = 0.1\nseed = 3\nrestitution = 0.9\n\
                     [method]\ndt = 0.1\nsteps = 20\n";

/// Runs the manifest `body` (over one scene file) as a study and returns its records as
/// text: the schema (names, order, types), then every row sorted by configuration, with
/// the timing and environment columns masked.
fn study_records(dir: &Path, name: &str, body: &str) -> String {
    scene_file(dir, "scene.toml", SCENE);
    let text = format!(
        "name = \"{name}\"\nrepetitions = 1\nwarmups = 0\n{body}\n[[scenes]]\nfile = \"scene.toml\"\n"
    );
    let manifest = scene_file(dir, &format!("{name}.toml"), &text);
    let out_dir = dir.join("results");
    let out = collide(&[
        "run",
        manifest.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--no-report",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let files: Vec<_> = std::fs::read_dir(out_dir.join(name))
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "parquet"))
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let frame = ParquetReader::new(std::fs::File::open(&files[0]).unwrap())
        .finish()
        .unwrap();
    let mut lines: Vec<String> = frame
        .columns()
        .iter()
        .map(|column| format!("{}: {}", column.name(), column.dtype()))
        .collect();
    let mut rows: Vec<Vec<String>> = (0..frame.height())
        .map(|row| {
            frame
                .columns()
                .iter()
                .map(|column| {
                    let name = column.name().as_str();
                    let value = column.get(row).unwrap();
                    if TIMINGS.contains(&name) || ENVIRONMENT.contains(&name) {
                        format!("{name} = <masked>")
                    } else {
                        format!("{name} = {value}")
                    }
                })
                .collect()
        })
        .collect();
    rows.sort();
    for row in rows {
        lines.push(String::new());
        lines.extend(row);
    }
    lines.join("\n")
}

#[test]
fn study_records_are_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let backends = study_records(
        dir.path(),
        "golden-backends",
        "[sweep]\nbroadphase = [\"grid\", \"allpairs\"]\nn = [150]\n\
         [backends]\nserial = true\nrayon = [2]\n",
    );
    golden("records-backends", &backends);
    let methods = study_records(
        dir.path(),
        "golden-methods",
        "[sweep]\nmethod = [\"step\", \"event\"]\nobserve = [\"accuracy\", \"timing\"]\n\
         zip = [\"method\", \"observe\"]\nseed = [5]\nsteps = [15]\ndt = [0.05]\n\
         [backends]\nserial = true\n",
    );
    golden("records-methods", &methods);
}
