//! mipray: a CPU ray tracer for animated scenes with ray-length MIP-map level selection
//! (Park & Kim 2010). See `README.md` for the frame loop and the LOD derivation.

pub mod scene;
pub mod texture;
pub mod authoring;
pub mod accel;
pub mod anim;
pub mod geometry;
pub mod lod;
pub mod render;
pub mod frame;
pub mod output;
pub mod cli;
pub mod bench;
pub mod report;
