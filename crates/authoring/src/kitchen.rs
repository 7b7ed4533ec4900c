//! The `kitchen` animation (after BART's kitchen): a tiled room with a checkered floor, a
//! table carrying a glass bowl and a glass tumbler, a framed mirror on the back wall, six
//! ceiling lights, and a toy car driving a closed loop around the floor as a rigid
//! hierarchy: `Car` (translation + yaw along the path) -> `Steer*` front pivots (steering
//! yaw from the path's curvature) -> `Wheel*` (spin from the distance rolled), the rear
//! wheels spinning directly under `Car`.
//!
//! Layout (metres; +Y up): the room spans x, z in [-3, 3], 2.8 m high; floor checker of
//! 0.5 m squares, walls of 15 cm tiles (both REPEAT); the table stands at (-0.8, 0, -1.5);
//! the mirror hangs on the back wall (z = -3) centred at (0.9, 1.45); the car's path is the
//! ellipse x = 0.3 + 1.6 cos(theta), z = 0.5 + 1.0 sin(theta), driven once in
//! [`KITCHEN_DURATION_SECONDS`] (keys every 0.05 s, LINEAR; the loop closes: the last key
//! is the first, with the yaw one turn on and the wheels a whole number of turns on).
//! Lights: six 7 cd lamps 0.4 m under the ceiling on a 3 m x 2 m grid, alternately warm and
//! cool, giving the floor 2-4 lux (about 1.2 lux straight under one lamp from that lamp
//! alone) and the walls 1-3 lux away from the lamps.

use std::f32::consts::{FRAC_PI_2, TAU};
use std::path::{Path, PathBuf};

use glam::{Affine3A, Quat, Vec3};

use super::animation::{Animation, Channel, Interpolation};
use super::builder::GltfBuilder;
use super::error::AuthoringError;
use super::handles::{MaterialId, MeshId, NodeId};
use super::material::{Material, TextureBinding, WrapMode};
use super::node::{Node, Primitive};
use super::scene_kit::{Room, add_camera, add_light, key_times, rotations_about};
use super::shapes::{MeshData, cuboid, cylinder, quad, uv_sphere};
use super::textures::{checkerboard, tiles};

/// File name (without extension) of the kitchen animation.
pub const KITCHEN_SCENE_NAME: &str = "kitchen";
/// Length of the kitchen animation: one lap of the car.
pub const KITCHEN_DURATION_SECONDS: f32 = 6.0;

/// Key intervals over the lap (a key every 0.05 s).
const KEY_INTERVALS: u32 = 120;
/// Room size.
const ROOM: Vec3 = Vec3::new(6.0, 2.8, 6.0);
/// Centre and semi-axes (x, z) of the car's elliptic path.
const PATH_CENTRE: Vec3 = Vec3::new(0.3, 0.0, 0.5);
const PATH_AXES: (f32, f32) = (1.6, 1.0);
/// Distance between the front and rear axles, and between the left and right wheels.
const WHEELBASE: f32 = 0.28;
const TRACK: f32 = 0.24;
/// Wheel width.
const WHEEL_WIDTH: f32 = 0.04;
/// Where the table stands.
const TABLE_POSITION: Vec3 = Vec3::new(-0.8, 0.0, -1.5);
const TABLE_HEIGHT: f32 = 0.75;

/// The kitchen animation as a builder (see the module documentation for its layout).
pub fn kitchen_scene() -> GltfBuilder {
    let mut scene = GltfBuilder::new();
    add_room(&mut scene);
    add_table(&mut scene);
    add_mirror(&mut scene);
    let car = add_car(&mut scene);
    for (i, (x, z)) in [
        (-1.5, -2.0),
        (1.5, -2.0),
        (-1.5, 0.0),
        (1.5, 0.0),
        (-1.5, 2.0),
        (1.5, 2.0),
    ]
    .into_iter()
    .enumerate()
    {
        let warm = Vec3::new(1.0, 0.93, 0.82);
        let cool = Vec3::new(0.9, 0.95, 1.0);
        add_light(
            &mut scene,
            &format!("Lamp{i}"),
            Vec3::new(x, ROOM.y - 0.4, z),
            if i % 2 == 0 { warm } else { cool },
            7.0,
        );
    }
    add_camera(
        &mut scene,
        Vec3::new(2.6, 1.65, 2.7),
        Vec3::new(-0.4, 0.45, -0.6),
        55.0,
    );
    scene.add_animation(car.animation());
    scene
}

