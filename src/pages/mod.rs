//! HTML pages that show what a command wrote, written beside it as `index.html`:
//! [`write_render_page`] (a rendered sequence: player, phase chart, per-frame stats,
//! summary; also `mipray report DIR...` for merged shards), [`write_compare_page`]
//! (`mipray compare`: method table, clickable Pareto plot, reference against a method with
//! a swipe divider, FLIP heat map, LOD view) and [`write_diff_page`] (`mipray diff`: frames
//! worst first, swipe and toggle, metrics, verdict).
//!
//! The pages read back the files the command already wrote (the stats files, through
//! their one reader [`crate::record`]; `compare.csv`, `compare_frames.csv`, `compare.md`,
//! `diff.csv`, the PNG/SVG files), so they depend on the file formats, not on the code
//! that wrote them. Each page is static and
//! self-contained apart from links to images relative to its folder: hand-written CSS and
//! JavaScript are inlined (`assets/`), nothing is fetched from the network, and the page
//! works from `file://`. The scripts record errors and image loads on `<html>` (`data-errors`,
//! `data-images`), which `tests/pages_browser.rs` reads from headless Chromium.

mod compare;
mod diff;
mod html;
mod render;

use std::path::{Path, PathBuf};

pub use compare::write_compare_page;
pub use diff::write_diff_page;
pub use render::write_render_page;

/// The page's file name in its folder.
pub const PAGE_NAME: &str = "index.html";

/// Why a page could not be written; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum PageError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// An input file is malformed or missing what the page needs.
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    /// The stats files could not be read (the error names the file and line).
    #[error(transparent)]
    Stats(#[from] crate::record::StatsFileError),
}

impl PageError {
    fn input(path: &Path, message: impl Into<String>) -> PageError {
        PageError::Input {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}

/// Writes `html` as `dir/index.html` atomically ([`crate::atomic_file`]: a temporary file
/// named after this process and `owner`, so shards finishing at once in one folder never
/// share one and a resumed shard knows its own, removed when the write fails), then
/// renamed into place.
fn write_page(dir: &Path, html: &str, owner: Option<&str>) -> Result<PathBuf, PageError> {
    let dir = non_empty(dir);
    let path = dir.join(PAGE_NAME);
    crate::atomic_file::write_bytes_atomically_as(&path, owner, html.as_bytes())
        .map_err(|(path, source)| PageError::Io { path, source })?;
    Ok(path)
}

/// `.` for the empty path (the parent of a bare file name such as `report.svg`).
fn non_empty(dir: &Path) -> &Path {
    if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    }
}
