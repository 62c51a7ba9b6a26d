//! A building corner (two walls and the ground) scanned by two spinning LiDARs.

use nalgebra::{Isometry3, Point3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{
    pose, rectangle_shapes, reference_planes, scan_pair, uniform, Scene, PLACEMENT_ATTEMPTS,
};
use crate::error::{Error, Result};
use crate::geometry::Plane;
use crate::sim::shapes::{Cuboid, IntensityRange, Rectangle, Shape};
use crate::sim::BeamModel;

/// Length of each corner wall, metres.
pub const CORNER_WALL_LENGTH: f64 = 20.0;
/// Height of the corner walls, metres.
pub const CORNER_WALL_HEIGHT: f64 = 6.0;
/// Clutter boxes keep this horizontal distance from both sensors, metres.
pub const SENSOR_CLEARANCE: f64 = 2.0;
/// Largest roll and pitch of the corner scene's target sensor, degrees.
pub const CORNER_MAX_TILT_DEG: f64 = 10.0;

/// Options of [`corner_scene`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerOptions {
    /// Seed of the layout, the extrinsics and the scans.
    pub seed: u64,
    /// Number of clutter boxes (cars, bins) between the walls.
    pub clutter_boxes: usize,
    /// Extra walls (0, 1 or 2) facing the corner walls 16 m away, making an alley or a courtyard.
    pub extra_walls: usize,
    /// Range noise (metres, 1 sigma); `None` uses the model's default.
    pub range_noise: Option<f64>,
    /// Dropout probability of each return.
    pub dropout: f64,
    /// Angle between the two walls, degrees (90 for the usual right-angled corner, which makes a
    /// cube corner with the ground: ambiguous for the planar method without `up`).
    pub wall_angle_deg: f64,
    /// Largest roll and pitch of the target sensor, degrees.
    pub target_tilt_deg: f64,
    /// Heading of the target relative to the reference, degrees; `None` draws it at random.
    pub target_relative_yaw_deg: Option<f64>,
}

impl Default for CornerOptions {
    fn default() -> Self {
        CornerOptions {
            seed: 0,
            clutter_boxes: 4,
            extra_walls: 0,
            range_noise: None,
            dropout: 0.0,
            wall_angle_deg: 90.0,
            target_tilt_deg: CORNER_MAX_TILT_DEG,
            target_relative_yaw_deg: None,
        }
    }
}

/// Accepted range of [`CornerOptions::wall_angle_deg`], degrees.
pub const CORNER_WALL_ANGLE_RANGE: (f64, f64) = (30.0, 150.0);

/// Largest number of extra walls of the corner scene.
pub const MAX_EXTRA_WALLS: usize = 2;

/// A building corner scanned by two sensors of `model`.
///
/// World frame: the corner at the origin, wall 1 in the plane `y = 0` along +x, wall 2 along
/// `(cos a, sin a, 0)` for the wall angle `a` (along +y by default), both 20 m long and 6 m high,
/// ground `z = 0`. The reference sensor stands about 1.8 m high, 5.7–8.5 m from the corner on
/// the bisector (4–6 m from each wall at 90 deg), with a random heading and a tilt under 3 deg;
/// the target sensor within 1.5 m of it (0.5 m vertically) with a random or given relative
/// heading and a tilt under `target_tilt_deg`. The true planes are wall 1, wall 2, the ground,
/// then any extra walls.
pub fn corner_scene(model: &BeamModel, options: &CornerOptions) -> Result<Scene> {
    validate_corner(options)?;
    let angle = options.wall_angle_deg;
    let (sin_a, cos_a) = angle.to_radians().sin_cos();
    let wall2 = Vector3::new(cos_a, sin_a, 0.0);
    let bisector = Vector3::new(
        (angle * 0.5).to_radians().cos(),
        (angle * 0.5).to_radians().sin(),
        0.0,
    );
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let rectangles = corner_walls(&wall2, options.extra_walls)?;
    let sensors = place_sensors(&mut rng, &bisector, options);
    let mut shapes = rectangle_shapes(&rectangles, 2);
    add_clutter_boxes(&mut rng, &mut shapes, &sensors, options)?;
    let CornerSensors {
        world_from_reference,
        world_from_target,
        ..
    } = sensors;
    let scan_seeds = (rng.random::<u64>(), rng.random::<u64>());
    let (reference, target) = scan_pair(
        model,
        &shapes,
        [&world_from_reference, &world_from_target],
        scan_seeds,
        options.range_noise,
        options.dropout,
    )?;
    let planes: Vec<Plane> = rectangles.iter().map(|r| r.plane()).collect();
    Ok(Scene {
        reference,
        target,
        reference_from_target: world_from_reference.inverse() * world_from_target,
        world_from_reference,
        planes: reference_planes(&planes, &world_from_reference),
        poles: Vec::new(),
        shapes,
    })
}

