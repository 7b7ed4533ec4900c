//! Whitted ray tracing: ambient + Lambert / Blinn-Phong direct light from every light with
//! shadow rays, mirror reflection, refraction with Fresnel and total internal reflection.
//! Materials follow one of two models (`render::ShadingModel`): energy-weighted lobes
//! (glTF-style) or the additive NFF/Whitted convention.
//!
//! Every ray carries its LOD method's state (`lod::RayLod`: the path length for `paper`, a
//! cone, or differentials); at a textured hit the method turns it into a texture lookup. The
//! integrator is generic over that state, so each method pays only for its own.
//!
//! Shading a hit is split in two steps so that a tile can trace its rays breadth first
//! (`render::tile`): `FrameScene::arrive` makes the surface, looks up the texture and asks
//! for the shadow rays (`ShadowRequest`); once those are traced, `FrameScene::finish`
//! sums the direct light and spawns the reflected and refracted rays, and records how the
//! hit's radiance combines with theirs (`Combine`). Evaluated bottom up, `Combine` performs
//! the same floating-point operations in the same order as a depth-first recursion would
//! (`color += weight * child`, the glass terms summed from zero before they are added), so
//! the image does not depend on the order in which rays are traced.

use glam::{Vec2, Vec3, Vec3A};

use crate::accel::Hit;
use crate::geometry::HitTriangle;
use crate::lod::{Footprint, KeptTriangle, LodCamera, LodMethod, RayLod, SurfaceHit, finite_level};
use crate::render::light::{Incident, Light};
use crate::render::material::{Material, ShadingModel};
use crate::render::ray_log::{RayClass, RayLog};
use crate::render::scene_bvh::SceneBvh;
use crate::render::surface::{SurfacePoint, dielectric_fresnel, interpolate_uv, reflect};
use crate::texture::{MipFilter, MipPyramid, PlannedLookup, Sampler, Texture};

/// Histogram bins for texture lookups per integer MIP level (textures up to 32768^2).
pub const MIP_LEVELS: usize = 16;

/// Secondary rays whose contribution weight falls below this are not traced.
const MIN_WEIGHT: f32 = 1e-3;

/// Glass surfaces a shadow ray passes through before it counts as blocked (a fixed bound
/// keeps the per-ray state on the stack).
pub(super) const MAX_SHADOW_GLASS: usize = 16;

/// Ambient radiance (linear RGB) reflected by every diffuse surface.
const AMBIENT: Vec3A = Vec3A::splat(0.03);

/// Counters gathered while tracing; summed per tile, then per frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceCounters {
    /// Every ray traced: primary, shadow, reflection, refraction.
    pub rays: u64,
    /// Texture lookups per integer level (floor of the clamped level).
    pub mip_histogram: [u64; MIP_LEVELS],
    /// Samples whose radiance came out non-finite and were replaced by black.
    pub nonfinite_samples: u64,
    /// Every ray traced, when the render records them (`film::render_image_recording`).
    pub log: Option<RayLog>,
}

impl Default for TraceCounters {
    fn default() -> Self {
        TraceCounters {
            rays: 0,
            mip_histogram: [0; MIP_LEVELS],
            nonfinite_samples: 0,
            log: None,
        }
    }
}

impl TraceCounters {
    /// Counters that also record every ray.
    pub fn recording() -> TraceCounters {
        TraceCounters {
            log: Some(RayLog::default()),
            ..TraceCounters::default()
        }
    }

    /// Adds `other`'s counts (and appends its recorded rays after these).
    pub fn add(&mut self, other: &TraceCounters) {
        self.rays += other.rays;
        self.nonfinite_samples += other.nonfinite_samples;
        for (a, b) in self.mip_histogram.iter_mut().zip(other.mip_histogram) {
            *a += b;
        }
        if let (Some(log), Some(more)) = (&mut self.log, &other.log) {
            log.rays.extend_from_slice(&more.rays);
        }
    }
}

/// Everything the integrator reads for one frame.
pub struct FrameScene<'a> {
    /// What rays are traced against.
    pub bvh: SceneBvh<'a>,
    pub materials: &'a [Material],
    pub textures: &'a [Texture],
    pub lights: &'a [Light],
    pub background: Vec3A,
    /// Scene ambient light for additive materials (AFF `am`).
    pub additive_ambient: Vec3A,
    pub lod: LodMethod,
    /// Added to every MIP-mapped level (`--lod-bias`; not to `none`).
    pub lod_bias: f32,
    /// How every texture's levels are read (`--mip-filter`); `None`: as its sampler says.
    pub mip_filter: Option<MipFilter>,
    /// The camera constants primary rays' LOD state starts from.
    pub lod_camera: LodCamera,
    pub max_depth: u32,
}

