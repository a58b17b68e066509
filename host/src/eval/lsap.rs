//! Linear sum assignment (the Hungarian problem) for the evaluation.
//!
//! Our own implementation of the shortest-augmenting-path algorithm of
//! Jonker & Volgenant in the rectangular form given by Crouse (2016,
//! "On implementing 2D rectangular assignment algorithms", pp. 1685–1686) —
//! the same algorithm, loop order and tie rules as SciPy's
//! `linear_sum_assignment`, which is the solver py-motmetrics uses here.
//! Matching SciPy step for step means that even on exactly tied costs we
//! pick the same assignment motmetrics picks, so MOTA/IDF1 agree exactly.
//!
//! Forbidden pairs are `NaN` (or ±∞), as in motmetrics: like
//! `motmetrics.lap.add_expensive_edges`, they are replaced by a constant so
//! large that the optimum first maximises the number of allowed pairs and
//! then minimises their summed cost; forbidden pairs are dropped from the
//! result.

/// Optimal one-to-one assignment of rows to columns of `costs` (row-major,
/// `rows × cols`), minimising the summed cost over a maximum number of
/// allowed (finite) pairs. Returns `(row, col)` pairs sorted by row.
pub fn assign(costs: &[f64], rows: usize, cols: usize) -> Vec<(usize, usize)> {
    debug_assert_eq!(costs.len(), rows * cols);
    if rows == 0 || cols == 0 || costs.len() != rows * cols {
        return Vec::new();
    }
    let finite = expensive_edges(costs, rows, cols);
    solve(&finite, rows, cols)
        .into_iter()
        .filter(|&(i, j)| costs[i * cols + j].is_finite())
        .collect()
}

/// `motmetrics.lap.add_expensive_edges`: non-finite entries become
/// `2·r·c + 1` with `c = max|finite| + 1`, `r = min(rows, cols)`; all zeros
/// when nothing is allowed.
fn expensive_edges(costs: &[f64], rows: usize, cols: usize) -> Vec<f64> {
    if costs.iter().all(|c| c.is_finite()) {
        return costs.to_vec();
    }
    if !costs.iter().any(|c| c.is_finite()) {
        return vec![0.0; costs.len()];
    }
    let r = rows.min(cols) as f64;
    let c = costs
        .iter()
        .filter(|c| c.is_finite())
        .fold(f64::NEG_INFINITY, |m, &x| m.max(x.abs()))
        + 1.0;
    let large = 2.0 * r * c + 1.0;
    costs
        .iter()
        .map(|&x| if x.is_finite() { x } else { large })
        .collect()
}

/// Full rectangular assignment of a finite cost matrix (every row of the
/// smaller side assigned). Crouse's algorithm as in SciPy.
fn solve(cost_in: &[f64], rows: usize, cols: usize) -> Vec<(usize, usize)> {
    // A tall matrix is transposed so that rows ≤ cols.
    let transpose = cols < rows;
    let (nr, nc, cost): (usize, usize, Vec<f64>) = if transpose {
        let mut t = vec![0.0; rows * cols];
        for i in 0..rows {
            for j in 0..cols {
                t[j * rows + i] = cost_in[i * cols + j];
            }
        }
        (cols, rows, t)
    } else {
        (rows, cols, cost_in.to_vec())
    };

    let mut u = vec![0.0f64; nr];
    let mut v = vec![0.0f64; nc];
    let mut shortest = vec![f64::INFINITY; nc];
    let mut path = vec![usize::MAX; nc];
    let mut col4row = vec![usize::MAX; nr];
    let mut row4col = vec![usize::MAX; nc];
    let mut sr = vec![false; nr];
    let mut sc = vec![false; nc];
    let mut remaining = vec![0usize; nc];

    for cur_row in 0..nr {
        // Shortest augmenting path from `cur_row`.
        let mut min_val = 0.0f64;
        let mut num_remaining = nc;
        for (it, r) in remaining.iter_mut().enumerate() {
            *r = nc - it - 1;
        }
        sr.iter_mut().for_each(|x| *x = false);
        sc.iter_mut().for_each(|x| *x = false);
        shortest.iter_mut().for_each(|x| *x = f64::INFINITY);
        let mut i = cur_row;
        let sink = loop {
            let mut index = usize::MAX;
            let mut lowest = f64::INFINITY;
            sr[i] = true;
            for (it, &j) in remaining.iter().enumerate().take(num_remaining) {
                let r = min_val + cost[i * nc + j] - u[i] - v[j];
                if r < shortest[j] {
                    path[j] = i;
                    shortest[j] = r;
                }
                if shortest[j] < lowest || (shortest[j] == lowest && row4col[j] == usize::MAX) {
                    lowest = shortest[j];
                    index = it;
                }
            }
            min_val = lowest;
            if index == usize::MAX || !min_val.is_finite() {
                // Cannot happen with finite costs; stop with what we have.
                return collect(transpose, &col4row);
            }
            let j = remaining[index];
            if row4col[j] == usize::MAX {
                sc[j] = true;
                break j;
            }
            i = row4col[j];
            sc[j] = true;
            num_remaining -= 1;
            remaining[index] = remaining[num_remaining];
        };

        // Dual update.
        u[cur_row] += min_val;
        for r in 0..nr {
            if sr[r] && r != cur_row {
                u[r] += min_val - shortest[col4row[r]];
            }
        }
        for c in 0..nc {
            if sc[c] {
                v[c] -= min_val - shortest[c];
            }
        }

        // Augment along the path.
        let mut j = sink;
        loop {
            let i = path[j];
            row4col[j] = i;
            std::mem::swap(&mut col4row[i], &mut j);
            if i == cur_row {
                break;
            }
        }
    }
    collect(transpose, &col4row)
}

