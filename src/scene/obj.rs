//! Wavefront OBJ (+ MTL) loader: a static scene (one node, no animation).
//!
//! Reads what `mipray export` writes losslessly, and general OBJ files too:
//! - geometry: `v` (with optional `w` or vertex colour, ignored), `vt`, `vn`, `f` (polygons
//!   are fan-triangulated), `o`/`g`, `usemtl`, `mtllib` (parsed by `tobj`);
//! - OBJ's `vt` origin is the image's bottom-left, mipray's (glTF's) the top-left: a `vt`
//!   of `(s, t)` becomes `(u, v) = (s, 1 - t)` (in f64, so an exported frame's UVs come
//!   back bit for bit);
//! - materials: `Kd` (linear base colour), `map_Kd` (sRGB texture; options `-clamp on` and
//!   any others skipped), `Ni` (ior), `d` / `Tr` (transmission = 1 - d, or Tr), `Ns`
//!   (shininess), `Ks` (mean = highlight strength), and mipray's exact statements
//!   `mipray_name`, `mipray_reflectance`, `mipray_specular`, `mipray_transmission`,
//!   `mipray_double_sided`, `mipray_wrap S T` (`repeat`/`clamp`/`mirrored`),
//!   `mipray_texture_name`, which take precedence;
//! - camera and lights: beside `frame_NNNN.obj`, a `camera_NNNN.json` (as `export` writes
//!   it) adds a camera node reproducing its eye, forward, up and vertical field of view,
//!   a node per light and the background. Without it the renderer frames the scene and
//!   adds its default light.
//!
//! Errors name the file and, where a line is at fault, its line number.

use std::cell::RefCell;
use std::fmt;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::scene::camera_file::CameraFile;
use crate::scene::{
    CameraDesc, LightDesc, MaterialDesc, MeshDesc, NodeDesc, PrimitiveDesc, SceneDesc, Trs,
};
use crate::texture::{MipPyramid, Sampler, Texture, WrapMode, decode_image};

/// Why an OBJ scene could not be loaded: the file (OBJ, MTL, texture or camera JSON), the
/// line when one is at fault, and what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjError {
    pub path: PathBuf,
    pub line: Option<usize>,
    pub message: String,
}

impl fmt::Display for ObjError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{line}: {}", self.path.display(), self.message),
            None => write!(f, "{}: {}", self.path.display(), self.message),
        }
    }
}

impl std::error::Error for ObjError {}

fn error(path: &Path, line: Option<usize>, message: impl Into<String>) -> ObjError {
    ObjError {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Loads an OBJ file (and its MTL, textures and sibling camera JSON) as a static scene.
///
/// # Errors
/// An unreadable or malformed OBJ/MTL/JSON file, a missing or undecodable texture, or a
/// non-finite number.
pub fn load(path: &Path) -> Result<SceneDesc, ObjError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| error(path, None, format!("cannot read file: {e}")))?;
    if let Some((line, message)) = first_bad_obj_line(&text) {
        return Err(error(path, Some(line), message));
    }
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    // Each material library read, in order: (its path, how many materials it defined).
    let libraries: RefCell<Vec<(PathBuf, usize)>> = RefCell::new(Vec::new());
    let mtl_error: RefCell<Option<ObjError>> = RefCell::new(None);
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let loaded = tobj::load_obj_buf(&mut Cursor::new(text.as_bytes()), &options, |mtl| {
        let mtl_path = dir.join(mtl);
        let result = load_mtl(&mtl_path);
        match &result {
            Ok((materials, _)) => libraries.borrow_mut().push((mtl_path, materials.len())),
            Err(e) => {
                mtl_error.borrow_mut().get_or_insert_with(|| e.clone());
            }
        }
        result.map_err(|_| tobj::LoadError::MaterialParseError)
    });
    if let Some(e) = mtl_error.into_inner() {
        return Err(e);
    }
    let (models, materials) = loaded.map_err(|e| error(path, None, e.to_string()))?;
    let materials = materials.map_err(|e| error(path, None, format!("material library: {e}")))?;

    let mut scene = SceneDesc {
        source: path.to_path_buf(),
        background: crate::scene::gltf::BACKGROUND,
        ..Default::default()
    };
    // Material i came from the library whose cumulative count first exceeds i.
    let mut library_of = Vec::with_capacity(materials.len());
    for (mtl_path, count) in libraries.into_inner() {
        library_of.extend(std::iter::repeat_n(mtl_path, count));
    }
    let mut texture_index: Vec<(PathBuf, Sampler, usize)> = Vec::new();
    for (i, m) in materials.iter().enumerate() {
        let mtl_path = library_of.get(i).cloned().unwrap_or_else(|| path.into());
        let desc = material(m, &mtl_path, &mut scene, &mut texture_index)?;
        scene.materials.push(desc);
    }

    let mut mesh = MeshDesc {
        name: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        ..Default::default()
    };
    for model in &models {
        if let Some(p) = primitive(&model.mesh, &scene, path)? {
            mesh.primitives.push(p);
        }
    }
    scene.meshes.push(mesh);
    scene.nodes.push(NodeDesc {
        name: "mesh".into(),
        mesh: Some(0),
        ..Default::default()
    });
    scene.roots.push(0);

    if let Some(camera_path) = sibling_camera(path) {
        add_camera_file(&mut scene, &camera_path)?;
    }
    Ok(scene)
}

