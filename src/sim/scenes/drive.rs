//! A simulated drive through a town: two units with limited fields of view, one looking forward at
//! the front of the vehicle and one looking backward at the rear, that never see the same thing at
//! the same time (issue 19: calibrating from a drive, from each unit's own motion).
//!
//! # The route
//! A staircase of streets: the vehicle starts at the origin heading +x and at the end of every
//! block (of random length, [`DRIVE_BLOCK_LENGTH_RANGE`]) turns 90 degrees, alternately left and
//! right (which comes first is drawn from the seed), on circular arcs of radius
//! [`DRIVE_TURN_RADIUS`] tangent to the straights, so the heading is continuous. It drives the
//! centre line at a constant speed on flat ground (z = 0); the route is as long as the drive
//! needs, so a default drive (200 frames at 10 Hz and 7 m/s, 139 m) takes two or three turns.
//!
//! # The vehicle's body
//! With `body_motion` the body pitches and rolls by a few tenths of a degree as sums of sinusoids
//! of incommensurate periods with phases from the seed, rolls outward in the turns in proportion
//! to the lateral acceleration (the curvature averaged over 3 m either side, so the roll has no
//! step where an arc starts), and its height bobs by about a centimetre: about
//! 0.5–1.5 degrees in all. Without it the motion is exactly planar (constant height, no pitch or
//! roll), the case where the units' height offset is unobservable from motion.
//!
//! # The town
//! Facades (buildings of random widths, heights and setbacks with gaps, as in
//! [`street_scene`](super::street_scene)) line both sides of every street of the route at
//! `+-STREET_FACADE_DISTANCE`; at each junction the two streets the route does not take run a few
//! tens of metres to a cross wall; the first and the last street end in a wall. Parked cars
//! (boxes), tree trunks and poles (cylinders) line the kerbs. `shapes[0]` is the ground
//! ([`DRIVE_GROUND_SHAPE`]); a default drive has about 70 shapes (seed 0: 72), a 200 s one
//! about 520. Before each scan the shapes that cannot be reached (farther than the model's
//! maximum range, or behind a unit whose field is at most 180 degrees) are culled, which changes
//! no point and keeps a frame's cost flat however long the drive.
//!
//! # The units
//! Both use [`drive_model`] (64 beams from -25 to +15 degrees, 0.2 degree columns, 0.5–100 m,
//! 1 cm noise) limited to `field_of_view_deg` (120 by default) about their +x axes. The reference
//! is at the front (about 1.8 m forward, 0.6–1.1 m up, looking forward), the target at the rear
//! (about 2.5 m back, looking backward), each with a few degrees and centimetres of random
//! mounting error. Both scan at the same instants `k / rate_hz` with no motion distortion.
//!
//! Nearly every one of a unit's 64 x 601 beams returns: a default frame holds about 37,500
//! points from the front unit and 36,000 from the rear one, half of them on the ground, and the
//! 200 frames take about 11 s on two cores (54 ms a frame for both units, release build).
//!
//! # Determinism
//! The layout, the mounting, the body motion and the scan seeds come from separate streams of one
//! `ChaCha8Rng` seeded with the seed, so the mounting and the body's motion do not depend on the
//! number of frames; the frames are the same whether scanned in parallel or not.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{Isometry3, Point3, Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::street::{clutter_shapes, STREET_FACADE_DISTANCE, STREET_HALF_WIDTH};
use super::{pose, uniform};
use crate::error::{Error, Result};
use crate::sim::shapes::{Cuboid, Cylinder, IntensityRange, Rectangle, Shape};
use crate::sim::{beams, scan, BeamModel, Scan, ScanOptions};

/// Most frames a drive may have (5 minutes at 10 Hz).
pub const DRIVE_MAX_FRAMES: usize = 3000;
/// Highest frame rate accepted, Hz.
pub const DRIVE_MAX_RATE_HZ: f64 = 100.0;
/// Highest speed accepted, m/s (72 km/h).
pub const DRIVE_MAX_SPEED: f64 = 20.0;
/// Radius of the route's turns on the centre line, metres.
pub const DRIVE_TURN_RADIUS: f64 = 9.0;
/// Range of the blocks' lengths (junction to junction), metres.
pub const DRIVE_BLOCK_LENGTH_RANGE: (f64, f64) = (40.0, 55.0);
/// Index of the ground in [`DriveScene::shapes`].
pub const DRIVE_GROUND_SHAPE: usize = 0;
/// Default horizontal field of view of both units, degrees.
pub const DRIVE_FIELD_OF_VIEW_DEG: f64 = 120.0;

