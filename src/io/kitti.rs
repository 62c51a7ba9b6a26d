//! KITTI Velodyne scans (`.bin`): little-endian float32 records `x y z intensity`, nothing else.
//!
//! ```
//! use lidarcal::io::{parse_points, Fields, FileFormat};
//! let bytes: Vec<u8> = [1.0f32, 2.0, 3.0, 0.5].iter().flat_map(|v| v.to_le_bytes()).collect();
//! let cloud = parse_points(&bytes, FileFormat::Kitti, &Fields::Default)?;
//! assert_eq!(cloud.data, [1.0, 2.0, 3.0, 0.5]);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use super::table::{self, Layout, Scalar};
use super::{Cloud, Fields};
use crate::error::{Error, Result};

const RECORD: usize = 16;

/// Parses a KITTI scan held in memory.
pub(crate) fn parse(bytes: &[u8], fields: &Fields) -> Result<Cloud> {
    if !bytes.len().is_multiple_of(RECORD) {
        return Err(Error::Format(format!(
            "{} bytes is not a whole number of 16-byte records (float32 x y z intensity): \
             not a KITTI scan, or truncated",
            bytes.len()
        )));
    }
    let available = table::default_names(4);
    let (pick, names) = table::select(&available, fields)?;
    let layouts: Vec<Layout> = pick
        .iter()
        .map(|&c| Layout {
            offset: 4 * c,
            stride: RECORD,
            scalar: Scalar::F32,
            big_endian: false,
        })
        .collect();
    let values = table::decode_binary(bytes, &layouts, bytes.len() / RECORD)?;
    Ok(table::finish(values, names, available))
}

/// Writes `x y z intensity` float32 records (intensity 0 when the table has none).
pub(crate) fn write(out: &mut Vec<u8>, names: &[String], data: &[f64]) -> Result<()> {
    let k = names.len();
    let mut idx = [None; 4];
    for (slot, name) in idx.iter_mut().zip(["x", "y", "z", "intensity"]) {
        *slot = table::find(names, name);
    }
    if idx[..3].iter().any(Option::is_none) {
        return Err(Error::InvalidInput(format!(
            "a KITTI scan needs columns x, y and z; got {}",
            names.join(" ")
        )));
    }
    for row in data.chunks_exact(k) {
        for slot in idx {
            let v = slot.and_then(|c| row.get(c)).copied().unwrap_or(0.0);
            out.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{parse_points, FileFormat};

    #[test]
    fn round_trip_and_truncation() {
        let names: Vec<String> = ["x", "y", "z"].map(String::from).to_vec();
        let mut b = Vec::new();
        write(&mut b, &names, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let c = parse_points(&b, FileFormat::Kitti, &Fields::All).unwrap();
        assert_eq!(c.data, [1.0, 2.0, 3.0, 0.0, 4.0, 5.0, 6.0, 0.0]);
        assert!(matches!(
            parse_points(&b[..30], FileFormat::Kitti, &Fields::All),
            Err(Error::Format(m)) if m.contains("16-byte records")
        ));
        assert!(write(&mut b, &["a".to_string()], &[1.0]).is_err());
    }
}
