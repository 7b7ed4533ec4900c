//! The `log2 P_b` rules of the frame loop (the constant itself is `lod::pb`): which
//! triangles get a new constant this frame and from what.
//!
//! - rigid motion (same shape key): keep the constant, no work;
//! - a new uniform scale `s`: object-space constant + `log2 s` (`lod::shift_log2_pb`);
//! - a new axis stretch: the object-space triangle under the exact diagonal;
//! - anything else (shear, skin, morph): recomputed from the world vertices.
//!
//! Each value depends only on the shape key and the vertices, never on earlier frames, so a
//! sequential run equals a frame rendered alone (`tests/frame_loop.rs`, `tests/deform.rs`
//! check it against a full recompute).

use std::collections::HashMap;
use std::ops::Range;
use std::sync::OnceLock;

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::Motion;
use super::animation::InstanceState;
use super::dirty::FrameChanges;
use super::posed::VertexSource;
use super::scene_geometry::SceneGeometry;
use super::setup::FrameSetup;
use crate::accel::Accel;
use crate::anim::NodeShape;
use crate::geometry::{FrameTriangles, Placement};
use crate::lod::log2::log2_in_place_in;
use crate::lod::{
    PixelFootprint, log2_pb, log2_pb_from_parts, log2_pb_with_texel_term, shift_log2_pb,
    texel_area, texel_term, uv_area,
};
use crate::scene::SceneDesc;
use crate::simd::{self, prefetch};

/// How many entries ahead the `log2 P_b` pass prefetches its slots.
const PREFETCH_AHEAD: usize = 16;

/// What the `log2 P_b` rules keep between frames: the object-space constants they start
/// from, the texel terms of the deforming slots, and the pass's reused buffers.
#[derive(Default)]
pub(super) struct Log2PbState {
    /// Per source triangle: `log2 P_b` of the rest vertices in object space (NaN where the
    /// material is untextured).
    pub object: Vec<f32>,
    /// Per slot: the texel terms of the deforming instances' triangles (`lod::texel_term`).
    texel_terms: DeformingTexelTerms,
    /// Scratch: one value per updated slot, reused every frame.
    values: Vec<Option<f32>>,
    /// Scratch: the dirty entries the update visits one by one.
    entries: Vec<u32>,
}

/// How many textured triangles the `log2 P_b` step gave a new constant.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Log2PbCounts {
    /// Computed from vertices (deformed, stretched or sheared).
    pub recomputed: usize,
    /// Shifted by a new uniform scale.
    pub shifted: usize,
}

impl Log2PbState {
    /// The object-space constants of `setup`'s scene (no slots yet).
    pub fn new(setup: &FrameSetup) -> Log2PbState {
        Log2PbState {
            object: object_space_log2_pb(&setup.scene, &setup.geometry, setup.footprint),
            ..Log2PbState::default()
        }
    }

    /// Makes [`DeformingTexelTerms`] for the slots as they are now (after every build of
    /// the tree, which orders the slots); nothing when no instance deforms or the LOD
    /// method has no `log2 P_b`.
    pub fn index_slots(&mut self, setup: &FrameSetup, triangles: &FrameTriangles) {
        let needed = setup.needs_log2_pb() && setup.deforms.contains(&VertexSource::Deformed);
        self.texel_terms = if needed {
            DeformingTexelTerms::new(setup, triangles, &self.object)
        } else {
            DeformingTexelTerms::default()
        };
    }

    /// `log2 P_b` of every triangle (the first frame; vertices read from `accel`, the tree
    /// over `triangles`); returns how many are textured.
    pub fn recompute_all(
        &mut self,
        setup: &FrameSetup,
        states: &[InstanceState],
        triangles: &mut FrameTriangles,
        accel: &Accel,
    ) -> usize {
        let pass = Pass {
            setup,
            triangles,
            accel,
            object: &self.object,
            texel_terms: &self.texel_terms,
            states,
            reads_vertices: states.iter().any(|state| state.shape.is_none()),
            stretches: stretches(setup, states),
        };
        pass.values_into(triangles.len(), |k| Some(k as u32), &mut self.values);
        let mut textured = 0;
        for (slot, &value) in self.values.iter().enumerate() {
            if let Some(value) = value {
                triangles.log2_pb[slot] = value;
                textured += 1;
            }
        }
        textured
    }