/// Beams of [`drive_model`] and its elevation limits, degrees.
const DRIVE_BEAMS: usize = 64;
const DRIVE_ELEVATION_RANGE_DEG: (f64, f64) = (-25.0, 15.0);
/// Half width of the window the curvature is averaged over for the roll in turns, metres.
const CURVATURE_WINDOW: f64 = 3.0;
/// Roll per lateral acceleration, degrees per m/s^2 (a soft passenger car: about 1 degree in a
/// 9 m turn at 7 m/s).
const ROLL_PER_LATERAL_ACCELERATION_DEG: f64 = 0.2;
/// Body pitch sinusoids: (amplitude in degrees, period in seconds).
const PITCH_WAVES: [(f64, f64); 3] = [(0.3, 1.37), (0.2, 2.71), (0.15, 4.43)];
/// Body roll sinusoids: (amplitude in degrees, period in seconds).
const ROLL_WAVES: [(f64, f64); 3] = [(0.25, 1.61), (0.15, 3.07), (0.1, 5.29)];
/// Body height sinusoids: (amplitude in metres, period in seconds).
const BOB_WAVES: [(f64, f64); 2] = [(0.008, 0.93), (0.005, 1.53)];
/// Length of the street behind the start, to its end wall, metres.
const STREET_BEHIND_START: f64 = 30.0;
/// Distance the route goes on past the drive's last pose before its last street ends, metres.
const ROUTE_END_MARGIN: f64 = 15.0;
/// Range of the distances from a junction to the cross wall of a street the route does not
/// take, metres.
const CROSS_STREET_LENGTH_RANGE: (f64, f64) = (12.0, 30.0);
/// Range of the facades' (and walls') heights, metres.
const FACADE_HEIGHT_RANGE: (f64, f64) = (6.0, 15.0);
/// Margin of the ground rectangle around the route's junctions, metres (beyond the units' range).
const GROUND_MARGIN: f64 = 120.0;
/// Nominal position of the reference (front) unit along the body, metres (positive: ahead of the
/// body's origin).
const REFERENCE_FORWARD: f64 = 1.8;
/// Nominal position of the target (rear) unit along the body, metres (negative: behind).
const TARGET_FORWARD: f64 = -2.5;
/// Range of both units' heights above the ground, metres.
const MOUNT_HEIGHT_RANGE: (f64, f64) = (0.6, 1.1);
/// Largest random mounting error of position (metres, per axis) and angle (degrees, per axis).
const MOUNT_POSITION_ERROR: f64 = 0.05;
const MOUNT_ANGLE_ERROR_DEG: f64 = 3.0;

/// Streams of the scene's `ChaCha8Rng`.
const LAYOUT_STREAM: u64 = 0;
const MOUNT_STREAM: u64 = 1;
const MOTION_STREAM: u64 = 2;
const SCAN_STREAM: u64 = 3;

/// Options of [`drive_scene`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveOptions {
    /// Seed of the town, the route's turns, the mounting, the body motion and the scans.
    pub seed: u64,
    /// Number of frames, in `2..=DRIVE_MAX_FRAMES`.
    pub frames: usize,
    /// Frame rate, Hz, in `(0, DRIVE_MAX_RATE_HZ]`.
    pub rate_hz: f64,
    /// Speed along the route, m/s, in `(0, DRIVE_MAX_SPEED]`.
    pub speed: f64,
    /// Body pitch, roll and bounce (see the module docs); without it the motion is planar.
    pub body_motion: bool,
    /// Keep the ground's returns; without it they are dropped (the ground still blocks beams).
    pub ground: bool,
    /// Horizontal field of view of both units, degrees, in `(0, 360]`.
    pub field_of_view_deg: f64,
    /// Range noise (metres, 1 sigma) of both units; `None` is [`drive_model`]'s 1 cm.
    pub range_noise: Option<f64>,
}

impl Default for DriveOptions {
    fn default() -> Self {
        DriveOptions {
            seed: 0,
            frames: 200,
            rate_hz: 10.0,
            speed: 7.0,
            body_motion: true,
            ground: true,
            field_of_view_deg: DRIVE_FIELD_OF_VIEW_DEG,
            range_noise: None,
        }
    }
}

/// A drive: each unit's frames in its own frame, and the ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveScene {
    /// The reference (front) unit's scans, one per frame, in its frame.
    pub reference_frames: Vec<Scan>,
    /// The target (rear) unit's scans, one per frame, in its frame.
    pub target_frames: Vec<Scan>,
    /// The true extrinsics: `p_ref = reference_from_target * p_tgt`.
    pub reference_from_target: Isometry3<f64>,
    /// The reference unit's true pose in the world at each frame.
    pub world_from_reference: Vec<Isometry3<f64>>,
    /// Time of each frame, seconds (`k / rate_hz`).
    pub times: Vec<f64>,
    /// The town in the world frame; `shapes[DRIVE_GROUND_SHAPE]` is the ground. The scans' shape
    /// indices refer to this list.
    pub shapes: Vec<Shape>,
}

impl DriveScene {
    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.times.len()
    }

    /// The target unit's true pose in the world at frame `k` (`None` past the last frame).
    pub fn world_from_target(&self, k: usize) -> Option<Isometry3<f64>> {
        self.world_from_reference
            .get(k)
            .map(|w| w * self.reference_from_target)
    }
}

