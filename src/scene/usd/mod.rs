//! OpenUSD loader: a `.usda`, `.usdc` or `.usdz` stage to a [`SceneDesc`], through the
//! `openusd` crate's composition engine (layers, references, payloads, variants, instancing
//! expanded).
//!
//! What each USD feature becomes (details in `docs/src/formats-usd.md` and each module):
//! - prims with `xformOpOrder` -> chains of nodes whose channels interpolate as USD does
//!   (`xform.rs`); every other prim that groups geometry -> an identity node;
//! - `Mesh` -> a mesh with one primitive per `materialBind` subset (`mesh.rs`); time-sampled
//!   `points` -> a point cache ([`crate::scene::PointCacheDesc`]);
//! - `Skeleton`, `SkelAnimation`, `SkelBindingAPI`, `BlendShape` -> joint nodes, a skin per
//!   bound mesh and morph targets (`skel.rs`);
//! - `Camera` -> a perspective camera; `UsdLux` lights -> point, spot and directional
//!   lights (`lights.rs`); `UsdPreviewSurface` + `UsdUVTexture` -> materials (`material.rs`);
//! - stage metadata: time codes become seconds (`/ timeCodesPerSecond`), an authored
//!   `startTimeCode`..`endTimeCode` the frame range (one frame per `framesPerSecond`), and
//!   `upAxis` and `metersPerUnit` a root node that turns the stage Y-up and into metres, so
//!   geometry, cameras and lights are converted together (and a stage converted from glTF
//!   comes back in glTF's frame).
//!
//! Invariants on `Ok` are those of `scene/mod.rs`. Bad input is an `Err` naming the file
//! and the prim or attribute, never a panic (`guard.rs`: hostile bytes are checked before
//! `openusd` parses them, and a panic inside it is caught as the last resort).

mod camera;
mod guard;
mod lights;
mod material;
mod mesh;
mod skel;
mod values;
mod xform;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3};
use openusd::usd::{self, Prim};

use crate::scene::{
    AnimationDesc, CameraDesc, ChannelDesc, ChannelTarget, FrameTimes, Interpolation, LightDesc,
    MeshDesc, NodeDesc, PrimitiveDesc, SceneDesc, SkinDesc, Trs,
};
use values::{Reader, scalar, token};

pub use guard::check_bytes;

/// Why a stage could not be loaded; the message names the prim or attribute and the problem.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct LoadError {
    pub path: PathBuf,
    pub message: String,
}

/// Radiance of rays that leave a USD stage without a `DomeLight` (as for glTF).
pub const BACKGROUND: Vec3 = super::gltf::BACKGROUND;

/// Most notes kept; past it one note says how many more there were.
const MAX_NOTES: usize = 40;

/// The stage metadata `mipray info` reports.
#[derive(Debug, Clone, PartialEq)]
pub struct StageMetadata {
    /// `"Y"` or `"Z"`: the axis applied (an authored axis USD does not allow reads as Y).
    pub up_axis: String,
    pub up_axis_authored: bool,
    pub meters_per_unit: f64,
    pub meters_per_unit_authored: bool,
    pub time_codes_per_second: f64,
    pub frames_per_second: f64,
    /// `(startTimeCode, endTimeCode)` when both are authored.
    pub time_code_range: Option<(f64, f64)>,
    /// How metadata USD reads but does not allow was read (an `upAxis` other than Y or Z, a
    /// time code range that ends before it starts).
    pub notes: Vec<String>,
}

/// Loads a `.usda`, `.usdc` or `.usdz` stage.
///
/// # Errors
/// A [`LoadError`] for an unreadable, malformed or inconsistent stage, a missing layer or
/// texture, or values the renderer cannot use (non-finite points, joint indices past the
/// skeleton, ...), naming the prim.
pub fn load(path: &Path) -> Result<SceneDesc, LoadError> {
    let error = |message| LoadError {
        path: path.to_path_buf(),
        message,
    };
    guard::check_file(path).map_err(error)?;
    guard::without_panics(|| load_stage(path)).map_err(error)
}

