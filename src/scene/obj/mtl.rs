//! MTL materials and their textures: what each statement means for mipray's material
//! (see the module comment of `scene::obj` for the list).

use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::{Vec3, Vec4};

use crate::scene::{MaterialDesc, SceneDesc};
use crate::texture::{
    ColorEncoding, MipFilter, MipPyramid, Sampler, Texture, WrapMode, decode_texels,
};

use super::validate::first_bad_mtl_line;
use super::{ObjError, error};

/// Parses a number of a `mipray_*` or standard statement.
pub(super) fn number(
    value: Option<&String>,
    key: &str,
    path: &Path,
    name: &str,
) -> Result<Option<f32>, ObjError> {
    let Some(value) = value else {
        return Ok(None);
    };
    let parsed: f64 = value.trim().parse().map_err(|_| {
        error(
            path,
            None,
            format!("material {name}: {key} {value}: not a number"),
        )
    })?;
    let x = parsed as f32;
    if !x.is_finite() {
        return Err(error(
            path,
            None,
            format!("material {name}: {key} {value}: out of range"),
        ));
    }
    Ok(Some(x))
}

/// The mean of a `Tf r g b` (or `Tf g`) transmission filter. The `Tf xyz ...` and
/// `Tf spectral ...` forms are not read (None: transmission falls back to `d` / `Tr`).
pub(super) fn transmission_filter(
    value: Option<&String>,
    path: &Path,
    name: &str,
) -> Result<Option<f32>, ObjError> {
    let Some(value) = value else {
        return Ok(None);
    };
    let words: Vec<&str> = value.split_whitespace().collect();
    if matches!(words.first(), Some(&"xyz") | Some(&"spectral")) {
        return Ok(None);
    }
    let numbers: Option<Vec<f64>> = words.iter().map(|w| w.parse().ok()).collect();
    match numbers.as_deref() {
        Some([g]) if g.is_finite() => Ok(Some(*g as f32)),
        Some([r, g, b]) if [r, g, b].iter().all(|x| x.is_finite()) => {
            Ok(Some(((r + g + b) / 3.0) as f32))
        }
        _ => Err(error(
            path,
            None,
            format!("material {name}: Tf {value}: expected r g b"),
        )),
    }
}

pub(super) fn wrap_mode(word: &str) -> Option<WrapMode> {
    match word {
        "repeat" => Some(WrapMode::Repeat),
        "clamp" => Some(WrapMode::ClampToEdge),
        "mirrored" => Some(WrapMode::MirroredRepeat),
        _ => None,
    }
}

/// Splits a `map_Kd` value into its options and the file name: whether `-clamp on` was
/// given, and the rest of the line after the options (file names may contain spaces).
pub(super) fn texture_statement(value: &str) -> (bool, String) {
    let mut rest = value.trim();
    let mut clamp = false;
    while let Some(option) = rest.strip_prefix('-') {
        let (name, after) = option
            .split_once(char::is_whitespace)
            .unwrap_or((option, ""));
        rest = after.trim_start();
        // How many arguments each option takes (at most; -o/-s/-t take 1 to 3 numbers).
        let max_args = match name {
            "o" | "s" | "t" => 3,
            "mm" => 2,
            _ => 1,
        };
        for k in 0..max_args {
            let (arg, after) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
            let numeric = arg.parse::<f64>().is_ok();
            if k > 0 && !numeric {
                break;
            }
            if name == "clamp" {
                clamp = arg == "on";
            }
            rest = after.trim_start();
        }
    }
    (clamp, rest.to_string())
}

pub(super) fn material(
    m: &tobj::Material,
    mtl_path: &Path,
    scene: &mut SceneDesc,
    textures: &mut Vec<(PathBuf, Sampler, usize)>,
) -> Result<MaterialDesc, ObjError> {
    let p = &m.unknown_param;
    let name = p
        .get("mipray_name")
        .cloned()
        .unwrap_or_else(|| m.name.clone());
    let num = |key: &str| number(p.get(key), key, mtl_path, &m.name);
    let f = |v: f64| v as f32;
    let defaults = MaterialDesc::default();
    let base_color = m
        .diffuse
        .map(|[r, g, b]| Vec3::new(f(r), f(g), f(b)))
        .unwrap_or(defaults.base_color);
    // Refraction is `Tf` (what `mipray export` writes, with `d 1`); files that mean
    // see-through by dissolve say `d` or `Tr`.
    let transmission = match num("mipray_transmission")? {
        Some(t) => t,
        None => match (
            transmission_filter(p.get("Tf"), mtl_path, &m.name)?,
            m.dissolve,
            num("Tr")?,
        ) {
            (Some(tf), _, _) => tf,
            (None, Some(d), _) => f(1.0 - d),
            (None, None, Some(tr)) => tr,
            (None, None, None) => 0.0,
        },
    };
    let specular = match num("mipray_specular")? {
        Some(s) => s,
        None => m
            .specular
            .map(|[r, g, b]| f((r + g + b) / 3.0))
            .unwrap_or(defaults.specular),
    };
    let double_sided = match p.get("mipray_double_sided").map(|s| s.trim()) {
        None => defaults.double_sided,
        Some("1") | Some("on") | Some("true") => true,
        Some("0") | Some("off") | Some("false") => false,
        Some(other) => {
            return Err(error(
                mtl_path,
                None,
                format!(
                    "material {}: mipray_double_sided {other}: expected 0 or 1",
                    m.name
                ),
            ));
        }
    };
    let base_color_texture = match &m.diffuse_texture {
        Some(statement) => Some(texture(m, statement, mtl_path, scene, textures)?),
        None => None,
    };
    // mipray_shading nff (+ mipray_ambient r g b): an AFF material exported as OBJ.
    let nff = p.get("mipray_shading").map(|s| s.trim()) == Some("nff");
    let ambient = p.get("mipray_ambient").and_then(|s| {
        let v: Vec<f32> = s
            .split_whitespace()
            .filter_map(|x| x.parse().ok())
            .collect();
        (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| Vec3::new(v[0], v[1], v[2]))
    });
    let desc = MaterialDesc {
        name,
        base_color,
        base_color_texture,
        reflectance: num("mipray_reflectance")?.unwrap_or(defaults.reflectance),
        transmission: transmission.clamp(0.0, 1.0),
        ior: m.optical_density.map(f).unwrap_or(defaults.ior),
        shininess: m.shininess.map(f).unwrap_or(defaults.shininess),
        specular,
        double_sided,
        ambient,
        shading: if nff {
            crate::scene::Shading::Nff
        } else {
            crate::scene::Shading::Physical
        },
    };
    let values = [
        desc.base_color.x,
        desc.base_color.y,
        desc.base_color.z,
        desc.reflectance,
        desc.ior,
        desc.shininess,
        desc.specular,
    ];
    if !values.iter().all(|v| v.is_finite()) {
        return Err(error(
            mtl_path,
            None,
            format!("material {}: non-finite parameter", m.name),
        ));
    }
    Ok(desc)
}

