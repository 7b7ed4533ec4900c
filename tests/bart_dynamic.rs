//! The frame loop on the original BART scenes (skips without ../shared/bart): hierarchical
//! rigid motion recomputes nothing, the toy car's squash recomputes exactly the car, the
//! museum recomputes exactly its morphing triangles.

use std::collections::BTreeSet;
use std::path::PathBuf;

use mipray::frame::{FrameClock, Motion, RenderSettings, Renderer};
use mipray::scene::SceneDesc;

mod common;

fn bart(relative: &str) -> Option<PathBuf> {
    common::shared_data::shared_path(&format!("bart/{relative}"))
}

/// Source triangles drawn by `node` or its descendants.
fn subtree_triangles(r: &Renderer, node: usize) -> BTreeSet<u32> {
    let scene = r.scene();
    let mut nodes = vec![node];
    let mut all = BTreeSet::new();
    while let Some(n) = nodes.pop() {
        all.insert(n);
        nodes.extend(&scene.nodes[n].children);
    }
    let g = r.geometry();
    (0..g.triangle_count() as u32)
        .filter(|&t| {
            all.contains(&(g.instances[g.triangle_instance[t as usize] as usize].node as usize))
        })
        .collect()
}

fn deformed_sources(r: &Renderer) -> BTreeSet<u32> {
    r.dirty()
        .moved()
        .into_iter()
        .filter(|&(_, m)| m == Motion::Deformed)
        .map(|(s, _)| r.triangles().source[s as usize])
        .collect()
}

fn renderer(scene: SceneDesc) -> (Renderer, FrameClock) {
    let clock = FrameClock::for_scene(&scene, None);
    (
        Renderer::new(
            scene,
            RenderSettings {
                width: 80,
                height: 60,
                ..Default::default()
            },
        ),
        clock,
    )
}

#[test]
fn kitchen_rigid_hierarchy_recomputes_nothing_and_the_squash_exactly_the_car() {
    let Some(path) = bart("kitchen/aff/kitchen.aff") else {
        return;
    };
    let (mut r, clock) = renderer(mipray::scene::aff::load(&path).unwrap());
    let car = r
        .scene()
        .nodes
        .iter()
        .position(|n| n.name == "toycar")
        .expect("a toycar node");
    let car_triangles = subtree_triangles(&r, car);
    assert!(car_triangles.len() > 1000, "{}", car_triangles.len());
    // The squash keys are at 19.75 s (scale 1) and 19.81 s (0.5 along x); 800 frames span
    // 0..20 s, so frames 790-792 change the car's shape.
    r.prepare(700, clock.time(700)).unwrap();
    let mut squashed = 0;
    for frame in 701..800 {
        let u = r.prepare(frame, clock.time(frame)).unwrap().update;
        let deformed = deformed_sources(&r);
        assert!(
            deformed.is_subset(&car_triangles),
            "frame {frame}: something outside the car deformed"
        );
        if (790..=792).contains(&frame) {
            assert_eq!(
                deformed, car_triangles,
                "frame {frame}: the squash deforms the whole car"
            );
            squashed += 1;
        }
        if clock.time(frame) < 19.75 {
            assert_eq!(
                (u.deformed_triangles, u.lod_recomputed),
                (0, 0),
                "frame {frame}: rigid motion only"
            );
            assert!(u.moved_triangles > 0, "frame {frame}: the car drives");
        }
    }
    assert_eq!(squashed, 3);
}

#[test]
fn museum_recomputes_only_its_morphing_triangles() {
    let Some(path) = bart("museum/aff/museum5.aff") else {
        return;
    };
    let (mut r, clock) = renderer(mipray::scene::aff::load(&path).unwrap());
    // `a -1.0 5.0 300`: frame 50 is the first after t = 0.
    let frames = clock.default_frames(0.0);
    assert_eq!(frames, 0..300);
    r.prepare(45, clock.time(45)).unwrap();
    let mut checked = 0;
    for frame in 46..90 {
        let t = clock.time(frame);
        let u = r.prepare(frame, t).unwrap().update;
        if t <= 0.0 || t >= 4.0 {
            continue; // the morph keys span 0..4 s
        }
        assert_eq!(u.deformed_triangles, 1024, "frame {frame} (t = {t})");
        assert_eq!(u.moved_triangles, 1024, "frame {frame}: nothing else moves");
        assert!(u.lod_recomputed <= 1024);
        checked += 1;
    }
    assert!(checked > 5, "only {checked} frames inside the morph");
}
