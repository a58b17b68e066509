//! One target's trellis for the multi-target Viterbi data association,
//! Section IV.C, eq. (10)–(12), Fig. 8.
//!
//! A trellis holds at most `D` uncommitted stages (frames) of at most `K`
//! nodes. A node is an observation of that frame (or the target's predicted
//! position when it was lost) with its predecessor π_j(t) in the previous
//! stage; the newest stage also keeps each node's full state (accumulated
//! cost C_j(t), position, velocity, appearance) in `front`, which is all the
//! next frame's edge costs need.
//!
//! Fixed memory: when a new stage arrives and `D` stages are held, the oldest
//! stage is *committed*: the node on the current best path (backtracked from
//! the minimum-cost front node — when every surviving path passes through
//! one node of that stage this is that node) becomes final, and every node
//! in later stages whose path does not go through it is pruned (forward
//! cascade). The best path always survives, so the front is never emptied.

use super::cost::{Cdf, ViewFeat};

/// Observation index of a node standing for "lost this frame: the target is
/// at its predicted position" (Section IV.C.2).
pub const PREDICTED: u16 = u16::MAX;

/// A trellis node as kept for backtracking (10 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Node {
    /// Index of the observation in its frame's slice, or [`PREDICTED`].
    pub obs: u16,
    /// The observation's `pair` field (0 for a predicted node).
    pub pair: u16,
    /// Left position, rounded to whole pixels (for predicted frames).
    pub x: i16,
    /// Left position, rounded to whole pixels.
    pub y: i16,
    /// π_j(t): index of the predecessor in the previous stage.
    pub pred: u8,
}

/// Full state of a node in the newest stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeState {
    /// C_j(t), eq. (12).
    pub cost: f32,
    /// Left view (position, raw area, histogram).
    pub left: ViewFeat,
    /// Right view, if the node's observation had one.
    pub right: Option<ViewFeat>,
    /// Velocity (left, px/frame), eq. (14).
    pub vel: [f32; 2],
    /// False until the first transition of the target's path.
    pub vel_known: bool,
    /// Depth of the last real observation on the path that had one, mm
    /// (an unpaired view carries its predecessor's depth).
    pub depth: Option<f32>,
    /// Consecutive predicted (lost) stages ending at this node.
    pub lost: u8,
}

/// One frame of a trellis.
#[derive(Debug, Clone)]
pub struct Stage<const K: usize> {
    /// Frame index.
    pub frame: u32,
    /// The nodes.
    pub nodes: heapless::Vec<Node, K>,
}

impl<const K: usize> Stage<K> {
    const fn new() -> Self {
        Stage {
            frame: 0,
            nodes: heapless::Vec::new(),
        }
    }
}

/// Rounds to i16 with saturation.
pub fn round_i16(v: f32) -> i16 {
    let r = libm::roundf(v);
    if r.is_nan() {
        0
    } else if r >= i16::MAX as f32 {
        i16::MAX
    } else if r <= i16::MIN as f32 {
        i16::MIN
    } else {
        r as i16
    }
}

/// A target's trellis.
#[derive(Debug, Clone)]
pub struct Trellis<const D: usize, const K: usize> {
    stages: [Stage<K>; D],
    head: usize,
    len: usize,
    /// States of the newest stage's nodes (same order), or of the last
    /// committed stage's chosen node when no stage is held.
    pub front: heapless::Vec<NodeState, K>,
}

impl<const D: usize, const K: usize> Default for Trellis<D, K> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const D: usize, const K: usize> Trellis<D, K> {
    /// Empty trellis.
    pub const fn new() -> Self {
        Trellis {
            stages: [const { Stage::new() }; D],
            head: 0,
            len: 0,
            front: heapless::Vec::new(),
        }
    }

    /// Number of uncommitted stages.
    pub const fn len(&self) -> usize {
        self.len
    }

    /// True when no stage is held.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Uncommitted stage `i` (0 = oldest).
    pub fn stage(&self, i: usize) -> Option<&Stage<K>> {
        if i >= self.len || D == 0 {
            return None;
        }
        self.stages.get((self.head + i) % D)
    }

    fn stage_mut(&mut self, i: usize) -> Option<&mut Stage<K>> {
        if i >= self.len || D == 0 {
            return None;
        }
        self.stages.get_mut((self.head + i) % D)
    }

    /// Index of the minimum-cost front node (first on ties).
    pub fn best_front(&self) -> Option<usize> {
        let mut best: Option<(usize, f32)> = None;
        for (i, s) in self.front.iter().enumerate() {
            if best.is_none_or(|(_, c)| s.cost < c) {
                best = Some((i, s.cost));
            }
        }
        best.map(|(i, _)| i)
    }

    /// Node index, per held stage (oldest first), of the path ending at front
    /// node `from`. Returns false if a predecessor index is broken.
    pub fn backtrack(&self, from: usize, out: &mut [u8; D]) -> bool {
        if self.len == 0 {
            return true;
        }
        let mut cur = from;
        for s in (0..self.len).rev() {
            let Some(stage) = self.stage(s) else {
                return false;
            };
            let Some(node) = stage.nodes.get(cur) else {
                return false;
            };
            if let Some(o) = out.get_mut(s) {
                *o = cur as u8;
            }
            cur = node.pred as usize;
        }
        true
    }

