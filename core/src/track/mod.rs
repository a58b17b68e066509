//! Low-frame-rate multi-fish tracking: feature-based temporal matching
//! (Section IV.B, eq. 7–9) and multi-target Viterbi data association
//! (Section IV.C, eq. 10–14, Algorithm 1, Fig. 8), with the greedy MC and NN
//! baselines of Table V and the cue ablation of Fig. 15.
//!
//! # Per frame ([`Tracker::step`], Algorithm 1)
//! For every live target k (in birth order):
//! 1. If its trellis holds `D` stages, commit the oldest (see [`viterbi`]).
//! 2. Build the new stage. **Viterbi:** every observation j whose edge cost
//!    from some front node i is below `gate_cost` becomes a node with
//!    π_j = argmin_i C_i + c_ij and C_j = C_π + c_πj (eq. 11–12); the `K−1`
//!    cheapest are kept (the rest counted in `nodes_dropped`), plus one
//!    *predicted* node (the target is lost this frame: position = prediction,
//!    velocity kept) from the cheapest front node, at cost C + `miss_cost`. Several trellises may
//!    take the same observation (shared nodes = occlusion, Section VI.C);
//!    **our addition:** before the stages are built, a joint *selection*
//!    assigns observations to targets one-to-one, greedily, smallest first,
//!    on each target's increment C_i + c_ij − min_i C_i (below `miss_cost`),
//!    and a node whose observation the selection gave to another target
//!    costs `share_cost` extra. A target thus takes a fish another target
//!    holds only when that explains the data clearly better than its
//!    alternatives (an occlusion), not merely because the two are close.
//!    At 5 fps free sharing let two targets collapse onto one fish while
//!    the other fish started a new track; the former oldest-first order
//!    let an older target take a younger one's fish whenever both were
//!    plausible (perfect detections, 8 hauls: success 0.675 → 0.709).
//!    The greedy assignment is then refined by pair exchanges on the total
//!    increment ([`greedy::improve_pairs`], `swap_passes`): greedy can hand
//!    two school mates entering side by side each other's fish when one
//!    crossed pair happens to be close, while the joint optimum of both
//!    first steps is the true one (8 hauls: 0.825 → 0.842 at 5 fps).
//!    **MC / NN:** one node per stage, from a greedy one-to-one assignment
//!    ([`greedy`]) on the matching cost (MC, accepted below `miss_cost`) or on
//!    the distance to the prediction (NN, accepted when
//!    ‖x − x̂‖²/σ_v² < `nn_gate`); unassigned targets get the predicted node.
//! 3. The minimum-cost node of the stage gives the target's position and
//!    velocity: x_t = x_j*, v_t = α(x_j* − x_π) + (1−α)v_π (eq. 13–14; a
//!    target's first transition sets v to the displacement, as it has no
//!    velocity yet; x_j* − x_π is the displacement of [`cost::motion_delta`],
//!    measured on the uncut box sides of a view the border cuts); its
//!    observation joins the selection set S.
//! 4. The target **exits** when it is lost this frame (its minimum-cost node
//!    is the predicted one) and that predicted position lies within `margin`
//!    M of the frame border or outside it (only once its velocity is known):
//!    "a track is restricted to end only when its predicted position is
//!    close to the frame border" — a fish still seen near the border keeps
//!    its track;
//!    it **dies** when its minimum-cost node is a predicted one with more
//!    than `max_lost` consecutive lost frames (Viterbi; so a long-lost
//!    target never grabs whatever is left as a last chance), or when it has
//!    no candidate after `max_lost` lost frames (MC/NN). Either way its trellis is
//!    backtracked from the minimum-cost front node, the uncommitted stages up
//!    to the last real observation are committed, and a
//!    [`TrackEvent::Closed`] carries the whole path.
//!
//! **Duplicates (Viterbi only; our addition):** independent trellises that
//! reach the same observation carry identical states from then on, so two
//! targets whose best paths take the same real observations in the last two
//! frames are one fish counted twice, and so are two targets whose best
//! nodes take the same observation when one of them is a newborn making its
//! first transition (a debris- or fragment-born target latching onto a
//! fish). The one with fewer observations on its path (then the higher
//! best cost C, then the younger) is dropped without committing its
//! uncommitted stages ([`CloseReason::Duplicate`]). A one-frame crossing of
//! two established targets (shared node, Section VI.C) is unaffected.
//!
//! **Folding (Viterbi only; our addition, [`TrackConfig::fold_shared`]):**
//! the check above sees only the newest nodes, but a best path can move
//! onto another target's nodes when it is backtracked later (a newborn that
//! took an observation the other target's best path only claimed a frame
//! afterwards). So closes are carried out after every target has stepped,
//! in birth order, and a closing track that has committed nothing and whose
//! every observation lies on the path (committed or best uncommitted) of
//! another live target, or of a recently closed track (a ring of the last
//! [`RECENT`] observations on closed tracks' uncommitted best paths: a
//! track that may fold has committed nothing, so its observations all lie
//! within the last D frames, the span of those paths), with at least as many
//! observations, is the same fish counted twice: it closes as
//! [`CloseReason::Duplicate`] and reports no frame (end to end, seed 6:
//! two one-frame tracks folded, count error +18.2 → +12.1 %).
//!
//! Then every valid observation not in S is a **new target** if it is
//! plausibly a fish entering (Section IV.C.2, "new targets tend to appear
//! close to the video frame border … false alarms … areas are usually
//! small"): its left box lies within M of a border, *or* its left area is at
//! least `birth_area_factor` · θ_A^L. Other unassociated observations are
//! false alarms by the paper's rule; with [`TrackConfig::confirm_births`]
//! (our addition, default 3) they are born *tentative*, and such a target
//! is reported only if it closes with that many observations on its path
//! ([`CloseReason::Unconfirmed`] otherwise): a fish whose entry the
//! segmentation missed is first seen small and mid-view. In the first frame of a haul (the first
//! [`Tracker::step`] after [`Tracker::new`] or [`Tracker::finish`]) every
//! unassociated observation is a new target: the fish already in view did
//! not enter through a border (our addition). An observation within the
//! vicinity gate (`lost_gate`) of a target lost this frame is not a new
//! target either: it is that target's partly hidden or cut view (our
//! addition; it had been born as a one-frame duplicate of the fish). For a
//! target lost on its first transition (no velocity yet) the gate is the
//! narrower `newborn_lost_gate`: its prediction is only `v_init`'s guess,
//! and a view it refused there is as often another fish (session 22). The
//! same holds for an observation cut by the frame border near the
//! prediction of a target that exits this frame: the fish's head has left
//! and its tail end, of other grey levels and too short to match, is still
//! in view (our addition; an uncut observation there is a fish entering and
//! is born; end to end, seeds 9–12: count error +12.3 → +4.4 %). The
//! birth and death rules are the same for all three association methods.
//!
//! A newborn target has no velocity: its first transition is projected with
//! the median displacement of accepted edges ([`sigma`]), and before there
//! are enough of those with v_ref (Table I) scaled to cross the frame width
//! in the paper's 4.3-frame lifespan ([`default_v_init`]). That is the
//! school's typical step, not this fish's: the first transition is also
//! tried projected the other way, `x − v_init`, at
//! [`TrackConfig::newborn_reverse_cost`] more, and the cheaper edge counts
//! (our addition: at 2.5 fps a fish swimming against the school was
//! otherwise never linked on its first transition and was born again).
//!
//! # Events
//! [`TrackEvent::Frame`] for every committed frame of a track (emitted up to
//! `D` frames late: online on a device) and [`TrackEvent::Closed`] with the
//! full path. A host collects everything by calling [`Tracker::finish`]
//! after the last frame.
//!
//! # Memory
//! `Tracker<T, D, K, H, N>`: T live targets, D stages of K nodes per trellis,
//! H path steps per track, N observations per frame; all inline, no heap.
//! [`DefaultTracker`] is 32 targets × 16 stages × 8 nodes, 32-step paths,
//! 64 observations per frame. Overflow of any capacity is counted in
//! [`TrackStats`], never fatal.

pub mod cost;
pub mod greedy;
pub mod observation;
pub mod outline;
pub mod sigma;
pub mod viterbi;

use core::fmt;

pub use cost::{Cues, Robust, Sigmas};
pub use observation::{CameraView, Observation};
pub use outline::ViewOutline;

use crate::error::ParamError;
use crate::image::Roi;
use crate::params::{Params, Tracker as Association};
use cost::{camera_cost, cdf, edge_features, motion_delta, DirectionRef, EdgeFeatures, ViewFeat};
use sigma::SigmaEstimator;
use viterbi::{round_i16, Node, NodeState, Trellis, PREDICTED};

