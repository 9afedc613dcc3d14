//! `collide report` from fixed synthetic records: the markdown is snapshot-tested, and
//! the numbers in it are checked against hand-computed speedups.

use collide::report::figures::scaling::{self, Figure};
use collide::report::{analysis, markdown};
use collide::run::backend_kind::{BackendKind, Placement};
use collide::run::summary::RunSummary;
use collide::study::environment::Environment;
use collide::study::records::{Record, RecordContext};

fn environment() -> Environment {
    Environment {
        hostname: "testhost".into(),
        cpu_model: "Test CPU @ 2.0GHz".into(),
        logical_cores: 2,
        physical_cores: 2,
        usable_cpus: 2,
        cpu_affinity: "0-1".into(),
        memory_bytes: 8 << 30,
        os: "Test OS, Linux 6.0".into(),
        rustc: "rustc 1.95.0".into(),
        profile: "release".into(),
        features: "mpi".into(),
        git_commit: "0123456789ab".into(),
        git_dirty: false,
        mpi_library: "mpirun (Open MPI) 4.1.4".into(),
        load_average_start: 0.5,
    }
}

fn summary(backend: &str, threads: usize, ranks: usize, n: usize, wall_s: f64) -> RunSummary {
    // What an MPI rank sends per step grows with the other ranks it sends to.
    let sent =
        |per_other_rank: f64| (backend == "mpi").then(|| per_other_rank * (ranks - 1) as f64);
    RunSummary {
        n,
        steps: 400,
        dt: 0.1,
        dt_auto_fraction: None,
        backend: backend.into(),
        workers: threads * ranks,
        threads,
        ranks,
        oversubscribed: threads * ranks > 2,
        boundary: "walls".into(),
        broadphase: "grid".into(),
        packing: 0.05,
        seed: Some(12345),
        wall_s,
        cpu_s: None,
        setup_s: 0.001,
        fps: 400.0 / wall_s,
        draw_s: None,
        fps_with_drawing: None,
        particle_steps_per_s: (n * 400) as f64 / wall_s,
        integration_s: 0.1 * wall_s,
        broad_phase_s: 0.6 * wall_s,
        collision_s: 0.2 * wall_s,
        communication_s: 0.0,
        messages_per_step_max: sent(4.5),
        messages_per_step_mean: sent(4.25),
        bytes_per_step_max: sent(2048.0),
        bytes_per_step_mean: sent(1536.0),
        collectives_per_step: (backend == "mpi").then_some(3.05),
        load_imbalance: (backend == "mpi").then_some(1.02),
        recuts: (backend == "mpi").then_some(0),
        setup_disks_max: (backend == "mpi").then_some(500),
        rank_cpus: None,
        kinetic_energy_initial: 500.0,
        kinetic_energy_final: 500.0,
        momentum_initial: [0.0, 0.0],
        momentum_final: [0.0, 0.0],
        pair_collisions: 1734,
        wall_collisions: 182,
        max_overlap: 0.138,
        max_wall_penetration: 0.0,
        state_hash: "51a3e11e31576e81".into(),
        method: "step".into(),
        observe: "timing".into(),
        events_per_s: None,
        collision_rate: Some(0.0867),
        temperature: Some(0.5),
        pressure: Some(0.0041),
        compressibility_z: Some(1.05),
        equilibrated: None,
        equilibration_cut: None,
        equilibration_cut_time: None,
        equilibration_mser5_cut_time: None,
        compressibility_z_from_zero: None,
        compressibility_z_se: None,
        compressibility_z_g: None,
        compressibility_z_n_eff: None,
        compressibility_z_plateau: None,
        collision_rate_se: None,
        collision_rate_g: None,
        temperature_se: None,
        temperature_g: None,
        z_reference: None,
        z_reference_se: None,
        z_reference_source: None,
        missed_collisions: None,
        missed_collision_fraction: None,
        mean_overlap: Some(0.02),
        energy_relative_error: Some(0.0),
        collapse_guard_fired: None,
        collapse_tc: None,
        collapse_time: None,
        time_reached: None,
        tc: None,
        temperature_curve: None,
        rms_step_over_radius: Some(0.1),
        choice: None,
    }
}

/// Serial at 1; rayon and MPI at 1, 2, 4 (4 oversubscribed on 2 cores): three
/// repetitions each, the middle one the median. Strong scaling: 1000 disks throughout.
fn records() -> Vec<Record> {
    study_records("strong")
}

/// The runs of [`records`] as a study of `scaling`; a weak one has n = 1000 × workers
/// and times that grow with the work.
fn study_records(scaling: &str) -> Vec<Record> {
    let environment = environment();
    let runs: [(BackendKind, usize, [f64; 3]); 7] = [
        (BackendKind::Serial, 1, [0.0100, 0.0102, 0.0110]),
        (BackendKind::Rayon, 1, [0.0104, 0.0105, 0.0120]),
        (BackendKind::Rayon, 2, [0.0055, 0.0056, 0.0060]),
        (BackendKind::Rayon, 4, [0.0060, 0.0070, 0.0090]),
        (BackendKind::Mpi, 1, [0.0106, 0.0108, 0.0115]),
        (BackendKind::Mpi, 2, [0.0058, 0.0060, 0.0061]),
        (BackendKind::Mpi, 4, [0.0100, 0.0120, 0.0150]),
    ];
    let mut records = Vec::new();
    for repetition in 0..3 {
        for (backend, workers, times) in runs {
            let key = format!(
                "scene=seed-1000;n=-;packing=-;dt=-;steps=-;seed=-;broadphase=-;backend={};workers={workers}",
                backend.name()
            );
            let context = RecordContext {
                study: "synthetic",
                manifest_hash: "m",
                build_id: "b",
                config_key: &key,
                scene: "seed-1000",
                scene_hash: "0123456789abcdef",
                scaling,
                backend,
                placement: backend.placement(workers),
                repetition,
                environment: &environment,
                study_started_utc: "2026-11-22T12:00:00Z",
            };
            let placement = backend.placement(workers);
            let (threads, ranks) = (placement.threads, placement.ranks);
            // Weak scaling: p workers do p times the work of one.
            let work = if scaling == "weak" { workers } else { 1 };
            let wall_s = times[repetition as usize] * work as f64;
            let mut record = Record::measured(
                &context,
                &summary(backend.name(), threads, ranks, 1000 * work, wall_s),
            );
            // Fixed, not this machine's: the load it was under when each run ended.
            record.load_average = 0.5 + 0.25 * f64::from(repetition);
            record.load_average_end = 0.75;
            records.push(record);
        }
    }
    records
}

