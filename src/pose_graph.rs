//! A small SE(3) pose graph: several poses made consistent with measured relative transforms.
//!
//! Node `i` holds a pose `T_i = reference_from_i`; node 0 is the reference and stays fixed (it
//! anchors the gauge). An edge ([`PoseGraphEdge`]) measures `Z = a_from_b` between nodes `a` and
//! `b` with an information matrix `W` (inverse covariance). Its error is the SE(3) tangent
//!
//! ```text
//! e = log(Z⁻¹ · T_a⁻¹ · T_b)        (translation first, then rotation; see edge_error)
//! ```
//!
//! which is zero when the poses agree with the measurement, and the cost is `F = Σ eᵀ W e` over
//! the edges (no factor 1/2, unlike [`crate::lm`]).
//!
//! [`refine_pose_graph`] minimises `F` by Gauss–Newton. Every free node (1, 2, ...) is perturbed on
//! the left, `T ← exp(δ) · T` with `δ = [rho; phi]` (see [`crate::geometry`]), so a graph of `n`
//! nodes has `6 (n - 1)` unknowns; the Jacobians are central differences of `e` with step
//! [`PoseGraphOptions::jacobian_step`]. Each iteration solves the normal equations (dense
//! Cholesky, with [`PoseGraphOptions::damping`] added to the diagonal) and takes the longest of
//! the steps `1, 1/2, 1/4, ...` (at most [`PoseGraphOptions::line_search_trials`] of them) that
//! does not raise the cost.
//!
//! The [`PoseGraphReport`] beside the poses says why the solve stopped ([`PoseGraphTermination`]).
//! It has **converged** when an accepted step moved the poses by less than
//! [`PoseGraphOptions::step_tolerance`] (tangent norm), when no step along the Gauss–Newton
//! direction kept the cost from rising (a minimum to rounding), or when there was nothing to
//! refine (no edges, or no node but the reference); it has not when
//! [`PoseGraphOptions::max_iterations`] ran out first. The cost never rises from one iteration
//! to the next, so `final_cost <= initial_cost` always.
//!
//! ```
//! use lidarcal::pose_graph::{refine_pose_graph, PoseGraphEdge, PoseGraphOptions};
//! use nalgebra::{Isometry3, Matrix6};
//!
//! // Node 1 measured 1 m along x of the reference, node 2 1 m along x of node 1, and node 2
//! // 2.1 m along x of the reference: the 10 cm misclosure is shared by the three edges.
//! let edge = |a, b, x| PoseGraphEdge {
//!     a,
//!     b,
//!     a_from_b: Isometry3::translation(x, 0.0, 0.0),
//!     information: Matrix6::identity(),
//! };
//! let edges = [edge(0, 1, 1.0), edge(1, 2, 1.0), edge(0, 2, 2.1)];
//! let start = [
//!     Isometry3::identity(),
//!     Isometry3::translation(1.0, 0.0, 0.0),
//!     Isometry3::translation(2.0, 0.0, 0.0),
//! ];
//! let solution = refine_pose_graph(&start, &edges, &PoseGraphOptions::default())?;
//! assert!(solution.report.converged);
//! assert!(solution.report.final_cost < solution.report.initial_cost);
//! assert!((solution.poses[2].translation.x - 2.0667).abs() < 1e-3);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use nalgebra::{DMatrix, DVector, Isometry3, Matrix6, Vector6};

use crate::geometry::{se3_exp, se3_log};
use crate::{Error, Result};

/// An edge of a pose graph: a measurement of `a_from_b` between nodes `a` and `b`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseGraphEdge {
    /// Index of node `a`.
    pub a: usize,
    /// Index of node `b`.
    pub b: usize,
    /// The measured transform mapping `b`'s points into `a`'s frame.
    pub a_from_b: Isometry3<f64>,
    /// Information matrix (inverse covariance) of the left-perturbation tangent `[rho, phi]`.
    pub information: Matrix6<f64>,
}

