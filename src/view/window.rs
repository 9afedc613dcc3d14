//! `collide view`: a scene run on its own thread and drawn in a window as it happens.
//!
//! The simulation thread steps the same engines as `collide simulate` (serial, or the
//! rayon stepper on its own pool), stopping at the scene's step count. After every
//! `steps per frame` steps it waits for an empty snapshot from the drawing thread, fills
//! it and hands it back; two snapshots circulate, so stepping goes on while a frame is
//! drawn. The drawing thread redraws the newest snapshot every frame (zoom and pan stay
//! smooth when steps are slow) and counts frames and steps apart: two rates, never one.

use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use minifb::{Key, KeyRepeat, ScaleMode, Window, WindowOptions};
use serde::Serialize;

use crate::backend::team::with_team;
use crate::backend::threads::{self, ThreadedStepper};
use crate::draw::raster::{Drawn, Frame, View, draw, fast_speed};
use crate::run::backend_kind::BackendKind;
use crate::run::spec::{Method, PreparedRun};
use crate::sim::engine::Engine;
use crate::sim::observe::state_hash;
use crate::sim::snapshot::Snapshot;
use crate::sim::{Domain, Particles};
use crate::system::output::write_atomically;
use crate::view::shm::SharedFrame;
use crate::view::status::{STATUS_ROWS, StatusFont};

/// What `collide view` was asked for, validated.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Pixels of the drawing (the status line comes below it).
    pub width: usize,
    pub height: usize,
    /// `None`: the serial engine; `Some`: the rayon stepper on a pool of this size.
    pub threads: Option<NonZeroUsize>,
    /// Exit after this many frames.
    pub frames: Option<u64>,
    /// Frames per second at most (`None`: as fast as they can be drawn).
    pub max_fps: Option<u32>,
    /// Steps between two snapshots at the start (keys change it).
    pub steps_per_frame: u64,
    /// Where to write the statistics (JSON) at exit.
    pub stats: Option<PathBuf>,
    /// Where to write the last frame (PNG) at exit, and the screenshot key's frames.
    pub screenshot: Option<PathBuf>,
}

/// What `--stats` writes: the frame rate and the step rate, and where the time went.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewStats {
    /// Frames drawn and presented.
    pub frames: u64,
    /// Frames per second over the frames' own time (the first frame's start to the
    /// last frame's end).
    pub frames_per_s: f64,
    /// Distinct states shown (snapshots taken; a paused or slow run redraws one).
    pub snapshots: u64,
    /// Steps done when the view closed.
    pub steps: u64,
    /// Steps per second of wall time, from the first frame to the view's close.
    pub steps_per_s: f64,
    pub n: usize,
    /// Simulated time at exit: steps × dt.
    pub simulated_time: f64,
    /// Median and 95th percentile of one frame's time (drawing, presenting, waiting).
    pub frame_ms_median: f64,
    pub frame_ms_p95: f64,
    /// Mean milliseconds per snapshot filled (simulation thread).
    pub snapshot_ms_mean: f64,
    /// Mean milliseconds per frame drawing (the disks and the status line).
    pub draw_ms_mean: f64,
    /// Mean milliseconds per frame handing the pixels to the window and reading its
    /// input.
    pub present_ms_mean: f64,
    /// How frames reach the X server: through shared memory (MIT-SHM) or its socket
    /// (XPutImage).
    pub shared_memory: bool,
    /// Mean milliseconds per frame spent waiting for the frame cap.
    pub wait_ms_mean: f64,
    /// Mean milliseconds per step (simulation thread).
    pub step_ms_mean: f64,
    /// How the last frame drew the disks: "circles" or "splat".
    pub drawn_as: &'static str,
    /// The hash of the state at exit (as `collide simulate` prints it).
    pub state_hash: String,
    pub backend: &'static str,
    pub threads: usize,
    pub width: usize,
    pub height: usize,
    /// The frame cap in frames per second (`null`: none).
    pub frame_cap_per_s: Option<u32>,
    /// The X display drawn on, and whether it was virtual (Xvfb; `null`: unknown).
    pub display: String,
    pub virtual_display: Option<bool>,
}

/// A snapshot handed between the two threads, with the step it shows.
#[derive(Debug, Default)]
struct Shown {
    snapshot: Snapshot,
    steps: u64,
}

