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

use std::ops::Range;

use rayon::prelude::*;

use super::two_level::PlacedChanges;

/// Source triangles per parallel listing task.
const LIST_CHUNK: usize = 16384;

/// How one triangle moved this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    Rigid,
    Scaled,
    Deformed,
}

/// How [`DirtySet::assign_in_source_order`] finds a range's moved sources.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Listed {
    /// By their motion in `source_motion` (taken from it).
    ByMotion,
    /// By their slot's bit, every one as [`Motion::Deformed`] (a deforming instance whose
    /// write set the bits of exactly the slots it moved and recorded no motions).
    DeformedByBit,
}

/// What moved this frame: the output of the dirty step, read by the tree step (what to
/// refit, and the marks a rebuild carries into the new slot order) and by the `log2 P_b`
/// step (which constants to recompute or shift).
#[derive(Debug, Default)]
pub(super) struct FrameChanges {
    pub dirty: DirtySet,
    /// The runs of the dirty list (entry indices, increasing) whose slots belong to deforming
    /// instances: the `log2 P_b` step walks those slots in slot order instead.
    pub deformed_entries: Vec<Range<usize>>,
    /// The runs of placed instances that scaled or changed shape: the entries the `log2
    /// P_b` step visits one by one (rigid runs keep their constants and are skipped whole).
    pub reshaped_entries: Vec<Range<usize>>,
    /// Whether this frame's write gave a moved triangle a non-finite vertex.
    pub moved_nonfinite: bool,
    /// What this frame's placed instances changed (two-level only; counted into the record).
    pub placed: PlacedChanges,
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

    /// Lists the source triangles of `visited` (increasing, disjoint ranges) whose entry in
    /// `source_motion` is set, in source order, as their slots (`slot_of_source`) with that
    /// motion, and clears those entries (a range [`Listed::DeformedByBit`]: those whose
    /// slot's bit is set, as deformed; only with `bits_set`): the parallel counterpart of [`Self::mark`] called in
    /// that order. The ranges are cut into chunks that are counted, then filled at their
    /// offsets, on rayon's threads; every read is sequential. Precondition: the set was just
    /// [`reset`](Self::reset) for every slot `slot_of_source` names; then either no bit is
    /// set (`bits_set` false: the listed slots' bits are set here, in a serial pass), or the
    /// bits of exactly the slots to be listed are (`bits_set` true: the write in slot order
    /// sets them as it goes, each task in its own words). Fills `listed` with how many
    /// entries each range gave, in order.
    pub fn assign_in_source_order(
        &mut self,
        visited: impl Iterator<Item = (Range<u32>, Listed)>,
        source_motion: &mut [Option<Motion>],
        slot_of_source: &[u32],
        bits_set: bool,
        listed: &mut Vec<usize>,
    ) {
        debug_assert!(self.slots.is_empty());
        // Each chunk with the index of the range it comes from and how it is listed.
        let visited: Vec<(Range<u32>, Listed)> = visited.collect();
        debug_assert!(bits_set || visited.iter().all(|(_, l)| *l == Listed::ByMotion));
        let chunks: Vec<(usize, Range<usize>, Listed)> = visited
            .iter()
            .cloned()
            .enumerate()
            .flat_map(|(index, (r, how))| {
                let (start, end) = (r.start as usize, r.end as usize);
                (start..end)
                    .step_by(LIST_CHUNK)
                    .map(move |a| (index, a..(a + LIST_CHUNK).min(end), how))
            })
            .collect();
        let bits = &self.bits;
        let marked = |source: usize| {
            let slot = slot_of_source[source] as usize;
            bits[slot / 64] & (1 << (slot % 64)) != 0
        };
        let counts: Vec<usize> = chunks
            .par_iter()
            .map(|(_, c, how)| match how {
                Listed::ByMotion => source_motion[c.clone()].iter().flatten().count(),
                Listed::DeformedByBit => c.clone().filter(|&s| marked(s)).count(),
            })
            .collect();
        listed.clear();
        listed.resize(visited.len(), 0);
        for ((index, ..), &count) in chunks.iter().zip(&counts) {
            listed[*index] += count;
        }
        let total = counts.iter().sum();
        self.slots.resize(total, 0);
        self.motions.resize(total, Motion::Rigid);
        // Each chunk's input (its `source_motion` entries) and output (its share of the list).
        let mut jobs = Vec::with_capacity(chunks.len());
        let (mut input, mut consumed) = (source_motion, 0);
        let (mut slots, mut motions) = (&mut self.slots[..], &mut self.motions[..]);
        for ((_, chunk, how), &count) in chunks.iter().zip(&counts) {
            let (_, rest) = std::mem::take(&mut input).split_at_mut(chunk.start - consumed);
            let (here, rest) = rest.split_at_mut(chunk.len());
            (input, consumed) = (rest, chunk.end);
            let (chunk_slots, rest) = std::mem::take(&mut slots).split_at_mut(count);
            slots = rest;
            let (chunk_motions, rest) = std::mem::take(&mut motions).split_at_mut(count);
            motions = rest;
            jobs.push((chunk.start, *how, here, chunk_slots, chunk_motions));
        }
        jobs.into_par_iter()
            .for_each(|(first, how, input, slots, motions)| {
                let out = slots.iter_mut().zip(motions.iter_mut());
                let fill = |listed: &mut dyn Iterator<Item = (usize, Motion)>| {
                    for ((source, motion), (slot, out)) in listed.zip(out) {
                        *slot = slot_of_source[source];
                        *out = motion;
                    }
                };
                match how {
                    Listed::ByMotion => fill(
                        &mut input
                            .iter_mut()
                            .enumerate()
                            .filter_map(|(k, m)| Some((first + k, m.take()?))),
                    ),
                    Listed::DeformedByBit => fill(
                        &mut (first..first + input.len())
                            .filter(|&s| marked(s))
                            .map(|s| (s, Motion::Deformed)),
                    ),
                }
            });
        if bits_set {
            debug_assert!(self.slots.iter().all(|&s| self.contains(s)));
            debug_assert_eq!(
                self.bits
                    .iter()
                    .map(|w| w.count_ones() as usize)
                    .sum::<usize>(),
                self.slots.len()
            );
        } else {
            for &slot in &self.slots {
                self.bits[slot as usize / 64] |= 1 << (slot % 64);
            }
        }
    }

