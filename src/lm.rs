//! Levenberg–Marquardt over a rigid transform.
//!
//! The unknown is a pose `T` (an [`Isometry3`]); an iteration solves for a tangent step
//! `delta = [rho; phi]` and updates by a **left** perturbation, `T <- exp(delta) * T`
//! (see [`crate::geometry`]). A problem implements [`LeastSquaresProblem`]: it accumulates the
//! Gauss–Newton normal equations `J^T W J`, `J^T W r` and the cost at a pose, so it never has to
//! store the Jacobian (the point-to-plane problem of [`crate::residuals`] streams over its points).
//!
//! The cost is `F = 1/2 sum_i rho(|r_i|^2)` with `rho` the [`Loss`] (identity for least squares),
//! the convention of Ceres and SciPy. Robust losses use iteratively reweighted normal equations
//! (`W = rho'`).
//!
//! Damping follows Nielsen (1999): `(J^T W J + mu D) delta = -g` with `D` the (floored) diagonal of
//! `J^T W J`, so the damping is invariant to the different units of rotation and translation; after
//! a step with gain ratio `q > 0`, `mu *= max(1/3, 1 - (2q - 1)^3)`; after a rejected step `mu *= nu`,
//! `nu *= 2`.
//!
//! The solve stops on the first of: gradient below [`LmOptions::gradient_tolerance`], step below
//! [`LmOptions::step_tolerance`], relative cost decrease below [`LmOptions::cost_tolerance`],
//! damping overflow (no step reduces the cost any more), or [`LmOptions::max_iterations`]. The
//! [`LmReport`] says which, and carries `J^T W J` at the solution for a covariance.

use nalgebra::{Isometry3, Matrix6, Vector6};

use crate::error::{Error, Result};
use crate::geometry::se3_exp;

/// A robust loss `rho(s)` applied to the squared residual `s = |r|^2` of each point.
///
/// Scaled as SciPy's `least_squares` with `f_scale`: `Huber { delta }` is quadratic up to
/// `|r| = delta`, linear beyond; `Cauchy { scale }` is `scale^2 ln(1 + s / scale^2)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Loss {
    /// Plain least squares, `rho(s) = s`.
    #[default]
    Squared,
    /// Huber: `s` for `s <= delta^2`, `2 delta sqrt(s) - delta^2` beyond.
    Huber {
        /// Residual magnitude where the loss turns linear (same units as the residual).
        delta: f64,
    },
    /// Cauchy: `scale^2 ln(1 + s / scale^2)`.
    Cauchy {
        /// Residual scale (same units as the residual).
        scale: f64,
    },
}

impl Loss {
    /// `(rho(s), rho'(s))` for a squared residual `s >= 0`.
    #[inline]
    pub fn evaluate(&self, s: f64) -> (f64, f64) {
        match *self {
            Loss::Squared => (s, 1.0),
            Loss::Huber { delta } => {
                if s <= delta * delta {
                    (s, 1.0)
                } else {
                    let r = s.sqrt();
                    (2.0 * delta * r - delta * delta, delta / r)
                }
            }
            Loss::Cauchy { scale } => {
                let c2 = scale * scale;
                (c2 * (s / c2).ln_1p(), 1.0 / (1.0 + s / c2))
            }
        }
    }

    /// `rho'(s)` alone: the IRLS weight, without the logarithm or root of the cost.
    #[inline]
    pub fn weight(&self, s: f64) -> f64 {
        match *self {
            Loss::Squared => 1.0,
            Loss::Huber { delta } => {
                if s <= delta * delta {
                    1.0
                } else {
                    delta / s.sqrt()
                }
            }
            Loss::Cauchy { scale } => 1.0 / (1.0 + s / (scale * scale)),
        }
    }

    /// Checks the loss parameter is finite and positive.
    pub fn validate(&self) -> Result<()> {
        match *self {
            Loss::Squared => Ok(()),
            Loss::Huber { delta: p } | Loss::Cauchy { scale: p } => {
                if p.is_finite() && p > 0.0 {
                    Ok(())
                } else {
                    Err(Error::InvalidInput(format!(
                        "robust loss scale must be finite and positive, got {p}"
                    )))
                }
            }
        }
    }
}

/// Gauss–Newton normal equations accumulated over residuals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalEquations {
    /// `J^T W J` (6x6, symmetric).
    pub hessian: Matrix6<f64>,
    /// `J^T W r`, the gradient of the cost.
    pub gradient: Vector6<f64>,
    /// `1/2 sum rho(|r|^2)`.
    pub cost: f64,
    /// Number of scalar residuals accumulated.
    pub residual_count: usize,
}

