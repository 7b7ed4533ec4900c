//! Scenes built in code for the deformation tests (a two-joint skinned strip, a morphed
//! quad), and helpers that pose a scene and collect its world-space vertices.

use glam::{Mat4, Quat, Vec3};
use mipray::anim::{AnimationSelection, Pose, VertexSpace, deform_primitive, primitive_deforms};
use mipray::scene::{
    AnimationDesc, ChannelDesc, ChannelTarget, Interpolation, MeshDesc, MorphTargetDesc, NodeDesc,
    PrimitiveDesc, SceneDesc, SkinDesc, Trs,
};

/// Where the skinned strip's mesh node sits. glTF ignores a skinned node's own transform,
/// so no skinned vertex may pick this offset up.
pub const STRIP_NODE_OFFSET: Vec3 = Vec3::new(10.0, 0.0, 0.0);

/// Node indices of [`skinned_strip_scene`].
pub const STRIP_MESH_NODE: usize = 0;
pub const STRIP_JOINT_0: usize = 1;
pub const STRIP_JOINT_1: usize = 2;

/// Columns of the strip: x of each vertex pair and its (joint 0, joint 1) weights.
pub const STRIP_COLUMNS: [(f32, [f32; 2]); 5] = [
    (0.0, [1.0, 0.0]),
    (0.5, [1.0, 0.0]),
    (1.0, [0.5, 0.5]),
    (1.5, [0.0, 1.0]),
    (2.0, [0.0, 1.0]),
];

/// A strip along +X from x = 0 to 2, y in {-0.5, 0.5}, normals +Z: vertices `2c` (y = -0.5)
/// and `2c + 1` (y = +0.5) for column `c` of [`STRIP_COLUMNS`], plus vertex 10 at (0, 2, 0)
/// with all weights zero (drawn by no triangle). Joint 0 (node 1) sits at the origin, joint 1
/// (node 2, child of joint 0) at (1, 0, 0); the bind pose is the rest pose (inverse bind
/// matrices identity and translate(-1, 0, 0)). The mesh node (node 0) is placed at
/// [`STRIP_NODE_OFFSET`]. Animation 0 ("bend") rotates joint 1 about +Z from 0 at t = 0 to
/// `bend_angle` at t = 1 (LINEAR, i.e. slerp).
pub fn skinned_strip_scene(bend_angle: f32) -> SceneDesc {
    let mut positions = Vec::new();
    let mut joints = Vec::new();
    let mut weights = Vec::new();
    for (x, [w0, w1]) in STRIP_COLUMNS {
        for y in [-0.5, 0.5] {
            positions.push(Vec3::new(x, y, 0.0));
            joints.push([0, 1, 0, 0]);
            weights.push([w0, w1, 0.0, 0.0]);
        }
    }
    positions.push(Vec3::new(0.0, 2.0, 0.0));
    joints.push([1, 0, 0, 0]);
    weights.push([0.0; 4]);
    let mut indices = Vec::new();
    for c in 0..4u32 {
        let (a, b, d, e) = (2 * c, 2 * c + 2, 2 * c + 3, 2 * c + 1);
        indices.extend([a, b, d, a, d, e]);
    }
    let primitive = PrimitiveDesc {
        normals: Some(vec![Vec3::Z; positions.len()]),
        positions,
        indices,
        joints: Some(joints),
        weights: Some(weights),
        ..Default::default()
    };
    let mut scene = SceneDesc::default();
    scene.meshes.push(MeshDesc {
        name: "strip".into(),
        primitives: vec![primitive],
        weights: Vec::new(),
    });
    scene.nodes = vec![
        NodeDesc {
            name: "strip".into(),
            local: translation(STRIP_NODE_OFFSET),
            mesh: Some(0),
            skin: Some(0),
            ..Default::default()
        },
        NodeDesc {
            name: "joint0".into(),
            children: vec![STRIP_JOINT_1],
            ..Default::default()
        },
        NodeDesc {
            name: "joint1".into(),
            local: translation(Vec3::X),
            ..Default::default()
        },
    ];
    scene.roots = vec![STRIP_MESH_NODE, STRIP_JOINT_0];
    scene.skins.push(SkinDesc {
        name: "strip skin".into(),
        joints: vec![STRIP_JOINT_0, STRIP_JOINT_1],
        inverse_bind_matrices: vec![Mat4::IDENTITY, Mat4::from_translation(-Vec3::X)],
        skeleton: Some(STRIP_JOINT_0),
    });
    let end = Quat::from_rotation_z(bend_angle);
    scene.animations.push(AnimationDesc {
        name: "bend".into(),
        channels: vec![ChannelDesc {
            node: STRIP_JOINT_1,
            target: ChannelTarget::Rotation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0],
            values: [Quat::IDENTITY.to_array(), end.to_array()].concat(),
            components: 4,
        }],
    });
    scene
}

