//! glTF loader tests: a round trip through files the tests write themselves (embedded,
//! external and GLB variants of one scene), the shared sample models against the triangle
//! counts documented in `../shared/gltf/SOURCE.md`, and malformed inputs that must be
//! reported as errors naming the file, never panics.

mod common;

use std::f32::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

use glam::{Mat4, Quat, Vec2, Vec3};
use mipray::anim::{AnimationSelection, Pose, VertexSpace, deform_primitive, primitive_deforms};
use mipray::scene::gltf::load;
use mipray::scene::{ChannelTarget, Interpolation, LightKind, SceneDesc};
use mipray::texture::{MipFilter, WrapMode};
use serde_json::{Value, json};

use common::BufferBuilder;
use common::invariants::{assert_valid, at_path, remove_member, value_paths};
use common::round_trip::{
    BIN_NAME, BIN_URI, PNG_HEIGHT, PNG_NAME, PNG_WIDTH, Storage, round_trip_scene, write,
    write_round_trip,
};

// ---------------------------------------------------------------------------------------
// Round trip
// ---------------------------------------------------------------------------------------

fn assert_close2(actual: Vec2, expected: Vec2) {
    assert!(
        (actual - expected).length() < 1e-5,
        "{actual} != {expected}"
    );
}

/// Every count and a selection of exact values of the round-trip scene.
fn check_round_trip(scene: &SceneDesc, file: &Path) {
    assert_eq!(scene.source, file);
    assert_eq!(scene.background, mipray::scene::gltf::BACKGROUND);

    // Counts.
    assert_eq!(scene.meshes.len(), 2);
    assert_eq!(scene.meshes[0].primitives.len(), 2);
    assert_eq!(
        scene.meshes[1].primitives.len(),
        1,
        "the line primitive is skipped"
    );
    assert_eq!(scene.nodes.len(), 7);
    assert_eq!(scene.roots, vec![0, 4]);
    assert_eq!(scene.materials.len(), 2);
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(scene.cameras.len(), 1, "the orthographic camera is skipped");
    assert_eq!(scene.lights.len(), 2);
    assert_eq!(scene.animations.len(), 1);
    assert_eq!(scene.animations[0].channels.len(), 3);
    // Node 0 and node 2 draw the quad mesh (3 triangles), node 1 the sparse triangle;
    // the orphan node 6 is outside the scene.
    assert_eq!(scene.instanced_triangle_count(), 3 + 1 + 3);
    assert!(
        scene.notes.iter().any(|n| n.contains("orthographic")),
        "{:?}",
        scene.notes
    );
    assert!(
        scene.notes.iter().any(|n| n.contains("point/line")),
        "{:?}",
        scene.notes
    );

    // Geometry: index types, normalised normals, transformed UVs from the override set.
    let quad = &scene.meshes[0].primitives[0];
    assert_eq!(quad.indices, vec![0, 1, 2, 0, 2, 3]);
    assert_eq!(quad.normals.as_deref(), Some(&[Vec3::Z; 4][..]));
    let uvs = quad.uvs.as_ref().expect("textured quad has UVs");
    // uv' = offset + R(rotation) * (scale * uv) with R = [[cos, sin], [-sin, cos]]:
    // (1, 0) -> (2, 0) -> (0, -2) -> (0.5, -1.75), and so on.
    let expected = [
        Vec2::new(0.5, 0.25),
        Vec2::new(0.5, -1.75),
        Vec2::new(3.5, -1.75),
        Vec2::new(3.5, 0.25),
    ];
    for (uv, expected) in uvs.iter().zip(expected) {
        assert_close2(*uv, expected);
    }
    assert_eq!(quad.material, Some(0));
    let glass = &scene.meshes[0].primitives[1];
    assert_eq!(glass.indices, vec![0, 1, 3]);
    assert!(glass.uvs.is_none() && glass.normals.is_none());
    let sparse = &scene.meshes[1].primitives[0];
    assert_eq!(
        sparse.positions,
        vec![Vec3::ZERO, Vec3::new(5.0, 6.0, 7.0), Vec3::Y]
    );
    assert_eq!(sparse.indices, vec![0, 1, 2]);
    assert_eq!(sparse.material, None);

    // Nodes.
    let root = &scene.nodes[0];
    assert_eq!(root.name, "root");
    assert_eq!(root.children, vec![1, 2]);
    assert_eq!(root.local.translation, Vec3::new(1.0, 2.0, 3.0));
    assert!(
        root.local
            .rotation
            .abs_diff_eq(Quat::from_rotation_y(FRAC_PI_2), 1e-6)
    );
    assert_eq!(root.local.scale, Vec3::splat(2.0));
    assert!(root.matrix.is_none());
    let matrix_child = &scene.nodes[1];
    let expected_matrix = Mat4::from_scale_rotation_translation(
        Vec3::splat(2.0),
        Quat::IDENTITY,
        Vec3::new(0.0, 0.0, 5.0),
    );
    assert_eq!(matrix_child.matrix, Some(expected_matrix));
    assert!(
        matrix_child
            .local
            .translation
            .abs_diff_eq(Vec3::new(0.0, 0.0, 5.0), 1e-6)
    );
    assert!(matrix_child.local.scale.abs_diff_eq(Vec3::splat(2.0), 1e-6));
    assert_eq!(scene.nodes[3].camera, Some(0));
    assert_eq!(
        scene.nodes[6].camera, None,
        "orthographic camera maps to none"
    );
    assert_eq!(
        (scene.nodes[4].light, scene.nodes[5].light),
        (Some(0), Some(1))
    );

    // Camera and lights.
    assert_eq!((scene.cameras[0].yfov, scene.cameras[0].znear), (0.8, 0.1));
    let point = &scene.lights[0];
    assert_eq!(point.kind, LightKind::Point);
    assert_eq!(
        (point.color, point.intensity, point.range),
        (Vec3::new(1.0, 0.5, 0.25), 40.0, Some(10.0))
    );
    let spot = &scene.lights[1];
    assert_eq!(
        spot.kind,
        LightKind::Spot {
            inner_cone: 0.2,
            outer_cone: 0.6
        }
    );
    assert_eq!(
        (spot.color, spot.intensity, spot.range),
        (Vec3::ONE, 5.0, None)
    );

    // Materials and the texture.
    let textured = &scene.materials[0];
    assert_eq!(textured.base_color, Vec3::new(0.5, 0.25, 1.0));
    assert_eq!(textured.base_color_texture, Some(0));
    assert!(textured.double_sided);
    assert_eq!(textured.reflectance, 0.25, "metallic 1 * (1 - 0.5)^2");
    assert_eq!(textured.specular, 0.125);
    assert!((textured.shininess - 30.0).abs() < 1e-3, "2 / 0.5^4 - 2");
    let glass = &scene.materials[1];
    assert_eq!(
        (glass.transmission, glass.ior, glass.reflectance),
        (0.9, 1.33, 0.0)
    );
    assert!(!glass.double_sided && glass.base_color_texture.is_none());
    let texture = &scene.textures[0];
    assert_eq!(texture.sampler.wrap_s, WrapMode::ClampToEdge);
    assert_eq!(texture.sampler.wrap_t, WrapMode::MirroredRepeat);
    // LINEAR_MIPMAP_NEAREST: one level a lookup.
    assert_eq!(texture.sampler.mip, MipFilter::Nearest);
    assert_eq!(texture.pyramid.base_size(), (PNG_WIDTH, PNG_HEIGHT));
    assert_eq!(texture.pyramid.level_count(), 3, "4x2, 2x1, 1x1");

    // Animation.
    let animation = &scene.animations[0];
    assert_eq!(animation.name, "move");
    assert_eq!(animation.duration(), 2.5);
    assert_eq!(scene.duration(), 2.5);
    let [step, linear, cubic] = &animation.channels[..] else {
        unreachable!()
    };
    assert_eq!(
        (step.node, step.target, step.interpolation),
        (0, ChannelTarget::Translation, Interpolation::Step)
    );
    assert_eq!(step.times, vec![0.0, 1.0, 2.0]);
    assert_eq!(
        step.values,
        vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    );
    assert_eq!(step.components, 3);
    assert_eq!(
        (linear.node, linear.target, linear.interpolation),
        (2, ChannelTarget::Rotation, Interpolation::Linear)
    );
    assert_eq!(
        linear.values,
        vec![0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0],
        "normalized i16 keys"
    );
    assert_eq!(linear.components, 4);
    assert_eq!(
        (cubic.target, cubic.interpolation),
        (ChannelTarget::Scale, Interpolation::CubicSpline)
    );
    assert_eq!(cubic.values.len(), 2 * 3 * 3);
    assert_eq!(
        &cubic.values[12..15],
        &[2.0, 3.0, 4.0],
        "value of key 1 follows its in-tangent"
    );
}

