//! Physics of the force model: virtual work, the ideal model, a pure ratio error, the closed
//! loop, and the truth's consistency with the simulator.

use std::path::{Path, PathBuf};

use hapcal_io::Device;
use hapcal_sim::Truth;
use hapcal_transmission::{Capstan, CapstanParams};
use nalgebra::{Matrix6, UnitQuaternion, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::{
    Direction, Drive, Error, ForceModel, Readings, WallConfig, closed_loop, home_readings,
    virtual_wall, wrench_error, wrench_map,
};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device")
}

fn reference() -> (Device, Truth) {
    let truth = hapcal_sim::read_truth(&fixtures().join("truth.toml")).expect("fixture truth");
    let device = truth
        .read_device(&fixtures().join("truth.toml"))
        .expect("fixture device");
    (device, truth)
}

/// Random readings within the limits, joint 6 kept ≥ 0.3 rad from its wrist singularity at 0.
fn random_readings(device: &Device, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut theta = hapcal_sim::sample_readings(device, rng, 1)
        .pop()
        .expect("one pose");
    if theta[5].abs() < 0.3 {
        theta[5] = 0.3f64.copysign(theta[5]) + theta[5];
    }
    theta
}

/// Body-frame displacement (linear m, angular rad) from pose `a` to pose `b`, expressed in the
/// frame of the pose `mid` between them.
fn body_displacement(
    a: &nalgebra::Isometry3<f64>,
    b: &nalgebra::Isometry3<f64>,
    mid: &nalgebra::Isometry3<f64>,
) -> Vector6<f64> {
    let lin = mid.rotation.inverse() * (b.translation.vector - a.translation.vector);
    let rel: UnitQuaternion<f64> = a.rotation.inverse() * b.rotation;
    let ang = rel.scaled_axis();
    Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
}

/// Virtual work through the whole truth model, motors to handle: the motor torques that
/// [`ForceModel::motor_torques`] gives for a wrench w do the same work on a small motor
/// motion as w does on the handle's resulting motion, `τ_m · δφ_m = w · δx`.
///
/// δx comes from forward kinematics alone (central differences of the end pose at
/// `θ ± h·u`), so the identity checks the body Jacobian and the transmission derivatives
/// (capstans, four-bar) independently. Central differences leave a relative error of order
/// `h²·|x'''|/|x'| ≈ h² ≈ 1e-8` (link lengths and transmission curvatures are O(1) per rad)
/// and round-off `ε·|x|/(h·|x'|) ≈ 1e-12`; the tolerance 1e-6 is far above both and far below
/// what a missing transmission factor costs (`Re/R` ≈ 2.5e-3, `ΔL/L` ≈ 1e-2), which the second
/// assertion shows.
#[test]
fn virtual_work_holds_from_motors_to_handle() {
    let (device, truth) = reference();
    let model = ForceModel::truth(&device, &truth).expect("truth model");
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let h = 1e-4;
    for _ in 0..10 {
        let theta = random_readings(&device, &mut rng);
        let u: Vec<f64> = (0..7).map(|_| rng.random_range(-1.0..1.0)).collect();
        let w = Vector6::from_fn(|_, _| rng.random_range(-2.0..2.0));
        let tau_m = model.motor_torques(&theta, &w).expect("torques");
        let step =
            |s: f64| -> Vec<f64> { theta.iter().zip(&u).map(|(t, d)| t + s * h * d).collect() };
        let (plus, minus) = (
            model.end_pose(&step(1.0)).expect("pose"),
            model.end_pose(&step(-1.0)).expect("pose"),
        );
        let mid = model.end_pose(&theta).expect("pose");
        let dx = body_displacement(&minus, &plus, &mid);
        // Motor angle φ_m = R·θ, so δφ_m = R·2h·u over the central step.
        let motor_work: f64 = (model.ratios().iter().zip(&u).zip(&tau_m))
            .map(|((r, du), t)| t * r * 2.0 * h * du)
            .sum();
        let handle_work = w.dot(&dx);
        let scale = motor_work.abs().max(handle_work.abs());
        assert!(
            (motor_work - handle_work).abs() <= 1e-6 * scale,
            "motor work {motor_work} J vs handle work {handle_work} J"
        );
        // Without the transmission derivatives (τ_m = τ_j/R) the identity fails.
        let tau_j = model.body_jacobian(&theta).expect("jacobian").transpose() * w;
        let naive_work: f64 = (tau_j.iter().zip(&u)).map(|(t, du)| t * 2.0 * h * du).sum();
        assert!(
            (naive_work - handle_work).abs() > 1e-4 * scale,
            "ignoring the transmissions should break virtual work: {naive_work} vs {handle_work}"
        );
    }
}

