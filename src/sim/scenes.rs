//! Scenes with ground truth: two sensors, their points in their own frames, the true
//! `reference_from_target` and the true geometry in the reference frame.
//!
//! * [`paper_scene`]: the synthetic protocol of the planar-surfaces paper (seed 000, Sec. IV-B):
//!   three 10 m planes meeting at a corner, the walls `alpha` degrees apart, 2500 points per plane
//!   with 0.1 m Gaussian noise and 2000 clutter points with a 5 m spread, per sensor. Points are
//!   sampled, not ray-cast; intensity 0, ring 0.
//! * [`corner_scene`]: a building corner (two 20 m x 6 m walls and the ground) scanned by two
//!   spinning LiDARs, with optional clutter boxes and extra walls.
//! * [`poles_scene`]: two non-parallel poles wrapped in retro-reflective tape (Xue et al., 2019, Sec. IV-A:
//!   axis z-component > 0.9, 1.5–4 m apart, 0.006 m range noise), a ground plane and optionally a
//!   bright road sign as a distractor.
//! * [`street_scene`]: a street with facades, kerbs, parked cars, trees and poles, scanned by a
//!   roof HDL-64E and a 45-degree-tilted wide-angle side unit (the real road rigs' layout).
//! * [`corridor_scene`]: a floor and two parallel walls, which leave the translation along the
//!   corridor unobservable.
//!
//! All layout draws come from one `ChaCha8Rng` seeded with the scene's seed, so a scene is a pure
//! function of its options.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::shapes::{Cuboid, Cylinder, IntensityRange, Rectangle, Shape};
use super::{scan, BeamModel, Scan, ScanOptions, ScanPoint};
use crate::error::{Error, Result};
use crate::geometry::{Line, Plane};

/// A pole of a scene: its axis (through the base centre, pointing up), radius and length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pole {
    /// The axis, through the base centre, directed from the base to the top.
    pub axis: Line,
    /// Radius, metres.
    pub radius: f64,
    /// Length along the axis, metres.
    pub length: f64,
}

/// Two sensors' points with ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The reference sensor's points, in its frame.
    pub reference: Scan,
    /// The target sensor's points, in its frame.
    pub target: Scan,
    /// The true extrinsics: `p_ref = reference_from_target * p_tgt`.
    pub reference_from_target: Isometry3<f64>,
    /// The reference sensor's pose in the scene's world frame.
    pub world_from_reference: Isometry3<f64>,
    /// The true planes (walls, ground) in the reference frame, normals toward the reference sensor.
    pub planes: Vec<Plane>,
    /// The true poles in the reference frame.
    pub poles: Vec<Pole>,
    /// The shapes in the world frame (empty for the sampled paper protocol).
    pub shapes: Vec<Shape>,
}

impl Scene {
    /// The target sensor's pose in the world frame.
    pub fn world_from_target(&self) -> Isometry3<f64> {
        self.world_from_reference * self.reference_from_target
    }
}

fn pose(translation: Vector3<f64>, roll: f64, pitch: f64, yaw: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

// ---------------------------------------------------------------------------------------------
// The paper protocol.

/// Points per plane in the paper protocol (7500 planar points over three planes).
pub const PAPER_POINTS_PER_PLANE: usize = 2500;
/// Clutter points in the paper protocol.
pub const PAPER_CLUTTER_POINTS: usize = 2000;
/// Gaussian noise of the planar points, metres (1 sigma, each axis).
pub const PAPER_PLANE_NOISE: f64 = 0.1;
/// Spread of the clutter points, metres (1 sigma, each axis).
pub const PAPER_CLUTTER_SPREAD: f64 = 5.0;
/// Side of each planar patch, metres.
pub const PAPER_PATCH_SIZE: f64 = 10.0;
/// Smallest and largest angle between the walls accepted, degrees.
pub const PAPER_ALPHA_RANGE_DEG: (f64, f64) = (20.0, 160.0);
/// Largest roll and pitch of a random configuration, degrees (the paper's (0, 20) deg, either sign).
pub const PAPER_MAX_TILT_DEG: f64 = 20.0;
/// Largest translation component of a random configuration, metres.
pub const PAPER_MAX_TRANSLATION: f64 = 1.5;

/// The ground truth of the paper's synthetic experiments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PaperConfiguration {
    /// Table II configuration 1: rotation (2.7337, -0.3946, -0.1809) rad, translation
    /// (0.8766, 0.4672, 1.0474) m.
    One,
    /// Table II configuration 2: rotation (-0.5174, 0.1277, 0.1222) rad, translation
    /// (1.3785, -1.3929, 1.3020) m.
    Two,
    /// Drawn from `seed` as Jiao et al. (2019) describe: roll and pitch within +-20 deg, yaw in
    /// [0, 360) deg, each translation component within +-1.5 m.
    Random,
}

