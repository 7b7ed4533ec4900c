//! The end of a regression check, shared by `mipray diff` and `render --check`: write the
//! report files and the diff page, and say whether every frame passed.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::atomic_file::write_text_atomically;
use crate::diff::{DiffReport, Verdict, junit_xml};

/// A check's report, written, and its verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckFinished {
    pub verdict: Verdict,
    /// The verdict in one line ([`DiffReport::verdict`]).
    pub summary: String,
    /// Frames that could not be compared (bad input: no reference frame, sizes that
    /// differ); the verdict is then `Failed`, and the CLI exits 2.
    pub not_compared: usize,
    /// `diff.md`.
    pub report: PathBuf,
    /// The diff page.
    pub page: PathBuf,
}

/// Checks, before any work, that a JUnit report can be written at `path`: its folder exists
/// and the path is not a folder (else a long run would end in an error after every frame
/// passed). Bad input to the check, so the exit status is 2.
pub fn check_junit_path(path: &Path) -> Result<()> {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let problem = if path.is_dir() {
        "is a folder; --junit takes a file name".to_string()
    } else if !parent.is_dir() {
        format!(
            "cannot write the JUnit report: the folder {} does not exist",
            parent.display()
        )
    } else {
        return Ok(());
    };
    Err(crate::diff::DiffInputError::Folder {
        dir: path.to_path_buf(),
        message: problem,
    }
    .into())
}

/// Writes diff.md / diff.csv (and the JUnit XML when asked) and the diff page into `out`;
/// returns the verdict and where they are.
///
/// # Errors
/// A report file or the page cannot be written.
pub fn finish_check(
    report: &DiffReport,
    out: &Path,
    junit: Option<&Path>,
) -> Result<CheckFinished> {
    report
        .write(out)
        .with_context(|| format!("{}: cannot write the diff report", out.display()))?;
    if let Some(path) = junit {
        write_text_atomically(path, &junit_xml(report))
            .with_context(|| format!("{}: cannot write JUnit XML", path.display()))?;
    }
    let summary = report.verdict();
    let page =
        crate::pages::write_diff_page(out, report.metric.name(), report.threshold, &summary)?;
    Ok(CheckFinished {
        verdict: if report.failed() + report.not_compared() == 0 {
            Verdict::Passed
        } else {
            Verdict::Failed
        },
        summary,
        not_compared: report.not_compared(),
        report: out.join("diff.md"),
        page,
    })
}
