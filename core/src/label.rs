//! Connected components, 8-connectivity (OpenCV's default for
//! `connectedComponentsWithStats`), with statistics accumulated while
//! scanning (the OpenMV model): area, upright box and the sums for the
//! centroid and second moments, from which PCA gives the oriented box
//! (Section III, Fig. 3).
//!
//! Two labelers:
//! - [`label_components`] labels a whole (ROI-sized) mask into a caller's
//!   `i32` label buffer with a pixel-indexed union-find whose parent links
//!   always point to an earlier pixel, so one raster pass resolves every
//!   label. Labels are numbered 1, 2, … in raster order of each component's
//!   first pixel (as OpenCV numbers them); a `keep(area)` predicate can drop
//!   components before they are numbered (eq. (4)). Never runs out of
//!   capacity: the label buffer is the union-find.
//! - [`StreamLabeler`] labels a frame row by row without a label image:
//!   only the runs of the previous and the current row are kept, with one
//!   table slot per live label; a component is reported with its
//!   [`Moments`] as soon as a row does not continue it. Memory bound:
//!   [`StreamLabeler::table_len`] slots for a `width`-pixel row.

/// Why labelling failed (only on caller buffers that are too small or a
/// frame too large for `i32` pixel indices).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LabelError {
    /// The label buffer is shorter than the mask, or the mask has more
    /// than `i32::MAX` pixels.
    BufferTooSmall,
    /// A [`StreamLabeler`] table is smaller than [`StreamLabeler::table_len`].
    TableTooSmall,
}

impl core::fmt::Display for LabelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LabelError::BufferTooSmall => write!(f, "labelling: label buffer too small"),
            LabelError::TableTooSmall => write!(f, "labelling: label table too small"),
        }
    }
}

impl core::error::Error for LabelError {}

/// Statistics of a set of pixels, accumulated exactly in integers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Moments {
    /// Number of pixels.
    pub area: u64,
    /// Σx.
    pub sx: u64,
    /// Σy.
    pub sy: u64,
    /// Σx².
    pub sxx: u64,
    /// Σy².
    pub syy: u64,
    /// Σxy.
    pub sxy: u64,
    /// Smallest x.
    pub x_min: u32,
    /// Smallest y.
    pub y_min: u32,
    /// Largest x.
    pub x_max: u32,
    /// Largest y.
    pub y_max: u32,
}

impl Default for Moments {
    fn default() -> Self {
        Moments::EMPTY
    }
}

/// Σ_{x=a}^{b−1} x and Σ x² for a run `[a, b)`.
#[inline]
fn run_sums(a: u64, b: u64) -> (u64, u64) {
    // Σx = (b(b−1) − a(a−1)) / 2; Σx² = (S2(b) − S2(a)), S2(n) = (n−1)n(2n−1)/6
    let s1 = |n: u64| n * n.saturating_sub(1) / 2;
    let s2 = |n: u64| {
        if n == 0 {
            0
        } else {
            (n - 1) * n * (2 * n - 1) / 6
        }
    };
    (s1(b) - s1(a), s2(b) - s2(a))
}

impl Moments {
    /// No pixels.
    pub const EMPTY: Moments = Moments {
        area: 0,
        sx: 0,
        sy: 0,
        sxx: 0,
        syy: 0,
        sxy: 0,
        x_min: u32::MAX,
        y_min: u32::MAX,
        x_max: 0,
        y_max: 0,
    };

    /// Adds the run of pixels `[x0, x1)` on row `y`.
    #[inline]
    pub fn add_run(&mut self, y: u32, x0: u32, x1: u32) {
        if x1 <= x0 {
            return;
        }
        let n = (x1 - x0) as u64;
        let (sx, sxx) = run_sums(x0 as u64, x1 as u64);
        let yy = y as u64;
        self.area += n;
        self.sx += sx;
        self.sy += n * yy;
        self.sxx += sxx;
        self.syy += n * yy * yy;
        self.sxy += sx * yy;
        self.x_min = self.x_min.min(x0);
        self.x_max = self.x_max.max(x1 - 1);
        self.y_min = self.y_min.min(y);
        self.y_max = self.y_max.max(y);
    }

    /// Adds another set of pixels (disjoint from this one).
    pub fn merge(&mut self, o: &Moments) {
        self.area += o.area;
        self.sx += o.sx;
        self.sy += o.sy;
        self.sxx += o.sxx;
        self.syy += o.syy;
        self.sxy += o.sxy;
        self.x_min = self.x_min.min(o.x_min);
        self.x_max = self.x_max.max(o.x_max);
        self.y_min = self.y_min.min(o.y_min);
        self.y_max = self.y_max.max(o.y_max);
    }

    /// Centroid `(x̄, ȳ)`; `(0, 0)` when empty.
    pub fn centroid(&self) -> (f32, f32) {
        if self.area == 0 {
            return (0.0, 0.0);
        }
        let n = self.area as f64;
        ((self.sx as f64 / n) as f32, (self.sy as f64 / n) as f32)
    }

    /// Population covariance `(c_xx, c_yy, c_xy)` of the pixel coordinates.
    pub fn covariance(&self) -> (f32, f32, f32) {
        if self.area == 0 {
            return (0.0, 0.0, 0.0);
        }
        let n = self.area as f64;
        let (mx, my) = (self.sx as f64 / n, self.sy as f64 / n);
        let cxx = (self.sxx as f64 / n - mx * mx).max(0.0);
        let cyy = (self.syy as f64 / n - my * my).max(0.0);
        let cxy = self.sxy as f64 / n - mx * my;
        (cxx as f32, cyy as f32, cxy as f32)
    }

