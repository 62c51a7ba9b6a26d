//! The bad-input battery at the Rust API level (tests/python/test_bad_input.py has the full one
//! through Python): every case returns the right `Error` variant with a message saying what is
//! wrong, and nothing panics.

#[cfg(feature = "io")]
use lidarcal::io::pcd::PcdFormat;
use lidarcal::kabsch::kabsch;
#[cfg(any(feature = "sim", feature = "io"))]
use lidarcal::Error;
use nalgebra::{Rotation3, Vector3};
// The calibrations' bad-input cases start from simulated scenes.
#[cfg(feature = "sim")]
use {
    lidarcal::calib::planes::{calibrate_planes, PlanarOptions},
    lidarcal::calib::poles::{calibrate_poles, PoleOptions},
    lidarcal::sim::scenes::{corner_scene, poles_scene, CornerOptions, PolesOptions},
    lidarcal::sim::BeamModel,
    nalgebra::Point3,
    std::time::Duration,
};

#[cfg(feature = "sim")]
fn corner() -> (Vec<Point3<f64>>, Vec<Point3<f64>>) {
    let model = BeamModel::from_name("vlp16").unwrap();
    let scene = corner_scene(
        &model,
        &CornerOptions {
            seed: 1,
            wall_angle_deg: 75.0,
            ..CornerOptions::default()
        },
    )
    .unwrap();
    (scene.reference.positions(), scene.target.positions())
}

#[cfg(feature = "sim")]
fn message_of<T: std::fmt::Debug>(r: lidarcal::Result<T>) -> Error {
    r.expect_err("the input must be refused")
}

#[cfg(any(feature = "sim", feature = "io"))]
fn assert_variant(e: &Error, invalid_input: bool, fragment: &str) {
    let is_invalid = matches!(e, Error::InvalidInput(_));
    let is_calibration = matches!(e, Error::Calibration { .. });
    assert!(
        if invalid_input {
            is_invalid
        } else {
            is_calibration
        },
        "wrong variant: {e:?}"
    );
    assert!(e.to_string().contains(fragment), "{e}");
}

#[cfg(feature = "sim")]
#[test]
fn planes_refuse_bad_clouds_with_clear_errors() {
    let (reference, target) = corner();
    let o = PlanarOptions::default();
    let run = |r: &[Point3<f64>]| message_of(calibrate_planes(r, &target, &o));

    assert_variant(&run(&[]), true, "has 0 points");
    let mut nan = reference.clone();
    nan[7].y = f64::NAN;
    assert_variant(&run(&nan), true, "non-finite");
    let huge: Vec<_> = reference.iter().map(|p| p * 1e300).collect();
    assert_variant(&run(&huge), true, "beyond +/-1e8 m");
    let mut one_far = reference.clone();
    one_far.push(Point3::new(f64::MAX, 0.0, 0.0));
    assert_variant(&run(&one_far), true, "1 point(s) with a coordinate beyond");
    assert_variant(
        &run(&vec![Point3::new(1.0, 2.0, 3.0); 500]),
        false,
        "coincident",
    );
    let line: Vec<_> = (0..500)
        .map(|i| Point3::new(i as f64, 2.0 * i as f64, 0.5 * i as f64))
        .collect();
    assert_variant(&run(&line), false, "collinear");
    let floor: Vec<_> = (0..2500)
        .map(|i| Point3::new((i % 50) as f64 * 0.1, (i / 50) as f64 * 0.1, -1.5))
        .collect();
    assert_variant(&run(&floor), false, "only 1 plane(s)");

    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let o = PlanarOptions {
            distance_threshold: Some(bad),
            ..PlanarOptions::default()
        };
        let e = message_of(calibrate_planes(&reference, &target, &o));
        assert_variant(&e, true, "distance_threshold must be finite and positive");
    }
}

