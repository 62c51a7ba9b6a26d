//! Python wrapper of [`crate::calib::result`]: `CalibrationResult` with the common fields,
//! `Refinement`, and the per-method `PlanarDetails`, `PoleDetails` and `TargetlessDetails`.
//! Every getter has the name of the Rust field it reads (`transform` and `initial_transform`
//! excepted: the package's name for `reference_from_target`); records inside the details
//! (`ordering`, `report`, `icp`, `hypotheses`, ...) are dicts keyed by the Rust field names.

use nalgebra::{Isometry3, Matrix6, Point3, Vector3};
use numpy::ndarray::{Ix1, Ix2};
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use pyo3::IntoPyObjectExt;

use super::arrays::{row_major, to_numpy};
use crate::calib::planes::{Ordering, PlanarDetails as Planar};
use crate::calib::poles::{Hypothesis, PoleDetails as Poles, PoleExtraction};
use crate::calib::result::{Calibration, Details, Refinement as Summary};
use crate::calib::targetless::{PlaneFeature, TargetlessDetails as Targetless};
use crate::geometry::{Line, Plane};
use crate::icp::IcpResult;
use crate::lm::LmReport;

type F64Array1<'py> = PyResult<Bound<'py, PyArray1<f64>>>;
type F64Array2<'py> = PyResult<Bound<'py, PyArray2<f64>>>;

/// A pose as a (4, 4) row-major array.
pub(crate) fn matrix4<'py>(py: Python<'py>, pose: &Isometry3<f64>) -> F64Array2<'py> {
    to_numpy(py, Ix2(4, 4), row_major(&pose.to_homogeneous()))
}

fn matrix6<'py>(py: Python<'py>, m: &Matrix6<f64>) -> F64Array2<'py> {
    to_numpy(py, Ix2(6, 6), row_major(m))
}

fn vector<'py>(py: Python<'py>, v: &[f64]) -> F64Array1<'py> {
    to_numpy(py, Ix1(v.len()), v.to_vec())
}

fn vec3<'py>(py: Python<'py>, v: &Vector3<f64>) -> F64Array1<'py> {
    vector(py, v.as_slice())
}

/// (K, 4) rows [nx, ny, nz, d].
fn planes_array<'py>(py: Python<'py>, planes: &[Plane]) -> F64Array2<'py> {
    let data = planes
        .iter()
        .flat_map(|p| p.coefficients().as_slice().to_vec())
        .collect();
    to_numpy(py, Ix2(planes.len(), 4), data)
}

/// (K, 6) rows [point, unit direction].
fn lines_array<'py>(py: Python<'py>, lines: &[Line]) -> F64Array2<'py> {
    let data = lines.iter().flat_map(line_row).collect();
    to_numpy(py, Ix2(lines.len(), 6), data)
}

fn line_row(l: &Line) -> [f64; 6] {
    let (p, d) = (l.point, l.direction);
    [p.x, p.y, p.z, d.x, d.y, d.z]
}

/// (2, 3) rows of points.
fn points_array<'py>(py: Python<'py>, points: &[Point3<f64>; 2]) -> F64Array2<'py> {
    let data = points.iter().flat_map(|p| p.coords.as_slice().to_vec());
    to_numpy(py, Ix2(2, 3), data.collect())
}

fn index_array<'py>(py: Python<'py>, v: &[usize]) -> Bound<'py, PyArray1<i64>> {
    PyArray1::from_iter(py, v.iter().map(|&i| i as i64))
}

fn indices<'py>(py: Python<'py>, sets: &[Vec<usize>]) -> Vec<Bound<'py, PyArray1<i64>>> {
    sets.iter().map(|v| index_array(py, v)).collect()
}

fn direction_share<'py>(
    py: Python<'py>,
    (v, share): &(Vector3<f64>, f64),
) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
    Ok((vec3(py, v)?, *share))
}

