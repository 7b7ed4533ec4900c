//! The binary buffer of a glTF file under construction: typed arrays appended one after
//! another, each with its own buffer view and accessor.
//!
//! Invariants: every view starts at a multiple of 4 bytes (all components written here
//! are 4 bytes wide, so accessors are aligned too); data is little-endian; accessor `i`
//! reads view `i`.

use super::gltf_json::{Accessor, BufferView, FLOAT, UNSIGNED_INT};

/// Bytes, views and accessors for the single buffer of a glTF file.
#[derive(Default)]
pub struct BinaryBuffer {
    pub bytes: Vec<u8>,
    pub views: Vec<BufferView>,
    pub accessors: Vec<Accessor>,
}

/// Whether an accessor declares its component-wise min and max (required for POSITION
/// and animation inputs).
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Bounds {
    Declared,
    Omitted,
}

impl BinaryBuffer {
    /// Appends `values` read as `count` elements of `components` floats each
    /// (`kind` is the glTF accessor type: "SCALAR", "VEC2", ...); returns the accessor.
    pub fn push_floats(
        &mut self,
        values: &[f32],
        components: usize,
        kind: &'static str,
        target: Option<u32>,
        bounds: Bounds,
    ) -> usize {
        debug_assert_eq!(values.len() % components, 0);
        let (min, max) = match bounds {
            Bounds::Declared => {
                let (min, max) = component_bounds(values, components);
                (Some(min), Some(max))
            }
            Bounds::Omitted => (None, None),
        };
        let view = self.push_view(values.iter().flat_map(|v| v.to_le_bytes()), target);
        self.accessors.push(Accessor {
            buffer_view: view,
            component_type: FLOAT,
            count: values.len() / components,
            kind,
            min,
            max,
        });
        self.accessors.len() - 1
    }

    /// Appends triangle indices; returns the accessor.
    pub fn push_indices(&mut self, indices: &[u32], target: u32) -> usize {
        let view = self.push_view(indices.iter().flat_map(|i| i.to_le_bytes()), Some(target));
        self.accessors.push(Accessor {
            buffer_view: view,
            component_type: UNSIGNED_INT,
            count: indices.len(),
            kind: "SCALAR",
            min: None,
            max: None,
        });
        self.accessors.len() - 1
    }

    fn push_view(&mut self, data: impl Iterator<Item = u8>, target: Option<u32>) -> usize {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        let byte_offset = self.bytes.len();
        self.bytes.extend(data);
        self.views.push(BufferView {
            buffer: 0,
            byte_offset,
            byte_length: self.bytes.len() - byte_offset,
            target,
        });
        self.views.len() - 1
    }
}

/// Component-wise minimum and maximum of `values` taken as elements of `components`.
fn component_bounds(values: &[f32], components: usize) -> (Vec<f32>, Vec<f32>) {
    let mut min = vec![f32::INFINITY; components];
    let mut max = vec![f32::NEG_INFINITY; components];
    for element in values.chunks(components) {
        for (c, &v) in element.iter().enumerate() {
            min[c] = min[c].min(v);
            max[c] = max[c].max(v);
        }
    }
    (min, max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_are_four_byte_aligned_and_bounds_are_per_component() {
        let mut buffer = BinaryBuffer::default();
        let a = buffer.push_floats(
            &[1.0, -2.0, 3.0, 0.5, 4.0, -1.0],
            3,
            "VEC3",
            None,
            Bounds::Declared,
        );
        let b = buffer.push_indices(&[0, 1, 2], 34963);
        assert_eq!((a, b), (0, 1));
        assert_eq!(buffer.accessors[0].count, 2);
        assert_eq!(buffer.accessors[0].min, Some(vec![0.5, -2.0, -1.0]));
        assert_eq!(buffer.accessors[0].max, Some(vec![1.0, 4.0, 3.0]));
        assert_eq!(buffer.views[1].byte_offset, 24);
        assert_eq!(buffer.bytes.len(), 36);
        assert!(buffer.views.iter().all(|v| v.byte_offset % 4 == 0));
        assert_eq!(&buffer.bytes[24..28], &0u32.to_le_bytes());
    }
}
