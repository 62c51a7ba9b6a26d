//! Point-to-plane and point-to-line residuals with analytic Jacobians, as [`LeastSquaresProblem`]s.
//!
//! The unknown is `T = reference_from_target` (`R`, `t`). A feature group pairs a geometric feature
//! with points measured by the *other* sensor:
//!
//! * [`Frame::Target`]: points in the target frame against a feature in the reference frame. For a
//!   plane `(n, d)`: `r = n . (T p) + d`, Jacobian `[n^T, (q x n)^T]` with `q = T p`.
//! * [`Frame::Reference`]: points in the reference frame against a feature in the target frame,
//!   `r = n . (T^-1 p) + d`. With `m = R n`: Jacobian `[-m^T, (m x p)^T]`.
//!
//! A point-to-line residual is the 2-vector of the point's offset from the line along two unit
//! vectors `e1, e2` orthogonal to the direction (fixed in the line's own frame), so its squared norm
//! is the squared distance; a robust loss acts on that distance. Jacobian rows are
//! `[e_k^T, (q x e_k)^T]` (target points) and `[-e_k^T, (e_k x p)^T]` (reference points, `e_k`
//! rotated into the reference frame).
//!
//! All Jacobians are with respect to the left perturbation `exp(delta) * T`, `delta = [rho; phi]`,
//! and are checked against central differences in the tests.
//!
//! ```
//! use lidarcal::geometry::{se3_exp, Plane};
//! use lidarcal::lm::{solve, LmOptions, Loss};
//! use lidarcal::residuals::{Frame, PlaneGroup, PointToPlane};
//! use nalgebra::{Point3, Vector3, Vector6};
//!
//! // Three orthogonal planes in the reference frame and points on them seen by the target sensor.
//! let ref_from_tgt = se3_exp(&Vector6::new(0.5, -0.2, 0.1, 0.05, -0.1, 0.3));
//! let mut groups = Vec::new();
//! for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
//!     let plane = Plane::new(axis, -1.0).unwrap(); // axis . p = 1
//!     let (u, v) = lidarcal::geometry::orthonormal_basis(&plane.normal);
//!     let points = (0..100)
//!         .map(|i| {
//!             let p_ref = Point3::from(axis + u * (i % 10) as f64 * 0.1 + v * (i / 10) as f64 * 0.1);
//!             ref_from_tgt.inverse() * p_ref
//!         })
//!         .collect();
//!     groups.push(PlaneGroup { plane, points, frame: Frame::Target });
//! }
//! let problem = PointToPlane::new(groups, Loss::Squared).unwrap();
//! let solution = solve(&problem, &nalgebra::Isometry3::identity(), &LmOptions::default()).unwrap();
//! assert!((solution.pose.to_homogeneous() - ref_from_tgt.to_homogeneous()).amax() < 1e-9);
//! ```

use nalgebra::{Isometry3, Matrix3, Point3, Vector3, Vector6};

use crate::geometry::hat;

use crate::error::{Error, Result};
use crate::fit::Moments;
use crate::geometry::{orthonormal_basis, Line, Plane};
use crate::lm::{accumulate, Accumulator, LeastSquaresProblem, Loss, NormalEquations};

/// Which sensor's frame a group's points are expressed in (the feature is in the other one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// Points in the target frame; the feature in the reference frame.
    Target,
    /// Points in the reference frame; the feature in the target frame.
    Reference,
}

/// Points that should lie on one plane.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneGroup {
    /// The plane, in the frame opposite to `frame`.
    pub plane: Plane,
    /// The points, in `frame`.
    pub points: Vec<Point3<f64>>,
    /// The frame of `points`.
    pub frame: Frame,
}

/// Points that should lie on one line.
#[derive(Debug, Clone, PartialEq)]
pub struct LineGroup {
    /// The line, in the frame opposite to `frame`.
    pub line: Line,
    /// The points, in `frame`.
    pub points: Vec<Point3<f64>>,
    /// The frame of `points`.
    pub frame: Frame,
}

