//! Python wrappers of the calibration methods and their result object.

use nalgebra::{Isometry3, Vector3};
use numpy::ndarray::{Ix1, Ix2};
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::arrays::{self, row_major, to_numpy};
use super::run;
use crate::calib::method::{self, Calibration, Cloud, Method, MethodOptions};
use crate::calib::planes::{
    calibrate_planes as rs_calibrate_planes, PlanarCalibration, PlanarOptions,
};
use crate::calib::poles::{
    calibrate_poles as rs_calibrate_poles, AxisFit, PoleCalibration, PoleOptions, Vendor,
};
use crate::calib::rig::{self, RigOptions};
use crate::calib::targetless::{
    calibrate_targetless as rs_calibrate_targetless, TargetlessCalibration, TargetlessOptions,
};
use crate::calib::Timings;
use crate::geometry::Plane;
use crate::lm::{LmOptions, LmReport, Loss};
use crate::pose_graph::{
    refine_pose_graph as rs_refine_pose_graph, PoseGraphEdge, PoseGraphOptions,
};

/// What a calibration method returned (the crate's own sum of the three results).
type Inner = Calibration;

/// The result of a calibration: `transform` maps target points into the reference frame.
#[pyclass(frozen, module = "lidarcal", name = "CalibrationResult")]
pub(crate) struct CalibrationResult {
    inner: Inner,
}

impl CalibrationResult {
    fn planes(&self) -> Option<&PlanarCalibration> {
        match &self.inner {
            Inner::Planes(p) => Some(p),
            _ => None,
        }
    }
    fn poles(&self) -> Option<&PoleCalibration> {
        match &self.inner {
            Inner::Poles(p) => Some(p),
            _ => None,
        }
    }
    fn targetless(&self) -> Option<&TargetlessCalibration> {
        match &self.inner {
            Inner::Targetless(p) => Some(p),
            _ => None,
        }
    }
    fn pose(&self) -> &Isometry3<f64> {
        match &self.inner {
            Inner::Planes(p) => &p.reference_from_target,
            Inner::Poles(p) => &p.reference_from_target,
            Inner::Targetless(p) => &p.reference_from_target,
        }
    }
    fn initial_pose(&self) -> &Isometry3<f64> {
        match &self.inner {
            Inner::Planes(p) => &p.initial_reference_from_target,
            Inner::Poles(p) => &p.initial_reference_from_target,
            Inner::Targetless(p) => &p.initial_reference_from_target,
        }
    }
    fn report(&self) -> Option<&LmReport> {
        match &self.inner {
            Inner::Planes(p) => p.report.as_ref(),
            Inner::Poles(p) => p.report.as_ref(),
            Inner::Targetless(p) => p.report.as_ref(),
        }
    }
    fn stage_timings(&self) -> &Timings {
        match &self.inner {
            Inner::Planes(p) => &p.timings,
            Inner::Poles(p) => &p.timings,
            Inner::Targetless(p) => &p.timings,
        }
    }
    fn rmse_values(&self) -> Vec<f64> {
        match &self.inner {
            Inner::Planes(p) => p.rmse.to_vec(),
            Inner::Poles(p) => p.pole_rmse.clone(),
            Inner::Targetless(p) => p.rmse.clone(),
        }
    }
}

fn lines_k6<'py>(
    py: Python<'py>,
    lines: &[crate::geometry::Line],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let data = lines
        .iter()
        .flat_map(|l| {
            [
                l.point.x,
                l.point.y,
                l.point.z,
                l.direction.x,
                l.direction.y,
                l.direction.z,
            ]
        })
        .collect();
    to_numpy(py, Ix2(lines.len(), 6), data)
}

/// (K, 4) rows [nx, ny, nz, d].
fn planes_array<'py>(py: Python<'py>, planes: &[Plane]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let data = planes
        .iter()
        .flat_map(|p| p.coefficients().as_slice().to_vec())
        .collect();
    to_numpy(py, Ix2(planes.len(), 4), data)
}

/// A pose as a (4, 4) row-major array.
pub(crate) fn matrix4<'py>(
    py: Python<'py>,
    pose: &Isometry3<f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    to_numpy(py, Ix2(4, 4), row_major(&pose.to_homogeneous()))
}

