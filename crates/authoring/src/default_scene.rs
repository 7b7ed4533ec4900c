//! The default animation, `animations/default.gltf`: a checkered floor receding to the
//! horizon (the classic minification-aliasing case for MIP level selection), a brick box
//! orbiting and spinning in front of the camera, a framed mirror that reflects the floor
//! and the box, a glass sphere that refracts them, two point lights and one camera.
//!
//! Layout (metres; +Y up, the camera looks toward -Z):
//! - camera at (0, 1.6, 4), pitched 6 degrees down, yfov 50 degrees, aspect 16:9: the
//!   horizon sits 6 degrees above the image centre and the floor reaches up to it;
//! - floor: 400 m x 400 m at y = 0 spanning z in [-390, 10], a 512 px checker of 8 x 8
//!   squares repeated 50 times per side (1 m squares), REPEAT wrap;
//! - `TexturedBox`: a 1 m brick cube tilted 20 degrees, orbiting (0, 1, -3.5) on a 2 m x
//!   1.2 m ellipse with a small bob while turning once about +Y: node animation of
//!   translation and rotation, LINEAR, 17 keys over exactly 1.6 s, last key = first key
//!   (rotation negated, the same orientation), so 48 frames at 30 fps loop seamlessly;
//! - `Mirror`: a 2.4 m x 1.6 m mirror (metallic 1, roughness 0) in a wooden frame standing
//!   at (3.6, 0, -6), turned -37 degrees about +Y so it faces halfway between the camera
//!   and the box's orbit: it shows the floor and the box at every key;
//! - `GlassSphere`: radius 0.7 m resting on the floor at (-1.2, 0.7, -0.2), transmission 1,
//!   ior 1.5; around t = 1.2 s the box passes behind it as seen from the camera;
//! - lights (illuminance `E = I cos(theta) / d^2`, no range): `KeyLight`, 150 cd at
//!   (-3, 5, 2), 5-8 m from the objects, gives them and the near floor 1.5-3.7 lux;
//!   `SkyLight`, 200 000 cd high above the floor at (0, 300, -150), gives the whole floor
//!   1.1-2.2 lux (1.6 near the camera, 1.1 at the far edge), so the distant checker,
//!   where aliasing shows, is lit about as well as the near one. With a Lambertian
//!   `albedo / pi` BRDF the near light squares leave about 0.5-1 radiance units.

use std::f32::consts::TAU;
use std::path::{Path, PathBuf};

use glam::{Quat, Vec2, Vec3};

use super::animation::{Animation, Channel, Interpolation};
use super::builder::GltfBuilder;
use super::error::AuthoringError;
use super::handles::NodeId;
use super::material::{Material, TextureBinding, WrapMode};
use super::node::{Node, PerspectiveCamera, PointLight};
use super::shapes::{cuboid, plane, quad, uv_sphere};
use super::textures::{BrickPattern, brick, checkerboard};

/// File name (without extension) of the default animation.
pub const DEFAULT_SCENE_NAME: &str = "default";

/// Length of the default animation in seconds: 48 frames at 30 fps.
pub const DEFAULT_DURATION_SECONDS: f32 = 1.6;

/// Keyframe intervals of the box animation over [`DEFAULT_DURATION_SECONDS`].
const KEY_INTERVALS: u32 = 16;

/// The camera's position: eye height 1.6 m.
const CAMERA_EYE: Vec3 = Vec3::new(0.0, 1.6, 4.0);
/// Downward tilt of the camera.
const CAMERA_PITCH_DEGREES: f32 = 6.0;
/// Centre of the box's orbit.
const ORBIT_CENTRE: Vec3 = Vec3::new(0.0, 1.0, -3.5);
/// Radius of the glass sphere.
const SPHERE_RADIUS: f32 = 0.7;
/// Centre of the glass sphere, which rests on the floor.
const SPHERE_CENTRE: Vec3 = Vec3::new(-1.2, SPHERE_RADIUS, -0.2);
/// Foot of the mirror stand (the mirror's node origin).
const MIRROR_POSITION: Vec3 = Vec3::new(3.6, 0.0, -6.0);
/// Turn of the mirror about +Y, so it faces between the camera and the orbit.
const MIRROR_YAW_DEGREES: f32 = -37.0;
/// Height of the mirror glass's centre above its foot.
const MIRROR_CENTRE_Y: f32 = 1.1;

/// The default animation as a builder (see the module documentation for its layout).
pub fn default_scene() -> GltfBuilder {
    let mut scene = GltfBuilder::new();
    add_floor(&mut scene);
    let box_node = add_textured_box(&mut scene);
    add_mirror(&mut scene);
    add_glass_sphere(&mut scene);
    add_lights(&mut scene);
    add_camera(&mut scene);
    scene.add_animation(box_animation(box_node));
    scene
}