    /// PCA of the covariance: `(angle, λ₁, λ₂)`, the first principal axis'
    /// angle from +x (y down) in `(−π/2, π/2]` and the eigenvalues
    /// `λ₁ ≥ λ₂ ≥ 0`. f32 through `libm` (explicit calls, identical on device
    /// and host; `micromath`'s sqrt is a few-percent approximation).
    pub fn principal_axes(&self) -> (f32, f32, f32) {
        let (a, b, c) = self.covariance();
        principal_axes_of(a, b, c)
    }
}

/// PCA of a covariance `(c_xx, c_yy, c_xy)`: `(angle, λ₁, λ₂)` as
/// [`Moments::principal_axes`].
pub fn principal_axes_of(a: f32, b: f32, c: f32) -> (f32, f32, f32) {
    {
        let half_tr = 0.5 * (a + b);
        let d = libm::sqrtf(0.25 * (a - b) * (a - b) + c * c);
        let l1 = half_tr + d;
        let l2 = (half_tr - d).max(0.0);
        let mut angle = 0.5 * libm::atan2f(2.0 * c, a - b);
        if angle <= -core::f32::consts::FRAC_PI_2 {
            angle += core::f32::consts::PI;
        }
        (angle, l1, l2)
    }
}

// ------------------------------------------------------------------------
// Whole-mask labelling (pixel-indexed union-find)
// ------------------------------------------------------------------------

/// Encoding of the label buffer during [`label_components`]:
/// 0 = background, `v > 0` = parent pixel index `v − 1` (always an earlier
/// pixel), `v < 0` = root of a tree holding `−v` pixels.
#[inline]
fn find_root(labels: &mut [i32], mut i: usize) -> Option<usize> {
    loop {
        let v = *labels.get(i)?;
        if v < 0 {
            return Some(i);
        }
        if v == 0 {
            return None;
        }
        let p = (v - 1) as usize;
        let pv = *labels.get(p)?;
        if pv < 0 {
            return Some(p);
        }
        if pv == 0 || (pv - 1) as usize >= p {
            return None; // corrupt (cannot happen): stop rather than loop
        }
        // path halving: parent ← grandparent (still an earlier pixel)
        labels[i] = pv;
        i = (pv - 1) as usize;
    }
}

#[inline]
fn union(labels: &mut [i32], a: usize, b: usize) {
    let (ra, rb) = match (find_root(labels, a), find_root(labels, b)) {
        (Some(ra), Some(rb)) => (ra, rb),
        _ => return,
    };
    if ra == rb {
        return;
    }
    let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
    let size = labels[lo].saturating_add(labels[hi]); // both negative
    labels[lo] = size;
    labels[hi] = lo as i32 + 1;
}

/// The numbering rule of both labellers' second pass for a union-find
/// entry `v`: a root (`v < 0`, a component of `−v` pixels) gets the next
/// number when `keep` accepts its area, else 0; `None` for any other entry
/// (its label is its parent's, already final).
#[inline]
fn root_label(v: i32, next: &mut u32, keep: &mut impl FnMut(u32) -> bool) -> Option<i32> {
    (v < 0).then(|| {
        if keep(v.unsigned_abs()) {
            *next += 1;
            *next as i32
        } else {
            0
        }
    })
}

/// Labels the 8-connected components of the nonzero pixels of `mask` into
/// `labels` (packed, `width × height`): 0 is background, components that
/// `keep(area)` accepts are numbered 1, 2, … in raster order of their first
/// pixel, the others are set to 0. Returns the number of kept components.
pub fn label_components(
    mask: crate::image::ImageView<'_>,
    labels: &mut [i32],
    keep: impl FnMut(u32) -> bool,
) -> Result<u32, LabelError> {
    let w = mask.width();
    label_components_in(mask, labels, |_| 0..w, keep)
}

/// [`label_components`] of a mask that is zero outside the columns
/// `cols(y)` of each row `y` (the ellipse spans of a local region): labels
/// are read and written only in those columns, so labels outside them
/// keep whatever they held (read them through the same columns). The
/// mask must be zero outside the columns (the previous row's mask is read
/// beside each run to find its neighbours); otherwise the labels are
/// wrong, though every access stays in bounds. With
/// `cols(y) = 0..width` this is [`label_components`]; a range reaching past
/// the width is clipped to it.
pub fn label_components_in(
    mask: crate::image::ImageView<'_>,
    labels: &mut [i32],
    cols: impl Fn(usize) -> core::ops::Range<usize>,
    mut keep: impl FnMut(u32) -> bool,
) -> Result<u32, LabelError> {
    let (w, h) = (mask.width(), mask.height());
    let span = |y: usize| {
        let r = cols(y);
        let end = r.end.min(w);
        r.start.min(end)..end
    };
    let n = w.checked_mul(h).ok_or(LabelError::BufferTooSmall)?;
    if labels.len() < n || n >= i32::MAX as usize {
        return Err(LabelError::BufferTooSmall);
    }
    let labels = &mut labels[..n];
    // pass 1: runs, unions with the 8-neighbours on the previous row
    for y in 0..h {
        let row = mask.row(y);
        let cs = span(y);
        let (mut x, end) = (cs.start, cs.end);
        while x < end {
            // background: skipped 16 pixels at a time, labels zeroed in one fill
            let z = next_where(row, x, end, true);
            if let Some(l) = labels.get_mut(y * w + x..y * w + z) {
                fill_stores(l, 0);
            }
            x = z;
            if x >= end {
                break;
            }
            let x0 = x;
            x = next_where(row, x, end, false);
            let p0 = y * w + x0;
            labels[p0] = -((x - x0) as i32);
            for l in &mut labels[p0 + 1..y * w + x] {
                *l = p0 as i32 + 1;
            }
            if y > 0 {
                // (the previous row is zero outside its columns, so its
                // foreground is found on the mask whatever they are)
                let lo = x0.saturating_sub(1);
                let hi = x.min(w - 1); // inclusive: x is the pixel right of the run
                let prev = (y - 1) * w;
                // one union per run of the previous row touching [lo, hi]
                // (its first pixel there), found on the previous mask row
                // (foreground there ⇔ nonzero label after pass 1)
                let prow = mask.row(y - 1);
                let mut xx = lo;
                while xx <= hi {
                    xx = next_where(prow, xx, hi + 1, true);
                    if xx > hi {
                        break;
                    }
                    union(labels, p0, prev + xx);
                    xx = next_where(prow, xx, hi + 1, false);
                }
            }
        }
    }
    // pass 2: raster order; a parent is always an earlier, already final
    // pixel. Only run starts can be roots and a run is one component, so
    // each run's first pixel is resolved and the rest of the run filled
    // with its label (background is already 0 from pass 1).
    let mut next = 0u32;
    for y in 0..h {
        let row = mask.row(y);
        let cs = span(y);
        let (mut x, end) = (cs.start, cs.end);
        while x < end {
            x = next_where(row, x, end, true);
            if x >= end {
                break;
            }
            let x1 = next_where(row, x, end, false);
            let i = y * w + x;
            let v = labels[i];
            let l = root_label(v, &mut next, &mut keep)
                .unwrap_or_else(|| labels.get((v - 1) as usize).copied().unwrap_or(0));
            if let Some(run) = labels.get_mut(i..y * w + x1) {
                run.fill(l);
            }
            x = x1;
        }
    }
    Ok(next)
}

