//! A scan simulator: multi-beam LiDAR models casting rays at shapes, and ready-made scenes with
//! ground truth, for tests, benches and demos.
//!
//! * [`beams`]: the VLP-16, HDL-32E, HDL-64E and OS1-128 beam models and custom ones.
//! * [`shapes`]: finite rectangles (walls, ground), boxes (clutter) and finite cylinders with a
//!   retro-reflective band (poles), each with its own intensity range.
//! * [`scan`] casts every beam of one revolution at a list of shapes (in parallel with the
//!   `parallel` feature); the nearest hit wins. Points come back in the **sensor frame**.
//! * [`scenes`]: the synthetic protocol of the planar-surfaces paper, a building corner scanned by
//!   two spinning LiDARs, and two taped poles, each with `reference_from_target` and the true
//!   planes / pole axes in the reference frame.
//!
//! # Determinism
//! A scan is a pure function of its inputs and `seed`: ring `i` draws its range noise, dropout and
//! intensities from its own `ChaCha8Rng` (seeded with `seed`, stream `i`), so the points are
//! bit-identical whatever the number of threads. Output order is **ring-major**: ring 0 (the lowest
//! beam) first, and within a ring by increasing azimuth column, starting at the sensor's +x axis and
//! turning counter-clockwise about +z. A model with a limited horizontal field of view
//! ([`BeamModel::with_horizontal_fov`]) fires only the columns inside it, starting at `-fov/2` and
//! turning counter-clockwise to `+fov/2`, so a ring's points are contiguous and in increasing
//! azimuth; the columns outside the field are not cast at all.
//!
//! # Why poles need a cylinder fit
//! A LiDAR sees the half of a pole that faces it, so a line fitted through a pole's points is offset
//! from the axis toward the sensor by about `pi r / 4` (and two sensors see opposite sides). The
//! study in [`study`] (its table is `docs/pole_axis_study.md`; rerun it with
//! `cargo run --release --example pole_axis_study`) measures this with a simulated VLP-16 and shows
//! that [`crate::fit::cylinder::fit_cylinder`] removes it.
//!
//! # Example
//! ```
//! use lidarcal::sim::{scan, BeamModel, Preset, ScanOptions};
//! use lidarcal::sim::shapes::{IntensityRange, Rectangle, Shape};
//! use nalgebra::{Isometry3, Point3, Vector3};
//!
//! // A VLP-16 two metres above a 40 m x 40 m ground plane.
//! let ground = Rectangle::centered(Point3::origin(), Vector3::x(), Vector3::y(), 40.0, 40.0)?;
//! let shapes = [Shape::rectangle(ground, IntensityRange::GROUND)];
//! let world_from_sensor = Isometry3::translation(0.0, 0.0, 2.0);
//! let model = BeamModel::preset(Preset::Vlp16);
//! let options = ScanOptions { seed: 7, ..ScanOptions::default() };
//! let points = scan(&model, &shapes, &world_from_sensor, &options)?;
//! // The 8 downward beams reach the ground within the square; the upward ones see nothing.
//! assert!(points.points.iter().all(|p| p.ring < 8));
//! assert!(points.points.iter().all(|p| (p.position.z + 2.0).abs() < 0.1));
//! # Ok::<(), lidarcal::Error>(())
//! ```

pub mod beams;
pub mod scenes;
pub mod shapes;
pub mod study;

use nalgebra::{Isometry3, Point3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub use beams::{BeamModel, BeamSettings, Preset};
pub use scenes::{Pole, Scene};
use shapes::Shape;

use crate::error::{ensure_finite, Error, Result};

/// Options of one simulated revolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanOptions {
    /// Seed of the range noise, dropout and intensity draws.
    pub seed: u64,
    /// Range noise in metres (1 sigma, along the beam); `None` uses the model's default.
    pub range_noise: Option<f64>,
    /// Probability in `[0, 1]` that a return is dropped.
    pub dropout: f64,
}

impl Default for ScanOptions {
    fn default() -> Self {
        ScanOptions {
            seed: 0,
            range_noise: None,
            dropout: 0.0,
        }
    }
}

/// One return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanPoint {
    /// Position in the sensor frame, metres.
    pub position: Point3<f64>,
    /// Intensity, 0–255.
    pub intensity: f64,
    /// Ring (beam) index, 0 = lowest elevation.
    pub ring: u16,
    /// Index of the shape that was hit, in the list given to [`scan`] (for generated point sets
    /// such as the paper protocol: the plane index, `None` for clutter).
    pub shape: Option<usize>,
}

