//! Refitting the wide tree in place, and its SAH cost.
//!
//! A full refit sets every leaf's lane (from concurrent tasks through [`LeafLanes`]: leaves
//! never share a lane), then every inner lane as the union of its child's lanes, children
//! first; a partial refit walks up from one leaf and stops at the first ancestor whose box
//! comes out unchanged. A tree of one leaf keeps no box.

use std::ops::Range;

use obvhs::aabb::Aabb;

use rayon::prelude::*;

use super::node::WideNode;
use super::{EMPTY, LEAF, WIDTH, WideBvh};

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

    /// Hints the cache to load the lines [`Self::set_leaf_box`] writes for lane `at` (its
    /// node's three lines of bounds; nothing when `at` names no node).
    #[inline(always)]
    pub fn prefetch_leaf_lane(&self, at: u32) {
        let node = at as usize / WIDTH;
        if node < self.len {
            let start = self.nodes.wrapping_add(node).cast::<u8>();
            for line in 0..3 {
                crate::simd::prefetch_ptr(start.wrapping_add(64 * line));
            }
        }
    }
}

impl WideBvh {
    /// Sets the box of the leaf in lane `at` (`node * WIDTH + lane`); a full refit sets
    /// every leaf's, then calls [`WideBvh::refit_inner`]. A tree of one leaf keeps no box
    /// (rays test that leaf whatever), so there it does nothing. (Refits write leaf boxes
    /// through [`WideBvh::leaf_lanes_writer`]; tests build trees with this.)
    #[cfg(test)]
    pub fn set_leaf_box(&mut self, at: u32, aabb: &Aabb) {
        self.boxes_changed();
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
        self.boxes_changed();
        LeafLanes {
            nodes: self.nodes.as_mut_ptr(),
            len: self.nodes.len(),
            one_leaf: self.root_leaf.is_some(),
            _nodes: std::marker::PhantomData,
        }
    }

    /// Refits every inner lane as the union of its child's lanes, children first, and
    /// returns the refitted tree's SAH cost ([`WideBvh::sah_cost`], the same bits): each
    /// node's share is taken while the refit has it in cache (every node's lanes are final
    /// when the backward walk reaches it), instead of a second pass over the nodes.
    pub fn refit_inner(&mut self, traversal: f32, intersection: f32) -> Option<f32> {
        self.boxes_changed();
        let mut runs = vec![0.0f64; self.nodes.len().div_ceil(SAH_CHUNK)];
        for index in (0..self.nodes.len()).rev() {
            let node = &self.nodes[index];
            runs[index / SAH_CHUNK] += node.weighted_area(traversal, intersection);
            if index > 0 {
                let aabb = node.bounds_union();
                self.set_lane(self.parent[index], &aabb);
            }
        }
        self.cost_of_runs(&runs, traversal)
    }

    /// The tree cut into subtrees of at most `most_nodes` nodes each, which a full refit
    /// can take side by side ([`WideBvh::refit_in_parts`]); `None` for a tree of one node
    /// or less, or one whose subtrees are not laid out in runs (never from `collapse`).
    pub fn parts(&self, most_nodes: usize) -> Option<Parts> {
        let n = self.nodes.len();
        if self.root_leaf.is_some() || n < 2 {
            return None;
        }
        // Per node: the least and one past the greatest index of its descendants, and how
        // many there are, from its children's (children come after their parents).
        let mut first = vec![u32::MAX; n];
        let mut end = vec![0u32; n];
        let mut count = vec![0u32; n];
        for index in (0..n).rev() {
            let (mut f, mut e, mut c) = (u32::MAX, 0, 0);
            for &child in self.inner_children(index) {
                let k = child as usize;
                f = f.min(child).min(first[k]);
                e = e.max(child + 1).max(end[k]);
                c += 1 + count[k];
            }
            (first[index], end[index], count[index]) = (f, e, c);
        }
        let descendants = |node: usize| -> Option<Range<u32>> {
            match count[node] {
                0 => Some(0..0),
                c => (end[node] - first[node] == c).then_some(first[node]..end[node]),
            }
        };
        // From the root down: a node with more descendants than `most_nodes` is opened
        // (its inner children become candidates, it stays above the parts).
        let mut parts = Vec::new();
        let mut top = vec![0u32];
        let mut pending: Vec<u32> = self.inner_children(0).copied().collect();
        while let Some(node) = pending.pop() {
            if count[node as usize] as usize >= most_nodes {
                top.push(node);
                pending.extend(self.inner_children(node as usize).copied());
            } else {
                parts.push((node, descendants(node as usize)?));
                top.push(node);
            }
        }
        top.sort_unstable_by(|a, b| b.cmp(a));
        let mut owner = vec![EMPTY; n];
        for (p, (root, range)) in parts.iter().enumerate() {
            owner[*root as usize] = p as u32;
            owner[range.start as usize..range.end as usize].fill(p as u32);
        }
        Some(Parts { parts, top, owner })
    }

