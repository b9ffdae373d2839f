//! `ForceModel::nominal` and `ForceModel::calibrated` run on `hapcal-runtime`; here they are
//! checked, to 1e-12, against `ForceModel::nominal_library` and
//! `ForceModel::calibrated_library`, an independent implementation (hapcal-kinematics'
//! chain, hapcal-transmission's capstans and Chebyshev polynomial, the device parsed by
//! hapcal-io instead of the runtime's own TOML reader).

use std::path::{Path, PathBuf};

use hapcal_force::{ForceModel, Readings, SweepConfig, Vector6, sample_poses, wrench_map};
use hapcal_io::{Device, read_device};

use crate::readings::readings;

/// Rounding bound: every quantity is O(1) (m, rad, N·m per N) and both sides compute it in a
/// few dozen floating-point operations, so they agree to far below 1e-12 unless the models
/// differ.
const TOL: f64 = 1e-12;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/reference-device")
        .join(name)
}

fn wrenches() -> [Vector6<f64>; 3] {
    [
        Vector6::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
        Vector6::new(1.5, -2.0, 0.5, 0.0, 0.0, 0.0),
        Vector6::new(-0.3, 0.7, 2.0, 0.05, -0.02, 0.1),
    ]
}

/// Largest difference between the two models' joint angles, `dq/dθ`, tip pose (rotation
/// entries, translation in m), body Jacobian and motor torques over 200 readings and three
/// wrenches.
fn largest_gap(runtime: &ForceModel, library: &ForceModel, device: &Device) -> f64 {
    assert!(
        runtime.runtime().is_some(),
        "the model under test runs on the runtime"
    );
    assert!(
        library.library_drives().is_some(),
        "the reference is the library"
    );
    let mut worst: f64 = 0.0;
    let mut gap = |a: &[f64], b: &[f64]| {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            worst = worst.max((x - y).abs());
        }
    };
    for theta in readings(&device.joint_limits(), 200) {
        let angles = |m: &ForceModel| m.joint_angles(&theta).expect("valid");
        gap(&angles(runtime), &angles(library));
        let derivatives = |m: &ForceModel| m.angle_derivatives(&theta).expect("valid");
        gap(&derivatives(runtime), &derivatives(library));
        let pose = |m: &ForceModel| {
            let p = m.end_pose(&theta).expect("valid");
            let mut v: Vec<f64> = p
                .rotation
                .to_rotation_matrix()
                .matrix()
                .iter()
                .copied()
                .collect();
            v.extend(p.translation.vector.iter());
            v
        };
        gap(&pose(runtime), &pose(library));
        let jac = |m: &ForceModel| m.body_jacobian(&theta).expect("valid").as_slice().to_vec();
        gap(&jac(runtime), &jac(library));
        for w in wrenches() {
            let tau = |m: &ForceModel| m.motor_torques(&theta, &w).expect("valid");
            gap(&tau(runtime), &tau(library));
            let back = |m: &ForceModel| m.joint_torques(&theta, &tau(m)).expect("valid");
            gap(&back(runtime), &back(library));
        }
    }
    worst
}

/// A constructor of a [`ForceModel`] from a device.
type Build = fn(&Device) -> Result<ForceModel, hapcal_force::Error>;

/// Asserts that the model `on_runtime` builds from the fixture `name` and the one
/// `on_library` builds from it agree within [`TOL`] ([`largest_gap`]).
#[track_caller]
fn runtime_matches_library(name: &str, on_runtime: Build, on_library: Build) {
    let device = read_device(&fixture(name)).expect("fixture");
    let runtime = on_runtime(&device).expect("runtime model");
    let library = on_library(&device).expect("library model");
    let worst = largest_gap(&runtime, &library, &device);
    assert!(worst <= TOL, "{name}: largest gap {worst:e}");
}

#[test]
fn calibrated_model_on_the_runtime_matches_the_library() {
    runtime_matches_library(
        "calibrated.toml",
        ForceModel::calibrated,
        ForceModel::calibrated_library,
    );
}

#[test]
fn nominal_model_on_the_runtime_matches_the_library() {
    // The calibrated file: `nominal` must drop its `[calibration]` (ideal drives).
    for name in ["device.toml", "calibrated.toml"] {
        runtime_matches_library(name, ForceModel::nominal, ForceModel::nominal_library);
    }
}

/// The wrench map of the force study (controller on the runtime, device = truth) equals the
/// one with the controller on the library, at the study's Fig. 12 pose and its 200 random
/// poses.
#[test]
fn wrench_map_on_the_runtime_matches_the_library() {
    let truth_path = fixture("truth.toml");
    let truth = hapcal_sim::read_truth(&truth_path).expect("fixture");
    let device = truth.read_device(&truth_path).expect("fixture");
    let calibrated = read_device(&fixture("calibrated.toml")).expect("fixture");
    let truth_model = ForceModel::truth(&device, &truth).expect("truth model");
    let pairs = [
        (
            ForceModel::nominal(&device).expect("runtime"),
            ForceModel::nominal_library(&device).expect("library"),
        ),
        (
            ForceModel::calibrated(&calibrated).expect("runtime"),
            ForceModel::calibrated_library(&calibrated).expect("library"),
        ),
    ];
    let sweep = SweepConfig::reference_device();
    let (mut poses, _) = sample_poses(&device, &truth_model, 3, &sweep).expect("poses");
    poses.push(vec![0.0, 0.45, 0.0, 1.05, 0.0, 0.6, 0.0]);
    for (runtime, library) in &pairs {
        for theta in &poses {
            let r = Readings {
                controller: hapcal_sim::quantise_readings(&device, theta),
                device: theta.clone(),
            };
            let m_runtime = wrench_map(runtime, &truth_model, &r, Some(3)).expect("map");
            let m_library = wrench_map(library, &truth_model, &r, Some(3)).expect("map");
            let worst = (m_runtime - m_library).amax();
            // M = A_truth⁻¹·A_model turns a gap of the model's rows into one of M amplified
            // by at most the truth's condition number, ≤ 100 at the accepted poses (8.1 at
            // the Fig. 12 pose): TOL·100.
            assert!(worst <= TOL * 100.0, "{theta:?}: largest gap {worst:e}");
        }
    }
}

/// Negative control: the comparison sees a change of one calibrated value far below any
/// physical tolerance (0.1 µm on `r_o` of capstan 2).
#[test]
fn comparison_detects_a_changed_transmission_value() {
    let device = read_device(&fixture("calibrated.toml")).expect("fixture");
    let mut changed = device.clone();
    let value = (changed.calibration.as_mut())
        .and_then(|c| c.values.iter_mut().find(|v| v.name == "capstan2.r_o"))
        .expect("capstan2.r_o");
    value.value += 1e-7;
    let runtime = ForceModel::calibrated(&changed).expect("runtime model");
    let library = ForceModel::calibrated_library(&device).expect("library model");
    let worst = largest_gap(&runtime, &library, &device);
    assert!(
        worst > 1e-7,
        "largest gap {worst:e}: the change went unseen"
    );
}
