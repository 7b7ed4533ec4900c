//! A render run: the layer above the frame loop that turns frames into a folder and judges
//! it. [`render_sequence`] drives the frame loop over a range (resume, shards, `--check`),
//! [`OutputDir`] owns the folder (frames, `stats.jsonl`, `summary.json`), and [`finish_check`]
//! ends a regression check (shared with `mipray diff`).
//!
//! Invariants: below the command line this is the only module that calls `diff`, `pages`
//! and `report` (`tests/architecture.rs`), so the frame loop and everything under it never
//! reach a tool; and nothing here prints: progress goes to a [`SequenceProgress`] and
//! results come back as values.

mod check;
mod output;
mod sequence;

pub use check::{CheckFinished, check_junit_path, finish_check};
pub use output::{FrameFormat, OutputDir, Shard, frame_file_name, write_frame_atomically};
pub use sequence::{
    Check, Resume, SequenceOutput, SequenceProgress, SequenceReport, WrittenFrame, render_sequence,
};