/// Writes `default.gltf`, `default.bin` and its PNGs into `dir`; returns their paths.
///
/// # Errors
/// [`AuthoringError::Io`] if `dir` cannot be created or a file cannot be written.
pub fn write_default(dir: &Path) -> Result<Vec<PathBuf>, AuthoringError> {
    default_scene().write(dir, DEFAULT_SCENE_NAME)
}

/// The 400 m checkered floor, its far edge 394 m from the camera.
fn add_floor(scene: &mut GltfBuilder) {
    const SIZE: f32 = 400.0;
    const TILE_METRES: f32 = 8.0; // one texture repeat = 8 x 8 squares of 1 m
    let checker = scene.add_image(
        "floor_checker",
        checkerboard(512, 8, [210, 210, 210, 255], [30, 30, 30, 255]),
    );
    let material = scene.add_material(Material::textured(
        "Floor",
        TextureBinding::new(checker, WrapMode::Repeat),
    ));
    let mesh = scene.add_simple_mesh(
        "Floor",
        plane(SIZE, SIZE, Vec2::splat(SIZE / TILE_METRES)),
        material,
    );
    scene.add_node(
        Node::new("Floor")
            .with_mesh(mesh)
            .with_translation(Vec3::new(0.0, 0.0, 10.0 - SIZE / 2.0)),
    );
}

/// The animated 1 m brick cube; its rest pose is the animation's first key.
fn add_textured_box(scene: &mut GltfBuilder) -> NodeId {
    let bricks = scene.add_image("box_brick", brick(256, &BrickPattern::default()));
    let material = scene.add_material(Material {
        roughness: 0.8,
        ..Material::textured("Brick", TextureBinding::new(bricks, WrapMode::Repeat))
    });
    let mesh = scene.add_simple_mesh("TexturedBox", cuboid(Vec3::ONE), material);
    scene.add_node(
        Node::new("TexturedBox")
            .with_mesh(mesh)
            .with_translation(box_translation(0))
            .with_rotation(box_rotation(0)),
    )
}

/// Box position at key `i`: a 2 m x 1.2 m ellipse around [`ORBIT_CENTRE`], nearest the
/// camera at i = 0, bobbing 0.2 m twice per loop.
fn box_translation(i: u32) -> Vec3 {
    let angle = TAU * (i % KEY_INTERVALS) as f32 / KEY_INTERVALS as f32;
    ORBIT_CENTRE
        + Vec3::new(
            2.0 * angle.sin(),
            0.2 * (2.0 * angle).sin(),
            1.2 * angle.cos(),
        )
}

/// Box orientation at key `i`: tilted 20 degrees about X, turned `i / 16` of a full turn
/// about +Y. Key 16 is key 0 negated (the same orientation; consecutive keys stay in the
/// same hemisphere, so slerp takes the short way).
fn box_rotation(i: u32) -> Quat {
    let angle = TAU * i as f32 / KEY_INTERVALS as f32;
    let tilt = Quat::from_rotation_x(20f32.to_radians());
    if i == KEY_INTERVALS {
        return -(tilt.normalize());
    }
    (Quat::from_rotation_y(angle) * tilt).normalize()
}

/// Translation and rotation of the box, LINEAR, keys every 0.1 s from 0 to 1.6 s.
fn box_animation(node: NodeId) -> Animation {
    let keys = 0..=KEY_INTERVALS;
    let times: Vec<f32> = keys
        .clone()
        .map(|i| i as f32 * DEFAULT_DURATION_SECONDS / KEY_INTERVALS as f32)
        .collect();
    let translations: Vec<Vec3> = keys.clone().map(box_translation).collect();
    let rotations: Vec<Quat> = keys.map(box_rotation).collect();
    Animation {
        name: "BoxOrbit".into(),
        channels: vec![
            Channel::translation(node, Interpolation::Linear, times.clone(), &translations),
            Channel::rotation(node, Interpolation::Linear, times, &rotations),
        ],
    }
}

