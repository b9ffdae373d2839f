//! Every model the ladder can choose on measurement files reaches the runtime: calibrate a
//! simulated robot with the model, write the calibrated URDF and its record
//! (`calibrate::write_outputs_beside`), load them with `hapcal_runtime::Robot`, and the
//! runtime's marker positions at the training and held-out configurations equal the
//! calibration library's own predictions (`CalibratedModel::end_poses_of`) within 1e-9 m, and
//! the held-out RMS the report prints is `hapcal predict`'s on the written files within 1e-9 m. The
//! values are then enlarged until each effect moves the markers by millimetres, in the
//! library's model and through `Robot::with_value`, and the two must still agree: a runtime
//! that left an effect out, or evaluated it on another geometry, fails there. A haptic
//! device's logs, calibrated with every model of its ladder, report the test log's distance
//! RMS `hapcal predict` gives on the device file `--out` writes, within 1e-9 m.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "sim/haptic_log.rs"]
mod haptic_log;
#[path = "sim/humanoid.rs"]
mod humanoid;
#[path = "sim/roundtrip.rs"]
mod roundtrip;
#[path = "sim/split_arm.rs"]
mod split_arm;

use roundtrip::{
    calibrate_tables, distance, held_out_rms_gap, runtime_marker, scratch, set_in_both, worst_gap,
};

use hapcal_calibrate::model::ModelName;
use std::path::{Path, PathBuf};

use hapcal_calibrate::inputs::Plan;
use hapcal_calibrate::measured::Robot as ArmRobot;
use hapcal_calibrate::model::ModelChoice;
use hapcal_calibrate::report::Outcome;
use hapcal_io::MeasurementTable;
use hapcal_runtime::{Pose, Robot};

/// Agreement required between the runtime and the library, m: both evaluate the same
/// equations in double precision; 1e-9 m leaves six orders of magnitude to rounding.
const TOLERANCE_M: f64 = 1e-9;

/// The calibration `calibrated` returns, written to its path with its record.
fn written((outcome, out): (Outcome, PathBuf)) -> (Outcome, PathBuf) {
    hapcal_calibrate::calibrate::write_outputs_beside(&outcome, &out, &[]).unwrap();
    (outcome, out)
}

/// Calibrates `model` on `train`, `test`; the path `<dir>/cal-<model>.urdf` to write it to,
/// cleared of the files of an earlier run.
fn calibrated(
    urdf: &Path,
    tips: &[&str],
    robot: &ArmRobot,
    model: ModelChoice,
    train: MeasurementTable,
    test: MeasurementTable,
    dir: &Path,
) -> (Outcome, PathBuf) {
    let plan = Plan {
        device: urdf.to_path_buf(),
        tip: tips[0].to_owned(),
        tips: tips[1..].iter().map(|t| (*t).to_owned()).collect(),
        data: Vec::new(),
        test: Vec::new(),
        model,
        ..Plan::bundled_default()
    };
    let tip_names: Vec<String> = plan.tips.clone();
    let device = hapcal_calibrate::data::load_device_tips(urdf, tips[0], &tip_names).unwrap();
    let out = dir.join(format!("cal-{model}.urdf"));
    let outcome = calibrate_tables(&plan, &device, robot, train, test, &out);
    (outcome, out)
}

/// The scale that makes a value of this name move a marker by millimetres (a compliance of
/// 1e-4 rad/(N·m) under tens of N·m; a harmonic of 2 mrad), or `None` for a value the check
/// leaves (kinematic deviations are exercised as identified).
fn enlarged(name: &str, unit: &str) -> Option<f64> {
    if name.starts_with("compliance.") || name.starts_with("transversal.") {
        Some(if unit == "rad/m" { 2e-3 } else { 1e-4 })
    } else if name.starts_with("harmonic.") {
        Some(2e-3)
    } else {
        None
    }
}

