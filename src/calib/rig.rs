//! One entry point over the calibration methods ([`Method::Auto`] picks the best certified one) and
//! the calibration of a whole rig: every target to the reference, every overlapping pair of
//! targets, and a small pose graph that makes the set consistent.
//!
//! * [`calibrate`] runs one method, or for [`Method::Auto`] the corner method, the targetless plane
//!   matching and (when both clouds carry intensity) the taped poles. Every result has passed
//!   [`crate::check`]; `auto` keeps the one with the best certificate (agreement less free-space
//!   violations), or the earliest method whose pose is the best's within what the checks detect
//!   (the corner method's exact pose over a targetless one 1 cm away that scores 0.01 higher), and
//!   refuses with [`FailureKind::InconsistentMethods`] when two certified results
//!   disagree beyond their tolerance and their certificates are within [`AUTO_MARGIN`]. A method
//!   that fails with [`Error::Calibration`] is skipped (its reason and kind are kept for the error
//!   when none succeeds); malformed input is returned at once.
//! * [`calibrate_rig`] builds the edges and refines them with [`refine_pose_graph`]
//!   (Gauss–Newton on the SE(3) tangent errors, each edge weighted by its information matrix,
//!   with a step halved whenever it would raise the cost).
//!
#![cfg_attr(feature = "sim", doc = "```")]
#![cfg_attr(not(feature = "sim"), doc = "```ignore")]
//! use lidarcal::calib::rig::{calibrate, Cloud, Method, MethodOptions};
//! use lidarcal::sim::scenes::{street_scene, StreetOptions};
//!
//! let scene = street_scene(&StreetOptions::default())?;
//! let (reference, target) = (scene.reference.positions(), scene.target.positions());
//! let result = calibrate(
//!     Cloud::new(&reference),
//!     Cloud::new(&target),
//!     Method::Auto,
//!     &MethodOptions::default(),
//! )?;
//! let truth = &scene.reference_from_target;
//! let (angle, distance) =
//!     lidarcal::calib::targetless::pose_error(truth, result.reference_from_target());
//! assert!(angle.to_degrees() < 0.1 && distance < 0.02);
//! println!("{} chose {}", Method::Auto.name(), result.method().name());
//! # Ok::<(), lidarcal::Error>(())
//! ```

use nalgebra::{DMatrix, DVector, Isometry3, Matrix6, Point3, Vector6};

use crate::calib::planes::{calibrate_planes, PlanarCalibration, PlanarOptions};
use crate::calib::poles::{calibrate_poles, PoleCalibration, PoleOptions};
use crate::calib::targetless::pose_error;
use crate::calib::targetless::{calibrate_targetless, TargetlessCalibration, TargetlessOptions};
use crate::check::CheckReport;
use crate::geometry::{se3_exp, se3_log};
use crate::icp::SurfaceCloud;
use crate::{Error, FailureKind, Result};

/// Distance (m) within which a mapped target point counts as agreeing with the reference cloud,
/// for the overlap test of a target pair in [`calibrate_rig`] ([`Method::Auto`] ranks by the
/// check's certificate instead).
pub const AGREEMENT_DISTANCE: f64 = 0.25;

/// [`Method::Auto`] prefers the earlier method (corner, targetless, poles) when its certificate
/// score is within this of the best (or its pose within the checks' detectable error of the
/// best's).
pub const AUTO_TIE: f64 = 0.01;

/// When two methods pass the check but disagree beyond their tolerance, [`Method::Auto`] keeps
/// the better one only when its certificate score (agreement less violations, both ways) is ahead
/// by at least this; otherwise it refuses with [`FailureKind::InconsistentMethods`].
pub const AUTO_MARGIN: f64 = 0.1;

/// A target pair becomes an edge of the rig only when its result brings at least this fraction of
/// the points of one onto the other (the units overlap).
pub const MIN_PAIR_OVERLAP: f64 = 0.2;

/// Name of the reference sensor in a [`RigCalibration`]; no target may use it.
pub const REFERENCE: &str = "reference";

/// Which calibration method to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Every applicable method; the result that fits best.
    #[default]
    Auto,
    /// Three planes of a wall corner ([`crate::calib::planes`]).
    Planes,
    /// The planes of an ordinary scene ([`crate::calib::targetless`]).
    Targetless,
    /// Taped poles, from intensity ([`crate::calib::poles`]).
    Poles,
}

