//! `OUT/length_frequency.svg` and `.png`: the length-frequency histogram of
//! the counted fish (paper Fig. 12 style), drawn with `plotters`.
//!
//! Bars: the counted fish with a length (`fish.csv`'s `length_mm`). When the
//! haul has a `truth.json`, the true lengths of the fish a tracker is meant
//! to count (those countable in at least one frame: visible left area
//! ≥ θ_A^L, the rule `fishtrack eval` uses) are overlaid as red outlined
//! bars. Bin width is a "nice" step (10, 20, 25, 50, 100 … mm) giving about
//! 15–30 bins over the range of both sets. Both files are written
//! atomically; their bytes depend only on the lengths (no dates), so reruns
//! are identical.

use std::sync::OnceLock;

use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::output::write_atomic;
use crate::overlay::FONT_BYTES;

/// Picture size, pixels.
pub const SIZE: (u32, u32) = (900, 560);

/// One histogram: `counts[i]` values in `[start + i·width, start + (i+1)·width)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// Left edge of the first bin, mm.
    pub start: f64,
    /// Bin width, mm.
    pub width: f64,
    /// Counts per bin.
    pub counts: Vec<u32>,
}

/// A bin width from 1, 2, 2.5, 5 × 10^k giving at most `max_bins` bins over `span`.
pub fn nice_width(span: f64, max_bins: usize) -> f64 {
    let raw = (span / max_bins.max(1) as f64).max(1e-9);
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|w| *w >= raw)
        .unwrap_or(10.0 * mag)
}

/// Histograms of `a` and `b` over shared bins (about 25 bins over both
/// ranges). Non-finite values are ignored.
pub fn shared_histograms(a: &[f64], b: &[f64]) -> (Histogram, Histogram) {
    let all: Vec<f64> = a
        .iter()
        .chain(b)
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo.is_finite() {
        (lo, hi)
    } else {
        (0.0, 1000.0)
    };
    let width = nice_width((hi - lo).max(10.0), 25);
    let start = (lo / width).floor() * width;
    let n = (((hi - start) / width).floor() as usize + 1).max(1);
    let hist = |v: &[f64]| {
        let mut counts = vec![0u32; n];
        for x in v.iter().filter(|x| x.is_finite()) {
            let i = (((x - start) / width).floor() as usize).min(n - 1);
            counts[i] += 1;
        }
        Histogram {
            start,
            width,
            counts,
        }
    };
    (hist(a), hist(b))
}

fn register_font() -> Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_BYTES).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the bundled plot font does not parse"))
    }
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    counted: &Histogram,
    truth: Option<&Histogram>,
    title: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    root.fill(&WHITE)?;
    let end = counted.start + counted.width * counted.counts.len() as f64;
    let ymax = counted
        .counts
        .iter()
        .chain(truth.map(|t| t.counts.as_slice()).unwrap_or(&[]))
        .copied()
        .max()
        .unwrap_or(0)
        .max(1);
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(56)
        .build_cartesian_2d(counted.start..end, 0u32..(ymax + 1 + ymax / 8))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_desc("length (mm)")
        .y_desc("number of fish")
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .x_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    let bar = |h: &Histogram, i: usize| {
        let x0 = h.start + h.width * i as f64;
        [(x0, 0u32), (x0 + h.width, h.counts[i])]
    };
    let blue = RGBColor(31, 119, 180);
    let n_counted: u32 = counted.counts.iter().sum();
    chart
        .draw_series(
            (0..counted.counts.len())
                .filter(|&i| counted.counts[i] > 0)
                .map(|i| Rectangle::new(bar(counted, i), blue.mix(0.75).filled())),
        )?
        .label(format!("FishTrack, counted fish ({n_counted})"))
        .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], blue.filled()));
    if let Some(t) = truth {
        let red = RGBColor(214, 39, 40);
        let n_truth: u32 = t.counts.iter().sum();
        chart
            .draw_series(
                (0..t.counts.len())
                    .filter(|&i| t.counts[i] > 0)
                    .map(|i| Rectangle::new(bar(t, i), red.stroke_width(2))),
            )?
            .label(format!("truth, countable fish ({n_truth})"))
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 6), (x + 14, y + 6)], red.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", 15))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The SVG text and the RGB pixels of the plot.
pub fn render(
    counted: &[f64],
    truth: Option<&[f64]>,
    title: &str,
) -> Result<(String, image::RgbImage)> {
    register_font()?;
    let (ch, th) = shared_histograms(counted, truth.unwrap_or(&[]));
    let th = truth.map(|_| th);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        draw(&root, &ch, th.as_ref(), title).map_err(|e| anyhow!("SVG plot: {e}"))?;
    }
    let (w, h) = SIZE;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        draw(&root, &ch, th.as_ref(), title).map_err(|e| anyhow!("PNG plot: {e}"))?;
    }
    let png = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow!("PNG plot buffer"))?;
    Ok((svg, png))
}

