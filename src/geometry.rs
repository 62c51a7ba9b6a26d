//! Rigid-body geometry: the SO(3) and SE(3) exponential and logarithm, 4x4 conversions, and the
//! [`Plane`] and [`Line`] types shared by the rest of the crate.
//!
//! # Conventions
//! * A transform `a_from_b` maps points of frame `b` into frame `a`: `p_a = R p_b + t`. Rigid
//!   transforms are nalgebra [`Isometry3<f64>`].
//! * A tangent vector of SE(3) is ordered **translation first**: `xi = [rho; phi]`, with `phi` the
//!   rotation vector (axis times angle, radians). [`se3_exp`] maps it to the transform
//!   `[exp(phi^), V(phi) rho; 0, 1]`, the true group exponential (not a "rotation then translation"
//!   shortcut).
//! * Perturbations are applied on the left: `T <- exp(delta) * T`. The Jacobians of
//!   [`crate::residuals`] are taken with respect to this `delta`.
//! * A plane is `normal . p + offset = 0` with a unit normal; a line is a point and a unit direction.
//!
//! The exponential uses Taylor series below a small angle and the logarithm goes through a unit
//! quaternion (Shepperd's method in nalgebra), so both stay accurate near 0 and near pi.
//!
//! ```
//! use lidarcal::geometry::{se3_exp, se3_log};
//! use nalgebra::Vector6;
//! let xi = Vector6::new(0.3, -1.0, 2.0, 0.1, -0.2, 3.0);
//! let back = se3_log(&se3_exp(&xi));
//! assert!((back - xi).norm() < 1e-12);
//! ```

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3,
    Vector4, Vector6,
};

use crate::error::{ensure_finite, Error, Result};

/// Below this rotation angle (radians) the exponential and its Jacobians use Taylor series.
/// At 1e-4 rad the first dropped term is ~1e-24, far below f64 resolution.
const SMALL_ANGLE: f64 = 1e-4;

/// Largest Frobenius norm of `R^T R - I` accepted for a rotation supplied by a caller. Matrices
/// printed with 6 significant digits (as calibration files usually are) pass; anything else is not
/// a rotation. Accepted matrices are re-orthonormalised.
pub const ORTHONORMALITY_TOLERANCE: f64 = 1e-4;

