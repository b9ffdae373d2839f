//! `hapcal predict`: the UR10 calibrated by `hapcal calibrate --out` on figaroh's bundled
//! poses (predictions and errors against the runtime and the calibration's own report), and
//! a hand-written two-joint arm with a schema-1 calibration record (region flag, σ).

use std::path::{Path, PathBuf};
use std::process::Output;

use hapcal_runtime::{Pose, Robot};
use serde_json::Value;

use crate::{hapcal, hapcal_ok, root, scratch, set_figure, show, stderr, succeeded, ur10_csv};

/// The UR10 calibrated (geometric) on the bundled poses, written as `dir/ur10.urdf` with its
/// sidecar; returns the URDF and the calibration's JSON report.
pub(crate) fn calibrated_ur10(dir: &Path) -> (PathBuf, Value) {
    let ur10 = root().join("fixtures/figaroh/ur10");
    let out = dir.join("ur10.urdf");
    let run = hapcal_ok(&[
        "calibrate",
        "--device",
        &show(&ur10.join("ur10_robot.urdf")),
        "--tip",
        "wrist_3_link",
        "--data",
        &show(&ur10.join("calibration.csv")),
        "--model",
        "geometric",
        "--json",
        "--out",
        &show(&out),
    ]);
    let report = serde_json::from_slice(&run.stdout).expect("one JSON document");
    (out, report)
}

/// The rows of a CSV file with a header: the header's names and each row's numbers (NaN for
/// a cell that is not a number).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    crate::read_table(path, |c| c.parse().unwrap_or(f64::NAN))
}

