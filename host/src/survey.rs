//! A survey: `fishtrack track HAUL... --out DIR` over several hauls, and the
//! rules that make every output folder trustworthy after an interruption.
//!
//! - One haul: its outputs go straight into `DIR` (DESIGN.md, "Output").
//! - Several hauls: tracked in parallel (rayon's pool, one worker per core,
//!   so at most that many hauls are in memory at once), each into
//!   `DIR/<haul directory name>/` (hauls on their own pool of
//!   [`HAUL_STACK_BYTES`]-stack threads), then `DIR/survey.csv` with one row per
//!   haul in the order given: `haul,fish_count,length_mean_mm,length_sd_mm,
//!   fish_measured,frames` (mean and sample SD of the measured fish's
//!   lengths; empty when no fish, resp. fewer than two, were measured).
//!   Two hauls with the same directory name are refused before any work.
//!   If a haul fails, the others still run to the end; every failure is
//!   printed, the first one (in the order given) decides the exit code, and
//!   `survey.csv` is not written, so a survey table always covers every
//!   haul asked for.
//! - Completion marker: before writing anything, a run deletes the folder's
//!   `summary.json` and any `.partial` temporary files an interrupted run
//!   left behind; every file is written atomically (temp file + rename) and
//!   `summary.json` is written last. So a folder with a `summary.json` is
//!   complete, a folder without one is not, and no file in it is ever
//!   half-written. `survey.csv` is written after every haul's `summary.json`.

use std::path::{Path, PathBuf};

use anyhow::Result;
use rayon::prelude::*;

use crate::error::InputError;
use crate::output::write_atomic;
use crate::track_cmd::{track_haul, HaulOutcome, TrackOptions};

/// Stack of a haul worker thread (the main thread's 8 MiB).
pub const HAUL_STACK_BYTES: usize = 8 << 20;

/// `survey.csv`'s header.
pub const SURVEY_HEADER: [&str; 6] = [
    "haul",
    "fish_count",
    "length_mean_mm",
    "length_sd_mm",
    "fish_measured",
    "frames",
];

/// The name of a haul: its directory's name (resolved for `.` and `..`).
pub fn haul_name(dir: &Path) -> String {
    dir.file_name()
        .filter(|n| *n != "." && *n != "..")
        .map(|n| n.to_string_lossy().into_owned())
        .or_else(|| {
            dir.canonicalize()
                .ok()
                .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        })
        .unwrap_or_else(|| "haul".into())
}

/// A haul name cut to 12 characters, for progress-bar labels.
pub fn short_name(dir: &Path) -> String {
    let n = haul_name(dir);
    if n.chars().count() > 12 {
        n.chars().take(11).chain(['…']).collect()
    } else {
        n
    }
}

/// Removes `.*.partial` temporary files an interrupted run left in `dir`
/// (best effort; only files this program names that way).
pub fn remove_partials(dir: &Path) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') && name.ends_with(".partial") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Makes `out` ready for a run: creates it, checks it is writable, deletes
/// the completion marker `summary.json` and stale temporary files. A folder
/// that cannot be created or written is bad input (exit code 2), named.
pub fn prepare_out_dir(out: &Path) -> Result<(), InputError> {
    std::fs::create_dir_all(out)
        .map_err(|e| InputError::file(out, format!("cannot create the output directory: {e}")))?;
    tempfile::Builder::new()
        .prefix(".fishtrack-probe.")
        .suffix(".partial")
        .tempfile_in(out)
        .map_err(|e| InputError::file(out, format!("output directory is not writable: {e}")))?;
    let marker = out.join("summary.json");
    if marker.exists() {
        std::fs::remove_file(&marker).map_err(|e| {
            InputError::file(&marker, format!("cannot remove the previous summary: {e}"))
        })?;
    }
    remove_partials(out);
    Ok(())
}

