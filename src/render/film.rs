//! The film: pixels rendered in square tiles ([`TILE`]) in parallel, stratified
//! supersampling, and the conversion of linear radiance to output pixels (with the sRGB
//! encoding of `colour`).
//!
//! Determinism: every pixel is a pure function of its coordinates (jitter comes from a hash
//! of pixel and sample index, not from a shared random state), each tile writes only its own
//! pixels, and the tiles' counters are summed in tile order, so the image and the counters
//! are the same whatever the thread count.
//!
//! Memory: the tiles write straight into the frame's pixels (no copy of the frame per tile
//! alongside it), so a frame holds 12 bytes per pixel while it renders; the largest size
//! `--size` accepts (`cli::args::MAX_PIXELS`, 16384 x 16384) needs about 3.2 GB for it.

use glam::Vec3;
use rayon::prelude::*;

use crate::colour::srgb8_encoder;
use crate::lod::{RayLod, with_lod_state};
use crate::render::camera::Camera;
use crate::render::integrator::{FrameScene, TraceCounters};
use crate::render::tile::{TileBuffers, TraceTile};

/// A tile's side in pixels. A tile traces each bounce's rays together, so a larger tile
/// fills the packets of its deeper bounces (mirror rays off a few mirrors, shadow rays
/// toward one light) with more rays; measured on BART Kitchen, 32 x 32 tiles were about 3%
/// faster than 16 x 16 and 64 x 64 slower again (the tile's lists outgrow the caches).
pub const TILE: u32 = 32;

// The Morton codes of a TILE x TILE square cover every pixel of the tile only when its
// side is a power of two; offsets up to 255 fit the table's bytes.
const _: () = assert!(TILE.is_power_of_two() && TILE <= 256);

/// A whole tile's pixel offsets in Morton order, made once at compile time.
const MORTON_ORDER: [(u8, u8); (TILE * TILE) as usize] = {
    let mut order = [(0, 0); (TILE * TILE) as usize];
    let mut code = 0;
    while code < order.len() {
        order[code] = (deinterleave(code as u32), deinterleave(code as u32 >> 1));
        code += 1;
    }
    order
};

/// The even bits of `code` (bits 0, 2, ..., 14) packed into a byte.
const fn deinterleave(code: u32) -> u8 {
    let mut packed = 0;
    let mut bit = 0;
    while bit < 8 {
        packed |= ((code >> (2 * bit)) & 1) << bit;
        bit += 1;
    }
    packed as u8
}

/// The pixels of the tile whose corner is `(x0, y0)` in a `width x height` image, in Morton
/// order: every run of 4^k pixels of a whole tile is a square block of 2^k x 2^k (a packet
/// of 64 primary rays at one sample per pixel is an 8 x 8 block, at four samples a 4 x 4
/// block), and a tile cut by the image's edge keeps the order of the pixels it has.
pub fn tile_pixels(
    (x0, y0): (u32, u32),
    width: u32,
    height: u32,
) -> impl Iterator<Item = (u32, u32)> {
    debug_assert!(x0 < width && y0 < height);
    let (w, h) = (TILE.min(width - x0), TILE.min(height - y0));
    MORTON_ORDER
        .iter()
        .map(|&(x, y)| (u32::from(x), u32::from(y)))
        .filter(move |&(x, y)| x < w && y < h)
        .map(move |(x, y)| (x0 + x, y0 + y))
}

/// Where pixel `(x, y)` of a `width`-pixel-wide image comes in the film's order: its tile
/// (row-major tiles) and its place in the tile's Morton order ([`tile_pixels`] lists a
/// tile's pixels by increasing place).
#[inline]
pub fn film_position(x: u32, y: u32, width: u32) -> (u32, u32) {
    // Saturating: a pixel of the image (`y * width + x` a u32) never reaches the limit.
    let tile = (y / TILE)
        .saturating_mul(width.div_ceil(TILE))
        .saturating_add(x / TILE);
    // The inverse of `deinterleave`: x's bits in the even places, y's in the odd ones.
    let spread = |v: u32| (0..8).fold(0, |code, bit| code | ((v >> bit) & 1) << (2 * bit));
    (tile, spread(x % TILE) | spread(y % TILE) << 1)
}

/// A rendered frame in linear RGB, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl LinearImage {
    /// 8-bit sRGB RGB bytes (clamped to [0, 1], rounded).
    pub fn to_srgb8(&self) -> Vec<u8> {
        let encoder = srgb8_encoder();
        self.pixels
            .iter()
            .flat_map(|p| p.to_array().map(|c| encoder.encode(c)))
            .collect()
    }
}

/// Renders all pixels of `camera` with `spp` samples each.
pub fn render_image(scene: &FrameScene, camera: &Camera, spp: u32) -> (LinearImage, TraceCounters) {
    render_image_with(scene, camera, spp, false)
}

