//! Point-cloud file formats (feature `io`).
//!
//! [`read_points`] reads a file into a [`Cloud`]: named `f64` columns, one row per point. The
//! format is chosen by the extension:
//!
//! | extension | format |
//! |---|---|
//! | `.pcd` | PCD v0.7: `ascii`, `binary`, `binary_compressed` (LZF); any field order, `COUNT > 1`, `_` padding |
//! | `.ply` | PLY: `ascii`, `binary_little_endian`, `binary_big_endian`; the `vertex` element |
//! | `.bin` | KITTI Velodyne scans: float32 `x y z intensity` records |
//! | `.npy` | NumPy arrays `(N, K)` of floats or integers, `K >= 3`: columns `x y z [intensity] [colK...]` |
//! | `.csv`, `.txt`, `.xyz`, `.asc` | text, one point per line, separated by commas, semicolons or blanks; an optional header line names the columns; `#` starts a comment |
//!
//! [`Fields`] chooses the columns: by default `x y z` and the intensity when the file has one
//! (found under `intensity`, `i`, `reflectivity`, `scalar_intensity`, `remission` or
//! `reflectance`, and always returned as `intensity`). Points with a non-finite value in a selected
//! column (PCL writes NaN for missing returns) are dropped and counted in [`Cloud::dropped`].
//!
//! Every malformed file (wrong header, truncated data, a corrupt LZF block) gives
//! [`crate::Error::Format`] naming the file and the problem; the operating system's
//! refusals (missing file, permissions) give [`crate::Error::Io`]. Nothing panics and
//! nothing allocates more than the file can hold.
//!
//! [`write_points`] writes a cloud in any of these formats (PCD and PLY binary with `float32`
//! columns, KITTI `float32`, `.npy` `float64`, text with the shortest decimal that round-trips).
//!
//! ```
//! use lidarcal::io::{parse_points, Fields, FileFormat};
//! let text = b"x,y,z,reflectivity\n1,2,3,40\n4,5,nan,50\n7,8,9,60\n";
//! let cloud = parse_points(text, FileFormat::Text, &Fields::Default)?;
//! assert_eq!(cloud.names, ["x", "y", "z", "intensity"]);
//! assert_eq!(cloud.len(), 2);
//! assert_eq!(cloud.dropped, 1);
//! assert_eq!(cloud.row(1), &[7.0, 8.0, 9.0, 60.0]);
//! # Ok::<(), lidarcal::Error>(())
//! ```

pub mod kitti;
pub mod npy;
pub mod pcd;
pub mod ply;
pub mod text;

mod table;

use std::path::Path;

use crate::error::{Error, Result};

pub use table::{default_names, Scalar};

/// Names a file's intensity column may have, compared without case; the first is canonical.
pub const INTENSITY_NAMES: [&str; 6] = [
    "intensity",
    "i",
    "reflectivity",
    "scalar_intensity",
    "remission",
    "reflectance",
];

/// A point cloud read from a file: `names.len()` columns of `f64`, row-major.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Cloud {
    /// The column names, in the order of [`Cloud::data`]'s columns.
    pub names: Vec<String>,
    /// Row-major values: point `i` is `data[i * names.len()..(i + 1) * names.len()]`.
    pub data: Vec<f64>,
    /// Points dropped because a selected column was NaN or infinite.
    pub dropped: usize,
    /// Every field the file offers (what [`Fields::All`] would return).
    pub available: Vec<String>,
}

impl Cloud {
    /// The number of points.
    pub fn len(&self) -> usize {
        self.data.len().checked_div(self.names.len()).unwrap_or(0)
    }

    /// Whether the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The number of columns.
    pub fn columns(&self) -> usize {
        self.names.len()
    }

    /// Point `i`'s values (panics if `i >= len()`, like slice indexing).
    pub fn row(&self, i: usize) -> &[f64] {
        let k = self.names.len();
        &self.data[i * k..(i + 1) * k]
    }

    /// The index of the column called `name` (intensity under any of its usual names).
    pub fn column(&self, name: &str) -> Option<usize> {
        table::find(&self.names, name)
    }
}

/// Which columns [`read_points`] returns.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Fields {
    /// `x y z`, plus `intensity` when the file has one under any of [`INTENSITY_NAMES`].
    #[default]
    Default,
    /// Every field of the file, in file order (padding fields `_` excluded).
    All,
    /// These fields, in this order; `intensity` matches any of [`INTENSITY_NAMES`].
    Named(Vec<String>),
}

/// The file formats [`read_points`] and [`write_points`] know.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileFormat {
    /// PCD v0.7 (`.pcd`).
    Pcd,
    /// PLY (`.ply`).
    Ply,
    /// KITTI Velodyne `.bin`: float32 `x y z intensity` records.
    Kitti,
    /// NumPy `.npy`.
    Npy,
    /// Delimited text (`.csv`, `.txt`, `.xyz`, `.asc`).
    Text,
}

