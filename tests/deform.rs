//! Skinning and morph targets end to end: scenes built in code with hand-computed poses, the
//! loader on a file that exercises every deformation attribute (and corrupted copies of
//! it), animation selection, and the shared Khronos sample models posed over their whole
//! animations against poses checked by hand or by an independent numpy implementation.

mod common;

use std::f32::consts::{FRAC_PI_2, FRAC_PI_4};
use std::path::{Path, PathBuf};

use glam::{Mat4, Quat, Vec3};
use mipray::anim::{
    AnimationSelection, Pose, VertexSpace, deform_primitive, primitive_deforms, select_animation,
};
use mipray::scene::gltf::load;
use mipray::scene::{ChannelDesc, ChannelTarget, Interpolation, SceneDesc};
use serde_json::{Value, json};

use common::deform_scenes::{
    Posed, QUAD_BASE, QUAD_DELTA, QUAD_MESH_WEIGHT, QUAD_NODE_WEIGHT, SKINNED_JOINTS_0,
    SKINNED_WEIGHTS_0, STRIP_COLUMNS, STRIP_JOINT_1, STRIP_MESH_NODE, STRIP_NODE_OFFSET,
    assert_deformable, bounds, morph_quad_scene, skinned_morph_gltf, skinned_strip_scene,
};
use common::invariants::{at_path, remove_member, value_paths};

fn assert_close(actual: Vec3, expected: Vec3, tolerance: f32, what: &str) {
    assert!(
        actual.abs_diff_eq(expected, tolerance),
        "{what}: {actual} != {expected} (tolerance {tolerance})"
    );
}

fn assert_bounds(actual: (Vec3, Vec3), expected: (Vec3, Vec3), tolerance: f32, what: &str) {
    assert_close(actual.0, expected.0, tolerance, &format!("{what}: min"));
    assert_close(actual.1, expected.1, tolerance, &format!("{what}: max"));
}

/// The deformed vertices of one primitive drawn by `node` (mesh 0, primitive 0 unless the
/// node draws another mesh).
fn deformed(scene: &SceneDesc, pose: &Pose, node: usize) -> (Vec<Vec3>, Vec<Vec3>, VertexSpace) {
    let mesh = scene.nodes[node].mesh.unwrap();
    let (mut positions, mut normals) = (Vec::new(), Vec::new());
    let space = deform_primitive(scene, pose, node, mesh, 0, &mut positions, &mut normals);
    (positions, normals, space)
}

fn pose_at(scene: &SceneDesc, selection: AnimationSelection, t: f32) -> Pose {
    let mut pose = Pose::default();
    pose.evaluate(scene, selection, t);
    pose
}

// ---------------------------------------------------------------------------------------
// Skinning, scene built in code
// ---------------------------------------------------------------------------------------

/// Where joint 1 alone puts a bind-pose point when rotated by `angle` about +Z: about its
/// origin (1, 0, 0).
fn about_joint_1(p: Vec3, angle: f32) -> Vec3 {
    Vec3::X + Quat::from_rotation_z(angle) * (p - Vec3::X)
}

#[test]
fn skinned_strip_rest_pose_is_the_bind_pose() {
    let scene = skinned_strip_scene(FRAC_PI_2);
    assert!(primitive_deforms(&scene, STRIP_MESH_NODE, 0, 0));
    let pose = pose_at(&scene, AnimationSelection::All, 0.0);
    let (positions, normals, space) = deformed(&scene, &pose, STRIP_MESH_NODE);
    assert_eq!(space, VertexSpace::World);
    let base = &scene.meshes[0].primitives[0].positions;
    // Joint matrices are identity at rest, and the mesh node's own offset is ignored.
    for (v, (p, b)) in positions.iter().zip(base).enumerate().take(10) {
        assert_close(*p, *b, 1e-6, &format!("vertex {v}"));
    }
    // Vertex 10 has all-zero weights: it stays rigidly attached to its node.
    assert_close(
        positions[10],
        STRIP_NODE_OFFSET + base[10],
        1e-6,
        "zero weights",
    );
    assert!(normals.iter().all(|n| n.abs_diff_eq(Vec3::Z, 1e-6)));
}

#[test]
fn bending_joint_1_moves_exactly_its_vertices() {
    let scene = skinned_strip_scene(FRAC_PI_2);
    // t = 1: joint 1 rotated by 90 degrees about +Z, so a point it carries goes from (x, y)
    // to (1 - y, x - 1): the joint-0 columns stay, the joint-1 columns fold up.
    let pose = pose_at(&scene, AnimationSelection::All, 1.0);
    let (positions, normals, _) = deformed(&scene, &pose, STRIP_MESH_NODE);
    let expected = [
        // x = 0 and 0.5: joint 0 only, unmoved.
        Vec3::new(0.0, -0.5, 0.0),
        Vec3::new(0.0, 0.5, 0.0),
        Vec3::new(0.5, -0.5, 0.0),
        Vec3::new(0.5, 0.5, 0.0),
        // x = 1, weights 0.5 / 0.5: average of (1, y) and (1 - y, 0).
        Vec3::new(1.25, -0.25, 0.0),
        Vec3::new(0.75, 0.25, 0.0),
        // x = 1.5 and 2: joint 1 only.
        Vec3::new(1.5, 0.5, 0.0),
        Vec3::new(0.5, 0.5, 0.0),
        Vec3::new(1.5, 1.0, 0.0),
        Vec3::new(0.5, 1.0, 0.0),
        // Zero weights: rigid with the node.
        STRIP_NODE_OFFSET + Vec3::new(0.0, 2.0, 0.0),
    ];
    for (v, (p, e)) in positions.iter().zip(expected).enumerate() {
        assert_close(*p, e, 1e-5, &format!("vertex {v}"));
    }
    // A rotation about Z keeps the +Z normals.
    assert!(normals.iter().all(|n| n.abs_diff_eq(Vec3::Z, 1e-6)));

    // Halfway (t = 0.5, slerp): 45 degrees.
    let pose = pose_at(&scene, AnimationSelection::All, 0.5);
    let (positions, _, _) = deformed(&scene, &pose, STRIP_MESH_NODE);
    let base = &scene.meshes[0].primitives[0].positions;
    for v in 6..10 {
        assert_close(
            positions[v],
            about_joint_1(base[v], FRAC_PI_4),
            1e-5,
            &format!("vertex {v}"),
        );
    }
}

