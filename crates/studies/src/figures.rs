//! SVG figures of the reproduction: the paper's Fig. 7 (joint-4 transmission error and its
//! polynomial), Fig. 8 (validation errors before and after calibration) and Table 3 as a chart.
//!
//! Every function is pure: it takes slices in the units its name states (SI unless the name says
//! `_mm` or `_pct`), converts to the plotted units (mrad, mm, %) itself and returns the SVG
//! document as a `String`. Drawing goes through `plotters`' SVG backend without font features:
//! labels are plain SVG `<text>` elements that the viewer renders, so no system font is read and
//! text widths for the layout are plotters' built-in estimate.
//!
//! Data handling, the same in every function:
//! - slices that describe the same points must have equal lengths, else
//!   [`FigureError::LengthMismatch`];
//! - non-finite values (NaN, ±∞) are skipped, never plotted, and never panic;
//! - empty slices give a valid SVG with title, axes and legend but no data marks.
//!
//! Architecture invariant: *figures only draw; they compute nothing but unit conversions, RMS
//! values for legends and axis ranges.*

use std::ops::Range;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{SegmentValue, SegmentedCoord};
use plotters::coord::types::{RangedCoordf64, RangedCoordi32};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// The chart type of the bar charts: one x segment per category, y in the plotted unit.
type CategoryChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<SegmentedCoord<RangedCoordi32>, RangedCoordf64>>;

/// Why a figure could not be drawn.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FigureError {
    /// Two slices that describe the same points have different lengths.
    #[error("length mismatch: {what}")]
    LengthMismatch {
        /// Which slices, and their lengths.
        what: String,
    },
    /// plotters reported an error while drawing (its message, as text).
    #[error("drawing failed: {message}")]
    Drawing {
        /// plotters' error message.
        message: String,
    },
}

/// Title of [`fig7_polynomial`].
pub const FIG7_TITLE: &str = "Joint-4 transmission error vs joint reading (cf. paper Fig. 7)";
/// Title of [`fig8_validation`].
pub const FIG8_TITLE: &str = "Validation errors before and after calibration (cf. paper Fig. 8)";
/// Title of [`improvement_bars`].
pub const IMPROVEMENT_TITLE: &str = "Improvement I per parameter (cf. paper Table 3)";
/// Bottom of the y axis of [`improvement_bars`], in %; lower values are drawn at this value.
pub const IMPROVEMENT_FLOOR_PCT: f64 = 70.0;

const FONT: &str = "sans-serif";
const TITLE_SIZE: u32 = 22;
const LABEL_SIZE: u32 = 15;
const BLUE: RGBColor = RGBColor(0, 114, 178);
const ORANGE: RGBColor = RGBColor(230, 159, 0);
const VERMILION: RGBColor = RGBColor(213, 94, 0);
const GREY: RGBColor = RGBColor(140, 140, 140);

