//! The two-level structure: one bottom-level tree per shared mesh (object space, built
//! once), a top-level tree over the instances that place them (rebuilt from the instances'
//! boxes when they move, one instance per leaf), and beside them the world-space tree over
//! everything else (the flat [`Accel`] the frame loop refits). Closest-hit queries walk the
//! instances first and the world tree with the limit they leave; any-hit (shadow) queries
//! walk the world tree first, whose large occluders stop most of them before an instance is
//! entered (both orders measured, BENCHMARKS.md). Rigid motion then costs a transform per
//! instance instead of a rewrite of every triangle (Embree's and OptiX's instancing).
//!
//! A ray enters an instance by its inverse transform without renormalising the direction,
//! so the object-space `t` is the world-space `t` and one closest-hit query runs through
//! every tree it enters with one limit. Ties break by source triangle as in the flat tree
//! (`source_base` turns a mesh's own triangle index into the scene's), so the hit found does
//! not depend on the top-level tree's shape.

use std::time::Duration;

use glam::{Affine3A, Mat4, Vec2, Vec3, Vec3A};
use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::builder::build_bvh2};

use super::query::{Closest, Hit, ObjectPacket, PacketQuery, Within};
use super::triangles::ShearedRay;
use super::wide::{LeafSides, PACKET, RayBoxes, WideBvh};
use super::{Accel, AccelError};
use crate::geometry::{FrameTriangles, Placement};

/// One instance of a shared mesh, as the frame loop describes it.
#[derive(Debug, Clone, Copy)]
pub struct TlasInstance {
    /// What hits on it report as [`Hit::instance`].
    pub index: u32,
    /// Mesh `i` of [`TwoLevelAccel::new`].
    pub mesh: u32,
    pub world_from_object: Mat4,
    /// Added to the mesh's own triangle index to give the scene's source triangle.
    pub source_base: u32,
}

/// A shared mesh's tree over its object-space triangles.
struct MeshBlas {
    triangles: FrameTriangles,
    accel: Accel,
    /// Boxes that together hold every triangle (empty for an empty mesh), tighter than its
    /// root box (the subtrees
    /// [`HULL_LEVELS`] below the root): an instance's world box is the union of their
    /// transformed boxes, which for a turned instance is much smaller than the transformed
    /// root box, so fewer rays enter it for nothing.
    hull: Vec<Aabb>,
}

/// How many wide levels below a mesh's root its hull boxes lie (up to `WIDTH^levels`
/// boxes, each transformed per instance and frame: eight corners).
const HULL_LEVELS: usize = 2;

/// An instance as rays read it, stored in top-level leaf order.
#[derive(Clone, Copy)]
struct Placed {
    mesh: u32,
    object_from_world: Affine3A,
    source_base: u32,
    /// Its index in the caller's instance list (what hits report).
    index: u32,
}

/// An instance whose transform collapses a dimension (a zero scale): it cannot be entered
/// by an inverse transform, but a flat mesh flattened along its normal is still seen, so its
/// triangles are placed in world space for the frame (rare; walked after the top level).
struct Collapsed {
    index: u32,
    source_base: u32,
    /// The tree over the world-space copies (their packs hold the mesh's own triangle
    /// index as the tie rule's source, before the base).
    accel: Accel,
    /// Per slot, the mesh slot it copies (what hits report).
    mesh_slot: Vec<u32>,
}

impl Collapsed {
    fn within(&self) -> Within<'_> {
        Within {
            source_base: self.source_base,
            instance: self.index,
            reported: Some(&self.mesh_slot),
        }
    }
}

/// A top-level tree over some instances.
#[derive(Default)]
struct TopLevel {
    tlas: WideBvh,
    /// Instances in top-level leaf order (a leaf's reference is its index here).
    placed: Vec<Placed>,
    /// Boxes of the last build, reused.
    boxes: Vec<Aabb>,
    /// Instances with a collapsed transform, walked after the tree.
    collapsed: Vec<Collapsed>,
    /// The box of the only instance when there is one: a one-leaf tree keeps no box, and
    /// entering an instance (transform, ray setup) costs more than testing it.
    single: Option<Aabb>,
}

impl TopLevel {
    /// Whether a ray may reach the instance at leaf `first` (always, in a tree with boxes:
    /// the walk tested them).
    #[inline(always)]
    fn reaches(&self, ray: &RayBoxes, t_max: f32) -> bool {
        self.single.is_none_or(|b| ray.enters_box(&b, t_max))
    }
}

/// Bottom-level trees of the shared meshes and the top-level trees over their instances:
/// one over the instances that never move (built once), one over those that do (rebuilt
/// when one moves), so a moving car among a static forest of instances pays for itself.
#[derive(Default)]
pub struct TwoLevelAccel {
    meshes: Vec<MeshBlas>,
    /// The meshes' trees' leaf sizes together, each mesh's leaves once (object space: an
    /// instance's scale is not applied), measured when they are built: with the world
    /// tree's, what decides whether a bounce packet walks with interval bounds
    /// (`RayPacket::set_with_apex`).
    mesh_leaf_sides: LeafSides,
    /// `[fixed, moving]`.
    levels: [TopLevel; 2],
}

/// Fewest rays of a packet that enter an instance as a packet of their own; fewer enter it
/// one by one (a packet's setup costs more than it saves for a ray or two).
const INSTANCE_PACKET: usize = 4;

const FIXED: usize = 0;
const MOVING: usize = 1;

/// What an instance's transform allows this frame.
enum Placing {
    /// Entered by its inverse transform; its world box.
    Inverse(Affine3A, Aabb),
    /// A finite transform without an inverse.
    Collapsed,
    /// Overflowing or NaN.
    NonFinite,
    /// An empty mesh.
    Nothing,
}

