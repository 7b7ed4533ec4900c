//! From obvhs's binary tree to the wide tree: each wide node takes a binary inner node's two
//! children and keeps opening its largest inner child until it has eight. Lanes keep the
//! binary tree's left-to-right (spatial) order, which the lane-order walks of shadow rays
//! rely on. Parents come before children, so a backwards sweep visits children first.

use obvhs::bvh2::Bvh2;

use super::node::WideNode;
use super::{EMPTY, LEAF, WIDTH, WideBvh};

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
        // The arrays grew by doubling; a tree is kept for many frames, so give back the
        // spare capacity (up to half of each array).
        wide.nodes.shrink_to_fit();
        wide.parent.shrink_to_fit();
        wide.leaf_lanes.shrink_to_fit();
        wide
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
    use crate::accel::wide::node::ChildRef;
    use crate::accel::wide::test_support::*;
    use glam::Vec3A;
    use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::builder::build_bvh2};
    use std::time::Duration;

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
}
