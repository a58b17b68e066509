//! Float reference of the tracker (core `track`, paper Sections IV.B–C):
//! the same association rules written plainly in `f64` with growable
//! vectors, as the yardstick for "identical track assignments".
//!
//! What must match the core exactly (the rules, not the code): cue
//! definitions (with the `cue_cap` cap and the `area_robust` /
//! `hist_robust` soft bounds c·ln(1 + z/c)) and σ estimation (last 128
//! chosen-edge samples per cue, median rank ⌊n/2⌋ / 0.4549, clamped to [default, 16·default], after
//! `min_sigma_samples`); the candidate gate; K − 1 cheapest real nodes plus
//! one predicted node per stage; commit of the oldest stage along the best
//! path with pruning at depth D; the joint selection of each frame's best
//! nodes (greedy one-to-one on C_i + c_ij − min C, refined by pair
//! exchanges on the total, `swap_passes`) and the share cost;
//! births (border margin or large area — else tentative, `confirm_births` — none next to a lost target's
//! prediction) and deaths (exit margin, `max_lost`); the newborn velocity
//! (median displacement, else v_ref · W / 4.3); greedy MC/NN; capacities
//! T, D, K, N; displacements between views the border cuts on one side of
//! an axis measured on the uncut box sides (`cut_aware_motion`), boxes
//! moved with a lost target's prediction; a newborn's first-transition
//! direction cue against its view's body axis in whole degrees (or the
//! candidate's; a lost newborn's from where it was seen; `axis_direction`).
//! Differences that are allowed: f64 instead of f32, exact histogram CDFs
//! instead of 16-bit fixed point.
#![allow(clippy::needless_range_loop)] // index loops mirror the paper's notation

use fishtrack_core::params::{Params, Tracker as Assoc};
use fishtrack_core::track::{Observation, TrackConfig};

/// Capacities mirrored from the core's const generics.
#[derive(Debug, Clone, Copy)]
pub struct Capacities {
    /// Live targets (T).
    pub targets: usize,
    /// Trellis depth (D).
    pub depth: usize,
    /// Nodes per stage (K).
    pub nodes: usize,
    /// Observations per frame (N).
    pub obs: usize,
}

impl Capacities {
    /// The core's `DefaultTracker`.
    pub const DEFAULT: Capacities = Capacities {
        targets: 32,
        depth: 16,
        nodes: 8,
        obs: 64,
    };
}

/// One committed frame of a track: observation index or `None` (predicted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Assignment {
    /// Frame index.
    pub frame: u32,
    /// Track id.
    pub track: u32,
    /// Observation index in the frame, `None` when predicted.
    pub obs: Option<u16>,
}

/// Result of [`compare`].
#[derive(Debug, Clone, Default)]
pub struct Agreement {
    /// Assignments in both.
    pub same: usize,
    /// Only in the first list (up to 10 shown).
    pub only_a: Vec<Assignment>,
    /// Only in the second list (up to 10 shown).
    pub only_b: Vec<Assignment>,
    /// Total differing assignments.
    pub differing: usize,
}

impl Agreement {
    /// True when both lists hold the same assignments.
    pub fn identical(&self) -> bool {
        self.differing == 0
    }
}

/// Compares two assignment lists as sets (order-free).
pub fn compare(a: &[Assignment], b: &[Assignment]) -> Agreement {
    let mut x = a.to_vec();
    let mut y = b.to_vec();
    x.sort();
    y.sort();
    let mut r = Agreement::default();
    let (mut i, mut j) = (0, 0);
    while i < x.len() || j < y.len() {
        match (x.get(i), y.get(j)) {
            (Some(p), Some(q)) if p == q => {
                r.same += 1;
                i += 1;
                j += 1;
            }
            (Some(p), Some(q)) if p < q => {
                r.differing += 1;
                if r.only_a.len() < 10 {
                    r.only_a.push(*p);
                }
                i += 1;
            }
            (Some(p), None) => {
                r.differing += 1;
                if r.only_a.len() < 10 {
                    r.only_a.push(*p);
                }
                i += 1;
            }
            (_, Some(q)) => {
                r.differing += 1;
                if r.only_b.len() < 10 {
                    r.only_b.push(*q);
                }
                j += 1;
            }
            (None, None) => break,
        }
    }
    r
}

#[derive(Debug, Clone)]
struct View {
    pos: [f64; 2],
    area: f64,
    cut: bool,
    /// Upright box: min corner, max corner (exclusive).
    lo: [f64; 2],
    hi: [f64; 2],
    /// Per axis (x, y): the border cuts the min side / the max side.
    cut_lo: [bool; 2],
    cut_hi: [bool; 2],
    cdf: Option<[f64; 15]>,
    /// Unit body axis of an uncut view elongated at least
    /// `MIN_AXIS_ELONGATION` (`TrackConfig::axis_direction`), its
    /// direction rounded to whole degrees.
    axis: Option<[f64; 2]>,
}

/// Displacement of the fish from view `a` to view `b` (core:
/// `track::cost::motion_delta`): per axis, when the border cuts one side
/// of either box (and not the other side), the uncut sides' displacement;
/// otherwise the centroids'.
fn displacement(a: &View, b: &View, cut_aware: bool) -> [f64; 2] {
    let mut d = [0.0; 2];
    for k in 0..2 {
        let lo = a.cut_lo[k] || b.cut_lo[k];
        let hi = a.cut_hi[k] || b.cut_hi[k];
        d[k] = if cut_aware && hi && !lo {
            b.lo[k] - a.lo[k]
        } else if cut_aware && lo && !hi {
            b.hi[k] - a.hi[k]
        } else {
            b.pos[k] - a.pos[k]
        };
    }
    d
}

/// The box is a view's upright box: non-empty and holding the centroid.
fn sane_box(v: &fishtrack_core::track::CameraView) -> bool {
    let b = &v.bbox;
    let (cx, cy) = (v.cx as f64, v.cy as f64);
    b.w > 0
        && b.h > 0
        && cx >= b.x as f64
        && cx <= b.right() as f64
        && cy >= b.y as f64
        && cy <= b.bottom() as f64
}

