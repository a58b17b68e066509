//! The border of a raw camera view on the rectified frame (our addition to
//! Section IV.C.2's border rules): where a fish enters, leaves or is cut.
//!
//! A rectification keeps every raw pixel only on a canvas larger than the
//! raw frame (the host's `stereo_rectify_canvas`); the raw view's border is
//! then the image of the raw frame's four edges under undistortion and the
//! rectifying rotation — four curves, each monotone along its side, that
//! bow in or out by up to a few hundred pixels. A rectangle cannot follow
//! them: a fish cut by a curve where it bows in has a box far from the
//! rectangle's side, so the tracker would take its part view for the whole
//! fish. [`ViewOutline`] holds each side as a polyline of [`OUTLINE_POINTS`]
//! samples; a rectangle is the outline with constant sides, and every test
//! here then reduces exactly to the rectangle's.
//!
//! Memory: 4 × (2 + [`OUTLINE_POINTS`]) `f32` per view (304 bytes).

use crate::image::Roi;

use super::cost;

/// Samples per side of a [`ViewOutline`].
pub const OUTLINE_POINTS: usize = 17;

/// One side of the border: the coordinate across the side (y for the top
/// and bottom, x for the left and right) at [`OUTLINE_POINTS`] evenly
/// spaced positions along it, from `from` to `to`; linear between samples,
/// constant beyond the ends.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Side {
    /// Position along the side of the first sample.
    pub from: f32,
    /// Position along the side of the last sample (`≥ from`).
    pub to: f32,
    /// The border's coordinate across the side at each sample.
    pub at: [f32; OUTLINE_POINTS],
}

impl Side {
    /// A straight side at `across`, spanning `from..=to`.
    pub const fn straight(from: f32, to: f32, across: f32) -> Side {
        Side {
            from,
            to,
            at: [across; OUTLINE_POINTS],
        }
    }

    /// The border's coordinate at position `t` along the side.
    pub fn value(&self, t: f32) -> f32 {
        let span = self.to - self.from;
        if span.is_nan() || span <= 0.0 {
            return self.at[0];
        }
        let u = ((t - self.from) / span).clamp(0.0, 1.0) * (OUTLINE_POINTS - 1) as f32;
        if u.is_nan() {
            return self.at[0];
        }
        let i = (u as usize).min(OUTLINE_POINTS - 2);
        let f = u - i as f32;
        let (a, b) = (self.at[i], self.at[i + 1]);
        if f <= 0.0 {
            a
        } else {
            a + f * (b - a)
        }
    }

    /// The greatest (`max`) or least coordinate of the border over the
    /// positions `a..=b` along the side (samples inside and both ends).
    fn extreme(&self, a: f32, b: f32, max: bool) -> f32 {
        let pick = |x: f32, y: f32| if max { x.max(y) } else { x.min(y) };
        let mut v = pick(self.value(a), self.value(b));
        let step = (self.to - self.from) / (OUTLINE_POINTS - 1) as f32;
        for (i, &s) in self.at.iter().enumerate() {
            let t = self.from + step * i as f32;
            if t > a && t < b {
                v = pick(v, s);
            }
        }
        v
    }
}

/// A raw view's border on the rectified frame (see the module docs):
/// inside is below `top`, above `bottom`, right of `left`, left of `right`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ViewOutline {
    /// Top side: y along x.
    pub top: Side,
    /// Bottom side: y (the first row below the view) along x.
    pub bottom: Side,
    /// Left side: x along y.
    pub left: Side,
    /// Right side: x (the first column right of the view) along y.
    pub right: Side,
}

impl ViewOutline {
    /// The outline of a rectangle.
    pub fn rect(r: &Roi) -> ViewOutline {
        let (x0, y0) = (r.x as f32, r.y as f32);
        let (x1, y1) = (r.right() as f32, r.bottom() as f32);
        ViewOutline {
            top: Side::straight(x0, x1, y0),
            bottom: Side::straight(x0, x1, y1),
            left: Side::straight(y0, y1, x0),
            right: Side::straight(y0, y1, x1),
        }
    }

    /// The sides of box `b` within `k` pixels of the border or beyond it
    /// ([`cost::CUT_X_MIN`], …): where the border may cut it. A box's left
    /// side is cut when it reaches the left border anywhere along the
    /// box's rows, and so on; for a rectangle, `b.x ≤ x0 + k`, ….
    pub fn cut_sides(&self, b: &Roi, k: u32) -> u8 {
        let k = k as f32;
        let (x0, y0) = (b.x as f32, b.y as f32);
        let (x1, y1) = (b.right() as f32, b.bottom() as f32);
        let mut s = 0;
        if x0 <= self.left.extreme(y0, y1, true) + k {
            s |= cost::CUT_X_MIN;
        }
        if x1 + k >= self.right.extreme(y0, y1, false) {
            s |= cost::CUT_X_MAX;
        }
        if y0 <= self.top.extreme(x0, x1, true) + k {
            s |= cost::CUT_Y_MIN;
        }
        if y1 + k >= self.bottom.extreme(x0, x1, false) {
            s |= cost::CUT_Y_MAX;
        }
        s
    }

