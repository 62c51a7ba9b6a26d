//! PCD v0.7 writer (the Point Cloud Library's format).
//!
//! Fields `x y z intensity` are written as 4-byte floats (`F 4`), and `ring` as a 2-byte unsigned
//! integer (`U 2`) when requested. `DATA binary` packs each point's fields little-endian with no
//! padding; `DATA ascii` writes one point per line with the shortest decimal that round-trips the
//! `f32`. The cloud is unorganised (`HEIGHT 1`) with the identity viewpoint.
//!
//! ```
//! use lidarcal::io::pcd::{write_pcd, PcdFormat, PcdPoint};
//! use nalgebra::Point3;
//! let points = [PcdPoint { position: Point3::new(1.0, 2.0, 3.0), intensity: 40.0, ring: 3 }];
//! let mut bytes = Vec::new();
//! write_pcd(&mut bytes, &points, true, PcdFormat::Ascii)?;
//! let text = String::from_utf8(bytes).unwrap();
//! assert!(text.contains("FIELDS x y z intensity ring\n"));
//! assert!(text.ends_with("DATA ascii\n1 2 3 40 3\n"));
//! # Ok::<(), lidarcal::Error>(())
//! ```

use std::io::{BufWriter, Write};
use std::path::Path;

use nalgebra::Point3;

use super::io_error;
use crate::error::{Error, Result};
use crate::sim::ScanPoint;

/// How the data section is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PcdFormat {
    /// One text line per point.
    Ascii,
    /// Packed little-endian records.
    Binary,
}

impl PcdFormat {
    fn keyword(self) -> &'static str {
        match self {
            PcdFormat::Ascii => "ascii",
            PcdFormat::Binary => "binary",
        }
    }
}

/// One point to write.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcdPoint {
    /// Position, metres (written as `f32`).
    pub position: Point3<f64>,
    /// Intensity (written as `f32`).
    pub intensity: f64,
    /// Ring index (written only when requested).
    pub ring: u16,
}

impl From<&ScanPoint> for PcdPoint {
    fn from(p: &ScanPoint) -> Self {
        PcdPoint {
            position: p.position,
            intensity: p.intensity,
            ring: p.ring,
        }
    }
}

/// The header of a cloud of `count` points.
pub fn header(count: usize, with_ring: bool, format: PcdFormat) -> String {
    let (fields, size, kind, each) = if with_ring {
        (
            "x y z intensity ring",
            "4 4 4 4 2",
            "F F F F U",
            "1 1 1 1 1",
        )
    } else {
        ("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1")
    };
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\n\
         TYPE {kind}\nCOUNT {each}\nWIDTH {count}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n\
         POINTS {count}\nDATA {}\n",
        format.keyword()
    )
}

fn write_error(e: &std::io::Error) -> Error {
    Error::Io(format!("writing PCD data: {e}"))
}

/// Writes `points` as PCD to `writer`. Errors for non-finite coordinates or intensities (PCD
/// readers choke on them) and for I/O failures ([`Error::Io`]).
pub fn write_pcd<W: Write>(
    writer: W,
    points: &[PcdPoint],
    with_ring: bool,
    format: PcdFormat,
) -> Result<()> {
    crate::error::ensure_finite(
        "points",
        points.iter().flat_map(|p| {
            p.position
                .coords
                .iter()
                .chain(std::iter::once(&p.intensity))
        }),
    )?;
    let mut w = BufWriter::new(writer);
    w.write_all(header(points.len(), with_ring, format).as_bytes())
        .map_err(|e| write_error(&e))?;
    for p in points {
        let v = [
            p.position.x as f32,
            p.position.y as f32,
            p.position.z as f32,
            p.intensity as f32,
        ];
        match format {
            PcdFormat::Binary => {
                for x in v {
                    w.write_all(&x.to_le_bytes()).map_err(|e| write_error(&e))?;
                }
                if with_ring {
                    w.write_all(&p.ring.to_le_bytes())
                        .map_err(|e| write_error(&e))?;
                }
            }
            PcdFormat::Ascii => {
                let line = if with_ring {
                    format!("{} {} {} {} {}\n", v[0], v[1], v[2], v[3], p.ring)
                } else {
                    format!("{} {} {} {}\n", v[0], v[1], v[2], v[3])
                };
                w.write_all(line.as_bytes()).map_err(|e| write_error(&e))?;
            }
        }
    }
    w.flush().map_err(|e| write_error(&e))
}

