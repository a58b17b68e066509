//! Grey-level mathematical morphology (Section III.A gradient, III.D
//! post-processing, V.A trawl-mesh removal) and the 3 × 3 binary median
//! filter (Section III.A). Binary masks are grey images holding 0 and 255,
//! so the grey operators serve both.
//!
//! **Border convention** — OpenCV's default for `erode`/`dilate`/
//! `morphologyEx` (`BORDER_CONSTANT` with `morphologyDefaultBorderValue()`):
//! pixels outside the image are ignored, i.e. a max never sees them and a
//! min never sees them. The median filter replicates the border, as
//! `cv2.medianBlur` does. Every function here equals its OpenCV counterpart
//! exactly; `host/tests/opencv_segment_oracle.rs` checks it.
//!
//! **Structuring elements** — the disk is OpenCV's
//! `getStructuringElement(MORPH_ELLIPSE, (k, k))` (for k = 7 not a Euclidean
//! disk: rows of half-width 0, 2, 3, 3, 3, 2, 0), rebuilt with integer
//! arithmetic. The diagonal lines are `np.eye(k)` (main diagonal, top-left
//! to bottom-right) and its mirror (anti-diagonal), anchored at the centre.
//!
//! **Cost** — a disk of radius r is decomposed row by row: each source row
//! is dilated horizontally to half-widths 1..=r (a 3-wide max, then one
//! 2-read max per further level, since `[x−1 ± (k−1)] ∪ [x+1 ± (k−1)]` is
//! `[x ± k]`), kept in a ring of 2r+1 rows (level 0 is read in place), and
//! each output row is the max of its 2r+1 level rows in ONE pass (up to
//! eight rows per pass, 32-byte blocks, no bounds checks: a handful of
//! vector min/max instructions per 32 pixels). A diagonal line of k pixels
//! is likewise one fused pass over k shifted row slices. Measured with
//! callgrind, see README "Performance".
//!
//! Memory bound: the disk operators need [`disk_scratch_len`] bytes of
//! caller scratch; nothing else.

use crate::image::ImageView;

/// Largest supported structuring-element size (odd), as in `Params`.
pub const MAX_SE: usize = 31;

/// Why a morphology call was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MorphError {
    /// The destination slice is shorter than `width × height`.
    DstTooSmall,
    /// The scratch slice is shorter than [`disk_scratch_len`].
    ScratchTooSmall,
}

impl core::fmt::Display for MorphError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            MorphError::DstTooSmall => write!(f, "morphology: destination buffer too small"),
            MorphError::ScratchTooSmall => write!(f, "morphology: scratch buffer too small"),
        }
    }
}

impl core::error::Error for MorphError {}

/// A symmetric disk-like structuring element described by the half-width
/// of each of its `2·radius + 1` rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Disk {
    /// Half-size r: the element spans rows and columns `−r..=r`.
    pub radius: usize,
    /// `half_widths[r + dy]` = half-width of row `dy` (row covers `−hw..=hw`).
    pub half_widths: [u8; MAX_SE],
}

/// Rounded integer square root: the k with `(k − ½)² ≤ n < (k + ½)²`.
const fn isqrt_round(n: u32) -> u32 {
    let mut k = 0u32;
    // 4n ≥ (2k+1)² ⇔ n ≥ (k+½)²
    while 4 * n as u64 >= (2 * k as u64 + 1) * (2 * k as u64 + 1) {
        k += 1;
    }
    k
}

impl Disk {
    /// OpenCV's `MORPH_ELLIPSE` element of size `size × size` (`size` odd,
    /// clamped to 1..=31; even sizes are rounded up). OpenCV computes row
    /// `dy`'s half-width as `round(c·√((r² − dy²)/r²))` with `c = r` for a
    /// square element, i.e. `round(√(r² − dy²))`, done here exactly in
    /// integers.
    pub const fn opencv_ellipse(size: u8) -> Disk {
        let mut s = size as usize;
        if s < 1 {
            s = 1;
        }
        if s > MAX_SE {
            s = MAX_SE;
        }
        let r = s / 2;
        let mut half_widths = [0u8; MAX_SE];
        let mut i = 0;
        while i <= 2 * r {
            let dy = i.abs_diff(r);
            half_widths[i] = isqrt_round((r * r - dy * dy) as u32) as u8;
            i += 1;
        }
        Disk {
            radius: r,
            half_widths,
        }
    }

    /// Half-width of row `dy` (`−r..=r`), 0 outside.
    pub fn half_width(&self, dy: isize) -> usize {
        let i = dy + self.radius as isize;
        if i < 0 {
            return 0;
        }
        self.half_widths.get(i as usize).copied().unwrap_or(0) as usize
    }

    /// True when offset `(dx, dy)` belongs to the element.
    pub fn contains(&self, dx: isize, dy: isize) -> bool {
        dy.unsigned_abs() <= self.radius && dx.unsigned_abs() <= self.half_width(dy)
    }
}

/// Scratch bytes the disk operators need for images `width` pixels wide:
/// a ring of 2r+1 rows × (r+1) horizontal levels, plus one output row.
pub const fn disk_scratch_len(width: usize, radius: usize) -> usize {
    (2 * radius + 1) * (radius + 1) * width + width
}

#[inline]
fn op<const MAX: bool>(a: u8, b: u8) -> u8 {
    if MAX {
        a.max(b)
    } else {
        a.min(b)
    }
}

const fn identity<const MAX: bool>() -> u8 {
    if MAX {
        0
    } else {
        255
    }
}

/// `acc[i] = op(acc[i], src[i])`, slice-wise.
#[inline]
fn combine<const MAX: bool>(acc: &mut [u8], src: &[u8]) {
    for (a, &s) in acc.iter_mut().zip(src) {
        *a = op::<MAX>(*a, s);
    }
}

/// Most input rows one output row of [`reduce`] combines.
const MAX_INPUTS: usize = 2 * MAX_SE + 1;

/// Bytes per block of the reduction kernel (two SSE / one AVX register).
const BLOCK: usize = 32;

/// `out[i] = op over k of srcs[k][i]` (identity when `srcs` is empty), in
/// one pass reading up to eight input rows (the kernel is instantiated for
/// each count 1..=8, so no input is read twice); more are folded in by
/// further passes. Blocks of [`BLOCK`] bytes with every slice cut to the
/// same length carry no bounds checks and unroll into a handful of vector
/// min/max instructions per block (one load per input, one store).
fn reduce<const MAX: bool>(out: &mut [u8], srcs: &[&[u8]]) {
    let n = srcs.iter().fold(out.len(), |n, s| n.min(s.len()));
    let out = &mut out[..n];
    let Some(&first) = srcs.first() else {
        out.fill(identity::<MAX>());
        return;
    };
    fn arr<'a, const K: usize>(srcs: &[&'a [u8]], first: &'a [u8]) -> [&'a [u8]; K] {
        let mut a = [first; K];
        for (e, &s) in a.iter_mut().zip(srcs) {
            *e = s;
        }
        a
    }
    match srcs.len() {
        1 => out.copy_from_slice(&first[..n]),
        2 => reduce_k::<MAX, 2>(out, &arr(srcs, first)),
        3 => reduce_k::<MAX, 3>(out, &arr(srcs, first)),
        4 => reduce_k::<MAX, 4>(out, &arr(srcs, first)),
        5 => reduce_k::<MAX, 5>(out, &arr(srcs, first)),
        6 => reduce_k::<MAX, 6>(out, &arr(srcs, first)),
        7 => reduce_k::<MAX, 7>(out, &arr(srcs, first)),
        _ => {
            reduce_k::<MAX, 8>(out, &arr(srcs, first));
            for &s in srcs.iter().skip(8) {
                combine::<MAX>(out, s);
            }
        }
    }
}

/// The first `m` bytes of `s` (a multiple of [`BLOCK`]) as blocks.
fn blocks(s: &[u8], m: usize) -> &[[u8; BLOCK]] {
    bytemuck::cast_slice(s.get(..m).unwrap_or(&[]))
}

/// `out[i] = op of the K rows at i` (all at least `out.len()` long).
fn reduce_k<const MAX: bool, const K: usize>(out: &mut [u8], r: &[&[u8]; K]) {
    let n = out.len();
    let m = n - n % BLOCK;
    let (ob, ot) = out.split_at_mut(m);
    let ob: &mut [[u8; BLOCK]] = bytemuck::cast_slice_mut(ob);
    let k = ob.len();
    let bl: [&[[u8; BLOCK]]; K] = core::array::from_fn(|j| blocks(r[j], m));
    if K == 0 || bl.iter().any(|b| b.len() < k) {
        return;
    }
    // every input cut to exactly k blocks: the loop below has no checks
    let bl: [&[[u8; BLOCK]]; K] = core::array::from_fn(|j| &bl[j][..k]);
    for i in 0..k {
        let mut acc = bl[0][i];
        for b in &bl[1..] {
            let v = &b[i];
            for j in 0..BLOCK {
                acc[j] = op::<MAX>(acc[j], v[j]);
            }
        }
        ob[i] = acc;
    }
    if ot.is_empty() {
        return;
    }
    if n >= BLOCK {
        // the tail as one more block ending at n (overlapping the last
        // whole block; recomputing those outputs is harmless)
        let at = |s: &[u8]| -> [u8; BLOCK] {
            s.get(n - BLOCK..n)
                .and_then(|b| b.try_into().ok())
                .unwrap_or([identity::<MAX>(); BLOCK])
        };
        let mut acc = [identity::<MAX>(); BLOCK];
        for s in r {
            let b = at(s);
            for j in 0..BLOCK {
                acc[j] = op::<MAX>(acc[j], b[j]);
            }
        }
        let t = ot.len();
        ot.copy_from_slice(&acc[BLOCK - t..]);
        return;
    }
    for (j, o) in ot.iter_mut().enumerate() {
        let i = m + j;
        let mut acc = identity::<MAX>();
        for s in r {
            acc = op::<MAX>(acc, s.get(i).copied().unwrap_or(acc));
        }
        *o = acc;
    }
}