    /// The `log2 P_b` step: the dirty triangles' constants, recomputed where deformed,
    /// shifted where scaled, kept where rigid. The slots of deforming instances are walked
    /// in slot order from the dirty bits ([`Self::update_deforming`]); the entries of placed
    /// instances that scaled or changed shape one by one; rigid runs are not visited.
    pub fn update(
        &mut self,
        setup: &FrameSetup,
        states: &[InstanceState],
        changes: &FrameChanges,
        triangles: &mut FrameTriangles,
        accel: &Accel,
    ) -> Log2PbCounts {
        let mut counts = Log2PbCounts::default();
        let walked = !self.texel_terms.is_empty();
        if walked {
            counts.recomputed += self.update_deforming(setup, changes, triangles, accel);
        }
        // The entries visited one by one, gathered from their runs so the pass is set up
        // once and splits across threads by their total (a scene that interleaves reshaped
        // and rigid instances has a run per instance).
        // (The table is empty only when nothing deforms: then there are no deformed runs.)
        debug_assert!(walked || changes.deformed == 0);
        let entries = &mut self.entries;
        entries.clear();
        for run in &changes.reshaped_entries {
            entries.extend(run.clone().map(|k| k as u32));
        }
        // Only placed instances without a shape key (sheared) read their slots' vertices
        // here: the others' vertices would be prefetched for nothing.
        let reads_vertices = states
            .iter()
            .zip(&setup.deforms)
            .any(|(state, &d)| state.shape.is_none() && d != VertexSource::Deformed);
        let pass = Pass {
            setup,
            triangles,
            accel,
            object: &self.object,
            texel_terms: &self.texel_terms,
            states,
            reads_vertices,
            stretches: stretches(setup, states),
        };
        let (slots, motions) = changes.dirty.listed();
        pass.values_into(
            entries.len(),
            |j| {
                let k = entries[j] as usize;
                (motions[k] != Motion::Rigid).then_some(slots[k])
            },
            &mut self.values,
        );
        for (&k, value) in entries.iter().zip(&self.values) {
            let Some(value) = *value else { continue };
            triangles.log2_pb[slots[k as usize] as usize] = value;
            match motions[k as usize] {
                Motion::Deformed => counts.recomputed += 1,
                _ => counts.shifted += 1,
            }
        }
        counts
    }

    /// `log2 P_b` of every dirty slot of a deforming instance, from its world vertices and
    /// its texel term ([`DeformingTexelTerms`]); returns how many it wrote (the textured
    /// ones). The walk goes through the dirty bits in slot order, so positions, terms and
    /// constants stream through memory instead of being fetched slot by scattered slot
    /// (the pass was ~15 ms of a million skinned triangles' update, most of it waiting on
    /// those loads), and each task writes its own range of slots.
    fn update_deforming(
        &self,
        setup: &FrameSetup,
        changes: &FrameChanges,
        triangles: &mut FrameTriangles,
        accel: &Accel,
    ) -> usize {
        let (table, footprint) = (&self.texel_terms, setup.footprint);
        // The walk over a run of bitset words: `DeformingWalk`.
        let walk = |first_word: usize, words: &[u64], out: &mut [f32]| {
            simd::dispatch(DeformingWalk {
                table,
                footprint,
                accel,
                first_word,
                words,
                out,
            })
        };
        let words = changes.dirty.words();
        let log2_pb = &mut triangles.log2_pb;
        if setup.parallelism.splits(changes.deformed) {
            log2_pb
                .par_chunks_mut(WALK_WORDS * 64)
                .zip(words.par_chunks(WALK_WORDS))
                .enumerate()
                .map(|(chunk, (out, words))| walk(chunk * WALK_WORDS, words, out))
                .sum()
        } else {
            walk(0, words, log2_pb)
        }
    }
}

