//! The adaptive correspondence distance of the odometry (the idea of KISS-ICP, Vizzo et al.,
//! 2023): how far the constant-velocity prediction has been from the registered pose, measured
//! as the largest displacement it causes within the sensor's range, and accumulated over the
//! frames that moved. Three of its standard deviations bound where a correspondence may lie.

use nalgebra::Isometry3;

/// Running statistics of the prediction's error (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct AdaptiveThreshold {
    initial: f64,
    min_motion: f64,
    max_range: f64,
    sum_squares: f64,
    samples: usize,
}

impl AdaptiveThreshold {
    /// Starts at `initial` (metres, used until a frame has moved by more than `min_motion`).
    pub(crate) fn new(initial: f64, min_motion: f64, max_range: f64) -> Self {
        AdaptiveThreshold {
            initial,
            min_motion,
            max_range,
            sum_squares: 0.0,
            samples: 0,
        }
    }

    /// The displacement `deviation` causes at most at the sensor's range: its translation plus
    /// the chord its rotation sweeps at `max_range`.
    fn displacement(&self, deviation: &Isometry3<f64>) -> f64 {
        let theta = deviation.rotation.angle();
        2.0 * self.max_range * (theta / 2.0).sin() + deviation.translation.vector.norm()
    }

    /// Records a registered frame: `deviation` is `prediction^-1 * registered`, `motion` the
    /// frame's motion from the previous one.
    pub(crate) fn update(&mut self, deviation: &Isometry3<f64>, motion: &Isometry3<f64>) {
        if self.displacement(motion) > self.min_motion {
            let e = self.displacement(deviation);
            self.sum_squares += e * e;
            self.samples += 1;
        }
    }

    /// The standard deviation of the prediction's error (metres).
    pub(crate) fn sigma(&self) -> f64 {
        if self.samples == 0 {
            self.initial
        } else {
            (self.sum_squares / self.samples as f64).sqrt()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn starts_at_the_initial_value_and_tracks_the_errors() {
        let mut t = AdaptiveThreshold::new(2.0, 0.1, 100.0);
        assert_eq!(t.sigma(), 2.0);
        let still = Isometry3::identity();
        t.update(&Isometry3::translation(0.3, 0.0, 0.0), &still);
        assert_eq!(t.sigma(), 2.0, "a standing frame says nothing");
        let moved = Isometry3::translation(1.0, 0.0, 0.0);
        t.update(&Isometry3::translation(0.03, 0.04, 0.0), &moved);
        assert!((t.sigma() - 0.05).abs() < 1e-12);
        let turn = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.001),
        );
        let mut r = AdaptiveThreshold::new(2.0, 0.1, 100.0);
        r.update(&turn, &moved);
        assert!((r.sigma() - 0.1).abs() < 1e-6);
    }
}