/// An MPI study of one setup: 1 rank, 4 ranks of 1 thread and 2 ranks of 2 threads (4
/// workers each), three runs each; the runs of 2 × 2 end in `hybrid_hash`.
fn hybrid_records(hybrid_hash: &str) -> Vec<Record> {
    let mut records = placed_records(&[(1, 1, 1, 0.0100), (4, 1, 1, 0.0040), (2, 2, 1, 0.0020)]);
    for record in records.iter_mut().filter(|r| r.threads > 1) {
        record.state_hash = hybrid_hash.into();
    }
    records
}

/// An MPI study of one setup, three runs at each (ranks, threads per rank, nodes,
/// seconds) of `placements`, keyed as a manifest's `[placement]` keys them.
fn placed_records(placements: &[(usize, usize, usize, f64)]) -> Vec<Record> {
    let environment = environment();
    let mut records = Vec::new();
    for &(ranks, threads, nodes, wall_s) in placements {
        let entry = |name: &str, count: usize| match count {
            1 => String::new(),
            count => format!(";{name}={count}"),
        };
        let key = format!(
            "scene=seed-1000;n=-;packing=-;dt=-;steps=-;seed=-;broadphase=-;backend=mpi;\
             workers={ranks}{}{}",
            entry("nodes", nodes),
            entry("threads", threads)
        );
        for repetition in 0..3 {
            let context = RecordContext {
                study: "hybrid",
                manifest_hash: "m",
                build_id: "b",
                config_key: &key,
                scene: "seed-1000",
                scene_hash: "0123456789abcdef",
                scaling: "strong",
                backend: BackendKind::Mpi,
                placement: Placement { ranks, threads },
                repetition,
                environment: &environment,
                study_started_utc: "2026-11-22T12:00:00Z",
            };
            let run = summary("mpi", threads, ranks, 1000, wall_s);
            records.push(Record::measured(&context, &run));
        }
    }
    records
}

/// A setup's scaling curves: each one's label and its (workers, speedup) points.
fn curves_of(setup: &analysis::Setup) -> Vec<(String, Vec<(u64, f64)>)> {
    (setup.backends.iter())
        .map(|b| {
            let points = b.points.iter().map(|p| (p.workers, p.speedup)).collect();
            (b.label(), points)
        })
        .collect()
}

#[test]
fn ranks_spread_over_two_nodes_are_a_curve_of_their_own() {
    let records = placed_records(&[(1, 1, 1, 0.0100), (4, 1, 1, 0.0040), (4, 1, 2, 0.0050)]);
    let setups = analysis::analyse(&records).unwrap();
    assert_eq!(setups.len(), 1, "one setup: the nodes are not part of it");
    let curves = curves_of(&setups[0]);
    // Pooled, 4 ranks would be one point of 6 runs; apart, each has its median.
    assert_eq!(
        curves,
        [
            ("mpi".to_owned(), vec![(1, 1.0), (4, 2.5)]),
            ("mpi, 2 nodes".to_owned(), vec![(4, 2.0)])
        ]
    );
    let text = markdown(&records);
    assert!(text.contains("| mpi, 2 nodes | 4 | 2.00 |"), "{text}");
}

#[test]
fn mpi_ranks_of_two_threads_are_a_curve_of_their_own_never_pooled_with_one_thread_ranks() {
    let records = hybrid_records("51a3e11e31576e81");
    let setups = analysis::analyse(&records).unwrap();
    assert_eq!(
        setups.len(),
        1,
        "one setup: the placement is not part of it"
    );
    let curves = curves_of(&setups[0]);
    // Both start from one rank of one thread: 0.01 s.
    assert_eq!(
        curves,
        [
            ("mpi".to_owned(), vec![(1, 1.0), (4, 2.5)]),
            ("mpi, 2 threads/rank".to_owned(), vec![(4, 5.0)])
        ]
    );
    assert_eq!(setups[0].distinct_hashes, 1);
    let text = markdown(&records);
    assert!(
        text.contains("| mpi, 2 threads/rank | 4 | 5.00 |"),
        "{text}"
    );
    // The results table gives each placement its row, told apart by its threads.
    let table = collide::report::tables::summary(&records).unwrap();
    let rows: Vec<Vec<&str>> = (table.lines())
        .skip_while(|l| !l.starts_with("workers"))
        .take(4)
        .map(|l| l.split_whitespace().take(2).collect())
        .collect();
    assert_eq!(
        rows,
        [
            vec!["workers", "threads"],
            vec!["1", "1"],
            vec!["4", "1"],
            vec!["4", "2"]
        ],
        "{table}"
    );
    // A configuration whose runs all failed is placed as its runs would have been.
    let mut failed = hybrid_records("51a3e11e31576e81");
    for record in failed.iter_mut().filter(|r| r.threads == 2) {
        record.status = collide::study::records::STATUS_FAILED.to_owned();
    }
    let table = collide::report::configurations::Table::of(&failed).text();
    let all_failed: Vec<Vec<&str>> = (table.lines())
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .filter(|words| words.last() == Some(&"3"))
        .collect();
    assert_eq!(all_failed.len(), 1, "{table}");
    assert_eq!(all_failed[0][..2], ["4", "2"], "{table}");
    // The hash check names each run's placement.
    let disagree = collide::report::tables::summary(&hybrid_records("ffff")).unwrap();
    assert!(
        disagree.contains("ffff: mpi × 2 ranks × 2 threads")
            && disagree.contains("mpi × 1, mpi × 4"),
        "{disagree}"
    );
}

fn markdown(records: &[Record]) -> String {
    let setups = analysis::analyse(records).unwrap();
    let figures: Vec<Vec<(Figure, String)>> = setups
        .iter()
        .enumerate()
        .map(|(index, setup)| {
            Figure::ALL
                .iter()
                .filter(|f| f.shows(setup))
                .map(|&f| (f, format!("setup-{}-{}.png", index + 1, f.file_stem())))
                .collect()
        })
        .collect();
    let pictures = markdown::Pictures {
        figures,
        scene: Some("scene.png".into()),
        accuracy: None,
    };
    markdown::markdown(records, &setups, "results/synthetic/", &pictures)
}

#[test]
fn the_report_of_fixed_records_matches_its_snapshot() {
    insta::assert_snapshot!(markdown(&records()));
}

