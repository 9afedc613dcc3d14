//! Validated run specifications: what to simulate and how, independent of any file format.
//!
//! `scene_file` turns TOML into a [`RunSpec`]; [`RunSpec::prepare`] (in `prepare.rs`)
//! builds the initial state and resolves `dt = "auto"`. Nothing here reads files or
//! prints.

use serde::Deserialize;

pub use crate::sim::engine::Method;
use crate::sim::event::EventParams;
use crate::sim::observe::Observables;
use crate::sim::scene::{Extent, GasSpec, Placement, RSA_JAMMING_PACKING};
use crate::sim::step::StepParams;
use crate::sim::{Broadphase, Particles, Scene};
pub use crate::stats::observables::Discard;

/// Where the disks come from.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    /// A seeded random gas.
    Gas(GasSpec),
    /// Disks listed one by one, already checked to fit the box without overlapping.
    Explicit(Scene),
}

/// How the time step is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DtChoice {
    Fixed(f64),
    /// The largest dt with v_max·dt ≤ `fraction`·r_min.
    Auto {
        fraction: f64,
    },
    /// The largest dt whose pilot misses at most `missed_tolerance` of its collisions
    /// (`dt = "auto"` without `dt_fraction`; see `crate::run::auto`).
    Tolerance,
}

/// The method as asked for: one of them, or the cheapest within the tolerance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub enum MethodChoice {
    Fixed(Method),
    /// `method = "auto"`: chosen by `crate::run::auto::choose`.
    Auto,
}

impl MethodChoice {
    pub fn name(self) -> &'static str {
        match self {
            MethodChoice::Fixed(method) => method.name(),
            MethodChoice::Auto => "auto",
        }
    }

    /// The event method (serial backend only) is or may be chosen.
    pub fn may_be_event(self) -> bool {
        self != MethodChoice::Fixed(Method::Step)
    }
}

impl std::str::FromStr for MethodChoice {
    type Err = String;

    fn from_str(text: &str) -> Result<MethodChoice, String> {
        match text {
            "step" => Ok(MethodChoice::Fixed(Method::Step)),
            "event" => Ok(MethodChoice::Fixed(Method::Event)),
            "auto" => Ok(MethodChoice::Auto),
            _ => Err(format!("expected step, event or auto, got \"{text}\"")),
        }
    }
}

impl TryFrom<String> for MethodChoice {
    type Error = String;

    fn try_from(text: String) -> Result<MethodChoice, String> {
        text.parse()
    }
}

/// Default of `dt_fraction`: the fastest disk moves at most a tenth of the smallest radius per step.
pub const DEFAULT_DT_FRACTION: f64 = 0.1;

/// Default of `missed_tolerance`: 10⁻³ (also the accuracy study's failure line).
pub const DEFAULT_MISSED_TOLERANCE: f64 = 1e-3;

/// Default TC model time of the event method, in units of r_min / v_rms (the time the
/// rms disk takes to cross its radius): far below a mean free time at any packing.
pub const DEFAULT_TC_FRACTION: f64 = 1e-4;

/// What a run measures besides time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Observe {
    /// Only what costs nothing in the timed loop.
    #[default]
    Timing,
    /// Also the exact missed-collision count of the step method (a swept pair test
    /// every step, excluded from `wall_s`).
    Accuracy,
}

