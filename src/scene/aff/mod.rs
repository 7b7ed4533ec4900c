//! BART / AFF loader: an `.aff` scene (NFF plus animation extensions, Lext et al. 2001) to a
//! [`SceneDesc`]. The format and its reference algorithms are summarised in the project's
//! BART notes (FORMAT.md); this module follows them exactly where they define behaviour.
//!
//! Split by concept:
//! - `lexer`: bytes -> tokens (Latin-1, CRLF, `#`/`%` comments anywhere, `{` `}` split);
//! - `reader`: typed reads with `file:line:` messages;
//! - `parser`: the command loop (global `fm` state, transform stack, includes, `k` blocks);
//! - `includes`: include/texture path rules, file cache, include-cycle detection;
//! - `mesh`: `m` with per-attribute indices, expanded to one index list;
//! - `shapes`: polygons (fan), open cones (32 segments, smooth normals), spheres;
//! - `materials`: `fm` -> [`MaterialDesc`](crate::scene::MaterialDesc), PPM textures (sRGB);
//! - [`tracks`]: `transl`/`scale` KB splines -> CUBICSPLINE, `rot` -> SQUAD channels;
//! - `camera`: `v` and the camera node; `builder`: nodes, meshes, primitives, `tpa` morphs.
//!
//! Scene mapping:
//! - **hierarchy**: a root node holds geometry outside any transform; each `xs` (static TRS,
//!   M = T·R·S) and `x name` (TRS from `k name`, identity without one) is a child node of
//!   the enclosing one; geometry goes to its node's mesh, one primitive per material run;
//! - **animation**: one clip named `"aff"` with every channel; `k` blocks resolve by name
//!   after the whole parse (the last block of a name wins; one block can drive several
//!   nodes); a node's rest TRS is its tracks sampled at the first frame time;
//! - **camera**: a root node named `camera` (see `camera`); **lights**: one root node per
//!   `l`, a point light of intensity pi (see below) with the given colour (default white) and
//!   `inverse_square: false` (NFF lights have no distance falloff);
//! - **tpa**: per run of triangles with one material and sample times, a child node whose
//!   mesh has sample 0 as base and one morph target per further sample (deltas of positions
//!   and of unit normals), driven by a LINEAR weights channel with one-hot keys at the sample
//!   times (linear interpolation between samples; clamped outside). Difference from the
//!   reference: normals are normalised per sample before interpolation (the reference
//!   interpolates the raw, non-unit normals, then normalises), so in-between normals can
//!   differ slightly in direction where a normal's length changes between samples;
//! - `SceneDesc::ambient` = `am` (default 1 1 1), `background` = `b` (default black),
//!   `frame_times` = `a` (frame i at `start + i (end - start) / (frames - 1)`; at most
//!   1,000,001 frames, a longer request spread over that many, noted).
//!
//! Not rendered as the reference would, each reported in `SceneDesc::notes` when used:
//! `visibility` tracks (parsed, ignored), `la` animated lights (static at their position),
//! the `v resolution` (informational; the CLI's size applies).

mod builder;
mod camera;
mod includes;
mod lexer;
mod materials;
mod mesh;
mod parser;
mod reader;
mod shapes;
pub mod tracks;

use std::path::{Path, PathBuf};

use glam::Vec3;

pub use super::gltf::LoadError;
pub use camera::look_at_rotation;
pub use lexer::{Lexer, Token, latin1};
pub use shapes::CONE_SEGMENTS;

use super::{
    AnimationDesc, CameraDesc, ChannelDesc, ChannelTarget, FrameTimes, Interpolation, LightDesc,
    LightKind, SceneDesc, Trs,
};
use crate::anim::{sample_rotation, sample_vec3};
use parser::Parser;

