//! Load-time scene description: the plain data a file loader produces.
//!
//! Nothing here knows a file format: `gltf.rs` fills a [`SceneDesc`] and the rest of the
//! renderer (animation, geometry, BVH, LOD, integrator) only ever reads these types.
//! Invariants every loader guarantees:
//! - all positions, normals, UVs, transforms, key values, morph deltas and weights, skin
//!   weights and inverse bind matrices are finite;
//! - every index (vertex, node, mesh, material, texture, camera, light, skin) is in range;
//! - a primitive's `indices.len()` is a multiple of 3;
//! - every per-vertex array of a primitive (normals, UVs, joints, skin weights, morph
//!   deltas) has one element per position; `joints` and `weights` are both set or both not;
//! - every primitive of a mesh has `mesh.weights.len()` morph targets, and a node's
//!   `weights` override has that length too; except a mesh whose primitives carry a point
//!   cache: it has one weight (the cache position) and its primitives no morph targets,
//!   joints or skin, and every sample of a cache has one position (and normal) per vertex;
//! - a primitive drawn by a node with a skin has every joint index below that skin's
//!   joint count;
//! - every file a load reads (scene file, buffers, images, material libraries, layers,
//!   includes) is read through [`sources`], which hashes it as it is read, so
//!   [`load_with_sources`] can list them and a render's identity covers them.
//!
//! Geometry is the un-deformed base: morph targets (even with non-zero default weights)
//! and skins are applied per frame by `anim::deform_primitive`.

pub mod aff;
pub mod camera_file;
pub mod gltf;
mod load;
pub mod obj;
pub mod sources;
pub mod usd;

pub use load::{load, load_with_sources};

use std::path::PathBuf;

use glam::{Mat4, Quat, Vec2, Vec3};

use crate::texture::Texture;

/// Everything needed to render any frame of an animated scene.
#[derive(Debug, Default)]
pub struct SceneDesc {
    /// Where the scene came from (used in messages and output folder names).
    pub source: PathBuf,
    pub meshes: Vec<MeshDesc>,
    pub nodes: Vec<NodeDesc>,
    /// Nodes of the rendered scene with no parent.
    pub roots: Vec<usize>,
    pub materials: Vec<MaterialDesc>,
    pub textures: Vec<Texture>,
    pub cameras: Vec<CameraDesc>,
    pub lights: Vec<LightDesc>,
    pub animations: Vec<AnimationDesc>,
    /// Skins referenced by `NodeDesc::skin`.
    pub skins: Vec<SkinDesc>,
    /// Radiance of rays that leave the scene (linear RGB).
    pub background: Vec3,
    /// Scene-wide ambient light colour, when the file defines one (AFF `am`, default 1 1 1
    /// there); the shaded ambient term is `ambient * material ambient * texture`. `None`
    /// (glTF): the renderer's fixed ambient applies.
    pub ambient: Option<Vec3>,
    /// The frame sequence the file asks for (AFF `a`), when it gives one.
    pub frame_times: Option<FrameTimes>,
    /// Features the file uses that this version renders only approximately or ignores
    /// (e.g. point primitives, orthographic cameras). Printed by `info` and at the start of
    /// `render`.
    pub notes: Vec<String>,
}

/// A file's own frame sequence: `frames` frames from `start` to `end` seconds, both ends
/// included (BART convention: frame `i` at `start + i * (end - start) / (frames - 1)`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTimes {
    pub start: f32,
    pub end: f32,
    pub frames: u32,
}

impl FrameTimes {
    /// Time of frame `i` (`start` when there is a single frame).
    pub fn time(&self, i: u32) -> f32 {
        if self.frames <= 1 {
            return self.start;
        }
        self.start + i as f32 * (self.end - self.start) / (self.frames - 1) as f32
    }
}

