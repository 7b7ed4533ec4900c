//! Structural similarity (SSIM) of Wang, Bovik, Sheikh and Simoncelli, "Image quality
//! assessment: from error visibility to structural similarity" (IEEE TIP, 2004).
//!
//! Constants are those of the paper and of its reference MATLAB code (`ssim_index.m`): an
//! 11x11 Gaussian window with sigma 1.5 whose weights are normalised to sum 1,
//! `K1 = 0.01`, `K2 = 0.03` and a dynamic range `L = 255`, so `C1 = (K1 L)^2` and
//! `C2 = (K2 L)^2`. Pixels are compared as 8-bit sRGB code values (0-255), what a person
//! sees, with all sums in `f64`.
//!
//! Convention: the SSIM map is computed for each channel (R, G, B) separately and averaged
//! over the 'valid' window positions only, those where the whole window lies inside the
//! image (as `filter2(window, img, 'valid')` in the reference code; no padding, so an
//! `w x h` image has `(w - 10) x (h - 10)` map entries). The result is the mean of the three
//! channels' mean SSIM. Like `ssim_index.m`, and unlike the later `ssim.m`, the images are
//! not downsampled first.
//!
//! Images smaller than 11 pixels in either dimension have no valid position; for them the
//! window is truncated at the image borders and its Gaussian weights are renormalised over
//! the pixels inside, and the map covers every pixel. This is a fallback so that tiny test
//! images still get a finite score; it is not part of the published metric.
//!
//! Written in-house because the SSIM of the `image-compare` crate is not the standard one
//! (different window and constants), so its scores cannot be compared with published ones.
//!
//! The Gaussian window is separable, so each of the five local moments (`E[x]`, `E[y]`,
//! `E[x^2]`, `E[y^2]`, `E[xy]`) is filtered horizontally and then vertically: 22 taps per
//! pixel instead of 121. Horizontally filtered rows are kept in a ring of 11 rows, so the
//! memory used is a few rows whatever the image height.

use image::RgbImage;

/// Side of the square Gaussian window, in pixels.
const WINDOW: usize = 11;
/// Pixels on each side of the window's centre.
const RADIUS: usize = WINDOW / 2;
/// Standard deviation of the Gaussian window, in pixels.
const SIGMA: f64 = 1.5;
const K1: f64 = 0.01;
const K2: f64 = 0.03;
/// Dynamic range of 8-bit code values.
const DYNAMIC_RANGE: f64 = 255.0;
/// Stabilises the luminance term when both local means are near zero.
const C1: f64 = (K1 * DYNAMIC_RANGE) * (K1 * DYNAMIC_RANGE);
/// Stabilises the contrast-structure term when both local variances are near zero.
const C2: f64 = (K2 * DYNAMIC_RANGE) * (K2 * DYNAMIC_RANGE);

/// Local moments filtered by the window: `E[x]`, `E[y]`, `E[x^2]`, `E[y^2]`, `E[xy]`.
const MOMENTS: usize = 5;

/// Mean SSIM of `test` against `reference`: the mean over the R, G and B channels of each
/// channel's mean SSIM over the valid window positions (see the module documentation).
///
/// Returns 1 for identical images. Both images must have the same size; if they differ, or
/// the images are empty, the result is `f64::NAN` (this never panics).
pub fn ssim(reference: &RgbImage, test: &RgbImage) -> f64 {
    if reference.dimensions() != test.dimensions() {
        return f64::NAN;
    }
    let (width, height) = reference.dimensions();
    let (width, height) = (width as usize, height as usize);
    if width == 0 || height == 0 {
        return f64::NAN;
    }
    let (columns, rows) = if width < WINDOW || height < WINDOW {
        (
            AxisWindows::truncated(width),
            AxisWindows::truncated(height),
        )
    } else {
        (AxisWindows::valid(width), AxisWindows::valid(height))
    };
    let mut scratch = Scratch::new(width, columns.len());
    let channel_sum: f64 = (0..3)
        .map(|channel| {
            let planes = ChannelPair {
                reference: reference.as_raw(),
                test: test.as_raw(),
                width,
                channel,
            };
            mean_channel_ssim(&planes, &columns, &rows, &mut scratch)
        })
        .sum();
    channel_sum / 3.0
}