/// The default tracker: 32 targets, trellis depth 16, 8 nodes per stage,
/// 32-step paths, 64 observations per frame.
pub type DefaultTracker = Tracker<32, 16, 8, 32, 64>;

/// Tracking options that are not Table I parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TrackConfig {
    /// Frame width, pixels (rectified).
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// The left and right rectified frames' rectangles that hold the raw
    /// views (OpenCV's `validPixROI1/2`; the whole frame by default). Their
    /// edges are the tracker's frame border — for the exit and birth margin
    /// M and for the border cut of the area cue: with a free scaling
    /// `alpha > 0` the raw view ends inside the rectified frame, and a fish
    /// cut there shows only part of its area although its box is far from
    /// the rectified frame's edge. Clipped to the frame.
    pub view: [Roi; 2],
    /// The left and right raw views' borders when they are not the
    /// rectangles `view` (a rectification onto a canvas that keeps every
    /// raw pixel, [`outline`]): then they, not `view`, decide the border
    /// cuts, births near the border and exits. Default `None`.
    pub outline: Option<[ViewOutline; 2]>,
    /// Cues of the matching cost (Fig. 15 ablation). Default: all.
    pub cues: Cues,
    /// Cost of a lost frame (the predicted node's edge). Default 24.
    pub miss_cost: f32,
    /// Extra cost of a Viterbi node whose observation the frame's joint
    /// selection gave to another target. Default 24
    /// (= `miss_cost`; measured on synthetic hauls: 12 → 24 raised success
    /// 0.465 → 0.478 at 5 fps, 48 gave no more).
    pub share_cost: f32,
    /// Edges costing this much or more are not considered. Default 48.
    pub gate_cost: f32,
    /// NN gate on ‖x − x̂‖²/σ_v². Default 6 (2.45 σ_v ≈ 610 px at 2048 with
    /// σ_v = 250 px: the radius the former 4 σ gate had with σ_v = 150 px).
    pub nn_gate: f32,
    /// An unassociated observation within ‖x − x̂‖²/σ_v² < `lost_gate` of a
    /// live target that is lost this frame (its minimum-cost node is the
    /// predicted one) is not a new target: it is that target's partly
    /// hidden view (Section IV.C.2, lost frames carried by prediction).
    /// Default 3 (session 22, with `newborn_lost_gate` 0.6; 6 → 3 / 2: end
    /// to end seeds 1–30 success 561 → 563 / 563 of 899, det recall after
    /// tracking 0.714 → 0.723 / 0.727, count error −3.1 → −1.3 / −0.3 %;
    /// `track_sim` Viterbi 0.755 / 0.694 → 0.758 / 0.701 and 0.758 /
    /// 0.704; perfect detections, seeds 1–12, 289 / 218 → 291 / 218 of
    /// 348 / 304). Session 2 chose 6 against no gate on perfect detections
    /// (8 hauls: 0.816 → 0.825 at 5 fps, 0.702 → 0.753 at 2.5 fps).
    pub lost_gate: f32,
    /// `lost_gate` for a target lost on its first transition (a newborn:
    /// no velocity yet, so its prediction is `v_init`'s guess). Default
    /// 0.6 (a tenth of the `lost_gate` of 6 it was measured against, a
    /// fifth of the default 3): a newborn that refuses the view beside
    /// its guess is as likely born on another fish (or a fragment) as on
    /// this one, and blocking that view's birth lost the fish for two
    /// frames (the newborn dies after `max_lost`, the view is blocked in
    /// both). Measured (session 22; 6 → 0.6): end to end seeds 1–30
    /// success 545 → 561 of 899, count error −3.2 → −0.9 % (1–12) and
    /// −6.9 → −4.5 % (13–30); `track_sim` Viterbi 0.756 / 0.657 → 0.755 /
    /// 0.694 at 5 / 2.5 fps; perfect detections (seeds 1–12) 291 / 220 →
    /// 289 / 218 (all with `lost_gate` 6). 0 (no newborn blocks births):
    /// 556, 0.738 / 0.692.
    pub newborn_lost_gate: f32,
    /// Maximum consecutive lost frames on a path; at most D − 2. Default 1:
    /// fish live about four frames at 5 fps, and on synthetic hauls a target
    /// carried longer mostly grabbed another fish (success 0.45 → 0.47 at
    /// 5 fps, 0.38 → 0.44 at 2.5 fps going from 3 to 1).
    pub max_lost: u8,
    /// An unassociated observation away from the border becomes a target when
    /// its left area ≥ this · θ_A^L (`Params::area_min`). Default 2
    /// (perfect detections, 8 hauls: 4 → 2 raised success 0.72 → 0.80; fish
    /// that first become countable mid-view — out of an occlusion, or small
    /// and far — were never born with 4).
    pub birth_area_factor: f32,
    /// Reference depth z_ref of the area normalisation, mm. Default 2000.
    pub z_ref_mm: f32,
    /// Default σ² until enough samples (see [`sigma`]).
    pub sigma_defaults: Sigmas,
    /// Width, pixels, that a fish crosses in the paper's 4.3-frame
    /// lifespan: the scale of a newborn's default velocity
    /// ([`default_v_init`]) until the data give one. Default: the frame
    /// width. The host sets the raw view's width (as for
    /// `sigma_defaults`): a canvas that keeps every raw pixel is 15–25 %
    /// wider than the view the fish cross.
    pub crossing_width: u32,
    /// Samples a cue needs before its σ² is estimated. Default 32.
    pub min_sigma_samples: u16,
    /// Cap on each cue's term z of the matching cost (robust eq. 9, see
    /// [`cost::camera_cost`]). Default ∞ (eq. 9 as published): caps of
    /// 4–9 were measured to lower the success rate on synthetic hauls.
    pub cue_cap: f32,
    /// Sweeps of pair exchanges that refine the Viterbi selection's greedy
    /// assignment ([`greedy::improve_pairs`]); 0 = greedy alone. Default 4.
    pub swap_passes: u8,
    /// Scale c of the soft bound ρ(z) = c·ln(1 + z/c) on the area term z_a
    /// ([`cost::soft_bound`]). Default ∞ (eq. 9 as published): measured
    /// with 9, perfect detections gained 2–4 fish of 293 at 5 and 2.5 fps
    /// and the `track_sim` simulation 0.757 → 0.779 at 5 fps, 0.657 →
    /// 0.655 at 2.5 fps — see README, tracking.
    pub area_robust: f32,
    /// Scale c of the soft bound on the histogram term z_h. Default ∞.
    pub hist_robust: f32,
    /// Scale c of the soft bound on the stereo depth term z_d (our cue).
    /// σ_d is a few per cent, so one frame whose depth is wrong — a box cut
    /// by the frame border or merged in one view, a mispaired right object
    /// (on synthetic hauls about 5 % of tracked observations are more than
    /// 20 % off) — gives z_d in the hundreds and vetoes a link that every
    /// other cue supports; the track then splits. With c the term grows
    /// only as c·ln(1 + z/c) beyond c. Default DEPTH_ROBUST.
    pub depth_robust: f32,
    /// Displacements between views the frame border cuts are measured on
    /// the box sides it does not cut ([`cost::motion_delta`]; our
    /// addition): vicinity, direction, velocity (eq. 13–14), the σ and
    /// `v_init` samples and the birth rule's `lost_gate` test. False:
    /// centroids throughout, as the paper. An observation's box must then
    /// be its view's upright box (one that is empty or misses the centroid
    /// counts as uncut).
    pub cut_aware_motion: bool,
    /// Fold shared tracks (Viterbi; our addition, see the module docs
    /// "Folding"): a track closing with nothing committed yet whose every
    /// observation lies on another, at least as long track's path is that
    /// fish counted twice and closes as [`CloseReason::Duplicate`].
    pub fold_shared: bool,
    /// A target's first transition takes its direction cue from the fish's
    /// body axis (our addition; see [`cost`], "direction reference"): a
    /// newborn has no velocity, so eq. (7)'s θ is measured against the
    /// principal axis of its uncut, elongated view ([`MIN_AXIS_ELONGATION`]),
    /// or of the candidate's when its own gives none, sign-free (head or
    /// tail first); a newborn lost on its first transition measures the
    /// displacement from where it was seen, not from its `v_init` guess.
    /// First transitions then add their θ² to σ_m's samples (they added 0
    /// before). Fish are carried through the view
    /// along their bodies; the fleet's `v_init` alone says nothing of a
    /// fish that swims another way. False: no direction cue on a first
    /// transition.
    pub axis_direction: bool,
    /// Cost of projecting a target's first transition the other way,
    /// `x̂ = x − v_init` instead of `x + v_init` (our addition; see
    /// [`cost`], "vicinity"). A newborn has no velocity, and `v_init` is the
    /// school's typical step; a fish that swims the other way (on synthetic
    /// hauls about a fifth of them), or one already in view when the haul
    /// starts, is then predicted `2·|v_init|` from where it goes. At 5 fps
    /// that is about 2 σ_v0 and the link survives; at 2.5 fps it is over
    /// 4 σ_v0 and no such first transition was linked (seeds 1–30: 0 of
    /// the 224 linked first transitions moved +x, 54 of the 137 broken
    /// ones did), so the fish was born again every frame. The first
    /// transition's cost is the lesser of the two projections', the
    /// reversed one plus this cost; a newborn lost on its first transition
    /// is projected forward only. Viterbi and MC (the matching cost); NN
    /// keeps the paper's one prediction. Default [`NEWBORN_REVERSE_COST`];
    /// ∞ = one projection, as the paper.
    pub newborn_reverse_cost: f32,
    /// Observations the paper's birth rule rejects as false alarms (away
    /// from the border and smaller than `birth_area_factor` · θ_A^L, after
    /// the first frame) are born as *tentative* targets (our addition)
    /// when this is ≥ 1: such a target is reported only if it closes with
    /// at least this many observations on its path, else it closes as
    /// [`CloseReason::Unconfirmed`] and reports nothing. A fish whose
    /// entry the segmentation missed (it is first seen mid-view, small)
    /// was never counted under the paper's rule. 0 = the paper's rule.
    /// Default [`CONFIRM_BIRTHS`].
    pub confirm_births: u8,
    /// A tentative target must also have moved, from the observation it
    /// was born on to its last one, by at least this many pixels per
    /// frame on average (left view): fish are carried through the view in
    /// about four frames (hundreds of pixels per frame at 5 fps), while a
    /// speck on the housing's window, a spot on the net or slow debris
    /// stays put. Default 5 % of the frame width (102 px at 2048), a
    /// fifth of the typical step.
    pub confirm_min_step: f32,
}

