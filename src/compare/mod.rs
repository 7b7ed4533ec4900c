//! `mipray compare`: every LOD method on the same frames, timed side by side and measured
//! against a supersampled level-0 reference.

pub mod report;
mod types;

pub use types::{CompareReport, FrameErrors, LightsRow, MethodSummary};
