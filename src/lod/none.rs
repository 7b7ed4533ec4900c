//! `none`: no MIP-mapping, bilinear at level 0 (the RTG baseline). Carries nothing.

use glam::Vec3A;

use super::{Footprint, LodCamera, LodMethod, RayLod, SurfaceHit};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NoLod;

impl RayLod for NoLod {
    const METHOD: LodMethod = LodMethod::None;
    const BYTES: usize = 0;
    type Kept = ();

    #[inline]
    fn primary(_: &LodCamera, _: f32, _: f32) -> Self {
        NoLod
    }

    #[inline]
    fn arrive(&mut self, _: &SurfaceHit) {}

    #[inline]
    fn footprint(&self, _: &SurfaceHit, _: &LodCamera, _: (u32, u32)) -> Footprint {
        Footprint::Base
    }

    #[inline]
    fn reflect(&self, _: &SurfaceHit, _: Vec3A) -> Self {
        NoLod
    }

    #[inline]
    fn refract(&self, _: &SurfaceHit, _: f32, _: Vec3A) -> Self {
        NoLod
    }
}
