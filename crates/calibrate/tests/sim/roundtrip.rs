//! The runtime against the calibration library on a written calibration, as the round-trip
//! tests compare them: the calibration of simulated tables, each one's marker positions, the
//! largest distance between the two, and a record value set in both.
#![allow(clippy::unwrap_used, dead_code, unreachable_pub)]

use std::path::Path;

use hapcal_calibrate::inputs::Plan;
use hapcal_calibrate::measured::{Robot as ArmRobot, run_tables};
use hapcal_calibrate::report::Outcome;
use hapcal_io::{Device, MeasurementTable};
use hapcal_problems::CalibratedModel;
use hapcal_runtime::{Pose, PredictionFrame, Predictor, Robot};

/// Calibrates `plan` on the tables `train` and `test` of `robot` (`run_tables`) and clears
/// the files an earlier run wrote at `out` (the output and its sidecar).
pub fn calibrate_tables(
    plan: &Plan,
    device: &Device,
    robot: &ArmRobot,
    train: MeasurementTable,
    test: MeasurementTable,
    out: &Path,
) -> Outcome {
    let start = std::time::Instant::now();
    let outcome = run_tables(plan, device, robot, vec![train], vec![test], start).unwrap();
    let _ = std::fs::remove_file(out);
    let _ = std::fs::remove_file(out.with_extension("calibration.toml"));
    outcome
}

/// A fresh folder `name` of this test binary under the system's temporary directory.
pub fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "hapcal-{}-{}-{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Distance between two points, m.
pub fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The runtime's position of marker `k` (on tip `k`) in the instrument frame at readings `q`.
pub fn runtime_marker(robot: &Robot, q: &[f64], k: usize) -> [f64; 3] {
    let mut ws = robot.workspace();
    let mut poses = vec![Pose::IDENTITY; robot.tip_names().len()];
    robot.deflected_tip_poses(q, &mut ws, &mut poses).unwrap();
    let instrument = robot.frame("instrument").unwrap_or(Pose::IDENTITY);
    let marker = robot
        .frame(&format!("marker{}", k + 1))
        .unwrap_or(Pose::IDENTITY);
    instrument.compose(&poses[k]).compose(&marker).translation_m
}

/// Largest distance between the runtime's and the library's markers (one on each of the
/// first `n_tips` tips) over `rows`, m.
pub fn worst_gap(
    robot: &Robot,
    library: &CalibratedModel,
    rows: &[Vec<f64>],
    n_tips: usize,
) -> f64 {
    let tips: Vec<usize> = (0..n_tips).collect();
    let mut worst: f64 = 0.0;
    for q in rows {
        for (k, pose) in library.end_poses_of(&tips, q).iter().enumerate() {
            let p = pose.translation.vector;
            worst = worst.max(distance(&runtime_marker(robot, q, k), &[p.x, p.y, p.z]));
        }
    }
    worst
}

/// `runtime` with its record's value `name` set to `value`, and the same value set in
/// `library` (whose joints are `joint_names`); panics where either does not hold the value.
pub fn set_in_both(
    runtime: &Robot,
    library: &mut CalibratedModel,
    joint_names: &[String],
    name: &str,
    value: f64,
) -> Robot {
    let set = runtime.with_value(name, value).unwrap();
    assert!(
        hapcal_calibrate::record::set_model_value(library, joint_names, name, value),
        "{name} is not a value of the library's model"
    );
    set
}

/// How far the held-out position RMS the report of `outcome` prints (its test set, m) lies
/// from the one `hapcal predict` reports for `test` on the written robot `robot`
/// (`predict::predict_table`: the errors against the measured columns), m.
pub fn held_out_rms_gap(outcome: &Outcome, robot: &Robot, test: &MeasurementTable) -> f64 {
    let predictor = Predictor::new(robot, PredictionFrame::Root).unwrap();
    let (_, errors) =
        hapcal_calibrate::predict::predict_table(&predictor, test, false, &mut |_| {}).unwrap();
    let predicted = errors.expect("measured columns").position.rms();
    let reported = (outcome.report.placements.iter())
        .find(|s| s.role == hapcal_calibrate::report::SetRole::Test)
        .and_then(|s| s.after.pose)
        .expect("a test set with pose figures")
        .position_rms_m;
    (reported - predicted).abs()
}