/// The stage's axis, unit and time metadata.
///
/// # Errors
/// As [`load`], for the stage's root layer.
pub fn metadata(path: &Path) -> Result<StageMetadata, LoadError> {
    let error = |message| LoadError {
        path: path.to_path_buf(),
        message,
    };
    guard::check_file(path).map_err(error)?;
    guard::without_panics(|| {
        let (stage, _) = open(path)?;
        read_metadata(&stage)
    })
    .map_err(error)
}

/// Opens the stage, with the text layers it read (to place a parse error found later).
fn open(path: &Path) -> Result<(usd::Stage, guard::TextLayers), String> {
    let name = path
        .to_str()
        .ok_or_else(|| "the path is not valid UTF-8".to_string())?;
    // Every layer the stage opens goes through the checking resolver (`guard.rs`).
    let text_layers = guard::TextLayers::default();
    let stage = usd::Stage::builder()
        .resolver(guard::CheckingResolver::new(text_layers.clone()))
        .open(name)
        .map_err(|e| stage_error(&text_layers.place(&format!("{e:#}"))))?;
    Ok((stage, text_layers))
}

/// The message for a stage that does not open. The USDA lexer reports a character or word
/// its grammar does not allow only as `Logos error: ()`; that is said in words.
fn stage_error(message: &str) -> String {
    let message = message.replace(
        "Logos error: ()",
        "a character or word USDA does not allow (a damaged or truncated file, or not USDA)",
    );
    format!("cannot open the stage: {message}")
}

fn read_metadata(stage: &usd::Stage) -> Result<StageMetadata, String> {
    let up = stage
        .stage_metadata("upAxis")
        .map_err(|e| e.to_string())?
        .as_ref()
        .and_then(token);
    let mut notes = Vec::new();
    // USD allows only Y and Z, but reads any token: UsdGeomGetStageUpAxis returns it as
    // authored, and usdview (like UsdLux's dome light) treats every axis but Z as Y.
    let up_axis = match up.as_deref() {
        Some("Z") => "Z".to_string(),
        None | Some("Y") => "Y".to_string(),
        Some(other) => {
            notes.push(format!(
                "upAxis \"{other}\" is not one USD allows (Y or Z); read as Y, as usdview does"
            ));
            "Y".to_string()
        }
    };
    let mpu = stage
        .stage_metadata("metersPerUnit")
        .map_err(|e| e.to_string())?
        .as_ref()
        .and_then(scalar);
    // USD's fallback unit is the centimetre.
    let meters_per_unit = mpu.unwrap_or(0.01);
    if !(meters_per_unit.is_finite() && meters_per_unit > 0.0) {
        return Err(format!(
            "metersPerUnit {meters_per_unit} must be a positive number"
        ));
    }
    let time_codes_per_second = stage.time_codes_per_second();
    let frames_per_second = stage.frames_per_second_or(time_codes_per_second);
    // The stage reports the rate it fell back on under timeCodesPerSecond; say which one the
    // file authored.
    let tcps_authored = stage
        .stage_metadata("timeCodesPerSecond")
        .ok()
        .flatten()
        .is_some();
    let tcps_name = if tcps_authored {
        "timeCodesPerSecond"
    } else {
        "framesPerSecond (standing in for the unauthored timeCodesPerSecond)"
    };
    for (name, v) in [
        (tcps_name, time_codes_per_second),
        ("framesPerSecond", frames_per_second),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(format!("{name} {v} must be a positive number"));
        }
    }
    let time_code_range = stage
        .has_authored_time_code_range()
        .then(|| (stage.start_time_code(), stage.end_time_code()));
    if let Some((start, end)) = time_code_range {
        if !(start.is_finite() && end.is_finite()) {
            return Err(format!(
                "startTimeCode {start} and endTimeCode {end} are not a finite range"
            ));
        }
        // usdview warns of an invalid frame range and plays nothing, showing time code 0.
        if start > end {
            notes.push(format!(
                "startTimeCode {start} is after endTimeCode {end}: an empty range, as in usdview, \
                 which shows the stage at time code 0; one frame at time code 0 (use --frames to choose)"
            ));
        }
    }
    Ok(StageMetadata {
        up_axis,
        up_axis_authored: up.is_some(),
        meters_per_unit,
        meters_per_unit_authored: mpu.is_some(),
        time_codes_per_second,
        frames_per_second,
        time_code_range,
        notes,
    })
}

