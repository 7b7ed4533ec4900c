//! Rendering one frame: camera, lights, the Whitted integrator and the tiled film.

pub mod camera;
pub mod film;
pub mod integrator;
pub mod light;
pub mod lod_view;

pub use camera::Camera;
pub use film::{LinearImage, render_image};
pub use integrator::{FrameScene, LodProbe, MIP_LEVELS, TraceCounters};
pub use light::Light;