/// The units' beam model: 64 beams from -25 to +15 degrees, 1800 columns per turn (0.2 degrees),
/// 0.5–100 m, 1 cm range noise, limited to a horizontal field of view of `field_of_view_deg`
/// (in `(0, 360]`) about +x, named `fov<degrees>` (`fov120`).
pub fn drive_model(field_of_view_deg: f64) -> Result<BeamModel> {
    let (low, high) = DRIVE_ELEVATION_RANGE_DEG;
    let step = (high - low) / (DRIVE_BEAMS - 1) as f64;
    let elevations: Vec<f64> = (0..DRIVE_BEAMS).map(|i| low + step * i as f64).collect();
    let settings = beams::BeamSettings::default();
    BeamModel::custom(
        &format!("fov{field_of_view_deg}"),
        &elevations,
        settings.columns,
        settings.min_range,
        settings.max_range,
        settings.range_noise,
    )?
    .with_horizontal_fov(field_of_view_deg)
}

/// Simulates a drive (see the module docs). Errors (`InvalidInput`) for options out of range.
pub fn drive_scene(options: &DriveOptions) -> Result<DriveScene> {
    validate(options)?;
    let model = drive_model(options.field_of_view_deg)?;
    let rng_on = |stream| {
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
        rng.set_stream(stream);
        rng
    };
    let duration = (options.frames - 1) as f64 / options.rate_hz;
    let mut layout = rng_on(LAYOUT_STREAM);
    let route = Route::new(&mut layout, options.speed * duration + ROUTE_END_MARGIN);
    let shapes = town(&mut layout, &route)?;
    let (body_from_reference, body_from_target) = mount_units(&mut rng_on(MOUNT_STREAM));
    let motion = BodyMotion::new(&mut rng_on(MOTION_STREAM), options.body_motion);
    let times: Vec<f64> = (0..options.frames)
        .map(|k| k as f64 / options.rate_hz)
        .collect();
    let world_from_body: Vec<Isometry3<f64>> = times
        .iter()
        .map(|&t| motion.world_from_body(&route, t, options.speed))
        .collect();
    let mut scan_rng = rng_on(SCAN_STREAM);
    let seeds = (scan_rng.random::<u64>(), scan_rng.random::<u64>());
    let ctx = FrameContext {
        model: &model,
        shapes: &shapes,
        options,
        body_from_reference: &body_from_reference,
        body_from_target: &body_from_target,
        seeds,
    };
    #[cfg(feature = "parallel")]
    let scanned: Vec<Result<(Scan, Scan)>> = {
        use rayon::prelude::*;
        world_from_body
            .par_iter()
            .enumerate()
            .map(|(k, w)| ctx.scan_frame(k, w))
            .collect()
    };
    #[cfg(not(feature = "parallel"))]
    let scanned: Vec<Result<(Scan, Scan)>> = world_from_body
        .iter()
        .enumerate()
        .map(|(k, w)| ctx.scan_frame(k, w))
        .collect();
    let mut reference_frames = Vec::with_capacity(options.frames);
    let mut target_frames = Vec::with_capacity(options.frames);
    for frame in scanned {
        let (reference, target) = frame?;
        reference_frames.push(reference);
        target_frames.push(target);
    }
    Ok(DriveScene {
        reference_frames,
        target_frames,
        reference_from_target: body_from_reference.inverse() * body_from_target,
        world_from_reference: world_from_body
            .iter()
            .map(|w| w * body_from_reference)
            .collect(),
        times,
        shapes,
    })
}

/// The `InvalidInput` checks of [`drive_scene`].
fn validate(options: &DriveOptions) -> Result<()> {
    if !(2..=DRIVE_MAX_FRAMES).contains(&options.frames) {
        return Err(Error::InvalidInput(format!(
            "a drive needs 2..={DRIVE_MAX_FRAMES} frames, got {}",
            options.frames
        )));
    }
    if !(options.rate_hz.is_finite()
        && options.rate_hz > 0.0
        && options.rate_hz <= DRIVE_MAX_RATE_HZ)
    {
        return Err(Error::InvalidInput(format!(
            "rate_hz must be in (0, {DRIVE_MAX_RATE_HZ}] Hz, got {}",
            options.rate_hz
        )));
    }
    if !(options.speed.is_finite() && options.speed > 0.0 && options.speed <= DRIVE_MAX_SPEED) {
        return Err(Error::InvalidInput(format!(
            "speed must be in (0, {DRIVE_MAX_SPEED}] m/s, got {}",
            options.speed
        )));
    }
    let fov = options.field_of_view_deg;
    if !(fov.is_finite() && fov > 0.0 && fov <= beams::FULL_TURN_DEG) {
        return Err(Error::InvalidInput(format!(
            "field_of_view_deg must be in (0, {}] degrees, got {fov}",
            beams::FULL_TURN_DEG
        )));
    }
    if let Some(noise) = options.range_noise {
        beams::check_noise(noise)?;
    }
    Ok(())
}

