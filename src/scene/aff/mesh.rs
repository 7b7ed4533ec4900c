//! The `m` command: an indexed mesh with independent per-attribute indices (as OBJ),
//! expanded so that one index list addresses positions, normals and UVs together.
//!
//! ```text
//! m vertices nv (x y z)*  [normals nn (x y z)*]  [texturecoords nt texname (u v)*]
//!   triangles ntri (v0 v1 v2 [n0 n1 n2] [t0 t1 t2])*
//! ```
//! Each distinct (vertex, normal, texcoord) index triple of a corner becomes one output
//! vertex (shared by the corners that use the same triple). Normals are normalised; a zero
//! normal is replaced by the face normal of the first triangle using it.

use std::collections::HashMap;

use glam::{Vec2, Vec3};

use super::builder::Geometry;
use super::reader::Reader;

/// Largest count accepted for one attribute or the triangle list (the reference stores
/// indices as u16; this only guards against absurd allocations in malformed files).
const MAX_COUNT: usize = 1 << 26;

/// A parsed `m`: its geometry and its texture name with the line it appears on.
pub struct ParsedMesh {
    pub geometry: Geometry,
    pub texture: Option<(String, u32)>,
}

fn read_list<T>(
    r: &mut Reader,
    n: usize,
    mut read: impl FnMut(&mut Reader) -> Result<T, String>,
) -> Result<Vec<T>, String> {
    let mut v = Vec::with_capacity(n.min(1 << 16));
    for _ in 0..n {
        v.push(read(r)?);
    }
    Ok(v)
}

/// Reads an `m` command (the `m` token already consumed).
pub fn read_mesh(r: &mut Reader) -> Result<ParsedMesh, String> {
    r.expect("vertices", "m")?;
    let nv = r.count("vertices", MAX_COUNT)?;
    let vertices = read_list(r, nv, |r| r.vec3("vertices"))?;
    let normals = if r.accept("normals") {
        let nn = r.count("normals", MAX_COUNT)?;
        Some(read_list(r, nn, |r| r.vec3("normals"))?)
    } else {
        None
    };
    let (uvs, texture) = if r.accept("texturecoords") {
        let nt = r.count("texturecoords", MAX_COUNT)?;
        let name = r.name("texturecoords")?;
        (
            Some(read_list(r, nt, |r| r.vec2("texturecoords"))?),
            Some(name),
        )
    } else {
        (None, None)
    };
    r.expect("triangles", "m")?;
    let ntri = r.count("triangles", MAX_COUNT)?;

    let mut g = Geometry {
        normals: normals.as_ref().map(|_| Vec::new()),
        uvs: uvs.as_ref().map(|_| Vec::new()),
        ..Default::default()
    };
    let mut corner_vertex: HashMap<(u32, u32, u32), u32> = HashMap::new();
    let index = |r: &mut Reader, len: usize, what: &str| -> Result<u32, String> {
        let line = r.peek().map_or(r.lexer.line(), |t| t.line);
        let i = r.int("triangles")?;
        if i < 0 || i as u64 >= len as u64 {
            return Err(r.error_at(
                line,
                format!("{what} index {i} out of range (the mesh has {len})"),
            ));
        }
        Ok(i as u32)
    };
    for _ in 0..ntri {
        let mut corners = [(0u32, u32::MAX, u32::MAX); 3];
        for c in &mut corners {
            c.0 = index(r, vertices.len(), "vertex")?;
        }
        if let Some(n) = &normals {
            for c in &mut corners {
                c.1 = index(r, n.len(), "normal")?;
            }
        }
        if let Some(t) = &uvs {
            for c in &mut corners {
                c.2 = index(r, t.len(), "texture coordinate")?;
            }
        }
        let face = {
            let [a, b, c] = corners.map(|c| vertices[c.0 as usize]);
            (b - a).cross(c - a).try_normalize().unwrap_or(Vec3::Z)
        };
        for c in corners {
            let next = g.positions.len() as u32;
            let v = *corner_vertex.entry(c).or_insert_with(|| {
                g.positions.push(vertices[c.0 as usize]);
                if let (Some(dst), Some(src)) = (g.normals.as_mut(), normals.as_ref()) {
                    dst.push(src[c.1 as usize].try_normalize().unwrap_or(face));
                }
                if let (Some(dst), Some(src)) = (g.uvs.as_mut(), uvs.as_ref()) {
                    let uv: Vec2 = src[c.2 as usize];
                    dst.push(uv);
                }
                next
            });
            g.indices.push(v);
        }
    }
    Ok(ParsedMesh {
        geometry: g,
        texture,
    })
}