/// Checks the loss and every group (non-empty, finite points); returns the number of points.
fn checked_count<'a>(
    kind: &str,
    loss: Loss,
    groups: impl ExactSizeIterator<Item = &'a [Point3<f64>]>,
) -> Result<usize> {
    loss.validate()?;
    if groups.len() == 0 {
        return Err(Error::InvalidInput(format!("no {kind} groups given")));
    }
    let mut count = 0;
    for (index, points) in groups.enumerate() {
        if points.is_empty() {
            return Err(Error::InvalidInput(format!(
                "{kind} group {index} has no points"
            )));
        }
        crate::error::ensure_points(&format!("points of {kind} group {index}"), points.iter())?;
        count += points.len();
    }
    Ok(count)
}

/// Point-to-plane alignment: `sum rho(r^2)` over every point of every group.
#[derive(Debug, Clone, PartialEq)]
pub struct PointToPlane {
    groups: Vec<PlaneGroup>,
    loss: Loss,
    count: usize,
}

impl PointToPlane {
    /// Builds the problem; fails on empty groups, non-finite points or an invalid loss.
    pub fn new(groups: Vec<PlaneGroup>, loss: Loss) -> Result<Self> {
        let count = checked_count("plane", loss, groups.iter().map(|g| g.points.as_slice()))?;
        Ok(PointToPlane {
            groups,
            loss,
            count,
        })
    }

    /// The groups.
    pub fn groups(&self) -> &[PlaneGroup] {
        &self.groups
    }

    /// The weighted least-squares problem of one IRLS step at `pose`: every point weighted by
    /// `rho'(r^2)` of its residual there, summarised as weighted moments (one pass, no
    /// logarithms). Iterating "solve it, re-weight at the solution" converges to a stationary
    /// point of this robust problem: there `sum rho'(r^2) r J = 0`, its gradient.
    pub fn reweighted(&self, pose: &Isometry3<f64>) -> Result<PlaneMomentsProblem> {
        let weigh =
            |g: &PlaneGroup| reweighted_group(&g.plane, g.frame, g.points.iter(), pose, self.loss);
        // Groups are independent: in parallel, each summed in order, so the result is the same
        // for any thread count.
        PlaneMomentsProblem::new(crate::par_map(&self.groups, weigh))
    }

    /// Residual and Jacobian row of every point, group after group (for checks and diagnostics).
    pub fn residuals(&self, pose: &Isometry3<f64>) -> Vec<(f64, Vector6<f64>)> {
        let mut out = Vec::with_capacity(self.count);
        for g in &self.groups {
            let term = PlaneTerm::new(g, pose);
            out.extend(g.points.iter().map(|p| term.residual(p)));
        }
        out
    }
}

/// The weighted moments of one IRLS step for the points of one plane group (in `frame`, the
/// plane in the other frame) at `pose`: each point weighted by `rho'(r^2)` of its residual, in
/// the order given, relative to the first point. [`PointToPlane::reweighted`] runs it per group;
/// the corner method runs it on its inliers in place, without copying them.
pub(crate) fn reweighted_group<'p>(
    plane: &Plane,
    frame: Frame,
    points: impl Iterator<Item = &'p Point3<f64>>,
    pose: &Isometry3<f64>,
    loss: Loss,
) -> PlaneMomentGroup {
    let term = PlaneTerm::of(plane, frame, pose);
    let mut points = points.peekable();
    let origin = points.peek().map_or_else(Point3::origin, |p| **p);
    let mut moments = Moments::new(origin);
    for p in points {
        let r = term.distance(p);
        moments.add_weighted(p, loss.weight(r * r));
    }
    PlaneMomentGroup {
        plane: *plane,
        moments,
        frame,
    }
}

/// The cost `1/2 sum rho(r^2)` (in [`NormalEquations::cost`]) of the points `point(item)` of one
/// plane group at `pose`, summed in fixed chunks ([`accumulate`]).
pub(crate) fn plane_cost<T: Sync>(
    plane: &Plane,
    frame: Frame,
    items: &[T],
    point: impl Fn(&T) -> Point3<f64> + Sync,
    pose: &Isometry3<f64>,
    loss: Loss,
) -> NormalEquations {
    let term = PlaneTerm::of(plane, frame, pose);
    accumulate(items, |item, acc: &mut NormalEquations| {
        let r = term.distance(&point(item));
        acc.add_cost(r * r, 1, loss);
    })
}