fn column(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

/// R = Rz(yaw)·Ry(pitch)·Rx(roll), figaroh's convention of `phix, phiy, phiz`.
fn rpy_rotation(roll: f64, pitch: f64, yaw: f64) -> [[f64; 3]; 3] {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

/// At the training rows: the predicted tip links (root frame) are the runtime's deflected
/// tip poses and the predicted markers (instrument frame) the runtime's poses composed with
/// the sidecar's frames, to 1e-12 m; the errors against the measured columns are computed
/// here from the file and the runtime (position RMS and orientation RMS), and agree with the
/// calibration's own report for its training rows (a second implementation of the model:
/// `hapcal_problems::CalibratedModel` before writing, the written URDF and sidecar after).
#[test]
fn predictions_at_the_training_rows_are_the_runtime_s_and_the_errors_the_calibration_s() {
    let dir = scratch("predict-ur10");
    let (urdf, report) = calibrated_ur10(&dir);
    let data = ur10_csv();
    let root_csv = dir.join("root.csv");
    let run = succeeded(predict_tip(
        &urdf,
        "wrist_3_link",
        &data,
        &["--poses", "--out", &show(&root_csv)],
    ));
    let summary = String::from_utf8_lossy(&run.stdout);
    assert!(summary.contains("predicted 23 rows"), "{summary}");
    let run = succeeded(predict_tip(
        &urdf,
        "wrist_3_link",
        &data,
        &["--instrument-frame", "--json"],
    ));
    let v: Value = serde_json::from_slice(&run.stdout).expect("one JSON document");

    let robot = Robot::load_urdf(&urdf, &["wrist_3_link"]).expect("the written robot");
    let instrument = robot.frame("instrument").expect("an instrument frame");
    let marker = robot.frame("marker1").unwrap_or(Pose::IDENTITY);
    let mut ws = robot.workspace();
    let (header, rows) = read_csv(&data);
    let (out_header, predicted) = read_csv(&root_csv);
    assert_eq!(predicted.len(), rows.len());
    let joints: Vec<usize> = (robot.joint_names().iter())
        .map(|j| column(&header, j))
        .collect();
    let [x, y, z, qw] = ["x", "y", "z", "qw"].map(|c| column(&out_header, c));
    let (mut sq_position, mut sq_angle) = (0.0, 0.0);
    let json_rows = v["rows"].as_array().expect("rows");
    for ((row, out), json_row) in rows.iter().zip(&predicted).zip(json_rows) {
        let q: Vec<f64> = joints.iter().map(|&c| row[c]).collect();
        let mut tip = [Pose::IDENTITY];
        robot
            .deflected_tip_poses(&q, &mut ws, &mut tip)
            .expect("valid");
        let t = tip[0].translation_m;
        for (a, c) in [x, y, z].into_iter().enumerate() {
            assert!((out[c] - t[a]).abs() <= 1e-12, "{} vs {}", out[c], t[a]);
        }
        assert!(out[qw] >= 0.0 && out[qw] <= 1.0, "{out:?}");
        let m = instrument.compose(&tip[0]).compose(&marker);
        let p = &json_row["tips"][0]["position_m"];
        for a in 0..3 {
            let got = p[a].as_f64().expect("a number");
            assert!((got - m.translation_m[a]).abs() <= 1e-12, "{got} vs {m:?}");
        }
        // The errors, from the file's columns.
        let measured = ["x1", "y1", "z1"].map(|c| row[column(&header, c)]);
        sq_position += (0..3)
            .map(|a| (m.translation_m[a] - measured[a]).powi(2))
            .sum::<f64>();
        let [roll, pitch, yaw] = ["phix1", "phiy1", "phiz1"].map(|c| row[column(&header, c)]);
        let r = rpy_rotation(roll, pitch, yaw);
        // trace(Rmᵀ·Rp) = 1 + 2 cos θ.
        let trace: f64 = (0..3)
            .flat_map(|i| (0..3).map(move |k| (i, k)))
            .map(|(i, k)| r[k][i] * m.rotation[k][i])
            .sum();
        let angle = ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
        sq_angle += angle * angle;
    }
    let n = rows.len() as f64;
    let rms_position = (sq_position / n).sqrt();
    let rms_angle = (sq_angle / n).sqrt();
    let errors = &v["errors"];
    let reported = errors["position_m"]["rms"].as_f64().expect("position RMS");
    assert!(
        (reported - rms_position).abs() <= 1e-12 + 1e-9 * rms_position,
        "{reported} vs {rms_position}"
    );
    assert_eq!(errors["position_m"]["count"], 23);
    // acos near 1 loses digits: 1e-6 relative covers rounding at these sub-degree angles.
    let reported_angle = errors["orientation_rad"]["rms"]
        .as_f64()
        .expect("orientation");
    assert!(
        (reported_angle - rms_angle).abs() <= 1e-6 * rms_angle,
        "{reported_angle} vs {rms_angle}"
    );
    // The calibration's report for its training rows: the same model, evaluated by the
    // calibration library before writing (1e-9 relative: the URDF's origins are written with
    // every digit).
    let from_calibration = set_figure(&report, "train", "position_rms_m");
    assert!(
        (reported - from_calibration).abs() <= 1e-9 * from_calibration,
        "predict {reported} m, calibrate {from_calibration} m"
    );
}

/// A planar two-joint arm (no link masses: lumped unit weights) with links of 0.5 and 0.4 m.
const ARM: &str = r#"<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <link name="upper"/>
  <link name="fore"/>
  <link name="tip"/>
  <joint name="joint1" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <joint name="joint2" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.5 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <joint name="tip_joint" type="fixed">
    <parent link="fore"/><child link="tip"/>
    <origin xyz="0.4 0 0" rpy="0 0 0"/>
  </joint>
</robot>
"#;

/// The compliance of joint 2 (rad/m under lumped unit weights) and its standard deviation.
const K2: f64 = 2e-3;
const K2_STD: f64 = 4e-4;

/// Writes the arm and a schema-1 record: joint 2's compliance with its σ and a 1 × 1
/// covariance, and the training region joint1 ∈ [−0.5, 0.5], joint2 ∈ [0.2, 1.2] rad.
fn calibrated_arm(dir: &Path) -> PathBuf {
    let urdf = dir.join("arm.urdf");
    std::fs::write(&urdf, ARM).expect("write");
    let record = format!(
        r#"schema_version = 1
model = "compliance"
tips = ["tip"]

[torque]
source = "lumped-unit-weights"
gravity_direction = [0.0, 0.0, -1.0]
gravity_m_s2 = 9.80665
tips = ["tip"]

[region]
rows = 40
joint = [
  {{ name = "joint1", min = -0.5, max = 0.5, unit = "rad" }},
  {{ name = "joint2", min = 0.2, max = 1.2, unit = "rad" }},
]

[values]
"compliance.joint2" = {{ value = {K2:?}, std = {K2_STD:?}, unit = "rad/m" }}

[covariance]
names = ["compliance.joint2"]
lower = [{:?}]
"#,
        K2_STD * K2_STD
    );
    std::fs::write(dir.join("arm.calibration.toml"), record).expect("write");
    urdf
}

/// Joint readings only (no measured columns): line 2 inside the region, line 3 with joint2
/// 0.3 rad above its training range (past the 5 % slack of 0.05 rad), line 4 with joint1
/// 0.04 rad below it (within the slack: inside).
const READINGS: &str = "joint1,joint2\n0.1,0.7\n0.2,1.5\n-0.54,0.5\n";

fn predict_json(urdf: &Path, readings: &Path) -> Value {
    let run = succeeded(predict_arm(urdf, readings, &["--json"]));
    serde_json::from_slice(&run.stdout).expect("one JSON document")
}

/// The arm calibrated in the scratch folder `name` ([`calibrated_arm`]) and [`READINGS`]
/// written there: the folder, the URDF, the readings' path and `predict --json` of them.
fn arm_predicted(name: &str) -> (PathBuf, PathBuf, PathBuf, Value) {
    let dir = scratch(name);
    let urdf = calibrated_arm(&dir);
    let readings = dir.join("readings.csv");
    std::fs::write(&readings, READINGS).expect("write");
    let v = predict_json(&urdf, &readings);
    (dir, urdf, readings, v)
}

/// `hapcal predict` of the arm `urdf` (tip `tip`) on `readings`, with `extra`.
fn predict_arm(urdf: &Path, readings: &Path, extra: &[&str]) -> Output {
    predict_tip(urdf, "tip", readings, extra)
}

/// `hapcal predict` of the robot `urdf` at the tip link `tip` on `readings`, with `extra`.
fn predict_tip(urdf: &Path, tip: &str, readings: &Path, extra: &[&str]) -> Output {
    let (urdf, readings) = (show(urdf), show(readings));
    let mut args = vec![
        "predict", "--device", &urdf, "--tip", tip, "--data", &readings,
    ];
    args.extend_from_slice(extra);
    hapcal(&args)
}

/// The region flag (needs the runtime to read the record's `[region]`), in `predict` and in
/// `compensate`.
#[test]
fn a_reading_outside_the_calibration_s_region_is_flagged() {
    let (dir, urdf, readings, v) = arm_predicted("predict-region");
    let rows = v["rows"].as_array().expect("rows");
    let flags: Vec<&Value> = rows.iter().map(|r| &r["outside_region"]).collect();
    assert!(flags[0].is_null() && flags[2].is_null(), "{flags:?}");
    assert_eq!(flags[1]["joint"], "joint2");
    let past = flags[1]["past"].as_f64().expect("a distance");
    assert!((past - 0.3).abs() < 1e-12, "{past}");
    assert_eq!(v["n_outside_region"], 1);
    // The text names the line, the joint and the distance.
    let out = dir.join("predicted.csv");
    let run = predict_arm(&urdf, &readings, &["--out", &show(&out)]);
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        text.contains(&format!(
            "{}:3: joint2 0.3000 rad above its training range",
            readings.display()
        )),
        "{text}"
    );
    let (header, written) = read_csv(&out);
    let flag = column(&header, "outside_region");
    let flags: Vec<f64> = written.iter().map(|r| r[flag]).collect();
    assert_eq!(flags, [0.0, 1.0, 0.0]);
    // compensate: the targets where the arm puts its tip at those readings; the command for
    // line 3 (the second target) lies outside the region and is listed.
    let positions: Vec<&Value> = rows.iter().map(|r| &r["tips"][0]["position_m"]).collect();
    let mut targets = String::from("x,y,z,joint1,joint2\n");
    for (p, q) in positions.iter().zip(["0.1,0.7", "0.2,1.5", "-0.54,0.5"]) {
        targets.push_str(&format!("{},{},{},{q}\n", p[0], p[1], p[2]));
    }
    let targets_path = dir.join("targets.csv");
    std::fs::write(&targets_path, targets).expect("write");
    let run = crate::compensate(&urdf, "tip", &targets_path, &dir.join("commands.csv"));
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(
        text.contains("outside the calibration's region")
            && text.contains(&format!("{}:3: joint2", targets_path.display()))
            && !text.contains(&format!("{}:2:", targets_path.display())),
        "{text}"
    );
}

/// σ of the prediction (needs `Robot::with_value`): with one compliance and its variance, σ
/// is |∂p/∂k|·std, the derivative computed here by central differences of two robots with
/// their compliances set through `Robot::with_compliances` (another path than the
/// predictor's `with_value`). The step here is 1e-2 std (the predictor's 1e-3): the two agree
/// to the differences' truncation, far below 1e-5 relative for a deflection this smooth in k.
#[test]
fn sigma_is_the_derivative_times_the_standard_deviation() {
    let (_, urdf, _, v) = arm_predicted("predict-sigma");
    assert_eq!(v["uncertainty"], "covariance", "{v}");
    assert_eq!(v["n_values"], 1, "{v}");
    let robot = Robot::load_urdf(&urdf, &["tip"]).expect("the arm");
    let h = 1e-2 * K2_STD;
    let plus = robot.with_compliances(&[0.0, K2 + h]).expect("valid");
    let minus = robot.with_compliances(&[0.0, K2 - h]).expect("valid");
    let mut ws = robot.workspace();
    let rows = v["rows"].as_array().expect("rows");
    for (row, q) in rows.iter().zip([[0.1, 0.7], [0.2, 1.5], [-0.54, 0.5]]) {
        let (mut a, mut b) = ([Pose::IDENTITY], [Pose::IDENTITY]);
        plus.deflected_tip_poses(&q, &mut ws, &mut a)
            .expect("valid");
        minus
            .deflected_tip_poses(&q, &mut ws, &mut b)
            .expect("valid");
        let derivative = (0..3)
            .map(|i| ((a[0].translation_m[i] - b[0].translation_m[i]) / (2.0 * h)).powi(2))
            .sum::<f64>()
            .sqrt();
        let expected = derivative * K2_STD;
        let sigma = row["tips"][0]["sigma_m"].as_f64().expect("a σ");
        assert!(expected > 1e-6, "the compliance moves the tip: {expected}");
        assert!(
            (sigma - expected).abs() <= 1e-5 * expected,
            "{q:?}: σ {sigma} m, |∂p/∂k|·std {expected} m"
        );
    }
}

/// Bad input: a reading that is not a number is named at file:line:column; an output over
/// the data file is refused. (The arm without a record: its predictions carry no σ.)
#[test]
fn bad_readings_and_outputs_are_named() {
    let dir = scratch("predict-bad");
    let urdf = dir.join("arm.urdf");
    std::fs::write(&urdf, ARM).expect("write");
    let readings = dir.join("readings.csv");
    std::fs::write(&readings, "joint1,joint2\n0.1,0.7\n0.2,abc\n").expect("write");
    let run = predict_arm(&urdf, &readings, &[]);
    assert_eq!(run.status.code(), Some(2));
    let err = stderr(&run);
    assert!(
        err.contains(&format!("{}:3:2", readings.display())) && err.contains("abc"),
        "{err}"
    );
    let run = predict_arm(&urdf, &readings, &["--out", &show(&readings)]);
    assert_eq!(run.status.code(), Some(2));
    assert!(
        std::fs::read_to_string(&readings).is_ok_and(|t| t.contains("abc")),
        "the input is untouched"
    );
    // Good readings of the robot without a record: predicted, no σ, said so.
    std::fs::write(&readings, "joint1,joint2\n0.1,0.7\n").expect("write");
    let run = succeeded(predict_arm(&urdf, &readings, &[]));
    let csv = String::from_utf8_lossy(&run.stdout);
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("line,x,y,z,sigma_m,outside_region,region_joint,region_past")
    );
    // Rigid: x = 0.5 cos 0.1 + 0.4 cos 0.8, z = 0.1 − 0.5 sin 0.1 − 0.4 sin 0.8 (rotation
    // about y takes x towards −z).
    let cells: Vec<&str> = lines.next().expect("a row").split(',').collect();
    let x: f64 = cells[1].parse().expect("x");
    let z: f64 = cells[3].parse().expect("z");
    assert!(
        (x - (0.5 * 0.1f64.cos() + 0.4 * 0.8f64.cos())).abs() < 1e-12,
        "{cells:?}"
    );
    assert!(
        (z - (0.1 - 0.5 * 0.1f64.sin() - 0.4 * 0.8f64.sin())).abs() < 1e-12,
        "{cells:?}"
    );
    assert_eq!(&cells[4..], ["", "0", "", ""]);
    assert!(stderr(&run).contains("no σ"), "{}", stderr(&run));
}