/// Run-table capacity (runs) that [`label_runs_in`] may need for a mask
/// whose row `y` is nonzero only in `len(y)` columns: at most one run per
/// two columns, rounded up, per row — so `(Σ len + rows) / 2` bounds it.
pub const fn run_capacity(pixels: usize, rows: usize) -> usize {
    (pixels + rows).div_ceil(2)
}

/// Columns `x0..x1` of a packed run word of [`label_runs_in`].
#[inline]
pub fn run_span(word: i32) -> core::ops::Range<usize> {
    let w = word as u32;
    (w & 0xffff) as usize..(w >> 16) as usize
}

/// A label buffer seen as a [`label_runs_in`] run table (two words a run;
/// an odd last word is left out).
#[inline]
pub fn as_run_table(words: &mut [i32]) -> &mut [[i32; 2]] {
    let n = words.len() / 2 * 2;
    bytemuck::cast_slice_mut(&mut words[..n])
}

/// The runs of row `y` of a [`label_runs_in`] table (empty for a row
/// past the table).
#[inline]
pub fn runs_of_row<'r>(runs: &'r [[i32; 2]], row_start: &[u32], y: usize) -> &'r [[i32; 2]] {
    match (row_start.get(y), row_start.get(y + 1)) {
        (Some(&s), Some(&e)) => runs.get(s as usize..e as usize).unwrap_or(&[]),
        _ => &[],
    }
}

/// Root of run `i` in a run union-find (`v < 0` root of `−v` pixels,
/// `v > 0` parent run `v − 1`, always an earlier run); path halving.
#[inline]
fn find_run_root(runs: &mut [[i32; 2]], mut i: usize) -> Option<usize> {
    loop {
        let v = runs.get(i)?[1];
        if v < 0 {
            return Some(i);
        }
        let p = (v as usize).checked_sub(1).filter(|&p| p < i)?;
        let pv = runs.get(p)?[1];
        if pv < 0 {
            return Some(p);
        }
        let g = (pv as usize).checked_sub(1).filter(|&g| g < p)?;
        runs[i][1] = pv; // parent ← grandparent (still an earlier run)
        i = g;
    }
}

#[inline]
fn union_runs(runs: &mut [[i32; 2]], a: usize, b: usize) {
    let (Some(ra), Some(rb)) = (find_run_root(runs, a), find_run_root(runs, b)) else {
        return;
    };
    if ra == rb {
        return;
    }
    let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
    runs[lo][1] = runs[lo][1].saturating_add(runs[hi][1]); // both negative
    runs[hi][1] = lo as i32 + 1;
}

/// [`label_components_in`] without a label image: the same components,
/// numbered the same way (1, 2, … in raster order of their first pixel,
/// `keep(area)` deciding which are numbered), as a table of runs.
///
/// On return `runs[row_start[y] as usize..row_start[y + 1] as usize]` are
/// the runs of row `y` left to right, each `[packed, label]`: `packed`
/// holds the columns ([`run_span`]), `label` is 0 for a component `keep`
/// refused. Returns (kept components, runs used). Like
/// [`label_components_in`], the mask must be zero outside `cols(y)`.
///
/// Why (issue 8): a region's first labelling (eq. (4)) needs each
/// component's pixels only run by run — for its statistics and for the
/// accepted mask — so writing and re-reading a 4-byte label per pixel
/// (three passes over the ellipse) is replaced by one pass over the mask
/// bytes and a union-find over runs, 8 bytes per run.
///
/// Errors: `row_start` shorter than `height + 1`, `runs` shorter than the
/// mask's runs ([`run_capacity`] of the columns is always enough), or a
/// mask wider than 65 535 columns.
pub fn label_runs_in(
    mask: crate::image::ImageView<'_>,
    cols: impl Fn(usize) -> core::ops::Range<usize>,
    runs: &mut [[i32; 2]],
    row_start: &mut [u32],
    mut keep: impl FnMut(u32) -> bool,
) -> Result<(u32, usize), LabelError> {
    let (w, h) = (mask.width(), mask.height());
    if w > 0xffff || row_start.len() <= h || runs.len() >= u32::MAX as usize {
        return Err(LabelError::BufferTooSmall);
    }
    // pass 1: runs, unions with the 8-neighbouring runs of the previous row
    let mut nr = 0usize;
    let mut prev = 0..0;
    for (y, start) in row_start.iter_mut().enumerate().take(h) {
        *start = nr as u32;
        let row = mask.row(y);
        let r = cols(y);
        let end = r.end.min(w);
        let mut x = r.start.min(end);
        let mut k = prev.start;
        while x < end {
            let x0 = next_where(row, x, end, true);
            if x0 >= end {
                break;
            }
            let x1 = next_where(row, x0, end, false);
            let slot = runs.get_mut(nr).ok_or(LabelError::BufferTooSmall)?;
            *slot = [(x0 | (x1 << 16)) as i32, -((x1 - x0) as i32)];
            // previous runs [px0, px1) touch [x0, x1) 8-connectedly iff
            // px1 ≥ x0 and px0 ≤ x1; both rows are sorted, so runs that
            // end left of this one end left of every later one too
            while k < prev.end && run_span(runs[k][0]).end < x0 {
                k += 1;
            }
            let mut kk = k;
            while kk < prev.end && run_span(runs[kk][0]).start <= x1 {
                union_runs(runs, nr, kk);
                kk += 1;
            }
            nr += 1;
            x = x1;
        }
        prev = *start as usize..nr;
    }
    row_start[h] = nr as u32;
    // pass 2: raster order; a parent is an earlier run, already final
    let mut next = 0u32;
    for i in 0..nr {
        let v = runs[i][1];
        let l = root_label(v, &mut next, &mut keep).unwrap_or_else(|| {
            (v as usize)
                .checked_sub(1)
                .and_then(|p| runs.get(p))
                .map_or(0, |r| r[1])
        });
        runs[i][1] = l;
    }
    Ok((next, nr))
}

