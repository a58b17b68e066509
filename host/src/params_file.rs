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
//! A `[track]` table overrides the tracker's options that are not Table I
//! parameters ([`TrackConfig`]'s fields listed in [`TrackOverrides`]), for
//! example for a haul recorded at a lower frame rate:
//!
//! ```toml
//! [track]
//! max_lost = 0      # at 2.5 fps a lost frame carries a fish half the frame
//! miss_cost = 24
//! ```
//!
//! Errors, each an [`InputError`] naming the file and, where there is one,
//! the key: unreadable file, TOML syntax error (with line and column), unknown
//! key, value of the wrong type or out of the type's range, and any
//! [`Params::validate`] or [`TrackConfig::validate`] failure.

use std::path::Path;

use fishtrack_core::track::TrackConfig;
use fishtrack_core::Params;

use crate::error::InputError;

/// The `[track]` table of a params file: tracker options beyond Table I
/// ([`TrackConfig`], whose field documentation gives each default and
/// why); a key not given keeps the default. Values are taken as-is (never
/// rescaled with the frame).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct TrackOverrides {
    /// [`TrackConfig::miss_cost`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub miss_cost: Option<f32>,
    /// [`TrackConfig::share_cost`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub share_cost: Option<f32>,
    /// [`TrackConfig::gate_cost`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gate_cost: Option<f32>,
    /// [`TrackConfig::nn_gate`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nn_gate: Option<f32>,
    /// [`TrackConfig::lost_gate`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lost_gate: Option<f32>,
    /// [`TrackConfig::newborn_lost_gate`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub newborn_lost_gate: Option<f32>,
    /// [`TrackConfig::max_lost`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_lost: Option<u8>,
    /// [`TrackConfig::birth_area_factor`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub birth_area_factor: Option<f32>,
    /// [`TrackConfig::z_ref_mm`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub z_ref_mm: Option<f32>,
    /// [`TrackConfig::min_sigma_samples`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_sigma_samples: Option<u16>,
    /// [`TrackConfig::cue_cap`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cue_cap: Option<f32>,
    /// [`TrackConfig::swap_passes`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub swap_passes: Option<u8>,
    /// [`TrackConfig::area_robust`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub area_robust: Option<f32>,
    /// [`TrackConfig::hist_robust`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hist_robust: Option<f32>,
    /// [`TrackConfig::depth_robust`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_robust: Option<f32>,
    /// [`TrackConfig::cut_aware_motion`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cut_aware_motion: Option<bool>,
    /// [`TrackConfig::axis_direction`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub axis_direction: Option<bool>,
    /// [`TrackConfig::fold_shared`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fold_shared: Option<bool>,
    /// [`TrackConfig::newborn_reverse_cost`] (`inf` turns it off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub newborn_reverse_cost: Option<f32>,
    /// [`TrackConfig::confirm_births`] (0 = the paper's birth rule).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub confirm_births: Option<u8>,
    /// [`TrackConfig::confirm_min_step`], pixels per frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub confirm_min_step: Option<f32>,
}

impl TrackOverrides {
    /// Sets the given fields in `cfg`.
    pub fn apply(&self, cfg: &mut TrackConfig) {
        fn set<T: Copy>(v: Option<T>, to: &mut T) {
            if let Some(v) = v {
                *to = v;
            }
        }
        set(self.miss_cost, &mut cfg.miss_cost);
        set(self.share_cost, &mut cfg.share_cost);
        set(self.gate_cost, &mut cfg.gate_cost);
        set(self.nn_gate, &mut cfg.nn_gate);
        set(self.lost_gate, &mut cfg.lost_gate);
        set(self.newborn_lost_gate, &mut cfg.newborn_lost_gate);
        set(self.max_lost, &mut cfg.max_lost);
        set(self.birth_area_factor, &mut cfg.birth_area_factor);
        set(self.z_ref_mm, &mut cfg.z_ref_mm);
        set(self.min_sigma_samples, &mut cfg.min_sigma_samples);
        set(self.cue_cap, &mut cfg.cue_cap);
        set(self.swap_passes, &mut cfg.swap_passes);
        set(self.area_robust, &mut cfg.area_robust);
        set(self.hist_robust, &mut cfg.hist_robust);
        set(self.depth_robust, &mut cfg.depth_robust);
        set(self.cut_aware_motion, &mut cfg.cut_aware_motion);
        set(self.axis_direction, &mut cfg.axis_direction);
        set(self.fold_shared, &mut cfg.fold_shared);
        set(self.newborn_reverse_cost, &mut cfg.newborn_reverse_cost);
        set(self.confirm_births, &mut cfg.confirm_births);
        set(self.confirm_min_step, &mut cfg.confirm_min_step);
    }
}

/// What a params file sets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamsFile {
    /// Table I parameters (defaults scaled to the frame, given keys as-is).
    pub params: Params,
    /// The `[track]` table.
    pub track: TrackOverrides,
}

/// The trellis depth the per-key check of `max_lost` uses: the default
/// tracker's.
const TRELLIS_DEPTH: usize = fishtrack_core::track::DefaultTracker::DEPTH;

/// Reads a params TOML file for frames `frame_width` pixels wide (see the
/// module documentation for how defaults and given keys combine).
pub fn load_params(path: impl AsRef<Path>, frame_width: u32) -> Result<ParamsFile, InputError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path)
        .map_err(|e| InputError::file(path, format!("cannot read params file: {e}")))?;
    params_from_str(&text, path, frame_width)
}