/// Writes, loads and compares `model`, then again with enlarged values; returns the two gaps
/// and how far the enlarged effects moved the markers.
fn round_trip(
    urdf: &Path,
    tips: &[&str],
    robot: &ArmRobot,
    model: ModelChoice,
    train: MeasurementTable,
    test: MeasurementTable,
) -> (f64, f64, f64) {
    let rows: Vec<Vec<f64>> = (train.rows.iter().chain(&test.rows))
        .map(|r| r.q.to_vec())
        .collect();
    let dir = scratch(&format!("{model}-{}", tips.join("-")));
    let test_rows = test.clone();
    let (outcome, out) = written(calibrated(urdf, tips, robot, model, train, test, &dir));
    let runtime = Robot::load_urdf(&out, tips).unwrap();
    // The held-out RMS the report prints is the one `hapcal predict` reports on the files.
    let held_out_gap = held_out_rms_gap(&outcome, &runtime, &test_rows);
    assert!(
        held_out_gap < TOLERANCE_M,
        "{model}: the report's held-out RMS and predict's on the written files differ by \
         {held_out_gap:e} m"
    );
    let record = runtime.calibration().expect("a record").clone();
    assert_eq!(record.model.map(|m| m.name()), Some(model.name()));
    let gap = worst_gap(&runtime, &outcome.model, &rows, tips.len());
    // Enlarge every load-dependent value and harmonic, in both.
    let mut library = outcome.model.clone();
    let mut enlarged_runtime = runtime.clone();
    let mut shifted: f64 = 0.0;
    for v in &record.values {
        let Some(value) = enlarged(&v.name, &v.unit) else {
            continue;
        };
        enlarged_runtime = set_in_both(
            &enlarged_runtime,
            &mut library,
            &robot.joint_names,
            &v.name,
            value,
        );
    }
    for q in &rows {
        let a = runtime_marker(&runtime, q, 0);
        let b = runtime_marker(&enlarged_runtime, q, 0);
        shifted = shifted.max(distance(&a, &b));
    }
    let enlarged_gap = worst_gap(&enlarged_runtime, &library, &rows, tips.len());
    (gap, enlarged_gap, shifted)
}

fn iiwa_tables(seed: u64, n: usize) -> (ArmRobot, MeasurementTable, MeasurementTable) {
    let robot = split_arm::robot();
    let truth = split_arm::truth(
        &robot,
        seed,
        split_arm::Effect::Harmonic {
            amplitude_rad: 1e-3,
            order: 1.0,
            phase_rad: 0.4,
        },
    );
    let train = split_arm::rows(&robot, &truth, n, (-2.5, 2.5), seed + 1, "train");
    let test = split_arm::rows(&robot, &truth, n / 2, (-2.5, 2.5), seed + 2, "test");
    (robot, train, test)
}

use split_arm::tracker::iiwa_urdf;

fn check(model: ModelChoice, (gap, enlarged_gap, shifted): (f64, f64, f64), effect: bool) {
    assert!(
        gap < TOLERANCE_M,
        "{model}: runtime and library differ by {gap:e} m"
    );
    assert!(
        enlarged_gap < TOLERANCE_M,
        "{model} with enlarged values: runtime and library differ by {enlarged_gap:e} m"
    );
    if effect {
        assert!(
            shifted > 1e-4,
            "{model}: the enlarged values moved the marker by only {shifted:e} m"
        );
    }
}

#[test]
fn every_model_of_a_serial_arm_round_trips_into_the_runtime() {
    let urdf = iiwa_urdf();
    for (model, effect) in [
        (ModelName::FramesOnly, false),
        (ModelName::JointOffsets, false),
        (ModelName::Geometric, false),
        (ModelName::Compliance, true),
        (ModelName::MassCompliance, true),
        (ModelName::ActuatorCompliance, true),
        (ModelName::TransversalCompliance, true),
        (ModelName::TransversalAxes, true),
        (ModelName::Harmonic, true),
        (ModelName::Harmonic2, true),
        (ModelName::ComplianceHarmonic, true),
        (ModelName::MassComplianceHarmonic, true),
    ] {
        let (robot, train, test) = iiwa_tables(5, 80);
        let result = round_trip(&urdf, &["ball_link"], &robot, model.into(), train, test);
        check(model.into(), result, effect);
    }
}

