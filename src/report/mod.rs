//! `mipray report`: statistics and a plot of a rendered sequence from its `stats.jsonl`.
//!
//! The record and its reader are [`crate::record`]'s ([`crate::record::Record`]: one line
//! read back, with the fields it had). [`report`] loads the records of one or more output
//! folders ([`crate::record::load_sequence`]: shards merged, sorted by frame, duplicates
//! dropped), summarises every timing phase and count
//! with [`crate::percentiles::Percentiles`] (min / median / nearest-rank p95 / max), computes the preprocessing
//! share of frame time and the rebuild count, and writes an SVG plot ([`write_svg`]).
//! Fields missing from older records are absent, never 0: a quantity no record has is left
//! out of the table and the plot. [`require_frames`] checks that an expected range is all
//! there (`report --expect-frames`, a farm's merge step).

mod complete;
mod error;
mod metrics;
pub(crate) mod plot;
mod stats;
mod summary;
mod summary_json;

use std::path::{Path, PathBuf};

pub use complete::{
    MissingFrames, frame_file_problem, frame_folders, missing_frames, require_frames,
};
pub use error::ReportError;
pub use metrics::{
    COUNTS, DEFORMED_TRIANGLES, LOD_RECOMPUTED, MOVED_TRIANGLES, Metric, PLOTTED_COUNTS,
    PREPROCESSING_PHASES, Quantities, RAYS, RENDER_MS, TIMING_PHASES, TOTAL_MS, TRIANGLES,
};
pub use plot::{SVG_SIZE, render_svg, write_svg};
pub use stats::{PhaseRow, PreprocessingShare, rebuild_count};
pub use summary::ReportSummary;
pub use summary_json::{PhasePercentiles, Summary};

/// Loads the records of `dirs`, writes the plot to `svg_out` (atomically, creating its
/// folder) and returns the statistics (`Display`: a Markdown table and summary lines).
///
/// # Errors
/// Loading fails (see [`crate::record::load_records`]), or the plot cannot be drawn or written.
pub fn report(dirs: &[PathBuf], svg_out: &Path) -> Result<ReportSummary, ReportError> {
    let sequence = crate::record::load_sequence(dirs)?;
    write_svg(&sequence.records, svg_out)?;
    Ok(ReportSummary::of(&sequence, svg_out.to_path_buf()))
}
