//! Python wrappers of the numerical kernels: Kabsch, SO(3)/SE(3) exp and log, the LM refinement
//! over point-to-plane and point-to-line residuals, and the residuals themselves.

use nalgebra::{Isometry3, Matrix6, Point3, Vector3, Vector4};
use numpy::ndarray::{Ix1, Ix2, Ix3};
use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PySequence};

use super::arrays::{self, row_major, to_numpy};
use super::defaults::table;
use super::run;
use crate::geometry::{self, Line, Plane};
use crate::lm::{self, LmOptions, LmReport, Loss};
use crate::residuals::{Frame, LineGroup, PlaneGroup, PointToLine, PointToPlane};

/// The rotation R minimising sum_i w_i |R b_i - a_i|^2, so that R @ b[i] ~ a[i].
///
/// a, b: (N, 3) arrays of corresponding vectors (float32 or float64), N >= 2.
/// weights: optional (N,) non-negative weights.
/// Raises ValueError for malformed input or vectors that do not determine a rotation (fewer than
/// two directions, i.e. second singular value below 1e-6 of the first).
#[pyfunction]
#[pyo3(signature = (a, b, weights=None))]
fn kabsch<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
    weights: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let a = arrays::vectors(a, "a")?;
    let b = arrays::vectors(b, "b")?;
    let w = weights
        .map(|w| arrays::vector(w, "weights", None))
        .transpose()?;
    let solution = run(py, || crate::kabsch::kabsch(&a, &b, w.as_deref()))?;
    to_numpy(py, Ix2(3, 3), row_major(solution.rotation.matrix()))
}

/// so3_exp(phi) -> (3, 3) rotation matrix of the rotation vector phi (axis * angle).
#[pyfunction]
fn so3_exp<'py>(py: Python<'py>, phi: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let phi = arrays::vector3(phi, "phi")?;
    let m = run(py, move || {
        finite_result("phi", phi.norm(), geometry::so3_exp(&phi).matrix())
    })?;
    to_numpy(py, Ix2(3, 3), m)
}

/// so3_log(rotation) -> (3,) rotation vector with norm in [0, pi].
///
/// Raises ValueError if the matrix is not a rotation (orthonormal within 1e-4, determinant +1).
#[pyfunction]
fn so3_log<'py>(
    py: Python<'py>,
    rotation: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let m = arrays::matrix3(rotation, "rotation")?;
    let phi = run(py, move || {
        geometry::rotation_from_matrix(&m).map(|r| geometry::so3_log(&r).as_slice().to_vec())
    })?;
    to_numpy(py, Ix1(3), phi)
}

/// se3_exp(xi) -> (4, 4) transform of the twist xi = [rho, phi] (translation part first).
#[pyfunction]
fn se3_exp<'py>(py: Python<'py>, xi: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let xi = arrays::vector6(xi, "xi")?;
    let m = run(py, move || {
        finite_result("xi", xi.norm(), &geometry::se3_exp(&xi).to_homogeneous())
    })?;
    to_numpy(py, Ix2(4, 4), m)
}

/// se3_log(transform) -> (6,) twist [rho, phi] with |phi| in [0, pi].
#[pyfunction]
fn se3_log<'py>(
    py: Python<'py>,
    transform: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let pose = transform_arg(transform, "transform")?;
    let xi = run(py, move || {
        finite_result(
            "transform",
            pose.translation.vector.norm(),
            &geometry::se3_log(&pose),
        )
        .map(|v| v.as_slice().to_vec())
    })?;
    to_numpy(py, Ix1(6), xi)
}

/// The row-major values of `m`, or a `ValueError` naming `what` when they are not finite: the
/// exponential of a vector of norm beyond ~1e154 overflows (its square is infinite), and so can
/// the logarithm of a transform with a translation near `f64::MAX`.
fn finite_result<R: nalgebra::Dim, C: nalgebra::Dim, S: nalgebra::RawStorage<f64, R, C>>(
    what: &str,
    norm: f64,
    m: &nalgebra::Matrix<f64, R, C, S>,
) -> crate::Result<Vec<f64>> {
    let values = row_major(m);
    if values.iter().all(|v| v.is_finite()) {
        Ok(values)
    } else {
        Err(crate::Error::InvalidInput(format!(
            "{what} (norm {norm:e}) is too large: the result is not finite"
        )))
    }
}

fn transform_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Isometry3<f64>> {
    geometry::isometry_from_matrix(&arrays::matrix4(obj, name)?)
        .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
}

