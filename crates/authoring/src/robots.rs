//! The `robots` animation (after BART's robots): four robots walking along a city street
//! between building facades. Each robot is a rigid hierarchy: `Robot*` (translation along
//! the street with a small bob) -> `Hip*` (thigh swing) -> `Knee*` (shin bend), and
//! `Shoulder*` (arm swing); every limb is a box hanging from its joint, so only rotation
//! keys move it. The walk cycle lasts [`STEP_CYCLE_SECONDS`] with keys every 1/8 of it
//! (LINEAR); the animation is [`ROBOTS_DURATION_SECONDS`] long.
//!
//! Layout (metres; +Y up, the street runs along Z): asphalt x in [-4, 4] (dashed centre
//! line), sidewalks of concrete tiles out to x = +-7, facades 18 m high at x = +-7 facing
//! the street, from z = -74 to z = 10, in four 21 m blocks per side alternating two window
//! textures (one texture repeat = 4 x 4 windows over 12 m). Robots: two on the road, two
//! on the sidewalks, two walking toward the camera and two away, one of them chrome
//! (metallic 1, roughness 0). One bright point light, 12 000 cd, 40 m above the street at
//! z = -8, gives the road 1.2-7.5 lux (7.5 under it, 6 at the camera, 1.2 at the far end)
//! and the facades about 1-2 lux.

use std::f32::consts::{PI, TAU};
use std::path::{Path, PathBuf};

use glam::{Quat, Vec2, Vec3};

use super::animation::{Animation, Channel, Interpolation};
use super::builder::GltfBuilder;
use super::error::AuthoringError;
use super::handles::{MaterialId, MeshId};
use super::material::{Material, TextureBinding, WrapMode};
use super::node::Node;
use super::scene_kit::{add_camera, add_light, key_times, rotations_about};
use super::shapes::{cuboid, plane, quad};
use super::textures::{asphalt, facade, tiles};

/// File name (without extension) of the robots animation.
pub const ROBOTS_SCENE_NAME: &str = "robots";
/// Length of the robots animation.
pub const ROBOTS_DURATION_SECONDS: f32 = 4.0;
/// One walk cycle (two steps).
pub const STEP_CYCLE_SECONDS: f32 = 1.0;

/// Keys per walk cycle.
const KEYS_PER_CYCLE: u32 = 8;
/// Street extent along Z and facade height.
const STREET_Z: (f32, f32) = (-74.0, 10.0);
const FACADE_HEIGHT: f32 = 18.0;
/// Hip height and limb lengths.
const HIP_Y: f32 = 0.9;
const THIGH: f32 = 0.45;
const SHIN: f32 = 0.42;
const ARM: f32 = 0.6;
const SHOULDER_Y: f32 = 1.5;

/// One robot: where it starts, its walking speed (m/s, along its facing), its facing
/// (+1: toward +Z, the camera; -1: away) and its phase in the cycle.
struct RobotSpec {
    name: &'static str,
    start: Vec3,
    speed: f32,
    facing: f32,
    phase: f32,
    chrome: bool,
    colour: Vec3,
}

const ROBOTS: [RobotSpec; 4] = [
    RobotSpec {
        name: "RobotA",
        start: Vec3::new(-1.6, 0.0, -9.0),
        speed: 1.0,
        facing: 1.0,
        phase: 0.0,
        chrome: false,
        colour: Vec3::new(0.8, 0.45, 0.1),
    },
    RobotSpec {
        name: "RobotB",
        start: Vec3::new(1.4, 0.0, -2.5),
        speed: 1.1,
        facing: -1.0,
        phase: 0.3,
        chrome: false,
        colour: Vec3::new(0.9, 0.9, 0.92),
    },
    RobotSpec {
        name: "RobotC",
        start: Vec3::new(-5.3, 0.0, -16.0),
        speed: 0.9,
        facing: 1.0,
        phase: 0.55,
        chrome: true,
        colour: Vec3::new(0.2, 0.45, 0.8),
    },
    RobotSpec {
        name: "RobotD",
        start: Vec3::new(5.2, 0.0, -5.0),
        speed: 1.2,
        facing: -1.0,
        phase: 0.8,
        chrome: false,
        colour: Vec3::new(0.3, 0.65, 0.3),
    },
];

