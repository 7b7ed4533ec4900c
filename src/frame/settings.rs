//! How frames are rendered: the options every command turns into a [`RenderSettings`].

use crate::accel::{BvhLayout, BvhPolicy};
use crate::anim::AnimationSelection;
use crate::lod::LodMethod;
use crate::texture::MipFilter;

/// How frames are rendered (the CLI's render options).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub lod: LodMethod,
    /// Levels added to every MIP-mapped lookup (`--lod-bias`; `none` ignores it).
    pub lod_bias: f32,
    /// How every texture's lookups read its MIP levels (`--mip-filter`); `None`: as each
    /// texture's sampler says (the file's, trilinear where it says nothing).
    pub mip_filter: Option<MipFilter>,
    /// Samples per pixel (stratified).
    pub spp: u32,
    /// Maximum number of reflection/refraction bounces.
    pub max_depth: u32,
    /// Number of lights: the scene's first N, plus ring lights when it has fewer.
    /// `None`: all of the scene's lights (at least one).
    pub lights: Option<usize>,
    pub bvh: BvhPolicy,
    /// Flat, two-level or decided per mesh (`--bvh auto`, the default).
    pub layout: BvhLayout,
    /// Which clips play (`--animation`).
    pub animation: AnimationSelection,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 640,
            height: 360,
            lod: LodMethod::Paper,
            lod_bias: 0.0,
            mip_filter: None,
            spp: 1,
            max_depth: 5,
            lights: None,
            bvh: BvhPolicy::Refit {
                rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
            },
            layout: BvhLayout::Auto,
            animation: AnimationSelection::All,
        }
    }
}
