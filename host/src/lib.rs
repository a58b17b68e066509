//! # fishtrack (host)
//!
//! The `fishtrack` command-line program's library: haul reading, calibration
//! parsing, stereo rectification, the float reference implementation,
//! synthetic hauls, evaluation and survey outputs. The device algorithms
//! live in `fishtrack-core`; this crate feeds them and checks them.
#![deny(missing_docs)]

pub mod bench_cmd;
pub mod calib;
pub mod columns;
pub mod compare_cmd;
pub mod demo_cmd;
pub mod detect;
pub mod error;
pub mod eval;
pub mod frame_source;
pub mod haul;
pub mod output;
pub mod overlay;
pub mod params_file;
pub mod plot;
pub mod progress;
pub mod rectify;
pub mod reference;
/// The stereo float reference under its former path.
pub use reference::stereo as reference_stereo;
pub mod stats;
pub mod stdout;
pub mod survey;
pub mod synth;
pub mod timing;
pub mod track_cmd;
pub mod truth;
pub mod truth_obs;

pub use error::InputError;
