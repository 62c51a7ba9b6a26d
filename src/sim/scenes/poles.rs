//! Two non-parallel poles wrapped in retro-reflective tape (Xue et al., 2019, Sec. IV-A).

use nalgebra::{Point3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{pose, reference_planes, scan_pair, uniform, Pole, Scene, PLACEMENT_ATTEMPTS};
use crate::error::{Error, Result};
use crate::geometry::Plane;
use crate::sim::shapes::{Cylinder, IntensityRange, Rectangle, Shape};
use crate::sim::BeamModel;

/// Range noise of the pole scene, metres (Xue et al., 2019, Sec. IV-A).
pub const POLES_RANGE_NOISE: f64 = 0.006;
/// Smallest z-component of a pole's axis (Xue et al., 2019).
pub const POLE_MIN_AXIS_Z: f64 = 0.9;
/// Smallest and largest distance between the poles' base centres, metres (Xue et al., 2019).
pub const POLE_SPACING_RANGE: (f64, f64) = (1.5, 4.0);
/// Smallest angle between the two pole axes, degrees: nearly parallel poles do not determine the
/// rotation about them, so they are redrawn.
pub const POLE_MIN_ANGLE_DEG: f64 = 3.0;
/// Pole length, metres.
pub const POLE_LENGTH: f64 = 3.0;
/// The taped band of each pole, metres from the base.
pub const POLE_BAND: (f64, f64) = (0.5, 2.5);
/// Largest roll and pitch of the pole scene's sensors by default, degrees.
pub const POLES_MAX_TILT_DEG: f64 = 15.0;
/// Largest pole radius accepted, metres.
pub const MAX_POLE_RADIUS: f64 = 1.0;

/// Options of [`poles_scene`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolesOptions {
    /// Seed of the layout, the extrinsics and the scans.
    pub seed: u64,
    /// Pole radius, metres.
    pub radius: f64,
    /// Horizontal distance from the reference sensor to the middle of the poles, metres.
    pub distance: f64,
    /// Add a retro-reflective road sign on a post as a distractor.
    pub distractor: bool,
    /// Range noise (metres, 1 sigma); `None` uses [`POLES_RANGE_NOISE`].
    pub range_noise: Option<f64>,
    /// Dropout probability of each return.
    pub dropout: f64,
    /// Largest roll and pitch of each sensor, degrees (at most 90).
    pub max_tilt_deg: f64,
    /// Mount the target sensor upside down (an extra 180 deg roll after the random pose).
    pub target_upside_down: bool,
}

impl Default for PolesOptions {
    fn default() -> Self {
        PolesOptions {
            seed: 0,
            radius: 0.1,
            distance: 5.0,
            distractor: false,
            range_noise: None,
            dropout: 0.0,
            max_tilt_deg: POLES_MAX_TILT_DEG,
            target_upside_down: false,
        }
    }
}

fn random_pole_axis(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    // z uniform in (0.9, 1]: the axis stays within ~26 deg of vertical.
    let z = uniform(rng, POLE_MIN_AXIS_Z + 1e-3, 1.0);
    let heading = uniform(rng, 0.0, std::f64::consts::TAU);
    let s = (1.0 - z * z).max(0.0).sqrt();
    Vector3::new(s * heading.cos(), s * heading.sin(), z)
}

