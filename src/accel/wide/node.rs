//! One node of the wide tree: eight child boxes as structure of arrays (each bound a row of
//! eight `f32`, one 32-byte vector) and what each child is (an inner node, a leaf's first
//! record and count, or unused: an inverted box no ray enters).

use glam::{Vec3A, Vec4};
use obvhs::aabb::Aabb;

use super::{EMPTY, LEAF, WIDTH};

/// A row of [`WideNode::bounds`]: the lower planes of x, y and z, then the upper ones.
///
/// Why an enum and not a `u8`: a node test picks its rows by the ray's direction, and the
/// compiler can prove an enum's rows in range where it checked a byte's (a compare and a
/// branch for each of the test's six rows, about a fifth of its instructions).
///
/// Each value is where its row starts among the node's bounds taken as one array of floats
/// (`row * WIDTH`): a load addresses it as base + value x 4, which x86-64 does within the
/// load itself. Numbered by row, every one of a node test's six loads took a shift first
/// (a row is 32 bytes, beyond the addressing modes' largest scale of 8).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(u8)]
pub enum Plane {
    #[default]
    LowX = 0,
    LowY = WIDTH as u8,
    LowZ = 2 * WIDTH as u8,
    HighX = 3 * WIDTH as u8,
    HighY = 4 * WIDTH as u8,
    HighZ = 5 * WIDTH as u8,
}

impl Plane {
    /// The plane of `axis` (0, 1 or 2; larger values are taken as z): the upper one when
    /// `upper`.
    #[inline(always)]
    pub const fn of(axis: usize, upper: bool) -> Plane {
        match (axis, upper) {
            (0, false) => Plane::LowX,
            (1, false) => Plane::LowY,
            (_, false) => Plane::LowZ,
            (0, true) => Plane::HighX,
            (1, true) => Plane::HighY,
            (_, true) => Plane::HighZ,
        }
    }

    /// The planes a ray meets first and last along x, y and z, from the signs of its
    /// direction: bit `axis` of `negative` set where it runs toward lower coordinates (it
    /// meets the upper plane first there). Bits above the third are ignored.
    ///
    /// A table of the eight sign patterns: making the six planes one comparison at a time
    /// was eight instructions of every ray's setup (64 rays a packet).
    #[inline(always)]
    pub fn met_first_and_last(negative: u32) -> ([Plane; 3], [Plane; 3]) {
        MET_FIRST_AND_LAST[(negative & 0b111) as usize]
    }

    /// The row of [`WideNode::bounds`] (0 to 5).
    #[inline(always)]
    pub const fn row(self) -> usize {
        self.first_float() / WIDTH
    }

    /// Where the row starts among a node's bounds as one array of floats.
    #[inline(always)]
    const fn first_float(self) -> usize {
        self as usize
    }
}

/// [`Plane::met_first_and_last`] of every sign pattern.
const MET_FIRST_AND_LAST: [([Plane; 3], [Plane; 3]); 8] = {
    let mut table = [([Plane::LowX; 3], [Plane::LowX; 3]); 8];
    let mut negative = 0;
    while negative < 8 {
        let mut axis = 0;
        while axis < 3 {
            let down = negative & (1 << axis) != 0;
            table[negative].0[axis] = Plane::of(axis, down);
            table[negative].1[axis] = Plane::of(axis, !down);
            axis += 1;
        }
        negative += 1;
    }
    table
};

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

    /// The bounds of every lane on `plane`. The slice's range checks compile away in
    /// release builds: a [`Plane`] starts a row, and the compiler knows the largest one
    /// leaves a whole row.
    #[inline(always)]
    pub(super) fn plane(&self, plane: Plane) -> &[f32; WIDTH] {
        let row = &self.bounds.as_flattened()[plane.first_float()..][..WIDTH];
        row.try_into().expect("a row is WIDTH floats")
    }

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_is_the_row_of_its_axis_and_side() {
        for axis in 0..3 {
            for upper in [false, true] {
                let plane = Plane::of(axis, upper);
                assert_eq!(plane.row(), axis + 3 * usize::from(upper));
                let node = WideNode {
                    bounds: std::array::from_fn(|row| [row as f32; WIDTH]),
                    ..WideNode::UNUSED
                };
                assert_eq!(node.plane(plane), &node.bounds[plane.row()]);
            }
        }
        assert_eq!(Plane::default(), Plane::LowX);
    }

    #[test]
    fn the_sign_table_names_the_planes_met_first_and_last() {
        for negative in 0..16u32 {
            let (front, back) = Plane::met_first_and_last(negative);
            for axis in 0..3 {
                let down = negative & (1 << axis) != 0;
                assert_eq!(
                    front[axis],
                    Plane::of(axis, down),
                    "{negative:b} axis {axis}"
                );
                assert_eq!(
                    back[axis],
                    Plane::of(axis, !down),
                    "{negative:b} axis {axis}"
                );
            }
        }
    }
}
