//! Plain-text rendering of a [`CalibrationReport`].

use crate::calibrate::{CalibrationReport, Figures};
use hapcal_calibrate::report::{Beyond, Coverage};
use std::fmt::Write;

fn mm(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{:.3}", v * 1e3))
}

pub(crate) fn scaled(value: f64, unit: &str) -> (f64, &'static str) {
    match unit {
        "m" => (value * 1e3, "mm"),
        "rad" => (value * 1e3, "mrad"),
        // Compliance: a few µrad per N·m (or per m of lumped lever arm) on real robots.
        "rad/(N·m)" => (value * 1e6, "µrad/(N·m)"),
        "rad/m" => (value * 1e6, "µrad/m"),
        _ => (value, ""),
    }
}

fn figures_cells(f: &Figures) -> [String; 3] {
    [
        mm(f.mean_absolute_error_m),
        mm(f.distance_error_m),
        mm(f.distance_rms_m),
    ]
}

/// A share as a whole percentage (`more than 1000 %` past 10: an extrapolation from readings
/// that hardly spread).
fn percent(share: f64) -> String {
    if share > 10.0 {
        "more than 1000 %".to_owned()
    } else {
        format!("{:.0} %", share * 100.0)
    }
}

/// How far one set reaches beyond a side: `40 of 40 workspace configurations, up to 2.02 rad
/// beyond (100 % of the range)`.
fn beyond_text(b: &Beyond, what: &str, unit: &str) -> String {
    format!(
        "{} of {} {what}, up to {:.3} {unit} beyond ({} of the range)",
        b.n_beyond,
        b.n,
        b.farthest,
        percent(b.farthest_share)
    )
}

/// The coverage section: where the calibration will be used against its training ranges, and
/// what the model choice did about it.
fn coverage(s: &mut String, c: &Coverage) {
    let mut sets = Vec::new();
    if c.n_workspace > 0 {
        sets.push(format!("{} workspace configurations", c.n_workspace));
    }
    if c.n_test > 0 {
        sets.push(format!("{} test rows", c.n_test));
    }
    let _ = writeln!(
        s,
        "
where the calibration will be used ({}), against the training ranges:",
        sets.join(", ")
    );
    if c.sides.is_empty() {
        let _ = writeln!(
            s,
            "  every configuration lies within the training range of every joint (to {} of \
             the range)",
            percent(hapcal_calibrate::measured::OUTSIDE_SHARE)
        );
        return;
    }
    let z = hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z;
    for side in &c.sides {
        let (lo, hi) = side.training_range;
        let unit = side.unit;
        let mut reach = Vec::new();
        if let Some(w) = side.workspace.filter(|w| w.n_beyond > 0) {
            reach.push(beyond_text(&w, "workspace configurations", unit));
        }
        if let Some(t) = side.test.filter(|t| t.n_beyond > 0) {
            reach.push(beyond_text(&t, "test rows", unit));
        }
        let _ = writeln!(
            s,
            "  {} {} its training range {lo:.3}..{hi:.3} {unit}: {}",
            side.joint,
            if side.upper { "above" } else { "below" },
            reach.join("; ")
        );
        let Some(f) = &side.fold else {
            if c.chosen {
                let _ = writeln!(
                    s,
                    "    no joint-range fold: the training readings' ties leave none at this end"
                );
            }
            continue;
        };
        let end = if f.upper { "top" } else { "bottom" };
        let reach = if f.emulates() {
            "as far as needed".to_owned()
        } else {
            format!(
                "less than the {} needed (a fold holds out at most {} of the rows): the \
                 calibration is not validated that far",
                percent(f.needed_share),
                percent(hapcal_calibrate::measured::MAX_RANGE_FOLD_SHARE)
            )
        };
        let _ = writeln!(
            s,
            "    judged by a joint-range fold holding out the {end} {} of the training rows, \
             an extrapolation of {} of the range it is fitted on, {reach}",
            percent(f.held_out_share),
            percent(f.emulated_share)
        );
    }
    if c.chosen && c.sides.iter().any(|side| side.fold.is_some()) {
        let _ = writeln!(
            s,
            "  a rung is taken only if, on these folds, it beats the rung chosen below it by {z} \
             standard errors at the extrapolation needed (a straight line through the \
             difference of {} blocks of held-out rows against how far they extrapolate) and its \
             advantage does not shrink the farther they extrapolate",
            hapcal_calibrate::measured::RANGE_BLOCKS
        );
    }
    if !c.chosen {
        let _ = writeln!(
            s,
            "  the model was given (--model): no joint-range fold judged it"
        );
    } else if c.stopped.is_empty() {
        let _ = writeln!(s, "  the joint-range folds stopped no rung");
    } else {
        for stop in &c.stopped {
            if !stop.judged {
                let _ = writeln!(
                    s,
                    "  the joint-range folds stopped {}: a fold leaves too few rows to fit it, \
                     so they cannot judge it where the calibration extrapolates",
                    stop.rung
                );
                continue;
            }
            let (d, se) = stop.range_difference;
            let _ = writeln!(
                s,
                "  the joint-range folds stopped {} (against {}: {:+.2} ± {:.2} per row at the \
                 extrapolation needed; {:+.2} per unit of extrapolation, {})",
                stop.rung,
                stop.compared_with,
                d,
                se,
                stop.range_growth,
                if stop.range_growth > 0.0 {
                    "its advantage shrinks"
                } else {
                    "its advantage holds"
                }
            );
        }
    }
}

