//! `_defaults()`: the Rust defaults behind the keywords of the extension module, so that a test
//! (`tests/python/test_defaults.py`) can hold the signatures, the stubs and the docstrings to them.
//!
//! A keyword whose default lives in Rust takes `None` in its signature and is filled from the Rust
//! `Default` (or constant) on the way in; each file of this layer reports the same values here,
//! read from the same place.

use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Adds an empty table for `function` (its name in the module, `Class.method` for a method) to
/// `out` and returns it, for the caller to fill with `keyword: default`.
pub(crate) fn table<'py>(out: &Bound<'py, PyDict>, function: &str) -> PyResult<Bound<'py, PyDict>> {
    let t = PyDict::new(out.py());
    out.set_item(function, &t)?;
    Ok(t)
}

/// {function: {keyword: default}}: the Rust defaults a keyword left out (or None) takes.
#[pyfunction]
#[pyo3(name = "_defaults")]
fn defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let out = PyDict::new(py);
    super::calib::defaults(&out)?;
    super::check::defaults(&out)?;
    super::kernels::defaults(&out)?;
    super::ransac::defaults(&out)?;
    super::sim::defaults(&out)?;
    Ok(out)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(defaults, m)?)
}
