//! The figures of the HTML report: each an inline SVG drawn with `plotters`' SVG backend (text
//! as `<text>` elements, no font file read), its caption and the numbers it plots.

use plotters::coord::types::RangedCoordf64;
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde_json::{Value, json};

use super::escape;

/// Result of drawing into a figure.
type Drawn = std::result::Result<(), Box<dyn std::error::Error>>;

/// Font family of every label (the browser's sans-serif).
const FONT: &str = "sans-serif";

/// Colours: frames only (before), training, test, workspace, and a highlight.
pub(crate) const GREY: RGBColor = RGBColor(150, 150, 150);
/// Training rows, calibrated.
pub(crate) const BLUE_: RGBColor = RGBColor(31, 119, 180);
/// Test rows, calibrated.
pub(crate) const ORANGE: RGBColor = RGBColor(230, 120, 20);
/// Workspace configurations.
pub(crate) const GREEN_: RGBColor = RGBColor(44, 160, 44);
/// The fine grid lines.
const LIGHT: RGBColor = RGBColor(238, 238, 238);
/// The chosen rung.
pub(crate) const RED_: RGBColor = RGBColor(214, 39, 40);

/// One figure of the report: an id (the element id, stable across runs), a caption (plain
/// text), the SVG document, and the numbers it plots (JSON, for the golden check).
#[derive(Clone, Debug)]
pub struct Figure {
    /// Element id, `fig-…`.
    pub id: String,
    /// Caption, plain text.
    pub caption: String,
    /// The `<svg>` document.
    pub svg: String,
    /// The numbers plotted.
    pub values: Value,
}

impl Figure {
    /// The figure `id` of `caption`, drawn as `svg`, plotting `values`.
    fn new(id: &str, caption: String, svg: String, values: Value) -> Figure {
        Figure {
            id: id.to_owned(),
            caption,
            svg,
            values,
        }
    }

    /// The `<figure>` element: the SVG inline, the caption, the numbers in `data-values`.
    pub fn html(&self) -> String {
        let svg = match self.svg.find("<svg") {
            Some(i) => &self.svg[i..],
            None => self.svg.as_str(),
        };
        format!(
            "<figure class=\"figure\" id=\"{}\" data-values=\"{}\">\n{}\n<figcaption>{}</figcaption>\n</figure>\n",
            escape(&self.id),
            escape(&self.values.to_string()),
            svg.trim_end(),
            escape(&self.caption)
        )
    }
}

/// `v` to 6 significant digits: the numbers a figure records (stable against the last bits
/// of a sum's order).
pub(crate) fn round6(v: f64) -> f64 {
    if !v.is_finite() || v == 0.0 {
        return if v.is_finite() { 0.0 } else { f64::NAN };
    }
    format!("{v:.5e}").parse().unwrap_or(v)
}

/// `values` rounded by [`round6`], as JSON.
pub(crate) fn rounded<'a>(values: impl IntoIterator<Item = &'a f64>) -> Value {
    values.into_iter().map(|v| round6(*v)).collect()
}

/// Draws with `draw` into an SVG of `size` pixels; on a drawing error, an SVG that says so.
fn svg(
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> Drawn,
) -> String {
    let mut out = String::new();
    let failed = {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        let drawn = root
            .fill(&WHITE)
            .map_err(boxed)
            .and_then(|()| draw(&root))
            .and_then(|()| root.present().map_err(boxed));
        drawn.err().map(|e| e.to_string())
    };
    match failed {
        None => out,
        Some(e) => format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"40\"><text x=\"10\" \
             y=\"25\" font-family=\"{FONT}\" font-size=\"14\">figure not drawn: {}</text></svg>",
            size.0,
            escape(&e)
        ),
    }
}

/// The legend of `chart`'s labelled series, in its upper right corner.
fn legend<'a, 'b: 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, CT>,
) -> Drawn {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 12))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// `labels` right-aligned left of `chart`'s rows, the first at the top: label `i` beside
/// `(x, n − 1 − i)`, `n` labels.
fn row_labels(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &ChartContext<'_, SVGBackend<'_>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    x: f64,
    labels: &[String],
) -> Drawn {
    let n = labels.len();
    let style = TextStyle::from((FONT, 12).into_font()).pos(Pos::new(HPos::Right, VPos::Center));
    for (i, label) in labels.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(x, (n - 1 - i) as f64));
        root.draw(&Text::new(label.clone(), (px - 8, py), style.clone()))?;
    }
    Ok(())
}