/// `v` moved by `d` (a lost target's prediction): centroid and box.
fn moved(v: &View, d: [f64; 2]) -> View {
    let mut m = v.clone();
    for k in 0..2 {
        m.pos[k] += d[k];
        m.lo[k] += d[k];
        m.hi[k] += d[k];
    }
    m
}

#[derive(Debug, Clone)]
struct Cand {
    obs: usize,
    left: View,
    right: Option<View>,
    depth: Option<f64>,
    bbox: (u32, u32, u32, u32),
    area: f64,
}

#[derive(Debug, Clone)]
struct State {
    cost: f64,
    left: View,
    right: Option<View>,
    vel: [f64; 2],
    vel_known: bool,
    depth: Option<f64>,
    lost: u32,
}

#[derive(Debug, Clone, Copy)]
struct Node {
    obs: Option<usize>,
    pred: usize,
    /// Left position (the confirmation of tentative targets).
    pos: [f64; 2],
}

struct Target {
    id: u32,
    hits: u32,
    stages: Vec<(u32, Vec<Node>)>,
    front: Vec<State>,
    closed: bool,
    /// Closed as a duplicate (nothing more committed).
    dup: bool,
    /// Close decided this frame, carried out after every target stepped.
    pending: bool,
    /// That close is an exit (lost with its prediction at the border).
    exit: bool,
    /// Committed path: (frame, observation).
    path: Vec<(u32, Option<usize>)>,
    /// Born where the paper's rule rejects a false alarm (mid-view, small):
    /// reported only if it closes with `confirm_births` observations,
    /// `confirm_min_step` px per frame from where it was born.
    tentative: bool,
    /// (frame, left position) of the observation it was born on.
    born: (u32, [f64; 2]),
}

/// Recently closed tracks' observations, as the core's ring
/// (`fishtrack_core::track::RECENT` slots, the oldest overwritten):
/// (track, frame, observation, the track's observations).
struct Recent {
    slots: Vec<Option<(u32, u32, usize, u32)>>,
    next: usize,
}

#[derive(Default)]
struct Sig {
    v: Vec<f64>,
    v0: Vec<f64>,
    a: Vec<f64>,
    m: Vec<f64>,
    h: Vec<f64>,
    d: Vec<f64>,
    vx: Vec<f64>,
    vy: Vec<f64>,
}

const WINDOW: usize = 128;

fn push(v: &mut Vec<f64>, x: f64) {
    if x.is_finite() {
        v.push(x);
        if v.len() > WINDOW {
            v.remove(0);
        }
    }
}

