//! The `museum` animation (after BART's museum): a gallery with a polished marble checker
//! floor (metallic 0.5, roughness 0: it reflects the room), five paintings on the walls,
//! and on a pedestal a sculpture that deforms by morph targets: an icosphere with three
//! targets (`Bumps`, `Stretch`, `Twist`, each with POSITION and NORMAL deltas) whose
//! weights play a CUBICSPLINE loop of [`MUSEUM_DURATION_SECONDS`].
//!
//! Detail: [`museum_scene`]`(detail)` subdivides the sculpture `3 + detail` times, so it has
//! `1280 * 4^detail` deforming triangles (detail 0: 1 280, 1: 5 120, 2: 20 480, 3: 81 920),
//! like BART's museum levels; the committed file uses [`MUSEUM_DEFAULT_DETAIL`].
//!
//! Layout (metres; +Y up): the room spans x, z in [-6, 6], 4.5 m high; floor squares of
//! 0.75 m (REPEAT); paintings 2 m x 1 m (256 x 128 px) centred 1.8 m up, three on the back wall
//! (z = -6) and two on the left (x = -6); the pedestal (0.8 m cube) stands at (0, 0, -1.5)
//! with the sculpture (radius 0.55 m) 0.65 m above it. Lights: two 60 cd lamps 1 m under
//! the ceiling, giving the floor 1.5-5 lux (4.9 under a lamp) and the paintings about
//! 1-2 lux.

use std::f32::consts::{PI, TAU};
use std::path::{Path, PathBuf};

use glam::{Quat, Vec2, Vec3};

use super::animation::{Animation, Channel, Interpolation};
use super::builder::GltfBuilder;
use super::error::AuthoringError;
use super::handles::NodeId;
use super::material::{Material, TextureBinding, WrapMode};
use super::node::Node;
use super::scene_kit::{Room, add_camera, add_light, key_times};
use super::shapes::{MeshData, MorphTarget, cuboid, icosphere, quad, smooth_normals};
use super::textures::{marble_checker, painting};

/// File name (without extension) of the museum animation.
pub const MUSEUM_SCENE_NAME: &str = "museum";
/// Length of the museum animation (one loop of the weights).
pub const MUSEUM_DURATION_SECONDS: f32 = 6.0;
/// Detail level of the committed museum: a 1 280-triangle sculpture.
pub const MUSEUM_DEFAULT_DETAIL: u32 = 0;
/// Largest supported detail level (81 920 sculpture triangles at 3; 4 would be 327 680).
pub const MUSEUM_MAX_DETAIL: u32 = 4;

/// Room size.
const ROOM: Vec3 = Vec3::new(12.0, 4.5, 12.0);
const PEDESTAL: Vec3 = Vec3::new(0.0, 0.0, -1.5);
const PEDESTAL_SIZE: f32 = 0.8;
const SCULPTURE_RADIUS: f32 = 0.55;
/// Weight key intervals over the loop (a key every 0.5 s).
const KEY_INTERVALS: u32 = 12;

/// Triangles of the sculpture at `detail`: `1280 * 4^detail`.
pub fn museum_sculpture_triangles(detail: u32) -> usize {
    1280 * 4usize.pow(detail)
}

/// The museum animation as a builder with the sculpture at `detail` (see the module
/// documentation).
///
/// # Panics
/// If `detail > MUSEUM_MAX_DETAIL`.
pub fn museum_scene(detail: u32) -> GltfBuilder {
    assert!(
        detail <= MUSEUM_MAX_DETAIL,
        "museum detail {detail} is too high"
    );
    let mut scene = GltfBuilder::new();
    add_room(&mut scene);
    add_paintings(&mut scene);
    let sculpture = add_sculpture(&mut scene, detail);
    add_light(
        &mut scene,
        "LampWest",
        Vec3::new(-2.0, ROOM.y - 1.0, 1.0),
        Vec3::new(1.0, 0.94, 0.85),
        60.0,
    );
    add_light(
        &mut scene,
        "LampEast",
        Vec3::new(2.5, ROOM.y - 1.0, -2.5),
        Vec3::new(0.92, 0.96, 1.0),
        60.0,
    );
    add_camera(
        &mut scene,
        Vec3::new(3.8, 1.7, 4.6),
        Vec3::new(-0.6, 1.25, -1.8),
        55.0,
    );
    scene.add_animation(weights_animation(sculpture));
    scene
}