/// A chart on an SVG drawing area with `f64` coordinates on both axes.
type RowChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A chart of one row per label (top to bottom, at `y = n − 1 − i`) over `x` from `lo` to
/// `hi`: its x mesh described by `x_desc` (axis descriptions `desc_size` px) and the labels
/// right-aligned in a margin `label_width` px wide.
fn labelled_rows<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, Shift>,
    (lo, hi): (f64, f64),
    labels: &[String],
    label_width: u32,
    x_desc: &str,
    desc_size: u32,
) -> std::result::Result<RowChart<'a, 'b>, Box<dyn std::error::Error>> {
    let n = labels.len().max(1);
    let mut chart = ChartBuilder::on(root)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(label_width)
        .build_cartesian_2d(lo..hi, -0.5..n as f64 - 0.5)?;
    chart
        .configure_mesh()
        .light_line_style(LIGHT)
        .disable_y_mesh()
        .y_label_formatter(&|_| String::new())
        .x_desc(x_desc)
        .label_style((FONT, 12))
        .axis_desc_style((FONT, desc_size))
        .draw()?;
    row_labels(root, &chart, lo, labels)?;
    Ok(chart)
}

/// A drawing error as the boxed error [`Drawn`] holds.
fn boxed<E: std::error::Error + 'static>(e: E) -> Box<dyn std::error::Error> {
    Box::new(e)
}

/// The range `[lo, hi]` of `values` widened by 5 % on each side (and to a nonzero width).
fn padded(values: impl Iterator<Item = f64>, include_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if include_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        0.5 * hi.abs().max(1e-9)
    };
    (
        if include_zero && lo == 0.0 {
            0.0
        } else {
            lo - pad
        },
        hi + pad,
    )
}

/// One group of bars (one per category) with optional error bars (± the given half width).
#[derive(Clone, Debug)]
pub(crate) struct BarGroup {
    /// Legend label.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// Value per category (`None`: no bar).
    pub values: Vec<Option<f64>>,
    /// Half width of the error bar per category.
    pub errors: Option<Vec<f64>>,
}

/// A bar chart: `categories` along x, a bar per group in each, error bars where given; the
/// category `highlight` is labelled in bold and marked.
pub(crate) fn bars(
    id: &str,
    caption: String,
    y_desc: &str,
    categories: &[String],
    groups: &[BarGroup],
    highlight: Option<usize>,
) -> Figure {
    let n = categories.len().max(1);
    let width = (140 * n as u32 + 160).clamp(520, 900);
    let (lo, hi) = padded(
        groups.iter().flat_map(|g| {
            (g.values.iter().enumerate()).flat_map(move |(i, v)| {
                let e = g
                    .errors
                    .as_ref()
                    .and_then(|e| e.get(i))
                    .copied()
                    .unwrap_or(0.0);
                v.map(|v| [v - e, v + e]).into_iter().flatten()
            })
        }),
        true,
    );
    let k = groups.len().max(1) as f64;
    let svg = svg((width, 340), |root| {
        let labels: Vec<String> = (categories.iter().enumerate())
            .map(|(i, c)| {
                if Some(i) == highlight {
                    format!("{c} (taken)")
                } else {
                    c.clone()
                }
            })
            .collect();
        let mut chart = ChartBuilder::on(root)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5..n as f64 - 0.5, lo..hi)?;
        chart
            .configure_mesh()
            .light_line_style(LIGHT)
            .disable_x_mesh()
            .x_label_formatter(&|_| String::new())
            .y_desc(y_desc)
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 13))
            .draw()?;
        let style = TextStyle::from((FONT, 13).into_font()).pos(Pos::new(HPos::Center, VPos::Top));
        for (i, label) in labels.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(i as f64, lo));
            root.draw(&Text::new(label.clone(), (px, py + 8), style.clone()))?;
        }
        if let Some(h) = highlight {
            let h = h as f64;
            chart.draw_series(std::iter::once(Rectangle::new(
                [(h - 0.48, lo), (h + 0.48, hi)],
                RED_.mix(0.08).filled(),
            )))?;
        }
        for (gi, g) in groups.iter().enumerate() {
            let w = 0.8 / k;
            let offset = -0.4 + w * gi as f64;
            let color = g.color;
            let rects = (g.values.iter().enumerate()).filter_map(|(i, v)| {
                v.map(|v| {
                    let x0 = i as f64 + offset + 0.05 * w;
                    Rectangle::new([(x0, 0.0_f64.max(lo)), (x0 + 0.9 * w, v)], color.filled())
                })
            });
            chart
                .draw_series(rects)?
                .label(g.label.as_str())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled())
                });
            if let Some(errors) = &g.errors {
                let whiskers =
                    (g.values.iter().zip(errors).enumerate()).filter_map(|(i, (v, e))| {
                        v.map(|v| {
                            let x = i as f64 + offset + 0.5 * w;
                            PathElement::new(
                                vec![
                                    (x - 0.15 * w, v - e),
                                    (x + 0.15 * w, v - e),
                                    (x, v - e),
                                    (x, v + e),
                                    (x - 0.15 * w, v + e),
                                    (x + 0.15 * w, v + e),
                                ],
                                BLACK.stroke_width(1),
                            )
                        })
                    });
                chart.draw_series(whiskers)?;
            }
        }
        if groups.len() > 1 || groups.iter().any(|g| !g.label.is_empty()) {
            legend(&mut chart)?;
        }
        Ok(())
    });
    let values = json!({
        "categories": categories,
        "groups": groups.iter().map(|g| json!({
            "label": g.label,
            "values": g.values.iter().map(|v| v.map(round6)).collect::<Vec<_>>(),
            "errors": g.errors.as_ref().map(rounded),
        })).collect::<Vec<_>>(),
    });
    Figure::new(id, caption, svg, values)
}

