//! The flat tree against brute force: closest hits, packets, refits, ties.

use std::time::Duration;

use bytemuck::TransparentWrapper;
use glam::{Vec2, Vec3, Vec3A};
use obvhs::{BvhBuildParams, bvh2::builder::build_bvh2};

use super::refit::LeafPass;
use super::*;
use crate::accel::triangles::intersect;
use crate::accel::wide::PACKET;
use crate::accel::{BvhPolicy, TreeStep};
use crate::geometry::FrameTriangles;

/// Triangles with placeholder shading data, source ids in order.
pub(in crate::accel) fn soup(tris: &[[Vec3A; 3]]) -> FrameTriangles {
    FrameTriangles {
        positions: tris.to_vec(),
        normals: vec![[Vec3::Z; 3]; tris.len()],
        uvs: vec![[Vec2::ZERO; 3]; tris.len()],
        material: vec![0; tris.len()],
        log2_pb: vec![0.0; tris.len()],
        source: (0..tris.len() as u32).collect(),
    }
}

#[test]
fn finds_closest_of_stacked_triangles() {
    let tri = |z: f32| {
        [
            Vec3A::new(-1.0, -1.0, z),
            Vec3A::new(1.0, -1.0, z),
            Vec3A::new(0.0, 1.0, z),
        ]
    };
    let mut tris = soup(&[tri(-5.0), tri(-2.0), tri(-9.0)]);
    let accel = Accel::build(&mut tris).unwrap();
    let hit = accel
        .closest_hit(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY)
        .unwrap();
    assert!((hit.t - 2.0).abs() < 1e-6);
    assert_eq!(tris.source[hit.triangle as usize], 1);
    let mut count = 0;
    accel.visit_hits(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY, |_, _| {
        count += 1;
        true
    });
    assert_eq!(count, 3);
    assert!(
        accel
            .closest_hit(Vec3A::new(5.0, 0.0, 0.0), Vec3A::NEG_Z, f32::INFINITY)
            .is_none()
    );
}

#[test]
fn axis_aligned_ray_hits_axis_aligned_flat_triangle() {
    // Floor at y = 0 seen straight down, and a wall at x = 3 hit along +x.
    let floor = [
        Vec3A::new(-1.0, 0.0, -1.0),
        Vec3A::new(1.0, 0.0, -1.0),
        Vec3A::new(0.0, 0.0, 1.0),
    ];
    let wall = [
        Vec3A::new(3.0, -1.0, -1.0),
        Vec3A::new(3.0, 1.0, -1.0),
        Vec3A::new(3.0, 0.0, 1.0),
    ];
    let mut tris = soup(&[floor, wall]);
    let accel = Accel::build(&mut tris).unwrap();
    let down = accel.closest_hit(Vec3A::new(0.0, 5.0, 0.0), Vec3A::NEG_Y, f32::INFINITY);
    assert!((down.unwrap().t - 5.0).abs() < 1e-6);
    let side = accel.closest_hit(Vec3A::new(-2.0, 0.0, 0.0), Vec3A::X, f32::INFINITY);
    assert!((side.unwrap().t - 5.0).abs() < 1e-6);
}

#[test]
fn rejects_non_finite_vertices() {
    let mut tris = soup(&[[Vec3A::ZERO, Vec3A::X, Vec3A::new(f32::NAN, 0.0, 0.0)]]);
    assert!(matches!(
        Accel::build(&mut tris),
        Err(AccelError::NonFiniteVertex { triangle: 0, .. })
    ));
}

#[test]
fn empty_scene_misses() {
    let mut tris = soup(&[]);
    let accel = Accel::build(&mut tris).unwrap();
    assert!(
        accel
            .closest_hit(Vec3A::ZERO, Vec3A::X, f32::INFINITY)
            .is_none()
    );
}

/// A small deterministic generator (xorshift) for the random soups below.
/// Xorshift: reproducible pseudo-random points (seed non-zero).
pub(in crate::accel) struct Rng(pub u64);
impl Rng {
    pub(in crate::accel) fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    /// A point in the cube of side `scale` centred on the origin.
    pub(in crate::accel) fn point(&mut self, scale: f32) -> Vec3A {
        Vec3A::new(self.next(), self.next(), self.next()) * scale - Vec3A::splat(scale / 2.0)
    }
}

/// Closest hit by testing every triangle of `by_source` (triangle `i` is source `i`, as in
/// [`soup`]; same test, same tie rule).
fn brute_force(by_source: &[[Vec3A; 3]], origin: Vec3A, direction: Vec3A) -> Option<(u32, f32)> {
    let mut best: Option<(u32, f32)> = None;
    for (source, p) in by_source.iter().enumerate() {
        let Some((t, _)) = intersect(p, origin, direction) else {
            continue;
        };
        let source = source as u32;
        if t >= 0.0 && best.is_none_or(|(s, b)| t < b || (t == b && source < s)) {
            best = Some((source, t));
        }
    }
    best
}

/// Exact ties far from the ray origin: an 8 x 8 grid of unit quads at z = 0, each
/// triangle three times (the copies tie exactly), seen from cameras up to 1e6 away. The
/// lowest source must win whatever order the tree visits the copies in, for single rays
/// and packets alike.
#[test]
fn exact_ties_far_from_the_origin_go_to_the_lowest_source() {
    let mut tris = Vec::new();
    for j in 0..8 {
        for i in 0..8 {
            let (x, y) = (i as f32, j as f32);
            let a = [
                Vec3A::new(x, y, 0.0),
                Vec3A::new(x + 1.0, y, 0.0),
                Vec3A::new(x + 1.0, y + 1.0, 0.0),
            ];
            let b = [a[0], a[2], Vec3A::new(x, y + 1.0, 0.0)];
            tris.extend([a, b, a, b, a, b]);
        }
    }
    // Shuffled, so copies land in different leaves with unrelated source ids.
    let mut rng = Rng(0x5851f42d4c957f2d);
    for i in (1..tris.len()).rev() {
        let j = (rng.next() * (i + 1) as f32) as usize % (i + 1);
        tris.swap(i, j);
    }
    let by_source = tris;
    let mut tris = soup(&by_source);
    let accel = Accel::build(&mut tris).unwrap();
    let mut checked = 0;
    for distance in [30.0f32, 1e3, 1e4, 1e5, 3e5, 1e6, 1e6, 1e6] {
        for _ in 0..100 {
            let eye = Vec3A::new(rng.next() * 2.0 - 1.0, rng.next() * 2.0 - 1.0, 1.0) * distance;
            let rays: Vec<(Vec3A, Vec3A)> = (0..64)
                .map(|_| {
                    let aim = Vec3A::new(rng.next() * 8.0, rng.next() * 8.0, 0.0);
                    (eye, (aim - eye).normalize())
                })
                .collect();
            let mut hits = vec![None; rays.len()];
            accel.closest_hits(&rays, f32::INFINITY, &mut hits);
            for (&(o, d), hit) in rays.iter().zip(&hits) {
                let single = accel.closest_hit(o, d, f32::INFINITY);
                let found = single.map(|h| (tris.source[h.triangle as usize], h.t));
                assert_eq!(
                    found,
                    brute_force(&by_source, o, d),
                    "eye {o} direction {d}"
                );
                assert_eq!(*hit, single, "packet and single ray, eye {o}");
                checked += found.is_some() as usize;
            }
        }
    }
    assert!(checked > 8000, "only {checked} rays hit the grid");
}

