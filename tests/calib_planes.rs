//! The planar-surfaces method end to end on synthetic corners with known ground truth.

mod common;

use common::{pose_errors, pose_rpy_deg, two_sensor_corner};
use lidarcal::calib::planes::{calibrate_planes, PlanarOptions};
use lidarcal::calib::Solver;
use lidarcal::geometry::Plane;
use lidarcal::lm::Loss;
use lidarcal::Error;
use nalgebra::{Point3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn any_mounting_is_recovered_without_initial_guess() {
    let poses = [
        pose_rpy_deg(0.0, 0.0, 0.0, [0.0, 0.0, 0.0]),
        pose_rpy_deg(2.0, -1.0, 30.0, [0.5, -0.3, 0.2]),
        pose_rpy_deg(0.0, 0.0, 180.0, [1.0, 0.5, 0.0]), // turned around
        pose_rpy_deg(30.0, 0.0, 10.0, [0.2, 0.8, -0.3]), // tilted 30 deg
        pose_rpy_deg(-20.0, 40.0, -70.0, [-0.5, 0.4, 0.6]), // tilted 45 deg
        pose_rpy_deg(180.0, 0.0, 45.0, [0.3, 0.3, 0.3]), // upside down
    ];
    for (i, truth) in poses.iter().enumerate() {
        let (reference, target) = two_sensor_corner(truth, 2500, 800, 0.02, 10 + i as u64);
        let result = calibrate_planes(&reference, &target, &PlanarOptions::default())
            .unwrap_or_else(|e| panic!("pose {i}: {e}"));
        let (r, t) = pose_errors(truth, &result.reference_from_target);
        assert!(r < 2e-3 && t < 1e-2, "pose {i}: {r} rad, {t} m");
        let report = result.details.report.as_ref().unwrap();
        assert!(report.converged());
        assert_eq!(result.refinement.solver, Solver::LevenbergMarquardt);
        assert_eq!(result.refinement.cost, report.final_cost);
        assert!(!result.details.ordering.used_up);
        assert!(
            result.details.ordering.margin > 0.05,
            "{:?}",
            result.details.ordering
        );
        // The closed form alone is already close; the refinement does not make it worse.
        let (r0, t0) = pose_errors(truth, &result.initial_reference_from_target);
        assert!(r0 < 1e-2 && t0 < 0.1, "closed form {r0} {t0}");
        // Estimated thresholds reflect the 2 cm noise.
        for th in result.details.distance_thresholds {
            assert!((0.04..0.09).contains(&th), "threshold {th}");
        }
        assert!(result.rmse.iter().all(|&e| e < 0.03), "{:?}", result.rmse);
        assert!(result.covariance.is_some());
    }
}

#[test]
fn robust_loss_path_agrees_with_sufficient_statistics() {
    let truth = pose_rpy_deg(5.0, -3.0, 60.0, [0.4, -0.2, 0.1]);
    let (reference, target) = two_sensor_corner(&truth, 2000, 500, 0.02, 3);
    let plain = calibrate_planes(
        &reference,
        &target,
        &PlanarOptions {
            loss: Some(Loss::Squared),
            ..PlanarOptions::default()
        },
    )
    .unwrap();
    let huber = calibrate_planes(
        &reference,
        &target,
        &PlanarOptions {
            loss: Some(Loss::Huber { delta: 0.05 }),
            ..PlanarOptions::default()
        },
    )
    .unwrap();
    let (r, t) = pose_errors(&plain.reference_from_target, &huber.reference_from_target);
    assert!(r < 1e-3 && t < 5e-3, "{r} {t}");
    let unrefined = calibrate_planes(
        &reference,
        &target,
        &PlanarOptions {
            refine: false,
            ..PlanarOptions::default()
        },
    )
    .unwrap();
    assert!(unrefined.details.report.is_none());
    assert_eq!(unrefined.refinement.solver, Solver::ClosedForm);
    assert!(unrefined.refinement.converged && unrefined.refinement.cost.is_nan());
    assert_eq!(
        unrefined.reference_from_target,
        unrefined.initial_reference_from_target
    );
}

/// Points on three mutually orthogonal planes (a cube corner), seen from inside.
fn cube_corner(seed: u64) -> Vec<Point3<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let corner = Vector3::new(5.0, 5.0, -1.5);
    let mut pts = Vec::new();
    for axis in 0..3 {
        for _ in 0..2000 {
            let mut p = corner;
            for other in (0..3).filter(|&o| o != axis) {
                p[other] -= rng.random_range(0.0..4.0);
            }
            p[axis] += 0.01 * common::gaussian(&mut rng);
            pts.push(Point3::from(p));
        }
    }
    pts
}

