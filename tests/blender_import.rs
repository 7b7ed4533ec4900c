//! An exported frame in Blender: `mipray export default --frames 24`, then
//! `blender -b --python tests/blender/check_import.py` imports the OBJ with the guide's axes
//! (File > Import > Wavefront (.obj)), runs the guide's camera script, and prints what came
//! in. Checked against the exported files: face, material, textured-material and image
//! counts exactly; glass as transmission with its IOR, alpha 1, not metallic, smooth; every
//! vertex at the guide's axis conversion of its OBJ position; the camera's location,
//! rotation, vertical field of view and resolution against `camera_0024.json` (within 1e-4);
//! and every vertex in front of the camera projecting where mipray's primary-ray convention
//! puts it.
//!
//! Without `blender` on the PATH the test prints that it skipped (Debian package `blender`,
//! 3.4). It is not run in CI (.ci/run does not install Blender).

/// The guide page whose Blender steps and camera script this test follows.
const GUIDE_PAGE: &str = "docs/src/export.md";

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

const FRAME: u32 = 24;
const BLENDER_TIMEOUT: Duration = Duration::from_secs(180);
const TOLERANCE: f64 = 1e-4;
const RECORD_PREFIX: &str = "MIPRAY_BLENDER_CHECK ";

fn manifest_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn blender_on_path() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("blender"))
        .find(|candidate| candidate.is_file())
}

