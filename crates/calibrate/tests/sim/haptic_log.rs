//! Simulated logs of the reference haptic device (fixtures/reference-device), for the tests
//! of its calibration: the truth the test knows and the calibration does not. Each test
//! binary that includes it uses part of it.
#![allow(dead_code)]

use std::path::Path;

use hapcal_io::{Device, LogRow};
use hapcal_sim::{Injected, MotionConfig, NoiseModel, SimConfig, Truth, simulate_motion};

/// The reference device and its truth (the paper's assigned deviations and transmissions).
pub(crate) fn reference() -> (Device, Truth) {
    let truth_file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device/truth.toml");
    let truth = hapcal_sim::read_truth(&truth_file).expect("fixture truth");
    let device = truth.read_device(&truth_file).expect("fixture device");
    (device, truth)
}

/// A motion log of `n` rows of the reference device (the paper's noise: cable encoder
/// σ_m ≈ 9.9 µm, external encoders a third of a count) with `effects` (the simulator's
/// effect syntax, e.g. `gravity_compliance:j2=5e-3`).
pub(crate) fn log(seed: u64, n: usize, effects: &[&str]) -> Vec<LogRow> {
    let (device, truth) = reference();
    let cable = device.cable_encoder.expect("fixture has a cable encoder");
    let effects: Vec<Injected> = effects.iter().map(|e| e.parse().unwrap()).collect();
    let cfg = SimConfig::new(seed, n).with_noise(NoiseModel::paper(&cable));
    simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &effects).expect("sim")
}

/// `hapcal calibrate --model <model>` on the reference device with the training log `rows`,
/// read from `train.csv`, no test log: the report.
pub(crate) fn calibrate_rows(
    model: hapcal_calibrate::model::ModelChoice,
    rows: Vec<LogRow>,
) -> hapcal_calibrate::report::CalibrationReport {
    calibrate_rows_judging(model, rows, hapcal_calibrate::fit::LADDER_ROWS)
}

/// [`calibrate_rows`] whose ladder judges at most `ladder_rows` of the rows.
pub(crate) fn calibrate_rows_judging(
    model: hapcal_calibrate::model::ModelChoice,
    rows: Vec<LogRow>,
    ladder_rows: usize,
) -> hapcal_calibrate::report::CalibrationReport {
    calibrated(model, rows, Vec::new(), ladder_rows).report
}

/// `hapcal calibrate --model <model>` on the reference device with the training log `rows`,
/// read from `train.csv`, and the test logs `test`, its ladder judging at most `ladder_rows`
/// of the rows: the outcome (report and calibrated device file).
pub(crate) fn calibrated(
    model: hapcal_calibrate::model::ModelChoice,
    rows: Vec<LogRow>,
    test: Vec<hapcal_calibrate::data::NamedLog>,
    ladder_rows: usize,
) -> hapcal_calibrate::report::Outcome {
    let (device, _) = reference();
    let plan = hapcal_calibrate::inputs::Plan {
        device: "fixtures/reference-device/device.toml".into(),
        model,
        data: Vec::new(),
        test: Vec::new(),
        ladder_rows,
        ..hapcal_calibrate::inputs::Plan::bundled_default()
    };
    let train = vec![hapcal_calibrate::data::NamedLog {
        name: "train".into(),
        path: "train.csv".into(),
        rows,
        warnings: Vec::new(),
    }];
    let start = std::time::Instant::now();
    hapcal_calibrate::haptic::calibrate_logs(&plan, device, train, test, start)
        .expect("a calibration of the simulated log")
}