/// Joint-4 transmission error against the joint reading (the paper's Fig. 7).
///
/// - `theta_rad`: joint-4 readings θ4 (rad), the x axis of both lines;
/// - `true_error_rad`: the simulated true transmission error at each θ4 (rad), drawn as a line;
/// - `polynomial_rad`: the identified 10th-order polynomial at each θ4 (rad), drawn as a line;
/// - `noisy_samples`: `(θ4 rad, error rad)` pairs measured by the external encoder, drawn as
///   small points.
///
/// Errors are plotted in mrad. The legend names the three series.
///
/// # Errors
/// [`FigureError::LengthMismatch`] if `true_error_rad` or `polynomial_rad` is not as long as
/// `theta_rad`; [`FigureError::Drawing`] if plotters fails.
pub fn fig7_polynomial(
    theta_rad: &[f64],
    true_error_rad: &[f64],
    polynomial_rad: &[f64],
    noisy_samples: &[(f64, f64)],
) -> Result<String, FigureError> {
    check_len(("theta_rad", theta_rad), ("true_error_rad", true_error_rad))?;
    check_len(("theta_rad", theta_rad), ("polynomial_rad", polynomial_rad))?;
    let scaled = |ys: &[f64]| finite_points(theta_rad.iter().zip(ys).map(|(&x, &y)| (x, y * 1e3)));
    let truth = scaled(true_error_rad);
    let poly = scaled(polynomial_rad);
    let noisy = finite_points(noisy_samples.iter().map(|&(x, y)| (x, y * 1e3)));
    let all = || truth.iter().chain(&poly).chain(&noisy);
    let x_range = padded_range(all().map(|p| p.0));
    let y_range = padded_range(all().map(|p| p.1));
    let (x_span, y_span) = (x_range.end - x_range.start, y_range.end - y_range.start);

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(drawing)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(FIG7_TITLE, (FONT, TITLE_SIZE))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(x_range, y_range)
            .map_err(drawing)?;
        chart
            .configure_mesh()
            .x_desc("joint reading θ4 (rad)")
            .y_desc("transmission error (mrad)")
            .x_label_formatter(&|v| tick_label(*v, x_span))
            .y_label_formatter(&|v| tick_label(*v, y_span))
            .label_style((FONT, LABEL_SIZE))
            .light_line_style(WHITE)
            .draw()
            .map_err(drawing)?;
        chart
            .draw_series(noisy.iter().map(|&p| Circle::new(p, 2, GREY.filled())))
            .map_err(drawing)?
            .label("external-encoder samples")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, GREY.filled()));
        chart
            .draw_series(LineSeries::new(truth, BLUE.stroke_width(3)))
            .map_err(drawing)?
            .label("true transmission error")
            .legend(|(x, y)| legend_line(x, y, BLUE));
        chart
            .draw_series(LineSeries::new(poly, VERMILION.stroke_width(2)))
            .map_err(drawing)?
            .label("identified 10th-order polynomial")
            .legend(|(x, y)| legend_line(x, y, VERMILION));
        draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        root.present().map_err(drawing)?;
    }
    Ok(svg)
}

/// Validation errors at each pose before and after calibration (the paper's Fig. 8).
///
/// Two stacked panels over the pose index (1 … n): the top one shows the position error of each
/// pose in mm (`position_before_m`, `position_after_m`, given in m), the bottom one the
/// orientation error in mrad (`orientation_before_rad`, `orientation_after_rad`, given in rad).
/// Each legend entry carries the RMS of its series in the plotted unit (non-finite values are
/// left out of the RMS; a series without finite values shows "RMS n/a").
///
/// # Errors
/// [`FigureError::LengthMismatch`] if the two position slices, or the two orientation slices,
/// differ in length; [`FigureError::Drawing`] if plotters fails.
pub fn fig8_validation(
    position_before_m: &[f64],
    position_after_m: &[f64],
    orientation_before_rad: &[f64],
    orientation_after_rad: &[f64],
) -> Result<String, FigureError> {
    check_len(
        ("position_before_m", position_before_m),
        ("position_after_m", position_after_m),
    )?;
    check_len(
        ("orientation_before_rad", orientation_before_rad),
        ("orientation_after_rad", orientation_after_rad),
    )?;

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 760)).into_drawing_area();
        root.fill(&WHITE).map_err(drawing)?;
        let root = root
            .titled(FIG8_TITLE, (FONT, TITLE_SIZE))
            .map_err(drawing)?;
        let (top, bottom) = root.split_vertically(root.dim_in_pixel().1 / 2);
        let panels = [
            (
                &top,
                "position error",
                "position error (mm)",
                "mm",
                position_before_m,
                position_after_m,
            ),
            (
                &bottom,
                "orientation error",
                "orientation error (mrad)",
                "mrad",
                orientation_before_rad,
                orientation_after_rad,
            ),
        ];
        for (area, caption, y_desc, unit, before, after) in panels {
            // Both inputs are SI (m, rad); the plotted units (mm, mrad) are 10³ of them.
            let series = |v: &[f64]| -> Vec<(i32, f64)> {
                (1..)
                    .zip(v)
                    .map(|(i, &e)| (i, e * 1e3))
                    .filter(|p| p.1.is_finite())
                    .collect()
            };
            let (before, after) = (series(before), series(after));
            let n = i32::try_from(before.len().max(after.len())).unwrap_or(i32::MAX - 1);
            let y_top = before
                .iter()
                .chain(&after)
                .map(|p| p.1)
                .fold(0.0_f64, f64::max);
            // Headroom above the data keeps the legend (upper right) off the markers.
            let y_end = padded_range([0.0, y_top * LEGEND_HEADROOM]).end;
            let mut chart = ChartBuilder::on(area)
                .caption(caption, (FONT, 18))
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(70)
                .build_cartesian_2d(0..n + 1, 0.0..y_end)
                .map_err(drawing)?;
            chart
                .configure_mesh()
                .x_desc("pose index")
                .y_desc(y_desc)
                .y_label_formatter(&|v| tick_label(*v, y_end))
                .label_style((FONT, LABEL_SIZE))
                .light_line_style(WHITE)
                .draw()
                .map_err(drawing)?;
            for (points, name, color) in [(before, "before", ORANGE), (after, "after", BLUE)] {
                let label = format!(
                    "{name} calibration (RMS {})",
                    rms(points.iter().map(|p| p.1))
                        .map_or_else(|| "n/a".to_owned(), |r| format!("{r:.3} {unit}"))
                );
                chart
                    .draw_series(LineSeries::new(
                        points.iter().copied(),
                        color.stroke_width(2),
                    ))
                    .map_err(drawing)?
                    .label(label)
                    .legend(move |(x, y)| legend_line(x, y, color));
                chart
                    .draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled())))
                    .map_err(drawing)?;
            }
            draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
        root.present().map_err(drawing)?;
    }
    Ok(svg)
}

