//! Borrowed 8-bit grayscale image views and rectangular regions of interest.
//!
//! Views never own pixels: frames live in caller-provided buffers (a camera
//! DMA buffer on the device, a decoded PNG on the host). Rows may be padded:
//! `stride >= width`. Memory bound: none of its own.

use crate::error::ImageError;

/// An axis-aligned rectangle `[x, x + w) × [y, y + h)` in pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Roi {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width in pixels.
    pub w: u32,
    /// Height in pixels.
    pub h: u32,
}

impl Roi {
    /// A rectangle from its top-left corner and size.
    pub const fn new(x: u32, y: u32, w: u32, h: u32) -> Self {
        Roi { x, y, w, h }
    }

    /// The whole of a `width × height` image.
    pub const fn full(width: u32, height: u32) -> Self {
        Roi::new(0, 0, width, height)
    }

    /// Exclusive right edge (saturating).
    pub const fn right(&self) -> u32 {
        self.x.saturating_add(self.w)
    }

    /// Exclusive bottom edge (saturating).
    pub const fn bottom(&self) -> u32 {
        self.y.saturating_add(self.h)
    }

    /// Number of pixels covered.
    pub const fn area(&self) -> u64 {
        self.w as u64 * self.h as u64
    }

    /// True when the rectangle covers no pixel.
    pub const fn is_empty(&self) -> bool {
        self.w == 0 || self.h == 0
    }

    /// True when pixel `(x, y)` lies inside.
    pub const fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x && y >= self.y && x < self.right() && y < self.bottom()
    }

    /// The overlap of two rectangles (empty when they do not meet).
    pub fn intersect(&self, other: &Roi) -> Roi {
        let x0 = self.x.max(other.x);
        let y0 = self.y.max(other.y);
        let x1 = self.right().min(other.right());
        let y1 = self.bottom().min(other.bottom());
        if x1 <= x0 || y1 <= y0 {
            Roi::default()
        } else {
            Roi::new(x0, y0, x1 - x0, y1 - y0)
        }
    }

    /// The smallest rectangle holding both (an empty one is ignored).
    pub fn union(&self, other: &Roi) -> Roi {
        if self.is_empty() {
            return *other;
        }
        if other.is_empty() {
            return *self;
        }
        let x0 = self.x.min(other.x);
        let y0 = self.y.min(other.y);
        let x1 = self.right().max(other.right());
        let y1 = self.bottom().max(other.bottom());
        Roi::new(x0, y0, x1 - x0, y1 - y0)
    }

    /// Grows the rectangle by `m` pixels on every side, clipped to a
    /// `width × height` image.
    pub fn expand_clipped(&self, m: u32, width: u32, height: u32) -> Roi {
        let x0 = self.x.saturating_sub(m);
        let y0 = self.y.saturating_sub(m);
        let x1 = self.right().saturating_add(m).min(width);
        let y1 = self.bottom().saturating_add(m).min(height);
        if x1 <= x0 || y1 <= y0 {
            Roi::default()
        } else {
            Roi::new(x0, y0, x1 - x0, y1 - y0)
        }
    }

    /// Intersection-over-union of two rectangles, in `[0, 1]`.
    pub fn iou(&self, other: &Roi) -> f32 {
        let i = self.intersect(other).area();
        let u = self.area() + other.area() - i;
        if u == 0 {
            0.0
        } else {
            i as f32 / u as f32
        }
    }
}

const fn needed_len(width: usize, height: usize, stride: usize) -> Option<usize> {
    if height == 0 {
        return Some(0);
    }
    match (height - 1).checked_mul(stride) {
        Some(v) => v.checked_add(width),
        None => None,
    }
}

fn check(width: usize, height: usize, stride: usize, len: usize) -> Result<(), ImageError> {
    if width == 0 || height == 0 {
        return Err(ImageError::Empty);
    }
    if stride < width {
        return Err(ImageError::StrideTooSmall { stride, width });
    }
    let needed = needed_len(width, height, stride).unwrap_or(usize::MAX);
    if len < needed {
        return Err(ImageError::BufferTooSmall { needed, got: len });
    }
    Ok(())
}

