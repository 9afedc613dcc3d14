//! Detection of inelastic collapse in the event-driven method: infinitely many
//! collisions in finite time, which stalls an unguarded (tc = 0) run with e < 1.
//!
//! The criterion looks at the simulated event sequence only (never at wall time), once
//! per window of collisions (one per disk): the run has collapsed when the last window
//! covered less than [`COLLAPSE_FRACTION`] of the simulated time the run's own mean
//! collision rate so far predicts for that many collisions. A healthy gas never comes
//! near: its rate fluctuates by about 1/√window between windows, and a cooling gas only
//! slows down (Haff: ω ∝ √T), which makes windows longer, not shorter; raising the rate
//! a million-fold would take a million-fold denser or hotter gas. A collapsing cluster,
//! by contrast, collides at geometrically shrinking intervals, so the window's span falls
//! towards 0 (to exactly 0 once the intervals drop below the rounding of the time)
//! within a few dozen of its collisions. Only dissipative scenes (pair or wall
//! restitution below 1) are judged: elastic disks cannot collapse, and a burst of
//! simultaneous elastic collisions (a Newton's cradle of touching disks) must not read
//! as one. What it leaves out: where in the box the collapse happened, and which disks
//! took part.

/// A window covering less than this fraction of its expected simulated time is collapse.
pub const COLLAPSE_FRACTION: f64 = 1e-6;

/// Collisions per window at least (a single disk's window still spans two wall bounces).
const MIN_WINDOW: u64 = 2;

/// The detector's state: where the current window started.
#[derive(Clone, Debug, PartialEq)]
pub struct CollapseDetector {
    /// Collisions per window: one per disk (at least [`MIN_WINDOW`]), so a window sees
    /// every disk collide about twice and its rate fluctuates little.
    window: u64,
    /// The collision count at which the current window ends (never, when not judging).
    window_end: u64,
    /// The time at which the current window started.
    window_start: f64,
    /// When collapse was found: the time of the window's last collision.
    collapse_time: Option<f64>,
}

impl CollapseDetector {
    /// A detector for `n_particles` disks, starting at time 0 with no collisions; it only
    /// judges `dissipative` scenes (some restitution below 1).
    pub fn new(n_particles: usize, dissipative: bool) -> CollapseDetector {
        let window = (n_particles as u64).max(MIN_WINDOW);
        CollapseDetector {
            window,
            window_end: if dissipative { window } else { u64::MAX },
            window_start: 0.0,
            collapse_time: None,
        }
    }

    /// The collision count at which [`CollapseDetector::judge`] is next due.
    #[inline(always)]
    pub fn window_end(&self) -> u64 {
        self.window_end
    }

    /// The time at which collapse was found, if it was.
    pub fn collapse_time(&self) -> Option<f64> {
        self.collapse_time
    }

    /// Judges the window that ends now, at `time` with `collisions` collisions since the
    /// start, and starts the next one; returns whether the run has collapsed.
    pub fn judge(&mut self, collisions: u64, time: f64) -> bool {
        let span = time - self.window_start;
        // The run's mean rate so far, collisions / time, predicts this span for a window.
        let expected = self.window as f64 * time / collisions as f64;
        if time > 0.0 && span < COLLAPSE_FRACTION * expected {
            self.collapse_time = Some(time);
        }
        self.window_start = time;
        self.window_end = collisions + self.window;
        self.collapse_time.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_rate_passes_and_a_stalled_clock_is_collapse() {
        let mut detector = CollapseDetector::new(100, true);
        // 100 collisions per unit time: windows of 100 collisions, one time unit each.
        for k in 1..=5_u64 {
            assert_eq!(detector.window_end(), 100 * k);
            assert!(!detector.judge(100 * k, k as f64));
        }
        // A window 1e-7 long where the mean rate (600 in 5) predicts 0.83: collapse.
        assert!(detector.judge(600, 5.0 + 1e-7));
        assert_eq!(detector.collapse_time(), Some(5.0 + 1e-7));
    }

    #[test]
    fn a_window_a_little_shorter_than_expected_is_not_collapse() {
        let mut detector = CollapseDetector::new(100, true);
        assert!(!detector.judge(100, 1.0));
        // Ten times faster than the mean rate: still far above 1e-6 of it.
        assert!(!detector.judge(200, 1.1));
        assert_eq!(detector.collapse_time(), None);
    }

    #[test]
    fn elastic_scenes_are_never_judged() {
        assert_eq!(CollapseDetector::new(100, false).window_end(), u64::MAX);
    }
}
