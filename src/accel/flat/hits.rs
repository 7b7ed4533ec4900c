//! Queries on the flat tree: the closest hit of one ray or of a packet, and every hit along
//! a ray (shadow rays). The leaf tests are compiled into the walks (`LeafVisit` with an
//! always-inlined method), so each SIMD copy of a walk carries its own.

use glam::Vec3A;

use super::Accel;
use crate::accel::query::{Closest, Hit, PacketQuery, Within};
use crate::accel::triangles::ShearedRay;
use crate::accel::wide::{LeafVisit, PACKET, RayBoxes};

impl Accel {
    /// The closest hit with `t` in `[0, t_max)`. Among hits at exactly the same distance
    /// (a shared edge, coplanar triangles) the lowest source triangle wins, so the result
    /// does not depend on the tree's shape: a refitted tree and a fresh build agree.
    #[inline]
    pub fn closest_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        let mut best = Closest::default();
        let ray = RayBoxes::new(origin, direction);
        let sheared = ShearedRay::new(origin, direction);
        self.closest_within(&Within::world(), &ray, &sheared, t_max, &mut best);
        best.hit
    }

    /// Continues a closest-hit query `best` (shared across the trees of a two-level
    /// structure) in this tree, whose triangles' source ids are `within`'s; returns the
    /// limit the query ends with.
    #[inline]
    pub(in crate::accel) fn closest_within(
        &self,
        within: &Within,
        ray: &RayBoxes,
        sheared: &ShearedRay,
        t_max: f32,
        best: &mut Closest,
    ) -> f32 {
        let mut end = t_max;
        self.wide.traverse(
            ray,
            t_max,
            ClosestLeaf {
                accel: self,
                within,
                sheared,
                best,
                end: &mut end,
            },
        );
        end
    }

    /// [`Accel::closest_hit`] for a packet of up to [`PACKET`] rays `(origin, direction)`
    /// walked together (coherent rays such as a tile's primary rays); `hits[i]` receives
    /// exactly what `closest_hit` returns for ray `i`.
    pub fn closest_hits(&self, rays: &[(Vec3A, Vec3A)], t_max: f32, hits: &mut [Option<Hit>]) {
        let n = rays.len().min(hits.len()).min(PACKET);
        PacketQuery::with(&rays[..n], t_max, |q| {
            self.closest_hits_within(&Within::world(), q);
            for (hit, best) in hits.iter_mut().zip(&q.best[..n]) {
                *hit = best.hit;
            }
        });
    }

    /// Continues the closest-hit queries `best` of a packet (limits `limits`) in this tree.
    pub(in crate::accel) fn closest_hits_within(&self, within: &Within, query: &mut PacketQuery) {
        let PacketQuery {
            packet,
            sheared,
            best,
            limits,
            ..
        } = query;
        self.wide
            .traverse_packet(packet, limits, |r, first, count, limit| {
                self.closest_in_leaf(within, &sheared[r], first, count, limit, &mut best[r]);
            });
    }

    /// Tests a leaf for a closest-hit query: keeps the nearest hit (ties to the lowest source
    /// triangle) and lowers `limit` to it.
    #[inline(always)]
    pub(in crate::accel) fn closest_in_leaf(
        &self,
        within: &Within,
        ray: &ShearedRay,
        first: u32,
        count: u32,
        limit: &mut f32,
        best: &mut Closest,
    ) {
        let cut = *limit;
        self.triangles
            .hits_in_leaf(ray, first, count, cut, |slot, source, t, bary| {
                let source = within.source_base + source;
                let better = match best.hit {
                    None => true,
                    Some(h) => t < h.t || (t == h.t && source < best.source),
                };
                if better {
                    best.hit = Some(Hit {
                        triangle: within.reported.map_or(slot, |r| r[slot as usize]),
                        instance: within.instance,
                        t,
                        bary,
                    });
                    best.source = source;
                    // Keep visiting boxes that start at `t` (up to rounding), where a tie
                    // may hide.
                    *limit = ray.tie_limit(t);
                }
                true
            });
    }

    /// Visits every triangle hit with `t` in `[0, t_max)`, as `visit(slot, t)`, in an order
    /// that depends on the tree, until `visit` returns false. Returns false when it was
    /// stopped early.
    #[inline]
    pub fn visit_hits(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        visit: impl FnMut(u32, f32) -> bool,
    ) -> bool {
        let ray = RayBoxes::new(origin, direction);
        let sheared = ShearedRay::new(origin, direction);
        self.visit_hits_of(&ray, &sheared, t_max, visit)
    }

    /// [`Accel::visit_hits`] for a ray whose constants are already made (the two-level
    /// structure reuses them for its top-level walk).
    #[inline]
    pub(in crate::accel) fn visit_hits_of(
        &self,
        ray: &RayBoxes,
        sheared: &ShearedRay,
        t_max: f32,
        mut visit: impl FnMut(u32, f32) -> bool,
    ) -> bool {
        self.wide
            .traverse_unordered(ray, t_max, |first: u32, count: u32, _: &mut f32| {
                self.triangles
                    .hits_in_leaf(sheared, first, count, t_max, |slot, _, t, _| visit(slot, t))
            })
    }
}

/// The closest-hit leaf test as a [`LeafVisit`] whose method is always inlined, so it is
/// compiled into the walk (its AVX2 copy included) rather than called per leaf.
struct ClosestLeaf<'a> {
    accel: &'a Accel,
    within: &'a Within<'a>,
    sheared: &'a ShearedRay,
    best: &'a mut Closest,
    end: &'a mut f32,
}

impl LeafVisit for ClosestLeaf<'_> {
    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, limit: &mut f32) -> bool {
        self.accel
            .closest_in_leaf(self.within, self.sheared, first, count, limit, self.best);
        *self.end = *limit;
        true
    }
}
