//! PCD v0.7, the Point Cloud Library's format: reader and writer.
//!
//! The reader takes `DATA ascii`, `binary` and `binary_compressed` (LZF, fields stored column by
//! column), any field order, every `SIZE`/`TYPE` pair PCL defines (`I`/`U` 1, 2, 4, 8 bytes; `F` 4
//! and 8), `COUNT > 1` (a field `n` with count 3 becomes columns `n_0 n_1 n_2`) and PCL's padding
//! fields named `_`, which are skipped. Organised clouds (`HEIGHT > 1`) are read row by row.
//!
//! The writer stores each column as a given [`Scalar`]; `DATA binary` packs the fields of a point
//! little-endian with no padding, `binary_compressed` LZF-compresses the column-major block, and
//! `ascii` writes the shortest decimal that round-trips the stored type. The cloud is unorganised
//! (`HEIGHT 1`) with the identity viewpoint.
//!
//! ```
//! use lidarcal::io::pcd::{write_pcd, PcdFormat, PcdPoint};
//! use lidarcal::io::{parse_points, Fields, FileFormat};
//! use nalgebra::Point3;
//! let points = [PcdPoint { position: Point3::new(1.0, 2.0, 3.0), intensity: 40.0, ring: 3 }];
//! let mut bytes = Vec::new();
//! write_pcd(&mut bytes, &points, true, PcdFormat::Ascii)?;
//! let text = String::from_utf8(bytes.clone()).unwrap();
//! assert!(text.contains("FIELDS x y z intensity ring\n"));
//! assert!(text.ends_with("DATA ascii\n1 2 3 40 3\n"));
//! let cloud = parse_points(&bytes, FileFormat::Pcd, &Fields::All)?;
//! assert_eq!(cloud.names, ["x", "y", "z", "intensity", "ring"]);
//! assert_eq!(cloud.data, [1.0, 2.0, 3.0, 40.0, 3.0]);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use std::io::Write;
use std::path::Path;

use nalgebra::Point3;

use super::io_error;
use super::table::{self, Layout, Scalar};
use super::{Cloud, Fields};
use crate::error::{Error, Result};

/// The longest header the reader accepts, in bytes.
const MAX_HEADER_BYTES: usize = 1 << 16;
/// The largest expansion an LZF stream can achieve: a 3-byte back reference yields 264 bytes.
const MAX_LZF_RATIO: usize = 88;
/// Most values (sum of the fields' COUNTs) one point may hold. Descriptor fields reach a few
/// hundred (VFH: 308, SHOT: 352); a larger COUNT is a corrupt header, refused before allocating.
pub const MAX_VALUES_PER_POINT: usize = 1 << 16;

/// How the data section is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PcdFormat {
    /// One text line per point.
    Ascii,
    /// Packed little-endian records.
    Binary,
    /// LZF-compressed, column-major fields.
    BinaryCompressed,
}

impl PcdFormat {
    fn keyword(self) -> &'static str {
        match self {
            PcdFormat::Ascii => "ascii",
            PcdFormat::Binary => "binary",
            PcdFormat::BinaryCompressed => "binary_compressed",
        }
    }
}

/// One field of a PCD header.
#[derive(Debug, Clone, PartialEq)]
struct Field {
    name: String,
    scalar: Scalar,
    count: usize,
}

/// A parsed header: fields, point count, encoding, and where the data starts.
#[derive(Debug)]
struct Header {
    fields: Vec<Field>,
    points: usize,
    format: PcdFormat,
    data_start: usize,
}

fn scalar(kind: &str, size: &str) -> Option<Scalar> {
    Some(match (kind, size) {
        ("I", "1") => Scalar::I8,
        ("U", "1") => Scalar::U8,
        ("I", "2") => Scalar::I16,
        ("U", "2") => Scalar::U16,
        ("I", "4") => Scalar::I32,
        ("U", "4") => Scalar::U32,
        ("I", "8") => Scalar::I64,
        ("U", "8") => Scalar::U64,
        ("F", "4") => Scalar::F32,
        ("F", "8") => Scalar::F64,
        _ => return None,
    })
}

fn type_letter(s: Scalar) -> (&'static str, usize) {
    match s {
        Scalar::I8 | Scalar::I16 | Scalar::I32 | Scalar::I64 => ("I", s.size()),
        Scalar::U8 | Scalar::U16 | Scalar::U32 | Scalar::U64 => ("U", s.size()),
        Scalar::F32 | Scalar::F64 => ("F", s.size()),
    }
}