fn median(v: &[f64], min: usize) -> Option<f64> {
    if v.len() < min.max(1) {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    Some(s[s.len() / 2])
}

struct Costs {
    s: [f64; 6], // v v0 a m h d
    cues: u8,
    v_init: [f64; 2],
    z_ref: f64,
    cap: f64,
    /// Soft-bound scales of the area, histogram and depth terms (∞ = none).
    area_c: f64,
    hist_c: f64,
    depth_c: f64,
    /// `TrackConfig::cut_aware_motion`.
    cut_aware: bool,
    /// `TrackConfig::newborn_reverse_cost` (∞ = forward projection only).
    reverse: f64,
}

struct Feat {
    d2: f64,
    a2: f64,
    m2: f64,
    h2: f64,
    z2: f64,
}

fn cdf(h: &[u32; 16]) -> Option<[f64; 15]> {
    let t: f64 = h.iter().map(|&x| x as f64).sum();
    if t == 0.0 {
        return None;
    }
    let mut c = [0.0; 15];
    let mut acc = 0.0;
    for b in 0..15 {
        acc += h[b] as f64;
        c[b] = acc / t;
    }
    Some(c)
}

fn feat(
    p: &View,
    vel: [f64; 2],
    c: &View,
    depths: (Option<f64>, Option<f64>),
    (v_ref, line, offset): ([f64; 2], bool, [f64; 2]),
    k: &Costs,
) -> Feat {
    let norm = |a: f64, z: Option<f64>| match (depths, z) {
        ((Some(_), Some(_)), Some(z)) => a * (z / k.z_ref).powi(2),
        _ => a,
    };
    let an = norm(p.area, depths.0);
    let bn = norm(c.area, depths.1);
    // A border-cut view's area is a lower bound: no penalty when it is the smaller.
    let cut_smaller = (p.cut && an < bn) || (c.cut && bn < an);
    let rel = if an + bn > 0.0 && !cut_smaller {
        2.0 * (an - bn).abs() / (an + bn)
    } else {
        0.0
    };
    let v = displacement(p, c, k.cut_aware);
    // the direction's displacement (a lost newborn's from its sighting)
    let w = [v[0] + offset[0], v[1] + offset[1]];
    let th = if w[0] * w[0] + w[1] * w[1] < 1.0 || v_ref == [0.0, 0.0] {
        0.0
    } else {
        // Angle between v and v_ref by the cosine formula, eq. (7).
        let cos =
            (w[0] * v_ref[0] + w[1] * v_ref[1]) / (w[0].hypot(w[1]) * v_ref[0].hypot(v_ref[1]));
        let th = cos.clamp(-1.0, 1.0).acos();
        // a body axis has no sign: the angle to its line
        if line {
            th.min(std::f64::consts::PI - th)
        } else {
            th
        }
    };
    let emd = match (&p.cdf, &c.cdf) {
        (Some(a), Some(b)) => a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum(),
        _ => 0.0,
    };
    // Relative stereo depth change (our fifth cue).
    let dz = match depths {
        (Some(a), Some(b)) if a + b > 0.0 => 2.0 * (a - b).abs() / (a + b),
        _ => 0.0,
    };
    Feat {
        d2: (v[0] - vel[0]).powi(2) + (v[1] - vel[1]).powi(2),
        a2: rel * rel,
        m2: th * th,
        h2: emd * emd,
        z2: dz * dz,
    }
}

/// Soft bound c·ln(1 + z/c) of an appearance term; z when c is ∞.
fn soft(z: f64, c: f64) -> f64 {
    if c.is_finite() {
        c * (z / c).ln_1p()
    } else {
        z
    }
}

fn cam_cost(f: &Feat, k: &Costs, first: bool) -> f64 {
    // Each cue's term capped at cue_cap (robust eq. 9); area and histogram
    // terms softly bounded by area_robust / hist_robust.
    let terms = [
        (1, f.d2 / if first { k.s[1] } else { k.s[0] }),
        (2, soft(f.a2 / k.s[2], k.area_c)),
        (4, f.m2 / k.s[3]),
        (8, soft(f.h2 / k.s[4], k.hist_c)),
        (16, soft(f.z2 / k.s[5], k.depth_c)),
    ];
    terms
        .iter()
        .filter(|(bit, _)| k.cues & bit != 0)
        .map(|&(_, z)| z.min(k.cap))
        .sum()
}

/// A view's border as four polylines (`fishtrack_core::track::ViewOutline`
/// in `f64`): per side, the span along it and the coordinate across it at
/// evenly spaced samples, linear between them, constant beyond.
struct Outline {
    /// top, bottom, left, right: (from, to, samples).
    sides: [(f64, f64, Vec<f64>); 4],
}

impl Outline {
    fn from_core(o: fishtrack_core::track::ViewOutline) -> Self {
        let side = |s: &fishtrack_core::track::outline::Side| {
            (
                s.from as f64,
                s.to as f64,
                s.at.iter().map(|&v| v as f64).collect(),
            )
        };
        Outline {
            sides: [side(&o.top), side(&o.bottom), side(&o.left), side(&o.right)],
        }
    }

    /// Side `i`'s coordinate at position `t` along it.
    fn at(&self, i: usize, t: f64) -> f64 {
        let (from, to, v) = &self.sides[i];
        let n = v.len() - 1;
        if to <= from {
            return v[0];
        }
        let u = ((t - from) / (to - from)).clamp(0.0, 1.0) * n as f64;
        let k = (u.floor() as usize).min(n - 1);
        v[k] + (u - k as f64) * (v[k + 1] - v[k])
    }

    /// Side `i`'s greatest (`max`) or least coordinate over `a..=b`.
    fn extreme(&self, i: usize, a: f64, b: f64, max: bool) -> f64 {
        let (from, to, v) = &self.sides[i];
        let n = v.len() - 1;
        let mut out = vec![self.at(i, a), self.at(i, b)];
        for (k, &x) in v.iter().enumerate() {
            let t = from + (to - from) * k as f64 / n as f64;
            if t > a && t < b {
                out.push(x);
            }
        }
        let f = if max { f64::max } else { f64::min };
        out.into_iter().reduce(f).unwrap_or(0.0)
    }

    /// Cut sides of box (x0, y0, x1, y1) within `k` px: [x-, y-], [x+, y+].
    fn cut(&self, (x0, y0, x1, y1): (f64, f64, f64, f64), k: f64) -> ([bool; 2], [bool; 2]) {
        (
            [
                x0 <= self.extreme(2, y0, y1, true) + k,
                y0 <= self.extreme(0, x0, x1, true) + k,
            ],
            [
                x1 + k >= self.extreme(3, y0, y1, false),
                y1 + k >= self.extreme(1, x0, x1, false),
            ],
        )
    }

    /// Point `q` at least `m` px inside.
    fn holds(&self, q: [f64; 2], m: f64) -> bool {
        q[0] >= self.at(2, q[1]) + m
            && q[0] < self.at(3, q[1]) - m
            && q[1] >= self.at(0, q[0]) + m
            && q[1] < self.at(1, q[0]) - m
    }
}

/// Stereo edge: (cost, left features, right features). A target's first
/// transition, seen where it was (not lost), also tries the motion
/// projection reversed, `x − v_init`, at `k.reverse` more; the cheaper
/// counts (core: `TrackConfig::newborn_reverse_cost`).
fn edge(p: &State, c: &Cand, k: &Costs) -> (f64, Feat, Option<Feat>) {
    if p.vel_known {
        return edge_along(p, c, k, p.vel);
    }
    let fwd = edge_along(p, c, k, k.v_init);
    if p.lost != 0 || !k.reverse.is_finite() {
        return fwd;
    }
    let back = edge_along(p, c, k, [-k.v_init[0], -k.v_init[1]]);
    if back.0 + k.reverse < fwd.0 {
        (back.0 + k.reverse, back.1, back.2)
    } else {
        fwd
    }
}

/// [`edge`] with the motion projection `x + v`.
fn edge_along(p: &State, c: &Cand, k: &Costs, v: [f64; 2]) -> (f64, Feat, Option<Feat>) {
    let first = !p.vel_known;
    let d = (p.depth, c.depth);
    // Direction reference: the target's own velocity; in its first frame
    // the sign-free body axis of the node's view, else of the candidate's,
    // measured from where the fish was seen (a lost newborn's node sits
    // `lost` steps of v_init beyond it); else none.
    let dir = |pv: &View, cv: &View| match (p.vel_known, pv.axis.or(cv.axis)) {
        (true, _) => (p.vel, false, [0.0, 0.0]),
        (false, Some(u)) => {
            let n = p.lost as f64;
            (u, true, [n * k.v_init[0], n * k.v_init[1]])
        }
        (false, None) => ([0.0, 0.0], false, [0.0, 0.0]),
    };
    let fl = feat(&p.left, v, &c.left, d, dir(&p.left, &c.left), k);
    let cl = cam_cost(&fl, k, first);
    match (&p.right, &c.right) {
        (Some(pr), Some(cr)) => {
            let fr = feat(pr, v, cr, d, dir(pr, cr), k);
            let cr_ = cam_cost(&fr, k, first);
            (cl + cr_, fl, Some(fr))
        }
        _ => (2.0 * cl, fl, None),
    }
}

/// Runs the reference tracker over all frames and returns every committed
/// assignment (after the final flush).
pub fn run(
    frames: &[Vec<Observation>],
    p: &Params,
    cfg: &TrackConfig,
    cap: Capacities,
) -> Vec<Assignment> {
    run_traced(frames, p, cfg, cap).assignments
}

/// Relative cost gap below which a target's choice between its two
/// cheapest new nodes is a *near tie*: the core accumulates costs in `f32`
/// and this reference in `f64`, and on a seed-19 scene of `track_sim` the
/// two cheapest nodes of one target differed by 1.4·10⁻⁴ in the core and
/// 4·10⁻⁵ here, in opposite order (a 10⁻⁵ relative drift after many
/// stages). Which of two such nodes wins is not decided by the algorithm,
/// only by rounding.
pub const NEAR_TIE_REL: f64 = 1e-4;

/// [`run`]'s assignments and the first frame with a near tie
/// ([`NEAR_TIE_REL`]) in some target's choice of its minimum-cost node.
#[derive(Debug, Clone, Default)]
pub struct Traced {
    /// What [`run`] returns.
    pub assignments: Vec<Assignment>,
    /// First frame whose stage argmin (eq. 13) was a near tie.
    pub first_near_tie: Option<u32>,
}

impl Traced {
    /// Whether the core's assignments `core` agree with these: identical,
    /// or differing only from `depth` frames before the first near tie on
    /// (a trellis of depth `depth` may still revise that many frames back).
    /// Every decision before a near tie must be the same.
    pub fn agrees_up_to_near_ties(&self, core: &[Assignment], depth: u32) -> bool {
        let rep = compare(core, &self.assignments);
        if rep.identical() {
            return true;
        }
        let Some(tie) = self.first_near_tie else {
            return false;
        };
        let first_diff = first_difference(core, &self.assignments);
        first_diff.is_some_and(|f| f + depth >= tie)
    }
}

/// The smallest frame of an assignment in one list and not the other.
fn first_difference(a: &[Assignment], b: &[Assignment]) -> Option<u32> {
    let x: std::collections::BTreeSet<_> = a.iter().copied().collect();
    let y: std::collections::BTreeSet<_> = b.iter().copied().collect();
    x.symmetric_difference(&y).map(|s| s.frame).min()
}

/// [`run`], also reporting the first near tie (see [`Traced`]).
pub fn run_traced(
    frames: &[Vec<Observation>],
    p: &Params,
    cfg: &TrackConfig,
    cap: Capacities,
) -> Traced {
    let mut first_near_tie: Option<u32> = None;
    let mut out = Vec::new();
    let mut targets: Vec<Target> = Vec::new();
    let mut sig = Sig::default();
    let mut next_id = 1u32;
    let mut recent = Recent {
        slots: vec![None; fishtrack_core::track::RECENT],
        next: 0,
    };
    let d0 = &cfg.sigma_defaults;
    let defaults = [
        d0.v as f64,
        d0.v0 as f64,
        d0.a as f64,
        d0.m as f64,
        d0.h as f64,
        d0.d as f64,
    ];
    let min = cfg.min_sigma_samples as usize;
    let alpha = p.alpha as f64;
    let miss = cfg.miss_cost as f64;
    let gate = cfg.gate_cost as f64;
    let m = p.margin as f64;
    // The raw views' rectangles, clipped to the frame: (x0, y0, x1, y1).
    let rect = |r: &fishtrack_core::Roi| {
        let x0 = r.x.min(cfg.width) as u64;
        let y0 = r.y.min(cfg.height) as u64;
        let x1 = (r.x as u64 + r.w as u64).min(cfg.width as u64);
        let y1 = (r.y as u64 + r.h as u64).min(cfg.height as u64);
        (x0, y0, x1, y1)
    };
    let views = [rect(&cfg.view[0]), rect(&cfg.view[1])];
    // With an outline (curved borders on a canvas): per side, the border's
    // least and greatest coordinate over a span along it.
    let outlines = cfg.outline.map(|o| o.map(Outline::from_core));
    // Which sides of box (x0, y0, x1, y1) lie within k px of the border of
    // view `cam` or beyond it: [x-, y-], [x+, y+].
    let cut_of = |cam: usize, (x0, y0, x1, y1): (u64, u64, u64, u64), k: u64| match &outlines {
        Some(o) => o[cam].cut((x0 as f64, y0 as f64, x1 as f64, y1 as f64), k as f64),
        None => {
            let (vx0, vy0, vx1, vy1) = views[cam];
            (
                [x0 <= vx0 + k, y0 <= vy0 + k],
                [x1 + k >= vx1, y1 + k >= vy1],
            )
        }
    };

    for (fi, obs) in frames.iter().enumerate() {
        let frame = fi as u32;
        // A box within 2 px of its view's edge (or across it) may be cut.
        let view = |v: &fishtrack_core::track::CameraView, cam: usize| {
            let b = &v.bbox;
            // per side: within 2 px of the view's side or across it
            let (lo, hi) = cut_of(
                cam,
                (
                    b.x as u64,
                    b.y as u64,
                    b.x as u64 + b.w as u64,
                    b.y as u64 + b.h as u64,
                ),
                2,
            );
            // which end of the fish is seen: none for a box that is empty
            // or misses the centroid
            let ok = sane_box(v);
            View {
                pos: [v.cx as f64, v.cy as f64],
                area: v.area as f64,
                cut: lo.iter().chain(&hi).any(|&c| c),
                lo: [b.x as f64, b.y as f64],
                hi: [b.right() as f64, b.bottom() as f64],
                cut_lo: lo.map(|c| ok && c),
                cut_hi: hi.map(|c| ok && c),
                cdf: cdf(&v.hist),
                axis: (cfg.axis_direction
                    && !lo.iter().chain(&hi).any(|&c| c)
                    && v.elongation >= fishtrack_core::track::MIN_AXIS_ELONGATION
                    && (v.angle as f64).abs() <= 8.0 * std::f64::consts::PI)
                    .then(|| {
                        // the line's direction in whole degrees (the core keeps
                        // one byte per view), 0 to 179
                        let d = ((v.angle as f64).to_degrees() % 180.0).round();
                        let d = (if d < 0.0 { d + 180.0 } else { d }) % 180.0;
                        let r = d.to_radians();
                        [r.cos(), r.sin()]
                    }),
            }
        };
        let cands: Vec<Cand> = obs
            .iter()
            .enumerate()
            .take(cap.obs)
            .filter(|(_, o)| o.is_valid())
            .map(|(i, o)| Cand {
                obs: i,
                left: view(&o.left, 0),
                right: o.right.as_ref().map(|v| view(v, 1)),
                depth: o.depth().map(|z| z as f64),
                bbox: (
                    o.left.bbox.x,
                    o.left.bbox.y,
                    o.left.bbox.right(),
                    o.left.bbox.bottom(),
                ),
                area: o.left.area as f64,
            })
            .collect();
        let lists = [&sig.v, &sig.v0, &sig.a, &sig.m, &sig.h, &sig.d];
        let mut s = [0.0; 6];
        for i in 0..6 {
            s[i] = match median(lists[i], min) {
                Some(x) => (x / 0.454_936_4f32 as f64).clamp(defaults[i], defaults[i] * 16.0),
                None => defaults[i],
            };
        }
        let v_init = match (median(&sig.vx, min), median(&sig.vy, min)) {
            (Some(x), Some(y)) => [x, y],
            // Before the data give one: v_ref crossing the width in the
            // paper's 4.3 frames of lifespan (Section II).
            _ => {
                let (x, y) = (p.v_ref_x as f64, p.v_ref_y as f64);
                let n = (x * x + y * y).sqrt();
                let s = cfg.crossing_width as f64 / 4.3 / n;
                [x * s, y * s]
            }
        };
        let k = Costs {
            s,
            cues: cfg.cues.0,
            v_init,
            z_ref: cfg.z_ref_mm as f64,
            cap: cfg.cue_cap as f64,
            area_c: cfg.area_robust as f64,
            hist_c: cfg.hist_robust as f64,
            depth_c: cfg.depth_robust as f64,
            cut_aware: cfg.cut_aware_motion,
            // NN keeps the one prediction x + v
            reverse: if p.tracker == Assoc::Nn {
                f64::INFINITY
            } else {
                cfg.newborn_reverse_cost as f64
            },
        };
        let mut taken = vec![false; obs.len()];

        // Greedy assignment for MC / NN, on each target's single front node.
        let mut greedy: Vec<Option<usize>> = vec![None; targets.len()];
        if p.tracker != Assoc::Viterbi {
            let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
            for (ti, t) in targets.iter().enumerate() {
                let st = &t.front[0];
                for (ci, c) in cands.iter().enumerate() {
                    let (cost, fl, _) = edge(st, c, &k);
                    let key = if p.tracker == Assoc::Nn {
                        let s2 = if st.vel_known { k.s[0] } else { k.s[1] };
                        (fl.d2 / s2 < cfg.nn_gate as f64).then_some(fl.d2)
                    } else {
                        (cost < gate && cost < miss).then_some(cost)
                    };
                    if let Some(key) = key {
                        pairs.push((key, ti, ci));
                    }
                }
            }
            pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
            let mut used = vec![false; cands.len()];
            for (_, ti, ci) in pairs {
                if greedy[ti].is_none() && !used[ci] {
                    greedy[ti] = Some(ci);
                    used[ci] = true;
                }
            }
        }

        for t in targets.iter_mut() {
            if t.stages.len() >= cap.depth {
                // a tentative target reports nothing until it is confirmed
                if t.tentative && confirmed(t, cfg) {
                    t.tentative = false;
                }
                if t.tentative {
                    let (hits, steps) = (t.hits, t.path.len());
                    commit_oldest(t, &mut Vec::new());
                    t.hits = hits;
                    t.path.truncate(steps);
                } else {
                    commit_oldest(t, &mut out);
                }
            }
        }
        // Viterbi selection: a joint one-to-one assignment (greedy, smallest
        // first) of observations to targets on the increment of the
        // target's best accumulated cost, C_i + c_ij − min C, below the
        // miss cost; taking another target's observation costs share_cost.
        let mut owner: Vec<Option<usize>> = vec![None; cands.len()];
        if p.tracker == Assoc::Viterbi {
            let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
            for (ti, t) in targets.iter().enumerate() {
                let base = t.front.iter().map(|s| s.cost).fold(f64::INFINITY, f64::min);
                for (ci, c) in cands.iter().enumerate() {
                    let mut inc = f64::INFINITY;
                    for st in &t.front {
                        let (e, _, _) = edge(st, c, &k);
                        if e < gate {
                            inc = inc.min(st.cost + e - base);
                        }
                    }
                    if inc < miss {
                        pairs.push((inc, ti, ci));
                    }
                }
            }
            pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
            let mut done = vec![false; targets.len()];
            let mut sel: Vec<Option<usize>> = vec![None; targets.len()];
            let mut key = std::collections::HashMap::new();
            for &(inc, ti, ci) in &pairs {
                key.insert((ti, ci), inc);
            }
            for (_, ti, ci) in pairs {
                if !done[ti] && owner[ci].is_none() {
                    done[ti] = true;
                    owner[ci] = Some(ti);
                    sel[ti] = Some(ci);
                }
            }
            // Pair exchanges on the total increment (unassigned = miss).
            let kf = |ti: usize, c: Option<usize>| match c {
                Some(c) => key.get(&(ti, c)).copied().unwrap_or(f64::INFINITY),
                None => miss,
            };
            for _ in 0..cfg.swap_passes {
                let mut changed = false;
                for i in 0..sel.len() {
                    for j in (i + 1)..sel.len() {
                        let (a, b) = (sel[i], sel[j]);
                        if a.is_none() && b.is_none() {
                            continue;
                        }
                        let now = kf(i, a) + kf(j, b);
                        let sw = kf(i, b) + kf(j, a);
                        if sw.is_finite()
                            && sw + (fishtrack_core::track::SWAP_MIN_GAIN as f64) < now
                        {
                            sel[i] = b;
                            sel[j] = a;
                            changed = true;
                        }
                    }
                }
                if !changed {
                    break;
                }
            }
            owner = vec![None; cands.len()];
            for (ti, c) in sel.iter().enumerate() {
                if let Some(c) = c {
                    owner[*c] = Some(ti);
                }
            }
        }

        for ti in 0..targets.len() {
            let t = &mut targets[ti];
            // New stage: (state, node).
            let mut new: Vec<(State, Node)> = Vec::new();
            let mk_real = |pst: &State, pi: usize, acc: f64, c: &Cand| -> (State, Node) {
                let d = displacement(&pst.left, &c.left, k.cut_aware);
                let vel = if pst.vel_known {
                    [
                        alpha * d[0] + (1.0 - alpha) * pst.vel[0],
                        alpha * d[1] + (1.0 - alpha) * pst.vel[1],
                    ]
                } else {
                    d
                };
                (
                    State {
                        cost: acc,
                        left: c.left.clone(),
                        right: c.right.clone(),
                        vel,
                        vel_known: true,
                        depth: c.depth.or(pst.depth),
                        lost: 0,
                    },
                    Node {
                        obs: Some(c.obs),
                        pred: pi,
                        pos: c.left.pos,
                    },
                )
            };
            let mk_pred = |pst: &State, pi: usize| -> (State, Node) {
                let v = if pst.vel_known { pst.vel } else { v_init };
                let mut s = pst.clone();
                s.cost = pst.cost + miss;
                s.left = moved(&pst.left, v);
                if let Some(r) = s.right.as_mut() {
                    *r = moved(r, v);
                }
                s.lost = pst.lost + 1;
                let pos = s.left.pos;
                (
                    s,
                    Node {
                        obs: None,
                        pred: pi,
                        pos,
                    },
                )
            };
            if p.tracker == Assoc::Viterbi {
                let mut real: Vec<(f64, usize, usize)> = Vec::new(); // (C, cand, pred)
                for (ci, c) in cands.iter().enumerate() {
                    // Observation selected for another target: share cost.
                    let share = match owner[ci] {
                        Some(o) if o != ti => cfg.share_cost as f64,
                        _ => 0.0,
                    };
                    let mut best: Option<(f64, usize)> = None;
                    for (i, st) in t.front.iter().enumerate() {
                        let (e, _, _) = edge(st, c, &k);
                        if e < gate && best.is_none_or(|b| st.cost + e + share < b.0) {
                            best = Some((st.cost + e + share, i));
                        }
                    }
                    if let Some((acc, i)) = best {
                        real.push((acc, ci, i));
                    }
                }
                real.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                real.truncate(cap.nodes - 1);
                for (acc, ci, pi) in real {
                    new.push(mk_real(&t.front[pi], pi, acc, &cands[ci]));
                }
                let lp = t
                    .front
                    .iter()
                    .enumerate()
                    .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost).then(a.0.cmp(&b.0)));
                if let Some((i, st)) = lp {
                    new.push(mk_pred(st, i));
                }
            } else {
                let st = &t.front[0];
                match greedy[ti] {
                    Some(ci) => {
                        let (e, _, _) = edge(st, &cands[ci], &k);
                        new.push(mk_real(st, 0, st.cost + e, &cands[ci]));
                    }
                    None if st.lost < cfg.max_lost as u32 => new.push(mk_pred(st, 0)),
                    None => {}
                }
            }
            if new.is_empty() {
                t.pending = true;
                continue;
            }
            let bi =
                (0..new.len()).fold(0, |b, i| if new[i].0.cost < new[b].0.cost { i } else { b });
            let c1 = new[bi].0.cost;
            let near_tie = new
                .iter()
                .enumerate()
                .any(|(i, n)| i != bi && n.0.cost - c1 <= NEAR_TIE_REL * c1.abs().max(1.0));
            if near_tie && first_near_tie.is_none() {
                first_near_tie = Some(frame);
            }
            if let Some(o) = new[bi].1.obs {
                taken[o] = true;
                let c = cands.iter().find(|c| c.obs == o).unwrap();
                let pst = &t.front[new[bi].1.pred];
                let (_, fl, fr) = edge(pst, c, &k);
                let first = !pst.vel_known;
                for f in std::iter::once(fl).chain(fr) {
                    push(if first { &mut sig.v0 } else { &mut sig.v }, f.d2);
                    push(&mut sig.a, f.a2);
                    push(&mut sig.m, f.m2);
                    push(&mut sig.h, f.h2);
                    push(&mut sig.d, f.z2);
                }
                let dv = displacement(&pst.left, &c.left, k.cut_aware);
                push(&mut sig.vx, dv[0]);
                push(&mut sig.vy, dv[1]);
            }
            let best = new[bi].0.clone();
            let new_best_lost = new[bi].1.obs.is_none();
            t.stages.push((frame, new.iter().map(|x| x.1).collect()));
            t.front = new.into_iter().map(|x| x.0).collect();
            if best.vel_known && new_best_lost {
                let q = best.left.pos;
                let inside = match &outlines {
                    Some(o) => o[0].holds(q, m),
                    None => {
                        let (vx0, vy0, vx1, vy1) = views[0];
                        let (vx0, vy0, vx1, vy1) = (vx0 as f64, vy0 as f64, vx1 as f64, vy1 as f64);
                        q[0] >= vx0 + m && q[0] < vx1 - m && q[1] >= vy0 + m && q[1] < vy1 - m
                    }
                };
                if !inside {
                    t.pending = true;
                    t.exit = true;
                }
            }
            if new_best_lost && best.lost > cfg.max_lost as u32 {
                t.pending = true;
            }
        }
        // Duplicate trellises: same observations in the last two frames of
        // their best paths, or the same newest observation when one of them
        // is a newborn on its first transition. Drop the one with less
        // evidence, then higher best cost, then the younger.
        if p.tracker == Assoc::Viterbi {
            for i in 0..targets.len() {
                for j in (i + 1)..targets.len() {
                    if targets[i].closed
                        || targets[j].closed
                        || targets[i].pending
                        || targets[j].pending
                    {
                        continue;
                    }
                    let (ki, kj) = (last_two(&targets[i]), last_two(&targets[j]));
                    let li = last_obs(&targets[i]);
                    let newborn = |t: &Target| t.hits == 0 && t.stages.len() == 2;
                    let same_newborn = li.is_some()
                        && li == last_obs(&targets[j])
                        && (newborn(&targets[i]) || newborn(&targets[j]));
                    let same_two = ki.is_some() && ki == kj;
                    if !same_two && !same_newborn {
                        continue;
                    }
                    let (ei, ej) = (evidence(&targets[i]), evidence(&targets[j]));
                    let d = if ej > ei
                        || (ej == ei && best_cost(&targets[j]) < best_cost(&targets[i]))
                    {
                        i
                    } else {
                        j
                    };
                    targets[d].closed = true; // nothing more committed
                    targets[d].dup = true;
                }
            }
        }
        let fold = p.tracker == Assoc::Viterbi && cfg.fold_shared;
        resolve_closes(&mut targets, fold, cfg, &mut recent, &mut out);

        // Births.
        let big = cfg.birth_area_factor as f64 * p.area_min as f64;
        let mu = p.margin;
        // Near the prediction of a target lost this frame: its partly
        // hidden view, not a new fish; near that of a target exiting now
        // (not folded as a duplicate), a view the border cuts is its
        // cut view.
        let near_lost: Vec<bool> = cands
            .iter()
            .map(|c| {
                let live_or_exit = |t: &&Target| !t.closed || (t.exit && !t.dup && c.left.cut);
                targets.iter().filter(live_or_exit).any(|t| {
                    let b = (0..t.front.len()).fold(0, |b, i| {
                        if t.front[i].cost < t.front[b].cost {
                            i
                        } else {
                            b
                        }
                    });
                    t.front.get(b).is_some_and(|s| {
                        let [dx, dy] = displacement(&s.left, &c.left, k.cut_aware);
                        let gate = if s.vel_known {
                            cfg.lost_gate
                        } else {
                            cfg.newborn_lost_gate
                        };
                        s.lost > 0 && (dx * dx + dy * dy) / k.s[0] < gate as f64
                    })
                })
            })
            .collect();
        targets.retain(|t| !t.closed);
        for (c, &near_lost) in cands.iter().zip(&near_lost) {
            if taken[c.obs] || near_lost {
                continue;
            }
            let (x0, y0, x1, y1) = c.bbox;
            let (mu, x0, y0, x1, y1) = (mu as u64, x0 as u64, y0 as u64, x1 as u64, y1 as u64);
            // within mu − 1 px of the border (integer boxes: closer than mu)
            let near = mu > 0 && {
                let (lo, hi) = cut_of(0, (x0, y0, x1, y1), mu - 1);
                lo.iter().chain(&hi).any(|&c| c)
            };
            // In the first frame every fish is already inside the view.
            // Elsewhere a small one is a false alarm (the paper), or a
            // tentative target (`confirm_births`).
            let tentative = fi > 0 && !near && c.area < big;
            if tentative && cfg.confirm_births == 0 {
                continue;
            }
            if targets.len() >= cap.targets {
                continue;
            }
            targets.push(Target {
                id: next_id,
                hits: 0,
                stages: vec![(
                    frame,
                    vec![Node {
                        obs: Some(c.obs),
                        pred: 0,
                        pos: c.left.pos,
                    }],
                )],
                front: vec![State {
                    cost: 0.0,
                    left: c.left.clone(),
                    right: c.right.clone(),
                    vel: [0.0, 0.0],
                    vel_known: false,
                    depth: c.depth,
                    lost: 0,
                }],
                closed: false,
                dup: false,
                pending: false,
                exit: false,
                path: Vec::new(),
                tentative,
                born: (frame, c.left.pos),
            });
            next_id += 1;
        }
    }
    for t in targets.iter_mut() {
        t.pending = true;
    }
    let fold = p.tracker == Assoc::Viterbi && cfg.fold_shared;
    resolve_closes(&mut targets, fold, cfg, &mut recent, &mut out);
    Traced {
        assignments: out,
        first_near_tie,
    }
}

