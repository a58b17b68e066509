//! Feature-based temporal matching cost, Section IV.B, eq. (7)–(9), and its
//! stereo form c = c^L + c^R (Section IV.C).
//!
//! For one camera, between a trellis node i (a target hypothesis at t−1) and
//! an observation j at t:
//! - vicinity  z_v = ‖x_j − x̂_i‖² / σ_v², with the motion projection
//!   x̂_i = x_i + v_i (Section IV.C.2), computed as ‖Δ_ij − v_i‖² with
//!   Δ_ij the displacement from i to j ([`motion_delta`]: the centroids',
//!   or the uncut box sides' for a view the border cuts, see below). A
//!   node whose velocity is still unknown (a target's first frame) is projected with the fleet's typical
//!   velocity `v_init` and uses the wider σ_v0 instead (see `sigma`);
//!   the tracker also tries it projected by `−v_init`, at a cost
//!   (`TrackConfig::newborn_reverse_cost`: a fish may swim against the
//!   school);
//! - area      z_a = (ΔA)² / σ_a². Areas are first normalised to a common
//!   range, `A·(z / Z_REF)²` (z = stereo depth, `TrackConfig::z_ref_mm`,
//!   default 2000 mm, the middle of the Cam-trawl's 1.2–3 m range), when both
//!   depths are known. **Deviation:** the paper squares the absolute
//!   difference; fish areas here span two orders of magnitude (3·10³ to
//!   2·10⁵ px), which no single σ_a fits, so ΔA is the relative difference
//!   `2|A_j − A_i| / (A_j + A_i)`;
//! - direction z_m = θ(v_ij, v_ref)² / σ_m², eq. (7), v_ij = Δ_ij;
//!   θ = 0 for a displacement under 1 px;
//!   **Deviation (border cuts):** a view whose box touches the frame border
//!   (within 2 px) shows only part of the fish, so its area is a lower
//!   bound: the area cue is 0 when the cut view is the smaller one; and its
//!   centroid is off the fish's, so displacements (vicinity, direction,
//!   the velocity of eq. 13–14) are measured on the box sides the border
//!   does not cut ([`motion_delta`], `TrackConfig::cut_aware_motion`);
//! - direction reference: **v_ref is the node's own velocity** when it has
//!   one (the target's motion trend, eq. 14). A node without a velocity
//!   (a target's first frame) takes the fish's **body axis** instead
//!   (`TrackConfig::axis_direction`, our addition): the principal axis of
//!   the node's view, or of the candidate's, when that view is uncut and
//!   elongated; an axis has no sign (a fish may be carried tail first), so
//!   θ is the angle to its line, in [0, π/2]. Fish are carried through the
//!   view along their bodies (synthetic hauls: median 10°, 90th percentile
//!   26° between the body axis and the next displacement), while `v_init`
//!   is only the fleet's typical step (seeds 1–30 / 31–60: success 594 →
//!   603 / 600 → 624). Without an axis a first transition has no
//!   direction cue. The paper chooses v_ref
//!   "according to the motion trend of fish schools or the movement of
//!   cameras"; a fixed (−1, 0) — or the school's mean motion — penalises
//!   every fish that swims another way (on synthetic hauls a quarter of the
//!   true links move towards +x), so each target's own trend is used.
//!   Table I's v_ref is therefore not used by the tracker;
//! - depth (our addition, bit [`Cues::DEPTH`]) z_d = (relative depth
//!   change)² / σ_d², `2|z_j − z_i| / (z_j + z_i)` when both stereo depths
//!   are known, else 0. Fish cross the view at nearly constant range, so
//!   the stereo depth separates fish that image-plane vicinity cannot at
//!   5 fps (measured on synthetic hauls: true links median 4 % change,
//!   wrong links 25 %);
//! - histogram z_h = EMD² / σ_h², EMD of the two 16-bin histograms, each
//!   normalised to unit mass: for 1-D histograms the EMD is the L1 distance
//!   of the cumulative histograms, in bins. An empty histogram gives EMD 0.
//!
//! The stereo cost sums both cameras when both the node and the observation
//! have a right view; otherwise the left camera counts twice, so costs stay
//! on one scale. Dropped cues ([`Cues`]) contribute 0 (Fig. 15 ablation).
//!
//! Angles use `libm::atan2f` (correctly rounded to a few ulp) rather than
//! micromath's 0.003-rad approximation, so core and f64 reference agree.

