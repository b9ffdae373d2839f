//! Writes `fixtures/reference-device/log.csv`: 200 poses of the paper's truth device
//! (`truth.toml`), seed 1, the paper's noise (σ_e = 2π/20000/3 rad, σ_m = 2π·R_d·σ_e).
//!
//! `cargo run -p hapcal-sim --example write_reference_log`; the integration test
//! `fixtures::reference_log_is_up_to_date` fails when the file and this program disagree.
#![allow(
    clippy::print_stdout,
    reason = "an example binary: it says which file it wrote"
)]

use std::path::Path;

use hapcal_sim::{NoiseModel, SimConfig, read_truth, simulate};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device");
    let dir = dir.canonicalize().unwrap_or(dir);
    let truth_file = dir.join("truth.toml");
    let truth = read_truth(&truth_file)?;
    let device = truth.read_device(&truth_file)?;
    let cable = device
        .cable_encoder
        .ok_or("the device has no [cable_encoder]")?;
    let cfg = SimConfig::new(1, 200).with_noise(NoiseModel::paper(&cable));
    let rows = simulate(&device, &truth, &cfg)?;
    let out = dir.join("log.csv");
    std::fs::write(&out, hapcal_io::write_log(&rows))?;
    println!("wrote {} poses to {}", rows.len(), out.display());
    Ok(())
}
