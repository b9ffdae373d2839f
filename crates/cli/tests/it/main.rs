//! End-to-end tests of the `hapcal` binary: the bundled default, JSON shape, URDF write-back,
//! and one clear error (non-zero exit, file:line:column) for each kind of bad input.

#![allow(clippy::unwrap_used)] // test helpers fail loudly on a malformed report; that is the test

mod binding;
mod columns;
mod compensate;
mod coverage;
mod force;
mod hostile;
mod hostile_cases;
mod html;
#[path = "../../../runtime/tests/it/iiwa_masses.rs"]
mod iiwa_masses;
mod joint_scale;
mod ladder_rows;
mod part_units;
mod plan_after;
mod predict;
mod predict_device;
mod setup_check;
mod setup_haptic;
mod setup_sockets;
mod written;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn hapcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hapcal"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// `hapcal args`, whose success is asserted.
fn hapcal_ok(args: &[&str]) -> Output {
    succeeded(hapcal(args))
}

/// `out`, whose success is asserted.
fn succeeded(out: Output) -> Output {
    assert!(out.status.success(), "{}", stderr(&out));
    out
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A path as an argument.
fn show(p: &Path) -> String {
    p.display().to_string()
}

/// Asserts that `out` ended with exit code `code` and that its standard error holds each of
/// `needles`; returns that standard error.
fn assert_exit(out: &Output, code: i32, needles: &[&str]) -> String {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(code), "{err}");
    for n in needles {
        assert!(err.contains(n), "{n:?} not in: {err}");
    }
    err
}

/// The `hapcal force` command line on the nominal device file `device`, the truth file `truth`
/// and the calibrated device file `calibrated`, then `more`.
fn force_args<'a>(
    device: &'a str,
    truth: &'a str,
    calibrated: &'a str,
    more: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![
        "force",
        "--device",
        device,
        "--truth",
        truth,
        "--calibrated",
        calibrated,
    ];
    args.extend_from_slice(more);
    args
}

/// `hapcal compensate` of `targets` on the robot `urdf` with the tip link `tip`, into `out`.
fn compensate(urdf: &Path, tip: &str, targets: &Path, out: &Path) -> Output {
    compensate_with(urdf, Some(tip), targets, out, &[])
}

/// `hapcal compensate` of `targets` on `device` (a URDF with the tip link `tip`, or a device
/// file with `None`), into `out`, with the flags `extra`.
fn compensate_with(
    device: &Path,
    tip: Option<&str>,
    targets: &Path,
    out: &Path,
    extra: &[&str],
) -> Output {
    let (device, targets, out) = (show(device), show(targets), show(out));
    let mut args = vec!["compensate", "--device", &device];
    args.extend(tip.iter().flat_map(|t| ["--tip", t]));
    args.extend(["--targets", &targets, "--out", &out]);
    args.extend_from_slice(extra);
    hapcal(&args)
}

/// The CSV file at `path` with a header: the header's names and each row's cells through
/// `number`.
fn read_table(path: &Path, number: impl Fn(&str) -> f64) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).expect("readable");
    let mut lines = text.lines();
    let header = (lines.next().expect("a header").split(','))
        .map(str::to_owned)
        .collect();
    let rows = lines.map(|l| l.split(',').map(&number).collect()).collect();
    (header, rows)
}

/// The bundled UR10's URDF (figaroh), as an argument.
fn ur10_urdf() -> String {
    show(&root().join("fixtures/figaroh/ur10/ur10_robot.urdf"))
}

/// The bundled UR10's camera recording (figaroh): 23 rows of 3 positions, roll, pitch, yaw,
/// then the 6 joints.
fn ur10_csv() -> PathBuf {
    root().join("fixtures/figaroh/ur10/calibration.csv")
}

/// `hapcal <command> --device <the UR10's URDF> --tip wrist_3_link --data <data>` and `extra`.
fn on_ur10(command: &str, data: &Path, extra: &[&str]) -> Output {
    let (urdf, data) = (ur10_urdf(), show(data));
    let mut args = vec![
        command,
        "--device",
        &urdf,
        "--tip",
        "wrist_3_link",
        "--data",
        &data,
    ];
    args.extend_from_slice(extra);
    hapcal(&args)
}

/// The UR10's camera recording, one row of cells per line (the header first).
fn ur10_rows() -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(ur10_csv()).expect("the UR10 recording");
    text.lines()
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

/// Rows of cells (the header first) as CSV text.
fn csv(rows: &[Vec<String>]) -> String {
    rows.iter().map(|r| r.join(",") + "\n").collect()
}

/// The index of column `name` in the header `rows[0]`.
fn column(rows: &[Vec<String>], name: &str) -> usize {
    rows[0]
        .iter()
        .position(|c| c == name)
        .unwrap_or_else(|| panic!("no column {name}"))
}