pub fn translation(t: Vec3) -> Trs {
    Trs {
        translation: t,
        ..Default::default()
    }
}

/// Base positions of [`morph_quad_scene`]'s quad.
pub const QUAD_BASE: [Vec3; 4] = [
    Vec3::new(0.0, 0.0, 0.0),
    Vec3::new(1.0, 0.0, 0.0),
    Vec3::new(1.0, 1.0, 0.0),
    Vec3::new(0.0, 1.0, 0.0),
];
/// Its one morph target: vertices 2 and 3 move, 0 and 1 stay.
pub const QUAD_DELTA: [Vec3; 4] = [
    Vec3::ZERO,
    Vec3::ZERO,
    Vec3::new(0.0, 1.0, 2.0),
    Vec3::new(-1.0, 0.0, 2.0),
];
/// Its default weight (`MeshDesc::weights`).
pub const QUAD_MESH_WEIGHT: f32 = 0.25;
/// Node 1's weights override.
pub const QUAD_NODE_WEIGHT: f32 = 0.75;

/// A unit quad with one morph target ([`QUAD_DELTA`], normals unchanged), drawn by node 0
/// (mesh weights) at (0, 0, -5) and node 1 (weights override) at (3, 0, 0). Animation 0
/// ("linear") keys node 0's weight LINEAR 0 -> 1 -> 0.25 at t = 0, 1, 2; animation 1 ("cubic")
/// keys it CUBICSPLINE from 0 (out-tangent 2/s) to 1 (in-tangent 0) over t = 0..1.
pub fn morph_quad_scene() -> SceneDesc {
    let primitive = PrimitiveDesc {
        positions: QUAD_BASE.to_vec(),
        normals: Some(vec![Vec3::Z; 4]),
        indices: vec![0, 1, 2, 0, 2, 3],
        morph_targets: vec![MorphTargetDesc {
            positions: Some(QUAD_DELTA.to_vec()),
            normals: None,
        }],
        ..Default::default()
    };
    let mut scene = SceneDesc::default();
    scene.meshes.push(MeshDesc {
        name: "quad".into(),
        primitives: vec![primitive],
        weights: vec![QUAD_MESH_WEIGHT],
    });
    scene.nodes = vec![
        NodeDesc {
            name: "mesh weights".into(),
            local: translation(Vec3::new(0.0, 0.0, -5.0)),
            mesh: Some(0),
            ..Default::default()
        },
        NodeDesc {
            name: "node weights".into(),
            local: translation(Vec3::new(3.0, 0.0, 0.0)),
            mesh: Some(0),
            weights: Some(vec![QUAD_NODE_WEIGHT]),
            ..Default::default()
        },
    ];
    scene.roots = vec![0, 1];
    let weights = |interpolation, times: &[f32], values: &[f32]| ChannelDesc {
        node: 0,
        target: ChannelTarget::Weights,
        interpolation,
        times: times.to_vec(),
        values: values.to_vec(),
        components: 1,
    };
    scene.animations.push(AnimationDesc {
        name: "linear".into(),
        channels: vec![weights(
            Interpolation::Linear,
            &[0.0, 1.0, 2.0],
            &[0.0, 1.0, 0.25],
        )],
    });
    // Per key: in-tangent, value, out-tangent.
    scene.animations.push(AnimationDesc {
        name: "cubic".into(),
        channels: vec![weights(
            Interpolation::CubicSpline,
            &[0.0, 1.0],
            &[0.0, 0.0, 2.0, 0.0, 1.0, 0.0],
        )],
    });
    scene
}