impl Method {
    /// `"auto"`, `"planes"`, `"targetless"` or `"poles"`.
    pub fn name(self) -> &'static str {
        match self {
            Method::Auto => "auto",
            Method::Planes => "planes",
            Method::Targetless => "targetless",
            Method::Poles => "poles",
        }
    }

    /// The method of that [`name`](Method::name); `Err(InvalidInput)` naming the choices otherwise.
    pub fn from_name(name: &str) -> Result<Method> {
        match name {
            "auto" => Ok(Method::Auto),
            "planes" => Ok(Method::Planes),
            "targetless" => Ok(Method::Targetless),
            "poles" => Ok(Method::Poles),
            other => Err(Error::InvalidInput(format!(
                "method must be 'auto', 'planes', 'targetless' or 'poles', got {other:?}"
            ))),
        }
    }
}

/// One sensor's cloud in its own frame, with intensities when it has them (the poles need them).
#[derive(Debug, Clone, Copy)]
pub struct Cloud<'a> {
    points: &'a [Point3<f64>],
    intensity: Option<&'a [f64]>,
}

impl<'a> Cloud<'a> {
    /// A cloud without intensity.
    pub fn new(points: &'a [Point3<f64>]) -> Self {
        Cloud {
            points,
            intensity: None,
        }
    }

    /// A cloud with one intensity per point; `Err(InvalidInput)` when the lengths differ.
    pub fn with_intensity(points: &'a [Point3<f64>], intensity: &'a [f64]) -> Result<Self> {
        if points.len() != intensity.len() {
            return Err(Error::InvalidInput(format!(
                "{} points but {} intensities",
                points.len(),
                intensity.len()
            )));
        }
        Ok(Cloud {
            points,
            intensity: Some(intensity),
        })
    }

    /// The points.
    pub fn points(&self) -> &'a [Point3<f64>] {
        self.points
    }

    /// The intensities, if any.
    pub fn intensity(&self) -> Option<&'a [f64]> {
        self.intensity
    }
}

/// What one method returned.
#[derive(Debug, Clone, PartialEq)]
pub enum Calibration {
    /// The corner method's result.
    Planes(Box<PlanarCalibration>),
    /// The targetless method's result.
    Targetless(Box<TargetlessCalibration>),
    /// The pole method's result.
    Poles(Box<PoleCalibration>),
}

impl Calibration {
    /// The method that produced it (never [`Method::Auto`]).
    pub fn method(&self) -> Method {
        match self {
            Calibration::Planes(_) => Method::Planes,
            Calibration::Targetless(_) => Method::Targetless,
            Calibration::Poles(_) => Method::Poles,
        }
    }

    /// `reference_from_target`.
    pub fn reference_from_target(&self) -> &Isometry3<f64> {
        match self {
            Calibration::Planes(c) => &c.reference_from_target,
            Calibration::Targetless(c) => &c.reference_from_target,
            Calibration::Poles(c) => &c.reference_from_target,
        }
    }

    /// The final check's report (consistent for every returned result).
    pub fn check(&self) -> &CheckReport {
        match self {
            Calibration::Planes(c) => &c.check,
            Calibration::Targetless(c) => &c.check,
            Calibration::Poles(c) => &c.check,
        }
    }

    /// Covariance of the left-perturbation tangent `[rho, phi]`, when the method gives one.
    pub fn covariance(&self) -> Option<Matrix6<f64>> {
        match self {
            Calibration::Planes(c) => c.covariance,
            Calibration::Targetless(c) => c.covariance,
            Calibration::Poles(c) => c.covariance,
        }
    }
}

/// The options of every method, and how [`Method::Auto`] compares their results.
#[derive(Debug, Clone, PartialEq)]
pub struct MethodOptions {
    /// For [`Method::Planes`].
    pub planes: PlanarOptions,
    /// For [`Method::Targetless`].
    pub targetless: TargetlessOptions,
    /// For [`Method::Poles`].
    pub poles: PoleOptions,
    /// See [`AGREEMENT_DISTANCE`].
    pub agreement_distance: f64,
    /// See [`AUTO_TIE`].
    pub auto_tie: f64,
    /// See [`AUTO_MARGIN`].
    pub auto_margin: f64,
}

impl Default for MethodOptions {
    fn default() -> Self {
        MethodOptions {
            planes: PlanarOptions::default(),
            targetless: TargetlessOptions::default(),
            poles: PoleOptions::default(),
            agreement_distance: AGREEMENT_DISTANCE,
            auto_tie: AUTO_TIE,
            auto_margin: AUTO_MARGIN,
        }
    }
}

impl MethodOptions {
    /// The defaults with `seed` for every method.
    pub fn with_seed(seed: u64) -> Self {
        let mut o = MethodOptions::default();
        o.planes.seed = seed;
        o.targetless.seed = seed;
        o.poles.seed = seed;
        o
    }
}

