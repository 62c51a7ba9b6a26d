//! NumPy `.npy` files holding a 2-D array `(N, K)`, `K >= 3`, of floats or integers (either byte
//! order, C or Fortran order). Columns are named `x y z intensity col4 col5 ...`. Structured
//! (record) dtypes and object arrays are refused with a clear error. The writer stores `<f8`.
//!
//! ```
//! use lidarcal::io::{parse_points, Fields, FileFormat};
//! let mut bytes = Vec::new();
//! lidarcal::io::npy::write(&mut bytes, 3, &[1.0, 2.0, 3.0]);
//! let cloud = parse_points(&bytes, FileFormat::Npy, &Fields::Default)?;
//! assert_eq!(cloud.data, [1.0, 2.0, 3.0]);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use super::table::{self, Layout, Scalar};
use super::{Cloud, Fields};
use crate::error::{Error, Result};

const MAGIC: &[u8] = b"\x93NUMPY";

fn bad(msg: impl Into<String>) -> Error {
    Error::Format(msg.into())
}

/// The value of `'key':` in the header dictionary, up to the next top-level comma or brace.
fn entry<'a>(header: &'a str, key: &str) -> Result<&'a str> {
    let pattern_single = format!("'{key}'");
    let pattern_double = format!("\"{key}\"");
    let at = header
        .find(&pattern_single)
        .or_else(|| header.find(&pattern_double))
        .ok_or_else(|| bad(format!("the header has no '{key}'")))?;
    let rest = &header[at + key.len() + 2..];
    let rest = rest
        .trim_start()
        .strip_prefix(':')
        .ok_or_else(|| bad(format!("'{key}' is not followed by ':'")))?
        .trim_start();
    let end = if rest.starts_with('(') || rest.starts_with('[') {
        let close = if rest.starts_with('(') { ')' } else { ']' };
        rest.find(close).map(|i| i + 1)
    } else {
        rest.find([',', '}'])
    }
    .ok_or_else(|| bad(format!("'{key}' has no end")))?;
    Ok(rest[..end].trim())
}

fn dtype(descr: &str) -> Result<(Scalar, bool)> {
    let d = descr.trim_matches(|c| c == '\'' || c == '"');
    if descr.starts_with('[') {
        return Err(bad(
            "structured dtypes are not supported: save a plain (N, K) float array",
        ));
    }
    let (big, code) = match d.as_bytes().first() {
        Some(b'>') => (true, &d[1..]),
        Some(b'<') | Some(b'|') | Some(b'=') => (false, &d[1..]),
        _ => (false, d),
    };
    let s = match code {
        "f4" => Scalar::F32,
        "f8" => Scalar::F64,
        "i1" => Scalar::I8,
        "u1" => Scalar::U8,
        "i2" => Scalar::I16,
        "u2" => Scalar::U16,
        "i4" => Scalar::I32,
        "u4" => Scalar::U32,
        "i8" => Scalar::I64,
        "u8" => Scalar::U64,
        _ => {
            return Err(bad(format!(
                "dtype {d:?} is not a float or integer type lidarcal reads"
            )))
        }
    };
    Ok((s, big))
}

