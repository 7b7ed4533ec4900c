//! The glTF/GLB entry point on arbitrary bytes. External buffers and images resolve beside
//! a path that does not exist, so only embedded data (data URIs, the GLB BIN chunk) loads.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("/nonexistent-mipray-fuzz/scene.glb");
    let _ = mipray::scene::gltf::load_from_bytes(path, data);
});
