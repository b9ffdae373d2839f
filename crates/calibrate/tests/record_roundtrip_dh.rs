//! Every model the ladder can choose on a D-H robot's measurement files reaches the runtime:
//! calibrate a simulated D-H arm (standard and modified D-H, fixed rows at both ends) with
//! the model, write the calibrated device file with its record in `[calibration]`
//! (`calibrate::write_outputs_beside`), load it with `hapcal_runtime::Robot::load_device`, and
//! the runtime's marker positions at the training and held-out configurations equal the
//! calibration library's own predictions (`CalibratedModel::end_poses_of`) within 1e-9 m, as
//! the held-out position RMS the report prints equals `hapcal predict`'s on the file. The
//! compliances and harmonics are then enlarged until each moves the marker by millimetres, in
//! the library's model and through `Robot::with_value`, and the D-H deviations moved through
//! `Robot::with_value` must move the runtime's marker as they move the library's: a runtime
//! that left an effect out, placed a joint elsewhere on its row or evaluated the loads on
//! another geometry fails there.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hapcal_calibrate::model::ModelName;
use std::path::Path;

use hapcal_calibrate::inputs::Plan;
use hapcal_calibrate::measured::Robot as ArmRobot;
use hapcal_calibrate::model::ModelChoice;
use hapcal_io::MeasurementTable;
use hapcal_runtime::Robot;

#[path = "sim/roundtrip.rs"]
mod roundtrip;
#[path = "sim/tracker.rs"]
mod tracker;

use roundtrip::{distance, scratch, set_in_both};

/// Agreement required between the runtime and the library, m: both evaluate the same
/// equations in double precision; 1e-9 m leaves six orders of magnitude to rounding.
const TOLERANCE_M: f64 = 1e-9;

/// A four-joint arm: a fixed base row, a vertical first joint, three horizontal ones (their
/// gravity loads are large), a fixed tool row; `convention` standard (`dh`) or modified
/// (`mdh`), with Hayati's β on the third joint's row.
fn device_text(convention: &str) -> String {
    let rows = [
        (0.0, 0.0, 0.12, 0.0, None, "\"fixed\""),
        (0.05, std::f64::consts::FRAC_PI_2, 0.30, 0.0, None, "1"),
        (0.42, 0.0, 0.0, 0.2, None, "2"),
        (0.35, 0.0, 0.02, -0.1, Some(0.0), "3"),
        (0.08, std::f64::consts::FRAC_PI_2, 0.0, 0.0, None, "4"),
        (0.03, 0.0, 0.09, 0.0, None, "\"fixed\""),
    ];
    let mut s = format!("name = \"test arm ({convention})\"\nconvention = \"{convention}\"\n");
    for (a, alpha, d, theta, beta, joint) in rows {
        s.push_str(&format!(
            "\n[[dh]]\na_m = {a:?}\nalpha_rad = {alpha:?}\nd_m = {d:?}\ntheta_rad = {theta:?}\n"
        ));
        if let Some(b) = beta {
            s.push_str(&format!("beta_rad = {b:?}\n"));
        }
        s.push_str(&format!("joint = {joint}\n"));
    }
    for j in 1..=4 {
        s.push_str(&format!(
            "\n[[joint]]\nname = \"j{j}\"\nlower_rad = -2.8\nupper_rad = 2.8\n"
        ));
    }
    s
}

/// Simulated tracker positions of one marker on the arm ([`tracker::tracker_tables`]) at
/// readings within 80 % of the limits: training and held-out tables.
fn tables(robot: &ArmRobot, n: usize, seed: u64) -> (MeasurementTable, MeasurementTable) {
    tracker::tracker_tables(robot, n, seed, |rng| tracker::within_limits(robot, rng))
}

/// The runtime's position of marker 1 in the instrument frame.
fn runtime_marker(robot: &Robot, q: &[f64]) -> [f64; 3] {
    roundtrip::runtime_marker(robot, q, 0)
}

/// Largest distance between the runtime's and the library's marker over `rows`, m.
fn worst_gap(robot: &Robot, library: &hapcal_problems::CalibratedModel, rows: &[Vec<f64>]) -> f64 {
    roundtrip::worst_gap(robot, library, rows, 1)
}

/// What one model's round trip measured, m.
struct Gaps {
    /// The report's held-out position RMS against `hapcal predict`'s on the written file.
    held_out: f64,
    /// Runtime against library, as identified.
    identified: f64,
    /// The same with the compliances and harmonics enlarged.
    enlarged: f64,
    /// How far the enlarged values moved the marker.
    shifted: f64,
    /// Largest gap between the runtime's and the library's marker moves when one D-H
    /// deviation is moved by 1 mm or 1 mrad (`Robot::with_value` against the library's
    /// parameter vector).
    moved_dh: f64,
    /// Number of D-H deviations so moved.
    n_dh: usize,
}

