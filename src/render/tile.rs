//! One tile of the film traced breadth first: every sample's primary ray, then every hit's
//! shadow rays, then every reflected and refracted ray, bounce by bounce, so that rays
//! that share a light or a direction are traced together as packets.
//!
//! A tile holds its rays as path vertices: a sample's primary ray is vertex `k` for the
//! `k`-th sample (pixels in Morton order within the tile, so that a packet of the first
//! bounce is a compact block of pixels; each pixel's samples in order), and the rays a hit
//! spawns get the next free numbers, so a vertex's children always come after it. Each
//! bounce:
//! 1. the pending rays are traced as packets of up to [`PACKET`] (the primary rays from the
//!    camera with interval bounds, later bounces from their hits by the masked walk);
//! 2. each hit's surface is made (from its triangle, read as its packet's hits came back)
//!    and its texture looked up (`FrameScene::arrive_at`), which lists the shadow rays its
//!    direct light needs;
//! 3. the shadow rays are traced, grouped by light, as packets of up to [`PACKET`]
//!    ([`SceneBvh::visit_hits_packet`]: rays from a tile's hits converge on the light);
//! 4. each hit's own light is summed and its reflected and refracted rays are spawned
//!    (`FrameScene::finish`), which become the next bounce's pending rays.
//!
//! Then every vertex's radiance is combined from its children's, last vertex first. The
//! image is bit for bit what tracing each sample depth first gives: every ray and every
//! lookup is the same, shadow rays meet the same surfaces (their order does not matter:
//! glass is multiplied in distance order), and `Combine` adds children in the recursion's
//! order. Memory: a tile's vertices and its current bounce's hits, cleared per tile.

use glam::{Vec3, Vec3A};

use crate::accel::{Hit, PACKET};
use crate::geometry::HitTriangle;
use crate::lod::RayLod;
use crate::render::camera::Camera;
use crate::render::film::{TILE, sample_offset, tile_pixels};
use crate::render::integrator::{
    Arrival, Combine, FrameScene, MAX_SHADOW_GLASS, ShadowRequest, Spawned, TraceCounters,
};
use crate::render::ray_log::RayClass;
use crate::simd::Kernel;

/// A hit waiting for its shadow rays: the sample's pixel and its requests
/// (`requests[first..end]`). Its vertex is its ray's: the bounce's hits wait in their rays'
/// order.
struct Waiting<L: RayLod> {
    arrival: Arrival<L>,
    pixel: u32,
    first: usize,
    end: usize,
}

/// A tile's working lists, kept by a worker from one tile to the next: a tile fills them
/// to a few thousand entries (an `Arrival` is a few hundred bytes), and growing them afresh
/// for every tile copied them over and over (3% of a BART Kitchen frame in `memmove`).
/// Every list is cleared before use, so what a tile computes does not depend on the tile
/// before it.
pub(super) struct TileBuffers<L: RayLod> {
    samples: Vec<(u32, u32, u32)>,
    vertices: Vec<Combine>,
    /// The bounce's rays and their hits, in the same order. Each is written in place by
    /// what makes it (the shading spawns the rays into the next bounce's list, the walks
    /// write the hits): entries copied from one list into another were built or freshly
    /// stored with narrow fields and read back as 16-byte loads, which the CPU cannot
    /// forward (a stall per ray). A bounce's rays need no list of where they belong: they
    /// are the vertices numbered from the bounce's first on, in order, all as deep as the
    /// bounce (see the module doc), and each carries its sample's pixel.
    rays: Vec<Spawned<L>>,
    hits: Vec<Option<Hit>>,
    next_rays: Vec<Spawned<L>>,
    waiting: Vec<Waiting<L>>,
    requests: Vec<ShadowRequest>,
    /// Per light, the indices of the requests toward it that have a ray, in request order.
    of_light: Vec<Vec<u32>>,
    pixel_of: Vec<u32>,
    /// The bounce's hit triangles, one per hit in `hits`' order, read as each packet's
    /// hits come back: a short loop whose loads (a slot's vertices, normals, uvs,
    /// material, `log2 P_b`) can overlap from hit to hit, where reading them at the start
    /// of each hit's shading put them at the head of its long dependent arithmetic. Faster
    /// in the `bench` build, within the noise in the release build (docs/benchmark-log.md).
    triangles: Vec<HitTriangle>,
    /// Where the method's level needs only the hit's distance ([`RayLod::LEVEL_AT_DISTANCE`]):
    /// the bounce's levels, one per ray in `rays`' order (a miss's is never read), computed
    /// a packet at a time as its hits come back, long before the hits' arrivals need them.
    /// Made on arrival, the logarithm (a division and a polynomial) headed the chain of
    /// dependent work that plans the hit's lookup; there it overlaps the walks. A packet's
    /// levels are one loop over arrays of its rays' states, distances and `log2 P_b`, which
    /// the compiler vectorises (eight lanes in the AVX2 copy; the same operations lane by
    /// lane, so the same bits), where one level per hit, pushed, cost about 30 instructions
    /// (docs/benchmark-log.md).
    levels: Vec<f32>,
}

