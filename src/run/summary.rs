//! The result of one run: the JSON summary (stable field names that later tools read)
//! and its human-readable form.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::stats::observables::{MANUAL_CUT, MIN_EFFECTIVE_POINTS, MIN_KEPT_BLOCKS};
use crate::stats::reference::{Reference, z_score};

/// One run's measurements. Field names are a public interface: scripts and the study
/// driver read them. Times are wall-clock seconds. (`Default` is a base to fill, as
/// `backend::summarize` does in parts; no run reports it.)
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// Number of disks.
    pub n: usize,
    /// Steps (intervals of dt for the event method) done: as asked, or fewer when the
    /// event method detected inelastic collapse.
    pub steps: u64,
    /// Time step (simulation time units).
    pub dt: f64,
    /// With `dt = "auto"`: the fraction f in v_max·dt = f·r_min that chose dt; null when dt was given.
    pub dt_auto_fraction: Option<f64>,
    pub backend: String,
    /// Workers used: threads × ranks (1 for serial).
    pub workers: usize,
    /// Threads per process (rayon pool size; 1 for serial and MPI).
    pub threads: usize,
    /// MPI processes (1 for serial and rayon).
    pub ranks: usize,
    /// True when threads × ranks exceeds the CPUs the run's process may use.
    pub oversubscribed: bool,
    pub boundary: String,
    pub broadphase: String,
    /// Area fraction covered by disks.
    pub packing: f64,
    /// Seed of a random scene; absent for explicit disks.
    pub seed: Option<u64>,
    /// Seconds in the stepping loop only.
    pub wall_s: f64,
    /// CPU seconds of the stepping loop, summed over threads and ranks (time spent
    /// waiting for a CPU is not counted); null where unknown.
    #[serde(default)]
    pub cpu_s: Option<f64>,
    /// Seconds to build the initial state and scratch memory, the first neighbour lists
    /// included.
    pub setup_s: f64,
    /// Steps per second of `wall_s`.
    pub fps: f64,
    /// Seconds drawing the whole box offscreen after every step (`draw = true`: filling
    /// the snapshot and rasterizing it at 800 × 800, as `collide view` draws), outside
    /// `wall_s`; null when the run did not draw.
    #[serde(default)]
    pub draw_s: Option<f64>,
    /// Frames per second with drawing, the seed's Figure 5: steps / (wall_s + draw_s);
    /// null when the run did not draw.
    #[serde(default)]
    pub fps_with_drawing: Option<f64>,
    /// n × steps / wall_s.
    pub particle_steps_per_s: f64,
    /// Seconds of `wall_s` moving disks and applying the boundary.
    pub integration_s: f64,
    /// Seconds of `wall_s` building the grid and finding and ordering overlapping pairs.
    pub broad_phase_s: f64,
    /// Seconds of `wall_s` applying the impulse law.
    pub collision_s: f64,
    /// Seconds of `wall_s` exchanging data between MPI ranks (0 without MPI).
    pub communication_s: f64,
    /// MPI: messages one rank sent per step of the stepping loop, the rank that sent most
    /// (counted as MPI's algorithms send them: see `backend::comm::Communicator`); null
    /// for serial and rayon.
    #[serde(default)]
    pub messages_per_step_max: Option<f64>,
    /// MPI: messages one rank sent per step, the mean over ranks; null for serial and rayon.
    #[serde(default)]
    pub messages_per_step_mean: Option<f64>,
    /// MPI: bytes one rank sent per step, the rank that sent most; null for serial and rayon.
    #[serde(default)]
    pub bytes_per_step_max: Option<f64>,
    /// MPI: bytes one rank sent per step, the mean over ranks; null for serial and rayon.
    #[serde(default)]
    pub bytes_per_step_mean: Option<f64>,
    /// MPI: collectives (all-reduces, all-gathers, exchanges, barriers) each rank called
    /// per step, the same on every rank; null for serial and rayon.
    #[serde(default)]
    pub collectives_per_step: Option<f64>,
    /// MPI: the most disks a rank held over the mean over ranks, averaged over the steps
    /// (1: even); null for serial and rayon.
    #[serde(default)]
    pub load_imbalance: Option<f64>,
    /// MPI: times the ranks cut their slabs again to even out their disks; null for
    /// serial and rayon.
    #[serde(default)]
    pub recuts: Option<u64>,
    /// MPI: the most disks a rank held during set-up (its placed bands, or its slab's
    /// disks); null for serial and rayon.
    #[serde(default)]
    pub setup_disks_max: Option<u64>,
    /// MPI: where each rank ran, in rank order, as `HOST:CPUS/THREADS` joined by `; `
    /// (its allowed CPUs as the kernel lists them, and its threads); null for serial and
    /// rayon, and inside a rank (the launching process fills it in).
    #[serde(default)]
    pub rank_cpus: Option<String>,
    pub kinetic_energy_initial: f64,
    pub kinetic_energy_final: f64,
    /// Total momentum [px, py] before the first step.
    pub momentum_initial: [f64; 2],
    pub momentum_final: [f64; 2],
    pub pair_collisions: u64,
    pub wall_collisions: u64,
    /// Largest overlap seen, as a fraction of the pair's contact distance.
    pub max_overlap: f64,
    /// Largest penetration of a disk into a wall seen after a move, as a fraction of its
    /// radius (0 with periodic boundaries and for the event method, which stops disks at
    /// the wall).
    #[serde(default)]
    pub max_wall_penetration: f64,
    /// Σ over the disks (mod 2⁶⁴) of xxh3-64 of id and final x, y, vx, vy: equal hashes,
    /// identical states, in any storage order.
    pub state_hash: String,
    /// `"step"` (time steps of dt) or `"event"` (the exact event-driven reference).
    #[serde(default = "default_method")]
    pub method: String,
    /// `"timing"`, or `"accuracy"` when the step method also counted missed collisions.
    #[serde(default = "default_observe")]
    pub observe: String,
    /// Event method: pair and wall collisions per second of `wall_s` (cell crossings not
    /// counted); null for the step method.
    #[serde(default)]
    pub events_per_s: Option<f64>,
    /// Pair collisions per disk per unit time, counting both disks of each:
    /// 2·pair_collisions / (n·steps·dt), comparable with Enskog's ω.
    #[serde(default)]
    pub collision_rate: Option<f64>,
    /// Mean temperature T̄ = kinetic energy per disk (k_B = 1), averaged over the run
    /// (over the sampled curve where there is one, in scenes with e < 1 on the serial
    /// backend, else the mean of start and end).
    #[serde(default)]
    pub temperature: Option<f64>,
    /// 2D pressure from the collision virial: P = (n·T̄ + Σ d·J / (2·steps·dt)) / A.
    /// In a walled box it is the bulk estimate over the whole box area (wall forces are
    /// not in the virial).
    #[serde(default)]
    pub pressure: Option<f64>,
    /// Z = P·A / (n·T̄).
    #[serde(default)]
    pub compressibility_z: Option<f64>,
    /// Whether the run's observables settled: true when the block series was cut (by
    /// MSER-5 in its first half, or by the scene's manual `discard`) and collision_rate,
    /// temperature, pressure and compressibility_z are means after the cut; false ("not
    /// equilibrated: run longer", or a discard that left too little) when they are
    /// averages from t = 0; null where no series was recorded (a state at rest).
    #[serde(default)]
    pub equilibrated: Option<bool>,
    /// Which rule placed the cut: `mser5` (found by MSER-5) or `manual` (the scene's
    /// `discard`); null where no series was recorded.
    #[serde(default)]
    pub equilibration_cut: Option<String>,
    /// Simulated time cut from the start as the transient (null unless equilibrated).
    #[serde(default)]
    pub equilibration_cut_time: Option<f64>,
    /// Where MSER-5 puts the end of the transient, whichever rule cut (so a manual
    /// discard can be checked against it): null when it finds none in the run's first
    /// half, or where no series was recorded.
    #[serde(default)]
    pub equilibration_mser5_cut_time: Option<f64>,
    /// Z averaged from t = 0, transient included (null where no series was recorded).
    #[serde(default)]
    pub compressibility_z_from_zero: Option<f64>,
    /// Standard error of compressibility_z from blocking the production blocks (null
    /// unless equilibrated).
    #[serde(default)]
    pub compressibility_z_se: Option<f64>,
    /// Statistical inefficiency g of Z's blocks (Geyer), ≥ 1: blocks per independent one.
    #[serde(default)]
    pub compressibility_z_g: Option<f64>,
    /// Production blocks / g: independent points Z is worth (under 50: flagged).
    #[serde(default)]
    pub compressibility_z_n_eff: Option<f64>,
    /// Whether the blocking curve of Z reached a plateau (false: the SE may be too small).
    #[serde(default)]
    pub compressibility_z_plateau: Option<bool>,
    /// Standard error and statistical inefficiency of collision_rate (as for Z).
    #[serde(default)]
    pub collision_rate_se: Option<f64>,
    #[serde(default)]
    pub collision_rate_g: Option<f64>,
    /// Standard error and statistical inefficiency of temperature (as for Z).
    #[serde(default)]
    pub temperature_se: Option<f64>,
    #[serde(default)]
    pub temperature_g: Option<f64>,
    /// Equal elastic disks in a periodic box without a field: the reference Z at this
    /// packing (an equation of state, or a tabulated value with its N and box), its
    /// standard uncertainty and its source; null elsewhere.
    #[serde(default)]
    pub z_reference: Option<f64>,
    #[serde(default)]
    pub z_reference_se: Option<f64>,
    #[serde(default)]
    pub z_reference_source: Option<String>,
    /// Pairs whose straight paths came within contact during a step without an impulse
    /// (exact swept test): 0 for the event method; for the step method only with
    /// `observe = "accuracy"` on the serial backend, else null.
    #[serde(default)]
    pub missed_collisions: Option<u64>,
    /// missed_collisions / (missed_collisions + pair_collisions), null when either is.
    #[serde(default)]
    pub missed_collision_fraction: Option<f64>,
    /// Mean overlap of the pairs that received an impulse, as a fraction of their contact
    /// distance (rounding-sized for the event method); null without pair collisions.
    #[serde(default)]
    pub mean_overlap: Option<f64>,
    /// (E_final − E_initial) / E_initial for elastic scenes (e = 1 for pairs and walls);
    /// null otherwise (then energy loss is physics: see `temperature_curve`).
    #[serde(default)]
    pub energy_relative_error: Option<f64>,
    /// Event method with e < 1: collisions the TC model made elastic; else null.
    #[serde(default)]
    pub collapse_guard_fired: Option<u64>,
    /// Event method with e < 1: the TC model time used; else null.
    #[serde(default)]
    pub collapse_tc: Option<f64>,
    /// Event method: the simulated time at which inelastic collapse was detected (the
    /// run stopped there, after `steps` intervals; see `sim::collapse`); null when none
    /// was, and for the step method.
    #[serde(default)]
    pub collapse_time: Option<f64>,
    /// Simulated time the run reached: steps·dt, or `collapse_time` (null in summaries
    /// written before it was recorded).
    #[serde(default)]
    pub time_reached: Option<f64>,
    /// Event method: the TC model time used (0: guard off), whatever e; null for the
    /// step method.
    #[serde(default)]
    pub tc: Option<f64>,
    /// Scenes with e < 1 (pairs or walls), serial backend: [t, T] at t = 0 and at up
    /// to 40 evenly spaced steps (ending at `collapse_time` if there was one); else null.
    #[serde(default)]
    pub temperature_curve: Option<Vec<[f64; 2]>>,
    /// v_rms·dt/r_min of the initial state: how far the rms disk moves per step, in
    /// radii (the accuracy study's x axis); null for a state at rest.
    #[serde(default)]
    pub rms_step_over_radius: Option<f64>,
    /// What `method = "auto"` or `dt = "auto"` (under `missed_tolerance`) chose and why:
    /// the pilots' missed fractions and the cost model's estimates; null when neither
    /// was automatic (or dt came from the dt_fraction rule with a fixed method).
    #[serde(default)]
    pub choice: Option<String>,
}