#[pymethods]
impl CalibrationResult {
    /// "planes", "poles" or "targetless".
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method().name()
    }
    /// The final check's report (a CheckReport; always "consistent" for a returned result).
    #[getter]
    fn check(&self) -> super::check::CheckReport {
        super::check::CheckReport {
            inner: self.inner.check().clone(),
        }
    }
    /// (4, 4) reference_from_target: p_ref = R @ p_tgt + t.
    #[getter]
    fn transform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix4(py, self.pose())
    }
    /// (4, 4) the closed-form estimate before the Levenberg–Marquardt refinement.
    #[getter]
    fn initial_transform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix4(py, self.initial_pose())
    }
    /// True when the refinement converged (or was not requested).
    #[getter]
    fn converged(&self) -> bool {
        self.report().is_none_or(|r| r.converged())
    }
    /// LM iterations (0 without refinement).
    #[getter]
    fn iterations(&self) -> usize {
        self.report().map_or(0, |r| r.iterations)
    }
    /// Final cost 1/2 sum r^2 of the refinement (NaN without refinement).
    #[getter]
    fn cost(&self) -> f64 {
        self.report().map_or(f64::NAN, |r| r.final_cost)
    }
    /// Why the refinement stopped ("none" without refinement).
    #[getter]
    fn termination(&self) -> &'static str {
        self.report().map_or("none", |r| r.termination.as_str())
    }
    /// RMS residual (metres) per matched feature: (3,) point-to-plane per plane, or (K,)
    /// point-to-axis per pole; both clouds together.
    #[getter]
    fn rmse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let v = self.rmse_values();
        to_numpy(py, Ix1(v.len()), v)
    }
    /// (3, 4) (corner) or (K, 4) (targetless) matched planes [nx, ny, nz, d] in the reference
    /// frame (normals toward the sensor); None for poles.
    #[getter]
    fn planes_reference<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        match &self.inner {
            Inner::Planes(p) => planes_array(py, &p.planes_reference).map(Some),
            Inner::Targetless(p) => planes_array(py, &p.planes_reference).map(Some),
            Inner::Poles(_) => Ok(None),
        }
    }
    /// Matched planes in the target frame, row i matching planes_reference[i]; None for poles.
    #[getter]
    fn planes_target<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        match &self.inner {
            Inner::Planes(p) => planes_array(py, &p.planes_target).map(Some),
            Inner::Targetless(p) => planes_array(py, &p.planes_target).map(Some),
            Inner::Poles(_) => Ok(None),
        }
    }
    /// Number of matched planes (targetless only, else None).
    #[getter]
    fn matched_planes(&self) -> Option<usize> {
        self.targetless().map(|t| t.planes_reference.len())
    }
    /// (2,) planes extracted from the reference and the target cloud (targetless only).
    #[getter]
    fn plane_counts(&self) -> Option<(usize, usize)> {
        self.targetless()
            .map(|t| (t.features[0].len(), t.features[1].len()))
    }
    /// (enumerated, distinct) plane-pair/triplet hypotheses (targetless only).
    #[getter]
    fn hypothesis_counts(&self) -> Option<(usize, usize)> {
        self.targetless()
            .map(|t| (t.hypotheses[0], t.hypotheses[1]))
    }
    /// Verification score of the best hypothesis: agreement minus 3 x the free-space violations
    /// (targetless only).
    #[getter]
    fn best_score(&self) -> Option<f64> {
        self.targetless().map(|t| t.best_score)
    }
    /// Best verification score of a hypothesis ending at a different pose (targetless only).
    #[getter]
    fn second_score(&self) -> Option<f64> {
        self.targetless().map(|t| t.second_score)
    }
    /// Share of the checked target points within 25 cm of a reference point at the best
    /// hypothesis (targetless only).
    #[getter]
    fn agreement(&self) -> Option<f64> {
        self.targetless().map(|t| t.agreement)
    }
    /// (target points in the reference's free space, reference points in the target's) as shares
    /// of the checked points, at the best hypothesis (targetless only).
    #[getter]
    fn violations(&self) -> Option<(f64, f64)> {
        self.targetless()
            .map(|t| (t.violations[0], t.violations[1]))
    }
    /// Whether the winning hypothesis came from the ground sweep (targetless only).
    #[getter]
    fn sweep(&self) -> Option<bool> {
        self.targetless().map(|t| t.sweep)
    }
    /// Whether the winning hypothesis was a plane triplet rather than a pair (targetless only).
    #[getter]
    fn triplet(&self) -> Option<bool> {
        self.targetless().map(|t| t.triplet)
    }
    /// ((3,) direction in the reference frame, share of the information) of the least
    /// constrained translation (targetless only).
    #[getter]
    fn weakest_translation<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<(Bound<'py, PyArray1<f64>>, f64)>> {
        self.targetless()
            .map(|t| {
                let (v, share) = t.weakest_translation;
                Ok((to_numpy(py, Ix1(3), v.as_slice().to_vec())?, share))
            })
            .transpose()
    }
    /// Fraction of the sampled target points with an ICP correspondence at the final distance
    /// (targetless with ICP only).
    #[getter]
    fn icp_fitness(&self) -> Option<f64> {
        self.targetless().and_then(|t| t.icp.map(|r| r.fitness))
    }
    /// (2, K) points per matched feature: row 0 reference, row 1 target (K = 3 planes or the
    /// matched poles).
    #[getter]
    fn inlier_counts<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        let (a, b) = self.index_sets();
        let k = a.len();
        let counts: Vec<i64> = a.iter().chain(b).map(|v| v.len() as i64).collect();
        numpy::ndarray::Array2::from_shape_vec((2, k), counts)
            .map(|a| numpy::IntoPyArray::into_pyarray(a, py))
            .unwrap_or_else(|_| PyArray2::zeros(py, (2, k), false))
    }
    /// int64 arrays: indices of each matched plane's (or pole's) points in the reference cloud.
    #[getter]
    fn inliers_reference<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<i64>>> {
        self.index_sets()
            .0
            .iter()
            .map(|v| PyArray1::from_iter(py, v.iter().map(|&i| i as i64)))
            .collect()
    }
    /// int64 arrays: indices of each matched plane's (or pole's) points in the target cloud.
    #[getter]
    fn inliers_target<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<i64>>> {
        self.index_sets()
            .1
            .iter()
            .map(|v| PyArray1::from_iter(py, v.iter().map(|&i| i as i64)))
            .collect()
    }
    /// (3,) RMS normal misalignment (rad) of each cyclic plane correspondence; lower is better.
    /// None for poles (see hypothesis_scores).
    #[getter]
    fn ordering_scores<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        self.planes()
            .map(|p| to_numpy(py, Ix1(3), p.ordering.scores.to_vec()))
            .transpose()
    }
    /// Runner-up score minus the chosen one (rad): how clearly the planes were matched; None for
    /// poles.
    #[getter]
    fn ordering_margin(&self) -> Option<f64> {
        self.planes().map(|p| p.ordering.margin)
    }
    /// True when the geometry was ambiguous and the `up` tie-break chose the correspondence;
    /// None for poles.
    #[getter]
    fn used_up(&self) -> Option<bool> {
        self.planes().map(|p| p.ordering.used_up)
    }
    /// (2, 3) the corner point in the reference and in the target frame; None for poles.
    #[getter]
    fn corners<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.planes()
            .map(|p| {
                let [a, b] = p.corners;
                to_numpy(py, Ix2(2, 3), vec![a.x, a.y, a.z, b.x, b.y, b.z])
            })
            .transpose()
    }
    /// (2,) inlier thresholds used for the reference and the target cloud (metres); None for poles.
    #[getter]
    fn distance_thresholds<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        let t = match &self.inner {
            Inner::Planes(p) => p.distance_thresholds,
            Inner::Targetless(p) => p.distance_thresholds,
            Inner::Poles(_) => return Ok(None),
        };
        to_numpy(py, Ix1(2), t.to_vec()).map(Some)
    }
    /// (K, 6) matched pole axes [point, unit direction] in the reference frame; None for planes.
    #[getter]
    fn poles_reference<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.poles()
            .map(|p| lines_k6(py, &p.poles_reference))
            .transpose()
    }
    /// (K, 6) matched pole axes in the target frame, directions signed to match
    /// poles_reference; None for planes.
    #[getter]
    fn poles_target<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.poles()
            .map(|p| lines_k6(py, &p.poles_target))
            .transpose()
    }
    /// (K,) radius of each matched pole (metres; given, or the mean of both clouds' estimates;
    /// 0 with axis_fit="line"); None for planes.
    #[getter]
    fn pole_radii<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        self.poles()
            .map(|p| to_numpy(py, Ix1(p.radii.len()), p.radii.clone()))
            .transpose()
    }
    /// (2,) intensity thresholds used for the reference and the target cloud; None for planes.
    #[getter]
    fn intensity_thresholds<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        self.poles()
            .map(|p| {
                let v = p
                    .extractions
                    .iter()
                    .map(|e| e.intensity_threshold)
                    .collect();
                to_numpy(py, Ix1(2), v)
            })
            .transpose()
    }
    /// (H,) score of every correspondence/sign hypothesis (lower is better), in enumeration
    /// order; None for planes.
    #[getter]
    fn hypothesis_scores<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        self.poles()
            .map(|p| {
                let v: Vec<f64> = p.hypotheses.iter().map(|h| h.score).collect();
                to_numpy(py, Ix1(v.len()), v)
            })
            .transpose()
    }
    /// Every hypothesis as a dict: matches [(reference pole, target pole, sign)], axis_rms (m),
    /// ground_angle_deg, ground_offset (m) (None without a plane), overlap, score,
    /// rotation_to_chosen_deg; None for planes.
    #[getter]
    fn hypotheses<'py>(&self, py: Python<'py>) -> PyResult<Option<Vec<Bound<'py, PyDict>>>> {
        let Some(p) = self.poles() else {
            return Ok(None);
        };
        let chosen = p.reference_from_target;
        let mut out = Vec::with_capacity(p.hypotheses.len());
        for h in &p.hypotheses {
            let d = PyDict::new(py);
            let matches: Vec<(usize, usize, i8)> = h.matches.clone();
            d.set_item("matches", matches)?;
            d.set_item("axis_rms", h.axis_rms)?;
            d.set_item("ground_angle_deg", h.ground_angle.map(f64::to_degrees))?;
            d.set_item("ground_offset", h.ground_offset)?;
            d.set_item("overlap", h.overlap)?;
            d.set_item("score", h.score)?;
            let rel = h.reference_from_target.inverse() * chosen;
            d.set_item("rotation_to_chosen_deg", rel.rotation.angle().to_degrees())?;
            out.push(d);
        }
        Ok(Some(out))
    }
    /// Index of the chosen hypothesis; None for planes.
    #[getter]
    fn chosen_hypothesis(&self) -> Option<usize> {
        self.poles().map(|p| p.chosen)
    }
    /// Score of the best hypothesis reaching a different transform minus the chosen one's
    /// (inf when all agree); None for planes.
    #[getter]
    fn hypothesis_margin(&self) -> Option<f64> {
        self.poles().map(|p| p.margin)
    }
    /// Poles: True when the margin is below 1 (a near-tie, though not refused). Targetless: True
    /// when a distinct pose verified almost as well as the best (only returned with
    /// refuse_ambiguous=False). None for the corner method.
    #[getter]
    fn ambiguous(&self) -> Option<bool> {
        match &self.inner {
            Inner::Poles(p) => Some(p.ambiguous),
            Inner::Targetless(t) => Some(t.ambiguous),
            Inner::Planes(_) => None,
        }
    }
    /// (6, 6) covariance of the left-perturbation tangent [rho, phi] (m, rad), or None.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        let c = match &self.inner {
            Inner::Planes(p) => p.covariance,
            Inner::Poles(p) => p.covariance,
            Inner::Targetless(p) => p.covariance,
        };
        c.map(|c| to_numpy(py, Ix2(6, 6), row_major(&c)))
            .transpose()
    }
    /// Milliseconds per stage, plus "total".
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let t = self.stage_timings();
        for (name, ms) in &t.stages {
            d.set_item(*name, *ms)?;
        }
        d.set_item("total", t.total())?;
        Ok(d)
    }
    fn __repr__(&self) -> String {
        let pose = self.pose();
        let t = pose.translation.vector;
        let rpy = pose.rotation.euler_angles();
        let rmse: Vec<String> = self
            .rmse_values()
            .iter()
            .map(|r| format!("{r:.4}"))
            .collect();
        let extra = match &self.inner {
            Inner::Planes(_) => String::new(),
            Inner::Targetless(t) => format!(
                ", matched_planes={}, best_score={:.3}, second_score={:.3}, ambiguous={}",
                t.planes_reference.len(),
                t.best_score,
                t.second_score,
                if t.ambiguous { "True" } else { "False" }
            ),
            Inner::Poles(p) => format!(
                ", poles={}, hypothesis_margin={:.2}, ambiguous={}",
                p.poles_reference.len(),
                p.margin,
                if p.ambiguous { "True" } else { "False" }
            ),
        };
        format!(
            "CalibrationResult(method='{}', converged={}, rotation_rpy_deg=[{:.3}, {:.3}, {:.3}], \
             translation_m=[{:.4}, {:.4}, {:.4}], rmse_m=[{}]{extra}, iterations={}, \
             total_ms={:.2})",
            self.method(),
            if self.converged() { "True" } else { "False" },
            rpy.0.to_degrees(),
            rpy.1.to_degrees(),
            rpy.2.to_degrees(),
            t.x,
            t.y,
            t.z,
            rmse.join(", "),
            self.iterations(),
            self.stage_timings().total()
        )
    }
}

