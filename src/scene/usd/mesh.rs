//! `UsdGeomMesh` to primitives: polygons triangulated as fans (winding reversed for
//! `orientation = "leftHanded"`), normals and texture coordinates of any interpolation
//! (`vertex`/`varying`, `faceVarying`, `uniform`, `constant`, indexed or not), one primitive
//! per `materialBind` subset, time-sampled points as a point cache.
//!
//! The renderer's vertices carry one normal and one uv each, so face corners are turned into
//! vertices: corners with the same point, normal and uv share a vertex. Each vertex remembers
//! its point (`Primitive::point_of_vertex`), through which per-point data (skin influences,
//! blend-shape offsets, point-cache samples) reaches it.
//!
//! Invariants on `Ok`: positions, normals and uvs are finite, one per vertex; indices are
//! in range and whole triangles; every point index of the file was checked against the
//! points.

use std::collections::HashMap;

use glam::{Vec2, Vec3};
use openusd::sdf::Value;
use openusd::usd::Prim;

use super::values::{Reader, attr_path, colors, first_nonfinite, ints, token, vec2s, vec3s};
use crate::scene::PointCacheDesc;

/// How a primvar's elements map onto the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Interpolation {
    Constant,
    Uniform,
    /// `vertex` and `varying` (the same for a polygon mesh).
    Vertex,
    FaceVarying,
}

/// A primvar's values (indices already applied) and their interpolation.
struct Primvar<T> {
    values: Vec<T>,
    interpolation: Interpolation,
}

impl<T: Copy> Primvar<T> {
    /// The value at face `face`, corner `corner` (flat index), point `point`.
    fn at(&self, face: usize, corner: usize, point: usize) -> T {
        match self.interpolation {
            Interpolation::Constant => self.values[0],
            Interpolation::Uniform => self.values[face],
            Interpolation::Vertex => self.values[point],
            Interpolation::FaceVarying => self.values[corner],
        }
    }
}

/// The mesh's polygons, checked.
pub(super) struct Topology {
    pub points: Vec<Vec3>,
    counts: Vec<usize>,
    indices: Vec<u32>,
    left_handed: bool,
    /// Faces to skip (`holeIndices`, or fewer than 3 corners).
    skipped: Vec<bool>,
}

impl Topology {
    pub fn face_count(&self) -> usize {
        self.counts.len()
    }
}