/// A read-only 8-bit grayscale image borrowed from a slice.
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> ImageView<'a> {
    /// A view of `height` rows of `width` pixels, rows `stride` bytes apart.
    pub fn new(
        data: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, ImageError> {
        check(width, height, stride, data.len())?;
        Ok(ImageView {
            data,
            width,
            height,
            stride,
        })
    }

    /// A tightly packed view (`stride == width`).
    pub fn packed(data: &'a [u8], width: usize, height: usize) -> Result<Self, ImageError> {
        Self::new(data, width, height, width)
    }

    /// Width in pixels.
    pub const fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub const fn height(&self) -> usize {
        self.height
    }

    /// Distance between row starts, in bytes.
    pub const fn stride(&self) -> usize {
        self.stride
    }

    /// The whole image as a [`Roi`].
    pub fn bounds(&self) -> Roi {
        Roi::full(self.width as u32, self.height as u32)
    }

    /// Row `y` (exactly `width` pixels); empty when `y` is out of range.
    pub fn row(&self, y: usize) -> &'a [u8] {
        if y >= self.height {
            return &[];
        }
        let start = y * self.stride;
        self.data.get(start..start + self.width).unwrap_or(&[])
    }

    /// Pixel `(x, y)`, or `None` outside the image.
    pub fn get(&self, x: usize, y: usize) -> Option<u8> {
        if x >= self.width || y >= self.height {
            return None;
        }
        self.data.get(y * self.stride + x).copied()
    }

    /// Pixel `(x, y)` with coordinates clamped to the image (replicated border).
    pub fn get_clamped(&self, x: isize, y: isize) -> u8 {
        let xc = x.clamp(0, self.width as isize - 1) as usize;
        let yc = y.clamp(0, self.height as isize - 1) as usize;
        self.data.get(yc * self.stride + xc).copied().unwrap_or(0)
    }

    /// A view of the part of this image inside `roi`.
    pub fn sub(&self, roi: Roi) -> Result<ImageView<'a>, ImageError> {
        if roi.is_empty()
            || roi.right() as usize > self.width
            || roi.bottom() as usize > self.height
        {
            return Err(ImageError::RoiOutOfBounds);
        }
        let start = roi.y as usize * self.stride + roi.x as usize;
        let data = self.data.get(start..).ok_or(ImageError::RoiOutOfBounds)?;
        ImageView::new(data, roi.w as usize, roi.h as usize, self.stride)
    }
}

/// A mutable 8-bit grayscale image borrowed from a slice.
#[derive(Debug)]
pub struct ImageViewMut<'a> {
    data: &'a mut [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> ImageViewMut<'a> {
    /// A mutable view of `height` rows of `width` pixels, rows `stride` bytes apart.
    pub fn new(
        data: &'a mut [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, ImageError> {
        check(width, height, stride, data.len())?;
        Ok(ImageViewMut {
            data,
            width,
            height,
            stride,
        })
    }

    /// A tightly packed mutable view (`stride == width`).
    pub fn packed(data: &'a mut [u8], width: usize, height: usize) -> Result<Self, ImageError> {
        Self::new(data, width, height, width)
    }

    /// Width in pixels.
    pub const fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub const fn height(&self) -> usize {
        self.height
    }

    /// Distance between row starts, in bytes.
    pub const fn stride(&self) -> usize {
        self.stride
    }

    /// A read-only view of the same pixels.
    pub fn as_view(&self) -> ImageView<'_> {
        ImageView {
            data: self.data,
            width: self.width,
            height: self.height,
            stride: self.stride,
        }
    }

    /// Row `y` for writing; empty when `y` is out of range.
    pub fn row_mut(&mut self, y: usize) -> &mut [u8] {
        if y >= self.height {
            return &mut [];
        }
        let start = y * self.stride;
        let end = start + self.width;
        self.data.get_mut(start..end).unwrap_or(&mut [])
    }

    /// Sets pixel `(x, y)`; ignored outside the image.
    pub fn set(&mut self, x: usize, y: usize, v: u8) {
        if x < self.width && y < self.height {
            if let Some(p) = self.data.get_mut(y * self.stride + x) {
                *p = v;
            }
        }
    }

    /// Fills the whole image with `v`.
    pub fn fill(&mut self, v: u8) {
        for y in 0..self.height {
            self.row_mut(y).fill(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn view_rejects_short_buffers() {
        let buf = [0u8; 11];
        assert_eq!(
            ImageView::new(&buf, 4, 3, 4).unwrap_err(),
            ImageError::BufferTooSmall {
                needed: 12,
                got: 11
            }
        );
        assert!(ImageView::new(&buf, 4, 3, 3).is_err());
        assert!(ImageView::new(&buf, 0, 3, 4).is_err());
        // last row needs only `width` bytes, not `stride`
        let buf = [0u8; 10];
        assert!(ImageView::new(&buf, 2, 3, 4).is_ok());
    }

    #[test]
    fn sub_view_reads_the_right_pixels() {
        let buf: [u8; 16] = core::array::from_fn(|i| i as u8);
        let v = ImageView::packed(&buf, 4, 4).unwrap();
        let s = v.sub(Roi::new(1, 2, 2, 2)).unwrap();
        assert_eq!(s.row(0), &[9, 10]);
        assert_eq!(s.row(1), &[13, 14]);
        assert_eq!(s.get(1, 1), Some(14));
        assert_eq!(s.get(2, 0), None);
        assert!(v.sub(Roi::new(3, 3, 2, 1)).is_err());
    }

    proptest! {
        // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn roi_intersection_is_inside_both(a in (0u32..100, 0u32..100, 0u32..50, 0u32..50), b in (0u32..100, 0u32..100, 0u32..50, 0u32..50)) {
            let ra = Roi::new(a.0, a.1, a.2, a.3);
            let rb = Roi::new(b.0, b.1, b.2, b.3);
            let i = ra.intersect(&rb);
            prop_assert!(i.area() <= ra.area().min(rb.area()));
            for y in i.y..i.bottom() { for x in i.x..i.right() {
                prop_assert!(ra.contains(x, y) && rb.contains(x, y));
            }}
            let iou = ra.iou(&rb);
            prop_assert!((0.0..=1.0).contains(&iou));
            let u = ra.union(&rb);
            prop_assert!(u.area() >= ra.area().max(rb.area()));
        }
    }
}
