//! The end of a regression check, shared by `mipray diff` and `render --check`: write the
//! report files, print the verdict, say whether every frame passed.

use std::path::Path;

use anyhow::{Context, Result};

use super::{DiffReport, junit_xml};

/// Whether a checked sequence stayed within its threshold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Passed,
    Failed,
}

/// Writes diff.md / diff.csv (and the JUnit XML when asked) into `out`, prints the verdict
/// and where the report is, and returns it.
///
/// # Errors
/// A report file cannot be written.
pub fn finish_report(report: &DiffReport, out: &Path, junit: Option<&Path>) -> Result<Verdict> {
    report
        .write(out)
        .with_context(|| format!("{}: cannot write the diff report", out.display()))?;
    if let Some(path) = junit {
        crate::atomic_file::write_text_atomically(path, &junit_xml(report))
            .with_context(|| format!("{}: cannot write JUnit XML", path.display()))?;
    }
    println!("{}", report.verdict());
    println!("report: {}", out.join("diff.md").display());
    let page = crate::pages::write_diff_page(
        out,
        report.metric.name(),
        report.threshold,
        &report.verdict(),
    )?;
    println!("page: {}", page.display());
    Ok(if report.failed() == 0 {
        Verdict::Passed
    } else {
        Verdict::Failed
    })
}