fn default_method() -> String {
    "step".to_owned()
}

fn default_observe() -> String {
    "timing".to_owned()
}

impl RunSummary {
    /// The summary `collide simulate --json` prints on the last line of its output.
    pub fn from_last_line(stdout: &str) -> serde_json::Result<RunSummary> {
        serde_json::from_str(stdout.lines().last().unwrap_or_default())
    }
}

impl fmt::Display for RunSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write_scene(f)?;
        self.write_workers_and_times(f)?;
        self.write_messages(f)?;
        self.write_conservation(f)?;
        self.write_method_and_accuracy(f)?;
        write!(f, "state hash {}", self.state_hash)
    }
}

/// The human-readable form, one group of lines per step of `fmt`.
impl RunSummary {
    /// The scene and the stepping asked for: disks, boundary, seed, steps, dt, search.
    fn write_scene(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let dt_rule = self.dt_auto_fraction.map_or_else(String::new, |fraction| {
            format!(" (auto: the fastest disk moves {fraction}·r_min per step)")
        });
        let seed = self
            .seed
            .map_or_else(|| "explicit disks".to_owned(), |s| format!("seed {s}"));
        writeln!(
            f,
            "{} disks, {} boundary, packing {:.4}, {seed}",
            self.n, self.boundary, self.packing
        )?;
        let search = match self.method.as_str() {
            "event" => "exact event times (no broad phase)".to_owned(),
            _ => format!("{} broad phase", self.broadphase),
        };
        writeln!(
            f,
            "{} steps of dt = {:.6e}{dt_rule}, {search}",
            self.steps, self.dt
        )
    }