/// A simulated return as a PCD record (the file formats know nothing of the simulator).
#[cfg(feature = "io")]
impl From<&ScanPoint> for crate::io::pcd::PcdPoint {
    fn from(p: &ScanPoint) -> Self {
        crate::io::pcd::PcdPoint {
            position: p.position,
            intensity: p.intensity,
            ring: p.ring,
        }
    }
}

/// The returns of one sensor, in the sensor frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scan {
    /// The points, ring-major (see the module docs).
    pub points: Vec<ScanPoint>,
}

impl Scan {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }
    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
    /// The positions alone.
    pub fn positions(&self) -> Vec<Point3<f64>> {
        self.points.iter().map(|p| p.position).collect()
    }
    /// Positions of the points that hit shape `index`.
    pub fn positions_of_shape(&self, index: usize) -> Vec<Point3<f64>> {
        self.points
            .iter()
            .filter(|p| p.shape == Some(index))
            .map(|p| p.position)
            .collect()
    }
}

fn check_pose(what: &str, pose: &Isometry3<f64>) -> Result<()> {
    ensure_finite(
        what,
        pose.translation
            .vector
            .iter()
            .chain(pose.rotation.coords.iter()),
    )?;
    let norm = pose.rotation.coords.norm();
    if (norm - 1.0).abs() > crate::geometry::ORTHONORMALITY_TOLERANCE {
        return Err(Error::InvalidInput(format!(
            "{what} is not rigid: its rotation quaternion has norm {norm}"
        )));
    }
    Ok(())
}

pub(crate) fn check_dropout(dropout: f64) -> Result<()> {
    if !(0.0..=1.0).contains(&dropout) {
        return Err(Error::InvalidInput(format!(
            "dropout must be a probability in [0, 1], got {dropout}"
        )));
    }
    Ok(())
}

/// The unit direction of beam `elevation` at `azimuth` in the sensor frame.
pub fn beam_direction(elevation: f64, azimuth: f64) -> Vector3<f64> {
    let (se, ce) = elevation.sin_cos();
    let (sa, ca) = azimuth.sin_cos();
    Vector3::new(ce * ca, ce * sa, se)
}

struct RingContext<'a> {
    model: &'a BeamModel,
    shapes: &'a [Shape],
    world_from_sensor: &'a Isometry3<f64>,
    noise: Normal<f64>,
    dropout: f64,
    seed: u64,
}

fn scan_ring(ctx: &RingContext<'_>, ring: usize, elevation: f64) -> Vec<ScanPoint> {
    let mut rng = ChaCha8Rng::seed_from_u64(ctx.seed);
    rng.set_stream(ring as u64);
    let origin = Point3::from(ctx.world_from_sensor.translation.vector);
    let step = ctx.model.azimuth_step();
    // 0 for the full turn, where `first + step * column` is bit for bit `step * column`.
    let first = ctx.model.first_azimuth();
    let ring_id = u16::try_from(ring).unwrap_or(u16::MAX);
    let mut out = Vec::new();
    for column in 0..ctx.model.swept_columns() {
        let d_sensor = beam_direction(elevation, first + step * column as f64);
        let d_world = ctx.world_from_sensor.rotation * d_sensor;
        let mut nearest: Option<(usize, shapes::Hit)> = None;
        for (index, shape) in ctx.shapes.iter().enumerate() {
            if let Some(hit) = shape.intersect(&origin, &d_world) {
                if nearest.is_none_or(|(_, best)| hit.t < best.t) {
                    nearest = Some((index, hit));
                }
            }
        }
        let Some((index, hit)) = nearest else {
            continue;
        };
        if hit.t < ctx.model.min_range() || hit.t > ctx.model.max_range() {
            continue;
        }
        let u: f64 = rng.random();
        let range = hit.t + ctx.noise.sample(&mut rng);
        let intensity = hit.intensity.at(rng.random());
        if u < ctx.dropout || range <= 0.0 {
            continue;
        }
        out.push(ScanPoint {
            position: Point3::from(d_sensor * range),
            intensity,
            ring: ring_id,
            shape: Some(index),
        });
    }
    out
}

