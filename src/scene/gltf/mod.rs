//! glTF 2.0 loader: a `.gltf` (JSON) or `.glb` (binary) file to a [`SceneDesc`].
//!
//! This is one of the two places that know a file format; nothing of the `gltf` crate
//! leaks past it. Steps: parse and validate the JSON (gltf), load buffers (GLB BIN chunk,
//! data URIs, relative files), then materials and their base-colour textures, meshes,
//! cameras, lights, nodes and the hierarchy, animations.
//!
//! Invariants on `Ok` (those listed in `scene/mod.rs`): every number is finite, every
//! index is in range, triangle lists are whole. Malformed input is an `Err` naming the
//! file and the element (accessor, mesh/primitive, node, image) — never a panic: every
//! byte range is checked before the gltf crate reads it (see `accessor.rs`). Features
//! rendered approximately (skins, morph animation, ignored texture slots) become
//! `SceneDesc::notes`.

mod accessor;
mod animation;
mod buffers;
mod material;
mod mesh;
mod nodes;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use glam::Vec3;

use super::SceneDesc;

/// Why a file could not be loaded; the message names the element and the problem.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct LoadError {
    pub path: PathBuf,
    pub message: String,
}

/// Radiance of rays that leave a glTF scene: glTF has no environment, so a dim neutral sky
/// that lets unlit geometry read as a silhouette.
pub const BACKGROUND: Vec3 = Vec3::new(0.05, 0.05, 0.08);

/// Loads a `.gltf` or `.glb` file into a scene description.
///
/// # Errors
/// A [`LoadError`] for an unreadable, malformed or inconsistent file, or a missing or
/// undecodable buffer or image it references.
pub fn load(path: &Path) -> Result<SceneDesc, LoadError> {
    load_scene(path).map_err(|message| LoadError {
        path: path.to_path_buf(),
        message,
    })
}

fn load_scene(path: &Path) -> Result<SceneDesc, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read file: {e}"))?;
    if bytes.is_empty() {
        return Err("file is empty".into());
    }
    let gltf::Gltf { document, blob } = parse(&bytes)?;
    let base_dir = path.parent().unwrap_or(Path::new(""));
    let buffers = buffers::Buffers::load(&document, blob, base_dir)?;

    let mut notes = Vec::new();
    let (materials, textures) =
        material::load_materials(&document, &buffers, base_dir, &mut notes)?;
    let meshes = mesh::load_meshes(&document, &buffers, &mut notes)?;
    let (cameras, camera_of) = nodes::load_cameras(&document, &mut notes)?;
    let lights = nodes::load_lights(&document)?;
    let nodes = nodes::load_nodes(&document, &camera_of)?;
    let roots = nodes::scene_roots(&document, &nodes)?;
    let animations = animation::load_animations(&document, &buffers, &nodes, &mut notes)?;
    note_rest_pose(&document, &mut notes);

    Ok(SceneDesc {
        source: path.to_path_buf(),
        meshes,
        nodes,
        roots,
        materials,
        textures,
        cameras,
        lights,
        animations,
        background: BACKGROUND,
        notes,
    })
}

/// Parses and validates the JSON (and GLB container). gltf's validation indexes arrays
/// with unchecked indices in a few hooks (e.g. a POSITION accessor index out of range),
/// so a panic there is caught and reported like any other malformed file.
fn parse(bytes: &[u8]) -> Result<gltf::Gltf, String> {
    match catch_unwind(AssertUnwindSafe(|| gltf::Gltf::from_slice(bytes))) {
        Ok(Ok(gltf)) => Ok(gltf),
        Ok(Err(e)) => Err(format!("not a valid glTF/GLB file: {e}")),
        Err(_) => Err("not a valid glTF/GLB file: it references elements that do not exist".into()),
    }
}

/// Notes for geometry shown in its rest pose until skinning and morphing land.
fn note_rest_pose(document: &gltf::Document, notes: &mut Vec<String>) {
    let skinned = document
        .nodes()
        .filter(|n| n.skin().is_some() && n.mesh().is_some())
        .count();
    if skinned > 0 {
        notes.push(format!(
            "{skinned} skinned mesh(es) rendered in rest pose (skinning lands with the frame loop)"
        ));
    }
    let morphed = document
        .meshes()
        .filter(|m| m.primitives().any(|p| p.morph_targets().len() > 0))
        .count();
    if morphed > 0 {
        notes.push(format!(
            "{morphed} mesh(es) with morph targets rendered with their default weights (morphing lands with the frame loop)"
        ));
    }
}