#[test]
fn round_trip_with_embedded_data_uris() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_round_trip(dir.path(), Storage::Embedded);
    let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
    check_round_trip(&scene, &path);
}

#[test]
fn round_trip_with_external_bin_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_round_trip(dir.path(), Storage::External);
    let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
    check_round_trip(&scene, &path);
    assert_eq!(scene.textures[0].name, PNG_NAME);
}

#[test]
fn round_trip_as_glb() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_round_trip(dir.path(), Storage::Binary);
    let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
    check_round_trip(&scene, &path);
}

#[test]
fn strips_fans_and_non_indexed_primitives_become_triangle_lists() {
    let mut b = BufferBuilder::default();
    let positions = b.positions(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ]);
    let json = json!({
        "asset": { "version": "2.0" },
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [
            { "attributes": { "POSITION": positions }, "mode": 5 },
            { "attributes": { "POSITION": positions }, "mode": 6 },
            { "attributes": { "POSITION": positions }, "mode": 0 },
        ] }],
    });
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "modes.gltf",
        &serde_json::to_vec(&common::with_embedded_buffer(json, &b)).unwrap(),
    );
    let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
    // No scene in the file: every parentless node is a root.
    assert_eq!(scene.roots, vec![0]);
    let primitives = &scene.meshes[0].primitives;
    assert_eq!(primitives.len(), 2, "points are skipped");
    assert_eq!(primitives[0].indices, vec![0, 1, 2, 1, 3, 2]);
    assert_eq!(primitives[1].indices, vec![1, 2, 0, 2, 3, 0]);
    assert_eq!(scene.instanced_triangle_count(), 4);
}