/// `x.floor()` without the library call: a build for baseline x86-64 has no rounding
/// instruction, and voxel and grid keys take a floor of every coordinate of every point (the
/// call was 2.5 % of a profile of the check). Equal to `f64::floor` for every finite `x` but
/// -0.0 (which gives +0.0); NaN stays NaN.
#[inline]
pub(crate) fn floor(x: f64) -> f64 {
    // From 2^52 up every double is an integer.
    const INTEGRAL: f64 = 4_503_599_627_370_496.0;
    if x.is_nan() || x.abs() >= INTEGRAL {
        return x;
    }
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// The cell of a cubic grid of side `cell` holding `v`: `floor(v / cell)` per axis. A float
/// beyond `i64` saturates in the cast, so callers bound their inputs.
pub(crate) fn cell_key(v: &Vector3<f64>, cell: f64) -> [i64; 3] {
    [0, 1, 2].map(|k| floor(v[k] / cell) as i64)
}

/// The skew-symmetric matrix `v^` such that `v^ w = v x w`.
pub fn hat(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Coefficients `(A, B, C)` of `sin(t)/t`, `(1-cos t)/t^2`, `(t - sin t)/t^3` for `t = |phi|`.
fn rodrigues_coefficients(theta: f64) -> (f64, f64, f64) {
    if theta < SMALL_ANGLE {
        let t2 = theta * theta;
        (
            1.0 - t2 / 6.0 * (1.0 - t2 / 20.0),
            0.5 - t2 / 24.0 * (1.0 - t2 / 30.0),
            1.0 / 6.0 - t2 / 120.0 * (1.0 - t2 / 42.0),
        )
    } else {
        // 1 - cos(t) = 2 sin^2(t/2) avoids cancellation for small t.
        let s = theta.sin();
        let half = (0.5 * theta).sin();
        let t2 = theta * theta;
        (
            s / theta,
            2.0 * half * half / t2,
            (theta - s) / (t2 * theta),
        )
    }
}

/// The SO(3) exponential: the rotation by `|phi|` radians about `phi / |phi|`.
pub fn so3_exp(phi: &Vector3<f64>) -> Rotation3<f64> {
    let (a, b, _) = rodrigues_coefficients(phi.norm());
    let k = hat(phi);
    Rotation3::from_matrix_unchecked(Matrix3::identity() + k * a + k * k * b)
}

/// The SO(3) logarithm: the rotation vector `phi` with `|phi|` in `[0, pi]`.
///
/// At exactly pi both `phi` and `-phi` are valid; one of them is returned.
pub fn so3_log(rotation: &Rotation3<f64>) -> Vector3<f64> {
    quaternion_log(&UnitQuaternion::from_rotation_matrix(rotation))
}

fn quaternion_log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    // q and -q are the same rotation; pick w >= 0 so the angle is in [0, pi].
    let (w, v) = if q.w < 0.0 {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let s = v.norm();
    if s < 1e-8 {
        // atan2(s, w) / s = (1 - s^2 / (3 w^2)) / w + O(s^4); here w ~ 1.
        if s == 0.0 {
            return Vector3::zeros();
        }
        return v * (2.0 / w * (1.0 - s * s / (3.0 * w * w)));
    }
    v * (2.0 * s.atan2(w) / s)
}

/// The rotation angle in radians, in `[0, pi]`. The error between two rotations is
/// `rotation_angle(&(r_true * r.inverse()))`.
pub fn rotation_angle(rotation: &Rotation3<f64>) -> f64 {
    let q = UnitQuaternion::from_rotation_matrix(rotation);
    2.0 * q.imag().norm().atan2(q.w.abs())
}

/// The left Jacobian `V(phi)` of SO(3): `se3_exp([rho; phi])` has translation `V(phi) rho`.
pub fn so3_left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let (_, b, c) = rodrigues_coefficients(phi.norm());
    let k = hat(phi);
    Matrix3::identity() + k * b + k * k * c
}

/// The inverse of [`so3_left_jacobian`], valid for `|phi| < 2 pi`.
pub fn so3_left_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let d = if theta < SMALL_ANGLE {
        let t2 = theta * theta;
        1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    } else {
        // (1 - A / (2B)) / t^2 with A / (2B) = (t/2) cot(t/2), which has no 1 - cos cancellation.
        let half = 0.5 * theta;
        (1.0 - half / half.tan()) / (theta * theta)
    };
    let k = hat(phi);
    Matrix3::identity() - k * 0.5 + k * k * d
}

/// The SE(3) exponential of `xi = [rho; phi]` (translation part first).
pub fn se3_exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let rho = xi.fixed_rows::<3>(0).into_owned();
    let phi = xi.fixed_rows::<3>(3).into_owned();
    let rotation = so3_exp(&phi);
    let t = so3_left_jacobian(&phi) * rho;
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// The SE(3) logarithm: `xi = [rho; phi]` with `|phi|` in `[0, pi]`.
pub fn se3_log(pose: &Isometry3<f64>) -> Vector6<f64> {
    let phi = quaternion_log(&pose.rotation);
    let rho = so3_left_jacobian_inverse(&phi) * pose.translation.vector;
    Vector6::new(rho.x, rho.y, rho.z, phi.x, phi.y, phi.z)
}