/// A 2.4 m x 1.6 m mirror in a wooden frame whose side posts stand on the floor; one bar
/// mesh serves the four frame bars and the back panel.
fn add_mirror(scene: &mut GltfBuilder) {
    const WIDTH: f32 = 2.4;
    const HEIGHT: f32 = 1.6;
    const BAR: f32 = 0.08;
    const DEPTH: f32 = 0.06;
    let glass = scene.add_material(Material::mirror("Mirror", Vec3::splat(0.95)));
    let wood = scene.add_material(Material {
        roughness: 0.6,
        ..Material::matte("MirrorFrame", Vec3::new(0.30, 0.18, 0.09))
    });
    let glass_mesh = scene.add_simple_mesh(
        "MirrorGlass",
        quad(WIDTH, HEIGHT, Vec2::ONE).without_uvs(),
        glass,
    );
    let bar_mesh = scene.add_simple_mesh("FrameBar", cuboid(Vec3::ONE).without_uvs(), wood);
    let glass_node = scene.add_node(
        Node::new("MirrorGlass")
            .with_mesh(glass_mesh)
            .with_translation(Vec3::new(0.0, MIRROR_CENTRE_Y, 0.0)),
    );
    let post_height = MIRROR_CENTRE_Y + HEIGHT / 2.0 + BAR;
    let bar_x = WIDTH / 2.0 + BAR / 2.0;
    let bars = [
        (
            "MirrorFrameTop",
            Vec3::new(0.0, post_height - BAR / 2.0, 0.0),
            Vec3::new(WIDTH + 2.0 * BAR, BAR, DEPTH),
        ),
        (
            "MirrorFrameBottom",
            Vec3::new(0.0, MIRROR_CENTRE_Y - HEIGHT / 2.0 - BAR / 2.0, 0.0),
            Vec3::new(WIDTH + 2.0 * BAR, BAR, DEPTH),
        ),
        (
            "MirrorFrameLeft",
            Vec3::new(-bar_x, post_height / 2.0, 0.0),
            Vec3::new(BAR, post_height, DEPTH),
        ),
        (
            "MirrorFrameRight",
            Vec3::new(bar_x, post_height / 2.0, 0.0),
            Vec3::new(BAR, post_height, DEPTH),
        ),
        (
            "MirrorBack",
            Vec3::new(0.0, MIRROR_CENTRE_Y, -0.015),
            Vec3::new(WIDTH, HEIGHT, 0.02),
        ),
    ];
    let mut children = vec![glass_node];
    for (name, translation, scale) in bars {
        children.push(
            scene.add_node(
                Node::new(name)
                    .with_mesh(bar_mesh)
                    .with_translation(translation)
                    .with_scale(scale),
            ),
        );
    }
    scene.add_node(
        Node::new("Mirror")
            .with_translation(MIRROR_POSITION)
            .with_rotation(Quat::from_rotation_y(MIRROR_YAW_DEGREES.to_radians()))
            .with_children(children),
    );
}

/// A clear glass ball resting on the floor between the camera and the box's orbit.
fn add_glass_sphere(scene: &mut GltfBuilder) {
    let glass = scene.add_material(Material::glass("Glass", 1.5));
    let mesh = scene.add_simple_mesh(
        "GlassSphere",
        uv_sphere(SPHERE_RADIUS, 32, 16).without_uvs(),
        glass,
    );
    scene.add_node(
        Node::new("GlassSphere")
            .with_mesh(mesh)
            .with_translation(SPHERE_CENTRE),
    );
}

/// A warm key light near the objects and a cool, strong light high above the far floor.
fn add_lights(scene: &mut GltfBuilder) {
    let key = scene.add_point_light(PointLight {
        name: "KeyLight".into(),
        color: Vec3::new(1.0, 0.95, 0.88),
        intensity: 150.0,
        range: None,
    });
    let sky = scene.add_point_light(PointLight {
        name: "SkyLight".into(),
        color: Vec3::new(0.9, 0.95, 1.0),
        intensity: 200_000.0,
        range: None,
    });
    scene.add_node(
        Node::new("KeyLight")
            .with_light(key)
            .with_translation(Vec3::new(-3.0, 5.0, 2.0)),
    );
    scene.add_node(
        Node::new("SkyLight")
            .with_light(sky)
            .with_translation(Vec3::new(0.0, 300.0, -150.0)),
    );
}

