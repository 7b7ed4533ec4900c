//! The shape part of each node's world transform, tracked exactly through the hierarchy.
//!
//! A triangle's `log2 P_b` depends only on its shape: a rotation or translation leaves it
//! unchanged. When a node's world linear part is `s R diag(d)` (a rotation `R` after a uniform
//! scale `s` and an axis stretch `d`, every ancestor scaling uniformly and nothing rotating
//! between the stretch and the mesh), its shape is fully described by `(s, d)`; those numbers
//! are products, in f64, of the exact local scale factors of the chain, so a pure rotation of
//! any node never changes their bits. Measuring them from the composed f32 matrix instead
//! would jitter in the last bits as a node turns.

use glam::{Mat3, Quat, Vec3};

use super::{AnimationSelection, Pose};
use crate::scene::SceneDesc;

/// World linear part `scale * R * diag(stretch)` (a similarity when `stretch` is `None`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeShape {
    /// Uniform scale, > 0.
    pub scale: f64,
    /// Axis stretch in the node's own frame (absolute values; `None`: no stretch).
    pub stretch: Option<[f64; 3]>,
}

impl NodeShape {
    /// `log2` of the uniform scale of a similarity (`None` when stretched).
    pub fn log2_similarity_scale(&self) -> Option<f64> {
        self.stretch.is_none().then(|| self.scale.log2())
    }

    /// The diagonal `scale * stretch` that reproduces the node's shape from object space.
    pub fn diagonal(&self) -> [f64; 3] {
        let d = self.stretch.unwrap_or([1.0; 3]);
        d.map(|x| x * self.scale)
    }
}

/// A node's own transform, as far as its shape is concerned.
#[derive(Debug, Clone, Copy)]
struct LocalShape {
    rotates: bool,
    /// `Some(|s|)` for a uniform scale, else the per-axis absolute factors.
    uniform: Option<f64>,
    axes: [f64; 3],
    /// A matrix node that is not a similarity, or a degenerate scale.
    general: bool,
}

/// Per node: its world shape, or `None` when the chain shears or stretches under a rotation
/// (then only the world vertices tell the shape). Nodes not reachable from the roots get
/// `None`. Allocates a [`Pose`]; a frame loop asks its pose ([`Pose::node_shapes`]).
pub fn node_shapes(
    scene: &SceneDesc,
    selection: AnimationSelection,
    time_s: f32,
) -> Vec<Option<NodeShape>> {
    let mut pose = Pose::default();
    pose.evaluate(scene, selection, time_s);
    let mut shapes = Vec::new();
    pose.node_shapes(scene, &mut shapes);
    shapes
}

impl Pose {
    /// Writes each node's world shape into `out` (see [`node_shapes`]), from the local
    /// rotations and scales this pose sampled: the channels are not sampled again.
    pub fn node_shapes(&self, scene: &SceneDesc, out: &mut Vec<Option<NodeShape>>) {
        out.clear();
        out.resize(scene.nodes.len(), None);
        let root = Some(NodeShape {
            scale: 1.0,
            stretch: None,
        });
        let mut stack: Vec<(usize, Option<NodeShape>)> =
            scene.roots.iter().map(|&r| (r, root)).collect();
        while let Some((node, parent)) = stack.pop() {
            let shape = parent.and_then(|p| compose(p, self.local_shape(scene, node)));
            out[node] = shape;
            for &child in &scene.nodes[node].children {
                stack.push((child, shape));
            }
        }
    }

    /// Node `node`'s own rotation-and-scale in this pose: a matrix node's (static) matrix,
    /// else its TRS with the selected channels applied.
    fn local_shape(&self, scene: &SceneDesc, node: usize) -> LocalShape {
        match scene.nodes[node].matrix {
            Some(m) => matrix_shape(Mat3::from_mat4(m)),
            None => {
                let local = &self.local[node];
                trs_shape(local.scale, local.rotation)
            }
        }
    }
}

/// `parent * local` when the result keeps the `s R diag(d)` form.
fn compose(parent: NodeShape, local: LocalShape) -> Option<NodeShape> {
    if local.general {
        return None;
    }
    match (parent.stretch, local.uniform) {
        (None, Some(c)) => Some(NodeShape {
            scale: parent.scale * c,
            stretch: None,
        }),
        (None, None) => Some(NodeShape {
            scale: parent.scale,
            stretch: Some(local.axes),
        }),
        // Under a stretch, a rotation would shear: only unrotated children keep the form.
        (Some(_), _) if local.rotates => None,
        (Some(d), Some(c)) => Some(NodeShape {
            scale: parent.scale * c,
            stretch: Some(d),
        }),
        (Some(d), None) => Some(NodeShape {
            scale: parent.scale,
            stretch: Some([0, 1, 2].map(|i| d[i] * local.axes[i])),
        }),
    }
}

