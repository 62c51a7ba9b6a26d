//! What every reader shares: scalar types, column selection, strided binary decoding, text rows,
//! and dropping non-finite points.

use super::{Cloud, Fields, INTENSITY_NAMES};
use crate::error::{Error, Result};

/// A stored scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scalar {
    /// `i8`
    I8,
    /// `u8`
    U8,
    /// `i16`
    I16,
    /// `u16`
    U16,
    /// `i32`
    I32,
    /// `u32`
    U32,
    /// `i64`
    I64,
    /// `u64`
    U64,
    /// `f32`
    F32,
    /// `f64`
    F64,
}

impl Scalar {
    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }
}

/// Where one column's values sit in a byte buffer: value `r` starts at `offset + r * stride`.
/// Row-major records and column-major blocks are both strided.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Layout {
    pub offset: usize,
    pub stride: usize,
    pub scalar: Scalar,
    pub big_endian: bool,
}

/// Finds `name` among `names` (exact, then case-insensitive; `intensity` and its aliases match
/// each other).
pub(crate) fn find(names: &[String], name: &str) -> Option<usize> {
    if let Some(i) = names.iter().position(|n| n == name) {
        return Some(i);
    }
    if let Some(i) = names.iter().position(|n| n.eq_ignore_ascii_case(name)) {
        return Some(i);
    }
    let is_intensity = |n: &str| INTENSITY_NAMES.iter().any(|a| a.eq_ignore_ascii_case(n));
    if is_intensity(name) {
        // In the order of INTENSITY_NAMES, so `intensity` wins over `i` if a file has both.
        for alias in INTENSITY_NAMES {
            if let Some(i) = names.iter().position(|n| n.eq_ignore_ascii_case(alias)) {
                return Some(i);
            }
        }
    }
    None
}

/// Resolves `fields` against the file's field names: the indices to read and the output names.
pub(crate) fn select(available: &[String], fields: &Fields) -> Result<(Vec<usize>, Vec<String>)> {
    let listing = || available.join(" ");
    match fields {
        Fields::All => {
            if available.is_empty() {
                return Err(Error::Format("the file declares no fields".into()));
            }
            Ok(((0..available.len()).collect(), available.to_vec()))
        }
        Fields::Default => {
            let mut idx = Vec::with_capacity(4);
            for axis in ["x", "y", "z"] {
                match find(available, axis) {
                    Some(i) => idx.push(i),
                    None => {
                        return Err(Error::Format(format!(
                            "no field '{axis}' (the file has: {})",
                            listing()
                        )))
                    }
                }
            }
            let mut names: Vec<String> = ["x", "y", "z"].map(String::from).to_vec();
            if let Some(i) = find(available, "intensity") {
                idx.push(i);
                names.push("intensity".into());
            }
            Ok((idx, names))
        }
        Fields::Named(wanted) => {
            if wanted.is_empty() {
                return Err(Error::InvalidInput(
                    "fields is empty: name at least one".into(),
                ));
            }
            let mut idx = Vec::with_capacity(wanted.len());
            for name in wanted {
                match find(available, name) {
                    Some(i) => idx.push(i),
                    None => {
                        return Err(Error::InvalidInput(format!(
                            "no field {name:?} (the file has: {})",
                            listing()
                        )))
                    }
                }
            }
            Ok((idx, wanted.clone()))
        }
    }
}

/// Reads `N` bytes at `offset`, or a truncation error.
#[inline]
fn bytes_at<const N: usize>(bytes: &[u8], offset: usize) -> Result<[u8; N]> {
    bytes
        .get(offset..offset.wrapping_add(N))
        .and_then(|s| <[u8; N]>::try_from(s).ok())
        .ok_or_else(|| Error::Format("the data section is truncated".into()))
}

macro_rules! decode_column {
    ($ty:ty, $n:literal, $bytes:expr, $layout:expr, $first:expr, $out:expr, $col:expr, $ncols:expr) => {{
        let l = $layout;
        for (r, row) in $out.chunks_exact_mut($ncols).enumerate() {
            let raw = bytes_at::<$n>($bytes, l.offset + ($first + r) * l.stride)?;
            let v = if l.big_endian {
                <$ty>::from_be_bytes(raw)
            } else {
                <$ty>::from_le_bytes(raw)
            };
            row[$col] = v as f64;
        }
    }};
}

