//! Queries on the flat tree: the closest hit of one ray or of a packet, and every hit along
//! a ray (shadow rays). The leaf tests are compiled into the walks (`LeafVisit` with an
//! always-inlined method), so each SIMD copy of a walk carries its own.

use glam::Vec3A;

use super::Accel;
use crate::accel::query::{Closest, Hit, PacketQuery, Within};
use crate::accel::triangles::{
    RAYS, ShearedLanes, ShearedRay, ShearedRows, lanes_of, runs_by_permutation,
};
#[cfg(target_arch = "x86_64")]
use crate::accel::triangles::{block_lanes_of, sixteen};
use crate::accel::wide::{GatheredLeaf, LeafVisit, PACKET, RayBoxes, listed, rays_below};
use crate::simd::F32x8;

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
            self.closest_hits_within(&Within::world(), q, true, n);
            for (hit, best) in hits.iter_mut().zip(&q.best[..n]) {
                *hit = best.hit;
            }
        });
    }

    /// [`Accel::closest_hits`] for rays from any origins (a bounce's reflected or refracted
    /// rays), walked together: with interval bounds when their lines pass through one point
    /// behind them (rays off a plane mirror), else by the masked traversal (each ray tests
    /// every node alone). Either way `hits[i]` is exactly what `closest_hit` returns for
    /// ray `i`.
    pub fn closest_hits_masked(
        &self,
        rays: &[(Vec3A, Vec3A)],
        t_max: f32,
        hits: &mut [Option<Hit>],
    ) {
        let n = rays.len().min(hits.len()).min(PACKET);
        if n == 0 {
            return;
        }
        PacketQuery::with_filled(
            |_| {},
            |q| {
                let leaf_side = self.wide.leaf_sides().typical();
                let bounded = q.fill_masked(&rays[..n], t_max, self.extent(), leaf_side);
                self.closest_hits_within(&Within::world(), q, bounded, n);
                for (hit, best) in hits.iter_mut().zip(&q.best[..n]) {
                    *hit = best.hit;
                }
            },
        )
    }

    /// The largest coordinate of the tree's boxes (0 for an empty tree): what
    /// [`PacketQuery::fill_masked`] needs to bound rays from an apex behind them.
    pub(in crate::accel) fn extent(&self) -> f32 {
        self.wide
            .root_box()
            .map_or(0.0, |b| b.min.abs().max(b.max.abs()).max_element())
    }

    /// Continues the closest-hit queries of the first `n` rays of `query` in this tree:
    /// walked as its packet when `packet` (filled by `fill`, or by `fill_masked` with
    /// bounds), else masked (each ray's own slab constants, from `fill_masked`).
    pub(in crate::accel) fn closest_hits_within(
        &self,
        within: &Within,
        query: &mut PacketQuery,
        packet: bool,
        n: usize,
    ) {
        let leaf = ClosestPacketLeaf {
            accel: self,
            within,
            sheared: &query.sheared,
            rows: &query.rows,
            // Only a packet walk hands a leaf its rays as a mask.
            one_permutation: if packet {
                groups_of_one_permutation(&query.sheared, n)
            } else {
                0
            },
            len: n,
            best: &mut query.best,
        };
        if packet {
            self.wide
                .traverse_packet_gathered(&query.packet, &mut query.limits, leaf);
        } else {
            self.wide
                .traverse_masked_ordered(&query.boxes[..n], &mut query.limits, leaf);
        }
    }

    /// Tests a leaf for the closest-hit queries of the packet rays `rays` (indices into
    /// `sheared`, `limits` and `best`), each triangle across the rays that share an axis
    /// permutation, eight at a time (sixteen where the AVX-512 routines run,
    /// `simd::avx512`): the same answers as [`Accel::closest_in_leaf`] for each ray alone
    /// (the same tie rule, the same limit afterwards).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn closest_in_leaf_across<const AVX: bool>(
        &self,
        within: &Within,
        sheared: &[ShearedRay; PACKET],
        rays: &[u8],
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
        best: &mut [Closest; PACKET],
    ) {
        let mut buffer = [0u8; PACKET];
        let (order, runs) = runs_by_permutation(sheared, rays, &mut buffer);
        let mut at = 0;
        for run in runs {
            // More rays than one group of eight: sixteen at a time where the CPU has
            // AVX-512.
            #[cfg(target_arch = "x86_64")]
            if AVX && run > RAYS && crate::simd::avx512() {
                for chunk in order[at..at + run].chunks(sixteen::WIDE) {
                    // Every triangle of the leaf is cut at the limit the ray entered it with.
                    let cut = block_lanes_of::<AVX>(limits, chunk);
                    // SAFETY: `simd::avx512()` holds only where the CPU has AVX-512F.
                    unsafe {
                        sixteen::hits_in_leaf(
                            &self.triangles,
                            sheared,
                            chunk,
                            u16::MAX,
                            &cut,
                            first,
                            count,
                            keeping_closer_lowering(within, best, sheared, limits, |l| {
                                usize::from(chunk[l])
                            }),
                        )
                    };
                }
                at += run;
                continue;
            }
            for chunk in order[at..at + run].chunks(RAYS) {
                let lanes = &ShearedLanes::of_rays::<AVX>(sheared, chunk);
                // Every triangle of the leaf is cut at the limit the ray entered it with.
                let cut = lanes_of::<AVX>(limits, chunk);
                self.triangles.hits_in_leaf_across::<AVX>(
                    lanes,
                    u32::MAX,
                    first,
                    count,
                    &cut,
                    keeping_closer_lowering(within, best, sheared, limits, |l| {
                        usize::from(chunk[l])
                    }),
                );
            }
            at += run;
        }
    }

    /// Tests a leaf for a closest-hit query: keeps the nearest hit (ties to the lowest source
    /// triangle) and lowers `limit` to it.
    #[inline(always)]
    pub(in crate::accel) fn closest_in_leaf<const AVX: bool>(
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
            .hits_in_leaf::<AVX>(ray, first, count, cut, |slot, source, t, bary| {
                if keep_if_closer(within, best, slot, source, t, bary) {
                    // Keep visiting boxes that start at `t` (up to rounding), where a tie
                    // may hide.
                    *limit = ray.tie_limit(t);
                }
                true
            });
    }

    /// [`Accel::visit_hits`] for a packet of up to [`PACKET`] rays `(origin, direction)`
    /// walked together (shadow rays of a tile toward one light): ray `r`'s hits with `t` in
    /// `[0, t_max[r])` are visited as `visit(r, slot, t)`, in an order that depends on the
    /// tree, until `visit` returns false for that ray. Returns the mask of the rays stopped
    /// early. Each ray meets exactly the triangles [`Accel::visit_hits`] meets for it alone
    /// (the same watertight test per ray and triangle), in another order.
    ///
    /// Rays whose segments converge on one point (toward a point light) walk with interval
    /// bounds over their segments taken backwards from it (one test per node for the whole
    /// packet, each ray testing only the leaves' boxes); others walk masked (each ray tests
    /// every node it reaches).
    pub fn visit_hits_packet(
        &self,
        rays: &[(Vec3A, Vec3A)],
        t_max: &[f32],
        visit: impl FnMut(usize, u32, f32) -> bool,
    ) -> u64 {
        let n = rays.len().min(t_max.len()).min(PACKET);
        if n == 0 {
            return 0;
        }
        PacketQuery::with_filled(
            |_| {},
            |q| {
                let converging = q.fill_occlusion(&rays[..n], &t_max[..n]);
                let mut ceilings = [0.0f32; PACKET];
                ceilings[..n].copy_from_slice(&t_max[..n]);
                let mut leaf = AnyHitPacketLeaf {
                    accel: self,
                    sheared: &q.sheared,
                    rows: &q.rows,
                    // Only the packet walk (converging rays) hands a leaf a mask.
                    one_permutation: if converging {
                        groups_of_one_permutation(&q.sheared, n)
                    } else {
                        0
                    },
                    len: n,
                    t_max: &ceilings,
                    visit,
                    stopped: 0,
                };
                if converging {
                    self.wide
                        .traverse_packet_gathered(&q.packet, &mut q.limits, &mut leaf);
                } else {
                    self.wide
                        .traverse_masked(&q.boxes[..n], &mut q.limits, &mut leaf);
                }
                leaf.stopped
            },
        )
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
        self.wide.traverse_unordered(
            ray,
            t_max,
            AnyHitLeaf {
                accel: self,
                sheared,
                t_max,
                visit: &mut visit,
            },
        )
    }
}

