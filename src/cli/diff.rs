//! `mipray diff REF TEST`, and the judging flags it shares with `render --check`.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Args;

use super::progress::print_check_end;
use crate::diff::{DiffMetric, DiffOptions, Verdict, diff_dirs};
use crate::run::finish_check;

/// How frames are judged against a reference (shared by `diff` and `render --check`).
#[derive(Args, Debug, Clone)]
pub struct CheckArgs {
    /// Metric that decides pass or fail.
    #[arg(long, value_enum, default_value_t = DiffMetric::Psnr)]
    pub metric: DiffMetric,
    /// Threshold for the metric [default: psnr 40 dB, flip 0.01, max-abs 0].
    #[arg(long, value_parser = parse_threshold)]
    pub threshold: Option<f64>,
    /// Also write a JUnit XML report (one test case per frame).
    #[arg(long)]
    pub junit: Option<PathBuf>,
}

/// A threshold is a number (NaN would fail every frame, whatever it held).
fn parse_threshold(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(t) if !t.is_nan() => Ok(t),
        Ok(_) => Err("not a number (NaN); give a threshold such as 40 or 0.01".into()),
        Err(e) => Err(e.to_string()),
    }
}

impl CheckArgs {
    /// `--threshold`, else the metric's default.
    pub fn threshold(&self) -> f64 {
        self.threshold.unwrap_or(self.metric.default_threshold())
    }
}

#[derive(Args, Debug, Clone)]
pub struct DiffArgs {
    /// The reference sequence's folder.
    pub reference: PathBuf,
    /// The sequence to check.
    pub test: PathBuf,
    #[command(flatten)]
    pub check: CheckArgs,
    /// Where diff.md, diff.csv and the failing frames' images go [default: TEST/diff].
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// `mipray diff`: `Ok(FAILURE)` when frames fall outside the threshold.
pub fn diff(args: &DiffArgs) -> Result<ExitCode> {
    if let Some(junit) = &args.check.junit {
        crate::run::check_junit_path(junit)?;
    }
    let options = DiffOptions {
        metric: args.check.metric,
        threshold: args.check.threshold(),
        out: args.out.clone().unwrap_or_else(|| args.test.join("diff")),
    };
    let report = diff_dirs(&args.reference, &args.test, &options)?;
    print!("{}", report.table());
    if let Some(note) = &report.stats_note {
        println!("stats not compared: {note}");
    }
    let finished = finish_check(&report, &options.out, args.check.junit.as_deref())?;
    print_check_end(&finished);
    Ok(match finished.verdict {
        Verdict::Passed => ExitCode::SUCCESS,
        Verdict::Failed => ExitCode::FAILURE,
    })
}