#[test]
fn every_figure_is_a_png_of_the_stated_size_with_each_backend_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let setups = analysis::analyse(&records()).unwrap();
    let drawn = scaling::draw_setup(&setups[0], dir.path(), "setup-1").unwrap();
    assert_eq!(drawn.len(), 4);
    for (figure, path) in drawn {
        let image = image::open(&path).unwrap().to_rgb8();
        assert_eq!(image.dimensions(), (900, 560), "{figure:?}");
        let count = |rgb: [u8; 3]| image.pixels().filter(|p| p.0 == rgb).count();
        // Each backend's colour, used in every figure: lines, markers and legend.
        for (backend, rgb) in [("rayon", [0x1f, 0x77, 0xb4]), ("mpi", [0xd6, 0x27, 0x28])] {
            assert!(
                count(rgb) > 200,
                "{figure:?}: {backend} barely drawn ({})",
                count(rgb)
            );
        }
        let white = count([255, 255, 255]);
        assert!(white < 900 * 560 * 98 / 100, "{figure:?} is nearly blank");
    }
}

/// [`records`] as if every step had been drawn, the drawing taking three times the
/// stepping: frames per second with drawing are a quarter of the steps per second.
fn drawn_records() -> Vec<Record> {
    let mut records = records();
    for record in &mut records {
        record.draw_s = 3.0 * record.wall_s;
        record.fps_with_drawing = record.steps as f64 / (record.wall_s + record.draw_s);
    }
    records
}

#[test]
fn drawn_runs_get_the_frames_per_second_figure_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let setups = analysis::analyse(&drawn_records()).unwrap();
    assert!(setups[0].drawn);
    let drawn = scaling::draw_setup(&setups[0], dir.path(), "setup-1").unwrap();
    assert_eq!(drawn.len(), 5);
    let (figure, path) = &drawn[4];
    assert_eq!(*figure, Figure::Drawing);
    assert!(path.ends_with("setup-1-fps-drawing.png"), "{path:?}");
    let image = image::open(path).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (900, 560));
    let count = |rgb: [u8; 3]| image.pixels().filter(|p| p.0 == rgb).count();
    // Each backend twice: frames with drawing, and steps without it (dashed).
    for (backend, rgb) in [
        ("serial", [0x33, 0x33, 0x33]),
        ("rayon", [0x1f, 0x77, 0xb4]),
        ("mpi", [0xd6, 0x27, 0x28]),
    ] {
        assert!(count(rgb) > 200, "{backend} barely drawn ({})", count(rgb));
    }

    let text = markdown(&drawn_records());
    assert!(text.contains("every step drawn offscreen"), "{text}");
    assert!(text.contains("frames/s with drawing |"), "{text}");
    // rayon at 2: median 0.0056 s for 400 steps, 71429 steps/s; drawing three times as
    // long, 400 / 0.0224 s = 17857 frames/s.
    assert!(
        text.contains("| rayon | 2 | 1.82 | 91% | 0.098 | 71429 | 17857 |"),
        "{text}"
    );
    assert!(text.contains("setup-1-fps-drawing.png"), "{text}");
    // Undrawn runs have no such figure or column.
    let plain = markdown(&records());
    assert!(
        !plain.contains("fps-drawing") && !plain.contains("with drawing"),
        "{plain}"
    );
}

#[test]
fn speedups_efficiencies_and_warnings_are_computed_from_the_medians() {
    let text = markdown(&records());
    // rayon at 2: S = 0.0102 / 0.0056 = 1.82, E = 91%; Karp–Flatt (1/1.82 − 1/2)/(1/2) = 0.098.
    assert!(
        text.contains("| rayon | 2 | 1.82 | 91% | 0.098 |"),
        "{text}"
    );
    // What the busiest MPI rank sent per step beside its timings (4.5 messages and 2 KiB
    // to each other rank); nothing for the other backends. Its Karp–Flatt, 1.235, lies
    // outside [0, 1]: not shown.
    assert!(
        text.contains("| mpi | 4 | 0.85 | 21% | — | 33333 | 13.5 | 6.0 |"),
        "{text}"
    );
    assert!(
        text.contains("| serial | 1 | 1.00 | 100% | — | 39216 | — | — |"),
        "{text}"
    );
    assert!(text.contains("Warning: oversubscribed"), "{text}");
    assert!(
        text.contains("mpi × 4") && text.contains("rayon × 4"),
        "{text}"
    );
    assert!(
        text.contains("falls below 75% at 4 workers (36%)"),
        "{text}"
    );
    assert!(text.contains("33.8 s"), "{text}");
    assert!(!text.contains("disagree"), "{text}");

    assert!(!text.contains("noisy"), "{text}");

    // One serial repetition twice as slow as the fastest: the medians stand, the report
    // says they were measured on a busy machine.
    let mut noisy = records();
    noisy[0].wall_s = 0.0200;
    noisy[0].load_average = 3.5;
    let text = markdown(&noisy);
    assert!(text.contains("Warning: noisy measurements"), "{text}");
    assert!(text.contains("reached 3.50 on 2 logical cores"), "{text}");
    assert!(
        text.contains("for serial × 1 (n = 1000, packing 0.050)"),
        "{text}"
    );

    let mut disagreeing = records();
    disagreeing[0].state_hash = "ffffffffffffffff".into();
    let text = markdown(&disagreeing);
    assert!(text.contains("Warning: backends disagree"), "{text}");
}

/// Every serial fraction a report prints ("f = …" of an Amdahl fit, a Karp–Flatt
/// column), as numbers.
fn serial_fractions(text: &str) -> Vec<f64> {
    let fits = text.split("f = ").skip(1).map(|rest| {
        let number: String = rest
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == '-')
            .collect();
        number.parse::<f64>().unwrap()
    });
    let karp_flatt = text
        .lines()
        .filter(|line| line.starts_with("| rayon |") || line.starts_with("| mpi |"))
        .filter_map(|line| line.split('|').nth(5)?.trim().parse::<f64>().ok());
    fits.chain(karp_flatt).collect()
}

