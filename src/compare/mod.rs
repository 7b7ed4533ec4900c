//! `mipray compare`: every LOD method on the same frames, timed side by side and measured
//! against a supersampled level-0 reference.

pub mod lod_error;
pub mod report;
mod run;
mod types;

pub use run::{CompareOptions, run_compare};
pub use types::{CompareReport, FrameErrors, LightsRow, MethodSummary};
