//! The HTML report of `hapcal calibrate`, from the typed [`CalibrationReport`].

use hapcal_calibrate::report::{CalibrationReport, SetReport, SetRole};

use super::Page;
use super::figures::{
    self, BLUE_, BarGroup, Binned, Figure, GREY, ORANGE, Panel, Points, RangeRow, Samples,
};
use hapcal_io::InputFile;

/// Bins of the residual-against-joint figure.
const JOINT_BINS: usize = 8;
/// Fewest samples a bin of the residual-against-joint figure needs to be drawn.
const MIN_BIN_SAMPLES: usize = 3;

/// The HTML report of a calibration: what made it (`command`, `inputs`), the model ladder,
/// the residuals before and after (per row, as histograms, per set and marker, against each
/// joint's reading), the joints' training ranges against the test rows and the workspace,
/// the parameters with σ, the pruned ones and the correlated pairs, the warnings and the text
/// report's words.
pub fn calibration_page(r: &CalibrationReport, command: &str, inputs: &[InputFile]) -> String {
    let mut page = Page::new(&format!("hapcal calibrate: {}", r.device), command, inputs);
    page.section("summary", "Result");
    page.paragraph(&format!(
        "Model taken: {}. Residual noise σ = {:.4} mm (from {}). Fit: {}.",
        r.model,
        r.sigma_m * 1e3,
        r.sigma_source,
        hapcal_calibrate::fit::termination_text(&r.termination)
    ));
    if !r.warnings.is_empty() {
        page.section("warnings", "Warnings");
        page.list("warnings", &r.warnings);
    }
    for f in figures(r) {
        if f.id == "fig-ladder" {
            page.section("ladder", "Model ladder");
            page.paragraph(&ladder_why(r));
        }
        if f.id == "fig-sets" {
            page.section("residuals", "Residuals before and after");
        }
        if f.id == "fig-ranges" {
            page.section("coverage", "Training ranges, test rows and workspace");
        }
        if f.id == "fig-parameters" {
            page.section("parameters", "Identified parameters");
        }
        page.figure(&f);
    }
    tables(r, &mut page);
    page.finish_with_text("hapcal calibrate", &crate::report::render_results(r))
}

/// Why the rung was taken, in words.
fn ladder_why(r: &CalibrationReport) -> String {
    let z = hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z;
    if r.ladder.is_empty() && r.cross_validation.is_empty() {
        return format!("The model was given: {}.", r.model);
    }
    format!(
        "Taken: {}. Scores by {}-fold cross-validation on {}; a rung is taken only if its \
         held-out error beats the rung chosen below it by {z} standard errors{}.",
        r.model,
        r.folds,
        crate::report::judged_rows(r),
        if r.coverage.as_ref().is_some_and(|c| !c.stopped.is_empty()) {
            ", and on the joint-range folds where the calibration must extrapolate (see the \
             text report)"
        } else {
            ""
        }
    )
}

/// Every figure that applies to `r`, in the page's order (ids `fig-ladder`, `fig-ladder-rms`,
/// `fig-sets`, `fig-residual-rows`, `fig-histograms`, `fig-markers`, `fig-residual-joint`,
/// `fig-ranges`, `fig-parameters`).
pub fn figures(r: &CalibrationReport) -> Vec<Figure> {
    let mut out = Vec::new();
    ladder(r, &mut out);
    sets(r, &mut out);
    samples(r, &mut out);
    ranges(r, &mut out);
    if !r.parameters.is_empty() {
        let names: Vec<String> = r.parameters.iter().map(|p| p.name.clone()).collect();
        let z: Vec<f64> = (r.parameters.iter())
            .map(|p| if p.std > 0.0 { p.value / p.std } else { 0.0 })
            .collect();
        out.push(figures::hbars(
            "fig-parameters",
            "Each identified parameter's value in units of its standard deviation σ (value / σ); \
             dashed: ±2 σ, bars inside them (grey) are not distinguished from zero by the data."
                .to_owned(),
            "value / σ",
            &names,
            &z,
            2.0,
        ));
    }
    out
}

/// One rung of the model choice as the HTML report shows it: of the ladder of measurement
/// files, or of the cross-validation of sockets and haptic logs.
struct Score {
    /// The rung's (or model's) name.
    name: String,
    /// Held-out RMS, mm.
    rms_mm: f64,
    /// Held-out score minus the bottom rung's, and its standard error: weighted squared
    /// error per row (the ladder), or squared error in mm² (the cross-validation).
    diff: (f64, f64),
    /// RMS on the joint-range folds, m (the ladder's, if any).
    range_rms_m: Option<f64>,
    /// Kept parameters.
    n_kept: usize,
}

