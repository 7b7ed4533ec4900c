//! glTF loader tests: a round trip through files the tests write themselves (embedded,
//! external and GLB variants of one scene), the shared sample models against the triangle
//! counts documented in `../shared/gltf/SOURCE.md`, and malformed inputs that must be
//! reported as errors naming the file, never panics.

mod common;

use std::f32::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

use glam::{Mat4, Quat, Vec2, Vec3};
use mipray::scene::gltf::load;
use mipray::scene::{ChannelTarget, Interpolation, LightKind, SceneDesc};
use mipray::texture::WrapMode;
use serde_json::{Value, json};

use common::{BufferBuilder, FLOAT, SHORT, UNSIGNED_SHORT};

// ---------------------------------------------------------------------------------------
// Round trip
// ---------------------------------------------------------------------------------------

/// Size of the base-colour PNG the round-trip scene uses.
const PNG_WIDTH: u32 = 4;
const PNG_HEIGHT: u32 = 2;

/// Where the round-trip scene's buffer and image live.
#[derive(Clone, Copy)]
enum Storage {
    /// Buffer and image as base64 data URIs inside the JSON.
    Embedded,
    /// `scene data.bin` (percent-encoded URI) and `tex.png` next to the `.gltf`.
    External,
    /// A `.glb`: buffer in the BIN chunk, image in a buffer view.
    Binary,
}

const BIN_NAME: &str = "scene data.bin";
const BIN_URI: &str = "scene%20data.bin";
const PNG_NAME: &str = "tex.png";