/// A dict of `(key, value)` pairs.
fn dict<'py>(
    py: Python<'py>,
    items: impl IntoIterator<Item = (&'static str, Bound<'py, PyAny>)>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in items {
        d.set_item(k, v)?;
    }
    Ok(d)
}

/// A value as a Python object (for [`dict`]).
fn any<'py>(py: Python<'py>, v: impl IntoPyObject<'py>) -> PyResult<Bound<'py, PyAny>> {
    v.into_bound_py_any(py)
}

fn lm_report<'py>(py: Python<'py>, r: &Option<LmReport>) -> PyResult<Option<Bound<'py, PyDict>>> {
    let Some(r) = r else { return Ok(None) };
    let items = [
        ("initial_cost", any(py, r.initial_cost)?),
        ("final_cost", any(py, r.final_cost)?),
        ("iterations", any(py, r.iterations)?),
        ("evaluations", any(py, r.evaluations)?),
        ("termination", any(py, r.termination.as_str())?),
        ("hessian", matrix6(py, &r.hessian)?.into_any()),
        ("residual_count", any(py, r.residual_count)?),
    ];
    dict(py, items).map(Some)
}

fn icp_result<'py>(py: Python<'py>, r: &Option<IcpResult>) -> PyResult<Option<Bound<'py, PyDict>>> {
    let Some(r) = r else { return Ok(None) };
    let covariance = r.covariance.as_ref().map(|c| matrix6(py, c)).transpose()?;
    let items = [
        ("pose", matrix4(py, &r.pose)?.into_any()),
        ("iterations", any(py, r.iterations)?),
        ("converged", any(py, r.converged)?),
        ("correspondences", any(py, r.correspondences)?),
        ("fitness", any(py, r.fitness)?),
        ("rmse", any(py, r.rmse)?),
        ("information", matrix6(py, &r.information)?.into_any()),
        ("covariance", any(py, covariance)?),
    ];
    dict(py, items).map(Some)
}

/// The result of a calibration: ``transform`` maps target points into the reference frame.
/// The fields every method fills; the method's own in ``details``.
#[pyclass(frozen, module = "lidarcal", name = "CalibrationResult")]
pub(crate) struct CalibrationResult {
    pub(crate) inner: Calibration,
}

impl<D: Into<Details>> From<Calibration<D>> for CalibrationResult {
    fn from(c: Calibration<D>) -> Self {
        CalibrationResult {
            inner: c.into_any(),
        }
    }
}

