//! Acceleration structure: obvhs builds a binary tree over the frame's triangles, which is
//! collapsed into the 8-wide tree that rays traverse and that is refitted ([`wide`]).
//!
//! Built without spatial splits so it can be refitted later. After a build the triangle
//! arrays are permuted into BVH order (`FrameTriangles::permute`), so a leaf's primitive
//! range indexes the triangle arrays directly: no indirection on the hot path. The hit test
//! reads the triangles from their own copy laid out four to a pack in slot order
//! ([`triangles`], watertight), refreshed with the boxes.
//! Leaf boxes are padded (see [`padded_box`]) because a flat triangle's box has zero
//! thickness and an axis-aligned ray can slip through it by rounding.

use std::cell::RefCell;
use std::time::Duration;

use glam::{Vec2, Vec3A};
use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::builder::build_bvh2};
use rayon::prelude::*;

use crate::geometry::FrameTriangles;

mod instanced;
mod policy;
mod triangles;
mod wide;

pub use instanced::{TlasInstance, TwoLevelAccel};
pub use policy::{BvhLayout, BvhPolicy, TreeStep};
pub use triangles::intersect;
use triangles::{PackedTriangles, ShearedRay};
pub use wide::PACKET;
pub(crate) use wide::avx2_walks;
use wide::{LeafVisit, RayBoxes, RayPacket, WideBvh};

/// Past this many triangles the edge and leaf-box refresh of a full refit runs on rayon's
/// threads (below it the fork costs more than the work).
const PARALLEL_REFIT_MIN: usize = 16_384;

/// The closest intersection along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Triangle slot (BVH order) in the triangles of `instance`'s tree.
    pub triangle: u32,
    /// [`Hit::WORLD`] for a triangle of the world-space tree (every hit of a flat BVH);
    /// otherwise the instance of a [`TwoLevelAccel`] whose object-space tree holds it.
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

/// A BVH over one frame's triangles.
#[derive(Default)]
pub struct Accel {
    /// The tree rays walk and refits update.
    wide: WideBvh,
    /// The triangles as the hit test reads them.
    triangles: PackedTriangles,
    /// Per leaf, in slot order: its first slot, triangle count and lane in the wide tree.
    /// Refits walk leaves (and packs) in this order, so they stream through the triangles.
    leaves: Vec<Leaf>,
    /// Per slot, its leaf's index in `leaves`.
    leaf_of_slot: Vec<u32>,
    /// SAH cost right after the last build (see [`Accel::sah_cost`]).
    build_cost: f32,
    /// `sah_cost()` of the tree as it is, kept from the last build or refit: the cost is a
    /// walk over every node, which a frame that moved nothing (a static scene) must not pay,
    /// and which the refit's time should include.
    cost: f32,
}

/// A leaf of the tree: its triangle slots and where the wide tree keeps its box.
#[derive(Clone, Copy)]
struct Leaf {
    first: u32,
    count: u32,
    lane: u32,
}

/// The best hit of a closest-hit query so far, with its source triangle (the tie rule).
#[derive(Clone, Copy)]
struct Closest {
    hit: Option<Hit>,
    source: u32,
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
struct Within<'a> {
    source_base: u32,
    instance: u32,
    /// Per slot, the slot its hits report (`None`: the slot itself); a collapsed instance's
    /// world-space copy reports its mesh's slots.
    reported: Option<&'a [u32]>,
}