#[test]
fn the_compliances_of_a_two_arm_tree_with_link_masses_round_trip_into_the_runtime() {
    let tips = ["l_hand", "r_hand"];
    let robot = humanoid::humanoid(&tips);
    let truth = humanoid::truth(&robot, 3);
    let train = humanoid::table(&robot, &truth, &[0, 1], 200, 4);
    let test = humanoid::table(&robot, &truth, &[0, 1], 30, 5);
    let dir = scratch("humanoid-urdf");
    let urdf = dir.join("humanoid.urdf");
    std::fs::write(&urdf, humanoid::humanoid_urdf()).unwrap();
    for (model, effect) in [
        (ModelName::Geometric, false),
        (ModelName::Compliance, true),
        (ModelName::TransversalCompliance, true),
        (ModelName::TransversalAxes, true),
        (ModelName::Harmonic, true),
    ] {
        let result = round_trip(
            &urdf,
            &tips,
            &robot,
            model.into(),
            train.clone(),
            test.clone(),
        );
        check(model.into(), result, effect);
    }
}

/// The README's first calibration: MUKCa's socket recordings of an iiwa 14 (the chain's end
/// point is the ball's centre), every compliance model the ladder holds for sockets, written
/// and loaded: the runtime's ball at configurations over the joint limits equals the
/// library's `CalibratedModel::end_point`.
#[test]
fn socket_calibrations_round_trip_into_the_runtime() {
    let dir = scratch("sockets");
    for model in [
        ModelName::Geometric,
        ModelName::MassCompliance,
        ModelName::ActuatorCompliance,
    ] {
        let plan = Plan {
            model: model.into(),
            test: Vec::new(),
            ..Plan::bundled_default()
        };
        let outcome = hapcal_calibrate::calibrate::run(&plan).unwrap();
        let out = dir.join(format!("iiwa-{model}.urdf"));
        let _ = std::fs::remove_file(&out);
        let _ = std::fs::remove_file(out.with_extension("calibration.toml"));
        hapcal_calibrate::calibrate::write_outputs_beside(&outcome, &out, &[]).unwrap();
        let runtime = Robot::load_urdf(&out, &["ball_link"]).unwrap();
        assert_eq!(
            runtime
                .calibration()
                .and_then(|r| r.model)
                .map(|m| m.name()),
            Some(model.name())
        );
        let mut ws = runtime.workspace();
        let mut worst: f64 = 0.0;
        for k in 0..40 {
            let q: Vec<f64> = (runtime.limits().iter().enumerate())
                .map(|(j, (lo, hi))| {
                    let t = 0.5 + 0.45 * ((k * 7 + j) as f64 * 0.61).sin();
                    lo + t * (hi - lo)
                })
                .collect();
            let mut pose = [Pose::IDENTITY];
            runtime.deflected_tip_poses(&q, &mut ws, &mut pose).unwrap();
            let p = outcome.model.end_point(&q);
            let r = pose[0].translation_m;
            let d = ((r[0] - p.x).powi(2) + (r[1] - p.y).powi(2) + (r[2] - p.z).powi(2)).sqrt();
            worst = worst.max(d);
        }
        assert!(
            worst < TOLERANCE_M,
            "{model}: runtime and library differ by {worst:e} m"
        );
    }
}

/// A torso with a prismatic lift, a turn and two 3-joint arms (fixed joints between moving
/// ones, a continuous joint about a skew axis, a head off the paths, link masses): simulated
/// tracker markers on both tools.
fn torso_tables(n: usize, seed: u64) -> (PathBuf, ArmRobot, MeasurementTable, MeasurementTable) {
    use rand::Rng;
    let urdf =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../runtime/test_data/torso_two_arms.urdf");
    let tips = ["l_tool".to_owned(), "r_tool".to_owned()];
    let robot = hapcal_calibrate::measured::robot_from_urdf(&urdf, &tips).unwrap();
    let (train, test) = split_arm::tracker::tracker_tables(&robot, n, seed, |rng| {
        (robot.limits.iter())
            .map(|&(lo, hi)| rng.random_range(0.8 * lo.max(-2.0)..0.8 * hi.min(2.0)))
            .collect()
    });
    (urdf, robot, train, test)
}

