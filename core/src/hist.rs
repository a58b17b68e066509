//! Grey-level histograms, the ratio histogram of eq. (2) and its
//! backprojection, eq. (3) (Section III.B).
//!
//! A histogram of `n` bins (n a power of two, 2..=256) puts grey level `v`
//! in bin `v >> (8 − log₂ n)` = `v · n / 256`, OpenCV's `calcHist` with
//! `ranges = [0, 256]` (uniform bins). Memory bound: the caller's arrays.

/// Bin of grey level `v` in an `bins`-bin histogram (`bins` a power of two
/// ≤ 256; other values are rounded down to one).
#[inline]
pub const fn bin_of(v: u8, bins: usize) -> usize {
    let shift = 8 - bins_log2(bins);
    (v as usize) >> shift
}

/// log₂ of `bins` rounded down, clamped to `0..=8`.
pub const fn bins_log2(bins: usize) -> u32 {
    if bins <= 1 {
        0
    } else if bins >= 256 {
        8
    } else {
        usize::BITS - 1 - bins.leading_zeros()
    }
}

/// Adds every pixel of `row` to a 256-bin histogram.
///
/// Pixels alternate between `hist` and a second, local histogram folded
/// in at the end: a run of equal grey levels (flat water) then increments
/// two counters in turn instead of one, so consecutive increments do not
/// wait on each other's store (about twice as fast on such rows; one extra
/// add per bin per call).
#[inline]
pub fn add_row_256(hist: &mut [u32; 256], row: &[u8]) {
    if row.len() < 512 {
        for &v in row {
            hist[v as usize] = hist[v as usize].wrapping_add(1);
        }
        return;
    }
    let mut other = [0u32; 256];
    let pairs = row.chunks_exact(2);
    let rest = pairs.remainder();
    for p in pairs {
        hist[p[0] as usize] = hist[p[0] as usize].wrapping_add(1);
        other[p[1] as usize] = other[p[1] as usize].wrapping_add(1);
    }
    for &v in rest {
        hist[v as usize] = hist[v as usize].wrapping_add(1);
    }
    for (h, o) in hist.iter_mut().zip(other) {
        *h = h.wrapping_add(o);
    }
}

/// Adds the pixels of `px` under the masks `m_low` and `m_high` (0 =
/// outside, anything else inside) to `h_low` and `h_high`: the masked
/// histograms of eq. (2). Blocks of 16 pixels outside both masks (the
/// water around a fish) are skipped with one test. The three slices are
/// read up to the shortest one's length.
#[inline]
pub fn add_masked_pair_256(
    h_low: &mut [u32; 256],
    h_high: &mut [u32; 256],
    px: &[u8],
    m_low: &[u8],
    m_high: &[u8],
) {
    let n = px.len().min(m_low.len()).min(m_high.len());
    let (px, m_low, m_high) = (&px[..n], &m_low[..n], &m_high[..n]);
    let mut one = |p: &[u8], l: &[u8], h: &[u8]| {
        for ((&v, &vl), &vh) in p.iter().zip(l).zip(h) {
            h_low[v as usize] = h_low[v as usize].wrapping_add((vl != 0) as u32);
            h_high[v as usize] = h_high[v as usize].wrapping_add((vh != 0) as u32);
        }
    };
    let (pc, lc, hc) = (
        px.chunks_exact(16),
        m_low.chunks_exact(16),
        m_high.chunks_exact(16),
    );
    let (pr, lr, hr) = (pc.remainder(), lc.remainder(), hc.remainder());
    for ((p, l), h) in pc.zip(lc).zip(hc) {
        if l.iter().zip(h).fold(0u8, |acc, (&a, &b)| acc | a | b) != 0 {
            one(p, l, h);
        }
    }
    one(pr, lr, hr);
}

/// Sum and sum of squares of the grey levels of `px`.
#[inline]
pub fn sum_sumsq(px: &[u8]) -> (u64, u64) {
    let (mut s1, mut s2) = (0u64, 0u64);
    // 1024 · 255² < 2³², so each block's sums fit u32 (and vectorise)
    for blk in px.chunks(1024) {
        s1 += blk.iter().map(|&p| p as u32).sum::<u32>() as u64;
        s2 += blk.iter().map(|&p| p as u32 * p as u32).sum::<u32>() as u64;
    }
    (s1, s2)
}

