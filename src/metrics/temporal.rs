//! Temporal flicker: how much a method's change from one frame to the next departs from the
//! reference's change over the same two frames.
//!
//! Per-frame metrics (PSNR, FLIP, SSIM) score each frame alone, so they miss aliasing that
//! shows only in motion: a minified texture sampled at too fine a MIP level shimmers, its
//! pixels jumping between texels from frame to frame where the converged reference changes
//! smoothly or not at all. Flicker compares the frame-to-frame differences instead:
//!
//! `flicker = mean over pixels and channels of |(test - previous_test) - (reference - previous_reference)|`
//!
//! in 8-bit sRGB code values (0-510). It is 0 when the test changes exactly as the reference
//! does, including when the test is off by a constant bias in both frames (a bias is an
//! error of each frame, not flicker), and grows with changes the reference does not have.

use image::RgbImage;

/// Mean absolute difference, per pixel and channel in code values, between the test's
/// frame-to-frame change (`test - previous_test`) and the reference's
/// (`reference - previous_reference`).
///
/// All four images must have the same size; if they do not, or they are empty, the result
/// is `f64::NAN` (this never panics).
pub fn flicker(
    previous_test: &RgbImage,
    test: &RgbImage,
    previous_reference: &RgbImage,
    reference: &RgbImage,
) -> f64 {
    let size = test.dimensions();
    let frames = [previous_test, previous_reference, reference];
    if frames.iter().any(|frame| frame.dimensions() != size) || test.as_raw().is_empty() {
        return f64::NAN;
    }
    let total = total_change_difference(
        previous_test.as_raw(),
        test.as_raw(),
        previous_reference.as_raw(),
        reference.as_raw(),
    );
    total as f64 / test.as_raw().len() as f64
}

/// Sum over all channel values of `|(test - previous_test) - (reference - previous_reference)|`.
/// Integer arithmetic, so the sum is exact (at most 510 per value, far below `u64::MAX`).
fn total_change_difference(
    previous_test: &[u8],
    test: &[u8],
    previous_reference: &[u8],
    reference: &[u8],
) -> u64 {
    previous_test
        .iter()
        .zip(test)
        .zip(previous_reference.iter().zip(reference))
        .map(|((&pt, &t), (&pr, &r))| {
            let test_change = t as i32 - pt as i32;
            let reference_change = r as i32 - pr as i32;
            (test_change - reference_change).unsigned_abs() as u64
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    fn gradient(width: u32, height: u32, phase: u32) -> RgbImage {
        RgbImage::from_fn(width, height, |x, y| {
            Rgb([
                ((x * 11 + phase) % 200) as u8,
                ((y * 7 + phase * 3) % 200) as u8,
                ((x + y + phase) % 200) as u8,
            ])
        })
    }

    fn add_offset(image: &RgbImage, offset: u8) -> RgbImage {
        let mut shifted = image.clone();
        shifted
            .pixels_mut()
            .for_each(|p| p.0 = p.0.map(|v| v + offset));
        shifted
    }

    #[test]
    fn identical_sequences_give_zero() {
        let (first, second) = (gradient(9, 7, 0), gradient(9, 7, 5));
        assert_eq!(flicker(&first, &second, &first, &second), 0.0);
    }

    #[test]
    fn constant_bias_is_not_flicker() {
        let (first, second) = (gradient(9, 7, 0), gradient(9, 7, 5));
        let (biased_first, biased_second) = (add_offset(&first, 40), add_offset(&second, 40));
        assert_eq!(flicker(&biased_first, &biased_second, &first, &second), 0.0);
    }

    #[test]
    fn toggling_checker_over_a_still_reference_gives_the_exact_mean() {
        // 5x3 pixels, 8 of them on the checker ((x + y) even); their red channel goes from
        // 100 to 140 while the reference stays still: 8 * 40 over 15 pixels * 3 channels.
        let still = RgbImage::from_pixel(5, 3, Rgb([100, 100, 100]));
        let toggled = RgbImage::from_fn(5, 3, |x, y| {
            let red = if (x + y) % 2 == 0 { 140 } else { 100 };
            Rgb([red, 100, 100])
        });
        assert_eq!(flicker(&still, &toggled, &still, &still), 320.0 / 45.0);
        // Toggling back is the same amount of flicker in the other direction.
        assert_eq!(flicker(&toggled, &still, &still, &still), 320.0 / 45.0);
    }

    #[test]
    fn full_black_white_inversion_over_a_still_reference_gives_255() {
        let checker = |invert: bool| {
            RgbImage::from_fn(4, 4, |x, y| {
                let on = ((x + y) % 2 == 0) != invert;
                Rgb([if on { 255 } else { 0 }; 3])
            })
        };
        let grey = RgbImage::from_pixel(4, 4, Rgb([128; 3]));
        assert_eq!(
            flicker(&checker(false), &checker(true), &grey, &grey),
            255.0
        );
    }

    #[test]
    fn size_mismatch_or_empty_images_give_nan() {
        let a = gradient(6, 4, 0);
        let b = gradient(6, 5, 0);
        assert!(flicker(&a, &a, &a, &b).is_nan());
        assert!(flicker(&b, &a, &a, &a).is_nan());
        let empty = RgbImage::new(0, 0);
        assert!(flicker(&empty, &empty, &empty, &empty).is_nan());
    }
}
