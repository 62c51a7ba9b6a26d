//! PLY (the Stanford polygon format): the `vertex` element of `ascii`, `binary_little_endian` and
//! `binary_big_endian` files, with any scalar properties in any order. Elements before `vertex`
//! (rare) are skipped, including their list properties; list properties inside `vertex` are
//! refused with a clear error. The writer stores `binary_little_endian` `float` properties.
//!
//! ```
//! use lidarcal::io::{parse_points, Fields, FileFormat};
//! let ply = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
//!     property float z\nproperty uchar scalar_intensity\nend_header\n1 2 3 7\n4 5 6 9\n";
//! let cloud = parse_points(ply, FileFormat::Ply, &Fields::Default)?;
//! assert_eq!(cloud.names, ["x", "y", "z", "intensity"]);
//! assert_eq!(cloud.data, [1.0, 2.0, 3.0, 7.0, 4.0, 5.0, 6.0, 9.0]);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use super::table::{self, Layout, Scalar};
use super::{Cloud, Fields};
use crate::error::{Error, Result};

const MAX_HEADER_BYTES: usize = 1 << 16;

fn bad(msg: impl Into<String>) -> Error {
    Error::Format(msg.into())
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

#[derive(Debug, Clone)]
enum Property {
    Scalar { name: String, scalar: Scalar },
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

fn scalar(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

fn scalar_of(name: &str) -> Result<Scalar> {
    scalar(name).ok_or_else(|| bad(format!("unknown property type {name:?}")))
}

/// Parses the header: encoding, elements, and where the body starts.
fn parse_header(bytes: &[u8]) -> Result<(Encoding, Vec<Element>, usize)> {
    if !bytes.starts_with(b"ply") {
        return Err(bad("does not start with \"ply\": not a PLY file"));
    }
    let window = &bytes[..bytes.len().min(MAX_HEADER_BYTES)];
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut pos = 0usize;
    while pos < window.len() {
        let end = window[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map(|i| pos + i)
            .ok_or_else(|| bad("the header has no end_header line (truncated?)"))?;
        let line = std::str::from_utf8(&window[pos..end])
            .map_err(|_| bad("the header is not text"))?
            .trim();
        pos = end + 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["ply"] | [] => {}
            ["comment", ..] | ["obj_info", ..] => {}
            ["format", kind, _version] => {
                encoding = Some(match *kind {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::Little,
                    "binary_big_endian" => Encoding::Big,
                    other => return Err(bad(format!("unknown PLY format {other:?}"))),
                })
            }
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| bad(format!("element {name}: count {count:?} is not a number")))?,
                properties: Vec::new(),
            }),
            ["property", "list", count, item, _name] => {
                let list = Property::List {
                    count: scalar_of(count)?,
                    item: scalar_of(item)?,
                };
                elements
                    .last_mut()
                    .ok_or_else(|| bad("a property comes before any element"))?
                    .properties
                    .push(list);
            }
            ["property", kind, name] => {
                let p = Property::Scalar {
                    name: name.to_string(),
                    scalar: scalar_of(kind)?,
                };
                elements
                    .last_mut()
                    .ok_or_else(|| bad("a property comes before any element"))?
                    .properties
                    .push(p);
            }
            ["end_header"] => {
                let encoding = encoding.ok_or_else(|| bad("the header has no format line"))?;
                return Ok((encoding, elements, pos));
            }
            _ => {
                return Err(bad(format!(
                    "unexpected header line {:?}",
                    line.chars().take(40).collect::<String>()
                )))
            }
        }
    }
    Err(bad("the header has no end_header line (truncated?)"))
}

fn read_uint(bytes: &[u8], at: usize, s: Scalar, big: bool) -> Result<usize> {
    let v = table::decode_binary(
        bytes,
        &[Layout {
            offset: at,
            stride: 0,
            scalar: s,
            big_endian: big,
        }],
        1,
    )?;
    let v = v.first().copied().unwrap_or(-1.0);
    if !(0.0..=(u32::MAX as f64)).contains(&v) || v.fract() != 0.0 {
        return Err(bad(format!("a list length {v} is not a valid count")));
    }
    Ok(v as usize)
}

