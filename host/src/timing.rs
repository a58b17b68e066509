//! `fishtrack timing-check`: the strobe/camera timing bench check over a
//! serial line.
//!
//! The host configures the housing processor ([`fishtrack_core::link`]),
//! runs a bench sequence of N frames and gets back, per frame, the times of
//! the six edges the device's pins produced (left/right trigger rise/fall,
//! strobe rise/fall). From them it measures what the footage of the paper
//! depends on (Cam-trawl stereo pairs at 5 fps, Section V; segmentation of
//! Section III needs evenly lit frames, stereo matching of Section IV.A
//! needs simultaneous left/right exposures) and compares against
//! [`Tolerances`]:
//!
//! - frame period error: `max |(t[n+1] − t[n]) − T|` over consecutive
//!   trigger rises of each camera, `T = 1 s / fps`;
//! - trigger jitter: residuals of each camera's trigger rises from their
//!   least-squares line `t = a + b·n` (max and RMS);
//! - left/right trigger skew: `max |t_L[n] − t_R[n]|`;
//! - strobe-to-exposure overlap margin: per frame and camera, the exposure
//!   is `[rise, rise + exposure_us]`; start margin = rise − strobe on, end
//!   margin = strobe off − exposure end; the minimum over frames;
//! - missing edges, frames reported, and frames lost to line corruption.

use std::fmt::Write as _;
use std::io::ErrorKind;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context};
use fishtrack_core::link::{self, Command, Decoder, FrameEdges, LinkError, Report, MAX_FRAME};
use fishtrack_core::strobe::StrobeConfig;

use crate::InputError;

/// How long the device may stay silent before the check gives up.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(3);
/// Largest accepted `--frames`.
pub const MAX_FRAMES: u32 = 100_000;

/// Pass limits of the bench check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Max |period − T|, µs. 100 µs is 0.05 % of the 200 ms Cam-trawl
    /// period; the tracker predicts positions with one velocity per frame
    /// step (Section IV.B, eqs. (7)–(14)), and a fish at 2 m/s moves 0.2 mm
    /// in 100 µs, far below a pixel. A timer-driven trigger is µs-exact, so
    /// anything larger means software timing or a stalled loop.
    pub period_error_us: f64,
    /// Max trigger jitter (residual from the fitted frame grid), µs. 50 µs
    /// is a tenth of the default 500 µs strobe margins: jitter this large
    /// already eats into them.
    pub jitter_max_us: f64,
    /// RMS trigger jitter, µs (20 µs: steady timing, not just one outlier).
    pub jitter_rms_us: f64,
    /// Max left/right trigger skew, µs. Stereo pairing and triangulation
    /// (Section IV.A, IV.D) assume simultaneous exposures: at 2 m/s a fish
    /// moves 40 µm in 20 µs, under a tenth of a pixel. A shared trigger
    /// line has ~0 skew; separate lines must stay within this.
    pub skew_us: f64,
    /// Min strobe-to-exposure margin at each end of the exposure, µs. 50 µs
    /// covers an LED driver's rise/fall time (1–20 µs) and a global-shutter
    /// camera's trigger-to-exposure latency (~10–30 µs).
    pub overlap_margin_us: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            period_error_us: 100.0,
            jitter_max_us: 50.0,
            jitter_rms_us: 20.0,
            skew_us: 20.0,
            overlap_margin_us: 50.0,
        }
    }
}

/// Frames the host had to discard.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LineStats {
    /// Frames discarded (garbage, truncated, bad CRC).
    pub bad_frames: u32,
    /// Bytes in them.
    pub bad_bytes: u32,
}

/// One line of the result table.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckLine {
    /// What is checked.
    pub name: &'static str,
    /// Measured value, formatted.
    pub measured: String,
    /// Tolerance, formatted.
    pub tolerance: String,
    /// Within tolerance.
    pub pass: bool,
    /// Where it went wrong (frames, lines), empty when fine.
    pub note: String,
}

fn line(
    name: &'static str,
    measured: String,
    tolerance: String,
    pass: bool,
    note: String,
) -> CheckLine {
    CheckLine {
        name,
        measured,
        tolerance,
        pass,
        note,
    }
}

