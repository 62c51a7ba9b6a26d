//! Hand-eye calibration from synchronized motions (`A_k X = X B_k`).
//!
//! Two sensors, the reference and the target, are mounted rigidly on one vehicle; the unknown is
//! `X = reference_from_target`. Each sensor's odometry gives its own poses. For two times `i`
//! and `j` a [`MotionPair`] holds `A = ref_i_from_ref_j` (`world_from_ref_i.inverse() *
//! world_from_ref_j`) and `B = tgt_i_from_tgt_j` for the same `i`, `j`; rigidity gives
//! `A X = X B`. No common view of the scene is needed.
//!
//! # Method
//! 1. **Rotation seed.** For a pair whose rotation exceeds
//!    [`HandEyeOptions::min_rotation_angle`], the rotation axes satisfy `axis(A) = R axis(B)`.
//!    A car on flat ground turns about the vertical only, so the axes alone leave the rotation
//!    about the vertical unobserved; the translations of **straight** pairs (rotation below the
//!    threshold, so `t_A ~ R t_B`) fix it. Both sets of unit vectors go into one weighted Kabsch
//!    (an axis weighted by `angle / rotation_sigma`, a direction by `|t| / translation_sigma`).
//!    When they span less than [`MIN_DIRECTION_SPREAD`] (a drive that only turns, never
//!    straight), the planar solve takes over: the tilt from the mean axes and the angle about
//!    them, together with the translation, from `(R_A - I) t + t_A = R t_B` linear in
//!    `(t, cos, sin)`. If nothing fixes the rotation, [`FailureKind::Unobservable`].
//! 2. **Translation seed.** `(R_A - I) t = R t_B - t_A` stacked over the pairs, solved through
//!    the eigen-decomposition of its normal matrix `N = sum (R_A - I)^T (R_A - I)`. `R_A - I`
//!    annihilates the rotation axis, so with planar motion `N` is singular along the common
//!    axis: an eigen-direction whose share of the trace of `N` is below [`UNOBSERVED_SHARE`] is
//!    left out (the solution has no component along it, the minimum norm) and reported as
//!    [`HandEye::unobserved_translation`].
//! 3. **Refinement.** Levenberg–Marquardt ([`crate::lm`], left perturbation of `X`) over every
//!    pair that moves, residuals `log(R_A R R_B^T R^T) / rotation_sigma` and
//!    `(R_A t + t_A - R t_B - t) / translation_sigma` in one block of six per pair under a
//!    Cauchy loss (scale [`HandEyeOptions::loss_scale`] times the robust spread of the
//!    residuals, so a drive noisier than the sigmas keeps its inliers), so a few bad odometry
//!    pairs do not pull the result. An unobserved translation direction is held at the seed's
//!    value by a prior along it. The spread is re-estimated and the solve repeated once.
//!
//! # When is a direction unobserved?
//! With one eigenvalue of `N` at share `s` of its trace, the translation's standard deviation
//! along it is about `sqrt(1 / (3 s))` times that of an average direction. [`UNOBSERVED_SHARE`]
//! (`1e-2`) flags a direction known about 6 times worse than the others. Planar driving gives a
//! share of 0; a car's body pitch and roll of about 1 degree gave `1.6e-3` in the test
//! `near_planar_drive_flags_the_vertical` (14 times worse: with the few centimetres the
//! horizontal translation is known to, the height would be off by decimetres, and odometry's
//! systematic errors make it worse). General 3D motion gives shares above `0.05`. A flagged
//! direction is reported, not guessed: take the height from a drawing or a tape measure.
//!
//! ```
//! use lidarcal::calib::sequence::hand_eye::{hand_eye, HandEyeOptions, MotionPair};
//! use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
//! let x = Isometry3::from_parts(
//!     Translation3::new(0.4, -0.2, 1.1),
//!     UnitQuaternion::from_euler_angles(0.1, -0.3, 1.2),
//! );
//! let motions = [
//!     (Vector3::new(1.0, 0.2, 0.0), Vector3::new(0.0, 0.0, 0.5)),
//!     (Vector3::new(0.3, 1.5, 0.2), Vector3::new(0.4, 0.0, 0.1)),
//!     (Vector3::new(-0.5, 0.1, 2.0), Vector3::new(0.0, 0.6, -0.2)),
//! ];
//! let pairs: Vec<MotionPair> = motions
//!     .iter()
//!     .map(|(t, r)| {
//!         let a = Isometry3::new(*t, *r);
//!         MotionPair { reference: a, target: x.inverse() * a * x }
//!     })
//!     .collect();
//! let solution = hand_eye(&pairs, &HandEyeOptions::default()).unwrap();
//! let (angle, distance) = lidarcal::geometry::pose_error(&solution.reference_from_target, &x);
//! assert!(angle < 1e-9 && distance < 1e-9);
//! assert!(solution.unobserved_translation.is_none());
//! ```

use nalgebra::{
    Isometry3, Matrix3, Matrix5, Matrix6, Rotation3, SymmetricEigen, Translation3, Unit,
    UnitQuaternion, Vector3, Vector5, Vector6,
};

use crate::error::{ensure_finite, ensure_positive, Error, FailureKind, Result};
use crate::geometry::{hat, orthonormal_basis, so3_left_jacobian_inverse, so3_log};
use crate::icp::weakest_directions;
use crate::kabsch::kabsch;
use crate::lm::{self, LeastSquaresProblem, LmOptions, LmReport, Loss, NormalEquations};

/// Fewest motion pairs [`hand_eye`] accepts.
pub const MIN_PAIRS: usize = 3;

