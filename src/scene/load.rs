//! The loader for a scene file, chosen by its extension.

use std::path::Path;

use anyhow::{Result, bail};

/// Loads a `.gltf`/`.glb`, `.aff` (BART), `.obj` or `.usda`/`.usdc`/`.usdz`/`.usd` (OpenUSD)
/// scene.
///
/// # Errors
/// An unsupported extension, or the loader's error (naming the file and the element).
pub fn load(path: &Path) -> Result<super::SceneDesc> {
    load_with_sources(path).map(|(scene, _)| scene)
}

/// [`load`], with every file the load read (the scene file, its buffers, textures, layers,
/// includes, material and camera files), each with a digest of its bytes (see
/// [`super::sources`]).
///
/// # Errors
/// As [`load`].
pub fn load_with_sources(
    path: &Path,
) -> Result<(super::SceneDesc, Vec<super::sources::SourceFile>)> {
    let (scene, files) = super::sources::recording(|| load_by_extension(path));
    Ok((scene?, files))
}

fn load_by_extension(path: &Path) -> Result<super::SceneDesc> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("gltf") | Some("glb") => Ok(super::gltf::load(path)?),
        Some("aff") => Ok(super::aff::load(path)?),
        Some("obj") => Ok(super::obj::load(path)?),
        Some("usda") | Some("usdc") | Some("usdz") | Some("usd") => Ok(super::usd::load(path)?),
        _ => bail!(
            "{}: unsupported scene format (expected .gltf, .glb, .aff, .obj, .usda, .usdc, .usdz or .usd)",
            path.display()
        ),
    }
}
