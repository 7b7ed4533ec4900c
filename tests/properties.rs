//! Property tests (proptest) over random triangles, transforms and animations:
//! - a rigid motion keeps `log2 P_b`; a uniform scale `s` shifts it by `log2 s`;
//! - a refitted BVH finds the same closest hits, bit for bit, as a fresh build;
//! - a sequence renders each frame bit-identical to that frame rendered alone.

use glam::{Quat, Vec2, Vec3, Vec3A};
use mipray::accel::Accel;
use mipray::frame::Renderer;
use mipray::geometry::FrameTriangles;
use mipray::lod::LodMethod;
use mipray::lod::{PixelFootprint, log2_pb};
use mipray::scene::{AnimationDesc, ChannelDesc, ChannelTarget, Interpolation};
use proptest::prelude::*;

mod common;

fn vec3(range: f32) -> impl Strategy<Value = Vec3> {
    (-range..range, -range..range, -range..range).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn uv() -> impl Strategy<Value = Vec2> {
    (-4.0f32..4.0, -4.0f32..4.0).prop_map(|(u, v)| Vec2::new(u, v))
}

/// A triangle whose area is not tiny against its edges (so f32 rounding of moved
/// vertices changes its area by a small relative amount).
fn triangle() -> impl Strategy<Value = [Vec3; 3]> {
    (vec3(10.0), vec3(10.0), vec3(10.0))
        .prop_filter("well-shaped", |(a, b, c)| {
            let area = (*b - *a).cross(*c - *a).length();
            let longest = (*b - *a)
                .length()
                .max((*c - *a).length())
                .max((*c - *b).length());
            area > 0.05 * longest * longest && longest > 0.1
        })
        .prop_map(|(a, b, c)| [a, b, c])
}

fn uvs() -> impl Strategy<Value = [Vec2; 3]> {
    (uv(), uv(), uv())
        .prop_filter("non-zero UV area", |(a, b, c)| {
            (*b - *a).perp_dot(*c - *a).abs() > 0.05
        })
        .prop_map(|(a, b, c)| [a, b, c])
}

fn rotation() -> impl Strategy<Value = Quat> {
    (vec3(1.0), -3.2f32..3.2).prop_filter_map("an axis", |(axis, angle)| {
        axis.try_normalize()
            .map(|a| Quat::from_axis_angle(a, angle))
    })
}

fn pb(p: [Vec3; 3], uv: [Vec2; 3]) -> f32 {
    log2_pb(
        p.map(Vec3A::from),
        uv,
        (256, 128),
        PixelFootprint::new(0.8, 360),
    )
}

proptest! {
    #[test]
    fn rigid_motion_keeps_log2_pb(
        p in triangle(), uv in uvs(), r in rotation(), t in vec3(100.0),
    ) {
        let moved = p.map(|v| r * v + t);
        // f32 vertices after a rotation and translation: relative error ~1e-6 per
        // coordinate at |t| = 100 against edges >= 0.1; 1e-2 levels is a 0.7% area change.
        prop_assert!((pb(moved, uv) - pb(p, uv)).abs() < 1e-2,
            "{} vs {}", pb(moved, uv), pb(p, uv));
    }

    #[test]
    fn uniform_scale_shifts_log2_pb_by_log2_s(
        p in triangle(), uv in uvs(), s in 0.01f32..100.0,
    ) {
        let scaled = p.map(|v| v * s);
        let shift = pb(scaled, uv) - pb(p, uv);
        prop_assert!((shift - s.log2()).abs() < 1e-3, "shift {shift}, log2 s {}", s.log2());
    }
}

/// `n` triangles' worth of attributes around `positions` (material 0, untextured).
fn frame_triangles(positions: Vec<[Vec3; 3]>) -> FrameTriangles {
    let n = positions.len();
    FrameTriangles {
        positions: positions.into_iter().map(|t| t.map(Vec3A::from)).collect(),
        normals: vec![[Vec3::Z; 3]; n],
        uvs: vec![[Vec2::ZERO; 3]; n],
        material: vec![0; n],
        log2_pb: vec![0.0; n],
        source: (0..n as u32).collect(),
    }
}

/// (source triangle, t bits, barycentric bits) of the closest hit.
type HitKey = Option<(u32, u32, [u32; 2])>;

fn closest(accel: &Accel, triangles: &FrameTriangles, origin: Vec3, dir: Vec3) -> HitKey {
    accel
        .closest_hit(origin.into(), dir.into(), f32::INFINITY)
        .map(|h| {
            (
                triangles.source[h.triangle as usize],
                h.t.to_bits(),
                h.bary.to_array().map(f32::to_bits),
            )
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn refit_finds_the_same_hits_as_a_fresh_build(
        before in prop::collection::vec(triangle(), 2..60),
        offsets in prop::collection::vec(vec3(3.0), 60),
        rays in prop::collection::vec((vec3(12.0), vec3(1.0)), 64),
    ) {
        let mut triangles = frame_triangles(before);
        let mut accel = Accel::build(&mut triangles).unwrap();
        // Move every triangle by its own offset (in BVH slot order), then refit all.
        let moved: Vec<[Vec3A; 3]> = accel
            .triangles_in_slot_order()
            .iter()
            .enumerate()
            .map(|(slot, tri)| {
                let offset = Vec3A::from(offsets[slot % offsets.len()]);
                tri.map(|v| v + offset)
            })
            .collect();
        for (slot, tri) in moved.iter().enumerate() {
            accel.set_triangle(slot as u32, tri);
        }
        let slots: Vec<u32> = (0..triangles.len() as u32).collect();
        accel.refit(&slots);
        let mut fresh_triangles = triangles.clone();
        fresh_triangles.positions = moved;
        let fresh = Accel::build(&mut fresh_triangles).unwrap();
        for (origin, dir) in rays {
            let Some(dir) = dir.try_normalize() else { continue };
            prop_assert_eq!(
                closest(&accel, &triangles, origin, dir),
                closest(&fresh, &fresh_triangles, origin, dir)
            );
        }
    }
}

/// The facing quad with random translation, rotation and scale keys at t = 0, 0.5, 1.
fn animated_quad(keys: &[(Vec3, Quat, f32)]) -> mipray::scene::SceneDesc {
    let mut scene = common::scenes::facing_quad_scene(3.0, 2.0, 64, 0.8);
    let node = scene.roots[0];
    let times = vec![0.0, 0.5, 1.0];
    let channel = |target, values: Vec<f32>, components| ChannelDesc {
        node,
        target,
        interpolation: Interpolation::Linear,
        times: times.clone(),
        values,
        components,
    };
    let base = Vec3::new(0.0, 0.0, -3.0);
    scene.animations.push(AnimationDesc {
        name: "random".into(),
        channels: vec![
            channel(
                ChannelTarget::Translation,
                keys.iter().flat_map(|k| (base + k.0).to_array()).collect(),
                3,
            ),
            channel(
                ChannelTarget::Rotation,
                keys.iter().flat_map(|k| k.1.to_array()).collect(),
                4,
            ),
            channel(
                ChannelTarget::Scale,
                keys.iter().flat_map(|k| [k.2; 3]).collect(),
                3,
            ),
        ],
    });
    scene
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn a_sequence_renders_each_frame_as_it_renders_alone(
        keys in prop::collection::vec((vec3(0.5), rotation(), 0.2f32..2.0), 3),
        method in prop::sample::select(LodMethod::ALL.to_vec()),
    ) {
        let settings = || common::scenes::settings(16, 12, method);
        let mut sequence = Renderer::new(animated_quad(&keys), settings());
        for frame in 0..5u32 {
            let t = frame as f32 / 4.0;
            let (in_sequence, _) = sequence.render_frame(frame, t).unwrap();
            let mut alone = Renderer::new(animated_quad(&keys), settings());
            let (by_itself, _) = alone.render_frame(frame, t).unwrap();
            let bits = |img: &mipray::render::LinearImage| -> Vec<[u32; 3]> {
                img.pixels.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
            };
            prop_assert!(bits(&in_sequence) == bits(&by_itself), "frame {frame}, {method}");
        }
    }
}
