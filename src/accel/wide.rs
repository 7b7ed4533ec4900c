//! The 8-wide BVH that rays traverse, collapsed from the binary tree that is built and
//! refitted (Embree's BVH8 layout for AVX, read in `embree/kernels/bvh/bvh_node_aabb.h`).
//!
//! Why wide: a binary tree costs one box test and one stack push or pop per level; eight
//! child boxes side by side in structure-of-arrays form are tested with one SIMD slab test
//! ([`Lanes`]: one 8-wide AVX instruction per step where the CPU has AVX2, two 4-wide SSE
//! ones on the x86-64 baseline), which cuts the levels to a third and the stack traffic
//! with them. The tree was 4-wide (SSE) until AVX2 was dispatched at run time: on BART
//! Kitchen whole frames, 8 wide with AVX2 took 0.90x the 4-wide tree's time, 8 wide with
//! SSE pairs 1.05x (BENCHMARKS.md, "an 8-wide tree with AVX2"), so a CPU without AVX2
//! (older than Intel Haswell, 2013, or AMD Excavator, 2015) pays about 5%. obvhs builds the
//! binary tree; it is collapsed once per build and then dropped: refits work on the wide
//! tree itself ([`WideBvh::refit_inner`], [`WideBvh::refit_leaf`]), and the SAH cost that
//! decides rebuilds is measured on it, the tree rays actually walk.
//!
//! Closest-hit traversal is near-first: the children a ray enters are sorted by entry
//! distance, the nearest is visited next, the others go on a stack with their entry
//! distance, and an entry whose distance is already beyond the closest hit so far is dropped
//! when popped. Queries whose answer does not depend on the order of visits (shadow rays:
//! any opaque hit, or every glass surface) skip the sort and take children in lane order
//! ([`WideBvh::traverse_unordered`]), which traced BART Kitchen's shadow rays 1.4x faster.
//! The traversal is generic over what a leaf does (closest hit, any hit, or a top-level
//! tree entering instances), so every kind of ray shares this one loop.

use std::mem::MaybeUninit;

use glam::{Vec3A, Vec4};

use obvhs::{aabb::Aabb, bvh2::Bvh2};

mod lanes;
mod packet;
pub use lanes::{Lanes, avx2_walks};
pub use packet::RayPacket;

/// Children per node.
pub const WIDTH: usize = 8;

/// Marks a child reference as a leaf (the low bits are its first triangle slot).
const LEAF: u32 = 1 << 31;
/// An unused lane (its box is inverted, so no ray enters it).
const EMPTY: u32 = u32::MAX;

/// Far distances are widened by this factor so rounding in the slab test never drops a box
/// a ray grazes (Ize 2013, "Robust BVH ray traversal": 1 + 2 gamma(3), rounded up).
const ROBUST_FAR: f32 = 1.0 + 4.0 * f32::EPSILON;

/// What a walk does at a leaf: `visit(first, count, &mut t_max)` may shrink `t_max` and
/// returns false to stop the walk. Closures implement it; a query whose leaf work should be
/// compiled into the walk itself (the closest-hit leaf test, into the AVX2 copy) implements
/// it on a struct with an `#[inline(always)]` method, which a closure cannot carry.
pub trait LeafVisit {
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool;
}

impl<F: FnMut(u32, u32, &mut f32) -> bool> LeafVisit for F {
    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        self(first, count, t_max)
    }
}

/// A pending subtree: child reference, leaf count, entry distance.
type StackEntry = (u32, u32, f32);

/// Stack entries a traversal keeps on the machine stack; deeper trees use a heap stack.
const INLINE_STACK: usize = 128;

/// One node: eight child boxes as structure of arrays (`bounds[plane][lane]`, planes lower
/// x, y, z then upper x, y, z; each row one 32-byte vector), and what each child is. 256
/// bytes, four cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct WideNode {
    bounds: [[f32; WIDTH]; 6],
    /// Inner child: its node index. Leaf child: `LEAF | first slot`. Unused: `EMPTY`.
    child: [u32; WIDTH],
    /// Leaf child: its triangle count; 0 otherwise.
    count: [u32; WIDTH],
}

impl WideNode {
    const UNUSED: WideNode = WideNode {
        bounds: [
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [EMPTY; WIDTH],
        count: [0; WIDTH],
    };

    fn lane_box(&self, lane: usize) -> Aabb {
        let b = &self.bounds;
        Aabb::new(
            Vec3A::new(b[0][lane], b[1][lane], b[2][lane]),
            Vec3A::new(b[3][lane], b[4][lane], b[5][lane]),
        )
    }

    /// The union of the used lanes' boxes.
    fn bounds_union(&self) -> Aabb {
        (0..WIDTH)
            .filter(|&lane| self.child[lane] != EMPTY)
            .fold(Aabb::empty(), |a, lane| a.union(&self.lane_box(lane)))
    }

    fn set_box(&mut self, lane: usize, aabb: &Aabb) {
        for axis in 0..3 {
            self.bounds[axis][lane] = aabb.min[axis];
            self.bounds[axis + 3][lane] = aabb.max[axis];
        }
    }
}

/// Concurrent writes of leaf boxes into distinct lanes ([`WideBvh::leaf_lanes_writer`]).
/// Two leaves may share a node but never a lane, and a lane's six bounds are its own `f32`s,
/// so tasks writing distinct lanes touch distinct memory; no reference to a whole node is
/// ever formed while they run.
pub struct LeafLanes<'a> {
    nodes: *mut WideNode,
    len: usize,
    one_leaf: bool,
    _nodes: std::marker::PhantomData<&'a mut [WideNode]>,
}