/// The unit vector at `heading` (radians from +x, counter-clockwise) and its left normal.
fn direction(heading: f64) -> Vector2<f64> {
    Vector2::new(heading.cos(), heading.sin())
}
fn left_of(heading: f64) -> Vector2<f64> {
    Vector2::new(-heading.sin(), heading.cos())
}

/// A piece of the route's centre line.
#[derive(Debug, Clone, Copy)]
enum Piece {
    /// A straight from `start` at `heading`.
    Straight {
        start: Vector2<f64>,
        heading: f64,
        length: f64,
    },
    /// An arc from `start` at `heading`, turning `turn` (+1 left, -1 right) on [`DRIVE_TURN_RADIUS`].
    Arc {
        start: Vector2<f64>,
        heading: f64,
        turn: f64,
        length: f64,
    },
}

impl Piece {
    fn length(&self) -> f64 {
        match *self {
            Piece::Straight { length, .. } | Piece::Arc { length, .. } => length,
        }
    }

    /// Position and (unwrapped) heading `u` metres along the piece.
    fn at(&self, u: f64) -> (Vector2<f64>, f64) {
        match *self {
            Piece::Straight { start, heading, .. } => (start + direction(heading) * u, heading),
            Piece::Arc {
                start,
                heading,
                turn,
                ..
            } => {
                let r = DRIVE_TURN_RADIUS;
                let centre = start + left_of(heading) * (turn * r);
                let h = heading + turn * u / r;
                (centre - left_of(h) * (turn * r), h)
            }
        }
    }
}

/// A street of the town: from `start` along `heading` for `length` metres (junction to junction),
/// with flags for the route's first and last street (which end in walls).
#[derive(Debug, Clone, Copy)]
struct Street {
    start: Vector2<f64>,
    heading: f64,
    length: f64,
    first: bool,
    last: bool,
}

/// The route: its pieces (with their start along the route), the streets and the junctions where
/// it turns (position, incoming and outgoing heading).
#[derive(Debug, Clone)]
struct Route {
    pieces: Vec<(f64, Piece)>,
    length: f64,
    streets: Vec<Street>,
    junctions: Vec<(Vector2<f64>, f64, f64)>,
}

impl Route {
    /// A staircase route at least `needed` metres long, from the origin along +x.
    fn new(rng: &mut ChaCha8Rng, needed: f64) -> Route {
        let r = DRIVE_TURN_RADIUS;
        let mut turn = if rng.random::<bool>() { 1.0 } else { -1.0 };
        let (mut vertex, mut heading) = (Vector2::zeros(), 0.0);
        let mut route = Route {
            pieces: Vec::new(),
            length: 0.0,
            streets: Vec::new(),
            junctions: Vec::new(),
        };
        loop {
            let (lo, hi) = DRIVE_BLOCK_LENGTH_RANGE;
            let block = uniform(rng, lo, hi);
            let first = route.streets.is_empty();
            let entry = if first { 0.0 } else { r };
            let next = vertex + direction(heading) * block;
            let last = route.length + block - entry >= needed;
            route.streets.push(Street {
                start: vertex,
                heading,
                length: block,
                first,
                last,
            });
            let straight = if last {
                block - entry
            } else {
                block - entry - r
            };
            route.push(Piece::Straight {
                start: vertex + direction(heading) * entry,
                heading,
                length: straight,
            });
            if last {
                return route;
            }
            let (start, _) = route.at(route.length);
            route.push(Piece::Arc {
                start,
                heading,
                turn,
                length: FRAC_PI_2 * r,
            });
            route
                .junctions
                .push((next, heading, heading + turn * FRAC_PI_2));
            heading += turn * FRAC_PI_2;
            turn = -turn;
            vertex = next;
        }
    }

    fn push(&mut self, piece: Piece) {
        self.pieces.push((self.length, piece));
        self.length += piece.length();
    }

    /// Position and unwrapped heading `s` metres along the route (straight on before the start
    /// and past the end).
    fn at(&self, s: f64) -> (Vector2<f64>, f64) {
        let index = self
            .pieces
            .partition_point(|(start, _)| *start <= s)
            .saturating_sub(1);
        let Some((start, piece)) = self.pieces.get(index) else {
            return (Vector2::zeros(), 0.0);
        };
        let u = s - start;
        // Before the start `u` is negative and the first straight runs backward; past the end of
        // the last piece the route goes straight on.
        let (p, h) = piece.at(u.min(piece.length()));
        let past = if index + 1 == self.pieces.len() {
            (u - piece.length()).max(0.0)
        } else {
            0.0
        };
        (p + direction(h) * past, h)
    }

