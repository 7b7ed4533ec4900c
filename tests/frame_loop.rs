//! The dynamic frame loop against its full-recompute reference: dirty-only `log2 P_b`
//! updates, refitted BVH hits, statelessness.

mod common;
#[path = "../benches/common/generated.rs"]
mod generated;

use common::scenes::*;
use glam::Vec3A;
use mipray::accel::Accel;
use mipray::frame::{BvhLayout, BvhPolicy, RenderSettings, Renderer, UpdateParallelism};
use mipray::lod::{
    PixelFootprint, log2_pb, log2_pb_with_texel_term, texel_area, texel_term, uv_area,
};

const FRAMES: u32 = 30;
const FPS: f32 = 30.0;

fn settings(bvh: BvhPolicy) -> RenderSettings {
    RenderSettings {
        width: 64,
        height: 48,
        bvh,
        ..Default::default()
    }
}

/// `log2 P_b` by source triangle (NaN for those without a slot: the instances of shared
/// meshes under the two-level BVH).
fn by_source(r: &Renderer) -> Vec<f32> {
    let t = r.triangles();
    let mut out = vec![f32::NAN; r.geometry().triangle_count()];
    for (slot, &source) in t.source.iter().enumerate() {
        out[source as usize] = t.log2_pb[slot];
    }
    out
}

/// The dynamic scene plus a textured skinned strip bending over the first second.
fn skinned_dynamic_scene() -> mipray::scene::SceneDesc {
    let (mut scene, _) = dynamic_scene();
    merge_textured(
        &mut scene,
        common::deform_scenes::skinned_strip_scene(1.3),
        0,
        glam::Vec3::new(-1.0, 1.5, -3.0),
    );
    scene
}

#[test]
fn dirty_only_update_equals_a_full_recompute_bit_for_bit() {
    let scene = skinned_dynamic_scene();
    let policy = BvhPolicy::Refit {
        rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
    };
    let mut sequential = Renderer::new(scene, settings(policy));
    for frame in 0..FRAMES {
        let time = frame as f32 / FPS;
        let update = sequential.prepare(frame, time).unwrap().update;
        let mut fresh = Renderer::new(skinned_dynamic_scene(), settings(policy));
        fresh.prepare(frame, time).unwrap();
        let (ts, tf) = (sequential.triangles(), fresh.triangles());
        let (ps, pf) = (sequential.world_positions(), fresh.world_positions());
        for (slot, &source) in ts.source.iter().enumerate() {
            let other = tf.source.iter().position(|&s| s == source).unwrap();
            let bits = |p: [Vec3A; 3]| p.map(|v| v.to_array().map(f32::to_bits));
            assert_eq!(
                bits(ps[slot]),
                bits(pf[other]),
                "frame {frame}, triangle {source} vertices"
            );
            // Shading normals too: the skinned strip's are read from the posed vertices,
            // which must be this frame's wherever its slots are.
            let normal_bits = |n: [glam::Vec3; 3]| n.map(|v| v.to_array().map(f32::to_bits));
            assert_eq!(
                normal_bits(sequential.slot_normals(slot)),
                normal_bits(fresh.slot_normals(other)),
                "frame {frame}, triangle {source} normals"
            );
        }
        let (a, b) = (by_source(&sequential), by_source(&fresh));
        for (source, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(
                x.to_bits() == y.to_bits(),
                "frame {frame}, triangle {source}: dirty-only {x} vs full {y}"
            );
        }
        if frame > 0 {
            // Rigid motions never recompute; the stretched card (2 triangles) and the bent
            // part of the strip (the 6 of its 8 triangles with a vertex weighted to joint 1)
            // are deformed and recomputed; the growing card (2 triangles) is shifted by log2 s.
            assert_eq!(update.deformed_triangles, 2 + 6, "frame {frame}");
            assert_eq!(update.lod_recomputed, 2 + 6, "frame {frame}");
            assert_eq!(update.lod_shifted, 2, "frame {frame}");
        }
    }
}