    /// Where the run ran and where its time went.
    fn write_workers_and_times(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let oversubscribed = if self.oversubscribed {
            " (oversubscribed: more workers than cores)"
        } else {
            ""
        };
        writeln!(
            f,
            "backend    {}, {} thread(s) × {} rank(s){oversubscribed}",
            self.backend, self.threads, self.ranks
        )?;
        writeln!(
            f,
            "time       {:.4} s stepping ({:.1} steps/s, {:.3e} particle-steps/s), {:.4} s setup",
            self.wall_s, self.fps, self.particle_steps_per_s, self.setup_s
        )?;
        if let (Some(draw_s), Some(fps_with_drawing)) = (self.draw_s, self.fps_with_drawing) {
            writeln!(
                f,
                "drawing    {draw_s:.4} s drawing every step offscreen ({fps_with_drawing:.1} frames/s with drawing)"
            )?;
        }
        writeln!(
            f,
            "stages     {:.4} s integration, {:.4} s broad phase, {:.4} s collisions, {:.4} s communication",
            self.integration_s, self.broad_phase_s, self.collision_s, self.communication_s
        )
    }

    /// Message traffic per rank per step, when the run recorded it.
    fn write_messages(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let (
            Some(messages),
            Some(messages_max),
            Some(bytes),
            Some(bytes_max),
            Some(collectives),
        ) = (
            self.messages_per_step_mean,
            self.messages_per_step_max,
            self.bytes_per_step_mean,
            self.bytes_per_step_max,
            self.collectives_per_step,
        ) {
            writeln!(
                f,
                "sent       per rank per step: {messages:.1} messages (most {messages_max:.1}), \
                 {bytes:.0} bytes (most {bytes_max:.0}), {collectives:.2} collectives"
            )?;
        }
        if let (Some(imbalance), Some(recuts)) = (self.load_imbalance, self.recuts) {
            writeln!(
                f,
                "balance    the busiest rank held {imbalance:.3}× the mean disks (over the \
                 steps); slabs cut again {recuts} times"
            )?;
        }
        if let Some(held) = self.setup_disks_max {
            let mean = self.n as f64 / self.ranks.max(1) as f64;
            writeln!(
                f,
                "set-up     no rank held more than {held} disks ({:.3}× the mean)",
                held as f64 / mean
            )?;
        }
        Ok(())
    }

