//! Refitting the wide tree in place, and its SAH cost.
//!
//! A full refit sets every leaf's lane (from concurrent tasks through [`LeafLanes`]: leaves
//! never share a lane), then every inner lane as the union of its child's lanes, children
//! first; a partial refit walks up from one leaf and stops at the first ancestor whose box
//! comes out unchanged. A tree of one leaf keeps no box.

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
}

impl WideBvh {
    /// Sets the box of the leaf in lane `at` (`node * WIDTH + lane`); a full refit sets
    /// every leaf's, then calls [`WideBvh::refit_inner`]. A tree of one leaf keeps no box
    /// (rays test that leaf whatever), so there it does nothing. (Refits write leaf boxes
    /// through [`WideBvh::leaf_lanes_writer`]; tests build trees with this.)
    #[cfg(test)]
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

    /// Refits every inner lane as the union of its child's lanes, children first, and
    /// returns the refitted tree's SAH cost ([`WideBvh::sah_cost`], the same bits): each
    /// node's share is taken while the refit has it in cache (every node's lanes are final
    /// when the backward walk reaches it), instead of a second pass over the nodes.
    pub fn refit_inner(&mut self, traversal: f32, intersection: f32) -> Option<f32> {
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
    ///
    /// Summed per run of [`SAH_CHUNK`] nodes (each run from its last node back, the order
    /// [`WideBvh::refit_inner`] meets them), then over the runs in order, so the value is
    /// the same whether the runs are summed on one thread or several.
    pub fn sah_cost(&self, traversal: f32, intersection: f32) -> Option<f32> {
        let run = |nodes: &[WideNode]| {
            nodes.iter().rev().fold(0.0f64, |sum, node| {
                sum + node.weighted_area(traversal, intersection)
            })
        };
        let runs: Vec<f64> = if self.nodes.len() >= PARALLEL_SAH_MIN_NODES {
            self.nodes.par_chunks(SAH_CHUNK).map(run).collect()
        } else {
            self.nodes.chunks(SAH_CHUNK).map(run).collect()
        };
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

/// Nodes per run of the SAH sum (fixed, so the sum's rounding does not depend on threads).
const SAH_CHUNK: usize = 1024;

/// Past this many nodes the SAH runs are summed on rayon's threads.
const PARALLEL_SAH_MIN_NODES: usize = 8 * SAH_CHUNK;

impl WideNode {
    /// The sum over used lanes of the lane box's half area times its cost (`traversal` for
    /// an inner child, `intersection` per triangle for a leaf).
    #[inline]
    fn weighted_area(&self, traversal: f32, intersection: f32) -> f64 {
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
            sum += f64::from(self.lane_box(lane).half_area()) * f64::from(step);
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
}