impl CalibrationResult {
    fn index_sets(&self) -> (&[Vec<usize>], &[Vec<usize>]) {
        match &self.inner {
            Inner::Planes(p) => (&p.inliers_reference, &p.inliers_target),
            Inner::Poles(p) => (&p.indices_reference, &p.indices_target),
            Inner::Targetless(p) => (&p.inliers_reference, &p.inliers_target),
        }
    }
}

fn up_arg(up: Option<&Bound<'_, PyAny>>) -> PyResult<Option<(Vector3<f64>, Vector3<f64>)>> {
    let Some(up) = up else {
        return Ok(None);
    };
    let d = arrays::dense(up, "up")?;
    let pair = match d.shape.as_slice() {
        [3] => (
            Vector3::from_column_slice(&d.data),
            Vector3::from_column_slice(&d.data),
        ),
        [2, 3] => (
            Vector3::from_column_slice(&d.data[..3]),
            Vector3::from_column_slice(&d.data[3..]),
        ),
        _ => {
            return Err(PyValueError::new_err(format!(
                "up must be a (3,) vector (same in both frames) or a (2, 3) array \
                 [up_reference, up_target], got shape {:?}",
                d.shape
            )))
        }
    };
    for v in [pair.0, pair.1] {
        if !(v.iter().all(|x| x.is_finite()) && v.norm() > 0.0) {
            return Err(PyValueError::new_err(
                "up vectors must be finite and non-zero",
            ));
        }
    }
    Ok(Some(pair))
}

