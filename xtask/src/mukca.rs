//! `cargo xtask mukca`: our calibration on MUKCa's real recordings, beside MUKCa's own optimiser.

use anyhow::{Context, Result, bail};
use serde_json::Value;
use std::fmt::Write;
use xshell::{Shell, cmd};

/// MUKCa's own optimiser on the same splits (issue #2; run by the project lead with their full
/// objective, 48 URDF-placement parameters, IPOPT): (unit, urdf, train, test, MAE before, MAE
/// after, distance error after), mm. `None` where only a range over placements was given.
/// MAE before, MAE after, distance error after (mm).
type Figures = Option<[f64; 3]>;
/// A split to calibrate: unit, URDF stem, training placement, test placements and their figures.
type Split<'a> = (&'a str, &'a str, &'a str, Vec<&'a str>, Vec<Figures>);

const REFERENCE: &[(&str, &str, &str, &str, Figures)] = &[
    (
        "kuka_14",
        "iiwa14",
        "front",
        "left_back",
        Some([0.808, 0.131, 0.006]),
    ),
    (
        "kuka_14",
        "iiwa14",
        "front",
        "raised_left",
        Some([0.804, 0.404, 0.164]),
    ),
    (
        "panda_1",
        "panda",
        "front",
        "back-high",
        Some([7.459, 0.825, 0.955]),
    ),
    (
        "panda_1",
        "panda",
        "front",
        "right",
        Some([7.987, 0.412, 0.261]),
    ),
    (
        "panda_6",
        "panda",
        "front",
        "left",
        Some([10.604, 0.227, 0.196]),
    ),
    (
        "panda_6",
        "panda",
        "front",
        "right",
        Some([10.577, 0.297, 0.073]),
    ),
    (
        "panda_7",
        "panda",
        "front",
        "right",
        Some([5.920, 0.301, 0.089]),
    ),
];

/// panda_2: trained on back_left, tested on the 8 others; MUKCa's figures only as ranges.
const PANDA_2_TESTS: &[&str] = &[
    "back_right",
    "front_center",
    "front_left",
    "front_right",
    "high",
    "mid-high",
    "mid_left",
    "mid_right",
];

struct Row {
    unit: String,
    train: String,
    test: String,
    model: String,
    before: f64,
    after: f64,
    dist_after: f64,
    theirs: Figures,
}

fn calibrate(sh: &Shell, unit: &str, urdf: &str, train: &str, tests: &[&str]) -> Result<Value> {
    let base = format!("fixtures/mukca/data/{unit}");
    let device = format!("fixtures/mukca/urdf/{urdf}.urdf");
    let data = format!("{base}/{train}");
    let tests: Vec<String> = tests.iter().map(|t| format!("{base}/{t}")).collect();
    let out = cmd!(sh, "cargo run --release --quiet -p hapcal -- calibrate --device {device} --data {data} --test {tests...} --json")
        .read()
        .with_context(|| format!("calibrating {unit} on {train}"))?;
    Ok(serde_json::from_str(&out)?)
}

fn mm(v: &Value, role: &str, name: &str, when: &str, key: &str) -> Result<f64> {
    let placements = v["placements"]
        .as_array()
        .context("no placements in the report")?;
    let p = placements
        .iter()
        .find(|p| p["name"] == name && p["role"] == role)
        .with_context(|| format!("placement {name} missing"))?;
    p[when][key]
        .as_f64()
        .map(|m| m * 1e3)
        .with_context(|| format!("{name}: {when}.{key} missing"))
}