impl<L: RayLod> Default for TileBuffers<L> {
    fn default() -> Self {
        TileBuffers {
            samples: Vec::new(),
            vertices: Vec::new(),
            rays: Vec::new(),
            hits: Vec::new(),
            next_rays: Vec::new(),
            waiting: Vec::new(),
            requests: Vec::new(),
            of_light: Vec::new(),
            pixel_of: Vec::new(),
            triangles: Vec::new(),
            levels: Vec::new(),
        }
    }
}

/// [`trace_tile`] as a kernel: the tile's loop and everything it inlines (the surfaces,
/// shading, the bookkeeping of vertices and shadow requests, a planned texture lookup's
/// plan and filter, which take the tile's copy as `AVX2`) compiled into each SIMD copy, so
/// that the copy with AVX2 runs it too. The walks, called once per packet or batch, go
/// through their own dispatch. The same bits in both copies: no operation is fused.
///
/// Why: about a third of a BART Kitchen frame's instructions are this loop's, and the
/// baseline copy computes them with SSE2 alone (two-operand forms and their register
/// copies, floors as library calls, masks counted bit by bit).
pub(super) struct TraceTile<'a, 'b, L: RayLod> {
    pub scene: &'a FrameScene<'a>,
    pub camera: &'a Camera,
    pub spp: u32,
    pub corner: (u32, u32),
    pub counters: &'a mut TraceCounters,
    pub buffers: &'a mut TileBuffers<L>,
    pub rows: &'a mut [&'b mut [Vec3]],
}

impl<L: RayLod> Kernel for TraceTile<'_, '_, L> {
    type Output = ();
    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        trace_tile::<L, AVX2>(
            self.scene,
            self.camera,
            self.spp,
            self.corner,
            self.counters,
            self.buffers,
            self.rows,
        )
    }
}

