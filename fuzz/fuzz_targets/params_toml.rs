//! The `--params` TOML reader on random text: never panics; whatever it
//! accepts passes `Params::validate`, and re-reading the accepted
//! parameters written back as TOML gives the same parameters.
#![no_main]

use std::path::Path;

use fishtrack::params_file::params_from_str;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&w, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    // Frame widths from tiny to the paper's 2048 and beyond.
    let width = [0, 1, 64, 512, 1000, 2048, 4096, 65535][usize::from(w % 8)];
    let path = Path::new("fuzz.toml");
    if let Ok(p) = params_from_str(text, path, width) {
        assert!(p.validate().is_ok(), "accepted invalid params {p:?}");
        let back = toml::to_string(&p).expect("params serialise");
        let again = params_from_str(&back, path, width).expect("written params re-read");
        // Compare bit patterns: -0.0 vs 0.0 would compare equal anyway.
        assert_eq!(format!("{again:?}"), format!("{p:?}"));
    }
});