fn bad(msg: impl Into<String>) -> Error {
    Error::Format(msg.into())
}

fn parse_count(key: &str, v: &str) -> Result<usize> {
    v.parse::<usize>()
        .map_err(|_| bad(format!("{key} {v:?} is not a non-negative integer")))
}

/// The header's lines as read, before they are checked against each other.
#[derive(Default)]
struct RawHeader {
    names: Option<Vec<String>>,
    sizes: Option<Vec<String>>,
    types: Option<Vec<String>>,
    counts: Option<Vec<usize>>,
    width: Option<usize>,
    height: Option<usize>,
    points: Option<usize>,
}

impl RawHeader {
    /// Records one header line other than `DATA`: its upper-cased `key` and its `values`.
    fn read(&mut self, key: &str, values: &[&str], line: &str) -> Result<()> {
        let one = || -> Result<usize> {
            match values {
                [v] => parse_count(key, v),
                _ => Err(bad(format!("{key} needs one value, got {values:?}"))),
            }
        };
        match key {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => {
                self.names = Some(values.iter().map(|s| s.to_string()).collect())
            }
            "SIZE" => self.sizes = Some(values.iter().map(|s| s.to_string()).collect()),
            "TYPE" => self.types = Some(values.iter().map(|s| s.to_ascii_uppercase()).collect()),
            "COUNT" => {
                self.counts = Some(
                    values
                        .iter()
                        .map(|v| parse_count("COUNT", v))
                        .collect::<Result<_>>()?,
                )
            }
            "WIDTH" => self.width = Some(one()?),
            "HEIGHT" => self.height = Some(one()?),
            "POINTS" => self.points = Some(one()?),
            _ => {
                return Err(bad(format!(
                    "unknown header line {:?}: not a PCD v0.7 file",
                    line.chars().take(40).collect::<String>()
                )))
            }
        }
        Ok(())
    }

    /// The fields from FIELDS, SIZE, TYPE and COUNT, checked against each other.
    fn fields(&self) -> Result<Vec<Field>> {
        let names = self
            .names
            .as_ref()
            .ok_or_else(|| bad("the header has no FIELDS line"))?;
        let sizes = self
            .sizes
            .as_ref()
            .ok_or_else(|| bad("the header has no SIZE line"))?;
        let types = self
            .types
            .as_ref()
            .ok_or_else(|| bad("the header has no TYPE line"))?;
        let counts = self.counts.clone().unwrap_or_else(|| vec![1; names.len()]);
        if names.is_empty() {
            return Err(bad("FIELDS is empty"));
        }
        if sizes.len() != names.len() || types.len() != names.len() || counts.len() != names.len() {
            return Err(bad(format!(
                "FIELDS, SIZE, TYPE and COUNT have different lengths ({}, {}, {}, {})",
                names.len(),
                sizes.len(),
                types.len(),
                counts.len()
            )));
        }
        // Each element of a field becomes a column; bound them before anything is allocated per
        // column (a corrupt COUNT once asked for 2e18 column names).
        let values: usize = counts.iter().fold(0usize, |a, &c| a.saturating_add(c));
        if values > MAX_VALUES_PER_POINT {
            return Err(bad(format!(
                "COUNT declares {values} values per point (at most \
                 {MAX_VALUES_PER_POINT}): the header is corrupt"
            )));
        }
        let mut fields = Vec::with_capacity(names.len());
        for (((name, size), kind), count) in names.iter().zip(sizes).zip(types).zip(counts) {
            let s = scalar(kind, size).ok_or_else(|| {
                bad(format!(
                    "field {name:?} has TYPE {kind} SIZE {size}, which PCD does not define"
                ))
            })?;
            if count == 0 {
                return Err(bad(format!("field {name:?} has COUNT 0")));
            }
            fields.push(Field {
                name: name.clone(),
                scalar: s,
                count,
            });
        }
        Ok(fields)
    }

    /// The number of points from POINTS and WIDTH x HEIGHT, which must agree when both are given.
    fn points(&self) -> Result<usize> {
        let from_dims = match (self.width, self.height) {
            (Some(w), Some(h)) => Some(
                w.checked_mul(h)
                    .ok_or_else(|| bad("WIDTH x HEIGHT overflows"))?,
            ),
            (Some(w), None) => Some(w),
            _ => None,
        };
        match (self.points, from_dims) {
            (Some(p), Some(d)) if p != d => Err(bad(format!(
                "POINTS {p} disagrees with WIDTH x HEIGHT = {d}"
            ))),
            (Some(p), _) => Ok(p),
            (None, Some(d)) => Ok(d),
            (None, None) => Err(bad("the header has neither POINTS nor WIDTH")),
        }
    }
}

