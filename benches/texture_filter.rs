//! Texture filtering alone: `cargo bench --bench texture_filter`.
//!
//! Times `MipPyramid::sample_bilinear` (level 0), `sample_trilinear` (LOD 2.37, between
//! levels 2 and 3) and `sample_anisotropic` (4 taps at that LOD) on pyramids built outside
//! the timed loop from images generated in code:
//! - `8-bit 64²`: small enough to stay in the first-level cache, so its rows time the
//!   arithmetic of a lookup rather than its memory traffic;
//! - `8-bit 1024²`: an 8-bit sRGB image with power-of-two sides;
//! - `8-bit 1044²`: the size of BART Kitchen's largest texture, whose texel coordinates
//!   cannot be computed exactly in f32;
//! - `16-bit 512²`: values no 8-bit code decodes to, so every level keeps `f32` texels.
//!
//! Lookup points (generated before timing, the same for every row):
//! - `sweep`: rows of points a quarter texel of level 3 apart, as neighbouring pixels of a
//!   tile look up a surface (successive lookups share cache lines);
//! - `random`: uniform over the texture (most lookups miss the caches of the larger levels);
//! - `tiled`: the sweep moved by whole periods into [-3, 4), so every lookup takes the
//!   Repeat wrap path.
//!
//! Prints a Markdown table of median nanoseconds per lookup over 11 runs of 2^20 lookups
//! (after 2 warm-up runs), on one thread, in the thread's CPU time (a shared machine makes
//! wall-clock time wait for a core), and which SIMD copy ran (`MIPRAY_SIMD=baseline`
//! forces the baseline). Arguments (after `--`): `bilinear`, `trilinear` or `anisotropic`
//! choose columns, other words are what a row's name must contain.

use std::hint::black_box;
use std::time::Instant;

use glam::{Vec2, Vec4};
use mipray::simd::Isa;
use mipray::texture::{MipPyramid, Sampler};

const LOOKUPS: usize = 1 << 20;
const RUNS: usize = 11;
const WARM_UP: usize = 2;
const LOD: f32 = 2.37;

/// A deterministic hash of `i` in [0, 1).
fn hash01(i: u64) -> f32 {
    let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
}

/// The 8-bit sRGB decoding of code `c` (what `decode_texels` gives an 8-bit image).
fn srgb8(c: u8) -> f32 {
    let c = f64::from(c) / 255.0;
    (if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }) as f32
}

/// A smooth image with noise, as 8-bit codes decoded (so the pyramid keeps codes).
fn image_8bit(side: u32) -> MipPyramid {
    let texels = (0..side * side)
        .map(|i| {
            let (x, y) = ((i % side) as f32, (i / side) as f32);
            let code = |k: u64, f: f32| {
                let smooth = 0.5 + 0.4 * (f * 0.05).sin();
                ((smooth + 0.1 * hash01(4 * u64::from(i) + k)) * 255.0) as u8
            };
            Vec4::new(
                srgb8(code(0, x)),
                srgb8(code(1, y)),
                srgb8(code(2, x + y)),
                1.0,
            )
        })
        .collect();
    MipPyramid::from_linear_rgba(side, side, texels).expect("valid size")
}

/// Values of 16-bit precision (no 8-bit code's), so every level keeps `f32`.
fn image_16bit(side: u32) -> MipPyramid {
    let texels = (0..side * side)
        .map(|i| {
            let v = |k: u64| (hash01(4 * u64::from(i) + k) * 65535.0).round() / 65535.0 + 1e-6;
            Vec4::new(v(0), v(1), v(2), 1.0)
        })
        .collect();
    MipPyramid::from_linear_rgba(side, side, texels).expect("valid size")
}

/// Lookup points of each pattern (see the module note) for a texture of `side` texels.
fn points(pattern: &str, side: u32) -> Vec<Vec2> {
    let step = 8.0 / side as f32 / 4.0; // a quarter texel of level 3
    let per_row = (1.0 / step) as usize;
    let sweep = |i: usize| {
        let (x, y) = (i % per_row, i / per_row);
        Vec2::new((x as f32 + 0.5) * step, (y as f32 * 0.37 * step).fract())
    };
    (0..LOOKUPS)
        .map(|i| match pattern {
            "sweep" => sweep(i),
            "random" => Vec2::new(hash01(2 * i as u64), hash01(2 * i as u64 + 1)),
            _ => sweep(i) + Vec2::new((i % 7) as f32 - 3.0, (i % 5) as f32 - 2.0),
        })
        .collect()
}

/// Seconds of CPU time this thread has used (wall-clock time where that is not available):
/// on a shared machine the thread may wait for a core, which CPU time leaves out.
fn thread_seconds() -> f64 {
    #[cfg(unix)]
    {
        let mut t = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `t` is a valid timespec for the call to write.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) } == 0 {
            return t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9;
        }
    }
    static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_secs_f64()
}

/// Median nanoseconds (of thread CPU time) per lookup of `lookup` over `uvs`.
fn time(uvs: &[Vec2], lookup: impl Fn(Vec2) -> Vec4) -> f64 {
    let mut times: Vec<f64> = (0..WARM_UP + RUNS)
        .map(|_| {
            let start = thread_seconds();
            let mut sum = Vec4::ZERO;
            for &uv in uvs {
                sum += lookup(black_box(uv));
            }
            black_box(sum);
            (thread_seconds() - start) * 1e9 / uvs.len() as f64
        })
        .skip(WARM_UP)
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    // Words naming lookups choose columns; the others choose rows.
    let lookups = ["bilinear", "trilinear", "anisotropic"];
    let (columns, filters): (Vec<String>, Vec<String>) = args
        .into_iter()
        .partition(|a| lookups.contains(&a.as_str()));
    let column = |name: &str| columns.is_empty() || columns.iter().any(|c| c == name);
    let wanted = |row: &str| filters.iter().all(|f| row.contains(f.as_str()));
    let images = [
        ("8-bit 64²", image_8bit(64)),
        ("8-bit 1024²", image_8bit(1024)),
        ("8-bit 1044²", image_8bit(1044)),
        ("16-bit 512²", image_16bit(512)),
    ];
    let sampler = Sampler::default();
    println!("SIMD copy: {:?}\n", Isa::current());
    println!("| image | points | bilinear ns | trilinear ns | anisotropic (4 taps) ns |");
    println!("|---|---|---:|---:|---:|");
    for (name, pyramid) in &images {
        let side = pyramid.base_size().0;
        for pattern in ["sweep", "random", "tiled"] {
            let row = format!("{name} {pattern}");
            if !wanted(&row) {
                continue;
            }
            let uvs = points(pattern, side);
            let axis = Vec2::new(3.0 / side as f32, 1.0 / side as f32);
            let bilinear = column("bilinear")
                .then(|| time(&uvs, |uv| pyramid.sample_bilinear(0, uv, sampler)));
            let trilinear = column("trilinear")
                .then(|| time(&uvs, |uv| pyramid.sample_trilinear(uv, LOD, sampler)));
            let aniso = column("anisotropic").then(|| {
                time(&uvs, |uv| {
                    pyramid.sample_anisotropic(uv, LOD, axis, 4, sampler)
                })
            });
            let [bilinear, trilinear, aniso] =
                [bilinear, trilinear, aniso].map(|t| t.map_or("-".into(), |t| format!("{t:.1}")));
            println!("| {name} | {pattern} | {bilinear} | {trilinear} | {aniso} |");
        }
    }
}
