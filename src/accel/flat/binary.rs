//! The binary tree a flat build collapses into the wide tree: obvhs's PLOC builder over the
//! triangles' padded boxes, in chunks when there are many.
//!
//! Why chunks: the builder's working arrays (two node arrays, Morton codes and its own
//! binary tree of `2n - 1` nodes) come to about 228 bytes per triangle while it runs, more
//! than a frame keeps for the triangle itself, so at a million triangles it set the
//! process's peak. Past [`CHUNK_TRIANGLES`] the triangles are split at the median of their
//! box centres along the longest axis of those centres, recursively, until each part is
//! at most a chunk; each chunk is built alone (its working arrays freed before the next
//! one starts) and only the nodes its root reaches are kept. The splits become the tree's
//! top inner nodes. Below the threshold (every BART scene, every sample scene) the build is
//! obvhs's, node for node, as before.
//!
//! Invariant (what `Accel::build` relies on): the tree's leaves cover every triangle exactly
//! once, each leaf's primitives are a contiguous run of `primitive_indices`, inner nodes
//! keep their two children adjacent (`first_index`, `first_index + 1`) with the root at
//! node 0, and every node's box holds the padded boxes below it.

use std::time::Duration;

use bytemuck::TransparentWrapper;
use glam::Vec3A;
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    bvh2::{Bvh2, builder::build_bvh2, node::Bvh2Node},
};

use super::{PaddedTriangle, padded_box};

/// Most triangles one PLOC build takes at once: its working arrays then stay near 30 MB
/// however large the mesh, and no BART or sample scene (the largest, BART Kitchen, has
/// 110,561 triangles) is split.
pub const CHUNK_TRIANGLES: usize = 1 << 17;

/// The binary tree over `positions` (primitive `i` is triangle `i`), built in chunks of at
/// most `chunk` triangles (module docs).
pub(in crate::accel) fn binary_tree(positions: &[[Vec3A; 3]], chunk: usize) -> Bvh2 {
    if positions.len() <= chunk.max(1) {
        return build_chunk(PaddedTriangle::wrap_slice(positions));
    }
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    let mut tree = ChunkedTree {
        positions,
        chunk: chunk.max(1),
        nodes: vec![Bvh2Node::default()],
        primitive_indices: Vec::with_capacity(positions.len()),
        gathered: Vec::new(),
    };
    tree.fill(0, &mut order);
    Bvh2 {
        nodes: tree.nodes,
        primitive_indices: tree.primitive_indices,
        ..Bvh2::default()
    }
}

/// obvhs's build as `Accel` always used it.
fn build_chunk(triangles: &[PaddedTriangle]) -> Bvh2 {
    build_bvh2(
        triangles,
        BvhBuildParams::medium_build(),
        &mut Duration::default(),
    )
}

/// The tree being assembled from the splits and the chunks' trees.
struct ChunkedTree<'a> {
    positions: &'a [[Vec3A; 3]],
    chunk: usize,
    nodes: Vec<Bvh2Node>,
    primitive_indices: Vec<u32>,
    /// A chunk's triangles copied together for its build (reused).
    gathered: Vec<[Vec3A; 3]>,
}

impl ChunkedTree<'_> {
    /// Makes node `at` the root of a tree over the triangles `part` lists (reordering
    /// `part`).
    fn fill(&mut self, at: usize, part: &mut [u32]) {
        if part.len() <= self.chunk {
            self.append_chunk(at, part);
            return;
        }
        let (left, right) = split_at_median(self.positions, part);
        let first = self.nodes.len();
        self.nodes.extend([Bvh2Node::default(); 2]);
        self.fill(first, left);
        self.fill(first + 1, right);
        let aabb = self.nodes[first].aabb().union(self.nodes[first + 1].aabb());
        self.nodes[at] = Bvh2Node::new(aabb, 0, first as u32);
    }

    /// Builds the chunk `part` lists and copies the nodes its root reaches, the root into
    /// node `at`, its primitives appended as the triangles' own indices.
    fn append_chunk(&mut self, at: usize, part: &[u32]) {
        self.gathered.clear();
        self.gathered
            .extend(part.iter().map(|&i| self.positions[i as usize]));
        let built = build_chunk(PaddedTriangle::wrap_slice(&self.gathered));
        let primitive_base = self.primitive_indices.len() as u32;
        self.primitive_indices
            .extend(built.primitive_indices.iter().map(|&p| part[p as usize]));
        // (node of the chunk's tree, where it goes); children are placed as adjacent pairs.
        let mut pending = vec![(0usize, at)];
        while let Some((from, to)) = pending.pop() {
            let node = built.nodes[from];
            self.nodes[to] = if node.is_leaf() {
                Bvh2Node::new(
                    *node.aabb(),
                    node.prim_count,
                    primitive_base + node.first_index,
                )
            } else {
                let first = self.nodes.len();
                self.nodes.extend([Bvh2Node::default(); 2]);
                let child = node.first_index as usize;
                pending.extend([(child, first), (child + 1, first + 1)]);
                Bvh2Node::new(*node.aabb(), 0, first as u32)
            };
        }
    }
}

