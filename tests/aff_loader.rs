//! AFF (BART) loader tests.

use std::path::{Path, PathBuf};
use std::time::Instant;

use mipray::scene::aff;

fn bart_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/bart");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("skipping: ../shared/bart not present");
        None
    }
}

#[test]
fn bart_scenes_probe() {
    let Some(dir) = bart_dir() else { return };
    for f in ["kitchen/aff/kitchen.aff", "robots/aff/Robot.aff", "museum/aff/museum5.aff"] {
        let t = Instant::now();
        let (scene, stats) = aff::load_with_stats(&dir.join(f)).unwrap();
        println!("{f}: {:?} in {:?}", stats, t.elapsed());
        println!("  inst tris {} meshes {} nodes {} mats {} tex {} lights {} notes {:?}", scene.instanced_triangle_count(), scene.meshes.len(), scene.nodes.len(), scene.materials.len(), scene.textures.len(), scene.lights.len(), scene.notes);
    }
}