/// The 1D Gaussian of the window, normalised to sum 1. The 2D window is its outer product
/// with itself, which then also sums to 1.
fn gaussian_weights() -> [f64; WINDOW] {
    let mut weights = [0.0; WINDOW];
    for (i, weight) in weights.iter_mut().enumerate() {
        let offset = i as f64 - RADIUS as f64;
        *weight = (-offset * offset / (2.0 * SIGMA * SIGMA)).exp();
    }
    let sum: f64 = weights.iter().sum();
    weights.iter_mut().for_each(|weight| *weight /= sum);
    weights
}

/// The windows along one axis of the image: for each output position, the first input
/// index it covers and its weights (at most `WINDOW` of them).
struct AxisWindows {
    starts: Vec<usize>,
    lengths: Vec<usize>,
    /// `WINDOW` slots per output position; the first `lengths[i]` are used.
    weights: Vec<f64>,
}

impl AxisWindows {
    /// Windows fully inside an axis of `n >= WINDOW` pixels, with the full Gaussian.
    fn valid(n: usize) -> Self {
        let outputs = n + 1 - WINDOW;
        let gaussian = gaussian_weights();
        AxisWindows {
            starts: (0..outputs).collect(),
            lengths: vec![WINDOW; outputs],
            weights: gaussian.repeat(outputs),
        }
    }

    /// One window centred on each of the `n` pixels, cut at both ends of the axis, with the
    /// Gaussian weights left renormalised to sum 1. The 2D window cut by the image is a
    /// rectangle, so renormalising each axis renormalises the 2D weights too.
    fn truncated(n: usize) -> Self {
        let gaussian = gaussian_weights();
        let mut windows = AxisWindows {
            starts: Vec::with_capacity(n),
            lengths: Vec::with_capacity(n),
            weights: vec![0.0; n * WINDOW],
        };
        for centre in 0..n {
            let first = centre.saturating_sub(RADIUS);
            let end = (centre + RADIUS + 1).min(n);
            let kept = &gaussian[first + RADIUS - centre..end + RADIUS - centre];
            let sum: f64 = kept.iter().sum();
            let slots = &mut windows.weights[centre * WINDOW..centre * WINDOW + kept.len()];
            for (slot, &weight) in slots.iter_mut().zip(kept) {
                *slot = weight / sum;
            }
            windows.starts.push(first);
            windows.lengths.push(end - first);
        }
        windows
    }

    /// Number of output positions.
    fn len(&self) -> usize {
        self.starts.len()
    }

    /// First input index and weights of output position `i`.
    fn window(&self, i: usize) -> (usize, &[f64]) {
        let weights = &self.weights[i * WINDOW..i * WINDOW + self.lengths[i]];
        (self.starts[i], weights)
    }
}

/// One channel of the two interleaved RGB images being compared.
struct ChannelPair<'a> {
    reference: &'a [u8],
    test: &'a [u8],
    width: usize,
    channel: usize,
}

impl ChannelPair<'_> {
    /// Copies row `y` of the channel of both images as `f64`, into `reference_row` and
    /// `test_row` (each `width` long).
    fn read_row(&self, y: usize, reference_row: &mut [f64], test_row: &mut [f64]) {
        let span = y * self.width * 3..(y + 1) * self.width * 3;
        let pixels = self.reference[span.clone()]
            .chunks_exact(3)
            .zip(self.test[span].chunks_exact(3));
        for ((r, t), (a, b)) in reference_row
            .iter_mut()
            .zip(test_row.iter_mut())
            .zip(pixels)
        {
            *r = a[self.channel] as f64;
            *t = b[self.channel] as f64;
        }
    }
}

/// Buffers reused across rows and channels, so no allocation happens per pixel.
struct Scratch {
    reference_row: Vec<f64>,
    test_row: Vec<f64>,
    /// Horizontally filtered moments: `WINDOW` rows of `outputs` each; image row `y` is in
    /// slot `y % WINDOW`, which is free again once the vertical windows have moved past it.
    ring: [Vec<f64>; MOMENTS],
    /// Fully (horizontally then vertically) filtered moments of one output row.
    filtered: [Vec<f64>; MOMENTS],
    /// Output positions per row.
    outputs: usize,
}

