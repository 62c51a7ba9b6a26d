//! Least-squares cylinder fit: the axis (and optionally the radius) of a pole from points on its
//! surface.
//!
//! A LiDAR sees the side of a pole facing it, so the centroid line of the points sits up to a
//! radius in front of the axis. [`fit_cylinder`] minimises `sum_i (dist(x_i, axis) - r)^2` over the
//! axis (4 degrees of freedom) and, when it is not given, the radius, with Levenberg–Marquardt.
//!
//! # Parametrisation
//! Around the current axis (point `p0`, unit direction `d0`, and `(b1, b2)` an orthonormal basis of
//! the plane orthogonal to `d0`), a step `delta = [a1, a2, w1, w2, dr]` moves the axis to
//! `p = p0 + a1 b1 + a2 b2`, `d = normalize(d0 + w1 b1 + w2 b2)` and the radius to `r + dr`. After
//! each accepted step `p0` is moved to the foot of the points' centroid on the axis, which keeps
//! translation and tilt decoupled. With `v = x - p0`, `u = v - (v.d0) d0`, `rho = |u|`, `n = u / rho`
//! the residual is `rho - r` and its derivatives at `delta = 0` are
//! `d/da_k = -n.b_k`, `d/dw_k = -(v.d0)(n.b_k)`, `d/dr = -1`.
//!
//! ```
//! use lidarcal::fit::cylinder::fit_cylinder;
//! use lidarcal::fit::fit_line;
//! use nalgebra::Point3;
//! // The half of a vertical pole of radius 0.2 at x = 5 that faces the origin.
//! let pts: Vec<_> = (0..200)
//!     .map(|i| {
//!         let a = std::f64::consts::PI * (0.5 + (i % 20) as f64 / 19.0);
//!         Point3::new(5.0 + 0.2 * a.cos(), 0.2 * a.sin(), 0.1 * (i / 20) as f64)
//!     })
//!     .collect();
//! let line = fit_line(&pts)?.line;
//! let fit = fit_cylinder(&pts, Some(0.2), &line, &Point3::origin())?;
//! assert!(fit.axis.distance(&Point3::new(5.0, 0.0, 0.5)) < 1e-6);
//! assert!(line.distance(&Point3::new(5.0, 0.0, 0.5)) > 0.1); // the centroid line is off
//! # Ok::<(), lidarcal::Error>(())
//! ```

use nalgebra::{Matrix5, Point3, Unit, Vector3, Vector5};

use crate::error::{ensure_finite, Error, Result};
use crate::geometry::{orthonormal_basis, Line};

/// Fewest points a cylinder fit accepts.
pub const MIN_POINTS: usize = 6;
/// Iteration cap of the Levenberg–Marquardt loop.
const MAX_ITERATIONS: usize = 100;
/// Stop when a step moves the axis by less than this (metres, or radians times metres of extent).
const STEP_TOLERANCE: f64 = 1e-10;
/// Initial Levenberg–Marquardt damping, relative to the largest diagonal entry of `J^T J`.
const INITIAL_DAMPING: f64 = 1e-6;
/// Points closer to the axis than this fraction of the radius get no radial direction.
const AXIS_EPSILON: f64 = 1e-12;

/// A fitted cylinder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CylinderFit {
    /// The axis, through the foot of the points' centroid, direction of the initial line's sign.
    pub axis: Line,
    /// The radius (the given one when it was fixed).
    pub radius: f64,
    /// Root-mean-square of `dist(x, axis) - radius`.
    pub rms: f64,
    /// Accepted Levenberg–Marquardt steps.
    pub iterations: usize,
    /// False when the iteration cap was hit.
    pub converged: bool,
}

fn recenter(point: &Point3<f64>, d: &Unit<Vector3<f64>>, centroid: &Point3<f64>) -> Point3<f64> {
    point + d.into_inner() * d.dot(&(centroid - point))
}

fn cost(points: &[Point3<f64>], p: &Point3<f64>, d: &Unit<Vector3<f64>>, r: f64) -> f64 {
    points
        .iter()
        .map(|x| {
            let v = x - p;
            let rho = (v - d.into_inner() * v.dot(d)).norm();
            (rho - r) * (rho - r)
        })
        .sum()
}

