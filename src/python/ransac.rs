//! Python wrappers of RANSAC: `ransac_plane`, `ransac_line`, `extract_planes`, the `Plane` and
//! `Line` result classes, and the raw scoring kernels (for parity tests and throughput figures).

use nalgebra::{Point3, Vector3, Vector4};
use numpy::ndarray::Ix1;
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::arrays::{self, to_numpy};
use super::defaults::table;
use super::run;
use crate::geometry::{Line, Plane};
use crate::ransac::consensus::{score_models, Score};
use crate::ransac::line::{ransac_line as rs_ransac_line, LineEstimator};
use crate::ransac::plane::{extract_planes as rs_extract_planes, ransac_plane as rs_ransac_plane};
use crate::ransac::plane::{ExtractOptions, PlaneEstimator};
use crate::ransac::{Cloud, RansacOptions};

fn indices_to_numpy<'py>(py: Python<'py>, indices: &[usize]) -> Bound<'py, PyArray1<i64>> {
    PyArray1::from_iter(py, indices.iter().map(|&i| i as i64))
}

/// A plane `normal . p + offset = 0` found in a point cloud, with its inliers.
#[pyclass(frozen, module = "lidarcal", name = "Plane")]
pub(crate) struct PyPlane {
    pub(crate) plane: Plane,
    pub(crate) inliers: Vec<usize>,
    pub(crate) rms: f64,
    pub(crate) hypotheses: usize,
}

#[pymethods]
impl PyPlane {
    /// (3,) unit normal, pointing toward the sensor (the origin of the cloud's frame).
    #[getter]
    fn normal<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(3), self.plane.normal.as_slice().to_vec())
    }
    /// Offset d of normal . p + d = 0 (the distance of the sensor to the plane).
    #[getter]
    fn offset(&self) -> f64 {
        self.plane.offset
    }
    /// (4,) coefficients [nx, ny, nz, d].
    #[getter]
    fn coefficients<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(4), self.plane.coefficients().as_slice().to_vec())
    }
    /// int64 indices of the inlier points in the input, ascending.
    #[getter]
    fn inliers<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        indices_to_numpy(py, &self.inliers)
    }
    /// Root-mean-square distance of the inliers to the plane.
    #[getter]
    fn rms(&self) -> f64 {
        self.rms
    }
    /// Hypotheses drawn by the RANSAC run that found the plane.
    #[getter]
    fn hypotheses(&self) -> usize {
        self.hypotheses
    }
    fn __repr__(&self) -> String {
        let n = self.plane.normal;
        format!(
            "Plane(normal=[{:.6}, {:.6}, {:.6}], offset={:.6}, inliers={}, rms={:.4})",
            n.x,
            n.y,
            n.z,
            self.plane.offset,
            self.inliers.len(),
            self.rms
        )
    }
}

/// A 3D line through `point` along the unit `direction`, with its inliers.
#[pyclass(frozen, module = "lidarcal", name = "Line")]
pub(crate) struct PyLine {
    line: Line,
    inliers: Vec<usize>,
    rms: f64,
    hypotheses: usize,
}

#[pymethods]
impl PyLine {
    /// (3,) a point on the line (the mean of the inliers).
    #[getter]
    fn point<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(3), self.line.point.coords.as_slice().to_vec())
    }
    /// (3,) unit direction (its sign is arbitrary).
    #[getter]
    fn direction<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(3), self.line.direction.as_slice().to_vec())
    }
    /// int64 indices of the inlier points in the input, ascending.
    #[getter]
    fn inliers<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        indices_to_numpy(py, &self.inliers)
    }
    /// Root-mean-square distance of the inliers to the line.
    #[getter]
    fn rms(&self) -> f64 {
        self.rms
    }
    /// Hypotheses drawn by RANSAC.
    #[getter]
    fn hypotheses(&self) -> usize {
        self.hypotheses
    }
    fn __repr__(&self) -> String {
        let (p, d) = (self.line.point, self.line.direction);
        format!(
            "Line(point=[{:.4}, {:.4}, {:.4}], direction=[{:.6}, {:.6}, {:.6}], inliers={}, rms={:.4})",
            p.x,
            p.y,
            p.z,
            d.x,
            d.y,
            d.z,
            self.inliers.len(),
            self.rms
        )
    }
}