/// The walk of [`Log2PbState::update_deforming`] over `words` (the dirty bitset's words
/// from `first_word` on), writing the constants of their textured slots into `out` (the
/// slots from `first_word * 64` on); returns how many it wrote. Per bitset word: the squared
/// cross products of its slots, then their logarithms in one batch (vectorised:
/// `lod::log2`), then the constants; the same bits as `log2_pb_with_texel_term` one slot
/// at a time. A whole dirty word (a mesh deforming everywhere) skips the per-slot lists:
/// its terms are read as they lie and its constants stored with a select. A
/// [`simd::Kernel`]: in the AVX2 copy a pack's four cross products in `f64` take one vector
/// per operation instead of two, and the logarithms are inlined there (dispatched again
/// per word, they were a call each). Together about 2.2 -> 1.75 ms of a million skinned
/// triangles' update on two threads (AMD EPYC VM).
struct DeformingWalk<'a> {
    table: &'a DeformingTexelTerms,
    footprint: PixelFootprint,
    accel: &'a Accel,
    first_word: usize,
    words: &'a [u64],
    out: &'a mut [f32],
}

impl simd::Kernel for DeformingWalk<'_> {
    type Output = usize;

    #[inline(always)]
    fn run<const AVX2: bool>(self) -> usize {
        let DeformingWalk {
            table,
            footprint,
            accel,
            first_word,
            words,
            out,
        } = self;
        let base = first_word * 64;
        let mut written = 0;
        let mut slots = [0usize; 64];
        let mut terms = [0f64; 64];
        // Three more than a word's slots: a pack's four lanes are stored at once.
        let mut cc = [0f64; 64 + 3];
        let mut logs = [0f64; 64];
        let mut values = [0f32; 64];
        // The squared cross products of the last pack read, four lanes at once: a pack
        // holds consecutive slots, which the walk visits in order.
        let mut pack: Option<(Range<usize>, [f64; 4])> = None;
        for (w, &word) in words.iter().enumerate() {
            let mut bits = word;
            let mut n = 0;
            let first = base + w * 64;
            // Every slot of the word dirty (a whole mesh deforming): taken pack by pack,
            // a slot of another instance or untextured (a NaN term) left out below.
            if word == u64::MAX
                && let Some(run) = table.run(first..first + 64)
            {
                let mut s = first;
                while s < first + 64 {
                    let (held, lanes) = accel.pack_cross_squared(s as u32);
                    let (held, stop) = (held.start as usize, (held.end as usize).min(first + 64));
                    if held == s {
                        // The pack starts here: its four lanes at once (those past its
                        // live slots are overwritten by the next pack, or unused).
                        cc[s - first..s - first + 4].copy_from_slice(&lanes);
                    } else {
                        // It started in the word before.
                        cc[s - first..stop - first].copy_from_slice(&lanes[s - held..stop - held]);
                    }
                    s = stop;
                }
                // The word's 64 constants side by side, from its slots' run of terms, and
                // stored in place where a slot has a term (a select, not a branch).
                logs.copy_from_slice(&cc[..64]);
                log2_in_place_in::<AVX2>(&mut logs);
                let out = &mut out[first - base..first - base + 64];
                for k in 0..64 {
                    let value = log2_pb_from_parts(cc[k], logs[k], run[k], footprint);
                    let textured = !run[k].is_nan();
                    out[k] = if textured { value } else { out[k] };
                    written += textured as usize;
                }
                continue;
            }
            while bits != 0 {
                let s = first + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let Some(term) = table.of(s) else { continue };
                let (held, lanes) = match &pack {
                    Some((held, lanes)) if held.contains(&s) => (held.start, *lanes),
                    _ => {
                        let (held, lanes) = accel.pack_cross_squared(s as u32);
                        let held = held.start as usize..held.end as usize;
                        (held.start, pack.insert((held, lanes)).1)
                    }
                };
                slots[n] = s;
                terms[n] = term;
                cc[n] = lanes[s - held];
                n += 1;
            }
            logs[..n].copy_from_slice(&cc[..n]);
            log2_in_place_in::<AVX2>(&mut logs[..n]);
            // The constants side by side (the branch-free form compiles to vectors here),
            // then stored where a slot has a texel term.
            for k in 0..n {
                values[k] = log2_pb_from_parts(cc[k], logs[k], terms[k], footprint);
            }
            for k in 0..n {
                if terms[k].is_nan() {
                    continue;
                }
                out[slots[k] - base] = values[k];
                written += 1;
            }
        }
        written
    }
}

