//! Progress bars and logging for the command line (DESIGN.md, "Command
//! line": long jobs show a progress bar on stderr, hidden when stderr is not
//! a terminal).
//!
//! - [`init`] is called once by `main` with the global `-v`/`-vv`/`-q` flags:
//!   it installs an `env_logger` logger (default level `warn`, `-v` `info`,
//!   `-vv` `debug`, `-vvv` `trace`, `-q` errors only; `RUST_LOG` refines it)
//!   that writes to stderr without breaking a progress bar being drawn.
//! - [`bar`] makes a progress bar (`frames/s` and ETA) that is drawn on
//!   stderr only when stderr is a terminal and `--quiet` was not given;
//!   otherwise it is hidden and costs nothing. Bars of hauls tracked in
//!   parallel are stacked in one [`MultiProgress`].
//!
//! Nothing here writes to stdout: the summaries commands print there stay
//! clean for scripts.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Set by `--quiet`.
static QUIET: AtomicBool = AtomicBool::new(false);

/// The one multi-bar every progress bar is added to.
fn multi() -> &'static MultiProgress {
    static MULTI: OnceLock<MultiProgress> = OnceLock::new();
    MULTI.get_or_init(|| {
        if bars_visible() {
            MultiProgress::with_draw_target(ProgressDrawTarget::stderr())
        } else {
            MultiProgress::with_draw_target(ProgressDrawTarget::hidden())
        }
    })
}

/// True when progress bars are drawn: stderr is a terminal and not `--quiet`.
pub fn bars_visible() -> bool {
    !QUIET.load(Ordering::Relaxed) && std::io::stderr().is_terminal()
}

/// True when `--quiet` was given.
pub fn quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// The log level for the global flags: `-q` → error, none → warn, `-v` →
/// info, `-vv` → debug, `-vvv` or more → trace.
pub fn level(verbose: u8, quiet: bool) -> log::LevelFilter {
    if quiet {
        return log::LevelFilter::Error;
    }
    match verbose {
        0 => log::LevelFilter::Warn,
        1 => log::LevelFilter::Info,
        2 => log::LevelFilter::Debug,
        _ => log::LevelFilter::Trace,
    }
}

/// Stderr writer that lifts the progress bars while a log line is printed.
struct BarSafeStderr;

impl Write for BarSafeStderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        multi().suspend(|| std::io::stderr().write_all(buf))?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

/// Installs the logger and records `--quiet`. Call once, first thing.
pub fn init(verbose: u8, quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
    let _ = env_logger::Builder::new()
        .filter_level(level(verbose, quiet))
        .parse_default_env()
        .format_timestamp(None)
        .format_target(verbose >= 2)
        .target(env_logger::Target::Pipe(Box::new(BarSafeStderr)))
        .try_init();
}

/// A progress bar over `len` items called `unit` (e.g. `frames`), labelled
/// `prefix`, showing items per second and the ETA; hidden unless
/// [`bars_visible`].
pub fn bar(len: u64, prefix: &str, unit: &str) -> ProgressBar {
    if !bars_visible() {
        return ProgressBar::hidden();
    }
    let template = format!(
        "{{prefix:>12.bold}} [{{bar:32}}] {{pos}}/{{len}} {unit} ({{per_sec}}, ETA {{eta}})"
    );
    let style = ProgressStyle::with_template(&template)
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    let pb = ProgressBar::new(len)
        .with_style(style)
        .with_prefix(prefix.to_string());
    multi().add(pb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verbosity_flags_map_to_levels() {
        assert_eq!(level(0, false), log::LevelFilter::Warn);
        assert_eq!(level(1, false), log::LevelFilter::Info);
        assert_eq!(level(2, false), log::LevelFilter::Debug);
        assert_eq!(level(5, false), log::LevelFilter::Trace);
        assert_eq!(level(2, true), log::LevelFilter::Error);
    }

    #[test]
    fn bars_are_hidden_off_a_terminal() {
        // `cargo test` captures stderr through a pipe or runs without a tty
        // in CI; either way the bar must be hidden when stderr is no tty.
        let b = bar(10, "test", "frames");
        if !std::io::stderr().is_terminal() {
            assert!(b.is_hidden());
        }
        b.inc(3);
        assert_eq!(b.position(), 3);
    }
}