/// What the keys ask of the simulation thread.
#[derive(Debug)]
struct Controls {
    paused: AtomicBool,
    steps_per_frame: AtomicU64,
    /// Single steps asked for while paused.
    single_steps: AtomicU64,
    quit: AtomicBool,
}

/// The status line's rates, over about half a second before the last update: frames
/// per second and steps per second, `None` until half a second has been measured.
struct Rates {
    since: Instant,
    frames: u64,
    steps: u64,
    per_s: Option<(f64, f64)>,
}

/// What the simulation thread leaves behind.
struct Stepped {
    particles: Particles,
    steps: u64,
    step_s: f64,
    snapshot_s: f64,
    snapshots: u64,
}

/// A window of `width` × `height` pixels that shows frames.
pub struct Screen {
    window: Window,
    /// Memory shared with the X server, where it offers it: frames go through it
    /// instead of the server's socket.
    shared: Option<SharedFrame>,
}

impl Screen {
    /// Opens a window, or says why there is none and what to do instead.
    pub fn open(title: &str, width: usize, height: usize) -> anyhow::Result<Screen> {
        let instead = "draw pictures without a display with `collide render SCENE --png FILE` \
                       (or --gif FILE), or run the view on a virtual display: \
                       `xvfb-run -a collide view SCENE`";
        if std::env::var_os("DISPLAY").is_none_or(|display| display.is_empty()) {
            bail!("no display to open a window on (DISPLAY is not set); {instead}");
        }
        // The frame is exactly the window's size: copied row by row, never resampled
        // (minifb's default, stretching, resamples every pixel of every frame).
        let options = WindowOptions {
            scale_mode: ScaleMode::UpperLeft,
            ..WindowOptions::default()
        };
        let mut window = Window::new(title, width, height, options)
            .map_err(|err| anyhow::anyhow!("cannot open a window ({err}); {instead}"))?;
        // Frames are paced by the view itself (see `--max-fps`), not by minifb.
        window.set_target_fps(0);
        let shared = SharedFrame::open(window.get_window_handle() as usize as u32, width, height);
        Ok(Screen { window, shared })
    }

    /// Shows the frame (box and status rows) and reads the window's input.
    pub fn present(&mut self, frame: &Frame) -> anyhow::Result<()> {
        match &mut self.shared {
            Some(shared) => {
                shared.present(&frame.pixels)?;
                self.window.update();
                Ok(())
            }
            None => self
                .window
                .update_with_buffer(&frame.pixels, frame.width, frame.height + frame.status_rows)
                .map_err(|err| anyhow::anyhow!("cannot draw in the window: {err}")),
        }
    }

    /// Whether frames go through memory shared with the X server (else its socket).
    pub fn shares_memory(&self) -> bool {
        self.shared.is_some()
    }

    /// The X11 window id (for reading the window back in tests).
    pub fn x11_window_id(&self) -> u32 {
        self.window.get_window_handle() as usize as u32
    }
}

/// Runs the scene in a window until it is closed (Escape or the window's close button)
/// or `options.frames` frames are drawn.
pub fn run(prepared: PreparedRun, options: &ViewOptions) -> anyhow::Result<ViewStats> {
    debug_assert!(options.threads.is_none() || prepared.method == Method::Step);
    let mut screen = Screen::open("collide view", options.width, options.height + STATUS_ROWS)?;
    let run = RunFacts {
        n: prepared.scene.particles.len(),
        dt: prepared.params.dt,
        total_steps: prepared.steps,
        domain: prepared.scene.domain,
        // Nobody can close a window on a virtual display: without `--frames` it closes
        // when the scene's steps are done and shown.
        closes_at_the_end: options.frames.is_none()
            && is_virtual(&std::env::var("DISPLAY").unwrap_or_default()) == Some(true),
    };
    if run.closes_at_the_end {
        crate::outln!(
            "the display is virtual (Xvfb) and --frames was not given: the view closes after \
             the scene's {} steps",
            run.total_steps
        );
    }
    let simulation = Simulation::start(prepared, options)?;
    let started = Instant::now();
    let (outcome, shown) = show_frames(&mut screen, &simulation, options, &run);
    let stepped = simulation.stop()?;
    let session_s = started.elapsed().as_secs_f64();
    outcome?;
    if let Some(path) = &options.screenshot {
        write_png(path, &shown.frame)?;
    }
    let times = FrameTimes {
        shared_memory: screen.shares_memory(),
        ..shown.times
    };
    let stats = view_stats(times, &stepped, session_s, shown.drawn_as, run.dt, options);
    if let Some(path) = &options.stats {
        let text = serde_json::to_string_pretty(&stats)?;
        write_atomically(path, |out| writeln!(out, "{text}"))?;
    }
    Ok(stats)
}