/// Improvement I per parameter (the paper's Table 3 as a chart), in %.
///
/// For parameter `names[i]`: a bar up to our median I `median_pct[i]`, a whisker from the 5th
/// percentile `p5_pct[i]` to the 95th `p95_pct[i]` (over repeated runs), and a marker at the
/// paper's value `paper_pct[i]` where the paper gives one. The y axis runs from
/// [`IMPROVEMENT_FLOOR_PCT`] to 100 %; values outside are drawn at the nearer end (a median below
/// the floor gives an empty bar). The chart widens with the number of parameters.
///
/// # Errors
/// [`FigureError::LengthMismatch`] if `median_pct`, `p5_pct`, `p95_pct` or `paper_pct` is not as
/// long as `names`; [`FigureError::Drawing`] if plotters fails.
pub fn improvement_bars(
    names: &[String],
    median_pct: &[f64],
    p5_pct: &[f64],
    p95_pct: &[f64],
    paper_pct: &[Option<f64>],
) -> Result<String, FigureError> {
    check_len(("names", names), ("median_pct", median_pct))?;
    check_len(("names", names), ("p5_pct", p5_pct))?;
    check_len(("names", names), ("p95_pct", p95_pct))?;
    check_len(("names", names), ("paper_pct", paper_pct))?;
    let clamp = |v: f64| v.clamp(IMPROVEMENT_FLOOR_PCT, 100.0);
    let width = u32::try_from(names.len()).map_or(u32::MAX, |n| (360 + 56 * n).max(900));

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, 540)).into_drawing_area();
        root.fill(&WHITE).map_err(drawing)?;
        let mut chart = category_chart(
            &root,
            IMPROVEMENT_TITLE,
            names,
            IMPROVEMENT_FLOOR_PCT..100.0,
        )?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(names.len() + 1)
            .x_label_formatter(&|v| category_name(names, v))
            .x_desc("parameter")
            .y_desc("improvement I (%), values below 70 % drawn at 70 %")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style((FONT, LABEL_SIZE))
            .light_line_style(WHITE)
            .draw()
            .map_err(drawing)?;
        let inset = segment_px(&chart, names.len()) / 4;
        let bars = (0..).zip(median_pct).filter(|(_, m)| m.is_finite());
        chart
            .draw_series(bars.map(|(i, &m)| {
                let mut bar = Rectangle::new(
                    [
                        (SegmentValue::Exact(i), IMPROVEMENT_FLOOR_PCT),
                        (SegmentValue::Exact(i + 1), clamp(m)),
                    ],
                    BLUE.mix(0.8).filled(),
                );
                bar.set_margin(0, 0, inset, inset);
                bar
            }))
            .map_err(drawing)?;
        let whiskers = (0..)
            .zip(p5_pct.iter().zip(p95_pct))
            .filter(|(_, (lo, hi))| lo.is_finite() && hi.is_finite());
        chart
            .draw_series(whiskers.map(|(i, (&lo, &hi))| {
                PathElement::new(
                    vec![
                        (SegmentValue::CenterOf(i), clamp(lo)),
                        (SegmentValue::CenterOf(i), clamp(hi)),
                    ],
                    BLACK.stroke_width(2),
                )
            }))
            .map_err(drawing)?;
        let paper = (0..)
            .zip(paper_pct)
            .filter_map(|(i, p)| p.filter(|v| v.is_finite()).map(|v| (i, v)));
        chart
            .draw_series(paper.map(|(i, v)| {
                Circle::new((SegmentValue::CenterOf(i), clamp(v)), 5, VERMILION.filled())
            }))
            .map_err(drawing)?;
        // A median below the axis has no bar: say so where the bar would start.
        let below = (0..)
            .zip(median_pct)
            .filter(|(_, m)| **m < IMPROVEMENT_FLOOR_PCT);
        chart
            .draw_series(below.map(|(i, _)| {
                EmptyElement::at((SegmentValue::CenterOf(i), IMPROVEMENT_FLOOR_PCT))
                    + Text::new(
                        format!("<{IMPROVEMENT_FLOOR_PCT:.0} %"),
                        (0, -4),
                        centred_above((FONT, 13)),
                    )
            }))
            .map_err(drawing)?;
        draw_side_legend(
            &root,
            &[
                (Mark::Bar(BLUE.mix(0.8)), "ours: median I"),
                (Mark::Whisker, "ours: 5-95 % range"),
                (Mark::Dot(VERMILION.to_rgba()), "paper (Table 3)"),
            ],
        )?;
        root.present().map_err(drawing)?;
    }
    Ok(svg)
}