/// The residual before → after in a setup finding, mm: the numbers after `key` (the
/// residual's name in the report, `frames-only RMS`, `socket-scatter RMS`, …) and after the
/// arrow.
fn before_after_mm(err: &str, key: &str) -> (f64, f64) {
    let key = format!("{key} ");
    let at = err.find(&key).expect("a residual") + key.len();
    let rest = &err[at..];
    let number = |s: &str| -> f64 {
        (s.split(' ').next().expect("a number"))
            .parse()
            .expect("mm")
    };
    let arrow = rest.find("→ ").expect("an arrow") + "→ ".len();
    (number(rest), number(&rest[arrow..]))
}

/// The warnings of `hapcal calibrate --json` with `args` (exit code 0 asserted).
fn calibration_warnings(args: &[&str]) -> Vec<String> {
    let mut all = vec!["calibrate"];
    all.extend_from_slice(args);
    all.push("--json");
    let out = hapcal(&all);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    v["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .map(|w| w.as_str().unwrap_or_default().to_owned())
        .collect()
}

/// Asserts that `hapcal calibrate` with `args` warns of no residual above its instrument's
/// typical σ.
fn assert_within_default_noise(args: &[&str]) {
    let warnings = calibration_warnings(args);
    assert!(
        !warnings.iter().any(|w| w.contains("typical σ")),
        "{args:?}: {warnings:?}"
    );
}

/// The next number in [0, 1) of a fixed linear congruential sequence whose state `state`
/// holds (advanced): test noise that is the same on every run.
fn next_uniform(state: &std::cell::Cell<u64>) -> f64 {
    let s = (state.get())
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    state.set(s);
    (s >> 11) as f64 / (1u64 << 53) as f64
}

/// A fresh scratch folder per test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hapcal-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// A MUKCa placement folder whose hole_0.csv is `bad` and hole_1.csv a copy of real data.
fn placement_with(name: &str, bad: &str) -> PathBuf {
    let dir = scratch(name);
    let front = root().join("fixtures/mukca/data/kuka_14/front");
    std::fs::write(dir.join("hole_0.csv"), bad).expect("write");
    std::fs::copy(front.join("hole_1.csv"), dir.join("hole_1.csv")).expect("copy");
    dir
}

fn iiwa() -> String {
    root()
        .join("fixtures/mukca/urdf/iiwa14.urdf")
        .display()
        .to_string()
}

fn json(out: &Output) -> Value {
    assert!(out.status.success(), "hapcal failed: {}", stderr(out));
    serde_json::from_slice(&out.stdout).expect("stdout is one JSON document")
}

/// The JSON report of `hapcal command` with the flags `common`, then `more`.
fn json_of(command: &str, common: &[&str], more: &[&str]) -> Value {
    let args: Vec<&str> = (std::iter::once(command))
        .chain(common.iter().copied())
        .chain(more.iter().copied())
        .collect();
    json(&hapcal(&args))
}

/// The text `field` of each entry of the array `list` of the JSON report `v`.
fn fields<'a>(v: &'a Value, list: &str, field: &str) -> Vec<&'a str> {
    (v[list].as_array().expect("an array").iter())
        .map(|entry| entry[field].as_str().expect("a text"))
        .collect()
}

/// The figure `key` after the fit (m or rad, as the key says) of the data set of `role`
/// (`train` or `test`) in a `hapcal calibrate --json` report: at the set's top level or among
/// its pose figures.
fn set_figure(report: &Value, role: &str, key: &str) -> f64 {
    let set = (report["placements"].as_array().expect("placements").iter())
        .find(|p| p["role"] == role)
        .unwrap_or_else(|| panic!("no {role} set"));
    let after = &set["after"];
    (after[key].as_f64())
        .or_else(|| after["pose"][key].as_f64())
        .unwrap_or_else(|| panic!("no {key} in {after}"))
}