/// Folds a 256-bin histogram into `out.len()` bins (a power of two ≤ 256).
pub fn fold_bins(hist: &[u32; 256], out: &mut [u32]) {
    out.fill(0);
    let bins = out.len();
    if bins == 0 {
        return;
    }
    for (v, &h) in hist.iter().enumerate() {
        if let Some(o) = out.get_mut(bin_of(v as u8, bins)) {
            *o = o.wrapping_add(h);
        }
    }
}

/// The ratio histogram of eq. (2) thresholded by θ_bp (eq. (3)) as a
/// 256-entry lookup table over grey levels: `lut[v]` is true when
/// `H_R(bin(v)) = min(H_high / H_low, 1) > θ_bp`.
///
/// A bin with `H_low = 0` has no defined ratio; it is taken as 0 (such grey
/// levels never occur in M_low, so they are not foreground). Since θ_bp < 1
/// the `min(·, 1)` never changes the decision. `h_high` and `h_low` must have
/// the same power-of-two length ≤ 256; the comparison is done in f32 per bin
/// (at most 256 divisions per region, none per pixel).
pub fn ratio_backprojection_lut(h_high: &[u32], h_low: &[u32], theta_bp: f32) -> [bool; 256] {
    let mut lut = [false; 256];
    let bins = h_low.len().min(h_high.len());
    if bins == 0 {
        return lut;
    }
    for (v, l) in lut.iter_mut().enumerate() {
        let b = bin_of(v as u8, bins);
        let (hh, hl) = match (h_high.get(b), h_low.get(b)) {
            (Some(&hh), Some(&hl)) => (hh, hl),
            _ => continue,
        };
        if hl == 0 {
            continue;
        }
        let ratio = (hh as f32 / hl as f32).min(1.0);
        *l = ratio > theta_bp;
    }
    lut
}

/// Bin of grey level `v` in a `bins`-bin histogram spanning the grey-level
/// range `[lo, hi]` of one local region (levels outside are clamped into
/// the end bins): `(clamp(v, lo, hi) − lo) · bins / (hi − lo + 1)`.
///
/// Why a local range (Section III.B): the ratio histogram can only tell a
/// fish from its background when their grey levels fall in different
/// bins. With 16 bins over the whole 0..=255 scale a bin is 16 levels wide,
/// wider than the whole contrast of a dim fish in dark water (fish 23 over
/// background 16, noise σ ≈ 2.5 on the synthetic hauls), so fish and
/// background share bins and the backprojection floods the ellipse. Spanning
/// the bins over the region's own range — from ⌊τ_low⌋ (everything at or
/// below it is background to eq. (1)) to its 99th percentile (robust to
/// marine-snow specks) — keeps the paper's bin count and makes a bin a
/// fixed fraction of the local contrast, as OpenCV's `calcHist` does with
/// `ranges = [lo, hi + 1]`.
#[inline]
pub const fn range_bin(v: u8, lo: u8, hi: u8, bins: usize) -> usize {
    let (lo, hi) = if hi < lo { (lo, lo) } else { (lo, hi) };
    let v = if v < lo {
        lo
    } else if v > hi {
        hi
    } else {
        v
    };
    let span = (hi - lo) as usize + 1;
    (v - lo) as usize * bins / span
}

/// Smallest grey level at or below which at least `pct`% of the
/// histogram's pixels lie (255 for an empty histogram).
pub fn percentile_256(hist: &[u32; 256], pct: u32) -> u8 {
    let total: u64 = hist.iter().map(|&h| h as u64).sum();
    let need = (total * pct.min(100) as u64).div_ceil(100);
    let mut acc = 0u64;
    for (v, &h) in hist.iter().enumerate() {
        acc += h as u64;
        if acc >= need && acc > 0 {
            return v as u8;
        }
    }
    255
}

/// Mean of a histogram's values ranked from the `lo`-th to the `hi`-th
/// tenth (`⌊n·lo/10⌋ ≤ rank < ⌊n·hi/10⌋`, bins counted in part at the two
/// ends): a trimmed mean. `None` when that range is empty or all zero.
pub fn trimmed_mean_256(hist: &[u32; 256], lo: u64, hi: u64) -> Option<f32> {
    let n: u64 = hist.iter().map(|&c| c as u64).sum();
    let (lo, hi) = (n * lo / 10, n * hi / 10);
    let (mut below, mut sum, mut cnt) = (0u64, 0u64, 0u64);
    for (v, &c) in hist.iter().enumerate() {
        let c = c as u64;
        let (a, b) = (below.max(lo), (below + c).min(hi));
        if b > a {
            sum += (b - a) * v as u64;
            cnt += b - a;
        }
        below += c;
    }
    (cnt > 0 && sum > 0).then(|| sum as f32 / cnt as f32)
}