/// `n` random triangles: by source, and as a soup to build over.
fn random_soup(rng: &mut Rng, n: usize) -> (Vec<[Vec3A; 3]>, FrameTriangles) {
    let tris: Vec<[Vec3A; 3]> = (0..n)
        .map(|_| {
            let c = rng.point(20.0);
            [c + rng.point(2.0), c + rng.point(2.0), c + rng.point(2.0)]
        })
        .collect();
    let soup = soup(&tris);
    (tris, soup)
}

/// Moves the triangles in `slots` by `f`, in the tree (its packs, then a refit) and in
/// `by_source` (the brute force's copy, by source); returns the refit's kind.
fn move_triangles(
    accel: &mut Accel,
    tris: &FrameTriangles,
    by_source: &mut [[Vec3A; 3]],
    slots: &[u32],
    mut f: impl FnMut(&[Vec3A; 3]) -> [Vec3A; 3],
) -> RefitKind {
    for &slot in slots {
        let source = tris.source[slot as usize] as usize;
        by_source[source] = f(&by_source[source]);
        accel.set_triangle(slot, &by_source[source]);
    }
    accel.refit(slots)
}

/// The tree's answers against brute force over `by_source`, the same triangles by source.
fn assert_matches_brute_force(
    accel: &Accel,
    tris: &FrameTriangles,
    by_source: &[[Vec3A; 3]],
    rng: &mut Rng,
) {
    let mut hits = 0;
    for _ in 0..2000 {
        let origin = rng.point(30.0);
        let direction = (rng.point(2.0) - origin * 0.05).normalize();
        let wide = accel
            .closest_hit(origin, direction, f32::INFINITY)
            .map(|h| (tris.source[h.triangle as usize], h.t));
        assert_eq!(wide, brute_force(by_source, origin, direction));
        hits += wide.is_some() as usize;
        // The shadow walk sees a hit exactly when the closest-hit walk does.
        let blocked = !accel.visit_hits(origin, direction, f32::INFINITY, |_, _| false);
        assert_eq!(blocked, wide.is_some());
    }
    assert!(
        hits > 200,
        "too few rays hit ({hits}): the test would prove little"
    );
}

#[test]
fn wide_walk_finds_what_testing_every_triangle_finds_before_and_after_refits() {
    let mut rng = Rng(0x9e3779b97f4a7c15);
    let (mut by_source, mut tris) = random_soup(&mut rng, 3000);
    let mut accel = Accel::build(&mut tris).unwrap();
    assert_matches_brute_force(&accel, &tris, &by_source, &mut rng);
    // A few triangles jump (partial refit), then all of them move (full refit).
    let moved: Vec<u32> = (0..3000).step_by(97).collect();
    assert_eq!(accel.sah_ratio(), 1.0);
    let shifts: Vec<Vec3A> = moved.iter().map(|_| rng.point(10.0)).collect();
    let mut shift = shifts.iter();
    let kind = move_triangles(&mut accel, &tris, &mut by_source, &moved, |t| {
        let s = *shift.next().unwrap();
        t.map(|v| v + s)
    });
    assert_eq!(kind, RefitKind::Partial);
    assert_matches_brute_force(&accel, &tris, &by_source, &mut rng);
    // The kept SAH ratio is the refitted tree's (the jumps changed its boxes).
    assert!(accel.sah_ratio() != 1.0, "{}", accel.sah_ratio());
    assert_eq!(accel.sah_ratio(), accel.sah_cost() / accel.build_cost);
    let all: Vec<u32> = (0..3000).collect();
    let kind = move_triangles(&mut accel, &tris, &mut by_source, &all, |t| {
        t.map(|v| v * 1.5 + Vec3A::new(1.0, 0.0, 0.0))
    });
    assert_eq!(kind, RefitKind::Full);
    assert_matches_brute_force(&accel, &tris, &by_source, &mut rng);
}
#[test]
fn a_tree_built_in_chunks_finds_what_testing_every_triangle_finds() {
    // Past `CHUNK_TRIANGLES` the builder takes the triangles a chunk at a time under median
    // splits; a chunk of 100 drives that path on 3,000 triangles (30 chunks, five levels
    // of splits), through the walks, packets, refits and the SAH ratio the rebuild policy
    // reads.
    let mut rng = Rng(0x51ab);
    let (mut by_source, mut tris) = random_soup(&mut rng, 3000);
    let mut accel = Accel::build_in_chunks(&mut tris, 100).unwrap();
    assert_eq!(accel.sah_ratio(), 1.0);
    assert_matches_brute_force(&accel, &tris, &by_source, &mut rng);
    let slots: u32 = accel.leaves.iter().map(|l| l.count).sum();
    assert_eq!(slots, 3000);
    let mut sources = tris.source.clone();
    sources.sort_unstable();
    assert!(sources.iter().copied().eq(0..3000));
    // Within a chunk the tree is obvhs's; the splits above cost little against one build.
    let whole = Accel::build(&mut soup(&by_source)).unwrap();
    let (chunked, one) = (accel.sah_cost(), whole.sah_cost());
    assert!(
        chunked < one * 1.25,
        "SAH cost {chunked} against {one} in one build"
    );
    let all: Vec<u32> = (0..3000).collect();
    let kind = move_triangles(&mut accel, &tris, &mut by_source, &all, |t| {
        t.map(|v| v * 0.5 - Vec3A::new(0.0, 3.0, 0.0))
    });
    assert_eq!(kind, RefitKind::Full);
    assert_matches_brute_force(&accel, &tris, &by_source, &mut rng);
}

