//! Which meshes the two-level structure places as instances and which it merges into the
//! world-space tree: the decision behind `--bvh auto` (the default) and the fixed rule of
//! `--bvh two-level`, made once per renderer from the scene at t = 0 and the settings.
//!
//! Invariants:
//! - The plan is a pure function of the scene, the animation selection and the settings
//!   (never of the first frame rendered), so a frame rendered alone is traced through the
//!   same layout as the same frame of a sequence.
//! - Skinned and morphed copies are never instances (their triangles are rewritten in world
//!   space every frame anyway); an empty mesh is never an instance under `auto`.
//! - The plan changes only what rays are traced through, never what a frame's counters
//!   (`moved_triangles`, `deformed_triangles`, `lod_recomputed`, `lod_shifted`) count.
//!
//! The `auto` cost model, per mesh primitive and per class of its copies:
//! - copies that never move are merged (a static instance gains nothing from a transform but
//!   costs a top-level box and a ray setup per visit), unless merging them stores more than
//!   [`MERGE_BUDGET_TRIANGLES`] extra triangles (a forest of one tree);
//! - copies moving rigidly or by a uniform scale are instanced when merging them would store
//!   more than that budget of extra triangles, or when their per-frame update merged
//!   (`REFIT_NS_PER_TRIANGLE` per triangle) costs more than placing them and the rays that
//!   enter them (`PLACE_NS_PER_INSTANCE` each, plus `ENTRY_NS_PER_RAY` per expected entry);
//! - copies whose shape changes (a non-uniform scale animation, or a shape only their world
//!   vertices tell) are merged under the same memory budget: instanced, they would pay a
//!   stretched `log2 P_b` at every hit on top of the entry cost;
//! - then, for the scene as a whole: a top-level tree costs every ray a walk
//!   (`TOP_LEVEL_NS_PER_RAY`) once anything is instanced. When nothing has to be instanced
//!   to keep memory within the budget, and the copies instanced for their update cost save
//!   less in total than that walk costs the frame's rays, they are merged too, and the scene
//!   is traced exactly as under `flat` ([`decide_auto_scene`]);
//! - a copy's expected ray entries are the frame's rays (pixels x samples x (1 + lights):
//!   primary rays and a shadow ray per light from each hit) times the share of the film its
//!   box covers seen from the camera, averaged over [`VIEW_SAMPLES`] times spread evenly over
//!   the animation (a box reaching the eye plane counts as the whole film). Between the
//!   samples this is a guess; the decision is of cost only, never of what a frame shows.
//!
//! The constants were measured on a shared 2-core machine (other sessions compiling; medians
//! of alternated runs), see the comment on each and the user page `docs/src/bvh-layout.md`.

use std::collections::HashMap;
use std::fmt;
use std::str::FromStr;

use glam::{Mat4, Vec3};

use super::posed::VertexSource;
use super::scene_geometry::SceneGeometry;
use crate::accel::BvhLayout;
use crate::anim::{AnimationSelection, NodeShape, Pose, moving_nodes};
use crate::scene::{ChannelTarget, SceneDesc};

// The four time constants were measured together, from one set of runs alternated on the
// 2-core AMD EPYC (Zen 4) VM, quiet (2026-12-05), with mirror packets that share no leaves
// walked masked:
//   mipray bench Robot.aff --frames 100..106 --size 800x600 --methods paper --threads 2
//     --lights 1 --repeats 5 --bvh flat,auto,two-level (four runs, the order turned round
//     in two: render times), and mipray render Robot.aff --frames 100..107 with the same
//     size, `--lod paper --threads 2`, --bvh flat | --bvh two-level, two runs each,
//     alternated (update times: total less render, medians of frames 101..107; BART
//     Robots: 1,340 moving parts of ~28 triangles, 62,490 moving triangles).
// The earlier set (2026-11-26, a 2-core Intel Xeon VM, before the masked mirror packets)
// was 11 ns per entry, 1,120 per instance and 63 per merged triangle, without a top-level
// term; it made `auto` instance 378 of Robots' parts, whose frames then rendered 1.6%
// slower than `flat`'s (5.1-8.6 ms a frame at 2 threads, in the runs above).
// Only their ratios matter: the decision compares sums of them.

/// How many times over the animation (its start and end included) the model looks at the
/// scene through its camera to estimate the rays entering each copy.
pub const VIEW_SAMPLES: usize = 9;

/// Per-ray cost of entering an instance, in ns per entry the model predicts. Fitted with
/// [`TOP_LEVEL_NS_PER_RAY`] to two layouts of BART Robots against `flat`: `two-level`
/// (1,340 parts instanced, 1,451,000 predicted entries at 800x600) rendered 35.9-42.1 ms a
/// frame more than `flat` (median 37.2 over about 337 ms), and `auto` with the earlier
/// constants (378 parts, 91,200 predicted entries) 5.1-8.6 ms more (median 5.5):
/// (37.2 - 5.5) ms / (1,451,000 - 91,200) entries.
pub const ENTRY_NS_PER_RAY: f64 = 23.0;

/// Per-ray cost of a top-level tree at all, in ns per ray of the model's count (pixels x
/// samples x (1 + lights)): every ray walks it once anything is instanced, whether or not
/// it enters an instance. The rest of the fit above: `auto`'s 5.5 ms less its 91,200
/// entries at [`ENTRY_NS_PER_RAY`], over the 960,000 rays of an 800x600 frame with one
/// light.
pub const TOP_LEVEL_NS_PER_RAY: f64 = 3.5;

