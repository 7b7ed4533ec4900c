//! The subset of the glTF 2.0 JSON schema the writer emits, as serde structs.
//!
//! Field order here is the key order in the file (serde writes struct fields in
//! declaration order), which keeps output byte-stable whatever features `serde_json` is
//! built with. Optional properties and empty arrays are left out, as glTF requires
//! arrays, when present, to be non-empty.

use std::collections::BTreeMap;

use serde::Serialize;

pub const FLOAT: u32 = 5126;
pub const UNSIGNED_INT: u32 = 5125;
pub const ARRAY_BUFFER: u32 = 34962;
pub const ELEMENT_ARRAY_BUFFER: u32 = 34963;
pub const LINEAR: u32 = 9729;
pub const LINEAR_MIPMAP_LINEAR: u32 = 9987;
pub const REPEAT: u32 = 10497;
pub const CLAMP_TO_EDGE: u32 = 33071;
pub const MIRRORED_REPEAT: u32 = 33648;

pub const KHR_LIGHTS_PUNCTUAL: &str = "KHR_lights_punctual";
pub const KHR_MATERIALS_TRANSMISSION: &str = "KHR_materials_transmission";
pub const KHR_MATERIALS_IOR: &str = "KHR_materials_ior";

fn is_empty<T>(v: &[T]) -> bool {
    v.is_empty()
}

fn is_false(b: &bool) -> bool {
    !*b
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Root {
    pub asset: Asset,
    #[serde(skip_serializing_if = "is_empty")]
    pub extensions_used: Vec<&'static str>,
    pub scene: usize,
    pub scenes: Vec<Scene>,
    #[serde(skip_serializing_if = "is_empty")]
    pub nodes: Vec<Node>,
    #[serde(skip_serializing_if = "is_empty")]
    pub cameras: Vec<Camera>,
    #[serde(skip_serializing_if = "is_empty")]
    pub meshes: Vec<Mesh>,
    #[serde(skip_serializing_if = "is_empty")]
    pub materials: Vec<Material>,
    #[serde(skip_serializing_if = "is_empty")]
    pub textures: Vec<Texture>,
    #[serde(skip_serializing_if = "is_empty")]
    pub samplers: Vec<Sampler>,
    #[serde(skip_serializing_if = "is_empty")]
    pub images: Vec<Image>,
    #[serde(skip_serializing_if = "is_empty")]
    pub animations: Vec<Animation>,
    #[serde(skip_serializing_if = "is_empty")]
    pub accessors: Vec<Accessor>,
    #[serde(skip_serializing_if = "is_empty")]
    pub buffer_views: Vec<BufferView>,
    #[serde(skip_serializing_if = "is_empty")]
    pub buffers: Vec<Buffer>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extensions: Option<RootExtensions>,
}

#[derive(Serialize)]
pub struct Asset {
    pub version: &'static str,
    pub generator: &'static str,
}

#[derive(Serialize)]
pub struct Scene {
    pub name: String,
    pub nodes: Vec<usize>,
}

#[derive(Serialize)]
pub struct Node {
    pub name: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera: Option<usize>,
    #[serde(skip_serializing_if = "is_empty")]
    pub children: Vec<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub translation: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f32; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extensions: Option<NodeExtensions>,
}

#[derive(Serialize)]
pub struct NodeExtensions {
    #[serde(rename = "KHR_lights_punctual")]
    pub lights_punctual: NodeLight,
}

#[derive(Serialize)]
pub struct NodeLight {
    pub light: usize,
}

#[derive(Serialize)]
pub struct Camera {
    pub name: String,
    #[serde(rename = "type")]
    pub kind: &'static str,
    pub perspective: Perspective,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Perspective {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aspect_ratio: Option<f32>,
    pub yfov: f32,
    pub znear: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zfar: Option<f32>,
}

#[derive(Serialize)]
pub struct Mesh {
    pub name: String,
    pub primitives: Vec<Primitive>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights: Option<Vec<f32>>,
}

#[derive(Serialize)]
pub struct Primitive {
    /// Attribute semantic (`POSITION`, `NORMAL`, `TEXCOORD_0`) to accessor, sorted.
    pub attributes: BTreeMap<&'static str, usize>,
    pub indices: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material: Option<usize>,
    /// Morph targets: semantic (`POSITION`, `NORMAL`) to delta accessor, per target.
    #[serde(skip_serializing_if = "is_empty")]
    pub targets: Vec<BTreeMap<&'static str, usize>>,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Material {
    pub name: String,
    pub pbr_metallic_roughness: PbrMetallicRoughness,
    #[serde(skip_serializing_if = "is_false")]
    pub double_sided: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extensions: Option<MaterialExtensions>,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct PbrMetallicRoughness {
    pub base_color_factor: [f32; 4],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_color_texture: Option<TextureInfo>,
    pub metallic_factor: f32,
    pub roughness_factor: f32,
}

#[derive(Serialize)]
pub struct TextureInfo {
    pub index: usize,
}

#[derive(Serialize)]
pub struct MaterialExtensions {
    #[serde(rename = "KHR_materials_ior", skip_serializing_if = "Option::is_none")]
    pub ior: Option<Ior>,
    #[serde(
        rename = "KHR_materials_transmission",
        skip_serializing_if = "Option::is_none"
    )]
    pub transmission: Option<Transmission>,
}

#[derive(Serialize)]
pub struct Ior {
    pub ior: f32,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Transmission {
    pub transmission_factor: f32,
}

#[derive(Serialize)]
pub struct Texture {
    pub sampler: usize,
    pub source: usize,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Sampler {
    pub mag_filter: u32,
    pub min_filter: u32,
    pub wrap_s: u32,
    pub wrap_t: u32,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Image {
    pub name: String,
    pub uri: String,
    pub mime_type: &'static str,
}

#[derive(Serialize)]
pub struct Animation {
    pub name: String,
    pub channels: Vec<Channel>,
    pub samplers: Vec<AnimationSampler>,
}

#[derive(Serialize)]
pub struct Channel {
    pub sampler: usize,
    pub target: ChannelTarget,
}

#[derive(Serialize)]
pub struct ChannelTarget {
    pub node: usize,
    pub path: &'static str,
}

#[derive(Serialize)]
pub struct AnimationSampler {
    pub input: usize,
    pub interpolation: &'static str,
    pub output: usize,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Accessor {
    pub buffer_view: usize,
    pub component_type: u32,
    pub count: usize,
    #[serde(rename = "type")]
    pub kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<Vec<f32>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<Vec<f32>>,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct BufferView {
    pub buffer: usize,
    pub byte_offset: usize,
    pub byte_length: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<u32>,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Buffer {
    pub uri: String,
    pub byte_length: usize,
}

#[derive(Serialize)]
pub struct RootExtensions {
    #[serde(rename = "KHR_lights_punctual")]
    pub lights_punctual: LightsPunctual,
}

#[derive(Serialize)]
pub struct LightsPunctual {
    pub lights: Vec<Light>,
}

#[derive(Serialize)]
pub struct Light {
    pub name: String,
    #[serde(rename = "type")]
    pub kind: &'static str,
    pub color: [f32; 3],
    pub intensity: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub range: Option<f32>,
}