/// The any-hit leaf test of one ray as a [`LeafVisit`], compiled into the walk as
/// [`ClosestLeaf`] is.
struct AnyHitLeaf<'a, F> {
    accel: &'a Accel,
    sheared: &'a ShearedRay,
    t_max: f32,
    visit: &'a mut F,
}

impl<F: FnMut(u32, f32) -> bool> LeafVisit for AnyHitLeaf<'_, F> {
    #[inline(always)]
    fn visit<const AVX: bool>(&mut self, first: u32, count: u32, _: &mut f32) -> bool {
        let visit = &mut self.visit;
        self.accel.triangles.hits_in_leaf::<AVX>(
            self.sheared,
            first,
            count,
            self.t_max,
            |slot, _, t, _| visit(slot, t),
        )
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
    fn visit<const AVX: bool>(&mut self, first: u32, count: u32, limit: &mut f32) -> bool {
        self.accel.closest_in_leaf::<AVX>(
            self.within,
            self.sheared,
            first,
            count,
            limit,
            self.best,
        );
        *self.end = *limit;
        true
    }
}

/// Rays in a leaf from which [`Accel::closest_in_leaf_across`] tests each triangle across
/// the rays; below it, each ray tests the leaf's packs alone (the answers are the same).
const ACROSS_RAYS_MIN: usize = 4;