fn round_trip(
    device_path: &Path,
    robot: &ArmRobot,
    model: ModelChoice,
    train: MeasurementTable,
    test: MeasurementTable,
    dir: &Path,
) -> Gaps {
    let rows: Vec<Vec<f64>> = (train.rows.iter().chain(&test.rows))
        .map(|r| r.q.to_vec())
        .collect();
    let plan = Plan {
        device: device_path.to_path_buf(),
        data: Vec::new(),
        test: Vec::new(),
        model,
        ..Plan::bundled_default()
    };
    let device = hapcal_io::read_device(device_path).unwrap();
    let out = dir.join(format!("cal-{model}.toml"));
    let outcome = roundtrip::calibrate_tables(&plan, &device, robot, train, test.clone(), &out);
    hapcal_calibrate::calibrate::write_outputs_beside(&outcome, &out, &[]).unwrap();
    let runtime = Robot::load_device(&out).unwrap();
    let record = runtime.calibration().expect("a record").clone();
    assert_eq!(record.model.map(|m| m.name()), Some(model.name()));
    let held_out = roundtrip::held_out_rms_gap(&outcome, &runtime, &test);
    assert_eq!(runtime.joint_names(), robot.joint_names.as_slice());
    let identified = worst_gap(&runtime, &outcome.model, &rows);

    let mut library = outcome.model.clone();
    let mut enlarged = runtime.clone();
    for v in &record.values {
        // 2 mrad of harmonic; 2e-3 rad/m of compliance under lumped loads of about a metre.
        if !(v.name.starts_with("compliance.") || v.name.starts_with("harmonic.")) {
            continue;
        }
        let value = 2e-3;
        enlarged = set_in_both(&enlarged, &mut library, &robot.joint_names, &v.name, value);
    }
    let shifted = (rows.iter())
        .map(|q| distance(&runtime_marker(&runtime, q), &runtime_marker(&enlarged, q)))
        .fold(0.0, f64::max);
    let enlarged_gap = worst_gap(&enlarged, &library, &rows);

    // Each D-H deviation the record holds, moved by 1 mm or 1 mrad on the enlarged robot.
    let chain = outcome.model.tips.first().unwrap_or(&outcome.model.chain);
    let mut moved_dh: f64 = 0.0;
    let mut n_dh = 0;
    for v in &record.values {
        let Some(i) = chain.param_index(&v.name) else {
            continue;
        };
        if v.name.starts_with("instrument.") || v.name.starts_with("marker") {
            continue;
        }
        let step = 1e-3;
        let moved = enlarged.with_value(&v.name, v.value + step).unwrap();
        let mut shifted_library = library.clone();
        shifted_library.x_kin[i] += step;
        for q in rows.iter().take(10) {
            let p = library.end_poses_of(&[0], q)[0].translation.vector;
            let p2 = shifted_library.end_poses_of(&[0], q)[0].translation.vector;
            let r = runtime_marker(&enlarged, q);
            let r2 = runtime_marker(&moved, q);
            let gap = distance(
                &[r2[0] - r[0], r2[1] - r[1], r2[2] - r[2]],
                &[p2.x - p.x, p2.y - p.y, p2.z - p.z],
            );
            moved_dh = moved_dh.max(gap);
        }
        n_dh += 1;
    }
    Gaps {
        held_out,
        identified,
        enlarged: enlarged_gap,
        shifted,
        moved_dh,
        n_dh,
    }
}

fn check(convention: &str, models: &[(ModelChoice, bool)], seed: u64) {
    let dir = scratch(convention);
    let device_path = dir.join("arm.toml");
    std::fs::write(&device_path, device_text(convention)).unwrap();
    let device = hapcal_io::read_device(&device_path).unwrap();
    let robot = hapcal_calibrate::data::robot_from_device(&device).unwrap();
    let (train, test) = tables(&robot, 80, seed);
    for &(model, effect) in models {
        let g = round_trip(
            &device_path,
            &robot,
            model,
            train.clone(),
            test.clone(),
            &dir,
        );
        assert!(
            g.held_out < TOLERANCE_M,
            "{convention} {model}: the report's held-out RMS and predict's on the written file \
             differ by {:e} m",
            g.held_out
        );
        assert!(
            g.identified < TOLERANCE_M,
            "{convention} {model}: runtime and library differ by {:e} m",
            g.identified
        );
        assert!(
            g.enlarged < TOLERANCE_M,
            "{convention} {model} with enlarged values: runtime and library differ by {:e} m",
            g.enlarged
        );
        assert!(
            g.moved_dh < TOLERANCE_M,
            "{convention} {model}: a D-H deviation moved through with_value moves the marker \
             {:e} m off the library's move",
            g.moved_dh
        );
        if model != ModelName::FramesOnly {
            assert!(
                g.n_dh > 0,
                "{convention} {model}: no D-H deviation recorded"
            );
        }
        if effect {
            assert!(
                g.shifted > 1e-4,
                "{convention} {model}: the enlarged values moved the marker by only {:e} m",
                g.shifted
            );
        }
    }
}

#[test]
fn every_model_of_a_standard_dh_arm_round_trips_into_the_runtime() {
    check(
        "dh",
        &[
            (ModelName::FramesOnly.into(), false),
            (ModelName::JointOffsets.into(), false),
            (ModelName::Geometric.into(), false),
            (ModelName::Compliance.into(), true),
            (ModelName::Harmonic.into(), true),
            (ModelName::ComplianceHarmonic.into(), true),
        ],
        7,
    );
}

#[test]
fn the_compliance_of_a_modified_dh_arm_round_trips_into_the_runtime() {
    check(
        "mdh",
        &[
            (ModelName::Geometric.into(), false),
            (ModelName::Compliance.into(), true),
        ],
        8,
    );
}