/// The `InvalidInput` checks of [`corner_scene`].
fn validate_corner(options: &CornerOptions) -> Result<()> {
    crate::sim::check_dropout(options.dropout)?;
    if options.extra_walls > MAX_EXTRA_WALLS {
        return Err(Error::InvalidInput(format!(
            "extra_walls must be at most {MAX_EXTRA_WALLS}, got {}",
            options.extra_walls
        )));
    }
    let angle = options.wall_angle_deg;
    if !(angle >= CORNER_WALL_ANGLE_RANGE.0 && angle <= CORNER_WALL_ANGLE_RANGE.1) {
        return Err(Error::InvalidInput(format!(
            "wall_angle_deg must be in [{}, {}], got {angle}",
            CORNER_WALL_ANGLE_RANGE.0, CORNER_WALL_ANGLE_RANGE.1
        )));
    }
    let tilt_deg = options.target_tilt_deg;
    if !(0.0..=90.0).contains(&tilt_deg) {
        return Err(Error::InvalidInput(format!(
            "target_tilt_deg must be in [0, 90], got {tilt_deg}"
        )));
    }
    if options
        .target_relative_yaw_deg
        .is_some_and(|y| !y.is_finite())
    {
        return Err(Error::InvalidInput(
            "target_relative_yaw_deg must be finite".into(),
        ));
    }
    Ok(())
}

/// Wall 1, wall 2 (along `wall2`), the ground, then the extra walls (no random draws).
fn corner_walls(wall2: &Vector3<f64>, extra_walls: usize) -> Result<Vec<Rectangle>> {
    let (l, h) = (CORNER_WALL_LENGTH, CORNER_WALL_HEIGHT);
    let mut rectangles = vec![
        Rectangle::new(Point3::origin(), Vector3::x() * l, Vector3::z() * h)?,
        Rectangle::new(Point3::origin(), wall2 * l, Vector3::z() * h)?,
        Rectangle::new(
            Point3::new(-2.0, -2.0, 0.0),
            Vector3::x() * (l + 4.0),
            Vector3::y() * (l + 4.0),
        )?,
    ];
    let far = 16.0;
    if extra_walls >= 1 {
        rectangles.push(Rectangle::new(
            Point3::new(0.0, far, 0.0),
            Vector3::x() * l,
            Vector3::z() * h,
        )?);
    }
    if extra_walls >= 2 {
        rectangles.push(Rectangle::new(
            Point3::new(far, 0.0, 0.0),
            Vector3::y() * l,
            Vector3::z() * h,
        )?);
    }
    Ok(rectangles)
}

/// The two sensors' poses in the world frame and their positions (kept clear of clutter).
struct CornerSensors {
    world_from_reference: Isometry3<f64>,
    world_from_target: Isometry3<f64>,
    reference_position: Vector3<f64>,
    target_position: Vector3<f64>,
}

/// Draws the reference pose on the bisector, then the target pose near it.
fn place_sensors(
    rng: &mut ChaCha8Rng,
    bisector: &Vector3<f64>,
    options: &CornerOptions,
) -> CornerSensors {
    let small_tilt = 3f64.to_radians();
    let along = uniform(rng, 4.0, 6.0) * std::f64::consts::SQRT_2;
    let across = uniform(rng, -1.0, 1.0);
    let reference_position = bisector * along
        + Vector3::new(-bisector.y, bisector.x, 0.0) * across
        + Vector3::z() * uniform(rng, 1.6, 2.0);
    let reference_yaw = uniform(rng, 0.0, std::f64::consts::TAU);
    let world_from_reference = pose(
        reference_position,
        uniform(rng, -small_tilt, small_tilt),
        uniform(rng, -small_tilt, small_tilt),
        reference_yaw,
    );
    let tilt = options.target_tilt_deg.to_radians();
    let target_position = reference_position
        + Vector3::new(
            uniform(rng, -1.5, 1.5),
            uniform(rng, -1.5, 1.5),
            uniform(rng, -0.5, 0.5),
        );
    let random_yaw = uniform(rng, 0.0, std::f64::consts::TAU);
    let world_from_target = pose(
        target_position,
        uniform(rng, -tilt, tilt),
        uniform(rng, -tilt, tilt),
        options
            .target_relative_yaw_deg
            .map_or(random_yaw, |y| reference_yaw + y.to_radians()),
    );
    CornerSensors {
        world_from_reference,
        world_from_target,
        reference_position,
        target_position,
    }
}

/// Adds up to `clutter_boxes` boxes inside the wedge, clear of the walls and both sensors.
fn add_clutter_boxes(
    rng: &mut ChaCha8Rng,
    shapes: &mut Vec<Shape>,
    sensors: &CornerSensors,
    options: &CornerOptions,
) -> Result<()> {
    let angle = options.wall_angle_deg;
    let (reference_position, target_position) =
        (sensors.reference_position, sensors.target_position);
    for _ in 0..options.clutter_boxes {
        for _ in 0..PLACEMENT_ATTEMPTS {
            let size = Vector3::new(
                uniform(rng, 0.5, 2.5),
                uniform(rng, 0.5, 2.5),
                uniform(rng, 0.5, 2.0),
            );
            // Inside the wedge between the walls, clear of both.
            let radius = uniform(rng, 2.5, 15.0);
            let theta = uniform(rng, 0.15, 0.85) * angle.to_radians();
            let center = Vector3::new(radius * theta.cos(), radius * theta.sin(), size.z * 0.5);
            let yaw = uniform(rng, 0.0, std::f64::consts::PI);
            let clear = [reference_position, target_position]
                .iter()
                .all(|s| (s.xy() - center.xy()).norm() > SENSOR_CLEARANCE + 0.5 * size.xy().norm());
            if clear {
                let b = Cuboid::new(pose(center, 0.0, 0.0, yaw), size)?;
                shapes.push(Shape::cuboid(b, IntensityRange::CLUTTER));
                break;
            }
        }
    }
    Ok(())
}