fn initial_arg(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Isometry3<f64>> {
    obj.map_or(Ok(Isometry3::identity()), |t| {
        transform_arg(t, "initial_transform")
    })
}

fn frame_arg(name: &str) -> PyResult<Frame> {
    match name {
        "target" => Ok(Frame::Target),
        "reference" => Ok(Frame::Reference),
        other => Err(PyValueError::new_err(format!(
            "frame must be 'target' or 'reference', got {other:?}"
        ))),
    }
}

/// A `loss` name and its scale; None is the Rust `Loss::default()`.
fn loss_arg(name: Option<&str>, scale: f64) -> PyResult<Loss> {
    let loss = match name {
        None => Loss::default(),
        Some("squared" | "linear") => Loss::Squared,
        Some("huber") => Loss::Huber { delta: scale },
        Some("cauchy") => Loss::Cauchy { scale },
        Some(other) => {
            return Err(PyValueError::new_err(format!(
                "loss must be 'squared', 'huber' or 'cauchy', got {other:?}"
            )))
        }
    };
    loss.validate()?;
    Ok(loss)
}

/// Per-group point arrays and frames, checked against the number of features.
fn groups_arg(
    points: &Bound<'_, PyAny>,
    frames: Option<Vec<String>>,
    count: usize,
) -> PyResult<Vec<(Vec<Point3<f64>>, Frame)>> {
    let seq = points.cast::<PySequence>().map_err(|_| {
        PyValueError::new_err("points must be a sequence of (N, 3) arrays, one per feature")
    })?;
    let n = seq.len()?;
    if n != count {
        return Err(PyValueError::new_err(format!(
            "points must hold one array per feature: {count} features, {n} arrays"
        )));
    }
    let frames = frames.unwrap_or_else(|| vec!["target".into(); count]);
    if frames.len() != count {
        return Err(PyValueError::new_err(format!(
            "frames must hold one entry per feature: {count} features, {} frames",
            frames.len()
        )));
    }
    (0..n)
        .map(|i| {
            let pts = arrays::points(&seq.get_item(i)?, &format!("points[{i}]"))?;
            Ok((pts, frame_arg(&frames[i])?))
        })
        .collect()
}

/// The result of a refinement: the transform and the solver's report.
#[pyclass(frozen, module = "lidarcal", name = "RefineResult")]
pub(crate) struct RefineResult {
    pose: Isometry3<f64>,
    report: LmReport,
}

#[pymethods]
impl RefineResult {
    /// (4, 4) reference_from_target transform.
    #[getter]
    fn transform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        to_numpy(py, Ix2(4, 4), row_major(&self.pose.to_homogeneous()))
    }
    /// Cost 1/2 sum rho(r^2) at the initial transform.
    #[getter]
    fn initial_cost(&self) -> f64 {
        self.report.initial_cost
    }
    /// Cost 1/2 sum rho(r^2) at the solution.
    #[getter]
    fn cost(&self) -> f64 {
        self.report.final_cost
    }
    /// Linear solves performed.
    #[getter]
    fn iterations(&self) -> usize {
        self.report.iterations
    }
    /// Cost evaluations.
    #[getter]
    fn evaluations(&self) -> usize {
        self.report.evaluations
    }
    /// Why the solver stopped.
    #[getter]
    fn termination(&self) -> &'static str {
        self.report.termination.as_str()
    }
    /// False only when the iteration cap was hit.
    #[getter]
    fn converged(&self) -> bool {
        self.report.converged()
    }
    /// Number of scalar residuals.
    #[getter]
    fn residual_count(&self) -> usize {
        self.report.residual_count
    }
    /// (6, 6) J^T W J at the solution, tangent order [rho, phi] (left perturbation).
    #[getter]
    fn hessian<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        to_numpy(py, Ix2(6, 6), row_major(&self.report.hessian))
    }
    /// (6, 6) covariance of [rho, phi], or None when it is not determined.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.report
            .covariance()
            .map(|c: Matrix6<f64>| to_numpy(py, Ix2(6, 6), row_major(&c)))
            .transpose()
    }
    fn __repr__(&self) -> String {
        let t = self.pose.translation.vector;
        let angle = self.pose.rotation.angle().to_degrees();
        format!(
            "RefineResult(converged={}, termination='{}', iterations={}, cost={:.6e}, \
             rotation_deg={angle:.4}, translation=[{:.4}, {:.4}, {:.4}])",
            if self.report.converged() {
                "True"
            } else {
                "False"
            },
            self.report.termination.as_str(),
            self.report.iterations,
            self.report.final_cost,
            t.x,
            t.y,
            t.z
        )
    }
}

/// The name `loss_arg` (and `calibrate_planes`) reads a loss by.
pub(super) fn loss_name(loss: Loss) -> &'static str {
    match loss {
        Loss::Squared => "squared",
        Loss::Huber { .. } => "huber",
        Loss::Cauchy { .. } => "cauchy",
    }
}

