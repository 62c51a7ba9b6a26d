//! Step 6: observability. The calibration is refused when the data do not constrain all six
//! degrees of freedom: the weakest direction of the translation (and rotation) information of
//! the final problem must hold at least [`TargetlessOptions::min_information_share`] of it.

use nalgebra::{Matrix3, Vector3};

use super::options::TargetlessOptions;
use super::segment::PlaneFeature;
use super::sweep_floor;
use crate::error::{Error, FailureKind, Result};
use crate::icp::{weakest_direction, weakest_directions, IcpResult};
use crate::lm::LmReport;

/// The weakest directions of the final problem.
pub(super) struct Observability {
    /// Weakest translation direction (reference frame) and its share of the information.
    pub(super) weakest_translation: (Vector3<f64>, f64),
    /// Weakest rotation axis and its share.
    pub(super) weakest_rotation: (Vector3<f64>, f64),
    /// Share of the weakest translation direction spanned by the matched planes' normals alone.
    pub(super) plane_translation_share: f64,
}

/// The observability of the final problem: the final ICP's information (`sum w n n^T` over its
/// correspondences) when it ran, else the plane refinement's (`report`). `Err(Calibration)` with
/// [`FailureKind::Unobservable`] naming the weak direction when its share is below
/// `options.min_information_share` (raised by [`sweep_floor`] for the translation of a pose from
/// the ground `sweep`).
pub(super) fn observability(
    matched: &[&PlaneFeature],
    icp: Option<&IcpResult>,
    report: Option<&LmReport>,
    sweep: bool,
    options: &TargetlessOptions,
) -> Result<Observability> {
    let mut plane_info = Matrix3::zeros();
    for f in matched {
        let n = f.plane.normal.into_inner();
        plane_info += n * n.transpose();
    }
    let plane_translation_share = weakest_direction(&plane_info).1;
    let (weakest_translation, weakest_rotation) = match (icp, report) {
        (Some(r), _) => (r.weakest_translation(), r.weakest_rotation()),
        (None, Some(rep)) => {
            let [translation, rotation] = weakest_directions(&rep.hessian);
            (translation, rotation)
        }
        (None, None) => ((Vector3::x(), 0.0), (Vector3::x(), 0.0)),
    };
    let source = if icp.is_some() {
        "the point-to-plane ICP"
    } else {
        "the matched planes"
    };
    let fmt = |v: &Vector3<f64>| format!("[{:.2}, {:.2}, {:.2}]", v.x, v.y, v.z);
    let translation_floor = sweep_floor(options.min_information_share, sweep);
    if weakest_translation.1 < translation_floor {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "the scene does not constrain the translation along {} (reference frame): it \
                 holds {:.2} % of the translation information of {source} (< {:.2} %{}); the \
                 matched planes' normals span {} direction(s) (as in a corridor or a straight \
                 street with only ground and parallel walls); add structure across that \
                 direction (a cross wall, poles, a building corner)",
                fmt(&weakest_translation.0),
                100.0 * weakest_translation.1,
                100.0 * translation_floor,
                if sweep {
                    " for a pose from the ground sweep"
                } else {
                    ""
                },
                if plane_translation_share > 1e-3 {
                    3
                } else if matched.len() > 1 {
                    2
                } else {
                    1
                },
            ),
        ));
    }
    if weakest_rotation.1 < options.min_information_share {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "the scene does not constrain the rotation about {} (reference frame): it holds \
                 {:.2} % of the rotation information of {source} (< {:.2} %)",
                fmt(&weakest_rotation.0),
                100.0 * weakest_rotation.1,
                100.0 * options.min_information_share
            ),
        ));
    }
    Ok(Observability {
        weakest_translation,
        weakest_rotation,
        plane_translation_share,
    })
}
