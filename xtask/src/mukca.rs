//! `cargo xtask mukca`: our calibration on MUKCa's real recordings, beside MUKCa's own optimiser.

use anyhow::{Context, Result, bail};
use serde_json::Value;
use std::fmt::Write;
use xshell::{Shell, cmd};

/// MUKCa's own optimiser on the same splits (run with MUKCa's full objective, 48
/// URDF-placement parameters, IPOPT): (unit, urdf, train, test, MAE before, MAE
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

/// One `hapcal calibrate … --json` run of a split; `extra` adds flags (`--folds`, `--model`).
fn calibrate(
    sh: &Shell,
    unit: &str,
    urdf: &str,
    train: &str,
    tests: &[&str],
    extra: &[String],
) -> Result<Value> {
    let base = format!("fixtures/mukca/data/{unit}");
    let device = format!("fixtures/mukca/urdf/{urdf}.urdf");
    let data = format!("{base}/{train}");
    let tests: Vec<String> = tests.iter().map(|t| format!("{base}/{t}")).collect();
    let out = cmd!(sh, "cargo run --release --quiet -p hapcal -- calibrate --device {device} --data {data} --test {tests...} --json {extra...}")
        .read()
        .with_context(|| format!("calibrating {unit} on {train}"))?;
    Ok(serde_json::from_str(&out)?)
}

/// Ours/MUKCa test-MAE ratios of the reference placements of one split's report.
fn ratios(v: &Value, tests: &[&str], theirs: &[Figures]) -> Result<Vec<f64>> {
    let mut out = Vec::new();
    for (test, theirs) in tests.iter().zip(theirs) {
        if let Some([_, a, _]) = theirs {
            out.push(mm(v, "test", test, "after", "mean_absolute_error_m")? / a);
        }
    }
    Ok(out)
}