/// The robots animation as a builder (see the module documentation for its layout).
pub fn robots_scene() -> GltfBuilder {
    let mut scene = GltfBuilder::new();
    add_street(&mut scene);
    let parts = RobotParts::new(&mut scene);
    let mut channels = Vec::new();
    for spec in &ROBOTS {
        channels.extend(add_robot(&mut scene, &parts, spec));
    }
    add_light(
        &mut scene,
        "StreetLight",
        Vec3::new(0.0, 40.0, -8.0),
        Vec3::new(1.0, 0.97, 0.92),
        12_000.0,
    );
    add_camera(
        &mut scene,
        Vec3::new(1.2, 1.8, 6.0),
        Vec3::new(-0.6, 1.4, -10.0),
        50.0,
    );
    scene.add_animation(Animation {
        name: "Walk".into(),
        channels,
    });
    scene
}

/// Writes `robots.gltf`, `robots.bin` and its PNGs into `dir`; returns their paths.
///
/// # Errors
/// [`AuthoringError::Io`] if `dir` cannot be created or a file cannot be written.
pub fn write_robots(dir: &Path) -> Result<Vec<PathBuf>, AuthoringError> {
    robots_scene().write(dir, ROBOTS_SCENE_NAME)
}

fn add_street(scene: &mut GltfBuilder) {
    let length = STREET_Z.1 - STREET_Z.0;
    let centre_z = (STREET_Z.0 + STREET_Z.1) / 2.0;
    let road_image = scene.add_image("asphalt", asphalt(256));
    let pavement_image = scene.add_image(
        "pavement",
        tiles(128, 4, 2, [170, 166, 158, 255], [110, 108, 104, 255]),
    );
    let road = scene.add_material(Material {
        roughness: 0.9,
        ..Material::textured("Asphalt", TextureBinding::new(road_image, WrapMode::Repeat))
    });
    let pavement = scene.add_material(Material::textured(
        "Pavement",
        TextureBinding::new(pavement_image, WrapMode::Repeat),
    ));
    // The road texture spans the road's width once and repeats every 8 m along it.
    let road_mesh = scene.add_simple_mesh(
        "Road",
        plane(8.0, length, Vec2::new(1.0, length / 8.0)),
        road,
    );
    scene.add_node(
        Node::new("Road")
            .with_mesh(road_mesh)
            .with_translation(Vec3::Z * centre_z),
    );
    // Sidewalks 15 cm high: a top plane and a kerb face, 4 x 4 slabs of 0.5 m per repeat.
    let walk_top = scene.add_simple_mesh(
        "SidewalkTop",
        plane(3.0, length, Vec2::new(1.5, length / 2.0)),
        pavement,
    );
    let kerb = scene.add_simple_mesh(
        "Kerb",
        quad(length, 0.15, Vec2::new(length / 2.0, 0.075)),
        pavement,
    );
    for (name, side) in [("Left", -1.0f32), ("Right", 1.0)] {
        scene.add_node(
            Node::new(&format!("Sidewalk{name}"))
                .with_mesh(walk_top)
                .with_translation(Vec3::new(side * 5.5, 0.15, centre_z)),
        );
        scene.add_node(
            Node::new(&format!("Kerb{name}"))
                .with_mesh(kerb)
                .with_translation(Vec3::new(side * 4.0, 0.075, centre_z))
                .with_rotation(Quat::from_rotation_y(-side * PI / 2.0)),
        );
    }
    let wall_colours = [[176, 150, 124, 255], [150, 160, 172, 255]];
    let materials: Vec<MaterialId> = (0..2)
        .map(|i| {
            let image = scene.add_image(
                &format!("facade{i}"),
                facade(256, 4, 4, wall_colours[i as usize], 17 + i),
            );
            scene.add_material(Material::textured(
                &format!("Facade{i}"),
                TextureBinding::new(image, WrapMode::Repeat),
            ))
        })
        .collect();
    const BLOCK: f32 = 21.0;
    const WINDOW_REPEAT: f32 = 12.0;
    let facade_meshes: Vec<MeshId> = materials
        .iter()
        .enumerate()
        .map(|(i, &m)| {
            scene.add_simple_mesh(
                &format!("Facade{i}"),
                quad(
                    BLOCK,
                    FACADE_HEIGHT,
                    Vec2::new(BLOCK, FACADE_HEIGHT) / WINDOW_REPEAT,
                ),
                m,
            )
        })
        .collect();
    let blocks = (length / BLOCK).round() as u32;
    for (name, side) in [("Left", -1.0f32), ("Right", 1.0)] {
        for b in 0..blocks {
            let z = STREET_Z.1 - BLOCK * (b as f32 + 0.5);
            let mesh = facade_meshes[((b + (side > 0.0) as u32) % 2) as usize];
            scene.add_node(
                Node::new(&format!("Facade{name}{b}"))
                    .with_mesh(mesh)
                    .with_translation(Vec3::new(side * 7.0, FACADE_HEIGHT / 2.0, z))
                    .with_rotation(Quat::from_rotation_y(-side * PI / 2.0)),
            );
        }
    }
}

