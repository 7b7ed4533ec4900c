//! Triangle-mesh geometry for authored scenes ([`MeshData`]) and generators for the basic
//! shapes: a vertical quad, a horizontal plane with UV repeat, a box with one UV square per
//! face, and a UV sphere.
//!
//! Conventions (glTF's): right-handed, +Y up; triangles wind counter-clockwise seen from
//! the side their normals point to; UV (0, 0) is the image's top-left, so `v` grows
//! downward on upright faces.

use glam::{Vec2, Vec3};

/// An indexed triangle list in object space.
///
/// Invariants checked by [`MeshData::validate`]: `normals` and `uvs`, when present, have
/// one entry per position; `indices.len()` is a positive multiple of 3 and every index is
/// `< positions.len()`; all numbers are finite.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MeshData {
    /// Vertex positions in object space (metres).
    pub positions: Vec<Vec3>,
    /// Unit-length vertex normals.
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates (set 0).
    pub uvs: Option<Vec<Vec2>>,
    /// Three indices per triangle.
    pub indices: Vec<u32>,
}

impl MeshData {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The same geometry without texture coordinates (for untextured materials).
    pub fn without_uvs(mut self) -> Self {
        self.uvs = None;
        self
    }

    /// Component-wise minimum and maximum of the positions (`None` when there are none).
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))),
        )
    }

    /// Checks the invariants listed on the type.
    ///
    /// # Errors
    /// A message naming the first broken invariant.
    pub fn validate(&self) -> Result<(), String> {
        let n = self.positions.len();
        if n == 0 {
            return Err("no positions".into());
        }
        if self.positions.iter().any(|p| !p.is_finite()) {
            return Err("non-finite position".into());
        }
        if let Some(normals) = &self.normals {
            if normals.len() != n {
                return Err(format!("{} normals for {n} positions", normals.len()));
            }
            if normals
                .iter()
                .any(|v| !v.is_finite() || (v.length() - 1.0).abs() > 1e-4)
            {
                return Err("normal that is not unit length".into());
            }
        }
        if let Some(uvs) = &self.uvs {
            if uvs.len() != n {
                return Err(format!("{} uvs for {n} positions", uvs.len()));
            }
            if uvs.iter().any(|v| !v.is_finite()) {
                return Err("non-finite uv".into());
            }
        }
        if self.indices.is_empty() || !self.indices.len().is_multiple_of(3) {
            return Err(format!(
                "{} indices (not a positive multiple of 3)",
                self.indices.len()
            ));
        }
        if let Some(&bad) = self.indices.iter().find(|&&i| i as usize >= n) {
            return Err(format!("index {bad} out of range for {n} positions"));
        }
        Ok(())
    }
}

