//! Checked accessor reads.
//!
//! gltf's `accessor::Iter` computes byte ranges from the accessor and its buffer view and
//! slices the buffer with them; a range past the end (or a stride smaller than an element,
//! or `count - 1` on an empty accessor) panics inside gltf. So every range an accessor
//! touches (base view, sparse indices view, sparse values view) is validated here first,
//! and gltf only decodes data already known to be in bounds. Sparse accessors are decoded
//! by gltf's iterator (it substitutes the sparse values), after this module has checked
//! that the sparse indices are strictly increasing and below `count`.

use std::ops::Range;

use gltf::accessor::sparse::{IndexType, Sparse};
use gltf::accessor::{Accessor, DataType, Dimensions, Item, Iter};
use gltf::buffer::View;

use super::buffers::Buffers;

/// Largest element count of an accessor with no buffer view (all zeros, or a sparse
/// accessor on zeros): no buffer bounds such a count, so a corrupt file could otherwise
/// ask for an unbounded allocation.
const MAX_VIEWLESS_COUNT: usize = 1 << 24;

/// How integer components of a float attribute are interpreted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Integers {
    /// Only `FLOAT` components are accepted (positions, normals, key times).
    Rejected,
    /// Integer components are normalized to [0, 1] or [-1, 1] (texture coordinates,
    /// rotation and weight keys, which glTF only allows as normalized integers).
    Normalized,
}

/// Names an accessor and what it is read for, e.g.
/// `accessor 3 (POSITION of mesh 0 primitive 1)`.
fn label(accessor: &Accessor, what: &str) -> String {
    format!("accessor {} ({what})", accessor.index())
}

/// Reads a float accessor of the given type as a flat list (`count * components`
/// numbers), converting normalized integers when `integers` allows them.
pub(super) fn read_floats(
    accessor: &Accessor,
    buffers: &Buffers,
    what: &str,
    dimensions: Dimensions,
    integers: Integers,
) -> Result<Vec<f32>, String> {
    if accessor.dimensions() != dimensions {
        return Err(format!(
            "{} has type {:?}, expected {:?}",
            label(accessor, what),
            accessor.dimensions(),
            dimensions
        ));
    }
    let components = dimensions.multiplicity();
    let normalized = integers == Integers::Normalized;
    match accessor.data_type() {
        DataType::F32 => read_flat::<f32>(accessor, buffers, what, components),
        DataType::U8 if normalized => Ok(convert(
            read_flat::<u8>(accessor, buffers, what, components)?,
            |c| f32::from(c) / 255.0,
        )),
        DataType::I8 if normalized => Ok(convert(
            read_flat::<i8>(accessor, buffers, what, components)?,
            |c| (f32::from(c) / 127.0).max(-1.0),
        )),
        DataType::U16 if normalized => Ok(convert(
            read_flat::<u16>(accessor, buffers, what, components)?,
            |c| f32::from(c) / 65535.0,
        )),
        DataType::I16 if normalized => Ok(convert(
            read_flat::<i16>(accessor, buffers, what, components)?,
            |c| (f32::from(c) / 32767.0).max(-1.0),
        )),
        other => Err(format!(
            "{} has component type {other:?}, which is not allowed here",
            label(accessor, what)
        )),
    }
}

/// Reads an index accessor (`SCALAR` of u8, u16 or u32) widened to u32.
pub(super) fn read_indices(
    accessor: &Accessor,
    buffers: &Buffers,
    what: &str,
) -> Result<Vec<u32>, String> {
    if accessor.dimensions() != Dimensions::Scalar {
        return Err(format!(
            "{} has type {:?}, expected Scalar",
            label(accessor, what),
            accessor.dimensions()
        ));
    }
    match accessor.data_type() {
        DataType::U8 => Ok(convert(
            read_items::<u8>(accessor, buffers, what)?,
            u32::from,
        )),
        DataType::U16 => Ok(convert(
            read_items::<u16>(accessor, buffers, what)?,
            u32::from,
        )),
        DataType::U32 => read_items::<u32>(accessor, buffers, what),
        other => Err(format!(
            "{} has component type {other:?}; indices must be unsigned byte, short or int",
            label(accessor, what)
        )),
    }
}