/// One `survey.csv` row.
#[derive(Debug, Clone, PartialEq)]
pub struct SurveyRow {
    /// Haul name.
    pub haul: String,
    /// Fish counted.
    pub fish_count: usize,
    /// Mean length of the measured fish, mm.
    pub length_mean_mm: Option<f64>,
    /// Sample SD of the measured fish's lengths, mm (n ≥ 2).
    pub length_sd_mm: Option<f64>,
    /// Fish with a length.
    pub fish_measured: usize,
    /// Frames tracked.
    pub frames: u32,
}

impl SurveyRow {
    /// The row of one haul's outcome.
    pub fn new(haul: String, o: &HaulOutcome) -> Self {
        let n = o.lengths.len();
        let mean = (n > 0).then(|| o.lengths.iter().sum::<f64>() / n as f64);
        let sd = mean.filter(|_| n > 1).map(|m| {
            (o.lengths.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        });
        SurveyRow {
            haul,
            fish_count: o.fish,
            length_mean_mm: mean,
            length_sd_mm: sd,
            fish_measured: n,
            frames: o.frames,
        }
    }
}

fn num(v: Option<f64>) -> String {
    v.map(|x| format!("{}", (x * 1000.0).round() / 1000.0))
        .unwrap_or_default()
}

/// Writes `survey.csv` atomically.
pub fn write_survey(path: &Path, rows: &[SurveyRow]) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "{}", SURVEY_HEADER.join(","))?;
        for r in rows {
            let haul = if r.haul.contains([',', '"', '\n']) {
                format!("\"{}\"", r.haul.replace('"', "\"\""))
            } else {
                r.haul.clone()
            };
            writeln!(
                w,
                "{haul},{},{},{},{},{}",
                r.fish_count,
                num(r.length_mean_mm),
                num(r.length_sd_mm),
                r.fish_measured,
                r.frames
            )?;
        }
        Ok(())
    })
}

fn report(h: &Path, dest: &Path, o: &HaulOutcome) -> Result<()> {
    crate::outln!(
        "{}: {} frames, {} fish ({} measured), {:.2} s/frame → {}",
        h.display(),
        o.frames,
        o.fish,
        o.lengths.len(),
        o.seconds_per_frame,
        dest.display()
    )
}

/// `fishtrack track HAUL... --out DIR` (see the module documentation).
pub fn run(hauls: &[PathBuf], out: &Path, opts: &TrackOptions) -> Result<()> {
    if let [one] = hauls {
        let o = track_haul(one, out, opts)?;
        return report(one, out, &o);
    }
    let names: Vec<String> = hauls.iter().map(|h| haul_name(h)).collect();
    for (i, n) in names.iter().enumerate() {
        if let Some(j) = names[..i].iter().position(|m| m == n) {
            return Err(InputError::file(
                &hauls[i],
                format!(
                    "has the same name `{n}` as {}: their outputs would share DIR/{n}/",
                    hauls[j].display()
                ),
            )
            .into());
        }
    }
    prepare_out_dir_plain(out)?;
    // Own pool: bounded by the cores, and with main-thread-sized stacks
    // (the pipeline's setup needs more than rayon's default 2 MiB).
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(hauls.len());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers)
        .stack_size(HAUL_STACK_BYTES)
        .thread_name(|i| format!("haul-{i}"))
        .build()?;
    let results: Vec<Result<HaulOutcome>> = pool.install(|| {
        hauls
            .par_iter()
            .zip(&names)
            .map(|(h, n)| track_haul(h, &out.join(n), opts))
            .collect()
    });
    let mut rows = Vec::new();
    let mut first_err = None;
    // an error printing must not stop the survey's files
    let mut print_err = None;
    for ((h, n), r) in hauls.iter().zip(&names).zip(results) {
        match r {
            Ok(o) => {
                if let Err(e) = report(h, &out.join(n), &o) {
                    print_err.get_or_insert(e);
                }
                rows.push(SurveyRow::new(n.clone(), &o));
            }
            Err(e) => {
                eprintln!("error: {}: {e:#}", h.display());
                first_err.get_or_insert(e);
            }
        }
    }
    if let Some(e) = first_err {
        return Err(e.context(format!(
            "{} of {} hauls failed; {} not written",
            hauls.len() - rows.len(),
            hauls.len(),
            out.join("survey.csv").display()
        )));
    }
    write_survey(&out.join("survey.csv"), &rows)?;
    if let Some(e) = print_err {
        return Err(e);
    }
    crate::outln!(
        "survey: {} hauls, {} fish → {}",
        rows.len(),
        rows.iter().map(|r| r.fish_count).sum::<usize>(),
        out.join("survey.csv").display()
    )
}