/// Slots store shading normals only for instances that do not deform: a scene where every
/// instance deforms keeps none (the array is empty), a mixed one keeps one entry per slot;
/// either way the normals shading reads are those of the posed vertices, under every
/// tree policy and after a rebuild.
#[test]
fn only_slots_of_undeformed_instances_store_normals() {
    let policy = BvhPolicy::Refit {
        rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
    };
    let mut skinned = Renderer::new(
        common::deform_scenes::skinned_strip_scene(1.3),
        settings(policy),
    );
    let mut mixed = Renderer::new(skinned_dynamic_scene(), settings(policy));
    for frame in [0, 3, 7] {
        let time = frame as f32 / FPS;
        skinned.prepare(frame, time).unwrap();
        mixed.prepare(frame, time).unwrap();
        assert!(skinned.triangles().normals.is_empty(), "frame {frame}");
        assert_eq!(
            mixed.triangles().normals.len(),
            mixed.triangles().len(),
            "frame {frame}"
        );
        for r in [&skinned, &mixed] {
            for slot in 0..r.triangles().len() {
                let n = r.slot_normals(slot);
                assert!(
                    n.iter().all(|v| (v.length() - 1.0).abs() < 1e-5),
                    "frame {frame}, slot {slot}: {n:?}"
                );
            }
        }
    }
    // Rebuilt every frame: the same normals as refitted.
    let mut rebuilt = Renderer::new(skinned_dynamic_scene(), settings(BvhPolicy::Rebuild));
    rebuilt.prepare(7, 7.0 / FPS).unwrap();
    let by_source = |r: &Renderer| {
        let mut out: Vec<_> = (0..r.triangles().len())
            .map(|s| {
                let n = r.slot_normals(s).map(|v| v.to_array().map(f32::to_bits));
                (r.triangles().source[s], n)
            })
            .collect();
        out.sort();
        out
    };
    assert_eq!(by_source(&rebuilt), by_source(&mixed));
}

/// Copies of one mesh stretched alike share their `log2 P_b` constants (computed once for
/// the group): each copy's must equal what it gets rendered alone, where it has no group,
/// whether it is turned or not; a copy stretched differently keeps its own.
#[test]
fn copies_stretched_alike_get_the_constants_each_gets_alone() {
    use mipray::scene::{
        ChannelDesc, ChannelTarget, Interpolation, MeshDesc, NodeDesc, SceneDesc, Trs,
    };
    // (translation, turn about z, stretch at t = 1)
    let copies = [
        (glam::Vec3::new(-3.0, 0.0, -8.0), 0.0, [1.5, 0.8, 1.0]),
        (glam::Vec3::new(-1.0, 0.0, -8.0), 0.0, [1.5, 0.8, 1.0]),
        (glam::Vec3::new(1.0, 0.0, -8.0), 0.7, [1.5, 0.8, 1.0]),
        (glam::Vec3::new(3.0, 0.0, -8.0), 0.0, [0.6, 1.9, 1.0]),
        (glam::Vec3::new(0.0, 2.0, -8.0), 0.0, [0.6, 1.9, 1.0]),
    ];
    let scene_of = |which: &[usize]| -> SceneDesc {
        let mut scene = generated::textured_scene();
        scene.meshes.push(MeshDesc {
            name: "patch".into(),
            primitives: vec![generated::patch(4, 3, 1.0, 1.0)],
            ..Default::default()
        });
        for &c in which {
            let (translation, turn, stretch) = copies[c];
            scene.nodes.push(NodeDesc {
                local: Trs {
                    translation,
                    rotation: glam::Quat::from_rotation_z(turn),
                    ..Default::default()
                },
                mesh: Some(0),
                ..Default::default()
            });
            let node = scene.nodes.len() - 1;
            scene.roots.push(node);
            scene.animations[0].channels.push(ChannelDesc {
                node,
                target: ChannelTarget::Scale,
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values: [[1.0; 3], stretch].concat(),
                components: 3,
            });
        }
        generated::add_camera(&mut scene, glam::Vec3::new(0.0, 0.0, 2.0), 1.0);
        scene
    };
    // Per node (in `which` order), its triangles' constants by local triangle.
    let constants = |which: &[usize], time: f32| -> Vec<Vec<u32>> {
        let policy = BvhPolicy::Refit {
            rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
        };
        let flat = RenderSettings {
            layout: BvhLayout::Flat,
            ..settings(policy)
        };
        let mut r = Renderer::new(scene_of(which), flat);
        r.prepare(0, 0.0).unwrap();
        r.prepare(1, time).unwrap();
        assert_eq!(r.triangles().len(), r.geometry().triangle_count());
        let (g, t) = (r.geometry(), r.triangles());
        let mut out: Vec<Vec<u32>> = g
            .instance_triangles
            .iter()
            .map(|range| vec![0; range.len()])
            .collect();
        for (slot, &source) in t.source.iter().enumerate() {
            let i = g.triangle_instance[source as usize] as usize;
            let local = (source - g.instance_triangles[i].start) as usize;
            out[i][local] = t.log2_pb[slot].to_bits();
        }
        out
    };
    for time in [0.5, 1.0] {
        let all = constants(&[0, 1, 2, 3, 4], time);
        for (c, constants_in_all) in all.iter().enumerate() {
            let alone = constants(&[c], time);
            assert_eq!(constants_in_all, &alone[0], "copy {c} at {time} s");
        }
        assert_ne!(all[0], all[3], "different stretches, different constants");
        assert_eq!(
            all[0], all[2],
            "a turn does not change a stretched constant"
        );
        assert!(all[0].iter().all(|&v| v != 0), "textured: a constant each");
    }
}