/// `dst.fill(v)` as a loop of vector stores, never a `memset` call: the
/// fills here are many and short (a background stretch of one label row),
/// where the call costs more than the stores, and glibc's `rep stosb` path
/// for longer ones is one instruction per byte to callgrind (issue 8's
/// instruction counts). `v` passes through `black_box` so the compiler
/// cannot see a byte splat and call `memset` after all.
#[inline]
pub(crate) fn fill_stores<T: Copy>(dst: &mut [T], v: T) {
    let v = core::hint::black_box(v);
    for d in dst {
        *d = v;
    }
}

/// First column `≥ x` (below `w`) whose pixel is nonzero (`nonzero` true)
/// or zero (`nonzero` false); `w` when there is none. Uniform stretches are
/// skipped 16 pixels per step.
#[inline]
pub(crate) fn next_where(row: &[u8], mut x: usize, w: usize, nonzero: bool) -> usize {
    let w = w.min(row.len());
    const ONES: u128 = u128::MAX / 255; // 0x0101…01
    let holds = |v: u128| {
        if nonzero {
            v != 0
        } else {
            v.wrapping_sub(ONES) & !v & (ONES << 7) != 0
        }
    };
    // the same test on one chunk of 16, then (in a long stretch) 64 pixels
    // per step (four chunks, one branch), then 16 per step
    if let Some(c) = row.get(x..x + 16).filter(|_| x + 16 <= w) {
        if holds(bytemuck::pod_read_unaligned(c)) {
            return first_byte(row, x, w, nonzero);
        }
        x += 16;
    }
    while x + 64 <= w {
        let Some(c) = row.get(x..x + 64) else { break };
        let mut any = false;
        for q in c.chunks_exact(16) {
            any |= holds(bytemuck::pod_read_unaligned(q));
        }
        if any {
            break;
        }
        x += 64;
    }
    while x + 16 <= w {
        let Some(c) = row.get(x..x + 16) else { break };
        let v: u128 = bytemuck::pod_read_unaligned(c);
        // skip the chunk when it holds no pixel of the kind sought:
        // all zero, or no zero byte (the classic SWAR zero-byte test)
        let skip = if nonzero {
            v == 0
        } else {
            v.wrapping_sub(ONES) & !v & (ONES << 7) == 0
        };
        if !skip {
            break;
        }
        x += 16;
    }
    first_byte(row, x, w, nonzero)
}

/// [`next_where`]'s pixel-by-pixel end (`w ≤ row.len()`).
#[inline]
fn first_byte(row: &[u8], mut x: usize, w: usize, nonzero: bool) -> usize {
    while x < w {
        let p = row.get(x).copied().unwrap_or(0);
        if (p != 0) == nonzero {
            return x;
        }
        x += 1;
    }
    w
}

// ------------------------------------------------------------------------
// Streaming labelling (no label image)
// ------------------------------------------------------------------------

/// One horizontal run `[x0, x1)` of the previous or current row and its label.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LabelRun {
    /// First column.
    pub x0: u32,
    /// One past the last column.
    pub x1: u32,
    /// Label slot.
    pub label: u32,
}

/// One label slot of a [`StreamLabeler`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    /// Union-find parent (itself for a root).
    pub parent: u32,
    /// In use.
    pub used: bool,
    /// Referenced by a run of the current row (scratch flag).
    pub live: bool,
    /// Statistics of the component (valid at roots).
    pub m: Moments,
}

impl Default for Slot {
    fn default() -> Self {
        Slot {
            parent: 0,
            used: false,
            live: false,
            m: Moments::EMPTY,
        }
    }
}

/// Words of one [`Slot`] in a [`StreamLabeler`] table (plain `u64`s so the
/// table can live in a caller's byte workspace without `unsafe`).
pub const SLOT_WORDS: usize = 11;

/// Words of one [`LabelRun`].
pub const RUN_WORDS: usize = 3;

impl Moments {
    /// Packs into 10 words.
    pub fn to_words(&self, w: &mut [u64]) {
        let v = [
            self.area,
            self.sx,
            self.sy,
            self.sxx,
            self.syy,
            self.sxy,
            self.x_min as u64,
            self.y_min as u64,
            self.x_max as u64,
            self.y_max as u64,
        ];
        for (d, s) in w.iter_mut().zip(v) {
            *d = s;
        }
    }