/// The round-trip scene: two meshes (u8/u16/u32 indices, a sparse POSITION accessor, a line
/// primitive to skip), a TRS/matrix hierarchy with an instanced mesh and an orphan node,
/// a perspective and an orthographic camera, a point and a spot light, a textured material
/// with `KHR_texture_transform` and a CLAMP/MIRRORED sampler, a glass material, and an
/// animation with STEP, LINEAR and CUBICSPLINE channels. Returns the JSON and the buffer.
fn round_trip_scene(storage: Storage, png: &[u8]) -> (Value, Vec<u8>) {
    let mut b = BufferBuilder::default();

    // Mesh 0: a unit quad (u16 indices, textured) and one triangle of it (u8 indices, glass).
    let quad_positions = b.positions(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ]);
    let quad_normals = b.floats(&[[0.0, 0.0, 2.0]; 4], "VEC3");
    let quad_uv0 = b.floats(&[[0.9, 0.9]; 4], "VEC2");
    let uv1: Vec<u8> = [[0u16, 0], [65535, 0], [65535, 65535], [0, 65535]]
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    let quad_uv1 = b.accessor(
        &uv1,
        UNSIGNED_SHORT,
        4,
        "VEC2",
        json!({ "normalized": true }),
    );
    let quad_indices = b.indices_u16(&[0, 1, 2, 0, 2, 3]);
    let glass_indices = b.indices_u8(&[0, 1, 3]);

    // Mesh 1: a triangle whose vertex 1 is replaced by a sparse substitution.
    let base: Vec<u8> = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let base_view = b.view(&base);
    let sparse_index_view = b.view(&[1u8]);
    let sparse_values: Vec<u8> = [5.0f32, 6.0, 7.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let sparse_value_view = b.view(&sparse_values);
    b.accessors.push(json!({
        "bufferView": base_view, "componentType": FLOAT, "count": 3, "type": "VEC3",
        "min": [0.0, 0.0, 0.0], "max": [5.0, 6.0, 7.0],
        "sparse": {
            "count": 1,
            "indices": { "bufferView": sparse_index_view, "componentType": 5121 },
            "values": { "bufferView": sparse_value_view },
        },
    }));
    let sparse_positions = b.accessors.len() - 1;
    let sparse_indices = b.indices_u32(&[0, 1, 2]);
    let line_indices = b.indices_u32(&[0, 1]);

    // Animation keys.
    let step_times = b.floats(&[[0.0], [1.0], [2.0]], "SCALAR");
    let step_values = b.floats(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]], "VEC3");
    let linear_times = b.floats(&[[0.0], [2.5]], "SCALAR");
    let rotations: Vec<u8> = [0i16, 0, 0, 32767, 0, 32767, 0, 0]
        .iter()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    let rotation_values = b.accessor(&rotations, SHORT, 2, "VEC4", json!({ "normalized": true }));
    let cubic_values = b.floats(
        &[
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.5, 0.5, 0.5],
            [0.25, 0.25, 0.25],
            [2.0, 3.0, 4.0],
            [0.0, 0.0, 0.0],
        ],
        "VEC3",
    );

    let image = match storage {
        Storage::Embedded => json!({ "uri": common::png_data_uri(png) }),
        Storage::External => json!({ "uri": PNG_NAME }),
        Storage::Binary => json!({ "bufferView": b.view(png), "mimeType": "image/png" }),
    };
    let buffer = match storage {
        Storage::Embedded => json!({ "byteLength": b.bin.len(), "uri": b.data_uri() }),
        Storage::External => json!({ "byteLength": b.bin.len(), "uri": BIN_URI }),
        Storage::Binary => json!({ "byteLength": b.bin.len() }),
    };

    let json = json!({
        "asset": { "version": "2.0" },
        "extensionsUsed": ["KHR_texture_transform", "KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior"],
        "scene": 0,
        "scenes": [{ "nodes": [0, 4] }],
        "nodes": [
            { "name": "root", "mesh": 0, "children": [1, 2], "translation": [1.0, 2.0, 3.0],
              "rotation": [0.0, 0.70710677, 0.0, 0.70710677], "scale": [2.0, 2.0, 2.0] },
            { "name": "matrix child", "mesh": 1,
              "matrix": [2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 5.0, 1.0] },
            { "name": "instance", "mesh": 0, "children": [3], "translation": [-3.0, 0.0, 0.0] },
            { "name": "camera", "camera": 0, "translation": [0.0, 1.0, 10.0] },
            { "name": "lamp", "children": [5], "extensions": { "KHR_lights_punctual": { "light": 0 } } },
            { "name": "spot", "extensions": { "KHR_lights_punctual": { "light": 1 } } },
            { "name": "orphan", "mesh": 1, "camera": 1 },
        ],
        "meshes": [
            { "name": "quad", "primitives": [
                { "attributes": { "POSITION": quad_positions, "NORMAL": quad_normals,
                                  "TEXCOORD_0": quad_uv0, "TEXCOORD_1": quad_uv1 },
                  "indices": quad_indices, "material": 0 },
                { "attributes": { "POSITION": quad_positions }, "indices": glass_indices, "material": 1 },
            ] },
            { "name": "sparse", "primitives": [
                { "attributes": { "POSITION": sparse_positions }, "indices": sparse_indices },
                { "attributes": { "POSITION": sparse_positions }, "indices": line_indices, "mode": 1 },
            ] },
        ],
        "materials": [
            { "name": "textured", "doubleSided": true,
              "pbrMetallicRoughness": {
                  "baseColorFactor": [0.5, 0.25, 1.0, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.5,
                  "baseColorTexture": { "index": 0, "texCoord": 0, "extensions": { "KHR_texture_transform": {
                      "offset": [0.5, 0.25], "rotation": FRAC_PI_2, "scale": [2.0, 3.0], "texCoord": 1 } } } } },
            { "name": "glass",
              "pbrMetallicRoughness": { "metallicFactor": 0.0, "roughnessFactor": 0.0 },
              "extensions": { "KHR_materials_transmission": { "transmissionFactor": 0.9 },
                              "KHR_materials_ior": { "ior": 1.33 } } },
        ],
        "textures": [{ "sampler": 0, "source": 0 }],
        "samplers": [{ "wrapS": 33071, "wrapT": 33648 }],
        "images": [image],
        "cameras": [
            { "type": "perspective", "perspective": { "yfov": 0.8, "znear": 0.1, "aspectRatio": 1.5 } },
            { "type": "orthographic", "orthographic": { "xmag": 1.0, "ymag": 1.0, "znear": 0.1, "zfar": 10.0 } },
        ],
        "extensions": { "KHR_lights_punctual": { "lights": [
            { "type": "point", "color": [1.0, 0.5, 0.25], "intensity": 40.0, "range": 10.0 },
            { "type": "spot", "intensity": 5.0, "spot": { "innerConeAngle": 0.2, "outerConeAngle": 0.6 } },
        ] } },
        "animations": [{ "name": "move", "channels": [
            { "sampler": 0, "target": { "node": 0, "path": "translation" } },
            { "sampler": 1, "target": { "node": 2, "path": "rotation" } },
            { "sampler": 2, "target": { "node": 2, "path": "scale" } },
        ], "samplers": [
            { "input": step_times, "output": step_values, "interpolation": "STEP" },
            { "input": linear_times, "output": rotation_values, "interpolation": "LINEAR" },
            { "input": linear_times, "output": cubic_values, "interpolation": "CUBICSPLINE" },
        ] }],
        "buffers": [buffer],
        "bufferViews": b.views,
        "accessors": b.accessors,
    });
    (json, b.bin)
}