/// Per-frame cost of a moving instance beyond its entries, in ns: its placement (inverse
/// transform, hull boxes) and its share of the top-level rebuild: the `two-level` update
/// on Robots (median 0.77-0.83 ms a frame, no world triangle moving) over its 1,340
/// instances.
pub const PLACE_NS_PER_INSTANCE: f64 = 600.0;

/// Per-frame cost of a moving triangle merged into the world tree, in ns: writing it,
/// listing it as dirty, refitting its leaf and shifting its `log2 P_b` (and its part's
/// share of the per-instance work): the `flat` update on Robots (median 2.38-2.81 ms a
/// frame) over its 62,490 moving triangles.
pub const REFIT_NS_PER_TRIANGLE: f64 = 42.0;

/// Resident bytes of a triangle merged into the world tree (normals, uvs, material,
/// `log2 P_b`, source, the packs that hold its positions, and its share of the tree; since
/// the flat build takes large inputs a chunk at a time, the peak is what a frame keeps).
/// Measured as the peak resident memory of the crowd under `--bvh flat` less that under
/// `--bvh two-level` (192 MB against 24 MB, `cargo bench --bench frame_loop -- rigid 1M`,
/// 2026-11-26; 374 against 59 before the chunked build, the per-source uvs and indices read
/// from the primitive and the positions kept only in the packs), over the 995,000
/// triangles instancing stores once.
pub const BYTES_PER_TRIANGLE: f64 = 169.0;

/// Most extra world-space triangles the copies of one mesh of one class may add (beyond the
/// first copy) and still be merged: 65,536 triangles are ~11 MB at [`BYTES_PER_TRIANGLE`].
pub const MERGE_BUDGET_TRIANGLES: usize = 65_536;

/// How one drawn copy (instance) of a mesh primitive moves over the selected animation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CopyMotion {
    /// Its node and every ancestor are never animated.
    Static,
    /// Placed by an animated node that only turns, moves and scales uniformly.
    Similarity,
    /// Placed by an animated node whose shape changes (a non-uniform scale animation, or a
    /// stretch under a rotation that only the world vertices tell).
    Reshaping,
    /// Skinned or morphed.
    Deformed,
}

/// One copy as the cost model sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CopyUse {
    pub motion: CopyMotion,
    /// Share of a frame's rays expected to enter the copy's box, in [0, 1]: the share of
    /// the film its box covers seen from the camera, averaged over the animation.
    pub ray_share: f64,
}

/// One mesh primitive and its copies.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshUse {
    pub triangles: usize,
    pub copies: Vec<CopyUse>,
}

/// Why a mesh's copies of one class are placed as they are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    /// No triangles: nothing to instance.
    Empty,
    /// Skinned or morphed: rewritten in world space every frame.
    Deforms,
    /// Never moves and few enough copies to merge.
    Static,
    /// Merging the copies would store more than the budget of extra triangles.
    ManyCopies,
    /// Moving: updating the triangles merged costs more than placing the instances and
    /// the rays that enter them.
    UpdateCostsMore,
    /// Moving: the rays' entries cost more than updating the triangles merged.
    EntriesCostMore,
    /// Moving: instancing would save less update time than a top-level tree costs the
    /// frame's rays, and nothing else needs one.
    TopLevelCostsMore,
    /// The shape changes: `log2 P_b` is recomputed either way; merged, hits pay no stretch.
    Reshapes,
    /// `--bvh two-level`: every copy an animated node places is an instance.
    TwoLevelRule,
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Reason::Empty => "no triangles",
            Reason::Deforms => "skinned or morphed",
            Reason::Static => "never moves",
            Reason::ManyCopies => "copies would cost memory merged",
            Reason::UpdateCostsMore => "update merged costs more than entries",
            Reason::EntriesCostMore => "entries cost more than update merged",
            Reason::TopLevelCostsMore => {
                "a top-level tree costs the rays more than instancing saves"
            }
            Reason::Reshapes => "shape changes",
            Reason::TwoLevelRule => "--bvh two-level places every moving copy",
        })
    }
}

/// Where a mesh's copies of one class go, and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Choice {
    pub instanced: bool,
    pub reason: Reason,
}

impl Choice {
    fn merged(reason: Reason) -> Choice {
        Choice {
            instanced: false,
            reason,
        }
    }

    fn instanced(reason: Reason) -> Choice {
        Choice {
            instanced: true,
            reason,
        }
    }
}

/// The decision for one mesh primitive, per class of copy (`None`: it has no such copy).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MeshChoice {
    pub fixed: Option<Choice>,
    pub similarity: Option<Choice>,
    pub reshaping: Option<Choice>,
    pub deformed: Option<Choice>,
}

impl MeshChoice {
    /// The choice for a copy moving as `motion`.
    pub fn of(&self, motion: CopyMotion) -> Option<Choice> {
        match motion {
            CopyMotion::Static => self.fixed,
            CopyMotion::Similarity => self.similarity,
            CopyMotion::Reshaping => self.reshaping,
            CopyMotion::Deformed => self.deformed,
        }
    }

    /// Whether any copy is instanced.
    pub fn any_instanced(&self) -> bool {
        [self.fixed, self.similarity, self.reshaping, self.deformed]
            .iter()
            .flatten()
            .any(|c| c.instanced)
    }
}

/// Whether merging `copies` copies of a `triangles`-triangle mesh stays within the budget.
fn fits_merged(copies: usize, triangles: usize) -> bool {
    copies.saturating_sub(1).saturating_mul(triangles) <= MERGE_BUDGET_TRIANGLES
}

