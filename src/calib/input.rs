//! What every calibration method asks of its input, and how it names the cloud an error concerns:
//! one rule set for the corner, pole and targetless methods.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::error::{ensure_points, Error, FailureKind, Result};

/// A cloud whose nearest point is farther than this from the origin is taken not to be in its
/// sensor's frame: every LiDAR sees something (the ground, its mount) within tens of metres, and
/// the methods orient what they fit (plane normals, the sides of a pole) toward the origin as the
/// sensor, so a far origin flips them and can turn a calibration by 180 degrees while every check
/// still passes.
pub(crate) const MAX_NEAREST_RANGE: f64 = 50.0;

/// `Err(InvalidInput)` unless the `which` cloud has at least `min_points` points (`needs` says
/// what for, e.g. "three planes need"), every coordinate finite and within
/// [`MAX_COORDINATE`](crate::error::MAX_COORDINATE), and a point within [`MAX_NEAREST_RANGE`] of
/// the origin (the cloud is in its sensor's frame).
pub(crate) fn check_cloud(
    points: &[Point3<f64>],
    which: &str,
    min_points: usize,
    needs: &str,
) -> Result<()> {
    if points.len() < min_points {
        return Err(Error::InvalidInput(format!(
            "the {which} cloud has {} points; {needs} at least {min_points}",
            points.len()
        )));
    }
    ensure_points(which, points.iter())?;
    let nearest = points
        .iter()
        .map(|p| p.coords.norm())
        .fold(f64::INFINITY, f64::min);
    if nearest > MAX_NEAREST_RANGE {
        return Err(Error::InvalidInput(format!(
            "the {which} cloud's nearest point is {nearest:.1} m from the origin: each cloud must \
             be in its own sensor's frame (origin at the sensor), which a LiDAR never sees only \
             beyond {MAX_NEAREST_RANGE} m"
        )));
    }
    Ok(())
}

/// Names the `which` cloud in an error from one cloud's stage: a degenerate fit is too few
/// features there, a refusal or bad input gets the cloud as context.
pub(crate) fn with_cloud(e: Error, which: &str) -> Error {
    match e {
        Error::Degenerate(m) => {
            Error::calibration(FailureKind::TooFewFeatures, format!("{which} cloud: {m}"))
        }
        e @ Error::Calibration { .. } => e.context(&format!("{which} cloud")),
        Error::InvalidInput(m) => Error::InvalidInput(format!("{which} cloud: {m}")),
        other => other,
    }
}

/// The pose rotating by `rotation`, then translating by `t`.
pub(crate) fn isometry(rotation: &Rotation3<f64>, t: Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(rotation),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(offset: f64) -> Vec<Point3<f64>> {
        (0..20)
            .map(|i| Point3::new(offset + i as f64 * 0.1, 1.0, 0.0))
            .collect()
    }

    #[test]
    fn one_rule_set() {
        assert!(check_cloud(&cloud(0.0), "reference", 9, "three planes need").is_ok());
        let few = check_cloud(&cloud(0.0)[..5], "target", 9, "three planes need").unwrap_err();
        assert_eq!(
            few.to_string(),
            "invalid input: the target cloud has 5 points; three planes need at least 9"
        );
        let far = check_cloud(&cloud(100.0), "reference", 9, "x").unwrap_err();
        assert!(far
            .to_string()
            .contains("must be in its own sensor's frame"));
        let mut nan = cloud(0.0);
        nan[3].y = f64::NAN;
        let bad = check_cloud(&nan, "reference", 9, "x").unwrap_err();
        assert!(bad.to_string().contains("non-finite"));
    }

    #[test]
    fn errors_name_the_cloud() {
        let e = with_cloud(Error::Degenerate("one plane".into()), "target");
        assert!(matches!(
            e,
            Error::Calibration {
                kind: FailureKind::TooFewFeatures,
                ..
            }
        ));
        assert!(e.to_string().contains("target cloud: one plane"));
        let e = with_cloud(Error::InvalidInput("x".into()), "reference");
        assert_eq!(e.to_string(), "invalid input: reference cloud: x");
    }
}
