//! Estimating the cue variances σ² of eq. (8) from the data (Section IV.B:
//! "calculated … by collecting the feature values for all temporal matching
//! candidates").
//!
//! Estimator (bounded memory, deterministic): after each frame, every target
//! contributes the squared features of its *chosen* candidate edge (the
//! minimum-cost node's edge; for MC/NN the assigned edge), which passed the
//! gate, from each camera. Each cue keeps the last [`WINDOW`] values in a
//! ring. At the start of a frame, a cue with at least `min_samples` values
//! gets the robust variance σ² = median(f²) / 0.4549 (0.4549 = median of
//! χ²₁, so σ² is the variance of a Gaussian feature), clamped to
//! [default, 16·default]; below `min_samples` the default holds. The floor
//! is the default (it was default/16): the samples are the *accepted*
//! edges, truncated by the gate and by the choice itself, so they
//! underestimate the spread — on synthetic hauls the estimate shrank σ and
//! the tracker then broke true links (success 0.40 vs 0.51 with the
//! default floor). The data can widen a cue (e.g. at 2.5 fps), not narrow
//! it below its default. σ² is fixed during a frame.
//! The median is the element of rank ⌊n/2⌋ of the window.
//!
//! The same rings estimate `v_init`, the velocity a newborn target is
//! projected with: the component-wise median displacement of accepted
//! edges; until `min_samples`, v_ref (Table I) scaled to cross the frame
//! width in the paper's 4.3 frames of lifespan (Section II).
//!
//! Memory: 8 rings of [`WINDOW`] f32 (3.6 KiB).

use super::cost::{EdgeFeatures, Sigmas};

/// Samples kept per cue.
pub const WINDOW: usize = 128;

/// Ratio median(χ²₁) — the median of f² for a unit Gaussian f.
pub const MEDIAN_CHI2_1: f32 = 0.454_936_4;

#[derive(Debug, Clone)]
struct Ring {
    buf: [f32; WINDOW],
    len: usize,
    next: usize,
}

impl Ring {
    const fn new() -> Self {
        Ring {
            buf: [0.0; WINDOW],
            len: 0,
            next: 0,
        }
    }

    fn push(&mut self, v: f32) {
        if !v.is_finite() {
            return;
        }
        if let Some(slot) = self.buf.get_mut(self.next) {
            *slot = v;
        }
        self.next = (self.next + 1) % WINDOW;
        self.len = (self.len + 1).min(WINDOW);
    }

    /// Element of rank ⌊n/2⌋, or `None` below `min` samples.
    fn median(&self, min: usize) -> Option<f32> {
        if self.len < min.max(1) {
            return None;
        }
        let mut tmp = [0.0f32; WINDOW];
        let src = self.buf.get(..self.len)?;
        let dst = tmp.get_mut(..self.len)?;
        dst.copy_from_slice(src);
        let (_, m, _) = dst.select_nth_unstable_by(self.len / 2, f32::total_cmp);
        Some(*m)
    }
}

/// Running robust estimate of the cue variances and of `v_init`.
#[derive(Debug, Clone)]
pub struct SigmaEstimator {
    v: Ring,
    v0: Ring,
    a: Ring,
    m: Ring,
    h: Ring,
    d: Ring,
    vx: Ring,
    vy: Ring,
}

impl Default for SigmaEstimator {
    fn default() -> Self {
        Self::new()
    }
}

impl SigmaEstimator {
    /// No samples yet.
    pub const fn new() -> Self {
        SigmaEstimator {
            v: Ring::new(),
            v0: Ring::new(),
            a: Ring::new(),
            m: Ring::new(),
            h: Ring::new(),
            d: Ring::new(),
            vx: Ring::new(),
            vy: Ring::new(),
        }
    }

    /// Adds one camera's squared features of an accepted edge; `first` when
    /// the node's velocity was unknown (σ_v0 population).
    pub fn push_features(&mut self, f: &EdgeFeatures, first: bool) {
        if first {
            self.v0.push(f.d2);
        } else {
            self.v.push(f.d2);
        }
        self.a.push(f.a2);
        self.m.push(f.m2);
        self.h.push(f.h2);
        self.d.push(f.z2);
    }

    /// Adds the (left) displacement of an accepted edge.
    pub fn push_velocity(&mut self, v: [f32; 2]) {
        self.vx.push(v[0]);
        self.vy.push(v[1]);
    }

    /// Current σ² (see the module documentation).
    pub fn sigmas(&self, defaults: &Sigmas, min_samples: usize) -> Sigmas {
        let est = |r: &Ring, d: f32| match r.median(min_samples) {
            Some(m) => (m / MEDIAN_CHI2_1).clamp(d, d * 16.0),
            None => d,
        };
        Sigmas {
            v: est(&self.v, defaults.v),
            v0: est(&self.v0, defaults.v0),
            a: est(&self.a, defaults.a),
            m: est(&self.m, defaults.m),
            h: est(&self.h, defaults.h),
            d: est(&self.d, defaults.d),
        }
    }

    /// Velocity for projecting a newborn target (median displacement).
    pub fn v_init(&self, min_samples: usize) -> [f32; 2] {
        self.v_init_or(min_samples, [0.0, 0.0])
    }

    /// As [`Self::v_init`], but `default` until `min_samples` displacements.
    pub fn v_init_or(&self, min_samples: usize, default: [f32; 2]) -> [f32; 2] {
        match (self.vx.median(min_samples), self.vy.median(min_samples)) {
            (Some(x), Some(y)) => [x, y],
            _ => default,
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn median_estimate_recovers_gaussian_variance() {
        // Deterministic "Gaussian" squares: quantiles of N(0, 100²).
        let mut e = SigmaEstimator::new();
        let d = Sigmas::for_frame(256);
        for i in 0..WINDOW {
            // Inverse-CDF-free approximation: f = 10·(rank-based quantile).
            let p = (i as f32 + 0.5) / WINDOW as f32;
            // |Z| quantile via a crude erfinv-free table: use p as the
            // probability of |Z| < q; solve with bisection on erf.
            let mut lo = 0.0f64;
            let mut hi = 6.0f64;
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if libm::erf(mid / core::f64::consts::SQRT_2) < p as f64 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let f = 100.0 * lo as f32;
            e.push_features(
                &EdgeFeatures {
                    d2: f * f,
                    a2: 0.0,
                    m2: 0.0,
                    h2: 0.0,
                    z2: 0.0,
                },
                false,
            );
        }
        let s = e.sigmas(&d, 32);
        assert!((s.v - 10_000.0).abs() < 500.0, "{}", s.v);
        // Too few samples: defaults.
        assert_eq!(s.v0, d.v0);
        // Floor at the default for an all-zero cue.
        assert_eq!(s.a, d.a);
    }

    #[test]
    fn window_forgets_old_samples() {
        let mut e = SigmaEstimator::new();
        for _ in 0..WINDOW {
            e.push_velocity([-500.0, 0.0]);
        }
        assert_eq!(e.v_init(8), [-500.0, 0.0]);
        for _ in 0..WINDOW {
            e.push_velocity([300.0, 10.0]);
        }
        assert_eq!(e.v_init(8), [300.0, 10.0]);
        e.push_velocity([f32::NAN, 0.0]);
        assert_eq!(e.v_init(8), [300.0, 10.0]);
    }
}
