//! SVG plots for model cards and reports (plotters, SVG back-end only: no fonts or bitmaps to
//! install; the text is drawn by the browser).

use plotters::prelude::*;

/// One named series of points.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub name: String,
    /// Points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Draw as a line (else as markers).
    pub line: bool,
}

/// Axes and title of a plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Axes {
    /// Title above the plot.
    pub title: String,
    /// Label of the x-axis.
    pub x_label: String,
    /// Label of the y-axis.
    pub y_label: String,
    /// Logarithmic y-axis (non-positive values are left out).
    pub log_y: bool,
}

const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Renders the series as an SVG document (640 x 400 px). Empty or non-finite data give a plot
/// with a note instead of an error.
#[must_use]
pub fn svg(axes: &Axes, series: &[Series]) -> String {
    let mut out = String::new();
    if draw(&mut out, axes, series).is_err() {
        out = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"640\" height=\"60\"><text x=\"10\" y=\"30\">{}: no data to plot</text></svg>",
            escape(&axes.title)
        );
    }
    out
}

fn draw(out: &mut String, axes: &Axes, series: &[Series]) -> Result<(), String> {
    let keep = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite() && (!axes.log_y || y > 0.0);
    let all: Vec<(f64, f64)> = series.iter().flat_map(|s| s.points.iter().copied().filter(keep)).collect();
    if all.is_empty() {
        return Err("no finite points".to_owned());
    }
    let (x_min, x_max) = span(all.iter().map(|p| p.0));
    let (y_min, y_max) = span(all.iter().map(|p| p.1));
    let root = SVGBackend::with_string(out, (640, 400)).into_drawing_area();
    root.fill(&WHITE).map_err(|error| error.to_string())?;
    let mut builder = ChartBuilder::on(&root);
    builder.caption(&axes.title, ("sans-serif", 18)).margin(12).x_label_area_size(40).y_label_area_size(70);
    if axes.log_y {
        let mut chart =
            builder.build_cartesian_2d(x_min..x_max, (y_min..y_max).log_scale()).map_err(|error| error.to_string())?;
        chart
            .configure_mesh()
            .x_desc(axes.x_label.as_str())
            .y_desc(axes.y_label.as_str())
            .draw()
            .map_err(|error| error.to_string())?;
        for (idx, s) in series.iter().enumerate() {
            draw_series(&mut chart, s, idx, &keep)?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|error| error.to_string())?;
    } else {
        let mut chart = builder.build_cartesian_2d(x_min..x_max, y_min..y_max).map_err(|error| error.to_string())?;
        chart
            .configure_mesh()
            .x_desc(axes.x_label.as_str())
            .y_desc(axes.y_label.as_str())
            .draw()
            .map_err(|error| error.to_string())?;
        for (idx, s) in series.iter().enumerate() {
            draw_series(&mut chart, s, idx, &keep)?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|error| error.to_string())?;
    }
    root.present().map_err(|error| error.to_string())?;
    Ok(())
}

fn draw_series<'a, DB: DrawingBackend + 'a, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    series: &Series,
    idx: usize,
    keep: &dyn Fn(&(f64, f64)) -> bool,
) -> Result<(), String>
where
    CT: plotters::coord::CoordTranslate<From = (f64, f64)>,
{
    let colour = COLOURS[idx % COLOURS.len()];
    let points: Vec<(f64, f64)> = series.points.iter().copied().filter(keep).collect();
    let legend = move |(x, y): (i32, i32)| PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2));
    if series.line {
        chart
            .draw_series(LineSeries::new(points, colour.stroke_width(1)))
            .map_err(|error| error.to_string())?
            .label(series.name.as_str())
            .legend(legend);
    } else {
        chart
            .draw_series(points.into_iter().map(|p| Circle::new(p, 3, colour.filled())))
            .map_err(|error| error.to_string())?
            .label(series.name.as_str())
            .legend(legend);
    }
    Ok(())
}

/// The range of the values, widened a little (and made non-empty).
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (low, high) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = if high > low { 0.05 * (high - low) } else { 0.5 * low.abs().max(1e-12) };
    (low - pad, high + pad)
}

/// Escapes text for SVG/HTML.
#[must_use]
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_an_svg_with_its_title_and_survives_empty_data() {
        let axes = Axes { title: "sweep".into(), x_label: "terms".into(), y_label: "error".into(), log_y: true };
        let series = [Series { name: "held-out".into(), points: vec![(1.0, 1e-3), (2.0, 5e-4)], line: false }];
        let text = svg(&axes, &series);
        assert!(text.starts_with("<svg") && text.contains("sweep"));
        let empty = svg(&axes, &[Series { name: "none".into(), points: vec![(1.0, -1.0)], line: true }]);
        assert!(empty.contains("no data to plot"));
    }
}