/// `dst[x] = op(src[x−1], src[x], src[x+1])` with out-of-range neighbours ignored.
fn line3<const MAX: bool>(src: &[u8], dst: &mut [u8]) {
    let n = src.len().min(dst.len());
    if n == 0 {
        return;
    }
    if n == 1 {
        dst[0] = src[0];
        return;
    }
    let (src, dst) = (&src[..n], &mut dst[..n]);
    dst[0] = op::<MAX>(src[0], src[1]);
    // interior: three shifted views of the row, one fused pass
    let (l, c, r) = (&src[..n - 2], &src[1..n - 1], &src[2..]);
    for (((d, &a), &b), &e) in dst[1..n - 1].iter_mut().zip(l).zip(c).zip(r) {
        *d = op::<MAX>(op::<MAX>(a, b), e);
    }
    dst[n - 1] = op::<MAX>(src[n - 2], src[n - 1]);
}

/// `dst[x] = op(src[x−1], src[x+1])`, out-of-range neighbours ignored
/// (a 1-pixel row is copied).
fn line_pair<const MAX: bool>(src: &[u8], dst: &mut [u8]) {
    let n = src.len().min(dst.len());
    if n < 2 {
        if let (Some(d), Some(&s)) = (dst.first_mut(), src.first()) {
            *d = s;
        }
        return;
    }
    let (src, dst) = (&src[..n], &mut dst[..n]);
    dst[0] = src[1];
    for ((d, &a), &b) in dst[1..n - 1].iter_mut().zip(&src[..n - 2]).zip(&src[2..]) {
        *d = op::<MAX>(a, b);
    }
    dst[n - 1] = src[n - 2];
}

/// The streaming core of the disk operators: keeps, for each of the last
/// 2r+1 source rows, its horizontal dilations (erosions) of half-width
/// 1..=r (level 0 is the source row itself, read in place), and hands
/// `emit(y, rows)` the 2r+1 (fewer at the borders) level rows whose
/// combination is output row `y`. `ring` needs [`ring_len`] bytes.
fn disk_stream<const MAX: bool>(
    src: ImageView<'_>,
    disk: &Disk,
    ring: &mut [u8],
    mut emit: impl FnMut(usize, &[&[u8]]),
) -> Result<(), MorphError> {
    let (w, h, r) = (src.width(), src.height(), disk.radius.min(MAX_SE / 2));
    let rows = 2 * r + 1;
    let slot = r * w;
    if ring.len() < ring_len(w, r) {
        return Err(MorphError::ScratchTooSmall);
    }
    let ring = &mut ring[..rows * slot];
    let mut loaded = 0usize; // rows 0..loaded have their levels in the ring
    for y in 0..h {
        let need = (y + r + 1).min(h);
        while loaded < need {
            if slot > 0 {
                let s = (loaded % rows) * slot;
                let block = &mut ring[s..s + slot];
                let mut prev: &[u8] = src.row(loaded);
                let mut rest = block;
                for level in 0..r {
                    let (next, tail) = rest.split_at_mut(w);
                    if level == 0 {
                        line3::<MAX>(prev, next);
                    } else {
                        // half-width k from k − 1: [x−1 ± (k−1)] ∪ [x+1 ± (k−1)]
                        // is [x ± k] for k ≥ 2, so two reads per pixel
                        line_pair::<MAX>(prev, next);
                    }
                    prev = next;
                    rest = tail;
                }
            }
            loaded += 1;
        }
        let mut srcs: [&[u8]; MAX_INPUTS] = [&[]; MAX_INPUTS];
        let mut k = 0usize;
        for dy in -(r as isize)..=(r as isize) {
            let yy = y as isize + dy;
            if yy < 0 || yy >= h as isize {
                continue;
            }
            let yy = yy as usize;
            let hw = disk.half_width(dy).min(r);
            let row: &[u8] = if hw == 0 {
                src.row(yy)
            } else {
                let s = (yy % rows) * slot + (hw - 1) * w;
                &ring[s..s + w]
            };
            if let Some(slot) = srcs.get_mut(k) {
                *slot = row;
                k += 1;
            }
        }
        emit(y, &srcs[..k]);
    }
    Ok(())
}

/// Ring bytes of [`disk_stream`]: `2r+1` rows × `r` levels.
const fn ring_len(width: usize, radius: usize) -> usize {
    (2 * radius + 1) * radius * width
}

/// Dilation (`MAX = true`) or erosion (`MAX = false`) of `src` by `disk`,
/// row by row: `emit(y, row)` receives each output row in order. OpenCV
/// border convention.
pub fn disk_rows<const MAX: bool>(
    src: ImageView<'_>,
    disk: &Disk,
    scratch: &mut [u8],
    mut emit: impl FnMut(usize, &[u8]),
) -> Result<(), MorphError> {
    let (w, r) = (src.width(), disk.radius);
    if scratch.len() < disk_scratch_len(w, r) {
        return Err(MorphError::ScratchTooSmall);
    }
    let (ring, rest) = scratch.split_at_mut(ring_len(w, r.min(MAX_SE / 2)));
    let out = &mut rest[..w];
    disk_stream::<MAX>(src, disk, ring, |y, rows| {
        reduce::<MAX>(out, rows);
        emit(y, out);
    })
}

/// Dilation (`MAX = true`) or erosion (`MAX = false`) of `src` by `disk`
/// into the packed `dst` (`width × height` bytes), OpenCV border convention.
pub fn disk_op<const MAX: bool>(
    src: ImageView<'_>,
    disk: &Disk,
    dst: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    let w = src.width();
    if dst.len() < w * src.height() {
        return Err(MorphError::DstTooSmall);
    }
    if scratch.len() < disk_scratch_len(w, disk.radius) {
        return Err(MorphError::ScratchTooSmall);
    }
    disk_stream::<MAX>(src, disk, scratch, |y, rows| {
        if let Some(d) = dst.get_mut(y * w..(y + 1) * w) {
            reduce::<MAX>(d, rows);
        }
    })
}

/// Dilation by a disk; see [`disk_op`].
pub fn dilate_disk(
    src: ImageView<'_>,
    disk: &Disk,
    dst: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    disk_op::<true>(src, disk, dst, scratch)
}

/// Erosion by a disk; see [`disk_op`].
pub fn erode_disk(
    src: ImageView<'_>,
    disk: &Disk,
    dst: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    disk_op::<false>(src, disk, dst, scratch)
}

/// Direction of a diagonal line element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Diagonal {
    /// Main diagonal, top-left to bottom-right (`np.eye(k)`).
    Main,
    /// Anti-diagonal, top-right to bottom-left (`np.fliplr(np.eye(k))`).
    Anti,
}

/// Row `y` of the dilation (`MAX`) or erosion of `src` by a diagonal line
/// of `len` pixels (odd, centred) into `out` (`width` bytes):
/// `out(x) = op_k src(x ± k, y + k)`, `k = −len/2..=len/2`, pixels outside
/// the image ignored.
pub fn line_row<const MAX: bool>(
    src: ImageView<'_>,
    y: usize,
    len: usize,
    dir: Diagonal,
    out: &mut [u8],
) {
    let (w, h) = (src.width(), src.height());
    let out = match out.get_mut(..w) {
        Some(o) => o,
        None => return,
    };
    let half = (len / 2).min(MAX_SE / 2);
    let shift_of = |k: isize| match dir {
        Diagonal::Main => k,
        Diagonal::Anti => -k,
    };
    // interior columns [lo, hi): every shifted pixel is inside the row, so
    // the output is one fused reduction of up to `len` shifted row slices
    let lo = half.min(w);
    let hi = w.saturating_sub(half).max(lo);
    let mut srcs: [&[u8]; MAX_INPUTS] = [&[]; MAX_INPUTS];
    let mut rows: [(&[u8], isize); MAX_INPUTS] = [(&[], 0); MAX_INPUTS];
    let mut n = 0usize;
    let hs = half as isize;
    for k in -hs..=hs {
        let yy = y as isize + k;
        if yy < 0 || yy >= h as isize {
            continue;
        }
        let row = src.row(yy as usize);
        let sh = shift_of(k);
        let s0 = (lo as isize + sh) as usize;
        let s1 = (hi as isize + sh) as usize;
        if let (Some(slot), Some(r)) = (srcs.get_mut(n), rows.get_mut(n)) {
            // an empty interior (w ≤ len − 1) reads no slice
            *slot = row.get(s0..s1).unwrap_or(&[]);
            *r = (row, sh);
            n += 1;
        }
    }
    if hi > lo {
        reduce::<MAX>(&mut out[lo..hi], &srcs[..n]);
    }
    // border columns [0, lo) and [hi, w): at most `half` each, pixel by
    // pixel over the same rows, out-of-image columns ignored
    let rows = &rows[..n];
    let border = |x: usize| -> u8 {
        let mut acc = identity::<MAX>();
        for &(row, sh) in rows {
            let xx = x as isize + sh;
            if xx >= 0 {
                if let Some(&v) = row.get(xx as usize) {
                    acc = op::<MAX>(acc, v);
                }
            }
        }
        acc
    };
    for (x, o) in out[..lo].iter_mut().enumerate() {
        *o = border(x);
    }
    for (x, o) in out[hi..].iter_mut().enumerate() {
        *o = border(hi + x);
    }
}

