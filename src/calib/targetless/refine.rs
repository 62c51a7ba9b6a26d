//! Step 5: refinement of the verified pose on every matched plane (Levenberg-Marquardt on the
//! planes' sufficient statistics), then the final point-to-plane ICP, or a nearby candidate that
//! keeps free space clearer.

use nalgebra::Isometry3;

use super::hypotheses::{agreeing, same_pose};
use super::options::TargetlessOptions;
use super::segment::{PlaneFeature, Prepared};
use super::verify::{Verified, Verifier, DISTINCT_ANGLE, DISTINCT_DISTANCE, VIOLATION_WEIGHT};
use crate::check::LazyCheck;
use crate::error::Result;
use crate::fit::Moments;
use crate::icp::IcpResult;
use crate::lm::{solve, LmOptions, LmReport};
use crate::residuals::{Frame, PlaneMomentGroup, PlaneMomentsProblem};

/// Verified hypotheses within [`DISTINCT_ANGLE`] / [`DISTINCT_DISTANCE`] of the winner (the same
/// answer to the ranking) that are also run through the final ICP; the one that settles elsewhere
/// and keeps the other sensor's free space clearer replaces the result (the plane refinement's
/// pose is the other candidate; see [`SCORE_MARGIN`]).
const NEAR_ALTERNATIVES: usize = 2;
/// Poses within this angle (radians, 0.5 deg) ...
const SETTLED_ANGLE: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// ... and this distance (metres) are one result: the check's default detectable error.
const SETTLED_DISTANCE: f64 = 0.06;
/// A candidate replaces the final ICP result when it puts fewer points into the other sensor's
/// free space and its score on the check's figures, `agreement - VIOLATION_WEIGHT violations`
/// (as in the verification), is higher by at least this much, and it passes the check.
const SCORE_MARGIN: f64 = 0.02;

/// The final ICP result `main`, or the first of `candidates` (other results for the same answer)
/// that settles elsewhere and fits better on the [`check`](crate::check::check)'s own figures (the
/// two clouds prepared for it once, by `prepare`): it
/// must pass the check, put fewer points into the other sensor's free space (both ways
/// together), and score `agreement - VIOLATION_WEIGHT violations` (the smaller agreement of the
/// two ways) at least [`SCORE_MARGIN`] higher.
///
/// ICP maximises agreement, not free space: on sparse 16-beam corners it settled 16-23 cm off
/// the truth along the weakest direction, a point or two of agreement above the truth but with
/// 3-13 % of the points in space the other sensor saw through (the truth: under 1 %). Both pass
/// the check, whose local re-alignment cannot see the other.
pub(super) fn prefer_free_space(
    main: IcpResult,
    candidates: impl IntoIterator<Item = IcpResult>,
    checks: &LazyCheck<'_>,
) -> IcpResult {
    // (passes, share of points in free space, score)
    let judge = |pose: &Isometry3<f64>| {
        checks
            .pair()
            .and_then(|pair| pair.check(pose))
            .ok()
            .map(|c| {
                let free = c.violations + c.reverse_violations;
                let agreement = c.agreement.min(c.reverse_agreement);
                (
                    c.failure.is_none(),
                    free,
                    agreement - VIOLATION_WEIGHT * free,
                )
            })
    };
    let mut best = main;
    let mut best_judged = None;
    // Poses already judged: the plane fit and the verified pose are one pose whenever the plane
    // refinement kept the verified pose, and a check costs as much as the ICP.
    let mut judged_poses: Vec<Isometry3<f64>> = Vec::new();
    for candidate in candidates {
        if same_pose(&candidate.pose, &best.pose, SETTLED_ANGLE, SETTLED_DISTANCE)
            || judged_poses.contains(&candidate.pose)
        {
            continue;
        }
        judged_poses.push(candidate.pose);
        if best_judged.is_none() {
            best_judged = judge(&best.pose);
        }
        let (Some((_, free, score)), Some(judged @ (passes, c_free, c_score))) =
            (best_judged, judge(&candidate.pose))
        else {
            continue;
        };
        if passes && c_free < free && c_score >= score + SCORE_MARGIN {
            best = candidate;
            best_judged = Some(judged);
        }
    }
    best
}

/// The plane refinement of a verified pose.
pub(super) struct PlaneRefinement {
    /// Matched planes `(reference, target)`: those that agree at the verified pose.
    pub(super) matches: Vec<(usize, usize)>,
    /// The refined pose, or the verified pose when the refinement moved it to another answer.
    pub(super) pose: Isometry3<f64>,
    pub(super) report: Option<LmReport>,
    pub(super) problem: Option<PlaneMomentsProblem>,
}