/// A ray a shaded hit spawns, waiting to be traced.
#[derive(Clone, Copy)]
pub(super) struct Spawned<L> {
    pub(super) class: RayClass,
    /// Pixel index (`y * width + x`) of the sample the ray serves, for the ray log (in
    /// the padding after `class` for the cheap LOD states: 48 bytes as before).
    pub(super) pixel: u32,
    pub(super) origin: Vec3A,
    pub(super) direction: Vec3A,
    pub(super) lod: L,
}

/// A hit's base-colour lookup, decided on arrival (see `FrameScene::texel_lookup`) and
/// filtered when the hit is finished.
#[derive(Clone, Copy)]
enum TexelLookup {
    /// No texture: white.
    Untextured,
    /// A bilinear or trilinear lookup in texture `texture`, its taps computed (`none`,
    /// `paper` and every method that picks one level). Made only by
    /// `FrameScene::texel_lookup`, always on the pyramid of `texture` in the scene that
    /// filters it: the filter reads the taps without bounds checks on that promise.
    Planned { texture: u32, plan: PlannedLookup },
    /// An anisotropic lookup (`Footprint::Anisotropic` at the biased `level`, which the
    /// lookup clamps), made in full when filtered.
    Anisotropic {
        texture: u32,
        uv: Vec2,
        level: f32,
        axis: Vec2,
        taps: u32,
    },
    /// An EWA lookup (`Footprint::Elliptical` at the biased `level`, which the lookup
    /// clamps), made in full when filtered.
    Elliptical {
        texture: u32,
        uv: Vec2,
        level: f32,
        major: Vec2,
        minor: Vec2,
    },
}

/// A hit whose surface is made and texture lookup planned, waiting for its shadow rays.
pub(super) struct Arrival<L: RayLod> {
    hit: Hit,
    /// What `reflect` and `refract` of the LOD method read of the triangle (nothing for
    /// `none` and `paper`).
    triangle: L::Kept,
    surface: SurfacePoint,
    /// Direction of the ray that arrived.
    direction: Vec3A,
    /// The ray's LOD state after `arrive`.
    lod: L,
    material: u32,
    /// The hit's base-colour lookup, decided on arrival and filtered in `finish`.
    lookup: TexelLookup,
    /// Bounces before this hit.
    depth: u32,
}

impl<L: RayLod> Arrival<L> {
    /// The arrival at `hit` on `triangle` of a ray from `origin` along `direction` carrying
    /// `lod` after `depth` bounces, its surface made but not the rest:
    /// [`FrameScene::arrive_at`] moves its LOD state and plans its lookup, in place.
    ///
    /// Why in place: an arrival made on the stack and then pushed onto a tile's list (208
    /// bytes a waiting hit for `paper`) was copied field by field from where its values had
    /// been spilled across the lookup's planning and the shadow requests: 59 instructions a
    /// hit, 2.4% of a BART Kitchen frame's. Written where it is kept, each value is stored
    /// once, when it is made. The surface is made here, before the push, from values at
    /// hand: made in place after a placeholder, each of its fields was stored twice.
    #[inline(always)]
    pub(super) fn unmade(
        triangle: &HitTriangle,
        hit: Hit,
        origin: Vec3A,
        direction: Vec3A,
        lod: L,
        depth: u32,
    ) -> Arrival<L> {
        Arrival {
            hit,
            triangle: L::Kept::keep(triangle),
            surface: SurfacePoint::at(triangle, &hit, origin, direction),
            direction,
            lod,
            material: triangle.material,
            lookup: TexelLookup::Untextured,
            depth,
        }
    }
}

/// A shadow ray a hit asks for toward one light, and (once traced) what reaches it.
#[derive(Clone, Copy)]
pub(super) struct ShadowRequest {
    /// The light, and what it sends toward the hit.
    pub(super) light: u32,
    pub(super) incident: Incident,
    /// `shading normal . to_light`.
    pub(super) cos: f32,
    /// The ray: origin, direction (`incident.to_light`) and search distance; `None` when
    /// the light is closer than the lift off the surface (nothing can shadow it).
    pub(super) ray: Option<(Vec3A, f32)>,
    /// What reaches the hit: filled by the tracer ([`shadow_transmittance`]).
    pub(super) transmittance: Vec3A,
}

/// How one path vertex's radiance is made from its children's: `radiance` starts as the
/// hit's own light and each step adds `weight * child` (a grouped run of steps is first
/// summed from zero, then added, as the glass term is).
///
/// One cache line: a tile keeps a vertex for each of its rays but shadow rays (a few
/// thousand), written as each hit is finished and read back when the tile combines them,
/// after its walks have evicted most of them. So the vectors are kept as three floats (the
/// arithmetic is `Vec3A`'s, on the same three lanes: the same bits).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Combine {
    radiance: Vec3,
    count: u8,
    /// Index of the first grouped step (`count` when none is), and whether a group exists
    /// (a glass term whose two branches were both below the weight limit still adds zero).
    group_from: u8,
    has_group: bool,
    steps: [Step; 3],
}

