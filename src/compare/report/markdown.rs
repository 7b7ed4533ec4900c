//! `compare.md`: the run's settings, the method table (the columns of `compare.csv`), how
//! to read it, Table 1 of Park & Kim when measured, and the MIP level shares.

use super::table::summary_numbers;
use super::{MS_DECIMALS, OVERHEAD_DECIMALS, readable};
use crate::compare::{CompareReport, LightsRow, MethodSummary};

/// `text` as one Markdown table cell (a `|` would end the cell).
fn md_cell(text: &str) -> String {
    text.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// `compare.md`: settings, method table, how to read it, Table 1 (when measured) and the
/// MIP level shares.
/// [`markdown`] followed by `appendix` (nothing added when it is empty).
pub fn markdown_with(report: &CompareReport, appendix: &str) -> String {
    let md = markdown(report);
    if appendix.is_empty() {
        md
    } else {
        format!("{md}\n{appendix}")
    }
}

pub fn markdown(report: &CompareReport) -> String {
    let mut lines = vec![
        format!("# LOD methods compared on {}", report.scene),
        String::new(),
        run_settings(report),
        String::new(),
    ];
    lines.extend(methods_table(&report.methods));
    lines.push(String::new());
    lines.push(HOW_TO_READ.to_owned());
    if !report.table1.is_empty() {
        lines.push(String::new());
        lines.extend(table1_section(&report.table1));
    }
    lines.push(String::new());
    lines.extend(mip_share_section(&report.methods));
    let mut md = lines.join("\n");
    md.push('\n');
    md
}

const HOW_TO_READ: &str = "**How to read.** `ms/frame` is the mean per-frame render time \
(median over the repeats) plus the method's share of the frame update; `overhead %` is \
against `none` measured in the same interleaved run, so both saw the same machine state. \
PSNR, SSIM and FLIP compare every frame with the level-0 supersampled reference (PSNR `inf`: \
identical). `LOD bias` is the mean of the method's MIP level minus the level of the probe's \
finite-difference reference (the ±½-pixel rays forced through the centre ray's chain of \
planes; the independent sub-pixel reference has its own section below), in levels: above 0 the method is blurrier than the reference, below 0 \
sharper; `LOD RMS` is the root mean square of the same difference. `LOD under` is the share \
of pixels under-filtered by more than half a level, i.e. at risk of aliasing. `flicker` is \
the mean absolute difference between the method's and the reference's frame-to-frame \
change, in 8-bit code values. `n/a`: not measured (flicker needs two frames).";

/// One line: size, frame range, reference spp, repeats, lights, LOD bias, MIP filter (when
/// `--mip-filter` set one), shared update.
fn run_settings(report: &CompareReport) -> String {
    let mip_filter = report
        .mip_filter
        .map_or(String::new(), |f| format!(", MIP filter {}", f.name()));
    format!(
        "{}x{} px, {}, reference {} spp, {} repeats, {} lights, LOD bias {}{mip_filter}, shared update {} ms/frame",
        report.width,
        report.height,
        frame_span(&report.frames),
        report.reference_spp,
        report.repeats,
        report.lights,
        report.lod_bias,
        readable(report.shared_update_ms, MS_DECIMALS),
    )
}

/// `frames first..last (count)`, or `no frames`.
fn frame_span(frames: &[u32]) -> String {
    match (frames.iter().min(), frames.iter().max()) {
        (Some(first), Some(last)) => format!("frames {first}..{last} ({} frames)", frames.len()),
        _ => "no frames".to_owned(),
    }
}

/// The method table: the columns of `compare.csv`, numbers right-aligned.
fn methods_table(methods: &[MethodSummary]) -> Vec<String> {
    if methods.is_empty() {
        return vec!["No methods were measured.".to_owned()];
    }
    let header = [
        "method",
        "bytes/ray",
        "ms/frame",
        "overhead %",
        "PSNR (dB)",
        "SSIM",
        "FLIP",
        "LOD bias",
        "LOD RMS",
        "LOD under",
        "flicker",
    ];
    let mut lines = table_head(&header);
    lines.extend(methods.iter().map(|m| {
        let mut cells = vec![md_cell(&m.method)];
        cells.extend(summary_numbers(m, readable));
        table_row(&cells)
    }));
    lines
}

/// Header and alignment rows: first column left-aligned, the numbers right-aligned.
fn table_head<S: AsRef<str>>(header: &[S]) -> Vec<String> {
    let align: Vec<&str> = (0..header.len())
        .map(|i| if i == 0 { ":---" } else { "---:" })
        .collect();
    vec![table_row(header), table_row(&align)]
}

fn table_row<S: AsRef<str>>(cells: &[S]) -> String {
    let cells: Vec<&str> = cells.iter().map(AsRef::as_ref).collect();
    format!("| {} |", cells.join(" | "))
}

/// Table 1 of Park & Kim: `none` against `paper` by light count.
fn table1_section(rows: &[LightsRow]) -> Vec<String> {
    let mut lines = vec![
        "## Table 1 (Park & Kim): none vs paper by light count".to_owned(),
        String::new(),
    ];
    lines.extend(table_head(&["lights", "none ms", "paper ms", "overhead %"]));
    lines.extend(rows.iter().map(|r| {
        table_row(&[
            r.lights.to_string(),
            readable(r.none_ms, MS_DECIMALS),
            readable(r.paper_ms, MS_DECIMALS),
            readable(r.overhead_pct, OVERHEAD_DECIMALS),
        ])
    }));
    lines
}

/// Methods as rows, levels 0 up to the highest level any method used as columns, in %.
fn mip_share_section(methods: &[MethodSummary]) -> Vec<String> {
    let mut lines = vec!["## MIP level share".to_owned(), String::new()];
    let Some(highest) = highest_used_level(methods) else {
        lines.push("No texture lookups were recorded.".to_owned());
        return lines;
    };
    lines.push("Share of texture lookups per MIP level, in %.".to_owned());
    lines.push(String::new());
    let header: Vec<String> = std::iter::once("method".to_owned())
        .chain((0..=highest).map(|level| format!("L{level}")))
        .collect();
    lines.extend(table_head(&header));
    lines.extend(methods.iter().map(|m| {
        let mut cells = vec![md_cell(&m.method)];
        cells.extend((0..=highest).map(|level| format!("{:.1}", share(m, level) * 100.0)));
        table_row(&cells)
    }));
    lines
}

/// The highest level with a positive share in any method; `None` without lookups.
pub(super) fn highest_used_level(methods: &[MethodSummary]) -> Option<usize> {
    methods
        .iter()
        .filter_map(|m| (0..m.mip_share.len()).rev().find(|&l| share(m, l) > 0.0))
        .max()
}

/// A method's share of lookups at `level`; 0 beyond its levels or when not finite (nothing
/// to show for it).
pub(super) fn share(m: &MethodSummary, level: usize) -> f64 {
    m.mip_share
        .get(level)
        .copied()
        .filter(|s| s.is_finite())
        .unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{METHODS, sample_report};
    use super::*;

    #[test]
    fn markdown_names_every_method_and_has_table1_only_when_measured() {
        let mut report = sample_report();
        let md = markdown(&report);
        assert!(md.starts_with("# LOD methods compared on sponza\n"));
        assert!(md.contains("320x240 px, frames 10..12 (3 frames), reference 64 spp"));
        for name in METHODS {
            assert!(md.contains(&format!("| {name} |")), "{name} missing:\n{md}");
        }
        assert!(md.contains("## Table 1 (Park & Kim)"));
        assert!(md.contains("| 8 | 30.000 | 30.600 | 2.00 |"));
        assert!(md.contains("**How to read.**"));
        report.table1.clear();
        assert!(!markdown(&report).contains("Table 1"));
    }

    #[test]
    fn the_settings_line_names_a_mip_filter_only_when_one_was_set() {
        let mut report = sample_report();
        assert!(!markdown(&report).contains("MIP filter"));
        report.mip_filter = Some(crate::texture::MipFilter::Nearest);
        let md = markdown(&report);
        assert!(
            md.contains("LOD bias 0, MIP filter nearest, shared update"),
            "{md}"
        );
    }

    #[test]
    fn markdown_mip_columns_stop_at_the_highest_used_level() {
        let md = markdown(&sample_report());
        assert!(md.contains("| method | L0 | L1 | L2 |\n"), "{md}");
        assert!(md.contains("| paper | 50.0 | 30.0 | 20.0 |"), "{md}");
        assert!(md.contains("| none | 100.0 | 0.0 | 0.0 |"), "{md}");
    }
}
