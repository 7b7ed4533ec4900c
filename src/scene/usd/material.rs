//! `UsdShade` materials: the bound material of a prim (`material:binding`, inherited down
//! namespace; `material:binding:full` preferred), its `UsdPreviewSurface`, and the
//! `UsdUVTexture` feeding its diffuse colour, mapped to the renderer's materials as the glTF
//! loader maps metallic/roughness (see `scene/gltf/material.rs` for the formulas):
//! - `diffuseColor` (value, or texture `rgb` times the texture's `scale`) -> base colour;
//! - `metallic`, `roughness` (values; textures on them are ignored, noted) -> mirror
//!   reflectance, highlight strength and exponent;
//! - `opacity < 1` (value; `opacityThreshold` 0) -> transmission `1 - opacity` with `ior`:
//!   glass; with `opacityThreshold > 0` it is a cut-out mask, which is ignored (noted);
//! - the texture's `wrapS`/`wrapT` (`repeat`, `mirror`, `clamp`; `black` is approximated by
//!   `clamp` and noted; `useMetadata` is `repeat`), `sourceColorSpace` (`raw` is linear,
//!   otherwise sRGB), `bias` (ignored when not zero, noted), the `UsdPrimvarReader_float2`
//!   `varname` (which primvar gives the uvs) and a `UsdTransform2d` between them.
//!
//! Ignored with a note: emissive colour, normal maps, occlusion, clearcoat, displacement,
//! shaders other than `UsdPreviewSurface` (their prims render with the default material).

use std::collections::HashMap;

use glam::{Vec2, Vec3};
use openusd::sdf::{self, Value};
use openusd::usd::{Prim, Stage};

use super::values::{Reader, attr_path, scalar, token, vec2, vec3_or_4, vec4};
use crate::scene::{MaterialDesc, Shading};
use crate::texture::{
    ColorEncoding, MipFilter, MipPyramid, Sampler, Texture, WrapMode, decode_texels,
};

/// Largest index of refraction kept (as for glTF).
const MAX_IOR: f32 = 4.0;
/// Longest chain of connections followed (a cycle of connections stops here).
const MAX_CONNECTION_HOPS: usize = 16;

/// How a textured material reads its uvs.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct UvRead {
    /// The primvar holding the uvs (`st` by default).
    pub primvar: String,
    /// `UsdTransform2d`: scale, rotation (degrees, counter-clockwise), translation.
    pub transform: Option<(Vec2, f32, Vec2)>,
}

impl UvRead {
    /// Applies the transform: `st' = translation + R(rotation) (scale * st)`.
    pub fn apply(&self, st: Vec2) -> Vec2 {
        match self.transform {
            None => st,
            Some((scale, degrees, translation)) => {
                let (sin, cos) = degrees.to_radians().sin_cos();
                let s = st * scale;
                Vec2::new(cos * s.x - sin * s.y, sin * s.x + cos * s.y) + translation
            }
        }
    }
}

/// A material as a mesh uses it.
#[derive(Debug, Clone)]
pub(super) struct Bound {
    pub index: usize,
    pub uv: Option<UvRead>,
    /// The diffuse colour is the mesh's own `displayColor` (a `UsdPrimvarReader_float3` of
    /// it feeds `diffuseColor`): each mesh takes a copy of the material with its colour,
    /// and the material's colour is the reader's fallback, for a mesh without one.
    pub reads_display_color: bool,
}

/// Builds materials and textures once each.
#[derive(Default)]
pub(super) struct Materials {
    pub materials: Vec<MaterialDesc>,
    pub textures: Vec<Texture>,
    /// (material prim path, double-sided) -> built.
    by_path: HashMap<(String, bool), Bound>,
    /// (resolved image, raw) -> pyramid index in `textures` (first texture made from it).
    by_image: HashMap<(String, bool), usize>,
    /// (resolved image, raw, wrap) -> texture index.
    by_texture: HashMap<(String, bool, [u8; 2]), usize>,
    /// displayColor (bits), double-sided -> material index.
    by_color: HashMap<([u32; 3], bool), usize>,
    /// (material index, diffuse colour bits) -> its copy in that colour.
    recoloured: HashMap<(usize, [u32; 3]), usize>,
}

