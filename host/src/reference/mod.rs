//! The float reference: the core's stages re-implemented independently in
//! plain `f64`, allocating, written for clarity, with `imageproc` for the
//! primitives. It is the yardstick `fishtrack compare` measures the core
//! against (DESIGN.md, "Float reference").

pub mod background;
pub mod compare;
pub mod epipolar;
pub mod fin;
pub mod photometric;
pub mod segment;
pub mod slant;
pub mod split;
pub mod stereo;
pub mod track;