/// Over 8,192 deformed triangles the `log2 P_b` update runs on several threads: every
/// value must equal the constant of the triangle's world vertices computed here, one by
/// one (the texel-term form deforming triangles get, within one f32 step of `log2_pb`),
/// and every triangle must be counted.
#[test]
fn parallel_log2_pb_update_equals_the_constant_computed_one_by_one() {
    // Every vertex lifted: all 10,368 triangles deform on every frame.
    // Rebuilt every frame, the write goes in source order and the `log2 P_b` step walks the
    // deformed slots; refitted, every slot is rewritten in slot order and the write takes
    // their constants itself.
    let lifted: Vec<u32> = (0..73 * 73).collect();
    let triangles = 2 * 72 * 72;
    let refit = BvhPolicy::Refit {
        rebuild_threshold: f32::INFINITY,
    };
    for policy in [BvhPolicy::Rebuild, refit] {
        constants_equal_those_computed_one_by_one(
            Renderer::new(morph_grid_scene(72, &lifted), settings(policy)),
            triangles,
        );
    }
}

fn constants_equal_those_computed_one_by_one(mut r: Renderer, triangles: usize) {
    // The grid's camera has yfov 0.8; frames are 48 pixels high; the checker is 64x64.
    let footprint = PixelFootprint::new(0.8, 48);
    for frame in [0, 3, 9] {
        let update = r.prepare(frame, frame as f32 / FPS).unwrap().update;
        assert_eq!(update.lod_recomputed, triangles, "frame {frame}");
        let (t, positions) = (r.triangles(), r.world_positions());
        for (slot, &p) in positions.iter().enumerate() {
            let term = texel_term(texel_area(uv_area(t.uvs[slot]), (64, 64)));
            let expected = log2_pb_with_texel_term(p, term, footprint);
            let plain = log2_pb(p, t.uvs[slot], (64, 64), footprint);
            assert!(
                (expected.to_bits() as i64 - plain.to_bits() as i64).abs() <= 1,
                "frame {frame}, slot {slot}: {expected} vs {plain}"
            );
            assert!(
                t.log2_pb[slot].to_bits() == expected.to_bits(),
                "frame {frame}, slot {slot}: updated {} vs one by one {expected}",
                t.log2_pb[slot]
            );
        }
    }
}

/// The dynamic scene (rigid, scaled and stretched cards, a rigidly moving card) plus a
/// skinned grid of 12,000 triangles whose every vertex moves and 30 patches of 288
/// triangles moving rigidly: every update step has more than 8,192 items of work, and more
/// than a sixteenth of the slots move, so `Auto` takes each parallel path.
fn large_dynamic_scene() -> mipray::scene::SceneDesc {
    let (mut scene, _) = dynamic_scene();
    let mut generated = generated::textured_scene();
    generated::add_skinned_grid(
        &mut generated,
        100,
        60,
        (4.0, 2.0),
        4,
        glam::Vec3::new(-2.0, -1.0, -9.0),
    );
    generated::add_rigid_patches(
        &mut generated,
        30,
        12,
        1.2,
        glam::Vec3::new(0.0, 0.0, -12.0),
    );
    merge_textured(&mut scene, generated, 0, glam::Vec3::ZERO);
    scene
}

/// Everything one `prepare` leaves behind, in slot order, as bits.
fn frame_bits(r: &Renderer) -> Vec<u32> {
    let t = r.triangles();
    let mut out: Vec<u32> = t.source.clone();
    out.extend(
        r.world_positions()
            .iter()
            .flatten()
            .flat_map(|v| v.to_array())
            .map(f32::to_bits),
    );
    out.extend(
        (0..t.len())
            .flat_map(|slot| r.slot_normals(slot))
            .flat_map(|v| v.to_array())
            .map(f32::to_bits),
    );
    out.extend(
        t.uvs
            .iter()
            .flatten()
            .flat_map(|v| v.to_array())
            .map(f32::to_bits),
    );
    out.extend(t.log2_pb.iter().map(|v| v.to_bits()));
    out
}

