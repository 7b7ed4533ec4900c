//! OpenUSD stages end to end: the USD samples in `../shared/usd/` render through the same
//! frame loop as their glTF originals in `../shared/gltf/`; a rigid time-sampled translation
//! stays rigid (no `log2 P_b` recomputed); a point cache written here marks exactly the
//! triangles whose vertices changed as deformed.
//!
//! Tests that read `../shared` skip (printing why) where it is absent, and fail under `CI`.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::shared_data::shared_path;
use serde_json::Value;

/// The seven USDZ conversions of Khronos samples and their glTF originals.
const SAMPLES: [(&str, &str); 7] = [
    ("AnimatedCube", "AnimatedCube/AnimatedCube.gltf"),
    ("AnimatedTriangle", "AnimatedTriangle/AnimatedTriangle.gltf"),
    ("BoxAnimated", "BoxAnimated/BoxAnimated.glb"),
    ("CesiumMan", "CesiumMan/CesiumMan.glb"),
    (
        "InterpolationTest",
        "InterpolationTest/InterpolationTest.glb",
    ),
    ("RiggedFigure", "RiggedFigure/RiggedFigure.glb"),
    ("RiggedSimple", "RiggedSimple/RiggedSimple.glb"),
];

fn mipray(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(args)
        .output()
        .expect("run mipray")
}

