//! When the tree is refitted and when it is rebuilt: the one policy decision of the per-frame
//! BVH update (kajiya / Embree habit: the update step and its policy in one small function).
//!
//! Refitting keeps the topology and only widens or narrows boxes, so it is cheap but lets the
//! tree decay as things move apart; the surface-area-heuristic cost measured against its
//! value right after the last build says when the decay is worth a rebuild.

use std::borrow::Cow;
use std::time::Instant;

use super::{Accel, RefitKind};

/// What rays are traced against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BvhLayout {
    /// One tree over every triangle in world space, refitted as they move.
    Flat,
    /// A tree per shared mesh in object space, a top-level tree over the instances placing
    /// them, and one world-space tree over the rest (what deforms or stands still; see
    /// [`super::TwoLevelAccel`]).
    TwoLevel,
    /// Per mesh, instanced where a cost model says instancing pays and merged into the
    /// world-space tree where it does not; exactly [`BvhLayout::Flat`] when nothing is
    /// instanced (the decision: `frame/layout.rs`).
    #[default]
    Auto,
}

impl BvhLayout {
    /// Every layout, as `--bvh` names them.
    pub const ALL: [BvhLayout; 3] = [BvhLayout::Flat, BvhLayout::TwoLevel, BvhLayout::Auto];

    /// Its `--bvh` name.
    pub const fn name(self) -> &'static str {
        match self {
            BvhLayout::Flat => "flat",
            BvhLayout::TwoLevel => "two-level",
            BvhLayout::Auto => "auto",
        }
    }
}

impl std::fmt::Display for BvhLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for BvhLayout {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        BvhLayout::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| format!("unknown BVH layout `{s}` (flat, two-level, auto)"))
    }
}

/// How the BVH follows the animation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BvhPolicy {
    /// Refit every frame; rebuild when the SAH cost exceeds `rebuild_threshold` times its
    /// value right after the last build.
    Refit { rebuild_threshold: f32 },
    /// Rebuild every frame that anything moved (for comparison).
    Rebuild,
}

impl BvhPolicy {
    /// Default rebuild threshold: a refitted tree 50% costlier than fresh is rebuilt.
    pub const DEFAULT_REBUILD_THRESHOLD: f32 = 1.5;

    /// Whether the tree should be rebuilt given its current SAH ratio (a NaN ratio rebuilds).
    pub fn wants_rebuild(self, sah_ratio: f32) -> bool {
        match self {
            BvhPolicy::Rebuild => true,
            BvhPolicy::Refit { rebuild_threshold } => !(sah_ratio <= rebuild_threshold),
        }
    }
}

/// What [`Accel::refit_or_rebuild`] decided for this frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TreeStep {
    /// Nothing moved: the tree is used as it is.
    Unchanged,
    /// The tree was refitted and is good enough.
    Refitted { refit_ms: f64 },
    /// The caller must rebuild (after a refit whose quality fell past the threshold, with
    /// its cost, or at once under [`BvhPolicy::Rebuild`] with `refit_ms` 0). The rebuild is
    /// the caller's because it reorders the caller's triangle arrays.
    Rebuild { refit_ms: f64 },
}

impl Accel {
    /// The refit-or-rebuild decision for a frame in which `moved_slots` changed: nothing
    /// moved -> unchanged; `Rebuild` policy -> rebuild; otherwise refit, then rebuild when
    /// the refitted tree's SAH ratio passes the policy's threshold.
    pub fn refit_or_rebuild(&mut self, moved_slots: &[u32], policy: BvhPolicy) -> TreeStep {
        self.refit_or_rebuild_listing(moved_slots.len(), || moved_slots.into(), policy)
    }

    /// [`Accel::refit_or_rebuild`] for `moved` moved triangles that `list` lists (any
    /// order, each once) when the refit needs them: only a partial refit does.
    pub fn refit_or_rebuild_listing<'a>(
        &mut self,
        moved: usize,
        list: impl FnOnce() -> Cow<'a, [u32]>,
        policy: BvhPolicy,
    ) -> TreeStep {
        if moved == 0 || policy == BvhPolicy::Rebuild {
            // No refit follows the last write: the leaf boxes a run writer set (the same as
            // before, or replaced by the rebuild) need no note.
            self.leaf_boxes_written = None;
        }
        if moved == 0 {
            return TreeStep::Unchanged;
        }
        if policy == BvhPolicy::Rebuild {
            return TreeStep::Rebuild { refit_ms: 0.0 };
        }
        // Timed with the tree's new SAH ratio, which the refit computes (a walk over every
        // node: part of deciding whether to rebuild).
        let t = Instant::now();
        let kind = self.refit_listing(moved, list);
        let refit_ms = t.elapsed().as_secs_f64() * 1e3;
        debug_assert_ne!(kind, RefitKind::None);
        if policy.wants_rebuild(self.sah_ratio()) {
            TreeStep::Rebuild { refit_ms }
        } else {
            TreeStep::Refitted { refit_ms }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_read_back_their_names() {
        for layout in BvhLayout::ALL {
            assert_eq!(layout.to_string().parse::<BvhLayout>(), Ok(layout));
        }
        assert!("mixed".parse::<BvhLayout>().is_err());
        assert_eq!(BvhLayout::default(), BvhLayout::Auto);
    }

    #[test]
    fn refit_policy_rebuilds_past_the_threshold_and_on_nan() {
        let policy = BvhPolicy::Refit {
            rebuild_threshold: 1.5,
        };
        assert!(!policy.wants_rebuild(1.0));
        assert!(!policy.wants_rebuild(1.5));
        assert!(policy.wants_rebuild(1.51));
        assert!(policy.wants_rebuild(f32::NAN));
        assert!(BvhPolicy::Rebuild.wants_rebuild(1.0));
    }

    #[test]
    fn nothing_moved_keeps_the_tree_under_either_policy() {
        let mut accel = Accel::default();
        for policy in [
            BvhPolicy::Rebuild,
            BvhPolicy::Refit {
                rebuild_threshold: 1.5,
            },
        ] {
            assert_eq!(accel.refit_or_rebuild(&[], policy), TreeStep::Unchanged);
        }
    }

    #[test]
    fn rebuild_policy_asks_for_a_rebuild_without_refitting() {
        let mut accel = Accel::default();
        assert_eq!(
            accel.refit_or_rebuild(&[0], BvhPolicy::Rebuild),
            TreeStep::Rebuild { refit_ms: 0.0 }
        );
    }
}