/// Morph targets load as data beside the un-morphed base; the default weights shape the
/// rest pose only when the pose is evaluated (they are no longer baked into positions).
#[test]
fn default_morph_weights_shape_the_rest_pose() {
    let mut b = BufferBuilder::default();
    let positions = b.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let normals = b.floats(&[[0.0, 0.0, 1.0]; 3], "VEC3");
    let position_deltas = b.floats(&[[0.0, 0.0, 2.0], [0.0, 0.0, 0.0], [4.0, 0.0, 0.0]], "VEC3");
    let normal_deltas = b.floats(
        &[[2.0, 0.0, -1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
        "VEC3",
    );
    let unused_deltas = b.floats(&[[9.0, 9.0, 9.0]; 3], "VEC3");
    let json = json!({
        "asset": { "version": "2.0" },
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "weights": [0.5, 0.0], "primitives": [{
            "attributes": { "POSITION": positions, "NORMAL": normals },
            "targets": [{ "POSITION": position_deltas, "NORMAL": normal_deltas }, { "POSITION": unused_deltas }],
        }] }],
    });
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "morph.gltf",
        &serde_json::to_vec(&common::with_embedded_buffer(json, &b)).unwrap(),
    );
    let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
    let mesh = &scene.meshes[0];
    assert_eq!(mesh.weights, vec![0.5, 0.0]);
    let primitive = &mesh.primitives[0];
    // The base geometry is exactly the file's.
    assert_eq!(primitive.positions, vec![Vec3::ZERO, Vec3::X, Vec3::Y]);
    assert_eq!(primitive.normals.as_deref(), Some(&[Vec3::Z; 3][..]));
    assert_eq!(primitive.morph_targets.len(), 2);
    assert_eq!(
        primitive.morph_targets[0].positions.as_deref(),
        Some(
            &[
                Vec3::new(0.0, 0.0, 2.0),
                Vec3::ZERO,
                Vec3::new(4.0, 0.0, 0.0)
            ][..]
        )
    );
    assert_eq!(
        primitive.morph_targets[0].normals.as_deref(),
        Some(&[Vec3::new(2.0, 0.0, -1.0), Vec3::ZERO, Vec3::ZERO][..])
    );
    assert_eq!(
        primitive.morph_targets[1].positions.as_deref(),
        Some(&[Vec3::splat(9.0); 3][..])
    );
    assert_eq!(primitive.morph_targets[1].normals, None);
    assert!(primitive_deforms(&scene, 0, 0, 0));

    // The rest pose: base + 0.5 * target 0.
    let mut pose = Pose::default();
    pose.evaluate(&scene, AnimationSelection::All, 0.0);
    let (mut positions, mut normals) = (Vec::new(), Vec::new());
    let space = deform_primitive(&scene, &pose, 0, 0, 0, &mut positions, &mut normals);
    assert_eq!(space, VertexSpace::Object);
    assert_eq!(
        positions,
        vec![Vec3::new(0.0, 0.0, 1.0), Vec3::X, Vec3::new(2.0, 1.0, 0.0)]
    );
    // Normal 0: (0, 0, 1) + 0.5 * (2, 0, -1) = (1, 0, 0.5), renormalised.
    assert!(normals[0].abs_diff_eq(Vec3::new(1.0, 0.0, 0.5).normalize(), 1e-6));
    assert_eq!(normals[1], Vec3::Z);
    assert!(
        !scene
            .notes
            .iter()
            .any(|n| n.contains("morph") || n.contains("rest pose")),
        "{:?}",
        scene.notes
    );
}