use crate::object::HIST_BINS;

/// Cumulative normalised histogram, fixed point: `cdf[b]` = 65535 · (mass of
/// bins 0..=b). The last bin (always 65535) is not stored.
pub type Cdf = [u16; HIST_BINS - 1];

/// Which cues enter the matching cost (bit set; Fig. 15 ablation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Cues(pub u8);

impl Cues {
    /// Vicinity cue z_v.
    pub const VICINITY: u8 = 1;
    /// Area cue z_a.
    pub const AREA: u8 = 2;
    /// Motion direction cue z_m.
    pub const DIRECTION: u8 = 4;
    /// Histogram (EMD) cue z_h.
    pub const HISTOGRAM: u8 = 8;
    /// Stereo depth consistency z_d (our addition).
    pub const DEPTH: u8 = 16;
    /// All five cues (the paper's four plus depth).
    pub const ALL: Cues = Cues(31);

    /// All cues but `bit` (one of the constants above).
    pub const fn without(bit: u8) -> Cues {
        Cues(31 & !bit)
    }

    /// True when `bit` is set.
    pub const fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }
}

impl Default for Cues {
    fn default() -> Self {
        Cues::ALL
    }
}

/// Variances σ² of the cue features (squared units: px², 1, rad², bins²).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sigmas {
    /// σ_v² — vicinity of a tracked node (velocity known), px².
    pub v: f32,
    /// σ_v0² — vicinity of a node in its target's first frame, px².
    pub v0: f32,
    /// σ_a² — relative area difference.
    pub a: f32,
    /// σ_m² — motion direction, rad².
    pub m: f32,
    /// σ_h² — EMD, bins².
    pub h: f32,
    /// σ_d² — relative depth change.
    pub d: f32,
}

impl Sigmas {
    /// Defaults for a `width`-pixel-wide frame: σ_v = 250 px and σ_v0 = 350 px
    /// at 2048 (scaled linearly; 5 fps prediction errors are hundreds of
    /// pixels), σ_a = 0.25, σ_m = 0.5 rad, σ_h = 1 bin, σ_d = 0.04.
    pub fn for_frame(width: u32) -> Sigmas {
        let s = width as f32 / crate::params::PAPER_FRAME_WIDTH as f32;
        let sv = 250.0 * s;
        let sv0 = 350.0 * s;
        Sigmas {
            v: (sv * sv).max(1.0),
            v0: (sv0 * sv0).max(1.0),
            a: 0.25 * 0.25,
            m: 0.5 * 0.5,
            h: 1.0,
            d: 0.04 * 0.04,
        }
    }
}

/// The state of one camera's view of a node that the cost needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewFeat {
    /// Centroid.
    pub pos: [f32; 2],
    /// Raw area, px.
    pub area: f32,
    /// The box touches the frame border: the area is a lower bound (some
    /// side is cut; [`ViewFeat::cut_sides`] names them when the box holds
    /// its centroid).
    pub cut: bool,
    /// The upright box `[x0, y0, x1, y1)` in the centroid's coordinates.
    pub bbox: [f32; 4],
    /// Which sides of the box the border cuts ([`CUT_X_MIN`], …).
    pub cut_sides: u8,
    /// Normalised cumulative histogram (`None` when the histogram is empty).
    pub cdf: Option<Cdf>,
    /// The body axis of an uncut, elongated view: the direction of its
    /// line in whole degrees, 0 to 179 ([`axis_degrees`]); [`NO_AXIS`]
    /// when the view gives none. (One byte fits in the struct's padding:
    /// the tracker holds hundreds of these.)
    pub axis: u8,
}

/// Largest |angle| [`axis_degrees`] reads, radians (8π; the oriented box
/// gives (−π/2, π/2]).
pub const MAX_AXIS_ANGLE: f32 = 8.0 * core::f32::consts::PI;

/// [`ViewFeat::axis`] of a view without a body axis.
pub const NO_AXIS: u8 = u8::MAX;

/// A body axis at `angle` radians (any sign or turn) as the degree of its
/// line, 0 to 179 (rounded; an axis has no sign); [`NO_AXIS`] when the
/// angle is not finite or beyond ±[`MAX_AXIS_ANGLE`].
pub fn axis_degrees(angle: f32) -> u8 {
    // (beyond a few turns an f32 angle has lost its degrees anyway)
    if angle.is_nan() || libm::fabsf(angle) > MAX_AXIS_ANGLE {
        return NO_AXIS;
    }
    let d = libm::roundf(libm::fmodf(angle.to_degrees(), 180.0));
    let d = if d < 0.0 { d + 180.0 } else { d };
    (d as u32 % 180) as u8
}

