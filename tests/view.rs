//! The live view: its window shows the offscreen frame pixel for pixel, a run with the
//! view reaches the state `collide simulate` reaches after the same steps, and without a
//! display it says what to do instead.
//!
//! The window tests need an X display. Without `DISPLAY` they run themselves again under
//! `xvfb-run`; with neither they fail (a CI machine without xvfb must not pass them).

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use x11rb::protocol::xproto::{ConnectionExt, ImageFormat};

use collide::draw::raster::{Frame, View, draw};
use collide::sim::scene::GasSpec;
use collide::sim::snapshot::Snapshot;
use collide::view::status::{STATUS_ROWS, StatusFont};
use collide::view::window::Screen;

use crate::util::{collide, json_summary};

/// Set in the environment of a test run again under xvfb-run.
const UNDER_XVFB: &str = "COLLIDE_TEST_UNDER_XVFB";

/// Whether the test `name` (its path in the test binary) should run here: yes when there
/// is a display; otherwise it is run again under xvfb-run (asserting that it passed there)
/// and need not run here. Panics when there is neither a display nor xvfb-run.
fn runs_here(name: &str) -> bool {
    if std::env::var_os("DISPLAY").is_some_and(|display| !display.is_empty()) {
        return true;
    }
    assert!(
        std::env::var_os(UNDER_XVFB).is_none(),
        "xvfb-run started {name} without a DISPLAY"
    );
    let xvfb_run = std::env::var_os("PATH").and_then(|path| {
        std::env::split_paths(&path)
            .map(|dir| dir.join("xvfb-run"))
            .find(|candidate| candidate.is_file())
    });
    let Some(xvfb_run) = xvfb_run else {
        panic!(
            "{name} needs an X display: DISPLAY is not set and xvfb-run is not installed; \
             install it with xauth, which xvfb-run needs (apt-get install xvfb xauth), or run \
             the tests on a display"
        );
    };
    let status = Command::new(xvfb_run)
        .args(["-a", "-s", "-screen 0 1280x1024x24"])
        .arg(std::env::current_exe().unwrap())
        .args([name, "--exact", "--test-threads", "1", "--nocapture"])
        .env(UNDER_XVFB, "1")
        .status()
        .expect("xvfb-run starts");
    assert!(status.success(), "{name} failed under xvfb-run");
    false
}