/// Why a parameter was pruned, in the report's words (`≈ +1.000·dtheta2` for a dependent
/// one).
pub(crate) fn pruned_why(p: &hapcal_calibrate::report::PrunedReport) -> String {
    if p.reason == hapcal_calibrate::report::PruneCause::NearZeroColumn {
        "no effect on the measurements".to_string()
    } else if p.depends_on.is_empty() {
        "not determined better than its plausible range".to_string()
    } else {
        let terms: Vec<String> = p
            .depends_on
            .iter()
            .map(|(n, c)| format!("{c:+.3}·{n}"))
            .collect();
        format!("≈ {}", terms.join(" "))
    }
}

/// Renders the report as the table `hapcal calibrate` prints.
pub fn render(r: &CalibrationReport) -> String {
    let mut s = render_results(r);
    let _ = writeln!(s, "\nelapsed: {:.1} ms", r.elapsed_s * 1e3);
    s
}

/// `beats it` or `does not beat it`: a ladder comparison's verdict in words.
fn beats_words(beats: bool) -> &'static str {
    if beats {
        "beats it"
    } else {
        "does not beat it"
    }
}

/// The rows the model choice judged, in the report's words: "the training data", or a
/// long log's sample ([`CalibrationReport::cross_validated_rows`]).
pub(crate) fn judged_rows(r: &CalibrationReport) -> String {
    match r.cross_validated_rows {
        None => "the training data".to_owned(),
        Some(n) => format!(
            "{n} rows spread over the training data (the chosen model is then fitted on every \
             row)"
        ),
    }
}

