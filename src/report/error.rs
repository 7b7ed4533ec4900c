//! Errors of the report: every one names the file (and line) it is about.

use std::path::PathBuf;

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A folder or file could not be listed, read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A folder holds neither `stats.jsonl` nor `stats.shard-*.jsonl`.
    #[error("{dir}: no stats.jsonl or stats.shard-*.jsonl")]
    NoStatsFile { dir: PathBuf },
    /// A line of a stats file is not JSON.
    #[error("{path}:{line}: invalid JSON: {source}")]
    Json {
        path: PathBuf,
        line: usize,
        source: serde_json::Error,
    },
    /// A line is JSON but not a frame record (no `frame`, a field of the wrong type).
    #[error("{path}:{line}: {message}")]
    Record {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// The stats files hold no record at all.
    #[error("no frame records in {sources}")]
    Empty { sources: String },
    /// Frames of the expected range have no record or no frame file (a shard failed, was
    /// cancelled or never ran).
    #[error(
        "{sources}: {count} frame(s) of {expected} have no record or no frame file: {frames} (render them again with --resume)"
    )]
    Incomplete {
        sources: String,
        count: usize,
        frames: String,
        expected: String,
    },
    /// The plot could not be drawn.
    #[error("{path}: cannot draw the plot: {message}")]
    Plot { path: PathBuf, message: String },
}

impl ReportError {
    /// Wraps an I/O error with the path it is about (for `map_err`).
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> ReportError {
        let path = path.into();
        move |source| ReportError::Io { path, source }
    }
}
