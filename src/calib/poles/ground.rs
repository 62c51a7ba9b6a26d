//! Each cloud's largest plane (the ground in a pole scene), a term of the hypothesis scores.

use nalgebra::Point3;

use crate::geometry::Plane;
use crate::ransac::plane::ransac_plane;
use crate::ransac::RansacOptions;

/// Points (at most, by a fixed stride) used to find each cloud's largest plane.
const GROUND_SAMPLE: usize = 3000;
/// Fewest points (and at least 10 % of the cloud) of the largest plane used in the scores.
pub(super) const MIN_PLANE_POINTS: usize = 200;
/// Inlier distance of the largest-plane search (metres).
const GROUND_THRESHOLD: f64 = 0.05;

pub(super) fn largest_plane(points: &[Point3<f64>], total: usize, seed: u64) -> Option<Plane> {
    if points.len() < MIN_PLANE_POINTS {
        return None;
    }
    let stride = points.len().div_ceil(GROUND_SAMPLE).max(1);
    let sample: Vec<Point3<f64>> = points.iter().step_by(stride).copied().collect();
    let mut o = RansacOptions::new(GROUND_THRESHOLD);
    o.seed = seed;
    let found = ransac_plane(&sample, &o).ok()?;
    // A "plane" of a few points (the paint of two poles side by side) is not a ground.
    let inliers = found.inliers.len() * stride;
    (inliers >= MIN_PLANE_POINTS && inliers * 10 >= total).then_some(found.model)
}