fn frame_list(frames: &[u32]) -> String {
    let mut s = String::new();
    for (i, f) in frames.iter().enumerate() {
        if i == 8 {
            let _ = write!(s, ", … ({} frames)", frames.len());
            break;
        }
        if i > 0 {
            s.push_str(", ");
        }
        let _ = write!(s, "{f}");
    }
    s
}

/// Residuals of `(n, t)` from their least-squares line.
fn residuals(points: &[(f64, f64)]) -> Vec<f64> {
    let k = points.len() as f64;
    if points.len() < 2 {
        return vec![0.0; points.len()];
    }
    let mn = points.iter().map(|p| p.0).sum::<f64>() / k;
    let mt = points.iter().map(|p| p.1).sum::<f64>() / k;
    let sxx: f64 = points.iter().map(|p| (p.0 - mn) * (p.0 - mn)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mn) * (p.1 - mt)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    points.iter().map(|p| p.1 - (mt + b * (p.0 - mn))).collect()
}

/// Measure the reported edges against the configuration and tolerances.
pub fn analyse(
    config: &StrobeConfig,
    requested: u32,
    edges: &[FrameEdges],
    line_stats: LineStats,
    tol: &Tolerances,
) -> Vec<CheckLine> {
    let mut out = Vec::new();
    let period = f64::from(config.period_us());
    let exposure = u64::from(config.exposure_us);

    // Frames reported.
    let got = edges.len() as u32;
    out.push(line(
        "frames reported",
        format!("{got}/{requested}"),
        "all".into(),
        got == requested,
        String::new(),
    ));

    // Missing edges.
    let mut missing = 0u32;
    let mut missing_notes: Vec<String> = Vec::new();
    let names = [
        "trigger L rise",
        "trigger L fall",
        "trigger R rise",
        "trigger R fall",
        "strobe on",
        "strobe off",
    ];
    for (k, name) in names.iter().enumerate() {
        let frames: Vec<u32> = edges
            .iter()
            .filter(|e| {
                [
                    e.trigger_left_rise,
                    e.trigger_left_fall,
                    e.trigger_right_rise,
                    e.trigger_right_fall,
                    e.strobe_rise,
                    e.strobe_fall,
                ][k]
                    .is_none()
            })
            .map(|e| e.frame)
            .collect();
        if !frames.is_empty() {
            missing += frames.len() as u32;
            missing_notes.push(format!("{name} missing in frames {}", frame_list(&frames)));
        }
    }
    let dropped_trigger = missing_notes.iter().any(|n| n.starts_with("trigger"));
    let mut note = missing_notes.join("; ");
    if dropped_trigger {
        note = format!("dropped trigger: {note}");
    }
    out.push(line(
        "missing edges",
        format!("{missing}"),
        "0".into(),
        missing == 0,
        note,
    ));

    // Period error and jitter, per camera.
    type Rise = fn(&FrameEdges) -> Option<u64>;
    let cams: [(&str, Rise); 2] = [
        ("L", |e| e.trigger_left_rise),
        ("R", |e| e.trigger_right_rise),
    ];
    let mut period_err: Option<(f64, u32, &str)> = None;
    let mut jit_max: Option<(f64, u32, &str)> = None;
    let mut jit_sq = 0.0;
    let mut jit_n = 0usize;
    for (cam, rise) in cams {
        let pts: Vec<(u32, u64)> = edges
            .iter()
            .filter_map(|e| rise(e).map(|t| (e.frame, t)))
            .collect();
        for w in pts.windows(2) {
            let (f0, t0) = w[0];
            let (f1, t1) = w[1];
            if f1 == f0 + 1 {
                let err = ((t1 as f64 - t0 as f64) - period).abs();
                if period_err.is_none_or(|p| err > p.0) {
                    period_err = Some((err, f1, cam));
                }
            }
        }
        let fpts: Vec<(f64, f64)> = pts.iter().map(|&(f, t)| (f64::from(f), t as f64)).collect();
        for (r, &(f, _)) in residuals(&fpts).iter().zip(&pts) {
            jit_sq += r * r;
            jit_n += 1;
            if jit_max.is_none_or(|j| r.abs() > j.0) {
                jit_max = Some((r.abs(), f, cam));
            }
        }
    }
    out.push(match period_err {
        Some((e, f, cam)) => line(
            "frame period error (max)",
            format!("{e:.0} us"),
            format!("<= {:.0} us", tol.period_error_us),
            e <= tol.period_error_us,
            if e > tol.period_error_us {
                format!("jitter: worst period ends at frame {f} (trigger {cam})")
            } else {
                String::new()
            },
        ),
        None => line(
            "frame period error (max)",
            "n/a".into(),
            format!("<= {:.0} us", tol.period_error_us),
            false,
            "no two consecutive frames with trigger edges".into(),
        ),
    });
    let (jm, jf, jc) = jit_max.unwrap_or((f64::INFINITY, 0, "-"));
    let rms = if jit_n > 0 {
        (jit_sq / jit_n as f64).sqrt()
    } else {
        f64::INFINITY
    };
    out.push(line(
        "trigger jitter (max)",
        format!("{jm:.1} us"),
        format!("<= {:.0} us", tol.jitter_max_us),
        jm <= tol.jitter_max_us,
        if jm > tol.jitter_max_us {
            format!("jitter: worst at frame {jf} (trigger {jc})")
        } else {
            String::new()
        },
    ));
    out.push(line(
        "trigger jitter (RMS)",
        format!("{rms:.1} us"),
        format!("<= {:.0} us", tol.jitter_rms_us),
        rms <= tol.jitter_rms_us,
        if rms > tol.jitter_rms_us {
            "jitter".into()
        } else {
            String::new()
        },
    ));

    // Skew.
    let skew = edges
        .iter()
        .filter_map(|e| {
            Some((
                e.trigger_left_rise?.abs_diff(e.trigger_right_rise?),
                e.frame,
            ))
        })
        .max();
    out.push(match skew {
        Some((s, f)) => line(
            "left/right trigger skew (max)",
            format!("{s} us"),
            format!("<= {:.0} us", tol.skew_us),
            s as f64 <= tol.skew_us,
            if s as f64 > tol.skew_us {
                format!("worst at frame {f}")
            } else {
                String::new()
            },
        ),
        None => line(
            "left/right trigger skew (max)",
            "n/a".into(),
            format!("<= {:.0} us", tol.skew_us),
            false,
            "no frame with both triggers".into(),
        ),
    });

    // Strobe-to-exposure overlap margins.
    let mut start: Option<(i64, u32)> = None;
    let mut end: Option<(i64, u32)> = None;
    let mut bad_start = Vec::new();
    let mut bad_end = Vec::new();
    for e in edges {
        let (Some(on), Some(off)) = (e.strobe_rise, e.strobe_fall) else {
            continue;
        };
        let mut fs = i64::MAX;
        let mut fe = i64::MAX;
        for rise in [e.trigger_left_rise, e.trigger_right_rise]
            .into_iter()
            .flatten()
        {
            fs = fs.min(rise as i64 - on as i64);
            fe = fe.min(off as i64 - (rise + exposure) as i64);
        }
        if fs == i64::MAX {
            continue;
        }
        if (fs as f64) < tol.overlap_margin_us {
            bad_start.push(e.frame);
        }
        if (fe as f64) < tol.overlap_margin_us {
            bad_end.push(e.frame);
        }
        if start.is_none_or(|s| fs < s.0) {
            start = Some((fs, e.frame));
        }
        if end.is_none_or(|s| fe < s.0) {
            end = Some((fe, e.frame));
        }
    }
    let margin_tol = format!(">= {:.0} us", tol.overlap_margin_us);
    for (name, m, bad, what) in [
        (
            "strobe-to-exposure margin, start (min)",
            start,
            bad_start,
            "late strobe: exposure starts before the strobe is on",
        ),
        (
            "strobe-to-exposure margin, end (min)",
            end,
            bad_end,
            "short strobe: strobe off before the exposure ends",
        ),
    ] {
        out.push(match m {
            Some((v, _)) => {
                let pass = v as f64 >= tol.overlap_margin_us;
                let note = if pass {
                    String::new()
                } else {
                    format!("{what} (frames {})", frame_list(&bad))
                };
                line(name, format!("{v} us"), margin_tol.clone(), pass, note)
            }
            None => line(
                name,
                "n/a".into(),
                margin_tol.clone(),
                false,
                "no frame with strobe and trigger edges".into(),
            ),
        });
    }

    // Line integrity.
    out.push(line(
        "serial frames discarded",
        format!("{} ({} bytes)", line_stats.bad_frames, line_stats.bad_bytes),
        "0".into(),
        line_stats.bad_frames == 0,
        if line_stats.bad_frames > 0 {
            "garbage on the line (resynchronised at the next delimiter)".into()
        } else {
            String::new()
        },
    ));
    out
}

