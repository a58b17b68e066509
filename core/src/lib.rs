//! # fishtrack-core
//!
//! The part of FishTrack that runs inside the Cam-trawl housing: every
//! algorithm of Chuang, Hwang, Williams & Towler, *Tracking Live Fish from
//! Low-Contrast and Low-Frame-Rate Stereo Videos* (IEEE TCSVT 2015), plus the
//! strobe/camera trigger driver and the serial link messages.
//!
//! Rules (see `DESIGN.md`):
//! - `#![no_std]`, no `alloc`: capacities are const generics, scratch memory
//!   is a caller-provided `&mut [u8]` whose size a `const fn` reports.
//! - Never panics: every fallible step returns a `Result`; a full container
//!   drops the least useful item and counts it.
//! - Integer arithmetic on pixels; `f32` through [`micromath::F32`] (called
//!   explicitly, so device and host compute the same thing) for geometry.
//!
//! Data flows one way: frame → objects → stereo objects → tracks → fish.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
#![deny(unsafe_code)]
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used, clippy::panic))]

pub mod epipolar;
pub mod error;
pub mod fin;
pub mod geometry;
pub mod image;
pub mod length;
pub mod link;
pub mod object;
pub mod params;
pub mod photometric;
pub mod pipeline;
pub mod refine;
pub mod remap;
pub mod slant;
pub mod snake;
pub mod stereo;
pub mod strobe;
pub mod track;

pub use error::{ImageError, ParamError};
pub use geometry::StereoGeometry;
pub use image::{ImageView, ImageViewMut, Roi};
pub use object::{Object, Objects, OrientedBox, Run, RunSpan};
pub use params::Params;
pub use segment::{segment_frame, workspace_size, SegmentError, SegmentStats};
pub mod background;
pub mod hist;
pub mod label;
pub mod lowres;
pub mod morph;
pub mod noise;
pub mod segment;
pub mod smooth;
pub mod threshold;