/// Simulates one revolution of `model` at `world_from_sensor` among `shapes` (world frame).
///
/// Every beam is cast at every azimuth column of the model's field of view; the nearest surface hit with `t > 0` is measured if
/// its distance is within the model's range limits (a nearer-than-minimum surface blocks the beam).
/// The range gets Gaussian noise along the beam, the return is dropped with probability
/// `options.dropout`, and its intensity is drawn uniformly from the surface's range. Errors for a
/// non-finite or non-rigid pose, a negative or non-finite noise, or a dropout outside `[0, 1]`.
pub fn scan(
    model: &BeamModel,
    shapes: &[Shape],
    world_from_sensor: &Isometry3<f64>,
    options: &ScanOptions,
) -> Result<Scan> {
    check_pose("world_from_sensor", world_from_sensor)?;
    check_dropout(options.dropout)?;
    let sigma = options.range_noise.unwrap_or(model.range_noise());
    beams::check_noise(sigma)?;
    let noise = Normal::new(0.0, sigma)
        .map_err(|e| Error::InvalidInput(format!("range noise {sigma}: {e}")))?;
    let ctx = RingContext {
        model,
        shapes,
        world_from_sensor,
        noise,
        dropout: options.dropout,
        seed: options.seed,
    };
    let elevations = model.elevations();
    #[cfg(feature = "parallel")]
    let rings: Vec<Vec<ScanPoint>> = {
        use rayon::prelude::*;
        elevations
            .par_iter()
            .enumerate()
            .map(|(ring, &e)| scan_ring(&ctx, ring, e))
            .collect()
    };
    #[cfg(not(feature = "parallel"))]
    let rings: Vec<Vec<ScanPoint>> = elevations
        .iter()
        .enumerate()
        .map(|(ring, &e)| scan_ring(&ctx, ring, e))
        .collect();
    Ok(Scan {
        points: rings.into_iter().flatten().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use shapes::{IntensityRange, Rectangle};

    fn ground() -> Vec<Shape> {
        let r = Rectangle::centered(Point3::origin(), Vector3::x(), Vector3::y(), 200.0, 200.0)
            .unwrap();
        vec![Shape::rectangle(r, IntensityRange::GROUND)]
    }

    #[test]
    fn noiseless_ground_hits_are_exact() {
        let model = BeamModel::preset(Preset::Vlp16);
        let pose = Isometry3::translation(1.0, -2.0, 1.5);
        let opts = ScanOptions {
            range_noise: Some(0.0),
            ..ScanOptions::default()
        };
        let s = scan(&model, &ground(), &pose, &opts).unwrap();
        assert_eq!(s.len(), 8 * 1800);
        for p in &s.points {
            assert!((p.position.z + 1.5).abs() < 1e-9);
            assert!(
                (IntensityRange::GROUND.min..=IntensityRange::GROUND.max).contains(&p.intensity)
            );
        }
        // Ring-major order.
        assert!(s.points.windows(2).all(|w| w[0].ring <= w[1].ring));
    }

    #[test]
    fn limited_field_of_view_sweeps_its_columns_only() {
        let model = BeamModel::preset(Preset::Vlp16)
            .with_horizontal_fov(90.0)
            .unwrap();
        let pose = Isometry3::translation(0.0, 0.0, 1.5);
        let opts = ScanOptions {
            range_noise: Some(0.0),
            ..ScanOptions::default()
        };
        let s = scan(&model, &ground(), &pose, &opts).unwrap();
        // 8 downward beams, -45..+45 degrees inclusive in 0.2 degree steps.
        assert_eq!(s.len(), 8 * 451);
        let limit = 45f64.to_radians() + 1e-9;
        for w in s.points.windows(2) {
            assert!(w[0].ring <= w[1].ring);
            if w[0].ring == w[1].ring {
                let a0 = w[0].position.y.atan2(w[0].position.x);
                let a1 = w[1].position.y.atan2(w[1].position.x);
                assert!(a0 < a1, "increasing azimuth within a ring");
            }
        }
        assert!(s
            .points
            .iter()
            .all(|p| p.position.y.atan2(p.position.x).abs() <= limit));
    }

    #[test]
    fn dropout_and_bad_options() {
        let model = BeamModel::preset(Preset::Vlp16);
        let pose = Isometry3::translation(0.0, 0.0, 1.5);
        let half = ScanOptions {
            dropout: 0.5,
            ..ScanOptions::default()
        };
        let n = scan(&model, &ground(), &pose, &half).unwrap().len() as f64;
        assert!((n / (8.0 * 1800.0) - 0.5).abs() < 0.03, "kept {n}");
        let all = ScanOptions {
            dropout: 1.0,
            ..ScanOptions::default()
        };
        assert!(scan(&model, &ground(), &pose, &all).unwrap().is_empty());
        for bad in [
            ScanOptions {
                dropout: 1.5,
                ..ScanOptions::default()
            },
            ScanOptions {
                dropout: f64::NAN,
                ..ScanOptions::default()
            },
            ScanOptions {
                range_noise: Some(-0.1),
                ..ScanOptions::default()
            },
        ] {
            assert!(matches!(
                scan(&model, &ground(), &pose, &bad),
                Err(Error::InvalidInput(_))
            ));
        }
        let mut nan_pose = pose;
        nan_pose.translation.vector.x = f64::NAN;
        assert!(scan(&model, &ground(), &nan_pose, &ScanOptions::default()).is_err());
    }
}