/// The `auto` decision for one mesh primitive when a frame traces `rays` rays (see the
/// module head), before the scene's own step ([`decide_auto_scene`]) weighs the top level.
pub fn decide_auto(mesh: &MeshUse, rays: f64) -> MeshChoice {
    let of = |motion| mesh.copies.iter().filter(move |c| c.motion == motion);
    let count = |motion| of(motion).count();
    let present = |motion, choice: Choice| (count(motion) > 0).then_some(choice);
    let t = mesh.triangles;
    let deformed = present(CopyMotion::Deformed, Choice::merged(Reason::Deforms));
    if t == 0 {
        let empty = Choice::merged(Reason::Empty);
        return MeshChoice {
            fixed: present(CopyMotion::Static, empty),
            similarity: present(CopyMotion::Similarity, empty),
            reshaping: present(CopyMotion::Reshaping, empty),
            deformed,
        };
    }
    let by_memory = |motion, otherwise: Choice| {
        if fits_merged(count(motion), t) {
            otherwise
        } else {
            Choice::instanced(Reason::ManyCopies)
        }
    };
    let similarity = by_memory(CopyMotion::Similarity, {
        if instancing_saving_ns(mesh, rays) > 0.0 {
            Choice::instanced(Reason::UpdateCostsMore)
        } else {
            Choice::merged(Reason::EntriesCostMore)
        }
    });
    MeshChoice {
        fixed: present(
            CopyMotion::Static,
            by_memory(CopyMotion::Static, Choice::merged(Reason::Static)),
        ),
        similarity: present(CopyMotion::Similarity, similarity),
        reshaping: present(
            CopyMotion::Reshaping,
            by_memory(CopyMotion::Reshaping, Choice::merged(Reason::Reshapes)),
        ),
        deformed,
    }
}

/// Update time a frame saves by instancing `mesh`'s rigidly moving copies rather than
/// merging them, in ns (negative where instancing costs more): their triangles' update
/// merged, less their placements and the rays' expected entries instanced.
fn instancing_saving_ns(mesh: &MeshUse, rays: f64) -> f64 {
    let rigid = mesh
        .copies
        .iter()
        .filter(|c| c.motion == CopyMotion::Similarity);
    let instanced_ns: f64 = rigid
        .clone()
        .map(|c| PLACE_NS_PER_INSTANCE + ENTRY_NS_PER_RAY * rays * c.ray_share)
        .sum();
    let merged_ns = rigid.count() as f64 * mesh.triangles as f64 * REFIT_NS_PER_TRIANGLE;
    merged_ns - instanced_ns
}

/// The `auto` decision for every mesh primitive of a scene (see the module head): each
/// mesh's own ([`decide_auto`]), then the top level's price. When no copy must be an
/// instance to keep memory within the budget, instancing pays only if the copies
/// instanced for their update cost save more, together, than a top-level walk costs the
/// frame's `rays`; otherwise they are merged too, and nothing is instanced.
pub fn decide_auto_scene(meshes: &[&MeshUse], rays: f64) -> Vec<MeshChoice> {
    let mut choices: Vec<MeshChoice> = meshes.iter().map(|m| decide_auto(m, rays)).collect();
    let for_update = Some(Choice::instanced(Reason::UpdateCostsMore));
    let needed = choices.iter().any(|c| {
        [c.fixed, c.similarity, c.reshaping, c.deformed]
            .iter()
            .flatten()
            .any(|c| c.instanced && c.reason == Reason::ManyCopies)
    });
    let saving: f64 = meshes
        .iter()
        .zip(&choices)
        .filter(|(_, c)| c.similarity == for_update)
        .map(|(m, _)| instancing_saving_ns(m, rays))
        .sum();
    if !needed && saving <= TOP_LEVEL_NS_PER_RAY * rays {
        for c in choices.iter_mut().filter(|c| c.similarity == for_update) {
            c.similarity = Some(Choice::merged(Reason::TopLevelCostsMore));
        }
    }
    choices
}

/// The `--bvh two-level` rule for one mesh primitive: every copy an animated node places is
/// an instance; static copies are merged within the memory budget; deformed ones never.
pub fn decide_two_level(mesh: &MeshUse) -> MeshChoice {
    let count = |motion| mesh.copies.iter().filter(|c| c.motion == motion).count();
    let present = |motion, choice: Choice| (count(motion) > 0).then_some(choice);
    let fixed = if fits_merged(count(CopyMotion::Static), mesh.triangles) {
        Choice::merged(Reason::Static)
    } else {
        Choice::instanced(Reason::ManyCopies)
    };
    MeshChoice {
        fixed: present(CopyMotion::Static, fixed),
        similarity: present(
            CopyMotion::Similarity,
            Choice::instanced(Reason::TwoLevelRule),
        ),
        reshaping: present(
            CopyMotion::Reshaping,
            Choice::instanced(Reason::TwoLevelRule),
        ),
        deformed: present(CopyMotion::Deformed, Choice::merged(Reason::Deforms)),
    }
}

/// One mesh primitive of the plan: what it is, how its copies move and where they go.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshPlan {
    /// `(mesh, primitive)` indices into the scene.
    pub mesh: u32,
    pub primitive: u32,
    pub name: String,
    pub usage: MeshUse,
    pub choice: MeshChoice,
}

/// The layout a renderer traces through, decided once from the scene and settings.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LayoutPlan {
    /// What was asked for.
    pub requested: BvhLayout,
    /// Per mesh primitive drawn, in order of first drawing instance.
    pub meshes: Vec<MeshPlan>,
    /// Per scene instance: whether it is placed as an instance of its shared mesh.
    pub instanced: Vec<bool>,
    /// Rays per frame the model assumed.
    pub rays_per_frame: f64,
}

/// What a frame is traced through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UsedLayout {
    /// One world-space tree over every triangle.
    Flat,
    /// Instances of shared meshes under top-level trees, beside the world-space tree.
    TwoLevel,
}

