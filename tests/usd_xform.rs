//! USD transforms against `openusd`'s own reading of them: for every xformOp kind, inverted
//! ops, `!resetXformStack!` and time samples (angles far apart included), the world
//! transform the frame loop poses equals the product of `openusd`'s
//! `local_to_parent_transform` over the prim's ancestors at every tested time, between
//! samples too (USD interpolates each op's value, the loader's channels must do the same).
//!
//! Scalar time samples are written with a decimal point: openusd 0.6's text reader keeps an
//! integer literal of a `double` attribute's time sample as an integer, which its
//! interpolation then holds instead of interpolating (the loader reads it as the declared
//! double and interpolates, as USD does).

use std::path::Path;

use glam::DMat4;
use openusd::schemas::geom::{Xform, Xformable};
use openusd::usd;

const STAGE: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
    timeCodesPerSecond = 24
)

def Xform "A"
{
    double3 xformOp:translate = (1, 2, 3)
    float3 xformOp:rotateXYZ.timeSamples = { 0: (0, 0, 0), 10: (30, 200, -400) }
    float3 xformOp:scale.timeSamples = { 0: (1, 1, 1), 10: (2, 0.5, 1) }
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ", "xformOp:scale"]

    def Xform "B"
    {
        double3 xformOp:translate:pivot = (0.5, -1, 0)
        double xformOp:rotateZ.timeSamples = { 0: 0.0, 4: 270.0, 10: 300.0 }
        quatf xformOp:orient = (0.8660254, 0, 0.5, 0)
        uniform token[] xformOpOrder = ["xformOp:translate:pivot", "xformOp:rotateZ", "xformOp:orient", "!invert!xformOp:translate:pivot"]

        def Xform "C"
        {
            double xformOp:translateX.timeSamples = { 2: -1.0, 8: 5.0 }
            float3 xformOp:rotateYXZ = (10, 20, 30)
            float xformOp:scaleZ = 3
            matrix4d xformOp:transform = ( (0, 1, 0, 0), (-1, 0, 0, 0), (0, 0, 1, 0), (4, 5, 6, 1) )
            uniform token[] xformOpOrder = ["!resetXformStack!", "xformOp:translateX", "xformOp:rotateYXZ", "xformOp:scaleZ", "xformOp:transform"]
        }
    }

    def Xform "D"
    {
        quatf xformOp:orient.timeSamples = { 0: (1, 0, 0, 0), 5: (0, 0, 1, 0), 10: (0.5, 0.5, 0.5, 0.5) }
        double xformOp:translateY.timeSamples = { 0: 0.0, 10: -4.0 }
        float xformOp:scaleX.timeSamples = { 0: 1.0, 10: 3.0 }
        float3 xformOp:rotateZYX.timeSamples = { 0: (0, 0, 0), 10: (-170, 95, 181) }
        float3 xformOp:scale = (2, 4, 0.5)
        float xformOp:rotateX = 33
        float xformOp:rotateY:extra = 12
        float xformOp:translateZ = 7
        float xformOp:scaleY = 2
        float3 xformOp:rotateXZY = (5, 6, 7)
        float3 xformOp:rotateZXY = (8, 9, 10)
        float3 xformOp:rotateYZX = (11, 12, 13)
        uniform token[] xformOpOrder = ["xformOp:orient", "xformOp:translateY", "xformOp:scaleX", "xformOp:rotateZYX", "!invert!xformOp:scale", "!invert!xformOp:rotateX", "xformOp:rotateY:extra", "xformOp:translateZ", "xformOp:scaleY", "xformOp:rotateXZY", "xformOp:rotateZXY", "!invert!xformOp:rotateYZX"]
    }

    def Xform "E"
    {
        matrix4d xformOp:transform.timeSamples = {
            0: ( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) ),
            6: ( (0, 2, 0, 0), (-2, 0, 0, 0), (0, 0, 2, 0), (1, 2, 3, 1) ),
        }
        uniform token[] xformOpOrder = ["xformOp:transform"]
    }
}
"#;