/// Byte length of the binary records of `e` starting at `start`.
fn skip_binary(bytes: &[u8], start: usize, e: &Element, big: bool) -> Result<usize> {
    let truncated = || bad(format!("element {} is truncated", e.name));
    let has_list = e
        .properties
        .iter()
        .any(|p| matches!(p, Property::List { .. }));
    if !has_list {
        let record: usize = e
            .properties
            .iter()
            .map(|p| match p {
                Property::Scalar { scalar, .. } => scalar.size(),
                Property::List { .. } => 0,
            })
            .sum();
        let len = e.count.checked_mul(record).ok_or_else(truncated)?;
        if start.checked_add(len).is_none_or(|end| end > bytes.len()) {
            return Err(truncated());
        }
        return Ok(len);
    }
    // Every record holds at least one list length, so this loop ends within the buffer.
    let mut pos = start;
    for _ in 0..e.count {
        for p in &e.properties {
            match p {
                Property::Scalar { scalar, .. } => pos = pos.saturating_add(scalar.size()),
                Property::List { count, item } => {
                    let n = read_uint(bytes, pos, *count, big)?;
                    pos = pos
                        .saturating_add(count.size())
                        .saturating_add(n.saturating_mul(item.size()));
                }
            }
            if pos > bytes.len() {
                return Err(truncated());
            }
        }
    }
    Ok(pos - start)
}

/// Parses a PLY file held in memory.
pub(crate) fn parse(bytes: &[u8], fields: &Fields) -> Result<Cloud> {
    let (encoding, elements, body_start) = parse_header(bytes)?;
    let v_index = elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| bad("no vertex element"))?;
    let vertex = &elements[v_index];
    let mut available = Vec::new();
    let mut scalars = Vec::new();
    for p in &vertex.properties {
        match p {
            Property::Scalar { name, scalar } => {
                available.push(name.clone());
                scalars.push(*scalar);
            }
            Property::List { .. } => {
                return Err(bad(
                    "the vertex element has a list property, which point clouds do not use",
                ))
            }
        }
    }
    let (pick, names) = table::select(&available, fields)?;
    let body = bytes.get(body_start..).unwrap_or_default();
    let n = vertex.count;
    let values = match encoding {
        Encoding::Ascii => {
            let text = std::str::from_utf8(body).map_err(|_| bad("the ascii body is not text"))?;
            let header_lines = bytes[..body_start].iter().filter(|&&b| b == b'\n').count();
            let mut lines = text
                .lines()
                .enumerate()
                .map(|(i, l)| (i + header_lines + 1, l))
                .filter(|(_, l)| !l.trim().is_empty());
            // One line per record of the elements before the vertices.
            let skip = elements[..v_index]
                .iter()
                .fold(0usize, |acc, e| acc.saturating_add(e.count));
            for _ in 0..skip {
                if lines.next().is_none() {
                    return Err(bad("the body ends before the vertex element"));
                }
            }
            let mut values = table::decode_text_rows(
                lines,
                |l| l.split_whitespace().collect(),
                &pick,
                available.len(),
                Some(n),
            )?;
            let picked: Vec<Scalar> = pick.iter().map(|&c| scalars[c]).collect();
            table::round_f32_columns(&mut values, &picked);
            values
        }
        Encoding::Little | Encoding::Big => {
            let big = encoding == Encoding::Big;
            let mut start = 0usize;
            for e in &elements[..v_index] {
                start = start.saturating_add(skip_binary(body, start, e, big)?);
            }
            let record: usize = scalars.iter().map(|s| s.size()).sum();
            let need = n.checked_mul(record).and_then(|b| b.checked_add(start));
            if need.is_none_or(|need| need > body.len()) {
                return Err(bad(format!(
                    "the binary body is truncated: {} bytes for {n} vertices of {record} bytes",
                    body.len().saturating_sub(start)
                )));
            }
            let mut offsets = Vec::with_capacity(scalars.len());
            let mut o = start;
            for s in &scalars {
                offsets.push(o);
                o += s.size();
            }
            let layouts: Vec<Layout> = pick
                .iter()
                .map(|&c| Layout {
                    offset: offsets[c],
                    stride: record,
                    scalar: scalars[c],
                    big_endian: big,
                })
                .collect();
            table::decode_binary(body, &layouts, n)?
        }
    };
    Ok(table::finish(values, names, available))
}