/// Reads points, faces and orientation.
pub(super) fn topology(
    reader: &Reader,
    prim: &Prim,
    notes: &mut Vec<String>,
) -> Result<Topology, String> {
    let path = prim.path().as_str();
    let points = match reader.static_value(prim, "points")? {
        Some(v) => vec3s(&v)
            .ok_or_else(|| format!("{}: expected point3f[] values", attr_path(prim, "points")))?,
        None => Vec::new(),
    };
    if let Some(i) = first_nonfinite(&points) {
        return Err(format!("{path}: point {i} is not finite ({})", points[i]));
    }
    let mut int_array = |name: &str| -> Result<Vec<i64>, String> {
        if reader.sample_count(prim, name)? > 1 {
            notes.push(format!(
                "{}: topology changes over time, which is not supported: the first sample is used",
                attr_path(prim, name)
            ));
        }
        match reader.static_value(prim, name)? {
            Some(v) => {
                ints(&v).ok_or_else(|| format!("{}: expected int[] values", attr_path(prim, name)))
            }
            None => Ok(Vec::new()),
        }
    };
    let raw_counts = int_array("faceVertexCounts")?;
    let raw_indices = int_array("faceVertexIndices")?;
    let mut counts = Vec::with_capacity(raw_counts.len());
    let mut total: usize = 0;
    for (f, &c) in raw_counts.iter().enumerate() {
        let c = usize::try_from(c)
            .map_err(|_| format!("{path}: face {f} has a negative vertex count {c}"))?;
        total = total.saturating_add(c);
        counts.push(c);
    }
    if total != raw_indices.len() {
        return Err(format!(
            "{path}: faceVertexCounts add up to {total} corners but faceVertexIndices has {}",
            raw_indices.len()
        ));
    }
    let mut indices = Vec::with_capacity(raw_indices.len());
    for (k, &i) in raw_indices.iter().enumerate() {
        match u32::try_from(i) {
            Ok(i) if (i as usize) < points.len() => indices.push(i),
            _ => {
                return Err(format!(
                    "{path}: faceVertexIndices[{k}] = {i} is outside the {} points",
                    points.len()
                ));
            }
        }
    }
    let left_handed = match reader
        .default_value(prim, "orientation")?
        .as_ref()
        .and_then(token)
    {
        Some(t) if t == "leftHanded" => true,
        Some(t) if t == "rightHanded" => false,
        Some(t) => {
            return Err(format!(
                "{}: unknown orientation '{t}'",
                attr_path(prim, "orientation")
            ));
        }
        None => false,
    };
    let mut skipped: Vec<bool> = counts.iter().map(|&c| c < 3).collect();
    let small = skipped.iter().filter(|&&s| s).count();
    if small > 0 {
        notes.push(format!(
            "{path}: {small} face(s) with fewer than 3 corners skipped"
        ));
    }
    if let Some(holes) = reader
        .static_value(prim, "holeIndices")?
        .as_ref()
        .and_then(ints)
    {
        let mut count = 0;
        for h in holes {
            if let Some(s) = usize::try_from(h).ok().and_then(|h| skipped.get_mut(h)) {
                *s = true;
                count += 1;
            }
        }
        if count > 0 {
            notes.push(format!(
                "{path}: {count} hole face(s) (holeIndices) left out"
            ));
        }
    }
    if let Some(scheme) = reader
        .default_value(prim, "subdivisionScheme")?
        .as_ref()
        .and_then(token)
    {
        if scheme != "none" {
            notes.push(format!(
                "{path}: subdivisionScheme '{scheme}' is rendered as its control polygons (no subdivision)"
            ));
        }
    } else {
        notes.push(format!(
            "{path}: subdivisionScheme unauthored (catmullClark by default) is rendered as its control polygons (no subdivision)"
        ));
    }
    Ok(Topology {
        points,
        counts,
        indices,
        left_handed,
        skipped,
    })
}

/// One triangulated primitive of a mesh, before it becomes a `PrimitiveDesc`.
#[derive(Debug, Default)]
pub(super) struct Primitive {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<u32>,
    /// The point each vertex was made from.
    pub point_of_vertex: Vec<u32>,
    /// The face-varying corner each vertex was made from (first one).
    pub corner_of_vertex: Vec<u32>,
}

/// What to read besides points: the uv primvar's name (`None`: no uvs) and its transform.
pub(super) struct Wanted<'a> {
    pub uv_primvar: Option<&'a str>,
    pub uv_transform: &'a dyn Fn(Vec2) -> Vec2,
}