/// Two taped poles, the ground and optionally a road sign, scanned by two sensors of `model`.
///
/// World frame: ground `z = 0`; the poles stand on it around `(distance, 0, 0)`, spaced 1.5–4 m
/// apart along y, axes drawn with z-component > 0.9 and at least 3 deg apart, 3 m long with tape
/// from 0.5 m to 2.5 m. The reference sensor is near `(0, -1, 1.2)`, the target near `(0, 1, 1.2)`,
/// each with a random heading and a tilt under `max_tilt_deg` (15 deg by default; the target
/// optionally upside down). The true planes are the ground alone; the
/// sign (when present) sits beside the poles, facing the sensors, with tape-bright intensity.
pub fn poles_scene(model: &BeamModel, options: &PolesOptions) -> Result<Scene> {
    validate_poles(options)?;
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let spacing = uniform(&mut rng, POLE_SPACING_RANGE.0, POLE_SPACING_RANGE.1);
    let a1 = random_pole_axis(&mut rng);
    let mut a2 = random_pole_axis(&mut rng);
    let min_angle = POLE_MIN_ANGLE_DEG.to_radians();
    for _ in 0..PLACEMENT_ATTEMPTS {
        if a1.angle(&a2) >= min_angle {
            break;
        }
        a2 = random_pole_axis(&mut rng);
    }
    if a1.angle(&a2) < min_angle {
        return Err(Error::Numerical(
            "could not draw two non-parallel pole axes".into(),
        ));
    }
    let d = options.distance;
    let bases = [
        Point3::new(d + uniform(&mut rng, -0.3, 0.3), -0.5 * spacing, 0.0),
        Point3::new(d + uniform(&mut rng, -0.3, 0.3), 0.5 * spacing, 0.0),
    ];
    let mut shapes = vec![Shape::rectangle(
        Rectangle::centered(
            Point3::new(d, 0.0, 0.0),
            Vector3::x(),
            Vector3::y(),
            4.0 * d + 20.0,
            4.0 * d + 20.0,
        )?,
        IntensityRange::GROUND,
    )];
    let mut cylinders = Vec::new();
    for (base, axis) in bases.iter().zip([a1, a2]) {
        let c = Cylinder::new(*base, axis, POLE_LENGTH, options.radius)?.with_band(
            POLE_BAND.0,
            POLE_BAND.1,
            IntensityRange::RETROREFLECTIVE,
        )?;
        cylinders.push(c);
        shapes.push(Shape::cylinder(c, IntensityRange::POLE));
    }
    let tilt = options.max_tilt_deg.to_radians();
    let mut sensor_pose = |y: f64| {
        let t = Vector3::new(
            uniform(&mut rng, -0.5, 0.5),
            y + uniform(&mut rng, -0.5, 0.5),
            uniform(&mut rng, 1.0, 1.5),
        );
        pose(
            t,
            uniform(&mut rng, -tilt, tilt),
            uniform(&mut rng, -tilt, tilt),
            uniform(&mut rng, 0.0, std::f64::consts::TAU),
        )
    };
    let world_from_reference = sensor_pose(-1.0);
    let mut world_from_target = sensor_pose(1.0);
    if options.target_upside_down {
        world_from_target *= UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0);
    }
    if options.distractor {
        let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
        let y = side * (0.5 * spacing + uniform(&mut rng, 1.5, 2.5));
        let x = d + uniform(&mut rng, -0.5, 1.0);
        let post = Cylinder::new(Point3::new(x + 0.05, y, 0.0), Vector3::z(), 2.0, 0.03)?;
        shapes.push(Shape::cylinder(post, IntensityRange::POLE));
        let sign =
            Rectangle::centered(Point3::new(x, y, 2.2), Vector3::y(), Vector3::z(), 0.6, 0.6)?;
        shapes.push(Shape::rectangle(sign, IntensityRange::RETROREFLECTIVE));
    }
    let noise = Some(options.range_noise.unwrap_or(POLES_RANGE_NOISE));
    let scan_seeds = (rng.random::<u64>(), rng.random::<u64>());
    let (reference, target) = scan_pair(
        model,
        &shapes,
        [&world_from_reference, &world_from_target],
        scan_seeds,
        noise,
        options.dropout,
    )?;
    let reference_from_world = world_from_reference.inverse();
    let poles = cylinders
        .iter()
        .map(|c| Pole {
            axis: c.axis().transformed(&reference_from_world),
            radius: c.radius(),
            length: c.length(),
        })
        .collect();
    let ground = Plane::new(Vector3::z(), 0.0)?;
    Ok(Scene {
        reference,
        target,
        reference_from_target: reference_from_world * world_from_target,
        world_from_reference,
        planes: reference_planes(&[ground], &world_from_reference),
        poles,
        shapes,
    })
}

/// The `InvalidInput` checks of [`poles_scene`].
fn validate_poles(options: &PolesOptions) -> Result<()> {
    crate::sim::check_dropout(options.dropout)?;
    if !(options.radius.is_finite() && options.radius > 0.0 && options.radius <= MAX_POLE_RADIUS) {
        return Err(Error::InvalidInput(format!(
            "pole radius must be in (0, {MAX_POLE_RADIUS}] metres, got {}",
            options.radius
        )));
    }
    if !(options.distance.is_finite() && options.distance >= 1.0 && options.distance <= 50.0) {
        return Err(Error::InvalidInput(format!(
            "pole distance must be in [1, 50] metres, got {}",
            options.distance
        )));
    }
    if !(options.max_tilt_deg.is_finite() && (0.0..=90.0).contains(&options.max_tilt_deg)) {
        return Err(Error::InvalidInput(format!(
            "max_tilt_deg must be in [0, 90], got {}",
            options.max_tilt_deg
        )));
    }
    Ok(())
}