/// Rows decoded together: every column of a block is written while the block's output (a few
/// tens of KiB) stays in cache, and blocks are what the threads share out.
const BLOCK_ROWS: usize = 2048;
/// Below this many rows one thread decodes everything (the pool's round trip costs more).
#[cfg(feature = "parallel")]
const PARALLEL_MIN_ROWS: usize = 65_536;

/// Decodes the rows `first..first + out.len() / ncols` of every layout into `out`.
fn decode_block(bytes: &[u8], layouts: &[Layout], first: usize, out: &mut [f64]) -> Result<()> {
    let ncols = layouts.len();
    for (c, l) in layouts.iter().enumerate() {
        match l.scalar {
            Scalar::I8 => decode_column!(i8, 1, bytes, l, first, out, c, ncols),
            Scalar::U8 => decode_column!(u8, 1, bytes, l, first, out, c, ncols),
            Scalar::I16 => decode_column!(i16, 2, bytes, l, first, out, c, ncols),
            Scalar::U16 => decode_column!(u16, 2, bytes, l, first, out, c, ncols),
            Scalar::I32 => decode_column!(i32, 4, bytes, l, first, out, c, ncols),
            Scalar::U32 => decode_column!(u32, 4, bytes, l, first, out, c, ncols),
            Scalar::I64 => decode_column!(i64, 8, bytes, l, first, out, c, ncols),
            Scalar::U64 => decode_column!(u64, 8, bytes, l, first, out, c, ncols),
            Scalar::F32 => decode_column!(f32, 4, bytes, l, first, out, c, ncols),
            Scalar::F64 => decode_column!(f64, 8, bytes, l, first, out, c, ncols),
        }
    }
    Ok(())
}

/// Decodes `rows` values of each layout into a row-major `f64` table. The caller has checked that
/// the buffer is long enough; a short buffer still gives an error, never a panic.
pub(crate) fn decode_binary(bytes: &[u8], layouts: &[Layout], rows: usize) -> Result<Vec<f64>> {
    let ncols = layouts.len();
    // Check the furthest byte once, so a truncated file fails before the allocation.
    for l in layouts {
        if rows > 0 {
            let last = (rows - 1)
                .checked_mul(l.stride)
                .and_then(|v| v.checked_add(l.offset))
                .and_then(|v| v.checked_add(l.scalar.size()));
            if last.is_none_or(|end| end > bytes.len()) {
                return Err(Error::Format(format!(
                    "the data section is truncated: {} bytes where {rows} points need more",
                    bytes.len()
                )));
            }
        }
    }
    let cells = rows
        .checked_mul(ncols)
        .ok_or_else(|| Error::Format(format!("{rows} points are too many")))?;
    let mut out = vec![0.0; cells];
    if ncols == 0 {
        return Ok(out);
    }
    let block = BLOCK_ROWS * ncols;
    #[cfg(feature = "parallel")]
    if rows >= PARALLEL_MIN_ROWS {
        use rayon::prelude::*;
        out.par_chunks_mut(block)
            .enumerate()
            .try_for_each(|(b, chunk)| decode_block(bytes, layouts, b * BLOCK_ROWS, chunk))?;
        return Ok(out);
    }
    for (b, chunk) in out.chunks_mut(block).enumerate() {
        decode_block(bytes, layouts, b * BLOCK_ROWS, chunk)?;
    }
    Ok(out)
}