impl UsedLayout {
    pub fn name(self) -> &'static str {
        match self {
            UsedLayout::Flat => "flat",
            UsedLayout::TwoLevel => "two-level",
        }
    }
}

impl fmt::Display for UsedLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for UsedLayout {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "flat" => Ok(UsedLayout::Flat),
            "two-level" => Ok(UsedLayout::TwoLevel),
            _ => Err(format!("unknown layout `{s}` (flat, two-level)")),
        }
    }
}

impl LayoutPlan {
    /// The plan for `scene` under `layout` (`pose`: the scene at t = 0; `deforms`: per
    /// instance, where its vertices come from; `samples`: the scene and its camera at a few
    /// times spread over the animation, t = 0 first).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        scene: &SceneDesc,
        geometry: &SceneGeometry,
        deforms: &[VertexSource],
        selection: AnimationSelection,
        pose: &Pose,
        samples: &[ViewSample],
        layout: BvhLayout,
        rays_per_frame: f64,
    ) -> LayoutPlan {
        let motions = copy_motions(scene, geometry, deforms, selection, pose);
        let mut object_boxes: HashMap<(u32, u32), (Vec3, Vec3)> = HashMap::new();
        let mut meshes: Vec<MeshPlan> = Vec::new();
        let mut index_of: HashMap<(u32, u32), usize> = HashMap::new();
        for (i, instance) in geometry.instances.iter().enumerate() {
            let key = (instance.mesh, instance.primitive);
            let k = *index_of.entry(key).or_insert_with(|| {
                let mesh = &scene.meshes[instance.mesh as usize];
                let name = if mesh.name.is_empty() {
                    format!("mesh {}", instance.mesh)
                } else {
                    mesh.name.clone()
                };
                meshes.push(MeshPlan {
                    mesh: instance.mesh,
                    primitive: instance.primitive,
                    name,
                    usage: MeshUse {
                        triangles: geometry.instance_triangles[i].len(),
                        copies: Vec::new(),
                    },
                    choice: MeshChoice::default(),
                });
                meshes.len() - 1
            });
            let ray_share = match motions[i] {
                CopyMotion::Deformed => 1.0,
                _ => {
                    let object = *object_boxes
                        .entry(key)
                        .or_insert_with(|| finite_box(&geometry.primitive(scene, i).positions));
                    mean_film_share(object, instance.node as usize, samples)
                }
            };
            meshes[k].usage.copies.push(CopyUse {
                motion: motions[i],
                ray_share,
            });
        }
        let choices: Vec<MeshChoice> = match layout {
            BvhLayout::Flat => vec![MeshChoice::default(); meshes.len()],
            BvhLayout::TwoLevel => meshes.iter().map(|m| decide_two_level(&m.usage)).collect(),
            BvhLayout::Auto => {
                let usages: Vec<&MeshUse> = meshes.iter().map(|m| &m.usage).collect();
                decide_auto_scene(&usages, rays_per_frame)
            }
        };
        for (m, choice) in meshes.iter_mut().zip(choices) {
            m.choice = choice;
        }
        let instanced = geometry
            .instances
            .iter()
            .enumerate()
            .map(|(i, instance)| {
                let k = index_of[&(instance.mesh, instance.primitive)];
                meshes[k].choice.of(motions[i]).is_some_and(|c| c.instanced)
            })
            .collect();
        LayoutPlan {
            requested: layout,
            meshes,
            instanced,
            rays_per_frame,
        }
    }

    /// What frames are traced through: flat when no copy is an instance (under `auto`
    /// exactly the `--bvh flat` path), else two-level.
    pub fn used(&self) -> UsedLayout {
        match self.requested {
            BvhLayout::Flat => UsedLayout::Flat,
            BvhLayout::TwoLevel => UsedLayout::TwoLevel,
            BvhLayout::Auto if self.instanced.iter().any(|&i| i) => UsedLayout::TwoLevel,
            BvhLayout::Auto => UsedLayout::Flat,
        }
    }

    /// Mesh primitives with at least one copy placed as an instance.
    pub fn instanced_meshes(&self) -> usize {
        if self.used() == UsedLayout::Flat {
            return 0;
        }
        self.meshes
            .iter()
            .filter(|m| m.choice.any_instanced())
            .count()
    }

    /// Ray entries per frame the model expects into `mesh`'s copies moving as `motion` were
    /// they instances.
    pub fn expected_entries(&self, mesh: &MeshPlan, motion: CopyMotion) -> f64 {
        mesh.usage
            .copies
            .iter()
            .filter(|c| c.motion == motion)
            .map(|c| self.rays_per_frame * c.ray_share)
            .sum()
    }

    /// The plan for people (`mipray info`): a summary line, then one line per mesh
    /// primitive when there are at most `detail_limit`, else one per class of decision.
    pub fn describe(&self, detail_limit: usize) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let copies: usize = self.instanced.len();
        let instanced = self.instanced.iter().filter(|&&i| i).count();
        let _ = writeln!(
            s,
            "bvh {}: {} ({} of {} mesh primitives instanced, {instanced} of {copies} copies; \
             model assumes {:.0} rays per frame)",
            self.requested,
            self.used(),
            self.instanced_meshes(),
            self.meshes.len(),
            self.rays_per_frame,
        );
        let classes = [
            (CopyMotion::Static, "static"),
            (CopyMotion::Similarity, "rigid"),
            (CopyMotion::Reshaping, "reshaping"),
            (CopyMotion::Deformed, "deformed"),
        ];
        if self.meshes.len() <= detail_limit {
            for m in &self.meshes {
                for (motion, label) in classes {
                    let Some(choice) = m.choice.of(motion) else {
                        continue;
                    };
                    let n = m.usage.copies.iter().filter(|c| c.motion == motion).count();
                    let entries = match motion {
                        CopyMotion::Similarity => format!(
                            "; ~{:.0} ray entries per frame instanced",
                            self.expected_entries(m, motion)
                        ),
                        _ => String::new(),
                    };
                    let _ = writeln!(
                        s,
                        "  {} (mesh {} primitive {}, {} triangles): {n} {label} {} {} ({}{entries})",
                        m.name,
                        m.mesh,
                        m.primitive,
                        m.usage.triangles,
                        if n == 1 { "copy" } else { "copies" },
                        if choice.instanced {
                            "instanced"
                        } else {
                            "merged"
                        },
                        choice.reason,
                    );
                }
            }
            return s;
        }
        // Grouped: per (class, decision, reason), how many meshes, copies and triangles.
        let mut groups: Vec<((&str, bool, Reason), (usize, usize, usize, f64))> = Vec::new();
        for m in &self.meshes {
            for (motion, label) in classes {
                let Some(choice) = m.choice.of(motion) else {
                    continue;
                };
                let n = m.usage.copies.iter().filter(|c| c.motion == motion).count();
                let key = (label, choice.instanced, choice.reason);
                let at = match groups.iter().position(|(k, _)| *k == key) {
                    Some(at) => at,
                    None => {
                        groups.push((key, (0, 0, 0, 0.0)));
                        groups.len() - 1
                    }
                };
                let g = &mut groups[at].1;
                g.0 += 1;
                g.1 += n;
                g.2 += n * m.usage.triangles;
                g.3 += self.expected_entries(m, motion);
            }
        }
        for ((label, instanced, reason), (meshes, copies, triangles, entries)) in groups {
            let entries = if label == "rigid" {
                format!("; ~{entries:.0} ray entries per frame instanced")
            } else {
                String::new()
            };
            let _ = writeln!(
                s,
                "  {meshes} mesh primitives, {copies} {label} copies, {triangles} triangles: {} ({reason}{entries})",
                if instanced { "instanced" } else { "merged" },
            );
        }
        s
    }
}

