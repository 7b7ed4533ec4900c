//! `mipray compare`: every LOD method on the same frames, timed side by side and measured
//! against a supersampled level-0 reference.

pub mod lod_error;
pub mod report;
mod run;
pub mod subpixel_reference;
mod types;

pub use run::{CompareOptions, median, run_compare};
pub use types::{CompareReport, FrameErrors, LightsRow, MethodSummary};