// ---------------------------------------------------------------------------------------
// Shared sample models
// ---------------------------------------------------------------------------------------

/// Models whose SOURCE.md count is per mesh, not per instance: the count there is the sum
/// over meshes, and the instanced count (what is traced) adds the repeated instances.
/// - CesiumMilkTruck: the 768-triangle wheel mesh is drawn by two nodes (front and rear
///   axle): 2856 + 768 = 3624.
/// - NegativeScaleTest: three 1280-triangle sphere meshes are each drawn twice (scale +1
///   and -1 versions side by side): 3884 + 3 * 1280 = 7724.
const PER_MESH_COUNTS: &[(&str, usize)] = &[("CesiumMilkTruck", 3624), ("NegativeScaleTest", 7724)];

/// One row of SOURCE.md's model table: the model and its documented triangle count.
struct ModelRow {
    name: String,
    triangles: Option<usize>,
}

/// Parses the `## Models` table: first column the model, last column "what it exercises"
/// with "N tris" or "1 triangle" (rows without a number are only checked to load).
fn parse_model_table(source: &str) -> Vec<ModelRow> {
    let table = source
        .split("## Models")
        .nth(1)
        .expect("SOURCE.md has a ## Models section");
    table
        .lines()
        .skip_while(|line| !line.starts_with('|'))
        .take_while(|line| line.starts_with('|'))
        .skip(2) // header and separator
        .map(|line| {
            let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
            ModelRow {
                name: cells[0].to_string(),
                triangles: triangle_count(cells[cells.len() - 1]),
            }
        })
        .collect()
}

