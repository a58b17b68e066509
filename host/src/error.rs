//! Errors that mean "the input is bad" (exit code 2), as opposed to runtime
//! failures (exit code 1). Every message names the file, frame or key.

use std::fmt;
use std::path::Path;

/// Bad input: a file, frame, calibration key or parameter that is wrong.
/// `fishtrack` exits with code 2 when the error chain holds one of these.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputError {
    /// Where: a file path, optionally with `: key` or `frame N`.
    pub location: String,
    /// What is wrong.
    pub message: String,
}

impl InputError {
    /// An error about a file as a whole.
    pub fn file(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        InputError {
            location: path.as_ref().display().to_string(),
            message: message.into(),
        }
    }

    /// An error about one key of a file (calibration, params).
    pub fn key(path: impl AsRef<Path>, key: &str, message: impl Into<String>) -> Self {
        InputError {
            location: format!("{}: key `{key}`", path.as_ref().display()),
            message: message.into(),
        }
    }

    /// An error without a file (a command-line value, for example).
    pub fn plain(location: impl Into<String>, message: impl Into<String>) -> Self {
        InputError {
            location: location.into(),
            message: message.into(),
        }
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.location, self.message)
    }
}

impl std::error::Error for InputError {}

/// Exit code for an error chain: 2 for bad input, 1 otherwise.
pub fn exit_code(err: &anyhow::Error) -> i32 {
    if err
        .chain()
        .any(|e| e.downcast_ref::<InputError>().is_some())
    {
        2
    } else {
        1
    }
}
