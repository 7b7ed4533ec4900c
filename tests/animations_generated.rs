//! The committed `animations/` files are exactly what `mipray_authoring` generates, and
//! the default animation has the structure the renderer's experiments rely on: one 16:9
//! camera, two `KHR_lights_punctual` point lights, a repeating checker floor, a mirror,
//! a glass object, and a 1.6 s animation of the textured box. The BART-style animations
//! have theirs: `kitchen` six lights and a car hierarchy with spinning wheels, `robots` one
//! light and jointed walking robots, `museum` a morphing sculpture whose triangle count
//! follows the detail knob, a reflective floor and textured paintings; and all three
//! render through the library with the per-frame updates they are meant to exercise.
//!
//! If the first test fails after a deliberate change to the generator, regenerate with
//! `cargo run --release --example gen_animations` and commit the result.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde_json::Value;

fn committed_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("animations")
}

/// A committed scene's JSON and its `.bin`.
fn committed_scene(name: &str) -> (Value, Vec<u8>) {
    let dir = committed_dir();
    let json = std::fs::read(dir.join(format!("{name}.gltf"))).expect("the committed .gltf");
    let doc: Value = serde_json::from_slice(&json).expect("the .gltf is JSON");
    let bin_name = doc["buffers"][0]["uri"].as_str().unwrap();
    let bin = std::fs::read(dir.join(bin_name)).expect("the .bin next to the .gltf");
    (doc, bin)
}

/// The committed `default.gltf` JSON and its `.bin`.
fn default_scene() -> (Value, Vec<u8>) {
    committed_scene("default")
}

/// The floats an accessor reads (FLOAT components, tightly packed).
fn read_floats(doc: &Value, bin: &[u8], accessor: &Value) -> Vec<f32> {
    let accessor = &doc["accessors"][accessor.as_u64().unwrap() as usize];
    assert_eq!(accessor["componentType"], 5126, "FLOAT accessor");
    let view = &doc["bufferViews"][accessor["bufferView"].as_u64().unwrap() as usize];
    let start = view["byteOffset"].as_u64().unwrap_or(0) as usize
        + accessor["byteOffset"].as_u64().unwrap_or(0) as usize;
    let components = match accessor["type"].as_str().unwrap() {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" => 4,
        other => panic!("unexpected accessor type {other}"),
    };
    let count = accessor["count"].as_u64().unwrap() as usize * components;
    bin[start..start + 4 * count]
        .chunks(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

fn node_named<'a>(doc: &'a Value, name: &str) -> (usize, &'a Value) {
    doc["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .enumerate()
        .find(|(_, n)| n["name"] == name)
        .unwrap_or_else(|| panic!("no node named {name}"))
}

/// The material of the first primitive of a node's mesh.
fn node_material<'a>(doc: &'a Value, node: &Value) -> &'a Value {
    let mesh = &doc["meshes"][node["mesh"].as_u64().unwrap() as usize];
    &doc["materials"][mesh["primitives"][0]["material"].as_u64().unwrap() as usize]
}

fn approx(value: &Value, expected: f64) -> bool {
    (value.as_f64().unwrap() - expected).abs() < 1e-5
}

#[test]
fn committed_animations_are_byte_identical_to_a_fresh_generation() {
    let fresh = tempfile::tempdir().unwrap();
    let written = mipray_authoring::write_all(fresh.path()).unwrap();
    let mut generated_names = BTreeSet::new();
    for path in &written {
        let name = path.file_name().unwrap().to_str().unwrap().to_owned();
        let committed = std::fs::read(committed_dir().join(&name))
            .unwrap_or_else(|e| panic!("animations/{name} is not committed: {e}"));
        assert!(
            committed == std::fs::read(path).unwrap(),
            "animations/{name} differs from the generator's output; \
             run `cargo run --release --example gen_animations` and commit"
        );
        generated_names.insert(name);
    }
    let expected: BTreeSet<String> = [
        "default.gltf",
        "default.bin",
        "default_floor_checker.png",
        "default_box_brick.png",
        "kitchen.gltf",
        "kitchen.bin",
        "kitchen_floor_checker.png",
        "kitchen_wall_tiles.png",
        "robots.gltf",
        "robots.bin",
        "robots_asphalt.png",
        "robots_pavement.png",
        "robots_facade0.png",
        "robots_facade1.png",
        "museum.gltf",
        "museum.bin",
        "museum_floor_marble.png",
        "museum_painting0.png",
        "museum_painting1.png",
        "museum_painting2.png",
        "museum_painting3.png",
        "museum_painting4.png",
    ]
    .map(String::from)
    .into();
    assert_eq!(generated_names, expected);
    // Nothing stale: every committed file comes from the generator.
    for entry in std::fs::read_dir(committed_dir()).unwrap() {
        let name = entry.unwrap().file_name().into_string().unwrap();
        assert!(
            generated_names.contains(&name),
            "animations/{name} is not generated"
        );
    }
}