#[cfg(feature = "sim")]
#[test]
fn a_spent_time_budget_stops_the_calibration_and_a_generous_one_changes_nothing() {
    let (reference, target) = corner();
    let spent = PlanarOptions {
        time_budget: Some(Duration::from_nanos(1)),
        ..PlanarOptions::default()
    };
    let e = message_of(calibrate_planes(&reference, &target, &spent));
    assert_variant(&e, false, "time budget of 0.000 s exhausted during");
    let free = calibrate_planes(&reference, &target, &PlanarOptions::default()).unwrap();
    let generous = PlanarOptions {
        time_budget: Some(Duration::from_secs(600)),
        ..PlanarOptions::default()
    };
    let limited = calibrate_planes(&reference, &target, &generous).unwrap();
    assert_eq!(free.reference_from_target, limited.reference_from_target);
}

#[cfg(feature = "sim")]
#[test]
fn poles_refuse_mismatched_and_far_input() {
    let model = BeamModel::from_name("vlp16").unwrap();
    let scene = poles_scene(&model, &PolesOptions::default()).unwrap();
    let points = scene.reference.positions();
    let intensities: Vec<f64> = scene.reference.points.iter().map(|p| p.intensity).collect();
    let o = PoleOptions::default();
    let e = message_of(calibrate_poles(
        &points,
        &intensities[1..],
        &points,
        &intensities,
        &o,
    ));
    assert_variant(&e, true, "intensities");
    let far: Vec<_> = points.iter().map(|p| p * 1e200).collect();
    let e = message_of(calibrate_poles(
        &far,
        &intensities,
        &points,
        &intensities,
        &o,
    ));
    assert_variant(&e, true, "beyond +/-1e8 m");
    let dull = vec![10.0; points.len()];
    let e = message_of(calibrate_poles(&points, &dull, &points, &intensities, &o));
    assert_variant(&e, false, "no clear class of bright");
}

#[test]
fn kabsch_is_scale_free_even_at_the_float_limits() {
    let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
    let b = [Vector3::x(), Vector3::y(), Vector3::new(1.0, 1.0, 1.0)];
    for scale in [1e-300, 1e-150, 1.0, 1e150, 1e300] {
        let bs: Vec<_> = b.iter().map(|v| v * scale).collect();
        let a: Vec<_> = bs.iter().map(|v| r * v).collect();
        let s = kabsch(&a, &bs, None).unwrap();
        assert!(
            (s.rotation.matrix() - r.matrix()).amax() < 1e-12,
            "scale {scale}"
        );
    }
    let w = [1e300, 1e300, 1e300];
    let a: Vec<_> = b.iter().map(|v| r * v).collect();
    let s = kabsch(&a, &b, Some(&w)).unwrap();
    assert!((s.rotation.matrix() - r.matrix()).amax() < 1e-12);
}

#[cfg(feature = "io")]
#[test]
fn writers_refuse_what_they_cannot_store() {
    let dir = std::env::temp_dir().join(format!("lidarcal-bad-input-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let names: Vec<String> = ["x", "y", "z"].iter().map(|s| s.to_string()).collect();
    let e = lidarcal::io::write_points(
        &dir.join("a.ply"),
        &names,
        &[1e300, 0.0, 0.0],
        PcdFormat::Binary,
    );
    assert_variant(&e.unwrap_err(), true, "does not fit the float32");
    let dup: Vec<String> = ["x", "y", "x"].iter().map(|s| s.to_string()).collect();
    let e = lidarcal::io::write_points(
        &dir.join("a.pcd"),
        &dup,
        &[1.0, 2.0, 3.0],
        PcdFormat::Binary,
    );
    assert_variant(&e.unwrap_err(), true, "appears twice");
    // float64 .npy keeps such values.
    lidarcal::io::write_points(
        &dir.join("a.npy"),
        &names,
        &[1e300, 0.0, 0.0],
        PcdFormat::Binary,
    )
    .unwrap();
    std::fs::remove_dir_all(&dir).ok();
}