impl Default for NormalEquations {
    fn default() -> Self {
        NormalEquations {
            hessian: Matrix6::zeros(),
            gradient: Vector6::zeros(),
            cost: 0.0,
            residual_count: 0,
        }
    }
}

impl NormalEquations {
    /// Adds one scalar residual `r` with Jacobian row `j`.
    #[inline]
    pub fn add(&mut self, r: f64, j: &Vector6<f64>, loss: Loss) {
        let (rho, w) = loss.evaluate(r * r);
        self.cost += 0.5 * rho;
        self.gradient += j * (w * r);
        self.hessian.syger(w, j, j, 1.0);
        self.residual_count += 1;
    }

    /// Adds a block of residuals sharing one loss evaluation on their squared norm (e.g. the two
    /// components of a point-to-line offset, so the loss acts on the distance).
    #[inline]
    pub fn add_block<const K: usize>(&mut self, r: &[f64; K], j: &[Vector6<f64>; K], loss: Loss) {
        let s: f64 = r.iter().map(|x| x * x).sum();
        let (rho, w) = loss.evaluate(s);
        self.cost += 0.5 * rho;
        for k in 0..K {
            self.gradient += j[k] * (w * r[k]);
            self.hessian.syger(w, &j[k], &j[k], 1.0);
        }
        self.residual_count += K;
    }

    /// Adds only the cost of a residual block (no derivatives).
    #[inline]
    pub fn add_cost(&mut self, squared_norm: f64, count: usize, loss: Loss) {
        self.cost += 0.5 * loss.evaluate(squared_norm).0;
        self.residual_count += count;
    }

    /// Adds another accumulation into this one.
    pub fn merge(&mut self, other: &NormalEquations) {
        self.hessian += other.hessian;
        self.gradient += other.gradient;
        self.cost += other.cost;
        self.residual_count += other.residual_count;
    }

    /// Copies the lower triangle into the upper one (accumulation fills the lower triangle only).
    pub fn symmetrize(&mut self) {
        self.hessian.fill_upper_triangle_with_lower_triangle();
    }
}

/// Items per chunk when accumulating in parallel. Chunks are fixed-size and their partial sums are
/// added in order, so results are bit-identical for any number of threads.
const CHUNK: usize = 2048;

/// A sum that can be accumulated in independent chunks and merged.
pub trait Accumulator: Default + Send {
    /// Adds another partial sum into this one.
    fn merge(&mut self, other: &Self);
}

impl Accumulator for NormalEquations {
    fn merge(&mut self, other: &Self) {
        NormalEquations::merge(self, other);
    }
}

/// Accumulates `f(item, &mut acc)` over `items`, in parallel with the `parallel` feature, and
/// deterministically for any thread count (fixed chunks, summed in order).
pub fn accumulate<T, A, F>(items: &[T], f: F) -> A
where
    T: Sync,
    A: Accumulator,
    F: Fn(&T, &mut A) + Sync,
{
    let chunk_sum = |chunk: &[T]| {
        let mut acc = A::default();
        for item in chunk {
            f(item, &mut acc);
        }
        acc
    };
    #[cfg(feature = "parallel")]
    let partials: Vec<A> = if items.len() > CHUNK {
        use rayon::prelude::*;
        items.par_chunks(CHUNK).map(chunk_sum).collect()
    } else {
        // One chunk: the same sum without a round trip through the thread pool.
        items.chunks(CHUNK).map(chunk_sum).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let partials: Vec<A> = items.chunks(CHUNK).map(chunk_sum).collect();
    let mut total = A::default();
    for p in &partials {
        total.merge(p);
    }
    total
}

/// A nonlinear least-squares problem over a rigid transform.
pub trait LeastSquaresProblem: Sync {
    /// Number of scalar residuals.
    fn residual_count(&self) -> usize;

    /// The cost at `pose` and, when `with_derivatives`, the normal equations with respect to a left
    /// perturbation `exp(delta) * pose`. Implementations may fill only the lower triangle of the
    /// Hessian: the solver symmetrises it.
    fn normal_equations(&self, pose: &Isometry3<f64>, with_derivatives: bool) -> NormalEquations;
}

/// Options of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Upper bound on iterations (linear solves, accepted or not).
    pub max_iterations: usize,
    /// Stop when the largest gradient component `|J^T W r|_inf` is below this.
    pub gradient_tolerance: f64,
    /// Stop when the tangent step `|delta|` (radians and metres together) is below this.
    pub step_tolerance: f64,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub cost_tolerance: f64,
    /// Initial damping `mu`, relative to the diagonal of `J^T W J`.
    pub initial_damping: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iterations: 100,
            gradient_tolerance: 1e-12,
            step_tolerance: 1e-12,
            cost_tolerance: 1e-14,
            initial_damping: 1e-3,
        }
    }
}