#[test]
fn committed_files_are_small() {
    let total: u64 = std::fs::read_dir(committed_dir())
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().len())
        .sum();
    assert!(total < 3 * 1024 * 1024, "animations/ holds {total} bytes");
}

#[test]
fn default_has_one_16_by_9_camera_at_eye_height() {
    let (doc, _) = default_scene();
    let cameras = doc["cameras"].as_array().unwrap();
    assert_eq!(cameras.len(), 1);
    assert_eq!(cameras[0]["type"], "perspective");
    let perspective = &cameras[0]["perspective"];
    assert!(approx(&perspective["yfov"], 50f64.to_radians()));
    assert!(approx(&perspective["aspectRatio"], 16.0 / 9.0));
    let camera_nodes: Vec<&Value> = doc["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|n| n.get("camera").is_some())
        .collect();
    assert_eq!(camera_nodes.len(), 1);
    assert_eq!(camera_nodes[0]["camera"], 0);
    assert_eq!(
        camera_nodes[0]["translation"],
        serde_json::json!([0.0, 1.6, 4.0])
    );
    // Pitched down 6 degrees about +X: quaternion (-sin 3deg, 0, 0, cos 3deg).
    let rotation = &camera_nodes[0]["rotation"];
    assert!(approx(&rotation[0], -(3f64.to_radians().sin())));
    assert!(approx(&rotation[3], 3f64.to_radians().cos()));
}

#[test]
fn default_has_two_punctual_point_lights_on_nodes() {
    let (doc, _) = default_scene();
    let used: Vec<&str> = doc["extensionsUsed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_str().unwrap())
        .collect();
    assert!(used.contains(&"KHR_lights_punctual"));
    let lights = doc["extensions"]["KHR_lights_punctual"]["lights"]
        .as_array()
        .unwrap();
    assert_eq!(lights.len(), 2);
    assert!(lights.iter().all(|l| l["type"] == "point"));
    assert_eq!(lights[0]["intensity"], 150.0);
    assert_eq!(lights[1]["intensity"], 200000.0);
    let (_, key) = node_named(&doc, "KeyLight");
    let (_, sky) = node_named(&doc, "SkyLight");
    assert_eq!(key["extensions"]["KHR_lights_punctual"]["light"], 0);
    assert_eq!(sky["extensions"]["KHR_lights_punctual"]["light"], 1);
    assert_eq!(key["translation"], serde_json::json!([-3.0, 5.0, 2.0]));
    assert_eq!(sky["translation"], serde_json::json!([0.0, 300.0, -150.0]));
}

#[test]
fn floor_is_a_400_m_checker_repeating_every_8_m() {
    let (doc, bin) = default_scene();
    let (_, floor) = node_named(&doc, "Floor");
    let material = node_material(&doc, floor);
    let texture = material["pbrMetallicRoughness"]["baseColorTexture"]["index"]
        .as_u64()
        .expect("the floor is textured") as usize;
    let sampler = &doc["samplers"][doc["textures"][texture]["sampler"].as_u64().unwrap() as usize];
    assert_eq!(sampler["wrapS"], 10497, "REPEAT");
    assert_eq!(sampler["wrapT"], 10497, "REPEAT");
    // The image: 512 x 512 with 64 px squares, alternating.
    let image = &doc["images"][doc["textures"][texture]["source"].as_u64().unwrap() as usize];
    let png = std::fs::read(committed_dir().join(image["uri"].as_str().unwrap())).unwrap();
    let checker = image::load_from_memory(&png).unwrap().to_rgba8();
    assert_eq!(checker.dimensions(), (512, 512));
    assert_eq!(checker.get_pixel(0, 0), checker.get_pixel(64, 64));
    assert_ne!(checker.get_pixel(0, 0), checker.get_pixel(64, 0));
    assert_eq!(checker.get_pixel(0, 0), checker.get_pixel(63, 63));
    // Geometry: 400 m square at y = 0; UVs span 50 repeats (8 squares of 1 m each).
    let mesh = &doc["meshes"][floor["mesh"].as_u64().unwrap() as usize];
    let attributes = &mesh["primitives"][0]["attributes"];
    let position = &doc["accessors"][attributes["POSITION"].as_u64().unwrap() as usize];
    assert_eq!(position["min"], serde_json::json!([-200.0, 0.0, -200.0]));
    assert_eq!(position["max"], serde_json::json!([200.0, 0.0, 200.0]));
    let uvs = read_floats(&doc, &bin, &attributes["TEXCOORD_0"]);
    assert_eq!(uvs.iter().copied().fold(f32::MIN, f32::max), 50.0);
    assert_eq!(uvs.iter().copied().fold(f32::MAX, f32::min), 0.0);
    assert_eq!(floor["translation"], serde_json::json!([0.0, 0.0, -190.0]));
}

#[test]
fn default_has_one_glass_and_one_mirror_material() {
    let (doc, _) = default_scene();
    let materials = doc["materials"].as_array().unwrap();
    let glass: Vec<&Value> = materials
        .iter()
        .filter(|m| m["extensions"]["KHR_materials_transmission"]["transmissionFactor"] == 1.0)
        .collect();
    assert_eq!(glass.len(), 1);
    assert_eq!(glass[0]["extensions"]["KHR_materials_ior"]["ior"], 1.5);
    assert_eq!(glass[0]["pbrMetallicRoughness"]["metallicFactor"], 0.0);
    assert_eq!(glass[0]["pbrMetallicRoughness"]["roughnessFactor"], 0.0);
    let (_, sphere) = node_named(&doc, "GlassSphere");
    assert_eq!(node_material(&doc, sphere), glass[0]);

    let mirrors: Vec<&Value> = materials
        .iter()
        .filter(|m| {
            let pbr = &m["pbrMetallicRoughness"];
            pbr["metallicFactor"] == 1.0 && pbr["roughnessFactor"] == 0.0
        })
        .collect();
    assert_eq!(mirrors.len(), 1);
    let (_, mirror_glass) = node_named(&doc, "MirrorGlass");
    assert_eq!(node_material(&doc, mirror_glass), mirrors[0]);
    // The mirror glass hangs under the `Mirror` node, which is turned about +Y.
    let (glass_index, _) = node_named(&doc, "MirrorGlass");
    let (_, mirror) = node_named(&doc, "Mirror");
    assert!(
        mirror["children"]
            .as_array()
            .unwrap()
            .contains(&glass_index.into())
    );
    assert!(approx(
        &mirror["rotation"][1],
        -(18.5f64.to_radians().sin())
    ));
}

#[test]
fn one_1_6_second_loop_animates_the_textured_box() {
    let (doc, bin) = default_scene();
    let animations = doc["animations"].as_array().unwrap();
    assert_eq!(animations.len(), 1);
    let animation = &animations[0];
    let (box_index, box_node) = node_named(&doc, "TexturedBox");
    let box_material = node_material(&doc, box_node);
    assert!(box_material["pbrMetallicRoughness"]["baseColorTexture"].is_object());

    let channels = animation["channels"].as_array().unwrap();
    let paths: BTreeSet<&str> = channels
        .iter()
        .map(|c| c["target"]["path"].as_str().unwrap())
        .collect();
    assert_eq!(paths, BTreeSet::from(["rotation", "translation"]));
    for channel in channels {
        assert_eq!(channel["target"]["node"], box_index);
        let sampler = &animation["samplers"][channel["sampler"].as_u64().unwrap() as usize];
        assert_eq!(sampler["interpolation"], "LINEAR");
        let input = &doc["accessors"][sampler["input"].as_u64().unwrap() as usize];
        assert_eq!(input["min"], serde_json::json!([0.0]));
        assert_eq!(input["max"], serde_json::json!([1.6]));
        let times = read_floats(&doc, &bin, &sampler["input"]);
        assert_eq!(times.len(), 17);
        assert_eq!(*times.last().unwrap(), 1.6f32);
        // 48 frames at 30 fps (t = i / 30) all lie within the keyed range.
        assert!(47.0 / 30.0 < *times.last().unwrap());

        let values = read_floats(&doc, &bin, &sampler["output"]);
        let width = values.len() / times.len();
        let (first, last) = (&values[..width], &values[values.len() - width..]);
        if channel["target"]["path"] == "translation" {
            // Loops: the last key is the first; the box travels 4 m side to side.
            assert_eq!(first, last);
            assert_eq!(first, [0.0, 1.0, -2.3]);
            let xs: Vec<f32> = values.chunks(3).map(|v| v[0]).collect();
            let span = xs.iter().copied().fold(f32::MIN, f32::max)
                - xs.iter().copied().fold(f32::MAX, f32::min);
            assert!((span - 4.0).abs() < 1e-5, "x span {span}");
        } else {
            // The same orientation at both ends (q and -q), one full turn in between.
            let dot: f32 = first.iter().zip(last).map(|(a, b)| a * b).sum();
            assert!((dot + 1.0).abs() < 1e-6, "first . last = {dot}");
        }
    }
}

// ---------------------------------------------------------------------------------------
// BART-style animations.

fn nodes(doc: &Value) -> &Vec<Value> {
    doc["nodes"].as_array().unwrap()
}

fn lights(doc: &Value) -> &Vec<Value> {
    doc["extensions"]["KHR_lights_punctual"]["lights"]
        .as_array()
        .unwrap()
}

/// Node index -> parent index.
fn parents(doc: &Value) -> Vec<Option<usize>> {
    let mut parent = vec![None; nodes(doc).len()];
    for (i, n) in nodes(doc).iter().enumerate() {
        for c in n["children"].as_array().into_iter().flatten() {
            parent[c.as_u64().unwrap() as usize] = Some(i);
        }
    }
    parent
}

/// Number of ancestors of `node` (0 for a root).
fn depth(parent: &[Option<usize>], node: usize) -> usize {
    let (mut d, mut at) = (0, node);
    while let Some(p) = parent[at] {
        d += 1;
        at = p;
    }
    d
}

/// (node, path) of every animation channel.
fn animated(doc: &Value) -> BTreeSet<(usize, String)> {
    doc["animations"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|a| a["channels"].as_array().unwrap())
        .map(|c| {
            (
                c["target"]["node"].as_u64().unwrap() as usize,
                c["target"]["path"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

fn one_camera(doc: &Value) {
    assert_eq!(doc["cameras"].as_array().unwrap().len(), 1);
    assert_eq!(doc["cameras"][0]["type"], "perspective");
}

#[test]
fn kitchen_has_six_lights_glass_mirror_and_a_three_level_car() {
    let (doc, _) = committed_scene("kitchen");
    one_camera(&doc);
    assert_eq!(lights(&doc).len(), 6);
    assert!(lights(&doc).iter().all(|l| l["type"] == "point"));
    let materials = doc["materials"].as_array().unwrap();
    assert!(
        materials
            .iter()
            .any(|m| m["extensions"]["KHR_materials_transmission"]["transmissionFactor"] == 1.0)
    );
    assert!(materials.iter().any(|m| {
        let pbr = &m["pbrMetallicRoughness"];
        pbr["metallicFactor"] == 1.0 && pbr["roughnessFactor"] == 0.0
    }));
    // Floor and walls are textured and REPEAT.
    for name in ["Floor", "WallBack"] {
        let (_, node) = node_named(&doc, name);
        let texture = node_material(&doc, node)["pbrMetallicRoughness"]["baseColorTexture"]["index"]
            .as_u64()
            .unwrap() as usize;
        let sampler = doc["textures"][texture]["sampler"].as_u64().unwrap() as usize;
        assert_eq!(doc["samplers"][sampler]["wrapS"], 10497, "{name}");
    }
    // Car -> steering pivot -> wheel: three levels, the wheels spinning, the pivots
    // steering, the body translating and turning.
    let parent = parents(&doc);
    let channels = animated(&doc);
    let (car, _) = node_named(&doc, "Car");
    assert!(channels.contains(&(car, "translation".into())));
    assert!(channels.contains(&(car, "rotation".into())));
    for side in ["Left", "Right"] {
        let (steer, _) = node_named(&doc, &format!("SteerFront{side}"));
        let (front, _) = node_named(&doc, &format!("WheelFront{side}"));
        let (rear, _) = node_named(&doc, &format!("WheelRear{side}"));
        assert_eq!(parent[front], Some(steer));
        assert_eq!(parent[steer], Some(car));
        assert_eq!(parent[rear], Some(car));
        assert_eq!(depth(&parent, front), depth(&parent, car) + 2);
        for node in [steer, front, rear] {
            assert!(channels.contains(&(node, "rotation".into())));
        }
    }
    let duration = doc["accessors"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|a| a["max"].as_array())
        .filter(|m| m.len() == 1)
        .map(|m| m[0].as_f64().unwrap())
        .fold(0.0, f64::max);
    assert!((4.0..=8.0).contains(&duration), "{duration} s");
}

#[test]
fn robots_have_one_light_and_jointed_walkers() {
    let (doc, _) = committed_scene("robots");
    one_camera(&doc);
    assert_eq!(lights(&doc).len(), 1);
    let parent = parents(&doc);
    let channels = animated(&doc);
    let robots: Vec<usize> = nodes(&doc)
        .iter()
        .enumerate()
        .filter(|(_, n)| {
            let name = n["name"].as_str().unwrap();
            name.starts_with("Robot") && name.len() == "RobotA".len()
        })
        .map(|(i, _)| i)
        .collect();
    assert!((3..=5).contains(&robots.len()), "{robots:?}");
    for &robot in &robots {
        assert!(channels.contains(&(robot, "translation".into())));
        // Animated joints under this robot, and how deep the deepest sits below it.
        let joints: Vec<usize> = channels
            .iter()
            .filter(|(n, path)| {
                path == "rotation" && {
                    let mut at = *n;
                    while let Some(p) = parent[at] {
                        if p == robot {
                            break;
                        }
                        at = p;
                    }
                    parent[at] == Some(robot)
                }
            })
            .map(|(n, _)| *n)
            .collect();
        assert!(joints.len() >= 6, "hips, knees, shoulders");
        let levels = joints
            .iter()
            .map(|&j| depth(&parent, j) - depth(&parent, robot))
            .max()
            .unwrap();
        assert!(levels >= 2, "robot {robot}: joints {levels} levels deep");
    }
    // Street and facades are textured.
    let textured = doc["materials"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|m| m["pbrMetallicRoughness"]["baseColorTexture"].is_object())
        .count();
    assert!(textured >= 3);
}

#[test]
fn museum_has_a_morphing_sculpture_reflective_floor_and_paintings() {
    let (doc, _) = committed_scene("museum");
    one_camera(&doc);
    assert_eq!(lights(&doc).len(), 2);
    let (sculpture_index, sculpture) = node_named(&doc, "Sculpture");
    let mesh = &doc["meshes"][sculpture["mesh"].as_u64().unwrap() as usize];
    let targets = mesh["primitives"][0]["targets"].as_array().unwrap();
    assert!(targets.len() >= 2);
    assert_eq!(mesh["weights"].as_array().unwrap().len(), targets.len());
    for t in targets {
        assert!(t["POSITION"].is_u64() && t["NORMAL"].is_u64());
    }
    let animation = &doc["animations"][0];
    let channel = animation["channels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["target"]["path"] == "weights")
        .expect("a weights channel");
    assert_eq!(channel["target"]["node"], sculpture_index);
    let sampler = &animation["samplers"][channel["sampler"].as_u64().unwrap() as usize];
    assert!(["LINEAR", "CUBICSPLINE"].contains(&sampler["interpolation"].as_str().unwrap()));
    let index_count = doc["accessors"][mesh["primitives"][0]["indices"].as_u64().unwrap() as usize]
        ["count"]
        .as_u64()
        .unwrap();
    assert!((1000..=4096).contains(&(index_count / 3)), "{index_count}");

    let (_, floor) = node_named(&doc, "Floor");
    let pbr = &node_material(&doc, floor)["pbrMetallicRoughness"];
    assert!(pbr["metallicFactor"].as_f64().unwrap() >= 0.5);
    assert_eq!(pbr["roughnessFactor"], 0.0);
    let paintings = nodes(&doc)
        .iter()
        .filter(|n| n["name"].as_str().unwrap().starts_with("Painting"))
        .filter(|n| node_material(&doc, n)["pbrMetallicRoughness"]["baseColorTexture"].is_object())
        .count();
    assert!(paintings >= 3);
}

#[test]
fn museum_detail_knob_scales_the_sculpture_by_four_per_level() {
    let dir = tempfile::tempdir().unwrap();
    let count = |detail: u32| {
        let name = format!("m{detail}");
        mipray_authoring::write_museum(dir.path(), &name, detail).unwrap();
        let json = std::fs::read(dir.path().join(format!("{name}.gltf"))).unwrap();
        let doc: Value = serde_json::from_slice(&json).unwrap();
        let (_, sculpture) = node_named(&doc, "Sculpture");
        let mesh = &doc["meshes"][sculpture["mesh"].as_u64().unwrap() as usize];
        let indices = mesh["primitives"][0]["indices"].as_u64().unwrap() as usize;
        doc["accessors"][indices]["count"].as_u64().unwrap() as usize / 3
    };
    let (low, high) = (count(0), count(2));
    assert_eq!(low, mipray_authoring::museum_sculpture_triangles(0));
    assert_eq!(high, 16 * low);
}

/// Renders frames 0, 1, 2 (at 30 fps) of a committed scene at 64 x 36 and checks each.
fn render_three_frames(name: &str) -> Vec<mipray::record::FrameRecord> {
    use mipray::frame::{RenderSettings, Renderer};
    let scene = mipray::scene::gltf::load(&committed_dir().join(format!("{name}.gltf"))).unwrap();
    let mut renderer = Renderer::new(
        scene,
        RenderSettings {
            width: 64,
            height: 36,
            ..Default::default()
        },
    );
    (0..3)
        .map(|frame| {
            let (image, record) = renderer.render_frame(frame, frame as f32 / 30.0).unwrap();
            assert!(
                image.pixels.iter().all(|p| p.is_finite()),
                "{name} frame {frame}"
            );
            assert!(
                image.pixels.iter().any(|p| p.max_element() > 0.05),
                "{name} is lit"
            );
            assert_eq!(record.nonfinite_samples, 0);
            assert!(
                record.mip_histogram.iter().sum::<u64>() > 0,
                "{name} frame {frame}: no texture lookups"
            );
            record
        })
        .collect()
}

#[test]
fn kitchen_renders_with_rigid_updates_only() {
    let records = render_three_frames("kitchen");
    for r in &records[1..] {
        assert!(r.update.moved_triangles > 0, "frame {}", r.frame);
        assert_eq!(r.update.lod_recomputed, 0, "frame {}", r.frame);
        assert_eq!(r.update.deformed_triangles, 0, "frame {}", r.frame);
    }
}

#[test]
fn robots_render_with_moving_limbs() {
    let records = render_three_frames("robots");
    for r in &records[1..] {
        assert!(r.update.moved_triangles > 0, "frame {}", r.frame);
        assert_eq!(r.update.deformed_triangles, 0, "frame {}", r.frame);
    }
}

#[test]
fn museum_renders_with_a_deforming_sculpture() {
    let records = render_three_frames("museum");
    for r in &records[1..] {
        assert!(r.update.deformed_triangles > 0, "frame {}", r.frame);
    }
}
