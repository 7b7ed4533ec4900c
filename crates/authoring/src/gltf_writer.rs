//! Encoding a [`GltfBuilder`] as glTF 2.0: `<name>.gltf` (JSON), `<name>.bin` (one buffer)
//! and one PNG per image, all side by side.
//!
//! Output is deterministic: the same builder gives the same bytes on every run (fixed key
//! order from `gltf_json.rs`, floats printed by `serde_json`'s shortest round-trip
//! formatting, elements in the order they were added, no timestamps). Accessors of
//! POSITION and of animation inputs carry `min`/`max`; each accessor has its own buffer
//! view aligned to 4 bytes; `extensionsUsed` lists exactly the extensions present.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use super::animation::{AnimatedProperty, Animation, Interpolation};
use super::binary_buffer::{BinaryBuffer, Bounds};
use super::builder::GltfBuilder;
use super::error::AuthoringError;
use super::gltf_json as json;
use super::material::{Material, TextureBinding, WrapMode};

/// Text of the `asset.generator` property.
pub const GENERATOR: &str = "mipray authoring";

/// One file of an encoded scene: its name (relative to the `.gltf`) and its bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EncodedFile {
    /// File name, a sibling of the `.gltf` (also the URI the `.gltf` uses).
    pub name: String,
    /// The file's complete content.
    pub bytes: Vec<u8>,
}

impl GltfBuilder {
    /// Encodes the scene as the files of `<name>.gltf`: the JSON first, then `<name>.bin`,
    /// then the PNGs (`<name>_<image name>.png`) in image order.
    ///
    /// # Errors
    /// [`AuthoringError::Invalid`] if `name` is empty or not a plain file name part, or if
    /// [`validate`](GltfBuilder::validate) fails; PNG and JSON encoding errors.
    pub fn encode(&self, name: &str) -> Result<Vec<EncodedFile>, AuthoringError> {
        let name_ok = !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !name_ok {
            return Err(AuthoringError::Invalid(format!(
                "bad scene file name {name:?}"
            )));
        }
        self.validate()?;
        let mut files = vec![EncodedFile {
            name: format!("{name}.gltf"),
            bytes: Vec::new(),
        }];
        let (root, bin) = self.encode_document(name);
        files.push(EncodedFile {
            name: format!("{name}.bin"),
            bytes: bin,
        });
        for (image_name, image) in &self.images {
            let bytes = image.encode_png().map_err(|source| AuthoringError::Png {
                name: image_name.clone(),
                source,
            })?;
            files.push(EncodedFile {
                name: image_file_name(name, image_name),
                bytes,
            });
        }
        let mut text = serde_json::to_vec_pretty(&root)?;
        text.push(b'\n');
        files[0].bytes = text;
        Ok(files)
    }