/// RANSAC options with `threshold`; `confidence` and `max_iterations` left None take the Rust
/// defaults of `RansacOptions::new`.
fn options(
    threshold: f64,
    confidence: Option<f64>,
    max_iterations: Option<usize>,
    seed: u64,
) -> RansacOptions {
    let d = RansacOptions::new(threshold);
    RansacOptions {
        confidence: confidence.unwrap_or(d.confidence),
        max_iterations: max_iterations.unwrap_or(d.max_iterations),
        seed,
        ..d
    }
}

/// The plane with the most support among `points`, by RANSAC with MSAC scoring, local
/// optimisation and a final least-squares refit on its inliers.
///
/// points: (N, 3) or (N, 4) array (float32 or float64), N >= 3.
/// distance_threshold: inlier distance in metres (> 0).
/// confidence: stop once an all-inlier sample was drawn with this probability.
/// max_iterations: cap on hypotheses. seed: the sampler's seed (same seed, same answer, any
/// thread count).
/// Left None, confidence and max_iterations take the Rust `RansacOptions::new` defaults:
/// confidence=0.999, max_iterations=10000.
#[pyfunction]
#[pyo3(signature = (points, distance_threshold, *, confidence=None, max_iterations=None, seed=0))]
fn ransac_plane(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    distance_threshold: f64,
    confidence: Option<f64>,
    max_iterations: Option<usize>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<PyPlane> {
    let points = arrays::points(points, "points")?;
    let opts = options(distance_threshold, confidence, max_iterations, seed);
    let r = run(py, move || rs_ransac_plane(&points, &opts))?;
    Ok(PyPlane {
        plane: r.model,
        inliers: r.inliers,
        rms: r.rms,
        hypotheses: r.hypotheses,
    })
}

/// The line with the most support among `points`, by RANSAC (see `ransac_plane`). N >= 2.
/// Left None, confidence and max_iterations take the Rust `RansacOptions::new` defaults:
/// confidence=0.999, max_iterations=10000.
#[pyfunction]
#[pyo3(signature = (points, distance_threshold, *, confidence=None, max_iterations=None, seed=0))]
fn ransac_line(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    distance_threshold: f64,
    confidence: Option<f64>,
    max_iterations: Option<usize>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<PyLine> {
    let points = arrays::points(points, "points")?;
    let opts = options(distance_threshold, confidence, max_iterations, seed);
    let r = run(py, move || rs_ransac_line(&points, &opts))?;
    Ok(PyLine {
        line: r.model,
        inliers: r.inliers,
        rms: r.rms,
        hypotheses: r.hypotheses,
    })
}

/// `count` planes, largest first: sequential RANSAC (inliers removed after each plane), then a
/// joint refinement that gives every point to the only plane within the threshold (points near
/// two planes, at the intersection lines, are dropped) and refits.
///
/// min_angle_deg: if given, a plane within this angle of an accepted one, or of the span of two
/// accepted normals, is discarded (its points leave the pool) and the search goes on, so the
/// planes found are linearly independent (three walls without a floor are not).
/// Raises CalibrationError when fewer than `count` planes with at least `min_inliers` inliers exist.
/// Left None, min_inliers and refinement_rounds take the Rust `ExtractOptions::new` defaults and
/// confidence and max_iterations those of `RansacOptions::new`: min_inliers=50,
/// refinement_rounds=3, confidence=0.999, max_iterations=10000.
#[pyfunction]
#[pyo3(signature = (points, count=3, distance_threshold=0.05, *, min_inliers=None, refinement_rounds=None, min_angle_deg=None, confidence=None, max_iterations=None, seed=0))]
#[allow(clippy::too_many_arguments)]
fn extract_planes(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    count: usize,
    distance_threshold: f64,
    min_inliers: Option<usize>,
    refinement_rounds: Option<usize>,
    min_angle_deg: Option<f64>,
    confidence: Option<f64>,
    max_iterations: Option<usize>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<Vec<PyPlane>> {
    let points = arrays::points(points, "points")?;
    let d = ExtractOptions::new(count, distance_threshold);
    let opts = ExtractOptions {
        count,
        min_inliers: min_inliers.unwrap_or(d.min_inliers),
        refinement_rounds: refinement_rounds.unwrap_or(d.refinement_rounds),
        ransac: options(distance_threshold, confidence, max_iterations, seed),
        min_angle_between: min_angle_deg.map(f64::to_radians),
    };
    if let Some(a) = min_angle_deg {
        if !(a.is_finite() && a > 0.0 && a < 90.0) {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "min_angle_deg must be in (0, 90), got {a}"
            )));
        }
    }
    let found = run(py, move || rs_extract_planes(&points, &opts))?;
    Ok(found
        .into_iter()
        .map(|p| PyPlane {
            plane: p.plane,
            inliers: p.inliers,
            rms: p.rms,
            hypotheses: p.hypotheses,
        })
        .collect())
}