/// Counts of what was ignored, turned into one note each at the end.
#[derive(Default)]
pub(super) struct Ignored {
    pub maps: usize,
    pub emissive: usize,
    pub cutout: usize,
    pub bias: usize,
    pub black_wrap: usize,
    pub other_shaders: usize,
    /// `diffuseColor` fed by a shader the loader does not evaluate (neither a texture nor
    /// a primvar reader of `displayColor`).
    pub other_colour_sources: usize,
    /// `UsdUVTexture`s without an image.
    pub textures_without_file: usize,
    /// `material:binding`s to a prim that does not exist.
    pub missing_bindings: usize,
}

impl Ignored {
    pub fn notes(&self, notes: &mut Vec<String>) {
        let mut note = |n: usize, what: &str| {
            if n > 0 {
                notes.push(format!("{n} material(s) {what}"));
            }
        };
        note(
            self.maps,
            "have textures on inputs other than diffuseColor (normal, roughness, metallic, occlusion, ...), which are ignored (values only)",
        );
        note(self.emissive, "have an emissive colour, which is ignored");
        note(
            self.cutout,
            "use opacityThreshold (a cut-out mask), which is ignored (rendered opaque)",
        );
        note(
            self.bias,
            "have a texture bias, which is ignored (the scale is applied)",
        );
        note(
            self.black_wrap,
            "use the 'black' wrap mode, approximated by clamping to the edge",
        );
        note(
            self.other_shaders,
            "use a surface shader other than UsdPreviewSurface; rendered with the default material",
        );
        note(
            self.other_colour_sources,
            "feed diffuseColor from a shader other than a texture or a displayColor primvar reader; the default diffuse colour is used",
        );
        note(
            self.textures_without_file,
            "have a UsdUVTexture without an image (inputs:file); its fallback colour is used",
        );
        if self.missing_bindings > 0 {
            notes.push(format!(
                "{} material binding(s) target a prim that does not exist; those meshes render as if nothing were bound (displayColor or the default material)",
                self.missing_bindings
            ));
        }
    }
}

impl Materials {
    /// The material bound to `prim` (or to the closest ancestor with a binding), built on
    /// first use; `None` when nothing is bound.
    pub fn bound(
        &mut self,
        reader: &Reader,
        prim: &Prim,
        double_sided: bool,
        ignored: &mut Ignored,
    ) -> Result<Option<Bound>, String> {
        let Some(material) = binding(reader, prim, ignored)? else {
            return Ok(None);
        };
        let key = (material.as_str().to_string(), double_sided);
        if let Some(bound) = self.by_path.get(&key) {
            return Ok(Some(bound.clone()));
        }
        let stage = reader.stage;
        let material_prim = stage.prim(material.clone());
        let bound = self.build(reader, &material_prim, double_sided, ignored)?;
        self.by_path.insert(key, bound.clone());
        Ok(Some(bound))
    }

    /// A plain material of `displayColor` (shared by meshes of the same colour).
    pub fn display_color(&mut self, color: Vec3, double_sided: bool) -> usize {
        let key = (color.to_array().map(f32::to_bits), double_sided);
        if let Some(&i) = self.by_color.get(&key) {
            return i;
        }
        self.materials.push(MaterialDesc {
            name: "displayColor".into(),
            base_color: color,
            double_sided,
            ..preview_defaults()
        });
        let i = self.materials.len() - 1;
        self.by_color.insert(key, i);
        i
    }

