//! `mipray`: render animated scenes with ray-length MIP-map level selection.
//! The command line lives in `mipray::cli`; this file only reports errors.

use std::process::ExitCode;

use clap::Parser;

/// Large allocations (trees, triangle arrays, textures) in 2 MiB pages where the system
/// has them: fewer TLB misses in the frame's walks and lookups (see `mipray::large_pages`).
#[global_allocator]
static ALLOCATOR: mipray::large_pages::LargePageAllocator = mipray::large_pages::LargePageAllocator;

fn main() -> ExitCode {
    // Before anything large is allocated, so the choice holds for the whole run.
    match std::env::var_os("MIPRAY_LARGE_PAGES")
        .as_deref()
        .map(|v| v.to_str())
    {
        None | Some(Some("on")) => mipray::large_pages::turn_on(),
        Some(Some("off")) => mipray::large_pages::turn_off(),
        Some(value) => {
            let value = value.unwrap_or("(not UTF-8)");
            eprintln!("error: MIPRAY_LARGE_PAGES={value}: expected `on` or `off`");
            return ExitCode::from(2);
        }
    };
    // Rust ignores SIGPIPE, which turns a closed pipe (`mipray diff ... | head`) into a
    // panic in `println!`; the default action ends the process quietly, like other tools.
    #[cfg(unix)]
    // SAFETY: called once at start-up, before any thread exists; SIG_DFL is a valid action.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Exit codes: 0 success; 1 failure (a regression check found frames outside the
    // threshold, or a render/load error); 2 a usage error (the parser's own, or a flag value
    // out of range: `UsageError`), or bad input to `diff` / `render --check` (a missing
    // frame, different sizes, unreadable files).
    match mipray::cli::run(mipray::cli::Cli::parse()) {
        Ok(code) => code,
        Err(error) => {
            eprintln!("error: {}", error_chain(&error));
            let usage = error.downcast_ref::<mipray::cli::UsageError>().is_some();
            let bad_input = error
                .downcast_ref::<mipray::diff::DiffInputError>()
                .is_some();
            if usage || bad_input {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// The error and its causes joined by `: ` (as `{:#}` prints them), leaving out a cause
/// whose text its parent's message already holds: many errors name their source in their
/// own message (`{path}: {source}`), and `{:#}` then printed it twice.
fn error_chain(error: &anyhow::Error) -> String {
    let mut text = error.to_string();
    for cause in error.chain().skip(1) {
        let cause = cause.to_string();
        if !text.contains(&cause) {
            text.push_str(": ");
            text.push_str(&cause);
        }
    }
    text
}
