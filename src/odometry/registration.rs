//! One frame's registration against the local map: point-to-plane Gauss–Newton on SE(3) (left
//! perturbation, tangent `[rho; phi]` as in [`crate::lm`]), each source point paired with the
//! nearest map point within the correspondence distance and weighted by a Cauchy loss.

use nalgebra::{Isometry3, Matrix6, Point3, Vector3};

use super::voxel_map::VoxelMap;
use crate::geometry::{se3_exp, se3_log};
use crate::icp::PlaneSums;
use crate::lm::{accumulate, Loss};

/// Fewest correspondences a Gauss–Newton step is taken from (six unknowns).
pub(crate) const MIN_CORRESPONDENCES: usize = 6;
/// Weight of a prior holding the pose to the prediction, relative to the mean diagonal of the
/// translation and of the rotation block of `J^T W J`: a direction the frame does not constrain
/// (the height when no ground is in view, a corridor's length) stays where the constant-velocity
/// prediction put it instead of wandering (measured without it: a metre of height in a frame
/// with no ground), and a constrained one moves by a thousandth of its share less.
const PRIOR: f64 = 1e-3;

/// What one registration found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Registration {
    pub(crate) pose: Isometry3<f64>,
    pub(crate) iterations: usize,
    pub(crate) converged: bool,
    pub(crate) correspondences: usize,
    /// Root-mean-square point-to-plane residual of the correspondences (metres, Cauchy-weighted).
    pub(crate) rmse: f64,
    /// `J^T W J` at the solution (tangent about the predicted sensor position).
    pub(crate) information: Matrix6<f64>,
}

fn linearise(
    map: &VoxelMap,
    source: &[Point3<f64>],
    pose: &Isometry3<f64>,
    distance: f64,
    kernel: f64,
    centre: &Vector3<f64>,
) -> PlaneSums {
    let loss = Loss::Cauchy { scale: kernel };
    let mut sums: PlaneSums = accumulate(source, |p, acc: &mut PlaneSums| {
        let q = pose * p;
        let Some(m) = map.nearest(&q, distance) else {
            return;
        };
        acc.add(
            m.normal.dot(&(q - m.position)),
            &m.normal,
            &(q.coords - centre),
            loss,
        );
    });
    sums.ne.symmetrize();
    sums
}

/// Registers `source` (sensor frame) to `map` from `initial` (`world_from_sensor`), with a Cauchy
/// loss of scale `kernel` (metres); `None` when
/// fewer than [`MIN_CORRESPONDENCES`] source points find a map point within `distance`.
pub(crate) fn register(
    map: &VoxelMap,
    source: &[Point3<f64>],
    initial: &Isometry3<f64>,
    distance: f64,
    kernel: f64,
    max_iterations: usize,
    tolerance: f64,
) -> Option<Registration> {
    let mut pose = *initial;
    let mut iterations = 0;
    let mut converged = false;
    // Steps and the prior are taken about the predicted sensor position, not the world's origin
    // (which may be a hundred metres away): there the rotation block of `J^T W J` measures the
    // scan's own leverage, so the prior's weight means the same thing in every frame.
    let centre = initial.translation.vector;
    let about = Isometry3::from_parts(initial.translation, nalgebra::UnitQuaternion::identity());
    let mut sums = linearise(map, source, &pose, distance, kernel, &centre);
    while iterations < max_iterations {
        if sums.matched < MIN_CORRESPONDENCES {
            return None;
        }
        let h = sums.ne.hessian;
        let weight = |from: usize| {
            let mean = (from..from + 3).map(|i| h[(i, i)]).sum::<f64>() / 3.0;
            (PRIOR * mean).max(1e-12)
        };
        let (wt, wr) = (weight(0), weight(3));
        // The pose's offset from the prediction, in the left tangent: `pose = exp(d) initial`.
        let d = se3_log(&(about.inverse() * pose * initial.inverse() * about));
        let mut damped = h;
        let mut gradient = sums.ne.gradient;
        for i in 0..6 {
            let w = if i < 3 { wt } else { wr };
            damped[(i, i)] += w;
            gradient[i] += w * d[i];
        }
        let step = damped.cholesky()?.solve(&(-gradient));
        pose = about * se3_exp(&step) * about.inverse() * pose;
        iterations += 1;
        sums = linearise(map, source, &pose, distance, kernel, &centre);
        if step.norm() < tolerance {
            converged = true;
            break;
        }
    }
    if sums.matched < MIN_CORRESPONDENCES {
        return None;
    }
    Some(Registration {
        pose,
        iterations,
        converged,
        correspondences: sums.matched,
        rmse: sums.rmse(),
        information: sums.ne.hessian,
    })
}
