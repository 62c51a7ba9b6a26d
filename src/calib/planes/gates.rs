//! The gates of the pipeline on the planes themselves: each wide enough, the refined planes in
//! agreement, and each matched plane landing on its partner in the other cloud.

use nalgebra::{Isometry3, Point3};

use super::refine::PlanePairs;
use super::{PlanarOptions, MIN_PLANE_AGREEMENT, MIN_PLANE_OVERLAP, PLANE_AGREEMENT_SAMPLES};
use crate::error::{Error, FailureKind, Result};
use crate::fit::Moments;
use crate::icp::SurfaceCloud;
use crate::ransac::plane::ExtractedPlane;
use crate::residuals::PlaneMomentsProblem;

/// `Err(TooFewFeatures)` when a plane's inliers span less than `min_width` along their shorter
/// in-plane axis (the side of a uniform patch with that spread, `sqrt(12 l)`).
pub(super) fn check_widths(
    points: &[Point3<f64>],
    found: &[ExtractedPlane],
    min_width: f64,
    which: &str,
) -> Result<()> {
    for (k, plane) in found.iter().enumerate() {
        let [_, width] =
            Moments::from_points(plane.inliers.iter().filter_map(|&i| points.get(i))).extents();
        if width < min_width {
            return Err(Error::calibration(
                FailureKind::TooFewFeatures,
                format!(
                    "{which} cloud: plane {k} spans only {width:.2} m across (< min_plane_width \
                     {min_width} m): the face of a box or a post, not a wall or the ground"
                ),
            ));
        }
    }
    Ok(())
}

/// Points of each cloud (at most, by a fixed stride) indexed for [`planes_land_on_planes`].
const LABEL_SAMPLES: usize = 30_000;

/// Each cloud's stride sample (at most [`LABEL_SAMPLES`] points) indexed for
/// [`planes_land_on_planes`], `[reference, target]`. It depends on the clouds alone, so the
/// corner method indexes them once for every choice of planes it tries.
pub(super) struct Landing {
    clouds: [SurfaceCloud; 2],
    strides: [usize; 2],
}

impl Landing {
    pub(super) fn new(reference: &[Point3<f64>], target: &[Point3<f64>]) -> Result<Self> {
        let sample = |points: &[Point3<f64>]| -> Result<(SurfaceCloud, usize)> {
            let stride = points.len().div_ceil(LABEL_SAMPLES).max(1);
            let kept = points.iter().step_by(stride).copied().collect();
            Ok((SurfaceCloud::new(kept)?, stride))
        };
        let (r, t) = crate::join(|| sample(reference), || sample(target));
        let ((r, stride_r), (t, stride_t)) = (r?, t?);
        Ok(Landing {
            clouds: [r, t],
            strides: [stride_r, stride_t],
        })
    }
}

/// `Err(NoAgreement)` when the inliers of a matched plane, mapped onto the other cloud, mostly
/// land nearest to points that are not inliers of its partner there: the two were different
/// surfaces, usually parallel and close (a pavement or kerb taken for the ground in one cloud, a
/// box top), so the three planes agree with one another but not with the scene. Each mapped inlier
/// (a stride sample) whose nearest point of the other cloud (of its sample in `landing`) lies
/// within the check's overlap distance counts; the share whose nearest point is an inlier of the
/// partner plane must reach [`MIN_PLANE_AGREEMENT`].
pub(super) fn planes_land_on_planes(
    landing: &Landing,
    [reference, target]: [&[Point3<f64>]; 2],
    inliers: [&[Vec<usize>; 3]; 2],
    pose: &Isometry3<f64>,
    overlap_distance: f64,
) -> Result<()> {
    // The matched plane of each sampled point (if any).
    let labels = |c: usize, len: usize| -> Vec<usize> {
        let mut label = vec![usize::MAX; len];
        for (k, idx) in inliers[c].iter().enumerate() {
            for &i in idx {
                if let Some(l) = label.get_mut(i) {
                    *l = k;
                }
            }
        }
        label.into_iter().step_by(landing.strides[c]).collect()
    };
    let (ref_labels, tgt_labels) = (labels(0, reference.len()), labels(1, target.len()));
    let [ref_cloud, tgt_cloud] = &landing.clouds;
    let inverse = pose.inverse();
    for (k, (ref_idx, tgt_idx)) in inliers[0].iter().zip(inliers[1].iter()).enumerate() {
        for (points, idx, onto, labels, map, which, other) in [
            (
                target,
                tgt_idx,
                ref_cloud,
                &ref_labels,
                pose,
                "target",
                "reference",
            ),
            (
                reference,
                ref_idx,
                tgt_cloud,
                &tgt_labels,
                &inverse,
                "reference",
                "target",
            ),
        ] {
            let stride = idx.len().div_ceil(PLANE_AGREEMENT_SAMPLES).max(1);
            let (mut overlap, mut agreeing) = (0usize, 0usize);
            for p in idx.iter().step_by(stride).filter_map(|&i| points.get(i)) {
                if let Some((j, _)) = onto.nearest(&(map * p), overlap_distance) {
                    overlap += 1;
                    agreeing += usize::from(labels.get(j) == Some(&k));
                }
            }
            let share = agreeing as f64 / overlap.max(1) as f64;
            if overlap >= MIN_PLANE_OVERLAP && share < MIN_PLANE_AGREEMENT {
                return Err(Error::calibration(
                    FailureKind::NoAgreement,
                    format!(
                        "plane {k} of the {which} cloud does not land on its partner in the \
                         {other} cloud: of its {overlap} inliers that land near {other} points, \
                         {:.0} % land nearest to inliers of the matched plane (< {:.0} %); the two \
                         are likely different surfaces, parallel and close (a pavement or kerb \
                         taken for the ground, a box top)",
                        100.0 * share,
                        100.0 * MIN_PLANE_AGREEMENT
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Per-plane RMS over both directions at `pose`; after a refinement, `Err(NoAgreement)` when a
/// plane's exceeds twice the larger inlier threshold.
pub(super) fn plane_rmse(
    pairs: &PlanePairs<'_>,
    moments_problem: &PlaneMomentsProblem,
    pose: &Isometry3<f64>,
    thresholds: [f64; 2],
    options: &PlanarOptions,
) -> Result<[f64; 3]> {
    let (inliers_ref, inliers_tgt) = (pairs.inliers_ref, pairs.inliers_tgt);
    let group_rms = moments_problem.group_rms(pose);
    let mut rmse = [0.0; 3];
    for i in 0..3 {
        let (n_t, n_r) = (inliers_tgt[i].len() as f64, inliers_ref[i].len() as f64);
        let (a, b) = (group_rms[2 * i], group_rms[2 * i + 1]);
        rmse[i] = ((a * a * n_t + b * b * n_r) / (n_t + n_r)).sqrt();
        let limit = 2.0 * thresholds[0].max(thresholds[1]);
        if options.refine && rmse[i] > limit {
            return Err(Error::calibration(
                FailureKind::NoAgreement,
                format!(
                "the matched planes do not agree after refinement: plane {i} has an RMS residual \
                 of {:.3} m (> {limit:.3} m); the two clouds may not show the same corner",
                rmse[i]
            ),
            ));
        }
    }
    Ok(rmse)
}