fn run_one(
    reference: Cloud<'_>,
    target: Cloud<'_>,
    method: Method,
    options: &MethodOptions,
) -> Result<Calibration> {
    match method {
        Method::Planes => calibrate_planes(reference.points, target.points, &options.planes)
            .map(|c| Calibration::Planes(Box::new(c))),
        Method::Targetless => {
            calibrate_targetless(reference.points, target.points, &options.targetless)
                .map(|c| Calibration::Targetless(Box::new(c)))
        }
        Method::Poles => match (reference.intensity, target.intensity) {
            (Some(ri), Some(ti)) => {
                calibrate_poles(reference.points, ri, target.points, ti, &options.poles)
                    .map(|c| Calibration::Poles(Box::new(c)))
            }
            _ => Err(Error::InvalidInput(
                "the pole method needs the intensity of both clouds".into(),
            )),
        },
        Method::Auto => auto(reference, target, options),
    }
}

/// Calibrates `reference_from_target` with one method, or with the best-fitting of all for
/// [`Method::Auto`] (see the [module docs](self)). Errors: malformed input at once;
/// `Err(Calibration)` listing each method's reason when none succeeds.
pub fn calibrate(
    reference: Cloud<'_>,
    target: Cloud<'_>,
    method: Method,
    options: &MethodOptions,
) -> Result<Calibration> {
    if !(options.agreement_distance.is_finite() && options.agreement_distance > 0.0) {
        return Err(Error::InvalidInput(format!(
            "agreement_distance must be finite and positive, got {}",
            options.agreement_distance
        )));
    }
    if !(options.auto_margin.is_finite() && options.auto_margin >= 0.0) {
        return Err(Error::InvalidInput(format!(
            "auto_margin must be finite and non-negative, got {}",
            options.auto_margin
        )));
    }
    if !(options.auto_tie.is_finite() && options.auto_tie >= 0.0) {
        return Err(Error::InvalidInput(format!(
            "auto_tie must be finite and non-negative, got {}",
            options.auto_tie
        )));
    }
    run_one(reference, target, method, options)
}

fn auto(reference: Cloud<'_>, target: Cloud<'_>, options: &MethodOptions) -> Result<Calibration> {
    let mut candidates = vec![Method::Planes, Method::Targetless];
    if reference.intensity.is_some() && target.intensity.is_some() {
        candidates.push(Method::Poles);
    }
    let mut results = Vec::new();
    let mut reasons = Vec::new();
    for method in candidates {
        match run_one(reference, target, method, options) {
            Ok(c) => results.push(c),
            Err(Error::Calibration { kind, message }) => {
                reasons.push((kind, format!("{}: {message}", method.name())))
            }
            Err(e) => return Err(e),
        }
    }
    if results.is_empty() {
        return Err(no_method_error(&reasons));
    }
    if results.len() == 1 {
        return Ok(results.remove(0));
    }
    // Every result passed its method's check. Rank them by the certificate (the noise scale of
    // the agreement comes from the clouds alone, so the reports compare directly).
    let reports: Vec<&CheckReport> = results.iter().map(Calibration::check).collect();
    let scores: Vec<f64> = reports.iter().map(|r| certificate_score(r)).collect();
    // Whether results `i` and `j` differ by more than either check can detect.
    let disagree = |i: usize, j: usize| {
        let (angle, distance) = pose_error(
            results[i].reference_from_target(),
            results[j].reference_from_target(),
        );
        let (a, b) = (reports[i], reports[j]);
        angle > a.detectable_rotation.max(b.detectable_rotation)
            || distance > a.detectable_translation.max(b.detectable_translation)
    };
    // The earliest method (the one made for the scene) whose score ties the best, or whose pose
    // is the best's within what the checks detect: a targetless pose 1 cm from the corner
    // method's exact one can score 0.01 higher on the same corner.
    let top = (0..scores.len())
        .max_by(|&a, &b| scores[a].total_cmp(&scores[b]).then(b.cmp(&a)))
        .unwrap_or(0);
    let pick = (0..scores.len())
        .find(|&i| scores[i] >= scores[top] - options.auto_tie || !disagree(i, top))
        .unwrap_or(top);
    for (i, other) in results.iter().enumerate() {
        let (chosen, rival) = (reports[pick], reports[i]);
        let (angle, distance) = pose_error(
            results[pick].reference_from_target(),
            other.reference_from_target(),
        );
        let rotation_tolerance = chosen.detectable_rotation.max(rival.detectable_rotation);
        let translation_tolerance = chosen
            .detectable_translation
            .max(rival.detectable_translation);
        if disagree(pick, i) && scores[pick] - scores[i] < options.auto_margin {
            return Err(Error::calibration(
                FailureKind::InconsistentMethods,
                format!(
                    "the {} and {} methods both passed the check but disagree by {:.2} deg / \
                     {:.1} cm (beyond their tolerance of {:.2} deg / {:.1} cm), and their \
                     certificates do not separate them (scores {:.3} and {:.3}, need a margin of \
                     {}): the scene fits two poses; calibrate with one method, or add structure",
                    results[pick].method().name(),
                    other.method().name(),
                    angle.to_degrees(),
                    distance * 100.0,
                    rotation_tolerance.to_degrees(),
                    translation_tolerance * 100.0,
                    scores[pick],
                    scores[i],
                    options.auto_margin
                ),
            ));
        }
    }
    Ok(results.swap_remove(pick))
}

