//! One node of the wide tree: eight child boxes as structure of arrays (each bound a row of
//! eight `f32`, one 32-byte vector) and what each child is (an inner node, a leaf's first
//! record and count, or unused: an inverted box no ray enters).

use glam::{Vec3A, Vec4};
use obvhs::aabb::Aabb;

use super::{EMPTY, LEAF, WIDTH};

/// One node: eight child boxes as structure of arrays (`bounds[plane][lane]`, planes lower
/// x, y, z then upper x, y, z; each row one 32-byte vector), and what each child is. 256
/// bytes, four cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct WideNode {
    pub(super) bounds: [[f32; WIDTH]; 6],
    /// Inner child: its node index. Leaf child: `LEAF | first slot`. Unused: `EMPTY`.
    pub(super) child: [u32; WIDTH],
    /// Leaf child: its triangle count; 0 otherwise.
    pub(super) count: [u32; WIDTH],
}

impl WideNode {
    pub(super) const UNUSED: WideNode = WideNode {
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

    pub(super) fn lane_box(&self, lane: usize) -> Aabb {
        let b = &self.bounds;
        Aabb::new(
            Vec3A::new(b[0][lane], b[1][lane], b[2][lane]),
            Vec3A::new(b[3][lane], b[4][lane], b[5][lane]),
        )
    }

    /// The union of the used lanes' boxes: the least of each lower row and the greatest of
    /// each upper row over all eight lanes at once (unused lanes hold an inverted box, which
    /// neither changes; a node with no used lane gives the empty box).
    #[inline]
    pub(super) fn bounds_union(&self) -> Aabb {
        let halves =
            |row: &[f32; WIDTH]| (Vec4::from_slice(&row[..4]), Vec4::from_slice(&row[4..]));
        let least = |row| {
            let (a, b) = halves(row);
            a.min(b).min_element()
        };
        let greatest = |row| {
            let (a, b) = halves(row);
            a.max(b).max_element()
        };
        let b = &self.bounds;
        Aabb::new(
            Vec3A::new(least(&b[0]), least(&b[1]), least(&b[2])),
            Vec3A::new(greatest(&b[3]), greatest(&b[4]), greatest(&b[5])),
        )
    }

    pub(super) fn set_box(&mut self, lane: usize, aabb: &Aabb) {
        for axis in 0..3 {
            self.bounds[axis][lane] = aabb.min[axis];
            self.bounds[axis + 3][lane] = aabb.max[axis];
        }
    }
}

/// A reference to a subtree: an inner node or a leaf's slot range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ChildRef {
    Node(u32),
    Leaf { first: u32, count: u32 },
}

impl ChildRef {
    #[inline(always)]
    pub(super) fn decode(child: u32, count: u32) -> ChildRef {
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