/// The encoding named by the `DATA` line.
fn data_format(values: &[&str]) -> Result<PcdFormat> {
    match values.first().map(|v| v.to_ascii_lowercase()).as_deref() {
        Some("ascii") => Ok(PcdFormat::Ascii),
        Some("binary") => Ok(PcdFormat::Binary),
        Some("binary_compressed") => Ok(PcdFormat::BinaryCompressed),
        other => Err(bad(format!(
            "DATA {:?}: expected ascii, binary or binary_compressed",
            other.unwrap_or("")
        ))),
    }
}

/// The header line starting at `pos` of `window` (the first bytes of the file, `bytes`), trimmed,
/// and where the next one starts.
fn header_line<'a>(bytes: &[u8], window: &'a [u8], pos: usize) -> Result<(&'a str, usize)> {
    let end = window[pos..]
        .iter()
        .position(|&b| b == b'\n')
        .map(|i| pos + i)
        .ok_or_else(|| {
            bad(if bytes.len() > MAX_HEADER_BYTES {
                "no DATA line in the first 64 KiB: not a PCD file".to_string()
            } else {
                "the header ends before its DATA line (not a PCD file, or truncated)".to_string()
            })
        })?;
    let line = std::str::from_utf8(&window[pos..end])
        .map_err(|_| bad("the header is not text: not a PCD file"))?
        .trim();
    Ok((line, end + 1))
}

/// Parses the header up to and including the `DATA` line.
fn parse_header(bytes: &[u8]) -> Result<Header> {
    let window = &bytes[..bytes.len().min(MAX_HEADER_BYTES)];
    let mut raw = RawHeader::default();
    let mut pos = 0usize;
    while pos < window.len() {
        let (line, next) = header_line(bytes, window, pos)?;
        pos = next;
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut parts = line.split_whitespace();
        let key = parts.next().unwrap_or_default().to_ascii_uppercase();
        let values: Vec<&str> = parts.collect();
        if key == "DATA" {
            let format = data_format(&values)?;
            return Ok(Header {
                fields: raw.fields()?,
                points: raw.points()?,
                format,
                data_start: pos,
            });
        }
        raw.read(&key, &values, line)?;
    }
    Err(bad(
        "the header ends before its DATA line (not a PCD file, or truncated)",
    ))
}

/// One selectable column: field index, element within the field.
struct Column {
    field: usize,
    element: usize,
}

/// The selectable columns of a header (padding `_` fields excluded) and their names.
fn columns(fields: &[Field]) -> (Vec<Column>, Vec<String>) {
    let mut cols = Vec::new();
    let mut names = Vec::new();
    for (f, field) in fields.iter().enumerate() {
        if field.name == "_" {
            continue;
        }
        for e in 0..field.count {
            cols.push(Column {
                field: f,
                element: e,
            });
            names.push(if field.count == 1 {
                field.name.clone()
            } else {
                format!("{}_{e}", field.name)
            });
        }
    }
    (cols, names)
}