/// The seed vectors (axes and straight directions) must have `s2 / s1 >= MIN_DIRECTION_SPREAD`
/// (singular values of Kabsch's cross-covariance) to fix the rotation. Two unit vectors at angle
/// `e` give `e^2 / 4`: `1e-3` asks for about 3.6 degrees. Kabsch's own limit (0.11 degrees) would
/// let odometry noise on the near-vertical axes of a planar drive pick the yaw.
pub const MIN_DIRECTION_SPREAD: f64 = 1e-3;

/// A translation eigen-direction whose share of the information is below this is unobserved
/// (see the module docs: known about 6 times worse than an average direction).
pub const UNOBSERVED_SHARE: f64 = 1e-2;

/// A straight pair (rotation below the threshold) seeds the rotation with its translation
/// direction when both sensors move at least this many `translation_sigma`.
const STRAIGHT_MIN_SIGMAS: f64 = 10.0;

/// Axes of rotations beyond this angle (radians, 170 degrees) are not used to seed: near 180
/// degrees the sign of an axis is decided by noise, separately for the two sensors.
const MAX_AXIS_ANGLE: f64 = 170.0 * std::f64::consts::PI / 180.0;

/// The median norm of six independent standard normals (`sqrt` of the median of chi-square with
/// six degrees of freedom, 5.348): whitened residuals of the expected noise have this median.
const CHI6_MEDIAN_NORM: f64 = 2.3126;

/// A pair is an inlier when its whitened residual norm is at most this many robust spreads
/// (about the 99.97 % quantile of the norm of six standard normals).
const INLIER_NORM: f64 = 5.0;

/// Weight of the prior that holds an unobserved translation direction, as a fraction of the
/// data's mean information per translation direction: strong enough to pin it, small enough
/// not to matter elsewhere (it acts along that direction only).
const PRIOR_STRENGTH: f64 = 1.0;

/// Robust refinements: the first from the seed, the second with the spread of its residuals.
const REFINEMENT_ROUNDS: usize = 2;

/// Planar seed: `|(cos, sin)|` solved as independent unknowns must lie within this factor of 1.
const PLANAR_SCALE_TOLERANCE: f64 = 2.0;

/// Relative eigenvalue below which the planar seed's normal matrix is singular.
const PLANAR_RANK_TOLERANCE: f64 = 1e-9;

/// One synchronized motion of the two sensors between two times `i` and `j`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionPair {
    /// `ref_i_from_ref_j`: `world_from_ref_i.inverse() * world_from_ref_j`.
    pub reference: Isometry3<f64>,
    /// `tgt_i_from_tgt_j`, the same times.
    pub target: Isometry3<f64>,
}

/// Options of [`hand_eye`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandEyeOptions {
    /// A pair's rotation axis counts (seeds the rotation) above this angle, radians. Below it the
    /// pair is "straight" and its translation direction seeds the rotation instead.
    pub min_rotation_angle: f64,
    /// Expected odometry rotation noise of one pair, radians: the unit of the rotation residuals.
    pub rotation_sigma: f64,
    /// Expected odometry translation noise of one pair, metres: the unit of the translation
    /// residuals.
    pub translation_sigma: f64,
    /// `true` for the Cauchy loss, `false` for plain least squares.
    pub robust: bool,
    /// Cauchy scale in units of the residuals' robust spread (at least the sigmas).
    pub loss_scale: f64,
    /// The refinement's solver options.
    pub lm: LmOptions,
}

impl Default for HandEyeOptions {
    fn default() -> Self {
        HandEyeOptions {
            min_rotation_angle: 1f64.to_radians(),
            rotation_sigma: 1e-3,
            translation_sigma: 0.01,
            robust: true,
            loss_scale: 4.0,
            lm: LmOptions::default(),
        }
    }
}

impl HandEyeOptions {
    /// Checks every option is in range.
    pub fn validate(&self) -> Result<()> {
        ensure_positive("min_rotation_angle", self.min_rotation_angle)?;
        if self.min_rotation_angle >= MAX_AXIS_ANGLE {
            return Err(Error::InvalidInput(format!(
                "min_rotation_angle must be below {MAX_AXIS_ANGLE} rad, got {}",
                self.min_rotation_angle
            )));
        }
        ensure_positive("rotation_sigma", self.rotation_sigma)?;
        ensure_positive("translation_sigma", self.translation_sigma)?;
        ensure_positive("loss_scale", self.loss_scale)
    }
}

/// The result of [`hand_eye`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandEye {
    /// The extrinsic `X`. Along [`HandEye::unobserved_translation`], if any, its translation has
    /// no component (the minimum norm): the motion says nothing there.
    pub reference_from_target: Isometry3<f64>,
    /// `J^T W J` of the pairs at the solution (whitened by the sigmas, robust weights included,
    /// the prior not), in the crate's tangent order `[rho; phi]` (translation first) of a left
    /// perturbation of `X`, as [`crate::lm`] and [`crate::icp::IcpResult::information`].
    pub information: Matrix6<f64>,
    /// RMS of the inlier pairs' rotation residual norms, radians.
    pub rotation_rms: f64,
    /// RMS of the inlier pairs' translation residual norms, metres.
    pub translation_rms: f64,
    /// Pairs that move (rotate above the threshold or translate) and entered the refinement.
    pub pairs_used: usize,
    /// Pairs of those whose whitened residual is within 5 robust spreads.
    pub inliers: usize,
    /// A unit direction (reference frame) the motion leaves unobserved, e.g. the common rotation
    /// axis (the vertical) of a planar drive; its largest component is positive.
    pub unobserved_translation: Option<Vector3<f64>>,
    /// The least-constrained rotation axis and its share of the rotation information.
    pub weakest_rotation: (Vector3<f64>, f64),
    /// The least-constrained translation direction and its share of the translation
    /// information (`0` unconstrained, `1/3` isotropic).
    pub weakest_translation: (Vector3<f64>, f64),
    /// The refinement's last solve (its Hessian includes the prior).
    pub report: LmReport,
}

