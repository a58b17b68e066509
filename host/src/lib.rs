//! # fishtrack (host)
//!
//! The `fishtrack` command-line program's library: haul reading, calibration
//! parsing, stereo rectification, the float reference implementation,
//! synthetic hauls, evaluation and survey outputs. The device algorithms
//! live in `fishtrack-core`; this crate feeds them and checks them.
#![deny(missing_docs)]

pub mod error;
pub mod synth;
pub mod truth;

pub use error::InputError;
