//! Step 5 of the [module docs](super): correspondence and sign hypotheses, each solved in closed
//! form and refined on point-to-axis distances.

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3};

use super::detect::*;
use crate::error::{Error, FailureKind, Result};
use crate::geometry::Line;
use crate::kabsch::kabsch;
use crate::lm::Loss;
use crate::residuals::{Frame, LineGroup, PointToLine};

/// Two poles closer than this to parallel (radians, 2 degrees) do not determine the rotation
/// about them.
pub(super) const MIN_POLE_ANGLE: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Cap on the number of hypotheses scored (more poles than that enumerate only the first).
pub(super) const MAX_HYPOTHESES: usize = 120;
/// A further pole matches a mapped pole when their directions are within this angle (radians,
/// 5 degrees) ...
const MATCH_ANGLE: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// ... and the mapped axis passes within this distance (metres) of the pole's centre.
const MATCH_DISTANCE: f64 = 0.3;

/// One correspondence/sign hypothesis and its score.
#[derive(Debug, Clone, PartialEq)]
pub struct Hypothesis {
    /// `(reference pole, target pole, sign)` pairs; `sign = -1` flips the target direction.
    pub matches: Vec<(usize, usize, i8)>,
    /// The refined transform of this hypothesis.
    pub reference_from_target: Isometry3<f64>,
    /// RMS point-to-axis residual after refinement (metres), both directions.
    pub axis_rms: f64,
    /// Angle between the reference's and the mapped target's largest plane (radians).
    pub ground_angle: Option<f64>,
    /// Difference of their offsets (metres).
    pub ground_offset: Option<f64>,
    /// Fraction of target points landing within `overlap_distance` of a reference point.
    pub overlap: f64,
    /// The score of the module docs (lower is better).
    pub score: f64,
}

pub(super) fn angle_between_lines(a: &Line, b: &Line) -> f64 {
    a.direction.dot(&b.direction).abs().clamp(0.0, 1.0).acos()
}

