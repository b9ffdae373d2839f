//! The effects library and the time-ordered motion.

use std::path::Path;

use hapcal_sim::{HAPTIC_LIBRARY, Injected, MotionConfig, NoiseModel, SimConfig, simulate_motion};

fn reference() -> (hapcal_io::Device, hapcal_sim::Truth) {
    let truth_file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device/truth.toml");
    let truth = hapcal_sim::read_truth(&truth_file).expect("fixture truth");
    let device = truth.read_device(&truth_file).expect("fixture device");
    (device, truth)
}

fn run(effects: &[&str], noise: NoiseModel) -> Vec<hapcal_io::LogRow> {
    let (device, truth) = reference();
    let effects: Vec<Injected> = effects.iter().map(|e| e.parse().expect("valid")).collect();
    let cfg = SimConfig::new(5, 120).with_noise(noise);
    simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &effects).expect("simulates")
}

#[test]
fn motion_is_time_ordered_within_limits_and_moves_both_ways() {
    let rows = run(&[], NoiseModel::none());
    let (device, _) = reference();
    let limits = device.joint_limits();
    assert!(rows.windows(2).all(|w| w[0].t_s < w[1].t_s));
    for (j, &(lo, hi)) in limits.iter().enumerate() {
        assert!(rows.iter().all(|r| (lo..=hi).contains(&r.q[j])));
        let ups = rows.windows(2).filter(|w| w[1].q[j] > w[0].q[j]).count();
        let downs = rows.windows(2).filter(|w| w[1].q[j] < w[0].q[j]).count();
        assert!(
            ups > 20 && downs > 20,
            "joint {}: {ups} up, {downs} down",
            j + 1
        );
    }
    // The same seed gives the same log.
    assert_eq!(run(&[], NoiseModel::none()), rows);
}

#[test]
fn backlash_shifts_the_external_encoder_by_its_half_width_against_the_motion() {
    let clean = run(&[], NoiseModel::none());
    let with = run(&["backlash:j2=1e-3"], NoiseModel::none());
    for (a, b) in clean.iter().zip(&with).skip(1).take(100) {
        let shift = b.ext[1].expect("ext2") - a.ext[1].expect("ext2");
        assert!((shift.abs() - 1e-3).abs() < 1e-12, "shift {shift}");
        assert_eq!(a.ext[0], b.ext[0]);
    }
}

#[test]
fn cable_effects_change_only_the_distance() {
    let clean = run(&[], NoiseModel::none());
    let with = run(&["cable_offset:c=2e-4"], NoiseModel::none());
    for (a, b) in clean.iter().zip(&with) {
        assert!((b.distance_m - a.distance_m - 2e-4).abs() < 1e-12);
        assert_eq!(a.q, b.q);
        assert_eq!(a.ext, b.ext);
    }
    let drift = run(&["thermal_drift:k=1e-5"], NoiseModel::none());
    let first = (drift[0].distance_m - clean[0].distance_m).abs();
    assert!(first < 1e-12, "no drift at t = 0: {first}");
    assert!((drift[100].distance_m - clean[100].distance_m).abs() > 1e-6);
}

#[test]
fn effects_that_do_not_fit_the_device_are_errors() {
    let (device, truth) = reference();
    let cfg = SimConfig::new(1, 10);
    let bad: Injected = "backlash:j9=1e-3".parse().expect("parses");
    let err = simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &[bad])
        .expect_err("no joint 9");
    assert!(err.to_string().contains("joints 1..7"), "{err}");
    let bad: Injected = "capstan_harmonic:j6=1e-3".parse().expect("parses");
    let err = simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &[bad])
        .expect_err("no capstan on 6");
    assert!(err.to_string().contains("no capstan"), "{err}");
    let period = MotionConfig {
        sample_period_s: 0.0,
    };
    let err = simulate_motion(&device, &truth, &cfg, &period, &[]).expect_err("period 0");
    assert!(err.to_string().contains("must be > 0"), "{err}");
    assert_eq!(HAPTIC_LIBRARY.len(), 8);
}
