//! Meshes: glTF primitives to indexed triangle lists in object space.
//!
//! Every primitive that comes out has finite positions, normals and UVs, one normal/UV per
//! position, and `indices.len() % 3 == 0` with every index `< positions.len()`.
//! Geometry is the un-deformed base: morph targets (`morph.rs`) and skin influences
//! (`skin.rs`) are loaded beside it and applied per frame by `anim::deform_primitive`.

use glam::{Vec2, Vec3};
use gltf::accessor::Dimensions;
use gltf::mesh::Mode;

use super::accessor::{Integers, read_floats, read_indices};
use super::buffers::Buffers;
use super::material::{UvSource, uv_source};
use super::morph;
use super::skin;
use crate::scene::{MeshDesc, PrimitiveDesc};

/// Per-document counts of things rendered approximately, turned into notes at the end.
#[derive(Default)]
struct Approximations {
    skipped_modes: usize,
    dropped_normals: usize,
    missing_uvs: usize,
    /// Primitives with more than one `JOINTS_n`/`WEIGHTS_n` set, folded into four
    /// influences per vertex.
    folded_influences: usize,
}

/// Whether a primitive mode is loaded (triangles, strips, fans); points and lines are
/// skipped, so a mesh's loaded primitives are its triangle-mode glTF primitives in order.
pub(super) fn is_loaded(mode: Mode) -> bool {
    matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    )
}

/// Loads every mesh; primitives that are not triangles (points, lines) are skipped.
pub(super) fn load_meshes(
    document: &gltf::Document,
    buffers: &Buffers,
    notes: &mut Vec<String>,
) -> Result<Vec<MeshDesc>, String> {
    let mut approximations = Approximations::default();
    let mut meshes = Vec::with_capacity(document.meshes().len());
    for mesh in document.meshes() {
        let weights = morph::default_weights(&mesh)?;
        let mut primitives = Vec::new();
        for primitive in mesh.primitives() {
            let what = format!("mesh {} primitive {}", mesh.index(), primitive.index());
            if let Some(desc) = load_primitive(&primitive, buffers, &what, &mut approximations)? {
                primitives.push(desc);
            }
        }
        meshes.push(MeshDesc {
            name: mesh.name().unwrap_or_default().to_string(),
            primitives,
            weights,
        });
    }
    push_notes(&approximations, notes);
    Ok(meshes)
}

fn push_notes(approximations: &Approximations, notes: &mut Vec<String>) {
    let Approximations {
        skipped_modes,
        dropped_normals,
        missing_uvs,
        folded_influences,
    } = *approximations;
    if skipped_modes > 0 {
        notes.push(format!(
            "{skipped_modes} point/line primitive(s) skipped (only triangles are rendered)"
        ));
    }
    if dropped_normals > 0 {
        notes.push(format!(
            "{dropped_normals} primitive(s) have zero-length normals; they are shaded flat instead"
        ));
    }
    if missing_uvs > 0 {
        notes.push(format!(
            "{missing_uvs} textured primitive(s) lack the UV set their texture reads; rendered untextured"
        ));
    }
    if folded_influences > 0 {
        notes.push(format!(
            "{folded_influences} skinned primitive(s) have more than 4 joint influences per vertex; the 4 largest are kept and rescaled"
        ));
    }
}

