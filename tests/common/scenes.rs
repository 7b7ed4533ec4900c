//! Scenes built in code for the end-to-end tests: no files, no ../shared.

use glam::{Quat, Vec2, Vec3, Vec4};
use mipray::scene::{
    AnimationDesc, CameraDesc, ChannelDesc, ChannelTarget, Interpolation, LightDesc, LightKind,
    MaterialDesc, MeshDesc, NodeDesc, PrimitiveDesc, SceneDesc, Trs,
};
use mipray::texture::{MipPyramid, Sampler, Texture, WrapMode};

/// A `size` x `size` checkerboard texture with `squares` squares per side.
pub fn checker(size: u32, squares: u32) -> Texture {
    let cell = (size / squares).max(1);
    let texels = (0..size * size)
        .map(|i| {
            let (x, y) = (i % size, i / size);
            if ((x / cell) + (y / cell)) % 2 == 0 {
                Vec4::new(0.9, 0.9, 0.9, 1.0)
            } else {
                Vec4::new(0.05, 0.1, 0.4, 1.0)
            }
        })
        .collect();
    Texture {
        name: format!("checker{size}"),
        pyramid: MipPyramid::from_linear_rgba(size, size, texels).expect("valid checker"),
        sampler: Sampler {
            wrap_s: WrapMode::Repeat,
            wrap_t: WrapMode::Repeat,
            ..Sampler::default()
        },
    }
}

/// A quad in the node's XY plane, centred at the origin, facing +Z, UVs `0..uv_repeat`.
pub fn quad(size: f32, uv_repeat: f32, material: usize) -> PrimitiveDesc {
    let h = size / 2.0;
    PrimitiveDesc {
        positions: vec![
            Vec3::new(-h, -h, 0.0),
            Vec3::new(h, -h, 0.0),
            Vec3::new(h, h, 0.0),
            Vec3::new(-h, h, 0.0),
        ],
        normals: Some(vec![Vec3::Z; 4]),
        uvs: Some(vec![
            Vec2::new(0.0, uv_repeat),
            Vec2::new(uv_repeat, uv_repeat),
            Vec2::new(uv_repeat, 0.0),
            Vec2::new(0.0, 0.0),
        ]),
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(material),
        ..Default::default()
    }
}

/// An octahedron-subdivided sphere (radius 1) with smooth normals.
pub fn sphere(material: usize, subdivisions: u32) -> PrimitiveDesc {
    let mut positions = vec![
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ];
    let mut indices: Vec<u32> = vec![
        0, 2, 4, 4, 2, 1, 1, 2, 5, 5, 2, 0, 4, 3, 0, 1, 3, 4, 5, 3, 1, 0, 3, 5,
    ];
    for _ in 0..subdivisions {
        let mut next = Vec::new();
        for t in indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]];
            let mut mid = |i: u32, j: u32| {
                positions.push((positions[i as usize] + positions[j as usize]).normalize());
                positions.len() as u32 - 1
            };
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            next.extend([a, ab, ca, ab, b, bc, ca, bc, c, ab, bc, ca]);
        }
        indices = next;
    }
    PrimitiveDesc {
        normals: Some(positions.clone()),
        positions,
        uvs: None,
        indices,
        material: Some(material),
        ..Default::default()
    }
}

pub fn node(name: &str, local: Trs, mesh: Option<usize>) -> NodeDesc {
    NodeDesc {
        name: name.into(),
        local,
        mesh,
        ..Default::default()
    }
}

pub fn at(translation: Vec3) -> Trs {
    Trs {
        translation,
        ..Default::default()
    }
}

pub fn textured(texture: usize) -> MaterialDesc {
    MaterialDesc {
        name: "textured".into(),
        base_color: Vec3::ONE,
        base_color_texture: Some(texture),
        ..Default::default()
    }
}

pub fn mirror() -> MaterialDesc {
    MaterialDesc {
        name: "mirror".into(),
        base_color: Vec3::ONE,
        reflectance: 1.0,
        ..Default::default()
    }
}

pub fn glass() -> MaterialDesc {
    MaterialDesc {
        name: "glass".into(),
        base_color: Vec3::ONE,
        transmission: 1.0,
        ior: 1.5,
        ..Default::default()
    }
}

