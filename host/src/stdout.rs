//! The commands' standard output.
//!
//! `println!` panics when the reader has gone (`fishtrack eval --json |
//! head -1`: "failed printing to stdout: Broken pipe"). The [`outln!`] and
//! [`out!`] macros write through [`write`] instead: a closed pipe ends the
//! printing quietly (later writes are skipped) while the command runs on,
//! so every output file is still written and the exit status still says
//! what the command found (a `compare` disagreement, a failed
//! `timing-check`); any other write error is an error naming standard
//! output.
//!
//! [`outln!`]: crate::outln
//! [`out!`]: crate::out

use std::fmt;
use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};

/// Set once a write found standard output closed by its reader.
static CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes `args` to standard output and flushes it; a no-op once the
/// reader has closed it ([`closed`]).
pub fn write(args: fmt::Arguments<'_>) -> anyhow::Result<()> {
    if closed() {
        return Ok(());
    }
    let mut out = io::stdout().lock();
    match out.write_fmt(args).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => {
            CLOSED.store(true, Ordering::Relaxed);
            Ok(())
        }
        Err(e) => Err(anyhow::Error::new(e).context("cannot write to standard output")),
    }
}

/// True once a write found standard output closed by its reader.
pub fn closed() -> bool {
    CLOSED.load(Ordering::Relaxed)
}

/// `println!` that returns `anyhow::Result<()>` ([`write`]).
#[macro_export]
macro_rules! outln {
    () => {
        $crate::stdout::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::stdout::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` that returns `anyhow::Result<()>` ([`write`]).
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::stdout::write(format_args!($($arg)*))
    };
}