impl Scratch {
    fn new(width: usize, outputs: usize) -> Self {
        Scratch {
            reference_row: vec![0.0; width],
            test_row: vec![0.0; width],
            ring: std::array::from_fn(|_| vec![0.0; WINDOW * outputs]),
            filtered: std::array::from_fn(|_| vec![0.0; outputs]),
            outputs,
        }
    }
}

/// Mean of one channel's SSIM map over all output positions.
fn mean_channel_ssim(
    planes: &ChannelPair,
    columns: &AxisWindows,
    rows: &AxisWindows,
    scratch: &mut Scratch,
) -> f64 {
    // Rows `0..rows_in_ring` have been filtered horizontally; windows only move down, so
    // each image row is filtered once.
    let mut rows_in_ring = 0;
    let mut sum = 0.0;
    for output_row in 0..rows.len() {
        let (first, weights) = rows.window(output_row);
        while rows_in_ring < first + weights.len() {
            filter_row_horizontally(planes, rows_in_ring, columns, scratch);
            rows_in_ring += 1;
        }
        filter_vertically(first, weights, scratch);
        sum += ssim_row_sum(&scratch.filtered);
    }
    sum / (rows.len() * columns.len()) as f64
}

/// Filters the five moments of image row `y` along the row into its ring slot.
fn filter_row_horizontally(
    planes: &ChannelPair,
    y: usize,
    columns: &AxisWindows,
    scratch: &mut Scratch,
) {
    planes.read_row(y, &mut scratch.reference_row, &mut scratch.test_row);
    let slot = (y % WINDOW) * scratch.outputs..(y % WINDOW + 1) * scratch.outputs;
    let [mean_x, mean_y, mean_xx, mean_yy, mean_xy] = &mut scratch.ring;
    for (i, output) in slot.enumerate() {
        let (first, weights) = columns.window(i);
        let xs = &scratch.reference_row[first..first + weights.len()];
        let ys = &scratch.test_row[first..first + weights.len()];
        let mut sums = [0.0; MOMENTS];
        for ((&weight, &x), &y) in weights.iter().zip(xs).zip(ys) {
            sums[0] += weight * x;
            sums[1] += weight * y;
            sums[2] += weight * x * x;
            sums[3] += weight * y * y;
            sums[4] += weight * x * y;
        }
        mean_x[output] = sums[0];
        mean_y[output] = sums[1];
        mean_xx[output] = sums[2];
        mean_yy[output] = sums[3];
        mean_xy[output] = sums[4];
    }
}

/// Filters the horizontally filtered rows `first..first + weights.len()` down the columns
/// into `scratch.filtered`. Whole rows at a time, so the inner loop is contiguous.
fn filter_vertically(first: usize, weights: &[f64], scratch: &mut Scratch) {
    let outputs = scratch.outputs;
    for (moment, filtered) in scratch.ring.iter().zip(scratch.filtered.iter_mut()) {
        filtered.fill(0.0);
        for (k, &weight) in weights.iter().enumerate() {
            let slot = (first + k) % WINDOW;
            let row = &moment[slot * outputs..(slot + 1) * outputs];
            for (sum, &value) in filtered.iter_mut().zip(row) {
                *sum += weight * value;
            }
        }
    }
}

/// Sum of the SSIM of every position of one output row.
fn ssim_row_sum(filtered: &[Vec<f64>; MOMENTS]) -> f64 {
    let [mean_x, mean_y, mean_xx, mean_yy, mean_xy] = filtered;
    mean_x
        .iter()
        .zip(mean_y)
        .zip(mean_xx)
        .zip(mean_yy)
        .zip(mean_xy)
        .map(|((((&mx, &my), &exx), &eyy), &exy)| ssim_from_moments(mx, my, exx, eyy, exy))
        .sum()
}