    /// How many nodes the tree has.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The inner children of node `index` (its lanes that hold a node).
    fn inner_children(&self, index: usize) -> impl Iterator<Item = &u32> + '_ {
        let node = &self.nodes[index];
        node.child.iter().filter(|&&c| c != EMPTY && c & LEAF == 0)
    }

    /// [`WideBvh::refit_inner`] with the leaf boxes set as it goes, a part at a time on
    /// rayon's threads: `set_leaves(Some(p), lanes)` sets the boxes of the leaves in part
    /// `p`'s nodes, then the part's inner lanes are refitted, children first, while its
    /// nodes are in the task's cache; then `set_leaves(None, lanes)` sets the leaves of the
    /// nodes above the parts and those are refitted. Every lane is a pure function of its
    /// children's, and each node's SAH share is summed in the order `refit_inner` sums it,
    /// so the tree and its cost are the same bits.
    pub fn refit_in_parts(
        &mut self,
        parts: &Parts,
        set_leaves: impl Fn(Option<usize>, &LeafLanes) + Sync,
        traversal: f32,
        intersection: f32,
    ) -> Option<f32> {
        self.boxes_changed();
        let n = self.nodes.len();
        assert_eq!(parts.owner.len(), n, "parts of another tree");
        let mut weighted = vec![0.0f64; n];
        {
            let lanes = LeafLanes {
                nodes: self.nodes.as_mut_ptr(),
                len: n,
                one_leaf: false,
                _nodes: std::marker::PhantomData,
            };
            let shares = SharePtr(weighted.as_mut_ptr());
            let parent = &self.parent;
            parts
                .parts
                .par_iter()
                .enumerate()
                .for_each(|(p, (root, range))| {
                    set_leaves(Some(p), &lanes);
                    for index in range.clone().rev() {
                        let index = index as usize;
                        // The SAH share reads a node's last line (what its lanes hold), which
                        // nothing else of the refit touches: hinted a few nodes ahead, or it
                        // missed on nearly every node (the hottest load of a million skinned
                        // triangles' refit).
                        // Its bound lines too: when the leaf boxes were set before the
                        // refit (by a writer of runs of slots, on whichever thread), the
                        // part's nodes are not in this task's cache.
                        if let Some(ahead) = index.checked_sub(CHILD_LINE_AHEAD)
                            && ahead >= range.start as usize
                        {
                            let node = lanes.nodes.wrapping_add(ahead).cast::<u8>();
                            for line in [0, 64, 128, CHILD_LINE] {
                                crate::simd::prefetch_ptr(node.wrapping_add(line));
                            }
                        }
                        // SAFETY: a part's nodes (its root and its root's descendants, which
                        // `parts` checked lie in `range`) are read and written by its task
                        // alone: every node's parent lane is in the same part or is its root's.
                        unsafe {
                            let node = &*lanes.nodes.add(index);
                            *shares.at(index) = node.weighted_area(traversal, intersection);
                            let aabb = node.bounds_union();
                            let at = parent[index] as usize;
                            debug_assert!(
                                parts.owner[at / WIDTH] == p as u32 || at / WIDTH == *root as usize
                            );
                            (*lanes.nodes.add(at / WIDTH)).set_box(at % WIDTH, &aabb);
                        }
                    }
                });
            set_leaves(None, &lanes);
        }
        for &index in &parts.top {
            let index = index as usize;
            let node = &self.nodes[index];
            weighted[index] = node.weighted_area(traversal, intersection);
            if index > 0 {
                let aabb = node.bounds_union();
                self.set_lane(self.parent[index], &aabb);
            }
        }
        // Summed into the runs' array one node at a time, each add waited on the store of
        // the one before (about a quarter of a million skinned triangles' inner refit,
        // serial after the parallel part): `run_sums` folds each run in a register.
        self.cost_of_runs(&run_sums(&weighted, |&share| share), traversal)
    }

    /// Refits the leaf in lane `at` (`node * WIDTH + lane`) to `aabb`, then its ancestors
    /// up to the first whose box comes out unchanged (its own ancestors cannot change).
    pub fn refit_leaf(&mut self, at: u32, aabb: &Aabb) {
        self.boxes_changed();
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
    ///
    /// Summed per run of [`SAH_CHUNK`] nodes (each run from its last node back, the order
    /// [`WideBvh::refit_inner`] meets them), then over the runs in order, so the value is
    /// the same whether the runs are summed on one thread or several.
    pub fn sah_cost(&self, traversal: f32, intersection: f32) -> Option<f32> {
        let runs = run_sums(&self.nodes, |node| {
            node.weighted_area(traversal, intersection)
        });
        self.cost_of_runs(&runs, traversal)
    }

    /// The SAH cost from the per-run sums of `WideNode::weighted_area`.
    fn cost_of_runs(&self, runs: &[f64], traversal: f32) -> Option<f32> {
        let root = self.nodes.first()?.bounds_union();
        let root_area = f64::from(root.half_area().max(f32::MIN_POSITIVE));
        let weighted = runs.iter().fold(0.0f64, |a, &b| a + b);
        Some((f64::from(traversal) + weighted / root_area) as f32)
    }
}