/// One primitive as a triangle list, or `None` for a skipped (non-triangle) mode.
fn load_primitive(
    primitive: &gltf::Primitive,
    buffers: &Buffers,
    what: &str,
    approximations: &mut Approximations,
) -> Result<Option<PrimitiveDesc>, String> {
    let mode = primitive.mode();
    if !is_loaded(mode) {
        approximations.skipped_modes += 1;
        return Ok(None);
    }
    let position_accessor = primitive
        .get(&gltf::Semantic::Positions)
        .ok_or_else(|| format!("{what} has no POSITION"))?;
    let positions = read_vec3s(&position_accessor, buffers, &format!("POSITION of {what}"))?;
    let normals = match primitive.get(&gltf::Semantic::Normals) {
        Some(accessor) => Some(read_attribute_vec3s(
            &accessor,
            buffers,
            "NORMAL",
            what,
            positions.len(),
        )?),
        None => None,
    };
    let normals = match normals {
        Some(n) => {
            let unit = normalized(n);
            if unit.is_none() {
                approximations.dropped_normals += 1;
            }
            unit
        }
        None => None,
    };
    let uvs = match uv_source(&primitive.material()) {
        Some(source) => {
            let uvs = read_uvs(primitive, source, buffers, what, positions.len())?;
            if uvs.is_none() {
                approximations.missing_uvs += 1;
            }
            uvs
        }
        None => None,
    };
    let indices = read_triangle_indices(primitive, mode, buffers, what, positions.len())?;
    let influences = skin::read_influences(primitive, buffers, what, positions.len())?;
    if influences.as_ref().is_some_and(|i| i.sets > 1) {
        approximations.folded_influences += 1;
    }
    let (joints, weights) = influences.map_or((None, None), |i| (Some(i.joints), Some(i.weights)));
    let morph_targets =
        morph::read_targets(primitive, buffers, what, positions.len(), normals.is_some())?;
    Ok(Some(PrimitiveDesc {
        positions,
        normals,
        uvs,
        indices,
        material: primitive.material().index(),
        joints,
        weights,
        morph_targets,
        point_cache: None,
    }))
}

/// Reads a FLOAT VEC3 accessor, rejecting non-finite values.
pub(super) fn read_vec3s(
    accessor: &gltf::Accessor,
    buffers: &Buffers,
    what: &str,
) -> Result<Vec<Vec3>, String> {
    let flat = read_floats(
        accessor,
        buffers,
        what,
        Dimensions::Vec3,
        Integers::Rejected,
    )?;
    let vectors: Vec<Vec3> = flat.chunks_exact(3).map(Vec3::from_slice).collect();
    check_finite(&vectors, |v| v.is_finite(), accessor, what)?;
    Ok(vectors)
}

/// Reads a per-vertex VEC3 attribute, which must have one element per position.
pub(super) fn read_attribute_vec3s(
    accessor: &gltf::Accessor,
    buffers: &Buffers,
    semantic: &str,
    what: &str,
    vertex_count: usize,
) -> Result<Vec<Vec3>, String> {
    let label = format!("{semantic} of {what}");
    let values = read_vec3s(accessor, buffers, &label)?;
    check_count(values.len(), vertex_count, accessor, &label)?;
    Ok(values)
}

pub(super) fn check_count(
    count: usize,
    vertex_count: usize,
    accessor: &gltf::Accessor,
    what: &str,
) -> Result<(), String> {
    if count == vertex_count {
        Ok(())
    } else {
        Err(format!(
            "accessor {} ({what}) has {count} elements but POSITION has {vertex_count}",
            accessor.index()
        ))
    }
}

pub(super) fn check_finite<T: std::fmt::Debug>(
    values: &[T],
    is_finite: impl Fn(&T) -> bool,
    accessor: &gltf::Accessor,
    what: &str,
) -> Result<(), String> {
    match values.iter().position(|v| !is_finite(v)) {
        None => Ok(()),
        Some(i) => Err(format!(
            "accessor {} ({what}) has a non-finite value at element {i}: {:?}",
            accessor.index(),
            values[i]
        )),
    }
}

/// Unit normals, or `None` if any normal has zero length (shade flat rather than guess).
fn normalized(normals: Vec<Vec3>) -> Option<Vec<Vec3>> {
    normals.into_iter().map(|n| n.try_normalize()).collect()
}