/// Parses a PCD file held in memory.
pub(crate) fn parse(bytes: &[u8], fields: &Fields) -> Result<Cloud> {
    let header = parse_header(bytes)?;
    let (cols, available) = columns(&header.fields);
    let (pick, names) = table::select(&available, fields)?;
    let data = bytes.get(header.data_start..).unwrap_or_default();
    let n = header.points;
    let record = header
        .fields
        .iter()
        .try_fold(0usize, |acc, f| {
            f.scalar
                .size()
                .checked_mul(f.count)
                .and_then(|b| acc.checked_add(b))
        })
        .ok_or_else(|| bad("the field sizes overflow"))?;
    let total = n
        .checked_mul(record)
        .ok_or_else(|| bad(format!("POINTS {n} is too large")))?;
    let values = match header.format {
        PcdFormat::Ascii => {
            // Token position of each field's first element.
            let mut first = Vec::with_capacity(header.fields.len());
            let mut tokens = 0usize;
            for f in &header.fields {
                first.push(tokens);
                tokens = tokens.saturating_add(f.count);
            }
            let select: Vec<usize> = pick
                .iter()
                .map(|&c| first[cols[c].field] + cols[c].element)
                .collect();
            let text = std::str::from_utf8(data).map_err(|_| bad("DATA ascii is not text"))?;
            let header_lines = bytes[..header.data_start]
                .iter()
                .filter(|&&b| b == b'\n')
                .count();
            let mut values = table::decode_text_rows(
                text.lines()
                    .enumerate()
                    .map(|(i, l)| (i + header_lines + 1, l)),
                |l| l.split_whitespace().collect(),
                &select,
                tokens,
                Some(n),
            )?;
            let scalars: Vec<Scalar> = pick
                .iter()
                .map(|&c| header.fields[cols[c].field].scalar)
                .collect();
            table::round_f32_columns(&mut values, &scalars);
            values
        }
        PcdFormat::Binary => {
            if data.len() < total {
                return Err(bad(format!(
                    "DATA binary is truncated: {} bytes where {n} points of {record} bytes need {total}",
                    data.len()
                )));
            }
            let mut offsets = Vec::with_capacity(header.fields.len());
            let mut o = 0usize;
            for f in &header.fields {
                offsets.push(o);
                o += f.scalar.size() * f.count;
            }
            let layouts: Vec<Layout> = pick
                .iter()
                .map(|&c| {
                    let f = &header.fields[cols[c].field];
                    Layout {
                        offset: offsets[cols[c].field] + cols[c].element * f.scalar.size(),
                        stride: record,
                        scalar: f.scalar,
                        big_endian: false,
                    }
                })
                .collect();
            table::decode_binary(data, &layouts, n)?
        }
        PcdFormat::BinaryCompressed => {
            let raw = decompress(data, total)?;
            // Column-major: each field's values for all points, field after field.
            let mut starts = Vec::with_capacity(header.fields.len());
            let mut o = 0usize;
            for f in &header.fields {
                starts.push(o);
                o += f.scalar.size() * f.count * n;
            }
            let layouts: Vec<Layout> = pick
                .iter()
                .map(|&c| {
                    let f = &header.fields[cols[c].field];
                    Layout {
                        offset: starts[cols[c].field] + cols[c].element * f.scalar.size(),
                        stride: f.scalar.size() * f.count,
                        scalar: f.scalar,
                        big_endian: false,
                    }
                })
                .collect();
            table::decode_binary(&raw, &layouts, n)?
        }
    };
    Ok(table::finish(values, names, available))
}

/// Decompresses a `binary_compressed` data section: two little-endian `u32` sizes, then LZF.
fn decompress(data: &[u8], expected: usize) -> Result<Vec<u8>> {
    let word = |i: usize| -> Result<usize> {
        data.get(i..i + 4)
            .and_then(|s| <[u8; 4]>::try_from(s).ok())
            .map(|b| u32::from_le_bytes(b) as usize)
            .ok_or_else(|| bad("DATA binary_compressed is truncated before its size words"))
    };
    let compressed = word(0)?;
    let uncompressed = word(4)?;
    if uncompressed != expected {
        return Err(bad(format!(
            "binary_compressed block holds {uncompressed} bytes uncompressed, but the header's \
             fields and POINTS need {expected}"
        )));
    }
    let body = data.get(8..).unwrap_or_default();
    if body.len() < compressed {
        return Err(bad(format!(
            "binary_compressed block is truncated: {} of {compressed} compressed bytes",
            body.len()
        )));
    }
    if expected == 0 {
        return Ok(Vec::new());
    }
    if expected / MAX_LZF_RATIO > compressed {
        return Err(bad(format!(
            "binary_compressed block claims {expected} bytes from {compressed}, more than LZF \
             can expand: the file is corrupt"
        )));
    }
    let out = lzf::decompress(&body[..compressed], expected).map_err(|e| {
        let why = match e {
            lzf::LzfError::BufferTooSmall => "it expands past the declared size".to_string(),
            lzf::LzfError::DataCorrupted => {
                "a back reference points before the start, or the stream ends mid-token".into()
            }
            other => format!("{other:?}"),
        };
        bad(format!(
            "corrupt LZF block in binary_compressed data: {why}"
        ))
    })?;
    if out.len() != expected {
        return Err(bad(format!(
            "binary_compressed block decompresses to {} bytes, not the {expected} declared",
            out.len()
        )));
    }
    Ok(out)
}