/// The parallel update (past the thresholds with `Auto`, and forced with `Parallel`) leaves
/// the same triangles, `log2 P_b`, dirty slots with the same motions (the parallel write
/// leaves a deforming instance's slots unlisted, so they are compared as `moved` lists
/// them) and the same counts as the update on one thread, on every frame, refitting and
/// rebuilding.
#[test]
fn parallel_update_equals_the_sequential_update_bit_for_bit() {
    let triangles = Renderer::new(large_dynamic_scene(), settings(BvhPolicy::Rebuild))
        .geometry()
        .triangle_count();
    assert!(triangles > 20_000, "{triangles} triangles");
    for policy in [
        BvhPolicy::Refit {
            rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
        },
        BvhPolicy::Rebuild,
    ] {
        let renderer = |parallelism| {
            let mut r = Renderer::new(large_dynamic_scene(), settings(policy));
            r.set_update_parallelism(parallelism);
            r
        };
        let mut one = renderer(UpdateParallelism::Sequential);
        let mut split = [
            renderer(UpdateParallelism::Auto),
            renderer(UpdateParallelism::Parallel),
        ];
        for frame in [0, 1, 2, 5, 6, 20, 21, 45] {
            let time = frame as f32 / FPS;
            let expected = one.prepare(frame, time).unwrap().update;
            if frame > 0 {
                assert!(
                    expected.deformed_triangles >= 12_000 && expected.moved_triangles > 20_000,
                    "frame {frame}: the skin and the patches move ({expected:?})"
                );
            }
            for r in &mut split {
                let update = r.prepare(frame, time).unwrap().update;
                let what = format!("frame {frame}, {policy:?}");
                assert_eq!(
                    r.dirty().moved(),
                    one.dirty().moved(),
                    "{what}: dirty slots"
                );
                assert!(
                    frame_bits(r) == frame_bits(&one),
                    "{what}: triangles differ"
                );
                assert_eq!(
                    (
                        update.moved_triangles,
                        update.deformed_triangles,
                        update.lod_recomputed,
                        update.lod_shifted
                    ),
                    (
                        expected.moved_triangles,
                        expected.deformed_triangles,
                        expected.lod_recomputed,
                        expected.lod_shifted
                    ),
                    "{what}"
                );
            }
        }
    }
}

/// Small scenes take the parallel path too when it is forced: the skinned strip and the
/// cards give the same frame as on one thread.
#[test]
fn forced_parallel_update_equals_the_sequential_update_on_a_small_scene() {
    let policy = BvhPolicy::Refit {
        rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
    };
    let mut one = Renderer::new(skinned_dynamic_scene(), settings(policy));
    one.set_update_parallelism(UpdateParallelism::Sequential);
    let mut split = Renderer::new(skinned_dynamic_scene(), settings(policy));
    split.set_update_parallelism(UpdateParallelism::Parallel);
    for frame in 0..FRAMES {
        let time = frame as f32 / FPS;
        one.prepare(frame, time).unwrap();
        split.prepare(frame, time).unwrap();
        assert_eq!(split.dirty().moved(), one.dirty().moved(), "frame {frame}");
        assert!(frame_bits(&split) == frame_bits(&one), "frame {frame}");
    }
}

/// A moved triangle whose vertices overflow stops the frame with an error naming it, on
/// one thread and split (the write flags it; the scan for the first one runs only then).
/// Refits only, so no rebuild runs before the frame loop's own check.
#[test]
fn overflowing_moved_vertex_stops_the_frame_on_every_path() {
    use mipray::scene::{ChannelDesc, ChannelTarget, Interpolation, MeshDesc, NodeDesc};
    let scene = || {
        let mut scene = generated::textured_scene();
        scene.meshes.push(MeshDesc {
            name: "patch".into(),
            primitives: vec![generated::patch(4, 4, 1.0, 1.0)],
            ..Default::default()
        });
        scene.nodes.push(NodeDesc {
            mesh: Some(0),
            ..Default::default()
        });
        scene.roots.push(0);
        for (target, end) in [
            (ChannelTarget::Translation, f32::MAX),
            (ChannelTarget::Scale, 1e38),
        ] {
            let start = if target == ChannelTarget::Scale {
                1.0
            } else {
                0.0
            };
            scene.animations[0].channels.push(ChannelDesc {
                node: 0,
                target,
                interpolation: Interpolation::Step,
                times: vec![0.0, 1.0],
                values: vec![start, start, start, end, end, end],
                components: 3,
            });
        }
        scene
    };
    let mut messages = Vec::new();
    let paths = [
        (UpdateParallelism::Sequential, BvhLayout::Flat),
        (UpdateParallelism::Parallel, BvhLayout::Flat),
        // The patch is an animated instance: the two-level path never writes its
        // triangles, it finds the overflow when it places the instance.
        (UpdateParallelism::Sequential, BvhLayout::TwoLevel),
    ];
    for (parallelism, layout) in paths {
        let refit = BvhPolicy::Refit {
            rebuild_threshold: f32::INFINITY,
        };
        let mut r = Renderer::new(
            scene(),
            RenderSettings {
                layout,
                ..settings(refit)
            },
        );
        r.set_update_parallelism(parallelism);
        r.prepare(0, 0.0).unwrap();
        let error = r
            .prepare(1, 1.0)
            .err()
            .expect("an overflowing vertex is an error");
        let message = error.to_string();
        // Triangles 0..4 only grow towards -x, -y and stay finite; triangle 4 is the first
        // moved one in source order with an infinite vertex. (The tree's own check, in slot
        // order, would name another one: the frame loop's check runs first.)
        assert!(
            message.starts_with("frame 1 (t = 1 s): triangle 4 has a non-finite vertex"),
            "{message}"
        );
        messages.push(message);
    }
    assert!(messages.iter().all(|m| *m == messages[0]), "{messages:?}");
}