/// The wide tree cut into subtrees ([`WideBvh::parts`]), for a refit that takes them side
/// by side; made once per build (refits keep the topology).
#[derive(Clone, Debug)]
pub struct Parts {
    /// Per part: its root node and the range of its root's descendants (`collapse` lays a
    /// node's descendants out in one run, depth first).
    parts: Vec<(u32, Range<u32>)>,
    /// The nodes in no part's range, in decreasing order (children first): the parts' roots
    /// and the nodes above them.
    top: Vec<u32>,
    /// Per node: the part it is the root or a descendant of (`EMPTY` above the parts).
    owner: Vec<u32>,
}

impl Parts {
    /// How many parts there are.
    pub fn len(&self) -> usize {
        self.parts.len()
    }

    /// The part whose nodes hold lane `at` (`node * WIDTH + lane`), `None` above the parts.
    pub fn part_of_lane(&self, at: u32) -> Option<usize> {
        let owner = self.owner[at as usize / WIDTH];
        (owner != EMPTY).then_some(owner as usize)
    }
}

/// How many nodes ahead the refit in parts hints a node's lane kinds and counts.
const CHILD_LINE_AHEAD: usize = 16;

/// Where in a node its lane kinds and counts start (its fourth cache line).
const CHILD_LINE: usize = std::mem::offset_of!(WideNode, child);

/// Per-node SAH shares written by the parts' tasks (each its own nodes').
struct SharePtr(*mut f64);

// SAFETY: each task writes only the entries of its own part's nodes (`refit_in_parts`).
unsafe impl Sync for SharePtr {}

impl SharePtr {
    fn at(&self, index: usize) -> *mut f64 {
        self.0.wrapping_add(index)
    }
}

/// Nodes per run of the SAH sum (fixed, so the sum's rounding does not depend on threads).
const SAH_CHUNK: usize = 1024;

/// Per run of [`SAH_CHUNK`] nodes, the sum of `share` over its nodes from its last back
/// (the order [`WideBvh::refit_inner`] meets them), in a register; the runs side by side
/// on large trees (the same bits: each run is summed alone).
fn run_sums<T: Sync>(nodes: &[T], share: impl Fn(&T) -> f64 + Sync) -> Vec<f64> {
    let run = |run: &[T]| run.iter().rev().fold(0.0f64, |sum, node| sum + share(node));
    if nodes.len() >= PARALLEL_SAH_MIN_NODES {
        nodes.par_chunks(SAH_CHUNK).map(run).collect()
    } else {
        nodes.chunks(SAH_CHUNK).map(run).collect()
    }
}

/// Past this many nodes the SAH runs are summed on rayon's threads.
const PARALLEL_SAH_MIN_NODES: usize = 8 * SAH_CHUNK;

