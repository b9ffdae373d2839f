//! Plain-text rendering of a [`CalibrationReport`].

use crate::calibrate::{CalibrationReport, Figures};
use std::fmt::Write;

fn mm(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{:.3}", v * 1e3))
}

fn scaled(value: f64, unit: &str) -> (f64, &'static str) {
    match unit {
        "m" => (value * 1e3, "mm"),
        "rad" => (value * 1e3, "mrad"),
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

/// Renders the report as the table `hapcal calibrate` prints.
pub fn render(r: &CalibrationReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "hapcal calibrate: {}", r.device);
    if !r.cross_validation.is_empty() {
        let _ = writeln!(
            s,
            "\nmodel choice by {}-fold cross-validation on the training data (held-out RMS; \
             held-out squared error minus the geometric model's, ± its standard error; a model \
             must beat the geometric one by {} standard error(s)):",
            r.folds,
            crate::calibrate::CV_SIGNIFICANCE_Z
        );
        for cv in &r.cross_validation {
            let (diff, se) = cv.difference_to_geometric_m2;
            let _ = writeln!(
                s,
                "  {:<20} {:>9.4} mm {:>+10.0} ± {:<8.0} µm²{}",
                model_name(cv.model),
                cv.heldout_rms_m * 1e3,
                diff * 1e12,
                se * 1e12,
                if cv.beats_geometric { "  beats" } else { "" }
            );
        }
    }
    let _ = writeln!(
        s,
        "\nmodel: {}; sigma = {:.4} mm (from {}); LM: {}",
        model_name(r.model),
        r.sigma_m * 1e3,
        r.sigma_source,
        r.termination
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
        let why = if p.reason == "near_zero_column" {
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
        };
        let _ = writeln!(s, "  {:<28} {why}", p.name);
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
    if !r.warnings.is_empty() {
        let _ = writeln!(s, "\nwarnings:");
        for w in &r.warnings {
            let _ = writeln!(s, "  - {w}");
        }
    }
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
    let _ = writeln!(s, "\nelapsed: {:.1} ms", r.elapsed_s * 1e3);
    s
}

/// The command-line name of a model (`mass-compliance`).
fn model_name(model: crate::calibrate::ModelChoice) -> String {
    clap::ValueEnum::to_possible_value(&model)
        .map_or_else(|| format!("{model:?}"), |v| v.get_name().to_owned())
}