/// Writes `kitchen.gltf`, `kitchen.bin` and its PNGs into `dir`; returns their paths.
///
/// # Errors
/// [`AuthoringError::Io`] if `dir` cannot be created or a file cannot be written.
pub fn write_kitchen(dir: &Path) -> Result<Vec<PathBuf>, AuthoringError> {
    kitchen_scene().write(dir, KITCHEN_SCENE_NAME)
}

fn add_room(scene: &mut GltfBuilder) {
    let checker = scene.add_image(
        "floor_checker",
        checkerboard(256, 8, [225, 220, 205, 255], [60, 52, 48, 255]),
    );
    let wall_tiles = scene.add_image(
        "wall_tiles",
        tiles(256, 8, 3, [196, 222, 226, 255], [120, 124, 126, 255]),
    );
    let floor = scene.add_material(Material {
        roughness: 0.7,
        ..Material::textured("Floor", TextureBinding::new(checker, WrapMode::Repeat))
    });
    let walls = scene.add_material(Material {
        roughness: 0.5,
        ..Material::textured(
            "WallTiles",
            TextureBinding::new(wall_tiles, WrapMode::Repeat),
        )
    });
    let ceiling = scene.add_material(Material::matte("Ceiling", Vec3::splat(0.8)));
    Room {
        size: ROOM,
        // 8 squares of 0.5 m per repeat; 8 tiles of 15 cm per repeat.
        floor: Some((floor, 4.0)),
        walls: Some((walls, Some(1.2))),
        ceiling: Some(ceiling),
    }
    .add(scene);
}

/// A wooden table with a glass bowl (a sphere) and a glass tumbler on it.
fn add_table(scene: &mut GltfBuilder) {
    let wood = scene.add_material(Material {
        roughness: 0.6,
        ..Material::matte("Wood", Vec3::new(0.42, 0.26, 0.13))
    });
    let top_size = Vec3::new(1.2, 0.05, 0.8);
    let leg = Vec3::new(0.06, TABLE_HEIGHT - top_size.y, 0.06);
    let mut parts = vec![cuboid(top_size).translated(Vec3::Y * (TABLE_HEIGHT - top_size.y / 2.0))];
    for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let at = Vec3::new(
            sx * (top_size.x / 2.0 - 0.06),
            leg.y / 2.0,
            sz * (top_size.z / 2.0 - 0.06),
        );
        parts.push(cuboid(leg).translated(at));
    }
    let table = MeshData::merged(parts).without_uvs();
    let mesh = scene.add_simple_mesh("Table", table, wood);
    let glass = scene.add_material(Material::glass("Glass", 1.5));
    let bowl_radius = 0.17;
    let bowl = scene.add_simple_mesh(
        "GlassBowl",
        uv_sphere(bowl_radius, 32, 16).without_uvs(),
        glass,
    );
    let tumbler = scene.add_simple_mesh(
        "GlassTumbler",
        cylinder(0.05, 0.14, 24).without_uvs(),
        glass,
    );
    let bowl_node = scene.add_node(
        Node::new("GlassBowl")
            .with_mesh(bowl)
            .with_translation(Vec3::new(0.15, TABLE_HEIGHT + bowl_radius, 0.05)),
    );
    let tumbler_node = scene.add_node(
        Node::new("GlassTumbler")
            .with_mesh(tumbler)
            .with_translation(Vec3::new(-0.3, TABLE_HEIGHT + 0.07, 0.15)),
    );
    scene.add_node(
        Node::new("Table")
            .with_mesh(mesh)
            .with_translation(TABLE_POSITION)
            .with_children([bowl_node, tumbler_node]),
    );
}