const _: () = assert!(std::mem::size_of::<Combine>() == 64, "a vertex in one line");

#[derive(Clone, Copy, Debug, Default)]
struct Step {
    weight: Vec3,
    child: u32,
}

impl Combine {
    /// A vertex with no radiance yet (a child's place before its hit is finished).
    pub(super) const EMPTY: Combine = Combine {
        radiance: Vec3::ZERO,
        count: 0,
        group_from: 0,
        has_group: false,
        steps: [Step {
            weight: Vec3::ZERO,
            child: 0,
        }; 3],
    };

    /// A vertex whose radiance is `radiance` alone (a miss: the background).
    #[inline]
    pub(super) fn leaf(radiance: Vec3A) -> Combine {
        Combine {
            radiance: radiance.into(),
            ..Combine::EMPTY
        }
    }

    /// Makes this vertex a leaf whose radiance is `radiance`, in place: its radiance and
    /// its step counts are stored where they live, and the steps are left as they are
    /// (none is read past `count`).
    ///
    /// Why not `*self = Combine::leaf(radiance)`: the compiler built that vertex on the
    /// stack and copied it with 32-byte loads that read back the narrow fields it had just
    /// stored there, at other offsets, which the CPU cannot forward (one load stalled on
    /// each finished hit: 3% of a BART Kitchen frame's samples).
    #[inline(always)]
    pub(super) fn make_leaf(&mut self, radiance: Vec3A) {
        self.radiance = radiance.into();
        self.count = 0;
        self.group_from = 0;
        self.has_group = false;
    }

    /// The vertex's radiance: its own light until [`Combine::evaluate`]'s sum is stored.
    #[inline]
    pub(super) fn radiance(&self) -> Vec3A {
        self.radiance.into()
    }

    #[inline]
    pub(super) fn set_radiance(&mut self, radiance: Vec3A) {
        self.radiance = radiance.into();
    }

    fn add(&mut self, weight: Vec3A, child: u32) {
        self.steps[self.count as usize] = Step {
            weight: weight.into(),
            child,
        };
        self.count += 1;
    }

    fn begin_group(&mut self) {
        self.group_from = self.count;
        self.has_group = true;
    }

    /// The vertex's radiance from its children's (`radiance_of(child)`), in the order and
    /// grouping of the depth-first recursion.
    #[inline]
    pub(super) fn evaluate(&self, radiance_of: impl Fn(u32) -> Vec3A) -> Vec3A {
        let mut color = self.radiance();
        let group_from = if self.has_group {
            self.group_from
        } else {
            self.count
        };
        for step in &self.steps[..group_from as usize] {
            color += Vec3A::from(step.weight) * radiance_of(step.child);
        }
        if self.has_group {
            let mut group = Vec3A::ZERO;
            for step in &self.steps[group_from as usize..self.count as usize] {
                group += Vec3A::from(step.weight) * radiance_of(step.child);
            }
            color += group;
        }
        color
    }
}

