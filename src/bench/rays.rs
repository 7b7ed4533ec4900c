//! `mipray bench --rays primary|shadow|all`: the tracing rate alone, per kind of ray, with
//! no shading, so that traversal and hit-test work is measured apart from everything else a
//! frame pays for (the number `side_by_side.sh` compares with Embree includes shading).
//!
//! Each frame is prepared once (animation, tree update); its rays are generated before the
//! clock starts: primary rays through pixel centres, and from every primary hit the shadow
//! ray toward every light exactly as the integrator spawns it (`render::shadow_ray_toward`).
//! Primary rays are closest-hit queries; shadow rays are occlusion queries that stop at the
//! first hit. Both are timed as the film traces them (packets: a tile's primary rays, and a
//! tile's shadow rays toward one light) and one ray at a time. Thread counts and repeats are interleaved as in the frame bench.

use std::fmt::Write;
use std::time::{Duration, Instant};

use anyhow::Result;
use glam::Vec3A;
use rayon::prelude::*;

use crate::accel::PACKET;
use crate::export::rays::{MISS, RayRecord, read_ray_file};
use crate::frame::Renderer;
use crate::percentiles::Percentiles;
use crate::render::film::{TILE, film_position, tile_pixels};
use crate::render::memory::check_frame_memory;
use crate::render::{RayClass, SceneBvh, shadow_ray_toward};

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
                | (RayKinds::Shadow, RayKind::Shadow | RayKind::ShadowSingle)
        )
    }
}

/// Which of mipray's ways of tracing `--rays` times: packets (as the film traces each
/// class), one ray at a time, or both. One alone is what an instruction count needs (a
/// profiler counts the whole process, not one row of the table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum RayApi {
    #[default]
    Both,
    Packets,
    Single,
}

impl RayApi {
    /// Whether rays traced in packets (`packets`) or one at a time are timed.
    fn includes(self, packets: bool) -> bool {
        match self {
            RayApi::Both => true,
            RayApi::Packets => packets,
            RayApi::Single => !packets,
        }
    }
}

/// One kind of ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayKind {
    /// Primary rays in packets, as the film traces them.
    Primary,
    /// The same rays one at a time (what packets are measured against).
    PrimarySingle,
    /// Shadow rays in packets, as the film traces them (a tile's rays toward one light).
    Shadow,
    /// The same rays one at a time.
    ShadowSingle,
}

impl RayKind {
    /// Whether its rays are traced in packets (else one at a time).
    fn in_packets(self) -> bool {
        match self {
            RayKind::Primary | RayKind::Shadow => true,
            RayKind::PrimarySingle | RayKind::ShadowSingle => false,
        }
    }
}

impl std::fmt::Display for RayKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            RayKind::Primary => "primary (packets)",
            RayKind::PrimarySingle => "primary (single)",
            RayKind::Shadow => "shadow",
            RayKind::ShadowSingle => "shadow (single)",
        })
    }
}

/// A ray to time: origin, unit direction, search distance, as seven floats (28 bytes).
///
/// Why not `(Vec3A, Vec3A, f32)`: that tuple is 48 bytes, and a frame's rays (11 to 23 MB
/// at 800 x 600) are read from memory as they are timed. Embree's anchor
/// (`../shared/anchors/embree_rays.c`) keeps the same rays as seven float arrays, 28 bytes a
/// ray, so the padded tuple made mipray's side read 1.7 times the bytes per ray; on an
/// Intel Xeon VM that cost its packets 1-9% of their rate (docs/benchmark-log.md). The
/// ray-file bench reads the file's 48-byte records, as that anchor does.
#[derive(Debug, Clone, Copy)]
#[repr(C)]
struct TimedRay {
    origin: [f32; 3],
    direction: [f32; 3],
    t_max: f32,
}

impl TimedRay {
    fn new(origin: Vec3A, direction: Vec3A, t_max: f32) -> TimedRay {
        TimedRay {
            origin: origin.to_array(),
            direction: direction.to_array(),
            t_max,
        }
    }

    /// Origin, direction and search distance, as the walks take them.
    #[inline(always)]
    fn parts(&self) -> (Vec3A, Vec3A, f32) {
        (
            Vec3A::from_array(self.origin),
            Vec3A::from_array(self.direction),
            self.t_max,
        )
    }
}

