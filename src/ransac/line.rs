//! Line estimation: the 2-point estimator, its scoring kernel and single-line RANSAC.

use nalgebra::Point3;

use super::consensus::{ransac, Score, GROUP};
use super::{Cloud, Estimator, RansacOptions, RansacResult};
use crate::error::Result;
use crate::fit::Moments;
use crate::geometry::Line;

/// Two sample points closer than this (relative to their distance from the cloud's frame origin
/// plus one metre) are coincident.
pub const MIN_SAMPLE_SEPARATION: f64 = 1e-9;

const BLOCK: usize = 1024;
const LANES: usize = 8;

/// The 2-point line estimator.
#[derive(Debug, Clone, Copy, Default)]
pub struct LineEstimator;

/// A line in the centred `f32` frame: point `[px, py, pz]` and unit direction `[ux, uy, uz]`.
pub type CentredLine = [f32; 6];

/// MSAC scores of up to [`GROUP`] lines over the structure-of-arrays cloud, in one pass.
/// The squared distance is `|q|^2 - (u . q)^2` with `q = p - point`.
pub fn score_lines_f32(
    count: bool,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    models: &[CentredLine],
    threshold: f32,
    out: &mut [Score],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { score_lines_f32_avx2(count, x, y, z, models, threshold, out) };
        return;
    }
    if count {
        score_lines_f32_impl::<true>(x, y, z, models, threshold, out)
    } else {
        score_lines_f32_impl::<false>(x, y, z, models, threshold, out)
    }
}

/// The same kernel compiled for AVX2 (8 lanes per instruction). FMA is deliberately not enabled:
/// every lane performs the same operations in the same order as the baseline build, so results
/// are bit-identical on machines with and without AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn score_lines_f32_avx2(
    count: bool,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    models: &[CentredLine],
    threshold: f32,
    out: &mut [Score],
) {
    if count {
        score_lines_f32_impl::<true>(x, y, z, models, threshold, out)
    } else {
        score_lines_f32_impl::<false>(x, y, z, models, threshold, out)
    }
}

#[inline(always)]
fn score_lines_f32_impl<const COUNT: bool>(
    x: &[f32],
    y: &[f32],
    z: &[f32],
    lines: &[CentredLine],
    threshold: f32,
    out: &mut [Score],
) {
    let count = lines.len().min(GROUP).min(out.len());
    let mut models = [[0f32; 6]; GROUP];
    models[..count].copy_from_slice(&lines[..count]);
    let t2 = threshold * threshold;
    let mut total_cost = [0f64; GROUP];
    let mut total_inliers = [0usize; GROUP];
    let n = x.len().min(y.len()).min(z.len());
    let kernel = |m: &[f32; 6], px: f32, py: f32, pz: f32| {
        let (qx, qy, qz) = (px - m[0], py - m[1], pz - m[2]);
        let along = m[3] * qx + m[4] * qy + m[5] * qz;
        qx * qx + qy * qy + qz * qz - along * along
    };
    for start in (0..n).step_by(BLOCK) {
        let end = (start + BLOCK).min(n);
        let (xb, yb, zb) = (&x[start..end], &y[start..end], &z[start..end]);
        let mut cost = [[0f32; LANES]; GROUP];
        let mut hits = [[0u32; LANES]; GROUP];
        let mut xc = xb.chunks_exact(LANES);
        let mut yc = yb.chunks_exact(LANES);
        let mut zc = zb.chunks_exact(LANES);
        for ((xs, ys), zs) in (&mut xc).zip(&mut yc).zip(&mut zc) {
            for k in 0..GROUP {
                for l in 0..LANES {
                    let d2 = kernel(&models[k], xs[l], ys[l], zs[l]);
                    let inside = d2 < t2;
                    cost[k][l] += if inside { d2 } else { t2 };
                    if COUNT {
                        hits[k][l] += inside as u32;
                    }
                }
            }
        }
        for ((xs, ys), zs) in xc
            .remainder()
            .iter()
            .zip(yc.remainder())
            .zip(zc.remainder())
        {
            for k in 0..GROUP {
                let d2 = kernel(&models[k], *xs, *ys, *zs);
                let inside = d2 < t2;
                cost[k][0] += if inside { d2 } else { t2 };
                if COUNT {
                    hits[k][0] += inside as u32;
                }
            }
        }
        for k in 0..GROUP {
            total_cost[k] += cost[k].iter().map(|&c| f64::from(c)).sum::<f64>();
            total_inliers[k] += hits[k].iter().map(|&h| h as usize).sum::<usize>();
        }
    }
    for k in 0..count {
        out[k] = Score {
            cost: total_cost[k],
            inliers: total_inliers[k],
        };
    }
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