/// The model choice's scores, and whether they are the ladder's (else the
/// cross-validation's); `None` without either.
fn scores(r: &CalibrationReport) -> Option<(bool, Vec<Score>)> {
    if !r.ladder.is_empty() {
        let rows = (r.ladder.iter()).map(|l| Score {
            name: l.rung.to_string(),
            rms_mm: l.heldout_rms_m * 1e3,
            diff: l.score_difference_to_frames,
            range_rms_m: l.range_rms_m,
            n_kept: l.n_kept,
        });
        return Some((true, rows.collect()));
    }
    let rows = (r.cross_validation.iter()).map(|c| Score {
        name: c.model.to_string(),
        rms_mm: c.heldout_rms_m * 1e3,
        diff: (
            c.difference_to_geometric_m2.0 * 1e6,
            c.difference_to_geometric_m2.1 * 1e6,
        ),
        range_rms_m: None,
        n_kept: c.n_kept,
    });
    (!r.cross_validation.is_empty()).then(|| (false, rows.collect()))
}

/// The ladder's figures: each rung's held-out score difference ± its standard error, and its
/// held-out RMS.
fn ladder(r: &CalibrationReport, out: &mut Vec<Figure>) {
    let Some((is_ladder, scores)) = scores(r) else {
        return;
    };
    let (y_desc, what) = if is_ladder {
        (
            "Σ e²/σ² per row minus frames only's",
            "held-out weighted squared error per row minus frames only's",
        )
    } else {
        (
            "mm² minus the geometric model's",
            "held-out squared error minus the geometric model's, mm²",
        )
    };
    let names: Vec<String> = scores.iter().map(|x| x.name.clone()).collect();
    let taken = names.iter().position(|n| *n == r.model.to_string());
    let group = |values: Vec<f64>, errors| {
        [BarGroup {
            label: String::new(),
            color: BLUE_,
            values: values.into_iter().map(Some).collect(),
            errors,
        }]
    };
    let diff = scores.iter().map(|x| x.diff.0).collect();
    let se = scores.iter().map(|x| x.diff.1).collect();
    out.push(figures::bars(
        "fig-ladder",
        format!(
            "Model ladder: each rung's {what}, ± its standard error (blocked folds); lower is \
             better. Taken: {}.",
            r.model
        ),
        y_desc,
        &names,
        &group(diff, Some(se)),
        taken,
    ));
    out.push(figures::bars(
        "fig-ladder-rms",
        "Model ladder: each rung's held-out RMS error over all folds, mm.".to_owned(),
        "held-out RMS, mm",
        &names,
        &group(scores.iter().map(|x| x.rms_mm).collect(), None),
        taken,
    ));
}

/// The table of the model choice's scores (the ladder's, or the cross-validation's).
fn score_table(r: &CalibrationReport, page: &mut Page) {
    let Some((is_ladder, scores)) = scores(r) else {
        return;
    };
    let rows: Vec<Vec<String>> = (scores.iter())
        .map(|x| {
            let (d, e) = x.diff;
            let mut row = vec![x.name.clone(), format!("{:.4}", x.rms_mm)];
            if is_ladder {
                row.push(format!("{d:+.2} ± {e:.2}"));
                row.push(
                    x.range_rms_m
                        .map_or_else(|| "–".to_owned(), |v| format!("{:.4}", v * 1e3)),
                );
            } else {
                row.push(format!("{d:+.4} ± {e:.4}"));
            }
            row.push(x.n_kept.to_string());
            row
        })
        .collect();
    if is_ladder {
        page.section("ladder-table", "Ladder scores");
        let head = [
            "rung",
            "held-out RMS, mm",
            "Σe²/σ² per row minus frames only's",
            "joint-range folds RMS, mm",
            "kept parameters",
        ];
        page.table(&head, &rows);
    } else {
        page.section("ladder-table", "Cross-validation scores");
        let head = [
            "model",
            "held-out RMS, mm",
            "minus the geometric model's, mm²",
            "kept parameters",
        ];
        page.table(&head, &rows);
    }
}

