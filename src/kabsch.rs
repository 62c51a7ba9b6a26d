//! Weighted Kabsch: the rotation that best aligns two sets of corresponding vectors.
//!
//! Given pairs `(a_i, b_i)` and weights `w_i >= 0`, [`kabsch`] returns the rotation `R` minimising
//! `sum_i w_i |R b_i - a_i|^2`. With `H = sum_i w_i a_i b_i^T = U S V^T`, the minimiser is
//! `R = U diag(1, 1, det(U V^T)) V^T`; the last factor keeps `R` a rotation when the unconstrained
//! optimum would be a reflection.
//!
//! The vectors are used as given. To align plane normals (the corner method) pass the unit normals
//! themselves, consistently oriented: subtracting a corner point from them, as one published
//! description does, mixes translation into the rotation. To align point sets, use
//! [`align_points`], which centres them first.
//!
//! # Degeneracy
//! A rotation is determined only if the vectors span at least two directions. The check is on the
//! singular values `s1 >= s2 >= s3` of `H`: the input is refused when `s2 < MIN_SINGULAR_RATIO * s1`.
//! For two unit vectors at angle `e` (equal weights) `s2 / s1 = (1 - cos e) / (1 + cos e) ~ e^2 / 4`,
//! so the default of `1e-6` refuses vectors within about 0.11 degrees of parallel (or antiparallel).
//!
//! ```
//! use lidarcal::kabsch::kabsch;
//! use nalgebra::{Rotation3, Vector3};
//! let r_true = Rotation3::from_euler_angles(0.1, -0.4, 2.0);
//! let b = [Vector3::x(), Vector3::y(), Vector3::new(1.0, 1.0, 1.0)];
//! let a: Vec<_> = b.iter().map(|v| r_true * v).collect();
//! let solution = kabsch(&a, &b, None).unwrap();
//! approx::assert_relative_eq!(solution.rotation, r_true, epsilon = 1e-12);
//! ```

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::error::{ensure_finite, Error, Result};

/// Input whose second singular value is below this fraction of the first is refused as degenerate
/// (see the module docs: about 0.11 degrees between two unit vectors).
const MIN_SINGULAR_RATIO: f64 = 1e-6;

/// The result of [`kabsch`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KabschSolution {
    /// The rotation `R` minimising `sum w_i |R b_i - a_i|^2`.
    pub rotation: Rotation3<f64>,
    /// Singular values of `H = sum w_i a_i b_i^T`, largest first.
    pub singular_values: Vector3<f64>,
    /// The minimised weighted sum of squares `sum w_i |R b_i - a_i|^2`.
    pub residual: f64,
}

fn check_inputs(a_len: usize, b_len: usize, weights: Option<&[f64]>) -> Result<()> {
    if a_len != b_len {
        return Err(Error::InvalidInput(format!(
            "a and b must have the same number of vectors, got {a_len} and {b_len}"
        )));
    }
    if a_len < 2 {
        return Err(Error::InvalidInput(format!(
            "at least 2 vector pairs are needed to determine a rotation, got {a_len}"
        )));
    }
    if let Some(w) = weights {
        if w.len() != a_len {
            return Err(Error::InvalidInput(format!(
                "weights must have one entry per vector pair ({a_len}), got {}",
                w.len()
            )));
        }
        ensure_finite("weights", w.iter())?;
        if let Some(i) = w.iter().position(|&x| x < 0.0) {
            return Err(Error::InvalidInput(format!(
                "weights must be non-negative, weights[{i}] = {}",
                w[i]
            )));
        }
        if w.iter().sum::<f64>() <= 0.0 {
            return Err(Error::InvalidInput("weights sum to zero".into()));
        }
    }
    Ok(())
}

/// The rotation `R` minimising `sum_i w_i |R b_i - a_i|^2` (equal weights when `weights` is `None`).
///
/// Returns [`Error::InvalidInput`] for mismatched lengths, fewer than two pairs, non-finite values or
/// negative weights, and [`Error::Degenerate`] when the vectors do not determine a rotation.
pub fn kabsch(
    a: &[Vector3<f64>],
    b: &[Vector3<f64>],
    weights: Option<&[f64]>,
) -> Result<KabschSolution> {
    check_inputs(a.len(), b.len(), weights)?;
    ensure_finite("a", a.iter().flat_map(|v| v.iter()))?;
    ensure_finite("b", b.iter().flat_map(|v| v.iter()))?;
    let weight = |i: usize| weights.map_or(1.0, |w| w[i]);
    // The rotation does not depend on the scale of the vectors or of the weights. Extreme scales
    // (|v| near 1e300 overflows H, near 1e-300 underflows it to zero) are brought near 1 by a
    // power of two, which is exact; ordinary input is left bit for bit as it was.
    let vector_scale = power_of_two_scale(a.iter().chain(b).map(|v| v.amax()));
    let weight_scale = power_of_two_scale(weights.unwrap_or_default().iter().copied());

    let mut h = Matrix3::zeros();
    let mut norms = 0.0;
    for (i, (ai, bi)) in a.iter().zip(b).enumerate() {
        let w = weight(i) * weight_scale;
        let (ai, bi) = (ai * vector_scale, bi * vector_scale);
        h += ai * bi.transpose() * w;
        norms += w * (ai.norm_squared() + bi.norm_squared());
    }
    let mut solution = solve(&h, norms)?;
    // Back to the caller's units (inf when the true residual is not representable).
    let unscale = vector_scale * vector_scale * weight_scale;
    solution.residual /= unscale;
    solution.singular_values /= unscale;
    Ok(solution)
}

