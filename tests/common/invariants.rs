//! Checks that hold for every scene the loader accepts, and JSON paths to mutate files
//! one value at a time.

use mipray::scene::SceneDesc;
use serde_json::{Value, json};

/// Paths (object keys and array indices) to every value nested in `value`.
pub fn value_paths(value: &Value, prefix: &mut Vec<Value>, out: &mut Vec<Vec<Value>>) {
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

pub fn at_path<'v>(value: &'v mut Value, path: &[Value]) -> &'v mut Value {
    path.iter().fold(value, |v, key| match key {
        Value::String(k) => &mut v[k.as_str()],
        _ => &mut v[key.as_u64().unwrap() as usize],
    })
}

/// Removes the object member at `path` (array elements are left alone: removing one
/// shifts every index after it, which the number mutations already cover).
pub fn remove_member(value: &mut Value, path: &[Value]) -> bool {
    let (last, parent) = path.split_last().unwrap();
    match (at_path(value, parent), last) {
        (Value::Object(map), Value::String(key)) => map.remove(key).is_some(),
        _ => false,
    }
}

/// The invariants `SceneDesc` promises (see `scene/mod.rs`).
pub fn assert_valid(scene: &SceneDesc, what: &str) {
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