impl FrameScene<'_> {
    /// The hit triangle in world space (the hit's distance and barycentrics made those of
    /// that triangle, see `scene_bvh`).
    #[inline]
    pub fn hit_triangle(&self, hit: &mut Hit, origin: Vec3A, direction: Vec3A) -> HitTriangle {
        self.bvh.hit_triangle(hit, origin, direction)
    }

    /// [`FrameScene::hit_triangle`] appended to `triangles`, written in place (see
    /// [`HitTriangle::UNSET`] for why); returns it.
    #[inline(always)]
    pub fn push_hit_triangle<'t>(
        &self,
        hit: &mut Hit,
        origin: Vec3A,
        direction: Vec3A,
        triangles: &'t mut Vec<HitTriangle>,
    ) -> &'t HitTriangle {
        triangles.push(HitTriangle::UNSET);
        let out = triangles.last_mut().expect("a triangle was just pushed");
        self.bvh.write_hit_triangle(hit, origin, direction, out);
        out
    }

    /// Radiance of the primary ray through film point `(px, py)` of `camera`, traced depth
    /// first one ray at a time (its shadow rays too), with the LOD state of method `L`: the
    /// reference the film's breadth-first tiles are tested against (they must agree bit for
    /// bit). It allocates per hit, and its texture lookups run in the baseline SIMD copy
    /// (the same bits as the AVX2 copy the tiles use where the CPU has it); the film does
    /// not use it.
    pub fn primary_radiance<L: RayLod>(
        &self,
        camera: &crate::render::Camera,
        px: f32,
        py: f32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let direction = camera.primary_direction(px, py);
        let lod = L::primary(&self.lod_camera, px, py);
        self.radiance_depth_first(camera.eye, direction, lod, 0, counters)
    }

    /// Radiance arriving at `origin` from `direction` (see [`Self::primary_radiance`]).
    fn radiance_depth_first<L: RayLod>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        counters.rays += 1;
        let Some(hit) = self.bvh.closest_hit(origin, direction, f32::INFINITY) else {
            return self.background;
        };
        let mut requests = Vec::new();
        let arrival = self.arrive(hit, origin, direction, lod, depth, &mut requests, counters);
        for request in &mut requests {
            let Some((from, t_max)) = request.ray else {
                continue;
            };
            let mut glass = [(0.0f32, 0u32, 0u32); MAX_SHADOW_GLASS];
            let mut met = 0;
            let clear =
                self.bvh
                    .visit_hits(from, request.incident.to_light, t_max, |t, m, source| {
                        if !self.passes_through(m, met) {
                            return false;
                        }
                        glass[met] = (t, source, m);
                        met += 1;
                        true
                    });
            request.transmittance = self.shadow_transmittance(!clear, &mut glass[..met]);
        }
        let mut spawned = Vec::new();
        let mut combine = Combine::EMPTY;
        // The pixel only labels the spawned rays for the tile's ray log, unused here.
        self.finish::<L, false>(&arrival, &requests, 0, 0, &mut spawned, &mut combine);
        let children: Vec<Vec3A> = spawned
            .iter()
            .map(|s| self.radiance_depth_first(s.origin, s.direction, s.lod, depth + 1, counters))
            .collect();
        combine.evaluate(|child| children[child as usize])
    }

    /// The method's level with the bias, and the level the pyramid lookup reads (what it
    /// makes of [`Self::lookup_level`] by clamping).
    pub(super) fn biased_level(&self, footprint: &Footprint, pyramid: &MipPyramid) -> (f32, f32) {
        match footprint {
            Footprint::Base => (0.0, 0.0),
            f => (
                finite_level(f.level() + self.lod_bias),
                clamped_biased_level(f.level(), self.lod_bias, pyramid),
            ),
        }
    }

    /// The level a lookup asks for: the method's level plus the bias, not clamped. Every
    /// lookup of a pyramid clamps its level itself, to the second value of
    /// [`Self::biased_level`] (the same bits, see [`clamped_biased_level`]), so a hit's level
    /// is clamped once, by the lookup.
    #[inline(always)]
    fn lookup_level(&self, footprint: &Footprint) -> f32 {
        match footprint {
            Footprint::Base => 0.0,
            f => f.level() + self.lod_bias,
        }
    }

    /// Makes the surface of a hit (of a ray from `origin` along `direction` carrying `lod`,
    /// after `depth` bounces), looks up its texture and appends the shadow rays its direct
    /// light needs to `requests` (in light order).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn arrive<L: RayLod>(
        &self,
        mut hit: Hit,
        origin: Vec3A,
        direction: Vec3A,
        lod: L,
        depth: u32,
        requests: &mut Vec<ShadowRequest>,
        counters: &mut TraceCounters,
    ) -> Arrival<L> {
        let triangle = self.hit_triangle(&mut hit, origin, direction);
        let mut arrival = Arrival::unmade(&triangle, hit, origin, direction, lod, depth);
        self.arrive_at::<L, false>(&triangle, &mut arrival, None, requests, counters);
        arrival
    }

    /// [`Self::arrive`] in place: makes `arrival` ([`Arrival::unmade`] from `triangle`, the
    /// hit's triangle as `FrameScene::hit_triangle` read it, which also settled the hit).
    /// The texture lookup is planned in the SIMD copy `AVX2` names:
    /// the caller's own (true only in the AVX2 copy, as in `simd::Kernel::run`).
    /// `level_ahead`: the method's level at this hit, computed when the walk returned it
    /// (only where [`RayLod::LEVEL_AT_DISTANCE`]; the same bits as its footprint's).
    // Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
    #[inline(always)]
    pub(super) fn arrive_at<L: RayLod, const AVX2: bool>(
        &self,
        triangle: &HitTriangle,
        arrival: &mut Arrival<L>,
        level_ahead: Option<f32>,
        requests: &mut Vec<ShadowRequest>,
        counters: &mut TraceCounters,
    ) {
        let (hit, direction) = (arrival.hit, arrival.direction);
        let lod_hit = arrival.surface.lod_hit(triangle, &hit, direction);
        arrival.lod.arrive(&lod_hit);
        let material = &self.materials[triangle.material as usize];
        self.texel_lookup::<L, AVX2>(
            &lod_hit,
            material,
            &arrival.lod,
            level_ahead,
            counters,
            &mut arrival.lookup,
        );
        let lit = match material.model {
            // The energy-weighted model lights only what is not fully transmissive.
            ShadingModel::EnergyWeighted => 1.0 - material.transmission > 0.0,
            ShadingModel::Additive { .. } => true,
        };
        if lit {
            self.request_shadows(&arrival.surface, requests, counters);
        }
    }

    /// The shadow ray toward every light that shines on the surface's side.
    // Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
    #[inline(always)]
    fn request_shadows(
        &self,
        surface: &SurfacePoint,
        requests: &mut Vec<ShadowRequest>,
        counters: &mut TraceCounters,
    ) {
        for (l, light) in self.lights.iter().enumerate() {
            let Some(incident) = light.incident(surface.position) else {
                continue;
            };
            if !surface.faces(incident.to_light) {
                continue;
            }
            counters.rays += 1;
            requests.push(ShadowRequest {
                light: l as u32,
                incident,
                cos: surface.shading_normal.dot(incident.to_light),
                ray: surface.shadow_ray(incident.distance),
                transmittance: Vec3A::ONE,
            });
        }
    }

    /// Sums the hit's own light (its shadow rays traced, `requests` as `arrive` appended
    /// them) and spawns the reflected and refracted rays: writes the vertex's [`Combine`]
    /// into `combine` (in place, where the caller keeps it), whose steps name the spawned
    /// rays as `first_child`, `first_child + 1`, ... in the order they are appended to
    /// `spawned` (after the rays it already holds), each labelled with the sample's `pixel`.
    /// The texture lookup is filtered in the SIMD copy `AVX2` names (as in
    /// [`Self::arrive_at`]).
    // Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
    #[inline(always)]
    pub(super) fn finish<L: RayLod, const AVX2: bool>(
        &self,
        arrival: &Arrival<L>,
        requests: &[ShadowRequest],
        first_child: u32,
        pixel: u32,
        spawned: &mut Vec<Spawned<L>>,
        combine: &mut Combine,
    ) {
        let material = &self.materials[arrival.material as usize];
        let surface = &arrival.surface;
        let direction = arrival.direction;
        let lod_hit = surface.lod_hit(arrival.triangle.triangle(), &arrival.hit, direction);
        let mut children = Children {
            first: first_child,
            pixel,
            before: spawned.len(),
            spawned,
        };
        match material.model {
            ShadingModel::EnergyWeighted => {
                let albedo = Vec3A::from(material.base_color) * self.texel::<AVX2>(&arrival.lookup);
                let opaque = 1.0 - material.transmission;
                let mut color = Vec3A::ZERO;
                if opaque > 0.0 {
                    let diffuse = albedo * (opaque * (1.0 - material.reflectance));
                    color += direct_light(surface, direction, diffuse, material, opaque, requests);
                    color += AMBIENT * diffuse;
                }
                combine.make_leaf(color);
                if arrival.depth >= self.max_depth {
                    return;
                }
                let mirror = opaque * material.reflectance;
                if mirror > MIN_WEIGHT {
                    let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
                    let lod = arrival.lod.reflect(&lod_hit, reflected);
                    let child = children.spawn(RayClass::Reflection, surface, reflected, lod);
                    combine.add(albedo * mirror, child);
                }
                if material.transmission > MIN_WEIGHT {
                    self.transmit(&lod_hit, arrival, albedo, material, &mut children, combine);
                }
            }
            ShadingModel::Additive { ambient } => {
                let texel = self.texel::<AVX2>(&arrival.lookup);
                let diffuse = Vec3A::from(material.base_color) * texel;
                let ambient = Vec3A::from(ambient) * texel;
                let mut color = self.additive_ambient * ambient;
                color += direct_light(surface, direction, diffuse, material, 1.0, requests);
                combine.make_leaf(color);
                if arrival.depth >= self.max_depth {
                    return;
                }
                if material.reflectance > MIN_WEIGHT {
                    let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
                    let lod = arrival.lod.reflect(&lod_hit, reflected);
                    let child = children.spawn(RayClass::Reflection, surface, reflected, lod);
                    combine.add(Vec3A::splat(material.reflectance), child);
                }
                if material.transmission > MIN_WEIGHT {
                    let r = surface.refraction(direction, material.ior);
                    let child = match r.transmitted {
                        Some((refracted, _)) => {
                            let lod = arrival.lod.refract(&lod_hit, r.eta, refracted);
                            let far = surface.far_side();
                            children.spawn(RayClass::Refraction, &far, refracted, lod)
                        }
                        None => {
                            let reflected =
                                reflect(direction, surface.shading_normal, surface.face_normal);
                            let lod = arrival.lod.reflect(&lod_hit, reflected);
                            children.spawn(RayClass::Reflection, surface, reflected, lod)
                        }
                    };
                    combine.add(Vec3A::splat(material.transmission), child);
                }
            }
        }
    }

    /// Glass: Fresnel-weighted reflection plus refraction tinted by the albedo; total
    /// internal reflection sends everything to the reflection.
    fn transmit<L: RayLod>(
        &self,
        lod_hit: &SurfaceHit,
        arrival: &Arrival<L>,
        albedo: Vec3A,
        material: &Material,
        children: &mut Children<L>,
        combine: &mut Combine,
    ) {
        let surface = &arrival.surface;
        let direction = lod_hit.direction;
        let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
        let weight = material.transmission;
        let r = surface.refraction(direction, material.ior);
        let Some((refracted, cos_t)) = r.transmitted else {
            let lod = arrival.lod.reflect(lod_hit, reflected);
            let child = children.spawn(RayClass::Reflection, surface, reflected, lod);
            combine.add(Vec3A::splat(weight), child);
            return;
        };
        let fresnel = dielectric_fresnel(r.cos_i, cos_t, r.eta);
        combine.begin_group();
        if weight * fresnel > MIN_WEIGHT {
            let lod = arrival.lod.reflect(lod_hit, reflected);
            let child = children.spawn(RayClass::Reflection, surface, reflected, lod);
            combine.add(Vec3A::splat(weight * fresnel), child);
        }
        if weight * (1.0 - fresnel) > MIN_WEIGHT {
            let lod = arrival.lod.refract(lod_hit, r.eta, refracted);
            let child = children.spawn(RayClass::Refraction, &surface.far_side(), refracted, lod);
            combine.add(albedo * (weight * (1.0 - fresnel)), child);
        }
    }

    /// Decides the base-colour lookup at a hit (its texture, coordinates and level; none
    /// when untextured) into `out` and hints the cache to load the texels it will read.
    /// Written in place, as its arrival is (`Arrival::unmade`): returned, a plan was copied
    /// into the arrival from the stack, 21 instructions a hit.
    ///
    /// Why the lookup is split from its filtering: a hit's texel is needed only when the
    /// hit is finished, after the tile's shadow rays are traced, and its texels are
    /// scattered over textures of megabytes, so reading them on arrival stalled on cache
    /// misses (the texel loads were the hottest lines of a BART Kitchen frame). Decided
    /// here and filtered in `finish`, with the same inputs and the same function, the
    /// result is the same bits and the misses overlap the shadow rays.
    // Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
    #[inline(always)]
    fn texel_lookup<L: RayLod, const AVX2: bool>(
        &self,
        lod_hit: &SurfaceHit,
        material: &Material,
        lod: &L,
        level_ahead: Option<f32>,
        counters: &mut TraceCounters,
        out: &mut TexelLookup,
    ) {
        let Some((t, texture)) = material
            .base_color_texture
            .and_then(|t| Some((t as u32, self.textures.get(t)?)))
        else {
            *out = TexelLookup::Untextured;
            return;
        };
        let uv = interpolate_uv(lod_hit.triangle.uvs, lod_hit.bary);
        let pyramid = &texture.pyramid;
        let footprint = match level_ahead {
            Some(level) => {
                debug_assert_eq!(
                    Some(level.to_bits()),
                    match lod.footprint(lod_hit, &self.lod_camera, pyramid.base_size()) {
                        Footprint::Level(l) => Some(l.to_bits()),
                        _ => None,
                    },
                    "the level computed ahead is the footprint's"
                );
                Footprint::Level(level)
            }
            None => lod.footprint(lod_hit, &self.lod_camera, pyramid.base_size()),
        };
        let level = self.lookup_level(&footprint);
        let sampler = self.sampler(texture);
        *out = match footprint {
            Footprint::Base => TexelLookup::Planned {
                texture: t,
                plan: pyramid.plan_bilinear_in::<AVX2>(0, uv, sampler),
            },
            Footprint::Level(_) => TexelLookup::Planned {
                texture: t,
                plan: pyramid.plan_trilinear_in::<AVX2>(uv, level, sampler),
            },
            Footprint::Anisotropic { axis, taps, .. } => TexelLookup::Anisotropic {
                texture: t,
                uv,
                level,
                axis,
                taps,
            },
            Footprint::Elliptical { major, minor, .. } => TexelLookup::Elliptical {
                texture: t,
                uv,
                level,
                major,
                minor,
            },
        };
        // A plan knows its level (the same split of the same clamped level).
        let read = match out {
            TexelLookup::Planned { plan, .. } => plan.level(),
            _ => pyramid.level_read(level, sampler.mip),
        };
        counters.mip_histogram[read.min(MIP_LEVELS - 1)] += 1;
    }

    /// How `texture` is read this frame: its sampler, with the frame's MIP filter where
    /// one is set.
    #[inline(always)]
    fn sampler(&self, texture: &Texture) -> Sampler {
        Sampler {
            mip: self.mip_filter.unwrap_or(texture.sampler.mip),
            ..texture.sampler
        }
    }

    /// The filtered base-colour texel of a lookup (white when untextured); a planned lookup
    /// filtered in the SIMD copy `AVX2` names (as in [`Self::arrive_at`]).
    #[inline(always)]
    fn texel<const AVX2: bool>(&self, lookup: &TexelLookup) -> Vec3A {
        match lookup {
            TexelLookup::Untextured => Vec3A::ONE,
            TexelLookup::Planned { texture, plan } => {
                let pyramid = &self.textures[*texture as usize].pyramid;
                // SAFETY: only `texel_lookup` makes a planned lookup, on the pyramid of
                // `self.textures[texture]`, and the textures do not change while `self` is
                // borrowed: the lookups of a frame are made and filtered by the same scene.
                unsafe { pyramid.sample_planned_colour_in::<AVX2>(plan) }
            }
            &TexelLookup::Anisotropic {
                texture,
                uv,
                level,
                axis,
                taps,
            } => {
                let texture = &self.textures[texture as usize];
                let pyramid = &texture.pyramid;
                let sampler = self.sampler(texture);
                Vec3A::from_vec4(pyramid.sample_anisotropic(uv, level, axis, taps, sampler))
            }
            &TexelLookup::Elliptical {
                texture,
                uv,
                level,
                major,
                minor,
            } => {
                let texture = &self.textures[texture as usize];
                // The bias scales the ellipse, so its minor axis fits the biased level.
                let scale = self.lod_bias.exp2();
                let pyramid = &texture.pyramid;
                Vec3A::from_vec4(pyramid.sample_ewa(
                    uv,
                    level,
                    (major, minor),
                    scale,
                    self.sampler(texture),
                ))
            }
        }
    }

    /// What reaches a surface through a shadow ray that met the glass surfaces `glass`
    /// (`(t, source, material)`, any order) and nothing else (`blocked`: something opaque,
    /// or more glass than [`MAX_SHADOW_GLASS`]): 0 when blocked, else the product of the
    /// glass transmissions in distance order (so it does not depend on the order of visits).
    pub(super) fn shadow_transmittance(
        &self,
        blocked: bool,
        glass: &mut [(f32, u32, u32)],
    ) -> Vec3A {
        if blocked {
            return Vec3A::ZERO;
        }
        glass.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut transmittance = Vec3A::ONE;
        for &(_, _, m) in glass.iter() {
            let material = &self.materials[m as usize];
            // Additive glass attenuates by T alone; energy-weighted transmission is tinted by
            // the base colour.
            let tint = if material.is_additive() {
                Vec3A::ONE
            } else {
                Vec3A::from(material.base_color)
            };
            transmittance *= tint * material.transmission;
        }
        if transmittance.max_element() > MIN_WEIGHT {
            transmittance
        } else {
            Vec3A::ZERO
        }
    }

    /// Whether a shadow ray's visit of a surface of material `m` lets it go on (glass, and
    /// fewer than [`MAX_SHADOW_GLASS`] met so far).
    #[inline]
    pub(super) fn passes_through(&self, m: u32, glass_so_far: usize) -> bool {
        self.materials[m as usize].transmission > 0.0 && glass_so_far < MAX_SHADOW_GLASS
    }
}

