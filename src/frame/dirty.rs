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

/// How [`DirtySet::assign_in_source_order`] takes a range's moved sources.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Listed {
    /// Listed by their motion in `source_motion` (taken from it).
    ByMotion,
    /// Left unlisted: a deforming instance whose write in slot order set the bits of
    /// exactly the slots it moved (every one [`Motion::Deformed`]) and recorded no motions.
    /// Its slots are in the set by their bits alone (see [`DirtySet`]).
    DeformedByBit,
}

/// What moved this frame: the output of the dirty step, read by the tree step (what to
/// refit, and the marks a rebuild carries into the new slot order) and by the `log2 P_b`
/// step (which constants to recompute or shift).
#[derive(Debug, Default)]
pub(super) struct FrameChanges {
    pub dirty: DirtySet,
    /// How many moved slots belong to deforming instances: the `log2 P_b` step walks
    /// those slots by their bits, in slot order.
    pub deformed: usize,
    /// The runs of placed instances that scaled or changed shape: the entries the `log2
    /// P_b` step visits one by one (rigid runs keep their constants and are skipped whole).
    pub reshaped_entries: Vec<Range<usize>>,
    /// Whether this frame's write gave a moved triangle a non-finite vertex.
    pub moved_nonfinite: bool,
    /// What this frame's placed instances changed (two-level only; counted into the record).
    pub placed: PlacedChanges,
}

/// The moved triangles of one frame: a bitset for membership, and a compact list of the
/// listed ones in the order they were marked, with their motion.
///
/// Invariant: every listed slot's bit is set, and the set bits no listed entry has are
/// the `unlisted` slots, all [`Motion::Deformed`]. Those are the slots of deforming
/// instances that the write in slot order marked by their bits alone: a frame that
/// deforms a million triangles does not build a list of them (which took about a
/// millisecond of its update) when the refit, the `log2 P_b` step and the record need
/// only the bits and the count. [`DirtySet::moved`] lists everything on demand.
#[derive(Debug, Default, Clone)]
pub struct DirtySet {
    bits: Vec<u64>,
    /// Listed moved slots, each once.
    slots: Vec<u32>,
    /// Motion of each entry of `slots`.
    motions: Vec<Motion>,
    /// Moved slots set in `bits` and not listed (all deformed).
    unlisted: usize,
}