/// Renders `scene` into `out` with `extra` flags; panics with stderr on failure.
fn render(scene: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    if !extra.contains(&"--size") {
        args.extend(["--size", "96x54"]);
    }
    args.extend_from_slice(extra);
    let output = mipray(&args);
    assert!(
        output.status.success(),
        "{} failed: {}",
        scene.display(),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The frame records of a rendered folder, in frame order.
fn records(out: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(out.join("stats.jsonl")).unwrap();
    let mut records: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    records.sort_by_key(|r| r["frame"].as_u64().unwrap());
    records
}

fn counter(record: &Value, name: &str) -> u64 {
    record[name]
        .as_u64()
        .unwrap_or_else(|| panic!("{name} missing in {record}"))
}

fn usd_dir() -> Option<PathBuf> {
    shared_path("usd")
}

#[test]
fn every_usdz_sample_renders_a_short_sequence_with_finite_samples() {
    let Some(dir) = usd_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    for (name, _) in SAMPLES {
        let scene = dir.join(format!("{name}.usdz"));
        let out = tmp.path().join(name);
        render(&scene, &out, &["--frames", "0..12", "--lights", "2"]);
        let records = records(&out);
        assert_eq!(records.len(), 12, "{name}");
        for r in &records {
            assert_eq!(counter(r, "nonfinite_samples"), 0, "{name}: {r}");
        }
        let moved: u64 = records[1..]
            .iter()
            .map(|r| counter(r, "moved_triangles"))
            .sum();
        assert!(moved > 0, "{name}: nothing moved in 12 frames");
    }
}

#[test]
fn a_time_sampled_translation_moves_rigidly_and_the_camera_comes_from_its_lens() {
    let Some(dir) = usd_dir() else { return };
    let scene_path = dir.join("animated_cube_translation.usda");
    let scene = mipray::scene::load(&scene_path).unwrap();
    // focalLength 218.12926, verticalAperture 20.955: the vertical field of view.
    assert_eq!(scene.cameras.len(), 1);
    let yfov = 2.0 * (20.955f64 / (2.0 * 218.12926)).atan();
    assert!(
        (scene.cameras[0].yfov as f64 - yfov).abs() < 1e-6,
        "{:?}",
        scene.cameras[0]
    );
    assert_eq!(scene.cameras[0].znear, 1.0);
    // The camera node sits at (50, 0, 1129.035) centimetres: metres after metersPerUnit.
    let camera_node = scene.nodes.iter().position(|n| n.camera.is_some()).unwrap();
    let world = mipray::anim::node_world_transforms(&scene, 0.0);
    let eye = world[camera_node].transform_point3(glam::Vec3::ZERO);
    assert!(
        (eye - glam::Vec3::new(0.5, 0.0, 11.290352)).length() < 1e-4,
        "{eye}"
    );
    // 100 time codes at the default 24 per second: the cube is 1 m along +X at 100/24 s.
    let cube = scene.nodes.iter().position(|n| n.mesh.is_some()).unwrap();
    let at_end = mipray::anim::node_world_transforms(&scene, 100.0 / 24.0)[cube];
    let moved = at_end.transform_point3(glam::Vec3::ZERO);
    assert!(
        (moved - glam::Vec3::new(1.0, 0.0, 0.0)).length() < 1e-5,
        "{moved}"
    );

    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cube");
    render(
        &scene_path,
        &out,
        &["--frames", "0..10", "--camera", "camera"],
    );
    let records = records(&out);
    for r in &records[1..] {
        assert_eq!(counter(r, "moved_triangles"), 12, "{r}");
        assert_eq!(counter(r, "deformed_triangles"), 0, "{r}");
        assert_eq!(counter(r, "lod_recomputed"), 0, "{r}");
        assert_eq!(counter(r, "lod_shifted"), 0, "{r}");
    }
}

/// The textured AnimatedCube turns by `orient` samples: rigid too, its textured triangles
/// keep their `log2 P_b` (computed once, on the first frame).
#[test]
fn a_textured_cube_turned_by_orient_samples_keeps_its_log2_pb() {
    let Some(dir) = usd_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cube");
    render(&dir.join("AnimatedCube.usdz"), &out, &["--frames", "0..8"]);
    let records = records(&out);
    assert_eq!(counter(&records[0], "lod_recomputed"), 12);
    for r in &records[1..] {
        assert_eq!(counter(r, "moved_triangles"), 12, "{r}");
        assert_eq!(counter(r, "deformed_triangles"), 0, "{r}");
        assert_eq!(counter(r, "lod_recomputed"), 0, "{r}");
    }
}

/// How a USD conversion's frames compare with its glTF original's.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Expect {
    /// Same animation and materials: PSNR >= 40 dB and mean FLIP <= 0.01 every frame, and
    /// the same moved and deformed counts every frame.
    Alike,
    /// The converter wrote a UsdPreviewSurface with its defaults (diffuse 0.18) where the
    /// glTF file has no material (the renderer's default grey 0.8): the same counts and the
    /// same silhouette every frame, shading differs.
    OtherMaterial,
    /// The converter resampled every joint at every time code (the glTF original has its
    /// own keys per channel, many of two keys): the images match, but where a joint moves
    /// by a few ulps between two frames in one file and not at all in the other, the frame
    /// loop's bit-exact "did this triangle change" test counts different deformed triangles
    /// (frames 17-25 and a few others of 40), so the counts are not compared.
    Resampled,
    /// The converter baked step keys into one-time-code ramps that start one time code
    /// late and cubic-spline keys into a sample per time code: only the first frame (before
    /// any key) matches the original; triangle counts match.
    RebakedKeys,
}

fn expectation(name: &str) -> Expect {
    match name {
        "AnimatedTriangle" => Expect::OtherMaterial,
        "InterpolationTest" => Expect::RebakedKeys,
        "RiggedFigure" => Expect::Resampled,
        _ => Expect::Alike,
    }
}

#[test]
fn usdz_conversions_render_like_their_gltf_originals() {
    let (Some(usd), Some(gltf)) = (usd_dir(), shared_path("gltf")) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    for (name, original) in SAMPLES {
        let usd_scene = usd.join(format!("{name}.usdz"));
        let gltf_scene = gltf.join(original);
        let a = mipray::scene::load(&gltf_scene).unwrap();
        let b = mipray::scene::load(&usd_scene).unwrap();
        assert_eq!(
            a.instanced_triangle_count(),
            b.instanced_triangle_count(),
            "{name}: triangle counts"
        );
        // Both at 30 fps from t = 0, so frame i shows the same time in both.
        let frames = ["--frames", "0..40", "--fps", "30", "--size", "160x90"];
        let (ga, ub) = (
            tmp.path().join(format!("{name}-gltf")),
            tmp.path().join(format!("{name}-usd")),
        );
        render(&gltf_scene, &ga, &frames);
        render(&usd_scene, &ub, &frames);
        let expect = expectation(name);
        let (ra, rb) = (records(&ga), records(&ub));
        if !matches!(expect, Expect::RebakedKeys | Expect::Resampled) {
            for (x, y) in ra.iter().zip(&rb) {
                for c in ["moved_triangles", "deformed_triangles"] {
                    assert_eq!(
                        counter(x, c),
                        counter(y, c),
                        "{name} frame {}: {c}",
                        x["frame"]
                    );
                }
            }
        }
        let check = |metric: &str, threshold: &str, frames: &str| {
            let report = tmp.path().join(format!("{name}-{metric}"));
            let (ga, ub) = (
                subset(&ga, frames, tmp.path()),
                subset(&ub, frames, tmp.path()),
            );
            let output = mipray(&[
                "diff",
                ga.to_str().unwrap(),
                ub.to_str().unwrap(),
                "--metric",
                metric,
                "--threshold",
                threshold,
                "--out",
                report.to_str().unwrap(),
            ]);
            assert!(
                output.status.success(),
                "{name}: {metric} outside {threshold}: {}",
                std::fs::read_to_string(report.join("diff.md")).unwrap_or_default()
            );
        };
        match expect {
            Expect::Alike | Expect::Resampled => {
                check("psnr", "40", "all");
                check("flip", "0.01", "all");
            }
            Expect::RebakedKeys => check("psnr", "40", "first"),
            Expect::OtherMaterial => {
                for i in 0..40 {
                    let frame = format!("frame_{i:04}.png");
                    assert_eq!(
                        silhouette(&ga.join(&frame)),
                        silhouette(&ub.join(&frame)),
                        "{name} {frame}: silhouettes differ"
                    );
                }
            }
        }
    }
}

/// `dir` itself for "all", or a copy holding only its first frame.
fn subset(dir: &Path, frames: &str, tmp: &Path) -> PathBuf {
    if frames == "all" {
        return dir.to_path_buf();
    }
    let copy = tmp.join(format!(
        "{}-first",
        dir.file_name().unwrap().to_str().unwrap()
    ));
    std::fs::create_dir_all(&copy).unwrap();
    std::fs::copy(dir.join("frame_0000.png"), copy.join("frame_0000.png")).unwrap();
    copy
}

/// Which pixels show something other than the background (the top-left pixel's colour).
fn silhouette(png: &Path) -> Vec<bool> {
    let image = image::open(png).unwrap().to_rgb8();
    let background = *image.get_pixel(0, 0);
    image.pixels().map(|p| *p != background).collect()
}

/// A 3x3-vertex grid of 8 triangles whose points are sampled at time codes 0, 10 and 20:
/// between 0 and 10 only the centre vertex moves, between 10 and 20 only a corner.
const POINT_CACHE: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
    timeCodesPerSecond = 24
    framesPerSecond = 24
    startTimeCode = 0
    endTimeCode = 30
)

