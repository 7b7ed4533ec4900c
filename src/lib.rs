//! mipray: a CPU ray tracer for animated scenes with ray-length MIP-map level selection
//! (Park & Kim 2010). See ARCHITECTURE.md for the frame loop and `docs/src/lod-methods.md`
//! for the LOD derivation.

pub mod accel;
pub mod anim;
pub mod atomic_file;
pub mod bench;
pub mod chart;
pub mod cli;
pub mod colour;
pub mod compare;
pub mod csv;
pub mod diff;
pub mod export;
pub mod frame;
pub mod geometry;
pub mod large_pages;
pub mod lod;
pub mod markup;
pub mod metrics;
pub mod pages;
pub mod percentiles;
pub mod record;
pub mod render;
pub mod report;
pub mod run;
pub mod scene;
pub mod simd;
pub mod texture;