    /// Writes the files of [`encode`](GltfBuilder::encode) into `dir` (created if needed)
    /// and returns their paths, `.gltf` first.
    ///
    /// # Errors
    /// Those of `encode`, and [`AuthoringError::Io`] naming the path that failed.
    pub fn write(&self, dir: &Path, name: &str) -> Result<Vec<PathBuf>, AuthoringError> {
        let files = self.encode(name)?;
        std::fs::create_dir_all(dir).map_err(|source| AuthoringError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let mut paths = Vec::with_capacity(files.len());
        for file in files {
            let path = dir.join(&file.name);
            std::fs::write(&path, &file.bytes).map_err(|source| AuthoringError::Io {
                path: path.clone(),
                source,
            })?;
            paths.push(path);
        }
        Ok(paths)
    }

    /// The JSON document and the binary buffer (the builder is already validated).
    fn encode_document(&self, name: &str) -> (json::Root, Vec<u8>) {
        let mut buffer = BinaryBuffer::default();
        let geometry_attributes = self.encode_geometries(&mut buffer);
        let meshes = self
            .meshes
            .iter()
            .map(|mesh| json::Mesh {
                name: mesh.name.clone(),
                primitives: mesh
                    .primitives
                    .iter()
                    .map(|p| {
                        let (attributes, indices, targets) =
                            geometry_attributes[p.geometry.0].clone();
                        json::Primitive {
                            attributes,
                            indices,
                            material: p.material.map(|m| m.0),
                            targets,
                        }
                    })
                    .collect(),
                weights: mesh_weights(self, mesh),
            })
            .collect();
        let textures = TextureTable::new(&self.materials);
        let animations = self
            .animations
            .iter()
            .map(|a| encode_animation(a, &mut buffer))
            .collect();
        let mut extensions_used = BTreeSet::new();
        let materials = self
            .materials
            .iter()
            .map(|m| encode_material(m, &textures, &mut extensions_used))
            .collect();
        let extensions = (!self.lights.is_empty()).then(|| {
            extensions_used.insert(json::KHR_LIGHTS_PUNCTUAL);
            self.encode_lights()
        });
        let bin = std::mem::take(&mut buffer.bytes);
        let root = json::Root {
            asset: json::Asset {
                version: "2.0",
                generator: GENERATOR,
            },
            extensions_used: extensions_used.into_iter().collect(),
            scene: 0,
            scenes: vec![json::Scene {
                name: name.into(),
                nodes: self.roots().into_iter().map(|n| n.0).collect(),
            }],
            nodes: self.encode_nodes(),
            cameras: self.encode_cameras(),
            meshes,
            materials,
            textures: textures.textures,
            samplers: textures.samplers,
            images: self
                .images
                .iter()
                .map(|(image_name, _)| json::Image {
                    name: image_name.clone(),
                    uri: image_file_name(name, image_name),
                    mime_type: "image/png",
                })
                .collect(),
            animations,
            accessors: buffer.accessors,
            buffer_views: buffer.views,
            buffers: vec![json::Buffer {
                uri: format!("{name}.bin"),
                byte_length: bin.len(),
            }],
            extensions,
        };
        (root, bin)
    }

    /// Writes every geometry's arrays; returns each one's attribute map, index accessor and
    /// morph targets' attribute maps.
    fn encode_geometries(&self, buffer: &mut BinaryBuffer) -> Vec<EncodedGeometry> {
        let target = Some(json::ARRAY_BUFFER);
        self.geometries
            .iter()
            .map(|(_, g)| {
                let mut attributes = BTreeMap::new();
                let positions: Vec<f32> = g.positions.iter().flat_map(|p| p.to_array()).collect();
                let position = buffer.push_floats(&positions, 3, "VEC3", target, Bounds::Declared);
                attributes.insert("POSITION", position);
                if let Some(normals) = &g.normals {
                    let flat: Vec<f32> = normals.iter().flat_map(|n| n.to_array()).collect();
                    let accessor = buffer.push_floats(&flat, 3, "VEC3", target, Bounds::Omitted);
                    attributes.insert("NORMAL", accessor);
                }
                if let Some(uvs) = &g.uvs {
                    let flat: Vec<f32> = uvs.iter().flat_map(|uv| uv.to_array()).collect();
                    let accessor = buffer.push_floats(&flat, 2, "VEC2", target, Bounds::Omitted);
                    attributes.insert("TEXCOORD_0", accessor);
                }
                let indices = buffer.push_indices(&g.indices, json::ELEMENT_ARRAY_BUFFER);
                let targets = g
                    .morph_targets
                    .iter()
                    .map(|t| {
                        let mut map = BTreeMap::new();
                        let flat: Vec<f32> =
                            t.positions.iter().flat_map(|d| d.to_array()).collect();
                        // Morph POSITION accessors need min/max like the base's.
                        let accessor =
                            buffer.push_floats(&flat, 3, "VEC3", target, Bounds::Declared);
                        map.insert("POSITION", accessor);
                        if let Some(normals) = &t.normals {
                            let flat: Vec<f32> =
                                normals.iter().flat_map(|d| d.to_array()).collect();
                            let accessor =
                                buffer.push_floats(&flat, 3, "VEC3", target, Bounds::Omitted);
                            map.insert("NORMAL", accessor);
                        }
                        map
                    })
                    .collect();
                (attributes, indices, targets)
            })
            .collect()
    }

    fn encode_nodes(&self) -> Vec<json::Node> {
        self.nodes
            .iter()
            .map(|n| json::Node {
                name: n.name.clone(),
                mesh: n.mesh.map(|m| m.0),
                camera: n.camera.map(|c| c.0),
                children: n.children.iter().map(|c| c.0).collect(),
                translation: (n.translation != glam::Vec3::ZERO).then(|| n.translation.to_array()),
                rotation: (n.rotation != glam::Quat::IDENTITY)
                    .then(|| n.rotation.normalize().to_array()),
                scale: (n.scale != glam::Vec3::ONE).then(|| n.scale.to_array()),
                extensions: n.light.map(|l| json::NodeExtensions {
                    lights_punctual: json::NodeLight { light: l.0 },
                }),
            })
            .collect()
    }

    fn encode_cameras(&self) -> Vec<json::Camera> {
        self.cameras
            .iter()
            .map(|c| json::Camera {
                name: c.name.clone(),
                kind: "perspective",
                perspective: json::Perspective {
                    aspect_ratio: c.aspect_ratio,
                    yfov: c.yfov,
                    znear: c.znear,
                    zfar: c.zfar,
                },
            })
            .collect()
    }

    fn encode_lights(&self) -> json::RootExtensions {
        let lights = self
            .lights
            .iter()
            .map(|l| json::Light {
                name: l.name.clone(),
                kind: "point",
                color: l.color.to_array(),
                intensity: l.intensity,
                range: l.range,
            })
            .collect();
        json::RootExtensions {
            lights_punctual: json::LightsPunctual { lights },
        }
    }
}

/// A geometry's attribute accessors, index accessor and morph targets' accessors.
type EncodedGeometry = (
    BTreeMap<&'static str, usize>,
    usize,
    Vec<BTreeMap<&'static str, usize>>,
);

/// `mesh.weights`: the mesh's own, or zeros when its geometry has morph targets.
fn mesh_weights(builder: &GltfBuilder, mesh: &super::node::Mesh) -> Option<Vec<f32>> {
    let targets = mesh.primitives.first().map_or(0, |p| {
        builder.geometries[p.geometry.0].1.morph_targets.len()
    });
    if !mesh.weights.is_empty() {
        Some(mesh.weights.clone())
    } else {
        (targets > 0).then(|| vec![0.0; targets])
    }
}

/// `<scene>_<image>.png`.
fn image_file_name(scene: &str, image: &str) -> String {
    format!("{scene}_{image}.png")
}

/// glTF textures and samplers: one texture per distinct (image, wrap modes) binding and
/// one sampler per distinct wrap-mode pair, both in order of first use by the materials.
struct TextureTable {
    bindings: Vec<TextureBinding>,
    textures: Vec<json::Texture>,
    samplers: Vec<json::Sampler>,
}

impl TextureTable {
    fn new(materials: &[Material]) -> Self {
        let mut table = TextureTable {
            bindings: Vec::new(),
            textures: Vec::new(),
            samplers: Vec::new(),
        };
        let mut wraps: Vec<(WrapMode, WrapMode)> = Vec::new();
        for binding in materials.iter().filter_map(|m| m.base_color_texture) {
            if table.bindings.contains(&binding) {
                continue;
            }
            let wrap = (binding.wrap_s, binding.wrap_t);
            let sampler = match wraps.iter().position(|w| *w == wrap) {
                Some(i) => i,
                None => {
                    wraps.push(wrap);
                    table.samplers.push(json::Sampler {
                        mag_filter: json::LINEAR,
                        min_filter: json::LINEAR_MIPMAP_LINEAR,
                        wrap_s: wrap_code(wrap.0),
                        wrap_t: wrap_code(wrap.1),
                    });
                    wraps.len() - 1
                }
            };
            table.bindings.push(binding);
            table.textures.push(json::Texture {
                sampler,
                source: binding.image.0,
            });
        }
        table
    }