#[test]
fn cube_corner_is_tied_without_up_and_the_check_or_up_breaks_the_tie() {
    let truth = pose_rpy_deg(0.0, 0.0, 15.0, [0.3, -0.2, 0.1]);
    let reference = cube_corner(1);
    let target: Vec<_> = cube_corner(2).iter().map(|p| truth.inverse() * p).collect();
    // Without `up` the three correspondences tie on the normals; each is solved and checked,
    // and seen from the sensors (not along the corner's diagonal) only the truth keeps the
    // points out of the other's free space.
    let result = calibrate_planes(&reference, &target, &PlanarOptions::default()).unwrap();
    let ordering = &result.details.ordering;
    assert!(!ordering.used_up);
    assert!(ordering.margin < 0.5f64.to_radians(), "{ordering:?}");
    let (r, t) = pose_errors(&truth, &result.reference_from_target);
    assert!(r < 2e-3 && t < 1e-2, "{r} {t}");
    // Gravity: z in the reference frame; the target's z is R^T z.
    let up_target = truth.rotation.inverse() * Vector3::z();
    let options = PlanarOptions {
        up: Some((Vector3::z(), up_target)),
        ..PlanarOptions::default()
    };
    let result = calibrate_planes(&reference, &target, &options).unwrap();
    assert!(result.details.ordering.used_up);
    let (r, t) = pose_errors(&truth, &result.reference_from_target);
    assert!(r < 2e-3 && t < 1e-2, "{r} {t}");
}

#[test]
fn parallel_planes_and_missing_planes_are_refused() {
    // Two parallel walls and a floor: not linearly independent.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let planes = [
        Plane::new(Vector3::x(), -5.0).unwrap(),
        Plane::new(Vector3::x(), -8.0).unwrap(),
        Plane::new(Vector3::z(), 1.5).unwrap(),
    ];
    let mut pts = Vec::new();
    for plane in &planes {
        let (u, v) = lidarcal::geometry::orthonormal_basis(&plane.normal);
        let origin = plane.project(&Point3::origin());
        for _ in 0..2000 {
            let a: f64 = rng.random_range(-3.0..3.0);
            let b: f64 = rng.random_range(-3.0..3.0);
            pts.push(origin + u * a + v * b);
        }
    }
    // The second wall is discarded as parallel to the first and no third plane remains.
    let err = calibrate_planes(&pts, &pts, &PlanarOptions::default()).unwrap_err();
    assert!(matches!(err, Error::Calibration { .. }), "{err}");
    assert!(err.to_string().contains("discarded as parallel"), "{err}");

    let floor: Vec<_> = pts[4000..].to_vec();
    let err = calibrate_planes(&floor, &floor, &PlanarOptions::default()).unwrap_err();
    assert!(matches!(err, Error::Calibration { .. }), "{err}");
    assert!(
        err.to_string().contains("reference cloud: only 1 plane(s)"),
        "{err}"
    );

    let few = vec![Point3::origin(); 5];
    assert!(matches!(
        calibrate_planes(&few, &few, &PlanarOptions::default()),
        Err(Error::InvalidInput(_))
    ));
}

#[test]
fn different_scenes_are_not_silently_aligned() {
    // The target sees a different corner (other angles): the planes cannot all agree.
    let truth = pose_rpy_deg(0.0, 0.0, 20.0, [0.2, 0.1, 0.0]);
    let (reference, _) = two_sensor_corner(&truth, 2000, 0, 0.01, 7);
    let target = cube_corner(9);
    match calibrate_planes(&reference, &target, &PlanarOptions::default()) {
        Err(Error::Calibration { message: m, .. }) => {
            assert!(m.contains("do not agree") || m.contains("ambiguous"), "{m}")
        }
        Err(e) => panic!("unexpected error {e}"),
        Ok(r) => panic!("calibrated different scenes: rmse {:?}", r.rmse),
    }
}