/// A pair in the form the solver uses.
#[derive(Debug, Clone, Copy)]
struct Motion {
    ra: Matrix3<f64>,
    ta: Vector3<f64>,
    rb: Matrix3<f64>,
    tb: Vector3<f64>,
    /// Rotation vectors (axis times angle) of `A` and `B`.
    phi_a: Vector3<f64>,
    phi_b: Vector3<f64>,
}

impl Motion {
    fn new(pair: &MotionPair) -> Self {
        Motion {
            ra: pair.reference.rotation.to_rotation_matrix().into_inner(),
            ta: pair.reference.translation.vector,
            rb: pair.target.rotation.to_rotation_matrix().into_inner(),
            tb: pair.target.translation.vector,
            phi_a: so3_log(&pair.reference.rotation.to_rotation_matrix()),
            phi_b: so3_log(&pair.target.rotation.to_rotation_matrix()),
        }
    }

    fn angle(&self) -> f64 {
        self.phi_a.norm().min(self.phi_b.norm())
    }

    /// Rotation residual `log(R_A R R_B^T R^T)` and translation residual
    /// `R_A t + t_A - R t_B - t`.
    fn residual(&self, x: &Isometry3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let r = x.rotation.to_rotation_matrix().into_inner();
        let t = x.translation.vector;
        let m = self.ra * r * self.rb.transpose() * r.transpose();
        let rotation = so3_log(&Rotation3::from_matrix_unchecked(m));
        let translation = self.ra * t + self.ta - r * self.tb - t;
        (rotation, translation)
    }

    /// The residuals and their Jacobian rows with respect to a left perturbation
    /// `exp([rho; phi]) X`: rotation rows first.
    fn linearise(&self, x: &Isometry3<f64>) -> ([f64; 6], [Vector6<f64>; 6]) {
        let r = x.rotation.to_rotation_matrix().into_inner();
        let t = x.translation.vector;
        let m = self.ra * r * self.rb.transpose() * r.transpose();
        let log_m = so3_log(&Rotation3::from_matrix_unchecked(m));
        // log(exp(R_A phi) M exp(-phi)) = log M + J_l^-1(log M) (R_A - M) phi to first order
        // (J_r^-1 = J_l^-1 M).
        let d_rotation = so3_left_jacobian_inverse(&log_m) * (self.ra - m);
        let ra_minus_i = self.ra - Matrix3::identity();
        let translation = ra_minus_i * t + self.ta - r * self.tb;
        // t <- t + phi x t + rho and R t_B <- R t_B + phi x R t_B.
        let d_translation_phi = -ra_minus_i * hat(&t) + hat(&(r * self.tb));
        let mut rows = [Vector6::zeros(); 6];
        let mut values = [0.0; 6];
        for i in 0..3 {
            values[i] = log_m[i];
            values[i + 3] = translation[i];
            for k in 0..3 {
                rows[i][k + 3] = d_rotation[(i, k)];
                rows[i + 3][k] = ra_minus_i[(i, k)];
                rows[i + 3][k + 3] = d_translation_phi[(i, k)];
            }
        }
        (values, rows)
    }
}

/// A prior `direction . t = value` with weight `1 / sigma`.
#[derive(Debug, Clone, Copy)]
struct Prior {
    direction: Vector3<f64>,
    value: f64,
    weight: f64,
}

/// The refinement's least-squares problem.
struct Refinement<'a> {
    motions: &'a [Motion],
    rotation_weight: f64,
    translation_weight: f64,
    loss: Loss,
    prior: Option<Prior>,
}

impl Refinement<'_> {
    /// Whitened residual norm of each pair.
    fn whitened_norms(&self, x: &Isometry3<f64>) -> Vec<f64> {
        self.motions
            .iter()
            .map(|m| {
                let (r, t) = m.residual(x);
                ((r * self.rotation_weight).norm_squared()
                    + (t * self.translation_weight).norm_squared())
                .sqrt()
            })
            .collect()
    }
}

impl LeastSquaresProblem for Refinement<'_> {
    fn residual_count(&self) -> usize {
        6 * self.motions.len() + usize::from(self.prior.is_some())
    }

    fn normal_equations(&self, x: &Isometry3<f64>, with_derivatives: bool) -> NormalEquations {
        let mut ne = NormalEquations::default();
        let weights = [
            self.rotation_weight,
            self.rotation_weight,
            self.rotation_weight,
            self.translation_weight,
            self.translation_weight,
            self.translation_weight,
        ];
        for m in self.motions {
            if with_derivatives {
                let (mut values, mut rows) = m.linearise(x);
                for i in 0..6 {
                    values[i] *= weights[i];
                    rows[i] *= weights[i];
                }
                ne.add_block(&values, &rows, self.loss);
            } else {
                let (r, t) = m.residual(x);
                let s = (r * self.rotation_weight).norm_squared()
                    + (t * self.translation_weight).norm_squared();
                ne.add_cost(s, 6, self.loss);
            }
        }
        if let Some(p) = self.prior {
            let t = x.translation.vector;
            let r = (p.direction.dot(&t) - p.value) * p.weight;
            if with_derivatives {
                let rot = t.cross(&p.direction);
                let j = Vector6::new(
                    p.direction.x,
                    p.direction.y,
                    p.direction.z,
                    rot.x,
                    rot.y,
                    rot.z,
                ) * p.weight;
                ne.add(r, &j, Loss::Squared);
            } else {
                ne.add_cost(r * r, 1, Loss::Squared);
            }
        }
        ne
    }
}

