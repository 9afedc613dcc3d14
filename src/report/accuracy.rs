//! The accuracy study's analysis: the successful runs grouped by packing, method, dt and
//! TC time, each point's errors against the event-driven reference at the same packing,
//! the Pareto front of speed against error, and for e < 1 the cooling curves against
//! Haff's law with where each run broke down. Pure: records in, numbers out; the report
//! and `figures` present them.

use std::collections::BTreeMap;

use crate::stats::median;
use crate::study::records::{Record, STATUS_OK};

/// A missed-collision fraction above this is a failed step (the stability map's boundary;
/// the default tolerance of `dt = "auto"`, [`crate::run::spec::DEFAULT_MISSED_TOLERANCE`]).
pub const FAILURE_MISSED_FRACTION: f64 = 1e-3;

/// A run whose disks went deeper into a wall than this fraction of their radius is
/// flagged: its walls do not hold (a step too coarse for the speeds at the walls, or
/// resting contact that sinks).
pub const FLAG_WALL_PENETRATION: f64 = 0.1;

/// One method at one packing, dt and TC time: medians over its repetitions.
#[derive(Clone, Debug, PartialEq)]
pub struct AccuracyPoint {
    pub method: String,
    pub packing: f64,
    pub dt: f64,
    /// The event method's TC time (0: guard off); NaN for the step method and in records
    /// older than schema version 5.
    pub tc: f64,
    /// The event method's detected collapse time (the first repetition's: runs are
    /// seeded); NaN when none.
    pub collapse_time: f64,
    /// v_rms·dt/r_min (NaN in records older than schema version 3).
    pub step_over_radius: f64,
    /// Simulated time steps·dt.
    pub sim_time: f64,
    pub runs: usize,
    pub wall_s: f64,
    pub particle_steps_per_s: f64,
    /// Simulated time per wall second (steps·dt / wall_s): the speed at equal physics.
    pub sim_time_per_s: f64,
    /// NaN where not measured (step method without `observe = "accuracy"`).
    pub missed_fraction: f64,
    pub max_overlap: f64,
    /// Fraction of the radius; NaN in records older than schema version 6.
    pub max_wall_penetration: f64,
    pub compressibility_z: f64,
    /// Z's standard error after the equilibration cut (blocking; median over the
    /// repetitions); NaN where the runs did not equilibrate and in records older than
    /// schema version 12.
    pub z_se: f64,
    pub collision_rate: f64,
    /// (Z − Z_ref)/Z_ref against the event reference at the same packing; NaN without one.
    pub z_error: f64,
    /// (ω − ω_ref)/ω_ref likewise.
    pub rate_error: f64,
    /// (E_final − E_initial)/E_initial of an elastic scene, potential energy included
    /// under gravity; NaN for inelastic scenes and where not recorded.
    pub energy_error: f64,
}

impl AccuracyPoint {
    /// The step failed: more than [`FAILURE_MISSED_FRACTION`] of its collisions missed.
    pub fn failed(&self) -> bool {
        self.missed_fraction > FAILURE_MISSED_FRACTION
    }

    /// Disks went more than [`FLAG_WALL_PENETRATION`] of their radius into a wall.
    pub fn deep_in_walls(&self) -> bool {
        self.max_wall_penetration > FLAG_WALL_PENETRATION
    }
}

/// Every point at one packing: the event reference (if run), the other event runs
/// (other TC times or dt) and the step method by decreasing dt.
#[derive(Clone, Debug, PartialEq)]
pub struct PackingGroup {
    pub packing: f64,
    pub reference: Option<AccuracyPoint>,
    /// Event runs besides the reference (e.g. with the TC guard off), by decreasing tc.
    pub events: Vec<AccuracyPoint>,
    pub steps: Vec<AccuracyPoint>,
}

/// A study is an accuracy study when it ran the event method or observed accuracy.
pub fn is_accuracy_study(records: &[Record]) -> bool {
    records
        .iter()
        .any(|r| r.status == STATUS_OK && (r.method == "event" || r.observe == "accuracy"))
}