#[test]
fn a_packet_finds_what_each_of_its_rays_finds_alone() {
    let mut rng = Rng(0x2545f4914f6cdd1d);
    let (_, mut tris) = random_soup(&mut rng, 4000);
    // A coherent packet (a camera's 8 x 8 block), an incoherent one, and a short one.
    let accel = Accel::build(&mut tris).unwrap();
    let eye = Vec3A::new(0.0, 0.0, 40.0);
    let coherent: Vec<(Vec3A, Vec3A)> = (0..64)
        .map(|i| {
            let (x, y) = ((i % 8) as f32, (i / 8) as f32);
            (
                eye,
                Vec3A::new(x * 0.01 - 0.04, y * 0.01 - 0.04, -1.0).normalize(),
            )
        })
        .collect();
    let scattered: Vec<(Vec3A, Vec3A)> = (0..64)
        .map(|_| {
            let origin = rng.point(30.0);
            (origin, (rng.point(2.0) - origin * 0.05).normalize())
        })
        .collect();
    // The block reflected by a mirror at z = 35 facing the soup: rays from several
    // origins on the mirror whose lines pass through the eye's image behind it (bounds
    // from that apex), as the camera's rays the other way.
    let image = Vec3A::new(0.0, 0.0, 30.0);
    let mirrored: Vec<(Vec3A, Vec3A)> = coherent
        .iter()
        .map(|&(_, d)| {
            let on_mirror = image + d * (5.0 / -d.z);
            (on_mirror, d)
        })
        .collect();
    // With this tree's leaves the mirror's packet walks with bounds (the test covers that
    // walk), and the scattered one masked.
    let leaf_side = accel.wide.leaf_sides().typical();
    assert!(crate::accel::wide::RayPacket::new(&[]).set_with_apex(&mirrored, 30.0, leaf_side));
    assert!(!crate::accel::wide::RayPacket::new(&[]).set_with_apex(&scattered, 30.0, leaf_side));
    let mut found = 0;
    for (rays, t_max) in [
        (&coherent[..], f32::INFINITY),
        (&scattered[..], f32::INFINITY),
        (&scattered[..13], 25.0),
        (&mirrored[..], f32::INFINITY),
        (&mirrored[..23], 50.0),
    ] {
        let mut hits = vec![None; rays.len()];
        accel.closest_hits(rays, t_max, &mut hits);
        let mut masked = vec![None; rays.len()];
        accel.closest_hits_masked(rays, t_max, &mut masked);
        for ((&(o, d), hit), masked) in rays.iter().zip(&hits).zip(&masked) {
            let alone = accel.closest_hit(o, d, t_max);
            assert_eq!(*hit, alone);
            assert_eq!(*masked, alone, "the masked walk");
            found += hit.is_some() as usize;
        }
    }
    assert!(
        found > 40,
        "too few hits ({found}) for the test to mean much"
    );
}

/// Packets whose fixed groups of eight rays (a packet's rows of eight) do and do not share
/// one axis permutation: those that do are tested at a leaf in their own lanes, the others
/// gathered and sorted by permutation, and a leaf can see both. A camera block whose upper
/// rows are narrow (every ray's largest direction axis is z) and whose lower rows are wide
/// (the outer rays' is x), and occlusion rays converging on a light near the diagonal of x
/// and y (rows where x or y is the largest axis, and rows with both); full packets and
/// packets cut short inside a group. Each ray finds, and meets, what it does alone.
#[test]
fn packets_whose_groups_mix_axis_permutations_answer_as_single_rays() {
    use crate::accel::triangles::{RAYS, ShearedRay};
    let mut rng = Rng(0x51_7cc1_b727_220a);
    let (_, mut tris) = random_soup(&mut rng, 4000);
    let accel = Accel::build(&mut tris).unwrap();
    // Which of a packet's first `n` rays lie in groups of one permutation, and in how many
    // groups of each kind (the test means little without both).
    let groups = |rays: &[(Vec3A, Vec3A)]| {
        let mut sheared = [ShearedRay::default(); PACKET];
        for (s, &(o, d)) in sheared.iter_mut().zip(rays) {
            *s = ShearedRay::new(o, d);
        }
        let one = super::hits::groups_of_one_permutation(&sheared, rays.len());
        let uniform = (0..rays.len().div_ceil(RAYS))
            .filter(|g| one & (1 << (g * RAYS)) != 0)
            .count();
        (uniform, rays.len().div_ceil(RAYS) - uniform)
    };
    use super::hits::FIXED_GROUP_TESTS;
    FIXED_GROUP_TESTS.with(|c| c.set([0; 4]));
    let (mut found, mut kinds) = (0, (0, 0));
    // Cameras inside the soup, looking down -z, up +y and along +x.
    for (eye, forward, right, up) in [
        (
            Vec3A::new(0.5, -0.25, 0.0),
            Vec3A::NEG_Z,
            Vec3A::X,
            Vec3A::Y,
        ),
        (Vec3A::new(-3.0, 2.0, 6.0), Vec3A::NEG_Z, Vec3A::X, Vec3A::Y),
        (Vec3A::new(4.0, -6.0, -2.0), Vec3A::Y, Vec3A::Z, Vec3A::X),
        (Vec3A::new(-7.0, 1.0, 3.0), Vec3A::X, Vec3A::Y, Vec3A::Z),
    ] {
        let camera: Vec<(Vec3A, Vec3A)> = (0..64)
            .map(|i| {
                let (x, y) = ((i % 8) as f32 - 3.5, (i / 8) as f32 - 3.5);
                let spread = if i < 32 { 0.05 } else { 0.45 };
                let direction = forward + right * (x * spread) + up * (y * 0.05);
                (eye, direction.normalize())
            })
            .collect();
        // The last two end in a group of one permutation cut short (5 rays; 13 in the
        // last block of sixteen).
        for rays in [
            &camera[..],
            &camera[..45],
            &camera[5..50],
            &camera[..29],
            &camera[3..32],
        ] {
            let (uniform, mixed) = groups(rays);
            kinds = (kinds.0 + uniform, kinds.1 + mixed);
            let mut hits = vec![None; rays.len()];
            accel.closest_hits(rays, f32::INFINITY, &mut hits);
            for (&(o, d), hit) in rays.iter().zip(&hits) {
                assert_eq!(*hit, accel.closest_hit(o, d, f32::INFINITY));
                found += hit.is_some() as usize;
            }
        }
    }
    assert!(found > 100, "too few hits ({found})");
    assert!(
        kinds.0 > 0 && kinds.1 > 0,
        "{} groups of one permutation, {} not",
        kinds.0,
        kinds.1
    );
    let [eight, sixteen, _, _] = FIXED_GROUP_TESTS.with(|c| c.get());
    println!("closest hits: {eight} group tests of eight in fixed lanes, {sixteen} of sixteen");
    assert!(eight + sixteen > 100, "the fixed groups hardly ran");
    if crate::simd::avx512() {
        assert!(
            sixteen > 0,
            "no block of sixteen in fixed lanes on an AVX-512 CPU"
        );
    }
    // Rows 0 and 1: y is every ray's largest axis; 2 to 4: some x, some y; 5 to 7: x.
    let light = Vec3A::new(40.0, 40.0, 1.0);
    let converging: Vec<(Vec3A, Vec3A, f32)> = (0..64)
        .map(|i| {
            let (x, y) = ((i % 8) as f32, (i / 8) as f32);
            let from = Vec3A::new(x * 0.2 - 0.7, y * 0.4 - 1.2, rng.next() - 0.5);
            let to = light - from;
            (from, to.normalize(), to.length() * 0.999)
        })
        .collect();
    let mut met = 0;
    // The last ends in a group of one permutation cut short (5 rays).
    for rays in [&converging[..], &converging[..30], &converging[..45]] {
        let pairs: Vec<(Vec3A, Vec3A)> = rays.iter().map(|&(o, d, _)| (o, d)).collect();
        let limits: Vec<f32> = rays.iter().map(|r| r.2).collect();
        assert!(crate::accel::wide::RayPacket::new(&[]).set_converging(&pairs, &limits));
        let (uniform, mixed) = groups(&pairs);
        assert!(
            uniform > 0 && mixed > 0,
            "{uniform} groups of one permutation, {mixed} not"
        );
        let mut seen = vec![Vec::new(); rays.len()];
        accel.visit_hits_packet(&pairs, &limits, |r, slot, t| {
            seen[r].push((slot, t.to_bits()));
            true
        });
        for (r, &(o, d, t_max)) in rays.iter().enumerate() {
            let mut alone = Vec::new();
            accel.visit_hits(o, d, t_max, |slot, t| {
                alone.push((slot, t.to_bits()));
                true
            });
            seen[r].sort_unstable();
            alone.sort_unstable();
            assert_eq!(seen[r], alone, "ray {r}");
            met += alone.len();
        }
        // Stopped at the first hit on an even slot, as alone.
        let stopped = accel.visit_hits_packet(&pairs, &limits, |_, slot, _| slot % 2 == 1);
        for (r, &(o, d, t_max)) in rays.iter().enumerate() {
            let blocked_alone = !accel.visit_hits(o, d, t_max, |slot, _| slot % 2 == 1);
            assert_eq!(stopped & (1 << r) != 0, blocked_alone, "ray {r}");
        }
    }
    assert!(met > 100, "too few hits met ({met})");
    let [_, _, eight, sixteen] = FIXED_GROUP_TESTS.with(|c| c.get());
    println!("occlusion: {eight} group tests of eight in fixed lanes, {sixteen} of sixteen");
    assert!(
        eight + sixteen > 100,
        "{eight} + {sixteen} occlusion group tests in fixed lanes"
    );
    if crate::simd::avx512() {
        assert!(
            sixteen > 0,
            "no occlusion block of sixteen in fixed lanes on an AVX-512 CPU"
        );
    }
}