/// The hit callback of a group test whose lane `l` holds the packet's ray `ray_of(l)`:
/// keeps each hit that is closer for its ray (a closest-hit ray never stops in a leaf: a
/// later triangle may be closer, so it always asks for more) and lowers the ray's limit to
/// it at once. A group test reads the limits only as it starts (its cut is a copy, so the
/// limits are free for this callback to write), and each triangle of the leaf is cut at
/// the limit the ray entered it with; the lowered limit takes effect from the next leaf.
/// The limit left is that of the last hit kept, the ray's best (the kept hits come closer
/// or tie): the bits a pass over the improved rays after the test wrote, without its mask,
/// its loop or its reads of the best hits (about 6% more primary rays a second, BART
/// Kitchen on an AMD Zen 5).
#[inline(always)]
fn keeping_closer_lowering<'a>(
    within: &'a Within,
    best: &'a mut [Closest; PACKET],
    sheared: &'a [ShearedRay; PACKET],
    limits: &'a mut [f32; PACKET],
    ray_of: impl Fn(usize) -> usize + 'a,
) -> impl FnMut(usize, u32, u32, f32, glam::Vec2) -> bool + 'a {
    move |l, slot, source, t, bary| {
        // A ray of the packet: below `PACKET`. The remainder (a mask) makes that known to
        // the compiler, so the three arrays are read without bounds checks.
        let r = ray_of(l);
        debug_assert!(r < PACKET, "ray {r} of a packet");
        let r = r % PACKET;
        if keep_if_closer(within, &mut best[r], slot, source, t, bary) {
            // Keep visiting boxes that start at `t` (up to rounding), where a tie may hide.
            limits[r] = sheared[r].tie_limit(t);
        }
        true
    }
}

/// Keeps the hit `(slot, source, t, bary)` in `best` when it is closer, or as close with a
/// lower source triangle (the tie rule); returns whether it was kept.
#[inline(always)]
fn keep_if_closer(
    within: &Within,
    best: &mut Closest,
    slot: u32,
    source: u32,
    t: f32,
    bary: glam::Vec2,
) -> bool {
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
    }
    better
}

/// The closest-hit leaf test of a packet: a few rays test the leaf one by one, more test
/// each triangle across them; in a packet walk, in the packet's fixed groups of [`RAYS`]
/// where a group's rays share one axis permutation (as a primary packet's mostly all do) and
/// at least [`FIXED_GROUP_MIN`] of them are inside the leaf.
struct ClosestPacketLeaf<'a> {
    accel: &'a Accel,
    within: &'a Within<'a>,
    sheared: &'a [ShearedRay; PACKET],
    /// `sheared` as rows.
    rows: &'a ShearedRows,
    /// The rays of the groups (rays `RAYS * g..RAYS * (g + 1)`) whose rays share one axis
    /// permutation: [`groups_of_one_permutation`].
    one_permutation: u64,
    /// The packet's rays (`0..len`).
    len: usize,
    best: &'a mut [Closest; PACKET],
}