/// The ideal model (nominal controller, error-free device) renders the desired wall force
/// with zero transverse component: `M = I` up to round-off. An LU solve is backward stable,
/// so the relative error is bounded by about `n·ε·κ` (Higham, *Accuracy and Stability of
/// Numerical Algorithms*, 2002, §9) with n = 6 and κ the truth Jacobian's 2-norm condition
/// number; the tolerance is 10× that.
#[test]
fn ideal_model_renders_zero_transverse_force() {
    let (device, _) = reference();
    let ideal = Truth::nominal(fixtures().join("device.toml"), &device);
    let truth = ForceModel::truth(&device, &ideal).expect("ideal truth");
    let nominal = ForceModel::nominal(&device).expect("nominal");
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let cfg = WallConfig {
        quantise: false,
        ..WallConfig::paper()
    };
    let mut poses = vec![home_readings(&device)];
    poses[0][5] = 0.6;
    for _ in 0..5 {
        let mut theta = random_readings(&device, &mut rng);
        theta[2] = 0.0;
        poses.push(theta);
    }
    for theta in &poses {
        let jt = truth.body_jacobian(theta).expect("jacobian");
        let a = nalgebra::DMatrix::from_fn(6, 6, |r, c| jt[(r, [0, 1, 3, 4, 5, 6][c])]);
        let s = a.singular_values();
        let tol = 10.0 * 6.0 * f64::EPSILON * s.max() / s.min();
        for sample in virtual_wall(&device, &nominal, &truth, theta, &cfg).expect("wall") {
            let w = sample.wrench;
            let f = sample.desired_n;
            assert!(
                w[0].abs() <= tol * f && w[1].abs() <= tol * f,
                "transverse force {} N, {} N at Fd = {f} N (tol {tol:e} relative)",
                w[0],
                w[1]
            );
            assert!((w[2] - f).abs() <= tol * f, "Fz {} N vs {f} N", w[2]);
        }
        // Quantised readings alone already break the identity: the test can fail.
        let quantised = Readings {
            controller: hapcal_sim::quantise_readings(&device, theta),
            device: theta.clone(),
        };
        let m = wrench_map(&nominal, &truth, &quantised, Some(3)).expect("map");
        assert!((m - Matrix6::identity()).norm() > 100.0 * tol);
    }
}

/// A pure ratio error scales only the magnitude. Every joint is given a capstan (R = 10), and
/// the device's drives have the true ratio `k·R` (`Re = (k − 1)·R`, paper eq. 1) while the
/// controller uses R; the controller reads the true joint angles (as from joint-side
/// encoders: `θ_c = q`, while the device's motor reading is `θ_d = k·q`), so the only error
/// is the torque ratio. Every joint torque is then `k` times the commanded one and
/// `w = k·w_d`: no direction error, magnitude error `(k − 1)·100 %`, to round-off (the
/// tolerance is 1e-9, far above the ~1e-14 of the solve and far below the direction error of
/// the same error on one joint only, checked last).
#[test]
fn pure_ratio_error_scales_only_the_magnitude() {
    let (device, _) = reference();
    let chain = device.chain().expect("chain");
    let x = vec![0.0; chain.n_params()];
    let k = 1.03;
    let capstan = Capstan::try_new(10.0, 0.06).expect("capstan");
    let ideal = Drive::Capstan {
        capstan,
        params: CapstanParams::default(),
    };
    let off = Drive::Capstan {
        capstan,
        params: CapstanParams {
            re: (k - 1.0) * 10.0,
            ..CapstanParams::default()
        },
    };
    let model =
        ForceModel::try_new(chain.clone(), x.clone(), vec![ideal.clone(); 7]).expect("model");
    let truth = ForceModel::try_new(chain.clone(), x.clone(), vec![off.clone(); 7]).expect("truth");
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    for _ in 0..5 {
        let q = random_readings(&device, &mut rng);
        let readings = Readings {
            controller: q.clone(),
            device: q.iter().map(|v| k * v).collect(),
        };
        let m = wrench_map(&model, &truth, &readings, Some(3)).expect("map");
        for d in Direction::ALL {
            let mut wd = Vector6::zeros();
            wd[d.index()] = 1.0;
            let e = wrench_error(&wd, &(m * wd), d);
            assert!(
                e.direction_deg.abs() < 1e-9,
                "{}: {} deg",
                d.name(),
                e.direction_deg
            );
            assert!(
                (e.magnitude_pct - (k - 1.0) * 100.0).abs() < 1e-9,
                "{}: {} %",
                d.name(),
                e.magnitude_pct
            );
        }
        // The same error on joint 1 alone turns the force.
        let mut drives = vec![ideal.clone(); 7];
        drives[0] = off.clone();
        let one = ForceModel::try_new(chain.clone(), x.clone(), drives).expect("truth");
        let mut dev = q.clone();
        dev[0] *= k;
        let readings = Readings {
            controller: q.clone(),
            device: dev,
        };
        let m1 = wrench_map(&model, &one, &readings, Some(3)).expect("map");
        let worst = Direction::ALL
            .iter()
            .map(|&d| {
                let mut wd = Vector6::zeros();
                wd[d.index()] = 1.0;
                wrench_error(&wd, &(m1 * wd), d).direction_deg
            })
            .fold(0.0, f64::max);
        assert!(
            worst > 1e-3,
            "a one-joint ratio error turns some wrench: {worst} deg"
        );
    }
}