/// A `width` x `height` rectangle in the XY plane, centred on the origin, facing +Z.
/// UVs run from (0, 0) at the top-left to `uv_repeat` at the bottom-right, so a texture
/// repeats `uv_repeat.x` times across and `uv_repeat.y` times down (with a REPEAT sampler).
pub fn quad(width: f32, height: f32, uv_repeat: Vec2) -> MeshData {
    let (hw, hh) = (width / 2.0, height / 2.0);
    MeshData {
        positions: vec![
            Vec3::new(-hw, hh, 0.0),
            Vec3::new(-hw, -hh, 0.0),
            Vec3::new(hw, -hh, 0.0),
            Vec3::new(hw, hh, 0.0),
        ],
        normals: Some(vec![Vec3::Z; 4]),
        uvs: Some(vec![
            Vec2::ZERO,
            Vec2::new(0.0, uv_repeat.y),
            uv_repeat,
            Vec2::new(uv_repeat.x, 0.0),
        ]),
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// A `width` (along X) by `depth` (along Z) rectangle in the XZ plane, centred on the
/// origin, facing +Y. Seen from above with -Z up, UV (0, 0) is the far-left corner and
/// `uv_repeat` the near-right one.
pub fn plane(width: f32, depth: f32, uv_repeat: Vec2) -> MeshData {
    let (hw, hd) = (width / 2.0, depth / 2.0);
    MeshData {
        positions: vec![
            Vec3::new(-hw, 0.0, -hd),
            Vec3::new(-hw, 0.0, hd),
            Vec3::new(hw, 0.0, hd),
            Vec3::new(hw, 0.0, -hd),
        ],
        normals: Some(vec![Vec3::Y; 4]),
        uvs: Some(vec![
            Vec2::ZERO,
            Vec2::new(0.0, uv_repeat.y),
            uv_repeat,
            Vec2::new(uv_repeat.x, 0.0),
        ]),
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// An axis-aligned box of the given edge lengths centred on the origin: 24 vertices (4 per
/// face, flat normals) and 12 triangles. Each face maps the whole texture, upright on the
/// four side faces as seen from outside; on the top face the image's top edge is at -Z, on
/// the bottom face at +Z.
pub fn cuboid(size: Vec3) -> MeshData {
    let h = size / 2.0;
    // (normal, right, up) of each face seen from outside: the face spans
    // centre +- right +- up, with UV (0, 0) at centre - right + up.
    let faces = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    let mut mesh = MeshData {
        normals: Some(Vec::with_capacity(24)),
        uvs: Some(Vec::with_capacity(24)),
        ..MeshData::default()
    };
    for (normal, right, up) in faces {
        let base = mesh.positions.len() as u32;
        let corners = [(-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (1.0, 1.0)];
        for (r, u) in corners {
            mesh.positions.push((normal + r * right + u * up) * h);
            mesh.normals.as_mut().unwrap().push(normal);
            mesh.uvs
                .as_mut()
                .unwrap()
                .push(Vec2::new((r + 1.0) / 2.0, (1.0 - u) / 2.0));
        }
        mesh.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    mesh
}

/// A sphere of `radius` centred on the origin, built from `segments` slices around +Y and
/// `rings` stacks from pole to pole, with smooth normals. U runs once around +Y, from -X
/// through +Z and +X back to -X (the seam's vertices are duplicated); V runs from 0 at the
/// north pole (+Y) to 1 at the south pole. The pole caps use one triangle per slice, so no
/// triangle is degenerate.
///
/// # Panics
/// If `segments < 3` or `rings < 2`.
pub fn uv_sphere(radius: f32, segments: u32, rings: u32) -> MeshData {
    assert!(
        segments >= 3 && rings >= 2,
        "a sphere needs >= 3 segments and >= 2 rings"
    );
    let mut mesh = MeshData {
        normals: Some(Vec::new()),
        uvs: Some(Vec::new()),
        ..MeshData::default()
    };
    let push = |mesh: &mut MeshData, normal: Vec3, uv: Vec2| {
        mesh.positions.push(normal * radius);
        mesh.normals.as_mut().unwrap().push(normal);
        mesh.uvs.as_mut().unwrap().push(uv);
    };
    // One pole vertex per slice (its UV sits mid-slice), then rings-1 rows of
    // segments+1 vertices (the seam column is duplicated), then the south pole per slice.
    for s in 0..segments {
        push(
            &mut mesh,
            Vec3::Y,
            Vec2::new((s as f32 + 0.5) / segments as f32, 0.0),
        );
    }
    for r in 1..rings {
        let v = r as f32 / rings as f32;
        let polar = v * std::f32::consts::PI;
        for s in 0..=segments {
            let u = s as f32 / segments as f32;
            let azimuth = u * std::f32::consts::TAU;
            let normal = Vec3::new(
                -polar.sin() * azimuth.cos(),
                polar.cos(),
                polar.sin() * azimuth.sin(),
            )
            .normalize();
            push(&mut mesh, normal, Vec2::new(u, v));
        }
    }
    let south = mesh.positions.len() as u32;
    for s in 0..segments {
        push(
            &mut mesh,
            Vec3::NEG_Y,
            Vec2::new((s as f32 + 0.5) / segments as f32, 1.0),
        );
    }
    let row = |r: u32| segments + (r - 1) * (segments + 1);
    for s in 0..segments {
        let (a, b) = (row(1) + s, row(1) + s + 1);
        mesh.indices.extend([s, a, b]);
    }
    for r in 1..rings - 1 {
        for s in 0..segments {
            let (a, b) = (row(r) + s, row(r) + s + 1);
            let (c, d) = (row(r + 1) + s, row(r + 1) + s + 1);
            mesh.indices.extend([a, c, d, a, d, b]);
        }
    }
    for s in 0..segments {
        let (a, b) = (row(rings - 1) + s, row(rings - 1) + s + 1);
        mesh.indices.extend([a, south + s, b]);
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every triangle winds counter-clockwise around the normals of its vertices and has a
    /// positive area.
    fn assert_winding_matches_normals(mesh: &MeshData) {
        mesh.validate().unwrap();
        let normals = mesh.normals.as_ref().unwrap();
        for tri in mesh.indices.chunks(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| mesh.positions[i as usize]);
            let face = (b - a).cross(c - a);
            assert!(face.length() > 1e-8, "degenerate triangle {tri:?}");
            for &i in tri {
                assert!(
                    face.dot(normals[i as usize]) > 0.0,
                    "triangle {tri:?} winds backwards"
                );
            }
        }
    }

    #[test]
    fn quad_faces_plus_z_with_top_left_uv_origin() {
        let m = quad(2.0, 1.0, Vec2::new(3.0, 2.0));
        assert_winding_matches_normals(&m);
        let uvs = m.uvs.as_ref().unwrap();
        assert_eq!(m.positions[0], Vec3::new(-1.0, 0.5, 0.0));
        assert_eq!(uvs[0], Vec2::ZERO);
        assert_eq!(m.positions[2], Vec3::new(1.0, -0.5, 0.0));
        assert_eq!(uvs[2], Vec2::new(3.0, 2.0));
    }

    #[test]
    fn plane_faces_plus_y_and_spans_its_size() {
        let m = plane(400.0, 300.0, Vec2::splat(50.0));
        assert_winding_matches_normals(&m);
        let (lo, hi) = m.bounds().unwrap();
        assert_eq!(lo, Vec3::new(-200.0, 0.0, -150.0));
        assert_eq!(hi, Vec3::new(200.0, 0.0, 150.0));
        assert_eq!(m.uvs.as_ref().unwrap()[2], Vec2::splat(50.0));
    }

    #[test]
    fn cuboid_has_six_outward_faces_with_full_uv_squares() {
        let m = cuboid(Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(m.positions.len(), 24);
        assert_eq!(m.triangle_count(), 12);
        assert_winding_matches_normals(&m);
        let (lo, hi) = m.bounds().unwrap();
        assert_eq!(
            (lo, hi),
            (Vec3::new(-0.5, -1.0, -1.5), Vec3::new(0.5, 1.0, 1.5))
        );
        let normals = m.normals.as_ref().unwrap();
        for (p, n) in m.positions.iter().zip(normals) {
            assert!(p.dot(*n) > 0.0, "normal points inward at {p}");
        }
        // The +Z face is upright: its top-left corner (-x, +y) has UV (0, 0).
        let front = 4 * 4;
        assert_eq!(normals[front], Vec3::Z);
        assert_eq!(m.positions[front], Vec3::new(-0.5, 1.0, 1.5));
        assert_eq!(m.uvs.as_ref().unwrap()[front], Vec2::ZERO);
    }

    #[test]
    fn uv_sphere_is_closed_with_radius_length_positions() {
        let m = uv_sphere(0.7, 16, 8);
        assert_winding_matches_normals(&m);
        for p in &m.positions {
            assert!((p.length() - 0.7).abs() < 1e-5);
        }
        // 2 caps of 16 triangles + 6 bands of 32.
        assert_eq!(m.triangle_count(), 2 * 16 + 6 * 32);
        // Closed surface: every edge is shared by exactly two triangles, in opposite
        // directions (modulo the duplicated seam and pole vertices, merged by position).
        let key = |i: u32| {
            let p = m.positions[i as usize] * 1e4;
            (p.x.round() as i64, p.y.round() as i64, p.z.round() as i64)
        };
        let mut edges = std::collections::HashMap::new();
        for tri in m.indices.chunks(3) {
            for k in 0..3 {
                let e = (key(tri[k]), key(tri[(k + 1) % 3]));
                *edges.entry(e).or_insert(0) += 1;
            }
        }
        for (&(a, b), &count) in &edges {
            assert_eq!(count, 1, "edge {a:?}->{b:?} used {count} times");
            assert_eq!(
                edges.get(&(b, a)),
                Some(&1),
                "edge {a:?}->{b:?} has no twin"
            );
        }
    }
}
