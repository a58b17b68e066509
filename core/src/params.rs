//! Every tunable of the pipeline, with the paper's Table I defaults.
//!
//! Pixel-valued parameters in the paper (θ_A^L, θ_A^U, M) refer to
//! 2048 × 2048 Cam-trawl frames. [`Params::for_frame`] scales them to other
//! frame sizes: areas by `(w / 2048)²`, lengths by `w / 2048` (w = frame
//! width), so a 512-pixel test haul keeps the same physical meaning.
//! Structuring-element sizes (7 px) are kept at the paper's values; they are
//! scaled too, to the nearest odd size ≥ 3, only below 1024-pixel frames.

use crate::error::ParamError;

/// Frame width the paper's pixel-valued parameters refer to.
pub const PAPER_FRAME_WIDTH: u32 = 2048;

/// Data-association method (paper Table V).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[serde(rename_all = "lowercase")]
pub enum Tracker {
    /// Matching cost + multi-target Viterbi data association (Section IV.C).
    #[default]
    Viterbi,
    /// Matching cost alone, greedy frame-to-frame (the paper's "MC").
    Mc,
    /// Nearest neighbour on predicted position (the paper's "NN").
    Nn,
}

/// All parameters of the pipeline. Field names are the keys of a
/// `--params` TOML file.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    // --- Automatic fish segmentation (Section III, Table I) ---
    /// p_low — shifting factor of the low threshold, eq. (1). Table I: 1.
    pub p_low: f32,
    /// p_high — shifting factor of the high threshold, eq. (1). Table I: 0.7.
    pub p_high: f32,
    /// θ_bp — threshold of the backprojected ratio histogram, eq. (3). Table I: 0.3.
    pub theta_bp: f32,
    /// θ_A^L — lower limit of object area in pixels, eq. (4). Table I: 2·10³ (2048² frame).
    pub area_min: u32,
    /// θ_A^U — upper limit of object area in pixels, eq. (4). Table I: 10⁶ (2048² frame).
    pub area_max: u32,
    /// θ_V — lower limit of an object's grey-level variance, eq. (6). Table I: 30.
    pub var_min: f32,
    /// Number of grey-level histogram bins for backprojection and EMD
    /// (Section III.B, VI.A: 16 is best).
    pub hist_bins: u8,
    /// Length of the diagonal line elements for trawl-mesh removal (Section V.A: 7).
    pub mesh_line_len: u8,
    /// Size of the disk structuring element (Section V.A: 7 × 7).
    pub disk_size: u8,
    /// Enlargement of the inscribed ellipse for the local region (Section III.A: 1.5).
    pub ellipse_scale: f32,
    /// Ablation switch: use both thresholds of eq. (1) (false: Otsu's τ alone).
    pub double_threshold: bool,
    /// Ablation switch: merge the two masks by histogram backprojection, eq. (2)–(3)
    /// (false: use M_high alone).
    pub backprojection: bool,
    /// Ablation switch: reject objects by variance, eq. (5)–(6).
    pub variance_rejection: bool,
    /// Downsampling factor of the coarse localisation pass (Section III.A,
    /// beyond the paper): the mesh-free frame is box-averaged `f × f`
    /// before the morphological gradient, which averages noise down so dim
    /// fish stand out, and the gradient is thresholded with hysteresis
    /// (`crate::segment::coarse`). 1 is the paper's full-resolution
    /// gradient with one global threshold; otherwise 4 to 16. Default 4.
    pub coarse_scale: u8,
    /// Rule of the variance test, eq. (6): `false` (default) compares the
    /// object's variance *in excess of the frame's measured noise
    /// variance* with θ_V scaled to that noise
    /// (`crate::segment::local`, beyond the paper); `true` is the paper's
    /// literal `σ_k² ≥ θ_V`.
    pub variance_literal: bool,
    /// Smallest elongation `√(λ₁/λ₂)` of an output object (beyond the
    /// paper; `crate::segment::local::elongated_enough`); 1 turns the test
    /// off. Default 2.
    pub min_elongation: f32,
    /// Smallest fill of an output object (beyond the paper;
    /// `crate::segment::local::solid_enough`): its pixels over the area
    /// `4π√(λ₁λ₂)` of its equivalent ellipse (1 for a filled ellipse,
    /// 3/π for a filled rectangle). A fish's mask is a solid body; a
    /// sparse net of strands — trawl mesh thicker than the line openings of
    /// Section V.A remove, which Otsu's split then thresholds in the mesh
    /// bands — fills a fraction of its ellipse. Applied to objects cut by
    /// the frame too (a fish's visible part is solid). 0 turns the test
    /// off. Default 0.4.
    pub min_fill: f32,
    /// Side of the box mean applied to a local region before its
    /// thresholds and masks (eq. (1)–(3)) are computed (beyond the paper;
    /// `crate::segment::local`): averaging `k × k` pixels divides the
    /// sensor noise σ by `k`, so a fish a few grey levels above the water
    /// thresholds as one body instead of salt-and-pepper. Object
    /// statistics (mean, variance, histogram) still use the unsmoothed
    /// pixels. Odd, 1 to 15; 1 is the paper (no smoothing). Default 1:
    /// 5 lowers the 2-D length error of large targets (8.13 → 7.64 % over
    /// seeds 1–8) but rounds the ends that the 3-D length and the tracker
    /// use (per-fish 3-D MAPE 2.8 → 3.9 %, README "Where FishTrack stands").
    pub local_smooth: u8,
    /// Whether the local regions are thresholded on the frame minus its
    /// smooth background (strobe glow, vignetting; beyond the paper,
    /// `crate::background`), in every region. Default on. (Until session
    /// 26 only regions whose coarse object was thinner than the opening
    /// square; measured on seeds 1–30, every region: segmentation recall
    /// 0.748 → 0.759, tracking success 582 → 591 of 899.)
    pub background: bool,
    /// Half-side `r` of the background's opening square, in 16-pixel
    /// cells: the square is `(2r + 1) · 16` pixels wide (176 px at the
    /// default 5 on a 2048-wide frame). 1 to 32.
    pub background_radius: u8,
    /// A component that fails the variance test of eq. (6) is kept when
    /// its mean stands this many water σ above the water (beyond the
    /// paper; `crate::segment::local::water_level`): a dim fish with
    /// little texture has a small variance but a clear contrast. 0 turns
    /// the rescue off.
    pub contrast_sigmas: f32,
    /// Smallest per-pixel noise σ, grey levels, that the variance limit
    /// of eq. (6) and the contrast rescue assume (beyond the paper;
    /// `crate::segment::local::variance_limit`): on a frame whose noise
    /// was smoothed away (defocus, the camera's denoising, compression)
    /// the measured σ falls far below what an 8-bit camera's water
    /// carries, and rules relative to it would take any smooth blob of a
    /// few grey levels — debris, glow, marine snow — for a fish. 0 turns
    /// the floor off.
    pub noise_floor: f32,
    /// Whether merged objects are split where the object's pixels, raised
    /// above a threshold between ⌊τ_low⌋ and their maximum, fall into
    /// stable elongated parts (beyond the paper; touching fish,
    /// `crate::segment::split`). Default off: it raises segmentation F1
    /// and lowers the 2-D length error on seeds 1–8 and 12–16, but a fish
    /// pair split in some frames and not in others costs the tracker
    /// (tracking success 0.564 → 0.551 on seeds 1–8, 0.582 → 0.560 on
    /// 12–16; README, "Where FishTrack stands").
    pub split_merged: bool,
    /// Whether a region whose thresholds found an object is thresholded a
    /// second time on the pixels its objects leave (beyond the paper;
    /// `crate::segment::local`, "the dim level"): Otsu's τ of a region
    /// holding a bright fish and a dim one falls between the two fish, and
    /// eq. (1)'s τ_low — the lower class's mean — above the dim one, so
    /// the dim fish beside a bright one is lost. The second pass sees the
    /// region without the first pass's objects grown by the disk's radius,
    /// and its objects pass the same tests. Default on.
    pub dim_level: bool,
    /// Where eq. (1)'s ⌊τ_high⌋ is at or below the region's water median,
    /// it is raised to this many water σ above it (beyond the paper;
    /// `crate::segment::local`, "the high floor"). On a fish a few σ above
    /// the water, Otsu's τ falls inside the water's noise and eq. (1) puts
    /// τ_low and τ_high both there: M_high then holds half the water, as
    /// M_low does, the ratio histogram of eq. (2) cannot tell fish from
    /// water, and the fish floods into a water-sized object that the
    /// contrast test rejects. Raised, M_high is the fish alone and the
    /// backprojection separates it. (Raising every τ_high below the floor,
    /// not only the collapsed ones, also cuts the dim tails off fish that
    /// eq. (1) measured well: per-frame 3-D length MAPE 3.05 % → 3.67 % on
    /// seeds 1–12.) 0 turns the floor off. Default 2.
    pub high_floor_sigmas: f32,
    /// Least edge step of a final object as a share of its contrast
    /// (beyond the paper; `crate::segment::local::edge_sharp_enough`): the
    /// mean grey-level step across the object's outline, two pixels in to
    /// two pixels out, against its mean's height above the water. A fish
    /// has a sharp outline (the step is most of its contrast); a glow of
    /// backscatter or strobe haze rises smoothly, so its thresholded
    /// outline sits on a slope. 0 turns the test off. Default 0.3.
    pub edge_step_ratio: f32,
    /// Objects of low contrast need a sharper outline (beyond the paper;
    /// `crate::segment::local::required_edge_ratio`): a final object whose
    /// contrast (its thresholded mean above the water's median) is under
    /// this many water σ must pass the edge test at
    /// `weak_edge_step_ratio` instead of `edge_step_ratio`. The top of a
    /// smooth debris blob or glow that Otsu splits off its region clears
    /// the contrast rescue (3 σ) and the edge test (0.3) by a hair
    /// (measured on seeds 1–12: debris objects at 2.8–3.1 σ with steps of
    /// 0.31–0.38 of their contrast), while fish that dim have steps of 0.4
    /// or more (35 of 36). 0 turns the rule off; it is part of the edge
    /// test, so `edge_step_ratio = 0` turns it off too. Default 3.5.
    pub weak_contrast_sigmas: f32,
    /// The edge test's ratio for the objects under `weak_contrast_sigmas`
    /// (never below `edge_step_ratio`). Default 0.4.
    pub weak_edge_step_ratio: f32,
    /// Mesh-residue test (beyond the paper;
    /// `crate::segment::local::mesh_residue`): a final object is refused
    /// when the grey levels the mesh removal (Section V.A) took from its
    /// pixels, on average, reach this many times its contrast (its
    /// thresholded mean above the water's median, as the edge test
    /// measures it). The openings leave a faint, blurred copy of the trawl
    /// mesh in the mesh-free frame, a few grey levels above the water; a
    /// sensitive coarse pass finds it, and its patches are solid, dim and
    /// sharp enough to pass every other test. Such a patch stood 4–6 grey
    /// levels above the water while the removal had taken 5–16 levels from
    /// its pixels (ratios 1.1–3.9, seeds 1–30); a fish hides the net behind
    /// it, so the removal takes only its texture's peaks and its noise
    /// (ratio under 0.7 for 99 % of 2 503 fish objects, the highest 1.13).
    /// 0 turns the test off; it has nothing to judge when `mesh_line_len`
    /// is under 3 (no removal). Default 1.
    pub mesh_residue_ratio: f32,
    /// Edge test: the inner and outer samples lie this many pixels in from
    /// the outline and beyond the first pixel out, so a step spans
    /// `2·edge_gap + 2` pixels. 2 at 2048 px wide, scaled with the frame
    /// width (at least 1): at 1024², with a fixed 2, a step spanned twice
    /// as much of a smooth glow, and debris glows passed (session 23).
    pub edge_gap: u8,

    /// Whether the right view is matched to the left's grey levels before
    /// the stereo pairing and the length are computed again on it, when
    /// the two cameras record the fish at different grey levels (beyond
    /// the paper; `crate::photometric`). Default on.
    pub photometric: bool,

    /// Whether a left object the object-height blocks left unpaired is
    /// looked for in the right image itself along its epipolar band (beyond
    /// the paper; `crate::epipolar`): depth and a right view for the
    /// tracker where the right view's segmentation missed or merged the
    /// fish. Its length is withheld. Default on.
    pub stereo_search: bool,

    // --- Multiple-fish tracking (Section IV.B–C, Table I) ---
    /// v_ref x component — reference motion vector, eq. (7). Table I: (−1, 0).
    pub v_ref_x: f32,
    /// v_ref y component.
    pub v_ref_y: f32,
    /// α — update rate of the target velocity, eq. (14). Table I: 0.3.
    pub alpha: f32,
    /// M — margin from the frame border for target entrance/exit, pixels. Table I: 100 (2048² frame).
    pub margin: u32,
    /// Data-association method.
    pub tracker: Tracker,

    // --- Fish length measurement (Section IV.D, Table I) ---
    /// θ_SAD — threshold of the SAD ratio for body-end mismatch, eq. (15). Table I: 16.
    pub theta_sad: f32,
    /// r — search range of the disparity refinement, pixels. Table I: 16.
    pub refine_range: u32,
    /// Block size of the dense disparity refinement (Section V.D: 8 × 8).
    pub refine_block: u8,
    /// Ablation switch: fish-tail end compensation (Section IV.D.1).
    pub tail_compensation: bool,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            p_low: 1.0,
            p_high: 0.7,
            theta_bp: 0.3,
            area_min: 2_000,
            area_max: 1_000_000,
            var_min: 30.0,
            hist_bins: 16,
            mesh_line_len: 7,
            disk_size: 7,
            ellipse_scale: 1.5,
            double_threshold: true,
            backprojection: true,
            variance_rejection: true,
            coarse_scale: 4,
            variance_literal: false,
            min_elongation: 2.0,
            min_fill: 0.4,
            local_smooth: 1,
            background: true,
            background_radius: 5,
            contrast_sigmas: 3.0,
            noise_floor: 1.25,
            split_merged: false,
            dim_level: true,
            high_floor_sigmas: 2.0,
            edge_step_ratio: 0.3,
            weak_contrast_sigmas: 3.5,
            weak_edge_step_ratio: 0.4,
            mesh_residue_ratio: 1.0,
            edge_gap: 2,
            photometric: true,
            stereo_search: true,
            v_ref_x: -1.0,
            v_ref_y: 0.0,
            alpha: 0.3,
            margin: 100,
            tracker: Tracker::Viterbi,
            theta_sad: 16.0,
            refine_range: 16,
            refine_block: 8,
            tail_compensation: true,
        }
    }
}

