//! Whitted ray tracing: ambient + Lambert / Blinn-Phong direct light from every light with
//! shadow rays, mirror reflection, refraction with Fresnel and total internal reflection.
//!
//! Every ray carries its LOD method's state (`lod::RayLod`: the path length for `paper`, a
//! cone, or differentials); at a textured hit the method turns it into a texture lookup. The
//! integrator is generic over that state, so each method pays only for its own. No
//! allocation per ray: recursion lives on the stack and per-tile counters are plain arrays.

use glam::{Vec2, Vec3A};

use crate::accel::{Accel, Hit};
use crate::geometry::FrameTriangles;
use crate::lod::{
    Footprint, LodCamera, LodMethod, RayLod, SurfaceHit, finite_level, with_lod_state,
};
use crate::render::camera::Camera;
use crate::render::light::Light;
use crate::scene::{MaterialDesc, Shading};
use crate::texture::{MipPyramid, Texture};

/// Histogram bins for texture lookups per integer MIP level (textures up to 32768^2).
pub const MIP_LEVELS: usize = 16;

/// Secondary rays whose contribution weight falls below this are not traced.
const MIN_WEIGHT: f32 = 1e-3;

/// Glass surfaces a shadow ray passes through before it counts as blocked (a fixed bound
/// keeps the per-ray state on the stack).
const MAX_SHADOW_GLASS: usize = 16;

/// Ambient radiance (linear RGB) reflected by every diffuse surface.
const AMBIENT: Vec3A = Vec3A::splat(0.03);

/// Counters gathered while tracing; summed per tile, then per frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TraceCounters {
    /// Every ray traced: primary, shadow, reflection, refraction.
    pub rays: u64,
    /// Texture lookups per integer level (floor of the clamped level).
    pub mip_histogram: [u64; MIP_LEVELS],
    /// Samples whose radiance came out non-finite and were replaced by black.
    pub nonfinite_samples: u64,
}

impl Default for TraceCounters {
    fn default() -> Self {
        TraceCounters {
            rays: 0,
            mip_histogram: [0; MIP_LEVELS],
            nonfinite_samples: 0,
        }
    }
}

impl TraceCounters {
    pub fn add(&mut self, other: &TraceCounters) {
        self.rays += other.rays;
        self.nonfinite_samples += other.nonfinite_samples;
        for (a, b) in self.mip_histogram.iter_mut().zip(other.mip_histogram) {
            *a += b;
        }
    }
}

/// Longest specular chain a probe records (mirror and glass bounces before the textured hit).
pub const MAX_CHAIN: usize = 16;

/// How a ray left one surface of a specular chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bend {
    Reflect,
    /// Refracted with relative index `eta = n_incident / n_transmitted`.
    Refract {
        eta: f32,
    },
}

/// The specular chain from the eye to a textured surface: each mirror or glass triangle
/// hit on the way and how the ray bent there, then the textured triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chain {
    bends: [(u32, Bend); MAX_CHAIN],
    len: usize,
}

impl Chain {
    fn new() -> Chain {
        Chain {
            bends: [(0, Bend::Reflect); MAX_CHAIN],
            len: 0,
        }
    }

    /// The surfaces passed before the textured one: (triangle slot, bend).
    pub fn bends(&self) -> &[(u32, Bend)] {
        &self.bends[..self.len]
    }
}

/// The LOD selected at the first textured surface along a specular chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LodProbe {
    /// Triangle slot (BVH order) of the textured hit.
    pub triangle: u32,
    /// Total distance from the ray's origin over every bounce.
    pub path_length: f32,
    /// The method's level including the bias, before clamping to the texture's pyramid.
    pub level: f32,
    /// The level the lookup used: clamped to `[0, last level]` (0 for `none`).
    pub clamped_level: f32,
    /// Texture coordinates at the hit.
    pub uv: Vec2,
    /// Index of the base-colour texture and its level-0 size.
    pub texture: usize,
    pub texture_size: (u32, u32),
    /// Number of MIP levels of that texture.
    pub texture_levels: usize,
    /// The mirrors and glass passed on the way.
    pub chain: Chain,
}