/// The table, one line per check.
pub fn render(lines: &[CheckLine]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<40} {:>16}  {:<11} result",
        "check", "measured", "tolerance"
    );
    for l in lines {
        let _ = write!(
            s,
            "{:<40} {:>16}  {:<11} {}",
            l.name,
            l.measured,
            l.tolerance,
            if l.pass { "PASS" } else { "FAIL" }
        );
        if !l.note.is_empty() {
            let _ = write!(s, "  {}", l.note);
        }
        s.push('\n');
    }
    s
}

/// The host end of the link: framed commands out, reports in.
struct Client {
    port: Box<dyn serialport::SerialPort>,
    name: String,
    decoder: Decoder,
    buf: [u8; 512],
    pos: usize,
    len: usize,
}

impl Client {
    fn send(&mut self, cmd: &Command) -> anyhow::Result<()> {
        let mut out = [0u8; MAX_FRAME];
        let n = link::encode(cmd, &mut out).map_err(|e| anyhow!("encoding {cmd:?}: {e}"))?;
        self.port
            .write_all(&out[..n])
            .and_then(|_| self.port.flush())
            .with_context(|| format!("{}: serial write failed", self.name))
    }

    fn stats(&self) -> LineStats {
        let s = self.decoder.stats();
        LineStats {
            bad_frames: s.errors,
            bad_bytes: s.discarded_bytes,
        }
    }

