//! `read_points` / `write_points`: the Rust readers and writers of `crate::io` for NumPy arrays.

use std::path::PathBuf;

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};

use super::{arrays, run};
use crate::io::{self, Fields};

fn fields_arg(fields: Option<&Bound<'_, PyAny>>) -> PyResult<Fields> {
    let Some(obj) = fields else {
        return Ok(Fields::Default);
    };
    if let Ok(s) = obj.cast::<PyString>() {
        let s = s.to_str()?;
        return if s == "all" {
            Ok(Fields::All)
        } else {
            Err(PyValueError::new_err(format!(
                "fields must be None, \"all\" or a sequence of field names, got the string {s:?}"
            )))
        };
    }
    let names: Vec<String> = obj.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "fields must be None, \"all\" or a sequence of field names, got {}",
            obj.get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default()
        ))
    })?;
    Ok(Fields::Named(names))
}

/// Reads a point cloud file into an (N, K) float64 array (see the stub for the documentation).
#[pyfunction]
#[pyo3(signature = (path, fields=None, *, with_info=false))]
fn read_points<'py>(
    py: Python<'py>,
    path: PathBuf,
    fields: Option<&Bound<'py, PyAny>>,
    with_info: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let selection = fields_arg(fields)?;
    let p = path.clone();
    let cloud = run(py, move || io::read_points(&p, &selection))?;
    let (n, k) = (cloud.len(), cloud.columns());
    let array = arrays::to_numpy(py, numpy::ndarray::Ix2(n, k), cloud.data)?.into_any();
    if !with_info {
        return Ok(array);
    }
    let info = PyDict::new(py);
    info.set_item("path", path.display().to_string())?;
    info.set_item("fields", cloud.names)?;
    info.set_item("available", cloud.available)?;
    info.set_item("points", n)?;
    info.set_item("dropped_non_finite", cloud.dropped)?;
    Ok(PyTuple::new(py, [array, info.into_any()])?.into_any())
}

/// Writes an (N, K) array as a point cloud file chosen by the extension.
#[pyfunction]
#[pyo3(signature = (path, points, fields=None, *, pcd_format="binary"))]
fn write_points(
    py: Python<'_>,
    path: PathBuf,
    points: &Bound<'_, PyAny>,
    fields: Option<Vec<String>>,
    pcd_format: &str,
) -> PyResult<()> {
    let pcd_format = match pcd_format {
        "binary" => io::pcd::PcdFormat::Binary,
        "binary_compressed" => io::pcd::PcdFormat::BinaryCompressed,
        "ascii" => io::pcd::PcdFormat::Ascii,
        other => {
            return Err(PyValueError::new_err(format!(
                "pcd_format must be \"binary\", \"binary_compressed\" or \"ascii\", got {other:?}"
            )))
        }
    };
    let d = arrays::dense(points, "points")?;
    let k = match d.shape.as_slice() {
        [_, k] if *k >= 3 => *k,
        _ => {
            return Err(PyValueError::new_err(format!(
            "points must be a 2-D array (N, K) with K >= 3 columns (x, y, z, ...), got shape {:?}",
            d.shape
        )))
        }
    };
    let names = match fields {
        Some(names) if names.len() != k => {
            return Err(PyValueError::new_err(format!(
                "fields names {} column(s) but points has {k}",
                names.len()
            )))
        }
        Some(names) => names,
        None => io::default_names(k),
    };
    run(py, move || {
        io::write_points(&path, &names, &d.data, pcd_format)
    })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_points, m)?)?;
    m.add_function(wrap_pyfunction!(write_points, m)?)?;
    Ok(())
}
