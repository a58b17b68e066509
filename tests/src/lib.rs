//! Shared helpers for FishTrack's cross-crate integration tests.
#![deny(missing_docs)]

use std::path::PathBuf;

/// Path of a workspace binary built by cargo for the integration tests.
pub fn bin(name: &str) -> PathBuf {
    let mut p = std::env::current_exe().expect("test executable path");
    p.pop();
    if p.ends_with("deps") {
        p.pop();
    }
    p.join(format!("{name}{}", std::env::consts::EXE_SUFFIX))
}