/// Horizontal bars, one per name (top to bottom), values in `unit`; a dashed line at ±`mark`.
pub(crate) fn hbars(
    id: &str,
    caption: String,
    x_desc: &str,
    names: &[String],
    values: &[f64],
    mark: f64,
) -> Figure {
    let n = names.len().max(1);
    let height = (18 * n as u32 + 90).clamp(160, 4000);
    let (lo, hi) = padded(values.iter().copied().chain([-mark, mark]), true);
    let svg = svg((760, height), |root| {
        let mut chart = labelled_rows(root, (lo, hi), names, 210, x_desc, 13)?;
        chart.draw_series((values.iter().enumerate()).map(|(i, v)| {
            let y = (n - 1 - i) as f64;
            let color = if v.abs() >= mark { BLUE_ } else { GREY };
            Rectangle::new([(0.0, y - 0.35), (*v, y + 0.35)], color.filled())
        }))?;
        for m in [-mark, mark] {
            chart.draw_series(DashedLineSeries::new(
                [(m, -0.5), (m, n as f64 - 0.5)],
                4,
                3,
                BLACK.stroke_width(1),
            ))?;
        }
        Ok(())
    });
    let values = json!({ "names": names, "values": rounded(values) });
    Figure::new(id, caption, svg, values)
}

/// A series of points.
#[derive(Clone, Debug)]
pub(crate) struct Points {
    /// Legend label.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// The points (x, y).
    pub points: Vec<(f64, f64)>,
}

/// A scatter plot of `series` (drawn in order, later on top), with a legend.
pub(crate) fn scatter(
    id: &str,
    caption: String,
    x_desc: &str,
    y_desc: &str,
    series: &[Points],
) -> Figure {
    let (x0, x1) = padded(
        series.iter().flat_map(|s| s.points.iter().map(|p| p.0)),
        false,
    );
    let (y0, y1) = padded(
        series.iter().flat_map(|s| s.points.iter().map(|p| p.1)),
        true,
    );
    let svg = svg((860, 340), |root| {
        let mut chart = ChartBuilder::on(root)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .light_line_style(LIGHT)
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 13))
            .draw()?;
        for s in series {
            let color = s.color;
            chart
                .draw_series(s.points.iter().map(|&p| Circle::new(p, 2, color.filled())))?
                .label(s.label.as_str())
                .legend(move |(x, y)| Circle::new((x + 6, y), 4, color.filled()));
        }
        legend(&mut chart)?;
        Ok(())
    });
    let values: Value = (series.iter())
        .map(|s| {
            json!({
                "label": s.label,
                "x": rounded(s.points.iter().map(|p| &p.0)),
                "y": rounded(s.points.iter().map(|p| &p.1)),
            })
        })
        .collect::<Value>();
    Figure::new(id, caption, svg, values)
}

/// One panel of small multiples: a title and its series.
#[derive(Clone, Debug)]
pub(crate) struct Panel<S> {
    /// The panel's title.
    pub title: String,
    /// Its series.
    pub series: Vec<S>,
}

/// Samples to histogram.
#[derive(Clone, Debug)]
pub(crate) struct Samples {
    /// Legend label.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// The values.
    pub values: Vec<f64>,
}

/// Number of bins of a histogram.
const HISTOGRAM_BINS: usize = 24;

