//! `fishtrack compare HAUL`: the no-heap core against the float reference
//! on the haul's rectified frames (DESIGN.md, "Float reference"):
//! segmentation of both views ([`crate::reference::compare`]: thresholds
//! within 1 grey level, identical object sets, mask IoU ≥ 0.99), stereo
//! pairs and lengths ([`crate::reference::stereo::compare`] on the core's
//! objects: identical pairs, usable lengths within 0.5 % and the same ones
//! withheld, withheld lengths within 0.5 % too), and track assignments
//! ([`crate::reference::track`] on the observations the pipeline built:
//! identical). Prints an agreement table; any disagreement is an error
//! (exit 1).

use std::path::Path;

use anyhow::Result;

use fishtrack_core::epipolar::SEARCHED_LEVEL;
use fishtrack_core::length::wholly_inside_valid;
use fishtrack_core::pipeline::{DefaultPipeline, PipelineEvent};

use crate::reference::compare::compare_segmentation;
use crate::reference::photometric as rp;
use crate::reference::stereo::{self as rs, Geometry, Gray, Limits};
use crate::reference::track::{self as rt, Assignment, Capacities};
use crate::track_cmd::{new_pipeline, prepare, views, TrackOptions};

/// A stereo pair (left, right object index) and its length, if any.
type PairLength<T> = (usize, usize, Option<T>);

#[derive(Default)]
struct Tally {
    frames: usize,
    pass: usize,
    worst: f64,
    first_fail: Option<String>,
}

impl Tally {
    fn add(&mut self, ok: bool, value: f64, what: impl FnOnce() -> String) {
        self.frames += 1;
        self.worst = self.worst.max(value);
        if ok {
            self.pass += 1;
        } else if self.first_fail.is_none() {
            self.first_fail = Some(what());
        }
    }

    fn ok(&self) -> bool {
        self.pass == self.frames
    }
}

