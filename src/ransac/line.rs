//! Line estimation: the 2-point estimator, its scoring kernel and single-line RANSAC.

use nalgebra::Point3;

use super::consensus::{ransac, Score, GROUP};
use super::kernel;
use super::{Cloud, Estimator, RansacOptions, RansacResult};
use crate::error::Result;
use crate::fit::Moments;
use crate::geometry::Line;

/// Two sample points closer than this (relative to their distance from the cloud's frame origin
/// plus one metre) are coincident.
const MIN_SAMPLE_SEPARATION: f64 = 1e-9;

/// The 2-point line estimator.
#[derive(Debug, Clone, Copy, Default)]
pub struct LineEstimator;

/// A line in the centred `f32` frame: point `[px, py, pz]` and unit direction `[ux, uy, uz]`.
pub type CentredLine = [f32; 6];

/// MSAC scores of up to [`GROUP`] lines over the structure-of-arrays cloud, in one pass.
/// The squared distance is `|q|^2 - (u . q)^2` with `q = p - point` (see [`super::kernel`]).
pub fn score_lines_f32(
    count_inliers: bool,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    lines: &[CentredLine],
    threshold: f32,
    out: &mut [Score],
) {
    kernel::score(
        count_inliers,
        x,
        y,
        z,
        lines,
        threshold,
        out,
        |m, px, py, pz| {
            let (qx, qy, qz) = (px - m[0], py - m[1], pz - m[2]);
            let along = m[3] * qx + m[4] * qy + m[5] * qz;
            qx * qx + qy * qy + qz * qz - along * along
        },
    );
}

/// A line in the cloud's centred `f32` frame.
pub fn centred_line(line: &Line, cloud: &Cloud<'_>) -> CentredLine {
    let p = line.point.coords - cloud.center();
    let u = line.direction;
    [
        p.x as f32, p.y as f32, p.z as f32, u.x as f32, u.y as f32, u.z as f32,
    ]
}

impl Estimator for LineEstimator {
    type Model = Line;
    const SAMPLE_SIZE: usize = 2;
    const NAME: &'static str = "line";

    fn minimal_model(&self, points: &[Point3<f64>], sample: &[usize]) -> Option<Line> {
        let a = points.get(*sample.first()?)?;
        let b = points.get(*sample.get(1)?)?;
        if (b - a).norm() <= MIN_SAMPLE_SEPARATION * (1.0 + a.coords.norm()) {
            return None;
        }
        Line::through(a, b).ok()
    }

    fn refit(&self, points: &[Point3<f64>], indices: &[usize]) -> Option<Line> {
        let moments = Moments::from_points(indices.iter().filter_map(|&i| points.get(i)));
        moments.line().ok().map(|fit| fit.line)
    }

    fn squared_distance(&self, model: &Line, p: &Point3<f64>) -> f64 {
        (p - model.closest_point(p)).norm_squared()
    }

    fn score(
        &self,
        cloud: &Cloud<'_>,
        models: &[Line],
        threshold: f64,
        count_inliers: bool,
        out: &mut [Score],
    ) {
        let (x, y, z) = cloud.soa();
        let lines: Vec<CentredLine> = models.iter().map(|m| centred_line(m, cloud)).collect();
        for (group, scores) in lines.chunks(GROUP).zip(out.chunks_mut(GROUP)) {
            score_lines_f32(count_inliers, x, y, z, group, threshold as f32, scores);
        }
    }

    fn check_cloud(&self, points: &[Point3<f64>]) -> Result<()> {
        Moments::from_points(points).line().map(|_| ())
    }
}

/// The line with the most support (MSAC) among `points`, refitted by least squares on its inliers.
pub fn ransac_line(points: &[Point3<f64>], options: &RansacOptions) -> Result<RansacResult<Line>> {
    ransac(&LineEstimator, points, options)
}