/// Magnitudes outside this range are rescaled before Kabsch accumulates products of them.
const SAFE_MAGNITUDE: (f64, f64) = (1e-100, 1e100);

/// `1` when the largest of `magnitudes` is inside [`SAFE_MAGNITUDE`] (or all are zero), else the
/// power of two that brings it near 1.
fn power_of_two_scale(magnitudes: impl Iterator<Item = f64>) -> f64 {
    let largest = magnitudes.fold(0.0f64, f64::max);
    if largest == 0.0 || (SAFE_MAGNITUDE.0..=SAFE_MAGNITUDE.1).contains(&largest) {
        return 1.0;
    }
    2f64.powi((-largest.log2().round() as i32).clamp(-1000, 1000))
}

/// Rotation from the cross-covariance `h = sum w a b^T`; `norms = sum w (|a|^2 + |b|^2)`.
fn solve(h: &Matrix3<f64>, norms: f64) -> Result<KabschSolution> {
    let svd = h.svd(true, true);
    let (u, v_t) = match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => (u, v_t),
        _ => return Err(Error::Numerical("SVD in Kabsch failed".into())),
    };
    // nalgebra does not promise an order; sort the singular values (and their vectors) descending.
    let s = svd.singular_values;
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| s[j].total_cmp(&s[i]));
    let sorted = Vector3::new(s[order[0]], s[order[1]], s[order[2]]);
    // Inputs are finite (checked above), so the singular values are too.
    if sorted[0] <= 0.0 || sorted[1] < MIN_SINGULAR_RATIO * sorted[0] {
        return Err(Error::Degenerate(format!(
            "the vectors do not determine a rotation: they span fewer than two directions \
             (singular values {:.3e}, {:.3e}, {:.3e}; need s2/s1 >= {MIN_SINGULAR_RATIO:e})",
            sorted[0], sorted[1], sorted[2]
        )));
    }
    let u = Matrix3::from_columns(&[u.column(order[0]), u.column(order[1]), u.column(order[2])]);
    let v = v_t.transpose();
    let v = Matrix3::from_columns(&[v.column(order[0]), v.column(order[1]), v.column(order[2])]);
    let d = if (u * v.transpose()).determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let mut correction = Matrix3::identity();
    correction[(2, 2)] = d;
    let r = u * correction * v.transpose();
    let rotation = Rotation3::from_matrix_unchecked(r);
    // sum w |R b - a|^2 = sum w (|a|^2 + |b|^2) - 2 tr(R^T H), and tr(R^T H) = s1 + s2 + d s3.
    let residual = (norms - 2.0 * (sorted[0] + sorted[1] + d * sorted[2])).max(0.0);
    if !r.iter().all(|x| x.is_finite()) {
        return Err(Error::Numerical(
            "Kabsch produced a non-finite rotation".into(),
        ));
    }
    Ok(KabschSolution {
        rotation,
        singular_values: sorted,
        residual,
    })
}