impl WideNode {
    /// The sum over used lanes of the lane box's half area times its cost (`traversal` for
    /// an inner child, `intersection` per triangle for a leaf), in lane order.
    ///
    /// The eight half areas are taken side by side from the bound rows (the compiler makes
    /// vectors of the loop), each lane with `Aabb::half_area`'s operations in its order,
    /// `(dx + dy) * dz + dx * dy`, so the same bits as one lane box at a time (a NaN's
    /// sign aside, which Rust leaves unspecified); the `f64` sum stays in lane order.
    #[inline]
    fn weighted_area(&self, traversal: f32, intersection: f32) -> f64 {
        let b = &self.bounds;
        let mut half_areas = [0.0f32; WIDTH];
        for (lane, half_area) in half_areas.iter_mut().enumerate() {
            let (dx, dy, dz) = (
                b[3][lane] - b[0][lane],
                b[4][lane] - b[1][lane],
                b[5][lane] - b[2][lane],
            );
            *half_area = (dx + dy) * dz + dx * dy;
        }
        self.weighted_sum(traversal, intersection, |lane| half_areas[lane])
    }

    /// [`Self::weighted_area`] one lane box at a time (the reference its tests hold it to).
    #[cfg(test)]
    fn weighted_area_by_lane_box(&self, traversal: f32, intersection: f32) -> f64 {
        self.weighted_sum(traversal, intersection, |lane| {
            self.lane_box(lane).half_area()
        })
    }

