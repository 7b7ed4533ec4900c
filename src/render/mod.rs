//! Rendering one frame: camera, materials, lights, the Whitted integrator and the tiled
//! film; the LOD probe for `--view lod` and `mipray compare`.
//!
//! `render` knows materials and lights only in its own terms (`Material`, `LightSource`):
//! `frame::appearance` builds them from the scene description, so nothing here names
//! a loader's type.

pub mod camera;
pub mod film;
pub mod integrator;
pub mod light;
pub mod lod_view;
pub mod material;
pub mod memory;
pub mod probe;
pub mod ray_log;
pub mod scene_bvh;
mod surface;
mod tile;

pub use camera::Camera;
pub use film::{LinearImage, render_image, render_image_recording};
pub use integrator::{FrameScene, MIP_LEVELS, TraceCounters};
pub use light::{Light, LightKind, LightSource};
pub use material::{Material, ShadingModel, highlight_floor};
pub use probe::{Bend, Chain, LodProbe};
pub use ray_log::{RayAnswer, RayClass, RayLog, TracedRay};
pub use scene_bvh::{InstanceShading, Instanced, PbRule, SceneBvh};
pub use surface::shadow_ray_toward;
