//! `hapcal diagnose`: read a device and a log, run [`hapcal_diagnose::diagnose`], render the
//! table and the residual maps (SVG).

use std::fmt::{self, Write as _};
use std::path::PathBuf;

use anyhow::{Context, Result};
use hapcal_diagnose::{DiagnoseConfig, Diagnosis, diagnose};

/// What `hapcal diagnose` was asked to do, validated.
#[derive(Clone, Debug)]
pub struct DiagnosePlan {
    /// Device file (TOML).
    pub device: PathBuf,
    /// Log (CSV, docs/design.md §5).
    pub data: PathBuf,
    /// Diagnosis settings.
    pub config: DiagnoseConfig,
    /// Units of the log's columns (SI unless set after [`DiagnosePlan::new`]).
    pub units: hapcal_io::Units,
}

impl DiagnosePlan {
    /// A plan from raw flags: `baseline` is `transmissions` or `geometric` (or their older
    /// names `full`, `kinematics`; `hapcal_diagnose::baseline_model`), `folds` ≥ 2.
    ///
    /// # Errors
    /// A bad baseline name or fold count.
    pub fn new(device: PathBuf, data: PathBuf, baseline: &str, folds: usize) -> Result<Self> {
        let baseline = hapcal_diagnose::baseline_model(baseline)?;
        if folds < 2 {
            anyhow::bail!("--folds must be at least 2, got {folds}");
        }
        Ok(Self {
            device,
            data,
            config: DiagnoseConfig {
                baseline,
                folds,
                ..DiagnoseConfig::default()
            },
            units: hapcal_io::Units::default(),
        })
    }
}

/// Reads the files and diagnoses the log; returns the diagnosis and the log's warnings.
///
/// # Errors
/// Unreadable or invalid files (named with line and column), or a failed baseline fit.
pub fn run(plan: &DiagnosePlan) -> Result<(Diagnosis, Vec<String>)> {
    let device = hapcal_io::read_device(&plan.device)
        .with_context(|| format!("reading device {}", plan.device.display()))?;
    let log = hapcal_io::read_log_in(&plan.data, &device, &plan.units)
        .with_context(|| format!("reading log {}", plan.data.display()))?;
    let d = diagnose(&device, &log.rows, &plan.config)
        .with_context(|| format!("diagnosing {}", plan.data.display()))?;
    Ok((d, log.warnings))
}

fn um(m: f64) -> String {
    format!("{:.1}", m * 1e6)
}

/// `significant` or `not significant`.
pub(crate) fn significance(significant: bool) -> &'static str {
    if significant {
        "significant"
    } else {
        "not significant"
    }
}

/// The diagnosis as a text report: gap, where (flagged bins and signals), which (every
/// candidate), how far (accepted effects with their parameters), verdict.
pub fn render(d: &Diagnosis) -> String {
    let mut s = String::new();
    let sections: [fn(&mut String, &Diagnosis) -> fmt::Result; 4] = [gap, where_, which, how_far];
    for section in sections {
        let _ = section(&mut s, d);
    }
    s
}

/// The baseline, the noise floor and the gap above it.
fn gap(s: &mut String, d: &Diagnosis) -> fmt::Result {
    let (samples, params) = (d.n_samples, d.n_params);
    let baseline = d.baseline.name();
    writeln!(
        s,
        "baseline: {baseline}, {samples} samples, {params} identifiable parameters"
    )?;
    writeln!(s, "floor: {}", d.floor_method)?;
    let (heldout, floor, gap) = (um(d.heldout_rms_m), um(d.floor_rms_m), um(d.gap_rms_m));
    writeln!(
        s,
        "held-out RMS {heldout} µm, floor {floor} µm, gap {gap} µm = {:.2} floors (p = {:.1e}, {})",
        d.gap_in_floors,
        d.gap_p_value,
        significance(d.gap_significant)
    )
}

/// WHERE: the signals the residual depends on, with their bins above the floor, and how much
/// of it a free joint-angle error explains.
fn where_(s: &mut String, d: &Diagnosis) -> fmt::Result {
    writeln!(
        s,
        "\nWHERE (signals the residual depends on; bins above the floor)"
    )?;
    for t in d.signals.iter().filter(|t| t.significant) {
        let bins: Vec<String> = (d.where_.iter())
            .filter(|b| b.signal == t.signal && b.flagged)
            .map(|b| format!("[{:.3}, {:.3}) {} µm", b.lo, b.hi, um(b.rms_m)))
            .collect();
        let bins = bins.join("; ");
        writeln!(s, "  {:14} p = {:.1e}  {bins}", t.signal, t.p_value)?;
    }
    let flagged = d.where_.iter().filter(|b| b.flagged).count();
    writeln!(s, "  {flagged} of {} bins flagged", d.where_.len())?;
    let joints: Vec<String> = (d.joints.iter())
        .map(|j| format!("j{} {:.0}%", j.joint, j.explained_pct))
        .collect();
    writeln!(
        s,
        "  free joint-angle error explains: {}",
        joints.join(", ")
    )
}