// SAFETY: the pointer comes from an exclusive borrow held for 'a; `set_leaf_box`'s contract
// keeps every lane to one task at a time.
unsafe impl Sync for LeafLanes<'_> {}

impl LeafLanes<'_> {
    /// [`WideBvh::set_leaf_box`] for lane `at` (`node * WIDTH + lane`).
    ///
    /// # Safety
    /// No other call for the same `at` may run at the same time.
    ///
    /// # Panics
    /// If `at` names no node.
    #[inline]
    pub unsafe fn set_leaf_box(&self, at: u32, aabb: &Aabb) {
        if self.one_leaf {
            return; // as `WideBvh::set_leaf_box`: a one-leaf tree keeps no box
        }
        let (node, lane) = (at as usize / WIDTH, at as usize % WIDTH);
        assert!(node < self.len, "node {node} of {}", self.len);
        // SAFETY: in bounds (checked); each write goes to one `f32` of this lane, which no
        // other task writes (the caller's contract), through a raw place (no `&mut` node).
        unsafe {
            let bounds = std::ptr::addr_of_mut!((*self.nodes.add(node)).bounds);
            for axis in 0..3 {
                (*bounds)[axis][lane] = aabb.min[axis];
                (*bounds)[axis + 3][lane] = aabb.max[axis];
            }
        }
    }
}

/// A reference to a subtree: an inner node or a leaf's slot range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ChildRef {
    Node(u32),
    Leaf { first: u32, count: u32 },
}

impl ChildRef {
    #[inline(always)]
    fn decode(child: u32, count: u32) -> ChildRef {
        if child & LEAF != 0 {
            ChildRef::Leaf {
                first: child & !LEAF,
                count,
            }
        } else {
            ChildRef::Node(child)
        }
    }
}

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

/// The ray constants of the slab test, splatted across the lanes once per ray
/// (`Default`: an all-zero placeholder for unused packet slots, never walked).
#[derive(Clone, Copy, Default)]
pub struct RayBoxes {
    origin: [Lanes; 3],
    inverse: [Lanes; 3],
    /// Per axis, the plane the ray meets first and last (`bounds` rows): lower then upper
    /// when it runs toward higher coordinates. Indices, not branches, in the node test.
    front: [usize; 3],
    back: [usize; 3],
}

impl RayBoxes {
    #[inline(always)]
    pub fn new(origin: Vec3A, direction: Vec3A) -> RayBoxes {
        RayBoxes::from_inverse(origin.to_array(), direction.to_array().map(safe_inverse))
    }

    /// The constants from the origin and the (safe) inverse direction.
    #[inline(always)]
    fn from_inverse(origin: [f32; 3], inverse: [f32; 3]) -> RayBoxes {
        let negative = inverse.map(|v| (v < 0.0) as usize);
        RayBoxes {
            origin: origin.map(Lanes::splat),
            inverse: inverse.map(Lanes::splat),
            front: [0, 1, 2].map(|axis| axis + 3 * negative[axis]),
            back: [0, 1, 2].map(|axis| axis + 3 * (1 - negative[axis])),
        }
    }

    /// Entry distances of the node's children and the mask of those the ray enters before
    /// `t_max` (bit `lane`); `AVX` only inside the AVX2 copy of a walk ([`Lanes`]).
    #[inline(always)]
    fn enter<const AVX: bool>(&self, node: &WideNode, t_max: f32) -> (Lanes, u32) {
        let mut near = Lanes::splat(0.0);
        let mut far = Lanes::splat(f32::INFINITY);
        for axis in 0..3 {
            let front = Lanes(node.bounds[self.front[axis]]);
            let back = Lanes(node.bounds[self.back[axis]]);
            let t_front = front
                .sub::<AVX>(self.origin[axis])
                .mul::<AVX>(self.inverse[axis]);
            let t_back = back
                .sub::<AVX>(self.origin[axis])
                .mul::<AVX>(self.inverse[axis]);
            near = near.max::<AVX>(t_front);
            far = far.min::<AVX>(t_back);
        }
        let far = far
            .mul::<AVX>(Lanes::splat(ROBUST_FAR))
            .min::<AVX>(Lanes::splat(t_max));
        (near, near.le_mask::<AVX>(far))
    }
}

impl RayBoxes {
    /// Whether the ray enters `aabb` before `t_max`: the slab test of one lane, for a box
    /// kept outside a node (the lone leaf of a one-leaf tree keeps none).
    #[inline(always)]
    pub fn enters_box(&self, aabb: &Aabb, t_max: f32) -> bool {
        let mut near = 0.0f32;
        let mut far = f32::INFINITY;
        let bounds = [aabb.min, aabb.max];
        for axis in 0..3 {
            let (origin, inverse) = (self.origin[axis].0[0], self.inverse[axis].0[0]);
            let front = bounds[self.front[axis] / 3][axis];
            let back = bounds[self.back[axis] / 3][axis];
            near = near.max((front - origin) * inverse);
            far = far.min((back - origin) * inverse);
        }
        near <= (far * ROBUST_FAR).min(t_max)
    }
}

/// Most rays in a packet.
pub const PACKET: usize = 64;

/// `1 / x`, kept finite and signed for zero and tiny components so that slab distances are
/// never NaN (`0 * inf`); 1e30 still puts an axis-parallel ray's far plane beyond any scene.
#[inline(always)]
fn safe_inverse(x: f32) -> f32 {
    if x.abs() < 1e-30 {
        1e30f32.copysign(x)
    } else {
        1.0 / x
    }
}

/// [`safe_inverse`] of four values at once (bit for bit the same).
#[inline(always)]
fn safe_inverse4(x: Vec4) -> Vec4 {
    let tiny = x.abs().cmplt(Vec4::splat(1e-30));
    Vec4::select(tiny, Vec4::splat(1e30).copysign(x), Vec4::ONE / x)
}