/// The rays of a packet's first `n` that lie in groups of [`RAYS`] (rays `RAYS * g..RAYS *
/// (g + 1)`, cut at `n`) whose rays all share one axis permutation, as a mask.
pub(super) fn groups_of_one_permutation(sheared: &[ShearedRay; PACKET], n: usize) -> u64 {
    let mut rays = 0u64;
    for at in (0..n.min(PACKET)).step_by(RAYS) {
        let group = &sheared[at..(at + RAYS).min(n)];
        let axes = group[0].axes_word();
        if group.iter().all(|ray| ray.axes_word() == axes) {
            rays |= rays_below(group.len()) << at;
        }
    }
    rays
}

/// Rays entering a leaf from one fixed group from which the group is tested in its own
/// lanes; fewer are gathered with other groups' (a lane group test costs the same for one
/// ray as for eight).
const FIXED_GROUP_MIN: u32 = 4;

// A group's rays are a byte of a packet's mask.
const _: () = assert!(RAYS == 8 && PACKET % RAYS == 0);

/// The rays of `entering` that a leaf tests in their fixed groups: those of groups of one
/// permutation (`one_permutation`) with at least [`FIXED_GROUP_MIN`] rays entering.
#[inline(always)]
fn in_fixed_groups(entering: u64, one_permutation: u64) -> u64 {
    let candidates = entering & one_permutation;
    let mut fixed = 0u64;
    for at in (0..PACKET).step_by(RAYS) {
        let group = candidates & (0xff << at);
        if group.count_ones() >= FIXED_GROUP_MIN {
            fixed |= group;
        }
    }
    fixed
}

/// How a packet leaf takes the rays `entering`: `None` to list them all (fewer than
/// [`ACROSS_RAYS_MIN`] in all, or no group for fixed lanes), else the rays tested in their
/// fixed groups ([`in_fixed_groups`]) and the rest, to list.
#[inline(always)]
fn split_entering(entering: u64, one_permutation: u64) -> Option<(u64, u64)> {
    let fixed = in_fixed_groups(entering, one_permutation);
    if (entering.count_ones() as usize) < ACROSS_RAYS_MIN || fixed == 0 {
        return None;
    }
    Some((fixed, entering & !fixed))
}

#[cfg(test)]
thread_local! {
    /// Group tests in fixed lanes on this thread, for tests to see that they ran:
    /// closest-hit groups of eight, of sixteen, and occlusion groups of eight, of sixteen.
    pub(super) static FIXED_GROUP_TESTS: std::cell::Cell<[usize; 4]> =
        const { std::cell::Cell::new([0; 4]) };
}

/// Counts a group test in fixed lanes of kind `kind` (see `FIXED_GROUP_TESTS`); nothing
/// outside tests.
#[inline(always)]
fn count_fixed_group(_kind: usize) {
    #[cfg(test)]
    FIXED_GROUP_TESTS.with(|c| {
        let mut counts = c.get();
        counts[_kind] += 1;
        c.set(counts);
    });
}

/// Whether the rays `live` (bit `l` for ray `at + l`) of the block of sixteen rays
/// `at..end` of a packet take one sixteen-lane test ([`sixteen::hits_in_leaf`]) rather than
/// two of eight: where both its groups share one permutation (`one_permutation`, see
/// [`groups_of_one_permutation`]) and more than eight of its rays are inside the leaf.
/// Below that, the two eight-lane tests cost less than one of sixteen.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn in_sixteen_lanes(
    live: u16,
    one_permutation: u64,
    sheared: &[ShearedRay; PACKET],
    at: usize,
    end: usize,
) -> bool {
    let block = rays_below(end - at) << at;
    live.count_ones() as usize > RAYS
        && one_permutation & block == block
        && sheared[at].axes_word() == sheared[end - 1].axes_word()
}

