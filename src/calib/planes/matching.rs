//! Steps 3-6 of the pipeline: the extracted planes checked for conditioning, put in right-handed
//! order, matched between the clouds (Kabsch on the normals) and the closed-form pose from the
//! corners.

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

use super::gates::check_widths;
use super::{
    isometry, Ordering, PlanarOptions, AMBIGUITY_RMS, MIN_NORMAL_SINGULAR_VALUE,
    UP_TIE_BREAK_MARGIN,
};
use crate::error::{Error, FailureKind, Result};
use crate::geometry::Plane;
use crate::kabsch::kabsch;
use crate::ransac::plane::ExtractedPlane;

fn normals(planes: &[Plane; 3]) -> [Vector3<f64>; 3] {
    planes.map(|p| p.normal.into_inner())
}

pub(super) fn check_conditioning(planes: &[Plane; 3], which: &str) -> Result<()> {
    let [a, b, c] = normals(planes);
    let m = Matrix3::from_columns(&[a, b, c]);
    let smallest = m.singular_values().min();
    if smallest < MIN_NORMAL_SINGULAR_VALUE {
        let angle =
            |u: &Vector3<f64>, v: &Vector3<f64>| u.dot(v).abs().min(1.0).acos().to_degrees();
        let closest = angle(&a, &b).min(angle(&a, &c)).min(angle(&b, &c));
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "the three planes of the {which} cloud are not linearly independent: smallest singular \
             value of the normals {smallest:.3} < {MIN_NORMAL_SINGULAR_VALUE} (two planes are \
             {closest:.1} deg from parallel, or all three share a direction)"
        ),
        ));
    }
    Ok(())
}

/// The point where three planes meet.
pub(super) fn corner(planes: &[Plane; 3]) -> Result<Point3<f64>> {
    Plane::common_point(planes).ok_or_else(|| {
        Error::calibration(
            FailureKind::TooFewFeatures,
            "the three planes do not meet in a point",
        )
    })
}

/// Puts three planes (with their inliers) in right-handed order: `(n0 x n1) . n2 > 0`.
pub(super) fn right_handed(mut planes: Vec<ExtractedPlane>) -> Vec<ExtractedPlane> {
    if planes.len() == 3 {
        let (a, b, c) = (
            planes[0].plane.normal,
            planes[1].plane.normal,
            planes[2].plane.normal,
        );
        if a.cross(&b).dot(&c) < 0.0 {
            planes.swap(1, 2);
        }
    }
    planes
}

/// Matches the planes and returns the chosen cyclic shift with its rotation. `tie`, when given,
/// takes that shift if it ties with the best (within [`AMBIGUITY_RMS`]), without `up`: the
/// next-plane search tries each of a tie's shifts and lets the check judge them; a shift that does
/// not tie is `Err(Ambiguous)` too, as the tie it was asked to resolve is not there.
pub(super) fn match_planes(
    reference: &[Plane; 3],
    target: &[Plane; 3],
    up: Option<(Vector3<f64>, Vector3<f64>)>,
    tie: Option<usize>,
) -> Result<(Ordering, nalgebra::Rotation3<f64>)> {
    let a = normals(reference);
    let b = normals(target);
    let mut rotations = Vec::with_capacity(3);
    let mut scores = [0.0; 3];
    for (k, score) in scores.iter_mut().enumerate() {
        let shifted = [b[k % 3], b[(k + 1) % 3], b[(k + 2) % 3]];
        let solution = kabsch(&a, &shifted, None)?;
        *score = (solution.residual / 3.0).sqrt();
        rotations.push(solution.rotation);
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| scores[i].total_cmp(&scores[j]));
    let margin = scores[order[1]] - scores[order[0]];
    let mut chosen = order[0];
    let mut used_up = false;
    if let Some(k) = tie {
        if margin >= AMBIGUITY_RMS || k >= 3 || scores[k] - scores[order[0]] >= AMBIGUITY_RMS {
            return Err(Error::calibration(
                FailureKind::Ambiguous,
                format!("shift {k} does not tie with the best ordering"),
            ));
        }
        chosen = k;
    } else if margin < AMBIGUITY_RMS {
        let Some((up_ref, up_tgt)) = up else {
            return Err(Error::calibration(
                FailureKind::Ambiguous,
                format!(
                    "ambiguous plane correspondence: two orderings fit the normals equally well \
                 (RMS misalignment {:.3} and {:.3} deg; the corner's angles are nearly equal, \
                 as in a cube corner); pass `up`, the gravity direction in each sensor's frame, \
                 to break the tie",
                    scores[order[0]].to_degrees(),
                    scores[order[1]].to_degrees()
                ),
            ));
        };
        if up_ref.norm() == 0.0 || up_tgt.norm() == 0.0 {
            return Err(Error::InvalidInput("up vectors must be non-zero".into()));
        }
        let candidates: Vec<usize> = order
            .iter()
            .copied()
            .filter(|&k| scores[k] - scores[order[0]] < AMBIGUITY_RMS)
            .collect();
        let up_error = |k: usize| {
            let mapped = rotations[k] * up_tgt.normalize();
            mapped.dot(&up_ref.normalize()).clamp(-1.0, 1.0).acos()
        };
        let mut by_up = candidates.clone();
        by_up.sort_by(|&i, &j| up_error(i).total_cmp(&up_error(j)));
        if by_up.len() > 1 && up_error(by_up[1]) - up_error(by_up[0]) < UP_TIE_BREAK_MARGIN {
            return Err(Error::calibration(
                FailureKind::Ambiguous,
                format!(
                    "ambiguous plane correspondence, and `up` does not break the tie (up errors \
                 {:.1} and {:.1} deg)",
                    up_error(by_up[0]).to_degrees(),
                    up_error(by_up[1]).to_degrees()
                ),
            ));
        }
        chosen = by_up[0];
        used_up = true;
    }
    let rotation = rotations[chosen];
    Ok((
        Ordering {
            scores,
            chosen,
            margin,
            used_up,
        },
        rotation,
    ))
}