/// A bundle of nearly parallel rays from different origins (no common apex, so the masked
/// walk) through a dense soup: the rays find hits early, so leaves pushed before those hits
/// are tested again with the shrunk limits when popped, sixteen rays at a time where the
/// CPU has AVX-512 and ray by ray otherwise. Each ray still finds exactly what it finds
/// alone, and with the other rays' hits first (the packet in reverse order too).
#[test]
fn a_masked_bundle_that_finds_hits_early_finds_each_ray_s_closest() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (_, mut tris) = random_soup(&mut rng, 6000);
    let accel = Accel::build(&mut tris).unwrap();
    for spacing in [0.05f32, 0.4, 2.0] {
        let bundle: Vec<(Vec3A, Vec3A)> = (0..64)
            .map(|i| {
                let (x, y) = ((i % 8) as f32 - 3.5, (i / 8) as f32 - 3.5);
                let origin = Vec3A::new(x * spacing, y * spacing, 40.0) + rng.point(0.01);
                let direction = (Vec3A::new(0.0, 0.0, -1.0) + rng.point(0.02)).normalize();
                (origin, direction)
            })
            .collect();
        let no_cap = f32::INFINITY;
        assert!(!crate::accel::wide::RayPacket::new(&[]).set_with_apex(&bundle, 30.0, no_cap));
        let reversed: Vec<(Vec3A, Vec3A)> = bundle.iter().rev().copied().collect();
        let mut found = 0;
        for rays in [&bundle[..], &reversed[..], &bundle[..20]] {
            let mut masked = vec![None; rays.len()];
            accel.closest_hits_masked(rays, f32::INFINITY, &mut masked);
            for (&(o, d), masked) in rays.iter().zip(&masked) {
                assert_eq!(*masked, accel.closest_hit(o, d, f32::INFINITY));
                found += masked.is_some() as usize;
            }
        }
        assert!(found > 100, "too few hits ({found}) at spacing {spacing}");
    }
}

