//! The floor of a skinned update on this machine: `cargo bench --bench update_floor`.
//!
//! The target for a million skinned triangles' update was at most 10% of a 640x480 frame.
//! This bench measures what the least such update costs here, without the frame loop:
//! 1M triangles (a 1,000 x 500-quad grid) skinned to 8 joints, two influences per vertex,
//! then one pass over the triangles in spatial (Morton) order, the order a BVH's leaves
//! have. That pass gathers the posed vertices and writes a packed copy (36 B), the leaf
//! boxes (4 triangles per leaf) and the `log2 P_b` constant (one `log2` per triangle,
//! taken in batches with `lod::log2` as the frame loop takes them, the texel term tabled). Last comes an 8-wide bottom-up refit of the boxes above the leaves.
//!
//! It is optimistic on purpose, so its times are a floor and not a design:
//! - no dirty tracking, no moved checks, no per-slot shading normals;
//! - no fallbacks for degenerate joints;
//! - the index buffer is already in leaf order.
//!
//! Two variants take out the `log2` and then the packed copy, to show what each costs. A
//! fourth adds back the least bookkeeping the frame loop owes the record's counters and the
//! never-a-NaN rule, fused into the triangle pass: each triangle compared with the packed
//! copy it overwrites (a changed flag, set in a dirty bitset and counted for
//! `deformed_triangles` and `lod_recomputed`) and its vertices checked finite.
//! A fifth keeps that bookkeeping and adds what the frame loop's design keeps besides: the
//! per-triangle shading normals (36 bytes, written beside the packs), and the leaf boxes and
//! `log2 P_b` taken in passes of their own over the packs after the write, as the record
//! times the refit and the `log2 P_b` step apart. A sixth is the fifth without the shading
//! normals: the frame loop no longer stores a deforming mesh's normals per triangle (a hit
//! reads them through the vertex indices), so it is the floor of an update laid out as the
//! frame loop lays it out today; the fourth is the floor the update's target is set against.
//! Medians of 25 frames after 5 warm-up frames. Rayon's global pool is used as it comes
//! (`RAYON_NUM_THREADS` sets it).
use glam::{Mat3A, Mat4, Vec3, Vec3A};
use mipray::lod::log2::log2_in_place;
use rayon::prelude::*;
use std::time::Instant;

const W: usize = 1000;
const H: usize = 500;

