//! Box overlap and per-frame one-to-one matching.
//!
//! Boxes are `[x, y, w, h]` (upright, raw pixels). IoU is computed exactly as
//! `motmetrics.distances.boxiou` does (same operations in the same order, so
//! the floating-point result is bit-identical), and the matching distance is
//! `1 − IoU`, forbidden (`NaN`) where it exceeds `max_distance` — motmetrics'
//! `iou_matrix(objs, hyps, max_iou=max_distance)`. Our evaluation uses
//! `max_distance = 0.6`, i.e. a pair may match when IoU ≥ 0.4.

use super::lsap;

/// The evaluation's matching threshold on `1 − IoU` (IoU ≥ 0.4).
pub const MAX_DISTANCE: f64 = 0.6;

/// Intersection over union of two `[x, y, w, h]` boxes (motmetrics `boxiou`).
pub fn iou(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    let (a_max_x, a_max_y) = (a[0] + a[2], a[1] + a[3]);
    let (b_max_x, b_max_y) = (b[0] + b[2], b[1] + b[3]);
    let ix = (a_max_x.min(b_max_x) - a[0].max(b[0])).max(0.0);
    let iy = (a_max_y.min(b_max_y) - a[1].max(b[1])).max(0.0);
    let i_vol = ix * iy;
    let a_vol = (a_max_x - a[0]).max(0.0) * (a_max_y - a[1]).max(0.0);
    let b_vol = (b_max_x - b[0]).max(0.0) * (b_max_y - b[1]).max(0.0);
    let u_vol = a_vol + b_vol - i_vol;
    if i_vol == 0.0 {
        0.0
    } else {
        i_vol / u_vol
    }
}

/// `1 − IoU` matrix (row-major, `objs × hyps`), `NaN` where it exceeds
/// `max_distance` (motmetrics `iou_matrix`).
pub fn iou_distances(objs: &[[f64; 4]], hyps: &[[f64; 4]], max_distance: f64) -> Vec<f64> {
    let mut d = Vec::with_capacity(objs.len() * hyps.len());
    for o in objs {
        for h in hyps {
            let dist = 1.0 - iou(o, h);
            d.push(if dist > max_distance { f64::NAN } else { dist });
        }
    }
    d
}

/// Optimal one-to-one matching of `objs` to `hyps` on `1 − IoU` with the
/// given maximum distance: the most pairs, then the least summed distance.
/// Returns `(obj index, hyp index)` pairs sorted by object.
pub fn match_boxes(objs: &[[f64; 4]], hyps: &[[f64; 4]], max_distance: f64) -> Vec<(usize, usize)> {
    let d = iou_distances(objs, hyps, max_distance);
    lsap::assign(&d, objs.len(), hyps.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_known_values() {
        let a = [0.0, 0.0, 10.0, 10.0];
        assert_eq!(iou(&a, &a), 1.0);
        assert_eq!(iou(&a, &[5.0, 0.0, 10.0, 10.0]), 50.0 / 150.0);
        assert_eq!(iou(&a, &[10.0, 0.0, 10.0, 10.0]), 0.0);
        assert_eq!(iou(&a, &[2.0, 2.0, 5.0, 5.0]), 25.0 / 100.0);
    }

    #[test]
    fn threshold_is_inclusive_at_iou_0_4() {
        // IoU exactly 0.4 is not representable after 1 − x; check both sides.
        let a = [0.0, 0.0, 10.0, 10.0];
        let ok = [0.0, 0.0, 10.0, 4.5]; // IoU 0.45
        let bad = [0.0, 0.0, 10.0, 3.5]; // IoU 0.35
        assert!(iou_distances(&[a], &[ok], MAX_DISTANCE)[0].is_finite());
        assert!(iou_distances(&[a], &[bad], MAX_DISTANCE)[0].is_nan());
    }

    #[test]
    fn matching_prefers_more_pairs_then_overlap() {
        let objs = [[0.0, 0.0, 10.0, 10.0], [8.0, 0.0, 10.0, 10.0]];
        let hyps = [[1.0, 0.0, 10.0, 10.0], [9.0, 0.0, 10.0, 10.0]];
        assert_eq!(
            match_boxes(&objs, &hyps, MAX_DISTANCE),
            vec![(0, 0), (1, 1)]
        );
    }
}