/// Nearest odd integer ≥ 3 to `v`.
fn odd_at_least_3(v: f32) -> u8 {
    let r = micromath::F32(v).round().0;
    let mut n = if r < 3.0 {
        3
    } else if r > 255.0 {
        255
    } else {
        r as u32
    };
    if n % 2 == 0 {
        n += 1;
    }
    n.min(255) as u8
}

impl Params {
    /// The Table I defaults scaled to a `width`-pixel-wide frame (see the
    /// module documentation for the rule).
    pub fn for_frame(width: u32) -> Params {
        Params::default().scaled_to(width)
    }

    /// These parameters, assumed to be given for a 2048-wide frame, scaled
    /// to a `width`-pixel-wide frame.
    pub fn scaled_to(mut self, width: u32) -> Params {
        if width == 0 || width == PAPER_FRAME_WIDTH {
            return self;
        }
        let s = width as f32 / PAPER_FRAME_WIDTH as f32;
        let s2 = s * s;
        self.area_min = ((self.area_min as f32 * s2) as u32).max(1);
        self.area_max = ((self.area_max as f32 * s2) as u32).max(self.area_min);
        self.margin = ((self.margin as f32 * s) as u32).max(1);
        self.background_radius = (libm::roundf(self.background_radius as f32 * s) as u8).max(1);
        self.edge_gap = (libm::roundf(self.edge_gap as f32 * s) as u8).max(1);
        if width < 1024 {
            self.mesh_line_len = odd_at_least_3(self.mesh_line_len as f32 * s * 2.0);
            self.disk_size = odd_at_least_3(self.disk_size as f32 * s * 2.0);
            if self.local_smooth > 1 {
                self.local_smooth = odd_at_least_3(self.local_smooth as f32 * s * 2.0);
            }
        }
        self
    }

