//! Free-space (visibility) consistency of two scans under a candidate transform.
//!
//! A LiDAR return at range `r` along a ray says more than "a surface is here": the space along
//! the ray in front of it is **empty**. A wrong transform (a 180-degree turn of a symmetric
//! street, a pose shifted along a facade) can make many points of one scan land near points of
//! the other, so point agreement alone cannot tell it from the truth; but it also puts points of
//! one scan into space the other sensor saw through, which the truth never does (up to moving
//! objects and noise).
//!
//! [`RangeImage`] bins a scan by azimuth and elevation around its own sensor and keeps the
//! nearest range per bin. A point (in that sensor's frame) is a **violation** when its bin holds a
//! return and the point lies clearly in front of it: `r < r_near - (VIOLATION_MARGIN +
//! VIOLATION_RELATIVE_MARGIN r_near)`. Points beyond the nearest return (occluded), in empty bins
//! (sky, outside the field of view) or within 3 m of the sensor (the blind
//! zone, the vehicle itself) are neutral. Keeping the *nearest* return per bin is the conservative
//! choice: a bin that holds the edge of a wall and the road behind it only counts the wall.
//!
//! ```
//! use lidarcal::visibility::RangeImage;
//! use nalgebra::Point3;
//!
//! // A wall 10 m ahead (x = 10).
//! let wall: Vec<_> = (0..400)
//!     .map(|i| Point3::new(10.0, (i % 20) as f64 * 0.2 - 2.0, (i / 20) as f64 * 0.2 - 2.0))
//!     .collect();
//! let image = RangeImage::new(&wall, RangeImage::DEFAULT_RESOLUTION)?;
//! assert_eq!(image.violation(&Point3::new(5.0, 0.0, 0.0)), Some(true)); // in the free space
//! assert_eq!(image.violation(&Point3::new(10.02, 0.0, 0.0)), Some(false)); // on the wall
//! assert_eq!(image.violation(&Point3::new(20.0, 0.0, 0.0)), Some(false)); // behind it
//! assert_eq!(image.violation(&Point3::new(-5.0, 0.0, 0.0)), None); // never looked there
//! # Ok::<(), lidarcal::Error>(())
//! ```

use nalgebra::{Isometry3, Point3};

use crate::error::{ensure_finite, Error, Result};

/// Points closer than this to the sensor (metres) are neutral: the blind zone of a spinning
/// LiDAR and the vehicle it is mounted on.
const MIN_VISIBILITY_RANGE: f64 = 3.0;
/// Absolute part of the margin by which a point must lie in front of the nearest return (m).
const VIOLATION_MARGIN: f64 = 0.5;
/// Relative part of that margin (share of the nearest return's range): bins widen with range.
const VIOLATION_RELATIVE_MARGIN: f64 = 0.05;
/// Scans of at least this many points are binned in two halves side by side.
const PARALLEL_POINTS: usize = 20_000;

/// The nearest range per azimuth/elevation bin of one scan, around its sensor (see the module
/// docs).
#[derive(Debug, Clone)]
pub struct RangeImage {
    resolution: f64,
    columns: usize,
    rows: usize,
    /// The first row stored: only the band of rows the scan reaches is (a spinning unit's
    /// 30-40 degrees of elevation, a fifth of the sphere), the others hold no return.
    first_row: usize,
    /// The nearest range of each bin of the stored rows, row by row (infinite where empty).
    nearest: Vec<f32>,
}

impl RangeImage {
    /// Default bin size (radians, 1 degree).
    pub const DEFAULT_RESOLUTION: f64 = std::f64::consts::PI / 180.0;

