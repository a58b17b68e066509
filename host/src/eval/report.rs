//! The evaluation report: a table for people, JSON (`--json`) for scripts.
//! Ratios are fractions in JSON (0.05 = 5 %), `null` where undefined
//! (e.g. precision with no prediction); the table prints percentages.

use std::fmt::Write as _;

use serde::Serialize;

use super::metrics::{DetectionScore, LengthScore, SegmentationScore, TrackingScore};
use super::mot::MotSummary;
use super::stereo::StereoScore;

/// Everything `fishtrack eval` measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Frames in the haul.
    pub frames: u32,
    /// Fish in the truth.
    pub truth_fish: u64,
    /// Fish with ≥ 1 countable frame (visible left area ≥ θ_A^L).
    pub countable_fish: u64,
    /// θ_A^L used, pixels.
    pub area_min_px: f64,
    /// Minimum IoU of a match.
    pub iou_min: f64,
    /// From tracks.csv (+ fish.csv).
    pub tracking: Option<TrackingScore>,
    /// From detections.csv.
    pub segmentation: Option<SegmentationScore>,
    /// From stereo.csv.
    pub stereo: Option<StereoScore>,
}

fn pct(x: f64) -> String {
    if x.is_finite() {
        format!("{:.2} %", 100.0 * x)
    } else {
        "n/a".into()
    }
}

fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.4}")
    } else {
        "n/a".into()
    }
}

struct Table(String);

impl Table {
    fn row(&mut self, name: &str, value: String) {
        let _ = writeln!(self.0, "  {name:<38} {value:>14}");
    }
    fn head(&mut self, title: &str) {
        let _ = writeln!(self.0, "{title}");
    }
    fn detection(&mut self, d: &DetectionScore) {
        self.row("precision (micro)", pct(d.precision));
        self.row("recall (micro)", pct(d.recall));
        self.row("precision (mean per frame)", pct(d.mean_frame_precision));
        self.row("recall (mean per frame)", pct(d.mean_frame_recall));
        self.row(
            "TP / FP / FN / ignored",
            format!("{} / {} / {} / {}", d.tp, d.fp, d.fn_, d.ignored),
        );
    }
    fn length(&mut self, what: &str, l: &LengthScore) {
        self.row(&format!("{what} MAPE"), pct(l.mape));
        self.row(
            &format!("{what} measured"),
            format!(
                "{}/{} ({})",
                l.measured,
                l.measurable,
                pct(l.fraction_measured)
            ),
        );
    }
    fn mot(&mut self, m: &MotSummary) {
        self.row("MOTA", num(m.mota));
        self.row("IDF1", num(m.idf1));
        self.row("ID switches", m.num_switches.to_string());
        self.row("MOTP (1 - IoU)", num(m.motp));
        self.row("IDP / IDR", format!("{} / {}", num(m.idp), num(m.idr)));
        self.row(
            "MT / PT / ML",
            format!(
                "{} / {} / {}",
                m.mostly_tracked, m.partially_tracked, m.mostly_lost
            ),
        );
        self.row("fragmentations", m.num_fragmentations.to_string());
    }
    fn tracking(&mut self, t: &TrackingScore) {
        self.head("tracking (tracks.csv)");
        self.detection(&t.detection);
        self.mot(&t.mot);
        self.row(
            "success rate (eq. 16)",
            format!(
                "{} ({}/{})",
                pct(t.success.rate),
                t.success.correctly_labelled,
                t.success.fish
            ),
        );
        if let Some(d) = &t.success_detected {
            self.row(
                "success among detected fish",
                format!("{} ({}/{})", pct(d.rate), d.correctly_labelled, d.fish),
            );
        }
        self.row(
            "count error",
            format!(
                "{} ({} tracks, {} fish)",
                pct(t.count.error),
                t.count.tracks,
                t.count.fish
            ),
        );
        match &t.length {
            Some(l) => self.length("fish length (fish.csv)", l),
            None => self.row("fish length", "no fish.csv".into()),
        }
    }
    fn segmentation(&mut self, s: &SegmentationScore) {
        self.head("segmentation (detections.csv)");
        self.detection(&s.detection);
        match &s.large_target_length {
            Some(l) => self.length("large-target 2-D length", l),
            None => self.row(
                "large-target 2-D length",
                "truth has no pixel points".into(),
            ),
        }
        self.row("2-D length from", s.length_source.into());
    }
    fn stereo(&mut self, s: &StereoScore) {
        self.head("stereo (stereo.csv)");
        self.row(
            "pairing accuracy",
            format!(
                "{} ({}/{})",
                pct(s.pairing_accuracy),
                s.correctly_paired,
                s.fish_frames
            ),
        );
        self.row(
            "pairing accuracy (segmented)",
            format!(
                "{} ({}/{})",
                pct(s.pairing_accuracy_detected),
                s.correctly_paired,
                s.detected
            ),
        );
        self.row(
            "wrongly paired / unpaired",
            format!("{} / {}", s.wrongly_paired, s.unpaired),
        );
        self.length("per-frame 3-D length", &s.length);
    }
}

impl Report {
    /// The human-readable table.
    pub fn table(&self) -> String {
        let mut t = Table(String::new());
        let _ = writeln!(
            t.0,
            "fishtrack eval: {} frames, {} fish ({} countable: left area >= {} px), match IoU >= {}",
            self.frames, self.truth_fish, self.countable_fish, self.area_min_px, self.iou_min
        );
        if let Some(x) = &self.tracking {
            t.tracking(x);
        }
        if let Some(x) = &self.segmentation {
            t.segmentation(x);
        }
        if let Some(x) = &self.stereo {
            t.stereo(x);
        }
        t.0
    }

    /// The JSON form (`--json`).
    pub fn json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }
}