def Mesh "Grid"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3, 3, 3, 3, 3, 3, 3, 3]
    int[] faceVertexIndices = [0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4, 3, 4, 7, 3, 7, 6, 4, 5, 8, 4, 8, 7]
    point3f[] points.timeSamples = {
        0: [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0), (0, 2, 0), (1, 2, 0), (2, 2, 0)],
        10: [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0.5), (2, 1, 0), (0, 2, 0), (1, 2, 0), (2, 2, 0)],
        20: [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0.5), (2, 1, 0), (0, 2, 0), (1, 2, 0), (2, 2, 0.75)],
    }
}
"#;

#[test]
fn a_point_cache_marks_exactly_the_changed_triangles_deformed() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cache.usda");
    std::fs::write(&path, POINT_CACHE).unwrap();
    let scene = mipray::scene::load(&path).unwrap();
    assert!(scene.meshes[0].primitives[0].point_cache.is_some());
    let out = tmp.path().join("out");
    // The stage's own frames: one per time code, 0..=30.
    render(&path, &out, &[]);
    let records = records(&out);
    assert_eq!(records.len(), 31);
    let indices = [
        0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4, 3, 4, 7, 3, 7, 6, 4, 5, 8, 4, 8, 7,
    ];
    let touching = |v: u32| indices.chunks(3).filter(|t| t.contains(&v)).count() as u64;
    for r in &records[1..] {
        let frame = counter(r, "frame");
        let expected = match frame {
            1..=10 => touching(4),  // the centre: 6 triangles
            11..=20 => touching(8), // the corner: 2 triangles
            _ => 0,                 // held after the last sample
        };
        assert_eq!(
            counter(r, "deformed_triangles"),
            expected,
            "frame {frame}: {r}"
        );
        assert_eq!(
            counter(r, "moved_triangles"),
            expected,
            "frame {frame}: {r}"
        );
        assert_eq!(counter(r, "nonfinite_samples"), 0);
    }
}

/// Two cameras of different lenses: the first is used by default, `--camera` picks the
/// other by prim name or path (the exported camera shows which), and an unknown name is an
/// error listing the cameras.
#[test]
fn camera_flag_picks_a_camera_by_prim_name_or_path() {
    let stage = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)
def Mesh "Tri"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}
def Camera "wide"
{
    float focalLength = 10
    float verticalAperture = 20
    double3 xformOp:translate = (0, 0, 5)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
def Xform "rig"
{
    def Camera "tele"
    {
        float focalLength = 100
        float verticalAperture = 20
        double3 xformOp:translate = (0, 0, 50)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
}
"#;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cameras.usda");
    std::fs::write(&path, stage).unwrap();
    let yfov_of = |camera: Option<&str>| {
        let out = tmp.path().join(format!(
            "export-{}",
            camera.unwrap_or("default").replace('/', "_")
        ));
        let mut args = vec![
            "export",
            path.to_str().unwrap(),
            "--frames",
            "0",
            "--out",
            out.to_str().unwrap(),
        ];
        if let Some(c) = camera {
            args.extend(["--camera", c]);
        }
        let output = mipray(&args);
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let json: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("camera_0000.json")).unwrap())
                .unwrap();
        json["yfov_degrees"].as_f64().unwrap()
    };
    let wide = (2.0 * (20.0f64 / 20.0).atan()).to_degrees();
    let tele = (2.0 * (20.0f64 / 200.0).atan()).to_degrees();
    assert!((yfov_of(None) - wide).abs() < 1e-3);
    assert!((yfov_of(Some("tele")) - tele).abs() < 1e-3);
    assert!((yfov_of(Some("/rig/tele")) - tele).abs() < 1e-3);
    assert!((yfov_of(Some("wide")) - wide).abs() < 1e-3);
    let output = mipray(&[
        "render",
        path.to_str().unwrap(),
        "--camera",
        "zoom",
        "--frames",
        "0",
    ]);
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("\"/wide\"") && stderr.contains("\"/rig/tele\""),
        "{stderr}"
    );
}

