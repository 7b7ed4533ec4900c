//! `mipray export`: each frame's world-space triangles exactly as the renderer traces them
//! (positions, shading normals, UVs, material, `log2 P_b`), the camera with its primary-ray
//! convention and the frame's lights, for other tools (Blender, a second renderer) and for
//! regression checks.
//!
//! Files per frame `N` in the output folder (formats in `docs/src/export.md` and
//! `docs/src/files.md`):
//! - `frame_NNNN.obj` (+ one shared `materials.mtl` and `textures/*.png`), or
//!   `frame_NNNN.ply` (binary little-endian, with per-face material, `log2_pb`, `deformed`);
//! - `camera_NNNN.json`: camera, primary-ray convention, lights, background;
//! - with `--rays`, `rays_NNNN.bin`: every ray the frame traces when rendered ([`rays`]).
//!
//! Invariants: meshes stream from `Renderer::triangles()` through a `BufWriter` (no second
//! in-memory copy of the mesh); every file is written to a hidden temporary file in the same
//! folder and renamed into place, so a file is either absent or complete.

pub mod camera;
mod obj;
mod ply;
pub mod rays;

use std::fs::{self, File};
use std::io::{self, BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::atomic_file::{self, AtomicWriteError};
use crate::frame::{FrameError, Motion, Renderer};
use crate::render::memory::{FrameTooLarge, LINEAR_PIXEL_BYTES, check_frame_memory};

pub use crate::scene::camera_file::{CameraFile, LightFile};
pub use obj::{MTL_FILE, texture_file_name};

/// Mesh file format of an export.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ExportFormat {
    /// Wavefront OBJ + MTL + PNG textures (Blender, most tools).
    #[default]
    Obj,
    /// Binary little-endian PLY with per-face material, log2_pb and deformed flags.
    Ply,
}

impl ExportFormat {
    pub fn extension(self) -> &'static str {
        match self {
            ExportFormat::Obj => "obj",
            ExportFormat::Ply => "ply",
        }
    }
}

/// What to export and where.
#[derive(Debug, Clone)]
pub struct ExportOptions {
    pub format: ExportFormat,
    pub dir: PathBuf,
    /// Half-open frame range; frame `i` is at `clock.time(i)` (as `render` does).
    pub frames: Range<u32>,
    pub clock: crate::frame::FrameClock,
    /// Also render each frame (with the renderer's settings) and write the rays it traced.
    pub rays: bool,
}

/// One exported frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedFrame {
    pub frame: u32,
    pub time_s: f32,
    pub mesh: PathBuf,
    pub camera: PathBuf,
    pub triangles: usize,
    /// Triangles flagged `deformed` (shape changed since the previous frame).
    pub deformed: usize,
    /// The ray file and its record count, with `ExportOptions::rays`.
    pub rays: Option<(PathBuf, usize)>,
}

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: io::Error },
    #[error("{path}: cannot encode texture: {source}")]
    Encode {
        path: PathBuf,
        source: image::ImageError,
    },
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// `--rays` at a size whose rays this process cannot hold.
    #[error(transparent)]
    Memory(#[from] FrameTooLarge),
    /// The renderer places some meshes as instances, whose triangles are not in its world
    /// tree: the export writes the world tree's triangles, so it needs the flat layout.
    #[error(
        "export needs every triangle in one world-space tree, but {meshes} mesh(es) are placed \
         as instances: make the renderer with the flat layout (`BvhLayout::Flat`)"
    )]
    Instanced { meshes: usize },
}

pub(crate) fn io_error(path: &Path) -> impl FnOnce(io::Error) -> ExportError + '_ {
    move |source| ExportError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// File name of frame `index`'s mesh: `frame_0000.obj` (at least four digits).
pub fn mesh_file_name(index: u32, format: ExportFormat) -> String {
    format!("frame_{index:04}.{}", format.extension())
}

/// File name of frame `index`'s camera: `camera_0000.json`.
pub fn camera_file_name(index: u32) -> String {
    format!("camera_{index:04}.json")
}

/// Streams a file through a `BufWriter` into place atomically ([`crate::atomic_file`]); on
/// any error `path` is untouched and the error names it (or the temporary file).
pub(crate) fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<(), ExportError> {
    atomic_file::write_atomically(path, write).map_err(|e| match e {
        AtomicWriteError::Io { path, source } => ExportError::Io { path, source },
        AtomicWriteError::Write(source) => io_error(path)(source),
    })
}

/// Per-slot bitset of the triangles the last `prepare` marked [`Motion::Deformed`].
pub(crate) fn deformed_slots(renderer: &Renderer) -> Vec<u64> {
    let mut bits = vec![0u64; renderer.triangles().len().div_ceil(64)];
    for (slot, motion) in renderer.dirty().moved() {
        if motion == Motion::Deformed {
            bits[slot as usize / 64] |= 1 << (slot % 64);
        }
    }
    bits
}

pub(crate) fn bit(bits: &[u64], slot: usize) -> bool {
    bits.get(slot / 64)
        .is_some_and(|w| w & (1 << (slot % 64)) != 0)
}