impl ClosestPacketLeaf<'_> {
    /// Tests a leaf for the rays of `entering` that lie in groups of one permutation, group
    /// by group, each group's rays in their fixed lanes (no list, no sort): the same tests,
    /// ray by ray, as [`Accel::closest_in_leaf_across`] makes on the rays gathered.
    #[inline(always)]
    fn visit_fixed_groups<const AVX: bool>(
        &mut self,
        entering: u64,
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        #[cfg(target_arch = "x86_64")]
        if AVX && crate::simd::avx512() {
            for at in (0..self.len).step_by(sixteen::WIDE) {
                let live = (entering >> at) as u16;
                if live == 0 {
                    continue;
                }
                let end = (at + sixteen::WIDE).min(self.len);
                if in_sixteen_lanes(live, self.one_permutation, self.sheared, at, end) {
                    count_fixed_group(1);
                    debug_assert!(self.rows.hold(self.sheared, at, end), "stale rows");
                    // Every triangle of the leaf is cut at the limit the ray entered it with.
                    let cut: [f32; sixteen::WIDE] = limits[at..at + sixteen::WIDE]
                        .try_into()
                        .expect("a block's limits");
                    // SAFETY: `simd::avx512()` holds only where the CPU has AVX-512F.
                    unsafe {
                        sixteen::hits_in_leaf_of_rows(
                            &self.accel.triangles,
                            self.rows,
                            self.sheared[at].k(),
                            at,
                            end - at,
                            live,
                            &cut,
                            first,
                            count,
                            keeping_closer_lowering(
                                self.within,
                                self.best,
                                self.sheared,
                                limits,
                                move |l| at + l,
                            ),
                        )
                    };
                    continue;
                }
                for half in [at, at + RAYS] {
                    let live = u32::from((entering >> half) as u8);
                    if live != 0 {
                        self.visit_group::<AVX>(half, live, first, count, limits);
                    }
                }
            }
            return;
        }
        for at in (0..self.len).step_by(RAYS) {
            let live = u32::from((entering >> at) as u8);
            if live != 0 {
                self.visit_group::<AVX>(at, live, first, count, limits);
            }
        }
    }

    /// The leaf test of the rays `live` (bit `l` for ray `at + l`) of the fixed group from
    /// ray `at`, whose rays share one permutation.
    #[inline(always)]
    fn visit_group<const AVX: bool>(
        &mut self,
        at: usize,
        live: u32,
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        count_fixed_group(0);
        // The group's rays in the packet (`of_row_block` asserts one to eight).
        let len = self.len.min(at + RAYS) - at;
        // Read from the packet's rows at each leaf (the group's lanes are a block of them).
        debug_assert!(self.rows.hold(self.sheared, at, at + len), "stale rows");
        let lanes = &ShearedLanes::of_row_block(self.rows, self.sheared[at].k(), at, len);
        // Every triangle of the leaf is cut at the limit the ray entered it with.
        let cut = F32x8(limits[at..at + RAYS].try_into().expect("a group's limits"));
        self.accel.triangles.hits_in_leaf_across::<AVX>(
            lanes,
            live,
            first,
            count,
            &cut,
            keeping_closer_lowering(self.within, self.best, self.sheared, limits, move |l| {
                at + l
            }),
        );
    }
}

impl GatheredLeaf for ClosestPacketLeaf<'_> {
    // Limits shrink to hit distances, which are at least 0.
    const STOPS_RAYS: bool = false;

    #[inline(always)]
    fn visit<const AVX: bool>(
        &mut self,
        rays: &[u8],
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        if rays.len() < ACROSS_RAYS_MIN {
            for &r in rays {
                let r = r as usize;
                self.accel.closest_in_leaf::<AVX>(
                    self.within,
                    &self.sheared[r],
                    first,
                    count,
                    &mut limits[r],
                    &mut self.best[r],
                );
            }
            return;
        }
        self.accel.closest_in_leaf_across::<AVX>(
            self.within,
            self.sheared,
            rays,
            first,
            count,
            limits,
            self.best,
        );
    }

    #[inline(always)]
    fn visit_entering<const AVX: bool>(
        &mut self,
        entering: u64,
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        let Some((fixed, rest)) = split_entering(entering, self.one_permutation) else {
            let mut buffer = [0u8; PACKET];
            let rays = listed(entering, &mut buffer);
            return self.visit::<AVX>(rays, first, count, limits);
        };
        if rest != 0 {
            // Rays of groups with several permutations or fewer than `FIXED_GROUP_MIN`
            // rays inside: listed, then sorted by permutation.
            let mut buffer = [0u8; PACKET];
            let rays = listed(rest, &mut buffer);
            self.accel.closest_in_leaf_across::<AVX>(
                self.within,
                self.sheared,
                rays,
                first,
                count,
                limits,
                self.best,
            );
        }
        self.visit_fixed_groups::<AVX>(fixed, first, count, limits);
    }
}