#[test]
fn a_tree_with_a_prismatic_joint_round_trips_into_the_runtime() {
    let (urdf, robot, train, test) = torso_tables(80, 21);
    for (model, effect) in [
        (ModelName::Geometric, false),
        (ModelName::Compliance, true),
        (ModelName::TransversalCompliance, true),
        (ModelName::Harmonic, true),
    ] {
        let result = round_trip(
            &urdf,
            &["l_tool", "r_tool"],
            &robot,
            model.into(),
            train.clone(),
            test.clone(),
        );
        check(model.into(), result, effect);
    }
}

/// The position error of every marker sample of `table` as `hapcal predict` computes it from
/// the written URDF `out` and its record (`Predictor::add_errors`, in the instrument frame),
/// in the order of the report's sample errors (rows, then markers); with the RMS of the
/// orientation errors of pose samples (rad; `None` without).
fn predicted_errors(
    out: &Path,
    tips: &[&str],
    table: &MeasurementTable,
) -> (Vec<f64>, Option<f64>) {
    use hapcal_runtime::{MarkerObservation, MeasuredErrors, PredictionFrame, Predictor};
    let robot = Robot::load_urdf(out, tips).unwrap();
    let predictor = Predictor::new(&robot, PredictionFrame::Instrument).unwrap();
    let mut ws = predictor.workspace();
    let mut position = Vec::new();
    let mut all = MeasuredErrors::default();
    for row in &table.rows {
        for m in &row.markers {
            let one = [MarkerObservation {
                marker: m.marker,
                position_m: m.position_m,
                rotation_wxyz: m.rotation,
            }];
            let mut errors = MeasuredErrors::default();
            predictor
                .add_errors(&row.q, &one, None, &mut ws, &mut errors)
                .unwrap();
            position.push(errors.position.max());
            predictor
                .add_errors(&row.q, &one, None, &mut ws, &mut all)
                .unwrap();
        }
    }
    let orientation = (all.orientation.count > 0).then(|| all.orientation.rms());
    (position, orientation)
}

/// Calibrates `model` on `train` and `test`, writes the URDF and its record, and returns the
/// largest difference between the position errors the report lists for each set (training,
/// then held-out) and those `predict` computes on the written files, m, with the report's
/// held-out mean and `predict`'s (m).
fn report_against_predict(
    urdf: &Path,
    tips: &[&str],
    robot: &ArmRobot,
    model: ModelChoice,
    train: &MeasurementTable,
    test: &MeasurementTable,
) -> (f64, f64, f64) {
    let dir = scratch(&format!("report-{model}-{}", tips.join("-")));
    let (outcome, out) = written(calibrated(
        urdf,
        tips,
        robot,
        model,
        train.clone(),
        test.clone(),
        &dir,
    ));
    let sets = &outcome.report.placements;
    assert_eq!(sets.len(), 2, "{model}: one training and one test set");
    let mut worst: f64 = 0.0;
    let mut means = (0.0, 0.0);
    for (set, table) in sets.iter().zip([train, test]) {
        let reported = &set.errors.as_ref().expect("sample errors").position_after_m;
        let (predicted, orientation) = predicted_errors(&out, tips, table);
        assert_eq!(reported.len(), predicted.len(), "{model} {}", set.name);
        for (a, b) in reported.iter().zip(&predicted) {
            worst = worst.max((a - b).abs());
        }
        let pose = set.after.pose.expect("pose figures");
        if let (Some(a), Some(b)) = (pose.orientation_rms_rad, orientation) {
            // The runtime's angle is an arccosine near 1: 1e-6 relative covers its rounding.
            assert!(
                (a - b).abs() <= 1e-6 * a + 1e-12,
                "{model} {}: orientation RMS reported {a} rad, predicted {b} rad",
                set.name
            );
        }
        if set.role == hapcal_calibrate::report::SetRole::Test {
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            means = (mean(reported), mean(&predicted));
        }
    }
    (worst, means.0, means.1)
}

fn assert_report_is_predict(
    model: ModelChoice,
    shape: &str,
    (worst, reported, predicted): (f64, f64, f64),
) {
    assert!(
        worst < TOLERANCE_M,
        "{model} on {shape}: the report's errors and predict's on the written files differ by up to \
         {worst:e} m (held-out mean reported {:.4} mm, predicted {:.4} mm)",
        reported * 1e3,
        predicted * 1e3
    );
}

