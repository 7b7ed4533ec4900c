//! Concurrent writes to distinct triangle slots.
//!
//! The update visits moved triangles in source order (instance by instance: reads of
//! vertices, indices and uvs stay sequential) but writes them to their BVH slots, which the
//! tree scatters. Slices cannot be split by such a permutation, so the parallel write goes
//! through raw pointers (the positions through the tree's `SlotLanes`: the packs hold the
//! only copy). Invariant that makes it sound: `Renderer::slot_of_source` maps the sources
//! that have a slot one-to-one onto the slots (`index_slots` inverts
//! `FrameTriangles::source`, itself a permutation of those sources after every build; under
//! the two-level BVH only the world tree's triangles have slots, and only they are
//! written), and each source triangle is visited by exactly one task, so no two tasks ever
//! touch the same slot (nor the same source's motion entry).
//!
//! The write in slot order (a frame that writes at least half the slots) is the other way
//! round: each task writes its own run of slots, and records motions by source through
//! [`SourceMotions`] on the same invariant.

use glam::{Vec2, Vec3, Vec3A};

use super::Motion;
use crate::accel::SlotLanes;
use crate::geometry::FrameTriangles;
use crate::simd::prefetch_ptr;

/// Mutable access to one slot of each per-slot array and of the tree's packs (which hold
/// the positions), handed to concurrent tasks.
pub struct SlotScatter<'a> {
    positions: SlotLanes<'a>,
    /// Null when no slot stores normals (every instance deforms: the write leaves them).
    normals: *mut [Vec3; 3],
    uvs: *mut [Vec2; 3],
    /// By source triangle.
    motions: *mut Option<Motion>,
    slots: usize,
    sources: usize,
    _arrays: std::marker::PhantomData<&'a mut FrameTriangles>,
}

// SAFETY: the pointers come from exclusive borrows held for 'a (`SlotLanes` is `Sync` on
// the same contract); `with_slot`'s contract keeps every slot to one task at a time.
unsafe impl Sync for SlotScatter<'_> {}

impl<'a> SlotScatter<'a> {
    /// Borrows the triangles' normals and uvs and the tree's packs (by slot) and a motion
    /// array (by source triangle).
    ///
    /// # Panics
    /// If the triangles' arrays and the packs differ in length (`normals` may be empty).
    pub fn new(
        triangles: &'a mut FrameTriangles,
        positions: SlotLanes<'a>,
        motions: &'a mut [Option<Motion>],
    ) -> Self {
        let len = triangles.len();
        assert!(
            (triangles.normals.len() == len || triangles.normals.is_empty())
                && triangles.uvs.len() == len
                && positions.slots() == len
        );
        SlotScatter {
            positions,
            normals: if triangles.normals.is_empty() {
                std::ptr::null_mut()
            } else {
                triangles.normals.as_mut_ptr()
            },
            uvs: triangles.uvs.as_mut_ptr(),
            sources: motions.len(),
            motions: motions.as_mut_ptr(),
            slots: len,
            _arrays: std::marker::PhantomData,
        }
    }

    /// Runs `write` on slot `slot`'s position, normal and uvs, stores the position back
    /// into its lane when `write` reports a motion, and stores the motion as source
    /// triangle `source`'s.
    ///
    /// # Safety
    /// No other call for the same `slot` or the same `source` may run at the same time
    /// (module docs).
    ///
    /// # Panics
    /// If `slot` or `source` is out of range.
    #[inline]
    pub unsafe fn with_slot(
        &self,
        slot: u32,
        source: u32,
        write: impl FnOnce(&mut [Vec3A; 3], Option<&mut [Vec3; 3]>, &mut [Vec2; 3]) -> Option<Motion>,
    ) {
        let (s, t) = (slot as usize, source as usize);
        assert!(
            s < self.slots && t < self.sources,
            "slot {s} of {}, source {t} of {}",
            self.slots,
            self.sources
        );
        // SAFETY: in bounds (checked), and exclusive for this call by the caller's contract.
        unsafe {
            let mut position = self.positions.get(slot);
            let normal = (!self.normals.is_null()).then(|| &mut *self.normals.add(s));
            let motion = write(&mut position, normal, &mut *self.uvs.add(s));
            if motion.is_some() {
                self.positions.set(slot, &position);
            }
            *self.motions.add(t) = motion;
        }
    }

    /// Hints the cache to load slot `slot` of each per-slot array (no effect when out of
    /// range): the write visits sources in order, so the slot a few sources ahead is known
    /// long before its (scattered) write.
    #[inline]
    pub fn prefetch(&self, slot: u32) {
        let s = slot as usize;
        if s < self.slots {
            self.positions.prefetch(slot);
            // SAFETY: in bounds; a prefetch reads nothing and writes nothing.
            unsafe {
                if !self.normals.is_null() {
                    prefetch_ptr(self.normals.add(s));
                }
                prefetch_ptr(self.uvs.add(s));
            }
        }
    }
}

/// Each source triangle's motion, written from concurrent tasks that visit slots (the write
/// in slot order records motions by source, for the listing in source order).
pub struct SourceMotions<'a> {
    motions: *mut Option<Motion>,
    len: usize,
    _array: std::marker::PhantomData<&'a mut [Option<Motion>]>,
}

// SAFETY: the pointer comes from an exclusive borrow held for 'a; `set`'s contract keeps
// every source to one task.
unsafe impl Sync for SourceMotions<'_> {}

impl<'a> SourceMotions<'a> {
    pub fn new(motions: &'a mut [Option<Motion>]) -> Self {
        SourceMotions {
            motions: motions.as_mut_ptr(),
            len: motions.len(),
            _array: std::marker::PhantomData,
        }
    }

    /// Stores source triangle `source`'s motion.
    ///
    /// # Safety
    /// No other call for the same `source` may run at the same time (each slot is visited
    /// by one task, and slots map one-to-one onto their sources: module docs).
    ///
    /// # Panics
    /// If `source` is out of range.
    #[inline]
    pub unsafe fn set(&self, source: u32, motion: Option<Motion>) {
        let t = source as usize;
        assert!(t < self.len, "source {t} of {}", self.len);
        // SAFETY: in bounds (checked), and exclusive for this call by the caller's contract.
        unsafe { *self.motions.add(t) = motion };
    }
}