/// Checks that `m` is a rotation (finite, orthonormal within [`ORTHONORMALITY_TOLERANCE`],
/// determinant +1) and returns the nearest exact rotation.
pub fn rotation_from_matrix(m: &Matrix3<f64>) -> Result<Rotation3<f64>> {
    ensure_finite("rotation matrix", m.iter())?;
    let defect = (m.transpose() * m - Matrix3::identity()).norm();
    if defect > ORTHONORMALITY_TOLERANCE {
        return Err(Error::InvalidInput(format!(
            "matrix is not orthonormal: |R^T R - I| = {defect:.3e} > {ORTHONORMALITY_TOLERANCE:e}"
        )));
    }
    if m.determinant() < 0.0 {
        return Err(Error::InvalidInput(
            "matrix has determinant -1: it is a reflection, not a rotation".into(),
        ));
    }
    // Nearest rotation in the Frobenius sense: the orthogonal polar factor U V^T.
    let svd = m.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => Ok(Rotation3::from_matrix_unchecked(u * v_t)),
        _ => Err(Error::Numerical("SVD of rotation matrix failed".into())),
    }
}

/// Converts a 4x4 homogeneous matrix `[R t; 0 0 0 1]` to a rigid transform, checking that it is one.
pub fn isometry_from_matrix(m: &Matrix4<f64>) -> Result<Isometry3<f64>> {
    ensure_finite("transform matrix", m.iter())?;
    let bottom = m.fixed_view::<1, 4>(3, 0);
    let expected = Vector4::new(0.0, 0.0, 0.0, 1.0).transpose();
    if (bottom - expected).amax() > 1e-9 {
        return Err(Error::InvalidInput(format!(
            "last row of a 4x4 transform must be [0, 0, 0, 1], got [{}, {}, {}, {}]",
            bottom[0], bottom[1], bottom[2], bottom[3]
        )));
    }
    let rotation = rotation_from_matrix(&m.fixed_view::<3, 3>(0, 0).into_owned())?;
    let t = m.fixed_view::<3, 1>(0, 3).into_owned();
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// The 4x4 homogeneous matrix of a rigid transform.
pub fn isometry_to_matrix(pose: &Isometry3<f64>) -> Matrix4<f64> {
    pose.to_homogeneous()
}

/// A unit vector pair `(b1, b2)` such that `(b1, b2, n)` is a right-handed orthonormal basis.
///
/// Uses the branch-free construction of Duff et al. (2017), continuous except at `n.z = 0` sign flips.
pub fn orthonormal_basis(n: &Unit<Vector3<f64>>) -> (Vector3<f64>, Vector3<f64>) {
    let sign = 1.0f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let b1 = Vector3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let b2 = Vector3::new(b, sign + n.y * n.y * a, -n.y);
    (b1, b2)
}

fn unit_vector(what: &str, v: &Vector3<f64>) -> Result<(Unit<Vector3<f64>>, f64)> {
    ensure_finite(what, v.iter())?;
    let norm = v.norm();
    if norm <= 1e-12 {
        return Err(Error::InvalidInput(format!(
            "{what} has zero length (|v| = {norm:e})"
        )));
    }
    Ok((Unit::new_unchecked(v / norm), norm))
}

/// A plane `normal . p + offset = 0` with a unit normal.
///
/// By the crate's convention the normal of an extracted plane points toward the sensor that saw
/// it, so `signed_distance(origin) = offset > 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal.
    pub normal: Unit<Vector3<f64>>,
    /// Offset `d` in `normal . p + d = 0` (the signed distance of the origin).
    pub offset: f64,
}

impl Plane {
    /// A plane from a (not necessarily unit) normal and offset; both are scaled so the normal is unit.
    pub fn new(normal: Vector3<f64>, offset: f64) -> Result<Self> {
        let (normal, norm) = unit_vector("plane normal", &normal)?;
        if !offset.is_finite() {
            return Err(Error::InvalidInput(format!(
                "plane offset is not finite: {offset}"
            )));
        }
        Ok(Plane {
            normal,
            offset: offset / norm,
        })
    }

