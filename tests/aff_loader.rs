//! AFF (BART) loader: tokenizer, parser, tracks against FORMAT.md's reference formulas, a
//! fixture using every command, error messages, and the three BART scenes when present.

use std::path::{Path, PathBuf};
use std::time::Instant;

mod common;

use glam::{DQuat, DVec3, Quat, Vec3, Vec4};
use mipray::anim::{AnimationSelection, Pose, sample_channel, sample_rotation, sample_vec3};
use mipray::scene::aff::tracks::{
    PositionKey, RotationKey, Tcb, position_channel, rotation_channel,
};
use mipray::scene::aff::{self, AffStats, CONE_SEGMENTS, Lexer};
use mipray::scene::{ChannelTarget, Interpolation, SceneDesc};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/aff/scene.aff")
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn load_text(text: &str) -> Result<(SceneDesc, AffStats), String> {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "t.aff", text);
    aff::load_with_stats(&p).map_err(|e| e.message)
}

fn close3(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).abs().max_element() <= tol
}

fn node_named(scene: &SceneDesc, name: &str) -> usize {
    scene.nodes.iter().position(|n| n.name == name).unwrap()
}

// ---------------------------------------------------------------- tokenizer and parser

#[test]
fn tokenizer_strips_comments_anywhere_handles_crlf_and_latin1() {
    let input = b"a -1.0 5.0 300  % frames\r\n# whole line f\xf6rslag\r\nk cam{transl 4%x\r\n}";
    let mut lexer = Lexer::new(input);
    let tokens: Vec<(String, u32)> = std::iter::from_fn(|| lexer.next_token())
        .map(|t| (t.to_text(), t.line))
        .collect();
    let want: Vec<(String, u32)> = [
        ("a", 1),
        ("-1.0", 1),
        ("5.0", 1),
        ("300", 1),
        ("k", 3),
        ("cam", 3),
        ("{", 3),
        ("transl", 3),
        ("4", 3),
        ("}", 4),
    ]
    .iter()
    .map(|(s, l)| (s.to_string(), *l))
    .collect();
    assert_eq!(tokens, want);
}

#[test]
fn mesh_per_attribute_indices_are_expanded() {
    let (scene, stats) = load_text(
        "fm 0 0 0 1 1 1 0 0 0 1 0 0\n\
         m vertices 4  0 0 0  1 0 0  1 1 0  0 1 0\n\
           normals 2  0 0 3  0 0 -1\n\
           triangles 2\n\
             0 1 2  0 0 0\n\
             0 2 3  1 1 0\n",
    )
    .unwrap();
    assert_eq!(stats.meshes, 1);
    assert_eq!(stats.mesh_triangles, 2);
    let p = &scene.meshes[0].primitives[0];
    // Corners (v, n): (0,0) (1,0) (2,0) | (0,1) (2,1) (3,0): 6 distinct pairs.
    assert_eq!(p.positions.len(), 6);
    assert_eq!(p.indices, vec![0, 1, 2, 3, 4, 5]);
    let n = p.normals.as_ref().unwrap();
    assert_eq!(n[0], Vec3::Z);
    assert_eq!(n[3], Vec3::NEG_Z);
    assert_eq!(n[5], Vec3::Z);
    assert_eq!(p.positions[5], Vec3::new(0.0, 1.0, 0.0));
    // An index out of range names the file and line.
    let err = load_text("m vertices 1 0 0 0\n triangles 1\n 0 0 7\n").unwrap_err();
    assert_eq!(err, "t.aff:3: vertex index 7 out of range (the mesh has 1)");
}

#[test]
fn fm_state_is_global_across_braces_and_includes() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "inc.aff", "fm 0 0 0 0 0 1 0 0 0 1 0 0\n");
    let main = write(
        dir.path(),
        "main.aff",
        "fm 0 0 0 1 0 0 0 0 0 1 0 0\n\
         xs 1 1 1 0 1 0 0 0 0 0 { i 0 inc.aff }\n\
         p 3 0 0 0 1 0 0 0 1 0\n",
    );
    let scene = aff::load(&main).unwrap();
    // The only geometry comes after the include: it uses the included (blue) material.
    let m = scene.meshes[0].primitives[0].material.unwrap();
    assert_eq!(scene.materials[m].base_color, Vec3::new(0.0, 0.0, 1.0));
    assert_eq!(scene.materials.len(), 1);
}

#[test]
fn include_cycle_is_an_error_naming_the_chain() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "a.aff", "% a\ni 0 b.aff\n");
    write(dir.path(), "b.aff", "\n\ni 0 a.aff\n");
    let err = aff::load(&dir.path().join("a.aff")).unwrap_err();
    assert_eq!(
        err.message,
        "b.aff:3: include cycle: a.aff -> b.aff -> a.aff"
    );
    // A file included twice in sequence is not a cycle.
    write(dir.path(), "leaf.aff", "p 3 0 0 0 1 0 0 0 1 0\n");
    let twice = write(dir.path(), "twice.aff", "i 0 leaf.aff\ni 0 leaf.aff\n");
    let (scene, stats) = aff::load_with_stats(&twice).unwrap();
    assert_eq!(stats.files, 3);
    assert_eq!(scene.instanced_triangle_count(), 2);
}

