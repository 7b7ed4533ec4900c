//! What a query answers and what it carries while it walks, shared by every tree (the flat
//! tree, the instances' object-space trees and the top-level trees above them).
//!
//! The tie rule lives here ([`Closest`]): among hits at exactly the same distance the
//! lowest source triangle wins, so the answer does not depend on which tree or walk found
//! it. A packet's buffers ([`PacketQuery`], 20 KiB) are kept per thread and filled in place.

use std::cell::RefCell;

use glam::{Vec2, Vec3A};

use super::triangles::{ShearedRay, ShearedRows};
use super::wide::{PACKET, RayBoxes, RayPacket};

/// The closest intersection along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Triangle slot (BVH order) in the triangles of `instance`'s tree.
    pub triangle: u32,
    /// [`Hit::WORLD`] for a triangle of the world-space tree (every hit of a flat BVH);
    /// otherwise the instance of a `TwoLevelAccel` whose object-space tree holds it.
    pub instance: u32,
    pub t: f32,
    /// Barycentric weights of vertices 1 and 2.
    pub bary: Vec2,
}

impl Hit {
    /// The `instance` of a hit on world-space triangles.
    pub const WORLD: u32 = u32::MAX;

    /// Which triangle was hit.
    #[inline]
    pub fn triangle_ref(&self) -> TriangleRef {
        TriangleRef {
            instance: self.instance,
            slot: self.triangle,
        }
    }
}

/// A triangle of a frame: a slot of the world-space tree ([`Hit::WORLD`]) or of the mesh an
/// instance places.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TriangleRef {
    pub instance: u32,
    pub slot: u32,
}

/// The best hit of a closest-hit query so far, with its source triangle (the tie rule).
#[derive(Clone, Copy)]
pub(super) struct Closest {
    pub(super) hit: Option<Hit>,
    pub(super) source: u32,
}

impl Default for Closest {
    fn default() -> Self {
        Closest {
            hit: None,
            source: u32::MAX,
        }
    }
}

/// Which tree a closest-hit query is walking: the base of its source triangles (the tie
/// rule; the packs hold each slot's source relative to it) and the instance its hits report.
pub(super) struct Within<'a> {
    pub(super) source_base: u32,
    pub(super) instance: u32,
    /// Per slot, the slot its hits report (`None`: the slot itself); a collapsed instance's
    /// world-space copy reports its mesh's slots.
    pub(super) reported: Option<&'a [u32]>,
}

impl<'a> Within<'a> {
    /// The world-space tree (its sources are the scene's).
    pub(super) fn world() -> Within<'a> {
        Within {
            source_base: 0,
            instance: Hit::WORLD,
            reported: None,
        }
    }
}

/// What a packet query keeps per ray: the packet's slab constants, the hit-test constants,
/// the best hit so far and the limit. Reused across packets on a thread and filled in place
/// (built and returned by value, these 20 KiB showed as 6% `memmove` in a primary-ray
/// profile).
pub(super) struct PacketQuery {
    pub(super) packet: RayPacket,
    pub(super) sheared: [ShearedRay; PACKET],
    /// The frames of `sheared` as rows, for the leaf tests of a packet's fixed groups (filled
    /// for packets that walk with bounds; masked walks test no fixed group).
    pub(super) rows: ShearedRows,
    pub(super) best: [Closest; PACKET],
    pub(super) limits: [f32; PACKET],
    /// Each ray's own slab constants (masked walks).
    pub(super) boxes: [RayBoxes; PACKET],
    /// Where the two-level structure takes the rays that enter an instance together.
    pub(super) object: ObjectPacket,
}

/// The rays of a packet that enter one instance, in its object space: ray `s` here is ray
/// `rays[s]` of the world packet.
pub(super) struct ObjectPacket {
    pub(super) packet: RayPacket,
    pub(super) sheared: [ShearedRay; PACKET],
    pub(super) limits: [f32; PACKET],
    /// `(origin, direction)` in object space, what `packet` is set from.
    pub(super) object_rays: [(Vec3A, Vec3A); PACKET],
}

thread_local! {
    static PACKET_QUERY: RefCell<Option<Box<PacketQuery>>> = const { RefCell::new(None) };
}

impl PacketQuery {
    pub(super) fn boxed() -> Box<PacketQuery> {
        Box::new(PacketQuery {
            packet: RayPacket::new(&[]),
            sheared: [ShearedRay::default(); PACKET],
            rows: ShearedRows::default(),
            best: [Closest::default(); PACKET],
            limits: [0.0; PACKET],
            boxes: [RayBoxes::default(); PACKET],
            object: ObjectPacket {
                packet: RayPacket::new(&[]),
                sheared: [ShearedRay::default(); PACKET],
                limits: [0.0; PACKET],
                object_rays: [(Vec3A::ZERO, Vec3A::ZERO); PACKET],
            },
        })
    }

