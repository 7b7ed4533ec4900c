//! Regenerates the project's authored animations (today `default.gltf` with its `.bin`
//! and PNGs) from `mipray::authoring`.
//!
//! Usage: `cargo run --release --example gen_animations [-- OUT_DIR]` (default
//! `animations/`). Prints each file written with its size. The output is deterministic,
//! and `tests/animations_generated.rs` checks the committed files match it byte for byte.

use std::path::PathBuf;

use anyhow::Context;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args_os().skip(1);
    let out_dir = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| "animations".into());
    if args.next().is_some() {
        anyhow::bail!("usage: gen_animations [OUT_DIR]");
    }
    let paths = mipray::authoring::write_all(&out_dir)
        .with_context(|| format!("writing animations into {}", out_dir.display()))?;
    let mut total = 0;
    for path in &paths {
        let size = std::fs::metadata(path)
            .with_context(|| format!("reading the size of {}", path.display()))?
            .len();
        total += size;
        println!("wrote {} ({size} bytes)", path.display());
    }
    println!("{} files, {total} bytes in total", paths.len());
    Ok(())
}