/// LZF-compresses `raw`; data LZF cannot shrink is stored as literal runs (still valid LZF).
fn compress(raw: &[u8]) -> Vec<u8> {
    if raw.is_empty() {
        return Vec::new();
    }
    match lzf::compress(raw) {
        Ok(c) => c,
        Err(_) => {
            let mut out = Vec::with_capacity(raw.len() + raw.len() / 32 + 1);
            for chunk in raw.chunks(32) {
                out.push((chunk.len() - 1) as u8);
                out.extend_from_slice(chunk);
            }
            out
        }
    }
}

/// Encodes `v` as `s`, little-endian, into `out`.
fn push_le(out: &mut Vec<u8>, s: Scalar, v: f64) {
    match s {
        Scalar::I8 => out.extend_from_slice(&(v as i8).to_le_bytes()),
        Scalar::U8 => out.extend_from_slice(&(v as u8).to_le_bytes()),
        Scalar::I16 => out.extend_from_slice(&(v as i16).to_le_bytes()),
        Scalar::U16 => out.extend_from_slice(&(v as u16).to_le_bytes()),
        Scalar::I32 => out.extend_from_slice(&(v as i32).to_le_bytes()),
        Scalar::U32 => out.extend_from_slice(&(v as u32).to_le_bytes()),
        Scalar::I64 => out.extend_from_slice(&(v as i64).to_le_bytes()),
        Scalar::U64 => out.extend_from_slice(&(v as u64).to_le_bytes()),
        Scalar::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
        Scalar::F64 => out.extend_from_slice(&v.to_le_bytes()),
    }
}

/// Formats `v` as stored in `s` (shortest round-trip decimal).
fn text_value(s: Scalar, v: f64) -> String {
    match s {
        Scalar::F32 => format!("{}", v as f32),
        Scalar::F64 => format!("{v}"),
        Scalar::U8 | Scalar::U16 | Scalar::U32 | Scalar::U64 => format!("{}", v as u64),
        _ => format!("{}", v as i64),
    }
}

/// The header of an unorganised cloud of `count` points with these columns.
fn table_header(names: &[String], types: &[Scalar], count: usize, format: PcdFormat) -> String {
    let letters: Vec<(&str, usize)> = types.iter().map(|&t| type_letter(t)).collect();
    let join = |f: &dyn Fn(usize) -> String| (0..names.len()).map(f).collect::<Vec<_>>().join(" ");
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\n\
         COUNT {}\nWIDTH {count}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {count}\nDATA {}\n",
        names.join(" "),
        join(&|i| letters[i].1.to_string()),
        join(&|i| letters[i].0.to_string()),
        join(&|_| "1".to_string()),
        format.keyword()
    )
}

/// Writes a table (row-major `data`, one [`Scalar`] per column) as PCD into `out`. Values are
/// converted with `as` (floats to the nearest `f32`, integers truncated and saturated).
pub fn write_table(
    out: &mut Vec<u8>,
    names: &[String],
    types: &[Scalar],
    data: &[f64],
    format: PcdFormat,
) -> Result<()> {
    let k = names.len();
    if k == 0 || types.len() != k || !data.len().is_multiple_of(k) {
        return Err(Error::InvalidInput(format!(
            "{} values, {} names and {} types do not make a table",
            data.len(),
            k,
            types.len()
        )));
    }
    let n = data.len() / k;
    out.extend_from_slice(table_header(names, types, n, format).as_bytes());
    match format {
        PcdFormat::Ascii => {
            for row in data.chunks_exact(k) {
                let line: Vec<String> = row
                    .iter()
                    .zip(types)
                    .map(|(&v, &t)| text_value(t, v))
                    .collect();
                out.extend_from_slice(line.join(" ").as_bytes());
                out.push(b'\n');
            }
        }
        PcdFormat::Binary => {
            for row in data.chunks_exact(k) {
                for (&v, &t) in row.iter().zip(types) {
                    push_le(out, t, v);
                }
            }
        }
        PcdFormat::BinaryCompressed => {
            let mut raw = Vec::new();
            for (c, &t) in types.iter().enumerate() {
                for r in 0..n {
                    push_le(&mut raw, t, data[r * k + c]);
                }
            }
            let packed = compress(&raw);
            let size = |v: usize| {
                u32::try_from(v).map_err(|_| {
                    Error::InvalidInput(format!(
                        "binary_compressed PCD holds at most 4 GiB; this cloud needs {v} bytes"
                    ))
                })
            };
            out.extend_from_slice(&size(packed.len())?.to_le_bytes());
            out.extend_from_slice(&size(raw.len())?.to_le_bytes());
            out.extend_from_slice(&packed);
        }
    }
    Ok(())
}