fn scores_to_numpy<'py>(
    py: Python<'py>,
    scores: &[Score],
) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<i64>>) {
    (
        PyArray1::from_iter(py, scores.iter().map(|s| s.cost)),
        PyArray1::from_iter(py, scores.iter().map(|s| s.inliers as i64)),
    )
}

/// MSAC costs sum(min(d^2, t^2)) and inlier counts (d < t) of the given planes (K, 4), as the
/// RANSAC search computes them (f32, centred on the cloud's bounding-box midpoint).
#[pyfunction]
#[allow(clippy::type_complexity)]
fn score_planes<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>,
    distance_threshold: f64,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<i64>>)> {
    let points = arrays::points(points, "points")?;
    let planes = arrays::rows(planes, "planes", 4)?
        .iter()
        .map(|c| Plane::from_coefficients(&Vector4::from_column_slice(c)))
        .collect::<crate::Result<Vec<_>>>()?;
    let opts = RansacOptions::new(distance_threshold);
    opts.validate()?;
    let scores = run(py, move || {
        let cloud = Cloud::new(&points)?;
        Ok(score_models(
            &PlaneEstimator,
            &cloud,
            &planes,
            distance_threshold,
            true,
        ))
    })?;
    Ok(scores_to_numpy(py, &scores))
}

/// MSAC costs and inlier counts of the given lines (K, 6) [px, py, pz, dx, dy, dz].
#[pyfunction]
#[allow(clippy::type_complexity)]
fn score_lines<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    lines: &Bound<'py, PyAny>,
    distance_threshold: f64,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<i64>>)> {
    let points = arrays::points(points, "points")?;
    let lines = arrays::rows(lines, "lines", 6)?
        .iter()
        .map(|r| {
            Line::new(
                Point3::new(r[0], r[1], r[2]),
                Vector3::new(r[3], r[4], r[5]),
            )
        })
        .collect::<crate::Result<Vec<_>>>()?;
    RansacOptions::new(distance_threshold).validate()?;
    let scores = run(py, move || {
        let cloud = Cloud::new(&points)?;
        Ok(score_models(
            &LineEstimator,
            &cloud,
            &lines,
            distance_threshold,
            true,
        ))
    })?;
    Ok(scores_to_numpy(py, &scores))
}

/// The Rust defaults behind this file's keywords (see `super::defaults`). The threshold and the
/// count have no Rust default (`extract_planes`' 3 planes at 0.05 m are this module's own); the
/// values read here do not depend on them.
pub(crate) fn defaults(out: &Bound<'_, PyDict>) -> PyResult<()> {
    let e = ExtractOptions::new(3, 0.05);
    let ransac = |name| {
        let t = table(out, name)?;
        t.set_item("confidence", e.ransac.confidence)?;
        t.set_item("max_iterations", e.ransac.max_iterations)?;
        t.set_item("seed", e.ransac.seed)?;
        PyResult::Ok(t)
    };
    ransac("ransac_plane")?;
    ransac("ransac_line")?;
    let t = ransac("extract_planes")?;
    t.set_item("min_inliers", e.min_inliers)?;
    t.set_item("refinement_rounds", e.refinement_rounds)?;
    Ok(())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPlane>()?;
    m.add_class::<PyLine>()?;
    m.add_function(wrap_pyfunction!(ransac_plane, m)?)?;
    m.add_function(wrap_pyfunction!(ransac_line, m)?)?;
    m.add_function(wrap_pyfunction!(extract_planes, m)?)?;
    m.add_function(wrap_pyfunction!(score_planes, m)?)?;
    m.add_function(wrap_pyfunction!(score_lines, m)?)?;
    Ok(())
}
