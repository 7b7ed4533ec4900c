//! `--view lod`: a false-colour image of the MIP level each pixel's texture lookup uses.
//!
//! Each pixel shows the level the frame's method selects (with its bias, clamped to the
//! texture's pyramid) at the first textured surface its centre ray reaches, directly or
//! through mirrors and glass (the dominant specular branch, as `FrameScene::probe`).
//! Colours run through fixed stops, one per level, blended for fractional levels:
//! 0 dark blue, 1 blue, 2 cyan, 3 green, 4 yellow, 5 orange, 6 red, 7 magenta, 8 and
//! above white. Pixels with no textured surface are black.

use image::RgbImage;
use rayon::prelude::*;

use crate::render::Camera;
use crate::render::integrator::FrameScene;

/// The colour of each integer level (sRGB bytes); past the last, the last.
pub const LEVEL_COLOURS: [[u8; 3]; 9] = [
    [20, 20, 120],
    [40, 90, 255],
    [0, 210, 230],
    [40, 200, 60],
    [250, 230, 40],
    [255, 140, 0],
    [230, 30, 30],
    [220, 40, 220],
    [255, 255, 255],
];

/// The false colour of a (finite or not) level: stops blended linearly.
pub fn level_colour(level: f32) -> [u8; 3] {
    let last = (LEVEL_COLOURS.len() - 1) as f32;
    // `max` maps NaN to 0 before the clamp.
    let level = level.max(0.0).min(last);
    let lower = level.floor() as usize;
    let upper = (lower + 1).min(LEVEL_COLOURS.len() - 1);
    let f = level - lower as f32;
    let (a, b) = (LEVEL_COLOURS[lower], LEVEL_COLOURS[upper]);
    [0, 1, 2].map(|c| (a[c] as f32 * (1.0 - f) + b[c] as f32 * f).round() as u8)
}

/// The level image of `scene.lod` seen through `camera`.
pub fn lod_image(scene: &FrameScene, camera: &Camera) -> RgbImage {
    let (w, h) = (camera.width, camera.height);
    let bytes: Vec<u8> = (0..w * h)
        .into_par_iter()
        .flat_map_iter(|i| {
            let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            match scene.probe_method(camera, x, y) {
                Some(p) => level_colour(p.clamped_level),
                None => [0, 0, 0],
            }
        })
        .collect();
    RgbImage::from_raw(w, h, bytes).expect("w * h * 3 bytes")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_hit_the_stops_and_blend_between_them() {
        assert_eq!(level_colour(0.0), LEVEL_COLOURS[0]);
        assert_eq!(level_colour(3.0), LEVEL_COLOURS[3]);
        assert_eq!(level_colour(100.0), LEVEL_COLOURS[8]);
        assert_eq!(level_colour(f32::NAN), LEVEL_COLOURS[0]);
        assert_eq!(level_colour(-2.0), LEVEL_COLOURS[0]);
        let mid = level_colour(0.5);
        for c in 0..3 {
            let (a, b) = (LEVEL_COLOURS[0][c] as i32, LEVEL_COLOURS[1][c] as i32);
            assert!((mid[c] as i32 - (a + b) / 2).abs() <= 1);
        }
    }
}
