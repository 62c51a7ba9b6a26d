//! `calib::method` and `calib::rig`: `Method::Auto` on the three kinds of simulated scene, and
//! `calibrate_rig` on a street seen by a roof unit and two tilted side units.

use lidarcal::calib::{calibrate, Cloud, Method, MethodOptions};
use lidarcal::Error;
use nalgebra::Point3;
// All but the featureless-ground case are simulated scenes.
#[cfg(feature = "sim")]
use {
    lidarcal::calib::{calibrate_rig, RigOptions},
    lidarcal::geometry::pose_error as geometry_pose_error,
    lidarcal::sim::beams::{BeamModel, Preset},
    lidarcal::sim::scenes::{
        corner_scene, poles_scene, street_scene, CornerOptions, PolesOptions, Side, StreetOptions,
    },
    lidarcal::sim::Scan,
};

/// (rotation error in degrees, translation error in metres).
#[cfg(feature = "sim")]
fn pose_error(a: &nalgebra::Isometry3<f64>, b: &nalgebra::Isometry3<f64>) -> (f64, f64) {
    let (angle, dist) = geometry_pose_error(a, b);
    (angle.to_degrees(), dist)
}

#[cfg(feature = "sim")]
fn street(side: Side) -> lidarcal::sim::scenes::Scene {
    street_scene(&StreetOptions {
        side,
        ..StreetOptions::default()
    })
    .unwrap()
}

#[cfg(feature = "sim")]
fn intensities(scan: &Scan) -> Vec<f64> {
    scan.points.iter().map(|p| p.intensity).collect()
}

#[cfg(feature = "sim")]
#[test]
fn auto_picks_the_corner_method_at_a_corner_and_targetless_on_a_street() {
    let model = BeamModel::preset(Preset::Vlp16);
    let corner = corner_scene(&model, &CornerOptions::default()).unwrap();
    let (r, t) = (corner.reference.positions(), corner.target.positions());
    // A 90-degree corner is a cube corner: the corner method needs the up direction (both units
    // are within a few degrees of level).
    let mut options = MethodOptions::default();
    options.planes.up = Some((nalgebra::Vector3::z(), nalgebra::Vector3::z()));
    let c = calibrate(Cloud::new(&r), Cloud::new(&t), Method::Auto, &options).unwrap();
    let (angle, dist) = pose_error(&corner.reference_from_target, &c.reference_from_target);
    assert_eq!(c.method(), Method::Planes, "{angle} {dist}");
    assert!(angle < 0.1 && dist < 0.02, "{angle} {dist}");

    let s = street(Side::Left);
    let (r, t) = (s.reference.positions(), s.target.positions());
    let c = calibrate(
        Cloud::new(&r),
        Cloud::new(&t),
        Method::Auto,
        &MethodOptions::default(),
    )
    .unwrap();
    let (angle, dist) = pose_error(&s.reference_from_target, &c.reference_from_target);
    assert_eq!(c.method(), Method::Targetless);
    assert!(angle < 0.1 && dist < 0.02, "{angle} {dist}");
    assert!(c.covariance.is_some());
}

#[cfg(feature = "sim")]
#[test]
fn auto_tries_the_poles_only_with_intensity() {
    let model = BeamModel::preset(Preset::Vlp16);
    let scene = poles_scene(&model, &PolesOptions::default()).unwrap();
    let (r, t) = (scene.reference.positions(), scene.target.positions());
    let (ri, ti) = (intensities(&scene.reference), intensities(&scene.target));
    let with = calibrate(
        Cloud::with_intensity(&r, &ri).unwrap(),
        Cloud::with_intensity(&t, &ti).unwrap(),
        Method::Auto,
        &MethodOptions::default(),
    );
    let without = calibrate(
        Cloud::new(&r),
        Cloud::new(&t),
        Method::Auto,
        &MethodOptions::default(),
    );
    let poles = with.unwrap();
    assert_eq!(poles.method(), Method::Poles);
    let (angle, dist) = pose_error(&scene.reference_from_target, &poles.reference_from_target);
    // The pole method's usual accuracy on these scenes (tests/calib_poles.rs: median 0.29 deg /
    // 2 cm); this scene gives 0.25 deg / 2.0 cm.
    assert!(
        angle < 0.5 && dist < 0.05,
        "{:?} {angle} {dist}",
        poles.method()
    );
    match without {
        Ok(c) => assert_ne!(c.method(), Method::Poles),
        Err(Error::Calibration { message: m, .. }) => {
            assert!(m.contains("planes:") && m.contains("targetless:") && !m.contains("poles:"))
        }
        Err(e) => panic!("{e}"),
    }
    // Forcing the poles without intensity is malformed input, not a failed calibration.
    assert!(matches!(
        calibrate(Cloud::new(&r), Cloud::new(&t), Method::Poles, &MethodOptions::default()),
        Err(Error::InvalidInput(m)) if m.contains("intensity")
    ));
}

