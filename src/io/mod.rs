//! Point-cloud file formats (feature `io`).
//!
//! * [`pcd`]: PCD v0.7 writer (`ascii` and `binary`), fields `x y z intensity` and optionally `ring`.
//!
//! I/O failures are returned as [`Error::Io`](crate::Error::Io) carrying the path and the OS message.

pub mod pcd;

use crate::error::Error;

/// Wraps a `std::io::Error` with the path it concerns.
pub(crate) fn io_error(path: &std::path::Path, e: &std::io::Error) -> Error {
    Error::Io(format!("{}: {e}", path.display()))
}