#[test]
fn errors_name_file_and_line() {
    let err = load_text("b 0 0 0\nv from 0 0 foo\n").unwrap_err();
    assert_eq!(
        err,
        "t.aff:2: expected a number after 'from', found 'foo': not a number"
    );
    // A number single precision cannot hold says so.
    let err = load_text("p 3 0 0 0 1e39 0 0 0 1 0\n").unwrap_err();
    assert_eq!(
        err,
        "t.aff:1: expected a number after 'p', found '1e39': outside the range of single precision (about ±3.4e38)"
    );
    let err = load_text("\n\nqq 1 2\n").unwrap_err();
    assert_eq!(err, "t.aff:3: unknown command 'qq'");
    let err = load_text("\ni 0 missing.aff\n").unwrap_err();
    assert!(
        err.starts_with("t.aff:2: cannot find include 'missing.aff'"),
        "{err}"
    );
    let err = load_text("tt nope.ppm 0 0 0 0 0 1 0 0 1 0 0 1 0 0 1\n").unwrap_err();
    assert!(
        err.starts_with("t.aff:1: texture 'nope.ppm' not found"),
        "{err}"
    );
    let err = load_text("}\n").unwrap_err();
    assert_eq!(err, "t.aff:1: '}' without an open 'x' or 'xs'");
    let err = load_text("k a {\n transl 2 0 0 0 0 0 0 0 1 0 0 0 0 0 0\n}").unwrap_err();
    assert_eq!(err, "t.aff:2: 'transl' needs at least 4 keys, found 2");
    let err = load_text("p 3 0 0 0 1 0").unwrap_err();
    assert_eq!(
        err,
        "t.aff:1: expected a number after 'p', found the end of the file"
    );
}

// ---------------------------------------------------------------- the fixture