/// Runs `command` with stdout and stderr in files (the record is larger than a pipe's
/// buffer), killing it after `timeout`. Returns (success, stdout, stderr).
fn run_to_files(mut command: Command, dir: &Path, timeout: Duration) -> (bool, String, String) {
    let (out, err) = (dir.join("blender.stdout"), dir.join("blender.stderr"));
    let mut child = command
        .stdin(Stdio::null())
        .stdout(File::create(&out).unwrap())
        .stderr(File::create(&err).unwrap())
        .spawn()
        .expect("start blender");
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > timeout {
            child.kill().ok();
            child.wait().ok();
            break None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
    let ok = status.is_some_and(|s| s.success());
    if status.is_none() {
        eprintln!("blender ran longer than {timeout:?} and was killed");
    }
    (ok, read(&out), read(&err))
}

// ------------------------------------------------------------------ the exported files

/// What the exported OBJ and MTL say Blender should show.
struct Exported {
    faces: usize,
    /// `v` lines in file order, mipray coordinates.
    vertices: Vec<[f64; 3]>,
    /// Materials named by `usemtl`.
    used: BTreeSet<String>,
    /// MTL entries by name.
    mtl: BTreeMap<String, MtlEntry>,
}

#[derive(Default)]
struct MtlEntry {
    map_kd: Option<String>,
    ior: Option<f64>,
    transmission: Option<f64>,
}

fn numbers(rest: &str) -> Vec<f64> {
    rest.split_whitespace()
        .map(|w| w.parse().unwrap())
        .collect()
}

fn read_exported(dir: &Path) -> Exported {
    let obj = std::fs::read_to_string(dir.join(format!("frame_{FRAME:04}.obj"))).unwrap();
    let mut exported = Exported {
        faces: 0,
        vertices: Vec::new(),
        used: BTreeSet::new(),
        mtl: BTreeMap::new(),
    };
    for line in obj.lines() {
        let (key, rest) = line.split_once(' ').unwrap_or((line, ""));
        match key {
            "f" => exported.faces += 1,
            "v" => exported.vertices.push(numbers(rest).try_into().unwrap()),
            "usemtl" => {
                exported.used.insert(rest.trim().to_string());
            }
            _ => {}
        }
    }
    let mtl = std::fs::read_to_string(dir.join("materials.mtl")).unwrap();
    let mut current = None;
    for line in mtl.lines() {
        let (key, rest) = line.split_once(' ').unwrap_or((line, ""));
        if key == "newmtl" {
            current = Some(rest.trim().to_string());
            exported
                .mtl
                .insert(rest.trim().to_string(), MtlEntry::default());
            continue;
        }
        let Some(entry) = current.as_ref().and_then(|c| exported.mtl.get_mut(c)) else {
            continue;
        };
        match key {
            // The file name is the last word (after any `-clamp on`).
            "map_Kd" => entry.map_kd = rest.split_whitespace().last().map(String::from),
            "Ni" => entry.ior = Some(numbers(rest)[0]),
            "mipray_transmission" => entry.transmission = Some(numbers(rest)[0]),
            _ => {}
        }
    }
    exported
}

// ------------------------------------------------------------------ conversions

/// The guide's conversion: mipray (+Y up, -Z forward) -> Blender (+Z up).
fn to_blender(v: [f64; 3]) -> [f64; 3] {
    [v[0], -v[2], v[1]]
}

fn vec3(v: &Value) -> [f64; 3] {
    let a: Vec<f64> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    a.try_into().unwrap()
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

/// Where mipray's primary-ray convention (camera JSON: `forward + sx tan aspect right +
/// sy tan up`, `sx`, `sy` in [-1, 1], `sy` up) puts world point `p`, in Blender's camera-view
/// coordinates: x, y in [0, 1] from the bottom-left, and the depth along `forward`.
fn mipray_view(camera: &Value, p: [f64; 3]) -> [f64; 3] {
    let eye = vec3(&camera["eye"]);
    let d = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
    let depth = dot(d, vec3(&camera["forward"]));
    let tan = camera["tan_half_fov"].as_f64().unwrap();
    let aspect = camera["aspect"].as_f64().unwrap();
    let sx = dot(d, vec3(&camera["right"])) / depth / (tan * aspect);
    let sy = dot(d, vec3(&camera["up"])) / depth / tan;
    [(sx + 1.0) / 2.0, (sy + 1.0) / 2.0, depth]
}

// ------------------------------------------------------------------ the checks

fn check_counts(record: &Value, exported: &Exported, dir: &Path) {
    assert_eq!(record["objects"], 1, "one object, o frame_{FRAME:04}");
    assert_eq!(record["faces"].as_u64().unwrap() as usize, exported.faces);
    let materials = record["materials"].as_array().unwrap();
    let names: BTreeSet<String> = materials
        .iter()
        .map(|m| m["name"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(names, exported.used, "materials: one per usemtl");

    let textured: BTreeMap<String, PathBuf> = exported
        .used
        .iter()
        .filter_map(|name| Some((name.clone(), dir.join(exported.mtl[name].map_kd.as_ref()?))))
        .collect();
    assert!(!textured.is_empty(), "the default scene has textures");
    for m in materials {
        let name = m["name"].as_str().unwrap();
        let image = m["image"].as_str().map(PathBuf::from);
        assert_eq!(image, textured.get(name).cloned(), "{name}'s base colour");
    }
    let images = record["images"].as_array().unwrap();
    let distinct: BTreeSet<&PathBuf> = textured.values().collect();
    assert_eq!(images.len(), distinct.len(), "one image per texture file");
    for image in images {
        let path = PathBuf::from(image["path"].as_str().unwrap());
        let (w, h) = image::image_dimensions(&path).expect("an exported texture");
        assert_eq!(
            image["size"],
            serde_json::json!([w, h]),
            "{}",
            path.display()
        );
    }
}

fn check_glass(record: &Value, exported: &Exported) {
    let mut glass = 0;
    for m in record["materials"].as_array().unwrap() {
        let name = m["name"].as_str().unwrap();
        let entry = &exported.mtl[name];
        let value = |key: &str| m[key].as_f64().unwrap();
        let transmission = entry.transmission.expect("mipray_transmission");
        assert!(
            close(value("transmission"), transmission, 1e-6),
            "{name}: {m}"
        );
        assert_eq!(value("alpha"), 1.0, "{name} is not dissolved: {m}");
        if transmission > 0.0 {
            glass += 1;
            assert!(close(value("ior"), entry.ior.unwrap(), 1e-6), "{name}: {m}");
            assert_eq!(value("metallic"), 0.0, "{name}: {m}");
            assert_eq!(value("roughness"), 0.0, "{name}: {m}");
        }
    }
    assert!(glass > 0, "the default scene's frame shows glass");
}

fn check_camera(record: &Value, camera: &Value) {
    let c = &record["camera"];
    let location = vec3(&c["location"]);
    let eye = to_blender(vec3(&camera["eye"]));
    for k in 0..3 {
        assert!(
            close(location[k], eye[k], TOLERANCE),
            "location {location:?} vs eye {eye:?}"
        );
    }
    // Columns of the camera's rotation: its local +X, +Y, +Z = right, up, -forward.
    let rows: Vec<[f64; 3]> = c["rotation"].as_array().unwrap().iter().map(vec3).collect();
    let back = vec3(&camera["forward"]).map(|x| -x);
    for (column, axis) in [vec3(&camera["right"]), vec3(&camera["up"]), back]
        .into_iter()
        .enumerate()
    {
        let expected = to_blender(axis);
        for row in 0..3 {
            assert!(
                close(rows[row][column], expected[row], TOLERANCE),
                "rotation column {column}: {rows:?} vs {expected:?}"
            );
        }
    }
    let yfov = camera["yfov_radians"].as_f64().unwrap();
    assert!(
        close(c["angle_y"].as_f64().unwrap(), yfov, TOLERANCE),
        "{c}"
    );
    assert_eq!(c["sensor_fit"], "VERTICAL");
    assert_eq!(
        c["resolution"],
        serde_json::json!([camera["width"], camera["height"]])
    );
}

/// Every imported vertex is its OBJ position through the guide's axes, and those in front
/// of the camera project where mipray's rays see them (f32 rotations in Blender: the
/// tolerance grows with the coordinate).
fn check_vertices(record: &Value, exported: &Exported, camera: &Value) {
    let vertices = record["vertices"].as_array().unwrap();
    assert_eq!(
        vertices.len(),
        exported.vertices.len(),
        "the importer keeps every corner"
    );
    let mut in_view = 0;
    for (i, (v, obj)) in vertices.iter().zip(&exported.vertices).enumerate() {
        let v: Vec<f64> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let expected = to_blender(*obj);
        for k in 0..3 {
            let tolerance = TOLERANCE * expected[k].abs().max(1.0);
            assert!(
                close(v[k], expected[k], tolerance),
                "vertex {i}: {v:?} vs {expected:?}"
            );
        }
        let view = mipray_view(camera, *obj);
        if view[2] < 0.1 {
            continue;
        }
        for k in 0..3 {
            let tolerance = TOLERANCE * view[k].abs().max(1.0);
            assert!(
                close(v[3 + k], view[k], tolerance),
                "vertex {i} in view: {v:?} vs {view:?}"
            );
        }
        in_view +=
            (0.0..=1.0).contains(&view[0]) as usize * (0.0..=1.0).contains(&view[1]) as usize;
    }
    assert!(in_view > 100, "only {in_view} vertices in the picture");
}

#[test]
fn exported_frame_imports_into_blender_with_glass_and_the_guide_camera() {
    let Some(blender) = blender_on_path() else {
        println!("skipped: `blender` is not on the PATH (Debian package `blender`, 3.4)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let export = Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(["export", "default", "--frames", &FRAME.to_string(), "--out"])
        .arg(dir.path())
        .current_dir(manifest_dir())
        .output()
        .expect("run mipray export");
    assert!(
        export.status.success(),
        "{}",
        String::from_utf8_lossy(&export.stderr)
    );

    let guide = std::fs::read_to_string(manifest_dir().join(GUIDE_PAGE)).unwrap();
    assert!(
        guide.contains("**Forward: -Z, Up: Y**"),
        "{GUIDE_PAGE} names the axes the script imports with"
    );
    let mut command = Command::new(&blender);
    command
        .args([
            "-b",
            "--factory-startup",
            "--python-exit-code",
            "1",
            "--python",
        ])
        .arg(manifest_dir().join("tests/blender/check_import.py"))
        .arg("--")
        .arg(dir.path())
        .arg(FRAME.to_string())
        .arg(manifest_dir().join(GUIDE_PAGE));
    let (ok, stdout, stderr) = run_to_files(command, dir.path(), BLENDER_TIMEOUT);
    assert!(ok, "blender failed\nstdout:\n{stdout}\nstderr:\n{stderr}");
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix(RECORD_PREFIX))
        .unwrap_or_else(|| panic!("no {RECORD_PREFIX}line\nstdout:\n{stdout}\nstderr:\n{stderr}"));
    let record: Value = serde_json::from_str(line).unwrap();
    println!("blender {} imported the frame", record["blender_version"]);

    let exported = read_exported(dir.path());
    let camera_file = dir.path().join(format!("camera_{FRAME:04}.json"));
    let camera: Value =
        serde_json::from_str(&std::fs::read_to_string(camera_file).unwrap()).unwrap();
    check_counts(&record, &exported, dir.path());
    check_glass(&record, &exported);
    check_camera(&record, &camera);
    check_vertices(&record, &exported, &camera);
}