/// Runs every split with the extra flags: the chosen model of each, and all the ours/MUKCa
/// test-MAE ratios of the reference placements in split order.
fn run_splits(
    sh: &Shell,
    units: &[Split<'_>],
    extra: &[String],
) -> Result<(Vec<String>, Vec<f64>)> {
    let mut picks = Vec::new();
    let mut all = Vec::new();
    for (unit, urdf, train, tests, theirs) in units {
        let v = calibrate(sh, unit, urdf, train, tests, extra)?;
        picks.push(v["model"].as_str().unwrap_or("?").to_string());
        all.extend(ratios(&v, tests, theirs)?);
    }
    Ok((picks, all))
}

/// Folds of the stability sweep (the choice must not depend on the fold count).
const FOLD_SWEEP: std::ops::RangeInclusive<usize> = 3..=10;

/// Fixed models of the diagnostic table (every candidate of `--model auto`, plus the joint
/// harmonic models, which are not candidates).
const FIXED_MODELS: &[&str] = &[
    "geometric",
    "compliance",
    "mass-compliance",
    "actuator-compliance",
    "harmonic",
    "harmonic2",
    "mass-compliance-harmonic",
];

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

/// Mean of `r` (0 for no value).
fn mean(r: &[f64]) -> f64 {
    r.iter().sum::<f64>() / r.len().max(1) as f64
}

/// Calibrates every split (default settings, each fold count of the sweep, each fixed model)
/// and writes docs/results/mukca.md; with `check`, verifies the acceptance instead of writing.
pub(crate) fn run(sh: &Shell, check: bool) -> Result<()> {
    cmd!(sh, "cargo build --release --quiet -p hapcal").run()?;
    let units = splits();
    let calibrated = calibrate_splits(sh, &units)?;
    let mut md = String::new();
    let failures = write_comparison(&mut md, &calibrated.rows)?;
    write_model_choice(&mut md, &calibrated.cv_lines)?;
    write_fold_stability(sh, &mut md, &units)?;
    write_fixed_models(sh, &mut md, &units)?;
    writeln!(md)?;
    md.push_str(WHAT_WAS_TRIED);
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

/// The splits to calibrate: the reference placements grouped by unit (in [`REFERENCE`]'s
/// order), then panda_2 with its eight test placements.
fn splits() -> Vec<Split<'static>> {
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
    units
}

/// The default calibration of every split: one row per test placement, and one line of the
/// model-choice table per split.
struct Calibrated {
    rows: Vec<Row>,
    /// `| unit | chosen | candidates |` rows.
    cv_lines: Vec<String>,
}

/// Calibrates every split with the default settings (`--model auto`, 5 folds).
///
/// # Errors
/// A failed calibration or a report without a test placement's figures.
fn calibrate_splits(sh: &Shell, units: &[Split<'_>]) -> Result<Calibrated> {
    let mut rows = Vec::new();
    let mut cv_lines = Vec::new();
    for (unit, urdf, train, tests, theirs) in units {
        let v = calibrate(sh, unit, urdf, train, tests, &[])?;
        let model = v["model"].as_str().unwrap_or("?").to_string();
        cv_lines.push(cv_line(unit, &model, &v));
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
    Ok(Calibrated { rows, cv_lines })
}

/// The model-choice row of `unit` (chosen `model`, calibration report `v`): each candidate's
/// held-out RMS and its squared-error difference to the geometric model.
fn cv_line(unit: &str, model: &str, v: &Value) -> String {
    let mut cells = Vec::new();
    for c in v["cross_validation"].as_array().into_iter().flatten() {
        let d = &c["difference_to_geometric_m2"];
        cells.push(format!(
            "{} {:.0} µm ({:+.0} ± {:.0} µm²{})",
            c["model"].as_str().unwrap_or("?"),
            c["heldout_rms_m"].as_f64().unwrap_or(f64::NAN) * 1e6,
            d[0].as_f64().unwrap_or(f64::NAN) * 1e12,
            d[1].as_f64().unwrap_or(f64::NAN) * 1e12,
            if c["beats_geometric"].as_bool() == Some(true) {
                ", beats"
            } else {
                ""
            },
        ));
    }
    format!("| {unit} | {model} | {} |", cells.join("; "))
}

/// The report's title and the table of ours beside MUKCa's figures per test placement, with
/// the mean ratio; returns the acceptance failures (a `before` that differs from MUKCa's, an
/// `after` more than 10 % worse).
fn write_comparison(md: &mut String, rows: &[Row]) -> Result<Vec<String>> {
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
    let mut ratios_default = Vec::new();
    let mut failures = Vec::new();
    for r in rows {
        let (tb, ta, td, change) = match r.theirs {
            Some([b, a, d]) => {
                ratios_default.push(r.after / a);
                failures.extend(acceptance_failures(r, b, a));
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
    let mean_ratio = mean(&ratios_default);
    writeln!(md)?;
    writeln!(
        md,
        "Mean of ours/MUKCa over the {} placements with individual reference figures: {:.3} ({:+.1} %).",
        ratios_default.len(),
        mean_ratio,
        (mean_ratio - 1.0) * 100.0
    )?;
    writeln!(md)?;
    writeln!(
        md,
        "The target, −20 % on average, is not met (see \"What was tried\" below)."
    )?;
    Ok(failures)
}

/// What `--check` verifies of row `r` against MUKCa's MAE before (`b`) and after (`a`), mm:
/// the same data (before within 0.0005 mm), and after no more than 10 % worse.
fn acceptance_failures(r: &Row, b: f64, a: f64) -> Vec<String> {
    let mut failures = Vec::new();
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
    failures
}

/// How the choice was made: the cross-validation of each split at the default 5 folds
/// (`cv_lines`: one row per split).
fn write_model_choice(md: &mut String, cv_lines: &[String]) -> Result<()> {
    writeln!(md)?;
    writeln!(md, "## Model choice")?;
    writeln!(md)?;
    writeln!(
        md,
        "`--model auto` climbs the ladder of socket recordings (geometric, then the compliance models) by 5-fold cross-validation on the training placement only, with the rule every kind of data uses (docs/engine.md, \"One model, one ladder\"). The held-out blocks are contiguous in recording order, per socket, and the cross-validation is repeated 3 times with the block boundaries shifted by a third of a block. A compliance model is taken only if its held-out squared error undercuts the geometric model's by more than two standard errors, the standard error taken over the held-out blocks (rows of one block are correlated); among the compliance models that pass, the lowest held-out RMS wins. Below: the held-out RMS of the 3-D point error, and the mean held-out squared-error difference to the geometric model ± its standard error (`beats`: by the margin)."
    )?;
    writeln!(md)?;
    writeln!(md, "| unit | chosen | candidates |")?;
    writeln!(md, "|---|---|---|")?;
    for line in cv_lines {
        writeln!(md, "{line}")?;
    }
    Ok(())
}

/// Stability of the choice over the fold count: every split again with `--folds F` for each F
/// of [`FOLD_SWEEP`].
///
/// # Errors
/// A failed calibration or a report without a test placement's figures.
fn write_fold_stability(sh: &Shell, md: &mut String, units: &[Split<'_>]) -> Result<()> {
    writeln!(md)?;
    writeln!(md, "## Stability over the number of folds")?;
    writeln!(md)?;
    writeln!(
        md,
        "The same splits with `--folds F` (each row: the chosen model per unit, and ours/MUKCa over the 7 reference placements):"
    )?;
    writeln!(md)?;
    let names: Vec<&str> = units.iter().map(|u| u.0).collect();
    writeln!(
        md,
        "| folds | {} | mean ratio | worst ratio |",
        names.join(" | ")
    )?;
    writeln!(md, "|---|{}---|---|", "---|".repeat(names.len()))?;
    for folds in FOLD_SWEEP {
        let (picks, all) = run_splits(sh, units, &["--folds".into(), folds.to_string()])?;
        let worst = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        writeln!(
            md,
            "| {folds} | {} | {:.3} | {:.3} |",
            picks.join(" | "),
            mean(&all),
            worst
        )?;
    }
    Ok(())
}

/// Every fixed model of [`FIXED_MODELS`] on the test placements: a diagnostic, never used for
/// a choice (the splits with reference figures only).
///
/// # Errors
/// A failed calibration or a report without a test placement's figures.
fn write_fixed_models(sh: &Shell, md: &mut String, units: &[Split<'_>]) -> Result<()> {
    writeln!(md)?;
    writeln!(md, "## Every model, fixed (diagnostic)")?;
    writeln!(md)?;
    writeln!(
        md,
        "Ours/MUKCa test MAE with `--model M` forced, per reference placement (order of the first table). These figures look at the test placements and are never used to choose; they show what the candidates, and the joint harmonic models that are not candidates, would give."
    )?;
    writeln!(md)?;
    let placements: Vec<String> = REFERENCE
        .iter()
        .map(|(u, _, _, t, _)| format!("{u} {t}"))
        .collect();
    writeln!(md, "| model | {} | mean |", placements.join(" | "))?;
    writeln!(md, "|---|{}---|", "---|".repeat(placements.len()))?;
    for model in FIXED_MODELS {
        let with_reference: Vec<Split<'_>> = (units.iter())
            .filter(|u| u.0 != "panda_2")
            .cloned()
            .collect();
        let (_, all) = run_splits(sh, &with_reference, &["--model".into(), model.to_string()])?;
        let cells: Vec<String> = all.iter().map(|r| format!("{r:.2}")).collect();
        writeln!(
            md,
            "| {model} | {} | {:.3} |",
            cells.join(" | "),
            mean(&all)
        )?;
    }
    Ok(())
}

/// Hand-written notes on what did not reach the target (numbers from the tables above, which
/// this task measures, or from the commands named here).
const WHAT_WAS_TRIED: &str = "\
## What was tried

- **The earlier choice rule** (lowest 5-fold held-out RMS, one pass) gave a mean ratio of 0.855 \
(−14.5 %), but only at 5 folds: panda_1 chose actuator compliance by less than one standard \
error, and with 6–10 folds back-high became 24–33 % worse than MUKCa's (mean −9.9 … −5.3 %). \
Per-row standard errors also understate the uncertainty, because the residuals of neighbouring \
configurations are correlated. The rule above (three shifted repeats, block standard errors, \
one-standard-error margin, used until the rule was made one for every kind of data) gives up \
the lucky panda_1 pick at 5 folds, which the training data cannot support (−4287 ± 5543 µm², \
0.8 standard errors), but at 7 folds mass compliance passed that margin on panda_1 and \
back-high became 24 % worse than MUKCa's (mean 0.911). The ladder's margin of two standard \
errors, argued from the number of comparisons a ladder makes (docs/engine.md), keeps the \
geometric model on panda_1 at every fold count from 3 to 10 (the sweep above). Its cost, \
measured earlier on data not bundled here: it also drops compliance on panda_2 and on panda_3 \
of the shared MUKCa dataset, where mass compliance lowers the test MAE of most placements.
- **Other partitions** (measured with the 1.5 margin). With 15 folds, and with 30 folds, which leaves out about one \
configuration per socket, `hapcal calibrate … --folds 15` and `--folds 30` pick the same models \
as the table above: kuka_14 mass compliance, panda_1, panda_6 and panda_2 geometric, and panda_7 \
actuator compliance at 15 folds, mass compliance at 30. Mean ratio 0.893 and 0.883, worst \
1.09 and 1.06.
- **Bagging** the geometric model: averaging the predictions of the five fits that each leave \
out one contiguous fifth of the training rows gives a mean ratio of 0.977, against 0.995 for the \
single fit. That is 2 %, too little to pay five fits for. Averaging ten bootstrap fits is worse, \
1.014. (Scratch script around `hapcal calibrate --model geometric`; not kept.)
- **Joint harmonic angle errors** (encoder eccentricity, `Δθ_j = a_j sin q_j + b_j cos q_j`, and \
the second order): `--model harmonic`, `harmonic2` and `mass-compliance-harmonic` in the fixed \
table. They lower the training error (panda_6 0.177 → 0.157 mm, panda_7 0.298 → 0.240 mm) but \
do not carry over to other placements: mean ratio 1.156, 1.716 and 1.029. One placement cannot \
tell 14 more angle-dependent parameters from the geometry. Fitted on all of a unit's placements \
together, as a diagnostic that is never used for a choice, they do help: `hapcal calibrate \
--device fixtures/mukca/urdf/panda.urdf --data fixtures/mukca/data/panda_1 --model \
harmonic` gives back-high 0.421 mm, against 0.554 mm with `--model geometric`. The effect \
exists, but it needs more than one placement. CV never favours them by a \
significant margin, so they are not candidates of `--model auto`.
- **Where the Panda error comes from.** Fitted on all of a unit's placements (the same \
command with `--data fixtures/mukca/data/panda_6`), the geometric model reaches 0.180 and \
0.177 mm on panda_6's left and right placements. From `front` alone it reaches \
0.218 and 0.281 mm, the same as MUKCa's optimiser. What is missing is parameter precision \
outside the training placement's configurations, not a model term we could name. On \
panda_6 and panda_7 no non-geometric model we tried (lumped, mass and actuator compliance, \
harmonics) does better than the geometric one by more than 5 % (the fixed table).
- Also tried (not measured by this task): ridge prior toward the nominal URDF (it reproduces \
MUKCa's own figures), forced compliance models, gear-ratio scale, socket-distance weight, \
outlier rejection, link bending.
";
