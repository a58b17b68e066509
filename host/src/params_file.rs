//! `--params FILE`: a TOML file overriding the Table I parameters.
//!
//! The keys are the field names of [`fishtrack_core::Params`] (e.g.
//! `p_low = 0.9`, `area_min = 500`, `tracker = "nn"`), all at the top
//! level, each optional:
//!
//! ```toml
//! theta_bp = 0.25
//! area_min = 500          # pixels of *this* haul's frames, taken as-is
//! tracker = "viterbi"
//! ```
//!
//! Defaults and scaling: a key that is not given takes its value from
//! [`Params::for_frame`]`(frame_width)`, i.e. the paper's default scaled to
//! the haul's frame width (areas by `(w/2048)²`, lengths by `w/2048`). A key
//! that *is* given is taken as-is: it is a value for the frames being
//! processed, in their own pixels, and is never rescaled. (So the same file
//! means the same pixel thresholds whatever the frame size; write a file per
//! frame size if the values are physical.)
//!
//! Errors, each an [`InputError`] naming the file and, where there is one,
//! the key: unreadable file, TOML syntax error (with line and column), unknown
//! key, value of the wrong type or out of the type's range, and any
//! [`Params::validate`] failure.

use std::path::Path;

use fishtrack_core::Params;

use crate::error::InputError;

/// Reads a params TOML file for frames `frame_width` pixels wide (see the
/// module documentation for how defaults and given keys combine).
pub fn load_params(path: impl AsRef<Path>, frame_width: u32) -> Result<Params, InputError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path)
        .map_err(|e| InputError::file(path, format!("cannot read params file: {e}")))?;
    params_from_str(&text, path, frame_width)
}

/// [`load_params`] on a string; `path` is only used in error messages.
pub fn params_from_str(text: &str, path: &Path, frame_width: u32) -> Result<Params, InputError> {
    let given: toml::Table = toml::from_str(text)
        .map_err(|e| InputError::file(path, format!("not a valid TOML file: {e}")))?;

    let defaults = Params::for_frame(frame_width);
    let mut merged = toml::Table::try_from(defaults)
        .map_err(|e| InputError::file(path, format!("internal: cannot encode defaults: {e}")))?;
    let known: Vec<String> = merged.keys().cloned().collect();

    for (key, value) in given {
        if !merged.contains_key(&key) {
            return Err(InputError::key(
                path,
                &key,
                format!("unknown parameter (known: {})", known.join(", ")),
            ));
        }
        // Check the key on its own, so a type error is pinned on it.
        let mut single = toml::Table::new();
        single.insert(key.clone(), value.clone());
        if let Err(e) = single.try_into::<Params>() {
            return Err(InputError::key(
                path,
                &key,
                format!("wrong type or value {value}: {}", e.message().trim()),
            ));
        }
        merged.insert(key, value);
    }

    let params: Params = merged
        .try_into()
        .map_err(|e| InputError::file(path, format!("invalid parameters: {e}")))?;
    params
        .validate()
        .map_err(|e| InputError::key(path, e.key(), e.to_string()))?;
    Ok(params)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fishtrack_core::params::Tracker;

    fn write(text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("params.toml");
        std::fs::write(&p, text).unwrap();
        (t, p)
    }

    fn err(text: &str, width: u32) -> (String, String) {
        let (_t, p) = write(text);
        let e = load_params(&p, width).unwrap_err();
        (e.to_string(), p.display().to_string())
    }

    #[test]
    fn empty_file_is_scaled_defaults() {
        let (_t, p) = write("# nothing\n");
        assert_eq!(load_params(&p, 512).unwrap(), Params::for_frame(512));
        assert_eq!(load_params(&p, 2048).unwrap(), Params::default());
        assert_ne!(Params::for_frame(512), Params::default());
    }

    #[test]
    fn given_keys_are_taken_as_is_others_scaled() {
        let (_t, p) = write(
            "area_min = 700\ntheta_bp = 0.25\nalpha = 1\ntracker = \"nn\"\nbackprojection = false\n",
        );
        let got = load_params(&p, 512).unwrap();
        let want = Params {
            area_min: 700, // not scaled by (512/2048)²
            theta_bp: 0.25,
            alpha: 1.0, // TOML integer accepted for a float key
            tracker: Tracker::Nn,
            backprojection: false,
            ..Params::for_frame(512)
        };
        assert_eq!(got, want);
        assert_eq!(got.area_max, 62_500); // 10⁶ · (512/2048)², the scaled default
        assert_eq!(got.margin, 25);
    }

    #[test]
    fn unknown_key_names_key_and_file() {
        let (e, p) = err("p_low = 0.9\nthreshold = 3\n", 2048);
        assert!(e.starts_with(&p), "{e}");
        assert!(e.contains("`threshold`") && e.contains("unknown"), "{e}");
        let (e, _) = err("[segment]\np_low = 0.9\n", 2048);
        assert!(e.contains("`segment`") && e.contains("unknown"), "{e}");
    }

    #[test]
    fn wrong_type_names_key() {
        for (text, key) in [
            ("p_low = \"high\"\n", "p_low"),
            ("area_min = 2.5\n", "area_min"),
            ("margin = -4\n", "margin"),
            ("hist_bins = 300\n", "hist_bins"),
            ("double_threshold = 1\n", "double_threshold"),
            ("tracker = \"kalman\"\n", "tracker"),
        ] {
            let (e, p) = err(text, 2048);
            assert!(e.starts_with(&p), "{e}");
            assert!(e.contains(&format!("`{key}`")), "{text}: {e}");
        }
    }

    #[test]
    fn validation_failure_names_key() {
        for (text, key) in [
            ("alpha = 1.5\n", "alpha"),
            ("p_high = 0.9\np_low = 0.5\n", "p_high"),
            ("hist_bins = 12\n", "hist_bins"),
            ("disk_size = 6\n", "disk_size"),
            // Given area_max is below the *scaled* default area_min (125 at 512 px).
            ("area_max = 100\n", "area_max"),
            ("theta_sad = nan\n", "theta_sad"),
        ] {
            let (e, p) = err(text, 512);
            assert!(e.starts_with(&p), "{e}");
            assert!(e.contains(&format!("`{key}`")), "{text}: {e}");
        }
        // Valid once area_min is given too (taken as-is at any width).
        let (_t, p) = write("area_max = 100\narea_min = 50\n");
        assert_eq!(load_params(&p, 2048).unwrap().area_max, 100);
    }

    #[test]
    fn syntax_error_and_missing_file_name_the_file() {
        let (e, p) = err("p_low = = 1\n", 2048);
        assert!(e.starts_with(&p) && e.contains("TOML"), "{e}");
        let (e, _) = err("p_low = 0.9\np_low = 0.8\n", 2048);
        assert!(e.contains("TOML"), "duplicate key: {e}");
        let missing = Path::new("/nonexistent/fishtrack/params.toml");
        let e = load_params(missing, 2048).unwrap_err().to_string();
        assert!(e.starts_with(&missing.display().to_string()), "{e}");
    }
}