/// A camera node at `eye` looking down -Z (no rotation).
pub fn camera_node(eye: Vec3, scene: &mut SceneDesc, yfov: f32) -> usize {
    scene.cameras.push(CameraDesc { yfov, znear: 0.01 });
    scene.nodes.push(NodeDesc {
        name: "camera".into(),
        local: at(eye),
        camera: Some(scene.cameras.len() - 1),
        ..Default::default()
    });
    scene.nodes.len() - 1
}

/// Adds a root node and returns its index.
pub fn add_root(scene: &mut SceneDesc, node: NodeDesc) -> usize {
    scene.nodes.push(node);
    let i = scene.nodes.len() - 1;
    scene.roots.push(i);
    i
}

/// A textured quad of `size` facing a camera `distance` away (camera at the origin looking
/// down -Z), with a `texture_size`^2 checker mapped once.
pub fn facing_quad_scene(distance: f32, size: f32, texture_size: u32, yfov: f32) -> SceneDesc {
    let mut scene = SceneDesc {
        background: Vec3::splat(0.1),
        ..Default::default()
    };
    scene.textures.push(checker(texture_size, 8));
    scene.materials.push(textured(0));
    scene.meshes.push(MeshDesc {
        name: "quad".into(),
        primitives: vec![quad(size, 1.0, 0)],
        ..Default::default()
    });
    add_root(
        &mut scene,
        node("quad", at(Vec3::new(0.0, 0.0, -distance)), Some(0)),
    );
    let cam = camera_node(Vec3::ZERO, &mut scene, yfov);
    scene.roots.push(cam);
    scene
}

/// A small "everything" scene: receding checker floor, moving textured box stand-in (a quad),
/// a mirror, a glass sphere, two lights, a camera; animated over 1 s.
pub fn showcase_scene() -> SceneDesc {
    let mut scene = SceneDesc {
        background: Vec3::new(0.3, 0.4, 0.6),
        ..Default::default()
    };
    scene.textures.push(checker(128, 8));
    scene.materials.extend([textured(0), mirror(), glass()]);
    let floor_rotation = Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2);
    scene.meshes.push(MeshDesc {
        name: "floor".into(),
        primitives: vec![quad(200.0, 100.0, 0)],
        ..Default::default()
    });
    scene.meshes.push(MeshDesc {
        name: "mirror".into(),
        primitives: vec![quad(3.0, 1.0, 1)],
        ..Default::default()
    });
    scene.meshes.push(MeshDesc {
        name: "ball".into(),
        primitives: vec![sphere(2, 3)],
        ..Default::default()
    });
    scene.meshes.push(MeshDesc {
        name: "card".into(),
        primitives: vec![quad(1.0, 1.0, 0)],
        ..Default::default()
    });
    add_root(
        &mut scene,
        node(
            "floor",
            Trs {
                rotation: floor_rotation,
                ..Default::default()
            },
            Some(0),
        ),
    );
    add_root(
        &mut scene,
        node(
            "mirror",
            Trs {
                translation: Vec3::new(2.5, 1.5, -8.0),
                rotation: Quat::from_rotation_y(-0.5),
                ..Default::default()
            },
            Some(1),
        ),
    );
    add_root(
        &mut scene,
        node("ball", at(Vec3::new(-1.0, 1.0, -5.0)), Some(2)),
    );
    let card = add_root(
        &mut scene,
        node("card", at(Vec3::new(0.5, 0.8, -4.0)), Some(3)),
    );
    let cam = camera_node(Vec3::new(0.0, 1.6, 0.0), &mut scene, 0.9);
    scene.roots.push(cam);
    for (i, p) in [Vec3::new(-3.0, 5.0, -2.0), Vec3::new(4.0, 4.0, -6.0)]
        .into_iter()
        .enumerate()
    {
        scene.lights.push(LightDesc {
            kind: LightKind::Point,
            color: Vec3::ONE,
            intensity: 60.0,
            range: None,
            inverse_square: true,
        });
        let n = add_root(
            &mut scene,
            NodeDesc {
                name: format!("light{i}"),
                local: at(p),
                light: Some(i),
                ..Default::default()
            },
        );
        let _ = n;
    }
    scene.animations.push(AnimationDesc {
        name: "slide".into(),
        channels: vec![ChannelDesc {
            node: card,
            target: ChannelTarget::Translation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0],
            values: vec![0.5, 0.8, -4.0, -0.5, 1.2, -3.0],
            components: 3,
        }],
    });
    scene
}

