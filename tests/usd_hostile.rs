//! The crate (`.usdc`) files of the hostile corpus and what they must give: a valid
//! one-triangle crate file written with openusd's own writer, then damaged one way each
//! (counts past the bytes, a table of contents outside the file, a truncated file, an
//! unsupported version). `tests/hostile.rs` renders every corpus file under a 1 GiB
//! address-space limit; here the damaged files are rewritten (ignored test, run by hand
//! after changing them) and checked to differ from the valid file only where intended.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use openusd::usdc::{CrateFile, CrateWriter};

const TRIANGLE: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Tri"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}
"#;

fn hostile_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/hostile")
}

/// The valid crate file.
fn valid_crate() -> Vec<u8> {
    let data = openusd::usda::parse(TRIANGLE).unwrap();
    let mut out = Cursor::new(Vec::new());
    CrateWriter::write(&data, &mut out).unwrap();
    out.into_inner()
}

fn u64_at(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap())
}

fn put_u64(bytes: &mut [u8], at: usize, value: u64) {
    bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
}

/// Start of the section named `name` (from the table of contents).
fn section(bytes: &[u8], name: &str) -> usize {
    let toc = u64_at(bytes, 16) as usize;
    let count = u64_at(bytes, toc) as usize;
    (0..count)
        .map(|s| toc + 8 + s * 32)
        .find(|&at| bytes[at..at + 16].starts_with(name.as_bytes()))
        .map(|at| u64_at(bytes, at + 16) as usize)
        .unwrap_or_else(|| panic!("no section {name}"))
}

/// Each damaged file: its name and bytes.
fn damaged() -> Vec<(&'static str, Vec<u8>)> {
    let valid = valid_crate();
    let mut out = Vec::new();
    let mut tokens = valid.clone();
    let at = section(&tokens, "TOKENS");
    put_u64(&mut tokens, at, 1 << 40);
    put_u64(&mut tokens, at + 8, 1 << 40);
    out.push(("usd_crate_token_count_huge.usdc", tokens));
    let mut fields = valid.clone();
    let at = section(&fields, "FIELDS");
    put_u64(&mut fields, at, 1 << 36);
    out.push(("usd_crate_field_count_huge.usdc", fields));
    let mut paths = valid.clone();
    let at = section(&paths, "PATHS");
    put_u64(&mut paths, at, 1 << 33);
    out.push(("usd_crate_path_count_huge.usdc", paths));
    // The points array's element count, at its value's payload.
    let file = CrateFile::open(Cursor::new(valid.clone())).unwrap();
    let points = file
        .fields
        .iter()
        .map(|f| f.value_rep)
        .find(|r| r.is_array() && !r.is_inlined() && r.ty().unwrap() as u32 == 24)
        .expect("a point3f[] value");
    let mut array = valid.clone();
    put_u64(&mut array, points.payload() as usize, 1 << 36);
    out.push(("usd_crate_array_count_huge.usdc", array));
    let mut toc = valid.clone();
    put_u64(&mut toc, 16, valid.len() as u64 + 1000);
    out.push(("usd_crate_toc_outside.usdc", toc));
    out.push((
        "usd_crate_truncated.usdc",
        valid[..valid.len() / 2].to_vec(),
    ));
    let mut old = valid.clone();
    old[8..11].copy_from_slice(&[0, 3, 0]);
    out.push(("usd_crate_version_old.usdc", old));
    out
}

/// Rewrites the crate files of the corpus.
#[test]
#[ignore = "rewrites tests/fixtures/hostile/usd_crate_*.usdc; run by hand after changing them"]
fn write_crate_fixtures() {
    for (name, bytes) in damaged() {
        std::fs::write(hostile_dir().join(name), bytes).unwrap();
    }
}

/// The committed files are what this file writes (so the corpus is reproducible), and the
/// valid crate file they were damaged from loads.
#[test]
fn the_committed_crate_fixtures_are_the_damaged_valid_file() {
    let tmp = tempfile::tempdir().unwrap();
    let valid = tmp.path().join("valid.usdc");
    std::fs::write(&valid, valid_crate()).unwrap();
    let scene = mipray::scene::load(&valid).unwrap();
    assert_eq!(scene.instanced_triangle_count(), 1);
    for (name, bytes) in damaged() {
        let committed = std::fs::read(hostile_dir().join(name)).unwrap_or_default();
        assert_eq!(
            committed, bytes,
            "{name} differs from what write_crate_fixtures writes"
        );
        let path = tmp.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let error = mipray::scene::load(&path).unwrap_err().to_string();
        assert!(error.contains(name), "{name}: {error}");
    }
}