/// What computing one triangle's constant reads, made once per pass and shared by its
/// threads.
struct Pass<'a> {
    setup: &'a FrameSetup,
    triangles: &'a FrameTriangles,
    /// The tree over `triangles`: their vertices.
    accel: &'a Accel,
    /// Per source triangle: the object-space constant.
    object: &'a [f32],
    texel_terms: &'a DeformingTexelTerms,
    /// Per instance: this frame's placement and shape key.
    states: &'a [InstanceState],
    /// Whether some triangle of the pass reads its slot's vertices (a placed instance
    /// without a shape key): only then are they prefetched (a stretched 1M crowd's pass
    /// was 1.17x slower fetching them for nothing).
    reads_vertices: bool,
    /// Per instance, see [`stretches`].
    stretches: Stretches,
}

impl Pass<'_> {
    /// Fills `values[k]` with the new `log2 P_b` of slot `slot_at(k)` for `k` in
    /// `0..count` (`None` where `slot_at` skips it or the triangle is untextured). Each
    /// value is a pure function of its own triangle, so the work splits across rayon's
    /// threads when there is enough of it, with results bit-identical to one thread's.
    fn values_into(
        &self,
        count: usize,
        slot_at: impl Fn(usize) -> Option<u32> + Sync,
        values: &mut Vec<Option<f32>>,
    ) {
        let value = |k: usize| {
            // The slots are scattered through the per-slot arrays: ask for the ones a few
            // entries ahead now (before, most of the pass's own time on a million deforming
            // triangles went to waiting for these loads).
            if let Some(ahead) = (k + PREFETCH_AHEAD < count)
                .then(|| slot_at(k + PREFETCH_AHEAD))
                .flatten()
            {
                self.prefetch_slot(ahead as usize);
            }
            slot_at(k).and_then(|slot| self.log2_pb_of(slot))
        };
        // Below 8,192 triangles (`UpdateParallelism::Auto`) rayon's split and join cost more
        // than the work (a triangle's constant takes tens of ns).
        if self.setup.parallelism.splits(count) {
            (0..count)
                .into_par_iter()
                .map(value)
                .collect_into_vec(values);
        } else {
            values.clear();
            values.extend((0..count).map(value));
        }
    }

    /// Hints the cache to load what [`Self::log2_pb_of`] reads of slot `s` (its vertices
    /// too when the pass reads vertices).
    #[inline]
    fn prefetch_slot(&self, s: usize) {
        let t = self.triangles;
        prefetch(&t.source, s);
        if self.reads_vertices {
            self.accel.prefetch_slot(s as u32);
        }
    }

    /// One triangle's `log2 P_b` by the rule for its instance's shape; `None` when
    /// untextured. The value depends only on the shape key and the vertices, never on the
    /// frames before: this is what keeps a sequential run equal to a fresh frame.
    fn log2_pb_of(&self, slot: u32) -> Option<f32> {
        let (geometry, triangles) = (&self.setup.geometry, self.triangles);
        let s = slot as usize;
        let source = triangles.source[s] as usize;
        let object = self.object[source];
        if object.is_nan() {
            return None;
        }
        let instance = geometry.triangle_instance[source] as usize;
        Some(
            match (
                self.states[instance].shape,
                &self.stretches.per_instance[instance],
            ) {
                // Stretch: the object-space triangle under the exact diagonal (a canonical value,
                // whatever rotation the frame adds), shared by the instances with the same
                // primitive, material and stretch.
                (_, Some(stretch)) => match stretch.shared {
                    Some(group) => self.shared_stretched_log2_pb(source, instance, stretch, group),
                    None => self.stretched_log2_pb(source, stretch),
                },
                // Similarity: the object-space constant plus log2 s.
                (Some(NodeShape { scale, .. }), None) => shift_log2_pb(object, scale.log2()),
                // Deforming (or sheared): from its world vertices. A deforming triangle's texel
                // term is read from the table (the source's uvs, perhaps in the other winding:
                // the same area); a sheared one takes the plain form from its slot's uvs. Each
                // triangle always gets the same form.
                (None, None) => match self.texel_terms.of(s) {
                    Some(term) => log2_pb_with_texel_term(
                        self.accel.triangle(slot),
                        term,
                        self.setup.footprint,
                    ),
                    None => {
                        let size = self.setup.texture_size(source).unwrap_or((1, 1));
                        log2_pb(
                            self.accel.triangle(slot),
                            triangles.uvs[s],
                            size,
                            self.setup.footprint,
                        )
                    }
                },
            },
        )
    }

    /// [`Self::stretched_log2_pb`] of source triangle `source` of instance `instance` (under
    /// its `stretch`), read from the constants of its group of instances: computed by the
    /// first to ask, on its thread, over the group's first instance's triangles with its
    /// own stretch, which every member shares (the same primitive, material and stretch, so
    /// the same bits).
    fn shared_stretched_log2_pb(
        &self,
        source: usize,
        instance: usize,
        stretch: &Stretch,
        group: u32,
    ) -> f32 {
        let ranges = &self.setup.geometry.instance_triangles;
        let (first, values) = &self.stretches.shared[group as usize];
        let values = values.get_or_init(|| {
            ranges[*first]
                .clone()
                .map(|s| self.stretched_log2_pb(s as usize, stretch))
                .collect()
        });
        values[source - ranges[instance].start as usize]
    }

    /// `log2 P_b` of a source triangle's rest vertices under its instance's stretch.
    fn stretched_log2_pb(&self, source: usize, stretch: &Stretch) -> f32 {
        let setup = self.setup;
        let instance = setup.geometry.triangle_instance[source] as usize;
        let primitive = setup.geometry.primitive(&setup.scene, instance);
        let placement = &stretch.placement;
        let p = setup.geometry.world_positions(
            &setup.scene,
            source as u32,
            placement,
            &primitive.positions,
        );
        log2_pb(
            p,
            setup
                .geometry
                .oriented_uvs(&setup.scene, source as u32, placement),
            stretch.texture_size,
            setup.footprint,
        )
    }
}

