//! Sample reports shared by the tests of the compare report files.

use std::path::Path;

use crate::compare::{CompareReport, FrameErrors, LightsRow, MethodSummary};

pub(super) const METHODS: [&str; 3] = ["none", "paper", "ray_cones"];

fn frame(frame: u32, ms: f64, flip: f64) -> FrameErrors {
    FrameErrors {
        frame,
        ms,
        psnr: 38.5,
        ssim: 0.98765,
        flip,
        lod_bias: 0.25,
        lod_rms: 0.5,
        lod_under: 0.125,
        lod_pixels: 1000,
        flicker: (frame > 10).then_some(1.5),
    }
}

fn method(name: &str, ms: f64, flip: f64, mip_share: Vec<f64>) -> MethodSummary {
    MethodSummary {
        method: name.to_owned(),
        bytes_per_ray: 4,
        ms_per_frame: ms,
        overhead_pct: 1.5,
        psnr: 38.5,
        ssim: 0.98765,
        flip,
        lod_bias: 0.25,
        lod_rms: 0.5,
        lod_under: 0.125,
        flicker: 1.5,
        mip_share,
        frames: (10..13).map(|f| frame(f, ms, flip)).collect(),
    }
}

/// 3 methods on frames 10..=12: `none` has an infinite PSNR (mean and first frame), `ray_cones` a NaN
/// flicker; Table 1 has two rows.
pub(super) fn sample_report() -> CompareReport {
    let mut none = method("none", 12.3456, 0.05, vec![1.0]);
    none.psnr = f64::INFINITY;
    none.frames[0].psnr = f64::INFINITY;
    let paper = method("paper", 12.9, 0.03, vec![0.5, 0.3, 0.2, 0.0, 0.0]);
    let mut cones = method("ray_cones", 13.5, 0.025, vec![0.6, 0.4]);
    cones.flicker = f64::NAN;
    CompareReport {
        scene: "sponza".to_owned(),
        width: 320,
        height: 240,
        frames: vec![10, 11, 12],
        reference_spp: 64,
        repeats: 5,
        lights: 2,
        shared_update_ms: 0.75,
        lod_bias: 0.0,
        mip_filter: None,
        methods: vec![none, paper, cones],
        table1: vec![
            LightsRow {
                lights: 1,
                none_ms: 10.0,
                paper_ms: 10.4,
                overhead_pct: 4.0,
            },
            LightsRow {
                lights: 8,
                none_ms: 30.0,
                paper_ms: 30.6,
                overhead_pct: 2.0,
            },
        ],
    }
}

/// Every float of every method and frame set to NaN (flicker too).
pub(super) fn all_nan_report() -> CompareReport {
    let mut report = sample_report();
    for m in &mut report.methods {
        m.ms_per_frame = f64::NAN;
        m.flip = f64::NAN;
        m.lod_rms = f64::NAN;
        m.mip_share = vec![f64::NAN; 3];
        for f in &mut m.frames {
            f.ms = f64::NAN;
            f.flip = f64::NAN;
            f.flicker = Some(f64::NAN);
        }
    }
    report
}

/// The text of every `<text>` element of the SVG at `path`, which must parse as XML.
pub(super) fn svg_texts(path: &Path) -> Vec<String> {
    let svg = std::fs::read_to_string(path).unwrap();
    let doc = roxmltree::Document::parse(&svg)
        .unwrap_or_else(|e| panic!("{}: invalid XML: {e}", path.display()));
    doc.descendants()
        .filter(|n| n.has_tag_name("text"))
        .map(|n| {
            n.descendants()
                .filter(|t| t.is_text())
                .filter_map(|t| t.text())
                .collect()
        })
        .collect()
}