impl DirtySet {
    /// Empties the set for a frame with `slots` triangles (keeps allocations).
    pub fn reset(&mut self, slots: usize) {
        self.bits.clear();
        self.bits.resize(slots.div_ceil(64), 0);
        self.slots.clear();
        self.motions.clear();
        self.unlisted = 0;
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
    /// motion, and clears those entries: the parallel counterpart of [`Self::mark`] called
    /// in that order. A range `Listed::DeformedByBit` is not listed: its moved slots are
    /// the set bits no listed entry has (only with `bits_set`), counted as unlisted.
    /// The listed ranges are cut into chunks that are counted, then filled at their offsets,
    /// on rayon's threads; every read is sequential. Precondition: the set was just
    /// [`reset`](Self::reset) for every slot `slot_of_source` names; then either no bit is
    /// set (`bits_set` false: the listed slots' bits are set here, in a serial pass), or the
    /// bits of exactly the moved slots of every range are (`bits_set` true: the write in
    /// slot order sets them as it goes, each task in its own words). Fills `listed` with how
    /// many entries each range gave to the list, in order (0 for a range left unlisted).
    pub fn assign_in_source_order(
        &mut self,
        visited: impl Iterator<Item = (Range<u32>, Listed)>,
        source_motion: &mut [Option<Motion>],
        slot_of_source: &[u32],
        bits_set: bool,
        listed: &mut Vec<usize>,
    ) {
        debug_assert!(self.slots.is_empty() && self.unlisted == 0);
        // Each chunk of a listed range, with the index of the range it comes from.
        let visited: Vec<(Range<u32>, Listed)> = visited.collect();
        debug_assert!(bits_set || visited.iter().all(|(_, l)| *l == Listed::ByMotion));
        let chunks: Vec<(usize, Range<usize>)> = visited
            .iter()
            .cloned()
            .enumerate()
            .filter(|(_, (_, how))| *how == Listed::ByMotion)
            .flat_map(|(index, (r, _))| {
                let (start, end) = (r.start as usize, r.end as usize);
                (start..end)
                    .step_by(LIST_CHUNK)
                    .map(move |a| (index, a..(a + LIST_CHUNK).min(end)))
            })
            .collect();
        let counts: Vec<usize> = chunks
            .par_iter()
            .map(|(_, c)| source_motion[c.clone()].iter().flatten().count())
            .collect();
        listed.clear();
        listed.resize(visited.len(), 0);
        for ((index, _), &count) in chunks.iter().zip(&counts) {
            listed[*index] += count;
        }
        let total = counts.iter().sum();
        self.slots.resize(total, 0);
        self.motions.resize(total, Motion::Rigid);
        // Each chunk's input (its `source_motion` entries) and output (its share of the list).
        let mut jobs = Vec::with_capacity(chunks.len());
        let (mut input, mut consumed) = (source_motion, 0);
        let (mut slots, mut motions) = (&mut self.slots[..], &mut self.motions[..]);
        for ((_, chunk), &count) in chunks.iter().zip(&counts) {
            let (_, rest) = std::mem::take(&mut input).split_at_mut(chunk.start - consumed);
            let (here, rest) = rest.split_at_mut(chunk.len());
            (input, consumed) = (rest, chunk.end);
            let (chunk_slots, rest) = std::mem::take(&mut slots).split_at_mut(count);
            slots = rest;
            let (chunk_motions, rest) = std::mem::take(&mut motions).split_at_mut(count);
            motions = rest;
            jobs.push((chunk.start, here, chunk_slots, chunk_motions));
        }
        jobs.into_par_iter()
            .for_each(|(first, input, slots, motions)| {
                let listed = input
                    .iter_mut()
                    .enumerate()
                    .filter_map(|(k, m)| Some((first + k, m.take()?)));
                for ((source, motion), (slot, out)) in listed.zip(slots.iter_mut().zip(motions)) {
                    *slot = slot_of_source[source];
                    *out = motion;
                }
            });
        if bits_set {
            debug_assert!(self.slots.iter().all(|&s| self.contains(s)));
            let set: usize = self.bits.iter().map(|w| w.count_ones() as usize).sum();
            self.unlisted = set - self.slots.len();
            debug_assert!(
                self.unlisted == 0 || visited.iter().any(|(_, l)| *l == Listed::DeformedByBit)
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

    /// How many slots moved (listed or not).
    pub fn len(&self) -> usize {
        self.slots.len() + self.unlisted
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// How many moved slots have motion `m`.
    pub fn count(&self, m: Motion) -> usize {
        let listed = self.motions.iter().filter(|&&x| x == m).count();
        if m == Motion::Deformed {
            listed + self.unlisted
        } else {
            listed
        }
    }

    /// How many moved slots are in the set by their bits alone (all deformed).
    pub(super) fn unlisted(&self) -> usize {
        self.unlisted
    }

    /// The listed entries, in the order they were marked: what the `log2 P_b` step's
    /// entry runs index.
    pub(super) fn listed(&self) -> (&[u32], &[Motion]) {
        (&self.slots, &self.motions)
    }

    /// Every moved slot, increasing.
    pub fn slots_in_order(&self) -> impl Iterator<Item = u32> + '_ {
        set_bits(&self.bits)
    }

    /// Every moved slot: the listed ones as they are when nothing is unlisted (no copy),
    /// else all of them, increasing.
    pub fn all_slots(&self) -> std::borrow::Cow<'_, [u32]> {
        if self.unlisted == 0 {
            std::borrow::Cow::Borrowed(&self.slots)
        } else {
            std::borrow::Cow::Owned(self.slots_in_order().collect())
        }
    }

    /// The unlisted moved slots (all deformed), increasing.
    pub(super) fn unlisted_slots(&self) -> Vec<u32> {
        if self.unlisted == 0 {
            return Vec::new();
        }
        let mut bits = self.bits.clone();
        for &slot in &self.slots {
            bits[slot as usize / 64] &= !(1 << (slot % 64));
        }
        set_bits(&bits).collect()
    }

    /// Every moved slot with its motion, increasing by slot: what moved, whichever way the
    /// frame's update listed it (sequential and parallel updates give the same).
    pub fn moved(&self) -> Vec<(u32, Motion)> {
        let mut listed: Vec<(u32, Motion)> = self
            .slots
            .iter()
            .copied()
            .zip(self.motions.iter().copied())
            .collect();
        listed.sort_unstable_by_key(|&(slot, _)| slot);
        let mut next = listed.iter().peekable();
        self.slots_in_order()
            .map(|slot| match next.peek() {
                Some(&&(s, motion)) if s == slot => {
                    next.next();
                    (slot, motion)
                }
                _ => (slot, Motion::Deformed),
            })
            .collect()
    }
}

/// The indices of the set bits of `words` (bit `i % 64` of word `i / 64`), increasing.
fn set_bits(words: &[u64]) -> impl Iterator<Item = u32> + '_ {
    words.iter().enumerate().flat_map(|(w, &word)| {
        let mut bits = word;
        std::iter::from_fn(move || {
            (bits != 0).then(|| {
                let b = bits.trailing_zeros();
                bits &= bits - 1;
                (w * 64) as u32 + b
            })
        })
    })
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
        // Only the range listed by motion is in the list (it comes first, so its entries
        // are the marked list's first); the rest are in the set by their bits.
        let first_range = per_range[0];
        assert!(first_range > 0 && per_range[1..].iter().all(|&c| c == 0));
        assert_eq!(by_bit.slots, one_by_one_mixed.slots[..first_range]);
        assert_eq!(by_bit.motions, one_by_one_mixed.motions[..first_range]);
        assert_eq!(by_bit.bits, one_by_one_mixed.bits);
        assert_eq!(by_bit.len(), one_by_one_mixed.len());
        for m in [Motion::Rigid, Motion::Scaled, Motion::Deformed] {
            assert_eq!(by_bit.count(m), one_by_one_mixed.count(m), "{m:?}");
        }
        assert_eq!(by_bit.moved(), one_by_one_mixed.moved());
        let mut all = one_by_one_mixed.slots.clone();
        all.sort_unstable();
        assert_eq!(by_bit.all_slots().into_owned(), all);
        assert_eq!(by_bit.slots_in_order().collect::<Vec<_>>(), all);
        let mut unlisted = one_by_one_mixed.slots[first_range..].to_vec();
        unlisted.sort_unstable();
        assert_eq!(by_bit.unlisted_slots(), unlisted);
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
