//! The files a scene load reads, each with a digest of its bytes: what a render's identity
//! covers (`record::RunIdentity`), so a resume or a shard notices a changed buffer,
//! texture, sublayer or include, not only a changed top file.
//!
//! Loaders read their files through [`read`] and [`read_to_string`] (or tell [`note`] the
//! bytes they got another way, as the USD resolver does); outside [`recording`] these are
//! plain reads. Each file's bytes are hashed once, as they are read, from the buffer the
//! loader uses anyway: no file is read a second time. Recording is per thread, which the
//! loaders (single-threaded) never leave.

use std::cell::RefCell;
use std::io;
use std::path::{Path, PathBuf};

/// One file a load read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceFile {
    /// The path as resolved (canonical when it names a file on disk).
    pub path: PathBuf,
    /// FNV-1a 64 of its bytes.
    pub digest: u64,
    pub len: u64,
}

thread_local! {
    static READS: RefCell<Option<Vec<SourceFile>>> = const { RefCell::new(None) };
}

/// Runs `load` and returns, with its result, the files it read through this module, each
/// once (the first read), in the order first read.
pub fn recording<T>(load: impl FnOnce() -> T) -> (T, Vec<SourceFile>) {
    let outer = READS.with(|r| r.borrow_mut().replace(Vec::new()));
    let result = load();
    let mut files = READS
        .with(|r| std::mem::replace(&mut *r.borrow_mut(), outer))
        .unwrap_or_default();
    let mut seen = std::collections::HashSet::new();
    files.retain(|f| seen.insert(f.path.clone()));
    (result, files)
}

/// `std::fs::read`, noted.
///
/// # Errors
/// As `std::fs::read`.
pub fn read(path: &Path) -> io::Result<Vec<u8>> {
    let bytes = std::fs::read(path)?;
    note(path, &bytes);
    Ok(bytes)
}

/// `std::fs::read_to_string`, noted.
///
/// # Errors
/// As `std::fs::read_to_string`.
pub fn read_to_string(path: &Path) -> io::Result<String> {
    let text = std::fs::read_to_string(path)?;
    note(path, text.as_bytes());
    Ok(text)
}

/// Notes that the load read `bytes` from `path` (nothing outside [`recording`]).
pub fn note(path: &Path, bytes: &[u8]) {
    READS.with(|r| {
        if let Some(files) = r.borrow_mut().as_mut() {
            files.push(SourceFile {
                path: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
                digest: fnv1a64(bytes),
                len: bytes.len() as u64,
            });
        }
    });
}

/// FNV-1a, 64 bits: the digest of `record::scene_identity` (fixed by two constants; the
/// loaders may not name the record module, hence this copy).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        hash = (hash ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_are_noted_only_while_recording_and_once_each() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.bin");
        std::fs::write(&a, b"a").unwrap();
        read(&a).unwrap();
        let ((), files) = recording(|| {
            read(&a).unwrap();
            read_to_string(&a).unwrap();
            note(Path::new("pkg.usdz[t.png]"), b"");
        });
        assert_eq!(files.len(), 2);
        assert_eq!(files[0].path, std::fs::canonicalize(&a).unwrap());
        // The published FNV-1a 64 test vectors: "a" and "".
        assert_eq!(files[0].digest, 0xaf63_dc4c_8601_ec8c);
        assert_eq!(files[1].digest, 0xcbf2_9ce4_8422_2325);
        let ((), none) = recording(|| ());
        assert!(none.is_empty());
    }
}