/// Reads a `JOINTS_n` accessor (`VEC4` of unsigned byte or short) widened to u16.
pub(super) fn read_joint_indices(
    accessor: &Accessor,
    buffers: &Buffers,
    what: &str,
) -> Result<Vec<[u16; 4]>, String> {
    if accessor.dimensions() != Dimensions::Vec4 {
        return Err(format!(
            "{} has type {:?}, expected Vec4",
            label(accessor, what),
            accessor.dimensions()
        ));
    }
    match accessor.data_type() {
        DataType::U8 => Ok(convert(
            read_items::<[u8; 4]>(accessor, buffers, what)?,
            |j| j.map(u16::from),
        )),
        DataType::U16 => read_items::<[u16; 4]>(accessor, buffers, what),
        other => Err(format!(
            "{} has component type {other:?}; joints must be unsigned byte or short",
            label(accessor, what)
        )),
    }
}

fn convert<C, T>(items: Vec<C>, f: impl Fn(C) -> T) -> Vec<T> {
    items.into_iter().map(f).collect()
}

/// Reads `components`-wide elements of component type `C`, flattened.
fn read_flat<C: Item + Copy>(
    accessor: &Accessor,
    buffers: &Buffers,
    what: &str,
    components: usize,
) -> Result<Vec<C>, String> {
    Ok(match components {
        1 => read_items::<C>(accessor, buffers, what)?,
        2 => read_items::<[C; 2]>(accessor, buffers, what)?.concat(),
        3 => read_items::<[C; 3]>(accessor, buffers, what)?.concat(),
        4 => read_items::<[C; 4]>(accessor, buffers, what)?.concat(),
        // MAT4: four 4-component columns (no column padding for 4-byte components, the
        // only kind callers ask for).
        16 => read_items::<[[C; 4]; 4]>(accessor, buffers, what)?
            .concat()
            .concat(),
        _ => {
            return Err(format!(
                "{} has {components} components per element, which is not supported",
                label(accessor, what)
            ));
        }
    })
}

/// Reads every element after validating all byte ranges; `T` must match the accessor's
/// element layout (the callers dispatch on component type and dimensions).
fn read_items<T: Item>(
    accessor: &Accessor,
    buffers: &Buffers,
    what: &str,
) -> Result<Vec<T>, String> {
    if std::mem::size_of::<T>() != accessor.size() {
        return Err(format!(
            "{} has {}-byte elements, expected {}",
            label(accessor, what),
            accessor.size(),
            std::mem::size_of::<T>()
        ));
    }
    let count = accessor.count();
    if count == 0 {
        // Also keeps gltf's iterator from computing `count - 1`.
        return Err(format!(
            "{} has count 0; glTF requires at least 1",
            label(accessor, what)
        ));
    }
    check_layout(accessor, buffers, what)?;
    let buffer_data = |buffer: gltf::Buffer| buffers.bytes(buffer.index());
    let items: Vec<T> = match Iter::<T>::new(accessor.clone(), buffer_data) {
        Some(iter) => iter.collect(),
        // glTF: an accessor without a buffer view (and not sparse) is all zeros.
        None if accessor.view().is_none() && accessor.sparse().is_none() => {
            (0..count).map(|_| T::zero()).collect()
        }
        None => {
            return Err(format!(
                "{} cannot be read from its buffer",
                label(accessor, what)
            ));
        }
    };
    if items.len() != count {
        return Err(format!(
            "{} yielded {} elements, expected count {count}",
            label(accessor, what),
            items.len()
        ));
    }
    Ok(items)
}

/// Byte range of `count` elements of `element` bytes, `stride` apart, from `offset`;
/// `None` on arithmetic overflow (a corrupt count or offset).
fn element_range(
    offset: usize,
    stride: usize,
    count: usize,
    element: usize,
) -> Option<Range<usize>> {
    if count == 0 {
        return Some(offset..offset);
    }
    let end = stride
        .checked_mul(count - 1)?
        .checked_add(offset)?
        .checked_add(element)?;
    Some(offset..end)
}