/// USD's `matrix4d` (row vectors) as the equivalent column-vector matrix.
fn column(m: openusd::gf::Matrix4d) -> DMat4 {
    DMat4::from_cols_array(&m.0)
}

/// openusd's world transform of `path` at time code `time`.
fn usd_world(stage: &usd::Stage, path: &str, time: f64) -> DMat4 {
    let xform = Xform::get(stage, path).unwrap().unwrap();
    let local = column(xform.local_to_parent_transform(time).unwrap());
    if xform.resets_xform_stack().unwrap() {
        return local;
    }
    match path.rsplit_once('/') {
        Some((parent, _)) if !parent.is_empty() => usd_world(stage, parent, time) * local,
        _ => local,
    }
}

fn check(scene_path: &Path, prims: &[&str], times: &[f64]) {
    let scene = mipray::scene::load(scene_path).unwrap();
    let stage = usd::Stage::open(scene_path.to_str().unwrap()).unwrap();
    for &time in times {
        let world = mipray::anim::node_world_transforms(&scene, (time / 24.0) as f32);
        for prim in prims {
            let node = scene.nodes.iter().position(|n| n.name == *prim).unwrap();
            let ours = world[node].as_dmat4();
            let theirs = usd_world(&stage, prim, time);
            let error = (ours - theirs)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(
                error
                    < 2e-4
                        * theirs
                            .to_cols_array()
                            .iter()
                            .fold(1.0f64, |m, x| m.max(x.abs())),
                "{prim} at time code {time}: ours {ours} vs openusd {theirs} (error {error})"
            );
        }
    }
}

#[test]
fn every_xform_op_kind_poses_as_openusd_composes_it_between_samples_too() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("xforms.usda");
    std::fs::write(&path, STAGE).unwrap();
    let times: Vec<f64> = (0..=44).map(|k| k as f64 * 0.25 - 0.5).collect();
    check(&path, &["/A", "/A/B", "/A/B/C", "/A/D"], &times);
}

/// An animated `transform` op is decomposed per sample: exact at the samples (USD
/// interpolates matrix entries between them, which no rotation channel can follow).
#[test]
fn an_animated_matrix_op_is_exact_at_its_samples() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("xforms.usda");
    std::fs::write(&path, STAGE).unwrap();
    check(&path, &["/A/E"], &[0.0, 6.0, 10.0]);
    let scene = mipray::scene::load(&path).unwrap();
    assert!(
        scene
            .notes
            .iter()
            .any(|n| n.contains("/A/E.xformOp:transform")),
        "{:?}",
        scene.notes
    );
}

/// A rigid move through a rotation op stays rigid: the node's shape key (scale and
/// stretch) never changes, so the frame loop keeps every `log2 P_b`.
#[test]
fn rotation_ops_leave_the_shape_key_unchanged() {
    let stage = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)
def Xform "R"
{
    float3 xformOp:rotateXYZ.timeSamples = { 0: (0, 0, 0), 24: (90, 720, -45) }
    double3 xformOp:translate.timeSamples = { 0: (0, 0, 0), 24: (5, 1, 2) }
    float3 xformOp:scale = (2, 2, 2)
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ", "xformOp:scale"]
}
"#;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("r.usda");
    std::fs::write(&path, stage).unwrap();
    let scene = mipray::scene::load(&path).unwrap();
    let node = scene.nodes.iter().position(|n| n.name == "/R").unwrap();
    let shape =
        |t: f32| mipray::anim::node_shapes(&scene, mipray::anim::AnimationSelection::All, t)[node];
    let first = shape(0.0).expect("a similarity");
    assert_eq!(first.scale, 2.0);
    for k in 1..=24 {
        assert_eq!(shape(k as f32 / 24.0), Some(first), "time code {k}");
    }
}
