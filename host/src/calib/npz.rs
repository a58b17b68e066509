//! NumPy `.npz` archives (a zip of `.npy` files), as VIAME camtrawl writes
//! its stereo calibration `cal.npz` with `numpy.savez` (stored or deflated).
//!
//! Only what calibrations need: little- or big-endian `f8`, `f4`, `i8`,
//! `i4` arrays of up to two dimensions, C or Fortran order, `.npy` format
//! versions 1 to 3.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use crate::error::InputError;

/// A numeric array read from an `.npy` member, as a row-major matrix
/// (a 1-D array of `n` values is `1 × n`, a 0-D array `1 × 1`).
#[derive(Debug, Clone, PartialEq)]
pub struct Array {
    /// The shape as stored.
    pub shape: Vec<usize>,
    /// Rows of the row-major view.
    pub rows: usize,
    /// Columns of the row-major view.
    pub cols: usize,
    /// Values, row-major.
    pub data: Vec<f64>,
}

fn header_field<'a>(header: &'a str, name: &str) -> Option<&'a str> {
    let pat = format!("'{name}'");
    let at = header.find(&pat)? + pat.len();
    let rest = header[at..].trim_start().strip_prefix(':')?.trim_start();
    Some(rest)
}

/// Parses one `.npy` byte buffer. `key` names the array in errors.
pub fn parse_npy(path: &Path, key: &str, bytes: &[u8]) -> Result<Array, InputError> {
    let err = |m: String| InputError::key(path, key, m);
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(err("not a .npy array (bad magic)".into()));
    }
    let major = bytes[6];
    let (hlen, hstart) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err(err("truncated .npy header".into()));
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => return Err(err(format!(".npy format version {v} is not supported"))),
    };
    let header_bytes = bytes
        .get(hstart..hstart + hlen)
        .ok_or_else(|| err("truncated .npy header".into()))?;
    let header = String::from_utf8_lossy(header_bytes);
    let descr = header_field(&header, "descr")
        .and_then(|r| {
            let q = r.chars().next()?;
            let body = &r[q.len_utf8()..];
            body.find(q).map(|e| &body[..e])
        })
        .ok_or_else(|| err("the .npy header has no 'descr'".into()))?;
    let fortran = header_field(&header, "fortran_order")
        .map(|r| r.starts_with("True"))
        .ok_or_else(|| err("the .npy header has no 'fortran_order'".into()))?;
    let shape_txt = header_field(&header, "shape")
        .and_then(|r| {
            let r = r.strip_prefix('(')?;
            r.find(')').map(|e| &r[..e])
        })
        .ok_or_else(|| err("the .npy header has no 'shape'".into()))?;
    let mut shape = Vec::new();
    for t in shape_txt.split(',') {
        let t = t.trim();
        if t.is_empty() {
            continue;
        }
        shape.push(
            t.parse::<usize>()
                .map_err(|_| err(format!("bad shape `({shape_txt})`")))?,
        );
    }
    let (little, kind, size) = {
        let b = descr.as_bytes();
        if b.len() < 3 {
            return Err(err(format!("unsupported dtype `{descr}`")));
        }
        let little = match b[0] {
            b'<' | b'=' | b'|' => true,
            b'>' => false,
            _ => return Err(err(format!("unsupported dtype `{descr}`"))),
        };
        let size: usize = descr[2..]
            .parse()
            .map_err(|_| err(format!("unsupported dtype `{descr}`")))?;
        (little, b[1], size)
    };
    if !matches!((kind, size), (b'f', 8) | (b'f', 4) | (b'i', 8) | (b'i', 4)) {
        return Err(err(format!(
            "dtype `{descr}` is not supported (float64, float32, int64, int32 are)"
        )));
    }
    let count = shape
        .iter()
        .try_fold(1usize, |a, &n| a.checked_mul(n))
        .ok_or_else(|| err(format!("shape `({shape_txt})` is too large")))?;
    let needed = count
        .checked_mul(size)
        .ok_or_else(|| err(format!("shape `({shape_txt})` is too large")))?;
    let payload = &bytes[hstart + hlen..];
    if payload.len() < needed {
        return Err(err(format!(
            "array data is truncated: {} bytes, {needed} needed",
            payload.len()
        )));
    }
    let mut flat = Vec::with_capacity(count);
    for i in 0..count {
        let mut b = [0u8; 8];
        b[..size].copy_from_slice(&payload[i * size..(i + 1) * size]);
        if !little {
            b[..size].reverse();
        }
        let v = match (kind, size) {
            (b'f', 8) => f64::from_le_bytes(b),
            (b'f', 4) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            (b'i', 8) => i64::from_le_bytes(b) as f64,
            (b'i', 4) => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            _ => {
                return Err(err(format!(
                    "dtype `{descr}` is not supported (float64, float32, int64, int32 are)"
                )))
            }
        };
        flat.push(v);
    }
    let (rows, cols) = match shape.as_slice() {
        [] => (1, 1),
        [n] => (1, *n),
        [r, c] => (*r, *c),
        _ => {
            return Err(err(format!(
                "array has {} dimensions, at most 2 expected",
                shape.len()
            )))
        }
    };
    let data = if fortran && rows > 1 && cols > 1 {
        let mut d = vec![0.0; count];
        for r in 0..rows {
            for c in 0..cols {
                d[r * cols + c] = flat[c * rows + r];
            }
        }
        d
    } else {
        flat
    };
    Ok(Array {
        shape,
        rows,
        cols,
        data,
    })
}