/// A plane group prepared for a given pose: the plane and the point map in one frame.
struct PlaneTerm {
    frame: Frame,
    /// Plane normal in the frame where residuals are computed (reference frame).
    normal: Vector3<f64>,
    offset: f64,
    pose: Isometry3<f64>,
    /// The plane in the points' own frame: the distance of a point without mapping it (the IRLS
    /// passes weigh every inlier by it, round after round).
    local_normal: Vector3<f64>,
    local_offset: f64,
}

impl PlaneTerm {
    fn new(group: &PlaneGroup, pose: &Isometry3<f64>) -> Self {
        Self::of(&group.plane, group.frame, pose)
    }

    fn of(plane: &Plane, frame: Frame, pose: &Isometry3<f64>) -> Self {
        match frame {
            Frame::Target => {
                // n . (R p + t) + d = (R^T n) . p + (n . t + d)
                let normal = plane.normal.into_inner();
                PlaneTerm {
                    frame: Frame::Target,
                    normal,
                    offset: plane.offset,
                    pose: *pose,
                    local_normal: pose.rotation.inverse_transform_vector(&normal),
                    local_offset: normal.dot(&pose.translation.vector) + plane.offset,
                }
            }
            Frame::Reference => {
                let plane = plane.transformed(pose);
                PlaneTerm {
                    frame: Frame::Reference,
                    normal: plane.normal.into_inner(),
                    offset: plane.offset,
                    pose: *pose,
                    local_normal: plane.normal.into_inner(),
                    local_offset: plane.offset,
                }
            }
        }
    }

    #[inline]
    fn residual(&self, p: &Point3<f64>) -> (f64, Vector6<f64>) {
        let n = &self.normal;
        match self.frame {
            Frame::Target => {
                let q = self.pose * p;
                let r = n.dot(&q.coords) + self.offset;
                let c = q.coords.cross(n);
                (r, Vector6::new(n.x, n.y, n.z, c.x, c.y, c.z))
            }
            Frame::Reference => {
                let r = n.dot(&p.coords) + self.offset;
                let c = n.cross(&p.coords);
                (r, Vector6::new(-n.x, -n.y, -n.z, c.x, c.y, c.z))
            }
        }
    }

    #[inline]
    fn distance(&self, p: &Point3<f64>) -> f64 {
        self.local_normal.dot(&p.coords) + self.local_offset
    }
}

/// IRLS-weighted sums of one plane group in the residual frame: `sum w`, `sum w q`,
/// `sum w q q^T` with `w = rho'(r^2)`, plus the cost `1/2 sum rho(r^2)`.
#[derive(Debug, Clone, Copy, Default)]
struct WeightedSums {
    weight: f64,
    first: Vector3<f64>,
    second: Matrix3<f64>,
    cost: f64,
    count: usize,
}

impl Accumulator for WeightedSums {
    fn merge(&mut self, o: &Self) {
        self.weight += o.weight;
        self.first += o.first;
        self.second += o.second;
        self.cost += o.cost;
        self.count += o.count;
    }
}

impl LeastSquaresProblem for PointToPlane {
    fn residual_count(&self) -> usize {
        self.count
    }

    /// Per point only the residual, its weight and the weighted first and second moments are
    /// accumulated; `J^T W J` and `J^T W r` follow in closed form (see [`PlaneMomentsProblem`]),
    /// because every Jacobian row is affine in the point.
    fn normal_equations(&self, pose: &Isometry3<f64>, with_derivatives: bool) -> NormalEquations {
        let loss = self.loss;
        let mut total = NormalEquations::default();
        for g in &self.groups {
            if !with_derivatives {
                total.merge(&plane_cost(
                    &g.plane,
                    g.frame,
                    &g.points,
                    |p| *p,
                    pose,
                    loss,
                ));
                continue;
            }
            let term = PlaneTerm::new(g, pose);
            let sums: WeightedSums = accumulate(&g.points, |p, acc: &mut WeightedSums| {
                let q = match term.frame {
                    Frame::Target => (term.pose * p).coords,
                    Frame::Reference => p.coords,
                };
                let r = term.normal.dot(&q) + term.offset;
                let (rho, w) = loss.evaluate(r * r);
                acc.weight += w;
                acc.first += q * w;
                acc.second.syger(w, &q, &q, 1.0);
                acc.cost += 0.5 * rho;
                acc.count += 1;
            });
            let mut second = sums.second;
            second.fill_upper_triangle_with_lower_triangle();
            let sign = match term.frame {
                Frame::Target => 1.0,
                Frame::Reference => -1.0,
            };
            let mut part = plane_normal_equations(
                &term.normal,
                term.offset,
                sign,
                sums.weight,
                &sums.first,
                &second,
            );
            part.cost = sums.cost;
            part.residual_count = sums.count;
            total.merge(&part);
        }
        total
    }
}