/// Writes `<name>.gltf`, `<name>.bin` and its PNGs into `dir` with the sculpture at
/// `detail`; returns their paths.
///
/// # Errors
/// [`AuthoringError::Io`] if `dir` cannot be created or a file cannot be written.
pub fn write_museum(dir: &Path, name: &str, detail: u32) -> Result<Vec<PathBuf>, AuthoringError> {
    museum_scene(detail).write(dir, name)
}

fn add_room(scene: &mut GltfBuilder) {
    let marble = scene.add_image(
        "floor_marble",
        marble_checker(512, 8, [232, 228, 218, 255], [46, 50, 58, 255]),
    );
    let floor = scene.add_material(Material {
        metallic: 0.5,
        roughness: 0.0,
        ..Material::textured(
            "PolishedMarble",
            TextureBinding::new(marble, WrapMode::Repeat),
        )
    });
    let walls = scene.add_material(Material {
        roughness: 0.9,
        ..Material::matte("Plaster", Vec3::new(0.72, 0.66, 0.58))
    });
    let ceiling = scene.add_material(Material::matte("Ceiling", Vec3::splat(0.85)));
    Room {
        size: ROOM,
        floor: Some((floor, 6.0)),
        walls: Some((walls, None)),
        ceiling: Some(ceiling),
    }
    .add(scene);
}

/// Five framed paintings (the frame is painted into each texture).
fn add_paintings(scene: &mut GltfBuilder) {
    let (w, h) = (2.0, 1.0);
    let half = ROOM / 2.0;
    let hangings = [
        (Vec3::new(-3.6, 1.8, -half.z + 0.02), 0.0),
        (Vec3::new(0.0, 1.8, -half.z + 0.02), 0.0),
        (Vec3::new(3.6, 1.8, -half.z + 0.02), 0.0),
        (Vec3::new(-half.x + 0.02, 1.8, -2.6), PI / 2.0),
        (Vec3::new(-half.x + 0.02, 1.8, 1.6), PI / 2.0),
    ];
    let mesh_geometry = quad(w, h, Vec2::ONE);
    for (i, (at, yaw)) in hangings.into_iter().enumerate() {
        let image = scene.add_image(
            &format!("painting{i}"),
            painting(256, 128, i as u32 % 4, 101 + i as u32),
        );
        let material = scene.add_material(Material {
            roughness: 0.7,
            ..Material::textured(
                &format!("Painting{i}"),
                TextureBinding::new(image, WrapMode::ClampToEdge),
            )
        });
        let mesh = scene.add_simple_mesh(&format!("Painting{i}"), mesh_geometry.clone(), material);
        scene.add_node(
            Node::new(&format!("Painting{i}"))
                .with_mesh(mesh)
                .with_translation(at)
                .with_rotation(Quat::from_rotation_y(yaw)),
        );
    }
}

/// The sculpture geometry at `detail` with its three morph targets.
pub(crate) fn sculpture_geometry(detail: u32) -> MeshData {
    let mut mesh = icosphere(SCULPTURE_RADIUS, 3 + detail);
    let base = mesh.positions.clone();
    let base_normals = mesh.normals.clone().unwrap();
    let target = |displace: &dyn Fn(Vec3) -> Vec3| {
        let moved: Vec<Vec3> = base.iter().map(|&p| displace(p)).collect();
        let normals = smooth_normals(&moved, &mesh.indices);
        MorphTarget {
            positions: moved.iter().zip(&base).map(|(m, p)| *m - *p).collect(),
            normals: Some(
                normals
                    .iter()
                    .zip(&base_normals)
                    .map(|(m, n)| *m - *n)
                    .collect(),
            ),
        }
    };
    let r = SCULPTURE_RADIUS;
    // Bumps: six lobes pushed out along the normal.
    let bumps = target(&|p: Vec3| {
        let q = p / r;
        let lobes =
            (q.x * q.x * q.x * q.x + q.y * q.y * q.y * q.y + q.z * q.z * q.z * q.z) * 1.6 - 0.5;
        p * (1.0 + 0.35 * lobes + 0.06 * (9.0 * q.x).sin() * (9.0 * q.y).sin() * (9.0 * q.z).sin())
    });
    // Stretch: taller and thinner.
    let stretch = target(&|p: Vec3| Vec3::new(p.x * 0.7, p.y * 1.6, p.z * 0.7));
    // Twist: about +Y by up to +-70 degrees from the bottom to the top, with a squash.
    let twist = target(&|p: Vec3| {
        let q = Quat::from_rotation_y(1.2 * p.y / r);
        let squashed = Vec3::new(p.x * 1.25, p.y, p.z * 0.6);
        q * squashed
    });
    mesh.morph_targets = vec![bumps, stretch, twist];
    mesh
}

