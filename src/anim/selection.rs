//! Which animation clips play: all of them together (the default) or one chosen by name or
//! index (the CLI's `--animation`).

use std::fmt::Write as _;

use crate::scene::{AnimationDesc, SceneDesc};

/// The clips a pose samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AnimationSelection {
    /// Every clip at once, each clamped at its ends; where two clips drive the same
    /// property, the later one in the file wins.
    #[default]
    All,
    /// Only the clip at this index of `SceneDesc::animations` (clamped at its ends). An
    /// index past the end plays nothing (the scene's rest pose); [`select_animation`] never
    /// returns one.
    One(usize),
}

impl AnimationSelection {
    /// The selected clips, in file order.
    pub fn clips(self, scene: &SceneDesc) -> &[AnimationDesc] {
        match self {
            AnimationSelection::All => &scene.animations,
            AnimationSelection::One(i) => scene.animations.get(i..=i).unwrap_or(&[]),
        }
    }

    /// Time of the last key of the selected clips in seconds (0 when nothing is animated);
    /// for `All` this is `SceneDesc::duration`.
    pub fn duration(self, scene: &SceneDesc) -> f32 {
        self.clips(scene)
            .iter()
            .map(AnimationDesc::duration)
            .fold(0.0, f32::max)
    }
}

/// Per node: whether a translation, rotation or scale channel of the selected clips drives
/// it or one of its ancestors (its world transform may change over time). Weights channels
/// do not count: they deform, they do not move.
pub fn moving_nodes(scene: &SceneDesc, selection: AnimationSelection) -> Vec<bool> {
    let mut driven = vec![false; scene.nodes.len()];
    for c in selection.clips(scene).iter().flat_map(|a| &a.channels) {
        if c.target != crate::scene::ChannelTarget::Weights && c.node < driven.len() {
            driven[c.node] = true;
        }
    }
    let mut moving = vec![false; scene.nodes.len()];
    let mut stack: Vec<(usize, bool)> = scene.roots.iter().map(|&r| (r, false)).collect();
    while let Some((i, parent_moves)) = stack.pop() {
        if i >= moving.len() || moving[i] {
            continue;
        }
        moving[i] = parent_moves || driven[i];
        stack.extend(scene.nodes[i].children.iter().map(|&c| (c, moving[i])));
    }
    moving
}

/// Resolves `--animation SPEC`: the clip whose name is `spec`, else the clip at index
/// `spec` (a decimal number).
///
/// # Errors
/// No clip has that name or index, or the name is shared by several clips; the message
/// lists the clips (index and name) to choose from.
pub fn select_animation(scene: &SceneDesc, spec: &str) -> Result<AnimationSelection, String> {
    // An empty spec would pick an unnamed clip by accident (unnamed clips go by number).
    if spec.trim().is_empty() {
        return Err(format!(
            "give an animation's name or number.{}",
            available(scene)
        ));
    }
    let named: Vec<usize> = (0..scene.animations.len())
        .filter(|&i| scene.animations[i].name == spec)
        .collect();
    match named.as_slice() {
        [i] => return Ok(AnimationSelection::One(*i)),
        [] => {}
        several => {
            return Err(format!(
                "{} animations are named {spec:?} (indices {several:?}); choose one by index.{}",
                several.len(),
                available(scene)
            ));
        }
    }
    match spec.trim().parse::<usize>() {
        Ok(i) if i < scene.animations.len() => Ok(AnimationSelection::One(i)),
        _ => Err(format!(
            "no animation named or numbered {spec:?}.{}",
            available(scene)
        )),
    }
}

/// " Available: 0 \"Walk\" (0.71 s), 1 (unnamed) (1.2 s)" or " The scene has no animations."
fn available(scene: &SceneDesc) -> String {
    if scene.animations.is_empty() {
        return " The scene has no animations.".into();
    }
    let mut s = String::from(" Available:");
    for (i, animation) in scene.animations.iter().enumerate() {
        let separator = if i == 0 { " " } else { ", " };
        let name = if animation.name.is_empty() {
            "(unnamed)".to_string()
        } else {
            format!("{:?}", animation.name)
        };
        let _ = write!(s, "{separator}{i} {name} ({} s)", animation.duration());
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{ChannelDesc, ChannelTarget, Interpolation};

    fn clip(name: &str, end: f32) -> AnimationDesc {
        AnimationDesc {
            name: name.into(),
            channels: vec![ChannelDesc {
                node: 0,
                target: ChannelTarget::Translation,
                interpolation: Interpolation::Linear,
                times: vec![0.0, end],
                values: vec![0.0; 6],
                components: 3,
            }],
        }
    }

    fn scene(clips: Vec<AnimationDesc>) -> SceneDesc {
        SceneDesc {
            animations: clips,
            ..Default::default()
        }
    }

    #[test]
    fn names_win_over_indices_and_durations_follow_the_selection() {
        let s = scene(vec![clip("walk", 2.0), clip("0", 5.0), clip("", 1.0)]);
        assert_eq!(select_animation(&s, "walk"), Ok(AnimationSelection::One(0)));
        // "0" is a name here, so it names clip 1 rather than indexing clip 0.
        assert_eq!(select_animation(&s, "0"), Ok(AnimationSelection::One(1)));
        assert_eq!(select_animation(&s, "2"), Ok(AnimationSelection::One(2)));
        assert_eq!(AnimationSelection::One(0).duration(&s), 2.0);
        assert_eq!(AnimationSelection::One(2).duration(&s), 1.0);
        assert_eq!(AnimationSelection::All.duration(&s), 5.0);
        assert_eq!(AnimationSelection::One(9).duration(&s), 0.0);
    }

    #[test]
    fn unknown_or_ambiguous_specs_list_the_clips() {
        let s = scene(vec![clip("walk", 2.0), clip("walk", 1.0), clip("", 1.0)]);
        let e = select_animation(&s, "run").unwrap_err();
        assert!(e.contains("\"run\""), "{e}");
        assert!(
            e.contains("0 \"walk\" (2 s), 1 \"walk\" (1 s), 2 (unnamed) (1 s)"),
            "{e}"
        );
        let e = select_animation(&s, "walk").unwrap_err();
        assert!(e.contains("indices [0, 1]"), "{e}");
        assert!(select_animation(&s, "3").is_err());
        assert!(select_animation(&s, "-1").is_err());
        let e = select_animation(&scene(Vec::new()), "0").unwrap_err();
        assert!(e.contains("no animations"), "{e}");
        // Empty: refused, not the unnamed clip 2.
        let e = select_animation(&s, "").unwrap_err();
        assert!(
            e.contains("name or number") && e.contains("2 (unnamed)"),
            "{e}"
        );
    }
}