/// Writes the round-trip scene into `dir` and returns the path of the glTF/GLB file.
fn write_round_trip(dir: &Path, storage: Storage) -> PathBuf {
    let png = common::png(PNG_WIDTH, PNG_HEIGHT);
    let (json, bin) = round_trip_scene(storage, &png);
    match storage {
        Storage::Embedded => write(
            dir,
            "embedded.gltf",
            &serde_json::to_vec_pretty(&json).unwrap(),
        ),
        Storage::External => {
            write(dir, BIN_NAME, &bin);
            write(dir, PNG_NAME, &png);
            write(
                dir,
                "external.gltf",
                &serde_json::to_vec_pretty(&json).unwrap(),
            )
        }
        Storage::Binary => write(dir, "binary.glb", &common::glb(&json, &bin)),
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write test file");
    path
}

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
    let primitive = &scene.meshes[0].primitives[0];
    assert_eq!(
        primitive.positions,
        vec![Vec3::new(0.0, 0.0, 1.0), Vec3::X, Vec3::new(2.0, 1.0, 0.0)]
    );
    // Normal 0: (0, 0, 1) + 0.5 * (2, 0, -1) = (1, 0, 0.5), renormalised.
    let normals = primitive.normals.as_ref().unwrap();
    assert!(normals[0].abs_diff_eq(Vec3::new(1.0, 0.0, 0.5).normalize(), 1e-6));
    assert_eq!(normals[1], Vec3::Z);
    assert!(
        scene.notes.iter().any(|n| n.contains("morph targets")),
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
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/gltf");
    if !root.is_dir() {
        println!("skipping: ../shared/gltf not present");
        return;
    }
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
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/gltf/TextureTransformMultiTest/TextureTransformMultiTest.glb");
    if !file.exists() {
        println!("skipping: ../shared/gltf not present");
        return;
    }
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

/// Paths (object keys and array indices) to every value nested in `value`.
fn value_paths(value: &Value, prefix: &mut Vec<Value>, out: &mut Vec<Vec<Value>>) {
    let children: Vec<(Value, &Value)> = match value {
        Value::Array(items) => items
            .iter()
            .enumerate()
            .map(|(i, v)| (json!(i), v))
            .collect(),
        Value::Object(map) => map.iter().map(|(k, v)| (json!(k), v)).collect(),
        _ => return,
    };
    for (key, child) in children {
        prefix.push(key);
        out.push(prefix.clone());
        value_paths(child, prefix, out);
        prefix.pop();
    }
}

fn at_path<'v>(value: &'v mut Value, path: &[Value]) -> &'v mut Value {
    path.iter().fold(value, |v, key| match key {
        Value::String(k) => &mut v[k.as_str()],
        _ => &mut v[key.as_u64().unwrap() as usize],
    })
}