impl Observe {
    pub fn name(self) -> &'static str {
        match self {
            Observe::Timing => "timing",
            Observe::Accuracy => "accuracy",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MethodSpec {
    pub dt: DtChoice,
    /// Number of steps, at least 1.
    pub steps: u64,
    pub broadphase: Broadphase,
    pub method: MethodChoice,
    /// Largest missed-collision fraction `method = "auto"` and `dt = "auto"` accept, in (0, 1).
    pub missed_tolerance: f64,
    /// TC model time of the event method (≥ 0); `None`: [`DEFAULT_TC_FRACTION`] of r_min / v_rms.
    pub tc: Option<f64>,
    pub observe: Observe,
    /// Draw the whole box offscreen after every step (the live view's renderer, timed
    /// apart from the stepping loop); serial and rayon backends only.
    pub draw: bool,
    /// How much of the run to drop before averaging its observables.
    pub discard: Discard,
}

impl MethodSpec {
    /// `steps` time steps of `dt` with the given broad phase: the default method, timing only.
    pub fn stepped(dt: f64, steps: u64, broadphase: Broadphase) -> MethodSpec {
        MethodSpec {
            dt: DtChoice::Fixed(dt),
            steps,
            broadphase,
            method: MethodChoice::Fixed(Method::Step),
            missed_tolerance: DEFAULT_MISSED_TOLERANCE,
            tc: None,
            observe: Observe::Timing,
            draw: false,
            discard: Discard::Automatic,
        }
    }
}

/// A complete, valid description of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    pub scene: SceneSource,
    pub method: MethodSpec,
    /// Extra work added to every step, to test `collide check` against a known
    /// slowdown; [`InjectedSlowdown::NONE`] in every real run.
    pub slowdown: InjectedSlowdown,
}

/// Busy work added after every step, as a fraction of that step's own wall time (0.25:
/// each step takes 25% longer). It changes timings only, never the disks.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InjectedSlowdown {
    fraction: f64,
}

impl InjectedSlowdown {
    pub const NONE: InjectedSlowdown = InjectedSlowdown { fraction: 0.0 };

    /// A slowdown of `fraction` (finite, 0 or more), or `None`.
    pub fn new(fraction: f64) -> Option<InjectedSlowdown> {
        (fraction.is_finite() && fraction >= 0.0).then_some(InjectedSlowdown { fraction })
    }

    pub fn fraction(self) -> f64 {
        self.fraction
    }
}

/// Estimated seconds to place a gas's disks ([`PLACEMENT_S_PER_DISK`]).
fn placement_seconds(gas: &GasSpec) -> f64 {
    let n = gas.n_particles as f64;
    let packing = match gas.extent {
        Extent::Packing(packing) => packing,
        Extent::Size { width, height } => n * gas.radius.mean_area() / (width * height),
    };
    let crowding = match gas.placement {
        // Random addition slows down as free room runs out near jamming.
        Placement::Random => 1.0 / (1.0 - packing / RSA_JAMMING_PACKING).max(0.01),
        Placement::Lattice => 1.0,
    };
    n * PLACEMENT_S_PER_DISK * crowding
}

/// A run ready to step: the initial state and the resolved method.
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedRun {
    pub scene: Scene,
    /// Figures of the initial disks, kept apart so that a backend may take the disks
    /// out of `scene` instead of copying them.
    pub initial: InitialFigures,
    pub params: StepParams,
    pub steps: u64,
    /// `Some(fraction)` when dt was chosen automatically.
    pub dt_auto_fraction: Option<f64>,
    /// What `method = "auto"` or `dt = "auto"` chose and why; `None` when nothing was.
    pub choice: Option<String>,
    pub seed: Option<u64>,
    pub method: Method,
    /// The event method's settings (its TC time resolved); unused by the step method.
    pub event: EventParams,
    pub observe: Observe,
    /// How much of the run to drop before averaging its observables.
    pub discard: Discard,
}

/// What a run's summary needs to know of its initial disks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialFigures {
    /// Area fraction covered by disks.
    pub packing: f64,
    pub rms_speed: f64,
    pub min_radius: f64,
    /// The disks' energy in the field ([`crate::sim::observe::potential_energy`]); 0
    /// without gravity.
    pub potential_energy: f64,
    /// Their kinetic energy and momentum.
    pub observables: Observables,
}

impl PreparedRun {
    /// Moves the initial disks out of the scene (leaving it empty), so that a run steps
    /// them without keeping a copy: at 10⁸ disks a copy costs 5 GB.
    pub fn take_particles(&mut self) -> Particles {
        std::mem::take(&mut self.scene.particles)
    }
}

