//! Where an instance's vertices come from this frame: its mesh's rest vertices placed by its
//! node, or (for skinned and morphed primitives) the vertices `anim::deform_primitive`
//! writes, in object or world space.

use glam::{Mat4, Vec3};

use crate::anim::{Pose, VertexSpace, deform_primitive};
use crate::geometry::{FrameTriangles, Placement, SceneGeometry};
use crate::scene::SceneDesc;

/// Where an instance's vertices come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VertexSource {
    /// The mesh's rest vertices placed by the node.
    Placed,
    /// Vertices skinned and/or morphed this frame.
    Deformed,
}

impl VertexSource {
    /// `Deformed` for a skinned or morphed primitive.
    pub fn of(deforms: bool) -> VertexSource {
        if deforms {
            VertexSource::Deformed
        } else {
            VertexSource::Placed
        }
    }
}

/// Reused vertex buffers for deformed primitives.
#[derive(Debug, Default)]
pub struct DeformScratch {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
}

/// The placement and vertex arrays of instance `i` for `pose`; a `Deformed` source has its
/// vertices written into `scratch`.
pub fn instance_vertices<'a>(
    scene: &'a SceneDesc,
    geometry: &SceneGeometry,
    pose: &Pose,
    i: usize,
    source: VertexSource,
    scratch: &'a mut DeformScratch,
) -> (Placement, &'a [Vec3], Option<&'a [Vec3]>) {
    let instance = geometry.instances[i];
    let world_from_node = pose.world_from_node[instance.node as usize];
    if source == VertexSource::Placed {
        let primitive = geometry.primitive(scene, i);
        return (
            Placement::new(world_from_node),
            &primitive.positions,
            primitive.normals.as_deref(),
        );
    }
    let space = deform_primitive(
        scene,
        pose,
        instance.node as usize,
        instance.mesh as usize,
        instance.primitive as usize,
        &mut scratch.positions,
        &mut scratch.normals,
    );
    let placement = match space {
        VertexSpace::Object => Placement::new(world_from_node),
        VertexSpace::World => Placement::new(Mat4::IDENTITY),
    };
    let normals = (!scratch.normals.is_empty()).then_some(scratch.normals.as_slice());
    (placement, &scratch.positions, normals)
}

/// Fills `out` (source order) with every triangle of the scene posed by `pose`.
pub fn write_all_triangles(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    pose: &Pose,
    deforms: &[VertexSource],
    scratch: &mut DeformScratch,
    out: &mut FrameTriangles,
) {
    out.positions.clear();
    out.normals.clear();
    out.uvs.clear();
    out.material.clear();
    out.log2_pb.clear();
    out.source.clear();
    for (i, instance) in geometry.instances.iter().enumerate() {
        let (placement, positions, normals) =
            instance_vertices(scene, geometry, pose, i, deforms[i], scratch);
        for source in geometry.instance_triangles[i].clone() {
            let (p, n) = geometry.world_triangle(source, &placement, positions, normals);
            out.positions.push(p);
            out.normals.push(n);
            out.uvs.push(geometry.oriented_uvs(source, &placement));
            out.material.push(instance.material);
            out.log2_pb.push(0.0);
            out.source.push(source);
        }
    }
}

/// Whether instance `i`'s deformation inputs are the same in both poses (node transform,
/// morph weights, and its skin's joint matrices), so its vertices cannot have changed.
pub fn same_deformation(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    i: usize,
    now: &Pose,
    before: &Pose,
) -> bool {
    let node = geometry.instances[i].node as usize;
    let skin_same = match scene.nodes[node].skin {
        Some(skin) => now.joint_matrices.get(skin) == before.joint_matrices.get(skin),
        None => true,
    };
    skin_same
        && now.world_from_node[node] == before.world_from_node[node]
        && now.morph_weights[node] == before.morph_weights[node]
}
