//! Generated dynamic scenes shared by the frame-loop bench (`benches/frame_loop.rs`) and its
//! end-to-end test (`tests/frame_loop.rs`, which includes this file by path): textured
//! patches on a grid, a skinned grid bent by a joint chain, and patches moving rigidly.
//! Everything is built in code, so the bench and the test need no files.

#![allow(dead_code)] // each includer uses its own subset

use glam::{Mat4, Quat, Vec2, Vec3, Vec4};
use mipray::scene::*;
use mipray::texture::{MipPyramid, Sampler, Texture};

/// A flat patch of `nx x ny` quads (2 nx ny triangles) in the XY plane, `width x height`
/// centred on the origin, texture repeated four times per unit, normals +Z.
pub fn patch(nx: u32, ny: u32, width: f32, height: f32) -> PrimitiveDesc {
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    for y in 0..=ny {
        for x in 0..=nx {
            let (u, v) = (x as f32 / nx as f32, y as f32 / ny as f32);
            positions.push(Vec3::new((u - 0.5) * width, (v - 0.5) * height, 0.0));
            uvs.push(Vec2::new(u * 4.0 * width, v * 4.0 * height));
        }
    }
    let mut indices = Vec::new();
    for y in 0..ny {
        for x in 0..nx {
            let i = y * (nx + 1) + x;
            indices.extend([i, i + 1, i + nx + 2, i, i + nx + 2, i + nx + 1]);
        }
    }
    PrimitiveDesc {
        normals: Some(vec![Vec3::Z; positions.len()]),
        positions,
        uvs: Some(uvs),
        indices,
        material: Some(0),
        ..Default::default()
    }
}

/// An empty scene with a 64x64 checker texture as material 0, a grey background and one
/// (empty) animation that the builders below add channels to.
pub fn textured_scene() -> SceneDesc {
    let texels = (0..64 * 64)
        .map(|i| {
            if (i % 64 / 8 + i / 64 / 8) % 2 == 0 {
                Vec4::ONE
            } else {
                Vec4::new(0.1, 0.2, 0.6, 1.0)
            }
        })
        .collect();
    SceneDesc {
        textures: vec![Texture {
            name: "checker".into(),
            pyramid: MipPyramid::from_linear_rgba(64, 64, texels).unwrap(),
            sampler: Sampler::default(),
        }],
        materials: vec![MaterialDesc {
            base_color: Vec3::ONE,
            base_color_texture: Some(0),
            ..Default::default()
        }],
        animations: vec![AnimationDesc {
            name: "generated".into(),
            channels: Vec::new(),
        }],
        background: Vec3::splat(0.2),
        ..Default::default()
    }
}

/// Adds a root node with `mesh` at `translation`; returns its index.
fn add_root(scene: &mut SceneDesc, node: NodeDesc) -> usize {
    scene.nodes.push(node);
    scene.roots.push(scene.nodes.len() - 1);
    scene.nodes.len() - 1
}

/// A LINEAR rotation channel on `node` about `axis` through `angles` (radians) at times
/// 0, 1, 2, ... seconds.
fn rotation_channel(node: usize, axis: Vec3, angles: &[f32]) -> ChannelDesc {
    ChannelDesc {
        node,
        target: ChannelTarget::Rotation,
        interpolation: Interpolation::Linear,
        times: (0..angles.len()).map(|k| k as f32).collect(),
        values: angles
            .iter()
            .flat_map(|&a| Quat::from_axis_angle(axis, a).to_array())
            .collect(),
        components: 4,
    }
}