/// Calibrates reference_from_target from a wall corner (three planes) seen by both sensors.
///
/// reference, target: (N, 3) or (N, 4) clouds in their sensors' frames (float32 or float64).
/// distance_threshold: plane inlier distance in metres; None estimates 3 sigma of each cloud's noise.
/// up: gravity direction, (3,) for both frames or (2, 3) [reference, target]; used only to break
///     a tie between plane correspondences (e.g. a cube corner).
/// refine: run the Levenberg–Marquardt refinement. loss: "auto" (Cauchy at the estimated noise
///     level, 1/3 of the threshold), "squared" (fastest: exact per-plane statistics), "huber" or
///     "cauchy" with loss_scale in metres.
/// time_budget_s: wall-clock limit in seconds; past it CalibrationError ("time budget ...
///     exhausted during <stage>") instead of running on. None: no limit.
/// Raises CalibrationError with the reason when no trustworthy result exists.
#[pyfunction]
#[pyo3(signature = (reference, target, *, distance_threshold=None, seed=0, up=None, refine=true, loss="auto", loss_scale=None, min_inliers=50, max_iterations=100, time_budget_s=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_planes(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    distance_threshold: Option<f64>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    up: Option<&Bound<'_, PyAny>>,
    refine: bool,
    loss: &str,
    loss_scale: Option<f64>,
    min_inliers: usize,
    max_iterations: usize,
    time_budget_s: Option<f64>,
) -> PyResult<CalibrationResult> {
    let time_budget = crate::budget::budget_from_secs(time_budget_s)?;
    let reference = arrays::points(reference, "reference")?;
    let target = arrays::points(target, "target")?;
    let needs_scale = |name: &str| {
        loss_scale.ok_or_else(|| {
            PyValueError::new_err(format!("loss={name:?} needs loss_scale (metres)"))
        })
    };
    let loss = match loss {
        "auto" => None,
        "squared" | "linear" => Some(Loss::Squared),
        "huber" => Some(Loss::Huber {
            delta: needs_scale("huber")?,
        }),
        "cauchy" => Some(Loss::Cauchy {
            scale: needs_scale("cauchy")?,
        }),
        other => {
            return Err(PyValueError::new_err(format!(
                "loss must be 'auto', 'squared', 'huber' or 'cauchy', got {other:?}"
            )))
        }
    };
    let options = PlanarOptions {
        distance_threshold,
        seed,
        up: up_arg(up)?,
        refine,
        loss,
        min_inliers,
        min_plane_width: crate::calib::planes::MIN_PLANE_WIDTH,
        lm: LmOptions {
            max_iterations,
            ..PlanarOptions::default().lm
        },
        time_budget,
        check: crate::check::CheckOptions::fitted(),
    };
    let inner = run(py, move || {
        rs_calibrate_planes(&reference, &target, &options)
    })?;
    Ok(CalibrationResult {
        inner: Inner::Planes(Box::new(inner)),
    })
}