/// Parses a `.npy` file held in memory.
pub(crate) fn parse(bytes: &[u8], fields: &Fields) -> Result<Cloud> {
    if !bytes.starts_with(MAGIC) {
        return Err(bad("no \\x93NUMPY magic: not a .npy file"));
    }
    let major = bytes
        .get(6)
        .copied()
        .ok_or_else(|| bad("truncated header"))?;
    let (len, start): (Option<usize>, usize) = match major {
        1 => (
            bytes
                .get(8..10)
                .map(|b| u16::from_le_bytes([b[0], b[1]]) as usize),
            10,
        ),
        2 | 3 => (
            bytes
                .get(8..12)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize),
            12,
        ),
        v => return Err(bad(format!("unknown .npy version {v}"))),
    };
    let len = len.ok_or_else(|| bad("truncated header"))?;
    let header = start
        .checked_add(len)
        .and_then(|end| bytes.get(start..end))
        .ok_or_else(|| bad("truncated header"))?;
    let header = std::str::from_utf8(header).map_err(|_| bad("the header is not text"))?;
    let (scalar, big) = dtype(entry(header, "descr")?)?;
    let fortran = match entry(header, "fortran_order")? {
        "True" => true,
        "False" => false,
        other => return Err(bad(format!("fortran_order {other:?} is not True or False"))),
    };
    let shape: Vec<usize> = entry(header, "shape")?
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse()
                .map_err(|_| bad(format!("shape entry {s:?} is not a number")))
        })
        .collect::<Result<_>>()?;
    let (n, k) = match shape.as_slice() {
        [n, k] if *k >= 3 => (*n, *k),
        _ => {
            return Err(bad(format!(
                "shape {shape:?}: a point cloud is a 2-D array (N, K) with K >= 3 columns"
            )))
        }
    };
    let body = &bytes[start + len..];
    let size = scalar.size();
    let need = n.checked_mul(k).and_then(|c| c.checked_mul(size));
    if need.is_none_or(|need| need > body.len()) {
        return Err(bad(format!(
            "the data is truncated: {} bytes for a ({n}, {k}) array of {size}-byte values",
            body.len()
        )));
    }
    let available = table::default_names(k);
    let (pick, names) = table::select(&available, fields)?;
    let layouts: Vec<Layout> = pick
        .iter()
        .map(|&c| {
            let (offset, stride) = if fortran {
                (c * n * size, size)
            } else {
                (c * size, k * size)
            };
            Layout {
                offset,
                stride,
                scalar,
                big_endian: big,
            }
        })
        .collect();
    let values = table::decode_binary(body, &layouts, n)?;
    Ok(table::finish(values, names, available))
}

/// Writes a C-order `<f8` array of `k` columns.
pub fn write(out: &mut Vec<u8>, k: usize, data: &[f64]) {
    let n = data.len() / k.max(1);
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({n}, {k}), }}");
    // Pad so the data starts on a 64-byte boundary, ending the header with a newline.
    let total = MAGIC.len() + 4 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{parse_points, FileFormat};

    fn npy(descr: &str, fortran: bool, shape: &str, body: &[u8]) -> Vec<u8> {
        let h = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}\n",
            if fortran { "True" } else { "False" }
        );
        let mut b = MAGIC.to_vec();
        b.extend_from_slice(&[1, 0]);
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(body);
        b
    }

    #[test]
    fn orders_and_types() {
        let c: Vec<u8> = (1..=6i16).flat_map(|v| v.to_be_bytes()).collect();
        let cloud = parse_points(
            &npy(">i2", false, "(2, 3)", &c),
            FileFormat::Npy,
            &Fields::All,
        )
        .unwrap();
        assert_eq!(cloud.data, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let f: Vec<u8> = [1.0f32, 4.0, 2.0, 5.0, 3.0, 6.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let cloud = parse_points(
            &npy("<f4", true, "(2, 3)", &f),
            FileFormat::Npy,
            &Fields::All,
        )
        .unwrap();
        assert_eq!(cloud.data, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    #[test]
    fn malformed_files_are_explained() {
        let e = |b: &[u8]| {
            parse_points(b, FileFormat::Npy, &Fields::All)
                .unwrap_err()
                .to_string()
        };
        assert!(e(b"PK\x03\x04").contains("not a .npy"));
        assert!(e(&npy("<f8", false, "(5,)", &[0; 40])).contains("2-D array"));
        assert!(e(&npy("<f8", false, "(2, 3)", &[0; 40])).contains("truncated"));
        assert!(e(&npy("|O", false, "(2, 3)", &[0; 48])).contains("not a float"));
        assert!(e(&npy(
            "<f8",
            false,
            "(99999999999999, 99999999999)",
            &[0; 48]
        ))
        .contains("truncated"));
    }
}
