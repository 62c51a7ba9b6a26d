//! Quality measures of a calibration without ground truth.
//!
//! [`rqe`] is the Rényi quadratic entropy "crispness" of Sheehan, Harrison and Newman
//! ("Self-calibration for a 3D laser", IJRR 2012), which Xue et al. (2019) use to compare
//! calibrations on real data: merge the two clouds with the calibration and measure how sharp the
//! result is. With
//! a Gaussian kernel of variance `sigma^2` per point, the entropy of the merged density is
//! `H = -ln C` with
//!
//! `C = 1/N^2 sum_i sum_j exp(-|x_i - x_j|^2 / (4 sigma^2))`
//!
//! (the convolution of two kernels has variance `2 sigma^2`; the constant normalisation of the
//! Gaussian is dropped, so `C` is in `(0, 1]`). A better calibration gives a crisper cloud: a
//! **larger** `C` and a smaller `H`.
//!
//! The double sum is `O(N^2)`; here pairs further apart than 3 kernel standard
//! deviations (`3 sqrt(2) sigma`) are dropped, where the kernel is below `exp(-4.5) = 0.011` of its
//! peak, and the remaining pairs are found with the hash [`Grid`] of cell `3 sqrt(2) sigma`. That
//! makes it `O(N k)` for `k` neighbours per point. The truncation lowers `C` by a bounded relative
//! amount that is the same for the calibrations being compared on the same clouds.
//!
//! ```
//! use lidarcal::metrics::rqe;
//! use nalgebra::Point3;
//! let sharp: Vec<_> = (0..100).map(|i| Point3::new(0.01 * i as f64, 0.0, 0.0)).collect();
//! let blurred: Vec<_> = (0..100)
//!     .map(|i| Point3::new(0.01 * i as f64, if i % 2 == 0 { 0.05 } else { -0.05 }, 0.0))
//!     .collect();
//! assert!(rqe(&sharp, 0.02)?.crispness > rqe(&blurred, 0.02)?.crispness);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use nalgebra::Point3;

use crate::cluster::Grid;
use crate::error::{Error, Result};

/// Pairs further apart than this many kernel standard deviations (`sqrt(2) sigma`) are dropped.
const RQE_TRUNCATION: f64 = 3.0;

/// The result of [`rqe`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rqe {
    /// `C` of the module docs, in `(0, 1]`; larger is crisper.
    pub crispness: f64,
    /// Rényi's quadratic entropy `-ln C`; smaller is crisper.
    pub entropy: f64,
    /// Ordered pairs `(i, j)` within the truncation radius (including `i = j`).
    pub pairs: u64,
}

/// Rényi quadratic entropy crispness of `points` with kernel width `sigma` (metres); see the
/// module docs. Errors for an empty or non-finite cloud or a non-positive `sigma`.
pub fn rqe(points: &[Point3<f64>], sigma: f64) -> Result<Rqe> {
    if !(sigma.is_finite() && sigma > 0.0) {
        return Err(Error::InvalidInput(format!(
            "sigma must be finite and positive, got {sigma}"
        )));
    }
    if points.is_empty() {
        return Err(Error::InvalidInput("rqe needs at least one point".into()));
    }
    let radius = RQE_TRUNCATION * std::f64::consts::SQRT_2 * sigma;
    let grid = Grid::new(points, radius)?;
    let inv = 1.0 / (4.0 * sigma * sigma);
    let mut sum = 0.0;
    let mut pairs = 0u64;
    for p in points {
        grid.for_each_within(p, radius, |_, d2| {
            sum += (-d2 * inv).exp();
            pairs += 1;
        });
    }
    let n = points.len() as f64;
    let crispness = sum / (n * n);
    Ok(Rqe {
        crispness,
        entropy: -crispness.ln(),
        pairs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_truncated_double_sum() {
        let pts: Vec<Point3<f64>> = (0..300)
            .map(|i| {
                let f = i as f64;
                Point3::new((f * 0.3).sin(), (f * 0.7).cos(), 0.01 * f)
            })
            .collect();
        let sigma = 0.1;
        let got = rqe(&pts, sigma).unwrap();
        let cut = RQE_TRUNCATION * std::f64::consts::SQRT_2 * sigma;
        let mut sum = 0.0;
        let mut full = 0.0;
        for a in &pts {
            for b in &pts {
                let d2 = (a - b).norm_squared();
                let k = (-d2 / (4.0 * sigma * sigma)).exp();
                full += k;
                if d2 <= cut * cut {
                    sum += k;
                }
            }
        }
        let n2 = (pts.len() * pts.len()) as f64;
        assert!((got.crispness - sum / n2).abs() < 1e-12);
        // The truncation changes it little.
        assert!((got.crispness - full / n2).abs() < 0.02 * full / n2);
        assert!((got.entropy + got.crispness.ln()).abs() < 1e-12);
    }

    #[test]
    fn rejects_bad_input() {
        let p = [Point3::origin()];
        assert!(rqe(&p, 0.0).is_err());
        assert!(rqe(&[], 0.1).is_err());
        assert!(rqe(&[Point3::new(f64::NAN, 0.0, 0.0)], 0.1).is_err());
        assert_eq!(rqe(&p, 0.1).unwrap().crispness, 1.0);
    }
}