/// SSIM of one window from its weighted moments (equation 13 of the paper). For identical
/// windows the numerator and denominator are computed from equal terms (`2ab` with `a = b`
/// is `a^2 + b^2` exactly in floating point), so the result is exactly 1.
fn ssim_from_moments(mean_x: f64, mean_y: f64, mean_xx: f64, mean_yy: f64, mean_xy: f64) -> f64 {
    let variance_x = mean_xx - mean_x * mean_x;
    let variance_y = mean_yy - mean_y * mean_y;
    let covariance = mean_xy - mean_x * mean_y;
    let luminance = (2.0 * mean_x * mean_y + C1) / (mean_x * mean_x + mean_y * mean_y + C1);
    let contrast_structure = (2.0 * covariance + C2) / (variance_x + variance_y + C2);
    luminance * contrast_structure
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    /// Deterministic pseudo-random bytes (xorshift64), so tests need no extra crate.
    struct Noise(u64);

    impl Noise {
        fn next_byte(&mut self) -> u8 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 56) as u8
        }
    }

    fn noise_image(width: u32, height: u32, seed: u64) -> RgbImage {
        let mut noise = Noise(seed);
        RgbImage::from_fn(width, height, |_, _| {
            Rgb([noise.next_byte(), noise.next_byte(), noise.next_byte()])
        })
    }

    /// Mid-grey with +-16 of noise: room for offsets without clipping.
    fn noisy_grey(width: u32, height: u32, seed: u64) -> RgbImage {
        let mut noise = Noise(seed);
        RgbImage::from_fn(width, height, |_, _| {
            Rgb(std::array::from_fn(|_| 112 + noise.next_byte() / 8))
        })
    }

    fn add_offset(image: &RgbImage, offset: u8) -> RgbImage {
        let mut shifted = image.clone();
        shifted
            .pixels_mut()
            .for_each(|p| p.0 = p.0.map(|v| v + offset));
        shifted
    }

    fn constant_image(width: u32, height: u32, value: [u8; 3]) -> RgbImage {
        RgbImage::from_pixel(width, height, Rgb(value))
    }

    /// Independent direct evaluation: the 2D Gaussian `exp(-(dx^2 + dy^2) / (2 sigma^2))`
    /// summed over the 121 (or, near the borders of small images, fewer) pixels of each
    /// window, normalised by the sum of the weights used.
    fn direct_ssim(reference: &RgbImage, test: &RgbImage) -> f64 {
        let (w, h) = reference.dimensions();
        let (w, h) = (w as i64, h as i64);
        let truncated = w < 11 || h < 11;
        let centres = |n: i64| if truncated { 0..n } else { 5..n - 5 };
        let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
        let mut channel_means = 0.0;
        for c in 0..3 {
            let (mut sum, mut count) = (0.0, 0.0);
            for cy in centres(h) {
                for cx in centres(w) {
                    let mut m = [0.0f64; 6];
                    for dy in -5i64..=5 {
                        for dx in -5i64..=5 {
                            let (x, y) = (cx + dx, cy + dy);
                            if x < 0 || y < 0 || x >= w || y >= h {
                                continue;
                            }
                            let g = (-((dx * dx + dy * dy) as f64) / (2.0 * 1.5 * 1.5)).exp();
                            let a = reference.get_pixel(x as u32, y as u32).0[c] as f64;
                            let b = test.get_pixel(x as u32, y as u32).0[c] as f64;
                            m[0] += g;
                            m[1] += g * a;
                            m[2] += g * b;
                            m[3] += g * a * a;
                            m[4] += g * b * b;
                            m[5] += g * a * b;
                        }
                    }
                    let [g, ea, eb, eaa, ebb, eab] = m.map(|v| v / m[0]);
                    assert!((g - 1.0).abs() < 1e-15);
                    let (va, vb, cov) = (eaa - ea * ea, ebb - eb * eb, eab - ea * eb);
                    sum += (2.0 * ea * eb + c1) * (2.0 * cov + c2)
                        / ((ea * ea + eb * eb + c1) * (va + vb + c2));
                    count += 1.0;
                }
            }
            channel_means += sum / count;
        }
        channel_means / 3.0
    }

    fn assert_close(actual: f64, expected: f64, tolerance: f64) {
        assert!(
            (actual - expected).abs() <= tolerance,
            "{actual} vs {expected} (difference {})",
            (actual - expected).abs()
        );
    }

    #[test]
    fn gaussian_window_is_normalised_and_symmetric() {
        let g = gaussian_weights();
        assert_close(g.iter().sum(), 1.0, 1e-15);
        for i in 0..WINDOW {
            assert_eq!(g[i], g[WINDOW - 1 - i]);
        }
        assert!(g[RADIUS] > g[RADIUS - 1]);
    }

    #[test]
    fn identical_images_give_one() {
        let a = noise_image(40, 30, 1);
        assert_close(ssim(&a, &a), 1.0, 1e-12);
        let small = noise_image(4, 7, 2);
        assert_close(ssim(&small, &small), 1.0, 1e-12);
    }

    #[test]
    fn ssim_is_symmetric() {
        let a = noise_image(33, 21, 3);
        let b = noise_image(33, 21, 4);
        assert_close(ssim(&a, &b), ssim(&b, &a), 1e-14);
    }

    #[test]
    fn constant_offset_lowers_ssim_more_the_larger_it_is() {
        let grey = noisy_grey(48, 36, 5);
        let plus_two = ssim(&grey, &add_offset(&grey, 2));
        let plus_ten = ssim(&grey, &add_offset(&grey, 10));
        assert!(plus_ten > 0.0 && plus_ten < 1.0, "{plus_ten}");
        assert!(plus_ten < plus_two, "{plus_ten} vs {plus_two}");
        assert!(plus_two < 1.0, "{plus_two}");
    }

    #[test]
    fn separable_filter_matches_direct_evaluation() {
        let a = noise_image(19, 14, 6);
        let b = noise_image(19, 14, 7);
        assert_close(ssim(&a, &b), direct_ssim(&a, &b), 1e-12);
        // A structurally related pair, so the score is far from zero.
        let grey = noisy_grey(23, 17, 8);
        let mut shifted = add_offset(&grey, 3);
        shifted.put_pixel(11, 8, Rgb([0, 255, 40]));
        assert_close(ssim(&grey, &shifted), direct_ssim(&grey, &shifted), 1e-12);
    }

    #[test]
    fn truncated_window_matches_direct_evaluation() {
        // Smaller than the window in one dimension, then in both.
        for (w, h) in [(25, 6), (7, 9)] {
            let a = noise_image(w, h, 9);
            let b = noise_image(w, h, 10);
            assert_close(ssim(&a, &b), direct_ssim(&a, &b), 1e-12);
        }
    }

    #[test]
    fn constant_images_give_the_luminance_term() {
        // Both variances and the covariance are zero, so SSIM = (2 c1 c2 + C1) /
        // (c1^2 + c2^2 + C1) per channel, with C1 = (0.01 * 255)^2 = 6.5025.
        let luminance = |a: f64, b: f64| (2.0 * a * b + 6.5025) / (a * a + b * b + 6.5025);
        let expected = (luminance(100.0, 150.0) + luminance(0.0, 255.0) + 1.0) / 3.0;
        for (w, h) in [(16, 12), (4, 4)] {
            let a = constant_image(w, h, [100, 0, 77]);
            let b = constant_image(w, h, [150, 255, 77]);
            assert_close(ssim(&a, &b), expected, 1e-9);
        }
        // 100 vs 150: (30000 + 6.5025) / (32500 + 6.5025).
        assert_close(luminance(100.0, 150.0), 0.923_092_310_530_793, 1e-12);
    }

    #[test]
    fn tiny_image_gives_a_finite_value() {
        let a = noise_image(4, 4, 11);
        let b = noise_image(4, 4, 12);
        let value = ssim(&a, &b);
        assert!(value.is_finite() && value <= 1.0, "{value}");
        assert!(
            ssim(
                &constant_image(1, 1, [9, 9, 9]),
                &constant_image(1, 1, [9, 9, 9])
            ) == 1.0
        );
    }

    #[test]
    fn different_sizes_or_empty_images_give_nan() {
        assert!(ssim(&noise_image(12, 12, 13), &noise_image(12, 13, 13)).is_nan());
        assert!(ssim(&RgbImage::new(0, 0), &RgbImage::new(0, 0)).is_nan());
        assert!(ssim(&RgbImage::new(0, 5), &RgbImage::new(0, 5)).is_nan());
    }

    /// Run with `cargo test --release --lib ssim_full_hd_time -- --ignored --nocapture`.
    #[test]
    #[ignore = "timing only; prints the time of one 1920x1080 SSIM"]
    fn ssim_full_hd_time() {
        let a = noise_image(1920, 1080, 14);
        let b = noise_image(1920, 1080, 15);
        let start = std::time::Instant::now();
        let value = ssim(&a, &b);
        println!("SSIM 1920x1080: {value:.6} in {:?}", start.elapsed());
    }
}