/// A packet of occlusion rays meets, for each ray, exactly the triangles the ray meets
/// alone (every hit, with the same distance bits), and a visitor that stops a ray stops it
/// as it would alone: rays from a tile's surface points converging on a light (several
/// origins, bounds over their segments taken backwards from the light), scattered rays
/// (the masked walk), and rays whose search ends short.
#[test]
fn an_occlusion_packet_meets_what_each_of_its_rays_meets_alone() {
    let mut rng = Rng(0x0dd_b1ade);
    let (_, mut tris) = random_soup(&mut rng, 4000);
    let accel = Accel::build(&mut tris).unwrap();
    let light = Vec3A::new(3.0, 30.0, -2.0);
    let converging: Vec<(Vec3A, Vec3A, f32)> = (0..64)
        .map(|i| {
            let (x, z) = ((i % 8) as f32, (i / 8) as f32);
            let from = Vec3A::new(x * 0.3 - 1.0, -12.0 + rng.next(), z * 0.3 - 1.0);
            let to = light - from;
            (from, to.normalize(), to.length() * 0.999)
        })
        .collect();
    let scattered: Vec<(Vec3A, Vec3A, f32)> = (0..64)
        .map(|_| {
            let origin = rng.point(30.0);
            (
                origin,
                (rng.point(2.0) - origin * 0.05).normalize(),
                10.0 + rng.next() * 30.0,
            )
        })
        .collect();
    let (mut met, mut stopped_rays) = (0, 0);
    for rays in [&converging[..], &scattered[..], &converging[..11]] {
        let pairs: Vec<(Vec3A, Vec3A)> = rays.iter().map(|&(o, d, _)| (o, d)).collect();
        let limits: Vec<f32> = rays.iter().map(|r| r.2).collect();
        // The converging rays walk with bounds over their segments, the scattered masked.
        let bounded = crate::accel::wide::RayPacket::new(&[]).set_converging(&pairs, &limits);
        assert_eq!(bounded, std::ptr::eq(rays.as_ptr(), converging.as_ptr()));
        // Every hit.
        let mut seen = vec![Vec::new(); rays.len()];
        let stopped = accel.visit_hits_packet(&pairs, &limits, |r, slot, t| {
            seen[r].push((slot, t.to_bits()));
            true
        });
        assert_eq!(stopped, 0);
        for (r, &(o, d, t_max)) in rays.iter().enumerate() {
            let mut alone = Vec::new();
            assert!(accel.visit_hits(o, d, t_max, |slot, t| {
                alone.push((slot, t.to_bits()));
                true
            }));
            seen[r].sort_unstable();
            alone.sort_unstable();
            assert_eq!(seen[r], alone, "ray {r}");
            met += alone.len();
        }
        // Stopped at the first hit on an even slot (an opaque surface; odd slots are glass).
        let mut glass_seen = vec![0usize; rays.len()];
        let stopped = accel.visit_hits_packet(&pairs, &limits, |r, slot, _| {
            glass_seen[r] += 1;
            slot % 2 == 1
        });
        for (r, &(o, d, t_max)) in rays.iter().enumerate() {
            let blocked_alone = !accel.visit_hits(o, d, t_max, |slot, _| slot % 2 == 1);
            assert_eq!(stopped & (1 << r) != 0, blocked_alone, "ray {r}");
            stopped_rays += blocked_alone as usize;
        }
    }
    assert!(
        met > 200 && stopped_rays > 20,
        "{met} hits met, {stopped_rays} rays stopped"
    );
    // Degenerate rays among converging ones (a NaN or zero direction, a NaN or huge origin,
    // a NaN or infinite limit): whether the packet gets bounds or not, every ray meets what
    // it meets alone, and the sound rays still meet triangles.
    let mut sound_met = 0;
    for (ray, broken) in [
        (5, (Vec3A::ZERO, Some(f32::NAN), None)),
        (5, (Vec3A::ZERO, None, Some(Vec3A::ZERO))),
        (9, (Vec3A::NAN, None, None)),
        (9, (Vec3A::splat(3e38), None, None)),
        (17, (Vec3A::ZERO, Some(f32::NAN), Some(Vec3A::NAN))),
        (17, (Vec3A::ZERO, Some(f32::INFINITY), None)),
    ] {
        // The ray's origin shifted, and its limit and direction replaced where given.
        let (shift, limit, direction) = broken;
        let mut rays = converging.clone();
        rays[ray].0 += shift;
        if let Some(t) = limit {
            rays[ray].2 = t;
        }
        if let Some(d) = direction {
            rays[ray].1 = d;
        }
        let pairs: Vec<(Vec3A, Vec3A)> = rays.iter().map(|&(o, d, _)| (o, d)).collect();
        let limits: Vec<f32> = rays.iter().map(|r| r.2).collect();
        let mut seen = vec![Vec::new(); rays.len()];
        accel.visit_hits_packet(&pairs, &limits, |r, slot, t| {
            seen[r].push((slot, t.to_bits()));
            true
        });
        for (r, &(o, d, t_max)) in rays.iter().enumerate() {
            let mut alone = Vec::new();
            accel.visit_hits(o, d, t_max, |slot, t| {
                alone.push((slot, t.to_bits()));
                true
            });
            seen[r].sort_unstable();
            alone.sort_unstable();
            assert_eq!(
                seen[r], alone,
                "ray {r} with ray {ray} broken by {broken:?}"
            );
            sound_met += if r == ray { 0 } else { alone.len() };
        }
    }
    assert!(sound_met > 100, "{sound_met} hits of sound rays");
}

/// The parallel full refit (subtree by subtree, leaf boxes and inner lanes written from
/// several tasks) leaves the tree and its SAH cost bit for bit as the sequential one does.
#[test]
fn parallel_full_refit_equals_sequential() {
    let mut rng = Rng(0x51f15eed);
    let (_, mut tris) = random_soup(&mut rng, 5000);
    let mut accel = Accel::build(&mut tris).unwrap();
    let original = accel.triangles_in_slot_order();
    let moved: Vec<[Vec3A; 3]> = original
        .iter()
        .map(|tri| {
            let shift = rng.point(3.0);
            tri.map(|v| v * 1.5 + shift)
        })
        .collect();
    let write = |accel: &mut Accel, tris: &[[Vec3A; 3]]| {
        for (slot, tri) in tris.iter().enumerate() {
            accel.set_triangle(slot as u32, tri);
        }
    };
    write(&mut accel, &moved);
    let sequential_cost = accel.refit_full(false, LeafPass::FromPacks);
    let sequential = accel.wide.bounds_bits();
    // Back to the original boxes, sequentially (so a lane the parallel refit skipped
    // would keep one and show), then the moved triangles again, in parallel.
    write(&mut accel, &original);
    accel.refit_full(false, LeafPass::FromPacks);
    assert_ne!(accel.wide.bounds_bits(), sequential);
    write(&mut accel, &moved);
    let parallel_cost = accel.refit_full(true, LeafPass::FromPacks);
    assert_eq!(accel.wide.bounds_bits(), sequential);
    assert_eq!(parallel_cost.to_bits(), sequential_cost.to_bits());
    // It went subtree by subtree.
    let parts = accel.refit_split.get().and_then(Option::as_ref);
    assert!(parts.is_some_and(|p| p.part_count() > 4));
    // And the refitted tree finds what a fresh build over the moved triangles finds.
    let mut fresh = tris.clone();
    fresh.positions = moved;
    let fresh = Accel::build(&mut fresh).unwrap();
    for _ in 0..300 {
        let (o, d) = (rng.point(40.0), rng.point(2.0).normalize_or_zero());
        let hit = |a: &Accel| a.closest_hit(o, d, f32::INFINITY).map(|h| h.t.to_bits());
        assert_eq!(hit(&accel), hit(&fresh));
    }
}