    /// Unpacks from 10 words (missing words read as 0).
    pub fn from_words(w: &[u64]) -> Moments {
        let g = |i: usize| w.get(i).copied().unwrap_or(0);
        Moments {
            area: g(0),
            sx: g(1),
            sy: g(2),
            sxx: g(3),
            syy: g(4),
            sxy: g(5),
            x_min: g(6) as u32,
            y_min: g(7) as u32,
            x_max: g(8) as u32,
            y_max: g(9) as u32,
        }
    }
}

impl Slot {
    fn decode(w: &[u64; SLOT_WORDS]) -> Slot {
        Slot {
            parent: w[0] as u32,
            used: (w[0] >> 32) & 1 == 1,
            live: (w[0] >> 33) & 1 == 1,
            m: Moments::from_words(&w[1..]),
        }
    }

    fn encode(&self, w: &mut [u64; SLOT_WORDS]) {
        w[0] = self.parent as u64 | (self.used as u64) << 32 | (self.live as u64) << 33;
        self.m.to_words(&mut w[1..]);
    }
}

impl LabelRun {
    fn decode(w: &[u32; RUN_WORDS]) -> LabelRun {
        LabelRun {
            x0: w[0],
            x1: w[1],
            label: w[2],
        }
    }

    fn encode(&self) -> [u32; RUN_WORDS] {
        [self.x0, self.x1, self.label]
    }
}

/// Slot table access by value.
struct Table<'a>(&'a mut [[u64; SLOT_WORDS]]);

impl Table<'_> {
    fn get(&self, i: usize) -> Option<Slot> {
        self.0.get(i).map(Slot::decode)
    }

    fn set(&mut self, i: usize, s: Slot) {
        if let Some(w) = self.0.get_mut(i) {
            s.encode(w);
        }
    }

    fn len(&self) -> usize {
        self.0.len()
    }
}

/// Run list access by value.
struct Runs<'a>(&'a mut [[u32; RUN_WORDS]]);

impl Runs<'_> {
    fn get(&self, i: usize) -> Option<LabelRun> {
        self.0.get(i).map(LabelRun::decode)
    }

    fn set(&mut self, i: usize, r: LabelRun) {
        if let Some(w) = self.0.get_mut(i) {
            *w = r.encode();
        }
    }
}

/// Row-by-row 8-connected labelling that keeps only two rows of runs and
/// reports each component's [`Moments`] when it is complete.
pub struct StreamLabeler<'a> {
    slots: Table<'a>,
    free: &'a mut [u32],
    n_free: usize,
    prev: Runs<'a>,
    n_prev: usize,
    cur: Runs<'a>,
    y: u32,
}

impl<'a> StreamLabeler<'a> {
    /// Label slots needed for rows `width` pixels wide: at most
    /// ⌈w/2⌉ live roots of the previous row plus ⌈w/2⌉ new ones.
    pub const fn table_len(width: usize) -> usize {
        2 * width.div_ceil(2) + 2
    }

    /// Run entries needed per row buffer.
    pub const fn runs_len(width: usize) -> usize {
        width.div_ceil(2) + 1
    }

    /// A labeler over caller tables: `slots` and `free` of
    /// [`Self::table_len`], `prev` and `cur` of [`Self::runs_len`].
    pub fn new(
        width: usize,
        slots: &'a mut [[u64; SLOT_WORDS]],
        free: &'a mut [u32],
        prev: &'a mut [[u32; RUN_WORDS]],
        cur: &'a mut [[u32; RUN_WORDS]],
    ) -> Result<Self, LabelError> {
        let t = Self::table_len(width);
        let r = Self::runs_len(width);
        if slots.len() < t || free.len() < t || prev.len() < r || cur.len() < r {
            return Err(LabelError::TableTooSmall);
        }
        let mut slots = Table(&mut slots[..t]);
        for i in 0..t {
            slots.set(i, Slot::default());
        }
        let free = &mut free[..t];
        for (i, f) in free.iter_mut().enumerate() {
            *f = (t - 1 - i) as u32; // pop from the end: slot 0 first
        }
        Ok(StreamLabeler {
            slots,
            free,
            n_free: t,
            prev: Runs(prev),
            n_prev: 0,
            cur: Runs(cur),
            y: 0,
        })
    }

    fn find(&mut self, mut i: u32) -> u32 {
        // parents form trees over used slots; bounded by the table size
        for _ in 0..self.slots.len() {
            let Some(si) = self.slots.get(i as usize) else {
                return i;
            };
            let p = si.parent;
            if p == i {
                return i;
            }
            let gp = self.slots.get(p as usize).map(|s| s.parent).unwrap_or(p);
            self.slots.set(i as usize, Slot { parent: gp, ..si });
            i = gp;
        }
        i
    }

    fn alloc(&mut self) -> Option<u32> {
        if self.n_free == 0 {
            return None;
        }
        self.n_free -= 1;
        let l = *self.free.get(self.n_free)?;
        self.slots.set(
            l as usize,
            Slot {
                parent: l,
                used: true,
                live: false,
                m: Moments::EMPTY,
            },
        );
        Some(l)
    }

    fn release(&mut self, l: u32) {
        if let Some(s) = self.slots.get(l as usize) {
            if s.used {
                self.slots.set(l as usize, Slot { used: false, ..s });
                if let Some(f) = self.free.get_mut(self.n_free) {
                    *f = l;
                    self.n_free += 1;
                }
            }
        }
    }

    fn set_live(&mut self, l: u32, live: bool) {
        if let Some(s) = self.slots.get(l as usize) {
            self.slots.set(l as usize, Slot { live, ..s });
        }
    }

    /// Feeds the next row: `fg(x)` tells whether pixel `x` (of `width`)
    /// is foreground. Completed components are passed to `done`.
    pub fn push_row(
        &mut self,
        width: usize,
        fg: impl Fn(usize) -> bool,
        done: impl FnMut(&Moments),
    ) {
        // current runs
        let mut n_cur = 0usize;
        let mut x = 0usize;
        while x < width {
            if !fg(x) {
                x += 1;
                continue;
            }
            let x0 = x;
            while x < width && fg(x) {
                x += 1;
            }
            self.open_run(&mut n_cur, x0, x);
        }
        self.connect(n_cur, done);
    }

