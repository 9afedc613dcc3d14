//! `method = "auto"` and `dt = "auto"` under a missed-collision tolerance: the cheapest
//! method and the largest dt whose pilot run misses at most `missed_tolerance` of its
//! collisions. Deterministic: decided from pilot runs of the pure core (`sim::pilot`,
//! fixed length, the scene's own seed) and a stated cost model, never from timings on
//! this machine, so every run and backend makes the same choice. Reads no files.

use std::borrow::Cow;

use crate::run::spec::{
    DEFAULT_DT_FRACTION, DtChoice, Method, MethodChoice, MethodSpec, SceneSource,
};
use crate::sim::event::EventParams;
use crate::sim::pilot::{StepPilot, event_pilot, step_pilot};
use crate::sim::scene::{Extent, PlacementError};
use crate::sim::step::auto_dt;
use crate::sim::{DiskFigures, Scene};

/// The dt fractions tried, largest first: v_max·dt = f·r_min for f = 4, 2, 1, ½, … 1/128.
const LADDER_TOP: f64 = 4.0;
const LADDER_RUNGS: i32 = 10;

/// Pilot length: the time the fastest disk takes to cross this many smallest radii (64 /
/// f steps at fraction f; about two collisions per disk at packing 0.05).
pub const PILOT_RADII: f64 = 64.0;

/// A pilot never runs more steps than the ladder's last rung needs (64 · 128).
const MAX_PILOT_STEPS: u64 = 8192;

/// Pilots run on at most this many disks: a random gas given by its packing is rebuilt
/// with this many disks (same seed, packing and speeds); other scenes run whole.
pub const PILOT_DISKS: usize = 2000;

/// One point of the cost model: the serial throughput of each method on a periodic gas
/// of unit disks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    pub n: f64,
    pub packing: f64,
    /// Step method: particle-steps per second (`step/n…/…`).
    pub step_particle_steps_per_s: f64,
    /// Event method: pair and wall collisions per second (`event/n…/…`).
    pub event_collisions_per_s: f64,
    /// Event method: disks brought to the current time and written out per second, as
    /// at every dt of a run (`event/observe_n…/…`).
    pub event_observed_disks_per_s: f64,
}

/// The cost model, measured by
/// `cargo bench --features mpi --bench kernels -- '^(step|event)/'` on one idle machine
/// (docs/accuracy.md, Choosing automatically), both methods in the same runs so that
/// their rates compare even where the machine differs: the median of three runs within
/// ten minutes on a 2-core AMD EPYC VM (the runs differed by up to 5% in the step rates,
/// 50% in the event rates at 10⁵ and threefold in the observation rates at 10⁵).
/// By N (rows), packing 0.05 then 0.3.
pub const MEASURED: [[Measured; 2]; 3] = [
    [
        measured(1e4, 0.05, 176.6e6, 1.135e6, 600e6),
        measured(1e4, 0.3, 91.8e6, 2.072e6, 610e6),
    ],
    [
        measured(1e5, 0.05, 176.4e6, 0.586e6, 174e6),
        measured(1e5, 0.3, 91.7e6, 1.127e6, 343e6),
    ],
    [
        measured(1e6, 0.05, 148.8e6, 0.278e6, 103e6),
        measured(1e6, 0.3, 77.0e6, 0.540e6, 124e6),
    ],
];

const fn measured(n: f64, packing: f64, step: f64, event: f64, observe: f64) -> Measured {
    Measured {
        n,
        packing,
        step_particle_steps_per_s: step,
        event_collisions_per_s: event,
        event_observed_disks_per_s: observe,
    }
}

/// The cost model's rates for `n` disks at `packing`: interpolated between the measured
/// points linearly in log N, in packing and in the log of each rate; beyond them, the
/// nearest point's.
pub fn cost_rates(n: f64, packing: f64) -> Measured {
    let along = |value: f64, low: f64, high: f64| ((value - low) / (high - low)).clamp(0.0, 1.0);
    let log_n = n.max(1.0).log10();
    let rows = MEASURED.len() - 1;
    let row_at = (0..rows)
        .find(|&row| log_n <= MEASURED[row + 1][0].n.log10())
        .unwrap_or(rows - 1);
    let (low, high) = (&MEASURED[row_at], &MEASURED[row_at + 1]);
    let u = along(log_n, low[0].n.log10(), high[0].n.log10());
    let w = along(packing, low[0].packing, low[1].packing);
    let mix = |rate: fn(&Measured) -> f64| {
        let at = |row: &[Measured; 2]| rate(&row[0]).ln() * (1.0 - w) + rate(&row[1]).ln() * w;
        (at(low) * (1.0 - u) + at(high) * u).exp()
    };
    Measured {
        n,
        packing,
        step_particle_steps_per_s: mix(|m| m.step_particle_steps_per_s),
        event_collisions_per_s: mix(|m| m.event_collisions_per_s),
        event_observed_disks_per_s: mix(|m| m.event_observed_disks_per_s),
    }
}