/// `J^T W J` and `J^T W r` of a plane group from its weighted sums: residual `r = n . q + d`,
/// Jacobian row `[sign n, -sign [n]x q]` (target points: sign +1, `q = T p`; reference points:
/// sign -1, `q = p` against the plane moved into the reference frame). `weight = sum w`,
/// `first = sum w q`, `second = sum w q q^T` (full symmetric). Cost and count are left at zero.
fn plane_normal_equations(
    normal: &Vector3<f64>,
    offset: f64,
    sign: f64,
    weight: f64,
    first: &Vector3<f64>,
    second: &Matrix3<f64>,
) -> NormalEquations {
    let k = hat(normal) * (-sign);
    let sum_r = normal.dot(first) + weight * offset;
    let sum_rq = second * normal + first * offset;
    let top_left = normal * normal.transpose() * weight;
    let top_right = normal * (k * first).transpose() * sign;
    let bottom_right = k * second * k.transpose();
    let mut ne = NormalEquations::default();
    ne.hessian.fixed_view_mut::<3, 3>(0, 0).copy_from(&top_left);
    ne.hessian
        .fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&top_right);
    ne.hessian
        .fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&top_right.transpose());
    ne.hessian
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&bottom_right);
    let top = normal * (sum_r * sign);
    let bottom = k * sum_rq;
    ne.gradient = Vector6::new(top.x, top.y, top.z, bottom.x, bottom.y, bottom.z);
    ne
}

/// Point-to-line alignment: `sum rho(dist^2)` over every point of every group.
#[derive(Debug, Clone, PartialEq)]
pub struct PointToLine {
    groups: Vec<LineGroup>,
    loss: Loss,
    count: usize,
}

impl PointToLine {
    /// Builds the problem; fails on empty groups, non-finite points or an invalid loss.
    pub fn new(groups: Vec<LineGroup>, loss: Loss) -> Result<Self> {
        let count = checked_count("line", loss, groups.iter().map(|g| g.points.as_slice()))?;
        Ok(PointToLine {
            groups,
            loss,
            count,
        })
    }

    /// The groups.
    pub fn groups(&self) -> &[LineGroup] {
        &self.groups
    }

    /// The two residual components and their Jacobian rows for every point, group after group.
    pub fn residuals(&self, pose: &Isometry3<f64>) -> Vec<([f64; 2], [Vector6<f64>; 2])> {
        let mut out = Vec::with_capacity(self.count);
        for g in &self.groups {
            let term = LineTerm::new(g, pose);
            out.extend(g.points.iter().map(|p| term.residual(p)));
        }
        out
    }
}

struct LineTerm {
    frame: Frame,
    /// Point on the line and the two perpendicular unit vectors, in the reference frame.
    point: Vector3<f64>,
    basis: [Vector3<f64>; 2],
    pose: Isometry3<f64>,
}

impl LineTerm {
    fn new(group: &LineGroup, pose: &Isometry3<f64>) -> Self {
        let (e1, e2) = orthonormal_basis(&group.line.direction);
        match group.frame {
            Frame::Target => LineTerm {
                frame: Frame::Target,
                point: group.line.point.coords,
                basis: [e1, e2],
                pose: *pose,
            },
            Frame::Reference => LineTerm {
                frame: Frame::Reference,
                point: (pose * group.line.point).coords,
                basis: [pose.rotation * e1, pose.rotation * e2],
                pose: *pose,
            },
        }
    }

    #[inline]
    fn residual(&self, p: &Point3<f64>) -> ([f64; 2], [Vector6<f64>; 2]) {
        let mut r = [0.0; 2];
        let mut j = [Vector6::zeros(); 2];
        match self.frame {
            Frame::Target => {
                let q = (self.pose * p).coords;
                let offset = q - self.point;
                for k in 0..2 {
                    let e = &self.basis[k];
                    let c = q.cross(e);
                    r[k] = e.dot(&offset);
                    j[k] = Vector6::new(e.x, e.y, e.z, c.x, c.y, c.z);
                }
            }
            Frame::Reference => {
                let offset = p.coords - self.point;
                for k in 0..2 {
                    let e = &self.basis[k];
                    let c = e.cross(&p.coords);
                    r[k] = e.dot(&offset);
                    j[k] = Vector6::new(-e.x, -e.y, -e.z, c.x, c.y, c.z);
                }
            }
        }
        (r, j)
    }
}