#[test]
fn uniform_scale_shifts_log2_pb_by_log2_s() {
    let (scene, [_, grow, _]) = dynamic_scene();
    let mut r = Renderer::new(scene, settings(BvhPolicy::Rebuild));
    r.prepare(0, 0.0).unwrap();
    let grow_slots = |r: &Renderer| -> Vec<usize> {
        // The growing card's triangles are those whose world centre is nearest its node.
        let positions = r.world_positions();
        (0..positions.len())
            .filter(|&s| {
                let c = (positions[s][0] + positions[s][1] + positions[s][2]) / 3.0;
                (c - Vec3A::new(1.5, 0.5, -6.0)).length() < 0.8
            })
            .collect()
    };
    let before: Vec<(u32, f32)> = grow_slots(&r)
        .iter()
        .map(|&s| (r.triangles().source[s], r.triangles().log2_pb[s]))
        .collect();
    assert_eq!(before.len(), 2, "the growing card has two triangles");
    // At t = 0.5 the scale is 1.5.
    r.prepare(15, 0.5).unwrap();
    let footprint = PixelFootprint::new(0.9, 48);
    let t = r.triangles();
    for (source, old) in before {
        let slot = t.source.iter().position(|&s| s == source).unwrap();
        let shifted = t.log2_pb[slot];
        assert!(
            (shifted - old - 1.5f32.log2()).abs() < 1e-6,
            "{old} -> {shifted}"
        );
        let full = log2_pb(
            r.accel().triangle(slot as u32),
            t.uvs[slot],
            (128, 128),
            footprint,
        );
        assert!(
            (shifted - full).abs() < 1e-6,
            "shifted {shifted} vs recomputed {full}"
        );
    }
    let _ = grow;
}

#[test]
fn rigid_only_animation_never_recomputes_after_the_first_frame() {
    // The showcase scene moves one card by translation only.
    let mut r = Renderer::new(
        showcase_scene(),
        settings(BvhPolicy::Refit {
            rebuild_threshold: 1.5,
        }),
    );
    let first = r.prepare(0, 0.0).unwrap().update;
    assert!(first.lod_recomputed > 0);
    for frame in 1..FRAMES {
        let u = r.prepare(frame, frame as f32 / FPS).unwrap().update;
        assert_eq!(u.lod_recomputed, 0, "frame {frame}");
        assert_eq!(u.lod_shifted, 0, "frame {frame}");
        assert_eq!(
            u.moved_triangles, 2,
            "frame {frame}: the card's two triangles move"
        );
    }
    // A static scene (time frozen) moves nothing.
    let u = r.prepare(FRAMES, (FRAMES - 1) as f32 / FPS).unwrap().update;
    assert_eq!(
        (u.moved_triangles, u.lod_recomputed, u.rebuild),
        (0, 0, false)
    );
}

/// Deterministic pseudo-random rays aimed into the scene's bounds.
fn rays(count: usize) -> Vec<(Vec3A, Vec3A)> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    (0..count)
        .map(|_| {
            let origin = Vec3A::new(next() * 8.0 - 4.0, next() * 3.0 + 0.1, next() * 4.0);
            let target = Vec3A::new(next() * 8.0 - 4.0, next() * 3.0, -3.0 - next() * 6.0);
            (origin, (target - origin).normalize())
        })
        .collect()
}