/// Calibrates reference_from_target from two (or more) non-parallel taped poles.
///
/// reference, target: (N, 4) clouds [x, y, z, intensity] in their sensors' frames.
/// intensity_threshold: returns at or above it are tape; wins over vendor.
/// vendor: "velodyne" (230), "hesai", "leishen" or "robosense" (200); with neither, the threshold
///     is the middle of the highest wide intensity gap above the median (tape is the brightest).
/// pole_radius: metres, or None to estimate it per pole. axis_fit: "cylinder" (default) or "line"
///     (the centroid line of Xue et al., biased by up to a radius; for comparison).
/// Raises ValueError for malformed input and CalibrationError with the reason (no bright points,
/// fewer than two poles, parallel poles, indistinguishable hypotheses). time_budget_s: as for
/// calibrate_planes (a huge cluster_tolerance on a dense cloud makes the clustering quadratic).
/// max_bright_fraction: refuse when more of a cloud's returns than this share are at or above the
///     threshold (tape is a small part of a scene; a threshold of 0 makes everything "tape");
///     raise it to 1.0 for a cloud cropped to the poles.
#[pyfunction]
#[pyo3(signature = (reference, target, *, intensity_threshold=None, vendor=None, pole_radius=None, seed=0, axis_fit="cylinder", cluster_tolerance=0.5, min_points=15, max_iterations=100, time_budget_s=None, max_bright_fraction=0.25))]
#[allow(clippy::too_many_arguments)]
fn calibrate_poles(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    pole_radius: Option<f64>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    axis_fit: &str,
    cluster_tolerance: f64,
    min_points: usize,
    max_iterations: usize,
    time_budget_s: Option<f64>,
    max_bright_fraction: f64,
) -> PyResult<CalibrationResult> {
    let time_budget = crate::budget::budget_from_secs(time_budget_s)?;
    let (reference, ref_intensity) = arrays::points_with_intensity(reference, "reference")?;
    let (target, tgt_intensity) = arrays::points_with_intensity(target, "target")?;
    let vendor = vendor.map(Vendor::from_name).transpose()?;
    let axis_fit = match axis_fit {
        "cylinder" => AxisFit::Cylinder,
        "line" => AxisFit::Line,
        other => {
            return Err(PyValueError::new_err(format!(
                "axis_fit must be 'cylinder' or 'line', got {other:?}"
            )))
        }
    };
    let defaults = PoleOptions::default();
    let options = PoleOptions {
        intensity_threshold,
        vendor,
        pole_radius,
        seed,
        axis_fit,
        cluster_tolerance,
        min_points,
        lm: LmOptions {
            max_iterations,
            ..defaults.lm
        },
        time_budget,
        max_bright_fraction,
        ..defaults
    };
    let inner = run(py, move || {
        rs_calibrate_poles(
            &reference,
            &ref_intensity,
            &target,
            &tgt_intensity,
            &options,
        )
    })?;
    Ok(CalibrationResult {
        inner: Inner::Poles(Box::new(inner)),
    })
}