    /// Material `index` with diffuse colour `color` (for a material that reads the mesh's
    /// `displayColor`; one copy per colour).
    pub fn recoloured(&mut self, index: usize, color: Vec3) -> usize {
        let key = (index, color.to_array().map(f32::to_bits));
        if let Some(&i) = self.recoloured.get(&key) {
            return i;
        }
        let mut copy = self.materials[index].clone();
        copy.base_color = color;
        self.materials.push(copy);
        let i = self.materials.len() - 1;
        self.recoloured.insert(key, i);
        i
    }

    /// The default material, double-sided or not (for meshes with neither a material nor a
    /// displayColor that need the double-sided flag).
    pub fn plain(&mut self, double_sided: bool) -> usize {
        self.display_color(Vec3::splat(0.18), double_sided)
    }

    fn build(
        &mut self,
        reader: &Reader,
        material: &Prim,
        double_sided: bool,
        ignored: &mut Ignored,
    ) -> Result<Bound, String> {
        let name = material.path().name().unwrap_or_default().to_string();
        let mut desc = MaterialDesc {
            name,
            double_sided,
            ..preview_defaults()
        };
        let Some(shader) = surface_shader(reader, material)? else {
            ignored.other_shaders += 1;
            self.materials.push(desc);
            return Ok(Bound {
                index: self.materials.len() - 1,
                uv: None,
                reads_display_color: false,
            });
        };
        let input = |name: &str| -> Result<Input, String> { shader_input(reader, &shader, name) };
        let mut uv = None;
        let mut reads_display_color = false;
        match input("diffuseColor")? {
            Input::Value(v) => {
                desc.base_color = color(&v, &shader, "inputs:diffuseColor")?;
            }
            Input::Connected(source, output) => match info_id(reader, &source)?.as_deref() {
                Some("UsdUVTexture") => match self.texture(reader, &source, &output, ignored)? {
                    Some((texture, read, scale)) => {
                        desc.base_color_texture = Some(texture);
                        desc.base_color = scale;
                        uv = Some(read);
                    }
                    None => desc.base_color = fallback_colour(reader, &source)?,
                },
                Some(id) if id.starts_with("UsdPrimvarReader_float") => {
                    match primvar_colour(reader, &source)? {
                        Some(fallback) => {
                            desc.base_color = fallback;
                            reads_display_color = true;
                        }
                        None => ignored.other_colour_sources += 1,
                    }
                }
                _ => ignored.other_colour_sources += 1,
            },
            Input::Unset => {}
        }
        let mut float = |name: &str, default: f32| -> Result<f32, String> {
            match input(name)? {
                Input::Value(v) => {
                    let x = scalar(&v).ok_or_else(|| {
                        format!(
                            "{}: expected a float",
                            attr_path(&shader, &format!("inputs:{name}"))
                        )
                    })? as f32;
                    if x.is_finite() {
                        Ok(x)
                    } else {
                        Err(format!(
                            "{}: not finite",
                            attr_path(&shader, &format!("inputs:{name}"))
                        ))
                    }
                }
                Input::Connected(..) => {
                    ignored.maps += 1;
                    Ok(default)
                }
                Input::Unset => Ok(default),
            }
        };
        let metallic = float("metallic", 0.0)?.clamp(0.0, 1.0);
        let roughness = float("roughness", 0.5)?.clamp(0.0, 1.0);
        let opacity = float("opacity", 1.0)?.clamp(0.0, 1.0);
        let threshold = float("opacityThreshold", 0.0)?;
        let ior = float("ior", 1.5)?;
        for map in [
            "normal",
            "occlusion",
            "displacement",
            "clearcoat",
            "specularColor",
        ] {
            if matches!(input(map)?, Input::Connected(..)) {
                ignored.maps += 1;
            }
        }
        match input("emissiveColor")? {
            Input::Value(v) if vec3_or_4(&v).is_some_and(|c| c.max_element() > 0.0) => {
                ignored.emissive += 1
            }
            Input::Connected(..) => ignored.emissive += 1,
            _ => {}
        }
        desc.reflectance = metallic * (1.0 - roughness).powi(2);
        desc.specular = 0.5 * (1.0 - roughness).powi(2);
        desc.shininess = (2.0 / roughness.powi(4).max(1e-4) - 2.0).clamp(1.0, 10000.0);
        if opacity < 1.0 {
            if threshold > 0.0 {
                ignored.cutout += 1;
            } else {
                desc.transmission = 1.0 - opacity;
            }
        }
        desc.ior = if ior == 0.0 {
            MAX_IOR
        } else {
            ior.clamp(1.0, MAX_IOR)
        };
        self.materials.push(desc);
        Ok(Bound {
            index: self.materials.len() - 1,
            uv,
            reads_display_color,
        })
    }