impl LeastSquaresProblem for PointToLine {
    fn residual_count(&self) -> usize {
        2 * self.count
    }

    fn normal_equations(&self, pose: &Isometry3<f64>, with_derivatives: bool) -> NormalEquations {
        let loss = self.loss;
        let mut total = NormalEquations::default();
        for g in &self.groups {
            let term = LineTerm::new(g, pose);
            let part = accumulate(&g.points, |p, acc: &mut NormalEquations| {
                let (r, j) = term.residual(p);
                if with_derivatives {
                    acc.add_block(&r, &j, loss);
                } else {
                    acc.add_cost(r[0] * r[0] + r[1] * r[1], 2, loss);
                }
            });
            total.merge(&part);
        }
        total
    }
}

/// Points of one plane group summarised by their [`Moments`] (count, mean, scatter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneMomentGroup {
    /// The plane, in the frame opposite to `frame`.
    pub plane: Plane,
    /// Moments of the group's points, in `frame`.
    pub moments: Moments,
    /// The frame of the points.
    pub frame: Frame,
}

/// Point-to-plane alignment with the least-squares loss, evaluated from per-group sufficient
/// statistics: an evaluation costs O(groups), not O(points).
///
/// It is exact, not an approximation: a residual `r = n . q + d` and its Jacobian row
/// `[n, q x n]` are affine in the point `q`, so `sum r^2`, `sum r J` and `sum J J^T` are
/// polynomials of degree two in the points and depend on them only through the count, the sum and
/// the sum of outer products. (A robust loss reweights each point and needs [`PointToPlane`].)
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneMomentsProblem {
    groups: Vec<PlaneMomentGroup>,
    count: usize,
}

impl PlaneMomentsProblem {
    /// Builds the problem; fails when there is no group or a group has no points.
    pub fn new(groups: Vec<PlaneMomentGroup>) -> Result<Self> {
        if groups.is_empty() {
            return Err(Error::InvalidInput("no plane groups given".into()));
        }
        if let Some(i) = groups.iter().position(|g| g.moments.count() == 0) {
            return Err(Error::InvalidInput(format!(
                "plane group {i} has no points"
            )));
        }
        let count = groups.iter().map(|g| g.moments.count()).sum();
        Ok(PlaneMomentsProblem { groups, count })
    }

    /// Root-mean-square residual of each group at `pose`.
    pub fn group_rms(&self, pose: &Isometry3<f64>) -> Vec<f64> {
        self.groups
            .iter()
            .map(|g| {
                let stats = GroupStats::new(g, pose);
                (stats.sum_r2 / stats.n).sqrt() // weighted RMS when the moments are weighted
            })
            .collect()
    }
}

/// One group's statistics in the residual frame: residual `r = n . q + d` over points `q` with
/// count `n`, sum `sigma` and second moment `second` (sum q q^T), plus the Jacobian's sign.
struct GroupStats {
    n: f64,
    normal: Vector3<f64>,
    offset: f64,
    sigma: Vector3<f64>,
    second: Matrix3<f64>,
    sum_r2: f64,
    /// +1 for target points (J = [n, q x n]); -1 for reference points (J = [-m, m x p]).
    sign: f64,
}

impl GroupStats {
    fn new(g: &PlaneMomentGroup, pose: &Isometry3<f64>) -> Self {
        let n = g.moments.weight();
        let mean = g.moments.mean().coords;
        let scatter = g.moments.scatter();
        let (normal, offset, mean_q, scatter_q, sign) = match g.frame {
            Frame::Target => {
                // q = T p: the mean moves, the scatter rotates.
                let r = pose.rotation.to_rotation_matrix().into_inner();
                let mean_q = (pose * Point3::from(mean)).coords;
                (
                    g.plane.normal.into_inner(),
                    g.plane.offset,
                    mean_q,
                    r * scatter * r.transpose(),
                    1.0,
                )
            }
            Frame::Reference => {
                let plane = g.plane.transformed(pose);
                (plane.normal.into_inner(), plane.offset, mean, scatter, -1.0)
            }
        };
        let second = scatter_q + mean_q * mean_q.transpose() * n;
        let mean_r = normal.dot(&mean_q) + offset;
        let sum_r2 = (normal.transpose() * scatter_q * normal)[0] + n * mean_r * mean_r;
        GroupStats {
            n,
            normal,
            offset,
            sigma: mean_q * n,
            second,
            sum_r2: sum_r2.max(0.0),
            sign,
        }
    }
}

