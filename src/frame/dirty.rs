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

use rayon::prelude::*;

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

    /// Lists, in the order `visited` yields them, the slots whose entry in `motion_of_slot`
    /// is set, with that motion, and clears `motion_of_slot`; the parallel counterpart of
    /// [`Self::mark`] called in that order. Preconditions: the set was just
    /// [`reset`](Self::reset) for `motion_of_slot.len()` slots, and `visited` yields each
    /// slot at most once.
    pub fn assign_in_order(
        &mut self,
        visited: impl ParallelIterator<Item = u32>,
        motion_of_slot: &mut [Option<Motion>],
    ) {
        debug_assert!(
            self.slots.is_empty() && self.bits.len() == motion_of_slot.len().div_ceil(64)
        );
        let marked = visited.filter_map(|slot| motion_of_slot[slot as usize].map(|m| (slot, m)));
        let mut listed = (
            std::mem::take(&mut self.slots),
            std::mem::take(&mut self.motions),
        );
        listed.par_extend(marked);
        (self.slots, self.motions) = listed;
        self.bits
            .par_iter_mut()
            .zip(motion_of_slot.par_chunks_mut(64))
            .for_each(|(word, motions)| {
                for (bit, motion) in motions.iter_mut().enumerate() {
                    if motion.take().is_some() {
                        *word |= 1 << bit;
                    }
                }
            });
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

    #[test]
    fn listing_in_order_equals_marking_one_by_one() {
        let order: Vec<u32> = (0..5000u32).map(|k| (k * 7919) % 5000).collect();
        let motion_at = |slot: u32| match slot % 5 {
            0 => Some(Motion::Rigid),
            1 => Some(Motion::Deformed),
            2 => Some(Motion::Scaled),
            _ => None,
        };
        let mut one_by_one = DirtySet::default();
        one_by_one.reset(5000);
        for &slot in &order {
            if let Some(m) = motion_at(slot) {
                one_by_one.mark(slot, m);
            }
        }
        let mut motions: Vec<Option<Motion>> = (0..5000).map(motion_at).collect();
        let mut listed = DirtySet::default();
        listed.reset(5000);
        listed.assign_in_order(order.par_iter().copied(), &mut motions);
        assert_eq!(listed.slots, one_by_one.slots);
        assert_eq!(listed.motions, one_by_one.motions);
        assert_eq!(listed.bits, one_by_one.bits);
        assert!(motions.iter().all(Option::is_none), "the marks are taken");
    }
}