/// Per instance: the stretch of its shape key as the placement [`Pass::stretched_log2_pb`]
/// applies (`None` unless the key has a stretch), made once per frame instead of once per
/// triangle (a 1M stretched crowd's pass spent most of its time inverting the same matrix);
/// instances that draw the same primitive with the same material under the same stretch
/// are grouped, so their constants are computed once (`Stretches`).
fn stretches(setup: &FrameSetup, states: &[InstanceState]) -> Stretches {
    let geometry = &setup.geometry;
    let mut per_instance: Vec<Option<Stretch>> = states
        .iter()
        .enumerate()
        .map(|(instance, state)| {
            let shape = state.shape.filter(|s| s.stretch.is_some())?;
            let [x, y, z] = shape.diagonal();
            let stretch = Mat4::from_scale(Vec3::new(x as f32, y as f32, z as f32));
            Some(Stretch {
                placement: Placement::new(stretch),
                texture_size: setup.instance_texture_size(instance).unwrap_or((1, 1)),
                shared: None,
            })
        })
        .collect();
    // Group by what a constant depends on: the primitive (vertices, indices, uvs), the
    // material (texture size and wrap modes) and the stretch as applied (its f32 diagonal).
    type Key = (u32, u32, u32, [u32; 3]);
    let mut members: HashMap<Key, (usize, usize)> = HashMap::new();
    let key = |instance: usize, stretch: &Stretch| -> Key {
        let i = geometry.instances[instance];
        let m = stretch.placement.world_from_object;
        let diagonal = [m.x_axis.x, m.y_axis.y, m.z_axis.z].map(f32::to_bits);
        (i.mesh, i.primitive, i.material, diagonal)
    };
    for (instance, stretch) in per_instance.iter().enumerate() {
        if let Some(stretch) = stretch {
            members
                .entry(key(instance, stretch))
                .and_modify(|(_, n)| *n += 1)
                .or_insert((instance, 1));
        }
    }
    let mut shared = Vec::new();
    let mut group_of: HashMap<Key, u32> = HashMap::new();
    for (instance, stretch) in per_instance.iter_mut().enumerate() {
        let Some(stretch) = stretch else { continue };
        let k = key(instance, stretch);
        let (first, count) = members[&k];
        if count < 2 {
            continue; // alone: computed triangle by triangle, across threads
        }
        let group = *group_of.entry(k).or_insert_with(|| {
            shared.push((first, OnceLock::new()));
            (shared.len() - 1) as u32
        });
        stretch.shared = Some(group);
    }
    Stretches {
        per_instance,
        shared,
    }
}

