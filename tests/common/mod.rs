//! Scene generators shared by the integration tests and the criterion benches
//! (the benches include this file with `#[path]`).
#![allow(dead_code)]

use lidarcal::geometry::{orthonormal_basis, se3_exp, Plane};
use lidarcal::residuals::{Frame, PlaneGroup};
use nalgebra::{Isometry3, Point3, Vector3, Vector6};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A standard normal sample by Box–Muller (keeps the dependency list short).
pub fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A wall corner: three planes in the reference frame, `n . p + d = 0`.
pub fn corner_planes() -> [Plane; 3] {
    [
        Plane::new(Vector3::new(-1.0, 0.15, 0.0), 5.0).unwrap(),
        Plane::new(Vector3::new(0.1, -1.0, 0.05), 4.0).unwrap(),
        Plane::new(Vector3::new(0.0, 0.05, 1.0), 1.8).unwrap(),
    ]
}

/// The ground-truth `reference_from_target` used by the benches and tests.
pub fn true_pose() -> Isometry3<f64> {
    se3_exp(&Vector6::new(0.8, -0.4, 0.3, 0.05, -0.08, 0.6))
}

/// `n_per_plane` target-frame points on each corner plane (uniform in a 6 m square patch), with
/// Gaussian noise of `sigma` metres along the normal.
pub fn corner_groups(n_per_plane: usize, sigma: f64, seed: u64) -> Vec<PlaneGroup> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let target_from_reference = true_pose().inverse();
    corner_planes()
        .iter()
        .map(|plane| {
            let (u, v) = orthonormal_basis(&plane.normal);
            let origin = plane.project(&Point3::origin());
            let points = (0..n_per_plane)
                .map(|_| {
                    let a: f64 = rng.random_range(-3.0..3.0);
                    let b: f64 = rng.random_range(-3.0..3.0);
                    let noise = gaussian(&mut rng) * sigma;
                    let p_ref = origin + u * a + v * b + plane.normal.into_inner() * noise;
                    target_from_reference * p_ref
                })
                .collect();
            PlaneGroup {
                plane: *plane,
                points,
                frame: Frame::Target,
            }
        })
        .collect()
}

/// An initial guess off the truth by about 5.7 degrees and 0.35 m.
pub fn perturbed_start() -> Isometry3<f64> {
    se3_exp(&Vector6::new(0.2, -0.25, 0.15, 0.06, 0.05, -0.06)) * true_pose()
}

/// A wall corner cloud in the sensor frame: three planes meeting at `corner`, each sampled on a
/// 4 m x 4 m patch that reaches the intersection lines, with Gaussian noise `sigma` along the
/// normal, plus `clutter` uniform points in a 10 m box. Returns the points and the true planes.
pub fn corner_cloud(
    n_per_plane: usize,
    clutter: usize,
    sigma: f64,
    seed: u64,
) -> (Vec<Point3<f64>>, [Plane; 3]) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let corner = Point3::new(6.0, 4.0, -1.5);
    // Left and right walls 100 degrees apart, a floor; all seen from the origin.
    let left = Vector3::new(-1.0, -0.2, 0.0).normalize();
    let right = Vector3::new(-0.3, -1.0, 0.05).normalize();
    let floor = Vector3::new(0.02, 0.0, 1.0).normalize();
    let normals = [left, right, floor];
    let planes = normals.map(|n| Plane::from_point_normal(&corner, &n).unwrap());
    let mut points = Vec::new();
    for (k, plane) in planes.iter().enumerate() {
        // Span each plane by the directions of its two intersection lines with the others, so
        // the patch starts exactly at the corner edges.
        let others: Vec<_> = (0..3).filter(|&j| j != k).collect();
        let e1 = plane.normal.cross(&normals[others[0]]).normalize();
        let e2 = plane.normal.cross(&normals[others[1]]).normalize();
        // Orient both edges toward the sensor side of the other planes.
        let e1 = if planes[others[1]].signed_distance(&(corner + e1)) > 0.0 {
            e1
        } else {
            -e1
        };
        let e2 = if planes[others[0]].signed_distance(&(corner + e2)) > 0.0 {
            e2
        } else {
            -e2
        };
        for _ in 0..n_per_plane {
            let a: f64 = rng.random_range(0.0..4.0);
            let b: f64 = rng.random_range(0.0..4.0);
            let noise = gaussian(&mut rng) * sigma;
            points.push(corner + e1 * a + e2 * b + plane.normal.into_inner() * noise);
        }
    }
    for _ in 0..clutter {
        points.push(Point3::new(
            rng.random_range(-2.0..8.0),
            rng.random_range(-4.0..6.0),
            rng.random_range(-1.5..3.5),
        ));
    }
    (points, planes)
}