/// [`render_image`], also recording every ray traced (`TraceCounters::log`, in film order:
/// tile by tile, each tile's rays in the order it traced them). The image is the same.
pub fn render_image_recording(
    scene: &FrameScene,
    camera: &Camera,
    spp: u32,
) -> (LinearImage, TraceCounters) {
    render_image_with(scene, camera, spp, true)
}

fn render_image_with(
    scene: &FrameScene,
    camera: &Camera,
    spp: u32,
    record: bool,
) -> (LinearImage, TraceCounters) {
    let (width, height) = (camera.width, camera.height);
    let mut image = LinearImage {
        width,
        height,
        pixels: vec![Vec3::ZERO; width as usize * height as usize],
    };
    let tiles = tile_rows(&mut image.pixels, width, height);
    let tile_counters =
        with_lod_state!(scene.lod, L => render_tiles::<L>(scene, camera, spp, record, tiles));
    let mut counters = if record {
        TraceCounters::recording()
    } else {
        TraceCounters::default()
    };
    for tile_counters in &tile_counters {
        counters.add(tile_counters);
    }
    (image, counters)
}

/// The rows of each tile of a `width x height` image whose pixels are `pixels`, tiles in
/// row-major order, each tile's rows top to bottom (each at most [`TILE`] pixels wide):
/// disjoint borrows, so the tiles can be written in parallel without copies.
fn tile_rows(pixels: &mut [Vec3], width: u32, height: u32) -> Vec<Vec<&mut [Vec3]>> {
    let tiles_x = width.div_ceil(TILE) as usize;
    let tiles_y = height.div_ceil(TILE) as usize;
    let side = TILE as usize;
    if tiles_x == 0 || tiles_y == 0 {
        return Vec::new();
    }
    let mut tiles: Vec<Vec<&mut [Vec3]>> = (0..tiles_x * tiles_y)
        .map(|tile| Vec::with_capacity(side.min(height as usize - tile / tiles_x * side)))
        .collect();
    for (y, row) in pixels.chunks_exact_mut(width as usize).enumerate() {
        let band = &mut tiles[y / side * tiles_x..][..tiles_x];
        for (rows, segment) in band.iter_mut().zip(row.chunks_mut(side)) {
            rows.push(segment);
        }
    }
    tiles
}

/// Renders every tile into its rows (`tiles`, from [`tile_rows`]) with the LOD state type
/// of `scene.lod` (chosen once here, so the per-ray code is monomorphised per method);
/// returns each tile's counters in tile order. Each worker keeps one set of working lists
/// for all the tiles it renders (`map_init`).
fn render_tiles<L: RayLod>(
    scene: &FrameScene,
    camera: &Camera,
    spp: u32,
    record: bool,
    tiles: Vec<Vec<&mut [Vec3]>>,
) -> Vec<TraceCounters> {
    let tiles_x = camera.width.div_ceil(TILE);
    tiles
        .into_par_iter()
        .enumerate()
        .map_init(TileBuffers::<L>::default, |buffers, (tile, mut rows)| {
            let mut counters = if record {
                TraceCounters::recording()
            } else {
                TraceCounters::default()
            };
            let tile = tile as u32;
            let origin = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
            crate::simd::dispatch(TraceTile {
                scene,
                camera,
                spp,
                corner: origin,
                counters: &mut counters,
                buffers,
                rows: &mut rows,
            });
            counters
        })
        .collect()
}

/// Sub-pixel position of sample `i` of `spp`: the pixel centre for one sample, otherwise a
/// jittered point in stratum `i` of an `n x n` grid, `n = ceil(sqrt(spp))` (a square `spp`
/// fills the grid exactly; others use its first `spp` strata, row by row).
pub fn sample_offset(x: u32, y: u32, i: u32, spp: u32) -> (f32, f32) {
    if spp <= 1 {
        return (0.5, 0.5);
    }
    let n = (spp as f64).sqrt().ceil() as u32;
    let h = hash3(x, y, i);
    let jx = (h & 0xffff) as f32 / 65536.0;
    let jy = (h >> 16) as f32 / 65536.0;
    (
        ((i % n) as f32 + jx) / n as f32,
        ((i / n) as f32 + jy) / n as f32,
    )
}

