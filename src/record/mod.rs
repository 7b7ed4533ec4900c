//! The record every frame leaves: one line of `stats.jsonl`, the preprocessing phases it
//! times, and the one reader of stats files that every tool uses.
//!
//! This is the only declaration of the per-frame record and a leaf: it imports nothing from
//! the rest of the crate, so the frame loop that fills it and the tools that read it back
//! (the output folder's resume, `mipray report`, `mipray diff`, the render page) all stand
//! on it. The JSON field names are the Rust field names; `update` is flattened, so a line
//! is one flat object. A line is written with `serde_json` ([`FrameRecord`] is
//! `Serialize`) and read back only through [`Record::parse`] (and [`load_sequence`] for the
//! files of a folder): tolerant of unknown fields and of fields older files lack (absent,
//! never invented as 0), strict about the types of the fields it knows; each tool then asks
//! for what it needs (the frame number always; a resumed render every field it rewrites,
//! [`Record::missing`]).
//!
//! Each record also says which run it belongs to (`scene` and `settings`, see
//! [`run_differences`]), so frames of different renders are never mixed in one sequence.
//!
//! [`Phase`] is the one list of the preprocessing phases (the update steps before the
//! render, in frame-loop order): the summary, the report table, its plot, the render page
//! and `compare` iterate over [`Phase::ALL`] rather than naming the fields again.

mod identity;
mod load;
mod read;

pub use identity::{
    RunIdentity, SettingDifference, Settings, describe_differences, run_differences,
    scene_files_identity, scene_identity,
};
pub use load::{
    MixedRuns, Sequence, StatsFileError, is_stats_file_name, load_records, load_sequence,
    read_stats_file,
};
pub use read::{Record, RecordError};

use serde::Serialize;

/// What one frame cost and produced: one line of `stats.jsonl`.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct FrameRecord {
    pub frame: u32,
    pub time_s: f32,
    pub width: u32,
    pub height: u32,
    pub lod_method: String,
    /// `--lod-bias` (absent in records written before it existed: read as 0, see
    /// [`Record::missing`]).
    pub lod_bias: f32,
    pub triangles: usize,
    pub lights: usize,
    pub spp: u32,
    /// What the frame was traced through: `flat` (one world-space tree) or `two-level`
    /// (instances of shared meshes beside the world-space tree), whichever `--bvh` asked for
    /// (`auto` picks per scene). Empty in records written before it existed.
    pub bvh_layout: String,
    /// Mesh primitives placed as instances (0 under `flat`; absent in older records).
    pub instanced_meshes: usize,
    /// The per-frame update: what moved and what each step cost.
    #[serde(flatten)]
    pub update: UpdateStats,
    pub render_ms: f64,
    /// Everything above plus camera/light placement (not the file write).
    pub total_ms: f64,
    /// All rays traced: primary, shadow, reflection, refraction.
    pub rays: u64,
    /// Texture lookups per integer level (floor of the clamped level), index 0 = level 0.
    pub mip_histogram: Vec<u64>,
    /// Samples that came out NaN/inf and were written as black (expected 0).
    pub nonfinite_samples: u64,
    /// The scene: its file name and a digest of its bytes ([`scene_identity`]). Empty, and
    /// not written, when unknown (records written before it existed).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub scene: String,
    /// The other files the scene load read (buffers, textures, layers, includes): how
    /// many and one digest of their bytes ([`scene_files_identity`]). Empty, and not
    /// written, when unknown (records written before it existed).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub scene_files: String,
    /// Every setting that changes the pixels, by flag name (`size`, `lod`, `max-depth`...).
    /// Empty, and not written, when unknown (records written before it existed).
    #[serde(skip_serializing_if = "Settings::is_empty")]
    pub settings: Settings,
}

/// What the per-frame update did and cost (flattened into each `stats.jsonl` line).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct UpdateStats {
    /// Animation evaluated at the frame time and moved vertices written (by a write in
    /// slot order, with the leaf boxes of the tree: see `Accel::slot_lanes_and_leaf_boxes`).
    pub animate_ms: f64,
    /// Classifying instances and triangles into the dirty set.
    pub dirty_ms: f64,
    /// Refitting the BVH to the moved triangles (0 when nothing moved or it was rebuilt):
    /// the leaf boxes the write did not set, and the boxes above them.
    pub refit_ms: f64,
    /// Building the BVH (first frame, or a rebuild), including the reorder into BVH order.
    pub build_ms: f64,
    /// Whether the BVH was built this frame.
    pub rebuild: bool,
    /// SAH cost of the tree used for this frame over its cost right after its last build.
    pub sah_ratio: f32,
    /// Updating `log2 P_b` for the dirty triangles (0 for methods that do not use it).
    pub lod_update_ms: f64,
    /// Triangles whose box moved this frame (rigid + scaled + deformed).
    pub moved_triangles: usize,
    /// Triangles whose shape changed this frame.
    pub deformed_triangles: usize,
    /// Textured triangles whose `log2 P_b` was computed this frame (all on the first frame).
    pub lod_recomputed: usize,
    /// Textured triangles whose `log2 P_b` was shifted by a new uniform scale.
    pub lod_shifted: usize,
}

/// One timed step of the per-frame update, before the render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Phase {
    /// Animation sampled and moved vertices written.
    Animate,
    /// The dirty set classified.
    Dirty,
    /// The BVH refitted.
    Refit,
    /// The BVH built (first frame or rebuild).
    Build,
    /// `log2 P_b` refreshed for the dirty triangles.
    LodUpdate,
}