/// "…; 254 tris; …" -> 254, "…on 1 triangle…" -> 1; several different numbers would be
/// ambiguous, so they fail the test rather than pick one.
fn triangle_count(text: &str) -> Option<usize> {
    let words: Vec<&str> = text.split_whitespace().collect();
    let mut counts: Vec<usize> = words
        .windows(2)
        .filter(|w| w[1].starts_with("tris") || w[1].starts_with("triangle"))
        .filter_map(|w| w[0].replace(',', "").parse().ok())
        .collect();
    counts.dedup();
    assert!(
        counts.len() <= 1,
        "ambiguous triangle counts {counts:?} in '{text}'"
    );
    counts.first().copied()
}

fn model_file(dir: &Path) -> PathBuf {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb")))
        .collect();
    assert_eq!(files.len(), 1, "one .gltf/.glb in {}", dir.display());
    files.remove(0)
}

#[test]
fn triangle_counts_are_read_from_the_table_cells() {
    assert_eq!(
        triangle_count("node TRS anim: 1 anim; 2 meshes, 254 tris; untextured"),
        Some(254)
    );
    assert_eq!(
        triangle_count("morph: 2 POSITION targets on 1 triangle, weights"),
        Some(1)
    );
    assert_eq!(
        triangle_count("skin: 2 joints on 1,876 verts; 4,672 tris"),
        Some(4672)
    );
    assert_eq!(triangle_count("UV orientation: 5 quads"), None);
}

#[test]
fn shared_sample_models_load_with_documented_triangle_counts() {
    let Some(root) = common::shared_data::shared_path("gltf") else {
        return;
    };
    let rows = parse_model_table(&std::fs::read_to_string(root.join("SOURCE.md")).unwrap());
    assert!(rows.len() >= 25, "parsed only {} model rows", rows.len());
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    let mut counted = 0;
    for dir in &dirs {
        let name = dir.file_name().unwrap().to_str().unwrap();
        let file = model_file(dir);
        let scene = load(&file).unwrap_or_else(|e| panic!("{name} failed to load: {e}"));
        let row = rows
            .iter()
            .find(|r| r.name == name)
            .unwrap_or_else(|| panic!("{name} is not in SOURCE.md"));
        let Some(documented) = row.triangles else {
            continue;
        };
        let per_mesh: usize = scene
            .meshes
            .iter()
            .flat_map(|m| &m.primitives)
            .map(|p| p.triangle_count())
            .sum();
        match PER_MESH_COUNTS.iter().find(|(model, _)| *model == name) {
            Some(&(_, instanced)) => {
                assert_eq!(per_mesh, documented, "{name}: mesh triangles");
                assert_eq!(
                    scene.instanced_triangle_count(),
                    instanced,
                    "{name}: instanced triangles"
                );
            }
            None => assert_eq!(
                scene.instanced_triangle_count(),
                documented,
                "{name}: instanced triangles"
            ),
        }
        counted += 1;
    }
    assert!(
        counted >= 20,
        "only {counted} models had a documented count"
    );
    assert!(
        dirs.iter()
            .any(|d| d.ends_with("TextureTransformMultiTest"))
    );
}

#[test]
fn texture_transform_multi_test_needs_the_extension_and_loads() {
    let Some(file) = common::shared_data::shared_path(
        "gltf/TextureTransformMultiTest/TextureTransformMultiTest.glb",
    ) else {
        return;
    };
    let scene = load(&file).unwrap_or_else(|e| panic!("{e}"));
    assert!(!scene.textures.is_empty());
    assert!(
        scene
            .meshes
            .iter()
            .flat_map(|m| &m.primitives)
            .any(|p| p.uvs.is_some())
    );
}

// ---------------------------------------------------------------------------------------
// Bad input
// ---------------------------------------------------------------------------------------

/// Loads `path`, which must fail with a message naming the file and containing `needles`.
fn expect_error(path: &Path, needles: &[&str]) -> String {
    let message = match load(path) {
        Ok(_) => panic!("{} loaded but should fail", path.display()),
        Err(e) => e.to_string(),
    };
    println!("{message}");
    let file_name = path.file_name().unwrap().to_str().unwrap();
    assert!(
        message.contains(file_name),
        "'{message}' does not name {file_name}"
    );
    for needle in needles {
        assert!(
            message.contains(needle),
            "'{message}' does not mention '{needle}'"
        );
    }
    message
}

