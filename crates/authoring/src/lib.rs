//! Authoring of the project's own animations: a small, deterministic glTF 2.0 writer
//! ([`GltfBuilder`]) with shape and texture generators, and the scenes made with it.
//!
//! The builder takes format-independent inputs (meshes as position/normal/UV/index
//! arrays, metallic-roughness materials with optional transmission and IOR, RGBA8
//! images, TRS nodes in a hierarchy, perspective cameras, point lights, keyframed node
//! animations) and writes `<name>.gltf` + `<name>.bin` + one PNG per image. The same
//! builder always gives the same bytes, so generated files can be committed and checked.
//!
//! Files: `builder.rs` (the scene under construction) with `handles.rs`, `material.rs`,
//! `node.rs`, `animation.rs` (its elements) and `validation.rs` (its checks);
//! `gltf_writer.rs` (encoding) with `gltf_json.rs` and `binary_buffer.rs` (the glTF
//! document and buffer); `shapes.rs` and `textures.rs` (generators); `default_scene.rs`
//! (the default animation) and the BART-style animations `kitchen.rs` (rigid car
//! hierarchy), `robots.rs` (walking jointed robots) and `museum.rs` (a morph-target
//! sculpture with a detail knob), with `scene_kit.rs` (helpers they share).

#![warn(missing_docs)]

mod animation;
mod binary_buffer;
mod builder;
mod default_scene;
mod error;
mod gltf_json;
mod gltf_writer;
mod handles;
mod kitchen;
mod material;
mod museum;
mod node;
mod robots;
mod scene_kit;
pub mod shapes;
pub mod textures;
mod validation;

use std::path::{Path, PathBuf};

pub use animation::{AnimatedProperty, Animation, Channel, Interpolation};
pub use builder::GltfBuilder;
pub use default_scene::{
    DEFAULT_DURATION_SECONDS, DEFAULT_SCENE_NAME, default_scene, write_default,
};
pub use error::AuthoringError;
pub use gltf_writer::{EncodedFile, GENERATOR};
pub use handles::{
    AnimationId, CameraId, GeometryId, ImageId, LightId, MaterialId, MeshId, NodeId,
};
pub use kitchen::{KITCHEN_DURATION_SECONDS, KITCHEN_SCENE_NAME, kitchen_scene, write_kitchen};
pub use material::{Material, TextureBinding, WrapMode};
pub use museum::{
    MUSEUM_DEFAULT_DETAIL, MUSEUM_DURATION_SECONDS, MUSEUM_MAX_DETAIL, MUSEUM_SCENE_NAME,
    museum_scene, museum_sculpture_triangles, write_museum,
};
pub use node::{Mesh, Node, PerspectiveCamera, PointLight, Primitive};
pub use robots::{
    ROBOTS_DURATION_SECONDS, ROBOTS_SCENE_NAME, STEP_CYCLE_SECONDS, robots_scene, write_robots,
};
pub use shapes::{MeshData, MorphTarget};
pub use textures::RgbaImage;

/// Writes every authored animation into `dir`: `default`, `kitchen`, `robots` and
/// `museum` (at [`MUSEUM_DEFAULT_DETAIL`]); returns the paths written, each scene's
/// `.gltf` first.
///
/// # Errors
/// The first scene's [`AuthoringError`].
pub fn write_all(dir: &Path) -> Result<Vec<PathBuf>, AuthoringError> {
    let mut paths = write_default(dir)?;
    paths.extend(write_kitchen(dir)?);
    paths.extend(write_robots(dir)?);
    paths.extend(write_museum(dir, MUSEUM_SCENE_NAME, MUSEUM_DEFAULT_DETAIL)?);
    Ok(paths)
}