/// `camera_NNNN.json` beside `frame_NNNN.obj`, if it exists.
fn sibling_camera(path: &Path) -> Option<PathBuf> {
    let stem = path.file_stem()?.to_str()?;
    let number = stem.strip_prefix("frame_")?;
    if number.is_empty() || !number.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let candidate = path.with_file_name(format!("camera_{number}.json"));
    candidate.is_file().then_some(candidate)
}

fn finite3(v: [f32; 3]) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// World transform whose origin is `origin` and whose -Z is `forward` (unit), with `up` its
/// +Y when given (else any perpendicular).
fn look_matrix(origin: Vec3, forward: Vec3, up: Option<Vec3>, right: Option<Vec3>) -> Mat4 {
    let z = -forward;
    let (x, y) = match (right, up) {
        (Some(x), Some(y)) => (x, y),
        _ => {
            let helper = if z.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
            let x = helper.cross(z).normalize_or(Vec3::X);
            (x, z.cross(x))
        }
    };
    Mat4::from_cols(
        x.extend(0.0),
        y.extend(0.0),
        z.extend(0.0),
        origin.extend(1.0),
    )
}

fn matrix_node(name: String, matrix: Mat4) -> NodeDesc {
    let (scale, rotation, translation) = matrix.to_scale_rotation_translation();
    NodeDesc {
        name,
        local: Trs {
            translation,
            rotation,
            scale,
        },
        matrix: Some(matrix),
        ..Default::default()
    }
}

/// Adds the camera, lights and background of an export's camera file.
fn add_camera_file(scene: &mut SceneDesc, path: &Path) -> Result<(), ObjError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| error(path, None, format!("cannot read file: {e}")))?;
    let file: CameraFile = serde_json::from_str(&text)
        .map_err(|e| error(path, Some(e.line()), format!("bad camera file: {e}")))?;
    let vectors = [file.eye, file.forward, file.up, file.right, file.background];
    // The renderer uses this value as given (no substitute), so refuse what it cannot use.
    let yfov = file.yfov_radians;
    if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
        return Err(error(
            path,
            None,
            format!("camera has yfov_radians {yfov}, outside (0, pi)"),
        ));
    }
    if !vectors.iter().all(|v| finite3(*v)) {
        return Err(error(path, None, "camera has a non-finite vector"));
    }
    // The exact fields (bit patterns) when they are present and agree with the decimals'
    // magnitude; the decimals otherwise.
    let exact = |v: [f32; 3], bits: [u32; 3]| {
        let b = bits.map(f32::from_bits);
        if (Vec3::from(b) - Vec3::from(v)).length() <= 1e-5 {
            Vec3::from(b)
        } else {
            Vec3::from(v)
        }
    };
    let eye = exact(file.eye, file.bits.eye);
    let forward = exact(file.forward, file.bits.forward);
    let up = exact(file.up, file.bits.up);
    let right = exact(file.right, file.bits.right);
    let camera_node = scene.nodes.len();
    scene.cameras.push(CameraDesc {
        yfov: file.yfov_radians,
        znear: 0.01,
    });
    let mut node = matrix_node(
        "camera".into(),
        look_matrix(eye, forward, Some(up), Some(right)),
    );
    node.camera = Some(scene.cameras.len() - 1);
    scene.nodes.push(node);
    scene.roots.push(camera_node);
    for (i, light) in file.lights.iter().enumerate() {
        let kind = light.light_kind().ok_or_else(|| {
            error(
                path,
                None,
                format!("light {i}: unknown kind {:?}", light.kind),
            )
        })?;
        let finite = finite3(light.position)
            && finite3(light.direction)
            && finite3(light.intensity)
            && light.range.is_none_or(f32::is_finite);
        if !finite {
            return Err(error(path, None, format!("light {i}: non-finite value")));
        }
        scene.lights.push(LightDesc {
            kind,
            color: Vec3::from(light.intensity),
            intensity: 1.0,
            range: light.range,
            inverse_square: light.inverse_square,
        });
        let direction = Vec3::from(light.direction).normalize_or(Vec3::NEG_Y);
        let mut node = matrix_node(
            format!("light {i}"),
            look_matrix(Vec3::from(light.position), direction, None, None),
        );
        node.light = Some(scene.lights.len() - 1);
        scene.roots.push(scene.nodes.len());
        scene.nodes.push(node);
    }
    scene.background = Vec3::from(file.background);
    Ok(())
}

