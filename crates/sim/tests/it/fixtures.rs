//! `fixtures/reference-device/log.csv`: readable, and what the simulator writes.

use hapcal_io::{N_EXT, read_device, read_log};
use hapcal_sim::{NoiseModel, SimConfig, simulate};

use crate::{paper_truth, reference};

#[test]
fn reference_log_reads_back() {
    let device = read_device(&reference("device.toml")).unwrap();
    let log = read_log(&reference("log.csv"), &device).unwrap();
    assert!(log.warnings.is_empty(), "{:?}", log.warnings);
    assert_eq!(log.rows.len(), 200);
    for row in &log.rows {
        assert_eq!(row.q.len(), 7);
        assert_eq!(row.ext.len(), N_EXT);
        assert!(row.ext.iter().all(Option::is_some), "line {}", row.line);
        // 0 < distance < full reach (0.35 + 0.10 + 0.21 + 0.21 + 0.05 + 0.03 m + deviations).
        assert!((0.0..0.96).contains(&row.distance_m), "line {}", row.line);
    }
}

/// Regenerate with `cargo run -p hapcal-sim --example write_reference_log`.
#[test]
fn reference_log_is_up_to_date() {
    let (truth, device) = paper_truth();
    let cfg = SimConfig::new(1, 200).with_noise(NoiseModel::paper(&device.cable_encoder.unwrap()));
    let rows = simulate(&device, &truth, &cfg).unwrap();
    let log = read_log(&reference("log.csv"), &device).unwrap();
    assert_eq!(log.rows.len(), rows.len());
    // Within 1e-12 rather than bit for bit: libm's sin/atan may differ in the last bit
    // between platforms.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(1.0);
    for (file, sim) in log.rows.iter().zip(&rows) {
        let line = file.line;
        assert!(
            file.q.iter().zip(&sim.q).all(|(a, b)| close(*a, *b)),
            "line {line}"
        );
        assert!(close(file.distance_m, sim.distance_m), "line {line}");
        for (a, b) in file.ext.iter().zip(&sim.ext) {
            assert!(close(a.unwrap(), b.unwrap()), "line {line}");
        }
    }
}