#[pymethods]
impl CalibrationResult {
    /// "planes", "poles" or "targetless".
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method().name()
    }
    /// (4, 4) reference_from_target: p_ref = R @ p_tgt + t.
    #[getter]
    fn transform<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        matrix4(py, &self.inner.reference_from_target)
    }
    /// (4, 4) the method's estimate before any refinement.
    #[getter]
    fn initial_transform<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        matrix4(py, &self.inner.initial_reference_from_target)
    }
    /// The final check's report (a CheckReport; always "consistent" for a returned result).
    #[getter]
    fn check(&self) -> super::check::CheckReport {
        super::check::CheckReport {
            inner: self.inner.check.clone(),
        }
    }
    /// (K,) RMS residual (metres) per matched feature, both clouds together: point-to-plane
    /// per plane, point-to-axis per pole.
    #[getter]
    fn rmse<'py>(&self, py: Python<'py>) -> F64Array1<'py> {
        vector(py, &self.inner.rmse)
    }
    /// int64 arrays: indices of each matched feature's (plane's or pole's) points in the
    /// reference cloud.
    #[getter]
    fn inliers_reference<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<i64>>> {
        indices(py, &self.inner.inliers_reference)
    }
    /// The same in the target cloud.
    #[getter]
    fn inliers_target<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<i64>>> {
        indices(py, &self.inner.inliers_target)
    }
    /// (6, 6) covariance of the left-perturbation tangent [rho, phi] (m, rad), or None.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.inner.covariance.map(|c| matrix6(py, &c)).transpose()
    }
    /// The solver that produced the returned pose, and how it ended.
    #[getter]
    fn refinement(&self) -> Refinement {
        Refinement {
            inner: self.inner.refinement,
        }
    }
    /// Milliseconds per stage, plus "total".
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = &self.inner.timings;
        let stages = t.stages.iter().map(|(name, ms)| Ok((*name, any(py, *ms)?)));
        let stages = stages.collect::<PyResult<Vec<_>>>()?;
        let total = ("total", any(py, t.total())?);
        dict(py, stages.into_iter().chain([total]))
    }
    /// The method's own diagnostics: PlanarDetails, PoleDetails or TargetlessDetails.
    #[getter]
    fn details(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        match &self.inner.details {
            Details::Planes(d) => PlanarDetails { inner: d.clone() }.into_py_any(py),
            Details::Poles(d) => PoleDetails { inner: d.clone() }.into_py_any(py),
            Details::Targetless(d) => TargetlessDetails { inner: d.clone() }.into_py_any(py),
        }
    }
    fn __repr__(&self) -> String {
        let c = &self.inner;
        let t = c.reference_from_target.translation.vector;
        let rpy = c.reference_from_target.rotation.euler_angles();
        let rmse: Vec<String> = c.rmse.iter().map(|r| format!("{r:.4}")).collect();
        let r = &c.refinement;
        format!(
            "CalibrationResult(method='{}', rotation_rpy_deg=[{:.3}, {:.3}, {:.3}], \
             translation_m=[{:.4}, {:.4}, {:.4}], rmse_m=[{}], refinement={}, total_ms={:.2})",
            c.method().name(),
            rpy.0.to_degrees(),
            rpy.1.to_degrees(),
            rpy.2.to_degrees(),
            t.x,
            t.y,
            t.z,
            rmse.join(", "),
            Refinement { inner: *r }.__repr__(),
            c.timings.total()
        )
    }
}

/// The solver that produced the returned pose ("closed_form", "levenberg_marquardt", "icp",
/// "verification" or "scene_alignment"), and how it ended.
#[pyclass(frozen, module = "lidarcal", name = "Refinement")]
pub(crate) struct Refinement {
    inner: Summary,
}

#[pymethods]
impl Refinement {
    /// "closed_form", "levenberg_marquardt", "icp", "verification" or "scene_alignment".
    #[getter]
    fn solver(&self) -> &'static str {
        self.inner.solver.name()
    }
    /// False only when the solver's iteration cap ran out first.
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }
    /// Iterations run (0 for the solvers without iterations of their own).
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    /// Final cost 1/2 sum rho(r^2) of Levenberg–Marquardt; NaN for the other solvers.
    #[getter]
    fn cost(&self) -> f64 {
        self.inner.cost
    }
    /// Why the solver stopped ("none" for the solvers without iterations of their own).
    #[getter]
    fn termination(&self) -> &'static str {
        self.inner.termination
    }
    fn __repr__(&self) -> String {
        let r = &self.inner;
        format!(
            "Refinement(solver='{}', converged={}, iterations={}, cost={}, termination='{}')",
            r.solver.name(),
            if r.converged { "True" } else { "False" },
            r.iterations,
            r.cost,
            r.termination
        )
    }
}

/// The corner method's own diagnostics (``CalibrationResult.details``).
#[pyclass(frozen, module = "lidarcal", name = "PlanarDetails")]
pub(crate) struct PlanarDetails {
    inner: Planar,
}