impl WideBvh {
    /// Collapses a binary tree: each wide node takes a binary inner node's two children and
    /// keeps opening its largest inner child (by surface area) until it has eight.
    /// `leaf_ref(first, count)` gives what the tree stores for a leaf (and what the leaf
    /// callback of [`WideBvh::traverse`] receives as `first`): the first slot, or the first
    /// record of the leaf's own layout.
    pub fn collapse(binary: &Bvh2, mut leaf_ref: impl FnMut(u32, u32) -> u32) -> WideBvh {
        let mut wide = WideBvh::default();
        let Some(root) = binary.nodes.first() else {
            return wide;
        };
        if root.is_leaf() {
            wide.root_leaf = Some((leaf_ref(root.first_index, root.prim_count), root.prim_count));
            return wide;
        }
        // (binary inner node, wide node it becomes, depth)
        let mut pending = vec![(0u32, 0u32, 1usize)];
        wide.nodes.push(WideNode::UNUSED);
        wide.parent.push(EMPTY);
        while let Some((id, at, depth)) = pending.pop() {
            wide.depth = wide.depth.max(depth);
            let (lanes, n) = open_children(binary, id);
            let lanes = &lanes[..n];
            let mut node = WideNode::UNUSED;
            for (lane, &child) in lanes.iter().enumerate() {
                let b = &binary.nodes[child as usize];
                node.set_box(lane, b.aabb());
                let here = at * WIDTH as u32 + lane as u32;
                if b.is_leaf() {
                    node.child[lane] = LEAF | leaf_ref(b.first_index, b.prim_count);
                    node.count[lane] = b.prim_count;
                    wide.leaf_lanes.push(here);
                } else {
                    let next = wide.nodes.len() as u32;
                    wide.nodes.push(WideNode::UNUSED);
                    wide.parent.push(here);
                    node.child[lane] = next;
                    pending.push((child, next, depth + 1));
                }
            }
            wide.nodes[at as usize] = node;
        }
        wide
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

    /// Sets the box of the leaf in lane `at` (`node * WIDTH + lane`); a full refit sets
    /// every leaf's, then calls [`WideBvh::refit_inner`]. A tree of one leaf keeps no box
    /// (rays test that leaf whatever), so there it does nothing.
    pub fn set_leaf_box(&mut self, at: u32, aabb: &Aabb) {
        if self.root_leaf.is_none() {
            self.set_lane(at, aabb);
        }
    }

    /// Every node's bounds as bits (tests compare trees bit for bit).
    #[cfg(test)]
    pub fn bounds_bits(&self) -> Vec<u32> {
        self.nodes
            .iter()
            .flat_map(|n| n.bounds.iter().flatten().map(|v| v.to_bits()))
            .collect()
    }

    /// Writes leaf boxes into their lanes from concurrent tasks (a full refit's leaves,
    /// one task per leaf).
    pub fn leaf_lanes_writer(&mut self) -> LeafLanes<'_> {
        LeafLanes {
            nodes: self.nodes.as_mut_ptr(),
            len: self.nodes.len(),
            one_leaf: self.root_leaf.is_some(),
            _nodes: std::marker::PhantomData,
        }
    }

    /// Replaces what the leaf in lane `at` refers to (its first record); for a tree of one
    /// leaf (no lanes) the root leaf's.
    pub fn set_leaf_ref(&mut self, at: u32, leaf_ref: u32) {
        if let Some((root_ref, _)) = &mut self.root_leaf {
            *root_ref = leaf_ref;
            return;
        }
        self.nodes[at as usize / WIDTH].child[at as usize % WIDTH] = LEAF | leaf_ref;
    }

    /// Refits every inner lane as the union of its child's lanes, children first.
    pub fn refit_inner(&mut self) {
        for index in (1..self.nodes.len()).rev() {
            let aabb = self.nodes[index].bounds_union();
            self.set_lane(self.parent[index], &aabb);
        }
    }

    /// Refits the leaf in lane `at` (`node * WIDTH + lane`) to `aabb`, then its ancestors
    /// up to the first whose box comes out unchanged (its own ancestors cannot change).
    pub fn refit_leaf(&mut self, at: u32, aabb: &Aabb) {
        if self.root_leaf.is_some() {
            return; // one leaf, no box (see `set_leaf_box`)
        }
        self.set_lane(at, aabb);
        let mut node = at as usize / WIDTH;
        while node != 0 {
            let aabb = self.nodes[node].bounds_union();
            let up = self.parent[node];
            if self.lane_box(up) == aabb {
                break;
            }
            self.set_lane(up, &aabb);
            node = up as usize / WIDTH;
        }
    }

    fn set_lane(&mut self, at: u32, aabb: &Aabb) {
        self.nodes[at as usize / WIDTH].set_box(at as usize % WIDTH, aabb);
    }

    fn lane_box(&self, at: u32) -> Aabb {
        self.nodes[at as usize / WIDTH].lane_box(at as usize % WIDTH)
    }

    /// Surface-area-heuristic cost relative to the root box: the expected cost of a ray
    /// through the root (one traversal step per node entered, one intersection per
    /// triangle of a leaf entered), the sum over lanes of its share of the root's area
    /// times its cost. `None` when the tree is one leaf or empty.
    pub fn sah_cost(&self, traversal: f32, intersection: f32) -> Option<f32> {
        let root = self.nodes.first()?.bounds_union();
        let root_area = f64::from(root.half_area().max(f32::MIN_POSITIVE));
        let mut cost = f64::from(traversal);
        for node in &self.nodes {
            for lane in 0..WIDTH {
                if node.child[lane] == EMPTY {
                    continue;
                }
                let share = f64::from(node.lane_box(lane).half_area()) / root_area;
                let step = if node.child[lane] & LEAF != 0 {
                    node.count[lane] as f32 * intersection
                } else {
                    traversal
                };
                cost += share * f64::from(step);
            }
        }
        Some(cost as f32)
    }