impl TwoLevelAccel {
    /// Builds one tree per mesh over `meshes` (object-space triangles whose `source` is the
    /// mesh's own triangle index); the meshes' arrays are permuted into tree order.
    ///
    /// # Errors
    /// A non-finite vertex.
    pub fn new(meshes: Vec<FrameTriangles>) -> Result<TwoLevelAccel, AccelError> {
        let meshes = meshes
            .into_iter()
            .map(|mut triangles| {
                let accel = Accel::build(&mut triangles)?;
                let bounds = accel.bounds();
                let mut hull = accel.wide.boxes_at_depth(HULL_LEVELS);
                if hull.is_empty() {
                    hull.extend(bounds);
                }
                Ok(MeshBlas {
                    triangles,
                    accel,
                    hull,
                })
            })
            .collect::<Result<Vec<_>, AccelError>>()?;
        let mesh_leaf_sides = meshes
            .iter()
            .map(|mesh| mesh.accel.wide.leaf_sides())
            .fold(LeafSides::default(), LeafSides::add);
        Ok(TwoLevelAccel {
            meshes,
            mesh_leaf_sides,
            ..Default::default()
        })
    }

    /// Mesh `i`'s triangles in its tree's slot order (object space; their vertices are
    /// in the mesh's tree, [`TwoLevelAccel::mesh_triangle`]).
    pub fn mesh_triangles(&self, i: u32) -> &FrameTriangles {
        &self.meshes[i as usize].triangles
    }

    /// The object-space vertices of mesh `i`'s slot `slot`.
    #[inline]
    pub fn mesh_triangle(&self, i: u32, slot: u32) -> [Vec3A; 3] {
        self.meshes[i as usize].accel.triangle(slot)
    }