/// Every target plane that agrees with a reference plane at `verified` is matched, and
/// Levenberg-Marquardt minimises the symmetric point-to-plane cost over all matched planes
/// (exact per-plane sufficient statistics, [`PlaneMomentsProblem`]).
pub(super) fn refine_planes(
    reference: &Prepared,
    target: &Prepared,
    verified: &Isometry3<f64>,
    options: &TargetlessOptions,
) -> Result<PlaneRefinement> {
    let (ref_f, tgt_f) = (&reference.features, &target.features);
    let threshold = reference.threshold.max(target.threshold);
    let matches = agreeing(
        ref_f,
        tgt_f,
        verified,
        None,
        options.normal_tolerance,
        (2.0 * threshold).max(0.1),
    );
    let mut groups = Vec::with_capacity(2 * matches.len());
    let voxels = |ds: &Prepared, f: &PlaneFeature| {
        Moments::from_points(f.voxels.iter().filter_map(|&i| ds.points.get(i)))
    };
    for &(i, j) in &matches {
        groups.push(PlaneMomentGroup {
            plane: ref_f[i].plane,
            moments: voxels(target, &tgt_f[j]),
            frame: Frame::Target,
        });
        groups.push(PlaneMomentGroup {
            plane: tgt_f[j].plane,
            moments: voxels(reference, &ref_f[i]),
            frame: Frame::Reference,
        });
    }
    if groups.is_empty() {
        return Ok(PlaneRefinement {
            matches,
            pose: *verified,
            report: None,
            problem: None,
        });
    }
    let lm = LmOptions {
        cost_tolerance: super::super::planes::CALIBRATION_COST_TOLERANCE,
        ..LmOptions::default()
    };
    let problem = PlaneMomentsProblem::new(groups)?;
    let s = solve(&problem, verified, &lm)?;
    // Planes matched wrongly (parallel planes at a similar offset) can pull the pose away from
    // what the points agree on; then the verified pose is kept.
    let pose = if same_pose(&s.pose, verified, DISTINCT_ANGLE, DISTINCT_DISTANCE) {
        s.pose
    } else {
        *verified
    };
    Ok(PlaneRefinement {
        matches,
        pose,
        report: Some(s.report),
        problem: Some(problem),
    })
}

/// The final ICP from the plane-refined pose (`None` when disabled), and the pose it gives.
/// Unless the result is about to be refused as ambiguous (that refusal stands either way),
/// other results for the same answer compete on free space ([`prefer_free_space`]): the
/// verified hypotheses within [`DISTINCT_ANGLE`] / [`DISTINCT_DISTANCE`] of the verified pose
/// that the ranking never polished on their own (`contenders`, best first), carried on by the
/// final ICP; the plane fit itself; and the verified pose.
pub(super) fn final_icp(
    verifier: &Verifier<'_>,
    checks: &LazyCheck<'_>,
    plane_pose: &Isometry3<f64>,
    verified: &Isometry3<f64>,
    contenders: impl Iterator<Item = Verified>,
    options: &TargetlessOptions,
    ambiguous: bool,
) -> Result<(Isometry3<f64>, Option<IcpResult>)> {
    if !options.icp {
        return Ok((*plane_pose, None));
    }
    let main = verifier.final_icp(plane_pose)?;
    if ambiguous {
        return Ok((main.pose, Some(main)));
    }
    let near: Vec<Isometry3<f64>> = contenders
        .map(|v| v.pose)
        .filter(|p| {
            same_pose(p, verified, DISTINCT_ANGLE, DISTINCT_DISTANCE)
                && !same_pose(p, verified, SETTLED_ANGLE, SETTLED_DISTANCE)
        })
        .take(NEAR_ALTERNATIVES)
        .collect();
    let settled = near
        .iter()
        .filter_map(|start| verifier.final_icp(start).ok())
        .filter(|r| r.converged);
    // The plane fit itself: on sparse 16-beam corners the final ICP pulled the exact pose of the
    // plane refinement 16-18 cm along the weakest direction (neighbouring scan rings taken for
    // the surface), where 3-13 % of the points land in the other's free space.
    let plane = verifier.fit_at(plane_pose).ok();
    // And the verified pose: matched planes that are not the same surface (a box top for the
    // ground) can pull the plane refinement, and ICP after it, off a verified pose that kept
    // free space clear.
    let verified_pose = verifier.fit_at(verified).ok();
    let chosen = prefer_free_space(main, settled.chain(plane).chain(verified_pose), checks);
    Ok((chosen.pose, Some(chosen)))
}
