//! A haptic calibration with the handle's gravity compliance, from the simulator through the
//! calibration library and the device file to the runtime: the runtime's end points equal the
//! library's predictions at training and held-out readings.

use std::path::Path;

use hapcal_calibrate::haptic::{
    ComplianceFit, HapticDevice, calibrated_log_state, compliance_device, compliance_values,
    identify_kinematics, identify_transmissions, identify_with_compliance, log_model,
};
use hapcal_contract::{ModelName, TorqueSource};
use hapcal_io::{CalibrationMeta, Device, LogRow};
use hapcal_problems::{DistanceLogState, EffectTermKind, handle_gravity_torques_nm};
use hapcal_runtime::{LoadError, Model};
use hapcal_sim::{Injected, MotionConfig, NoiseModel, SimConfig, simulate_motion};

use crate::fixture;

/// The runtime and the library evaluate the same model with different code (the runtime's
/// folded chain against `hapcal-kinematics`' parameterised one): they agree to rounding,
/// far below this (1 nm).
const TOL_M: f64 = 1e-9;

/// The handle compliance the simulator puts on joints 2 and 3, rad/(N·m).
const COMPLIANCE: f64 = 5e-3;

/// A motion log of the reference device: `n` rows, the paper's noise, the handle compliance
/// [`COMPLIANCE`] on joints 2 and 3.
fn log(seed: u64, n: usize) -> Vec<LogRow> {
    let truth_file = fixture("reference-device/truth.toml");
    let truth = hapcal_sim::read_truth(&truth_file).expect("fixture truth");
    let device = truth.read_device(&truth_file).expect("fixture device");
    let cable = device.cable_encoder.expect("a cable encoder");
    let effect: Injected = format!("gravity_compliance:j2={COMPLIANCE},j3={COMPLIANCE}")
        .parse()
        .expect("effect");
    let cfg = SimConfig::new(seed, n).with_noise(NoiseModel::paper(&cable));
    simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &[effect]).expect("sim")
}

/// The library's end point (m, rig frame) at readings `theta`, under the distance-log state
/// `s` on `haptic`'s chain: the readings through the state's transmissions, each joint
/// deflected by its compliance times the handle's gravity torque
/// (`hapcal_problems::handle_gravity_torques_nm` at the corrected angles), the chain at the
/// state's deviations.
fn library_end_point(haptic: &HapticDevice, s: &DistanceLogState, theta: &[f64]) -> [f64; 3] {
    let mut q = theta.to_vec();
    for tr in &s.transmissions {
        q[tr.joint()] = tr.eval(theta[tr.joint()]).0;
    }
    let mass = haptic.device.handle.expect("a handle").mass_kg;
    let tau = handle_gravity_torques_nm(&haptic.chain, &s.x_kin, &q, mass).expect("torques");
    for (term, coef) in &s.terms {
        if let EffectTermKind::Compliance { joint } = term.kind {
            q[joint] += coef * tau[joint];
        }
    }
    let p = haptic.chain.end_point(&s.x_kin, &q);
    [p.x, p.y, p.z]
}

/// Largest gap (m) between the runtime's end points and the library's under `s`, and the
/// largest gap between the runtime's distance and the library's distance-log model (the
/// model the calibration fitted: residual·σ + measured), over `rows`.
fn gaps(model: &Model, haptic: &HapticDevice, s: &DistanceLogState, rows: &[LogRow]) -> (f64, f64) {
    let lin = log_model(haptic, rows, Vec::new())
        .expect("log model")
        .linearise(s)
        .expect("linearise");
    let (mut point, mut distance) = (0.0f64, 0.0f64);
    for (i, row) in rows.iter().enumerate() {
        let p = model
            .end_pose(&row.q)
            .expect("valid readings")
            .translation_m;
        let want = library_end_point(haptic, s, &row.q);
        for k in 0..3 {
            point = point.max((p[k] - want[k]).abs());
        }
        let d = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let d_lib = lin.residuals[i] * lin.sigma[i] + row.distance_m;
        distance = distance.max((d - d_lib).abs());
    }
    (point, distance)
}