pub fn channel(node: usize, target: ChannelTarget, times: &[f32], values: &[f32]) -> ChannelDesc {
    let components = if target == ChannelTarget::Rotation {
        4
    } else {
        3
    };
    ChannelDesc {
        node,
        target,
        interpolation: Interpolation::Linear,
        times: times.to_vec(),
        values: values.to_vec(),
        components,
    }
}

/// The showcase scene plus three more textured cards: one spinning (rigid), one growing
/// uniformly (scaled), one stretched along x (non-uniform: deformed). Returns the scene and
/// the node indices of (spinning, growing, stretched).
pub fn dynamic_scene() -> (SceneDesc, [usize; 3]) {
    let mut scene = showcase_scene();
    let card_mesh = scene
        .meshes
        .iter()
        .position(|m| m.name == "card")
        .expect("card mesh");
    let spin = add_root(
        &mut scene,
        node("spin", at(Vec3::new(-2.0, 1.0, -6.0)), Some(card_mesh)),
    );
    let grow = add_root(
        &mut scene,
        node("grow", at(Vec3::new(1.5, 0.5, -6.0)), Some(card_mesh)),
    );
    let stretch = add_root(
        &mut scene,
        node("stretch", at(Vec3::new(0.0, 2.2, -7.0)), Some(card_mesh)),
    );
    let q0 = Quat::IDENTITY.to_array();
    let q1 = Quat::from_rotation_y(2.5).to_array();
    let spin_values: Vec<f32> = q0.iter().chain(&q1).copied().collect();
    scene.animations.push(AnimationDesc {
        name: "dynamic".into(),
        channels: vec![
            channel(spin, ChannelTarget::Rotation, &[0.0, 1.0], &spin_values),
            channel(
                grow,
                ChannelTarget::Scale,
                &[0.0, 1.0],
                &[1.0, 1.0, 1.0, 2.0, 2.0, 2.0],
            ),
            channel(
                stretch,
                ChannelTarget::Scale,
                &[0.0, 1.0],
                &[1.0, 1.0, 1.0, 3.0, 1.0, 1.0],
            ),
        ],
    });
    (scene, [spin, grow, stretch])
}

/// Appends every node, mesh, skin and animation channel of `other` to `scene` (indices
/// shifted), with `other`'s primitives drawn with `material` and given planar UVs (x, y).
pub fn merge_textured(scene: &mut SceneDesc, mut other: SceneDesc, material: usize, offset: Vec3) {
    let (nodes, meshes, skins) = (scene.nodes.len(), scene.meshes.len(), scene.skins.len());
    for mesh in &mut other.meshes {
        for p in &mut mesh.primitives {
            p.material = Some(material);
            p.uvs = Some(
                p.positions
                    .iter()
                    .map(|v| Vec2::new(v.x * 0.5, v.y * 0.5))
                    .collect(),
            );
        }
    }
    for node in &mut other.nodes {
        node.children.iter_mut().for_each(|c| *c += nodes);
        node.mesh = node.mesh.map(|m| m + meshes);
        node.skin = node.skin.map(|s| s + skins);
    }
    for skin in &mut other.skins {
        skin.joints.iter_mut().for_each(|j| *j += nodes);
        skin.skeleton = skin.skeleton.map(|s| s + nodes);
    }
    for root in &other.roots {
        other.nodes[*root].local.translation += offset;
    }
    scene.roots.extend(other.roots.iter().map(|r| r + nodes));
    scene.nodes.extend(other.nodes);
    scene.meshes.extend(other.meshes);
    scene.skins.extend(other.skins);
    let channels: Vec<ChannelDesc> = other
        .animations
        .into_iter()
        .flat_map(|a| a.channels)
        .map(|mut c| {
            c.node += nodes;
            c
        })
        .collect();
    scene.animations.push(AnimationDesc {
        name: "merged".into(),
        channels,
    });
}