/// The successful serial runs grouped by packing (ascending), each step point compared
/// with the event reference of the same packing: the guarded event run (the first, if
/// several dt or TC times were run); the other event runs are listed apart.
pub fn analyse(records: &[Record]) -> Vec<PackingGroup> {
    // Packing is a float computed from the box: group on its 4-decimal text, the
    // precision the report prints, so equal manifest packings land together. Runs that
    // differ in tc are never merged.
    let mut runs: BTreeMap<(String, String, String, String), Vec<&Record>> = BTreeMap::new();
    for record in records.iter().filter(|r| r.status == STATUS_OK) {
        let key = (
            format!("{:.4}", record.packing),
            record.method.clone(),
            format!("{:e}", record.tc),
            format!("{:e}", record.dt),
        );
        runs.entry(key).or_default().push(record);
    }
    let mut groups: BTreeMap<String, PackingGroup> = BTreeMap::new();
    for ((packing_key, method, ..), group) in &runs {
        let point = summarise(method, group);
        let entry = groups
            .entry(packing_key.clone())
            .or_insert_with(|| PackingGroup {
                packing: point.packing,
                reference: None,
                events: Vec::new(),
                steps: Vec::new(),
            });
        if method == "event" {
            entry.events.push(point);
        } else {
            entry.steps.push(point);
        }
    }
    let mut groups: Vec<PackingGroup> = groups.into_values().collect();
    groups.sort_by(|a, b| a.packing.total_cmp(&b.packing));
    for group in &mut groups {
        group.steps.sort_by(|a, b| b.dt.total_cmp(&a.dt));
        // Guarded first (tc not recorded counts as guarded: NaN sorts above every tc),
        // by decreasing tc; the reference is the first guarded run.
        group.events.sort_by(|a, b| b.tc.total_cmp(&a.tc));
        if !group.events.is_empty() {
            let chosen = group.events.iter().position(|p| p.tc != 0.0).unwrap_or(0);
            group.reference = Some(group.events.remove(chosen));
        }
        if let Some(reference) = &group.reference {
            let (z_ref, rate_ref) = (reference.compressibility_z, reference.collision_rate);
            for point in group.steps.iter_mut().chain(&mut group.events) {
                point.z_error = relative_error(point.compressibility_z, z_ref);
                point.rate_error = relative_error(point.collision_rate, rate_ref);
            }
        }
        if let Some(reference) = &mut group.reference {
            reference.z_error = 0.0;
            reference.rate_error = 0.0;
        }
    }
    groups
}

fn relative_error(value: f64, reference: f64) -> f64 {
    if reference != 0.0 {
        (value - reference) / reference
    } else {
        f64::NAN
    }
}

/// Medians of one (packing, method, dt) group of runs.
fn summarise(method: &str, runs: &[&Record]) -> AccuracyPoint {
    let med = |field: fn(&Record) -> f64| {
        let mut values: Vec<f64> = runs.iter().map(|r| field(r)).collect();
        median(&mut values)
    };
    let first = runs[0];
    let wall_s = med(|r| r.wall_s);
    let sim_time = first.steps as f64 * first.dt;
    AccuracyPoint {
        method: method.to_owned(),
        packing: first.packing,
        dt: first.dt,
        tc: first.tc,
        collapse_time: first.collapse_time,
        step_over_radius: med(|r| r.rms_step_over_radius),
        sim_time,
        runs: runs.len(),
        wall_s,
        particle_steps_per_s: med(|r| r.particle_steps_per_s),
        sim_time_per_s: sim_time / wall_s,
        missed_fraction: med(|r| r.missed_collision_fraction),
        max_overlap: med(|r| r.max_overlap),
        max_wall_penetration: med(|r| r.max_wall_penetration),
        compressibility_z: med(|r| r.compressibility_z),
        z_se: med(|r| r.compressibility_z_se),
        collision_rate: med(|r| r.collision_rate),
        z_error: f64::NAN,
        rate_error: f64::NAN,
        energy_error: med(|r| r.energy_relative_error),
    }
}