/// Limb meshes, each hanging from its joint (the node origin) down -Y.
struct RobotParts {
    torso: MeshId,
    head: MeshId,
    thigh: MeshId,
    shin: MeshId,
    arm: MeshId,
    chrome_torso: MeshId,
    chrome_head: MeshId,
    chrome_thigh: MeshId,
    chrome_shin: MeshId,
    chrome_arm: MeshId,
}

impl RobotParts {
    fn new(scene: &mut GltfBuilder) -> Self {
        let grey = scene.add_material(Material {
            metallic: 0.6,
            roughness: 0.4,
            ..Material::matte("RobotSteel", Vec3::splat(0.6))
        });
        let chrome = scene.add_material(Material::mirror("RobotChrome", Vec3::splat(0.9)));
        let torso = cuboid(Vec3::new(0.5, 0.62, 0.3))
            .translated(Vec3::Y * (HIP_Y + 0.36))
            .without_uvs();
        let head = cuboid(Vec3::new(0.26, 0.26, 0.26))
            .translated(Vec3::Y * (SHOULDER_Y + 0.2))
            .without_uvs();
        let thigh = cuboid(Vec3::new(0.15, THIGH, 0.15))
            .translated(-Vec3::Y * THIGH / 2.0)
            .without_uvs();
        let mut shin = cuboid(Vec3::new(0.13, SHIN, 0.13)).translated(-Vec3::Y * SHIN / 2.0);
        shin.append(cuboid(Vec3::new(0.15, 0.06, 0.26)).translated(Vec3::new(
            0.0,
            -SHIN - 0.0,
            0.05,
        )));
        let shin = shin.without_uvs();
        let arm = cuboid(Vec3::new(0.1, ARM, 0.1))
            .translated(-Vec3::Y * ARM / 2.0)
            .without_uvs();
        RobotParts {
            torso: scene.add_simple_mesh("Torso", torso.clone(), grey),
            head: scene.add_simple_mesh("Head", head.clone(), grey),
            thigh: scene.add_simple_mesh("Thigh", thigh.clone(), grey),
            shin: scene.add_simple_mesh("Shin", shin.clone(), grey),
            arm: scene.add_simple_mesh("Arm", arm.clone(), grey),
            chrome_torso: scene.add_simple_mesh("ChromeTorso", torso, chrome),
            chrome_head: scene.add_simple_mesh("ChromeHead", head, chrome),
            chrome_thigh: scene.add_simple_mesh("ChromeThigh", thigh, chrome),
            chrome_shin: scene.add_simple_mesh("ChromeShin", shin, chrome),
            chrome_arm: scene.add_simple_mesh("ChromeArm", arm, chrome),
        }
    }
}

/// Walk-cycle angles at cycle phase `p` (in turns): hip swing (forward is +), knee bend
/// (always >= 0), shoulder swing, and the body's vertical bob.
fn walk_pose(p: f32) -> (f32, f32, f32, f32) {
    let a = TAU * p;
    let hip = 0.45 * a.sin();
    // The knee bends while the leg swings forward (the second half of the swing back).
    let knee = 0.7 * (0.5 - 0.5 * (a + 0.6).cos()).powi(2) * (a.cos() > -0.2) as u8 as f32
        + 0.1 * (0.5 - 0.5 * (2.0 * a).cos());
    let shoulder = -0.4 * a.sin();
    let bob = 0.03 * (2.0 * a).cos();
    (hip, knee, shoulder, bob)
}