/// One tobj mesh as a primitive (`None` when it has no triangles).
fn primitive(
    mesh: &tobj::Mesh,
    scene: &SceneDesc,
    path: &Path,
) -> Result<Option<PrimitiveDesc>, ObjError> {
    if mesh.indices.len() < 3 {
        return Ok(None);
    }
    let count = mesh.positions.len() / 3;
    let f32s = |values: &[f64]| -> Result<Vec<f32>, ObjError> {
        values
            .iter()
            .map(|&v| {
                let x = v as f32;
                if x.is_finite() {
                    Ok(x)
                } else {
                    Err(error(path, None, format!("number out of range: {v}")))
                }
            })
            .collect()
    };
    let positions: Vec<Vec3> = f32s(&mesh.positions)?
        .chunks_exact(3)
        .map(Vec3::from_slice)
        .collect();
    let normals = if mesh.normals.len() == 3 * count {
        let normals = f32s(&mesh.normals)?
            .chunks_exact(3)
            .map(|n| {
                let n = Vec3::from_slice(n);
                // An exported normal is unit already: renormalising would move its last bits.
                if (n.length_squared() - 1.0).abs() <= 1e-5 {
                    n
                } else {
                    n.normalize_or_zero()
                }
            })
            .collect();
        Some(normals)
    } else {
        None
    };
    let flipped: Vec<f64> = mesh
        .texcoords
        .chunks_exact(2)
        .flat_map(|st| [st[0], 1.0 - st[1]])
        .collect();
    let textured = mesh
        .material_id
        .and_then(|m| scene.materials.get(m))
        .is_some_and(|m| m.base_color_texture.is_some());
    let uvs = if mesh.texcoords.len() == 2 * count {
        Some(
            f32s(&flipped)?
                .chunks_exact(2)
                .map(Vec2::from_slice)
                .collect(),
        )
    } else if textured {
        Some(vec![Vec2::ZERO; count])
    } else {
        None
    };
    let indices: Vec<u32> = mesh.indices.clone();
    if indices.iter().any(|&i| i as usize >= count) || !indices.len().is_multiple_of(3) {
        return Err(error(path, None, "face index out of range"));
    }
    Ok(Some(PrimitiveDesc {
        positions,
        normals,
        uvs,
        indices,
        material: mesh.material_id.filter(|&m| m < scene.materials.len()),
        ..Default::default()
    }))
}

