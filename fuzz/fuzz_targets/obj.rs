//! The OBJ loader on arbitrary text (non-UTF-8 input is the reader's error, checked in the
//! stable suite). MTL files resolve beside a path that does not exist.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("/nonexistent-mipray-fuzz/scene.obj");
    let _ = mipray::scene::obj::load_from_text(path, text);
});