#[test]
fn refitted_tree_finds_the_same_hits_as_a_fresh_build() {
    let scene = skinned_dynamic_scene();
    // Never rebuild, so every frame after the first traces a refitted tree.
    let mut r = Renderer::new(
        scene,
        settings(BvhPolicy::Refit {
            rebuild_threshold: f32::INFINITY,
        }),
    );
    let rays = rays(10_000);
    for frame in 0..FRAMES {
        let u = r.prepare(frame, frame as f32 / FPS).unwrap().update;
        assert_eq!(u.rebuild, frame == 0, "frame {frame}");
        let mut fresh_triangles = r.triangles().clone();
        fresh_triangles.positions = r.world_positions();
        let fresh = Accel::build(&mut fresh_triangles).unwrap();
        let mut hits = 0;
        for (i, &(o, d)) in rays.iter().enumerate() {
            let a = r.accel().closest_hit(o, d, f32::INFINITY);
            let b = fresh.closest_hit(o, d, f32::INFINITY);
            let a = a.map(|h| {
                (
                    r.triangles().source[h.triangle as usize],
                    h.t.to_bits(),
                    h.bary.to_array().map(f32::to_bits),
                )
            });
            let b = b.map(|h| {
                (
                    fresh_triangles.source[h.triangle as usize],
                    h.t.to_bits(),
                    h.bary.to_array().map(f32::to_bits),
                )
            });
            assert_eq!(a, b, "frame {frame}, ray {i}");
            hits += a.is_some() as usize;
        }
        assert!(hits > 5_000, "frame {frame}: only {hits} rays hit anything");
    }
}

#[test]
fn morph_recomputes_exactly_the_triangles_touching_moved_vertices() {
    let n = 6u32;
    // Vertex 0 is the corner both triangles of the first quad share (the diagonal starts
    // there); 17 (row 2, column 3) and 30 (row 4, column 2) are interior: six triangles each.
    let lifted = [0u32, 17, 30];
    let mut r = Renderer::new(
        morph_grid_scene(n, &lifted),
        settings(BvhPolicy::Refit {
            rebuild_threshold: 1.5,
        }),
    );
    r.prepare(0, 0.0).unwrap();
    let indices = r.scene().meshes[0].primitives[0].indices.clone();
    let expected: Vec<u32> = (0..indices.len() as u32 / 3)
        .filter(|t| {
            indices[*t as usize * 3..*t as usize * 3 + 3]
                .iter()
                .any(|v| lifted.contains(v))
        })
        .collect();
    assert_eq!(expected.len(), 2 + 6 + 6);
    for frame in 1..10 {
        let u = r.prepare(frame, frame as f32 / 10.0).unwrap().update;
        let (t, positions) = (r.triangles(), r.world_positions());
        let mut recomputed: Vec<u32> = (0..t.len())
            .filter(|&s| positions[s].iter().any(|p| p.z > -2.0 + 1e-6))
            .map(|s| t.source[s])
            .collect();
        recomputed.sort();
        assert_eq!(recomputed, expected, "frame {frame}: lifted triangles");
        assert_eq!(u.deformed_triangles, expected.len(), "frame {frame}");
        assert_eq!(u.lod_recomputed, expected.len(), "frame {frame}");
    }
    // Past the last key the weight holds: nothing moves.
    r.prepare(10, 1.5).unwrap();
    let u = r.prepare(11, 1.6).unwrap().update;
    assert_eq!((u.moved_triangles, u.lod_recomputed), (0, 0));
}

#[test]
fn frame_alone_equals_frame_in_sequence_with_refit_and_rebuild() {
    for policy in [
        BvhPolicy::Refit {
            rebuild_threshold: 1.5,
        },
        BvhPolicy::Rebuild,
    ] {
        let mut seq = Renderer::new(skinned_dynamic_scene(), settings(policy));
        let mut images = Vec::new();
        for frame in 0..8 {
            images.push(
                seq.render_frame(frame, frame as f32 / 8.0)
                    .unwrap()
                    .0
                    .to_srgb8(),
            );
        }
        for k in [3u32, 7] {
            let mut alone = Renderer::new(skinned_dynamic_scene(), settings(policy));
            let image = alone.render_frame(k, k as f32 / 8.0).unwrap().0.to_srgb8();
            assert!(
                image == images[k as usize],
                "{policy:?}: frame {k} alone differs from the sequence"
            );
        }
    }
}

