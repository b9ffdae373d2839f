//! The residual maps of a diagnosis as one SVG document each: per signal the held-out RMS of
//! every bin (a bar, red where it lies significantly above the floor) and the floor (a black
//! tick), on one common scale. What `hapcal diagnose --svg` writes and its HTML report shows.

use std::fmt::Write as _;

use crate::Diagnosis;
use crate::arm::ArmDiagnosis;

/// The residual maps as one SVG document: per signal, each bin's held-out RMS (bar, µm; red
/// when flagged above the floor) and the floor (black tick) ([`bar_panels_svg`]).
pub fn residual_map_svg(d: &Diagnosis) -> String {
    let bins = d.where_.iter().map(|b| {
        let title = format!(
            "[{:.3}, {:.3}) rms {:.1} µm, floor {:.1} µm, n {}",
            b.lo,
            b.hi,
            b.rms_m * 1e6,
            b.floor_rms_m * 1e6,
            b.n
        );
        (b.signal.as_str(), b.rms_m, b.floor_rms_m, b.flagged, title)
    });
    let significant = |name: &str| (d.signals.iter()).any(|t| t.signal == name && t.significant);
    let (panels, ymax) = grouped(bins, |name, _| significant(name), 1e-9);
    bar_panels_svg(
        &format!(
            "Held-out residual RMS per bin (µm, common scale to {:.0} µm); red: above the floor; tick: floor. Verdict: {}",
            ymax * 1e6,
            d.verdict
        ),
        &panels,
        ymax,
    )
}

/// The bars of `bins` (signal, held-out RMS and floor in m, flagged, tooltip) as one panel per
/// signal in the order the signals first appear, and their common scale: the largest RMS or
/// floor, at least `least` (m). A panel is in bold if `bold` holds for any of its bars.
pub fn grouped<'a>(
    bins: impl IntoIterator<Item = (&'a str, f64, f64, bool, String)>,
    bold: impl Fn(&str, &Bar) -> bool,
    least: f64,
) -> (Vec<Panel>, f64) {
    let mut panels: Vec<Panel> = Vec::new();
    let mut ymax = 0.0_f64;
    for (name, value_m, floor_m, flagged, title) in bins {
        ymax = ymax.max(value_m.max(floor_m));
        let k = panels
            .iter()
            .position(|p| p.name == name)
            .unwrap_or_else(|| {
                panels.push(Panel {
                    name: name.to_owned(),
                    bold: false,
                    bars: Vec::new(),
                });
                panels.len() - 1
            });
        let bar = Bar {
            value_m,
            floor_m,
            flagged,
            title,
        };
        panels[k].bold |= bold(name, &bar);
        panels[k].bars.push(bar);
    }
    (panels, ymax.max(least))
}

/// One bar of a residual map: the held-out RMS of a bin and its floor.
pub struct Bar {
    /// Held-out RMS, m.
    pub value_m: f64,
    /// Floor (or reference) RMS, m: a black tick.
    pub floor_m: f64,
    /// Drawn red: significantly above the floor.
    pub flagged: bool,
    /// Tooltip.
    pub title: String,
}

/// One panel of a residual map: a signal and its bins.
pub struct Panel {
    /// Signal name, the panel's label.
    pub name: String,
    /// Label in bold (the residual depends on the signal).
    pub bold: bool,
    /// The bins, in the signal's order.
    pub bars: Vec<Bar>,
}

/// Residual maps as one SVG document: a grid of small panels (5 per row), each a bar per bin
/// on the common scale `0..ymax` (m), red when flagged, a black tick at the floor, `title` on
/// top. Hand-written SVG (no fonts read).
pub fn bar_panels_svg(title: &str, panels: &[Panel], ymax: f64) -> String {
    let (pw, ph, cols) = (220.0, 140.0, 5usize);
    let rows = panels.len().div_ceil(cols).max(1);
    let (w, h) = (pw * cols as f64, ph * rows as f64 + 40.0);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="10">"#
    );
    let _ = writeln!(s, r#"<text x="10" y="20" font-size="14">{title}</text>"#);
    for (k, panel) in panels.iter().enumerate() {
        let (x0, y0) = (pw * (k % cols) as f64, 40.0 + ph * (k / cols) as f64);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}"{}>{}</text>"#,
            x0 + 10.0,
            y0 + 12.0,
            if panel.bold {
                r#" font-weight="bold""#
            } else {
                ""
            },
            panel.name
        );
        let (bx, by, bw, bh) = (x0 + 10.0, y0 + 18.0, pw - 30.0, ph - 40.0);
        let _ = writeln!(
            s,
            r##"<rect x="{bx}" y="{by}" width="{bw}" height="{bh}" fill="none" stroke="#999"/>"##
        );
        let n = panel.bars.len().max(1) as f64;
        for (i, b) in panel.bars.iter().enumerate() {
            let bar_h = bh * (b.value_m / ymax).min(1.0);
            let floor_y = by + bh - bh * (b.floor_m / ymax).min(1.0);
            let x = bx + bw * i as f64 / n + 2.0;
            let width = bw / n - 4.0;
            let color = if b.flagged { "#d62728" } else { "#1f77b4" };
            let _ = writeln!(
                s,
                r#"<rect x="{x:.1}" y="{:.1}" width="{width:.1}" height="{bar_h:.1}" fill="{color}"><title>{}</title></rect>"#,
                by + bh - bar_h,
                b.title
            );
            let _ = writeln!(
                s,
                r#"<line x1="{x:.1}" x2="{:.1}" y1="{floor_y:.1}" y2="{floor_y:.1}" stroke="black" stroke-width="2"/>"#,
                x + width
            );
        }
    }
    s.push_str("</svg>\n");
    s
}

/// The residual maps as one SVG document: per signal (each joint reading, time, each joint's
/// gravity torque, the tip's reach, height and azimuth), each bin's held-out 3-D RMS (bar, mm;
/// red when significantly above the floor, Holm) and the floor (black tick), on one common
/// scale ([`bar_panels_svg`]).
pub fn arm_map_svg(d: &ArmDiagnosis) -> String {
    let bins = d.where_.iter().map(|b| {
        let title = format!(
            "[{:.3}, {:.3}] rms {:.4} mm, floor {:.4} mm, n {}, p {:.1e}",
            b.lo,
            b.hi,
            b.rms_m * 1e3,
            b.floor_rms_m * 1e3,
            b.n,
            b.p_value
        );
        (b.signal.as_str(), b.rms_m, b.floor_rms_m, b.flagged, title)
    });
    let (panels, ymax) = grouped(bins, |_, bar| bar.flagged, 1e-12);
    bar_panels_svg(
        &format!(
            "Held-out 3-D residual RMS per bin (common scale to {:.3} mm); red: above the floor (Holm); tick: {}. Verdict: {}",
            ymax * 1e3,
            if d.floor_rms_m.is_some() {
                "floor"
            } else {
                "overall RMS (no floor)"
            },
            d.verdict
        ),
        &panels,
        ymax,
    )
}