fn figure(v: &Value, name: &str, when: &str, key: &str) -> f64 {
    let p = v["placements"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap();
    p[when][key].as_f64().unwrap()
}

#[test]
fn bundled_default_reproduces_mukca_before_figures_and_improves_on_test_data() {
    let v = json(&hapcal(&["calibrate", "--model", "geometric", "--json"]));
    // MUKCa's own figures for the nominal iiwa URDF, to 0.001 mm: a check of
    // our forward kinematics and of the metric.
    assert!((figure(&v, "left_back", "before", "mean_absolute_error_m") - 0.808e-3).abs() < 0.5e-6);
    assert!(
        (figure(&v, "raised_left", "before", "mean_absolute_error_m") - 0.804e-3).abs() < 0.5e-6
    );
    assert_eq!(fields(&v, "placements", "role"), ["train", "test", "test"]);
    // Calibration removes most of the error on the held-out placements (MUKCa: 0.131, 0.404 mm).
    assert!(figure(&v, "left_back", "after", "mean_absolute_error_m") < 0.2e-3);
    assert!(figure(&v, "raised_left", "after", "mean_absolute_error_m") < 0.45e-3);
    assert!(figure(&v, "front", "after", "distance_error_m") < 0.05e-3);
    // The three gauge freedoms of the base translation are found by the pruning.
    let pruned = fields(&v, "pruned", "name");
    for name in [
        "joint_a1.x",
        "joint_a1.y",
        "joint_a1.z",
        "ball_joint.rx",
        "ball_joint.ry",
        "ball_joint.rz",
    ] {
        assert!(pruned.contains(&name), "{name} not pruned: {pruned:?}");
    }
}

#[test]
fn calibrated_urdf_reproduces_the_calibrated_figures() {
    let dir = scratch("urdf-out");
    let out_urdf = dir.join("iiwa14_calibrated.urdf");
    let front = root().join("fixtures/mukca/data/kuka_14/front");
    let test = root().join("fixtures/mukca/data/kuka_14/left_back");
    let (front, test) = (front.display().to_string(), test.display().to_string());
    let out_s = out_urdf.display().to_string();
    let calibrate = |device: &str, more: &[&str]| {
        let mut args = vec![
            "calibrate",
            "--device",
            device,
            "--data",
            &front,
            "--test",
            &test,
            "--model",
            "geometric",
            "--json",
        ];
        args.extend_from_slice(more);
        json(&hapcal(&args))
    };
    let first = calibrate(&iiwa(), &["--out", &out_s]);
    // Calibrating again from the written URDF starts where the first calibration ended.
    let second = calibrate(&out_s, &[]);
    let after = figure(&first, "left_back", "after", "mean_absolute_error_m");
    let before_again = figure(&second, "left_back", "before", "mean_absolute_error_m");
    assert!(
        (after - before_again).abs() < 1e-9,
        "{after} vs {before_again}"
    );
}

#[test]
fn missing_data_folder_is_one_clear_error() {
    let err = iiwa_refused("/nonexistent/placement", &[]);
    assert!(
        err.starts_with("hapcal: error: reading measurements in /nonexistent/placement"),
        "{err}"
    );
}

/// `hapcal calibrate` of the bundled iiwa on `data` with the arguments `more`, which must
/// exit 2 without a panic; its standard error.
fn iiwa_refused(data: &str, more: &[&str]) -> String {
    let iiwa = iiwa();
    let mut args = vec!["calibrate", "--device", &iiwa, "--data", data];
    args.extend_from_slice(more);
    let out = hapcal(&args);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(!err.contains("panicked"), "{err}");
    err
}

fn bad_placement_error(name: &str, content: &str) -> String {
    iiwa_refused(&placement_with(name, content).display().to_string(), &[])
}

const GOOD: &str = "0.1,0.2,0.3,-1.0,0.5,0.6,0.7\n";

#[test]
fn ragged_row_names_file_and_line() {
    let err = bad_placement_error("ragged", &format!("{GOOD}0.1,0.2,0.3\n"));
    assert!(err.contains("hole_0.csv:2"), "{err}");
}

#[test]
fn nan_names_file_line_and_column() {
    let err = bad_placement_error("nan", &format!("{GOOD}0.1,NaN,0.3,-1.0,0.5,0.6,0.7\n"));
    assert!(err.contains("hole_0.csv:2:2"), "{err}");
}

#[test]
fn non_numeric_cell_names_file_line_and_column() {
    let err = bad_placement_error(
        "text",
        &format!("{GOOD}{GOOD}0.1,0.2,abc,-1.0,0.5,0.6,0.7\n"),
    );
    assert!(err.contains("hole_0.csv:3:3"), "{err}");
    assert!(err.contains("abc"), "{err}");
}

#[test]
fn joint_count_mismatch_is_an_error() {
    let err = bad_placement_error(
        "joints",
        "0.1,0.2,0.3,-1.0,0.5,0.6\n0.1,0.2,0.3,-1.0,0.5,0.6\n",
    );
    assert!(err.contains("hole_0.csv:1"), "{err}");
    assert!(err.contains('7') && err.contains('6'), "{err}");
}

#[test]
fn fewer_configurations_than_parameters_is_an_error() {
    let dir = scratch("few");
    std::fs::write(
        dir.join("hole_0.csv"),
        format!("{GOOD}0.2,0.1,0.3,-1.1,0.5,0.6,0.7\n"),
    )
    .unwrap();
    std::fs::write(dir.join("hole_1.csv"), "0.1,0.25,0.3,-1.0,0.5,0.6,0.75\n").unwrap();
    let err = iiwa_refused(&dir.display().to_string(), &["--model", "geometric"]);
    assert!(err.contains("3 configurations"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn urdf_without_the_tip_link_is_an_error() {
    let out = hapcal(&["calibrate", "--device", &iiwa(), "--tip", "no_such_link"]);
    assert_exit(&out, 2, &["no_such_link", "ball_link"]);
}

#[test]
fn zero_counts_are_usage_errors_naming_the_argument() {
    for (args, name, floor) in [
        (
            &["simulate", "--poses", "0", "--out", "unused.csv"][..],
            "--poses",
            "between 1 and",
        ),
        (
            &["blind-test", "--cases", "0"][..],
            "--cases",
            "between 1 and",
        ),
        (&["calibrate", "--folds", "1"][..], "--folds", "at least 2"),
    ] {
        let out = hapcal(args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(name) && err.contains(floor), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn import_urdf_writes_a_device_file_that_calibrates_alike() {
    let out = hapcal_ok(&["import-urdf", &iiwa(), "--tip", "ball_link"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("joint_a4") && text.contains("ball_joint"),
        "{text}"
    );
    let dir = scratch("import");
    let toml_path: &Path = &dir.join("iiwa14.toml");
    std::fs::write(toml_path, &text).unwrap();
    let front = root()
        .join("fixtures/mukca/data/kuka_14/front")
        .display()
        .to_string();
    let v = json(&hapcal(&[
        "calibrate",
        "--device",
        &toml_path.display().to_string(),
        "--data",
        &front,
        "--model",
        "geometric",
        "--json",
    ]));
    assert!((figure(&v, "front", "before", "mean_absolute_error_m") - 0.723e-3).abs() < 0.5e-6);
}

#[test]
fn simulated_log_calibrates_with_the_distance_model() {
    let dir = scratch("simulate");
    let log = dir.join("log.csv");
    let truth = root().join("fixtures/reference-device/truth.toml");
    hapcal_ok(&[
        "simulate",
        "--truth",
        &truth.display().to_string(),
        "--seed",
        "3",
        "--poses",
        "120",
        "--out",
        &log.display().to_string(),
    ]);
    let text = std::fs::read_to_string(&log).unwrap();
    assert_eq!(text.lines().count(), 121, "header + 120 rows");
    // Without the external encoders' columns auto has no transmissions rung: geometric, then
    // the handle compliance (the device has a handle mass), whose angle terms absorb part of
    // the transmission errors and predicts best held out: on this log joint 4's comes out
    // negative far beyond its σ (the joint-4 transmission error it absorbs), an estimate no
    // real device has, so the ladder keeps the geometric model and says why.
    std::fs::write(&log, without_ext_columns(&text)).unwrap();
    let device = root().join("fixtures/reference-device/device.toml");
    let v = json(&hapcal(&[
        "calibrate",
        "--device",
        &device.display().to_string(),
        "--data",
        &log.display().to_string(),
        "--json",
    ]));
    assert_eq!(
        fields(&v, "cross_validation", "model"),
        ["geometric", "compliance"]
    );
    assert_eq!(v["model"], "geometric");
    assert!(
        (v["warnings"].as_array().unwrap().iter()).any(|w| {
            let w = w.as_str().unwrap();
            w.contains("the compliance model predicted the held-out rows best but was left out")
                && w.contains("joint_compliance.j4")
                && w.contains("below zero")
        }),
        "{}",
        v["warnings"]
    );
    assert!(
        v["termination"]
            .as_str()
            .unwrap()
            .starts_with("converged ("),
        "{}",
        v["termination"]
    );
    let before = figure(&v, "log", "before", "distance_rms_m");
    let after = figure(&v, "log", "after", "distance_rms_m");
    // No transmissions on raw readings: most transmission errors stay (the paper's 44.7 % case),
    // but the distance RMS still falls well below the nominal model's (several mm).
    assert!(before > 1e-3, "{before}");
    assert!(after < 0.5 * before, "{after} vs {before}");
}

/// A log CSV without its external-encoder columns (`ext1..`).
fn without_ext_columns(text: &str) -> String {
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !header[i].starts_with("ext"))
        .collect();
    let mut out = String::new();
    for line in text.lines() {
        let cells: Vec<&str> = line.split(',').collect();
        let kept: Vec<&str> = keep.iter().map(|&i| cells[i]).collect();
        out.push_str(&kept.join(","));
        out.push('\n');
    }
    out
}

/// Every subcommand's `--help` (and `-h`) is plain text: no rustdoc links or paths, and the
/// margins it states for `--model auto` are the ones the code uses.
#[test]
fn every_help_is_plain_text() {
    let top = hapcal_ok(&["--help"]);
    let top = String::from_utf8_lossy(&top.stdout).into_owned();
    // The subcommands, as `hapcal --help` lists them.
    let subcommands: Vec<String> = (top.lines())
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_owned)
        .collect();
    assert!(subcommands.len() >= 10, "{subcommands:?}");
    let mut texts = vec![("hapcal --help".to_owned(), top.clone())];
    for sub in &subcommands {
        for flag in ["--help", "-h"] {
            let out = hapcal(&[sub, flag]);
            assert!(out.status.success(), "{sub} {flag}: {}", stderr(&out));
            let text = String::from_utf8_lossy(&out.stdout).into_owned();
            texts.push((format!("hapcal {sub} {flag}"), text));
        }
    }
    for (what, text) in &texts {
        for bad in ["[", "]", "crate::"] {
            assert!(!text.contains(bad), "{what} contains {bad:?}:\n{text}");
        }
    }
    let calibrate = &texts
        .iter()
        .find(|(w, _)| w == "hapcal calibrate --help")
        .unwrap()
        .1;
    // One rule for every kind of data, with its margin.
    let ladder_margin = format!(
        "by {} standard errors",
        hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z
    );
    assert!(calibrate.contains(&ladder_margin), "{calibrate}");
    // Auto names the ladder of every kind of data.
    for kind in [
        "Measurement files",
        "Socket recordings",
        "haptic device's logs",
    ] {
        assert!(calibrate.contains(kind), "{kind}: {calibrate}");
    }
    // Every --model value is explained in words.
    for &model in hapcal_calibrate::model::ModelChoice::all() {
        let needle = format!("- {model}:");
        let line = calibrate
            .lines()
            .map(str::trim_start)
            .find(|l| l.starts_with(&needle));
        let help = line.map_or("", |l| &l[needle.len()..]);
        assert!(
            help.split_whitespace().count() >= 3,
            "--model {model}: {calibrate}"
        );
    }
}

/// The text report and the JSON name the model by its `--model` value and the fit's end in
/// words, never by a Rust name.
#[test]
fn reports_name_models_by_their_command_line_values() {
    let out = hapcal_ok(&["calibrate", "--model", "mass-compliance"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("model: mass-compliance;"), "{text}");
    assert!(text.contains("LM: converged ("), "{text}");
    for rust in ["MassCompliance", "Reached", "Geometric"] {
        assert!(!text.contains(rust), "{rust}: {text}");
    }
}

/// The two-step covariance's sensitivity `G` (paper::Sensitivity) is what step 2 really does:
/// perturbing one transmission parameter of step 1 by δ and re-running step 2 moves the
/// kinematic estimate by −G·δ, to first order (checked to 2 % of the largest move).
#[test]
fn transmission_sensitivity_predicts_how_step_2_moves() {
    use hapcal::paper::{Reference, Sensitivity, identify_kinematics, identify_transmissions};
    use hapcal_problems::CapstanProblem;
    let r = Reference::load(&root().join("fixtures/reference-device/truth.toml")).unwrap();
    let cfg = hapcal_sim::SimConfig::new(3, 120).with_noise(r.noise);
    let rows = hapcal_sim::simulate(&r.device, &r.truth, &cfg).unwrap();
    let t = identify_transmissions(&r, &rows).unwrap();
    let (_, kin) = identify_kinematics(&r, &rows, Some(&t)).unwrap();
    let s = Sensitivity::at(&r, &rows, &t, &kin).unwrap();
    // Capstan 2's ratio error (index 1 of its six parameters; capstan 2 starts at column 6).
    let delta = 2e-4;
    let mut t2 = t.clone();
    let mut col = CapstanProblem::col(&t2.capstans[1].params);
    col[1] += delta;
    t2.capstans[1].params = CapstanProblem::params(col.as_ref());
    let (_, kin2) = identify_kinematics(&r, &rows, Some(&t2)).unwrap();
    assert_eq!(kin2.covariance.free, kin.covariance.free, "same kept set");
    let moved: Vec<f64> = (kin.covariance.free.iter())
        .map(|&i| kin2.fit.x[i] - kin.fit.x[i])
        .collect();
    let largest = moved.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    assert!(
        largest > 1e-6,
        "the perturbation must move the estimate: {largest}"
    );
    for (k, m) in moved.iter().enumerate() {
        let predicted = -s.g[(k, 6 + 1)] * delta;
        assert!(
            (m - predicted).abs() < 0.02 * largest,
            "parameter {k}: moved {m:e}, predicted {predicted:e}"
        );
    }
}

#[test]
fn plan_poses_refines_the_distance_poses_of_a_separate_transmission_run() {
    let dir = scratch("plan-refine");
    let out = dir.join("poses.csv");
    let device = root().join("fixtures/reference-device/device.toml");
    let args = |extra: &[&'static str]| {
        let mut v = vec![
            "plan-poses".to_owned(),
            "--device".to_owned(),
            device.to_str().unwrap().to_owned(),
            "--count".to_owned(),
            "30".to_owned(),
            "--candidates".to_owned(),
            "60".to_owned(),
            "--criterion".to_owned(),
            "i-optimal".to_owned(),
            "--out".to_owned(),
            out.to_str().unwrap().to_owned(),
        ];
        v.extend(extra.iter().map(|s| (*s).to_owned()));
        v
    };
    let refused = Command::new(env!("CARGO_BIN_EXE_hapcal"))
        .args(args(&["--refine"]))
        .output()
        .unwrap();
    assert_exit(
        &refused,
        2,
        &[
            "refining the poses over the joint box needs distance measurements planned without the transmission rows",
        ],
    );
    // The refinement itself takes about two minutes in a debug build.
    if std::env::var_os("RUN_SLOW_TESTS").is_none() {
        return;
    }
    let run = Command::new(env!("CARGO_BIN_EXE_hapcal"))
        .args(args(&["--refine", "--separate-transmission-run"]))
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", stderr(&run));
    let text = String::from_utf8_lossy(&run.stdout);
    // Only the 28 kinematic columns; the refined criterion tr(W·M⁻¹) is a mean square in m²,
    // positive and far below 1 mm² (1e-6 m²).
    assert!(text.contains("; 28 columns"), "{text}");
    let refined: f64 = text
        .lines()
        .find_map(|l| l.split("criterion ").nth(1))
        .and_then(|rest| rest.split_whitespace().next())
        .unwrap()
        .parse()
        .unwrap();
    assert!(refined > 0.0 && refined < 1e-6, "{refined}");
    let csv = std::fs::read_to_string(&out).unwrap();
    assert_eq!(csv.lines().count(), 31);
}

#[test]
fn plan_poses_writes_the_chosen_readings_and_beats_a_random_set() {
    let dir = scratch("plan");
    let out = dir.join("poses.csv");
    let device = root().join("fixtures/reference-device/device.toml");
    let run = hapcal_ok(&[
        "plan-poses",
        "--device",
        device.to_str().unwrap(),
        "--measurement",
        "distance",
        "--count",
        "30",
        "--candidates",
        "45",
        "--out",
        out.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(&out).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("q1,q2,q3,q4,q5,q6,q7"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 30);
    // Every reading lies within the device's joint limits (docs/design.md §2).
    let limits = hapcal_io::read_device(&device).unwrap().joint_limits();
    assert_eq!(limits.len(), 7);
    for q in &rows {
        for (v, &(lo, hi)) in q.iter().zip(&limits) {
            assert!((lo..=hi).contains(v), "{q:?}");
        }
    }
    // The summary reports the planned set's log det above the random set's.
    let text = String::from_utf8_lossy(&run.stdout);
    let log_det = |name: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with("  ") && l.split_whitespace().next() == Some(name))
            .unwrap();
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    assert!(log_det("planned") > log_det("random"), "{text}");
    assert!(
        text.contains("dalpha7"),
        "the undetermined parameters are named: {text}"
    );
}

/// `hapcal diagnose` names its baseline and the kind of data in words (`--baseline` values),
/// never by a Rust name; it writes the residual maps only where `--svg` says (run from an
/// empty folder without `--svg`, the folder stays empty).
#[test]
fn diagnose_reports_name_the_baseline_and_the_data_in_words() {
    let dir = scratch("diagnose-words");
    let cwd = scratch("diagnose-words-cwd");
    let show = |p: &Path| p.display().to_string();
    let haptic = Command::new(env!("CARGO_BIN_EXE_hapcal"))
        .args([
            "diagnose",
            "--device",
            &show(&root().join("fixtures/reference-device/device.toml")),
            "--data",
            &show(&root().join("fixtures/reference-device/log.csv")),
        ])
        .current_dir(&cwd)
        .output()
        .expect("the binary runs");
    let left: Vec<_> = std::fs::read_dir(&cwd).expect("scratch folder").collect();
    assert!(left.is_empty(), "diagnose without --svg wrote {left:?}");
    assert!(
        !stderr(&haptic).contains("wrote"),
        "no file is announced: {}",
        stderr(&haptic)
    );
    let arm = on_ur10(
        "diagnose",
        &ur10_csv(),
        &["--test-last", "0.3", "--svg", &show(&dir.join("arm.svg"))],
    );
    for (out, first) in [
        (&haptic, "baseline: transmissions, "),
        (&arm, "geometric baseline: marker data, "),
    ] {
        assert!(out.status.success(), "{}", stderr(out));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.starts_with(first), "{text}");
        for rust in [
            "Transmissions",
            "Geometric",
            "Markers",
            "Sockets",
            "Distances",
        ] {
            assert!(!text.contains(rust), "{rust}: {text}");
        }
    }
    let maps = std::fs::read_to_string(dir.join("arm.svg")).expect("--svg wrote the maps");
    assert!(maps.starts_with("<svg"), "{maps}");
}

/// The same for distance logs (a device with its own cable encoder and no transmissions: the
/// reference device without its capstans and parallelogram, on its bundled log): the geometric
/// rung of `hapcal diagnose`'s ladder is `hapcal calibrate`'s cross-validated geometric error,
/// and the diagnosis's own held-out error of that baseline (a linearised cross-validation at
/// the estimate) is a distance error of the same size, not zero (it once summed position
/// residuals only, and a distance log has none).
#[test]
fn diagnosis_and_calibration_give_the_same_cross_validated_error_on_distance_logs() {
    let dir = scratch("same-model-distances");
    let device_text = std::fs::read_to_string(root().join("fixtures/reference-device/device.toml"))
        .expect("the reference device");
    let mut plain = String::new();
    let mut skip = false;
    for line in device_text.lines() {
        if line.starts_with('[') {
            skip = line.starts_with("[[capstan") || line.starts_with("[parallelogram");
        }
        if !skip {
            plain.push_str(line);
            plain.push('\n');
        }
    }
    let device = dir.join("plain.toml");
    std::fs::write(&device, plain).expect("write the device");
    let device = device.display().to_string();
    let log = root()
        .join("fixtures/reference-device/log.csv")
        .display()
        .to_string();
    let svg = dir.join("maps.svg").display().to_string();
    let common = [
        "--device",
        device.as_str(),
        "--data",
        log.as_str(),
        "--json",
    ];
    let (d, from_calibration) = same_geometric_cross_validation(&common, &svg);
    assert_eq!(d["kind"], "distances", "{d}");
    // The linearised cross-validation of the diagnosis against the refitted one of the
    // calibration: the same model about its estimate, within 1 % (0.09 % measured).
    let own = d["cv_rms_m"]
        .as_f64()
        .expect("the diagnosis's held-out RMS");
    assert!(
        (own - from_calibration).abs() <= 0.01 * from_calibration,
        "diagnosis {own} m, calibration {from_calibration} m"
    );
    // The text names the errors as distances, the stated σ as one per distance.
    let svg2 = dir.join("maps2.svg").display().to_string();
    let out = hapcal(&[
        "diagnose",
        "--device",
        device.as_str(),
        "--data",
        log.as_str(),
        "--sigma-m",
        "1e-5",
        "--svg",
        svg2.as_str(),
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("LADDER (RMS of the distance error, mm)") && text.contains("mm per distance"),
        "{text}"
    );
}

/// `--workspace`: configurations beyond a joint's training range make the ladder judge each
/// model on folds that hold out that end of the range; socket data refuse the option.
#[test]
fn a_workspace_beyond_the_training_range_adds_joint_range_folds() {
    let dir = scratch("workspace");
    let show = |p: &Path| p.display().to_string();
    let data = ur10_csv();
    // The first training row with shoulder_pan_joint 1 rad past the largest reading (the
    // UR10's readings lie within ±π, its limits ±2π).
    let text = std::fs::read_to_string(&data).expect("UR10 data");
    let mut lines = text.lines();
    let header = lines.next().expect("header");
    let pan = (header.split(','))
        .position(|c| c == "shoulder_pan_joint")
        .expect("column");
    let rows: Vec<Vec<f64>> = (lines.filter(|l| !l.trim().is_empty()))
        .map(|l| {
            l.split(',')
                .map(|v| v.trim().parse().expect("number"))
                .collect()
        })
        .collect();
    let max = rows
        .iter()
        .map(|r| r[pan])
        .fold(f64::NEG_INFINITY, f64::max);
    let mut beyond = rows[0].clone();
    beyond[pan] = max + 1.0;
    let cells: Vec<String> = beyond.iter().map(f64::to_string).collect();
    let workspace = dir.join("workspace.csv");
    std::fs::write(&workspace, format!("{header}\n{}\n", cells.join(","))).expect("write");
    let out = succeeded(on_ur10(
        "calibrate",
        &data,
        &["--workspace", &show(&workspace), "--json"],
    ));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let folds = report["range_folds"].as_array().expect("range folds");
    assert!(
        folds
            .iter()
            .any(|f| f["joint"] == "shoulder_pan_joint" && f["upper"] == true),
        "{folds:?}"
    );
    // Socket recordings have no joint-range folds: the option is refused by name.
    let sockets = hapcal(&["calibrate", "--workspace", &show(&workspace)]);
    assert_exit(&sockets, 2, &["--workspace"]);
}

/// The diagnosis and the calibration fit one model with one code path: on the bundled UR10
/// poses (last 30 % held out), each kinematic rung of `hapcal diagnose`'s ladder gives the
/// held-out position RMS that `hapcal calibrate --model <rung>` reports for the same rows.
/// Both are the same least-squares solution evaluated on the same rows, so they agree to
/// rounding (1e-9 relative), far below the 1 % a second implementation would differ by.
#[test]
fn diagnosis_and_calibration_give_the_same_held_out_error_for_the_same_model() {
    let ur10 = root().join("fixtures/figaroh/ur10");
    let urdf = ur10.join("ur10_robot.urdf").display().to_string();
    let data = ur10.join("calibration.csv").display().to_string();
    let svg = scratch("same-model").join("maps.svg").display().to_string();
    let common = [
        "--device",
        urdf.as_str(),
        "--tip",
        "wrist_3_link",
        "--data",
        data.as_str(),
        "--test-last",
        "0.3",
        "--json",
    ];
    let d = json_of("diagnose", &common, &["--svg", svg.as_str()]);
    let ladder = d["ladder"].as_array().expect("a ladder");
    let mut compared = 0;
    for rung in ["frames-only", "joint-offsets", "geometric"] {
        let from_diagnosis = (ladder.iter())
            .find(|r| r["rung"] == rung)
            .and_then(|r| r["test_rms_m"][0].as_f64())
            .unwrap_or_else(|| panic!("the ladder has no {rung} rung: {ladder:?}"));
        let c = json_of("calibrate", &common, &["--model", rung]);
        let from_calibration = set_figure(&c, "test", "position_rms_m");
        assert!(
            (from_diagnosis - from_calibration).abs() <= 1e-9 * from_calibration,
            "{rung}: diagnose {from_diagnosis} m, calibrate {from_calibration} m"
        );
        compared += 1;
    }
    assert_eq!(compared, 3);
}

/// The same for socket recordings: the geometric rung's cross-validated error in `hapcal
/// diagnose`'s ladder is the one `hapcal calibrate`'s model table reports for geometric (one
/// cross-validation, the same folds), on MUKCa's kuka_14.
#[test]
fn diagnosis_and_calibration_give_the_same_cross_validated_error_on_sockets() {
    let data = root().join("fixtures/mukca/data/kuka_14");
    let front = data.join("front").display().to_string();
    let left_back = data.join("left_back").display().to_string();
    let svg = scratch("same-model-sockets")
        .join("maps.svg")
        .display()
        .to_string();
    let urdf = iiwa();
    let common = [
        "--device",
        urdf.as_str(),
        "--tip",
        "ball_link",
        "--data",
        front.as_str(),
        "--test",
        left_back.as_str(),
        "--json",
    ];
    same_geometric_cross_validation(&common, &svg);
}

/// Runs `hapcal diagnose` and `hapcal calibrate` with the `common` flags and checks that the
/// geometric rung of the diagnosis's ladder is the calibration's cross-validated geometric
/// error (one cross-validation, the same folds; 1e-9 relative). Returns the diagnosis's JSON
/// and that error, m.
fn same_geometric_cross_validation(common: &[&str], svg: &str) -> (Value, f64) {
    let d = json_of("diagnose", common, &["--svg", svg]);
    let from_diagnosis = (d["ladder"].as_array().expect("a ladder").iter())
        .find(|r| r["rung"] == "geometric")
        .and_then(|r| r["cv_rms_m"].as_f64())
        .expect("a geometric rung");
    let c = json_of("calibrate", common, &[]);
    let from_calibration = (c["cross_validation"]
        .as_array()
        .expect("a model table")
        .iter())
    .find(|m| m["model"] == "geometric")
    .and_then(|m| m["heldout_rms_m"].as_f64())
    .expect("geometric in the model table");
    assert!(
        (from_diagnosis - from_calibration).abs() <= 1e-9 * from_calibration,
        "diagnose {from_diagnosis} m, calibrate {from_calibration} m"
    );
    (d, from_calibration)
}

/// The same for the cross-validated errors of measurement files (TIAGo's motion capture, no
/// held-out rows): every kinematic rung of the diagnosis's ladder has the cross-validated RMS
/// of the calibration's ladder (one cross-validation, the same folds; 1e-9 relative).
#[test]
fn diagnosis_and_calibration_give_the_same_cross_validated_error_on_markers() {
    let tiago = root().join("fixtures/figaroh/tiago");
    let urdf = tiago.join("tiago.urdf").display().to_string();
    let data = (tiago.join("qualysis_base_hand_calibration.csv"))
        .display()
        .to_string();
    let svg = scratch("same-model-markers")
        .join("maps.svg")
        .display()
        .to_string();
    let common = [
        "--device",
        urdf.as_str(),
        "--tip",
        "arm_7_link",
        "--data",
        data.as_str(),
        "--json",
    ];
    let mut diagnose = vec!["diagnose"];
    diagnose.extend(common);
    diagnose.extend(["--svg", svg.as_str()]);
    let d = json(&hapcal(&diagnose));
    let mut calibrate = vec!["calibrate"];
    calibrate.extend(common);
    let c = json(&hapcal(&calibrate));
    let cv = |v: &Value, key: &str, rung: &str| {
        (v["ladder"].as_array().expect("a ladder").iter())
            .find(|r| r["rung"] == rung)
            .and_then(|r| r[key].as_f64())
            .unwrap_or_else(|| panic!("no {rung} rung: {v}"))
    };
    for rung in ["frames-only", "joint-offsets", "geometric"] {
        let (from_diagnosis, from_calibration) =
            (cv(&d, "cv_rms_m", rung), cv(&c, "heldout_rms_m", rung));
        assert!(
            (from_diagnosis - from_calibration).abs() <= 1e-9 * from_calibration,
            "{rung}: diagnose {from_diagnosis} m, calibrate {from_calibration} m"
        );
    }
}