/// UsdLux lights and UsdPreviewSurface materials map as `docs/src/formats-usd.md` says.
#[test]
fn lights_and_materials_map_as_documented() {
    let stage = r#"#usda 1.0
(
    metersPerUnit = 0.5
    upAxis = "Y"
)
def Mesh "Glass"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    texCoord2f[] primvars:uv1 = [(0, 0), (1, 0), (0, 1)] (interpolation = "vertex")
    rel material:binding = </M/Glass>
}
def Mesh "Textured"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 1), (1, 0, 1), (0, 1, 1)]
    texCoord2f[] primvars:uv1 = [(0, 0), (1, 0), (0, 1)] (interpolation = "vertex")
    rel material:binding = </M/Tex>
}
def Scope "M"
{
    def Material "Glass"
    {
        token outputs:surface.connect = </M/Glass/S.outputs:surface>
        def Shader "S"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (0.2, 0.4, 0.6)
            float inputs:opacity = 0.25
            float inputs:ior = 1.33
            float inputs:metallic = 1.0
            float inputs:roughness = 0.0
            token outputs:surface
        }
    }
    def Material "Tex"
    {
        token outputs:surface.connect = </M/Tex/S.outputs:surface>
        def Shader "S"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </M/Tex/T.outputs:rgb>
            token outputs:surface
        }
        def Shader "R"
        {
            uniform token info:id = "UsdPrimvarReader_float2"
            token inputs:varname = "uv1"
            float2 outputs:result
        }
        def Shader "T"
        {
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @checker.png@
            float2 inputs:st.connect = </M/Tex/R.outputs:result>
            token inputs:wrapS = "mirror"
            token inputs:wrapT = "black"
            float4 inputs:scale = (0.5, 0.5, 0.5, 1)
            float3 outputs:rgb
        }
    }
}
def SphereLight "Bulb" { float inputs:intensity = 10  float inputs:exposure = 1  float inputs:radius = 2 }
def RectLight "Panel" { float inputs:intensity = 3  float inputs:width = 2  float inputs:height = 4 }
def DiskLight "Spot" (prepend apiSchemas = ["ShapingAPI"]) { float inputs:intensity = 1  float inputs:shaping:cone:angle = 30  float inputs:shaping:cone:softness = 0.5 }
def DistantLight "Sun" { float intensity = 2  color3f color = (1, 0.5, 0.25) }
"#;
    use mipray::scene::LightKind;
    use mipray::texture::WrapMode;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("looks.usda");
    std::fs::write(&path, stage).unwrap();
    image::RgbImage::from_fn(4, 4, |x, y| {
        image::Rgb(if (x + y) % 2 == 0 { [255; 3] } else { [0; 3] })
    })
    .save(tmp.path().join("checker.png"))
    .unwrap();
    let scene = mipray::scene::load(&path).unwrap();
    let material =
        |mesh: usize| &scene.materials[scene.meshes[mesh].primitives[0].material.unwrap()];
    let glass = material(0);
    assert_eq!(glass.transmission, 0.75);
    assert_eq!(glass.ior, 1.33);
    assert_eq!(glass.reflectance, 1.0, "a smooth metal is a mirror");
    assert_eq!(glass.base_color, glam::Vec3::new(0.2, 0.4, 0.6));
    assert!(glass.base_color_texture.is_none());
    let textured = material(1);
    let texture = &scene.textures[textured.base_color_texture.unwrap()];
    assert_eq!(texture.sampler.wrap_s, WrapMode::MirroredRepeat);
    assert_eq!(texture.sampler.wrap_t, WrapMode::ClampToEdge);
    assert_eq!(
        textured.base_color,
        glam::Vec3::splat(0.5),
        "the texture's scale"
    );
    // The uvs come from primvar uv1, t flipped to v.
    let uvs = scene.meshes[1].primitives[0].uvs.as_ref().unwrap();
    assert_eq!(uvs[0], glam::Vec2::new(0.0, 1.0));
    assert!(
        scene.notes.iter().any(|n| n.contains("'black' wrap")),
        "{:?}",
        scene.notes
    );
    // Lights: radii and sizes in metres (metersPerUnit 0.5).
    let light = |name: &str| {
        let node = scene.nodes.iter().find(|n| n.name == name).unwrap();
        scene.lights[node.light.unwrap()]
    };
    let pi = std::f32::consts::PI;
    let bulb = light("/Bulb");
    assert_eq!(bulb.kind, LightKind::Point);
    assert!((bulb.intensity - 20.0 * pi * 1.0).abs() < 1e-4, "{bulb:?}");
    let panel = light("/Panel");
    assert!(
        matches!(panel.kind, LightKind::Spot { outer_cone, .. } if (outer_cone - pi / 2.0).abs() < 1e-6)
    );
    assert!(
        (panel.intensity - 3.0 * 1.0 * 2.0).abs() < 1e-5,
        "{panel:?}"
    );
    let spot = light("/Spot");
    match spot.kind {
        LightKind::Spot {
            inner_cone,
            outer_cone,
        } => {
            assert!((outer_cone - 30f32.to_radians()).abs() < 1e-6);
            assert!((inner_cone - 15f32.to_radians()).abs() < 1e-6);
        }
        other => panic!("{other:?}"),
    }
    let sun = light("/Sun");
    assert_eq!(sun.kind, LightKind::Directional);
    assert_eq!(sun.intensity, 2.0);
    assert_eq!(sun.color, glam::Vec3::new(1.0, 0.5, 0.25));
}