/// Reads every `NAME.npy` member of an `.npz` archive, keyed by `NAME`.
pub fn read_npz(path: &Path) -> Result<BTreeMap<String, Array>, InputError> {
    let file = std::fs::File::open(path)
        .map_err(|e| InputError::file(path, format!("cannot open: {e}")))?;
    let mut zip = zip::ZipArchive::new(file)
        .map_err(|e| InputError::file(path, format!("not a readable .npz (zip) archive: {e}")))?;
    let mut out = BTreeMap::new();
    for i in 0..zip.len() {
        let mut member = zip
            .by_index(i)
            .map_err(|e| InputError::file(path, format!("bad zip member #{i}: {e}")))?;
        let name = member.name().to_string();
        let key = name.strip_suffix(".npy").unwrap_or(&name).to_string();
        let mut bytes = Vec::new();
        member
            .read_to_end(&mut bytes)
            .map_err(|e| InputError::key(path, &key, format!("cannot read the array: {e}")))?;
        out.insert(key.clone(), parse_npy(path, &key, &bytes)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(descr: &str, fortran: bool, shape: &str, payload: &[u8]) -> Vec<u8> {
        let mut h = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}",
            if fortran { "True" } else { "False" }
        );
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut v = b"\x93NUMPY\x01\x00".to_vec();
        v.extend_from_slice(&(h.len() as u16).to_le_bytes());
        v.extend_from_slice(h.as_bytes());
        v.extend_from_slice(payload);
        v
    }

    #[test]
    fn reads_c_and_fortran_order_and_dtypes() {
        let vals: Vec<u8> = (1..=6).flat_map(|i| (i as f64).to_le_bytes()).collect();
        let a = parse_npy(Path::new("c.npz"), "R", &npy("<f8", false, "(2, 3)", &vals)).unwrap();
        assert_eq!((a.rows, a.cols), (2, 3));
        assert_eq!(a.data, vec![1., 2., 3., 4., 5., 6.]);
        let f = parse_npy(Path::new("c.npz"), "R", &npy("<f8", true, "(2, 3)", &vals)).unwrap();
        assert_eq!(f.data, vec![1., 3., 5., 2., 4., 6.]);
        let be: Vec<u8> = [1.5f32, -2.0]
            .iter()
            .flat_map(|v| v.to_be_bytes())
            .collect();
        let b = parse_npy(Path::new("c.npz"), "T", &npy(">f4", false, "(2,)", &be)).unwrap();
        assert_eq!((b.rows, b.cols), (1, 2));
        assert_eq!(b.data, vec![1.5, -2.0]);
    }

    proptest::proptest! {
        #[test]
        fn never_panics_on_garbage(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..200),
                                   header in "\\PC{0,80}") {
            let _ = parse_npy(Path::new("g.npz"), "X", &bytes);
            let mut v = b"\x93NUMPY\x01\x00".to_vec();
            v.extend_from_slice(&(header.len() as u16).to_le_bytes());
            v.extend_from_slice(header.as_bytes());
            v.extend_from_slice(&bytes);
            let _ = parse_npy(Path::new("g.npz"), "X", &v);
        }
    }

    #[test]
    fn rejects_truncated_and_odd_arrays() {
        let vals: Vec<u8> = (1..=5).flat_map(|i| (i as f64).to_le_bytes()).collect();
        let e = parse_npy(Path::new("c.npz"), "R", &npy("<f8", false, "(2, 3)", &vals))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`R`") && e.contains("truncated"), "{e}");
        let e = parse_npy(
            Path::new("c.npz"),
            "R",
            &npy("<c16", false, "(1,)", &[0; 16]),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("not supported"), "{e}");
        let e = parse_npy(Path::new("c.npz"), "R", b"garbage!!!!!")
            .unwrap_err()
            .to_string();
        assert!(e.contains("magic"), "{e}");
        let e = parse_npy(
            Path::new("c.npz"),
            "R",
            &npy("<f8", false, "(99999999999, 99999999999)", &[]),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("too large"), "{e}");
    }
}