fn trs_shape(scale: Vec3, rotation: Quat) -> LocalShape {
    let a = scale.abs();
    let axes = [a.x as f64, a.y as f64, a.z as f64];
    let valid = a.is_finite() && a.min_element() > 0.0;
    let uniform = (a.x == a.y && a.y == a.z).then_some(a.x as f64);
    let rotates = !(rotation == Quat::IDENTITY || rotation == -Quat::IDENTITY);
    LocalShape {
        rotates,
        uniform,
        axes,
        general: !valid,
    }
}

/// A (static) matrix node: a similarity (rotating unless its linear part is a multiple of
/// the identity), or general.
fn matrix_shape(l: Mat3) -> LocalShape {
    let l = l.as_dmat3();
    let g = l.transpose() * l;
    let s2 = (g.x_axis.x + g.y_axis.y + g.z_axis.z) / 3.0;
    let general = LocalShape {
        rotates: true,
        uniform: None,
        axes: [1.0; 3],
        general: true,
    };
    if !(s2.is_finite() && s2 > 0.0) {
        return general;
    }
    let err = (g - glam::DMat3::from_diagonal(glam::DVec3::splat(s2)))
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    if err > 1e-5 * s2 {
        return general;
    }
    let s = s2.sqrt();
    let rotates = (l - glam::DMat3::from_diagonal(glam::DVec3::splat(s)))
        .to_cols_array()
        .iter()
        .any(|x| x.abs() > 1e-12 * s);
    LocalShape {
        rotates,
        uniform: Some(s),
        axes: [s; 3],
        general: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{NodeDesc, Trs};
    use glam::Mat4;

    fn node(scale: Vec3, rotation: Quat, children: Vec<usize>) -> NodeDesc {
        NodeDesc {
            local: Trs {
                scale,
                rotation,
                ..Default::default()
            },
            children,
            ..Default::default()
        }
    }

    #[test]
    fn chains_multiply_uniform_factors_and_carry_unrotated_stretch() {
        let r = Quat::from_rotation_z(0.7);
        let scene = SceneDesc {
            nodes: vec![
                node(Vec3::splat(2.0), r, vec![1, 2]),
                node(Vec3::splat(-1.5), r, vec![]),
                node(Vec3::new(1.0, 2.0, 1.0), r, vec![3, 4]),
                node(Vec3::splat(3.0), Quat::IDENTITY, vec![]),
                node(Vec3::ONE, r, vec![]),
            ],
            roots: vec![0],
            ..Default::default()
        };
        let s = node_shapes(&scene, AnimationSelection::All, 0.0);
        assert_eq!(
            s[0],
            Some(NodeShape {
                scale: 2.0,
                stretch: None
            })
        );
        assert_eq!(
            s[1],
            Some(NodeShape {
                scale: 3.0,
                stretch: None
            })
        );
        assert_eq!(
            s[2],
            Some(NodeShape {
                scale: 2.0,
                stretch: Some([1.0, 2.0, 1.0])
            })
        );
        assert_eq!(
            s[3],
            Some(NodeShape {
                scale: 6.0,
                stretch: Some([1.0, 2.0, 1.0])
            })
        );
        assert_eq!(s[4], None, "a rotation under a stretch shears");
        assert_eq!(s[3].unwrap().diagonal(), [6.0, 12.0, 6.0]);
    }

    #[test]
    fn matrix_nodes_use_their_similarity_scale() {
        let m = Mat4::from_scale_rotation_translation(
            Vec3::splat(4.0),
            Quat::from_rotation_x(1.0),
            Vec3::ONE,
        );
        let scene = SceneDesc {
            nodes: vec![NodeDesc {
                matrix: Some(m),
                ..Default::default()
            }],
            roots: vec![0],
            ..Default::default()
        };
        let s = node_shapes(&scene, AnimationSelection::All, 0.0)[0].unwrap();
        assert!((s.scale - 4.0).abs() < 1e-6 && s.stretch.is_none());
    }
}