/// The LM options of the refine functions: `LmOptions::default()` with their `max_iterations`.
fn lm_options(max_iterations: Option<usize>) -> LmOptions {
    let d = LmOptions::default();
    LmOptions {
        max_iterations: max_iterations.unwrap_or(d.max_iterations),
        ..d
    }
}

/// Levenberg–Marquardt refinement of reference_from_target from point-to-plane residuals.
///
/// planes: (K, 4) rows [nx, ny, nz, d] with n . p + d = 0.
/// points: K arrays (N_k, 3) or (N_k, 4); points[k] should lie on planes[k].
/// frames: K strings; "target" (default) means points[k] are in the target frame and planes[k] in
///     the reference frame, "reference" the opposite. Mixing both gives the symmetric cost.
/// loss: "squared", "huber" or "cauchy"; loss_scale is the robust scale in metres.
/// Left None, loss and max_iterations take the Rust `Loss::default()` and `LmOptions::default()`:
/// loss='squared', max_iterations=100.
#[pyfunction]
#[pyo3(signature = (planes, points, initial_transform=None, *, frames=None, loss=None, loss_scale=0.1, max_iterations=None))]
#[allow(clippy::too_many_arguments)]
fn refine_point_to_plane(
    py: Python<'_>,
    planes: &Bound<'_, PyAny>,
    points: &Bound<'_, PyAny>,
    initial_transform: Option<&Bound<'_, PyAny>>,
    frames: Option<Vec<String>>,
    loss: Option<&str>,
    loss_scale: f64,
    max_iterations: Option<usize>,
) -> PyResult<RefineResult> {
    let planes = arrays::rows(planes, "planes", 4)?
        .iter()
        .map(|c| Plane::from_coefficients(&Vector4::from_column_slice(c)))
        .collect::<crate::Result<Vec<_>>>()?;
    let options = RefineArgs::parse(
        points,
        planes.len(),
        initial_transform,
        frames,
        loss,
        loss_scale,
    )?;
    refine(py, options, planes, max_iterations, |groups, loss| {
        let groups = groups
            .into_iter()
            .map(|(plane, points, frame)| PlaneGroup {
                plane,
                points,
                frame,
            })
            .collect();
        PointToPlane::new(groups, loss)
    })
}

/// The arguments the refine functions share, checked.
struct RefineArgs {
    groups: Vec<(Vec<Point3<f64>>, Frame)>,
    initial: Isometry3<f64>,
    loss: Loss,
}

impl RefineArgs {
    fn parse(
        points: &Bound<'_, PyAny>,
        count: usize,
        initial_transform: Option<&Bound<'_, PyAny>>,
        frames: Option<Vec<String>>,
        loss: Option<&str>,
        loss_scale: f64,
    ) -> PyResult<Self> {
        Ok(RefineArgs {
            groups: groups_arg(points, frames, count)?,
            initial: initial_arg(initial_transform)?,
            loss: loss_arg(loss, loss_scale)?,
        })
    }
}

/// Pairs each feature with its points and frame, builds the problem and solves it with the GIL
/// released.
fn refine<T, P, B>(
    py: Python<'_>,
    args: RefineArgs,
    features: Vec<T>,
    max_iterations: Option<usize>,
    build: B,
) -> PyResult<RefineResult>
where
    T: Send,
    P: lm::LeastSquaresProblem,
    B: FnOnce(Vec<(T, Vec<Point3<f64>>, Frame)>, Loss) -> crate::Result<P> + Send,
{
    let RefineArgs {
        groups,
        initial,
        loss,
    } = args;
    let groups: Vec<(T, Vec<Point3<f64>>, Frame)> = features
        .into_iter()
        .zip(groups)
        .map(|(feature, (points, frame))| (feature, points, frame))
        .collect();
    let solution = run(py, move || {
        let problem = build(groups, loss)?;
        lm::solve(&problem, &initial, &lm_options(max_iterations))
    })?;
    Ok(RefineResult {
        pose: solution.pose,
        report: solution.report,
    })
}

/// A line from a row `[px, py, pz, dx, dy, dz]`.
pub(crate) fn line_from_row(row: &[f64]) -> crate::Result<Line> {
    Line::new(
        Point3::new(row[0], row[1], row[2]),
        Vector3::new(row[3], row[4], row[5]),
    )
}

