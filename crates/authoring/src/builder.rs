//! The scene builder: a format-independent description of a glTF scene under
//! construction (geometry, meshes, images, materials, nodes, cameras, point lights,
//! animations), addressed by typed handles. `gltf_writer.rs` turns it into files and
//! `validation.rs` checks it first.
//!
//! Invariant: elements keep the order they were added in, which is the order of the
//! written glTF arrays, so output is deterministic.

use super::animation::Animation;
use super::handles::{
    AnimationId, CameraId, GeometryId, ImageId, LightId, MaterialId, MeshId, NodeId,
};
use super::material::Material;
use super::node::{Mesh, Node, PerspectiveCamera, PointLight, Primitive};
use super::shapes::MeshData;
use super::textures::RgbaImage;

/// A scene under construction: add elements, get handles, then
/// [`write`](GltfBuilder::write) it as glTF 2.0.
#[derive(Debug, Clone, Default)]
pub struct GltfBuilder {
    pub(crate) geometries: Vec<(String, MeshData)>,
    pub(crate) meshes: Vec<Mesh>,
    pub(crate) images: Vec<(String, RgbaImage)>,
    pub(crate) materials: Vec<Material>,
    pub(crate) nodes: Vec<Node>,
    pub(crate) cameras: Vec<PerspectiveCamera>,
    pub(crate) lights: Vec<PointLight>,
    pub(crate) animations: Vec<Animation>,
}

impl GltfBuilder {
    /// An empty scene.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds geometry that one or more mesh primitives can draw; it is written once.
    pub fn add_geometry(&mut self, name: &str, geometry: MeshData) -> GeometryId {
        self.geometries.push((name.into(), geometry));
        GeometryId(self.geometries.len() - 1)
    }

    /// Adds a mesh made of `primitives`.
    pub fn add_mesh(&mut self, name: &str, primitives: Vec<Primitive>) -> MeshId {
        self.meshes.push(Mesh {
            name: name.into(),
            primitives,
            weights: Vec::new(),
        });
        MeshId(self.meshes.len() - 1)
    }

    /// Sets a mesh's default morph-target weights (one per morph target of its geometry).
    ///
    /// # Panics
    /// If `mesh` is not a mesh of this builder.
    pub fn set_mesh_weights(&mut self, mesh: MeshId, weights: Vec<f32>) {
        self.meshes[mesh.0].weights = weights;
    }

    /// Morph targets of a mesh: those of its first primitive's geometry (0 when the mesh
    /// or geometry is unknown).
    pub fn morph_target_count(&self, mesh: MeshId) -> usize {
        self.meshes
            .get(mesh.0)
            .and_then(|m| m.primitives.first())
            .and_then(|p| self.geometries.get(p.geometry.0))
            .map_or(0, |(_, g)| g.morph_targets.len())
    }

    /// Adds `geometry` and a one-primitive mesh of the same name drawing it with `material`.
    pub fn add_simple_mesh(
        &mut self,
        name: &str,
        geometry: MeshData,
        material: MaterialId,
    ) -> MeshId {
        let geometry = self.add_geometry(name, geometry);
        self.add_mesh(
            name,
            vec![Primitive {
                geometry,
                material: Some(material),
            }],
        )
    }

    /// Adds an image, written as `<scene name>_<name>.png` next to the `.gltf`. `name`
    /// must be unique in the scene and made of ASCII letters, digits, `_` and `-`.
    pub fn add_image(&mut self, name: &str, image: RgbaImage) -> ImageId {
        self.images.push((name.into(), image));
        ImageId(self.images.len() - 1)
    }

    /// Adds a material that mesh primitives can use.
    pub fn add_material(&mut self, material: Material) -> MaterialId {
        self.materials.push(material);
        MaterialId(self.materials.len() - 1)
    }

    /// Adds a camera; a node carrying it places it in the scene.
    pub fn add_camera(&mut self, camera: PerspectiveCamera) -> CameraId {
        self.cameras.push(camera);
        CameraId(self.cameras.len() - 1)
    }

    /// Adds a point light (`KHR_lights_punctual`); a node carrying it places it.
    pub fn add_point_light(&mut self, light: PointLight) -> LightId {
        self.lights.push(light);
        LightId(self.lights.len() - 1)
    }

    /// Adds a node; nodes that end up nobody's child are the scene's roots.
    pub fn add_node(&mut self, node: Node) -> NodeId {
        self.nodes.push(node);
        NodeId(self.nodes.len() - 1)
    }

    /// Makes `child` a child of `parent`.
    ///
    /// # Panics
    /// If `parent` is not a node of this builder.
    pub fn add_child(&mut self, parent: NodeId, child: NodeId) {
        self.nodes[parent.0].children.push(child);
    }

    /// Adds an animation; its channels refer to nodes of this builder.
    pub fn add_animation(&mut self, animation: Animation) -> AnimationId {
        self.animations.push(animation);
        AnimationId(self.animations.len() - 1)
    }

    /// The node behind a handle.
    ///
    /// # Panics
    /// If `id` is not a node of this builder.
    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id.0]
    }

    /// Nodes that are nobody's child, in the order they were added.
    pub fn roots(&self) -> Vec<NodeId> {
        let mut is_child = vec![false; self.nodes.len()];
        for node in &self.nodes {
            for c in &node.children {
                if let Some(flag) = is_child.get_mut(c.0) {
                    *flag = true;
                }
            }
        }
        (0..self.nodes.len())
            .filter(|&i| !is_child[i])
            .map(NodeId)
            .collect()
    }
}