#[test]
fn fixture_uses_every_command() {
    let (scene, stats) = aff::load_with_stats(&fixture()).unwrap();
    // Counts per source command.
    assert_eq!(stats.files, 2);
    assert_eq!(stats.meshes, 1);
    assert_eq!(stats.mesh_triangles, 2);
    assert_eq!(stats.polygons, 3);
    assert_eq!(stats.polygon_triangles, 4);
    assert_eq!(stats.textured_triangles, 1);
    assert_eq!(stats.morph_triangles, 2);
    assert_eq!(stats.cones, 1);
    assert_eq!(stats.cone_triangles, 2 * CONE_SEGMENTS as usize);
    assert_eq!((stats.static_transforms, stats.animated_transforms), (2, 1));
    assert_eq!(stats.key_blocks, 3);
    assert_eq!(stats.total_triangles(), 9 + 64);
    assert_eq!(scene.instanced_triangle_count(), stats.total_triangles());

    // Scene-wide values.
    assert_eq!(scene.background, Vec3::new(0.1, 0.2, 0.3));
    assert_eq!(scene.ambient, Some(Vec3::splat(0.5)));
    let frames = scene.frame_times.unwrap();
    assert_eq!((frames.start, frames.end, frames.frames), (0.0, 2.0, 5));
    assert_eq!(frames.time(1), 0.5);
    assert_eq!(frames.time(4), 2.0);

    // Lights: white by default, no distance falloff, intensity pi (the NFF light through
    // the integrator's Lambert `1/pi`).
    assert_eq!(scene.lights.len(), 2);
    assert_eq!(scene.lights[0].color, Vec3::ONE);
    assert_eq!(scene.lights[1].color, Vec3::new(0.5, 0.25, 0.125));
    assert!(
        scene
            .lights
            .iter()
            .all(|l| !l.inverse_square && l.intensity == std::f32::consts::PI)
    );
    let l1 = node_named(&scene, "light1");
    assert_eq!(scene.nodes[l1].local.translation, Vec3::new(-1.0, 4.0, 1.0));
    assert_eq!(scene.nodes[l1].light, Some(1));

    // Camera: vertical FOV in radians, hither below 1e-4 becomes 1.
    assert_eq!(scene.cameras.len(), 1);
    assert!((scene.cameras[0].yfov - 45f32.to_radians()).abs() < 1e-7);
    assert_eq!(scene.cameras[0].znear, 1.0);

    // Materials: global fm, the include's fm carries out of it.
    let root = &scene.meshes[scene.nodes[scene.roots[0]].mesh.unwrap()];
    assert_eq!(root.primitives.len(), 3); // p (red), c (blue), tt (blue + texture)
    let red = &scene.materials[root.primitives[0].material.unwrap()];
    assert_eq!(red.base_color, Vec3::new(0.8, 0.2, 0.2));
    assert_eq!(
        (red.reflectance, red.specular, red.shininess),
        (0.5, 0.5, 20.0)
    );
    assert_eq!(red.ambient, Some(Vec3::splat(0.1)));
    assert!(red.double_sided);
    let cone = &root.primitives[1];
    assert_eq!(cone.indices.len(), 3 * 64);
    assert!(cone.normals.is_some());
    let blue = &scene.materials[cone.material.unwrap()];
    assert_eq!(blue.base_color, Vec3::new(0.3, 0.3, 0.9));
    assert_eq!((blue.transmission, blue.ior), (0.5, 1.5));
    let textured = &scene.materials[root.primitives[2].material.unwrap()];
    assert_eq!(textured.base_color, blue.base_color);
    assert_eq!(textured.base_color_texture, Some(0));
    let uvs = root.primitives[2].uvs.as_ref().unwrap();
    assert_eq!(uvs[1], glam::Vec2::new(1.0, 1.0));

    // Texture: PPM with a header comment, sRGB, row 0 of the file at v = 0, repeat.
    assert_eq!(scene.textures.len(), 1);
    let tex = &scene.textures[0];
    assert_eq!(tex.name, "checker.ppm");
    let level = &tex.pyramid.levels[0];
    assert_eq!((level.width, level.height), (2, 2));
    assert_eq!(level.texel(0), Vec4::new(1.0, 0.0, 0.0, 1.0));
    assert_eq!(level.texel(2), Vec4::new(0.0, 0.0, 1.0, 1.0));
    assert_eq!(tex.sampler.wrap_s, mipray::texture::WrapMode::Repeat);

    // The xs node: T R S from the command, its mesh expanded per attribute.
    let xs = scene
        .nodes
        .iter()
        .find(|n| n.local.translation == Vec3::new(10.0, 0.0, 0.0))
        .unwrap();
    assert_eq!(xs.local.scale, Vec3::splat(2.0));
    assert!(close3(xs.local.rotation * Vec3::X, Vec3::NEG_Z, 1e-6));
    let m = &scene.meshes[xs.mesh.unwrap()].primitives[0];
    assert_eq!(m.positions.len(), 6);
    assert_eq!(m.normals.as_ref().unwrap()[0], Vec3::Z);

    // tpa: one morph group (same material and times), one target, one-hot LINEAR weights.
    let tpa = node_named(&scene, "tpa");
    let mesh = &scene.meshes[scene.nodes[tpa].mesh.unwrap()];
    assert_eq!(mesh.weights, vec![0.0]);
    let p = &mesh.primitives[0];
    assert_eq!(p.indices.len(), 6);
    assert_eq!(p.morph_targets.len(), 1);
    assert_eq!(
        p.morph_targets[0].positions.as_ref().unwrap()[0],
        Vec3::new(0.0, 0.0, 2.0)
    );
    let glass = &scene.materials[p.material.unwrap()];
    assert_eq!((glass.transmission, glass.ior), (0.8, 1.0)); // ior <= 0 -> 1
    let anim = &scene.animations[0];
    let w = anim.channels.iter().find(|c| c.node == tpa).unwrap();
    assert_eq!(w.target, ChannelTarget::Weights);
    assert_eq!(w.interpolation, Interpolation::Linear);
    assert_eq!(
        (w.times.clone(), w.values.clone()),
        (vec![0.0, 2.0], vec![0.0, 1.0])
    );

    // Animated transform and camera tracks, sampled through the pose.
    let spinner = node_named(&scene, "spinner");
    let camera = node_named(&scene, "camera");
    let mut pose = Pose::default();
    pose.evaluate(&scene, AnimationSelection::All, 1.0);
    let (s, r, t) = pose.world_from_node[spinner].to_scale_rotation_translation();
    assert!(close3(t, Vec3::new(1.0, 2.0, 3.0), 1e-5));
    assert!(close3(s, Vec3::splat(2.0), 1e-5));
    assert!(close3(r * Vec3::X, Vec3::NEG_Z, 1e-5), "{r}");
    pose.evaluate(&scene, AnimationSelection::All, 0.0);
    let cam = pose.world_from_node[camera];
    assert!(close3(
        cam.transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 1.0, 5.0),
        1e-6
    ));
    assert!(close3(
        cam.transform_vector3(Vec3::NEG_Z),
        Vec3::NEG_Z,
        1e-6
    ));
    pose.evaluate(&scene, AnimationSelection::All, 10.0);
    let cam = pose.world_from_node[camera];
    assert!(close3(
        cam.transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 1.0, 3.0),
        1e-6
    ));

    // Notes: ignored visibility and the unused block.
    assert!(
        scene
            .notes
            .iter()
            .any(|n| n.contains("'visibility' tracks"))
    );
    assert!(
        scene
            .notes
            .iter()
            .any(|n| n.contains("not used by any node: unused_block"))
    );
}