#[test]
fn auto_lists_every_reason_and_passes_malformed_input_through() {
    // Flat ground only: no corner, no plane pair.
    let ground: Vec<Point3<f64>> = (0..4000)
        .map(|i| {
            let (x, y) = ((i % 80) as f64 * 0.2 - 8.0, (i / 80) as f64 * 0.2 - 5.0);
            Point3::new(x, y, -1.8 + 0.002 * ((i * 7919) % 11) as f64)
        })
        .collect();
    match calibrate(
        Cloud::new(&ground),
        Cloud::new(&ground),
        Method::Auto,
        &MethodOptions::default(),
    ) {
        Err(Error::Calibration { message: m, .. }) => {
            assert!(m.starts_with("no method calibrated this pair"), "{m}");
            assert!(m.contains("planes:") && m.contains("targetless:"), "{m}");
        }
        other => panic!("{other:?}"),
    }
    let few = [Point3::origin(); 5];
    assert!(matches!(
        calibrate(
            Cloud::new(&few),
            Cloud::new(&ground),
            Method::Auto,
            &MethodOptions::default()
        ),
        Err(Error::InvalidInput(_))
    ));
    assert!(Cloud::with_intensity(&few, &[1.0; 4]).is_err());
    let bad = MethodOptions {
        agreement_distance: f64::NAN,
        ..MethodOptions::default()
    };
    assert!(matches!(
        calibrate(Cloud::new(&ground), Cloud::new(&ground), Method::Auto, &bad),
        Err(Error::InvalidInput(m)) if m.contains("agreement_distance")
    ));
}

#[cfg(feature = "sim")]
#[test]
fn rig_of_a_roof_unit_and_two_side_units() {
    let (left, right) = (street(Side::Left), street(Side::Right));
    let reference = left.reference.positions();
    let (l, r) = (left.target.positions(), right.target.positions());
    let options = RigOptions {
        method: Method::Targetless,
        ..RigOptions::default()
    };
    let rig = calibrate_rig(
        Cloud::new(&reference),
        &[("left", Cloud::new(&l)), ("right", Cloud::new(&r))],
        &options,
    )
    .unwrap();
    for (name, scene) in [("left", &left), ("right", &right)] {
        let pose = rig.transform(name).unwrap();
        let (angle, dist) = pose_error(&scene.reference_from_target, pose);
        assert!(angle < 0.1 && dist < 0.02, "{name} {angle} {dist}");
    }
    assert_eq!(rig.direct.len(), 2);
    assert!(rig.unconnected.is_empty());
    let pairs: Vec<(&str, &str)> = rig
        .edges
        .iter()
        .map(|e| (e.a.as_str(), e.b.as_str()))
        .collect();
    assert!(pairs.contains(&("reference", "left")) && pairs.contains(&("reference", "right")));
    for e in &rig.edges {
        assert_eq!(e.method, Method::Targetless);
        assert!(e.rotation_residual_deg.is_finite() && e.translation_residual_m < 0.05);
    }
    // A left-right edge is either kept (then in the graph) or reported with its reason.
    let kept = pairs.contains(&("left", "right"));
    let failed = rig.failures.iter().any(|f| f.a == "left" && f.b == "right");
    assert!(kept != failed, "{:?}", rig.failures);
    // The pose graph settled, and never raised the cost of the start.
    let report = rig.pose_graph;
    assert!(report.converged, "{report:?}");
    assert!(report.iterations > 0 && report.final_cost <= report.initial_cost);
}

#[cfg(feature = "sim")]
#[test]
fn rig_argument_errors() {
    let s = street(Side::Left);
    let (reference, target) = (s.reference.positions(), s.target.positions());
    let cloud = Cloud::new(&target);
    let options = RigOptions::default();
    for (targets, needle) in [
        (vec![], "targets is empty"),
        (vec![("reference", cloud)], "reserved"),
        (
            vec![("a", cloud), ("a", cloud)],
            "two targets are named \"a\"",
        ),
    ] {
        match calibrate_rig(Cloud::new(&reference), &targets, &options) {
            Err(Error::InvalidInput(m)) => assert!(m.contains(needle), "{m}"),
            other => panic!("{needle}: {other:?}"),
        }
    }
    // Bad pose-graph options are refused before any calibration runs.
    let mut bad = RigOptions::default();
    bad.pose_graph.jacobian_step = 0.0;
    match calibrate_rig(Cloud::new(&reference), &[("left", cloud)], &bad) {
        Err(Error::InvalidInput(m)) => assert!(m.contains("jacobian_step"), "{m}"),
        other => panic!("jacobian_step: {other:?}"),
    }
}
