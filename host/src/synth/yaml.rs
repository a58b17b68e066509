//! `calibration.yml` written exactly as OpenCV's `cv::FileStorage` writes
//! YAML: `%YAML:1.0`, `---`, integer scalars, and `!!opencv-matrix` nodes
//! (`rows`, `cols`, `dt: d`, `data` as a flow sequence wrapped at OpenCV's
//! margin of 71 columns with a 7-space continuation indent). Numbers use
//! OpenCV's rule: integral values as `%d.`, others as `%.17g`.

use nalgebra::{Matrix3, Vector3};

use super::rig::Rig;

/// OpenCV's YAML wrap margin.
const WRAP_MARGIN: usize = 71;
/// Indent of a continuation line inside a matrix's `data: [ … ]`.
const DATA_INDENT: usize = 7;

/// Formats a double as OpenCV's FileStorage does.
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

/// Appends one `!!opencv-matrix` node of doubles.
fn write_matrix(out: &mut String, name: &str, rows: usize, cols: usize, data: &[f64]) {
    out.push_str(&format!(
        "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n"
    ));
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

fn mat3(m: &Matrix3<f64>) -> Vec<f64> {
    (0..3)
        .flat_map(|r| (0..3).map(move |c| m[(r, c)]))
        .collect()
}

fn vec3(v: &Vector3<f64>) -> Vec<f64> {
    vec![v.x, v.y, v.z]
}

/// The text of `calibration.yml` for a rig.
pub fn calibration_yaml(rig: &Rig) -> String {
    let mut out = String::from("%YAML:1.0\n---\n");
    out.push_str(&format!("image_width: {}\n", rig.width));
    out.push_str(&format!("image_height: {}\n", rig.height));
    write_matrix(&mut out, "M1", 3, 3, &mat3(&rig.left.matrix()));
    write_matrix(&mut out, "D1", 1, 5, &rig.left.dist);
    write_matrix(&mut out, "M2", 3, 3, &mat3(&rig.right.matrix()));
    write_matrix(&mut out, "D2", 1, 5, &rig.right.dist);
    write_matrix(&mut out, "R", 3, 3, &mat3(&rig.r));
    write_matrix(&mut out, "T", 3, 1, &vec3(&rig.t));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }
}