/// Triangulates the faces `faces` (`None`: every face) into one primitive.
pub(super) fn triangulate(
    reader: &Reader,
    prim: &Prim,
    topology: &Topology,
    faces: Option<&[bool]>,
    wanted: &Wanted,
    normals_vary: bool,
    notes: &mut Vec<String>,
) -> Result<Primitive, String> {
    let normals = normals_primvar(reader, prim, topology)?;
    let uvs = match wanted.uv_primvar {
        Some(name) => {
            let attr = format!("primvars:{name}");
            // A primvar reader's `varname` is any token (empty by default): one that names
            // no property names no primvar the mesh has.
            let uvs = if super::values::is_property_name(&attr) {
                primvar(reader, prim, &attr, topology, vec2s, "texCoord2f[]")?
            } else {
                None
            };
            if uvs.is_none() {
                notes.push(format!(
                    "{}: the material reads primvar '{name}', which the mesh does not have; untextured",
                    prim.path().as_str()
                ));
            }
            uvs
        }
        None => None,
    };
    if let Some(n) = &normals
        && let Some(i) = first_nonfinite(&n.values)
    {
        return Err(format!(
            "{}: normal {i} is not finite",
            prim.path().as_str()
        ));
    }
    if let Some(uv) = &uvs
        && let Some(i) = uv.values.iter().position(|v| !v.is_finite())
    {
        return Err(format!(
            "{}: texture coordinate {i} is not finite",
            prim.path().as_str()
        ));
    }
    let mut out = Primitive {
        normals: normals.as_ref().map(|_| Vec::new()),
        uvs: uvs.as_ref().map(|_| Vec::new()),
        ..Default::default()
    };
    // Corners that agree in point, normal and uv share a vertex. With time-varying normals
    // that are not per point, corners never share (their normals may part later).
    let mut vertex_of: HashMap<(u32, [u32; 3], [u32; 2], u32), u32> = HashMap::new();
    let mut corner = 0usize;
    let mut polygon: Vec<u32> = Vec::new();
    for (face, &count) in topology.counts.iter().enumerate() {
        let first = corner;
        corner += count;
        if topology.skipped[face] || faces.is_some_and(|f| !f[face]) {
            continue;
        }
        polygon.clear();
        for c in first..first + count {
            let point = topology.indices[c];
            let normal = normals.as_ref().map(|n| n.at(face, c, point as usize));
            let uv = uvs
                .as_ref()
                .map(|u| (wanted.uv_transform)(u.at(face, c, point as usize)));
            let uv = uv.map(|uv| Vec2::new(uv.x, 1.0 - uv.y));
            let unshared = normals_vary
                && normals
                    .as_ref()
                    .is_some_and(|n| n.interpolation != Interpolation::Vertex);
            let key = (
                point,
                normal.map_or([0; 3], |n| n.to_array().map(f32::to_bits)),
                uv.map_or([0; 2], |uv| uv.to_array().map(f32::to_bits)),
                if unshared { c as u32 } else { 0 },
            );
            let next = out.positions.len() as u32;
            let vertex = *vertex_of.entry(key).or_insert_with(|| {
                out.positions.push(topology.points[point as usize]);
                if let (Some(ns), Some(n)) = (out.normals.as_mut(), normal) {
                    ns.push(n.try_normalize().unwrap_or(Vec3::ZERO));
                }
                if let (Some(us), Some(uv)) = (out.uvs.as_mut(), uv) {
                    us.push(uv);
                }
                out.point_of_vertex.push(point);
                out.corner_of_vertex.push(c as u32);
                next
            });
            polygon.push(vertex);
        }
        for k in 1..polygon.len() - 1 {
            let (b, c) = if topology.left_handed {
                (polygon[k + 1], polygon[k])
            } else {
                (polygon[k], polygon[k + 1])
            };
            out.indices.extend([polygon[0], b, c]);
        }
    }
    Ok(out)
}

/// `primvars:normals` (which wins) or `normals`, of the stage's first sample or default.
fn normals_primvar(
    reader: &Reader,
    prim: &Prim,
    topology: &Topology,
) -> Result<Option<Primvar<Vec3>>, String> {
    if let Some(n) = primvar(
        reader,
        prim,
        "primvars:normals",
        topology,
        vec3s,
        "normal3f[]",
    )? {
        return Ok(Some(n));
    }
    primvar(reader, prim, "normals", topology, vec3s, "normal3f[]")
}

/// Whether the mesh's normals are time-sampled.
pub(super) fn normals_vary(reader: &Reader, prim: &Prim) -> Result<bool, String> {
    let name = if reader.has_value(prim, "primvars:normals")? {
        "primvars:normals"
    } else {
        "normals"
    };
    Ok(reader.sample_count(prim, name)? > 1)
}

