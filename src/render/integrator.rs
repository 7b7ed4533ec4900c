//! Whitted ray tracing: ambient + Lambert / Blinn-Phong direct light from every light with
//! shadow rays, mirror reflection, refraction with Fresnel and total internal reflection.
//! Materials follow one of two models (`render::ShadingModel`): energy-weighted lobes
//! (glTF-style) or the additive NFF/Whitted convention.
//!
//! Every ray carries its LOD method's state (`lod::RayLod`: the path length for `paper`, a
//! cone, or differentials); at a textured hit the method turns it into a texture lookup. The
//! integrator is generic over that state, so each method pays only for its own. No
//! allocation per ray: recursion lives on the stack and per-tile counters are plain arrays.

use glam::{Vec3, Vec3A};

use crate::accel::Hit;
use crate::geometry::HitTriangle;
use crate::lod::{Footprint, LodCamera, LodMethod, RayLod, SurfaceHit, finite_level};
use crate::render::camera::Camera;
use crate::render::light::Light;
use crate::render::material::{Material, ShadingModel};
use crate::render::ray_log::{RayClass, RayLog};
use crate::render::scene_bvh::SceneBvh;
use crate::render::surface::{SurfacePoint, dielectric_fresnel, interpolate_uv, reflect};
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

    /// Sets the pixel the next recorded rays belong to.
    #[inline]
    pub(super) fn set_pixel(&mut self, pixel: u32) {
        if let Some(log) = &mut self.log {
            log.pixel = pixel;
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
    /// The camera constants primary rays' LOD state starts from.
    pub lod_camera: LodCamera,
    pub max_depth: u32,
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
        self.radiance(RayClass::Primary, camera.eye, direction, lod, 0, counters)
    }

    /// [`FrameScene::primary_radiance`] for a primary ray already traced: `direction` is
    /// `camera.primary_direction(px, py)` and `hit` what `closest_hit` found along it (the
    /// film traces a tile's primary rays as packets, then shades each).
    #[inline]
    pub fn primary_radiance_at<L: RayLod>(
        &self,
        camera: &Camera,
        (px, py): (f32, f32),
        direction: Vec3A,
        hit: Option<Hit>,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let lod = L::primary(&self.lod_camera, px, py);
        counters.rays += 1;
        if let Some(log) = &mut counters.log {
            log.closest(RayClass::Primary, camera.eye, direction, f32::INFINITY, hit);
        }
        self.shade(hit, camera.eye, direction, lod, 0, counters)
    }

    /// Radiance arriving at `origin` from `direction` along a ray of class `class`; `lod`
    /// is the ray's LOD state, `depth` the number of bounces so far.
    pub fn radiance<L: RayLod>(
        &self,
        class: RayClass,
        origin: Vec3A,
        direction: Vec3A,
        lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        counters.rays += 1;
        let hit = self.bvh.closest_hit(origin, direction, f32::INFINITY);
        if let Some(log) = &mut counters.log {
            log.closest(class, origin, direction, f32::INFINITY, hit);
        }
        self.shade(hit, origin, direction, lod, depth, counters)
    }

    /// The hit triangle in world space (the hit's distance and barycentrics made those of
    /// that triangle, see `scene_bvh`).
    #[inline]
    pub fn hit_triangle(&self, hit: &mut Hit, origin: Vec3A, direction: Vec3A) -> HitTriangle {
        self.bvh.hit_triangle(hit, origin, direction)
    }

    /// Radiance leaving the hit `hit` (background when `None`) of a ray from `origin` along
    /// `direction`, toward that ray.
    fn shade<L: RayLod>(
        &self,
        hit: Option<Hit>,
        origin: Vec3A,
        direction: Vec3A,
        mut lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let Some(mut hit) = hit else {
            return self.background;
        };
        let triangle = self.hit_triangle(&mut hit, origin, direction);
        let surface = SurfacePoint::at(&triangle, &hit, origin, direction);
        let lod_hit = surface.lod_hit(&triangle, &hit, direction);
        lod.arrive(&lod_hit);
        let material = &self.materials[triangle.material as usize];
        if let ShadingModel::Additive { ambient } = material.model {
            return self
                .shade_additive(&lod_hit, &surface, material, ambient, lod, depth, counters);
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
            color += albedo
                * mirror
                * self.spawn(
                    RayClass::Reflection,
                    &surface,
                    reflected,
                    lod,
                    depth,
                    counters,
                );
        }
        if material.transmission > MIN_WEIGHT {
            color += self.transmit(&lod_hit, &surface, albedo, material, lod, depth, counters);
        }
        color
    }

    /// The method's level with the bias, and the level the pyramid lookup uses.
    pub(super) fn biased_level(&self, footprint: &Footprint, pyramid: &MipPyramid) -> (f32, f32) {
        match footprint {
            Footprint::Base => (0.0, 0.0),
            f => {
                let level = finite_level(f.level() + self.lod_bias);
                (level, pyramid.clamp_level(level))
            }
        }
    }

    /// The additive NFF/Whitted convention (AFF files, FORMAT.md 1.8):
    /// `am*amb*tex + sum_lights(diff*tex*Lc*N.L + highlight) + spec*L_reflect + T*L_refract`,
    /// with `ambient` the material's ambient reflectance.
    #[allow(clippy::too_many_arguments)]
    fn shade_additive<L: RayLod>(
        &self,
        lod_hit: &SurfaceHit,
        surface: &SurfacePoint,
        material: &Material,
        ambient: Vec3,
        lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let direction = lod_hit.direction;
        let texel = self.texel(lod_hit, material, &lod, counters);
        let diffuse = Vec3A::from(material.base_color) * texel;
        let ambient = Vec3A::from(ambient) * texel;
        let mut color = self.additive_ambient * ambient;
        color += self.direct_light(surface, direction, diffuse, material, 1.0, counters);
        if depth >= self.max_depth {
            return color;
        }
        if material.reflectance > MIN_WEIGHT {
            let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
            let lod = lod.reflect(lod_hit, reflected);
            color += material.reflectance
                * self.spawn(
                    RayClass::Reflection,
                    surface,
                    reflected,
                    lod,
                    depth,
                    counters,
                );
        }
        if material.transmission > MIN_WEIGHT {
            let r = surface.refraction(direction, material.ior);
            let traced = match r.transmitted {
                Some((refracted, _)) => {
                    let lod = lod.refract(lod_hit, r.eta, refracted);
                    self.spawn(
                        RayClass::Refraction,
                        &surface.far_side(),
                        refracted,
                        lod,
                        depth,
                        counters,
                    )
                }
                None => {
                    let reflected = reflect(direction, surface.shading_normal, surface.face_normal);
                    let lod = lod.reflect(lod_hit, reflected);
                    self.spawn(
                        RayClass::Reflection,
                        surface,
                        reflected,
                        lod,
                        depth,
                        counters,
                    )
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
        material: &Material,
        lod: &L,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let Some(texture) = material
            .base_color_texture
            .and_then(|t| self.textures.get(t))
        else {
            return Vec3A::ONE;
        };
        let uv = interpolate_uv(lod_hit.triangle.uvs, lod_hit.bary);
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
            // The bias scales the ellipse, so its minor axis fits the biased level.
            Footprint::Elliptical { major, minor, .. } => {
                let scale = self.lod_bias.exp2();
                pyramid.sample_ewa(uv, level, (major, minor), scale, texture.sampler)
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
        material: &Material,
        opaque: f32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let mut color = Vec3A::ZERO;
        for light in self.lights {
            let Some(incident) = light.incident(surface.position) else {
                continue;
            };
            if !surface.faces(incident.to_light) {
                continue;
            }
            let cos = surface.shading_normal.dot(incident.to_light);
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
        let Some((origin, t_max)) = surface.shadow_ray(distance) else {
            return Vec3A::ONE;
        };
        // Collect the glass surfaces on the way and multiply them in distance order, so the
        // result does not depend on the tree's traversal order (float products do).
        let mut glass = [(0.0f32, 0u32, 0u32); MAX_SHADOW_GLASS];
        let mut count = 0;
        let unblocked = self
            .bvh
            .visit_hits(origin, to_light, t_max, |t, m, source| {
                let material = &self.materials[m as usize];
                if material.transmission <= 0.0 || count == MAX_SHADOW_GLASS {
                    return false;
                }
                glass[count] = (t, source, m);
                count += 1;
                true
            });
        if let Some(log) = &mut counters.log {
            log.shadow(origin, to_light, t_max, !unblocked || count > 0);
        }
        if !unblocked {
            return Vec3A::ZERO;
        }
        let glass = &mut glass[..count];
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

    /// Glass: Fresnel-weighted reflection plus refraction tinted by the albedo; total
    /// internal reflection sends everything to the reflection.
    #[allow(clippy::too_many_arguments)]
    fn transmit<L: RayLod>(
        &self,
        lod_hit: &SurfaceHit,
        surface: &SurfacePoint,
        albedo: Vec3A,
        material: &Material,
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
            return weight
                * self.spawn(
                    RayClass::Reflection,
                    surface,
                    reflected,
                    lod,
                    depth,
                    counters,
                );
        };
        let fresnel = dielectric_fresnel(r.cos_i, cos_t, r.eta);
        let mut color = Vec3A::ZERO;
        if weight * fresnel > MIN_WEIGHT {
            let lod = lod.reflect(lod_hit, reflected);
            color += weight
                * fresnel
                * self.spawn(
                    RayClass::Reflection,
                    surface,
                    reflected,
                    lod,
                    depth,
                    counters,
                );
        }
        if weight * (1.0 - fresnel) > MIN_WEIGHT {
            let lod = lod.refract(lod_hit, r.eta, refracted);
            let through = self.spawn(
                RayClass::Refraction,
                &surface.far_side(),
                refracted,
                lod,
                depth,
                counters,
            );
            color += albedo * (weight * (1.0 - fresnel)) * through;
        }
        color
    }

    /// Traces a secondary ray of class `class` leaving the surface on the side
    /// `face_normal` points to.
    #[inline]
    fn spawn<L: RayLod>(
        &self,
        class: RayClass,
        surface: &SurfacePoint,
        direction: Vec3A,
        lod: L,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let origin = surface.position + surface.face_normal * surface.epsilon;
        self.radiance(class, origin, direction, lod, depth + 1, counters)
    }
}