/// Closed-form transform from matched axes: Kabsch on directions, least squares on offsets.
pub(super) fn closed_form(pairs: &[(Line, Line)]) -> Result<Isometry3<f64>> {
    let a: Vec<Vector3<f64>> = pairs
        .iter()
        .map(|(r, _)| r.direction.into_inner())
        .collect();
    let b: Vec<Vector3<f64>> = pairs
        .iter()
        .map(|(_, t)| t.direction.into_inner())
        .collect();
    let rotation = kabsch(&a, &b, None)?.rotation;
    let mut lhs = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for (r, t) in pairs {
        let u = r.direction.into_inner();
        let p = Matrix3::identity() - u * u.transpose();
        lhs += p;
        rhs += p * (r.point.coords - rotation * t.point.coords);
    }
    let translation = lhs.cholesky().map(|c| c.solve(&rhs)).ok_or_else(|| {
        Error::Degenerate("the matched axes are parallel: translation undetermined".into())
    })?;
    Ok(Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// Points of a pole moved toward their own axis by the radius (see the module docs).
pub(super) fn offset_points(points: &[Point3<f64>], pole: &DetectedPole) -> Vec<Point3<f64>> {
    pole.indices
        .iter()
        .filter_map(|&i| points.get(i))
        .map(|p| {
            let foot = pole.axis.closest_point(p);
            let radial = p - foot;
            let rho = radial.norm();
            if rho > 0.0 && pole.radius > 0.0 {
                p - radial * (pole.radius / rho)
            } else {
                *p
            }
        })
        .collect()
}

pub(super) struct Clouds<'a> {
    pub(super) reference: &'a [Point3<f64>],
    pub(super) target: &'a [Point3<f64>],
    pub(super) poles_ref: &'a [DetectedPole],
    pub(super) poles_tgt: &'a [DetectedPole],
}

pub(super) fn point_to_axis_problem(
    clouds: &Clouds<'_>,
    matches: &[(usize, usize, i8)],
    loss: Loss,
) -> Result<PointToLine> {
    let mut groups = Vec::with_capacity(2 * matches.len());
    for &(i, k, _) in matches {
        let (pr, pt) = (&clouds.poles_ref[i], &clouds.poles_tgt[k]);
        groups.push(LineGroup {
            line: pr.axis,
            points: offset_points(clouds.target, pt),
            frame: Frame::Target,
        });
        groups.push(LineGroup {
            line: pt.axis,
            points: offset_points(clouds.reference, pr),
            frame: Frame::Reference,
        });
    }
    PointToLine::new(groups, loss)
}

pub(super) fn axis_rms(problem: &PointToLine, pose: &Isometry3<f64>) -> f64 {
    let r = problem.residuals(pose);
    if r.is_empty() {
        return f64::INFINITY;
    }
    let sum: f64 = r.iter().map(|(v, _)| v[0] * v[0] + v[1] * v[1]).sum();
    (sum / r.len() as f64).sqrt()
}

/// Extends a base match by the poles not in it, by proximity of the mapped axes.
pub(super) fn extend_matches(
    base: &[(usize, usize, i8)],
    pose: &Isometry3<f64>,
    clouds: &Clouds<'_>,
) -> Vec<(usize, usize, i8)> {
    let mut matches = base.to_vec();
    for (i, pr) in clouds.poles_ref.iter().enumerate() {
        if matches.iter().any(|m| m.0 == i) {
            continue;
        }
        let mut best: Option<(f64, usize, i8)> = None;
        for (k, pt) in clouds.poles_tgt.iter().enumerate() {
            if matches.iter().any(|m| m.1 == k) {
                continue;
            }
            let mapped = pt.axis.transformed(pose);
            let cos = mapped.direction.dot(&pr.axis.direction);
            if cos.abs().clamp(0.0, 1.0).acos() > MATCH_ANGLE {
                continue;
            }
            let d = mapped.distance(&pr.axis.point);
            if d < MATCH_DISTANCE && best.is_none_or(|b| d < b.0) {
                best = Some((d, k, if cos < 0.0 { -1 } else { 1 }));
            }
        }
        if let Some((_, k, s)) = best {
            matches.push((i, k, s));
        }
    }
    matches
}

pub(super) fn signed_axis(pole: &DetectedPole, sign: i8) -> Line {
    if sign < 0 {
        pole.axis.reversed()
    } else {
        pole.axis
    }
}

pub(super) fn per_pole_rms(
    clouds: &Clouds<'_>,
    matches: &[(usize, usize, i8)],
    loss: Loss,
    pose: &Isometry3<f64>,
) -> Result<Vec<f64>> {
    let problem = point_to_axis_problem(clouds, matches, loss)?;
    let residuals = problem.residuals(pose);
    let mut out = Vec::with_capacity(matches.len());
    let mut start = 0;
    let sizes: Vec<usize> = problem.groups().iter().map(|g| g.points.len()).collect();
    for pair in sizes.chunks(2) {
        let n: usize = pair.iter().sum();
        let sum: f64 = residuals
            .get(start..start + n)
            .unwrap_or(&[])
            .iter()
            .map(|(v, _)| v[0] * v[0] + v[1] * v[1])
            .sum();
        out.push((sum / n.max(1) as f64).sqrt());
        start += n;
    }
    Ok(out)
}

/// The base matches of the hypotheses: the first non-parallel pair of reference poles (largest
/// first) against every ordered non-parallel pair of target poles, with the four sign
/// combinations each, at most [`MAX_HYPOTHESES`].
pub(super) fn base_matches(
    poles_ref: &[DetectedPole],
    poles_tgt: &[DetectedPole],
) -> Result<Vec<[(usize, usize, i8); 2]>> {
    // The base pair of reference poles: the first non-parallel pair, largest poles first.
    let base = base_pair(poles_ref).ok_or_else(|| {
        Error::calibration(
            FailureKind::Unobservable,
            "reference cloud: the poles are parallel",
        )
    })?;
    let mut bases = Vec::new();
    for k0 in 0..poles_tgt.len() {
        for k1 in 0..poles_tgt.len() {
            if k0 == k1
                || angle_between_lines(&poles_tgt[k0].axis, &poles_tgt[k1].axis) < MIN_POLE_ANGLE
            {
                continue;
            }
            for (s0, s1) in [(1, 1), (1, -1), (-1, 1), (-1, -1)] {
                if bases.len() < MAX_HYPOTHESES {
                    bases.push([(base.0, k0, s0), (base.1, k1, s1)]);
                }
            }
        }
    }
    Ok(bases)
}

pub(super) fn base_pair(poles: &[DetectedPole]) -> Option<(usize, usize)> {
    for i in 0..poles.len() {
        for j in i + 1..poles.len() {
            if angle_between_lines(&poles[i].axis, &poles[j].axis) >= MIN_POLE_ANGLE {
                return Some((i, j));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::se3_exp;
    use nalgebra::Vector6;

    fn pole(direction: Vector3<f64>) -> DetectedPole {
        DetectedPole {
            axis: Line::new(Point3::origin(), direction).unwrap(),
            radius: 0.05,
            rms: 0.0,
            indices: Vec::new(),
            extent: (0.0, 1.0),
        }
    }

    #[test]
    fn base_matches_pair_the_signs_of_ordered_non_parallel_target_pairs() {
        let z = pole(Vector3::z());
        let tilted = pole(Vector3::new(0.3, 0.0, 1.0));
        let reference = [z.clone(), tilted.clone()];
        let bases = base_matches(&reference, &[z.clone(), tilted.clone(), z.clone()]).unwrap();
        // Target pairs (0, 1), (1, 0), (1, 2) and (2, 1): poles 0 and 2 are parallel.
        assert_eq!(bases.len(), 16);
        assert_eq!(bases[0], [(0, 0, 1), (1, 1, 1)]);
        assert_eq!(bases[3], [(0, 0, -1), (1, 1, -1)]);
        assert_eq!(bases[4], [(0, 1, 1), (1, 0, 1)]);
        assert!(base_matches(&[z.clone(), z.clone()], &[z, tilted]).is_err());
    }

    #[test]
    fn closed_form_recovers_a_pose_from_two_axes() {
        let truth = se3_exp(&Vector6::new(0.3, -1.2, 0.4, 0.2, -0.1, 2.5));
        let a = Line::new(Point3::new(5.0, -1.0, 0.0), Vector3::new(0.1, 0.0, 1.0)).unwrap();
        let b = Line::new(Point3::new(5.5, 2.0, 0.3), Vector3::new(-0.1, 0.2, 1.0)).unwrap();
        let inv = truth.inverse();
        // Target axes through other points of the same lines.
        let ta = Line::new(
            inv * (a.point + a.direction.into_inner() * 0.7),
            inv.rotation * a.direction.into_inner(),
        )
        .unwrap();
        let tb = Line::new(
            inv * (b.point - b.direction.into_inner() * 1.3),
            inv.rotation * b.direction.into_inner(),
        )
        .unwrap();
        let got = closed_form(&[(a, ta), (b, tb)]).unwrap();
        let err = got.inverse() * truth;
        assert!(err.rotation.angle() < 1e-9 && err.translation.vector.norm() < 1e-9);
        // The global sign flip fits the axes equally well but is another rotation.
        let flipped = closed_form(&[(a, ta.reversed()), (b, tb.reversed())]).unwrap();
        let err = flipped.inverse() * truth;
        assert!((err.rotation.angle() - std::f64::consts::PI).abs() < 1e-6);
        // Parallel axes leave the translation along them free.
        assert!(closed_form(&[(a, ta), (a, ta)]).is_err());
    }
}