/// The per-set figure: each set's error before and after calibration.
fn sets(r: &CalibrationReport, out: &mut Vec<Figure>) {
    if r.placements.is_empty() {
        return;
    }
    let names: Vec<String> = (r.placements.iter())
        .map(|p| format!("{} ({})", p.name, role_word(p.role)))
        .collect();
    let pose = r.placements.iter().any(|p| p.before.pose.is_some());
    let (groups, y_desc, what) = if pose {
        let rms = |before: bool| -> Vec<Option<f64>> {
            (r.placements.iter())
                .map(|p| {
                    let f = if before { &p.before } else { &p.after };
                    f.pose.map(|f| f.position_rms_m * 1e3)
                })
                .collect()
        };
        (
            vec![
                BarGroup {
                    label: "frames only".to_owned(),
                    color: GREY,
                    values: rms(true),
                    errors: None,
                },
                BarGroup {
                    label: format!("calibrated ({})", r.model),
                    color: BLUE_,
                    values: rms(false),
                    errors: None,
                },
            ],
            "position RMS, mm",
            "3-D position RMS error",
        )
    } else {
        let get = |before: bool,
                   f: fn(&hapcal_calibrate::report::Figures) -> Option<f64>|
         -> Vec<Option<f64>> {
            (r.placements.iter())
                .map(|p| f(if before { &p.before } else { &p.after }).map(|v| v * 1e3))
                .collect()
        };
        let mut groups = Vec::new();
        type Pick = fn(&hapcal_calibrate::report::Figures) -> Option<f64>;
        let kinds: [(&str, Pick); 3] = [
            ("mean absolute error", |f| f.mean_absolute_error_m),
            ("distance error", |f| f.distance_error_m),
            ("distance RMS", |f| f.distance_rms_m),
        ];
        for (label, f) in kinds {
            let (b, a) = (get(true, f), get(false, f));
            if b.iter().chain(&a).any(Option::is_some) {
                groups.push(BarGroup {
                    label: format!("{label}, nominal"),
                    color: GREY,
                    values: b,
                    errors: None,
                });
                groups.push(BarGroup {
                    label: format!("{label}, calibrated"),
                    color: if groups.len() < 2 { BLUE_ } else { ORANGE },
                    values: a,
                    errors: None,
                });
            }
        }
        (
            groups,
            "mm",
            "errors (MUKCa consistency and distortion, distance RMS)",
        )
    };
    if groups.is_empty() {
        return;
    }
    out.push(figures::bars(
        "fig-sets",
        format!("Each data set's {what} before and after calibration (training sets are fitted, test sets only evaluated)."),
        y_desc,
        &names,
        &groups,
        None,
    ));
}

/// `training` or `test`.
fn role_word(role: SetRole) -> &'static str {
    match role {
        SetRole::Train => "training",
        SetRole::Test => "test",
    }
}

/// One sample's error, frames only and calibrated, with where it comes from.
struct Sample<'a> {
    /// The set.
    set: &'a SetReport,
    /// Row index in recording order over all sets.
    row: usize,
    /// The row's joint readings.
    q: &'a [f64],
    /// Marker (0-based), or `None` for a distance sample.
    marker: Option<usize>,
    /// Error frames only and calibrated, m (absolute for distances).
    before: f64,
    /// Calibrated.
    after: f64,
}

/// Every sample of every set, in recording order (sets in the report's order).
fn all_samples(r: &CalibrationReport) -> Vec<Sample<'_>> {
    let mut out = Vec::new();
    let mut row0 = 0;
    for set in &r.placements {
        let Some(e) = &set.errors else { continue };
        let (mut k, mut d) = (0, 0);
        for (i, row) in e.rows.iter().enumerate() {
            if row.distance {
                if let (Some(b), Some(a)) = (e.distance_before_m.get(d), e.distance_after_m.get(d))
                {
                    out.push(Sample {
                        set,
                        row: row0 + i,
                        q: &row.q,
                        marker: None,
                        before: b.abs(),
                        after: a.abs(),
                    });
                }
                d += 1;
            }
            for &m in &row.markers {
                if let (Some(b), Some(a)) = (e.position_before_m.get(k), e.position_after_m.get(k))
                {
                    out.push(Sample {
                        set,
                        row: row0 + i,
                        q: &row.q,
                        marker: Some(m),
                        before: *b,
                        after: *a,
                    });
                }
                k += 1;
            }
        }
        row0 += e.rows.len();
    }
    out
}

