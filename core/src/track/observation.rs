//! What tracking consumes: one stereo-matched object of one frame
//! (Section IV.C: "a pair of stereo-matched objects … as one observation").
//!
//! Kept deliberately small and independent of the segmentation and stereo
//! types: the pipeline fills it from the stereo stage's output. Coordinates
//! are rectified pixels, so left and right centroids share a row.

use crate::image::Roi;
use crate::object::HIST_BINS;

/// One camera's view of an observation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CameraView {
    /// Centroid x, rectified pixels.
    pub cx: f32,
    /// Centroid y, rectified pixels.
    pub cy: f32,
    /// Upright bounding box, rectified pixels.
    pub bbox: Roi,
    /// A(O): mask area in pixels.
    pub area: u32,
    /// 16-bin grey-level histogram of the mask (raw counts; normalised by
    /// the matching cost).
    pub hist: [u32; HIST_BINS],
    /// Angle of the mask's first principal axis from +x, radians (y down;
    /// the oriented box's, Section III).
    pub angle: f32,
    /// Elongation of the oriented box, half length over half height
    /// (`w_o / h_o`); 0 when unknown.
    pub elongation: f32,
}

impl CameraView {
    /// True when the centroid is a finite number within ±10⁶ pixels.
    pub fn is_valid(&self) -> bool {
        let ok = |v: f32| v.is_finite() && v > -1.0e6 && v < 1.0e6;
        ok(self.cx) && ok(self.cy)
    }
}

/// A stereo observation of one frame: the left object, its stereo partner in
/// the right view (if stereo pairing found one), and its depth.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Observation {
    /// The left camera's object.
    pub left: CameraView,
    /// The right camera's object; `None` for an unpaired left object (its
    /// matching cost then counts the left camera twice, see `cost`).
    pub right: Option<CameraView>,
    /// Depth z of the object from stereo triangulation, mm; `None` if unknown.
    pub depth_mm: Option<f32>,
    /// Index of the stereo pair (or object) this observation was built from,
    /// handed back in track events.
    pub pair: u16,
}

impl Observation {
    /// True when every coordinate the tracker uses is a finite number. Invalid
    /// observations are skipped (and counted) by the tracker.
    pub fn is_valid(&self) -> bool {
        self.left.is_valid() && self.right.as_ref().is_none_or(CameraView::is_valid)
    }

    /// Depth if it is a usable positive finite number.
    pub fn depth(&self) -> Option<f32> {
        match self.depth_mm {
            Some(z) if z.is_finite() && z > 0.0 && z < 1.0e7 => Some(z),
            _ => None,
        }
    }
}