/// How much higher than the largest value the y axis of [`fig8_validation`] reaches, so that the
/// legend box fits above the data.
const LEGEND_HEADROOM: f64 = 1.4;
/// Width in pixels kept free right of a category chart's plot for its legend.
const LEGEND_GUTTER_PX: u32 = 230;

/// The symbol of a legend entry drawn by [`draw_side_legend`].
enum Mark {
    /// A filled swatch, for bars.
    Bar(RGBAColor),
    /// A short black vertical line, for whiskers.
    Whisker,
    /// A filled dot, for point markers.
    Dot(RGBAColor),
}

/// Draws a legend in the gutter right of a category chart's plot, on the whole figure `root`
/// (plotters' own legend is clipped to the plot, where it would hide the bars).
fn draw_side_legend(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    entries: &[(Mark, &str)],
) -> Result<(), FigureError> {
    let x = i32::try_from(root.dim_in_pixel().0.saturating_sub(LEGEND_GUTTER_PX)).unwrap_or(0) + 20;
    let style =
        TextStyle::from((FONT, LABEL_SIZE).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    for ((mark, text), y) in entries.iter().zip((70..).step_by(24)) {
        match mark {
            Mark::Bar(c) => root.draw(&Rectangle::new([(x, y - 7), (x + 20, y + 7)], c.filled())),
            Mark::Whisker => root.draw(&PathElement::new(
                vec![(x + 10, y - 8), (x + 10, y + 8)],
                BLACK.stroke_width(2),
            )),
            Mark::Dot(c) => root.draw(&Circle::new((x + 10, y), 5, c.filled())),
        }
        .map_err(drawing)?;
        root.draw(&Text::new(*text, (x + 30, y), style.clone()))
            .map_err(drawing)?;
    }
    Ok(())
}

/// A text style anchored at the bottom centre, for values written above a point.
fn centred_above(font: (&'static str, u32)) -> TextStyle<'static> {
    TextStyle::from(font.into_font()).pos(Pos::new(HPos::Center, VPos::Bottom))
}

/// A tick label for value `v` on an axis spanning `span`: enough decimals for plotters' tick
/// steps (1, 2 or 5 times a power of ten, at most about 20 ticks), and never "-0.0".
fn tick_label(v: f64, span: f64) -> String {
    let step = span.abs() / 20.0;
    let decimals = if step > 0.0 && step.is_finite() {
        // Small, finite after the clamp: the cast cannot truncate.
        (-step.log10().floor()).clamp(0.0, 6.0) as usize
    } else {
        1
    };
    let text = format!("{v:.decimals$}");
    if text.starts_with('-') && text.bytes().all(|b| matches!(b, b'-' | b'0' | b'.')) {
        text[1..].to_owned()
    } else {
        text
    }
}

/// A chart whose x axis has one segment per entry of `names` (at least two segments, so that a
/// single category still gets a proper width).
fn category_chart<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, Shift>,
    title: &str,
    names: &[String],
    y_range: Range<f64>,
) -> Result<CategoryChart<'a, 'b>, FigureError> {
    let last = i32::try_from(names.len().max(2) - 1).unwrap_or(i32::MAX - 1);
    ChartBuilder::on(root)
        .caption(title, (FONT, TITLE_SIZE))
        .margin(15)
        .margin_right(LEGEND_GUTTER_PX)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d((0..last).into_segmented(), y_range)
        .map_err(drawing)
}

/// Width in pixels of one category segment of a [`category_chart`].
fn segment_px<X: Ranged, Y: Ranged>(
    chart: &ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
    n: usize,
) -> u32 {
    let segments = u32::try_from(n.max(2)).unwrap_or(u32::MAX);
    chart.plotting_area().dim_in_pixel().0 / segments
}

/// The x tick label of a category chart: the name at a segment's centre, else nothing.
fn category_name(names: &[String], v: &SegmentValue<i32>) -> String {
    match v {
        SegmentValue::CenterOf(i) => usize::try_from(*i)
            .ok()
            .and_then(|i| names.get(i))
            .cloned()
            .unwrap_or_default(),
        _ => String::new(),
    }
}

/// Draws the legend box at `position`.
fn draw_legend<'a, 'b: 'a, X: Ranged, Y: Ranged>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, Cartesian2d<X, Y>>,
    position: SeriesLabelPosition,
) -> Result<(), FigureError> {
    chart
        .configure_series_labels()
        .position(position)
        .label_font((FONT, LABEL_SIZE))
        // Wider than plotters' default: its text width estimate is short for capitals.
        .margin(14)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(drawing)
}

/// A short horizontal line for a legend entry.
fn legend_line(x: i32, y: i32, color: RGBColor) -> PathElement<(i32, i32)> {
    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
}

/// `Err(LengthMismatch)` unless both slices have the same length.
fn check_len<A, B>(a: (&str, &[A]), b: (&str, &[B])) -> Result<(), FigureError> {
    if a.1.len() == b.1.len() {
        Ok(())
    } else {
        Err(FigureError::LengthMismatch {
            what: format!(
                "{} has {} values but {} has {}",
                a.0,
                a.1.len(),
                b.0,
                b.1.len()
            ),
        })
    }
}

/// The points whose coordinates are both finite.
fn finite_points(points: impl Iterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    points
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect()
}

/// The range of the finite `values` widened by 5 % on each side; `-1..1` without finite values,
/// and a range of non-zero width around a single value.
fn padded_range(values: impl IntoIterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return -1.0..1.0;
    }
    let span = hi - lo;
    let pad = if span > 0.0 {
        0.05 * span
    } else {
        (0.05 * lo.abs()).max(1.0)
    };
    let (start, end) = (lo - pad, hi + pad);
    if start.is_finite() && end.is_finite() {
        start..end
    } else {
        lo..hi.max(lo + 1.0)
    }
}