/// Unit vector of an axis of [`axis_degrees`] (zero for [`NO_AXIS`], which
/// gives no direction cue).
pub fn axis_vector(deg: u8) -> [f32; 2] {
    if deg >= 180 {
        return [0.0; 2];
    }
    let r = (deg as f32).to_radians();
    [libm::cosf(r), libm::sinf(r)]
}

/// [`ViewFeat::cut_sides`] bit: the border cuts the box's left side.
pub const CUT_X_MIN: u8 = 1;
/// The box's right side is cut.
pub const CUT_X_MAX: u8 = 2;
/// The box's top side is cut.
pub const CUT_Y_MIN: u8 = 4;
/// The box's bottom side is cut.
pub const CUT_Y_MAX: u8 = 8;

/// The fish's displacement from view `a` to view `b` (our addition, beyond
/// eq. (7)–(8)). A view the frame border cuts shows only part of the fish,
/// so its centroid lies off the fish's, towards the inside of the frame, by
/// up to half a body length (a fish entering at the right border moves
/// hundreds of pixels less, centroid to centroid, than it swims). Along an
/// axis where one of the two boxes is cut on one side only, the
/// displacement is therefore that of the box sides the border does not cut
/// (the fish's head or tail, seen whole in both views); otherwise, and with
/// `cut_aware` false (the paper), that of the centroids.
pub fn motion_delta(a: &ViewFeat, b: &ViewFeat, cut_aware: bool) -> [f32; 2] {
    let cut = a.cut_sides | b.cut_sides;
    let axis = |k: usize, lo: u8, hi: u8| {
        let centre = b.pos[k] - a.pos[k];
        if !cut_aware || (cut & lo != 0) == (cut & hi != 0) {
            centre
        } else if cut & hi != 0 {
            b.bbox[k] - a.bbox[k]
        } else {
            b.bbox[k + 2] - a.bbox[k + 2]
        }
    };
    [axis(0, CUT_X_MIN, CUT_X_MAX), axis(1, CUT_Y_MIN, CUT_Y_MAX)]
}

/// Squared feature values of one camera's edge (what σ estimation collects).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EdgeFeatures {
    /// ‖x_j − x̂_i‖², px².
    pub d2: f32,
    /// (relative area difference)².
    pub a2: f32,
    /// θ(v_ij, v_ref)², rad².
    pub m2: f32,
    /// EMD², bins².
    pub h2: f32,
    /// (relative depth change)².
    pub z2: f32,
}

/// Cumulative normalised histogram of raw counts (`None` if all zero).
pub fn cdf(hist: &[u32; HIST_BINS]) -> Option<Cdf> {
    let total: u64 = hist.iter().map(|&h| h as u64).sum();
    if total == 0 {
        return None;
    }
    let mut out = [0u16; HIST_BINS - 1];
    let mut cum = 0u64;
    for (o, &h) in out.iter_mut().zip(hist.iter()) {
        cum += h as u64;
        *o = (cum * 65535 / total) as u16;
    }
    Some(out)
}

/// 1-D earth mover's distance between two normalised histograms, in bins:
/// Σ_b |CDF_a(b) − CDF_b(b)|. 0 if either histogram is empty.
pub fn emd(a: &Option<Cdf>, b: &Option<Cdf>) -> f32 {
    match (a, b) {
        (Some(a), Some(b)) => {
            let s: u32 = a
                .iter()
                .zip(b.iter())
                .map(|(&x, &y)| (x as i32 - y as i32).unsigned_abs())
                .sum();
            s as f32 / 65535.0
        }
        _ => 0.0,
    }
}

/// The direction reference of eq. (7) for one camera's edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionRef {
    /// v_ref; zero gives no direction cue.
    pub v_ref: [f32; 2],
    /// `v_ref` is a sign-free body axis: θ is taken to its line,
    /// min(θ, π − θ).
    pub line: bool,
    /// Added to the displacement before θ is measured: a newborn lost on
    /// its first transition sits at `v_init`'s guess, and its heading is
    /// measured from where it was seen, `lost · v_init` back.
    pub offset: [f32; 2],
}