    /// A plane from coefficients `[a, b, c, d]` of `a x + b y + c z + d = 0`.
    pub fn from_coefficients(c: &Vector4<f64>) -> Result<Self> {
        Plane::new(Vector3::new(c.x, c.y, c.z), c.w)
    }

    /// The plane through `point` with normal direction `normal`.
    pub fn from_point_normal(point: &Point3<f64>, normal: &Vector3<f64>) -> Result<Self> {
        ensure_finite("plane point", point.coords.iter())?;
        let (normal, _) = unit_vector("plane normal", normal)?;
        Ok(Plane {
            normal,
            offset: -normal.dot(&point.coords),
        })
    }

    /// Coefficients `[nx, ny, nz, d]`.
    pub fn coefficients(&self) -> Vector4<f64> {
        Vector4::new(self.normal.x, self.normal.y, self.normal.z, self.offset)
    }

    /// Signed distance of `p`: positive on the side the normal points to.
    pub fn signed_distance(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&p.coords) + self.offset
    }

    /// The point where three planes meet, `None` when their normals are linearly dependent (two
    /// parallel planes, or three sharing a line's direction).
    pub fn common_point(planes: &[Plane; 3]) -> Option<Point3<f64>> {
        let [a, b, c] = planes.map(|p| p.normal.into_inner().transpose());
        let rhs = Vector3::new(-planes[0].offset, -planes[1].offset, -planes[2].offset);
        Matrix3::from_rows(&[a, b, c])
            .lu()
            .solve(&rhs)
            .map(Point3::from)
    }

    /// The orthogonal projection of `p` onto the plane.
    pub fn project(&self, p: &Point3<f64>) -> Point3<f64> {
        p - self.normal.into_inner() * self.signed_distance(p)
    }

    /// The same plane with the normal reversed.
    pub fn flipped(&self) -> Plane {
        Plane {
            normal: -self.normal,
            offset: -self.offset,
        }
    }

    /// The same plane, its normal pointing to the side of `viewpoint` (kept as is if `viewpoint` lies on it).
    pub fn oriented_toward(&self, viewpoint: &Point3<f64>) -> Plane {
        if self.signed_distance(viewpoint) < 0.0 {
            self.flipped()
        } else {
            *self
        }
    }

    /// This plane, given in frame `b`, expressed in frame `a`.
    pub fn transformed(&self, a_from_b: &Isometry3<f64>) -> Plane {
        let normal = a_from_b.rotation * self.normal;
        let offset = self.offset - normal.dot(&a_from_b.translation.vector);
        Plane { normal, offset }
    }
}

/// A 3D line through `point` along the unit vector `direction`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    /// A point on the line.
    pub point: Point3<f64>,
    /// Unit direction.
    pub direction: Unit<Vector3<f64>>,
}

impl Line {
    /// A line through `point` along `direction` (normalised).
    pub fn new(point: Point3<f64>, direction: Vector3<f64>) -> Result<Self> {
        ensure_finite("line point", point.coords.iter())?;
        let (direction, _) = unit_vector("line direction", &direction)?;
        Ok(Line { point, direction })
    }

    /// The line through `a` and `b`, directed from `a` to `b`.
    pub fn through(a: &Point3<f64>, b: &Point3<f64>) -> Result<Self> {
        Line::new(*a, b - a)
    }

    /// The point of the line closest to `p`.
    pub fn closest_point(&self, p: &Point3<f64>) -> Point3<f64> {
        self.point + self.direction.into_inner() * self.direction.dot(&(p - self.point))
    }

    /// Euclidean distance from `p` to the line.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        (p - self.closest_point(p)).norm()
    }

    /// This line, given in frame `b`, expressed in frame `a`.
    pub fn transformed(&self, a_from_b: &Isometry3<f64>) -> Line {
        Line {
            point: a_from_b * self.point,
            direction: a_from_b.rotation * self.direction,
        }
    }

    /// The same line with its direction reversed.
    pub fn reversed(&self) -> Line {
        Line {
            point: self.point,
            direction: -self.direction,
        }
    }
}