/// Lower median (the ⌈n/2⌉-th smallest) of a histogram's values: the
/// first bin where the running count reaches half; the last bin when the
/// histogram is empty.
pub fn median(hist: &[u32]) -> usize {
    let total: u64 = hist.iter().map(|&h| h as u64).sum();
    let half = total.div_ceil(2).max(1);
    let mut acc = 0u64;
    for (i, &c) in hist.iter().enumerate() {
        acc += c as u64;
        if acc >= half {
            return i;
        }
    }
    hist.len().saturating_sub(1)
}

/// Median and median absolute deviation (both lower medians, [`median`])
/// of a histogram's values; `dev` is caller scratch, as long as `hist`
/// (deviations beyond it count in its last bin).
pub fn median_mad(hist: &[u32], dev: &mut [u32]) -> (usize, usize) {
    let bins = hist.len().min(dev.len());
    let (hist, dev) = (&hist[..bins], &mut dev[..bins]);
    dev.fill(0);
    let med = median(hist);
    for (i, &c) in hist.iter().enumerate() {
        if let Some(d) = dev.get_mut(i.abs_diff(med).min(bins.saturating_sub(1))) {
            *d = d.saturating_add(c);
        }
    }
    (med, median(dev))
}

/// [`fold_bins`] with the bins spanning `[lo, hi]` ([`range_bin`]).
pub fn fold_bins_range(hist: &[u32; 256], lo: u8, hi: u8, out: &mut [u32]) {
    out.fill(0);
    let bins = out.len();
    for (v, &h) in hist.iter().enumerate() {
        if let Some(o) = out.get_mut(range_bin(v as u8, lo, hi, bins)) {
            *o = o.wrapping_add(h);
        }
    }
}

