//! `mipray export`: triangle counts, the OBJ round trip (re-loaded frame renders like the
//! animation), the PLY layout with `log2_pb` and `deformed`, the camera JSON's primary
//! rays, and bad input.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::{Quat, Vec2, Vec3, Vec4};
use mipray::export::{ExportFormat, ExportOptions, export_frames};
use mipray::frame::appearance::material_descs;
use mipray::frame::{Motion, RenderSettings, Renderer};
use mipray::scene::{
    AnimationDesc, ChannelDesc, ChannelTarget, Interpolation, MaterialDesc, MeshDesc, NodeDesc,
    PrimitiveDesc, SceneDesc, Trs,
};
use mipray::texture::{MipFilter, MipPyramid, Sampler, Texture};

mod common;

fn mipray(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run mipray")
}

fn default_scene() -> SceneDesc {
    let path = mipray::cli::resolve_scene("default").expect("default scene");
    mipray::cli::load_scene(&path).expect("load default scene")
}

/// `mipray export SCENE --frames FRAME --size SIZE --rays --out DIR`, which must succeed;
/// the path of the ray file it wrote (its OBJ, `frame_NNNN.obj`, beside it).
fn export_rays(scene: &str, frame: u32, size: &str, dir: &Path) -> PathBuf {
    let frame_arg = frame.to_string();
    let run = mipray(&[
        "export",
        scene,
        "--frames",
        &frame_arg,
        "--size",
        size,
        "--rays",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    dir.join(format!("rays_{frame:04}.bin"))
}

fn settings(width: u32, height: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        ..RenderSettings::default()
    }
}

fn export(
    renderer: &mut Renderer,
    dir: &Path,
    format: ExportFormat,
    frames: std::ops::Range<u32>,
) -> Vec<mipray::export::ExportedFrame> {
    let options = ExportOptions {
        format,
        dir: dir.to_path_buf(),
        frames,
        clock: mipray::frame::FrameClock::Fps(30.0),
        rays: false,
    };
    export_frames(renderer, &options, |_| {}).expect("export")
}

// ---------------------------------------------------------------- PLY reader (from its header)

#[derive(Debug, Clone, PartialEq)]
enum Value {
    F(f32),
    I(i64),
    List(Vec<i64>),
}

#[derive(Debug)]
enum Property {
    Scalar {
        ty: String,
        name: String,
    },
    List {
        count: String,
        item: String,
        name: String,
    },
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

struct Ply {
    comments: Vec<String>,
    /// Per element: its rows, each a map from property name to value.
    elements: Vec<(Element, Vec<HashMap<String, Value>>)>,
}

fn read_scalar(ty: &str, bytes: &[u8], at: &mut usize) -> Value {
    let take = |n: usize, at: &mut usize| {
        let s = &bytes[*at..*at + n];
        *at += n;
        s
    };
    match ty {
        "float" | "float32" => Value::F(f32::from_le_bytes(take(4, at).try_into().unwrap())),
        "int" | "int32" => Value::I(i32::from_le_bytes(take(4, at).try_into().unwrap()) as i64),
        "uint" | "uint32" => Value::I(u32::from_le_bytes(take(4, at).try_into().unwrap()) as i64),
        "uchar" | "uint8" => Value::I(take(1, at)[0] as i64),
        other => panic!("unexpected PLY type {other}"),
    }
}

fn read_ply(path: &Path) -> Ply {
    let bytes = std::fs::read(path).expect("read ply");
    let end = b"end_header\n";
    let header_len = bytes
        .windows(end.len())
        .position(|w| w == end)
        .expect("end_header")
        + end.len();
    let header = std::str::from_utf8(&bytes[..header_len]).expect("ascii header");
    let mut lines = header.lines();
    assert_eq!(lines.next(), Some("ply"));
    let mut comments = Vec::new();
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", f, "1.0"] => assert_eq!(*f, "binary_little_endian"),
            ["comment", ..] => comments.push(line["comment ".len()..].to_string()),
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count.parse().unwrap(),
                properties: Vec::new(),
            }),
            ["property", "list", count, item, name] => elements
                .last_mut()
                .unwrap()
                .properties
                .push(Property::List {
                    count: count.to_string(),
                    item: item.to_string(),
                    name: name.to_string(),
                }),
            ["property", ty, name] => {
                elements
                    .last_mut()
                    .unwrap()
                    .properties
                    .push(Property::Scalar {
                        ty: ty.to_string(),
                        name: name.to_string(),
                    })
            }
            ["end_header"] => {}
            other => panic!("unexpected header line {other:?}"),
        }
    }
    let mut at = header_len;
    let mut out = Vec::new();
    for element in elements {
        let mut rows = Vec::with_capacity(element.count);
        for _ in 0..element.count {
            let mut row = HashMap::new();
            for p in &element.properties {
                match p {
                    Property::Scalar { ty, name } => {
                        row.insert(name.clone(), read_scalar(ty, &bytes, &mut at));
                    }
                    Property::List { count, item, name } => {
                        let Value::I(n) = read_scalar(count, &bytes, &mut at) else {
                            panic!("list count")
                        };
                        let items = (0..n)
                            .map(|_| match read_scalar(item, &bytes, &mut at) {
                                Value::I(i) => i,
                                v => panic!("list item {v:?}"),
                            })
                            .collect();
                        row.insert(name.clone(), Value::List(items));
                    }
                }
            }
            rows.push(row);
        }
        out.push((element, rows));
    }
    assert_eq!(at, bytes.len(), "body is exactly the declared layout");
    Ply {
        comments,
        elements: out,
    }
}