/// Angle in degrees between two unit normals, ignoring sign.
pub fn normal_error_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.dot(b).abs().min(1.0).acos().to_degrees()
}

/// The same wall corner seen by two sensors: independent samples of `corner_cloud`, the second
/// expressed in the target frame of `reference_from_target`.
pub fn two_sensor_corner(
    reference_from_target: &Isometry3<f64>,
    n_per_plane: usize,
    clutter: usize,
    sigma: f64,
    seed: u64,
) -> (Vec<Point3<f64>>, Vec<Point3<f64>>) {
    let (reference, _) = corner_cloud(n_per_plane, clutter, sigma, seed);
    let (in_reference, _) = corner_cloud(n_per_plane, clutter, sigma, seed + 1000);
    let target_from_reference = reference_from_target.inverse();
    let target = in_reference
        .iter()
        .map(|p| target_from_reference * p)
        .collect();
    (reference, target)
}

/// Rotation (rad) and translation (m) errors of `estimate` against `truth`.
pub fn pose_errors(truth: &Isometry3<f64>, estimate: &Isometry3<f64>) -> (f64, f64) {
    let r = (truth.rotation * estimate.rotation.inverse()).angle();
    let t = (truth.translation.vector - estimate.translation.vector).norm();
    (r, t)
}

/// A pose from roll, pitch, yaw (degrees) and a translation (metres).
pub fn pose_rpy_deg(roll: f64, pitch: f64, yaw: f64, t: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        nalgebra::Translation3::new(t[0], t[1], t[2]),
        nalgebra::UnitQuaternion::from_euler_angles(
            roll.to_radians(),
            pitch.to_radians(),
            yaw.to_radians(),
        ),
    )
}

/// `../shared/eval_data/SensorsCalibration` beside the checkout, if present.
pub fn sensors_calibration_dir() -> Option<std::path::PathBuf> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/eval_data/SensorsCalibration");
    dir.is_dir().then_some(dir)
}

/// `None` with a note when the shared data are absent outside CI; a panic in CI (`CI` set), where
/// they must be present.
pub fn require_sensors_calibration() -> Option<std::path::PathBuf> {
    match sensors_calibration_dir() {
        Some(d) => Some(d),
        None if std::env::var_os("CI").is_some() => {
            panic!("../shared/eval_data/SensorsCalibration is missing: CI must run with ../shared")
        }
        None => {
            eprintln!("skipped: ../shared/eval_data/SensorsCalibration not present");
            None
        }
    }
}

/// The first three columns of a little-endian float32 `.npy` array of shape `(N, C)`, `C >= 3`.
pub fn load_npy_xyz(path: &std::path::Path) -> Vec<Point3<f64>> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        &bytes[..6],
        b"\x93NUMPY",
        "{} is not an npy file",
        path.display()
    );
    let (header_len, start) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        )
    };
    let header = std::str::from_utf8(&bytes[start..start + header_len]).unwrap();
    assert!(header.contains("'<f4'") && header.contains("'fortran_order': False"));
    let shape = &header[header.find("'shape': (").unwrap() + 10..];
    let shape = &shape[..shape.find(')').unwrap()];
    let dims: Vec<usize> = shape
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let (n, c) = (dims[0], dims[1]);
    let data = &bytes[start + header_len..];
    let value = |k: usize| f32::from_le_bytes(data[4 * k..4 * k + 4].try_into().unwrap()) as f64;
    (0..n)
        .map(|i| Point3::new(value(i * c), value(i * c + 1), value(i * c + 2)))
        .collect()
}

/// The 4x4 `matrix_4x4` that follows `keys` (in order) in the reference JSON, as an isometry.
pub fn reference_extrinsic(dir: &std::path::Path, keys: &[&str]) -> Isometry3<f64> {
    let text = std::fs::read_to_string(dir.join("reference_extrinsics.json")).unwrap();
    let mut at = 0;
    for key in keys.iter().chain(&["matrix_4x4"]) {
        at += text[at..]
            .find(&format!("\"{key}\""))
            .unwrap_or_else(|| panic!("{key} not in the reference JSON"));
    }
    let numbers: Vec<f64> = text[at + "\"matrix_4x4\"".len()..]
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .filter(|s| !s.is_empty())
        .take(16)
        .map(|s| s.parse().unwrap())
        .collect();
    let m = nalgebra::Matrix4::from_row_slice(&numbers);
    lidarcal::geometry::isometry_from_matrix(&m).unwrap()
}

/// The three real_world scenes of SensorsCalibration.
pub const REAL_WORLD_SCENES: [&str; 3] = [
    "2022-02-15-17-31-37-050",
    "2022-02-15-17-36-04-449",
    "2022-02-15-17-45-07-750",
];