/// Eye height 1.6 m, 6 degrees down: the horizon sits 6 degrees above the image centre.
fn add_camera(scene: &mut GltfBuilder) {
    let camera = scene.add_camera(PerspectiveCamera {
        name: "Camera".into(),
        yfov: 50f32.to_radians(),
        aspect_ratio: Some(16.0 / 9.0),
        znear: 0.05,
        zfar: Some(1000.0),
    });
    scene.add_node(
        Node::new("Camera")
            .with_camera(camera)
            .with_translation(CAMERA_EYE)
            .with_rotation(Quat::from_rotation_x(-CAMERA_PITCH_DEGREES.to_radians())),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_animation_loops_and_lasts_exactly_the_duration() {
        let animation = box_animation(NodeId(0));
        assert_eq!(animation.duration(), 1.6);
        let [translation, rotation] = [&animation.channels[0], &animation.channels[1]];
        assert_eq!(translation.times.len(), 17);
        assert_eq!(translation.values[..3], translation.values[48..]);
        let first = Quat::from_slice(&rotation.values[..4]);
        let last = Quat::from_slice(&rotation.values[64..]);
        assert!(
            first.dot(last) < -0.999_999,
            "same orientation, opposite sign"
        );
        for pair in rotation.values.chunks(4).collect::<Vec<_>>().windows(2) {
            let dot = Quat::from_slice(pair[0]).dot(Quat::from_slice(pair[1]));
            assert!(dot > 0.9, "consecutive keys in one hemisphere");
        }
    }

    #[test]
    fn box_never_dips_into_the_floor_or_hits_the_sphere() {
        for i in 0..=KEY_INTERVALS {
            let p = box_translation(i);
            // Half the height of a unit cube tilted 20 degrees about X.
            let half_height = 0.5 * (20f32.to_radians().cos() + 20f32.to_radians().sin());
            assert!(p.y - half_height > 0.1, "key {i} at {p}");
            let to_sphere = p - SPHERE_CENTRE;
            assert!(to_sphere.length() > SPHERE_RADIUS + 0.87 + 0.5, "key {i}");
        }
    }

    /// The camera node's world-from-camera transform and its camera, from the builder.
    fn camera(scene: &GltfBuilder) -> (glam::Mat4, PerspectiveCamera) {
        let node = scene.nodes.iter().find(|n| n.camera.is_some()).unwrap();
        let world_from_camera =
            glam::Mat4::from_rotation_translation(node.rotation, node.translation);
        (world_from_camera, scene.cameras[0].clone())
    }

    /// Normalized image coordinates of a world point, in [-1, 1] when in view.
    fn project(scene: &GltfBuilder, world: Vec3) -> Vec2 {
        let (world_from_camera, camera) = camera(scene);
        let p = world_from_camera.inverse().transform_point3(world);
        assert!(p.z < 0.0, "{world} is behind the camera");
        let half_height = (camera.yfov / 2.0).tan();
        let half_width = half_height * camera.aspect_ratio.unwrap();
        Vec2::new(p.x / -p.z / half_width, p.y / -p.z / half_height)
    }

    #[test]
    fn box_sphere_and_mirror_are_in_view() {
        let scene = default_scene();
        let in_view = |p: Vec3| project(&scene, p).abs().max_element() < 0.9;
        for i in 0..=KEY_INTERVALS {
            assert!(in_view(box_translation(i)), "box key {i}");
        }
        assert!(in_view(SPHERE_CENTRE), "sphere");
        assert!(
            in_view(MIRROR_POSITION + MIRROR_CENTRE_Y * Vec3::Y),
            "mirror"
        );
        // The horizon (a far point at eye height) is above the centre, the floor below.
        let horizon = project(&scene, Vec3::new(0.0, 1.6, -1.0e5));
        assert!(horizon.y > 0.1 && horizon.y < 0.5, "horizon at {horizon}");
        let far_floor = project(&scene, Vec3::new(0.0, 0.0, -389.0));
        assert!(
            horizon.y - far_floor.y < 0.01,
            "floor reaches near the horizon"
        );
    }

    #[test]
    fn mirror_shows_the_box_to_the_camera() {
        let scene = default_scene();
        let mirror = scene.nodes.iter().find(|n| n.name == "Mirror").unwrap();
        let centre = mirror.translation + MIRROR_CENTRE_Y * Vec3::Y;
        let normal = mirror.rotation * Vec3::Z;
        let (world_from_camera, _) = camera(&scene);
        let eye = world_from_camera.transform_point3(Vec3::ZERO);
        assert!(
            (eye - centre).dot(normal) > 0.0,
            "camera sees the mirror's front"
        );
        let mirrored_eye = eye - 2.0 * (eye - centre).dot(normal) * normal;
        let mut reflected_keys = 0;
        for i in 0..=KEY_INTERVALS {
            let target = box_translation(i);
            assert!(
                (target - centre).dot(normal) > 0.0,
                "box in front of the mirror"
            );
            // Where the line from the mirrored eye to the box crosses the mirror plane.
            let d = target - mirrored_eye;
            let t = (centre - mirrored_eye).dot(normal) / d.dot(normal);
            let local = mirror.rotation.inverse() * (mirrored_eye + t * d - centre);
            if local.x.abs() < 1.2 && local.y.abs() < 0.8 {
                reflected_keys += 1;
            }
        }
        assert_eq!(
            reflected_keys,
            KEY_INTERVALS + 1,
            "box seen in the mirror at every key"
        );
    }

    #[test]
    fn default_scene_validates() {
        default_scene().validate().unwrap();
    }
}
