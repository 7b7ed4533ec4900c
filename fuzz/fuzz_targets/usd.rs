//! The USD loader on arbitrary bytes: the first byte picks the layer's kind (0 text
//! `.usda`, 1 crate `.usdc`, otherwise package `.usdz`), the rest is the file, written to a
//! temporary folder and loaded as `mipray` loads any stage (byte checks, `openusd`'s text,
//! crate and package readers, composition, the schema mapping). Any input must load or
//! give an error: never a panic, a hang or a huge allocation.
//!
//! Under `--cfg fuzzing` the loader does not catch `openusd`'s panics (see
//! `scene/usd/guard.rs`). With `MIPRAY_FUZZ_PANICS=1` they reach libFuzzer as crashes
//! (to see what the byte checks let through); by default this target catches them as the
//! loader does in every other build, so the run looks for what no guard can catch: aborts
//! (huge allocations past libFuzzer's malloc limit, stack overflows) and hangs.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

fn folder() -> &'static std::path::Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary folder"))
        .path()
}

/// Whether panics go to libFuzzer (`MIPRAY_FUZZ_PANICS=1`) or are caught here.
fn catch_panics() -> bool {
    static CATCH: OnceLock<bool> = OnceLock::new();
    *CATCH.get_or_init(|| {
        let catch = std::env::var_os("MIPRAY_FUZZ_PANICS").is_none();
        if catch {
            // libfuzzer-sys's hook aborts on any panic; the loader's edge catches them.
            std::panic::set_hook(Box::new(|_| {}));
        }
        catch
    })
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
    if catch_panics() {
        let _ = std::panic::catch_unwind(|| mipray::scene::usd::load(&path));
    } else {
        let _ = mipray::scene::usd::load(&path);
    }
});