    /// Energy, momentum and collision counts: what a correct step conserves or bounds.
    fn write_conservation(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let relative_change = (self.kinetic_energy_final - self.kinetic_energy_initial)
            / self.kinetic_energy_initial.abs().max(f64::MIN_POSITIVE);
        writeln!(
            f,
            "energy     {:.9e} → {:.9e} (relative change {relative_change:+.3e})",
            self.kinetic_energy_initial, self.kinetic_energy_final
        )?;
        writeln!(
            f,
            "momentum   [{:+.3e}, {:+.3e}] → [{:+.3e}, {:+.3e}]",
            self.momentum_initial[0],
            self.momentum_initial[1],
            self.momentum_final[0],
            self.momentum_final[1]
        )?;
        writeln!(
            f,
            "collisions {} pair, {} wall; max overlap {:.3}% of contact distance, max wall \
             penetration {:.3}% of radius",
            self.pair_collisions,
            self.wall_collisions,
            100.0 * self.max_overlap,
            100.0 * self.max_wall_penetration
        )
    }

    /// The equilibration cut and the error bars of the observables, with the warnings.
    fn write_equilibration(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (
            self.equilibrated,
            self.compressibility_z,
            self.compressibility_z_se,
        ) {
            (Some(true), Some(z), Some(se)) => {
                writeln!(
                    f,
                    "equilibrium cut at t = {:.4e} ({}); Z = {z:.5} ± {se:.5} (g = {:.2}, \
                     N_eff = {:.0}; from t = 0: {})",
                    self.equilibration_cut_time.unwrap_or(0.0),
                    match self.manual_cut() {
                        true => "manual discard",
                        false => "MSER-5",
                    },
                    self.compressibility_z_g.unwrap_or(f64::NAN),
                    self.compressibility_z_n_eff.unwrap_or(f64::NAN),
                    self.compressibility_z_from_zero
                        .map_or_else(|| "n/a".to_owned(), |z| format!("{z:.5}")),
                )?;
                for warning in self.equilibration_warnings() {
                    writeln!(f, "warning    {warning}")?;
                }
                Ok(())
            }
            (Some(false), ..) => writeln!(
                f,
                "equilibrium {} (the observables above are averages from t = 0, transient \
                 included)",
                self.unsettled()
            ),
            _ => Ok(()),
        }?;
        self.write_reference(f)
    }

