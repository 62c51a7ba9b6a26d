//! Python wrappers of the calibration methods and their result object.

use nalgebra::{Isometry3, Vector3};
use numpy::ndarray::{Ix1, Ix2};
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::arrays::{self, row_major, to_numpy};
use super::run;
use crate::calib::planes::{
    calibrate_planes as rs_calibrate_planes, PlanarCalibration, PlanarOptions,
};
use crate::lm::{LmOptions, Loss};

/// The result of a calibration: `transform` maps target points into the reference frame.
#[pyclass(frozen, module = "lidarcal", name = "CalibrationResult")]
pub(crate) struct CalibrationResult {
    inner: PlanarCalibration,
}

fn matrix4<'py>(py: Python<'py>, pose: &Isometry3<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    to_numpy(py, Ix2(4, 4), row_major(&pose.to_homogeneous()))
}

#[pymethods]
impl CalibrationResult {
    /// "planes".
    #[getter]
    fn method(&self) -> &'static str {
        "planes"
    }
    /// (4, 4) reference_from_target: p_ref = R @ p_tgt + t.
    #[getter]
    fn transform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix4(py, &self.inner.reference_from_target)
    }
    /// (4, 4) the closed-form estimate before the Levenberg–Marquardt refinement.
    #[getter]
    fn initial_transform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix4(py, &self.inner.initial_reference_from_target)
    }
    /// True when the refinement converged (or was not requested).
    #[getter]
    fn converged(&self) -> bool {
        self.inner.report.as_ref().is_none_or(|r| r.converged())
    }
    /// LM iterations (0 without refinement).
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.report.as_ref().map_or(0, |r| r.iterations)
    }
    /// Final cost 1/2 sum r^2 of the refinement (NaN without refinement).
    #[getter]
    fn cost(&self) -> f64 {
        self.inner
            .report
            .as_ref()
            .map_or(f64::NAN, |r| r.final_cost)
    }
    /// Why the refinement stopped ("none" without refinement).
    #[getter]
    fn termination(&self) -> &'static str {
        self.inner
            .report
            .as_ref()
            .map_or("none", |r| r.termination.as_str())
    }
    /// (3,) RMS point-to-plane residual per matched plane (metres), both clouds together.
    #[getter]
    fn rmse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(3), self.inner.rmse.to_vec())
    }
    /// (3, 4) matched planes [nx, ny, nz, d] in the reference frame (normals toward the sensor).
    #[getter]
    fn planes_reference<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let data = self
            .inner
            .planes_reference
            .iter()
            .flat_map(|p| p.coefficients().iter().copied().collect::<Vec<_>>())
            .collect();
        to_numpy(py, Ix2(3, 4), data)
    }
    /// (3, 4) matched planes in the target frame, row i matching planes_reference[i].
    #[getter]
    fn planes_target<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let data = self
            .inner
            .planes_target
            .iter()
            .flat_map(|p| p.coefficients().iter().copied().collect::<Vec<_>>())
            .collect();
        to_numpy(py, Ix2(3, 4), data)
    }
    /// (2, 3) inliers per matched plane: row 0 reference, row 1 target.
    #[getter]
    fn inlier_counts<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        let counts: Vec<i64> = self
            .inner
            .inliers_reference
            .iter()
            .chain(&self.inner.inliers_target)
            .map(|v| v.len() as i64)
            .collect();
        numpy::ndarray::Array2::from_shape_vec((2, 3), counts)
            .map(|a| numpy::IntoPyArray::into_pyarray(a, py))
            .unwrap_or_else(|_| PyArray2::zeros(py, (2, 3), false))
    }
    /// Three int64 arrays: indices of each matched plane's inliers in the reference cloud.
    #[getter]
    fn inliers_reference<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<i64>>> {
        self.inner
            .inliers_reference
            .iter()
            .map(|v| PyArray1::from_iter(py, v.iter().map(|&i| i as i64)))
            .collect()
    }
    /// Three int64 arrays: indices of each matched plane's inliers in the target cloud.
    #[getter]
    fn inliers_target<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<i64>>> {
        self.inner
            .inliers_target
            .iter()
            .map(|v| PyArray1::from_iter(py, v.iter().map(|&i| i as i64)))
            .collect()
    }
    /// (3,) RMS normal misalignment (rad) of each cyclic plane correspondence; lower is better.
    #[getter]
    fn ordering_scores<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(3), self.inner.ordering.scores.to_vec())
    }
    /// Runner-up score minus the chosen one (rad): how clearly the planes were matched.
    #[getter]
    fn ordering_margin(&self) -> f64 {
        self.inner.ordering.margin
    }
    /// True when the geometry was ambiguous and the `up` tie-break chose the correspondence.
    #[getter]
    fn used_up(&self) -> bool {
        self.inner.ordering.used_up
    }
    /// (2, 3) the corner point in the reference and in the target frame.
    #[getter]
    fn corners<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let [a, b] = self.inner.corners;
        to_numpy(py, Ix2(2, 3), vec![a.x, a.y, a.z, b.x, b.y, b.z])
    }
    /// (2,) inlier thresholds used for the reference and the target cloud (metres).
    #[getter]
    fn distance_thresholds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(2), self.inner.distance_thresholds.to_vec())
    }
    /// (6, 6) covariance of the left-perturbation tangent [rho, phi] (m, rad), or None.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.inner
            .covariance
            .map(|c| to_numpy(py, Ix2(6, 6), row_major(&c)))
            .transpose()
    }
    /// Milliseconds per stage, plus "total".
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, ms) in &self.inner.timings.stages {
            d.set_item(*name, *ms)?;
        }
        d.set_item("total", self.inner.timings.total())?;
        Ok(d)
    }
    fn __repr__(&self) -> String {
        let pose = &self.inner.reference_from_target;
        let t = pose.translation.vector;
        let rpy = pose.rotation.euler_angles();
        format!(
            "CalibrationResult(method='planes', converged={}, rotation_rpy_deg=[{:.3}, {:.3}, {:.3}], \
             translation_m=[{:.4}, {:.4}, {:.4}], rmse_m=[{:.4}, {:.4}, {:.4}], iterations={}, \
             total_ms={:.2})",
            if self.converged() { "True" } else { "False" },
            rpy.0.to_degrees(),
            rpy.1.to_degrees(),
            rpy.2.to_degrees(),
            t.x,
            t.y,
            t.z,
            self.inner.rmse[0],
            self.inner.rmse[1],
            self.inner.rmse[2],
            self.iterations(),
            self.inner.timings.total()
        )
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
/// Raises CalibrationError with the reason when no trustworthy result exists.
#[pyfunction]
#[pyo3(signature = (reference, target, *, distance_threshold=None, seed=0, up=None, refine=true, loss="auto", loss_scale=None, min_inliers=50, max_iterations=100))]
#[allow(clippy::too_many_arguments)]
fn calibrate_planes(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    distance_threshold: Option<f64>,
    seed: u64,
    up: Option<&Bound<'_, PyAny>>,
    refine: bool,
    loss: &str,
    loss_scale: Option<f64>,
    min_inliers: usize,
    max_iterations: usize,
) -> PyResult<CalibrationResult> {
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
        lm: LmOptions {
            max_iterations,
            ..PlanarOptions::default().lm
        },
    };
    let inner = run(py, move || {
        rs_calibrate_planes(&reference, &target, &options)
    })?;
    Ok(CalibrationResult { inner })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CalibrationResult>()?;
    m.add_function(wrap_pyfunction!(calibrate_planes, m)?)?;
    Ok(())
}