/// Calibrates reference_from_target from the planes of an ordinary scene (a street), without an
/// initial guess: plane pairs and triplets matched by their angles, verified by ICP, refined on
/// every matched plane and by point-to-plane ICP on the whole clouds.
///
/// reference, target: (N, 3) or (N, 4) clouds in their sensors' frames.
/// distance_threshold: plane inlier distance (m); None estimates it per cloud.
/// voxel_size: downsampling voxel (m). max_planes: planes per cloud. max_translation: the largest
///     distance between the sensors (m); no pose beyond it is returned. challenger_range: poses up
///     to this multiple of max_translation are verified too, and when one fits as well as or
///     better than the best within range the calibration is refused (ambiguous / out_of_range)
///     rather than answered with the best pose within range; 1.0 trusts the bound. icp: run the final
///     ICP. min_information_share: the weakest direction's share of the information below which
///     the calibration is refused as unobservable. ground_sweep: also hypothesise from the
///     largest plane of each cloud turned about its normal (no common plane pair needed).
///     refuse_ambiguous: raise when a distinct pose verifies almost as well as the best (else
///     return it with ambiguous=True).
/// Raises CalibrationError naming why (too few planes, nothing verifies, an unconstrained
/// direction such as the axis of a corridor).
#[pyfunction]
#[pyo3(signature = (reference, target, *, distance_threshold=None, voxel_size=0.1, max_planes=10, max_translation=5.0, challenger_range=2.0, icp=true, min_information_share=0.01, ground_sweep=true, refuse_ambiguous=true, seed=0))]
#[allow(clippy::too_many_arguments)]
fn calibrate_targetless(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    distance_threshold: Option<f64>,
    voxel_size: f64,
    max_planes: usize,
    max_translation: f64,
    challenger_range: f64,
    icp: bool,
    min_information_share: f64,
    ground_sweep: bool,
    refuse_ambiguous: bool,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<CalibrationResult> {
    let reference = arrays::points(reference, "reference")?;
    let target = arrays::points(target, "target")?;
    let options = TargetlessOptions {
        challenger_range,
        ground_sweep,
        refuse_ambiguous,
        distance_threshold,
        voxel_size,
        max_planes,
        max_translation,
        icp,
        min_information_share,
        seed,
        ..TargetlessOptions::default()
    };
    let inner = run(py, move || {
        rs_calibrate_targetless(&reference, &target, &options)
    })?;
    Ok(CalibrationResult {
        inner: Inner::Targetless(Box::new(inner)),
    })
}

/// The options `calibrate(method="auto")` and `calibrate_rig` pass on: `seed` to every method,
/// `up` to the corner method, `distance_threshold` to the corner and targetless methods,
/// `intensity_threshold`, `vendor` and `max_bright_fraction` to the poles.
fn method_options(
    seed: u64,
    up: Option<&Bound<'_, PyAny>>,
    distance_threshold: Option<f64>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    max_bright_fraction: Option<f64>,
) -> PyResult<MethodOptions> {
    let mut o = MethodOptions::with_seed(seed);
    if let Some(f) = max_bright_fraction {
        o.poles.max_bright_fraction = f;
    }
    o.planes.up = up_arg(up)?;
    o.planes.distance_threshold = distance_threshold;
    o.targetless.distance_threshold = distance_threshold;
    o.poles.intensity_threshold = intensity_threshold;
    o.poles.vendor = vendor.map(Vendor::from_name).transpose()?;
    Ok(o)
}

/// Points and, for an (N, 4) array, intensities.
type OwnedCloud = (Vec<nalgebra::Point3<f64>>, Option<Vec<f64>>);

fn owned_cloud(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<OwnedCloud> {
    let d = arrays::dense(obj, name)?;
    if d.shape.len() == 2 && d.shape[1] == 4 {
        let (p, i) = arrays::points_with_intensity(obj, name)?;
        Ok((p, Some(i)))
    } else {
        Ok((arrays::points(obj, name)?, None))
    }
}

fn borrow_cloud(c: &OwnedCloud) -> crate::Result<Cloud<'_>> {
    match &c.1 {
        Some(i) => Cloud::with_intensity(&c.0, i),
        None => Ok(Cloud::new(&c.0)),
    }
}

/// calibrate(method="auto") in Rust: the corner method, the targetless method and, when both
/// clouds are (N, 4), the poles; each result certified by check, the best certificate kept
/// (within 0.01 of the best, the earlier method wins). Raises CalibrationError (with kind) listing
/// each method's reason when none succeeds, or of kind "inconsistent_methods" when two certified
/// results disagree.
#[pyfunction]
#[pyo3(signature = (reference, target, *, seed=0, up=None, distance_threshold=None, intensity_threshold=None, vendor=None, max_bright_fraction=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_auto(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    up: Option<&Bound<'_, PyAny>>,
    distance_threshold: Option<f64>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    max_bright_fraction: Option<f64>,
) -> PyResult<CalibrationResult> {
    let options = method_options(
        seed,
        up,
        distance_threshold,
        intensity_threshold,
        vendor,
        max_bright_fraction,
    )?;
    let reference = owned_cloud(reference, "reference")?;
    let target = owned_cloud(target, "target")?;
    let inner = run(py, move || {
        method::calibrate(
            borrow_cloud(&reference)?,
            borrow_cloud(&target)?,
            Method::Auto,
            &options,
        )
    })?;
    Ok(CalibrationResult { inner })
}