/// Adds a skinned grid of `nx x ny` quads (`width x height`, its left edge at `origin`)
/// bound to a chain of `joints` joints along +X. Each vertex blends the two joints whose
/// segment it lies in; the root joint turns about +Z and every other joint about +Y over
/// time, so every vertex moves on every frame.
pub fn add_skinned_grid(
    scene: &mut SceneDesc,
    nx: u32,
    ny: u32,
    (width, height): (f32, f32),
    joints: usize,
    origin: Vec3,
) {
    let mut primitive = patch(nx, ny, width, height);
    let segment = width / joints as f32;
    let (mut joint_of, mut weight_of) = (Vec::new(), Vec::new());
    for p in &mut primitive.positions {
        let x = p.x + width * 0.5; // 0..width along the chain
        *p += origin + Vec3::X * width * 0.5; // bind space = world space at rest
        let along = (x / segment).min(joints as f32 - 1.0);
        let k = (along.floor() as usize).min(joints - 1);
        let next = (k + 1).min(joints - 1);
        let w = along - k as f32;
        joint_of.push([k as u16, next as u16, 0, 0]);
        weight_of.push([1.0 - w, w, 0.0, 0.0]);
    }
    primitive.joints = Some(joint_of);
    primitive.weights = Some(weight_of);
    scene.meshes.push(MeshDesc {
        name: "skinned grid".into(),
        primitives: vec![primitive],
        weights: Vec::new(),
    });
    let mesh = scene.meshes.len() - 1;
    let skin = scene.skins.len();
    add_root(
        scene,
        NodeDesc {
            name: "skinned grid".into(),
            mesh: Some(mesh),
            skin: Some(skin),
            ..Default::default()
        },
    );
    // The chain: joint 0 at `origin`, each next one `segment` further along its parent's +X.
    let first = scene.nodes.len();
    let mut inverse_bind_matrices = Vec::new();
    for j in 0..joints {
        let local = if j == 0 { origin } else { Vec3::X * segment };
        scene.nodes.push(NodeDesc {
            name: format!("joint {j}"),
            local: Trs {
                translation: local,
                ..Default::default()
            },
            children: if j + 1 < joints {
                vec![first + j + 1]
            } else {
                Vec::new()
            },
            ..Default::default()
        });
        inverse_bind_matrices.push(Mat4::from_translation(
            -(origin + Vec3::X * segment * j as f32),
        ));
        let (axis, angles) = if j == 0 {
            (Vec3::Z, [0.0, 0.2, 0.0])
        } else {
            (Vec3::Y, [0.0, 0.4, -0.2])
        };
        scene.animations[0]
            .channels
            .push(rotation_channel(first + j, axis, &angles));
    }
    scene.roots.push(first);
    scene.skins.push(SkinDesc {
        name: "chain".into(),
        joints: (first..first + joints).collect(),
        inverse_bind_matrices,
        skeleton: Some(first),
    });
}

/// Adds `count` instances of one `n x n`-quad unit patch in a grid of side `spacing`
/// centred on `centre`, each turning about +Z and sliding along +X over time (rigid motion:
/// translation and rotation channels only).
pub fn add_rigid_patches(scene: &mut SceneDesc, count: usize, n: u32, spacing: f32, centre: Vec3) {
    scene.meshes.push(MeshDesc {
        name: "rigid patch".into(),
        primitives: vec![patch(n, n, 1.0, 1.0)],
        weights: Vec::new(),
    });
    let mesh = scene.meshes.len() - 1;
    let side = (count as f64).sqrt().ceil() as usize;
    for k in 0..count {
        let cell = Vec3::new((k % side) as f32, (k / side) as f32, 0.0);
        let at =
            centre + (cell - Vec3::new(side as f32 - 1.0, side as f32 - 1.0, 0.0) * 0.5) * spacing;
        let node = add_root(
            scene,
            NodeDesc {
                name: format!("patch {k}"),
                local: Trs {
                    translation: at,
                    ..Default::default()
                },
                mesh: Some(mesh),
                ..Default::default()
            },
        );
        let turn = 0.3 + 0.01 * (k % 7) as f32;
        scene.animations[0]
            .channels
            .push(rotation_channel(node, Vec3::Z, &[0.0, turn, 0.0]));
        scene.animations[0].channels.push(ChannelDesc {
            node,
            target: ChannelTarget::Translation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0, 2.0],
            values: [at, at + Vec3::X * 0.2 * spacing, at]
                .iter()
                .flat_map(|v| v.to_array())
                .collect(),
            components: 3,
        });
    }
}

/// Adds a camera at `eye` looking down -Z with vertical field of view `yfov`.
pub fn add_camera(scene: &mut SceneDesc, eye: Vec3, yfov: f32) {
    scene.cameras.push(CameraDesc { yfov, znear: 0.1 });
    let camera = scene.cameras.len() - 1;
    add_root(
        scene,
        NodeDesc {
            name: "camera".into(),
            local: Trs {
                translation: eye,
                ..Default::default()
            },
            camera: Some(camera),
            ..Default::default()
        },
    );
}