/// How well a certified pose fits: the smaller of the two agreements (points within `3 sigma` of
/// the other cloud's surface) less the larger free-space violation share.
fn certificate_score(report: &CheckReport) -> f64 {
    report.agreement.min(report.reverse_agreement)
        - report.violations.max(report.reverse_violations)
}

/// The error when every method of [`Method::Auto`] refused: the kind of the method that got
/// furthest (a scene found ambiguous or unobservable says more than another method's missing
/// features), every method's reason in the message.
fn no_method_error(reasons: &[(FailureKind, String)]) -> Error {
    let rank = |k: FailureKind| match k {
        FailureKind::InconsistentMethods => 0,
        FailureKind::Ambiguous => 1,
        FailureKind::Unobservable => 2,
        FailureKind::OutOfRange => 3,
        FailureKind::NoAgreement => 4,
        FailureKind::TimeBudget => 5,
        FailureKind::TooFewFeatures => 6,
    };
    let kind = reasons
        .iter()
        .map(|(k, _)| *k)
        .min_by_key(|k| rank(*k))
        .unwrap_or(FailureKind::TooFewFeatures);
    let text: Vec<&str> = reasons.iter().map(|(_, m)| m.as_str()).collect();
    Error::calibration(
        kind,
        format!("no method calibrated this pair ({})", text.join("; ")),
    )
}

/// An edge of a pose graph: a measurement of `a_from_b` between nodes `a` and `b`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseGraphEdge {
    /// Index of node `a`.
    pub a: usize,
    /// Index of node `b`.
    pub b: usize,
    /// The measured transform mapping `b`'s points into `a`'s frame.
    pub a_from_b: Isometry3<f64>,
    /// Information matrix (inverse covariance) of the left-perturbation tangent `[rho, phi]`.
    pub information: Matrix6<f64>,
}

/// Tangent error `log(z⁻¹ · a⁻¹ · b)` of an edge measuring `z = a_from_b` against poses `a`, `b`
/// (each `reference_from_node`): translation first, then rotation.
pub fn edge_error(
    a_from_b: &Isometry3<f64>,
    reference_from_a: &Isometry3<f64>,
    reference_from_b: &Isometry3<f64>,
) -> Vector6<f64> {
    se3_log(&(a_from_b.inverse() * reference_from_a.inverse() * reference_from_b))
}

fn graph_cost(poses: &[Isometry3<f64>], edges: &[PoseGraphEdge]) -> f64 {
    edges
        .iter()
        .map(|e| {
            let r = edge_error(&e.a_from_b, &poses[e.a], &poses[e.b]);
            (r.transpose() * e.information * r)[(0, 0)]
        })
        .sum()
}

/// Step of the central differences of [`refine_pose_graph`].
const GRAPH_STEP: f64 = 1e-6;