/// The same for a tree built in chunks (as past 131,072 triangles), whose leaves' slots
/// follow the chunks, and for a tree with two triangles far from the rest, whose leaves
/// hang from the nodes above the parts: every subtree is still one run of nodes, so the
/// parallel refit cuts both and gives the sequential refit's bits.
#[test]
fn parallel_full_refit_of_chunked_and_lopsided_trees_equals_sequential() {
    let mut rng = Rng(0xc0ffee);
    let (positions, mut tris) = random_soup(&mut rng, 6000);
    let chunked = Accel::build_in_chunks(&mut tris, 700).unwrap();
    parallel_refit_equals_sequential(chunked, &mut rng);
    let mut lopsided = positions;
    for x in [1e5f32, -1e5] {
        let c = Vec3A::new(x, 0.0, 0.0);
        lopsided.push([c, c + Vec3A::X, c + Vec3A::Y]);
    }
    let lopsided = Accel::build(&mut soup(&lopsided)).unwrap();
    assert!(parallel_refit_equals_sequential(lopsided, &mut rng) > 0);
}

/// A copy of `accel`'s tree and packs, without the parallel refit's cut (made again by the
/// copy's first parallel refit) or a run writer's note.
fn copy_of(accel: &Accel) -> Accel {
    Accel {
        wide: accel.wide.clone(),
        triangles: accel.triangles.clone(),
        leaves: accel.leaves.clone(),
        leaf_of_slot: accel.leaf_of_slot.clone(),
        build_cost: accel.build_cost,
        cost: accel.cost,
        refit_split: Default::default(),
        leaf_boxes_written: None,
    }
}

/// Moves every triangle of `accel`, refits a copy sequentially and the tree in parallel,
/// checks the two are the same bits; returns how many leaves hang above the parts.
fn parallel_refit_equals_sequential(mut accel: Accel, rng: &mut Rng) -> usize {
    for slot in 0..accel.slots() as u32 {
        let shift = rng.point(2.0);
        let tri = accel.triangle(slot).map(|v| v * 0.7 + shift);
        accel.set_triangle(slot, &tri);
    }
    let mut copy = copy_of(&accel);
    let sequential = copy.refit_full(false, LeafPass::FromPacks);
    let parallel = accel.refit_full(true, LeafPass::FromPacks);
    assert_eq!(parallel.to_bits(), sequential.to_bits());
    assert_eq!(accel.wide.bounds_bits(), copy.wide.bounds_bits());
    let split = accel.refit_split.get().and_then(Option::as_ref);
    split
        .expect("the tree is cut into parts")
        .leaves(None)
        .len()
}

/// Leaf boxes set by a writer of runs of slots (on two threads, each run's leaves after
/// its slots) leave the tree as writing the slots and refitting from the packs does, bit
/// for bit with its SAH cost: for a full refit (the leaves that straddle two runs set by
/// the refit), for a partial one (which still walks up from a leaf whose box is set), and
/// for run lengths that cut leaves and that do not. A frame that moved nothing leaves no
/// note behind: the next write through the plain lanes refits every leaf from the packs.
#[test]
fn leaf_boxes_set_by_a_run_writer_refit_as_the_packs_do() {
    let mut rng = Rng(0x1eaf_b0c5);
    let (_, mut tris) = random_soup(&mut rng, 3000);
    let built = Accel::build_in_chunks(&mut tris, 700).unwrap();
    let slots = built.slots() as u32;
    let (mut straddled, mut kinds) = (0, Vec::new());
    for (run, share) in [(64u32, 1.0), (7, 1.0), (1, 1.0), (4096, 1.0), (64, 0.02)] {
        let mut moved: Vec<(u32, [Vec3A; 3])> = Vec::new();
        for slot in 0..slots {
            if rng.next() < share {
                let shift = rng.point(1.0);
                moved.push((slot, built.triangle(slot).map(|v| v * 1.3 + shift)));
            }
        }
        let mut by_packs = copy_of(&built);
        for (slot, tri) in &moved {
            by_packs.set_triangle(*slot, tri);
        }
        let by_packs_kind = by_packs.refit(&moved.iter().map(|m| m.0).collect::<Vec<_>>());
        let mut by_runs = copy_of(&built);
        {
            let (lanes, boxes) = by_runs.slot_lanes_and_leaf_boxes(run);
            let runs: Vec<std::ops::Range<u32>> = (0..slots)
                .step_by(run as usize)
                .map(|start| start..(start + run).min(slots))
                .collect();
            std::thread::scope(|scope| {
                for half in runs.chunks(runs.len().div_ceil(2)) {
                    let (lanes, boxes, moved) = (&lanes, &boxes, &moved);
                    scope.spawn(move || {
                        for slots in half {
                            for (slot, tri) in moved.iter().filter(|m| slots.contains(&m.0)) {
                                // SAFETY: each run (so each slot) is one task's.
                                unsafe { lanes.set(*slot, tri) };
                            }
                            // SAFETY: as above.
                            unsafe { boxes.set_inside(lanes, slots.clone()) };
                        }
                    });
                }
            });
        }
        let kind = by_runs.refit(&moved.iter().map(|m| m.0).collect::<Vec<_>>());
        assert_eq!(kind, by_packs_kind);
        kinds.push(kind);
        assert_eq!(
            by_runs.wide.bounds_bits(),
            by_packs.wide.bounds_bits(),
            "runs of {run}"
        );
        assert_eq!(by_runs.cost.to_bits(), by_packs.cost.to_bits());
        assert_ne!(by_runs.wide.bounds_bits(), built.wide.bounds_bits());
        straddled += by_runs
            .leaves
            .iter()
            .filter(|l| l.first / run != (l.first + l.count - 1) / run)
            .count();
    }
    assert!(straddled > 100, "{straddled}");
    assert!(kinds.contains(&RefitKind::Full) && kinds.contains(&RefitKind::Partial));
    // The run writer's note does not outlive a frame that moved nothing.
    let mut accel = copy_of(&built);
    let _ = accel.slot_lanes_and_leaf_boxes(64);
    assert_eq!(
        accel.refit_or_rebuild_listing(
            0,
            || unreachable!(),
            BvhPolicy::Refit {
                rebuild_threshold: 1.5
            }
        ),
        TreeStep::Unchanged
    );
    assert_eq!(accel.leaf_boxes_written, None);
}