/// Writes `points` as a PCD file at `path` (created or truncated).
pub fn write_pcd_file(
    path: &Path,
    points: &[PcdPoint],
    with_ring: bool,
    format: PcdFormat,
) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| io_error(path, &e))?;
    write_pcd(file, points, with_ring, format).map_err(|e| match e {
        Error::Io(m) => Error::Io(format!("{}: {m}", path.display())),
        other => other,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<PcdPoint> {
        (0..5)
            .map(|i| PcdPoint {
                position: Point3::new(i as f64 * 0.5, -1.25, 3.0 + i as f64),
                intensity: 10.0 * i as f64,
                ring: i as u16 + 7,
            })
            .collect()
    }

    /// Splits a PCD byte stream into header lines and the data section.
    fn split(bytes: &[u8]) -> (Vec<String>, &[u8]) {
        let key = b"DATA ";
        let start = bytes.windows(key.len()).position(|w| w == key).unwrap();
        let end = start + bytes[start..].iter().position(|&b| b == b'\n').unwrap() + 1;
        let header = String::from_utf8(bytes[..end].to_vec()).unwrap();
        (header.lines().map(String::from).collect(), &bytes[end..])
    }

    #[test]
    fn binary_round_trip_with_ring() {
        let pts = sample();
        let mut bytes = Vec::new();
        write_pcd(&mut bytes, &pts, true, PcdFormat::Binary).unwrap();
        let (header, data) = split(&bytes);
        assert!(header.contains(&"FIELDS x y z intensity ring".to_string()));
        assert!(header.contains(&"TYPE F F F F U".to_string()));
        assert!(header.contains(&"POINTS 5".to_string()));
        assert_eq!(header.last().unwrap(), "DATA binary");
        assert_eq!(data.len(), 5 * 18);
        for (p, rec) in pts.iter().zip(data.chunks_exact(18)) {
            let f = |k: usize| f32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().unwrap());
            assert_eq!(f(0), p.position.x as f32);
            assert_eq!(f(1), p.position.y as f32);
            assert_eq!(f(2), p.position.z as f32);
            assert_eq!(f(3), p.intensity as f32);
            assert_eq!(u16::from_le_bytes([rec[16], rec[17]]), p.ring);
        }
    }

    #[test]
    fn ascii_round_trip_without_ring() {
        let pts = sample();
        let mut bytes = Vec::new();
        write_pcd(&mut bytes, &pts, false, PcdFormat::Ascii).unwrap();
        let (header, data) = split(&bytes);
        assert!(header.contains(&"SIZE 4 4 4 4".to_string()));
        let text = std::str::from_utf8(data).unwrap();
        let rows: Vec<Vec<f32>> = text
            .lines()
            .map(|l| l.split(' ').map(|x| x.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 5);
        for (p, row) in pts.iter().zip(&rows) {
            assert_eq!(row.len(), 4);
            assert_eq!(row[2], p.position.z as f32);
            assert_eq!(row[3], p.intensity as f32);
        }
    }

    #[test]
    fn errors_are_reported() {
        let mut pts = sample();
        pts[1].intensity = f64::NAN;
        assert!(matches!(
            write_pcd(Vec::new(), &pts, false, PcdFormat::Ascii),
            Err(Error::InvalidInput(_))
        ));
        let missing = Path::new("/nonexistent-dir-lidarcal/x.pcd");
        assert!(matches!(
            write_pcd_file(missing, &sample(), false, PcdFormat::Binary),
            Err(Error::Io(m)) if m.contains("nonexistent-dir-lidarcal")
        ));
    }
}
