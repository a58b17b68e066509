//! Diagnostic dump (development aid): per segmented object of every left
//! frame, its raw box and features, as CSV on stdout (`gt`, `gtl`: the
//! coarse pass's seed and low hysteresis thresholds).
//! `seg_diag [--no-var] [--literal] [--regions] [--noise-floor F] HAUL...` (`--regions`: also
//! one `R,…` row per local region: raw-left centre, semi-axes, angle, τ).
use anyhow::Result;
use fishtrack::detect::{detection_rows, load_calibration};
use fishtrack::haul::Haul;
use fishtrack::rectify::Rectifier;
use fishtrack_core::image::ImageView;
use fishtrack_core::object::Objects;
use fishtrack_core::params::Params;
use fishtrack_core::segment::{segment_frame_traced, workspace_size, RECOMMENDED_MAX_ROI_PIXELS};

fn main() -> Result<()> {
    let mut no_var = false;
    let mut literal = false;
    let mut regions = false;
    let mut hauls = vec![];
    let mut noise_floor = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--noise-floor" => noise_floor = args.next().and_then(|v| v.parse::<f32>().ok()),
            "--no-var" => no_var = true,
            "--literal" => literal = true,
            "--regions" => regions = true,
            _ => hauls.push(a),
        }
    }
    println!("haul,frame,x,y,w,h,len,area,mean,var,hw,hh,gt,noise16,vlim,gtl");
    for hp in hauls {
        let haul = Haul::open(std::path::Path::new(&hp))?;
        let calib = load_calibration(&haul)?;
        // the default rectification (the canvas): its own frame size
        let rect = Rectifier::new(&calib);
        let (w, h) = (rect.size().0 as usize, rect.size().1 as usize);
        let mut p = Params::for_frame(calib.width);
        p.variance_rejection = !no_var;
        p.variance_literal = literal;
        if let Some(f) = noise_floor {
            p.noise_floor = f;
        }
        let mut ws = vec![0u8; workspace_size(w, h, RECOMMENDED_MAX_ROI_PIXELS)];
        let mut objs: Box<Objects<64, 16384>> = Box::default();
        for pair in &haul.frames {
            let (left, _) = haul.load_pair(pair, Some((calib.width, calib.height)))?;
            let rl = rect.rectify_left(&left)?;
            let view = ImageView::packed(rl.as_raw(), w, h).map_err(|e| anyhow::anyhow!("{e}"))?;
            let mut traces = Vec::new();
            let st = segment_frame_traced(view, &p, &mut ws, &mut objs, &mut |t| traces.push(*t))
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            if regions {
                for t in &traces {
                    let r = &t.region;
                    let (x, y) = rect.left.rect_to_raw(r.cx as f64, r.cy as f64);
                    println!(
                        "R,{hp},{},{x:.1},{y:.1},{:.1},{:.1},{:.3},{},{},{}",
                        pair.index, r.a, r.b, r.angle, t.tau, t.t_low, t.t_high
                    );
                }
            }
            let rows = detection_rows(pair.index, &objs, &rect.left);
            for (r, o) in rows.iter().zip(objs.items.iter()) {
                println!(
                    "{},{},{:.1},{:.1},{:.1},{:.1},{:.1},{},{:.2},{:.2},{:.1},{:.1},{},{},{:.2},{}",
                    hp,
                    pair.index,
                    r.bbox[0],
                    r.bbox[1],
                    r.bbox[2],
                    r.bbox[3],
                    r.length_px.unwrap_or(-1.0),
                    o.area,
                    o.mean,
                    o.variance,
                    o.obb.half_w,
                    o.obb.half_h,
                    st.gradient_threshold,
                    st.noise_sigma16,
                    st.var_limit,
                    st.gradient_threshold_low
                );
            }
        }
    }
    Ok(())
}