#[test]
fn no_report_prints_a_serial_fraction_outside_zero_to_one_or_from_two_worker_counts() {
    // Rayon and MPI at 1, 2, 4: fits with f within [0, 1], with their residuals.
    let text = markdown(&records());
    let fractions = serial_fractions(&text);
    assert!(!fractions.is_empty(), "{text}");
    assert!(
        fractions.iter().all(|f| (0.0..=1.0).contains(f)),
        "{fractions:?}\n{text}"
    );
    assert!(text.contains("residuals 1: "), "{text}");
    // MPI at 4 three times slower than at 1: the least-squares f exceeds 1, not shown.
    let mut slower = records();
    for record in slower
        .iter_mut()
        .filter(|r| r.backend == "mpi" && r.workers == 4)
    {
        record.wall_s *= 3.0;
    }
    let text = markdown(&slower);
    let fractions = serial_fractions(&text);
    assert!(
        fractions.iter().all(|f| (0.0..=1.0).contains(f)),
        "{fractions:?}\n{text}"
    );
    assert!(
        text.contains("mpi: the least-squares serial fraction is"),
        "{text}"
    );
    // Only 1 and 2 workers: no serial fraction at all, and a sentence saying why.
    let two: Vec<Record> = records().into_iter().filter(|r| r.workers < 4).collect();
    let text = markdown(&two);
    assert_eq!(serial_fractions(&text), Vec::<f64>::new(), "{text}");
    assert!(text.contains("2 worker count(s), fewer than 3"), "{text}");
}

#[test]
fn runs_under_ten_milliseconds_are_flagged_and_medians_carry_an_interval() {
    let text = markdown(&records());
    // Serial: median 0.0102 of 0.0100, 0.0102, 0.0110, inside its bootstrap interval.
    // Every backend's column in milliseconds, the unit that fits its fastest run.
    assert!(
        text.contains("| workers | serial [ms] | rayon [ms] | mpi [ms] |"),
        "{text}"
    );
    assert!(
        text.contains("| 10.2 [10.0, 11.0] (10.0–11.0, 3 runs)"),
        "{text}"
    );
    // Rayon at 2 takes 5.6 ms: too short to time well.
    assert!(
        text.contains("5.6 [5.5, 6.0] (5.5–6.0, 3 runs) ⏱"),
        "{text}"
    );
    assert!(text.contains("run more steps"), "{text}");
}