/// The humanoid as many real ones are described (every joint about z after a fixed `rpy`
/// frame), CAD masses, per-axis transversal compliance in the truth, and motion-capture
/// markers of 2 mm noise per axis on both hands: few rows for so many parameters, so the
/// fits hold many parameters at their starting values.
fn z_axes_humanoid_tables(n: usize) -> (PathBuf, ArmRobot, MeasurementTable, MeasurementTable) {
    let tips = ["l_hand", "r_hand"];
    let robot = humanoid::z_axes_humanoid(false, &tips);
    let truth = humanoid::truth_with(&robot, 31, hapcal_problems::Transversal::PerAxis);
    let train = humanoid::table_with_noise(&robot, &truth, &[0, 1], n, 32, 2e-3);
    let test = humanoid::table_with_noise(&robot, &truth, &[0, 1], n / 3, 33, 2e-3);
    let dir = scratch("z-humanoid-urdf");
    let urdf = dir.join("humanoid-z.urdf");
    std::fs::write(&urdf, humanoid::humanoid_urdf_z_axes(false)).unwrap();
    (urdf, robot, train, test)
}

/// The per-axis transversal compliance on a humanoid whose joints all turn about z after
/// fixed `rpy` frames, 2 mm marker noise: the report's training and held-out errors are
/// `predict`'s on the files calibrate wrote.
#[test]
fn per_axis_transversal_compliance_of_a_z_axes_humanoid_reports_what_its_files_give() {
    let (urdf, robot, train, test) = z_axes_humanoid_tables(150);
    for model in [
        ModelChoice::Model(ModelName::TransversalAxes),
        ModelChoice::Auto,
    ] {
        let result =
            report_against_predict(&urdf, &["l_hand", "r_hand"], &robot, model, &train, &test);
        assert_report_is_predict(model, "the z-axes humanoid", result);
    }
}

/// The simulated humanoid of fixtures/sim-humanoid (the generator's seeds: truth 11, rows
/// 12; 550 rows, the last 30 % held out), calibrated with the model the ladder takes there
/// (transversal compliance): the record carries the covariance of every value it estimated,
/// and `predict`'s 1σ per coordinate covers the held-out prediction errors (against the
/// simulated truth, without the marker noise) as a normal error's does, 68.3 %. Each
/// coordinate covered is a Bernoulli trial: the share is held to 3 binomial standard
/// deviations of the number of held-out rows: the coordinates of one row, and the rows, are
/// not independent trials (one estimate's error moves them all), so the spread over the 990
/// coordinates would understate it (the data are fixed, so the test cannot flake).
/// With the standard deviations alone (the record without covariance) σ is tens of times
/// the errors and covers nearly all of them.
#[test]
fn predict_sigma_covers_the_held_out_errors_of_the_simulated_humanoid() {
    use hapcal_runtime::{PredictionFrame, Predictor, TipPrediction, UncertaintyBasis};
    let tips = ["l_hand", "r_hand"];
    let robot = humanoid::humanoid(&tips);
    let truth = humanoid::truth(&robot, 11);
    let mut train = humanoid::table(&robot, &truth, &[0, 1], 550, 12);
    let test_rows = train.rows.split_off(385);
    let test = MeasurementTable {
        rows: test_rows,
        ..train.clone()
    };
    let dir = scratch("coverage-humanoid");
    let urdf = dir.join("humanoid.urdf");
    std::fs::write(&urdf, humanoid::humanoid_urdf()).unwrap();
    let model = ModelChoice::Model(ModelName::TransversalCompliance);
    let (outcome, out) = written(calibrated(
        &urdf,
        &tips,
        &robot,
        model,
        train,
        test.clone(),
        &dir,
    ));
    let record = outcome.record.as_ref().expect("a record");
    let covariance = record.covariance.as_ref().expect("a covariance");
    let estimated = (record.values.iter()).filter(|v| v.std > 0.0).count();
    assert_eq!(
        covariance.names.len(),
        estimated,
        "the covariance of every estimated value"
    );
    let runtime = Robot::load_urdf(&out, &tips).unwrap();
    let predictor = Predictor::new(&runtime, PredictionFrame::Instrument).unwrap();
    assert_eq!(predictor.basis(), UncertaintyBasis::Covariance);
    let true_model = hapcal_problems::CalibratedModel {
        equilibrium: true,
        ..truth.problem.model(truth.x.as_ref())
    };
    let mut ws = predictor.workspace();
    let mut predicted = [TipPrediction::default(); 2];
    let (mut covered, mut n) = (0usize, 0usize);
    let mut sq_ratio = 0.0;
    for row in &test.rows {
        predictor.predict(&row.q, &mut ws, &mut predicted).unwrap();
        for (k, p) in predicted.iter().enumerate() {
            let t = true_model.end_pose_of(k, &row.q).translation.vector;
            let sigma = p.sigma_axes_m.expect("a σ per coordinate");
            for a in 0..3 {
                let e = p.pose.translation_m[a] - t[a];
                covered += usize::from(e.abs() <= sigma[a]);
                sq_ratio += (e / sigma[a]).powi(2);
                n += 1;
            }
        }
    }
    let share = covered as f64 / n as f64;
    let normal = 0.6827;
    let spread = 3.0 * (normal * (1.0 - normal) / test.rows.len() as f64).sqrt();
    assert!(
        (share - normal).abs() <= spread,
        "predict's 1σ covers {:.1} % of {n} held-out coordinates (RMS error/σ {:.2}), expected \
         {:.1} ± {:.1} %",
        100.0 * share,
        (sq_ratio / n as f64).sqrt(),
        100.0 * normal,
        100.0 * spread
    );
}