impl LmOptions {
    fn validate(&self) -> Result<()> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(Error::InvalidInput(format!(
                    "LM option {name} must be finite and >= 0, got {v}"
                )))
            }
        };
        positive("gradient_tolerance", self.gradient_tolerance)?;
        positive("step_tolerance", self.step_tolerance)?;
        positive("cost_tolerance", self.cost_tolerance)?;
        positive("initial_damping", self.initial_damping)?;
        if self.max_iterations == 0 {
            return Err(Error::InvalidInput(
                "max_iterations must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// The gradient fell below the tolerance (includes a zero-residual fit).
    GradientTolerance,
    /// The step fell below the tolerance.
    StepTolerance,
    /// An accepted step lowered the cost by less than the relative tolerance.
    CostTolerance,
    /// No step lowered the cost even with very strong damping: a minimum to machine precision.
    NoFurtherDecrease,
    /// The iteration cap was reached first.
    MaxIterations,
}

impl Termination {
    /// `true` for every reason except [`Termination::MaxIterations`].
    pub fn converged(&self) -> bool {
        !matches!(self, Termination::MaxIterations)
    }

    /// A short lower-case name (`"gradient_tolerance"`, ...).
    pub fn as_str(&self) -> &'static str {
        match self {
            Termination::GradientTolerance => "gradient_tolerance",
            Termination::StepTolerance => "step_tolerance",
            Termination::CostTolerance => "cost_tolerance",
            Termination::NoFurtherDecrease => "no_further_decrease",
            Termination::MaxIterations => "max_iterations",
        }
    }
}

/// What happened during a solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmReport {
    /// Cost at the initial pose.
    pub initial_cost: f64,
    /// Cost at the returned pose.
    pub final_cost: f64,
    /// Linear solves performed (accepted and rejected steps).
    pub iterations: usize,
    /// Cost evaluations, including the initial one.
    pub evaluations: usize,
    /// Why the solver stopped.
    pub termination: Termination,
    /// `J^T W J` at the returned pose (tangent order `[rho; phi]`, left perturbation).
    pub hessian: Matrix6<f64>,
    /// Number of scalar residuals.
    pub residual_count: usize,
}

impl LmReport {
    /// `true` unless the iteration cap was hit.
    pub fn converged(&self) -> bool {
        self.termination.converged()
    }

    /// Covariance of the left-perturbation tangent `[rho; phi]`: `s^2 (J^T J)^-1` with the residual
    /// variance `s^2 = 2 F / (m - 6)`. Meaningful for the least-squares loss; `None` when the
    /// Hessian is singular or there are no more residuals than parameters.
    pub fn covariance(&self) -> Option<Matrix6<f64>> {
        if self.residual_count <= 6 {
            return None;
        }
        let sigma2 = 2.0 * self.final_cost / (self.residual_count - 6) as f64;
        self.hessian.cholesky().map(|c| c.inverse() * sigma2)
    }
}

/// The result of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmSolution {
    /// The refined transform.
    pub pose: Isometry3<f64>,
    /// Diagnostics.
    pub report: LmReport,
}

/// Largest damping before the solver concludes no step can lower the cost.
const MAX_DAMPING: f64 = 1e32;
/// Floor of the damping diagonal relative to its largest entry (keeps unobserved directions damped).
const DIAGONAL_FLOOR: f64 = 1e-9;

fn evaluate<P: LeastSquaresProblem + ?Sized>(
    problem: &P,
    pose: &Isometry3<f64>,
    with_derivatives: bool,
) -> Result<NormalEquations> {
    let mut ne = problem.normal_equations(pose, with_derivatives);
    if with_derivatives {
        ne.symmetrize();
    }
    let finite = ne.cost.is_finite()
        && (!with_derivatives
            || (ne.hessian.iter().all(|x| x.is_finite())
                && ne.gradient.iter().all(|x| x.is_finite())));
    if !finite {
        return Err(Error::Numerical(
            "the problem produced a non-finite cost or derivative".into(),
        ));
    }
    Ok(ne)
}