/// A 1.6 m x 1.0 m mirror in a dark frame on the back wall.
fn add_mirror(scene: &mut GltfBuilder) {
    let (w, h, bar) = (1.6, 1.0, 0.06);
    let mirror = scene.add_material(Material::mirror("Mirror", Vec3::splat(0.92)));
    let frame = scene.add_material(Material::matte("MirrorFrame", Vec3::new(0.1, 0.1, 0.12)));
    let glass = scene.add_simple_mesh(
        "MirrorGlass",
        quad(w, h, glam::Vec2::ONE).without_uvs(),
        mirror,
    );
    let frame_mesh = MeshData::merged([
        cuboid(Vec3::new(w + 2.0 * bar, bar, 0.03)).translated(Vec3::Y * (h + bar) / 2.0),
        cuboid(Vec3::new(w + 2.0 * bar, bar, 0.03)).translated(-Vec3::Y * (h + bar) / 2.0),
        cuboid(Vec3::new(bar, h, 0.03)).translated(Vec3::X * (w + bar) / 2.0),
        cuboid(Vec3::new(bar, h, 0.03)).translated(-Vec3::X * (w + bar) / 2.0),
    ])
    .without_uvs();
    let frame_mesh = scene.add_simple_mesh("MirrorFrame", frame_mesh, frame);
    let glass_node = scene.add_node(
        Node::new("MirrorGlass")
            .with_mesh(glass)
            .with_translation(Vec3::Z * 0.005),
    );
    scene.add_node(
        Node::new("Mirror")
            .with_mesh(frame_mesh)
            .with_translation(Vec3::new(0.9, 1.45, -ROOM.z / 2.0 + 0.02))
            .with_children([glass_node]),
    );
}

/// The car's animated nodes.
struct Car {
    body: NodeId,
    steer: [NodeId; 2],
    wheels: [NodeId; 4],
    wheel_radius: f32,
}

/// Point of the path at parameter `theta`.
fn path_point(theta: f32) -> Vec3 {
    PATH_CENTRE + Vec3::new(PATH_AXES.0 * theta.cos(), 0.0, PATH_AXES.1 * theta.sin())
}

/// Arc length of the path from parameter 0 to each key's parameter (fine chords).
fn path_lengths() -> Vec<f32> {
    const FINE: u32 = 32;
    let mut lengths = vec![0.0];
    let mut total = 0.0;
    for k in 0..KEY_INTERVALS {
        for f in 0..FINE {
            let t0 = TAU * (k * FINE + f) as f32 / (KEY_INTERVALS * FINE) as f32;
            let t1 = TAU * (k * FINE + f + 1) as f32 / (KEY_INTERVALS * FINE) as f32;
            total += path_point(t1).distance(path_point(t0));
        }
        lengths.push(total);
    }
    lengths
}

/// Wheel radius near 7 cm that rolls a whole number of turns per lap.
fn wheel_radius(lap: f32) -> f32 {
    let turns = (lap / (TAU * 0.07)).round();
    lap / (TAU * turns)
}

/// Heading (yaw about +Y of the car's +X forward axis) at each key, unwrapped.
fn headings() -> Vec<f32> {
    let mut out: Vec<f32> = Vec::new();
    for k in 0..=KEY_INTERVALS {
        let theta = TAU * k as f32 / KEY_INTERVALS as f32;
        let d = Vec3::new(-PATH_AXES.0 * theta.sin(), 0.0, PATH_AXES.1 * theta.cos());
        let mut yaw = (-d.z).atan2(d.x);
        if let Some(&prev) = out.last() {
            while yaw - prev > std::f32::consts::PI {
                yaw -= TAU;
            }
            while yaw - prev < -std::f32::consts::PI {
                yaw += TAU;
            }
        }
        out.push(yaw);
    }
    out
}

