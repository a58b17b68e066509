//! Core vs reference agreement for segmentation (`fishtrack compare`):
//! per-region Otsu thresholds within 1 grey level, every object matched
//! one-to-one with mask IoU ≥ 0.99, oriented-box lengths within 0.5 %.

use super::segment::{segment, RefResult};
use fishtrack_core::segment::{segment_frame_traced, workspace_size, RegionTrace, SegmentStats};
use fishtrack_core::{ImageView, Objects, Params};
use image::GrayImage;
use std::collections::HashSet;

/// Objects per frame the comparison's core run holds.
pub const CMP_OBJECTS: usize = 256;
/// Mask runs per frame the comparison's core run holds.
pub const CMP_RUNS: usize = 1 << 16;

/// Agreement figures for one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SegAgreement {
    /// Objects found by the core.
    pub core_objects: usize,
    /// Objects found by the reference.
    pub ref_objects: usize,
    /// Objects matched one-to-one (greedy by IoU, IoU > 0.5).
    pub matched: usize,
    /// Smallest IoU over matched pairs (1 when none).
    pub min_iou: f64,
    /// Largest relative difference of the oriented-box length (2·half_w)
    /// over matched pairs.
    pub max_length_rel_diff: f64,
    /// Regions (with thresholds) matched by centre.
    pub regions_matched: usize,
    /// Largest |τ_core − τ_ref| over the regions that produced the
    /// reference's objects (the per-object Otsu thresholds).
    pub max_tau_diff: u8,
    /// Largest |τ_core − τ_ref| over all matched regions, with or without
    /// objects (information: in tiny noise-only regions Otsu's criterion has
    /// near-ties that the two float formulations break differently).
    pub max_tau_diff_all_regions: u8,
    /// Largest |⌊τ_low⌋ or ⌊τ_high⌋ core − reference| over matched regions.
    pub max_shift_diff: u8,
    /// The core's counters.
    pub core_stats: SegmentStats,
}

impl SegAgreement {
    /// The DESIGN.md criteria: thresholds within 1 grey level, identical
    /// object sets, every mask IoU ≥ 0.99.
    pub fn passes(&self) -> bool {
        self.core_objects == self.ref_objects
            && self.matched == self.core_objects
            && self.min_iou >= 0.99
            && self.max_tau_diff <= 1
            && self.max_length_rel_diff <= 0.005
    }
}

/// Core objects as pixel sets.
pub fn core_masks<const N: usize, const R: usize>(
    objs: &Objects<N, R>,
) -> Vec<HashSet<(u32, u32)>> {
    objs.items
        .iter()
        .map(|o| {
            objs.runs_of(o)
                .iter()
                .flat_map(|r| (r.x0..r.x1).map(move |x| (x as u32, r.y as u32)))
                .collect()
        })
        .collect()
}

fn iou(a: &HashSet<(u32, u32)>, b: &HashSet<(u32, u32)>) -> f64 {
    let i = a.intersection(b).count() as f64;
    let u = (a.len() + b.len()) as f64 - i;
    if u == 0.0 {
        1.0
    } else {
        i / u
    }
}

/// Runs the core and the reference on `img` and measures their agreement.
/// Fails only if the core rejects the frame or the parameters.
pub fn compare_segmentation(
    img: &GrayImage,
    params: &Params,
) -> Result<(SegAgreement, RefResult), fishtrack_core::segment::SegmentError> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut ws = vec![0u8; workspace_size(w, h, w * h)];
    let mut out: Box<Objects<CMP_OBJECTS, CMP_RUNS>> = Box::default();
    let mut traces: Vec<RegionTrace> = Vec::new();
    let view = ImageView::packed(img.as_raw(), w, h)
        .map_err(fishtrack_core::segment::SegmentError::Image)?;
    let stats = segment_frame_traced(view, params, &mut ws, &mut out, &mut |t| traces.push(*t))?;
    let reference = segment(img, params);
    let cm = core_masks(&out);
    let rm: Vec<&HashSet<(u32, u32)>> = reference.objects.iter().map(|o| &o.pixels).collect();
    // greedy one-to-one matching by IoU
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, a) in cm.iter().enumerate() {
        for (j, b) in rm.iter().enumerate() {
            let v = iou(a, b);
            if v > 0.5 {
                pairs.push((v, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut ui, mut uj) = (HashSet::new(), HashSet::new());
    let mut min_iou: f64 = 1.0;
    let mut max_len: f64 = 0.0;
    for (v, i, j) in pairs {
        if ui.contains(&i) || uj.contains(&j) {
            continue;
        }
        ui.insert(i);
        uj.insert(j);
        min_iou = min_iou.min(v);
        let lc = 2.0 * out.items[i].obb.half_w as f64;
        let lr = 2.0 * reference.objects[j].obb.2;
        max_len = max_len.max((lc - lr).abs() / lr.max(1e-9));
    }
    // regions: match by centre (same coarse component ⇒ same centroid) and
    // level
    let core_region = |r: &super::segment::RefRegion| -> Option<&RegionTrace> {
        traces
            .iter()
            .filter(|t| t.level == r.level)
            .map(|t| {
                let d = ((r.cx - t.region.cx as f64).powi(2) + (r.cy - t.region.cy as f64).powi(2))
                    .sqrt();
                (d, t)
            })
            .filter(|(d, _)| *d < 0.5)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, t)| t)
    };
    let (mut rmatched, mut max_tau_all, mut max_shift) = (0usize, 0u8, 0u8);
    for r in reference.regions.iter() {
        let (Some(tau), Some(t)) = (r.tau, core_region(r)) else {
            continue;
        };
        rmatched += 1;
        max_tau_all = max_tau_all.max(tau.abs_diff(t.tau));
        max_shift = max_shift
            .max((r.t_low.floor() as u8).abs_diff(t.t_low))
            .max((r.t_high.floor() as u8).abs_diff(t.t_high));
    }
    let mut max_tau = 0u8;
    for o in &reference.objects {
        let r = &reference.regions[o.region];
        match (r.tau, core_region(r)) {
            (Some(tau), Some(t)) => max_tau = max_tau.max(tau.abs_diff(t.tau)),
            _ => max_tau = u8::MAX, // the core has no such region
        }
    }
    Ok((
        SegAgreement {
            core_objects: cm.len(),
            ref_objects: rm.len(),
            matched: ui.len(),
            min_iou,
            max_length_rel_diff: max_len,
            regions_matched: rmatched,
            max_tau_diff: max_tau,
            max_tau_diff_all_regions: max_tau_all,
            max_shift_diff: max_shift,
            core_stats: stats,
        },
        reference,
    ))
}