fn check_pairs(pairs: &[MotionPair]) -> Result<()> {
    if pairs.len() < MIN_PAIRS {
        return Err(Error::InvalidInput(format!(
            "hand-eye calibration needs at least {MIN_PAIRS} motion pairs, got {}",
            pairs.len()
        )));
    }
    for (k, p) in pairs.iter().enumerate() {
        for (name, pose) in [("reference", &p.reference), ("target", &p.target)] {
            let values = pose
                .translation
                .vector
                .iter()
                .chain(pose.rotation.coords.iter());
            ensure_finite(&format!("motion pair {k} ({name})"), values)?;
        }
    }
    Ok(())
}

/// The robust spread of whitened residual norms: their median over that of
/// pure noise, at least 1 (the sigmas are the floor).
fn robust_spread(norms: &[f64]) -> f64 {
    let mut sorted = norms.to_vec();
    sorted.sort_by(f64::total_cmp);
    let median = match sorted.len() {
        0 => 0.0,
        n if n % 2 == 1 => sorted[n / 2],
        n => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
    };
    (median / CHI6_MEDIAN_NORM).max(1.0)
}

/// The rotation seed: weighted Kabsch over axes and straight directions, else the planar solve.
fn initial_rotation(motions: &[Motion], options: &HandEyeOptions) -> Result<Rotation3<f64>> {
    let mut a = Vec::new();
    let mut b = Vec::new();
    let mut w = Vec::new();
    let min_translation = STRAIGHT_MIN_SIGMAS * options.translation_sigma;
    for m in motions {
        let (angle_a, angle_b) = (m.phi_a.norm(), m.phi_b.norm());
        let angle = angle_a.min(angle_b);
        if angle > options.min_rotation_angle && angle_a.max(angle_b) < MAX_AXIS_ANGLE {
            a.push(m.phi_a / angle_a);
            b.push(m.phi_b / angle_b);
            w.push(angle / options.rotation_sigma);
        } else if angle_a.max(angle_b) <= options.min_rotation_angle {
            let (na, nb) = (m.ta.norm(), m.tb.norm());
            if na.min(nb) >= min_translation {
                a.push(m.ta / na);
                b.push(m.tb / nb);
                w.push(na.min(nb) / options.translation_sigma);
            }
        }
    }
    if a.len() >= 2 {
        if let Ok(solution) = kabsch(&a, &b, Some(&w)) {
            let s = solution.singular_values;
            if s[1] >= MIN_DIRECTION_SPREAD * s[0] {
                return Ok(solution.rotation);
            }
        }
    }
    planar_rotation(motions, options).ok_or_else(|| {
        Error::calibration(
            FailureKind::Unobservable,
            "the motion does not fix the rotation: all motions rotate about one axis and none \
             translates enough across it to fix the rotation about that axis (drive straight \
             segments, or turns while moving)",
        )
    })
}

/// Planar seed for drives that turn about one axis and have no straight segment: the tilt aligns
/// the mean axes, the angle `psi` about the reference axis `n` comes from
/// `(R_A - I) t - cos(psi) u_perp - sin(psi) (n x u) = (n . u) n - t_A` with `u = R_tilt t_B`,
/// linear in `(t, cos psi, sin psi)`. `None` if that does not determine `psi`.
fn planar_rotation(motions: &[Motion], options: &HandEyeOptions) -> Option<Rotation3<f64>> {
    let rotating: Vec<&Motion> = motions
        .iter()
        .filter(|m| m.angle() > options.min_rotation_angle)
        .collect();
    let reference = rotating
        .iter()
        .max_by(|p, q| p.phi_a.norm().total_cmp(&q.phi_a.norm()))?
        .phi_a;
    let (mut sum_a, mut sum_b) = (Vector3::zeros(), Vector3::zeros());
    for m in &rotating {
        // A and B have equal angles, so their axes flip together.
        let sign = if m.phi_a.dot(&reference) < 0.0 {
            -1.0
        } else {
            1.0
        };
        sum_a += m.phi_a * sign;
        sum_b += m.phi_b * sign;
    }
    let n = sum_a.try_normalize(f64::EPSILON)?;
    let nb = sum_b.try_normalize(f64::EPSILON)?;
    let tilt = Rotation3::rotation_between(&nb, &n).unwrap_or_else(|| {
        let (perpendicular, _) = orthonormal_basis(&Unit::new_unchecked(nb));
        Rotation3::from_axis_angle(&Unit::new_unchecked(perpendicular), std::f64::consts::PI)
    });
    let mut lhs = Matrix5::zeros();
    let mut rhs = Vector5::zeros();
    for m in motions {
        let u = tilt * m.tb;
        let along = n * n.dot(&u);
        let mut rows = nalgebra::Matrix3x5::zeros();
        rows.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(m.ra - Matrix3::identity()));
        rows.set_column(3, &-(u - along));
        rows.set_column(4, &-n.cross(&u));
        lhs += rows.transpose() * rows;
        rhs += rows.transpose() * (along - m.ta);
    }
    let eig = SymmetricEigen::new(lhs);
    let largest = eig.eigenvalues.amax();
    let mut x = Vector5::zeros();
    for i in 0..5 {
        let v = eig.eigenvectors.column(i);
        if eig.eigenvalues[i] > PLANAR_RANK_TOLERANCE * largest {
            x += v * (v.dot(&rhs) / eig.eigenvalues[i]);
        } else if v[3].hypot(v[4]) > 0.5 {
            // The angle itself is (partly) in the null space.
            return None;
        }
    }
    let scale = x[3].hypot(x[4]);
    if !(scale.is_finite()
        && scale > 1.0 / PLANAR_SCALE_TOLERANCE
        && scale < PLANAR_SCALE_TOLERANCE)
    {
        return None;
    }
    let psi = x[4].atan2(x[3]);
    Some(Rotation3::from_axis_angle(&Unit::new_unchecked(n), psi) * tilt)
}

