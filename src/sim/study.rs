//! The pole-axis study (after Table II of Xue et al., "Automatic Calibration of Dual-LiDARs
//! Using Two Poles Stickered with Retro-Reflective Tape", 2019): how far from a
//! pole's true axis is (a) the line fitted through its points and (b) the axis of a fitted
//! cylinder, for a VLP-16 at a given distance from a pole of a given radius.
//!
//! Setup of one trial: a vertical pole 3 m long standing at `(distance, 0, 0)`, a level VLP-16 at
//! height 1 m above the pole's base with a random heading (so the azimuth sampling phase varies),
//! range noise 0.006 m, no ground. The **axis offset error** of a fitted line is the mean, over the
//! heights of the lowest and the highest hit, of the distance from the fitted line to the true axis
//! measured in the horizontal plane at that height (the text's eq. 5 reading).
//!
//! `cargo run --release --example pole_axis_study` prints the full table; `docs/pole_axis_study.md`
//! holds it and is included below.
//!
#![doc = include_str!("../../docs/pole_axis_study.md")]

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::shapes::{Cylinder, IntensityRange, Shape};
use super::{scan, BeamModel, Preset, ScanOptions};
use crate::error::{Error, Result};
use crate::fit::cylinder::fit_cylinder;
use crate::fit::fit_line;
use crate::geometry::Line;

/// Range noise of the study, metres (Xue et al., 2019).
pub const STUDY_RANGE_NOISE: f64 = 0.006;
/// Length of the studied pole, metres.
pub const STUDY_POLE_LENGTH: f64 = 3.0;
/// Height of the sensor above the pole's base, metres.
pub const STUDY_SENSOR_HEIGHT: f64 = 1.0;

/// The outcome of one trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoleAxisTrial {
    /// Points on the pole.
    pub points: usize,
    /// Axis offset error of the line through the points (PCA), metres.
    pub line_error: f64,
    /// Axis offset error of the cylinder fit with the radius known, metres.
    pub cylinder_error: f64,
    /// Axis offset error of the cylinder fit with the radius estimated, metres.
    pub cylinder_free_radius_error: f64,
    /// The estimated radius of the free-radius fit, metres.
    pub estimated_radius: f64,
}

/// Mean distance from `fitted` to `truth` in the planes orthogonal to `truth` at axial
/// coordinates `heights` (relative to `truth.point`).
pub fn axis_offset_error(fitted: &Line, truth: &Line, heights: &[f64]) -> Result<f64> {
    let a = truth.direction.into_inner();
    let cos = a.dot(&fitted.direction);
    if cos.abs() < 1e-6 || heights.is_empty() {
        return Err(Error::Degenerate(
            "fitted line is orthogonal to the axis (or no heights given)".into(),
        ));
    }
    let total: f64 = heights
        .iter()
        .map(|h| {
            let q = truth.point + a * *h;
            let t = a.dot(&(q - fitted.point)) / cos;
            truth.distance(&(fitted.point + fitted.direction.into_inner() * t))
        })
        .sum();
    Ok(total / heights.len() as f64)
}

/// One trial of the study: a VLP-16 at `distance` metres from a pole of `radius` metres.
pub fn pole_axis_trial(distance: f64, radius: f64, seed: u64) -> Result<PoleAxisTrial> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let pole = Cylinder::new(
        Point3::new(distance, 0.0, -STUDY_SENSOR_HEIGHT),
        Vector3::z(),
        STUDY_POLE_LENGTH,
        radius,
    )?;
    let shapes = [Shape::cylinder(pole, IntensityRange::RETROREFLECTIVE)];
    let yaw = std::f64::consts::TAU * rng.random::<f64>();
    let world_from_sensor = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    );
    let options = ScanOptions {
        seed: rng.random(),
        range_noise: Some(STUDY_RANGE_NOISE),
        dropout: 0.0,
    };
    let points = scan(
        &BeamModel::preset(Preset::Vlp16),
        &shapes,
        &world_from_sensor,
        &options,
    )?
    .positions();
    let truth = pole.axis().transformed(&world_from_sensor.inverse());
    let heights: Vec<f64> = {
        let along = points
            .iter()
            .map(|p| truth.direction.dot(&(p - truth.point)));
        let (lo, hi) = along.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), h| {
            (lo.min(h), hi.max(h))
        });
        vec![lo, hi]
    };
    let line = fit_line(&points)?.line;
    let viewpoint = Point3::origin();
    let known = fit_cylinder(&points, Some(radius), &line, &viewpoint)?;
    let free = fit_cylinder(&points, None, &line, &viewpoint)?;
    Ok(PoleAxisTrial {
        points: points.len(),
        line_error: axis_offset_error(&line, &truth, &heights)?,
        cylinder_error: axis_offset_error(&known.axis, &truth, &heights)?,
        cylinder_free_radius_error: axis_offset_error(&free.axis, &truth, &heights)?,
        estimated_radius: free.radius,
    })
}