    /// Curvature (1/m, positive to the left) averaged over `s +- CURVATURE_WINDOW`.
    fn smoothed_curvature(&self, s: f64) -> f64 {
        let (_, ahead) = self.at(s + CURVATURE_WINDOW);
        let (_, behind) = self.at(s - CURVATURE_WINDOW);
        (ahead - behind) / (2.0 * CURVATURE_WINDOW)
    }
}

/// The body's pitch, roll and height waves (phases drawn from the seed), or none.
struct BodyMotion {
    enabled: bool,
    pitch_phases: [f64; PITCH_WAVES.len()],
    roll_phases: [f64; ROLL_WAVES.len()],
    bob_phases: [f64; BOB_WAVES.len()],
}

fn waves<const N: usize>(waves: &[(f64, f64); N], phases: &[f64; N], t: f64) -> f64 {
    waves
        .iter()
        .zip(phases)
        .map(|((amplitude, period), phase)| amplitude * (TAU * t / period + phase).sin())
        .sum()
}

impl BodyMotion {
    fn new(rng: &mut ChaCha8Rng, enabled: bool) -> BodyMotion {
        let mut phases = || uniform(rng, 0.0, TAU);
        BodyMotion {
            enabled,
            pitch_phases: std::array::from_fn(|_| phases()),
            roll_phases: std::array::from_fn(|_| phases()),
            bob_phases: std::array::from_fn(|_| phases()),
        }
    }

    /// The body's pose at time `t` (origin on the ground under the body's centre, x forward,
    /// z up).
    fn world_from_body(&self, route: &Route, t: f64, speed: f64) -> Isometry3<f64> {
        let s = speed * t;
        let (p, heading) = route.at(s);
        if !self.enabled {
            return pose(Vector3::new(p.x, p.y, 0.0), 0.0, 0.0, heading);
        }
        let lateral_acceleration = speed * speed * route.smoothed_curvature(s);
        let roll = waves(&ROLL_WAVES, &self.roll_phases, t)
            + ROLL_PER_LATERAL_ACCELERATION_DEG * lateral_acceleration;
        let pitch = waves(&PITCH_WAVES, &self.pitch_phases, t);
        let bob = waves(&BOB_WAVES, &self.bob_phases, t);
        pose(
            Vector3::new(p.x, p.y, bob),
            roll.to_radians(),
            pitch.to_radians(),
            heading,
        )
    }
}

/// Draws `body_from_reference` (front, looking forward) and `body_from_target` (rear, looking
/// backward).
fn mount_units(rng: &mut ChaCha8Rng) -> (Isometry3<f64>, Isometry3<f64>) {
    let mut mount = |forward: f64, yaw: f64| {
        let e = MOUNT_POSITION_ERROR;
        let a = MOUNT_ANGLE_ERROR_DEG.to_radians();
        let (lo, hi) = MOUNT_HEIGHT_RANGE;
        let position = Vector3::new(
            forward + uniform(rng, -e, e),
            uniform(rng, -e, e),
            uniform(rng, lo, hi),
        );
        pose(
            position,
            uniform(rng, -a, a),
            uniform(rng, -a, a),
            yaw + uniform(rng, -a, a),
        )
    };
    let reference = mount(REFERENCE_FORWARD, 0.0);
    let target = mount(TARGET_FORWARD, PI);
    (reference, target)
}

/// The point `z` metres above `p` of the ground plane.
fn at_height(p: Vector2<f64>, z: f64) -> Point3<f64> {
    Point3::new(p.x, p.y, z)
}

/// A vertical rectangle from `start` along `along` (a horizontal unit vector) for `width`,
/// `height` tall.
fn wall(start: Vector2<f64>, along: Vector2<f64>, width: f64, height: f64) -> Result<Rectangle> {
    Rectangle::new(
        at_height(start, 0.0),
        Vector3::new(along.x, along.y, 0.0) * width,
        Vector3::z() * height,
    )
}