    /// The texture behind a `UsdUVTexture` output: its index, how its uvs are read, and
    /// the colour factor (`scale.rgb`). `None` for a texture without an image
    /// (`inputs:file` unset or empty), which USD renders in its fallback colour.
    fn texture(
        &mut self,
        reader: &Reader,
        shader: &Prim,
        output: &str,
        ignored: &mut Ignored,
    ) -> Result<Option<(usize, UvRead, Vec3)>, String> {
        let path = shader.path().as_str().to_string();
        if !matches!(output, "rgb" | "rgba") {
            ignored.maps += 1;
        }
        let file = match shader_input(reader, shader, "file")? {
            Input::Value(Value::AssetPath(a)) if !a.asset_path().is_empty() => a,
            Input::Value(Value::AssetPath(_)) | Input::Unset => {
                ignored.textures_without_file += 1;
                return Ok(None);
            }
            _ => return Err(format!("{path}: inputs:file is not an asset path")),
        };
        let resolved = file
            .resolved_path()
            .map(str::to_string)
            .ok_or_else(|| format!("{path}: texture file '{}' not found", file.asset_path()))?;
        let raw = matches!(
            shader_input(reader, shader, "sourceColorSpace")?,
            Input::Value(v) if token(&v).as_deref() == Some("raw")
        );
        let wrap = |name: &str, ignored: &mut Ignored| -> Result<WrapMode, String> {
            Ok(match shader_input(reader, shader, name)? {
                Input::Value(v) => match token(&v).as_deref() {
                    Some("repeat") | Some("useMetadata") | None => WrapMode::Repeat,
                    Some("mirror") => WrapMode::MirroredRepeat,
                    Some("clamp") => WrapMode::ClampToEdge,
                    Some("black") => {
                        ignored.black_wrap += 1;
                        WrapMode::ClampToEdge
                    }
                    Some(other) => {
                        return Err(format!(
                            "{}: unknown wrap mode '{other}'",
                            attr_path(shader, &format!("inputs:{name}"))
                        ));
                    }
                },
                _ => WrapMode::Repeat,
            })
        };
        let sampler = Sampler {
            wrap_s: wrap("wrapS", ignored)?,
            wrap_t: wrap("wrapT", ignored)?,
            // UsdUVTexture has no minification filter: trilinear, as everywhere else.
            mip: MipFilter::Linear,
        };
        let scale = match shader_input(reader, shader, "scale")? {
            Input::Value(v) => {
                let s = vec4(&v)
                    .map(|s| Vec3::new(s[0], s[1], s[2]))
                    .or_else(|| vec3_or_4(&v));
                match s {
                    Some(s) if s.is_finite() => s.max(Vec3::ZERO),
                    _ => {
                        return Err(format!(
                            "{}: expected a finite float4",
                            attr_path(shader, "inputs:scale")
                        ));
                    }
                }
            }
            _ => Vec3::ONE,
        };
        if let Input::Value(v) = shader_input(reader, shader, "bias")?
            && vec4(&v).is_some_and(|b| b[..3].iter().any(|&x| x != 0.0))
        {
            ignored.bias += 1;
        }
        let read = uv_read(reader, shader)?;
        let index = self.texture_index(&resolved, raw, sampler, &path)?;
        Ok(Some((index, read, scale)))
    }