/// A USDA file with a character its grammar does not allow: the error names the file and
/// says so in words (the lexer itself reports only `Logos error: ()`).
#[test]
fn a_damaged_usda_file_is_an_error_in_words() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("damaged.usda");
    std::fs::write(&path, "#usda 1.0\n$\n").unwrap();
    let out = mipray(&["info", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(stderr.contains("damaged.usda"), "{stderr}");
    assert!(stderr.contains("does not allow"), "{stderr}");
    assert!(!stderr.contains("Logos"), "{stderr}");
}

/// A stage written to a temporary folder and loaded through the library.
fn load_text(text: &str) -> (tempfile::TempDir, Result<mipray::scene::SceneDesc, String>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stage.usda");
    std::fs::write(&path, text).unwrap();
    let scene = mipray::scene::load(&path).map_err(|e| e.to_string());
    (dir, scene)
}

/// A triangle mesh prim named `name` with extra lines `body`.
fn triangle(name: &str, body: &str) -> String {
    format!(
        r#"def Mesh "{name}"
{{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    {body}
}}
"#
    )
}

/// Names that cannot name a prim are refused in words. Two of them (`""` at the root, `.`
/// anywhere) made the stage's traversal run forever; the test runs on a watchdog thread so
/// a regression fails instead of hanging the suite.
#[test]
fn prims_that_cannot_be_named_are_refused_instead_of_hanging() {
    let cases = [
        (
            "#usda 1.0\ndef Xform \"\"\n{\n}\n",
            "the root of the stage is named \"\"",
        ),
        (
            "#usda 1.0\ndef Xform \"A\"\n{\n    def Xform \".\"\n    {\n    }\n}\n",
            "/A is named \".\"",
        ),
    ];
    for (text, expected) in cases {
        let (sender, receiver) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = sender.send(load_text(text).1.map(|_| ()));
        });
        let result = receiver
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("loading the stage did not end within a minute");
        let error = result.expect_err("a prim without a valid name loaded");
        assert!(error.contains(expected), "{error}");
    }
    // The check enters only what the stage draws: below an `over` (never drawn) a reference
    // to a layer that does not exist is never composed, and the stage loads.
    let (_dir, scene) = load_text(&format!(
        "#usda 1.0\nover \"Unused\"\n{{\n    def Scope \"M\" (references = @missing.usda@)\n    {{\n    }}\n}}\n{}",
        triangle("Drawn", "")
    ));
    assert_eq!(scene.unwrap().meshes.len(), 1);
}

/// A SkelRoot holding a one-joint skeleton (with `skeleton_line` among its properties) and
/// a triangle skinned to it (with `mesh_line` among its properties).
fn skinned_stage(skeleton_line: &str, mesh_line: &str) -> String {
    format!(
        r#"#usda 1.0
def SkelRoot "Root"
{{
    def Skeleton "Skel" (prepend apiSchemas = ["SkelBindingAPI"])
    {{
        {skeleton_line}
        uniform token[] joints = ["a"]
        uniform matrix4d[] bindTransforms = [( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) )]
        uniform matrix4d[] restTransforms = [( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (2, 0, 0, 1) )]
    }}
    {}
}}
"#,
        triangle(
            "m",
            &format!(
                r#"int[] primvars:skel:jointIndices = [0, 0, 0] (interpolation = "vertex" elementSize = 1)
    float[] primvars:skel:jointWeights = [1, 1, 1] (interpolation = "vertex" elementSize = 1)
    {mesh_line}
    rel skel:skeleton = </Root/Skel>"#
            )
        )
    )
}