/// Writes `data` (row-major, one `float` property per name) as binary little-endian PLY.
pub(crate) fn write(out: &mut Vec<u8>, names: &[String], data: &[f64]) {
    let n = data.len() / names.len().max(1);
    out.extend_from_slice(
        format!("ply\nformat binary_little_endian 1.0\ncomment written by lidarcal\nelement vertex {n}\n")
            .as_bytes(),
    );
    for name in names {
        out.extend_from_slice(format!("property float {name}\n").as_bytes());
    }
    out.extend_from_slice(b"end_header\n");
    for v in data {
        out.extend_from_slice(&(*v as f32).to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{parse_points, FileFormat};

    fn err(bytes: &[u8]) -> String {
        match parse_points(bytes, FileFormat::Ply, &Fields::Default) {
            Err(Error::Format(m)) => m,
            other => panic!("expected a format error, got {other:?}"),
        }
    }

    #[test]
    fn binary_both_endians_and_a_face_element_first() {
        for big in [false, true] {
            let mut b = format!(
                "ply\nformat {} 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
                 element vertex 2\nproperty double z\nproperty float x\nproperty ushort i\n\
                 property float y\nend_header\n",
                if big {
                    "binary_big_endian"
                } else {
                    "binary_little_endian"
                }
            )
            .into_bytes();
            let put = |b: &mut Vec<u8>, bytes_le: Vec<u8>| {
                if big {
                    b.extend(bytes_le.into_iter().rev())
                } else {
                    b.extend(bytes_le)
                }
            };
            b.push(3);
            for i in 0..3i32 {
                put(&mut b, i.to_le_bytes().to_vec());
            }
            for p in 0..2 {
                put(&mut b, (3.0f64 + p as f64).to_le_bytes().to_vec());
                put(&mut b, (1.0f32 + p as f32).to_le_bytes().to_vec());
                put(&mut b, (100u16 + p as u16).to_le_bytes().to_vec());
                put(&mut b, (2.0f32 + p as f32).to_le_bytes().to_vec());
            }
            let c = parse_points(&b, FileFormat::Ply, &Fields::Default).unwrap();
            assert_eq!(
                c.data,
                [1.0, 2.0, 3.0, 100.0, 2.0, 3.0, 4.0, 101.0],
                "big={big}"
            );
            assert!(err(&b[..b.len() - 1]).contains("truncated"));
        }
    }

    #[test]
    fn round_trip() {
        let names: Vec<String> = ["x", "y", "z", "intensity"].map(String::from).to_vec();
        let data = [0.5, -1.0, 2.25, 30.0, 1.0, 2.0, 3.0, 4.0];
        let mut b = Vec::new();
        write(&mut b, &names, &data);
        let c = parse_points(&b, FileFormat::Ply, &Fields::All).unwrap();
        assert_eq!(c.names, names);
        assert_eq!(c.data, data);
    }

    #[test]
    fn malformed_files_are_explained() {
        assert!(err(b"PLY\n").contains("not a PLY file"));
        assert!(
            err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n")
                .contains("end_header")
        );
        assert!(
            err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n")
                .contains("unknown property type")
        );
        assert!(
            err(b"ply\nformat ascii 1.0\nelement vertex x\nend_header\n").contains("not a number")
        );
        assert!(err(
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                property float z\nend_header\n1 2 3\n"
        )
        .contains("1 of 2 points"));
        assert!(err(b"ply\nformat ascii 1.0\nelement face 1\nend_header\n").contains("no vertex"));
        assert!(err(b"ply\nelement vertex 0\nend_header\n").contains("no format line"));
        // A face list claiming 2^32 - 1 indices.
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement face 1\n\
            property list uint int idx\nelement vertex 1\nproperty float x\nproperty float y\n\
            property float z\nend_header\n"
            .to_vec();
        b.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(err(&b).contains("truncated"));
    }
}
