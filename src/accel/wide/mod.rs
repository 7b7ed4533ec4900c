//! The 8-wide BVH that rays traverse, collapsed from the binary tree that is built and
//! refitted (Embree's BVH8 layout for AVX, read in `embree/kernels/bvh/bvh_node_aabb.h`).
//!
//! Why wide: a binary tree costs one box test and one stack push or pop per level; eight
//! child boxes side by side in structure-of-arrays form are tested with one SIMD slab test
//! ([`Lanes`]: one 8-wide AVX instruction per step where the CPU has AVX2, two 4-wide SSE
//! ones on the x86-64 baseline), which cuts the levels to a third and the stack traffic
//! with them. The tree was 4-wide (SSE) until AVX2 was dispatched at run time: on BART
//! Kitchen whole frames, 8 wide with AVX2 took 0.90x the 4-wide tree's time, 8 wide with
//! SSE pairs 1.05x, so a CPU without AVX2 (older than Intel Haswell, 2013, or AMD
//! Excavator, 2015) pays about 5%.
//!
//! By step of the algorithm:
//! - [`node`]: the node layout (eight child boxes as structure of arrays, 256 bytes);
//! - [`collapse`]: obvhs builds the binary tree; it is collapsed once per build and then
//!   dropped;
//! - [`refit`]: refits work on the wide tree itself (leaf lanes, then inner lanes children
//!   first, or up from one leaf), and the SAH cost that decides rebuilds is measured on it,
//!   the tree rays actually walk;
//! - [`walk`]: one ray, near-first (closest hit) or in lane order (any hit);
//! - [`packet`]: up to [`PACKET`] coherent rays walking together, pruned by interval tests;
//! - [`masked`]: up to [`PACKET`] rays walking together, each testing every node alone;
//! - [`Lanes`] (`simd::F32x8`): eight `f32` and the two ways to compute on them.

use obvhs::aabb::Aabb;

mod collapse;
mod masked;
mod node;
mod packet;
mod refit;
#[cfg(test)]
pub(in crate::accel) mod test_support;
mod walk;

/// One `f32` per child lane of a node.
pub use crate::simd::F32x8 as Lanes;
pub use node::WideNode;
pub use packet::{GatheredLeaf, RayPacket, listed, rays_below};
pub use refit::{LeafLanes, Parts};
pub use walk::{LeafVisit, RayBoxes};

/// Children per node.
pub const WIDTH: usize = 8;

/// Marks a child reference as a leaf (the low bits are its first triangle slot).
const LEAF: u32 = 1 << 31;

/// An unused lane (its box is inverted, so no ray enters it).
const EMPTY: u32 = u32::MAX;

/// Far distances are widened by this factor so rounding in the slab test never drops a box
/// a ray grazes (Ize 2013, "Robust BVH ray traversal": 1 + 2 gamma(3), rounded up).
const ROBUST_FAR: f32 = 1.0 + 4.0 * f32::EPSILON;

/// The wide tree, with what its refits need: each node's parent lane and each leaf's lane.
#[derive(Default, Clone)]
pub struct WideBvh {
    /// Parents before children (a child's index is larger than its parent's), so walking
    /// the nodes backwards visits children first.
    nodes: Vec<WideNode>,
    /// The root when the whole tree is one leaf (a scene of at most one leaf's triangles).
    root_leaf: Option<(u32, u32)>,
    /// Per node, `parent * WIDTH + lane` of the lane that holds it (`EMPTY` for the root).
    parent: Vec<u32>,
    /// Per leaf, in the order `collapse` met them: `node * WIDTH + lane`.
    leaf_lanes: Vec<u32>,
    /// Longest root-to-leaf path in wide nodes (sizes the traversal stack).
    depth: usize,
}

/// Most rays in a packet.
pub const PACKET: usize = 64;

impl WideBvh {
    /// The union of the root's lanes (`None` for an empty tree or a tree of one leaf, which
    /// keeps no box).
    pub fn root_box(&self) -> Option<Aabb> {
        self.nodes.first().map(WideNode::bounds_union)
    }

    /// The boxes of the subtrees `levels` wide levels below the root (a leaf met higher
    /// up is its own box): together they hold every triangle, more tightly than the root
    /// box, which is what a transformed copy of them needs (empty when the tree keeps no
    /// boxes: one leaf or none).
    pub fn boxes_at_depth(&self, levels: usize) -> Vec<Aabb> {
        let mut boxes = Vec::new();
        if self.nodes.is_empty() {
            return boxes;
        }
        let mut frontier = vec![(0u32, 1usize)];
        while let Some((index, level)) = frontier.pop() {
            let node = &self.nodes[index as usize];
            for lane in 0..WIDTH {
                let child = node.child[lane];
                if child == EMPTY {
                    continue;
                }
                if child & LEAF != 0 || level >= levels {
                    boxes.push(node.lane_box(lane));
                } else {
                    frontier.push((child, level + 1));
                }
            }
        }
        boxes
    }

    /// Every leaf's `(node * WIDTH + lane)`, in the order `collapse` called `leaf_ref`.
    pub fn leaf_lanes(&self) -> &[u32] {
        &self.leaf_lanes
    }
}