/// Renders the tile whose corner is `(x0, y0)` into `rows` (its rows of the frame, top to
/// bottom, each as wide as the tile), tracing its pixels in the order of [`tile_pixels`],
/// with the LOD state `L`, using `buffers` for its lists; its texture lookups run in the
/// SIMD copy `AVX2` names (the kernel's own).
#[inline(always)]
fn trace_tile<L: RayLod, const AVX2: bool>(
    scene: &FrameScene,
    camera: &Camera,
    spp: u32,
    (x0, y0): (u32, u32),
    counters: &mut TraceCounters,
    buffers: &mut TileBuffers<L>,
    rows: &mut [&mut [Vec3]],
) {
    let TileBuffers {
        samples,
        vertices,
        rays,
        hits,
        next_rays,
        waiting,
        requests,
        of_light,
        pixel_of,
        triangles,
        levels,
    } = buffers;
    let x1 = (x0 + TILE).min(camera.width);
    let y1 = (y0 + TILE).min(camera.height);
    samples.clear();
    samples.extend(
        tile_pixels((x0, y0), camera.width, camera.height)
            .flat_map(|(x, y)| (0..spp).map(move |i| (x, y, i))),
    );
    debug_assert_eq!(samples.len(), ((x1 - x0) * (y1 - y0) * spp) as usize);
    vertices.clear();
    primary_bounce::<L>(
        scene, camera, spp, samples, counters, rays, hits, triangles, levels,
    );
    // The bounce's rays are vertices `first_vertex..` in order, each `depth` bounces deep;
    // the vertices before them are made (`vertices.len() == first_vertex`).
    let (mut first_vertex, mut depth) = (0u32, 0u32);
    while !rays.is_empty() {
        debug_assert_eq!(vertices.len(), first_vertex as usize);
        // Arrive at every hit (a miss waits for nothing).
        waiting.clear();
        requests.clear();
        let mut hit_triangles = triangles.iter();
        for (i, (ray, &hit)) in rays.iter().zip(hits.iter()).enumerate() {
            let Some(hit) = hit else {
                continue;
            };
            let triangle = hit_triangles.next().expect("a triangle per hit");
            let level_ahead = if L::LEVEL_AT_DISTANCE {
                Some(levels[i])
            } else {
                None
            };
            let first = requests.len();
            // Made in place (see `Arrival::unmade`).
            waiting.push(Waiting {
                arrival: Arrival::unmade(triangle, hit, ray.origin, ray.direction, ray.lod, depth),
                pixel: ray.pixel,
                first,
                end: first,
            });
            let w = waiting.last_mut().expect("a waiting hit was just pushed");
            scene.arrive_at::<L, AVX2>(triangle, &mut w.arrival, level_ahead, requests, counters);
            w.end = requests.len();
        }
        trace_shadows(scene, waiting, requests, counters, of_light, pixel_of);
        // Make the bounce's vertices in their rays' order: a miss is the background, a hit
        // is finished, which spawns the next bounce's rays, numbered on from the bounce's
        // last vertex in the order they are spawned.
        next_rays.clear();
        let next_first = first_vertex + rays.len() as u32;
        // Checked, not assumed: `set_len` below relies on it.
        assert_eq!(hits.len(), rays.len(), "a hit entry per ray");
        vertices.reserve(rays.len());
        let mut finishing = waiting.iter();
        // Each vertex is written once, where its hit is finished, into the list's spare
        // room: setting the bounce's vertices empty beforehand (a resize) stored to lines
        // the tile's walks had evicted in a tight loop that waited on them (1% of a Kitchen
        // frame), and pushing them one by one cost a length update each.
        for (slot, hit) in vertices.spare_capacity_mut()[..rays.len()]
            .iter_mut()
            .zip(hits.iter())
        {
            if hit.is_none() {
                slot.write(Combine::leaf(scene.background));
                continue;
            }
            let w = finishing.next().expect("a waiting hit per hit");
            // In place: a combine made on the stack and then copied stalled on reading its
            // small fields' fresh stores back as 16-byte loads.
            let vertex = slot.write(Combine::EMPTY);
            scene.finish::<L, AVX2>(
                &w.arrival,
                &requests[w.first..w.end],
                next_first + next_rays.len() as u32,
                w.pixel,
                next_rays,
                vertex,
            );
        }
        // SAFETY: the loop above wrote every one of the `rays.len()` slots after the
        // vertices made so far (it zips them with `hits`, as long as `rays` by the assert),
        // all within the room reserved; had `finish` panicked, the length would be unchanged.
        unsafe { vertices.set_len(next_first as usize) };
        (first_vertex, depth) = (next_first, depth + 1);
        std::mem::swap(rays, next_rays);
        trace_bounce(scene, rays, counters, hits, triangles, levels);
    }
    // Last vertex first: children are numbered after their parents.
    for v in (0..vertices.len()).rev() {
        let radiance = vertices[v].evaluate(|child| vertices[child as usize].radiance());
        vertices[v].set_radiance(radiance);
    }
    debug_assert!(rows.len() == (y1 - y0) as usize);
    debug_assert!(rows.iter().all(|row| row.len() == (x1 - x0) as usize));
    let mut sum = Vec3A::ZERO;
    for (k, vertex) in vertices[..samples.len()].iter().enumerate() {
        let radiance = vertex.radiance();
        if radiance.is_finite() {
            sum += radiance.max(Vec3A::ZERO);
        } else {
            counters.nonfinite_samples += 1;
        }
        if (k as u32 + 1) % spp == 0 {
            let (x, y, _) = samples[k];
            rows[(y - y0) as usize][(x - x0) as usize] = Vec3::from(sum / spp as f32);
            sum = Vec3A::ZERO;
        }
    }
}

