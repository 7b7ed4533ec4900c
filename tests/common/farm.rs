//! What the farm tests (Slurm, Kubernetes, Open Job Description) share: the example job
//! files, a single-machine reference render, and the checks of a farm's output folder
//! against it.
//!
//! A farm's output must equal one machine's: every frame byte for byte, and every record
//! field that is a function of the frame alone. Excluded from the record comparison: the
//! timings (`*_ms`, wall-clock), and the fields that depend on what the same process
//! rendered before, since each shard (and each resumed task) starts from a fresh BVH:
//! `rebuild` and `sah_ratio` (the tree's history) everywhere, and `moved_triangles`,
//! `deformed_triangles`, `lod_recomputed`, `lod_shifted` (what changed since the previous
//! frame) on the first frame a process rendered. Where a test knows those first frames, it
//! checks them (`rebuild` is set there) and compares the change counts on all the others.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::process::Command;

use mipray::record::{FrameRecord, Record};

/// The scene every farm test renders: the project's default animation, by path so that a
/// job started in any folder finds it.
pub const SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/animations/default.gltf");

/// The release binary under test.
pub const MIPRAY: &str = env!("CARGO_BIN_EXE_mipray");

/// `examples/cluster/<relative>`.
pub fn example(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/cluster")
        .join(relative)
}

/// `A..B` as the command line writes it.
pub fn frames_arg(frames: &Range<u32>) -> String {
    format!("{}..{}", frames.start, frames.end)
}

/// Renders `frames` of [`SCENE`] at `size` on this machine alone, into `out`.
pub fn render_reference(frames: &Range<u32>, size: &str, out: &Path) {
    let output = Command::new(MIPRAY)
        .args([
            "render",
            SCENE,
            "--frames",
            &frames_arg(frames),
            "--size",
            size,
        ])
        .arg("--out")
        .arg(out)
        .output()
        .expect("run mipray");
    assert!(
        output.status.success(),
        "reference render failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The frame files (`frame_NNNN.*`) of a folder, by name.
pub fn frame_files(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("frame_"))
        .collect()
}

/// Hidden temporary files (`.NAME.PID.tmp`) in a folder: what an interrupted write leaves.
pub fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.ends_with(".tmp"))
        .collect()
}

/// `frame_NNNN.png`.
pub fn frame_name(frame: u32) -> String {
    format!("frame_{frame:04}.png")
}

/// Every frame the farm has is byte-identical to the reference's frame of that number.
/// Returns the frame numbers present.
pub fn assert_frames_match_reference(reference: &Path, farm: &Path) -> BTreeSet<u32> {
    let mut present = BTreeSet::new();
    for name in frame_files(farm) {
        let number: u32 = name["frame_".len()..name.len() - ".png".len()]
            .parse()
            .unwrap_or_else(|_| panic!("{}: unexpected frame file {name}", farm.display()));
        let ours = std::fs::read(farm.join(&name)).unwrap();
        let theirs = std::fs::read(reference.join(&name))
            .unwrap_or_else(|e| panic!("reference {name}: {e}"));
        assert!(
            ours == theirs,
            "{}: {name} differs from the single-machine frame ({} against {} bytes)",
            farm.display(),
            ours.len(),
            theirs.len()
        );
        present.insert(number);
    }
    present
}

/// The farm folder holds exactly the frames of `frames`, each byte-identical to the
/// reference's, and no temporary file.
pub fn assert_complete_sequence(reference: &Path, farm: &Path, frames: &Range<u32>) {
    let present = assert_frames_match_reference(reference, farm);
    let expected: BTreeSet<u32> = frames.clone().collect();
    assert_eq!(present, expected, "{}: frames on disk", farm.display());
    assert_eq!(
        temporaries(farm),
        Vec::<String>::new(),
        "{}: temporary files left",
        farm.display()
    );
}

/// How many lines of the folder's stats files (`stats*.jsonl`) name each frame.
pub fn record_lines_per_frame(dir: &Path) -> BTreeMap<u32, usize> {
    let mut lines = BTreeMap::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if !mipray::record::is_stats_file_name(&name) {
            continue;
        }
        for line in std::fs::read_to_string(&path).unwrap().lines() {
            let record = Record::parse(line)
                .unwrap_or_else(|e| panic!("{}: bad line {line:?}: {e:?}", path.display()));
            *lines.entry(record.frame()).or_insert(0) += 1;
        }
    }
    lines
}