/// Most frames a stage's own time code range gives (a longer range keeps its start and end,
/// with frames further apart; `info` shows the spacing and `--frames`/`--fps` choose others).
const MAX_STAGE_FRAMES: f64 = 1e6;

/// Reads `framesPerSecond` when authored.
trait FramesPerSecond {
    fn frames_per_second_or(&self, fallback: f64) -> f64;
}

impl FramesPerSecond for usd::Stage {
    fn frames_per_second_or(&self, fallback: f64) -> f64 {
        self.stage_metadata("framesPerSecond")
            .ok()
            .flatten()
            .as_ref()
            .and_then(scalar)
            .unwrap_or(fallback)
    }
}

impl StageMetadata {
    /// The frames the stage asks for: one per `1 / framesPerSecond` seconds from
    /// `startTimeCode` to `endTimeCode` (both included).
    pub fn frame_times(&self) -> Option<FrameTimes> {
        let (start, end) = self.time_code_range?;
        if start > end {
            // An empty range: the stage at time code 0, as usdview shows it.
            return Some(FrameTimes {
                start: 0.0,
                end: 0.0,
                frames: 1,
            });
        }
        let frames = self.stage_frames(start, end).min(MAX_STAGE_FRAMES) as u32 + 1;
        Some(FrameTimes {
            start: (start / self.time_codes_per_second) as f32,
            end: (end / self.time_codes_per_second) as f32,
            frames,
        })
    }

    /// The frames (less one) a time code range asks for at `framesPerSecond`.
    fn stage_frames(&self, start: f64, end: f64) -> f64 {
        let seconds = (end - start) / self.time_codes_per_second;
        (seconds * self.frames_per_second).round().max(0.0)
    }

    /// A note when the time code range asks for more frames than a stage's own range gives.
    fn frame_limit_note(&self) -> Option<String> {
        let (start, end) = self.time_code_range?;
        (self.stage_frames(start, end) > MAX_STAGE_FRAMES).then(|| {
            format!(
                "the time code range {start}..{end} asks for more than {} frames at {} frames per second; \
                 the default range is {} frames over the same time (use --frames and --fps to choose)",
                MAX_STAGE_FRAMES + 1.0,
                self.frames_per_second,
                MAX_STAGE_FRAMES + 1.0
            )
        })
    }

    /// The root transform that turns the stage Y-up and into metres (identity when it is
    /// already both).
    fn root_matrix(&self) -> Option<Mat4> {
        let s = self.meters_per_unit as f32;
        let z_up = self.up_axis == "Z";
        if !z_up && self.meters_per_unit == 1.0 {
            return None;
        }
        // Z-up to Y-up: a quarter turn about X taking +Z to +Y (exact zeros and ones).
        let rotation = if z_up {
            Mat4::from_cols_array(&[
                1.0, 0.0, 0.0, 0.0, //
                0.0, 0.0, -1.0, 0.0, //
                0.0, 1.0, 0.0, 0.0, //
                0.0, 0.0, 0.0, 1.0,
            ])
        } else {
            Mat4::IDENTITY
        };
        Some(Mat4::from_scale(Vec3::splat(s)) * rotation)
    }
}

/// Everything built so far while walking the stage.
pub(super) struct Builder<'s> {
    reader: Reader<'s>,
    nodes: Vec<NodeDesc>,
    roots: Vec<usize>,
    /// The node everything hangs from (the axis/unit root), when there is one.
    stage_root: Option<usize>,
    meshes: Vec<MeshDesc>,
    cameras: Vec<CameraDesc>,
    lights: Vec<LightDesc>,
    skins: Vec<SkinDesc>,
    channels: Vec<ChannelDesc>,
    materials: material::Materials,
    ignored: material::Ignored,
    background: Vec3,
    notes: Vec<String>,
    meters_per_unit: f64,
    /// Prim path -> its own (innermost) node.
    node_of: HashMap<String, usize>,
    skeletons: HashMap<String, skel::Skeleton>,
    /// Meshes with a skeleton binding, bound once every skeleton is known.
    skinned: Vec<skel::PendingMesh>,
}

