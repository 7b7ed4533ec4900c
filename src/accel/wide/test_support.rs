//! Trees and rays shared by the wide tree's tests (and the pseudo-random stream the
//! triangle packs' tests use too).

use glam::Vec3A;
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    bvh2::{Bvh2, builder::build_bvh2},
};
use std::time::Duration;

use super::{RayBoxes, WideBvh};

/// A xorshift64 stream.
pub fn xorshift(mut seed: u64) -> impl FnMut() -> u64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    }
}

/// Floats in `[low, low + span)` from [`xorshift`] (24 bits each).
pub fn uniform(seed: u64, low: f32, span: f32) -> impl FnMut() -> f32 {
    let mut next = xorshift(seed);
    move || (next() >> 40) as f32 / (1u64 << 24) as f32 * span + low
}

/// A row of unit boxes along x.
pub fn boxes(n: usize) -> Vec<Aabb> {
    (0..n)
        .map(|i| {
            let x = i as f32 * 2.0;
            Aabb::new(Vec3A::new(x, 0.0, 0.0), Vec3A::new(x + 1.0, 1.0, 1.0))
        })
        .collect()
}

pub fn build(n: usize) -> Bvh2 {
    let mut params = BvhBuildParams::medium_build();
    params.max_prims_per_leaf = 1;
    build_bvh2(&boxes(n), params, &mut Duration::default())
}

/// Every leaf slot the walk reaches.
pub fn reached(wide: &WideBvh, origin: Vec3A, direction: Vec3A) -> Vec<u32> {
    let mut out = Vec::new();
    wide.traverse(
        &RayBoxes::new(origin, direction),
        f32::INFINITY,
        |first: u32, count: u32, _: &mut f32| {
            out.extend(first..first + count);
            true
        },
    );
    out.sort();
    out
}
