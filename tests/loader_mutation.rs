//! Mutation tests for the text loaders on the stable toolchain (the glTF one is in
//! `gltf_loader.rs`): the AFF fixture scene (with its include and PPM texture, in memory)
//! and a small textured OBJ with its MTL, changed one token at a time: every token
//! replaced by hostile tokens, every token removed, the file cut after every token.
//! Loading may fail, but must never panic, and a scene that loads must keep the
//! `SceneDesc` invariants (finite numbers, indices in range).

use std::path::{Path, PathBuf};

use mipray::scene::SceneDesc;

mod common;

use common::invariants::assert_valid;

/// Tokens that stress counts, indices, numbers and structure.
const HOSTILE_TOKENS: [&str; 12] = [
    "0",
    "-1",
    "1",
    "3",
    "4294967295",
    "99999999999999999999",
    "1e30",
    "-1e-30",
    "nan",
    "{",
    "}",
    "\u{ff}",
];

/// Byte ranges of the whitespace-separated tokens of `text`.
fn token_ranges(text: &str) -> Vec<std::ops::Range<usize>> {
    let mut ranges = Vec::new();
    let mut start = None;
    for (i, c) in text.char_indices() {
        match (c.is_whitespace(), start) {
            (true, Some(s)) => {
                ranges.push(s..i);
                start = None;
            }
            (false, None) => start = Some(i),
            _ => {}
        }
    }
    if let Some(s) = start {
        ranges.push(s..text.len());
    }
    ranges
}

/// Every single-token mutation of `text`, each with a description.
fn mutations(text: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for range in token_ranges(text) {
        let token = &text[range.clone()];
        let (before, after) = (&text[..range.start], &text[range.end..]);
        for hostile in HOSTILE_TOKENS {
            out.push((
                format!("{before}{hostile}{after}"),
                format!("'{token}' at byte {} -> '{hostile}'", range.start),
            ));
        }
        out.push((
            format!("{before}{after}"),
            format!("'{token}' at byte {} removed", range.start),
        ));
        out.push((
            text[..range.end].to_string(),
            format!("cut after byte {}", range.end),
        ));
    }
    out
}

/// Loads each mutation with `load`; panics on a panic or an invalid scene. Returns
/// (loaded, rejected) counts.
fn run_mutations(
    text: &str,
    label: &str,
    load: impl Fn(&str) -> Result<SceneDesc, String>,
) -> (usize, usize) {
    let (mut loaded, mut rejected) = (0, 0);
    for (mutated, what) in mutations(text) {
        let what = format!("{label}: {what}");
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load(&mutated))) {
            Err(_) => panic!("panic with {what}"),
            Ok(Ok(scene)) => {
                assert_valid(&scene, &what);
                loaded += 1;
            }
            Ok(Err(e)) => {
                assert!(!e.is_empty(), "{what}: empty error");
                rejected += 1;
            }
        }
    }
    (loaded, rejected)
}

fn aff_fixture(name: &str) -> Vec<u8> {
    std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/aff")
            .join(name),
    )
    .unwrap()
}

/// AFF files are Latin-1: one char per byte, so mutations keep the bytes they do not touch.
fn latin1_decode(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

fn latin1_encode(text: &str) -> Vec<u8> {
    text.chars()
        .map(|c| u8::try_from(c).unwrap_or(b'?'))
        .collect()
}

/// Loads the AFF scene `main` (as `scene.aff`) with `parts` as its `parts.aff`.
fn load_aff(main: &str, parts: &str) -> Result<SceneDesc, String> {
    let files = [
        (PathBuf::from("scene.aff"), latin1_encode(main)),
        (PathBuf::from("parts.aff"), latin1_encode(parts)),
        (PathBuf::from("checker.ppm"), aff_fixture("checker.ppm")),
    ];
    mipray::scene::aff::load_from_memory(Path::new("scene.aff"), files)
        .map(|(scene, _)| scene)
        .map_err(|e| e.to_string())
}

#[test]
fn mutated_aff_files_never_panic_or_yield_invalid_scenes() {
    let scene = latin1_decode(&aff_fixture("scene.aff"));
    let parts = latin1_decode(&aff_fixture("parts.aff"));
    load_aff(&scene, &parts).expect("the unmutated fixture loads");
    let (loaded, rejected) = run_mutations(&scene, "scene.aff", |m| load_aff(m, &parts));
    let (parts_loaded, parts_rejected) =
        run_mutations(&parts, "parts.aff", |m| load_aff(&scene, m));
    println!(
        "scene.aff: {loaded} loaded, {rejected} rejected; parts.aff: {parts_loaded} loaded, {parts_rejected} rejected"
    );
    assert!(
        loaded > 200 && rejected > 500,
        "loaded {loaded}, rejected {rejected}"
    );
    assert!(parts_loaded > 10 && parts_rejected > 50);
}

const OBJ: &str = "\
# a textured quad and a triangle with normals
mtllib quad.mtl
o quad
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 1 0
usemtl checker
f 1/1/1 2/2/1 3/3/1 4/4/1
o tri
v 0 1 0
v 1 1 0
v 0 2 0
usemtl plain
f 5//1 6//1 7//1
";

const MTL: &str = "\
newmtl checker
Kd 1 1 1
map_Kd checker.png
newmtl plain
Kd 0.5 0.2 0.1
Ks 0.1 0.1 0.1
Ns 20
";

/// Writes the OBJ's MTL (`mtl`) and texture into `dir` and loads `obj` as `dir/quad.obj`.
fn load_obj(dir: &Path, obj: &str, mtl: &str) -> Result<SceneDesc, String> {
    std::fs::write(dir.join("quad.mtl"), mtl).unwrap();
    mipray::scene::obj::load_from_text(&dir.join("quad.obj"), obj).map_err(|e| e.to_string())
}

#[test]
fn mutated_obj_files_never_panic_or_yield_invalid_scenes() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("checker.png"), common::png(4, 4)).unwrap();
    let scene = load_obj(dir.path(), OBJ, MTL).expect("the unmutated OBJ loads");
    assert_eq!(scene.materials.len(), 2);
    let (loaded, rejected) = run_mutations(OBJ, "quad.obj", |m| load_obj(dir.path(), m, MTL));
    let (mtl_loaded, mtl_rejected) =
        run_mutations(MTL, "quad.mtl", |m| load_obj(dir.path(), OBJ, m));
    println!(
        "quad.obj: {loaded} loaded, {rejected} rejected; quad.mtl: {mtl_loaded} loaded, {mtl_rejected} rejected"
    );
    assert!(
        loaded > 100 && rejected > 100,
        "loaded {loaded}, rejected {rejected}"
    );
    assert!(mtl_loaded > 20 && mtl_rejected > 20);
}