/// A skeleton marked `guide` (as exporters often do) or hidden still skins its meshes: it is
/// never drawn, only read.
#[test]
fn a_guide_skeleton_still_skins_its_meshes() {
    for skeleton_line in [
        "uniform token purpose = \"guide\"",
        "token visibility = \"invisible\"",
        "",
    ] {
        let (_dir, scene) = load_text(&skinned_stage(skeleton_line, ""));
        let scene = scene.unwrap_or_else(|e| panic!("{skeleton_line}: {e}"));
        assert_eq!(scene.skins.len(), 1, "{skeleton_line}: {:?}", scene.notes);
    }
    // Dual-quaternion skinning is skinned with linear blending, and said so.
    let text = skinned_stage(
        "",
        "uniform token primvars:skel:skinningMethod = \"dualQuaternion\"",
    );
    let scene = load_text(&text).1.unwrap();
    assert!(
        scene.notes.iter().any(|n| n.contains("dual quaternion")),
        "{:?}",
        scene.notes
    );
    // Only below a SkelRoot does UsdSkel skin: elsewhere the mesh's own points hold.
    let scene = load_text(&text.replace("def SkelRoot", "def Xform"))
        .1
        .unwrap();
    assert!(scene.skins.is_empty(), "{:?}", scene.notes);
    assert!(
        scene
            .notes
            .iter()
            .any(|n| n.contains("not below a SkelRoot")),
        "{:?}",
        scene.notes
    );
}

/// The usual way to colour a mesh by its `displayColor` in a material (a
/// `UsdPrimvarReader_float3` into `diffuseColor`) gives each mesh its own colour; a missing
/// image and a binding to nothing fall back as USD does, with notes instead of errors.
#[test]
fn materials_fall_back_as_usd_does() {
    let text = format!(
        r#"#usda 1.0
{}{}{}{}
def Scope "M"
{{
    def Material "ByColor"
    {{
        token outputs:surface.connect = </M/ByColor/S.outputs:surface>
        def Shader "S"
        {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </M/ByColor/P.outputs:result>
            token outputs:surface
        }}
        def Shader "P"
        {{
            uniform token info:id = "UsdPrimvarReader_float3"
            token inputs:varname = "displayColor"
            float3 inputs:fallback = (0.5, 0.5, 0.5)
            float3 outputs:result
        }}
    }}
    def Material "NoImage"
    {{
        token outputs:surface.connect = </M/NoImage/S.outputs:surface>
        def Shader "S"
        {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </M/NoImage/T.outputs:rgb>
            token outputs:surface
        }}
        def Shader "T"
        {{
            uniform token info:id = "UsdUVTexture"
            float4 inputs:fallback = (0.1, 0.2, 0.3, 1)
            float3 outputs:rgb
        }}
    }}
}}
"#,
        triangle(
            "Red",
            "color3f[] primvars:displayColor = [(1, 0, 0)]\n    rel material:binding = </M/ByColor>"
        ),
        triangle(
            "Green",
            "color3f[] primvars:displayColor = [(0, 1, 0)]\n    rel material:binding = </M/ByColor>"
        ),
        triangle("Plain", "rel material:binding = </M/NoImage>"),
        triangle(
            "Orphan",
            "color3f[] primvars:displayColor = [(0, 0, 1)]\n    rel material:binding = </M/Gone>"
        ),
    );
    let (_dir, scene) = load_text(&text);
    let scene = scene.unwrap();
    let colour = |name: &str| {
        let node = scene.nodes.iter().find(|n| n.name == name).unwrap();
        let mesh = &scene.meshes[node.mesh.unwrap()];
        scene.materials[mesh.primitives[0].material.unwrap()].base_color
    };
    assert_eq!(colour("/Red"), glam::Vec3::new(1.0, 0.0, 0.0));
    assert_eq!(colour("/Green"), glam::Vec3::new(0.0, 1.0, 0.0));
    assert_eq!(colour("/Plain"), glam::Vec3::new(0.1, 0.2, 0.3));
    assert_eq!(colour("/Orphan"), glam::Vec3::new(0.0, 0.0, 1.0));
    for note in ["without an image", "target a prim that does not exist"] {
        assert!(
            scene.notes.iter().any(|n| n.contains(note)),
            "{note}: {:?}",
            scene.notes
        );
    }
}

/// openusd does not enter an instance nested in another instance: the missing geometry is
/// noted, not silent.
#[test]
fn an_unexpanded_nested_instance_is_noted() {
    let text = format!(
        r#"#usda 1.0
def Xform "Protos"
{{
    def Xform "Leaf"
    {{
        {}
    }}
    def Xform "Set"
    {{
        def Xform "a" (instanceable = true references = </Protos/Leaf>)
        {{
        }}
    }}
}}
def Xform "World"
{{
    def Xform "set1" (instanceable = true references = </Protos/Set>)
    {{
    }}
}}
"#,
        triangle("tri", "")
    );
    let (_dir, scene) = load_text(&text);
    let scene = scene.unwrap();
    assert!(
        scene
            .notes
            .iter()
            .any(|n| n.contains("/World/set1/a: an instance inside an instance")),
        "{:?}",
        scene.notes
    );
}