/// Proportional force feedback divides a small open-loop error E by 1 + G: for `M = I + E`,
/// `C − I = E/(1 + G) + O(|E|²)` (see [`closed_loop`]); the remainder is bounded by
/// `2|E|²` for |E| ≪ 1.
#[test]
fn feedback_divides_the_error_by_one_plus_gain() {
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let e = Matrix6::from_fn(|_, _| rng.random_range(-1e-3..1e-3));
    let m = Matrix6::identity() + e;
    for gain in [0.0, 1.0, 10.0] {
        let c = closed_loop(&m, gain).expect("closed loop");
        let remainder = (c - Matrix6::identity() - e / (1.0 + gain)).norm();
        assert!(
            remainder <= 2.0 * e.norm_squared(),
            "G = {gain}: {remainder:e}"
        );
    }
    let err = closed_loop(&m, -1.0).expect_err("negative gain");
    assert_eq!(
        err.to_string(),
        "gain = -1 is invalid: expected a finite number ≥ 0"
    );
}

/// The truth model's joint angles are the simulator's (`hapcal_sim::true_joint_angles`).
#[test]
fn truth_model_agrees_with_the_simulator() {
    let (device, truth) = reference();
    let model = ForceModel::truth(&device, &truth).expect("truth model");
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    for _ in 0..20 {
        let theta = random_readings(&device, &mut rng);
        let ours = model.joint_angles(&theta).expect("angles");
        let sim = hapcal_sim::true_joint_angles(&device, &truth, &theta).expect("sim angles");
        assert_eq!(ours, sim);
    }
}

/// The committed calibrated reference device reads back as capstans 1–3 with their identified
/// parameters and the joint-4 polynomial; a wrong unit is an error naming the entry, from the
/// library and from the runtime.
#[test]
fn calibrated_device_file_gives_the_calibrated_drives() {
    let path = fixtures().join("calibrated.toml");
    let device = hapcal_io::read_device(&path).expect("calibrated fixture");
    let model = ForceModel::calibrated_library(&device).expect("calibrated model");
    let drives = model.library_drives().expect("a library model");
    let re1 = device
        .calibration
        .as_ref()
        .and_then(|c| c.values.iter().find(|v| v.name == "capstan1.re"))
        .map(|v| v.value)
        .expect("capstan1.re");
    match &drives[0] {
        Drive::Capstan { params, .. } => assert_eq!(params.re, re1),
        other => panic!("joint 1: {other:?}"),
    }
    match &drives[3] {
        Drive::Polynomial { ratio, poly } => {
            assert_eq!(*ratio, 12.0);
            assert_eq!(poly.degree(), 10);
        }
        other => panic!("joint 4: {other:?}"),
    }
    assert!(matches!(drives[6], Drive::Direct));
    let runtime = ForceModel::calibrated(&device).expect("calibrated model");
    assert!(runtime.runtime().is_some() && runtime.library_drives().is_none());
    assert_eq!(runtime.ratios(), model.ratios());

    let mut bad = device.clone();
    if let Some(v) = (bad.calibration.as_mut())
        .and_then(|c| c.values.iter_mut().find(|v| v.name == "capstan2.r_o"))
    {
        v.unit = "rad".into();
    }
    let err = ForceModel::calibrated_library(&bad).expect_err("wrong unit");
    assert!(matches!(err, Error::Calibration { .. }));
    assert_eq!(
        err.to_string(),
        "calibration value \"capstan2.r_o\": unit is \"rad\", expected \"m\""
    );
    let err = ForceModel::calibrated(&bad).expect_err("wrong unit");
    assert!(matches!(err, Error::Runtime { .. }));
    // The runtime reads the record through the file contract: refused at its line.
    let message = err.to_string();
    assert!(
        message.starts_with("runtime model: device file:")
            && message.ends_with(": \"capstan2.r_o\" is in \"rad\", expected \"m\""),
        "{message}"
    );
}

/// Direction names survive the round trip through `Display` and `FromStr`.
#[test]
fn direction_names_round_trip() {
    for d in Direction::ALL {
        assert_eq!(d.to_string().parse::<Direction>().expect("round trip"), d);
    }
    let err = "Fw".parse::<Direction>().expect_err("not a direction");
    assert_eq!(
        err.to_string(),
        "unknown wrench direction \"Fw\": expected Fx, Fy, Fz, Mx, My or Mz"
    );
}