#[test]
fn the_window_shows_the_offscreen_frame_pixel_for_pixel() {
    if !runs_here("view::the_window_shows_the_offscreen_frame_pixel_for_pixel") {
        return;
    }
    let scene = GasSpec {
        seed: 7,
        ..GasSpec::unit(3000, 0.2)
    }
    .build()
    .unwrap();
    let mut snapshot = Snapshot::default();
    snapshot.fill_from(&scene.particles, 2.0);
    let (width, height) = (240, 200);
    let view = View::whole_box(width, height, scene.domain.width, scene.domain.height);
    let mut frame = Frame::with_status_rows(STATUS_ROWS);
    draw(&snapshot, &view, &mut frame);
    StatusFont::default().write(&mut frame, "3000 disks, read back");
    let rows = height + STATUS_ROWS;

    let mut screen = Screen::open("collide view test", width, rows).unwrap();
    for _ in 0..5 {
        screen.present(&frame).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    let (connection, _) = x11rb::connect(None).unwrap();
    let image = connection
        .get_image(
            ImageFormat::Z_PIXMAP,
            screen.x11_window_id(),
            0,
            0,
            width as u16,
            rows as u16,
            !0,
        )
        .unwrap()
        .reply()
        .unwrap();
    // A 24-bit visual stores each pixel in 32 bits, little-endian: B, G, R, unused.
    assert_eq!(image.data.len(), 4 * width * rows);
    let shown: Vec<u32> = image
        .data
        .chunks_exact(4)
        .map(|bgrx| u32::from_le_bytes([bgrx[0], bgrx[1], bgrx[2], 0]))
        .collect();
    let differing = shown
        .iter()
        .zip(&frame.pixels)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(differing, 0, "{differing} of {} pixels differ", shown.len());
    // The frame is not blank: disks of several colours, and the status line.
    let mut colours = frame.pixels.clone();
    colours.sort_unstable();
    colours.dedup();
    assert!(colours.len() > 20, "{} colours", colours.len());
}

fn temp_dir() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

/// `collide view SCENE ARGS --stats FILE`, which must succeed; its statistics.
fn view_stats(args: &[&str], stats: &PathBuf) -> serde_json::Value {
    let stats_arg = stats.to_str().unwrap();
    let out = collide(&[&["view"], args, &["--stats", stats_arg]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "view {args:?} failed: {stderr}");
    serde_json::from_str(&std::fs::read_to_string(stats).unwrap()).unwrap()
}

#[test]
fn a_run_with_the_view_reaches_the_state_simulate_reaches_after_the_same_steps() {
    if !runs_here(
        "view::a_run_with_the_view_reaches_the_state_simulate_reaches_after_the_same_steps",
    ) {
        return;
    }
    let dir = temp_dir();
    let scene = "experiments/scenes/seed-1000.toml";
    for threads in [None, Some("2")] {
        let stats_path = dir.path().join("stats.json");
        let shot = dir.path().join("last.png");
        let mut args = vec![
            scene,
            "--steps",
            "60",
            "--steps-per-frame",
            "4",
            "--frames",
            "12",
            "--max-fps",
            "0",
            "--size",
            "200x160",
            "--screenshot",
            shot.to_str().unwrap(),
        ];
        if let Some(threads) = threads {
            args.extend(["--threads", threads]);
        }
        let stats = view_stats(&args, &stats_path);
        let steps = stats["steps"].as_u64().unwrap();
        assert!((4..=60).contains(&steps), "{steps} steps");
        let simulated = json_summary(&["simulate", scene, "--steps", &steps.to_string()]);
        assert_eq!(stats["state_hash"], simulated["state_hash"], "{threads:?}");
        assert_eq!(stats["frames"], 12);
        assert_eq!(stats["n"], 1000);
        assert_eq!(stats["frame_cap_per_s"], serde_json::Value::Null);
        assert_eq!(
            stats["virtual_display"],
            std::env::var_os(UNDER_XVFB).is_some()
        );
        assert_eq!(
            stats["backend"],
            if threads.is_some() { "rayon" } else { "serial" }
        );
        for field in [
            "frames_per_s",
            "steps_per_s",
            "frame_ms_median",
            "frame_ms_p95",
        ] {
            assert!(stats[field].as_f64().unwrap() >= 0.0, "{field}");
        }
        // At most one new state per frame, each 4 steps on.
        let snapshots = stats["snapshots"].as_u64().unwrap();
        assert!(
            snapshots <= 13 && steps <= 4 * snapshots,
            "{snapshots} states, {steps} steps"
        );
        let png = image::open(&shot).unwrap().to_rgb8();
        assert_eq!(png.dimensions(), (200, 160 + STATUS_ROWS as u32));
    }
}

/// Nobody can close a window on Xvfb: without `--frames` the view must end by itself
/// once the scene's steps are shown (before, it drew the last state forever).
#[test]
fn on_a_virtual_display_without_frames_the_view_ends_after_the_scenes_steps() {
    if !runs_here("view::on_a_virtual_display_without_frames_the_view_ends_after_the_scenes_steps")
    {
        return;
    }
    if std::env::var_os(UNDER_XVFB).is_none() {
        // A real display: a user closes the window; nothing to check here.
        return;
    }
    let dir = temp_dir();
    let stats_path = dir.path().join("stats.json");
    let stats_arg = stats_path.to_str().unwrap();
    let args = [
        "view",
        "experiments/scenes/seed-1000.toml",
        "--steps",
        "40",
        "--steps-per-frame",
        "8",
        "--max-fps",
        "0",
        "--size",
        "120x100",
        "--stats",
        stats_arg,
    ];
    let mut child = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if std::time::Instant::now() > deadline {
            child.kill().ok();
            panic!("the view on Xvfb without --frames did not end within 60 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success());
    let mut said = String::new();
    std::io::Read::read_to_string(&mut child.stdout.take().unwrap(), &mut said).unwrap();
    assert!(said.contains("closes after the scene's 40 steps"), "{said}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats_path).unwrap()).unwrap();
    assert_eq!(stats["steps"], 40);
}

#[test]
fn without_a_display_the_view_exits_2_and_points_at_render() {
    let out = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(["view", "experiments/scenes/seed-1000.toml", "--frames", "1"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env_remove("DISPLAY")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no display") && stderr.contains("collide render"),
        "{stderr}"
    );
}