    /// [`Self::push_row`] with foreground `row[x] > t`: the same labels and
    /// moments, but background is skipped 256 or 32 pixels at a time (a
    /// chunk whose maximum is at most `t`, one vectorised reduction), so a mostly
    /// empty row costs a fraction of an instruction per pixel.
    pub fn push_row_above(&mut self, row: &[u8], t: u8, done: impl FnMut(&Moments)) {
        const CHUNK: usize = 32;
        const WIDE: usize = 8 * CHUNK;
        let width = row.len();
        let mut n_cur = 0usize;
        let mut x = 0usize;
        while x < width {
            if let Some(c) = row.get(x..x + WIDE) {
                if c.iter().fold(0u8, |m, &v| m.max(v)) <= t {
                    x += WIDE;
                    continue;
                }
            }
            if let Some(c) = row.get(x..x + CHUNK) {
                if c.iter().fold(0u8, |m, &v| m.max(v)) <= t {
                    x += CHUNK;
                    continue;
                }
            }
            if row[x] <= t {
                x += 1;
                continue;
            }
            let x0 = x;
            while x < width && row[x] > t {
                x += 1;
            }
            self.open_run(&mut n_cur, x0, x);
        }
        self.connect(n_cur, done);
    }

    /// Appends the unlabelled run `[x0, x1)` as the current row's `n_cur`-th.
    fn open_run(&mut self, n_cur: &mut usize, x0: usize, x1: usize) {
        self.cur.set(
            *n_cur,
            LabelRun {
                x0: x0 as u32,
                x1: x1 as u32,
                label: u32::MAX,
            },
        );
        *n_cur += 1;
    }

    /// Connects the `n_cur` runs of the current row to the previous row's,
    /// updates the moments and retires finished components.
    fn connect(&mut self, n_cur: usize, mut done: impl FnMut(&Moments)) {
        let y = self.y;
        // connect to the previous row (two-pointer sweep, 8-connectivity:
        // previous run [p.x0, p.x1) touches [r.x0 − 1, r.x1])
        let mut j0 = 0usize;
        for k in 0..n_cur {
            let Some(r) = self.cur.get(k) else { break };
            let mut label: Option<u32> = None;
            while j0 < self.n_prev && self.prev.get(j0).is_some_and(|p| p.x1 < r.x0) {
                j0 += 1;
            }
            let mut j = j0;
            while j < self.n_prev {
                let Some(p) = self.prev.get(j) else { break };
                if p.x0 > r.x1 {
                    break;
                }
                let rp = self.find(p.label);
                label = Some(match label {
                    None => rp,
                    Some(l) => {
                        let rl = self.find(l);
                        if rl != rp {
                            let (keep, gone) = if rl < rp { (rl, rp) } else { (rp, rl) };
                            if let (Some(mut sk), Some(sg)) =
                                (self.slots.get(keep as usize), self.slots.get(gone as usize))
                            {
                                sk.m.merge(&sg.m);
                                self.slots.set(keep as usize, sk);
                                self.slots.set(gone as usize, Slot { parent: keep, ..sg });
                            }
                            keep
                        } else {
                            rl
                        }
                    }
                });
                j += 1;
            }
            let l = match label {
                Some(l) => l,
                // a new component; never fails with table_len slots
                None => match self.alloc() {
                    Some(l) => l,
                    None => continue,
                },
            };
            if let Some(mut s) = self.slots.get(l as usize) {
                s.m.add_run(y, r.x0, r.x1);
                self.slots.set(l as usize, s);
            }
            self.cur.set(k, LabelRun { label: l, ..r });
        }
        // compress current labels to roots and mark them live
        for k in 0..n_cur {
            let Some(c) = self.cur.get(k) else { break };
            if c.label == u32::MAX {
                continue;
            }
            let r = self.find(c.label);
            self.cur.set(k, LabelRun { label: r, ..c });
            self.set_live(r, true);
        }
        // Every slot in use is a label of a previous run (all were live roots
        // after the last row) or was allocated this row for a run with no
        // upper neighbour (a live root: it takes part in no union before the
        // next row). So retiring the previous runs' labels frees every slot
        // that is finished or merged away, and nothing else.
        for k in 0..self.n_prev {
            let l = self.prev.get(k).map(|p| p.label).unwrap_or(u32::MAX);
            self.retire(l, &mut done);
        }
        for k in 0..n_cur {
            let l = self.cur.get(k).map(|c| c.label).unwrap_or(u32::MAX);
            self.set_live(l, false);
        }
        core::mem::swap(&mut self.prev, &mut self.cur);
        self.n_prev = n_cur;
        self.y = self.y.saturating_add(1);
    }

    /// Emits and frees `l` if it is a finished root, frees it if it was merged.
    fn retire(&mut self, l: u32, done: &mut impl FnMut(&Moments)) {
        let Some(s) = self.slots.get(l as usize) else {
            return;
        };
        if !s.used || s.live {
            return;
        }
        if s.parent == l {
            done(&s.m);
        }
        self.release(l);
    }

