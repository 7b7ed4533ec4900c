//! Wavefront OBJ (+ MTL) loader: a static scene (one node, no animation).
//!
//! Reads what `mipray export` writes losslessly, and general OBJ files too:
//! - geometry: `v` (with optional `w` or vertex colour, ignored), `vt`, `vn`, `f` (polygons
//!   are fan-triangulated), `o`/`g`, `usemtl`, `mtllib` (parsed by `tobj`);
//! - OBJ's `vt` origin is the image's bottom-left, mipray's (glTF's) the top-left: a `vt`
//!   of `(s, t)` becomes `(u, v) = (s, 1 - t)` (in f64, so an exported frame's UVs come
//!   back bit for bit);
//! - materials: `Kd` (linear base colour), `map_Kd` (sRGB texture; options `-clamp on` and
//!   any others skipped), `Ni` (ior), `Tf` / `d` / `Tr` (transmission = mean of Tf, else
//!   1 - d, else Tr), `Ns`
//!   (shininess), `Ks` (mean = highlight strength), and mipray's exact statements
//!   `mipray_name`, `mipray_reflectance`, `mipray_specular`, `mipray_transmission`,
//!   `mipray_double_sided`, `mipray_wrap S T` (`repeat`/`clamp`/`mirrored`),
//!   `mipray_mip linear|nearest` (how the MIP levels are read),
//!   `mipray_texture_name`, which take precedence;
//! - camera and lights: beside `frame_NNNN.obj`, a `camera_NNNN.json` (as `export` writes
//!   it) adds a camera node reproducing its eye, forward, up and vertical field of view,
//!   a node per light and the background. Without it the renderer frames the scene and
//!   adds its default light.
//!
//! Errors name the file and, where a line is at fault, its line number.

mod camera;
mod mtl;
mod validate;

use std::cell::RefCell;
use std::fmt;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::scene::{MeshDesc, NodeDesc, PrimitiveDesc, SceneDesc};
use crate::texture::Sampler;

use camera::{add_camera_file, sibling_camera};
use mtl::{load_mtl, material};
use validate::first_bad_obj_line;

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
    let text = crate::scene::sources::read_to_string(path)
        .map_err(|e| error(path, None, format!("cannot read file: {e}")))?;
    load_from_text(path, &text)
}

/// [`load`] on OBJ text already read from `path` (for fuzzing); its MTL, textures and
/// camera JSON are still looked up beside `path`.
///
/// # Errors
/// As [`load`].
pub fn load_from_text(path: &Path, text: &str) -> Result<SceneDesc, ObjError> {
    // An empty file is a mistake, not an empty scene (as for the other formats).
    if text.trim().is_empty() {
        return Err(error(path, None, "file is empty"));
    }
    if let Some((line, message)) = first_bad_obj_line(text) {
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

#[cfg(test)]
mod tests {
    use super::mtl::{texture_statement, transmission_filter};
    use super::validate::first_bad_mtl_line;
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
    fn numbers_no_f32_can_hold_are_located() {
        let tri = "f 1 2 3\n";
        for (line, shown) in [
            ("v nan 0 0", "NaN"),
            ("v 0 inf 0", "inf"),
            ("v 0 0 -1e39", "-1e39"),
            // tobj divides by w: x / w is what must fit.
            ("v 1e30 0 0 1e-30", "1e60"),
            ("vn 0 NaN 1", "NaN"),
            ("vt 1e40 0", "1e40"),
        ] {
            let text = format!("v 0 0 0\nv 1 0 0\n{line}\nv 0 1 0\n{tri}");
            let (at, message) = first_bad_obj_line(&text).expect(line);
            assert_eq!(at, 3, "{line}");
            assert!(
                message.contains(&format!("a coordinate is {shown},"))
                    && message.contains("finite"),
                "{line}: {message}"
            );
        }
        // Large but representable, the smallest subnormal, what a w brings back into range,
        // and numbers tobj does not keep (vertex colours, a third uv, a comment) are fine.
        for fine in [
            "v 3e38 -3e38 1e-45\nvt 0 1\n",
            "v 1e40 0 0 1e10\n",
            "v 1 0 0 inf\n",
            "v 0 0 0 nan 0 0\n",
            "vt 0 0 1e39\n",
            "vt 0 0 # inf\n",
            "vn 0 0 1 nan\n",
        ] {
            assert_eq!(first_bad_obj_line(fine), None, "{fine}");
        }
    }

    #[test]
    fn tf_is_read_as_transmission() {
        let tf = |v: &str| transmission_filter(Some(&v.to_string()), Path::new("a.mtl"), "m");
        assert_eq!(tf("1 1 1"), Ok(Some(1.0)));
        assert_eq!(tf("0.25 0.5 0.75"), Ok(Some(0.5)));
        assert_eq!(tf("0.5"), Ok(Some(0.5)));
        assert_eq!(tf("spectral glass.rfl"), Ok(None));
        let e = tf("1 x 1").unwrap_err();
        assert!(
            e.to_string().contains("a.mtl") && e.to_string().contains("Tf 1 x 1"),
            "{e}"
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
