//! Chart setup shared by the plots of `mipray report` and `mipray compare` (plotters' SVG
//! backend): the palette, the caption font, the margins and label areas, lines drawn as
//! broken runs with a legend entry, and the legend box.
//!
//! One place, so every mipray plot looks alike and a method or phase keeps its colour.

use plotters::coord::Shift;
use plotters::prelude::*;

/// Line colours: one per quantity of a panel (a panel has at most 7), or per method in the
/// `mipray compare` plots.
pub(crate) const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(0, 0, 0),
];

/// Font family of every caption and label (SVG text, so no font files are needed).
pub(crate) const FONT: &str = "sans-serif";

/// Points of one line segment: (frame, value).
pub(crate) type Run = Vec<(i64, f64)>;

/// The colour of series `index`, cycling through [`PALETTE`].
pub(crate) fn series_color(index: usize) -> RGBColor {
    PALETTE[index % PALETTE.len()]
}

/// A plotters error as the message the plot errors carry.
pub(crate) fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// A chart builder on `area` with a caption of `caption_size` px and the house margin and
/// axis label areas; the caller sets the coordinates (linear, log) and the mesh.
pub(crate) fn chart_on<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, Shift>,
    caption: impl AsRef<str>,
    caption_size: u32,
) -> ChartBuilder<'a, 'b, SVGBackend<'b>> {
    let mut builder = ChartBuilder::on(area);
    builder
        .caption(caption, (FONT, caption_size))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70);
    builder
}

/// Draws `runs` as one series in `color` with a legend entry `label`; a run of a single
/// point has no line, so it is drawn as a dot.
pub(crate) fn draw_runs<'a, 'b: 'a, X, Y>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, Cartesian2d<X, Y>>,
    label: &str,
    runs: &[Run],
    color: RGBColor,
) -> Result<(), String>
where
    X: Ranged<ValueType = i64>,
    Y: Ranged<ValueType = f64>,
{
    let style = color.stroke_width(2);
    chart
        .draw_series(runs.iter().map(|run| PathElement::new(run.clone(), style)))
        .map_err(text)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
    let dots = runs.iter().filter(|run| run.len() == 1).flatten();
    chart
        .draw_series(dots.map(|&p| Circle::new(p, 3, color.filled())))
        .map_err(text)?;
    Ok(())
}

/// The legend in the upper right (where the plots keep headroom), when there are entries.
pub(crate) fn draw_legend<'a, 'b: 'a, C>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, C>,
    entries: usize,
) -> Result<(), String>
where
    C: CoordTranslate,
{
    if entries == 0 {
        return Ok(());
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_cycle_through_the_palette() {
        assert_eq!(series_color(0), PALETTE[0]);
        assert_eq!(series_color(PALETTE.len() + 2), PALETTE[2]);
    }

    #[test]
    fn a_chart_with_runs_and_legend_is_valid_svg() {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (300, 200)).into_drawing_area();
            root.fill(&WHITE).unwrap();
            let mut chart = chart_on(&root, "caption", 14)
                .build_cartesian_2d(0i64..4, 0.0..2.0)
                .unwrap();
            chart.configure_mesh().draw().unwrap();
            let runs = vec![vec![(0, 1.0), (1, 1.5)], vec![(3, 0.5)]];
            draw_runs(&mut chart, "series_ms", &runs, series_color(1)).unwrap();
            draw_legend(&mut chart, 1).unwrap();
            root.present().unwrap();
        }
        assert!(
            svg.contains("\ncaption\n") && svg.contains("\nseries_ms\n"),
            "{svg}"
        );
        // The lone point of the second run is a dot.
        assert!(svg.contains("<circle"), "{svg}");
    }
}