/// Histograms side by side, one panel each; in a panel every series is binned on the same
/// `HISTOGRAM_BINS` bins from 0 to the largest value of the panel and drawn as a step line.
pub(crate) fn histograms(
    id: &str,
    caption: String,
    x_desc: &str,
    panels: &[Panel<Samples>],
) -> Figure {
    let cols = panels.len().max(1);
    let mut data = Vec::new();
    for p in panels {
        let top = (p.series.iter().flat_map(|s| s.values.iter().copied()))
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max)
            .max(1e-12);
        let width = top / HISTOGRAM_BINS as f64;
        let counts: Vec<Vec<usize>> = (p.series.iter())
            .map(|s| {
                let mut c = vec![0; HISTOGRAM_BINS];
                for v in s.values.iter().filter(|v| v.is_finite()) {
                    let b = ((v / width) as usize).min(HISTOGRAM_BINS - 1);
                    c[b] += 1;
                }
                c
            })
            .collect();
        data.push((width, counts));
    }
    let svg = svg(((430 * cols as u32).min(900), 320), |root| {
        let areas = root.split_evenly((1, cols));
        for ((p, (width, counts)), area) in panels.iter().zip(&data).zip(areas) {
            let ymax = counts.iter().flatten().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
            let mut chart = ChartBuilder::on(&area)
                .caption(p.title.as_str(), (FONT, 14))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(50)
                .build_cartesian_2d(0.0..width * HISTOGRAM_BINS as f64, 0.0..ymax)?;
            chart
                .configure_mesh()
                .light_line_style(LIGHT)
                .x_desc(x_desc)
                .y_desc("samples")
                .x_labels(5)
                .label_style((FONT, 12))
                .axis_desc_style((FONT, 12))
                .draw()?;
            for (s, c) in p.series.iter().zip(counts) {
                let mut steps = vec![(0.0, 0.0)];
                for (b, &n) in c.iter().enumerate() {
                    steps.push((b as f64 * width, n as f64));
                    steps.push(((b + 1) as f64 * width, n as f64));
                }
                steps.push((HISTOGRAM_BINS as f64 * width, 0.0));
                let color = s.color;
                chart
                    .draw_series(LineSeries::new(steps, color.stroke_width(2)))?
                    .label(s.label.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 14, y)], color.stroke_width(2))
                    });
            }
            legend(&mut chart)?;
        }
        Ok(())
    });
    let values: Value = (panels.iter())
        .zip(&data)
        .map(|(p, (width, counts))| {
            json!({
                "title": p.title,
                "bin_width": round6(*width),
                "series": p.series.iter().map(|s| s.label.clone()).collect::<Vec<_>>(),
                "counts": counts,
            })
        })
        .collect::<Value>();
    Figure::new(id, caption, svg, values)
}

/// Binned means: per bin, its centre, the mean and the interval's ends.
#[derive(Clone, Debug)]
pub(crate) struct Binned {
    /// Legend label.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// Per bin: (centre, mean, lower end, upper end).
    pub bins: Vec<(f64, f64, f64, f64)>,
}

/// Small multiples of binned means with their intervals (3 panels per row), one panel per
/// joint: the title names the joint, x its reading in `x_units[k]`.
pub(crate) fn binned_panels(
    id: &str,
    caption: String,
    y_desc: &str,
    x_units: &[&str],
    panels: &[Panel<Binned>],
) -> Figure {
    let cols = panels.len().clamp(1, 3);
    let rows = panels.len().div_ceil(cols).max(1);
    let (y0, y1) = padded(
        panels.iter().flat_map(|p| {
            p.series
                .iter()
                .flat_map(|s| s.bins.iter().flat_map(|b| [b.2, b.3]))
        }),
        true,
    );
    let svg = svg((900, 250 * rows as u32), |root| {
        let areas = root.split_evenly((rows, cols));
        for (k, (p, area)) in panels.iter().zip(areas).enumerate() {
            let (x0, x1) = padded(
                p.series.iter().flat_map(|s| s.bins.iter().map(|b| b.0)),
                false,
            );
            let mut chart = ChartBuilder::on(&area)
                .caption(p.title.as_str(), (FONT, 13))
                .margin(8)
                .x_label_area_size(34)
                .y_label_area_size(50)
                .build_cartesian_2d(x0..x1, y0..y1)?;
            let unit = x_units.get(k).copied().unwrap_or("");
            chart
                .configure_mesh()
                .light_line_style(LIGHT)
                .x_desc(format!("reading, {unit}"))
                .y_desc(y_desc)
                .x_labels(5)
                .y_labels(5)
                .label_style((FONT, 11))
                .axis_desc_style((FONT, 11))
                .draw()?;
            for s in &p.series {
                let color = s.color;
                chart.draw_series(LineSeries::new(
                    s.bins.iter().map(|b| (b.0, b.1)),
                    color.stroke_width(2),
                ))?;
                chart.draw_series(s.bins.iter().map(|b| {
                    PathElement::new(vec![(b.0, b.2), (b.0, b.3)], color.stroke_width(1))
                }))?;
                chart.draw_series(
                    s.bins
                        .iter()
                        .map(|b| Circle::new((b.0, b.1), 3, color.filled())),
                )?;
            }
        }
        Ok(())
    });
    let values: Value = (panels.iter())
        .map(|p| {
            json!({
                "title": p.title,
                "series": p.series.iter().map(|s| json!({
                    "label": s.label,
                    "centre": rounded(s.bins.iter().map(|b| &b.0)),
                    "mean": rounded(s.bins.iter().map(|b| &b.1)),
                    "low": rounded(s.bins.iter().map(|b| &b.2)),
                    "high": rounded(s.bins.iter().map(|b| &b.3)),
                })).collect::<Vec<_>>(),
            })
        })
        .collect::<Value>();
    Figure::new(id, caption, svg, values)
}

