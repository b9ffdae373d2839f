//! `cargo xtask real-data`: `hapcal calibrate` on the published real recordings in `fixtures/`
//! (camera poses of a UR10, motion-capture markers on TIAGo, camera poses of a two-axis
//! positioner), first 70 % of the rows in file order train, the last 30 % test; the held-out
//! errors of frames only and of the calibrated model beside what the data's publishers report.

use anyhow::{Context, Result, bail};
use serde_json::Value;
use std::ffi::OsString;
use std::fmt::Write;
use std::path::Path;
use xshell::{Shell, cmd};

/// One recording: name, `hapcal calibrate` arguments, and the publisher's figures (markdown).
struct Dataset {
    name: &'static str,
    args: &'static [&'static str],
    published: &'static str,
    /// For a simulated recording: the rung the simulation holds and the noise floor of the
    /// held-out position RMS, m, that `--check` holds the calibration to.
    truth: Option<(&'static str, f64)>,
}

/// The UR10 camera poses (figaroh-examples):
/// device, tips and data, the arguments of `hapcal calibrate` and `diagnose`.
pub(crate) const UR10: &[&str] = &[
    "--device",
    "fixtures/figaroh/ur10/ur10_robot.urdf",
    "--tip",
    "wrist_3_link",
    "--data",
    "fixtures/figaroh/ur10/calibration.csv",
];

/// The TIAGo hand markers (figaroh-examples):
/// device, tips and data, the arguments of `hapcal calibrate` and `diagnose`.
pub(crate) const TIAGO: &[&str] = &[
    "--device",
    "fixtures/figaroh/tiago/tiago.urdf",
    "--tip",
    "arm_7_link",
    "--data",
    "fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv",
];

/// The two-axis positioner (industrial_calibration):
/// device, tips and data, the arguments of `hapcal calibrate` and `diagnose`.
pub(crate) const POSITIONER: &[&str] = &[
    "--device",
    "fixtures/industrial-calibration/two_axis_positioner.toml",
    "--data",
    "fixtures/industrial-calibration/measurements.yaml",
];

/// The simulated humanoid's hand markers (sim_humanoid):
/// device, tips and data, the arguments of `hapcal calibrate` and `diagnose`.
pub(crate) const HUMANOID: &[&str] = &[
    "--device",
    "fixtures/sim-humanoid/humanoid.urdf",
    "--tip",
    "l_hand",
    "--tip",
    "r_hand",
    "--data",
    "fixtures/sim-humanoid/mocap.csv",
];

const DATASETS: &[Dataset] = &[
    Dataset {
        name: "UR10, camera + checkerboard poses (figaroh-examples)",
        args: UR10,
        published: "figaroh 1.0.2, same split: frames only 4.28 / 4.45 / 6.59 mm, 0.65 / 0.71 / \
                    1.11°; calibrated 3.84 / 4.04 / 6.18 mm, 0.51 / 0.54 / 0.82° (mean / RMS / \
                    max, fixtures/figaroh/README.md)",
        truth: None,
    },
    Dataset {
        name: "TIAGo, four motion-capture markers on the hand (figaroh-examples)",
        args: TIAGO,
        published: "figaroh 1.0.2, same split, marker 1: frames only 3.36 / 3.70 / 7.59 mm; \
                    joint offsets 4.08 / 4.24 / 5.45 mm, full parameters 3.80 / 4.07 / 5.60 mm \
                    (both worse than frames only; fixtures/figaroh/README.md)",
        truth: None,
    },
    Dataset {
        name: "Two-axis positioner seen by a static camera (industrial_calibration)",
        args: POSITIONER,
        published: "industrial_calibration, all 205 poses in-sample: static D-H 3.82 mm (σ 1.45), \
                    0.0053 rad; calibrated D-H 1.74 mm (σ 0.92), 0.0032 rad (mean position and \
                    orientation difference, fixtures/industrial-calibration/README.md)",
        truth: None,
    },
    Dataset {
        name: "Simulated two-arm humanoid, a motion-capture marker on each hand (sim_humanoid)",
        args: HUMANOID,
        published: "simulated by `cargo run --release -p hapcal-calibrate --example sim_humanoid \
                    -- fixtures/sim-humanoid` (truth in fixtures/sim-humanoid/truth.toml): \
                    geometric deviations of 0.3 mm and 0.3 mrad, axial and transversal \
                    compliance on the torso and both arms, a CAD mass on every link and the \
                    head, marker noise 0.2 mm per axis: a noise floor of √3·0.2 = 0.35 mm \
                    RMS held out",
        truth: Some(("transversal-compliance", 3.464e-4)),
    },
    Dataset {
        name: "Simulated two-arm humanoid as real motion capture behaves (sim_humanoid, real-like)",
        args: &[
            "--device",
            "fixtures/sim-humanoid/humanoid.urdf",
            "--tip",
            "l_hand",
            "--tip",
            "r_hand",
            "--data",
            "fixtures/sim-humanoid/real-like.csv",
        ],
        published: "simulated by `cargo run --release -p hapcal-calibrate --example sim_humanoid \
                    -- --real-like fixtures/sim-humanoid` (truth in fixtures/sim-humanoid/\
                    real-like-truth.toml): 350 rows, geometric deviations of 0.3 mm and 0.3 \
                    mrad, axial compliance and per-axis transversal compliance (one axis four \
                    times the other), link masses 10 % off the URDF's CAD masses, marker noise \
                    2 mm per axis: a noise floor of √3·2 = 3.46 mm RMS held out. At that noise \
                    the per-axis model does not beat the isotropic one it contains by two \
                    standard errors, so the ladder keeps the isotropic one",
        truth: Some(("transversal-compliance", 3.464e-3)),
    },
];