impl LeastSquaresProblem for PlaneMomentsProblem {
    fn residual_count(&self) -> usize {
        self.count
    }

    fn normal_equations(&self, pose: &Isometry3<f64>, with_derivatives: bool) -> NormalEquations {
        let mut ne = NormalEquations::default();
        for g in &self.groups {
            let s = GroupStats::new(g, pose);
            ne.cost += 0.5 * s.sum_r2;
            ne.residual_count += g.moments.count();
            if !with_derivatives {
                continue;
            }
            let part =
                plane_normal_equations(&s.normal, s.offset, s.sign, s.n, &s.sigma, &s.second);
            ne.hessian += part.hessian;
            ne.gradient += part.gradient;
        }
        ne
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{rotation_angle, se3_exp};
    use crate::lm::{solve, LmOptions, Termination};
    use nalgebra::Vector6;

    fn pose() -> Isometry3<f64> {
        se3_exp(&Vector6::new(0.7, -1.3, 0.4, 0.6, -0.9, 2.2))
    }

    fn sample_points(seed: u64, n: usize) -> Vec<Point3<f64>> {
        // A small deterministic generator keeps these unit tests free of RNG crates.
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 8.0 - 4.0
        };
        (0..n)
            .map(|_| Point3::new(next(), next(), next()))
            .collect()
    }

    /// Central-difference Jacobian of `f` with respect to the left perturbation of `pose`.
    fn numeric_jacobian<const K: usize>(
        pose: &Isometry3<f64>,
        f: impl Fn(&Isometry3<f64>) -> [f64; K],
    ) -> [Vector6<f64>; K] {
        let h = 1e-6;
        let mut j = [Vector6::zeros(); K];
        for i in 0..6 {
            let mut d = Vector6::zeros();
            d[i] = h;
            let plus = f(&(se3_exp(&d) * pose));
            let minus = f(&(se3_exp(&-d) * pose));
            for k in 0..K {
                j[k][i] = (plus[k] - minus[k]) / (2.0 * h);
            }
        }
        j
    }