    /// The glTF texture index of a binding seen by [`TextureTable::new`].
    fn index_of(&self, binding: TextureBinding) -> usize {
        self.bindings
            .iter()
            .position(|b| *b == binding)
            .expect("every material binding is in the table")
    }
}

fn wrap_code(wrap: WrapMode) -> u32 {
    match wrap {
        WrapMode::Repeat => json::REPEAT,
        WrapMode::ClampToEdge => json::CLAMP_TO_EDGE,
        WrapMode::MirroredRepeat => json::MIRRORED_REPEAT,
    }
}

fn encode_material(
    m: &Material,
    textures: &TextureTable,
    extensions_used: &mut BTreeSet<&'static str>,
) -> json::Material {
    let ior = m.ior.map(|ior| {
        extensions_used.insert(json::KHR_MATERIALS_IOR);
        json::Ior { ior }
    });
    let transmission = m.transmission.map(|t| {
        extensions_used.insert(json::KHR_MATERIALS_TRANSMISSION);
        json::Transmission {
            transmission_factor: t,
        }
    });
    let has_extensions = ior.is_some() || transmission.is_some();
    json::Material {
        name: m.name.clone(),
        pbr_metallic_roughness: json::PbrMetallicRoughness {
            base_color_factor: m.base_color.to_array(),
            base_color_texture: m.base_color_texture.map(|b| json::TextureInfo {
                index: textures.index_of(b),
            }),
            metallic_factor: m.metallic,
            roughness_factor: m.roughness,
        },
        double_sided: m.double_sided,
        extensions: has_extensions.then_some(json::MaterialExtensions { ior, transmission }),
    }
}

/// One sampler per channel; channels of an animation with identical key times share one
/// input accessor.
fn encode_animation(animation: &Animation, buffer: &mut BinaryBuffer) -> json::Animation {
    let mut inputs: Vec<(&[f32], usize)> = Vec::new();
    let mut channels = Vec::new();
    let mut samplers = Vec::new();
    for (i, ch) in animation.channels.iter().enumerate() {
        let input = match inputs
            .iter()
            .find(|(times, _)| *times == ch.times.as_slice())
        {
            Some(&(_, accessor)) => accessor,
            None => {
                let accessor = buffer.push_floats(&ch.times, 1, "SCALAR", None, Bounds::Declared);
                inputs.push((&ch.times, accessor));
                accessor
            }
        };
        let (kind, components) = match ch.property {
            AnimatedProperty::Rotation => ("VEC4", 4),
            AnimatedProperty::Weights { .. } => ("SCALAR", 1),
            _ => ("VEC3", 3),
        };
        let output = buffer.push_floats(&ch.values, components, kind, None, Bounds::Omitted);
        samplers.push(json::AnimationSampler {
            input,
            interpolation: match ch.interpolation {
                Interpolation::Linear => "LINEAR",
                Interpolation::Step => "STEP",
                Interpolation::CubicSpline => "CUBICSPLINE",
            },
            output,
        });
        channels.push(json::Channel {
            sampler: i,
            target: json::ChannelTarget {
                node: ch.node.0,
                path: match ch.property {
                    AnimatedProperty::Translation => "translation",
                    AnimatedProperty::Rotation => "rotation",
                    AnimatedProperty::Scale => "scale",
                    AnimatedProperty::Weights { .. } => "weights",
                },
            },
        });
    }
    json::Animation {
        name: animation.name.clone(),
        channels,
        samplers,
    }
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec2, Vec3};
    use serde_json::Value;