    /// Appends a stage. The caller commits first when `len() == D`;
    /// returns false (nothing changed) if the trellis is full or the node
    /// and state counts differ.
    pub fn push(&mut self, frame: u32, nodes: &[Node], states: &[NodeState]) -> bool {
        if self.len >= D || nodes.len() != states.len() || nodes.len() > K || nodes.is_empty() {
            return false;
        }
        let idx = (self.head + self.len) % D;
        let Some(stage) = self.stages.get_mut(idx) else {
            return false;
        };
        stage.frame = frame;
        stage.nodes.clear();
        self.front.clear();
        for (n, s) in nodes.iter().zip(states.iter()) {
            let _ = stage.nodes.push(*n);
            let _ = self.front.push(*s);
        }
        self.len += 1;
        true
    }

    /// Commits the oldest stage along the current best path and prunes the
    /// paths that disagree (see the module documentation). Returns the
    /// committed frame and node.
    pub fn commit_oldest(&mut self) -> Option<(u32, Node)> {
        if self.len == 0 {
            return None;
        }
        let best = self.best_front()?;
        let mut path = [0u8; D];
        if !self.backtrack(best, &mut path) {
            return None;
        }
        let chosen = *path.first()? as usize;
        let (frame, node) = {
            let st = self.stage(0)?;
            (st.frame, *st.nodes.get(chosen)?)
        };
        // Drop the stage; cascade the pruning forward.
        self.head = (self.head + 1) % D;
        self.len -= 1;
        // `keep`/`map` describe the previous stage: kept flag and new index.
        let mut keep = [false; K];
        let mut map = [0u8; K];
        if let Some(k) = keep.get_mut(chosen) {
            *k = true;
        }
        for s in 0..self.len {
            let Some(stage) = self.stage_mut(s) else {
                break;
            };
            let mut nk = [false; K];
            let mut nm = [0u8; K];
            let mut w = 0usize;
            let n = stage.nodes.len();
            for r in 0..n {
                let Some(mut node) = stage.nodes.get(r).copied() else {
                    break;
                };
                let p = node.pred as usize;
                if keep.get(p).copied().unwrap_or(false) {
                    node.pred = if s == 0 {
                        0
                    } else {
                        map.get(p).copied().unwrap_or(0)
                    };
                    if let Some(slot) = stage.nodes.get_mut(w) {
                        *slot = node;
                    }
                    if let Some(f) = nk.get_mut(r) {
                        *f = true;
                    }
                    if let Some(m) = nm.get_mut(r) {
                        *m = w as u8;
                    }
                    w += 1;
                }
            }
            stage.nodes.truncate(w);
            keep = nk;
            map = nm;
        }
        // The front follows the newest stage (or the committed one).
        let mut w = 0usize;
        for r in 0..self.front.len() {
            if keep.get(r).copied().unwrap_or(false) {
                if let Some(st) = self.front.get(r).copied() {
                    if let Some(slot) = self.front.get_mut(w) {
                        *slot = st;
                    }
                    w += 1;
                }
            }
        }
        self.front.truncate(w);
        Some((frame, node))
    }
}

/// A node's appearance for the histogram cue from raw view data.
pub fn view_feat(pos: [f32; 2], area: u32, cdf: Option<Cdf>) -> ViewFeat {
    ViewFeat {
        pos,
        area: area as f32,
        cut: false,
        bbox: [pos[0], pos[1], pos[0], pos[1]],
        cut_sides: 0,
        cdf,
        axis: super::cost::NO_AXIS,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn st(cost: f32) -> NodeState {
        NodeState {
            cost,
            left: view_feat([0.0, 0.0], 1, None),
            right: None,
            vel: [0.0, 0.0],
            vel_known: false,
            depth: None,
            lost: 0,
        }
    }

    fn nd(obs: u16, pred: u8) -> Node {
        Node {
            obs,
            pair: obs,
            x: 0,
            y: 0,
            pred,
        }
    }

    #[test]
    fn commit_follows_best_path_and_prunes_the_rest() {
        let mut t: Trellis<3, 4> = Trellis::new();
        assert!(t.push(0, &[nd(0, 0)], &[st(0.0)]));
        assert!(t.push(1, &[nd(0, 0), nd(1, 0)], &[st(1.0), st(2.0)]));
        // Stage 2: node 0 from 1 (cost 5), node 1 from 0 (cost 3 → best).
        assert!(t.push(2, &[nd(4, 1), nd(5, 0)], &[st(5.0), st(3.0)]));
        assert!(!t.push(3, &[nd(0, 0)], &[st(0.0)]));
        assert_eq!(t.commit_oldest(), Some((0, nd(0, 0))));
        assert_eq!(t.len(), 2);
        // Committing stage 1 along best path (node 0 of stage 1, obs 0).
        assert_eq!(t.commit_oldest(), Some((1, nd(0, 0))));
        // Stage 2 keeps only the node whose predecessor was obs 0: obs 5.
        let s = t.stage(0).unwrap();
        assert_eq!(s.nodes.len(), 1);
        assert_eq!(s.nodes[0].obs, 5);
        assert_eq!(t.front.len(), 1);
        assert_eq!(t.front[0].cost, 3.0);
        // Commit the newest: front keeps its chosen node.
        assert_eq!(t.commit_oldest().map(|c| c.1.obs), Some(5));
        assert!(t.is_empty());
        assert_eq!(t.front.len(), 1);
        assert_eq!(t.commit_oldest(), None);
    }

    #[test]
    fn rounding_saturates() {
        assert_eq!(round_i16(1e9), i16::MAX);
        assert_eq!(round_i16(-1e9), i16::MIN);
        assert_eq!(round_i16(f32::NAN), 0);
        assert_eq!(round_i16(2.5), 3);
    }
}
