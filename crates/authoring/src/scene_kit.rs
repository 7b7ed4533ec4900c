//! Small helpers the authored scenes share: a looking-at camera, a point light on its own
//! node, a room's inward-facing walls, and key-time sequences.

use glam::{Quat, Vec2, Vec3};

use super::builder::GltfBuilder;
use super::handles::{MaterialId, NodeId};
use super::node::{Node, PerspectiveCamera, PointLight};
use super::shapes::{plane, quad};

/// A 16:9 perspective camera named `Camera` at `eye` looking at `target` with +Y up.
pub(crate) fn add_camera(scene: &mut GltfBuilder, eye: Vec3, target: Vec3, yfov_degrees: f32) {
    let camera = scene.add_camera(PerspectiveCamera {
        name: "Camera".into(),
        yfov: yfov_degrees.to_radians(),
        aspect_ratio: Some(16.0 / 9.0),
        znear: 0.05,
        zfar: Some(1000.0),
    });
    scene.add_node(
        Node::new("Camera")
            .with_camera(camera)
            .looking_at(eye, target, Vec3::Y),
    );
}

/// A point light of `intensity` candela (no range) on a node of the same name at `at`.
pub(crate) fn add_light(
    scene: &mut GltfBuilder,
    name: &str,
    at: Vec3,
    color: Vec3,
    intensity: f32,
) -> NodeId {
    let light = scene.add_point_light(PointLight {
        name: name.into(),
        color,
        intensity,
        range: None,
    });
    scene.add_node(Node::new(name).with_light(light).with_translation(at))
}

/// The inner surfaces of a box-shaped room centred on x = z = 0: floor (y = 0), ceiling
/// (y = `size.y`) and four walls, all facing inward. `tile` is the texture repeat length
/// in metres for the floor and for the walls (walls without one have no UVs); `None`
/// materials leave a surface out.
pub(crate) struct Room {
    pub size: Vec3,
    pub floor: Option<(MaterialId, f32)>,
    pub walls: Option<(MaterialId, Option<f32>)>,
    pub ceiling: Option<MaterialId>,
}

impl Room {
    pub(crate) fn add(&self, scene: &mut GltfBuilder) {
        let s = self.size;
        if let Some((material, tile)) = self.floor {
            let mesh = scene.add_simple_mesh(
                "Floor",
                plane(s.x, s.z, Vec2::new(s.x, s.z) / tile),
                material,
            );
            scene.add_node(Node::new("Floor").with_mesh(mesh));
        }
        if let Some(material) = self.ceiling {
            let mesh = scene.add_simple_mesh(
                "Ceiling",
                plane(s.x, s.z, Vec2::ONE).without_uvs(),
                material,
            );
            scene.add_node(
                Node::new("Ceiling")
                    .with_mesh(mesh)
                    .with_translation(Vec3::Y * s.y)
                    .with_rotation(Quat::from_rotation_x(std::f32::consts::PI)),
            );
        }
        if let Some((material, tile)) = self.walls {
            let wall = |width: f32| match tile {
                Some(tile) => quad(width, s.y, Vec2::new(width, s.y) / tile),
                None => quad(width, s.y, Vec2::ONE).without_uvs(),
            };
            let long = scene.add_simple_mesh("WallX", wall(s.x), material);
            let deep = scene.add_simple_mesh("WallZ", wall(s.z), material);
            let half = s / 2.0;
            let walls = [
                ("WallBack", long, Vec3::new(0.0, half.y, -half.z), 0.0),
                ("WallFront", long, Vec3::new(0.0, half.y, half.z), 180.0),
                ("WallLeft", deep, Vec3::new(-half.x, half.y, 0.0), 90.0),
                ("WallRight", deep, Vec3::new(half.x, half.y, 0.0), -90.0),
            ];
            for (name, mesh, at, yaw) in walls {
                scene.add_node(
                    Node::new(name)
                        .with_mesh(mesh)
                        .with_translation(at)
                        .with_rotation(Quat::from_rotation_y(f32::to_radians(yaw))),
                );
            }
        }
    }
}

/// `intervals + 1` key times evenly spaced from 0 to `duration` seconds.
pub(crate) fn key_times(duration: f32, intervals: u32) -> Vec<f32> {
    (0..=intervals)
        .map(|i| duration * i as f32 / intervals as f32)
        .collect()
}

/// Rotations about `axis` by the given angles, each sign-aligned with the previous key so
/// LINEAR slerp between consecutive keys takes the short way.
pub(crate) fn rotations_about(axis: Vec3, angles: impl IntoIterator<Item = f32>) -> Vec<Quat> {
    let mut out: Vec<Quat> = Vec::new();
    for angle in angles {
        let mut q = Quat::from_axis_angle(axis, angle);
        if out.last().is_some_and(|p| p.dot(q) < 0.0) {
            q = -q;
        }
        out.push(q);
    }
    out
}