    use super::*;
    use crate::animation::Channel;
    use crate::handles::{MeshId, NodeId};
    use crate::node::{Node, PointLight, Primitive};
    use crate::shapes::{cuboid, quad};
    use crate::textures::checkerboard;

    /// A scene using every feature: a geometry shared by two meshes, a mesh instanced by
    /// two nodes, a child node, one image behind two wrap modes, and STEP, LINEAR and
    /// CUBICSPLINE channels (two sharing their key times).
    fn feature_scene() -> GltfBuilder {
        let mut b = GltfBuilder::new();
        let image = b.add_image("tiles", checkerboard(8, 2, [255; 4], [0, 0, 0, 255]));
        let repeat = b.add_material(Material::textured(
            "Repeat",
            TextureBinding::new(image, WrapMode::Repeat),
        ));
        let clamp = b.add_material(Material::textured(
            "Clamp",
            TextureBinding {
                image,
                wrap_s: WrapMode::ClampToEdge,
                wrap_t: WrapMode::MirroredRepeat,
            },
        ));
        let also_repeat = b.add_material(Material::textured(
            "AlsoRepeat",
            TextureBinding::new(image, WrapMode::Repeat),
        ));
        let cube = b.add_geometry("Cube", cuboid(Vec3::ONE));
        let mesh_a = b.add_mesh(
            "A",
            vec![Primitive {
                geometry: cube,
                material: Some(repeat),
            }],
        );
        let mesh_b = b.add_mesh(
            "B",
            vec![
                Primitive {
                    geometry: cube,
                    material: Some(clamp),
                },
                Primitive {
                    geometry: cube,
                    material: None,
                },
            ],
        );
        let card = b.add_simple_mesh("Card", quad(1.0, 1.0, Vec2::ONE), also_repeat);
        let light = b.add_point_light(PointLight {
            name: "Lamp".into(),
            color: Vec3::ONE,
            intensity: 10.0,
            range: Some(20.0),
        });
        let child = b.add_node(Node::new("Child").with_mesh(mesh_a).with_light(light));
        let parent = b.add_node(
            Node::new("Parent")
                .with_mesh(mesh_a)
                .with_translation(Vec3::new(1.0, 2.0, 3.0))
                .with_children([child]),
        );
        let other = b.add_node(Node::new("Other").with_mesh(mesh_b));
        let card_node = b.add_node(Node::new("Card").with_mesh(card));
        b.add_child(parent, card_node);
        let times = vec![0.0, 0.5, 1.0];
        b.add_animation(Animation {
            name: "Everything".into(),
            channels: vec![
                Channel::scale(
                    parent,
                    Interpolation::Step,
                    times.clone(),
                    &[Vec3::ONE, Vec3::splat(2.0), Vec3::ONE],
                ),
                Channel::rotation(
                    child,
                    Interpolation::Linear,
                    times.clone(),
                    &[Quat::IDENTITY, Quat::from_rotation_y(1.0), Quat::IDENTITY],
                ),
                Channel::translation(
                    other,
                    Interpolation::CubicSpline,
                    vec![0.0, 2.0],
                    &[
                        Vec3::ZERO,
                        Vec3::ZERO,
                        Vec3::X,
                        Vec3::Y,
                        Vec3::Z,
                        Vec3::ZERO,
                    ],
                ),
            ],
        });
        b
    }

