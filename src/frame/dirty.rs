//! What changed this frame: the dirty set that drives both the BVH update and the LOD update.
//!
//! Per triangle (by BVH slot) one of four motions, decided per instance from its transform
//! and, for deforming meshes, per triangle from its vertices:
//! - *static*: untouched (not in the set);
//! - *rigid*: moved by a rotation + translation: its box moves, `log2 P_b` is unchanged;
//! - *scaled*: moved by a similarity with a new uniform scale `s`: `log2 P_b` is the
//!   object-space constant plus `log2 s`;
//! - *deformed*: shape changed (skinning, morphing, non-uniform scale or shear): `log2 P_b`
//!   is recomputed from its world vertices.

/// How one triangle moved this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    Rigid,
    Scaled,
    Deformed,
}

/// The moved triangles of one frame: a bitset for membership and a compact list in the
/// order they were marked, with their motion.
#[derive(Debug, Default, Clone)]
pub struct DirtySet {
    bits: Vec<u64>,
    /// Moved slots, each once.
    pub slots: Vec<u32>,
    /// Motion of each entry of `slots`.
    pub motions: Vec<Motion>,
}

impl DirtySet {
    /// Empties the set for a frame with `slots` triangles (keeps allocations).
    pub fn reset(&mut self, slots: usize) {
        self.bits.clear();
        self.bits.resize(slots.div_ceil(64), 0);
        self.slots.clear();
        self.motions.clear();
    }

    /// Marks a slot as moved (a slot marked twice keeps its first motion).
    #[inline]
    pub fn mark(&mut self, slot: u32, motion: Motion) {
        let (word, bit) = (slot as usize / 64, slot % 64);
        if self.bits[word] & (1 << bit) == 0 {
            self.bits[word] |= 1 << bit;
            self.slots.push(slot);
            self.motions.push(motion);
        }
    }

    #[inline]
    pub fn contains(&self, slot: u32) -> bool {
        self.bits
            .get(slot as usize / 64)
            .is_some_and(|w| w & (1 << (slot % 64)) != 0)
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }

    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// How many entries have motion `m`.
    pub fn count(&self, m: Motion) -> usize {
        self.motions.iter().filter(|&&x| x == m).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dirty_set_marks_once() {
        let mut d = DirtySet::default();
        d.reset(130);
        d.mark(129, Motion::Rigid);
        d.mark(3, Motion::Deformed);
        d.mark(129, Motion::Deformed);
        assert_eq!(d.slots, vec![129, 3]);
        assert_eq!(d.motions, vec![Motion::Rigid, Motion::Deformed]);
        assert!(d.contains(3) && d.contains(129) && !d.contains(4));
        assert_eq!(d.count(Motion::Deformed), 1);
        d.reset(130);
        assert!(d.is_empty() && !d.contains(3));
    }
}