/// `pyramid.clamp_level(finite_level(level + bias))`, the same bits, as `clamp_level`
/// alone: it already sends NaN to 0 and the infinities to the ends, and its range `[0,
/// last]` lies inside `finite_level`'s, so the first clamp never changes what the second
/// gives. One clamp less on every textured hit.
#[inline(always)]
fn clamped_biased_level(level: f32, bias: f32, pyramid: &MipPyramid) -> f32 {
    pyramid.clamp_level(level + bias)
}

/// Lambert + Blinn-Phong from every light whose shadow ray `requests` holds (in light
/// order), each through its transmittance.
fn direct_light(
    surface: &SurfacePoint,
    direction: Vec3A,
    diffuse: Vec3A,
    material: &Material,
    opaque: f32,
    requests: &[ShadowRequest],
) -> Vec3A {
    let mut color = Vec3A::ZERO;
    for request in requests {
        let transmittance = request.transmittance;
        if transmittance == Vec3A::ZERO {
            continue;
        }
        let incident = &request.incident;
        let irradiance = incident.irradiance * transmittance * request.cos;
        color += diffuse * irradiance * std::f32::consts::FRAC_1_PI;
        if material.specular > 0.0 {
            let half = (incident.to_light - direction).normalize_or_zero();
            let cos = surface.shading_normal.dot(half).max(0.0);
            if cos < material.highlight_floor {
                // `powf` would give +0 (`material::highlight_floor`): the highlight adds
                // nothing, so the frame is the same bits without the call.
                continue;
            }
            let highlight = cos.powf(material.shininess);
            let normalization = (material.shininess + 8.0) / (8.0 * std::f32::consts::PI);
            color += irradiance * (opaque * material.specular * normalization * highlight);
        }
    }
    color
}

