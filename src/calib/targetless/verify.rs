//! Step 4: verification of the hypotheses (screening ICP and score, then a longer ICP and the full
//! score) and the choice of the best pose and its closest distinct rival.

use std::sync::Arc;

use nalgebra::{Isometry3, Point3};

use super::hypotheses::{same_pose, Candidate};
use super::segment::PlaneFeature;
use crate::error::Result;
use crate::icp::{
    point_to_plane_fit_on_planes, point_to_plane_icp, point_to_plane_icp_on_planes, IcpOptions,
    IcpResult, PlaneNormals, SurfaceCloud,
};
use crate::visibility::RangeImage;

/// Two verified hypotheses further apart than this rotation (radians, 2 degrees) ...
pub(super) const DISTINCT_ANGLE: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// ... or this translation (metres) are different answers (for the second-best score).
pub(super) const DISTINCT_DISTANCE: f64 = 0.3;
/// A verified target point agrees when a reference point lies within this distance (metres).
pub(super) const VERIFY_DISTANCE: f64 = 0.25;
/// Target points (at most, by a fixed stride) scored in the verification.
const VERIFY_SAMPLES: usize = 800;
/// Reference points (at most, by a fixed stride) checked against the target's free space.
const VERIFY_REFERENCE_SAMPLES: usize = 2000;
/// Weight of the free-space violations in the verification score: `score = agreement -
/// VIOLATION_WEIGHT (v_target + v_reference)`, each `v` the share of a cloud's checked points that
/// fall into space the other sensor saw through ([`crate::visibility`]).
pub(super) const VIOLATION_WEIGHT: f64 = 3.0;
/// Pairs of the best pose and a close contender polished by the full ICP before the result is
/// called ambiguous or not (see the verification in [`calibrate_targetless`](super::calibrate_targetless)).
pub(super) const MAX_POLISHED: usize = 4;
/// A challenger (beyond `max_translation`) makes the result ambiguous when it scores at least
/// this share of the best (a pose within range does from [`AMBIGUITY_RATIO`]).
pub(super) const CHALLENGER_AMBIGUITY_RATIO: f64 = 0.9;
/// Target points (at most, by a fixed stride) scored in the screening of every hypothesis.
const SCREEN_SAMPLES: usize = 300;
/// Reference points (at most, by a fixed stride) checked against the target's free space in the
/// screening.
const SCREEN_REFERENCE_SAMPLES: usize = 700;
/// Distinct hypotheses (best screening scores) that go on to the full verification.
pub(super) const SCREEN_KEEP: usize = 12;
/// The result is ambiguous when a distinct pose scores at least this share of the best. At 0.8,
/// two adversarial rooms and corners whose runner-up scored 78-79 % came back 107-120 degrees
/// off; the real pairs' runner-ups score at most 70 %.
pub(super) const AMBIGUITY_RATIO: f64 = 0.75;

/// Options of the quick ICP of the screening (the first stage of the verification), for a
/// plane-pair hypothesis or a ground-sweep one (wider first distance: the start is up to half a
/// step of yaw and the in-plane translation away).
pub(super) fn screen_icp_options(sweep: bool) -> IcpOptions {
    IcpOptions {
        max_distance: if sweep { 2.0 } else { 1.0 },
        min_distance: 0.5,
        shrink: 0.7,
        max_iterations: if sweep { 7 } else { 3 },
        samples: 300,
        step_tolerance: 1e-4,
    }
}

/// Options of the short ICP that continues from the screened pose of each verified hypothesis.
pub(super) fn verify_icp_options() -> IcpOptions {
    IcpOptions {
        max_distance: 0.5,
        min_distance: 0.3,
        shrink: 0.7,
        max_iterations: 6,
        samples: 400,
        step_tolerance: 1e-4,
    }
}

/// A hypothesis after its short ICP, with its verification (see [`VIOLATION_WEIGHT`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Verified {
    pub(super) pose: Isometry3<f64>,
    pub(super) agreement: f64,
    pub(super) violations: [f64; 2],
    pub(super) score: f64,
}