impl DirectionRef {
    /// A target's own velocity (or the paper's fixed v_ref).
    pub const fn velocity(v: [f32; 2]) -> DirectionRef {
        DirectionRef {
            v_ref: v,
            line: false,
            offset: [0.0; 2],
        }
    }

    /// No direction cue.
    pub const NONE: DirectionRef = DirectionRef::velocity([0.0; 2]);
}

/// θ(v, v_ref) of eq. (7) in [0, π]; 0 when ‖v‖ < 1 px or v_ref is zero.
/// ([`edge_features`] folds it to [0, π/2] for a sign-free axis.)
pub fn direction_angle(v: [f32; 2], v_ref: [f32; 2]) -> f32 {
    if v[0] * v[0] + v[1] * v[1] < 1.0 || v_ref[0] * v_ref[0] + v_ref[1] * v_ref[1] <= 0.0 {
        return 0.0;
    }
    let cross = v_ref[0] * v[1] - v_ref[1] * v[0];
    let dot = v_ref[0] * v[0] + v_ref[1] * v[1];
    libm::fabsf(libm::atan2f(cross, dot))
}

/// Area normalised to depth `Z_REF`: A·(z/z_ref)² when `z` is known.
pub fn normalised_area(area: f32, depth: Option<f32>, z_ref: f32) -> f32 {
    match depth {
        Some(z) if z_ref > 0.0 => {
            let r = z / z_ref;
            area * r * r
        }
        _ => area,
    }
}

/// Squared features of one camera's edge from node view `prev` (moving by
/// `vel`) to observation view `cand`: the vicinity is the displacement
/// ([`motion_delta`]) minus `vel`, i.e. `x_j − x̂_i`. `depths` are (node,
/// observation); the areas are depth-normalised only when both are known.
/// `dir` is the direction reference ([`DirectionRef`]).
pub fn edge_features(
    prev: &ViewFeat,
    vel: [f32; 2],
    cand: &ViewFeat,
    depths: (Option<f32>, Option<f32>),
    dir: DirectionRef,
    z_ref: f32,
    cut_aware: bool,
) -> EdgeFeatures {
    let disp = motion_delta(prev, cand, cut_aware);
    let dx = disp[0] - vel[0];
    let dy = disp[1] - vel[1];
    let (za, zb) = match depths {
        (Some(a), Some(b)) => (Some(a), Some(b)),
        _ => (None, None),
    };
    let an = normalised_area(prev.area, za, z_ref);
    let bn = normalised_area(cand.area, zb, z_ref);
    let cut_smaller = (prev.cut && an < bn) || (cand.cut && bn < an);
    let rel = if an + bn > 0.0 && !cut_smaller {
        2.0 * libm::fabsf(an - bn) / (an + bn)
    } else {
        0.0
    };
    let moved = [disp[0] + dir.offset[0], disp[1] + dir.offset[1]];
    let th = direction_angle(moved, dir.v_ref);
    // an axis has no sign: the angle to its line
    let th = if dir.line {
        th.min(core::f32::consts::PI - th)
    } else {
        th
    };
    let e = emd(&prev.cdf, &cand.cdf);
    let dz = match (za, zb) {
        (Some(a), Some(b)) if a + b > 0.0 => 2.0 * libm::fabsf(a - b) / (a + b),
        _ => 0.0,
    };
    EdgeFeatures {
        d2: dx * dx + dy * dy,
        a2: rel * rel,
        m2: th * th,
        h2: e * e,
        z2: dz * dz,
    }
}

/// Robust forms of the matching cost's terms (our addition, see
/// [`camera_cost`]). `NONE` is eq. (9) as published.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Robust {
    /// Cap on every term z (`TrackConfig::cue_cap`).
    pub cap: f32,
    /// Scale c of the area term's soft bound ρ(z) = c·ln(1 + z/c)
    /// (`TrackConfig::area_robust`); ∞ = z.
    pub area: f32,
    /// Scale c of the histogram term's soft bound
    /// (`TrackConfig::hist_robust`); ∞ = z.
    pub hist: f32,
    /// Scale c of the depth term's soft bound
    /// (`TrackConfig::depth_robust`); ∞ = z.
    pub depth: f32,
}

impl Robust {
    /// Eq. (9) as published: no cap, no soft bound.
    pub const NONE: Robust = Robust {
        cap: f32::INFINITY,
        area: f32::INFINITY,
        hist: f32::INFINITY,
        depth: f32::INFINITY,
    };
}