    /// Object-space triangles across all meshes (each stored once, however many instances).
    pub fn mesh_triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.triangles.len()).sum()
    }

    /// Instances rays can hit this frame (those with an empty mesh are left out).
    pub fn instance_count(&self) -> usize {
        self.levels
            .iter()
            .map(|l| l.placed.len() + l.collapsed.len())
            .sum()
    }

    /// Places the moving instances for this frame and rebuilds their top-level tree.
    ///
    /// # Errors
    /// The [`TlasInstance::index`] of the first instance whose world box is not finite (a
    /// transform that overflows or is NaN); the tree is then left empty.
    pub fn set_instances(&mut self, instances: &[TlasInstance]) -> Result<(), u32> {
        self.set_level(MOVING, instances)
    }

    /// Places the instances that never move (once, on the first frame), as
    /// [`TwoLevelAccel::set_instances`].
    ///
    /// # Errors
    /// As [`TwoLevelAccel::set_instances`].
    pub fn set_fixed_instances(&mut self, instances: &[TlasInstance]) -> Result<(), u32> {
        self.set_level(FIXED, instances)
    }

    fn set_level(&mut self, level: usize, instances: &[TlasInstance]) -> Result<(), u32> {
        let mut top = std::mem::take(&mut self.levels[level]);
        let built = self.build_level(&mut top, instances);
        if built.is_err() {
            top = TopLevel::default();
        }
        self.levels[level] = top;
        built
    }

    fn build_level(&self, top: &mut TopLevel, instances: &[TlasInstance]) -> Result<(), u32> {
        let mut placed = Vec::with_capacity(instances.len());
        top.boxes.clear();
        top.tlas = WideBvh::default();
        top.placed.clear();
        top.collapsed.clear();
        top.single = None;
        for instance in instances {
            let (object_from_world, aabb) = match self.placing(instance) {
                Placing::Inverse(inverse, aabb) => (inverse, aabb),
                Placing::Nothing => continue,
                Placing::NonFinite => return Err(instance.index),
                Placing::Collapsed => {
                    let collapsed = self.collapse(instance).ok_or(instance.index)?;
                    top.collapsed.push(collapsed);
                    continue;
                }
            };
            placed.push(Placed {
                mesh: instance.mesh,
                object_from_world,
                source_base: instance.source_base,
                index: instance.index,
            });
            top.boxes.push(aabb);
        }
        if placed.is_empty() {
            return Ok(());
        }
        // One instance per leaf: entering an instance costs a transform and the ray's
        // setup, so the top-level boxes should decide as much as they can.
        let params = BvhBuildParams {
            max_prims_per_leaf: 1,
            ..BvhBuildParams::medium_build()
        };
        let bvh = build_bvh2(&top.boxes, params, &mut Duration::default());
        top.placed = bvh
            .primitive_indices
            .iter()
            .map(|&i| placed[i as usize])
            .collect();
        top.tlas = WideBvh::collapse(&bvh, |first, _| first);
        if let [only] = top.boxes[..] {
            top.single = Some(only);
        }
        Ok(())
    }

    /// What instance `instance`'s transform allows this frame.
    fn placing(&self, instance: &TlasInstance) -> Placing {
        let Some(mesh) = self
            .meshes
            .get(instance.mesh as usize)
            .filter(|m| !m.hull.is_empty())
        else {
            return Placing::Nothing;
        };
        let to_world = Affine3A::from_mat4(instance.world_from_object);
        let world_box = mesh.hull.iter().fold(Aabb::empty(), |a, b| {
            a.union(&transformed_box(b, &to_world))
        });
        if !(world_box.min.is_finite() && world_box.max.is_finite()) {
            return Placing::NonFinite;
        }
        let inverse = to_world.inverse();
        let invertible = to_world.matrix3.determinant() != 0.0
            && inverse.matrix3.is_finite()
            && inverse.translation.is_finite();
        if invertible {
            Placing::Inverse(inverse, world_box)
        } else {
            Placing::Collapsed
        }
    }

    /// A collapsed instance's triangles placed in world space, as the flat path places them
    /// (`None` if a vertex overflows).
    fn collapse(&self, instance: &TlasInstance) -> Option<Collapsed> {
        let MeshBlas {
            triangles: mesh,
            accel: mesh_accel,
            ..
        } = &self.meshes[instance.mesh as usize];
        let placement = Placement::new(instance.world_from_object);
        let n = mesh.len();
        let mut triangles = FrameTriangles {
            positions: (0..n)
                .map(|k| {
                    let object = mesh_accel.triangle(k as u32);
                    placement
                        .place_triangle(object, mesh.normals[k], mesh.uvs[k])
                        .0
                })
                .collect(),
            normals: vec![[Vec3::ZERO; 3]; n],
            uvs: vec![[Vec2::ZERO; 3]; n],
            material: vec![0; n],
            log2_pb: vec![0.0; n],
            source: mesh.source.clone(),
        };
        let accel = Accel::build(&mut triangles).ok()?;
        // Back from each copy's source to the mesh slot it copies (sources are unique).
        let mut slot_of_source: Vec<(u32, u32)> = (0..n as u32)
            .map(|k| (mesh.source[k as usize], k))
            .collect();
        slot_of_source.sort_unstable();
        let mesh_slot = triangles
            .source
            .iter()
            .map(|source| {
                let at = slot_of_source.partition_point(|&(s, _)| s < *source);
                slot_of_source[at].1
            })
            .collect();
        Some(Collapsed {
            index: instance.index,
            source_base: instance.source_base,
            accel,
            mesh_slot,
        })
    }

    /// The closest hit with `t` in `[0, t_max)` over the world-space tree `world` and every
    /// instance; ties to the lowest source triangle, as
    /// [`Accel::closest_hit`].
    pub fn closest_hit(
        &self,
        world: &Accel,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> Option<Hit> {
        let mut best = Closest::default();
        let ray = RayBoxes::new(origin, direction);
        let sheared = ShearedRay::new(origin, direction);
        // Instances first, then the world tree: a ray that hits an instance then walks less of
        // the world, and the world walk needs no limit of its own to start from (measured:
        // -0.7% instructions per frame on BART Kitchen, -1.0% on Robots, hits unchanged).
        let mut limit = t_max;
        for top in &self.levels {
            // The limit each tree ends with carries on, as `Accel::closest_within` returns it.
            let mut end = limit;
            top.tlas
                .traverse(&ray, limit, |first: u32, _: u32, walk_limit: &mut f32| {
                    if top.reaches(&ray, *walk_limit) {
                        let placed = &top.placed[first as usize];
                        *walk_limit = self.closest_in_instance(
                            placed,
                            origin,
                            direction,
                            *walk_limit,
                            &mut best,
                        );
                        end = *walk_limit;
                    }
                    true
                });
            limit = end;
        }
        for c in self.levels.iter().flat_map(|l| &l.collapsed) {
            limit = c
                .accel
                .closest_within(&c.within(), &ray, &sheared, limit, &mut best);
        }
        world.closest_within(&Within::world(), &ray, &sheared, limit, &mut best);
        best.hit
    }

    /// [`TwoLevelAccel::closest_hit`] for a packet of up to [`PACKET`] rays: the top-level
    /// trees and the world tree are each walked once for the packet; the rays that enter an
    /// instance together (at least `INSTANCE_PACKET`) walk it as a packet of their own,
    /// fewer one by one.
    pub fn closest_hits(
        &self,
        world: &Accel,
        rays: &[(Vec3A, Vec3A)],
        t_max: f32,
        hits: &mut [Option<Hit>],
    ) {
        let n = rays.len().min(hits.len()).min(PACKET);
        PacketQuery::with(&rays[..n], t_max, |q| {
            self.closest_hits_filled(world, rays, q, true, n);
            for (hit, best) in hits.iter_mut().zip(&q.best[..n]) {
                *hit = best.hit;
            }
        });
    }

    /// [`TwoLevelAccel::closest_hits`] for rays from any origins (a bounce's reflected and
    /// refracted rays): each tree is walked once for the packet, with interval bounds when
    /// the rays' lines pass through one point behind them, else by the masked walk (as
    /// [`Accel::closest_hits_masked`]); the rays that enter an instance together walk it as
    /// a packet of their own. `hits[i]` is exactly what `closest_hit` returns for ray `i`.
    pub fn closest_hits_scattered(
        &self,
        world: &Accel,
        rays: &[(Vec3A, Vec3A)],
        t_max: f32,
        hits: &mut [Option<Hit>],
    ) {
        let n = rays.len().min(hits.len()).min(PACKET);
        if n == 0 {
            return;
        }
        let extent = self
            .levels
            .iter()
            .filter_map(|top| top.tlas.root_box().or(top.single))
            .map(|b| b.min.abs().max(b.max.abs()).max_element())
            .fold(world.extent(), f32::max);
        let leaf_side = world.wide.leaf_sides().add(self.mesh_leaf_sides).typical();
        PacketQuery::with_filled(
            |_| {},
            |q| {
                let bounded = q.fill_masked(&rays[..n], t_max, extent, leaf_side);
                self.closest_hits_filled(world, rays, q, bounded, n);
                for (hit, best) in hits.iter_mut().zip(&q.best[..n]) {
                    *hit = best.hit;
                }
            },
        )
    }

    /// Continues the closest-hit queries of the first `n` rays of `query` (the packet
    /// `rays`) through the instances, then the world tree, as `closest_hit` does: each tree
    /// walked as the query's packet when `packet` (filled by `fill`, or by `fill_masked`
    /// with bounds), else masked (each ray's own slab constants).
    fn closest_hits_filled(
        &self,
        world: &Accel,
        rays: &[(Vec3A, Vec3A)],
        query: &mut PacketQuery,
        packet: bool,
        n: usize,
    ) {
        {
            let PacketQuery {
                packet: rays_packet,
                sheared,
                best,
                limits,
                boxes,
                object,
                ..
            } = &mut *query;
            let (rays_packet, boxes) = (&*rays_packet, &*boxes);
            let ray = |r: usize| if packet { rays_packet.ray(r) } else { boxes[r] };
            for top in &self.levels {
                let leaf = |entering: &[u8], first: u32, _: u32, limits: &mut [f32; PACKET]| {
                    self.closest_in_entered_instance(
                        top, first, rays, entering, ray, limits, best, object,
                    );
                };
                if packet {
                    top.tlas.traverse_packet_gathered(rays_packet, limits, leaf);
                } else {
                    top.tlas.traverse_masked_ordered(&boxes[..n], limits, leaf);
                }
            }
            for c in self.levels.iter().flat_map(|l| &l.collapsed) {
                for r in 0..n {
                    limits[r] = c.accel.closest_within(
                        &c.within(),
                        &ray(r),
                        &sheared[r],
                        limits[r],
                        &mut best[r],
                    );
                }
            }
        }
        world.closest_hits_within(&Within::world(), query, packet, n);
    }

    /// Continues the closest-hit queries of the packet rays `entering` (indices into `rays`,
    /// `limits` and `best`; `ray(r)`: ray `r`'s slab constants) in the instance at leaf
    /// `first` of `top`: the rays that reach it together walk it as a packet of their own
    /// (at least [`INSTANCE_PACKET`]), fewer one by one.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn closest_in_entered_instance(
        &self,
        top: &TopLevel,
        first: u32,
        rays: &[(Vec3A, Vec3A)],
        entering: &[u8],
        ray: impl Fn(usize) -> RayBoxes,
        limits: &mut [f32; PACKET],
        best: &mut [Closest; PACKET],
        object: &mut ObjectPacket,
    ) {
        let mut inside = [0u8; PACKET];
        let mut k = 0;
        for &r in entering {
            if top.reaches(&ray(r as usize), limits[r as usize]) {
                inside[k] = r;
                k += 1;
            }
        }
        let placed = &top.placed[first as usize];
        if k >= INSTANCE_PACKET {
            self.closest_in_instance_packet(placed, rays, &inside[..k], limits, best, object);
            return;
        }
        for &r in &inside[..k] {
            let r = r as usize;
            let (origin, direction) = rays[r];
            limits[r] =
                self.closest_in_instance(placed, origin, direction, limits[r], &mut best[r]);
        }
    }

    /// Continues a closest-hit query in one instance's tree; returns the new limit.
    #[inline]
    fn closest_in_instance(
        &self,
        placed: &Placed,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        best: &mut Closest,
    ) -> f32 {
        let mesh = &self.meshes[placed.mesh as usize];
        let (o, d) = object_ray(&placed.object_from_world, origin, direction);
        let within = Within {
            source_base: placed.source_base,
            instance: placed.index,
            reported: None,
        };
        mesh.accel.closest_within(
            &within,
            &RayBoxes::new(o, d),
            &ShearedRay::new(o, d),
            t_max,
            best,
        )
    }

    /// [`TwoLevelAccel::closest_in_instance`] for the rays `inside` of a packet of world
    /// rays `rays` (their queries `best`, limits `limits`), walked as one packet of their
    /// own in the instance's object space: each ray is transformed as it would be alone, and
    /// a packet finds for each ray what it finds alone, so the hits are the same bits.
    fn closest_in_instance_packet(
        &self,
        placed: &Placed,
        rays: &[(Vec3A, Vec3A)],
        inside: &[u8],
        limits: &mut [f32; PACKET],
        best: &mut [Closest; PACKET],
        object: &mut ObjectPacket,
    ) {
        let mesh = &self.meshes[placed.mesh as usize];
        for (s, &r) in inside.iter().enumerate() {
            let (origin, direction) = rays[r as usize];
            let (o, d) = object_ray(&placed.object_from_world, origin, direction);
            object.object_rays[s] = (o, d);
            object.limits[s] = limits[r as usize];
        }
        ShearedRay::fill(&mut object.sheared, &object.object_rays[..inside.len()]);
        let within = Within {
            source_base: placed.source_base,
            instance: placed.index,
            reported: None,
        };
        object.packet.set(&object.object_rays[..inside.len()]);
        let ObjectPacket {
            packet,
            sheared,
            limits: object_limits,
            ..
        } = object;
        mesh.accel
            .wide
            .traverse_packet(packet, object_limits, |s, first, count, limit| {
                let r = inside[s] as usize;
                // A closure is not told the walk's copy: the four-lane pack tests, which
                // give the same bits as the eight-lane one.
                mesh.accel.closest_in_leaf::<false>(
                    &within,
                    &sheared[s],
                    first,
                    count,
                    limit,
                    &mut best[r],
                );
            });
        for (s, &r) in inside.iter().enumerate() {
            limits[r as usize] = object_limits[s];
        }
    }

    /// Visits every hit with `t` in `[0, t_max)` in the world tree and every instance as
    /// `visit(instance, slot, t)` (instance [`Hit::WORLD`] for the world tree) until
    /// `visit` returns false; returns false when it was stopped early.
    pub fn visit_hits(
        &self,
        world: &Accel,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        mut visit: impl FnMut(u32, u32, f32) -> bool,
    ) -> bool {
        let ray = RayBoxes::new(origin, direction);
        if !world.visit_hits_of(
            &ray,
            &ShearedRay::new(origin, direction),
            t_max,
            |slot, t| visit(Hit::WORLD, slot, t),
        ) {
            return false;
        }
        for top in &self.levels {
            let go_on =
                top.tlas
                    .traverse_unordered(&ray, t_max, |first: u32, _: u32, _: &mut f32| {
                        if !top.reaches(&ray, t_max) {
                            return true;
                        }
                        let placed = &top.placed[first as usize];
                        let (o, d) = object_ray(&placed.object_from_world, origin, direction);
                        self.meshes[placed.mesh as usize].accel.visit_hits(
                            o,
                            d,
                            t_max,
                            |slot, t| visit(placed.index, slot, t),
                        )
                    });
            if !go_on {
                return false;
            }
        }
        self.visit_hits_in_collapsed(origin, direction, t_max, visit)
    }

    /// [`TwoLevelAccel::visit_hits`] for a packet of up to [`PACKET`] rays (a tile's shadow
    /// rays toward one light): ray `r`'s hits with `t` in `[0, t_max[r])` are visited as
    /// `visit(r, instance, slot, t)` until `visit` returns false for that ray; returns the
    /// mask of the rays stopped early. In the order of [`TwoLevelAccel::visit_hits`]: the
    /// world tree walked by the packet ([`Accel::visit_hits_packet`]), then the top-level
    /// trees walked masked by the rays it did not stop, each instance entered by at least
    /// `INSTANCE_PACKET` of them as an object-space packet of its own (fewer one by one),
    /// then the collapsed instances ray by ray: each ray meets exactly the triangles it meets
    /// alone (or is stopped, as alone).
    pub fn visit_hits_packet(
        &self,
        world: &Accel,
        rays: &[(Vec3A, Vec3A)],
        t_max: &[f32],
        mut visit: impl FnMut(usize, u32, u32, f32) -> bool,
    ) -> u64 {
        let n = rays.len().min(t_max.len()).min(PACKET);
        let mut stopped = world.visit_hits_packet(&rays[..n], &t_max[..n], |r, slot, t| {
            visit(r, Hit::WORLD, slot, t)
        });
        let all = if n == PACKET { u64::MAX } else { (1 << n) - 1 };
        if stopped == all {
            return stopped;
        }
        // The rays the world tree did not stop walk the top-level trees masked (a stopped
        // ray's limit is negative: no walk takes it further).
        let mut boxes = [RayBoxes::default(); PACKET];
        let mut limits = [-1.0f32; PACKET];
        for r in 0..n {
            if stopped & (1 << r) == 0 {
                let (origin, direction) = rays[r];
                boxes[r] = RayBoxes::new(origin, direction);
                limits[r] = t_max[r];
            }
        }
        for top in &self.levels {
            let leaf = |entering: &[u8], first: u32, _: u32, limits: &mut [f32; PACKET]| {
                let placed = &top.placed[first as usize];
                let mesh = &self.meshes[placed.mesh as usize];
                let mut inside = [0u8; PACKET];
                let mut object_rays = [(Vec3A::ZERO, Vec3A::ZERO); PACKET];
                let mut object_limits = [0.0f32; PACKET];
                let mut k = 0;
                for &r in entering {
                    let r = r as usize;
                    // A one-leaf tree hands over every ray, the stopped ones too.
                    if limits[r] < 0.0 || !top.reaches(&boxes[r], t_max[r]) {
                        continue;
                    }
                    let (origin, direction) = rays[r];
                    inside[k] = r as u8;
                    object_rays[k] = object_ray(&placed.object_from_world, origin, direction);
                    object_limits[k] = t_max[r];
                    k += 1;
                }
                // Rays entering together walk the instance as a packet of their own (toward
                // a point light they converge in object space too), fewer one by one.
                let object_stopped = if k >= INSTANCE_PACKET {
                    mesh.accel.visit_hits_packet(
                        &object_rays[..k],
                        &object_limits[..k],
                        |s, slot, t| visit(inside[s] as usize, placed.index, slot, t),
                    )
                } else {
                    let mut object_stopped = 0u64;
                    for s in 0..k {
                        let (o, d) = object_rays[s];
                        let r = inside[s] as usize;
                        let clear = mesh.accel.visit_hits(o, d, object_limits[s], |slot, t| {
                            visit(r, placed.index, slot, t)
                        });
                        if !clear {
                            object_stopped |= 1 << s;
                        }
                    }
                    object_stopped
                };
                let mut bits = object_stopped;
                while bits != 0 {
                    let r = inside[bits.trailing_zeros() as usize] as usize;
                    bits &= bits - 1;
                    stopped |= 1 << r;
                    limits[r] = -1.0;
                }
            };
            top.tlas.traverse_masked(&boxes[..n], &mut limits, leaf);
        }
        for r in 0..n {
            if stopped & (1 << r) != 0 {
                continue;
            }
            let (origin, direction) = rays[r];
            if !self.visit_hits_in_collapsed(origin, direction, t_max[r], |i, slot, t| {
                visit(r, i, slot, t)
            }) {
                stopped |= 1 << r;
            }
        }
        stopped
    }

    /// The collapsed instances' part of [`TwoLevelAccel::visit_hits`] (walked last).
    fn visit_hits_in_collapsed(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        mut visit: impl FnMut(u32, u32, f32) -> bool,
    ) -> bool {
        self.levels.iter().flat_map(|l| &l.collapsed).all(|c| {
            c.accel.visit_hits(origin, direction, t_max, |slot, t| {
                visit(c.index, c.mesh_slot[slot as usize], t)
            })
        })
    }
}

