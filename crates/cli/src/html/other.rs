//! The HTML reports of `hapcal diagnose` and `hapcal predict`, from their typed reports.

use hapcal_diagnose::Diagnosis;
use hapcal_diagnose::arm::ArmDiagnosis;

use super::Page;
use super::figures::{self, BLUE_, BarGroup, Figure, GREY, Points, RED_};
use hapcal_calibrate::predict::Prediction;
use hapcal_io::InputFile;

/// A diagnosis as its HTML report shows it, whichever the device: the gap, the candidates of
/// every round, the accepted effects, the verdict, the residual maps and the text report.
#[derive(Clone, Debug)]
pub struct DiagnosisView {
    /// The verdict in words.
    pub verdict: String,
    /// Held-out RMS of the baseline and after the accepted effects, m.
    pub heldout_rms_m: (f64, f64),
    /// Floor of the held-out RMS, m, if any.
    pub floor_rms_m: Option<f64>,
    /// The gap above the floor, m, and the share of it the accepted effects closed, %.
    pub gap: (f64, f64),
    /// Every candidate: round, effect, held-out RMS before and after (m), gap closed (%),
    /// accepted, reason.
    pub candidates: Vec<(usize, String, f64, f64, f64, bool, String)>,
    /// The accepted effects in order: effect, held-out RMS before and after (m), gap closed (%).
    pub steps: Vec<(String, f64, f64, f64)>,
    /// Things the user should know.
    pub notes: Vec<String>,
}

/// The view of a diagnosis `$d` (haptic or arm: the same fields by name) whose floor is
/// `$floor`.
macro_rules! view_of {
    ($d:expr, $floor:expr) => {{
        let d = $d;
        DiagnosisView {
            verdict: d.verdict.to_string(),
            heldout_rms_m: (d.heldout_rms_m, d.heldout_rms_final_m),
            floor_rms_m: $floor,
            gap: (d.gap_rms_m, d.gap_closed_pct),
            candidates: (d.candidates.iter())
                .map(|c| {
                    let (b, a) = (c.heldout_rms_before_m, c.heldout_rms_after_m);
                    (
                        c.round,
                        c.effect.name().to_owned(),
                        b,
                        a,
                        c.gap_closed_pct,
                        c.accepted,
                        c.reason.clone(),
                    )
                })
                .collect(),
            steps: (d.steps.iter())
                .map(|s| {
                    (
                        s.effect.name().to_owned(),
                        s.heldout_rms_before_m,
                        s.heldout_rms_after_m,
                        s.gap_closed_pct,
                    )
                })
                .collect(),
            notes: d.notes.clone(),
        }
    }};
}

impl DiagnosisView {
    /// A haptic device's diagnosis.
    pub fn haptic(d: &Diagnosis) -> DiagnosisView {
        view_of!(d, Some(d.floor_rms_m))
    }

    /// The view with the diagnosis' `warnings` (as the command prints them) before its notes.
    pub fn with_warnings(mut self, warnings: Vec<String>) -> DiagnosisView {
        self.notes.splice(0..0, warnings);
        self
    }

    /// A serial arm's diagnosis.
    pub fn arm(d: &ArmDiagnosis) -> DiagnosisView {
        view_of!(d, d.floor_rms_m)
    }
}

/// The HTML report of a diagnosis: the verdict, how far each accepted effect shrinks the gap,
/// the candidates, the residual maps (`maps_svg`), the notes and the text report (`text`).
pub fn diagnosis_page(
    view: &DiagnosisView,
    text: &str,
    maps_svg: &str,
    command: &str,
    inputs: &[InputFile],
) -> String {
    let mut page = Page::new("hapcal diagnose", command, inputs);
    page.section("verdict", "Verdict");
    page.paragraph(&format!("Verdict: {}.", view.verdict));
    page.paragraph(&format!(
        "Held-out RMS {:.4} mm with the baseline, {:.4} mm with the accepted effects{}; the gap \
         above the floor is {:.4} mm, of which the accepted effects closed {:.0} %.",
        view.heldout_rms_m.0 * 1e3,
        view.heldout_rms_m.1 * 1e3,
        view.floor_rms_m
            .map_or_else(String::new, |f| format!(" (floor {:.4} mm)", f * 1e3)),
        view.gap.0 * 1e3,
        view.gap.1
    ));
    if !view.notes.is_empty() {
        page.section("warnings", "Warnings and notes");
        page.list("warnings", &view.notes);
    }
    for f in diagnosis_figures(view, maps_svg) {
        page.figure(&f);
    }
    page.section("candidates", "Candidates");
    let rows: Vec<Vec<String>> = (view.candidates.iter())
        .map(|(round, effect, b, a, closed, accepted, reason)| {
            vec![
                round.to_string(),
                effect.clone(),
                format!("{:.4}", b * 1e3),
                format!("{:.4}", a * 1e3),
                format!("{closed:.0}"),
                if *accepted { "yes" } else { "no" }.to_owned(),
                reason.clone(),
            ]
        })
        .collect();
    page.table(
        &[
            "round",
            "effect",
            "held-out RMS before, mm",
            "after, mm",
            "gap closed, %",
            "accepted",
            "why",
        ],
        &rows,
    );
    page.finish_with_text("hapcal diagnose", text)
}