/// The town: the ground, facades, cross and end walls, parked cars, trunks and poles.
fn town(rng: &mut ChaCha8Rng, route: &Route) -> Result<Vec<Shape>> {
    let d = STREET_FACADE_DISTANCE;
    let mut walls = Vec::new();
    let mut boxes = Vec::new();
    let mut cylinders = Vec::new();
    for street in &route.streets {
        let along = direction(street.heading);
        let left = left_of(street.heading);
        let from = if street.first {
            -STREET_BEHIND_START
        } else {
            d
        };
        let to = if street.last {
            street.length + d
        } else {
            street.length - d
        };
        for side in [-1.0, 1.0] {
            facades(rng, &mut walls, street.start, along, left * side, from, to)?;
            kerb_clutter(
                rng,
                &mut boxes,
                &mut cylinders,
                street.start,
                (along, left * side),
                (from, to),
                street.heading,
            )?;
        }
        for (end, at) in [(street.first, from), (street.last, to)] {
            if end {
                let (lo, hi) = FACADE_HEIGHT_RANGE;
                let corner = street.start + along * at - left * d;
                walls.push(wall(corner, left, 2.0 * d, uniform(rng, lo, hi))?);
            }
        }
    }
    for &(junction, heading_in, heading_out) in &route.junctions {
        // The streets the route does not take: straight on, and back from the outgoing one.
        for arm in [heading_in, heading_out + PI] {
            let along = direction(arm);
            let left = left_of(arm);
            let (lo, hi) = CROSS_STREET_LENGTH_RANGE;
            let length = uniform(rng, lo, hi);
            let (hlo, hhi) = FACADE_HEIGHT_RANGE;
            for side in [-1.0, 1.0] {
                let start = junction + along * d + left * (side * d);
                walls.push(wall(start, along, length - d, uniform(rng, hlo, hhi))?);
            }
            let corner = junction + along * length - left * d;
            walls.push(wall(corner, left, 2.0 * d, uniform(rng, hlo, hhi))?);
        }
    }
    let mut shapes = vec![Shape::rectangle(ground(route)?, IntensityRange::GROUND)];
    shapes.extend(
        walls
            .iter()
            .map(|r| Shape::rectangle(*r, IntensityRange::WALL)),
    );
    shapes.extend(clutter_shapes(&boxes, &cylinders));
    Ok(shapes)
}

/// The ground: a rectangle over the streets' ends with [`GROUND_MARGIN`] around.
fn ground(route: &Route) -> Result<Rectangle> {
    let (mut lo, mut hi) = (Vector2::zeros(), Vector2::zeros());
    for s in &route.streets {
        for p in [s.start, s.start + direction(s.heading) * s.length] {
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
    }
    let margin = Vector2::repeat(GROUND_MARGIN);
    let (lo, hi) = (lo - margin, hi + margin);
    Rectangle::new(
        at_height(lo, 0.0),
        Vector3::x() * (hi.x - lo.x),
        Vector3::y() * (hi.y - lo.y),
    )
}

/// Buildings along one side (`outward`, a unit vector) of a street, from `from` to `to` metres
/// along it: random widths, heights and setbacks, with gaps (as in the street scene).
fn facades(
    rng: &mut ChaCha8Rng,
    walls: &mut Vec<Rectangle>,
    origin: Vector2<f64>,
    along: Vector2<f64>,
    outward: Vector2<f64>,
    from: f64,
    to: f64,
) -> Result<()> {
    let mut t = from;
    while t < to - 1.0 {
        let width = uniform(rng, 8.0, 25.0).min(to - t);
        let (lo, hi) = FACADE_HEIGHT_RANGE;
        let height = uniform(rng, lo, hi);
        let offset = STREET_FACADE_DISTANCE + uniform(rng, 0.0, 0.4);
        walls.push(wall(
            origin + along * t + outward * offset,
            along,
            width,
            height,
        )?);
        t += width + uniform(rng, 1.0, 4.0);
    }
    Ok(())
}

/// Parked cars (boxes), tree trunks and poles (cylinders) along one kerb of a street, `span`
/// metres along it from `origin`; `axes` are the street's direction and the kerb's side.
fn kerb_clutter(
    rng: &mut ChaCha8Rng,
    boxes: &mut Vec<Cuboid>,
    cylinders: &mut Vec<Cylinder>,
    origin: Vector2<f64>,
    axes: (Vector2<f64>, Vector2<f64>),
    span: (f64, f64),
    heading: f64,
) -> Result<()> {
    let (along, outward) = axes;
    let mut t = span.0 + uniform(rng, 2.0, 8.0);
    while t < span.1 - 5.0 {
        let kind: f64 = rng.random();
        if kind < 0.45 {
            let size = Vector3::new(
                uniform(rng, 3.8, 4.8),
                uniform(rng, 1.7, 1.9),
                uniform(rng, 1.4, 1.7),
            );
            let centre = origin + along * (t + 0.5 * size.x) + outward * (STREET_HALF_WIDTH - 1.1);
            let yaw = heading + uniform(rng, -0.05, 0.05);
            boxes.push(Cuboid::new(
                pose(
                    Vector3::new(centre.x, centre.y, 0.5 * size.z),
                    0.0,
                    0.0,
                    yaw,
                ),
                size,
            )?);
            t += size.x + uniform(rng, 2.0, 12.0);
        } else {
            let base = origin + along * t + outward * (STREET_HALF_WIDTH + 0.6);
            let (length, radius) = if kind < 0.75 {
                (uniform(rng, 2.5, 4.0), uniform(rng, 0.12, 0.3))
            } else {
                (uniform(rng, 3.0, 6.0), uniform(rng, 0.05, 0.1))
            };
            cylinders.push(Cylinder::new(
                at_height(base, 0.0),
                Vector3::z(),
                length,
                radius,
            )?);
            t += uniform(rng, 6.0, 14.0);
        }
    }
    Ok(())
}

/// What every frame's scans share.
struct FrameContext<'a> {
    model: &'a BeamModel,
    shapes: &'a [Shape],
    options: &'a DriveOptions,
    body_from_reference: &'a Isometry3<f64>,
    body_from_target: &'a Isometry3<f64>,
    seeds: (u64, u64),
}