/// One joint's row of the coverage figure: its name, training range and the readings of the
/// test rows and the workspace configurations (in the joint's unit).
#[derive(Clone, Debug)]
pub(crate) struct RangeRow {
    /// The joint's name and unit, as the label shows them.
    pub label: String,
    /// Training range (min, max).
    pub training: (f64, f64),
    /// Test rows' readings.
    pub test: Vec<f64>,
    /// Workspace configurations' readings.
    pub workspace: Vec<f64>,
}

/// Each joint's training range (a bar from 0 to 1: readings as a share of the range, so that
/// joints of different spans share one axis) with the test rows (orange, above) and the
/// workspace configurations (green, below) placed on it.
pub(crate) fn ranges(id: &str, caption: String, rows: &[RangeRow]) -> Figure {
    let n = rows.len().max(1);
    let share = |r: &RangeRow, v: f64| {
        let span = r.training.1 - r.training.0;
        if span > 0.0 {
            (v - r.training.0) / span
        } else {
            0.5
        }
    };
    let (lo, hi) = padded(
        rows.iter()
            .flat_map(|r| r.test.iter().chain(&r.workspace).map(move |&v| share(r, v)))
            .chain([0.0, 1.0]),
        false,
    );
    let height = (34 * n as u32 + 90).clamp(160, 1400);
    let labels: Vec<String> = (rows.iter())
        .map(|r| format!("{} [{:.3}, {:.3}]", r.label, r.training.0, r.training.1))
        .collect();
    let svg = svg((860, height), |root| {
        let x_desc =
            "reading as a share of the joint's training range (0: its minimum, 1: its maximum)";
        let mut chart = labelled_rows(root, (lo, hi), &labels, 230, x_desc, 12)?;
        for (i, r) in rows.iter().enumerate() {
            let y = (n - 1 - i) as f64;
            chart.draw_series(std::iter::once(Rectangle::new(
                [(0.0, y - 0.12), (1.0, y + 0.12)],
                BLUE_.mix(0.5).filled(),
            )))?;
            chart.draw_series(
                r.test
                    .iter()
                    .map(|&v| Circle::new((share(r, v), y + 0.25), 2, ORANGE.filled())),
            )?;
            chart.draw_series(
                r.workspace
                    .iter()
                    .map(|&v| Circle::new((share(r, v), y - 0.25), 2, GREEN_.filled())),
            )?;
        }
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label("training range")
            .legend(|(x, y)| {
                Rectangle::new([(x, y - 4), (x + 14, y + 4)], BLUE_.mix(0.5).filled())
            });
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label("test rows")
            .legend(|(x, y)| Circle::new((x + 6, y), 3, ORANGE.filled()));
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label("workspace")
            .legend(|(x, y)| Circle::new((x + 6, y), 3, GREEN_.filled()));
        legend(&mut chart)?;
        Ok(())
    });
    let values = json!(
        rows.iter()
            .map(|r| json!({
                "joint": r.label,
                "training": [round6(r.training.0), round6(r.training.1)],
                "test": rounded(&r.test),
                "workspace": rounded(&r.workspace),
            }))
            .collect::<Vec<_>>()
    );
    Figure::new(id, caption, svg, values)
}

/// A figure made elsewhere (an SVG document written by hand), with its caption and numbers.
pub(crate) fn external(id: &str, caption: String, svg: String, values: Value) -> Figure {
    Figure::new(id, caption, svg, values)
}
