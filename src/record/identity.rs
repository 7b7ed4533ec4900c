//! What identifies the run a record belongs to: the scene (its file name and a digest of
//! its bytes, and a digest of the other files its load read: buffers, textures, layers,
//! includes) and every setting that changes the pixels, by its flag name. Two records
//! whose identities differ come from different renders, and their frames must not be
//! mixed in one sequence (a resume, shards into one folder, a merge).
//!
//! Invariants: an identity holds nothing a machine decides (no absolute path, process id,
//! thread count or time), so shards on different machines that render the same scene the
//! same way agree; it is stored as text, stable across builds (the digest is FNV-1a, fixed
//! by its definition, never `std`'s `DefaultHasher`). A part absent from a record (written
//! before it existed) is unknown and never counts as a difference.

use std::collections::BTreeMap;
use std::io::Read;

use super::FrameRecord;

/// One setting on which two records disagree, as each has it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SettingDifference {
    /// `scene`, or a setting's flag name (`size`, `lod`, ...).
    pub name: String,
    /// The value in the first record (the one already on disk).
    pub kept: String,
    /// The value in the second record.
    pub new: String,
}

/// The settings on which `kept` and `new` disagree, `scene` first, then the settings by
/// name; a part either record lacks is unknown and left out.
pub fn run_differences(kept: &FrameRecord, new: &FrameRecord) -> Vec<SettingDifference> {
    let differ = |name: &str, kept: &String, new: &String| {
        (!kept.is_empty() && !new.is_empty() && kept != new).then(|| SettingDifference {
            name: name.into(),
            kept: kept.clone(),
            new: new.clone(),
        })
    };
    let scene = differ("scene", &kept.scene, &new.scene);
    let files = differ("scene files", &kept.scene_files, &new.scene_files);
    let settings = kept.settings.iter().filter_map(|(name, value)| {
        let other = new.settings.get(name)?;
        (other != value).then(|| SettingDifference {
            name: name.clone(),
            kept: value.clone(),
            new: other.clone(),
        })
    });
    scene.into_iter().chain(files).chain(settings).collect()
}

/// The differences as one phrase, each side named: with `kept` = "there" and `new` = "now",
/// `size 320x180 there, 48x27 now; lod paper there, none now`.
pub fn describe_differences(differences: &[SettingDifference], kept: &str, new: &str) -> String {
    let parts: Vec<String> = differences
        .iter()
        .map(|d| format!("{} {} {kept}, {} {new}", d.name, d.kept, d.new))
        .collect();
    parts.join("; ")
}

/// A record's `settings`: flag name to value.
pub type Settings = BTreeMap<String, String>;

/// The identity a run stamps on each record it writes (empty parts: unknown).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RunIdentity {
    /// See [`scene_identity`].
    pub scene: String,
    /// See [`scene_files_identity`].
    pub scene_files: String,
    pub settings: Settings,
}

impl RunIdentity {
    /// Writes this identity into `record`.
    pub fn stamp(&self, record: &mut FrameRecord) {
        record.scene.clone_from(&self.scene);
        record.scene_files.clone_from(&self.scene_files);
        record.settings.clone_from(&self.settings);
    }

    /// The settings on which `kept` (a record on disk) and this run disagree.
    pub fn differences_from(&self, kept: &FrameRecord) -> Vec<SettingDifference> {
        let mut ours = FrameRecord::default();
        self.stamp(&mut ours);
        run_differences(kept, &ours)
    }
}

impl FrameRecord {
    /// Whether the record says which run it belongs to (records written before the
    /// identity existed do not).
    pub fn has_run_identity(&self) -> bool {
        !(self.scene.is_empty() && self.settings.is_empty())
    }
}

/// The `scene` of a record: the file's name and the FNV-1a 64-bit digest of its bytes in
/// hex (`default.gltf#9f3c0e5d1a2b4c6d`). Files the scene references (buffers, textures)
/// are not part of it: see [`scene_files_identity`].
///
/// # Errors
/// The scene cannot be read.
pub fn scene_identity(file_name: &str, mut bytes: impl Read) -> std::io::Result<String> {
    let mut digest = Fnv1a64::default();
    let mut buffer = vec![0u8; 1 << 16];
    loop {
        let n = bytes.read(&mut buffer)?;
        if n == 0 {
            break;
        }
        digest.update(&buffer[..n]);
    }
    Ok(format!("{file_name}#{:016x}", digest.0))
}

/// The `scene_files` of a record: how many other files the scene load read (besides the
/// scene file) and the FNV-1a 64-bit digest of their digests, in the order the load read
/// them (`3 files#0f1e2d3c4b5a6978`), or `none`. Their names are left out (an identity
/// holds no path; the scene file, part of the identity, names them), so a changed byte in
/// any of them changes it, a moved file does not.
pub fn scene_files_identity(digests: &[u64]) -> String {
    if digests.is_empty() {
        return "none".into();
    }
    let mut digest = Fnv1a64::default();
    for d in digests {
        digest.update(&d.to_le_bytes());
    }
    let count = digests.len();
    let files = if count == 1 { "file" } else { "files" };
    format!("{count} {files}#{:016x}", digest.0)
}

/// FNV-1a, 64 bits: a digest defined by two constants, the same on every build.
struct Fnv1a64(u64);

impl Default for Fnv1a64 {
    fn default() -> Self {
        Fnv1a64(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a64 {
    fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(scene: &str, settings: &[(&str, &str)]) -> FrameRecord {
        FrameRecord {
            scene: scene.into(),
            settings: settings
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
            ..FrameRecord::default()
        }
    }

    #[test]
    fn the_digest_is_fnv1a_and_fixed() {
        // The published FNV-1a 64 test vectors: "" and "a".
        assert_eq!(
            scene_identity("s.gltf", &b""[..]).unwrap(),
            "s.gltf#cbf29ce484222325"
        );
        assert_eq!(
            scene_identity("s.gltf", &b"a"[..]).unwrap(),
            "s.gltf#af63dc4c8601ec8c"
        );
    }

    #[test]
    fn differences_name_each_setting_both_records_have() {
        let kept = record(
            "a#1",
            &[("size", "320x180"), ("lod", "paper"), ("spp", "1")],
        );
        let new = record("b#2", &[("size", "48x27"), ("lod", "paper"), ("fps", "24")]);
        let found = run_differences(&kept, &new);
        assert_eq!(
            describe_differences(&found, "there", "now"),
            "scene a#1 there, b#2 now; size 320x180 there, 48x27 now"
        );
        // Absent parts are unknown: an older record without them agrees with anything.
        assert!(run_differences(&record("", &[]), &new).is_empty());
        assert!(run_differences(&kept, &kept).is_empty());
    }
}
