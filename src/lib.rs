//! mipray: a CPU ray tracer for animated scenes with ray-length MIP-map level selection
//! (Park & Kim 2010). See `README.md` for the frame loop and the LOD derivation.

pub mod accel;
pub mod anim;
pub mod atomic_file;
pub mod authoring;
pub mod bench;
pub mod cli;
pub mod compare;
pub mod csv;
pub mod diff;
pub mod export;
pub mod frame;
pub mod geometry;
pub mod lod;
pub mod markup;
pub mod metrics;
pub mod output;
pub mod pages;
pub mod render;
pub mod report;
pub mod scene;
pub mod simd;
pub mod texture;