/// `log2 P_b` of every source triangle from its rest vertices in object space; NaN where the
/// material is untextured.
fn object_space_log2_pb(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    footprint: PixelFootprint,
) -> Vec<f32> {
    let identity = Placement::new(Mat4::IDENTITY);
    let mut out = vec![f32::NAN; geometry.triangle_count()];
    for (i, instance) in geometry.instances.iter().enumerate() {
        let material = &geometry.materials[instance.material as usize];
        let Some(texture) = material
            .base_color_texture
            .and_then(|t| scene.textures.get(t))
        else {
            continue;
        };
        let primitive = geometry.primitive(scene, i);
        for source in geometry.instance_triangles[i].clone() {
            let (p, _) =
                geometry.world_triangle(scene, source, &identity, &primitive.positions, None);
            out[source as usize] = log2_pb(
                p,
                geometry.oriented_uvs(scene, source, &identity),
                texture.pyramid.base_size(),
                footprint,
            );
        }
    }
    out
}

/// An instance's stretch for [`Pass::stretched_log2_pb`]: `diag(shape.diagonal())` as a
/// placement, and the instance's texture size.
struct Stretch {
    placement: Placement,
    texture_size: (u32, u32),
    /// Index of the instances drawing the same primitive with the same material under the
    /// same stretch (in [`Stretches::shared`]), when there are several: their triangles'
    /// constants are the same, computed once for all of them.
    shared: Option<u32>,
}

/// Per instance: its stretch (`None` unless its shape key has one); and the constants of
/// each group of instances that share a primitive, a material and a stretch (a crowd of
/// copies squashed and stretched by the same animation), made by the first triangle of the
/// group that asks, in the order of the primitive's triangles.
struct Stretches {
    per_instance: Vec<Option<Stretch>>,
    /// Per group: its first instance and, once asked, its triangles' constants.
    shared: Vec<(usize, OnceLock<Vec<f32>>)>,
}

/// Per BVH slot, the [`texel_term`] of a textured triangle of a deforming instance, made
/// at each build of the tree: the uvs and texture of a skinned or morphed mesh never change
/// while its vertices do, so its `log2 P_b` needs only the slot's vertices and this term
/// (its `log2` taken once, not per frame).
/// Empty when no instance deforms; otherwise 8 bytes for every slot of the world tree,
/// remade in O(slots) after each build.
#[derive(Debug, Default)]
pub(super) struct DeformingTexelTerms {
    /// NaN for the slots of other instances and untextured triangles (a term is never NaN:
    /// areas are never negative, and a non-finite one gives `+inf`).
    per_slot: Vec<f64>,
}

impl DeformingTexelTerms {
    fn new(setup: &FrameSetup, triangles: &FrameTriangles, object_log2_pb: &[f32]) -> Self {
        let (geometry, deforms) = (&setup.geometry, &setup.deforms);
        let term = |&source: &u32| {
            let instance = geometry.triangle_instance[source as usize] as usize;
            let textured = !object_log2_pb[source as usize].is_nan();
            if deforms[instance] != VertexSource::Deformed || !textured {
                return f64::NAN;
            }
            let size = setup.texture_size(source as usize).unwrap_or((1, 1));
            // The source's uvs: a slot may hold them in the other winding, the same area.
            texel_term(texel_area(
                uv_area(geometry.triangle_uvs(&setup.scene, source)),
                size,
            ))
        };
        let per_slot = if setup.parallelism.splits(triangles.len()) {
            triangles.source.par_iter().map(term).collect()
        } else {
            triangles.source.iter().map(term).collect()
        };
        DeformingTexelTerms { per_slot }
    }

    fn is_empty(&self) -> bool {
        self.per_slot.is_empty()
    }

    /// The terms of slots `slots` (NaN where [`Self::of`] gives none), if they all exist.
    #[inline]
    fn run(&self, slots: Range<usize>) -> Option<&[f64]> {
        self.per_slot.get(slots)
    }

    /// Slot `s`'s texel term, if it belongs to a deforming instance and is textured.
    #[inline]
    fn of(&self, s: usize) -> Option<f64> {
        let term = *self.per_slot.get(s)?;
        (!term.is_nan()).then_some(term)
    }
}

/// Bitset words (64 slots each) per task of the deforming walk.
const WALK_WORDS: usize = 256;