/// The rig calibration in Rust (lidarcal.calibrate_rig wraps it). targets: a list of
/// (name, cloud); the method options as for calibrate_auto. Returns a dict: "transforms" and
/// "direct" ({name: (4, 4)}), "edges" (a list of (a, b, method, a_from_b,
/// rotation_residual_deg, translation_residual_m, CalibrationResult)), "failures"
/// ({(a, b): reason}), "unconnected" (names) and "pose_graph" (the refinement's report: a dict of
/// converged, termination, iterations, initial_cost, final_cost).
#[pyfunction]
#[pyo3(signature = (reference, targets, *, method="auto", pairwise=true, require_all=true, seed=0, up=None, distance_threshold=None, intensity_threshold=None, vendor=None, max_bright_fraction=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_rig<'py>(
    py: Python<'py>,
    reference: &Bound<'py, PyAny>,
    targets: Vec<(String, Bound<'py, PyAny>)>,
    method: &str,
    pairwise: bool,
    require_all: bool,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    up: Option<&Bound<'py, PyAny>>,
    distance_threshold: Option<f64>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    max_bright_fraction: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let method = Method::from_name(method)?;
    let methods = method_options(
        seed,
        up,
        distance_threshold,
        intensity_threshold,
        vendor,
        max_bright_fraction,
    )?;
    let reference = owned_cloud(reference, "reference")?;
    let clouds = targets
        .iter()
        .map(|(name, obj)| Ok((name.clone(), owned_cloud(obj, name)?)))
        .collect::<PyResult<Vec<_>>>()?;
    let options = RigOptions {
        method,
        methods,
        pairwise,
        require_all,
        ..RigOptions::default()
    };
    let out = run(py, move || {
        let borrowed = clouds
            .iter()
            .map(|(n, c)| Ok((n.as_str(), borrow_cloud(c)?)))
            .collect::<crate::Result<Vec<_>>>()?;
        rig::calibrate_rig(borrow_cloud(&reference)?, &borrowed, &options)
    })?;
    let d = PyDict::new(py);
    let poses = |list: &[(String, Isometry3<f64>)]| -> PyResult<Bound<'py, PyDict>> {
        let m = PyDict::new(py);
        for (name, pose) in list {
            m.set_item(name, matrix4(py, pose)?)?;
        }
        Ok(m)
    };
    d.set_item("transforms", poses(&out.transforms)?)?;
    d.set_item("direct", poses(&out.direct)?)?;
    let edges = out
        .edges
        .into_iter()
        .map(|e| {
            Ok((
                e.a,
                e.b,
                e.method.name(),
                matrix4(py, &e.a_from_b)?,
                e.rotation_residual_deg,
                e.translation_residual_m,
                Bound::new(py, CalibrationResult { inner: e.result })?,
            ))
        })
        .collect::<PyResult<Vec<_>>>()?;
    d.set_item("edges", edges)?;
    let failures = PyDict::new(py);
    let failure_kinds = PyDict::new(py);
    for f in &out.failures {
        failures.set_item((f.a.clone(), f.b.clone()), f.reason.clone())?;
        failure_kinds.set_item((f.a.clone(), f.b.clone()), f.kind.map(|k| k.name()))?;
    }
    d.set_item("failures", failures)?;
    d.set_item("failure_kinds", failure_kinds)?;
    d.set_item("unconnected", out.unconnected)?;
    let report = out.pose_graph;
    let graph = PyDict::new(py);
    graph.set_item("converged", report.converged)?;
    graph.set_item("termination", report.termination.as_str())?;
    graph.set_item("iterations", report.iterations)?;
    graph.set_item("initial_cost", report.initial_cost)?;
    graph.set_item("final_cost", report.final_cost)?;
    d.set_item("pose_graph", graph)?;
    Ok(d)
}

