//! The full refit of a million moved triangles, alone: `cargo bench --bench refit`.
//!
//! The `frame_loop` bench times a refit inside whole frames, where the write before it
//! leaves the caches in a different state each run; this one times `Accel::refit` over a
//! 1,000 x 500-quad grid (1M triangles, the skinned row's mesh) whose every vertex moves
//! between refits, so the variants of the refit can be compared on their own. Medians of 25
//! refits after 5 warm-up ones (the new vertices written into the packs before each, as the
//! frame update writes them, outside the timing), on rayon's global pool (`RAYON_NUM_THREADS` sets it).
use std::time::Instant;

use glam::{Vec2, Vec3, Vec3A};
use mipray::accel::Accel;
use mipray::geometry::FrameTriangles;

const W: usize = 1000;
const H: usize = 500;

/// The grid's vertex `(x, y)` at time `t`: a travelling wave across a gently bent sheet.
fn vertex(x: usize, y: usize, t: f32) -> Vec3A {
    let (u, v) = (x as f32 * 0.01, y as f32 * 0.01);
    Vec3A::new(u, v, 0.2 * (3.0 * u + t).sin() * (2.0 * v - t).cos())
}

fn grid(t: f32) -> Vec<[Vec3A; 3]> {
    let mut tris = Vec::with_capacity(2 * W * H);
    for y in 0..H {
        for x in 0..W {
            let [a, b, c, d] =
                [(x, y), (x + 1, y), (x + 1, y + 1), (x, y + 1)].map(|(x, y)| vertex(x, y, t));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    tris
}

fn main() {
    let positions = grid(0.0);
    let n = positions.len();
    let mut triangles = FrameTriangles {
        positions,
        normals: vec![[Vec3::Z; 3]; n],
        uvs: vec![[Vec2::ZERO; 3]; n],
        material: vec![0; n],
        log2_pb: vec![0.0; n],
        source: (0..n as u32).collect(),
    };
    let mut accel = Accel::build(&mut triangles).expect("finite grid");
    let all: Vec<u32> = (0..n as u32).collect();
    let mut times = Vec::new();
    for frame in 1..=30 {
        // Each slot's triangle at the new time (slots are in BVH order: go by source).
        let moved = grid(frame as f32 * 0.05);
        // (Written into the packs outside the timing: the frame update writes them.)
        for (slot, &source) in triangles.source.iter().enumerate() {
            accel.set_triangle(slot as u32, &moved[source as usize]);
        }
        let start = Instant::now();
        accel.refit(&all);
        let ms = start.elapsed().as_secs_f64() * 1e3;
        if frame > 5 {
            times.push(ms);
        }
    }
    times.sort_by(f64::total_cmp);
    println!(
        "full refit of {n} triangles, {} threads: median {:.2} ms (min {:.2}, max {:.2}), SAH ratio {:.3}",
        rayon::current_num_threads(),
        times[times.len() / 2],
        times[0],
        times[times.len() - 1],
        accel.sah_ratio()
    );
}