/// The samples' primary rays into `rays` (in the samples' order), traced as packets of up to
/// [`PACKET`] (an 8 x 8 block of a whole tile at one sample per pixel), their hits into
/// `hits`, each hit's triangle into `triangles` and, with [`RayLod::LEVEL_AT_DISTANCE`], its
/// level into `levels` (all four cleared first).
#[allow(clippy::too_many_arguments)]
// Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
#[inline(always)]
fn primary_bounce<L: RayLod>(
    scene: &FrameScene,
    camera: &Camera,
    spp: u32,
    samples: &[(u32, u32, u32)],
    counters: &mut TraceCounters,
    rays: &mut Vec<Spawned<L>>,
    hits: &mut Vec<Option<Hit>>,
    triangles: &mut Vec<HitTriangle>,
    levels: &mut Vec<f32>,
) {
    rays.clear();
    rays.extend(samples.iter().map(|&(x, y, i)| {
        let (sx, sy) = sample_offset(x, y, i, spp);
        let (px, py) = (x as f32 + sx, y as f32 + sy);
        Spawned {
            class: RayClass::Primary,
            pixel: y * camera.width + x,
            origin: camera.eye,
            direction: camera.primary_direction(px, py),
            lod: L::primary(&scene.lod_camera, px, py),
        }
    }));
    trace_packets(
        scene,
        rays,
        counters,
        hits,
        triangles,
        levels,
        |rays, hits| scene.bvh.closest_hits(rays, f32::INFINITY, hits),
    );
}

/// A bounce's reflected and refracted rays (`rays`, in the order they were spawned) traced
/// as packets of up to [`PACKET`] (`SceneBvh::closest_hits_scattered`: each ray finds
/// exactly what it finds alone), their hits into `hits`, each hit's triangle into
/// `triangles` and, with [`RayLod::LEVEL_AT_DISTANCE`], its level into `levels` (all three
/// cleared first).
// Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
#[inline(always)]
fn trace_bounce<L: RayLod>(
    scene: &FrameScene,
    rays: &[Spawned<L>],
    counters: &mut TraceCounters,
    hits: &mut Vec<Option<Hit>>,
    triangles: &mut Vec<HitTriangle>,
    levels: &mut Vec<f32>,
) {
    trace_packets(
        scene,
        rays,
        counters,
        hits,
        triangles,
        levels,
        |rays, hits| scene.bvh.closest_hits_scattered(rays, f32::INFINITY, hits),
    );
}

/// `rays` traced by `closest` in packets of up to [`PACKET`], the hits written in place into
/// `hits` (cleared and sized first); each ray counted and logged, and each hit's triangle
/// appended to `triangles` (cleared first) as its packet's hits come back, and with
/// [`RayLod::LEVEL_AT_DISTANCE`] each ray's level written to `levels` (cleared and sized
/// first; ray `i`'s at `i`, a miss's never read). Reading a hit's triangle may replace its
/// distance and barycentrics (`SceneBvh::hit_triangle`); the log records the hit as the
/// walk returned it.
#[inline(always)]
fn trace_packets<L: RayLod>(
    scene: &FrameScene,
    rays: &[Spawned<L>],
    counters: &mut TraceCounters,
    hits: &mut Vec<Option<Hit>>,
    triangles: &mut Vec<HitTriangle>,
    levels: &mut Vec<f32>,
    mut closest: impl FnMut(&[(Vec3A, Vec3A)], &mut [Option<Hit>]),
) {
    hits.clear();
    hits.resize(rays.len(), None);
    triangles.clear();
    levels.clear();
    if L::LEVEL_AT_DISTANCE {
        levels.resize(rays.len(), f32::NAN);
    }
    let mut packet_rays = [(Vec3A::ZERO, Vec3A::ZERO); PACKET];
    for (first, (packet, packet_hits)) in (0..)
        .step_by(PACKET)
        .zip(rays.chunks(PACKET).zip(hits.chunks_mut(PACKET)))
    {
        for (traced, ray) in packet_rays.iter_mut().zip(packet) {
            *traced = (ray.origin, ray.direction);
        }
        closest(&packet_rays[..packet.len()], packet_hits);
        // The packet's level inputs, lane `i` for its ray `i` (a miss's lane keeps a
        // placeholder: its level is computed and never read).
        let mut states = [packet[0].lod; PACKET];
        let (mut distance, mut log2_pb) = ([0.0f32; PACKET], [0.0f32; PACKET]);
        // Zipped, not indexed: the packet's length is not known to be at most `PACKET`, so
        // each indexed store was a bounds check.
        let lanes = states
            .iter_mut()
            .zip(distance.iter_mut().zip(log2_pb.iter_mut()));
        for ((ray, hit), (state, (distance, log2_pb))) in packet.iter().zip(packet_hits).zip(lanes)
        {
            counters.rays += 1;
            if let Some(log) = &mut counters.log {
                log.closest(
                    ray.pixel,
                    ray.class,
                    ray.origin,
                    ray.direction,
                    f32::INFINITY,
                    *hit,
                );
            }
            if let Some(hit) = hit {
                let triangle = scene.push_hit_triangle(hit, ray.origin, ray.direction, triangles);
                if L::LEVEL_AT_DISTANCE {
                    // The settled hit's distance (reading the triangle may replace it), as
                    // the arrival's `RayLod::arrive` reads it.
                    (*state, *distance, *log2_pb) = (ray.lod, hit.t, triangle.log2_pb);
                }
            }
        }
        if L::LEVEL_AT_DISTANCE {
            // Every lane, a whole packet's worth: a loop of fixed length over arrays, which
            // the compiler vectorises.
            let mut level = [0.0f32; PACKET];
            for (i, level) in level.iter_mut().enumerate() {
                *level = states[i].level_at_distance(distance[i], log2_pb[i]);
            }
            levels[first..first + packet.len()].copy_from_slice(&level[..packet.len()]);
        }
    }
}