    /// True when point `p` lies at least `m` pixels inside the border (for
    /// a rectangle, `x0 + m ≤ x < x1 − m` and the same in y).
    pub fn holds(&self, p: [f32; 2], m: f32) -> bool {
        let [x, y] = p;
        x >= self.left.value(y) + m
            && x < self.right.value(y) - m
            && y >= self.top.value(x) + m
            && y < self.bottom.value(x) - m
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The rectangle tests as written before outlines existed.
    fn rect_cut(b: &Roi, v: &Roi, k: u32) -> u8 {
        let mut s = 0;
        if b.x <= v.x + k {
            s |= cost::CUT_X_MIN;
        }
        if b.right() + k >= v.right() {
            s |= cost::CUT_X_MAX;
        }
        if b.y <= v.y + k {
            s |= cost::CUT_Y_MIN;
        }
        if b.bottom() + k >= v.bottom() {
            s |= cost::CUT_Y_MAX;
        }
        s
    }

    proptest! {
        /// A rectangle's outline cuts and holds exactly as the rectangle.
        #[test]
        fn a_rectangle_is_its_outline(
            (vx, vy, vw, vh) in (0u32..500, 0u32..500, 1u32..3000, 1u32..3000),
            (bx, by, bw, bh) in (0u32..4000, 0u32..4000, 0u32..900, 0u32..900),
            k in 0u32..120,
            (px, py) in (-100.0f32..4000.0, -100.0f32..4000.0),
            m in 0.0f32..150.0,
        ) {
            let v = Roi::new(vx, vy, vw, vh);
            let b = Roi::new(bx, by, bw, bh);
            let o = ViewOutline::rect(&v);
            prop_assert_eq!(o.cut_sides(&b, k), rect_cut(&b, &v, k));
            let inside = px >= vx as f32 + m
                && px < v.right() as f32 - m
                && py >= vy as f32 + m
                && py < v.bottom() as f32 - m;
            prop_assert_eq!(o.holds([px, py], m), inside);
        }
    }

    /// A view whose left border bows in by 100 px at mid-height (as a raw
    /// edge does on a canvas).
    fn bowed() -> ViewOutline {
        let mut o = ViewOutline::rect(&Roi::new(0, 0, 2000, 2000));
        for (i, a) in o.left.at.iter_mut().enumerate() {
            let t = i as f32 / (OUTLINE_POINTS - 1) as f32;
            *a = 400.0 * t * (1.0 - t); // 0 at the corners, 100 mid-height
        }
        o
    }

    #[test]
    fn a_bowed_border_cuts_where_it_bows() {
        let o = bowed();
        // mid-height, starting at x = 90: the border is at 100 there
        let mid = Roi::new(90, 950, 300, 100);
        assert_ne!(o.cut_sides(&mid, 2) & cost::CUT_X_MIN, 0);
        // the same box as a rectangle view would see no cut
        assert_eq!(
            ViewOutline::rect(&Roi::new(0, 0, 2000, 2000)).cut_sides(&mid, 2),
            0
        );
        // near a corner the border is at x ≈ 0: x = 90 is inside
        let corner = Roi::new(90, 20, 300, 60);
        assert_eq!(o.cut_sides(&corner, 2) & cost::CUT_X_MIN, 0);
        // a box spanning the bow meets the border at its deepest point
        let tall = Roi::new(60, 100, 300, 1800);
        assert_ne!(o.cut_sides(&tall, 2) & cost::CUT_X_MIN, 0);
        // holds: at mid-height x = 150 is 50 px inside, x = 250 150 px
        assert!(!o.holds([150.0, 1000.0], 100.0));
        assert!(o.holds([250.0, 1000.0], 100.0));
        // and 60 px below the top is within the margin of 100
        assert!(!o.holds([250.0, 60.0], 100.0));
        assert_eq!(o.left.value(1000.0), 100.0);
        assert_eq!(o.left.value(-50.0), 0.0);
    }

    #[test]
    fn degenerate_sides_never_panic() {
        let mut o = bowed();
        o.top = Side::straight(5.0, 5.0, 10.0);
        o.left.to = f32::NAN;
        let b = Roi::new(0, 0, 10, 10);
        let _ = o.cut_sides(&b, 2);
        let _ = o.holds([f32::NAN, 3.0], 1.0);
        assert_eq!(o.top.value(100.0), 10.0);
    }
}