#[test]
fn half_and_half_vertex_lands_at_the_average_of_its_joints() {
    let angle = 1.0; // radians, arbitrary
    let scene = skinned_strip_scene(angle);
    let pose = pose_at(&scene, AnimationSelection::All, 1.0);
    let (positions, _, _) = deformed(&scene, &pose, STRIP_MESH_NODE);
    let base = &scene.meshes[0].primitives[0].positions;
    assert_eq!(STRIP_COLUMNS[2].1, [0.5, 0.5]);
    for v in [4, 5] {
        let by_joint_0 = base[v];
        let by_joint_1 = about_joint_1(base[v], angle);
        assert_close(
            positions[v],
            (by_joint_0 + by_joint_1) / 2.0,
            1e-5,
            &format!("vertex {v}"),
        );
    }
}

#[test]
fn skinned_normals_follow_the_inverse_transpose() {
    // Joint 1 scaled by (sx, 1, 1), then turned 90 degrees about +Z, about its origin
    // (1, 0, 0): on the joint-1 columns M3 = R90 diag(sx, 1, 1), not symmetric, so a normal
    // matrix transposed the wrong way shows. Normals there are tilted to (1, 1, 0) / sqrt 2.
    // Positions: (x, y) -> (1, 0) + R90 (sx (x - 1), y) = (1 - y, sx (x - 1)).
    // Normals: M3^-T n = R90 diag(1 / sx, 1, 1) n ~ R90 (1 / sx, 1, 0) = (-1, 1 / sx, 0).
    // sx = -2 mirrors (det < 0): the normal must still be M3^-T n, not its negation.
    for sx in [2.0, -2.0] {
        let mut scene = skinned_strip_scene(FRAC_PI_2);
        scene.nodes[STRIP_JOINT_1].local.scale = Vec3::new(sx, 1.0, 1.0);
        let tilted = Vec3::new(1.0, 1.0, 0.0).normalize();
        scene.meshes[0].primitives[0].normals.as_mut().unwrap()[6..10].fill(tilted);
        let pose = pose_at(&scene, AnimationSelection::All, 1.0);
        let (positions, normals, _) = deformed(&scene, &pose, STRIP_MESH_NODE);
        let base = &scene.meshes[0].primitives[0].positions;
        for v in 6..10 {
            let b = base[v];
            let what = format!("sx = {sx}, vertex {v}");
            assert_close(
                positions[v],
                Vec3::new(1.0 - b.y, sx * (b.x - 1.0), b.z),
                1e-5,
                &what,
            );
            let expected = Vec3::new(-1.0, 1.0 / sx, 0.0).normalize();
            assert_close(normals[v], expected, 1e-5, &what);
        }
    }
}

#[test]
fn overflowing_joint_is_reported_and_its_vertices_fall_back_to_the_node() {
    // Joint 1's scale times its inverse bind matrix's overflows f32: joint matrix 1 is
    // infinite. Vertices it influences fall back to the rigid placement (node offset);
    // joint-0-only vertices are skinned as usual.
    let mut scene = skinned_strip_scene(0.0);
    scene.nodes[STRIP_JOINT_1].local.scale = Vec3::splat(1e30);
    scene.skins[0].inverse_bind_matrices[1] = Mat4::from_scale(Vec3::splat(1e30));
    let pose = pose_at(&scene, AnimationSelection::All, 0.0);
    assert_eq!(pose.nonfinite_joint(), Some((0, 1)));
    let (positions, normals, _) = deformed(&scene, &pose, STRIP_MESH_NODE);
    let base = &scene.meshes[0].primitives[0].positions;
    assert!(positions.iter().chain(&normals).all(|v| v.is_finite()));
    for v in 0..4 {
        assert_close(positions[v], base[v], 1e-6, "joint 0 only");
    }
    for v in 4..11 {
        assert_close(positions[v], STRIP_NODE_OFFSET + base[v], 1e-6, "fallback");
    }
}

#[test]
fn deformation_is_bit_identical_across_calls_and_reused_poses() {
    let scene = skinned_strip_scene(1.234);
    let fresh = pose_at(&scene, AnimationSelection::All, 0.37);
    let first = deformed(&scene, &fresh, STRIP_MESH_NODE);
    let mut reused = pose_at(&scene, AnimationSelection::All, 0.9);
    reused.evaluate(&scene, AnimationSelection::All, 0.37);
    let second = deformed(&scene, &reused, STRIP_MESH_NODE);
    let bits = |v: &[Vec3]| -> Vec<[u32; 3]> {
        v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
    };
    assert_eq!(bits(&first.0), bits(&second.0));
    assert_eq!(bits(&first.1), bits(&second.1));
}

// ---------------------------------------------------------------------------------------
// Morph targets, scene built in code
// ---------------------------------------------------------------------------------------

fn expected_quad(weight: f32) -> Vec<Vec3> {
    QUAD_BASE
        .iter()
        .zip(QUAD_DELTA)
        .map(|(b, d)| *b + weight * d)
        .collect()
}

fn assert_quad_weight(scene: &SceneDesc, pose: &Pose, node: usize, weight: f32, what: &str) {
    assert_eq!(pose.morph_weights[node].len(), 1, "{what}");
    assert!(
        (pose.morph_weights[node][0] - weight).abs() < 1e-6,
        "{what}: weight {} != {weight}",
        pose.morph_weights[node][0]
    );
    let (positions, normals, space) = deformed(scene, pose, node);
    assert_eq!(space, VertexSpace::Object, "{what}");
    for (v, (p, e)) in positions.iter().zip(expected_quad(weight)).enumerate() {
        assert_close(*p, e, 1e-6, &format!("{what}: vertex {v}"));
    }
    assert_eq!(normals, vec![Vec3::Z; 4], "{what}: no normal deltas");
}