/// The compliance calibration of `train` (step 1, step 2, then the joint problem with the
/// compliances, as `hapcal calibrate --model compliance` runs it).
fn calibrate(haptic: &HapticDevice, train: &[LogRow]) -> ComplianceFit {
    let t = identify_transmissions(haptic, train).expect("step 1");
    let (_, kin) = identify_kinematics(haptic, train, Some(&t)).expect("step 2");
    identify_with_compliance(haptic, train, Some(&t), &kin).expect("compliance fit")
}

#[test]
fn a_haptic_compliance_calibration_evaluates_in_the_runtime_as_in_the_library() {
    let device = hapcal_io::read_device(&fixture("reference-device/device.toml")).expect("fixture");
    let haptic = HapticDevice::new(device).expect("a haptic device");
    let (train, held_out) = (log(31, 200), log(32, 60));
    let fit = calibrate(&haptic, &train);
    let notes = format!(
        "the reference device's simulated log (seed 31, 200 rows, handle compliance \
         {COMPLIANCE} rad/(N·m) on joints 2 and 3) calibrated with the compliance model; \
         written by hapcal-runtime's test haptic_record"
    );
    let calibrated = compliance_device(&haptic, &train, &fit, notes).expect("device");
    let text = hapcal_io::write_device(&calibrated);
    if std::env::var_os("UPDATE_FIXTURES").is_some() {
        // Rewrites the committed file the next test and the C ABI's and Python's tests load.
        std::fs::write(
            fixture("reference-device/compliance-calibrated.toml"),
            &text,
        )
        .expect("write the fixture");
    }

    // The record, read back by the io reader (checked by the contract).
    let again = hapcal_io::parse_device(&text, Path::new("calibrated.toml")).expect("reads back");
    let record = again.calibration.as_ref().expect("a [calibration]");
    assert_eq!(record.schema_version, Some(1));
    assert_eq!(record.model, Some(ModelName::Compliance));
    let torque = record.torque.as_ref().expect("a torque source");
    assert_eq!(torque.source, TorqueSource::HandleMass);
    assert_eq!(torque.gravity_m_s2, hapcal_problems::GRAVITY_M_S2);
    assert_eq!(
        torque.handle_mass_kg,
        haptic.device.handle.map(|h| h.mass_kg)
    );
    let region = record.region.as_ref().expect("a region");
    assert_eq!((region.rows, region.joints.len()), (200, 7));
    let covariance = record.covariance.as_ref().expect("a covariance");
    assert_eq!(covariance.names.len(), record.values.len());
    for name in ["joint_compliance.j2", "joint_compliance.j3"] {
        let v = record.value(name).expect(name);
        assert_eq!(v.unit, "rad/(N·m)");
        // The recorded σ is the covariance's diagonal.
        let i = covariance.names.iter().position(|n| n == name).expect(name);
        assert!((covariance.get(i, i).sqrt() - v.std).abs() <= 1e-12 * v.std);
    }

    let model = Model::from_toml(&text, "calibrated.toml").expect("the runtime loads it");
    assert_eq!(model.compliances()[0], 0.0, "joint 1 is not loaded: pruned");
    assert!(model.compliances()[1] > 0.0 && model.compliances()[2] > 0.0);
    // The library's model of the fit: nominal chain at the fitted deviations.
    for (what, rows) in [("training", &train), ("held-out", &held_out)] {
        let (point, distance) = gaps(&model, &haptic, &fit.state, rows);
        assert!(point <= TOL_M, "{what}: end points differ by {point:e} m");
        assert!(
            distance <= TOL_M,
            "{what}: distances differ by {distance:e} m"
        );
    }
    // The library reading the file it wrote (calibrated rows, the record's values) agrees.
    let state = calibrated_log_state(&again).expect("library state");
    let file_haptic = HapticDevice::new(again.clone()).expect("a haptic device");
    let (point, _) = gaps(&model, &file_haptic, &state, &held_out);
    assert!(point <= TOL_M, "file: end points differ by {point:e} m");

    // An earlier hapcal's record of the same fit (values only, no [calibration.torque]):
    // the handle's load from [handle], gravity along minus joint 1's axis, as the library.
    let legacy = haptic
        .device
        .with_calibration(&compliance_values(&fit), CalibrationMeta::default())
        .expect("legacy");
    let legacy = Model::from_toml(&hapcal_io::write_device(&legacy), "legacy.toml")
        .expect("the runtime loads an earlier record");
    let (point, _) = gaps(&legacy, &haptic, &fit.state, &held_out);
    assert!(
        point <= TOL_M,
        "earlier record: end points differ by {point:e} m"
    );
    assert!(!legacy.has_region());

    // Negative control: the same model without its compliances is far off (the handle's
    // sag, tens of µm), so the comparisons above see the deflection.
    let rigid = model
        .with_handle_compliance(&[0.0; 7], 0.0, [0.0, 0.0, -1.0])
        .expect("rigid");
    let (point, _) = gaps(&rigid, &haptic, &fit.state, &held_out);
    assert!(point > 1e-6, "without compliance: {point:e} m");

    // The region: the training readings are inside, a reading past joint 2's range is not.
    for row in &train {
        assert_eq!(model.outside_region(&row.q).expect("valid"), None);
    }
    let mut past = train[0].q.clone();
    let j2 = &region.joints[1];
    past[1] = j2.max + 0.5 * (j2.max - j2.min);
    let (joint, by) = model
        .outside_region(&past)
        .expect("valid")
        .expect("outside");
    assert_eq!(joint, 1);
    assert!((by - 0.5 * (j2.max - j2.min)).abs() < 1e-12);
}