    /// Checks every value against its allowed range; the error names the key.
    pub fn validate(&self) -> Result<(), ParamError> {
        fn finite(name: &'static str, v: f32) -> Result<(), ParamError> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(ParamError::NotFinite(name))
            }
        }
        fn range(name: &'static str, ok: bool, allowed: &'static str) -> Result<(), ParamError> {
            if ok {
                Ok(())
            } else {
                Err(ParamError::OutOfRange { name, allowed })
            }
        }
        for (n, v) in [
            ("p_low", self.p_low),
            ("p_high", self.p_high),
            ("theta_bp", self.theta_bp),
            ("var_min", self.var_min),
            ("ellipse_scale", self.ellipse_scale),
            ("min_elongation", self.min_elongation),
            ("min_fill", self.min_fill),
            ("contrast_sigmas", self.contrast_sigmas),
            ("noise_floor", self.noise_floor),
            ("high_floor_sigmas", self.high_floor_sigmas),
            ("edge_step_ratio", self.edge_step_ratio),
            ("weak_contrast_sigmas", self.weak_contrast_sigmas),
            ("weak_edge_step_ratio", self.weak_edge_step_ratio),
            ("mesh_residue_ratio", self.mesh_residue_ratio),
            ("v_ref_x", self.v_ref_x),
            ("v_ref_y", self.v_ref_y),
            ("alpha", self.alpha),
            ("theta_sad", self.theta_sad),
        ] {
            finite(n, v)?;
        }
        range("p_low", (0.0..=1.0).contains(&self.p_low), "0 ≤ p_low ≤ 1")?;
        range(
            "p_high",
            (0.0..=1.0).contains(&self.p_high),
            "0 ≤ p_high ≤ 1",
        )?;
        if self.p_high > self.p_low {
            return Err(ParamError::Inconsistent {
                name: "p_high",
                why: "p_high must not exceed p_low (τ_high ≥ τ_low)",
            });
        }
        range(
            "theta_bp",
            (0.0..1.0).contains(&self.theta_bp),
            "0 ≤ theta_bp < 1",
        )?;
        range("area_min", self.area_min >= 1, "area_min ≥ 1")?;
        if self.area_max < self.area_min {
            return Err(ParamError::Inconsistent {
                name: "area_max",
                why: "area_max must be ≥ area_min",
            });
        }
        range("var_min", self.var_min >= 0.0, "var_min ≥ 0")?;
        range(
            "hist_bins",
            matches!(self.hist_bins, 2 | 4 | 8 | 16 | 32 | 64 | 128),
            "a power of two, 2 to 128",
        )?;
        range(
            "mesh_line_len",
            self.mesh_line_len % 2 == 1 && (1..=31).contains(&self.mesh_line_len),
            "odd, 1 to 31",
        )?;
        range(
            "disk_size",
            self.disk_size % 2 == 1 && (1..=31).contains(&self.disk_size),
            "odd, 1 to 31",
        )?;
        range(
            "ellipse_scale",
            (1.0..=4.0).contains(&self.ellipse_scale),
            "1 ≤ ellipse_scale ≤ 4",
        )?;
        range(
            "local_smooth",
            self.local_smooth % 2 == 1 && (1..=15).contains(&self.local_smooth),
            "odd, 1 to 15",
        )?;
        range(
            "contrast_sigmas",
            (0.0..=100.0).contains(&self.contrast_sigmas),
            "0 to 100",
        )?;
        range(
            "noise_floor",
            (0.0..=50.0).contains(&self.noise_floor),
            "0 to 50 grey levels",
        )?;
        range(
            "high_floor_sigmas",
            (0.0..=100.0).contains(&self.high_floor_sigmas),
            "0 to 100",
        )?;
        range(
            "edge_step_ratio",
            (0.0..=1.0).contains(&self.edge_step_ratio),
            "0 to 1",
        )?;
        range(
            "weak_contrast_sigmas",
            (0.0..=100.0).contains(&self.weak_contrast_sigmas),
            "0 to 100",
        )?;
        range(
            "weak_edge_step_ratio",
            (0.0..=1.0).contains(&self.weak_edge_step_ratio),
            "0 to 1",
        )?;
        range(
            "mesh_residue_ratio",
            (0.0..=100.0).contains(&self.mesh_residue_ratio),
            "0 to 100",
        )?;
        range("edge_gap", (1..=16).contains(&self.edge_gap), "1 to 16")?;
        range(
            "background_radius",
            (1..=32).contains(&self.background_radius),
            "1 to 32",
        )?;
        range(
            "coarse_scale",
            self.coarse_scale == 1 || (4..=16).contains(&self.coarse_scale),
            "1, or 4 to 16",
        )?;
        range(
            "min_elongation",
            (0.0..=10.0).contains(&self.min_elongation),
            "0 ≤ min_elongation ≤ 10",
        )?;
        range(
            "min_fill",
            (0.0..=1.0).contains(&self.min_fill),
            "0 ≤ min_fill ≤ 1",
        )?;
        let vr = self.v_ref_x * self.v_ref_x + self.v_ref_y * self.v_ref_y;
        range("v_ref_x", vr > 1e-12, "v_ref must not be the zero vector")?;
        range("alpha", (0.0..=1.0).contains(&self.alpha), "0 ≤ alpha ≤ 1")?;
        range("margin", self.margin <= 4096, "0 ≤ margin ≤ 4096")?;
        range("theta_sad", self.theta_sad > 0.0, "theta_sad > 0")?;
        range(
            "refine_range",
            (1..=256).contains(&self.refine_range),
            "1 ≤ refine_range ≤ 256",
        )?;
        range(
            "refine_block",
            (2..=32).contains(&self.refine_block),
            "2 ≤ refine_block ≤ 32",
        )?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_table_one_and_valid() {
        let p = Params::default();
        assert_eq!((p.p_low, p.p_high, p.theta_bp), (1.0, 0.7, 0.3));
        assert_eq!(
            (p.area_min, p.area_max, p.var_min),
            (2_000, 1_000_000, 30.0)
        );
        assert_eq!(
            (p.v_ref_x, p.v_ref_y, p.alpha, p.margin),
            (-1.0, 0.0, 0.3, 100)
        );
        assert_eq!((p.theta_sad, p.refine_range), (16.0, 16));
        assert_eq!(p.validate(), Ok(()));
    }

