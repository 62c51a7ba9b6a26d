//! The data-driven intensity threshold (step 1 of the [module docs](super)).

use crate::error::{Error, FailureKind, Result};

/// The automatic threshold's gap must span at least this fraction of the intensity range.
pub(super) const MIN_INTENSITY_GAP: f64 = 0.1;
/// Fewest returns above the automatic threshold's gap: a handful of saturated returns above the
/// tape is not the tape class.
pub(super) const MIN_BRIGHT_CLASS: usize = 20;

/// The data-driven intensity threshold of the module docs.
pub fn data_threshold(intensities: &[f64]) -> Result<f64> {
    let mut v: Vec<f64> = intensities
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    if v.len() < 2 {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            "too few intensities to choose a threshold",
        ));
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let (lo, hi) = (v[0], v[v.len() - 1]);
    let range = hi - lo;
    // Tape is the brightest class: take the highest gap above the median that is wide enough
    // and leaves at least MIN_BRIGHT_CLASS returns above it, not the widest gap (a bright facade
    // between the clutter and the tape opens a wider gap below itself and was taken for tape).
    let upper = &v[v.len() / 2..];
    let mut best = (0.0, hi);
    for (k, w) in upper.windows(2).enumerate().rev() {
        let gap = w[1] - w[0];
        let above = upper.len() - (k + 1);
        if above >= MIN_BRIGHT_CLASS && range > 0.0 && gap >= MIN_INTENSITY_GAP * range {
            best = (gap, 0.5 * (w[0] + w[1]));
            break;
        }
        if gap > best.0 {
            best = (gap, 0.5 * (w[0] + w[1]));
        }
    }
    if range <= 0.0 || best.0 < MIN_INTENSITY_GAP * range {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "no clear class of bright (retro-reflective) returns: the widest intensity gap above \
             the median is {:.1} of a range {lo:.1}..{hi:.1} (need {:.0} %); pass \
             intensity_threshold or vendor",
            best.0,
            MIN_INTENSITY_GAP * 100.0
        ),
        ));
    }
    Ok(best.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_threshold_splits_the_bright_tail() {
        let mut v: Vec<f64> = (0..1000).map(|i| 5.0 + (i % 76) as f64).collect();
        v.extend((0..20).map(|i| 235.0 + i as f64));
        let t = data_threshold(&v).unwrap();
        assert!(t > 80.0 && t < 235.0, "{t}");
        let flat: Vec<f64> = (0..1000).map(|i| (i % 256) as f64).collect();
        assert!(matches!(
            data_threshold(&flat),
            Err(Error::Calibration { .. })
        ));
    }
}