/// What the status line says of the run, fixed for its length.
struct RunFacts {
    n: usize,
    dt: f64,
    total_steps: u64,
    domain: Domain,
    /// Close the window once the last step is shown.
    closes_at_the_end: bool,
}

/// The simulation thread, the keys' controls it reads, and the two queues of snapshots
/// between it and the window: empty ones to fill, full ones to draw.
struct Simulation {
    controls: Arc<Controls>,
    empty_tx: Sender<Shown>,
    full_rx: Receiver<Shown>,
    thread: thread::JoinHandle<Stepped>,
}

impl Simulation {
    /// Starts stepping `prepared` on its own thread, with two empty snapshots to fill.
    fn start(prepared: PreparedRun, options: &ViewOptions) -> anyhow::Result<Simulation> {
        let controls = Arc::new(Controls {
            paused: AtomicBool::new(false),
            steps_per_frame: AtomicU64::new(options.steps_per_frame),
            single_steps: AtomicU64::new(0),
            quit: AtomicBool::new(false),
        });
        let (empty_tx, empty_rx) = channel::<Shown>();
        let (full_tx, full_rx) = channel::<Shown>();
        for _ in 0..2 {
            empty_tx.send(Shown::default()).ok();
        }
        let stepping = Stepping::new(&prepared, options.threads)?;
        let thread = {
            let controls = Arc::clone(&controls);
            thread::Builder::new()
                .name("collide-view-simulation".to_owned())
                .spawn(move || simulate(prepared, stepping, &controls, &empty_rx, &full_tx))
                .context("cannot start the simulation thread")?
        };
        Ok(Simulation {
            controls,
            empty_tx,
            full_rx,
            thread,
        })
    }

    /// Tells the thread to quit, hangs up its queues and takes what it stepped.
    fn stop(self) -> anyhow::Result<Stepped> {
        self.controls.quit.store(true, Ordering::Relaxed);
        drop(self.empty_tx);
        drop(self.full_rx);
        self.thread
            .join()
            .map_err(|_| anyhow::anyhow!("the simulation thread panicked"))
    }
}

/// What the frame loop leaves: the last frame, how it was drawn, and where the time went.
struct ShownFrames {
    frame: Frame,
    drawn_as: Drawn,
    times: FrameTimes,
}

/// Draws the newest snapshot in every frame until the window is closed, `--frames`
/// frames are drawn, or the simulation thread stops unexpectedly (the error).
fn show_frames(
    screen: &mut Screen,
    simulation: &Simulation,
    options: &ViewOptions,
    run: &RunFacts,
) -> (anyhow::Result<()>, ShownFrames) {
    let font = StatusFont::default();
    let (controls, domain) = (&simulation.controls, &run.domain);
    let mut view = View::whole_box(options.width, options.height, domain.width, domain.height);
    let mut frame = Frame::with_status_rows(STATUS_ROWS);
    let mut shown: Option<Shown> = None;
    let mut times = FrameTimes::default();
    let mut drawn_as = Drawn::Circles;
    let mut screenshots = 0_u32;
    let frame_interval = options
        .max_fps
        .map(|fps| Duration::from_secs_f64(1.0 / f64::from(fps)));
    let mut rates = Rates::since(Instant::now());
    let mut closing = false;
    let outcome = loop {
        let drawn = times.frame_s.len() as u64;
        if closing || !screen.window.is_open() || options.frames.is_some_and(|k| drawn >= k) {
            break Ok(());
        }
        let frame_start = Instant::now();
        // A new state if one is ready (at most one per frame, so that `steps per
        // frame` holds); the one it replaces goes back to be refilled.
        if shown.is_none() {
            shown = simulation.full_rx.recv().ok();
        } else if let Ok(fresh) = simulation.full_rx.try_recv()
            && let Some(old) = shown.replace(fresh)
        {
            simulation.empty_tx.send(old).ok();
        }
        let Some(current) = shown.as_ref() else {
            break Err(anyhow::anyhow!(
                "the simulation thread stopped unexpectedly"
            ));
        };
        // The status line describes the state drawn in this frame.
        rates.update(drawn, current.steps);
        let status = status_line(&rates, current, controls, run.n, run.dt, run.total_steps);
        let draw_start = Instant::now();
        drawn_as = draw(&current.snapshot, &view, &mut frame);
        font.write(&mut frame, &status);
        times.draw_s += draw_start.elapsed().as_secs_f64();
        let present_start = Instant::now();
        if let Err(err) = screen.present(&frame) {
            break Err(err);
        }
        times.present_s += present_start.elapsed().as_secs_f64();
        closing = apply_keys(
            screen,
            controls,
            &mut view,
            options,
            domain,
            &frame,
            &mut screenshots,
        );
        if let Some(interval) = frame_interval {
            let wait_start = Instant::now();
            if let Some(rest) = interval.checked_sub(frame_start.elapsed()) {
                thread::sleep(rest);
            }
            times.wait_s += wait_start.elapsed().as_secs_f64();
        }
        times.frame_s.push(frame_start.elapsed().as_secs_f64());
        closing |= run.closes_at_the_end && current.steps == run.total_steps;
    };
    let shown = ShownFrames {
        frame,
        drawn_as,
        times,
    };
    (outcome, shown)
}