#[test]
fn linear_morph_weights_give_base_plus_weight_times_delta() {
    let scene = morph_quad_scene();
    assert!(primitive_deforms(&scene, 0, 0, 0));
    // Keys 0 -> 1 -> 0.25 at t = 0, 1, 2; clamped after.
    for (t, w) in [
        (0.0, 0.0),
        (0.5, 0.5),
        (1.0, 1.0),
        (1.5, 0.625),
        (2.0, 0.25),
        (3.0, 0.25),
    ] {
        let pose = pose_at(&scene, AnimationSelection::One(0), t);
        assert_quad_weight(&scene, &pose, 0, w, &format!("linear t = {t}"));
    }
}

#[test]
fn cubic_spline_morph_weights_give_base_plus_weight_times_delta() {
    let scene = morph_quad_scene();
    // Hermite from 0 (out-tangent 2/s) to 1 (in-tangent 0) over one second:
    // w(s) = 2 h10(s) + h01(s), h10 = s^3 - 2 s^2 + s, h01 = -2 s^3 + 3 s^2.
    // s = 0.25: 2 * 0.140625 + 0.15625 = 0.4375; s = 0.5: 2 * 0.125 + 0.5 = 0.75.
    for (t, w) in [
        (0.0, 0.0),
        (0.25, 0.4375),
        (0.5, 0.75),
        (1.0, 1.0),
        (2.0, 1.0),
    ] {
        let pose = pose_at(&scene, AnimationSelection::One(1), t);
        assert_quad_weight(&scene, &pose, 0, w, &format!("cubic t = {t}"));
    }
    // All clips together: the later clip ("cubic") wins on the shared target.
    let pose = pose_at(&scene, AnimationSelection::All, 0.5);
    assert_quad_weight(&scene, &pose, 0, 0.75, "all clips");
}

#[test]
fn node_weights_override_mesh_weights_and_animated_weights_override_both() {
    let mut scene = morph_quad_scene();
    let animations = std::mem::take(&mut scene.animations);
    let pose = pose_at(&scene, AnimationSelection::All, 0.5);
    assert_quad_weight(&scene, &pose, 0, QUAD_MESH_WEIGHT, "mesh weights");
    assert_quad_weight(&scene, &pose, 1, QUAD_NODE_WEIGHT, "node weights");
    // Node 0 animated: the channel wins over the mesh weights, node 1 keeps its own.
    scene.animations = animations;
    let pose = pose_at(&scene, AnimationSelection::One(0), 0.5);
    assert_quad_weight(&scene, &pose, 0, 0.5, "animated over mesh");
    assert_quad_weight(&scene, &pose, 1, QUAD_NODE_WEIGHT, "node weights kept");
    // Node 1 animated: the channel wins over the node weights.
    scene.animations[0].channels.push(ChannelDesc {
        node: 1,
        target: ChannelTarget::Weights,
        interpolation: Interpolation::Step,
        times: vec![0.0],
        values: vec![-2.0],
        components: 1,
    });
    let pose = pose_at(&scene, AnimationSelection::One(0), 0.5);
    assert_quad_weight(&scene, &pose, 1, -2.0, "animated over node");
}

// ---------------------------------------------------------------------------------------
// Animation selection
// ---------------------------------------------------------------------------------------

#[test]
fn animation_selection_by_name_and_index() {
    let scene = morph_quad_scene();
    assert_eq!(
        select_animation(&scene, "linear"),
        Ok(AnimationSelection::One(0))
    );
    assert_eq!(
        select_animation(&scene, "cubic"),
        Ok(AnimationSelection::One(1))
    );
    assert_eq!(
        select_animation(&scene, "0"),
        Ok(AnimationSelection::One(0))
    );
    assert_eq!(
        select_animation(&scene, "1"),
        Ok(AnimationSelection::One(1))
    );
    assert_eq!(AnimationSelection::One(0).duration(&scene), 2.0);
    assert_eq!(AnimationSelection::One(1).duration(&scene), 1.0);
    assert_eq!(AnimationSelection::All.duration(&scene), 2.0);
    for unknown in ["walk", "2", "-1", "", "Linear"] {
        let e = select_animation(&scene, unknown).unwrap_err();
        assert!(
            e.contains("0 \"linear\" (2 s), 1 \"cubic\" (1 s)"),
            "{unknown:?}: {e}"
        );
    }
    // One clip plays alone: the strip is not bent by the quad's clips and vice versa.
    let strip = skinned_strip_scene(FRAC_PI_2);
    let pose = pose_at(&strip, AnimationSelection::One(5), 1.0);
    assert_eq!(
        pose.joint_matrices[0][1],
        Mat4::IDENTITY,
        "no such clip: rest"
    );
}

// ---------------------------------------------------------------------------------------
// Loader: deformation attributes
// ---------------------------------------------------------------------------------------

/// Writes `json` (with its buffer embedded) as `skinned_morph.gltf` in `dir`.
fn write_gltf(dir: &Path, json: &Value) -> PathBuf {
    let path = dir.join("skinned_morph.gltf");
    std::fs::write(&path, serde_json::to_vec(json).unwrap()).unwrap();
    path
}

