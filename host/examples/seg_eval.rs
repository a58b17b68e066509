//! Segmentation-only evaluation (issue 4, paper Section V.A and Fig. 13):
//! segments every left frame of each haul ([`fishtrack::detect`]), writes
//! `OUT/<haul>/detections.csv` and prints segmentation precision/recall and
//! the single-camera length MAPE of large targets, per haul and pooled.
//!
//! ```text
//! cargo run --release -p fishtrack --example seg_eval -- [--single] [--no-bp]
//!     [--no-var] [--bins N] [--paper] [--literal-var]
//!     [--full-res-coarse] [--var-min X] [--elong X] [--smooth K]
//!     [--alpha A|auto|canvas] [--split | --no-split] [--no-dim]
//!     [--params FILE] [--out DIR] HAUL...
//!
//! `--paper` runs the paper's Section III alone (full-resolution coarse
//! gradient with one global threshold, literal θ_V, no elongation test, no
//! local smoothing, no border exemption of the elongation test).
//! `--split` / `--no-split` turn the split of merged objects
//! (`Params::split_merged`, `fishtrack_core::segment::split`) on / off.
//! `--no-dim` turns off the dim level (`Params::dim_level`).
//! `--params FILE` starts from a `fishtrack track --params` TOML file's
//! parameters (its `[track]` table is ignored); the flags apply on top,
//! and `double_threshold`, `backprojection`, `variance_rejection` and
//! `variance_literal` always come from the flags.
//! ```

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use fishtrack::detect::detect_haul_scaling;
use fishtrack::eval::evaluate;
use fishtrack::rectify::Scaling;
use fishtrack_core::params::Params;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let (mut single, mut no_bp, mut no_var, mut bins) = (false, false, false, None);
    let (mut paper, mut literal, mut scale1) = (false, false, false);
    let (mut var_min, mut elong): (Option<f32>, Option<f32>) = (None, None);
    let mut smooth: Option<u8> = None;
    let mut no_bg = false;
    let mut no_dim = false;
    let mut split: Option<bool> = None;
    let mut bg_r: Option<u8> = None;
    let mut csig: Option<f32> = None;
    let mut out = std::env::temp_dir().join("seg_eval");
    let mut hauls = Vec::new();
    let mut alpha = Scaling::default();
    let mut params_file: Option<PathBuf> = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--single" => single = true,
            "--no-bp" => no_bp = true,
            "--no-var" => no_var = true,
            "--paper" => paper = true,
            "--no-bg" => no_bg = true,
            "--no-dim" => no_dim = true,
            "--no-split" => split = Some(false),
            "--split" => split = Some(true),
            "--contrast" => csig = Some(args.next().context("--contrast K")?.parse()?),
            "--bg-r" => bg_r = Some(args.next().context("--bg-r N")?.parse()?),
            "--literal-var" => literal = true,
            "--full-res-coarse" => scale1 = true,
            "--var-min" => var_min = Some(args.next().context("--var-min X")?.parse()?),
            "--smooth" => smooth = Some(args.next().context("--smooth K")?.parse()?),
            "--elong" => elong = Some(args.next().context("--elong X")?.parse()?),
            "--bins" => bins = Some(args.next().context("--bins N")?.parse::<u8>()?),
            "--alpha" => {
                alpha = fishtrack::track_cmd::parse_scaling(&args.next().context("--alpha A")?)?
            }
            "--out" => out = PathBuf::from(args.next().context("--out DIR")?),
            "--params" => params_file = Some(PathBuf::from(args.next().context("--params FILE")?)),
            s if s.starts_with("--") => bail!("unknown option {s}"),
            _ => hauls.push(PathBuf::from(a)),
        }
    }
    if hauls.is_empty() {
        bail!("usage: seg_eval [--single] [--no-bp] [--no-var] [--bins N] [--out DIR] HAUL...");
    }
    let (mut tp, mut fp, mut fn_) = (0u64, 0u64, 0u64);
    let (mut ape_sum, mut n_len, mut n_meas) = (0.0f64, 0u64, 0u64);
    println!("haul                     frames  objects  precision  recall  large-MAPE  measured");
    for haul in &hauls {
        let truth = fishtrack::truth::Truth::load(&haul.join("truth.json"))?;
        let mut p = match &params_file {
            Some(f) => fishtrack::params_file::load_params(f, truth.width)?.params,
            None => Params::for_frame(truth.width),
        };
        p.double_threshold = !single;
        p.backprojection = !no_bp;
        p.variance_rejection = !no_var;
        if let Some(b) = bins {
            p.hist_bins = b;
        }
        if let Some(c) = csig {
            p.contrast_sigmas = c;
        }
        if no_bg {
            p.background = false;
        }
        if no_dim {
            p.dim_level = false;
        }
        if let Some(s) = split {
            p.split_merged = s;
        }
        if paper {
            // the paper's pipeline: no step beyond Section III
            (literal, scale1) = (true, true);
            p.min_elongation = 1.0;
            p.local_smooth = 1;
            p.background = false;
            p.contrast_sigmas = 0.0;
            p.split_merged = false;
            p.dim_level = false;
            p.high_floor_sigmas = 0.0;
            p.edge_step_ratio = 0.0;
            p.min_fill = 0.0;
            p.mesh_residue_ratio = 0.0;
        }
        if let Some(r) = bg_r {
            p.background_radius = r;
        }
        if let Some(k) = smooth {
            p.local_smooth = k;
        }
        p.variance_literal = literal;
        if scale1 {
            p.coarse_scale = 1;
        }
        if let Some(v) = var_min {
            p.var_min = v;
        }
        if let Some(e) = elong {
            p.min_elongation = e;
        }
        let name = haul
            .file_name()
            .map_or("haul".into(), |n| n.to_string_lossy().into_owned());
        let od = out.join(&name);
        let sum = detect_haul_scaling(haul, &p, alpha, &od)?;
        let rep = evaluate(haul, &od)?;
        let seg = rep.segmentation.context("no segmentation score")?;
        let d = &seg.detection;
        tp += d.tp;
        fp += d.fp;
        fn_ += d.fn_;
        let (mape, meas) = match &seg.large_target_length {
            Some(l) => {
                ape_sum += l.mape * l.measured as f64;
                n_len += l.measured;
                n_meas += l.measurable;
                (l.mape, format!("{}/{}", l.measured, l.measurable))
            }
            None => (f64::NAN, "-".into()),
        };
        println!(
            "{:<24} {:>6} {:>8} {:>10.4} {:>7.4} {:>10.2}% {:>9}",
            name,
            sum.frames,
            sum.objects,
            d.precision,
            d.recall,
            100.0 * mape,
            meas
        );
    }
    let prec = tp as f64 / (tp + fp).max(1) as f64;
    let rec = tp as f64 / (tp + fn_).max(1) as f64;
    println!(
        "{:<24} {:>6} {:>8} {:>10.4} {:>7.4} {:>10.2}% {:>9}",
        "ALL",
        "",
        "",
        prec,
        rec,
        100.0 * ape_sum / n_len.max(1) as f64,
        format!("{n_len}/{n_meas}")
    );
    Ok(())
}