impl<'a> Within<'a> {
    /// The world-space tree (its sources are the scene's).
    fn world() -> Within<'a> {
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
struct PacketQuery {
    packet: RayPacket,
    sheared: [ShearedRay; PACKET],
    best: [Closest; PACKET],
    limits: [f32; PACKET],
    /// Where the two-level structure takes the rays that enter an instance together.
    object: ObjectPacket,
}

/// The rays of a packet that enter one instance, in its object space: ray `s` here is ray
/// `rays[s]` of the world packet.
struct ObjectPacket {
    packet: RayPacket,
    sheared: [ShearedRay; PACKET],
    limits: [f32; PACKET],
    /// `(origin, direction)` in object space, what `packet` is set from.
    object_rays: [(Vec3A, Vec3A); PACKET],
}

thread_local! {
    static PACKET_QUERY: RefCell<Option<Box<PacketQuery>>> = const { RefCell::new(None) };
}

impl PacketQuery {
    fn boxed() -> Box<PacketQuery> {
        Box::new(PacketQuery {
            packet: RayPacket::new(&[]),
            sheared: [ShearedRay::default(); PACKET],
            best: [Closest::default(); PACKET],
            limits: [0.0; PACKET],
            object: ObjectPacket {
                packet: RayPacket::new(&[]),
                sheared: [ShearedRay::default(); PACKET],
                limits: [0.0; PACKET],
                object_rays: [(Vec3A::ZERO, Vec3A::ZERO); PACKET],
            },
        })
    }

    /// Fills the query for `rays` (at most [`PACKET`]) with limit `t_max`.
    fn fill(&mut self, rays: &[(Vec3A, Vec3A)], t_max: f32) {
        let n = rays.len().min(PACKET);
        self.packet.set(&rays[..n]);
        for (sheared, &(origin, direction)) in self.sheared.iter_mut().zip(&rays[..n]) {
            *sheared = ShearedRay::new(origin, direction);
        }
        self.best[..n].fill(Closest::default());
        self.limits.fill(t_max);
    }

    /// Runs `query` on this thread's query filled for `rays` (a fresh one if the thread's
    /// is in use, which no caller does today: queries do not nest).
    fn with<R>(
        rays: &[(Vec3A, Vec3A)],
        t_max: f32,
        query: impl FnOnce(&mut PacketQuery) -> R,
    ) -> R {
        PACKET_QUERY.with(|cell| match cell.try_borrow_mut() {
            Ok(mut slot) => {
                let q = slot.get_or_insert_with(PacketQuery::boxed);
                q.fill(rays, t_max);
                query(q)
            }
            Err(_) => {
                let mut q = PacketQuery::boxed();
                q.fill(rays, t_max);
                query(&mut q)
            }
        })
    }
}

/// Which refit ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefitKind {
    /// Nothing moved.
    None,
    /// Only the leaves of moved triangles and their ancestors.
    Partial,
    /// Every leaf and inner node.
    Full,
}

/// Relative costs of the surface-area heuristic: one node visit vs one triangle test.
const SAH_TRAVERSAL_COST: f32 = 1.0;
const SAH_INTERSECTION_COST: f32 = 1.0;

/// A partial refit walks up from each moved leaf; past this share of leaves a full sweep
/// is cheaper.
const PARTIAL_REFIT_MAX_SHARE: f64 = 0.1;

/// Errors that stop a BVH build.
#[derive(Debug, thiserror::Error)]
pub enum AccelError {
    #[error("triangle {triangle} has a non-finite vertex ({vertex:?})")]
    NonFiniteVertex { triangle: usize, vertex: [f32; 3] },
}

