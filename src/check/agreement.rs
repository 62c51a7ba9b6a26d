//! The first stages of a check, at one pose: overlap and agreement both ways, and free-space
//! violations both ways.

use nalgebra::{Isometry3, Point3};

use super::PreparedPair;
use crate::icp::SurfaceCloud;
use crate::visibility::RangeImage;

/// Overlap and agreement both ways at one pose.
pub(super) struct Agreement {
    /// Target points in the overlap.
    pub(super) overlap_points: usize,
    /// Overlapping target points with a surface normal there, and the same for reference points.
    pub(super) normals: (usize, usize),
    /// Share of the sampled target points in the overlap.
    pub(super) overlap: f64,
    /// The same for the reference points.
    pub(super) reverse_overlap: f64,
    /// Share of the overlapping target points within `limit` of the reference surface.
    pub(super) agreement: f64,
    /// The same for the reference points on the target surface.
    pub(super) reverse_agreement: f64,
    /// Root-mean-square residual of the agreeing target points.
    pub(super) rmse: f64,
    /// The residual a point agrees within (metres): `3 sigma` of the noise.
    pub(super) limit: f64,
}

/// Free-space violations both ways at one pose.
pub(super) struct FreeSpace {
    /// Share of the target points in the reference sensor's free space.
    pub(super) violations: f64,
    /// Share of the reference points in the target sensor's free space.
    pub(super) reverse_violations: f64,
}

impl FreeSpace {
    /// The larger share of the two ways.
    pub(super) fn worse(&self) -> f64 {
        self.violations.max(self.reverse_violations)
    }
}

impl PreparedPair {
    /// Residuals both ways at a pose: target samples on the reference surface, reference samples
    /// on the target surface.
    fn both_ways(&self, pose: &Isometry3<f64>) -> ((usize, Vec<f64>), (usize, Vec<f64>)) {
        let (r, g, options) = (&self.reference, &self.target, &self.options);
        let inverse = pose.inverse();
        crate::join(
            || residuals(&r.surface, &g.samples, pose, options.overlap_distance),
            || residuals(&g.surface, &r.samples, &inverse, options.overlap_distance),
        )
    }

    /// Overlap and agreement both ways at `t`.
    pub(super) fn agreement(&self, t: &Isometry3<f64>) -> Agreement {
        let (r, g, noise) = (&self.reference, &self.target, self.noise);
        let ((overlap_t, mut res_t), (overlap_r, res_r)) = self.both_ways(t);
        let (normals_t, normals_r) = (res_t.len(), res_r.len());
        let limit = 3.0 * noise;
        let agreement = agree(&res_t, limit);
        let reverse_agreement = agree(&res_r, limit);
        res_t.retain(|r| *r <= limit);
        let rmse = if res_t.is_empty() {
            0.0
        } else {
            (res_t.iter().map(|r| r * r).sum::<f64>() / res_t.len() as f64).sqrt()
        };
        let overlap = overlap_t as f64 / g.samples.len().max(1) as f64;
        let reverse_overlap = overlap_r as f64 / r.samples.len().max(1) as f64;
        Agreement {
            overlap_points: overlap_t,
            normals: (normals_t, normals_r),
            overlap,
            reverse_overlap,
            agreement,
            reverse_agreement,
            rmse,
            limit,
        }
    }

    /// How much the agreement rises from `given` to `pose`: the smaller of the rises both ways.
    pub(super) fn agreement_gain(&self, given: &Agreement, pose: &Isometry3<f64>) -> f64 {
        let ((_, forward), (_, backward)) = self.both_ways(pose);
        (agree(&forward, given.limit) - given.agreement)
            .min(agree(&backward, given.limit) - given.reverse_agreement)
    }

    /// Free-space violations both ways at `t`.
    pub(super) fn free_space(&self, t: &Isometry3<f64>) -> FreeSpace {
        let (r, g) = (&self.reference, &self.target);
        let inverse = t.inverse();
        let violations = violation_share(&r.image, &g.samples, t);
        let reverse_violations = violation_share(&g.image, &r.samples, &inverse);
        FreeSpace {
            violations,
            reverse_violations,
        }
    }
}

/// Share of `res` within `limit` (0 for none).
fn agree(res: &[f64], limit: f64) -> f64 {
    if res.is_empty() {
        0.0
    } else {
        res.iter().filter(|r| **r <= limit).count() as f64 / res.len() as f64
    }
}

/// Point-to-plane residuals of `points` mapped by `pose` onto `surface`: `(in overlap, |residual|
/// of those with a surface normal)`.
fn residuals(
    surface: &SurfaceCloud,
    points: &[Point3<f64>],
    pose: &Isometry3<f64>,
    overlap_distance: f64,
) -> (usize, Vec<f64>) {
    // Per point: `None` outside the overlap, `Some(None)` in it without a normal. Each point is
    // independent (a normal is a pure function of the cloud), so they are taken in parallel,
    // in order: the normals computed here are most of a check's work after its preparation.
    let found = crate::par_map(points, |p| {
        let q = pose * p;
        let (i, _) = surface.nearest(&q, overlap_distance)?;
        let residual = match (surface.normal(i), surface.points().get(i)) {
            (Some(n), Some(s)) => Some(n.dot(&(q - s)).abs()),
            _ => None,
        };
        Some(residual)
    });
    let overlap = found.iter().filter(|f| f.is_some()).count();
    (overlap, found.into_iter().flatten().flatten().collect())
}

/// Share of `points` (their own sensor's frame) that land in `image`'s free space once mapped by
/// `image_from_points`, of those it tests ([`RangeImage::tally`]).
fn violation_share(
    image: &RangeImage,
    points: &[Point3<f64>],
    image_from_points: &Isometry3<f64>,
) -> f64 {
    let (violations, tested) = image.tally(points, image_from_points);
    violations as f64 / tested.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::super::{CheckOptions, PreparedPair};
    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

    /// A floor and two walls around the sensor, `step` metres between points.
    fn room(step: f64) -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        let n = (8.0 / step) as i32;
        for i in -n..=n {
            for j in -n..=n {
                let (a, b) = (f64::from(i) * step, f64::from(j) * step);
                points.push(Point3::new(a, b, -1.5));
                if b > -1.5 {
                    points.push(Point3::new(6.0, a, b));
                    points.push(Point3::new(a, 5.0, b));
                }
            }
        }
        points
    }

    #[test]
    fn the_overlap_alone_is_the_agreements_overlap() {
        let reference = room(0.1);
        let shift = Isometry3::from_parts(
            Translation3::new(0.4, -0.3, 0.1),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.2),
        );
        let target: Vec<Point3<f64>> = room(0.13).iter().map(|p| shift * p).collect();
        let pair = PreparedPair::new(&reference, &target, &CheckOptions::default()).unwrap();
        let truth = shift.inverse();
        for pose in [
            truth,
            Translation3::new(0.2, 0.0, 0.0) * truth,
            Translation3::new(3.0, 1.0, 0.0) * truth,
            Isometry3::identity(),
        ] {
            let overlap = pair.overlap(&pose);
            assert_eq!(overlap, pair.agreement(&pose).overlap);
            assert!((0.0..=1.0).contains(&overlap));
        }
        assert!(pair.overlap(&truth) > 0.5);
    }
}