/// Reusable buffers for posing a scene and collecting its world-space vertices.
#[derive(Default)]
pub struct Posed {
    pub pose: Pose,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// World-space positions of every drawn primitive, traversal order.
    pub world: Vec<Vec3>,
    /// World-space unit normals of the primitives that have normals (deformed ones only).
    pub world_normals: Vec<Vec3>,
}

impl Posed {
    /// Poses the scene and fills `world` (and `world_normals` for deformed primitives).
    pub fn evaluate(&mut self, scene: &SceneDesc, selection: AnimationSelection, time_s: f32) {
        self.pose.evaluate(scene, selection, time_s);
        self.world.clear();
        self.world_normals.clear();
        for node in scene.traversal_order() {
            let Some(mesh) = scene.nodes[node].mesh else {
                continue;
            };
            let world_from_node = self.pose.world_from_node[node];
            for (p, primitive) in scene.meshes[mesh].primitives.iter().enumerate() {
                if !primitive_deforms(scene, node, mesh, p) {
                    self.world.extend(
                        primitive
                            .positions
                            .iter()
                            .map(|&v| world_from_node.transform_point3(v)),
                    );
                    continue;
                }
                let space = deform_primitive(
                    scene,
                    &self.pose,
                    node,
                    mesh,
                    p,
                    &mut self.positions,
                    &mut self.normals,
                );
                match space {
                    VertexSpace::World => {
                        self.world.extend_from_slice(&self.positions);
                        self.world_normals.extend_from_slice(&self.normals);
                    }
                    VertexSpace::Object => {
                        let normal_from_object =
                            glam::Mat3::from_mat4(world_from_node).inverse().transpose();
                        self.world.extend(
                            self.positions
                                .iter()
                                .map(|&v| world_from_node.transform_point3(v)),
                        );
                        self.world_normals.extend(
                            self.normals
                                .iter()
                                .map(|&n| (normal_from_object * n).normalize()),
                        );
                    }
                }
            }
        }
    }

    /// Axis-aligned bounds of `world`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        bounds(&self.world)
    }
}

/// Axis-aligned bounds of points (infinite when empty).
pub fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(min, max), &p| (min.min(p), max.max(p)),
    )
}

