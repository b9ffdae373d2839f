//! Calibrates a URDF robot from a CSV of marker positions through the library alone: TIAGo's
//! arm and prismatic torso, four motion-capture markers on the hand (figaroh's recording,
//! fixtures/figaroh/tiago). The first 70 % of the rows train, the rest test; the model is chosen
//! on the ladder frames only → joint offsets → geometric → compliance. Exits with an error if
//! the calibrated model is worse than frames only on the held-out rows.
//!
//! `cargo run --release -p hapcal-calibrate --example calibrate_urdf`
#![allow(clippy::print_stdout)] // an example prints what it found

use anyhow::Result;
use hapcal_calibrate::measured::{
    MeasuredConfig, calibrate_measured, load_tables, robot_from_urdf,
};
use std::path::PathBuf;

fn main() -> Result<()> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/figaroh/tiago");
    let robot = robot_from_urdf(&dir.join("tiago.urdf"), &["arm_7_link".to_owned()])?;
    let mut train = load_tables(
        &[dir.join("qualysis_base_hand_calibration.csv")],
        &robot,
        &hapcal_io::Units::default(),
    )?;
    // Hold out the last 30 % of the rows, in file order.
    let mut test = train.clone();
    let k = (0.7 * train[0].rows.len() as f64).round() as usize;
    test[0].rows = train[0].rows.split_off(k);
    let cfg = MeasuredConfig {
        ..MeasuredConfig::default()
    };
    let out = calibrate_measured(&robot, &train, &test, &cfg)?;
    println!("chosen model: {}", out.rung);
    for r in &out.ladder {
        println!(
            "  {:<14} held-out RMS {:.3} mm",
            r.rung.to_string(),
            r.heldout_rms_m * 1e3
        );
    }
    for (name, role, n, before, after) in &out.sets {
        println!(
            "{name} ({role}, {n} rows): position RMS {:.3} mm frames only, {:.3} mm calibrated",
            before.position_rms_m * 1e3,
            after.position_rms_m * 1e3
        );
    }
    for w in &out.warnings {
        println!("warning: {w}");
    }
    // The ladder's promise: never worse than frames only on held-out rows.
    for (name, role, _, before, after) in &out.sets {
        if *role == hapcal_calibrate::report::SetRole::Test
            && after.position_rms_m > before.position_rms_m * (1.0 + 1e-9)
        {
            anyhow::bail!(
                "{name}: calibrated position RMS {:.3} mm is worse than frames only's {:.3} mm",
                after.position_rms_m * 1e3,
                before.position_rms_m * 1e3
            );
        }
    }
    Ok(())
}