/// Where the frames' time went: each frame's, and the sums of its parts; and whether
/// presenting went through shared memory.
#[derive(Default)]
struct FrameTimes {
    frame_s: Vec<f64>,
    draw_s: f64,
    present_s: f64,
    wait_s: f64,
    shared_memory: bool,
}

/// The `--stats` of a session of `session_s` seconds, steps of `dt`, that ended with
/// `stepped`.
fn view_stats(
    times: FrameTimes,
    stepped: &Stepped,
    session_s: f64,
    drawn_as: Drawn,
    dt: f64,
    options: &ViewOptions,
) -> ViewStats {
    let FrameTimes {
        mut frame_s,
        draw_s,
        present_s,
        wait_s,
        shared_memory,
    } = times;
    let n = stepped.particles.len();
    let display = std::env::var("DISPLAY").unwrap_or_default();
    let frames = frame_s.len() as u64;
    let per_frame = |seconds: f64| 1e3 * seconds / frames.max(1) as f64;
    let frames_s: f64 = frame_s.iter().sum();
    ViewStats {
        frames,
        frames_per_s: frames as f64 / frames_s,
        snapshots: stepped.snapshots,
        steps: stepped.steps,
        steps_per_s: stepped.steps as f64 / session_s,
        n,
        simulated_time: stepped.steps as f64 * dt,
        frame_ms_median: 1e3 * quantile(&mut frame_s, 0.5),
        frame_ms_p95: 1e3 * quantile(&mut frame_s, 0.95),
        snapshot_ms_mean: 1e3 * stepped.snapshot_s / stepped.snapshots.max(1) as f64,
        draw_ms_mean: per_frame(draw_s),
        present_ms_mean: per_frame(present_s),
        shared_memory,
        wait_ms_mean: per_frame(wait_s),
        step_ms_mean: 1e3 * stepped.step_s / stepped.steps.max(1) as f64,
        drawn_as: drawn_as.name(),
        state_hash: state_hash(&stepped.particles),
        backend: if options.threads.is_some() {
            BackendKind::Rayon
        } else {
            BackendKind::Serial
        }
        .name(),
        threads: options.threads.map_or(1, NonZeroUsize::get),
        width: options.width,
        height: options.height,
        frame_cap_per_s: options.max_fps,
        virtual_display: is_virtual(&display),
        display,
    }
}

