//! OBJ + MTL + PNG writer.
//!
//! Conventions: positions and normals are world space (+Y up, -Z forward, as glTF); one
//! vertex, texture coordinate and normal per triangle corner (no sharing), one `usemtl`
//! group per material. OBJ's `vt` origin is the bottom-left of the image while mipray's
//! (glTF's) is the top-left, so `vt` holds `u, 1 - v` (computed in f64, exact for the
//! coordinates a frame holds); `scene::obj` flips it back. Numbers are printed in the
//! shortest form that parses back to the same f32.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use image::{DynamicImage, ImageFormat, RgbImage, RgbaImage};

use super::{ExportError, io_error, write_atomically};
use crate::colour::encode_srgb8;
use crate::frame::Renderer;
use crate::frame::appearance::material_descs;
use crate::scene::MaterialDesc;
use crate::texture::{MipFilter, Texture, WrapMode};

/// The shared material library every exported OBJ frame references.
pub const MTL_FILE: &str = "materials.mtl";

/// `textures/<index>_<name>.png`: the name is the texture's own, reduced to
/// `[A-Za-z0-9._-]` without an image extension.
pub fn texture_file_name(index: usize, texture: &Texture) -> String {
    let base = Path::new(&texture.name)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let stem = match base.rsplit_once('.') {
        Some((stem, ext))
            if ["png", "jpg", "jpeg", "ppm", "pnm", "pgm"]
                .contains(&ext.to_ascii_lowercase().as_str()) =>
        {
            stem.to_string()
        }
        _ => base,
    };
    let mut clean: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if clean.is_empty() {
        clean = "texture".into();
    }
    format!("textures/{index}_{clean}.png")
}

/// Name of material `i` in the MTL: `<i>_<name>` with whitespace replaced (`usemtl` reads
/// the rest of its line, and the index keeps names unique).
pub(crate) fn material_name(i: usize, material: &MaterialDesc) -> String {
    let clean: String = material
        .name
        .chars()
        .map(|c| if c.is_whitespace() { '_' } else { c })
        .collect();
    if clean.is_empty() {
        format!("{i}")
    } else {
        format!("{i}_{clean}")
    }
}

/// Writes each base-colour texture the materials use once (level 0, 8-bit sRGB; RGB when
/// every alpha is 1, RGBA otherwise). Returns texture index -> relative file name.
pub(crate) fn write_textures(
    renderer: &Renderer,
    dir: &Path,
) -> Result<BTreeMap<usize, String>, ExportError> {
    let scene = renderer.scene();
    let mut names = BTreeMap::new();
    for material in renderer.materials() {
        let Some(index) = material.base_color_texture else {
            continue;
        };
        let Some(texture) = scene.textures.get(index) else {
            continue;
        };
        if names.contains_key(&index) {
            continue;
        }
        let name = texture_file_name(index, texture);
        let path = dir.join(&name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io_error(parent))?;
        }
        let level = &texture.pyramid.levels[0];
        let opaque = level.texels().all(|t| t.w == 1.0);
        let image = if opaque {
            let bytes = level
                .texels()
                .flat_map(|t| [t.x, t.y, t.z].map(encode_srgb8))
                .collect();
            DynamicImage::ImageRgb8(
                RgbImage::from_raw(level.width, level.height, bytes).expect("level size"),
            )
        } else {
            let alpha = |a: f32| (a.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            let bytes = level
                .texels()
                .flat_map(|t| {
                    [
                        encode_srgb8(t.x),
                        encode_srgb8(t.y),
                        encode_srgb8(t.z),
                        alpha(t.w),
                    ]
                })
                .collect();
            DynamicImage::ImageRgba8(
                RgbaImage::from_raw(level.width, level.height, bytes).expect("level size"),
            )
        };
        let mut encoded = Vec::new();
        image
            .write_to(&mut std::io::Cursor::new(&mut encoded), ImageFormat::Png)
            .map_err(|source| ExportError::Encode {
                path: path.clone(),
                source,
            })?;
        write_atomically(&path, |w| w.write_all(&encoded))?;
        names.insert(index, name);
    }
    Ok(names)
}

fn wrap_name(mode: WrapMode) -> &'static str {
    match mode {
        WrapMode::Repeat => "repeat",
        WrapMode::ClampToEdge => "clamp",
        WrapMode::MirroredRepeat => "mirrored",
    }
}