    /// Walks the tree near-first along a ray, calling `leaf(leaf_ref, count, &mut t_max)` for
    /// every leaf it enters before `t_max`. The leaf may shrink `t_max` (closest hit: later
    /// boxes beyond it are skipped) or return false to stop (any hit). Returns false when a
    /// leaf stopped the walk.
    #[inline(always)]
    pub fn traverse(&self, ray: &RayBoxes, t_max: f32, leaf: impl LeafVisit) -> bool {
        self.traverse_in::<true>(ray, t_max, leaf)
    }

    /// [`WideBvh::traverse`] for queries whose answer does not depend on the order of
    /// visits (any hit, every hit): children are taken in lane order, not sorted.
    #[inline(always)]
    pub fn traverse_unordered(&self, ray: &RayBoxes, t_max: f32, leaf: impl LeafVisit) -> bool {
        self.traverse_in::<false>(ray, t_max, leaf)
    }

    #[inline(always)]
    fn traverse_in<const ORDERED: bool>(
        &self,
        ray: &RayBoxes,
        t_max: f32,
        leaf: impl LeafVisit,
    ) -> bool {
        if let Some((first, count)) = self.root_leaf {
            let mut leaf = leaf;
            let mut t = t_max;
            return leaf.visit(first, count, &mut t);
        }
        if self.nodes.is_empty() {
            return true;
        }
        let needed = self.depth * (WIDTH - 1) + 1;
        if needed <= INLINE_STACK {
            // Left uninitialised: zeroing 1.5 KiB per ray showed as 7% of a primary-ray
            // profile (memset), and `walk` only reads entries it wrote.
            let mut stack = [const { MaybeUninit::uninit() }; INLINE_STACK];
            self.walk_on::<ORDERED>(&mut stack, ray, t_max, leaf)
        } else {
            // Only trees deeper than ~18 wide levels (pathological inputs) pay this.
            let mut stack = vec![MaybeUninit::uninit(); needed];
            self.walk_on::<ORDERED>(&mut stack, ray, t_max, leaf)
        }
    }

    /// [`WideBvh::walk`] in its AVX2 copy where the CPU has AVX2, else the baseline one.
    #[inline(always)]
    fn walk_on<const ORDERED: bool>(
        &self,
        stack: &mut [MaybeUninit<StackEntry>],
        ray: &RayBoxes,
        t_max: f32,
        leaf: impl LeafVisit,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if avx2_walks() {
            // SAFETY: the CPU has AVX2 (detected).
            return unsafe { self.walk_avx2::<ORDERED>(stack, ray, t_max, leaf) };
        }
        self.walk::<ORDERED, false>(stack, ray, t_max, leaf)
    }

    /// The AVX2 copy of [`WideBvh::walk`]: the walk, its node tests and the leaf callback
    /// are all inlined here and compiled for AVX2 (the leaf's own arithmetic only changes
    /// encoding: no fused multiply-add is formed, so it rounds as the baseline does).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn walk_avx2<const ORDERED: bool>(
        &self,
        stack: &mut [MaybeUninit<StackEntry>],
        ray: &RayBoxes,
        t_max: f32,
        leaf: impl LeafVisit,
    ) -> bool {
        self.walk::<ORDERED, true>(stack, ray, t_max, leaf)
    }

    /// The traversal loop. The stack holds at most `depth * (WIDTH - 1) + 1` entries: each
    /// level pushes at most `WIDTH - 1` siblings.
    #[inline(always)]
    fn walk<const ORDERED: bool, const AVX: bool>(
        &self,
        stack: &mut [MaybeUninit<StackEntry>],
        ray: &RayBoxes,
        mut t_max: f32,
        mut leaf: impl LeafVisit,
    ) -> bool {
        let mut top = 0usize;
        let mut current = ChildRef::Node(0);
        loop {
            match current {
                ChildRef::Node(index) => {
                    let node = &self.nodes[index as usize];
                    let (near, mask) = ray.enter::<AVX>(node, t_max);
                    if mask != 0 {
                        current = if ORDERED {
                            push_far_take_near(node, near, mask, stack, &mut top)
                        } else {
                            push_rest_take_first(node, near, mask, stack, &mut top)
                        };
                        continue;
                    }
                }
                ChildRef::Leaf { first, count } => {
                    if !leaf.visit(first, count, &mut t_max) {
                        return false;
                    }
                }
            }
            // Pop the nearest pending subtree that still starts before the closest hit.
            loop {
                if top == 0 {
                    return true;
                }
                top -= 1;
                // SAFETY: entries below `top` were all written by `push_far_take_near`.
                let (child, count, near) = unsafe { stack[top].assume_init() };
                if near <= t_max {
                    current = ChildRef::decode(child, count);
                    break;
                }
            }
        }
    }
}