    /// The next intact report; device errors and protocol mismatches abort.
    fn recv(&mut self, waiting_for: &str) -> anyhow::Result<Report> {
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        loop {
            while self.pos < self.len {
                let b = self.buf[self.pos];
                self.pos += 1;
                match self.decoder.push::<Report>(b) {
                    None | Some(Err(LinkError::Truncated | LinkError::BadCrc { .. })) => {}
                    Some(Ok(Report::Error(e))) => {
                        bail!("{}: device error ({:?}): {}", self.name, e.code, e.detail)
                    }
                    Some(Ok(r)) => return Ok(r),
                    Some(Err(LinkError::Version { got, expected })) => bail!(
                        "{}: device speaks protocol version {got}, expected {expected} \
                         (update the firmware or fishtrack so both match)",
                        self.name
                    ),
                    Some(Err(_)) => {}
                }
            }
            if Instant::now() >= deadline {
                bail!(
                    "{}: device stopped answering: nothing for {} s while waiting for {waiting_for}",
                    self.name,
                    ANSWER_TIMEOUT.as_secs()
                );
            }
            match self.port.read(&mut self.buf) {
                Ok(n) => {
                    self.pos = 0;
                    self.len = n;
                }
                Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {
                }
                Err(e) => bail!("{}: serial read failed: {e}", self.name),
            }
        }
    }

    fn status(&mut self, what: &str) -> anyhow::Result<link::Status> {
        loop {
            if let Report::Status(s) = self.recv(what)? {
                return Ok(s);
            }
        }
    }
}