pub(super) fn to_array<T: Clone>(v: &[T]) -> Result<[T; 3]> {
    match v {
        [a, b, c] => Ok([a.clone(), b.clone(), c.clone()]),
        _ => Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!("expected 3 planes, got {}", v.len()),
        )),
    }
}

/// The planes of the two clouds, checked (wide enough, independent normals) and matched: the
/// target's in the order of the reference's.
pub(super) struct Matched<'a> {
    pub(super) planes_ref: [Plane; 3],
    /// The target's planes in matched order.
    pub(super) planes_tgt: [Plane; 3],
    /// The target's extracted planes in matched order.
    pub(super) matched_tgt: Vec<&'a ExtractedPlane>,
    pub(super) ordering: Ordering,
    /// The rotation of the chosen ordering (Kabsch on the normals).
    pub(super) rotation: nalgebra::Rotation3<f64>,
}

/// Checks the extracted planes of both clouds and matches them ([`match_planes`], `tie` as
/// there).
pub(super) fn match_found<'a>(
    reference: &[Point3<f64>],
    target: &[Point3<f64>],
    found_ref: &[ExtractedPlane],
    found_tgt: &'a [ExtractedPlane],
    options: &PlanarOptions,
    tie: Option<usize>,
) -> Result<Matched<'a>> {
    for (points, found, which) in [
        (reference, found_ref, "reference"),
        (target, found_tgt, "target"),
    ] {
        check_widths(points, found, options.min_plane_width, which)?;
    }
    let planes_ref = to_array(&found_ref.iter().map(|p| p.plane).collect::<Vec<_>>())?;
    let planes_tgt_rh = to_array(&found_tgt.iter().map(|p| p.plane).collect::<Vec<_>>())?;
    check_conditioning(&planes_ref, "reference")?;
    check_conditioning(&planes_tgt_rh, "target")?;
    let (ordering, rotation) = match_planes(&planes_ref, &planes_tgt_rh, options.up, tie)?;
    let k = ordering.chosen;
    let matched_tgt: Vec<&ExtractedPlane> = (0..3).map(|i| &found_tgt[(i + k) % 3]).collect();
    let planes_tgt = [
        matched_tgt[0].plane,
        matched_tgt[1].plane,
        matched_tgt[2].plane,
    ];
    Ok(Matched {
        planes_ref,
        planes_tgt,
        matched_tgt,
        ordering,
        rotation,
    })
}

/// The closed-form pose: the matched rotation, and the translation that maps the target's corner
/// (the planes' intersection) onto the reference's. Returns `([reference corner, target corner],
/// pose)`.
pub(super) fn closed_form(matched: &Matched<'_>) -> Result<([Point3<f64>; 2], Isometry3<f64>)> {
    let rotation = matched.rotation;
    let corner_ref = corner(&matched.planes_ref)?;
    let corner_tgt = corner(&matched.planes_tgt)?;
    let initial = isometry(&rotation, corner_ref.coords - rotation * corner_tgt.coords);
    Ok(([corner_ref, corner_tgt], initial))
}