/// Everything the integrator reads for one frame.
pub struct FrameScene<'a> {
    pub triangles: &'a FrameTriangles,
    pub accel: &'a Accel,
    pub materials: &'a [MaterialDesc],
    pub textures: &'a [Texture],
    pub lights: &'a [Light],
    pub background: Vec3A,
    /// Scene ambient light for NFF materials (AFF `am`).
    pub nff_ambient: Vec3A,
    pub lod: LodMethod,
    /// Added to every MIP-mapped level (`--lod-bias`; not to `none`).
    pub lod_bias: f32,
    /// The camera constants primary rays' LOD state starts from.
    pub lod_camera: LodCamera,
    pub max_depth: u32,
}

/// Surface data at a hit, oriented towards the incoming ray.
#[derive(Clone, Copy)]
struct SurfacePoint {
    position: Vec3A,
    /// Geometric normal on the side the ray came from.
    face_normal: Vec3A,
    /// Interpolated normal, flipped to the same side as `face_normal`.
    shading_normal: Vec3A,
    /// +1 or -1: what turns the mesh's vertex normals to the side of `shading_normal`.
    normal_sign: f32,
    /// Whether the ray arrived on the front (counter-clockwise) side.
    entering: bool,
    /// Offset that lifts spawned rays off the surface.
    epsilon: f32,
}