    /// The texture of image `resolved` with `sampler`, decoding the image once.
    fn texture_index(
        &mut self,
        resolved: &str,
        raw: bool,
        sampler: Sampler,
        shader: &str,
    ) -> Result<usize, String> {
        let wrap_code = |w: WrapMode| match w {
            WrapMode::Repeat => 0u8,
            WrapMode::ClampToEdge => 1,
            WrapMode::MirroredRepeat => 2,
        };
        let key = (
            resolved.to_string(),
            raw,
            [wrap_code(sampler.wrap_s), wrap_code(sampler.wrap_t)],
        );
        if let Some(&i) = self.by_texture.get(&key) {
            return Ok(i);
        }
        let (pyramid, name) = match self.by_image.get(&(resolved.to_string(), raw)) {
            Some(&i) => (
                self.textures[i].pyramid.clone(),
                self.textures[i].name.clone(),
            ),
            None => decode(resolved, raw, shader)?,
        };
        self.textures.push(Texture {
            name,
            pyramid,
            sampler,
        });
        let index = self.textures.len() - 1;
        self.by_image
            .entry((resolved.to_string(), raw))
            .or_insert(index);
        self.by_texture.insert(key, index);
        Ok(index)
    }
}

/// Reads and decodes an image (a file, or an entry of a `.usdz` package).
fn decode(resolved: &str, raw: bool, shader: &str) -> Result<(MipPyramid, String), String> {
    use openusd::ar::{DefaultResolver, ResolvedPath, Resolver};
    let what = format!("{shader}: texture '{resolved}'");
    let bytes = DefaultResolver::new()
        .open_asset(&ResolvedPath::new(resolved))
        .and_then(|mut asset| {
            let mut bytes = Vec::new();
            std::io::Read::read_to_end(&mut asset, &mut bytes)?;
            Ok(bytes)
        })
        .map_err(|e| format!("{what}: cannot read it: {e}"))?;
    crate::scene::sources::note(std::path::Path::new(resolved), &bytes);
    let encoding = if raw {
        ColorEncoding::Linear
    } else {
        ColorEncoding::Srgb
    };
    let (width, height, texels) =
        decode_texels(&bytes, encoding).map_err(|e| format!("{what}: {e}"))?;
    let pyramid =
        MipPyramid::from_linear_rgba(width, height, texels).map_err(|e| format!("{what}: {e}"))?;
    let name = resolved
        .rsplit(['/', '['])
        .next()
        .unwrap_or(resolved)
        .trim_end_matches(']')
        .to_string();
    Ok((pyramid, name))
}

/// The renderer's reading of an unset UsdPreviewSurface: diffuse 0.18, roughness 0.5.
fn preview_defaults() -> MaterialDesc {
    let roughness: f32 = 0.5;
    MaterialDesc {
        name: String::new(),
        base_color: Vec3::splat(0.18),
        reflectance: 0.0,
        specular: 0.5 * (1.0 - roughness).powi(2),
        shininess: (2.0 / roughness.powi(4) - 2.0).clamp(1.0, 10000.0),
        shading: Shading::Physical,
        ..MaterialDesc::default()
    }
}

fn color(v: &Value, shader: &Prim, input: &str) -> Result<Vec3, String> {
    match vec3_or_4(v) {
        Some(c) if c.is_finite() => Ok(c.max(Vec3::ZERO)),
        _ => Err(format!(
            "{}: expected a finite colour",
            attr_path(shader, input)
        )),
    }
}

