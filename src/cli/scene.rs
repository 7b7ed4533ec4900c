//! From a scene argument to a loaded, clocked scene: the one path every command takes
//! (name lookup in animations/, loader by extension, notes, clip selection, frame range).

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

use super::args::{SequenceArgs, parse_frames};
use crate::anim::{AnimationSelection, select_animation};
use crate::frame::FrameClock;
use crate::scene::SceneDesc;
use crate::scene::sources::SourceFile;

pub use crate::scene::load as load_scene;

/// `error`, naming the scene file `path` when it stopped a frame (an animation that carries
/// a vertex out of single precision's range, ...): the loader names the file for what it
/// can check at load, and an error found at a later frame names it too.
pub fn naming_the_scene(error: anyhow::Error, path: &Path) -> anyhow::Error {
    let stopped_a_frame = error.chain().any(|cause| {
        cause.downcast_ref::<crate::frame::FrameError>().is_some()
            || matches!(
                cause.downcast_ref::<crate::export::ExportError>(),
                Some(crate::export::ExportError::Frame(_))
            )
    });
    if stopped_a_frame {
        error.context(path.display().to_string())
    } else {
        error
    }
}

/// A scene ready for the frame loop.
pub struct OpenedScene {
    pub path: PathBuf,
    /// The file's stem: names the default output folder.
    pub name: String,
    pub desc: SceneDesc,
    pub clock: FrameClock,
    /// The frames asked for (`--frames`), else the selected clips once.
    pub frames: Range<u32>,
    /// Which clips play (`--animation`).
    pub animation: AnimationSelection,
    /// Every file the load read, the scene file first, each with a digest of its bytes.
    pub sources: Vec<SourceFile>,
}

/// Resolves, loads and clocks the scene of `args`; prints the loader's notes on stderr.
pub fn open_scene(args: &SequenceArgs) -> Result<OpenedScene> {
    // Cheap argument errors first, before a possibly long load.
    let asked_frames = args.frames.as_deref().map(parse_frames).transpose()?;
    let path = resolve_scene(&args.scene)?;
    let (mut desc, sources) = crate::scene::load_with_sources(&path)?;
    if let Some(name) = &args.camera {
        select_camera(&mut desc, name)
            .map_err(|e| anyhow::anyhow!("{}: --camera {name}: {e}", path.display()))?;
    }
    for note in &desc.notes {
        eprintln!("note: {}: {note}", path.display());
    }
    let animation = match &args.animation {
        Some(spec) => select_animation(&desc, spec)
            .map_err(|e| anyhow::anyhow!("{}: --animation {spec}: {e}", path.display()))?,
        None => AnimationSelection::All,
    };
    let clock = FrameClock::for_scene(&desc, args.fps);
    let frames = asked_frames.unwrap_or_else(|| clock.default_frames(animation.duration(&desc)));
    if let (FrameClock::Fps(fps), Some(last)) = (&clock, frames.clone().next_back()) {
        // A frame's time is kept in single precision (the animation and the record read
        // it): an fps so small that a frame's time overflows it is refused, not rendered at
        // an infinite time.
        let time = clock.time(last);
        if !time.is_finite() {
            return Err(super::args::usage(format!(
                "--fps {fps}: frame {last} would be at {time} s, beyond single precision's range"
            )));
        }
    }
    Ok(OpenedScene {
        name: scene_name(&path),
        path,
        desc,
        clock,
        frames,
        animation,
        sources,
    })
}

/// Finds a scene: an existing file path, or `NAME` in `animations/` (as `.gltf` or `.glb`),
/// looked up in the current folder and then in the crate's own `animations/`.
pub fn resolve_scene(scene: &str) -> Result<PathBuf> {
    let direct = PathBuf::from(scene);
    if direct.is_file() {
        return Ok(direct);
    }
    if direct.is_dir() {
        bail!(
            "{scene}: is a folder; give a scene file (.gltf, .glb, .usd*, .aff or .obj) or a name in animations/"
        );
    }
    let folders = [
        PathBuf::from("animations"),
        Path::new(env!("CARGO_MANIFEST_DIR")).join("animations"),
    ];
    for folder in &folders {
        for ext in ["gltf", "glb"] {
            let candidate = folder.join(format!("{scene}.{ext}"));
            if candidate.is_file() {
                return Ok(candidate);
            }
        }
    }
    bail!(
        "{scene}: no such file, and no scene of that name in animations/ (looked in {})",
        folders
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// Makes the camera of the node named `name` the scene's camera: the frame loop looks
/// through the first camera in traversal order, so every other node's camera is dropped.
/// A node matches by its whole name or, for USD prim paths, by its last component.
///
/// # Errors
/// No camera node, or several, match; the message lists the camera nodes.
pub fn select_camera(desc: &mut SceneDesc, name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("--camera: give a camera node's name".into());
    }
    let cameras: Vec<usize> = desc
        .traversal_order()
        .into_iter()
        .filter(|&i| desc.nodes[i].camera.is_some())
        .collect();
    let matches = |node: &str| node == name || node.rsplit('/').next() == Some(name);
    let chosen: Vec<usize> = cameras
        .iter()
        .copied()
        .filter(|&i| matches(&desc.nodes[i].name))
        .collect();
    let listed = || {
        let names: Vec<String> = cameras
            .iter()
            .map(|&i| match desc.nodes[i].name.as_str() {
                "" => format!("an unnamed camera (node {i}), which no name can choose"),
                named => format!("{named:?}"),
            })
            .collect();
        if names.is_empty() {
            "the scene has no cameras".to_string()
        } else {
            format!("cameras: {}", names.join(", "))
        }
    };
    match chosen.as_slice() {
        [one] => {
            for &other in &cameras {
                if other != *one {
                    desc.nodes[other].camera = None;
                }
            }
            Ok(())
        }
        [] => Err(format!("no camera node is named {name:?} ({})", listed())),
        _ => Err(format!(
            "{} camera nodes match {name:?}; give the whole name ({})",
            chosen.len(),
            listed()
        )),
    }
}

fn scene_name(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::NodeDesc;

    /// Two camera nodes, "front" and one without a name.
    fn two_cameras() -> SceneDesc {
        let camera = |name: &str| NodeDesc {
            name: name.into(),
            camera: Some(0),
            ..NodeDesc::default()
        };
        SceneDesc {
            nodes: vec![camera("front"), camera("")],
            roots: vec![0, 1],
            ..SceneDesc::default()
        }
    }

    #[test]
    fn cameras_are_chosen_by_name_and_unnamed_ones_are_listed_as_such() {
        let mut desc = two_cameras();
        select_camera(&mut desc, "front").unwrap();
        assert_eq!(desc.nodes[0].camera, Some(0));
        assert_eq!(desc.nodes[1].camera, None);
        let mut desc = two_cameras();
        let error = select_camera(&mut desc, "back").unwrap_err();
        assert!(
            error.contains("\"front\"") && error.contains("unnamed camera (node 1)"),
            "{error}"
        );
        // An empty name would pick the unnamed camera by accident: refused.
        let error = select_camera(&mut two_cameras(), "").unwrap_err();
        assert!(error.contains("give a camera node's name"), "{error}");
    }
}