/// Per instance: how it moves over the selected animation (see [`CopyMotion`]).
fn copy_motions(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    deforms: &[VertexSource],
    selection: AnimationSelection,
    pose: &Pose,
) -> Vec<CopyMotion> {
    let moving = moving_nodes(scene, selection);
    let mut shapes = Vec::new();
    pose.node_shapes(scene, &mut shapes);
    let reshaping = reshaping_nodes(scene, selection, &shapes);
    geometry
        .instances
        .iter()
        .zip(deforms)
        .map(|(instance, source)| {
            let node = instance.node as usize;
            if *source == VertexSource::Deformed {
                CopyMotion::Deformed
            } else if !moving[node] {
                CopyMotion::Static
            } else if reshaping[node] {
                CopyMotion::Reshaping
            } else {
                CopyMotion::Similarity
            }
        })
        .collect()
}

/// Per node: whether its shape may change over the animation: its rest shape is not a
/// similarity-with-stretch the shape key tracks (`None`), or a scale channel on it or an
/// ancestor keys a non-uniform scale, or scales a chain that holds a stretch. (A decision
/// of cost only: a copy judged rigid that reshapes is still traced and counted exactly.)
fn reshaping_nodes(
    scene: &SceneDesc,
    selection: AnimationSelection,
    rest_shapes: &[Option<NodeShape>],
) -> Vec<bool> {
    let n = scene.nodes.len();
    let mut scaled = vec![false; n];
    let mut non_uniform = vec![false; n];
    for c in selection.clips(scene).iter().flat_map(|a| &a.channels) {
        if c.target == ChannelTarget::Scale && c.node < n {
            scaled[c.node] = true;
            let uniform = c.components == 3
                && c.values
                    .chunks_exact(3)
                    .all(|v| v[0] == v[1] && v[1] == v[2]);
            non_uniform[c.node] |= !uniform;
        }
    }
    let mut out = vec![false; n];
    let mut stack: Vec<(usize, bool, bool)> =
        scene.roots.iter().map(|&r| (r, false, false)).collect();
    let mut seen = vec![false; n];
    while let Some((i, parent_scaled, parent_non_uniform)) = stack.pop() {
        if i >= n || seen[i] {
            continue;
        }
        seen[i] = true;
        let chain_scaled = parent_scaled || scaled[i];
        let chain_non_uniform = parent_non_uniform || non_uniform[i];
        let stretched = rest_shapes
            .get(i)
            .copied()
            .flatten()
            .is_none_or(|s| s.stretch.is_some());
        let rest_unknown = rest_shapes.get(i).copied().flatten().is_none();
        out[i] = rest_unknown || chain_non_uniform || (chain_scaled && stretched);
        stack.extend(
            scene.nodes[i]
                .children
                .iter()
                .map(|&c| (c, chain_scaled, chain_non_uniform)),
        );
    }
    out
}

/// A camera as the model estimates primary rays from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestView {
    pub eye: Vec3,
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    /// Half the film's extent at unit distance, across and up (`tan(yfov / 2)` x aspect).
    pub half_width: f32,
    pub half_height: f32,
}

impl RestView {
    /// The view of `camera`.
    pub fn of(camera: &crate::render::Camera) -> RestView {
        let half_height = (camera.yfov * 0.5).tan();
        let aspect = camera.width.max(1) as f32 / camera.height.max(1) as f32;
        RestView {
            eye: camera.eye.into(),
            forward: camera.forward.into(),
            right: camera.right.into(),
            up: camera.up.into(),
            half_width: half_height * aspect,
            half_height,
        }
    }