/// Every model of the measurement ladder on the three data shapes the tests build: positions
/// of one marker on a serial arm (the iiwa 14), poses of that marker, and positions of two
/// markers on a tree (the z-axes humanoid): the training and held-out errors the report
/// lists are `predict`'s on the written URDF and record, to 1e-9 m.
#[test]
fn every_model_reports_what_its_files_give_on_every_data_shape() {
    let iiwa = iiwa_urdf();
    let (arm, train, test) = iiwa_tables(7, 80);
    for model in ModelName::ALL {
        if ModelChoice::from(model)
            .check_fits(hapcal_calibrate::model::DataKind::Measurements)
            .is_err()
        {
            continue;
        }
        let result =
            report_against_predict(&iiwa, &["ball_link"], &arm, model.into(), &train, &test);
        assert_report_is_predict(model.into(), "iiwa positions", result);
    }
    let (arm, train, test) = iiwa_pose_tables(8, 60);
    for model in [
        ModelName::FramesOnly,
        ModelName::JointOffsets,
        ModelName::Geometric,
        ModelName::Compliance,
        ModelName::MassCompliance,
        ModelName::TransversalCompliance,
        ModelName::TransversalAxes,
    ] {
        let result =
            report_against_predict(&iiwa, &["ball_link"], &arm, model.into(), &train, &test);
        assert_report_is_predict(model.into(), "iiwa poses", result);
    }
    let (urdf, humanoid, train, test) = z_axes_humanoid_tables(120);
    for model in [
        ModelName::FramesOnly,
        ModelName::JointOffsets,
        ModelName::Geometric,
        ModelName::Compliance,
        ModelName::TransversalCompliance,
    ] {
        let result = report_against_predict(
            &urdf,
            &["l_hand", "r_hand"],
            &humanoid,
            model.into(),
            &train,
            &test,
        );
        assert_report_is_predict(model.into(), "two markers on the z-axes humanoid", result);
    }
}

/// [`iiwa_tables`] with the marker's orientation measured too (noise 1 mrad per axis): pose
/// rows.
fn iiwa_pose_tables(seed: u64, n: usize) -> (ArmRobot, MeasurementTable, MeasurementTable) {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let robot = split_arm::robot();
    let truth = split_arm::truth(&robot, seed, split_arm::Effect::Ratio { epsilon: 0.0 });
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed + 3);
    let noise = Normal::new(0.0, 1e-3).unwrap();
    let mut posed = |mut table: MeasurementTable| {
        for row in &mut table.rows {
            let pose = truth.framed.tips()[0].end_pose(&truth.x, &row.q);
            let tilt = hapcal_kinematics::UnitQuaternion::from_scaled_axis(
                hapcal_kinematics::Vector3::from_fn(|_, _| noise.sample(&mut rng)),
            );
            let r = (pose.rotation * tilt).into_inner();
            row.markers[0].rotation = Some([r.w, r.i, r.j, r.k]);
        }
        table.has_orientation = true;
        table
    };
    let train = posed(split_arm::rows(
        &robot,
        &truth,
        n,
        (-2.5, 2.5),
        seed + 1,
        "train",
    ));
    let test = posed(split_arm::rows(
        &robot,
        &truth,
        n / 2,
        (-2.5, 2.5),
        seed + 2,
        "test",
    ));
    (robot, train, test)
}