/// Default [`TrackConfig::confirm_births`]: 3 observations. Measured end
/// to end (session 40; success, count error): seeds 1–30 612 → 618 of 899
/// at +1.8 → +1.8 %, seeds 31–60 639 → 644 of 997 at +0.6 → +0.7 %; with 2,
/// 618 and 645 but the count rose (+2.3 and +1.0 %; seeds 1–3 +4.9 →
/// +7.4 %): a second sighting is as often the rest of a fish whose track
/// broke as a fish whose entry was missed.
pub const CONFIRM_BIRTHS: u8 = 3;

/// Default [`TrackConfig::newborn_reverse_cost`]: a reversed first step
/// must beat the forward one by this much. Measured on seeds 1–30 / 31–60
/// (success at 5 and 2.5 fps, README "Tracking"): 0 costs 16 fish at 5
/// fps; 12 leaves 5 fps at 1 251 of 1 896 (as without) and lifts 2.5 fps
/// 971 → 1 009 of 1 662.
pub const NEWBORN_REVERSE_COST: f32 = 12.0;

/// Default [`TrackConfig::depth_robust`].
pub const DEPTH_ROBUST: f32 = f32::INFINITY;

/// The sides of box `b` within `k` pixels of the matching side of `view`
/// or beyond it ([`cost::CUT_X_MIN`], …): where the view's border may cut it.
pub fn cut_sides(b: &Roi, view: &Roi, k: u32) -> u8 {
    ViewOutline::rect(view).cut_sides(b, k)
}

/// True when `b` comes within `k` pixels of an edge of `view` or crosses it
/// (`b.x ≤ view.x + k`, …): a box there may be cut by the view's border.
pub fn near_edge(b: &Roi, view: &Roi, k: u32) -> bool {
    cut_sides(b, view, k) != 0
}

impl TrackConfig {
    /// [`TrackConfig::view`] clipped to the frame.
    pub fn views(&self) -> [Roi; 2] {
        let f = Roi::full(self.width, self.height);
        [self.view[0].intersect(&f), self.view[1].intersect(&f)]
    }

    /// The views' borders: [`TrackConfig::outline`], else the rectangles
    /// of [`TrackConfig::views`].
    pub fn outlines(&self) -> [ViewOutline; 2] {
        self.outline
            .unwrap_or_else(|| self.views().map(|v| ViewOutline::rect(&v)))
    }

    /// Defaults for a `width × height` rectified frame.
    pub fn for_frame(width: u32, height: u32) -> TrackConfig {
        TrackConfig {
            width,
            height,
            view: [Roi::full(width, height); 2],
            outline: None,
            cues: Cues::ALL,
            miss_cost: 24.0,
            share_cost: 24.0,
            gate_cost: 48.0,
            nn_gate: 6.0,
            lost_gate: 3.0,
            newborn_lost_gate: 0.6,
            max_lost: 1,
            birth_area_factor: 2.0,
            z_ref_mm: 2000.0,
            sigma_defaults: Sigmas::for_frame(width),
            crossing_width: width,
            min_sigma_samples: 32,
            cue_cap: f32::INFINITY,
            swap_passes: 4,
            area_robust: f32::INFINITY,
            hist_robust: f32::INFINITY,
            depth_robust: DEPTH_ROBUST,
            cut_aware_motion: true,
            fold_shared: true,
            axis_direction: true,
            newborn_reverse_cost: NEWBORN_REVERSE_COST,
            confirm_births: CONFIRM_BIRTHS,
            confirm_min_step: 0.05 * width as f32,
        }
    }

    /// Checks the configuration for a trellis of depth `depth`.
    pub fn validate(&self, depth: usize) -> Result<(), TrackError> {
        let pos = |v: f32| v.is_finite() && v > 0.0;
        if self.width == 0 || self.height == 0 || self.width > 32_000 || self.height > 32_000 {
            return Err(TrackError::Config("width/height: 1 to 32000"));
        }
        if self.crossing_width == 0 || self.crossing_width > 32_000 {
            return Err(TrackError::Config("crossing_width: 1 to 32000"));
        }
        if self
            .view
            .iter()
            .any(|v| v.intersect(&Roi::full(self.width, self.height)).is_empty())
        {
            return Err(TrackError::Config(
                "view: a non-empty rectangle inside the frame",
            ));
        }
        let finite_side = |s: &outline::Side| {
            s.from.is_finite()
                && s.to.is_finite()
                && s.from <= s.to
                && s.at.iter().all(|v| v.is_finite())
        };
        if self.outline.is_some_and(|o| {
            !o.iter()
                .all(|v| [v.top, v.bottom, v.left, v.right].iter().all(finite_side))
        }) {
            return Err(TrackError::Config(
                "outline: finite sides, each spanning from ≤ to",
            ));
        }
        if !self.share_cost.is_finite() || self.share_cost < 0.0 {
            return Err(TrackError::Config("share_cost: finite, ≥ 0"));
        }
        if !pos(self.miss_cost)
            || !pos(self.gate_cost)
            || !pos(self.nn_gate)
            || !pos(self.lost_gate)
            || !self.newborn_lost_gate.is_finite()
            || self.newborn_lost_gate < 0.0
            || self.cue_cap.is_nan()
            || self.cue_cap <= 0.0
            || self.area_robust.is_nan()
            || self.area_robust <= 0.0
            || self.hist_robust.is_nan()
            || self.hist_robust <= 0.0
            || self.depth_robust.is_nan()
            || self.depth_robust <= 0.0
            || self.newborn_reverse_cost.is_nan()
            || self.newborn_reverse_cost < 0.0
        {
            return Err(TrackError::Config(
                "miss_cost, gate_cost, nn_gate, lost_gate: finite, > 0; newborn_lost_gate: finite, ≥ 0; cue_cap, area_robust, hist_robust, depth_robust: > 0; newborn_reverse_cost: ≥ 0",
            ));
        }
        if !self.confirm_min_step.is_finite() || self.confirm_min_step < 0.0 {
            return Err(TrackError::Config("confirm_min_step: finite, ≥ 0"));
        }
        if self.max_lost as usize + 2 > depth {
            return Err(TrackError::Config("max_lost must be ≤ trellis depth − 2"));
        }
        if !self.birth_area_factor.is_finite()
            || self.birth_area_factor < 0.0
            || !pos(self.z_ref_mm)
        {
            return Err(TrackError::Config("birth_area_factor ≥ 0, z_ref_mm > 0"));
        }
        let s = &self.sigma_defaults;
        if ![s.v, s.v0, s.a, s.m, s.h, s.d].iter().all(|&v| pos(v)) {
            return Err(TrackError::Config("sigma_defaults: finite, > 0"));
        }
        if self.cues.0 > 31 {
            return Err(TrackError::Config("cues: bits 0–4 only"));
        }
        Ok(())
    }
}

/// Why the tracker refused a call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum TrackError {
    /// A Table I parameter is invalid.
    Params(ParamError),
    /// The tracking configuration or the capacities are invalid.
    Config(&'static str),
    /// Frame indices must increase.
    FrameOrder {
        /// Last frame stepped.
        last: u32,
        /// Frame given.
        got: u32,
    },
}

