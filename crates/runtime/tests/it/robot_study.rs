//! Compensation ([`hapcal_runtime::compensate`]) and the accuracy study of
//! docs/results/runtime.md: a simulated iiwa 14 whose truth is the nominal URDF plus joint
//! origin deviations plus gravity compliance, commanded with the nominal inverse kinematics
//! and with the compensated commands.

use hapcal_runtime::{Compensation, CompensationConfig, Pose, Robot, Target, compensate};

use crate::fixture;
use crate::iiwa_masses::{JOINTS, calibrated_iiwa_text, with_iiwa_masses};
use crate::robot::{compliance, joint_samples, scratch, write_calibrated};

/// Joint compliances of the simulated truth, rad/(N·m): 1/k from 10 kN·m/rad at the base to
/// 3.3 kN·m/rad at the wrist, the order of the iiwa's joint stiffness (its joint torque
/// sensors make each joint an elastic element).
const K_TRUTH: [f64; 7] = [1e-4, 1e-4, 1.5e-4, 1.5e-4, 2e-4, 3e-4, 3e-4];

/// The simulated truth (calibrated origins, masses, compliance) and the nominal robot.
fn truth_and_nominal(name: &str) -> (Robot, Robot) {
    let dir = scratch(name);
    let values: Vec<_> = (JOINTS.iter().zip(K_TRUTH))
        .map(|(j, k)| compliance(j, k, "rad/(N·m)"))
        .collect();
    let truth_path = write_calibrated(
        &dir,
        &with_iiwa_masses(&calibrated_iiwa_text()),
        &values,
        &["ball_link"],
    );
    let truth = Robot::load_urdf(&truth_path, &["ball_link"]).expect("valid");
    let nominal_text = with_iiwa_masses(
        &std::fs::read_to_string(fixture("mukca/urdf/iiwa14.urdf")).expect("fixture"),
    );
    let nominal =
        Robot::from_urdf_str(&nominal_text, "iiwa14.urdf", None, &["ball_link"]).expect("valid");
    assert!(truth.has_compliance() && !nominal.has_compliance());
    (truth, nominal)
}

/// A controller's tolerances: 1 µm and 1 µrad.
const CONFIG: CompensationConfig = CompensationConfig {
    tolerance_m: 1e-6,
    tolerance_rad: 1e-6,
    max_iterations: 50,
    damping_m: 1e-3,
    orientation_scale_m: 0.1,
};

/// Joint configurations within 80 % of the iiwa's ranges, the elbow (joint A4) bent by at
/// least 0.3 rad: the nominal inverse kinematics' solutions of the targets. A target the
/// nominal arm reaches stretched (A4 near 0) lies on the edge of its workspace, and the true
/// arm, whose links differ by the deviations and which sags, may not reach it at all.
fn commands(robot: &Robot, n: usize) -> Vec<Vec<f64>> {
    joint_samples(robot, n)
        .into_iter()
        .map(|q| {
            let mut q: Vec<f64> = q.into_iter().map(|v| 0.8 * v).collect();
            q[3] = q[3].signum() * (0.3 + q[3].abs()).min(0.8 * 2.0942);
            q
        })
        .collect()
}

