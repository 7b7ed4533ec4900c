//! What changed this frame: the dirty set that drives both the BVH update and the LOD update.
//!
//! Per triangle (by BVH slot) one of four motions, decided per instance from its transform
//! and, for deforming meshes, per triangle from its vertices:
//! - *static*: untouched (not in the set);
//! - *rigid*: moved by a rotation + translation: its box moves, `log2 P_b` is unchanged;
//! - *scaled*: moved by a similarity with a new uniform scale `s`: `log2 P_b` is the
//!   object-space constant plus `log2 s`;
//! - *deformed*: shape changed (skinning, morphing, non-uniform scale or shear): `log2 P_b`
//!   is recomputed from its world vertices.

use glam::{DMat3, Mat4};

/// How one triangle moved this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    Rigid,
    Scaled,
    Deformed,
}

/// The moved triangles of one frame: a bitset for membership and a compact list in the
/// order they were marked, with their motion.
#[derive(Debug, Default, Clone)]
pub struct DirtySet {
    bits: Vec<u64>,
    /// Moved slots, each once.
    pub slots: Vec<u32>,
    /// Motion of each entry of `slots`.
    pub motions: Vec<Motion>,
}

impl DirtySet {
    /// Empties the set for a frame with `slots` triangles (keeps allocations).
    pub fn reset(&mut self, slots: usize) {
        self.bits.clear();
        self.bits.resize(slots.div_ceil(64), 0);
        self.slots.clear();
        self.motions.clear();
    }

    /// Marks a slot as moved (a slot marked twice keeps its first motion).
    #[inline]
    pub fn mark(&mut self, slot: u32, motion: Motion) {
        let (word, bit) = (slot as usize / 64, slot % 64);
        if self.bits[word] & (1 << bit) == 0 {
            self.bits[word] |= 1 << bit;
            self.slots.push(slot);
            self.motions.push(motion);
        }
    }

    #[inline]
    pub fn contains(&self, slot: u32) -> bool {
        self.bits.get(slot as usize / 64).is_some_and(|w| w & (1 << (slot % 64)) != 0)
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }

    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// How many entries have motion `m`.
    pub fn count(&self, m: Motion) -> usize {
        self.motions.iter().filter(|&&x| x == m).count()
    }
}

/// The uniform scale of a similarity transform (rotation, reflection, uniform scale,
/// translation), or `None` when the linear part shears or scales non-uniformly (or is
/// degenerate / non-finite). Computed in f64: `L^T L = s^2 I` within a relative 1e-5.
pub fn similarity_scale(world_from_object: Mat4) -> Option<f64> {
    let l = glam::Mat3::from_mat4(world_from_object).as_dmat3();
    let g = l.transpose() * l;
    let s2 = (g.x_axis.x + g.y_axis.y + g.z_axis.z) / 3.0;
    if !(s2.is_finite() && s2 > 0.0) {
        return None;
    }
    let off = (g - DMat3::from_diagonal(glam::DVec3::splat(s2))).to_cols_array();
    let err = off.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    (err <= 1e-5 * s2).then(|| s2.sqrt())
}

/// `log2` of a similarity's uniform scale, rounded to a 2^-20 grid (about 1e-6 levels).
///
/// Rotating a node changes the f32 matrix and so the last bits of its measured scale; on the
/// grid those jitters vanish, so a rigid motion compares equal to the previous frame, and the
/// `log2 P_b` built from it is the same value whichever frame computed it.
pub fn quantized_log2_scale(world_from_object: Mat4) -> Option<f64> {
    const GRID: f64 = (1u64 << 20) as f64;
    similarity_scale(world_from_object).map(|s| (s.log2() * GRID).round() / GRID)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    #[test]
    fn dirty_set_marks_once() {
        let mut d = DirtySet::default();
        d.reset(130);
        d.mark(129, Motion::Rigid);
        d.mark(3, Motion::Deformed);
        d.mark(129, Motion::Deformed);
        assert_eq!(d.slots, vec![129, 3]);
        assert_eq!(d.motions, vec![Motion::Rigid, Motion::Deformed]);
        assert!(d.contains(3) && d.contains(129) && !d.contains(4));
        assert_eq!(d.count(Motion::Deformed), 1);
        d.reset(130);
        assert!(d.is_empty() && !d.contains(3));
    }

    #[test]
    fn recognises_similarities() {
        let r = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
        let m = Mat4::from_scale_rotation_translation(Vec3::splat(2.5), r, Vec3::new(1.0, 2.0, 3.0));
        assert!((similarity_scale(m).unwrap() - 2.5).abs() < 1e-6);
        let mirrored = Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        assert!((similarity_scale(mirrored).unwrap() - 1.0).abs() < 1e-12);
        assert!(similarity_scale(Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0))).is_none());
        assert!(similarity_scale(Mat4::from_scale(Vec3::ZERO)).is_none());
        let shear = Mat4::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        assert!(similarity_scale(shear).is_none());
    }

    #[test]
    fn rotation_keeps_the_quantized_scale() {
        let base = quantized_log2_scale(Mat4::from_scale(Vec3::splat(3.0))).unwrap();
        for k in 0..100 {
            let r = Quat::from_euler(glam::EulerRot::YXZ, k as f32 * 0.37, k as f32 * 0.11, -0.5);
            let m = Mat4::from_scale_rotation_translation(Vec3::splat(3.0), r, Vec3::splat(k as f32));
            assert_eq!(quantized_log2_scale(m).unwrap().to_bits(), base.to_bits(), "rotation {k}");
        }
        assert!((base - 3f64.log2()).abs() < 1e-6);
    }
}
