//! The sRGB encoding of output pixels: linear radiance in [0, 1] to an 8-bit code value.
//!
//! One function shared by everything that turns linear values into what a person sees: the
//! film's PNG frames (`render::film`), the image metrics reading float frames
//! (`metrics::read_srgb8`) and the exported material colours (`export::obj`), so a frame
//! compared or exported is encoded exactly as it was written. (Texture decoding goes the
//! other way, sRGB to linear, in `texture::decode`.)
//!
//! Invariant: every input maps to a code value; non-finite values (NaN, ±inf) encode as 0
//! and values outside [0, 1] are clamped, so no pixel is ever lost or undefined.

/// Linear [0, 1] to an 8-bit sRGB code value.
pub fn encode_srgb8(linear: f32) -> u8 {
    let c = if linear.is_finite() {
        linear.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let encoded = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (encoded * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_encoding_endpoints_and_midpoint() {
        assert_eq!(encode_srgb8(0.0), 0);
        assert_eq!(encode_srgb8(1.0), 255);
        assert_eq!(encode_srgb8(0.214_041_14), 128);
        assert_eq!(encode_srgb8(f32::NAN), 0);
        assert_eq!(encode_srgb8(7.0), 255);
    }
}