/// The diagnosis' figures: the held-out RMS after each accepted effect (`fig-steps`), each
/// candidate's share of the gap closed (`fig-candidates`) and the residual maps (`fig-maps`).
pub fn diagnosis_figures(view: &DiagnosisView, maps_svg: &str) -> Vec<Figure> {
    let mut out = Vec::new();
    let mut names = vec!["baseline".to_owned()];
    let mut rms = vec![Some(view.heldout_rms_m.0 * 1e3)];
    for (effect, _, after, _) in &view.steps {
        names.push(format!("+ {effect}"));
        rms.push(Some(after * 1e3));
    }
    let mut groups = vec![BarGroup {
        label: "held-out RMS".to_owned(),
        color: BLUE_,
        values: rms,
        errors: None,
    }];
    if let Some(f) = view.floor_rms_m {
        groups.push(BarGroup {
            label: "noise floor".to_owned(),
            color: GREY,
            values: vec![Some(f * 1e3); names.len()],
            errors: None,
        });
    }
    out.push(figures::bars(
        "fig-steps",
        format!("Held-out RMS of the baseline and after each accepted effect, against the noise floor. Verdict: {}.", view.verdict),
        "held-out RMS, mm",
        &names,
        &groups,
        None,
    ));
    if !view.candidates.is_empty() {
        let names: Vec<String> = (view.candidates.iter())
            .map(|c| format!("{}: {}", c.0, c.1))
            .collect();
        let closed: Vec<f64> = view.candidates.iter().map(|c| c.4).collect();
        out.push(figures::hbars(
            "fig-candidates",
            "Share of the gap each candidate closes in its round (round: effect), %; blue: at \
             least 10 %."
                .to_owned(),
            "gap closed, %",
            &names,
            &closed,
            10.0,
        ));
    }
    out.push(figures::external(
        "fig-maps",
        "Residual maps: the baseline's held-out residual RMS per bin of each signal; red: above \
         the floor."
            .to_owned(),
        maps_svg.to_owned(),
        serde_json::Value::Null,
    ));
    out
}

/// The HTML report of a prediction: the errors against the measured columns, each row's
/// predicted 1σ with the rows outside the calibration's region, and those rows.
pub fn prediction_page(p: &Prediction, text: &str, command: &str, inputs: &[InputFile]) -> String {
    let mut page = Page::new(&format!("hapcal predict: {}", p.data), command, inputs);
    page.section("summary", "Prediction");
    page.paragraph(&format!(
        "{} rows predicted in the {} frame; uncertainty from {}; {} rows outside the \
         calibration's region.",
        p.rows.len(),
        p.frame,
        p.uncertainty,
        p.n_outside_region
    ));
    if let Some(note) = &p.uncertainty_note {
        page.paragraph(note);
    }
    if !p.warnings.is_empty() {
        page.section("warnings", "Warnings");
        page.list("warnings", &p.warnings);
    }
    if let Some(e) = &p.errors {
        page.section("errors", "Errors against the measured columns");
        let rows: Vec<Vec<String>> = (hapcal_calibrate::predict::error_kinds(e).into_iter())
            .map(|(what, f, unit, _)| {
                let [mean, rms, max] = [f.mean, f.rms, f.max].map(|v| format!("{:.4}", v * 1e3));
                vec![
                    what.to_owned(),
                    f.count.to_string(),
                    mean,
                    rms,
                    max,
                    unit.to_owned(),
                ]
            })
            .collect();
        page.table(
            &["error", "samples", "mean", "RMS", "largest", "unit"],
            &rows,
        );
    }
    for f in prediction_figures(p) {
        page.section("sigma", "Predicted uncertainty");
        page.figure(&f);
    }
    let outside: Vec<Vec<String>> = (p.rows.iter())
        .filter_map(|r| {
            r.outside_region.as_ref().map(|o| {
                vec![
                    r.line.to_string(),
                    o.joint.clone(),
                    format!("{:+.4}", o.past),
                ]
            })
        })
        .collect();
    page.section("outside", "Configurations outside the calibration's region");
    if outside.is_empty() {
        page.paragraph("Every row lies within the calibration's region.");
    } else {
        page.table(
            &[
                "line",
                "joint farthest past its range",
                "past the range (rad, m if prismatic)",
            ],
            &outside,
        );
    }
    page.finish_with_text("hapcal predict", text)
}

/// The prediction's figure: each row's predicted 1σ of the first tip's position against its
/// line, rows outside the region in red (`fig-sigma`); none without σ.
pub fn prediction_figures(p: &Prediction) -> Vec<Figure> {
    let point = |inside: bool| -> Vec<(f64, f64)> {
        (p.rows.iter())
            .filter(|r| r.outside_region.is_none() == inside)
            .filter_map(|r| {
                r.tips
                    .first()
                    .and_then(|t| t.sigma_m)
                    .map(|s| (r.line as f64, s * 1e3))
            })
            .collect()
    };
    let (inside, outside) = (point(true), point(false));
    if inside.is_empty() && outside.is_empty() {
        return Vec::new();
    }
    vec![figures::scatter(
        "fig-sigma",
        "Predicted 1σ of the first tip's position at each row of the data file; red: outside the \
         calibration's region (an extrapolation)."
            .to_owned(),
        "line in the data file",
        "predicted 1σ, mm",
        &[
            Points {
                label: "inside the region".to_owned(),
                color: BLUE_,
                points: inside,
            },
            Points {
                label: "outside the region".to_owned(),
                color: RED_,
                points: outside,
            },
        ],
    )]
}