/// Writes the single-triangle glTF after `corrupt` has changed its JSON or buffer.
fn write_corrupted(
    dir: &Path,
    name: &str,
    positions: &[[f32; 3]],
    indices: &[u16],
    corrupt: impl FnOnce(&mut Value),
) -> PathBuf {
    let (json, buffers) = common::single_triangle(positions, indices);
    let mut json = common::with_embedded_buffer(json, &buffers);
    corrupt(&mut json);
    write(dir, name, &serde_json::to_vec(&json).unwrap())
}

const TRIANGLE: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

#[test]
fn single_triangle_helper_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_corrupted(dir.path(), "ok.gltf", &TRIANGLE, &[0, 1, 2], |_| {});
    let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.instanced_triangle_count(), 1);
    assert_eq!(scene.meshes[0].primitives[0].positions[2], Vec3::Y);
}

#[test]
fn truncated_glb_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let png = common::png(PNG_WIDTH, PNG_HEIGHT);
    let (json, bin) = round_trip_scene(Storage::Binary, &png);
    let glb = common::glb(&json, &bin);
    // Cut in the middle of the BIN chunk's data.
    let cut = glb.len() - bin.len() / 2;
    let path = write(dir.path(), "truncated.glb", &glb[..cut]);
    expect_error(
        &path,
        &[&format!(
            "GLB header declares {} bytes but the file has {cut}",
            glb.len()
        )],
    );
}

/// A GLB whose magic is damaged is said to be neither GLB nor JSON, not reported as the
/// JSON parser's complaint about its first byte; JSON with leading blanks still loads.
#[test]
fn a_damaged_magic_is_neither_glb_nor_json() {
    let dir = tempfile::tempdir().unwrap();
    let png = common::png(PNG_WIDTH, PNG_HEIGHT);
    let (json, bin) = round_trip_scene(Storage::Binary, &png);
    let mut glb = common::glb(&json, &bin);
    glb[..4].copy_from_slice(b"gLTF");
    let path = write(dir.path(), "magic.glb", &glb);
    expect_error(
        &path,
        &["magic.glb", "neither binary glTF", "nor glTF JSON"],
    );
    let full = write_round_trip(dir.path(), Storage::Embedded);
    let mut text = b"\n  \t".to_vec();
    text.extend(std::fs::read(&full).unwrap());
    let path = write(dir.path(), "blank_first.gltf", &text);
    load(&path).unwrap_or_else(|e| panic!("{e}"));
}

/// A GLB whose header declares fewer bytes than the file holds is read from the declared
/// bytes alone, with a note saying how many were ignored; an exact GLB gets no such note.
#[test]
fn bytes_past_a_glbs_declared_length_are_ignored_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let png = common::png(PNG_WIDTH, PNG_HEIGHT);
    let (json, bin) = round_trip_scene(Storage::Binary, &png);
    let glb = common::glb(&json, &bin);
    let exact = load(&write(dir.path(), "exact.glb", &glb)).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        !exact.notes.iter().any(|n| n.contains("declares")),
        "{:?}",
        exact.notes
    );
    let mut longer = glb.clone();
    longer.extend_from_slice(b"trailer");
    let scene = load(&write(dir.path(), "longer.glb", &longer)).unwrap_or_else(|e| panic!("{e}"));
    let note = scene
        .notes
        .iter()
        .find(|n| n.contains("declares"))
        .unwrap_or_else(|| panic!("no note among {:?}", scene.notes));
    assert!(
        note.contains(&format!("declares {} bytes", glb.len()))
            && note.contains(&format!("the file has {}", longer.len()))
            && note.contains("the 7 bytes after them are ignored"),
        "{note}"
    );
    assert_eq!(scene.meshes.len(), exact.meshes.len());
    // A header that declares only the JSON chunk leaves the BIN chunk outside the GLB: the
    // buffer it holds is then missing, and the error says why.
    let json_chunk = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let mut short = glb.clone();
    short[8..12].copy_from_slice(&((20 + json_chunk) as u32).to_le_bytes());
    expect_error(
        &write(dir.path(), "short.glb", &short),
        &["short.glb", &format!("declares {} bytes", 20 + json_chunk)],
    );
}