/// A mesh: one or more primitives, each with its own material.
#[derive(Debug, Default, Clone)]
pub struct MeshDesc {
    pub name: String,
    pub primitives: Vec<PrimitiveDesc>,
    /// Default morph target weights, one per morph target of each primitive (zeros when
    /// the file gives none; empty for a mesh without morph targets).
    pub weights: Vec<f32>,
}

/// An indexed triangle list in object space.
#[derive(Debug, Default, Clone)]
pub struct PrimitiveDesc {
    /// Base (un-morphed, un-skinned) vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex unit normals of the base geometry; `None` means flat shading from the
    /// geometric normal.
    pub normals: Option<Vec<Vec3>>,
    /// The texture coordinates the material's base-colour texture reads (its `texCoord` set,
    /// with `KHR_texture_transform` already applied). `None` when untextured.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangle list, three indices per triangle, each `< positions.len()`.
    pub indices: Vec<u32>,
    /// Index into `SceneDesc::materials`; `None` uses [`MaterialDesc::default`].
    pub material: Option<usize>,
    /// Per-vertex joint indices (glTF `JOINTS_0`) into `SkinDesc::joints` of the skin of
    /// the node that draws the mesh. A file with further sets (`JOINTS_1`, ...) is folded
    /// into one: the 4 largest weights of each vertex are kept and rescaled to the vertex's
    /// total weight over all sets. `None` for an unskinned primitive.
    pub joints: Option<Vec<[u16; 4]>>,
    /// Per-vertex joint weights (glTF `WEIGHTS_0`, normalized integers converted), each
    /// non-negative, paired slot by slot with `joints`. Used as given (glTF says they sum
    /// to 1; they are not renormalised except when folding sets).
    pub weights: Option<Vec<[f32; 4]>>,
    /// Morph targets: per-vertex deltas added to the base geometry, weighted by the node's
    /// effective morph weights (`anim::Pose::morph_weights`).
    pub morph_targets: Vec<MorphTargetDesc>,
    /// Time-sampled vertices (a USD point cache) replacing `positions` and `normals` at
    /// every time; `None` for everything else.
    pub point_cache: Option<PointCacheDesc>,
}

/// A point cache: a primitive's vertices sampled at several times. Its mesh has a single
/// morph weight, the cache position `s` in `[0, samples - 1]`, animated by a weights channel
/// whose key `k` has the value `k` (linear keys give `s = k + u` between samples `k` and
/// `k + 1`, step keys hold `k`). The vertices at `s` are `P_k + u (P_{k+1} - P_k)`, except
/// that a vertex equal in both samples is `P_k` bit for bit: so exactly the triangles whose
/// vertices changed come out changed, and only those are marked deformed by the frame loop.
#[derive(Debug, Default, Clone)]
pub struct PointCacheDesc {
    /// Per sample: one position per vertex.
    pub positions: Vec<Vec<Vec3>>,
    /// Per sample: one unit normal per vertex; `None` keeps the primitive's `normals`.
    pub normals: Option<Vec<Vec<Vec3>>>,
}

/// One morph target of a primitive: displacements of the base attributes (glTF
/// `TANGENT` deltas are not loaded: the renderer uses no tangents).
#[derive(Debug, Default, Clone)]
pub struct MorphTargetDesc {
    /// Position deltas, one per vertex; `None` when the target does not move positions.
    pub positions: Option<Vec<Vec3>>,
    /// Normal deltas, one per vertex; `None` when the target has none or the primitive
    /// has no normals.
    pub normals: Option<Vec<Vec3>>,
}

/// A skin: the joints that deform the vertices of the meshes drawn by nodes using it.
#[derive(Debug, Default, Clone)]
pub struct SkinDesc {
    pub name: String,
    /// Node index of each joint; a vertex's joint index `j` refers to `joints[j]`.
    pub joints: Vec<usize>,
    /// Per joint: the matrix taking the mesh's bind-pose space to the joint's space
    /// (identity when the file gives none). Same length as `joints`.
    pub inverse_bind_matrices: Vec<Mat4>,
    /// The skeleton's root node, if the file names one (informative only: joint
    /// matrices are computed from the joints' world transforms).
    pub skeleton: Option<usize>,
}