/// The `[track]` table `value`, each key checked on its own (known, of its
/// type, and valid in a default [`TrackConfig`]) so an error names it.
fn track_overrides(
    value: toml::Value,
    path: &Path,
    frame_width: u32,
) -> Result<TrackOverrides, InputError> {
    let toml::Value::Table(table) = value else {
        return Err(InputError::key(path, "track", "must be a table ([track])"));
    };
    for (key, v) in &table {
        let mut single = toml::Table::new();
        single.insert(key.clone(), v.clone());
        let one: TrackOverrides = single.try_into().map_err(|e: toml::de::Error| {
            InputError::key(
                path,
                &format!("track.{key}"),
                format!(
                    "unknown key or wrong type or value {v}: {}",
                    e.message().trim()
                ),
            )
        })?;
        let mut cfg = TrackConfig::for_frame(frame_width.max(1), frame_width.max(1));
        one.apply(&mut cfg);
        cfg.validate(TRELLIS_DEPTH)
            .map_err(|e| InputError::key(path, &format!("track.{key}"), format!("{e}")))?;
    }
    let all: TrackOverrides = table
        .try_into()
        .map_err(|e| InputError::file(path, format!("invalid [track] table: {e}")))?;
    Ok(all)
}

/// [`load_params`] on a string; `path` is only used in error messages.
pub fn params_from_str(
    text: &str,
    path: &Path,
    frame_width: u32,
) -> Result<ParamsFile, InputError> {
    let mut given: toml::Table = toml::from_str(text)
        .map_err(|e| InputError::file(path, format!("not a valid TOML file: {e}")))?;
    let track = match given.remove("track") {
        Some(v) => track_overrides(v, path, frame_width)?,
        None => TrackOverrides::default(),
    };

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
    Ok(ParamsFile { params, track })
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

    /// Each `(text, key)`: loading `text` for `width`-pixel frames fails
    /// with an error that starts with the file and names `key`.
    fn assert_errors_name_keys(cases: &[(&str, &str)], width: u32) {
        for (text, key) in cases {
            let (e, p) = err(text, width);
            assert!(e.starts_with(&p), "{e}");
            assert!(e.contains(&format!("`{key}`")), "{text}: {e}");
        }
    }

    #[test]
    fn empty_file_is_scaled_defaults() {
        let (_t, p) = write("# nothing\n");
        assert_eq!(load_params(&p, 512).unwrap().params, Params::for_frame(512));
        assert_eq!(load_params(&p, 2048).unwrap().params, Params::default());
        assert_eq!(
            load_params(&p, 2048).unwrap().track,
            TrackOverrides::default()
        );
        assert_ne!(Params::for_frame(512), Params::default());
    }

    #[test]
    fn given_keys_are_taken_as_is_others_scaled() {
        let (_t, p) = write(
            "area_min = 700\ntheta_bp = 0.25\nalpha = 1\ntracker = \"nn\"\nbackprojection = false\n",
        );
        let got = load_params(&p, 512).unwrap().params;
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
        assert_errors_name_keys(
            &[
                ("p_low = \"high\"\n", "p_low"),
                ("area_min = 2.5\n", "area_min"),
                ("margin = -4\n", "margin"),
                ("hist_bins = 300\n", "hist_bins"),
                ("double_threshold = 1\n", "double_threshold"),
                ("tracker = \"kalman\"\n", "tracker"),
            ],
            2048,
        );
    }

    #[test]
    fn validation_failure_names_key() {
        assert_errors_name_keys(
            &[
                ("alpha = 1.5\n", "alpha"),
                ("p_high = 0.9\np_low = 0.5\n", "p_high"),
                ("hist_bins = 12\n", "hist_bins"),
                ("disk_size = 6\n", "disk_size"),
                // Given area_max is below the *scaled* default area_min (125 at 512 px).
                ("area_max = 100\n", "area_max"),
                ("theta_sad = nan\n", "theta_sad"),
            ],
            512,
        );
        // Valid once area_min is given too (taken as-is at any width).
        let (_t, p) = write("area_max = 100\narea_min = 50\n");
        assert_eq!(load_params(&p, 2048).unwrap().params.area_max, 100);
    }

    #[test]
    fn track_table_overrides_the_tracker_and_names_bad_keys() {
        let (_t, p) =
            write("p_low = 0.9\n[track]\nmax_lost = 0\nmiss_cost = 30\nfold_shared = false\nnewborn_reverse_cost = inf\nconfirm_births = 0\n");
        let f = load_params(&p, 2048).unwrap();
        assert_eq!(f.params.p_low, 0.9);
        let mut cfg = TrackConfig::for_frame(2048, 2048);
        f.track.apply(&mut cfg);
        let want = TrackConfig {
            max_lost: 0,
            miss_cost: 30.0,
            fold_shared: false,
            newborn_reverse_cost: f32::INFINITY,
            confirm_births: 0,
            ..TrackConfig::for_frame(2048, 2048)
        };
        assert_eq!(cfg, want);
        assert_errors_name_keys(
            &[
                ("[track]\nmax_los = 1\n", "track.max_los"),
                ("[track]\nmax_lost = -1\n", "track.max_lost"),
                ("[track]\nmax_lost = 15\n", "track.max_lost"),
                ("[track]\nmiss_cost = 0\n", "track.miss_cost"),
                ("[track]\nfold_shared = 1\n", "track.fold_shared"),
                (
                    "[track]\nnewborn_reverse_cost = -1\n",
                    "track.newborn_reverse_cost",
                ),
                (
                    "[track]\nnewborn_reverse_cost = nan\n",
                    "track.newborn_reverse_cost",
                ),
                ("[track]\nconfirm_births = -1\n", "track.confirm_births"),
                ("[track]\nconfirm_births = 300\n", "track.confirm_births"),
                ("[track]\nconfirm_min_step = -1\n", "track.confirm_min_step"),
                ("track = 3\n", "track"),
            ],
            2048,
        );
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