    fn parse(files: &[EncodedFile]) -> Value {
        serde_json::from_slice(&files[0].bytes).unwrap()
    }

    #[test]
    fn encodes_hierarchy_instancing_textures_and_interpolations() {
        let files = feature_scene().encode("features").unwrap();
        let names: Vec<&str> = files.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(
            names,
            ["features.gltf", "features.bin", "features_tiles.png"]
        );
        let doc = parse(&files);
        // Parent (1) and Other (2) are the roots; Child (0) and Card (3) hang under Parent.
        assert_eq!(doc["scenes"][0]["nodes"], serde_json::json!([1, 2]));
        assert_eq!(doc["nodes"][1]["children"], serde_json::json!([0, 3]));
        assert_eq!(doc["nodes"][0]["mesh"], 0);
        assert_eq!(doc["nodes"][1]["mesh"], 0);
        assert_eq!(
            doc["nodes"][0]["extensions"]["KHR_lights_punctual"]["light"],
            0
        );
        // The cube's accessors are written once and shared by all three primitives.
        let cube = &doc["meshes"][0]["primitives"][0];
        for p in doc["meshes"][1]["primitives"].as_array().unwrap() {
            assert_eq!(p["attributes"], cube["attributes"]);
            assert_eq!(p["indices"], cube["indices"]);
        }
        assert!(doc["meshes"][1]["primitives"][1].get("material").is_none());
        // Two textures (Repeat and AlsoRepeat share one), two samplers, one image.
        assert_eq!(doc["textures"].as_array().unwrap().len(), 2);
        assert_eq!(doc["samplers"][0]["wrapS"], 10497);
        assert_eq!(doc["samplers"][1]["wrapS"], 33071);
        assert_eq!(doc["samplers"][1]["wrapT"], 33648);
        assert_eq!(
            doc["materials"][2]["pbrMetallicRoughness"]["baseColorTexture"]["index"],
            0
        );
        assert_eq!(doc["images"][0]["uri"], "features_tiles.png");
        // Samplers: STEP and LINEAR share the input; CUBICSPLINE stores 3 values per key.
        let samplers = doc["animations"][0]["samplers"].as_array().unwrap();
        let interpolations: Vec<&str> = samplers
            .iter()
            .map(|s| s["interpolation"].as_str().unwrap())
            .collect();
        assert_eq!(interpolations, ["STEP", "LINEAR", "CUBICSPLINE"]);
        assert_eq!(samplers[0]["input"], samplers[1]["input"]);
        assert_ne!(samplers[0]["input"], samplers[2]["input"]);
        let accessor = |i: &Value| &doc["accessors"][i.as_u64().unwrap() as usize];
        assert_eq!(
            accessor(&samplers[0]["input"])["max"],
            serde_json::json!([1.0])
        );
        assert_eq!(accessor(&samplers[2]["input"])["count"], 2);
        assert_eq!(accessor(&samplers[2]["output"])["count"], 6);
        assert_eq!(accessor(&samplers[1]["output"])["type"], "VEC4");
        assert_eq!(
            accessor(&cube["attributes"]["POSITION"])["min"],
            serde_json::json!([-0.5, -0.5, -0.5])
        );
        // Buffer: declared length matches the .bin; every view starts 4-byte aligned.
        assert_eq!(doc["buffers"][0]["byteLength"], files[1].bytes.len());
        for view in doc["bufferViews"].as_array().unwrap() {
            assert_eq!(view["byteOffset"].as_u64().unwrap() % 4, 0);
        }
        assert_eq!(
            doc["extensionsUsed"],
            serde_json::json!(["KHR_lights_punctual"])
        );
    }