/// Dilation (`MAX`) or erosion of `src` by a diagonal line into the packed
/// `dst`; see [`line_row`].
pub fn line_op<const MAX: bool>(
    src: ImageView<'_>,
    len: usize,
    dir: Diagonal,
    dst: &mut [u8],
) -> Result<(), MorphError> {
    let (w, h) = (src.width(), src.height());
    if dst.len() < w * h {
        return Err(MorphError::DstTooSmall);
    }
    for (y, out) in dst.chunks_exact_mut(w.max(1)).take(h).enumerate() {
        line_row::<MAX>(src, y, len, dir, out);
    }
    Ok(())
}

/// Grey opening by a diagonal line (erosion then dilation), `tmp` and `dst`
/// both packed `width × height`.
pub fn open_line(
    src: ImageView<'_>,
    len: usize,
    dir: Diagonal,
    tmp: &mut [u8],
    dst: &mut [u8],
) -> Result<(), MorphError> {
    let (w, h) = (src.width(), src.height());
    line_op::<false>(src, len, dir, tmp)?;
    let t = ImageView::packed(tmp, w, h).map_err(|_| MorphError::DstTooSmall)?;
    line_op::<true>(t, len, dir, dst)
}

/// Trawl-mesh removal (Section V.A): the grey opening by the main-diagonal
/// line of `len` pixels followed by the grey opening by the anti-diagonal
/// line, `γ_anti(γ_main(f))`.
///
/// Why this combination: an opening by a line keeps exactly the bright
/// structures that contain that line. The mesh is a grid of thin bright
/// strands along both diagonals. `γ_main` keeps the main-diagonal strands
/// and removes the anti-diagonal ones (a strand thinner than `len/√2`
/// contains no crossing line), leaving at each grid crossing only the
/// main-diagonal strand's pixels; `γ_anti` then removes those, crossings
/// included, since no anti-diagonal line of `len` fits in them any more.
/// The pixel-wise minimum of the two openings, the other natural choice,
/// removes both strand directions too but keeps the crossing points (they
/// contain both lines), which the coarse gradient then picks up as specks;
/// the union (maximum) of openings would keep every strand. A fish body,
/// several times thicker than `len/√2`, contains both lines almost
/// everywhere and survives both openings (only its outline is smoothed at
/// the scale of `len`). The result is anti-extensive: no pixel brightens.
///
/// `out` receives the result; `tmp` is packed `width × height` scratch.
pub fn remove_mesh(
    src: ImageView<'_>,
    len: usize,
    tmp: &mut [u8],
    out: &mut [u8],
) -> Result<(), MorphError> {
    let (w, h) = (src.width(), src.height());
    if out.len() < w * h || tmp.len() < w * h {
        return Err(MorphError::DstTooSmall);
    }
    if len >= 3 && tmp.len() >= mesh_scratch_len(w, len) {
        return remove_mesh_fused(src, len, tmp, out);
    }
    open_line(src, len, Diagonal::Main, tmp, out)?;
    line_op::<false>(
        ImageView::packed(&out[..w * h], w, h).map_err(|_| MorphError::DstTooSmall)?,
        len,
        Diagonal::Anti,
        tmp,
    )?;
    line_op::<true>(
        ImageView::packed(&tmp[..w * h], w, h).map_err(|_| MorphError::DstTooSmall)?,
        len,
        Diagonal::Anti,
        out,
    )
}

/// Scratch bytes of [`remove_mesh_fused`] for rows of `width` pixels and
/// lines of `len` pixels: four rings of `mesh_ring` sheared rows, two
/// identity rows and two output rows of `mesh_row_len` bytes each, plus
/// 15 bytes to align them to 16.
pub const fn mesh_scratch_len(width: usize, len: usize) -> usize {
    let half = mesh_half(len);
    (4 * mesh_ring(half) + 4) * mesh_row_len(width, half) + (MESH_ALIGN - 1)
}

/// `len / 2`, at most `MAX_SE / 2`.
const fn mesh_half(len: usize) -> usize {
    if len / 2 < MAX_SE / 2 {
        len / 2
    } else {
        MAX_SE / 2
    }
}

/// Rows per ring of [`remove_mesh_fused`]: a stage reads the `len + 1`
/// rows of its pair of output rows while the stage before it is
/// `⌈half/2⌉` pairs ahead, `2⌈half/2⌉ + half + 2 ≤ len + 2` rows in all.
const fn mesh_ring(half: usize) -> usize {
    2 * half + 3
}

/// Alignment of the sheared rows of [`remove_mesh_fused`]: one SSE/NEON
/// register, so every block read can be an aligned memory operand.
const MESH_ALIGN: usize = 16;

/// Left padding of a sheared row: image column `c` of row `y` is at byte
/// `MESH_PAD + c + shear(y)`, `shear < 16`, and the reads of a block start
/// up to `half + 16` columns left of column 0.
const fn mesh_pad(half: usize) -> usize {
    half + MESH_ALIGN
}

/// Bytes per sheared row (a multiple of [`MESH_ALIGN`]): the padding, the
/// row, its shear, and the blocks' overrun of up to 15 + 33 columns on
/// the right.
const fn mesh_row_len(width: usize, half: usize) -> usize {
    (mesh_pad(half) + width + half + 64).div_ceil(MESH_ALIGN) * MESH_ALIGN
}

/// Where image row `y` starts in a sheared row read by a line along `dir`
/// (see [`remove_mesh_fused`]): column `c` is at byte `pad + c + shear`,
/// with `shear ≡ −y` (main diagonal) or `≡ y` (anti-diagonal) mod 16.
fn mesh_shear(y: usize, dir: Diagonal) -> usize {
    match dir {
        Diagonal::Main => (MESH_ALIGN - y % MESH_ALIGN) % MESH_ALIGN,
        Diagonal::Anti => y % MESH_ALIGN,
    }
}

