//! Nodes of the scene hierarchy and what they carry: meshes (primitives drawing a
//! geometry with a material), a perspective camera, a `KHR_lights_punctual` point light.
//!
//! Conventions (glTF's): right-handed, +Y up; a camera looks down its node's -Z; a
//! node's local transform is translation * rotation * scale.

use glam::{Quat, Vec3};

use super::handles::{CameraId, GeometryId, LightId, MaterialId, MeshId, NodeId};

/// One primitive of a mesh: a geometry drawn with a material.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Primitive {
    /// The triangles drawn.
    pub geometry: GeometryId,
    /// `None` uses the glTF default material.
    pub material: Option<MaterialId>,
}

/// A mesh: primitives that several nodes may instance.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Shown by viewers; need not be unique.
    pub name: String,
    /// At least one.
    pub primitives: Vec<Primitive>,
    /// Default morph-target weights (glTF `mesh.weights`), one per target of its
    /// primitives' geometries (which must all have the same number of targets). Empty
    /// writes zeros when the geometries have targets.
    pub weights: Vec<f32>,
}

/// A perspective camera; it looks down its node's -Z with +Y up.
#[derive(Debug, Clone, PartialEq)]
pub struct PerspectiveCamera {
    /// Shown by viewers; need not be unique.
    pub name: String,
    /// Vertical field of view in radians, in (0, pi).
    pub yfov: f32,
    /// Width over height; `None` lets the renderer use its image's.
    pub aspect_ratio: Option<f32>,
    /// Near plane distance, > 0.
    pub znear: f32,
    /// Far plane distance, > `znear`; `None` is an infinite projection.
    pub zfar: Option<f32>,
}

/// A `KHR_lights_punctual` point light at its node's origin.
#[derive(Debug, Clone, PartialEq)]
pub struct PointLight {
    /// Shown by viewers; need not be unique.
    pub name: String,
    /// Linear RGB colour.
    pub color: Vec3,
    /// Luminous intensity in candela (illuminance at distance d is `intensity / d^2`).
    pub intensity: f32,
    /// Distance past which the light has no effect; `None` is unlimited.
    pub range: Option<f32>,
}

/// A node of the scene hierarchy: a local TRS transform and what it carries.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Shown by viewers and used to find nodes in tests; need not be unique.
    pub name: String,
    /// Local translation, relative to the parent.
    pub translation: Vec3,
    /// Unit quaternion.
    pub rotation: Quat,
    /// Local scale along the node's axes.
    pub scale: Vec3,
    /// Nodes whose transforms are relative to this one; each node has at most one parent.
    pub children: Vec<NodeId>,
    /// A mesh drawn with this node's world transform.
    pub mesh: Option<MeshId>,
    /// A camera placed at this node's origin.
    pub camera: Option<CameraId>,
    /// A light placed at this node's origin.
    pub light: Option<LightId>,
}

impl Node {
    /// An empty node with the identity transform.
    pub fn new(name: &str) -> Self {
        Node {
            name: name.into(),
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
            children: Vec::new(),
            mesh: None,
            camera: None,
            light: None,
        }
    }

    /// Sets the local translation.
    pub fn with_translation(mut self, translation: Vec3) -> Self {
        self.translation = translation;
        self
    }

    /// Sets the local rotation (a unit quaternion).
    pub fn with_rotation(mut self, rotation: Quat) -> Self {
        self.rotation = rotation;
        self
    }

    /// Sets the local scale.
    pub fn with_scale(mut self, scale: Vec3) -> Self {
        self.scale = scale;
        self
    }

    /// Attaches a mesh.
    pub fn with_mesh(mut self, mesh: MeshId) -> Self {
        self.mesh = Some(mesh);
        self
    }

    /// Attaches a camera.
    pub fn with_camera(mut self, camera: CameraId) -> Self {
        self.camera = Some(camera);
        self
    }

    /// Attaches a light.
    pub fn with_light(mut self, light: LightId) -> Self {
        self.light = Some(light);
        self
    }

    /// Appends children (each must have no other parent).
    pub fn with_children(mut self, children: impl IntoIterator<Item = NodeId>) -> Self {
        self.children.extend(children);
        self
    }

    /// Places the node at `eye` and turns it so its -Z axis points at `target` and its +Y
    /// axis leans toward `up` (what a camera or spot light needs).
    ///
    /// # Panics
    /// If `target == eye` or the view direction is parallel to `up`.
    pub fn looking_at(self, eye: Vec3, target: Vec3, up: Vec3) -> Self {
        let back = (eye - target).normalize();
        let right = up.cross(back).normalize();
        assert!(back.is_finite() && right.is_finite(), "degenerate look-at");
        let true_up = back.cross(right);
        let rotation = Quat::from_mat3(&glam::Mat3::from_cols(right, true_up, back)).normalize();
        self.with_translation(eye).with_rotation(rotation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn looking_at_points_minus_z_at_the_target_with_y_up() {
        let eye = Vec3::new(1.0, 2.0, 3.0);
        let target = Vec3::new(4.0, 0.0, -3.0);
        let node = Node::new("Camera").looking_at(eye, target, Vec3::Y);
        assert_eq!(node.translation, eye);
        let forward = node.rotation * Vec3::NEG_Z;
        assert!(
            forward.abs_diff_eq((target - eye).normalize(), 1e-6),
            "{forward}"
        );
        let up = node.rotation * Vec3::Y;
        assert!(up.y > 0.0 && up.dot(forward).abs() < 1e-6);
        let right = node.rotation * Vec3::X;
        assert!(right.y.abs() < 1e-6, "no roll: right stays horizontal");
    }
}