impl FrameScene<'_> {
    /// Radiance of the primary ray through film point `(px, py)` of `camera`, carrying the
    /// LOD state of method `L` (the film picks `L` from `self.lod` with `lod::with_lod_state!`).
    #[inline]
    pub fn primary_radiance<L: RayLod>(
        &self,
        camera: &Camera,
        px: f32,
        py: f32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let direction = camera.primary_direction(px, py);
        let lod = L::primary(&self.lod_camera, px, py);
        self.radiance(camera.eye, direction, lod, 0, counters)
    }

    /// Radiance arriving at `origin` from `direction`; `lod` is the ray's LOD state,
    /// `depth` the number of bounces so far.
    pub fn radiance<L: RayLod>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        mut lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        counters.rays += 1;
        let Some(hit) = self
            .accel
            .closest_hit(self.triangles, origin, direction, f32::INFINITY)
        else {
            return self.background;
        };
        let slot = hit.triangle as usize;
        let surface = self.surface_point(&hit, origin, direction);
        let lod_hit = surface.lod_hit(self.triangles, &hit, direction);
        lod.arrive(&lod_hit);
        let material = &self.materials[self.triangles.material[slot] as usize];
        if material.shading == Shading::Nff {
            return self.shade_nff(&lod_hit, &surface, material, lod, depth, counters);
        }
        let albedo =
            Vec3A::from(material.base_color) * self.texel(&lod_hit, material, &lod, counters);

        let opaque = 1.0 - material.transmission;
        let mut color = Vec3A::ZERO;
        if opaque > 0.0 {
            let diffuse = albedo * (opaque * (1.0 - material.reflectance));
            color += self.direct_light(&surface, direction, diffuse, material, opaque, counters);
            color += AMBIENT * diffuse;
        }
        if depth >= self.max_depth {
            return color;
        }
        let mirror = opaque * material.reflectance;
        if mirror > MIN_WEIGHT {
            let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
            let lod = lod.reflect(&lod_hit, reflected);
            color += albedo * mirror * self.spawn(&surface, reflected, lod, depth, counters);
        }
        if material.transmission > MIN_WEIGHT {
            color += self.transmit(&lod_hit, &surface, albedo, material, lod, depth, counters);
        }
        color
    }

    /// Follows the primary ray through film point `(px, py)` along perfect mirrors and
    /// glass (the dominant specular branch) to its first textured surface and reports the
    /// LOD method `L` selects there. For tests, `--view lod` and `mipray compare`; the
    /// integrator computes the same quantities inline.
    pub fn probe<L: RayLod>(&self, camera: &Camera, px: f32, py: f32) -> Option<LodProbe> {
        let direction = camera.primary_direction(px, py);
        self.probe_ray(camera.eye, direction, L::primary(&self.lod_camera, px, py))
    }

    /// [`Self::probe`] with the state type of `self.lod`.
    pub fn probe_method(&self, camera: &Camera, px: f32, py: f32) -> Option<LodProbe> {
        with_lod_state!(self.lod, L => self.probe::<L>(camera, px, py))
    }

    /// [`Self::probe`] for any ray and starting state.
    pub fn probe_ray<L: RayLod>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        mut lod: L,
    ) -> Option<LodProbe> {
        let (mut origin, mut direction) = (origin, direction);
        let mut path_length = 0.0f32;
        let mut chain = Chain::new();
        loop {
            let hit = self
                .accel
                .closest_hit(self.triangles, origin, direction, f32::INFINITY)?;
            let slot = hit.triangle as usize;
            let surface = self.surface_point(&hit, origin, direction);
            let lod_hit = surface.lod_hit(self.triangles, &hit, direction);
            lod.arrive(&lod_hit);
            path_length += hit.t;
            let material = &self.materials[self.triangles.material[slot] as usize];
            if let Some((index, texture)) = material
                .base_color_texture
                .and_then(|t| Some((t, self.textures.get(t)?)))
            {
                let footprint =
                    lod.footprint(&lod_hit, &self.lod_camera, texture.pyramid.base_size());
                let (level, clamped_level) = self.biased_level(&footprint, &texture.pyramid);
                return Some(LodProbe {
                    triangle: hit.triangle,
                    path_length,
                    level,
                    clamped_level,
                    uv: interpolate_uv(self.triangles.uvs[slot], hit.bary),
                    texture: index,
                    texture_size: texture.pyramid.base_size(),
                    texture_levels: texture.pyramid.level_count(),
                    chain,
                });
            }
            if chain.len == MAX_CHAIN || chain.len as u32 >= self.max_depth {
                return None;
            }
            let (next, bend) = dominant_bend(&surface, direction, material)?;
            lod = match bend {
                Bend::Reflect => lod.reflect(&lod_hit, next),
                Bend::Refract { eta } => lod.refract(&lod_hit, eta, next),
            };
            chain.bends[chain.len] = (hit.triangle, bend);
            chain.len += 1;
            let side = match bend {
                Bend::Reflect => surface.face_normal,
                Bend::Refract { .. } => -surface.face_normal,
            };
            direction = next;
            origin = surface.position + side * surface.epsilon;
        }
    }

    /// Where a ray from `origin` along `direction` lands in texture space if it follows
    /// `chain` (the probe of a nearby ray) and then meets the plane of `textured`: each
    /// surface is intersected as its triangle's plane, with barycentrics extrapolated
    /// outside the triangle, and bent the same way. The finite-difference LOD reference
    /// traces its neighbouring pixel rays with this. `None` if a plane is missed (parallel
    /// or behind) or a refraction becomes total internal reflection.
    pub fn follow_chain(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        chain: &Chain,
        textured: u32,
    ) -> Option<Vec2> {
        let (mut origin, mut direction) = (origin, direction);
        for &(slot, bend) in chain.bends() {
            let surface = self.plane_point(slot, origin, direction)?;
            direction = match bend {
                Bend::Reflect => reflect(direction, surface.shading_normal, surface.face_normal),
                Bend::Refract { eta } => {
                    let n = surface.shading_normal;
                    let cos_i = (-direction.dot(n)).clamp(0.0, 1.0);
                    refract(direction, n, cos_i, eta)?.0
                }
            };
            origin = surface.position;
        }
        let slot = textured as usize;
        let (_, bary) = plane_barycentrics(self.triangles.positions[slot], origin, direction)?;
        Some(interpolate_uv(self.triangles.uvs[slot], bary))
    }

    /// The hit of a ray with the plane of triangle `slot`, as a surface point.
    fn plane_point(&self, slot: u32, origin: Vec3A, direction: Vec3A) -> Option<SurfacePoint> {
        let (t, bary) =
            plane_barycentrics(self.triangles.positions[slot as usize], origin, direction)?;
        let hit = Hit {
            t,
            triangle: slot,
            bary,
        };
        Some(self.surface_point(&hit, origin, direction))
    }

    /// The method's level with the bias, and the level the pyramid lookup uses.
    fn biased_level(&self, footprint: &Footprint, pyramid: &MipPyramid) -> (f32, f32) {
        match footprint {
            Footprint::Base => (0.0, 0.0),
            f => {
                let level = finite_level(f.level() + self.lod_bias);
                (level, pyramid.clamp_level(level))
            }
        }
    }

    fn surface_point(&self, hit: &Hit, origin: Vec3A, direction: Vec3A) -> SurfacePoint {
        let slot = hit.triangle as usize;
        let [p0, p1, p2] = self.triangles.positions[slot];
        let geometric = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        let [n0, n1, n2] = self.triangles.normals[slot];
        let (b1, b2) = (hit.bary.x, hit.bary.y);
        let interpolated =
            Vec3A::from(n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2).normalize_or_zero();
        let entering = geometric.dot(direction) <= 0.0;
        let face_normal = if entering { geometric } else { -geometric };
        let (shading_normal, normal_sign) = match interpolated.dot(face_normal) {
            d if d > 0.0 => (interpolated, 1.0),
            d if d < 0.0 => (-interpolated, -1.0),
            _ => (face_normal, if entering { 1.0 } else { -1.0 }),
        };
        let position = origin + direction * hit.t;
        let magnitude = position.abs().max_element().max(origin.abs().max_element());
        SurfacePoint {
            position,
            face_normal,
            shading_normal,
            normal_sign,
            entering,
            epsilon: 1e-5 + magnitude * 2f32.powi(-17),
        }
    }

    /// The NFF/Whitted convention (AFF files, FORMAT.md 1.8), purely additive:
    /// `am*amb*tex + sum_lights(diff*tex*Lc*N.L + highlight) + spec*L_reflect + T*L_refract`.
    fn shade_nff<L: RayLod>(
        &self,
        lod_hit: &SurfaceHit,
        surface: &SurfacePoint,
        material: &MaterialDesc,
        lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let direction = lod_hit.direction;
        let texel = self.texel(lod_hit, material, &lod, counters);
        let diffuse = Vec3A::from(material.base_color) * texel;
        let ambient = Vec3A::from(material.ambient.unwrap_or(material.base_color)) * texel;
        let mut color = self.nff_ambient * ambient;
        color += self.direct_light(surface, direction, diffuse, material, 1.0, counters);
        if depth >= self.max_depth {
            return color;
        }
        if material.reflectance > MIN_WEIGHT {
            let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
            let lod = lod.reflect(lod_hit, reflected);
            color += material.reflectance * self.spawn(surface, reflected, lod, depth, counters);
        }
        if material.transmission > MIN_WEIGHT {
            let r = surface.refraction(direction, material.ior);
            let traced = match r.transmitted {
                Some((refracted, _)) => {
                    let lod = lod.refract(lod_hit, r.eta, refracted);
                    self.spawn(&surface.far_side(), refracted, lod, depth, counters)
                }
                None => {
                    let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
                    let lod = lod.reflect(lod_hit, reflected);
                    self.spawn(surface, reflected, lod, depth, counters)
                }
            };
            color += material.transmission * traced;
        }
        color
    }

    /// The filtered base-colour texel at a hit (white when untextured).
    #[inline]
    fn texel<L: RayLod>(
        &self,
        lod_hit: &SurfaceHit,
        material: &MaterialDesc,
        lod: &L,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let Some(texture) = material
            .base_color_texture
            .and_then(|t| self.textures.get(t))
        else {
            return Vec3A::ONE;
        };
        let uv = interpolate_uv(self.triangles.uvs[lod_hit.slot], lod_hit.bary);
        let pyramid = &texture.pyramid;
        let footprint = lod.footprint(lod_hit, &self.lod_camera, pyramid.base_size());
        let (_, level) = self.biased_level(&footprint, pyramid);
        counters.mip_histogram[(level as usize).min(MIP_LEVELS - 1)] += 1;
        let texel = match footprint {
            Footprint::Base => pyramid.sample_bilinear(0, uv, texture.sampler),
            Footprint::Level(_) => pyramid.sample_trilinear(uv, level, texture.sampler),
            Footprint::Anisotropic { axis, taps, .. } => {
                pyramid.sample_anisotropic(uv, level, axis, taps, texture.sampler)
            }
        };
        Vec3A::new(texel.x, texel.y, texel.z)
    }

    /// Lambert + Blinn-Phong from every light, each through a shadow ray.
    fn direct_light(
        &self,
        surface: &SurfacePoint,
        direction: Vec3A,
        diffuse: Vec3A,
        material: &MaterialDesc,
        opaque: f32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let mut color = Vec3A::ZERO;
        for light in self.lights {
            let Some(incident) = light.incident(surface.position) else {
                continue;
            };
            let cos = surface.shading_normal.dot(incident.to_light);
            if cos <= 0.0 || surface.face_normal.dot(incident.to_light) <= 0.0 {
                continue;
            }
            let transmittance =
                self.shadow_transmittance(surface, incident.to_light, incident.distance, counters);
            if transmittance == Vec3A::ZERO {
                continue;
            }
            let irradiance = incident.irradiance * transmittance * cos;
            color += diffuse * irradiance * std::f32::consts::FRAC_1_PI;
            if material.specular > 0.0 {
                let half = (incident.to_light - direction).normalize_or_zero();
                let highlight = surface
                    .shading_normal
                    .dot(half)
                    .max(0.0)
                    .powf(material.shininess);
                let normalization = (material.shininess + 8.0) / (8.0 * std::f32::consts::PI);
                color += irradiance * (opaque * material.specular * normalization * highlight);
            }
        }
        color
    }

    /// Fraction of light that reaches the surface: 0 behind anything opaque, the product of
    /// transmission times untextured base colour through glass.
    fn shadow_transmittance(
        &self,
        surface: &SurfacePoint,
        to_light: Vec3A,
        distance: f32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        counters.rays += 1;
        let origin = surface.position + surface.face_normal * surface.epsilon;
        let t_max = if distance.is_finite() {
            distance * (1.0 - 1e-4) - surface.epsilon
        } else {
            f32::INFINITY
        };
        if !(t_max > 0.0) {
            return Vec3A::ONE;
        }
        // Collect the glass surfaces on the way and multiply them in distance order, so the
        // result does not depend on the tree's traversal order (float products do).
        let mut glass = [(0.0f32, 0u32, 0u32); MAX_SHADOW_GLASS];
        let mut count = 0;
        let unblocked =
            self.accel
                .visit_hits(self.triangles, origin, to_light, t_max, |slot, t| {
                    let material = &self.materials[self.triangles.material[slot as usize] as usize];
                    if material.transmission <= 0.0 || count == MAX_SHADOW_GLASS {
                        return false;
                    }
                    glass[count] = (t, self.triangles.source[slot as usize], slot);
                    count += 1;
                    true
                });
        if !unblocked {
            return Vec3A::ZERO;
        }
        let glass = &mut glass[..count];
        glass.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut transmittance = Vec3A::ONE;
        for &(_, _, slot) in glass.iter() {
            let material = &self.materials[self.triangles.material[slot as usize] as usize];
            // NFF glass attenuates by T alone; glTF transmission is tinted by the base colour.
            let tint = if material.shading == Shading::Nff {
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

    /// Glass: Fresnel-weighted reflection plus refraction tinted by the albedo; total
    /// internal reflection sends everything to the reflection.
    #[allow(clippy::too_many_arguments)]
    fn transmit<L: RayLod>(
        &self,
        lod_hit: &SurfaceHit,
        surface: &SurfacePoint,
        albedo: Vec3A,
        material: &MaterialDesc,
        lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let direction = lod_hit.direction;
        let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
        let weight = material.transmission;
        let r = surface.refraction(direction, material.ior);
        let Some((refracted, cos_t)) = r.transmitted else {
            let lod = lod.reflect(lod_hit, reflected);
            return weight * self.spawn(surface, reflected, lod, depth, counters);
        };
        let fresnel = dielectric_fresnel(r.cos_i, cos_t, r.eta);
        let mut color = Vec3A::ZERO;
        if weight * fresnel > MIN_WEIGHT {
            let lod = lod.reflect(lod_hit, reflected);
            color += weight * fresnel * self.spawn(surface, reflected, lod, depth, counters);
        }
        if weight * (1.0 - fresnel) > MIN_WEIGHT {
            let lod = lod.refract(lod_hit, r.eta, refracted);
            let through = self.spawn(&surface.far_side(), refracted, lod, depth, counters);
            color += albedo * (weight * (1.0 - fresnel)) * through;
        }
        color
    }

    /// Traces a secondary ray leaving the surface on the side `face_normal` points to.
    #[inline]
    fn spawn<L: RayLod>(
        &self,
        surface: &SurfacePoint,
        direction: Vec3A,
        lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let origin = surface.position + surface.face_normal * surface.epsilon;
        self.radiance(origin, direction, lod, depth + 1, counters)
    }
}

/// The branch a probe follows at a mirror or glass surface: refraction through mostly
/// transmissive surfaces (reflection on total internal reflection), reflection off mostly
/// reflective ones; `None` for anything else (a diffuse surface ends the chain).
fn dominant_bend(
    surface: &SurfacePoint,
    direction: Vec3A,
    material: &MaterialDesc,
) -> Option<(Vec3A, Bend)> {
    let reflected = || reflect(direction, surface.shading_normal, surface.face_normal);
    if material.transmission >= 0.5 {
        let r = surface.refraction(direction, material.ior);
        Some(match r.transmitted {
            Some((refracted, _)) => (refracted, Bend::Refract { eta: r.eta }),
            None => (reflected(), Bend::Reflect),
        })
    } else if material.reflectance >= 0.5 {
        Some((reflected(), Bend::Reflect))
    } else {
        None
    }
}

/// Texture coordinates at barycentrics `(b1, b2)`.
#[inline]
fn interpolate_uv([t0, t1, t2]: [Vec2; 3], bary: Vec2) -> Vec2 {
    t0 * (1.0 - bary.x - bary.y) + t1 * bary.x + t2 * bary.y
}

/// Distance to, and barycentrics of, the point where a ray meets a triangle's plane, with
/// no bounds on the barycentrics (Moller-Trumbore without the inside test). `None` when the
/// ray is parallel to the plane, the triangle is degenerate, or the plane is behind.
fn plane_barycentrics(p: [Vec3A; 3], origin: Vec3A, direction: Vec3A) -> Option<(f32, Vec2)> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let pvec = direction.cross(e2);
    let det = e1.dot(pvec);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let tvec = origin - p[0];
    let b1 = tvec.dot(pvec) * inv;
    let qvec = tvec.cross(e1);
    let b2 = direction.dot(qvec) * inv;
    let t = e2.dot(qvec) * inv;
    (t > 0.0 && t.is_finite() && b1.is_finite() && b2.is_finite()).then_some((t, Vec2::new(b1, b2)))
}

/// Snell refraction at a surface: the incident cosine, the relative index, and the
/// transmitted direction with its cosine (`None` on total internal reflection).
#[derive(Clone, Copy)]
struct Refraction {
    cos_i: f32,
    eta: f32,
    transmitted: Option<(Vec3A, f32)>,
}

impl SurfacePoint {
    /// Refraction of `direction` into (or out of) a material of index `ior`, on the side the
    /// ray arrived from.
    fn refraction(&self, direction: Vec3A, ior: f32) -> Refraction {
        let eta = if self.entering { 1.0 / ior } else { ior };
        let n = self.shading_normal;
        let cos_i = (-direction.dot(n)).clamp(0.0, 1.0);
        Refraction {
            cos_i,
            eta,
            transmitted: refract(direction, n, cos_i, eta),
        }
    }

    /// What a LOD method reads at this hit.
    #[inline]
    fn lod_hit<'t>(
        &self,
        triangles: &'t FrameTriangles,
        hit: &Hit,
        direction: Vec3A,
    ) -> SurfaceHit<'t> {
        SurfaceHit {
            triangles,
            slot: hit.triangle as usize,
            t: hit.t,
            direction,
            face_normal: self.face_normal,
            shading_normal: self.shading_normal,
            normal_sign: self.normal_sign,
            bary: hit.bary,
        }
    }

    /// The same point seen from the far side (where a transmitted ray leaves).
    fn far_side(&self) -> SurfacePoint {
        SurfacePoint {
            face_normal: -self.face_normal,
            ..*self
        }
    }
}