/// One point to write.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcdPoint {
    /// Position, metres (written as `f32`).
    pub position: Point3<f64>,
    /// Intensity (written as `f32`).
    pub intensity: f64,
    /// Ring index (written as `U 2` only when requested).
    pub ring: u16,
}

/// Writes `points` (`x y z intensity` as `F 4`, and `ring` as `U 2` when `with_ring`) as PCD to
/// `writer`. Errors for non-finite coordinates or intensities (PCD readers choke on them) and for
/// I/O failures ([`Error::Io`]).
pub fn write_pcd<W: Write>(
    mut writer: W,
    points: &[PcdPoint],
    with_ring: bool,
    format: PcdFormat,
) -> Result<()> {
    let mut names: Vec<String> = ["x", "y", "z", "intensity"].map(String::from).to_vec();
    let mut types = vec![Scalar::F32; 4];
    if with_ring {
        names.push("ring".into());
        types.push(Scalar::U16);
    }
    let mut data = Vec::with_capacity(points.len() * names.len());
    for p in points {
        data.extend_from_slice(&[p.position.x, p.position.y, p.position.z, p.intensity]);
        if with_ring {
            data.push(f64::from(p.ring));
        }
    }
    crate::error::ensure_finite("points", data.iter())?;
    let mut bytes = Vec::new();
    write_table(&mut bytes, &names, &types, &data, format)?;
    writer.write_all(&bytes).map_err(|e| Error::Io {
        kind: e.kind(),
        message: format!("writing PCD data: {e}"),
    })
}

