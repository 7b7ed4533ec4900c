//! `mipray export`: each frame's world-space triangles (OBJ or PLY), camera and lights.

// The options' doc comments are the command's `--help` text, where `<scene>` is a
// placeholder the user reads, not an HTML tag.
#![allow(rustdoc::invalid_html_tags)]

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use super::args::{LightArgs, SequenceArgs, TraceArgs, render_settings};
use super::scene::{naming_the_scene, open_scene};
use crate::accel::BvhLayout;
use crate::export::{ExportFormat, ExportOptions, export_frames};
use crate::frame::Renderer;

/// `mipray export` options (render's defaults: 640x360, 30 fps).
#[derive(Args, Debug, Clone)]
pub struct ExportArgs {
    #[command(flatten)]
    pub sequence: SequenceArgs,
    #[command(flatten)]
    pub lights: LightArgs,
    /// Mesh file format.
    #[arg(long, value_enum, default_value_t = ExportFormat::Obj)]
    pub format: ExportFormat,
    /// Output folder [default: out/<scene>/export/].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also render each frame and write every ray it traces to `rays_NNNN.bin` (primary,
    /// shadow, reflection and refraction rays with their answers; format in the guide).
    #[arg(long)]
    pub rays: bool,
    /// Maximum reflection/refraction depth of the rendered frames (with `--rays`).
    #[arg(long, default_value_t = 5)]
    pub max_depth: u32,
    /// Samples per pixel of the rendered frames (with `--rays`).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
}

/// `mipray export`: prepares each frame with render's settings and writes its triangles,
/// camera and lights (see `export`).
pub fn export(args: &ExportArgs) -> Result<()> {
    let trace = TraceArgs {
        lod_bias: 0.0,
        mip_filter: None,
        max_depth: args.max_depth,
    };
    let mut settings = render_settings(&args.sequence, &trace, args.lights.lights, args.spp)?;
    // Every triangle in one world-space tree: the files hold its triangles, and the ray
    // file's answers are its slots (under `auto` a mesh placed as an instance would be left
    // out of both). With `--rays`, the frames are traced as `render --bvh flat` traces them.
    settings.layout = BvhLayout::Flat;
    let scene = open_scene(&args.sequence)?;
    settings.animation = scene.animation;
    let options = ExportOptions {
        format: args.format,
        dir: args
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from("out").join(&scene.name).join("export")),
        frames: scene.frames.clone(),
        clock: scene.clock,
        rays: args.rays,
    };
    let mut renderer = Renderer::new(scene.desc, settings);
    let scene_path = scene.path;
    let done = export_frames(&mut renderer, &options, |f| {
        println!(
            "frame {:04}  t={:.3}s  {} triangles  {} deformed  -> {}",
            f.frame,
            f.time_s,
            f.triangles,
            f.deformed,
            f.mesh.display()
        );
        if let Some((path, count)) = &f.rays {
            println!("            {count} rays -> {}", path.display());
        }
    })
    .map_err(|e| naming_the_scene(e.into(), &scene_path))?;
    println!(
        "exported {} frame(s) into {}",
        done.len(),
        options.dir.display()
    );
    Ok(())
}
