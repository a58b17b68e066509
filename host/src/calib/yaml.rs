//! The subset of OpenCV FileStorage YAML that stereo calibrations use, read
//! and written by hand (serde_yaml rejects the `%YAML:1.0` directive and the
//! `!!opencv-matrix` tag).
//!
//! Read: a `%YAML:1.0` (OpenCV ≤ 4) or `%YAML 1.2` (OpenCV 5) header, an
//! optional `---`, then top-level `key: value` entries. A value is a number,
//! a (quoted) string, a flow sequence `[ a, b, … ]`, or an
//! `!!opencv-matrix` mapping with `rows`, `cols`, `dt` and `data`, whose
//! flow sequence may span several lines. Other nested mappings are skipped.
//! Numbers follow YAML: `1.`, `-2.5e-03`, `.Nan`, `.Inf`, `-.Inf`.
//!
//! Written: exactly the bytes `cv2.FileStorage` writes for double matrices
//! (`%YAML:1.0`, `---`, 3-space indent, `dt: d`, `%.17g` numbers, OpenCV's
//! line wrapping); `synth` writes its `calibration.yml` through this writer.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use crate::error::InputError;

/// One top-level value of a FileStorage file.
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    /// A number (integers are stored exactly in an `f64`).
    Number(f64),
    /// Any other scalar, unquoted.
    Text(String),
    /// A `rows × cols` matrix, row-major (`!!opencv-matrix`), or a flow
    /// sequence of numbers (stored as `1 × n`).
    Matrix {
        /// Number of rows.
        rows: usize,
        /// Number of columns.
        cols: usize,
        /// `rows * cols` values, row-major.
        data: Vec<f64>,
    },
    /// A nested mapping this reader does not interpret.
    Other,
}

/// Parses a YAML number the way OpenCV writes them (`.Nan`, `.Inf` included).
pub fn parse_number(s: &str) -> Option<f64> {
    let t = s.trim();
    match t {
        ".nan" | ".NaN" | ".Nan" | ".NAN" => return Some(f64::NAN),
        ".inf" | ".Inf" | ".INF" | "+.inf" | "+.Inf" | "+.INF" => return Some(f64::INFINITY),
        "-.inf" | "-.Inf" | "-.INF" => return Some(f64::NEG_INFINITY),
        _ => {}
    }
    if t.is_empty()
        || !t
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '+' | '-' | '.' | 'e' | 'E'))
    {
        return None;
    }
    t.parse::<f64>().ok()
}

fn strip_comment(line: &str) -> &str {
    // '#' starts a comment unless inside quotes (OpenCV never quotes '#').
    let mut in_quote = None;
    for (i, c) in line.char_indices() {
        match (c, in_quote) {
            ('"' | '\'', None) => in_quote = Some(c),
            (q, Some(open)) if q == open => in_quote = None,
            ('#', None) => return &line[..i],
            _ => {}
        }
    }
    line
}

fn unquote(s: &str) -> String {
    let t = s.trim();
    if t.len() >= 2
        && ((t.starts_with('"') && t.ends_with('"')) || (t.starts_with('\'') && t.ends_with('\'')))
    {
        t[1..t.len() - 1].to_string()
    } else {
        t.to_string()
    }
}

/// Parses the numbers of a flow sequence body (without the brackets).
fn parse_seq(path: &Path, key: &str, body: &str) -> Result<Vec<f64>, InputError> {
    let mut out = Vec::new();
    for tok in body.split(',') {
        let tok = tok.trim();
        if tok.is_empty() {
            continue;
        }
        let v = parse_number(tok).ok_or_else(|| {
            InputError::key(
                path,
                key,
                format!("`{tok}` in the data list is not a number"),
            )
        })?;
        out.push(v);
    }
    Ok(out)
}

/// Text between the first `[` and its matching `]` (no nesting in OpenCV
/// matrices), or an error naming the key.
fn bracketed<'a>(path: &Path, key: &str, s: &'a str) -> Result<&'a str, InputError> {
    let open = s
        .find('[')
        .ok_or_else(|| InputError::key(path, key, "expected a `[ … ]` list"))?;
    let close = s[open..]
        .find(']')
        .ok_or_else(|| InputError::key(path, key, "the `[` list is never closed with `]`"))?;
    Ok(&s[open + 1..open + close])
}

