//! `mipray compare`: every LOD method on the same frames, timed side by side and measured
//! against a supersampled level-0 reference.

pub mod lod_error;
mod method_spec;
pub mod report;
mod run;
pub mod subpixel_reference;
pub mod subpixel_table;
mod types;

pub use method_spec::{MAX_VARIANT_SPP, MethodSpec};
pub use run::{CompareOptions, CompareResults, run_compare};
pub use types::{
    CompareReport, FrameErrors, LevelError, LightsRow, MethodSummary, SubpixelFrameErrors,
    SubpixelSummary,
};
