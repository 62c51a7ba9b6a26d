//! A street (targetless plane matching) and a corridor (its unobservable case).

use nalgebra::{Isometry3, Point3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{pose, rectangle_shapes, reference_planes, scan_pair, uniform, Pole, Scene};
use crate::error::{Error, Result};
use crate::geometry::Plane;
use crate::sim::shapes::{Cuboid, Cylinder, IntensityRange, Rectangle, Shape};
use crate::sim::{scan, BeamModel, Scan, ScanOptions};

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
    validate_street(options)?;
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let (rectangles, mut boxes) = street_layout(&mut rng, options.cross_wall)?;
    let cylinders = if options.clutter {
        kerb_clutter(&mut rng, &mut boxes)?
    } else {
        Vec::new()
    };
    let (world_from_reference, reference_from_target) = mount_sensors(&mut rng, options);
    let world_from_target = world_from_reference * reference_from_target;
    let shapes = street_shapes(&rectangles, &boxes, &cylinders);
    let scan_seeds = (rng.random::<u64>(), rng.random::<u64>());
    let (reference, target) = scan_street(
        &shapes,
        [&world_from_reference, &world_from_target],
        scan_seeds,
        options.range_noise,
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

/// The `InvalidInput` checks of [`street_scene`].
fn validate_street(options: &StreetOptions) -> Result<()> {
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
    Ok(())
}

/// The road, the facades (drawn) and the optional cross wall as rectangles (road first), and the
/// pavements as boxes.
fn street_layout(rng: &mut ChaCha8Rng, cross_wall: bool) -> Result<(Vec<Rectangle>, Vec<Cuboid>)> {
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
            let width = uniform(rng, 8.0, 25.0).min(half - x);
            let height = uniform(rng, 6.0, 15.0);
            let y = sign * (STREET_FACADE_DISTANCE + uniform(rng, 0.0, 0.4));
            rectangles.push(Rectangle::new(
                Point3::new(x, y, 0.0),
                Vector3::x() * width,
                Vector3::z() * height,
            )?);
            x += width + uniform(rng, 1.0, 4.0);
        }
    }
    if cross_wall {
        rectangles.push(Rectangle::new(
            Point3::new(30.0, -STREET_FACADE_DISTANCE, 0.0),
            Vector3::y() * (2.0 * STREET_FACADE_DISTANCE),
            Vector3::z() * 8.0,
        )?);
    }
    Ok((rectangles, boxes))
}

/// Parked cars (pushed onto `boxes`), tree trunks and poles (returned) along both kerbs.
fn kerb_clutter(rng: &mut ChaCha8Rng, boxes: &mut Vec<Cuboid>) -> Result<Vec<Cylinder>> {
    let half = 0.5 * STREET_LENGTH;
    let mut cylinders = Vec::new();
    for sign in [-1.0, 1.0] {
        let mut x = -half + uniform(rng, 0.0, 8.0);
        while x < half - 5.0 {
            let kind: f64 = rng.random();
            let y = sign * (STREET_HALF_WIDTH + 0.6);
            if kind < 0.4 {
                let size = Vector3::new(
                    uniform(rng, 3.8, 4.8),
                    uniform(rng, 1.7, 1.9),
                    uniform(rng, 1.4, 1.7),
                );
                let center = Vector3::new(x, sign * (STREET_HALF_WIDTH - 1.1), 0.5 * size.z);
                let yaw = uniform(rng, -0.05, 0.05);
                boxes.push(Cuboid::new(pose(center, 0.0, 0.0, yaw), size)?);
                x += size.x + uniform(rng, 1.0, 8.0);
            } else if kind < 0.8 {
                let radius = uniform(rng, 0.12, 0.3);
                let trunk = Cylinder::new(
                    Point3::new(x, y, 0.0),
                    Vector3::z(),
                    uniform(rng, 2.5, 4.0),
                    radius,
                )?;
                cylinders.push(trunk);
                x += uniform(rng, 4.0, 10.0);
            } else {
                let post = Cylinder::new(
                    Point3::new(x, y, 0.0),
                    Vector3::z(),
                    uniform(rng, 3.0, 6.0),
                    uniform(rng, 0.05, 0.1),
                )?;
                cylinders.push(post);
                x += uniform(rng, 4.0, 10.0);
            }
        }
    }
    Ok(cylinders)
}

/// Draws `world_from_reference` (the roof unit) and `reference_from_target` (the side unit).
fn mount_sensors(
    rng: &mut ChaCha8Rng,
    options: &StreetOptions,
) -> (Isometry3<f64>, Isometry3<f64>) {
    // The vehicle drives along +x in the right lane; the roof unit is the reference.
    let small = 1f64.to_radians();
    let vehicle_y = -0.5 * STREET_HALF_WIDTH + uniform(rng, -0.5, 0.5);
    let world_from_reference = pose(
        Vector3::new(uniform(rng, -2.0, 2.0), vehicle_y, 2.0),
        uniform(rng, -small, small),
        uniform(rng, -small, small),
        uniform(rng, -2.0 * small, 2.0 * small),
    );
    let (side_sign, yaw) = match options.side {
        Side::Left => (1.0, std::f64::consts::FRAC_PI_2),
        Side::Right => (-1.0, -std::f64::consts::FRAC_PI_2),
    };
    let mount_error = 3f64.to_radians();
    let reference_from_target = pose(
        Vector3::new(
            uniform(rng, -0.2, 0.2) + options.target_offset,
            side_sign * uniform(rng, 0.45, 0.65),
            -uniform(rng, 0.3, 0.5),
        ),
        uniform(rng, -mount_error, mount_error),
        options.target_tilt_deg.to_radians() + uniform(rng, -mount_error, mount_error),
        yaw + uniform(rng, -mount_error, mount_error),
    );
    (world_from_reference, reference_from_target)
}

/// The shapes in scan order: rectangles (the road ground-bright, the rest walls), boxes, poles.
fn street_shapes(rectangles: &[Rectangle], boxes: &[Cuboid], cylinders: &[Cylinder]) -> Vec<Shape> {
    let mut shapes = rectangle_shapes(rectangles, 0);
    shapes.extend(clutter_shapes(boxes, cylinders));
    shapes
}

/// Parked cars (boxes) and then poles and trunks (cylinders) as shapes, with their intensities.
pub(super) fn clutter_shapes<'a>(
    boxes: &'a [Cuboid],
    cylinders: &'a [Cylinder],
) -> impl Iterator<Item = Shape> + 'a {
    boxes
        .iter()
        .map(|b| Shape::cuboid(*b, IntensityRange::CLUTTER))
        .chain(
            cylinders
                .iter()
                .map(|c| Shape::cylinder(*c, IntensityRange::POLE)),
        )
}

/// Scans the street with the roof HDL-64E (reference) and the wide-angle side unit (target).
fn scan_street(
    shapes: &[Shape],
    world_from: [&Isometry3<f64>; 2],
    scan_seeds: (u64, u64),
    range_noise: Option<f64>,
) -> Result<(Scan, Scan)> {
    let reference = scan(
        &BeamModel::preset(crate::sim::Preset::Hdl64e),
        shapes,
        world_from[0],
        &ScanOptions {
            seed: scan_seeds.0,
            range_noise,
            dropout: 0.0,
        },
    )?;
    let target = scan(
        &wide_angle_model()?,
        shapes,
        world_from[1],
        &ScanOptions {
            seed: scan_seeds.1,
            range_noise,
            dropout: 0.0,
        },
    )?;
    Ok((reference, target))
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
    let model = BeamModel::preset(crate::sim::Preset::Vlp16);
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