/// What a stage asks for that mipray does not do is noted: an off-centre aperture, and a
/// time code range longer than a stage's own range gives.
#[test]
fn aperture_offsets_and_overlong_ranges_are_noted() {
    let text = r#"#usda 1.0
(
    startTimeCode = 0
    endTimeCode = 100000000
)
def Camera "Cam"
{
    float horizontalApertureOffset = 3
}
"#;
    let scene = load_text(text).1.unwrap();
    for note in [
        "/Cam.horizontalApertureOffset is ignored",
        "asks for more than 1000001 frames",
    ] {
        assert!(
            scene.notes.iter().any(|n| n.contains(note)),
            "{note}: {:?}",
            scene.notes
        );
    }
}

/// USD's text format allows C-style comments and whitespace after the header; openusd's
/// reader does not, so the loader hands it the layer without them.
#[test]
fn c_style_comments_and_a_loose_header_load() {
    let text = format!(
        "#usda 1.0 \n// a line comment\n/* a block\n   comment */\n{}",
        triangle("Drawn", "// after a property")
    );
    let (_dir, scene) = load_text(&text);
    assert_eq!(scene.unwrap().meshes.len(), 1);
}

/// The one triangle of a stage's one mesh: its three corners and their normals.
fn only_triangle(scene: &mipray::scene::SceneDesc) -> (Vec<[f32; 3]>, Option<Vec<[f32; 3]>>) {
    assert_eq!(scene.meshes.len(), 1);
    let primitive = &scene.meshes[0].primitives[0];
    assert_eq!(primitive.indices.len(), 3);
    let corners = |values: &[glam::Vec3]| {
        primitive
            .indices
            .iter()
            .map(|&i| values[i as usize].to_array())
            .collect::<Vec<_>>()
    };
    (
        corners(&primitive.positions),
        primitive.normals.as_deref().map(corners),
    )
}

/// USD's text format writes numbers without a digit on one side of the point (`.5`, `0.`,
/// `1.e5`); openusd's reader does not, so the loader gives them the digit.
#[test]
fn numbers_with_a_bare_point_load_with_their_values() {
    let text = r#"#usda 1.0
(
    startTimeCode = 0.
    endTimeCode = 1.e1
)
def Mesh "M"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(.5, -.25, 0.), (1.e1, 0, 5.E-1), (0, 1., -0.)]
}
"#;
    let scene = load_text(text).1.unwrap();
    let (corners, _) = only_triangle(&scene);
    assert_eq!(
        corners,
        [[0.5, -0.25, 0.0], [10.0, 0.0, 0.5], [0.0, 1.0, 0.0]]
    );
    let times = scene.frame_times.expect("the stage's own range");
    assert_eq!(times.frames, 11);
}

/// Legacy value type names USD still reads (`PointFloat`, `NormalFloat`, `Vec3f`, ...) and
/// `config` variability, as older exporters wrote them.
#[test]
fn legacy_type_names_load_as_the_types_they_stand_for() {
    let text = r#"#usda 1.0
def Mesh "M" (
    customData = {
        Vec3f pivot = (1, 2, 3)
    }
)
{
    config token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    PointFloat[] points = [(0, 0, 0), (2, 0, 0), (0, 3, 0)]
    NormalFloat[] normals = [(0, 0, 1), (0, 0, 1), (0, 0, 1)] (
        interpolation = "vertex"
    )
    custom Color tint = (1, 0.5, 0.25)
}
"#;
    let scene = load_text(text).1.unwrap();
    let (corners, normals) = only_triangle(&scene);
    assert_eq!(corners, [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0]]);
    assert_eq!(normals, Some(vec![[0.0, 0.0, 1.0]; 3]));
    // `config` reads as `uniform`: the authored scheme holds, so no subdivision note.
    assert!(
        !scene.notes.iter().any(|n| n.contains("subdivision")),
        "{:?}",
        scene.notes
    );
}

