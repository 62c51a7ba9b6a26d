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
//! * [`drive_scene`]: a vehicle driving an S through a town for 20 s, a forward-looking unit at
//!   its front and a backward-looking one at its rear that never see the same thing at the same
//!   time, with the true poses of every frame (calibration from motion).
//!
//! All layout draws come from one `ChaCha8Rng` seeded with the scene's seed, so a scene is a pure
//! function of its options.

mod corner;
mod drive;
mod paper;
mod poles;
mod street;

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use super::shapes::{IntensityRange, Rectangle, Shape};
use super::{scan, BeamModel, Scan, ScanOptions};
use crate::error::Result;
use crate::geometry::{Line, Plane};

pub use corner::{
    corner_scene, CornerOptions, CORNER_MAX_TILT_DEG, CORNER_WALL_ANGLE_RANGE, CORNER_WALL_HEIGHT,
    CORNER_WALL_LENGTH, MAX_EXTRA_WALLS, SENSOR_CLEARANCE,
};
pub use drive::{
    drive_model, drive_scene, DriveOptions, DriveScene, DRIVE_BLOCK_LENGTH_RANGE,
    DRIVE_FIELD_OF_VIEW_DEG, DRIVE_GROUND_SHAPE, DRIVE_MAX_FRAMES, DRIVE_MAX_RATE_HZ,
    DRIVE_MAX_SPEED, DRIVE_TURN_RADIUS,
};
pub use paper::{
    paper_configuration, paper_scene, PaperConfiguration, PaperOptions, PAPER_ALPHA_RANGE_DEG,
    PAPER_CLUTTER_POINTS, PAPER_CLUTTER_SPREAD, PAPER_MAX_TILT_DEG, PAPER_MAX_TRANSLATION,
    PAPER_PATCH_SIZE, PAPER_PLANE_NOISE, PAPER_POINTS_PER_PLANE,
};
pub use poles::{
    poles_scene, PolesOptions, MAX_POLE_RADIUS, POLES_MAX_TILT_DEG, POLES_RANGE_NOISE, POLE_BAND,
    POLE_LENGTH, POLE_MIN_ANGLE_DEG, POLE_MIN_AXIS_Z, POLE_SPACING_RANGE,
};
pub use street::{
    corridor_scene, street_scene, wide_angle_model, Side, StreetOptions, KERB_HEIGHT,
    STREET_FACADE_DISTANCE, STREET_HALF_WIDTH, STREET_LENGTH,
};

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

/// Attempts at placing each clutter box (or drawing a pole axis) before giving up on it.
const PLACEMENT_ATTEMPTS: usize = 50;

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

/// `rectangles` as shapes in order: the one at `ground` with the ground's intensities, the rest
/// with a wall's.
fn rectangle_shapes(rectangles: &[Rectangle], ground: usize) -> Vec<Shape> {
    rectangles
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let intensity = if i == ground {
                IntensityRange::GROUND
            } else {
                IntensityRange::WALL
            };
            Shape::rectangle(*r, intensity)
        })
        .collect()
}

/// The rotation `Rz(yaw) Ry(pitch) Rx(roll)` (helper for callers building poses).
pub fn rotation_zyx(yaw: f64, pitch: f64, roll: f64) -> Rotation3<f64> {
    Rotation3::from_euler_angles(roll, pitch, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::sim::Preset;
    use rand::SeedableRng;

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