/// Checks that `count` elements of `element` bytes at `offset` (with the view's stride,
/// or tightly packed) lie inside `view`, and that `view` lies inside its buffer.
fn check_view_range(
    owner: &str,
    view: &View,
    buffers: &Buffers,
    offset: usize,
    count: usize,
    element: usize,
) -> Result<(), String> {
    buffers.view_bytes(view)?;
    let stride = view.stride().unwrap_or(element);
    if stride < element {
        return Err(format!(
            "{owner}: buffer view {} has byteStride {stride}, smaller than the {element}-byte element",
            view.index()
        ));
    }
    let range = element_range(offset, stride, count, element).ok_or_else(|| {
        format!("{owner}: byte range overflows (offset {offset}, stride {stride}, count {count})")
    })?;
    if range.end > view.length() {
        return Err(format!(
            "{owner} reads bytes {}..{} but buffer view {} has {} bytes",
            range.start,
            range.end,
            view.index(),
            view.length()
        ));
    }
    Ok(())
}

/// Validates every byte range the accessor reads, so gltf's iterator cannot go out of
/// bounds.
fn check_layout(accessor: &Accessor, buffers: &Buffers, what: &str) -> Result<(), String> {
    let owner = label(accessor, what);
    let count = accessor.count();
    match accessor.view() {
        Some(view) => check_view_range(
            &owner,
            &view,
            buffers,
            accessor.offset(),
            count,
            accessor.size(),
        )?,
        None if count > MAX_VIEWLESS_COUNT => {
            return Err(format!(
                "{owner} has no buffer view and count {count}, more than the {MAX_VIEWLESS_COUNT} supported"
            ));
        }
        None => {}
    }
    if let Some(sparse) = accessor.sparse() {
        check_sparse(&owner, &sparse, count, accessor.size(), buffers)?;
    }
    Ok(())
}

/// Checks a sparse substitution: both views in range, indices strictly increasing and
/// below the accessor's count (gltf's iterator relies on that order).
fn check_sparse(
    owner: &str,
    sparse: &Sparse,
    count: usize,
    element: usize,
    buffers: &Buffers,
) -> Result<(), String> {
    let substituted = sparse.count();
    if substituted == 0 || substituted > count {
        return Err(format!(
            "{owner}: sparse count {substituted} must be in 1..={count}"
        ));
    }
    let indices = sparse.indices();
    let index_size = indices.index_type().size();
    let indices_owner = format!("{owner}, sparse indices");
    check_view_range(
        &indices_owner,
        &indices.view(),
        buffers,
        indices.offset(),
        substituted,
        index_size,
    )?;
    let values = sparse.values();
    let values_owner = format!("{owner}, sparse values");
    check_view_range(
        &values_owner,
        &values.view(),
        buffers,
        values.offset(),
        substituted,
        element,
    )?;

    let view = indices.view();
    let bytes = buffers.view_bytes(&view)?;
    let stride = view.stride().unwrap_or(index_size);
    let mut previous: Option<u32> = None;
    for i in 0..substituted {
        let at = indices.offset() + i * stride;
        let index = read_sparse_index(&bytes[at..at + index_size], indices.index_type());
        if index as usize >= count {
            return Err(format!(
                "{owner}: sparse index {index} is not below count {count}"
            ));
        }
        if previous.is_some_and(|p| index <= p) {
            return Err(format!(
                "{owner}: sparse indices are not strictly increasing at {index}"
            ));
        }
        previous = Some(index);
    }
    Ok(())
}

/// Decodes one little-endian sparse index (`bytes` has exactly the index size).
fn read_sparse_index(bytes: &[u8], index_type: IndexType) -> u32 {
    match index_type {
        IndexType::U8 => u32::from(bytes[0]),
        IndexType::U16 => u32::from(u16::from_le_bytes([bytes[0], bytes[1]])),
        IndexType::U32 => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn element_range_covers_last_element_only_to_its_size() {
        assert_eq!(element_range(4, 16, 3, 12), Some(4..48));
        assert_eq!(element_range(0, 12, 0, 12), Some(0..0));
        assert_eq!(element_range(0, 12, usize::MAX, 12), None);
    }
}
