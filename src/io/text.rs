//! Delimited text (`.csv`, `.txt`, `.xyz`, `.asc`): one point per line, values separated by commas,
//! semicolons, tabs or spaces (detected from the first data line). A first line that is not all
//! numbers names the columns; otherwise they are `x y z intensity col4 ...`. Lines starting with
//! `#` and blank lines are skipped. The writer uses commas for `.csv` and spaces otherwise, with a
//! header line.
//!
//! ```
//! use lidarcal::io::{parse_points, Fields, FileFormat};
//! let cloud = parse_points(b"# a scan\n1 2 3\n4 5 6\n", FileFormat::Text, &Fields::Default)?;
//! assert_eq!(cloud.names, ["x", "y", "z"]);
//! assert_eq!(cloud.len(), 2);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use std::path::Path;

use super::table;
use super::{Cloud, Fields};
use crate::error::{Error, Result};

fn bad(msg: impl Into<String>) -> Error {
    Error::Format(msg.into())
}

fn delimiter(line: &str) -> Option<char> {
    [',', ';', '\t'].into_iter().find(|&d| line.contains(d))
}

fn split(line: &str, delim: Option<char>) -> Vec<&str> {
    match delim {
        Some(d) => line.split(d).map(str::trim).collect(),
        None => line.split_whitespace().collect(),
    }
}

/// Parses delimited text held in memory.
pub(crate) fn parse(bytes: &[u8], fields: &Fields) -> Result<Cloud> {
    let text = std::str::from_utf8(bytes).map_err(|_| bad("not UTF-8 text"))?;
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
        .peekable();
    let Some(&(_, first)) = lines.peek() else {
        return Err(bad("no data lines"));
    };
    let delim = delimiter(first);
    let tokens = split(first, delim);
    let is_header = tokens.iter().any(|t| t.parse::<f64>().is_err());
    let available: Vec<String> = if is_header {
        lines.next();
        tokens
            .iter()
            .map(|t| t.trim_matches(|c| c == '"' || c == '\'').to_string())
            .collect()
    } else {
        table::default_names(tokens.len())
    };
    let (pick, names) = table::select(&available, fields)?;
    let values = table::decode_text_rows(lines, |l| split(l, delim), &pick, available.len(), None)?;
    Ok(table::finish(values, names, available))
}

/// Writes a header line and one line per point, with commas for `.csv` and spaces otherwise.
pub(crate) fn write(out: &mut Vec<u8>, names: &[String], data: &[f64], path: &Path) {
    let csv = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let sep = if csv { "," } else { " " };
    out.extend_from_slice(names.join(sep).as_bytes());
    out.push(b'\n');
    for row in data.chunks_exact(names.len().max(1)) {
        let line: Vec<String> = row.iter().map(|v| format!("{v}")).collect();
        out.extend_from_slice(line.join(sep).as_bytes());
        out.push(b'\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{parse_points, FileFormat};

    #[test]
    fn headers_delimiters_and_errors() {
        let c = parse_points(b"X;Y;Z;i\n1;2;3;4\n", FileFormat::Text, &Fields::Default).unwrap();
        assert_eq!(c.data, [1.0, 2.0, 3.0, 4.0]);
        let c = parse_points(b"1\t2\t3\n", FileFormat::Text, &Fields::Default).unwrap();
        assert_eq!(c.names, ["x", "y", "z"]);
        let e = parse_points(b"1,2,3\n4,5\n", FileFormat::Text, &Fields::Default).unwrap_err();
        assert!(e.to_string().contains("line 2: 2 value(s) where 3"), "{e}");
        let e = parse_points(b"# nothing\n", FileFormat::Text, &Fields::Default).unwrap_err();
        assert!(e.to_string().contains("no data lines"));
        let e = parse_points(b"1,2\n", FileFormat::Text, &Fields::Default).unwrap_err();
        assert!(e.to_string().contains("no field 'z'"));
    }

    #[test]
    fn round_trip() {
        let names: Vec<String> = ["x", "y", "z", "ring"].map(String::from).to_vec();
        let data = [0.1, 1e-300, -3.5, 7.0];
        for ext in ["a.csv", "a.txt"] {
            let mut b = Vec::new();
            write(&mut b, &names, &data, Path::new(ext));
            let c = parse_points(&b, FileFormat::Text, &Fields::All).unwrap();
            assert_eq!(c.names, names);
            assert_eq!(c.data, data);
        }
    }
}