impl FrameContext<'_> {
    /// Frame `k`'s scans, the body at `world_from_body`.
    fn scan_frame(&self, k: usize, world_from_body: &Isometry3<f64>) -> Result<(Scan, Scan)> {
        let k = k as u64;
        Ok((
            self.scan_unit(
                &(world_from_body * self.body_from_reference),
                self.seeds.0.wrapping_add(k),
            )?,
            self.scan_unit(
                &(world_from_body * self.body_from_target),
                self.seeds.1.wrapping_add(k),
            )?,
        ))
    }

    /// One unit's scan among the shapes it can reach, with the shape indices of the whole town.
    fn scan_unit(&self, world_from_sensor: &Isometry3<f64>, seed: u64) -> Result<Scan> {
        let origin = Point3::from(world_from_sensor.translation.vector);
        let forward = world_from_sensor.rotation * Vector3::x();
        // Every beam of a field of at most 180 degrees points forward (its x is cos(elevation)
        // cos(azimuth) >= 0), so nothing wholly behind the unit can be hit.
        let half_space = self.model.horizontal_fov() <= PI;
        let reach = self.model.max_range();
        let kept: Vec<usize> = self
            .shapes
            .iter()
            .enumerate()
            .filter(|(_, shape)| {
                let (centre, radius) = shape.bounding_sphere();
                let offset = centre - origin;
                offset.norm() - radius <= reach && !(half_space && offset.dot(&forward) < -radius)
            })
            .map(|(i, _)| i)
            .collect();
        let local: Vec<Shape> = kept
            .iter()
            .filter_map(|&i| self.shapes.get(i))
            .copied()
            .collect();
        let options = ScanOptions {
            seed,
            range_noise: self.options.range_noise,
            dropout: 0.0,
        };
        let mut points = scan(self.model, &local, world_from_sensor, &options)?.points;
        for p in &mut points {
            p.shape = p.shape.and_then(|i| kept.get(i).copied());
        }
        if !self.options.ground {
            points.retain(|p| p.shape != Some(DRIVE_GROUND_SHAPE));
        }
        Ok(Scan { points })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(frames: usize) -> DriveOptions {
        DriveOptions {
            seed: 3,
            frames,
            ..DriveOptions::default()
        }
    }

    #[test]
    fn same_seed_same_drive() {
        let options = small(3);
        let a = drive_scene(&options).unwrap();
        let b = drive_scene(&options).unwrap();
        assert_eq!(a, b);
        let c = drive_scene(&DriveOptions { seed: 4, ..options }).unwrap();
        assert_ne!(a.reference_frames, c.reference_frames);
        assert_eq!(a.frames(), 3);
        assert_eq!(a.times, vec![0.0, 0.1, 0.2]);
        assert!(a.world_from_target(3).is_none());
        // Mounting does not depend on the number of frames.
        let longer = drive_scene(&small(4)).unwrap();
        assert_eq!(longer.reference_from_target, a.reference_from_target);
    }

    #[test]
    fn points_lie_in_the_field_of_view_and_on_the_shapes() {
        let drive = drive_scene(&small(2)).unwrap();
        let limit = 60f64.to_radians() + 1e-9;
        for scans in [&drive.reference_frames, &drive.target_frames] {
            for s in scans {
                assert!(s.len() > 10_000, "{} points", s.len());
                for p in &s.points {
                    assert!(p.position.y.atan2(p.position.x).abs() <= limit);
                    assert!(p.shape.is_some_and(|i| i < drive.shapes.len()));
                }
                assert!(s.points.windows(2).all(|w| w[0].ring <= w[1].ring));
            }
        }
        // Noiseless ground points are on z = 0 in the world (shape indices are the town's).
        let exact = drive_scene(&DriveOptions {
            range_noise: Some(0.0),
            ..small(2)
        })
        .unwrap();
        for k in 0..2 {
            let w = exact.world_from_target(k).unwrap();
            let on_ground: Vec<_> = exact.target_frames[k]
                .positions_of_shape(DRIVE_GROUND_SHAPE)
                .iter()
                .map(|p| w * p)
                .collect();
            assert!(on_ground.len() > 1000);
            assert!(on_ground.iter().all(|p| p.z.abs() < 1e-9));
        }
    }

    #[test]
    fn the_units_never_see_the_same_thing() {
        let drive = drive_scene(&DriveOptions {
            frames: 6,
            rate_hz: 0.5,
            ..small(6)
        })
        .unwrap();
        for k in 0..drive.frames() {
            let wr = drive.world_from_reference[k];
            let wt = drive.world_from_target(k).unwrap();
            let reference: Vec<Point3<f64>> = drive.reference_frames[k]
                .points
                .iter()
                .map(|p| wr * p.position)
                .collect();
            let grid = crate::grid::NeighbourGrid::new(&reference, 0.5);
            for p in &drive.target_frames[k].points {
                assert!(grid.nearest(&(wt * p.position), 0.5).is_none(), "frame {k}");
            }
        }
    }

    #[test]
    fn planar_motion_without_body_motion() {
        let drive = drive_scene(&DriveOptions {
            // The default drive's 20 s (the route is the same), 2 frames a second.
            body_motion: false,
            frames: 40,
            rate_hz: 2.0,
            ground: false,
            ..small(40)
        })
        .unwrap();
        let first = drive.world_from_reference[0];
        let mut yaw_min: f64 = 0.0;
        let mut yaw_max: f64 = 0.0;
        let mut previous = 0.0;
        let mut unwrapped = 0.0;
        // The sign of each turn, in order.
        let mut turns: Vec<f64> = Vec::new();
        let mut turning = false;
        for w in &drive.world_from_reference {
            assert!((w.translation.z - first.translation.z).abs() < 1e-12);
            // Relative to the first pose only the yaw changes.
            let relative = w.rotation * first.rotation.inverse();
            let (roll, pitch, yaw) = relative.euler_angles();
            assert!(roll.abs() < 1e-12 && pitch.abs() < 1e-12);
            let mut step = yaw - previous;
            if step > PI {
                step -= TAU;
            } else if step < -PI {
                step += TAU;
            }
            unwrapped += step;
            previous = yaw;
            let now_turning = step.abs() > 1e-9;
            if now_turning && !turning {
                turns.push(step.signum());
            }
            turning = now_turning;
            yaw_min = yaw_min.min(unwrapped);
            yaw_max = yaw_max.max(unwrapped);
        }
        // At least two turns of 90 degrees, alternately left and right.
        assert!(turns.len() >= 2, "{turns:?}");
        assert!(turns.windows(2).all(|w| w[0] == -w[1]), "{turns:?}");
        assert!(
            (yaw_max - yaw_min - FRAC_PI_2).abs() < 1e-9,
            "{yaw_min} {yaw_max}"
        );
        // No ground returns.
        for s in drive.reference_frames.iter().chain(&drive.target_frames) {
            assert!(s.points.iter().all(|p| p.shape != Some(DRIVE_GROUND_SHAPE)));
        }
        assert!(drive.shapes.len() < 150, "{} shapes", drive.shapes.len());
    }

    #[test]
    fn body_motion_is_small_and_smooth() {
        let route = Route::new(&mut ChaCha8Rng::seed_from_u64(1), 300.0);
        let motion = BodyMotion::new(&mut ChaCha8Rng::seed_from_u64(2), true);
        let mut previous: Option<Isometry3<f64>> = None;
        let mut largest_tilt: f64 = 0.0;
        for k in 0..400 {
            let w = motion.world_from_body(&route, k as f64 * 0.1, 7.0);
            let (roll, pitch, _) = w.rotation.euler_angles();
            largest_tilt = largest_tilt.max(roll.abs()).max(pitch.abs());
            assert!(roll.abs().to_degrees() < 2.0 && pitch.abs().to_degrees() < 1.5);
            assert!(w.translation.z.abs() < 0.02);
            if let Some(p) = previous {
                // 0.7 m a frame and no jump in heading.
                let step = p.inverse() * w;
                assert!((step.translation.vector.norm() - 0.7).abs() < 0.05);
                assert!(step.rotation.angle() < 0.1);
            }
            previous = Some(w);
        }
        assert!(largest_tilt.to_degrees() > 0.5);
    }

    #[test]
    fn bad_options_are_refused() {
        for bad in [
            DriveOptions {
                frames: 1,
                ..DriveOptions::default()
            },
            DriveOptions {
                frames: DRIVE_MAX_FRAMES + 1,
                ..DriveOptions::default()
            },
            DriveOptions {
                rate_hz: 0.0,
                ..DriveOptions::default()
            },
            DriveOptions {
                rate_hz: f64::NAN,
                ..DriveOptions::default()
            },
            DriveOptions {
                rate_hz: 101.0,
                ..DriveOptions::default()
            },
            DriveOptions {
                speed: -1.0,
                ..DriveOptions::default()
            },
            DriveOptions {
                field_of_view_deg: 0.0,
                ..DriveOptions::default()
            },
            DriveOptions {
                field_of_view_deg: 400.0,
                ..DriveOptions::default()
            },
            DriveOptions {
                range_noise: Some(-0.01),
                ..DriveOptions::default()
            },
        ] {
            assert!(
                matches!(drive_scene(&bad), Err(Error::InvalidInput(_))),
                "{bad:?}"
            );
        }
        assert_eq!(drive_model(120.0).unwrap().name(), "fov120");
    }
}