    /// A two-target morphed icosphere with CUBICSPLINE weights.
    fn morph_scene() -> (GltfBuilder, NodeId) {
        use crate::shapes::{MorphTarget, icosphere};
        let mut b = GltfBuilder::new();
        let mut sphere = icosphere(1.0, 1);
        let n = sphere.positions.len();
        sphere.morph_targets = vec![
            MorphTarget {
                positions: vec![Vec3::Y; n],
                normals: Some(vec![Vec3::ZERO; n]),
            },
            MorphTarget {
                positions: sphere.positions.iter().map(|p| *p * 0.5).collect(),
                normals: Some(vec![Vec3::ZERO; n]),
            },
        ];
        let material = b.add_material(Material::matte("M", Vec3::ONE));
        let mesh = b.add_simple_mesh("Blob", sphere, material);
        b.set_mesh_weights(mesh, vec![0.25, 0.0]);
        let node = b.add_node(Node::new("Blob").with_mesh(mesh));
        b.add_animation(Animation {
            name: "Morph".into(),
            channels: vec![Channel::weights(
                node,
                Interpolation::CubicSpline,
                vec![0.0, 1.0],
                2,
                vec![0.0, 0.0, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.0, 0.0],
            )],
        });
        (b, node)
    }

    #[test]
    fn encodes_morph_targets_default_weights_and_weight_channels() {
        let (scene, _) = morph_scene();
        let doc = parse(&scene.encode("morph").unwrap());
        let mesh = &doc["meshes"][0];
        assert_eq!(mesh["weights"], serde_json::json!([0.25, 0.0]));
        let targets = mesh["primitives"][0]["targets"].as_array().unwrap();
        assert_eq!(targets.len(), 2);
        for t in targets {
            let position = &doc["accessors"][t["POSITION"].as_u64().unwrap() as usize];
            assert_eq!(position["count"], 42);
            assert!(position["min"].is_array() && position["max"].is_array());
            assert!(t["NORMAL"].is_u64());
        }
        let animation = &doc["animations"][0];
        assert_eq!(animation["channels"][0]["target"]["path"], "weights");
        let sampler = &animation["samplers"][0];
        assert_eq!(sampler["interpolation"], "CUBICSPLINE");
        let output = &doc["accessors"][sampler["output"].as_u64().unwrap() as usize];
        assert_eq!(
            (output["type"].as_str(), output["count"].as_u64()),
            (Some("SCALAR"), Some(12))
        );

        // Weights for the wrong number of targets, or on a node without targets, are refused.
        let (mut wrong, node) = morph_scene();
        if let AnimatedProperty::Weights { targets } = &mut wrong.animations[0].channels[0].property
        {
            *targets = 3;
        }
        wrong.animations[0].channels[0].values.extend([0.0; 6]);
        assert!(matches!(
            wrong.encode("bad"),
            Err(AuthoringError::Invalid(_))
        ));
        let (mut bad_default, _) = morph_scene();
        bad_default.set_mesh_weights(MeshId(0), vec![1.0]);
        assert!(matches!(
            bad_default.encode("bad"),
            Err(AuthoringError::Invalid(_))
        ));
        let _ = node;
    }