/// Refines a pose graph whose node 0 is fixed (see lidarcal.refine_pose_graph).
#[pyfunction]
#[pyo3(signature = (poses, edges, iterations=20))]
fn refine_pose_graph<'py>(
    py: Python<'py>,
    poses: Vec<Bound<'py, PyAny>>,
    edges: Vec<(usize, usize, Bound<'py, PyAny>, Bound<'py, PyAny>)>,
    iterations: usize,
) -> PyResult<Vec<Bound<'py, PyArray2<f64>>>> {
    let poses = poses
        .iter()
        .enumerate()
        .map(|(i, p)| {
            Ok(crate::geometry::isometry_from_matrix(&arrays::matrix4(
                p,
                &format!("poses[{i}]"),
            )?)?)
        })
        .collect::<PyResult<Vec<_>>>()?;
    let edges = edges
        .iter()
        .enumerate()
        .map(|(k, (a, b, z, w))| {
            let z = crate::geometry::isometry_from_matrix(&arrays::matrix4(
                z,
                &format!("edges[{k}] a_from_b"),
            )?)?;
            let w = arrays::matrix(w, &format!("edges[{k}] information"), 6, 6)?;
            Ok(PoseGraphEdge {
                a: *a,
                b: *b,
                a_from_b: z,
                information: nalgebra::Matrix6::from_row_slice(&w),
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let options = PoseGraphOptions {
        max_iterations: iterations,
        ..PoseGraphOptions::default()
    };
    let refined = run(py, move || rs_refine_pose_graph(&poses, &edges, &options))?;
    refined.poses.iter().map(|p| matrix4(py, p)).collect()
}

/// Fraction of target points that land within `distance` of a reference point under
/// `transform` (reference_from_target).
#[pyfunction]
#[pyo3(signature = (reference, target, transform, distance=0.25))]
fn overlap(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    transform: &Bound<'_, PyAny>,
    distance: f64,
) -> PyResult<f64> {
    let reference = arrays::points(reference, "reference")?;
    let target = arrays::points(target, "target")?;
    let pose = crate::geometry::isometry_from_matrix(&arrays::matrix4(transform, "transform")?)?;
    if !(distance.is_finite() && distance > 0.0) {
        return Err(PyValueError::new_err(format!(
            "distance must be finite and positive, got {distance}"
        )));
    }
    run(py, move || {
        let surface = crate::icp::SurfaceCloud::new(reference)?;
        Ok(surface.overlap(&target, &pose, distance))
    })
}

/// Rényi quadratic entropy crispness of a cloud (larger is crisper); see lidarcal.metrics.rqe.
#[pyfunction]
fn rqe(py: Python<'_>, points: &Bound<'_, PyAny>, sigma: f64) -> PyResult<f64> {
    let points = arrays::points(points, "points")?;
    run(py, move || crate::metrics::rqe(&points, sigma)).map(|r| r.crispness)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CalibrationResult>()?;
    m.add_function(wrap_pyfunction!(calibrate_planes, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_poles, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_targetless, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_auto, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_rig, m)?)?;
    m.add_function(wrap_pyfunction!(refine_pose_graph, m)?)?;
    m.add_function(wrap_pyfunction!(overlap, m)?)?;
    m.add("AGREEMENT_DISTANCE", method::AGREEMENT_DISTANCE)?;
    m.add("AUTO_TIE", method::AUTO_TIE)?;
    m.add("MIN_PAIR_OVERLAP", rig::MIN_PAIR_OVERLAP)?;
    m.add(
        "MAX_BRIGHT_FRACTION",
        crate::calib::poles::MAX_BRIGHT_FRACTION,
    )?;
    m.add_function(wrap_pyfunction!(rqe, m)?)?;
    Ok(())
}