/// Options of [`refine_pose_graph`]; the defaults are what the rig calibration uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseGraphOptions {
    /// Gauss–Newton iterations at most (default 20); 0 returns the start unchanged.
    pub max_iterations: usize,
    /// Stop (converged) once an accepted step moves the poses by less than this tangent norm
    /// (default `1e-10`).
    pub step_tolerance: f64,
    /// Step of the central differences of the Jacobians, in the tangent (default `1e-6`).
    pub jacobian_step: f64,
    /// Added to the diagonal of the normal equations before solving (default `1e-9`).
    pub damping: f64,
    /// Step lengths `1, 1/2, 1/4, ...` tried per iteration before giving up on a step that does
    /// not raise the cost (default 20).
    pub line_search_trials: usize,
}

impl Default for PoseGraphOptions {
    fn default() -> Self {
        PoseGraphOptions {
            max_iterations: 20,
            step_tolerance: 1e-10,
            jacobian_step: 1e-6,
            damping: 1e-9,
            line_search_trials: 20,
        }
    }
}

impl PoseGraphOptions {
    /// `Err(InvalidInput)` naming the first bad option: a non-finite or negative
    /// `step_tolerance` or `damping`, a non-finite or non-positive `jacobian_step`, or no
    /// `line_search_trials`.
    pub fn validate(&self) -> Result<()> {
        let bad = |name: &str, must: &str, v: f64| {
            Err(Error::InvalidInput(format!(
                "pose graph option {name} must be {must}, got {v}"
            )))
        };
        if !(self.step_tolerance.is_finite() && self.step_tolerance >= 0.0) {
            return bad("step_tolerance", "finite and >= 0", self.step_tolerance);
        }
        if !(self.jacobian_step.is_finite() && self.jacobian_step > 0.0) {
            return bad("jacobian_step", "finite and positive", self.jacobian_step);
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return bad("damping", "finite and >= 0", self.damping);
        }
        if self.line_search_trials == 0 {
            return Err(Error::InvalidInput(
                "pose graph option line_search_trials must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// Why [`refine_pose_graph`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PoseGraphTermination {
    /// An accepted step was shorter than [`PoseGraphOptions::step_tolerance`].
    StepTolerance,
    /// No step along the Gauss–Newton direction kept the cost from rising: a minimum to rounding.
    NoFurtherDecrease,
    /// Nothing to refine: no edges, or no node besides the reference.
    NothingToRefine,
    /// [`PoseGraphOptions::max_iterations`] ran out first.
    MaxIterations,
}

impl PoseGraphTermination {
    /// `true` for every reason except [`PoseGraphTermination::MaxIterations`].
    pub fn converged(&self) -> bool {
        !matches!(self, PoseGraphTermination::MaxIterations)
    }

    /// A short lower-case name (`"step_tolerance"`, ...).
    pub fn as_str(&self) -> &'static str {
        match self {
            PoseGraphTermination::StepTolerance => "step_tolerance",
            PoseGraphTermination::NoFurtherDecrease => "no_further_decrease",
            PoseGraphTermination::NothingToRefine => "nothing_to_refine",
            PoseGraphTermination::MaxIterations => "max_iterations",
        }
    }
}

/// What [`refine_pose_graph`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseGraphReport {
    /// `termination.converged()`: the solve stopped for any reason but the iteration cap.
    pub converged: bool,
    /// Why it stopped.
    pub termination: PoseGraphTermination,
    /// Gauss–Newton iterations run (normal equations solved), including a last one whose line
    /// search found no step.
    pub iterations: usize,
    /// Cost `Σ eᵀ W e` at the start.
    pub initial_cost: f64,
    /// Cost at the returned poses (never above `initial_cost`).
    pub final_cost: f64,
}

/// The result of [`refine_pose_graph`].
#[derive(Debug, Clone, PartialEq)]
pub struct PoseGraphSolution {
    /// The refined poses `reference_from_node`, node 0 unchanged.
    pub poses: Vec<Isometry3<f64>>,
    /// Diagnostics.
    pub report: PoseGraphReport,
}

/// Tangent error `log(z⁻¹ · a⁻¹ · b)` of an edge measuring `z = a_from_b` against poses `a`, `b`
/// (each `reference_from_node`): translation first, then rotation.
pub fn edge_error(
    a_from_b: &Isometry3<f64>,
    reference_from_a: &Isometry3<f64>,
    reference_from_b: &Isometry3<f64>,
) -> Vector6<f64> {
    se3_log(&(a_from_b.inverse() * reference_from_a.inverse() * reference_from_b))
}

/// The cost `Σ eᵀ W e` of `poses` over `edges` (every edge's nodes must exist).
fn graph_cost(poses: &[Isometry3<f64>], edges: &[PoseGraphEdge]) -> f64 {
    edges
        .iter()
        .map(|e| {
            let r = edge_error(&e.a_from_b, &poses[e.a], &poses[e.b]);
            (r.transpose() * e.information * r)[(0, 0)]
        })
        .sum()
}

/// `Err(InvalidInput)` for an edge joining a node to itself or to a node out of range, an
/// information matrix that is not finite and symmetric, or a node (other than the fixed first)
/// in no edge.
fn validate_graph(poses: &[Isometry3<f64>], edges: &[PoseGraphEdge]) -> Result<()> {
    for (k, e) in edges.iter().enumerate() {
        if e.a >= poses.len() || e.b >= poses.len() || e.a == e.b {
            return Err(Error::InvalidInput(format!(
                "edge {k} joins nodes {} and {} of a graph with {} nodes",
                e.a,
                e.b,
                poses.len()
            )));
        }
        if e.information.iter().any(|v| !v.is_finite())
            || (e.information - e.information.transpose()).amax()
                > 1e-9 * e.information.amax().max(1.0)
        {
            return Err(Error::InvalidInput(format!(
                "edge {k}: the information matrix must be finite and symmetric"
            )));
        }
    }
    if let Some(lonely) = (1..poses.len()).find(|&n| !edges.iter().any(|e| e.a == n || e.b == n)) {
        return Err(Error::InvalidInput(format!(
            "node {lonely} is in no edge: nothing places it"
        )));
    }
    Ok(())
}

/// The damped Gauss-Newton normal equations `(J^T W J + damping I, J^T W e)` of the graph at
/// `current` (every node but the first free), the Jacobian by central differences of
/// [`edge_error`] under a left perturbation of each free node.
fn normal_equations(
    current: &[Isometry3<f64>],
    edges: &[PoseGraphEdge],
    options: &PoseGraphOptions,
) -> (DMatrix<f64>, DVector<f64>) {
    let size = 6 * current.len().saturating_sub(1);
    let h = options.jacobian_step;
    let mut hessian = DMatrix::<f64>::zeros(size, size);
    let mut gradient = DVector::<f64>::zeros(size);
    for e in edges {
        let e0 = edge_error(&e.a_from_b, &current[e.a], &current[e.b]);
        let mut jac = DMatrix::<f64>::zeros(6, size);
        for node in [e.a, e.b] {
            if node == 0 {
                continue;
            }
            for d in 0..6 {
                let mut delta = Vector6::zeros();
                delta[d] = h;
                let moved = |sign: f64| {
                    let step = se3_exp(&(delta * sign));
                    let (mut pa, mut pb) = (current[e.a], current[e.b]);
                    if node == e.a {
                        pa = step * pa;
                    } else {
                        pb = step * pb;
                    }
                    edge_error(&e.a_from_b, &pa, &pb)
                };
                let column = (moved(1.0) - moved(-1.0)) / (2.0 * h);
                for r in 0..6 {
                    jac[(r, 6 * (node - 1) + d)] = column[r];
                }
            }
        }
        let w = DMatrix::from_iterator(6, 6, e.information.iter().copied());
        let e0 = DVector::from_iterator(6, e0.iter().copied());
        let jtw = jac.transpose() * w;
        hessian += &jtw * &jac;
        gradient += &jtw * e0;
    }
    for i in 0..size {
        hessian[(i, i)] += options.damping;
    }
    (hessian, gradient)
}

/// Refines the poses `reference_from_node` of a pose graph whose node 0 (the reference) is fixed:
/// minimises `Σ eᵀ W e` over the edges by Gauss–Newton (see the [module docs](self)). Returns the
/// refined poses, node 0 unchanged, and a [`PoseGraphReport`]. `Err(InvalidInput)` for bad
/// `options`, an edge naming a missing node, a self-loop, a non-finite or non-symmetric
/// information matrix, or a node in no edge; `Err(Degenerate)` when the information does not
/// constrain every node.
pub fn refine_pose_graph(
    poses: &[Isometry3<f64>],
    edges: &[PoseGraphEdge],
    options: &PoseGraphOptions,
) -> Result<PoseGraphSolution> {
    options.validate()?;
    validate_graph(poses, edges)?;
    let mut current = poses.to_vec();
    let free = poses.len().saturating_sub(1);
    let mut cost = graph_cost(&current, edges);
    let mut report = PoseGraphReport {
        converged: true,
        termination: PoseGraphTermination::NothingToRefine,
        iterations: 0,
        initial_cost: cost,
        final_cost: cost,
    };
    if free == 0 || edges.is_empty() {
        return Ok(PoseGraphSolution {
            poses: current,
            report,
        });
    }
    let mut termination = PoseGraphTermination::MaxIterations;
    for _ in 0..options.max_iterations {
        report.iterations += 1;
        let (hessian, gradient) = normal_equations(&current, edges, options);
        let Some(step) = hessian.cholesky().map(|c| -c.solve(&gradient)) else {
            return Err(Error::Degenerate(
                "the pose graph does not constrain every node (an information matrix is not \
                 positive definite)"
                    .into(),
            ));
        };
        let mut scale = 1.0;
        let mut accepted = None;
        for _ in 0..options.line_search_trials {
            let mut trial = current.clone();
            for (node, pose) in trial.iter_mut().enumerate().skip(1) {
                let s = step.rows(6 * (node - 1), 6) * scale;
                *pose = se3_exp(&Vector6::from_iterator(s.iter().copied())) * *pose;
            }
            let c = graph_cost(&trial, edges);
            if c.is_finite() && c <= cost {
                accepted = Some((trial, c));
                break;
            }
            scale *= 0.5;
        }
        let Some((trial, c)) = accepted else {
            termination = PoseGraphTermination::NoFurtherDecrease;
            break;
        };
        let moved = step.norm() * scale;
        current = trial;
        cost = c;
        if moved < options.step_tolerance {
            termination = PoseGraphTermination::StepTolerance;
            break;
        }
    }
    report.termination = termination;
    report.converged = termination.converged();
    report.final_cost = cost;
    Ok(PoseGraphSolution {
        poses: current,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn pose(t: [f64; 3], axis: [f64; 3], angle: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_scaled_axis(Vector3::from(axis).normalize() * angle),
        )
    }

    /// Rotation angle and translation distance between two poses.
    fn pose_error(x: &Isometry3<f64>, y: &Isometry3<f64>) -> (f64, f64) {
        let d = x.inverse() * y;
        (d.rotation.angle(), d.translation.vector.norm())
    }

    /// Nodes 1 and 2 measured from the reference (`a`, `b`) and from each other (`ab`, weighted
    /// `w_ab`), all information matrices the identity otherwise.
    fn triangle(
        a: Isometry3<f64>,
        b: Isometry3<f64>,
        ab: Isometry3<f64>,
        w_ab: f64,
    ) -> Vec<PoseGraphEdge> {
        let eye = Matrix6::identity();
        vec![
            PoseGraphEdge {
                a: 0,
                b: 1,
                a_from_b: a,
                information: eye,
            },
            PoseGraphEdge {
                a: 0,
                b: 2,
                a_from_b: b,
                information: eye,
            },
            PoseGraphEdge {
                a: 1,
                b: 2,
                a_from_b: ab,
                information: eye * w_ab,
            },
        ]
    }

    fn with_iterations(max_iterations: usize) -> PoseGraphOptions {
        PoseGraphOptions {
            max_iterations,
            ..PoseGraphOptions::default()
        }
    }

    #[test]
    fn consistent_graph_stays_put_and_a_cycle_error_is_shared_by_weight() {
        let a = pose([1.0, 0.5, 0.2], [0.0, 0.0, 1.0], 0.4);
        let b = pose([-1.0, 0.3, 0.1], [0.2, 1.0, 0.0], -0.3);
        let edges = |ab: Isometry3<f64>, w_ab: f64| triangle(a, b, ab, w_ab);
        let truth = a.inverse() * b;
        let start = [Isometry3::identity(), a, b];
        let options = with_iterations(20);
        let out = refine_pose_graph(&start, &edges(truth, 1.0), &options).unwrap();
        for (x, y) in out.poses.iter().zip(&start) {
            let (r, t) = pose_error(x, y);
            assert!(r < 1e-9 && t < 1e-9, "{r} {t}");
        }
        // A 3 cm error on the a-b edge: with equal weights it is shared, with a heavy weight
        // the graph follows that edge.
        let off = Isometry3::translation(0.03, 0.0, 0.0) * truth;
        let shared = refine_pose_graph(&start, &edges(off, 1.0), &options)
            .unwrap()
            .poses;
        let residual = |p: &[Isometry3<f64>]| edge_error(&off, &p[1], &p[2]).norm();
        let heavy = refine_pose_graph(&start, &edges(off, 1e6), &options)
            .unwrap()
            .poses;
        assert!(residual(&shared) > 0.005 && residual(&shared) < 0.025);
        assert!(residual(&heavy) < 1e-4, "{}", residual(&heavy));
        assert_eq!(shared[0], Isometry3::identity());
        // The cost went down from the start.
        assert!(graph_cost(&shared, &edges(off, 1.0)) < graph_cost(&start, &edges(off, 1.0)));
    }

    #[test]
    fn the_report_says_how_the_solve_went() {
        let a = pose([1.0, 0.5, 0.2], [0.0, 0.0, 1.0], 0.4);
        let b = pose([-1.0, 0.3, 0.1], [0.2, 1.0, 0.0], -0.3);
        let truth = a.inverse() * b;
        let options = PoseGraphOptions::default();
        // Consistent measurements, a disturbed start: back to the truth, the cost to ~0.
        let edges = triangle(a, b, truth, 1.0);
        let start = [
            Isometry3::identity(),
            Isometry3::translation(0.02, -0.01, 0.0) * a,
            pose([0.0; 3], [1.0, 0.0, 0.0], 0.01) * b,
        ];
        let solution = refine_pose_graph(&start, &edges, &options).unwrap();
        let report = solution.report;
        assert!(report.converged, "{report:?}");
        assert!(report.termination.converged());
        assert!(report.iterations > 0 && report.iterations <= options.max_iterations);
        assert!(report.final_cost <= report.initial_cost, "{report:?}");
        assert!(
            report.initial_cost > 1e-4 && report.final_cost < 1e-12,
            "{report:?}"
        );
        assert_eq!(report.initial_cost, graph_cost(&start, &edges));
        assert_eq!(report.final_cost, graph_cost(&solution.poses, &edges));
        for (x, y) in solution
            .poses
            .iter()
            .zip([Isometry3::identity(), a, b].iter())
        {
            let (r, t) = pose_error(x, y);
            assert!(r < 1e-9 && t < 1e-9, "{r} {t}");
        }
        // Already at the minimum: one iteration, a step of nothing.
        let at_rest = refine_pose_graph(&[Isometry3::identity(), a, b], &edges, &options)
            .unwrap()
            .report;
        assert!(at_rest.converged && at_rest.iterations >= 1, "{at_rest:?}");
        // One iteration is not enough from the disturbed start, and says so.
        let capped = refine_pose_graph(&start, &edges, &with_iterations(1))
            .unwrap()
            .report;
        assert_eq!(capped.termination, PoseGraphTermination::MaxIterations);
        assert!(!capped.converged && capped.iterations == 1);
        assert!(capped.final_cost < capped.initial_cost);
        // No iterations: the start, unchanged.
        let none = refine_pose_graph(&start, &edges, &with_iterations(0)).unwrap();
        assert_eq!(none.poses, start.to_vec());
        assert!(!none.report.converged && none.report.iterations == 0);
        assert_eq!(none.report.final_cost, none.report.initial_cost);
        // Only the reference: nothing to do.
        let alone = refine_pose_graph(&[a], &[], &options).unwrap();
        assert_eq!(alone.poses, vec![a]);
        assert_eq!(
            alone.report.termination,
            PoseGraphTermination::NothingToRefine
        );
        assert!(alone.report.converged && alone.report.iterations == 0);
        assert_eq!(alone.report.termination.as_str(), "nothing_to_refine");
    }

    #[test]
    fn options_are_validated() {
        assert_eq!(PoseGraphOptions::default().validate(), Ok(()));
        let zero_iterations = with_iterations(0);
        assert_eq!(zero_iterations.validate(), Ok(()));
        let bad = [
            PoseGraphOptions {
                step_tolerance: -1.0,
                ..PoseGraphOptions::default()
            },
            PoseGraphOptions {
                step_tolerance: f64::NAN,
                ..PoseGraphOptions::default()
            },
            PoseGraphOptions {
                jacobian_step: 0.0,
                ..PoseGraphOptions::default()
            },
            PoseGraphOptions {
                jacobian_step: f64::INFINITY,
                ..PoseGraphOptions::default()
            },
            PoseGraphOptions {
                damping: -1e-9,
                ..PoseGraphOptions::default()
            },
            PoseGraphOptions {
                line_search_trials: 0,
                ..PoseGraphOptions::default()
            },
        ];
        let names = [
            "step_tolerance",
            "step_tolerance",
            "jacobian_step",
            "jacobian_step",
            "damping",
            "line_search_trials",
        ];
        let poses = [Isometry3::identity(); 2];
        let edge = PoseGraphEdge {
            a: 0,
            b: 1,
            a_from_b: Isometry3::identity(),
            information: Matrix6::identity(),
        };
        for (options, name) in bad.iter().zip(names) {
            assert!(
                matches!(options.validate(), Err(Error::InvalidInput(ref m)) if m.contains(name)),
                "{options:?}"
            );
            // refine_pose_graph checks them first.
            assert!(matches!(
                refine_pose_graph(&poses, std::slice::from_ref(&edge), options),
                Err(Error::InvalidInput(m)) if m.contains(name)
            ));
        }
    }

    #[test]
    fn bad_graphs_are_errors() {
        let e = PoseGraphEdge {
            a: 0,
            b: 3,
            a_from_b: Isometry3::identity(),
            information: Matrix6::identity(),
        };
        let options = with_iterations(5);
        let poses = [Isometry3::identity(); 2];
        assert!(matches!(
            refine_pose_graph(&poses, std::slice::from_ref(&e), &options),
            Err(Error::InvalidInput(_))
        ));
        let mut nan = e.clone();
        nan.b = 1;
        nan.information[(0, 0)] = f64::NAN;
        assert!(matches!(
            refine_pose_graph(&poses, &[nan], &options),
            Err(Error::InvalidInput(_))
        ));
        // Node 2 is in no edge.
        let mut one = e;
        one.b = 1;
        let three = [Isometry3::identity(); 3];
        assert!(matches!(
            refine_pose_graph(&three, &[one], &options),
            Err(Error::InvalidInput(m)) if m.contains("node 2")
        ));
    }
}