    /// The reference Z and how far this run is from it, in combined standard errors.
    fn write_reference(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (Some(z_ref), Some(se_ref), Some(source)) = (
            self.z_reference,
            self.z_reference_se,
            &self.z_reference_source,
        ) else {
            return Ok(());
        };
        let reference = Reference {
            z: z_ref,
            se: se_ref,
            source: "",
        };
        let comparison = match (self.compressibility_z, self.compressibility_z_se) {
            (Some(z), Some(se)) if self.equilibrated == Some(true) => format!(
                "this run {z:.5} ± {se:.5}, z-score {:+.2}",
                z_score(z, se, &reference)
            ),
            _ => format!("this run {} (no comparison)", self.unsettled()),
        };
        writeln!(
            f,
            "reference  Z = {z_ref:.5} ± {se_ref:.5} ({source}); {comparison}"
        )
    }

    /// Whether the cut was the scene's manual `discard` rather than MSER-5's.
    fn manual_cut(&self) -> bool {
        self.equilibration_cut.as_deref() == Some(MANUAL_CUT)
    }

    /// Why a run with a series has no production window, in words.
    fn unsettled(&self) -> String {
        match self.manual_cut() {
            true => format!(
                "has too little left after its discard (fewer than {MIN_KEPT_BLOCKS} blocks): \
                 discard less or run longer"
            ),
            false => "not equilibrated: run longer".to_owned(),
        }
    }

    /// Sentences flagging an average or an error bar that cannot be trusted: a manual
    /// discard shorter than the transient MSER-5 finds, too few independent points, or
    /// no plateau in the blocking curve.
    pub fn equilibration_warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        if self.manual_cut()
            && let Some(cut) = self.equilibration_cut_time
        {
            match self.equilibration_mser5_cut_time {
                Some(transient) if cut < transient => warnings.push(format!(
                    "the discard keeps t = {cut:.4e} to {transient:.4e}, which MSER-5 counts \
                     as transient: the averages may carry part of it; discard more, or let MSER-5 cut \
                     (\"auto\")"
                )),
                Some(_) => {}
                None => warnings.push(
                    "MSER-5 finds no end of the transient in the run's first half: the \
                     averages after the discard may carry part of it; run longer"
                        .to_owned(),
                ),
            }
        }
        if let Some(n_eff) = self.compressibility_z_n_eff
            && n_eff < MIN_EFFECTIVE_POINTS
        {
            warnings.push(format!(
                "Z is worth {n_eff:.0} independent points (under {MIN_EFFECTIVE_POINTS:.0}): \
                 its error bar is itself uncertain; run longer"
            ));
        }
        if self.compressibility_z_plateau == Some(false) {
            warnings.push(
                "the blocking curve of Z has no plateau: its error bar may be too small; \
                 run longer"
                    .to_owned(),
            );
        }
        warnings
    }

    /// The method, its accuracy measures, the collapse guard and any automatic choice.
    fn write_method_and_accuracy(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let show =
            |value: Option<f64>| value.map_or_else(|| "n/a".to_owned(), |v| format!("{v:.4e}"));
        let count = |value: Option<u64>| value.map_or_else(|| "n/a".to_owned(), |v| v.to_string());
        writeln!(
            f,
            "method     {} ({}), events/s {}",
            self.method,
            self.observe,
            show(self.events_per_s)
        )?;
        writeln!(
            f,
            "accuracy   collision rate {}, pressure {}, Z {}, missed {} (fraction {}), mean overlap {}",
            show(self.collision_rate),
            show(self.pressure),
            show(self.compressibility_z),
            count(self.missed_collisions),
            show(self.missed_collision_fraction),
            show(self.mean_overlap)
        )?;
        self.write_equilibration(f)?;
        if let Some(guard) = self.collapse_guard_fired {
            writeln!(
                f,
                "collapse   TC guard fired {guard} times (tc = {})",
                show(self.collapse_tc)
            )?;
        }
        if let Some(time) = self.collapse_time {
            writeln!(
                f,
                "collapse   inelastic collapse detected at t = {time:.6e}: the event method stopped there, in step {}",
                self.steps
            )?;
        }
        if let Some(choice) = &self.choice {
            writeln!(f, "chosen     {choice}")?;
        }
        Ok(())
    }
}