    #[test]
    fn scaling_follows_frame_size() {
        let p = Params::for_frame(1024);
        assert_eq!(p.area_min, 500);
        assert_eq!(p.margin, 50);
        assert_eq!(p.disk_size, 7);
        let q = Params::for_frame(512);
        assert_eq!(q.area_min, 125);
        assert_eq!(q.margin, 25);
        assert_eq!(q.disk_size, 5); // 7 · (512/1024) = 3.5 → 4 → next odd 5
                                    // the edge test's gap: 2 px at 2048, 1 at 1024 and below, 4 at 4096
        assert_eq!(p.edge_gap, 1);
        assert_eq!(q.edge_gap, 1);
        assert_eq!(Params::for_frame(4096).edge_gap, 4);
        assert_eq!(Params::for_frame(3072).edge_gap, 3);
        assert_eq!(q.validate(), Ok(()));
        assert_eq!(Params::for_frame(2048), Params::default());
    }

    #[test]
    fn validate_names_the_key() {
        let mut p = Params {
            alpha: 1.5,
            ..Params::default()
        };
        assert_eq!(p.validate().unwrap_err().key(), "alpha");
        p.alpha = f32::NAN;
        assert_eq!(p.validate().unwrap_err(), ParamError::NotFinite("alpha"));
        let p = Params {
            p_high: 1.0,
            p_low: 0.5,
            ..Params::default()
        };
        assert_eq!(p.validate().unwrap_err().key(), "p_high");
        let p = Params {
            hist_bins: 12,
            ..Params::default()
        };
        assert_eq!(p.validate().unwrap_err().key(), "hist_bins");
        let p = Params {
            area_max: 10,
            ..Params::default()
        };
        assert_eq!(p.validate().unwrap_err().key(), "area_max");
        let p = Params {
            disk_size: 6,
            ..Params::default()
        };
        assert_eq!(p.validate().unwrap_err().key(), "disk_size");
        for bad in [0u8, 2, 3, 17] {
            let p = Params {
                coarse_scale: bad,
                ..Params::default()
            };
            assert_eq!(p.validate().unwrap_err().key(), "coarse_scale");
        }
        let p = Params {
            min_elongation: f32::NAN,
            ..Params::default()
        };
        assert_eq!(p.validate().unwrap_err().key(), "min_elongation");
        for bad in [f32::NAN, -0.1, 1.5] {
            let p = Params {
                min_fill: bad,
                ..Params::default()
            };
            assert_eq!(p.validate().unwrap_err().key(), "min_fill");
        }
        assert!(Params {
            min_fill: 0.0,
            ..Params::default()
        }
        .validate()
        .is_ok());
        for bad in [f32::NAN, -0.1, 100.5] {
            let p = Params {
                mesh_residue_ratio: bad,
                ..Params::default()
            };
            assert_eq!(p.validate().unwrap_err().key(), "mesh_residue_ratio");
        }
    }
}