fn add_car(scene: &mut GltfBuilder) -> Car {
    let lap = *path_lengths().last().unwrap();
    let radius = wheel_radius(lap);
    let paint = scene.add_material(Material {
        roughness: 0.35,
        ..Material::matte("CarPaint", Vec3::new(0.75, 0.08, 0.06))
    });
    let window = scene.add_material(Material {
        roughness: 0.2,
        ..Material::matte("CarWindow", Vec3::new(0.08, 0.1, 0.14))
    });
    let rubber = scene.add_material(Material::matte("Tyre", Vec3::splat(0.05)));
    let hub = scene.add_material(Material {
        metallic: 0.8,
        roughness: 0.3,
        ..Material::matte("Hub", Vec3::new(0.85, 0.8, 0.3))
    });
    let chassis_y = radius + 0.03;
    let body = MeshData::merged([
        cuboid(Vec3::new(0.44, 0.08, 0.2)).translated(Vec3::Y * chassis_y),
        cuboid(Vec3::new(0.1, 0.03, 0.16)).translated(Vec3::new(0.2, chassis_y + 0.05, 0.0)),
    ])
    .without_uvs();
    let cabin = cuboid(Vec3::new(0.22, 0.08, 0.17))
        .translated(Vec3::new(-0.03, chassis_y + 0.08, 0.0))
        .without_uvs();
    let body_geometry = scene.add_geometry("CarBody", body);
    let cabin_geometry = scene.add_geometry("CarCabin", cabin);
    let body_mesh = scene.add_mesh(
        "Car",
        vec![
            Primitive {
                geometry: body_geometry,
                material: Some(paint),
            },
            Primitive {
                geometry: cabin_geometry,
                material: Some(window),
            },
        ],
    );
    let wheel = wheel_mesh(scene, radius, rubber, hub);
    let axle_x = WHEELBASE / 2.0;
    let side = TRACK / 2.0;
    let wheel_node = |scene: &mut GltfBuilder, name: &str, at: Vec3| {
        scene.add_node(Node::new(name).with_mesh(wheel).with_translation(at))
    };
    let fl = wheel_node(scene, "WheelFrontLeft", Vec3::ZERO);
    let fr = wheel_node(scene, "WheelFrontRight", Vec3::ZERO);
    let rl = wheel_node(scene, "WheelRearLeft", Vec3::new(-axle_x, radius, -side));
    let rr = wheel_node(scene, "WheelRearRight", Vec3::new(-axle_x, radius, side));
    let steer_l = scene.add_node(
        Node::new("SteerFrontLeft")
            .with_translation(Vec3::new(axle_x, radius, -side))
            .with_children([fl]),
    );
    let steer_r = scene.add_node(
        Node::new("SteerFrontRight")
            .with_translation(Vec3::new(axle_x, radius, side))
            .with_children([fr]),
    );
    let body = scene.add_node(
        Node::new("Car")
            .with_mesh(body_mesh)
            .with_translation(path_point(0.0))
            .with_rotation(Quat::from_rotation_y(headings()[0]))
            .with_children([steer_l, steer_r, rl, rr]),
    );
    Car {
        body,
        steer: [steer_l, steer_r],
        wheels: [fl, fr, rl, rr],
        wheel_radius: radius,
    }
}

/// A tyre (a cylinder along Z) with a gold hub cross sticking out of both faces, so its
/// spin shows.
fn wheel_mesh(scene: &mut GltfBuilder, radius: f32, rubber: MaterialId, hub: MaterialId) -> MeshId {
    let along_z = Affine3A::from_rotation_x(FRAC_PI_2);
    let tyre = cylinder(radius, WHEEL_WIDTH, 20)
        .without_uvs()
        .transformed(along_z);
    let bar = |angle: f32| {
        cuboid(Vec3::new(1.5 * radius, 0.18 * radius, WHEEL_WIDTH + 0.006))
            .without_uvs()
            .transformed(Affine3A::from_rotation_z(angle))
    };
    let cross = MeshData::merged([bar(0.0), bar(FRAC_PI_2)]);
    let tyre = scene.add_geometry("Tyre", tyre);
    let cross = scene.add_geometry("Hub", cross);
    scene.add_mesh(
        "Wheel",
        vec![
            Primitive {
                geometry: tyre,
                material: Some(rubber),
            },
            Primitive {
                geometry: cross,
                material: Some(hub),
            },
        ],
    )
}