/// The rays of one frame.
struct FrameRays {
    primary: Vec<TimedRay>,
    shadow: Vec<TimedRay>,
    /// The shadow rays the film traces together: per tile and light, up to [`PACKET`] at a
    /// time, as ranges of `shadow`.
    shadow_packets: Vec<std::ops::Range<usize>>,
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
/// times (each a sample of at least `min_sample`, see `timed_in`), and reports the rate
/// per kind.
pub fn run_ray_bench(
    renderer: &mut Renderer,
    frames: std::ops::Range<u32>,
    clock: crate::frame::FrameClock,
    kinds: RayKinds,
    api: RayApi,
    threads: &[usize],
    repeats: usize,
    min_sample: Duration,
) -> Result<Vec<RayRate>> {
    // A frame's rays are made before they are timed: at least one primary ray a pixel
    // (the shadow rays of their hits come on top).
    if !frames.is_empty() {
        let settings = renderer.settings();
        let per_pixel = std::mem::size_of::<TimedRay>() as u64;
        check_frame_memory(settings.width, settings.height, per_pixel, || {
            "tracing a frame's rays at this size".to_string()
        })?;
    }
    let pools = threads
        .iter()
        .map(|&t| rayon::ThreadPoolBuilder::new().num_threads(t).build())
        .collect::<Result<Vec<_>, _>>()?;
    let mut rates = Vec::new();
    let all = [
        RayKind::Primary,
        RayKind::PrimarySingle,
        RayKind::Shadow,
        RayKind::ShadowSingle,
    ];
    for kind in all {
        if !kinds.includes(kind) || !api.includes(kind.in_packets()) {
            continue;
        }
        // seconds[thread config][repeat], summed over frames; hits from the first repeat
        let mut seconds = vec![vec![0.0f64; repeats]; threads.len()];
        let (mut rays, mut hits) = (0usize, 0usize);
        for frame in frames.clone() {
            let prepared = renderer.prepare(frame, clock.time(frame))?;
            let generated = frame_rays(renderer, &prepared);
            rays += match kind {
                RayKind::Primary | RayKind::PrimarySingle => generated.primary.len(),
                RayKind::Shadow | RayKind::ShadowSingle => generated.shadow.len(),
            };
            let bvh = renderer.frame_scene(&prepared).bvh;
            for repeat in 0..repeats {
                for k in 0..threads.len() {
                    let c = (k + repeat) % threads.len();
                    let (n, s) =
                        timed_in(&pools[c], min_sample, || trace_all(kind, &bvh, &generated));
                    seconds[c][repeat] += s;
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

/// `work`'s result (from its first pass) and the seconds one pass takes, run in `pool` and
/// timed there: passes are made back to back until they have taken at least `min_sample`
/// (one pass when it is zero), and their time is divided by their number.
///
/// Why: `install` from outside the pool hands the work to a sleeping worker and blocks
/// until it is done, and that worker's caches may be cold. Neither is the tracer's cost,
/// but timed from outside around one pass they were most of a small class's spread: BART
/// Kitchen's 2,250 glass rays take under a millisecond a pass, and one thread traced them
/// at 2.1 to 3.5 Mrays/s from one run to the next. Embree's anchor times its passes on the
/// thread that traces, with the same minimum. A class that takes longer than the minimum
/// is timed one pass at a time, as before.
fn timed_in<T: Send>(
    pool: &rayon::ThreadPool,
    min_sample: Duration,
    mut work: impl FnMut() -> T + Send,
) -> (T, f64) {
    pool.install(|| {
        let start = Instant::now();
        let result = work();
        let mut passes = 1u32;
        while start.elapsed() < min_sample {
            work();
            passes += 1;
        }
        (result, start.elapsed().as_secs_f64() / f64::from(passes))
    })
}

/// Primary rays through every pixel centre, tile by tile in the film's order (so packets
/// group the same rays as in a render), and the shadow rays of their hits.
fn frame_rays(renderer: &Renderer, prepared: &crate::frame::PreparedFrame) -> FrameRays {
    let camera = &prepared.camera;
    let scene = renderer.frame_scene(prepared);
    let (w, h) = (camera.width, camera.height);
    let tiles_x = w.div_ceil(TILE);
    // Per tile, its primary rays in the film's pixel order and, per light, the shadow rays
    // of their hits (the film's grouping: `render::tile` traces a tile's requests light by
    // light).
    let per_tile: Vec<(Vec<TimedRay>, Vec<Vec<TimedRay>>)> = (0..tiles_x * h.div_ceil(TILE))
        .into_par_iter()
        .map(|tile| {
            let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
            let primary: Vec<TimedRay> = tile_pixels((x0, y0), w, h)
                .map(|(x, y)| {
                    let d = camera.primary_direction(x as f32 + 0.5, y as f32 + 0.5);
                    TimedRay::new(camera.eye, d, f32::INFINITY)
                })
                .collect();
            let hits: Vec<_> = primary
                .iter()
                .map(|ray| {
                    let (o, d, t_max) = ray.parts();
                    (o, d, scene.bvh.closest_hit(o, d, t_max))
                })
                .collect();
            let shadow = prepared
                .lights
                .iter()
                .map(|light| {
                    hits.iter()
                        .filter_map(|&(o, d, hit)| {
                            let (o, d, t_max) = shadow_ray_toward(&scene, hit?, o, d, light)?;
                            Some(TimedRay::new(o, d, t_max))
                        })
                        .collect()
                })
                .collect();
            (primary, shadow)
        })
        .collect();
    let mut primary = Vec::new();
    let mut shadow = Vec::new();
    let mut shadow_packets = Vec::new();
    for (tile_primary, tile_shadow) in per_tile {
        primary.extend(tile_primary);
        for group in tile_shadow {
            let start = shadow.len();
            shadow.extend(group);
            for at in (start..shadow.len()).step_by(PACKET) {
                shadow_packets.push(at..(at + PACKET).min(shadow.len()));
            }
        }
    }
    FrameRays {
        primary,
        shadow,
        shadow_packets,
    }
}

/// Traces a frame's rays of kind `kind` on the current pool; returns how many hit
/// (primary) or were blocked (shadow).
fn trace_all(kind: RayKind, bvh: &SceneBvh, rays: &FrameRays) -> usize {
    match kind {
        RayKind::Primary => rays
            .primary
            .par_chunks(1024)
            .map(|chunk| {
                chunk
                    .chunks(PACKET)
                    .map(|packet| {
                        let mut pairs = [(Vec3A::ZERO, Vec3A::ZERO); PACKET];
                        for (pair, ray) in pairs.iter_mut().zip(packet) {
                            let (o, d, _) = ray.parts();
                            *pair = (o, d);
                        }
                        let mut hits = [None; PACKET];
                        let n = packet.len();
                        bvh.closest_hits(&pairs[..n], f32::INFINITY, &mut hits[..n]);
                        hits[..n].iter().filter(|h| h.is_some()).count()
                    })
                    .sum::<usize>()
            })
            .sum(),
        RayKind::PrimarySingle => rays
            .primary
            .par_chunks(1024)
            .map(|chunk| {
                chunk
                    .iter()
                    .filter(|ray| {
                        let (o, d, t_max) = ray.parts();
                        bvh.closest_hit(o, d, t_max).is_some()
                    })
                    .count()
            })
            .sum(),
        RayKind::Shadow => rays
            .shadow_packets
            .par_chunks(16)
            .map(|packets| {
                packets
                    .iter()
                    .map(|range| {
                        let packet = &rays.shadow[range.clone()];
                        let mut pairs = [(Vec3A::ZERO, Vec3A::ZERO); PACKET];
                        let mut limits = [0.0f32; PACKET];
                        for (k, ray) in packet.iter().enumerate() {
                            let (o, d, t_max) = ray.parts();
                            pairs[k] = (o, d);
                            limits[k] = t_max;
                        }
                        let n = packet.len();
                        let stopped =
                            bvh.visit_hits_packet(&pairs[..n], &limits[..n], |_, _, _, _| false);
                        stopped.count_ones() as usize
                    })
                    .sum::<usize>()
            })
            .sum(),
        RayKind::ShadowSingle => rays
            .shadow
            .par_chunks(1024)
            .map(|chunk| {
                chunk
                    .iter()
                    .filter(|ray| {
                        let (o, d, t_max) = ray.parts();
                        !bvh.visit_hits(o, d, t_max, |_, _, _| false)
                    })
                    .count()
            })
            .sum(),
    }
}

/// Rate of one class of a ray file's rays at one thread count, and how many answers
/// differed from the recorded ones.
#[derive(Debug, Clone)]
pub struct RayFileRate {
    pub class: RayClass,
    /// How the class was traced: "packets" or "single".
    pub api: &'static str,
    pub threads: usize,
    pub rays: usize,
    /// Share that hit (closest hit) or were blocked (shadow).
    pub hit_share: f64,
    /// Answers that differ from the file's (triangle and distance bits, or blocked).
    pub mismatches: usize,
    pub rays_per_second: Percentiles,
}

/// How one class of a ray file's rays is traced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FileKernel {
    /// Closest hits in the film's packets ([`FilmPackets`]; primary rays, as the
    /// film traces them).
    ClosestPackets,
    ClosestSingle,
    /// Closest hits in the film's packets of rays from any origins (a
    /// bounce's reflected and refracted rays, as a tile traces them).
    ClosestScattered,
    /// Any hit in `[t min, t max)`.
    Occlusion,
    /// Any hit, in the film's packets (shadow rays, as a tile
    /// traces them: grouped by light, in the order its hits asked for them).
    OcclusionPackets,
}

impl FileKernel {
    /// Whether it traces rays in packets (else one at a time).
    fn in_packets(self) -> bool {
        match self {
            FileKernel::ClosestPackets
            | FileKernel::ClosestScattered
            | FileKernel::OcclusionPackets => true,
            FileKernel::ClosestSingle | FileKernel::Occlusion => false,
        }
    }
}

/// Traces the rays of a ray file (`mipray export --rays`) on frame `frame` of the
/// renderer's scene, class by class, on the kernels `api` names, for each thread count,
/// `repeats` times (each a sample of at least `min_sample`, see `timed_in`); checks
/// every answer against the recorded one.
///
/// # Errors
/// The file cannot be read (or held in memory), asks what mipray's kernels do not trace
/// (a `t min` other than 0: they trace every ray from its origin), names faces the frame
/// does not have (recorded on another scene or frame), or the frame cannot be prepared.
pub fn run_ray_file_bench(
    renderer: &mut Renderer,
    frame: u32,
    clock: crate::frame::FrameClock,
    path: &std::path::Path,
    api: RayApi,
    threads: &[usize],
    repeats: usize,
    min_sample: Duration,
) -> Result<Vec<RayFileRate>> {
    let records = read_ray_file(path)?;
    if records.is_empty() {
        // Known from the header: refused before the frame is prepared.
        anyhow::bail!(
            "{}: the file holds no rays (its header says 0): nothing to time",
            path.display()
        );
    }
    let pools = threads
        .iter()
        .map(|&t| rayon::ThreadPoolBuilder::new().num_threads(t).build())
        .collect::<Result<Vec<_>, _>>()?;
    let prepared = renderer.prepare(frame, clock.time(frame))?;
    let face_of_slot = crate::export::face_of_slot(renderer);
    let size = (prepared.camera.width, prepared.camera.height);
    check_records_fit(path, &records, face_of_slot.len(), size)?;
    let bvh = renderer.frame_scene(&prepared).bvh;
    let mut rates = Vec::new();
    for class in RayClass::ALL {
        let rays: Vec<&RayRecord> = records.iter().filter(|r| r.class == class).collect();
        if rays.is_empty() {
            continue;
        }
        let kernels: &[FileKernel] = match class {
            RayClass::Primary => &[FileKernel::ClosestPackets, FileKernel::ClosestSingle],
            RayClass::Shadow => &[FileKernel::OcclusionPackets, FileKernel::Occlusion],
            RayClass::Reflection | RayClass::Refraction => {
                &[FileKernel::ClosestScattered, FileKernel::ClosestSingle]
            }
        };
        for &kernel in kernels {
            if !api.includes(kernel.in_packets()) {
                continue;
            }
            let mut seconds = vec![vec![0.0f64; repeats]; threads.len()];
            let packets = FilmPackets::of(&rays, prepared.camera.width);
            let mut answers = answer_buffer(packets.ranges.len() * PACKET);
            let mut mismatches = 0;
            for repeat in 0..repeats {
                for k in 0..threads.len() {
                    let c = (k + repeat) % threads.len();
                    let ((), s) = timed_in(&pools[c], min_sample, || {
                        trace_records(kernel, &bvh, &rays, &packets, &mut answers);
                    });
                    seconds[c][repeat] += s;
                    // The first sample's answers are checked (outside its clock; later
                    // samples overwrite them with their own). Only the first: a check per
                    // sample would add its instructions to every repeat, and an instruction
                    // count takes one pass as the difference between repeats.
                    if repeat == 0 && k == 0 {
                        mismatches = packets
                            .answered(&rays, &answers)
                            .filter(|(r, a)| !answer_matches(r, *a, &face_of_slot))
                            .count();
                    }
                }
            }
            let hits = packets
                .answered(&rays, &answers)
                .filter(|(_, a)| a.is_some())
                .count();
            for (c, &t) in threads.iter().enumerate() {
                rates.push(RayFileRate {
                    class,
                    api: if kernel.in_packets() {
                        "packets"
                    } else {
                        "single"
                    },
                    threads: t,
                    rays: rays.len(),
                    hit_share: hits as f64 / rays.len() as f64,
                    mismatches,
                    rays_per_second: Percentiles::of(
                        seconds[c].iter().map(|s| rays.len() as f64 / s.max(1e-9)),
                    ),
                });
            }
        }
    }
    Ok(rates)
}

/// Checks that mipray's kernels can trace `records` as recorded on a frame of `faces`
/// faces and `size` pixels: every `t min` is 0 (the kernels start every ray at its origin; a later start would need
/// a moved origin, whose rounding would change the answers), every pixel index lies in the
/// frame (the film's packets are cut by pixel, so a file recorded at another size would be
/// timed in other packets), and no closest hit names a face past the frame's last (a file
/// recorded on another scene or frame).
fn check_records_fit(
    path: &std::path::Path,
    records: &[RayRecord],
    faces: usize,
    size: (u32, u32),
) -> Result<()> {
    let path = path.display();
    if let Some((i, r)) = records.iter().enumerate().find(|(_, r)| r.t_min != 0.0) {
        anyhow::bail!(
            "{path}: record {i} has t min {}: mipray's kernels trace every ray from its \
             origin, so a ray file for `bench --rays` needs t min 0 (as `export --rays` \
             writes it)",
            r.t_min
        );
    }
    let (width, height) = size;
    let pixels = u64::from(width) * u64::from(height);
    if let Some((i, r)) = records
        .iter()
        .enumerate()
        .find(|(_, r)| u64::from(r.pixel) >= pixels)
    {
        anyhow::bail!(
            "{path}: record {i} names pixel {} but a {width}x{height} frame has {pixels}: was \
             the file recorded at this size (`--size`)?",
            r.pixel
        );
    }
    let names_a_face = |r: &&RayRecord| r.class != RayClass::Shadow && r.result != MISS;
    if let Some(r) = records
        .iter()
        .filter(names_a_face)
        .find(|r| r.result as usize >= faces)
    {
        anyhow::bail!(
            "{path}: a recorded hit names face {} but this frame has {faces} faces: was the \
             file recorded on this scene and frame?",
            r.result
        );
    }
    Ok(())
}

/// What a kernel answered for one ray: the hit slot and distance (closest hit), or
/// `Some((0, NaN))` for blocked (occlusion); `None` for a miss or a clear shadow ray.
type Answer = Option<(u32, f32)>;

/// A buffer for `n` answers, its memory already written (so mapped).
///
/// Why: the timed passes write their answers into one buffer made before any clock starts.
/// A buffer allocated per pass (tens of megabytes for a real frame's class, so fresh pages
/// from the system each time) put its page faults inside every pass's time: about 2,400 a
/// pass for BART Robots' 1.96 M shadow rays, a cost Embree's anchor, which keeps its
/// answers in its packets, never pays.
fn answer_buffer(n: usize) -> Vec<Answer> {
    let mut answers = Vec::with_capacity(n);
    answers.resize(n, None);
    answers
}

/// How many packets [`trace_records`] hands a thread at a time.
const GROUP: usize = 16;

/// The packets a class's records are traced in: the packets the film traced them in, as
/// far as the records tell, each with the search distance its rays share.
///
/// The film traces a tile's rays bounce by bounce, a bounce's shadow rays light by light,
/// each batch in packets of up to [`PACKET`] in the order the tile's pixels come (Morton
/// order); a packet never holds rays of two tiles, two bounces or two lights. The records
/// follow that order, so a batch ends where the tile changes or the next record's pixel
/// comes earlier in the tile's order than the last one's (the next bounce or light starts
/// over): there a packet ends even if it is not full. (A batch whose first pixel comes
/// after the last pixel of the batch before it joins that batch's last packet: a small
/// batch, which the film would have traced alone.) Cut every [`PACKET`] records instead,
/// packets held rays of two batches, which the film never traces together and whose rays
/// share less (a shadow packet of two bounces has no one point its rays converge on): in
/// BART Kitchen frame 400's file, 2,053 batch ends fell inside the 16,302 runs of 64
/// shadow records, 1,666 inside the 13,414 of mirror records.
struct FilmPackets {
    /// Each packet's records, in order and together every record once.
    ranges: Vec<std::ops::Range<usize>>,
    /// Each packet's shared search distance: the largest `t max` of its records. Made
    /// before the clock starts, as Embree's anchor lays out its packets before timing
    /// them, and as the renderer knows its packets' limit (infinity) without a pass over
    /// their rays: folded inside the timed pass with `f32::max` (a NaN test a step, 64
    /// dependent steps a packet) it took 5% of the samples of the primary rays' passes.
    limits: Vec<f32>,
}

impl FilmPackets {
    /// The packets of `rays` (one class's records, in the file's order) from an image
    /// `width` pixels wide.
    fn of(rays: &[&RayRecord], width: u32) -> FilmPackets {
        let width = width.max(1);
        let position = |r: &RayRecord| film_position(r.pixel % width, r.pixel / width, width);
        let mut ranges = Vec::new();
        let mut start = 0;
        for i in 1..=rays.len() {
            let ends = i == rays.len() || i - start == PACKET || {
                let (before, next) = (position(rays[i - 1]), position(rays[i]));
                next.0 != before.0 || next.1 < before.1
            };
            if ends {
                ranges.push(start..i);
                start = i;
            }
        }
        let limits = ranges
            .iter()
            .map(|range| {
                rays[range.clone()]
                    .iter()
                    .fold(0.0f32, |m, r| m.max(r.t_max))
            })
            .collect();
        FilmPackets { ranges, limits }
    }

    /// Each record with its answer, from `answers` as [`trace_records`] lays them out
    /// (packet `p`'s from `p * PACKET` on).
    fn answered<'a>(
        &'a self,
        rays: &'a [&'a RayRecord],
        answers: &'a [Answer],
    ) -> impl Iterator<Item = (&'a RayRecord, Answer)> + 'a {
        self.ranges
            .iter()
            .zip(answers.chunks(PACKET))
            .flat_map(move |(range, out)| {
                rays[range.clone()].iter().zip(out).map(|(r, &a)| (*r, a))
            })
    }
}

/// Every answer of `kernel` for `rays`, packet by packet, into `answers` (packet `p`'s from
/// `p * PACKET` on; groups of packets side by side).
fn trace_records(
    kernel: FileKernel,
    bvh: &SceneBvh,
    rays: &[&RayRecord],
    packets: &FilmPackets,
    answers: &mut [Answer],
) {
    // Answers are written in place: with a list collected per packet and the lists
    // flattened, shadow packets measured 13% fewer rays a second, the harness's cost and
    // not the tracer's (Embree's anchor writes its answers in place too).
    debug_assert_eq!(answers.len(), packets.ranges.len() * PACKET);
    answers
        .par_chunks_mut(GROUP * PACKET)
        .zip(packets.ranges.par_chunks(GROUP))
        .zip(packets.limits.par_chunks(GROUP))
        .for_each(|((out, ranges), limits)| {
            for ((out, range), &limit) in out.chunks_mut(PACKET).zip(ranges).zip(limits) {
                let packet = &rays[range.clone()];
                trace_packet(kernel, bvh, packet, limit, &mut out[..packet.len()]);
            }
        });
}

/// [`trace_records`] of one packet of rays, into `out` (as long as `packet`), `limit` its
/// shared search distance.
fn trace_packet(
    kernel: FileKernel,
    bvh: &SceneBvh,
    packet: &[&RayRecord],
    limit: f32,
    out: &mut [Answer],
) {
    match kernel {
        FileKernel::ClosestPackets => closest_in_packet(bvh, packet, limit, false, out),
        FileKernel::ClosestScattered => closest_in_packet(bvh, packet, limit, true, out),
        FileKernel::ClosestSingle => {
            for (answer, r) in out.iter_mut().zip(packet) {
                let (origin, direction) = r.origin_direction();
                *answer = closest_answer(bvh.closest_hit(origin, direction, r.t_max));
            }
        }
        FileKernel::OcclusionPackets => {
            let pairs = packet_rays(packet);
            let mut limits = [0.0f32; PACKET];
            for (limit, r) in limits.iter_mut().zip(packet) {
                *limit = r.t_max;
            }
            let n = packet.len();
            let stopped = bvh.visit_hits_packet(&pairs[..n], &limits[..n], |_, _, _, _| false);
            for (k, answer) in out.iter_mut().enumerate() {
                *answer = (stopped & (1 << k) != 0).then_some((0, f32::NAN));
            }
        }
        FileKernel::Occlusion => {
            for (answer, r) in out.iter_mut().zip(packet) {
                let (origin, direction) = r.origin_direction();
                let clear = bvh.visit_hits(origin, direction, r.t_max, |_, _, _| false);
                *answer = (!clear).then_some((0, f32::NAN));
            }
        }
    }
}

/// Closest hits of the rays of `packet` (at most [`PACKET`]) as one packet, into `out` (as
/// long as `packet`): from one origin with interval bounds (primary rays), or with
/// `scattered` from any origins by the masked walk (a bounce's rays).
///
/// The packet shares one search distance (`t_max`: the largest of its rays' `t max`,
/// infinity in files `export --rays` writes); a ray whose closest hit lies at or past its
/// own `t max` then has none below it either, so dropping that hit gives the answer a
/// search cut at its own `t max` gives.
fn closest_in_packet(
    bvh: &SceneBvh,
    packet: &[&RayRecord],
    t_max: f32,
    scattered: bool,
    out: &mut [Answer],
) {
    let pairs = packet_rays(packet);
    let mut hits = [None; PACKET];
    let n = packet.len();
    if scattered {
        bvh.closest_hits_scattered(&pairs[..n], t_max, &mut hits[..n]);
    } else {
        bvh.closest_hits(&pairs[..n], t_max, &mut hits[..n]);
    }
    for ((answer, &hit), r) in out.iter_mut().zip(&hits[..n]).zip(packet) {
        *answer = closest_answer(hit.filter(|h| h.t < r.t_max));
    }
}

/// The `(origin, direction)` of each record of `packet` (at most [`PACKET`]; the slots past
/// it are zero).
fn packet_rays(packet: &[&RayRecord]) -> [(Vec3A, Vec3A); PACKET] {
    let mut pairs = [(Vec3A::ZERO, Vec3A::ZERO); PACKET];
    for (pair, r) in pairs.iter_mut().zip(packet) {
        *pair = r.origin_direction();
    }
    pairs
}

/// A closest-hit query's answer: the hit slot and distance.
fn closest_answer(hit: Option<crate::accel::Hit>) -> Answer {
    hit.map(|h| (h.triangle, h.t))
}

/// Whether `answer` is what record `r` holds (the same face and distance bits, or the same
/// blocked flag).
fn answer_matches(r: &RayRecord, answer: Answer, face_of_slot: &[u32]) -> bool {
    match (r.class, answer) {
        (RayClass::Shadow, a) => (r.result == 1) == a.is_some(),
        (_, None) => r.result == MISS,
        (_, Some((slot, t))) => {
            face_of_slot.get(slot as usize) == Some(&r.result) && t.to_bits() == r.t.to_bits()
        }
    }
}

/// A Markdown table of a ray file's rates per class.
pub fn ray_file_table(rates: &[RayFileRate]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| class | traced as | threads | count | hit or blocked | Mrays/s (median) | min..max | answers differing |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|");
    for r in rates {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1}% | {:.3} | {:.3}..{:.3} | {} |",
            r.class.name(),
            r.api,
            r.threads,
            r.rays,
            100.0 * r.hit_share,
            r.rays_per_second.median / 1e6,
            r.rays_per_second.min / 1e6,
            r.rays_per_second.max / 1e6,
            r.mismatches
        );
    }
    s
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

    /// A shadow record of pixel `(x, y)` of an 80-pixel-wide image searched to `t_max`.
    fn record(x: u32, y: u32, t_max: f32) -> RayRecord {
        RayRecord {
            origin: glam::Vec3::ZERO,
            direction: glam::Vec3::Y,
            t_min: 0.0,
            t_max,
            class: RayClass::Shadow,
            pixel: y * 80 + x,
            result: 0,
            t: f32::NAN,
        }
    }

    /// The bench's packets end where the film's do: at a full packet, at a new tile, and
    /// where the next record's pixel comes earlier in the tile's order (a new bounce or
    /// light); each packet's limit is its rays' largest.
    #[test]
    fn film_packets_end_where_the_film_s_batches_end() {
        let mut records = Vec::new();
        // Tile 0, first batch: 100 pixels in the film's order (two packets, 64 and 36).
        let first: Vec<(u32, u32)> = tile_pixels((0, 0), 80, 64).take(100).collect();
        for (i, &(x, y)) in first.iter().enumerate() {
            records.push(record(x, y, i as f32));
        }
        // Tile 0 again, a later bounce: starts over near the tile's corner.
        for &(x, y) in first.iter().skip(3).step_by(7) {
            records.push(record(x, y, 1.0));
        }
        // Tile 1: a new tile, even though its first pixel comes at a later place than the
        // last record's in its own tile.
        for (x, y) in tile_pixels((TILE, 0), 80, 64).skip(100).take(10) {
            records.push(record(x, y, f32::INFINITY));
        }
        let rays: Vec<&RayRecord> = records.iter().collect();
        let packets = FilmPackets::of(&rays, 80);
        let second = first.iter().skip(3).step_by(7).count();
        // Cut every 64 records instead, the second packet would have mixed the batches.
        assert_eq!(
            packets.ranges,
            vec![
                0..64,
                64..100,
                100..100 + second,
                100 + second..110 + second
            ]
        );
        assert_eq!(packets.limits[..2], [63.0, 99.0]);
        assert_eq!(packets.limits[2..], [1.0, f32::INFINITY]);
        // Each packet's answers start at `p * PACKET`, and `answered` pairs every record
        // with its own.
        let answers: Vec<Answer> = (0..packets.ranges.len() * PACKET)
            .map(|i| Some((i as u32, 0.0)))
            .collect();
        let answered: Vec<(u32, u32)> = packets
            .answered(&rays, &answers)
            .map(|(r, a)| (r.pixel, a.unwrap().0))
            .collect();
        assert_eq!(answered.len(), records.len());
        assert_eq!(answered[64], (records[64].pixel, PACKET as u32));
        assert_eq!(answered[100], (records[100].pixel, 2 * PACKET as u32));
    }

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

    /// A timed ray takes Embree's anchor's 28 bytes and gives back the bits it was made
    /// of (infinite and negative-zero components included).
    #[test]
    fn a_timed_ray_is_seven_floats_and_keeps_its_bits() {
        assert_eq!(std::mem::size_of::<TimedRay>(), 28);
        let (o, d) = (Vec3A::new(1.5, -0.0, 1e30), Vec3A::new(0.0, -1.0, 3e-39));
        for t_max in [f32::INFINITY, 0.25, f32::MIN_POSITIVE] {
            let (o2, d2, t2) = TimedRay::new(o, d, t_max).parts();
            let bits = |v: Vec3A| v.to_array().map(f32::to_bits);
            assert_eq!((bits(o2), bits(d2)), (bits(o), bits(d)));
            assert_eq!(t2.to_bits(), t_max.to_bits());
        }
    }

    /// A sample shorter than the minimum is made of passes back to back, and its time is
    /// one pass's; with no minimum it is exactly one pass (what an instruction count needs).
    #[test]
    fn a_timed_sample_repeats_short_work_and_reports_one_pass() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let pass = Duration::from_millis(2);
        let mut passes = 0u32;
        let (first, seconds) = timed_in(&pool, Duration::from_millis(20), || {
            passes += 1;
            std::thread::sleep(pass);
            passes
        });
        assert_eq!(first, 1, "the result is the first pass's");
        // At most ten passes of at least 2 ms reach 20 ms; a second pass is made unless the
        // first alone took 20 ms (a stalled machine).
        assert!(passes <= 10, "{passes} passes of 2 ms for 20 ms");
        assert!(passes >= 2 || seconds >= 0.02, "one pass of {seconds} s");
        // Each pass sleeps at least 2 ms; a sample of ten or fewer took at least 20 ms.
        assert!(seconds >= pass.as_secs_f64(), "{seconds} s a pass");
        assert!(
            seconds * f64::from(passes) >= 0.02,
            "{seconds} s x {passes}"
        );

        let mut once = 0u32;
        let (_, seconds) = timed_in(&pool, Duration::ZERO, || {
            once += 1;
            std::thread::sleep(pass);
        });
        assert_eq!(once, 1);
        assert!(seconds >= pass.as_secs_f64());
    }
}