/// A textured `n x n`-quad grid in the XY plane (unit size) with one morph target that lifts
/// the vertices listed in `lifted` along +Z; its weight goes 0 -> 1 over one second.
pub fn morph_grid_scene(n: u32, lifted: &[u32]) -> SceneDesc {
    let mut positions = Vec::new();
    for y in 0..=n {
        for x in 0..=n {
            positions.push(Vec3::new(
                x as f32 / n as f32 - 0.5,
                y as f32 / n as f32 - 0.5,
                0.0,
            ));
        }
    }
    let mut indices = Vec::new();
    for y in 0..n {
        for x in 0..n {
            let i = y * (n + 1) + x;
            indices.extend([i, i + 1, i + n + 2, i, i + n + 2, i + n + 1]);
        }
    }
    let mut delta = vec![Vec3::ZERO; positions.len()];
    for &v in lifted {
        delta[v as usize] = Vec3::new(0.0, 0.0, 0.3);
    }
    let primitive = PrimitiveDesc {
        normals: Some(vec![Vec3::Z; positions.len()]),
        uvs: Some(
            positions
                .iter()
                .map(|p| Vec2::new(p.x + 0.5, 0.5 - p.y))
                .collect(),
        ),
        positions,
        indices,
        material: Some(0),
        morph_targets: vec![mipray::scene::MorphTargetDesc {
            positions: Some(delta),
            normals: None,
        }],
        ..Default::default()
    };
    let mut scene = SceneDesc {
        background: Vec3::splat(0.2),
        ..Default::default()
    };
    scene.textures.push(checker(64, 8));
    scene.materials.push(textured(0));
    scene.meshes.push(MeshDesc {
        name: "grid".into(),
        primitives: vec![primitive],
        weights: vec![0.0],
    });
    let grid = add_root(
        &mut scene,
        node("grid", at(Vec3::new(0.0, 0.0, -2.0)), Some(0)),
    );
    let cam = camera_node(Vec3::ZERO, &mut scene, 0.8);
    scene.roots.push(cam);
    scene.animations.push(AnimationDesc {
        name: "lift".into(),
        channels: vec![ChannelDesc {
            node: grid,
            target: ChannelTarget::Weights,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0],
            values: vec![0.0, 1.0],
            components: 1,
        }],
    });
    scene
}

/// Adds a textured mesh (material `material`) of two degenerate triangles: one of zero world
/// area (collinear) and one of zero UV area, with a zero and a huge vertex normal.
pub fn add_degenerate_mesh(scene: &mut SceneDesc, material: usize) {
    let degenerate = PrimitiveDesc {
        positions: vec![
            Vec3::new(0.0, 1.0, -3.0),
            Vec3::new(1.0, 1.0, -3.0),
            Vec3::new(2.0, 1.0, -3.0),
            Vec3::new(0.0, 1.5, -3.0),
        ],
        normals: Some(vec![
            Vec3::ZERO,
            Vec3::new(f32::MAX, 0.0, 0.0),
            Vec3::Y,
            Vec3::Z,
        ]),
        uvs: Some(vec![
            Vec2::ZERO,
            Vec2::X,
            Vec2::new(2.0, 0.0),
            Vec2::new(3.0, 0.0),
        ]),
        indices: vec![0, 1, 2, 0, 1, 3],
        material: Some(material),
        ..Default::default()
    };
    scene.meshes.push(MeshDesc {
        name: "degenerate".into(),
        primitives: vec![degenerate],
        ..Default::default()
    });
    let n = scene.meshes.len() - 1;
    add_root(scene, node("degenerate", Default::default(), Some(n)));
}

/// Render settings for the end-to-end tests: `width x height`, one sample, depth 5.
pub fn settings(
    width: u32,
    height: u32,
    lod: mipray::lod::LodMethod,
) -> mipray::frame::RenderSettings {
    mipray::frame::RenderSettings {
        width,
        height,
        lod,
        spp: 1,
        max_depth: 5,
        lights: None,
        ..Default::default()
    }
}
