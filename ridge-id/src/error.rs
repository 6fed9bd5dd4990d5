//! The error type of `ridge-id`: every failure is one line naming the file, the line
//! (when there is one) and the problem.

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

/// Why an identification run could not produce a report.
///
/// `Display` is a single line without a trailing newline, e.g.
/// `LOG.csv line 17: column y: "abc" is not a number`; the binary prefixes `error: `.
#[derive(Debug)]
pub enum IdError {
    /// Opening or reading a file failed.
    Io {
        /// The file.
        path: PathBuf,
        /// The line being read, if any had been read.
        line: Option<u64>,
        /// The operating system's error.
        source: io::Error,
    },
    /// A problem at one line of a CSV file (header or data row).
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number (the header is usually line 1).
        line: u64,
        /// What is wrong, e.g. `column y: "abc" is not a number`.
        message: String,
    },
    /// A problem with a whole record (too short, not excited, nothing fits).
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An option value or combination that cannot work (e.g. `--beta 1.5`).
    Usage(String),
    /// Writing the plot failed.
    Plot {
        /// The PNG file.
        path: PathBuf,
        /// What the drawing library reported.
        message: String,
    },
}

impl IdError {
    /// A problem at `line` of `path`.
    pub fn line(path: &Path, line: u64, message: impl Into<String>) -> Self {
        IdError::Line {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    /// A problem with the whole file `path`.
    pub fn file(path: &Path, message: impl Into<String>) -> Self {
        IdError::File {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    /// The file the error is about, if any.
    pub fn path(&self) -> Option<&Path> {
        match self {
            IdError::Io { path, .. }
            | IdError::Line { path, .. }
            | IdError::File { path, .. }
            | IdError::Plot { path, .. } => Some(path),
            IdError::Usage(_) => None,
        }
    }

    /// The line the error is about, if any.
    pub fn line_number(&self) -> Option<u64> {
        match self {
            IdError::Line { line, .. } => Some(*line),
            IdError::Io { line, .. } => *line,
            _ => None,
        }
    }
}

/// Flattens a message onto one line (a path or an OS message could contain newlines).
fn one_line(s: &str) -> String {
    s.split(['\n', '\r'])
        .filter(|p| !p.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

impl fmt::Display for IdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let text = match self {
            IdError::Io {
                path,
                line: Some(line),
                source,
            } => format!("{} line {line}: cannot read: {source}", path.display()),
            IdError::Io {
                path,
                line: None,
                source,
            } => format!("{}: cannot open: {source}", path.display()),
            IdError::Line {
                path,
                line,
                message,
            } => format!("{} line {line}: {message}", path.display()),
            IdError::File { path, message } => format!("{}: {message}", path.display()),
            IdError::Usage(message) => message.clone(),
            IdError::Plot { path, message } => {
                format!("{}: cannot write the plot: {message}", path.display())
            }
        };
        f.write_str(&one_line(&text))
    }
}

impl std::error::Error for IdError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            IdError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}