#[test]
fn render_draws_the_disks_as_a_png_and_the_run_as_a_gif() {
    use image::AnimationDecoder;

    let dir = tempfile::tempdir().unwrap();
    let (png, gif) = (dir.path().join("scene.png"), dir.path().join("run.gif"));
    let out = crate::util::collide(&[
        "render",
        "experiments/scenes/seed-1000.toml",
        "--n",
        "2000",
        "--steps",
        "40",
        "--frames",
        "5",
        "--png",
        png.to_str().unwrap(),
        "--gif",
        gif.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let picture = image::open(&png).unwrap().to_rgb8();
    // A square box: 800 pixels and a 10-pixel margin each side, and the colour key below.
    assert_eq!(picture.dimensions(), (820, 860));
    // The key's bar runs from blue (at rest) to red (twice the rms speed) under the box.
    let key_row = 860 - 40 + 6;
    let blue = picture.get_pixel(11, key_row).0;
    let red = picture.get_pixel(10 + 239, key_row).0;
    assert!(blue[2] > 200 && blue[0] < 60, "{blue:?}");
    assert!(red[0] > 220 && red[2] < 60, "{red:?}");
    let coloured = picture.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    // 2000 disks at packing 0.05 cover about 5% of the box, plus its outline.
    assert!(coloured > 800 * 800 / 40, "only {coloured} coloured pixels");
    let file = std::fs::File::open(&gif).unwrap();
    let frames = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(file))
        .unwrap()
        .into_frames()
        .count();
    assert_eq!(frames, 5);
}

#[test]
fn weak_scaling_efficiency_is_the_one_worker_time_over_the_p_worker_time() {
    let records = study_records("weak");
    let text = markdown(&records);
    // One setup, keyed by n per worker, though n differs at every worker count.
    assert_eq!(text.matches("### Speedup").count(), 1, "{text}");
    assert!(text.contains("weak scaling, n = 1000 × workers"), "{text}");
    // rayon at 2: E = T(1, 1000) / T(2, 2000) = 0.0102 / 0.0112 = 91%, scaled speedup 2·E.
    assert!(text.contains("| rayon | 2 | 1.82 | 91% | — |"), "{text}");
    assert!(text.contains("Gustafson"), "{text}");
    assert!(!text.contains("Amdahl fit"), "{text}");
}

/// Writes `records` as a Parquet file in `dir`, after `edit` changed the table.
fn parquet_with(
    dir: &std::path::Path,
    records: &[Record],
    edit: impl FnOnce(&mut polars::prelude::DataFrame),
) -> std::path::PathBuf {
    use polars::prelude::ParquetWriter;
    let mut frame = collide::study::records::to_frame(records).unwrap();
    edit(&mut frame);
    let path = dir.join("study.parquet");
    let file = std::fs::File::create(&path).unwrap();
    ParquetWriter::new(file).finish(&mut frame).unwrap();
    path
}

#[test]
fn a_file_written_by_schema_version_1_is_reported_as_timed_strong_scaling() {
    // A real file of the seed-report study, written by the collide of schema version 1
    // (no scaling, method or accuracy columns).
    let dir = tempfile::tempdir().unwrap();
    let out = crate::util::collide(&[
        "report",
        "tests/fixtures/schema-1-seed-report.parquet",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(
        text.contains("| workers | serial [")
            && text.contains("] | rayon [")
            && text.contains("] | mpi ["),
        "{text}"
    );
    assert!(text.contains("Every run ended in the same state"), "{text}");
    assert!(!text.contains("weak scaling"), "{text}");
}

#[test]
fn a_file_missing_a_measured_column_or_from_a_newer_collide_is_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    type Damage = Box<dyn FnOnce(&mut polars::prelude::DataFrame)>;
    let cases: [(&str, Damage); 2] = [
        (
            "no `wall_s` column",
            Box::new(|frame| {
                frame.drop_in_place("wall_s").unwrap();
            }),
        ),
        (
            "newer than this collide",
            Box::new(|frame| {
                let version = polars::prelude::Column::new(
                    "schema_version".into(),
                    vec![99u32; frame.height()],
                );
                frame.with_column(version).unwrap();
            }),
        ),
    ];
    for (reason, edit) in cases {
        let path = parquet_with(dir.path(), &records(), edit);
        let out = crate::util::collide(&[
            "report",
            path.to_str().unwrap(),
            "--out",
            dir.path().to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains(reason) && stderr.contains("study.parquet"),
            "{stderr}"
        );
    }
}

/// An accuracy study from the fixed records: at packings 0.05 and 0.4, the event
/// reference and the step method at v_rms·dt/r = 1, 0.1 and 0.01, whose missed
/// fraction and pressure error shrink with dt (1 and 0.1 fail, 0.01 passes).
fn accuracy_records() -> Vec<Record> {
    let template = serial_record();
    let mut out = Vec::new();
    for packing in [0.05, 0.4] {
        for (method, dt, missed, z_factor, wall_s) in [
            ("event", 0.1, 0.0, 1.0, 0.05),
            ("step", 1.0, 0.2, 0.6, 0.004),
            ("step", 0.1, 0.004, 0.95, 0.03),
            ("step", 0.01, 0.0002, 0.995, 0.3),
        ] {
            let mut record = template.clone();
            record.method = method.into();
            record.observe = if method == "step" {
                "accuracy"
            } else {
                "timing"
            }
            .into();
            record.packing = packing;
            record.dt = dt;
            record.steps = (10.0 / dt).round() as u64;
            record.rms_step_over_radius = dt;
            // Denser gases take longer, so the packings' curves do not overlap.
            record.wall_s = wall_s * (1.0 + 4.0 * packing);
            record.missed_collision_fraction = missed;
            record.max_overlap = dt.min(1.0);
            record.max_wall_penetration = 2.0 * dt;
            record.compressibility_z = (1.0 + 4.0 * packing) * z_factor;
            record.collision_rate = (0.1 + packing) * z_factor;
            // An energy error growing with dt (none recorded for the event reference).
            record.energy_relative_error = match method {
                "step" => -0.1 * dt,
                _ => f64::NAN,
            };
            out.push(record);
        }
    }
    out
}

#[test]
fn the_accuracy_report_tabulates_errors_and_draws_the_pareto_and_stability_figures() {
    use collide::report::accuracy;
    use collide::report::figures::{self, pareto::Pareto, stability::Stability};
    let records = accuracy_records();
    assert!(accuracy::is_accuracy_study(&records));
    assert!(!accuracy::is_accuracy_study(&self::records()));
    let groups = accuracy::analyse(&records);
    let dir = tempfile::tempdir().unwrap();
    let pareto = figures::write(&Pareto(&groups), dir.path()).unwrap();
    let stability = figures::write(&Stability(&groups), dir.path()).unwrap();
    let count =
        |image: &image::RgbImage, rgb: [u8; 3]| image.pixels().filter(|p| p.0 == rgb).count();
    let pareto = image::open(&pareto).unwrap().to_rgb8();
    assert_eq!(pareto.dimensions(), (2000, 600));
    // Both packings' curves (the palette's blue and red) are drawn.
    let blue = count(&pareto, [0x1f, 0x77, 0xb4]);
    let red = count(&pareto, [0xd6, 0x27, 0x28]);
    assert!(blue > 200 && red > 200, "blue {blue}, red {red}");
    let stability = image::open(&stability).unwrap().to_rgb8();
    assert_eq!(stability.dimensions(), (1100, 560));
    // Six cells (two packings × three steps) in colours from green to red, and the
    // failure boundary in black.
    let white = count(&stability, [255, 255, 255]);
    assert!(white < 1100 * 560 / 2, "mostly blank: {white} white pixels");
    assert!(count(&stability, [0, 0, 0]) > 500);
    // One packing alone (a study without a packing sweep) still fills its row of cells.
    let one_packing = accuracy::analyse(&records[..4]);
    assert_eq!(one_packing.len(), 1);
    let one_row = dir.path().join("one-row");
    std::fs::create_dir(&one_row).unwrap();
    let one_row = figures::write(&Stability(&one_packing), &one_row).unwrap();
    let one_row = image::open(&one_row).unwrap().to_rgb8();
    let white = count(&one_row, [255, 255, 255]);
    assert!(
        white < 1100 * 560 * 3 / 4,
        "cells not drawn: {white} white pixels"
    );
    let pictures = markdown::Pictures {
        accuracy: Some(markdown::AccuracySection {
            groups,
            figures: vec![
                "accuracy-pareto.png".into(),
                "accuracy-stability.png".into(),
            ],
            cooling: Vec::new(),
        }),
        ..Default::default()
    };
    let setups = analysis::analyse(&records).unwrap();
    let text = markdown::markdown(&records, &setups, "results/accuracy/", &pictures);
    assert!(text.starts_with("# Accuracy report"), "{text}");
    assert!(text.contains("### Packing 0.40"), "{text}");
    // dt = 0.1 at packing 0.4: simulated time 10 in 0.03·2.6 s, Z = 2.6·0.95 against 2.6
    // (a −5% error), and it fails (4e-3 missed > 1e-3) and goes 0.2 r into the walls
    // (flagged above 0.1 r).
    assert!(
        text.contains(
            "| step | 0.1 | 0.100 | 0.0780 | 128.2 | 4.000e7 | **4.00e-3** | 0.100 | **0.200** | 2.4700 | -5.00% |"
        ),
        "{text}"
    );
    assert!(
        text.contains("| 2.00e-4 | 0.010 | 0.020 | 2.5870 |"),
        "{text}"
    );
    assert!(
        text.contains("The step method fails at v_rms·dt/r ≥ 0.100"),
        "{text}"
    );
    // Each row ends in its energy error: the step's, and a dash for the reference.
    assert!(text.contains("| ω error | ΔE/E |"), "{text}");
    assert!(text.contains("| -1.0e-2 |\n"), "{text}");
    assert!(text.contains("| reference | — |\n"), "{text}");
    assert!(text.contains("![accuracy-stability.png](accuracy-stability.png)"));
    // One run per setup: no scaling sections.
    assert!(!text.contains("Time per run"), "{text}");
}

#[test]
fn the_report_says_what_method_and_dt_auto_chose() {
    let mut records = records();
    for record in &mut records {
        record.choice = "method auto: event, cheaper".into();
    }
    let text = markdown(&records);
    assert_eq!(
        text.matches("> **Chosen automatically** for scene").count(),
        1,
        "once per scene and choice: {text}"
    );
    assert!(text.contains("method auto: event, cheaper"), "{text}");
}

/// A cooling curve as JSON text: T = 0.5/(1 + rate·t/10)² at t = 0, 0.5, … (`samples`
/// of them after t = 0), every other point raised by the fraction `wobble`.
fn haff_curve(rate: f64, wobble: f64, samples: usize) -> String {
    let points: Vec<[f64; 2]> = (0..=samples)
        .map(|i| {
            let t = 0.5 * i as f64;
            [
                t,
                0.5 * (1.0 + wobble * (i % 2) as f64) / (1.0 + rate * t / 10.0).powi(2),
            ]
        })
        .collect();
    serde_json::to_string(&points).unwrap()
}

/// The markdown report of a cooling study's records with its accuracy section.
fn cooling_report(records: &[Record], section: markdown::AccuracySection) -> String {
    let pictures = markdown::Pictures {
        figures: Vec::new(),
        scene: None,
        accuracy: Some(section),
    };
    let setups = analysis::analyse(records).unwrap();
    markdown::markdown(records, &setups, "results/cooling/", &pictures)
}

/// A successful serial record of the fixed set, to vary.
fn serial_record() -> Record {
    records()
        .into_iter()
        .find(|r| r.backend == "serial")
        .unwrap()
}

#[test]
fn the_cooling_report_says_whether_and_when_each_run_broke_down_and_marks_the_collapse() {
    use collide::report::accuracy::{self, Breakdown};
    use collide::report::figures::{self, cooling::Cooling};
    let template = serial_record();
    // Two event runs at the same dt that differ only in tc: the guarded one follows
    // Haff's law (t₀ = 10) to t = 20; the unguarded one wobbles 10% about it and
    // collapsed at t = 12, where its curve ends. The large step cools twice as fast.
    let mut records = Vec::new();
    for (method, tc, collapse, text) in [
        ("event", 0.0, 12.0, haff_curve(1.0, 0.1, 24)),
        ("step", f64::NAN, f64::NAN, haff_curve(2.0, 0.0, 40)),
        ("event", 1e-4, f64::NAN, haff_curve(1.0, 0.0, 40)),
    ] {
        let mut record = template.clone();
        record.method = method.into();
        record.dt = 0.5;
        record.packing = 0.1;
        record.rms_step_over_radius = 0.5;
        record.tc = tc;
        record.collapse_time = collapse;
        record.temperature_curve = text;
        records.push(record);
    }
    let curves = accuracy::cooling(&records);
    let order: Vec<(&str, f64)> = curves.iter().map(|c| (c.method.as_str(), c.tc)).collect();
    assert_eq!(order.len(), 3, "runs differing in tc stay apart: {order:?}");
    assert_eq!((order[0], order[1].1), (("event", 1e-4), 0.0));
    // t₀ comes from the guarded run, not the collapsed one.
    assert!((curves[0].haff_t0 - 10.0).abs() < 1e-9);
    assert_eq!(curves[0].breakdown(), None);
    assert_eq!(
        curves[1].breakdown(),
        Some(Breakdown::Collapse { time: 12.0 })
    );
    // The large step is 5.1% off at t = 0.5 already: ((1 + 0.05)/(1 + 0.1))² = 0.911.
    assert_eq!(
        curves[2].breakdown(),
        Some(Breakdown::OffHaff { time: 0.5 })
    );

    // The collapsed run (the palette's red) ends in a cross: drawn without its collapse
    // time (the same points, dashed all the same since they are 10% off Haff's law) the
    // chart has fewer red pixels.
    let red_pixels = |curves: &[accuracy::CoolingCurve]| {
        let dir = tempfile::tempdir().unwrap();
        let path = figures::write(&Cooling(curves), dir.path()).unwrap();
        let image = image::open(&path).unwrap().to_rgb8();
        image.pixels().filter(|p| p.0 == [0xd6, 0x27, 0x28]).count()
    };
    let mut unmarked = curves.clone();
    unmarked[1].collapse_time = f64::NAN;
    let (marked, plain) = (red_pixels(&curves), red_pixels(&unmarked));
    assert!(
        marked > plain + 50,
        "{marked} red pixels with the cross, {plain} without"
    );

    let section = markdown::AccuracySection {
        groups: accuracy::analyse(&records),
        figures: Vec::new(),
        cooling: curves,
    };
    let event_rows: Vec<String> = section.groups[0]
        .events
        .iter()
        .map(|p| accuracy::method_label(&p.method, p.tc))
        .collect();
    assert_eq!(event_rows, ["event, tc = 0"]);
    let text = cooling_report(&records, section);
    for row in [
        "| 0.10 | event, tc = 0.0001 | 0.5 | 0.500 | 2.000 | 0.1111 | 0.1111 | 0.00% | — | no (to t/t₀ = 2.000) |",
        "| 0.10 | event, tc = 0 | 0.5 | 0.500 | 1.200 | 0.2066 | 0.2066 | **10.00%** | — | **collapsed at t/t₀ = 1.200** (t = 12.0000) |",
        "| 0.10 | step | 0.5 | 0.500 | 2.000 | 0.0400 | 0.1111 | **64.00%** | — | **off Haff by > 5% from t/t₀ = 0.050** |",
        "| event, tc = 0.0001 | exact | — |",
        "| event, tc = 0, **collapsed at t = 12.0000** | exact | — |",
    ] {
        assert!(text.contains(row), "missing {row}\n{text}");
    }
}

#[test]
fn the_cooling_chart_compares_each_method_with_haffs_law_and_marks_breakdowns() {
    use collide::report::accuracy;
    use collide::report::figures::{self, cooling::Cooling};
    let template = serial_record();
    // The event run follows Haff's law with t₀ = 10 exactly; the small step within 1%;
    // the large step loses energy twice as fast (T₀/(1 + 2t/t₀)²): a breakdown.
    let curve = |rate: f64, wobble: f64| haff_curve(rate, wobble, 40);
    let mut records = Vec::new();
    for (method, dt, text) in [
        ("step", 0.5, curve(2.0, 0.0)),
        ("event", 0.5, curve(1.0, 0.0)),
        ("step", 0.01, curve(1.0, 0.01)),
    ] {
        let mut record = template.clone();
        record.method = method.into();
        record.dt = dt;
        record.packing = 0.1;
        record.rms_step_over_radius = dt;
        record.temperature_curve = text;
        records.push(record);
    }
    let curves = accuracy::cooling(&records);
    let methods: Vec<(&str, f64)> = curves.iter().map(|c| (c.method.as_str(), c.dt)).collect();
    assert_eq!(methods, [("event", 0.5), ("step", 0.5), ("step", 0.01)]);
    assert!(
        (curves[0].haff_t0 - 10.0).abs() < 1e-9,
        "{}",
        curves[0].haff_t0
    );
    assert!(curves[0].haff_deviation < 1e-12 && !curves[0].broke_down());
    assert!(curves[1].broke_down(), "{}", curves[1].haff_deviation);
    assert!(!curves[2].broke_down(), "{}", curves[2].haff_deviation);
    let dir = tempfile::tempdir().unwrap();
    let path = figures::write(&Cooling(&curves), dir.path()).unwrap();
    assert!(path.ends_with("accuracy-cooling.png"));
    let image = image::open(&path).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (1400, 620));
    let count = |rgb: [u8; 3]| image.pixels().filter(|p| p.0 == rgb).count();
    // Haff's law in black and the first two curves in the palette's blue and red.
    assert!(count([0, 0, 0]) > 1000, "Haff's law drawn");
    assert!(count([0x1f, 0x77, 0xb4]) > 200 && count([0xd6, 0x27, 0x28]) > 100);
    let section = markdown::AccuracySection {
        groups: accuracy::analyse(&records),
        figures: Vec::new(),
        cooling: curves,
    };
    let text = cooling_report(&records, section);
    assert!(text.contains("## Cooling (e < 1)"), "{text}");
    assert!(
        text.contains("![accuracy-cooling.png](accuracy-cooling.png)"),
        "{text}"
    );
    // Only the large step's deviation is bold.
    assert_eq!(text.matches("%** |").count(), 1, "{text}");
}

/// The scaling prediction of fixed records: its section names the network it assumed
/// and the extrapolation factor, and its figure is drawn.
#[test]
fn the_prediction_of_an_mpi_study_says_what_it_assumed_and_is_drawn() {
    use collide::cluster::network::assumed_band;
    use collide::report::figures::{self, prediction::FILE_NAME};
    use collide::report::prediction;
    let records = records();
    let predicted = prediction::predict(&records, &assumed_band()).unwrap();
    let text = prediction::markdown(&predicted, Some(FILE_NAME));
    assert!(text.contains("assumed network (none measured)"), "{text}");
    assert!(
        text.contains("10000 predicted ranks / 4 measured = 2500×"),
        "{text}"
    );
    let dir = tempfile::tempdir().unwrap();
    let analysed = figures::Analysed {
        prediction: Some(&predicted),
        ..Default::default()
    };
    let drawn = figures::draw(&analysed, dir.path()).unwrap();
    assert_eq!(drawn.0.len(), 1);
    assert!(dir.path().join(FILE_NAME).is_file());
}

/// [`accuracy_records`] with the configuration keys an accuracy manifest gives them:
/// packing, dt, steps, method and observe swept, the rest the scene's.
fn keyed_accuracy_records() -> Vec<Record> {
    let mut records = accuracy_records();
    for record in &mut records {
        record.config_key = format!(
            "scene=gas;n=-;packing={};dt={};steps={};seed=-;broadphase=-;backend=serial;workers=1;method={};observe={}",
            record.packing, record.dt, record.steps, record.method, record.observe
        );
    }
    records
}

#[test]
fn the_results_table_has_a_column_for_each_swept_setting_and_a_line_for_the_rest() {
    use collide::report::configurations::Table;

    let text = Table::of(&keyed_accuracy_records()).text();
    let mut lines = text.lines();
    let constants = lines.next().unwrap();
    assert!(constants.starts_with("Every run:"), "{text}");
    for shared in [
        "backend = serial",
        "workers = 1",
        "n = 1000",
        "seed = 12345",
    ] {
        assert!(constants.contains(shared), "{shared}: {text}");
    }
    let header: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
    assert_eq!(
        header[..5],
        ["packing", "dt", "steps", "method", "observe"],
        "{text}"
    );
    for constant in ["backend", "workers", "n", "seed", "broadphase", "scene"] {
        assert!(
            !header.contains(&constant),
            "{constant} is a column: {text}"
        );
    }
    // One row per configuration, the event method's told apart from the step's.
    let rows: Vec<&str> = lines.take_while(|l| !l.starts_with('⏱')).collect();
    assert_eq!(rows.len(), 8, "{text}");
    assert!(
        rows[0].split_whitespace().collect::<Vec<_>>()[..5]
            == ["0.05", "0.1", "100", "event", "timing"],
        "{text}"
    );
    // Times in the unit of each column's fastest: 4.8 ms (step, dt = 1, packing 0.05).
    assert!(rows[1].contains("4.8 ms"), "{text}");
    assert!(rows[3].contains("360.0 ms"), "{text}");
}

#[test]
fn the_results_table_of_drawn_runs_shows_frames_per_second_with_drawing() {
    use collide::report::configurations::Table;

    let text = Table::of(&drawn_records()).text();
    let header = text.lines().nth(1).unwrap();
    assert!(header.contains("frames/s with drawing"), "{text}");
    // rayon at 2: 400 steps in 5.6 ms, drawn in three times that: 17857 frames/s.
    let row = text
        .lines()
        .find(|l| l.starts_with("rayon") && l.contains(" 2 "))
        .unwrap();
    assert!(row.contains("71429") && row.contains("17857"), "{text}");
    assert!(!Table::of(&records()).text().contains("with drawing"));
}

#[test]
fn the_results_export_as_csv_and_json_with_every_setting_and_units_in_the_names() {
    use collide::report::configurations::Table;

    let table = Table::of(&records());
    let json: serde_json::Value = serde_json::from_str(&table.json()).unwrap();
    let rows = json.as_array().unwrap();
    assert_eq!(rows.len(), 7, "{json}");
    let serial = &rows[0];
    assert_eq!(serial["backend"], "serial");
    assert_eq!(serial["workers"], 1);
    // Constant settings too: a script needs no header line.
    assert_eq!(serial["n"], 1000);
    assert_eq!(serial["study"], "synthetic");
    assert_eq!(serial["median_s"], 0.0102);
    assert_eq!(serial["repetitions"], 3);
    assert!(serial["fps_with_drawing"].is_null(), "{serial}");

    let csv = table.csv();
    let lines: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(lines.len(), 8, "{csv}");
    assert!(lines.iter().all(|l| l.len() == lines[0].len()), "{csv}");
    let column = |name: &str| lines[0].iter().position(|h| *h == name).unwrap();
    for name in [
        "median_s",
        "median_ci_low_s",
        "min_s",
        "max_s",
        "steps_per_s",
    ] {
        column(name);
    }
    let rayon_2 = lines
        .iter()
        .find(|l| l[column("backend")] == "rayon" && l[column("workers")] == "2")
        .unwrap();
    assert_eq!(rayon_2[column("median_s")].parse::<f64>().unwrap(), 0.0056);
    // Not measured: empty.
    assert_eq!(rayon_2[column("fps_with_drawing")], "");

    let markdown = table.markdown();
    let lines: Vec<&str> = markdown.lines().collect();
    assert!(
        lines[0].starts_with("Every run: study = synthetic"),
        "{markdown}"
    );
    assert!(
        lines[2].starts_with("| backend | workers | median |"),
        "{markdown}"
    );
    assert!(lines[3].starts_with("| --- | ---: | ---: |"), "{markdown}");
    assert_eq!(
        lines[4],
        "| serial | 1 | 10.2 ms | 10.0–11.0 ms | 10.0–11.0 ms | 3 | 0 |"
    );
}

/// Seeds 1 to 4 of one setup, each with Z and the collision rate after its cut and
/// blocked error bars `se_scale` times those of the worked example in docs/accuracy.md;
/// beside them a rayon run of seed 1 (the same numbers: counted once), a seed 5 that
/// did not equilibrate (left out), a failed run of seed 6, and a second setup (another
/// dt) run with one seed only (no replicas).
fn replica_records(se_scale: f64) -> Vec<Record> {
    let template = serial_record();
    let z = [6.46555, 6.44791, 6.45851, 6.45827];
    let z_se = [0.00658, 0.00614, 0.00532, 0.00580];
    let rate = [4.3555, 4.3480, 4.3541, 4.3505];
    let rate_se = [0.0045, 0.0043, 0.0041, 0.0046];
    let seeded = |seed: u64, dt: &str| {
        let mut record = template.clone();
        record.seed = Some(seed);
        record.config_key = template
            .config_key
            .replace("seed=-", &format!("seed={seed}"))
            .replace("dt=-", &format!("dt={dt}"));
        record
    };
    let mut out = Vec::new();
    for (index, seed) in (1..=4).enumerate() {
        let mut record = seeded(seed, "-");
        record.compressibility_z = z[index];
        record.compressibility_z_se = se_scale * z_se[index];
        record.collision_rate = rate[index];
        record.collision_rate_se = se_scale * rate_se[index];
        out.push(record);
    }
    let mut copy = out[0].clone();
    copy.backend = "rayon".into();
    copy.config_key = copy.config_key.replace("backend=serial", "backend=rayon");
    out.push(copy);
    let mut unsettled = seeded(5, "-");
    (unsettled.compressibility_z, unsettled.compressibility_z_se) = (7.0, f64::NAN);
    out.push(unsettled);
    let mut failed = out[0].clone();
    (failed.seed, failed.status) = (Some(6), "failed".into());
    out.push(failed);
    let mut alone = out[0].clone();
    alone.config_key = seeded(1, "0.05").config_key;
    out.push(alone);
    out
}

#[test]
fn the_spread_over_seeds_is_reported_and_recorded_beside_the_runs_own_error_bars() {
    use collide::study::{records, replicas};
    let records = replica_records(1.0);
    let groups = replicas::checks(&records);
    assert_eq!(groups.len(), 1, "{groups:?}");
    let group = &groups[0].1;
    assert_eq!(group.seeds, [1, 2, 3, 4]);
    // By hand: the mean of the four, s/√4, and √(Σ SE²)/4.
    let z = &records[..4];
    let mean = z.iter().map(|r| r.compressibility_z).sum::<f64>() / 4.0;
    let s2 = z
        .iter()
        .map(|r| (r.compressibility_z - mean).powi(2))
        .sum::<f64>()
        / 3.0;
    let within = z
        .iter()
        .map(|r| r.compressibility_z_se.powi(2))
        .sum::<f64>()
        .sqrt()
        / 4.0;
    let check = group.checks[0];
    assert!((check.replica.mean - mean).abs() < 1e-12);
    assert!((check.replica.se - s2.sqrt() / 2.0).abs() < 1e-12);
    assert!((check.replica.half_width_95 - 3.182 * s2.sqrt() / 2.0).abs() < 1e-12);
    assert!((check.within_se - within).abs() < 1e-12);
    assert!(!group.checks.iter().any(|c| c.disagrees()), "{group:?}");
    let text = markdown(&records);
    assert!(
        text.contains("## Replicas: the spread over seeds"),
        "{text}"
    );
    assert!(
        text.contains(
            "| seed-1000 n=1000 | 1, 2, 3, 4 | Z | 6.45756 ± 0.00363 | ± 0.0116 | 0.00299 | 1.2 |"
        ),
        "{text}"
    );
    assert!(!text.contains("error bars disagree"), "{text}");
    // The records carry it in every successful row of the setup, through Parquet.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.parquet");
    records::write(&path, &records).unwrap();
    let read = records::read(&path).unwrap();
    for (index, row) in read.iter().enumerate() {
        let replicated = index < 6;
        assert_eq!(row.replicas, replicated.then_some(4), "row {index}");
        assert_eq!(
            row.compressibility_z_replica_se.is_finite(),
            replicated,
            "row {index}"
        );
    }
    assert_eq!(read[2].compressibility_z_replica_mean, check.replica.mean);
    assert_eq!(read[2].compressibility_z_replica_se, check.replica.se);
    assert_eq!(
        read[3].collision_rate_replica_se,
        group.checks[1].replica.se
    );
}

#[test]
fn error_bars_that_disagree_with_the_spread_over_seeds_are_flagged_either_way() {
    // Error bars ten times too small: the spread is 12× the runs' own SE.
    let text = markdown(&replica_records(0.1));
    assert!(
        text.contains(
            "> **Warning: error bars disagree with the spread over seeds.** Z of seed-1000 \
             n=1000 over 4 seeds: replica SE 0.00363, 12× the within-run SE 0.000299; the \
             runs' blocked error bars are too small"
        ),
        "{text}"
    );
    assert!(text.contains("| **12** |"), "{text}");
    // Ten times too large: the seeds agree better than their error bars say.
    let text = markdown(&replica_records(10.0));
    assert!(text.contains("Z of seed-1000 n=1000 over 4 seeds: replica SE 0.00363, 0.12×"));
    assert!(text.contains("the seeds agree better than their error bars say"));
}
