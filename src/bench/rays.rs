//! `mipray bench --rays primary|shadow|all`: the tracing rate alone, per kind of ray, with
//! no shading, so that traversal and hit-test work is measured apart from everything else a
//! frame pays for (the number `side_by_side.sh` compares with Embree includes shading).
//!
//! Each frame is prepared once (animation, tree update); its rays are generated before the
//! clock starts: primary rays through pixel centres, and from every primary hit the shadow
//! ray toward every light exactly as the integrator spawns it (`render::shadow_ray_toward`).
//! Primary rays are closest-hit queries; shadow rays are occlusion queries that stop at the
//! first hit. Thread counts and repeats are interleaved as in the frame bench.

use std::fmt::Write;
use std::time::Instant;

use anyhow::Result;
use glam::Vec3A;
use rayon::prelude::*;

use crate::accel::PACKET;
use crate::frame::Renderer;
use crate::percentiles::Percentiles;
use crate::render::film::TILE;
use crate::render::{SceneBvh, shadow_ray_toward};

/// Which rays `--rays` times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RayKinds {
    Primary,
    Shadow,
    All,
}

impl RayKinds {
    fn includes(self, kind: RayKind) -> bool {
        matches!(
            (self, kind),
            (RayKinds::All, _)
                | (RayKinds::Primary, RayKind::Primary | RayKind::PrimarySingle)
                | (RayKinds::Shadow, RayKind::Shadow)
        )
    }
}

/// One kind of ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayKind {
    /// Primary rays in packets, as the film traces them.
    Primary,
    /// The same rays one at a time (what packets are measured against).
    PrimarySingle,
    Shadow,
}

impl std::fmt::Display for RayKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            RayKind::Primary => "primary (packets)",
            RayKind::PrimarySingle => "primary (single)",
            RayKind::Shadow => "shadow",
        })
    }
}

/// A ray to time: origin, unit direction, search distance.
type TimedRay = (Vec3A, Vec3A, f32);

/// The rays of one frame.
struct FrameRays {
    primary: Vec<TimedRay>,
    shadow: Vec<TimedRay>,
}

/// Rate of one kind of ray at one thread count, over repeats.
#[derive(Debug, Clone)]
pub struct RayRate {
    pub kind: RayKind,
    pub threads: usize,
    /// Rays per repeat (all frames).
    pub rays: usize,
    /// Share of rays that hit (primary) or were blocked (shadow), from the first repeat.
    pub hit_share: f64,
    pub rays_per_second: Percentiles,
}

/// Traces the rays of every frame of `renderer`'s scene for each thread count, `repeats`
/// times, and reports the rate per kind.
pub fn run_ray_bench(
    renderer: &mut Renderer,
    frames: std::ops::Range<u32>,
    clock: crate::frame::FrameClock,
    kinds: RayKinds,
    threads: &[usize],
    repeats: usize,
) -> Result<Vec<RayRate>> {
    let pools = threads
        .iter()
        .map(|&t| rayon::ThreadPoolBuilder::new().num_threads(t).build())
        .collect::<Result<Vec<_>, _>>()?;
    let mut rates = Vec::new();
    for kind in [RayKind::Primary, RayKind::PrimarySingle, RayKind::Shadow] {
        if !kinds.includes(kind) {
            continue;
        }
        // seconds[thread config][repeat], summed over frames; hits from the first repeat
        let mut seconds = vec![vec![0.0f64; repeats]; threads.len()];
        let (mut rays, mut hits) = (0usize, 0usize);
        for frame in frames.clone() {
            let prepared = renderer.prepare(frame, clock.time(frame))?;
            let generated = frame_rays(renderer, &prepared);
            let list = match kind {
                RayKind::Primary | RayKind::PrimarySingle => &generated.primary,
                RayKind::Shadow => &generated.shadow,
            };
            rays += list.len();
            let bvh = renderer.frame_scene(&prepared).bvh;
            for repeat in 0..repeats {
                for k in 0..threads.len() {
                    let c = (k + repeat) % threads.len();
                    let start = Instant::now();
                    let n = pools[c].install(|| trace_all(kind, &bvh, list));
                    seconds[c][repeat] += start.elapsed().as_secs_f64();
                    if repeat == 0 && k == 0 {
                        hits += n;
                    }
                }
            }
        }
        for (c, &t) in threads.iter().enumerate() {
            rates.push(RayRate {
                kind,
                threads: t,
                rays,
                hit_share: hits as f64 / rays.max(1) as f64,
                rays_per_second: Percentiles::of(
                    seconds[c].iter().map(|s| rays as f64 / s.max(1e-9)),
                ),
            });
        }
    }
    Ok(rates)
}

