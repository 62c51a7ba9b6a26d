//! The calibration of a whole rig: every target to the reference, every overlapping pair of
//! targets, and a small pose graph that makes the set consistent.
//!
//! [`calibrate_rig`] calibrates each pair with [`calibrate`] (any [`Method`], [`Method::Auto`] by
//! default), keeps a target pair as an edge when the units overlap under its result, places every
//! target by breadth-first search from the reference, and refines the placed poses with
//! [`refine_pose_graph`] (Gauss–Newton on the SE(3) tangent errors, see [`crate::pose_graph`]),
//! each edge weighted by [`edge_information`]. The [`RigCalibration`] carries the refined poses,
//! every edge with its residual against them, the pairs that gave no edge and why, and the pose
//! graph's [`PoseGraphReport`].
//!
//! ```no_run
//! use lidarcal::calib::rig::{calibrate_rig, RigOptions};
//! use lidarcal::calib::Cloud;
//! # let (top, left, right): (Vec<nalgebra::Point3<f64>>, Vec<_>, Vec<_>) = Default::default();
//!
//! let targets = [("left", Cloud::new(&left)), ("right", Cloud::new(&right))];
//! let rig = calibrate_rig(Cloud::new(&top), &targets, &RigOptions::default())?;
//! println!("top_from_left = {:?}", rig.transform("left"));
//! assert!(rig.pose_graph.converged);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use nalgebra::{Isometry3, Matrix6, Vector6};

use crate::calib::method::{calibrate, Cloud, Method, MethodOptions};
use crate::calib::result::Calibration;
use crate::icp::SurfaceCloud;
use crate::pose_graph::{
    edge_error, refine_pose_graph, PoseGraphEdge, PoseGraphOptions, PoseGraphReport,
};
use crate::{Error, FailureKind, Result};

/// A target pair becomes an edge of the rig only when its result brings at least this fraction of
/// the points of one onto the other (the units overlap).
pub const MIN_PAIR_OVERLAP: f64 = 0.2;

/// Largest disagreement (degrees) of an edge with the refined rig before [`calibrate_rig`] takes
/// the edges to contradict each other. Around a cycle of correct edges the pose graph leaves each
/// a few hundredths of a degree (the real road rig of `benches/targetless_accuracy.py` with its
/// three edges: 0.05-0.07 degrees, 0.6-1.1 cm); one wrong edge in a cycle of three left the rig
/// 37-47 degrees off when it was averaged in.
pub const MAX_EDGE_ROTATION_RESIDUAL_DEG: f64 = 1.0;
/// Largest disagreement (metres) of an edge with the refined rig; see
/// [`MAX_EDGE_ROTATION_RESIDUAL_DEG`].
pub const MAX_EDGE_TRANSLATION_RESIDUAL_M: f64 = 0.1;

/// Name of the reference sensor in a [`RigCalibration`]; no target may use it.
pub const REFERENCE: &str = "reference";

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
        .covariance
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
    /// How the pose graph is refined.
    pub pose_graph: PoseGraphOptions,
}