/// The sampling variance of `v.score` verified on `samples` (target and reference points): the
/// agreement and the target's violations are shares of the same target points (a point agrees or
/// violates, not both), the reference's violations a share of the reference points.
pub(super) fn score_variance(v: &Verified, samples: [usize; 2]) -> f64 {
    let [n_target, n_reference] = samples.map(|n| n.max(1) as f64);
    let a = v.agreement.clamp(0.0, 1.0);
    let [t, r] = v.violations.map(|x| x.clamp(0.0, 1.0));
    let w = VIOLATION_WEIGHT;
    (a * (1.0 - a) + w * w * t * (1.0 - t) + 2.0 * w * a * t) / n_target
        + w * w * r * (1.0 - r) / n_reference
}

/// Indices and scores of the verified hypotheses, best first (ties keep the enumeration order).
pub(super) fn rank(verified: &[Option<Verified>]) -> Vec<(usize, f64)> {
    let mut ranked: Vec<(usize, f64)> = verified
        .iter()
        .enumerate()
        .filter_map(|(k, v)| v.map(|v| (k, v.score)))
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    ranked
}

/// The best of verified poses (`pool`, best first, each with its hypothesis) and its closest
/// distinct rival. A close runner-up may be the same answer, not polished as far: both get the
/// full ICP (`polish`) and are scored again before the result is called ambiguous. When the two
/// settle on one pose, the next distinct contender is polished in turn (up to [`MAX_POLISHED`]):
/// in a street turned by half a turn the two best hypotheses can be the same flip 0.4 m apart,
/// and the truth beyond max_translation only third. A best pose beyond max_translation (not
/// `within`) is always polished against the best pose within range, and only poses within range
/// challenge it.
pub(super) fn settle_best(
    pool: &[(Candidate, Verified)],
    within: &impl Fn(&Verified) -> bool,
    polish: &impl Fn(&Verified) -> Option<Verified>,
) -> Option<(Candidate, Verified, Option<Verified>)> {
    let &(winner, mut top) = pool.first()?;
    let mut top_polished = None;
    let mut runner_up = None;
    let mut polished_pairs = 0;
    for &(_, v) in pool {
        // Against a challenger that screened best, the best pose within range.
        let eligible = within(&v) || (within(&top) && v.score >= AMBIGUITY_RATIO * top.score);
        if !eligible || same_pose(&v.pose, &top.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE) {
            continue;
        }
        let close = !within(&top) || v.score >= AMBIGUITY_RATIO * top.score;
        if !close || polished_pairs == MAX_POLISHED {
            runner_up = Some(v);
            break;
        }
        polished_pairs += 1;
        let a = top_polished.or_else(|| polish(&top));
        match (a, polish(&v)) {
            (Some(a), Some(b))
                if same_pose(&a.pose, &b.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE) =>
            {
                top = if b.score > a.score { b } else { a };
                top_polished = Some(top);
            }
            (Some(a), Some(b)) => {
                (top, runner_up) = if b.score > a.score {
                    (b, Some(a))
                } else {
                    (a, Some(b))
                };
                break;
            }
            (Some(a), None) => {
                (top, runner_up) = (a, Some(v));
                break;
            }
            (None, Some(b)) => {
                top = b;
                top_polished = Some(b);
            }
            (None, None) => {
                runner_up = Some(v);
                break;
            }
        }
    }
    Some((winner, top, runner_up))
}

/// Every `len / count`-th point of `points` (a fixed stride): about `count` of them.
pub(super) fn stride_sample(points: &[Point3<f64>], count: usize) -> Vec<Point3<f64>> {
    let stride = points.len().div_ceil(count).max(1);
    points.iter().step_by(stride).copied().collect()
}

/// Sampled points a pose is scored on: target points (agreement with the reference, and the
/// reference's free space) and reference points (the target's free space).
pub(super) type Samples = [Vec<Point3<f64>>; 2];

/// Scores poses of the (downsampled) target against the (downsampled) reference: the reference's
/// surface for the agreement and ICP, both clouds' range images for the free space, and the
/// points sampled for the screening (`quick`) and for the full verification (`full`).
pub(super) struct Verifier<'a> {
    surface: Arc<SurfaceCloud>,
    /// The reference's planes, for the normals of its scan-line points in the final ICP.
    planes: PlaneNormals,
    target: &'a [Point3<f64>],
    reference_image: RangeImage,
    target_image: RangeImage,
    quick: Samples,
    full: Samples,
    final_icp: IcpOptions,
}