/// The lanes set in `mask` ordered by increasing `near` distance, and how many there are;
/// among equal distances the higher lane comes first when `HIGH_LANE_FIRST`, else the lower.
///
/// Branch-free: each lane's key is its distance's bits (non-negative floats order as
/// integers) with the lane's tie rank in the three lowest bits, lanes not set sort last,
/// and a sorting network orders the eight keys ([`SORT_EIGHT`]); two entered lanes, the
/// most common case after one, take a single comparison. The insertion sort this replaces
/// branched on every comparison and mispredicted often (its compare was the hottest line
/// of single-ray traversal). Distances within eight ulps may come out in either order,
/// which only changes the order of visits, never what a query finds.
///
/// Why the tie rank matters: a ray leaving a surface starts inside many boxes, all entered
/// at 0. Single rays keep the insertion sort's order among them (higher lane first): lower
/// lane first made BART Robots frames 10% slower. Packets, whose interval bound is 0 for
/// every box holding the camera, go lower lane first (14% faster on BART Kitchen's primary
/// rays than the other way).
#[inline(always)]
fn lanes_near_to_far<const HIGH_LANE_FIRST: bool>(
    near: Lanes,
    mask: u32,
) -> ([usize; WIDTH], usize) {
    const RANK: u32 = WIDTH as u32 - 1;
    let near = near.0;
    let rank = |lane: u32| if HIGH_LANE_FIRST { RANK - lane } else { lane };
    // `& 0x7fff_ffff`: a -0.0 entry distance sorts as 0.
    let key = |lane: usize| (near[lane].to_bits() & (0x7fff_ffff & !RANK)) | rank(lane as u32);
    let n = mask.count_ones() as usize;
    let mut lanes = [0; WIDTH];
    if n == 2 {
        let a = mask.trailing_zeros() as usize;
        let b = (mask & (mask - 1)).trailing_zeros() as usize;
        let a_first = key(a) < key(b);
        lanes[0] = if a_first { a } else { b };
        lanes[1] = if a_first { b } else { a };
        return (lanes, 2);
    }
    let mut keys: [u32; WIDTH] = std::array::from_fn(|lane| {
        if mask & (1 << lane) != 0 {
            key(lane)
        } else {
            u32::MAX
        }
    });
    sort_eight(&mut keys);
    for (lane, k) in lanes.iter_mut().zip(keys) {
        *lane = rank(k & RANK) as usize;
    }
    (lanes, n)
}

/// Sorts eight keys with a sorting network of 19 exchanges, the fewest possible (Knuth,
/// TAOCP vol. 3, 5.3.4), spelled out so that it compiles to straight-line minimum and
/// maximum instructions (a loop over a table of pairs was not unrolled).
/// `tests::the_eight_key_network_sorts_every_zero_one_input` checks it.
#[inline(always)]
fn sort_eight(k: &mut [u32; 8]) {
    #[inline(always)]
    fn exchange(k: &mut [u32; 8], i: usize, j: usize) {
        let (a, b) = (k[i], k[j]);
        k[i] = a.min(b);
        k[j] = a.max(b);
    }
    exchange(k, 0, 2);
    exchange(k, 1, 3);
    exchange(k, 4, 6);
    exchange(k, 5, 7);
    exchange(k, 0, 4);
    exchange(k, 1, 5);
    exchange(k, 2, 6);
    exchange(k, 3, 7);
    exchange(k, 0, 1);
    exchange(k, 2, 3);
    exchange(k, 4, 5);
    exchange(k, 6, 7);
    exchange(k, 2, 4);
    exchange(k, 3, 5);
    exchange(k, 1, 4);
    exchange(k, 3, 6);
    exchange(k, 1, 2);
    exchange(k, 3, 4);
    exchange(k, 5, 6);
}

/// Of the entered children (`mask`), returns the nearest and pushes the others so that the
/// next nearest is popped first.
#[inline(always)]
fn push_far_take_near(
    node: &WideNode,
    near: Lanes,
    mask: u32,
    stack: &mut [MaybeUninit<StackEntry>],
    top: &mut usize,
) -> ChildRef {
    if mask.count_ones() == 1 {
        let lane = mask.trailing_zeros() as usize;
        return ChildRef::decode(node.child[lane], node.count[lane]);
    }
    let distances = near.0;
    let (lanes, n) = lanes_near_to_far::<true>(near, mask);
    for &farther in lanes[1..n].iter().rev() {
        stack[*top] =
            MaybeUninit::new((node.child[farther], node.count[farther], distances[farther]));
        *top += 1;
    }
    let lane = lanes[0];
    ChildRef::decode(node.child[lane], node.count[lane])
}

/// Of the entered children (`mask`), returns the first in lane order and pushes the others.
#[inline(always)]
fn push_rest_take_first(
    node: &WideNode,
    near: Lanes,
    mask: u32,
    stack: &mut [MaybeUninit<StackEntry>],
    top: &mut usize,
) -> ChildRef {
    let distances = near.0;
    let lane = mask.trailing_zeros() as usize;
    let mut rest = mask & (mask - 1);
    while rest != 0 {
        let other = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        stack[*top] = MaybeUninit::new((node.child[other], node.count[other], distances[other]));
        *top += 1;
    }
    ChildRef::decode(node.child[lane], node.count[lane])
}

