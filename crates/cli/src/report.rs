//! Plain-text rendering of a [`CalibrationReport`].

use crate::calibrate::{CalibrationReport, Figures};
use hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z;
use hapcal_calibrate::report::{
    Beyond, Coverage, CoverageSide, NestedComparison, ParamReport, PoseFigures,
};
use std::fmt::{self, Write};

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
fn coverage(s: &mut String, c: &Coverage) -> fmt::Result {
    let mut sets = Vec::new();
    if c.n_workspace > 0 {
        sets.push(format!("{} workspace configurations", c.n_workspace));
    }
    if c.n_test > 0 {
        sets.push(format!("{} test rows", c.n_test));
    }
    writeln!(
        s,
        "\nwhere the calibration will be used ({}), against the training ranges:",
        sets.join(", ")
    )?;
    if c.sides.is_empty() {
        return writeln!(
            s,
            "  every configuration lies within the training range of every joint (to {} of \
             the range)",
            percent(hapcal_calibrate::measured::OUTSIDE_SHARE)
        );
    }
    for side in &c.sides {
        coverage_side(s, side, c.chosen)?;
    }
    if c.chosen && c.sides.iter().any(|side| side.fold.is_some()) {
        writeln!(
            s,
            "  a rung is taken only if, on these folds, it beats the rung chosen below it by {} \
             standard errors at the extrapolation needed (a straight line through the \
             difference of {} blocks of held-out rows against how far they extrapolate) and its \
             advantage does not shrink the farther they extrapolate",
            LADDER_SIGNIFICANCE_Z,
            hapcal_calibrate::measured::RANGE_BLOCKS
        )?;
    }
    range_stops(s, c)
}