impl<'a> Verifier<'a> {
    /// Indexes `reference` (with its `planes`, indices into it) and images both clouds;
    /// `final_icp` is the ICP of [`polish`](Self::polish) and of the final refinement.
    pub(super) fn new(
        reference: &[Point3<f64>],
        planes: &[PlaneFeature],
        target: &'a [Point3<f64>],
        final_icp: IcpOptions,
    ) -> Result<Self> {
        // Three independent builds, side by side (the errors in this order).
        let (surface, (reference_image, target_image)) = crate::join(
            || SurfaceCloud::new(reference.to_vec()).map(Arc::new),
            || {
                crate::join(
                    || RangeImage::new(reference, RangeImage::DEFAULT_RESOLUTION),
                    || RangeImage::new(target, RangeImage::DEFAULT_RESOLUTION),
                )
            },
        );
        let (surface, reference_image, target_image) = (surface?, reference_image?, target_image?);
        let planes = PlaneNormals::new(
            &surface,
            planes
                .iter()
                .map(|f| (f.plane.normal.into_inner(), f.voxels.as_slice())),
        );
        Ok(Verifier {
            surface,
            planes,
            target,
            reference_image,
            target_image,
            full: [
                stride_sample(target, VERIFY_SAMPLES),
                stride_sample(reference, VERIFY_REFERENCE_SAMPLES),
            ],
            quick: [
                stride_sample(target, SCREEN_SAMPLES),
                stride_sample(reference, SCREEN_REFERENCE_SAMPLES),
            ],
            final_icp,
        })
    }

    /// The indexed reference (its voxels), shared with the check.
    pub(super) fn surface(&self) -> Arc<SurfaceCloud> {
        Arc::clone(&self.surface)
    }

    /// The reference's range image (points in the reference sensor's frame).
    pub(super) fn reference_image(&self) -> &RangeImage {
        &self.reference_image
    }

    /// Target and reference points of the full verification.
    pub(super) fn full_samples(&self) -> [usize; 2] {
        [self.full[0].len(), self.full[1].len()]
    }

    /// The verification score of `pose` on `samples` (see [`VIOLATION_WEIGHT`]).
    pub(super) fn score(&self, pose: Isometry3<f64>, samples: &Samples) -> Verified {
        let [target_points, reference_points] = samples;
        let agreement = self.surface.overlap(target_points, &pose, VERIFY_DISTANCE);
        let share = |count: usize, total: usize| count as f64 / total.max(1) as f64;
        let violations = [
            share(
                self.reference_image.count_violations(target_points, &pose),
                target_points.len(),
            ),
            share(
                self.target_image
                    .count_violations(reference_points, &pose.inverse()),
                reference_points.len(),
            ),
        ];
        Verified {
            pose,
            agreement,
            violations,
            score: agreement - VIOLATION_WEIGHT * (violations[0] + violations[1]),
        }
    }

    /// The full verification score of `pose`, without moving it.
    pub(super) fn score_full(&self, pose: Isometry3<f64>) -> Verified {
        self.score(pose, &self.full)
    }

    fn icp_then_score(
        &self,
        start: &Isometry3<f64>,
        icp: &IcpOptions,
        samples: &Samples,
    ) -> Option<Verified> {
        point_to_plane_icp(&self.surface, self.target, start, icp)
            .ok()
            .map(|r| self.score(r.pose, samples))
    }

    /// The screening of one hypothesis: a quick ICP and the score on the quick samples.
    pub(super) fn screen(&self, candidate: &Candidate) -> Option<Verified> {
        self.icp_then_score(
            &candidate.pose,
            &screen_icp_options(candidate.sweep),
            &self.quick,
        )
    }

    /// The verification of a screened pose: a short ICP and the full score.
    pub(super) fn verify(&self, start: &Isometry3<f64>) -> Option<Verified> {
        self.icp_then_score(start, &verify_icp_options(), &self.full)
    }

    /// A pose probed around the best one (a half turn, a slide): screened, then verified.
    pub(super) fn settle(&self, start: &Isometry3<f64>) -> Option<Verified> {
        self.icp_then_score(start, &screen_icp_options(false), &self.quick)
            .and_then(|v| self.verify(&v.pose))
    }

    /// A verified pose carried on by the final ICP and scored again.
    pub(super) fn polish(&self, v: &Verified) -> Option<Verified> {
        self.icp_then_score(&v.pose, &self.final_icp, &self.full)
    }