/// [`remove_mesh`] in one streaming pass over the frame (identical
/// output): the four line operators (erosion and dilation along the main
/// diagonal, then along the anti-diagonal) are chained through rings of
/// `mesh_ring` rows each, so every intermediate row is made once, read
/// `len + 1` times while it is in cache, and the frame is read once and
/// written once. Rows outside the image are an identity row (255 before an
/// erosion, 0 before a dilation) and ring rows carry padding holding the
/// reader's identity: the OpenCV border convention (outside pixels
/// ignored) without a border case. Lines of fewer than 3 pixels are the
/// identity, copied. `scratch` needs [`mesh_scratch_len`] bytes.
///
/// **Sheared rows.** The `len` inputs of an output pixel lie on a
/// diagonal, so in plain rows they sit at `len` different column offsets
/// and no two of them can share an alignment. Each ring row is stored
/// shifted by its row number mod 16 (against the direction of the line
/// that reads it), which turns the diagonal into a vertical line as far as
/// alignment goes: all `len` inputs of a 32-pixel block start on the same
/// 16-byte boundary. Every input is then an aligned memory operand of the
/// min/max instruction (one instruction per input and 16 pixels instead of
/// a load and a min/max), and an output row is whole blocks with no tail
/// case; the few columns computed left and right of the row land in the
/// next ring's padding and are reset to the identity.
///
/// **Rows in pairs.** Output pixel `(x, y)` and its diagonal neighbour
/// `(x ± 1, y + 1)` share `len − 1` of their `len` inputs — the same bytes
/// of the same sheared rows — so each stage makes two rows at once: the
/// op of the shared inputs, then each row's own end input. That is
/// `(len + 1)/2` reads and ops per output pixel instead of `len` (4 instead
/// of 7 for Table I's lines); the loads were what bounded the pass.
pub fn remove_mesh_fused(
    src: ImageView<'_>,
    len: usize,
    scratch: &mut [u8],
    out: &mut [u8],
) -> Result<(), MorphError> {
    let (w, h) = (src.width(), src.height());
    let half = mesh_half(len);
    if out.len() < w * h {
        return Err(MorphError::DstTooSmall);
    }
    if half == 0 {
        for (y, o) in out.chunks_exact_mut(w.max(1)).take(h).enumerate() {
            o.copy_from_slice(src.row(y));
        }
        return Ok(());
    }
    let rr = mesh_ring(half);
    let l = mesh_row_len(w, half);
    let pad = mesh_pad(half);
    let scratch = scratch
        .get_mut(..mesh_scratch_len(w, len))
        .ok_or(MorphError::ScratchTooSmall)?;
    if w == 0 || h == 0 {
        return Ok(());
    }
    let skip = scratch
        .as_ptr()
        .align_offset(MESH_ALIGN)
        .min(MESH_ALIGN - 1);
    let scratch = scratch
        .get_mut(skip..skip + (4 * rr + 4) * l)
        .ok_or(MorphError::ScratchTooSmall)?;
    let (r0, rest) = scratch.split_at_mut(rr * l);
    let (r1, rest) = rest.split_at_mut(rr * l);
    let (r2, rest) = rest.split_at_mut(rr * l);
    let (r3, rest) = rest.split_at_mut(rr * l);
    let (id_min, rest) = rest.split_at_mut(l);
    let (id_max, rows) = rest.split_at_mut(l);
    id_min.fill(255);
    id_max.fill(0);
    let (id_min, id_max) = (&*id_min, &*id_max);
    let g = MeshGeom {
        w,
        h,
        half,
        l,
        pad,
        ring: rr,
    };
    let fail = MorphError::ScratchTooSmall;
    // step p: source rows 2p, 2p + 1 into the first ring, then stage s
    // (1..=4) makes its pair of rows 2j, 2j + 1 with j = p − s·c: stage
    // s − 1 has then made its rows up to 2j + 2c + 1 ≥ 2j + 1 + half, all
    // that the pair reads (rows past the image are identity)
    let c = half.div_ceil(2);
    for p in 0..h.div_ceil(2) + 4 * c {
        for t in [2 * p, 2 * p + 1] {
            if t < h {
                let at = (t % rr) * l + pad + mesh_shear(t, Diagonal::Main);
                let d = r0.get_mut(at..at + w).ok_or(fail)?;
                d.copy_from_slice(src.row(t));
                g.reset_border(r0, at, false).ok_or(fail)?;
            }
        }
        let row_of = |s: usize| p.checked_sub(s * c).map(|j| 2 * j).filter(|&y| y < h);
        if let Some(y) = row_of(1) {
            g.stage::<false>(r0, id_min, y, Diagonal::Main, r1, Some(Diagonal::Main))
                .ok_or(fail)?;
        }
        if let Some(y) = row_of(2) {
            g.stage::<true>(r1, id_max, y, Diagonal::Main, r2, Some(Diagonal::Anti))
                .ok_or(fail)?;
        }
        if let Some(y) = row_of(3) {
            g.stage::<false>(r2, id_min, y, Diagonal::Anti, r3, Some(Diagonal::Anti))
                .ok_or(fail)?;
        }
        if let Some(y) = row_of(4) {
            let ms = g
                .stage::<true>(r3, id_max, y, Diagonal::Anti, rows, None)
                .ok_or(fail)?;
            for (i, m) in ms.iter().enumerate() {
                let (Some(m), yy) = (*m, y + i) else { continue };
                let o = out
                    .get_mut(yy * w..(yy + 1) * w)
                    .ok_or(MorphError::DstTooSmall)?;
                o.copy_from_slice(rows.get(i * l + m..i * l + m + w).ok_or(fail)?);
            }
        }
    }
    Ok(())
}

/// The frame and row geometry of [`remove_mesh_fused`].
struct MeshGeom {
    w: usize,
    h: usize,
    half: usize,
    /// Bytes per sheared row.
    l: usize,
    /// [`mesh_pad`].
    pad: usize,
    /// Rows per ring ([`mesh_ring`]).
    ring: usize,
}

impl MeshGeom {
    /// `m = −x0 ∈ 0..16`, where `x0` is the first column computed for
    /// output row `y` of a line along `dir`: the column whose inputs all
    /// start on a 16-byte boundary (they start at byte
    /// `pad + x0 + s·(y' − y) + shear(y')`, `≡ pad + x0 − s·y` mod 16, with
    /// `s` = 1 on the main diagonal and −1 on the anti-diagonal).
    fn lead(&self, y: usize, dir: Diagonal) -> usize {
        match dir {
            Diagonal::Main => (self.pad + MESH_ALIGN - y % MESH_ALIGN) % MESH_ALIGN,
            Diagonal::Anti => (self.pad + y) % MESH_ALIGN,
        }
    }

    /// Sets the 16 bytes left and right of the row starting at byte `at`
    /// of `ring` (columns −16..0 and w..w + 16, which hold every column
    /// within `half ≤ 15` of the row that a reader of a valid output
    /// touches) to the identity of the reader: 0 before a dilation
    /// (`reader_max`), 255 before an erosion.
    fn reset_border(&self, ring: &mut [u8], at: usize, reader_max: bool) -> Option<()> {
        let id = [if reader_max { 0 } else { 255 }; MESH_ALIGN];
        let left = at.checked_sub(MESH_ALIGN)?;
        ring.get_mut(left..at)?.copy_from_slice(&id);
        let right = at + self.w;
        ring.get_mut(right..right + MESH_ALIGN)?
            .copy_from_slice(&id);
        Some(())
    }

    /// Rows `y` and `y + 1` (only `y` when `y + 1 = h`) of the line
    /// operator along `dir` on the sheared rows of `ring` (row `y'` in slot
    /// `y' mod ring`, `identity` outside `0..h`), written as whole 32-byte
    /// blocks into their slots of `next`, sheared for `next_dir` with their
    /// borders reset to the next reader's identity, or (`next_dir` `None`)
    /// into the two rows of `next` (`l` bytes apart), column `c` at byte
    /// `c + m` of its row: the `m` of each row is returned. `None` if a
    /// slice did not fit (cannot happen with the scratch laid out by
    /// [`remove_mesh_fused`]).
    fn stage<const MAX: bool>(
        &self,
        ring: &[u8],
        identity: &[u8],
        y: usize,
        dir: Diagonal,
        next: &mut [u8],
        next_dir: Option<Diagonal>,
    ) -> Option<[Option<usize>; 2]> {
        let (half, l, rr) = (self.half, self.l, self.ring);
        let k = 2 * half + 1;
        let two = y + 1 < self.h && matches!(k, 3 | 5 | 7);
        if !two {
            let m = self.stage_one::<MAX>(ring, identity, y, dir, next, next_dir)?;
            let m2 = if y + 1 < self.h {
                let n2 = match next_dir {
                    Some(_) => &mut *next,
                    None => next.get_mut(l..)?,
                };
                Some(self.stage_one::<MAX>(ring, identity, y + 1, dir, n2, next_dir)?)
            } else {
                None
            };
            return Some([Some(m), m2]);
        }
        // row y from x0 = −m, row y + 1 from x0 + s: the same input bytes
        // (for s = 1 and m = 0 one block earlier, so that row y + 1 starts
        // at or left of column 0)
        let m0 = self.lead(y, dir);
        let m = if dir == Diagonal::Main && m0 == 0 {
            MESH_ALIGN
        } else {
            m0
        };
        let m1 = match dir {
            Diagonal::Main => m - 1,
            Diagonal::Anti => m + 1,
        };
        let nb = (self.w + m + 1).div_ceil(BLOCK);
        let ring: &[u128] = bytemuck::try_cast_slice(ring).ok()?;
        let identity: &[u128] = bytemuck::try_cast_slice(identity).ok()?;
        let (pa, pb) = match next_dir {
            Some(nd) => (
                (y % rr) * l + self.pad + mesh_shear(y, nd) - m,
                ((y + 1) % rr) * l + self.pad + mesh_shear(y + 1, nd) - m1,
            ),
            None => (0, l),
        };
        let src = MeshSrc {
            ring,
            identity,
            y,
            base: self.pad - m,
            n16: nb * (BLOCK / MESH_ALIGN),
            dir,
        };
        let (a, b) = two_rows(next, pa, pb, nb * BLOCK)?;
        match k {
            3 => reduce_pair::<MAX, 4>(a, b, &self.inputs::<4>(&src, 4)?)?,
            5 => reduce_pair::<MAX, 6>(a, b, &self.inputs::<6>(&src, 6)?)?,
            _ => reduce_pair::<MAX, 8>(a, b, &self.inputs::<8>(&src, 8)?)?,
        }
        if next_dir.is_some() {
            // an erosion's output is read by a dilation and vice versa
            self.reset_border(next, pa + m, !MAX)?;
            self.reset_border(next, pb + m1, !MAX)?;
        }
        Some([Some(m), Some(m1)])
    }