/// Refines the poses `reference_from_node` of a pose graph whose node 0 (the reference) is fixed:
/// minimises `Σ eᵀ W e` over the edges by Gauss–Newton (Jacobians by central differences on the
/// left perturbation `T ← exp(δ) T`; a step that raises the cost is halved). Returns the refined
/// poses, node 0 unchanged. `Err(InvalidInput)` for an edge naming a missing node, a self-loop,
/// a non-finite or non-symmetric information matrix, or a node in no edge; `Err(Degenerate)` when
/// the information does not constrain every node.
pub fn refine_pose_graph(
    poses: &[Isometry3<f64>],
    edges: &[PoseGraphEdge],
    iterations: usize,
) -> Result<Vec<Isometry3<f64>>> {
    for (k, e) in edges.iter().enumerate() {
        if e.a >= poses.len() || e.b >= poses.len() || e.a == e.b {
            return Err(Error::InvalidInput(format!(
                "edge {k} joins nodes {} and {} of a graph with {} nodes",
                e.a,
                e.b,
                poses.len()
            )));
        }
        if e.information.iter().any(|v| !v.is_finite())
            || (e.information - e.information.transpose()).amax()
                > 1e-9 * e.information.amax().max(1.0)
        {
            return Err(Error::InvalidInput(format!(
                "edge {k}: the information matrix must be finite and symmetric"
            )));
        }
    }
    if let Some(lonely) = (1..poses.len()).find(|&n| !edges.iter().any(|e| e.a == n || e.b == n)) {
        return Err(Error::InvalidInput(format!(
            "node {lonely} is in no edge: nothing places it"
        )));
    }
    let mut current = poses.to_vec();
    let free = poses.len().saturating_sub(1);
    if free == 0 || edges.is_empty() {
        return Ok(current);
    }
    let size = 6 * free;
    let mut cost = graph_cost(&current, edges);
    for _ in 0..iterations {
        let mut hessian = DMatrix::<f64>::zeros(size, size);
        let mut gradient = DVector::<f64>::zeros(size);
        for e in edges {
            let e0 = edge_error(&e.a_from_b, &current[e.a], &current[e.b]);
            let mut jac = DMatrix::<f64>::zeros(6, size);
            for node in [e.a, e.b] {
                if node == 0 {
                    continue;
                }
                for d in 0..6 {
                    let mut delta = Vector6::zeros();
                    delta[d] = GRAPH_STEP;
                    let moved = |sign: f64| {
                        let step = se3_exp(&(delta * sign));
                        let (mut pa, mut pb) = (current[e.a], current[e.b]);
                        if node == e.a {
                            pa = step * pa;
                        } else {
                            pb = step * pb;
                        }
                        edge_error(&e.a_from_b, &pa, &pb)
                    };
                    let column = (moved(1.0) - moved(-1.0)) / (2.0 * GRAPH_STEP);
                    for r in 0..6 {
                        jac[(r, 6 * (node - 1) + d)] = column[r];
                    }
                }
            }
            let w = DMatrix::from_iterator(6, 6, e.information.iter().copied());
            let e0 = DVector::from_iterator(6, e0.iter().copied());
            let jtw = jac.transpose() * w;
            hessian += &jtw * &jac;
            gradient += &jtw * e0;
        }
        for i in 0..size {
            hessian[(i, i)] += 1e-9;
        }
        let Some(step) = hessian.cholesky().map(|c| -c.solve(&gradient)) else {
            return Err(Error::Degenerate(
                "the pose graph does not constrain every node (an information matrix is not \
                 positive definite)"
                    .into(),
            ));
        };
        let mut scale = 1.0;
        let mut accepted = None;
        for _ in 0..20 {
            let mut trial = current.clone();
            for (node, pose) in trial.iter_mut().enumerate().skip(1) {
                let s = step.rows(6 * (node - 1), 6) * scale;
                *pose = se3_exp(&Vector6::from_iterator(s.iter().copied())) * *pose;
            }
            let c = graph_cost(&trial, edges);
            if c.is_finite() && c <= cost {
                accepted = Some((trial, c));
                break;
            }
            scale *= 0.5;
        }
        let Some((trial, c)) = accepted else { break };
        let moved = step.norm() * scale;
        current = trial;
        cost = c;
        if moved < 1e-10 {
            break;
        }
    }
    Ok(current)
}

/// Default edge weight when a method gives no covariance: 1 cm and 0.1 degree.
fn default_information() -> Matrix6<f64> {
    let r = 0.1f64.to_radians();
    Matrix6::from_diagonal(&Vector6::new(
        1e4,
        1e4,
        1e4,
        1.0 / (r * r),
        1.0 / (r * r),
        1.0 / (r * r),
    ))
}

/// The weight of a rig edge: the inverse of the result's covariance plus a floor of 1 mm and
/// 0.01 degree (a covariance from thousands of points is optimistic), or
/// 1 cm / 0.1 degree when the method gives none.
pub fn edge_information(result: &Calibration) -> Matrix6<f64> {
    let Some(cov) = result
        .covariance()
        .filter(|c| c.iter().all(|v| v.is_finite()))
    else {
        return default_information();
    };
    let r = 0.01f64.to_radians();
    let floor = Matrix6::from_diagonal(&Vector6::new(1e-6, 1e-6, 1e-6, r * r, r * r, r * r));
    let info = (cov + floor)
        .try_inverse()
        .unwrap_or_else(default_information);
    (info + info.transpose()) * 0.5
}

