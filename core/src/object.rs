//! Segmented objects: what segmentation (Section III) hands to stereo
//! pairing (Section IV.A) and tracking (Section IV.B).
//!
//! Masks are stored as horizontal runs in one shared, fixed-capacity pool
//! per frame ([`Objects::runs`]), so an object costs a few dozen bytes plus
//! its runs. Memory bound: `N · size_of::<Object>() + R · size_of::<Run>()`.

use crate::image::Roi;

/// Number of grey-level bins of an object's histogram (Section III.B, IV.B.4).
pub const HIST_BINS: usize = 16;

/// One horizontal run of mask pixels: row `y`, columns `[x0, x1)`, in the
/// coordinates of the (rectified) frame the object was segmented in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Run {
    /// Row.
    pub y: u16,
    /// First column.
    pub x0: u16,
    /// One past the last column.
    pub x1: u16,
}

impl Run {
    /// Number of pixels in the run.
    pub const fn len(&self) -> u32 {
        self.x1.saturating_sub(self.x0) as u32
    }

    /// True when the run holds no pixel.
    pub const fn is_empty(&self) -> bool {
        self.x1 <= self.x0
    }
}

/// Oriented bounding box from the PCA of the object mask (Section III, Fig. 3):
/// the width is measured along the first principal axis.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OrientedBox {
    /// Centre x, pixels.
    pub cx: f32,
    /// Centre y, pixels.
    pub cy: f32,
    /// Half of the extent along the first principal axis (the box width w_o / 2).
    pub half_w: f32,
    /// Half of the extent along the second principal axis (the box height h_o / 2).
    pub half_h: f32,
    /// Angle of the first principal axis from the +x axis, radians, y pointing down,
    /// in `(-π/2, π/2]`.
    pub angle: f32,
}

/// Index range of an object's runs in [`Objects::runs`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RunSpan {
    /// First run.
    pub start: u32,
    /// Number of runs.
    pub len: u32,
}

/// One segmented object.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Object {
    /// Upright bounding box (Fig. 3, red).
    pub bbox: Roi,
    /// Oriented bounding box (Fig. 3, green).
    pub obb: OrientedBox,
    /// A(O_k): number of mask pixels.
    pub area: u32,
    /// Mean grey level of the mask pixels, Ī_k.
    pub mean: f32,
    /// σ_k², eq. (5): unbiased grey-level variance of the mask pixels.
    pub variance: f32,
    /// 16-bin grey-level histogram of the mask pixels (bin = value >> 4).
    pub hist: [u32; HIST_BINS],
    /// The object's mask runs in the frame's run pool.
    pub runs: RunSpan,
    /// The thresholding level that found it: 0 the region's own (Section
    /// III), 1 the dim level on what level 0 left (`Params::dim_level`).
    pub level: u8,
}

/// The objects of one frame (one camera), with their masks.
///
/// `N`: maximum objects; `R`: maximum mask runs over all objects.
#[derive(Debug, Clone)]
pub struct Objects<const N: usize, const R: usize> {
    /// The objects, in no particular order.
    pub items: heapless::Vec<Object, N>,
    /// Shared pool of mask runs; each object's [`RunSpan`] points into it.
    pub runs: heapless::Vec<Run, R>,
    /// Objects dropped because `N` or `R` was exceeded (the smallest go first).
    pub dropped: u32,
}

impl<const N: usize, const R: usize> Default for Objects<N, R> {
    fn default() -> Self {
        Objects {
            items: heapless::Vec::new(),
            runs: heapless::Vec::new(),
            dropped: 0,
        }
    }
}

impl<const N: usize, const R: usize> Objects<N, R> {
    /// An empty set.
    pub const fn new() -> Self {
        Objects {
            items: heapless::Vec::new(),
            runs: heapless::Vec::new(),
            dropped: 0,
        }
    }

    /// Removes every object and run, and zeroes the drop counter.
    pub fn clear(&mut self) {
        self.items.clear();
        self.runs.clear();
        self.dropped = 0;
    }

    /// The mask runs of `obj` (empty if its span is not in the pool).
    pub fn runs_of(&self, obj: &Object) -> &[Run] {
        let s = obj.runs.start as usize;
        let e = s.saturating_add(obj.runs.len as usize);
        self.runs.get(s..e).unwrap_or(&[])
    }
}
