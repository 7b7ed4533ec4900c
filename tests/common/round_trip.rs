//! The round-trip scene: one glTF scene exercising every feature the loader supports,
//! written as embedded JSON, as JSON with an external `.bin` and PNG, or as a GLB.

use std::f32::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use super::{BufferBuilder, FLOAT, SHORT, UNSIGNED_SHORT};

/// Size of the base-colour PNG the round-trip scene uses.
pub const PNG_WIDTH: u32 = 4;
pub const PNG_HEIGHT: u32 = 2;

/// Where the round-trip scene's buffer and image live.
#[derive(Clone, Copy)]
pub enum Storage {
    /// Buffer and image as base64 data URIs inside the JSON.
    Embedded,
    /// `scene data.bin` (percent-encoded URI) and `tex.png` next to the `.gltf`.
    External,
    /// A `.glb`: buffer in the BIN chunk, image in a buffer view.
    Binary,
}

pub const BIN_NAME: &str = "scene data.bin";
pub const BIN_URI: &str = "scene%20data.bin";
pub const PNG_NAME: &str = "tex.png";

/// The round-trip scene: two meshes (u8/u16/u32 indices, a sparse POSITION accessor, a line
/// primitive to skip), a TRS/matrix hierarchy with an instanced mesh and an orphan node,
/// a perspective and an orthographic camera, a point and a spot light, a textured material
/// with `KHR_texture_transform` and a CLAMP/MIRRORED sampler, a glass material, and an
/// animation with STEP, LINEAR and CUBICSPLINE channels. Returns the JSON and the buffer.
pub fn round_trip_scene(storage: Storage, png: &[u8]) -> (Value, Vec<u8>) {
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
        Storage::Embedded => json!({ "uri": super::png_data_uri(png) }),
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
        "samplers": [{ "wrapS": 33071, "wrapT": 33648, "minFilter": 9985 }],
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
pub fn write_round_trip(dir: &Path, storage: Storage) -> PathBuf {
    let png = super::png(PNG_WIDTH, PNG_HEIGHT);
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
        Storage::Binary => write(dir, "binary.glb", &super::glb(&json, &bin)),
    }
}

pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write test file");
    path
}
