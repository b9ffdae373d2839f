//! `hapcal predict` and `hapcal compensate` on device files as `hapcal calibrate --out
//! device.toml` writes them: a serial robot's D-H table (industrial_calibration's two-axis
//! positioner, calibrated with the compliance model) and a haptic device (the reference
//! device on its bundled log). Predicting the training rows of the written file reproduces the
//! calibration's own training RMS: the calibration library evaluated the model before
//! writing, the runtime evaluates the written file.

use std::path::Path;

use serde_json::Value;

use crate::{
    assert_exit, compensate_with, hapcal, root, scratch, set_figure, show, stderr, succeeded,
};

/// Agreement of predict's and calibrate's training RMS, m: the same model in two
/// implementations, written with every digit; rounding stays far below it.
const TOLERANCE_M: f64 = 1e-9;

/// Runs `hapcal` with `args` and returns its JSON document (exit 0 asserted).
fn json_of(args: &[&str]) -> Value {
    let run = hapcal(args);
    assert!(run.status.success(), "{args:?}: {}", stderr(&run));
    serde_json::from_slice(&run.stdout).expect("one JSON document")
}

/// `hapcal calibrate --model compliance --json` of `device` on `data`, written to `out`: the
/// report and the written device file's text.
fn calibrated_with_compliance(device: &Path, data: &Path, out: &Path) -> (Value, String) {
    let report = json_of(&[
        "calibrate",
        "--device",
        &show(device),
        "--data",
        &show(data),
        "--model",
        "compliance",
        "--json",
        "--out",
        &show(out),
    ]);
    let written = std::fs::read_to_string(out).expect("the calibrated device file");
    (report, written)
}

/// Asserts that every row of `predict --json`'s `v` lies in the calibration's region and
/// that its RMS of `errors` (`position_m` or `distance_m`) is the report's training figure
/// `key` within [`TOLERANCE_M`].
fn assert_reproduces_training(v: &Value, report: &Value, errors: &str, key: &str) {
    assert_eq!(v["n_outside_region"], 0, "training rows lie in the region");
    let predicted = v["errors"][errors]["rms"].as_f64().expect("the errors");
    let calibrated = set_figure(report, "train", key);
    assert!(
        (predicted - calibrated).abs() <= TOLERANCE_M,
        "predict {predicted} m, calibrate {calibrated} m"
    );
}

#[test]
fn a_calibrated_dh_robot_predicts_its_training_rows_as_calibrate_reported_them() {
    let dir = scratch("predict-positioner");
    let fixtures = root().join("fixtures/industrial-calibration");
    let device = fixtures.join("two_axis_positioner.toml");
    let data = fixtures.join("measurements.yaml");
    let out = dir.join("positioner.toml");
    let (report, written) = calibrated_with_compliance(&device, &data, &out);
    assert_eq!(report["model"], "compliance", "{}", report["model"]);
    assert!(written.contains("lumped-unit-weights"), "{written}");
    let v = json_of(&[
        "predict",
        "--device",
        &show(&out),
        "--data",
        &show(&data),
        "--json",
    ]);
    let n_rows = v["rows"].as_array().expect("rows").len();
    assert!(n_rows > 10, "{n_rows} rows");
    assert_eq!(v["uncertainty"], "covariance", "{}", v["uncertainty_note"]);
    let sigma = v["rows"][0]["tips"][0]["sigma_m"].as_f64().expect("a σ");
    assert!(sigma > 0.0 && sigma < 1e-2, "σ {sigma} m");
    assert_reproduces_training(&v, &report, "position_m", "position_rms_m");
    // The instrument frame: the same errors, the predictions are the markers.
    let framed = json_of(&[
        "predict",
        "--device",
        &show(&out),
        "--data",
        &show(&data),
        "--instrument-frame",
        "--json",
    ]);
    assert_eq!(framed["frame"], "instrument");
    // A device file's chain has one tip: --tip is refused in words.
    let refused = hapcal(&[
        "predict",
        "--device",
        &show(&out),
        "--tip",
        "tool0",
        "--data",
        &show(&data),
    ]);
    assert_exit(&refused, 2, &["predict it without --tip"]);
    compensate_onto_predictions(&dir, &out, &v);
}

/// `hapcal compensate` on the calibrated positioner: the first rows' predicted tips (root
/// frame, `predict --json`'s `root_frame`) as targets are reached.
fn compensate_onto_predictions(dir: &Path, device: &Path, root_frame: &Value) {
    let mut targets = String::from("x,y,z\n");
    for row in root_frame["rows"].as_array().expect("rows").iter().take(5) {
        let p = &row["tips"][0]["position_m"];
        let c: Vec<String> = (0..3)
            .map(|a| format!("{:?}", p[a].as_f64().expect("a number")))
            .collect();
        targets.push_str(&format!("{}\n", c.join(",")));
    }
    let targets_path = dir.join("targets.csv");
    std::fs::write(&targets_path, targets).expect("write the targets");
    let commands = dir.join("commands.csv");
    succeeded(compensate_with(device, None, &targets_path, &commands, &[]));
    let text = std::fs::read_to_string(&commands).expect("the commands");
    assert_eq!(text.lines().count(), 6, "{text}");
    assert!(text.starts_with("line,q1,q2,"), "{text}");
}

#[test]
fn a_calibrated_haptic_device_predicts_its_log_s_distances_as_calibrate_reported_them() {
    let dir = scratch("predict-haptic");
    let fixtures = root().join("fixtures/reference-device");
    let log = fixtures.join("log.csv");
    let out = dir.join("calibrated.toml");
    let (report, written) = calibrated_with_compliance(&fixtures.join("device.toml"), &log, &out);
    assert!(written.contains("joint_compliance.j"), "{written}");
    let csv = dir.join("handle.csv");
    let v = json_of(&[
        "predict",
        "--device",
        &show(&out),
        "--data",
        &show(&log),
        "--json",
        "--out",
        &show(&csv),
    ]);
    assert_eq!(v["frame"], "base");
    assert_eq!(v["tips"][0], "handle");
    assert_eq!(v["rows"].as_array().expect("rows").len(), 200);
    assert_eq!(v["errors"]["distance_m"]["count"], 200);
    assert_reproduces_training(&v, &report, "distance_m", "distance_rms_m");
    // The handle's predicted position is at the predicted distance: the CSV's x, y, z.
    let text = std::fs::read_to_string(&csv).expect("the predictions");
    assert!(
        text.starts_with("line,x,y,z,sigma_m,outside_region"),
        "{text}"
    );
    // A haptic device has no instrument frame: refused in words.
    let refused = hapcal(&[
        "predict",
        "--device",
        &show(&out),
        "--data",
        &show(&log),
        "--instrument-frame",
    ]);
    assert_exit(&refused, 2, &["it has no instrument frame"]);
}