#[test]
fn loader_reads_skins_influences_and_morph_targets() {
    let dir = tempfile::tempdir().unwrap();
    let (json, b) = skinned_morph_gltf();
    let json = common::with_embedded_buffer(json, &b);
    let scene = load(&write_gltf(dir.path(), &json)).unwrap_or_else(|e| panic!("{e}"));
    assert_deformable(&scene, "skinned_morph.gltf");

    assert_eq!(scene.skins.len(), 1);
    let skin = &scene.skins[0];
    assert_eq!(skin.name, "arm");
    assert_eq!(skin.joints, vec![1, 2]);
    assert_eq!(skin.skeleton, Some(1));
    assert_eq!(
        skin.inverse_bind_matrices,
        vec![Mat4::IDENTITY, Mat4::from_translation(-Vec3::X)]
    );
    assert_eq!(scene.nodes[0].skin, Some(0));
    assert_eq!(scene.nodes[3].skin, None);
    assert_eq!(scene.nodes[0].weights, Some(vec![0.5]));
    assert_eq!(scene.nodes[3].weights, None);

    let mesh = &scene.meshes[0];
    assert_eq!(mesh.weights, vec![0.25]);
    let primitive = &mesh.primitives[0];
    assert_eq!(primitive.positions, QUAD_BASE.to_vec(), "base, not morphed");
    assert_eq!(
        primitive.morph_targets[0].positions.as_deref(),
        Some(&QUAD_DELTA[..])
    );
    assert_eq!(
        primitive.morph_targets[0].normals.as_deref(),
        Some(&[Vec3::ZERO, Vec3::X, Vec3::ZERO, Vec3::ZERO][..])
    );

    // Vertices 0-2: the second set has zero weights, so set 0 comes through (u8 / 255).
    let joints = primitive.joints.as_ref().unwrap();
    let weights = primitive.weights.as_ref().unwrap();
    for v in 0..3 {
        assert_eq!(joints[v], SKINNED_JOINTS_0[v].map(u16::from), "vertex {v}");
        assert_eq!(
            weights[v],
            SKINNED_WEIGHTS_0[v].map(|w| f32::from(w) / 255.0),
            "vertex {v}"
        );
    }
    // Vertex 3 has 5 non-zero influences: (j0, 102/255), (j1, 77/255) from set 0 and
    // (j1, 0.1), (j0, 0.1), (j1, 0.1) from set 1. Kept: the two of set 0, then the first two
    // 0.1s in file order; rescaled by total / kept.
    assert_eq!(joints[3], [0, 1, 1, 0]);
    let (a, c) = (102.0 / 255.0, 77.0 / 255.0);
    let scale = (a + c + 0.3) / (a + c + 0.2);
    let expected = [a * scale, c * scale, 0.1 * scale, 0.1 * scale];
    for (w, e) in weights[3].iter().zip(expected) {
        assert!((w - e).abs() < 1e-6, "{:?} vs {expected:?}", weights[3]);
    }

    // Weights channel: CUBICSPLINE with one component per key value.
    let channel = &scene.animations[0].channels[0];
    assert_eq!(channel.target, ChannelTarget::Weights);
    assert_eq!(channel.interpolation, Interpolation::CubicSpline);
    assert_eq!(channel.components, 1);
    assert_eq!(channel.values, vec![0.0, 0.0, 2.0, 0.0, 1.0, 0.0]);

    // Notes: the folded influences and the mesh drawn without its skin; nothing about
    // rest poses any more.
    let notes = scene.notes.join("\n");
    assert!(notes.contains("more than 4 joint influences"), "{notes}");
    assert!(
        notes.contains("1 node(s) draw a mesh with JOINTS/WEIGHTS but have no skin"),
        "{notes}"
    );
    assert!(!notes.contains("rest pose"), "{notes}");
    assert!(primitive_deforms(&scene, 0, 0, 0), "skinned and morphed");
    assert!(primitive_deforms(&scene, 3, 0, 0), "morphed, not skinned");

    // Posed at t = 1: weight 1 on node 0 (animated), joint 1 rotated 90 degrees about +Z.
    // Vertex 2 (1, 1, 0) is carried by joint 1 alone: morphed to (1, 2, 2), then rotated
    // about (1, 0, 0): (1, 0, 0) + R90 (0, 2, 2) = (1 - 2, 0, 2). The node's translation (5, 0, 0)
    // is ignored (skinned). Node 3 (no skin) uses the mesh weight 0.25, in object space.
    let pose = pose_at(&scene, AnimationSelection::All, 1.0);
    let (positions, _, space) = deformed(&scene, &pose, 0);
    assert_eq!(space, VertexSpace::World);
    assert_close(
        positions[2],
        Vec3::new(-1.0, 0.0, 2.0),
        1e-5,
        "skinned vertex 2",
    );
    let (positions, _, space) = deformed(&scene, &pose, 3);
    assert_eq!(space, VertexSpace::Object);
    assert_close(
        positions[2],
        QUAD_BASE[2] + 0.25 * QUAD_DELTA[2],
        1e-6,
        "unskinned",
    );
}

/// A corruption of the file: what it is, the change, and what the error must mention.
type Corruption = (
    &'static str,
    Box<dyn Fn(&mut Value)>,
    &'static [&'static str],
);