/// The translation seed and the unobserved direction, if any.
fn initial_translation(
    motions: &[Motion],
    rotation: &Rotation3<f64>,
) -> Result<(Vector3<f64>, Option<Vector3<f64>>)> {
    let mut normal = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for m in motions {
        let c = m.ra - Matrix3::identity();
        normal += c.transpose() * c;
        rhs += c.transpose() * (rotation * m.tb - m.ta);
    }
    let eig = SymmetricEigen::new(normal);
    let trace = normal.trace();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let share = |i: usize| {
        if trace > 0.0 {
            eig.eigenvalues[i] / trace
        } else {
            0.0
        }
    };
    if share(order[1]) < UNOBSERVED_SHARE {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "the motion leaves two or more directions of the translation unobserved \
                 (information shares {:.1e}, {:.1e}): the pairs barely rotate; drive turns",
                share(order[0]).max(0.0),
                share(order[1]).max(0.0)
            ),
        ));
    }
    let unobserved = (share(order[0]) < UNOBSERVED_SHARE).then(|| {
        let v = eig.eigenvectors.column(order[0]).into_owned();
        if v[v.iamax()] < 0.0 {
            -v
        } else {
            v
        }
    });
    let mut t = Vector3::zeros();
    for (rank, &i) in order.iter().enumerate() {
        if rank == 0 && unobserved.is_some() {
            continue;
        }
        let v = eig.eigenvectors.column(i);
        t += v * (v.dot(&rhs) / eig.eigenvalues[i]);
    }
    Ok((t, unobserved))
}