/// Writes `materials.mtl`: one `newmtl` per entry of `Renderer::materials()`, described by
/// `frame::appearance::material_descs` (in order, so a re-load keeps the indices),
/// standard statements for other tools and `mipray_*` statements with the exact parameters.
pub(crate) fn write_mtl(
    renderer: &Renderer,
    dir: &Path,
    textures: &BTreeMap<usize, String>,
) -> Result<(), ExportError> {
    let scene = renderer.scene();
    let path = dir.join(MTL_FILE);
    write_atomically(&path, |w| {
        writeln!(w, "# mipray export: materials indexed as the renderer's")?;
        writeln!(
            w,
            "# Kd is linear RGB; mipray_* statements carry the exact parameters (other tools ignore them)"
        )?;
        for (i, m) in material_descs(scene).iter().enumerate() {
            let [r, g, b] = m.base_color.to_array();
            writeln!(w, "\nnewmtl {}", material_name(i, m))?;
            if !m.name.is_empty() {
                writeln!(w, "mipray_name {}", m.name)?;
            }
            writeln!(w, "Kd {r} {g} {b}")?;
            writeln!(w, "Ks {0} {0} {0}", m.specular)?;
            writeln!(w, "Ns {}", m.shininess)?;
            writeln!(w, "Ni {}", m.ior)?;
            write_transmission(w, m)?;
            let illum = if m.transmission > 0.0 {
                7
            } else if m.reflectance > 0.0 {
                3
            } else {
                2
            };
            writeln!(w, "illum {illum}")?;
            if let Some((index, file)) = m
                .base_color_texture
                .and_then(|t| textures.get(&t).map(|f| (t, f)))
            {
                let sampler = scene.textures[index].sampler;
                let clamp = sampler.wrap_s == WrapMode::ClampToEdge
                    && sampler.wrap_t == WrapMode::ClampToEdge;
                let option = if clamp { "-clamp on " } else { "" };
                writeln!(w, "map_Kd {option}{file}")?;
                writeln!(
                    w,
                    "mipray_wrap {} {}",
                    wrap_name(sampler.wrap_s),
                    wrap_name(sampler.wrap_t)
                )?;
                if sampler.mip != MipFilter::default() {
                    writeln!(w, "mipray_mip {}", sampler.mip.name())?;
                }
                writeln!(w, "mipray_texture_name {}", scene.textures[index].name)?;
            }
            writeln!(w, "mipray_reflectance {}", m.reflectance)?;
            writeln!(w, "mipray_specular {}", m.specular)?;
            writeln!(w, "mipray_transmission {}", m.transmission)?;
            writeln!(w, "mipray_double_sided {}", u8::from(m.double_sided))?;
            if m.shading == crate::scene::Shading::Nff {
                writeln!(w, "mipray_shading nff")?;
                if let Some(a) = m.ambient {
                    writeln!(w, "mipray_ambient {} {} {}", a.x, a.y, a.z)?;
                }
            }
        }
        Ok(())
    })
}

/// The transmission statements. mipray's transmission is refraction, not dissolve: the
/// surface stays fully there (`d 1`; Blender's importer reads `d` as alpha, so `d 0` made
/// glass invisible) and passes light through its transmission filter `Tf`, which Blender
/// 3.4's importer (*File > Import > Wavefront (.obj)*) turns into the Principled BSDF's
/// Transmission. Its PBR extension statements `Pm 0` and `Pr 0` keep glass from becoming
/// metal (`illum 7` implies reflection, i.e. metallic 1) and make it smooth, as mipray's
/// refraction is.
fn write_transmission(w: &mut impl Write, m: &MaterialDesc) -> std::io::Result<()> {
    writeln!(w, "d 1")?;
    if m.transmission > 0.0 {
        writeln!(w, "Tf {0} {0} {0}", m.transmission)?;
        writeln!(w, "Pm 0")?;
        writeln!(w, "Pr 0")?;
    }
    Ok(())
}

/// The slots of a frame's triangles in the order the OBJ writes them: grouped by material
/// (in material order), then by source triangle. Source order, not slot order, so the file
/// does not depend on how the tree was built (a frame exported after others, or alone,
/// writes the same file). Triangles whose material index is not below `material_count` are
/// not written (none are: every slot names one of the scene's materials or the default one).
pub(crate) fn slots_in_face_order(
    material_of_slot: &[u32],
    source_of_slot: &[u32],
    material_count: usize,
) -> Vec<u32> {
    let mut slots: Vec<u32> = (0..material_of_slot.len() as u32)
        .filter(|&s| (material_of_slot[s as usize] as usize) < material_count)
        .collect();
    slots.sort_unstable_by_key(|&s| (material_of_slot[s as usize], source_of_slot[s as usize]));
    slots
}

/// Streams the frame's triangles into `path`, grouped by material.
pub(crate) fn write_obj(
    renderer: &Renderer,
    path: &Path,
    frame: u32,
    time_s: f32,
) -> Result<(), ExportError> {
    let t = renderer.triangles();
    let materials = material_descs(renderer.scene());
    write_atomically(path, |w| {
        writeln!(
            w,
            "# mipray export: frame {frame}, time {time_s} s, {} triangles",
            t.len()
        )?;
        writeln!(
            w,
            "# world space, +Y up, -Z forward (glTF); per-corner vertices; vt = (u, 1 - v) of mipray's top-left-origin (u, v)"
        )?;
        writeln!(w, "# camera and lights: camera_{frame:04}.json")?;
        writeln!(w, "mtllib {MTL_FILE}")?;
        writeln!(w, "o frame_{frame:04}")?;
        let mut next = 1usize;
        let mut current = None;
        for slot in slots_in_face_order(&t.material, &t.source, materials.len()) {
            let m = t.material[slot as usize] as usize;
            if current != Some(m) {
                writeln!(w, "usemtl {}", material_name(m, &materials[m]))?;
                current = Some(m);
            }
            let slot = slot as usize;
            for p in &renderer.accel().triangle(slot as u32) {
                writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
            }
            for uv in &t.uvs[slot] {
                writeln!(w, "vt {} {}", uv.x, 1.0 - uv.y as f64)?;
            }
            for n in &renderer.slot_normals(slot) {
                writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
            }
            let (a, b, c) = (next, next + 1, next + 2);
            writeln!(w, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?;
            next += 3;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transmission_lines(transmission: f32) -> String {
        let material = MaterialDesc {
            transmission,
            ..MaterialDesc::default()
        };
        let mut out = Vec::new();
        write_transmission(&mut out, &material).unwrap();
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn glass_is_opaque_to_dissolve_and_transmits_through_tf() {
        assert_eq!(transmission_lines(1.0), "d 1\nTf 1 1 1\nPm 0\nPr 0\n");
        assert_eq!(
            transmission_lines(0.25),
            "d 1\nTf 0.25 0.25 0.25\nPm 0\nPr 0\n"
        );
        assert_eq!(transmission_lines(0.0), "d 1\n");
    }
}