#[pymethods]
impl PlanarDetails {
    /// (3, 4) matched planes [nx, ny, nz, d] in the reference frame (normals toward the sensor).
    #[getter]
    fn planes_reference<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        planes_array(py, &self.inner.planes_reference)
    }
    /// (3, 4) matched planes in the target frame, row i matching planes_reference[i].
    #[getter]
    fn planes_target<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        planes_array(py, &self.inner.planes_target)
    }
    /// (2, 3) the corner point in the reference and in the target frame.
    #[getter]
    fn corners<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        points_array(py, &self.inner.corners)
    }
    /// The plane correspondence: {"scores": (3,) RMS normal misalignment (rad) of each cyclic
    /// shift, "chosen": the shift used, "margin": runner-up minus chosen (rad), "used_up": the
    /// gravity tie-break decided}.
    #[getter]
    fn ordering<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let o: &Ordering = &self.inner.ordering;
        let items = [
            ("scores", vector(py, &o.scores)?.into_any()),
            ("chosen", any(py, o.chosen)?),
            ("margin", any(py, o.margin)?),
            ("used_up", any(py, o.used_up)?),
        ];
        dict(py, items)
    }
    /// (2,) inlier thresholds used for the reference and the target cloud (metres).
    #[getter]
    fn distance_thresholds<'py>(&self, py: Python<'py>) -> F64Array1<'py> {
        vector(py, &self.inner.distance_thresholds)
    }
    /// The Levenberg–Marquardt report (a dict) or None when refine was off.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        lm_report(py, &self.inner.report)
    }
    fn __repr__(&self) -> String {
        let o = &self.inner.ordering;
        format!(
            "PlanarDetails(matched_planes=3, ordering_chosen={}, ordering_margin_rad={:.4}, \
             used_up={}, distance_thresholds_m=[{:.4}, {:.4}])",
            o.chosen,
            o.margin,
            if o.used_up { "True" } else { "False" },
            self.inner.distance_thresholds[0],
            self.inner.distance_thresholds[1]
        )
    }
}

/// The pole method's own diagnostics (``CalibrationResult.details``).
#[pyclass(frozen, module = "lidarcal", name = "PoleDetails")]
pub(crate) struct PoleDetails {
    inner: Poles,
}

fn hypothesis<'py>(py: Python<'py>, h: &Hypothesis) -> PyResult<Bound<'py, PyDict>> {
    let items = [
        ("matches", any(py, h.matches.clone())?),
        (
            "reference_from_target",
            matrix4(py, &h.reference_from_target)?.into_any(),
        ),
        ("axis_rms", any(py, h.axis_rms)?),
        ("ground_angle", any(py, h.ground_angle)?),
        ("ground_offset", any(py, h.ground_offset)?),
        ("overlap", any(py, h.overlap)?),
        ("score", any(py, h.score)?),
    ];
    dict(py, items)
}

fn extraction<'py>(py: Python<'py>, e: &PoleExtraction) -> PyResult<Bound<'py, PyDict>> {
    let poles = e.poles.iter().map(|p| {
        let items = [
            ("axis", vector(py, &line_row(&p.axis))?.into_any()),
            ("radius", any(py, p.radius)?),
            ("rms", any(py, p.rms)?),
            ("indices", index_array(py, &p.indices).into_any()),
            ("extent", any(py, p.extent)?),
        ];
        dict(py, items)
    });
    let rejected = e.rejected.iter().map(|r| {
        dict(
            py,
            [
                ("size", any(py, r.size)?),
                ("reason", any(py, r.reason.as_str())?),
            ],
        )
    });
    let items = [
        ("intensity_threshold", any(py, e.intensity_threshold)?),
        ("bright_points", any(py, e.bright_points)?),
        ("poles", any(py, poles.collect::<PyResult<Vec<_>>>()?)?),
        (
            "rejected",
            any(py, rejected.collect::<PyResult<Vec<_>>>()?)?,
        ),
    ];
    dict(py, items)
}