/// An `a` line a user may not have meant is rendered as the formula says, with a note: no
/// frames (one frame at the start time), an end before the start (played backwards), or
/// more frames than a default range renders (spread over that many).
#[test]
fn unusual_frame_times_are_noted() {
    let scene = |a: &str| {
        load_text(&format!("{a}\np 3\n-1 -1 0\n1 -1 0\n0 1 0\n"))
            .unwrap()
            .0
    };
    let noted = |scene: &SceneDesc, text: &str| scene.notes.iter().any(|n| n.contains(text));
    assert!(noted(&scene("a 0 1 0"), "'a 0 1 0' asks for no frames"));
    assert!(noted(
        &scene("a 5 1 10"),
        "'a 5 1 10' ends before it starts"
    ));
    let usual = scene("a 0 1 10");
    assert!(
        !noted(&usual, "asks for no frames") && !noted(&usual, "ends before it starts"),
        "{:?}",
        usual.notes
    );
    // More frames than a default range renders: spread over 1,000,001 over the same time,
    // as a USD stage's range is; the last frame shows the end time.
    let many = scene("a 0 1 2000000000");
    assert!(
        noted(
            &many,
            "'a 0 1 2000000000' asks for more than 1000001 frames"
        ),
        "{:?}",
        many.notes
    );
    let times = many.frame_times.expect("frame times");
    assert_eq!(
        (times.start, times.end, times.frames),
        (0.0, 1.0, 1_000_001)
    );
    assert_eq!(times.time(1_000_000), 1.0);
    let most = scene("a 0 1 1000001");
    assert_eq!(most.frame_times.map(|t| t.frames), Some(1_000_001));
    assert!(!noted(&most, "asks for more than"), "{:?}", most.notes);
}

#[test]
fn tpa_weights_reproduce_linear_interpolation_between_samples() {
    let (scene, _) = load_text(
        "tpa 3\n 0\n 0 0 0 0 0 1  1 0 0 0 0 1  0 1 0 0 0 1\n\
         1\n 0 0 1 1 0 0  1 0 1 1 0 0  0 1 1 1 0 0\n\
         3\n 0 0 5 0 0 1  1 0 5 0 0 1  0 1 5 0 0 1\n",
    )
    .unwrap();
    let tpa = node_named(&scene, "tpa");
    let mesh = &scene.meshes[scene.nodes[tpa].mesh.unwrap()];
    let p = &mesh.primitives[0];
    let channel = &scene.animations[0].channels[0];
    let z_at = |t: f32| {
        let mut w = vec![0.0; 2];
        sample_channel(channel, t, &mut w);
        p.positions[0].z
            + w[0] * p.morph_targets[0].positions.as_ref().unwrap()[0].z
            + w[1] * p.morph_targets[1].positions.as_ref().unwrap()[0].z
    };
    for (t, z) in [
        (-1.0, 0.0),
        (0.0, 0.0),
        (0.5, 0.5),
        (1.0, 1.0),
        (2.0, 3.0),
        (3.0, 5.0),
        (9.0, 5.0),
    ] {
        assert!((z_at(t) - z).abs() < 1e-6, "t = {t}: {} vs {z}", z_at(t));
    }
}

// ---------------------------------------------------------------- tracks vs. FORMAT.md

/// FORMAT.md 1.4 segment choice: clamp to [t_1, t_n-2], else the first j with t < t_j+2.
fn reference_segment(times: &[f64], t: f64) -> (usize, f64) {
    let n = times.len();
    if t <= times[1] {
        return (0, 0.0);
    }
    if t >= times[n - 2] {
        return (n - 4, 1.0);
    }
    let j = (0..n - 3).find(|&j| t < times[j + 2]).unwrap();
    (j, (t - times[j + 1]) / (times[j + 2] - times[j + 1]))
}

fn kb(k: &[(f64, [f64; 3])], j: usize) -> ((f64, f64), (f64, f64)) {
    let t: Vec<f64> = (0..4).map(|i| k[j + i].0).collect();
    let [t1, c1, b1] = k[j + 1].1;
    let [t2, c2, b2] = k[j + 2].1;
    let adj0 = 2.0 * (t[2] - t[1]) / (t[2] - t[0]);
    let adj1 = 2.0 * (t[2] - t[1]) / (t[3] - t[1]);
    (
        (
            0.5 * adj0 * (1.0 - t1) * (1.0 + c1) * (1.0 + b1),
            0.5 * adj0 * (1.0 - t1) * (1.0 - c1) * (1.0 - b1),
        ),
        (
            0.5 * adj1 * (1.0 - t2) * (1.0 - c2) * (1.0 + b2),
            0.5 * adj1 * (1.0 - t2) * (1.0 + c2) * (1.0 - b2),
        ),
    )
}

