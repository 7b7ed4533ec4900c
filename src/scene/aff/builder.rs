//! Scene assembly: nodes, meshes and primitives as the parser emits geometry.
//!
//! Each `x`/`xs` block is a node; geometry inside it goes into that node's mesh (created on
//! first use). Consecutive geometry of one node with the same material (and the same
//! attributes: normals present or not) is appended to the same primitive, so a node's mesh
//! has about one primitive per material. Geometry outside every transform goes to the root
//! node. Vertex-morphing `tpa` triangles cannot share a mesh with static primitives (all
//! primitives of a mesh have the same morph target count), so they go into a child node of
//! their own (`tpa` group), one per run of triangles with the same material and sample times.

use glam::{Vec2, Vec3};

use crate::scene::{MeshDesc, MorphTargetDesc, NodeDesc, PrimitiveDesc, Trs};

/// Triangles to add to a node: positions, optional per-vertex normals and UVs, indices.
#[derive(Debug, Default)]
pub struct Geometry {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<u32>,
}

/// One `tpa` triangle: per sample, its time and three (position, normal) pairs.
#[derive(Debug, Clone)]
pub struct MorphTriangle {
    pub times: Vec<f32>,
    pub samples: Vec<[(Vec3, Vec3); 3]>,
}

/// A `tpa` group node: its sample times (the weights channel keys).
#[derive(Debug, Clone)]
pub struct MorphGroup {
    pub node: usize,
    /// The node's mesh (one primitive: base positions and normals, one target per sample).
    pub mesh: usize,
    pub times: Vec<f32>,
}

#[derive(Debug, Default)]
pub struct Builder {
    pub nodes: Vec<NodeDesc>,
    pub meshes: Vec<MeshDesc>,
    pub roots: Vec<usize>,
    pub morph_groups: Vec<MorphGroup>,
    /// The open `tpa` group: (parent node, material, time bits, group index).
    open_group: Option<(usize, usize, Vec<u32>, usize)>,
}

impl Builder {
    /// Adds a node under `parent` (a root when `None`) and returns its index.
    pub fn add_node(&mut self, parent: Option<usize>, name: String, local: Trs) -> usize {
        let index = self.nodes.len();
        self.nodes.push(NodeDesc {
            name,
            local,
            ..Default::default()
        });
        match parent {
            Some(p) => self.nodes[p].children.push(index),
            None => self.roots.push(index),
        }
        index
    }

    fn mesh_of(&mut self, node: usize) -> usize {
        if let Some(m) = self.nodes[node].mesh {
            return m;
        }
        let m = self.meshes.len();
        self.meshes.push(MeshDesc {
            name: self.nodes[node].name.clone(),
            ..Default::default()
        });
        self.nodes[node].mesh = Some(m);
        m
    }

    /// Appends triangles with `material` to `node`'s mesh.
    pub fn add_geometry(&mut self, node: usize, material: usize, g: Geometry) {
        if g.indices.is_empty() {
            return;
        }
        let mesh = self.mesh_of(node);
        let primitives = &mut self.meshes[mesh].primitives;
        let fits = primitives.last().is_some_and(|p| {
            p.material == Some(material)
                && p.normals.is_some() == g.normals.is_some()
                && p.uvs.is_some() == g.uvs.is_some()
        });
        if !fits {
            primitives.push(PrimitiveDesc {
                normals: g.normals.as_ref().map(|_| Vec::new()),
                uvs: g.uvs.as_ref().map(|_| Vec::new()),
                material: Some(material),
                ..Default::default()
            });
        }
        let last = primitives.len() - 1;
        let p = &mut primitives[last];
        let base = p.positions.len() as u32;
        p.positions.extend_from_slice(&g.positions);
        if let (Some(dst), Some(src)) = (p.normals.as_mut(), g.normals.as_ref()) {
            dst.extend_from_slice(src);
        }
        if let (Some(dst), Some(src)) = (p.uvs.as_mut(), g.uvs.as_ref()) {
            dst.extend_from_slice(src);
        }
        p.indices.extend(g.indices.iter().map(|i| i + base));
    }

    /// Adds a `tpa` triangle under `parent`: base = sample 0, one morph target per further
    /// sample (deltas of positions and of unit normals).
    pub fn add_morph_triangle(&mut self, parent: usize, material: usize, tri: MorphTriangle) {
        let bits: Vec<u32> = tri.times.iter().map(|t| t.to_bits()).collect();
        let group = match &self.open_group {
            Some((p, m, b, g)) if *p == parent && *m == material && *b == bits => *g,
            _ => {
                let node = self.add_node(Some(parent), "tpa".into(), Trs::default());
                let mesh = self.mesh_of(node);
                let targets = tri.times.len() - 1;
                self.meshes[mesh].weights = vec![0.0; targets];
                self.meshes[mesh].primitives.push(PrimitiveDesc {
                    normals: Some(Vec::new()),
                    material: Some(material),
                    morph_targets: vec![
                        MorphTargetDesc {
                            positions: Some(Vec::new()),
                            normals: Some(Vec::new()),
                        };
                        targets
                    ],
                    ..Default::default()
                });
                let g = self.morph_groups.len();
                self.morph_groups.push(MorphGroup {
                    node,
                    mesh,
                    times: tri.times.clone(),
                });
                self.open_group = Some((parent, material, bits, g));
                g
            }
        };
        let p = &mut self.meshes[self.morph_groups[group].mesh].primitives[0];
        let base = p.positions.len() as u32;
        let geometric = {
            let [a, b, c] = tri.samples[0].map(|(pos, _)| pos);
            (b - a).cross(c - a).try_normalize().unwrap_or(Vec3::Z)
        };
        let unit = |n: Vec3| n.try_normalize().unwrap_or(geometric);
        for v in 0..3 {
            let (p0, n0) = tri.samples[0][v];
            p.positions.push(p0);
            // The group's primitive and targets were created with normals and positions.
            p.normals.get_or_insert_default().push(unit(n0));
            for (target, sample) in p.morph_targets.iter_mut().zip(&tri.samples[1..]) {
                let (pi, ni) = sample[v];
                target.positions.get_or_insert_default().push(pi - p0);
                target
                    .normals
                    .get_or_insert_default()
                    .push(unit(ni) - unit(n0));
            }
        }
        p.indices.extend([base, base + 1, base + 2]);
    }

    /// Ends the open `tpa` group (any other command between `tpa`s starts a new group only
    /// if it changes the parent or material, so nothing needs to call this but a new scope).
    pub fn close_morph_group(&mut self) {
        self.open_group = None;
    }
}
