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
    /// How large the leaves' boxes are ([`WideBvh::leaf_sides`]): measured on first use,
    /// forgotten when a refit moves the boxes.
    leaf_sides: std::sync::OnceLock<LeafSides>,
}

/// The sizes of a tree's leaf boxes, summarised: the sum of the `log2` of each box's
/// largest side (approximated, see [`LeafSides::of_side`]) and how many boxes were summed.
/// Summaries of several trees add up ([`LeafSides::add`]), and [`LeafSides::typical`] is
/// their geometric mean: the size of a leaf a ray meets, which decides whether a packet's
/// rays lie close enough together to share leaves (`packet::ApexBounds::over_rows`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LeafSides {
    log2_sum: f64,
    count: u64,
}

impl LeafSides {
    /// One box of largest side `side`; a side that is zero, subnormal or not finite (a
    /// leaf of degenerate or unbounded triangles) adds nothing.
    ///
    /// `log2` by Mitchell's approximation: a positive normal `f32`'s bits, read as an
    /// integer and scaled by `2^-23`, are its exponent plus its mantissa's fraction, which
    /// is `127 + log2(side)` within 0.09. A summary needs no more, and a tree of a hundred
    /// thousand leaves would spend about a millisecond a frame on `f32::log2`.
    fn of_side(side: f32) -> LeafSides {
        if !(side >= f32::MIN_POSITIVE && side <= f32::MAX) {
            return LeafSides::default();
        }
        LeafSides {
            log2_sum: f64::from(side.to_bits()) / MANTISSA_SCALE - 127.0,
            count: 1,
        }
    }

    /// Both summaries together.
    pub fn add(self, other: LeafSides) -> LeafSides {
        LeafSides {
            log2_sum: self.log2_sum + other.log2_sum,
            count: self.count + other.count,
        }
    }

    /// The geometric mean of the summed sides (through the inverse of the approximation
    /// [`LeafSides::of_side`] takes, so boxes all of one side give that side back); 0 when
    /// no box was summed.
    pub fn typical(self) -> f32 {
        if self.count == 0 {
            return 0.0;
        }
        let mean = self.log2_sum / self.count as f64;
        // Within the exponents of positive normal floats: the mean of such logarithms is.
        let bits = ((mean + 127.0) * MANTISSA_SCALE).clamp(1.0, f64::from(f32::MAX.to_bits()));
        f32::from_bits(bits as u32)
    }
}

/// `2^23`: an `f32`'s mantissa bits.
const MANTISSA_SCALE: f64 = (1u32 << 23) as f64;

/// Most rays in a packet.
pub const PACKET: usize = 64;

impl WideBvh {
    /// The sizes of the tree's leaf boxes ([`LeafSides`]; none for a tree of one leaf,
    /// which keeps no box). Measured once, on first use after a build or refit: a pass
    /// over the nodes that only scenes tracing bounce packets pay for.
    pub fn leaf_sides(&self) -> LeafSides {
        *self.leaf_sides.get_or_init(|| {
            let mut sides = LeafSides::default();
            for node in &self.nodes {
                for lane in 0..WIDTH {
                    let child = node.child[lane];
                    if child != EMPTY && child & LEAF != 0 {
                        let side = (0..3)
                            .map(|axis| node.bounds[axis + 3][lane] - node.bounds[axis][lane])
                            .fold(0.0f32, f32::max);
                        sides = sides.add(LeafSides::of_side(side));
                    }
                }
            }
            sides
        })
    }

    /// Forgets the measured [`WideBvh::leaf_sides`]: every change of boxes calls it.
    fn boxes_changed(&mut self) {
        self.leaf_sides = std::sync::OnceLock::new();
    }

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

#[cfg(test)]
mod tests {
    use super::LeafSides;

    /// Boxes all of one side give it back exactly; a mixture gives its geometric mean
    /// within the approximation's error; degenerate sides add nothing, and nothing gives 0.
    #[test]
    fn leaf_sides_summarise_to_the_geometric_mean() {
        for side in [1.0f32, 0.37, 1e-20, 3.5e30, f32::MIN_POSITIVE] {
            let sides = (0..5).fold(LeafSides::default(), |s, _| s.add(LeafSides::of_side(side)));
            assert_eq!(sides.typical(), side);
        }
        let mixed = [0.01f32, 0.1, 1.0, 10.0, 100.0, 3.0, 0.3]
            .map(LeafSides::of_side)
            .into_iter()
            .fold(LeafSides::default(), LeafSides::add);
        let exact = (0.01f64 * 0.1 * 1.0 * 10.0 * 100.0 * 3.0 * 0.3).powf(1.0 / 7.0);
        let typical = f64::from(mixed.typical());
        assert!(
            (typical / exact).log2().abs() < 0.1,
            "{typical} against {exact}"
        );
        for degenerate in [0.0, -1.0, 1e-40, f32::INFINITY, f32::NAN] {
            assert_eq!(LeafSides::of_side(degenerate), LeafSides::default());
        }
        assert_eq!(LeafSides::default().typical(), 0.0);
        let one = LeafSides::of_side(2.0);
        assert_eq!(one.add(LeafSides::of_side(f32::NAN)).typical(), 2.0);
    }
}