/// Hand-eye calibration: the `reference_from_target` that best explains synchronized motions.
///
/// Returns [`Error::InvalidInput`] for fewer than [`MIN_PAIRS`] pairs, non-finite poses or bad
/// options; [`Error::Calibration`] with [`FailureKind::TooFewFeatures`] when fewer than
/// [`MIN_PAIRS`] pairs move, and [`FailureKind::Unobservable`] when no pair rotates (a straight
/// drive leaves the translation free) or nothing fixes the rotation.
pub fn hand_eye(pairs: &[MotionPair], options: &HandEyeOptions) -> Result<HandEye> {
    options.validate()?;
    check_pairs(pairs)?;
    let min_translation = STRAIGHT_MIN_SIGMAS * options.translation_sigma;
    let motions: Vec<Motion> = pairs
        .iter()
        .map(Motion::new)
        .filter(|m| {
            m.phi_a.norm().max(m.phi_b.norm()) > options.min_rotation_angle
                || m.ta.norm().max(m.tb.norm()) >= min_translation
        })
        .collect();
    if motions.len() < MIN_PAIRS {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
                "only {} of {} motion pairs move (rotate more than {:.2} degrees or translate \
                 {min_translation} m); at least {MIN_PAIRS} are needed",
                motions.len(),
                pairs.len(),
                options.min_rotation_angle.to_degrees()
            ),
        ));
    }
    if !motions
        .iter()
        .any(|m| m.angle() > options.min_rotation_angle)
    {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "no motion pair rotates by more than {:.2} degrees: a straight drive leaves the \
                 translation unobserved (and the rotation about the direction of travel); drive \
                 turns",
                options.min_rotation_angle.to_degrees()
            ),
        ));
    }

    let rotation = initial_rotation(&motions, options)?;
    let (t0, unobserved) = initial_translation(&motions, &rotation)?;
    let mut x = Isometry3::from_parts(
        Translation3::from(t0),
        UnitQuaternion::from_rotation_matrix(&rotation),
    );

    let mut problem = Refinement {
        motions: &motions,
        rotation_weight: 1.0 / options.rotation_sigma,
        translation_weight: 1.0 / options.translation_sigma,
        loss: Loss::Squared,
        prior: None,
    };
    if let Some(direction) = unobserved {
        let data = problem.normal_equations(&x, true);
        let mean = data.hessian.fixed_view::<3, 3>(0, 0).trace() / 3.0;
        problem.prior = Some(Prior {
            direction,
            value: direction.dot(&t0),
            weight: (PRIOR_STRENGTH * mean).sqrt(),
        });
    }
    let mut report = None;
    let mut spread = 1.0;
    for _ in 0..REFINEMENT_ROUNDS {
        spread = robust_spread(&problem.whitened_norms(&x));
        if options.robust {
            problem.loss = Loss::Cauchy {
                scale: options.loss_scale * spread,
            };
        }
        let solution = lm::solve(&problem, &x, &options.lm)?;
        x = solution.pose;
        report = Some(solution.report);
    }
    let report = report.ok_or_else(|| Error::Numerical("no refinement ran".into()))?;
    if let Some(p) = problem.prior {
        // The prior held it there up to the solver's tolerance; make it exact.
        let t = x.translation.vector;
        x.translation.vector = t - p.direction * (p.direction.dot(&t) - p.value);
    }

    let norms = problem.whitened_norms(&x);
    let inlier_limit = INLIER_NORM * robust_spread(&norms).max(spread);
    let (mut inliers, mut rotation_sq, mut translation_sq) = (0usize, 0.0, 0.0);
    for (m, norm) in motions.iter().zip(&norms) {
        if *norm <= inlier_limit {
            let (r, t) = m.residual(&x);
            inliers += 1;
            rotation_sq += r.norm_squared();
            translation_sq += t.norm_squared();
        }
    }
    let rms = |sum: f64| {
        if inliers > 0 {
            (sum / inliers as f64).sqrt()
        } else {
            0.0
        }
    };
    problem.prior = None;
    let mut data = problem.normal_equations(&x, true);
    data.symmetrize();
    let information = data.hessian;
    let [weakest_translation, weakest_rotation] = weakest_directions(&information);
    Ok(HandEye {
        reference_from_target: x,
        information,
        rotation_rms: rms(rotation_sq),
        translation_rms: rms(translation_sq),
        pairs_used: motions.len(),
        inliers,
        unobserved_translation: unobserved,
        weakest_rotation,
        weakest_translation,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_error, se3_exp};

    /// xorshift64* with Box-Muller normals: deterministic and independent of `rand`'s API.
    struct Rng(u64);

    impl Rng {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let x = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
            ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }

        fn normal(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }

        fn vector(&mut self, sigma: f64) -> Vector3<f64> {
            Vector3::new(self.normal(), self.normal(), self.normal()) * sigma
        }
    }

    const STRIDES: [usize; 3] = [1, 5, 10];
    /// Odometry noise per frame and axis: 0.05 degrees, 1 cm.
    const FRAME_ROTATION_NOISE: f64 = 0.05 * std::f64::consts::PI / 180.0;
    const FRAME_TRANSLATION_NOISE: f64 = 0.01;

    fn random_extrinsic(rng: &mut Rng) -> Isometry3<f64> {
        let axis = rng.vector(1.0).normalize();
        let angle = 0.5 + 2.5 * rng.uniform();
        let t =
            Vector3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 3.0 - Vector3::repeat(1.5);
        Isometry3::new(t, axis * angle)
    }

    /// `world_from_ref` of a vehicle moving and turning about every axis.
    fn general_drive(rng: &mut Rng, frames: usize) -> Vec<Isometry3<f64>> {
        let mut pose = Isometry3::identity();
        let mut poses = vec![pose];
        for _ in 1..frames {
            pose *= Isometry3::new(rng.vector(1.0), rng.vector(0.2));
            poses.push(pose);
        }
        poses
    }

    /// A car on flat ground at 1 m per frame: `(frames, yaw rate in degrees per frame)` segments,
    /// body pitch and roll oscillating with amplitude `tilt` (radians). The reference frame is the
    /// car's, z up.
    fn planar_drive(segments: &[(usize, f64)], tilt: f64) -> Vec<Isometry3<f64>> {
        let (mut psi, mut position) = (0.0f64, Vector3::zeros());
        let mut poses = Vec::new();
        let mut k = 0.0f64;
        for &(frames, rate) in segments {
            for _ in 0..frames {
                let pitch = tilt * (0.21 * k).sin();
                let roll = tilt * (0.13 * k + 1.0).sin();
                let rotation = UnitQuaternion::from_euler_angles(roll, pitch, psi);
                poses.push(Isometry3::from_parts(
                    Translation3::from(position),
                    rotation,
                ));
                position += Vector3::new(psi.cos(), psi.sin(), 0.0);
                psi += rate.to_radians();
                k += 1.0;
            }
        }
        poses
    }

    /// Straight stretches and turns both ways.
    const CITY: [(usize, f64); 12] = [
        (20, 0.0),
        (30, 3.0),
        (20, 0.0),
        (30, -3.0),
        (15, 0.0),
        (30, -3.0),
        (25, 0.0),
        (30, 3.0),
        (20, 0.0),
        (20, -4.5),
        (20, 0.0),
        (20, 4.5),
    ];

    /// Odometry of a trajectory: each frame's increment perturbed, the poses accumulated.
    fn odometry(truth: &[Isometry3<f64>], rng: &mut Rng) -> Vec<Isometry3<f64>> {
        let Some(first) = truth.first() else {
            return Vec::new();
        };
        let mut pose = *first;
        let mut poses = vec![pose];
        for w in truth.windows(2) {
            let increment = w[0].inverse() * w[1];
            let noise = rng.vector(FRAME_TRANSLATION_NOISE);
            let noise_r = rng.vector(FRAME_ROTATION_NOISE);
            let xi = Vector6::new(noise.x, noise.y, noise.z, noise_r.x, noise_r.y, noise_r.z);
            pose *= increment * se3_exp(&xi);
            poses.push(pose);
        }
        poses
    }

    /// Motion pairs of a reference drive and the target rigidly mounted by `x`, noisy odometry
    /// of both when `noise` (seed) is given.
    fn motion_pairs(
        reference: &[Isometry3<f64>],
        x: &Isometry3<f64>,
        noise: Option<u64>,
    ) -> Vec<MotionPair> {
        let target: Vec<_> = reference.iter().map(|p| p * x).collect();
        let (reference, target) = match noise {
            Some(seed) => {
                let mut rng = Rng(seed);
                (odometry(reference, &mut rng), odometry(&target, &mut rng))
            }
            None => (reference.to_vec(), target),
        };
        let mut pairs = Vec::new();
        for stride in STRIDES {
            for i in 0..reference.len().saturating_sub(stride) {
                let j = i + stride;
                pairs.push(MotionPair {
                    reference: reference[i].inverse() * reference[j],
                    target: target[i].inverse() * target[j],
                });
            }
        }
        pairs
    }

    /// Rotation error (degrees) and translation error (metres) with the component along
    /// `unobserved` left out.
    fn errors(result: &HandEye, x: &Isometry3<f64>) -> (f64, f64) {
        let (angle, _) = pose_error(&result.reference_from_target, x);
        let mut d = result.reference_from_target.translation.vector - x.translation.vector;
        if let Some(n) = result.unobserved_translation {
            d -= n * n.dot(&d);
        }
        (angle.to_degrees(), d.norm())
    }

    fn is_vertical(n: Option<Vector3<f64>>) -> bool {
        n.is_some_and(|n| n.z.abs() > 0.999)
    }

    #[test]
    fn general_motion_is_recovered_exactly() {
        let mut rng = Rng(7);
        let x = random_extrinsic(&mut rng);
        let pairs = motion_pairs(&general_drive(&mut rng, 60), &x, None);
        let result = hand_eye(&pairs, &HandEyeOptions::default()).unwrap();
        let (angle, distance) = pose_error(&result.reference_from_target, &x);
        assert!(
            angle < 1e-9 && distance < 1e-9,
            "{angle:e} rad {distance:e} m"
        );
        assert!(result.unobserved_translation.is_none());
        assert_eq!(result.inliers, result.pairs_used);
        assert_eq!(result.pairs_used, pairs.len());
        assert!(result.rotation_rms < 1e-9 && result.translation_rms < 1e-9);
        assert!(result.weakest_translation.1 > 0.05 && result.weakest_rotation.1 > 0.05);
    }

    #[test]
    fn general_motion_with_odometry_noise() {
        let mut worst = (0.0f64, 0.0f64);
        for seed in 1..=4 {
            let mut rng = Rng(100 + seed);
            let x = random_extrinsic(&mut rng);
            let pairs = motion_pairs(&general_drive(&mut rng, 200), &x, Some(seed));
            let result = hand_eye(&pairs, &HandEyeOptions::default()).unwrap();
            let (angle, distance) = errors(&result, &x);
            println!(
                "general seed {seed}: {angle:.4} deg {distance:.4} m, rms {:.2e} rad {:.3} m, \
                 {} of {} inliers",
                result.rotation_rms, result.translation_rms, result.inliers, result.pairs_used
            );
            assert!(result.unobserved_translation.is_none());
            worst = (worst.0.max(angle), worst.1.max(distance));
        }
        println!("general worst: {:.4} deg {:.4} m", worst.0, worst.1);
        assert!(worst.0 < 0.1 && worst.1 < 0.02, "{worst:?}");
    }

    #[test]
    fn planar_drive_reports_the_vertical_and_recovers_the_rest() {
        let mut rng = Rng(11);
        let x = random_extrinsic(&mut rng);
        let drive = planar_drive(&CITY, 0.0);
        let result = hand_eye(&motion_pairs(&drive, &x, None), &HandEyeOptions::default()).unwrap();
        assert!(is_vertical(result.unobserved_translation));
        let (angle, distance) = errors(&result, &x);
        assert!(
            angle < 1e-9 && distance < 1e-9,
            "{angle:e} deg {distance:e} m"
        );
        // The reported translation has nothing along the vertical.
        assert!(result.reference_from_target.translation.z.abs() < 1e-9);
        assert!(result.weakest_translation.0.z.abs() > 0.999);
        assert!(result.weakest_translation.1 < 1e-9);

        let mut worst = (0.0f64, 0.0f64);
        for seed in 1..=4 {
            let result = hand_eye(
                &motion_pairs(&drive, &x, Some(seed)),
                &HandEyeOptions::default(),
            )
            .unwrap();
            assert!(is_vertical(result.unobserved_translation));
            let (angle, distance) = errors(&result, &x);
            let predicted = result.information.try_inverse().map(|c| {
                (
                    c[(5, 5)].sqrt().to_degrees(),
                    c[(0, 0)].sqrt(),
                    c[(1, 1)].sqrt(),
                )
            });
            println!(
                "planar seed {seed}: {angle:.4} deg {distance:.4} m (horizontal); predicted \
                 std (yaw deg, x m, y m) {predicted:?}"
            );
            worst = (worst.0.max(angle), worst.1.max(distance));
        }
        // Measured: 0.09-0.15 deg, 1.3-5.2 cm over four seeds. The yaw comes from the directions
        // of travel (1 cm per metre of odometry noise), the horizontal translation from the six
        // turns of the drive: the overlapping pairs share their noise, so the information matrix
        // (0.004 deg, 2 mm) is far too optimistic.
        println!("planar worst: {:.4} deg {:.4} m", worst.0, worst.1);
        assert!(worst.0 < 0.2 && worst.1 < 0.07, "{worst:?}");
    }

    #[test]
    fn near_planar_drive_flags_the_vertical() {
        let mut rng = Rng(12);
        let x = random_extrinsic(&mut rng);
        let drive = planar_drive(&CITY, 1f64.to_radians());
        let exact = hand_eye(&motion_pairs(&drive, &x, None), &HandEyeOptions::default()).unwrap();
        let share = exact.weakest_translation.1;
        let (angle, distance) = errors(&exact, &x);
        println!("near-planar exact: share {share:.2e}, {angle:.2e} deg {distance:.2e} m");
        assert!(is_vertical(exact.unobserved_translation));
        assert!(share < UNOBSERVED_SHARE);
        assert!(angle < 0.02 && distance < 0.005, "{angle} deg {distance} m");

        let mut worst = (0.0f64, 0.0f64);
        for seed in 1..=4 {
            let result = hand_eye(
                &motion_pairs(&drive, &x, Some(seed)),
                &HandEyeOptions::default(),
            )
            .unwrap();
            assert!(is_vertical(result.unobserved_translation));
            let (angle, distance) = errors(&result, &x);
            println!("near-planar seed {seed}: {angle:.4} deg {distance:.4} m (horizontal)");
            worst = (worst.0.max(angle), worst.1.max(distance));
        }
        // Measured: 0.04-0.13 deg, 1.0-7.4 cm (horizontal) over four seeds.
        println!("near-planar worst: {:.4} deg {:.4} m", worst.0, worst.1);
        assert!(worst.0 < 0.2 && worst.1 < 0.1, "{worst:?}");
    }

    #[test]
    fn turning_without_straight_segments_uses_the_planar_seed() {
        let mut rng = Rng(13);
        let x = random_extrinsic(&mut rng);
        let segments: Vec<(usize, f64)> = (0..12)
            .map(|i| (15, if i % 2 == 0 { 3.0 } else { -2.0 }))
            .collect();
        let drive = planar_drive(&segments, 0.0);
        let result = hand_eye(&motion_pairs(&drive, &x, None), &HandEyeOptions::default()).unwrap();
        assert!(is_vertical(result.unobserved_translation));
        let (angle, distance) = errors(&result, &x);
        assert!(
            angle < 1e-9 && distance < 1e-9,
            "{angle:e} deg {distance:e} m"
        );
    }

    #[test]
    fn unobservable_motion_is_refused() {
        let mut rng = Rng(14);
        let x = random_extrinsic(&mut rng);
        let straight = planar_drive(&[(50, 0.0)], 0.0);
        let err = hand_eye(
            &motion_pairs(&straight, &x, None),
            &HandEyeOptions::default(),
        );
        assert_eq!(
            err.unwrap_err().kind(),
            Some(FailureKind::Unobservable),
            "a straight drive"
        );
        // Spinning in place about one axis: nothing fixes the rotation about it.
        let spin: Vec<_> = (0..40)
            .map(|k| Isometry3::new(Vector3::zeros(), Vector3::z() * 0.1 * k as f64))
            .collect();
        let err = hand_eye(&motion_pairs(&spin, &x, None), &HandEyeOptions::default());
        let err = err.unwrap_err();
        assert_eq!(err.kind(), Some(FailureKind::Unobservable), "{err}");
        assert!(err.to_string().contains("one axis"), "{err}");
    }

    #[test]
    fn malformed_input_is_refused() {
        let options = HandEyeOptions::default();
        let moving = MotionPair {
            reference: Isometry3::new(Vector3::x(), Vector3::z()),
            target: Isometry3::new(Vector3::x(), Vector3::z()),
        };
        assert!(matches!(
            hand_eye(&[moving, moving], &options),
            Err(Error::InvalidInput(_))
        ));
        let mut nan = moving;
        nan.target.translation.vector.y = f64::NAN;
        assert!(matches!(
            hand_eye(&[moving, moving, nan], &options),
            Err(Error::InvalidInput(_))
        ));
        let still = MotionPair {
            reference: Isometry3::identity(),
            target: Isometry3::identity(),
        };
        assert_eq!(
            hand_eye(&[moving, still, still, still], &options)
                .unwrap_err()
                .kind(),
            Some(FailureKind::TooFewFeatures)
        );
        let bad = HandEyeOptions {
            translation_sigma: 0.0,
            ..options
        };
        assert!(hand_eye(&[moving; 3], &bad).is_err());
    }

    #[test]
    fn analytic_jacobian_matches_numerical() {
        let mut rng = Rng(15);
        for _ in 0..5 {
            let x = random_extrinsic(&mut rng);
            // Deliberately inconsistent with x: the residuals are far from zero.
            let motion = Motion::new(&MotionPair {
                reference: Isometry3::new(rng.vector(2.0), rng.vector(0.8)),
                target: Isometry3::new(rng.vector(2.0), rng.vector(0.8)),
            });
            let (values, rows) = motion.linearise(&x);
            let stacked = |delta: &Vector6<f64>| {
                let (r, t) = motion.residual(&(se3_exp(delta) * x));
                Vector6::new(r.x, r.y, r.z, t.x, t.y, t.z)
            };
            let at = stacked(&Vector6::zeros());
            for i in 0..6 {
                assert!((values[i] - at[i]).abs() < 1e-14);
            }
            let h = 1e-6;
            for k in 0..6 {
                let mut step = Vector6::zeros();
                step[k] = h;
                let numeric = (stacked(&step) - stacked(&-step)) / (2.0 * h);
                for i in 0..6 {
                    let analytic = rows[i][k];
                    assert!(
                        (numeric[i] - analytic).abs() < 1e-6 * (1.0 + analytic.abs()),
                        "d r{i} / d delta{k}: numeric {} analytic {analytic}",
                        numeric[i]
                    );
                }
            }
        }
    }

    #[test]
    fn gross_outliers_do_not_move_the_result() {
        let mut rng = Rng(16);
        let x = random_extrinsic(&mut rng);
        let drive = planar_drive(&CITY, 1f64.to_radians());
        let clean = motion_pairs(&drive, &x, Some(5));
        let mut dirty = clean.clone();
        let mut corrupted = 0;
        for (k, pair) in dirty.iter_mut().enumerate() {
            if k % 20 == 7 {
                let axis = rng.vector(1.0).normalize();
                let gross = Isometry3::new(rng.vector(0.3), axis * 3f64.to_radians());
                pair.reference *= gross;
                corrupted += 1;
            }
        }
        let options = HandEyeOptions::default();
        let base = hand_eye(&clean, &options).unwrap();
        let robust = hand_eye(&dirty, &options).unwrap();
        let plain = hand_eye(
            &dirty,
            &HandEyeOptions {
                robust: false,
                ..options
            },
        )
        .unwrap();
        let (moved_r, moved_t) =
            pose_error(&robust.reference_from_target, &base.reference_from_target);
        let (plain_r, plain_t) =
            pose_error(&plain.reference_from_target, &base.reference_from_target);
        println!(
            "outliers {corrupted} of {}: robust moved {:.4} deg {:.4} m, least squares {:.4} deg \
             {:.4} m; {} inliers of {}",
            dirty.len(),
            moved_r.to_degrees(),
            moved_t,
            plain_r.to_degrees(),
            plain_t,
            robust.inliers,
            robust.pairs_used
        );
        assert!(moved_r.to_degrees() < 0.01 && moved_t < 0.01);
        assert!(moved_r < 0.2 * plain_r && moved_t < 0.2 * plain_t);
        assert!(robust.inliers <= robust.pairs_used - corrupted);
        assert!(robust.inliers + 2 * corrupted >= robust.pairs_used);
    }
}
