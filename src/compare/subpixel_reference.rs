//! An independent LOD reference from real sub-pixel rays.
//!
//! The finite-difference reference (`lod_error.rs`, "probe reference") forces its half-pixel
//! rays through the centre ray's chain of planes with extrapolated normals: it is the
//! finite-difference form of `diffs`, blind to edges, seams and curvature. This one traces
//! a stratified `GRID x GRID` set of sub-pixel rays through the actual scene (each follows
//! its own dominant specular chain to whatever it hits, `FrameScene::probe`), keeps those
//! that reach the same textured surface as the centre ray (same material and texture,
//! same number of specular bounces), and fits the texel footprint by least squares:
//! `uv * (W, H) = a + J_x dx + J_y dy` over the kept rays' film offsets `(dx, dy)` in
//! pixels. From the fitted Jacobian it reports the level under two conventions:
//! - **longest axis** (OpenGL, what the methods aim at): `log2 max(|J_x|, |J_y|)`;
//! - **area** (the square of the same area): `0.5 log2 |det J|`, which does not charge a
//!   method the full incidence elongation (a receding floor).
//!
//! The fit is *undefined* (the pixel is counted, not measured) when fewer than half the
//! sub-rays reach the centre's surface (silhouettes), the kept offsets are collinear, or
//! the fit's largest residual exceeds a tenth of the footprint's longest axis (a UV seam or
//! another discontinuity inside the pixel). Levels are clamped to the texture's pyramid
//! like the probe reference's, so only differences a lookup can see count.

use glam::{DVec2, Vec2};
use rayon::prelude::*;

use super::lod_error::{LodReference, ReferenceLevel, clamp_to_pyramid};
use crate::lod::{NoLod, TexelGradients};
use crate::render::Camera;
use crate::render::integrator::FrameScene;
use crate::render::probe::LodProbe;

/// Sub-pixel rays per side: `GRID^2` rays per pixel.
pub const GRID: u32 = 4;

/// Fewest sub-rays that must reach the centre ray's surface for a fit.
const MIN_KEPT: usize = (GRID * GRID / 2) as usize;

/// Largest fit residual (any sub-ray, texels) allowed, as a share of the footprint's
/// longest axis. A step of `H` texels across the middle of the pixel fits with slope
/// `1.6 H` and a largest residual of `0.3 H` (0.19 of the axis); a smooth surface's
/// curvature leaves a few hundredths.
const MAX_RESIDUAL_SHARE: f64 = 0.1;

/// The sub-pixel reference levels of one frame under both conventions.
pub struct SubpixelReference {
    /// Longest-axis levels (and the levels of the same fit `diffs-aniso` and `diffs-ewa`
    /// are measured against).
    pub longest_axis: LodReference,
    /// Area-preserving levels (anisotropic as above).
    pub area: LodReference,
    /// Pixels whose centre ray reached a textured surface.
    pub textured: u64,
    /// Of those, pixels where the fit is undefined (silhouettes, seams).
    pub undefined: u64,
}

impl SubpixelReference {
    /// `undefined / textured` (0 when nothing textured was seen).
    pub fn undefined_share(&self) -> f64 {
        if self.textured == 0 {
            0.0
        } else {
            self.undefined as f64 / self.textured as f64
        }
    }
}

/// What one pixel gave: nothing textured, an undefined fit, or levels.
#[derive(Debug, Clone, Copy, PartialEq)]
enum PixelFit {
    Untextured,
    Undefined,
    Levels {
        longest_axis: ReferenceLevel,
        area: ReferenceLevel,
    },
}