    /// Row `y` alone (see [`MeshGeom::stage`]); its `m`.
    fn stage_one<const MAX: bool>(
        &self,
        ring: &[u8],
        identity: &[u8],
        y: usize,
        dir: Diagonal,
        next: &mut [u8],
        next_dir: Option<Diagonal>,
    ) -> Option<usize> {
        let (half, l, rr) = (self.half, self.l, self.ring);
        let k = 2 * half + 1;
        let m = self.lead(y, dir);
        // blocks cover columns x0 .. x0 + 32·nb ⊇ 0 .. w; in u128 units
        let nb = (self.w + m).div_ceil(BLOCK);
        let n16 = nb * (BLOCK / MESH_ALIGN);
        let ring: &[u128] = bytemuck::try_cast_slice(ring).ok()?;
        let identity: &[u128] = bytemuck::try_cast_slice(identity).ok()?;
        let base = self.pad - m;
        // column x0 of row y: in the next ring's slot, sheared for its
        // reader; in the output row, byte 0
        let at = match next_dir {
            Some(nd) => (y % rr) * l + self.pad + mesh_shear(y, nd) - m,
            None => 0,
        };
        let out = next.get_mut(at..at + nb * BLOCK)?;
        let src = MeshSrc {
            ring,
            identity,
            y,
            base,
            n16,
            dir,
        };
        match k {
            3 => reduce_aligned::<MAX, 3>(out, &self.inputs::<3>(&src, 3)?)?,
            5 => reduce_aligned::<MAX, 5>(out, &self.inputs::<5>(&src, 5)?)?,
            7 => reduce_aligned::<MAX, 7>(out, &self.inputs::<7>(&src, 7)?)?,
            _ => reduce_aligned_dyn::<MAX>(out, &self.inputs::<{ MAX_SE }>(&src, k)?[..k])?,
        }
        if next_dir.is_some() {
            // an erosion's output is read by a dilation and vice versa
            self.reset_border(next, at + m, !MAX)?;
        }
        Some(m)
    }
}

/// The disjoint `n`-byte parts of `buf` at `a` and at `b`.
fn two_rows(buf: &mut [u8], a: usize, b: usize, n: usize) -> Option<(&mut [u8], &mut [u8])> {
    if a < b {
        let (lo, hi) = buf.split_at_mut(b);
        Some((lo.get_mut(a..a + n)?, hi.get_mut(..n)?))
    } else {
        let (lo, hi) = buf.split_at_mut(a);
        let (b_part, a_part) = (lo.get_mut(b..b + n)?, hi.get_mut(..n)?);
        Some((a_part, b_part))
    }
}

/// What [`MeshGeom::inputs`] needs to find the inputs of one output row.
struct MeshSrc<'a> {
    ring: &'a [u128],
    identity: &'a [u128],
    y: usize,
    /// `pad − m` (see [`MeshGeom::lead`]).
    base: usize,
    /// Words per input.
    n16: usize,
    dir: Diagonal,
}

impl MeshGeom {
    /// The first `n ≤ K` inputs of output row `src.y` and the row after it
    /// (rows `y − half ..= y − half + n − 1`, shifted along the diagonal;
    /// identity rows outside the image), `n16` aligned words each; the
    /// rest empty.
    #[inline(always)]
    fn inputs<'a, const K: usize>(&self, src: &MeshSrc<'a>, n: usize) -> Option<[&'a [u128]; K]> {
        let (half, l, rr) = (self.half, self.l, self.ring);
        let identity = src.identity.get(..src.n16)?;
        let mut srcs: [&[u128]; K] = [&[]; K];
        // input i: column x0 + s·(i − half) of row y' = y − half + i, at
        // byte pad − m + s·(i − half) + shear(y'), a multiple of 16; the
        // slot of row y' is (y − half + i) mod ring, stepped
        let mut slot = (src.y + rr - half) % rr;
        for (i, sl) in srcs.iter_mut().take(n).enumerate() {
            let yy = (src.y + i).wrapping_sub(half);
            *sl = if yy < self.h {
                let at = match src.dir {
                    Diagonal::Main => (src.base + i).checked_sub(half)?,
                    Diagonal::Anti => src.base + half - i,
                } + mesh_shear(yy, src.dir);
                let s = (slot * l + at) / MESH_ALIGN;
                src.ring.get(s..s + src.n16)?
            } else {
                identity
            };
            slot = if slot + 1 == rr { 0 } else { slot + 1 };
        }
        Some(srcs)
    }
}

/// The `K` inputs cut to exactly `n` 32-byte blocks each, or `None` if
/// one is short: the loops over them then carry no bounds checks, and
/// reading a block through `[u128; 2]` tells the compiler it is 16-byte
/// aligned (memory operands of pminub / pmaxub).
#[inline(always)]
fn aligned_blocks<'a, const K: usize>(
    r: &[&'a [u128]; K],
    n: usize,
) -> Option<[&'a [[u128; 2]]; K]> {
    let bl: [&[[u128; 2]]; K] = core::array::from_fn(|j| {
        r.get(j)
            .and_then(|s| bytemuck::try_cast_slice(s.get(..2 * n)?).ok())
            .unwrap_or(&[])
    });
    if bl.iter().any(|b| b.len() < n) {
        return None;
    }
    Some(core::array::from_fn(|j| &bl[j][..n]))
}

/// `out` (32-byte blocks) = the op of the first `K` inputs (16-byte words,
/// two per block), block-wise; `None` if there are fewer inputs or one is
/// short.
#[inline(never)]
fn reduce_aligned<const MAX: bool, const K: usize>(out: &mut [u8], r: &[&[u128]; K]) -> Option<()> {
    let ob: &mut [[u8; BLOCK]] = bytemuck::try_cast_slice_mut(out).ok()?;
    let n = ob.len();
    if K == 0 || r.len() < K {
        return None;
    }
    let bl = aligned_blocks(r, n)?;
    let (first, rest) = bl.split_first()?;
    for (i, (o, a)) in ob.iter_mut().zip(*first).enumerate() {
        let mut acc: [u8; BLOCK] = *bytemuck::cast_ref::<[u128; 2], [u8; BLOCK]>(a);
        for b in rest {
            let v = bytemuck::cast_ref::<[u128; 2], [u8; BLOCK]>(&b[i]);
            for j in 0..BLOCK {
                acc[j] = op::<MAX>(acc[j], v[j]);
            }
        }
        *o = acc;
    }
    Some(())
}

/// Two output rows from `K` inputs (see [`remove_mesh_fused`], "Rows in
/// pairs"): `a` = the op of inputs `0..K−1`, `b` = the op of inputs
/// `1..K`, block-wise, the `K − 2` shared inputs combined once; `None` if
/// an input is short or the rows differ in length.
#[inline(never)]
fn reduce_pair<const MAX: bool, const K: usize>(
    a: &mut [u8],
    b: &mut [u8],
    r: &[&[u128]; K],
) -> Option<()> {
    let oa: &mut [[u8; BLOCK]] = bytemuck::try_cast_slice_mut(a).ok()?;
    let ob: &mut [[u8; BLOCK]] = bytemuck::try_cast_slice_mut(b).ok()?;
    let n = oa.len();
    if K < 3 || ob.len() != n {
        return None;
    }
    let bl = aligned_blocks(r, n)?;
    let (first, rest) = bl.split_first()?;
    let (last, mid) = rest.split_last()?;
    let (m0, mid) = mid.split_first()?;
    for (i, ((oa, ob), (f, z))) in oa
        .iter_mut()
        .zip(ob.iter_mut())
        .zip(first.iter().zip(*last))
        .enumerate()
    {
        let mut acc: [u8; BLOCK] = *bytemuck::cast_ref::<[u128; 2], [u8; BLOCK]>(&m0[i]);
        for c in mid {
            let v = bytemuck::cast_ref::<[u128; 2], [u8; BLOCK]>(&c[i]);
            for j in 0..BLOCK {
                acc[j] = op::<MAX>(acc[j], v[j]);
            }
        }
        let f = bytemuck::cast_ref::<[u128; 2], [u8; BLOCK]>(f);
        let z = bytemuck::cast_ref::<[u128; 2], [u8; BLOCK]>(z);
        let mut xa = acc;
        for j in 0..BLOCK {
            xa[j] = op::<MAX>(xa[j], f[j]);
        }
        for j in 0..BLOCK {
            acc[j] = op::<MAX>(acc[j], z[j]);
        }
        *oa = xa;
        *ob = acc;
    }
    Some(())
}

/// [`reduce_aligned`] for any number of inputs (lines longer than 7).
fn reduce_aligned_dyn<const MAX: bool>(out: &mut [u8], r: &[&[u128]]) -> Option<()> {
    let ob: &mut [[u8; BLOCK]] = bytemuck::try_cast_slice_mut(out).ok()?;
    if r.is_empty() || r.iter().any(|s| s.len() < 2 * ob.len()) {
        return None;
    }
    for (i, o) in ob.iter_mut().enumerate() {
        let mut acc = [identity::<MAX>(); BLOCK];
        for s in r {
            if let Some(b) = s.get(2 * i..2 * i + 2) {
                let v: &[u8] = bytemuck::cast_slice(b);
                for (a, &x) in acc.iter_mut().zip(v) {
                    *a = op::<MAX>(*a, x);
                }
            }
        }
        *o = acc;
    }
    Some(())
}

