//! The `lidarcal._lidarcal` extension module: a thin layer that checks arguments, converts arrays,
//! releases the GIL around Rust work and maps errors to Python exceptions. Nothing numerical
//! happens here.

use std::panic::{catch_unwind, AssertUnwindSafe};

use pyo3::create_exception;
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError, PyRuntimeError,
    PyValueError,
};
use pyo3::prelude::*;

use crate::Error;

mod arrays;
mod calib;
mod check;
mod defaults;
mod io;
mod kernels;
mod ransac;
mod result;
mod sequence;
mod sim;

create_exception!(
    lidarcal,
    CalibrationError,
    PyRuntimeError,
    "A calibration could not produce a trustworthy result; the message says why."
);

create_exception!(
    lidarcal,
    FileFormatError,
    PyValueError,
    "A file is not a valid point cloud of its format; the message names the file and the problem."
);

/// One place where core errors become Python exceptions: malformed or degenerate input is a
/// `ValueError`, a failed calibration a `lidarcal.CalibrationError`, a file the system refused an
/// `OSError` of the matching subclass, a malformed file a `lidarcal.FileFormatError` (a `ValueError`).
impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        match e {
            Error::InvalidInput(m) | Error::Degenerate(m) => PyValueError::new_err(m),
            Error::Calibration { kind, message } => calibration_error(kind, message),
            Error::Numerical(m) => calibration_error(
                crate::FailureKind::NoAgreement,
                format!("numerical failure: {m}"),
            ),
            Error::Io { kind, message } => match kind {
                std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
                std::io::ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
                std::io::ErrorKind::IsADirectory => PyIsADirectoryError::new_err(message),
                _ => PyOSError::new_err(message),
            },
            Error::Format(m) => FileFormatError::new_err(m),
        }
    }
}

/// A `CalibrationError` whose `kind` attribute is the failure kind's name.
fn calibration_error(kind: crate::FailureKind, message: String) -> PyErr {
    let err = CalibrationError::new_err(message);
    Python::attach(|py| {
        // Setting an attribute on a fresh exception instance cannot fail in practice; if it
        // did, the error would still carry its message.
        let _ = err.value(py).setattr("kind", kind.name());
    });
    err
}

/// Runs `f` with the GIL released, turning its `Err` into an exception and any panic (a bug) into a
/// `RuntimeError` instead of unwinding into the interpreter.
pub(crate) fn run<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> crate::Result<T> + Send,
{
    match py.detach(|| catch_unwind(AssertUnwindSafe(f))) {
        Ok(Ok(value)) => Ok(value),
        Ok(Err(e)) => Err(e.into()),
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in lidarcal (a bug, please report it): {msg}"
            )))
        }
    }
}

#[pymodule]
fn _lidarcal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("CalibrationError", m.py().get_type::<CalibrationError>())?;
    m.add("FileFormatError", m.py().get_type::<FileFormatError>())?;
    m.add(
        "INTENSITY_NAMES",
        pyo3::types::PyTuple::new(m.py(), crate::io::INTENSITY_NAMES)?,
    )?;
    io::register(m)?;
    kernels::register(m)?;
    ransac::register(m)?;
    result::register(m)?;
    calib::register(m)?;
    check::register(m)?;
    sequence::register(m)?;
    sim::register(m)?;
    defaults::register(m)?;
    Ok(())
}