/// Writes `points` as a PCD file at `path` (created or truncated).
pub fn write_pcd_file(
    path: &Path,
    points: &[PcdPoint],
    with_ring: bool,
    format: PcdFormat,
) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| io_error(path, &e))?;
    write_pcd(std::io::BufWriter::new(file), points, with_ring, format).map_err(|e| match e {
        Error::Io { kind, message } => Error::Io {
            kind,
            message: format!("{}: {message}", path.display()),
        },
        other => other,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{parse_points, FileFormat};

    fn sample() -> Vec<PcdPoint> {
        (0..5)
            .map(|i| PcdPoint {
                position: Point3::new(i as f64 * 0.5, -1.25, 3.0 + i as f64),
                intensity: 10.0 * i as f64,
                ring: i as u16 + 7,
            })
            .collect()
    }

    fn expected(points: &[PcdPoint]) -> Vec<f64> {
        points
            .iter()
            .flat_map(|p| {
                [
                    p.position.x,
                    p.position.y,
                    p.position.z,
                    p.intensity,
                    f64::from(p.ring),
                ]
            })
            .collect()
    }

    #[test]
    fn every_encoding_round_trips() {
        let pts = sample();
        for format in [
            PcdFormat::Ascii,
            PcdFormat::Binary,
            PcdFormat::BinaryCompressed,
        ] {
            let mut bytes = Vec::new();
            write_pcd(&mut bytes, &pts, true, format).unwrap();
            let cloud = parse_points(&bytes, FileFormat::Pcd, &Fields::All).unwrap();
            assert_eq!(
                cloud.names,
                ["x", "y", "z", "intensity", "ring"],
                "{format:?}"
            );
            assert_eq!(cloud.data, expected(&pts), "{format:?}");
            assert_eq!(cloud.dropped, 0);
        }
    }

    #[test]
    fn binary_layout_is_packed() {
        let mut bytes = Vec::new();
        write_pcd(&mut bytes, &sample(), true, PcdFormat::Binary).unwrap();
        let header = parse_header(&bytes).unwrap();
        assert_eq!(bytes.len() - header.data_start, 5 * 18);
        assert_eq!(header.points, 5);
    }

    #[test]
    fn padding_count_and_field_order() {
        // x y z padding(4 bytes) then a 3-element normal, in a shuffled order: normal first.
        let mut bytes = b"VERSION .7\nFIELDS n z y x _\nSIZE 4 4 4 4 1\nTYPE F F F F U\n\
            COUNT 3 1 1 1 4\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n"
            .to_vec();
        for p in 0..2u8 {
            for v in [0.1, 0.2, 0.3, 3.0, 2.0, 1.0] {
                bytes.extend_from_slice(&(v as f32 + f32::from(p)).to_le_bytes());
            }
            bytes.extend_from_slice(&[0xAA; 4]);
        }
        let cloud = parse_points(&bytes, FileFormat::Pcd, &Fields::Default).unwrap();
        assert_eq!(cloud.names, ["x", "y", "z"]);
        assert_eq!(cloud.data, [1.0, 2.0, 3.0, 2.0, 3.0, 4.0]);
        assert_eq!(cloud.available, ["n_0", "n_1", "n_2", "z", "y", "x"]);
        let n = parse_points(&bytes, FileFormat::Pcd, &Fields::Named(vec!["n_2".into()])).unwrap();
        assert_eq!(n.data, [0.3f32 as f64, 1.3f32 as f64]);
    }

    #[test]
    fn nan_points_are_dropped() {
        let text = b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 1\nDATA ascii\n\
            1 2 3\nnan nan nan\n4 5 6\n";
        let cloud = parse_points(text, FileFormat::Pcd, &Fields::Default).unwrap();
        assert_eq!(cloud.data, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(cloud.dropped, 1);
    }

    fn err(bytes: &[u8]) -> String {
        match parse_points(bytes, FileFormat::Pcd, &Fields::Default) {
            Err(Error::Format(m)) => m,
            other => panic!("expected a format error, got {other:?}"),
        }
    }

    #[test]
    fn malformed_files_are_explained() {
        let mut good = Vec::new();
        write_pcd(&mut good, &sample(), false, PcdFormat::Binary).unwrap();
        assert!(err(&good[..good.len() - 3]).contains("truncated"));
        assert!(err(b"hello world\n").contains("unknown header line"));
        assert!(
            err(b"FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nDATA binary\n")
                .contains("different lengths")
        );
        assert!(
            err(b"FIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nWIDTH 1\nDATA binary\n")
                .contains("does not define")
        );
        assert!(
            err(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA zip\n")
                .contains("DATA \"zip\"")
        );
        assert!(
            err(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 3\nDATA ascii\n")
                .contains("disagrees")
        );
        assert!(
            err(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nDATA ascii\n1 2 3\n")
                .contains("1 of 2 points")
        );
        assert!(
            err(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n1 2 b\n")
                .contains("\"b\" is not a number")
        );
        assert!(
            err(b"FIELDS a b c\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nDATA ascii\n")
                .contains("no field 'x'")
        );
    }

    #[test]
    fn corrupt_compressed_blocks_are_explained() {
        let mut good = Vec::new();
        write_pcd(&mut good, &sample(), false, PcdFormat::BinaryCompressed).unwrap();
        let start = parse_header(&good).unwrap().data_start;
        // Wrong uncompressed size.
        let mut b = good.clone();
        b[start + 4] ^= 1;
        assert!(err(&b).contains("uncompressed"));
        // A back reference before the start of the output.
        let mut b = good[..start].to_vec();
        b.extend_from_slice(&3u32.to_le_bytes());
        b.extend_from_slice(&80u32.to_le_bytes());
        b.extend_from_slice(&[0xE0, 0xFF, 0xFF]);
        assert!(err(&b).contains("corrupt LZF"), "{}", err(&b));
        // Claims far more than it could expand to.
        let mut b = b"FIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nWIDTH 100000\nDATA binary_compressed\n"
            .to_vec();
        b.extend_from_slice(&4u32.to_le_bytes());
        b.extend_from_slice(&2_400_000u32.to_le_bytes());
        b.extend_from_slice(&[0; 4]);
        assert!(err(&b).contains("more than LZF"));
        // Truncated compressed body.
        assert!(err(&good[..good.len() - 2]).contains("truncated"));
    }

    #[test]
    fn write_errors_are_reported() {
        let mut pts = sample();
        pts[1].intensity = f64::NAN;
        assert!(matches!(
            write_pcd(Vec::new(), &pts, false, PcdFormat::Ascii),
            Err(Error::InvalidInput(_))
        ));
        let missing = Path::new("/nonexistent-dir-lidarcal/x.pcd");
        assert!(matches!(
            write_pcd_file(missing, &sample(), false, PcdFormat::Binary),
            Err(Error::Io { message, kind: std::io::ErrorKind::NotFound }) if message.contains("nonexistent-dir-lidarcal")
        ));
    }
}
