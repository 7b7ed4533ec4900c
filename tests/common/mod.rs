//! Test helpers that write glTF files: a binary-buffer builder for accessors, a GLB
//! container writer and a tiny PNG encoder, so tests need no asset files.

#![allow(dead_code)]

pub mod deform_scenes;
pub mod farm;
pub mod files;
pub mod invariants;
pub mod round_trip;
pub mod scenes;
pub mod shared_data;

use std::io::Cursor;

use base64::Engine as _;
use serde_json::{Value, json};

pub const UNSIGNED_BYTE: u32 = 5121;
pub const SHORT: u32 = 5122;
pub const UNSIGNED_SHORT: u32 = 5123;
pub const UNSIGNED_INT: u32 = 5125;
pub const FLOAT: u32 = 5126;

/// Accumulates one binary buffer plus the buffer views and accessors that describe it.
#[derive(Default)]
pub struct BufferBuilder {
    pub bin: Vec<u8>,
    pub views: Vec<Value>,
    pub accessors: Vec<Value>,
}

impl BufferBuilder {
    /// Appends `bytes` (4-byte aligned) as a new buffer view of buffer 0; returns its index.
    pub fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views
            .push(json!({ "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len() }));
        self.bin.extend_from_slice(bytes);
        self.views.len() - 1
    }

    /// Adds an accessor over a new view holding `bytes`; `extra` is merged into its JSON.
    pub fn accessor(
        &mut self,
        bytes: &[u8],
        component_type: u32,
        count: usize,
        kind: &str,
        extra: Value,
    ) -> usize {
        let view = self.view(bytes);
        let mut accessor = json!({ "bufferView": view, "componentType": component_type, "count": count, "type": kind });
        merge(&mut accessor, extra);
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// FLOAT accessor of `N`-component elements (`kind` is SCALAR/VEC2/VEC3/VEC4).
    pub fn floats<const N: usize>(&mut self, data: &[[f32; N]], kind: &str) -> usize {
        let bytes: Vec<u8> = data
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        self.accessor(&bytes, FLOAT, data.len(), kind, json!({}))
    }

    /// POSITION accessor (with the min/max glTF requires).
    pub fn positions(&mut self, data: &[[f32; 3]]) -> usize {
        let bytes: Vec<u8> = data
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let (min, max) = bounds(data);
        self.accessor(
            &bytes,
            FLOAT,
            data.len(),
            "VEC3",
            json!({ "min": min, "max": max }),
        )
    }

    pub fn indices_u8(&mut self, data: &[u8]) -> usize {
        self.accessor(data, UNSIGNED_BYTE, data.len(), "SCALAR", json!({}))
    }

    pub fn indices_u16(&mut self, data: &[u16]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, UNSIGNED_SHORT, data.len(), "SCALAR", json!({}))
    }

    pub fn indices_u32(&mut self, data: &[u32]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, UNSIGNED_INT, data.len(), "SCALAR", json!({}))
    }

    /// The buffer as a base64 data URI.
    pub fn data_uri(&self) -> String {
        format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        )
    }
}

/// Per-component min and max of positions (glTF requires them on POSITION).
fn bounds(data: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut min = [f32::MAX; 3];
    let mut max = [f32::MIN; 3];
    for p in data {
        for k in 0..3 {
            if p[k].is_finite() {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
    }
    (min, max)
}

/// Shallow-merges the keys of object `extra` into object `target`.
pub fn merge(target: &mut Value, extra: Value) {
    if let (Some(target), Value::Object(extra)) = (target.as_object_mut(), extra) {
        target.extend(extra);
    }
}

/// A GLB container: 12-byte header, JSON chunk (space padded), BIN chunk (zero padded).
pub fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json_bytes = serde_json::to_vec(json).expect("serialize JSON");
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// A `width` x `height` RGBA PNG with a simple gradient.
pub fn png(width: u32, height: u32) -> Vec<u8> {
    let image = image::RgbaImage::from_fn(width, height, |x, y| {
        image::Rgba([(x * 60) as u8, (y * 120) as u8, 200, 255])
    });
    let mut bytes = Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, image::ImageFormat::Png)
        .expect("encode PNG");
    bytes.into_inner()
}

/// A base64 data URI of a PNG.
pub fn png_data_uri(png: &[u8]) -> String {
    format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(png)
    )
}

/// Smallest valid glTF: one triangle from `positions`/`indices` in an embedded buffer.
/// Tests corrupt it to check one error at a time.
pub fn single_triangle(positions: &[[f32; 3]], indices: &[u16]) -> (Value, BufferBuilder) {
    let mut buffers = BufferBuilder::default();
    let position = buffers.positions(positions);
    let index = buffers.indices_u16(indices);
    let json = json!({
        "asset": { "version": "2.0" },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": position }, "indices": index }] }],
    });
    (json, buffers)
}

/// Completes `json` with `buffers` as buffer 0 embedded as a data URI.
pub fn with_embedded_buffer(mut json: Value, buffers: &BufferBuilder) -> Value {
    merge(
        &mut json,
        json!({
            "buffers": [{ "byteLength": buffers.bin.len(), "uri": buffers.data_uri() }],
            "bufferViews": buffers.views,
            "accessors": buffers.accessors,
        }),
    );
    json
}

/// Runs the `mipray` binary with `args` in `cwd` and returns its output.
pub fn mipray(args: &[&str], cwd: &std::path::Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run mipray")
}