/// A world ray in an instance's object space; the direction keeps the length the
/// transform gives it, so distances along the ray stay world distances.
#[inline]
fn object_ray(object_from_world: &Affine3A, origin: Vec3A, direction: Vec3A) -> (Vec3A, Vec3A) {
    (
        object_from_world.transform_point3a(origin),
        object_from_world.transform_vector3a(direction),
    )
}

/// The world box of an object box under `to_world` (its eight corners), grown by a few
/// ulps of its magnitude: the box is tested in world space, the triangles in object space,
/// and rounding of the transform must not let a hit on the box's edge slip past.
fn transformed_box(bounds: &Aabb, to_world: &Affine3A) -> Aabb {
    let mut out = Aabb::empty();
    for corner in 0..8 {
        let pick = |bit: usize, axis: usize| {
            if corner & bit != 0 {
                bounds.max[axis]
            } else {
                bounds.min[axis]
            }
        };
        let p = Vec3A::new(pick(1, 0), pick(2, 1), pick(4, 2));
        out.extend(to_world.transform_point3a(p));
    }
    let magnitude = out.min.abs().max(out.max.abs()).max_element();
    let pad = Vec3A::splat(magnitude * 2f32.powi(-18) + f32::MIN_POSITIVE * 8.0);
    Aabb::new(out.min - pad, out.max + pad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::intersect;
    use crate::accel::tests::{Rng, soup};
    use glam::{Quat, Vec3};

    fn random_mesh(rng: &mut Rng, n: usize) -> Vec<[Vec3A; 3]> {
        (0..n)
            .map(|_| {
                let c = rng.point(3.0);
                [c + rng.point(1.2), c + rng.point(1.2), c + rng.point(1.2)]
            })
            .collect()
    }

    /// Two random meshes of `sizes` triangles for instances to place, and a world tree over
    /// `world` random triangles whose source ids come after the instances' (1000 on).
    fn random_two_level(
        rng: &mut Rng,
        sizes: [usize; 2],
        world: usize,
    ) -> (TwoLevelAccel, FrameTriangles, Accel) {
        let meshes = sizes.map(|n| soup(&random_mesh(rng, n)));
        let two = TwoLevelAccel::new(meshes.into()).unwrap();
        let mut world_tris = soup(&random_mesh(rng, world));
        for s in world_tris.source.iter_mut() {
            *s += 1000;
        }
        let accel = Accel::build(&mut world_tris).unwrap();
        (two, world_tris, accel)
    }

    /// Two meshes placed five times each (rotated, scaled, mirrored) plus a world tree:
    /// every ray finds what testing every placed triangle in world space finds (the same
    /// triangle and instance; `t` within rounding of the transform).
    #[test]
    fn instances_find_what_their_world_space_triangles_find() {
        let mut rng = Rng(7);
        let (mut two, world_tris, world) = random_two_level(&mut rng, [40, 25], 30);
        let mut instances = Vec::new();
        for k in 0..10u32 {
            let m = k % 2;
            let scale = if k == 3 {
                Vec3::new(-1.5, 1.5, 1.5)
            } else {
                Vec3::splat(0.5 + 0.2 * k as f32)
            };
            instances.push(TlasInstance {
                index: k,
                mesh: m,
                world_from_object: Mat4::from_scale_rotation_translation(
                    scale,
                    Quat::from_rotation_y(k as f32) * Quat::from_rotation_x(0.3 * k as f32),
                    Vec3::from(rng.point(8.0)),
                ),
                source_base: 100 * k,
            });
        }
        // Half never move (their own top-level tree), half do.
        two.set_fixed_instances(&instances[..4]).unwrap();
        two.set_instances(&instances[4..]).unwrap();
        assert_eq!(two.instance_count(), 10);
        let (mut hits, mut rays) = (0, Vec::new());
        for r in 0..400 {
            let origin = rng.point(20.0);
            // Aimed near an instance's origin or the world tree's (most hit something).
            let aim = instances
                .get(r % (instances.len() + 1))
                .map_or(Vec3::ZERO, |i| i.world_from_object.w_axis.truncate());
            let direction = (Vec3A::from(aim) + rng.point(2.0) - origin).normalize();
            rays.push((origin, direction));
            // Brute force: every instance's triangles placed in world space.
            let mut expected: Option<(u32, u32, f32)> = None;
            let world_part = (
                world.triangles_in_slot_order(),
                world_tris.source.clone(),
                Hit::WORLD,
            );
            let placed_parts = instances.iter().enumerate().map(|(index, inst)| {
                let mesh = two.mesh_triangles(inst.mesh);
                let placed: Vec<[Vec3A; 3]> = (0..mesh.len() as u32)
                    .map(|k| two.mesh_triangle(inst.mesh, k))
                    .map(|t| t.map(|p| inst.world_from_object.transform_point3a(p)))
                    .collect();
                let ids: Vec<u32> = mesh.source.iter().map(|s| s + inst.source_base).collect();
                (placed, ids, index as u32)
            });
            for (tris, base, id) in std::iter::once(world_part).chain(placed_parts) {
                for (slot, tri) in tris.iter().enumerate() {
                    if let Some((t, _)) = intersect(tri, origin, direction)
                        && expected.is_none_or(|(_, _, best)| t < best)
                    {
                        expected = Some((id, base[slot], t));
                    }
                }
            }
            let found = two.closest_hit(&world, origin, direction, f32::INFINITY);
            match (expected, found) {
                (None, None) => {}
                (Some((id, _, t)), Some(hit)) => {
                    hits += 1;
                    assert_eq!(hit.instance, id, "ray {origin} {direction}");
                    assert!((hit.t - t).abs() <= 1e-4 * t.max(1.0), "t {} vs {t}", hit.t);
                }
                (e, f) => panic!("ray {origin} {direction}: expected {e:?}, found {f:?}"),
            }
            // Any-hit: some hit exactly when the closest-hit query finds one.
            let mut any = false;
            two.visit_hits(&world, origin, direction, f32::INFINITY, |_, _, _| {
                any = true;
                false
            });
            assert_eq!(any, found.is_some());
        }
        assert!(hits > 150, "only {hits} rays hit: the test shows little");
        // Packets answer as single rays.
        for chunk in rays.chunks(PACKET) {
            let mut packet = vec![None; chunk.len()];
            two.closest_hits(&world, chunk, f32::INFINITY, &mut packet);
            for (&(o, d), hit) in chunk.iter().zip(packet) {
                assert_eq!(hit, two.closest_hit(&world, o, d, f32::INFINITY));
            }
        }
    }

    /// Pinhole packets aimed at instances, so that whole packets (and parts of packets,
    /// below and above [`INSTANCE_PACKET`] rays) enter an instance together: each ray finds
    /// the same bits as alone, with one instance (no top-level boxes) and with many.
    #[test]
    fn rays_entering_an_instance_together_find_what_each_finds_alone() {
        let mut rng = Rng(11);
        let (mut two, _, world) = random_two_level(&mut rng, [60, 35], 30);
        let instances: Vec<TlasInstance> = (0..6u32)
            .map(|k| TlasInstance {
                index: k,
                mesh: k % 2,
                world_from_object: Mat4::from_scale_rotation_translation(
                    Vec3::splat(0.6 + 0.3 * k as f32) * if k == 4 { -1.0 } else { 1.0 },
                    Quat::from_rotation_z(0.7 * k as f32) * Quat::from_rotation_x(0.4),
                    Vec3::from(rng.point(6.0)),
                ),
                source_base: 100 * k,
            })
            .collect();
        let mut compared = 0;
        for set in [&instances[..1], &instances[..]] {
            two.set_instances(set).unwrap();
            for (k, inst) in set.iter().enumerate() {
                let aim = Vec3A::from(inst.world_from_object.w_axis.truncate());
                // Narrow packets (every ray in the instance's box) to wide ones (a few).
                for spread in [0.02f32, 0.1, 0.4, 1.5] {
                    let origin = aim + Vec3A::new(9.0, 4.0 - k as f32, 7.0);
                    let forward = (aim - origin).normalize();
                    let right = forward.cross(Vec3A::Y).normalize();
                    let up = right.cross(forward);
                    let rays: Vec<(Vec3A, Vec3A)> = (0..PACKET)
                        .map(|i| {
                            let (x, y) = ((i % 8) as f32 / 7.0 - 0.5, (i / 8) as f32 / 7.0 - 0.5);
                            let d = forward + (right * x + up * y) * spread;
                            (origin, d.normalize())
                        })
                        .collect();
                    let mut packet = vec![None; PACKET];
                    two.closest_hits(&world, &rays, f32::INFINITY, &mut packet);
                    for (i, (&(o, d), hit)) in rays.iter().zip(&packet).enumerate() {
                        let alone = two.closest_hit(&world, o, d, f32::INFINITY);
                        assert_eq!(*hit, alone, "instance {k}, spread {spread}, ray {i}");
                        compared += hit.is_some_and(|h| h.instance != Hit::WORLD) as usize;
                    }
                }
            }
        }
        assert!(compared > 300, "only {compared} rays hit an instance");
    }

    /// Bounce packets (scattered origins; a plane mirror's rays through one apex) and shadow
    /// packets (scattered origins toward a point light, a patch of origins toward a light
    /// behind an instance, a directional light) over one fixed instance (no top-level
    /// boxes), five moving ones (one mirrored) and a collapsed one: each ray finds the same
    /// closest hit as alone, and meets the same triangles (or is stopped, as alone).
    #[test]
    fn scattered_and_shadow_packets_find_what_each_ray_finds_alone() {
        let mut rng = Rng(23);
        let (mut two, _, world) = random_two_level(&mut rng, [50, 30], 40);
        let place = |k: u32, world_from_object| TlasInstance {
            index: k,
            mesh: k % 2,
            world_from_object,
            source_base: 100 * k,
        };
        let moving: Vec<TlasInstance> = (1..6u32)
            .map(|k| {
                place(
                    k,
                    Mat4::from_scale_rotation_translation(
                        Vec3::splat(0.5 + 0.25 * k as f32) * if k == 3 { -1.0 } else { 1.0 },
                        Quat::from_rotation_y(0.9 * k as f32) * Quat::from_rotation_x(0.2),
                        Vec3::from(rng.point(7.0)),
                    ),
                )
            })
            .chain([place(6, Mat4::from_scale(Vec3::new(1.0, 1.0, 0.0)))])
            .collect();
        let fixed = [place(0, Mat4::from_translation(Vec3::new(2.0, -1.0, 1.0)))];
        two.set_fixed_instances(&fixed).unwrap();
        two.set_instances(&moving).unwrap();
        let centres: Vec<Vec3A> = fixed
            .iter()
            .chain(&moving)
            .map(|i| Vec3A::from(i.world_from_object.w_axis.truncate()))
            .collect();

        // Closest hits.
        let mut bounce_sets: Vec<Vec<(Vec3A, Vec3A)>> = Vec::new();
        for round in 0..12 {
            let scattered = (0..PACKET - round)
                .map(|i| {
                    let origin = rng.point(12.0);
                    let aim = centres[i % centres.len()] + rng.point(2.0);
                    (origin, (aim - origin).normalize())
                })
                .collect();
            bounce_sets.push(scattered);
            // A plane mirror's rays: lines through an apex behind the plane y = -8.
            let apex = Vec3A::new(0.0, -14.0, 0.0) + rng.point(2.0);
            let aim = centres[round % centres.len()];
            let mirrored = (0..PACKET)
                .map(|i| {
                    let (x, z) = ((i % 8) as f32 / 7.0 - 0.5, (i / 8) as f32 / 7.0 - 0.5);
                    let through = aim + Vec3A::new(x, 0.0, z) * (1.0 + round as f32);
                    let d = (through - apex).normalize();
                    (apex + d * ((-8.0 - apex.y) / d.y), d)
                })
                .collect();
            bounce_sets.push(mirrored);
        }
        let (mut compared, mut on_instances) = (0, 0);
        for rays in &bounce_sets {
            let mut hits = vec![None; rays.len()];
            two.closest_hits_scattered(&world, rays, f32::INFINITY, &mut hits);
            for (i, (&(o, d), hit)) in rays.iter().zip(&hits).enumerate() {
                assert_eq!(
                    *hit,
                    two.closest_hit(&world, o, d, f32::INFINITY),
                    "ray {i}"
                );
                compared += hit.is_some() as usize;
                on_instances += hit.is_some_and(|h| h.instance != Hit::WORLD) as usize;
            }
        }
        assert!(
            compared > 600 && on_instances > 300,
            "{compared} hits, {on_instances} on instances"
        );

        // Any hits: a triangle whose slot is even stops the ray (opaque), the
        // others are let through (glass) and listed.
        let opaque = |slot: u32| slot.is_multiple_of(2);
        let alone = |o: Vec3A, d: Vec3A, t_max: f32| {
            let mut met = Vec::new();
            let clear = two.visit_hits(&world, o, d, t_max, |instance, slot, _| {
                met.push((instance, slot));
                !opaque(slot)
            });
            met.sort_unstable();
            (clear, met)
        };
        // Each set: its rays and their limits.
        type ShadowSet = (Vec<(Vec3A, Vec3A)>, Vec<f32>);
        let mut shadow_sets: Vec<ShadowSet> = Vec::new();
        for round in 0..12 {
            let light = centres[round % centres.len()] + Vec3A::new(0.5, 6.0, -0.5);
            let towards = |o: Vec3A| {
                let to = light - o;
                ((o, to.normalize()), to.length() * 0.999)
            };
            // Scattered origins, and a small patch of origins below the instance.
            let scattered: (Vec<_>, Vec<_>) = (0..PACKET).map(|_| towards(rng.point(12.0))).unzip();
            let below = centres[round % centres.len()] - Vec3A::new(0.0, 5.0, 0.0);
            let patch: (Vec<_>, Vec<_>) = (0..PACKET)
                .map(|i| {
                    let (x, z) = ((i % 8) as f32 / 7.0 - 0.5, (i / 8) as f32 / 7.0 - 0.5);
                    towards(below + Vec3A::new(x, 0.0, z) * 0.8)
                })
                .unzip();
            let sun = Vec3A::new(0.2, 1.0, -0.1).normalize();
            let directional = (
                (0..PACKET / 2).map(|_| (rng.point(10.0), sun)).collect(),
                vec![f32::INFINITY; PACKET / 2],
            );
            shadow_sets.extend([scattered, patch, directional]);
        }
        let (mut stopped_rays, mut clear_rays, mut met_instances) = (0, 0, 0);
        for (rays, t_max) in &shadow_sets {
            let mut met = vec![Vec::new(); rays.len()];
            let stopped = two.visit_hits_packet(&world, rays, t_max, |r, instance, slot, _| {
                met[r].push((instance, slot));
                !opaque(slot)
            });
            for (r, (&(o, d), &limit)) in rays.iter().zip(t_max).enumerate() {
                let (clear, expected) = alone(o, d, limit);
                assert_eq!(stopped & (1 << r) == 0, clear, "ray {r}: {o} {d}");
                met_instances += expected.iter().filter(|m| m.0 != Hit::WORLD).count();
                if clear {
                    clear_rays += 1;
                    met[r].sort_unstable();
                    assert_eq!(met[r], expected, "ray {r}: {o} {d}");
                } else {
                    stopped_rays += 1;
                }
            }
        }
        assert!(
            stopped_rays > 300 && clear_rays > 300 && met_instances > 300,
            "{stopped_rays} stopped, {clear_rays} clear, {met_instances} instance hits met"
        );
    }

    #[test]
    fn collapsed_instances_are_hit_in_world_space_and_empty_ones_left_out() {
        let tri = [Vec3A::ZERO, Vec3A::X, Vec3A::Y];
        let mut two = TwoLevelAccel::new(vec![soup(&[tri]), soup(&[])]).unwrap();
        let world = Accel::default();
        // Instance k: index k, source base k.
        let instance = |k: u32, mesh, world_from_object| TlasInstance {
            index: k,
            mesh,
            world_from_object,
            source_base: k,
        };
        let instances = [
            // Flattened along its own normal: still a triangle, seen from +z.
            instance(0, 0, Mat4::from_scale(Vec3::new(2.0, 2.0, 0.0))),
            instance(1, 1, Mat4::IDENTITY),
            instance(2, 0, Mat4::from_translation(Vec3::new(0.0, 0.0, -2.0))),
            // Flattened within its plane: a segment, never hit.
            instance(3, 0, Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0))),
        ];
        two.set_instances(&instances).unwrap();
        assert_eq!(two.instance_count(), 3);
        let trace = |two: &TwoLevelAccel, origin| {
            two.closest_hit(&world, origin, Vec3A::NEG_Z, f32::INFINITY)
        };
        let near = trace(&two, Vec3A::new(0.2, 0.2, 5.0)).unwrap();
        assert_eq!((near.instance, near.triangle), (0, 0));
        assert!((near.t - 5.0).abs() < 1e-5);
        // Only the collapsed instance covers (1.2, 0.2): the translated one ends at x + y = 1.
        let far_only = trace(&two, Vec3A::new(1.2, 0.2, 5.0)).unwrap();
        assert_eq!(far_only.instance, 0);
        let mut packet = [None; 2];
        let rays = [
            (Vec3A::new(0.2, 0.2, 5.0), Vec3A::NEG_Z),
            (Vec3A::new(0.2, 0.2, -1.0), Vec3A::NEG_Z),
        ];
        two.closest_hits(&world, &rays, f32::INFINITY, &mut packet);
        assert_eq!(packet[0], Some(near));
        assert_eq!(packet[1].map(|h| h.instance), Some(2));
        let mut seen = Vec::new();
        two.visit_hits(
            &world,
            Vec3A::new(0.2, 0.2, 5.0),
            Vec3A::NEG_Z,
            f32::INFINITY,
            |i, _, _| {
                seen.push(i);
                true
            },
        );
        seen.sort_unstable();
        assert_eq!(seen, [0, 2]);
        two.set_instances(&[]).unwrap();
        assert!(trace(&two, Vec3A::ZERO).is_none());
        // An overflowing transform is reported (by index), not built into the tree.
        let overflow = instance(7, 0, Mat4::from_scale(Vec3::splat(f32::MAX)));
        let nan = instance(8, 0, Mat4::from_translation(Vec3::splat(f32::NAN)));
        assert_eq!(two.set_instances(&[instances[2], overflow]), Err(7));
        assert_eq!(two.set_fixed_instances(&[nan]), Err(8));
        assert_eq!(two.instance_count(), 0);
    }
}
