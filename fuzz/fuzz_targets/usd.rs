//! The USD loader on arbitrary bytes: the first byte picks the layer's kind (0 text
//! `.usda`, 1 crate `.usdc`, otherwise package `.usdz`), the rest is the file, written to a
//! temporary folder and loaded as `mipray` loads any stage (byte checks, `openusd`'s text,
//! crate and package readers, composition, the schema mapping). Any input must load or
//! give an error: never a panic, a hang or a huge allocation.
//!
//! Under `--cfg fuzzing` the loader does not catch `openusd`'s panics (see
//! `scene/usd/guard.rs`), so a panic the byte checks let through is reported here.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

fn folder() -> &'static std::path::Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary folder"))
        .path()
}

fuzz_target!(|data: &[u8]| {
    let Some((&kind, bytes)) = data.split_first() else {
        return;
    };
    let name = match kind {
        0 => "layer.usda",
        1 => "layer.usdc",
        _ => "layer.usdz",
    };
    let path = folder().join(name);
    if std::fs::write(&path, bytes).is_err() {
        return;
    }
    let _ = mipray::scene::usd::load(&path);
});