/// The material bound to `prim` or its closest ancestor with a binding. A binding to a prim
/// that does not exist binds nothing (as in USD, which warns); it is counted in `ignored`.
fn binding(
    reader: &Reader,
    prim: &Prim,
    ignored: &mut Ignored,
) -> Result<Option<sdf::Path>, String> {
    let stage = reader.stage;
    let mut current = Some(prim.path().clone());
    while let Some(path) = current {
        if path == sdf::Path::abs_root() {
            break;
        }
        let p = stage.prim(path.clone());
        for rel in ["material:binding:full", "material:binding"] {
            if let Some(target) = reader.targets(&p, rel)?.into_iter().next() {
                let target = target.prim_path();
                if !prim_exists(stage, &target) {
                    ignored.missing_bindings += 1;
                    return Ok(None);
                }
                return Ok(Some(target));
            }
        }
        current = path.parent();
    }
    Ok(None)
}

fn prim_exists(stage: &Stage, path: &sdf::Path) -> bool {
    stage.prim(path.clone()).is_valid().unwrap_or(false)
}

/// The shader behind the material's `outputs:surface` (through node graphs), when it is a
/// `UsdPreviewSurface`.
fn surface_shader(reader: &Reader, material: &Prim) -> Result<Option<Prim>, String> {
    let stage = reader.stage;
    let mut attr = material
        .path()
        .append_property("outputs:surface")
        .map_err(|e| e.to_string())?;
    for _ in 0..MAX_CONNECTION_HOPS {
        let connections = stage
            .attribute(attr.clone())
            .connections()
            .map_err(|e| format!("{}: {e:#}", attr.as_str()))?;
        let Some(source) = connections.into_iter().next() else {
            return Ok(None);
        };
        let prim = connected_prim(stage, &source, attr.as_str())?;
        match info_id(reader, &prim)?.as_deref() {
            Some("UsdPreviewSurface") => return Ok(Some(prim)),
            Some(_) => return Ok(None),
            // A node graph: follow its output on.
            None => attr = source,
        }
    }
    Err(format!(
        "{}: connections loop or nest too deeply",
        material.path().as_str()
    ))
}

/// The prim that attribute `what`'s connection `source` leads to: the path, as the file
/// wrote it, checked before the lookup walks it (`values::walkable_path`); an error when
/// no such prim exists.
fn connected_prim(stage: &Stage, source: &sdf::Path, what: &str) -> Result<Prim, String> {
    super::values::walkable_path(source).map_err(|e| format!("{what}: {e}"))?;
    let prim = stage.prim(source.prim_path());
    if !prim.is_valid().unwrap_or(false) {
        return Err(format!(
            "{what}: connected to {}, which does not exist",
            source.as_str()
        ));
    }
    Ok(prim)
}

fn info_id(reader: &Reader, shader: &Prim) -> Result<Option<String>, String> {
    Ok(reader
        .default_value(shader, "info:id")?
        .as_ref()
        .and_then(token))
}

/// A shader input: a value, a connection to another shader's output, or nothing.
enum Input {
    Value(Value),
    /// The source shader and the name of its output (`rgb`, `result`, ...).
    Connected(Prim, String),
    Unset,
}

/// Resolves `inputs:NAME` of `shader`: a connection is followed through material and
/// node-graph interface inputs to a shader output, or to the interface input's value.
fn shader_input(reader: &Reader, shader: &Prim, name: &str) -> Result<Input, String> {
    let stage = reader.stage;
    let mut prim = shader.clone();
    let mut attr_name = format!("inputs:{name}");
    for _ in 0..MAX_CONNECTION_HOPS {
        let attr = super::values::attribute(&prim, &attr_name)?;
        let connections = attr
            .connections()
            .map_err(|e| format!("{}: {e:#}", attr_path(&prim, &attr_name)))?;
        let Some(source) = connections.into_iter().next() else {
            return Ok(match reader.default_value(&prim, &attr_name)? {
                Some(v) => Input::Value(v),
                None => Input::Unset,
            });
        };
        let source_prim = connected_prim(stage, &source, &attr_path(&prim, &attr_name))?;
        if !source.is_property_path() {
            return Err(format!(
                "{}: connected to <{}>, which is not a property",
                attr_path(&prim, &attr_name),
                source.as_str()
            ));
        }
        let property = super::values::property_name(&source).to_string();
        match property.strip_prefix("outputs:") {
            Some(output) if info_id(reader, &source_prim)?.is_some() => {
                return Ok(Input::Connected(source_prim, output.to_string()));
            }
            // An interface input or node-graph output: follow it on.
            _ => {
                prim = source_prim;
                attr_name = property;
            }
        }
    }
    Err(format!(
        "{}: connections loop or nest too deeply",
        attr_path(shader, &format!("inputs:{name}"))
    ))
}