/// Carries out the closes decided this frame in birth order; with `fold`,
/// a track that committed nothing and whose every observation lies on
/// another live or recently closed track with at least as many
/// observations is a duplicate and outputs nothing.
fn resolve_closes(
    targets: &mut [Target],
    fold: bool,
    cfg: &TrackConfig,
    recent: &mut Recent,
    out: &mut Vec<Assignment>,
) {
    for i in 0..targets.len() {
        if !targets[i].pending {
            continue;
        }
        targets[i].pending = false;
        if fold && is_shared(targets, i, recent) {
            targets[i].closed = true;
            targets[i].dup = true;
            continue;
        }
        // a tentative target too short to confirm: nothing output
        if targets[i].tentative && !confirmed(&targets[i], cfg) {
            targets[i].closed = true;
            targets[i].dup = true;
            continue;
        }
        close(&mut targets[i], out);
        if !fold {
            continue;
        }
        // the closed track's uncommitted best path, as the core's ring
        let t = &targets[i];
        for (f, o) in real_steps(t) {
            let n = recent.slots.len();
            recent.slots[recent.next] = Some((t.id, f, o, t.hits));
            recent.next = (recent.next + 1) % n;
        }
    }
}

/// Real (frame, observation) steps of the best uncommitted path.
fn real_steps(t: &Target) -> Vec<(u32, usize)> {
    let path = best_path(t);
    (0..t.stages.len())
        .filter_map(|s| t.stages[s].1[path[s]].obs.map(|o| (t.stages[s].0, o)))
        .collect()
}