/// Options of [`calibrate_rig`].
#[derive(Debug, Clone, PartialEq)]
pub struct RigOptions {
    /// The method of every edge.
    pub method: Method,
    /// The methods' options.
    pub methods: MethodOptions,
    /// Also calibrate every pair of targets, kept as an edge when they overlap.
    pub pairwise: bool,
    /// `Err` when some target cannot be connected to the reference (else it is listed in
    /// [`RigCalibration::unconnected`]).
    pub require_all: bool,
    /// See [`MIN_PAIR_OVERLAP`].
    pub min_pair_overlap: f64,
    /// Gauss–Newton iterations of the pose graph.
    pub graph_iterations: usize,
}

impl Default for RigOptions {
    fn default() -> Self {
        RigOptions {
            method: Method::Auto,
            methods: MethodOptions::default(),
            pairwise: true,
            require_all: true,
            min_pair_overlap: MIN_PAIR_OVERLAP,
            graph_iterations: 20,
        }
    }
}

/// One pairwise calibration used by [`calibrate_rig`].
#[derive(Debug, Clone, PartialEq)]
pub struct RigEdge {
    /// Sensor `a` ([`REFERENCE`] or a target name).
    pub a: String,
    /// Sensor `b`.
    pub b: String,
    /// The method that calibrated it.
    pub method: Method,
    /// Maps `b`'s points into `a`'s frame.
    pub a_from_b: Isometry3<f64>,
    /// The information matrix it was weighted with.
    pub information: Matrix6<f64>,
    /// Disagreement of the refined rig with this edge, rotation (degrees).
    pub rotation_residual_deg: f64,
    /// Disagreement of the refined rig with this edge, translation (m).
    pub translation_residual_m: f64,
    /// The method's full result (diagnostics, inliers, covariance).
    pub result: Calibration,
}

/// A pair that gave no edge, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct RigFailure {
    /// Sensor `a`.
    pub a: String,
    /// Sensor `b`.
    pub b: String,
    /// The reason.
    pub reason: String,
    /// Its kind (`None` only for a pair calibrated but barely overlapping).
    pub kind: Option<FailureKind>,
}

/// The calibrated rig.
#[derive(Debug, Clone, PartialEq)]
pub struct RigCalibration {
    /// `(name, reference_from_name)` after the pose-graph refinement, in the targets' order.
    pub transforms: Vec<(String, Isometry3<f64>)>,
    /// `(name, reference_from_name)` of the direct calibrations to the reference that succeeded.
    pub direct: Vec<(String, Isometry3<f64>)>,
    /// Every pairwise result used, with its residual against the refined rig.
    pub edges: Vec<RigEdge>,
    /// The pairs that could not be calibrated or do not overlap.
    pub failures: Vec<RigFailure>,
    /// Targets nothing connects to the reference (only with `require_all = false`).
    pub unconnected: Vec<String>,
}

impl RigCalibration {
    /// `reference_from_name` after refinement, if that target was placed.
    pub fn transform(&self, name: &str) -> Option<&Isometry3<f64>> {
        self.transforms
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, p)| p)
    }
}