/// Runs the comparison on `dir`, rectified with `rect_alpha` and tracked at
/// frame rate `fps` (as `fishtrack track --rect-alpha … --fps …`; the
/// defaults when `None`), and prints the table; errors when any criterion
/// fails.
pub fn run(
    dir: &Path,
    rect_alpha: Option<crate::rectify::Scaling>,
    fps: Option<f64>,
) -> Result<()> {
    let opts = TrackOptions {
        rect_alpha,
        fps,
        ..TrackOptions::default()
    };
    let setup = prepare(dir, &opts)?;
    let mut pipe = new_pipeline(&setup)?;
    let cfg = setup.pipeline_config();
    let mut ws =
        vec![0u8; DefaultPipeline::workspace_size(setup.width as usize, setup.height as usize)];
    let geom = Geometry::from_core(&setup.geometry);
    let limits = Limits::from(&cfg.pairing);
    let (mut seg, mut pairs, mut lengths) = (Tally::default(), Tally::default(), Tally::default());
    let mut disparities = Tally::default();
    let mut raw_lengths = Tally::default();
    let mut all_obs = Vec::new();
    let mut photo_pool = rp::Pool::default();
    let mut photo_rig = (1.0f64, 0.0f64);
    let mut core_asg: Vec<Assignment> = Vec::new();
    let on_event = |e: &PipelineEvent, out: &mut Vec<Assignment>| {
        if let PipelineEvent::TrackFrame {
            track, frame, obs, ..
        } = *e
        {
            out.push(Assignment { frame, track, obs });
        }
    };
    for pair in &setup.haul.frames {
        let (l, r) = setup.rectified(pair)?;
        for (side, img) in [("left", &l), ("right", &r)] {
            let (a, _) = compare_segmentation(img, &setup.params).map_err(|e| {
                anyhow::anyhow!(
                    "frame {} ({side}): core segmentation failed: {e}",
                    pair.index
                )
            })?;
            let worst = 1.0 - a.min_iou;
            seg.add(a.passes(), worst, || {
                format!(
                    "frame {} {side}: core {} / reference {} objects, {} matched, min IoU {:.4}, τ diff {}, length diff {:.4}",
                    pair.index, a.core_objects, a.ref_objects, a.matched, a.min_iou, a.max_tau_diff, a.max_length_rel_diff
                )
            });
        }
        let (lv, rv) = views(&l, &r)?;
        pipe.process_frame(pair.index, lv, rv, &mut ws, &mut |e| {
            on_event(e, &mut core_asg)
        })
        .map_err(|e| anyhow::anyhow!("frame {}: pipeline: {e}", pair.index))?;
        all_obs.push(pipe.observations().to_vec());
        // stereo on the core's objects
        let lo = rs::ref_objects(pipe.left_objects());
        // the segmented right objects only: the search below finds its own
        let mut ro = rs::ref_objects(pipe.right_objects());
        ro.truncate(
            pipe.right_objects()
                .items
                .iter()
                .filter(|o| o.level != SEARCHED_LEVEL)
                .count(),
        );
        let (w, h) = (l.width() as usize, l.height() as usize);
        let lg = Gray {
            data: l.as_raw(),
            w,
            h,
        };
        let rg = Gray {
            data: r.as_raw(),
            w,
            h,
        };
        let mut ref_pairs = rs::pair(&lg, &rg, &lo, &ro, &geom, &limits);
        // the photometric match (core: `photometric`), then pairs again on
        // the mapped right view
        let mapped;
        let mut rg = rg;
        if setup.params.photometric {
            let q = photo_pool.add_levels(&lg, &rg);
            photo_pool.add_frame(&lg, &rg, &lo, &ref_pairs, q);
            if let Some(m) = photo_pool.map() {
                photo_rig = m;
            }
            let photo_map = (photo_rig.0 * q, photo_rig.1);
            if !rp::is_identity(photo_map) {
                mapped = rp::apply(&rg, photo_map);
                rg = Gray {
                    data: &mapped,
                    w,
                    h,
                };
                ref_pairs = rs::pair(&lg, &rg, &lo, &ro, &geom, &limits);
            }
        }
        if setup.params.stereo_search {
            crate::reference::epipolar::search_unpaired(
                &lg,
                &rg,
                &lo,
                &mut ro,
                &mut ref_pairs,
                &geom,
                &limits,
            );
        }
        let reference_raw: Vec<PairLength<rs::RefLength>> = ref_pairs
            .iter()
            .map(|p| {
                // lengths are measured for pairs wholly inside both views
                // only (the core's right objects, searched ones included,
                // have the reference's indices wherever the pair sets agree,
                // which `pairs` below checks)
                let inside = match (
                    pipe.left_objects().items.get(p.left),
                    pipe.right_objects().items.get(p.right),
                ) {
                    (Some(a), Some(b)) => {
                        wholly_inside_valid(&a.bbox, &b.bbox, &cfg.valid, cfg.inside_margin)
                    }
                    _ => false,
                };
                let len = inside
                    .then(|| rs::length(&lg, &rg, &lo, &ro, p, &geom, &setup.params, &cfg.length))
                    .flatten();
                (p.left, p.right, len)
            })
            .collect();
        // only usable lengths: both sides must withhold the same ones
        let reference: Vec<PairLength<f64>> = reference_raw
            .iter()
            .map(|&(a, b, l)| (a, b, l.filter(|v| v.consistent).map(|v| v.length)))
            .collect();
        let core_raw: Vec<PairLength<(f64, bool)>> = pipe
            .pairs()
            .pairs
            .iter()
            .zip(pipe.lengths())
            .map(|(p, l)| {
                (
                    p.left as usize,
                    p.right as usize,
                    l.map(|v| (v.length_mm as f64, v.consistent)),
                )
            })
            .collect();
        let core: Vec<PairLength<f64>> = core_raw
            .iter()
            .map(|&(a, b, l)| (a, b, l.filter(|v| v.1).map(|v| v.0)))
            .collect();
        let a = rs::compare(&core, &reference);
        // the withheld lengths as well: the same end points and snakes
        // must give the same figure even where the gates then drop it
        let core_withheld: Vec<PairLength<f64>> = core_raw
            .iter()
            .map(|&(a, b, l)| (a, b, l.filter(|v| !v.1).map(|v| v.0)))
            .collect();
        let reference_withheld: Vec<PairLength<f64>> = reference_raw
            .iter()
            .map(|&(a, b, l)| (a, b, l.filter(|v| !v.consistent).map(|v| v.length)))
            .collect();
        let ra = rs::compare(&core_withheld, &reference_withheld);
        raw_lengths.add(
            ra.measured_by_one == 0 && ra.max_length_rel_diff <= 0.005,
            ra.max_length_rel_diff,
            || {
                format!(
                    "frame {}: largest withheld-length difference {:.3} %, {} pairs withheld by one side only",
                    pair.index,
                    100.0 * ra.max_length_rel_diff,
                    ra.measured_by_one
                )
            },
        );
        // the coarse disparity d_o of every pair both sides made (the
        // tracker's depth cue): the same candidate, to the core's integer
        // shift
        let mut worst_d = 0.0f64;
        let mut first_d = None;
        for p in pipe.pairs().pairs.iter() {
            let Some(q) = ref_pairs
                .iter()
                .find(|q| q.left == p.left as usize && q.right == p.right as usize)
            else {
                continue;
            };
            let diff = (p.d_o as f64 - q.d_o).abs();
            if diff > worst_d {
                worst_d = diff;
                first_d = Some((p.left, p.right, p.d_o, q.d_o));
            }
        }
        disparities.add(worst_d <= 1.0, worst_d, || {
            let (l, r, c, q) = first_d.unwrap_or_default();
            format!(
                "frame {}: pair ({l}, {r}) d_o core {c}, reference {q}",
                pair.index
            )
        });
        pairs.add(a.pairs_identical, 0.0, || {
            format!(
                "frame {}: core pairs {:?}, reference pairs {:?}",
                pair.index,
                core.iter().map(|c| (c.0, c.1)).collect::<Vec<_>>(),
                reference.iter().map(|c| (c.0, c.1)).collect::<Vec<_>>()
            )
        });
        lengths.add(
            a.measured_by_one == 0 && a.max_length_rel_diff <= 0.005,
            a.max_length_rel_diff,
            || {
                format!(
                    "frame {}: largest length difference {:.3} %, {} pairs measured by one side only",
                    pair.index,
                    100.0 * a.max_length_rel_diff,
                    a.measured_by_one
                )
            },
        );
    }
    pipe.finish(&mut |e| on_event(e, &mut core_asg));
    // the reference numbers frames by slice index from 0; the haul from 1
    let ref_asg: Vec<Assignment> =
        rt::run(&all_obs, &setup.params, &cfg.track, Capacities::DEFAULT)
            .into_iter()
            .map(|a| Assignment {
                frame: a.frame + 1,
                ..a
            })
            .collect();
    let ta = rt::compare(&core_asg, &ref_asg);

    crate::outln!(
        "fishtrack compare: {} ({} frame pairs), core vs float reference",
        setup.haul.dir.display(),
        setup.haul.frames.len()
    )?;
    crate::outln!(
        "{:<52} {:>12} {:>10}  result",
        "criterion",
        "frames ok",
        "worst"
    )?;
    let line = |name: &str, t: &Tally, worst: String| -> Result<()> {
        crate::outln!(
            "{:<52} {:>12} {:>10}  {}",
            name,
            format!("{}/{}", t.pass, t.frames),
            worst,
            if t.ok() { "agree" } else { "DISAGREE" }
        )
    };
    line(
        "segmentation (τ ±1, same objects, IoU ≥ 0.99)",
        &seg,
        format!("{:.4}", 1.0 - seg.worst),
    )?;
    line("stereo pairs identical", &pairs, "-".into())?;
    line(
        "coarse disparities d_o within 1 px",
        &disparities,
        format!("{worst_d:.1} px", worst_d = disparities.worst),
    )?;
    line(
        "stereo lengths within 0.5 %",
        &lengths,
        format!("{:.3} %", 100.0 * lengths.worst),
    )?;
    line(
        "withheld stereo lengths within 0.5 %",
        &raw_lengths,
        format!("{:.3} %", 100.0 * raw_lengths.worst),
    )?;
    crate::outln!(
        "{:<52} {:>12} {:>10}  {}",
        "track assignments identical",
        format!("{}/{}", ta.same, ta.same + ta.differing),
        ta.differing,
        if ta.identical() { "agree" } else { "DISAGREE" }
    )?;
    let mut failed = Vec::new();
    for (name, t) in [
        ("segmentation", &seg),
        ("stereo pairs", &pairs),
        ("coarse disparities", &disparities),
        ("stereo lengths", &lengths),
        ("withheld stereo lengths", &raw_lengths),
    ] {
        if let Some(f) = &t.first_fail {
            crate::outln!("first {name} disagreement: {f}")?;
            failed.push(name);
        }
    }
    if !ta.identical() {
        crate::outln!(
            "track assignments only in the core: {:?}; only in the reference: {:?}",
            ta.only_a,
            ta.only_b
        )?;
        failed.push("track assignments");
    }
    if failed.is_empty() {
        crate::outln!("core and reference agree")?;
        Ok(())
    } else {
        anyhow::bail!("core and reference disagree: {}", failed.join(", "))
    }
}