/// Compliances so large that the torque equilibrium's fixed-point iteration does not
/// contract (the z-axes humanoid's truth compliances ×100, a robot that would fold under its
/// weight): the fit is named implausible (`hapcal calibrate` stops with exit 2 and writes
/// nothing). (×−100, a robot that would bend against its weight, as the real two-arm
/// humanoid's unconverged transversal-axes fit had them, no longer reaches this finding: the
/// compliance prior prunes the compliances its data cannot determine, and the fit is stopped
/// on its negative compliances instead.) The files it would write still hold the
/// calibration: with every compliance the record holds scaled down a hundredfold in the
/// files and in the library's model alike (an equilibrium the iteration reaches), the runtime
/// gives the library's markers, as it would not if a value the fit held at its warm start
/// were missing from the record. At the fitted values the two are not compared point by
/// point: the iteration amplifies rounding (`check_reproduced` says by how much), so the
/// written files are not refused for it.
#[test]
fn an_equilibrium_the_deflection_does_not_reach_is_implausible() {
    use hapcal_calibrate::report::ImplausibleKind;
    use hapcal_identify::Problem as _;
    let tips = ["l_hand", "r_hand"];
    let robot = humanoid::z_axes_humanoid(false, &tips);
    let mut truth = humanoid::truth_with(&robot, 31, hapcal_problems::Transversal::PerAxis);
    let layout = truth.problem.layout();
    for i in 0..layout.len() {
        let name = layout.name(i);
        if name.starts_with("compliance.") || name.starts_with("transversal.") {
            truth.x[i] *= 100.0;
        }
    }
    let train = humanoid::table_with_noise(&robot, &truth, &[0, 1], 150, 32, 2e-3);
    let test = humanoid::table_with_noise(&robot, &truth, &[0, 1], 50, 33, 2e-3);
    let dir = scratch("no-equilibrium");
    let urdf = dir.join("humanoid-z.urdf");
    std::fs::write(&urdf, humanoid::humanoid_urdf_z_axes(false)).unwrap();
    let model = ModelChoice::Model(ModelName::TransversalAxes);
    let (outcome, out) = calibrated(&urdf, &tips, &robot, model, train, test, &dir);
    let kinds: Vec<ImplausibleKind> = (outcome.report.implausible.iter())
        .map(|i| i.kind)
        .collect();
    assert!(
        kinds.contains(&ImplausibleKind::NoEquilibrium),
        "the fit is not named implausible for its equilibrium: {kinds:?}"
    );
    hapcal_calibrate::calibrate::write_outputs_beside(&outcome, &out, &[])
        .expect("the files are written");
    let runtime = Robot::load_urdf(&out, &tips).unwrap();
    let record = runtime.calibration().expect("a record").clone();
    let mut library = outcome.model.clone();
    let mut scaled = runtime.clone();
    let mut n_scaled = 0;
    for v in &record.values {
        if v.name.starts_with("compliance.") || v.name.starts_with("transversal.") {
            scaled = set_in_both(
                &scaled,
                &mut library,
                &robot.joint_names,
                &v.name,
                v.value / 100.0,
            );
            n_scaled += 1;
        }
    }
    assert!(n_scaled > 0, "no compliance in the record");
    let rows: Vec<Vec<f64>> = (outcome.report.placements.iter())
        .filter_map(|set| set.errors.as_ref())
        .flat_map(|e| e.rows.iter().map(|r| r.q.to_vec()))
        .collect();
    let gap = worst_gap(&scaled, &library, &rows, tips.len());
    assert!(
        gap < TOLERANCE_M,
        "scaled down, the runtime and the library differ by {gap:e} m"
    );
}