fn is_shared(targets: &[Target], i: usize, recent: &Recent) -> bool {
    let t = &targets[i];
    if !t.path.is_empty() {
        return false;
    }
    let mine = real_steps(t);
    let n = mine.len() as u32;
    if n == 0 {
        return false;
    }
    for (j, o) in targets.iter().enumerate() {
        if j == i || o.dup {
            continue;
        }
        let ev = if o.closed { o.hits } else { evidence(o) };
        if ev < n {
            continue;
        }
        let steps = real_steps(o);
        if mine
            .iter()
            .all(|&(f, ob)| o.path.contains(&(f, Some(ob))) || steps.contains(&(f, ob)))
        {
            return true;
        }
    }
    let (f0, o0) = mine[0];
    recent.slots.iter().flatten().any(|&(id, f, o, ev)| {
        ev >= n
            && f == f0
            && o == o0
            && mine.iter().all(|&(mf, mo)| {
                recent
                    .slots
                    .iter()
                    .flatten()
                    .any(|&(qi, qf, qo, _)| qi == id && qf == mf && qo == mo)
            })
    })
}

/// Path (node index per stage) ending at the cheapest front node.
fn best_path(t: &Target) -> Vec<usize> {
    let mut b = 0;
    for (i, s) in t.front.iter().enumerate() {
        if s.cost < t.front[b].cost {
            b = i;
        }
    }
    let mut path = vec![0; t.stages.len()];
    let mut cur = b;
    for s in (0..t.stages.len()).rev() {
        path[s] = cur;
        cur = t.stages[s].1[cur].pred;
    }
    path
}