    /// The final point-to-plane ICP from `start`. The reference's scan-line points take their
    /// plane's normal ([`PlaneNormals`]): the final pose is fitted to the surfaces, not to the
    /// rings of a sparse unit. The verification keeps the points' own normals: the rules that
    /// rank and refuse its poses were set on those scores.
    pub(super) fn final_icp(&self, start: &Isometry3<f64>) -> Result<IcpResult> {
        let (planes, options) = (Some(&self.planes), &self.final_icp);
        point_to_plane_icp_on_planes(&self.surface, planes, self.target, start, options)
    }

    /// The final point-to-plane ICP from `start` on the points' own normals, as the check's
    /// re-alignment sees the reference.
    pub(super) fn final_icp_own_normals(&self, start: &Isometry3<f64>) -> Result<IcpResult> {
        point_to_plane_icp(&self.surface, self.target, start, &self.final_icp)
    }

    /// The final ICP's correspondences and information at `pose`, without moving it.
    pub(super) fn fit_at(&self, pose: &Isometry3<f64>) -> Result<IcpResult> {
        let (planes, options) = (Some(&self.planes), &self.final_icp);
        point_to_plane_fit_on_planes(&self.surface, planes, self.target, pose, options)
    }
}

/// The verification (step 4) of `chosen` hypotheses: every one screened, the best
/// [`SCREEN_KEEP`] distinct screened poses verified. The verified poses best first, each with
/// the hypothesis it grew from.
pub(super) fn verify_hypotheses(
    verifier: &Verifier<'_>,
    chosen: &[Candidate],
) -> Vec<(Candidate, Verified)> {
    let screened: Vec<Option<Verified>> = crate::par_map(chosen, |c| verifier.screen(c));
    let mut kept: Vec<(usize, Isometry3<f64>)> = Vec::new();
    for (k, _) in rank(&screened) {
        if kept.len() >= SCREEN_KEEP {
            break;
        }
        let Some(Some(v)) = screened.get(k) else {
            continue;
        };
        if !kept
            .iter()
            .any(|(_, p)| same_pose(p, &v.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE))
        {
            kept.push((k, v.pose));
        }
    }
    let verified: Vec<Option<Verified>> = crate::par_map(&kept, |(_, pose)| verifier.verify(pose));
    rank(&verified)
        .iter()
        .filter_map(|&(k, _)| {
            let v = verified.get(k).copied().flatten()?;
            let c = kept.get(k).and_then(|(i, _)| chosen.get(*i)).copied()?;
            Some((c, v))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settle_best_polishes_a_close_rival_and_merges_one_that_settles_on_the_best() {
        let at = |x: f64, score: f64| {
            let pose = Isometry3::translation(x, 0.0, 0.0);
            let c = Candidate {
                pose,
                free: None,
                support: 0.0,
                sweep: false,
            };
            let v = Verified {
                pose,
                agreement: score,
                violations: [0.0; 2],
                score,
            };
            (c, v)
        };
        let within = |v: &Verified| v.pose.translation.vector.norm() <= 5.0;
        // A rival 1 m away at 90 % is polished and stays distinct: it is the runner-up.
        let pool = [at(0.0, 1.0), at(1.0, 0.9), at(2.0, 0.5)];
        let stay = |v: &Verified| Some(*v);
        let (_, top, runner) = settle_best(&pool, &within, &stay).unwrap();
        assert_eq!(top.score, 1.0);
        assert_eq!(runner.map(|r| r.score), Some(0.9));
        // When the rival settles onto the best (polishing moves 1 m to 0 m) they are one answer,
        // and the next contender, at 50 %, is the runner-up without being polished.
        let onto_best = |v: &Verified| {
            let x = v.pose.translation.vector.x;
            Some(if x < 1.5 { at(0.0, v.score).1 } else { *v })
        };
        let (_, top, runner) = settle_best(&pool, &within, &onto_best).unwrap();
        assert_eq!(top.pose.translation.vector.x, 0.0);
        assert_eq!(runner.map(|r| r.score), Some(0.5));
        // A best pose beyond range is always polished against the best within range, and the
        // better after polishing wins.
        let pool = [at(7.0, 1.0), at(1.0, 0.5)];
        let lift = |v: &Verified| Some(at(v.pose.translation.vector.x, v.score * 3.0).1);
        let (_, top, runner) = settle_best(&pool, &within, &lift).unwrap();
        assert_eq!(top.pose.translation.vector.x, 7.0);
        assert_eq!(runner.map(|r| r.pose.translation.vector.x), Some(1.0));
        assert!(settle_best(&[], &within, &stay).is_none());
    }
}