/// Which of the (speed, error) points are Pareto-optimal: no other point is at least as
/// fast and at least as accurate and better in one. Points with a NaN are never on it.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<bool> {
    points
        .iter()
        .map(|&(speed, error)| {
            !speed.is_nan()
                && !error.is_nan()
                && !points
                    .iter()
                    .any(|&(s, e)| s >= speed && e <= error && (s > speed || e < error))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::environment::Environment;
    use crate::study::records::RecordContext;

    /// A successful record with nothing measured yet.
    fn blank_ok() -> Record {
        let environment = Environment {
            hostname: "h".into(),
            cpu_model: "c".into(),
            logical_cores: 2,
            physical_cores: 2,
            usable_cpus: 2,
            cpu_affinity: "0-1".into(),
            memory_bytes: 1,
            os: "o".into(),
            rustc: "r".into(),
            profile: "release".into(),
            features: String::new(),
            git_commit: "g".into(),
            git_dirty: false,
            mpi_library: "none".into(),
            load_average_start: 0.0,
        };
        let context = RecordContext {
            study: "accuracy",
            ..crate::study::records::serial_context(&environment)
        };
        let mut record = Record::failed(&context, STATUS_OK, String::new());
        record.status = STATUS_OK.to_owned();
        record
    }

    #[test]
    fn event_labels_give_the_tc_time_to_three_significant_digits() {
        assert_eq!(method_label("event", 0.0), "event, tc = 0");
        assert_eq!(
            method_label("event", 0.00009999999999999988),
            "event, tc = 0.0001"
        );
        assert_eq!(method_label("event", 0.0123456), "event, tc = 0.0123");
        assert_eq!(method_label("event", f64::NAN), "event");
        assert_eq!(method_label("step", 0.1), "step");
    }

    #[test]
    fn the_pareto_front_keeps_the_points_nothing_beats() {
        // (speed, error): (3, 0.5) beats (2, 0.6); (1, 0.01) and (3, 0.5) trade off;
        // the NaN point is left out; equal points are both kept.
        let points = [
            (3.0, 0.5),
            (2.0, 0.6),
            (1.0, 0.01),
            (f64::NAN, 0.0),
            (1.0, 0.01),
        ];
        assert_eq!(pareto_front(&points), [true, false, true, false, true]);
    }

    #[test]
    fn relative_errors_are_against_the_event_run_of_the_same_packing() {
        let record = |method: &str, packing: f64, dt: f64, z: f64, rate: f64, wall: f64| {
            let mut r = blank_ok();
            r.method = method.to_owned();
            r.packing = packing;
            r.dt = dt;
            r.steps = (60.0 / dt).round() as u64;
            r.compressibility_z = z;
            r.collision_rate = rate;
            r.wall_s = wall;
            r.missed_collision_fraction = if method == "event" { 0.0 } else { dt / 10.0 };
            r
        };
        let records = [
            record("step", 0.4, 0.01, 2.75, 1.40, 1.0),
            record("event", 0.4, 0.1, 2.80, 1.50, 0.2),
            record("step", 0.4, 0.1, 2.52, 1.20, 0.1),
            record("step", 0.4, 0.1, 2.52, 1.20, 0.3),
            record("step", 0.05, 0.1, 1.10, 0.09, 0.1),
        ];
        let groups = analyse(&records);
        assert_eq!(groups.len(), 2);
        assert!(groups[0].reference.is_none() && groups[0].steps[0].z_error.is_nan());
        let dense = &groups[1];
        assert_eq!(dense.reference.as_ref().unwrap().compressibility_z, 2.80);
        let dts: Vec<f64> = dense.steps.iter().map(|p| p.dt).collect();
        assert_eq!(dts, [0.1, 0.01]);
        let coarse = &dense.steps[0];
        assert_eq!(coarse.runs, 2);
        assert!((coarse.wall_s - 0.2).abs() < 1e-12);
        assert!((coarse.sim_time_per_s - 300.0).abs() < 1e-9);
        assert!((coarse.z_error - (-0.1)).abs() < 1e-12);
        assert!((coarse.rate_error - (-0.2)).abs() < 1e-12);
        assert!(coarse.failed() && !dense.steps[1].failed());
    }
}

/// A cooling curve deviating from Haff's law by more than this (relative, anywhere up to
/// the end of the run) has broken down.
pub const HAFF_BREAKDOWN: f64 = 0.05;

/// One e < 1 run's cooling curve against Haff's law T₀/(1 + t/t₀)².
#[derive(Clone, Debug, PartialEq)]
pub struct CoolingCurve {
    pub method: String,
    pub packing: f64,
    pub dt: f64,
    /// The event method's TC time (0: guard off); NaN for the step method.
    pub tc: f64,
    /// v_rms·dt/r_min at the start (NaN where not recorded).
    pub step_over_radius: f64,
    /// [t, T] from the record's `temperature_curve` (the first repetition: the runs are
    /// seeded, so the repetitions' curves are the same); it ends at a collapse.
    pub points: Vec<[f64; 2]>,
    /// Haff's t₀ at this packing, fitted to the event reference's curve (see [`cooling`]).
    pub haff_t0: f64,
    /// Largest |T/T_Haff − 1| over the curve.
    pub haff_deviation: f64,
    /// The event method's TC guard count; `None` for the step method.
    pub collapse_guard_fired: Option<u64>,
    /// The event method's detected inelastic collapse time; NaN when none.
    pub collapse_time: f64,
}

/// A run's method as the report and figures label it: the event method with its TC
/// time where recorded ("event, tc = 0"), the step method by name.
pub fn method_label(method: &str, tc: f64) -> String {
    if method == "event" && tc.is_finite() {
        format!("event, tc = {}", three_significant(tc))
    } else {
        method.to_owned()
    }
}

/// A number rounded to three significant digits, written shortest ("0", "0.0001",
/// "0.25"): the default TC time is a fraction of r/v_rms, whose rounding
/// ("0.00009999999999999988") says nothing.
fn three_significant(value: f64) -> String {
    let rounded: f64 = format!("{value:.2e}")
        .parse()
        .expect("a formatted float parses");
    format!("{rounded}")
}

/// How and when a run broke down.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Breakdown {
    /// The event method detected inelastic collapse at this time (and stopped there).
    Collapse { time: f64 },
    /// T first departed from Haff's law by more than [`HAFF_BREAKDOWN`] at this sampled
    /// time.
    OffHaff { time: f64 },
}