/// Adds one robot's nodes; returns its animation channels.
fn add_robot(scene: &mut GltfBuilder, parts: &RobotParts, spec: &RobotSpec) -> Vec<Channel> {
    let robot_colour = scene.add_material(Material {
        roughness: 0.5,
        ..Material::matte(&format!("{}Paint", spec.name), spec.colour)
    });
    let (torso, head, thigh, shin, arm) = if spec.chrome {
        (
            parts.chrome_torso,
            parts.chrome_head,
            parts.chrome_thigh,
            parts.chrome_shin,
            parts.chrome_arm,
        )
    } else {
        (parts.torso, parts.head, parts.thigh, parts.shin, parts.arm)
    };
    let times = key_times(
        ROBOTS_DURATION_SECONDS,
        KEYS_PER_CYCLE * (ROBOTS_DURATION_SECONDS / STEP_CYCLE_SECONDS) as u32,
    );
    let phase_at = |t: f32, offset: f32| t / STEP_CYCLE_SECONDS + spec.phase + offset;
    let name = spec.name;
    let mut channels = Vec::new();
    let mut children = Vec::new();
    // A coloured chest plate shows which robot is which.
    let plate = scene.add_simple_mesh(
        &format!("{name}Plate"),
        cuboid(Vec3::new(0.3, 0.25, 0.04))
            .translated(Vec3::new(0.0, HIP_Y + 0.45, 0.16))
            .without_uvs(),
        robot_colour,
    );
    children.push(scene.add_node(Node::new(&format!("{name}Plate")).with_mesh(plate)));
    children.push(scene.add_node(Node::new(&format!("{name}Head")).with_mesh(head)));
    for (side_name, side, offset) in [("L", -1.0f32, 0.0f32), ("R", 1.0, 0.5)] {
        let knee = scene.add_node(
            Node::new(&format!("{name}Knee{side_name}"))
                .with_mesh(shin)
                .with_translation(-Vec3::Y * THIGH),
        );
        let hip = scene.add_node(
            Node::new(&format!("{name}Hip{side_name}"))
                .with_mesh(thigh)
                .with_translation(Vec3::new(side * 0.13, HIP_Y, 0.0))
                .with_children([knee]),
        );
        let shoulder = scene.add_node(
            Node::new(&format!("{name}Shoulder{side_name}"))
                .with_mesh(arm)
                .with_translation(Vec3::new(side * 0.31, SHOULDER_Y, 0.0)),
        );
        children.extend([hip, shoulder]);
        // Rotation about -X swings a limb hanging down -Y toward +Z (forward).
        let pose: Vec<_> = times
            .iter()
            .map(|&t| walk_pose(phase_at(t, offset)))
            .collect();
        for (node, angles) in [
            (hip, pose.iter().map(|p| -p.0).collect::<Vec<_>>()),
            (knee, pose.iter().map(|p| p.1).collect()),
            (shoulder, pose.iter().map(|p| -p.2).collect()),
        ] {
            channels.push(Channel::rotation(
                node,
                Interpolation::Linear,
                times.clone(),
                &rotations_about(Vec3::X, angles),
            ));
        }
    }
    let root = scene.add_node(
        Node::new(name)
            .with_mesh(torso)
            .with_translation(spec.start)
            .with_rotation(Quat::from_rotation_y(if spec.facing > 0.0 {
                0.0
            } else {
                PI
            }))
            .with_children(children),
    );
    let positions: Vec<Vec3> = times
        .iter()
        .map(|&t| {
            let bob = walk_pose(phase_at(t, 0.0)).3;
            spec.start + Vec3::new(0.0, bob, spec.facing * spec.speed * t)
        })
        .collect();
    channels.push(Channel::translation(
        root,
        Interpolation::Linear,
        times,
        &positions,
    ));
    channels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feet_stay_above_the_ground_and_knees_only_bend_backward() {
        for i in 0..64 {
            let (hip, knee, _, bob) = walk_pose(i as f32 / 64.0);
            assert!(knee >= 0.0);
            // Ankle height: hip height + bob - thigh and shin projected on Y.
            let ankle = HIP_Y + bob - THIGH * hip.cos() - SHIN * (hip - knee).cos();
            assert!(ankle > -0.05, "phase {i}/64: ankle at {ankle}");
        }
    }

    #[test]
    fn robots_stay_on_the_street_in_view_range() {
        for spec in &ROBOTS {
            let end = spec.start.z + spec.facing * spec.speed * ROBOTS_DURATION_SECONDS;
            assert!(
                end < 4.0 && end > STREET_Z.0 + 10.0,
                "{} ends at {end}",
                spec.name
            );
            assert!(spec.start.x.abs() < 6.5);
        }
    }
}
