//! Test data from `../shared` (the BART scenes, the Khronos sample models), which a fresh
//! clone does not have. A test that needs it asks here: without the data it prints why it
//! skipped, unless the environment variable `CI` is set, where a missing data set is a
//! failure (a check that cannot fail when its data is absent must not pass in CI).
//!
//! `MIPRAY_SHARED_DIR` points elsewhere (a git worktree's `../shared` is not the main
//! checkout's).

use std::path::{Path, PathBuf};

/// `CARGO_MANIFEST_DIR/../shared/<relative>` (or `$MIPRAY_SHARED_DIR/<relative>`) when it
/// exists.
///
/// # Panics
/// When it does not exist and `CI` is set.
pub fn shared_path(relative: &str) -> Option<PathBuf> {
    let root = std::env::var_os("MIPRAY_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared"));
    let path = root.join(relative);
    if path.exists() {
        return Some(path);
    }
    skip_or_fail(&format!("{} not present", path.display()));
    None
}

/// Prints `skipping: <reason>`, or panics with the reason when `CI` is set.
pub fn skip_or_fail(reason: &str) {
    if std::env::var_os("CI").is_some() {
        panic!("{reason}, and CI is set: this test needs its data in CI");
    }
    println!("skipping: {reason}");
}