/// Each corruption of the deformation data is an error naming the element.
#[test]
fn loader_rejects_inconsistent_deformation_data() {
    let dir = tempfile::tempdir().unwrap();
    let (json, b) = skinned_morph_gltf();
    let cases: Vec<Corruption> = vec![
        (
            "skin with one joint",
            Box::new(|j| j["skins"][0]["joints"] = json!([1])),
            &["node 0", "mesh 0", "1 joints", "joint index 1"],
        ),
        (
            "mesh weights of the wrong length",
            Box::new(|j| j["meshes"][0]["weights"] = json!([0.25, 0.5])),
            &["mesh 0", "2 morph weights", "1 morph targets"],
        ),
        (
            "node weights of the wrong length",
            Box::new(|j| j["nodes"][0]["weights"] = json!([])),
            &["node 0", "0 morph weights"],
        ),
        (
            "JOINTS_0 without WEIGHTS_0",
            Box::new(|j| {
                let attributes = &mut j["meshes"][0]["primitives"][0]["attributes"];
                assert!(
                    attributes
                        .as_object_mut()
                        .unwrap()
                        .remove("WEIGHTS_0")
                        .is_some()
                );
            }),
            &["JOINTS_0 but no WEIGHTS_0"],
        ),
        (
            "float joints",
            Box::new(|j| {
                // Point JOINTS_0 at the FLOAT VEC4 accessor of WEIGHTS_1.
                let attributes = &mut j["meshes"][0]["primitives"][0]["attributes"];
                attributes["JOINTS_0"] = attributes["WEIGHTS_1"].clone();
            }),
            &["JOINTS_0", "joints must be unsigned byte or short"],
        ),
        (
            "too few inverse bind matrices",
            Box::new(|j| {
                let ibm = j["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize;
                j["accessors"][ibm]["count"] = json!(1);
            }),
            &["inverseBindMatrices of skin 0", "1 matrices", "2 joints"],
        ),
        (
            "morph target with the wrong count",
            Box::new(|j| {
                let target = &j["meshes"][0]["primitives"][0]["targets"][0]["POSITION"];
                let accessor = target.as_u64().unwrap() as usize;
                j["accessors"][accessor]["count"] = json!(3);
            }),
            &[
                "POSITION of mesh 0 primitive 0 morph target 0",
                "3 elements",
            ],
        ),
        (
            "primitives with different target counts",
            Box::new(|j| {
                let mut second = j["meshes"][0]["primitives"][0].clone();
                second["targets"] = json!([]);
                j["meshes"][0]["primitives"]
                    .as_array_mut()
                    .unwrap()
                    .push(second);
            }),
            &[
                "mesh 0 primitive 1 has 0 morph targets",
                "primitive 0 has 1",
            ],
        ),
    ];
    let embedded = common::with_embedded_buffer(json.clone(), &b);
    for (what, corrupt, needles) in cases {
        let mut corrupted = embedded.clone();
        corrupt(&mut corrupted);
        let path = write_gltf(dir.path(), &corrupted);
        let error = load(&path).map(|_| ()).expect_err(what).to_string();
        assert!(error.contains("skinned_morph.gltf"), "{what}: {error}");
        for needle in needles {
            assert!(error.contains(needle), "{what}: {error:?} lacks {needle:?}");
        }
    }
    // Buffer data: a NaN inverse bind matrix, a negative weight.
    let ibm_view = {
        let ibm = json["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize;
        b.accessors[ibm]["bufferView"].as_u64().unwrap() as usize
    };
    let weights1_view = {
        let w = json["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_1"]
            .as_u64()
            .unwrap() as usize;
        b.accessors[w]["bufferView"].as_u64().unwrap() as usize
    };
    for (view, word, value, needles) in [
        (
            ibm_view,
            5,
            f32::NAN,
            &["inverseBindMatrices of skin 0", "non-finite"][..],
        ),
        (weights1_view, 12, -0.5, &["WEIGHTS_1", "non-negative"][..]),
    ] {
        let mut corrupted = common::BufferBuilder {
            bin: b.bin.clone(),
            views: b.views.clone(),
            accessors: b.accessors.clone(),
        };
        let at = b.views[view]["byteOffset"].as_u64().unwrap() as usize + 4 * word;
        corrupted.bin[at..at + 4].copy_from_slice(&value.to_le_bytes());
        let corrupted = common::with_embedded_buffer(json.clone(), &corrupted);
        let error = load(&write_gltf(dir.path(), &corrupted))
            .map(|_| ())
            .expect_err("corrupted buffer")
            .to_string();
        for needle in needles {
            assert!(error.contains(needle), "{error:?} lacks {needle:?}");
        }
    }
}

/// Values glTF forbids but files contain load with a note saying what mipray does instead:
/// a vertex whose joint weights sum to zero (it follows its node unskinned) and a rotation
/// key of zero length (the identity where the frame's rotation cannot be normalised). The
/// valid file gets neither note.
#[test]
fn zero_weights_and_zero_rotation_keys_load_with_notes() {
    let dir = tempfile::tempdir().unwrap();
    let (json, b) = skinned_morph_gltf();
    let notes_of = |bin: Vec<u8>| {
        let corrupted = common::BufferBuilder {
            bin,
            views: b.views.clone(),
            accessors: b.accessors.clone(),
        };
        let scene = load(&write_gltf(
            dir.path(),
            &common::with_embedded_buffer(json.clone(), &corrupted),
        ))
        .unwrap_or_else(|e| panic!("{e}"));
        assert_deformable(&scene, "degenerate values");
        let pose = pose_at(&scene, AnimationSelection::All, 0.0);
        let (positions, _, _) = deformed(&scene, &pose, 0);
        assert!(positions.iter().all(|p| p.is_finite()), "{positions:?}");
        scene.notes.join("\n")
    };
    let start_of = |accessor: &Value| {
        let view = b.accessors[accessor.as_u64().unwrap() as usize]["bufferView"]
            .as_u64()
            .unwrap() as usize;
        b.views[view]["byteOffset"].as_u64().unwrap() as usize
    };
    let clean = notes_of(b.bin.clone());
    assert!(
        !clean.contains("summing to zero") && !clean.contains("zero length"),
        "{clean}"
    );
    // Vertex 0: its WEIGHTS_0 (unsigned bytes) zeroed; its WEIGHTS_1 are zero already.
    let mut bin = b.bin.clone();
    let weights0 = start_of(&json["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"]);
    bin[weights0..weights0 + 4].fill(0);
    // The rotation channel's first key (sampler 1's output, float VEC4) zeroed.
    let keys = start_of(&json["animations"][0]["samplers"][1]["output"]);
    bin[keys..keys + 16].fill(0);
    let notes = notes_of(bin);
    assert!(
        notes.contains("1 skinned vertex(es) have joint weights summing to zero"),
        "{notes}"
    );
    assert!(
        notes.contains("animation 0 channel 1: 1 rotation key(s) have zero length"),
        "{notes}"
    );
}

/// Every number of the file replaced by hostile values and every member removed: loading
/// may fail but never panics, and a loaded scene keeps the deformation invariants (and
/// deforms to finite vertices).
#[test]
fn corrupted_deformation_files_never_panic_or_deform_to_non_finite_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let (json, b) = skinned_morph_gltf();
    let json = common::with_embedded_buffer(json, &b);
    let mut paths = Vec::new();
    value_paths(&json, &mut Vec::new(), &mut paths);
    // The data URI is not a number; leave the buffer to the other tests.
    let hostile = [
        json!(0),
        json!(1),
        json!(2),
        json!(-1),
        json!(65535),
        json!(1e30),
        json!(0.5),
    ];
    let file = dir.path().join("mutated.gltf");
    let (mut loaded, mut rejected) = (0, 0);
    let mut check = |mutated: &Value, what: &str| {
        std::fs::write(&file, serde_json::to_vec(mutated).unwrap()).unwrap();
        match std::panic::catch_unwind(|| load(&file)) {
            Err(_) => panic!("panic with {what}"),
            Ok(Ok(scene)) => {
                assert_deformable(&scene, what);
                loaded += 1;
            }
            Ok(Err(_)) => rejected += 1,
        }
    };
    for path in &paths {
        let mut removed = json.clone();
        if remove_member(&mut removed, path) {
            check(&removed, &format!("{path:?} removed"));
        }
        if at_path(&mut json.clone(), path).is_number() {
            for value in &hostile {
                let mut mutated = json.clone();
                *at_path(&mut mutated, path) = value.clone();
                check(&mutated, &format!("{path:?} = {value}"));
            }
        }
    }
    assert!(
        loaded > 50 && rejected > 50,
        "loaded {loaded}, rejected {rejected}"
    );
}

// ---------------------------------------------------------------------------------------
// Shared sample models
// ---------------------------------------------------------------------------------------

fn shared_gltf() -> Option<PathBuf> {
    common::shared_data::shared_path("gltf")
}

fn load_model(root: &Path, name: &str) -> SceneDesc {
    let dir = root.join(name);
    let file = ["glb", "gltf"]
        .iter()
        .map(|ext| dir.join(format!("{name}.{ext}")))
        .find(|f| f.is_file())
        .unwrap_or_else(|| panic!("{name}: no {name}.glb or {name}.gltf"));
    load(&file).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The selections a model is played with: each clip alone, plus all together.
fn selections(scene: &SceneDesc) -> Vec<AnimationSelection> {
    let mut s: Vec<_> = (0..scene.animations.len())
        .map(AnimationSelection::One)
        .collect();
    s.push(AnimationSelection::All);
    s
}

/// Frame times at 30 fps covering the selection's duration, end included.
fn frame_times(scene: &SceneDesc, selection: AnimationSelection) -> Vec<f32> {
    let frames = (selection.duration(scene) * 30.0).ceil() as u32;
    (0..=frames).map(|i| i as f32 / 30.0).collect()
}

const DEFORMING_MODELS: [&str; 9] = [
    "SimpleSkin",
    "RiggedSimple",
    "RiggedFigure",
    "CesiumMan",
    "Fox",
    "AnimatedMorphCube",
    "AnimatedMorphSphere",
    "SimpleMorph",
    "InterpolationTest",
];

#[test]
fn shared_models_animate_with_finite_vertices_in_every_frame() {
    let Some(root) = shared_gltf() else { return };
    let mut posed = Posed::default();
    for name in DEFORMING_MODELS {
        let scene = load_model(&root, name);
        assert_deformable(&scene, name);
        assert!(!scene.animations.is_empty(), "{name} is animated");
        assert!(
            !scene.notes.iter().any(|n| n.contains("rest pose")),
            "{name}: {:?}",
            scene.notes
        );
        let vertex_count: usize = scene
            .traversal_order()
            .into_iter()
            .filter_map(|n| scene.nodes[n].mesh)
            .flat_map(|m| &scene.meshes[m].primitives)
            .map(|p| p.positions.len())
            .sum();
        for selection in selections(&scene) {
            let mut moved = false;
            let mut first: Option<Vec<Vec3>> = None;
            for t in frame_times(&scene, selection) {
                posed.evaluate(&scene, selection, t);
                let what = format!("{name} {selection:?} t = {t}");
                assert_eq!(posed.world.len(), vertex_count, "{what}");
                assert!(
                    posed.world.iter().all(|p| p.is_finite()),
                    "{what}: positions"
                );
                assert!(
                    posed
                        .world_normals
                        .iter()
                        .all(|n| (n.length() - 1.0).abs() < 1e-4),
                    "{what}: normals"
                );
                let first = first.get_or_insert_with(|| posed.world.clone());
                moved |= *first != posed.world;
            }
            // Every clip of these models moves some vertex.
            assert!(moved, "{name} {selection:?}: no vertex ever moves");
        }
    }
}

/// Skinned models posed with no animation (every node at its rest TRS) sit at their bind
/// pose: each skinned vertex equals its base position placed by the skinned node's world
/// transform (numpy: equal to 1e-5 of the size for SimpleSkin, RiggedFigure, CesiumMan and
/// Fox). RiggedSimple's inverse bind matrices bind its cylinder a quarter turn about the
/// cylinder's axis from where the mesh node puts it (numpy: vertices differ by up to
/// sqrt 2 = a quarter turn of the unit radius), so there only the bounds agree.
#[test]
fn skinned_models_rest_pose_is_the_bind_pose() {
    let Some(root) = shared_gltf() else { return };
    let mut posed = Posed::default();
    for name in [
        "SimpleSkin",
        "RiggedSimple",
        "RiggedFigure",
        "CesiumMan",
        "Fox",
    ] {
        let mut scene = load_model(&root, name);
        scene.animations.clear();
        posed.evaluate(&scene, AnimationSelection::All, 0.0);
        let mut rigid = Vec::new();
        for node in scene.traversal_order() {
            let Some(mesh) = scene.nodes[node].mesh else {
                continue;
            };
            assert!(scene.nodes[node].skin.is_some(), "{name}");
            let world_from_node = posed.pose.world_from_node[node];
            for primitive in &scene.meshes[mesh].primitives {
                rigid.extend(
                    primitive
                        .positions
                        .iter()
                        .map(|&p| world_from_node.transform_point3(p)),
                );
            }
        }
        let (min, max) = bounds(&rigid);
        let tolerance = 1e-5 * (max - min).max_element();
        if name == "RiggedSimple" {
            assert_bounds(posed.bounds(), (min, max), tolerance, name);
            continue;
        }
        for (v, (skinned, rigid)) in posed.world.iter().zip(&rigid).enumerate() {
            assert_close(*skinned, *rigid, tolerance, &format!("{name} vertex {v}"));
        }
    }
}

/// SimpleSkin (a 1 x 2 strip, 10 vertices, joint 0 = node 1 at the origin, joint 1 = node 2
/// at (0, 1, 0); inverse bind matrices identity and translate(0, -1, 0); weights per row
/// y = 0, 0.5, 1, 1.5, 2: joint 0 1 / 0.75 / 0.5 / 0.25 / 0, joint 1 the rest; all read
/// from the .bin files with a hex dump). Joint 1's rotation keys (LINEAR) are, every 0.5 s
/// from 0: 0, 45, 90, 90, 45, 0, 0, -45, -90, -90, -45, 0 degrees about +Z (quaternions
/// (0, 0, +-0.707, 0.707) normalised: exactly 90 degrees).
/// Joint 1 rotated by a about (0, 1): p -> (0, 1) + R(a) (p - (0, 1)).
/// - t = 0: the bind pose, bounds [-0.5, 0, 0]..[0.5, 2, 0] (the POSITION min/max).
/// - t = 1 (+90: (x, y) -> (1 - y, 1 + x)): the y = 2 row (joint 1 only) goes to
///   (-1, 0.5) and (-1, 1.5); the y = 1.5 row (0.25 / 0.75) to (-0.5, 0.75) and
///   (-0.25, 1.5); y = 1 (0.5 / 0.5) to (-0.25, 0.75) and (0.25, 1.25); y = 0.5
///   (0.75 / 0.25) to (-0.25, 0.5) and (0.5, 0.75); y = 0 stays. Bounds
///   [-1, 0, 0]..[0.5, 1.5, 0].
/// - t = 4 (-90: (x, y) -> (y - 1, 1 - x)): the mirror image, bounds [-0.5, 0, 0]..[1, 1.5, 0].
/// - t = 0.75 (slerp halfway between the 45 and 90 degree keys): bounds from the numpy
///   implementation (which normalises both keys before the slerp, as glTF requires:
///   the stored 0.383 / 0.924 key is 45.03 degrees), [-1.1152017, 0, 0]..[0.5383037,
///   1.8444428, 0].
#[test]
fn simple_skin_matches_hand_computed_poses() {
    let Some(root) = shared_gltf() else { return };
    let scene = load_model(&root, "SimpleSkin");
    let mut posed = Posed::default();
    posed.evaluate(&scene, AnimationSelection::All, 0.0);
    assert_bounds(
        posed.bounds(),
        (Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 2.0, 0.0)),
        1e-6,
        "t = 0",
    );
    posed.evaluate(&scene, AnimationSelection::All, 1.0);
    let expected = [
        (-0.5, 0.0),
        (0.5, 0.0),
        (-0.25, 0.5),
        (0.5, 0.75),
        (-0.25, 0.75),
        (0.25, 1.25),
        (-0.5, 0.75),
        (-0.25, 1.5),
        (-1.0, 0.5),
        (-1.0, 1.5),
    ];
    for (v, (p, (x, y))) in posed.world.iter().zip(expected).enumerate() {
        assert_close(*p, Vec3::new(x, y, 0.0), 1e-5, &format!("t = 1 vertex {v}"));
    }
    assert_bounds(
        posed.bounds(),
        (Vec3::new(-1.0, 0.0, 0.0), Vec3::new(0.5, 1.5, 0.0)),
        1e-5,
        "t = 1",
    );
    posed.evaluate(&scene, AnimationSelection::All, 4.0);
    assert_bounds(
        posed.bounds(),
        (Vec3::new(-0.5, 0.0, 0.0), Vec3::new(1.0, 1.5, 0.0)),
        1e-5,
        "t = 4",
    );
    posed.evaluate(&scene, AnimationSelection::All, 0.75);
    assert_bounds(
        posed.bounds(),
        (
            Vec3::new(-1.1152017, 0.0, 0.0),
            Vec3::new(0.5383037, 1.8444428, 0.0),
        ),
        1e-5,
        "t = 0.75",
    );
}

/// SimpleMorph: one triangle (0, 0), (1, 0), (0.5, 0.5); target 0 moves vertex 2 by (-1, 1),
/// target 1 by (1, 1); mesh weights (0.5, 0.5); weight keys (LINEAR) at t = 0..4:
/// (0, 0), (0, 1), (1, 1), (1, 0), (0, 0) (read from simpleMorphGeometry.bin and
/// simpleMorphAnimation.bin). So vertex 2 = (0.5, 0.5) + w0 (-1, 1) + w1 (1, 1).
#[test]
fn simple_morph_equals_base_plus_weights_times_targets() {
    let Some(root) = shared_gltf() else { return };
    let mut scene = load_model(&root, "SimpleMorph");
    assert_eq!(scene.meshes[0].weights, vec![0.5, 0.5]);
    let mut posed = Posed::default();
    for (t, vertex_2) in [
        (0.0, Vec3::new(0.5, 0.5, 0.0)),
        (0.5, Vec3::new(1.0, 1.0, 0.0)),
        (1.0, Vec3::new(1.5, 1.5, 0.0)),
        (2.0, Vec3::new(0.5, 2.5, 0.0)),
        (3.0, Vec3::new(-0.5, 1.5, 0.0)),
        (4.0, Vec3::new(0.5, 0.5, 0.0)),
    ] {
        posed.evaluate(&scene, AnimationSelection::All, t);
        assert_close(posed.world[0], Vec3::ZERO, 1e-6, "vertex 0");
        assert_close(posed.world[1], Vec3::X, 1e-6, "vertex 1");
        assert_close(posed.world[2], vertex_2, 1e-6, &format!("t = {t}"));
    }
    // No animation: the mesh's default weights (0.5, 0.5) give (0.5, 1.5).
    scene.animations.clear();
    posed.evaluate(&scene, AnimationSelection::All, 0.0);
    assert_close(
        posed.world[2],
        Vec3::new(0.5, 1.5, 0.0),
        1e-6,
        "default weights",
    );
}

/// AnimatedMorphCube: a cube of half-size 0.01 (POSITION min/max), node scale 100 and
/// rotation (0, 0.7071, -0.7071, 0), a half turn about (0, 1, -1) / sqrt 2 that maps object
/// (x, y, z) to world (-x, -z, -y): the base cube is [-1, 1]^3 in world space.
/// - t = 0: weights (0, 0) (first key): bounds are the base cube.
/// - t = 1.6 (key at 1.5999998): weights (0.99999994, 0). Target 0 ("thin") moves the 12
///   vertices with y = -0.01 by +0.01893253 in y (its accessor max; the others by 0): object
///   y range [0.00893253, 0.01], world z = -100 y in [-1, -0.893253].
///   (Key values and deltas read with numpy from the GLB's accessors.)
#[test]
fn animated_morph_cube_bounds_match_its_weights() {
    let Some(root) = shared_gltf() else { return };
    let scene = load_model(&root, "AnimatedMorphCube");
    let mut posed = Posed::default();
    posed.evaluate(&scene, AnimationSelection::All, 0.0);
    assert_bounds(
        posed.bounds(),
        (Vec3::splat(-1.0), Vec3::splat(1.0)),
        1e-4,
        "t = 0",
    );
    posed.evaluate(&scene, AnimationSelection::All, 1.6);
    assert_bounds(
        posed.bounds(),
        (Vec3::splat(-1.0), Vec3::new(1.0, 1.0, -0.893253)),
        1e-4,
        "t = 1.6",
    );
}

/// A pose checked against numpy: model, selection, time, bounds min and max.
type Reference = (&'static str, AnimationSelection, f32, [f32; 3], [f32; 3]);

/// CesiumMan and Fox: the body stays in a sane box around its rest pose and keeps its
/// height (within 10% of the rest pose in every frame, 25% for the leaping fox) while the
/// bounds change; at chosen times the bounds match an independent numpy
/// implementation of the glTF rules (TRS/matrix hierarchy, LINEAR lerp and slerp sampling,
/// world_from_joint * inverse bind, weighted sum over JOINTS_0/WEIGHTS_0), to 1e-4 of the
/// model's size.
#[test]
fn walking_figures_keep_their_height_and_match_reference_poses() {
    let Some(root) = shared_gltf() else { return };
    let references: [Reference; 5] = [
        (
            "CesiumMan",
            AnimationSelection::All,
            0.5,
            [-0.2546667, 0.0174847, -0.4057231],
            [0.1899066, 1.501989, 0.3717686],
        ),
        (
            "CesiumMan",
            AnimationSelection::All,
            1.0,
            [-0.2021819, -0.0014262, -0.5075166],
            [0.1668429, 1.457235, 0.4623297],
        ),
        (
            "Fox",
            AnimationSelection::One(0),
            1.0,
            [-11.59716, -0.1308652, -83.31096],
            [22.20523, 76.69425, 63.70193],
        ),
        (
            "Fox",
            AnimationSelection::One(1),
            0.375,
            [-12.81479, 1.350163, -91.50563],
            [12.37045, 73.90589, 70.07819],
        ),
        (
            "Fox",
            AnimationSelection::One(2),
            0.5,
            [-13.14519, -1.251693, -95.98852],
            [14.06211, 73.81708, 68.20671],
        ),
    ];
    let mut posed = Posed::default();
    for name in ["CesiumMan", "Fox"] {
        let mut scene = load_model(&root, name);
        let animations = std::mem::take(&mut scene.animations);
        posed.evaluate(&scene, AnimationSelection::All, 0.0);
        let rest = posed.bounds();
        let rest_height = rest.1.y - rest.0.y;
        let size = (rest.1 - rest.0).max_element();
        scene.animations = animations;
        for (_, selection, t, min, max) in references.iter().filter(|r| r.0 == name) {
            posed.evaluate(&scene, *selection, *t);
            assert_bounds(
                posed.bounds(),
                (Vec3::from(*min), Vec3::from(*max)),
                1e-4 * size,
                &format!("{name} {selection:?} t = {t}"),
            );
        }
        for selection in selections(&scene) {
            if name == "Fox" && selection == AnimationSelection::All {
                continue; // three clips overriding each other: not a pose to judge
            }
            // Within 10% of the rest height, except the fox's run: it leaps with all feet
            // off the ground, down to 79.6% of its rest height at t = 0.4 (62.912 of
            // 79.029, lowest point 6.44 above the ground; the numpy implementation agrees
            // frame by frame), so it gets 25%.
            let allowed = if name == "Fox" && selection == AnimationSelection::One(2) {
                0.25
            } else {
                0.1
            };
            // The sane box: the rest bounds grown by half the model's size (CesiumMan's
            // T-pose is 0.31 deep; a stride reaches 0.38 in front of it).
            let sane = (rest.0 - 0.5 * size, rest.1 + 0.5 * size);
            let mut largest_change: f32 = 0.0;
            let mut first = None;
            for t in frame_times(&scene, selection) {
                posed.evaluate(&scene, selection, t);
                let b = posed.bounds();
                let height = b.1.y - b.0.y;
                assert!(
                    (height - rest_height).abs() <= allowed * rest_height,
                    "{name} {selection:?} t = {t}: height {height}, rest {rest_height}"
                );
                assert!(
                    b.0.cmpge(sane.0).all() && b.1.cmple(sane.1).all(),
                    "{name} {selection:?} t = {t}: bounds {b:?} outside {sane:?}"
                );
                let f = *first.get_or_insert(b);
                largest_change = largest_change
                    .max((b.0 - f.0).abs().max_element())
                    .max((b.1 - f.1).abs().max_element());
            }
            assert!(
                largest_change > 0.03 * rest_height,
                "{name} {selection:?}: bounds change by only {largest_change}"
            );
        }
    }
}

/// RiggedSimple and RiggedFigure at a time between keys, against the same numpy
/// implementation (RiggedSimple: a cylinder bent by 2 joints under matrix nodes;
/// RiggedFigure: 19 joints, two keys per channel, t = 0.625 halfway).
#[test]
fn rigged_models_match_reference_poses() {
    let Some(root) = shared_gltf() else { return };
    let mut posed = Posed::default();
    for (name, t, min, max) in [
        (
            "RiggedSimple",
            1.0,
            [-1.0, -4.575077, -1.0],
            [2.866495, 4.10051, 0.9999996],
        ),
        (
            "RiggedFigure",
            0.625,
            [-0.4566427, -0.0000001, -0.1227416],
            [0.4473928, 1.467088, 0.2174513],
        ),
    ] {
        let scene = load_model(&root, name);
        posed.evaluate(&scene, AnimationSelection::All, t);
        let size = (Vec3::from(max) - Vec3::from(min)).max_element();
        assert_bounds(
            posed.bounds(),
            (Vec3::from(min), Vec3::from(max)),
            1e-4 * size,
            &format!("{name} t = {t}"),
        );
    }
}

#[test]
fn interpolation_test_clips_are_selected_by_name() {
    let Some(root) = shared_gltf() else { return };
    let scene = load_model(&root, "InterpolationTest");
    for (i, name) in [
        "Step Scale",
        "Linear Scale",
        "CubicSpline Scale",
        "Step Rotation",
        "CubicSpline Rotation",
        "Linear Rotation",
        "Step Translation",
        "CubicSpline Translation",
        "Linear Translation",
    ]
    .into_iter()
    .enumerate()
    {
        assert_eq!(
            select_animation(&scene, name),
            Ok(AnimationSelection::One(i))
        );
    }
    let e = select_animation(&scene, "Cubic Scale").unwrap_err();
    assert!(e.contains("2 \"CubicSpline Scale\""), "{e}");
}