/// FORMAT.md's Kochanek-Bartels position spline, written out directly.
fn reference_position(keys: &[PositionKey], t: f64) -> DVec3 {
    let times: Vec<f64> = keys.iter().map(|k| k.time as f64).collect();
    let (j, u) = reference_segment(&times, t);
    let tcb: Vec<(f64, [f64; 3])> = keys
        .iter()
        .map(|k| {
            (
                k.time as f64,
                [
                    k.tcb.tension as f64,
                    k.tcb.continuity as f64,
                    k.tcb.bias as f64,
                ],
            )
        })
        .collect();
    let ((out0, out1), (in0, in1)) = kb(&tcb, j);
    let p: Vec<DVec3> = (0..4).map(|i| keys[j + i].value.as_dvec3()).collect();
    let d = p[2] - p[1];
    let tout = out0 * (p[1] - p[0]) + out1 * d;
    let tin = in0 * d + in1 * (p[3] - p[2]);
    p[1] + u * tout + u * u * (3.0 * d - 2.0 * tout - tin) + u * u * u * (-2.0 * d + tout + tin)
}

fn reference_slerp(p: DQuat, q: DQuat, u: f64) -> DQuat {
    let angle = p.dot(q).clamp(-1.0, 1.0).acos();
    let s = angle.sin();
    if s < 1e-6 {
        return p;
    }
    let (a, b) = (((1.0 - u) * angle).sin() / s, (u * angle).sin() / s);
    DQuat::from_xyzw(
        a * p.x + b * q.x,
        a * p.y + b * q.y,
        a * p.z + b * q.z,
        a * p.w + b * q.w,
    )
}

fn reference_log(q: DQuat) -> DQuat {
    let v = DVec3::new(q.x, q.y, q.z);
    let phi = q.w.clamp(-1.0, 1.0).acos();
    let s = phi.sin();
    let v = if s.abs() < 1e-6 { v } else { v * (phi / s) };
    DQuat::from_xyzw(v.x, v.y, v.z, 0.0)
}

fn reference_exp(q: DQuat) -> DQuat {
    let v = DVec3::new(q.x, q.y, q.z);
    let phi = v.length();
    let s = phi.sin();
    let v = if s.abs() < 1e-6 { v } else { v * (s / phi) };
    DQuat::from_xyzw(v.x, v.y, v.z, phi.cos())
}

fn qadd(a: DQuat, b: DQuat, wa: f64, wb: f64) -> DQuat {
    DQuat::from_xyzw(
        wa * a.x + wb * b.x,
        wa * a.y + wb * b.y,
        wa * a.z + wb * b.z,
        wa * a.w + wb * b.w,
    )
}

/// FORMAT.md's rotation track (squad with KB tangents, hemisphere flips written back).
fn reference_rotation(keys: &[RotationKey], t: f64) -> DQuat {
    let mut q: Vec<DQuat> = keys
        .iter()
        .map(|k| {
            let axis = k.axis.as_dvec3().normalize();
            let half = (k.angle_deg as f64).to_radians() / 2.0;
            let v = axis * half.sin();
            DQuat::from_xyzw(v.x, v.y, v.z, half.cos())
        })
        .collect();
    let tcb: Vec<(f64, [f64; 3])> = keys
        .iter()
        .map(|k| {
            (
                k.time as f64,
                [
                    k.tcb.tension as f64,
                    k.tcb.continuity as f64,
                    k.tcb.bias as f64,
                ],
            )
        })
        .collect();
    let times: Vec<f64> = keys.iter().map(|k| k.time as f64).collect();
    let (target, u) = reference_segment(&times, t);
    for j in 0..=target {
        if q[j + 1].dot(q[j + 2]) < 0.0 {
            q[j + 2] = -q[j + 2];
        }
        if j < target {
            continue;
        }
        let (q0, q1, q2, q3) = (q[j], q[j + 1], q[j + 2], q[j + 3]);
        let ((out0, out1), (in0, in1)) = kb(&tcb, j);
        let l = reference_log(q1.inverse() * q2);
        let tout = qadd(l, reference_log(q0.inverse() * q1), out1, out0);
        let tin = qadd(l, reference_log(q2.inverse() * q3), in0, in1);
        let a = q1 * reference_exp(qadd(tout, l, 0.5, -0.5));
        let b = q2 * reference_exp(qadd(l, tin, 0.5, -0.5));
        return reference_slerp(
            reference_slerp(q1, q2, u),
            reference_slerp(a, b, u),
            2.0 * u * (1.0 - u),
        );
    }
    unreachable!()
}

