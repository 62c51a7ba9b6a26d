//! NumPy array arguments to Rust values, with errors that name the argument and the problem.

use nalgebra::{Matrix3, Matrix4, Point3, Vector3, Vector6};
use numpy::ndarray::{Array, Dimension};
use numpy::{IntoPyArray, PyArray, PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A dense float64 array copied out of a Python object, in C order.
pub(crate) struct Dense {
    pub data: Vec<f64>,
    pub shape: Vec<usize>,
}

fn copy_out<'py, T>(array: &Bound<'py, PyArrayDyn<T>>, cast: impl Fn(T) -> f64) -> Dense
where
    T: numpy::Element + Copy,
{
    let readonly = array.readonly();
    let view = readonly.as_array();
    Dense {
        data: view.iter().map(|&x| cast(x)).collect(),
        shape: view.shape().to_vec(),
    }
}

/// Reads any array-like of real numbers. float64 and float32 arrays are read directly; integer
/// arrays and nested sequences go through `numpy.asarray`; anything else is a `ValueError`.
pub(crate) fn dense(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Dense> {
    if let Ok(a) = obj.cast::<PyArrayDyn<f64>>() {
        return Ok(copy_out(a, |x| x));
    }
    if let Ok(a) = obj.cast::<PyArrayDyn<f32>>() {
        return Ok(copy_out(a, f64::from));
    }
    let numpy = obj.py().import("numpy")?;
    let array = numpy
        .call_method1("asarray", (obj,))
        .map_err(|e| PyValueError::new_err(format!("{name} could not be read as an array: {e}")))?;
    let dtype = array.getattr("dtype")?;
    let kind: String = dtype.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "f" | "i" | "u") {
        return Err(PyValueError::new_err(format!(
            "{name} must hold real numbers (float32 or float64), got dtype {}",
            dtype.str()?
        )));
    }
    let converted = array.call_method1("astype", ("float64",))?;
    let a = converted.cast::<PyArrayDyn<f64>>()?;
    Ok(copy_out(a, |x| x))
}

fn check_finite(d: &Dense, name: &str) -> PyResult<()> {
    let bad = d.data.iter().filter(|x| !x.is_finite()).count();
    if bad == 0 {
        return Ok(());
    }
    let width = d.shape.iter().skip(1).product::<usize>().max(1);
    let first = d.data.iter().position(|x| !x.is_finite()).unwrap_or(0) / width;
    Err(PyValueError::new_err(format!(
        "{name} contains {bad} non-finite value(s) (NaN or inf); the first is in row {first}"
    )))
}

fn shape_str(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(|s| s.to_string()).collect();
    format!("({})", parts.join(", "))
}

/// An `(N, 3)` or `(N, 4)` array of points (a fourth column, intensity, is ignored here).
pub(crate) fn points(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Point3<f64>>> {
    let d = dense(obj, name)?;
    if d.shape.len() != 2 || !(d.shape[1] == 3 || d.shape[1] == 4) {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (N, 3) or (N, 4), got {}",
            shape_str(&d.shape)
        )));
    }
    check_finite(&d, name)?;
    let cols = d.shape[1];
    Ok(d.data
        .chunks_exact(cols)
        .map(|r| Point3::new(r[0], r[1], r[2]))
        .collect())
}

/// An `(N, 4)` array `[x, y, z, intensity]`: the points and their intensities. NaN anywhere is
/// a `ValueError` naming the column, the count and the first row.
pub(crate) fn points_with_intensity(
    obj: &Bound<'_, PyAny>,
    name: &str,
) -> PyResult<(Vec<Point3<f64>>, Vec<f64>)> {
    let d = dense(obj, name)?;
    if d.shape.len() != 2 || d.shape[1] != 4 {
        return Err(PyValueError::new_err(format!(
            "calibrate_poles needs an (N, 4) array with intensity in the fourth column; \
             {name} has shape {}",
            shape_str(&d.shape)
        )));
    }
    let bad_rows = |col: std::ops::Range<usize>| {
        let rows: Vec<usize> = d
            .data
            .chunks_exact(4)
            .enumerate()
            .filter(|(_, r)| r[col.clone()].iter().any(|x| !x.is_finite()))
            .map(|(i, _)| i)
            .collect();
        rows
    };
    let bad = bad_rows(0..3);
    if let Some(first) = bad.first() {
        return Err(PyValueError::new_err(format!(
            "{name} has {} row(s) with NaN or infinite coordinates; the first is row {first}",
            bad.len()
        )));
    }
    let bad = bad_rows(3..4);
    if let Some(first) = bad.first() {
        return Err(PyValueError::new_err(format!(
            "{name} has {} NaN or infinite intensity value(s); the first is in row {first}",
            bad.len()
        )));
    }
    Ok(d.data
        .chunks_exact(4)
        .map(|r| (Point3::new(r[0], r[1], r[2]), r[3]))
        .unzip())
}