/// The limit of a ray whose any-hit query has stopped: below every entry distance, so the
/// ray enters no more boxes, and negative, which ends the packet's walk once every ray has
/// it.
const STOPPED: f32 = -1.0;

/// The any-hit leaf test of a packet: each ray visits its hits until its visitor stops it.
struct AnyHitPacketLeaf<'a, F> {
    accel: &'a Accel,
    sheared: &'a [ShearedRay; PACKET],
    /// `sheared` as rows.
    rows: &'a ShearedRows,
    /// The rays of the groups whose rays share one axis permutation
    /// ([`groups_of_one_permutation`]).
    one_permutation: u64,
    /// The packet's rays (`0..len`).
    len: usize,
    /// Each ray's own search distance (its limit drops to [`STOPPED`] when it stops).
    t_max: &'a [f32; PACKET],
    visit: F,
    stopped: u64,
}

impl<F: FnMut(usize, u32, f32) -> bool> GatheredLeaf for &mut AnyHitPacketLeaf<'_, F> {
    #[inline(always)]
    fn visit<const AVX: bool>(
        &mut self,
        rays: &[u8],
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        if rays.len() < ACROSS_RAYS_MIN {
            for &r in rays {
                let r = r as usize;
                let visit = &mut self.visit;
                let finished = !self.accel.triangles.hits_in_leaf::<AVX>(
                    &self.sheared[r],
                    first,
                    count,
                    self.t_max[r],
                    |slot, _, t, _| visit(r, slot, t),
                );
                if finished {
                    limits[r] = STOPPED;
                    self.stopped |= 1 << r;
                }
            }
            return;
        }
        self.visit_across::<AVX>(rays, first, count, limits);
    }

    #[inline(always)]
    fn visit_entering<const AVX: bool>(
        &mut self,
        entering: u64,
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        let Some((fixed, rest)) = split_entering(entering, self.one_permutation) else {
            let mut buffer = [0u8; PACKET];
            let rays = listed(entering, &mut buffer);
            return self.visit::<AVX>(rays, first, count, limits);
        };
        if rest != 0 {
            // Rays of groups with several permutations or fewer than `FIXED_GROUP_MIN`
            // rays inside: listed, then sorted by permutation.
            let mut buffer = [0u8; PACKET];
            let rays = listed(rest, &mut buffer);
            self.visit_across::<AVX>(rays, first, count, limits);
        }
        self.visit_fixed_groups::<AVX>(fixed, first, count, limits);
    }
}

