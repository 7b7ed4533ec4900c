//! `mipray info SCENE`: what a scene contains, and how its triangles move.

use anyhow::Result;
use clap::Args;

use super::scene::{load_scene, resolve_scene};
use crate::frame::FrameClock;
use crate::scene::SceneDesc;

#[derive(Args, Debug, Clone)]
pub struct InfoArgs {
    /// A .gltf/.glb, .aff, .obj or .usda/.usdc/.usdz path, or the name of a scene in
    /// animations/ (e.g. `default`).
    pub scene: String,
}

/// `mipray info`.
pub fn info(args: &InfoArgs) -> Result<()> {
    let path = resolve_scene(&args.scene)?;
    let desc = load_scene(&path)?;
    print!("{}", describe(&desc));
    print!("{}", describe_layout(desc));
    if is_usd(&path) {
        print!("{}", describe_stage(&crate::scene::usd::metadata(&path)?));
    }
    Ok(())
}

fn is_usd(path: &std::path::Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    matches!(ext.as_deref(), Some("usda" | "usdc" | "usdz" | "usd"))
}

/// The USD stage metadata `mipray info` prints, and how the loader applied it.
pub fn describe_stage(m: &crate::scene::usd::StageMetadata) -> String {
    use std::fmt::Write;
    let authored = |a: bool| if a { "authored" } else { "USD's fallback" };
    let mut s = String::new();
    let _ = writeln!(
        s,
        "upAxis: {} ({}){}",
        m.up_axis,
        authored(m.up_axis_authored),
        if m.up_axis == "Z" {
            "; turned Y-up for rendering"
        } else {
            ""
        }
    );
    let _ = writeln!(
        s,
        "metersPerUnit: {} ({}){}",
        m.meters_per_unit,
        authored(m.meters_per_unit_authored),
        if m.meters_per_unit != 1.0 {
            "; scaled to metres for rendering"
        } else {
            ""
        }
    );
    let range = match m.time_code_range {
        Some((start, end)) => format!("startTimeCode {start}, endTimeCode {end}"),
        None => "no time code range authored".to_string(),
    };
    let _ = writeln!(
        s,
        "time codes: {} per second, {} frames per second, {range}",
        m.time_codes_per_second, m.frames_per_second
    );
    s
}

/// Drawn triangles by how they move (all clips playing).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct TriangleMotion {
    /// Under no animated node and not deforming. and not deforming.
    pub fixed: usize,
    /// Placed by a node that is animated or has an animated ancestor (rigid or scaled).
    pub animated: usize,
    /// Skinned or with morph targets.
    pub deforming: usize,
    /// Nodes targeted by a translation/rotation/scale channel.
    pub animated_nodes: usize,
}

impl TriangleMotion {
    pub fn of(scene: &SceneDesc) -> TriangleMotion {
        use crate::scene::ChannelTarget;
        let mut targeted = vec![false; scene.nodes.len()];
        for c in scene.animations.iter().flat_map(|a| &a.channels) {
            if c.target != ChannelTarget::Weights && c.node < targeted.len() {
                targeted[c.node] = true;
            }
        }
        let mut out = TriangleMotion {
            animated_nodes: targeted.iter().filter(|&&t| t).count(),
            ..Default::default()
        };
        let mut stack: Vec<(usize, bool)> = scene.roots.iter().map(|&r| (r, false)).collect();
        while let Some((i, parent_animated)) = stack.pop() {
            let node = &scene.nodes[i];
            let animated = parent_animated || targeted[i];
            if let Some(mesh) = node.mesh {
                for (p, primitive) in scene.meshes[mesh].primitives.iter().enumerate() {
                    let n = primitive.triangle_count();
                    if crate::anim::primitive_deforms(scene, i, mesh, p) {
                        out.deforming += n;
                    } else if animated {
                        out.animated += n;
                    } else {
                        out.fixed += n;
                    }
                }
            }
            stack.extend(node.children.iter().map(|&c| (c, animated)));
        }
        out
    }
}

/// Most mesh primitives `mipray info` lists one by one; more are summarised by decision.
const LAYOUT_LINES: usize = 24;

/// What `--bvh auto` (the default) decides for `scene` at the default render settings.
pub fn describe_layout(scene: SceneDesc) -> String {
    let settings = crate::frame::RenderSettings::default();
    let note = format!(
        "(at {}x{}, {} spp; the decision depends on the rays per frame)\n",
        settings.width, settings.height, settings.spp
    );
    let renderer = crate::frame::Renderer::new(scene, settings);
    renderer.layout().describe(LAYOUT_LINES) + &note
}

/// The text `mipray info` prints.
pub fn describe(scene: &SceneDesc) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let primitives: usize = scene.meshes.iter().map(|m| m.primitives.len()).sum();
    let _ = writeln!(s, "scene: {}", scene.source.display());
    let motion = TriangleMotion::of(scene);
    let _ = writeln!(
        s,
        "triangles: {} ({} static, {} moved by animated nodes, {} skinned or morphing)",
        scene.instanced_triangle_count(),
        motion.fixed,
        motion.animated,
        motion.deforming
    );
    let _ = writeln!(
        s,
        "meshes: {} ({primitives} primitives)",
        scene.meshes.len()
    );
    let tracks: usize = scene.animations.iter().map(|a| a.channels.len()).sum();
    let _ = writeln!(
        s,
        "nodes: {} ({} animated, {tracks} key tracks)",
        scene.nodes.len(),
        motion.animated_nodes
    );
    let _ = writeln!(s, "materials: {}", scene.materials.len());
    let _ = writeln!(s, "textures: {}", scene.textures.len());
    for t in &scene.textures {
        let (w, h) = t.pyramid.base_size();
        let _ = writeln!(
            s,
            "  {}: {w}x{h}, {} MIP levels, wrap {:?}/{:?}, MIP filter {}",
            t.name,
            t.pyramid.level_count(),
            t.sampler.wrap_s,
            t.sampler.wrap_t,
            t.sampler.mip.name()
        );
    }
    let clock = FrameClock::for_scene(scene, None);
    let frames = clock.default_frames(scene.duration());
    let (first, last) = (
        clock.time(frames.start),
        clock.time(frames.end.saturating_sub(1)),
    );
    let source = if scene.frame_times.is_some() {
        "the file's frame times"
    } else {
        "30 fps"
    };
    let _ = writeln!(
        s,
        "frames: {}..{} ({} frames, t = {first:.3} to {last:.3} s, {source})",
        frames.start,
        frames.end,
        frames.len()
    );
    let _ = writeln!(s, "animations: {}", scene.animations.len());
    for (i, a) in scene.animations.iter().enumerate() {
        let name = if a.name.is_empty() {
            format!("#{i}")
        } else {
            a.name.clone()
        };
        let _ = writeln!(
            s,
            "  {name}: {:.3} s, {} channels",
            a.duration(),
            a.channels.len()
        );
    }
    let _ = writeln!(s, "cameras: {}", scene.cameras.len());
    for c in &scene.cameras {
        let _ = writeln!(s, "  perspective, yfov {:.2} deg", c.yfov.to_degrees());
    }
    let _ = writeln!(s, "lights: {}", scene.lights.len());
    for l in &scene.lights {
        let _ = writeln!(
            s,
            "  {:?}, intensity {}, colour {:?}",
            l.kind,
            l.intensity,
            l.color.to_array()
        );
    }
    for note in &scene.notes {
        let _ = writeln!(s, "note: {note}");
    }
    s
}