fn load_stage(path: &Path) -> Result<SceneDesc, String> {
    let (stage, text_layers) = open(path)?;
    let metadata = read_metadata(&stage)?;
    let mut b = Builder {
        reader: Reader {
            stage: &stage,
            time_codes_per_second: metadata.time_codes_per_second,
        },
        nodes: Vec::new(),
        roots: Vec::new(),
        stage_root: None,
        meshes: Vec::new(),
        cameras: Vec::new(),
        lights: Vec::new(),
        skins: Vec::new(),
        channels: Vec::new(),
        materials: material::Materials::default(),
        ignored: material::Ignored::default(),
        background: BACKGROUND,
        notes: Vec::new(),
        meters_per_unit: metadata.meters_per_unit,
        node_of: HashMap::new(),
        skeletons: HashMap::new(),
        skinned: Vec::new(),
    };
    if let Some(matrix) = metadata.root_matrix() {
        let root = b.add_node(None, "stage (upAxis, metersPerUnit)".into());
        b.nodes[root].matrix = Some(matrix);
        b.nodes[root].local = xform::decompose(&matrix);
        b.stage_root = Some(root);
    }
    check_prim_names(&stage)?;
    b.notes.extend(metadata.notes.iter().cloned());
    b.notes.extend(metadata.frame_limit_note());
    let mut paths = Vec::new();
    stage
        .traverse(TRAVERSAL, |p| paths.push(p.clone()))
        .map_err(|e| format!("cannot traverse the stage: {e:#}"))?;
    check_composition(&stage, &text_layers)?;
    note_unexpanded_nested_instances(&stage, &paths, &mut b.notes)?;
    // The traversal is depth first, parents before children, so a skipped prim's subtree
    // is the run of paths right after it: one prefix at a time is enough.
    let mut skipped: Option<String> = None;
    for path in &paths {
        let name = path.as_str();
        if skipped.as_deref().is_some_and(|s| is_under(name, s)) {
            continue;
        }
        skipped = None;
        let prim = stage.prim(path.clone());
        if !b.visit(&prim)? {
            skipped = Some(name.to_string());
        }
    }
    check_composition(&stage, &text_layers)?;
    skel::bind_meshes(&mut b)?;
    b.ignored.notes(&mut b.notes);
    let Builder {
        nodes,
        roots,
        meshes,
        cameras,
        lights,
        skins,
        channels,
        materials,
        background,
        mut notes,
        ..
    } = b;
    dedupe_notes(&mut notes);
    let animations = if channels.is_empty() {
        Vec::new()
    } else {
        vec![AnimationDesc {
            name: "stage".into(),
            channels,
        }]
    };
    Ok(SceneDesc {
        source: path.to_path_buf(),
        meshes,
        nodes,
        roots,
        materials: materials.materials,
        textures: materials.textures,
        cameras,
        lights,
        animations,
        skins,
        background,
        ambient: None,
        frame_times: metadata.frame_times(),
        notes,
    })
}

/// The prims the loader reads: active, loaded, defined and not abstract, instance proxies
/// included (each instance's prims are loaded as its own).
const TRAVERSAL: usd::PrimPredicate = usd::PrimPredicate::DEFAULT_PROXIES;