// Memory and time a run needs, known before anything is allocated. The step method's
// figure is peak resident memory over N at N = 10⁷ (`/usr/bin/time -v collide simulate
// experiments/scenes/seed-1000.toml --n 10000000 --packing 0.3 --steps 10 --seed 42`) on
// a 2-core x86-64 Linux machine, release build, with the neighbour-list broad phase:
// 82 B per disk serial and 94 B with rayon on 2 threads for equal disks, 99 B and 112 B
// for radii from 0.5 to 1.5 with equal masses; masses by area add an array, 8 B. By its
// arrays' sizes, each further thread adds about 6 B (its band's union-find and
// resolution-order scratch), so 8 threads stay below the 160 kept here. The event
// method's, from the slope between N = 250 000 and 10⁶: 352 B (serial), with an
// intercept of about 21 MB. Re-measure when the state or its scratch memory changes size.

/// Peak resident bytes per disk of the step method, any backend (the largest measured,
/// with room for 8 threads).
pub const STEP_BYTES_PER_DISK: u64 = 160;
/// Peak resident bytes per disk of the event method (its calendar of predicted events).
pub const EVENT_BYTES_PER_DISK: u64 = 368;
/// Peak resident bytes of a run before its disks: the program, its libraries, the pool.
pub const BASE_BYTES: u64 = 32 << 20;
/// Seconds the set-up (placement in bands, ordering, the first grid and lists) takes per
/// disk of a dilute gas in one process, from `setup_s` of the command above with
/// `--steps 1`; the cost grows as 1 / (1 − packing / jamming). Measured (one run each):
/// 0.54 µs per disk at 10⁷ and packing 0.05, 0.71 µs at 0.3, 1.16 µs at 10⁶ and 0.45,
/// 4.48 µs at 0.5 (the model: 0.66, 1.33, 3.4, 6.9); the dilute gas sets the constant,
/// and the note errs long, never short.
pub const PLACEMENT_S_PER_DISK: f64 = 0.6e-6;

/// What a run will hold, how long building its disks takes and how many steps it
/// takes, estimated from the spec alone (see [`STEP_BYTES_PER_DISK`] for the
/// measurements behind it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    pub n_particles: u64,
    /// Steps of the run (the event method's are the step method's with the same dt).
    pub steps: u64,
    /// Copies of the whole state: MPI ranks that each build every disk
    /// ([`RunSpec::whole_scene_copies`]); 1 otherwise.
    pub copies: u64,
    /// Bytes per disk per copy for the method the run may use.
    pub bytes_per_disk: u64,
    /// Peak resident bytes of all copies together.
    pub bytes: u64,
    /// Seconds to place the disks (0 for listed disks).
    pub placement_s: f64,
}

impl RunSpec {
    /// How many processes of a run on `ranks` MPI ranks each build the whole scene: all
    /// of them, unless the ranks place a seeded gas in parts (then the disks are shared
    /// out: one copy in all).
    pub fn whole_scene_copies(&self, ranks: usize) -> usize {
        match self.may_prepare_in_parts() {
            true => 1,
            false => ranks,
        }
    }

    /// The run's [`Footprint`] with `copies` copies of its state (ranks of an MPI run).
    pub fn footprint(&self, copies: usize) -> Footprint {
        let (n_particles, placement_s) = match &self.scene {
            SceneSource::Gas(gas) => (gas.n_particles as u64, placement_seconds(gas)),
            SceneSource::Explicit(scene) => (scene.particles.len() as u64, 0.0),
        };
        let bytes_per_disk = if self.method.method.may_be_event() {
            EVENT_BYTES_PER_DISK
        } else {
            STEP_BYTES_PER_DISK
        };
        let copies = copies.max(1) as u64;
        let bytes = n_particles
            .saturating_mul(bytes_per_disk)
            .saturating_add(BASE_BYTES)
            .saturating_mul(copies);
        Footprint {
            n_particles,
            steps: self.method.steps,
            copies,
            bytes_per_disk,
            bytes,
            placement_s,
        }
    }
}

impl Footprint {
    /// The run's size as disks × steps: what a study's estimate of the time left weighs
    /// its runs by (at least 1).
    pub fn disk_steps(&self) -> u64 {
        self.n_particles.saturating_mul(self.steps).max(1)
    }
}