fn last_obs(t: &Target) -> Option<usize> {
    let n = t.stages.len();
    if n == 0 {
        return None;
    }
    let path = best_path(t);
    t.stages[n - 1].1[path[n - 1]].obs
}

fn best_cost(t: &Target) -> f64 {
    t.front.iter().map(|s| s.cost).fold(f64::INFINITY, f64::min)
}

fn last_two(t: &Target) -> Option<(usize, usize)> {
    let n = t.stages.len();
    if n < 2 {
        return None;
    }
    let path = best_path(t);
    match (
        t.stages[n - 1].1[path[n - 1]].obs,
        t.stages[n - 2].1[path[n - 2]].obs,
    ) {
        (Some(a), Some(b)) => Some((a, b)),
        _ => None,
    }
}

/// A tentative target has `confirm_births` observations on its path and
/// moved at least `confirm_min_step` px per frame from its birth to its
/// last observation (positions in whole pixels, as the core's nodes).
fn confirmed(t: &Target, cfg: &TrackConfig) -> bool {
    let (need, min_step) = (cfg.confirm_births as u32, cfg.confirm_min_step as f64);
    if evidence(t) < need {
        return false;
    }
    let path = best_path(t);
    let Some((frame, pos)) = (0..t.stages.len()).rev().find_map(|s| {
        let n = &t.stages[s].1[path[s]];
        n.obs.map(|_| (t.stages[s].0, n.pos))
    }) else {
        return false;
    };
    let frames = frame.saturating_sub(t.born.0);
    let (dx, dy) = (
        pos[0].round() - t.born.1[0].round(),
        pos[1].round() - t.born.1[1].round(),
    );
    frames > 0 && dx * dx + dy * dy >= (min_step * frames as f64).powi(2)
}