#[test]
fn tiny_and_empty_trees_answer_packets_and_refits() {
    // Two triangles: the whole tree is one leaf (no wide node), then nothing at all.
    let tri = |z: f32| {
        [
            Vec3A::new(-1.0, -1.0, z),
            Vec3A::new(1.0, -1.0, z),
            Vec3A::new(0.0, 1.0, z),
        ]
    };
    let mut tris = soup(&[tri(-5.0), tri(-2.0)]);
    let mut accel = Accel::build(&mut tris).unwrap();
    let rays = [
        (Vec3A::ZERO, Vec3A::NEG_Z),
        (Vec3A::new(9.0, 0.0, 0.0), Vec3A::NEG_Z),
    ];
    let mut hits = [None; 2];
    accel.closest_hits(&rays, f32::INFINITY, &mut hits);
    assert_eq!(hits[0].map(|h| h.t), Some(2.0));
    assert!(hits[1].is_none());
    // Move the near one behind the far one.
    let near = tris.source.iter().position(|&s| s == 1).unwrap();
    accel.set_triangle(near as u32, &tri(-7.0));
    let moved: Vec<u32> = (0..2).collect();
    accel.refit(&moved);
    assert_eq!(
        accel
            .closest_hit(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY)
            .map(|h| h.t),
        Some(5.0)
    );
    assert!(accel.sah_cost() > 0.0);
    // One triangle: certainly a tree of one leaf; a full refit moves it.
    let mut one = soup(&[tri(-3.0)]);
    let mut accel = Accel::build(&mut one).unwrap();
    accel.set_triangle(0, &tri(-4.0));
    assert_eq!(accel.refit(&[0]), RefitKind::Full);
    assert_eq!(
        accel
            .closest_hit(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY)
            .map(|h| h.t),
        Some(4.0)
    );
    let mut empty = soup(&[]);
    let accel = Accel::build(&mut empty).unwrap();
    accel.closest_hits(&rays, f32::INFINITY, &mut hits);
    assert_eq!(hits, [None, None]);
    assert!(accel.visit_hits(Vec3A::ZERO, Vec3A::X, f32::INFINITY, |_, _| false));
}

#[test]
fn packets_of_axis_parallel_and_repeated_rays_match_single_rays() {
    let mut rng = Rng(99);
    let (_, mut tris) = random_soup(&mut rng, 2000);
    let accel = Accel::build(&mut tris).unwrap();
    // Directions with zero components, both signs of zero, and the same ray many times.
    let mut rays = Vec::new();
    for d in [
        Vec3A::X,
        Vec3A::NEG_X,
        Vec3A::Y,
        Vec3A::NEG_Z,
        Vec3A::new(-0.0, 0.0, 1.0),
    ] {
        for i in 0..6 {
            rays.push((Vec3A::new(i as f32 - 3.0, 1.5, -0.5) - d * 30.0, d));
        }
    }
    rays.extend(std::iter::repeat_n(
        (Vec3A::new(0.0, 0.0, 30.0), Vec3A::NEG_Z),
        10,
    ));
    assert!(rays.len() <= PACKET);
    let mut hits = vec![None; rays.len()];
    accel.closest_hits(&rays, f32::INFINITY, &mut hits);
    for (&(o, d), hit) in rays.iter().zip(&hits) {
        assert_eq!(*hit, accel.closest_hit(o, d, f32::INFINITY));
    }
    assert!(hits.iter().filter(|h| h.is_some()).count() > 5);
}

#[test]
fn rays_through_shared_edges_and_vertices_of_a_mesh_never_slip_through() {
    // A jittered 40 x 40 grid of quads (two triangles each) in a tilted plane; rays aimed
    // exactly at its vertices and at points on its shared edges must all hit it.
    let n = 40;
    let mut rng = Rng(12345);
    let mut grid = vec![Vec3A::ZERO; (n + 1) * (n + 1)];
    for y in 0..=n {
        for x in 0..=n {
            let jitter = if x == 0 || y == 0 || x == n || y == n {
                Vec3A::ZERO
            } else {
                Vec3A::new(rng.next() - 0.5, rng.next() - 0.5, 0.0) * 0.6
            };
            let p = Vec3A::new(x as f32, y as f32, 0.0) + jitter;
            grid[y * (n + 1) + x] = Vec3A::new(p.x, p.y, 0.37 * p.x - 0.21 * p.y);
        }
    }
    let at = |x: usize, y: usize| grid[y * (n + 1) + x];
    let mut quads = Vec::new();
    for y in 0..n {
        for x in 0..n {
            quads.push([at(x, y), at(x + 1, y), at(x + 1, y + 1)]);
            quads.push([at(x, y), at(x + 1, y + 1), at(x, y + 1)]);
        }
    }
    let mut tris = soup(&quads);
    let accel = Accel::build(&mut tris).unwrap();
    let eye = Vec3A::new(17.3, 21.1, 60.0);
    let mut misses = 0;
    let mut rays = 0;
    for y in 1..n {
        for x in 1..n {
            // The vertex, the midpoints of its right and upper edges and of the diagonal.
            let targets = [
                at(x, y),
                (at(x, y) + at(x + 1, y)) * 0.5,
                (at(x, y) + at(x, y + 1)) * 0.5,
                (at(x, y) + at(x + 1, y + 1)) * 0.5,
            ];
            for target in targets {
                rays += 1;
                let direction = (target - eye).normalize();
                misses += accel.closest_hit(eye, direction, f32::INFINITY).is_none() as usize;
            }
        }
    }
    assert_eq!(
        misses, 0,
        "{misses} of {rays} rays slipped through the mesh"
    );
}

#[test]
fn the_builder_reads_the_same_boxes_from_the_positions_as_from_a_box_array() {
    // The build hands obvhs the positions themselves (`PaddedTriangle`); the tree must be
    // the one a separate array of padded boxes gives, node for node.
    let mut rng = Rng(0xb0c5);
    let (tris, _) = random_soup(&mut rng, 3000);
    let params = BvhBuildParams::medium_build();
    let boxes: Vec<Aabb> = tris.iter().map(padded_box).collect();
    let from_boxes = build_bvh2(&boxes, params, &mut Duration::default());
    let wrapped = PaddedTriangle::wrap_slice(&tris);
    let from_positions = build_bvh2(wrapped, params, &mut Duration::default());
    assert_eq!(
        from_positions.primitive_indices,
        from_boxes.primitive_indices
    );
    assert_eq!(from_positions.nodes.len(), from_boxes.nodes.len());
    for (a, b) in from_positions.nodes.iter().zip(&from_boxes.nodes) {
        assert_eq!((a.aabb().min, a.aabb().max), (b.aabb().min, b.aabb().max));
        assert_eq!((a.first_index, a.prim_count), (b.first_index, b.prim_count));
    }
    for (w, b) in wrapped.iter().zip(&boxes) {
        assert_eq!(obvhs::Boundable::aabb(w), *b);
    }
}