/// Traces every request's shadow ray and fills in its transmittance: per light, the
/// requests in the order they were made, as packets of up to [`PACKET`]. `of_light` and
/// `pixel_of` are working lists (their contents on entry do not matter).
///
/// The requests are sorted by light in one pass: a pass over all of them for each light
/// cost a frame with six lights about 5% of its instructions (BART Kitchen).
// Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
#[inline(always)]
fn trace_shadows<L: RayLod>(
    scene: &FrameScene,
    waiting: &[Waiting<L>],
    requests: &mut [ShadowRequest],
    counters: &mut TraceCounters,
    of_light: &mut Vec<Vec<u32>>,
    pixel_of: &mut Vec<u32>,
) {
    // The pixel each request serves (for the ray log).
    pixel_of.clear();
    if counters.log.is_some() {
        pixel_of.resize(requests.len(), 0);
        for w in waiting {
            pixel_of[w.first..w.end].fill(w.pixel);
        }
    }
    let mut chosen = [0usize; PACKET];
    let mut rays = [(Vec3A::ZERO, Vec3A::ZERO); PACKET];
    let mut t_max = [0.0f32; PACKET];
    let mut glass = [[(0.0f32, 0u32, 0u32); MAX_SHADOW_GLASS]; PACKET];
    of_light.resize_with(scene.lights.len(), Vec::new);
    for list in of_light.iter_mut() {
        list.clear();
    }
    for (i, request) in requests.iter().enumerate() {
        if request.ray.is_some() {
            of_light[request.light as usize].push(i as u32);
        }
    }
    for (light, list) in of_light.iter().enumerate() {
        debug_assert!(
            list.iter()
                .all(|&i| requests[i as usize].light == light as u32)
        );
        for packet in list.chunks(PACKET) {
            let n = packet.len();
            for (k, &index) in packet.iter().enumerate() {
                let index = index as usize;
                let request = &requests[index];
                let (origin, limit) = request.ray.expect("requests with a ray");
                chosen[k] = index;
                rays[k] = (origin, request.incident.to_light);
                t_max[k] = limit;
            }
            let mut met = [0usize; PACKET];
            let stopped =
                scene
                    .bvh
                    .visit_hits_packet(&rays[..n], &t_max[..n], |r, t, m, source| {
                        if !scene.passes_through(m, met[r]) {
                            return false;
                        }
                        glass[r][met[r]] = (t, source, m);
                        met[r] += 1;
                        true
                    });
            for r in 0..n {
                let blocked = stopped & (1 << r) != 0;
                let request = &mut requests[chosen[r]];
                request.transmittance =
                    scene.shadow_transmittance(blocked, &mut glass[r][..met[r]]);
                if let Some(log) = &mut counters.log {
                    let (origin, direction) = rays[r];
                    log.shadow(
                        pixel_of[chosen[r]],
                        origin,
                        direction,
                        t_max[r],
                        blocked || met[r] > 0,
                    );
                }
            }
        }
    }
}