/// Minimises the problem's cost over rigid transforms, starting from `initial`.
///
/// Returns [`Error::InvalidInput`] for invalid options or a problem without residuals, and
/// [`Error::Numerical`] if the problem evaluates to non-finite values.
pub fn solve<P: LeastSquaresProblem + ?Sized>(
    problem: &P,
    initial: &Isometry3<f64>,
    options: &LmOptions,
) -> Result<LmSolution> {
    options.validate()?;
    if problem.residual_count() == 0 {
        return Err(Error::InvalidInput("the problem has no residuals".into()));
    }
    let mut pose = *initial;
    let mut current = evaluate(problem, &pose, true)?;
    let initial_cost = current.cost;
    let mut evaluations = 1;
    let mut mu = options.initial_damping;
    let mut nu = 2.0;
    let mut iterations = 0;

    let termination = loop {
        if current.gradient.amax() <= options.gradient_tolerance {
            break Termination::GradientTolerance;
        }
        if iterations >= options.max_iterations {
            break Termination::MaxIterations;
        }
        if mu > MAX_DAMPING {
            break Termination::NoFurtherDecrease;
        }
        iterations += 1;

        let diag_max = current.hessian.diagonal().amax();
        let mut damping = current.hessian.diagonal();
        damping.apply(|d| *d = d.max(DIAGONAL_FLOOR * diag_max).max(f64::MIN_POSITIVE));
        let mut lhs = current.hessian;
        for i in 0..6 {
            lhs[(i, i)] += mu * damping[i];
        }
        let Some(chol) = lhs.cholesky() else {
            mu *= nu;
            nu *= 2.0;
            continue;
        };
        let delta = -chol.solve(&current.gradient);
        if delta.norm() <= options.step_tolerance {
            break Termination::StepTolerance;
        }
        let candidate = se3_exp(&delta) * pose;
        let trial = evaluate(problem, &candidate, false)?;
        evaluations += 1;
        // Predicted decrease of the quadratic model: 1/2 delta^T (mu D delta - g).
        let predicted = 0.5 * delta.dot(&(damping.component_mul(&delta) * mu - current.gradient));
        let actual = current.cost - trial.cost;
        let gain = if predicted > 0.0 {
            actual / predicted
        } else {
            -1.0
        };
        if gain > 0.0 && actual > 0.0 {
            let previous_cost = current.cost;
            pose = candidate;
            current = evaluate(problem, &pose, true)?;
            evaluations += 1;
            mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * gain - 1.0).powi(3));
            nu = 2.0;
            if previous_cost - current.cost <= options.cost_tolerance * previous_cost {
                break Termination::CostTolerance;
            }
        } else {
            mu *= nu;
            nu *= 2.0;
        }
    };

    Ok(LmSolution {
        pose,
        report: LmReport {
            initial_cost,
            final_cost: current.cost,
            iterations,
            evaluations,
            termination,
            hessian: current.hessian,
            residual_count: current.residual_count,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn losses_match_their_definitions() {
        let h = Loss::Huber { delta: 2.0 };
        assert_eq!(h.evaluate(1.0), (1.0, 1.0));
        let (rho, w) = h.evaluate(9.0);
        assert!((rho - (2.0 * 2.0 * 3.0 - 4.0)).abs() < 1e-15);
        assert!((w - 2.0 / 3.0).abs() < 1e-15);
        let c = Loss::Cauchy { scale: 0.5 };
        let (rho, w) = c.evaluate(1.0);
        assert!((rho - 0.25 * 5.0f64.ln()).abs() < 1e-15);
        assert!((w - 0.2).abs() < 1e-15);
        // rho' is the derivative of rho.
        for loss in [Loss::Squared, h, c] {
            for s in [0.3, 2.0, 7.0] {
                let eps = 1e-6;
                let numeric = (loss.evaluate(s + eps).0 - loss.evaluate(s - eps).0) / (2.0 * eps);
                assert!((numeric - loss.evaluate(s).1).abs() < 1e-8);
                assert_eq!(loss.weight(s), loss.evaluate(s).1);
            }
        }
        assert!(Loss::Huber { delta: 0.0 }.validate().is_err());
        assert!(Loss::Cauchy { scale: f64::NAN }.validate().is_err());
    }

    #[test]
    fn options_are_validated() {
        struct Empty;
        impl LeastSquaresProblem for Empty {
            fn residual_count(&self) -> usize {
                0
            }
            fn normal_equations(&self, _: &Isometry3<f64>, _: bool) -> NormalEquations {
                NormalEquations::default()
            }
        }
        let id = Isometry3::identity();
        assert!(solve(&Empty, &id, &LmOptions::default()).is_err());
        let bad = LmOptions {
            max_iterations: 0,
            ..LmOptions::default()
        };
        assert!(solve(&Empty, &id, &bad).is_err());
    }
}