/// Refuses a prim whose name cannot name a prim: USD itself refuses them, and openusd's
/// traversal would never end on two of them (a root prim named `""` or any prim named `.`
/// makes a child path equal to its parent, which it visits again). A walk over the composed
/// child names before the traversal, entering the prims the traversal enters (those its
/// predicate does not prune): entering others would compose what the stage never uses
/// (an unloaded payload, a `class`), and their composition errors would fail the stage.
/// Every listed name is checked, entered or not, as the traversal lists them all.
fn check_prim_names(stage: &usd::Stage) -> Result<(), String> {
    let root = openusd::sdf::Path::abs_root();
    let mut stack = vec![root.clone()];
    while let Some(parent) = stack.pop() {
        let names = if parent == root {
            stage.root_prims()
        } else {
            stage.prim(parent.clone()).child_names()
        }
        .map_err(|e| format!("{}: {e:#}", parent.as_str()))?;
        for name in names {
            let name = name.as_str();
            if !is_prim_name(name) {
                let below = if parent == root {
                    "the root of the stage".to_string()
                } else {
                    parent.as_str().to_string()
                };
                return Err(format!(
                    "a prim under {below} is named {name:?}, which is not a prim name \
                     (a letter or '_', then letters, digits or '_')"
                ));
            }
            let child = parent
                .append_path(name)
                .map_err(|e| format!("{}/{name}: {e:#}", parent.as_str()))?;
            let status = stage
                .prim_status(child.clone())
                .map_err(|e| format!("{}: {e:#}", child.as_str()))?;
            if TRAVERSAL.matches(status) {
                stack.push(child);
            }
        }
    }
    Ok(())
}

/// openusd's traversal does not enter an instance that lies inside another instance (the
/// inner prototype's prims never appear), so their geometry would be missing without a
/// word. Such an inner instance with nothing below it in the traversal is noted.
fn note_unexpanded_nested_instances(
    stage: &usd::Stage,
    paths: &[openusd::sdf::Path],
    notes: &mut Vec<String>,
) -> Result<(), String> {
    // The instances enclosing the current path (the traversal is depth first).
    let mut enclosing: Vec<&str> = Vec::new();
    for (i, path) in paths.iter().enumerate() {
        let name = path.as_str();
        while enclosing.last().is_some_and(|outer| !is_under(name, outer)) {
            enclosing.pop();
        }
        let status = stage
            .prim_status(path.clone())
            .map_err(|e| format!("{name}: {e:#}"))?;
        if !status.contains(usd::PrimStatus::INSTANCE) {
            continue;
        }
        let entered = paths
            .get(i + 1)
            .is_some_and(|next| is_under(next.as_str(), name));
        if !enclosing.is_empty() && !entered {
            notes.push(format!(
                "{name}: an instance inside an instance; nested instances are not expanded, \
                 so what its prototype holds is not drawn"
            ));
        }
        enclosing.push(name);
    }
    Ok(())
}

/// A USD identifier: a letter (any script, as USD's UTF-8 identifiers allow) or `_`, then
/// letters, digits or `_`.
fn is_prim_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c == '_' || c.is_alphabetic())
        && chars.all(|c| c == '_' || c.is_alphanumeric())
}

/// A missing layer, a composition cycle and the like: openusd reports them as recoverable
/// composition errors; the renderer cannot draw a stage with holes, so they are errors.
fn check_composition(stage: &usd::Stage, text_layers: &guard::TextLayers) -> Result<(), String> {
    match stage.composition_errors().first() {
        None => Ok(()),
        Some(e) => Err(format!(
            "composition failed: {}",
            text_layers.place(&e.to_string())
        )),
    }
}

/// Whether `path` is `prefix` or below it.
fn is_under(path: &str, prefix: &str) -> bool {
    path.strip_prefix(prefix)
        .is_some_and(|rest| rest.is_empty() || rest.starts_with('/'))
}

/// Identical notes once, and at most [`MAX_NOTES`].
fn dedupe_notes(notes: &mut Vec<String>) {
    let mut seen = std::collections::HashSet::new();
    notes.retain(|n| seen.insert(n.clone()));
    if notes.len() > MAX_NOTES {
        let more = notes.len() - MAX_NOTES;
        notes.truncate(MAX_NOTES);
        notes.push(format!("... and {more} more notes"));
    }
}

/// What a prim type is to the loader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PrimKind {
    /// A transformable group (or a transformable prim with nothing else the loader reads).
    Xform,
    /// A group without a transform of its own (`Scope`, untyped prims).
    Group,
    Mesh,
    Camera,
    Light,
    Skeleton,
    /// Read where it is used (materials, shaders, animations, blend shapes, subsets):
    /// its subtree makes no nodes.
    Referenced,
    /// A geometry type the renderer does not draw (noted); its subtree is skipped.
    Unsupported,
}