/// The committed compliance calibration (`fixtures/reference-device/compliance-calibrated.toml`,
/// which the C ABI's tests load; the test above rewrites it with `UPDATE_FIXTURES=1`) against
/// the library's reading of the same file.
#[test]
fn the_committed_compliance_fixture_evaluates_as_the_library_reads_it() {
    let path = fixture("reference-device/compliance-calibrated.toml");
    let device: Device = hapcal_io::read_device(&path).expect("fixture");
    let state = calibrated_log_state(&device).expect("library state");
    let haptic = HapticDevice::new(device).expect("a haptic device");
    let model = Model::load(&path).expect("the runtime loads it");
    assert!(model.compliances().iter().any(|&k| k != 0.0));
    let (point, distance) = gaps(&model, &haptic, &state, &log(33, 40));
    assert!(
        point <= TOL_M && distance <= TOL_M,
        "{point:e} m, {distance:e} m"
    );
}

/// A mistyped value name is refused at its line and column, not skipped.
#[test]
fn a_mistyped_value_name_is_refused_at_its_line() {
    let path = fixture("reference-device/compliance-calibrated.toml");
    let text = std::fs::read_to_string(&path).expect("fixture");
    let bad = text.replacen("joint_compliance.j2", "joint_complience.j2", 1);
    let line = 1 + bad
        .lines()
        .position(|l| l.contains("joint_complience.j2"))
        .expect("the mistyped name");
    match Model::from_toml(&bad, "calibrated.toml") {
        Err(LoadError::Parse {
            line: l,
            column,
            message,
            ..
        }) => {
            assert_eq!((l, column), (line, 1));
            assert!(
                message.contains("\"joint_complience.j2\": unknown value name"),
                "{message}"
            );
        }
        other => panic!("expected a refusal at line {line}, got {other:?}"),
    }
    // A joint the device does not have, in a valid name.
    let bad = text.replace("joint_compliance.j2", "joint_compliance.j9");
    let err = Model::from_toml(&bad, "calibrated.toml").expect_err("no joint 9");
    assert!(
        err.to_string().contains(&format!(
            "calibrated.toml:{line}:1: [calibration.values] joint_compliance.j9: the device has \
             joints 1..=7"
        )),
        "{err}"
    );
}
