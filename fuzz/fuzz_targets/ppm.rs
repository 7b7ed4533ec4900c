//! The texture decoder (PPM/PNG/JPEG by content) on arbitrary bytes: an image or an
//! error, never a panic or an allocation out of proportion to the input.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = mipray::texture::decode_texels(data, mipray::texture::ColorEncoding::Srgb);
});
