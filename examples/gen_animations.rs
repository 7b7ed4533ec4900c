//! Regenerates the project's authored animations (`default`, `kitchen`, `robots` and
//! `museum`, each a `.gltf` with its `.bin` and PNGs) from `mipray_authoring`.
//!
//! Usage:
//! - `cargo run --release --example gen_animations [-- OUT_DIR]` (default `animations/`)
//!   writes all four; `tests/animations_generated.rs` checks the committed files match
//!   this output byte for byte.
//! - `cargo run --release --example gen_animations -- --museum-detail N [OUT_DIR]` writes
//!   only the museum with its sculpture at detail `N` (`1280 * 4^N` deforming triangles,
//!   N <= 4) as `museum_detailN.gltf`, for benchmarks.
//!
//! Prints each file written with its size.

use std::path::PathBuf;

use anyhow::Context;
use mipray_authoring::{MUSEUM_MAX_DETAIL, museum_sculpture_triangles, write_all, write_museum};

const USAGE: &str = "usage: gen_animations [--museum-detail N] [OUT_DIR]";

fn main() -> anyhow::Result<()> {
    let mut out_dir: Option<PathBuf> = None;
    let mut museum_detail: Option<u32> = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--museum-detail" {
            let value = args.next().context(USAGE)?;
            let detail: u32 = value
                .parse()
                .with_context(|| format!("--museum-detail {value:?} is not a number"))?;
            anyhow::ensure!(
                detail <= MUSEUM_MAX_DETAIL,
                "--museum-detail must be at most {MUSEUM_MAX_DETAIL}"
            );
            museum_detail = Some(detail);
        } else if arg.starts_with("--") || out_dir.is_some() {
            anyhow::bail!("{USAGE}");
        } else {
            out_dir = Some(arg.into());
        }
    }
    let out_dir = out_dir.unwrap_or_else(|| "animations".into());
    let paths = match museum_detail {
        Some(detail) => {
            println!(
                "museum at detail {detail}: {} sculpture triangles",
                museum_sculpture_triangles(detail)
            );
            write_museum(&out_dir, &format!("museum_detail{detail}"), detail)
        }
        None => write_all(&out_dir),
    }
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