/// What the files contained, counted per source command (for `info` and tests). "Meshes"
/// are `m` commands, the unit FORMAT.md's scene facts count (Kitchen 393, Robots 1,849); a
/// file included twice counts twice, as its geometry is loaded twice.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AffStats {
    /// Files parsed, an include counted each time it is expanded (the main file too).
    pub files: usize,
    /// `m` commands and their triangles.
    pub meshes: usize,
    pub mesh_triangles: usize,
    /// `p` and `pp` commands and their fan triangles.
    pub polygons: usize,
    pub polygon_triangles: usize,
    /// `tt` and `ttp` triangles.
    pub textured_triangles: usize,
    /// `tpa` (vertex-morphing) triangles.
    pub morph_triangles: usize,
    /// `c` commands and the triangles of their tessellation ([`CONE_SEGMENTS`] x 2 each).
    pub cones: usize,
    pub cone_triangles: usize,
    /// `s` commands and the triangles of their tessellation.
    pub spheres: usize,
    pub sphere_triangles: usize,
    /// `xs` and `x` blocks.
    pub static_transforms: usize,
    pub animated_transforms: usize,
    /// Distinct `k` names.
    pub key_blocks: usize,
    /// `l` and `la` lights.
    pub lights: usize,
    /// Distinct texture files.
    pub textures: usize,
}

impl AffStats {
    /// Triangles of the source's own triangles and polygons (`m`, `p`/`pp`, `tt`/`ttp`):
    /// FORMAT.md's "static" count, without `tpa` and tessellated cones and spheres.
    pub fn source_triangles(&self) -> usize {
        self.mesh_triangles + self.polygon_triangles + self.textured_triangles
    }

    /// Every triangle the scene renders.
    pub fn total_triangles(&self) -> usize {
        self.source_triangles() + self.morph_triangles + self.cone_triangles + self.sphere_triangles
    }
}

/// Loads an `.aff` file and everything it includes.
///
/// # Errors
/// A [`LoadError`] for the main file whose message names the file and line of the problem
/// (`kitchen.aff:1234: expected a number after 'v', found 'foo': not a number`): unreadable or missing
/// include or texture, malformed number or count, unknown command, index out of range,
/// include cycle (naming the chain), unbalanced `}`, decreasing key times.
pub fn load(path: &Path) -> Result<SceneDesc, LoadError> {
    load_with_stats(path).map(|(scene, _)| scene)
}

/// [`load`], also returning the per-command counts.
pub fn load_with_stats(path: &Path) -> Result<(SceneDesc, AffStats), LoadError> {
    load_scene(path).map_err(|message| LoadError {
        path: path.to_path_buf(),
        message,
    })
}

/// [`load_with_stats`] on files held in memory: `files` maps paths to contents, `main` is
/// one of them; includes and textures resolve by the usual rules among `files` only (the
/// disk is never read). For fuzzing and tests.
///
/// # Errors
/// As [`load`].
pub fn load_from_memory(
    main: &Path,
    files: impl IntoIterator<Item = (PathBuf, Vec<u8>)>,
) -> Result<(SceneDesc, AffStats), LoadError> {
    let files: Vec<(PathBuf, Vec<u8>)> = files.into_iter().collect();
    let error = |message| LoadError {
        path: main.to_path_buf(),
        message,
    };
    if files
        .iter()
        .any(|(path, bytes)| path == main && bytes.is_empty())
    {
        return Err(error("file is empty".into()));
    }
    let files = includes::Files::in_memory(files);
    if !files.exists(main) {
        return Err(error("cannot read file: not found".into()));
    }
    let mut p = new_parser(main);
    p.files = files;
    p.parse_file(main, &display_name(main)).map_err(error)?;
    finish(main, p).map_err(error)
}

/// A parser for the scene whose main file is `path`.
fn new_parser(path: &Path) -> Parser {
    let main_dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let root_name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "aff".into());
    Parser::new(main_dir, root_name)
}

fn display_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

fn load_scene(path: &Path) -> Result<(SceneDesc, AffStats), String> {
    if !path.is_file() {
        return Err("cannot read file: not found".into());
    }
    // An empty main file is a mistake (a failed download or copy), not an empty scene: as
    // for glTF and USD files, an error rather than a black picture.
    if std::fs::metadata(path).is_ok_and(|m| m.len() == 0) {
        return Err("file is empty".into());
    }
    let mut p = new_parser(path);
    p.parse_file(path, &display_name(path))?;
    finish(path, p)
}

