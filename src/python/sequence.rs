//! Python wrappers of [`crate::odometry`] and [`crate::calib::sequence`]: `odometry(frames)` and
//! `calibrate_sequence(reference_frames, target_frames) -> SequenceResult`.

use nalgebra::{Isometry3, Point3, Vector3};
use numpy::ndarray::{Ix1, Ix3};
use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::arrays::{self, row_major, to_numpy};
use super::result::matrix4;
use super::run;
use crate::calib::sequence::{
    calibrate_sequence as rs_calibrate_sequence, SequenceCalibration, SequenceOptions,
};
use crate::odometry::{odometry as rs_odometry, OdometryOptions};

/// The frames of a list (or any sequence) of `(N, 3|4)` arrays.
fn frames_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Vec<Point3<f64>>>> {
    if obj.is_instance_of::<pyo3::types::PyString>() || obj.hasattr("shape")? {
        return Err(PyTypeError::new_err(format!(
            "{name} must be a list of (N, 3) or (N, 4) arrays, one per frame, got {}",
            obj.get_type().name()?
        )));
    }
    let mut frames = Vec::new();
    for (k, item) in obj.try_iter()?.enumerate() {
        frames.push(arrays::points(&item?, &format!("{name}[{k}]"))?);
    }
    Ok(frames)
}

fn odometry_options(
    voxel: Option<f64>,
    min_range: Option<f64>,
    max_range: Option<f64>,
) -> OdometryOptions {
    let d = OdometryOptions::default();
    OdometryOptions {
        voxel: voxel.unwrap_or(d.voxel),
        min_range: min_range.unwrap_or(d.min_range),
        max_range: max_range.unwrap_or(d.max_range),
        ..d
    }
}

fn poses_array<'py>(
    py: Python<'py>,
    poses: &[Isometry3<f64>],
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let data = poses
        .iter()
        .flat_map(|p| row_major(&p.to_homogeneous()))
        .collect();
    to_numpy(py, Ix3(poses.len(), 4, 4), data)
}

fn vec3<'py>(py: Python<'py>, v: &Vector3<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
    to_numpy(py, Ix1(3), v.as_slice().to_vec())
}

/// The poses of one sensor over a recording, from its own frames (LiDAR odometry: each frame
/// registered point-to-plane to a local voxel map of the frames before it, with a
/// constant-velocity prediction and an adaptive correspondence distance, as KISS-ICP does).
///
/// frames: a list of (N, 3) or (N, 4) arrays in the sensor's frame, in time order at a steady rate.
/// voxel: map voxel in metres (default 1.0; frames are downsampled to half of it for the map and
///     1.5 times it for the registration). min_range, max_range: returns kept (default 0.5-100 m).
/// Returns a (K, 4, 4) float64 array of world_from_sensor, the world being the first frame.
/// Raises ValueError for bad input, CalibrationError (kind "no_agreement") if it loses track.
#[pyfunction]
#[pyo3(signature = (frames, *, voxel=None, min_range=None, max_range=None))]
fn odometry<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    voxel: Option<f64>,
    min_range: Option<f64>,
    max_range: Option<f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let frames = frames_arg(frames, "frames")?;
    let options = odometry_options(voxel, min_range, max_range);
    let result = run(py, || rs_odometry(&frames, &options))?;
    poses_array(py, &result.poses)
}

/// What `calibrate_sequence` found: the extrinsic, the hand-eye estimate it started from, the
/// map alignment's evidence and both sensors' trajectories.
#[pyclass(frozen, module = "lidarcal", name = "SequenceResult")]
pub(crate) struct SequenceResult {
    inner: SequenceCalibration,
}