/// The rays a hit spawns, numbered from `first` in the order they are pushed.
struct Children<'a, L> {
    first: u32,
    /// The pixel of the sample the rays serve.
    pixel: u32,
    /// How many rays `spawned` held before this hit's.
    before: usize,
    spawned: &'a mut Vec<Spawned<L>>,
}

impl<L: RayLod> Children<'_, L> {
    /// A secondary ray of class `class` leaving the surface on the side `face_normal`
    /// points to; returns its number.
    fn spawn(&mut self, class: RayClass, surface: &SurfacePoint, direction: Vec3A, lod: L) -> u32 {
        let origin = surface.position + surface.face_normal * surface.epsilon;
        let index = (self.spawned.len() - self.before) as u32;
        self.spawned.push(Spawned {
            class,
            pixel: self.pixel,
            origin,
            direction,
            lod,
        });
        self.first + index
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::COARSEST_LEVEL;

    /// The lookup's level with one clamp is the level with both, bit for bit, for levels and
    /// biases of every kind (non-finite, signed zeros, past either end, huge) and pyramids
    /// of one level to the most.
    #[test]
    fn one_clamp_gives_the_level_of_two() {
        let values = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            0.3,
            -0.3,
            1.0,
            7.99,
            13.5,
            COARSEST_LEVEL,
            -COARSEST_LEVEL,
            2000.0,
            -2000.0,
            f32::MAX,
            f32::MIN,
            1e-40,
        ];
        for size in [1u32, 2, 300, 16384] {
            let pyramid =
                MipPyramid::from_linear_rgba(size, 1, vec![glam::Vec4::ONE; size as usize])
                    .unwrap();
            for level in values {
                for bias in [0.0, -0.0, 1.5, -1.5, -1e30, f32::NAN] {
                    let both = pyramid.clamp_level(finite_level(level + bias));
                    let one = clamped_biased_level(level, bias, &pyramid);
                    assert_eq!(one.to_bits(), both.to_bits(), "{level} {bias} {size}");
                }
            }
        }
    }

    /// Bottom-up combination is the recursion's arithmetic: direct steps, then the grouped
    /// glass term summed from zero and added once.
    #[test]
    fn combine_adds_direct_steps_then_the_group() {
        let radiances = [
            Vec3A::ZERO,
            Vec3A::new(0.5, 2.0, 8.0),
            Vec3A::new(1.0, 1.0, 1.0),
            Vec3A::new(3.0, 0.0, 1.0),
        ];
        let mut c = Combine::leaf(Vec3A::new(0.1, 0.2, 0.3));
        c.add(Vec3A::splat(0.5), 1);
        c.begin_group();
        c.add(Vec3A::splat(0.25), 2);
        c.add(Vec3A::new(0.1, 0.2, 0.3), 3);
        let got = c.evaluate(|i| radiances[i as usize]);
        let mut expected = Vec3A::new(0.1, 0.2, 0.3);
        expected += Vec3A::splat(0.5) * radiances[1];
        let mut group = Vec3A::ZERO;
        group += 0.25 * radiances[2];
        group += Vec3A::new(0.1, 0.2, 0.3) * radiances[3];
        expected += group;
        assert_eq!(
            got.to_array().map(f32::to_bits),
            expected.to_array().map(f32::to_bits)
        );
        // A used vertex made a leaf in place is the leaf made afresh: its old steps are
        // not read.
        let mut reused = c;
        reused.make_leaf(Vec3A::new(0.4, 0.5, 0.6));
        let fresh = Combine::leaf(Vec3A::new(0.4, 0.5, 0.6));
        assert_eq!(
            reused
                .evaluate(|i| radiances[i as usize])
                .to_array()
                .map(f32::to_bits),
            fresh
                .evaluate(|i| radiances[i as usize])
                .to_array()
                .map(f32::to_bits)
        );
        reused.add(Vec3A::splat(2.0), 1);
        assert_eq!(
            reused.evaluate(|i| radiances[i as usize]),
            Vec3A::new(0.4, 0.5, 0.6) + Vec3A::splat(2.0) * radiances[1]
        );
        // An empty group still adds its zero (the recursion adds transmit's zero sum).
        let mut empty = Combine::leaf(Vec3A::new(-0.0, 1.0, 2.0));
        empty.begin_group();
        assert_eq!(
            empty.evaluate(|_| Vec3A::ONE).x.to_bits(),
            (-0.0f32 + 0.0).to_bits()
        );
    }
}