/// Most frames an `a` line's own range gives, as for a USD stage's time code range: a
/// longer range keeps its start and end with frames further apart (`--frames` and `--fps`
/// choose others).
const MAX_AFF_FRAMES: u32 = 1_000_001;

/// Notes for an `a start end frames` line a user may not have meant: no frames at all
/// (rendered as one frame at `start`), an end before the start (played backwards, as the
/// line's formula says), or more frames than [`MAX_AFF_FRAMES`] (spread over that many).
fn note_frame_times(times: &mut Option<FrameTimes>, notes: &mut Vec<String>) {
    let Some(t) = times else { return };
    if t.frames > MAX_AFF_FRAMES {
        notes.push(format!(
            "'a {} {} {}' asks for more than {MAX_AFF_FRAMES} frames; the default range is \
             {MAX_AFF_FRAMES} frames over the same time (use --frames and --fps to choose)",
            t.start, t.end, t.frames
        ));
        t.frames = MAX_AFF_FRAMES;
    }
    if t.frames == 0 {
        notes.push(format!(
            "'a {} {} 0' asks for no frames; the default range is one frame, at time {}",
            t.start, t.end, t.start
        ));
    } else if t.end < t.start {
        notes.push(format!(
            "'a {} {} {}' ends before it starts: the animation plays backwards",
            t.start, t.end, t.frames
        ));
    }
}

/// The scene and counts of a whole parse: `k` blocks resolved onto their nodes, then the
/// camera, the lights and the morph channels added, each section in its own step below
/// (node order: the parse's, then the camera, then the lights; channel order: animated
/// transforms, camera, morph weights).
fn finish(path: &Path, mut p: Parser) -> Result<(SceneDesc, AffStats), String> {
    let mut notes = std::mem::take(&mut p.notes);
    if p.scopes.len() > 1 {
        notes.push(format!(
            "{} transform block(s) not closed by '}}' at the end of the file",
            p.scopes.len() - 1
        ));
    }
    note_frame_times(&mut p.frame_times, &mut notes);
    let rest_time = p.frame_times.map_or(0.0, |f| f.start);
    let mut tracks = ResolvedTracks::default();
    animate_transforms(&mut p, rest_time, &mut tracks);
    let cameras = add_camera(&mut p, rest_time, &mut tracks, &mut notes)?;
    let lights = add_lights(&mut p, &mut notes);
    add_morph_channels(&p, &mut tracks.channels);
    note_track_findings(&p, &tracks, &mut notes);
    if p.materials.used_default {
        notes.push("geometry before the first 'fm' uses plain white diffuse".into());
    }
    notes.push(
        "textures are treated as sRGB; shine is used as the Phong exponent without the OpenGL x4"
            .into(),
    );
    let stats = counts(&p);
    Ok((
        scene_of(path, p, cameras, lights, tracks.channels, notes),
        stats,
    ))
}

/// The channels made from `k` blocks so far, and what was found while making them.
#[derive(Default)]
struct ResolvedTracks {
    channels: Vec<ChannelDesc>,
    /// Names of the `k` blocks some node used.
    used_blocks: std::collections::HashSet<String>,
    /// Nodes whose block has a `visibility` track (ignored).
    visibility_ignored: usize,
    /// Rotation tracks whose backward key times are approximated.
    approximations: usize,
}

/// Animated transforms: each `x name` node takes the channels of its `k name` block and its
/// rest TRS from them.
fn animate_transforms(p: &mut Parser, rest_time: f32, tracks: &mut ResolvedTracks) {
    for (node, name) in &p.x_nodes {
        let Some(block) = p.key_blocks.get(name) else {
            continue;
        };
        tracks.used_blocks.insert(name.clone());
        if block.visibility.is_some() {
            tracks.visibility_ignored += 1;
        }
        let local = track_channels(
            block,
            *node,
            rest_time,
            &mut tracks.channels,
            &mut tracks.approximations,
        );
        p.builder.nodes[*node].local = local;
    }
}

