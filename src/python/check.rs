//! Python wrapper of [`crate::check`]: `check(reference, target, transform) -> CheckReport`.

use nalgebra::Vector3;
use numpy::ndarray::Ix1;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::arrays::{self, to_numpy};
use super::defaults::table;
use super::result::matrix4;
use super::run;
use crate::check::{check as rs_check, CheckOptions, CheckReport as Report};
use crate::geometry::isometry_from_matrix;

/// What `check` found: `verdict` ("consistent", "inconsistent" or "unverifiable"), a one-line
/// `reason` and the evidence (overlap, agreement, free-space violations, the correction a local
/// re-alignment applies, observability and the smallest errors this scene detects).
#[pyclass(frozen, module = "lidarcal", name = "CheckReport")]
pub(crate) struct CheckReport {
    pub(crate) inner: Report,
}

fn vec3<'py>(py: Python<'py>, v: &Vector3<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
    to_numpy(py, Ix1(3), v.as_slice().to_vec())
}

#[pymethods]
impl CheckReport {
    /// "consistent", "inconsistent" or "unverifiable".
    #[getter]
    fn verdict(&self) -> &'static str {
        self.inner.verdict.name()
    }
    /// One line saying why.
    #[getter]
    fn reason(&self) -> &str {
        &self.inner.reason
    }
    /// Share of the sampled target points within overlap_distance of a reference point.
    #[getter]
    fn overlap(&self) -> f64 {
        self.inner.overlap
    }
    /// Share of the sampled reference points within overlap_distance of a target point.
    #[getter]
    fn reverse_overlap(&self) -> f64 {
        self.inner.reverse_overlap
    }
    /// Share of the overlapping target points within 3 sigma of the reference surface.
    #[getter]
    fn agreement(&self) -> f64 {
        self.inner.agreement
    }
    /// Share of the overlapping reference points within 3 sigma of the target surface.
    #[getter]
    fn reverse_agreement(&self) -> f64 {
        self.inner.reverse_agreement
    }
    /// Rise of the agreement (the smaller of both ways) from the given pose to `aligned`.
    #[getter]
    fn agreement_gain(&self) -> f64 {
        self.inner.agreement_gain
    }
    /// Share of target points in the reference sensor's free space (of those it could see).
    #[getter]
    fn violations(&self) -> f64 {
        self.inner.violations
    }
    /// Share of reference points in the target sensor's free space.
    #[getter]
    fn reverse_violations(&self) -> f64 {
        self.inner.reverse_violations
    }
    /// RMS point-to-plane residual of the agreeing target points (metres).
    #[getter]
    fn rmse(&self) -> f64 {
        self.inner.rmse
    }
    /// Noise scale used (metres, 1 sigma).
    #[getter]
    fn noise(&self) -> f64 {
        self.inner.noise
    }
    /// Target points in the overlap.
    #[getter]
    fn overlap_points(&self) -> usize {
        self.inner.overlap_points
    }
    /// (4, 4) the pose a local re-alignment prefers.
    #[getter]
    fn aligned<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix4(py, &self.inner.aligned)
    }
    /// Rotation from the given pose to `aligned` (degrees).
    #[getter]
    fn correction_rotation_deg(&self) -> f64 {
        self.inner.correction_rotation.to_degrees()
    }
    /// Translation from the given pose to `aligned` (metres).
    #[getter]
    fn correction_translation_m(&self) -> f64 {
        self.inner.correction_translation
    }
    /// (3,) least-constrained translation direction (reference frame).
    #[getter]
    fn weakest_translation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        vec3(py, &self.inner.weakest_translation.0)
    }
    /// Its share of the translation information (1/3 isotropic, 0 unconstrained).
    #[getter]
    fn weakest_translation_share(&self) -> f64 {
        self.inner.weakest_translation.1
    }
    /// (3,) least-constrained rotation axis.
    #[getter]
    fn weakest_rotation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        vec3(py, &self.inner.weakest_rotation.0)
    }
    /// Its share of the rotation information.
    #[getter]
    fn weakest_rotation_share(&self) -> f64 {
        self.inner.weakest_rotation.1
    }
    /// Smallest rotation error this scene flags (degrees).
    #[getter]
    fn detectable_rotation_deg(&self) -> f64 {
        self.inner.detectable_rotation.to_degrees()
    }
    /// Smallest translation error this scene flags (metres).
    #[getter]
    fn detectable_translation_m(&self) -> f64 {
        self.inner.detectable_translation
    }
    /// True when the verdict is "consistent".
    fn __bool__(&self) -> bool {
        self.inner.is_consistent()
    }
    /// The report as a plain dict (JSON-ready).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let d = pyo3::types::PyDict::new(py);
        let r = &self.inner;
        d.set_item("verdict", r.verdict.name())?;
        d.set_item("reason", &r.reason)?;
        d.set_item("overlap", r.overlap)?;
        d.set_item("reverse_overlap", r.reverse_overlap)?;
        d.set_item("agreement", r.agreement)?;
        d.set_item("reverse_agreement", r.reverse_agreement)?;
        d.set_item("agreement_gain", r.agreement_gain)?;
        d.set_item("violations", r.violations)?;
        d.set_item("reverse_violations", r.reverse_violations)?;
        d.set_item("rmse", r.rmse)?;
        d.set_item("noise", r.noise)?;
        d.set_item("overlap_points", r.overlap_points)?;
        d.set_item(
            "correction_rotation_deg",
            r.correction_rotation.to_degrees(),
        )?;
        d.set_item("correction_translation_m", r.correction_translation)?;
        d.set_item(
            "weakest_translation",
            r.weakest_translation.0.as_slice().to_vec(),
        )?;
        d.set_item("weakest_translation_share", r.weakest_translation.1)?;
        d.set_item("weakest_rotation", r.weakest_rotation.0.as_slice().to_vec())?;
        d.set_item("weakest_rotation_share", r.weakest_rotation.1)?;
        d.set_item(
            "detectable_rotation_deg",
            r.detectable_rotation.to_degrees(),
        )?;
        d.set_item("detectable_translation_m", r.detectable_translation)?;
        Ok(d)
    }
    fn __repr__(&self) -> String {
        format!("CheckReport({})", self.inner)
    }
}

