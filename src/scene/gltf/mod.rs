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
//! rendered approximately or ignored (point/line primitives, orthographic cameras, ignored
//! texture slots, more than 4 joint influences, skins without joints) become
//! `SceneDesc::notes`. Skins and morph targets are loaded as data (`skin.rs`, `morph.rs`);
//! the geometry stays un-deformed and `anim` poses and deforms it per frame.

mod accessor;
mod animation;
mod buffers;
mod material;
mod mesh;
mod morph;
mod nodes;
mod skin;

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

/// [`load`] on the bytes of a `.gltf` or `.glb` file already read from `path` (for
/// fuzzing); external buffers and images are still looked up beside `path`.
///
/// # Errors
/// As [`load`].
pub fn load_from_bytes(path: &Path, bytes: &[u8]) -> Result<SceneDesc, LoadError> {
    scene_from_bytes(path, bytes).map_err(|message| LoadError {
        path: path.to_path_buf(),
        message,
    })
}

fn load_scene(path: &Path) -> Result<SceneDesc, String> {
    let bytes = crate::scene::sources::read(path).map_err(|e| format!("cannot read file: {e}"))?;
    scene_from_bytes(path, &bytes)
}

fn scene_from_bytes(path: &Path, bytes: &[u8]) -> Result<SceneDesc, String> {
    if bytes.is_empty() {
        return Err("file is empty".into());
    }
    match checked_glb_length(bytes)? {
        // Bytes past a GLB's declared length are not part of it: the GLB parser would read
        // chunks from them, so it is handed the declared bytes only.
        Some(declared) if declared < bytes.len() => {
            let trailing = format!(
                "GLB header declares {declared} bytes but the file has {}; the {} bytes after \
                 them are ignored",
                bytes.len(),
                bytes.len() - declared
            );
            let mut scene = scene_from_document_bytes(path, &bytes[..declared])
                .map_err(|e| format!("{e} ({trailing})"))?;
            scene.notes.insert(0, trailing);
            Ok(scene)
        }
        _ => scene_from_document_bytes(path, bytes),
    }
}

/// [`scene_from_bytes`] on the bytes of the glTF JSON or of the GLB as its header declares it
/// ([`checked_glb_length`] has judged the header).
fn scene_from_document_bytes(path: &Path, bytes: &[u8]) -> Result<SceneDesc, String> {
    let mut notes = Vec::new();
    let gltf::Gltf { document, blob } = parse(bytes)?;
    let base_dir = path.parent().unwrap_or(Path::new(""));
    let buffers = buffers::Buffers::load(&document, blob, base_dir)?;

    let (materials, textures) =
        material::load_materials(&document, &buffers, base_dir, &mut notes)?;
    let meshes = mesh::load_meshes(&document, &buffers, &mut notes)?;
    let (cameras, camera_of) = nodes::load_cameras(&document, &mut notes)?;
    let lights = nodes::load_lights(&document)?;
    let nodes = nodes::load_nodes(&document, &camera_of)?;
    let roots = nodes::scene_roots(&document, &nodes)?;
    let skins = skin::load_skins(&document, &buffers)?;
    skin::check_skinned_nodes(&document, &nodes, &meshes, &skins, &mut notes)?;
    let animations = animation::load_animations(&document, &buffers, &nodes, &mut notes)?;

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
        skins,
        background: BACKGROUND,
        ambient: None,
        frame_times: None,
        notes,
    })
}