/// The resolved method and step, and why (`None` when nothing was automatic).
#[derive(Clone, Debug, PartialEq)]
pub struct Choice {
    pub method: Method,
    pub dt: f64,
    /// The f of v_max·dt = f·r_min when dt came from a rule; `None` for a given dt.
    pub dt_auto_fraction: Option<f64>,
    pub reason: Option<String>,
}

/// Resolves `method` and `dt` for `scene` (built from `source`); `event` is the event
/// method's resolved settings, used by its pilot.
///
/// `figures` are the whole scene's; `scene` may hold only some of its disks (a rank's)
/// when the choice needs no pilot ([`needs_pilots`]).
pub fn choose(
    source: &SceneSource,
    scene: &Scene,
    figures: &DiskFigures,
    spec: &MethodSpec,
    event: EventParams,
) -> Result<Choice, PlacementError> {
    if let Some(choice) = without_pilots(scene, figures, spec) {
        return Ok(choice);
    }
    let pilot_scene = pilot_scene(source, scene)?;
    let pilot_scene = pilot_scene.as_ref();
    let time = auto_dt(
        &pilot_scene.particles.figures(),
        &pilot_scene.domain,
        &pilot_scene.physics,
        PILOT_RADII,
    );
    let (step, pilot, dt_note) = step_choice(scene, figures, pilot_scene, spec, time);
    let pilots = Pilots {
        notes: format!(
            "{dt_note}{}",
            describe_step_pilot(pilot_scene, &pilot, spec.missed_tolerance)
        ),
        step_passes: pilot.missed_fraction() <= spec.missed_tolerance,
        scene: pilot_scene,
        time,
    };
    if spec.method == MethodChoice::Fixed(Method::Step) {
        return Ok(Choice {
            reason: Some(pilots.notes),
            ..step
        });
    }
    Ok(method_auto(scene, spec, event, step, &pilots))
}

/// The step method at `fraction` (v_max·dt = fraction·r_min) of `scene`, whose disks
/// have `figures`.
fn fraction_dt(scene: &Scene, figures: &DiskFigures, fraction: f64) -> Choice {
    Choice {
        method: Method::Step,
        dt: auto_dt(figures, &scene.domain, &scene.physics, fraction),
        dt_auto_fraction: Some(fraction),
        reason: None,
    }
}

/// Whether choosing the method or dt runs pilots on the whole scene: all but a fixed
/// method with a fixed dt or a dt rule, and the event method under a tolerance (it
/// misses nothing).
pub fn needs_pilots(spec: &MethodSpec) -> bool {
    !matches!(
        (spec.method, spec.dt),
        (
            MethodChoice::Fixed(_),
            DtChoice::Fixed(_) | DtChoice::Auto { .. }
        ) | (MethodChoice::Fixed(Method::Event), DtChoice::Tolerance)
    )
}

/// The choices that need no pilot ([`needs_pilots`]).
fn without_pilots(scene: &Scene, figures: &DiskFigures, spec: &MethodSpec) -> Option<Choice> {
    match (spec.method, spec.dt) {
        (MethodChoice::Fixed(method), DtChoice::Fixed(dt)) => Some(Choice {
            method,
            dt,
            dt_auto_fraction: None,
            reason: None,
        }),
        (MethodChoice::Fixed(method), DtChoice::Auto { fraction }) => Some(Choice {
            method,
            ..fraction_dt(scene, figures, fraction)
        }),
        (MethodChoice::Fixed(Method::Event), DtChoice::Tolerance) => Some(Choice {
            method: Method::Event,
            reason: Some(format!(
                "dt auto: the event method misses no collisions, so dt is the dt_fraction rule \
                 (v_max·dt = {DEFAULT_DT_FRACTION}·r_min)"
            )),
            ..fraction_dt(scene, figures, DEFAULT_DT_FRACTION)
        }),
        _ => None,
    }
}