impl Default for RigOptions {
    fn default() -> Self {
        RigOptions {
            method: Method::Auto,
            methods: MethodOptions::default(),
            pairwise: true,
            require_all: true,
            min_pair_overlap: MIN_PAIR_OVERLAP,
            pose_graph: PoseGraphOptions::default(),
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
    /// How the pose-graph refinement of the placed targets went.
    pub pose_graph: PoseGraphReport,
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
/// is reached through it. Errors: `InvalidInput` for no targets, a target named [`REFERENCE`],
/// two targets of one name or bad [`RigOptions::pose_graph`]; `Calibration` naming every pair's
/// reason when some target cannot be placed and `require_all` is set (or when none can);
/// `Calibration` of kind [`FailureKind::InconsistentMethods`] when the kept edges contradict each
/// other: an edge disagrees with the refined rig by more than [`MAX_EDGE_ROTATION_RESIDUAL_DEG`]
/// or [`MAX_EDGE_TRANSLATION_RESIDUAL_M`]. A cycle that does not close has a wrong edge, and
/// which one the rig cannot tell: averaged in, it bends every pose of the cycle.
pub fn calibrate_rig(
    reference: Cloud<'_>,
    targets: &[(&str, Cloud<'_>)],
    options: &RigOptions,
) -> Result<RigCalibration> {
    validate_inputs(targets, options)?;
    // Node 0 is the reference, node i + 1 the target i.
    let names: Vec<&str> = std::iter::once(REFERENCE)
        .chain(targets.iter().map(|(n, _)| *n))
        .collect();
    let clouds: Vec<Cloud<'_>> = std::iter::once(reference)
        .chain(targets.iter().map(|(_, c)| *c))
        .collect();
    let mut pairs = Pairs::new(&names);
    pairs.calibrate_direct(&clouds, options)?;
    if options.pairwise {
        pairs.calibrate_target_pairs(&clouds, options)?;
    }
    let Pairs {
        measured,
        failures,
        direct,
        ..
    } = pairs;
    let poses = initial_poses(clouds.len(), &measured);
    let unconnected = check_connected(&names, &poses, &failures, options)?;
    let (edges, transforms, report) = refine(&names, &poses, measured, options)?;
    Ok(RigCalibration {
        transforms,
        direct,
        edges,
        failures,
        unconnected,
        pose_graph: report,
    })
}

/// The `InvalidInput` checks of [`calibrate_rig`], in its documented order.
fn validate_inputs(targets: &[(&str, Cloud<'_>)], options: &RigOptions) -> Result<()> {
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
    options.pose_graph.validate()
}

/// The pairwise calibrations of a rig: the results kept as edges (node indices, 0 the reference),
/// the pairs that gave none, and the direct results to the reference.
struct Pairs<'n> {
    names: &'n [&'n str],
    measured: Vec<(usize, usize, Calibration)>,
    failures: Vec<RigFailure>,
    direct: Vec<(String, Isometry3<f64>)>,
}

impl<'n> Pairs<'n> {
    fn new(names: &'n [&'n str]) -> Self {
        Pairs {
            names,
            measured: Vec::new(),
            failures: Vec::new(),
            direct: Vec::new(),
        }
    }

    fn fail(&mut self, a: usize, b: usize, kind: Option<FailureKind>, reason: String) {
        self.failures.push(RigFailure {
            a: self.names[a].to_string(),
            b: self.names[b].to_string(),
            reason,
            kind,
        })
    }

    /// Each target against the reference.
    fn calibrate_direct(&mut self, clouds: &[Cloud<'_>], options: &RigOptions) -> Result<()> {
        for b in 1..clouds.len() {
            match calibrate(clouds[0], clouds[b], options.method, &options.methods) {
                Ok(c) => {
                    self.direct
                        .push((self.names[b].to_string(), c.reference_from_target));
                    self.measured.push((0, b, c));
                }
                Err(Error::Calibration { kind, message }) => self.fail(0, b, Some(kind), message),
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Each pair of targets, kept when the result brings at least `min_pair_overlap` of one's
    /// points onto the other.
    fn calibrate_target_pairs(&mut self, clouds: &[Cloud<'_>], options: &RigOptions) -> Result<()> {
        for a in 1..clouds.len() {
            // Indexed once per target, on its first calibrated pair.
            let mut surface: Option<SurfaceCloud> = None;
            for b in a + 1..clouds.len() {
                let c = match calibrate(clouds[a], clouds[b], options.method, &options.methods) {
                    Ok(c) => c,
                    Err(Error::Calibration { kind, message }) => {
                        self.fail(a, b, Some(kind), message);
                        continue;
                    }
                    Err(e) => return Err(e),
                };
                let surface = match surface {
                    Some(ref s) => s,
                    None => surface.insert(SurfaceCloud::new(clouds[a].points().to_vec())?),
                };
                let shared = surface.overlap(
                    clouds[b].points(),
                    &c.reference_from_target,
                    options.methods.agreement_distance,
                );
                if shared < options.min_pair_overlap {
                    self.fail(
                        a,
                        b,
                        None,
                        "the two units barely overlap under the result".into(),
                    );
                    continue;
                }
                self.measured.push((a, b, c));
            }
        }
        Ok(())
    }
}

/// Initial poses: breadth-first from the reference (node 0) over the measured edges; `None` for
/// the nodes nothing reaches.
fn initial_poses(
    nodes: usize,
    measured: &[(usize, usize, Calibration)],
) -> Vec<Option<Isometry3<f64>>> {
    let mut poses: Vec<Option<Isometry3<f64>>> = vec![None; nodes];
    poses[0] = Some(Isometry3::identity());
    let mut changed = true;
    while changed {
        changed = false;
        for (a, b, c) in measured {
            match (poses[*a], poses[*b]) {
                (Some(pa), None) => {
                    poses[*b] = Some(pa * c.reference_from_target);
                    changed = true;
                }
                (None, Some(pb)) => {
                    poses[*a] = Some(pb * c.reference_from_target.inverse());
                    changed = true;
                }
                _ => {}
            }
        }
    }
    poses
}

/// The targets left unplaced; `Err` naming every pair's reason when some are and `require_all` is
/// set, or when none is placed.
fn check_connected(
    names: &[&str],
    poses: &[Option<Isometry3<f64>>],
    failures: &[RigFailure],
    options: &RigOptions,
) -> Result<Vec<String>> {
    let unconnected: Vec<String> = (1..poses.len())
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
    Ok(unconnected)
}

/// What [`refine`] gives: the edges with their residuals, `(name, reference_from_name)` of the
/// placed targets, and the pose graph's report.
type Refined = (Vec<RigEdge>, Vec<(String, Isometry3<f64>)>, PoseGraphReport);

/// The pose graph over the placed nodes, refined from `poses`, and every usable edge's residual
/// against the result.
fn refine(
    names: &[&str],
    poses: &[Option<Isometry3<f64>>],
    measured: Vec<(usize, usize, Calibration)>,
    options: &RigOptions,
) -> Result<Refined> {
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
                a_from_b: c.reference_from_target,
                information: edge_information(&c),
            };
            Some(((a, b, c), edge))
        })
        .unzip();
    let start: Vec<Isometry3<f64>> = poses.iter().flatten().copied().collect();
    let solution = refine_pose_graph(&start, &graph, &options.pose_graph)?;
    let refined = solution.poses;
    let refined_of = |node: usize| index[node].and_then(|i| refined.get(i)).copied();
    let mut edges = Vec::with_capacity(measured.len());
    for ((a, b, c), g) in measured.into_iter().zip(&graph) {
        if let (Some(pa), Some(pb)) = (refined_of(a), refined_of(b)) {
            let (rotation_residual_deg, translation_residual_m) =
                residual(&c.reference_from_target, &pa, &pb);
            edges.push(RigEdge {
                a: names[a].to_string(),
                b: names[b].to_string(),
                method: c.method(),
                a_from_b: c.reference_from_target,
                information: g.information,
                rotation_residual_deg,
                translation_residual_m,
                result: c,
            });
        }
    }
    let residuals = edges.iter().map(|e| {
        (
            e.a.as_str(),
            e.b.as_str(),
            e.rotation_residual_deg,
            e.translation_residual_m,
        )
    });
    if let Some(message) = contradiction(residuals) {
        return Err(Error::calibration(
            FailureKind::InconsistentMethods,
            message,
        ));
    }
    let transforms = (1..poses.len())
        .filter_map(|i| refined_of(i).map(|p| (names[i].to_string(), p)))
        .collect();
    Ok((edges, transforms, solution.report))
}

/// The disagreement of edge `a_from_b` with the rig's poses of `a` and `b`: rotation (degrees)
/// and translation (metres).
fn residual(
    a_from_b: &Isometry3<f64>,
    reference_from_a: &Isometry3<f64>,
    reference_from_b: &Isometry3<f64>,
) -> (f64, f64) {
    let err = edge_error(a_from_b, reference_from_a, reference_from_b);
    (
        err.fixed_rows::<3>(3).norm().to_degrees(),
        err.fixed_rows::<3>(0).norm(),
    )
}

/// Why the rig's edges contradict each other, from each edge's `(a, b, rotation residual in
/// degrees, translation residual in metres)` against the refined rig: `None` when every residual
/// is within [`MAX_EDGE_ROTATION_RESIDUAL_DEG`] and [`MAX_EDGE_TRANSLATION_RESIDUAL_M`].
fn contradiction<'e>(
    residuals: impl Iterator<Item = (&'e str, &'e str, f64, f64)>,
) -> Option<String> {
    let all: Vec<(&str, &str, f64, f64)> = residuals.collect();
    let beyond = |&&(_, _, r, t): &&(&str, &str, f64, f64)| {
        r > MAX_EDGE_ROTATION_RESIDUAL_DEG || t > MAX_EDGE_TRANSLATION_RESIDUAL_M
    };
    all.iter().find(beyond)?;
    let listed: Vec<String> = all
        .iter()
        .map(|(a, b, r, t)| format!("{a}-{b} {r:.2} deg / {:.1} cm", t * 100.0))
        .collect();
    Some(format!(
        "the pairwise calibrations contradict each other: around a cycle of the rig the edges \
         disagree with the best common poses by {} (tolerance {MAX_EDGE_ROTATION_RESIDUAL_DEG} \
         deg / {:.0} cm); at least one edge is wrong and the rig cannot tell which: check each \
         pair (`lidarcal check`), or calibrate without the target pairs (pairwise = false)",
        listed.join(", "),
        MAX_EDGE_TRANSLATION_RESIDUAL_M * 100.0
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose_graph::{refine_pose_graph, PoseGraphEdge, PoseGraphOptions};
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// The residuals the rig judges for three sensors whose target pair `1-2` is measured
    /// `turn_deg` degrees off about the vertical.
    fn cycle_residuals(turn_deg: f64) -> Vec<(String, String, f64, f64)> {
        let pose = |x: f64, y: f64, yaw_deg: f64| {
            Isometry3::from_parts(
                Translation3::new(x, y, 0.0),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians()),
            )
        };
        let truth = [
            pose(0.0, 0.0, 0.0),
            pose(0.0, 0.6, 90.0),
            pose(0.0, -0.6, -90.0),
        ];
        let off = pose(0.0, 0.0, turn_deg);
        let edge = |a: usize, b: usize, wrong: bool| {
            let measured = truth[a].inverse() * truth[b];
            PoseGraphEdge {
                a,
                b,
                a_from_b: if wrong { off * measured } else { measured },
                information: default_information(),
            }
        };
        let edges = [edge(0, 1, false), edge(0, 2, false), edge(1, 2, true)];
        let start = [truth[0], truth[1], truth[0] * edges[1].a_from_b];
        let solved = refine_pose_graph(&start, &edges, &PoseGraphOptions::default()).unwrap();
        edges
            .iter()
            .map(|e| {
                let (r, t) = residual(&e.a_from_b, &solved.poses[e.a], &solved.poses[e.b]);
                (e.a.to_string(), e.b.to_string(), r, t)
            })
            .collect()
    }

    fn judged(residuals: &[(String, String, f64, f64)]) -> Option<String> {
        contradiction(
            residuals
                .iter()
                .map(|(a, b, r, t)| (a.as_str(), b.as_str(), *r, *t)),
        )
    }

    #[test]
    fn a_cycle_that_closes_is_kept_and_one_that_does_not_is_refused() {
        // Edges off by a tenth of a degree between them close well within the tolerance.
        let closes = cycle_residuals(0.1);
        assert!(judged(&closes).is_none(), "{closes:?}");
        // One target pair measured 40 degrees off: the graph spreads it around the cycle, every
        // edge far beyond the tolerance, and the rig says so.
        let open = cycle_residuals(40.0);
        let message = judged(&open).expect("a cycle 40 degrees open");
        assert!(open.iter().all(|(_, _, r, _)| *r > 5.0), "{open:?}");
        assert!(
            message.contains("contradict each other") && message.contains("1-2"),
            "{message}"
        );
    }
}
