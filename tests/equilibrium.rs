//! The equilibration cut, the error bars and the reference comparison of a run's
//! pressure, end to end: a dense lattice start melts, the cut removes the melting, and
//! the rest agrees with the equation of state within its error bar; a run too short to
//! settle says so instead of printing a number.

use crate::util::{collide, json_summary, scene_file};

/// 1024 equal disks on a square lattice at `packing` in a periodic box (the event
/// method, T = 0.5), over `steps` intervals of `dt`.
fn dense_lattice(dir: &std::path::Path, packing: f64, dt: f64, steps: u64) -> String {
    let text = format!(
        "[scene]\nn = 1024\npacking = {packing}\nradius = 1.0\nmass = 1.0\nspeed_rms = 1.0\n\
         boundary = \"periodic\"\nplacement = \"lattice\"\nseed = 1\n\n\
         [method]\nmethod = \"event\"\ndt = {dt}\nsteps = {steps}\n"
    );
    let path = scene_file(dir, "dense.toml", &text);
    path.to_str().unwrap().to_owned()
}

#[test]
fn a_melted_lattice_agrees_with_luding_within_its_error_bar() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dense_lattice(dir.path(), 0.6, 1.0, 500);
    let json = json_summary(&["simulate", &scene]);
    assert_eq!(json["equilibrated"], true, "{json}");
    let cut = json["equilibration_cut_time"].as_f64().unwrap();
    // The lattice melts within a few units of time; the cut removes that, not the run.
    assert!(cut > 0.0 && cut < 250.0, "cut at {cut}");
    let z = json["compressibility_z"].as_f64().unwrap();
    let se = json["compressibility_z_se"].as_f64().unwrap();
    let z_ref = json["z_reference"].as_f64().unwrap();
    let se_ref = json["z_reference_se"].as_f64().unwrap();
    assert!(
        json["z_reference_source"]
            .as_str()
            .unwrap()
            .starts_with("Luding")
    );
    let score = (z - z_ref) / (se * se + se_ref * se_ref).sqrt();
    assert!(
        score.abs() < 3.0,
        "Z = {z} ± {se} against {z_ref} ± {se_ref}"
    );
    // A real error bar: a fraction of a percent, from more than a few blocks.
    assert!(se > 0.0 && se < 0.01 * z, "SE {se}");
    assert!(json["compressibility_z_g"].as_f64().unwrap() >= 1.0);
    assert!(json["compressibility_z_n_eff"].as_f64().unwrap() > 20.0);
}

#[test]
fn a_run_too_short_to_melt_says_so_instead_of_printing_a_number() {
    let dir = tempfile::tempdir().unwrap();
    // At packing 0.72 the lattice melts over t ≈ 100: a run to t = 40 is transient
    // throughout.
    let scene = dense_lattice(dir.path(), 0.72, 0.5, 80);
    let json = json_summary(&["simulate", &scene]);
    assert_eq!(json["equilibrated"], false, "{json}");
    assert!(json["compressibility_z_se"].is_null());
    assert!(json["equilibration_cut_time"].is_null());
    let out = collide(&["simulate", &scene]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("not equilibrated: run longer"), "{text}");
    assert!(!text.contains("z-score"), "{text}");
}