/// A glTF file exercising everything the loader reads for deformation: a quad (node 0)
/// skinned by two joints (nodes 1 and 2, inverse bind matrices identity and
/// translate(-1, 0, 0), skeleton node 1) with `JOINTS_0` (unsigned byte) / `WEIGHTS_0`
/// (normalized unsigned byte) and a second set `JOINTS_1` (unsigned short) / `WEIGHTS_1`
/// (float) that only vertex 3 uses; one morph target with POSITION and NORMAL deltas, mesh
/// weights [0.25], node 0 weights [0.5]; node 3 draws the same mesh without a skin. The
/// animation keys node 0's weight CUBICSPLINE and node 2's rotation LINEAR.
pub fn skinned_morph_gltf() -> (serde_json::Value, super::BufferBuilder) {
    use super::{BufferBuilder, UNSIGNED_BYTE, UNSIGNED_SHORT};
    use serde_json::json;
    let mut b = BufferBuilder::default();
    let positions = b.positions(&QUAD_BASE.map(|v| v.to_array()));
    let normals = b.floats(&[[0.0, 0.0, 1.0]; 4], "VEC3");
    let indices = b.indices_u16(&[0, 1, 2, 0, 2, 3]);
    let joints0 = b.accessor(
        &SKINNED_JOINTS_0.concat(),
        UNSIGNED_BYTE,
        4,
        "VEC4",
        json!({}),
    );
    let weights0 = b.accessor(
        &SKINNED_WEIGHTS_0.concat(),
        UNSIGNED_BYTE,
        4,
        "VEC4",
        json!({ "normalized": true }),
    );
    let joints1_bytes: Vec<u8> = SKINNED_JOINTS_1
        .iter()
        .flatten()
        .flat_map(|j| j.to_le_bytes())
        .collect();
    let joints1 = b.accessor(&joints1_bytes, UNSIGNED_SHORT, 4, "VEC4", json!({}));
    let weights1 = b.floats(&SKINNED_WEIGHTS_1, "VEC4");
    let position_deltas = b.floats(&QUAD_DELTA.map(|v| v.to_array()), "VEC3");
    let normal_deltas = b.floats(
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]],
        "VEC3",
    );
    let ibm = b.floats(
        &[
            Mat4::IDENTITY.to_cols_array(),
            Mat4::from_translation(-Vec3::X).to_cols_array(),
        ],
        "MAT4",
    );
    let times = b.floats(&[[0.0], [1.0]], "SCALAR");
    // CUBICSPLINE: (in-tangent, value, out-tangent) per key.
    let weight_keys = b.floats(&[[0.0], [0.0], [2.0], [0.0], [1.0], [0.0]], "SCALAR");
    let rotation_keys = b.floats(
        &[
            Quat::IDENTITY.to_array(),
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_2).to_array(),
        ],
        "VEC4",
    );
    let json = json!({
        "asset": { "version": "2.0" },
        "scene": 0,
        "scenes": [{ "nodes": [0, 1, 3] }],
        "nodes": [
            { "name": "skinned", "mesh": 0, "skin": 0, "weights": [0.5], "translation": [5.0, 0.0, 0.0] },
            { "name": "root joint", "children": [2] },
            { "name": "tip joint", "translation": [1.0, 0.0, 0.0] },
            { "name": "unskinned", "mesh": 0, "translation": [0.0, 0.0, -3.0] },
        ],
        "meshes": [{ "name": "quad", "weights": [0.25], "primitives": [{
            "attributes": {
                "POSITION": positions, "NORMAL": normals,
                "JOINTS_0": joints0, "WEIGHTS_0": weights0,
                "JOINTS_1": joints1, "WEIGHTS_1": weights1,
            },
            "indices": indices,
            "targets": [{ "POSITION": position_deltas, "NORMAL": normal_deltas }],
        }] }],
        "skins": [{ "name": "arm", "joints": [1, 2], "inverseBindMatrices": ibm, "skeleton": 1 }],
        "animations": [{
            "name": "wave",
            "samplers": [
                { "input": times, "output": weight_keys, "interpolation": "CUBICSPLINE" },
                { "input": times, "output": rotation_keys, "interpolation": "LINEAR" },
            ],
            "channels": [
                { "sampler": 0, "target": { "node": 0, "path": "weights" } },
                { "sampler": 1, "target": { "node": 2, "path": "rotation" } },
            ],
        }],
    });
    (json, b)
}

/// `JOINTS_0` of [`skinned_morph_gltf`].
pub const SKINNED_JOINTS_0: [[u8; 4]; 4] = [[0, 0, 0, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]];
/// `WEIGHTS_0` (normalized: divide by 255).
pub const SKINNED_WEIGHTS_0: [[u8; 4]; 4] = [
    [255, 0, 0, 0],
    [128, 127, 0, 0],
    [255, 0, 0, 0],
    [102, 77, 0, 0],
];
/// `JOINTS_1`.
pub const SKINNED_JOINTS_1: [[u16; 4]; 4] = [[0; 4], [0; 4], [0; 4], [1, 0, 1, 0]];
/// `WEIGHTS_1`: only vertex 3 has a second set of influences.
pub const SKINNED_WEIGHTS_1: [[f32; 4]; 4] = [[0.0; 4], [0.0; 4], [0.0; 4], [0.1, 0.1, 0.1, 0.0]];

