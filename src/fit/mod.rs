//! Least-squares fits of geometric primitives to points.
//!
//! [`Moments`] accumulates the count, mean and scatter matrix of a point set (shifted to the first
//! point for numerical robustness); [`Moments::plane`] and [`Moments::line`] turn them into the
//! total-least-squares plane (normal = eigenvector of the smallest scatter eigenvalue) and line
//! (direction = eigenvector of the largest). The same moments are sufficient statistics for the
//! squared point-to-plane distances of the set under any rigid motion.
//!
//! ```
//! use lidarcal::fit::fit_plane;
//! use nalgebra::Point3;
//! let pts: Vec<_> = (0..20).map(|i| Point3::new((i % 5) as f64, (i / 5) as f64, 2.0)).collect();
//! let fit = fit_plane(&pts).unwrap();
//! assert!((fit.plane.normal.z.abs() - 1.0).abs() < 1e-12);
//! assert!(fit.plane.signed_distance(&Point3::new(7.0, -3.0, 2.0)).abs() < 1e-12);
//! ```

pub mod cylinder;

use nalgebra::{Matrix3, Point3, SymmetricEigen, Unit, Vector3};

use crate::error::{Error, Result};
use crate::geometry::{Line, Plane};

/// Below this ratio of the middle to the largest scatter eigenvalue, points are called collinear
/// (no plane is determined); below it for the largest eigenvalue relative to the squared extent
/// scale, coincident (no line).
const DEGENERACY_RATIO: f64 = 1e-12;

/// Count, mean and scatter of a point set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Moments {
    origin: Vector3<f64>,
    count: usize,
    weight: f64,
    sum: Vector3<f64>,
    outer: Matrix3<f64>,
}

impl Moments {
    /// Empty moments, accumulated relative to `origin` (any point near the data; it only affects
    /// rounding, not the result).
    pub fn new(origin: Point3<f64>) -> Self {
        Moments {
            origin: origin.coords,
            count: 0,
            weight: 0.0,
            sum: Vector3::zeros(),
            outer: Matrix3::zeros(),
        }
    }

    /// Moments of `points` (shifted to the first one).
    pub fn from_points<'a, I: IntoIterator<Item = &'a Point3<f64>>>(points: I) -> Self {
        let mut iter = points.into_iter().peekable();
        let origin = iter.peek().map_or(Point3::origin(), |p| **p);
        let mut m = Moments::new(origin);
        for p in iter {
            m.add(p);
        }
        m
    }

    /// Adds one point.
    #[inline]
    pub fn add(&mut self, p: &Point3<f64>) {
        self.add_weighted(p, 1.0);
    }

    /// Adds one point with weight `w >= 0` (all statistics become weighted sums).
    #[inline]
    pub fn add_weighted(&mut self, p: &Point3<f64>, w: f64) {
        let d = p.coords - self.origin;
        self.count += 1;
        self.weight += w;
        let dw = d * w;
        self.sum += dw;
        self.outer += dw * d.transpose();
    }

    /// Number of points.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Total weight (the number of points when none was weighted).
    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// The (weighted) mean point.
    pub fn mean(&self) -> Point3<f64> {
        if self.weight <= 0.0 {
            return Point3::from(self.origin);
        }
        Point3::from(self.origin + self.sum / self.weight)
    }

    /// The (weighted) scatter matrix `sum w (p - mean)(p - mean)^T`.
    pub fn scatter(&self) -> Matrix3<f64> {
        if self.weight <= 0.0 {
            return Matrix3::zeros();
        }
        let m = self.sum / self.weight;
        self.outer - m * self.sum.transpose()
    }

    /// Eigenvalues (ascending) and matching unit eigenvectors of the scatter matrix.
    pub fn principal_axes(&self) -> ([f64; 3], [Vector3<f64>; 3]) {
        let eig = SymmetricEigen::new(self.scatter());
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
        let values = order.map(|i| eig.eigenvalues[i].max(0.0));
        let vectors = order.map(|i| eig.eigenvectors.column(i).into_owned());
        (values, vectors)
    }

    /// The extent of the points along their two largest principal axes (metres, larger first):
    /// `sqrt(12 l / w)` of the scatter eigenvalues, the sides of a uniform rectangle with that
    /// spread.
    pub fn extents(&self) -> [f64; 2] {
        let (values, _) = self.principal_axes();
        let side = |l: f64| (12.0 * l / self.weight.max(1.0)).sqrt();
        [side(values[2]), side(values[1])]
    }