/// A shader's `inputs:fallback` as a colour; black when unset (the default both the
/// `UsdUVTexture` and the `UsdPrimvarReader` specifications give).
fn fallback_colour(reader: &Reader, shader: &Prim) -> Result<Vec3, String> {
    match shader_input(reader, shader, "fallback")? {
        Input::Value(v) => color(&v, shader, "inputs:fallback"),
        _ => Ok(Vec3::ZERO),
    }
}

/// For a `UsdPrimvarReader_float3` (or `float4`) of `displayColor`: its fallback colour
/// (black by default). `None` for a reader of another primvar.
fn primvar_colour(reader: &Reader, primvar_reader: &Prim) -> Result<Option<Vec3>, String> {
    let varname = match shader_input(reader, primvar_reader, "varname")? {
        Input::Value(v) => token(&v),
        _ => None,
    };
    if varname.as_deref() != Some("displayColor") {
        return Ok(None);
    }
    fallback_colour(reader, primvar_reader).map(Some)
}

/// How a `UsdUVTexture` reads its uvs: the primvar reader's `varname` (default `st`), and
/// a `UsdTransform2d` between them.
fn uv_read(reader: &Reader, texture: &Prim) -> Result<UvRead, String> {
    let mut read = UvRead {
        primvar: "st".into(),
        transform: None,
    };
    let Input::Connected(mut source, _) = shader_input(reader, texture, "st")? else {
        return Ok(read);
    };
    if info_id(reader, &source)?.as_deref() == Some("UsdTransform2d") {
        let get2 = |name: &str, default: Vec2| -> Result<Vec2, String> {
            Ok(match shader_input(reader, &source, name)? {
                Input::Value(v) => vec2(&v).filter(|v| v.is_finite()).ok_or_else(|| {
                    format!(
                        "{}: expected a finite float2",
                        attr_path(&source, &format!("inputs:{name}"))
                    )
                })?,
                _ => default,
            })
        };
        let scale = get2("scale", Vec2::ONE)?;
        let translation = get2("translation", Vec2::ZERO)?;
        let rotation = match shader_input(reader, &source, "rotation")? {
            Input::Value(v) => scalar(&v)
                .map(|x| x as f32)
                .filter(|x| x.is_finite())
                .unwrap_or(0.0),
            _ => 0.0,
        };
        read.transform = Some((scale, rotation, translation));
        match shader_input(reader, &source, "in")? {
            Input::Connected(next, _) => source = next,
            _ => return Ok(read),
        }
    }
    if info_id(reader, &source)?
        .as_deref()
        .is_some_and(|id| id.starts_with("UsdPrimvarReader"))
    {
        if let Input::Value(v) = shader_input(reader, &source, "varname")?
            && let Some(name) = token(&v)
        {
            read.primvar = name;
        }
    }
    Ok(read)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transform2d_scales_rotates_then_translates() {
        let read = UvRead {
            primvar: "st".into(),
            transform: Some((Vec2::new(2.0, 1.0), 90.0, Vec2::new(0.5, 0.0))),
        };
        let out = read.apply(Vec2::new(1.0, 0.0));
        assert!((out - Vec2::new(0.5, 2.0)).length() < 1e-6, "{out}");
    }
}