/// An `(N, 3)` array of vectors.
pub(crate) fn vectors(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Vector3<f64>>> {
    let d = dense(obj, name)?;
    if d.shape.len() != 2 || d.shape[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (N, 3), got {}",
            shape_str(&d.shape)
        )));
    }
    check_finite(&d, name)?;
    Ok(d.data
        .chunks_exact(3)
        .map(|r| Vector3::new(r[0], r[1], r[2]))
        .collect())
}

/// A 1-D array of `len` values (any length when `len` is `None`).
pub(crate) fn vector(obj: &Bound<'_, PyAny>, name: &str, len: Option<usize>) -> PyResult<Vec<f64>> {
    let d = dense(obj, name)?;
    let ok = d.shape.len() == 1 && len.is_none_or(|n| d.shape[0] == n);
    if !ok {
        let expected = len.map_or("(N,)".to_string(), |n| format!("({n},)"));
        return Err(PyValueError::new_err(format!(
            "{name} must have shape {expected}, got {}",
            shape_str(&d.shape)
        )));
    }
    check_finite(&d, name)?;
    Ok(d.data)
}

/// A 2-D array of exactly `rows x cols` values, row-major.
pub(crate) fn matrix(
    obj: &Bound<'_, PyAny>,
    name: &str,
    rows: usize,
    cols: usize,
) -> PyResult<Vec<f64>> {
    let d = dense(obj, name)?;
    if d.shape != [rows, cols] {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape ({rows}, {cols}), got {}",
            shape_str(&d.shape)
        )));
    }
    check_finite(&d, name)?;
    Ok(d.data)
}

/// An `(K, cols)` array, row-major, with K >= 1.
pub(crate) fn rows(obj: &Bound<'_, PyAny>, name: &str, cols: usize) -> PyResult<Vec<Vec<f64>>> {
    let d = dense(obj, name)?;
    if d.shape.len() != 2 || d.shape[1] != cols || d.shape[0] == 0 {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (K, {cols}) with K >= 1, got {}",
            shape_str(&d.shape)
        )));
    }
    check_finite(&d, name)?;
    Ok(d.data.chunks_exact(cols).map(|r| r.to_vec()).collect())
}

pub(crate) fn matrix3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Matrix3<f64>> {
    Ok(Matrix3::from_row_slice(&matrix(obj, name, 3, 3)?))
}

pub(crate) fn matrix4(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Matrix4<f64>> {
    Ok(Matrix4::from_row_slice(&matrix(obj, name, 4, 4)?))
}

pub(crate) fn vector3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vector3<f64>> {
    Ok(Vector3::from_column_slice(&vector(obj, name, Some(3))?))
}

pub(crate) fn vector6(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vector6<f64>> {
    Ok(Vector6::from_column_slice(&vector(obj, name, Some(6))?))
}

/// A `seed` argument: any non-negative Python integer below 2**64. Without this, PyO3's own
/// conversion raises an `OverflowError` that does not name the argument.
pub(crate) fn seed(obj: &Bound<'_, PyAny>) -> PyResult<u64> {
    let bad = || {
        PyValueError::new_err(format!(
            "seed must be an integer in [0, 2**64), got {}",
            obj.repr()
                .map(|r| r.to_string())
                .unwrap_or_else(|_| "?".into())
        ))
    };
    if obj.is_instance_of::<pyo3::types::PyBool>() {
        return Err(bad());
    }
    let value: i128 = obj.extract().map_err(|_| bad())?;
    u64::try_from(value).map_err(|_| bad())
}

/// A new NumPy array of the given shape from row-major data.
pub(crate) fn to_numpy<'py, D: Dimension>(
    py: Python<'py>,
    shape: D,
    data: Vec<f64>,
) -> PyResult<Bound<'py, PyArray<f64, D>>> {
    let array = Array::from_shape_vec(shape, data).map_err(|e| {
        pyo3::exceptions::PyRuntimeError::new_err(format!("internal shape error: {e}"))
    })?;
    Ok(array.into_pyarray(py))
}

/// Row-major data of a nalgebra matrix.
pub(crate) fn row_major<R: nalgebra::Dim, C: nalgebra::Dim, S: nalgebra::RawStorage<f64, R, C>>(
    m: &nalgebra::Matrix<f64, R, C, S>,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(m.nrows() * m.ncols());
    for i in 0..m.nrows() {
        for j in 0..m.ncols() {
            out.push(m[(i, j)]);
        }
    }
    out
}