pub(crate) fn run(sh: &Shell, check: bool) -> Result<()> {
    cmd!(sh, "cargo build --release --quiet -p hapcal").run()?;
    let mut rows = Vec::new();
    let mut units: Vec<Split<'_>> = Vec::new();
    for &(unit, urdf, train, test, theirs) in REFERENCE {
        match units.iter_mut().find(|u| u.0 == unit) {
            Some(u) => {
                u.3.push(test);
                u.4.push(theirs);
            }
            None => units.push((unit, urdf, train, vec![test], vec![theirs])),
        }
    }
    units.push((
        "panda_2",
        "panda",
        "back_left",
        PANDA_2_TESTS.to_vec(),
        vec![None; PANDA_2_TESTS.len()],
    ));
    for (unit, urdf, train, tests, theirs) in &units {
        let v = calibrate(sh, unit, urdf, train, tests)?;
        let model = v["model"].as_str().unwrap_or("?").to_string();
        for (test, theirs) in tests.iter().zip(theirs) {
            rows.push(Row {
                unit: unit.to_string(),
                train: train.to_string(),
                test: test.to_string(),
                model: model.clone(),
                before: mm(&v, "test", test, "before", "mean_absolute_error_m")?,
                after: mm(&v, "test", test, "after", "mean_absolute_error_m")?,
                dist_after: mm(&v, "test", test, "after", "distance_error_m")?,
                theirs: *theirs,
            });
        }
    }
    let mut md = String::new();
    writeln!(md, "# hapcal on MUKCa real-robot recordings")?;
    writeln!(md)?;
    writeln!(
        md,
        "Written by `cargo xtask mukca` (release build; each split is one `hapcal calibrate --device fixtures/mukca/urdf/<urdf>.urdf --data <train> --test <tests…> --json`). Figures in mm: MAE = mean absolute error of the ball positions to their socket mean on the *test* placement, dist = socket-distance error; MUKCa's own optimiser (IPOPT, 48 URDF-placement parameters, regularised) beside ours."
    )?;
    writeln!(md)?;
    writeln!(
        md,
        "| unit | train | test | MAE before (ours) | MAE before (MUKCa) | model | MAE after (ours) | MAE after (MUKCa) | change | dist after (ours) | dist after (MUKCa) |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|")?;
    let mut ratios = Vec::new();
    let mut failures = Vec::new();
    for r in &rows {
        let (tb, ta, td, change) = match r.theirs {
            Some([b, a, d]) => {
                ratios.push(r.after / a);
                if (r.before - b).abs() > 0.0005 {
                    failures.push(format!(
                        "{} {}: before {:.4} mm differs from MUKCa's {b:.3}",
                        r.unit, r.test, r.before
                    ));
                }
                if r.after > 1.10 * a {
                    failures.push(format!(
                        "{} {}: after {:.3} mm is more than 10 % worse than {a:.3}",
                        r.unit, r.test, r.after
                    ));
                }
                (
                    format!("{b:.3}"),
                    format!("{a:.3}"),
                    format!("{d:.3}"),
                    format!("{:+.0} %", (r.after / a - 1.0) * 100.0),
                )
            }
            None => (
                "5.6–11.1".into(),
                "0.65–1.36".into(),
                "0.02–0.77".into(),
                "-".into(),
            ),
        };
        writeln!(
            md,
            "| {} | {} | {} | {:.3} | {tb} | {} | {:.3} | {ta} | {change} | {:.3} | {td} |",
            r.unit, r.train, r.test, r.before, r.model, r.after, r.dist_after
        )?;
    }
    let mean_ratio = ratios.iter().sum::<f64>() / ratios.len().max(1) as f64;
    writeln!(md)?;
    writeln!(
        md,
        "Mean of ours/MUKCa over the {} placements with individual reference figures: {:.3} ({:+.1} %).",
        ratios.len(),
        mean_ratio,
        (mean_ratio - 1.0) * 100.0
    )?;
    writeln!(md)?;
    writeln!(
        md,
        "The issue's target, −20 % on average, is not met. How firm the model choice is: on panda_1 the \
         actuator-compliance model wins the 5-fold cross-validation by less than one standard error of \
         the paired held-out difference (the JSON report gives both); with 6–10 folds the choice moves \
         to per-joint or lumped compliance and back-high becomes 24–33 % worse than MUKCa's (measured \
         with `hapcal calibrate … --folds F`, F = 3…10: mean −13.5, −14.0, −14.5, −9.9, −7.7, −5.3 %). \
         Within one placement the shoulder's gravity torque hardly changes, so compliance and geometry \
         are nearly confounded. Fitted on all three panda_1 placements together (a diagnostic, never \
         used for a choice), mass compliance brings back-high to 0.362 mm against 0.554 mm for the \
         geometric model: the effect is real but one placement cannot pin it down."
    )?;
    writeln!(md)?;
    writeln!(
        md,
        "Speed: docs/results/speed.md (instruction counts and the criterion bench; wall times depend on the machine's load)."
    )?;
    println!("{md}");
    if check {
        if !failures.is_empty() {
            bail!("MUKCa check failed:\n{}", failures.join("\n"));
        }
    } else {
        sh.write_file("docs/results/mukca.md", &md)?;
        eprintln!("wrote docs/results/mukca.md");
    }
    Ok(())
}