/// Soft bound ρ(z) = c·ln(1 + z/c) of a cue term: ≈ z for z ≪ c, growing
/// only logarithmically beyond (the negative log-likelihood of a
/// heavy-tailed, Cauchy-like feature); `z` itself when c is ∞.
pub fn soft_bound(z: f32, c: f32) -> f32 {
    if c.is_finite() && c > 0.0 {
        c * libm::log1pf(z / c)
    } else {
        z
    }
}

/// One camera's matching cost c_ij, eq. (9), from squared features.
/// `first` selects σ_v0 for a node whose velocity is not yet known.
///
/// **Robust forms (our addition):** each cue's term z is capped at `r.cap`
/// (`TrackConfig::cue_cap`; default ∞, see there): at 5 fps single cues are
/// heavy-tailed (a fish turns, bends, or is cut by the border), and one
/// outlying cue must not veto a link the other cues support. The
/// appearance terms (area, histogram) and the stereo depth term can instead
/// be softly bounded, [`soft_bound`] with `r.area` / `r.hist` / `r.depth`
/// (see the `TrackConfig` fields for their defaults). With
/// [`Robust::NONE`] this is eq. (9) exactly.
pub fn camera_cost(f: &EdgeFeatures, s: &Sigmas, first: bool, cues: Cues, r: &Robust) -> f32 {
    let mut c = 0.0;
    let cap = r.cap;
    let t = |z: f32| if z < cap { z } else { cap };
    if cues.has(Cues::VICINITY) {
        c += t(f.d2 / if first { s.v0 } else { s.v });
    }
    if cues.has(Cues::AREA) {
        c += t(soft_bound(f.a2 / s.a, r.area));
    }
    if cues.has(Cues::DIRECTION) {
        c += t(f.m2 / s.m);
    }
    if cues.has(Cues::HISTOGRAM) {
        c += t(soft_bound(f.h2 / s.h, r.hist));
    }
    if cues.has(Cues::DEPTH) {
        c += t(soft_bound(f.z2 / s.d, r.depth));
    }
    c
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn axes_are_lines_in_whole_degrees() {
        use core::f32::consts::PI;
        assert_eq!(axis_degrees(0.0), 0);
        assert_eq!(axis_degrees(PI / 2.0), 90);
        assert_eq!(axis_degrees(-PI / 2.0), 90);
        assert_eq!(axis_degrees(PI), 0);
        assert_eq!(axis_degrees(-PI / 4.0), 135);
        assert_eq!(axis_degrees(3.0 * PI + 0.1), axis_degrees(0.1));
        assert_eq!(axis_degrees(-0.001), 0);
        assert_eq!(axis_degrees(PI - 0.001), 0);
        assert_eq!(axis_degrees(f32::NAN), NO_AXIS);
        assert_eq!(axis_degrees(f32::INFINITY), NO_AXIS);
        assert_eq!(axis_degrees(1e37), NO_AXIS);
        assert_eq!(axis_degrees(-30.0), NO_AXIS);
        assert_eq!(axis_degrees(-25.0), axis_degrees(-25.0 + 8.0 * PI));
        assert_eq!(axis_vector(NO_AXIS), [0.0; 2]);
        let v = axis_vector(axis_degrees(1.0));
        assert!((v[0] - 1f32.cos()).abs() < 0.01 && (v[1] - 1f32.sin()).abs() < 0.01);
        // every degree in range
        for a in -720..720 {
            assert!(axis_degrees(a as f32 * 0.01) < 180);
        }
    }

    #[test]
    fn emd_of_shifted_spike_is_the_shift() {
        let mut a = [0u32; 16];
        let mut b = [0u32; 16];
        a[3] = 10;
        b[7] = 99;
        assert!((emd(&cdf(&a), &cdf(&b)) - 4.0).abs() < 1e-3);
        assert_eq!(emd(&cdf(&a), &cdf(&a)), 0.0);
        assert_eq!(emd(&cdf(&[0; 16]), &cdf(&b)), 0.0);
        // Half the mass moved by 2 bins: EMD 1.
        let mut c = [0u32; 16];
        c[3] = 5;
        c[5] = 5;
        assert!((emd(&cdf(&a), &cdf(&c)) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn direction_angle_against_reference() {
        let r = [-1.0, 0.0];
        assert!(direction_angle([-300.0, 0.0], r).abs() < 1e-6);
        assert!((direction_angle([300.0, 0.0], r) - core::f32::consts::PI).abs() < 1e-5);
        assert!((direction_angle([0.0, 50.0], r) - core::f32::consts::FRAC_PI_2).abs() < 1e-5);
        assert!((direction_angle([0.0, -50.0], r) - core::f32::consts::FRAC_PI_2).abs() < 1e-5);
        assert_eq!(direction_angle([0.5, 0.5], r), 0.0);
    }

    #[test]
    fn cost_sums_the_selected_cues() {
        let f = EdgeFeatures {
            d2: 100.0,
            a2: 1.0,
            m2: 4.0,
            h2: 9.0,
            z2: 0.0,
        };
        let s = Sigmas {
            v: 100.0,
            v0: 400.0,
            a: 1.0,
            m: 1.0,
            h: 1.0,
            d: 1.0,
        };
        assert_eq!(camera_cost(&f, &s, false, Cues::ALL, &Robust::NONE), 15.0);
        assert_eq!(camera_cost(&f, &s, true, Cues::ALL, &Robust::NONE), 14.25);
        assert_eq!(
            camera_cost(&f, &s, false, Cues::without(Cues::HISTOGRAM), &Robust::NONE),
            6.0
        );
        assert_eq!(camera_cost(&f, &s, false, Cues(0), &Robust::NONE), 0.0);
        // Capped: 1 + 1 + 3 + 3 (z_v = 1, z_a = 1, z_m = 4 → 3, z_h = 9 → 3).
        let capped = Robust {
            cap: 3.0,
            ..Robust::NONE
        };
        assert_eq!(camera_cost(&f, &s, false, Cues::ALL, &capped), 8.0);
        // Soft bounds on area and histogram: 1 + 4·ln(1 + 1/4) + 4 +
        // 4·ln(1 + 9/4) instead of 1 + 1 + 4 + 9.
        let soft = Robust {
            area: 4.0,
            hist: 4.0,
            ..Robust::NONE
        };
        let want = 1.0 + 4.0 * (1.25f64).ln() + 4.0 + 4.0 * (3.25f64).ln();
        let got = camera_cost(&f, &s, false, Cues::ALL, &soft) as f64;
        assert!((got - want).abs() < 1e-5, "{got} {want}");
        // The depth term's soft bound: z_d = 100 → 4·ln(26) (σ_d² = 1).
        let deep = EdgeFeatures { z2: 100.0, ..f };
        let depth_soft = Robust {
            depth: 4.0,
            ..Robust::NONE
        };
        let got = camera_cost(&deep, &s, false, Cues::ALL, &depth_soft) as f64;
        let want = 15.0 + 4.0 * 26f64.ln();
        assert!((got - want).abs() < 1e-4, "{got} {want}");
        assert_eq!(
            camera_cost(&deep, &s, false, Cues::ALL, &Robust::NONE),
            115.0
        );
        // ρ(z) ≤ z, ≈ z for small z, and ρ = z with c = ∞.
        assert_eq!(soft_bound(7.0, f32::INFINITY), 7.0);
        assert!((soft_bound(0.01, 9.0) - 0.01).abs() < 1e-5);
        assert!(soft_bound(100.0, 9.0) < 23.0);
    }

    #[test]
    fn depth_normalisation_removes_range() {
        // The same fish at 1 m and 2 m: area quarters, normalised areas equal.
        let p = ViewFeat {
            pos: [0.0, 0.0],
            area: 4000.0,
            cut: false,
            bbox: [0.0; 4],
            cut_sides: 0,
            cdf: None,
            axis: NO_AXIS,
        };
        let q = ViewFeat {
            pos: [0.0, 0.0],
            area: 1000.0,
            cut: false,
            bbox: [0.0; 4],
            cut_sides: 0,
            cdf: None,
            axis: NO_AXIS,
        };
        let f = edge_features(
            &p,
            [0.0, 0.0],
            &q,
            (Some(1000.0), Some(2000.0)),
            DirectionRef::velocity([-1.0, 0.0]),
            2000.0,
            true,
        );
        assert!(f.a2 < 1e-12);
        let g = edge_features(
            &p,
            [0.0, 0.0],
            &q,
            (None, Some(2000.0)),
            DirectionRef::velocity([-1.0, 0.0]),
            2000.0,
            true,
        );
        assert!((g.a2 - 1.44).abs() < 1e-5); // 2·3000/5000 = 1.2
    }
}
