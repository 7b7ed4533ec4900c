//! Import rules between layers (issue 14): the renderer, LOD and BVH never name the
//! load-time scene description, `lod` does not depend on the render camera, and loaders do
//! not import the exporter. Each rule reads the source files, so a new import that breaks a
//! rule fails here with the file and line that names the forbidden module.

use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir` (recursively), sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(dir) = pending.pop() {
        let entries = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                pending.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Byte offsets in `text` where a path names `crate::<module>`, directly
/// (`crate::scene::X`) or as a top-level item of a grouped import, which may span lines
/// (`use crate::{geometry, scene::X};`).
fn module_mentions(text: &str, module: &str) -> Vec<usize> {
    let is_ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let starts_with_module = |rest: &str| {
        rest.strip_prefix(module)
            .is_some_and(|after| !after.starts_with(is_ident))
    };
    let mut found = Vec::new();
    for (i, m) in text.match_indices("crate::") {
        let rest = &text[i + m.len()..];
        let grouped = rest.strip_prefix('{').is_some_and(|group| {
            top_level_items(group).any(|item| starts_with_module(item.trim_start()))
        });
        if starts_with_module(rest) || grouped {
            found.push(i);
        }
    }
    found
}

/// The comma-separated items of a `{...}` group at its own depth (text after the `{`, up to
/// the matching `}`); nested groups stay inside their item.
fn top_level_items(group: &str) -> impl Iterator<Item = &str> {
    let mut depth = 0;
    let mut start = 0;
    let mut items = Vec::new();
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                items.push(&group[start..i]);
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.into_iter()
}

/// `file:line: text` of every place under `src/<layer>` that names `crate::<module>`.
fn imports(layer: &str, module: &str) -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("src")
        .join(layer);
    assert!(root.is_dir(), "{} is not a directory", root.display());
    let mut found = Vec::new();
    for file in rust_files(&root) {
        let text = std::fs::read_to_string(&file)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", file.display()));
        for offset in module_mentions(&text, module) {
            let line = text[..offset].matches('\n').count() + 1;
            let shown = text[offset..].lines().next().unwrap_or_default();
            found.push(format!("{}:{line}: {shown}", file.display()));
        }
    }
    found
}

#[test]
fn layers_do_not_import_scene() {
    for layer in ["render", "lod", "accel"] {
        let found = imports(layer, "scene");
        assert!(
            found.is_empty(),
            "src/{layer} must not name crate::scene (build render types in geometry::appearance):\n{}",
            found.join("\n")
        );
    }
}

#[test]
fn scene_does_not_import_export() {
    let found = imports("scene", "export");
    assert!(
        found.is_empty(),
        "src/scene must not name crate::export (shared file types live in scene):\n{}",
        found.join("\n")
    );
}

#[test]
fn lod_does_not_import_render() {
    let found = imports("lod", "render");
    assert!(
        found.is_empty(),
        "src/lod must not name crate::render (it takes a lod::ViewFrame):\n{}",
        found.join("\n")
    );
}

#[test]
fn import_check_finds_direct_and_grouped_paths() {
    let finds = |text: &str| !module_mentions(text, "scene").is_empty();
    assert!(finds("use crate::scene::{LightDesc, LightKind};"));
    assert!(finds("    kind: crate::scene::LightKind::Point,"));
    assert!(finds("use crate::{geometry::FrameTriangles, scene};"));
    assert!(finds(
        "use crate::{\n    geometry::{A, B},\n    scene::MaterialDesc,\n};"
    ));
    assert!(!finds("use crate::scenery::Thing;"));
    assert!(!finds("use crate::render::FrameScene;"));
    assert!(!finds("use crate::{geometry::{scene_like, X}, render};"));
    assert!(!finds("// the scene description"));
}
