//! glTF 2.0 loader (stub until the loader lands).

use std::path::Path;

use super::SceneDesc;

#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct LoadError {
    pub path: std::path::PathBuf,
    pub message: String,
}

/// Loads a `.gltf` or `.glb` file into a scene description.
pub fn load(path: &Path) -> Result<SceneDesc, LoadError> {
    let _ = path;
    todo!("glTF loader")
}