    /// The sum in lane order over used lanes of `half_area(lane)` times the lane's cost.
    #[inline(always)]
    fn weighted_sum(
        &self,
        traversal: f32,
        intersection: f32,
        half_area: impl Fn(usize) -> f32,
    ) -> f64 {
        let mut sum = 0.0f64;
        for lane in 0..WIDTH {
            let child = self.child[lane];
            if child == EMPTY {
                continue;
            }
            let step = if child & LEAF != 0 {
                self.count[lane] as f32 * intersection
            } else {
                traversal
            };
            sum += f64::from(half_area(lane)) * f64::from(step);
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::wide::test_support::*;
    use glam::Vec3A;
    use obvhs::aabb::Aabb;

    /// A node's SAH share from its rows side by side gives the bits of one lane box at a
    /// time: random boxes of every magnitude, flat, point-like, inverted and non-finite
    /// ones, with unused, inner and leaf lanes of many counts mixed.
    #[test]
    fn weighted_area_of_the_rows_equals_lane_box_by_lane_box() {
        let mut next = xorshift(0x5eed_1234);
        let mut value = || {
            let bits = next();
            match bits % 11 {
                0 => 0.0,
                1 => -0.0,
                2 => f32::INFINITY,
                3 => f32::NEG_INFINITY,
                4 => f32::NAN,
                5 => f32::MAX,
                6 => f32::from_bits(1 + (bits >> 40) as u32),
                _ => (bits >> 40) as f32 * 1e-3 * if bits & 1 == 0 { 1.0 } else { -1e30 },
            }
        };
        let mut kinds = xorshift(99);
        for _ in 0..5000 {
            let mut node = WideNode::UNUSED;
            for lane in 0..WIDTH {
                match kinds() % 4 {
                    0 => continue, // unused: the inverted box
                    1 => node.child[lane] = lane as u32 + 1,
                    _ => {
                        node.child[lane] = LEAF | lane as u32;
                        node.count[lane] = (kinds() % 9) as u32;
                    }
                }
                let (a, b) = (
                    Vec3A::new(value(), value(), value()),
                    Vec3A::new(value(), value(), value()),
                );
                let aabb = if kinds().is_multiple_of(3) {
                    Aabb::new(a, b)
                } else {
                    Aabb::new(a.min(b), a.max(b))
                };
                node.set_box(lane, &aabb);
            }
            for (traversal, intersection) in [(1.0, 1.0), (0.3, 2.5), (f32::MAX, 1e-30)] {
                let ours = node.weighted_area(traversal, intersection);
                let reference = node.weighted_area_by_lane_box(traversal, intersection);
                // A NaN's sign and payload are not specified (the vector code may take the
                // operands of a sum in the other order); any NaN is the same cost.
                let same =
                    ours.to_bits() == reference.to_bits() || (ours.is_nan() && reference.is_nan());
                assert!(same, "{ours} against {reference}: {node:?}");
            }
        }
    }

    /// The leaves' sizes are measured again after every kind of refit, not kept from
    /// before: a leaf grown a thousandfold raises the typical side.
    #[test]
    fn leaf_sides_follow_refits() {
        let binary = build(16);
        let mut wide = WideBvh::collapse(&binary, |first, _| first);
        let before = wide.leaf_sides();
        assert_eq!(before.count as usize, wide.leaf_lanes.len());
        let huge = Aabb::new(Vec3A::ZERO, Vec3A::splat(1000.0));
        wide.refit_leaf(wide.leaf_lanes[0], &huge);
        let after_one = wide.leaf_sides();
        assert!(
            after_one.typical() > before.typical(),
            "{after_one:?} {before:?}"
        );
        for leaf in 1..wide.leaf_lanes.len() {
            wide.set_leaf_box(wide.leaf_lanes[leaf], &huge);
        }
        wide.refit_inner(1.0, 1.0);
        assert_eq!(wide.leaf_sides().typical(), 1000.0);
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
        let cost = full.refit_inner(1.0, 1.0);
        // The cost taken on the way up is the cost of the refitted tree, to the bit.
        assert_eq!(cost, full.sah_cost(1.0, 1.0));
        assert!(cost.is_some_and(|c| c > 1.0));
        for (a, b) in full.nodes.iter().zip(&wide.nodes) {
            assert_eq!(a.bounds, b.bounds);
        }
    }

    /// Cutting a tree into parts: every node is above the parts or in exactly one part
    /// (its root or one of the root's descendants, which lie in the part's range), every
    /// part but the leaf-only ones keeps within its bound, the nodes above come children
    /// first, and a refit in parts gives the serial refit's bits.
    #[test]
    fn parts_cover_every_node_once_and_refit_alike() {
        // A row of boxes and two far away: the far ones become leaves of the nodes above
        // the parts, which the refit sets after the parts.
        let mut row = boxes(3000);
        for x in [1e6f32, -1e6] {
            row.push(Aabb::new(
                Vec3A::new(x, 0.0, 0.0),
                Vec3A::new(x + 1.0, 1.0, 1.0),
            ));
        }
        let mut params = obvhs::BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 1;
        let binary = obvhs::bvh2::builder::build_bvh2(&row, params, &mut Default::default());
        let mut wide = WideBvh::collapse(&binary, |first, _| first);
        for most in [1, 8, 40, 10_000] {
            let parts = wide.parts(most).unwrap();
            let mut seen = vec![0; wide.nodes.len()];
            for (p, (root, range)) in parts.parts.iter().enumerate() {
                assert!(range.len() < most.max(1) || range.is_empty());
                seen[*root as usize] += 1;
                for index in range.clone() {
                    seen[index as usize] += 1;
                    assert_eq!(parts.owner[index as usize], p as u32);
                    // Its parent is in the same part.
                    let up = wide.parent[index as usize] as usize / WIDTH;
                    assert!(up == *root as usize || range.contains(&(up as u32)));
                }
            }
            for &index in &parts.top {
                let index = index as usize;
                // Above the parts (a part's root is counted there and as its part's).
                seen[index] += usize::from(parts.owner[index] == EMPTY);
            }
            assert!(seen.iter().all(|&s| s == 1), "{most}: {seen:?}");
            assert!(parts.top.windows(2).all(|w| w[0] > w[1]));
            assert_eq!(parts.top.last(), Some(&0));
        }
        // Move every leaf, then refit serially and in parts.
        let leaf_boxes: Vec<Aabb> = (0..wide.leaf_lanes.len())
            .map(|i| {
                let x = (i * 7919 % 3002) as f32;
                Aabb::new(Vec3A::new(x, -x, 0.5), Vec3A::new(x + 2.0, 1.0 - x, 3.0))
            })
            .collect();
        let mut serial = wide.clone();
        for (i, aabb) in leaf_boxes.iter().enumerate() {
            serial.set_leaf_box(serial.leaf_lanes[i], aabb);
        }
        let serial_cost = serial.refit_inner(1.0, 1.0);
        let parts = wide.parts(40).unwrap();
        let leaf_lanes = wide.leaf_lanes.clone();
        assert!(
            leaf_lanes
                .iter()
                .any(|&at| parts.part_of_lane(at).is_none())
        );
        let cost = wide.refit_in_parts(
            &parts,
            |part, lanes| {
                for (i, &at) in leaf_lanes.iter().enumerate() {
                    if parts.part_of_lane(at) == part {
                        // SAFETY: each leaf is set by the one call for its part.
                        unsafe { lanes.set_leaf_box(at, &leaf_boxes[i]) };
                    }
                }
            },
            1.0,
            1.0,
        );
        assert_eq!(cost.map(f32::to_bits), serial_cost.map(f32::to_bits));
        assert_eq!(wide.bounds_bits(), serial.bounds_bits());
    }
}