/// Calibrates several targets against one reference and makes the set consistent: each target to
/// the reference; with `pairwise`, each pair of targets too, kept when the result brings at least
/// `min_pair_overlap` of one's points onto the other; initial poses by breadth-first search from
/// the reference; then [`refine_pose_graph`] with every kept edge weighted by
/// [`edge_information`]. A target that fails against the reference but overlaps a placed target
/// is reached through it. Errors: `InvalidInput` for no targets, a target named [`REFERENCE`] or
/// two targets of one name; `Calibration` naming every pair's reason when some target cannot be
/// placed and `require_all` is set (or when none can).
pub fn calibrate_rig(
    reference: Cloud<'_>,
    targets: &[(&str, Cloud<'_>)],
    options: &RigOptions,
) -> Result<RigCalibration> {
    if targets.is_empty() {
        return Err(Error::InvalidInput("targets is empty".into()));
    }
    for (i, (name, _)) in targets.iter().enumerate() {
        if *name == REFERENCE {
            return Err(Error::InvalidInput(format!(
                "'{REFERENCE}' is reserved for the reference sensor; rename that target"
            )));
        }
        if targets[..i].iter().any(|(n, _)| n == name) {
            return Err(Error::InvalidInput(format!(
                "two targets are named {name:?}"
            )));
        }
    }
    if !(options.min_pair_overlap.is_finite() && (0.0..=1.0).contains(&options.min_pair_overlap)) {
        return Err(Error::InvalidInput(format!(
            "min_pair_overlap must be in [0, 1], got {}",
            options.min_pair_overlap
        )));
    }
    // Node 0 is the reference, node i + 1 the target i.
    let names: Vec<&str> = std::iter::once(REFERENCE)
        .chain(targets.iter().map(|(n, _)| *n))
        .collect();
    let clouds: Vec<Cloud<'_>> = std::iter::once(reference)
        .chain(targets.iter().map(|(_, c)| *c))
        .collect();
    let mut measured: Vec<(usize, usize, Calibration)> = Vec::new();
    let mut failures = Vec::new();
    let mut fail = |a: usize, b: usize, kind: Option<FailureKind>, reason: String| {
        failures.push(RigFailure {
            a: names[a].to_string(),
            b: names[b].to_string(),
            reason,
            kind,
        })
    };
    let mut direct = Vec::new();
    for b in 1..clouds.len() {
        match calibrate(clouds[0], clouds[b], options.method, &options.methods) {
            Ok(c) => {
                direct.push((names[b].to_string(), *c.reference_from_target()));
                measured.push((0, b, c));
            }
            Err(Error::Calibration { kind, message }) => fail(0, b, Some(kind), message),
            Err(e) => return Err(e),
        }
    }
    if options.pairwise {
        for a in 1..clouds.len() {
            // Indexed once per target, on its first calibrated pair.
            let mut surface: Option<SurfaceCloud> = None;
            for b in a + 1..clouds.len() {
                let c = match calibrate(clouds[a], clouds[b], options.method, &options.methods) {
                    Ok(c) => c,
                    Err(Error::Calibration { kind, message }) => {
                        fail(a, b, Some(kind), message);
                        continue;
                    }
                    Err(e) => return Err(e),
                };
                let surface = match surface {
                    Some(ref s) => s,
                    None => surface.insert(SurfaceCloud::new(clouds[a].points.to_vec())?),
                };
                let shared = surface.overlap(
                    clouds[b].points,
                    c.reference_from_target(),
                    options.methods.agreement_distance,
                );
                if shared < options.min_pair_overlap {
                    fail(
                        a,
                        b,
                        None,
                        "the two units barely overlap under the result".into(),
                    );
                    continue;
                }
                measured.push((a, b, c));
            }
        }
    }
    // Initial poses: breadth-first from the reference over the measured edges.
    let mut poses: Vec<Option<Isometry3<f64>>> = vec![None; clouds.len()];
    poses[0] = Some(Isometry3::identity());
    let mut changed = true;
    while changed {
        changed = false;
        for (a, b, c) in &measured {
            match (poses[*a], poses[*b]) {
                (Some(pa), None) => {
                    poses[*b] = Some(pa * c.reference_from_target());
                    changed = true;
                }
                (None, Some(pb)) => {
                    poses[*a] = Some(pb * c.reference_from_target().inverse());
                    changed = true;
                }
                _ => {}
            }
        }
    }
    let unconnected: Vec<String> = (1..clouds.len())
        .filter(|&i| poses[i].is_none())
        .map(|i| names[i].to_string())
        .collect();
    let placed = poses.iter().filter(|p| p.is_some()).count();
    if !unconnected.is_empty() && (options.require_all || placed == 1) {
        let reasons: Vec<String> = failures
            .iter()
            .map(|f| format!("{}->{}: {}", f.a, f.b, f.reason))
            .collect();
        // The kind of the first unconnected target's own failure against the reference.
        let kind = failures
            .iter()
            .find(|f| f.a == REFERENCE && unconnected.contains(&f.b))
            .and_then(|f| f.kind)
            .unwrap_or(FailureKind::TooFewFeatures);
        return Err(Error::calibration(
            kind,
            format!(
                "could not connect {} to the reference ({})",
                unconnected.join(", "),
                reasons.join("; ")
            ),
        ));
    }
    // The graph over the placed nodes only (edges between unplaced targets cannot be used).
    let index: Vec<Option<usize>> = {
        let mut next = 0;
        poses
            .iter()
            .map(|p| {
                p.map(|_| {
                    next += 1;
                    next - 1
                })
            })
            .collect()
    };
    let (measured, graph): (Vec<(usize, usize, Calibration)>, Vec<PoseGraphEdge>) = measured
        .into_iter()
        .filter_map(|(a, b, c)| {
            let edge = PoseGraphEdge {
                a: index[a]?,
                b: index[b]?,
                a_from_b: *c.reference_from_target(),
                information: edge_information(&c),
            };
            Some(((a, b, c), edge))
        })
        .unzip();
    let start: Vec<Isometry3<f64>> = poses.iter().flatten().copied().collect();
    let refined = refine_pose_graph(&start, &graph, options.graph_iterations)?;
    let refined_of = |node: usize| index[node].and_then(|i| refined.get(i)).copied();
    let mut edges = Vec::with_capacity(measured.len());
    for ((a, b, c), g) in measured.into_iter().zip(&graph) {
        if let (Some(pa), Some(pb)) = (refined_of(a), refined_of(b)) {
            let err = edge_error(c.reference_from_target(), &pa, &pb);
            edges.push(RigEdge {
                a: names[a].to_string(),
                b: names[b].to_string(),
                method: c.method(),
                a_from_b: *c.reference_from_target(),
                information: g.information,
                rotation_residual_deg: err.fixed_rows::<3>(3).norm().to_degrees(),
                translation_residual_m: err.fixed_rows::<3>(0).norm(),
                result: c,
            });
        }
    }
    let transforms = (1..clouds.len())
        .filter_map(|i| refined_of(i).map(|p| (names[i].to_string(), p)))
        .collect();
    Ok(RigCalibration {
        transforms,
        direct,
        edges,
        failures,
        unconnected,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn pose(t: [f64; 3], axis: [f64; 3], angle: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_scaled_axis(Vector3::from(axis).normalize() * angle),
        )
    }

    #[test]
    fn method_names_round_trip() {
        for m in [
            Method::Auto,
            Method::Planes,
            Method::Targetless,
            Method::Poles,
        ] {
            assert_eq!(Method::from_name(m.name()), Ok(m));
        }
        assert!(matches!(
            Method::from_name("icp"),
            Err(Error::InvalidInput(m)) if m.contains("'targetless'")
        ));
    }

    #[test]
    fn consistent_graph_stays_put_and_a_cycle_error_is_shared_by_weight() {
        let a = pose([1.0, 0.5, 0.2], [0.0, 0.0, 1.0], 0.4);
        let b = pose([-1.0, 0.3, 0.1], [0.2, 1.0, 0.0], -0.3);
        let eye = Matrix6::identity();
        let edges = |ab: Isometry3<f64>, w_ab: f64| {
            vec![
                PoseGraphEdge {
                    a: 0,
                    b: 1,
                    a_from_b: a,
                    information: eye,
                },
                PoseGraphEdge {
                    a: 0,
                    b: 2,
                    a_from_b: b,
                    information: eye,
                },
                PoseGraphEdge {
                    a: 1,
                    b: 2,
                    a_from_b: ab,
                    information: eye * w_ab,
                },
            ]
        };
        let truth = a.inverse() * b;
        let start = [Isometry3::identity(), a, b];
        let out = refine_pose_graph(&start, &edges(truth, 1.0), 20).unwrap();
        for (x, y) in out.iter().zip(&start) {
            let (r, t) = crate::calib::targetless::pose_error(x, y);
            assert!(r < 1e-9 && t < 1e-9, "{r} {t}");
        }
        // A 3 cm error on the a-b edge: with equal weights it is shared, with a heavy weight
        // the graph follows that edge.
        let off = Isometry3::translation(0.03, 0.0, 0.0) * truth;
        let shared = refine_pose_graph(&start, &edges(off, 1.0), 20).unwrap();
        let residual = |p: &[Isometry3<f64>]| edge_error(&off, &p[1], &p[2]).norm();
        let heavy = refine_pose_graph(&start, &edges(off, 1e6), 20).unwrap();
        assert!(residual(&shared) > 0.005 && residual(&shared) < 0.025);
        assert!(residual(&heavy) < 1e-4, "{}", residual(&heavy));
        assert_eq!(shared[0], Isometry3::identity());
        // The cost went down from the start.
        assert!(graph_cost(&shared, &edges(off, 1.0)) < graph_cost(&start, &edges(off, 1.0)));
    }

    #[test]
    fn bad_graphs_are_errors() {
        let e = PoseGraphEdge {
            a: 0,
            b: 3,
            a_from_b: Isometry3::identity(),
            information: Matrix6::identity(),
        };
        let poses = [Isometry3::identity(); 2];
        assert!(matches!(
            refine_pose_graph(&poses, std::slice::from_ref(&e), 5),
            Err(Error::InvalidInput(_))
        ));
        let mut nan = e.clone();
        nan.b = 1;
        nan.information[(0, 0)] = f64::NAN;
        assert!(matches!(
            refine_pose_graph(&poses, &[nan], 5),
            Err(Error::InvalidInput(_))
        ));
        // Node 2 is in no edge.
        let mut one = e;
        one.b = 1;
        let three = [Isometry3::identity(); 3];
        assert!(matches!(
            refine_pose_graph(&three, &[one], 5),
            Err(Error::InvalidInput(m)) if m.contains("node 2")
        ));
    }
}