/// Splits `part` into halves at the median of the triangles' box centres along the longest
/// axis of those centres (ties by triangle index, so the split is a pure function of the
/// input).
fn split_at_median<'p>(
    positions: &[[Vec3A; 3]],
    part: &'p mut [u32],
) -> (&'p mut [u32], &'p mut [u32]) {
    let centre = |i: u32| {
        let b = padded_box(&positions[i as usize]);
        // Halves first: the sum of two coordinates near f32::MAX would overflow.
        b.min * 0.5 + b.max * 0.5
    };
    let bounds = part.iter().fold(Aabb::empty(), |mut a, &i| {
        a.extend(centre(i));
        a
    });
    let extent = bounds.diagonal();
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = part.len() / 2;
    part.select_nth_unstable_by(mid, |&a, &b| {
        centre(a)[axis].total_cmp(&centre(b)[axis]).then(a.cmp(&b))
    });
    part.split_at_mut(mid)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_triangles(n: usize, seed: u64) -> Vec<[Vec3A; 3]> {
        let mut state = seed;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32
        };
        (0..n)
            .map(|_| {
                let c = Vec3A::new(next(), next(), next()) * 100.0;
                std::array::from_fn(|_| c + Vec3A::new(next(), next(), next()))
            })
            .collect()
    }

    /// Walks the tree from the root: every triangle in exactly one leaf, children adjacent
    /// and inside their parent's box, every triangle's padded box inside its leaf's.
    fn check_tree(tree: &Bvh2, positions: &[[Vec3A; 3]]) -> usize {
        let mut seen = vec![0u32; positions.len()];
        let mut leaves = 0;
        let mut pending = vec![0usize];
        let contains = |outer: &Aabb, inner: &Aabb| {
            outer.min.cmple(inner.min).all() && inner.max.cmple(outer.max).all()
        };
        while let Some(i) = pending.pop() {
            let node = &tree.nodes[i];
            if node.is_leaf() {
                leaves += 1;
                let first = node.first_index as usize;
                for &p in &tree.primitive_indices[first..first + node.prim_count as usize] {
                    seen[p as usize] += 1;
                    assert!(contains(node.aabb(), &padded_box(&positions[p as usize])));
                }
            } else {
                let c = node.first_index as usize;
                assert!(c > i, "children after their parent");
                for child in [c, c + 1] {
                    assert!(contains(node.aabb(), tree.nodes[child].aabb()));
                    pending.push(child);
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "each triangle in one leaf");
        leaves
    }

    #[test]
    fn chunked_tree_covers_every_triangle_once_inside_its_boxes() {
        let positions = random_triangles(5_000, 7);
        for chunk in [1, 2, 3, 64, 1_000, 2_499, 2_500, 4_999] {
            let tree = binary_tree(&positions, chunk);
            let leaves = check_tree(&tree, &positions);
            // Compacted: only reachable nodes are kept.
            assert_eq!(tree.nodes.len(), 2 * leaves - 1, "chunk {chunk}");
        }
    }

    #[test]
    fn below_one_chunk_the_tree_is_obvhs_own() {
        let positions = random_triangles(3_000, 11);
        let ours = binary_tree(&positions, CHUNK_TRIANGLES);
        let theirs = build_chunk(PaddedTriangle::wrap_slice(&positions));
        assert_eq!(ours.primitive_indices, theirs.primitive_indices);
        assert_eq!(ours.nodes.len(), theirs.nodes.len());
        for (a, b) in ours.nodes.iter().zip(&theirs.nodes) {
            assert_eq!(
                (a.aabb(), a.prim_count, a.first_index),
                (b.aabb(), b.prim_count, b.first_index)
            );
        }
    }

    #[test]
    fn chunked_tree_is_a_pure_function_of_its_input() {
        // Many equal centres (a stack of identical triangles) exercise the ties.
        let mut positions = random_triangles(2_000, 3);
        let same = positions[0];
        positions.extend(std::iter::repeat_n(same, 1_500));
        let a = binary_tree(&positions, 100);
        let b = binary_tree(&positions, 100);
        check_tree(&a, &positions);
        assert_eq!(a.primitive_indices, b.primitive_indices);
        assert!(
            a.nodes
                .iter()
                .zip(&b.nodes)
                .all(|(x, y)| x.aabb() == y.aabb()
                    && x.first_index == y.first_index
                    && x.prim_count == y.prim_count)
        );
    }

    #[test]
    fn huge_coordinates_split_without_overflow() {
        // Box centres as (min + max) / 2 would overflow here.
        let big = f32::MAX * 0.9;
        let positions: Vec<[Vec3A; 3]> = (0..600)
            .map(|i| {
                let x = if i % 2 == 0 { big } else { -big } * (1.0 - i as f32 * 1e-4);
                let p = Vec3A::new(x, i as f32, 0.0);
                [p, p + Vec3A::Y, p + Vec3A::Z]
            })
            .collect();
        let tree = binary_tree(&positions, 50);
        check_tree(&tree, &positions);
        assert!(
            tree.nodes
                .iter()
                .all(|n| n.aabb().min.is_finite() && n.aabb().max.is_finite())
        );
        // The split is along x (where the extent is), so it separated the two signs.
        let root = &tree.nodes[0];
        let halves = [
            &tree.nodes[root.first_index as usize],
            &tree.nodes[root.first_index as usize + 1],
        ];
        assert!(
            halves.iter().any(|h| h.aabb().max.x < 0.0)
                && halves.iter().any(|h| h.aabb().min.x > 0.0)
        );
    }
}