/// Options of [`paper_scene`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperOptions {
    /// Angle between the two walls about the vertical, degrees (the paper uses 60..=120).
    pub alpha_deg: f64,
    /// Which ground truth.
    pub configuration: PaperConfiguration,
    /// Seed of every random draw.
    pub seed: u64,
}

impl Default for PaperOptions {
    fn default() -> Self {
        PaperOptions {
            alpha_deg: 90.0,
            configuration: PaperConfiguration::One,
            seed: 0,
        }
    }
}

/// The paper's `reference_from_target` for a configuration.
///
/// The paper prints each rotation as three angles "on x-, y- and z-axis" but the values only fit
/// its stated ranges when read as yaw, pitch, roll (Z-Y-X: `R = Rz(a0) Ry(a1) Rx(a2)`), so that is
/// how they are read here.
pub fn paper_configuration(
    configuration: PaperConfiguration,
    rng: &mut ChaCha8Rng,
) -> Isometry3<f64> {
    match configuration {
        PaperConfiguration::One => pose(
            Vector3::new(0.8766, 0.4672, 1.0474),
            -0.1809,
            -0.3946,
            2.7337,
        ),
        PaperConfiguration::Two => pose(
            Vector3::new(1.3785, -1.3929, 1.3020),
            0.1222,
            0.1277,
            -0.5174,
        ),
        PaperConfiguration::Random => {
            let tilt = PAPER_MAX_TILT_DEG.to_radians();
            let roll = uniform(rng, -tilt, tilt);
            let pitch = uniform(rng, -tilt, tilt);
            let yaw = uniform(rng, 0.0, std::f64::consts::TAU);
            let m = PAPER_MAX_TRANSLATION;
            let t = Vector3::new(
                uniform(rng, -m, m),
                uniform(rng, -m, m),
                uniform(rng, -m, m),
            );
            pose(t, roll, pitch, yaw)
        }
    }
}

fn normal(sigma: f64) -> Result<Normal<f64>> {
    Normal::new(0.0, sigma).map_err(|e| Error::Numerical(format!("normal distribution: {e}")))
}

fn paper_points(
    patches: &[(Point3<f64>, Vector3<f64>, Vector3<f64>); 3],
    clutter_center: &Point3<f64>,
    sensor_from_world: &Isometry3<f64>,
    rng: &mut ChaCha8Rng,
) -> Result<Scan> {
    let plane_noise = normal(PAPER_PLANE_NOISE)?;
    let clutter = normal(PAPER_CLUTTER_SPREAD)?;
    let mut points = Vec::with_capacity(3 * PAPER_POINTS_PER_PLANE + PAPER_CLUTTER_POINTS);
    for (index, (corner, eu, ev)) in patches.iter().enumerate() {
        for _ in 0..PAPER_POINTS_PER_PLANE {
            let (s, t): (f64, f64) = (rng.random(), rng.random());
            let n = Vector3::from_fn(|_, _| plane_noise.sample(rng));
            let p = corner + eu * s + ev * t + n;
            points.push(ScanPoint {
                position: sensor_from_world * p,
                intensity: 0.0,
                ring: 0,
                shape: Some(index),
            });
        }
    }
    for _ in 0..PAPER_CLUTTER_POINTS {
        let p = clutter_center + Vector3::from_fn(|_, _| clutter.sample(rng));
        points.push(ScanPoint {
            position: sensor_from_world * p,
            intensity: 0.0,
            ring: 0,
            shape: None,
        });
    }
    Ok(Scan { points })
}