fn prim_kind(type_name: &str) -> PrimKind {
    match type_name {
        "Xform" | "SkelRoot" => PrimKind::Xform,
        "" | "Scope" => PrimKind::Group,
        "Mesh" => PrimKind::Mesh,
        "Camera" => PrimKind::Camera,
        "DistantLight" | "SphereLight" | "DiskLight" | "RectLight" | "CylinderLight"
        | "DomeLight" | "DomeLight_1" | "GeometryLight" | "PortalLight" => PrimKind::Light,
        "Skeleton" => PrimKind::Skeleton,
        "Material" | "Shader" | "NodeGraph" | "SkelAnimation" | "BlendShape" | "GeomSubset"
        | "RenderSettings" | "RenderProduct" | "RenderVar" | "RenderPass" | "Backdrop" => {
            PrimKind::Referenced
        }
        "Cube" | "Sphere" | "Cylinder" | "Cylinder_1" | "Cone" | "Capsule" | "Capsule_1"
        | "Plane" | "Points" | "BasisCurves" | "NurbsCurves" | "HermiteCurves" | "NurbsPatch"
        | "TetMesh" | "PointInstancer" | "Volume" => PrimKind::Unsupported,
        // Unknown (custom) schemas group what is below them.
        _ => PrimKind::Group,
    }
}

