//! Frame-to-frame greedy association for the baselines of Table V: the
//! paper's "MC" (matching cost alone, eq. 9) and "NN" (nearest neighbour on
//! the predicted position). The tracker builds a key matrix (MC: the stereo
//! matching cost; NN: the squared distance to the prediction) with
//! `f32::INFINITY` for gated-out pairs, and this module assigns one-to-one.

/// Greedy one-to-one assignment: repeatedly takes the smallest finite key
/// among free rows and free columns (ties: lowest row, then lowest column)
/// and writes `out[row] = Some(col)`. Rows without a partner stay `None`.
///
/// Work is bounded by `min(rows, cols) · rows · cols` key reads.
pub fn greedy_assign<const N: usize>(keys: &[[f32; N]], cols: usize, out: &mut [Option<u16>]) {
    let rows = keys.len().min(out.len());
    let cols = cols.min(N).min(u16::MAX as usize);
    for o in out.iter_mut() {
        *o = None;
    }
    let mut col_used = [false; N];
    for _ in 0..rows.min(cols) {
        let mut best: Option<(usize, usize, f32)> = None;
        for (r, row) in keys.iter().enumerate().take(rows) {
            if out.get(r).is_some_and(|o| o.is_some()) {
                continue;
            }
            for (c, &k) in row.iter().enumerate().take(cols) {
                if col_used.get(c).copied().unwrap_or(true) || !k.is_finite() {
                    continue;
                }
                if best.is_none_or(|(_, _, bk)| k < bk) {
                    best = Some((r, c, k));
                }
            }
        }
        let Some((r, c, _)) = best else {
            break;
        };
        if let Some(o) = out.get_mut(r) {
            *o = Some(c as u16);
        }
        if let Some(u) = col_used.get_mut(c) {
            *u = true;
        }
    }
}

/// Improves a one-to-one assignment by pairwise exchanges (2-opt) on the
/// total key, an unassigned row costing `miss`: two rows swap their columns,
/// or an unassigned row takes an assigned row's column, whenever that
/// lowers the sum by more than `min_gain`. Used on the Viterbi selection
/// (Section IV.C, our addition): greedy smallest-first can give school mates
/// entering side by side each other's fish when one crossed pair happens to
/// be close, although the joint assignment is clearly the other one (for a
/// common displacement error e and separation Δ the swap costs 2‖Δ‖² more).
/// At most `passes` sweeps over row pairs; work ≤ passes · rows² key reads.
pub fn improve_pairs<const N: usize>(
    keys: &[[f32; N]],
    miss: f32,
    min_gain: f32,
    passes: usize,
    out: &mut [Option<u16>],
) {
    let rows = keys.len().min(out.len());
    let key = |r: usize, c: Option<u16>| -> f32 {
        match c {
            Some(c) => keys
                .get(r)
                .and_then(|row| row.get(c as usize))
                .copied()
                .unwrap_or(f32::INFINITY),
            None => miss,
        }
    };
    for _ in 0..passes {
        let mut changed = false;
        for i in 0..rows {
            for j in (i + 1)..rows {
                let (Some(&a), Some(&b)) = (out.get(i), out.get(j)) else {
                    continue;
                };
                if a.is_none() && b.is_none() {
                    continue;
                }
                let now = key(i, a) + key(j, b);
                let swapped = key(i, b) + key(j, a);
                if swapped.is_finite() && swapped + min_gain < now {
                    if let Some(o) = out.get_mut(i) {
                        *o = b;
                    }
                    if let Some(o) = out.get_mut(j) {
                        *o = a;
                    }
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn total(keys: &[[f32; 5]], out: &[Option<u16>], miss: f32) -> f32 {
        out.iter()
            .enumerate()
            .map(|(r, c)| c.map_or(miss, |c| keys[r][c as usize]))
            .sum()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        /// Pair exchanges keep the assignment one-to-one on finite keys,
        /// never raise the total, and end 2-opt optimal.
        #[test]
        fn pair_exchanges_improve_greedy(
            k in proptest::collection::vec(proptest::option::weighted(0.7, 0.0f32..24.0), 20)
        ) {
            let mut keys = [[f32::INFINITY; 5]; 4];
            for (i, v) in k.iter().enumerate() {
                keys[i / 5][i % 5] = v.unwrap_or(f32::INFINITY);
            }
            let miss = 24.0;
            let mut out = [None; 4];
            greedy_assign(&keys, 5, &mut out);
            let before = total(&keys, &out, miss);
            improve_pairs(&keys, miss, 0.0, 1000, &mut out);
            let after = total(&keys, &out, miss);
            prop_assert!(after <= before + 1e-3, "{after} > {before}");
            let mut used = [false; 5];
            for (r, c) in out.iter().enumerate() {
                if let Some(c) = c {
                    prop_assert!(keys[r][*c as usize].is_finite());
                    prop_assert!(!used[*c as usize], "column {c} twice");
                    used[*c as usize] = true;
                }
            }
            for i in 0..4 {
                for j in (i + 1)..4 {
                    let mut sw = out;
                    sw.swap(i, j);
                    let t = total(&keys, &sw, miss);
                    prop_assert!(!(t.is_finite() && t + 1e-3 < after), "swap {i} {j}: {t} < {after}");
                }
            }
        }
    }

    const I: f32 = f32::INFINITY;

    #[test]
    fn greedy_takes_smallest_first() {
        let keys = [[1.0, 2.0, I], [0.5, 3.0, I], [I, I, I]];
        let mut out = [None; 3];
        greedy_assign(&keys, 3, &mut out);
        // (1,0) at 0.5 first, then (0,1) at 2.0; row 2 has no finite key.
        assert_eq!(out, [Some(1), Some(0), None]);
    }

    #[test]
    fn ties_go_to_lowest_row_then_column() {
        let keys = [[1.0, 1.0], [1.0, 1.0]];
        let mut out = [None; 2];
        greedy_assign(&keys, 2, &mut out);
        assert_eq!(out, [Some(0), Some(1)]);
    }

    #[test]
    fn pair_exchange_fixes_greedy_swap() {
        // Greedy takes (0,1) at 1 then (1,0) at 9: total 10; the exchange
        // (0,0) at 3 + (1,1) at 3 = 6 is better.
        let keys = [[3.0, 1.0], [9.0, 3.0]];
        let mut out = [None; 2];
        greedy_assign(&keys, 2, &mut out);
        assert_eq!(out, [Some(1), Some(0)]);
        improve_pairs(&keys, 24.0, 0.0, 4, &mut out);
        assert_eq!(out, [Some(0), Some(1)]);
    }

    #[test]
    fn unassigned_row_takes_column_when_cheaper() {
        // Row 0 holds column 0 at 20; row 1 (unassigned, miss 24) would take
        // it at 1: 20 + 24 > 24 + 1.
        let keys = [[20.0], [1.0]];
        let mut out = [Some(0), None];
        improve_pairs(&keys, 24.0, 0.0, 4, &mut out);
        assert_eq!(out, [None, Some(0)]);
    }
}
