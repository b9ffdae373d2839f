//! Integration tests of `hapcal-sim`.

mod effects;
mod fixtures;
mod simulate;
mod truth;

use std::path::PathBuf;

use hapcal_io::Device;
use hapcal_sim::{Truth, read_truth};

/// `fixtures/reference-device/{name}`.
fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/reference-device")
        .join(name)
}

/// The paper's truth device and its nominal device.
fn paper_truth() -> (Truth, Device) {
    let path = reference("truth.toml");
    let truth = read_truth(&path).expect("the fixture truth file is valid");
    let device = truth
        .read_device(&path)
        .expect("the fixture device is valid");
    (truth, device)
}

/// Sample standard deviation.
fn std_dev(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

/// Mean.
fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}