#[test]
fn a_build_moves_the_positions_into_the_packs_slot_by_slot() {
    // The packs are the only copy of the positions once a tree is built: the build leaves
    // `positions` empty, and each slot reads back the bits of the triangle its source names,
    // in chunked builds too; `build_from_positions` gives the same tree and slot order.
    let mut rng = Rng(0x90d5);
    let (by_source, tris) = random_soup(&mut rng, 2000);
    for chunk in [BUILD_CHUNK_TRIANGLES, 300] {
        let mut built = tris.clone();
        let accel = Accel::build_in_chunks(&mut built, chunk).unwrap();
        assert!(built.positions.is_empty());
        assert_eq!(accel.slots(), built.len());
        for (slot, &source) in built.source.iter().enumerate() {
            let bits = |t: [Vec3A; 3]| t.map(|v| v.to_array().map(f32::to_bits));
            assert_eq!(
                bits(accel.triangle(slot as u32)),
                bits(by_source[source as usize]),
                "slot {slot}"
            );
        }
        let all = accel.triangles_in_slot_order();
        assert!((0..all.len()).all(|s| all[s] == accel.triangle(s as u32)));
    }
    let mut built = tris.clone();
    let accel = Accel::build(&mut built).unwrap();
    let (other, order) = Accel::build_from_positions(by_source.clone(), &tris.source).unwrap();
    assert_eq!(
        order
            .iter()
            .map(|&i| tris.source[i as usize])
            .collect::<Vec<_>>(),
        built.source
    );
    assert_eq!(
        other.triangles_in_slot_order(),
        accel.triangles_in_slot_order()
    );
    assert_eq!(other.wide.bounds_bits(), accel.wide.bounds_bits());
    // A non-finite vertex stops the build and names its source; the triangles stay as they
    // were.
    let mut bad = tris.clone();
    bad.positions[7][1].y = f32::NAN;
    bad.source[7] = 4242;
    let kept = bad.positions.clone();
    assert!(matches!(
        Accel::build(&mut bad),
        Err(AccelError::NonFiniteVertex { triangle: 4242, .. })
    ));
    assert_eq!(bad.positions.len(), kept.len());
}

#[test]
fn a_built_tree_keeps_no_spare_capacity_in_its_packs() {
    // Packs are reserved exactly from the leaves' sizes; before, they grew by doubling and a
    // million-triangle grid kept 30% of its pack array unused.
    let mut rng = Rng(0xcafe);
    let (_, mut tris) = random_soup(&mut rng, 5000);
    let accel = Accel::build(&mut tris).unwrap();
    let packs = &accel.triangles;
    assert_eq!(packs.pack_capacity(), packs.pack_count());
    assert!(packs.pack_count() * crate::accel::triangles::LANES >= tris.len());
    assert_eq!(accel.leaves.capacity(), accel.leaves.len());
}

mod chunked {
    //! Chunked builds against the single build on hard inputs: stacked copies of one
    //! triangle (every centre equal), zero-area slivers and points, coordinates from 1e-3
    //! to 1e30, and chunks from one triangle up.
    use proptest::prelude::*;

    use super::*;

    /// A triangle of one of the hard kinds, around a centre whose magnitude spans 33
    /// orders.
    fn hard_triangle() -> impl Strategy<Value = [Vec3A; 3]> {
        let centre = (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0, -3i32..30)
            .prop_map(|(x, y, z, e)| Vec3A::new(x, y, z) * 10f32.powi(e));
        let corner =
            (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0).prop_map(|(x, y, z)| Vec3A::new(x, y, z));
        (centre, corner.clone(), corner, 0u8..4).prop_map(|(c, a, b, kind)| {
            let size = c.abs().max_element().max(1.0) * 0.01;
            match kind {
                0 => [c, c + a * size, c + b * size],            // ordinary
                1 => [c, c + a * size, c + a * (2.0 * size)],    // collinear: zero area
                2 => [c, c, c],                                  // a point
                _ => [c, c + a * size, c + a * size + b * 1e-6], // a sliver
            }
        })
    }

    type Answer = (Option<(u32, u32, [u32; 2])>, bool, Vec<u32>);

    fn answer(accel: &Accel, tris: &FrameTriangles, origin: Vec3A, direction: Vec3A) -> Answer {
        let hit = accel
            .closest_hit(origin, direction, f32::INFINITY)
            .map(|h| {
                (
                    tris.source[h.triangle as usize],
                    h.t.to_bits(),
                    h.bary.to_array().map(f32::to_bits),
                )
            });
        let mut met = Vec::new();
        let clear = accel.visit_hits(origin, direction, f32::INFINITY, |slot, _| {
            met.push(tris.source[slot as usize]);
            true
        });
        met.sort_unstable();
        (hit, clear, met)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test]
        fn a_chunked_build_answers_every_ray_as_the_single_build(
            mut tris in prop::collection::vec(hard_triangle(), 1..300),
            copies in 0usize..40,
            chunk in 1usize..40,
            aims in prop::collection::vec((0usize..1000, (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0)), 48),
        ) {
            // A stack of copies of the first triangle: equal centres, exact ties.
            let first = tris[0];
            tris.extend(std::iter::repeat_n(first, copies));
            let mut single = soup(&tris);
            let mut chunked = soup(&tris);
            let one = Accel::build(&mut single).unwrap();
            let parts = Accel::build_in_chunks(&mut chunked, chunk).unwrap();
            for (pick, (x, y, z)) in aims {
                // From off a triangle's centre, aimed at it: most rays hit something.
                let target = tris[pick % tris.len()];
                let centre = (target[0] + target[1] + target[2]) / 3.0;
                let reach = centre.abs().max_element().max(1.0);
                let origin = centre + Vec3A::new(x, y, z + 2.0) * reach;
                let Some(direction) = (centre - origin).try_normalize() else { continue };
                prop_assert_eq!(
                    answer(&parts, &chunked, origin, direction),
                    answer(&one, &single, origin, direction)
                );
            }
        }
    }
}