    /// Share of the film the box `min..max` covers seen from here, in [0, 1]: 0 behind the
    /// camera or off the film, 1 when the box reaches the eye plane (the camera may be in
    /// it), and 1 when a number is not finite.
    fn film_share(&self, min: Vec3, max: Vec3) -> f64 {
        if !(min.cmple(max).all()) {
            return 0.0; // an empty box
        }
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        let (mut ahead, mut behind) = (false, false);
        for k in 0..8 {
            let corner = Vec3::new(
                if k & 1 == 0 { min.x } else { max.x },
                if k & 2 == 0 { min.y } else { max.y },
                if k & 4 == 0 { min.z } else { max.z },
            );
            let d = corner - self.eye;
            let z = d.dot(self.forward);
            if !(z > 0.0) {
                behind = true;
                continue;
            }
            ahead = true;
            let film = [
                d.dot(self.right) / (z * self.half_width),
                d.dot(self.up) / (z * self.half_height),
            ];
            for a in 0..2 {
                lo[a] = lo[a].min(film[a]);
                hi[a] = hi[a].max(film[a]);
            }
        }
        if !ahead {
            return 0.0;
        }
        if behind {
            return 1.0;
        }
        let covered = |a: usize| (hi[a].min(1.0) - lo[a].max(-1.0)).max(0.0) as f64 / 2.0;
        let share = covered(0) * covered(1);
        if share.is_finite() { share } else { 1.0 }
    }
}

/// The scene and its camera at one time, as the model samples them.
#[derive(Debug, Clone)]
pub struct ViewSample {
    /// Per node: world from node.
    pub world_from_node: Vec<Mat4>,
    pub view: RestView,
}

/// The box of the finite points of `positions` (an empty, inverted box when none).
fn finite_box(positions: &[Vec3]) -> (Vec3, Vec3) {
    let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &p in positions.iter().filter(|p| p.is_finite()) {
        min = min.min(p);
        max = max.max(p);
    }
    (min, max)
}

/// The world box of the object box `(min, max)` placed by `world` (its eight corners).
fn placed_box((min, max): (Vec3, Vec3), world: Mat4) -> (Vec3, Vec3) {
    if !min.cmple(max).all() {
        return (min, max);
    }
    let corners = (0..8).map(|k| {
        world.transform_point3(Vec3::new(
            if k & 1 == 0 { min.x } else { max.x },
            if k & 2 == 0 { min.y } else { max.y },
            if k & 4 == 0 { min.z } else { max.z },
        ))
    });
    let corners: Vec<Vec3> = corners.collect();
    finite_box(&corners)
}

