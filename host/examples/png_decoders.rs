//! Decodes every PNG of a haul with `image`'s PNG decoder and with
//! `zune-png`, checks the pixels are identical and prints the median
//! decode time per frame of each (issue 8: pick the decoder by measurement).
//!
//! `png_decoders HAUL [--repeats K]`

use std::time::Instant;

use anyhow::{bail, Context, Result};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let haul = std::path::PathBuf::from(args.first().context("usage: png_decoders HAUL")?);
    let repeats: usize = args
        .iter()
        .position(|a| a == "--repeats")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let mut files = Vec::new();
    for side in ["left", "right"] {
        for e in std::fs::read_dir(haul.join(side))? {
            let p = e?.path();
            if p.extension().is_some_and(|x| x == "png") {
                files.push(p);
            }
        }
    }
    files.sort();
    let bytes: Vec<Vec<u8>> = files.iter().map(std::fs::read).collect::<Result<_, _>>()?;
    let (mut t_image, mut t_zune) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        for (f, b) in files.iter().zip(&bytes) {
            let t = Instant::now();
            let a = image::load_from_memory_with_format(b, image::ImageFormat::Png)?.into_luma8();
            t_image.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let mut d = zune_png::PngDecoder::new(zune_core::bytestream::ZCursor::new(&b[..]));
            let z = d
                .decode_raw()
                .map_err(|e| anyhow::anyhow!("{}: {e:?}", f.display()))?;
            t_zune.push(t.elapsed().as_secs_f64());
            if a.as_raw() != &z {
                bail!("{}: the decoders disagree", f.display());
            }
        }
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(|a, b| a.total_cmp(b));
        v[v.len() / 2] * 1e3
    };
    println!(
        "{} frames x {repeats}: image png {:.2} ms/frame, zune-png {:.2} ms/frame (median), pixels identical",
        files.len(),
        med(&mut t_image),
        med(&mut t_zune)
    );
    Ok(())
}