/// Each bundled recording's name and its `hapcal calibrate` arguments (without the split).
pub(crate) fn recordings() -> impl Iterator<Item = (&'static str, &'static [&'static str])> {
    DATASETS.iter().map(|d| (d.name, d.args))
}

/// Fraction of each file's rows, the last in file order, held out.
pub(crate) const TEST_LAST: &str = "0.3";

/// Figures of one data set in the JSON report: (position mean, RMS, max in m; orientation
/// mean, RMS, max in rad if any).
fn pose(v: &Value) -> Option<([f64; 3], Option<[f64; 3]>)> {
    let p = v.get("pose")?;
    let f = |k: &str| p.get(k).and_then(Value::as_f64);
    let position = [
        f("position_mean_m")?,
        f("position_rms_m")?,
        f("position_max_m")?,
    ];
    let orientation = match (
        f("orientation_mean_rad"),
        f("orientation_rms_rad"),
        f("orientation_max_rad"),
    ) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    Some((position, orientation))
}

fn mm(v: [f64; 3]) -> String {
    format!("{:.2} / {:.2} / {:.2}", v[0] * 1e3, v[1] * 1e3, v[2] * 1e3)
}

fn deg(v: Option<[f64; 3]>) -> String {
    v.map_or_else(
        || "–".to_owned(),
        |v| {
            format!(
                "{:.2} / {:.2} / {:.2}",
                v[0].to_degrees(),
                v[1].to_degrees(),
                v[2].to_degrees()
            )
        },
    )
}

/// The test rows' figures of `d` with the model forced to `rung` (`--model`), as
/// `position mean / RMS / max, orientation mean / RMS / max`.
fn forced_test_figures(
    sh: &Shell,
    (hapcal, pre): (&OsString, &[OsString]),
    d: &Dataset,
    rung: &str,
) -> Result<String> {
    let args: Vec<&str> = d.args.to_vec();
    let model = rung;
    let json = cmd!(
        sh,
        "{hapcal} {pre...} calibrate {args...} --test-last {TEST_LAST} --model {model} --json"
    )
    .read()
    .with_context(|| format!("calibrating {} with {rung}", d.name))?;
    let report: Value = serde_json::from_str(&json).context("parsing the JSON report")?;
    let test = (report["placements"].as_array().into_iter().flatten())
        .find(|s| s["role"] == "test")
        .and_then(|s| pose(&s["after"]));
    Ok(test.map_or_else(|| "–".to_owned(), |(p, o)| format!("{}, {}", mm(p), deg(o))))
}

/// Runs every recording; with `check`, only verifies that no calibrated model is worse than
/// frames only on its held-out rows.
pub(crate) fn run(sh: &Shell, check: bool, bin: Option<&Path>) -> Result<()> {
    let (hapcal, pre) = crate::hapcal_cmd(bin);
    let (hapcal, pre) = (&hapcal, pre.as_slice());
    let mut md = String::from(
        "# Real recordings, held out\n\nWritten by `cargo xtask real-data` (release build). Each \
         recording is calibrated with the one `hapcal calibrate` command shown, on the files as \
         published; `--test-last 0.3` trains on the first 70 % of the rows in file order and \
         tests on the rest. The model is chosen by blocked cross-validation on the training rows \
         over the ladder frames only → joint offsets → geometric → compliance → transversal \
         compliance (isotropic or per axis) → joint harmonics (docs/engine.md, the rule that \
         picks a rung); frames only fits the instrument and marker frames to the nominal kinematics. Errors on the test rows: \
         3-D position error of every marker sample (mean / RMS / max, mm) and, for pose data, \
         the angle of the relative rotation (mean / RMS / max, °).\n",
    );
    let machine = cmd!(sh, "uname -srm").read().unwrap_or_default();
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_owned())
        })
        .unwrap_or_default();
    let _ = writeln!(
        md,
        "\nMachine: {cpu}, {} logical cores, {machine}. The ladder table gives, per rung, the \
         cross-validation that chose the model and, for comparison only, the test rows' errors \
         had that rung been forced with `--model`.",
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    let mut worse = Vec::new();
    for d in DATASETS {
        let args: Vec<&str> = d.args.to_vec();
        let json = cmd!(
            sh,
            "{hapcal} {pre...} calibrate {args...} --test-last {TEST_LAST} --json"
        )
        .read()
        .with_context(|| format!("calibrating {}", d.name))?;
        let report: Value = serde_json::from_str(&json).context("parsing the JSON report")?;
        let model = report["model"].as_str().unwrap_or("?").replace('-', " ");
        let _ = writeln!(md, "\n## {}\n", d.name);
        let _ = writeln!(
            md,
            "`hapcal calibrate {} --test-last {TEST_LAST}`\n",
            d.args.join(" ")
        );
        let _ = writeln!(md, "Model chosen: **{model}**.\n");
        if let Some(ladder) = report["ladder"].as_array() {
            let _ = writeln!(
                md,
                "| rung | cross-validated position RMS on the training rows (mm) | held-out score minus frames only's (Σ e²/σ² per row, ± standard error) | test rows with this rung forced: position (mm), orientation (°) |\n|---|---|---|---|"
            );
            for r in ladder {
                let rung = r["rung"].as_str().unwrap_or("?");
                let diff = &r["score_difference_to_frames"];
                let forced = forced_test_figures(sh, (hapcal, pre), d, rung)?;
                let _ = writeln!(
                    md,
                    "| {} | {:.2} | {:+.2} ± {:.2} | {} |",
                    rung.replace('-', " "),
                    r["heldout_rms_m"].as_f64().unwrap_or(f64::NAN) * 1e3,
                    signed_hundredths(diff[0].as_f64().unwrap_or(f64::NAN)),
                    diff[1].as_f64().unwrap_or(f64::NAN),
                    forced
                );
            }
        }
        let _ = writeln!(
            md,
            "\n| data set | rows | position, frames only | position, calibrated | orientation, frames only | orientation, calibrated |\n|---|---|---|---|---|---|"
        );
        for set in report["placements"].as_array().into_iter().flatten() {
            let (Some((p0, o0)), Some((p1, o1))) = (pose(&set["before"]), pose(&set["after"]))
            else {
                bail!("{}: a data set without pose figures", d.name);
            };
            let role = set["role"].as_str().unwrap_or("?");
            let _ = writeln!(
                md,
                "| {} ({role}) | {} | {} | {} | {} | {} |",
                set["name"].as_str().unwrap_or("?"),
                set["n_rows"],
                mm(p0),
                mm(p1),
                deg(o0),
                deg(o1)
            );
            if role == "test" && p1[1] > p0[1] * (1.0 + 1e-9) {
                worse.push(format!(
                    "{}: test position RMS {:.3} mm calibrated against {:.3} mm frames only",
                    d.name,
                    p1[1] * 1e3,
                    p0[1] * 1e3
                ));
            }
        }
        if let Some((rung, floor)) = d.truth {
            let chosen = report["model"].as_str().unwrap_or("?");
            let test_rms = (report["placements"].as_array().into_iter().flatten())
                .filter(|s| s["role"] == "test")
                .filter_map(|s| pose(&s["after"]))
                .map(|(p, _)| p[1])
                .fold(0.0, f64::max);
            // The estimation error of ~180 parameters from ~2,300 residuals adds about 4 % to
            // the noise; 15 % is a margin of more than three times that.
            if chosen != rung || test_rms > 1.15 * floor {
                worse.push(format!(
                    "{}: chose {chosen} (the simulation holds {rung}), test position RMS {:.3} mm \
                     against a floor of {:.3} mm",
                    d.name,
                    test_rms * 1e3,
                    floor * 1e3
                ));
            }
        }
        for w in report["warnings"].as_array().into_iter().flatten() {
            let _ = writeln!(md, "\n> {}", w.as_str().unwrap_or_default());
        }
        let _ = writeln!(md, "\nPublished: {}.", d.published);
    }
    if check {
        if !worse.is_empty() {
            bail!(
                "calibrated worse than frames only, or off the simulated truth:\n{}",
                worse.join("\n")
            );
        }
        println!("real-data: no calibrated model worse than frames only on its test rows");
        return Ok(());
    }
    sh.write_file("docs/results/real-data.md", md)?;
    println!("wrote docs/results/real-data.md");
    if !worse.is_empty() {
        println!("calibrated worse than frames only:\n{}", worse.join("\n"));
    }
    Ok(())
}

/// `x` rounded to hundredths with the sign of what is shown: a difference that rounds to zero
/// prints `+0.00` whichever side of zero its rounding noise falls (`-7e-14` is not `-0.00`).
fn signed_hundredths(x: f64) -> f64 {
    (x * 100.0).round() / 100.0 + 0.0
}