/// Parses and validates the JSON (and GLB container).
///
/// gltf's validation misses a few references (see [`check_unvalidated_references`]), so
/// those are checked first on the unvalidated document; a panic anywhere else in parsing
/// is still caught and reported like any other malformed file.
fn parse(bytes: &[u8]) -> Result<gltf::Gltf, String> {
    let parsed = catch_unwind(AssertUnwindSafe(|| {
        let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(bytes)?;
        Ok::<_, gltf::Error>(check_unvalidated_references(&document).map(|()| (document, blob)))
    }));
    let (document, blob) = match parsed {
        Ok(Ok(checked)) => checked?,
        Ok(Err(e)) => return Err(format!("not a valid glTF/GLB file: {e}")),
        Err(_) => return Err("not a valid glTF/GLB file: the parser failed on it".into()),
    };
    match catch_unwind(AssertUnwindSafe(|| {
        gltf::Document::from_json(document.into_json())
    })) {
        Ok(Ok(document)) => Ok(gltf::Gltf { document, blob }),
        Ok(Err(e)) => Err(format!("not a valid glTF/GLB file: {e}")),
        Err(_) => Err("not a valid glTF/GLB file: validation failed on it".into()),
    }
}

/// Size of the GLB file header (magic, version, total length).
const GLB_HEADER_SIZE: usize = 12;

/// For a GLB, checks the header's version and total length against the file's size, so a
/// truncated file is reported as such, and returns that length (`None` for glTF JSON). The
/// glTF spec wants it equal to the file's length; fewer leaves bytes that are not part of
/// the GLB.
fn checked_glb_length(bytes: &[u8]) -> Result<Option<usize>, String> {
    if !bytes.starts_with(b"glTF") {
        // Not a GLB: then JSON, whose first non-blank byte opens an object. Anything else
        // (a GLB with a damaged magic, another format) is said as such, not as the JSON
        // parser's "expected value at line 1 column 1".
        let first = bytes.iter().find(|b| !b.is_ascii_whitespace());
        if first.is_some_and(|&b| b != b'{') {
            return Err(
                "not a valid glTF/GLB file: neither binary glTF (its first 4 bytes are not \
                 `glTF`) nor glTF JSON (it does not start with `{`)"
                    .into(),
            );
        }
        return Ok(None);
    }
    let word = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
    };
    let (Some(version), Some(length)) = (word(4), word(8)) else {
        return Err(format!(
            "GLB file is truncated inside its {GLB_HEADER_SIZE}-byte header"
        ));
    };
    if version != 2 {
        return Err(format!("GLB version {version} is not supported (only 2)"));
    }
    if (length as usize) < GLB_HEADER_SIZE || length as usize > bytes.len() {
        return Err(format!(
            "GLB header declares {length} bytes but the file has {}; it is truncated or corrupt",
            bytes.len()
        ));
    }
    Ok(Some(length as usize))
}

/// Checks the references gltf's validation does not (it would index or unwrap them
/// unchecked later): each primitive's POSITION accessor, each animation channel's target
/// node and path, and each image's source.
fn check_unvalidated_references(document: &gltf::Document) -> Result<(), String> {
    use gltf::json::{mesh::Semantic, validation::Checked};
    let json = document.as_json();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let Some(index) = primitive
                .attributes
                .get(&Checked::Valid(Semantic::Positions))
            else {
                continue;
            };
            if index.value() >= json.accessors.len() {
                return Err(format!(
                    "mesh {m} primitive {p}: POSITION refers to accessor {}, but there are {} accessors",
                    index.value(),
                    json.accessors.len()
                ));
            }
        }
    }
    for (a, animation) in json.animations.iter().enumerate() {
        for (c, channel) in animation.channels.iter().enumerate() {
            let node = channel.target.node.value();
            if node >= json.nodes.len() {
                return Err(format!(
                    "animation {a} channel {c} targets node {node}, but there are {} nodes",
                    json.nodes.len()
                ));
            }
            if let Checked::Invalid = channel.target.path {
                return Err(format!(
                    "animation {a} channel {c} has an unknown target path"
                ));
            }
        }
    }
    for (i, image) in json.images.iter().enumerate() {
        match (&image.uri, &image.buffer_view, &image.mime_type) {
            (Some(_), None, _) | (None, Some(_), Some(_)) => {}
            (None, Some(_), None) => {
                return Err(format!("image {i} has a bufferView but no mimeType"));
            }
            _ => return Err(format!("image {i} needs exactly one of uri and bufferView")),
        }
    }
    Ok(())
}