/// Grey morphological gradient `dilate − erode` by `disk` (Section III.A,
/// `cv2.MORPH_GRADIENT`) into the packed `dst`.
pub fn gradient_disk(
    src: ImageView<'_>,
    disk: &Disk,
    dst: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    let (w, r) = (src.width(), disk.radius.min(MAX_SE / 2));
    if dst.len() < w * src.height() {
        return Err(MorphError::DstTooSmall);
    }
    if scratch.len() < disk_scratch_len(w, disk.radius) {
        return Err(MorphError::ScratchTooSmall);
    }
    // dilation straight into `dst`, then each erosion row into `tmp` and
    // subtracted from the dilation row
    disk_op::<true>(src, disk, dst, scratch)?;
    let (ring, rest) = scratch.split_at_mut(ring_len(w, r));
    let tmp = &mut rest[..w];
    disk_stream::<false>(src, disk, ring, |y, rows| {
        if let Some(d) = dst.get_mut(y * w..(y + 1) * w) {
            reduce::<false>(tmp, rows);
            for (a, &b) in d.iter_mut().zip(tmp.iter()) {
                *a = a.saturating_sub(b);
            }
        }
    })
}

/// Closing (dilate then erode) by `disk`, in place on the packed `img`.
/// `tmp` is packed `width × height` scratch.
pub fn close_disk_in_place(
    img: &mut [u8],
    width: usize,
    height: usize,
    disk: &Disk,
    tmp: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    two_step_in_place::<true>(img, width, height, disk, tmp, scratch)
}

/// Opening (erode then dilate) by `disk`, in place on the packed `img`.
pub fn open_disk_in_place(
    img: &mut [u8],
    width: usize,
    height: usize,
    disk: &Disk,
    tmp: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    two_step_in_place::<false>(img, width, height, disk, tmp, scratch)
}

fn two_step_in_place<const CLOSE: bool>(
    img: &mut [u8],
    width: usize,
    height: usize,
    disk: &Disk,
    tmp: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    let n = width * height;
    if img.len() < n {
        return Err(MorphError::DstTooSmall);
    }
    if scratch.len() < disk_scratch_len(width, disk.radius) {
        return Err(MorphError::ScratchTooSmall);
    }
    if tmp.len() < n {
        return Err(MorphError::DstTooSmall);
    }
    if bits::two_step::<CLOSE>(img, width, height, disk, tmp) {
        return Ok(());
    }
    two_step_bytes::<CLOSE>(img, width, height, disk, tmp, scratch)
}

/// [`two_step_in_place`] on grey levels (any mask, any image).
fn two_step_bytes<const CLOSE: bool>(
    img: &mut [u8],
    width: usize,
    height: usize,
    disk: &Disk,
    tmp: &mut [u8],
    scratch: &mut [u8],
) -> Result<(), MorphError> {
    let n = width * height;
    if img.len() < n {
        return Err(MorphError::DstTooSmall);
    }
    {
        let v = ImageView::packed(&img[..n], width, height).map_err(|_| MorphError::DstTooSmall)?;
        disk_op::<CLOSE>(v, disk, tmp, scratch)?;
    }
    let t = ImageView::packed(tmp.get(..n).ok_or(MorphError::DstTooSmall)?, width, height)
        .map_err(|_| MorphError::DstTooSmall)?;
    if CLOSE {
        disk_op::<false>(t, disk, img, scratch)
    } else {
        disk_op::<true>(t, disk, img, scratch)
    }
}

/// Closing and opening of 0/255 masks on bit planes (64 pixels per word):
/// a dilation by the disk is, per row, the union of each input row's
/// horizontal dilation by the row's half-width (shifts of the words) over
/// the disk's rows; an erosion is the complement of the dilation of the
/// complement (the OpenCV border convention: outside pixels are the
/// identity, 0 for a dilation, so 1 for an erosion). Exactly the grey
/// result on 0/255 input.
mod bits {
    use super::Disk;

    /// Byte `b` as eight 0/255 pixels (bit i → byte i).
    const UNPACK: [u64; 256] = {
        let mut t = [0u64; 256];
        let mut b = 0;
        while b < 256 {
            let mut v = 0u64;
            let mut i = 0;
            while i < 8 {
                if (b >> i) & 1 != 0 {
                    v |= 0xff << (8 * i);
                }
                i += 1;
            }
            t[b] = v;
            b += 1;
        }
        t
    };

    /// Plane layout: one zero word, then per row `nw` words of pixels and
    /// one zero pad word, so every word's neighbours in a flat slice are
    /// its row neighbours or zero.
    #[derive(Clone, Copy)]
    struct Layout {
        nw: usize,
        ns: usize,
        h: usize,
        len: usize,
        tail: u64,
    }

    impl Layout {
        fn row(&self, y: usize) -> core::ops::Range<usize> {
            1 + y * self.ns..1 + y * self.ns + self.nw
        }

        /// Clears the pads and the bits beyond the width.
        fn fix(&self, p: &mut [u64]) {
            if let Some(z) = p.first_mut() {
                *z = 0;
            }
            for y in 0..self.h {
                let r = self.row(y);
                if let Some(l) = p.get_mut(r.end - 1) {
                    *l &= self.tail;
                }
                if let Some(pad) = p.get_mut(r.end) {
                    *pad = 0;
                }
            }
        }
    }

    /// Closing (`CLOSE`) or opening of the packed `img` in place when it is
    /// a 0/255 mask and `tmp` holds the bit planes; false (nothing written
    /// to `img`) otherwise.
    pub(super) fn two_step<const CLOSE: bool>(
        img: &mut [u8],
        w: usize,
        h: usize,
        disk: &Disk,
        tmp: &mut [u8],
    ) -> bool {
        let r = disk.radius.min(super::MAX_SE / 2);
        if w == 0 || h == 0 || r == 0 {
            return false;
        }
        let nw = w.div_ceil(64);
        let lay = Layout {
            nw,
            ns: nw + 1,
            h,
            len: 1 + h * (nw + 1),
            tail: if w % 64 == 0 {
                u64::MAX
            } else {
                (1u64 << (w % 64)) - 1
            },
        };
        let plane = lay.len;
        let (_, words, _) = bytemuck::pod_align_to_mut::<u8, u64>(tmp);
        // planes: X (input), Y (output), L1..Lr (horizontal dilations)
        let Some(words) = words.get_mut(..plane * (r + 2)) else {
            return false;
        };
        let (x, rest) = words.split_at_mut(plane);
        let (y, levels) = rest.split_at_mut(plane);
        if !pack(img, w, &lay, x) {
            return false;
        }
        // closing: dilate, erode = !dilate(!·); opening: erode, dilate
        if !CLOSE {
            complement(x, &lay);
        }
        dilate(x, y, levels, &lay, r, disk);
        complement(y, &lay);
        dilate(y, x, levels, &lay, r, disk);
        if CLOSE {
            complement(x, &lay);
        }
        unpack(x, img, w, &lay);
        true
    }

    /// Packs the 0/255 rows of `img` into `out` (bit x of a row at word
    /// x / 64, bit x % 64); false when a byte is neither 0 nor 255.
    fn pack(img: &[u8], w: usize, lay: &Layout, out: &mut [u64]) -> bool {
        crate::label::fill_stores(out, 0);
        for (yy, row) in img.chunks_exact(w).take(lay.h).enumerate() {
            // 0 → 0, 255 → 0, anything else → nonzero
            if row.iter().fold(0u8, |a, &p| a | (p.wrapping_add(1) >> 1)) != 0 {
                return false;
            }
            let o = out.get_mut(lay.row(yy)).unwrap_or(&mut []);
            let mut chunks = row.chunks_exact(64);
            for (c, word) in (&mut chunks).zip(o.iter_mut()) {
                let mut acc = 0u64;
                for (k, e) in c.chunks_exact(8).enumerate() {
                    let v = u64::from_le_bytes(e.try_into().unwrap_or([0; 8]));
                    // the top bit of byte i to bit i
                    let b = ((v >> 7) & 0x0101_0101_0101_0101).wrapping_mul(0x0102_0408_1020_4080)
                        >> 56;
                    acc |= b << (8 * k);
                }
                *word = acc;
            }
            if let Some(word) = o.get_mut(w / 64) {
                let mut acc = 0u64;
                for (i, &p) in chunks.remainder().iter().enumerate() {
                    acc |= ((p >> 7) as u64) << i;
                }
                if !chunks.remainder().is_empty() {
                    *word = acc;
                }
            }
        }
        true
    }

    /// Writes the bit rows back as 0/255 bytes.
    fn unpack(bits: &[u64], img: &mut [u8], w: usize, lay: &Layout) {
        for (yy, row) in img.chunks_exact_mut(w).take(lay.h).enumerate() {
            let b = bits.get(lay.row(yy)).unwrap_or(&[]);
            for (chunk, &word) in row.chunks_mut(64).zip(b.iter()) {
                let done = chunk.len() / 8 * 8;
                let mut eight = chunk.chunks_exact_mut(8);
                for (k, c) in (&mut eight).enumerate() {
                    let v = UNPACK[((word >> (8 * k)) & 0xff) as usize];
                    c.copy_from_slice(&v.to_le_bytes());
                }
                for (i, p) in eight.into_remainder().iter_mut().enumerate() {
                    *p = if (word >> (done + i)) & 1 != 0 {
                        255
                    } else {
                        0
                    };
                }
            }
        }
    }