/// Per slot of the renderer's triangles, its face index in the OBJ export of the frame (the
/// `result` of a hit in the ray file, whatever the mesh format exported beside it).
pub fn face_of_slot(renderer: &Renderer) -> Vec<u32> {
    let triangles = renderer.triangles();
    let order = obj::slots_in_face_order(
        &triangles.material,
        &triangles.source,
        renderer.materials().len(),
    );
    let mut face = vec![rays::MISS; triangles.len()];
    for (index, &slot) in order.iter().enumerate() {
        face[slot as usize] = index as u32;
    }
    face
}

/// The bytes per pixel [`write_frame_rays`] holds at least: when the film joins its tiles,
/// the frame's linear pixels, every tile's log and the frame's log at once (two logged rays
/// per sample's primary ray); then the frame's log and its records in the file's layout.
/// The larger of the two (the bounces' and shadow rays come on top of both).
fn recorded_pixel_bytes(spp: u32) -> u64 {
    let logged = std::mem::size_of::<crate::render::TracedRay>() as u64;
    let record = std::mem::size_of::<rays::RayRecord>() as u64;
    let samples = u64::from(spp.max(1));
    (LINEAR_PIXEL_BYTES + 2 * logged * samples).max((logged + record) * samples)
}

/// Renders the prepared frame recording its rays and writes them to `path` (the result of
/// a hit as the face index in the frame's OBJ export); returns the number of rays.
fn write_frame_rays(
    renderer: &Renderer,
    prepared: &crate::frame::PreparedFrame,
    path: &Path,
) -> Result<usize, ExportError> {
    let scene = renderer.frame_scene(prepared);
    let spp = renderer.settings().spp.max(1);
    let (_, counters) = crate::render::render_image_recording(&scene, &prepared.camera, spp);
    let log = counters.log.unwrap_or_default();
    let face_of_slot = face_of_slot(renderer);
    let records: Vec<rays::RayRecord> = log
        .rays
        .iter()
        .map(|ray| rays::RayRecord::of(ray, &face_of_slot))
        .collect();
    write_atomically(path, |w| rays::write_records(w, &records))?;
    Ok(records.len())
}

/// Exports `options.frames` of the renderer's scene into `options.dir` (created if
/// needed), calling `on_frame` after each frame's files are in place.
///
/// When the range starts after frame 0, frame `start - 1` is prepared first (and not
/// written) so that `deformed` always means "changed since the previous frame", whatever
/// frame an export starts at; frame 0 has no previous frame and flags nothing.
///
/// The renderer must use the flat layout ([`crate::accel::BvhLayout::Flat`]): the files
/// hold the world tree's triangles, and the ray file's answers are its slots' faces, so a
/// mesh placed as an instance would be missing from both.
///
/// # Errors
/// The renderer places meshes as instances, the folder or a file cannot be written, a
/// texture cannot be encoded, or animation produced a non-finite vertex.
pub fn export_frames(
    renderer: &mut Renderer,
    options: &ExportOptions,
    mut on_frame: impl FnMut(&ExportedFrame),
) -> Result<Vec<ExportedFrame>, ExportError> {
    let meshes = renderer.layout().instanced_meshes();
    if meshes > 0 {
        return Err(ExportError::Instanced { meshes });
    }
    if options.rays && !options.frames.is_empty() {
        let settings = renderer.settings();
        check_frame_memory(
            settings.width,
            settings.height,
            recorded_pixel_bytes(settings.spp),
            || "recording a frame's rays at this size".to_string(),
        )?;
    }
    fs::create_dir_all(&options.dir).map_err(io_error(&options.dir))?;
    let time_of = |frame: u32| options.clock.time(frame);
    if options.frames.start > 0 {
        let previous = options.frames.start - 1;
        renderer.prepare(previous, time_of(previous))?;
    }
    if options.format == ExportFormat::Obj {
        let textures = obj::write_textures(renderer, &options.dir)?;
        obj::write_mtl(renderer, &options.dir, &textures)?;
    }
    let mut done = Vec::new(); // grows with the frames written, not the range asked for
    for frame in options.frames.clone() {
        let time_s = time_of(frame);
        let prepared = renderer.prepare(frame, time_s)?;
        let mesh = options.dir.join(mesh_file_name(frame, options.format));
        let deformed = deformed_slots(renderer);
        match options.format {
            ExportFormat::Obj => obj::write_obj(renderer, &mesh, frame, time_s)?,
            ExportFormat::Ply => ply::write_ply(renderer, &mesh, frame, time_s, &deformed)?,
        }
        let camera = options.dir.join(camera_file_name(frame));
        let file = CameraFile::new(
            frame,
            time_s,
            &prepared.camera,
            &prepared.lights,
            renderer.scene().background,
        );
        let json = serde_json::to_string_pretty(&file).map_err(|e| io_error(&camera)(e.into()))?;
        write_atomically(&camera, |w| {
            w.write_all(json.as_bytes())?;
            w.write_all(b"\n")
        })?;
        let rays = if options.rays {
            let path = options.dir.join(rays::ray_file_name(frame));
            let count = write_frame_rays(renderer, &prepared, &path)?;
            Some((path, count))
        } else {
            None
        };
        let exported = ExportedFrame {
            frame,
            time_s,
            mesh,
            camera,
            triangles: renderer.triangles().len(),
            deformed: deformed.iter().map(|w| w.count_ones() as usize).sum(),
            rays,
        };
        on_frame(&exported);
        done.push(exported);
    }
    Ok(done)
}
