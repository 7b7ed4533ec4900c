//! Binary little-endian PLY writer: the frame's triangles in BVH order with per-face
//! material, `log2_pb` and `deformed` flags.
//!
//! Layout: `element vertex` (3 per face, no sharing: `float x y z nx ny nz u v`), then
//! `element face` (`list uchar int vertex_indices` = 3, `3i`, `3i + 1`, `3i + 2`;
//! `int material`; `float log2_pb`; `uchar deformed`). UVs are mipray's own (origin at
//! the image's top-left, not flipped), bit-exact.

use std::io::Write;
use std::path::Path;

use super::{ExportError, bit, write_atomically};
use crate::frame::Renderer;

pub(crate) fn write_ply(
    renderer: &Renderer,
    path: &Path,
    frame: u32,
    time_s: f32,
    deformed: &[u64],
) -> Result<(), ExportError> {
    let t = renderer.triangles();
    let n = t.len();
    write_atomically(path, |w| {
        write!(
            w,
            "ply\n\
             format binary_little_endian 1.0\n\
             comment mipray export frame {frame}\n\
             comment time_s {time_s}\n\
             comment world space, +Y up, -Z forward (glTF); faces in BVH order, 3 unshared vertices each\n\
             comment u v: mipray texture coordinates, origin at the image's top-left (not flipped)\n\
             comment material: index into the renderer's materials (materials.mtl order of an OBJ export)\n\
             comment log2_pb: Park & Kim per-triangle constant (0 where untextured)\n\
             comment deformed: 1 = shape changed since the previous frame; frame 0 and static or rigidly moving triangles: 0\n\
             element vertex {}\n\
             property float x\n\
             property float y\n\
             property float z\n\
             property float nx\n\
             property float ny\n\
             property float nz\n\
             property float u\n\
             property float v\n\
             element face {n}\n\
             property list uchar int vertex_indices\n\
             property int material\n\
             property float log2_pb\n\
             property uchar deformed\n\
             end_header\n",
            3 * n
        )?;
        let mut vertex = [0u8; 32];
        for slot in 0..n {
            let positions = renderer.accel().triangle(slot as u32);
            let normals = renderer.slot_normals(slot);
            for (k, p) in positions.iter().enumerate() {
                let nn = normals[k];
                let uv = t.uvs[slot][k];
                let values = [p.x, p.y, p.z, nn.x, nn.y, nn.z, uv.x, uv.y];
                for (chunk, v) in vertex.chunks_exact_mut(4).zip(values) {
                    chunk.copy_from_slice(&v.to_le_bytes());
                }
                w.write_all(&vertex)?;
            }
        }
        let mut face = [0u8; 22];
        for slot in 0..n {
            let first = 3 * slot as i32;
            face[0] = 3;
            face[1..5].copy_from_slice(&first.to_le_bytes());
            face[5..9].copy_from_slice(&(first + 1).to_le_bytes());
            face[9..13].copy_from_slice(&(first + 2).to_le_bytes());
            face[13..17].copy_from_slice(&(t.material[slot] as i32).to_le_bytes());
            face[17..21].copy_from_slice(&t.log2_pb[slot].to_le_bytes());
            face[21] = u8::from(bit(deformed, slot));
            w.write_all(&face)?;
        }
        Ok(())
    })
}