    /// Ends the frame: reports every component still open.
    pub fn finish(&mut self, mut done: impl FnMut(&Moments)) {
        for k in 0..self.n_prev {
            let l = self.prev.get(k).map(|p| p.label).unwrap_or(u32::MAX);
            self.retire(l, &mut done);
        }
        self.n_prev = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::ImageView;
    use proptest::prelude::*;

    /// Flood fill, 8-connectivity: component index per pixel (usize::MAX = bg),
    /// components numbered in raster order of first pixel.
    fn flood(mask: &[u8], w: usize, h: usize) -> (Vec<usize>, usize) {
        let mut lab = vec![usize::MAX; w * h];
        let mut n = 0;
        for s in 0..w * h {
            if mask[s] == 0 || lab[s] != usize::MAX {
                continue;
            }
            let mut stack = vec![s];
            lab[s] = n;
            while let Some(p) = stack.pop() {
                let (x, y) = ((p % w) as isize, (p / w) as isize);
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (xx, yy) = (x + dx, y + dy);
                        if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                            continue;
                        }
                        let q = yy as usize * w + xx as usize;
                        if mask[q] != 0 && lab[q] == usize::MAX {
                            lab[q] = n;
                            stack.push(q);
                        }
                    }
                }
            }
            n += 1;
        }
        (lab, n)
    }

    fn random_mask(w: usize, h: usize, seed: u64, density: u64) -> Vec<u8> {
        let mut s = seed;
        (0..w * h)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 33) % 100 < density) as u8 * 255
            })
            .collect()
    }

    fn moments_of(lab: &[usize], w: usize, n: usize) -> Vec<Moments> {
        let mut m = vec![Moments::EMPTY; n];
        for (i, &l) in lab.iter().enumerate() {
            if l != usize::MAX {
                m[l].add_run((i / w) as u32, (i % w) as u32, (i % w) as u32 + 1);
            }
        }
        m
    }

    #[test]
    fn moments_of_a_run() {
        let mut a = Moments::EMPTY;
        a.add_run(2, 3, 6); // (3,2) (4,2) (5,2)
        assert_eq!(
            (a.area, a.sx, a.sy, a.sxx, a.syy, a.sxy),
            (3, 12, 6, 50, 12, 24)
        );
        assert_eq!((a.x_min, a.x_max, a.y_min, a.y_max), (3, 5, 2, 2));
        let (ang, l1, l2) = a.principal_axes();
        assert!(
            ang.abs() < 1e-6 && (l1 - 2.0 / 3.0).abs() < 1e-5 && l2.abs() < 1e-6,
            "{ang} {l1} {l2}"
        );
        let mut d = Moments::EMPTY;
        for i in 0..10 {
            d.add_run(i, i, i + 1);
        }
        let (ang, _, l2) = d.principal_axes();
        assert!((ang - core::f32::consts::FRAC_PI_4).abs() < 1e-5, "{ang}");
        assert!(l2.abs() < 1e-4);
    }

    /// A random mask zeroed outside random per-row column spans (some
    /// reaching past the width; with `full`, a third of the rows whole),
    /// and the spans.
    fn masked_to_spans(
        w: usize,
        h: usize,
        seed: u64,
        density: u64,
        span_seed: u64,
        full: bool,
    ) -> (Vec<u8>, Vec<core::ops::Range<usize>>) {
        let mut mask = random_mask(w, h, seed, density);
        let mut s = span_seed;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s as usize
        };
        let spans: Vec<core::ops::Range<usize>> = (0..h)
            .map(|_| {
                let a = next() % (w + 1);
                let b = next() % (w + 6); // may reach past the width
                if full && next() % 3 == 0 {
                    0..w
                } else {
                    a.min(b)..a.max(b)
                }
            })
            .collect();
        for (y, r) in spans.iter().enumerate() {
            for x in 0..w {
                if !r.contains(&x) {
                    mask[y * w + x] = 0;
                }
            }
        }
        (mask, spans)
    }

    proptest! {
        // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn next_where_is_the_first_match(len in 0usize..300, seed in any::<u64>(), density in 0u64..100, x in 0usize..320, w in 0usize..320, nonzero in any::<bool>()) {
            let mut s = seed;
            let row: Vec<u8> = (0..len).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); if (s >> 33) % 1000 < density { (s >> 56) as u8 | 1 } else { 0 } }).collect();
            let lim = w.min(row.len());
            // the plain scan: the first matching column in [x, lim), else lim
            let want = (x..lim).find(|&i| (row[i] != 0) == nonzero).unwrap_or(lim);
            prop_assert_eq!(next_where(&row, x, w, nonzero), want);
        }

        #[test]
        fn label_components_equals_flood_fill(w in 1usize..100, h in 1usize..40, seed in any::<u64>(), density in 0u64..100, min_area in 0u32..6) {
            let mask = random_mask(w, h, seed, density);
            let (fl, n) = flood(&mask, w, h);
            let areas = {
                let mut a = vec![0u32; n];
                for &l in &fl { if l != usize::MAX { a[l] += 1; } }
                a
            };
            let mut labels = vec![0i32; w * h];
            let k = label_components(ImageView::packed(&mask, w, h).unwrap(), &mut labels, |a| a >= min_area).unwrap();
            // kept components numbered in raster order of first pixel
            let mut map = vec![0i32; n];
            let mut next = 0;
            for c in 0..n { if areas[c] >= min_area { next += 1; map[c] = next; } }
            prop_assert_eq!(k as i32, next);
            for i in 0..w * h {
                let want = if fl[i] == usize::MAX { 0 } else { map[fl[i]] };
                prop_assert_eq!(labels[i], want);
            }
            prop_assert!(label_components(ImageView::packed(&mask, w, h).unwrap(), &mut labels[..w * h - 1], |_| true).is_err());
        }

        /// On a mask that is zero outside per-row column spans (an
        /// ellipse's), labelling only the spans gives, inside them, the
        /// whole labelling's labels and count, and writes nothing outside.
        #[test]
        fn label_components_in_spans_equals_whole(w in 1usize..90, h in 1usize..40, seed in any::<u64>(), density in 0u64..100, min_area in 0u32..6) {
            let (mask, spans) = masked_to_spans(w, h, seed, density, seed ^ 0x9e37_79b9_7f4a_7c15, false);
            let view = ImageView::packed(&mask, w, h).unwrap();
            let mut whole = vec![0i32; w * h];
            let kw = label_components(view, &mut whole, |a| a >= min_area).unwrap();
            let mut part = vec![-7i32; w * h];
            let kp = label_components_in(view, &mut part, |y| spans[y].clone(), |a| a >= min_area).unwrap();
            prop_assert_eq!(kp, kw);
            for (y, r) in spans.iter().enumerate() {
                for x in 0..w {
                    let i = y * w + x;
                    if r.contains(&x) {
                        prop_assert_eq!(part[i], whole[i]);
                    } else {
                        prop_assert_eq!(part[i], -7);
                    }
                }
            }
        }

        /// The run table labels every pixel as [`label_components_in`]
        /// does (same count, same numbers, keep asked the same areas), its
        /// runs are the mask's maximal runs row by row, [`run_capacity`] of
        /// the columns is enough, and one run less of room is an error.
        #[test]
        fn label_runs_in_equals_label_components_in(w in 1usize..90, h in 1usize..40, seed in any::<u64>(), density in 0u64..100, min_area in 0u32..6) {
            let (mask, spans) = masked_to_spans(w, h, seed, density, seed ^ 0x5851_f42d_4c95_7f2d, true);
            let view = ImageView::packed(&mask, w, h).unwrap();
            let mut want = vec![0i32; w * h];
            let mut asked_w = Vec::new();
            let kw = label_components_in(view, &mut want, |y| spans[y].clone(), |a| { asked_w.push(a); a >= min_area }).unwrap();
            let cols: usize = spans.iter().map(|r| r.end.min(w) - r.start.min(r.end.min(w))).sum();
            let cap = run_capacity(cols, h);
            let mut runs = vec![[0i32; 2]; cap];
            let mut starts = vec![0u32; h + 1];
            let mut asked_r = Vec::new();
            let (kr, nr) = label_runs_in(view, |y| spans[y].clone(), &mut runs, &mut starts, |a| { asked_r.push(a); a >= min_area }).unwrap();
            prop_assert_eq!(kr, kw);
            prop_assert_eq!(asked_r, asked_w);
            prop_assert_eq!(starts[h] as usize, nr);
            let mut got = vec![0i32; w * h];
            for y in 0..h {
                let mut last_end = None;
                for run in &runs[starts[y] as usize..starts[y + 1] as usize] {
                    let r = run_span(run[0]);
                    prop_assert!(r.start < r.end && r.end <= w);
                    // maximal: not adjacent to the previous run of the row
                    if let Some(e) = last_end { prop_assert!(r.start > e); }
                    last_end = Some(r.end);
                    for x in r { got[y * w + x] = run[1]; }
                }
            }
            for (y, r) in spans.iter().enumerate() {
                for x in 0..w {
                    let i = y * w + x;
                    if r.contains(&x) { prop_assert_eq!(got[i], want[i]); } else { prop_assert_eq!(got[i], 0); }
                }
            }
            if nr > 0 {
                prop_assert!(label_runs_in(view, |y| spans[y].clone(), &mut runs[..nr - 1], &mut starts, |_| true).is_err());
            }
            prop_assert!(label_runs_in(view, |y| spans[y].clone(), &mut runs, &mut starts[..h], |_| true).is_err());
        }

        #[test]
        fn stream_labeler_equals_flood_fill(w in 1usize..40, h in 1usize..40, seed in any::<u64>(), density in 0u64..100) {
            let mask = random_mask(w, h, seed, density);
            let (fl, n) = flood(&mask, w, h);
            let mut want = moments_of(&fl, w, n);
            let t = StreamLabeler::table_len(w);
            let r = StreamLabeler::runs_len(w);
            let (mut slots, mut free) = (vec![[0u64; SLOT_WORDS]; t], vec![0u32; t]);
            let (mut prev, mut cur) = (vec![[0u32; RUN_WORDS]; r], vec![[0u32; RUN_WORDS]; r]);
            let mut sl = StreamLabeler::new(w, &mut slots, &mut free, &mut prev, &mut cur).unwrap();
            let mut got = Vec::new();
            for y in 0..h {
                let row = &mask[y * w..(y + 1) * w];
                sl.push_row(w, |x| row[x] != 0, |m| got.push(*m));
            }
            sl.finish(|m| got.push(*m));
            let key = |m: &Moments| (m.y_min, m.x_min, m.area, m.sx, m.sy, m.sxy);
            want.sort_by_key(key);
            got.sort_by_key(key);
            prop_assert_eq!(got, want);
        }

        /// The chunk-skipping row scan equals the per-pixel one on grey rows
        /// wide enough for whole 32-pixel chunks, sparse and dense.
        #[test]
        fn push_row_above_equals_push_row(w in 1usize..700, h in 1usize..24, seed in any::<u64>(), t in any::<u8>(), sparse in any::<bool>()) {
            let mut s = seed | 1;
            let img: Vec<u8> = (0..w * h).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                let v = (s >> 24) as u8;
                if sparse && (s >> 40) % 16 != 0 { v.min(t) } else { v }
            }).collect();
            let tl = StreamLabeler::table_len(w);
            let r = StreamLabeler::runs_len(w);
            let run = |fast: bool| {
                let (mut slots, mut free) = (vec![[0u64; SLOT_WORDS]; tl], vec![0u32; tl]);
                let (mut prev, mut cur) = (vec![[0u32; RUN_WORDS]; r], vec![[0u32; RUN_WORDS]; r]);
                let mut sl = StreamLabeler::new(w, &mut slots, &mut free, &mut prev, &mut cur).unwrap();
                let mut got = Vec::new();
                for y in 0..h {
                    let row = &img[y * w..(y + 1) * w];
                    if fast {
                        sl.push_row_above(row, t, |m| got.push(*m));
                    } else {
                        sl.push_row(w, |x| row[x] > t, |m| got.push(*m));
                    }
                }
                sl.finish(|m| got.push(*m));
                got
            };
            prop_assert_eq!(run(true), run(false));
        }
    }
}