/// Run the bench check on `port` for `frames` frames with the default
/// timing; prints the table. `Err` when a check fails (exit 1) or the
/// input is bad (exit 2).
pub fn run(port: &Path, frames: u32) -> anyhow::Result<()> {
    if frames == 0 || frames > MAX_FRAMES {
        return Err(InputError::plain(
            "--frames",
            format!("must be 1..={MAX_FRAMES}, got {frames}"),
        )
        .into());
    }
    let config = StrobeConfig::default();
    let name = port.display().to_string();
    let p = serialport::new(port.to_string_lossy(), 115_200)
        .timeout(Duration::from_millis(100))
        .open()
        .map_err(|e| InputError::file(port, format!("cannot open serial port: {e}")))?;
    let _ = p.clear(serialport::ClearBuffer::All);
    let mut c = Client {
        port: p,
        name,
        decoder: Decoder::new(),
        buf: [0; 512],
        pos: 0,
        len: 0,
    };

    // Stop a free-running device; its Status answer also proves the version.
    c.send(&Command::Stop)?;
    c.status("the status answer")?;
    c.send(&Command::Configure(config))?;
    let st = c.status("the configuration answer")?;
    if st.config != config {
        bail!(
            "{}: device kept timing {:?}, asked for {:?}",
            c.name,
            st.config,
            config
        );
    }
    c.send(&Command::RunBench { frames })?;
    let mut edges: Vec<FrameEdges> = Vec::new();
    loop {
        match c.recv(&format!("frame {} of {frames}", edges.len()))? {
            Report::Edges(e) => edges.push(e),
            Report::BenchDone { .. } => break,
            _ => {}
        }
    }
    let tol = Tolerances::default();
    let lines = analyse(&config, frames, &edges, c.stats(), &tol);
    crate::outln!(
        "fishtrack timing-check: {} (protocol {}), {frames} frames at {} fps",
        c.name,
        link::PROTOCOL_VERSION,
        config.fps
    )?;
    crate::outln!(
        "timing: exposure {} us, strobe lead {} us, strobe width {} us, trigger width {} us, period {} us",
        config.exposure_us, config.strobe_lead_us, config.strobe_width_us, config.trigger_width_us,
        config.period_us()
    )?;
    crate::outln!()?;
    crate::out!("{}", render(&lines))?;
    let failed: Vec<&CheckLine> = lines.iter().filter(|l| !l.pass).collect();
    if failed.is_empty() {
        crate::outln!("\nRESULT: PASS")?;
        Ok(())
    } else {
        crate::outln!(
            "\nRESULT: FAIL ({} of {} checks)",
            failed.len(),
            lines.len()
        )?;
        let mut msg = String::from("timing check failed:");
        for l in failed {
            let _ = write!(
                msg,
                "\n  {}: {} (tolerance {})",
                l.name, l.measured, l.tolerance
            );
            if !l.note.is_empty() {
                let _ = write!(msg, " — {}", l.note);
            }
        }
        Err(anyhow!(msg))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: u64 = 200_000;

    /// Ideal edges of the default timing; `f(n, &mut edges)` perturbs them.
    fn frames(n: u32, f: impl Fn(u32, &mut FrameEdges)) -> Vec<FrameEdges> {
        (0..n)
            .map(|i| {
                let t0 = 1_000 + T * u64::from(i);
                let mut e = FrameEdges {
                    frame: i,
                    strobe_rise: Some(t0),
                    trigger_left_rise: Some(t0 + 500),
                    trigger_right_rise: Some(t0 + 500),
                    trigger_left_fall: Some(t0 + 600),
                    trigger_right_fall: Some(t0 + 600),
                    strobe_fall: Some(t0 + 3_000),
                };
                f(i, &mut e);
                e
            })
            .collect()
    }

    fn check(edges: &[FrameEdges], stats: LineStats) -> Vec<CheckLine> {
        analyse(
            &StrobeConfig::default(),
            4,
            edges,
            stats,
            &Tolerances::default(),
        )
    }

    fn get<'a>(lines: &'a [CheckLine], name: &str) -> &'a CheckLine {
        lines.iter().find(|l| l.name == name).unwrap()
    }

    fn shift(e: &mut FrameEdges, d: i64) {
        for t in [
            &mut e.strobe_rise,
            &mut e.strobe_fall,
            &mut e.trigger_left_rise,
            &mut e.trigger_left_fall,
            &mut e.trigger_right_rise,
            &mut e.trigger_right_fall,
        ] {
            *t = t.map(|v| (v as i64 + d) as u64);
        }
    }

    #[test]
    fn ideal_edges_pass_with_exact_margins() {
        let l = check(&frames(4, |_, _| {}), LineStats::default());
        assert!(l.iter().all(|l| l.pass), "{}", render(&l));
        assert_eq!(
            get(&l, "strobe-to-exposure margin, start (min)").measured,
            "500 us"
        );
        assert_eq!(
            get(&l, "strobe-to-exposure margin, end (min)").measured,
            "500 us"
        );
        assert_eq!(get(&l, "frame period error (max)").measured, "0 us");
        assert_eq!(get(&l, "left/right trigger skew (max)").measured, "0 us");
    }

    #[test]
    fn jitter_pattern_with_known_fit() {
        // Offsets +d, −d, −d, +d: the fitted slope is exactly T, so the
        // residuals are ±d: max d, RMS d; periods T−2d, T, T+2d.
        let d = 60;
        let l = check(
            &frames(4, |i, e| shift(e, [d, -d, -d, d][i as usize])),
            LineStats::default(),
        );
        assert_eq!(get(&l, "trigger jitter (max)").measured, "60.0 us");
        assert_eq!(get(&l, "trigger jitter (RMS)").measured, "60.0 us");
        assert_eq!(get(&l, "frame period error (max)").measured, "120 us");
        assert!(!get(&l, "trigger jitter (max)").pass);
        assert!(get(&l, "trigger jitter (max)").note.contains("jitter"));
        // The whole frame moved: margins and skew are intact.
        assert!(get(&l, "left/right trigger skew (max)").pass);
        assert!(get(&l, "strobe-to-exposure margin, start (min)").pass);
    }

    #[test]
    fn skew_late_and_short_strobe_and_dropped_trigger_are_named() {
        let l = check(
            &frames(4, |i, e| {
                if i == 2 {
                    e.trigger_right_rise = e.trigger_right_rise.map(|t| t + 30);
                }
            }),
            LineStats::default(),
        );
        let s = get(&l, "left/right trigger skew (max)");
        assert_eq!((s.measured.as_str(), s.pass), ("30 us", false));
        assert!(s.note.contains("frame 2"));

        let l = check(
            &frames(4, |_, e| e.strobe_rise = e.strobe_rise.map(|t| t + 800)),
            LineStats::default(),
        );
        let s = get(&l, "strobe-to-exposure margin, start (min)");
        assert_eq!((s.measured.as_str(), s.pass), ("-300 us", false));
        assert!(s.note.starts_with("late strobe"));

        let l = check(
            &frames(4, |_, e| e.strobe_fall = e.strobe_fall.map(|t| t - 1_500)),
            LineStats::default(),
        );
        let s = get(&l, "strobe-to-exposure margin, end (min)");
        assert_eq!((s.measured.as_str(), s.pass), ("-1000 us", false));
        assert!(s.note.starts_with("short strobe"));

        let l = check(
            &frames(4, |i, e| {
                if i == 1 {
                    e.trigger_right_rise = None;
                    e.trigger_right_fall = None;
                }
            }),
            LineStats::default(),
        );
        let m = get(&l, "missing edges");
        assert_eq!((m.measured.as_str(), m.pass), ("2", false));
        assert!(
            m.note.contains("dropped trigger")
                && m.note.contains("trigger R rise missing in frames 1")
        );
    }

    #[test]
    fn garbage_and_missing_frames_fail() {
        let l = check(
            &frames(3, |_, _| {}),
            LineStats {
                bad_frames: 2,
                bad_bytes: 17,
            },
        );
        let g = get(&l, "serial frames discarded");
        assert_eq!((g.measured.as_str(), g.pass), ("2 (17 bytes)", false));
        assert!(g.note.contains("garbage"));
        assert!(!get(&l, "frames reported").pass);
        let l = check(&[], LineStats::default());
        assert!(l.iter().filter(|l| !l.pass).count() >= 5);
    }

    #[test]
    fn bad_frame_count_is_input_error() {
        let e = run(Path::new("/nonexistent"), 0).unwrap_err();
        assert_eq!(crate::error::exit_code(&e), 2);
        let e = run(Path::new("/nonexistent/tty"), 5).unwrap_err();
        assert_eq!(crate::error::exit_code(&e), 2);
        assert!(e.to_string().contains("/nonexistent/tty"));
    }
}
