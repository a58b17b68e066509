//! Grey-level thresholds: Otsu's method on a 256-bin histogram and the
//! shifted thresholds of eq. (1) (Section III.A).
//!
//! Convention (as OpenCV's `THRESH_BINARY` and imageproc's `otsu_level`): a
//! threshold `t` splits grey levels into a lower class `p ≤ t` and an upper
//! class (the foreground) `p > t`. Memory bound: none; work: O(256).

/// Otsu's threshold (the paper's ref. 21) of a 256-bin grey-level histogram: the level `t`
/// maximising the between-class variance of `{p ≤ t}` and `{p > t}`.
///
/// This mirrors OpenCV's `getThreshVal_Otsu_8u` step for step (f64
/// arithmetic on 256 bins, classes with a weight below `FLT_EPSILON`
/// skipped, the first maximum wins), so `cv2.threshold(.., THRESH_OTSU)`
/// returns the same value; the oracle test checks it. An empty or
/// single-valued histogram gives 0.
pub fn otsu(hist: &[u32; 256]) -> u8 {
    let total: u64 = hist.iter().map(|&h| h as u64).sum();
    if total == 0 {
        return 0;
    }
    let scale = 1.0 / total as f64;
    let mut mu = 0.0f64;
    for (i, &h) in hist.iter().enumerate() {
        mu += i as f64 * h as f64;
    }
    mu *= scale;
    let eps = f32::EPSILON as f64;
    let (mut mu1, mut q1) = (0.0f64, 0.0f64);
    let (mut max_sigma, mut max_val) = (0.0f64, 0u8);
    for (i, &h) in hist.iter().enumerate() {
        let p_i = h as f64 * scale;
        mu1 *= q1;
        q1 += p_i;
        let q2 = 1.0 - q1;
        if q1.min(q2) < eps || q1.max(q2) > 1.0 - eps {
            continue;
        }
        mu1 = (mu1 + i as f64 * p_i) / q1;
        let mu2 = (mu - q1 * mu1) / q2;
        let sigma = q1 * q2 * (mu1 - mu2) * (mu1 - mu2);
        if sigma > max_sigma {
            max_sigma = sigma;
            max_val = i as u8;
        }
    }
    max_val
}

/// μ_L(τ): the mean grey level of the lower class `p ≤ tau` (eq. (1)), or
/// `tau` itself when that class is empty.
pub fn lower_class_mean(hist: &[u32; 256], tau: u8) -> f32 {
    let (mut n, mut s) = (0u64, 0u64);
    for (i, &h) in hist.iter().enumerate().take(tau as usize + 1) {
        n += h as u64;
        s += i as u64 * h as u64;
    }
    if n == 0 {
        tau as f32
    } else {
        (s as f64 / n as f64) as f32
    }
}

/// The shifted threshold of eq. (1), `τ_x = τ − p (τ − μ_L(τ))`, as an
/// integer level for the `p > t` convention: a pixel is foreground when its
/// grey level exceeds the real value τ_x, i.e. when it exceeds `⌊τ_x⌋`.
/// `p` is clamped to `[0, 1]`, so `⌊μ_L⌋ ≤ result ≤ τ`.
pub fn shifted_threshold(tau: u8, mu_low: f32, p: f32) -> u8 {
    let p = if p.is_finite() {
        p.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mu = if mu_low.is_finite() {
        mu_low.clamp(0.0, tau as f32)
    } else {
        tau as f32
    };
    let tx = tau as f32 - p * (tau as f32 - mu);
    // floor of a value in [0, 255]
    let f = tx as i32; // truncation == floor for non-negative values
    f.clamp(0, tau as i32) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Brute-force Otsu over exact integer between-class variance (an
    /// independent formulation): maximise (N·S₁ − n₁·S)² / (n₁ (N − n₁)).
    fn otsu_exact(hist: &[u32; 256]) -> Option<u8> {
        let n: f64 = hist.iter().map(|&h| h as f64).sum();
        let s: f64 = hist
            .iter()
            .enumerate()
            .map(|(i, &h)| i as f64 * h as f64)
            .sum();
        let (mut n1, mut s1) = (0.0, 0.0);
        let mut best = (-1.0f64, None);
        for (i, &h) in hist.iter().enumerate() {
            n1 += h as f64;
            s1 += i as f64 * h as f64;
            if n1 == 0.0 || n1 == n {
                continue;
            }
            let d = n * s1 - n1 * s;
            let v = d * d / (n1 * (n - n1));
            if v > best.0 * (1.0 + 1e-9) {
                best = (v, Some(i as u8));
            }
        }
        best.1
    }

    #[test]
    fn otsu_splits_two_modes() {
        let mut h = [0u32; 256];
        h[40] = 1000;
        h[200] = 300;
        let t = otsu(&h);
        assert!((40..200).contains(&t), "t = {t}");
        assert_eq!(t, 40); // first maximum: every t in 40..200 is equal
        assert_eq!(otsu(&[0; 256]), 0);
        let mut one = [0u32; 256];
        one[77] = 5;
        assert_eq!(otsu(&one), 0);
    }

    #[test]
    fn shifted_thresholds_of_eq1() {
        // τ = 100, μ_L = 60: p = 1 → 60, p = 0.7 → 72, p = 0 → 100
        assert_eq!(shifted_threshold(100, 60.0, 1.0), 60);
        assert_eq!(shifted_threshold(100, 60.0, 0.7), 72);
        assert_eq!(shifted_threshold(100, 60.0, 0.0), 100);
        assert_eq!(shifted_threshold(100, 60.5, 1.0), 60);
        assert_eq!(shifted_threshold(0, 0.0, 1.0), 0);
        assert_eq!(shifted_threshold(10, f32::NAN, f32::NAN), 10);
        let mut h = [0u32; 256];
        h[10] = 1;
        h[20] = 3;
        h[90] = 9;
        assert_eq!(lower_class_mean(&h, 50), 17.5);
        assert_eq!(lower_class_mean(&h, 5), 5.0);
    }

    proptest! {
        // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn otsu_maximises_between_class_variance(h in proptest::collection::vec(0u32..5000, 256)) {
            let mut hist = [0u32; 256];
            hist.copy_from_slice(&h);
            let t = otsu(&hist);
            if let Some(e) = otsu_exact(&hist) {
                // equal up to near-ties of the variance
                let var = |t: u8| {
                    let n: f64 = hist.iter().map(|&h| h as f64).sum();
                    let s: f64 = hist.iter().enumerate().map(|(i, &h)| i as f64 * h as f64).sum();
                    let n1: f64 = hist[..=t as usize].iter().map(|&h| h as f64).sum();
                    let s1: f64 = hist[..=t as usize].iter().enumerate().map(|(i, &h)| i as f64 * h as f64).sum();
                    let d = n * s1 - n1 * s;
                    if n1 == 0.0 || n1 == n { 0.0 } else { d * d / (n1 * (n - n1)) }
                };
                prop_assert!((var(t) - var(e)).abs() <= 1e-6 * var(e).max(1.0), "t={} e={}", t, e);
            }
            let mu = lower_class_mean(&hist, t);
            prop_assert!(mu <= t as f32 + 1e-3);
            let lo = shifted_threshold(t, mu, 1.0);
            let hi = shifted_threshold(t, mu, 0.7);
            prop_assert!(lo <= hi && hi <= t);
        }
    }
}