/// The rotation angle (radians) and translation distance (metres) between two transforms:
/// `angle(R_a R_b^T)` and `|t_a - t_b|`.
pub fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let r = (a.rotation * b.rotation.inverse()).to_rotation_matrix();
    (
        rotation_angle(&r),
        (a.translation.vector - b.translation.vector).norm(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn rot_err(a: &Rotation3<f64>, b: &Rotation3<f64>) -> f64 {
        rotation_angle(&(a * b.inverse()))
    }

    #[test]
    fn floor_is_the_library_floor() {
        let mut values = vec![
            0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.999_999_999,
            -2.000_000_001,
            1e12 + 0.5,
            -1e12 - 0.5,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            9.007e15,
            -9.007e15,
            1e300,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        values.extend((0..2000).map(|i| (i as f64 - 1000.0) * 0.0137));
        for x in values {
            assert_eq!(floor(x), x.floor(), "{x}");
        }
        assert!(floor(f64::NAN).is_nan());
    }

    #[test]
    fn so3_round_trip_across_angles() {
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        for &angle in &[
            0.0,
            1e-12,
            1e-8,
            1e-5,
            SMALL_ANGLE,
            1e-3,
            0.5,
            2.0,
            3.0,
            std::f64::consts::PI - 1e-6,
            std::f64::consts::PI - 1e-10,
        ] {
            let phi = axis * angle;
            let r = so3_exp(&phi);
            let expected = Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle);
            assert!(rot_err(&r, &expected) < 1e-14, "exp at {angle}");
            let back = so3_log(&r);
            assert_relative_eq!(back, phi, epsilon = 1e-12 * angle.max(1.0));
        }
    }

    #[test]
    fn so3_log_at_exactly_pi() {
        for axis in [
            Vector3::x(),
            Vector3::y(),
            Vector3::new(1.0, 1.0, 1.0).normalize(),
        ] {
            let r = Rotation3::from_axis_angle(&Unit::new_normalize(axis), std::f64::consts::PI);
            let phi = so3_log(&r);
            assert_relative_eq!(phi.norm(), std::f64::consts::PI, epsilon = 1e-12);
            assert!(rot_err(&so3_exp(&phi), &r) < 1e-12);
        }
    }

    #[test]
    fn se3_round_trip_and_series_match() {
        for &angle in &[0.0, 1e-9, 0.99 * SMALL_ANGLE, 1.01 * SMALL_ANGLE, 1.0, 3.1] {
            let phi = Vector3::new(0.2, 0.9, -0.4).normalize() * angle;
            let xi = Vector6::new(1.5, -2.0, 0.7, phi.x, phi.y, phi.z);
            let pose = se3_exp(&xi);
            assert_relative_eq!(se3_log(&pose), xi, epsilon = 1e-12);
            // V(phi) V(phi)^-1 = I on both sides of the series threshold.
            let prod = so3_left_jacobian(&phi) * so3_left_jacobian_inverse(&phi);
            assert_relative_eq!(prod, Matrix3::identity(), epsilon = 1e-13);
        }
    }

    #[test]
    fn se3_exp_matches_matrix_exponential() {
        // Compare against a truncated power series of the 4x4 twist matrix.
        let xi = Vector6::new(0.4, -0.1, 0.3, 0.2, -0.3, 0.25);
        let mut twist = Matrix4::zeros();
        twist
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&hat(&Vector3::new(xi[3], xi[4], xi[5])));
        twist[(0, 3)] = xi[0];
        twist[(1, 3)] = xi[1];
        twist[(2, 3)] = xi[2];
        let mut term = Matrix4::identity();
        let mut sum = Matrix4::identity();
        for k in 1..30 {
            term = term * twist / k as f64;
            sum += term;
        }
        assert_relative_eq!(se3_exp(&xi).to_homogeneous(), sum, epsilon = 1e-13);
    }

    #[test]
    fn matrix_conversion_validates() {
        let pose = se3_exp(&Vector6::new(1.0, 2.0, 3.0, 0.1, 0.2, 0.3));
        let m = isometry_to_matrix(&pose);
        let back = isometry_from_matrix(&m).unwrap();
        assert_relative_eq!(back.to_homogeneous(), m, epsilon = 1e-14);

        let mut bad = m;
        bad[(3, 0)] = 0.5;
        assert!(matches!(
            isometry_from_matrix(&bad),
            Err(Error::InvalidInput(_))
        ));
        let mut scaled = m;
        scaled[(0, 0)] *= 1.1;
        assert!(isometry_from_matrix(&scaled).is_err());
        let mut reflect = Matrix4::identity();
        reflect[(2, 2)] = -1.0;
        assert!(isometry_from_matrix(&reflect).is_err());
        let mut nan = m;
        nan[(1, 1)] = f64::NAN;
        assert!(isometry_from_matrix(&nan).is_err());
    }

    #[test]
    fn plane_transform_keeps_points_on_plane() {
        let plane = Plane::new(Vector3::new(1.0, 2.0, 2.0), -6.0).unwrap();
        assert_relative_eq!(plane.normal.norm(), 1.0);
        assert_relative_eq!(plane.offset, -2.0);
        let p_b = plane.project(&Point3::new(3.0, -1.0, 4.0));
        assert_relative_eq!(plane.signed_distance(&p_b), 0.0, epsilon = 1e-12);
        let a_from_b = se3_exp(&Vector6::new(0.5, -1.0, 2.0, 0.3, -0.2, 1.0));
        let plane_a = plane.transformed(&a_from_b);
        assert_relative_eq!(
            plane_a.signed_distance(&(a_from_b * p_b)),
            0.0,
            epsilon = 1e-12
        );
        let off = Point3::new(9.0, 9.0, 9.0);
        assert_relative_eq!(
            plane_a.signed_distance(&(a_from_b * off)),
            plane.signed_distance(&off),
            epsilon = 1e-12
        );
        let toward = plane.oriented_toward(&Point3::origin());
        assert!(toward.offset >= 0.0);
        assert!(Plane::new(Vector3::zeros(), 1.0).is_err());
        assert!(Plane::new(Vector3::x(), f64::NAN).is_err());
    }

    #[test]
    fn line_distance_and_transform() {
        let line = Line::through(&Point3::new(0.0, 0.0, 0.0), &Point3::new(0.0, 0.0, 2.0)).unwrap();
        assert_relative_eq!(line.distance(&Point3::new(3.0, 4.0, 7.0)), 5.0);
        let a_from_b = se3_exp(&Vector6::new(0.5, -1.0, 2.0, 0.3, -0.2, 1.0));
        let p = Point3::new(3.0, 4.0, 7.0);
        assert_relative_eq!(
            line.transformed(&a_from_b).distance(&(a_from_b * p)),
            5.0,
            epsilon = 1e-12
        );
        assert!(Line::through(&p, &p).is_err());
    }

    #[test]
    fn orthonormal_basis_is_right_handed() {
        for n in [
            Vector3::z(),
            -Vector3::z(),
            Vector3::x(),
            Vector3::new(0.3, -0.4, 1e-9),
            Vector3::new(-1.0, 2.0, -3.0),
        ] {
            let n = Unit::new_normalize(n);
            let (b1, b2) = orthonormal_basis(&n);
            assert_relative_eq!(b1.norm(), 1.0, epsilon = 1e-14);
            assert_relative_eq!(b2.norm(), 1.0, epsilon = 1e-14);
            assert_relative_eq!(b1.dot(&b2), 0.0, epsilon = 1e-14);
            assert_relative_eq!(b1.cross(&b2), n.into_inner(), epsilon = 1e-14);
        }
    }
}