    /// The total-least-squares plane. Needs at least 3 points that are not collinear.
    pub fn plane(&self) -> Result<PlaneFit> {
        if self.count < 3 {
            return Err(Error::InvalidInput(format!(
                "a plane needs at least 3 points, got {}",
                self.count
            )));
        }
        let (values, vectors) = self.principal_axes();
        if values[1] <= DEGENERACY_RATIO * values[2] || values[2] <= 0.0 {
            return Err(Error::Degenerate(
                "the points are collinear or coincident: no plane is determined".into(),
            ));
        }
        let normal = Unit::new_normalize(vectors[0]);
        let plane = Plane::from_point_normal(&self.mean(), &normal)?;
        Ok(PlaneFit {
            plane,
            rms: (values[0] / self.weight).sqrt(),
            eigenvalues: values,
        })
    }

    /// The total-least-squares line. Needs at least 2 distinct points.
    pub fn line(&self) -> Result<LineFit> {
        if self.count < 2 {
            return Err(Error::InvalidInput(format!(
                "a line needs at least 2 points, got {}",
                self.count
            )));
        }
        let (values, vectors) = self.principal_axes();
        if values[2] <= 0.0 {
            return Err(Error::Degenerate(
                "the points are coincident: no line is determined".into(),
            ));
        }
        let line = Line::new(self.mean(), vectors[2])?;
        Ok(LineFit {
            line,
            rms: ((values[0] + values[1]) / self.weight).sqrt(),
            eigenvalues: values,
        })
    }
}

/// A fitted plane with its quality.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFit {
    /// The plane through the mean, normal along the smallest principal axis (sign arbitrary).
    pub plane: Plane,
    /// Root-mean-square point-to-plane distance.
    pub rms: f64,
    /// Scatter eigenvalues, ascending.
    pub eigenvalues: [f64; 3],
}

/// A fitted line with its quality.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineFit {
    /// The line through the mean along the largest principal axis (sign arbitrary).
    pub line: Line,
    /// Root-mean-square point-to-line distance.
    pub rms: f64,
    /// Scatter eigenvalues, ascending.
    pub eigenvalues: [f64; 3],
}

fn check_finite(points: &[Point3<f64>]) -> Result<()> {
    crate::error::ensure_points("points", points.iter())
}

/// Total-least-squares plane through `points`.
pub fn fit_plane(points: &[Point3<f64>]) -> Result<PlaneFit> {
    check_finite(points)?;
    Moments::from_points(points).plane()
}

/// Total-least-squares line through `points`.
pub fn fit_line(points: &[Point3<f64>]) -> Result<LineFit> {
    check_finite(points)?;
    Moments::from_points(points).line()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_fit_recovers_tilted_plane_far_from_origin() {
        let n = Vector3::new(0.2, -0.3, 0.93).normalize();
        let (u, v) = crate::geometry::orthonormal_basis(&Unit::new_normalize(n));
        let center = Vector3::new(1000.0, -2000.0, 50.0);
        let pts: Vec<_> = (0..100)
            .map(|i| {
                let a = (i % 10) as f64 - 4.5;
                let b = (i / 10) as f64 - 4.5;
                // Checkerboard signs: zero mean and uncorrelated with both grid axes.
                let noise = if (i % 10 + i / 10) % 2 == 0 {
                    0.01
                } else {
                    -0.01
                };
                Point3::from(center + u * a + v * b + n * noise)
            })
            .collect();
        let fit = fit_plane(&pts).unwrap();
        assert!(fit.plane.normal.dot(&n).abs() > 1.0 - 1e-12);
        assert!((fit.rms - 0.01).abs() < 1e-9);
        assert!(fit.plane.signed_distance(&Point3::from(center)).abs() < 1e-9);
    }

    #[test]
    fn line_fit_and_degeneracies() {
        let d = Vector3::new(1.0, 2.0, -0.5).normalize();
        let pts: Vec<_> = (0..10)
            .map(|i| Point3::from(d * i as f64 + Vector3::x()))
            .collect();
        let fit = fit_line(&pts).unwrap();
        assert!(fit.line.direction.dot(&d).abs() > 1.0 - 1e-12);
        // rms is the square root of an eigenvalue at rounding level (~1e-16 of the largest).
        assert!(fit.rms < 1e-6);
        assert!(matches!(fit_plane(&pts), Err(Error::Degenerate(_))));
        let same = vec![Point3::new(1.0, 1.0, 1.0); 5];
        assert!(matches!(fit_line(&same), Err(Error::Degenerate(_))));
        assert!(matches!(fit_plane(&same), Err(Error::Degenerate(_))));
        assert!(matches!(fit_plane(&pts[..2]), Err(Error::InvalidInput(_))));
        assert!(matches!(fit_line(&pts[..1]), Err(Error::InvalidInput(_))));
        let nan = vec![Point3::new(f64::NAN, 0.0, 0.0); 3];
        assert!(fit_plane(&nan).is_err());
    }
}