    /// Fills the query for `rays` (at most [`PACKET`]) with limit `t_max`.
    pub(super) fn fill(&mut self, rays: &[(Vec3A, Vec3A)], t_max: f32) {
        let n = rays.len().min(PACKET);
        self.packet.set(&rays[..n]);
        ShearedRay::fill_with_rows(&mut self.sheared[..n], &mut self.rows, &rays[..n]);
        self.best[..n].fill(Closest::default());
        self.limits.fill(t_max);
    }

    /// Fills the query for the occlusion rays `rays` (at most [`PACKET`]), ray `r` searched
    /// up to `t_max[r]`: the packet with interval bounds when the rays converge on one
    /// point, each ray's own slab constants (for the masked walk) when they do not. Returns
    /// whether the packet has bounds.
    // Always inlined: the tile kernel (`render::tile::TraceTile`) calls it, and so gets it
    // compiled into each of its SIMD copies.
    #[inline(always)]
    pub(super) fn fill_occlusion(&mut self, rays: &[(Vec3A, Vec3A)], t_max: &[f32]) -> bool {
        let n = rays.len().min(PACKET).min(t_max.len());
        let converging = self.packet.set_converging(&rays[..n], &t_max[..n]);
        self.fill_ray_constants(&rays[..n], !converging);
        self.limits[..n].copy_from_slice(&t_max[..n]);
        converging
    }

    /// Fills the query for closest hits of `rays` (at most [`PACKET`]) from any origins,
    /// with limit `t_max`: the packet with interval bounds when the rays' lines pass through
    /// one point behind them and the rays lie close enough together to share leaves
    /// (`extent`: the largest coordinate of the trees' boxes; `leaf_side`: their typical
    /// leaf's side, see `RayPacket::set_with_apex`), each ray's own slab constants (for the
    /// masked walk) when they do not. Returns whether the packet has bounds.
    // Always inlined: the tile kernel (`render::tile::TraceTile`) calls it, and so gets it
    // compiled into each of its SIMD copies.
    #[inline(always)]
    pub(super) fn fill_masked(
        &mut self,
        rays: &[(Vec3A, Vec3A)],
        t_max: f32,
        extent: f32,
        leaf_side: f32,
    ) -> bool {
        let n = rays.len().min(PACKET);
        let bounded = self.packet.set_with_apex(&rays[..n], extent, leaf_side);
        self.fill_ray_constants(&rays[..n], !bounded);
        self.best[..n].fill(Closest::default());
        self.limits.fill(t_max);
        bounded
    }

    /// Each ray's hit-test constants (as rows too for a packet walk, whose leaves test fixed
    /// groups of rays), and its own slab constants when it walks `masked`.
    #[inline(always)]
    fn fill_ray_constants(&mut self, rays: &[(Vec3A, Vec3A)], masked: bool) {
        if masked {
            ShearedRay::fill(&mut self.sheared, rays);
            for (boxes, &(origin, direction)) in self.boxes.iter_mut().zip(rays) {
                *boxes = RayBoxes::new(origin, direction);
            }
        } else {
            ShearedRay::fill_with_rows(&mut self.sheared, &mut self.rows, rays);
        }
    }

    /// Runs `query` on this thread's query filled for `rays` with limit `t_max` (a fresh
    /// one if the thread's is in use, which no caller does today: queries do not nest).
    pub(super) fn with<R>(
        rays: &[(Vec3A, Vec3A)],
        t_max: f32,
        query: impl FnOnce(&mut PacketQuery) -> R,
    ) -> R {
        Self::with_filled(|q| q.fill(rays, t_max), query)
    }

    /// Runs `query` on this thread's query after `fill` (a fresh one if the thread's is in
    /// use).
    pub(super) fn with_filled<R>(
        fill: impl FnOnce(&mut PacketQuery),
        query: impl FnOnce(&mut PacketQuery) -> R,
    ) -> R {
        PACKET_QUERY.with(|cell| match cell.try_borrow_mut() {
            Ok(mut slot) => {
                let q = slot.get_or_insert_with(PacketQuery::boxed);
                fill(q);
                query(q)
            }
            Err(_) => {
                let mut q = PacketQuery::boxed();
                fill(&mut q);
                query(&mut q)
            }
        })
    }
}