/// The step method's dt, its pilot at that dt (on `pilot_scene`, over the simulated
/// `pilot_time`), and a note on how dt was chosen.
fn step_choice(
    scene: &Scene,
    figures: &DiskFigures,
    pilot_scene: &Scene,
    spec: &MethodSpec,
    pilot_time: f64,
) -> (Choice, StepPilot, String) {
    match spec.dt {
        DtChoice::Fixed(dt) => {
            let steps = ((pilot_time / dt).ceil() as u64).clamp(1, MAX_PILOT_STEPS);
            let pilot = step_pilot(pilot_scene, dt, steps, spec.broadphase);
            let choice = Choice {
                method: Method::Step,
                dt,
                dt_auto_fraction: None,
                reason: None,
            };
            (choice, pilot, String::new())
        }
        DtChoice::Auto { fraction } => {
            let choice = fraction_dt(scene, figures, fraction);
            let dt = auto_dt(
                &pilot_scene.particles.figures(),
                &pilot_scene.domain,
                &pilot_scene.physics,
                fraction,
            );
            let steps = ((PILOT_RADII / fraction).ceil() as u64).clamp(1, MAX_PILOT_STEPS);
            let pilot = step_pilot(pilot_scene, dt, steps, spec.broadphase);
            (choice, pilot, format!("dt_fraction = {fraction}; "))
        }
        DtChoice::Tolerance => {
            let (fraction, pilot) = largest_passing_fraction(pilot_scene, spec);
            let verdict = if pilot.missed_fraction() <= spec.missed_tolerance {
                "the largest of 4·2^-k (k < 10) within"
            } else {
                "the smallest tried, still above"
            };
            let note = format!("dt auto: v_max·dt = {fraction}·r_min, {verdict} the tolerance; ",);
            (fraction_dt(scene, figures, fraction), pilot, note)
        }
    }
}

/// What the step method's pilot found, against the tolerance.
fn describe_step_pilot(pilot_scene: &Scene, pilot: &StepPilot, tolerance: f64) -> String {
    format!(
        "pilot ({} disks, {} steps of {:.4e}): {} of {} met pairs missed = {:.2e} against \
         missed_tolerance {tolerance:e}",
        pilot_scene.particles.len(),
        pilot.steps,
        pilot.dt,
        pilot.missed_collisions,
        pilot.missed_collisions + pilot.pair_collisions,
        pilot.missed_fraction(),
    )
}

/// The pilots of `method = "auto"` so far: the scene they ran on, the simulated time
/// they cover, whether the step method's stayed within the tolerance, and the notes on dt
/// and that pilot.
struct Pilots<'a> {
    scene: &'a Scene,
    time: f64,
    step_passes: bool,
    notes: String,
}

/// `method = "auto"`: the step method with gravity or when the event pilot collapses,
/// else the cheaper method under the cost model (the event method when the step method
/// misses more than the tolerance).
fn method_auto(
    scene: &Scene,
    spec: &MethodSpec,
    event: EventParams,
    step: Choice,
    pilots: &Pilots<'_>,
) -> Choice {
    let notes = &pilots.notes;
    let step_passes = pilots.step_passes;
    if scene.physics.gravity.is_some() {
        return Choice {
            reason: Some(format!(
                "method auto: step, the only method with gravity (the event method flies \
                 straight lines); {notes}"
            )),
            ..step
        };
    }
    let n = scene.particles.len() as f64;
    let rates = cost_rates(n, scene.packing());
    let step_cost = n * spec.steps as f64 / rates.step_particle_steps_per_s;
    // Both methods run the same simulated time, steps × dt.
    let sim_time = spec.steps as f64 * step.dt;
    let pilot_time = pilots.time;
    let event_run = event_pilot(pilots.scene, event, pilot_time);
    if let Some(collapse_time) = event_run.collapse_time {
        let caveat = if step_passes {
            ""
        } else {
            ", though it misses more than the tolerance"
        };
        return Choice {
            reason: Some(format!(
                "method auto: step{caveat}: the event method collapsed in its pilot at \
                 t = {collapse_time:.4e} (tc = {:e}; a larger tc guards against it); \
                 {notes}",
                event.tc
            )),
            ..step
        };
    }
    let events = event_run.collisions as f64;
    let events_per_disk_time = events / (pilots.scene.particles.len() as f64 * pilot_time);
    // The collisions of the whole run, and the state observed at each of its steps.
    let event_cost = events_per_disk_time * n * sim_time / rates.event_collisions_per_s
        + n * spec.steps as f64 / rates.event_observed_disks_per_s;
    let costs = format!(
        "cost model at N = {n}, packing {:.3} (step {:.1} M particle-steps/s, event {:.2} M \
         collisions/s and {:.0} M observed disks/s): step {step_cost:.3e} s, event \
         {event_cost:.3e} s ({events} collisions in the event pilot to t = {pilot_time:.4e})",
        scene.packing(),
        rates.step_particle_steps_per_s / 1e6,
        rates.event_collisions_per_s / 1e6,
        rates.event_observed_disks_per_s / 1e6,
    );
    if step_passes && step_cost <= event_cost {
        Choice {
            reason: Some(format!(
                "method auto: step, within the tolerance and cheaper; {costs}; {notes}"
            )),
            ..step
        }
    } else {
        let why = if step_passes {
            "cheaper"
        } else {
            "the step method misses more than the tolerance"
        };
        Choice {
            method: Method::Event,
            reason: Some(format!("method auto: event, {why}; {costs}; {notes}")),
            ..step
        }
    }
}