/// Acts on the keys pressed since the last frame: pause, single step, steps per frame,
/// zoom, pan, whole box, screenshot. Returns whether Escape asked to close.
fn apply_keys(
    screen: &Screen,
    controls: &Controls,
    view: &mut View,
    options: &ViewOptions,
    domain: &Domain,
    frame: &Frame,
    screenshots: &mut u32,
) -> bool {
    let mut closing = false;
    for key in screen.window.get_keys_pressed(KeyRepeat::Yes) {
        match key {
            Key::Escape => closing = true,
            Key::Space => {
                controls.paused.fetch_xor(true, Ordering::Relaxed);
            }
            Key::Period => {
                controls.single_steps.fetch_add(1, Ordering::Relaxed);
            }
            Key::RightBracket => {
                let spf = controls.steps_per_frame.load(Ordering::Relaxed);
                controls
                    .steps_per_frame
                    .store((spf * 2).min(1 << 20), Ordering::Relaxed);
            }
            Key::LeftBracket => {
                let spf = controls.steps_per_frame.load(Ordering::Relaxed);
                controls
                    .steps_per_frame
                    .store((spf / 2).max(1), Ordering::Relaxed);
            }
            Key::Equal | Key::NumPadPlus => view.zoom_by(1.25),
            Key::Minus | Key::NumPadMinus => view.zoom_by(0.8),
            Key::Left => view.pan_by(-0.1, 0.0),
            Key::Right => view.pan_by(0.1, 0.0),
            Key::Up => view.pan_by(0.0, 0.1),
            Key::Down => view.pan_by(0.0, -0.1),
            Key::Key0 => {
                *view = View::whole_box(options.width, options.height, domain.width, domain.height);
            }
            Key::P => {
                *screenshots += 1;
                let path = options
                    .screenshot
                    .clone()
                    .unwrap_or_else(|| PathBuf::from(format!("collide-view-{screenshots}.png")));
                match write_png(&path, frame) {
                    Ok(()) => crate::outln!("screenshot written to {}", path.display()),
                    Err(err) => eprintln!("error: {err:#}"),
                }
            }
            _ => {}
        }
    }
    closing
}

impl Rates {
    /// No frames and no steps yet, counted from `since`.
    fn since(since: Instant) -> Rates {
        Rates {
            since,
            frames: 0,
            steps: 0,
            per_s: None,
        }
    }

    /// Rates from the frames drawn and the steps shown since the last update, once
    /// half a second has passed since it.
    fn update(&mut self, frames: u64, steps: u64) {
        let seconds = self.since.elapsed().as_secs_f64();
        if seconds >= 0.5 {
            *self = Rates {
                since: Instant::now(),
                frames,
                steps,
                per_s: Some((
                    (frames - self.frames) as f64 / seconds,
                    (steps - self.steps) as f64 / seconds,
                )),
            };
        }
    }

    /// "12 frames/s  340 steps/s", or "measuring" before the first half second.
    fn describe(&self) -> String {
        match self.per_s {
            Some((frames, steps)) => format!("{frames:.0} frames/s  {steps:.0} steps/s"),
            None => "frames/s and steps/s: measuring".to_owned(),
        }
    }
}

/// The status line under the box: the two rates, the run, and the controls' state.
fn status_line(
    rates: &Rates,
    current: &Shown,
    controls: &Controls,
    n: usize,
    dt: f64,
    total_steps: u64,
) -> String {
    let paused = controls.paused.load(Ordering::Relaxed);
    format!(
        "{}  N {}  t {:.3}  E {:.6e}  step {}/{}  {} steps/frame{}",
        rates.describe(),
        n,
        current.steps as f64 * dt,
        current.snapshot.kinetic_energy,
        current.steps,
        total_steps,
        controls.steps_per_frame.load(Ordering::Relaxed),
        if paused { "  paused (space)" } else { "" },
    )
}

/// The engine the simulation thread steps: the serial reference, or the rayon stepper
/// with its own pool (never the global one).
enum Stepping {
    Serial(Engine),
    Rayon {
        pool: rayon::ThreadPool,
        stepper: Box<ThreadedStepper>,
    },
}

impl Stepping {
    fn new(prepared: &PreparedRun, threads: Option<NonZeroUsize>) -> anyhow::Result<Stepping> {
        let scene = &prepared.scene;
        Ok(match threads {
            None => Stepping::Serial(Engine::new(
                scene,
                prepared.method,
                prepared.params,
                prepared.event,
            )),
            Some(threads) => Stepping::Rayon {
                pool: threads::pool(threads)?,
                stepper: Box::new(ThreadedStepper::new(
                    scene.domain,
                    scene.physics,
                    prepared.params,
                    &scene.particles,
                    threads.get(),
                )),
            },
        })
    }

    fn step(&mut self, particles: &mut Particles) {
        match self {
            Stepping::Serial(engine) => engine.step(particles),
            Stepping::Rayon { pool, stepper } => {
                pool.install(|| with_team(|team| stepper.step(particles, team)))
            }
        }
    }
}

