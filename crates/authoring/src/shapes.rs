//! Triangle-mesh geometry for authored scenes ([`MeshData`]) and generators for the basic
//! shapes: a vertical quad, a horizontal plane with UV repeat, a box with one UV square per
//! face, and a UV sphere.
//!
//! Conventions (glTF's): right-handed, +Y up; triangles wind counter-clockwise seen from
//! the side their normals point to; UV (0, 0) is the image's top-left, so `v` grows
//! downward on upright faces.

use glam::{Affine3A, Mat3, Vec2, Vec3};

/// One morph target of a geometry: per-vertex displacements added, scaled by the target's
/// weight, to the base positions (and normals) (glTF `mesh.primitives[].targets`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MorphTarget {
    /// POSITION deltas, one per base vertex.
    pub positions: Vec<Vec3>,
    /// NORMAL deltas, one per base vertex; only allowed when the base has normals.
    pub normals: Option<Vec<Vec3>>,
}

/// An indexed triangle list in object space, optionally with morph targets.
///
/// Invariants checked by [`MeshData::validate`]: `normals` and `uvs`, when present, have
/// one entry per position; `indices.len()` is a positive multiple of 3 and every index is
/// `< positions.len()`; all numbers are finite; every morph target has one delta per
/// position, and either all targets carry normal deltas (and the base has normals) or none.
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
    /// Morph targets (deltas over this base geometry), written as the primitive's `targets`.
    pub morph_targets: Vec<MorphTarget>,
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

    /// The geometry moved by `transform`: positions transformed, normals (and morph deltas)
    /// by its linear part's inverse transpose, normals re-normalized. A transform with a
    /// negative determinant would flip the winding, so it is refused.
    ///
    /// # Panics
    /// If `transform`'s linear part has a non-positive determinant.
    pub fn transformed(mut self, transform: Affine3A) -> Self {
        let linear = Mat3::from(transform.matrix3);
        assert!(
            linear.determinant() > 0.0,
            "transform must keep the winding"
        );
        let normal_matrix = linear.inverse().transpose();
        for p in &mut self.positions {
            *p = transform.transform_point3(*p);
        }
        if let Some(normals) = &mut self.normals {
            for n in normals {
                *n = (normal_matrix * *n).normalize();
            }
        }
        for target in &mut self.morph_targets {
            for d in &mut target.positions {
                *d = linear * *d;
            }
            if let Some(normals) = &mut target.normals {
                for d in normals {
                    *d = normal_matrix * *d;
                }
            }
        }
        self
    }

    /// The same geometry moved by `offset`.
    pub fn translated(self, offset: Vec3) -> Self {
        self.transformed(Affine3A::from_translation(offset))
    }

    /// Appends `other`'s triangles. Both must have the same attributes (normals, UVs) and
    /// neither may have morph targets.
    ///
    /// # Panics
    /// If the attributes differ or either has morph targets.
    pub fn append(&mut self, other: MeshData) {
        assert!(
            self.morph_targets.is_empty() && other.morph_targets.is_empty(),
            "cannot append geometries with morph targets"
        );
        assert_eq!(self.normals.is_some(), other.normals.is_some(), "normals");
        assert_eq!(self.uvs.is_some(), other.uvs.is_some(), "uvs");
        let base = self.positions.len() as u32;
        self.positions.extend(other.positions);
        if let (Some(a), Some(b)) = (&mut self.normals, other.normals) {
            a.extend(b);
        }
        if let (Some(a), Some(b)) = (&mut self.uvs, other.uvs) {
            a.extend(b);
        }
        self.indices.extend(other.indices.iter().map(|i| i + base));
    }

    /// `parts` appended into one geometry (see [`append`](MeshData::append)).
    ///
    /// # Panics
    /// If `parts` is empty or [`append`](MeshData::append) panics.
    pub fn merged(parts: impl IntoIterator<Item = MeshData>) -> MeshData {
        let mut parts = parts.into_iter();
        let mut mesh = parts.next().expect("at least one part");
        for part in parts {
            mesh.append(part);
        }
        mesh
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
        let with_normals = self.morph_targets.first().map(|t| t.normals.is_some());
        for (i, target) in self.morph_targets.iter().enumerate() {
            if target.positions.len() != n || target.positions.iter().any(|d| !d.is_finite()) {
                return Err(format!("morph target {i} needs {n} finite position deltas"));
            }
            if Some(target.normals.is_some()) != with_normals {
                return Err("morph targets must all have normal deltas or none".into());
            }
            if let Some(normals) = &target.normals {
                if self.normals.is_none() {
                    return Err(format!(
                        "morph target {i} has normal deltas but the base has no normals"
                    ));
                }
                if normals.len() != n || normals.iter().any(|d| !d.is_finite()) {
                    return Err(format!("morph target {i} needs {n} finite normal deltas"));
                }
            }
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
        morph_targets: Vec::new(),
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
        morph_targets: Vec::new(),
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

/// A closed cylinder of `radius` and `height` along +Y, centred on the origin, with
/// `segments` slices: smooth side normals, flat caps. Side UVs run once around (u) and from
/// the top (v = 0) to the bottom (v = 1); cap UVs map the disc onto the unit square.
///
/// # Panics
/// If `segments < 3`.
pub fn cylinder(radius: f32, height: f32, segments: u32) -> MeshData {
    assert!(segments >= 3, "a cylinder needs >= 3 segments");
    let mut mesh = MeshData {
        normals: Some(Vec::new()),
        uvs: Some(Vec::new()),
        ..MeshData::default()
    };
    let push = |mesh: &mut MeshData, p: Vec3, n: Vec3, uv: Vec2| {
        mesh.positions.push(p);
        mesh.normals.as_mut().unwrap().push(n);
        mesh.uvs.as_mut().unwrap().push(uv);
    };
    let hh = height / 2.0;
    // Around +Y counter-clockwise seen from above: direction (sin a, 0, cos a).
    let dir = |s: u32| {
        let a = std::f32::consts::TAU * s as f32 / segments as f32;
        Vec3::new(a.sin(), 0.0, a.cos())
    };
    for s in 0..=segments {
        let d = dir(s);
        let u = s as f32 / segments as f32;
        push(&mut mesh, d * radius + hh * Vec3::Y, d, Vec2::new(u, 0.0));
        push(&mut mesh, d * radius - hh * Vec3::Y, d, Vec2::new(u, 1.0));
    }
    for s in 0..segments {
        let (t0, b0, t1, b1) = (2 * s, 2 * s + 1, 2 * s + 2, 2 * s + 3);
        mesh.indices.extend([t0, b0, b1, t0, b1, t1]);
    }
    for (y, normal) in [(hh, Vec3::Y), (-hh, Vec3::NEG_Y)] {
        let centre = mesh.positions.len() as u32;
        push(&mut mesh, y * Vec3::Y, normal, Vec2::splat(0.5));
        for s in 0..segments {
            let d = dir(s);
            push(
                &mut mesh,
                d * radius + y * Vec3::Y,
                normal,
                Vec2::new(0.5 + 0.5 * d.x, 0.5 + 0.5 * d.z),
            );
        }
        for s in 0..segments {
            let (a, b) = (centre + 1 + s, centre + 1 + (s + 1) % segments);
            if normal.y > 0.0 {
                mesh.indices.extend([centre, a, b]);
            } else {
                mesh.indices.extend([centre, b, a]);
            }
        }
    }
    mesh
}

/// A sphere of `radius` made by subdividing an icosahedron `subdivisions` times: each level
/// splits every triangle into four, so it has `20 * 4^subdivisions` triangles of nearly
/// equal size. Vertices are shared (smooth normals, no UVs), which suits morph targets.
pub fn icosphere(radius: f32, subdivisions: u32) -> MeshData {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let p = (positions[a as usize] + positions[b as usize]).normalize();
                positions.push(p);
                positions.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(triangles.len() * 4);
        for [a, b, c] in triangles {
            let ab = midpoint(a, b, &mut positions);
            let bc = midpoint(b, c, &mut positions);
            let ca = midpoint(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        triangles = next;
    }
    MeshData {
        normals: Some(positions.clone()),
        positions: positions.iter().map(|p| *p * radius).collect(),
        uvs: None,
        indices: triangles.into_iter().flatten().collect(),
        morph_targets: Vec::new(),
    }
}

/// Area-weighted smooth vertex normals of an indexed triangle list over `positions`
/// (vertices no triangle uses get +Y).
pub fn smooth_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut normals = vec![Vec3::ZERO; positions.len()];
    for tri in indices.chunks(3) {
        let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| positions[i as usize]);
        let face = (b - a).cross(c - a);
        for &i in tri {
            normals[i as usize] += face;
        }
    }
    normals
        .into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Y))
        .collect()
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
    fn cylinder_and_icosphere_wind_outward() {
        let c = cylinder(0.5, 2.0, 12);
        assert_winding_matches_normals(&c);
        assert_eq!(c.triangle_count(), 4 * 12);
        let (lo, hi) = c.bounds().unwrap();
        assert!((hi.y - 1.0).abs() < 1e-6 && (lo.y + 1.0).abs() < 1e-6);
        for s in 0..3 {
            let m = icosphere(2.0, s);
            assert_winding_matches_normals(&m);
            assert_eq!(m.triangle_count(), 20 * 4usize.pow(s));
            assert_eq!(m.positions.len(), 10 * 4usize.pow(s) + 2);
            assert!(m.positions.iter().all(|p| (p.length() - 2.0).abs() < 1e-5));
        }
    }

    #[test]
    fn transformed_moves_positions_and_keeps_unit_normals() {
        let m = cuboid(Vec3::ONE).transformed(Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, 1.0, 1.0),
            glam::Quat::from_rotation_y(0.3),
            Vec3::Y,
        ));
        assert_winding_matches_normals(&m);
        let mut two = cuboid(Vec3::ONE);
        two.append(cuboid(Vec3::ONE).translated(Vec3::X * 3.0));
        assert_eq!(two.triangle_count(), 24);
        assert_eq!(two.bounds().unwrap().1, Vec3::new(3.5, 0.5, 0.5));
        two.validate().unwrap();
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