/// A primvar's values with indices applied, checked against the topology; `None` when the
/// mesh does not author it.
fn primvar<T: Copy>(
    reader: &Reader,
    prim: &Prim,
    name: &str,
    topology: &Topology,
    convert: impl Fn(&Value) -> Option<Vec<T>>,
    expected: &str,
) -> Result<Option<Primvar<T>>, String> {
    let Some(value) = reader.static_value(prim, name)? else {
        return Ok(None);
    };
    let values = convert(&value)
        .ok_or_else(|| format!("{}: expected {expected} values", attr_path(prim, name)))?;
    primvar_from(reader, prim, name, topology, values).map(Some)
}

/// Applies `NAME:indices` and checks the element count of `values` for its interpolation.
fn primvar_from<T: Copy>(
    reader: &Reader,
    prim: &Prim,
    name: &str,
    topology: &Topology,
    values: Vec<T>,
) -> Result<Primvar<T>, String> {
    let what = attr_path(prim, name);
    let interpolation = interpolation(reader, prim, name, &what)?;
    let indices_name = format!("{name}:indices");
    let values = match reader
        .static_value(prim, &indices_name)?
        .as_ref()
        .and_then(ints)
    {
        Some(indices) => indices
            .iter()
            .enumerate()
            .map(|(k, &i)| {
                usize::try_from(i)
                    .ok()
                    .and_then(|i| values.get(i).copied())
                    .ok_or_else(|| {
                        format!(
                            "{what}: index {k} ({i}) is outside its {} values",
                            values.len()
                        )
                    })
            })
            .collect::<Result<Vec<T>, String>>()?,
        None => values,
    };
    let needed = match interpolation {
        Interpolation::Constant => 1,
        Interpolation::Uniform => topology.counts.len(),
        Interpolation::Vertex => topology.points.len(),
        Interpolation::FaceVarying => topology.indices.len(),
    };
    if values.len() < needed {
        return Err(format!(
            "{what}: {:?} interpolation needs {needed} values but there are {}",
            interpolation,
            values.len()
        ));
    }
    Ok(Primvar {
        values,
        interpolation,
    })
}

fn interpolation(
    reader: &Reader,
    prim: &Prim,
    name: &str,
    what: &str,
) -> Result<Interpolation, String> {
    Ok(
        match reader
            .attr_token_metadata(prim, name, "interpolation")
            .as_deref()
        {
            None | Some("vertex") | Some("varying") => Interpolation::Vertex,
            Some("faceVarying") => Interpolation::FaceVarying,
            Some("uniform") => Interpolation::Uniform,
            Some("constant") => Interpolation::Constant,
            Some(other) => return Err(format!("{what}: unknown interpolation '{other}'")),
        },
    )
}

/// The mesh's `displayColor`: its single value, or the average of several (with a note,
/// as the renderer has no per-vertex colour). `None` when unauthored.
pub(super) fn display_color(
    reader: &Reader,
    prim: &Prim,
    notes: &mut Vec<String>,
) -> Result<Option<Vec3>, String> {
    let Some(value) = reader.static_value(prim, "primvars:displayColor")? else {
        return Ok(None);
    };
    let colors = colors(&value).ok_or_else(|| {
        format!(
            "{}: expected color3f[] values",
            attr_path(prim, "primvars:displayColor")
        )
    })?;
    if colors.iter().any(|c| !c.is_finite()) {
        return Err(format!(
            "{}: a colour is not finite",
            attr_path(prim, "primvars:displayColor")
        ));
    }
    match colors.as_slice() {
        [] => Ok(None),
        [c] => Ok(Some(c.max(Vec3::ZERO))),
        many => {
            notes.push(format!(
                "{}: displayColor varies over the mesh; its average colour is used",
                prim.path().as_str()
            ));
            let sum: Vec3 = many.iter().copied().sum();
            Ok(Some((sum / many.len() as f32).max(Vec3::ZERO)))
        }
    }
}