/// Creates the survey folder `out` and removes a stale `survey.csv` (it is
/// rewritten only when every haul succeeds) and temporary files.
pub fn prepare_out_dir_plain(out: &Path) -> Result<(), InputError> {
    std::fs::create_dir_all(out)
        .map_err(|e| InputError::file(out, format!("cannot create the output directory: {e}")))?;
    let csv = out.join("survey.csv");
    if csv.exists() {
        std::fs::remove_file(&csv).map_err(|e| {
            InputError::file(&csv, format!("cannot remove the previous table: {e}"))
        })?;
    }
    remove_partials(out);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(lengths: &[f64], fish: usize) -> HaulOutcome {
        HaulOutcome {
            fish,
            measured: lengths.len(),
            frames: 30,
            seconds_per_frame: 0.1,
            lengths: lengths.to_vec(),
        }
    }

    #[test]
    fn rows_have_mean_and_sample_sd() {
        let r = SurveyRow::new("h1".into(), &outcome(&[300.0, 400.0, 500.0], 5));
        assert_eq!(r.length_mean_mm, Some(400.0));
        assert_eq!(r.length_sd_mm, Some(100.0));
        assert_eq!((r.fish_count, r.fish_measured, r.frames), (5, 3, 30));
        let one = SurveyRow::new("h2".into(), &outcome(&[321.5], 1));
        assert_eq!((one.length_mean_mm, one.length_sd_mm), (Some(321.5), None));
        let none = SurveyRow::new("h3".into(), &outcome(&[], 0));
        assert_eq!((none.length_mean_mm, none.length_sd_mm), (None, None));

        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("survey.csv");
        let odd = SurveyRow {
            haul: "a,b".into(),
            ..none.clone()
        };
        write_survey(&p, &[r, one, none, odd]).unwrap();
        assert_eq!(
            std::fs::read_to_string(&p).unwrap(),
            "haul,fish_count,length_mean_mm,length_sd_mm,fish_measured,frames\n\
             h1,5,400,100,3,30\nh2,1,321.5,,1,30\nh3,0,,,0,30\n\"a,b\",0,,,0,30\n"
        );
    }

    #[test]
    fn names_and_out_dir_preparation() {
        assert_eq!(haul_name(Path::new("/x/hauls/h_2024_07")), "h_2024_07");
        assert_eq!(
            short_name(Path::new("/x/a_very_long_haul_name")),
            "a_very_long…"
        );
        let t = tempfile::tempdir().unwrap();
        let out = t.path().join("o");
        std::fs::create_dir(&out).unwrap();
        std::fs::write(out.join("summary.json"), "{}").unwrap();
        std::fs::write(out.join(".tracks.csv.abc.partial"), "half").unwrap();
        std::fs::write(out.join("tracks.csv"), "1,1\n").unwrap();
        prepare_out_dir(&out).unwrap();
        let mut left: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["tracks.csv"]);
        // a path below a regular file cannot be created: bad input, named
        let f = t.path().join("file");
        std::fs::write(&f, "x").unwrap();
        let e = prepare_out_dir(&f.join("out")).unwrap_err().to_string();
        assert!(e.contains("file/out") && e.contains("cannot create"), "{e}");
    }
}