/// The sub-pixel reference of every pixel of `camera`.
pub fn subpixel_reference(scene: &FrameScene, camera: &Camera) -> SubpixelReference {
    let (w, h) = (camera.width, camera.height);
    let fits: Vec<PixelFit> = (0..w * h)
        .into_par_iter()
        .map(|i| fit_pixel(scene, camera, (i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
        .collect();
    let textured = fits.iter().filter(|f| **f != PixelFit::Untextured).count() as u64;
    let undefined = fits.iter().filter(|f| **f == PixelFit::Undefined).count() as u64;
    let levels = |pick: fn(&PixelFit) -> Option<ReferenceLevel>| LodReference {
        width: w,
        levels: fits.iter().map(pick).collect(),
    };
    SubpixelReference {
        longest_axis: levels(|f| match f {
            PixelFit::Levels { longest_axis, .. } => Some(*longest_axis),
            _ => None,
        }),
        area: levels(|f| match f {
            PixelFit::Levels { area, .. } => Some(*area),
            _ => None,
        }),
        textured,
        undefined,
    }
}

/// Offset of sub-ray `i` of the `GRID x GRID` stratified pattern from the pixel centre.
fn subpixel_offset(i: u32) -> Vec2 {
    let cell = |k: u32| (k as f32 + 0.5) / GRID as f32 - 0.5;
    Vec2::new(cell(i % GRID), cell(i / GRID))
}

fn fit_pixel(scene: &FrameScene, camera: &Camera, px: f32, py: f32) -> PixelFit {
    let Some(centre) = scene.probe::<NoLod>(camera, px, py) else {
        return PixelFit::Untextured;
    };
    let size = DVec2::new(centre.texture_size.0 as f64, centre.texture_size.1 as f64);
    let samples: Vec<(DVec2, DVec2)> = (0..GRID * GRID)
        .filter_map(|i| {
            let offset = subpixel_offset(i);
            let p = scene.probe::<NoLod>(camera, px + offset.x, py + offset.y)?;
            same_surface(&centre, &p).then(|| (offset.as_dvec2(), p.uv.as_dvec2() * size))
        })
        .collect();
    if samples.len() < MIN_KEPT {
        return PixelFit::Undefined;
    }
    let Some(gradients) = fit_texel_gradients(&samples) else {
        return PixelFit::Undefined;
    };
    let clamp = |level: f32| clamp_to_pyramid(level, &centre);
    let anisotropic = clamp(gradients.anisotropic().0);
    let elliptical = clamp(gradients.elliptical().level);
    PixelFit::Levels {
        longest_axis: ReferenceLevel {
            isotropic: clamp(gradients.isotropic_level()),
            anisotropic,
            elliptical,
        },
        area: ReferenceLevel {
            isotropic: clamp(area_level(&gradients)),
            anisotropic,
            elliptical,
        },
    }
}

/// Whether a sub-ray's textured hit is on the centre ray's surface: same material and
/// texture, reached through the same number of mirror and glass bounces.
fn same_surface(centre: &LodProbe, p: &LodProbe) -> bool {
    p.material == centre.material
        && p.texture == centre.texture
        && p.chain.bends().len() == centre.chain.bends().len()
}

/// Least-squares affine fit `texel = a + J_x dx + J_y dy` over `(offset, texel)` samples;
/// `None` for collinear offsets, a non-finite fit, or a residual above
/// `MAX_RESIDUAL_SHARE` of the longest axis.
fn fit_texel_gradients(samples: &[(DVec2, DVec2)]) -> Option<TexelGradients> {
    let n = samples.len() as f64;
    let mean_offset = samples.iter().map(|s| s.0).sum::<DVec2>() / n;
    let mean_texel = samples.iter().map(|s| s.1).sum::<DVec2>() / n;
    // Centred normal equations: [sxx sxy; sxy syy] [J_x J_y]^T = [sxt; syt].
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    let (mut sxt, mut syt) = (DVec2::ZERO, DVec2::ZERO);
    for &(o, t) in samples {
        let (o, t) = (o - mean_offset, t - mean_texel);
        sxx += o.x * o.x;
        sxy += o.x * o.y;
        syy += o.y * o.y;
        sxt += t * o.x;
        syt += t * o.y;
    }
    let det = sxx * syy - sxy * sxy;
    if !(det > 1e-9 * (sxx * syy).max(f64::MIN_POSITIVE)) {
        return None;
    }
    let jx = (sxt * syy - syt * sxy) / det;
    let jy = (syt * sxx - sxt * sxy) / det;
    let residual = samples
        .iter()
        .map(|&(o, t)| {
            let o = o - mean_offset;
            (t - mean_texel - jx * o.x - jy * o.y).length()
        })
        .fold(0.0, f64::max);
    let longest = jx.length().max(jy.length());
    let fits = residual <= MAX_RESIDUAL_SHARE * longest;
    (jx.is_finite() && jy.is_finite() && fits).then(|| TexelGradients {
        dx: jx.as_vec2(),
        dy: jy.as_vec2(),
    })
}

/// The area-preserving level: `0.5 log2 |J_x x J_y|`, the side of the square of the
/// footprint's area (very negative for a degenerate footprint, clamped later).
fn area_level(g: &TexelGradients) -> f32 {
    let area = (g.dx.x as f64 * g.dy.y as f64 - g.dx.y as f64 * g.dy.x as f64).abs();
    (0.5 * area.max(1e-30).log2()) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_samples(texel: impl Fn(DVec2) -> DVec2) -> Vec<(DVec2, DVec2)> {
        (0..GRID * GRID)
            .map(|i| {
                let o = subpixel_offset(i).as_dvec2();
                (o, texel(o))
            })
            .collect()
    }

    #[test]
    fn an_affine_footprint_is_fitted_exactly() {
        let (jx, jy) = (DVec2::new(3.0, 1.0), DVec2::new(-0.5, 2.0));
        let samples = grid_samples(|o| DVec2::new(10.0, 20.0) + jx * o.x + jy * o.y);
        let g = fit_texel_gradients(&samples).unwrap();
        assert!((g.dx.as_dvec2() - jx).length() < 1e-9 && (g.dy.as_dvec2() - jy).length() < 1e-9);
        // Longest axis |(3, 1)| = 3.16; area |3 * 2 + 0.5| = 6.5.
        assert!((g.isotropic_level() - 10f32.sqrt().log2()).abs() < 1e-5);
        assert!((area_level(&g) - 0.5 * 6.5f32.log2()).abs() < 1e-6);
    }

    #[test]
    fn a_fit_survives_missing_rays_but_not_collinear_ones_or_a_seam() {
        let j = DVec2::new(2.0, 0.0);
        let affine = |o: DVec2| j * o.x + DVec2::new(0.0, 4.0) * o.y;
        // A silhouette cut off the left half: the right half still fits exactly.
        let half: Vec<_> = grid_samples(affine)
            .into_iter()
            .filter(|s| s.0.x > 0.0)
            .collect();
        let g = fit_texel_gradients(&half).unwrap();
        assert!((g.dx.as_dvec2() - j).length() < 1e-9);
        // One column only: no x information.
        let column: Vec<_> = grid_samples(affine)
            .into_iter()
            .filter(|s| s.0.x < -0.3)
            .collect();
        assert!(fit_texel_gradients(&column).is_none());
        // A seam: the right half jumps by a whole texture (1000 texels).
        let seam = grid_samples(|o| affine(o) + DVec2::X * if o.x > 0.0 { 1000.0 } else { 0.0 });
        assert!(fit_texel_gradients(&seam).is_none());
        // Gentle curvature (a 5% change of the slope across the pixel) still fits.
        let curved = grid_samples(|o| affine(o) + DVec2::X * 0.1 * o.x * o.x);
        assert!(fit_texel_gradients(&curved).is_some());
    }
}