/// The base-colour UVs with `KHR_texture_transform` applied, or `None` if the primitive
/// lacks the set the material reads.
fn read_uvs(
    primitive: &gltf::Primitive,
    source: UvSource,
    buffers: &Buffers,
    what: &str,
    vertex_count: usize,
) -> Result<Option<Vec<Vec2>>, String> {
    let Some(accessor) = primitive.get(&gltf::Semantic::TexCoords(source.set)) else {
        return Ok(None);
    };
    let label = format!("TEXCOORD_{} of {what}", source.set);
    let flat = read_floats(
        &accessor,
        buffers,
        &label,
        Dimensions::Vec2,
        Integers::Normalized,
    )?;
    let mut uvs: Vec<Vec2> = flat.chunks_exact(2).map(Vec2::from_slice).collect();
    check_count(uvs.len(), vertex_count, &accessor, &label)?;
    check_finite(&uvs, |uv| uv.is_finite(), &accessor, &label)?;
    if let Some(transform) = source.transform {
        uvs.iter_mut().for_each(|uv| *uv = transform.apply(*uv));
        let label = format!("{label} after KHR_texture_transform");
        check_finite(&uvs, |uv| uv.is_finite(), &accessor, &label)?;
    }
    Ok(Some(uvs))
}

/// The primitive's triangle list: its indices (or 0..n), strips and fans unrolled.
fn read_triangle_indices(
    primitive: &gltf::Primitive,
    mode: Mode,
    buffers: &Buffers,
    what: &str,
    vertex_count: usize,
) -> Result<Vec<u32>, String> {
    let indices = match primitive.indices() {
        Some(accessor) => {
            let label = format!("indices of {what}");
            let indices = read_indices(&accessor, buffers, &label)?;
            if let Some(bad) = indices.iter().find(|&&i| i as usize >= vertex_count) {
                return Err(format!(
                    "accessor {} ({label}) has index {bad}, but there are only {vertex_count} vertices",
                    accessor.index()
                ));
            }
            indices
        }
        None => {
            let count =
                u32::try_from(vertex_count).map_err(|_| format!("{what} has too many vertices"))?;
            (0..count).collect()
        }
    };
    let triangles = match mode {
        Mode::TriangleStrip => strip_to_list(&indices),
        Mode::TriangleFan => fan_to_list(&indices),
        _ => indices,
    };
    if triangles.len() % 3 != 0 {
        return Err(format!(
            "{what} has {} indices, not a multiple of 3",
            triangles.len()
        ));
    }
    Ok(triangles)
}

/// glTF strip order: triangle `i` is `(i, i+1, i+2)` for even `i`, `(i, i+2, i+1)` for
/// odd `i`, so all triangles keep the first one's winding.
fn strip_to_list(strip: &[u32]) -> Vec<u32> {
    strip
        .windows(3)
        .enumerate()
        .flat_map(|(i, w)| {
            if i % 2 == 0 {
                [w[0], w[1], w[2]]
            } else {
                [w[0], w[2], w[1]]
            }
        })
        .collect()
}

/// glTF fan order: triangle `i` is `(i+1, i+2, 0)`.
fn fan_to_list(fan: &[u32]) -> Vec<u32> {
    match fan.split_first() {
        Some((&hub, rim)) => rim.windows(2).flat_map(|w| [w[0], w[1], hub]).collect(),
        None => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_unroll_with_consistent_winding() {
        assert_eq!(
            strip_to_list(&[0, 1, 2, 3, 4]),
            vec![0, 1, 2, 1, 3, 2, 2, 3, 4]
        );
        assert_eq!(fan_to_list(&[0, 1, 2, 3]), vec![1, 2, 0, 2, 3, 0]);
        assert!(strip_to_list(&[0, 1]).is_empty());
        assert!(fan_to_list(&[]).is_empty());
    }

    #[test]
    fn zero_normal_drops_all_normals() {
        assert_eq!(
            normalized(vec![Vec3::new(0.0, 2.0, 0.0)]),
            Some(vec![Vec3::Y])
        );
        assert_eq!(normalized(vec![Vec3::Y, Vec3::ZERO]), None);
    }
}