    /// Complements the pixels (pads and bits beyond the width stay clear).
    fn complement(p: &mut [u64], lay: &Layout) {
        for v in p.iter_mut() {
            *v = !*v;
        }
        lay.fix(p);
    }

    /// `dst` = dilation of `src` by `disk` (pixels outside are 0); `levels`
    /// holds `r` planes: level k is `src` dilated row-wise by `[−k, k]`.
    fn dilate(
        src: &[u64],
        dst: &mut [u64],
        levels: &mut [u64],
        lay: &Layout,
        r: usize,
        disk: &Disk,
    ) {
        let plane = lay.len;
        let Some(src) = src.get(..plane) else { return };
        let Some(dst) = dst.get_mut(..plane) else {
            return;
        };
        if plane < 2 {
            return;
        }
        for k in 1..=r {
            let (done, cur) = levels.split_at_mut((k - 1) * plane);
            let prev: &[u64] = if k == 1 {
                src
            } else {
                done.get((k - 2) * plane..).unwrap_or(&[])
            };
            let Some(cur) = cur.get_mut(..plane) else {
                return;
            };
            let (Some(mid), Some(left), Some(right), Some(pv)) = (
                src.get(1..plane - 1),
                src.get(..plane - 2),
                src.get(2..),
                prev.get(1..plane - 1),
            ) else {
                return;
            };
            let out = cur.get_mut(1..plane - 1).unwrap_or(&mut []);
            // bit x ← bits x ± k (the pads make row ends zero)
            for ((((o, &m), &l), &rt), &p) in out.iter_mut().zip(mid).zip(left).zip(right).zip(pv) {
                *o = p | (m >> k) | (rt << (64 - k)) | (m << k) | (l >> (64 - k));
            }
        }
        crate::label::fill_stores(dst, 0);
        let (h, ns) = (lay.h as isize, lay.ns);
        for dy in -(r as isize)..=(r as isize) {
            let hw = disk.half_width(dy).min(r);
            let from: &[u64] = if hw == 0 {
                src
            } else {
                levels.get((hw - 1) * plane..hw * plane).unwrap_or(&[])
            };
            // output rows y with y + dy inside: [max(0, −dy), min(h, h − dy))
            let y0 = (-dy).max(0);
            let y1 = (h - dy).min(h);
            if y1 <= y0 {
                continue;
            }
            let (a, b) = (1 + y0 as usize * ns, 1 + y1 as usize * ns);
            let sa = (a as isize + dy * ns as isize) as usize;
            let (Some(o), Some(f)) = (dst.get_mut(a..b), from.get(sa..sa + (b - a))) else {
                continue;
            };
            for (o, &f) in o.iter_mut().zip(f) {
                *o |= f;
            }
        }
        lay.fix(dst);
    }
}

/// 3 × 3 median of a binary mask (nonzero = 1) into the packed `dst` as
/// 0 / 255, replicated border (`cv2.medianBlur(mask, 3)` on a 0/255 mask):
/// a pixel is set when at least 5 of its 9 neighbours are.
pub fn median3_binary(src: ImageView<'_>, dst: &mut [u8]) -> Result<(), MorphError> {
    let w = src.width();
    median3_binary_in(src, dst, |_| 0..w)
}