fn pkey(time: f32, value: [f32; 3], tcb: [f32; 3]) -> PositionKey {
    PositionKey {
        time,
        value: Vec3::from(value),
        tcb: Tcb {
            tension: tcb[0],
            continuity: tcb[1],
            bias: tcb[2],
        },
    }
}

fn rkey(time: f32, axis: [f32; 3], angle_deg: f32, tcb: [f32; 3]) -> RotationKey {
    RotationKey {
        time,
        axis: Vec3::from(axis),
        angle_deg,
        tcb: Tcb {
            tension: tcb[0],
            continuity: tcb[1],
            bias: tcb[2],
        },
    }
}

fn position_track() -> Vec<PositionKey> {
    vec![
        pkey(-1.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        pkey(0.0, [1.0, 0.5, -1.0], [0.0, 0.0, 0.3]),
        pkey(0.7, [2.0, -1.0, 0.0], [0.5, 1.5, 0.0]),
        pkey(2.0, [2.5, 3.0, 1.0], [-0.2, 0.1, -0.4]),
        pkey(2.0, [4.0, 3.0, 1.0], [0.0, 0.0, 0.0]), // duplicate time: a jump
        pkey(3.5, [3.0, 0.0, 2.0], [0.0, 0.0, 0.0]),
        pkey(4.0, [0.0, 1.0, 2.0], [0.0, 0.0, 0.0]),
        pkey(6.0, [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]),
    ]
}

#[test]
fn kb_position_channel_matches_reference_formula() {
    let keys = position_track();
    let c = position_channel(&keys, 0, ChannelTarget::Translation).unwrap();
    assert_eq!(c.interpolation, Interpolation::CubicSpline);
    assert_eq!(c.times, vec![0.0, 0.7, 2.0, 2.0, 3.5, 4.0]);
    for i in 0..=2000 {
        let t = -2.0 + 8.0 * i as f64 / 2000.0;
        let got = sample_vec3(&c, t as f32).as_dvec3();
        let want = reference_position(&keys, t);
        assert!(
            (got - want).abs().max_element() < 1e-5,
            "t = {t}: {got} vs {want}"
        );
    }
}

#[test]
fn splines_equal_keys_at_key_times_clamp_outside_and_jump_at_duplicates() {
    let keys = position_track();
    let c = position_channel(&keys, 0, ChannelTarget::Translation).unwrap();
    for k in &keys[1..keys.len() - 1] {
        if k.time == 2.0 {
            continue; // the duplicated time takes the later key
        }
        assert!(
            close3(sample_vec3(&c, k.time), k.value, 1e-6),
            "key at {}",
            k.time
        );
    }
    assert_eq!(sample_vec3(&c, 2.0), Vec3::new(4.0, 3.0, 1.0));
    assert!(close3(
        sample_vec3(&c, 1.9999),
        Vec3::new(2.5, 3.0, 1.0),
        1e-3
    ));
    // Clamped outside [t_1, t_n-2]: the end keys only shape tangents.
    assert_eq!(sample_vec3(&c, -5.0), Vec3::new(1.0, 0.5, -1.0));
    assert_eq!(sample_vec3(&c, 5.0), Vec3::new(0.0, 1.0, 2.0));
    assert_eq!(sample_vec3(&c, 100.0), Vec3::new(0.0, 1.0, 2.0));
}

#[test]
fn duplicate_times_at_the_ends_of_a_track() {
    // Robots' camera: the first two keys share a time; the kitchen wheels: zero-length
    // segments in the interior; here also at the end.
    let keys = vec![
        pkey(0.0, [0.0, 0.0, 0.0], [0.0; 3]),
        pkey(0.0, [1.0, 0.0, 0.0], [0.0; 3]),
        pkey(1.0, [2.0, 0.0, 0.0], [0.0; 3]),
        pkey(2.0, [3.0, 1.0, 0.0], [0.0; 3]),
        pkey(2.0, [5.0, 1.0, 0.0], [0.0; 3]),
        pkey(3.0, [6.0, 0.0, 0.0], [0.0; 3]),
    ];
    let c = position_channel(&keys, 0, ChannelTarget::Translation).unwrap();
    for i in 0..=400 {
        let t = -1.0 + 4.0 * i as f64 / 400.0;
        if t == 2.0 {
            continue; // reference: t >= t_n-2 clamps to the later key too; checked below
        }
        let got = sample_vec3(&c, t as f32).as_dvec3();
        let want = reference_position(&keys, t);
        assert!(
            (got - want).abs().max_element() < 1e-5,
            "t = {t}: {got} vs {want}"
        );
        assert!(got.is_finite());
    }
    assert_eq!(sample_vec3(&c, 2.0), Vec3::new(5.0, 1.0, 0.0));
}

#[test]
fn key_times_going_back_evaluate_like_the_reference() {
    // Robots' gun_rot: times restart (42 after 48).
    let mut keys: Vec<PositionKey> = (0..8)
        .map(|i| pkey(i as f32, [i as f32, (i * i) as f32 * 0.1, 0.0], [0.0; 3]))
        .collect();
    keys.extend((0..6).map(|i| pkey(4.5 + i as f32, [-(i as f32), 1.0, i as f32], [0.0; 3])));
    let c = position_channel(&keys, 0, ChannelTarget::Translation).unwrap();
    assert!(c.times.windows(2).all(|w| w[0] <= w[1]));
    for i in 0..=800 {
        let t = -1.0 + 12.0 * i as f64 / 800.0;
        let got = sample_vec3(&c, t as f32).as_dvec3();
        let want = reference_position(&keys, t);
        assert!(
            (got - want).abs().max_element() < 1e-4,
            "t = {t}: {got} vs {want}"
        );
    }
}

fn wheel_track() -> Vec<RotationKey> {
    // A wheel spinning about -z past 360 degrees, keys 90 degrees apart, a zero-length
    // segment (instant 90-degree jump) as in the kitchen, one key with TCB and an unnormalised
    // axis as in Robots.
    let mut keys = Vec::new();
    for i in 0..12 {
        let t = i as f32 * 0.25;
        let extra = if i >= 8 { 90.0 } else { 0.0 };
        keys.push(rkey(t, [0.0, 0.0, -1.0], 90.0 * i as f32 + extra, [0.0; 3]));
    }
    // Duplicate time 1.75: 630 then 720 degrees (an instant 90-degree jump).
    keys.insert(8, rkey(1.75, [0.0, 0.0, -1.0], 720.0, [0.0; 3]));
    keys[6].tcb = Tcb {
        tension: 0.5,
        continuity: 0.0,
        bias: 0.2,
    };
    keys[4].axis = Vec3::new(0.0, 0.0, -1.077);
    keys
}

#[test]
fn squad_rotation_channel_matches_reference() {
    let keys = wheel_track();
    let (c, approximated) = rotation_channel(&keys, 0).unwrap();
    assert!(!approximated);
    assert_eq!(c.interpolation, Interpolation::Squad);
    for i in 0..=1000 {
        let t = -0.5 + 4.0 * i as f64 / 1000.0;
        let got = sample_rotation(&c, t as f32).as_dquat().normalize();
        let want = reference_rotation(&keys, t);
        // Same rotation (q and -q alike) within 1e-5 radians.
        let angle = 2.0 * got.dot(want).abs().min(1.0).acos();
        assert!(angle < 1e-5, "t = {t}: {got} vs {want} ({angle} rad)");
    }
}

#[test]
fn squad_equals_keys_clamps_and_is_continuous_past_360() {
    let keys = wheel_track();
    let (c, _) = rotation_channel(&keys, 0).unwrap();
    let rot = |deg: f32| Quat::from_axis_angle(Vec3::NEG_Z, deg.to_radians());
    for k in &keys[1..keys.len() - 1] {
        if k.time == 1.75 {
            continue;
        }
        assert!(
            sample_rotation(&c, k.time).angle_between(rot(k.angle_deg)) < 1e-4,
            "{}",
            k.time
        );
    }
    // Clamp outside [t_1, t_n-2].
    assert!(sample_rotation(&c, -3.0).angle_between(rot(90.0)) < 1e-5);
    let last = &keys[keys.len() - 2];
    assert!(sample_rotation(&c, 99.0).angle_between(rot(last.angle_deg)) < 1e-5);
    // Continuity: 90 degrees per 0.25 s, so 1/400 s steps never turn more than ~1 degree
    // (with some overshoot allowance), except at the deliberate jump at t = 1.75.
    let mut previous = sample_rotation(&c, 0.25);
    for i in 1..=1000 {
        let t = 0.25 + 2.25 * i as f32 / 1000.0;
        let q = sample_rotation(&c, t);
        let step = q.angle_between(previous).to_degrees();
        let across_jump = (t - 1.75).abs() < 0.003;
        assert!(step < 2.0 || across_jump, "t = {t}: step {step} degrees");
        previous = q;
    }
    // The jump at the duplicated time: the later key (720) from 1.75 on, 630 just before.
    assert!(sample_rotation(&c, 1.75).angle_between(rot(720.0)) < 1e-4);
    assert!(sample_rotation(&c, 1.7499).angle_between(rot(630.0)) < 0.01);
}

// ---------------------------------------------------------------- the BART scenes

fn bart_dir() -> Option<PathBuf> {
    common::shared_data::shared_path("bart")
}

fn load_bart(dir: &Path, file: &str) -> (SceneDesc, AffStats) {
    let start = Instant::now();
    let loaded = aff::load_with_stats(&dir.join(file)).unwrap();
    println!(
        "{file}: loaded in {:.0} ms",
        start.elapsed().as_secs_f64() * 1e3
    );
    loaded
}

fn camera_at(scene: &SceneDesc, t: f32) -> (Vec3, Vec3) {
    let mut pose = Pose::default();
    pose.evaluate(scene, AnimationSelection::All, t);
    let m = pose.world_from_node[node_named(scene, "camera")];
    (
        m.transform_point3(Vec3::ZERO),
        m.transform_vector3(Vec3::NEG_Z).normalize(),
    )
}

#[test]
fn bart_kitchen_counts_and_camera() {
    let Some(dir) = bart_dir() else { return };
    let (scene, stats) = load_bart(&dir, "kitchen/aff/kitchen.aff");
    assert_eq!(stats.mesh_triangles, 110_561);
    assert_eq!(stats.source_triangles(), 110_561);
    assert_eq!(scene.instanced_triangle_count(), 110_561);
    assert_eq!(stats.meshes, 393);
    assert_eq!(scene.lights.len(), 6);
    assert_eq!(stats.animated_transforms, 7);
    assert_eq!(stats.key_blocks, 6);
    assert_eq!(scene.textures.len(), 8);
    let f = scene.frame_times.unwrap();
    assert_eq!((f.start, f.end, f.frames), (0.0, 20.0, 800));
    assert_eq!(scene.background, Vec3::new(0.5, 0.5, 1.0));
    assert_eq!(scene.ambient, Some(Vec3::splat(2.5)));
    let (position, direction) = camera_at(&scene, 0.0);
    assert!(
        close3(position, Vec3::new(3.75, 2.3, 3.6), 1e-4),
        "{position}"
    );
    assert!(
        close3(direction, Vec3::new(-0.31, -0.42, -0.85), 0.01),
        "{direction}"
    );
    // Glass: T = 0.85, IOR 1.55 on 19,128 triangles.
    let glass_tris: usize = scene
        .meshes
        .iter()
        .flat_map(|m| &m.primitives)
        .filter(|p| {
            let m = &scene.materials[p.material.unwrap()];
            m.transmission == 0.85 && m.ior == 1.55
        })
        .map(|p| p.triangle_count())
        .sum();
    assert_eq!(glass_tris, 19_128);
}

#[test]
fn bart_robots_counts() {
    let Some(dir) = bart_dir() else { return };
    let (scene, stats) = load_bart(&dir, "robots/aff/Robot.aff");
    assert_eq!(stats.mesh_triangles, 71_708);
    assert_eq!(scene.instanced_triangle_count(), 71_708);
    assert_eq!(stats.meshes, 1_849);
    assert_eq!(scene.lights.len(), 1);
    assert_eq!(stats.animated_transforms, 190);
    assert_eq!(stats.key_blocks, 187);
    assert_eq!(scene.textures.len(), 44);
    let f = scene.frame_times.unwrap();
    assert_eq!((f.start, f.end, f.frames), (0.0, 50.0, 800));
    assert_eq!(scene.background, Vec3::ZERO);
    // Poses stay finite over the whole animation.
    let mut pose = Pose::default();
    for i in (0..800).step_by(37) {
        pose.evaluate(&scene, AnimationSelection::All, f.time(i));
        assert!(pose.world_from_node.iter().all(|m| m.is_finite()));
    }
}

#[test]
fn bart_museum_counts_and_camera() {
    let Some(dir) = bart_dir() else { return };
    let (scene, stats) = load_bart(&dir, "museum/aff/museum5.aff");
    assert_eq!(stats.source_triangles(), 10_284);
    assert_eq!(
        (
            stats.mesh_triangles,
            stats.polygon_triangles,
            stats.textured_triangles
        ),
        (10_000, 274, 10)
    );
    assert_eq!(stats.morph_triangles, 1_024);
    assert_eq!(stats.cones, 8);
    assert_eq!(stats.cone_triangles, 8 * 2 * CONE_SEGMENTS as usize);
    assert_eq!(scene.instanced_triangle_count(), stats.total_triangles());
    assert_eq!(scene.lights.len(), 2);
    assert_eq!(scene.textures.len(), 5);
    let f = scene.frame_times.unwrap();
    assert_eq!((f.start, f.end, f.frames), (-1.0, 5.0, 300));
    let (position, direction) = camera_at(&scene, -1.0);
    assert!(
        close3(position, Vec3::new(0.0, 1.8, -9.0), 1e-4),
        "{position}"
    );
    assert!(direction.z > 0.95, "{direction}");
    // The sculpture: K = 5 samples at 0..4, one morph group.
    let tpa = node_named(&scene, "tpa");
    let mesh = &scene.meshes[scene.nodes[tpa].mesh.unwrap()];
    assert_eq!(mesh.weights.len(), 4);
    assert_eq!(mesh.primitives[0].triangle_count(), 1_024);
}