impl Accel {
    /// Builds a BVH over `triangles` (in any order) and permutes them into BVH order.
    ///
    /// # Errors
    /// A non-finite vertex (obvhs would panic on it).
    pub fn build(triangles: &mut FrameTriangles) -> Result<Accel, AccelError> {
        check_finite(triangles)?;
        if triangles.is_empty() {
            return Ok(Accel::default());
        }
        let boxes: Vec<Aabb> = triangles.positions.iter().map(padded_box).collect();
        let bvh = build_bvh2(
            &boxes,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        triangles.permute(&bvh.primitive_indices);
        let mut leaves = Vec::new();
        let mut wide = WideBvh::collapse(&bvh, |first, count| {
            leaves.push(Leaf {
                first,
                count,
                lane: 0,
            });
            first
        });
        for (leaf, &lane) in leaves.iter_mut().zip(wide.leaf_lanes()) {
            leaf.lane = lane;
        }
        // Packs and leaves in slot order; each leaf then refers to its first pack.
        leaves.sort_unstable_by_key(|l| l.first);
        let mut packed = PackedTriangles::default();
        let mut leaf_of_slot = vec![0; triangles.len()];
        for (i, leaf) in leaves.iter().enumerate() {
            let (first, count) = (leaf.first as usize, leaf.count as usize);
            leaf_of_slot[first..first + count].fill(i as u32);
            let first_pack = packed.push_leaf(
                &triangles.positions,
                &triangles.source,
                leaf.first,
                leaf.count,
            );
            wide.set_leaf_ref(leaf.lane, first_pack);
        }
        let mut accel = Accel {
            wide,
            triangles: packed,
            leaves,
            leaf_of_slot,
            build_cost: 0.0,
            cost: 0.0,
        };
        accel.build_cost = accel.sah_cost();
        accel.cost = accel.build_cost;
        Ok(accel)
    }

    /// Surface-area-heuristic cost of the tree, relative to its root box: the expected cost
    /// of a ray through the root. Compared with its value right after the build to decide
    /// when refitting has degraded the tree enough to rebuild it.
    pub fn sah_cost(&self) -> f32 {
        self.wide
            .sah_cost(SAH_TRAVERSAL_COST, SAH_INTERSECTION_COST)
            .unwrap_or_else(|| {
                // One leaf (or nothing): every ray tests every triangle.
                self.leaves
                    .first()
                    .map_or(0.0, |l| l.count as f32 * SAH_INTERSECTION_COST)
            })
    }

    /// The box of every triangle in the tree (`None` when empty).
    pub fn bounds(&self, triangles: &FrameTriangles) -> Option<Aabb> {
        if self.leaves.is_empty() {
            return None;
        }
        Some(self.wide.root_box().unwrap_or_else(|| {
            self.leaves.iter().fold(Aabb::empty(), |a, l| {
                a.union(&leaf_box(&triangles.positions, l.first, l.count))
            })
        }))
    }

    /// `sah_cost() / cost right after the last build` (1 for an empty tree), as of the last
    /// build or refit.
    pub fn sah_ratio(&self) -> f32 {
        if self.build_cost > 0.0 {
            self.cost / self.build_cost
        } else {
            1.0
        }
    }

    /// Refits the boxes to the moved triangles `moved_slots` (BVH order) after their
    /// positions changed in `triangles`. The tree's topology is kept.
    pub fn refit(&mut self, triangles: &FrameTriangles, moved_slots: &[u32]) -> RefitKind {
        if moved_slots.is_empty() || self.leaves.is_empty() {
            return RefitKind::None;
        }
        let kind = if moved_slots.len() as f64 > PARTIAL_REFIT_MAX_SHARE * self.leaves.len() as f64
        {
            self.refit_full(triangles, triangles.len() >= PARALLEL_REFIT_MIN);
            RefitKind::Full
        } else {
            self.refit_partial(triangles, moved_slots);
            RefitKind::Partial
        };
        self.cost = self.sah_cost();
        kind
    }

    /// Refits every leaf and inner box (on rayon's threads when `parallel`: each box is a
    /// pure function of its triangles, so the split changes no bit).
    fn refit_full(&mut self, triangles: &FrameTriangles, parallel: bool) {
        let positions = &triangles.positions;
        self.triangles.update_all(positions, parallel);
        // Leaves in slot order (their triangles read in order), each box written straight
        // into its lane: a list of boxes then a serial pass of scattered lane writes cost
        // as much again.
        let box_of = |leaf: &Leaf| (leaf.lane, leaf_box(positions, leaf.first, leaf.count));
        if parallel {
            let lanes = self.wide.leaf_lanes_writer();
            self.leaves.par_iter().with_min_len(512).for_each(|leaf| {
                let (lane, aabb) = box_of(leaf);
                // SAFETY: every leaf has its own lane (`Leaf::lane` is one-to-one).
                unsafe { lanes.set_leaf_box(lane, &aabb) };
            });
        } else {
            for leaf in &self.leaves {
                let (lane, aabb) = box_of(leaf);
                self.wide.set_leaf_box(lane, &aabb);
            }
        }
        self.wide.refit_inner();
    }

    /// Updates each moved triangle's pack lane and leaf box, then the leaf's ancestors up to
    /// the first whose box comes out unchanged.
    fn refit_partial(&mut self, triangles: &FrameTriangles, moved_slots: &[u32]) {
        for &slot in moved_slots {
            let positions = &triangles.positions;
            self.triangles.update(slot, &positions[slot as usize]);
            let leaf = self.leaves[self.leaf_of_slot[slot as usize] as usize];
            let aabb = leaf_box(positions, leaf.first, leaf.count);
            self.wide.refit_leaf(leaf.lane, &aabb);
        }
    }

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
    fn closest_within(
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
    fn closest_hits_within(&self, within: &Within, query: &mut PacketQuery) {
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
    fn closest_in_leaf(
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
    fn visit_hits_of(
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

fn check_finite(triangles: &FrameTriangles) -> Result<(), AccelError> {
    for (i, tri) in triangles.positions.iter().enumerate() {
        if let Some(v) = tri.iter().find(|v| !v.is_finite()) {
            return Err(AccelError::NonFiniteVertex {
                triangle: triangles.source[i] as usize,
                vertex: v.to_array(),
            });
        }
    }
    Ok(())
}

/// A triangle's box grown by a few ulps of its own magnitude on every axis, so that a flat
/// box still has volume and slab tests cannot miss it by rounding.
pub fn padded_box(tri: &[Vec3A; 3]) -> Aabb {
    let min = tri[0].min(tri[1]).min(tri[2]);
    let max = tri[0].max(tri[1]).max(tri[2]);
    let magnitude = min.abs().max(max.abs()).max_element();
    let pad = Vec3A::splat(magnitude * 2f32.powi(-20) + f32::MIN_POSITIVE * 8.0);
    Aabb::new(min - pad, max + pad)
}

/// The union of the padded boxes of the `count` triangles from slot `first` (a leaf).
fn leaf_box(positions: &[[Vec3A; 3]], first: u32, count: u32) -> Aabb {
    positions[first as usize..(first + count) as usize]
        .iter()
        .fold(Aabb::empty(), |a, tri| a.union(&padded_box(tri)))
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use glam::Vec3;

    /// Triangles with placeholder shading data, source ids in order.
    pub(in crate::accel) fn soup(tris: &[[Vec3A; 3]]) -> FrameTriangles {
        FrameTriangles {
            positions: tris.to_vec(),
            normals: vec![[Vec3::Z; 3]; tris.len()],
            uvs: vec![[Vec2::ZERO; 3]; tris.len()],
            material: vec![0; tris.len()],
            log2_pb: vec![0.0; tris.len()],
            source: (0..tris.len() as u32).collect(),
        }
    }

    #[test]
    fn finds_closest_of_stacked_triangles() {
        let tri = |z: f32| {
            [
                Vec3A::new(-1.0, -1.0, z),
                Vec3A::new(1.0, -1.0, z),
                Vec3A::new(0.0, 1.0, z),
            ]
        };
        let mut tris = soup(&[tri(-5.0), tri(-2.0), tri(-9.0)]);
        let accel = Accel::build(&mut tris).unwrap();
        let hit = accel
            .closest_hit(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY)
            .unwrap();
        assert!((hit.t - 2.0).abs() < 1e-6);
        assert_eq!(tris.source[hit.triangle as usize], 1);
        let mut count = 0;
        accel.visit_hits(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY, |_, _| {
            count += 1;
            true
        });
        assert_eq!(count, 3);
        assert!(
            accel
                .closest_hit(Vec3A::new(5.0, 0.0, 0.0), Vec3A::NEG_Z, f32::INFINITY)
                .is_none()
        );
    }

    #[test]
    fn axis_aligned_ray_hits_axis_aligned_flat_triangle() {
        // Floor at y = 0 seen straight down, and a wall at x = 3 hit along +x.
        let floor = [
            Vec3A::new(-1.0, 0.0, -1.0),
            Vec3A::new(1.0, 0.0, -1.0),
            Vec3A::new(0.0, 0.0, 1.0),
        ];
        let wall = [
            Vec3A::new(3.0, -1.0, -1.0),
            Vec3A::new(3.0, 1.0, -1.0),
            Vec3A::new(3.0, 0.0, 1.0),
        ];
        let mut tris = soup(&[floor, wall]);
        let accel = Accel::build(&mut tris).unwrap();
        let down = accel.closest_hit(Vec3A::new(0.0, 5.0, 0.0), Vec3A::NEG_Y, f32::INFINITY);
        assert!((down.unwrap().t - 5.0).abs() < 1e-6);
        let side = accel.closest_hit(Vec3A::new(-2.0, 0.0, 0.0), Vec3A::X, f32::INFINITY);
        assert!((side.unwrap().t - 5.0).abs() < 1e-6);
    }

    #[test]
    fn rejects_non_finite_vertices() {
        let mut tris = soup(&[[Vec3A::ZERO, Vec3A::X, Vec3A::new(f32::NAN, 0.0, 0.0)]]);
        assert!(matches!(
            Accel::build(&mut tris),
            Err(AccelError::NonFiniteVertex { triangle: 0, .. })
        ));
    }

    #[test]
    fn empty_scene_misses() {
        let mut tris = soup(&[]);
        let accel = Accel::build(&mut tris).unwrap();
        assert!(
            accel
                .closest_hit(Vec3A::ZERO, Vec3A::X, f32::INFINITY)
                .is_none()
        );
    }

    /// A small deterministic generator (xorshift) for the random soups below.
    /// Xorshift: reproducible pseudo-random points (seed non-zero).
    pub(in crate::accel) struct Rng(pub u64);
    impl Rng {
        pub(in crate::accel) fn next(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
        /// A point in the cube of side `scale` centred on the origin.
        pub(in crate::accel) fn point(&mut self, scale: f32) -> Vec3A {
            Vec3A::new(self.next(), self.next(), self.next()) * scale - Vec3A::splat(scale / 2.0)
        }
    }

    /// Closest hit by testing every triangle (same test, same tie rule).
    fn brute_force(tris: &FrameTriangles, origin: Vec3A, direction: Vec3A) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        for (slot, p) in tris.positions.iter().enumerate() {
            let Some((t, _)) = intersect(p, origin, direction) else {
                continue;
            };
            let source = tris.source[slot];
            if t >= 0.0 && best.is_none_or(|(s, b)| t < b || (t == b && source < s)) {
                best = Some((source, t));
            }
        }
        best
    }

    /// Exact ties far from the ray origin: an 8 x 8 grid of unit quads at z = 0, each
    /// triangle three times (the copies tie exactly), seen from cameras up to 1e6 away. The
    /// lowest source must win whatever order the tree visits the copies in, for single rays
    /// and packets alike.
    #[test]
    fn exact_ties_far_from_the_origin_go_to_the_lowest_source() {
        let mut tris = Vec::new();
        for j in 0..8 {
            for i in 0..8 {
                let (x, y) = (i as f32, j as f32);
                let a = [
                    Vec3A::new(x, y, 0.0),
                    Vec3A::new(x + 1.0, y, 0.0),
                    Vec3A::new(x + 1.0, y + 1.0, 0.0),
                ];
                let b = [a[0], a[2], Vec3A::new(x, y + 1.0, 0.0)];
                tris.extend([a, b, a, b, a, b]);
            }
        }
        // Shuffled, so copies land in different leaves with unrelated source ids.
        let mut rng = Rng(0x5851f42d4c957f2d);
        for i in (1..tris.len()).rev() {
            let j = (rng.next() * (i + 1) as f32) as usize % (i + 1);
            tris.swap(i, j);
        }
        let mut tris = soup(&tris);
        let accel = Accel::build(&mut tris).unwrap();
        let mut checked = 0;
        for distance in [30.0f32, 1e3, 1e4, 1e5, 3e5, 1e6, 1e6, 1e6] {
            for _ in 0..100 {
                let eye =
                    Vec3A::new(rng.next() * 2.0 - 1.0, rng.next() * 2.0 - 1.0, 1.0) * distance;
                let rays: Vec<(Vec3A, Vec3A)> = (0..64)
                    .map(|_| {
                        let aim = Vec3A::new(rng.next() * 8.0, rng.next() * 8.0, 0.0);
                        (eye, (aim - eye).normalize())
                    })
                    .collect();
                let mut hits = vec![None; rays.len()];
                accel.closest_hits(&rays, f32::INFINITY, &mut hits);
                for (&(o, d), hit) in rays.iter().zip(&hits) {
                    let single = accel.closest_hit(o, d, f32::INFINITY);
                    let found = single.map(|h| (tris.source[h.triangle as usize], h.t));
                    assert_eq!(found, brute_force(&tris, o, d), "eye {o} direction {d}");
                    assert_eq!(*hit, single, "packet and single ray, eye {o}");
                    checked += found.is_some() as usize;
                }
            }
        }
        assert!(checked > 8000, "only {checked} rays hit the grid");
    }

    fn random_soup(rng: &mut Rng, n: usize) -> FrameTriangles {
        let tris: Vec<[Vec3A; 3]> = (0..n)
            .map(|_| {
                let c = rng.point(20.0);
                [c + rng.point(2.0), c + rng.point(2.0), c + rng.point(2.0)]
            })
            .collect();
        soup(&tris)
    }

    fn assert_matches_brute_force(accel: &Accel, tris: &FrameTriangles, rng: &mut Rng) {
        let mut hits = 0;
        for _ in 0..2000 {
            let origin = rng.point(30.0);
            let direction = (rng.point(2.0) - origin * 0.05).normalize();
            let wide = accel
                .closest_hit(origin, direction, f32::INFINITY)
                .map(|h| (tris.source[h.triangle as usize], h.t));
            assert_eq!(wide, brute_force(tris, origin, direction));
            hits += wide.is_some() as usize;
            // The shadow walk sees a hit exactly when the closest-hit walk does.
            let blocked = !accel.visit_hits(origin, direction, f32::INFINITY, |_, _| false);
            assert_eq!(blocked, wide.is_some());
        }
        assert!(
            hits > 200,
            "too few rays hit ({hits}): the test would prove little"
        );
    }

    #[test]
    fn wide_walk_finds_what_testing_every_triangle_finds_before_and_after_refits() {
        let mut rng = Rng(0x9e3779b97f4a7c15);
        let mut tris = random_soup(&mut rng, 3000);
        let mut accel = Accel::build(&mut tris).unwrap();
        assert_matches_brute_force(&accel, &tris, &mut rng);
        // A few triangles jump (partial refit), then all of them move (full refit).
        let moved: Vec<u32> = (0..3000).step_by(97).collect();
        for &slot in &moved {
            let shift = rng.point(10.0);
            tris.positions[slot as usize] = tris.positions[slot as usize].map(|v| v + shift);
        }
        assert_eq!(accel.sah_ratio(), 1.0);
        assert_eq!(accel.refit(&tris, &moved), RefitKind::Partial);
        assert_matches_brute_force(&accel, &tris, &mut rng);
        // The kept SAH ratio is the refitted tree's (the jumps changed its boxes).
        assert!(accel.sah_ratio() != 1.0, "{}", accel.sah_ratio());
        assert_eq!(accel.sah_ratio(), accel.sah_cost() / accel.build_cost);
        let all: Vec<u32> = (0..3000).collect();
        for p in &mut tris.positions {
            *p = p.map(|v| v * 1.5 + Vec3A::new(1.0, 0.0, 0.0));
        }
        assert_eq!(accel.refit(&tris, &all), RefitKind::Full);
        assert_matches_brute_force(&accel, &tris, &mut rng);
    }
    #[test]
    fn a_packet_finds_what_each_of_its_rays_finds_alone() {
        let mut rng = Rng(0x2545f4914f6cdd1d);
        let mut tris = random_soup(&mut rng, 4000);
        // A coherent packet (a camera's 8 x 8 block), an incoherent one, and a short one.
        let accel = Accel::build(&mut tris).unwrap();
        let eye = Vec3A::new(0.0, 0.0, 40.0);
        let coherent: Vec<(Vec3A, Vec3A)> = (0..64)
            .map(|i| {
                let (x, y) = ((i % 8) as f32, (i / 8) as f32);
                (
                    eye,
                    Vec3A::new(x * 0.01 - 0.04, y * 0.01 - 0.04, -1.0).normalize(),
                )
            })
            .collect();
        let scattered: Vec<(Vec3A, Vec3A)> = (0..64)
            .map(|_| {
                let origin = rng.point(30.0);
                (origin, (rng.point(2.0) - origin * 0.05).normalize())
            })
            .collect();
        let mut found = 0;
        for (rays, t_max) in [
            (&coherent[..], f32::INFINITY),
            (&scattered[..], f32::INFINITY),
            (&scattered[..13], 25.0),
        ] {
            let mut hits = vec![None; rays.len()];
            accel.closest_hits(rays, t_max, &mut hits);
            for (&(o, d), hit) in rays.iter().zip(&hits) {
                assert_eq!(*hit, accel.closest_hit(o, d, t_max));
                found += hit.is_some() as usize;
            }
        }
        assert!(
            found > 40,
            "too few hits ({found}) for the test to mean much"
        );
    }

    /// The parallel full refit (leaf boxes written into their lanes from several tasks)
    /// leaves the tree bit for bit as the sequential one does.
    #[test]
    fn parallel_full_refit_equals_sequential() {
        let mut rng = Rng(0x51f15eed);
        let mut tris = random_soup(&mut rng, 5000);
        let mut accel = Accel::build(&mut tris).unwrap();
        let original = tris.clone();
        for tri in &mut tris.positions {
            let shift = rng.point(3.0);
            for v in tri.iter_mut() {
                *v = *v * 1.5 + shift;
            }
        }
        accel.refit_full(&tris, false);
        let sequential = accel.wide.bounds_bits();
        // Back to the original boxes, sequentially (so a lane the parallel refit skipped
        // would keep one and show), then the moved triangles again, in parallel.
        accel.refit_full(&original, false);
        assert_ne!(accel.wide.bounds_bits(), sequential);
        accel.refit_full(&tris, true);
        assert_eq!(accel.wide.bounds_bits(), sequential);
        // Every pack lane holds its slot's moved triangle.
        for (slot, tri) in tris.positions.iter().enumerate() {
            assert_eq!(accel.triangles.triangle(slot as u32), *tri, "slot {slot}");
        }
        // And the refitted tree finds what a fresh build over the moved triangles finds.
        let fresh = Accel::build(&mut tris.clone()).unwrap();
        for _ in 0..300 {
            let (o, d) = (rng.point(40.0), rng.point(2.0).normalize_or_zero());
            let hit = |a: &Accel| a.closest_hit(o, d, f32::INFINITY).map(|h| h.t.to_bits());
            assert_eq!(hit(&accel), hit(&fresh));
        }
    }

    #[test]
    fn tiny_and_empty_trees_answer_packets_and_refits() {
        // Two triangles: the whole tree is one leaf (no wide node), then nothing at all.
        let tri = |z: f32| {
            [
                Vec3A::new(-1.0, -1.0, z),
                Vec3A::new(1.0, -1.0, z),
                Vec3A::new(0.0, 1.0, z),
            ]
        };
        let mut tris = soup(&[tri(-5.0), tri(-2.0)]);
        let mut accel = Accel::build(&mut tris).unwrap();
        let rays = [
            (Vec3A::ZERO, Vec3A::NEG_Z),
            (Vec3A::new(9.0, 0.0, 0.0), Vec3A::NEG_Z),
        ];
        let mut hits = [None; 2];
        accel.closest_hits(&rays, f32::INFINITY, &mut hits);
        assert_eq!(hits[0].map(|h| h.t), Some(2.0));
        assert!(hits[1].is_none());
        // Move the near one behind the far one: the refit must move the packed copy too.
        tris.positions[tris.source.iter().position(|&s| s == 1).unwrap()] = tri(-7.0);
        let moved: Vec<u32> = (0..2).collect();
        accel.refit(&tris, &moved);
        assert_eq!(
            accel
                .closest_hit(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY)
                .map(|h| h.t),
            Some(5.0)
        );
        assert!(accel.sah_cost() > 0.0);
        // One triangle: certainly a tree of one leaf; a full refit moves it.
        let mut one = soup(&[tri(-3.0)]);
        let mut accel = Accel::build(&mut one).unwrap();
        one.positions[0] = tri(-4.0);
        assert_eq!(accel.refit(&one, &[0]), RefitKind::Full);
        assert_eq!(
            accel
                .closest_hit(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY)
                .map(|h| h.t),
            Some(4.0)
        );
        let mut empty = soup(&[]);
        let accel = Accel::build(&mut empty).unwrap();
        accel.closest_hits(&rays, f32::INFINITY, &mut hits);
        assert_eq!(hits, [None, None]);
        assert!(accel.visit_hits(Vec3A::ZERO, Vec3A::X, f32::INFINITY, |_, _| false));
    }

    #[test]
    fn packets_of_axis_parallel_and_repeated_rays_match_single_rays() {
        let mut rng = Rng(99);
        let mut tris = random_soup(&mut rng, 2000);
        let accel = Accel::build(&mut tris).unwrap();
        // Directions with zero components, both signs of zero, and the same ray many times.
        let mut rays = Vec::new();
        for d in [
            Vec3A::X,
            Vec3A::NEG_X,
            Vec3A::Y,
            Vec3A::NEG_Z,
            Vec3A::new(-0.0, 0.0, 1.0),
        ] {
            for i in 0..6 {
                rays.push((Vec3A::new(i as f32 - 3.0, 1.5, -0.5) - d * 30.0, d));
            }
        }
        rays.extend(std::iter::repeat_n(
            (Vec3A::new(0.0, 0.0, 30.0), Vec3A::NEG_Z),
            10,
        ));
        assert!(rays.len() <= PACKET);
        let mut hits = vec![None; rays.len()];
        accel.closest_hits(&rays, f32::INFINITY, &mut hits);
        for (&(o, d), hit) in rays.iter().zip(&hits) {
            assert_eq!(*hit, accel.closest_hit(o, d, f32::INFINITY));
        }
        assert!(hits.iter().filter(|h| h.is_some()).count() > 5);
    }

    #[test]
    fn rays_through_shared_edges_and_vertices_of_a_mesh_never_slip_through() {
        // A jittered 40 x 40 grid of quads (two triangles each) in a tilted plane; rays aimed
        // exactly at its vertices and at points on its shared edges must all hit it.
        let n = 40;
        let mut rng = Rng(12345);
        let mut grid = vec![Vec3A::ZERO; (n + 1) * (n + 1)];
        for y in 0..=n {
            for x in 0..=n {
                let jitter = if x == 0 || y == 0 || x == n || y == n {
                    Vec3A::ZERO
                } else {
                    Vec3A::new(rng.next() - 0.5, rng.next() - 0.5, 0.0) * 0.6
                };
                let p = Vec3A::new(x as f32, y as f32, 0.0) + jitter;
                grid[y * (n + 1) + x] = Vec3A::new(p.x, p.y, 0.37 * p.x - 0.21 * p.y);
            }
        }
        let at = |x: usize, y: usize| grid[y * (n + 1) + x];
        let mut quads = Vec::new();
        for y in 0..n {
            for x in 0..n {
                quads.push([at(x, y), at(x + 1, y), at(x + 1, y + 1)]);
                quads.push([at(x, y), at(x + 1, y + 1), at(x, y + 1)]);
            }
        }
        let mut tris = soup(&quads);
        let accel = Accel::build(&mut tris).unwrap();
        let eye = Vec3A::new(17.3, 21.1, 60.0);
        let mut misses = 0;
        let mut rays = 0;
        for y in 1..n {
            for x in 1..n {
                // The vertex, the midpoints of its right and upper edges and of the diagonal.
                let targets = [
                    at(x, y),
                    (at(x, y) + at(x + 1, y)) * 0.5,
                    (at(x, y) + at(x, y + 1)) * 0.5,
                    (at(x, y) + at(x + 1, y + 1)) * 0.5,
                ];
                for target in targets {
                    rays += 1;
                    let direction = (target - eye).normalize();
                    misses += accel.closest_hit(eye, direction, f32::INFINITY).is_none() as usize;
                }
            }
        }
        assert_eq!(
            misses, 0,
            "{misses} of {rays} rays slipped through the mesh"
        );
    }
}