/// An untextured skinned strip beside the textured one (both bend every frame, on one
/// thread and split): only textured deformed triangles get a recomputed `log2 P_b` and are
/// counted, each equal to what a fresh renderer computes for the frame; the untextured
/// strip's slots keep their 0.
#[test]
fn untextured_deforming_triangles_are_neither_recomputed_nor_counted() {
    let scene = || {
        let mut scene = skinned_dynamic_scene();
        let plain = scene
            .materials
            .iter()
            .position(|m| m.base_color_texture.is_none())
            .expect("an untextured material");
        merge_textured(
            &mut scene,
            common::deform_scenes::skinned_strip_scene(1.1),
            plain,
            glam::Vec3::new(1.0, 1.5, -3.0),
        );
        scene
    };
    let policy = BvhPolicy::Refit {
        rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
    };
    for parallelism in [UpdateParallelism::Sequential, UpdateParallelism::Parallel] {
        let mut r = Renderer::new(scene(), settings(policy));
        r.set_update_parallelism(parallelism);
        for frame in 0..12 {
            let time = frame as f32 / FPS;
            let update = r.prepare(frame, time).unwrap().update;
            let (g, t) = (r.geometry(), r.triangles());
            let textured = |slot: u32| {
                let source = t.source[slot as usize] as usize;
                let instance = g.instances[g.triangle_instance[source] as usize];
                g.materials[instance.material as usize]
                    .base_color_texture
                    .is_some()
            };
            let deformed: Vec<u32> = r
                .dirty()
                .moved()
                .into_iter()
                .filter(|&(_, m)| m == mipray::frame::Motion::Deformed)
                .map(|(s, _)| s)
                .collect();
            let what = format!("{parallelism:?}, frame {frame}");
            if frame > 0 {
                let untextured = deformed.iter().filter(|&&s| !textured(s)).count();
                assert!(
                    untextured >= 6,
                    "{what}: the plain strip bends ({untextured})"
                );
                assert_eq!(
                    update.lod_recomputed,
                    deformed.len() - untextured,
                    "{what}: only textured triangles are counted"
                );
            }
            let mut fresh = Renderer::new(scene(), settings(policy));
            fresh.prepare(frame, time).unwrap();
            let expected = by_source(&fresh);
            for (slot, &source) in t.source.iter().enumerate() {
                let value = t.log2_pb[slot];
                if !textured(slot as u32) {
                    assert_eq!(value, 0.0, "{what}: untextured triangle {source}");
                }
                assert!(
                    value.to_bits() == expected[source as usize].to_bits(),
                    "{what}: triangle {source}: {value} vs fresh {}",
                    expected[source as usize]
                );
            }
        }
    }
}

/// Two skinned grids over the same area, one textured and one not, both bending every
/// frame: their slots interleave, so the dirty set's words are full and mixed, and the
/// `log2 P_b` step takes such words whole. Only the textured triangles are recomputed and
/// counted, each equal to a fresh renderer's value; the untextured keep 0.
#[test]
fn whole_dirty_words_of_textured_and_untextured_deforming_triangles() {
    let scene = || {
        let mut scene = generated::textured_scene();
        // In one plane, the second half a quad across from the first.
        for shift in [0.0, 1.0 / 32.0] {
            let origin = glam::Vec3::new(-2.0 + shift, -1.0 + shift, -6.0);
            generated::add_skinned_grid(&mut scene, 64, 40, (4.0, 2.0), 4, origin);
        }
        scene.materials.push(mipray::scene::MaterialDesc::default());
        let plain = scene.materials.len() - 1;
        scene.meshes.last_mut().unwrap().primitives[0].material = Some(plain);
        generated::add_camera(&mut scene, glam::Vec3::new(0.0, 0.0, 2.0), 1.0);
        scene
    };
    let per_grid = 2 * 64 * 40;
    let policy = BvhPolicy::Refit {
        rebuild_threshold: f32::INFINITY,
    };
    for parallelism in [UpdateParallelism::Sequential, UpdateParallelism::Parallel] {
        let mut r = Renderer::new(scene(), settings(policy));
        r.set_update_parallelism(parallelism);
        for frame in 0..5 {
            let time = frame as f32 / FPS;
            let update = r.prepare(frame, time).unwrap().update;
            let what = format!("{parallelism:?}, frame {frame}");
            // The second grid's sources come after the first's.
            let t = r.triangles();
            let textured = |slot: usize| (t.source[slot] as usize) < per_grid;
            let mixed_words = (0..t.source.len() / 64)
                .filter(|w| {
                    let kinds = (w * 64..w * 64 + 64).map(textured);
                    let count = kinds.filter(|&k| k).count();
                    count > 0 && count < 64
                })
                .count();
            assert!(mixed_words > 10, "{what}: {mixed_words} mixed words");
            if frame > 0 {
                assert_eq!(update.deformed_triangles, 2 * per_grid, "{what}");
                assert_eq!(update.lod_recomputed, per_grid, "{what}");
            }
            let mut fresh = Renderer::new(scene(), settings(policy));
            fresh.prepare(frame, time).unwrap();
            let expected = by_source(&fresh);
            for (slot, &source) in t.source.iter().enumerate() {
                let value = t.log2_pb[slot];
                if !textured(slot) {
                    assert_eq!(value, 0.0, "{what}: untextured triangle {source}");
                }
                assert!(
                    value.to_bits() == expected[source as usize].to_bits(),
                    "{what}: triangle {source}: {value} vs fresh {}",
                    expected[source as usize]
                );
            }
        }
    }
}