/// Mean over `samples` of the share of the film the object box placed by `node` covers:
/// the share of a frame's primary rays expected to enter it (0 without samples).
fn mean_film_share(object: (Vec3, Vec3), node: usize, samples: &[ViewSample]) -> f64 {
    if samples.is_empty() {
        return 0.0;
    }
    let total: f64 = samples
        .iter()
        .map(|s| {
            let world = s
                .world_from_node
                .get(node)
                .copied()
                .unwrap_or(Mat4::IDENTITY);
            let (min, max) = placed_box(object, world);
            s.view.film_share(min, max)
        })
        .sum();
    total / samples.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mesh(triangles: usize, copies: &[(CopyMotion, f64)]) -> MeshUse {
        MeshUse {
            triangles,
            copies: copies
                .iter()
                .map(|&(motion, ray_share)| CopyUse { motion, ray_share })
                .collect(),
        }
    }

    /// Rays of a 640x360 frame with one light.
    const RAYS: f64 = 640.0 * 360.0 * 2.0;

    #[test]
    fn a_mesh_drawn_once_and_never_moving_is_merged() {
        let c = decide_auto(&mesh(100_000, &[(CopyMotion::Static, 0.5)]), RAYS);
        assert_eq!(c.fixed, Some(Choice::merged(Reason::Static)));
        assert!(!c.any_instanced());
    }

    #[test]
    fn tiny_moving_parts_are_merged() {
        // BART Robots' parts: ~28 triangles, each a small share of the scene.
        let parts = vec![(CopyMotion::Similarity, 0.002); 10];
        let c = decide_auto(&mesh(28, &parts), RAYS);
        assert_eq!(c.similarity, Some(Choice::merged(Reason::EntriesCostMore)));
    }

    #[test]
    fn a_large_rigid_mesh_drawn_once_is_instanced() {
        // A twentieth of the film: 23,000 entries cost less than refitting 200,000 triangles.
        let c = decide_auto(&mesh(200_000, &[(CopyMotion::Similarity, 0.05)]), RAYS);
        assert_eq!(
            c.similarity,
            Some(Choice::instanced(Reason::UpdateCostsMore))
        );
        // A quarter of its size filling the film costs more in entries than merged.
        let c = decide_auto(&mesh(50_000, &[(CopyMotion::Similarity, 1.0)]), RAYS);
        assert_eq!(c.similarity, Some(Choice::merged(Reason::EntriesCostMore)));
    }

    #[test]
    fn the_entry_cost_decides_between_merged_and_instanced() {
        // One copy seen by every ray: instanced only when its update costs more than the
        // frame's entries and its placement.
        let entries_ns = PLACE_NS_PER_INSTANCE + ENTRY_NS_PER_RAY * RAYS;
        let break_even = (entries_ns / REFIT_NS_PER_TRIANGLE) as usize;
        let just_below = decide_auto(
            &mesh(break_even - 1, &[(CopyMotion::Similarity, 1.0)]),
            RAYS,
        );
        let just_above = decide_auto(
            &mesh(break_even + 1, &[(CopyMotion::Similarity, 1.0)]),
            RAYS,
        );
        assert!(!just_below.any_instanced());
        assert!(just_above.any_instanced());
    }

    #[test]
    fn instancing_that_saves_less_than_the_top_level_costs_is_dropped() {
        // Robots-like: parts of 100 triangles, each seen by ~140 rays: each saves a little
        // update time instanced, but ten of them far less than a top-level walk costs.
        let part = mesh(100, &[(CopyMotion::Similarity, 0.0003)]);
        assert!(instancing_saving_ns(&part, RAYS) > 0.0);
        assert_eq!(
            decide_auto(&part, RAYS).similarity,
            Some(Choice::instanced(Reason::UpdateCostsMore))
        );
        let parts = vec![&part; 10];
        for c in decide_auto_scene(&parts, RAYS) {
            assert_eq!(
                c.similarity,
                Some(Choice::merged(Reason::TopLevelCostsMore))
            );
            assert!(!c.any_instanced());
        }
        // A crowd that must be instanced for memory pays for the top level anyway, so the
        // parts keep the choice that saves them time.
        let crowd = mesh(5_000, &vec![(CopyMotion::Similarity, 0.01); 200]);
        let mut with_crowd = parts.clone();
        with_crowd.push(&crowd);
        let choices = decide_auto_scene(&with_crowd, RAYS);
        assert!(choices.iter().all(MeshChoice::any_instanced));
        assert_eq!(
            choices[0].similarity,
            Some(Choice::instanced(Reason::UpdateCostsMore))
        );
        // So does a large rigid mesh whose instancing saves more than the walk costs.
        let big = mesh(200_000, &[(CopyMotion::Similarity, 0.05)]);
        let mut with_big = parts.clone();
        with_big.push(&big);
        assert!(
            decide_auto_scene(&with_big, RAYS)
                .iter()
                .all(MeshChoice::any_instanced)
        );
        // Moving copies merged for their entries, and static ones, are left as they were.
        let small = mesh(
            28,
            &[(CopyMotion::Similarity, 0.002), (CopyMotion::Static, 0.1)],
        );
        let alone = decide_auto_scene(&[&small], RAYS);
        assert_eq!(alone, vec![decide_auto(&small, RAYS)]);
    }

    #[test]
    fn the_top_level_cost_decides_between_flat_and_two_level() {
        // One copy no ray enters: instancing saves its update less its placement, which must
        // exceed the top level's walk over every ray of the frame.
        let walk_ns = TOP_LEVEL_NS_PER_RAY * RAYS;
        let break_even = ((walk_ns + PLACE_NS_PER_INSTANCE) / REFIT_NS_PER_TRIANGLE) as usize;
        let at = |t: usize| decide_auto_scene(&[&mesh(t, &[(CopyMotion::Similarity, 0.0)])], RAYS);
        assert_eq!(
            at(break_even)[0].similarity,
            Some(Choice::merged(Reason::TopLevelCostsMore))
        );
        assert_eq!(
            at(break_even + 1)[0].similarity,
            Some(Choice::instanced(Reason::UpdateCostsMore))
        );
        // Without rays the walk is free, and the per-mesh choice stands.
        let part = mesh(100, &[(CopyMotion::Similarity, 0.0)]);
        assert!(decide_auto_scene(&[&part], 0.0)[0].any_instanced());
    }

    #[test]
    fn a_mesh_drawn_by_many_nodes_is_instanced_when_merging_costs_memory() {
        // The crowd: 200 copies of 5,000 triangles, each a small share of the scene.
        let crowd = vec![(CopyMotion::Similarity, 0.01); 200];
        let c = decide_auto(&mesh(5_000, &crowd), RAYS);
        assert_eq!(c.similarity, Some(Choice::instanced(Reason::ManyCopies)));
        // A static forest too.
        let forest = vec![(CopyMotion::Static, 0.01); 200];
        assert_eq!(
            decide_auto(&mesh(5_000, &forest), RAYS).fixed,
            Some(Choice::instanced(Reason::ManyCopies))
        );
        // A few static copies of a small mesh are merged.
        let chairs = vec![(CopyMotion::Static, 0.01); 8];
        assert_eq!(
            decide_auto(&mesh(500, &chairs), RAYS).fixed,
            Some(Choice::merged(Reason::Static))
        );
    }

    #[test]
    fn uniform_scale_may_instance_but_a_changing_shape_is_merged() {
        let big = 200_000;
        let uniform = decide_auto(&mesh(big, &[(CopyMotion::Similarity, 0.05)]), RAYS);
        let stretched = decide_auto(&mesh(big, &[(CopyMotion::Reshaping, 0.05)]), RAYS);
        assert!(uniform.any_instanced());
        assert_eq!(stretched.reshaping, Some(Choice::merged(Reason::Reshapes)));
    }

    #[test]
    fn skinned_and_morphed_copies_are_never_instanced() {
        let many = vec![(CopyMotion::Deformed, 1.0); 500];
        for choice in [
            decide_auto(&mesh(100_000, &many), RAYS),
            decide_two_level(&mesh(100_000, &many)),
        ] {
            assert_eq!(choice.deformed, Some(Choice::merged(Reason::Deforms)));
            assert!(!choice.any_instanced());
        }
    }

    #[test]
    fn a_mesh_without_triangles_is_not_instanced() {
        let copies = [
            (CopyMotion::Static, 0.0),
            (CopyMotion::Similarity, 0.0),
            (CopyMotion::Reshaping, 0.0),
        ];
        let c = decide_auto(&mesh(0, &copies), RAYS);
        assert!(!c.any_instanced());
        assert_eq!(c.similarity, Some(Choice::merged(Reason::Empty)));
        // No rays at all (an empty frame) decide nothing differently for it.
        assert!(!decide_auto(&mesh(0, &copies), 0.0).any_instanced());
    }

    #[test]
    fn classes_without_copies_have_no_choice() {
        let c = decide_auto(&mesh(10, &[(CopyMotion::Static, 0.1)]), RAYS);
        assert_eq!(c.similarity, None);
        assert_eq!(c.reshaping, None);
        assert_eq!(c.deformed, None);
    }

    #[test]
    fn two_level_places_every_moving_copy() {
        let c = decide_two_level(&mesh(
            28,
            &[
                (CopyMotion::Similarity, 0.001),
                (CopyMotion::Reshaping, 0.001),
                (CopyMotion::Static, 0.001),
            ],
        ));
        assert_eq!(c.similarity, Some(Choice::instanced(Reason::TwoLevelRule)));
        assert_eq!(c.reshaping, Some(Choice::instanced(Reason::TwoLevelRule)));
        assert_eq!(c.fixed, Some(Choice::merged(Reason::Static)));
    }

    #[test]
    fn film_share_is_the_covered_part_of_the_film_and_guarded() {
        let view = RestView {
            eye: Vec3::ZERO,
            forward: Vec3::NEG_Z,
            right: Vec3::X,
            up: Vec3::Y,
            half_width: 1.0,
            half_height: 1.0,
        };
        // A box filling the right half of the film at distance 2.
        let half = view.film_share(Vec3::new(0.0, -2.0, -2.0), Vec3::new(2.0, 2.0, -2.0));
        assert!((half - 0.5).abs() < 1e-6, "{half}");
        // Larger than the film: clipped to all of it.
        let all = view.film_share(Vec3::new(-9.0, -9.0, -3.0), Vec3::new(9.0, 9.0, -2.0));
        assert_eq!(all, 1.0);
        // Behind the camera, off the film, empty: nothing.
        assert_eq!(view.film_share(Vec3::splat(1.0), Vec3::splat(2.0)), 0.0);
        let aside = view.film_share(Vec3::new(5.0, 0.0, -2.0), Vec3::new(6.0, 1.0, -2.0));
        assert_eq!(aside, 0.0);
        assert_eq!(view.film_share(Vec3::ONE, Vec3::ZERO), 0.0);
        // Reaching the eye plane: the camera may be inside it.
        assert_eq!(view.film_share(Vec3::splat(-1.0), Vec3::splat(1.0)), 1.0);
        // No vertex at all, and a placement that overflows.
        let sample = |world: Mat4| ViewSample {
            world_from_node: vec![world],
            view,
        };
        let nothing = finite_box(&[]);
        assert_eq!(mean_film_share(nothing, 0, &[sample(Mat4::IDENTITY)]), 0.0);
        let unit = finite_box(&[Vec3::ZERO, Vec3::ONE]);
        let huge = Mat4::from_translation(Vec3::new(0.0, 0.0, -1e30))
            * Mat4::from_scale(Vec3::splat(1e30));
        let share = mean_film_share(unit, 0, &[sample(huge)]);
        assert!((0.0..=1.0).contains(&share), "{share}");
        // The mean over the samples: in view at one time of two.
        let ahead = Mat4::from_translation(Vec3::new(-0.5, -0.5, -1.5));
        let behind = Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0));
        let one = mean_film_share(unit, 0, &[sample(ahead)]);
        let half = mean_film_share(unit, 0, &[sample(ahead), sample(behind)]);
        assert!(
            one > 0.0 && (half - one / 2.0).abs() < 1e-12,
            "{one} {half}"
        );
        assert_eq!(mean_film_share(unit, 0, &[]), 0.0);
    }

    /// A root with a child, the child scaled by a channel keyed with `values` (three per
    /// key), optionally under a statically stretched root.
    fn scaled_child_scene(values: &[f32], root_scale: Vec3) -> SceneDesc {
        use crate::scene::{AnimationDesc, ChannelDesc, Interpolation, NodeDesc, Trs};
        let mut scene = SceneDesc::default();
        scene.nodes.push(NodeDesc {
            local: Trs {
                scale: root_scale,
                ..Default::default()
            },
            children: vec![1],
            ..Default::default()
        });
        scene.nodes.push(NodeDesc::default());
        scene.roots = vec![0];
        scene.animations.push(AnimationDesc {
            name: "scale".into(),
            channels: vec![ChannelDesc {
                node: 1,
                target: ChannelTarget::Scale,
                interpolation: Interpolation::Linear,
                times: (0..values.len() / 3).map(|k| k as f32).collect(),
                values: values.to_vec(),
                components: 3,
            }],
        });
        scene
    }

    fn reshaping_child(values: &[f32], root_scale: Vec3) -> bool {
        let scene = scaled_child_scene(values, root_scale);
        let mut pose = Pose::default();
        pose.evaluate(&scene, AnimationSelection::All, 0.0);
        let mut shapes = Vec::new();
        pose.node_shapes(&scene, &mut shapes);
        reshaping_nodes(&scene, AnimationSelection::All, &shapes)[1]
    }

    #[test]
    fn a_uniform_scale_animation_keeps_the_shape_a_non_uniform_one_changes_it() {
        let uniform = [1.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        let non_uniform = [1.0, 1.0, 1.0, 2.0, 1.0, 1.0];
        assert!(!reshaping_child(&uniform, Vec3::ONE));
        assert!(reshaping_child(&non_uniform, Vec3::ONE));
        // A uniform scale of a node under a stretched parent still changes the stretch key.
        assert!(reshaping_child(&uniform, Vec3::new(2.0, 1.0, 1.0)));
    }
}