/// Position (m) and orientation (rad) distance between two poses.
fn distance(a: &Pose, b: &Pose) -> (f64, f64) {
    let p = (0..3)
        .map(|i| (a.translation_m[i] - b.translation_m[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    // trace(Aᵀ·B) = 1 + 2·cos(angle).
    let mut trace = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            trace += a.rotation[i][j] * b.rotation[i][j];
        }
    }
    let angle = (0.5 * (trace - 1.0)).clamp(-1.0, 1.0).acos();
    (p, angle)
}

struct Errors {
    rms_m: f64,
    max_m: f64,
    max_rad: f64,
}

fn summarize(errors: &[(f64, f64)]) -> Errors {
    let n = errors.len() as f64;
    Errors {
        rms_m: (errors.iter().map(|(p, _)| p * p).sum::<f64>() / n).sqrt(),
        max_m: errors.iter().map(|(p, _)| *p).fold(0.0, f64::max),
        max_rad: errors.iter().map(|(_, a)| *a).fold(0.0, f64::max),
    }
}

/// The accuracy study: 1000 six-dimensional targets reachable by the nominal robot; the
/// truth's tip is measured (simulated) at the nominal command and at the compensated one.
#[test]
fn compensation_brings_the_true_tip_onto_1000_targets() {
    let (truth, nominal) = truth_and_nominal("study");
    let (mut ws_truth, mut ws_nominal) = (truth.workspace(), nominal.workspace());
    let mut tip = [Pose::IDENTITY];
    let (mut before, mut after) = (Vec::new(), Vec::new());
    let mut q = vec![0.0; 7];
    let (mut iterations, mut deflection_iterations, mut unreached) = (0, 0, 0);
    for q_nominal in commands(&nominal, 1000) {
        let target = nominal
            .tip_pose(0, &q_nominal, &mut ws_nominal)
            .expect("valid");
        truth
            .deflected_tip_poses(&q_nominal, &mut ws_truth, &mut tip)
            .expect("valid");
        before.push(distance(&tip[0], &target));
        let c: Compensation = compensate(
            &truth,
            0,
            &Target::Pose(target),
            &q_nominal,
            &CONFIG,
            &mut ws_truth,
            &mut q,
        )
        .expect("valid");
        iterations = iterations.max(c.iterations);
        deflection_iterations = deflection_iterations.max(c.deflection.iterations);
        unreached += usize::from(!c.reached);
        truth
            .deflected_tip_poses(&q, &mut ws_truth, &mut tip)
            .expect("valid");
        after.push(distance(&tip[0], &target));
    }
    let (b, a) = (summarize(&before), summarize(&after));
    // The study's figures, copied into docs/results/runtime.md with this test's command
    // (`-- --nocapture`).
    eprintln!(
        "nominal commands: RMS {:.3} mm, max {:.3} mm, max {:.3} mrad; compensated: RMS {:.2e} mm, max {:.2e} mm, max {:.2e} mrad; unreached {unreached}; at most {iterations} steps, {deflection_iterations} deflection iterations",
        b.rms_m * 1e3,
        b.max_m * 1e3,
        b.max_rad * 1e3,
        a.rms_m * 1e3,
        a.max_m * 1e3,
        a.max_rad * 1e3
    );
    // The deviations (0.2–0.8 mm, 0.3–1.2 mrad per joint) and the sag leave the nominal
    // commands millimetres off; compensation removes that to the controller's tolerance.
    assert!(b.rms_m > 1e-3, "nominal RMS {} m", b.rms_m);
    assert_eq!(unreached, 0);
    assert!(a.max_m <= CONFIG.tolerance_m, "{} m", a.max_m);
    assert!(a.max_rad <= CONFIG.tolerance_rad, "{} rad", a.max_rad);
}

#[test]
fn a_position_target_is_reached_and_an_unreachable_one_is_reported() {
    let (truth, nominal) = truth_and_nominal("reach");
    let mut ws = truth.workspace();
    let mut q = vec![0.0; 7];
    let start = [0.3, 0.5, -0.2, -1.1, 0.4, 0.7, 0.1];
    let goal = nominal
        .tip_pose(0, &start, &mut nominal.workspace())
        .expect("valid");
    let c = compensate(
        &truth,
        0,
        &Target::Position(goal.translation_m),
        &start,
        &CONFIG,
        &mut ws,
        &mut q,
    )
    .expect("valid");
    assert!(c.reached && c.position_error_m <= 1e-6, "{c:?}");
    assert_eq!(c.orientation_error_rad, 0.0);
    // 3 m from the base: beyond the iiwa's 0.82 m reach.
    let far = Target::Position([3.0, 0.0, 0.5]);
    let c = compensate(&truth, 0, &far, &start, &CONFIG, &mut ws, &mut q).expect("valid");
    assert!(!c.reached && c.position_error_m > 2.0, "{c:?}");
    // Bad input is an error, not a result.
    let nan = Target::Position([f64::NAN, 0.0, 0.5]);
    let e = compensate(&truth, 0, &nan, &start, &CONFIG, &mut ws, &mut q).expect_err("nan");
    assert_eq!(e.to_string(), "target[0] = NaN is not finite");
    // A pose target's translation is checked as its rotation is (entries 9–11).
    let mut pose = goal;
    pose.translation_m[1] = f64::INFINITY;
    let pose = Target::Pose(pose);
    let e = compensate(&truth, 0, &pose, &start, &CONFIG, &mut ws, &mut q)
        .expect_err("infinite translation");
    assert_eq!(e.to_string(), "target[10] = inf is not finite");
    let e = compensate(&truth, 1, &far, &start, &CONFIG, &mut ws, &mut q).expect_err("tip");
    assert!(e.to_string().contains("tip"), "{e}");
}

/// The compensated command is the one the truth needs: commanding it to the *rigid* truth
/// misses the target by about the sag, so compensation did account for the deflection.
#[test]
fn compensation_accounts_for_the_deflection() {
    let (truth, nominal) = truth_and_nominal("sag");
    let rigid = truth.with_compliances(&[0.0; 7]).expect("valid");
    let mut ws = truth.workspace();
    let start = [0.0, 0.9, 0.0, -0.6, 0.0, 0.8, 0.0];
    let target = nominal
        .tip_pose(0, &start, &mut nominal.workspace())
        .expect("valid");
    let mut q = vec![0.0; 7];
    let goal = Target::Pose(target);
    let c = compensate(&truth, 0, &goal, &start, &CONFIG, &mut ws, &mut q).expect("valid");
    assert!(c.reached, "{c:?}");
    let at_rigid = rigid.tip_pose(0, &q, &mut ws).expect("valid");
    let (sag_m, _) = distance(&at_rigid, &target);
    // Arm stretched forward: the sag at the ball is a fraction of a millimetre or more.
    assert!(sag_m > 1e-4, "{sag_m} m");
}
