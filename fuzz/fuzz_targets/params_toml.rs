//! The `--params` TOML reader on random text: never panics; whatever it
//! accepts passes `Params::validate`, its `[track]` table applied to a
//! default `TrackConfig` passes `TrackConfig::validate`, and re-reading the
//! accepted file written back as TOML (Table I keys and the `[track]`
//! table) gives the same file.
#![no_main]

use std::path::Path;

use fishtrack::params_file::params_from_str;
use fishtrack_core::track::{DefaultTracker, TrackConfig};
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
    if let Ok(file) = params_from_str(text, path, width) {
        let p = &file.params;
        assert!(p.validate().is_ok(), "accepted invalid params {p:?}");
        let side = width.clamp(1, 32_000);
        let mut cfg = TrackConfig::for_frame(side, side);
        file.track.apply(&mut cfg);
        assert!(
            cfg.validate(DefaultTracker::DEPTH).is_ok(),
            "accepted an invalid [track] table {:?}",
            file.track
        );
        let mut table = toml::Table::try_from(p).expect("params encode");
        let track = toml::Table::try_from(file.track).expect("[track] encodes");
        table.insert("track".into(), toml::Value::Table(track));
        let back = toml::to_string(&table).expect("params serialise");
        let again = params_from_str(&back, path, width).expect("written params re-read");
        // Compare bit patterns: -0.0 vs 0.0 would compare equal anyway.
        assert_eq!(format!("{again:?}"), format!("{file:?}"));
    }
});
