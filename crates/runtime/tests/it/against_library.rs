//! The runtime's numbers against the kinematics and transmission libraries', to 1e-12.

use std::f64::consts::PI;

use hapcal_io::read_device;
use hapcal_kinematics::{Chain, DhConvention as KinConvention, DhRow as KinRow};
use hapcal_runtime::{
    CapstanParams, DOMAIN_MARGIN, DhConvention, DhRow, Drive, Evaluation, MAX_COEFFS, Model,
};
use hapcal_transmission::{Capstan, Chebyshev, JointRad};
use proptest::prelude::*;

use crate::robot::pose_gap;
use crate::{fixture, readings};

const TOL: f64 = 1e-12;

fn wrenches() -> [[f64; 6]; 3] {
    [
        [0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
        [1.5, -2.0, 0.5, 0.0, 0.0, 0.0],
        [-0.3, 0.7, 2.0, 0.05, -0.02, 0.1],
    ]
}

/// The calibrated and nominal reference devices against `hapcal-kinematics` at 200 joint
/// configurations spread over the joint box: tip pose, spatial Jacobian and body Jacobian
/// (`diag(Rᵀ, Rᵀ)·J_geo` from the library's geometric Jacobian). The drives and motor
/// torques are compared with the calibration library in hapcal-force's tests
/// (`ForceModel::calibrated` runs on this crate; `ForceModel::calibrated_library` does not).
#[test]
fn reference_devices_match_the_kinematics_library() {
    for name in [
        "reference-device/calibrated.toml",
        "reference-device/device.toml",
    ] {
        let path = fixture(name);
        let device = read_device(&path).expect("fixture");
        let model = Model::load(&path).expect("fixture");
        let chain = device.chain().expect("fixture");
        let x = vec![0.0; chain.n_params()];
        let n = model.n_joints();
        let mut worst: f64 = 0.0;
        for q in readings(&device.joint_limits(), 200) {
            let lib_pose = chain.end_pose(&x, &q);
            let pose = model.end_pose_at_joints(&q).expect("valid");
            worst = worst.max(pose_gap(&pose, &lib_pose));
            let lib = chain.geometric_jacobian(&x, &q);
            let rt = lib_pose.rotation.to_rotation_matrix().matrix().transpose();
            let (mut spatial, mut body) = (vec![[0.0; 6]; n], vec![[0.0; 6]; n]);
            model
                .spatial_jacobian_at_joints(&q, &mut spatial)
                .expect("valid");
            model.body_jacobian_at_joints(&q, &mut body).expect("valid");
            for k in 0..n {
                let lin = rt * lib.fixed_view::<3, 1>(0, k);
                let ang = rt * lib.fixed_view::<3, 1>(3, k);
                for r in 0..3 {
                    worst = worst.max((spatial[k][r] - lib[(r, k)]).abs());
                    worst = worst.max((spatial[k][3 + r] - lib[(3 + r, k)]).abs());
                    worst = worst.max((body[k][r] - lin[r]).abs());
                    worst = worst.max((body[k][3 + r] - ang[r]).abs());
                }
            }
        }
        assert!(worst <= TOL, "{name}: largest gap {worst:e}");
    }
}

/// `evaluate` writes what the single calls return.
#[test]
fn evaluate_equals_the_single_calls() {
    let path = fixture("reference-device/calibrated.toml");
    let device = read_device(&path).expect("fixture");
    let model = Model::load(&path).expect("fixture");
    let n = model.n_joints();
    for theta in readings(&device.joint_limits(), 50) {
        let mut jac = vec![[0.0; 6]; n];
        let pose = model.body_jacobian(&theta, &mut jac).expect("valid");
        for w in wrenches() {
            let mut tau = vec![0.0; n];
            model.motor_torques(&theta, &w, &mut tau).expect("valid");
            let mut out = Evaluation::default();
            model.evaluate(&theta, &w, &mut out).expect("valid");
            assert_eq!(&out.motor_torques_nm[..n], &tau[..]);
            assert_eq!(&out.body_jacobian[..n], &jac[..]);
            assert_eq!(out.pose, pose);
        }
    }
}

/// Negative control: the comparison with the kinematics library sees a change of one D-H
/// value far below any physical tolerance (0.1 µm on `a` of row 2).
#[test]
fn comparison_detects_a_changed_dh_value() {
    let path = fixture("reference-device/calibrated.toml");
    let mut device = read_device(&path).expect("fixture");
    let model = Model::load(&path).expect("fixture");
    device.dh[2].a_m += 1e-7;
    let chain = device.chain().expect("valid");
    let x = vec![0.0; chain.n_params()];
    let mut worst: f64 = 0.0;
    for q in readings(&device.joint_limits(), 20) {
        let pose = model.end_pose_at_joints(&q).expect("valid");
        worst = worst.max(pose_gap(&pose, &chain.end_pose(&x, &q)));
    }
    assert!(
        worst > 1e-8,
        "largest gap {worst:e}: the change went unseen"
    );
}

/// A modified D-H chain with a Hayati β and fixed rows at both ends, against
/// `hapcal-kinematics`.
#[test]
fn modified_dh_with_beta_matches_the_kinematics_library() {
    let rows = [
        (0.1, 0.3, 0.05, 0.2, None, false),
        (0.0, -1.2, 0.1, 0.1, Some(0.02), true),
        (0.3, 0.4, -0.02, -0.3, None, true),
        (0.25, 1.5, 0.07, 0.05, Some(-0.01), true),
        (0.05, -0.2, 0.03, 0.4, None, false),
    ];
    for (convention, kin_convention) in [
        (DhConvention::Modified, KinConvention::Modified),
        (DhConvention::Standard, KinConvention::Standard),
    ] {
        let ours: Vec<DhRow> = (rows.iter())
            .map(|&(a_m, alpha_rad, d_m, theta_rad, beta_rad, joint)| DhRow {
                a_m,
                alpha_rad,
                d_m,
                theta_rad,
                beta_rad,
                joint,
            })
            .collect();
        let mut next = 0;
        let theirs: Vec<KinRow> = (rows.iter())
            .map(
                |&(a_m, alpha_rad, d_m, theta_rad, beta_rad, joint)| KinRow {
                    convention: kin_convention,
                    a_m,
                    alpha_rad,
                    d_m,
                    theta_rad,
                    beta_rad,
                    joint: joint.then(|| {
                        next += 1;
                        next - 1
                    }),
                },
            )
            .collect();
        let model = Model::from_dh(convention, &ours, &[Drive::DIRECT; 3]).expect("valid");
        let chain = Chain::from_dh(&theirs).expect("valid");
        let x = vec![0.0; chain.n_params()];
        for q in readings(&[(-2.0, 2.0); 3], 50) {
            let pose = model.end_pose_at_joints(&q).expect("valid");
            assert!(pose_gap(&pose, &chain.end_pose(&x, &q)) <= TOL);
            let mut jac = vec![[0.0; 6]; 3];
            model
                .spatial_jacobian_at_joints(&q, &mut jac)
                .expect("valid");
            let lib = chain.geometric_jacobian(&x, &q);
            for (k, col) in jac.iter().enumerate() {
                for (r, v) in col.iter().enumerate() {
                    assert!((v - lib[(r, k)]).abs() <= TOL, "{convention:?} ({r}, {k})");
                }
            }
        }
    }
}

/// The body Jacobian against central differences of the runtime's own pose: linear rows
/// from the end point, angular rows from `Rᵀ·dR` (the body angular velocity).
#[test]
fn body_jacobian_matches_central_differences() {
    let model = Model::load(&fixture("reference-device/calibrated.toml")).expect("fixture");
    let h = 1e-6;
    for q in readings(&[(-1.0, 1.0); 7], 20) {
        let mut jac = [[0.0; 6]; 7];
        let pose = model.body_jacobian_at_joints(&q, &mut jac).expect("valid");
        for k in 0..7 {
            let (mut up, mut down) = (q.clone(), q.clone());
            up[k] += h;
            down[k] -= h;
            let (pu, pd) = (
                model.end_pose_at_joints(&up).expect("valid"),
                model.end_pose_at_joints(&down).expect("valid"),
            );
            let dp: Vec<f64> = (0..3)
                .map(|i| (pu.translation_m[i] - pd.translation_m[i]) / (2.0 * h))
                .collect();
            let lin = pose.inverse_rotate(&[dp[0], dp[1], dp[2]]);
            // dR/dq = R·[ω_b]×: ω_b from the off-diagonal entries of Rᵀ·dR.
            let skew = |i: usize, j: usize| -> f64 {
                (0..3)
                    .map(|m| {
                        pose.rotation[m][i] * (pu.rotation[m][j] - pd.rotation[m][j]) / (2.0 * h)
                    })
                    .sum()
            };
            let ang = [skew(2, 1), skew(0, 2), skew(1, 0)];
            for r in 0..3 {
                assert!((jac[k][r] - lin[r]).abs() < 1e-8, "joint {k} row {r}");
                assert!(
                    (jac[k][3 + r] - ang[r]).abs() < 1e-8,
                    "joint {k} row {}",
                    3 + r
                );
            }
        }
    }
}

/// `dq/dθ` against central differences of q, for every drive kind of the calibrated device.
#[test]
fn angle_derivatives_match_central_differences() {
    let model = Model::load(&fixture("reference-device/calibrated.toml")).expect("fixture");
    let h = 1e-6;
    for drive in model.drives() {
        for i in 0..50 {
            let theta = -1.5 + 0.06 * i as f64;
            let (_, g) = drive.angle_and_derivative(theta);
            let fd = (drive.angle_and_derivative(theta + h).0
                - drive.angle_and_derivative(theta - h).0)
                / (2.0 * h);
            assert!(
                (g - fd).abs() < 1e-8 * (1.0 + fd.abs()),
                "θ = {theta}: {g} vs {fd}"
            );
        }
    }
}

/// Joint readings over a joint range and past it by the polynomial domain's margin, rad.
const READING_RAD: std::ops::RangeInclusive<f64> = -3.2..=3.2;

/// Valid eq. 1 parameters for a drum distance `d` (m): offsets and ratio errors beyond any
/// identified one, eccentricities up to 0.3 D, every phase.
fn capstan_params(d: f64) -> impl Strategy<Value = CapstanParams> {
    (
        -0.05..=0.05f64,
        -0.1..=0.1f64,
        -0.3 * d..=0.3 * d,
        -PI..=PI,
        -0.3 * d..=0.3 * d,
        -PI..=PI,
    )
        .prop_map(
            |(c_rad, re, r_o_m, beta_o_rad, r_i_m, beta_i_rad)| CapstanParams {
                c_rad,
                re,
                r_o_m,
                beta_o_rad,
                r_i_m,
                beta_i_rad,
            },
        )
}

proptest! {
    /// A capstan drive of the runtime gives the calibration library's joint angle
    /// (`Capstan::output_rad`, paper eq. 1) and `dq/dθ` (`1 + Capstan::error_dtheta`).
    /// Tolerance: both are sums of a few terms below 10 rad, so the rounding of one evaluation
    /// is ~1e-15; 1e-12 rad (relative for `dq/dθ`, which reaches R·r/(D − r)) is any
    /// difference in the formula, not rounding.
    #[test]
    fn capstan_drive_matches_the_library(
        (ratio, d, p) in (2.0..=20.0f64, 0.02..=0.1f64)
            .prop_flat_map(|(ratio, d)| (Just(ratio), Just(d), capstan_params(d))),
        theta in READING_RAD,
    ) {
        let drive = Drive::capstan(ratio, d, p).expect("valid parameters");
        let capstan = Capstan::try_new(ratio, d).expect("valid capstan");
        capstan.check_params(&p).expect("valid parameters");
        let (q, dq) = drive.angle_and_derivative(theta);
        let q_lib = capstan.output_rad(&p, JointRad(theta));
        let dq_lib = 1.0 + capstan.error_dtheta(&p, JointRad(theta));
        prop_assert!((q - q_lib).abs() <= TOL, "q {q} vs {q_lib}");
        prop_assert!((dq - dq_lib).abs() <= TOL * dq_lib.abs().max(1.0), "dq/dθ {dq} vs {dq_lib}");
    }

    /// A polynomial drive of the runtime gives the calibration library's joint angle
    /// `θ + p(θ)` and `1 + p'(θ)` (`Chebyshev::eval`, `Chebyshev::derivative`) for 1 to
    /// `MAX_COEFFS` coefficients, over the domain and its margin. Tolerance as for the
    /// capstan: coefficients below 0.1 rad and |u| ≤ 1.1 keep every term small.
    #[test]
    fn polynomial_drive_matches_the_library(
        lo in -2.0..=0.0f64,
        width in 0.5..=3.0f64,
        coeffs in prop::collection::vec(-0.1..=0.1f64, 1..=MAX_COEFFS),
        share in -DOMAIN_MARGIN..=1.0 + DOMAIN_MARGIN,
    ) {
        let hi = lo + width;
        let theta = lo + share * width;
        let drive = Drive::polynomial(1.0, lo, hi, &coeffs).expect("valid polynomial");
        let lib = Chebyshev::try_new(lo, hi, coeffs).expect("valid polynomial");
        let (q, dq) = drive.angle_and_derivative(theta);
        let (q_lib, dq_lib) = (theta + lib.eval(theta), 1.0 + lib.derivative(theta));
        prop_assert!((q - q_lib).abs() <= TOL, "q {q} vs {q_lib}");
        prop_assert!((dq - dq_lib).abs() <= TOL * dq_lib.abs().max(1.0), "dq/dθ {dq} vs {dq_lib}");
    }
}

/// The property tests above can fail: a drive with one parameter off by 1e-9 (rad, or m for an
/// eccentricity) is told apart from the library's at a reading away from zero.
#[test]
fn drive_comparison_detects_a_changed_parameter() {
    let (ratio, d) = (10.0, 0.06);
    let p = CapstanParams {
        c_rad: 1e-3,
        re: -0.025,
        r_o_m: 0.2e-3,
        beta_o_rad: -1.8,
        r_i_m: 5e-6,
        beta_i_rad: -0.26,
    };
    let capstan = Capstan::try_new(ratio, d).expect("valid capstan");
    let theta = 0.7;
    let q_lib = capstan.output_rad(&p, JointRad(theta));
    let off = CapstanParams {
        r_o_m: p.r_o_m + 1e-9,
        ..p
    };
    let (q, _) = Drive::capstan(ratio, d, off)
        .expect("valid parameters")
        .angle_and_derivative(theta);
    assert!((q - q_lib).abs() > TOL, "gap {:e}", (q - q_lib).abs());
}