/// Time-sampled points (and normals) as a point cache over `primitive`'s vertices, with
/// the sample times in seconds; `None` when the points do not change over time. A sample
/// whose point count differs from the rest pose stops the cache there (noted).
pub(super) fn point_cache(
    reader: &Reader,
    prim: &Prim,
    topology: &Topology,
    primitives: &[Primitive],
    notes: &mut Vec<String>,
) -> Result<Option<(Vec<f32>, Vec<PointCacheDesc>)>, String> {
    let path = prim.path().as_str();
    let samples = reader.samples(prim, "points")?;
    if samples.values.len() < 2 {
        return Ok(None);
    }
    let mut times = Vec::new();
    let mut per_sample: Vec<Vec<Vec3>> = Vec::new();
    for (time, value) in samples.times.iter().zip(&samples.values) {
        let points = vec3s(value)
            .ok_or_else(|| format!("{}: expected point3f[] values", attr_path(prim, "points")))?;
        if points.len() != topology.points.len() {
            notes.push(format!(
                "{path}: points change count at t = {time} s ({} instead of {}): the point cache stops before it",
                points.len(),
                topology.points.len()
            ));
            break;
        }
        if let Some(i) = first_nonfinite(&points) {
            return Err(format!(
                "{path}: point {i} of the sample at t = {time} s is not finite"
            ));
        }
        times.push(*time);
        per_sample.push(points);
    }
    if per_sample.len() < 2 || per_sample.iter().all(|s| *s == per_sample[0]) {
        return Ok(None);
    }
    let normal_samples = cached_normals(reader, prim, topology, &times, notes)?;
    let caches = primitives
        .iter()
        .map(|p| {
            let positions = per_sample
                .iter()
                .map(|points| {
                    p.point_of_vertex
                        .iter()
                        .map(|&i| points[i as usize])
                        .collect()
                })
                .collect();
            let normals = match (&normal_samples, &p.normals) {
                (Some(samples), Some(_)) => Some(
                    samples
                        .iter()
                        .map(|n| {
                            p.point_of_vertex
                                .iter()
                                .zip(&p.corner_of_vertex)
                                .map(|(&point, &corner)| {
                                    let v = match n.interpolation {
                                        Interpolation::Vertex => n.values[point as usize],
                                        Interpolation::FaceVarying => n.values[corner as usize],
                                        _ => n.values[0],
                                    };
                                    v.try_normalize().unwrap_or(Vec3::ZERO)
                                })
                                .collect()
                        })
                        .collect(),
                ),
                _ => None,
            };
            PointCacheDesc { positions, normals }
        })
        .collect();
    Ok(Some((times, caches)))
}

/// Time-sampled normals at the cache's sample times (per point or per corner), or `None`
/// when they do not vary (the rest normals then hold at every time, as USD reads them).
fn cached_normals(
    reader: &Reader,
    prim: &Prim,
    topology: &Topology,
    times: &[f32],
    notes: &mut Vec<String>,
) -> Result<Option<Vec<Primvar<Vec3>>>, String> {
    let name = if reader.has_value(prim, "primvars:normals")? {
        "primvars:normals"
    } else {
        "normals"
    };
    let samples = reader.samples(prim, name)?;
    if samples.values.len() < 2 {
        return Ok(None);
    }
    if samples.times.get(..times.len()) != Some(times) {
        notes.push(format!(
            "{}: normals are sampled at other times than points; the rest normals are used",
            prim.path().as_str()
        ));
        return Ok(None);
    }
    let mut out = Vec::with_capacity(times.len());
    for value in samples.values.iter().take(times.len()) {
        let values = vec3s(value)
            .ok_or_else(|| format!("{}: expected normal3f[] values", attr_path(prim, name)))?;
        if let Some(i) = first_nonfinite(&values) {
            return Err(format!(
                "{}: normal {i} of a sample is not finite",
                attr_path(prim, name)
            ));
        }
        let primvar = primvar_from(reader, prim, name, topology, values)?;
        if !matches!(
            primvar.interpolation,
            Interpolation::Vertex | Interpolation::FaceVarying
        ) {
            return Ok(None);
        }
        out.push(primvar);
    }
    Ok(Some(out))
}