#[pymethods]
impl PoleDetails {
    /// (K, 6) matched pole axes [point, unit direction] in the reference frame.
    #[getter]
    fn poles_reference<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        lines_array(py, &self.inner.poles_reference)
    }
    /// (K, 6) matched pole axes in the target frame, directions signed to match
    /// poles_reference.
    #[getter]
    fn poles_target<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        lines_array(py, &self.inner.poles_target)
    }
    /// (K,) radius of each matched pole (metres; given, or the mean of both clouds' estimates;
    /// 0 with axis_fit="line").
    #[getter]
    fn radii<'py>(&self, py: Python<'py>) -> F64Array1<'py> {
        vector(py, &self.inner.radii)
    }
    /// The poles found in the reference and in the target cloud: two dicts of
    /// intensity_threshold, bright_points, poles (dicts of axis (6,), radius, rms, indices,
    /// extent) and rejected (dicts of size, reason).
    #[getter]
    fn extractions<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .extractions
            .iter()
            .map(|e| extraction(py, e))
            .collect()
    }
    /// Every correspondence/sign hypothesis in enumeration order, a dict of matches
    /// [(reference pole, target pole, sign)], reference_from_target (4, 4), axis_rms (m),
    /// ground_angle (rad) and ground_offset (m) (None without a plane), overlap and score (lower
    /// is better).
    #[getter]
    fn hypotheses<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .hypotheses
            .iter()
            .map(|h| hypothesis(py, h))
            .collect()
    }
    /// Index of the chosen hypothesis.
    #[getter]
    fn chosen(&self) -> usize {
        self.inner.chosen
    }
    /// Score of the best hypothesis reaching a different transform minus the chosen one's (inf
    /// when all agree).
    #[getter]
    fn margin(&self) -> f64 {
        self.inner.margin
    }
    /// True when the margin is below 1 (a near-tie, though not refused).
    #[getter]
    fn ambiguous(&self) -> bool {
        self.inner.ambiguous
    }
    /// The chosen hypothesis's Levenberg–Marquardt report (a dict), or None.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        lm_report(py, &self.inner.report)
    }
    fn __repr__(&self) -> String {
        let d = &self.inner;
        format!(
            "PoleDetails(matched_poles={}, radii_m={:.3?}, hypotheses={}, chosen={}, \
             margin={:.3}, ambiguous={})",
            d.poles_reference.len(),
            d.radii,
            d.hypotheses.len(),
            d.chosen,
            d.margin,
            if d.ambiguous { "True" } else { "False" }
        )
    }
}

/// The targetless method's own diagnostics (``CalibrationResult.details``).
#[pyclass(frozen, module = "lidarcal", name = "TargetlessDetails")]
pub(crate) struct TargetlessDetails {
    inner: Targetless,
}

fn feature<'py>(py: Python<'py>, f: &PlaneFeature) -> PyResult<Bound<'py, PyDict>> {
    let items = [
        (
            "plane",
            vector(py, f.plane.coefficients().as_slice())?.into_any(),
        ),
        ("voxels", index_array(py, &f.voxels).into_any()),
        ("centroid", vec3(py, &f.centroid.coords)?.into_any()),
        ("extent", vector(py, &f.extent)?.into_any()),
    ];
    dict(py, items)
}