/// `J^T J` and `J^T r` at `(p, d, r)` in the basis described in the module docs.
fn normal_equations(
    points: &[Point3<f64>],
    p: &Point3<f64>,
    d: &Unit<Vector3<f64>>,
    r: f64,
    b: &(Vector3<f64>, Vector3<f64>),
) -> (Matrix5<f64>, Vector5<f64>) {
    let mut h = Matrix5::zeros();
    let mut g = Vector5::zeros();
    for x in points {
        let (res, j) = residual_and_jacobian(x, p, d, r, b);
        h += j * j.transpose();
        g += j * res;
    }
    (h, g)
}

/// One residual and its Jacobian row `[d/da1, d/da2, d/dw1, d/dw2, d/dr]`.
fn residual_and_jacobian(
    x: &Point3<f64>,
    p: &Point3<f64>,
    d: &Unit<Vector3<f64>>,
    r: f64,
    (b1, b2): &(Vector3<f64>, Vector3<f64>),
) -> (f64, Vector5<f64>) {
    let v = x - p;
    let along = v.dot(d);
    let u = v - d.into_inner() * along;
    let rho = u.norm();
    if rho <= AXIS_EPSILON * r.max(1.0) {
        return (rho - r, Vector5::new(0.0, 0.0, 0.0, 0.0, -1.0));
    }
    let n = u / rho;
    let (n1, n2) = (n.dot(b1), n.dot(b2));
    (
        rho - r,
        Vector5::new(-n1, -n2, -along * n1, -along * n2, -1.0),
    )
}

/// The quantities the fit moves: a point of the axis (the foot of the points' centroid), the
/// axis direction and the radius.
#[derive(Debug, Clone, Copy)]
struct Axis {
    p: Point3<f64>,
    d: Unit<Vector3<f64>>,
    r: f64,
}

/// Fits a cylinder to `points` on its surface, starting from `initial` (typically the
/// [`fit_line`](super::fit_line) of the points) and `viewpoint` (the sensor that saw them).
///
/// The start axis is `initial` shifted away from `viewpoint` by the radius (the points lie on the
/// side facing the sensor). With `radius = None` the radius is estimated too, starting from half
/// the points' spread across the viewing direction. Errors for fewer than [`MIN_POINTS`] points,
/// non-finite values, a non-positive radius, or a viewpoint on the initial axis; returns
/// `Err(Degenerate)` when the points do not determine the axis (e.g. all at one height).
pub fn fit_cylinder(
    points: &[Point3<f64>],
    radius: Option<f64>,
    initial: &Line,
    viewpoint: &Point3<f64>,
) -> Result<CylinderFit> {
    check_input(points, radius, initial, viewpoint)?;
    let centroid = Point3::from(
        points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / points.len() as f64,
    );
    let mut axis = start(points, radius, initial, viewpoint, &centroid)?;
    let estimate_radius = radius.is_none();
    let mut current = cost(points, &axis.p, &axis.d, axis.r);
    let mut lambda = None;
    let mut iterations = 0;
    let mut converged = false;
    for _ in 0..MAX_ITERATIONS {
        let basis = orthonormal_basis(&axis.d);
        let (mut h, mut g) = normal_equations(points, &axis.p, &axis.d, axis.r, &basis);
        if !estimate_radius {
            h.row_mut(4).fill(0.0);
            h.column_mut(4).fill(0.0);
            h[(4, 4)] = 1.0;
            g[4] = 0.0;
        }
        let scale = h.diagonal().max().max(f64::MIN_POSITIVE);
        let mu = lambda.unwrap_or(INITIAL_DAMPING * scale);
        let (accepted, mu) = damped_step(points, &centroid, &axis, current, (&h, &g), &basis, mu);
        lambda = Some(mu);
        let Some((next, c, step_size)) = accepted else {
            // No descent direction left: at a minimum up to rounding.
            converged = true;
            break;
        };
        axis = next;
        current = c;
        iterations += 1;
        if step_size < STEP_TOLERANCE {
            converged = true;
            break;
        }
    }
    if !(current.is_finite() && axis.r.is_finite()) {
        return Err(Error::Numerical("cylinder fit diverged".into()));
    }
    let line = Line::new(axis.p, axis.d.into_inner())?;
    let line = if line.direction.dot(&initial.direction) < 0.0 {
        line.reversed()
    } else {
        line
    };
    Ok(CylinderFit {
        axis: line,
        radius: axis.r,
        rms: (current / points.len() as f64).sqrt(),
        iterations,
        converged,
    })
}

