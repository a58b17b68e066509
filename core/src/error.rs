//! Error types of the core, one small enum per kind of operation (the
//! smoltcp model). Each implements `Display` and `core::error::Error`, and
//! `defmt::Format` with the `defmt` feature.

use core::fmt;

/// Why a [`crate::Params`] value was rejected by [`crate::Params::validate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ParamError {
    /// The named parameter is NaN or infinite.
    NotFinite(&'static str),
    /// The named parameter is outside its allowed range.
    OutOfRange {
        /// Parameter name as written in a params file.
        name: &'static str,
        /// Human-readable allowed range.
        allowed: &'static str,
    },
    /// Two parameters contradict each other (named: the first of the two).
    Inconsistent {
        /// Parameter name as written in a params file.
        name: &'static str,
        /// What is wrong.
        why: &'static str,
    },
}

impl ParamError {
    /// The params-file key this error is about.
    pub const fn key(&self) -> &'static str {
        match self {
            ParamError::NotFinite(n) => n,
            ParamError::OutOfRange { name, .. } => name,
            ParamError::Inconsistent { name, .. } => name,
        }
    }
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamError::NotFinite(n) => write!(f, "parameter `{n}` is not a finite number"),
            ParamError::OutOfRange { name, allowed } => {
                write!(f, "parameter `{name}` is out of range (allowed: {allowed})")
            }
            ParamError::Inconsistent { name, why } => write!(f, "parameter `{name}`: {why}"),
        }
    }
}

impl core::error::Error for ParamError {}

/// Why an image view or a caller-provided buffer was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ImageError {
    /// Width or height is zero.
    Empty,
    /// Stride is smaller than the width.
    StrideTooSmall {
        /// Row stride in bytes.
        stride: usize,
        /// Image width in pixels.
        width: usize,
    },
    /// The slice is shorter than `(height - 1) * stride + width`.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// Two images that must have the same size do not.
    SizeMismatch,
    /// A region of interest lies (partly) outside the image.
    RoiOutOfBounds,
}

impl fmt::Display for ImageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImageError::Empty => write!(f, "image has zero width or height"),
            ImageError::StrideTooSmall { stride, width } => {
                write!(f, "row stride {stride} is smaller than width {width}")
            }
            ImageError::BufferTooSmall { needed, got } => {
                write!(f, "buffer holds {got} bytes, {needed} needed")
            }
            ImageError::SizeMismatch => write!(f, "image sizes differ"),
            ImageError::RoiOutOfBounds => write!(f, "region of interest lies outside the image"),
        }
    }
}

impl core::error::Error for ImageError {}