impl fmt::Display for TrackError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TrackError::Params(e) => write!(f, "{e}"),
            TrackError::Config(w) => write!(f, "tracker configuration: {w}"),
            TrackError::FrameOrder { last, got } => {
                write!(f, "frame {got} does not follow frame {last}")
            }
        }
    }
}

impl core::error::Error for TrackError {}

impl From<ParamError> for TrackError {
    fn from(e: ParamError) -> Self {
        TrackError::Params(e)
    }
}

/// One committed frame of a track.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PathStep {
    /// Frame index as given to [`Tracker::step`].
    pub frame: u32,
    /// Index of the observation in that frame's slice; `None` when the
    /// target was lost and carried by its prediction.
    pub obs: Option<u16>,
    /// The observation's `pair` field (0 when predicted).
    pub pair: u16,
    /// Left position (rectified px, rounded): the observation's centroid or
    /// the prediction.
    pub x: i16,
    /// Left position y.
    pub y: i16,
}

/// Why a track ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CloseReason {
    /// Its prediction reached the border margin (left the field of view).
    Exit,
    /// Lost for more than `max_lost` frames in a row.
    Lost,
    /// [`Tracker::finish`] was called.
    End,
    /// Its best path had joined another target's (the same observations in
    /// the last two frames), or, with [`TrackConfig::fold_shared`], every
    /// observation on it lies on another at least as long track: a
    /// duplicate, dropped without committing its uncommitted stages.
    Duplicate,
    /// A tentative target ([`TrackConfig::confirm_births`]) closed with
    /// fewer observations than that: a false alarm by the paper's birth
    /// rule, dropped without committing (no frame reported).
    Unconfirmed,
}

/// What the tracker reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrackEvent<'a> {
    /// One frame of a track became final.
    Frame {
        /// Track id (1, 2, … in order of birth).
        track: u32,
        /// The frame.
        step: PathStep,
    },
    /// A track ended; every frame of it has been reported.
    Closed {
        /// Track id.
        track: u32,
        /// Why.
        reason: CloseReason,
        /// Frame of its first observation.
        first_frame: u32,
        /// Frame of its last observation.
        last_frame: u32,
        /// Frames with an observation.
        hits: u32,
        /// The path, up to `H` steps (predicted frames included).
        path: &'a [PathStep],
        /// True when the path had more than `H` steps (the first `H` are kept).
        truncated: bool,
    },
}

/// Receives track events.
pub trait EventSink {
    /// One event.
    fn event(&mut self, e: &TrackEvent<'_>);
}

impl<F: FnMut(&TrackEvent<'_>)> EventSink for F {
    fn event(&mut self, e: &TrackEvent<'_>) {
        self(e)
    }
}

/// Counters of skipped or dropped items (capacity overflow is not fatal).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TrackStats {
    /// Frames stepped.
    pub frames: u32,
    /// Observations beyond the N per frame.
    pub obs_dropped: u32,
    /// Observations with non-finite coordinates.
    pub obs_invalid: u32,
    /// New targets not created because T targets were alive.
    pub targets_dropped: u32,
    /// Gated candidates not kept because a stage holds K nodes.
    pub nodes_dropped: u32,
    /// Path steps beyond H (not kept in the closed event's path).
    pub path_steps_dropped: u32,
    /// Targets born.
    pub targets_born: u32,
    /// Tracks closed.
    pub tracks_closed: u32,
}

/// An observation with its cost features precomputed for the frame.
#[derive(Debug, Clone, Copy)]
struct Cand {
    obs: u16,
    pair: u16,
    left: ViewFeat,
    right: Option<ViewFeat>,
    depth: Option<f32>,
    bbox: Roi,
    area: u32,
}

/// Fixed inputs of a frame's edge costs.
#[derive(Debug, Clone, Copy)]
struct Ctx {
    sig: Sigmas,
    cues: Cues,
    v_init: [f32; 2],
    z_ref: f32,
    robust: Robust,
    cut_aware: bool,
    /// [`TrackConfig::newborn_reverse_cost`].
    reverse_cost: f32,
}

/// Per-camera features of one stereo edge.
#[derive(Debug, Clone, Copy)]
struct Edge {
    cost: f32,
    left: EdgeFeatures,
    right: Option<EdgeFeatures>,
}