impl Builder<'_> {
    /// Adds a node under `parent` (or as a root); returns its index.
    fn add_node(&mut self, parent: Option<usize>, name: String) -> usize {
        let i = self.nodes.len();
        self.nodes.push(NodeDesc {
            name,
            local: Trs::default(),
            ..Default::default()
        });
        match parent {
            Some(p) => self.nodes[p].children.push(i),
            None => self.roots.push(i),
        }
        i
    }

    /// Handles one prim (its parent was handled before it); returns whether its children
    /// are to be visited.
    fn visit(&mut self, prim: &Prim) -> Result<bool, String> {
        let path = prim.path().as_str().to_string();
        let type_name = prim
            .type_name()
            .map_err(|e| format!("{path}: {e:#}"))?
            .map(|t| t.as_str().to_string())
            .unwrap_or_default();
        let kind = prim_kind(&type_name);
        if kind == PrimKind::Referenced {
            return Ok(false);
        }
        // A skeleton is never drawn, only read by the meshes bound to it: exporters often
        // mark it `guide` (or hide it), and its meshes must still be skinned.
        if kind != PrimKind::Skeleton && !self.rendered(prim)? {
            return Ok(false);
        }
        if kind == PrimKind::Unsupported {
            self.notes.push(format!(
                "{path}: {type_name} prims are not drawn (only Mesh geometry is); skipped"
            ));
            return Ok(false);
        }
        let parent_node = prim
            .path()
            .parent()
            .and_then(|p| self.node_of.get(p.as_str()).copied())
            .or(self.stage_root);
        let chain = if kind == PrimKind::Group {
            xform::Chain::default()
        } else {
            xform::chain(&self.reader, prim, &mut self.notes)?
        };
        let mut parent = if chain.resets {
            self.stage_root
        } else {
            parent_node
        };
        let count = chain.nodes.len();
        for (k, link) in chain.nodes.into_iter().enumerate() {
            let name = if k + 1 == count {
                path.clone()
            } else {
                format!("{path} (xformOp {})", k + 1)
            };
            let node = self.add_node(parent, name);
            self.nodes[node].local = link.local;
            self.nodes[node].matrix = link.matrix;
            for track in link.tracks {
                self.channels.push(ChannelDesc {
                    node,
                    target: track.target,
                    interpolation: Interpolation::Linear,
                    times: track.times,
                    values: track.values,
                    components: track.components,
                });
            }
            parent = Some(node);
        }
        let node = match (count, parent) {
            (0, _) | (_, None) => self.add_node(parent, path.clone()),
            (_, Some(node)) => node,
        };
        self.node_of.insert(path, node);
        match kind {
            PrimKind::Mesh => self.add_mesh(prim, node)?,
            PrimKind::Camera => camera::add(self, prim, node)?,
            PrimKind::Light => lights::add(self, prim, node)?,
            PrimKind::Skeleton => skel::add_skeleton(self, prim, node)?,
            _ => {}
        }
        Ok(true)
    }

    /// Whether the prim is rendered: not `invisible`, and of `default` or `render` purpose.
    fn rendered(&mut self, prim: &Prim) -> Result<bool, String> {
        let path = prim.path().as_str();
        let visibility = self.reader.static_value(prim, "visibility")?;
        if self.reader.sample_count(prim, "visibility")? > 1 {
            self.notes.push(format!(
                "{path}: animated visibility is not supported; its first value holds"
            ));
        }
        if visibility.as_ref().and_then(token).as_deref() == Some("invisible") {
            return Ok(false);
        }
        let purpose = self.reader.default_value(prim, "purpose")?;
        Ok(!matches!(
            purpose.as_ref().and_then(token).as_deref(),
            Some("guide") | Some("proxy")
        ))
    }

    fn add_mesh(&mut self, prim: &Prim, node: usize) -> Result<(), String> {
        let reader = &self.reader;
        let path = prim.path().as_str().to_string();
        let topology = mesh::topology(reader, prim, &mut self.notes)?;
        let double_sided = reader
            .default_value(prim, "doubleSided")?
            .as_ref()
            .and_then(scalar)
            .is_some_and(|x| x != 0.0);
        let normals_vary = mesh::normals_vary(reader, prim)?;
        let groups = self.material_groups(prim, &topology, double_sided)?;
        let mut primitives = Vec::new();
        let mut materials = Vec::new();
        for (faces, bound) in &groups {
            let uv = bound.as_ref().and_then(|b| b.1.clone());
            let transform = |st| uv.as_ref().map_or(st, |u: &material::UvRead| u.apply(st));
            let wanted = mesh::Wanted {
                uv_primvar: uv.as_ref().map(|u| u.primvar.as_str()),
                uv_transform: &transform,
            };
            let p = mesh::triangulate(
                &self.reader,
                prim,
                &topology,
                faces.as_deref(),
                &wanted,
                normals_vary,
                &mut self.notes,
            )?;
            if p.indices.is_empty() {
                continue;
            }
            // A textured material whose uvs are missing renders untextured.
            let material = match bound {
                Some((index, Some(_))) if p.uvs.is_none() => Some(self.untextured_copy(*index)),
                Some((index, _)) => Some(*index),
                None => None,
            };
            primitives.push(p);
            materials.push(material);
        }
        if primitives.is_empty() {
            return Ok(());
        }
        let cache = mesh::point_cache(&self.reader, prim, &topology, &primitives, &mut self.notes)?;
        let bound_to_skeleton = skel::is_bound(self, prim)?;
        let mut descs: Vec<PrimitiveDesc> = primitives
            .iter()
            .zip(&materials)
            .map(|(p, &material)| PrimitiveDesc {
                positions: p.positions.clone(),
                normals: p.normals.clone(),
                uvs: p.uvs.clone(),
                indices: p.indices.clone(),
                material,
                ..Default::default()
            })
            .collect();
        let mesh_index = self.meshes.len();
        let mut weights = Vec::new();
        match cache {
            Some(_) if bound_to_skeleton => self.notes.push(format!(
                "{path}: time-sampled points on a skinned mesh are not supported: skinned from its first sample"
            )),
            Some((times, caches)) => {
                for (desc, cache) in descs.iter_mut().zip(caches) {
                    desc.point_cache = Some(cache);
                }
                weights = vec![0.0];
                let values = (0..times.len()).map(|k| k as f32).collect();
                self.channels.push(ChannelDesc {
                    node,
                    target: ChannelTarget::Weights,
                    interpolation: Interpolation::Linear,
                    times,
                    values,
                    components: 1,
                });
            }
            None => {}
        }
        self.meshes.push(MeshDesc {
            name: path.clone(),
            primitives: descs,
            weights,
        });
        self.nodes[node].mesh = Some(mesh_index);
        if bound_to_skeleton {
            self.skinned.push(skel::PendingMesh {
                prim: prim.clone(),
                mesh: mesh_index,
                node,
                point_of_vertex: primitives.into_iter().map(|p| p.point_of_vertex).collect(),
            });
        }
        Ok(())
    }

    /// The faces of each material group (`None`: all faces) and its material (index and
    /// uv reading), from `materialBind` subsets and the mesh's own binding.
    #[allow(clippy::type_complexity)]
    fn material_groups(
        &mut self,
        prim: &Prim,
        topology: &mesh::Topology,
        double_sided: bool,
    ) -> Result<Vec<(Option<Vec<bool>>, Option<(usize, Option<material::UvRead>)>)>, String> {
        let path = prim.path().as_str().to_string();
        let faces = topology.face_count();
        let mut covered = vec![false; faces];
        let mut groups = Vec::new();
        let children = prim.children().map_err(|e| format!("{path}: {e:#}"))?;
        for child in children {
            let is_subset = child
                .type_name()
                .ok()
                .flatten()
                .is_some_and(|t| t.as_str() == "GeomSubset");
            if !is_subset {
                continue;
            }
            let family = self
                .reader
                .default_value(&child, "familyName")?
                .as_ref()
                .and_then(token);
            let element = self
                .reader
                .default_value(&child, "elementType")?
                .as_ref()
                .and_then(token);
            if family.as_deref() != Some("materialBind")
                || element.as_deref().is_some_and(|e| e != "face")
            {
                continue;
            }
            let indices = self
                .reader
                .static_value(&child, "indices")?
                .as_ref()
                .and_then(values::ints)
                .unwrap_or_default();
            let mut mask = vec![false; faces];
            for (k, &f) in indices.iter().enumerate() {
                let slot = usize::try_from(f)
                    .ok()
                    .and_then(|f| mask.get_mut(f))
                    .ok_or_else(|| {
                        format!(
                            "{}: indices[{k}] = {f} is outside the mesh's {faces} faces",
                            child.path().as_str()
                        )
                    })?;
                *slot = true;
            }
            for (c, &m) in covered.iter_mut().zip(&mask) {
                *c |= m;
            }
            let bound = self.material_of(&child, prim, double_sided)?;
            groups.push((Some(mask), bound));
        }
        let rest: Vec<bool> = covered.iter().map(|&c| !c).collect();
        if groups.is_empty() {
            let bound = self.material_of(prim, prim, double_sided)?;
            return Ok(vec![(None, bound)]);
        }
        if rest.iter().any(|&r| r) {
            let bound = self.material_of(prim, prim, double_sided)?;
            groups.push((Some(rest), bound));
        }
        Ok(groups)
    }

    /// The material bound to `prim` (a mesh or subset), else one of the mesh's
    /// `displayColor`, else the default (a plain double-sided one when needed).
    fn material_of(
        &mut self,
        prim: &Prim,
        mesh: &Prim,
        double_sided: bool,
    ) -> Result<Option<(usize, Option<material::UvRead>)>, String> {
        if let Some(bound) =
            self.materials
                .bound(&self.reader, prim, double_sided, &mut self.ignored)?
        {
            if bound.reads_display_color
                && let Some(color) = mesh::display_color(&self.reader, mesh, &mut self.notes)?
            {
                let index = self.materials.recoloured(bound.index, color);
                return Ok(Some((index, bound.uv)));
            }
            return Ok(Some((bound.index, bound.uv)));
        }
        if let Some(color) = mesh::display_color(&self.reader, mesh, &mut self.notes)? {
            return Ok(Some((
                self.materials.display_color(color, double_sided),
                None,
            )));
        }
        Ok(double_sided.then(|| (self.materials.plain(true), None)))
    }

    /// A copy of material `index` without its texture (for a mesh lacking the uvs).
    fn untextured_copy(&mut self, index: usize) -> usize {
        let mut copy = self.materials.materials[index].clone();
        copy.base_color_texture = None;
        copy.name = format!("{} (untextured)", copy.name);
        self.materials.materials.push(copy);
        self.materials.materials.len() - 1
    }
}
