//! The repository's own files, listed for tests that read them as text (the docs' runnable
//! examples, the architecture rules over `src/`).

use std::path::{Path, PathBuf};

/// Every file under `dir` (recursively) whose extension is `extension`, sorted.
///
/// # Panics
/// If a folder under `dir` cannot be listed (naming it).
pub fn files_with_extension(dir: &Path, extension: &str) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(dir) = pending.pop() {
        let entries = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        for entry in entries {
            let path = entry
                .unwrap_or_else(|e| panic!("cannot read an entry of {}: {e}", dir.display()))
                .path();
            if path.is_dir() {
                pending.push(path);
            } else if path.extension().is_some_and(|e| e == extension) {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}
