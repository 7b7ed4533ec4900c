//! Encoding a [`GltfBuilder`] as glTF 2.0: `<name>.gltf` (JSON), `<name>.bin` (one buffer)
//! and one PNG per image, all side by side.
//!
//! Output is deterministic: the same builder gives the same bytes on every run (fixed key
//! order from `gltf_json.rs`, floats printed by `serde_json`'s shortest round-trip
//! formatting, elements in the order they were added, no timestamps). Accessors of
//! POSITION and of animation inputs carry `min`/`max`; each accessor has its own buffer
//! view aligned to 4 bytes; `extensionsUsed` lists exactly the extensions present.

use std::collections::BTreeSet;
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
    pub name: String,
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
                        let (attributes, indices) = geometry_attributes[p.geometry.0].clone();
                        json::Primitive {
                            attributes,
                            indices,
                            material: p.material.map(|m| m.0),
                        }
                    })
                    .collect(),
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

    /// Writes every geometry's arrays; returns each one's attribute map and index accessor.
    fn encode_geometries(
        &self,
        buffer: &mut BinaryBuffer,
    ) -> Vec<(std::collections::BTreeMap<&'static str, usize>, usize)> {
        let target = Some(json::ARRAY_BUFFER);
        self.geometries
            .iter()
            .map(|(_, g)| {
                let mut attributes = std::collections::BTreeMap::new();
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
                (attributes, indices)
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