fn f(row: &HashMap<String, Value>, key: &str) -> f32 {
    match row[key] {
        Value::F(x) => x,
        ref v => panic!("{key}: {v:?}"),
    }
}

fn int(row: &HashMap<String, Value>, key: &str) -> i64 {
    match row[key] {
        Value::I(x) => x,
        ref v => panic!("{key}: {v:?}"),
    }
}

/// The triangle count `mipray info SCENE` prints.
fn info_triangle_count(scene: &str) -> usize {
    let info = mipray(&["info", scene]);
    assert!(info.status.success());
    String::from_utf8_lossy(&info.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("triangles: "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .expect("info prints the triangle count")
}

/// Runs `bench SCENE --frames FRAME --size SIZE --rays FILE` and returns its table's rows,
/// after checking that no answer differs from the file's.
fn bench_rows_agree(scene: &str, frame: &str, size: &str, file: &Path) -> Vec<String> {
    bench_api_rows_agree(scene, frame, size, file, "both")
}

/// [`bench_rows_agree`] timing only the kernels `--api api` names.
fn bench_api_rows_agree(
    scene: &str,
    frame: &str,
    size: &str,
    file: &Path,
    api: &str,
) -> Vec<String> {
    let bench = mipray(&[
        "bench",
        scene,
        "--frames",
        frame,
        "--size",
        size,
        "--rays",
        file.to_str().unwrap(),
        "--api",
        api,
        "--threads",
        "1",
        "--repeats",
        "1",
    ]);
    assert!(
        bench.status.success(),
        "{}",
        String::from_utf8_lossy(&bench.stderr)
    );
    let table = String::from_utf8_lossy(&bench.stdout).into_owned();
    let rows: Vec<String> = table
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| class"))
        .map(str::to_string)
        .collect();
    for row in &rows {
        assert!(row.trim_end().ends_with("| 0 |"), "answers differ: {row}");
    }
    rows
}

// ---------------------------------------------------------------- tests

#[test]
fn exported_triangle_counts_match_info_for_obj_and_ply() {
    let count = info_triangle_count("default");
    assert!(count > 100);

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    for format in ["obj", "ply"] {
        let run = mipray(&[
            "export", "default", "--frames", "7..9", "--format", format, "--out", out,
        ]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        for frame in [7, 8] {
            let path = dir.path().join(format!("frame_{frame:04}.{format}"));
            let triangles = if format == "obj" {
                let text = std::fs::read_to_string(&path).unwrap();
                assert_eq!(
                    text.lines().filter(|l| l.starts_with("v ")).count(),
                    3 * count
                );
                text.lines().filter(|l| l.starts_with("f ")).count()
            } else {
                let ply = read_ply(&path);
                assert_eq!(ply.elements[0].0.count, 3 * count);
                ply.elements[1].0.count
            };
            assert_eq!(triangles, count, "{}", path.display());
            assert!(dir.path().join(format!("camera_{frame:04}.json")).is_file());
        }
    }
    assert!(dir.path().join("materials.mtl").is_file());
    // No temporary files are left behind.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

type TriangleKey = [u32; 9];

fn key(p: &[glam::Vec3A; 3]) -> TriangleKey {
    let mut k = [0; 9];
    for (i, v) in p.iter().enumerate() {
        for (j, c) in v.to_array().iter().enumerate() {
            k[3 * i + j] = c.to_bits();
        }
    }
    k
}

#[test]
fn reloaded_obj_frame_renders_like_the_animation_at_that_frame() {
    let scene = default_scene();
    let frames = mipray::frame::FrameClock::Fps(30.0).default_frames(scene.duration());
    let frame = (frames.start + frames.end) / 2;
    assert!(frame > 0);
    let time_s = (frame as f64 / 30.0) as f32;
    let (w, h) = (96, 54);

    let dir = tempfile::tempdir().unwrap();
    let mut exporter = Renderer::new(scene, settings(w, h));
    export(
        &mut exporter,
        dir.path(),
        ExportFormat::Obj,
        frame..frame + 1,
    );
    let exported: HashMap<TriangleKey, ([Vec3; 3], [Vec2; 3], u32)> = {
        let (t, positions) = (exporter.triangles(), exporter.world_positions());
        (0..t.len())
            .map(|s| {
                let normals = exporter.slot_normals(s);
                (key(&positions[s]), (normals, t.uvs[s], t.material[s]))
            })
            .collect()
    };
    assert_eq!(
        exported.len(),
        exporter.triangles().len(),
        "triangles are distinct"
    );

    // Textures: decoding the exported PNG gives the original 8-bit image's bytes.
    let original = image::open(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("animations/default_floor_checker.png"),
    )
    .unwrap()
    .to_rgb8();
    let written: Vec<PathBuf> = std::fs::read_dir(dir.path().join("textures"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    assert_eq!(written.len(), 2, "{written:?}");
    let floor = written
        .iter()
        .find(|p| p.to_string_lossy().contains("floor_checker"))
        .expect("floor texture written");
    assert_eq!(image::open(floor).unwrap().to_rgb8(), original);

    // The animated scene at that frame.
    let mut animated = Renderer::new(default_scene(), settings(w, h));
    let (reference, _) = animated.render_frame(frame, time_s).unwrap();

    // The exported frame as a static scene.
    let obj = dir.path().join(format!("frame_{frame:04}.obj"));
    let reloaded_scene = mipray::cli::load_scene(&obj).expect("reload OBJ");
    assert_eq!(reloaded_scene.animations.len(), 0);
    assert_eq!(reloaded_scene.cameras.len(), 1);
    assert_eq!(reloaded_scene.lights.len(), 2);
    let mut reloaded = Renderer::new(reloaded_scene, settings(w, h));
    let (image, _) = reloaded.render_frame(0, 0.0).unwrap();

    // Positions, UVs and materials come back bit for bit, normals to rounding.
    let (t, positions) = (reloaded.triangles(), reloaded.world_positions());
    assert_eq!(t.len(), exported.len());
    for (s, p) in positions.iter().enumerate() {
        let (normals, uvs, material) = exported
            .get(&key(p))
            .expect("every re-loaded triangle is an exported one");
        assert_eq!(t.uvs[s], *uvs);
        assert_eq!(t.material[s], *material);
        for (a, b) in reloaded.slot_normals(s).iter().zip(normals) {
            assert!((*a - *b).length() < 1e-6, "{a} vs {b}");
        }
    }
    // The descriptions behind the renderer's material indices (names and flags included).
    let reloaded_materials = material_descs(reloaded.scene());
    let exported_materials = material_descs(exporter.scene());
    for (m, (a, b)) in reloaded_materials
        .iter()
        .zip(&exported_materials)
        .enumerate()
    {
        assert_eq!(a.name, b.name, "material {m}");
        assert_eq!(a.base_color, b.base_color);
        assert_eq!(
            (
                a.reflectance,
                a.transmission,
                a.ior,
                a.shininess,
                a.specular,
                a.double_sided
            ),
            (
                b.reflectance,
                b.transmission,
                b.ior,
                b.shininess,
                b.specular,
                b.double_sided
            )
        );
        assert_eq!(
            a.base_color_texture.is_some(),
            b.base_color_texture.is_some()
        );
    }

    let to_rgb = |img: &mipray::render::LinearImage| {
        image::RgbImage::from_raw(img.width, img.height, img.to_srgb8()).unwrap()
    };
    let (a, b) = (to_rgb(&reference), to_rgb(&image));
    let mean_abs = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.as_raw().len() as f64;
    let (metrics, _) = mipray::metrics::compare(&a, &b);
    assert!(mean_abs < 0.5, "mean abs {mean_abs}");
    assert!(metrics.psnr_db > 40.0, "psnr {}", metrics.psnr_db);
}

/// Two textured quads: node 0 static, node 1 with a non-uniform scale animation (which the
/// frame loop classifies as a deformation).
fn deforming_scene() -> SceneDesc {
    let texels: Vec<Vec4> = (0..16)
        .map(|i| Vec4::new((i % 4) as f32 / 3.0, (i / 4) as f32 / 3.0, 0.5, 1.0))
        .collect();
    let texture = Texture {
        name: "ramp".into(),
        pyramid: MipPyramid::from_linear_rgba(4, 4, texels).unwrap(),
        sampler: Sampler::default(),
    };
    let quad = PrimitiveDesc {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        normals: Some(vec![Vec3::Z; 4]),
        uvs: Some(vec![
            Vec2::new(0.0, 1.0),
            Vec2::new(2.0, 1.0),
            Vec2::new(2.0, 0.0),
            Vec2::new(0.0, 0.0),
        ]),
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Default::default()
    };
    let node = |name: &str, x: f32| NodeDesc {
        name: name.into(),
        local: Trs {
            translation: Vec3::new(x, 0.0, -5.0),
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        },
        mesh: Some(0),
        ..Default::default()
    };
    SceneDesc {
        source: "deforming".into(),
        meshes: vec![MeshDesc {
            name: "quad".into(),
            primitives: vec![quad],
            weights: Vec::new(),
        }],
        nodes: vec![node("static", -1.5), node("stretched", 1.5)],
        roots: vec![0, 1],
        materials: vec![MaterialDesc {
            name: "ramp".into(),
            base_color: Vec3::ONE,
            base_color_texture: Some(0),
            ..Default::default()
        }],
        textures: vec![texture],
        animations: vec![AnimationDesc {
            name: "stretch".into(),
            channels: vec![ChannelDesc {
                node: 1,
                target: ChannelTarget::Scale,
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values: vec![1.0, 1.0, 1.0, 3.0, 1.0, 1.0],
                components: 3,
            }],
        }],
        ..Default::default()
    }
}

#[test]
fn ply_parses_from_its_header_with_exact_log2_pb_and_deformed_flags() {
    let dir = tempfile::tempdir().unwrap();
    let mut exporter = Renderer::new(deforming_scene(), settings(64, 48));
    let done = export(&mut exporter, dir.path(), ExportFormat::Ply, 0..3);
    assert_eq!(
        done.iter().map(|d| d.deformed).collect::<Vec<_>>(),
        [0, 2, 2]
    );

    // A second renderer walks the same frames: the PLY must hold its values.
    let mut check = Renderer::new(deforming_scene(), settings(64, 48));
    for frame in 0..3u32 {
        let time_s = (frame as f64 / 30.0) as f32;
        check.prepare(frame, time_s).unwrap();
        let ply = read_ply(&dir.path().join(format!("frame_{frame:04}.ply")));
        assert!(
            ply.comments
                .iter()
                .any(|c| c == &format!("mipray export frame {frame}"))
        );
        assert!(ply.comments.iter().any(|c| c.starts_with("time_s ")));
        let (vertex, vertices) = &ply.elements[0];
        let (face, faces) = &ply.elements[1];
        assert_eq!(
            (vertex.name.as_str(), face.name.as_str()),
            ("vertex", "face")
        );
        let (t, positions) = (check.triangles(), check.world_positions());
        assert_eq!(t.len(), 4);
        assert_eq!(face.count, t.len());
        assert_eq!(vertex.count, 3 * t.len());
        let names: Vec<&str> = vertex
            .properties
            .iter()
            .map(|p| match p {
                Property::Scalar { name, .. } => name.as_str(),
                Property::List { name, .. } => name.as_str(),
            })
            .collect();
        assert_eq!(names, ["x", "y", "z", "nx", "ny", "nz", "u", "v"]);
        for (slot, row) in faces.iter().enumerate() {
            let Value::List(corners) = &row["vertex_indices"] else {
                panic!("vertex_indices is a list")
            };
            assert_eq!(corners.len(), 3);
            for (k, &c) in corners.iter().enumerate() {
                let v = &vertices[c as usize];
                let p = positions[slot][k];
                assert_eq!([f(v, "x"), f(v, "y"), f(v, "z")], p.to_array());
                let n = check.slot_normals(slot)[k];
                assert_eq!([f(v, "nx"), f(v, "ny"), f(v, "nz")], n.to_array());
                assert_eq!([f(v, "u"), f(v, "v")], t.uvs[slot][k].to_array());
            }
            assert_eq!(f(row, "log2_pb").to_bits(), t.log2_pb[slot].to_bits());
            assert!(
                t.log2_pb[slot] != 0.0,
                "textured triangles have a real log2_pb"
            );
            assert_eq!(int(row, "material"), t.material[slot] as i64);
            let deformed = check.dirty().contains(slot as u32)
                && check
                    .dirty()
                    .moved()
                    .contains(&(slot as u32, Motion::Deformed));
            assert_eq!(
                int(row, "deformed") == 1,
                deformed,
                "frame {frame} slot {slot}"
            );
            // Only the stretched node's triangles (sources 2 and 3), and never on frame 0.
            let expected = frame > 0 && t.source[slot] >= 2;
            assert_eq!(
                int(row, "deformed") == 1,
                expected,
                "frame {frame} slot {slot}"
            );
        }
    }

    // Starting at frame 2 flags the same triangles (frame 1 is prepared, not written).
    let later = tempfile::tempdir().unwrap();
    let mut renderer = Renderer::new(deforming_scene(), settings(64, 48));
    let done = export(&mut renderer, later.path(), ExportFormat::Ply, 2..3);
    assert_eq!(done[0].deformed, 2);
    assert_eq!(
        std::fs::read(later.path().join("frame_0002.ply")).unwrap(),
        std::fs::read(dir.path().join("frame_0002.ply")).unwrap()
    );
}

fn f32_field(v: &serde_json::Value, key: &str) -> f32 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key}")) as f32
}

fn vec_field(v: &serde_json::Value, key: &str) -> [f32; 3] {
    let a = v[key].as_array().unwrap_or_else(|| panic!("{key}"));
    assert_eq!(a.len(), 3);
    std::array::from_fn(|i| a[i].as_f64().unwrap() as f32)
}

#[test]
fn camera_json_reproduces_the_corner_primary_rays_bit_for_bit() {
    for (w, h, frame) in [(640u32, 360u32, 12u32), (97, 55, 30)] {
        let dir = tempfile::tempdir().unwrap();
        let mut exporter = Renderer::new(default_scene(), settings(w, h));
        export(
            &mut exporter,
            dir.path(),
            ExportFormat::Ply,
            frame..frame + 1,
        );
        let text =
            std::fs::read_to_string(dir.path().join(format!("camera_{frame:04}.json"))).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();

        let mut renderer = Renderer::new(default_scene(), settings(w, h));
        let prepared = renderer
            .prepare(frame, (frame as f64 / 30.0) as f32)
            .unwrap();
        let camera = prepared.camera;

        let (forward, right, up) = (
            vec_field(&json, "forward"),
            vec_field(&json, "right"),
            vec_field(&json, "up"),
        );
        let eye = vec_field(&json, "eye");
        assert_eq!(eye, camera.eye.to_array());
        assert_eq!(forward, camera.forward.to_array());
        assert_eq!(up, camera.up.to_array());
        assert_eq!(right, camera.right.to_array());
        assert_eq!(json["width"].as_u64(), Some(w as u64));
        assert_eq!(json["height"].as_u64(), Some(h as u64));
        assert_eq!(f32_field(&json, "yfov_radians"), camera.yfov);
        assert!((f32_field(&json, "yfov_degrees") - camera.yfov.to_degrees()).abs() < 1e-4);
        let tan = f32_field(&json, "tan_half_fov");
        let aspect = f32_field(&json, "aspect");
        assert_eq!(
            json["bits"]["tan_half_fov"].as_u64(),
            Some(tan.to_bits() as u64)
        );
        assert_eq!(
            json["primary_ray"]["pixel_centre"],
            serde_json::json!([0.5, 0.5])
        );
        assert_eq!(json["primary_ray"]["y_down"], serde_json::json!(true));

        // The documented formula, evaluated here from the JSON fields in f32.
        let (wf, hf) = (w as f32, h as f32);
        let corners = [(0u32, 0u32), (w - 1, 0), (0, h - 1), (w - 1, h - 1)];
        for (x, y) in corners {
            let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
            let sx = (2.0 * px / wf - 1.0) * tan * aspect;
            let sy = (1.0 - 2.0 * py / hf) * tan;
            let d: [f32; 3] = std::array::from_fn(|i| forward[i] + right[i] * sx + up[i] * sy);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let dir = d.map(|c| c / len);
            let expected = camera.primary_direction(px, py).to_array();
            assert_eq!(
                dir.map(f32::to_bits),
                expected.map(f32::to_bits),
                "pixel ({x}, {y}) at {w}x{h}"
            );
        }
        assert_ne!(
            camera.primary_direction(0.5, 0.5),
            camera.primary_direction(wf - 0.5, hf - 0.5)
        );

        // Lights and background as the renderer has them.
        let lights = json["lights"].as_array().unwrap();
        assert_eq!(lights.len(), prepared.lights.len());
        assert_eq!(lights.len(), 2);
        for (l, light) in lights.iter().zip(&prepared.lights) {
            assert_eq!(vec_field(l, "position"), light.position.to_array());
            assert_eq!(vec_field(l, "intensity"), light.intensity.to_array());
            assert_eq!(vec_field(l, "direction"), light.direction.to_array());
        }
        assert_eq!(
            vec_field(&json, "background"),
            renderer.scene().background.to_array()
        );
    }
}

/// A texture read one level a lookup (glTF `*_MIPMAP_NEAREST`, or `--mip-filter`) keeps its
/// filter through an OBJ export (`mipray_mip nearest`); a word other than `linear` or
/// `nearest` is an error naming the file.
#[test]
fn the_mip_filter_survives_an_obj_export() {
    let mut scene = default_scene();
    assert!(!scene.textures.is_empty());
    for t in &mut scene.textures {
        t.sampler.mip = MipFilter::Nearest;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut exporter = Renderer::new(scene, settings(32, 18));
    export(&mut exporter, dir.path(), ExportFormat::Obj, 0..1);
    let obj = dir.path().join("frame_0000.obj");
    let reloaded = mipray::cli::load_scene(&obj).expect("reload OBJ");
    assert!(!reloaded.textures.is_empty());
    for t in &reloaded.textures {
        assert_eq!(t.sampler.mip, MipFilter::Nearest, "{}", t.name);
    }
    let mtl = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "mtl"))
        .expect("an MTL file");
    let text = std::fs::read_to_string(&mtl).unwrap();
    std::fs::write(&mtl, text.replace("mipray_mip nearest", "mipray_mip cubic")).unwrap();
    let error = format!("{:#}", mipray::cli::load_scene(&obj).unwrap_err());
    assert!(
        error.contains("mipray_mip cubic")
            && error.contains(&*mtl.file_name().unwrap().to_string_lossy()),
        "{error}"
    );
}

#[test]
fn general_obj_without_mipray_statements_loads() {
    let dir = tempfile::tempdir().unwrap();
    let mut png = Vec::new();
    image::RgbImage::from_fn(2, 2, |x, y| {
        image::Rgb([(x * 255) as u8, (y * 255) as u8, 128])
    })
    .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
    .unwrap();
    std::fs::write(dir.path().join("tex.png"), &png).unwrap();
    std::fs::write(
        dir.path().join("thing.mtl"),
        "newmtl glassy\nKd 0.25 0.5 0.75\nNi 1.33\nd 0.25\nNs 64\nmap_Kd -clamp on tex.png\n\nnewmtl plain\nKd 1 0 0\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("thing.obj"),
        "mtllib thing.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl glassy\nf 1/1 2/2 3/3 4/4\nusemtl plain\nf 1 3 4\n",
    )
    .unwrap();
    let scene = mipray::cli::load_scene(&dir.path().join("thing.obj")).expect("loads");
    assert_eq!(scene.materials.len(), 2);
    let glassy = &scene.materials[0];
    assert_eq!(glassy.base_color, Vec3::new(0.25, 0.5, 0.75));
    assert_eq!(glassy.ior, 1.33);
    assert_eq!(glassy.transmission, 0.75);
    assert_eq!(glassy.shininess, 64.0);
    let texture = &scene.textures[glassy.base_color_texture.expect("textured")];
    assert_eq!(
        texture.sampler.wrap_s,
        mipray::texture::WrapMode::ClampToEdge
    );
    assert_eq!(texture.pyramid.base_size(), (2, 2));
    assert_eq!(
        scene.instanced_triangle_count(),
        3,
        "the quad is split in two"
    );
    let quad = &scene.meshes[0].primitives[0];
    assert_eq!(quad.material, Some(0));
    // vt (0, 0) is the image's bottom-left: mipray's v = 1.
    let uvs = quad.uvs.as_ref().unwrap();
    let at_origin = quad
        .positions
        .iter()
        .position(|p| *p == Vec3::ZERO)
        .unwrap();
    assert_eq!(uvs[at_origin], Vec2::new(0.0, 1.0));
    assert!(scene.cameras.is_empty() && scene.lights.is_empty());
    let mut renderer = Renderer::new(scene, settings(16, 16));
    let (image, _) = renderer.render_frame(0, 0.0).unwrap();
    assert!(image.pixels.iter().all(|p| p.is_finite()));
}

#[test]
fn bad_input_gives_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let missing = mipray(&[
        "export",
        "no_such_scene_xyz",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr).into_owned();
    assert!(err.contains("no_such_scene_xyz"), "{err}");
    assert!(!err.contains("panicked"), "{err}");

    // An output folder below a regular file cannot be created.
    let blocker = dir.path().join("file.txt");
    std::fs::write(&blocker, "x").unwrap();
    let unwritable = blocker.join("sub");
    let run = mipray(&[
        "export",
        "default",
        "--frames",
        "0",
        "--out",
        unwritable.to_str().unwrap(),
    ]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(err.contains("file.txt"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(!unwritable.exists());

    // The library reports the same without panicking.
    let mut renderer = Renderer::new(deforming_scene(), settings(8, 8));
    let options = ExportOptions {
        format: ExportFormat::Obj,
        dir: unwritable.clone(),
        frames: 0..1,
        clock: mipray::frame::FrameClock::Fps(30.0),
        rays: false,
    };
    assert!(export_frames(&mut renderer, &options, |_| {}).is_err());

    // Malformed OBJ / MTL: errors name the file and line.
    let bad = dir.path().join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 zero\nf 1 2 3\n").unwrap();
    let e = mipray::scene::obj::load(&bad).unwrap_err();
    assert_eq!(e.line, Some(3));
    assert!(
        e.to_string().starts_with(&format!("{}:3:", bad.display())),
        "{e}"
    );
    std::fs::write(&bad, "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(dir.path().join("m.mtl"), "newmtl a\nKd 0.5\n").unwrap();
    let e = mipray::scene::obj::load(&bad).unwrap_err();
    assert!(e.path.ends_with("m.mtl") && e.line == Some(2), "{e}");
    std::fs::write(dir.path().join("m.mtl"), "newmtl a\nmap_Kd missing.png\n").unwrap();
    std::fs::write(&bad, "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap();
    let e = mipray::scene::obj::load(&bad).unwrap_err();
    assert_eq!(e.line, Some(5), "{e}");
    std::fs::write(&bad, "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let e = mipray::scene::obj::load(&bad).unwrap_err();
    assert!(e.path.ends_with("missing.png"), "{e}");
    let run = mipray(&["info", bad.to_str().unwrap()]);
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("missing.png"));
}

// ---------------------------------------------------------------- the ray file

/// The per-corner triangles of an exported OBJ, in face order.
fn obj_faces(path: &Path) -> Vec<[glam::Vec3A; 3]> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut v = Vec::new();
    let mut faces = Vec::new();
    for line in text.lines() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let c: Vec<f32> = w.map(|x| x.parse().unwrap()).collect();
                v.push(glam::Vec3A::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let i: Vec<usize> = w
                    .map(|c| c.split('/').next().unwrap().parse::<usize>().unwrap() - 1)
                    .collect();
                assert_eq!(i.len(), 3, "{line}");
                faces.push([v[i[0]], v[i[1]], v[i[2]]]);
            }
            _ => {}
        }
    }
    faces
}

/// `export --rays` records every class of ray the default animation traces (it has mirrors,
/// glass and two lights), each answer checked by brute force against the exported mesh's
/// faces (the face recorded is one at the nearest distance, bit for bit; a miss crosses no
/// face; a shadow ray is blocked exactly when some face lies within its interval), and
/// `bench --rays FILE` traces the file on mipray's kernels with no answer differing.
#[test]
fn the_ray_file_records_every_ray_with_answers_brute_force_confirms() {
    use mipray::accel::intersect;
    use mipray::export::rays::{MISS, read_ray_file};
    use mipray::render::RayClass;
    use mipray::render::film::tile_pixels;
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (48u32, 27u32);
    let size = format!("{w}x{h}");
    let file = export_rays("default", 5, &size, dir.path());
    let records = read_ray_file(&file).unwrap();
    let faces = obj_faces(&dir.path().join("frame_0005.obj"));
    let count = |c: RayClass| records.iter().filter(|r| r.class == c).count();
    assert_eq!(
        count(RayClass::Primary),
        (w * h) as usize,
        "one primary ray per pixel"
    );
    for class in [RayClass::Shadow, RayClass::Reflection, RayClass::Refraction] {
        assert!(count(class) > 20, "{class:?}: {}", count(class));
    }
    // Film order: tile by tile, a tile's pixels in Morton order, so the first primary rays
    // are the first tile's top-left 2 x 2, then its 8 x 8 block, in the film's order; and
    // every pixel has its primary ray once.
    let primary: Vec<u32> = records
        .iter()
        .filter(|r| r.class == RayClass::Primary)
        .map(|r| r.pixel)
        .collect();
    assert_eq!(primary[..4], [0, 1, w, w + 1]);
    let film_order: Vec<u32> = tile_pixels((0, 0), w, h)
        .take(64)
        .map(|(x, y)| y * w + x)
        .collect();
    assert_eq!(primary[..64], film_order[..]);
    let mut block: Vec<u32> = (0..8)
        .flat_map(|y| (0..8).map(move |x| y * w + x))
        .collect();
    let mut first = primary[..64].to_vec();
    block.sort();
    first.sort();
    assert_eq!(first, block);
    let distinct: std::collections::HashSet<u32> = primary.iter().copied().collect();
    assert_eq!(distinct.len(), primary.len(), "a pixel's primary ray twice");
    let mut checked = [0usize; 4];
    for r in &records {
        assert!(r.pixel < w * h);
        let (origin, direction) = r.origin_direction();
        let hit_t = |tri: &[glam::Vec3A; 3]| intersect(tri, origin, direction).map(|(t, _)| t);
        let nearest = faces
            .iter()
            .filter_map(hit_t)
            .filter(|&t| t >= r.t_min && t < r.t_max)
            .fold(None, |m: Option<f32>, t| Some(m.map_or(t, |m| m.min(t))));
        match r.class {
            RayClass::Shadow => {
                assert_eq!(r.result == 1, nearest.is_some(), "shadow ray {r:?}");
                assert!(r.t.is_nan());
            }
            _ if r.result == MISS => {
                assert_eq!(nearest, None, "a recorded miss crosses a face: {r:?}");
                assert!(r.t.is_nan());
            }
            _ => {
                let face = &faces[r.result as usize];
                assert_eq!(hit_t(face).map(f32::to_bits), Some(r.t.to_bits()), "{r:?}");
                assert_eq!(
                    nearest.map(f32::to_bits),
                    Some(r.t.to_bits()),
                    "not the nearest: {r:?}"
                );
            }
        }
        checked[r.class as usize] += 1;
    }
    assert_eq!(checked.iter().sum::<usize>(), records.len());

    let rows = bench_rows_agree("default", "5", &size, &file);
    assert_eq!(
        rows.len(),
        8,
        "packets and single for primary, shadow, reflection and refraction: {rows:?}"
    );
    // `--api` times one way alone, every class of it, and the rows are those of both.
    for api in ["packets", "single"] {
        let alone = bench_api_rows_agree("default", "5", &size, &file, api);
        let column = |row: &String| row.split('|').nth(2).map(|c| c.trim().to_string());
        assert_eq!(alone.len(), 4, "{api}: {alone:?}");
        assert!(
            alone.iter().all(|row| column(row).as_deref() == Some(api)),
            "{alone:?}"
        );
        let classes = |rows: &[String]| -> Vec<Option<String>> {
            rows.iter()
                .filter(|row| column(row).as_deref() == Some(api))
                .map(|row| row.split('|').nth(1).map(|c| c.trim().to_string()))
                .collect()
        };
        assert_eq!(classes(&alone), classes(&rows), "{api}");
    }
}

/// `tools/anchors/split_ray_file.py` splits a ray file into parts that hold every ray once,
/// each in its class's part and in the file's order: primary rays alone, and each
/// secondary class by bounce, the first bounce's rays leaving (within the tool's tolerance)
/// their pixel's primary hit, the later ones not. A file that is not a ray file is refused
/// with its name. (Needs `python3`; skipped without it, and a failure where `CI` is set.)
#[test]
fn split_ray_file_parts_hold_every_ray_once_by_class_and_bounce() {
    use mipray::export::rays::{RayRecord, read_ray_file};
    use mipray::render::RayClass;
    let python = |args: &[&std::ffi::OsStr]| {
        Command::new("python3")
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/anchors/split_ray_file.py"))
            .args(args)
            .output()
    };
    if !Command::new("python3")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
    {
        common::shared_data::skip_or_fail(
            "python3, which runs tools/anchors/split_ray_file.py, not found",
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let file = export_rays("default", 5, "48x27", dir.path());
    let records = read_ray_file(&file).unwrap();
    let parts_dir = dir.path().join("parts");
    let split = python(&[file.as_os_str(), parts_dir.as_os_str()]).unwrap();
    assert!(
        split.status.success(),
        "{}",
        String::from_utf8_lossy(&split.stderr)
    );

    // Each pixel's primary hit point and distance.
    let mut primary_hit = HashMap::new();
    for r in records.iter().filter(|r| r.class == RayClass::Primary) {
        if r.t.is_finite() {
            primary_hit.insert(r.pixel, (r.origin + r.direction * r.t, r.t));
        }
    }
    // Every field, bit for bit (`RayRecord`'s `==` fails on the NaN distance of a miss).
    let bits = |r: &RayRecord| {
        (
            r.origin.to_array().map(f32::to_bits),
            r.direction.to_array().map(f32::to_bits),
            [r.t_min, r.t_max, r.t].map(f32::to_bits),
            (r.class, r.pixel, r.result),
        )
    };
    let mut total = 0;
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&parts_dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_str().unwrap().to_string();
        let part = read_ray_file(&path).unwrap();
        assert!(!part.is_empty(), "{name}: an empty part was written");
        let (class, bounce) = name.split_once('_').unwrap_or((name.as_str(), ""));
        // In the file's order: each of the part's rays found after the one before it.
        let mut from = 0;
        for r in &part {
            assert_eq!(r.class.name(), class, "{name}: {r:?}");
            let at = records[from..]
                .iter()
                .position(|f| bits(f) == bits(r))
                .unwrap_or_else(|| panic!("{name}: {r:?} not in the file after ray {from}"));
            from += at + 1;
            if r.class == RayClass::Primary {
                assert_eq!(bounce, "");
                continue;
            }
            let first = primary_hit
                .get(&r.pixel)
                .is_some_and(|&(hit, t)| r.origin.distance(hit) <= 1e-3 * t);
            assert_eq!(
                bounce,
                if first { "first" } else { "later" },
                "{name}: {r:?}"
            );
        }
        total += part.len();
        names.push(name);
    }
    names.sort();
    assert_eq!(total, records.len(), "parts {names:?}");
    for name in [
        "primary",
        "shadow_first",
        "shadow_later",
        "reflection_first",
    ] {
        assert!(names.iter().any(|n| n == name), "no {name} in {names:?}");
    }

    let not_rays = dir.path().join("frame_0005.obj");
    let refused = python(&[not_rays.as_os_str(), parts_dir.as_os_str()]).unwrap();
    assert!(!refused.status.success());
    let message = String::from_utf8_lossy(&refused.stderr);
    assert!(
        message.contains("frame_0005.obj") && message.contains("not a ray file"),
        "{message}"
    );
}

/// A scene of moving meshes (BART-like robots at a small size): the library refuses a
/// renderer that places them as instances (`two-level`) instead of writing a partial mesh,
/// and `export` writes every triangle `info` counts, its ray file's answers those faces
/// (`bench --rays FILE` finds no answer differing).
#[test]
fn a_scene_with_instances_exports_every_triangle_and_its_rays_agree() {
    let count = info_triangle_count("robots");
    let size = "32x24";
    let path = mipray::cli::resolve_scene("robots").expect("robots scene");
    let mut renderer = Renderer::new(
        mipray::cli::load_scene(&path).expect("load robots"),
        RenderSettings {
            layout: mipray::frame::BvhLayout::TwoLevel,
            ..settings(32, 24)
        },
    );
    let instanced = renderer.layout().instanced_meshes();
    assert!(
        instanced > 0,
        "robots at {size} has no instance under two-level"
    );
    let dir = tempfile::tempdir().unwrap();
    let options = ExportOptions {
        format: ExportFormat::Obj,
        dir: dir.path().join("library"),
        frames: 0..1,
        clock: mipray::frame::FrameClock::Fps(30.0),
        rays: false,
    };
    let refused = export_frames(&mut renderer, &options, |_| {}).unwrap_err();
    assert!(refused.to_string().contains("instances"), "{refused}");
    assert!(!dir.path().join("library").join("frame_0000.obj").exists());

    let out = dir.path().join("cli");
    let rays = export_rays("robots", 3, size, &out);
    let obj = std::fs::read_to_string(out.join("frame_0003.obj")).unwrap();
    assert_eq!(obj.lines().filter(|l| l.starts_with("f ")).count(), count);
    let rows = bench_rows_agree("robots", "3", size, &rays);
    assert!(rows.len() >= 4, "{rows:?}");
}

/// `bench --rays FILE` cuts each ray at its own `t max`, though a packet's rays share one
/// search distance: hits of the default animation's closest-hit rays are moved just past
/// or exactly onto their `t max` (a search up to `t max` excludes it: the hit becomes a
/// miss), and no answer differs. A `t min` the kernels do not trace, a file recorded on
/// another scene or at another size, and a file of no rays are refused with the file's
/// name.
#[test]
fn bench_on_a_ray_file_cuts_each_ray_at_its_own_t_max_and_refuses_what_it_cannot_trace() {
    use mipray::export::rays::{MISS, read_ray_file, write_records};
    use mipray::render::RayClass;
    let dir = tempfile::tempdir().unwrap();
    let size = "48x27";
    let records = read_ray_file(&export_rays("default", 5, size, dir.path())).unwrap();
    let mut cut = records.clone();
    let (mut misses, mut kept) = (0, 0);
    for (i, r) in cut.iter_mut().enumerate() {
        if r.class == RayClass::Shadow || r.result == MISS {
            continue;
        }
        if i % 2 == 0 {
            (r.t_max, r.result, r.t) = (r.t, MISS, f32::NAN);
            misses += 1;
        } else {
            r.t_max = r.t.next_up();
            kept += 1;
        }
    }
    assert!(misses > 20 && kept > 20, "{misses} cut, {kept} kept");
    let write = |name: &str, records: &[mipray::export::rays::RayRecord]| {
        let path = dir.path().join(name);
        let mut bytes = Vec::new();
        write_records(&mut bytes, records).unwrap();
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let rows = bench_rows_agree("default", "5", size, &write("cut.bin", &cut));
    assert_eq!(rows.len(), 8, "{rows:?}");

    let refused = |path: &Path, problem: &str| {
        let bench = mipray(&[
            "bench",
            "default",
            "--frames",
            "5",
            "--size",
            size,
            "--rays",
            path.to_str().unwrap(),
            "--repeats",
            "1",
        ]);
        let stderr = String::from_utf8_lossy(&bench.stderr);
        assert!(!bench.status.success(), "accepted {}", path.display());
        assert!(
            stderr.contains(path.file_name().unwrap().to_str().unwrap())
                && stderr.contains(problem),
            "{stderr}"
        );
    };
    let mut later_start = records.clone();
    later_start[3].t_min = 0.25;
    refused(&write("t_min.bin", &later_start), "t min 0.25");
    let mut other_scene = records.clone();
    let hit = other_scene
        .iter_mut()
        .find(|r| r.class != RayClass::Shadow && r.result != MISS)
        .unwrap();
    hit.result = 1_000_000_000;
    refused(&write("other.bin", &other_scene), "names face 1000000000");
    // Recorded at another size: a pixel one past the frame's last.
    let mut other_size = records.clone();
    other_size[2].pixel = 48 * 27;
    refused(
        &write("size.bin", &other_size),
        "record 2 names pixel 1296 but a 48x27 frame has 1296",
    );
    refused(&write("empty.bin", &[]), "holds no rays");
}