/// Root mean square of `values`, `None` if there are none.
fn rms(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum_sq, n) = values.fold((0.0, 0_usize), |(s, n), v| (s + v * v, n + 1));
    (n > 0).then(|| (sum_sq / n as f64).sqrt())
}

/// plotters' error as a [`FigureError::Drawing`].
fn drawing(e: impl std::fmt::Display) -> FigureError {
    FigureError::Drawing {
        message: e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Number of times `needle` occurs in `svg`.
    fn count(svg: &str, needle: &str) -> usize {
        svg.matches(needle).count()
    }

    /// `fill="#RRGGBB"` as the SVG backend writes it.
    fn fill(c: RGBColor) -> String {
        format!("fill=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2)
    }

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| (*s).to_owned()).collect()
    }

    /// Deterministic "noise" in [-1, 1] (a fixed sequence, no RNG needed).
    fn wiggle(i: usize) -> f64 {
        ((i * 7919 % 101) as f64 / 50.0) - 1.0
    }

    /// θ4, true error, polynomial (rad) and noisy samples for [`fig7_polynomial`].
    type Fig7Data = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<(f64, f64)>);

    fn fig7_data(n: usize, n_noisy: usize) -> Fig7Data {
        let theta: Vec<f64> = (0..n)
            .map(|i| -1.2 + 2.4 * i as f64 / (n - 1) as f64)
            .collect();
        let truth: Vec<f64> = theta
            .iter()
            .map(|t| 1e-3 * (0.8 * (3.0 * t).sin() + 0.3 * t))
            .collect();
        let poly: Vec<f64> = truth.iter().map(|e| e + 2e-5).collect();
        let noisy = (0..n_noisy)
            .map(|i| {
                let t = -1.2 + 2.4 * i as f64 / n_noisy as f64;
                (
                    t,
                    1e-3 * (0.8 * (3.0 * t).sin() + 0.3 * t) + 1e-4 * wiggle(i),
                )
            })
            .collect();
        (theta, truth, poly, noisy)
    }

    fn fig8_data(n: usize) -> [Vec<f64>; 4] {
        let f = |scale: f64, k: usize| -> Vec<f64> {
            (0..n).map(|i| scale * (1.2 + wiggle(i + k))).collect()
        };
        [f(1e-3, 0), f(1e-4, 1), f(4e-3, 2), f(5e-4, 3)]
    }

    type Table3 = (Vec<String>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<Option<f64>>);

    fn table3() -> Table3 {
        (
            names(&["dtheta3", "da1", "dalpha2", "dd4", "dtheta5", "r_o4"]),
            vec![97.5, 91.2, 65.0, 99.1, 88.0, 94.4],
            vec![95.0, 85.0, 40.0, 98.0, 80.0, 92.0],
            vec![99.0, 95.5, 80.0, 99.8, 93.0, 96.9],
            vec![Some(98.0), None, Some(72.0), Some(99.5), None, Some(93.0)],
        )
    }

    #[test]
    fn fig7_has_title_legend_and_one_circle_per_sample() {
        let (theta, truth, poly, noisy) = fig7_data(200, 40);
        let svg = fig7_polynomial(&theta, &truth, &poly, &noisy).expect("valid data");
        assert!(svg.starts_with("<svg"), "{}", &svg[..60]);
        assert!(svg.contains(FIG7_TITLE));
        for label in [
            "external-encoder samples",
            "true transmission error",
            "identified 10th-order polynomial",
            "(mrad)",
            "(rad)",
        ] {
            assert!(svg.contains(label), "missing {label:?}");
        }
        // 40 samples + 1 legend marker.
        assert_eq!(count(&svg, "<circle"), 41);
        // One data line + one legend line per colour (axes and ticks are black polylines).
        assert_eq!(count(&svg, "stroke=\"#0072B2\""), 2);
        assert_eq!(count(&svg, "stroke=\"#D55E00\""), 2);
        assert!(!svg.contains(">\n-0.0\n<"), "negative zero tick");
    }

    #[test]
    fn fig7_plots_error_in_mrad() {
        // A sample at 1 mrad must put the y range around 1, so a tick label "1.0" appears.
        let svg = fig7_polynomial(&[0.0, 1.0], &[0.0, 2e-3], &[0.0, 2e-3], &[]).expect("valid");
        assert!(
            svg.contains(">\n1.0\n<") || svg.contains(">1.0<"),
            "no 1.0 mrad tick"
        );
    }

    #[test]
    fn fig7_rejects_mismatched_lengths() {
        let err = fig7_polynomial(&[0.0, 1.0], &[0.0], &[0.0, 1.0], &[]).expect_err("mismatch");
        assert!(matches!(err, FigureError::LengthMismatch { .. }));
        assert_eq!(
            err.to_string(),
            "length mismatch: theta_rad has 2 values but true_error_rad has 1"
        );
        let err = fig7_polynomial(&[0.0], &[0.0], &[], &[]).expect_err("mismatch");
        assert!(err.to_string().contains("polynomial_rad has 0"), "{err}");
    }

    #[test]
    fn fig8_has_both_panels_rms_legends_and_one_circle_per_pose() {
        let [pb, pa, ob, oa] = fig8_data(25);
        let svg = fig8_validation(&pb, &pa, &ob, &oa).expect("valid data");
        assert!(svg.starts_with("<svg"));
        assert!(svg.contains(FIG8_TITLE));
        for label in [
            "position error (mm)",
            "orientation error (mrad)",
            "pose index",
        ] {
            assert!(svg.contains(label), "missing {label:?}");
        }
        let rms_mm = rms(pb.iter().map(|v| v * 1e3)).expect("non-empty");
        let expected = format!("before calibration (RMS {rms_mm:.3} mm)");
        assert!(svg.contains(&expected), "missing {expected:?}");
        let rms_mrad = rms(oa.iter().map(|v| v * 1e3)).expect("non-empty");
        let expected = format!("after calibration (RMS {rms_mrad:.3} mrad)");
        assert!(svg.contains(&expected), "missing {expected:?}");
        // One marker per pose and series; legends use lines, not circles.
        assert_eq!(count(&svg, "<circle"), 4 * 25);
        // Per colour: one data line + one legend line in each panel.
        assert_eq!(count(&svg, "stroke=\"#0072B2\""), 4);
        assert_eq!(count(&svg, "stroke=\"#E69F00\""), 4);
    }

    #[test]
    fn fig8_rms_ignores_non_finite_values_and_says_na_for_none() {
        let svg = fig8_validation(
            &[3e-3, f64::NAN],
            &[4e-3, 0.0],
            &[f64::NAN],
            &[f64::INFINITY],
        )
        .expect("valid shapes");
        assert!(svg.contains("before calibration (RMS 3.000 mm)"));
        assert!(svg.contains("after calibration (RMS 2.828 mm)"));
        assert!(svg.contains("before calibration (RMS n/a)"));
        assert_eq!(count(&svg, "<circle"), 3);
    }

    #[test]
    fn fig8_rejects_mismatched_lengths() {
        let err = fig8_validation(&[1.0], &[1.0], &[1.0, 2.0], &[1.0]).expect_err("mismatch");
        assert_eq!(
            err.to_string(),
            "length mismatch: orientation_before_rad has 2 values but orientation_after_rad has 1"
        );
    }

    #[test]
    fn improvement_bars_have_one_bar_per_parameter_and_one_marker_per_paper_value() {
        let (n, med, p5, p95, paper) = table3();
        let svg = improvement_bars(&n, &med, &p5, &p95, &paper).expect("valid data");
        assert!(svg.starts_with("<svg"));
        assert!(svg.contains(IMPROVEMENT_TITLE));
        for label in [
            "ours: median I",
            "ours: 5-95 % range",
            "paper (Table 3)",
            "(%)",
        ] {
            assert!(svg.contains(label), "missing {label:?}");
        }
        for name in &n {
            assert!(
                svg.contains(&format!(">\n{name}\n<")),
                "missing tick {name}"
            );
        }
        // Bars are filled with BLUE: 6 bars + 1 legend swatch.
        assert_eq!(count(&svg, &fill(BLUE)), 7);
        // 4 paper values + 1 legend marker.
        assert_eq!(count(&svg, "<circle"), 5);
        // 6 whiskers + 1 legend line (axes and ticks are 1 px wide).
        assert_eq!(count(&svg, "stroke=\"#000000\" stroke-width=\"2\""), 7);
        // dalpha2's median of 65 % is below the axis and is marked as such.
        assert_eq!(count(&svg, "&lt;70 %"), 1);
    }

    #[test]
    fn improvement_bars_clamp_to_the_axis() {
        // A median of 10 % must not draw below the plot: its bar has zero height.
        let svg = improvement_bars(
            &names(&["a", "b"]),
            &[10.0, 150.0],
            &[5.0, 100.0],
            &[20.0, 100.0],
            &[Some(-3.0), Some(120.0)],
        )
        .expect("valid");
        let ys: Vec<f64> = svg
            .split("<circle")
            .skip(1)
            .filter_map(|c| c.split("cy=\"").nth(1)?.split('"').next()?.parse().ok())
            .collect();
        assert_eq!(ys.len(), 3);
        // The paper markers sit on the floor and on the top of the axis: far apart, in range.
        assert!(ys[0] > ys[1] + 300.0, "{ys:?}");
        assert!(ys.iter().all(|y| (0.0..540.0).contains(y)), "{ys:?}");
    }

    #[test]
    fn improvement_bars_reject_mismatched_lengths() {
        let (n, med, p5, p95, paper) = table3();
        let err = improvement_bars(&n, &med, &p5, &p95[1..], &paper).expect_err("mismatch");
        assert_eq!(
            err.to_string(),
            "length mismatch: names has 6 values but p95_pct has 5"
        );
        let err = improvement_bars(&n, &med, &p5, &p95, &paper[1..]).expect_err("mismatch");
        assert!(matches!(err, FigureError::LengthMismatch { .. }));
    }

    #[test]
    fn empty_and_non_finite_inputs_give_valid_svgs() {
        let empty: [f64; 0] = [];
        let svgs = [
            fig7_polynomial(&empty, &empty, &empty, &[]),
            fig7_polynomial(&[f64::NAN], &[f64::INFINITY], &[1.0], &[(f64::NAN, 0.0)]),
            fig8_validation(&empty, &empty, &empty, &empty),
            improvement_bars(&[], &empty, &empty, &empty, &[]),
            improvement_bars(
                &names(&["x"]),
                &[f64::NAN],
                &[f64::NAN],
                &[1.0],
                &[Some(f64::NAN)],
            ),
        ];
        for svg in svgs {
            let svg = svg.expect("empty data is drawn, not rejected");
            assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
            assert!(!svg.contains("NaN") && !svg.contains("inf"), "{svg}");
        }
    }

    /// Writes the three figures to the temporary directory, to look at them (e.g. convert with
    /// `rsvg-convert -o fig.png $TMPDIR/hapcal_fig7.svg`).
    #[test]
    fn figures_are_written_to_the_temp_dir() {
        let (theta, truth, poly, noisy) = fig7_data(200, 40);
        let [pb, pa, ob, oa] = fig8_data(25);
        let (n, med, p5, p95, paper) = table3();
        let figures = [
            (
                "hapcal_fig7.svg",
                fig7_polynomial(&theta, &truth, &poly, &noisy),
            ),
            ("hapcal_fig8.svg", fig8_validation(&pb, &pa, &ob, &oa)),
            (
                "hapcal_table3.svg",
                improvement_bars(&n, &med, &p5, &p95, &paper),
            ),
        ];
        for (file, svg) in figures {
            let path = std::env::temp_dir().join(file);
            std::fs::write(&path, svg.expect("valid data")).expect("temp dir is writable");
            let back = std::fs::read_to_string(&path).expect("just written");
            assert!(back.starts_with("<svg"), "{}", path.display());
        }
    }
}