    /// The membership bits, to be set by a write that visits slots in order (see
    /// [`Self::assign_in_source_order`]'s `bits_set`).
    pub fn words_mut(&mut self) -> &mut [u64] {
        &mut self.bits
    }

    /// The membership bits: bit `s % 64` of word `s / 64` is slot `s`.
    pub fn words(&self) -> &[u64] {
        &self.bits
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
    fn listing_in_source_order_equals_marking_one_by_one() {
        let n = 3 * LIST_CHUNK as u32 + 500;
        // A permutation of the slots, and visited ranges with gaps, one longer than a chunk.
        let slot_of_source: Vec<u32> = (0..n).map(|k| (k * 7919) % n).collect();
        let visited = [
            3..40,
            50..50,
            100..100 + 2 * LIST_CHUNK as u32 + 7,
            n - 300..n,
        ];
        let motion_at = |source: u32| match source % 5 {
            0 => Some(Motion::Rigid),
            1 => Some(Motion::Deformed),
            2 => Some(Motion::Scaled),
            _ => None,
        };
        let mut one_by_one = DirtySet::default();
        one_by_one.reset(n as usize);
        for source in visited.iter().cloned().flatten() {
            if let Some(m) = motion_at(source) {
                one_by_one.mark(slot_of_source[source as usize], m);
            }
        }
        let mut motions: Vec<Option<Motion>> = (0..n).map(motion_at).collect();
        // The same listing when a write in slot order has already set the bits.
        let mut preset = DirtySet::default();
        preset.reset(n as usize);
        for &slot in &one_by_one.slots {
            preset.words_mut()[slot as usize / 64] |= 1 << (slot % 64);
        }
        let mut preset_motions = motions.clone();
        preset.assign_in_source_order(
            visited.iter().map(|r| (r.clone(), Listed::ByMotion)),
            &mut preset_motions,
            &slot_of_source,
            true,
            &mut Vec::new(),
        );
        assert_eq!(preset.slots, one_by_one.slots);
        assert_eq!(preset.motions, one_by_one.motions);
        assert_eq!(preset.bits, one_by_one.bits);
        // A range of deformed sources listed from the preset bits alone (no motions
        // recorded for it), beside ranges listed by motion: the same list.
        let deformed_only = |source: u32| motion_at(source).filter(|m| *m == Motion::Deformed);
        let mut mixed_motions: Vec<Option<Motion>> = (0..n)
            .map(|s| {
                if s < visited[1].start {
                    motion_at(s)
                } else {
                    deformed_only(s)
                }
            })
            .collect();
        let mut one_by_one_mixed = DirtySet::default();
        one_by_one_mixed.reset(n as usize);
        for source in visited.iter().cloned().flatten() {
            if let Some(m) = mixed_motions[source as usize] {
                one_by_one_mixed.mark(slot_of_source[source as usize], m);
            }
        }
        let mut by_bit = DirtySet::default();
        by_bit.reset(n as usize);
        for &slot in &one_by_one_mixed.slots {
            by_bit.words_mut()[slot as usize / 64] |= 1 << (slot % 64);
        }
        // The write records no motion for the sources it lists by bit.
        for source in visited[1].start..n {
            mixed_motions[source as usize] = None;
        }
        let mut per_range = Vec::new();
        by_bit.assign_in_source_order(
            visited.iter().enumerate().map(|(k, r)| {
                let how = if k == 0 {
                    Listed::ByMotion
                } else {
                    Listed::DeformedByBit
                };
                (r.clone(), how)
            }),
            &mut mixed_motions,
            &slot_of_source,
            true,
            &mut per_range,
        );
        assert!(one_by_one_mixed.len() > LIST_CHUNK / 4);
        assert_eq!(by_bit.slots, one_by_one_mixed.slots);
        assert_eq!(by_bit.motions, one_by_one_mixed.motions);
        assert_eq!(by_bit.bits, one_by_one_mixed.bits);
        // Every visited source's motion was taken.
        assert!(
            visited
                .iter()
                .cloned()
                .flatten()
                .all(|s| mixed_motions[s as usize].is_none())
        );
        let mut listed = DirtySet::default();
        listed.reset(n as usize);
        let mut per_range = Vec::new();
        listed.assign_in_source_order(
            visited.iter().map(|r| (r.clone(), Listed::ByMotion)),
            &mut motions,
            &slot_of_source,
            false,
            &mut per_range,
        );
        assert!(one_by_one.len() > LIST_CHUNK);
        let expected: Vec<usize> = visited
            .iter()
            .map(|r| r.clone().filter(|&s| motion_at(s).is_some()).count())
            .collect();
        assert_eq!(per_range, expected);
        assert_eq!(listed.slots, one_by_one.slots);
        assert_eq!(listed.motions, one_by_one.motions);
        assert_eq!(listed.bits, one_by_one.bits);
        let untouched = |s: u32| !visited.iter().any(|r| r.contains(&s));
        for source in 0..n {
            let expected = if untouched(source) {
                motion_at(source)
            } else {
                None
            };
            assert_eq!(
                motions[source as usize], expected,
                "source {source}: visited marks are taken, others kept"
            );
        }
    }
}