/// Writes `stem.svg` and `stem.png` (e.g. `OUT/length_frequency`).
pub fn write_length_frequency(
    stem: &std::path::Path,
    counted: &[f64],
    truth: Option<&[f64]>,
    title: &str,
) -> Result<()> {
    let (svg, png) = render(counted, truth, title)?;
    write_atomic(&stem.with_extension("svg"), |w| w.write_all(svg.as_bytes()))?;
    write_png(&stem.with_extension("png"), &png)
}

/// Lengths of the fish of `HAUL/truth.json` that a tracker is meant to
/// count (countable in at least one frame, as `fishtrack eval` decides);
/// `None` without a truth file. A truth file that does not read is
/// reported as a warning (it does not stop a tracking run) and skipped.
pub fn truth_countable_lengths(haul_dir: &std::path::Path) -> Option<Vec<f64>> {
    let path = haul_dir.join("truth.json");
    if !path.is_file() {
        return None;
    }
    let read = || -> Result<Vec<f64>, crate::error::InputError> {
        let truth = crate::truth::Truth::load(&path)?;
        let frames = crate::eval::truth_frames::TruthFrames::new(&truth)?;
        Ok(frames
            .countable_fish()
            .into_iter()
            .map(|k| truth.fish[k].length_mm)
            .collect())
    };
    read()
        .map_err(|e| log::warn!("{e}; the length-frequency plot shows no truth"))
        .ok()
}

/// `OUT/length_frequency.svg` and `.png` for a haul's counted `fish`, with
/// the truth overlaid when the haul has one.
pub fn write_haul_plot(
    haul_dir: &std::path::Path,
    out: &std::path::Path,
    fish: &[crate::output::FishOut],
) -> Result<()> {
    let counted: Vec<f64> = fish.iter().filter_map(|f| f.length_mm).collect();
    let title = format!(
        "Length frequency: {} ({} fish counted, {} measured)",
        crate::survey::short_name(haul_dir),
        fish.len(),
        counted.len()
    );
    write_length_frequency(
        &out.join("length_frequency"),
        &counted,
        truth_countable_lengths(haul_dir).as_deref(),
        &title,
    )
}

/// Writes an RGB picture as PNG, atomically.
pub fn write_png(path: &std::path::Path, img: &image::RgbImage) -> Result<()> {
    write_atomic(path, |w| {
        let enc = image::codecs::png::PngEncoder::new(w);
        image::ImageEncoder::write_image(
            enc,
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_widths() {
        assert_eq!(nice_width(500.0, 25), 20.0);
        assert_eq!(nice_width(600.0, 25), 25.0);
        assert_eq!(nice_width(1000.0, 25), 50.0);
        assert_eq!(nice_width(90.0, 25), 5.0);
    }

    #[test]
    fn histograms_share_bins_and_count_every_value() {
        let a = [212.0, 219.9, 220.0, 480.0, f64::NAN];
        let b = [205.0, 700.0];
        let (ha, hb) = shared_histograms(&a, &b);
        assert_eq!((ha.start, ha.width), (hb.start, hb.width));
        assert_eq!(ha.width, 20.0); // span 495 mm → 20 mm bins
        assert_eq!(ha.start, 200.0);
        assert_eq!(ha.counts.iter().sum::<u32>(), 4);
        assert_eq!(hb.counts.iter().sum::<u32>(), 2);
        assert_eq!(ha.counts[0], 2); // 212, 219.9
        assert_eq!(ha.counts[1], 1); // 220
        assert_eq!(*hb.counts.last().unwrap(), 1); // 700 in the last bin
        assert_eq!(ha.counts.len(), 26);
    }

    #[test]
    fn plot_has_bars_labels_and_is_deterministic() {
        let counted = [300.0, 310.0, 320.0, 450.0];
        let truth = [305.0, 315.0, 455.0, 600.0, 610.0];
        let (svg, png) = render(&counted, Some(&truth), "haul 1").unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..40]);
        assert!(svg.contains("length (mm)") && svg.contains("truth, countable fish (5)"));
        assert!(svg.contains("counted fish (4)"));
        // blue bars and red outlines in the bitmap
        let has = |c: [u8; 3]| png.pixels().any(|p| p.0 == c);
        assert!(has([214, 39, 40]));
        assert!(
            png.pixels()
                .filter(|p| p.0[2] > 150 && p.0[0] < 120)
                .count()
                > 500
        );
        let (svg2, png2) = render(&counted, Some(&truth), "haul 1").unwrap();
        assert_eq!(svg, svg2);
        assert_eq!(png, png2);
        // no truth: no red
        let (_, png3) = render(&counted, None, "haul 1").unwrap();
        assert!(!png3.pixels().any(|p| p.0 == [214, 39, 40]));
    }
}