/// [`median3_binary`] computed only at the columns `cols(y)` of each row
/// `y` (clipped to the row), every other pixel of `dst` set to 0: equal to
/// the whole median followed by zeroing outside `cols` (the neighbours are
/// read wherever they are), at the cost of the columns kept.
pub fn median3_binary_in(
    src: ImageView<'_>,
    dst: &mut [u8],
    cols: impl Fn(usize) -> core::ops::Range<usize>,
) -> Result<(), MorphError> {
    let (w, h) = (src.width(), src.height());
    if dst.len() < w * h {
        return Err(MorphError::DstTooSmall);
    }
    // per block of MEDIAN_BLOCK columns: column counts (0..=3) with a
    // one-pixel halo (replicated at the row ends) into `pad`, then the
    // horizontal 3-sum against 5; both loops are slice-wise and vectorise
    const MEDIAN_BLOCK: usize = 256;
    let mut pad = [0u8; MEDIAN_BLOCK + 2];
    for y in 0..h {
        let up = src.row(y.saturating_sub(1));
        let mid = src.row(y);
        let down = src.row((y + 1).min(h - 1));
        let count = |x: usize| -> u8 {
            let g = |r: &[u8]| (r.get(x).copied().unwrap_or(0) != 0) as u8;
            g(up) + g(mid) + g(down)
        };
        let out = &mut dst[y * w..(y + 1) * w];
        let span = cols(y);
        let (c0, c1) = (span.start.min(w), span.end.min(w));
        // (store loops, not memset: see `label::fill_stores`)
        crate::label::fill_stores(&mut out[..c0], 0);
        crate::label::fill_stores(&mut out[c1.max(c0)..], 0);
        let mut x0 = c0;
        while x0 < c1 {
            let x1 = (x0 + MEDIAN_BLOCK).min(c1);
            let n = x1 - x0;
            pad[0] = count(x0.saturating_sub(1));
            pad[n + 1] = count(if x1 < w { x1 } else { w - 1 });
            if let (Some(a), Some(b), Some(c)) = (up.get(x0..x1), mid.get(x0..x1), down.get(x0..x1))
            {
                for (((p, &a), &b), &c) in pad[1..=n].iter_mut().zip(a).zip(b).zip(c) {
                    *p = (a != 0) as u8 + (b != 0) as u8 + (c != 0) as u8;
                }
            }
            let (l, m, r) = (&pad[..n], &pad[1..=n], &pad[2..n + 2]);
            for (((o, &l), &m), &r) in out[x0..x1].iter_mut().zip(l).zip(m).zip(r) {
                *o = if l + m + r >= 5 { 255 } else { 0 };
            }
            x0 = x1;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn naive<const MAX: bool>(
        img: &[u8],
        w: usize,
        h: usize,
        se: &dyn Fn(isize, isize) -> bool,
        r: isize,
    ) -> Vec<u8> {
        let mut out = vec![0u8; w * h];
        for y in 0..h as isize {
            for x in 0..w as isize {
                let mut acc = identity::<MAX>();
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (xx, yy) = (x + dx, y + dy);
                        if se(dx, dy) && xx >= 0 && yy >= 0 && xx < w as isize && yy < h as isize {
                            acc = op::<MAX>(acc, img[yy as usize * w + xx as usize]);
                        }
                    }
                }
                out[y as usize * w + x as usize] = acc;
            }
        }
        out
    }

    #[test]
    fn ellipse_7_is_opencvs() {
        let d = Disk::opencv_ellipse(7);
        assert_eq!(d.radius, 3);
        assert_eq!(&d.half_widths[..7], &[0, 2, 3, 3, 3, 2, 0]);
        let d5 = Disk::opencv_ellipse(5);
        assert_eq!(&d5.half_widths[..5], &[0, 2, 2, 2, 0]);
        assert_eq!(Disk::opencv_ellipse(1).half_widths[0], 0);
        assert_eq!(Disk::opencv_ellipse(3).half_widths[..3], [0, 1, 0]);
    }

    #[test]
    fn median_is_majority() {
        let img = [0, 255, 0, 255, 255, 0, 0, 0, 0u8];
        let mut out = [0u8; 9];
        median3_binary(ImageView::packed(&img, 3, 3).unwrap(), &mut out).unwrap();
        // centre: 3 of 9 set → 0; top-left (replicated): 0,0,255,0,0,255,255,255,255 → 5 → 255
        assert_eq!(out[4], 0);
        assert_eq!(out[0], 255);
    }

    proptest! {
        // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn bit_plane_close_open_equal_grey(
            w in 1usize..150, h in 1usize..40,
            size in prop::sample::select(vec![1u8, 3, 5, 7, 9, 11]),
            seed in any::<u64>(), density in 0u8..=255, grey in any::<bool>(),
        ) {
            let mut s = seed;
            let mut next = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 56) as u8 };
            // blobs: a pixel copies its left or upper neighbour most of the time
            let mut img = vec![0u8; w * h];
            for y in 0..h {
                for x in 0..w {
                    let v = next();
                    img[y * w + x] = if v < 160 && x > 0 {
                        img[y * w + x - 1]
                    } else if v < 200 && y > 0 {
                        img[(y - 1) * w + x]
                    } else if next() < density { 255 } else { 0 };
                }
            }
            if grey && w * h > 0 {
                img[(seed as usize) % (w * h)] = 7; // not a mask: the grey path
            }
            let d = Disk::opencv_ellipse(size);
            let mut scratch = vec![0u8; disk_scratch_len(w, d.radius)];
            let mut tmp = vec![0u8; w * h];
            for close in [true, false] {
                let mut want = img.clone();
                let mut got = img.clone();
                if close {
                    two_step_bytes::<true>(&mut want, w, h, &d, &mut tmp, &mut scratch).unwrap();
                    close_disk_in_place(&mut got, w, h, &d, &mut tmp, &mut scratch).unwrap();
                } else {
                    two_step_bytes::<false>(&mut want, w, h, &d, &mut tmp, &mut scratch).unwrap();
                    open_disk_in_place(&mut got, w, h, &d, &mut tmp, &mut scratch).unwrap();
                }
                prop_assert_eq!(&got, &want, "close {}", close);
            }
        }

        #[test]
        fn disk_ops_equal_naive(w in 1usize..70, h in 1usize..24, size in prop::sample::select(vec![1u8, 3, 5, 7, 9]), seed in any::<u64>()) {
            let mut s = seed;
            let img: Vec<u8> = (0..w * h).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 56) as u8 }).collect();
            let d = Disk::opencv_ellipse(size);
            let v = ImageView::packed(&img, w, h).unwrap();
            let mut scratch = vec![0u8; disk_scratch_len(w, d.radius)];
            let mut out = vec![0u8; w * h];
            dilate_disk(v, &d, &mut out, &mut scratch).unwrap();
            prop_assert_eq!(&out, &naive::<true>(&img, w, h, &|dx, dy| d.contains(dx, dy), d.radius as isize));
            erode_disk(v, &d, &mut out, &mut scratch).unwrap();
            prop_assert_eq!(&out, &naive::<false>(&img, w, h, &|dx, dy| d.contains(dx, dy), d.radius as isize));
            // the fused gradient equals naive dilation minus naive erosion,
            // with the exact scratch size and with a roomier one
            let grad_want: Vec<u8> = naive::<true>(&img, w, h, &|dx, dy| d.contains(dx, dy), d.radius as isize)
                .iter()
                .zip(naive::<false>(&img, w, h, &|dx, dy| d.contains(dx, dy), d.radius as isize))
                .map(|(a, b)| a - b)
                .collect();
            gradient_disk(v, &d, &mut out, &mut scratch).unwrap();
            prop_assert_eq!(&out, &grad_want);
            let mut big = vec![0u8; 3 * disk_scratch_len(w, d.radius)];
            gradient_disk(v, &d, &mut out, &mut big).unwrap();
            prop_assert_eq!(&out, &grad_want);
            let len = 2 * d.radius + 1;
            let hl = d.radius as isize;
            for dir in [Diagonal::Main, Diagonal::Anti] {
                let se = |dx: isize, dy: isize| match dir { Diagonal::Main => dx == dy, Diagonal::Anti => dx == -dy };
                line_op::<true>(v, len, dir, &mut out).unwrap();
                prop_assert_eq!(&out, &naive::<true>(&img, w, h, &se, hl));
                line_op::<false>(v, len, dir, &mut out).unwrap();
                prop_assert_eq!(&out, &naive::<false>(&img, w, h, &se, hl));
            }
            // mesh removal equals the naive composition of the four line operators
            if len >= 3 {
                let main = |dx: isize, dy: isize| dx == dy;
                let anti = |dx: isize, dy: isize| dx == -dy;
                let e1 = naive::<false>(&img, w, h, &main, hl);
                let o1 = naive::<true>(&e1, w, h, &main, hl);
                let e2 = naive::<false>(&o1, w, h, &anti, hl);
                let want = naive::<true>(&e2, w, h, &anti, hl);
                let mut tmp = vec![0u8; w * h];
                remove_mesh(v, len, &mut tmp, &mut out).unwrap();
                prop_assert_eq!(&out, &want);
            }
            // too-small buffers are errors, not panics
            prop_assert!(dilate_disk(v, &d, &mut out[..w * h - 1], &mut scratch).is_err());
            if d.radius > 0 {
                prop_assert!(dilate_disk(v, &d, &mut out, &mut scratch[..1]).is_err());
            }
        }

        /// The blocked median equals a naive 3 × 3 majority with the
        /// border replicated, on widths across several blocks.
        #[test]
        fn median3_equals_naive(w in 1usize..600, h in 1usize..6, seed in any::<u64>(), density in 1u64..8) {
            let mut s = seed | 1;
            let img: Vec<u8> = (0..w * h).map(|_| { s ^= s << 13; s ^= s >> 7; s ^= s << 17; if s % 8 < density { 255 } else { 0 } }).collect();
            let mut out = vec![7u8; w * h];
            median3_binary(ImageView::packed(&img, w, h).unwrap(), &mut out).unwrap();
            for y in 0..h {
                for x in 0..w {
                    let mut n = 0;
                    for dy in -1isize..=1 {
                        for dx in -1isize..=1 {
                            let yy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                            let xx = (x as isize + dx).clamp(0, w as isize - 1) as usize;
                            n += (img[yy * w + xx] != 0) as u32;
                        }
                    }
                    prop_assert_eq!(out[y * w + x], if n >= 5 { 255 } else { 0 }, "({}, {})", x, y);
                }
            }
            // the span-limited median: the same inside each row's span, 0 outside
            let cols = |y: usize| {
                let a = (seed as usize >> (y % 8)) % (w + 3);
                let b = (seed as usize >> (8 + y % 8)) % (w + 3);
                a.min(b)..a.max(b)
            };
            let mut part = vec![9u8; w * h];
            median3_binary_in(ImageView::packed(&img, w, h).unwrap(), &mut part, cols).unwrap();
            for y in 0..h {
                let c = cols(y);
                for x in 0..w {
                    let want = if c.contains(&x) { out[y * w + x] } else { 0 };
                    prop_assert_eq!(part[y * w + x], want, "span ({}, {}) {:?}", x, y, c);
                }
            }
        }

        /// The fused streaming mesh removal equals the naive composition
        /// of the four line operators, with the exact scratch size.
        #[test]
        fn fused_mesh_removal_equals_naive(w in 1usize..150, h in 1usize..40, len in prop::sample::select(vec![1usize, 3, 5, 7, 9, 31]), seed in any::<u64>(), skew in 0usize..16) {
            let mut s = seed;
            let img: Vec<u8> = (0..w * h).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 56) as u8 }).collect();
            let v = ImageView::packed(&img, w, h).unwrap();
            let hl = (len / 2) as isize;
            let main = |dx: isize, dy: isize| dx == dy;
            let anti = |dx: isize, dy: isize| dx == -dy;
            let e1 = naive::<false>(&img, w, h, &main, hl);
            let o1 = naive::<true>(&e1, w, h, &main, hl);
            let e2 = naive::<false>(&o1, w, h, &anti, hl);
            let want = naive::<true>(&e2, w, h, &anti, hl);
            // the scratch at any alignment (the sheared rows align themselves)
            let mut buf = vec![7u8; mesh_scratch_len(w, len) + skew];
            let scratch = &mut buf[skew..];
            let mut out = vec![0u8; w * h];
            remove_mesh_fused(v, len, scratch, &mut out).unwrap();
            prop_assert_eq!(&out, &want);
            if len >= 3 {
                prop_assert!(remove_mesh_fused(v, len, &mut scratch[..mesh_scratch_len(w, len) - 1], &mut out).is_err());
            }
        }

        #[test]
        fn mesh_removal_is_anti_extensive(w in 1usize..30, h in 1usize..30, seed in any::<u64>()) {
            let mut s = seed;
            let img: Vec<u8> = (0..w * h).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1); (s >> 56) as u8 }).collect();
            let v = ImageView::packed(&img, w, h).unwrap();
            let (mut t1, mut out) = (vec![0u8; w * h], vec![0u8; w * h]);
            remove_mesh(v, 7, &mut t1, &mut out).unwrap();
            prop_assert!(out.iter().zip(&img).all(|(o, i)| o <= i));
        }
    }

    #[test]
    fn mesh_strands_go_fish_stays() {
        let (w, h) = (64usize, 64usize);
        let mut img = vec![20u8; w * h];
        // diagonal strands in both directions, 1 px wide, every 16 px
        for y in 0..h {
            for x in 0..w {
                if (x + y) % 16 == 0 || (x + 64 - y) % 16 == 0 {
                    img[y * w + x] = 200;
                }
            }
        }
        // a fish: filled ellipse 40×18 centred at (32,32)
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f32 - 32.0, y as f32 - 32.0);
                if dx * dx / 400.0 + dy * dy / 81.0 <= 1.0 {
                    img[y * w + x] = 150;
                }
            }
        }
        let v = ImageView::packed(&img, w, h).unwrap();
        let (mut t1, mut out) = (vec![0u8; w * h], vec![0u8; w * h]);
        remove_mesh(v, 7, &mut t1, &mut out).unwrap();
        assert_eq!(out[32 * w + 32], 150, "fish centre kept");
        // every strand pixel goes, crossings included, except within len/2 of
        // the image border where the lines are cut short (outside ignored)
        let left: Vec<(usize, usize)> = (0..w * h)
            .filter(|&i| out[i] == 200)
            .map(|i| (i % w, i / w))
            .collect();
        assert!(
            left.iter()
                .all(|&(x, y)| x.min(y).min(w - 1 - x).min(h - 1 - y) < 3),
            "{left:?}"
        );
        // the fish keeps its interior (its outline may be smoothed)
        let fish_kept = out.iter().filter(|&&p| p == 150).count();
        assert!(
            fish_kept as f32 > 0.85 * std::f32::consts::PI * 180.0,
            "{fish_kept}"
        );
    }
}
