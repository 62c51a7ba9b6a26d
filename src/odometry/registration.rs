//! One frame's registration against the local map: point-to-plane Gauss–Newton on SE(3) (left
//! perturbation, tangent `[rho; phi]` as in [`crate::lm`]), each source point paired with the
//! nearest map point within the correspondence distance and weighted by a Cauchy loss.

use nalgebra::{Isometry3, Matrix6, Point3, Vector6};

use super::voxel_map::VoxelMap;
use crate::geometry::se3_exp;
use crate::lm::{accumulate, Accumulator, Loss, NormalEquations};

/// Fewest correspondences a Gauss–Newton step is taken from (six unknowns).
pub(crate) const MIN_CORRESPONDENCES: usize = 6;
/// Ridge added to the diagonal of `J^T W J`, relative to its largest diagonal entry, so a
/// direction the frame does not constrain (a corridor's length) stays where the prediction put
/// it instead of making the step singular.
const RIDGE: f64 = 1e-9;

/// What one registration found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Registration {
    pub(crate) pose: Isometry3<f64>,
    pub(crate) iterations: usize,
    pub(crate) converged: bool,
    pub(crate) correspondences: usize,
    /// Root-mean-square point-to-plane residual of the correspondences (metres, Cauchy-weighted).
    pub(crate) rmse: f64,
    /// `J^T W J` at the solution.
    pub(crate) information: Matrix6<f64>,
}

#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    ne: NormalEquations,
    matched: usize,
    squared: f64,
    weight: f64,
}

impl Accumulator for Sums {
    fn merge(&mut self, o: &Self) {
        self.ne.merge(&o.ne);
        self.matched += o.matched;
        self.squared += o.squared;
        self.weight += o.weight;
    }
}

fn linearise(
    map: &VoxelMap,
    source: &[Point3<f64>],
    pose: &Isometry3<f64>,
    distance: f64,
    kernel: f64,
) -> Sums {
    let loss = Loss::Cauchy { scale: kernel };
    let mut sums: Sums = accumulate(source, |p, acc: &mut Sums| {
        let q = pose * p;
        let Some(m) = map.nearest(&q, distance) else {
            return;
        };
        let n = m.normal;
        let r = n.dot(&(q - m.position));
        let c = q.coords.cross(&n);
        let j = Vector6::new(n.x, n.y, n.z, c.x, c.y, c.z);
        acc.ne.add(r, &j, loss);
        acc.matched += 1;
        let w = loss.weight(r * r);
        acc.squared += w * r * r;
        acc.weight += w;
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
    let mut sums = linearise(map, source, &pose, distance, kernel);
    while iterations < max_iterations {
        if sums.matched < MIN_CORRESPONDENCES {
            return None;
        }
        let h = sums.ne.hessian;
        let scale = (0..6).map(|i| h[(i, i)]).fold(0.0, f64::max).max(1e-12);
        let damped = h + Matrix6::identity() * (RIDGE * scale);
        let step = damped.cholesky()?.solve(&(-sums.ne.gradient));
        pose = se3_exp(&step) * pose;
        iterations += 1;
        sums = linearise(map, source, &pose, distance, kernel);
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
        rmse: (sums.squared / sums.weight.max(f64::MIN_POSITIVE)).sqrt(),
        information: sums.ne.hessian,
    })
}