#[pymethods]
impl TargetlessDetails {
    /// (K, 4) matched planes [nx, ny, nz, d] in the reference frame.
    #[getter]
    fn planes_reference<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        planes_array(py, &self.inner.planes_reference)
    }
    /// (K, 4) matched planes in the target frame, row i matching planes_reference[i].
    #[getter]
    fn planes_target<'py>(&self, py: Python<'py>) -> F64Array2<'py> {
        planes_array(py, &self.inner.planes_target)
    }
    /// The planes extracted from the reference and from the target cloud: two lists of dicts of
    /// plane (4,), voxels (indices into the downsampled cloud), centroid (3,), extent (2,).
    #[getter]
    fn features<'py>(&self, py: Python<'py>) -> PyResult<Vec<Vec<Bound<'py, PyDict>>>> {
        let cloud = |fs: &[PlaneFeature]| fs.iter().map(|f| feature(py, f)).collect();
        self.inner.features.iter().map(|fs| cloud(fs)).collect()
    }
    /// (enumerated, distinct) plane-pair/triplet hypotheses.
    #[getter]
    fn hypothesis_counts(&self) -> (usize, usize) {
        let [a, b] = self.inner.hypothesis_counts;
        (a, b)
    }
    /// Hypotheses verified by ICP.
    #[getter]
    fn verified(&self) -> usize {
        self.inner.verified
    }
    /// Whether the winning hypothesis was a plane triplet rather than a pair.
    #[getter]
    fn triplet(&self) -> bool {
        self.inner.triplet
    }
    /// Whether the winning hypothesis came from the ground sweep.
    #[getter]
    fn sweep(&self) -> bool {
        self.inner.sweep
    }
    /// Verification score of the best hypothesis: agreement minus 3 x the free-space violations.
    #[getter]
    fn best_score(&self) -> f64 {
        self.inner.best_score
    }
    /// Best verification score of a hypothesis ending at a different pose (0 when none).
    #[getter]
    fn second_score(&self) -> f64 {
        self.inner.second_score
    }
    /// Share of the checked target points within 25 cm of a reference point at the best
    /// hypothesis.
    #[getter]
    fn agreement(&self) -> f64 {
        self.inner.agreement
    }
    /// (target points in the reference's free space, reference points in the target's) as shares
    /// of the checked points, at the best hypothesis.
    #[getter]
    fn violations(&self) -> (f64, f64) {
        let [a, b] = self.inner.violations;
        (a, b)
    }
    /// True when a distinct pose verified almost as well as the best (only returned with
    /// refuse_ambiguous=False).
    #[getter]
    fn ambiguous(&self) -> bool {
        self.inner.ambiguous
    }
    /// (2,) inlier thresholds used for the reference and the target cloud (metres).
    #[getter]
    fn distance_thresholds<'py>(&self, py: Python<'py>) -> F64Array1<'py> {
        vector(py, &self.inner.distance_thresholds)
    }
    /// The Levenberg–Marquardt report of the plane refinement (a dict), or None.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        lm_report(py, &self.inner.report)
    }
    /// The final ICP (a dict of pose, iterations, converged, correspondences, fitness, rmse,
    /// information, covariance), or None when disabled.
    #[getter]
    fn icp<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        icp_result(py, &self.inner.icp)
    }
    /// ((3,) direction in the reference frame, share of the information) of the least
    /// constrained translation.
    #[getter]
    fn weakest_translation<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
        direction_share(py, &self.inner.weakest_translation)
    }
    /// ((3,) axis, share of the information) of the least constrained rotation.
    #[getter]
    fn weakest_rotation<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
        direction_share(py, &self.inner.weakest_rotation)
    }
    /// Share of the weakest translation direction spanned by the matched planes' normals alone.
    #[getter]
    fn plane_translation_share(&self) -> f64 {
        self.inner.plane_translation_share
    }
    fn __repr__(&self) -> String {
        let d = &self.inner;
        format!(
            "TargetlessDetails(matched_planes={}, hypothesis_counts=({}, {}), verified={}, \
             best_score={:.3}, second_score={:.3}, agreement={:.3}, ambiguous={}, \
             weakest_translation_share={:.4})",
            d.planes_reference.len(),
            d.hypothesis_counts[0],
            d.hypothesis_counts[1],
            d.verified,
            d.best_score,
            d.second_score,
            d.agreement,
            if d.ambiguous { "True" } else { "False" },
            d.weakest_translation.1
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CalibrationResult>()?;
    m.add_class::<Refinement>()?;
    m.add_class::<PlanarDetails>()?;
    m.add_class::<PoleDetails>()?;
    m.add_class::<TargetlessDetails>()?;
    Ok(())
}