/// The text report without the wall time: the machine-independent results (what the HTML
/// report shows in its words).
pub fn render_results(r: &CalibrationReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "hapcal calibrate: {}", r.device);
    if !r.cross_validation.is_empty() {
        let _ = writeln!(
            s,
            "\nmodel choice by {}-fold cross-validation on {} (held-out RMS; held-out squared \
             error minus the geometric model's, ± its standard error; a model is taken only if \
             it beats the one chosen below it by {} standard errors):",
            r.folds,
            judged_rows(r),
            hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z
        );
        // The names' column as wide as the longest (mass-compliance-harmonic).
        let width = (r.cross_validation.iter())
            .map(|cv| cv.model.to_string().len())
            .max()
            .unwrap_or(0);
        let bottom = r.cross_validation.first().map(|cv| cv.model);
        for cv in &r.cross_validation {
            let (diff, se) = cv.difference_to_geometric_m2;
            // A rung above the second level was compared with the rung chosen below it, which
            // need not be the bottom one: that comparison decided, so it is shown.
            let against = match (cv.compared_with, bottom) {
                (Some(m), Some(b)) if m != b => {
                    let (d, e) = cv.difference_to_compared_m2;
                    let z = hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z;
                    format!(
                        "{}; against {m}: {:+.0} ± {:.0} µm², {}",
                        if cv.beats_geometric {
                            format!("  beats {b}")
                        } else {
                            String::new()
                        },
                        d * 1e12,
                        e * 1e12,
                        if d + z * e < 0.0 {
                            "beats it"
                        } else {
                            "does not beat it"
                        }
                    )
                }
                _ if cv.beats_geometric => "  beats".to_owned(),
                _ => String::new(),
            };
            let nested = cv.nested.as_ref().map_or_else(String::new, |n| {
                format!(
                    "; against {}, which it contains: {:+.0} ± {:.0} µm², {}",
                    n.contains,
                    n.difference.0 * 1e12,
                    n.difference.1 * 1e12,
                    beats_words(n.beats)
                )
            });
            let _ = writeln!(
                s,
                "  {:<width$} {:>9.4} mm {:>+10.0} ± {:<8.0} µm²{against}{nested}",
                cv.model.to_string(),
                cv.heldout_rms_m * 1e3,
                diff * 1e12,
                se * 1e12,
            );
        }
    }
    if !r.ladder.is_empty() {
        let _ = writeln!(
            s,
            "\nmodel ladder by {}-fold blocked cross-validation on the training rows (held-out \
             position RMS; held-out weighted squared error per row, Σ e²/σ², minus frames \
             only's, ± its standard error; a rung is taken only if it beats the one chosen \
             below it by {} standard errors):",
            r.folds,
            hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z
        );
        let width = (r.ladder.iter())
            .map(|l| l.rung.to_string().len())
            .max()
            .unwrap_or(0);
        let ranged = r.ladder.iter().any(|l| l.range_rms_m.is_some());
        if ranged {
            let _ = writeln!(
                s,
                "  (then, on the joint-range folds below: held-out position RMS, and weighted \
                 squared error per row minus frames only's)"
            );
        }
        for l in &r.ladder {
            let (diff, se) = l.score_difference_to_frames;
            let range = match l.range_rms_m {
                Some(rms) => format!(
                    "   {:>9.4} mm {:>+9.2}",
                    rms * 1e3,
                    l.range_difference_to_frames
                ),
                None => String::new(),
            };
            let nested = l.nested.as_ref().map_or_else(String::new, |n| {
                format!(
                    "   against {}, which it contains: {:+.2} ± {:.2}, {}",
                    n.contains,
                    n.difference.0,
                    n.difference.1,
                    beats_words(n.beats)
                )
            });
            let _ = writeln!(
                s,
                "  {:<width$} {:>9.4} mm {:>+9.2} ± {:<7.2}{range}{nested}",
                l.rung.to_string(),
                l.heldout_rms_m * 1e3,
                diff,
                se
            );
        }
    }
    if let Some(c) = &r.coverage {
        coverage(&mut s, c);
    }
    let _ = writeln!(
        s,
        "\nmodel: {}; sigma = {:.4} mm (from {}); LM: {}; back end {}",
        r.model,
        r.sigma_m * 1e3,
        r.sigma_source,
        hapcal_calibrate::fit::termination_text(&r.termination),
        r.backend
    );
    let _ = writeln!(
        s,
        "\nidentified ({} parameters, value ± std):",
        r.parameters.len()
    );
    for p in &r.parameters {
        let (v, unit) = scaled(p.value, p.unit);
        let (sd, _) = scaled(p.std, p.unit);
        let _ = writeln!(s, "  {:<28} {:>+10.4} ± {:<8.4} {unit}", p.name, v, sd);
    }
    let _ = writeln!(
        s,
        "\npruned ({} parameters, not identifiable from these data):",
        r.pruned.len()
    );
    for p in &r.pruned {
        let _ = writeln!(s, "  {:<28} {}", p.name, pruned_why(p));
    }
    if !r.frames.is_empty() {
        let _ = writeln!(s, "\nframes (xyz mm; roll, pitch, yaw deg):");
        for f in &r.frames {
            let [x, y, z] = f.xyz_m;
            let [a, b, c] = f.rpy_rad;
            let _ = writeln!(
                s,
                "  {:<12} {:>10.3} {:>10.3} {:>10.3}   {:>9.4} {:>9.4} {:>9.4}",
                f.name,
                x * 1e3,
                y * 1e3,
                z * 1e3,
                a.to_degrees(),
                b.to_degrees(),
                c.to_degrees()
            );
        }
    }
    if !r.correlated.is_empty() {
        let _ = writeln!(s, "\nstrongly correlated pairs (|corr| > 0.95):");
        for (a, b, c) in &r.correlated {
            let _ = writeln!(s, "  {a} ~ {b}: {c:+.3}");
        }
    }
    if let Some(o) = &r.observability {
        let _ = writeln!(
            s,
            "\nobservability of the scaled Jacobian ({} parameters, {} poses): O1 = {:.4e}, O2 = {:.4e} (condition number {:.1}), O3 = {:.4e}, O4 = {:.4e}, O5 = {:.4e}",
            o.n_params, o.n_poses, o.o1, o.o2, o.condition_number, o.o3, o.o4, o.o5
        );
    }
    if !r.downweighted.is_empty() {
        let _ = writeln!(
            s,
            "\nbounded by the Huber loss (residual as measured → what the fit saw, mm):"
        );
        for d in &r.downweighted {
            let _ = writeln!(
                s,
                "  {}  {:.3} → {:.3}",
                d.place(),
                d.residual_m * 1e3,
                d.bound_m * 1e3
            );
        }
    }
    if let Some(step) = r.equilibrium_step_m {
        let solved = if r.equilibrium_refits > 0 {
            format!(
                "solved by fixed-point iteration (loads of the deflected robot, {} refits); ",
                r.equilibrium_refits
            )
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "\ntorque equilibrium: {solved}one more fixed-point step would move the tips by at \
             most {:.4} mm{}",
            step * 1e3,
            if step > hapcal_calibrate::measured::EQUILIBRIUM_SHARE * r.sigma_m {
                " (see the warnings)"
            } else if r.equilibrium_refits > 0 {
                ""
            } else {
                " (the loads of the undeflected robot suffice)"
            }
        );
    }
    if !r.warnings.is_empty() {
        let _ = writeln!(s, "\nwarnings:");
        for w in &r.warnings {
            let _ = writeln!(s, "  - {w}");
        }
    }
    if r.placements.iter().any(|p| p.before.pose.is_some()) {
        let _ = writeln!(
            s,
            "\nposition error (mm), orientation error (deg), distance error (mm): mean / RMS / max, frames only → calibrated"
        );
        for p in &r.placements {
            let (Some(b), Some(a)) = (p.before.pose, p.after.pose) else {
                continue;
            };
            let distance_only = b.distance_rms_m.is_some() && b.position_rms_m == 0.0;
            if !distance_only {
                let _ = writeln!(
                    s,
                    "  {:<24} {:<5} {:>4}  position {:.3} / {:.3} / {:.3} → {:.3} / {:.3} / {:.3}",
                    p.name,
                    p.role,
                    p.n_rows,
                    b.position_mean_m * 1e3,
                    b.position_rms_m * 1e3,
                    b.position_max_m * 1e3,
                    a.position_mean_m * 1e3,
                    a.position_rms_m * 1e3,
                    a.position_max_m * 1e3
                );
            }
            if let (Some(bm), Some(br), Some(bx), Some(am), Some(ar), Some(ax)) = (
                b.distance_mean_m,
                b.distance_rms_m,
                b.distance_max_m,
                a.distance_mean_m,
                a.distance_rms_m,
                a.distance_max_m,
            ) {
                let (name, role, n) = if distance_only {
                    (p.name.as_str(), p.role.to_string(), p.n_rows.to_string())
                } else {
                    ("", String::new(), String::new())
                };
                let _ = writeln!(
                    s,
                    "  {name:<24} {role:<5} {n:>4}  distance {:.3} / {:.3} / {:.3} → {:.3} / {:.3} / {:.3}",
                    bm * 1e3,
                    br * 1e3,
                    bx * 1e3,
                    am * 1e3,
                    ar * 1e3,
                    ax * 1e3
                );
            }
            if let (Some(bm), Some(br), Some(bx), Some(am), Some(ar), Some(ax)) = (
                b.orientation_mean_rad,
                b.orientation_rms_rad,
                b.orientation_max_rad,
                a.orientation_mean_rad,
                a.orientation_rms_rad,
                a.orientation_max_rad,
            ) {
                let _ = writeln!(
                    s,
                    "  {:<24} {:<5} {:>4}  orientation {:.3} / {:.3} / {:.3} → {:.3} / {:.3} / {:.3}",
                    "",
                    "",
                    "",
                    bm.to_degrees(),
                    br.to_degrees(),
                    bx.to_degrees(),
                    am.to_degrees(),
                    ar.to_degrees(),
                    ax.to_degrees()
                );
            }
        }
    } else if (r.placements.iter()).all(|p| {
        p.before.mean_absolute_error_m.is_none()
            && p.before.distance_error_m.is_none()
            && p.after.mean_absolute_error_m.is_none()
            && p.after.distance_error_m.is_none()
    }) {
        // A haptic device's logs: the cable distance's RMS alone.
        let _ = writeln!(
            s,
            "\ndistance RMS (mm): the nominal model on the raw readings → the calibrated model"
        );
        let _ = writeln!(
            s,
            "  {:<16} {:<5} {:>4}  {:>10} {:>10}",
            "log", "role", "rows", "before", "after"
        );
        for p in &r.placements {
            let _ = writeln!(
                s,
                "  {:<16} {:<5} {:>4}  {:>10} {:>10}",
                p.name,
                p.role,
                p.n_rows,
                mm(p.before.distance_rms_m),
                mm(p.after.distance_rms_m)
            );
        }
    } else {
        let _ = writeln!(
            s,
            "\nfigures of merit (mm): MAE = mean absolute error to the socket mean, dist = socket distance error"
        );
        let _ = writeln!(
            s,
            "  {:<16} {:<5} {:>4}  {:>10} {:>10} {:>10}  {:>10} {:>10} {:>10}",
            "placement",
            "role",
            "rows",
            "MAE before",
            "dist bef.",
            "rms before",
            "MAE after",
            "dist after",
            "rms after"
        );
        for p in &r.placements {
            let b = figures_cells(&p.before);
            let a = figures_cells(&p.after);
            let _ = writeln!(
                s,
                "  {:<16} {:<5} {:>4}  {:>10} {:>10} {:>10}  {:>10} {:>10} {:>10}",
                p.name, p.role, p.n_rows, b[0], b[1], b[2], a[0], a[1], a[2]
            );
        }
    }
    s
}