/// The invariants the loader promises for deformation data (see `scene/mod.rs`), and that
/// posing and deforming every drawn primitive gives finite vertices and unit normals.
pub fn assert_deformable(scene: &SceneDesc, what: &str) {
    for (m, mesh) in scene.meshes.iter().enumerate() {
        assert!(
            mesh.weights.iter().all(|w| w.is_finite()),
            "{what}: mesh {m} weights"
        );
        for primitive in &mesh.primitives {
            let n = primitive.positions.len();
            assert_eq!(
                primitive.joints.is_some(),
                primitive.weights.is_some(),
                "{what}"
            );
            assert!(
                primitive.joints.as_ref().is_none_or(|j| j.len() == n),
                "{what}"
            );
            assert!(
                primitive
                    .weights
                    .iter()
                    .flatten()
                    .flatten()
                    .all(|w| w.is_finite() && *w >= 0.0),
                "{what}: skin weights"
            );
            assert_eq!(
                primitive.morph_targets.len(),
                mesh.weights.len(),
                "{what}: targets"
            );
            for target in &primitive.morph_targets {
                for deltas in [&target.positions, &target.normals].into_iter().flatten() {
                    assert_eq!(deltas.len(), n, "{what}: delta count");
                    assert!(deltas.iter().all(|d| d.is_finite()), "{what}: deltas");
                }
                assert!(
                    target.normals.is_none() || primitive.normals.is_some(),
                    "{what}"
                );
            }
        }
    }
    for skin in &scene.skins {
        assert_eq!(
            skin.joints.len(),
            skin.inverse_bind_matrices.len(),
            "{what}"
        );
        assert!(
            skin.joints.iter().all(|&j| j < scene.nodes.len()),
            "{what}: joint node"
        );
        assert!(
            skin.inverse_bind_matrices.iter().all(|m| m.is_finite()),
            "{what}: IBM"
        );
    }
    for node in &scene.nodes {
        let targets = node.mesh.map_or(0, |m| scene.meshes[m].weights.len());
        assert!(
            node.weights.as_ref().is_none_or(|w| w.len() == targets),
            "{what}: node weights"
        );
        let (Some(skin), Some(mesh)) = (node.skin, node.mesh) else {
            continue;
        };
        let joint_count = scene.skins[skin].joints.len();
        for joints in scene.meshes[mesh]
            .primitives
            .iter()
            .filter_map(|p| p.joints.as_ref())
        {
            assert!(
                joints
                    .iter()
                    .flatten()
                    .all(|&j| usize::from(j) < joint_count),
                "{what}: joint index"
            );
        }
    }
    // Deformed vertices as `deform_primitive` returns them (before any placement by the
    // caller): finite positions, unit normals.
    let (mut pose, mut positions, mut normals) = (Pose::default(), Vec::new(), Vec::new());
    for t in [0.0, 0.3, 1.0, 100.0] {
        pose.evaluate(scene, AnimationSelection::All, t);
        for node in scene.traversal_order() {
            let Some(mesh) = scene.nodes[node].mesh else {
                continue;
            };
            for p in 0..scene.meshes[mesh].primitives.len() {
                deform_primitive(scene, &pose, node, mesh, p, &mut positions, &mut normals);
                assert!(
                    positions.iter().all(|p| p.is_finite()),
                    "{what}: t = {t}: positions"
                );
                assert!(
                    normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4),
                    "{what}: t = {t}: normals"
                );
            }
        }
    }
}