/// The files of a plausible calibration (the per-axis transversal compliance of the z-axes
/// humanoid, 2 mm noise) pass the check `hapcal calibrate` makes before writing them.
#[test]
fn the_files_of_a_plausible_calibration_reproduce_it() {
    let (urdf, robot, train, test) = z_axes_humanoid_tables(150);
    let tips = ["l_hand", "r_hand"];
    let dir = scratch("reproduced");
    let model = ModelChoice::Model(ModelName::TransversalAxes);
    let (outcome, out) = written(calibrated(&urdf, &tips, &robot, model, train, test, &dir));
    assert!(
        outcome.report.implausible.is_empty(),
        "{:?}",
        outcome.report.implausible
    );
    let runtime = Robot::load_urdf(&out, &tips).unwrap();
    hapcal_calibrate::calibrate::check_reproduced(&outcome, &runtime).unwrap();
}

/// Every model of a haptic device's ladder (geometric, transmissions and, the reference device
/// having a handle mass, compliance) calibrated on a simulated log with a handle compliance
/// on joints 2 and 3, with a test log read from its file: the test log's distance RMS the
/// report prints is the one `hapcal predict` gives on the written device file and that log
/// (`predict::predict`, the command's own path), within 1e-9 m; the models differ, so each
/// written file is checked against its own report.
#[test]
fn every_haptic_model_reports_what_its_device_file_gives() {
    use hapcal_calibrate::report::SetRole;
    let (device, _) = haptic_log::reference();
    let (rungs, _) = hapcal_calibrate::haptic::haptic_rungs(true, true);
    assert_eq!(
        rungs,
        [
            ModelName::Geometric,
            ModelName::Transmissions,
            ModelName::Compliance
        ]
    );
    let effects = ["gravity_compliance:j2=5e-3,j3=5e-3"];
    let dir = scratch("haptic-logs");
    let test_path = dir.join("test.csv");
    let test_rows = haptic_log::log(62, 150, &effects);
    std::fs::write(&test_path, hapcal_io::write_log(&test_rows)).unwrap();
    let test_log = hapcal_io::read_log(&test_path, &device).unwrap();
    let mut reported_rms = Vec::new();
    for model in rungs {
        let test = vec![hapcal_calibrate::data::NamedLog {
            name: "test".into(),
            path: test_path.clone(),
            rows: test_log.rows.clone(),
            warnings: Vec::new(),
        }];
        let train = haptic_log::log(61, 300, &effects);
        let outcome = haptic_log::calibrated(
            model.into(),
            train,
            test,
            hapcal_calibrate::fit::LADDER_ROWS,
        );
        assert_eq!(outcome.report.model, model);
        let out = dir.join(format!("cal-{model}.toml"));
        hapcal_calibrate::calibrate::write_outputs_beside(&outcome, &out, &[]).unwrap();
        let predicted = hapcal_calibrate::predict::predict(
            &out,
            &[],
            &test_path,
            &hapcal_io::Units::default(),
            false,
            false,
            &mut |_, _| {},
        )
        .unwrap();
        let errors = predicted
            .prediction
            .errors
            .expect("the test log's distances");
        let predicted_rms = errors.distance_m.expect("distance errors").rms;
        let set = (outcome.report.placements.iter())
            .find(|p| p.role == SetRole::Test)
            .expect("a test log");
        let reported = set.after.distance_rms_m.expect("a distance RMS");
        assert!(
            (reported - predicted_rms).abs() < TOLERANCE_M,
            "{model}: the report's test distance RMS {reported:e} m and predict's on the \
             written device file {predicted_rms:e} m differ by {:e} m",
            (reported - predicted_rms).abs()
        );
        reported_rms.push(reported);
    }
    // Three different models: the written files differ, so agreeing with each is no accident
    // of one model. The compliance model, the truth's, predicts the held-out rows within
    // twice the cable encoder's noise (about 10 µm); the geometric model, without the
    // transmissions, does not.
    assert!(
        reported_rms[2] < 20e-6 && reported_rms[0] > reported_rms[2],
        "{reported_rms:?}"
    );
}