/// The figures of the per-sample errors: per row, histograms, per set and marker, against
/// each joint.
fn samples(r: &CalibrationReport, out: &mut Vec<Figure>) {
    let s = all_samples(r);
    if s.is_empty() {
        return;
    }
    let positions = s.iter().any(|x| x.marker.is_some());
    let what = if positions {
        "3-D position error"
    } else {
        "absolute distance error"
    };
    let pick = |role: SetRole, after: bool| -> Vec<(f64, f64)> {
        (s.iter().filter(|x| x.set.role == role))
            .map(|x| (x.row as f64, 1e3 * if after { x.after } else { x.before }))
            .collect()
    };
    let before: Vec<(f64, f64)> = s.iter().map(|x| (x.row as f64, x.before * 1e3)).collect();
    let mut series = vec![Points {
        label: "frames only".to_owned(),
        color: GREY,
        points: before,
    }];
    for (role, color) in [(SetRole::Train, BLUE_), (SetRole::Test, ORANGE)] {
        let p = pick(role, true);
        if !p.is_empty() {
            series.push(Points {
                label: format!("calibrated, {}", role_word(role)),
                color,
                points: p,
            });
        }
    }
    out.push(figures::scatter(
        "fig-residual-rows",
        format!(
            "The {what} of every sample, in recording order (rows of the sets one after the \
             other, training first), frames only and calibrated ({})",
            r.model
        ),
        "row",
        &format!("{what}, mm"),
        &series,
    ));
    let mut panels = Vec::new();
    for role in [SetRole::Train, SetRole::Test] {
        let v: Vec<&Sample> = s.iter().filter(|x| x.set.role == role).collect();
        if v.is_empty() {
            continue;
        }
        panels.push(Panel {
            title: format!("{} rows", role_word(role)),
            series: vec![
                Samples {
                    label: "frames only".to_owned(),
                    color: GREY,
                    values: v.iter().map(|x| x.before * 1e3).collect(),
                },
                Samples {
                    label: "calibrated".to_owned(),
                    color: BLUE_,
                    values: v.iter().map(|x| x.after * 1e3).collect(),
                },
            ],
        });
    }
    out.push(figures::histograms(
        "fig-histograms",
        format!("Histograms of the {what}, frames only and calibrated, per set."),
        &format!("{what}, mm"),
        &panels,
    ));
    // Per set and marker: RMS before and after.
    let mut keys: Vec<(usize, Option<usize>)> = Vec::new();
    let index_of = |set: &SetReport| {
        r.placements
            .iter()
            .position(|p| std::ptr::eq(p, set))
            .unwrap_or(0)
    };
    for x in &s {
        let key = (index_of(x.set), x.marker);
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let rms = |key: (usize, Option<usize>), after: bool| -> Option<f64> {
        let v: Vec<f64> = (s.iter())
            .filter(|x| (index_of(x.set), x.marker) == key)
            .map(|x| if after { x.after } else { x.before })
            .collect();
        (!v.is_empty())
            .then(|| 1e3 * (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt())
    };
    let names: Vec<String> = (keys.iter())
        .map(|&(set, marker)| {
            let p = &r.placements[set];
            match marker {
                Some(m) => format!("{} marker {}", role_word(p.role), m + 1),
                None => format!("{} distance", role_word(p.role)),
            }
        })
        .collect();
    out.push(figures::bars(
        "fig-markers",
        format!("RMS of the {what} per set and marker, frames only and calibrated."),
        "RMS, mm",
        &names,
        &[
            BarGroup {
                label: "frames only".to_owned(),
                color: GREY,
                values: keys.iter().map(|&k| rms(k, false)).collect(),
                errors: None,
            },
            BarGroup {
                label: "calibrated".to_owned(),
                color: BLUE_,
                values: keys.iter().map(|&k| rms(k, true)).collect(),
                errors: None,
            },
        ],
        None,
    ));
    joints(r, &s, what, out);
}

/// The joints of the report's sample rows (name, unit).
fn joint_list(r: &CalibrationReport) -> &[(String, &'static str)] {
    (r.placements.iter())
        .filter_map(|p| p.errors.as_ref())
        .map(|e| e.joints.as_slice())
        .find(|j| !j.is_empty())
        .unwrap_or(&[])
}

/// Residual against each joint's reading: binned means of every sample, frames only and
/// calibrated, with the interval mean ± 2 standard errors.
fn joints(r: &CalibrationReport, s: &[Sample<'_>], what: &str, out: &mut Vec<Figure>) {
    let joints = joint_list(r);
    let mut panels = Vec::new();
    let mut units = Vec::new();
    for (j, (name, unit)) in joints.iter().enumerate() {
        let q: Vec<f64> = s.iter().filter_map(|x| x.q.get(j).copied()).collect();
        let (lo, hi) = q
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        if !(hi - lo).is_finite() || hi <= lo {
            continue;
        }
        let width = (hi - lo) / JOINT_BINS as f64;
        let series = [(false, "frames only", GREY), (true, "calibrated", BLUE_)].map(
            |(after, label, color)| {
                let mut bins = Vec::new();
                for b in 0..JOINT_BINS {
                    let v: Vec<f64> = (s.iter())
                        .filter(|x| {
                            x.q.get(j).is_some_and(|&qj| {
                                ((((qj - lo) / width) as usize).min(JOINT_BINS - 1)) == b
                            })
                        })
                        .map(|x| 1e3 * if after { x.after } else { x.before })
                        .collect();
                    if v.len() < MIN_BIN_SAMPLES {
                        continue;
                    }
                    let n = v.len() as f64;
                    let mean = v.iter().sum::<f64>() / n;
                    let sd = (v.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
                    let half = 2.0 * sd / n.sqrt();
                    bins.push((
                        lo + (b as f64 + 0.5) * width,
                        mean,
                        mean - half,
                        mean + half,
                    ));
                }
                Binned {
                    label: label.to_owned(),
                    color,
                    bins,
                }
            },
        );
        panels.push(Panel {
            title: format!("{name} ({unit})"),
            series: series.to_vec(),
        });
        units.push(*unit);
    }
    if panels.is_empty() {
        return;
    }
    out.push(figures::binned_panels(
        "fig-residual-joint",
        format!(
            "The {what} against each joint's reading: mean over the samples of each of {JOINT_BINS} \
             bins of the reading (all sets), ± 2 standard errors; grey frames only, blue \
             calibrated. A trend in the calibrated means is an effect of that joint the model \
             lacks."
        ),
        &format!("mean {what}, mm"),
        &units,
        &panels,
    ));
}

/// Each joint's training range against the test rows and the workspace.
fn ranges(r: &CalibrationReport, out: &mut Vec<Figure>) {
    let joints = joint_list(r);
    if joints.is_empty() {
        return;
    }
    let rows_of = |role: SetRole| -> Vec<&[f64]> {
        (r.placements.iter().filter(|p| p.role == role))
            .filter_map(|p| p.errors.as_ref())
            .flat_map(|e| e.rows.iter().map(|row| &row.q[..]))
            .collect()
    };
    let (train, test) = (rows_of(SetRole::Train), rows_of(SetRole::Test));
    let workspace: Vec<&[f64]> = (r.coverage.iter())
        .flat_map(|c| c.workspace_q.iter().map(Vec::as_slice))
        .collect();
    let rows: Vec<RangeRow> = (joints.iter().enumerate())
        .filter_map(|(j, (name, unit))| {
            let t: Vec<f64> = train.iter().filter_map(|q| q.get(j).copied()).collect();
            let lo = t.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = t.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (lo <= hi).then(|| RangeRow {
                label: format!("{name}, {unit}"),
                training: (lo, hi),
                test: test.iter().filter_map(|q| q.get(j).copied()).collect(),
                workspace: workspace.iter().filter_map(|q| q.get(j).copied()).collect(),
            })
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    out.push(figures::ranges(
        "fig-ranges",
        "Each joint's training range (bar; its ends in the label) with the readings of the test \
         rows (orange, above) and of the --workspace configurations (green, below): outside the \
         bar the calibration extrapolates."
            .to_owned(),
        &rows,
    ));
}

/// The tables: ladder scores, parameters with σ, pruned ones, correlated pairs.
fn tables(r: &CalibrationReport, page: &mut Page) {
    score_table(r, page);
    page.section("parameter-table", "Parameters");
    let rows: Vec<Vec<String>> = (r.parameters.iter())
        .map(|p| crate::report::parameter_cells(p).to_vec())
        .collect();
    page.paragraph(&format!(
        "{} identified parameters (value and standard deviation σ):",
        r.parameters.len()
    ));
    if !rows.is_empty() {
        page.table(&["parameter", "value", "σ", "unit"], &rows);
    }
    page.paragraph(&format!(
        "{} pruned parameters (not identifiable from these data):",
        r.pruned.len()
    ));
    if !r.pruned.is_empty() {
        let rows: Vec<Vec<String>> = (r.pruned.iter())
            .map(|p| vec![p.name.clone(), crate::report::pruned_why(p)])
            .collect();
        page.table(&["parameter", "why pruned"], &rows);
    }
    if r.correlated.is_empty() {
        page.paragraph("No pair of kept parameters is correlated beyond |0.95|.");
    } else {
        page.paragraph("Strongly correlated pairs of kept parameters (|correlation| > 0.95):");
        let rows: Vec<Vec<String>> = (r.correlated.iter())
            .map(|(a, b, c)| vec![a.clone(), b.clone(), format!("{c:+.3}")])
            .collect();
        page.table(&["parameter", "parameter", "correlation"], &rows);
    }
}