impl Car {
    /// Body translation and yaw along the path, front-wheel steering yaw from the path's
    /// curvature (`atan(wheelbase * dheading/ds)`), wheel spin `-s / r` about the axle.
    fn animation(&self) -> Animation {
        let times = key_times(KITCHEN_DURATION_SECONDS, KEY_INTERVALS);
        let lengths = path_lengths();
        let yaw = headings();
        let n = KEY_INTERVALS as usize;
        let positions: Vec<Vec3> = (0..=n)
            .map(|k| path_point(TAU * (k % n) as f32 / n as f32))
            .collect();
        let steering: Vec<f32> = (0..=n)
            .map(|k| {
                // Central differences around the closed loop.
                let (prev, next) = ((k + n - 1) % n, (k + 1) % n);
                let lap = lengths[n];
                let ds = (lengths[next] - lengths[prev]).rem_euclid(lap);
                let dyaw = (yaw[next] - yaw[prev]).rem_euclid(TAU);
                let dyaw = if dyaw > std::f32::consts::PI {
                    dyaw - TAU
                } else {
                    dyaw
                };
                (WHEELBASE * dyaw / ds).atan()
            })
            .collect();
        let spin: Vec<f32> = lengths.iter().map(|s| -s / self.wheel_radius).collect();
        let spin_keys = rotations_about(Vec3::Z, spin);
        let mut channels = vec![
            Channel::translation(self.body, Interpolation::Linear, times.clone(), &positions),
            Channel::rotation(
                self.body,
                Interpolation::Linear,
                times.clone(),
                &rotations_about(Vec3::Y, yaw),
            ),
        ];
        let steer_keys = rotations_about(Vec3::Y, steering);
        for node in self.steer {
            channels.push(Channel::rotation(
                node,
                Interpolation::Linear,
                times.clone(),
                &steer_keys,
            ));
        }
        for node in self.wheels {
            channels.push(Channel::rotation(
                node,
                Interpolation::Linear,
                times.clone(),
                &spin_keys,
            ));
        }
        Animation {
            name: "CarLap".into(),
            channels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn car_lap_closes_and_wheels_roll_whole_turns() {
        let lengths = path_lengths();
        let lap = lengths[KEY_INTERVALS as usize];
        let r = wheel_radius(lap);
        let turns = lap / (TAU * r);
        assert!((turns - turns.round()).abs() < 1e-3 && (0.06..0.08).contains(&r));
        let yaw = headings();
        // One full turn (clockwise seen from above: x = cos, z = sin turns about -Y).
        assert!((yaw[KEY_INTERVALS as usize] - yaw[0] + TAU).abs() < 1e-3);
        // Spin per key stays well under half a turn, so slerp spins the right way.
        let per_key = lengths
            .windows(2)
            .map(|w| (w[1] - w[0]) / r)
            .fold(0.0, f32::max);
        assert!(per_key < 1.5, "{per_key} rad per key");
    }

    #[test]
    fn path_stays_clear_of_the_table_and_walls() {
        for k in 0..KEY_INTERVALS {
            let p = path_point(TAU * k as f32 / KEY_INTERVALS as f32);
            assert!(p.x.abs() < ROOM.x / 2.0 - 0.4 && p.z.abs() < ROOM.z / 2.0 - 0.4);
            let d = (p - TABLE_POSITION).abs();
            assert!(d.x > 0.6 + 0.3 || d.z > 0.4 + 0.3, "key {k} at {p}");
        }
    }
}