/// Removes the object member at `path` (array elements are left alone: removing one
/// shifts every index after it, which the number mutations already cover).
fn remove_member(value: &mut Value, path: &[Value]) -> bool {
    let (last, parent) = path.split_last().unwrap();
    match (at_path(value, parent), last) {
        (Value::Object(map), Value::String(key)) => map.remove(key).is_some(),
        _ => false,
    }
}

/// Mutates the round-trip scene's JSON one change at a time: every number (counts,
/// offsets, strides, indices, component types, factors, ...) replaced by hostile values,
/// every object member removed, and every buffer word overwritten. Loading may fail, but must never panic or produce a
/// non-finite number or an out-of-range index.
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

/// The invariants `SceneDesc` promises (see `scene/mod.rs`).
fn assert_valid(scene: &SceneDesc, what: &str) {
    for primitive in scene.meshes.iter().flat_map(|m| &m.primitives) {
        let n = primitive.positions.len();
        assert!(
            primitive.positions.iter().all(|p| p.is_finite()),
            "{what}: positions"
        );
        assert!(
            primitive.normals.iter().flatten().all(|v| v.is_finite()),
            "{what}: normals"
        );
        assert!(
            primitive.uvs.iter().flatten().all(|uv| uv.is_finite()),
            "{what}: uvs"
        );
        assert!(
            primitive.normals.as_ref().is_none_or(|v| v.len() == n),
            "{what}: normal count"
        );
        assert!(
            primitive.uvs.as_ref().is_none_or(|v| v.len() == n),
            "{what}: uv count"
        );
        assert!(primitive.indices.len() % 3 == 0, "{what}: whole triangles");
        assert!(
            primitive.indices.iter().all(|&i| (i as usize) < n),
            "{what}: index range"
        );
        assert!(
            primitive.material.is_none_or(|m| m < scene.materials.len()),
            "{what}: material"
        );
    }
    for node in &scene.nodes {
        let local = &node.local;
        assert!(
            local.translation.is_finite() && local.rotation.is_finite() && local.scale.is_finite(),
            "{what}: node"
        );
        assert!(
            node.children.iter().all(|&c| c < scene.nodes.len()),
            "{what}: children"
        );
        assert!(
            node.mesh.is_none_or(|m| m < scene.meshes.len()),
            "{what}: mesh"
        );
        assert!(
            node.camera.is_none_or(|c| c < scene.cameras.len()),
            "{what}: camera"
        );
        assert!(
            node.light.is_none_or(|l| l < scene.lights.len()),
            "{what}: light"
        );
    }
    assert!(
        scene.roots.iter().all(|&r| r < scene.nodes.len()),
        "{what}: roots"
    );
    for channel in scene.animations.iter().flat_map(|a| &a.channels) {
        assert!(channel.node < scene.nodes.len(), "{what}: channel node");
        assert!(
            channel
                .times
                .iter()
                .chain(&channel.values)
                .all(|v| v.is_finite()),
            "{what}: keys"
        );
        assert!(
            channel.times.windows(2).all(|t| t[0] <= t[1]),
            "{what}: key order"
        );
    }
    for material in &scene.materials {
        assert!(
            material.base_color.is_finite() && material.ior.is_finite(),
            "{what}: material"
        );
        assert!(
            material
                .base_color_texture
                .is_none_or(|t| t < scene.textures.len()),
            "{what}: texture"
        );
    }
    for light in &scene.lights {
        assert!(
            light.color.is_finite() && light.intensity.is_finite(),
            "{what}: light"
        );
    }
}