/// The fields of a record that depend on its frame alone (see the module docs).
fn frame_fields(r: &FrameRecord) -> impl PartialEq + std::fmt::Debug {
    (
        (r.frame, r.time_s.to_bits(), r.width, r.height, r.spp),
        (r.lod_method.clone(), r.lod_bias.to_bits()),
        (r.triangles, r.lights, r.rays, r.nonfinite_samples),
        r.mip_histogram.clone(),
    )
}

/// What changed since the previous frame rendered by the same process.
fn change_counts(r: &FrameRecord) -> impl PartialEq + std::fmt::Debug {
    (
        r.update.moved_triangles,
        r.update.deformed_triangles,
        r.update.lod_recomputed,
        r.update.lod_shifted,
    )
}

/// The farm's records, merged as `mipray report` merges them, have one line per frame of
/// `frames` (none twice, none missing, across all stats files) and equal the reference's
/// frame by frame in every field that depends on the frame alone. `first_frames`, when
/// known, are the frames a process started on: they must show a BVH build, and the change
/// counts of every other frame must equal the reference's.
pub fn assert_records_match_reference(
    reference: &Path,
    farm: &Path,
    frames: &Range<u32>,
    first_frames: Option<&BTreeSet<u32>>,
) {
    let lines = record_lines_per_frame(farm);
    let expected: BTreeMap<u32, usize> = frames.clone().map(|f| (f, 1)).collect();
    assert_eq!(lines, expected, "{}: stats lines per frame", farm.display());
    let ours =
        mipray::record::load_sequence(&[farm.to_path_buf()]).expect("merge the farm's records");
    let theirs =
        mipray::record::load_sequence(&[reference.to_path_buf()]).expect("reference records");
    assert_eq!(ours.duplicates_dropped, 0);
    assert_eq!(ours.records.len(), frames.len());
    assert_eq!(theirs.records.len(), frames.len());
    for (a, b) in ours.records.iter().zip(&theirs.records) {
        let (a, b) = (&a.values, &b.values);
        assert_eq!(frame_fields(a), frame_fields(b), "frame {}", a.frame);
        if let Some(firsts) = first_frames {
            if firsts.contains(&a.frame) {
                assert!(
                    a.update.rebuild,
                    "frame {}: a process's first frame builds its BVH",
                    a.frame
                );
            } else {
                assert_eq!(
                    change_counts(a),
                    change_counts(b),
                    "frame {}: change counts",
                    a.frame
                );
            }
        }
    }
}

/// The first frame of each shard's stats file in `dir`: where each shard's process started
/// (a resumed task starts elsewhere too; the caller adds those).
pub fn shard_starts(dir: &Path) -> BTreeSet<u32> {
    let mut starts = BTreeSet::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if !(name.starts_with("stats.shard-") && name.ends_with(".jsonl")) {
            continue;
        }
        let first = std::fs::read_to_string(&path)
            .unwrap()
            .lines()
            .map(|line| Record::parse(line).unwrap().frame())
            .min();
        starts.extend(first);
    }
    starts
}

/// The first frame (at 30 fps) of [`write_failing_scene`] that cannot be rendered.
pub const FIRST_FAILING_FRAME: u32 = 4;

/// Writes a one-triangle glTF whose node jumps, at frame [`FIRST_FAILING_FRAME`], to a
/// translation and scale that overflow its vertices to infinity: mipray loads it and
/// renders the frames before, then fails on that frame ("triangle 0 has a non-finite
/// vertex"). Returns its path.
pub fn write_failing_scene(dir: &Path) -> PathBuf {
    use serde_json::json;
    let (json, mut buffers) = super::single_triangle(
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[0, 1, 2],
    );
    // Between frames 3 (t = 0.1 s) and 4 (t = 0.1333 s).
    let jump = 0.12f32;
    let times = buffers.floats(&[[0.0f32], [jump]], "SCALAR");
    super::merge(
        &mut buffers.accessors[times],
        json!({ "min": [0.0], "max": [jump] }),
    );
    let translation = buffers.floats(&[[0.0f32; 3], [f32::MAX; 3]], "VEC3");
    let scale = buffers.floats(&[[1.0f32; 3], [1e38; 3]], "VEC3");
    let mut json = super::with_embedded_buffer(json, &buffers);
    super::merge(
        &mut json,
        json!({ "animations": [{
            "samplers": [
                { "input": times, "output": translation, "interpolation": "STEP" },
                { "input": times, "output": scale, "interpolation": "STEP" },
            ],
            "channels": [
                { "sampler": 0, "target": { "node": 0, "path": "translation" } },
                { "sampler": 1, "target": { "node": 0, "path": "scale" } },
            ],
        }] }),
    );
    let path = dir.join("overflowing.gltf");
    std::fs::write(&path, serde_json::to_vec_pretty(&json).unwrap()).unwrap();
    path
}