fn add(a: [f32; 2], b: [f32; 2]) -> [f32; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

/// Stereo matching cost c = c^L + c^R (Section IV.C) of the edge from node
/// state `p` to candidate `c`. A first transition seen where the target
/// was (not lost) is projected both ways along `v_init`, the reversed
/// projection at `reverse_cost` more ([`TrackConfig::newborn_reverse_cost`]);
/// the cheaper edge counts.
fn edge(p: &NodeState, c: &Cand, x: &Ctx) -> Edge {
    if p.vel_known {
        return edge_with(p, c, x, p.vel);
    }
    let e = edge_with(p, c, x, x.v_init);
    // every cost term is ≥ 0: a forward edge at most `reverse_cost` cannot
    // lose, and needs no second evaluation
    if p.lost != 0 || e.cost <= x.reverse_cost || !x.reverse_cost.is_finite() {
        return e;
    }
    let r = edge_with(p, c, x, [-x.v_init[0], -x.v_init[1]]);
    let rc = r.cost + x.reverse_cost;
    if rc < e.cost {
        Edge { cost: rc, ..r }
    } else {
        e
    }
}

/// [`edge`] with the motion projection `x̂ = x + vel`.
fn edge_with(p: &NodeState, c: &Cand, x: &Ctx, vel: [f32; 2]) -> Edge {
    let first = !p.vel_known;
    let depths = (p.depth, c.depth);
    let fl = edge_features(
        &p.left,
        vel,
        &c.left,
        depths,
        direction_ref(p, &p.left, &c.left, x.v_init),
        x.z_ref,
        x.cut_aware,
    );
    let cl = camera_cost(&fl, &x.sig, first, x.cues, &x.robust);
    match (&p.right, &c.right) {
        (Some(pr), Some(cr)) => {
            let dir = direction_ref(p, pr, cr, x.v_init);
            let fr = edge_features(pr, vel, cr, depths, dir, x.z_ref, x.cut_aware);
            let c_r = camera_cost(&fr, &x.sig, first, x.cues, &x.robust);
            Edge {
                cost: cl + c_r,
                left: fl,
                right: Some(fr),
            }
        }
        _ => Edge {
            cost: 2.0 * cl,
            left: fl,
            right: None,
        },
    }
}

/// Least elongation (`w_o / h_o`) of a view whose body axis gives a
/// newborn's direction cue.
pub const MIN_AXIS_ELONGATION: f32 = 2.0;

/// Minimum gain of a pair exchange in the Viterbi selection
/// ([`greedy::improve_pairs`]); keeps near-ties with greedy's choice.
pub const SWAP_MIN_GAIN: f32 = 1e-3;

/// Mean lifespan of a fish in view at 5 fps, frames (paper Section II).
pub const LIFESPAN_FRAMES: f32 = 4.3;

/// A newborn's velocity before the data give one: v_ref (Table I), scaled
/// to cross the frame width in [`LIFESPAN_FRAMES`].
pub fn default_v_init(params: &Params, width: u32) -> [f32; 2] {
    let (x, y) = (params.v_ref_x, params.v_ref_y);
    let n = micromath::F32(x * x + y * y).sqrt().0;
    if n.is_nan() || n <= 0.0 {
        return [0.0, 0.0];
    }
    let s = width as f32 / LIFESPAN_FRAMES / n;
    [x * s, y * s]
}

/// The direction reference of eq. (7) for one camera's edge from node `p`
/// (view `pv`) to a candidate view `cv` (see `cost`): the target's own
/// velocity when known; else (its first transition) the sign-free body
/// axis of the node's view, or of the candidate's when the node's gives
/// none ([`TrackConfig::axis_direction`]), measured on the displacement
/// from where the fish was seen (a predicted node, a newborn lost on its
/// first transition, sits `lost · v_init` beyond it); else none.
fn direction_ref(p: &NodeState, pv: &ViewFeat, cv: &ViewFeat, v_init: [f32; 2]) -> DirectionRef {
    if p.vel_known {
        return DirectionRef::velocity(p.vel);
    }
    let ax = if pv.axis != cost::NO_AXIS {
        pv.axis
    } else {
        cv.axis
    };
    if ax == cost::NO_AXIS {
        return DirectionRef::NONE;
    }
    let n = p.lost as f32;
    DirectionRef {
        v_ref: cost::axis_vector(ax),
        line: true,
        offset: [n * v_init[0], n * v_init[1]],
    }
}

/// State of a real node reached from `p` (eq. 13–14).
fn real_state(p: &NodeState, cost: f32, c: &Cand, alpha: f32, cut_aware: bool) -> NodeState {
    let d = motion_delta(&p.left, &c.left, cut_aware);
    let vel = if p.vel_known {
        [
            alpha * d[0] + (1.0 - alpha) * p.vel[0],
            alpha * d[1] + (1.0 - alpha) * p.vel[1],
        ]
    } else {
        d
    };
    NodeState {
        cost,
        left: c.left,
        right: c.right,
        vel,
        vel_known: true,
        depth: c.depth.or(p.depth),
        lost: 0,
    }
}

/// State of the predicted (lost) node following `p`.
fn predicted_state(p: &NodeState, cost: f32, v_init: [f32; 2]) -> NodeState {
    let vel = if p.vel_known { p.vel } else { v_init };
    let mut s = *p;
    s.cost = cost;
    s.left = shifted(&p.left, vel);
    if let Some(r) = s.right.as_mut() {
        *r = shifted(r, vel);
    }
    s.lost = p.lost.saturating_add(1);
    s
}

/// A view moved by `v` (a lost target's prediction): centroid and box; the
/// box keeps the sides the border cut (the prediction of a partial view).
fn shifted(f: &ViewFeat, v: [f32; 2]) -> ViewFeat {
    let mut g = *f;
    g.pos = add(f.pos, v);
    g.bbox = [
        f.bbox[0] + v[0],
        f.bbox[1] + v[1],
        f.bbox[2] + v[0],
        f.bbox[3] + v[1],
    ];
    g
}

fn node_of(s: &NodeState, obs: u16, pair: u16, pred: usize) -> Node {
    Node {
        obs,
        pair,
        x: round_i16(s.left.pos[0]),
        y: round_i16(s.left.pos[1]),
        pred: pred.min(u8::MAX as usize) as u8,
    }
}

/// A live target: its trellis and its committed path.
#[derive(Debug, Clone)]
struct Target<const D: usize, const K: usize, const H: usize> {
    id: u32,
    trellis: Trellis<D, K>,
    path: heapless::Vec<PathStep, H>,
    truncated: bool,
    hits: u32,
    first_frame: u32,
    last_frame: u32,
    closing: Option<CloseReason>,
    /// Close decided this frame, carried out after every target stepped.
    pending: Option<CloseReason>,
    /// Born by [`TrackConfig::confirm_births`]: reported only if it closes
    /// with that many observations, having moved like a fish.
    tentative: bool,
    /// Left position of the observation it was born on (whole pixels).
    born_at: [i16; 2],
}

/// The multi-fish tracker (see the module documentation).
#[derive(Debug, Clone)]
pub struct Tracker<const T: usize, const D: usize, const K: usize, const H: usize, const N: usize> {
    cfg: TrackConfig,
    targets: heapless::Vec<Target<D, K, H>, T>,
    next_id: u32,
    sigma: SigmaEstimator,
    last_frame: Option<u32>,
    stats: TrackStats,
    cands: heapless::Vec<Cand, N>,
    taken: [bool; N],
    keys: [[f32; N]; T],
    recent: [Recent; RECENT],
    recent_next: usize,
    /// The last step used Viterbi association.
    viterbi: bool,
}

/// Observations of recently closed tracks kept for folding (see
/// [`TrackConfig::fold_shared`]): a ring, the oldest overwritten.
pub const RECENT: usize = 64;

/// One observation of a recently closed track.
#[derive(Debug, Clone, Copy, Default)]
struct Recent {
    track: u32,
    frame: u32,
    obs: u16,
    /// The track's observations (0 = empty slot).
    evidence: u16,
}

impl<const T: usize, const D: usize, const K: usize, const H: usize, const N: usize>
    Tracker<T, D, K, H, N>
{
    /// Trellis depth D (stages held before the oldest is committed).
    pub const DEPTH: usize = D;

    /// A tracker with no targets. Fails on an invalid configuration or
    /// capacities (D ≥ 2, 2 ≤ K ≤ 255, 1 ≤ N < 65535, T ≥ 1).
    pub fn new(cfg: TrackConfig) -> Result<Self, TrackError> {
        if D < 2 || !(2..=255).contains(&K) || N == 0 || N >= u16::MAX as usize || T == 0 {
            return Err(TrackError::Config(
                "capacities: D ≥ 2, 2 ≤ K ≤ 255, 1 ≤ N < 65535, T ≥ 1",
            ));
        }
        cfg.validate(D)?;
        Ok(Tracker {
            cfg,
            targets: heapless::Vec::new(),
            next_id: 1,
            sigma: SigmaEstimator::new(),
            last_frame: None,
            stats: TrackStats::default(),
            cands: heapless::Vec::new(),
            taken: [false; N],
            keys: [[f32::INFINITY; N]; T],
            recent: [Recent::default(); RECENT],
            recent_next: 0,
            viterbi: false,
        })
    }

    /// Counters so far.
    pub fn stats(&self) -> TrackStats {
        self.stats
    }

    /// The configuration.
    pub fn config(&self) -> &TrackConfig {
        &self.cfg
    }

    /// Number of live targets.
    pub fn live_targets(&self) -> usize {
        self.targets.len()
    }

    /// The σ² in use for the next frame.
    pub fn sigmas(&self) -> Sigmas {
        self.sigma.sigmas(
            &self.cfg.sigma_defaults,
            self.cfg.min_sigma_samples as usize,
        )
    }

    /// Processes frame `frame` (indices must increase; gaps are allowed and
    /// treated as one step) with its observations, reporting committed
    /// frames and closed tracks to `sink`.
    pub fn step<S: EventSink + ?Sized>(
        &mut self,
        frame: u32,
        observations: &[Observation],
        params: &Params,
        sink: &mut S,
    ) -> Result<(), TrackError> {
        params.validate()?;
        let first_frame = self.last_frame.is_none();
        if let Some(last) = self.last_frame {
            if frame <= last {
                return Err(TrackError::FrameOrder { last, got: frame });
            }
        }
        self.last_frame = Some(frame);
        self.stats.frames = self.stats.frames.saturating_add(1);
        self.load(observations);
        let min = self.cfg.min_sigma_samples as usize;
        let ctx = Ctx {
            sig: self.sigma.sigmas(&self.cfg.sigma_defaults, min),
            cues: self.cfg.cues,
            v_init: self
                .sigma
                .v_init_or(min, default_v_init(params, self.cfg.crossing_width)),
            z_ref: self.cfg.z_ref_mm,
            cut_aware: self.cfg.cut_aware_motion,
            // NN, the paper's baseline, takes the nearest observation to
            // the one prediction x + v
            reverse_cost: if params.tracker == Association::Nn {
                f32::INFINITY
            } else {
                self.cfg.newborn_reverse_cost
            },
            robust: Robust {
                cap: self.cfg.cue_cap,
                area: self.cfg.area_robust,
                hist: self.cfg.hist_robust,
                depth: self.cfg.depth_robust,
            },
        };
        match params.tracker {
            Association::Viterbi => self.step_viterbi(frame, &ctx, params, sink),
            Association::Mc | Association::Nn => self.step_greedy(frame, &ctx, params, sink),
        }
        if params.tracker == Association::Viterbi {
            self.drop_duplicates(sink);
        }
        self.viterbi = params.tracker == Association::Viterbi;
        self.resolve_closes(self.viterbi, sink);
        self.births(frame, params, first_frame, ctx.sig.v);
        Ok(())
    }

    /// Closes every live target (reason [`CloseReason::End`], or
    /// [`CloseReason::Duplicate`] when [`TrackConfig::fold_shared`] folds
    /// it), reporting the rest of their paths. The tracker can then be reused for a new haul.
    pub fn finish<S: EventSink + ?Sized>(&mut self, sink: &mut S) {
        for t in self.targets.iter_mut() {
            if t.closing.is_none() && t.pending.is_none() {
                t.pending = Some(CloseReason::End);
            }
        }
        self.resolve_closes(self.viterbi, sink);
        self.targets.clear();
        self.last_frame = None;
        self.recent = [Recent::default(); RECENT];
        self.recent_next = 0;
    }

    /// Carries out the closes decided this frame, in birth order, folding
    /// shared tracks (see [`TrackConfig::fold_shared`]).
    fn resolve_closes<S: EventSink + ?Sized>(&mut self, viterbi: bool, sink: &mut S) {
        let fold_on = viterbi && self.cfg.fold_shared;
        for i in 0..self.targets.len() {
            let Some(reason) = self.targets.get(i).and_then(|t| t.pending) else {
                continue;
            };
            let fold = fold_on && self.is_shared(i);
            let Some(t) = self.targets.get_mut(i) else {
                continue;
            };
            t.pending = None;
            if fold {
                close(t, CloseReason::Duplicate, &mut self.stats, sink);
                continue;
            }
            if t.tentative && !confirmed(t, self.cfg.confirm_births, self.cfg.confirm_min_step) {
                close(t, CloseReason::Unconfirmed, &mut self.stats, sink);
                continue;
            }
            close(t, reason, &mut self.stats, sink);
            if !fold_on {
                continue;
            }
            let ev = t.hits.min(u16::MAX as u32) as u16;
            // the steps of the closed track's trellis (the last D frames):
            // a track that may fold has committed nothing, so its steps all
            // lie in that span; `t.path` would hold only the first H steps
            for (frame, obs) in real_steps(&t.trellis) {
                if let Some(slot) = self.recent.get_mut(self.recent_next) {
                    *slot = Recent {
                        track: t.id,
                        frame,
                        obs,
                        evidence: ev,
                    };
                    self.recent_next = (self.recent_next + 1) % RECENT;
                }
            }
        }
    }

    /// True when target `i` has committed nothing and every observation on
    /// its best path lies on the path of another live or recently closed
    /// track with at least as many observations.
    fn is_shared(&self, i: usize) -> bool {
        let Some(t) = self.targets.get(i) else {
            return false;
        };
        if !t.path.is_empty() {
            return false;
        }
        let mine = real_steps(&t.trellis);
        let n = mine.len() as u32;
        if n == 0 {
            return false;
        }
        let covered = |has: &dyn Fn(u32, u16) -> bool| mine.iter().all(|&(f, o)| has(f, o));
        for (j, o) in self.targets.iter().enumerate() {
            if j == i || o.closing == Some(CloseReason::Duplicate) {
                continue;
            }
            let ev = if o.closing.is_some() {
                o.hits
            } else {
                evidence(o)
            };
            if ev < n {
                continue;
            }
            let steps = real_steps(&o.trellis);
            let on = |f: u32, ob: u16| {
                o.path.iter().any(|s| s.frame == f && s.obs == Some(ob))
                    || steps.iter().any(|&(sf, so)| sf == f && so == ob)
            };
            if covered(&on) {
                return true;
            }
        }
        let Some(&(f0, o0)) = mine.first() else {
            return false;
        };
        self.recent.iter().any(|r| {
            r.evidence as u32 >= n
                && r.frame == f0
                && r.obs == o0
                && covered(&|f, ob| {
                    self.recent.iter().any(|q| {
                        q.evidence > 0 && q.track == r.track && q.frame == f && q.obs == ob
                    })
                })
        })
    }

    /// Precomputes the frame's candidates.
    fn load(&mut self, observations: &[Observation]) {
        self.cands.clear();
        for t in self.taken.iter_mut() {
            *t = false;
        }
        let [vl, vr] = self.cfg.outlines();
        let cfg_axis = self.cfg.axis_direction;
        for (i, o) in observations.iter().enumerate() {
            if i >= N {
                self.stats.obs_dropped = self.stats.obs_dropped.saturating_add(1);
                continue;
            }
            if !o.is_valid() {
                self.stats.obs_invalid = self.stats.obs_invalid.saturating_add(1);
                continue;
            }
            let view = |v: &CameraView, r: &ViewOutline| {
                let bbox = [
                    v.bbox.x as f32,
                    v.bbox.y as f32,
                    v.bbox.right() as f32,
                    v.bbox.bottom() as f32,
                ];
                // a box that is empty or misses the centroid says nothing
                // about which end of the fish is seen: centroids then
                let sane = !v.bbox.is_empty()
                    && v.cx >= bbox[0]
                    && v.cx <= bbox[2]
                    && v.cy >= bbox[1]
                    && v.cy <= bbox[3];
                let sides = r.cut_sides(&v.bbox, 2);
                ViewFeat {
                    pos: [v.cx, v.cy],
                    area: v.area as f32,
                    cut: sides != 0,
                    bbox,
                    cut_sides: if sane { sides } else { 0 },
                    cdf: cdf(&v.hist),
                    axis: if sides == 0 && cfg_axis && v.elongation >= MIN_AXIS_ELONGATION {
                        cost::axis_degrees(v.angle)
                    } else {
                        cost::NO_AXIS
                    },
                }
            };
            let _ = self.cands.push(Cand {
                obs: i as u16,
                pair: o.pair,
                left: view(&o.left, &vl),
                right: o.right.as_ref().map(|v| view(v, &vr)),
                depth: o.depth(),
                bbox: o.left.bbox,
                area: o.left.area,
            });
        }
    }

    fn step_viterbi<S: EventSink + ?Sized>(
        &mut self,
        frame: u32,
        ctx: &Ctx,
        params: &Params,
        sink: &mut S,
    ) {
        let cfg = self.cfg;
        // Selection: which target each observation is the best node of,
        // from a joint one-to-one assignment (see the module docs).
        for (t, row) in self.targets.iter_mut().zip(self.keys.iter_mut()) {
            if t.trellis.len() >= D {
                commit(t, &cfg, &mut self.stats, sink);
            }
            for k in row.iter_mut() {
                *k = f32::INFINITY;
            }
            let base = best_cost_of(&t.trellis);
            for (c, k) in self.cands.iter().zip(row.iter_mut()) {
                for s in t.trellis.front.iter() {
                    let e = edge(s, c, ctx);
                    if e.cost.partial_cmp(&cfg.gate_cost) != Some(core::cmp::Ordering::Less) {
                        continue;
                    }
                    let inc = s.cost + e.cost - base;
                    if inc < cfg.miss_cost && inc < *k {
                        *k = inc;
                    }
                }
            }
        }
        let live = self.targets.len().min(T);
        let mut assign = [None; T];
        greedy_assign_rows(&self.keys, live, self.cands.len(), &mut assign);
        if let (Some(k), Some(o)) = (self.keys.get(..live), assign.get_mut(..live)) {
            greedy::improve_pairs(k, cfg.miss_cost, SWAP_MIN_GAIN, cfg.swap_passes as usize, o);
        }
        let mut owner = [u8::MAX; N];
        for (ti, a) in assign.iter().enumerate().take(live) {
            if let Some(o) = a.and_then(|ci| owner.get_mut(ci as usize)) {
                *o = ti.min(u8::MAX as usize - 1) as u8;
            }
        }
        for (ti, t) in self.targets.iter_mut().enumerate() {
            let mut nodes: heapless::Vec<Node, K> = heapless::Vec::new();
            let mut states: heapless::Vec<NodeState, K> = heapless::Vec::new();
            // Real candidates: the K − 1 cheapest C_j, sorted by (C_j, j).
            let mut best: heapless::Vec<(f32, usize, usize, f32), K> = heapless::Vec::new();
            for (ci, c) in self.cands.iter().enumerate() {
                // Taking an observation the joint selection gave another
                // target costs `share_cost` (see the module docs).
                let share = match owner.get(ci).copied() {
                    Some(o) if o != u8::MAX && o as usize != ti => cfg.share_cost,
                    _ => 0.0,
                };
                let mut b: Option<(usize, f32, f32)> = None; // (pred, C, c)
                for (i, s) in t.trellis.front.iter().enumerate() {
                    let e = edge(s, c, ctx);
                    if e.cost.partial_cmp(&cfg.gate_cost) != Some(core::cmp::Ordering::Less) {
                        continue;
                    }
                    let acc = s.cost + e.cost + share;
                    if b.is_none_or(|(_, bc, _)| acc < bc) {
                        b = Some((i, acc, e.cost));
                    }
                }
                let Some((pi, acc, ec)) = b else {
                    continue;
                };
                let pos = best
                    .iter()
                    .position(|&(bc, _, _, _)| acc < bc)
                    .unwrap_or(best.len());
                if best.len() < K - 1 {
                    let _ = best.insert(pos, (acc, ci, pi, ec));
                } else {
                    self.stats.nodes_dropped = self.stats.nodes_dropped.saturating_add(1);
                    if pos < best.len() {
                        best.pop();
                        let _ = best.insert(pos, (acc, ci, pi, ec));
                    }
                }
            }
            for &(acc, ci, pi, _) in best.iter() {
                let (Some(c), Some(p)) = (self.cands.get(ci), t.trellis.front.get(pi)) else {
                    continue;
                };
                let s = real_state(p, acc, c, params.alpha, ctx.cut_aware);
                let _ = nodes.push(node_of(&s, c.obs, c.pair, pi));
                let _ = states.push(s);
            }
            // The predicted node, from the cheapest front node (the target
            // dies in `advance` if it wins after max_lost lost frames).
            let mut lp: Option<(usize, f32)> = None;
            for (i, s) in t.trellis.front.iter().enumerate() {
                if lp.is_none_or(|(_, c)| s.cost < c) {
                    lp = Some((i, s.cost));
                }
            }
            if let Some((i, c)) = lp {
                if let Some(p) = t.trellis.front.get(i) {
                    let s = predicted_state(p, c + cfg.miss_cost, ctx.v_init);
                    let _ = nodes.push(node_of(&s, PREDICTED, 0, i));
                    let _ = states.push(s);
                }
            }
            advance(
                t,
                frame,
                &nodes,
                &states,
                &self.cands,
                ctx,
                &cfg,
                params,
                &mut self.sigma,
                &mut self.taken,
            );
        }
    }

    fn step_greedy<S: EventSink + ?Sized>(
        &mut self,
        frame: u32,
        ctx: &Ctx,
        params: &Params,
        sink: &mut S,
    ) {
        let cfg = self.cfg;
        let nn = params.tracker == Association::Nn;
        for (t, row) in self.targets.iter_mut().zip(self.keys.iter_mut()) {
            if t.trellis.len() >= D {
                commit(t, &cfg, &mut self.stats, sink);
            }
            for k in row.iter_mut() {
                *k = f32::INFINITY;
            }
            let Some(p) = t.trellis.best_front().and_then(|b| t.trellis.front.get(b)) else {
                continue;
            };
            for (c, k) in self.cands.iter().zip(row.iter_mut()) {
                let e = edge(p, c, ctx);
                if nn {
                    let s2 = if p.vel_known { ctx.sig.v } else { ctx.sig.v0 };
                    if e.left.d2 / s2 < cfg.nn_gate {
                        *k = e.left.d2;
                    }
                } else if e.cost < cfg.gate_cost && e.cost < cfg.miss_cost {
                    *k = e.cost;
                }
            }
        }
        let live = self.targets.len().min(T);
        let mut assign = [None; T];
        greedy_assign_rows(&self.keys, live, self.cands.len(), &mut assign);
        for (t, a) in self.targets.iter_mut().zip(assign.iter()) {
            let mut nodes: heapless::Vec<Node, K> = heapless::Vec::new();
            let mut states: heapless::Vec<NodeState, K> = heapless::Vec::new();
            if let Some(pi) = t.trellis.best_front() {
                if let Some(p) = t.trellis.front.get(pi) {
                    match a.and_then(|ci| self.cands.get(ci as usize)) {
                        Some(c) => {
                            let e = edge(p, c, ctx);
                            let s = real_state(p, p.cost + e.cost, c, params.alpha, ctx.cut_aware);
                            let _ = nodes.push(node_of(&s, c.obs, c.pair, pi));
                            let _ = states.push(s);
                        }
                        None if p.lost < cfg.max_lost => {
                            let s = predicted_state(p, p.cost + cfg.miss_cost, ctx.v_init);
                            let _ = nodes.push(node_of(&s, PREDICTED, 0, pi));
                            let _ = states.push(s);
                        }
                        None => {}
                    }
                }
            }
            advance(
                t,
                frame,
                &nodes,
                &states,
                &self.cands,
                ctx,
                &cfg,
                params,
                &mut self.sigma,
                &mut self.taken,
            );
        }
    }

    /// Drops duplicate trellises (see the module documentation). O(T²) per
    /// frame.
    fn drop_duplicates<S: EventSink + ?Sized>(&mut self, sink: &mut S) {
        let n = self.targets.len();
        for i in 0..n {
            for j in (i + 1)..n {
                let (Some(a), Some(b)) = (self.targets.get(i), self.targets.get(j)) else {
                    continue;
                };
                if a.closing.is_some()
                    || b.closing.is_some()
                    || a.pending.is_some()
                    || b.pending.is_some()
                {
                    continue;
                }
                let ka = last_two(&a.trellis);
                let same_two = ka.is_some() && ka == last_two(&b.trellis);
                let la = last_obs(&a.trellis);
                let newborn = |t: &Target<D, K, H>| t.hits == 0 && t.trellis.len() == 2;
                let same_newborn =
                    la.is_some() && la == last_obs(&b.trellis) && (newborn(a) || newborn(b));
                if !same_two && !same_newborn {
                    continue;
                }
                let (ea, eb) = (evidence(a), evidence(b));
                let drop = if eb > ea || (eb == ea && best_cost(b) < best_cost(a)) {
                    i
                } else {
                    j
                };
                if let Some(t) = self.targets.get_mut(drop) {
                    close(t, CloseReason::Duplicate, &mut self.stats, sink);
                }
            }
        }
    }

    /// New targets from unassociated observations (see the module docs).
    /// Observations near a lost target's prediction are marked taken first,
    /// including cut views near a target exiting this step; then the
    /// targets closed this step are removed.
    fn births(&mut self, frame: u32, params: &Params, first_frame: bool, sv2: f32) {
        let (vl, m) = (self.cfg.outlines()[0], params.margin);
        let cut_aware = self.cfg.cut_aware_motion;
        let big = self.cfg.birth_area_factor * params.area_min as f32;
        let gate = self.cfg.lost_gate;
        let newborn_gate = self.cfg.newborn_lost_gate;
        for c in self.cands.iter() {
            let Some(tk) = self.taken.get_mut(c.obs as usize).filter(|tk| !**tk) else {
                continue;
            };
            // Near a lost target's prediction: its partly hidden view.
            *tk |= self.targets.iter().any(|t| {
                (t.closing.is_none() || (t.closing == Some(CloseReason::Exit) && c.left.cut))
                    && t.trellis
                        .best_front()
                        .and_then(|b| t.trellis.front.get(b))
                        .is_some_and(|s| {
                            let [dx, dy] = motion_delta(&s.left, &c.left, cut_aware);
                            s.lost > 0
                                && (dx * dx + dy * dy) / sv2
                                    < if s.vel_known { gate } else { newborn_gate }
                        })
            });
        }
        self.targets.retain(|t| t.closing.is_none());
        for c in self.cands.iter() {
            if self.taken.get(c.obs as usize).copied().unwrap_or(true) {
                continue;
            }
            let near_border = m > 0 && vl.cut_sides(&c.bbox, m - 1) != 0;
            let tentative = !first_frame && !near_border && (c.area as f32) < big;
            if tentative && self.cfg.confirm_births == 0 {
                continue;
            }
            let s = NodeState {
                cost: 0.0,
                left: c.left,
                right: c.right,
                vel: [0.0, 0.0],
                vel_known: false,
                depth: c.depth,
                lost: 0,
            };
            let mut t = Target {
                id: self.next_id,
                trellis: Trellis::new(),
                path: heapless::Vec::new(),
                truncated: false,
                hits: 0,
                first_frame: frame,
                last_frame: frame,
                closing: None,
                pending: None,
                tentative,
                born_at: [round_i16(c.left.pos[0]), round_i16(c.left.pos[1])],
            };
            if !t
                .trellis
                .push(frame, &[node_of(&s, c.obs, c.pair, 0)], &[s])
            {
                continue;
            }
            if self.targets.push(t).is_err() {
                self.stats.targets_dropped = self.stats.targets_dropped.saturating_add(1);
                continue;
            }
            self.next_id = self.next_id.wrapping_add(1);
            self.stats.targets_born = self.stats.targets_born.saturating_add(1);
        }
    }
}

fn greedy_assign_rows<const T: usize, const N: usize>(
    keys: &[[f32; N]; T],
    rows: usize,
    cols: usize,
    out: &mut [Option<u16>; T],
) {
    let rows = rows.min(T);
    if let (Some(k), Some(o)) = (keys.get(..rows), out.get_mut(..rows)) {
        greedy::greedy_assign(k, cols, o);
    }
}

/// Pushes the new stage of a target (or closes it when the stage is empty),
/// records its minimum-cost node (set S, σ samples) and tests its exit.
/// Closes are only marked (`pending`) and carried out once every target
/// has stepped ([`Tracker::step`]), so that a closing track can be compared
/// with the others' paths of this frame.
#[allow(clippy::too_many_arguments)]
fn advance<const D: usize, const K: usize, const H: usize, const N: usize>(
    t: &mut Target<D, K, H>,
    frame: u32,
    nodes: &[Node],
    states: &[NodeState],
    cands: &heapless::Vec<Cand, N>,
    ctx: &Ctx,
    cfg: &TrackConfig,
    params: &Params,
    sigma: &mut SigmaEstimator,
    taken: &mut [bool; N],
) {
    if nodes.is_empty() {
        t.pending = Some(CloseReason::Lost);
        return;
    }
    // argmin_j C_j(t), first on ties.
    let mut bi = 0usize;
    for (i, s) in states.iter().enumerate() {
        if states.get(bi).is_some_and(|b| s.cost < b.cost) {
            bi = i;
        }
    }
    if let (Some(n), Some(_)) = (nodes.get(bi), states.get(bi)) {
        if n.obs != PREDICTED {
            if let Some(tk) = taken.get_mut(n.obs as usize) {
                *tk = true;
            }
            let c = cands.iter().find(|c| c.obs == n.obs);
            let p = t.trellis.front.get(n.pred as usize);
            if let (Some(c), Some(p)) = (c, p) {
                let e = edge(p, c, ctx);
                let first = !p.vel_known;
                sigma.push_features(&e.left, first);
                if let Some(r) = e.right.as_ref() {
                    sigma.push_features(r, first);
                }
                sigma.push_velocity(motion_delta(&p.left, &c.left, ctx.cut_aware));
            }
        }
    }
    if !t.trellis.push(frame, nodes, states) {
        // Cannot happen (the caller committed); keep the target alive as is.
        return;
    }
    let lost_now = nodes.get(bi).is_some_and(|n| n.obs == PREDICTED);
    if let (Some(s), true) = (states.get(bi), lost_now) {
        if s.vel_known {
            let p = s.left.pos;
            if !cfg.outlines()[0].holds(p, params.margin as f32) {
                t.pending = Some(CloseReason::Exit);
                return;
            }
        }
        if s.lost > cfg.max_lost {
            t.pending = Some(CloseReason::Lost);
        }
    }
}

/// (frame, observation) of the real nodes on the best uncommitted path.
fn real_steps<const D: usize, const K: usize>(t: &Trellis<D, K>) -> heapless::Vec<(u32, u16), D> {
    let mut out = heapless::Vec::new();
    let mut path = [0u8; D];
    if !t.best_front().is_some_and(|b| t.backtrack(b, &mut path)) {
        return out;
    }
    for s in 0..t.len() {
        let step = t.stage(s).and_then(|st| {
            st.nodes
                .get(path.get(s).copied().unwrap_or(0) as usize)
                .map(|nd| (st.frame, nd.obs))
        });
        if let Some((f, o)) = step.filter(|&(_, o)| o != PREDICTED) {
            let _ = out.push((f, o));
        }
    }
    out
}

/// Observation of the best front node, if real.
fn last_obs<const D: usize, const K: usize>(t: &Trellis<D, K>) -> Option<u16> {
    let n = t.len();
    let last = t.stage(n.checked_sub(1)?)?.nodes.get(t.best_front()?)?;
    (last.obs != PREDICTED).then_some(last.obs)
}

/// C of a trellis's best front node (∞ when empty).
fn best_cost_of<const D: usize, const K: usize>(t: &Trellis<D, K>) -> f32 {
    t.best_front()
        .and_then(|b| t.front.get(b))
        .map_or(f32::INFINITY, |s| s.cost)
}

/// C of the best front node.
fn best_cost<const D: usize, const K: usize, const H: usize>(t: &Target<D, K, H>) -> f32 {
    t.trellis
        .best_front()
        .and_then(|b| t.trellis.front.get(b))
        .map_or(f32::INFINITY, |s| s.cost)
}

/// Observations of the best path's last two stages, if both are real.
fn last_two<const D: usize, const K: usize>(t: &Trellis<D, K>) -> Option<(u16, u16)> {
    let n = t.len();
    if n < 2 {
        return None;
    }
    let last = t.stage(n - 1)?.nodes.get(t.best_front()?)?;
    let prev = t.stage(n - 2)?.nodes.get(last.pred as usize)?;
    (last.obs != PREDICTED && prev.obs != PREDICTED).then_some((last.obs, prev.obs))
}

/// A tentative target is confirmed ([`TrackConfig::confirm_births`]): at
/// least `need` observations on its path, and its last one (on the
/// uncommitted best path: a target closes within `max_lost` ≤ D − 2
/// frames of it) at least `min_step` px per frame from where it was born.
fn confirmed<const D: usize, const K: usize, const H: usize>(
    t: &Target<D, K, H>,
    need: u8,
    min_step: f32,
) -> bool {
    if evidence(t) < u32::from(need) {
        return false;
    }
    let mut path = [0u8; D];
    let Some(b) = t.trellis.best_front() else {
        return false;
    };
    if !t.trellis.backtrack(b, &mut path) {
        return false;
    }
    let last = (0..t.trellis.len()).rev().find_map(|s| {
        let st = t.trellis.stage(s)?;
        let nd = st.nodes.get(path.get(s).copied().unwrap_or(0) as usize)?;
        (nd.obs != PREDICTED).then_some((st.frame, nd.x, nd.y))
    });
    let Some((frame, x, y)) = last else {
        return false;
    };
    let frames = frame.saturating_sub(t.first_frame);
    if frames == 0 {
        return false;
    }
    let dx = f32::from(x) - f32::from(t.born_at[0]);
    let dy = f32::from(y) - f32::from(t.born_at[1]);
    dx * dx + dy * dy >= (min_step * frames as f32) * (min_step * frames as f32)
}

/// Observations on a target's path: committed hits + real nodes of the
/// uncommitted best path.
fn evidence<const D: usize, const K: usize, const H: usize>(t: &Target<D, K, H>) -> u32 {
    let mut path = [0u8; D];
    let mut n = t.hits;
    if t.trellis
        .best_front()
        .is_some_and(|b| t.trellis.backtrack(b, &mut path))
    {
        for s in 0..t.trellis.len() {
            let real = t
                .trellis
                .stage(s)
                .and_then(|st| st.nodes.get(path.get(s).copied().unwrap_or(0) as usize))
                .is_some_and(|nd| nd.obs != PREDICTED);
            n += real as u32;
        }
    }
    n
}

/// Appends a committed step to the target's path and reports it.
fn record<const D: usize, const K: usize, const H: usize, S: EventSink + ?Sized>(
    t: &mut Target<D, K, H>,
    frame: u32,
    node: &Node,
    stats: &mut TrackStats,
    sink: &mut S,
) {
    let step = PathStep {
        frame,
        obs: if node.obs == PREDICTED {
            None
        } else {
            Some(node.obs)
        },
        pair: node.pair,
        x: node.x,
        y: node.y,
    };
    if step.obs.is_some() {
        t.hits = t.hits.saturating_add(1);
        t.last_frame = frame;
    }
    if t.path.push(step).is_err() {
        t.truncated = true;
        stats.path_steps_dropped = stats.path_steps_dropped.saturating_add(1);
    }
    sink.event(&TrackEvent::Frame { track: t.id, step });
}

/// Commits the target's oldest stage (its trellis is full). A tentative
/// target ([`TrackConfig::confirm_births`]) that is [`confirmed`] by now
/// becomes an ordinary one; one that is not drops the stage unreported, so
/// a target that is never confirmed reports no frame however long it
/// lives (a speck on the window for the whole haul).
fn commit<const D: usize, const K: usize, const H: usize, S: EventSink + ?Sized>(
    t: &mut Target<D, K, H>,
    cfg: &TrackConfig,
    stats: &mut TrackStats,
    sink: &mut S,
) {
    if t.tentative && confirmed(t, cfg.confirm_births, cfg.confirm_min_step) {
        t.tentative = false;
    }
    if let Some((frame, node)) = t.trellis.commit_oldest() {
        if !t.tentative {
            record(t, frame, &node, stats, sink);
        }
    }
}

/// Backtracks the best path, commits it up to its last observation and
/// reports the closed track.
fn close<const D: usize, const K: usize, const H: usize, S: EventSink + ?Sized>(
    t: &mut Target<D, K, H>,
    reason: CloseReason,
    stats: &mut TrackStats,
    sink: &mut S,
) {
    if t.closing.is_some() {
        return;
    }
    t.closing = Some(reason);
    let mut path = [0u8; D];
    let ok = !matches!(reason, CloseReason::Duplicate | CloseReason::Unconfirmed)
        && t.trellis
            .best_front()
            .is_some_and(|b| t.trellis.backtrack(b, &mut path));
    if ok {
        let n = t.trellis.len();
        let mut last_real = None;
        for s in 0..n {
            let node = t
                .trellis
                .stage(s)
                .and_then(|st| st.nodes.get(path.get(s).copied().unwrap_or(0) as usize));
            if node.is_some_and(|nd| nd.obs != PREDICTED) {
                last_real = Some(s);
            }
        }
        if let Some(lr) = last_real {
            for s in 0..=lr {
                let step = t.trellis.stage(s).and_then(|st| {
                    st.nodes
                        .get(path.get(s).copied().unwrap_or(0) as usize)
                        .map(|nd| (st.frame, *nd))
                });
                if let Some((frame, node)) = step {
                    record(t, frame, &node, stats, sink);
                }
            }
        }
    }
    stats.tracks_closed = stats.tracks_closed.saturating_add(1);
    sink.event(&TrackEvent::Closed {
        track: t.id,
        reason,
        first_frame: t.first_frame,
        last_frame: t.last_frame,
        hits: t.hits,
        path: &t.path,
        truncated: t.truncated,
    });
}

#[cfg(test)]
mod tests;