/// Camera: the `v` view as a root node named `camera` (animated by a `k camera` block's
/// `transl` and `rot`); no camera without a `v`.
///
/// # Errors
/// A view angle outside (0, 180) degrees.
fn add_camera(
    p: &mut Parser,
    rest_time: f32,
    tracks: &mut ResolvedTracks,
    notes: &mut Vec<String>,
) -> Result<Vec<CameraDesc>, String> {
    let Some(view) = p.view else {
        notes.push("the file has no 'v' view: no camera".into());
        return Ok(Vec::new());
    };
    if !(view.angle > 0.0 && view.angle < 180.0) {
        return Err(format!(
            "view angle {} is outside (0, 180) degrees",
            view.angle
        ));
    }
    let cameras = vec![CameraDesc {
        yfov: view.angle.to_radians(),
        znear: view.hither,
    }];
    let rest = Trs {
        translation: view.from,
        rotation: look_at_rotation(view.from, view.at, view.up),
        scale: Vec3::ONE,
    };
    let node = p.builder.add_node(None, "camera".into(), rest);
    p.builder.nodes[node].camera = Some(0);
    if let Some(block) = p.key_blocks.get("camera") {
        tracks.used_blocks.insert("camera".into());
        let channels = &mut tracks.channels;
        let mut local =
            track_channels(block, node, rest_time, channels, &mut tracks.approximations);
        // Only transl and rot apply to the camera: scale stays 1, a missing track keeps
        // the `v` value.
        local.scale = Vec3::ONE;
        if block.translation.is_none() {
            local.translation = view.from;
        }
        if block.rotation.is_none() {
            local.rotation = rest.rotation;
        }
        channels.retain(|c| !(c.node == node && c.target == ChannelTarget::Scale));
        p.builder.nodes[node].local = local;
    }
    let (w, h) = view.resolution;
    notes.push(format!(
        "the file asks for {w}x{h} pixels (v resolution); the render size options apply"
    ));
    Ok(cameras)
}

/// Lights: one root node per `l`/`la`, a point light without distance falloff.
fn add_lights(p: &mut Parser, notes: &mut Vec<String>) -> Vec<LightDesc> {
    let mut lights = Vec::new();
    let mut animated_lights = Vec::new();
    for (i, light) in p.lights.iter().enumerate() {
        lights.push(LightDesc {
            kind: LightKind::Point,
            color: light.color,
            // NFF shades `diff * Lc * max(0, N.L)`; the integrator's Lambert term is
            // `albedo * E * cos / pi`, so an irradiance of pi reproduces the NFF light.
            intensity: std::f32::consts::PI,
            range: None,
            inverse_square: false,
        });
        let name = light.name.clone().unwrap_or_else(|| format!("light{i}"));
        if light.name.is_some() {
            animated_lights.push(name.clone());
        }
        let node = p.builder.add_node(
            None,
            name,
            Trs {
                translation: light.position,
                ..Default::default()
            },
        );
        p.builder.nodes[node].light = Some(i);
    }
    if !lights.is_empty() {
        notes.push(
            "AFF point lights have no distance falloff (lights use inverse_square = false)".into(),
        );
    }
    if !animated_lights.is_empty() {
        notes.push(format!(
            "animated lights (la) are placed statically: {}",
            animated_lights.join(", ")
        ));
    }
    lights
}

/// Vertex morphing: per `tpa` group of two samples or more, a LINEAR weights channel with
/// one-hot keys at the sample times.
fn add_morph_channels(p: &Parser, channels: &mut Vec<ChannelDesc>) {
    for group in &p.builder.morph_groups {
        let k = group.times.len();
        if k < 2 {
            continue;
        }
        let targets = k - 1;
        let mut values = vec![0.0; k * targets];
        for i in 1..k {
            values[i * targets + (i - 1)] = 1.0;
        }
        channels.push(ChannelDesc {
            node: group.node,
            target: ChannelTarget::Weights,
            interpolation: Interpolation::Linear,
            times: group.times.clone(),
            values,
            components: targets,
        });
    }
}