/// The input errors of [`fit_cylinder`]: too few or non-finite points, a non-finite initial line
/// or viewpoint, a radius that is not positive.
fn check_input(
    points: &[Point3<f64>],
    radius: Option<f64>,
    initial: &Line,
    viewpoint: &Point3<f64>,
) -> Result<()> {
    if points.len() < MIN_POINTS {
        return Err(Error::InvalidInput(format!(
            "a cylinder fit needs at least {MIN_POINTS} points, got {}",
            points.len()
        )));
    }
    crate::error::ensure_points("points", points.iter())?;
    ensure_finite(
        "initial line and viewpoint",
        initial
            .point
            .coords
            .iter()
            .chain(initial.direction.iter())
            .chain(viewpoint.coords.iter()),
    )?;
    if let Some(r) = radius {
        if !(r.is_finite() && r > 0.0) {
            return Err(Error::InvalidInput(format!(
                "cylinder radius must be positive and finite, got {r}"
            )));
        }
    }
    Ok(())
}

/// The start of the fit: `initial` moved through the foot of `centroid` and shifted away from
/// `viewpoint` by the radius (the given one, or half the points' spread across the viewing
/// direction).
fn start(
    points: &[Point3<f64>],
    radius: Option<f64>,
    initial: &Line,
    viewpoint: &Point3<f64>,
    centroid: &Point3<f64>,
) -> Result<Axis> {
    let d = initial.direction;
    let foot = recenter(&initial.point, &d, centroid);
    // Unit vector from the viewpoint toward the axis, orthogonal to it.
    let to_axis = foot - viewpoint;
    let away = to_axis - d.into_inner() * to_axis.dot(&d);
    let away_norm = away.norm();
    if away_norm <= AXIS_EPSILON {
        return Err(Error::InvalidInput(
            "the viewpoint lies on the initial axis: no side of the cylinder faces it".into(),
        ));
    }
    let away = away / away_norm;
    let r = match radius {
        Some(r) => r,
        None => {
            let across = d.cross(&away);
            let (lo, hi) = points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    let s = (x - foot).dot(&across);
                    (lo.min(s), hi.max(s))
                });
            let r0 = 0.5 * (hi - lo);
            if r0 <= 0.0 {
                return Err(Error::Degenerate(
                    "the points have no extent across the viewing direction: the radius is undetermined".into(),
                ));
            }
            r0
        }
    };
    Ok(Axis {
        p: foot + away * r,
        d,
        r,
    })
}