fn morton(x: u32, y: u32) -> u64 {
    let spread = |mut v: u64| {
        v &= 0xffff_ffff;
        v = (v | (v << 16)) & 0x0000_ffff_0000_ffff;
        v = (v | (v << 8)) & 0x00ff_00ff_00ff_00ff;
        v = (v | (v << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        v = (v | (v << 1)) & 0x5555_5555_5555_5555;
        v
    };
    spread(x as u64) | (spread(y as u64) << 1)
}

#[derive(Clone, Copy, Default)]
struct Bounds {
    min: Vec3A,
    max: Vec3A,
}

/// One variant, compiled on its own (a runtime flag let the compiler compute the `log2`
/// anyway and select).
fn floor<
    const WITH_LOG2: bool,
    const WITH_PACKS: bool,
    const WITH_BOOKKEEPING: bool,
    const AS_THE_RECORD_TIMES: bool,
    const WITH_SLOT_NORMALS: bool,
>() -> [f64; 4] {
    let nv = (W + 1) * (H + 1);
    let rest: Vec<Vec3> = (0..nv)
        .map(|i| {
            Vec3::new(
                (i % (W + 1)) as f32 * 0.01,
                (i / (W + 1)) as f32 * 0.01,
                0.0,
            )
        })
        .collect();
    let rest_n: Vec<Vec3> = vec![Vec3::Z; nv];
    let joints: Vec<[u16; 4]> = (0..nv)
        .map(|i| {
            let j = ((i % (W + 1)) * 7 / W) as u16;
            [j, (j + 1).min(7), 0, 0]
        })
        .collect();
    let weights: Vec<[f32; 4]> = (0..nv)
        .map(|i| {
            let f = (i % (W + 1)) as f32 / W as f32 * 7.0;
            let w = f - f.floor();
            [1.0 - w, w, 0.0, 0.0]
        })
        .collect();
    // Triangles in Morton order of their quads (what a BVH's leaf order looks like).
    let mut quads: Vec<(u64, u32, u32)> = (0..H as u32)
        .flat_map(|y| (0..W as u32).map(move |x| (morton(x, y), x, y)))
        .collect();
    quads.sort_unstable();
    let mut index: Vec<[u32; 3]> = Vec::with_capacity(2 * W * H);
    for &(_, x, y) in &quads {
        let v = |x: u32, y: u32| y * (W as u32 + 1) + x;
        index.push([v(x, y), v(x + 1, y), v(x + 1, y + 1)]);
        index.push([v(x, y), v(x + 1, y + 1), v(x, y + 1)]);
    }
    let nt = index.len();
    let term: Vec<f64> = vec![3.5; nt];
    let mut posed = vec![Vec3::ZERO; nv];
    let mut posed_n = vec![Vec3::ZERO; nv];
    let mut packed = vec![[Vec3::NAN; 3]; nt];
    // Bookkeeping: the per-triangle dirty bitset, the count of changed triangles and
    // whether every moved vertex was finite.
    let mut dirty = vec![0u64; nt.div_ceil(64)];
    let mut changed_triangles = 0usize;
    let mut all_finite = true;
    let mut log2_pb = vec![0f32; nt];
    // Per-triangle shading normals (written only by the variant that keeps the record's
    // separate steps).
    let mut normals = vec![[Vec3::ZERO; 3]; if WITH_SLOT_NORMALS { nt } else { 0 }];
    let mut leaves = vec![Bounds::default(); nt.div_ceil(4)];
    // Upper levels of an 8-wide tree over the leaves.
    let mut levels: Vec<Vec<Bounds>> = Vec::new();
    let mut n = leaves.len();
    while n > 1 {
        n = n.div_ceil(8);
        levels.push(vec![Bounds::default(); n]);
    }
    let mut times = Vec::new();
    for frame in 0..30 {
        let t = frame as f32 * 0.05;
        let mats: Vec<Mat4> = (0..8)
            .map(|j| {
                Mat4::from_rotation_z(0.1 * (t + j as f32).sin())
                    * Mat4::from_translation(Vec3::new(0.0, 0.01 * j as f32, 0.0))
            })
            .collect();
        let start = Instant::now();
        // 1. skinning
        posed
            .par_chunks_mut(4096)
            .zip(posed_n.par_chunks_mut(4096))
            .enumerate()
            .for_each(|(c, (p, n))| {
                for k in 0..p.len() {
                    let v = c * 4096 + k;
                    let mut m = Mat4::ZERO;
                    for (&j, &w) in joints[v].iter().zip(&weights[v]) {
                        if w != 0.0 {
                            m += mats[j as usize] * w;
                        }
                    }
                    p[k] = m.transform_point3(rest[v]);
                    let l = Mat3A::from_mat4(m);
                    let cof = Mat3A::from_cols(
                        l.y_axis.cross(l.z_axis),
                        l.z_axis.cross(l.x_axis),
                        l.x_axis.cross(l.y_axis),
                    );
                    n[k] = Vec3::from((cof * Vec3A::from(rest_n[v])).normalize_or_zero());
                }
            });
        let t1 = Instant::now();
        if AS_THE_RECORD_TIMES {
            // The frame loop's steps as its record times them: the write (packs, shading
            // normals, the moved test), then the leaf boxes, then `log2 P_b`, each its own
            // pass over the packs.
            // Without slot normals each task gets an empty run of them (as the frame loop
            // does for a mesh that deforms: its normals are read through the vertex indices
            // at a hit).
            let normal_runs: Vec<&mut [[Vec3; 3]]> = if WITH_SLOT_NORMALS {
                normals.chunks_mut(4096).collect()
            } else {
                (0..nt.div_ceil(4096)).map(|_| Default::default()).collect()
            };
            let (changed, finite) = packed
                .par_chunks_mut(4096)
                .zip(normal_runs)
                .zip(dirty.par_chunks_mut(64))
                .enumerate()
                .map(|(c, ((pk, nm), dw))| {
                    let (mut changed, mut finite) = (0, true);
                    dw.fill(0);
                    for k in 0..pk.len() {
                        let tri = c * 4096 + k;
                        let [a, b, d] = index[tri].map(|i| posed[i as usize]);
                        if let Some(nm) = nm.get_mut(k) {
                            *nm = index[tri].map(|i| posed_n[i as usize]);
                        }
                        let moved = pk[k] != [a, b, d];
                        dw[k / 64] |= u64::from(moved) << (k % 64);
                        changed += moved as usize;
                        finite &= a.is_finite() & b.is_finite() & d.is_finite();
                        pk[k] = [a, b, d];
                    }
                    (changed, finite)
                })
                .reduce(|| (0, true), |a, b| (a.0 + b.0, a.1 && b.1));
            changed_triangles += changed;
            all_finite &= finite;
            leaves
                .par_chunks_mut(1024)
                .zip(packed.par_chunks(4096))
                .for_each(|(lv, pk)| {
                    for (leaf, tris) in lv.iter_mut().zip(pk.chunks(4)) {
                        let mut b = Bounds {
                            min: Vec3A::INFINITY,
                            max: Vec3A::NEG_INFINITY,
                        };
                        for &[a, p, d] in tris {
                            b.min = b.min.min(Vec3A::from(a.min(p).min(d)));
                            b.max = b.max.max(Vec3A::from(a.max(p).max(d)));
                        }
                        *leaf = b;
                    }
                });
            log2_pb
                .par_chunks_mut(4096)
                .zip(packed.par_chunks(4096))
                .enumerate()
                .for_each(|(c, (lp, pk))| {
                    let mut cc = [0f64; 4096];
                    for (k, &[a, b, d]) in pk.iter().enumerate() {
                        let [p0, p1, p2] = [a, b, d].map(|v| v.as_dvec3());
                        let cr = (p1 - p0).cross(p2 - p0);
                        cc[k] = cr.dot(cr);
                    }
                    let cc = &mut cc[..pk.len()];
                    log2_in_place(cc);
                    for (k, log) in cc.iter().enumerate() {
                        lp[k] = (0.25 * log - term[c * 4096 + k] + 7.0) as f32;
                    }
                });
        } else {
            // 2. per triangle, in leaf order: pack, leaf box, log2 P_b
            let (changed, finite) = packed
                .par_chunks_mut(4096)
                .zip(log2_pb.par_chunks_mut(4096))
                .zip(leaves.par_chunks_mut(1024))
                .zip(dirty.par_chunks_mut(64))
                .enumerate()
                .map(|(c, (((pk, lp), lv), dw))| {
                    let mut cc = [0f64; 4096];
                    let (mut changed, mut finite) = (0, true);
                    if WITH_BOOKKEEPING {
                        dw.fill(0);
                    }
                    for k in 0..pk.len() {
                        let tri = c * 4096 + k;
                        let [a, b, d] = index[tri].map(|i| posed[i as usize]);
                        if WITH_BOOKKEEPING {
                            let moved = pk[k] != [a, b, d];
                            dw[k / 64] |= u64::from(moved) << (k % 64);
                            changed += moved as usize;
                            finite &= a.is_finite() & b.is_finite() & d.is_finite();
                        }
                        if WITH_PACKS {
                            pk[k] = [a, b, d];
                        }
                        let [p0, p1, p2] = [a, b, d].map(|v| v.as_dvec3());
                        let cr = (p1 - p0).cross(p2 - p0);
                        cc[k] = cr.dot(cr);
                        let leaf = &mut lv[k / 4];
                        let (lo, hi) = (Vec3A::from(a.min(b).min(d)), Vec3A::from(a.max(b).max(d)));
                        if k % 4 == 0 {
                            *leaf = Bounds { min: lo, max: hi };
                        } else {
                            leaf.min = leaf.min.min(lo);
                            leaf.max = leaf.max.max(hi);
                        }
                    }
                    // The logarithms in one batch, as the frame loop takes them (`lod::log2`).
                    let cc = &mut cc[..pk.len()];
                    if WITH_LOG2 {
                        log2_in_place(cc);
                    }
                    for (k, log) in cc.iter().enumerate() {
                        lp[k] = (0.25 * log - term[c * 4096 + k] + 7.0) as f32;
                    }
                    (changed, finite)
                })
                .reduce(|| (0, true), |a, b| (a.0 + b.0, a.1 && b.1));
            changed_triangles += changed;
            all_finite &= finite;
        }
        let t2 = Instant::now();
        // 3. bottom-up refit of the upper levels
        let mut below: &[Bounds] = &leaves;
        for level in levels.iter_mut() {
            level.par_chunks_mut(512).enumerate().for_each(|(c, out)| {
                for (k, o) in out.iter_mut().enumerate() {
                    let first = (c * 512 + k) * 8;
                    let kids = &below[first..(first + 8).min(below.len())];
                    let mut b = kids[0];
                    for kid in &kids[1..] {
                        b.min = b.min.min(kid.min);
                        b.max = b.max.max(kid.max);
                    }
                    *o = b;
                }
            });
            below = level;
        }
        let t3 = Instant::now();
        if frame >= 5 {
            times.push([
                (t1 - start).as_secs_f64() * 1e3,
                (t2 - t1).as_secs_f64() * 1e3,
                (t3 - t2).as_secs_f64() * 1e3,
                (t3 - start).as_secs_f64() * 1e3,
            ]);
        }
    }
    let med = |i: usize| {
        let mut v: Vec<f64> = times.iter().map(|t| t[i]).collect();
        v.sort_by(|a, b| a.total_cmp(b));
        v[v.len() / 2]
    };
    // Keeps the outputs alive (and the passes from being optimised away).
    std::hint::black_box((&packed, &log2_pb, &levels, &dirty, &normals));
    if WITH_BOOKKEEPING || AS_THE_RECORD_TIMES {
        assert!(all_finite, "a skinned vertex came out non-finite");
        // Nearly every triangle moves each frame (the grid's corner at the origin does not).
        assert!(
            changed_triangles > 29 * nt && changed_triangles <= 30 * nt,
            "changed {changed_triangles} of {} triangle updates",
            30 * nt
        );
    }
    [med(0), med(1), med(2), med(3)]
}

fn main() {
    println!(
        "1M skinned triangles, {} threads (medians of 25 frames, ms)\n",
        rayon::current_num_threads()
    );
    println!("| variant | skinning | triangle pass | refit above the leaves | total |");
    println!("|---|---:|---:|---:|---:|");
    type Variant = (&'static str, fn() -> [f64; 4]);
    let variants: [Variant; 6] = [
        (
            "packs + boxes + log2 P_b",
            floor::<true, true, false, false, false>,
        ),
        (
            "packs + boxes, no log2",
            floor::<false, true, false, false, false>,
        ),
        (
            "boxes only, no packs, no log2",
            floor::<false, false, false, false, false>,
        ),
        (
            "packs + boxes + log2 P_b + changed test, dirty bits, count, NaN check",
            floor::<true, true, true, false, false>,
        ),
        (
            "the same + shading normals, with boxes and log2 P_b as separate passes (the record's steps)",
            floor::<true, true, true, true, true>,
        ),
        (
            "the same without the shading normals (read through the vertex indices at a hit, as the frame loop does for a deforming mesh)",
            floor::<true, true, true, true, false>,
        ),
    ];
    for (name, run) in variants {
        let [skin, triangles, refit, total] = run();
        println!("| {name} | {skin:.2} | {triangles:.2} | {refit:.2} | {total:.2} |");
    }
}