/// The rigid transform `a_from_b` minimising `sum_i w_i |T b_i - a_i|^2` over corresponding points.
///
/// Needs at least three points that are not collinear (two pairs determine the rotation about their
/// joining line only).
pub fn align_points(
    a: &[Point3<f64>],
    b: &[Point3<f64>],
    weights: Option<&[f64]>,
) -> Result<Isometry3<f64>> {
    check_inputs(a.len(), b.len(), weights)?;
    crate::error::ensure_points("a", a.iter())?;
    crate::error::ensure_points("b", b.iter())?;
    let weight = |i: usize| weights.map_or(1.0, |w| w[i]);
    let total: f64 = (0..a.len()).map(weight).sum();
    let mut ca = Vector3::zeros();
    let mut cb = Vector3::zeros();
    for (i, (pa, pb)) in a.iter().zip(b).enumerate() {
        ca += pa.coords * weight(i);
        cb += pb.coords * weight(i);
    }
    ca /= total;
    cb /= total;
    let mut h = Matrix3::zeros();
    let mut norms = 0.0;
    for (i, (pa, pb)) in a.iter().zip(b).enumerate() {
        let (da, db) = (pa.coords - ca, pb.coords - cb);
        h += da * db.transpose() * weight(i);
        norms += weight(i) * (da.norm_squared() + db.norm_squared());
    }
    let solution = solve(&h, norms)?;
    let t = ca - solution.rotation * cb;
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&solution.rotation),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::rotation_angle;
    use approx::assert_relative_eq;

    fn vectors() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(1.0, 0.2, -0.3),
            Vector3::new(-0.4, 1.0, 0.5),
            Vector3::new(0.3, -0.2, 1.0),
            Vector3::new(2.0, 1.0, 1.0),
        ]
    }

    #[test]
    fn recovers_rotation_exactly() {
        let r_true = Rotation3::from_euler_angles(2.9, -1.2, 0.4);
        let b = vectors();
        let a: Vec<_> = b.iter().map(|v| r_true * v).collect();
        let s = kabsch(&a, &b, None).unwrap();
        assert!(rotation_angle(&(r_true * s.rotation.inverse())) < 1e-12);
        assert_relative_eq!(s.residual, 0.0, epsilon = 1e-12);
    }

    #[test]
    fn reflection_is_corrected() {
        // a is a mirror image of b: the best proper rotation is not the reflection.
        let b = vectors();
        let a: Vec<_> = b.iter().map(|v| Vector3::new(v.x, v.y, -v.z)).collect();
        let s = kabsch(&a, &b, None).unwrap();
        assert_relative_eq!(s.rotation.matrix().determinant(), 1.0, epsilon = 1e-12);
        let direct: f64 = a
            .iter()
            .zip(&b)
            .map(|(ai, bi)| (s.rotation * bi - ai).norm_squared())
            .sum();
        assert_relative_eq!(direct, s.residual, epsilon = 1e-10);
        assert!(s.residual > 0.1);
    }

    #[test]
    fn two_vectors_suffice_and_weights_matter() {
        let r_true = Rotation3::from_euler_angles(0.3, 0.2, -0.1);
        let b = vec![Vector3::x(), Vector3::y()];
        let a: Vec<_> = b.iter().map(|v| r_true * v).collect();
        let s = kabsch(&a, &b, None).unwrap();
        assert!(rotation_angle(&(r_true * s.rotation.inverse())) < 1e-12);

        // A corrupted third pair with zero weight changes nothing.
        let mut a3 = a.clone();
        let mut b3 = b.clone();
        a3.push(Vector3::new(5.0, -3.0, 1.0));
        b3.push(Vector3::z());
        let w = [1.0, 1.0, 0.0];
        let s3 = kabsch(&a3, &b3, Some(&w)).unwrap();
        assert!(rotation_angle(&(r_true * s3.rotation.inverse())) < 1e-12);
    }

    #[test]
    fn degenerate_and_malformed_inputs_are_errors() {
        let x = Vector3::x();
        assert!(matches!(
            kabsch(&[x, x * 2.0], &[x, x], None),
            Err(Error::Degenerate(_))
        ));
        assert!(matches!(
            kabsch(&[x, -x], &[x, -x], None),
            Err(Error::Degenerate(_))
        ));
        let tiny = Vector3::new(1.0, 1e-5, 0.0).normalize(); // 1e-5 rad from x
        assert!(matches!(
            kabsch(&[x, tiny], &[x, tiny], None),
            Err(Error::Degenerate(_))
        ));
        let zero = Vector3::zeros();
        assert!(kabsch(&[zero, zero], &[zero, zero], None).is_err());
        assert!(matches!(
            kabsch(&[x], &[x], None),
            Err(Error::InvalidInput(_))
        ));
        assert!(kabsch(&[x, x], &[x], None).is_err());
        let nan = Vector3::new(f64::NAN, 0.0, 0.0);
        assert!(kabsch(&[x, nan], &[x, x], None).is_err());
        let y = Vector3::y();
        assert!(kabsch(&[x, y], &[x, y], Some(&[1.0, -1.0])).is_err());
        assert!(kabsch(&[x, y], &[x, y], Some(&[0.0, 0.0])).is_err());
        assert!(kabsch(&[x, y], &[x, y], Some(&[1.0])).is_err());
    }

    #[test]
    fn align_points_recovers_transform() {
        let r = Rotation3::from_euler_angles(0.5, -0.7, 2.5);
        let t = Vector3::new(1.0, -2.0, 0.5);
        let b: Vec<Point3<f64>> = vectors().into_iter().map(Point3::from).collect();
        let a: Vec<_> = b.iter().map(|p| r * p + t).collect();
        let pose = align_points(&a, &b, None).unwrap();
        assert!(rotation_angle(&(r * pose.rotation.to_rotation_matrix().inverse())) < 1e-12);
        assert_relative_eq!(pose.translation.vector, t, epsilon = 1e-12);
        let collinear: Vec<Point3<f64>> = (0..5).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
        assert!(matches!(
            align_points(&collinear, &collinear, None),
            Err(Error::Degenerate(_))
        ));
    }
}