/// `uint[]` arrays (openusd reads no unsigned arrays) load as `int64[]`, which holds every
/// `uint` value.
#[test]
fn unsigned_integer_arrays_load() {
    let text = r#"#usda 1.0
def Mesh "M"
{
    uniform token subdivisionScheme = "none"
    uint[] faceVertexCounts = [3]
    uint[] faceVertexIndices = [2, 0, 1]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    uint64[] ids = [18446744073]
}
"#;
    let scene = load_text(text).1.unwrap();
    let (corners, _) = only_triangle(&scene);
    assert_eq!(corners, [[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]);
    // A `uint64` past the largest `int64` is refused, not altered.
    let (_dir, scene) = load_text(&text.replace("18446744073", "18446744073709551615"));
    let error = scene.map(|_| ()).unwrap_err();
    assert!(
        error.contains("stage.usda") && error.contains("18446744073709551615"),
        "{error}"
    );
}

/// An `upAxis` USD does not allow (only Y and Z) is read as USD's own tools read it: USD
/// returns the token as authored and usdview treats every axis but Z as Y. So the stage is
/// not turned, and a note says so.
#[test]
fn an_x_up_axis_reads_as_y_with_a_note() {
    let stage = |axis: &str| {
        format!(
            "#usda 1.0\n(\n    upAxis = \"{axis}\"\n    metersPerUnit = 1\n)\n{}",
            triangle("M", "")
        )
    };
    let turned = |scene: &mipray::scene::SceneDesc| {
        scene
            .nodes
            .iter()
            .any(|n| n.name.starts_with("stage (upAxis"))
    };
    let z = load_text(&stage("Z")).1.unwrap();
    assert!(turned(&z));
    let x = load_text(&stage("X")).1.unwrap();
    assert!(!turned(&x));
    let (corners, _) = only_triangle(&x);
    assert_eq!(corners, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    assert!(
        x.notes
            .iter()
            .any(|n| n.contains("upAxis \"X\"") && n.contains("read as Y")),
        "{:?}",
        x.notes
    );
}

/// A time code range that ends before it starts is empty to usdview (a warning, no
/// playback, the stage shown at time code 0): it gives one frame at time 0, noted.
#[test]
fn a_reversed_time_code_range_gives_one_frame_at_time_zero() {
    let text = format!(
        "#usda 1.0\n(\n    startTimeCode = 10\n    endTimeCode = 2\n)\n{}",
        triangle("M", "")
    );
    let scene = load_text(&text).1.unwrap();
    let times = scene.frame_times.expect("a frame sequence");
    assert_eq!((times.start, times.end, times.frames), (0.0, 0.0, 1));
    assert!(
        scene
            .notes
            .iter()
            .any(|n| n.contains("startTimeCode 10 is after endTimeCode 2")),
        "{:?}",
        scene.notes
    );
}

/// A parse error in a text layer names the layer and the line it is on (openusd's reader
/// reports none), for the root layer and for a sublayer.
#[test]
fn a_text_parse_error_names_its_layer_and_line() {
    let (dir, root) = load_text(&format!(
        "#usda 1.0\n// a comment\n{}def Xform \"X\" {{\n    double a = = 1\n}}\n",
        triangle("M", "")
    ));
    let error = root.map(|_| ()).unwrap_err();
    let at = format!("{}:12:", dir.path().join("stage.usda").display()); // the `double` line
    assert!(error.contains(&at), "{error}");

    let sub = dir.path().join("sub.usda");
    std::fs::write(
        &sub,
        "#usda 1.0\n\ndef Xform \"S\"\n{\n    point3f[] p = [(.5, 0, 0)]\n    double b = = 1\n}\n",
    )
    .unwrap();
    let root = dir.path().join("root.usda");
    std::fs::write(&root, "#usda 1.0\n(\n    subLayers = [@./sub.usda@]\n)\n").unwrap();
    let error = mipray::scene::load(&root)
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(error.contains("root.usda"), "{error}");
    assert!(error.contains("sub.usda:6:"), "{error}");
}

/// A primvar reader's `varname` is any token (empty by default): one that names no
/// property (here the empty name, `primvars:`) names no primvar the mesh has, so the mesh
/// loads untextured with a note, as for any primvar it lacks.
#[test]
fn a_primvar_reader_naming_no_property_leaves_the_mesh_untextured() {
    let stage = |varname: &str| {
        format!(
            r#"#usda 1.0
{}def Material "Tex"
{{
    token outputs:surface.connect = </Tex/S.outputs:surface>
    def Shader "S"
    {{
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor.connect = </Tex/T.outputs:rgb>
        token outputs:surface
    }}
    def Shader "R"
    {{
        uniform token info:id = "UsdPrimvarReader_float2"
        token inputs:varname = "{varname}"
        float2 outputs:result
    }}
    def Shader "T"
    {{
        uniform token info:id = "UsdUVTexture"
        asset inputs:file = @checker.png@
        float2 inputs:st.connect = </Tex/R.outputs:result>
        float3 outputs:rgb
    }}
}}
"#,
            triangle(
                "Tri",
                "texCoord2f[] primvars:st = [(0, 0), (1, 0), (0, 1)] (interpolation = \"vertex\")\n    rel material:binding = </Tex>"
            )
        )
    };
    let tmp = tempfile::tempdir().unwrap();
    image::RgbImage::from_pixel(2, 2, image::Rgb([200; 3]))
        .save(tmp.path().join("checker.png"))
        .unwrap();
    let load = |varname: &str| {
        let path = tmp.path().join("reader.usda");
        std::fs::write(&path, stage(varname)).unwrap();
        mipray::scene::load(&path).unwrap()
    };
    let named = load("st");
    assert!(named.meshes[0].primitives[0].uvs.is_some());
    for varname in ["", "s}t"] {
        let scene = load(varname);
        assert!(scene.meshes[0].primitives[0].uvs.is_none(), "{varname:?}");
        let note = format!("reads primvar '{varname}', which the mesh does not have");
        assert!(
            scene.notes.iter().any(|n| n.contains(&note)),
            "{varname:?}: {:?}",
            scene.notes
        );
    }
}
