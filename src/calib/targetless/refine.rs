//! Step 5: the final ICP result, or a nearby candidate that keeps free space clearer.

use nalgebra::Isometry3;

use super::hypotheses::*;
use super::verify::*;
use crate::check::PreparedPair;
use crate::error::Result;
use crate::icp::IcpResult;

/// Verified hypotheses within [`DISTINCT_ANGLE`] / [`DISTINCT_DISTANCE`] of the winner (the same
/// answer to the ranking) that are also run through the final ICP; the one that settles elsewhere
/// and keeps the other sensor's free space clearer replaces the result (the plane refinement's
/// pose is the other candidate; see [`SCORE_MARGIN`]).
pub const NEAR_ALTERNATIVES: usize = 2;
/// Poses within this angle (radians, 0.5 deg) ...
pub const SETTLED_ANGLE: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// ... and this distance (metres) are one result: the check's default detectable error.
pub const SETTLED_DISTANCE: f64 = 0.06;
/// A candidate replaces the final ICP result when it puts fewer points into the other sensor's
/// free space and its score on the check's figures, `agreement - VIOLATION_WEIGHT violations`
/// (as in the verification), is higher by at least this much, and it passes the check.
pub const SCORE_MARGIN: f64 = 0.02;

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
pub(super) fn prefer_free_space<'a>(
    main: IcpResult,
    candidates: impl IntoIterator<Item = IcpResult>,
    prepare: impl Fn() -> Result<&'a PreparedPair>,
) -> IcpResult {
    // (passes, share of points in free space, score)
    let judge = |pose: &Isometry3<f64>| {
        prepare().and_then(|pair| pair.check(pose)).ok().map(|c| {
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