    #[test]
    fn encoding_is_deterministic() {
        assert_eq!(
            feature_scene().encode("x").unwrap(),
            feature_scene().encode("x").unwrap()
        );
    }

    #[test]
    fn write_puts_every_file_in_the_directory() {
        let dir = tempfile::tempdir().unwrap();
        let paths = feature_scene()
            .write(&dir.path().join("sub"), "features")
            .unwrap();
        assert_eq!(paths.len(), 3);
        let encoded = feature_scene().encode("features").unwrap();
        for (path, file) in paths.iter().zip(&encoded) {
            assert_eq!(path.file_name().unwrap().to_str().unwrap(), file.name);
            assert_eq!(std::fs::read(path).unwrap(), file.bytes);
        }
    }

    #[test]
    fn rejects_scenes_that_break_gltf_rules() {
        let expect_invalid = |b: &GltfBuilder, what: &str| match b.encode("bad") {
            Err(AuthoringError::Invalid(message)) => {
                assert!(
                    message.contains(what),
                    "{message:?} should mention {what:?}"
                )
            }
            other => panic!("expected an invalid-scene error about {what}, got {other:?}"),
        };
        let mut two_parents = feature_scene();
        two_parents.add_node(Node::new("Thief").with_children([NodeId(0)]));
        expect_invalid(&two_parents, "more than one parent");

        let mut cycle = feature_scene();
        cycle.add_child(NodeId(0), NodeId(1));
        expect_invalid(&cycle, "cycle");

        let mut unsorted = feature_scene();
        unsorted.animations[0].channels[0].times = vec![0.0, 1.0, 0.5];
        expect_invalid(&unsorted, "strictly increasing");

        let mut short = feature_scene();
        short.animations[0].channels[2].values.pop();
        expect_invalid(&short, "wrong number of key values");

        let mut foreign = feature_scene();
        foreign.add_node(Node::new("Dangling").with_mesh(MeshId(99)));
        expect_invalid(&foreign, "refers to mesh 99");

        let mut bad_image = feature_scene();
        bad_image.images[0].0 = "../escape".into();
        expect_invalid(&bad_image, "bad file name");

        assert!(matches!(
            feature_scene().encode("a/b"),
            Err(AuthoringError::Invalid(_))
        ));
    }
}