fn parse_matrix(path: &Path, key: &str, body: &str) -> Result<Node, InputError> {
    // body: the text after `key:`, the mapping's indented lines joined with '\n'.
    let mut rows = None;
    let mut cols = None;
    let mut data = None;
    let mut offset = 0;
    for line in body.split('\n') {
        let start = offset;
        offset += line.len() + 1;
        let line = line.trim();
        if let Some(v) = line.strip_prefix("rows:") {
            rows = Some(v.trim().parse::<usize>().map_err(|_| {
                InputError::key(path, key, format!("`rows: {}` is not a count", v.trim()))
            })?);
        } else if let Some(v) = line.strip_prefix("cols:") {
            cols = Some(v.trim().parse::<usize>().map_err(|_| {
                InputError::key(path, key, format!("`cols: {}` is not a count", v.trim()))
            })?);
        } else if line.starts_with("data:") {
            // the list may span this and the following lines
            let seq = bracketed(path, key, &body[start..])?;
            data = Some(parse_seq(path, key, seq)?);
            break;
        }
    }
    let rows = rows.ok_or_else(|| InputError::key(path, key, "matrix has no `rows`"))?;
    let cols = cols.ok_or_else(|| InputError::key(path, key, "matrix has no `cols`"))?;
    let data = data.ok_or_else(|| InputError::key(path, key, "matrix has no `data`"))?;
    if rows.checked_mul(cols) != Some(data.len()) {
        return Err(InputError::key(
            path,
            key,
            format!(
                "matrix says {rows}x{cols} but `data` holds {} values",
                data.len()
            ),
        ));
    }
    Ok(Node::Matrix { rows, cols, data })
}

/// Reads a FileStorage YAML text into its top-level entries. `path` is only
/// used in error messages.
pub fn parse(path: &Path, text: &str) -> Result<BTreeMap<String, Node>, InputError> {
    let mut lines = text.lines().peekable();
    match lines.peek() {
        Some(first) if first.trim_start().starts_with("%YAML") => {
            lines.next();
        }
        _ => return Err(InputError::file(
            path,
            "not an OpenCV FileStorage YAML file (first line is not `%YAML:1.0` or `%YAML 1.2`)",
        )),
    }
    // Group lines into top-level entries: an entry starts with a non-indented
    // `key:` line; indented lines continue it.
    let mut entries: Vec<(usize, String, String)> = Vec::new(); // (line no, key, text)
    for (no, raw) in lines.enumerate() {
        let line_no = no + 2;
        let line = strip_comment(raw);
        if line.trim().is_empty() || line.trim() == "---" || line.trim() == "..." {
            continue;
        }
        if !line.starts_with(' ') && !line.starts_with('\t') {
            let colon = line.find(':').ok_or_else(|| {
                InputError::file(
                    path,
                    format!(
                        "line {line_no}: expected `key: value`, found `{}`",
                        line.trim()
                    ),
                )
            })?;
            let key = unquote(&line[..colon]);
            entries.push((line_no, key, line[colon + 1..].to_string()));
        } else if let Some(last) = entries.last_mut() {
            last.2.push('\n');
            last.2.push_str(line);
        } else {
            return Err(InputError::file(
                path,
                format!("line {line_no}: indented text before any key"),
            ));
        }
    }
    let mut out = BTreeMap::new();
    for (line_no, key, value) in entries {
        let head = value.lines().next().unwrap_or("").trim();
        let node = if head.starts_with("!!opencv-matrix") {
            parse_matrix(path, &key, &value)?
        } else if head.starts_with('[') {
            let seq = bracketed(path, &key, &value)?;
            let data = parse_seq(path, &key, seq)?;
            Node::Matrix {
                rows: 1,
                cols: data.len(),
                data,
            }
        } else if head.is_empty() || head.starts_with("!!") || head.starts_with('{') {
            Node::Other
        } else if let Some(v) = parse_number(head) {
            Node::Number(v)
        } else {
            Node::Text(unquote(head))
        };
        if out.insert(key.clone(), node).is_some() {
            return Err(InputError::key(
                path,
                &key,
                format!("line {line_no}: key appears twice"),
            ));
        }
    }
    Ok(out)
}