impl<F: FnMut(usize, u32, f32) -> bool> AnyHitPacketLeaf<'_, F> {
    /// Tests a leaf for the rays of `fixed` that lie in groups of one permutation, in their
    /// fixed lanes (no list, no sort): per ray the same tests in the same order as gathered.
    /// Where the CPU has AVX-512, a block of sixteen rays goes in one test when
    /// [`in_sixteen_lanes`] says so, as closest-hit leaves do: a tile's shadow rays toward
    /// a light often cross a leaf near it together (BART Kitchen frame 400's first-bounce
    /// shadow rays on an AMD Zen 5: about 10% more rays a second than in two tests of
    /// eight).
    #[inline(always)]
    fn visit_fixed_groups<const AVX: bool>(
        &mut self,
        fixed: u64,
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        #[cfg(target_arch = "x86_64")]
        if AVX && crate::simd::avx512() {
            for at in (0..self.len).step_by(sixteen::WIDE) {
                let live = (fixed >> at) as u16;
                if live == 0 {
                    continue;
                }
                let end = (at + sixteen::WIDE).min(self.len);
                if in_sixteen_lanes(live, self.one_permutation, self.sheared, at, end) {
                    count_fixed_group(3);
                    let visit = &mut self.visit;
                    debug_assert!(self.rows.hold(self.sheared, at, end), "stale rows");
                    // SAFETY: `simd::avx512()` holds only where the CPU has AVX-512F.
                    let alive = unsafe {
                        sixteen::hits_in_leaf_of_rows(
                            &self.accel.triangles,
                            self.rows,
                            self.sheared[at].k(),
                            at,
                            end - at,
                            live,
                            self.t_max[at..at + sixteen::WIDE]
                                .try_into()
                                .expect("a block's limits"),
                            first,
                            count,
                            |l, slot, _, t, _| visit(at + l, slot, t),
                        )
                    };
                    stop_from(&mut self.stopped, at, u32::from(live & !alive), limits);
                    continue;
                }
                for half in [at, at + RAYS] {
                    self.visit_group::<AVX>(half, fixed, first, count, limits);
                }
            }
            return;
        }
        for at in (0..self.len).step_by(RAYS) {
            self.visit_group::<AVX>(at, fixed, first, count, limits);
        }
    }

    /// The leaf test of the rays of `fixed` in the fixed group of eight from ray `at`,
    /// whose rays share one permutation.
    #[inline(always)]
    fn visit_group<const AVX: bool>(
        &mut self,
        at: usize,
        fixed: u64,
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        let live = u32::from((fixed >> at) as u8);
        if live == 0 {
            return;
        }
        count_fixed_group(2);
        // The group's rays in the packet (`of_row_block` asserts one to eight).
        let len = self.len.min(at + RAYS) - at;
        debug_assert!(self.rows.hold(self.sheared, at, at + len), "stale rows");
        let lanes = &ShearedLanes::of_row_block(self.rows, self.sheared[at].k(), at, len);
        let cut = F32x8(
            self.t_max[at..at + RAYS]
                .try_into()
                .expect("a group's limits"),
        );
        let visit = &mut self.visit;
        let alive = self.accel.triangles.hits_in_leaf_across::<AVX>(
            lanes,
            live,
            first,
            count,
            &cut,
            |l, slot, _, t, _| visit(at + l, slot, t),
        );
        stop_from(&mut self.stopped, at, live & !alive, limits);
    }

    /// Tests each triangle of a leaf across the rays `rays`, sorted into runs of one
    /// permutation and cut into groups of [`RAYS`].
    #[inline(always)]
    fn visit_across<const AVX: bool>(
        &mut self,
        rays: &[u8],
        first: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        let mut buffer = [0u8; PACKET];
        let (order, runs) = runs_by_permutation(self.sheared, rays, &mut buffer);
        let visit = &mut self.visit;
        let mut at = 0;
        for run in runs {
            for chunk in order[at..at + run].chunks(RAYS) {
                let lanes = &ShearedLanes::of_rays::<AVX>(self.sheared, chunk);
                let cut = lanes_of::<AVX>(self.t_max, chunk);
                let all = (1u32 << chunk.len()) - 1;
                let alive = self.accel.triangles.hits_in_leaf_across::<AVX>(
                    lanes,
                    all,
                    first,
                    count,
                    &cut,
                    |l, slot, _, t, _| visit(chunk[l] as usize, slot, t),
                );
                let finished = all & !alive;
                stop(&mut self.stopped, chunk, finished, limits);
            }
            at += run;
        }
    }
}

/// [`stop`] for a fixed group from ray `at` (bit `l` of `finished` for ray `at + l`): the
/// group's bits go into `stopped` at once, without reading a list of its rays.
#[inline(always)]
fn stop_from(stopped: &mut u64, at: usize, mut finished: u32, limits: &mut [f32; PACKET]) {
    *stopped |= u64::from(finished) << at;
    while finished != 0 {
        let l = finished.trailing_zeros() as usize;
        finished &= finished - 1;
        // A ray of the packet: the remainder (a mask) spares the bounds check.
        debug_assert!(at + l < PACKET, "ray {} of a packet", at + l);
        limits[(at + l) % PACKET] = STOPPED;
    }
}

/// Marks the rays `finished` (bit `l` for ray `chunk[l]`) of an any-hit packet as stopped.
#[inline(always)]
fn stop(stopped: &mut u64, chunk: &[u8], mut finished: u32, limits: &mut [f32; PACKET]) {
    while finished != 0 {
        let l = finished.trailing_zeros() as usize;
        finished &= finished - 1;
        let r = chunk[l] as usize;
        limits[r] = STOPPED;
        *stopped |= 1 << r;
    }
}