impl FileFormat {
    /// The format for a path's extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        match ext.as_str() {
            "pcd" => Ok(FileFormat::Pcd),
            "ply" => Ok(FileFormat::Ply),
            "bin" => Ok(FileFormat::Kitti),
            "npy" => Ok(FileFormat::Npy),
            "csv" | "txt" | "xyz" | "asc" => Ok(FileFormat::Text),
            _ => Err(Error::InvalidInput(format!(
                "{}: unknown point-cloud extension {:?}; expected .pcd, .ply, .bin (KITTI), .npy, \
                 .csv, .txt, .xyz or .asc",
                path.display(),
                ext
            ))),
        }
    }
}

/// Reads a point cloud from `path`, the format chosen by its extension (see the module docs).
pub fn read_points(path: &Path, fields: &Fields) -> Result<Cloud> {
    let format = FileFormat::from_path(path)?;
    let bytes = std::fs::read(path).map_err(|e| io_error(path, &e))?;
    parse_points(&bytes, format, fields).map_err(|e| with_path(path, e))
}

/// Parses a point cloud held in memory (what [`read_points`] does after reading the file). Errors
/// do not name a file.
pub fn parse_points(bytes: &[u8], format: FileFormat, fields: &Fields) -> Result<Cloud> {
    match format {
        FileFormat::Pcd => pcd::parse(bytes, fields),
        FileFormat::Ply => ply::parse(bytes, fields),
        FileFormat::Kitti => kitti::parse(bytes, fields),
        FileFormat::Npy => npy::parse(bytes, fields),
        FileFormat::Text => text::parse(bytes, fields),
    }
}

/// Writes `data` (row-major, `names.len()` columns) to `path` in the format of its extension;
/// `pcd_format` chooses the PCD encoding (other formats ignore it). KITTI `.bin` needs columns
/// `x y z` and writes `intensity` (0 when absent). Errors for non-finite values, a ragged `data`
/// and I/O failures.
pub fn write_points(
    path: &Path,
    names: &[String],
    data: &[f64],
    pcd_format: pcd::PcdFormat,
) -> Result<()> {
    let format = FileFormat::from_path(path)?;
    if names.is_empty() || !data.len().is_multiple_of(names.len()) {
        return Err(Error::InvalidInput(format!(
            "{} values do not make rows of {} column(s)",
            data.len(),
            names.len()
        )));
    }
    if let Some(bad) = names.iter().find(|n| !table::valid_name(n)) {
        return Err(Error::InvalidInput(format!(
            "column name {bad:?} is not a plain word (letters, digits, '_' and '.')"
        )));
    }
    if let Some((i, dup)) = names
        .iter()
        .enumerate()
        .find(|(i, n)| names[..*i].contains(n))
    {
        return Err(Error::InvalidInput(format!(
            "column name {dup:?} appears twice (columns {} and {i}): a reader could not tell \
             them apart",
            names.iter().position(|n| n == dup).unwrap_or(0)
        )));
    }
    crate::error::ensure_finite("points", data.iter())?;
    if matches!(
        format,
        FileFormat::Pcd | FileFormat::Ply | FileFormat::Kitti
    ) {
        // These store float32: a larger value would be written as inf and dropped on reading.
        if let Some(i) = data.iter().position(|v| v.abs() > f64::from(f32::MAX)) {
            return Err(Error::InvalidInput(format!(
                "{}: value {:e} (row {}, column {}) does not fit the float32 this format \
                 stores (|v| <= {:e}); write a .npy file (float64) instead",
                path.display(),
                data[i],
                i / names.len(),
                i % names.len(),
                f32::MAX
            )));
        }
    }
    let mut bytes = Vec::new();
    match format {
        FileFormat::Pcd => {
            let types = vec![Scalar::F32; names.len()];
            pcd::write_table(&mut bytes, names, &types, data, pcd_format)?
        }
        FileFormat::Ply => ply::write(&mut bytes, names, data),
        FileFormat::Kitti => kitti::write(&mut bytes, names, data)?,
        FileFormat::Npy => npy::write(&mut bytes, names.len(), data),
        FileFormat::Text => text::write(&mut bytes, names, data, path),
    }
    std::fs::write(path, bytes).map_err(|e| io_error(path, &e))
}

/// Wraps a `std::io::Error` with the path it concerns.
pub(crate) fn io_error(path: &Path, e: &std::io::Error) -> Error {
    Error::Io {
        kind: e.kind(),
        message: format!("{}: {e}", path.display()),
    }
}

/// Prefixes a parse error with the file it came from.
fn with_path(path: &Path, e: Error) -> Error {
    match e {
        Error::Format(m) => Error::Format(format!("{}: {m}", path.display())),
        Error::InvalidInput(m) => Error::InvalidInput(format!("{}: {m}", path.display())),
        other => other,
    }
}