    #[test]
    fn plane_jacobians_match_central_differences() {
        let plane = Plane::new(Vector3::new(0.3, -0.5, 0.8), 1.7).unwrap();
        for frame in [Frame::Target, Frame::Reference] {
            let points = sample_points(1, 25);
            let problem = PointToPlane::new(
                vec![PlaneGroup {
                    plane,
                    points: points.clone(),
                    frame,
                }],
                Loss::Squared,
            )
            .unwrap();
            let analytic = problem.residuals(&pose());
            for (i, (r, j)) in analytic.iter().enumerate() {
                let single = |t: &Isometry3<f64>| [problem.residuals(t)[i].0];
                let numeric = numeric_jacobian(&pose(), single);
                let err = (numeric[0] - j).amax();
                assert!(err < 1e-7, "{frame:?} point {i}: |J - J_num| = {err:e}");
                // The residual is the signed distance in the stated frame.
                let expected = match frame {
                    Frame::Target => plane.signed_distance(&(pose() * points[i])),
                    Frame::Reference => plane.signed_distance(&(pose().inverse() * points[i])),
                };
                assert!((r - expected).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn line_jacobians_match_central_differences() {
        let line = Line::new(Point3::new(1.0, -2.0, 0.5), Vector3::new(0.2, 0.1, 0.97)).unwrap();
        for frame in [Frame::Target, Frame::Reference] {
            let points = sample_points(2, 25);
            let problem = PointToLine::new(
                vec![LineGroup {
                    line,
                    points: points.clone(),
                    frame,
                }],
                Loss::Squared,
            )
            .unwrap();
            let analytic = problem.residuals(&pose());
            for (i, (r, j)) in analytic.iter().enumerate() {
                let single = |t: &Isometry3<f64>| problem.residuals(t)[i].0;
                let numeric = numeric_jacobian(&pose(), single);
                for k in 0..2 {
                    let err = (numeric[k] - j[k]).amax();
                    assert!(err < 1e-7, "{frame:?} point {i} row {k}: {err:e}");
                }
                let expected = match frame {
                    Frame::Target => line.distance(&(pose() * points[i])),
                    Frame::Reference => line.distance(&(pose().inverse() * points[i])),
                };
                assert!((r[0].hypot(r[1]) - expected).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn normal_equations_equal_dense_sums() {
        let plane = Plane::new(Vector3::new(0.3, -0.5, 0.8), 1.7).unwrap();
        let groups = vec![
            PlaneGroup {
                plane,
                points: sample_points(3, 5000),
                frame: Frame::Target,
            },
            PlaneGroup {
                plane: plane.flipped(),
                points: sample_points(4, 300),
                frame: Frame::Reference,
            },
        ];
        let loss = Loss::Huber { delta: 0.5 };
        let problem = PointToPlane::new(groups, loss).unwrap();
        let mut ne = problem.normal_equations(&pose(), true);
        ne.symmetrize();
        let mut h = nalgebra::Matrix6::zeros();
        let mut g = Vector6::zeros();
        let mut cost = 0.0;
        for (r, j) in problem.residuals(&pose()) {
            let (rho, w) = loss.evaluate(r * r);
            cost += 0.5 * rho;
            g += j * (w * r);
            h += j * j.transpose() * w;
        }
        assert!((ne.cost - cost).abs() < 1e-9 * cost);
        assert!((ne.gradient - g).amax() < 1e-8 * g.amax());
        assert!((ne.hessian - h).amax() < 1e-8 * h.amax());
        let cost_only = problem.normal_equations(&pose(), false);
        assert!((cost_only.cost - cost).abs() < 1e-9 * cost);
        assert_eq!(ne.residual_count, 5300);
    }

    #[test]
    fn lm_recovers_pose_from_lines_with_robust_loss() {
        // Three skew lines determine the pose; a few gross outliers are tamed by Cauchy.
        let truth = se3_exp(&Vector6::new(0.3, 0.2, -0.1, 0.1, 0.2, -0.3));
        let lines = [
            Line::new(Point3::new(0.0, 0.0, 0.0), Vector3::z()).unwrap(),
            Line::new(Point3::new(2.0, 0.0, 0.0), Vector3::y()).unwrap(),
            Line::new(Point3::new(0.0, 3.0, 1.0), Vector3::x()).unwrap(),
        ];
        let groups = lines
            .iter()
            .enumerate()
            .map(|(k, line)| {
                let mut points: Vec<_> = (0..50)
                    .map(|i| {
                        truth.inverse()
                            * (line.point + line.direction.into_inner() * (i as f64 * 0.1 - 2.5))
                    })
                    .collect();
                points[7] += Vector3::new(0.5, -0.4, 0.3) * (k + 1) as f64;
                LineGroup {
                    line: *line,
                    points,
                    frame: Frame::Target,
                }
            })
            .collect();
        let problem = PointToLine::new(groups, Loss::Cauchy { scale: 0.01 }).unwrap();
        let sol = solve(&problem, &Isometry3::identity(), &LmOptions::default()).unwrap();
        assert!(sol.report.converged());
        let r_err =
            rotation_angle(&(truth.rotation * sol.pose.rotation.inverse()).to_rotation_matrix());
        let t_err = (truth.translation.vector - sol.pose.translation.vector).norm();
        assert!(r_err < 1e-4 && t_err < 1e-4, "{r_err} {t_err}");
    }

    #[test]
    fn symmetric_plane_problem_converges_from_far() {
        let truth = se3_exp(&Vector6::new(1.0, -2.0, 0.5, 0.4, -0.3, 1.2));
        let planes = [
            Plane::new(Vector3::new(1.0, 0.0, 0.2), -3.0).unwrap(),
            Plane::new(Vector3::new(0.1, 1.0, 0.0), -2.0).unwrap(),
            Plane::new(Vector3::new(0.0, 0.1, 1.0), 1.5).unwrap(),
        ];
        let mut groups = Vec::new();
        for (k, plane_ref) in planes.iter().enumerate() {
            let on_ref: Vec<_> = sample_points(10 + k as u64, 200)
                .iter()
                .map(|p| plane_ref.project(p))
                .collect();
            let plane_tgt = plane_ref.transformed(&truth.inverse());
            groups.push(PlaneGroup {
                plane: *plane_ref,
                points: on_ref.iter().map(|p| truth.inverse() * p).collect(),
                frame: Frame::Target,
            });
            groups.push(PlaneGroup {
                plane: plane_tgt,
                points: on_ref,
                frame: Frame::Reference,
            });
        }
        let problem = PointToPlane::new(groups, Loss::Squared).unwrap();
        let sol = solve(&problem, &Isometry3::identity(), &LmOptions::default()).unwrap();
        assert!(sol.report.converged(), "{:?}", sol.report);
        assert_ne!(sol.report.termination, Termination::MaxIterations);
        assert!((sol.pose.to_homogeneous() - truth.to_homogeneous()).amax() < 1e-9);
        assert!(sol.report.final_cost < 1e-18);
        assert!(sol.report.initial_cost > 1.0);
    }

    #[test]
    fn moments_problem_is_exact() {
        let plane = Plane::new(Vector3::new(0.3, -0.5, 0.8), 1.7).unwrap();
        let other = Plane::new(Vector3::new(-0.6, 0.1, 0.2), -4.0).unwrap();
        let groups = vec![
            PlaneGroup {
                plane,
                points: sample_points(21, 3000),
                frame: Frame::Target,
            },
            PlaneGroup {
                plane: other,
                points: sample_points(22, 700)
                    .iter()
                    .map(|p| p + Vector3::new(40.0, -25.0, 3.0))
                    .collect(),
                frame: Frame::Reference,
            },
        ];
        let pointwise = PointToPlane::new(groups.clone(), Loss::Squared).unwrap();
        let moments = PlaneMomentsProblem::new(
            groups
                .iter()
                .map(|g| PlaneMomentGroup {
                    plane: g.plane,
                    moments: Moments::from_points(&g.points),
                    frame: g.frame,
                })
                .collect(),
        )
        .unwrap();
        for pose in [pose(), Isometry3::identity(), pose().inverse()] {
            let mut a = pointwise.normal_equations(&pose, true);
            a.symmetrize();
            let b = moments.normal_equations(&pose, true);
            assert!(
                (a.cost - b.cost).abs() < 1e-10 * a.cost,
                "{} {}",
                a.cost,
                b.cost
            );
            assert!((a.gradient - b.gradient).amax() < 1e-10 * a.gradient.amax());
            assert!((a.hessian - b.hessian).amax() < 1e-10 * a.hessian.amax());
            assert_eq!(a.residual_count, b.residual_count);
            let c = moments.normal_equations(&pose, false);
            assert!((c.cost - a.cost).abs() < 1e-10 * a.cost);
        }
        let rms = moments.group_rms(&pose());
        let direct: Vec<f64> = groups
            .iter()
            .map(|g| {
                let single = PointToPlane::new(vec![g.clone()], Loss::Squared).unwrap();
                let r = single.residuals(&pose());
                (r.iter().map(|(r, _)| r * r).sum::<f64>() / r.len() as f64).sqrt()
            })
            .collect();
        for (a, b) in rms.iter().zip(&direct) {
            assert!((a - b).abs() < 1e-9 * b);
        }
    }

    #[test]
    fn bad_groups_are_rejected() {
        let plane = Plane::new(Vector3::z(), 0.0).unwrap();
        assert!(PointToPlane::new(vec![], Loss::Squared).is_err());
        let empty = PlaneGroup {
            plane,
            points: vec![],
            frame: Frame::Target,
        };
        assert!(PointToPlane::new(vec![empty], Loss::Squared).is_err());
        let nan = PlaneGroup {
            plane,
            points: vec![Point3::new(f64::NAN, 0.0, 0.0)],
            frame: Frame::Target,
        };
        assert!(PointToPlane::new(vec![nan], Loss::Squared).is_err());
        let ok = PlaneGroup {
            plane,
            points: vec![Point3::origin()],
            frame: Frame::Target,
        };
        assert!(PointToPlane::new(vec![ok], Loss::Huber { delta: -1.0 }).is_err());
    }
}
