//! Image metrics between a reference frame and a test frame, on 8-bit sRGB pixels (what a
//! person sees): PSNR, mean FLIP, maximum absolute channel difference, share of differing
//! pixels, and a FLIP heat map.
//!
//! PSNR is `10 log10(255^2 / MSE)` over all three channels; identical images have an
//! infinite PSNR (written as `inf` in tables). Mean FLIP is the LDR-FLIP of Andersson et al.
//! (2020) at 67 pixels per degree, from NVIDIA's reference implementation (`nv-flip`).

pub mod ssim;
pub mod temporal;

use std::path::Path;

use image::RgbImage;

/// How far a test frame is from its reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMetrics {
    /// Peak signal-to-noise ratio in dB (`f64::INFINITY` when identical).
    pub psnr_db: f64,
    /// Mean FLIP error in [0, 1].
    pub mean_flip: f64,
    /// Largest absolute difference of any channel of any pixel (0-255).
    pub max_abs: u8,
    /// Pixels with any channel different.
    pub differing_pixels: u64,
    /// `differing_pixels / pixel count`.
    pub differing_share: f64,
}

/// Errors reading or comparing frames.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    #[error("{path}: cannot read image: {message}")]
    Read { path: String, message: String },
    #[error("{reference} is {rw}x{rh} but {test} is {tw}x{th}")]
    SizeMismatch {
        reference: String,
        test: String,
        rw: u32,
        rh: u32,
        tw: u32,
        th: u32,
    },
}

/// Reads a frame as 8-bit sRGB: PNG as stored; float images (EXR, linear) are encoded with
/// the sRGB transfer function first, as the PNG writer does.
pub fn read_srgb8(path: &Path) -> Result<RgbImage, MetricsError> {
    let err = |message: String| MetricsError::Read {
        path: path.display().to_string(),
        message,
    };
    let image = image::open(path).map_err(|e| err(e.to_string()))?;
    Ok(match image {
        image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_) => {
            let linear = image.to_rgb32f();
            let (w, h) = linear.dimensions();
            let bytes = linear
                .into_raw()
                .into_iter()
                .map(crate::colour::encode_srgb8)
                .collect();
            RgbImage::from_raw(w, h, bytes).expect("same size")
        }
        other => other.to_rgb8(),
    })
}

/// Compares two frames of equal size; returns the metrics and FLIP's per-pixel error map.
pub fn compare(reference: &RgbImage, test: &RgbImage) -> (FrameMetrics, nv_flip::FlipImageFloat) {
    debug_assert_eq!(reference.dimensions(), test.dimensions());
    let (w, h) = reference.dimensions();
    let mut squared = 0u64;
    let mut max_abs = 0u8;
    let mut differing_pixels = 0u64;
    for (a, b) in reference.pixels().zip(test.pixels()) {
        let mut differs = false;
        for c in 0..3 {
            let d = a.0[c].abs_diff(b.0[c]);
            squared += d as u64 * d as u64;
            max_abs = max_abs.max(d);
            differs |= d != 0;
        }
        differing_pixels += differs as u64;
    }
    let pixels = (w as u64 * h as u64).max(1);
    let mse = squared as f64 / (3 * pixels) as f64;
    let psnr_db = if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    };
    let flip_ref = nv_flip::FlipImageRgb8::with_data(w, h, reference.as_raw());
    let flip_test = nv_flip::FlipImageRgb8::with_data(w, h, test.as_raw());
    let error_map = nv_flip::flip(flip_ref, flip_test, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    let mean_flip = nv_flip::FlipPool::from_image(&error_map).mean() as f64;
    let metrics = FrameMetrics {
        psnr_db,
        mean_flip,
        max_abs,
        differing_pixels,
        differing_share: differing_pixels as f64 / pixels as f64,
    };
    (metrics, error_map)
}

/// FLIP's error map coloured with the magma palette (black: no difference).
pub fn heat_map(error_map: &nv_flip::FlipImageFloat) -> RgbImage {
    let coloured = error_map.apply_color_lut(&nv_flip::magma_lut());
    RgbImage::from_raw(coloured.width(), coloured.height(), coloured.to_vec())
        .expect("FLIP returns w*h*3 bytes")
}

/// Formats a PSNR for tables (`inf` for identical frames).
pub fn format_psnr(psnr_db: f64) -> String {
    if psnr_db.is_infinite() {
        "inf".to_string()
    } else {
        format!("{psnr_db:.2}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            image::Rgb([
                (x * 7 % 256) as u8,
                (y * 5 % 256) as u8,
                ((x + y) * 3 % 256) as u8,
            ])
        })
    }

    #[test]
    fn identical_frames_have_infinite_psnr_and_zero_flip() {
        let a = gradient(32, 24);
        let (m, _) = compare(&a, &a);
        assert!(m.psnr_db.is_infinite());
        assert_eq!((m.max_abs, m.differing_pixels), (0, 0));
        assert_eq!(m.mean_flip, 0.0);
    }

    #[test]
    fn one_changed_pixel_gives_the_closed_form_psnr() {
        let a = gradient(32, 24);
        let mut b = a.clone();
        let p = b.get_pixel_mut(5, 7);
        p.0[1] = p.0[1].wrapping_add(100);
        let (m, error_map) = compare(&a, &b);
        // MSE = 100^2 / (3 * 32 * 24).
        let expected = 10.0 * (255.0f64 * 255.0 / (10_000.0 / (3.0 * 768.0))).log10();
        assert!(
            (m.psnr_db - expected).abs() < 1e-9,
            "{} vs {expected}",
            m.psnr_db
        );
        assert_eq!((m.max_abs, m.differing_pixels), (100, 1));
        assert!((m.differing_share - 1.0 / 768.0).abs() < 1e-12);
        assert!(m.mean_flip > 0.0 && m.mean_flip < 0.05, "{}", m.mean_flip);
        assert_eq!(heat_map(&error_map).dimensions(), (32, 24));
    }
}