fn collect(transpose: bool, col4row: &[usize]) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = col4row
        .iter()
        .enumerate()
        .filter(|(_, &c)| c != usize::MAX)
        .map(|(r, &c)| if transpose { (c, r) } else { (r, c) })
        .collect();
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Brute force: best (count, −cost) over all partial injective maps,
    /// each row choosing a column or none (`(cols + 1)^rows` choices).
    fn brute(costs: &[f64], rows: usize, cols: usize) -> (usize, f64) {
        let mut best = (0usize, 0.0f64);
        let total = (cols + 1).pow(rows as u32);
        'outer: for mut code in 0..total {
            let mut used = vec![false; cols];
            let (mut n, mut s) = (0usize, 0.0f64);
            for i in 0..rows {
                let choice = code % (cols + 1);
                code /= cols + 1;
                if choice == cols {
                    continue;
                }
                let c = costs[i * cols + choice];
                if used[choice] || !c.is_finite() {
                    continue 'outer;
                }
                used[choice] = true;
                n += 1;
                s += c;
            }
            if n > best.0 || (n == best.0 && s < best.1) {
                best = (n, s);
            }
        }
        best
    }

    #[test]
    fn agrees_with_brute_force_on_random_matrices_with_forbidden_pairs() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..2000 {
            let rows = rng.random_range(0..6);
            let cols = rng.random_range(0..6);
            let p_nan = rng.random_range(0.0..0.8);
            let costs: Vec<f64> = (0..rows * cols)
                .map(|_| {
                    if rng.random_bool(p_nan) {
                        f64::NAN
                    } else {
                        rng.random_range(-1.0..1.0)
                    }
                })
                .collect();
            let got = assign(&costs, rows, cols);
            let mut rs: Vec<usize> = got.iter().map(|p| p.0).collect();
            let mut cs: Vec<usize> = got.iter().map(|p| p.1).collect();
            rs.dedup();
            cs.sort_unstable();
            cs.dedup();
            assert_eq!(rs.len(), got.len(), "one column per row");
            assert_eq!(cs.len(), got.len(), "one row per column");
            let sum: f64 = got.iter().map(|&(i, j)| costs[i * cols + j]).sum();
            let (n, best) = brute(&costs, rows, cols);
            assert_eq!(got.len(), n, "maximum number of allowed pairs");
            assert!((sum - best).abs() < 1e-9, "{sum} vs {best}");
        }
    }

    #[test]
    fn constant_matrix_gives_identity_like_scipy() {
        // SciPy returns the identity for a constant square matrix (scipy#11602).
        let got = assign(&[1.0; 9], 3, 3);
        assert_eq!(got, vec![(0, 0), (1, 1), (2, 2)]);
    }

    #[test]
    fn empty_and_all_forbidden() {
        assert!(assign(&[], 0, 3).is_empty());
        assert!(assign(&[f64::NAN; 4], 2, 2).is_empty());
    }
}