/// Parses whitespace- or delimiter-separated rows: `select` are token indices, `min_tokens` the
/// number every row must have. Stops after `max_rows` rows when given. `first_line` numbers the
/// lines in messages.
pub(crate) fn decode_text_rows<'a, I>(
    lines: I,
    split: impl Fn(&'a str) -> Vec<&'a str>,
    select: &[usize],
    min_tokens: usize,
    max_rows: Option<usize>,
) -> Result<Vec<f64>>
where
    I: Iterator<Item = (usize, &'a str)>,
{
    let mut out = Vec::new();
    let mut rows = 0usize;
    for (line_no, line) in lines {
        if max_rows.is_some_and(|m| rows >= m) {
            break;
        }
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let tokens = split(line);
        if tokens.len() < min_tokens {
            return Err(Error::Format(format!(
                "line {line_no}: {} value(s) where {min_tokens} are needed",
                tokens.len()
            )));
        }
        for &t in select {
            let token = tokens.get(t).copied().unwrap_or_default();
            let v: f64 = token
                .parse()
                .map_err(|_| Error::Format(format!("line {line_no}: {token:?} is not a number")))?;
            out.push(v);
        }
        rows += 1;
    }
    if let Some(m) = max_rows {
        if rows < m {
            return Err(Error::Format(format!(
                "the data section is truncated: {rows} of {m} points"
            )));
        }
    }
    Ok(out)
}

/// Rounds the text-parsed values of `f32` columns to `f32`, as a binary reader would store them
/// (a PCD or PLY text file writes the shortest decimal of the declared type).
pub(crate) fn round_f32_columns(values: &mut [f64], scalars: &[Scalar]) {
    let k = scalars.len();
    if k == 0 || !scalars.contains(&Scalar::F32) {
        return;
    }
    for row in values.chunks_exact_mut(k) {
        for (v, s) in row.iter_mut().zip(scalars) {
            if *s == Scalar::F32 {
                *v = f64::from(*v as f32);
            }
        }
    }
}

/// Builds the cloud, dropping rows with a non-finite value.
pub(crate) fn finish(mut data: Vec<f64>, names: Vec<String>, available: Vec<String>) -> Cloud {
    let k = names.len();
    let mut kept = 0usize;
    let rows = data.len().checked_div(k).unwrap_or(0);
    for r in 0..rows {
        let finite = data[r * k..(r + 1) * k].iter().all(|v| v.is_finite());
        if finite {
            if kept != r {
                data.copy_within(r * k..(r + 1) * k, kept * k);
            }
            kept += 1;
        }
    }
    data.truncate(kept * k);
    Cloud {
        names,
        data,
        dropped: rows - kept,
        available,
    }
}

/// Whether a column name can be written into a header (a plain word).
pub(crate) fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.')
}

/// Default names for unnamed columns: `x y z intensity col4 col5 ...`.
pub fn default_names(k: usize) -> Vec<String> {
    (0..k)
        .map(|i| match i {
            0 => "x".to_string(),
            1 => "y".to_string(),
            2 => "z".to_string(),
            3 => "intensity".to_string(),
            _ => format!("col{i}"),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(s: &str) -> Vec<String> {
        s.split(' ').map(String::from).collect()
    }

    #[test]
    fn intensity_aliases_resolve() {
        let n = names("x y z reflectivity ring");
        assert_eq!(find(&n, "intensity"), Some(3));
        assert_eq!(find(&n, "Ring"), Some(4));
        assert_eq!(find(&n, "t"), None);
        let (idx, out) = select(&n, &Fields::Default).unwrap();
        assert_eq!(idx, [0, 1, 2, 3]);
        assert_eq!(out, ["x", "y", "z", "intensity"]);
    }

    #[test]
    fn missing_fields_are_named() {
        let n = names("x y intensity");
        let err = select(&n, &Fields::Default).unwrap_err().to_string();
        assert!(
            err.contains("no field 'z'") && err.contains("x y intensity"),
            "{err}"
        );
        let err = select(&n, &Fields::Named(vec!["ring".into()])).unwrap_err();
        assert!(matches!(err, Error::InvalidInput(m) if m.contains("\"ring\"")));
    }

    #[test]
    fn strided_decoding_checks_bounds() {
        let bytes: Vec<u8> = [1.5f32, -2.0, 3.25]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let l = Layout {
            offset: 0,
            stride: 4,
            scalar: Scalar::F32,
            big_endian: false,
        };
        assert_eq!(decode_binary(&bytes, &[l], 3).unwrap(), [1.5, -2.0, 3.25]);
        assert!(matches!(
            decode_binary(&bytes, &[l], 4),
            Err(Error::Format(_))
        ));
        let huge = Layout {
            stride: usize::MAX / 2,
            ..l
        };
        assert!(matches!(
            decode_binary(&bytes, &[huge], 3),
            Err(Error::Format(_))
        ));
    }

    #[test]
    fn non_finite_rows_are_dropped_and_counted() {
        let data = vec![1.0, 2.0, f64::NAN, 4.0, 5.0, 6.0, 7.0, f64::INFINITY];
        let c = finish(data, names("a b"), names("a b"));
        assert_eq!(c.data, [1.0, 2.0, 5.0, 6.0]);
        assert_eq!(c.dropped, 2);
        assert_eq!(c.len(), 2);
    }
}
