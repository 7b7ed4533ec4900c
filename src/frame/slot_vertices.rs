//! Each slot's vertex indices in slot order, compact: what the update's write in slot order
//! reads instead of the index buffers (which slot order visits scattered).
//!
//! A slot keeps three 16-bit deltas (6 bytes, not the 12 of three indices, so that the copy
//! costs a million-triangle mesh 6 MB): its first vertex's index less the previous slot's,
//! and its other two less its first. A slot whose deltas do not fit, and the first slot of
//! every run of [`RUN`] slots (so runs decode independently, one per task), is *escaped*:
//! its indices are read from its index buffer instead. Which instance a slot's source
//! belongs to is kept as runs of slots (a mesh's triangles stay together in the tree's
//! leaves, so there are few). Invariant: decoding gives exactly the indices the index
//! buffers list, whatever the mesh (the escape covers every index the deltas cannot reach).

use rayon::prelude::*;

/// Slots per independently decoded run (the write in slot order takes one per task).
pub const RUN: usize = 4096;

/// The first delta of an escaped slot.
const ESCAPE: i16 = i16::MIN;

/// One slot's indices as decoded: its source's instance and vertex indices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotIndices {
    pub instance: u32,
    pub vertices: [u32; 3],
}

/// Every slot's vertex indices, encoded (module docs).
#[derive(Debug, Default)]
pub struct SlotVertices {
    /// Per slot.
    deltas: Vec<[i16; 3]>,
    /// `(first slot, instance)` of each run of slots whose sources share an instance, in
    /// slot order, the first at slot 0.
    instances: Vec<(u32, u32)>,
}

impl SlotVertices {
    /// Encodes slots `0..slots`, slot `s` holding the triangle of `indices(s)`; run by
    /// run on rayon's threads when `parallel` (each run is encoded on its own, so the
    /// result is the same either way).
    #[cfg(test)]
    pub fn new(
        slots: usize,
        indices: impl Fn(usize) -> SlotIndices + Sync,
        parallel: bool,
    ) -> SlotVertices {
        let mut encoded = SlotVertices::default();
        encoded.encode(slots, indices, parallel);
        encoded
    }

    /// Empties it, keeping its allocation for the next [`Self::encode`] (a scene that
    /// rebuilds its tree every frame encodes every frame: the allocation's churn slowed
    /// the builder's own allocations that follow).
    pub fn clear(&mut self) {
        self.deltas.clear();
        self.instances.clear();
    }

    /// [`Self::new`] into this one's allocation.
    pub fn encode(
        &mut self,
        slots: usize,
        indices: impl Fn(usize) -> SlotIndices + Sync,
        parallel: bool,
    ) {
        let SlotVertices { deltas, instances } = self;
        deltas.clear();
        deltas.resize(slots, [0i16; 3]);
        let encode_run = |run: usize, out: &mut [[i16; 3]]| {
            let mut instances: Vec<(u32, u32)> = Vec::new();
            let mut previous = 0i64;
            for (k, delta) in out.iter_mut().enumerate() {
                let s = run * RUN + k;
                let SlotIndices { instance, vertices } = indices(s);
                if instances.last().is_none_or(|&(_, i)| i != instance) {
                    instances.push((s as u32, instance));
                }
                let [a, b, c] = vertices.map(i64::from);
                let fits = |d: i64| (-i64::from(i16::MAX)..=i64::from(i16::MAX)).contains(&d);
                let (d0, d1, d2) = (a - previous, b - a, c - a);
                let escaped = k == 0 || !(fits(d0) && fits(d1) && fits(d2));
                *delta = if escaped {
                    [ESCAPE, 0, 0]
                } else {
                    [d0 as i16, d1 as i16, d2 as i16]
                };
                previous = a;
            }
            instances
        };
        let per_run: Vec<Vec<(u32, u32)>> = if parallel {
            deltas
                .par_chunks_mut(RUN)
                .enumerate()
                .map(|(run, out)| encode_run(run, out))
                .collect()
        } else {
            deltas
                .chunks_mut(RUN)
                .enumerate()
                .map(|(run, out)| encode_run(run, out))
                .collect()
        };
        // The runs' instance lists joined, a run that goes on in the next one merged.
        instances.clear();
        for (start, instance) in per_run.into_iter().flatten() {
            if instances.last().is_none_or(|&(_, i)| i != instance) {
                instances.push((start, instance));
            }
        }
    }

    /// How many slots it holds.
    pub fn len(&self) -> usize {
        self.deltas.len()
    }