/// The synthetic protocol of the planar-surfaces paper (Sec. IV-B).
///
/// World frame: the corner at the origin, ground `z = 0`, wall 1 the half-plane along +x, wall 2
/// along `(cos alpha, sin alpha, 0)`. Each sensor gets its own 2500 noisy points per plane
/// (uniform on a 10 m x 10 m patch, the ground patch being the parallelogram between the walls) and
/// 2000 clutter points around the middle of the patches. The reference sensor stands 2 m high
/// inside the wedge, 5 m from the corner, with a random heading.
pub fn paper_scene(options: &PaperOptions) -> Result<Scene> {
    let (lo, hi) = PAPER_ALPHA_RANGE_DEG;
    if !(lo..=hi).contains(&options.alpha_deg) {
        return Err(Error::InvalidInput(format!(
            "alpha must be in [{lo}, {hi}] degrees, got {}",
            options.alpha_deg
        )));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let alpha = options.alpha_deg.to_radians();
    let e1 = Vector3::x();
    let e2 = Vector3::new(alpha.cos(), alpha.sin(), 0.0);
    let up = Vector3::z();
    let size = PAPER_PATCH_SIZE;
    let o = Point3::origin();
    let patches = [
        (o, e1 * size, up * size),
        (o, e2 * size, up * size),
        (o, e1 * size, e2 * size),
    ];
    let bisector = (e1 + e2).normalize();
    let clutter_center = Point3::from((e1 + e2) * (size / 3.0) + up * (size / 3.0));
    let yaw = uniform(&mut rng, 0.0, std::f64::consts::TAU);
    let world_from_reference = pose(bisector * 5.0 + up * 2.0, 0.0, 0.0, yaw);
    let reference_from_target = paper_configuration(options.configuration, &mut rng);
    let world_from_target = world_from_reference * reference_from_target;
    let reference = paper_points(
        &patches,
        &clutter_center,
        &world_from_reference.inverse(),
        &mut rng,
    )?;
    let target = paper_points(
        &patches,
        &clutter_center,
        &world_from_target.inverse(),
        &mut rng,
    )?;
    let planes = [e1.cross(&up), e2.cross(&up), up]
        .iter()
        .map(|n| Plane::new(*n, 0.0))
        .collect::<Result<Vec<_>>>()?;
    Ok(Scene {
        reference,
        target,
        reference_from_target,
        world_from_reference,
        planes: reference_planes(&planes, &world_from_reference),
        poles: Vec::new(),
        shapes: Vec::new(),
    })
}

fn reference_planes(world_planes: &[Plane], world_from_reference: &Isometry3<f64>) -> Vec<Plane> {
    let reference_from_world = world_from_reference.inverse();
    world_planes
        .iter()
        .map(|p| {
            p.transformed(&reference_from_world)
                .oriented_toward(&Point3::origin())
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// The building corner.

/// Length of each corner wall, metres.
pub const CORNER_WALL_LENGTH: f64 = 20.0;
/// Height of the corner walls, metres.
pub const CORNER_WALL_HEIGHT: f64 = 6.0;
/// Clutter boxes keep this horizontal distance from both sensors, metres.
pub const SENSOR_CLEARANCE: f64 = 2.0;
/// Largest roll and pitch of the corner scene's target sensor, degrees.
pub const CORNER_MAX_TILT_DEG: f64 = 10.0;
/// Attempts at placing each clutter box before giving up on it.
const PLACEMENT_ATTEMPTS: usize = 50;

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

/// Scans `shapes` from the reference and the target pose with the same model, noise and dropout
/// and independent seeds.
fn scan_pair(
    model: &BeamModel,
    shapes: &[Shape],
    world_from: [&Isometry3<f64>; 2],
    seeds: (u64, u64),
    range_noise: Option<f64>,
    dropout: f64,
) -> Result<(Scan, Scan)> {
    let options = |seed| ScanOptions {
        seed,
        range_noise,
        dropout,
    };
    Ok((
        scan(model, shapes, world_from[0], &options(seeds.0))?,
        scan(model, shapes, world_from[1], &options(seeds.1))?,
    ))
}

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
    super::check_dropout(options.dropout)?;
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
    let (sin_a, cos_a) = angle.to_radians().sin_cos();
    let wall2 = Vector3::new(cos_a, sin_a, 0.0);
    let bisector = Vector3::new(
        (angle * 0.5).to_radians().cos(),
        (angle * 0.5).to_radians().sin(),
        0.0,
    );
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
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
    if options.extra_walls >= 1 {
        rectangles.push(Rectangle::new(
            Point3::new(0.0, far, 0.0),
            Vector3::x() * l,
            Vector3::z() * h,
        )?);
    }
    if options.extra_walls >= 2 {
        rectangles.push(Rectangle::new(
            Point3::new(far, 0.0, 0.0),
            Vector3::y() * l,
            Vector3::z() * h,
        )?);
    }
    let small_tilt = 3f64.to_radians();
    let along = uniform(&mut rng, 4.0, 6.0) * std::f64::consts::SQRT_2;
    let across = uniform(&mut rng, -1.0, 1.0);
    let reference_position = bisector * along
        + Vector3::new(-bisector.y, bisector.x, 0.0) * across
        + Vector3::z() * uniform(&mut rng, 1.6, 2.0);
    let reference_yaw = uniform(&mut rng, 0.0, std::f64::consts::TAU);
    let world_from_reference = pose(
        reference_position,
        uniform(&mut rng, -small_tilt, small_tilt),
        uniform(&mut rng, -small_tilt, small_tilt),
        reference_yaw,
    );
    let tilt = tilt_deg.to_radians();
    let target_position = reference_position
        + Vector3::new(
            uniform(&mut rng, -1.5, 1.5),
            uniform(&mut rng, -1.5, 1.5),
            uniform(&mut rng, -0.5, 0.5),
        );
    let random_yaw = uniform(&mut rng, 0.0, std::f64::consts::TAU);
    let world_from_target = pose(
        target_position,
        uniform(&mut rng, -tilt, tilt),
        uniform(&mut rng, -tilt, tilt),
        options
            .target_relative_yaw_deg
            .map_or(random_yaw, |y| reference_yaw + y.to_radians()),
    );
    let mut shapes: Vec<Shape> = rectangles
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let intensity = if i == 2 {
                IntensityRange::GROUND
            } else {
                IntensityRange::WALL
            };
            Shape::rectangle(*r, intensity)
        })
        .collect();
    for _ in 0..options.clutter_boxes {
        for _ in 0..PLACEMENT_ATTEMPTS {
            let size = Vector3::new(
                uniform(&mut rng, 0.5, 2.5),
                uniform(&mut rng, 0.5, 2.5),
                uniform(&mut rng, 0.5, 2.0),
            );
            // Inside the wedge between the walls, clear of both.
            let radius = uniform(&mut rng, 2.5, 15.0);
            let theta = uniform(&mut rng, 0.15, 0.85) * angle.to_radians();
            let center = Vector3::new(radius * theta.cos(), radius * theta.sin(), size.z * 0.5);
            let yaw = uniform(&mut rng, 0.0, std::f64::consts::PI);
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

// ---------------------------------------------------------------------------------------------
// Two taped poles.

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
/// Pole paint outside the band.
pub const POLE_PAINT: IntensityRange = IntensityRange {
    min: 30.0,
    max: 80.0,
};

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
    super::check_dropout(options.dropout)?;
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
        shapes.push(Shape::cylinder(c, POLE_PAINT));
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
        shapes.push(Shape::cylinder(post, POLE_PAINT));
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

// ---------------------------------------------------------------------------------------------
// A street (targetless plane matching) and a corridor (its unobservable case).

/// Half width of the simulated road between the kerbs, metres.
pub const STREET_HALF_WIDTH: f64 = 4.0;
/// Distance of the facades from the road's centre line, metres.
pub const STREET_FACADE_DISTANCE: f64 = 8.0;
/// Height of the kerbs, metres.
pub const KERB_HEIGHT: f64 = 0.15;
/// Length of the simulated street (and corridor), metres.
pub const STREET_LENGTH: f64 = 120.0;

/// A PandarQT-like short-range unit: 64 beams from -52.1 to +52.1 degrees, 600 columns, 0.3-60 m,
/// 2 cm range noise (the side units of the real road rigs).
pub fn wide_angle_model() -> Result<BeamModel> {
    let elevations: Vec<f64> = (0..64).map(|i| -52.1 + 104.2 * i as f64 / 63.0).collect();
    BeamModel::custom("qt64", &elevations, 600, 0.3, 60.0, 0.02)
}

/// Which side of the vehicle the street scene's target unit is mounted on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Side {
    /// Left (+y of the vehicle), looking left and down.
    #[default]
    Left,
    /// Right (-y), looking right and down.
    Right,
}

/// Options of [`street_scene`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreetOptions {
    /// Seed of the layout, the extrinsics and the scans.
    pub seed: u64,
    /// Side of the target unit.
    pub side: Side,
    /// Downward tilt of the target unit, degrees (the real rigs: about 45).
    pub target_tilt_deg: f64,
    /// Parked cars, trees and poles along the kerbs (what pins the translation along the street).
    pub clutter: bool,
    /// A wall across the street 30 m ahead (a T junction).
    pub cross_wall: bool,
    /// Range noise (metres, 1 sigma) of both sensors; `None` uses each model's default.
    pub range_noise: Option<f64>,
    /// Extra position of the target unit along the vehicle (metres, forward positive; e.g. -3
    /// for a unit at the back of a car), on top of the small random one. In `[-5, 5]`.
    pub target_offset: f64,
}

impl Default for StreetOptions {
    fn default() -> Self {
        StreetOptions {
            seed: 0,
            side: Side::Left,
            target_tilt_deg: 45.0,
            clutter: true,
            cross_wall: false,
            range_noise: None,
            target_offset: 0.0,
        }
    }
}

/// A street scanned by a roof LiDAR (HDL-64E, the reference, about 2 m up, nearly level) and a
/// tilted wide-angle side unit ([`wide_angle_model`], the target, on the left or right of the
/// roof, tilted `target_tilt_deg` down and outward, with a few degrees of random mounting error).
///
/// World frame: the street runs along x, the road (z = 0) is `2 * STREET_HALF_WIDTH` wide with
/// kerbs and raised pavements up to the facades at `y = +-STREET_FACADE_DISTANCE`; the facades are
/// buildings of random widths, heights and small setbacks (up to 0.4 m) with gaps between them.
/// With `clutter`, parked cars (boxes), tree trunks and poles (cylinders) line the kerbs. The
/// true planes are the road, then the facade segments.
pub fn street_scene(options: &StreetOptions) -> Result<Scene> {
    if !(options.target_tilt_deg.is_finite() && (0.0..=80.0).contains(&options.target_tilt_deg)) {
        return Err(Error::InvalidInput(format!(
            "target_tilt_deg must be in [0, 80], got {}",
            options.target_tilt_deg
        )));
    }
    if !(options.target_offset.is_finite() && options.target_offset.abs() <= 5.0) {
        return Err(Error::InvalidInput(format!(
            "target_offset must be in [-5, 5] m, got {}",
            options.target_offset
        )));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let half = 0.5 * STREET_LENGTH;
    let mut rectangles = vec![Rectangle::new(
        Point3::new(-half, -STREET_FACADE_DISTANCE - 1.0, 0.0),
        Vector3::x() * STREET_LENGTH,
        Vector3::y() * (2.0 * STREET_FACADE_DISTANCE + 2.0),
    )?];
    let mut boxes = Vec::new();
    // Pavements: raised slabs from the kerb to the facades.
    for sign in [-1.0, 1.0] {
        let width = STREET_FACADE_DISTANCE - STREET_HALF_WIDTH;
        let center = Vector3::new(
            0.0,
            sign * (STREET_HALF_WIDTH + 0.5 * width),
            0.5 * KERB_HEIGHT,
        );
        boxes.push(Cuboid::new(
            pose(center, 0.0, 0.0, 0.0),
            Vector3::new(STREET_LENGTH, width, KERB_HEIGHT),
        )?);
    }
    // Facades: buildings with gaps and setbacks.
    for sign in [-1.0, 1.0] {
        let mut x = -half;
        while x < half {
            let width = uniform(&mut rng, 8.0, 25.0).min(half - x);
            let height = uniform(&mut rng, 6.0, 15.0);
            let y = sign * (STREET_FACADE_DISTANCE + uniform(&mut rng, 0.0, 0.4));
            rectangles.push(Rectangle::new(
                Point3::new(x, y, 0.0),
                Vector3::x() * width,
                Vector3::z() * height,
            )?);
            x += width + uniform(&mut rng, 1.0, 4.0);
        }
    }
    if options.cross_wall {
        rectangles.push(Rectangle::new(
            Point3::new(30.0, -STREET_FACADE_DISTANCE, 0.0),
            Vector3::y() * (2.0 * STREET_FACADE_DISTANCE),
            Vector3::z() * 8.0,
        )?);
    }
    let mut cylinders = Vec::new();
    if options.clutter {
        for sign in [-1.0, 1.0] {
            let mut x = -half + uniform(&mut rng, 0.0, 8.0);
            while x < half - 5.0 {
                let kind: f64 = rng.random();
                let y = sign * (STREET_HALF_WIDTH + 0.6);
                if kind < 0.4 {
                    let size = Vector3::new(
                        uniform(&mut rng, 3.8, 4.8),
                        uniform(&mut rng, 1.7, 1.9),
                        uniform(&mut rng, 1.4, 1.7),
                    );
                    let center = Vector3::new(x, sign * (STREET_HALF_WIDTH - 1.1), 0.5 * size.z);
                    let yaw = uniform(&mut rng, -0.05, 0.05);
                    boxes.push(Cuboid::new(pose(center, 0.0, 0.0, yaw), size)?);
                    x += size.x + uniform(&mut rng, 1.0, 8.0);
                } else if kind < 0.8 {
                    let radius = uniform(&mut rng, 0.12, 0.3);
                    let trunk = Cylinder::new(
                        Point3::new(x, y, 0.0),
                        Vector3::z(),
                        uniform(&mut rng, 2.5, 4.0),
                        radius,
                    )?;
                    cylinders.push(trunk);
                    x += uniform(&mut rng, 4.0, 10.0);
                } else {
                    let post = Cylinder::new(
                        Point3::new(x, y, 0.0),
                        Vector3::z(),
                        uniform(&mut rng, 3.0, 6.0),
                        uniform(&mut rng, 0.05, 0.1),
                    )?;
                    cylinders.push(post);
                    x += uniform(&mut rng, 4.0, 10.0);
                }
            }
        }
    }
    // The vehicle drives along +x in the right lane; the roof unit is the reference.
    let small = 1f64.to_radians();
    let vehicle_y = -0.5 * STREET_HALF_WIDTH + uniform(&mut rng, -0.5, 0.5);
    let world_from_reference = pose(
        Vector3::new(uniform(&mut rng, -2.0, 2.0), vehicle_y, 2.0),
        uniform(&mut rng, -small, small),
        uniform(&mut rng, -small, small),
        uniform(&mut rng, -2.0 * small, 2.0 * small),
    );
    let (side_sign, yaw) = match options.side {
        Side::Left => (1.0, std::f64::consts::FRAC_PI_2),
        Side::Right => (-1.0, -std::f64::consts::FRAC_PI_2),
    };
    let mount_error = 3f64.to_radians();
    let reference_from_target = pose(
        Vector3::new(
            uniform(&mut rng, -0.2, 0.2) + options.target_offset,
            side_sign * uniform(&mut rng, 0.45, 0.65),
            -uniform(&mut rng, 0.3, 0.5),
        ),
        uniform(&mut rng, -mount_error, mount_error),
        options.target_tilt_deg.to_radians() + uniform(&mut rng, -mount_error, mount_error),
        yaw + uniform(&mut rng, -mount_error, mount_error),
    );
    let world_from_target = world_from_reference * reference_from_target;
    let mut shapes: Vec<Shape> = rectangles
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let intensity = if i == 0 {
                IntensityRange::GROUND
            } else {
                IntensityRange::WALL
            };
            Shape::rectangle(*r, intensity)
        })
        .collect();
    shapes.extend(
        boxes
            .iter()
            .map(|b| Shape::cuboid(*b, IntensityRange::CLUTTER)),
    );
    shapes.extend(cylinders.iter().map(|c| Shape::cylinder(*c, POLE_PAINT)));
    let scan_seeds = (rng.random::<u64>(), rng.random::<u64>());
    let reference = scan(
        &BeamModel::preset(super::Preset::Hdl64e),
        &shapes,
        &world_from_reference,
        &ScanOptions {
            seed: scan_seeds.0,
            range_noise: options.range_noise,
            dropout: 0.0,
        },
    )?;
    let target = scan(
        &wide_angle_model()?,
        &shapes,
        &world_from_target,
        &ScanOptions {
            seed: scan_seeds.1,
            range_noise: options.range_noise,
            dropout: 0.0,
        },
    )?;
    let planes: Vec<Plane> = rectangles.iter().map(|r| r.plane()).collect();
    let reference_from_world = world_from_reference.inverse();
    Ok(Scene {
        reference,
        target,
        reference_from_target,
        world_from_reference,
        planes: reference_planes(&planes, &world_from_reference),
        poles: cylinders
            .iter()
            .map(|c| Pole {
                axis: c.axis().transformed(&reference_from_world),
                radius: c.radius(),
                length: c.length(),
            })
            .collect(),
        shapes,
    })
}

/// A corridor: a floor and two parallel walls 3 m apart along x, longer than the sensors'
/// range, scanned by two VLP-16s 1 m apart (the target turned and tilted). Nothing constrains the
/// translation along the corridor: the case the targetless method must refuse.
pub fn corridor_scene(seed: u64) -> Result<Scene> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let length = 2.0 * STREET_LENGTH;
    let half = 0.5 * length;
    let rectangles = [
        Rectangle::new(
            Point3::new(-half, -1.5, 0.0),
            Vector3::x() * length,
            Vector3::y() * 3.0,
        )?,
        Rectangle::new(
            Point3::new(-half, -1.5, 0.0),
            Vector3::x() * length,
            Vector3::z() * 3.0,
        )?,
        Rectangle::new(
            Point3::new(-half, 1.5, 0.0),
            Vector3::x() * length,
            Vector3::z() * 3.0,
        )?,
    ];
    let shapes: Vec<Shape> = rectangles
        .iter()
        .map(|r| Shape::rectangle(*r, IntensityRange::WALL))
        .collect();
    let world_from_reference = pose(
        Vector3::new(0.0, uniform(&mut rng, -0.3, 0.3), 1.5),
        0.0,
        0.0,
        uniform(&mut rng, -0.2, 0.2),
    );
    let world_from_target = pose(
        Vector3::new(1.0, uniform(&mut rng, -0.3, 0.3), 1.2),
        uniform(&mut rng, -0.2, 0.2),
        0.3,
        uniform(&mut rng, 0.5, 1.5),
    );
    let model = BeamModel::preset(super::Preset::Vlp16);
    let scan_seeds = (rng.random::<u64>(), rng.random::<u64>());
    let (reference, target) = scan_pair(
        &model,
        &shapes,
        [&world_from_reference, &world_from_target],
        scan_seeds,
        None,
        0.0,
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

/// The rotation `Rz(yaw) Ry(pitch) Rx(roll)` (helper for callers building poses).
pub fn rotation_zyx(yaw: f64, pitch: f64, roll: f64) -> Rotation3<f64> {
    Rotation3::from_euler_angles(roll, pitch, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Preset;

    #[test]
    fn paper_configurations_match_table() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let one = paper_configuration(PaperConfiguration::One, &mut rng);
        let (r, p, y) = one.rotation.euler_angles();
        assert!(
            (y - 2.7337).abs() < 1e-12 && (p + 0.3946).abs() < 1e-12 && (r + 0.1809).abs() < 1e-12
        );
        let rand = paper_configuration(PaperConfiguration::Random, &mut rng);
        assert!(rand.translation.vector.amax() <= PAPER_MAX_TRANSLATION);
    }

    #[test]
    fn paper_scene_counts_and_validation() {
        let s = paper_scene(&PaperOptions::default()).unwrap();
        assert_eq!(s.reference.len(), 9500);
        assert_eq!(s.target.len(), 9500);
        assert_eq!(s.planes.len(), 3);
        let bad = PaperOptions {
            alpha_deg: 190.0,
            ..PaperOptions::default()
        };
        assert!(matches!(paper_scene(&bad), Err(Error::InvalidInput(_))));
    }

    #[test]
    fn scenes_reject_bad_options() {
        let m = BeamModel::preset(Preset::Vlp16);
        let bad = PolesOptions {
            radius: -0.1,
            ..PolesOptions::default()
        };
        assert!(matches!(poles_scene(&m, &bad), Err(Error::InvalidInput(_))));
        let bad = CornerOptions {
            dropout: 2.0,
            ..CornerOptions::default()
        };
        assert!(matches!(
            corner_scene(&m, &bad),
            Err(Error::InvalidInput(_))
        ));
        let bad = CornerOptions {
            extra_walls: 3,
            ..CornerOptions::default()
        };
        assert!(corner_scene(&m, &bad).is_err());
    }
}