/// The largest fraction on the ladder whose pilot misses at most the tolerance, with its
/// pilot; the smallest tried if none does.
fn largest_passing_fraction(scene: &Scene, spec: &MethodSpec) -> (f64, StepPilot) {
    let mut last = None;
    for k in 0..LADDER_RUNGS {
        let fraction = LADDER_TOP * 2f64.powi(-k);
        let dt = auto_dt(
            &scene.particles.figures(),
            &scene.domain,
            &scene.physics,
            fraction,
        );
        let steps = ((PILOT_RADII / fraction).ceil() as u64).clamp(1, MAX_PILOT_STEPS);
        let pilot = step_pilot(scene, dt, steps, spec.broadphase);
        if pilot.missed_fraction() <= spec.missed_tolerance {
            return (fraction, pilot);
        }
        last = Some((fraction, pilot));
    }
    last.expect("the ladder has rungs")
}

/// The scene the pilots run: a random gas given by its packing with more than
/// [`PILOT_DISKS`] disks is rebuilt with that many (same seed and settings).
fn pilot_scene<'a>(
    source: &SceneSource,
    scene: &'a Scene,
) -> Result<Cow<'a, Scene>, PlacementError> {
    match source {
        SceneSource::Gas(gas)
            if gas.n_particles > PILOT_DISKS && matches!(gas.extent, Extent::Packing(_)) =>
        {
            let mut small = *gas;
            small.n_particles = PILOT_DISKS;
            Ok(Cow::Owned(small.build()?))
        }
        _ => Ok(Cow::Borrowed(scene)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a / b - 1.0).abs() < 1e-12
    }

    #[test]
    fn cost_rates_are_the_measured_ones_at_the_measured_points_and_held_beyond() {
        for row in &MEASURED {
            for point in row {
                let rates = cost_rates(point.n, point.packing);
                assert!(close(
                    rates.step_particle_steps_per_s,
                    point.step_particle_steps_per_s
                ));
                assert!(close(
                    rates.event_collisions_per_s,
                    point.event_collisions_per_s
                ));
            }
        }
        let (first, last) = (&MEASURED[0][0], &MEASURED[2][1]);
        let below = cost_rates(10.0, 0.01);
        assert!(close(
            below.event_collisions_per_s,
            first.event_collisions_per_s
        ));
        let above = cost_rates(1e9, 0.6);
        assert!(close(
            above.step_particle_steps_per_s,
            last.step_particle_steps_per_s
        ));
    }

    #[test]
    fn cost_rates_between_points_lie_between_them() {
        // Halfway in log N and in packing between the first two rows: the geometric mean
        // of the four corners.
        let corners = [
            MEASURED[0][0],
            MEASURED[0][1],
            MEASURED[1][0],
            MEASURED[1][1],
        ];
        let rates = cost_rates((1e4f64 * 1e5).sqrt(), 0.175);
        let mean =
            |rate: fn(&Measured) -> f64| corners.iter().map(|m| rate(m).ln()).sum::<f64>() / 4.0;
        assert!(close(
            rates.event_collisions_per_s,
            mean(|m| m.event_collisions_per_s).exp()
        ));
        assert!(close(
            rates.step_particle_steps_per_s,
            mean(|m| m.step_particle_steps_per_s).exp()
        ));
    }
}
