//! Files: include and texture path resolution, a byte cache (or files held in memory, for
//! fuzzing: [`Files::in_memory`]), include-cycle detection.
//!
//! Path rules (SOURCE.md, "Path resolution"): names in `i <detail> <file>` are bare file
//! names relative to the scene's `aff/` directory; they are looked up next to the including
//! file, then next to the main file. Texture names are looked up next to the including
//! file, then in `../TextureFiles/` from it, then the same two places from the main file.
//! A file included many times (Robots includes each body part ten times) is read once.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where a name may be, in lookup order, without duplicates.
fn unique(paths: Vec<PathBuf>) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = Vec::with_capacity(paths.len());
    for p in paths {
        if !out.contains(&p) {
            out.push(p);
        }
    }
    out
}

/// Candidate paths of an included file.
pub fn include_candidates(current_dir: &Path, main_dir: &Path, name: &str) -> Vec<PathBuf> {
    unique(vec![current_dir.join(name), main_dir.join(name)])
}

/// Candidate paths of a texture file.
pub fn texture_candidates(current_dir: &Path, main_dir: &Path, name: &str) -> Vec<PathBuf> {
    unique(vec![
        current_dir.join(name),
        current_dir.join("../TextureFiles").join(name),
        main_dir.join(name),
        main_dir.join("../TextureFiles").join(name),
    ])
}

/// Read files and the chain of files being parsed.
#[derive(Default)]
pub struct Files {
    cache: HashMap<PathBuf, Arc<[u8]>>,
    /// In-memory mode (fuzzing, tests): the only files there are; the disk is never read.
    in_memory: bool,
    /// Files being parsed, outermost first: (canonical path, display name).
    chain: Vec<(PathBuf, String)>,
    /// Files parsed so far, includes counted each time they are expanded.
    pub expanded: usize,
}

impl Files {
    /// Files held in memory, keyed by path; nothing else exists.
    pub fn in_memory(files: impl IntoIterator<Item = (PathBuf, Vec<u8>)>) -> Files {
        Files {
            cache: files.into_iter().map(|(p, b)| (p, b.into())).collect(),
            in_memory: true,
            ..Default::default()
        }
    }

    /// Whether `path` names a readable file.
    pub fn exists(&self, path: &Path) -> bool {
        if self.in_memory {
            self.cache.contains_key(path)
        } else {
            path.is_file()
        }
    }

    /// Reads `path` (cached).
    pub fn read(&mut self, path: &Path) -> Result<Arc<[u8]>, String> {
        let key = self.canonical(path);
        if let Some(bytes) = self.cache.get(&key) {
            return Ok(bytes.clone());
        }
        if self.in_memory {
            return Err(format!("cannot read '{}': not found", path.display()));
        }
        let bytes: Arc<[u8]> = crate::scene::sources::read(path)
            .map_err(|e| format!("cannot read '{}': {e}", path.display()))?
            .into();
        self.cache.insert(key, bytes.clone());
        Ok(bytes)
    }

    /// Enters `path`: an error naming the chain when it is already being parsed.
    pub fn enter(&mut self, path: &Path, name: &str) -> Result<(), String> {
        let key = self.canonical(path);
        if self.chain.iter().any(|(p, _)| *p == key) {
            let mut names: Vec<&str> = self.chain.iter().map(|(_, n)| n.as_str()).collect();
            names.push(name);
            return Err(format!("include cycle: {}", names.join(" -> ")));
        }
        self.chain.push((key, name.to_string()));
        self.expanded += 1;
        Ok(())
    }

    pub fn leave(&mut self) {
        self.chain.pop();
    }

    /// The key of `path` in the cache and the include chain.
    fn canonical(&self, path: &Path) -> PathBuf {
        if self.in_memory {
            return path.to_path_buf();
        }
        std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
    }
}
