//! The files `mipray compare` writes from a [`CompareReport`].
//!
//! - `compare.csv`: one row per method, in report order, with the columns
//!   `method,bytes_per_ray,ms_per_frame,overhead_pct,psnr,ssim,flip,lod_bias,lod_rms,lod_under,flicker`
//!   (the means over the frame range; see `MethodSummary`).
//! - `compare_frames.csv`: long format, one row per (method, frame), with the columns
//!   `method,frame,ms,psnr,ssim,flip,lod_bias,lod_rms,lod_under,lod_pixels,flicker`;
//!   `flicker` is empty for the first frame of the range, which has no previous frame.
//! - `compare.md`: the run's settings, the method table (the columns of `compare.csv`), how
//!   to read it, Table 1 of Park & Kim (`none` vs `paper` by light count) when it was
//!   measured, and the share of texture lookups per MIP level.
//! - `pareto.svg`: error against time, one labelled point per method; left panel mean
//!   FLIP, right panel LOD RMS error (levels), both against ms per frame.
//! - `error_per_frame.svg`: mean FLIP of every frame, one line per method.
//! - `mip_levels.svg`: share of lookups per MIP level, grouped bars per method (the
//!   paper's Fig. 4).
//!
//! Numbers have a fixed number of decimals per column (ms 3, overhead 2, PSNR 2, SSIM 5,
//! FLIP 5, LOD 3, flicker 3). In the CSV files NaN is written `nan` and infinities `inf` /
//! `-inf`, so every column stays numeric for Python's `float()` and Rust's `parse`; the
//! Markdown writes `n/a` for NaN, for people.
//!
//! A method keeps its colour in every plot (its index in the report, over a palette of 8;
//! more methods reuse colours). Non-finite values are left out of the plots; a plot with
//! nothing to draw still is a valid SVG whose caption says so.
//!
//! A report without methods is not an error: every file is still written (CSV headers only,
//! plots whose captions say there is no data), so a run that measured nothing leaves a complete,
//! self-describing folder instead of a partial one.
//!
//! Every file is written to a temporary sibling and renamed into place.
//!
//! Files: `table.rs` (the two CSV files), `markdown.rs` (`compare.md`), `plots.rs` (the
//! three SVGs, with the chart setup shared with `mipray report` in `crate::chart`).

#[cfg(test)]
mod fixtures;
mod markdown;
mod plots;
mod table;

use std::path::{Path, PathBuf};

use super::CompareReport;
use crate::atomic_file::write_text_atomically;

pub use markdown::{markdown, markdown_with};
pub use plots::write_plots;
pub use table::{csv, frames_csv};

/// Why the compare report could not be written; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum CompareReportError {
    /// A folder or file could not be created or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// plotters could not draw the plot.
    #[error("{path}: cannot draw the plot: {message}")]
    Plot { path: PathBuf, message: String },
}

// Decimals per kind of quantity, shared by the CSV files and the Markdown.
pub(super) const MS_DECIMALS: usize = 3;
pub(super) const OVERHEAD_DECIMALS: usize = 2;
pub(super) const PSNR_DECIMALS: usize = 2;
pub(super) const SSIM_DECIMALS: usize = 5;
pub(super) const FLIP_DECIMALS: usize = 5;
pub(super) const LOD_DECIMALS: usize = 3;
pub(super) const FLICKER_DECIMALS: usize = 3;

/// `v` with `decimals` decimals; NaN and infinities spelled as Python's `float()` reads
/// them (`nan`, `inf`, `-inf`), so a column stays numeric.
pub(super) fn fixed(v: f64, decimals: usize) -> String {
    if v.is_nan() {
        "nan".to_owned()
    } else if v.is_infinite() {
        if v > 0.0 { "inf" } else { "-inf" }.to_owned()
    } else {
        format!("{v:.decimals$}")
    }
}

/// Like [`fixed`], but NaN (not measured) reads `n/a` for a person.
pub(super) fn readable(v: f64, decimals: usize) -> String {
    if v.is_nan() {
        "n/a".to_owned()
    } else {
        fixed(v, decimals)
    }
}

/// Writes `compare.csv`, `compare_frames.csv`, `compare.md` (the report's Markdown, then
/// `md_appendix`, e.g. another reference's section) and the three plots into `dir`
/// (created if needed); returns the six paths in that order. A report without methods
/// still gets all six files (see the module comment).
pub fn write_all(
    report: &CompareReport,
    md_appendix: &str,
    dir: &Path,
) -> Result<Vec<PathBuf>, CompareReportError> {
    create_dir(dir)?;
    let texts = [
        ("compare.csv", csv(report)),
        ("compare_frames.csv", frames_csv(report)),
        ("compare.md", markdown_with(report, md_appendix)),
    ];
    let mut written = Vec::with_capacity(texts.len() + plots::PLOTS.len());
    for (name, text) in texts {
        let path = dir.join(name);
        write_file(&path, &text)?;
        written.push(path);
    }
    written.extend(write_plots(report, dir)?);
    Ok(written)
}

pub(super) fn create_dir(dir: &Path) -> Result<(), CompareReportError> {
    std::fs::create_dir_all(dir).map_err(|source| CompareReportError::Io {
        path: dir.to_path_buf(),
        source,
    })
}

pub(super) fn write_file(path: &Path, text: &str) -> Result<(), CompareReportError> {
    write_text_atomically(path, text).map_err(|source| CompareReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::fixtures::{METHODS, sample_report, svg_texts};
    use super::table::SUMMARY_HEADER;
    use super::*;

    #[test]
    fn numbers_have_fixed_decimals_and_python_spellings() {
        assert_eq!(fixed(12.3456, MS_DECIMALS), "12.346");
        assert_eq!(fixed(f64::NAN, 3), "nan");
        assert_eq!(fixed(f64::INFINITY, 2), "inf");
        assert_eq!(fixed(f64::NEG_INFINITY, 2), "-inf");
        assert_eq!(readable(f64::NAN, 3), "n/a");
    }

    #[test]
    fn write_all_writes_six_files_and_svgs_name_every_method() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("compare");
        let written = write_all(&sample_report(), "", &out).unwrap();
        let names: Vec<_> = written
            .iter()
            .map(|p| p.file_name().unwrap().to_str().unwrap())
            .collect();
        assert_eq!(
            names,
            [
                "compare.csv",
                "compare_frames.csv",
                "compare.md",
                "pareto.svg",
                "error_per_frame.svg",
                "mip_levels.svg"
            ]
        );
        for path in &written {
            assert!(path.is_file(), "{}", path.display());
        }
        for svg in &written[3..] {
            let texts = svg_texts(svg);
            for name in METHODS {
                assert!(
                    texts.iter().any(|t| t.trim() == name),
                    "{name} not in {}: {texts:?}",
                    svg.display()
                );
            }
        }
        // Nothing left behind but the six files (no temporaries).
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 6);
    }

    #[test]
    fn zero_methods_still_write_every_file() {
        let mut report = sample_report();
        report.methods.clear();
        report.table1.clear();
        report.frames.clear();
        let dir = tempfile::tempdir().unwrap();
        let written = write_all(&report, "", dir.path()).unwrap();
        assert_eq!(written.len(), 6);
        assert_eq!(
            std::fs::read_to_string(&written[0]).unwrap(),
            format!("{SUMMARY_HEADER}\n")
        );
        let md = std::fs::read_to_string(&written[2]).unwrap();
        assert!(md.contains("No methods were measured."));
        assert!(md.contains("No texture lookups were recorded."));
        for svg in &written[3..] {
            svg_texts(svg);
        }
    }
}