fn add_sculpture(scene: &mut GltfBuilder, detail: u32) -> NodeId {
    let stone = scene.add_material(Material::matte("Pedestal", Vec3::splat(0.82)));
    let bronze = scene.add_material(Material {
        metallic: 0.3,
        roughness: 0.4,
        ..Material::matte("Bronze", Vec3::new(0.75, 0.5, 0.25))
    });
    let pedestal = scene.add_simple_mesh(
        "Pedestal",
        cuboid(Vec3::splat(PEDESTAL_SIZE))
            .translated(Vec3::Y * PEDESTAL_SIZE / 2.0)
            .without_uvs(),
        stone,
    );
    scene.add_node(
        Node::new("Pedestal")
            .with_mesh(pedestal)
            .with_translation(PEDESTAL),
    );
    let mesh = scene.add_simple_mesh("Sculpture", sculpture_geometry(detail), bronze);
    scene.add_node(
        Node::new("Sculpture")
            .with_mesh(mesh)
            .with_translation(PEDESTAL + Vec3::Y * (PEDESTAL_SIZE + 0.65)),
    )
}

/// Weight of each target at time `t` and its derivative per second: bumps swell twice per
/// loop, the stretch once (half a period late), the twist turns one way then the other.
fn weights_at(t: f32) -> ([f32; 3], [f32; 3]) {
    let w = TAU / MUSEUM_DURATION_SECONDS;
    let bumps = 0.5 - 0.5 * (2.0 * w * t).cos();
    let d_bumps = w * (2.0 * w * t).sin();
    let stretch = 0.5 - 0.5 * (w * t + PI / 2.0).cos();
    let d_stretch = 0.5 * w * (w * t + PI / 2.0).sin();
    let twist = 0.8 * (w * t).sin();
    let d_twist = 0.8 * w * (w * t).cos();
    ([bumps, stretch, twist], [d_bumps, d_stretch, d_twist])
}

/// CUBICSPLINE weight keys every 0.5 s: values and tangents (per second) of
/// [`weights_at`], so the Hermite curve follows the smooth loop.
fn weights_animation(node: NodeId) -> Animation {
    let times = key_times(MUSEUM_DURATION_SECONDS, KEY_INTERVALS);
    let mut values = Vec::new();
    for &t in &times {
        let (w, d) = weights_at(t);
        values.extend(d); // in-tangent
        values.extend(w);
        values.extend(d); // out-tangent
    }
    Animation {
        name: "SculptureMorph".into(),
        channels: vec![Channel::weights(
            node,
            Interpolation::CubicSpline,
            times,
            3,
            values,
        )],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sculpture_triangles_grow_by_four_per_detail_level() {
        for detail in 0..3 {
            let g = sculpture_geometry(detail);
            g.validate().unwrap();
            assert_eq!(g.triangle_count(), museum_sculpture_triangles(detail));
            assert_eq!(g.morph_targets.len(), 3);
        }
    }

    #[test]
    fn weights_loop_and_change_from_the_first_frame() {
        let (first, _) = weights_at(0.0);
        let (last, _) = weights_at(MUSEUM_DURATION_SECONDS);
        for (a, b) in first.iter().zip(last) {
            assert!((a - b).abs() < 1e-5);
        }
        let (next, _) = weights_at(1.0 / 30.0);
        assert!(first.iter().zip(next).any(|(a, b)| a != &b));
    }
}
