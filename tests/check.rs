//! `lidarcal::check`: verdicts on simulated scenes with known truth, the gate `certify`, bad input.
#![cfg(feature = "sim")]

use lidarcal::check::{certify, check, CheckOptions, PreparedPair, Verdict};
use lidarcal::sim::scenes::{corridor_scene, street_scene, StreetOptions};
use lidarcal::{Error, FailureKind};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// The default simulated street: reference and target points and the true `reference_from_target`.
fn default_street() -> (Vec<Point3<f64>>, Vec<Point3<f64>>, Isometry3<f64>) {
    let scene = street_scene(&StreetOptions::default()).unwrap();
    (
        scene.reference.positions(),
        scene.target.positions(),
        scene.reference_from_target,
    )
}

#[test]
fn the_truth_is_consistent_and_gross_errors_are_not() {
    let (reference, target, truth) = default_street();
    let options = CheckOptions::default();
    let report = check(&reference, &target, &truth, &options).unwrap();
    assert_eq!(report.verdict, Verdict::Consistent, "{report}");
    assert!(report.failure.is_none());
    assert!(report.correction_translation < 0.02 && report.correction_rotation < 0.002);
    assert!(certify(&reference, &target, &truth, &options).is_ok());

    let turned = truth * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 3.0);
    let shifted = Translation3::new(0.0, 0.0, 0.25) * truth;
    let tilted = truth * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 2f64.to_radians());
    for wrong in [turned, shifted, tilted] {
        let report = check(&reference, &target, &wrong, &options).unwrap();
        assert_ne!(report.verdict, Verdict::Consistent, "{report}");
        let err = certify(&reference, &target, &wrong, &options).unwrap_err();
        assert!(err.kind().is_some(), "{err}");
    }
}

#[test]
fn a_prepared_pair_reports_what_check_reports_at_every_pose() {
    let (reference, target, truth) = default_street();
    let options = CheckOptions::default();
    let pair = PreparedPair::new(&reference, &target, &options).unwrap();
    let shifted = Translation3::new(0.0, 0.0, 0.25) * truth;
    for pose in [truth, shifted, truth] {
        let (once, alone) = (
            pair.check(&pose).unwrap(),
            check(&reference, &target, &pose, &options).unwrap(),
        );
        assert_eq!(once.verdict, alone.verdict);
        assert_eq!(once.reason, alone.reason);
        assert_eq!(once.aligned, alone.aligned);
        assert_eq!(once.agreement.to_bits(), alone.agreement.to_bits());
        assert_eq!(once.violations.to_bits(), alone.violations.to_bits());
        assert_eq!(once.noise.to_bits(), alone.noise.to_bits());
    }
    assert!(pair.certify(&truth).is_ok());
    assert!(pair.certify(&shifted).unwrap_err().kind().is_some());
    let nan = Isometry3::translation(f64::NAN, 0.0, 0.0);
    assert!(matches!(pair.check(&nan), Err(Error::InvalidInput(_))));
}

#[test]
fn a_pose_whose_neighbour_fits_more_points_is_flagged_by_its_agreement_gain() {
    let (reference, target, truth) = default_street();
    let options = CheckOptions::default();
    let at_truth = check(&reference, &target, &truth, &options).unwrap();
    assert!(
        at_truth.agreement_gain.abs() < 0.02,
        "{}",
        at_truth.agreement_gain
    );
    // 12 cm up: the ground of one scan floats above the other's; the re-alignment puts it back
    // and agrees on many more points.
    let raised = Translation3::new(0.0, 0.0, 0.12) * truth;
    let report = check(&reference, &target, &raised, &options).unwrap();
    assert!(report.agreement_gain > 0.1, "{report}");
    // With the gain test alone (every other test switched off) the pose is still flagged.
    let gain_only = CheckOptions {
        rotation_tolerance: 1.0,
        translation_tolerance: 10.0,
        weak_rotation_tolerance: 1.0,
        weak_translation_tolerance: 10.0,
        ..options
    };
    let report = check(&reference, &target, &raised, &gain_only).unwrap();
    assert_eq!(report.verdict, Verdict::Inconsistent, "{report}");
    assert!(
        report.reason.contains("fits clearly more points"),
        "{report}"
    );
    let relaxed = CheckOptions {
        max_agreement_gain: 1.0,
        ..gain_only
    };
    let report = check(&reference, &target, &raised, &relaxed).unwrap();
    assert_eq!(report.verdict, Verdict::Consistent, "{report}");
}

#[test]
fn a_corridor_is_unverifiable_and_certify_says_unobservable() {
    let scene = corridor_scene(0).unwrap();
    let (reference, target) = (scene.reference.positions(), scene.target.positions());
    let options = CheckOptions::default();
    let report = check(&reference, &target, &scene.reference_from_target, &options).unwrap();
    assert_eq!(report.verdict, Verdict::Unverifiable, "{report}");
    assert_eq!(report.failure, Some(FailureKind::Unobservable));
    let err = certify(&reference, &target, &scene.reference_from_target, &options).unwrap_err();
    assert_eq!(err.kind(), Some(FailureKind::Unobservable), "{err}");
}

#[test]
fn clouds_that_do_not_overlap_are_unverifiable() {
    let scene = street_scene(&StreetOptions::default()).unwrap();
    let (reference, target) = (scene.reference.positions(), scene.target.positions());
    let far = Translation3::new(500.0, 0.0, 0.0) * scene.reference_from_target;
    let report = check(&reference, &target, &far, &CheckOptions::default()).unwrap();
    assert_eq!(report.verdict, Verdict::Unverifiable);
    assert_eq!(report.failure, Some(FailureKind::TooFewFeatures));
}

#[test]
fn bad_input_is_an_error_not_a_verdict() {
    let scene = street_scene(&StreetOptions::default()).unwrap();
    let (reference, mut target) = (scene.reference.positions(), scene.target.positions());
    let options = CheckOptions::default();
    let pose = Isometry3::identity();
    assert!(matches!(
        check(&reference[..5], &target, &pose, &options),
        Err(Error::InvalidInput(_))
    ));
    let bad = CheckOptions {
        min_agreement: 1.5,
        ..options
    };
    assert!(matches!(
        check(&reference, &target, &pose, &bad),
        Err(Error::InvalidInput(m)) if m.contains("min_agreement")
    ));
    let nan = Isometry3::translation(f64::NAN, 0.0, 0.0);
    assert!(matches!(
        check(&reference, &target, &nan, &options),
        Err(Error::InvalidInput(_))
    ));
    target[7].x = f64::INFINITY;
    assert!(matches!(
        check(&reference, &target, &pose, &options),
        Err(Error::InvalidInput(_))
    ));
}