/// A card whose node mirrors and unmirrors mid-sequence (x scale +1, -1, +1, stepped) beside
/// the skinned strip: the slots' uvs (which follow the winding, and which a write under an
/// unchanged winding leaves alone) equal a fresh renderer's on every frame.
#[test]
fn slot_uvs_follow_a_winding_that_flips_mid_sequence() {
    use mipray::scene::{ChannelTarget, Interpolation};
    let scene = || {
        let mut scene = skinned_dynamic_scene();
        let card = scene
            .meshes
            .iter()
            .position(|m| m.name == "card")
            .expect("card mesh");
        let flipping = add_root(
            &mut scene,
            node("flipping", at(glam::Vec3::new(2.5, 1.0, -5.0)), Some(card)),
        );
        let mut flip = channel(
            flipping,
            ChannelTarget::Scale,
            &[0.0, 0.3, 0.6],
            &[1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
        );
        flip.interpolation = Interpolation::Step;
        scene.animations[0].channels.push(flip);
        scene
    };
    let uvs_by_source = |r: &Renderer| {
        let t = r.triangles();
        let mut out = vec![[[0u32; 2]; 3]; t.len()];
        for (slot, &source) in t.source.iter().enumerate() {
            out[source as usize] = t.uvs[slot].map(|uv| uv.to_array().map(f32::to_bits));
        }
        out
    };
    let policy = BvhPolicy::Refit {
        rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
    };
    let mut sequence = Renderer::new(scene(), settings(policy));
    let mut flips = 0;
    let mut last = None;
    for frame in 0..FRAMES {
        let time = frame as f32 / FPS;
        sequence.prepare(frame, time).unwrap();
        let mirrored = (0.3..0.6).contains(&time);
        flips += (last.is_some_and(|l| l != mirrored)) as u32;
        last = Some(mirrored);
        let mut fresh = Renderer::new(scene(), settings(policy));
        fresh.prepare(frame, time).unwrap();
        assert!(
            uvs_by_source(&sequence) == uvs_by_source(&fresh),
            "frame {frame} (mirrored: {mirrored}): slot uvs differ from a fresh frame's"
        );
    }
    assert_eq!(flips, 2, "the sequence mirrors and unmirrors the card");
}

/// Moving instances with no triangles first and last in source order, around rigid, scaled
/// and stretched cards and the skinned strip: they visit nothing and list no dirty entry,
/// which must not shift which entries the `log2 P_b` update takes for whose (one thread and
/// split, flat and two-level), and the two-level build must not index past the last
/// triangle for the last one. Every textured slot's constant equals a fresh frame's.
#[test]
fn moving_instances_without_triangles_shift_no_update() {
    use mipray::scene::{ChannelTarget, MeshDesc, PrimitiveDesc};
    let scene = || {
        let mut scene = skinned_dynamic_scene();
        scene.meshes.push(MeshDesc {
            name: "empty".into(),
            primitives: vec![PrimitiveDesc {
                positions: vec![glam::Vec3::ZERO; 3],
                uvs: Some(vec![glam::Vec2::ZERO; 3]),
                material: Some(0),
                ..Default::default()
            }],
            ..Default::default()
        });
        let empty = scene.meshes.len() - 1;
        for (name, first) in [("empty first", true), ("empty last", false)] {
            let node = add_root(
                &mut scene,
                node(name, at(glam::Vec3::new(0.0, -2.0, -4.0)), Some(empty)),
            );
            if first {
                let root = scene.roots.pop().unwrap();
                scene.roots.insert(0, root);
            }
            scene.animations[0].channels.push(channel(
                node,
                ChannelTarget::Translation,
                &[0.0, 1.0],
                &[0.0, -2.0, -4.0, 1.0, -2.0, -4.0],
            ));
        }
        scene
    };
    let policy = BvhPolicy::Refit {
        rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
    };
    for layout in [BvhLayout::Flat, BvhLayout::TwoLevel] {
        let settings = || RenderSettings {
            layout,
            ..settings(policy)
        };
        for parallelism in [UpdateParallelism::Sequential, UpdateParallelism::Parallel] {
            let mut r = Renderer::new(scene(), settings());
            r.set_update_parallelism(parallelism);
            for frame in 0..10 {
                let time = frame as f32 / FPS;
                let update = r.prepare(frame, time).unwrap().update;
                if frame > 0 {
                    assert!(update.lod_shifted > 0 || layout == BvhLayout::TwoLevel);
                    assert!(update.lod_recomputed > 0, "{layout:?} frame {frame}");
                }
                let mut fresh = Renderer::new(scene(), settings());
                fresh.prepare(frame, time).unwrap();
                let (got, expected) = (by_source(&r), by_source(&fresh));
                for (source, (x, y)) in got.iter().zip(&expected).enumerate() {
                    assert!(
                        x.to_bits() == y.to_bits(),
                        "{layout:?} {parallelism:?} frame {frame}, triangle {source}: {x} vs fresh {y}"
                    );
                }
            }
        }
    }
}