    /// Decodes run `run` (slots `run * RUN ..`, at most [`RUN`]) into `out`, reading an
    /// escaped slot's indices with `escaped(slot, instance)`.
    pub fn decode_run(
        &self,
        run: usize,
        escaped: impl Fn(usize, u32) -> [u32; 3],
        out: &mut Vec<SlotIndices>,
    ) {
        out.clear();
        let first = run * RUN;
        let end = (first + RUN).min(self.deltas.len());
        if first >= end {
            return;
        }
        // Sized once and written by index: a push per slot (its capacity test and length
        // update) was most of the decoding's time.
        out.resize(
            end - first,
            SlotIndices {
                instance: 0,
                vertices: [0; 3],
            },
        );
        let decoded = &mut out[..];
        // The instance run holding `first`; then, segment by segment, the slots up to the
        // next run's start (no per-slot check of where the instance changes).
        let mut at = self
            .instances
            .partition_point(|&(start, _)| start as usize <= first)
            - 1;
        let mut previous = 0u32;
        let mut s = first;
        while s < end {
            let instance = self.instances[at].1;
            let stop = self.next_instance_start(at).min(end);
            let segment = &mut decoded[s - first..stop - first];
            for ((slot, &[d0, d1, d2]), slot_out) in
                (s..stop).zip(&self.deltas[s..stop]).zip(segment)
            {
                let vertices = if d0 == ESCAPE {
                    escaped(slot, instance)
                } else {
                    let a = previous.wrapping_add_signed(i32::from(d0));
                    [
                        a,
                        a.wrapping_add_signed(i32::from(d1)),
                        a.wrapping_add_signed(i32::from(d2)),
                    ]
                };
                previous = vertices[0];
                *slot_out = SlotIndices { instance, vertices };
            }
            s = stop;
            at += 1;
        }
    }

    /// The first slot after instance run `at` (past the end for the last).
    fn next_instance_start(&self, at: usize) -> usize {
        self.instances
            .get(at + 1)
            .map_or(usize::MAX, |&(start, _)| start as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes every run, with the escape reading the truth.
    fn decoded(truth: &[SlotIndices]) -> Vec<SlotIndices> {
        let encoded = SlotVertices::new(truth.len(), |s| truth[s], false);
        assert_eq!(
            encoded.instances,
            SlotVertices::new(truth.len(), |s| truth[s], true).instances
        );
        let mut all = Vec::new();
        let mut run = Vec::new();
        for r in 0..truth.len().div_ceil(RUN) {
            encoded.decode_run(
                r,
                |s, instance| {
                    assert_eq!(instance, truth[s].instance, "slot {s}'s instance");
                    truth[s].vertices
                },
                &mut run,
            );
            all.extend_from_slice(&run);
        }
        all
    }

    #[test]
    fn decoding_gives_back_every_index_whatever_its_distance() {
        // Near and far neighbours, the largest indices, deltas at the edge of i16 and just
        // past it, instances changing mid-run and across runs.
        let mut truth = Vec::new();
        let mut x = 12345u64;
        for s in 0..3 * RUN + 77 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let base = match s % 7 {
                0 => (x >> 33) as u32,          // anywhere
                1 => u32::MAX - (s as u32 % 3), // the largest indices
                _ => 1000 + s as u32,           // a neighbour of the previous slot
            };
            let step = match s % 5 {
                0 => 32767,
                1 => -32767,
                2 => 32768,
                3 => -32768,
                _ => 1,
            };
            let other = base.wrapping_add_signed(step);
            truth.push(SlotIndices {
                instance: (s / 1000 + s / 4095) as u32 % 3,
                vertices: [base, other, base.wrapping_sub(2)],
            });
        }
        assert_eq!(decoded(&truth), truth);
    }

    #[test]
    fn a_grid_in_leaf_order_rarely_escapes() {
        // The frame-loop bench's kind of mesh: quads of a 1,000-wide grid, row by row.
        let truth: Vec<SlotIndices> = (0..2 * RUN as u32)
            .map(|t| {
                let (x, y) = ((t / 2) % 1000, (t / 2) / 1000);
                let v = y * 1001 + x;
                SlotIndices {
                    instance: 0,
                    vertices: [v, v + 1, v + 1002],
                }
            })
            .collect();
        let encoded = SlotVertices::new(truth.len(), |s| truth[s], true);
        let escapes = encoded.deltas.iter().filter(|d| d[0] == ESCAPE).count();
        assert_eq!(escapes, 2, "only each run's first slot");
        assert_eq!(decoded(&truth), truth);
    }

    #[test]
    fn no_slots_decode_to_nothing() {
        let encoded = SlotVertices::new(0, |_| unreachable!(), true);
        assert_eq!(encoded.len(), 0);
        assert!(decoded(&[]).is_empty());
    }
}