/// OpenCV's YAML wrap margin (`CV_FS_MAX_LEN`-based flow-sequence wrap).
const WRAP_MARGIN: usize = 71;
/// Indent of a continuation line inside a matrix's `data: [ … ]`.
const DATA_INDENT: usize = 7;

/// Formats a double as OpenCV's FileStorage does (`icvDoubleToString`):
/// integral values below 2³¹ as `%d.` (`1.`, `0.`, `-3.`), others as C's
/// `%.17g` (`0.050000000000000003`, `9.9999999999999995e-21`), `.Nan`,
/// `.Inf`, `-.Inf` for non-finite values. `%.17g` reads back to the same
/// `f64`, so a written calibration round-trips bit-exactly.
pub fn format_double(v: f64) -> String {
    if v.is_nan() {
        return ".Nan".into();
    }
    if v.is_infinite() {
        return if v > 0.0 {
            ".Inf".into()
        } else {
            "-.Inf".into()
        };
    }
    let rounded = v.round();
    if rounded == v && rounded.abs() < 2_147_483_647.0 {
        return format!("{}.", rounded as i64);
    }
    format_g17(v)
}

/// C's `%.17g`.
fn format_g17(v: f64) -> String {
    const P: i32 = 17;
    // Exponent after rounding to P significant digits.
    let sci = format!("{:.*e}", (P - 1) as usize, v);
    let (mant, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    if !(-4..P).contains(&exp) {
        let mant = trim_zeros(mant);
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{mant}e{sign}{:02}", exp.abs())
    } else {
        let decimals = (P - 1 - exp).max(0) as usize;
        trim_zeros(&format!("{v:.decimals$}")).to_string()
    }
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// Writes the header of a FileStorage YAML file.
pub fn header() -> String {
    "%YAML:1.0\n---\n".to_string()
}

/// Appends `key: value` for an integer scalar.
pub fn write_int(out: &mut String, key: &str, v: i64) {
    let _ = writeln!(out, "{key}: {v}");
}

/// Appends a `rows × cols` double matrix as an `!!opencv-matrix` node, laid
/// out byte for byte as `cv2.FileStorage` writes it: 3-space indent, `dt: d`,
/// numbers by [`format_double`], the `data` flow sequence wrapped at OpenCV's
/// margin of 71 columns with a 7-space continuation indent.
pub fn write_matrix(out: &mut String, key: &str, rows: usize, cols: usize, data: &[f64]) {
    let _ = writeln!(out, "{key}: !!opencv-matrix");
    let _ = writeln!(out, "   rows: {rows}");
    let _ = writeln!(out, "   cols: {cols}");
    let _ = writeln!(out, "   dt: d");
    let mut line = String::from("   data: [");
    for (i, v) in data.iter().enumerate() {
        let s = format_double(*v);
        if i > 0 {
            line.push(',');
        }
        let new_offset = line.len() + s.len();
        if i > 0 && new_offset > WRAP_MARGIN && new_offset - DATA_INDENT > 10 {
            out.push_str(&line);
            out.push('\n');
            line = " ".repeat(DATA_INDENT);
        } else {
            line.push(' ');
        }
        line.push_str(&s);
    }
    line.push_str(" ]\n");
    out.push_str(&line);
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "%YAML:1.0\n---\nimage_width: 640\nname: \"left cam\"\nM1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 5.0e+02, 0., 3.195e+02, 0., 5.0e+02,\n       2.395e+02, 0., 0., 1. ]\nD1: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ -0.1, .Nan, -.Inf, 0. ]\nseq: [ 1, 2, 3 ]\n";

    #[test]
    fn reads_multiline_matrices_scalars_and_nan() {
        let m = parse(Path::new("x.yml"), SAMPLE).unwrap();
        assert_eq!(m["image_width"], Node::Number(640.0));
        assert_eq!(m["name"], Node::Text("left cam".into()));
        match &m["M1"] {
            Node::Matrix { rows, cols, data } => {
                assert_eq!((*rows, *cols), (3, 3));
                assert_eq!(data[2], 319.5);
                assert_eq!(data[5], 239.5);
                assert_eq!(data[8], 1.0);
            }
            other => panic!("{other:?}"),
        }
        match &m["D1"] {
            Node::Matrix { data, .. } => {
                assert!(data[1].is_nan());
                assert_eq!(data[2], f64::NEG_INFINITY);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            m["seq"],
            Node::Matrix {
                rows: 1,
                cols: 3,
                data: vec![1.0, 2.0, 3.0]
            }
        );
    }

    #[test]
    fn writer_round_trips_exactly() {
        let data = [
            412.5,
            0.0,
            158.3,
            -1.0e-7,
            1.0 / 3.0,
            -0.21,
            1e300,
            -2.5,
            1.0,
        ];
        let mut s = header();
        write_int(&mut s, "image_width", 320);
        write_matrix(&mut s, "M1", 3, 3, &data);
        let m = parse(Path::new("w.yml"), &s).unwrap();
        assert_eq!(
            m["M1"],
            Node::Matrix {
                rows: 3,
                cols: 3,
                data: data.to_vec()
            }
        );
        assert_eq!(m["image_width"], Node::Number(320.0));
    }

    #[test]
    fn doubles_format_as_opencv() {
        assert_eq!(format_double(0.0), "0.");
        assert_eq!(format_double(-0.0), "0.");
        assert_eq!(format_double(1.0), "1.");
        assert_eq!(format_double(123456789.0), "123456789.");
        assert_eq!(format_double(1967.123456789012), "1967.1234567890119");
        assert_eq!(format_double(-0.1234567890123), "-0.12345678901230001");
        assert_eq!(format_double(0.05), "0.050000000000000003");
        assert_eq!(format_double(1e-4), "0.0001");
        assert_eq!(format_double(-2e-4), "-0.00020000000000000001");
        assert_eq!(format_double(1e-20), "9.9999999999999995e-21");
        assert_eq!(format_double(1.0 / 3.0), "0.33333333333333331");
        assert_eq!(format_double(1023.5), "1023.5");
        assert_eq!(format_double(f64::NAN), ".Nan");
        assert_eq!(format_double(f64::NEG_INFINITY), "-.Inf");
    }

    proptest::proptest! {
        /// `%.17g` reads back to the same double.
        #[test]
        fn formatted_doubles_read_back_exactly(bits in proptest::prelude::any::<u64>()) {
            let v = f64::from_bits(bits);
            proptest::prop_assume!(v.is_finite());
            let back = parse_number(&format_double(v)).unwrap();
            proptest::prop_assert_eq!(back.to_bits(), (v + 0.0).to_bits());
        }
    }

    proptest::proptest! {
        #[test]
        fn never_panics_on_garbage(body in "(\\PC|\n| |:|\\[|\\]|,|!!opencv-matrix|rows: |cols: |data: ){0,120}") {
            let _ = parse(Path::new("g.yml"), &format!("%YAML:1.0\n{body}"));
        }
    }

    #[test]
    fn rejects_bad_text_naming_the_key() {
        let bad = "%YAML:1.0\nM1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1, 2, 3 ]\n";
        let e = parse(Path::new("c.yml"), bad).unwrap_err().to_string();
        assert!(
            e.contains("c.yml") && e.contains("`M1`") && e.contains("3x3"),
            "{e}"
        );
        let bad = "%YAML:1.0\nM1: !!opencv-matrix\n   rows: 1\n   cols: 2\n   dt: d\n   data: [ 1, abc ]\n";
        let e = parse(Path::new("c.yml"), bad).unwrap_err().to_string();
        assert!(e.contains("`M1`") && e.contains("abc"), "{e}");
        let e = parse(Path::new("c.yml"), "M1: 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("c.yml") && e.contains("%YAML"), "{e}");
    }
}