fn evidence(t: &Target) -> u32 {
    let path = best_path(t);
    t.hits
        + (0..t.stages.len())
            .filter(|&s| t.stages[s].1[path[s]].obs.is_some())
            .count() as u32
}

fn commit_oldest(t: &mut Target, out: &mut Vec<Assignment>) {
    let path = best_path(t);
    let chosen = path[0];
    let (frame, nodes) = t.stages.remove(0);
    t.hits += nodes[chosen].obs.is_some() as u32;
    t.path.push((frame, nodes[chosen].obs));
    out.push(Assignment {
        frame,
        track: t.id,
        obs: nodes[chosen].obs.map(|o| o as u16),
    });
    // Keep only paths through the committed node.
    let mut keep: Vec<Option<usize>> = (0..nodes.len())
        .map(|i| (i == chosen).then_some(0))
        .collect();
    for (si, (_, stage)) in t.stages.iter_mut().enumerate() {
        let mut next_keep = vec![None; stage.len()];
        let mut kept = Vec::new();
        for (i, n) in stage.iter().enumerate() {
            if let Some(np) = keep[n.pred] {
                next_keep[i] = Some(kept.len());
                kept.push(Node {
                    obs: n.obs,
                    pred: if si == 0 { 0 } else { np },
                    pos: n.pos,
                });
            }
        }
        *stage = kept;
        keep = next_keep;
    }
    t.front = t
        .front
        .iter()
        .enumerate()
        .filter(|(i, _)| keep[*i].is_some())
        .map(|(_, s)| s.clone())
        .collect();
}