#[test]
fn truncated_json_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let full = write_round_trip(dir.path(), Storage::Embedded);
    let text = std::fs::read(&full).unwrap();
    let path = write(dir.path(), "truncated.gltf", &text[..text.len() / 2]);
    expect_error(&path, &["not a valid glTF/GLB"]);
}

#[test]
fn missing_external_bin_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_round_trip(dir.path(), Storage::External);
    std::fs::remove_file(dir.path().join(BIN_NAME)).unwrap();
    expect_error(&path, &["buffer 0", BIN_URI, BIN_NAME]);
}

#[test]
fn short_external_bin_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_round_trip(dir.path(), Storage::External);
    let bin = std::fs::read(dir.path().join(BIN_NAME)).unwrap();
    write(dir.path(), BIN_NAME, &bin[..bin.len() - 10]);
    expect_error(
        &path,
        &[
            "buffer 0",
            &format!(
                "has {} bytes but declares byteLength {}",
                bin.len() - 10,
                bin.len()
            ),
        ],
    );
}

#[test]
fn missing_external_png_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_round_trip(dir.path(), Storage::External);
    std::fs::remove_file(dir.path().join(PNG_NAME)).unwrap();
    expect_error(&path, &["image 0", PNG_NAME]);
}

#[test]
fn undecodable_png_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_round_trip(dir.path(), Storage::External);
    write(dir.path(), PNG_NAME, b"\x89PNG but not really");
    expect_error(&path, &["image 0", PNG_NAME]);
}

#[test]
fn index_out_of_range_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_corrupted(dir.path(), "bad_index.gltf", &TRIANGLE, &[0, 1, 7], |_| {});
    expect_error(
        &path,
        &["accessor 1", "mesh 0 primitive 0", "index 7", "3 vertices"],
    );
}

#[test]
fn nan_position_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let positions = [[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let path = write_corrupted(dir.path(), "nan.gltf", &positions, &[0, 1, 2], |_| {});
    expect_error(
        &path,
        &[
            "accessor 0",
            "POSITION of mesh 0 primitive 0",
            "non-finite",
            "element 1",
        ],
    );
}

#[test]
fn accessor_overflowing_its_view_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    // 3 VEC3 floats are 36 bytes; claiming 10 elements reads 120.
    let path = write_corrupted(dir.path(), "overflow.gltf", &TRIANGLE, &[0, 1, 2], |json| {
        json["accessors"][0]["count"] = json!(10);
    });
    expect_error(
        &path,
        &[
            "accessor 0 (POSITION of mesh 0 primitive 0) reads bytes 0..120 but buffer view 0 has 36 bytes",
        ],
    );
}

#[test]
fn view_overflowing_its_buffer_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_corrupted(dir.path(), "view.gltf", &TRIANGLE, &[0, 1, 2], |json| {
        json["bufferViews"][1]["byteOffset"] = json!(4000);
    });
    expect_error(
        &path,
        &["buffer view 1 (bytes 4000..4006) does not fit buffer 0 of 42 bytes"],
    );
}

#[test]
fn sparse_index_past_count_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let png = common::png(PNG_WIDTH, PNG_HEIGHT);
    let (mut json, _) = round_trip_scene(Storage::Embedded, &png);
    // The sparse accessor substitutes vertex 1; shrinking it to one element puts that
    // substitution past the end.
    let sparse = json["accessors"]
        .as_array()
        .unwrap()
        .iter()
        .position(|a| a.get("sparse").is_some())
        .unwrap();
    json["accessors"][sparse]["count"] = json!(1);
    let path = write(
        dir.path(),
        "sparse.gltf",
        &serde_json::to_vec(&json).unwrap(),
    );
    expect_error(&path, &["sparse index 1 is not below count 1"]);
}