/// [`ratio_backprojection_lut`] with the bins spanning `[lo, hi]`
/// ([`range_bin`]); `h_high` and `h_low` have the same length.
pub fn ratio_backprojection_lut_range(
    h_high: &[u32],
    h_low: &[u32],
    lo: u8,
    hi: u8,
    theta_bp: f32,
) -> [bool; 256] {
    let mut lut = [false; 256];
    let bins = h_low.len().min(h_high.len());
    for (v, l) in lut.iter_mut().enumerate() {
        let b = range_bin(v as u8, lo, hi, bins);
        let (hh, hl) = match (h_high.get(b), h_low.get(b)) {
            (Some(&hh), Some(&hl)) => (hh, hl),
            _ => continue,
        };
        if hl == 0 {
            continue;
        }
        *l = (hh as f32 / hl as f32).min(1.0) > theta_bp;
    }
    lut
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trimmed_mean_is_the_mean_of_the_sorted_values_in_the_rank_range() {
        // values 0..100 once each: ranks 10..60 are the values 10..59
        let mut h = [0u32; 256];
        (0..100).for_each(|v| h[v] += 1);
        assert_eq!(trimmed_mean_256(&h, 1, 6), Some(34.5));
        // a bin straddling the range's ends counts in part
        let mut h = [0u32; 256];
        h[10] = 5;
        h[20] = 5;
        // n = 10: ranks 1..6 are 10, 10, 10, 10, 20
        assert_eq!(trimmed_mean_256(&h, 1, 6), Some(12.0));
        assert_eq!(trimmed_mean_256(&[0; 256], 1, 6), None);
    }

    #[test]
    fn bins_follow_calc_hist() {
        assert_eq!(bin_of(0, 16), 0);
        assert_eq!(bin_of(15, 16), 0);
        assert_eq!(bin_of(16, 16), 1);
        assert_eq!(bin_of(255, 16), 15);
        assert_eq!(bin_of(255, 8), 7);
        assert_eq!(bin_of(255, 32), 31);
        assert_eq!(bin_of(200, 256), 200);
        let mut h = [0u32; 256];
        add_row_256(&mut h, &[0, 1, 17, 255, 255]);
        let mut f = [0u32; 16];
        fold_bins(&h, &mut f);
        assert_eq!((f[0], f[1], f[15]), (2, 1, 2));
    }

    #[test]
    fn ratio_lut_of_eq2_eq3() {
        let mut hl = [0u32; 16];
        let mut hh = [0u32; 16];
        hl[3] = 100; // background-dominated bin: ratio 0.1
        hh[3] = 10;
        hl[8] = 50; // foreground bin: ratio 0.9
        hh[8] = 45;
        hl[9] = 10; // exactly θ: not > θ
        hh[9] = 3;
        let lut = ratio_backprojection_lut(&hh, &hl, 0.3);
        assert!(!lut[3 * 16 + 5]);
        assert!(lut[8 * 16] && lut[8 * 16 + 15]);
        assert!(!lut[9 * 16]);
        assert!(!lut[0] && !lut[255]);
    }

    #[test]
    fn range_bins_follow_calc_hist_ranges() {
        // calcHist(ranges = [10, 26]) with 16 bins: one level per bin
        assert_eq!(range_bin(10, 10, 25, 16), 0);
        assert_eq!(range_bin(25, 10, 25, 16), 15);
        assert_eq!(range_bin(17, 10, 25, 16), 7);
        // clamped ends, degenerate range
        assert_eq!(range_bin(0, 10, 25, 16), 0);
        assert_eq!(range_bin(255, 10, 25, 16), 15);
        assert_eq!(range_bin(200, 30, 20, 16), 0);
        let mut h = [0u32; 256];
        for v in 0..100u8 {
            add_row_256(&mut h, &[v]);
        }
        assert_eq!(percentile_256(&h, 99), 98);
        assert_eq!(percentile_256(&h, 50), 49);
        assert_eq!(percentile_256(&[0; 256], 99), 255);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 128 }))]
        /// Median and MAD of a histogram equal the lower medians of the
        /// sorted values and of their sorted absolute deviations.
        #[test]
        fn median_mad_equals_sorting(vals in proptest::collection::vec(0u8..64, 1..300)) {
            extern crate std;
            use std::vec::Vec;
            let mut h = [0u32; 64];
            for &v in &vals {
                h[v as usize] += 1;
            }
            let mut sorted = vals.clone();
            sorted.sort_unstable();
            let k = sorted.len().div_ceil(2) - 1;
            let med = sorted[k] as usize;
            let mut dev: Vec<usize> = sorted.iter().map(|&v| (v as usize).abs_diff(med)).collect();
            dev.sort_unstable();
            proptest::prop_assert_eq!(median_mad(&h, &mut [0u32; 64]), (med, dev[k]));
        }

        /// The two-counter histogram equals a naive count, for rows shorter
        /// and longer than the split threshold, odd and even lengths.
        #[test]
        fn add_row_256_equals_naive(len in 0usize..1500, seed in proptest::prelude::any::<u64>(), levels in 1u64..256) {
            let mut s = seed | 1;
            let row: std::vec::Vec<u8> = (0..len).map(|_| { s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s % levels) as u8 }).collect();
            let mut want = [3u32; 256];
            for &v in &row { want[v as usize] += 1; }
            let mut got = [3u32; 256];
            add_row_256(&mut got, &row);
            proptest::prop_assert_eq!(got, want);
        }
        /// The block-skipping masked pair histogram equals a naive count.
        #[test]
        fn add_masked_pair_256_equals_naive(len in 0usize..200, seed in proptest::prelude::any::<u64>(), dens in 0u64..8) {
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let px: std::vec::Vec<u8> = (0..len).map(|_| next() as u8).collect();
            let ml: std::vec::Vec<u8> = (0..len).map(|_| if next() % 8 < dens { (next() as u8) | 1 } else { 0 }).collect();
            let mh: std::vec::Vec<u8> = (0..len).map(|_| if next() % 16 < dens { 255 } else { 0 }).collect();
            let (mut wl, mut wh) = ([1u32; 256], [2u32; 256]);
            for i in 0..len {
                if ml[i] != 0 { wl[px[i] as usize] += 1; }
                if mh[i] != 0 { wh[px[i] as usize] += 1; }
            }
            let (mut gl, mut gh) = ([1u32; 256], [2u32; 256]);
            add_masked_pair_256(&mut gl, &mut gh, &px, &ml, &mh);
            proptest::prop_assert_eq!(gl, wl);
            proptest::prop_assert_eq!(gh, wh);
        }

        /// The blocked sums equal naive u64 sums.
        #[test]
        fn sum_sumsq_equals_naive(len in 0usize..5000, seed in proptest::prelude::any::<u64>()) {
            let mut s = seed | 1;
            let px: std::vec::Vec<u8> = (0..len).map(|_| { s ^= s << 13; s ^= s >> 7; s ^= s << 17; if s % 3 == 0 { 255 } else { s as u8 } }).collect();
            let want = (px.iter().map(|&p| p as u64).sum::<u64>(), px.iter().map(|&p| p as u64 * p as u64).sum::<u64>());
            proptest::prop_assert_eq!(sum_sumsq(&px), want);
        }
    }
}
