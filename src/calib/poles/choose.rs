//! Step 6 of the [module docs](super): the winning hypothesis, its margin and the poles' fit.

use super::fit::MAX_RADIUS;
use super::hypotheses::*;
use super::options::*;
use crate::error::{Error, FailureKind, Result};
use crate::geometry::Line;

/// Two refined hypotheses within this rotation (radians) ...
const SAME_POSE_ANGLE: f64 = 0.01;
/// ... and this translation (metres) of each other are the same solution.
const SAME_POSE_DISTANCE: f64 = 0.05;
/// A score margin below this flags the choice as ambiguous.
pub(super) const AMBIGUITY_MARGIN: f64 = 1.0;
/// A score margin below this refuses the calibration: the best two are indistinguishable.
pub(super) const REFUSE_MARGIN: f64 = 0.2;
/// Largest RMS distance (metres) of a matched pole's points from its axis model at the result;
/// correct results stay under 1 cm, a pose from mismatched poles lands decimetres off.
pub(super) const MAX_POLE_RMSE: f64 = 0.05;
/// What [`MAX_POLE_RMSE`] allows in addition for [`AxisFit::Line`], whose residuals include the
/// pole's thickness (metres).
const LINE_FIT_THICKNESS: f64 = 0.2;

/// The lowest-scoring hypothesis and its margin over the best one that refined to a different
/// transform (infinite when there is none); refused when there is no hypothesis or the margin is
/// below [`REFUSE_MARGIN`].
pub(super) fn choose(hypotheses: &[Hypothesis]) -> Result<(usize, f64)> {
    let mut order: Vec<usize> = (0..hypotheses.len()).collect();
    order.sort_by(|&a, &b| hypotheses[a].score.total_cmp(&hypotheses[b].score));
    let Some(&chosen) = order.first() else {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            "no pair of non-parallel target poles to match",
        ));
    };
    // The runner-up is the best hypothesis that reached a different transform: hypotheses that
    // refine to the same pose are one solution, not a tie.
    let best_pose = hypotheses[chosen].reference_from_target;
    let runner_up = order.iter().copied().skip(1).find(|&j| {
        let d = hypotheses[j].reference_from_target.inverse() * best_pose;
        d.rotation.angle() > SAME_POSE_ANGLE || d.translation.vector.norm() > SAME_POSE_DISTANCE
    });
    let margin = runner_up.map_or(f64::INFINITY, |j| {
        hypotheses[j].score - hypotheses[chosen].score
    });
    if let Some(j) = runner_up.filter(|_| margin < REFUSE_MARGIN) {
        let (a, b) = (&hypotheses[chosen], &hypotheses[j]);
        return Err(Error::calibration(FailureKind::Ambiguous, format!(
            "ambiguous pole correspondence: the best two hypotheses score {:.3} and {:.3} \
             (margin {margin:.3} < {REFUSE_MARGIN}; axis RMS {:.4} / {:.4} m, overlap {:.3} / {:.3}); \
             the scene is symmetric (e.g. two vertical poles on flat ground with nothing else)",
            a.score, b.score, a.axis_rms, b.axis_rms, a.overlap, b.overlap
        )));
    }
    Ok((chosen, margin))
}

/// The matched poles of a hypothesis, in match order.
pub(super) struct MatchedPoles {
    /// Axes in the reference frame.
    pub(super) poles_reference: Vec<Line>,
    /// Axes in the target frame, signed to match the reference's.
    pub(super) poles_target: Vec<Line>,
    /// The given radius (cylinder fits), else the mean of the two clouds' estimates.
    pub(super) radii: Vec<f64>,
    /// Indices of each pole's points in the reference cloud.
    pub(super) inliers_reference: Vec<Vec<usize>>,
    /// Indices of each pole's points in the target cloud.
    pub(super) inliers_target: Vec<Vec<usize>>,
}