/// Levenberg–Marquardt refinement of reference_from_target from point-to-line distances.
///
/// lines: (K, 6) rows [px, py, pz, dx, dy, dz] (a point and a direction).
/// points, frames, loss, max_iterations: as in refine_point_to_plane (left None: loss='squared',
/// max_iterations=100, the Rust defaults).
#[pyfunction]
#[pyo3(signature = (lines, points, initial_transform=None, *, frames=None, loss=None, loss_scale=0.1, max_iterations=None))]
#[allow(clippy::too_many_arguments)]
fn refine_point_to_line(
    py: Python<'_>,
    lines: &Bound<'_, PyAny>,
    points: &Bound<'_, PyAny>,
    initial_transform: Option<&Bound<'_, PyAny>>,
    frames: Option<Vec<String>>,
    loss: Option<&str>,
    loss_scale: f64,
    max_iterations: Option<usize>,
) -> PyResult<RefineResult> {
    let lines = arrays::rows(lines, "lines", 6)?
        .iter()
        .map(|r| line_from_row(r))
        .collect::<crate::Result<Vec<_>>>()?;
    let options = RefineArgs::parse(
        points,
        lines.len(),
        initial_transform,
        frames,
        loss,
        loss_scale,
    )?;
    refine(py, options, lines, max_iterations, |groups, loss| {
        let groups = groups
            .into_iter()
            .map(|(line, points, frame)| LineGroup {
                line,
                points,
                frame,
            })
            .collect();
        PointToLine::new(groups, loss)
    })
}

/// point_to_plane_residuals(points, plane, transform, frame="target") -> (r (N,), J (N, 6))
///
/// Residuals and analytic Jacobian rows (left perturbation, [rho, phi]) of one plane group.
#[pyfunction]
#[pyo3(signature = (points, plane, transform, frame="target"))]
#[allow(clippy::type_complexity)]
fn point_to_plane_residuals<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    plane: &Bound<'py, PyAny>,
    transform: &Bound<'py, PyAny>,
    frame: &str,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>)> {
    let points = arrays::points(points, "points")?;
    let plane = Plane::from_coefficients(&Vector4::from_column_slice(&arrays::vector(
        plane,
        "plane",
        Some(4),
    )?))?;
    let pose = transform_arg(transform, "transform")?;
    let frame = frame_arg(frame)?;
    let n = points.len();
    let rows = run(py, move || {
        Ok(PointToPlane::new(
            vec![PlaneGroup {
                plane,
                points,
                frame,
            }],
            Loss::Squared,
        )?
        .residuals(&pose))
    })?;
    let r = rows.iter().map(|(r, _)| *r).collect();
    let j = rows.iter().flat_map(|(_, j)| j.iter().copied()).collect();
    Ok((to_numpy(py, Ix1(n), r)?, to_numpy(py, Ix2(n, 6), j)?))
}

/// point_to_line_residuals(points, line, transform, frame="target") -> (r (N, 2), J (N, 2, 6))
///
/// The two perpendicular offset components and their Jacobian rows for one line group.
#[pyfunction]
#[pyo3(signature = (points, line, transform, frame="target"))]
#[allow(clippy::type_complexity)]
fn point_to_line_residuals<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    line: &Bound<'py, PyAny>,
    transform: &Bound<'py, PyAny>,
    frame: &str,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray3<f64>>)> {
    let points = arrays::points(points, "points")?;
    let line = line_from_row(&arrays::vector(line, "line", Some(6))?)?;
    let pose = transform_arg(transform, "transform")?;
    let frame = frame_arg(frame)?;
    let n = points.len();
    let rows = run(py, move || {
        Ok(PointToLine::new(
            vec![LineGroup {
                line,
                points,
                frame,
            }],
            Loss::Squared,
        )?
        .residuals(&pose))
    })?;
    let r = rows.iter().flat_map(|(r, _)| r.iter().copied()).collect();
    let j = rows
        .iter()
        .flat_map(|(_, j)| j.iter().flat_map(|row| row.iter().copied()))
        .collect();
    Ok((to_numpy(py, Ix2(n, 2), r)?, to_numpy(py, Ix3(n, 2, 6), j)?))
}

/// The Rust defaults behind this file's keywords (see `super::defaults`).
pub(crate) fn defaults(out: &Bound<'_, PyDict>) -> PyResult<()> {
    for name in ["refine_point_to_plane", "refine_point_to_line"] {
        let t = table(out, name)?;
        t.set_item("loss", loss_name(Loss::default()))?;
        t.set_item("max_iterations", LmOptions::default().max_iterations)?;
    }
    Ok(())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RefineResult>()?;
    m.add_function(wrap_pyfunction!(kabsch, m)?)?;
    m.add_function(wrap_pyfunction!(so3_exp, m)?)?;
    m.add_function(wrap_pyfunction!(so3_log, m)?)?;
    m.add_function(wrap_pyfunction!(se3_exp, m)?)?;
    m.add_function(wrap_pyfunction!(se3_log, m)?)?;
    m.add_function(wrap_pyfunction!(refine_point_to_plane, m)?)?;
    m.add_function(wrap_pyfunction!(refine_point_to_line, m)?)?;
    m.add_function(wrap_pyfunction!(point_to_plane_residuals, m)?)?;
    m.add_function(wrap_pyfunction!(point_to_line_residuals, m)?)?;
    Ok(())
}