/// Mirror direction about the shading normal; if that points into the surface (possible
/// with interpolated normals at grazing angles) the geometric normal is used instead.
#[inline]
fn reflect(direction: Vec3A, shading_normal: Vec3A, face_normal: Vec3A) -> Vec3A {
    let r = direction - 2.0 * direction.dot(shading_normal) * shading_normal;
    if r.dot(face_normal) > 0.0 {
        r.normalize()
    } else {
        (direction - 2.0 * direction.dot(face_normal) * face_normal).normalize()
    }
}

/// Snell refraction of unit `direction` through a surface with normal `n` (facing the
/// incoming ray), relative index `eta = n_incident / n_transmitted`. `None` on total
/// internal reflection. Returns the direction and the cosine of the transmitted angle.
#[inline]
fn refract(direction: Vec3A, n: Vec3A, cos_i: f32, eta: f32) -> Option<(Vec3A, f32)> {
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let t = eta * direction + (eta * cos_i - cos_t) * n;
    Some((t.normalize(), cos_t))
}

/// Unpolarised Fresnel reflectance of a dielectric boundary.
#[inline]
fn dielectric_fresnel(cos_i: f32, cos_t: f32, eta: f32) -> f32 {
    // With eta = n1/n2: r_s = (n1 cos_i - n2 cos_t)/(n1 cos_i + n2 cos_t), divided by n2.
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let f = 0.5 * (rs * rs + rp * rp);
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_at_normal_incidence_is_schlick_r0() {
        let eta = 1.0 / 1.5;
        let f = dielectric_fresnel(1.0, 1.0, eta);
        assert!((f - 0.04).abs() < 1e-6, "{f}");
        // Grazing incidence reflects everything.
        assert!(dielectric_fresnel(0.0, 0.7, eta) > 0.999);
    }

    #[test]
    fn refraction_obeys_snell_and_total_internal_reflection() {
        let n = Vec3A::Y;
        let angle = 40f32.to_radians();
        let d = Vec3A::new(angle.sin(), -angle.cos(), 0.0);
        let (t, cos_t) = refract(d, n, angle.cos(), 1.0 / 1.5).unwrap();
        let sin_t = (1.0 - cos_t * cos_t).sqrt();
        assert!((angle.sin() - 1.5 * sin_t).abs() < 1e-5);
        assert!((t.x - sin_t).abs() < 1e-5 && t.y < 0.0);
        // From glass to air past the critical angle (41.8 degrees): TIR.
        let steep = 60f32.to_radians();
        let d = Vec3A::new(steep.sin(), -steep.cos(), 0.0);
        assert!(refract(d, n, steep.cos(), 1.5).is_none());
    }

    #[test]
    fn reflection_never_enters_the_surface() {
        let face = Vec3A::Y;
        let bent = Vec3A::new(0.9, 0.1, 0.0).normalize();
        let d = Vec3A::new(1.0, -0.05, 0.0).normalize();
        let r = reflect(d, bent, face);
        assert!(r.dot(face) > 0.0);
        assert!((r.length() - 1.0).abs() < 1e-6);
    }
}