impl PrimitiveDesc {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// A node's local transform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trs {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Default for Trs {
    fn default() -> Self {
        Trs {
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        }
    }
}

impl Trs {
    pub fn to_mat4(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// A node of the scene hierarchy.
#[derive(Debug, Default, Clone)]
pub struct NodeDesc {
    pub name: String,
    /// Local transform at rest; animation channels override its components.
    pub local: Trs,
    /// A node given by a matrix keeps the exact matrix here (animation never targets such
    /// a node, as the glTF spec requires); `local` then holds its decomposition.
    pub matrix: Option<Mat4>,
    pub children: Vec<usize>,
    pub mesh: Option<usize>,
    pub camera: Option<usize>,
    pub light: Option<usize>,
    /// Index into `SceneDesc::skins`: the mesh is skinned by it (its vertices are placed
    /// by the joints, and this node's own transform is ignored for it, as glTF requires).
    pub skin: Option<usize>,
    /// Morph weights for this node's mesh, overriding `MeshDesc::weights`.
    pub weights: Option<Vec<f32>>,
}

/// A surface's appearance, mapped to the Whitted model.
#[derive(Debug, Clone)]
pub struct MaterialDesc {
    pub name: String,
    /// Linear RGB base colour factor (multiplies the texture).
    pub base_color: Vec3,
    /// Index into `SceneDesc::textures`.
    pub base_color_texture: Option<usize>,
    /// Mirror reflectance in [0, 1] (see `docs/src/formats.md` for the metallic/roughness
    /// mapping).
    pub reflectance: f32,
    /// Specular transmission in [0, 1] (`KHR_materials_transmission`).
    pub transmission: f32,
    /// Index of refraction (`KHR_materials_ior`, default 1.5).
    pub ior: f32,
    /// Phong exponent for the highlight of direct light.
    pub shininess: f32,
    /// Phong highlight strength.
    pub specular: f32,
    pub double_sided: bool,
    /// Ambient reflectance colour (AFF `fm` ambient); `None` when the file gives none (the
    /// renderer's fixed ambient model applies).
    pub ambient: Option<Vec3>,
    /// Which shading convention the parameters follow.
    pub shading: Shading,
}

/// How a material's parameters combine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Shading {
    /// glTF-style, energy weighted: diffuse `(1 - transmission)(1 - reflectance)`, mirror
    /// reflection tinted by the base colour (metal), transmission tinted by it with Fresnel.
    #[default]
    Physical,
    /// The NFF/Whitted convention of AFF files (FORMAT.md 1.8), purely additive:
    /// `am*amb*tex + sum_lights(diff*tex*N.L + highlight) + spec*L_reflect + T*L_refract`,
    /// reflection and refraction untinted, no Fresnel.
    Nff,
}

impl Default for MaterialDesc {
    fn default() -> Self {
        MaterialDesc {
            name: "default".into(),
            base_color: Vec3::splat(0.8),
            base_color_texture: None,
            reflectance: 0.0,
            transmission: 0.0,
            ior: 1.5,
            shininess: 32.0,
            specular: 0.0,
            double_sided: false,
            ambient: None,
            shading: Shading::Physical,
        }
    }
}

/// A perspective camera; it looks down its node's -Z with +Y up (glTF convention).
#[derive(Debug, Clone, Copy)]
pub struct CameraDesc {
    /// Vertical field of view in radians, in (0, pi).
    pub yfov: f32,
    pub znear: f32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LightKind {
    /// Radiates from the node's origin; intensity in candela.
    Point,
    /// Shines along the node's -Z; intensity in lux.
    Directional,
    /// Point light restricted to a cone along -Z (angles in radians).
    Spot { inner_cone: f32, outer_cone: f32 },
}

#[derive(Debug, Clone, Copy)]
pub struct LightDesc {
    pub kind: LightKind,
    /// Linear RGB colour.
    pub color: Vec3,
    pub intensity: f32,
    /// Distance past which the light has no effect (`None`: unlimited).
    pub range: Option<f32>,
    /// Irradiance falls off as `1 / d^2` (physical lights, glTF). `false`: no distance
    /// falloff (NFF/AFF point lights deliver `color * intensity` at any distance).
    pub inverse_square: bool,
}

/// What an animation channel drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelTarget {
    Translation,
    Rotation,
    Scale,
    /// Morph target weights of the node's mesh (`components` = its morph target count).
    Weights,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    Step,
    Linear,
    CubicSpline,
    /// Rotations only (4 components): spherical quadrangle interpolation. Values are laid
    /// out like CUBICSPLINE, per key the incoming control quaternion `b_k`, the key `q_k`
    /// and the outgoing control `a_k`; segment k -> k+1 is
    /// `slerp(slerp(q_k, q_k+1, u), slerp(a_k, b_k+1, u), 2u(1-u))` with a slerp that does
    /// not flip hemispheres (see `anim::sample`). Used by the AFF loader for BART `rot`
    /// tracks.
    Squad,
}

/// One keyframe track of one node property.
#[derive(Debug, Clone)]
pub struct ChannelDesc {
    pub node: usize,
    pub target: ChannelTarget,
    pub interpolation: Interpolation,
    /// Strictly non-decreasing key times in seconds.
    pub times: Vec<f32>,
    /// Flat key values: `times.len() * components` numbers, or three times that for
    /// CUBICSPLINE (in-tangent, value, out-tangent per key, as glTF stores them) and SQUAD
    /// (in-control, value, out-control quaternions per key).
    /// Components: 3 (translation, scale), 4 (rotation quaternion x, y, z, w), or the
    /// morph target count (weights).
    pub values: Vec<f32>,
    pub components: usize,
}

#[derive(Debug, Clone, Default)]
pub struct AnimationDesc {
    pub name: String,
    pub channels: Vec<ChannelDesc>,
}

impl AnimationDesc {
    /// Time of the last key over all channels (0 for an empty animation).
    pub fn duration(&self) -> f32 {
        self.channels
            .iter()
            .filter_map(|c| c.times.last().copied())
            .fold(0.0, f32::max)
    }
}

impl SceneDesc {
    /// Number of triangles drawn by the scene's node hierarchy (a mesh instanced twice counts
    /// twice), which is what the renderer traces.
    pub fn instanced_triangle_count(&self) -> usize {
        let mut count = 0;
        self.visit_nodes(|node| {
            if let Some(mesh) = node.mesh {
                count += self.meshes[mesh]
                    .primitives
                    .iter()
                    .map(|p| p.triangle_count())
                    .sum::<usize>();
            }
        });
        count
    }

    /// Calls `f` on every node reachable from the roots, parents before children.
    pub fn visit_nodes(&self, mut f: impl FnMut(&NodeDesc)) {
        for i in self.traversal_order() {
            f(&self.nodes[i]);
        }
    }

    /// Indices of the nodes reachable from the roots, depth first, parents before children,
    /// children in file order. "The first camera" and "the first N lights" follow this order.
    pub fn traversal_order(&self) -> Vec<usize> {
        let mut order = Vec::with_capacity(self.nodes.len());
        let mut stack: Vec<usize> = self.roots.iter().rev().copied().collect();
        while let Some(i) = stack.pop() {
            order.push(i);
            stack.extend(self.nodes[i].children.iter().rev().copied());
        }
        order
    }

    /// The longest animation's duration in seconds (0 for a static scene).
    pub fn duration(&self) -> f32 {
        self.animations
            .iter()
            .map(|a| a.duration())
            .fold(0.0, f32::max)
    }
}