    /// Bins `points` (in the sensor's frame) at `resolution` radians. Points within
    /// 3 m are left out.
    pub fn new(points: &[Point3<f64>], resolution: f64) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 1e-4 && resolution < 1.0) {
            return Err(Error::InvalidInput(format!(
                "range image resolution must be in (1e-4, 1) rad, got {resolution}"
            )));
        }
        ensure_finite("points", points.iter().flat_map(|p| p.coords.iter()))?;
        let columns = (std::f64::consts::TAU / resolution).ceil() as usize;
        let rows = (std::f64::consts::PI / resolution).ceil() as usize + 1;
        let mut image = RangeImage {
            resolution,
            columns,
            rows,
            first_row: 0,
            nearest: Vec::new(),
        };
        // The row is monotone in z / r: the band of rows comes from the extreme ratios, before
        // any bin is stored.
        let band = |chunk: &[Point3<f64>]| {
            let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
            for p in chunk {
                let r = p.coords.norm();
                if r >= MIN_VISIBILITY_RANGE {
                    low = low.min(p.z / r);
                    high = high.max(p.z / r);
                }
            }
            (low, high)
        };
        // Minima and maxima do not depend on the order they are taken in: the halves of a
        // large scan are binned side by side (the image of a 120k-point scan took 4 ms alone)
        // and give the image one pass would.
        let halves = points.split_at(if points.len() >= PARALLEL_POINTS {
            points.len() / 2
        } else {
            0
        });
        let ((low_a, high_a), (low_b, high_b)) = crate::join(|| band(halves.0), || band(halves.1));
        let (low, high) = (low_a.min(low_b), high_a.max(high_b));
        if low > high {
            return Ok(image);
        }
        let (first, last) = (image.row(low), image.row(high));
        image.first_row = first;
        let size = columns * (last - first + 1);
        let fill = |chunk: &[Point3<f64>]| {
            let mut nearest = vec![f32::INFINITY; if chunk.is_empty() { 0 } else { size }];
            for p in chunk {
                let r = p.coords.norm();
                if r < MIN_VISIBILITY_RANGE {
                    continue;
                }
                if let Some(slot) = image.bin(p, r, size).and_then(|b| nearest.get_mut(b)) {
                    *slot = slot.min(r as f32);
                }
            }
            nearest
        };
        // The second half is never empty (the band above has a point); the first is when the
        // scan is small.
        let (mut nearest, first_half) = crate::join(|| fill(halves.1), || fill(halves.0));
        for (x, y) in nearest.iter_mut().zip(&first_half) {
            *x = x.min(*y);
        }
        image.nearest = nearest;
        Ok(image)
    }

    /// The row of elevation ratio `z / r`.
    fn row(&self, ratio: f64) -> usize {
        let elevation = ratio.clamp(-1.0, 1.0).asin() + std::f64::consts::FRAC_PI_2;
        ((elevation / self.resolution) as usize).min(self.rows - 1)
    }

    /// The index in `nearest` of the bin of `p` at range `r`, `None` outside the `stored` bins.
    fn bin(&self, p: &Point3<f64>, r: f64, stored: usize) -> Option<usize> {
        if r <= 0.0 {
            return None;
        }
        let row = self.row(p.z / r).checked_sub(self.first_row)?;
        if row * self.columns >= stored {
            return None;
        }
        let azimuth = p.y.atan2(p.x) + std::f64::consts::PI;
        let c = ((azimuth / self.resolution) as usize).min(self.columns - 1);
        Some(row * self.columns + c)
    }

    /// Whether `p` (sensor frame) lies in space the scan saw through: `Some(true)` for a
    /// violation, `Some(false)` when it is on or behind the scan's return, `None` when neutral.
    pub fn violation(&self, p: &Point3<f64>) -> Option<bool> {
        let r = p.coords.norm();
        if !r.is_finite() || r < MIN_VISIBILITY_RANGE {
            return None;
        }
        let near = f64::from(*self.nearest.get(self.bin(p, r, self.nearest.len())?)?);
        if !near.is_finite() {
            return None;
        }
        Some(r < near - VIOLATION_MARGIN - VIOLATION_RELATIVE_MARGIN * near)
    }

    /// The number of `points` (another scan's, in its own sensor's frame) that violate this
    /// scan's free space once mapped by `this_from_points`. Points within
    /// 3 m of their own sensor are left out as well: they are mostly the
    /// vehicle both sensors ride on, which the other sensor's blind zone hides.
    pub fn count_violations(
        &self,
        points: &[Point3<f64>],
        this_from_points: &Isometry3<f64>,
    ) -> usize {
        self.tally(points, this_from_points).0
    }

    /// As [`count_violations`](Self::count_violations), with the number of points tested (not
    /// neutral) beside it: `(violations, tested)`.
    pub fn tally(
        &self,
        points: &[Point3<f64>],
        this_from_points: &Isometry3<f64>,
    ) -> (usize, usize) {
        let mut violations = 0;
        let mut tested = 0;
        for p in points
            .iter()
            .filter(|p| p.coords.norm() >= MIN_VISIBILITY_RANGE)
        {
            if let Some(violates) = self.violation(&(this_from_points * p)) {
                tested += 1;
                violations += usize::from(violates);
            }
        }
        (violations, tested)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_resolution_and_points() {
        assert!(RangeImage::new(&[], 0.0).is_err());
        assert!(RangeImage::new(&[], f64::NAN).is_err());
        assert!(RangeImage::new(&[Point3::new(f64::NAN, 0.0, 0.0)], 0.01).is_err());
        let empty = RangeImage::new(&[], 0.01).unwrap();
        assert_eq!(empty.violation(&Point3::new(5.0, 0.0, 0.0)), None);
        assert_eq!(empty.violation(&Point3::origin()), None);
    }

    #[test]
    fn poles_straight_up_and_down_have_a_bin() {
        let image = RangeImage::new(&[Point3::new(0.0, 0.0, 10.0)], 0.02).unwrap();
        assert_eq!(image.violation(&Point3::new(0.0, 0.0, 5.0)), Some(true));
        assert_eq!(image.violation(&Point3::new(0.0, 0.0, -5.0)), None);
    }

    #[test]
    fn a_large_scan_binned_in_halves_gives_the_one_pass_image() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let scan: Vec<Point3<f64>> = (0..(PARALLEL_POINTS + 5001))
            .map(|_| {
                Point3::new(
                    rng.random_range(-40.0..40.0),
                    rng.random_range(-40.0..40.0),
                    rng.random_range(-3.0..3.0),
                )
            })
            .collect();
        let image = RangeImage::new(&scan, RangeImage::DEFAULT_RESOLUTION).unwrap();
        // The nearest range of each bin in one pass over the scan, in order.
        let mut nearest = vec![f32::INFINITY; image.nearest.len()];
        for p in &scan {
            let r = p.coords.norm();
            if r < MIN_VISIBILITY_RANGE {
                continue;
            }
            if let Some(b) = image.bin(p, r, nearest.len()) {
                nearest[b] = nearest[b].min(r as f32);
            }
        }
        assert!(nearest.iter().filter(|r| r.is_finite()).count() > 1000);
        assert_eq!(image.nearest, nearest);
    }

    #[test]
    fn the_stored_band_answers_as_a_whole_sphere_would() {
        use rand::{RngExt, SeedableRng};
        // A scan within -15..+10 degrees of elevation, and probes above and below it too.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let direction = |azimuth: f64, elevation: f64, r: f64| {
            Point3::new(
                r * elevation.cos() * azimuth.cos(),
                r * elevation.cos() * azimuth.sin(),
                r * elevation.sin(),
            )
        };
        let scan: Vec<Point3<f64>> = (0..5000)
            .map(|_| {
                let azimuth = rng.random_range(-3.2..3.2);
                let elevation = rng.random_range(-15f64..10.0).to_radians();
                direction(azimuth, elevation, rng.random_range(1.0..40.0))
            })
            .collect();
        let resolution = 2f64.to_radians();
        let image = RangeImage::new(&scan, resolution).unwrap();
        // The bin of a point over the whole sphere, as the image's docs define it.
        let bin = |p: &Point3<f64>| {
            let r = p.coords.norm();
            let azimuth = p.y.atan2(p.x) + std::f64::consts::PI;
            let elevation = (p.z / r).clamp(-1.0, 1.0).asin() + std::f64::consts::FRAC_PI_2;
            (
                (azimuth / resolution) as usize,
                (elevation / resolution) as usize,
            )
        };
        let (mut violations, mut neutral, mut behind) = (0, 0, 0);
        for _ in 0..5000 {
            let azimuth = rng.random_range(-3.2..3.2);
            let elevation = rng.random_range(-40f64..40.0).to_radians();
            let p = direction(azimuth, elevation, rng.random_range(0.5..50.0));
            let r = p.coords.norm();
            let near = scan
                .iter()
                .filter(|q| q.coords.norm() >= MIN_VISIBILITY_RANGE && bin(q) == bin(&p))
                .map(|q| q.coords.norm() as f32)
                .fold(f32::INFINITY, f32::min);
            let expected = (r >= MIN_VISIBILITY_RANGE && near.is_finite()).then(|| {
                let near = f64::from(near);
                r < near - VIOLATION_MARGIN - VIOLATION_RELATIVE_MARGIN * near
            });
            assert_eq!(image.violation(&p), expected, "{p:?}");
            violations += usize::from(expected == Some(true));
            neutral += usize::from(expected.is_none());
            behind += usize::from(expected == Some(false));
        }
        assert!(
            violations > 200 && neutral > 500 && behind > 500,
            "{violations} {neutral} {behind}"
        );
    }

    #[test]
    fn counting_uses_the_transform() {
        // A 6 x 6 m wall 10 m ahead; a 2 x 2 m patch of it, moved 4 m closer, lies in front of it.
        let grid = |half: i32| -> Vec<Point3<f64>> {
            (-half..=half)
                .flat_map(|i| (-half..=half).map(move |j| (i, j)))
                .map(|(i, j)| Point3::new(10.0, f64::from(i) * 0.1, f64::from(j) * 0.1))
                .collect()
        };
        let (wall, patch) = (grid(30), grid(10));
        let image = RangeImage::new(&wall, RangeImage::DEFAULT_RESOLUTION).unwrap();
        let shifted = Isometry3::translation(-4.0, 0.0, 0.0);
        assert_eq!(image.count_violations(&patch, &Isometry3::identity()), 0);
        assert_eq!(image.count_violations(&patch, &shifted), patch.len());
    }
}