#[pymethods]
impl SequenceResult {
    /// Always "sequence".
    #[getter]
    fn method(&self) -> &'static str {
        "sequence"
    }
    /// reference_from_target, a 4x4 float64 matrix.
    #[getter]
    fn transform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix4(py, &self.inner.reference_from_target)
    }
    /// The hand-eye estimate (from the two trajectories alone) the map alignment started from.
    #[getter]
    fn hand_eye_transform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix4(py, &self.inner.hand_eye.reference_from_target)
    }
    /// The translation direction (reference frame) the motion left unobserved (the vertical of
    /// a drive on flat ground), or None; the map alignment fixed it from the shared views.
    #[getter]
    fn unobserved_by_motion<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        self.inner
            .hand_eye
            .unobserved_translation
            .map(|v| vec3(py, &v))
            .transpose()
    }
    /// Share of the target's samples on the reference's map at the result.
    #[getter]
    fn fitness(&self) -> f64 {
        self.inner.alignment.fitness
    }
    /// RMS point-to-plane residual of the map alignment (metres).
    #[getter]
    fn rmse(&self) -> f64 {
        self.inner.alignment.rmse
    }
    /// Whether the map alignment converged.
    #[getter]
    fn converged(&self) -> bool {
        self.inner.alignment.converged
    }
    /// Map alignment iterations.
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.alignment.iterations
    }
    /// The reference sensor's poses, (K, 4, 4) world_from_reference (world: its first frame).
    #[getter]
    fn reference_poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        poses_array(py, &self.inner.reference_odometry.poses)
    }
    /// The target sensor's poses, (K, 4, 4) in its own world (its first frame).
    #[getter]
    fn target_poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        poses_array(py, &self.inner.target_odometry.poses)
    }
    /// Path length the reference sensor travelled (metres).
    #[getter]
    fn distance(&self) -> f64 {
        self.inner.reference_odometry.distance
    }
    /// 6x6 covariance of the tangent [rho; phi] from the map alignment's residuals, or None; a
    /// lower bound (odometry error between the two sensors' views is not in it).
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.inner
            .covariance
            .map(|c| to_numpy(py, numpy::ndarray::Ix2(6, 6), row_major(&c)))
            .transpose()
    }
    /// (direction, share): the map alignment's least-constrained translation direction.
    #[getter]
    fn weakest_translation<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
        let (d, s) = self.inner.weakest_translation;
        Ok((vec3(py, &d)?, s))
    }
    /// (axis, share): the map alignment's least-constrained rotation axis.
    #[getter]
    fn weakest_rotation<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
        let (d, s) = self.inner.weakest_rotation;
        Ok((vec3(py, &d)?, s))
    }
    /// Stage timings in milliseconds: odometry, hand_eye, align.
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, ms) in &self.inner.timings.stages {
            d.set_item(*name, *ms)?;
        }
        Ok(d)
    }
    fn __repr__(&self) -> String {
        let t = self.inner.reference_from_target.translation.vector;
        let (r, p, y) = self.inner.reference_from_target.rotation.euler_angles();
        format!(
            "SequenceResult(translation=[{:.3}, {:.3}, {:.3}] m, rpy=[{:.2}, {:.2}, {:.2}] deg, \
             fitness={:.2}, rmse={:.3} m, distance={:.1} m, frames={})",
            t.x,
            t.y,
            t.z,
            r.to_degrees(),
            p.to_degrees(),
            y.to_degrees(),
            self.inner.alignment.fitness,
            self.inner.alignment.rmse,
            self.inner.reference_odometry.distance,
            self.inner.reference_odometry.poses.len()
        )
    }
}

/// Calibrates reference_from_target from a drive: frame k of both lists taken at the same time.
///
/// The two sensors need not see the same thing at the same time. Each sensor's odometry gives its
/// trajectory; hand-eye calibration of the synchronized motions gives a first extrinsic (all but
/// the height on flat ground); the target's frames placed by the reference's trajectory are then
/// aligned to the map the reference built of the same streets, which brings it to centimetres and
/// fixes the height from the ground both saw.
///
/// reference_frames, target_frames: lists of (N, 3) or (N, 4) arrays, each in its sensor's frame.
/// seed: accepted for symmetry with the other methods; no stage makes a random choice, so the
///     result does not depend on it.
/// voxel, min_range, max_range: the odometry's (see `odometry`).
/// strides: frame strides of the motion pairs (default [5, 10, 20]).
/// Raises ValueError for bad input (different frame counts, fewer than 10 frames, NaN in a
/// frame), CalibrationError with kind "unobservable" (a standing vehicle, no turn, no shared
/// ground), "no_agreement" or "too_few_features" when the drive does not determine the extrinsic.
#[pyfunction]
#[pyo3(signature = (reference_frames, target_frames, *, seed=0, voxel=None, min_range=None, max_range=None, strides=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_sequence(
    py: Python<'_>,
    reference_frames: &Bound<'_, PyAny>,
    target_frames: &Bound<'_, PyAny>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    voxel: Option<f64>,
    min_range: Option<f64>,
    max_range: Option<f64>,
    strides: Option<Vec<usize>>,
) -> PyResult<SequenceResult> {
    let _ = seed; // validated by `arrays::seed`; no stage draws random numbers
    let reference = frames_arg(reference_frames, "reference_frames")?;
    let target = frames_arg(target_frames, "target_frames")?;
    let d = SequenceOptions::default();
    let options = SequenceOptions {
        odometry: odometry_options(voxel, min_range, max_range),
        strides: strides.unwrap_or(d.strides.clone()),
        ..d
    };
    if options.strides.is_empty() || options.strides.contains(&0) {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "strides must be a non-empty list of positive frame counts, got {:?}",
            options.strides
        )));
    }
    let inner = run(py, || rs_calibrate_sequence(&reference, &target, &options))?;
    Ok(SequenceResult { inner })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<SequenceResult>()?;
    m.add_function(wrap_pyfunction!(odometry, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_sequence, m)?)?;
    Ok(())
}