/// The up to eight binary nodes a wide node over binary inner node `id` holds, in the
/// binary tree's left-to-right order: start from its two children and replace the inner one
/// with the largest surface area by its own two children until there are eight or only
/// leaves remain.
fn open_children(binary: &Bvh2, id: u32) -> ([u32; WIDTH], usize) {
    let first = binary.nodes[id as usize].first_index;
    let mut lanes = [0; WIDTH];
    (lanes[0], lanes[1]) = (first, first + 1);
    let mut n = 2;
    while n < WIDTH {
        let area = |c: u32| binary.nodes[c as usize].aabb().half_area();
        let largest = (0..n)
            .filter(|&i| !binary.nodes[lanes[i] as usize].is_leaf())
            .max_by(|&a, &b| area(lanes[a]).total_cmp(&area(lanes[b])));
        let Some(i) = largest else { break };
        let opened = binary.nodes[lanes[i] as usize].first_index;
        // The two children take the opened node's place, so the lanes keep the binary
        // tree's left-to-right order (the builder's spatial order). Walks that take
        // children in lane order (shadow rays) depend on it: appending the second child
        // instead made BART Robots' shadow rays 2x slower (a blocker found at depth 3 in the
        // builder's order took 8 nodes in the shuffled one).
        lanes.copy_within(i + 1..n, i + 2);
        lanes[i] = opened;
        lanes[i + 1] = opened + 1;
        n += 1;
    }
    (lanes, n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::{BvhBuildParams, bvh2::builder::build_bvh2};
    use std::time::Duration;

    /// A row of unit boxes along x.
    /// A xorshift64 stream.
    fn xorshift(mut seed: u64) -> impl FnMut() -> u64 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        }
    }

    /// Floats in `[low, low + span)` from [`xorshift`] (24 bits each).
    fn uniform(seed: u64, low: f32, span: f32) -> impl FnMut() -> f32 {
        let mut next = xorshift(seed);
        move || (next() >> 40) as f32 / (1u64 << 24) as f32 * span + low
    }

    fn boxes(n: usize) -> Vec<Aabb> {
        (0..n)
            .map(|i| {
                let x = i as f32 * 2.0;
                Aabb::new(Vec3A::new(x, 0.0, 0.0), Vec3A::new(x + 1.0, 1.0, 1.0))
            })
            .collect()
    }

    fn build(n: usize) -> Bvh2 {
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 1;
        build_bvh2(&boxes(n), params, &mut Duration::default())
    }

    /// Every leaf slot the walk reaches.
    fn reached(wide: &WideBvh, origin: Vec3A, direction: Vec3A) -> Vec<u32> {
        let mut out = Vec::new();
        wide.traverse(
            &RayBoxes::new(origin, direction),
            f32::INFINITY,
            |first: u32, count: u32, _: &mut f32| {
                out.extend(first..first + count);
                true
            },
        );
        out.sort();
        out
    }

    #[test]
    fn every_leaf_is_one_lane_and_a_ray_along_the_row_reaches_all() {
        let binary = build(100);
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let mut lanes = wide.leaf_lanes.clone();
        lanes.sort();
        lanes.dedup();
        assert_eq!(lanes.len(), 100);
        let all = reached(&wide, Vec3A::new(-5.0, 0.5, 0.5), Vec3A::X);
        assert_eq!(all.len(), 100);
        assert!(wide.nodes.len() < binary.nodes.len() / 2);
        // Parents come before children.
        for (i, &p) in wide.parent.iter().enumerate().skip(1) {
            assert!((p as usize / WIDTH) < i);
        }
    }

    #[test]
    fn rays_reach_exactly_the_boxes_they_cross() {
        let binary = build(37);
        let wide = WideBvh::collapse(&binary, |first, _| first);
        // Straight down through box 5 (x in [10, 11]) only; between boxes nothing.
        let slots = reached(&wide, Vec3A::new(10.5, 5.0, 0.5), Vec3A::NEG_Y);
        assert_eq!(slots.len(), 1);
        let b = binary.primitive_indices[slots[0] as usize];
        assert_eq!(b, 5);
        assert!(reached(&wide, Vec3A::new(11.5, 5.0, 0.5), Vec3A::NEG_Y).is_empty());
    }

    #[test]
    fn unordered_walks_reach_the_same_leaves() {
        let binary = build(300);
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let walk = |unordered: bool, origin: Vec3A, direction: Vec3A, t_max: f32| {
            let mut out = Vec::new();
            let ray = RayBoxes::new(origin, direction);
            let leaf = |first: u32, count: u32, _: &mut f32| {
                out.extend(first..first + count);
                true
            };
            if unordered {
                wide.traverse_unordered(&ray, t_max, leaf);
            } else {
                wide.traverse(&ray, t_max, leaf);
            }
            out.sort();
            out
        };
        let mut reached = 0;
        for k in 0..500 {
            let f = |i: u32| ((k * 7 + i).wrapping_mul(2654435761) >> 8) as f32 / 16777216.0;
            // Along the row of boxes, both ways, slightly tilted.
            let origin = Vec3A::new(f(0) * 620.0 - 10.0, f(1), f(2));
            let along = if k % 2 == 0 { 1.0 } else { -1.0 };
            let direction = Vec3A::new(along, (f(4) - 0.5) * 0.02, (f(5) - 0.5) * 0.02);
            let t_max = if k % 3 == 0 {
                f(6) * 100.0
            } else {
                f32::INFINITY
            };
            let ordered = walk(false, origin, direction, t_max);
            assert_eq!(walk(true, origin, direction, t_max), ordered);
            reached += ordered.len();
        }
        assert!(
            reached > 200,
            "only {reached} leaves reached: the test means little"
        );
    }

    #[test]
    fn closest_first_walk_skips_boxes_beyond_the_limit() {
        let binary = build(64);
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let ray = RayBoxes::new(Vec3A::new(-5.0, 0.5, 0.5), Vec3A::X);
        // A leaf that sets the limit at its first box's entry: only boxes that start before
        // it are visited afterwards, and the first box reached is the nearest one.
        let mut visited = Vec::new();
        wide.traverse(
            &ray,
            f32::INFINITY,
            |first: u32, _: u32, t_max: &mut f32| {
                let b = binary.primitive_indices[first as usize];
                visited.push(b);
                *t_max = (*t_max).min(5.0 + b as f32 * 2.0 + 1.0);
                true
            },
        );
        assert_eq!(visited, vec![0]);
    }

    #[test]
    fn refits_move_a_leaf_and_its_ancestors() {
        let binary = build(16);
        // Leaves in the order collapse meets them, by first slot, with their boxes.
        let mut order = Vec::new();
        let mut wide = WideBvh::collapse(&binary, |first, _| {
            order.push(first);
            first
        });
        let box_of_slot = |slot: u32| {
            *binary
                .nodes
                .iter()
                .find(|n| n.is_leaf() && n.first_index == slot)
                .unwrap()
                .aabb()
        };
        let mut leaf_boxes: Vec<Aabb> = order.iter().map(|&f| box_of_slot(f)).collect();
        let original_cost = wide.sah_cost(1.0, 1.0).unwrap();
        // Box 3 jumps far up: by a partial refit of its leaf lane, then by a full refit.
        let moved = order
            .iter()
            .position(|&f| binary.primitive_indices[f as usize] == 3)
            .unwrap();
        leaf_boxes[moved] = Aabb::new(Vec3A::new(6.0, 100.0, 0.0), Vec3A::new(7.0, 101.0, 1.0));
        wide.refit_leaf(wide.leaf_lanes[moved], &leaf_boxes[moved]);
        assert!(reached(&wide, Vec3A::new(6.5, 5.0, 0.5), Vec3A::NEG_Y).is_empty());
        assert_eq!(
            reached(&wide, Vec3A::new(6.5, 200.0, 0.5), Vec3A::NEG_Y).len(),
            1
        );
        // The cost is read from the refitted boxes (relative to the grown root box).
        assert_ne!(wide.sah_cost(1.0, 1.0).unwrap(), original_cost);
        let mut full = WideBvh::collapse(&binary, |first, _| first);
        for (leaf, aabb) in leaf_boxes.iter().enumerate() {
            full.set_leaf_box(full.leaf_lanes[leaf], aabb);
        }
        full.refit_inner();
        for (a, b) in full.nodes.iter().zip(&wide.nodes) {
            assert_eq!(a.bounds, b.bounds);
        }
    }

    #[test]
    fn axis_parallel_rays_never_see_nan() {
        let wide = WideBvh::collapse(&build(8), |first, _| first);
        // The origin on a box plane along a zero direction component.
        assert_eq!(
            reached(&wide, Vec3A::new(0.0, 0.0, -3.0), Vec3A::Z).len(),
            1
        );
        assert_eq!(
            reached(&wide, Vec3A::new(0.0, 0.0, -3.0), -Vec3A::Z).len(),
            0
        );
    }

    /// The sorting network hands out every entered lane once, nearest first.
    #[test]
    fn entered_lanes_come_out_nearest_first() {
        let mut next = xorshift(0x9e3779b97f4a7c15);
        let mut counts = [0; WIDTH + 1];
        for _ in 0..20000 {
            let (r, s) = (next(), next());
            // Distances over many magnitudes, with zeros (both signs) and exact repeats.
            let near: [f32; WIDTH] = std::array::from_fn(|i| match (r >> (8 * i)) & 7 {
                0 => 0.0,
                1 => -0.0,
                2 => 1.5,
                _ => f32::from_bits(((s >> (4 * i)) as u32 & 0x3fff_ffff) + 0x0080_0000),
            });
            let mask = (next() & 0xff) as u32;
            let (lanes, n) = if r & 1 == 0 {
                lanes_near_to_far::<true>(Lanes(near), mask)
            } else {
                lanes_near_to_far::<false>(Lanes(near), mask)
            };
            counts[n] += 1;
            let mut sorted: Vec<usize> = lanes[..n].to_vec();
            sorted.sort_unstable();
            let expected: Vec<usize> = (0..WIDTH).filter(|l| mask & (1 << l) != 0).collect();
            assert_eq!(sorted, expected, "every entered lane once, no other");
            for pair in lanes[..n].windows(2) {
                let (a, b) = (near[pair[0]].abs(), near[pair[1]].abs());
                // Ordered, up to the eight ulps the lane bits take.
                assert!(
                    a.to_bits() >> 3 <= b.to_bits() >> 3,
                    "{near:?} {mask:b} -> {lanes:?}"
                );
            }
        }
        assert!(
            counts.iter().all(|&c| c > 0),
            "every entered count: {counts:?}"
        );
    }

    /// The AVX2 copy of the walk visits exactly the leaves the baseline copy visits, in the
    /// same order, with the same limits (boxes scattered in 3D, rays from inside and
    /// outside them, some axis-parallel, closest-hit limits shrinking at leaves).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_walk_visits_what_the_baseline_walk_visits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            println!("skipped: this CPU has no AVX2, only the baseline walk runs here");
            return;
        }
        let mut next = uniform(0x2545f4914f6cdd1d, -10.0, 20.0);
        let scattered: Vec<Aabb> = (0..700)
            .map(|_| {
                let a = Vec3A::new(next(), next(), next());
                Aabb::new(a, a + Vec3A::new(next(), next(), next()).abs() * 0.5)
            })
            .collect();
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 2;
        let binary = build_bvh2(&scattered, params, &mut Duration::default());
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let mut visits = 0;
        for k in 0..400 {
            let origin = Vec3A::new(next(), next(), next()) * 1.2;
            let mut direction = Vec3A::new(next(), next(), next());
            if k % 5 == 0 {
                direction.y = 0.0;
            }
            let ray = RayBoxes::new(origin, direction);
            let walk = |avx: bool, ordered: bool| {
                let mut seen = Vec::new();
                let leaf = |first: u32, count: u32, t: &mut f32| {
                    seen.push((first, count, t.to_bits()));
                    *t *= 0.9; // a closest hit shrinking the limit
                    true
                };
                let mut stack = [const { MaybeUninit::uninit() }; INLINE_STACK];
                // SAFETY: AVX2 detected above.
                match (avx, ordered) {
                    (false, true) => wide.walk::<true, false>(&mut stack, &ray, 40.0, leaf),
                    (false, false) => wide.walk::<false, false>(&mut stack, &ray, 40.0, leaf),
                    (true, true) => unsafe { wide.walk_avx2::<true>(&mut stack, &ray, 40.0, leaf) },
                    (true, false) => unsafe {
                        wide.walk_avx2::<false>(&mut stack, &ray, 40.0, leaf)
                    },
                };
                seen
            };
            for ordered in [true, false] {
                let baseline = walk(false, ordered);
                assert_eq!(walk(true, ordered), baseline, "ray {k}, ordered {ordered}");
                visits += baseline.len();
            }
        }
        assert!(
            visits > 2000,
            "only {visits} leaf visits: the test means little"
        );
    }

    /// Walking the wide tree depth first in lane order meets the leaves in the binary
    /// tree's own left-to-right order (what the lane-order walks of shadow rays rely on).
    #[test]
    fn lanes_keep_the_binary_trees_left_to_right_order() {
        let mut next = uniform(0x9e3779b97f4a7c15, 0.0, 20.0);
        let scattered: Vec<Aabb> = (0..500)
            .map(|_| {
                let a = Vec3A::new(next(), next(), next());
                Aabb::new(a, a + Vec3A::new(next(), next(), next()) * 0.05)
            })
            .collect();
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 1;
        let binary = build_bvh2(&scattered, params, &mut Duration::default());
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let mut binary_order = Vec::new();
        let mut pending = vec![0u32];
        while let Some(id) = pending.pop() {
            let node = &binary.nodes[id as usize];
            if node.is_leaf() {
                binary_order.push(node.first_index);
            } else {
                pending.extend([node.first_index + 1, node.first_index]);
            }
        }
        let mut wide_order = Vec::new();
        let mut pending = vec![ChildRef::Node(0)];
        while let Some(child) = pending.pop() {
            match child {
                ChildRef::Leaf { first, .. } => wide_order.push(first),
                ChildRef::Node(index) => {
                    let node = &wide.nodes[index as usize];
                    for lane in (0..WIDTH).rev().filter(|&l| node.child[l] != EMPTY) {
                        pending.push(ChildRef::decode(node.child[lane], node.count[lane]));
                    }
                }
            }
        }
        assert_eq!(binary_order.len(), 500);
        assert_eq!(wide_order, binary_order);
    }

    /// The 0-1 principle: a network that sorts every sequence of zeros and ones sorts
    /// every sequence.
    #[test]
    fn the_eight_key_network_sorts_every_zero_one_input() {
        for bits in 0u32..256 {
            let mut keys: [u32; 8] = std::array::from_fn(|i| (bits >> i) & 1);
            sort_eight(&mut keys);
            assert!(
                keys.windows(2).all(|w| w[0] <= w[1]),
                "{bits:08b} -> {keys:?}"
            );
        }
    }

    #[test]
    fn equal_distances_come_out_in_the_chosen_lane_order() {
        let zeros = Lanes::splat(0.0);
        let all = (1 << WIDTH) - 1;
        let down: [usize; WIDTH] = std::array::from_fn(|i| WIDTH - 1 - i);
        let up: [usize; WIDTH] = std::array::from_fn(|i| i);
        assert_eq!(lanes_near_to_far::<true>(zeros, all), (down, WIDTH));
        assert_eq!(lanes_near_to_far::<false>(zeros, all), (up, WIDTH));
        let mut near = Lanes::splat(5.0);
        near.0[..4].copy_from_slice(&[2.0, 0.0, 1.0, 0.0]);
        let (lanes, n) = lanes_near_to_far::<true>(near, 0b1011);
        assert_eq!(&lanes[..n], &[3, 1, 0]);
        let (lanes, n) = lanes_near_to_far::<false>(near, 0b1010);
        assert_eq!(&lanes[..n], &[1, 3]);
        let (lanes, n) = lanes_near_to_far::<true>(near, 0b1010);
        assert_eq!(&lanes[..n], &[3, 1]);
    }

    #[test]
    fn four_inverses_at_once_equal_one_at_a_time() {
        let values = [
            0.0,
            -0.0,
            1e-31,
            -1e-31,
            1e-30,
            -1e-30,
            3.0,
            -0.7,
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        for group in values.chunks_exact(4) {
            let four = safe_inverse4(Vec4::from_slice(group)).to_array();
            for (x, inv) in group.iter().zip(four) {
                assert_eq!(inv.to_bits(), safe_inverse(*x).to_bits(), "1 / {x}");
            }
        }
    }

    /// A box kept outside the tree answers exactly as the same box in a node's lane.
    #[test]
    fn a_lone_box_answers_as_a_lane() {
        let mut next = uniform(12345, -2.0, 4.0);
        let mut agreed = [0; 2];
        for _ in 0..2000 {
            let a = Vec3A::new(next(), next(), next());
            let b = Vec3A::new(next(), next(), next());
            let aabb = Aabb::new(a.min(b), a.max(b));
            let mut node = WideNode::UNUSED;
            node.set_box(1, &aabb);
            // Aimed near the box; axis-parallel directions too (a zero component).
            let origin = Vec3A::new(next(), next(), next()) * 2.0;
            let mut d = (a + b) * 0.5 + Vec3A::new(next(), next(), next()) * 0.5 - origin;
            if next() > 1.0 {
                d.y = 0.0;
            }
            let ray = RayBoxes::new(origin, d);
            let limit = next().abs() * 3.0;
            let lane = ray.enter::<false>(&node, limit).1 & 0b10 != 0;
            assert_eq!(ray.enters_box(&aabb, limit), lane);
            agreed[lane as usize] += 1;
        }
        assert!(
            agreed[0] > 100 && agreed[1] > 100,
            "{agreed:?}: both answers exercised"
        );
    }
}