/// Parses a number of a `mipray_*` or standard statement.
fn number(
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

fn wrap_mode(word: &str) -> Option<WrapMode> {
    match word {
        "repeat" => Some(WrapMode::Repeat),
        "clamp" => Some(WrapMode::ClampToEdge),
        "mirrored" => Some(WrapMode::MirroredRepeat),
        _ => None,
    }
}

/// Splits a `map_Kd` value into its options and the file name: whether `-clamp on` was
/// given, and the rest of the line after the options (file names may contain spaces).
fn texture_statement(value: &str) -> (bool, String) {
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

fn material(
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
    let transmission = match num("mipray_transmission")? {
        Some(t) => t,
        None => match (m.dissolve, num("Tr")?) {
            (Some(d), _) => f(1.0 - d),
            (None, Some(tr)) => tr,
            (None, None) => 0.0,
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
fn texture(
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
    let bytes = std::fs::read(&texture_path).map_err(|e| {
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
    let (width, height, texels): (u32, u32, Vec<Vec4>) = decode_image(&bytes, true)
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
type MaterialLibrary = <tobj::MTLLoadResult as IntoIterator>::Item;

/// Reads and parses a material library, checking its lines first so a bad one is reported
/// with its number (and never reaches the parser's own unchecked paths).
fn load_mtl(path: &Path) -> Result<MaterialLibrary, ObjError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| error(path, None, format!("cannot read material library: {e}")))?;
    if let Some((line, message)) = first_bad_mtl_line(&text) {
        return Err(error(path, Some(line), message));
    }
    tobj::load_mtl_buf(&mut Cursor::new(text.as_bytes()))
        .map_err(|e| error(path, None, e.to_string()))
}

fn floats(words: &[&str]) -> usize {
    words
        .iter()
        .take_while(|w| w.parse::<f64>().is_ok())
        .count()
}

/// The first line (1-based) of an MTL text the parser would reject, and why.
fn first_bad_mtl_line(text: &str) -> Option<(usize, String)> {
    for (i, line) in text.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&key, args)) = words.split_first() else {
            continue;
        };
        let problem = match key {
            "Ka" | "Kd" | "Ks" | "Ke" if floats(args) < 3 => Some("expected three numbers"),
            "Ns" | "Ni" | "d" if floats(args) < 1 => Some("expected a number"),
            "illum" if args.first().and_then(|a| a.parse::<u8>().ok()).is_none() => {
                Some("expected an illumination model number")
            }
            "newmtl" | "map_Ka" | "map_Kd" | "map_Ks" | "map_Bump" | "map_bump" | "map_Ns"
            | "map_ns" | "map_NS" | "bump" | "map_d"
                if args.is_empty() =>
            {
                Some("expected a name")
            }
            _ => None,
        };
        if let Some(problem) = problem {
            return Some((i + 1, format!("{key}: {problem}")));
        }
    }
    None
}

/// Resolves a 1-based or negative (relative) OBJ index against `count` elements so far.
fn index_ok(word: &str, count: usize) -> bool {
    match word.parse::<i64>() {
        Ok(i) if i > 0 => (i as usize) <= count,
        Ok(i) if i < 0 => i.unsigned_abs() as usize <= count,
        _ => false,
    }
}

/// The first line (1-based) of an OBJ text the parser would reject, and why.
fn first_bad_obj_line(text: &str) -> Option<(usize, String)> {
    let (mut v, mut vt, mut vn) = (0usize, 0usize, 0usize);
    for (i, line) in text.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&key, args)) = words.split_first() else {
            continue;
        };
        let problem: Option<String> = match key {
            "v" => {
                let n = floats(args);
                if n < 3 || args.len() != n || !matches!(n, 3 | 4 | 6) {
                    Some("expected x y z [w | r g b]".into())
                } else if n == 4 && args[3].parse::<f64>() == Ok(0.0) {
                    Some("w is zero".into())
                } else {
                    v += 1;
                    None
                }
            }
            "vt" => {
                if floats(args) < 2 {
                    Some("expected u v".into())
                } else {
                    vt += 1;
                    None
                }
            }
            "vn" => {
                if floats(args) < 3 {
                    Some("expected x y z".into())
                } else {
                    vn += 1;
                    None
                }
            }
            "f" => {
                if args.len() < 3 {
                    Some("a face needs at least three vertices".into())
                } else {
                    args.iter().find_map(|corner| {
                        let parts: Vec<&str> = corner.split('/').collect();
                        let ok = match parts.as_slice() {
                            [a] => index_ok(a, v),
                            [a, b] => index_ok(a, v) && index_ok(b, vt),
                            [a, "", c] => index_ok(a, v) && index_ok(c, vn),
                            [a, b, c] => index_ok(a, v) && index_ok(b, vt) && index_ok(c, vn),
                            _ => false,
                        };
                        (!ok).then(|| {
                            format!("face corner {corner}: bad or out-of-range index ({v} v, {vt} vt, {vn} vn so far)")
                        })
                    })
                }
            }
            "l" => Some("line elements are not supported".into()),
            "usemtl" | "mtllib" if args.is_empty() => Some(format!("{key} needs a name")),
            _ => None,
        };
        if let Some(problem) = problem {
            return Some((i + 1, format!("{key}: {problem}")));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_lines_are_located() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1\nf 1 2 3\n";
        assert_eq!(first_bad_obj_line(text).map(|(l, _)| l), Some(3));
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n";
        assert_eq!(first_bad_obj_line(text).map(|(l, _)| l), Some(5));
        assert_eq!(
            first_bad_obj_line("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -1\n"),
            None
        );
        assert_eq!(
            first_bad_mtl_line("newmtl a\nKd 0.5\n").map(|(l, _)| l),
            Some(2)
        );
    }

    #[test]
    fn map_kd_options_are_skipped() {
        assert_eq!(
            texture_statement("-clamp on textures/0_a.png"),
            (true, "textures/0_a.png".into())
        );
        assert_eq!(
            texture_statement("-s 1 1 1 -o 0.5 0.5 -bm 2 my file.png"),
            (false, "my file.png".into())
        );
        assert_eq!(texture_statement("a.png"), (false, "a.png".into()));
    }
}