/// A 32-bit integer hash (lowbias32 by Chris Wellons) of three integers.
fn hash3(x: u32, y: u32, z: u32) -> u32 {
    let mut h =
        x.wrapping_mul(0x9e37_79b9) ^ y.wrapping_mul(0x85eb_ca6b) ^ z.wrapping_mul(0xc2b2_ae35);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^ (h >> 16)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel belongs to exactly one tile, in the row of that tile's origin that
    /// `render_tiles` gives it (tiles row-major), edge tiles cut by the image.
    #[test]
    fn tile_rows_cover_every_pixel_once_at_its_tiles_origin() {
        for (width, height) in [
            (1u32, 1u32),
            (33, 65),
            (100, 37),
            (64, 32),
            (1, 70),
            (70, 1),
        ] {
            let mut pixels: Vec<Vec3> = (0..width * height)
                .map(|i| Vec3::new(i as f32, 0.0, 0.0))
                .collect();
            let tiles_x = width.div_ceil(TILE);
            let tiles = tile_rows(&mut pixels, width, height);
            assert_eq!(tiles.len() as u32, tiles_x * height.div_ceil(TILE));
            let mut seen = vec![0u32; (width * height) as usize];
            for (tile, rows) in tiles.iter().enumerate() {
                let (x0, y0) = (
                    (tile as u32 % tiles_x) * TILE,
                    (tile as u32 / tiles_x) * TILE,
                );
                assert_eq!(rows.len() as u32, TILE.min(height - y0), "{width}x{height}");
                for (dy, row) in rows.iter().enumerate() {
                    assert_eq!(row.len() as u32, TILE.min(width - x0), "{width}x{height}");
                    for (dx, p) in row.iter().enumerate() {
                        let index = (y0 + dy as u32) * width + x0 + dx as u32;
                        assert_eq!(p.x, index as f32, "{width}x{height} tile {tile}");
                        seen[index as usize] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&n| n == 1), "{width}x{height}");
        }
        let mut empty: Vec<Vec3> = Vec::new();
        assert!(tile_rows(&mut empty, 0, 5).is_empty());
        assert!(tile_rows(&mut empty, 5, 0).is_empty());
    }

    /// Walking the tiles and each tile's pixels in the film's order, a pixel's position
    /// names its tile and rises at every step (images of whole and cut tiles).
    #[test]
    fn a_pixel_s_film_position_is_its_place_in_the_film_s_order() {
        for (width, height) in [(800u32, 600u32), (32, 32), (33, 70), (1, 1)] {
            let tiles_x = width.div_ceil(TILE);
            let mut last = None;
            for tile in 0..tiles_x * height.div_ceil(TILE) {
                let corner = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
                for (x, y) in tile_pixels(corner, width, height) {
                    let position = film_position(x, y, width);
                    assert_eq!(position.0, tile, "({x}, {y}) in {width}x{height}");
                    assert!(last < Some(position), "({x}, {y}) in {width}x{height}");
                    last = Some(position);
                }
            }
        }
    }

    /// Every pixel of a whole or partial tile comes exactly once; in a whole tile every run
    /// of 4^k pixels (a packet of 64 rays at one sample per pixel, of 16 pixels at four) is
    /// a square block of 2^k x 2^k.
    #[test]
    fn a_tile_s_pixels_come_once_each_in_square_blocks() {
        for (w, h) in [(TILE, TILE), (1, 1), (TILE, 3), (5, TILE), (7, 9)] {
            let order: Vec<(u32, u32)> = tile_pixels((0, 0), w, h).collect();
            assert_eq!(order.len(), (w * h) as usize, "{w}x{h}");
            let mut seen = vec![false; (w * h) as usize];
            for &(x, y) in &order {
                assert!(x < w && y < h, "{w}x{h}: ({x}, {y})");
                assert!(!std::mem::replace(&mut seen[(y * w + x) as usize], true));
            }
        }
        let whole: Vec<(u32, u32)> = tile_pixels((0, 0), TILE, TILE).collect();
        // A tile cut by the image's edge keeps the whole tile's order, at its own corner.
        for (w, h) in [(TILE, 3), (5, TILE), (7, 9)] {
            let inside = whole.iter().copied().filter(|&(x, y)| x < w && y < h);
            assert!(tile_pixels((0, 0), w, h).eq(inside), "{w}x{h}");
            let (x0, y0) = (3 * TILE, TILE);
            let placed = whole
                .iter()
                .filter(|&&(x, y)| x < w && y < h)
                .map(|&(x, y)| (x0 + x, y0 + y));
            assert!(
                tile_pixels((x0, y0), x0 + w, y0 + h).eq(placed),
                "{w}x{h} at ({x0}, {y0})"
            );
        }
        for side in [2u32, 4, 8, 16, TILE] {
            for run in whole.chunks((side * side) as usize) {
                let (x0, y0) = run[0];
                assert!(x0 % side == 0 && y0 % side == 0, "{side}: {run:?}");
                assert!(
                    run.iter()
                        .all(|&(x, y)| x / side == x0 / side && y / side == y0 / side),
                    "{side}: {run:?}"
                );
            }
        }
    }

    #[test]
    fn samples_are_stratified_and_inside_the_pixel() {
        let spp = 16;
        let mut seen = vec![false; 16];
        for i in 0..spp {
            let (sx, sy) = sample_offset(5, 9, i, spp);
            assert!((0.0..1.0).contains(&sx) && (0.0..1.0).contains(&sy));
            let stratum = (sy * 4.0) as usize * 4 + (sx * 4.0) as usize;
            assert!(!seen[stratum], "two samples in stratum {stratum}");
            seen[stratum] = true;
        }
        assert_eq!(sample_offset(1, 2, 0, 1), (0.5, 0.5));
    }
}