#[test]
fn node_cycle_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_corrupted(dir.path(), "cycle.gltf", &TRIANGLE, &[0, 1, 2], |json| {
        json["nodes"] = json!([{ "mesh": 0 }, { "children": [2] }, { "children": [1] }]);
    });
    expect_error(&path, &["cycle"]);
}

#[test]
fn unknown_accessor_index_is_an_error_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_corrupted(dir.path(), "unknown.gltf", &TRIANGLE, &[0, 1, 2], |json| {
        json["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
    });
    expect_error(
        &path,
        &["POSITION refers to accessor 99, but there are 2 accessors"],
    );
}

#[test]
fn empty_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "empty.gltf", b"");
    expect_error(&path, &["empty"]);
}

#[test]
fn random_bytes_are_an_error() {
    let dir = tempfile::tempdir().unwrap();
    // A fixed xorshift sequence: arbitrary but reproducible bytes.
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state as u8
        })
        .collect();
    let path = write(dir.path(), "noise.glb", &bytes);
    expect_error(&path, &["not a valid glTF/GLB"]);
}

#[test]
fn missing_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    expect_error(&dir.path().join("absent.gltf"), &["cannot read file"]);
}

// ---------------------------------------------------------------------------------------
// Robustness
// ---------------------------------------------------------------------------------------

/// Mutates the round-trip scene's JSON one change at a time: every number (counts,
/// offsets, strides, indices, component types, factors, ...) replaced by hostile values,
/// every object member removed, and every buffer word overwritten. Loading may fail, but
/// must never panic or produce a non-finite number or an out-of-range index.
#[test]
fn mutated_files_never_panic_or_yield_invalid_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let png = common::png(PNG_WIDTH, PNG_HEIGHT);
    let (json, bin) = round_trip_scene(Storage::Binary, &png);
    let mut paths = Vec::new();
    value_paths(&json, &mut Vec::new(), &mut paths);
    assert!(paths.len() > 300, "only {} values to mutate", paths.len());
    let hostile = [
        json!(0),
        json!(1),
        json!(3),
        json!(-1),
        json!(5126),
        json!(255),
        json!(65535),
        json!(4294967295u64),
        json!(1e30),
        json!(0.5),
    ];
    let file = dir.path().join("mutated.glb");
    let (mut loaded, mut rejected) = (0, 0);
    let mut check = |mutated: &Value, bin: &[u8], what: &str| {
        std::fs::write(&file, common::glb(mutated, bin)).unwrap();
        match std::panic::catch_unwind(|| load(&file)) {
            Err(_) => panic!("panic with {what}"),
            Ok(Ok(scene)) => {
                assert_valid(&scene, what);
                loaded += 1;
            }
            Ok(Err(_)) => rejected += 1,
        }
    };
    for path in &paths {
        let mut removed = json.clone();
        if remove_member(&mut removed, path) {
            check(&removed, &bin, &format!("{path:?} removed"));
        }
        if at_path(&mut json.clone(), path).is_number() {
            for value in &hostile {
                let mut mutated = json.clone();
                *at_path(&mut mutated, path) = value.clone();
                check(&mutated, &bin, &format!("{path:?} = {value}"));
            }
        }
    }
    // Buffer data: every aligned word as a NaN, a huge and a negative number.
    for word in (0..bin.len() / 4).map(|w| 4 * w) {
        for hostile in [f32::NAN.to_bits(), u32::MAX, (-1.0f32).to_bits()] {
            let mut corrupted = bin.clone();
            corrupted[word..word + 4].copy_from_slice(&hostile.to_le_bytes());
            check(
                &json,
                &corrupted,
                &format!("buffer word at {word} = {hostile:#x}"),
            );
        }
    }
    assert!(
        loaded > 100 && rejected > 100,
        "loaded {loaded}, rejected {rejected}"
    );
}