impl MatchedPoles {
    /// Collects the poles of `matches` from both clouds.
    pub(super) fn new(
        clouds: &Clouds<'_>,
        matches: &[(usize, usize, i8)],
        options: &PoleOptions,
    ) -> Self {
        let mut poles_reference = Vec::new();
        let mut poles_target = Vec::new();
        let mut radii = Vec::new();
        let mut inliers_reference = Vec::new();
        let mut inliers_target = Vec::new();
        for &(i, k, s) in matches {
            let (pr, pt) = (&clouds.poles_ref[i], &clouds.poles_tgt[k]);
            poles_reference.push(pr.axis);
            poles_target.push(signed_axis(pt, s));
            radii.push(match options.pole_radius {
                Some(r) if options.axis_fit == AxisFit::Cylinder => r,
                _ => 0.5 * (pr.radius + pt.radius),
            });
            inliers_reference.push(pr.indices.clone());
            inliers_target.push(pt.indices.clone());
        }
        MatchedPoles {
            poles_reference,
            poles_target,
            radii,
            inliers_reference,
            inliers_target,
        }
    }
}

/// Refuses a pose at which a matched pole lies more than [`MAX_POLE_RMSE`] (plus
/// [`LINE_FIT_THICKNESS`] for centroid lines) from its axis, or a matched radius above
/// [`MAX_RADIUS`].
pub(super) fn check_pole_fit(pole_rmse: &[f64], radii: &[f64], axis_fit: AxisFit) -> Result<()> {
    // A centroid line sits up to a radius in front of the axis and estimates no radius: its
    // residuals include the pole's thickness, allowed up to LINE_FIT_THICKNESS.
    let allowed = match axis_fit {
        AxisFit::Cylinder => MAX_POLE_RMSE,
        AxisFit::Line => MAX_POLE_RMSE + LINE_FIT_THICKNESS,
    };
    if let Some((k, worst)) = pole_rmse
        .iter()
        .copied()
        .enumerate()
        .find(|&(_, r)| !(r.is_finite() && r <= allowed))
    {
        return Err(Error::calibration(
            FailureKind::OutOfRange,
            format!(
                "pole {k} lies {worst:.3} m (RMS) from its matched axis at the best pose (> \
                 {:.3} m; correct matches stay under 1 cm): the poles found in the two \
                 clouds are not the same poles, or one is barely seen",
                allowed
            ),
        ));
    }
    if let Some(r) = radii.iter().find(|r| !(r.is_finite() && **r <= MAX_RADIUS)) {
        return Err(Error::calibration(
            FailureKind::OutOfRange,
            format!("a matched pole has a radius of {r:.2} m (> {MAX_RADIUS} m): not a pole"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;

    fn hypothesis(score: f64, pose: Isometry3<f64>) -> Hypothesis {
        Hypothesis {
            matches: Vec::new(),
            reference_from_target: pose,
            axis_rms: 0.0,
            ground_angle: None,
            ground_offset: None,
            overlap: 1.0,
            score,
        }
    }

    #[test]
    fn choose_measures_the_margin_to_another_pose() {
        let here = Isometry3::identity();
        let there = Isometry3::translation(1.0, 0.0, 0.0);
        // Hypotheses that refined to the same pose are one solution, not a tie.
        let h = [
            hypothesis(3.0, there),
            hypothesis(1.0, here),
            hypothesis(1.05, here),
        ];
        let (chosen, margin) = choose(&h).unwrap();
        assert_eq!(chosen, 1);
        assert!((margin - 2.0).abs() < 1e-12, "{margin}");
        assert_eq!(choose(&h[1..]).unwrap(), (0, f64::INFINITY));
        // Two poses within REFUSE_MARGIN are indistinguishable.
        let tie = [hypothesis(1.0, here), hypothesis(1.1, there)];
        assert!(matches!(choose(&tie), Err(Error::Calibration { .. })));
        assert!(choose(&[]).is_err());
    }

    #[test]
    fn check_pole_fit_allows_centroid_lines_their_thickness() {
        assert!(check_pole_fit(&[0.01, 0.02], &[0.05, 0.05], AxisFit::Cylinder).is_ok());
        assert!(check_pole_fit(&[0.1], &[0.05], AxisFit::Cylinder).is_err());
        assert!(check_pole_fit(&[0.1], &[0.0], AxisFit::Line).is_ok());
        assert!(check_pole_fit(&[f64::NAN], &[0.05], AxisFit::Line).is_err());
        assert!(check_pole_fit(&[0.01], &[2.0], AxisFit::Cylinder).is_err());
    }
}