/// Notes on the key tracks: backward key times, approximated rotation segments, ignored
/// visibility tracks, unused blocks.
fn note_track_findings(p: &Parser, tracks: &ResolvedTracks, notes: &mut Vec<String>) {
    if p.tracks_going_back > 0 {
        notes.push(format!(
            "{} key track(s) have key times that go back; they are evaluated as the reference does (the first segment ending after t)",
            p.tracks_going_back
        ));
    }
    if tracks.approximations > 0 {
        notes.push(format!(
            "{} rotation track(s) have key times going back that make the reference enter a squad segment part-way; such segments play in full over their time range",
            tracks.approximations
        ));
    }
    if tracks.visibility_ignored > 0 {
        notes.push(format!(
            "{} node(s) have 'visibility' tracks, which are ignored (always visible)",
            tracks.visibility_ignored
        ));
    }
    let mut unused: Vec<&str> = p
        .key_blocks
        .keys()
        .map(String::as_str)
        .filter(|n| !tracks.used_blocks.contains(*n))
        .collect();
    unused.sort_unstable();
    if !unused.is_empty() {
        notes.push(format!(
            "key blocks not used by any node: {}",
            unused.join(", ")
        ));
    }
}

/// The per-command counts, completed with what is known only at the end.
fn counts(p: &Parser) -> AffStats {
    let mut stats = p.stats.clone();
    stats.files = p.files.expanded;
    stats.key_blocks = p.key_blocks.len();
    stats.lights = p.lights.len();
    stats.textures = p.materials.textures.len();
    stats
}

/// The scene description: the parse's nodes, meshes and materials with the camera, lights
/// and one clip named `"aff"` holding every channel (none when nothing is animated).
fn scene_of(
    path: &Path,
    p: Parser,
    cameras: Vec<CameraDesc>,
    lights: Vec<LightDesc>,
    channels: Vec<ChannelDesc>,
    notes: Vec<String>,
) -> SceneDesc {
    let animations = if channels.is_empty() {
        Vec::new()
    } else {
        vec![AnimationDesc {
            name: "aff".into(),
            channels,
        }]
    };
    SceneDesc {
        source: path.to_path_buf(),
        meshes: p.builder.meshes,
        nodes: p.builder.nodes,
        roots: p.builder.roots,
        materials: p.materials.materials,
        textures: p.materials.textures,
        cameras,
        lights,
        animations,
        skins: Vec::new(),
        background: p.background.unwrap_or(Vec3::ZERO),
        ambient: Some(p.ambient.unwrap_or(Vec3::ONE)),
        frame_times: p.frame_times,
        notes,
    }
}

/// Adds the channels of `block` for `node` and returns the node's TRS sampled at
/// `rest_time` (identity components for missing tracks).
fn track_channels(
    block: &tracks::KeyBlock,
    node: usize,
    rest_time: f32,
    channels: &mut Vec<ChannelDesc>,
    approximations: &mut usize,
) -> Trs {
    let mut local = Trs::default();
    if let Some(c) = block
        .translation
        .as_deref()
        .and_then(|k| tracks::position_channel(k, node, ChannelTarget::Translation))
    {
        local.translation = sample_vec3(&c, rest_time);
        channels.push(c);
    }
    if let Some((c, approximated)) = block
        .rotation
        .as_deref()
        .and_then(|k| tracks::rotation_channel(k, node))
    {
        *approximations += usize::from(approximated);
        local.rotation = sample_rotation(&c, rest_time);
        channels.push(c);
    }
    if let Some(c) = block
        .scale
        .as_deref()
        .and_then(|k| tracks::position_channel(k, node, ChannelTarget::Scale))
    {
        local.scale = sample_vec3(&c, rest_time);
        channels.push(c);
    }
    local
}
