//! LOD error in levels against a finite-difference reference (LOD-ANCHORS.md 4.3).
//!
//! For each pixel whose centre ray reaches a textured surface (directly or through mirrors
//! and glass, the probe's dominant specular chain), the rays through the four points half a
//! pixel left, right, above and below the centre follow the same chain: each surface is met
//! as its triangle's plane and bent the same way (`FrameScene::follow_chain`). Their texture
//! coordinates give the texel Jacobian by central differences,
//! `J_x = (uv(x + 1/2) - uv(x - 1/2)) * (W, H)` and likewise `J_y`, and from it the
//! reference level in the OpenGL convention the methods use, `log2 max(|J_x|, |J_y|)`
//! (`diffs-aniso` is compared with the anisotropic level of the same Jacobian, `diffs-ewa`
//! with the level of its clamped minor axis: each with the level its filter is built on).
//! Both levels are clamped to the texture's pyramid, so only differences a lookup can see
//! count. A pixel whose neighbouring rays miss a plane of the chain is left out.

use glam::{Vec2, Vec3A};
use rayon::prelude::*;

use crate::lod::{LodMethod, NoLod, TexelGradients};
use crate::render::Camera;
use crate::render::integrator::FrameScene;
use crate::render::probe::LodProbe;

/// The reference levels of one pixel, clamped to its texture's pyramid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceLevel {
    pub isotropic: f32,
    /// `diffs-aniso`'s level of the same Jacobian (`TexelGradients::anisotropic`).
    pub anisotropic: f32,
    /// `diffs-ewa`'s level of the same Jacobian (`TexelGradients::elliptical`).
    pub elliptical: f32,
}

impl ReferenceLevel {
    /// The reference level `method` is measured against.
    pub fn for_method(&self, method: LodMethod) -> f32 {
        match method {
            LodMethod::DiffsAniso => self.anisotropic,
            LodMethod::DiffsEwa => self.elliptical,
            _ => self.isotropic,
        }
    }
}

/// A frame's reference levels, row-major, `None` where no textured surface was measured.
pub struct LodReference {
    pub width: u32,
    pub levels: Vec<Option<ReferenceLevel>>,
}

/// How far a method's levels are from the reference over one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LodErrorStats {
    /// Mean of `method - reference` (positive: blurrier).
    pub bias: f64,
    pub rms: f64,
    /// Share of pixels more than half a level below the reference (aliasing risk).
    pub under: f64,
    pub pixels: u64,
}

/// Half-pixel offsets of the central differences.
const HALF: f32 = 0.5;

/// The reference levels of every pixel of `camera` (pixel centres).
pub fn reference_levels(scene: &FrameScene, camera: &Camera) -> LodReference {
    let (w, h) = (camera.width, camera.height);
    let levels = (0..w * h)
        .into_par_iter()
        .map(|i| reference_at(scene, camera, (i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
        .collect();
    LodReference { width: w, levels }
}

fn reference_at(scene: &FrameScene, camera: &Camera, px: f32, py: f32) -> Option<ReferenceLevel> {
    let centre = scene.probe::<NoLod>(camera, px, py)?;
    let uv = |dx: f32, dy: f32| -> Option<Vec2> {
        let direction: Vec3A = camera.primary_direction(px + dx, py + dy);
        scene.follow_chain(camera.eye, direction, &centre.chain, centre.triangle)
    };
    let size = Vec2::new(centre.texture_size.0 as f32, centre.texture_size.1 as f32);
    let gradients = TexelGradients {
        dx: (uv(HALF, 0.0)? - uv(-HALF, 0.0)?) * size,
        dy: (uv(0.0, HALF)? - uv(0.0, -HALF)?) * size,
    };
    if !(gradients.dx.is_finite() && gradients.dy.is_finite()) {
        return None;
    }
    let clamp = |level: f32| clamp_to_pyramid(level, &centre);
    Some(ReferenceLevel {
        isotropic: clamp(gradients.isotropic_level()),
        anisotropic: clamp(gradients.anisotropic().0),
        elliptical: clamp(gradients.elliptical().level),
    })
}

/// `level` clamped to the levels `probe`'s texture has.
pub(super) fn clamp_to_pyramid(level: f32, probe: &LodProbe) -> f32 {
    level
        .max(0.0)
        .min(probe.texture_levels.saturating_sub(1) as f32)
}

/// The error of `scene.lod` (with `scene.lod_bias`) against `reference`.
pub fn method_error(
    scene: &FrameScene,
    camera: &Camera,
    reference: &LodReference,
) -> LodErrorStats {
    let w = reference.width;
    let (sum, sum2, under, pixels) = reference
        .levels
        .par_iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let r = (*r)?;
            let (x, y) = (i as u32 % w, i as u32 / w);
            let probe = scene.probe_method(camera, x as f32 + 0.5, y as f32 + 0.5)?;
            let d = (probe.clamped_level - r.for_method(scene.lod)) as f64;
            Some((d, d * d, (d < -0.5) as u64, 1u64))
        })
        .reduce(
            || (0.0, 0.0, 0, 0),
            |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3 + b.3),
        );
    if pixels == 0 {
        return LodErrorStats {
            bias: f64::NAN,
            rms: f64::NAN,
            under: f64::NAN,
            pixels: 0,
        };
    }
    let n = pixels as f64;
    LodErrorStats {
        bias: sum / n,
        rms: (sum2 / n).sqrt(),
        under: under as f64 / n,
        pixels,
    }
}