/// The texture a `map_Kd` statement names (loaded once per file and sampler).
pub(super) fn texture(
    m: &tobj::Material,
    statement: &str,
    mtl_path: &Path,
    scene: &mut SceneDesc,
    textures: &mut Vec<(PathBuf, Sampler, usize)>,
) -> Result<usize, ObjError> {
    let (clamp, file) = texture_statement(statement);
    if file.is_empty() {
        return Err(error(
            mtl_path,
            None,
            format!("material {}: map_Kd without a file name", m.name),
        ));
    }
    let mut sampler = if clamp {
        Sampler {
            wrap_s: WrapMode::ClampToEdge,
            wrap_t: WrapMode::ClampToEdge,
            mip: MipFilter::Linear,
        }
    } else {
        Sampler::default()
    };
    if let Some(wrap) = m.unknown_param.get("mipray_wrap") {
        let words: Vec<&str> = wrap.split_whitespace().collect();
        match words.as_slice() {
            [s, t] if wrap_mode(s).is_some() && wrap_mode(t).is_some() => {
                sampler.wrap_s = wrap_mode(s).unwrap_or_default();
                sampler.wrap_t = wrap_mode(t).unwrap_or_default();
            }
            _ => {
                return Err(error(
                    mtl_path,
                    None,
                    format!(
                        "material {}: mipray_wrap {wrap}: expected two of repeat, clamp, mirrored",
                        m.name
                    ),
                ));
            }
        }
    }
    if let Some(mip) = m.unknown_param.get("mipray_mip") {
        sampler.mip = MipFilter::from_name(mip.trim()).ok_or_else(|| {
            error(
                mtl_path,
                None,
                format!(
                    "material {}: mipray_mip {mip}: expected linear or nearest",
                    m.name
                ),
            )
        })?;
    }
    let texture_path = mtl_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(file.replace('\\', "/"));
    if let Some(&(_, _, index)) = textures
        .iter()
        .find(|(p, s, _)| *p == texture_path && *s == sampler)
    {
        return Ok(index);
    }
    let bytes = crate::scene::sources::read(&texture_path).map_err(|e| {
        error(
            &texture_path,
            None,
            format!(
                "texture of material {} (in {}): {e}",
                m.name,
                mtl_path.display()
            ),
        )
    })?;
    let (width, height, texels): (u32, u32, Vec<Vec4>) = decode_texels(&bytes, ColorEncoding::Srgb)
        .map_err(|e| error(&texture_path, None, format!("cannot decode texture: {e}")))?;
    let pyramid = MipPyramid::from_linear_rgba(width, height, texels)
        .map_err(|e| error(&texture_path, None, format!("bad texture: {e}")))?;
    let name = m
        .unknown_param
        .get("mipray_texture_name")
        .cloned()
        .unwrap_or(file);
    scene.textures.push(Texture {
        name,
        pyramid,
        sampler,
    });
    let index = scene.textures.len() - 1;
    textures.push((texture_path, sampler, index));
    Ok(index)
}

/// A parsed material library: materials and name -> index (tobj's own types).
pub(super) type MaterialLibrary = <tobj::MTLLoadResult as IntoIterator>::Item;

/// Reads and parses a material library, checking its lines first so a bad one is reported
/// with its number (and never reaches the parser's own unchecked paths).
pub(super) fn load_mtl(path: &Path) -> Result<MaterialLibrary, ObjError> {
    let text = crate::scene::sources::read_to_string(path)
        .map_err(|e| error(path, None, format!("cannot read material library: {e}")))?;
    if let Some((line, message)) = first_bad_mtl_line(&text) {
        return Err(error(path, Some(line), message));
    }
    tobj::load_mtl_buf(&mut Cursor::new(text.as_bytes()))
        .map_err(|e| error(path, None, e.to_string()))
}
