//! Errors of the report: every one names the file (and line) it is about.

use std::path::PathBuf;

use crate::record::StatsFileError;

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The stats files could not be read (the error names the file and line).
    #[error(transparent)]
    Stats(#[from] StatsFileError),
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Frames of the expected range have no record, no frame file or a damaged one (a
    /// shard failed, was cancelled or never ran; a file was cut short).
    #[error(
        "{sources}: {count} frame(s) of {expected} have no record or no frame file: {frames} (render them again with --resume){damaged}"
    )]
    Incomplete {
        sources: String,
        count: u64,
        frames: String,
        expected: String,
        /// `; damaged frame files: ...` when some are, else empty.
        damaged: String,
    },
    /// The records of the sequence came from different runs (another scene or settings).
    #[error("{0}; render the frames again with one scene and settings, or report them apart")]
    MixedRuns(crate::record::MixedRuns),
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