/// WHICH: every candidate of every round, its held-out RMS before and after and the
/// decision.
fn which(s: &mut String, d: &Diagnosis) -> fmt::Result {
    writeln!(s, "\nWHICH (held-out RMS before → after, share of the gap)")?;
    writeln!(
        s,
        "  {:>2} {:22} {:>9} {:>9} {:>7} {:>9}  decision",
        "rd", "effect", "before µm", "after µm", "gap %", "p"
    )?;
    for c in &d.candidates {
        let (before, after) = (um(c.heldout_rms_before_m), um(c.heldout_rms_after_m));
        let accepted = if c.accepted { "ACCEPTED: " } else { "" };
        writeln!(
            s,
            "  {:>2} {:22} {before:>9} {after:>9} {:>7.0} {:>9.1e}  {accepted}{}",
            c.round, c.effect, c.gap_closed_pct, c.p_value, c.reason
        )?;
    }
    Ok(())
}

/// HOW FAR: each accepted effect's share of the gap and its parameters; what is still
/// unexplained, the notes and the verdict.
fn how_far(s: &mut String, d: &Diagnosis) -> fmt::Result {
    writeln!(s, "\nHOW FAR")?;
    for st in &d.steps {
        let (before, after) = (um(st.heldout_rms_before_m), um(st.heldout_rms_after_m));
        writeln!(
            s,
            "  + {}: held-out RMS {before} → {after} µm, closes {:.0} % of the gap",
            st.effect, st.gap_closed_pct
        )?;
        for p in &st.parameters {
            let (name, value, std, unit) = (&p.name, p.value, p.std, &p.unit);
            writeln!(s, "      {name:34} {value:>12.4e} ± {std:.1e} {unit}")?;
        }
        if !st.confusable_with.is_empty() {
            let names: Vec<&str> = st.confusable_with.iter().map(|e| e.name()).collect();
            writeln!(s, "      resembles: {}", names.join(", "))?;
        }
    }
    let (rms, closed) = (um(d.heldout_rms_final_m), d.gap_closed_pct);
    writeln!(s, "  final held-out RMS {rms} µm; gap closed {closed:.0} %")?;
    if !d.leads.is_empty() {
        writeln!(s, "  still unexplained along: {}", d.leads.join(", "))?;
    }
    for n in &d.notes {
        writeln!(s, "note: {n}")?;
    }
    writeln!(s, "\nverdict: {}", d.verdict)
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use hapcal_calibrate::model::ModelName;

    #[test]
    fn plan_rejects_bad_flags() {
        let err = DiagnosePlan::new("d".into(), "l".into(), "everything", 5)
            .expect_err("unknown baseline");
        assert!(err.to_string().contains("baseline must be"), "{err}");
        let err = DiagnosePlan::new("d".into(), "l".into(), "full", 1).expect_err("one fold");
        assert!(err.to_string().contains("--folds"), "{err}");
        // A model the haptic diagnosis does not start from is refused by its --model name.
        let err = DiagnosePlan::new("d".into(), "l".into(), "mass-compliance", 5)
            .expect_err("not a baseline");
        assert!(
            err.to_string().contains(
                "baseline must be transmissions or geometric (full and kinematics are the \
                 same): a haptic device's log is diagnosed against one of the two, not \
                 mass-compliance"
            ),
            "{err}"
        );
    }

    #[test]
    fn baselines_are_models_and_the_older_names_still_read() {
        for (name, model) in [
            ("transmissions", ModelName::Transmissions),
            ("full", ModelName::Transmissions),
            ("geometric", ModelName::Geometric),
            ("kinematics", ModelName::Geometric),
            ("Full", ModelName::Transmissions),
            ("GEOMETRIC", ModelName::Geometric),
        ] {
            let plan = DiagnosePlan::new("d".into(), "l".into(), name, 5).expect("a baseline");
            assert_eq!(plan.config.baseline, model, "{name}");
        }
    }
}
