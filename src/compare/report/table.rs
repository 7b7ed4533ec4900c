//! `compare.csv` (one row per method) and `compare_frames.csv` (one row per method and
//! frame); see the parent module for the columns and number formats.

use super::{
    FLICKER_DECIMALS, FLIP_DECIMALS, LOD_DECIMALS, MS_DECIMALS, OVERHEAD_DECIMALS, PSNR_DECIMALS,
    SSIM_DECIMALS, fixed,
};
use crate::compare::{CompareReport, MethodSummary};
use crate::csv::csv_field;

pub(super) const SUMMARY_HEADER: &str = "method,bytes_per_ray,ms_per_frame,overhead_pct,psnr,ssim,flip,lod_bias,lod_rms,lod_under,flicker";
pub(super) const FRAMES_HEADER: &str =
    "method,frame,ms,psnr,ssim,flip,lod_bias,lod_rms,lod_under,lod_pixels,flicker";

/// `compare.csv`: the header and one row per method, in report order.
pub fn csv(report: &CompareReport) -> String {
    let rows = report.methods.iter().map(|m| {
        let mut fields = vec![csv_field(&m.method).into_owned()];
        fields.extend(summary_numbers(m, fixed));
        fields.join(",")
    });
    csv_lines(SUMMARY_HEADER, rows)
}

/// `compare_frames.csv`: the header and one row per (method, frame), methods in report
/// order, frames in the order measured.
pub fn frames_csv(report: &CompareReport) -> String {
    let rows = report.methods.iter().flat_map(|m| {
        let method = csv_field(&m.method).into_owned();
        m.frames.iter().map(move |f| {
            let fields = [
                method.clone(),
                f.frame.to_string(),
                fixed(f.ms, MS_DECIMALS),
                fixed(f.psnr, PSNR_DECIMALS),
                fixed(f.ssim, SSIM_DECIMALS),
                fixed(f.flip, FLIP_DECIMALS),
                fixed(f.lod_bias, LOD_DECIMALS),
                fixed(f.lod_rms, LOD_DECIMALS),
                fixed(f.lod_under, LOD_DECIMALS),
                f.lod_pixels.to_string(),
                f.flicker
                    .map_or_else(String::new, |v| fixed(v, FLICKER_DECIMALS)),
            ];
            fields.join(",")
        })
    });
    csv_lines(FRAMES_HEADER, rows)
}

/// The header and rows, each ending in a newline.
fn csv_lines(header: &str, rows: impl Iterator<Item = String>) -> String {
    let mut out = String::from(header);
    out.push('\n');
    for row in rows {
        out.push_str(&row);
        out.push('\n');
    }
    out
}

/// A method's numeric columns after `method`, as `compare.csv` and the Markdown table
/// order them; `number` decides how NaN reads.
pub(super) fn summary_numbers(m: &MethodSummary, number: fn(f64, usize) -> String) -> Vec<String> {
    vec![
        m.bytes_per_ray.to_string(),
        number(m.ms_per_frame, MS_DECIMALS),
        number(m.overhead_pct, OVERHEAD_DECIMALS),
        number(m.psnr, PSNR_DECIMALS),
        number(m.ssim, SSIM_DECIMALS),
        number(m.flip, FLIP_DECIMALS),
        number(m.lod_bias, LOD_DECIMALS),
        number(m.lod_rms, LOD_DECIMALS),
        number(m.lod_under, LOD_DECIMALS),
        number(m.flicker, FLICKER_DECIMALS),
    ]
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{METHODS, sample_report};
    use super::*;

    #[test]
    fn csv_has_the_header_and_one_parseable_row_per_method() {
        let report = sample_report();
        let csv = csv(&report);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], SUMMARY_HEADER);
        assert_eq!(lines.len(), 1 + METHODS.len());
        let columns = SUMMARY_HEADER.split(',').count();
        for (line, m) in lines[1..].iter().zip(&report.methods) {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), columns, "{line}");
            assert_eq!(fields[0], m.method);
            for field in &fields[1..] {
                field
                    .parse::<f64>()
                    .unwrap_or_else(|_| panic!("{field} in {line}"));
            }
            let ms: f64 = fields[2].parse().unwrap();
            assert!(
                (ms - m.ms_per_frame).abs() <= 0.0005,
                "{ms} vs {}",
                m.ms_per_frame
            );
        }
        assert_eq!(lines[1].split(',').nth(4), Some("inf"));
        assert_eq!(lines[3].split(',').nth(10), Some("nan"));
    }

    #[test]
    fn frames_csv_has_one_row_per_method_and_frame() {
        let report = sample_report();
        let csv = frames_csv(&report);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], FRAMES_HEADER);
        assert_eq!(lines.len(), 1 + METHODS.len() * 3);
        let columns = FRAMES_HEADER.split(',').count();
        for line in &lines[1..] {
            assert_eq!(line.split(',').count(), columns, "{line}");
        }
        // The first frame has no flicker: an empty last field.
        assert_eq!(
            lines[1],
            "none,10,12.346,inf,0.98765,0.05000,0.250,0.500,0.125,1000,"
        );
        assert!(lines[2].ends_with(",1000,1.500"), "{}", lines[2]);
    }
}