impl Phase {
    /// Every phase, in frame-loop order.
    pub const ALL: [Phase; 5] = [
        Phase::Animate,
        Phase::Dirty,
        Phase::Refit,
        Phase::Build,
        Phase::LodUpdate,
    ];

    /// Its field in `stats.jsonl` and `summary.json` (milliseconds).
    pub const fn field_name(self) -> &'static str {
        match self {
            Phase::Animate => "animate_ms",
            Phase::Dirty => "dirty_ms",
            Phase::Refit => "refit_ms",
            Phase::Build => "build_ms",
            Phase::LodUpdate => "lod_update_ms",
        }
    }

    /// Its name for people (progress lines, benchmark tables).
    pub const fn label(self) -> &'static str {
        match self {
            Phase::Animate => "animate",
            Phase::Dirty => "dirty",
            Phase::Refit => "refit",
            Phase::Build => "build",
            Phase::LodUpdate => "LOD update",
        }
    }

    /// Whether every LOD method pays it; only the `log2 P_b` refresh is paid by the methods
    /// that read `log2 P_b` alone (see `compare`).
    pub const fn is_shared(self) -> bool {
        !matches!(self, Phase::LodUpdate)
    }
}

impl UpdateStats {
    /// Milliseconds spent in `phase`.
    pub fn phase_ms(&self, phase: Phase) -> f64 {
        match phase {
            Phase::Animate => self.animate_ms,
            Phase::Dirty => self.dirty_ms,
            Phase::Refit => self.refit_ms,
            Phase::Build => self.build_ms,
            Phase::LodUpdate => self.lod_update_ms,
        }
    }

    /// Milliseconds of the whole update: the sum of every phase.
    pub fn preprocessing_ms(&self) -> f64 {
        Phase::ALL.iter().map(|&p| self.phase_ms(p)).sum()
    }
}

impl FrameRecord {
    /// The `stats.jsonl` name of every field, in the order a line is written.
    pub const FIELDS: [&'static str; 30] = [
        "frame",
        "time_s",
        "width",
        "height",
        "lod_method",
        "lod_bias",
        "triangles",
        "lights",
        "spp",
        "bvh_layout",
        "instanced_meshes",
        "animate_ms",
        "dirty_ms",
        "refit_ms",
        "build_ms",
        "rebuild",
        "sah_ratio",
        "lod_update_ms",
        "moved_triangles",
        "deformed_triangles",
        "lod_recomputed",
        "lod_shifted",
        "render_ms",
        "total_ms",
        "rays",
        "mip_histogram",
        "nonfinite_samples",
        "scene",
        "scene_files",
        "settings",
    ];

    /// Fields that records written before they existed lack, and whose absence means their
    /// default (`lod_bias`: 0, no bias; `bvh_layout` and `instanced_meshes`: not recorded,
    /// empty and 0; `scene`, `scene_files` and `settings`: unknown, empty): a record without
    /// them is still complete.
    pub const DEFAULTED: &'static [&'static str] = &[
        "lod_bias",
        "bvh_layout",
        "instanced_meshes",
        "scene",
        "scene_files",
        "settings",
    ];

    /// Milliseconds spent in `phase` this frame.
    pub fn phase_ms(&self, phase: Phase) -> f64 {
        self.update.phase_ms(phase)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase_accessor_reads_the_field_its_name_says() {
        let update = UpdateStats {
            animate_ms: 1.0,
            dirty_ms: 2.0,
            refit_ms: 3.0,
            build_ms: 4.0,
            lod_update_ms: 5.0,
            ..UpdateStats::default()
        };
        let json = serde_json::to_value(update).unwrap();
        for phase in Phase::ALL {
            assert_eq!(
                json[phase.field_name()].as_f64(),
                Some(update.phase_ms(phase)),
                "{phase:?}"
            );
        }
        assert_eq!(update.preprocessing_ms(), 15.0);
    }

    #[test]
    fn line_is_flat_and_in_declaration_order() {
        let line = serde_json::to_string(&FrameRecord::default()).unwrap();
        let expected = r#"{"frame":0,"time_s":0.0,"width":0,"height":0,"lod_method":"","lod_bias":0.0,"triangles":0,"lights":0,"spp":0,"bvh_layout":"","instanced_meshes":0,"animate_ms":0.0,"dirty_ms":0.0,"refit_ms":0.0,"build_ms":0.0,"rebuild":false,"sah_ratio":0.0,"lod_update_ms":0.0,"moved_triangles":0,"deformed_triangles":0,"lod_recomputed":0,"lod_shifted":0,"render_ms":0.0,"total_ms":0.0,"rays":0,"mip_histogram":[],"nonfinite_samples":0}"#;
        assert_eq!(line, expected);
    }

    #[test]
    fn field_list_is_the_written_line_in_order() {
        let record = FrameRecord {
            scene: "s.gltf#0".into(),
            scene_files: "none".into(),
            settings: Settings::from([("size".into(), "1x1".into())]),
            ..FrameRecord::default()
        };
        let line = serde_json::to_string(&record).unwrap();
        let at: Vec<usize> = FrameRecord::FIELDS
            .iter()
            .map(|f| line.find(&format!("\"{f}\":")).expect(f))
            .collect();
        assert!(at.windows(2).all(|w| w[0] < w[1]), "{line}");
        // One more for the setting inside `settings`.
        assert_eq!(line.matches("\":").count(), FrameRecord::FIELDS.len() + 1);
        for name in FrameRecord::DEFAULTED {
            assert!(FrameRecord::FIELDS.contains(name), "{name}");
        }
    }
}
