//! Acceleration structures: what rays are traced against, arranged by algorithm.
//!
//! - `flat`: one tree over the frame's world-space triangles. obvhs builds a binary tree
//!   (without spatial splits, so it can be refitted; past [`BUILD_CHUNK_TRIANGLES`] a chunk
//!   at a time under median splits, which bounds the builder's memory), which is collapsed
//!   into the 8-wide tree rays walk and refits update (`wide`); the triangle arrays are
//!   permuted into the tree's slot order after a build, so a leaf's slot range indexes them
//!   directly, and the positions move into the tree's packs, their only copy from then on.
//! - `query`: the answers (`Hit`, `TriangleRef`) and the per-query state every tree shares
//!   (the best hit so far and its tie rule, a packet's reusable buffers).
//! - `instanced`: the two-level structure: object-space trees of shared meshes placed by
//!   instances under a top-level tree.
//! - `policy`: when to refit and when to rebuild.
//! - `triangles`: triangles packed four per SIMD test, watertight.
//! - `wide`: the 8-wide tree itself: node layout and collapse, refit and SAH, the walks,
//!   packets, lanes.
//!
//! Which SIMD copy of the walks runs is decided in one place, [`crate::simd`].
//!
//! The invariant every tree keeps: the closest hit is the nearest, ties to the lowest source
//! triangle, so the answer does not depend on the tree's shape, on refits or on the walk
//! (packets and single rays find the same hits).

mod flat;
mod instanced;
mod policy;
mod query;
mod triangles;
mod wide;

pub use flat::{Accel, AccelError, BUILD_CHUNK_TRIANGLES, RefitKind, RunLeafBoxes, padded_box};
pub use instanced::{TlasInstance, TwoLevelAccel};
pub use policy::{BvhLayout, BvhPolicy, TreeStep};
pub use query::{Hit, TriangleRef};
pub use triangles::{LANES as PACK_LANES, SlotLanes, intersect};
pub use wide::PACKET;

#[cfg(test)]
pub(crate) use flat::tests;