/// The simulation thread: steps, and fills an empty snapshot after every batch of
/// steps (and for the initial state); ends when the drawing thread hangs up.
fn simulate(
    prepared: PreparedRun,
    mut stepping: Stepping,
    controls: &Controls,
    empty: &Receiver<Shown>,
    full: &Sender<Shown>,
) -> Stepped {
    let fast = fast_speed(&prepared.scene.particles);
    let mut stepped = Stepped {
        particles: prepared.scene.particles,
        steps: 0,
        step_s: 0.0,
        snapshot_s: 0.0,
        snapshots: 0,
    };
    let mut unshown = true;
    while !controls.quit.load(Ordering::Relaxed) {
        if unshown {
            let Ok(mut shown) = empty.recv() else { break };
            let start = Instant::now();
            shown.snapshot.fill_from(&stepped.particles, fast);
            shown.steps = stepped.steps;
            stepped.snapshot_s += start.elapsed().as_secs_f64();
            stepped.snapshots += 1;
            if full.send(shown).is_err() {
                break;
            }
            unshown = false;
        }
        let batch = if controls.paused.load(Ordering::Relaxed) {
            controls.single_steps.swap(0, Ordering::Relaxed)
        } else {
            controls.steps_per_frame.load(Ordering::Relaxed)
        };
        let batch = batch.min(prepared.steps - stepped.steps);
        if batch == 0 {
            // Paused, or the run is over: nothing new to show.
            thread::sleep(Duration::from_millis(5));
            continue;
        }
        let start = Instant::now();
        for _ in 0..batch {
            stepping.step(&mut stepped.particles);
        }
        stepped.step_s += start.elapsed().as_secs_f64();
        stepped.steps += batch;
        unshown = true;
    }
    stepped
}

/// Writes the frame (box and status line) as an 8-bit RGB PNG, atomically.
pub fn write_png(path: &Path, frame: &Frame) -> anyhow::Result<()> {
    let rows = frame.height + frame.status_rows;
    let rgb: Vec<u8> = frame
        .pixels
        .iter()
        .flat_map(|&pixel| {
            let [_, r, g, b] = pixel.to_be_bytes();
            [r, g, b]
        })
        .collect();
    write_atomically(path, |out| {
        let mut encoder = png::Encoder::new(out, frame.width as u32, rows as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(std::io::Error::other)?;
        writer
            .write_image_data(&rgb)
            .map_err(std::io::Error::other)?;
        writer.finish().map_err(std::io::Error::other)
    })
}

/// The `q` quantile of `values` (nearest rank; 0 for none). Sorts `values`.
fn quantile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let rank = (q * values.len() as f64).ceil() as usize;
    values[rank.clamp(1, values.len()) - 1]
}

/// Whether the X display `display` (":99", "localhost:10.0") is an Xvfb virtual
/// display: the server process named in its lock file is `Xvfb`. `None` when that
/// cannot be told (a remote display, no lock file).
fn is_virtual(display: &str) -> Option<bool> {
    let number = display.strip_prefix(':')?.split('.').next()?;
    let lock = std::fs::read_to_string(format!("/tmp/.X{number}-lock")).ok()?;
    let pid: u32 = lock.trim().parse().ok()?;
    let name = std::fs::read_to_string(format!("/proc/{pid}/comm")).ok()?;
    Some(name.trim() == "Xvfb")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_take_the_nearest_rank() {
        let mut ms: Vec<f64> = (1..=20).rev().map(f64::from).collect();
        assert_eq!(quantile(&mut ms, 0.5), 10.0);
        assert_eq!(quantile(&mut ms, 0.95), 19.0);
        assert_eq!(quantile(&mut [], 0.5), 0.0);
    }

    #[test]
    fn the_status_line_says_the_rates_are_being_measured_until_half_a_second_has_passed() {
        let mut rates = Rates::since(Instant::now());
        rates.update(3, 30);
        assert_eq!(rates.describe(), "frames/s and steps/s: measuring");
        let mut rates = Rates::since(Instant::now() - Duration::from_secs(1));
        rates.update(10, 400);
        let said = rates.describe();
        let [frames, steps]: [f64; 2] = [said.split(' ').next(), said.split("  ").nth(1)]
            .map(|part| part.unwrap().split(' ').next().unwrap().parse().unwrap());
        assert!(
            (5.0..=10.0).contains(&frames) && (200.0..=400.0).contains(&steps),
            "{said}"
        );
    }

    #[test]
    fn a_display_without_a_local_server_is_not_known_to_be_virtual() {
        assert_eq!(is_virtual("remote:10.0"), None);
        assert_eq!(is_virtual(":4242"), None);
    }
}