/// One Levenberg–Marquardt iteration from `at` (cost `current`) with the normal equations
/// `(h, g)` in the tangent `basis` of `at.d`: the damping `mu` grows tenfold until a step lowers
/// the cost (at most 32 tries). Returns the accepted axis with its cost and step norm, if any, and
/// the damping to start the next iteration from.
fn damped_step(
    points: &[Point3<f64>],
    centroid: &Point3<f64>,
    at: &Axis,
    current: f64,
    (h, g): (&Matrix5<f64>, &Vector5<f64>),
    basis: &(Vector3<f64>, Vector3<f64>),
    mut mu: f64,
) -> (Option<(Axis, f64, f64)>, f64) {
    let scale = h.diagonal().max().max(f64::MIN_POSITIVE);
    for _ in 0..32 {
        let mut damped = *h;
        for i in 0..5 {
            damped[(i, i)] += mu * h[(i, i)].max(1e-12 * scale);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&-g)) else {
            mu *= 10.0;
            continue;
        };
        let (b1, b2) = basis;
        let p_new = at.p + b1 * step[0] + b2 * step[1];
        let d_new = Unit::new_normalize(at.d.into_inner() + b1 * step[2] + b2 * step[3]);
        let r_new = at.r + step[4];
        if r_new.is_nan() || r_new <= 0.0 {
            mu *= 10.0;
            continue;
        }
        let p_new = recenter(&p_new, &d_new, centroid);
        let c = cost(points, &p_new, &d_new, r_new);
        if c.is_finite() && c <= current {
            let next = Axis {
                p: p_new,
                d: d_new,
                r: r_new,
            };
            return (Some((next, c, step.norm())), (mu / 3.0).max(1e-15 * scale));
        }
        mu *= 10.0;
    }
    (None, mu)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::fit_line;

    fn half_pole(center: Vector3<f64>, dir: Vector3<f64>, r: f64) -> Vec<Point3<f64>> {
        let d = Unit::new_normalize(dir);
        let (b1, b2) = orthonormal_basis(&d);
        (0..300)
            .map(|i| {
                // Facing -b1 (toward a viewpoint on that side), +-80 deg.
                let a = std::f64::consts::PI + (((i % 15) as f64 / 14.0) - 0.5) * 2.8;
                let h = (i / 15) as f64 * 0.1 - 1.0;
                let wiggle = if i % 2 == 0 { 1e-3 } else { -1e-3 };
                Point3::from(
                    center + d.into_inner() * h + (b1 * a.cos() + b2 * a.sin()) * (r + wiggle),
                )
            })
            .collect()
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let p = Point3::new(0.3, -0.2, 0.1);
        let d = Unit::new_normalize(Vector3::new(0.1, 0.2, 1.0));
        let basis = orthonormal_basis(&d);
        let (b1, b2) = basis;
        let r = 0.25;
        let eval = |delta: &Vector5<f64>, x: &Point3<f64>| {
            let pp = p + b1 * delta[0] + b2 * delta[1];
            let dd = Unit::new_normalize(d.into_inner() + b1 * delta[2] + b2 * delta[3]);
            residual_and_jacobian(x, &pp, &dd, r + delta[4], &basis).0
        };
        for x in [Point3::new(1.0, 0.5, 2.0), Point3::new(-0.4, 0.3, -1.5)] {
            let (_, j) = residual_and_jacobian(&x, &p, &d, r, &basis);
            let h = 1e-6;
            for k in 0..5 {
                let mut e = Vector5::zeros();
                e[k] = h;
                let numeric = (eval(&e, &x) - eval(&-e, &x)) / (2.0 * h);
                assert!(
                    (numeric - j[k]).abs() < 1e-7,
                    "k = {k}: {numeric} vs {}",
                    j[k]
                );
            }
        }
    }

    #[test]
    fn recovers_axis_with_known_and_estimated_radius() {
        let center = Vector3::new(6.0, 1.0, 1.0);
        let dir = Vector3::new(0.1, -0.15, 1.0);
        let truth = Line::new(Point3::from(center), dir).unwrap();
        let r = 0.3;
        let pts = half_pole(center, dir, r);
        let (b1, _) = orthonormal_basis(&truth.direction);
        let viewpoint = Point3::from(center - b1 * 5.0);
        let line = fit_line(&pts).unwrap().line;
        assert!(truth.distance(&line.point) > 0.1);
        for radius in [Some(r), None] {
            let fit = fit_cylinder(&pts, radius, &line, &viewpoint).unwrap();
            assert!(fit.converged);
            assert!(
                truth.distance(&fit.axis.point) < 2e-3,
                "{radius:?}: {fit:?}"
            );
            assert!(fit.axis.direction.dot(&truth.direction).abs() > 1.0 - 1e-6);
            assert!((fit.radius - r).abs() < 2e-3);
            assert!(fit.rms < 2e-3);
        }
    }

    #[test]
    fn rejects_bad_input() {
        let pts = half_pole(Vector3::new(5.0, 0.0, 0.0), Vector3::z(), 0.2);
        let line = fit_line(&pts).unwrap().line;
        let vp = Point3::origin();
        assert!(fit_cylinder(&pts[..3], None, &line, &vp).is_err());
        assert!(fit_cylinder(&pts, Some(-1.0), &line, &vp).is_err());
        assert!(fit_cylinder(&pts, Some(f64::NAN), &line, &vp).is_err());
        let mut nan = pts.clone();
        nan[0].x = f64::NAN;
        assert!(fit_cylinder(&nan, None, &line, &vp).is_err());
        assert!(fit_cylinder(&pts, None, &line, &line.point).is_err());
    }
}
