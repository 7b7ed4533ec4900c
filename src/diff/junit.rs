//! JUnit XML for CI systems: one test case per frame, a failure element for each frame
//! outside the threshold, an error element for each frame that could not be compared (bad
//! input, such as a missing reference frame).

use std::fmt::Write as _;

use super::DiffReport;
use crate::markup::escape;
use crate::metrics::format_psnr;

/// The report as JUnit XML (testsuites > testsuite > testcase per frame).
pub fn junit_xml(report: &DiffReport) -> String {
    let suite = format!(
        "mipray diff {} vs {}",
        report.reference_dir.display(),
        report.test_dir.display()
    );
    let mut s = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let (n, failed, errors) = (report.frames.len(), report.failed(), report.not_compared());
    let _ = writeln!(
        s,
        "<testsuites name=\"mipray\" tests=\"{n}\" failures=\"{failed}\" errors=\"{errors}\">"
    );
    let _ = writeln!(
        s,
        "  <testsuite name=\"{}\" tests=\"{n}\" failures=\"{failed}\" errors=\"{errors}\">",
        escape(&suite)
    );
    for f in &report.frames {
        let name = format!("frame_{:04}", f.frame);
        if let Some(problem) = &f.problem {
            let _ = writeln!(
                s,
                "    <testcase classname=\"mipray.diff\" name=\"{name}\">\n      \
                 <error type=\"bad-input\" message=\"{}\">reference {}\ntest {}</error>\n    </testcase>",
                escape(problem),
                escape(&f.reference.display().to_string()),
                escape(&f.test.display().to_string()),
            );
            continue;
        }
        let m = &f.metrics;
        let summary = format!(
            "psnr {} dB, mean FLIP {:.5}, max abs {}, {} differing pixels; {} threshold {}",
            format_psnr(m.psnr_db),
            m.mean_flip,
            m.max_abs,
            m.differing_pixels,
            report.metric.name(),
            report.threshold
        );
        if f.passed {
            let _ = writeln!(
                s,
                "    <testcase classname=\"mipray.diff\" name=\"{name}\"/>"
            );
        } else {
            let _ = writeln!(
                s,
                "    <testcase classname=\"mipray.diff\" name=\"{name}\">"
            );
            let detail = format!(
                "reference {}\ntest {}\nheat map {}",
                f.reference.display(),
                f.test.display(),
                f.heat_map
                    .as_ref()
                    .map_or(String::from("-"), |p| p.display().to_string())
            );
            let _ = writeln!(
                s,
                "      <failure type=\"regression\" message=\"{}\">{}</failure>",
                escape(&summary),
                escape(&detail)
            );
            let _ = writeln!(s, "    </testcase>");
        }
    }
    s.push_str("  </testsuite>\n</testsuites>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup_and_drops_control_characters() {
        assert_eq!(escape("a<b>&\"c'\u{1}"), "a&lt;b&gt;&amp;&quot;c&#39;");
    }
}
