//! The smooth background of a frame (core: `fishtrack_core::background`),
//! in plain `f64` from its definition: 16 × 16 cell means, a grey opening
//! by a `(2r + 1)²` square of cells, a 3 × 3 mean, bilinear interpolation
//! between cell centres. Values are kept in sixteenths of a grey level and
//! rounded half up at the same steps as the core, so the two agree
//! exactly (every interpolation weight is a multiple of 1/32).

use image::GrayImage;

/// Cell side, pixels (core: `background::BLOCK`).
pub const BLOCK: u32 = 16;
/// Level of flat water after subtraction (core: `background::OFFSET`).
pub const OFFSET: f64 = 32.0;

/// The background grid of one frame.
pub struct Background {
    cells: Vec<f64>,
    bw: usize,
    bh: usize,
}

fn half_up(v: f64) -> f64 {
    (v + 0.5).floor()
}

impl Background {
    /// Estimates the background of `img` with an opening of half-side `r` cells.
    pub fn estimate(img: &GrayImage, r: usize) -> Background {
        let (w, h) = img.dimensions();
        let bw = w.div_ceil(BLOCK) as usize;
        let bh = h.div_ceil(BLOCK) as usize;
        let mut mean = vec![0.0; bw * bh];
        for (i, m) in mean.iter_mut().enumerate() {
            let (cx, cy) = ((i % bw) as u32 * BLOCK, (i / bw) as u32 * BLOCK);
            let (mut s, mut n) = (0.0, 0.0);
            for y in cy..(cy + BLOCK).min(h) {
                for x in cx..(cx + BLOCK).min(w) {
                    s += img.get_pixel(x, y).0[0] as f64;
                    n += 1.0;
                }
            }
            *m = half_up(16.0 * s / n);
        }
        // the grey opening: the minimum over each cell's square, then the
        // maximum of those minima over the square
        let window = |src: &[f64], x: usize, y: usize, rad: usize, max: bool| {
            let mut v = if max { f64::MIN } else { f64::MAX };
            for yy in y.saturating_sub(rad)..=(y + rad).min(bh - 1) {
                for xx in x.saturating_sub(rad)..=(x + rad).min(bw - 1) {
                    let p = src[yy * bw + xx];
                    v = if max { v.max(p) } else { v.min(p) };
                }
            }
            v
        };
        let eroded: Vec<f64> = (0..bw * bh)
            .map(|i| window(&mean, i % bw, i / bw, r, false))
            .collect();
        let opened: Vec<f64> = (0..bw * bh)
            .map(|i| window(&eroded, i % bw, i / bw, r, true))
            .collect();
        let cells = (0..bw * bh)
            .map(|i| {
                let (x, y) = (i % bw, i / bw);
                let (mut s, mut n) = (0.0, 0.0);
                for yy in y.saturating_sub(1)..=(y + 1).min(bh - 1) {
                    for xx in x.saturating_sub(1)..=(x + 1).min(bw - 1) {
                        s += opened[yy * bw + xx];
                        n += 1.0;
                    }
                }
                half_up(s / n)
            })
            .collect();
        Background { cells, bw, bh }
    }

    /// Lower cell, upper cell and the fraction between them of pixel
    /// coordinate `p` on an axis of `n` cells (centres at `16 k + 7.5`).
    fn axis(p: u32, n: usize) -> (usize, usize, f64) {
        let t = (p as f64 - 7.5) / BLOCK as f64;
        if t <= 0.0 || n < 2 {
            return (0, 0, 0.0);
        }
        let c0 = t.floor() as usize;
        if c0 + 1 >= n {
            return (n - 1, n - 1, 0.0);
        }
        (c0, c0 + 1, t - c0 as f64)
    }

    /// The background at pixel `(x, y)`, whole grey levels.
    pub fn at(&self, x: u32, y: u32) -> f64 {
        let (x0, x1, fx) = Self::axis(x, self.bw);
        let (y0, y1, fy) = Self::axis(y, self.bh);
        let c = |cx: usize, cy: usize| self.cells[cy * self.bw + cx];
        let v = c(x0, y0) * (1.0 - fx) * (1.0 - fy)
            + c(x1, y0) * fx * (1.0 - fy)
            + c(x0, y1) * (1.0 - fx) * fy
            + c(x1, y1) * fx * fy;
        half_up(half_up(v) / 16.0)
    }

    /// `clamp(p − background + OFFSET, 0, 255)` at pixel `(x, y)`.
    pub fn subtract(&self, p: u8, x: u32, y: u32) -> u8 {
        (p as f64 - self.at(x, y) + OFFSET).clamp(0.0, 255.0) as u8
    }
}