fn close(t: &mut Target, out: &mut Vec<Assignment>) {
    if t.closed {
        return;
    }
    t.closed = true;
    let path = best_path(t);
    let last_real = (0..t.stages.len())
        .rev()
        .find(|&s| t.stages[s].1[path[s]].obs.is_some());
    if let Some(lr) = last_real {
        for s in 0..=lr {
            let o = t.stages[s].1[path[s]].obs;
            t.hits += o.is_some() as u32;
            t.path.push((t.stages[s].0, o));
            out.push(Assignment {
                frame: t.stages[s].0,
                track: t.id,
                obs: t.stages[s].1[path[s]].obs.map(|o| o as u16),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn a(frame: u32, track: u32, obs: Option<u16>) -> Assignment {
        Assignment { frame, track, obs }
    }

    #[test]
    fn agreement_up_to_near_ties_allows_only_divergence_after_a_tie() {
        let base = vec![a(1, 1, Some(0)), a(30, 1, Some(1)), a(40, 2, Some(0))];
        let traced = |tie| Traced {
            assignments: base.clone(),
            first_near_tie: tie,
        };
        // identical: always
        assert!(traced(None).agrees_up_to_near_ties(&base, 16));
        let mut late = base.clone();
        late[2] = a(40, 3, Some(0));
        // a difference with no near tie, or before it by more than the depth
        assert!(!traced(None).agrees_up_to_near_ties(&late, 16));
        assert!(!traced(Some(57)).agrees_up_to_near_ties(&late, 16));
        // within the depth before the tie, or after it
        assert!(traced(Some(56)).agrees_up_to_near_ties(&late, 16));
        assert!(traced(Some(35)).agrees_up_to_near_ties(&late, 16));
        // the earliest difference counts
        let mut early = late.clone();
        early[0] = a(1, 1, None);
        assert!(!traced(Some(35)).agrees_up_to_near_ties(&early, 16));
    }
}
