//! Calibration methods: they take the two sensors' clouds and return `reference_from_target`.
//!
//! * [`planes`]: three planar surfaces of a wall corner seen by both sensors (Jiao et al., 2019),
//!   without an initial guess and for any mounting orientation.
//! * [`poles`]: two or more non-parallel poles wrapped in retro-reflective tape (Xue et al., 2019), with
//!   the cylinder axis instead of the centroid line and a scored choice among the 8 hypotheses.
//! * [`targetless`]: the planes of an ordinary scene (a street), matched by plane pairs and
//!   triplets without an initial guess, verified and refined by point-to-plane ICP; refuses
//!   scenes that leave a degree of freedom unobserved.
//! * [`method`]: one entry point over the three ([`calibrate`]; [`Method::Auto`] keeps the
//!   best-fitting certified result).
//! * [`result`]: what every method returns ([`Calibration`]: the common fields, and the method's
//!   own in `details`).
//! * [`rig`]: the calibration of a whole rig ([`calibrate_rig`]), made consistent by a small pose
//!   graph ([`crate::pose_graph`]).
//!
//! The entry points of [`method`] and [`rig`] and the types of [`result`] are re-exported here.

pub(crate) mod input;
pub mod method;
pub mod planes;
pub mod poles;
pub mod result;
pub mod rig;
pub mod sequence;
pub mod targetless;

pub use method::{calibrate, Cloud, Method, MethodOptions};
pub use result::{
    Calibration, Details, MethodDetails, PlanarCalibration, PoleCalibration, Refinement, Solver,
    TargetlessCalibration,
};
pub use rig::{calibrate_rig, RigCalibration, RigOptions};

use std::time::Instant;

/// Wall-clock time of each pipeline stage, in milliseconds.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Timings {
    /// `(stage, milliseconds)` in the order each stage first ran; a stage that runs more than once
    /// (the corner method's next-plane search repeats matching, refinement and certification)
    /// holds the sum of its runs.
    pub stages: Vec<(&'static str, f64)>,
}

impl Timings {
    /// Total of all stages.
    pub fn total(&self) -> f64 {
        self.stages.iter().map(|(_, ms)| ms).sum()
    }
}

/// Records consecutive stage durations.
pub(crate) struct Stopwatch {
    last: Instant,
    timings: Timings,
}

impl Stopwatch {
    pub(crate) fn start() -> Self {
        Stopwatch {
            last: Instant::now(),
            timings: Timings::default(),
        }
    }

    /// Closes the current stage under `name`, adding to it if it ran before.
    pub(crate) fn lap(&mut self, name: &'static str) {
        let now = Instant::now();
        let ms = now.duration_since(self.last).as_secs_f64() * 1e3;
        match self.timings.stages.iter_mut().find(|(n, _)| *n == name) {
            Some((_, total)) => *total += ms,
            None => self.timings.stages.push((name, ms)),
        }
        self.last = now;
    }

    pub(crate) fn finish(self) -> Timings {
        self.timings
    }
}

#[cfg(test)]
mod tests {
    use super::Stopwatch;

    #[test]
    fn a_stage_that_runs_twice_is_one_entry_holding_both_runs() {
        let mut clock = Stopwatch::start();
        clock.lap("match");
        std::thread::sleep(std::time::Duration::from_millis(2));
        clock.lap("refine");
        clock.lap("match");
        std::thread::sleep(std::time::Duration::from_millis(2));
        clock.lap("match");
        let timings = clock.finish();
        let names: Vec<&str> = timings.stages.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, ["match", "refine"]);
        // The second and third runs of "match" are in its entry: at least the 2 ms slept there.
        assert!(timings.stages[0].1 >= 2.0, "{:?}", timings.stages);
        assert!(timings.stages[1].1 >= 2.0, "{:?}", timings.stages);
        assert_eq!(timings.total(), timings.stages[0].1 + timings.stages[1].1);
    }
}