/// One end of a joint's training range the calibration is used beyond: how far, and the
/// joint-range fold that judged the model there (`chosen`: the model was chosen).
fn coverage_side(s: &mut String, side: &CoverageSide, chosen: bool) -> fmt::Result {
    let (lo, hi) = side.training_range;
    let unit = side.unit;
    let mut reach = Vec::new();
    if let Some(w) = side.workspace.filter(|w| w.n_beyond > 0) {
        reach.push(beyond_text(&w, "workspace configurations", unit));
    }
    if let Some(t) = side.test.filter(|t| t.n_beyond > 0) {
        reach.push(beyond_text(&t, "test rows", unit));
    }
    writeln!(
        s,
        "  {} {} its training range {lo:.3}..{hi:.3} {unit}: {}",
        side.joint,
        if side.upper { "above" } else { "below" },
        reach.join("; ")
    )?;
    let Some(f) = &side.fold else {
        if chosen {
            writeln!(
                s,
                "    no joint-range fold: the training readings' ties leave none at this end"
            )?;
        }
        return Ok(());
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
    writeln!(
        s,
        "    judged by a joint-range fold holding out the {end} {} of the training rows, \
         an extrapolation of {} of the range it is fitted on, {reach}",
        percent(f.held_out_share),
        percent(f.emulated_share)
    )
}

/// The rungs the joint-range folds stopped, and why.
fn range_stops(s: &mut String, c: &Coverage) -> fmt::Result {
    if !c.chosen {
        return writeln!(
            s,
            "  the model was given (--model): no joint-range fold judged it"
        );
    } else if c.stopped.is_empty() {
        return writeln!(s, "  the joint-range folds stopped no rung");
    }
    for stop in &c.stopped {
        if !stop.judged {
            writeln!(
                s,
                "  the joint-range folds stopped {}: a fold leaves too few rows to fit it, \
                 so they cannot judge it where the calibration extrapolates",
                stop.rung
            )?;
            continue;
        }
        let (d, se) = stop.range_difference;
        let holds = if stop.range_growth > 0.0 {
            "its advantage shrinks"
        } else {
            "its advantage holds"
        };
        writeln!(
            s,
            "  the joint-range folds stopped {} (against {}: {d:+.2} ± {se:.2} per row at the \
             extrapolation needed; {:+.2} per unit of extrapolation, {holds})",
            stop.rung, stop.compared_with, stop.range_growth,
        )?;
    }
    Ok(())
}

/// Why a parameter was pruned, in the report's words (`≈ +1.000·dtheta2` for a dependent
/// one).
pub(crate) fn pruned_why(p: &hapcal_calibrate::report::PrunedReport) -> String {
    if p.reason == hapcal_calibrate::report::PruneCause::NearZeroColumn {
        "no effect on the measurements".to_string()
    } else if p.reason == hapcal_calibrate::report::PruneCause::AtZero {
        "held at zero: below zero within the noise when fitted".to_string()
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

/// A section of the text report, appended to the text.
type Section = fn(&mut String, &CalibrationReport) -> fmt::Result;

/// The text report without the wall time: the machine-independent results (what the HTML
/// report shows in its words), section by section.
pub fn render_results(r: &CalibrationReport) -> String {
    let mut s = format!("hapcal calibrate: {}\n", r.device);
    let sections: [Section; 7] = [
        cross_validation,
        ladder,
        |s, r| r.coverage.as_ref().map_or(Ok(()), |c| coverage(s, c)),
        fit,
        frames,
        diagnostics,
        errors,
    ];
    for section in sections {
        let _ = section(&mut s, r);
    }
    s
}

/// The comparison of a model with the simpler one it contains, after `lead`: its score
/// difference (`difference`, in words) and whether it beats it.
fn nested_text(
    n: Option<&NestedComparison>,
    lead: &str,
    difference: fn(f64, f64) -> String,
) -> String {
    n.map_or_else(String::new, |n| {
        let (d, e) = n.difference;
        let words = beats_words(n.beats);
        format!(
            "{lead}against {}, which it contains: {}, {words}",
            n.contains,
            difference(d, e)
        )
    })
}

/// The model choice by cross-validation (sockets and haptic logs): each model's held-out
/// RMS and squared error minus the geometric model's.
fn cross_validation(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    if r.cross_validation.is_empty() {
        return Ok(());
    }
    let z = LADDER_SIGNIFICANCE_Z;
    writeln!(
        s,
        "\nmodel choice by {}-fold cross-validation on {} (held-out RMS; held-out squared \
         error minus the geometric model's, ± its standard error; a model is taken only if \
         it beats the one chosen below it by {z} standard errors):",
        r.folds,
        judged_rows(r),
    )?;
    // The names' column as wide as the longest (mass-compliance-harmonic).
    let width = (r.cross_validation.iter())
        .map(|cv| cv.model.to_string().len())
        .max()
        .unwrap_or(0);
    let bottom = r.cross_validation.first().map(|cv| cv.model);
    let um2 = |d: f64, e: f64| format!("{:+.0} ± {:.0} µm²", d * 1e12, e * 1e12);
    for cv in &r.cross_validation {
        let (diff, se) = cv.difference_to_geometric_m2;
        // A rung above the second level was compared with the rung chosen below it, which
        // need not be the bottom one: that comparison decided, so it is shown.
        let against = match (cv.compared_with, bottom) {
            (Some(m), Some(b)) if m != b => {
                let (d, e) = cv.difference_to_compared_m2;
                let beats = if cv.beats_geometric {
                    format!("  beats {b}")
                } else {
                    String::new()
                };
                let words = beats_words(d + z * e < 0.0);
                format!("{beats}; against {m}: {}, {words}", um2(d, e))
            }
            _ if cv.beats_geometric => "  beats".to_owned(),
            _ => String::new(),
        };
        let nested = nested_text(cv.nested.as_ref(), "; ", um2);
        writeln!(
            s,
            "  {:<width$} {:>9.4} mm {:>+10.0} ± {:<8.0} µm²{against}{nested}",
            cv.model.to_string(),
            cv.heldout_rms_m * 1e3,
            diff * 1e12,
            se * 1e12,
        )?;
    }
    Ok(())
}

/// The model ladder of measurement files: each rung's held-out RMS and weighted squared
/// error minus frames only's, and on the joint-range folds.
fn ladder(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    if r.ladder.is_empty() {
        return Ok(());
    }
    writeln!(
        s,
        "\nmodel ladder by {}-fold blocked cross-validation on {} (held-out position RMS; \
         held-out weighted squared error per row, Σ e²/σ², minus frames only's, ± its \
         standard error; a rung is taken only if it beats the one chosen below it by {} \
         standard errors):",
        r.folds,
        // A long file's ladder is judged on a sample of its training rows.
        match r.cross_validated_rows {
            None => "the training rows".to_owned(),
            Some(_) => judged_rows(r),
        },
        LADDER_SIGNIFICANCE_Z
    )?;
    let width = (r.ladder.iter())
        .map(|l| l.rung.to_string().len())
        .max()
        .unwrap_or(0);
    if r.ladder.iter().any(|l| l.range_rms_m.is_some()) {
        writeln!(
            s,
            "  (then, on the joint-range folds below: held-out position RMS, and weighted \
             squared error per row minus frames only's)"
        )?;
    }
    for l in &r.ladder {
        let (diff, se) = l.score_difference_to_frames;
        let range = l.range_rms_m.map_or_else(String::new, |rms| {
            format!(
                "   {:>9.4} mm {:>+9.2}",
                rms * 1e3,
                l.range_difference_to_frames
            )
        });
        let nested = nested_text(l.nested.as_ref(), "   ", |d, e| format!("{d:+.2} ± {e:.2}"));
        writeln!(
            s,
            "  {:<width$} {:>9.4} mm {:>+9.2} ± {:<7.2}{range}{nested}",
            l.rung.to_string(),
            l.heldout_rms_m * 1e3,
            diff,
            se
        )?;
    }
    Ok(())
}

/// A parameter's cells as both reports show them: name, value and σ scaled to a readable
/// unit ([`scaled`], 4 decimals), that unit.
pub(crate) fn parameter_cells(p: &ParamReport) -> [String; 4] {
    let (v, unit) = scaled(p.value, p.unit);
    let (sd, _) = scaled(p.std, p.unit);
    [
        p.name.clone(),
        format!("{v:+.4}"),
        format!("{sd:.4}"),
        unit.to_owned(),
    ]
}

/// The model taken and the fit's end, the identified parameters and the pruned ones.
fn fit(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    writeln!(
        s,
        "\nmodel: {}; sigma = {:.4} mm (from {}); LM: {}; back end {}",
        r.model,
        r.sigma_m * 1e3,
        r.sigma_source,
        hapcal_calibrate::fit::termination_text(&r.termination),
        r.backend
    )?;
    let n = r.parameters.len();
    writeln!(s, "\nidentified ({n} parameters, value ± std):")?;
    for p in &r.parameters {
        let [name, v, sd, unit] = parameter_cells(p);
        writeln!(s, "  {name:<28} {v:>10} ± {sd:<8} {unit}")?;
    }
    let n = r.pruned.len();
    writeln!(
        s,
        "\npruned ({n} parameters, not identifiable from these data):"
    )?;
    for p in &r.pruned {
        writeln!(s, "  {:<28} {}", p.name, pruned_why(p))?;
    }
    Ok(())
}

/// The identified frames (instrument, markers): position in mm, roll, pitch, yaw in degrees.
fn frames(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    if r.frames.is_empty() {
        return Ok(());
    }
    writeln!(s, "\nframes (xyz mm; roll, pitch, yaw deg):")?;
    for f in &r.frames {
        let [x, y, z] = f.xyz_m.map(|v| v * 1e3);
        let [a, b, c] = f.rpy_rad.map(f64::to_degrees);
        let name = &f.name;
        writeln!(
            s,
            "  {name:<12} {x:>10.3} {y:>10.3} {z:>10.3}   {a:>9.4} {b:>9.4} {c:>9.4}"
        )?;
    }
    Ok(())
}

/// What qualifies the fit: correlated pairs, observability, the rows the Huber loss
/// bounded, the torque equilibrium, the warnings.
fn diagnostics(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    if !r.correlated.is_empty() {
        writeln!(s, "\nstrongly correlated pairs (|corr| > 0.95):")?;
        for (a, b, c) in &r.correlated {
            writeln!(s, "  {a} ~ {b}: {c:+.3}")?;
        }
    }
    if let Some(o) = &r.observability {
        writeln!(
            s,
            "\nobservability of the scaled Jacobian ({} parameters, {} poses): O1 = {:.4e}, O2 = {:.4e} (condition number {:.1}), O3 = {:.4e}, O4 = {:.4e}, O5 = {:.4e}",
            o.n_params, o.n_poses, o.o1, o.o2, o.condition_number, o.o3, o.o4, o.o5
        )?;
    }
    if !r.downweighted.is_empty() {
        writeln!(
            s,
            "\nbounded by the Huber loss (residual as measured → what the fit saw, mm):"
        )?;
        for d in &r.downweighted {
            let (e, bound) = (d.residual_m * 1e3, d.bound_m * 1e3);
            writeln!(s, "  {}  {e:.3} → {bound:.3}", d.place())?;
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
        let why = if step > hapcal_calibrate::measured::EQUILIBRIUM_SHARE * r.sigma_m {
            " (see the warnings)"
        } else if r.equilibrium_refits > 0 {
            ""
        } else {
            " (the loads of the undeflected robot suffice)"
        };
        writeln!(
            s,
            "\ntorque equilibrium: {solved}one more fixed-point step would move the tips by at \
             most {:.4} mm{why}",
            step * 1e3
        )?;
    }
    if !r.warnings.is_empty() {
        writeln!(s, "\nwarnings:")?;
        for w in &r.warnings {
            writeln!(s, "  - {w}")?;
        }
    }
    Ok(())
}

/// Each set's errors before and after: of marker data ([`pose_errors`]), of a haptic
/// device's logs ([`log_distances`]) or of socket placements ([`socket_figures`]).
fn errors(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    if r.placements.iter().any(|p| p.before.pose.is_some()) {
        pose_errors(s, r)
    } else if (r.placements.iter()).all(|p| {
        p.before.mean_absolute_error_m.is_none()
            && p.before.distance_error_m.is_none()
            && p.after.mean_absolute_error_m.is_none()
            && p.after.distance_error_m.is_none()
    }) {
        log_distances(s, r)
    } else {
        socket_figures(s, r)
    }
}

/// Mean, RMS and largest of one error, before and after, as `mean / RMS / max → …` (each
/// times `scale`), if both are known.
fn spread(
    before: [Option<f64>; 3],
    after: [Option<f64>; 3],
    scale: fn(f64) -> f64,
) -> Option<String> {
    let text = |v: [Option<f64>; 3]| -> Option<String> {
        Some(format!(
            "{:.3} / {:.3} / {:.3}",
            scale(v[0]?),
            scale(v[1]?),
            scale(v[2]?)
        ))
    };
    Some(format!("{} → {}", text(before)?, text(after)?))
}

/// Marker data: each set's position, distance and orientation errors, mean / RMS / max,
/// frames only → calibrated.
fn pose_errors(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    writeln!(
        s,
        "\nposition error (mm), orientation error (deg), distance error (mm): mean / RMS / max, frames only → calibrated"
    )?;
    let mm = |v: f64| v * 1e3;
    for p in &r.placements {
        let (Some(b), Some(a)) = (p.before.pose, p.after.pose) else {
            continue;
        };
        let position =
            |f: PoseFigures| [f.position_mean_m, f.position_rms_m, f.position_max_m].map(Some);
        let distance = |f: PoseFigures| [f.distance_mean_m, f.distance_rms_m, f.distance_max_m];
        let orientation = |f: PoseFigures| {
            [
                f.orientation_mean_rad,
                f.orientation_rms_rad,
                f.orientation_max_rad,
            ]
        };
        let distance_only = b.distance_rms_m.is_some() && b.position_rms_m == 0.0;
        if !distance_only {
            let text = spread(position(b), position(a), mm).unwrap_or_default();
            let (name, role, n) = (&p.name, &p.role, p.n_rows);
            writeln!(s, "  {name:<24} {role:<5} {n:>4}  position {text}")?;
        }
        if let Some(text) = spread(distance(b), distance(a), mm) {
            let (name, role, n) = if distance_only {
                (p.name.as_str(), p.role.to_string(), p.n_rows.to_string())
            } else {
                ("", String::new(), String::new())
            };
            writeln!(s, "  {name:<24} {role:<5} {n:>4}  distance {text}")?;
        }
        if let Some(text) = spread(orientation(b), orientation(a), f64::to_degrees) {
            writeln!(s, "  {:<24} {:<5} {:>4}  orientation {text}", "", "", "")?;
        }
    }
    Ok(())
}

/// A haptic device's logs: the cable distance's RMS before and after.
fn log_distances(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    writeln!(
        s,
        "\ndistance RMS (mm): the nominal model on the raw readings → the calibrated model"
    )?;
    let row = |s: &mut String, cells: [&str; 5]| {
        let [name, role, n, before, after] = cells;
        writeln!(s, "  {name:<16} {role:<5} {n:>4}  {before:>10} {after:>10}")
    };
    row(s, ["log", "role", "rows", "before", "after"])?;
    for p in &r.placements {
        let (role, n) = (p.role.to_string(), p.n_rows.to_string());
        let (before, after) = (mm(p.before.distance_rms_m), mm(p.after.distance_rms_m));
        row(s, [&p.name, &role, &n, &before, &after])?;
    }
    Ok(())
}

/// Socket placements: MUKCa's consistency and distortion and the distance RMS, before and
/// after.
fn socket_figures(s: &mut String, r: &CalibrationReport) -> fmt::Result {
    writeln!(
        s,
        "\nfigures of merit (mm): MAE = mean absolute error to the socket mean, dist = socket distance error"
    )?;
    let row = |s: &mut String, c: [&str; 9]| {
        writeln!(
            s,
            "  {:<16} {:<5} {:>4}  {:>10} {:>10} {:>10}  {:>10} {:>10} {:>10}",
            c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
        )
    };
    row(
        s,
        [
            "placement",
            "role",
            "rows",
            "MAE before",
            "dist bef.",
            "rms before",
            "MAE after",
            "dist after",
            "rms after",
        ],
    )?;
    for p in &r.placements {
        let (role, n) = (p.role.to_string(), p.n_rows.to_string());
        let [b, a] = [&p.before, &p.after].map(figures_cells);
        row(
            s,
            [&p.name, &role, &n, &b[0], &b[1], &b[2], &a[0], &a[1], &a[2]],
        )?;
    }
    Ok(())
}