impl CoolingCurve {
    /// T(t) under Haff's law from this curve's T₀.
    pub fn haff(&self, t: f64) -> f64 {
        self.points[0][1] / (1.0 + t / self.haff_t0).powi(2)
    }

    /// |T/T_Haff − 1| at a point of the curve.
    fn deviation(&self, [t, temperature]: [f64; 2]) -> f64 {
        (temperature / self.haff(t) - 1.0).abs()
    }

    /// Whether and when the run broke down: a collapse, else the first sampled point
    /// off Haff's law by more than [`HAFF_BREAKDOWN`].
    pub fn breakdown(&self) -> Option<Breakdown> {
        if self.collapse_time.is_finite() {
            return Some(Breakdown::Collapse {
                time: self.collapse_time,
            });
        }
        self.points
            .iter()
            .find(|&&point| {
                let deviation = self.deviation(point);
                deviation.is_nan() || deviation > HAFF_BREAKDOWN
            })
            .map(|point| Breakdown::OffHaff { time: point[0] })
    }

    /// The curve collapsed or deviates from Haff's law by more than [`HAFF_BREAKDOWN`].
    pub fn broke_down(&self) -> bool {
        self.breakdown().is_some()
    }
}

/// The cooling curves of a study's successful e < 1 runs (records with a
/// `temperature_curve`), one per packing, method, TC time and dt, ordered by packing,
/// event first (guarded by decreasing tc, then unguarded), then by decreasing dt.
/// Haff's t₀ is fitted, per packing, to the first event run's curve (the guarded
/// reference, which cannot collapse) by least squares on √(T₀/T) − 1 = t/t₀ (the law's
/// linear form); the restitution is not in the records, so the law is the event
/// method's, and the other curves are judged against it. Empty without curves, or at a
/// packing without an event run.
pub fn cooling(records: &[Record]) -> Vec<CoolingCurve> {
    let mut runs: BTreeMap<(String, bool, String, String), &Record> = BTreeMap::new();
    for record in records
        .iter()
        .filter(|r| r.status == STATUS_OK && !r.temperature_curve.is_empty())
    {
        // Decreasing tc as increasing text: 1/(1 + tc) in fixed width; a tc not
        // recorded (NaN: older records, or the step method) as the empty text, first.
        let tc_order = if record.tc.is_nan() {
            String::new()
        } else {
            format!("{:.15}", 1.0 / (1.0 + record.tc))
        };
        let key = (
            format!("{:.4}", record.packing),
            record.method != "event",
            tc_order,
            format!("{:024.12}", 1.0 / record.dt),
        );
        runs.entry(key).or_insert(record);
    }
    let mut curves = Vec::new();
    let (mut t0, mut packing) = (f64::NAN, String::new());
    for ((packing_key, is_step, ..), record) in runs {
        if packing_key != packing {
            (t0, packing) = (f64::NAN, packing_key);
        }
        let Ok(points) = serde_json::from_str::<Vec<[f64; 2]>>(&record.temperature_curve) else {
            continue;
        };
        if points.len() < 2 || points[0][1] <= 0.0 {
            continue;
        }
        if !is_step && t0.is_nan() {
            t0 = haff_t0(&points);
        }
        if t0.is_nan() {
            continue;
        }
        let mut curve = CoolingCurve {
            method: record.method.clone(),
            packing: record.packing,
            dt: record.dt,
            tc: record.tc,
            step_over_radius: record.rms_step_over_radius,
            points,
            haff_t0: t0,
            haff_deviation: 0.0,
            collapse_guard_fired: record.collapse_guard_fired,
            collapse_time: record.collapse_time,
        };
        curve.haff_deviation = curve
            .points
            .iter()
            .map(|&point| curve.deviation(point))
            .fold(0.0, f64::max);
        curves.push(curve);
    }
    curves
}

/// Least-squares t₀ of √(T₀/T) − 1 = t/t₀ over a curve (NaN if it does not cool).
fn haff_t0(points: &[[f64; 2]]) -> f64 {
    let t_zero = points[0][1];
    let (tt, ty) =
        points
            .iter()
            .filter(|p| p[1] > 0.0)
            .fold((0.0, 0.0), |(tt, ty), &[t, temperature]| {
                let y = (t_zero / temperature).sqrt() - 1.0;
                (tt + t * t, ty + t * y)
            });
    if ty > 0.0 { tt / ty } else { f64::NAN }
}