/// Checks a transform against the two clouds, independent of how it was found.
///
/// reference, target: (N, 3) or (N, 4) clouds in their sensors' frames.
/// transform: (4, 4) reference_from_target (p_ref = R @ p_tgt + t), from any source.
/// noise: range noise in metres (1 sigma), or None to measure it. The other keywords left None
///     take the Rust `CheckOptions::default()`: voxel_size=0.1, samples=4000,
///     rotation_tolerance_deg=0.5, translation_tolerance_m=0.06.
/// Returns a CheckReport; raises ValueError for malformed input (an inconsistent or
/// unverifiable transform is a verdict, not an exception).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (reference, target, transform, *, noise=None, voxel_size=None, samples=None, rotation_tolerance_deg=None, translation_tolerance_m=None))]
pub(crate) fn check(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    transform: &Bound<'_, PyAny>,
    noise: Option<f64>,
    voxel_size: Option<f64>,
    samples: Option<usize>,
    rotation_tolerance_deg: Option<f64>,
    translation_tolerance_m: Option<f64>,
) -> PyResult<CheckReport> {
    let reference = arrays::points(reference, "reference")?;
    let target = arrays::points(target, "target")?;
    let pose = isometry_from_matrix(&arrays::matrix4(transform, "transform")?)?;
    let defaults = CheckOptions::default();
    let options = CheckOptions {
        noise: noise.or(defaults.noise),
        voxel_size: voxel_size.unwrap_or(defaults.voxel_size),
        samples: samples.unwrap_or(defaults.samples),
        rotation_tolerance: rotation_tolerance_deg
            .map(f64::to_radians)
            .unwrap_or(defaults.rotation_tolerance),
        translation_tolerance: translation_tolerance_m.unwrap_or(defaults.translation_tolerance),
        ..defaults
    };
    let inner = run(py, move || rs_check(&reference, &target, &pose, &options))?;
    Ok(CheckReport { inner })
}

/// The Rust defaults behind `check`'s keywords (see `super::defaults`).
pub(crate) fn defaults(out: &Bound<'_, PyDict>) -> PyResult<()> {
    let o = CheckOptions::default();
    let t = table(out, "check")?;
    t.set_item("voxel_size", o.voxel_size)?;
    t.set_item("samples", o.samples)?;
    t.set_item("rotation_tolerance_deg", o.rotation_tolerance.to_degrees())?;
    t.set_item("translation_tolerance_m", o.translation_tolerance)?;
    Ok(())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CheckReport>()?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    Ok(())
}