/// Primary rays through every pixel centre, tile by tile in the film's order (so packets
/// group the same rays as in a render), and the shadow rays of their hits.
fn frame_rays(renderer: &Renderer, prepared: &crate::frame::PreparedFrame) -> FrameRays {
    let camera = &prepared.camera;
    let scene = renderer.frame_scene(prepared);
    let (w, h) = (camera.width, camera.height);
    let tiles_x = w.div_ceil(TILE);
    let primary: Vec<TimedRay> = (0..tiles_x * h.div_ceil(TILE))
        .flat_map(|tile| {
            let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
            (y0..(y0 + TILE).min(h))
                .flat_map(move |y| (x0..(x0 + TILE).min(w)).map(move |x| (x, y)))
        })
        .map(|(x, y)| {
            let d = camera.primary_direction(x as f32 + 0.5, y as f32 + 0.5);
            (camera.eye, d, f32::INFINITY)
        })
        .collect();
    let shadow = primary
        .par_iter()
        .flat_map_iter(|&(o, d, t_max)| {
            let hit = scene.bvh.closest_hit(o, d, t_max);
            let scene = &scene;
            prepared
                .lights
                .iter()
                .filter_map(move |light| shadow_ray_toward(scene, hit?, o, d, light))
        })
        .collect();
    FrameRays { primary, shadow }
}

/// Traces `rays` on the current pool; returns how many hit (primary) or were blocked
/// (shadow).
fn trace_all(kind: RayKind, bvh: &SceneBvh, rays: &[TimedRay]) -> usize {
    rays.par_chunks(1024)
        .map(|chunk| match kind {
            RayKind::Primary => chunk
                .chunks(PACKET)
                .map(|packet| {
                    let mut pairs = [(Vec3A::ZERO, Vec3A::ZERO); PACKET];
                    for (pair, &(o, d, _)) in pairs.iter_mut().zip(packet) {
                        *pair = (o, d);
                    }
                    let mut hits = [None; PACKET];
                    let n = packet.len();
                    bvh.closest_hits(&pairs[..n], f32::INFINITY, &mut hits[..n]);
                    hits[..n].iter().filter(|h| h.is_some()).count()
                })
                .sum(),
            RayKind::PrimarySingle => chunk
                .iter()
                .filter(|&&(o, d, t_max)| bvh.closest_hit(o, d, t_max).is_some())
                .count(),
            RayKind::Shadow => chunk
                .iter()
                .filter(|&&(o, d, t_max)| !bvh.visit_hits(o, d, t_max, |_, _, _| false))
                .count(),
        })
        .sum()
}

/// A Markdown table of ray rates.
pub fn ray_table(rates: &[RayRate]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| rays | threads | count | hit or blocked | Mrays/s (median) | min..max |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|");
    for r in rates {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.1}% | {:.3} | {:.3}..{:.3} |",
            r.kind,
            r.threads,
            r.rays,
            100.0 * r.hit_share,
            r.rays_per_second.median / 1e6,
            r.rays_per_second.min / 1e6,
            r.rays_per_second.max / 1e6
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_select_what_they_name() {
        assert!(
            RayKinds::All.includes(RayKind::Primary) && RayKinds::All.includes(RayKind::Shadow)
        );
        assert!(RayKinds::Primary.includes(RayKind::Primary));
        assert!(RayKinds::Primary.includes(RayKind::PrimarySingle));
        assert!(!RayKinds::Primary.includes(RayKind::Shadow));
        assert!(!RayKinds::Shadow.includes(RayKind::Primary));
    }
}
