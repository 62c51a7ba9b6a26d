//! Step 4 of the [module docs](super): one cluster's pole test and axis (cylinder or line) fit.

use nalgebra::{Point3, Vector3};

use super::detect::*;
use super::options::*;
use crate::fit::cylinder::fit_cylinder;
use crate::fit::Moments;
use crate::ransac::line::ransac_line;
use crate::ransac::RansacOptions;

/// Largest RMS of a pole's cylinder fit (metres): a flat strip of a sign does not fit.
pub(super) const MAX_CYLINDER_RMS: f64 = 0.03;
/// Largest accepted estimated radius (metres).
pub(super) const MAX_RADIUS: f64 = 1.0;

/// Tests and fits one cluster; `Err` carries the reason it is not a pole.
pub(super) fn fit_pole(
    members: &[Point3<f64>],
    indices: &[usize],
    options: &PoleOptions,
) -> std::result::Result<DetectedPole, String> {
    let moments = Moments::from_points(members);
    let (values, vectors) = moments.principal_axes();
    let elongation = if values[1] > 0.0 {
        (values[2] / values[1]).sqrt()
    } else {
        f64::INFINITY
    };
    let mean = moments.mean();
    let (lo, hi) = extent_along(members, &mean, &vectors[2]);
    let length = hi - lo;
    if elongation < options.min_elongation {
        return Err(format!(
            "compact bright blob (a sign?): elongation {elongation:.2} < {:.2}, length {length:.2} m",
            options.min_elongation
        ));
    }
    if length < options.min_length {
        return Err(format!(
            "too short: {length:.2} m < {:.2} m",
            options.min_length
        ));
    }
    let threshold = match options.pole_radius {
        Some(r) => 1.2 * r + 0.03,
        None => 3.0 * values[1].sqrt() + 0.03,
    };
    let mut ransac = RansacOptions::new(threshold);
    ransac.seed = options.seed;
    let line = ransac_line(members, &ransac).map_err(|e| format!("no line: {e}"))?;
    if line.inliers.len() < options.min_points {
        return Err(format!(
            "only {} points on its line (need {})",
            line.inliers.len(),
            options.min_points
        ));
    }
    let inlier_points: Vec<Point3<f64>> = line.inliers.iter().map(|&k| members[k]).collect();
    let inlier_indices: Vec<usize> = line.inliers.iter().map(|&k| indices[k]).collect();
    let (axis, radius, rms) = match options.axis_fit {
        AxisFit::Line => {
            let fit = Moments::from_points(&inlier_points)
                .line()
                .map_err(|e| format!("no line: {e}"))?;
            (fit.line, 0.0, fit.rms)
        }
        AxisFit::Cylinder => {
            let fit = fit_cylinder(
                &inlier_points,
                options.pole_radius,
                &line.model,
                &Point3::origin(),
            )
            .map_err(|e| format!("no cylinder: {e}"))?;
            if fit.rms > MAX_CYLINDER_RMS {
                return Err(format!(
                    "not a cylinder: RMS {:.3} m > {MAX_CYLINDER_RMS} m",
                    fit.rms
                ));
            }
            if 2.0 * fit.radius > length {
                return Err(format!(
                    "wider than long: radius {:.3} m for a length of {length:.2} m",
                    fit.radius
                ));
            }
            if !(fit.radius > 0.0 && fit.radius <= MAX_RADIUS) {
                return Err(format!(
                    "implausible radius {:.3} m (max {MAX_RADIUS} m)",
                    fit.radius
                ));
            }
            (fit.axis, fit.radius, fit.rms)
        }
    };
    // Deterministic direction: away from the sensor's "down" is not known, so point it along the
    // largest coordinate of the direction with a positive sign.
    let d = axis.direction.into_inner();
    let k = d.iamax();
    let axis = if d[k] < 0.0 { axis.reversed() } else { axis };
    let (lo, hi) = inlier_points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            let s = (p - axis.point).dot(&axis.direction);
            (lo.min(s), hi.max(s))
        });
    Ok(DetectedPole {
        axis,
        radius,
        rms,
        indices: inlier_indices,
        extent: (lo, hi),
    })
}

/// The smallest and largest coordinate of `points` along `axis`, measured from `origin`.
pub(super) fn extent_along(
    points: &[Point3<f64>],
    origin: &Point3<f64>,
    axis: &Vector3<f64>,
) -> (f64, f64) {
    points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            let s = (p - origin).dot(axis);
            (lo.min(s), hi.max(s))
        })
}
