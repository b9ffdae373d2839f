//! Integration tests: analytic Jacobians against central finite differences on random chains.

use std::f64::consts::PI;

use hapcal_kinematics::{
    Chain, DhConvention, DhRow, FkWorkspace, Isometry3, LANES, Placement, joint_trig,
    joint_trig_lanes,
};
use nalgebra::Vector3;
use proptest::prelude::*;

/// Finite-difference step (m or rad).
const H: f64 = 1e-6;
/// Longest random `x` / `q` vectors; the chain uses a prefix of them.
const MAX_PARAMS: usize = 8 * 5;
const MAX_PLACEMENT_PARAMS: usize = 8 * 6;
const MAX_JOINTS: usize = 7;

// ---- strategies --------------------------------------------------------------------------

fn dh_row(convention: DhConvention, with_beta: bool) -> impl Strategy<Value = DhRow> {
    let beta = if with_beta {
        prop::option::of(-0.3..0.3f64).boxed()
    } else {
        Just(None).boxed()
    };
    (-0.4..0.4f64, -PI..PI, -0.4..0.4f64, -PI..PI, beta).prop_map(
        move |(a_m, alpha_rad, d_m, theta_rad, beta_rad)| DhRow {
            convention,
            a_m,
            alpha_rad,
            d_m,
            theta_rad,
            beta_rad,
            joint: None,
        },
    )
}

/// A fixed rig → base row (maybe) followed by 3–7 jointed rows.
fn dh_chain(convention: DhConvention, with_beta: bool) -> impl Strategy<Value = Chain> {
    (
        prop::option::of(dh_row(convention, with_beta)),
        prop::collection::vec(dh_row(convention, with_beta), 3..=7),
    )
        .prop_map(|(fixed, jointed)| {
            let jointed = jointed.into_iter().enumerate().map(|(j, r)| DhRow {
                joint: Some(j),
                ..r
            });
            let rows: Vec<DhRow> = fixed.into_iter().chain(jointed).collect();
            Chain::from_dh(&rows).expect("random rows are valid")
        })
}

fn unit_axis() -> impl Strategy<Value = [f64; 3]> {
    (-1.0..1.0f64, -PI..PI).prop_map(|(z, phi)| {
        let r = (1.0 - z * z).sqrt();
        [r * phi.cos(), r * phi.sin(), z]
    })
}

fn origin() -> impl Strategy<Value = ([f64; 3], [f64; 3])> {
    (
        prop::array::uniform3(-0.3..0.3f64),
        prop::array::uniform3(-PI..PI),
    )
}

/// 3–7 revolute joints, each preceded by 0–2 fixed joints, then 0–2 trailing fixed joints.
fn placement_chain() -> impl Strategy<Value = Chain> {
    let fixed_run = || prop::collection::vec(origin(), 0..=2);
    (
        prop::collection::vec((fixed_run(), origin(), unit_axis()), 3..=7),
        fixed_run(),
    )
        .prop_map(|(joints, trailing)| {
            let fixed = |k: usize, (xyz_m, rpy_rad): ([f64; 3], [f64; 3])| Placement {
                name: format!("fixed{k}"),
                xyz_m,
                rpy_rad,
                axis: None,
                prismatic: false,
            };
            let mut placements = Vec::new();
            for (j, (before, (xyz_m, rpy_rad), axis)) in joints.into_iter().enumerate() {
                for o in before {
                    placements.push(fixed(placements.len(), o));
                }
                let name = format!("joint{}", j + 1);
                placements.push(Placement {
                    name,
                    xyz_m,
                    rpy_rad,
                    axis: Some(axis),
                    prismatic: false,
                });
            }
            for o in trailing {
                placements.push(fixed(placements.len(), o));
            }
            Chain::from_placements(&placements).expect("random placements are valid")
        })
}

fn any_chain() -> impl Strategy<Value = Chain> {
    prop_oneof![
        dh_chain(DhConvention::Standard, false),
        dh_chain(DhConvention::Standard, true),
        dh_chain(DhConvention::Modified, true),
        placement_chain(),
    ]
}

/// A chain with random deviations `x` (|x| ≤ 1e-2) and joint angles `q` (|q| ≤ pi).
fn chain_x_q() -> impl Strategy<Value = (Chain, Vec<f64>, Vec<f64>)> {
    (
        any_chain(),
        prop::collection::vec(-1e-2..1e-2f64, MAX_PARAMS.max(MAX_PLACEMENT_PARAMS)),
        prop::collection::vec(-PI..PI, MAX_JOINTS),
    )
        .prop_map(|(chain, mut x, mut q)| {
            x.truncate(chain.n_params());
            q.truncate(chain.n_joints());
            (chain, x, q)
        })
}

// ---- finite differences ------------------------------------------------------------------

/// Rotation vector of `log(a · bᵀ)`, accurate for small angles (atan2, not acos).
fn rotation_log(a: &Isometry3<f64>, b: &Isometry3<f64>) -> Vector3<f64> {
    let rel = a.rotation * b.rotation.inverse();
    let (w, v) = (rel.scalar(), rel.imag());
    let (w, v) = if w < 0.0 { (-w, -v) } else { (w, v) };
    let n = v.norm();
    if n == 0.0 {
        Vector3::zeros()
    } else {
        v * (2.0 * n.atan2(w) / n)
    }
}

/// Central difference of the tip pose along coordinate `k` of `v`: (linear m, angular rad)
/// per unit of `v[k]`.
fn central_difference(
    v: &[f64],
    k: usize,
    pose: impl Fn(&[f64]) -> Isometry3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let (mut up, mut down) = (v.to_vec(), v.to_vec());
    up[k] += H;
    down[k] -= H;
    let (t_up, t_down) = (pose(&up), pose(&down));
    let linear = (t_up.translation.vector - t_down.translation.vector) / (2.0 * H);
    (linear, rotation_log(&t_up, &t_down) / (2.0 * H))
}

fn check_close(what: &str, analytic: &[f64], fd: &[f64]) -> Result<(), TestCaseError> {
    for (k, (a, f)) in analytic.iter().zip(fd).enumerate() {
        prop_assert!(
            (a - f).abs() <= 1e-8 + 1e-6 * f.abs(),
            "{what}, row {k}: analytic {a} vs fd {f}"
        );
    }
    Ok(())
}

// ---- properties --------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn param_jacobians_match_central_differences((chain, x, q) in chain_x_q()) {
        let point_jac = chain.point_jacobian_wrt_params(&x, &q);
        let pose_jac = chain.pose_jacobian_wrt_params(&x, &q);
        prop_assert_eq!(pose_jac.fixed_rows::<3>(0), point_jac.rows(0, 3));
        for (j, info) in chain.params().iter().enumerate() {
            let (linear, angular) = central_difference(&x, j, |x| chain.end_pose(x, &q));
            check_close(&format!("point, {}", info.name), point_jac.column(j).as_slice(), linear.as_slice())?;
            let pose_col = pose_jac.column(j);
            check_close(&format!("pose linear, {}", info.name), &pose_col.as_slice()[..3], linear.as_slice())?;
            check_close(&format!("pose angular, {}", info.name), &pose_col.as_slice()[3..], angular.as_slice())?;
        }
    }

    #[test]
    fn geometric_jacobian_matches_central_differences((chain, x, q) in chain_x_q()) {
        let jac = chain.geometric_jacobian(&x, &q);
        for (j, name) in chain.joint_names().iter().enumerate() {
            let (linear, angular) = central_difference(&q, j, |q| chain.end_pose(&x, q));
            let col = jac.column(j);
            check_close(&format!("linear, {name}"), &col.as_slice()[..3], linear.as_slice())?;
            check_close(&format!("angular, {name}"), &col.as_slice()[3..], angular.as_slice())?;
        }
    }

    #[test]
    fn end_point_is_the_last_frame_origin((chain, x, q) in chain_x_q()) {
        let poses = chain.frame_poses(&x, &q);
        let end = chain.end_pose(&x, &q);
        prop_assert_eq!(poses.len(), chain.factors().len());
        prop_assert!((poses[poses.len() - 1].translation.vector - end.translation.vector).norm() < 1e-15);
        prop_assert_eq!(chain.end_point(&x, &q).coords, end.translation.vector);
    }

    #[test]
    fn frozen_chain_matches_the_factor_chain((chain, x, q) in chain_x_q()) {
        let frozen = chain.freeze(&x);
        let mut ws = FkWorkspace::new(&chain);
        let mut jac = vec![0.0; 3 * chain.n_params()];
        let mut jac_frozen = jac.clone();
        let p = chain.point_and_jacobian_in(&x, &q, &mut ws, &mut jac);
        // Twice, to check that the workspace is reusable.
        for _ in 0..2 {
            let pf = frozen.point_and_jacobian(&q, &mut jac_frozen, &mut ws);
            prop_assert!((pf - p).norm() < 1e-12, "{pf} vs {p}");
        }
        prop_assert!((frozen.end_point(&q) - p).norm() < 1e-12);
        for (k, (a, b)) in jac.iter().zip(&jac_frozen).enumerate() {
            prop_assert!((a - b).abs() < 1e-12, "entry {k}: {a} vs {b}");
        }
        // Angles by their sines and cosines; the distance gradient is uᵀ·∂P/∂x.
        let trig = joint_trig(&q);
        prop_assert!((frozen.end_point_trig(&q, &trig) - p).norm() < 1e-12);
        let mut grad = vec![0.0; chain.n_params()];
        for t in [None, Some(trig.as_slice())] {
            let pd = frozen.distance_gradient(&q, t, &mut grad, &mut ws);
            prop_assert!((pd - p).norm() < 1e-12);
            let u = p.coords / p.coords.norm();
            for (j, g) in grad.iter().enumerate() {
                let expected = u.x * jac[3 * j] + u.y * jac[3 * j + 1] + u.z * jac[3 * j + 2];
                prop_assert!((g - expected).abs() < 1e-12, "param {j}: {g} vs {expected}");
            }
        }
    }

    #[test]
    fn lane_kernel_matches_the_scalar_path_and_central_differences(
        (chain, x, _) in chain_x_q(),
        qs in prop::collection::vec(prop::collection::vec(-PI..PI, MAX_JOINTS), LANES),
    ) {
        let frozen = chain.freeze(&x);
        // Chains with a general or prismatic joint axis take the scalar path only.
        prop_assume!(frozen.supports_lanes());
        let n = chain.n_params();
        let qs: Vec<Vec<f64>> = qs.into_iter().map(|mut q| { q.truncate(chain.n_joints()); q }).collect();
        let trigs: Vec<_> = qs.iter().map(|q| joint_trig(q)).collect();
        let lane_trig = joint_trig_lanes(std::array::from_fn(|l| qs[l].as_slice()));
        let mut dist = [[0.0; LANES]];
        let mut grad = vec![[0.0; LANES]; n];
        frozen.distance_gradient_lanes(&lane_trig, 1.0, &mut dist, Some(&mut grad));
        let dist = dist[0];
        // The gradient scales with `grad_scale`; the distances do not depend on it.
        let mut dist_scaled = [[0.0; LANES]];
        let mut grad_scaled = vec![[0.0; LANES]; n];
        frozen.distance_gradient_lanes(&lane_trig, 0.5, &mut dist_scaled, Some(&mut grad_scaled));
        let dist_scaled = dist_scaled[0];
        prop_assert_eq!(dist_scaled, dist);
        for (g, h) in grad.iter().zip(&grad_scaled) {
            for l in 0..LANES {
                prop_assert!((0.5 * g[l] - h[l]).abs() <= 1e-15 * g[l].abs().max(1.0), "{} vs {}", g[l], h[l]);
            }
        }
        let mut dist_only = [[0.0; LANES]];
        frozen.distance_gradient_lanes(&lane_trig, 1.0, &mut dist_only, None);
        let dist_only = dist_only[0];
        // Three groups in one call (the second and third the first again): the same results
        // for each group as the call with one.
        let trig3: Vec<_> = lane_trig.iter().chain(&lane_trig).chain(&lane_trig).copied().collect();
        let mut dist3 = [[0.0; LANES]; 3];
        let mut grad3 = vec![[0.0; LANES]; 3 * n];
        frozen.distance_gradient_lanes(&trig3, 1.0, &mut dist3, Some(&mut grad3));
        for g in 0..3 {
            prop_assert_eq!(dist3[g], dist);
            prop_assert_eq!(&grad3[g * n..(g + 1) * n], grad.as_slice());
        }
        // Into the columns of a Jacobian, from row 5, one extra column left alone.
        let mut columns = vec![vec![-1.0; 5 + 3 * LANES + 2]; n + 1];
        let mut col_refs: Vec<&mut [f64]> = columns.iter_mut().map(|c| c.as_mut_slice()).collect();
        let mut dist_cols = [[0.0; LANES]; 3];
        frozen.distance_gradient_lanes_into(&trig3, 1.0, &mut dist_cols, &mut col_refs, 5);
        prop_assert_eq!(dist_cols, dist3);
        for (j, column) in columns.iter().enumerate() {
            for (row, v) in column.iter().enumerate() {
                let expected = match row.checked_sub(5) {
                    Some(k) if j < n && k < 3 * LANES => grad3[(k / LANES) * n + j][k % LANES],
                    _ => -1.0,
                };
                prop_assert_eq!(*v, expected, "column {}, row {}", j, row);
            }
        }
        let mut ws = FkWorkspace::new(&chain);
        let mut scalar = vec![0.0; n];
        for (l, q) in qs.iter().enumerate() {
            let p = frozen.distance_gradient(q, Some(&trigs[l]), &mut scalar, &mut ws);
            let d = p.coords.norm();
            // The same quantities by other operations: rounding differences only, a few ulps
            // of the largest term (|P| ≤ ~2 m, gradient entries ≤ ~2 m/rad).
            prop_assert!((dist[l] - d).abs() <= 1e-12 * d.max(1.0), "lane {l}: |P| {} vs {d}", dist[l]);
            prop_assert_eq!(dist_only[l], dist[l]);
            let scale = scalar.iter().fold(1.0_f64, |m, g| m.max(g.abs()));
            for (j, g) in scalar.iter().enumerate() {
                prop_assert!((grad[j][l] - g).abs() <= 1e-12 * scale, "lane {l}, param {j}: {} vs {g}", grad[j][l]);
            }
            // And the analytic row against central differences of |P| (step H; truncation
            // error O(H²·|∂³|P||) ≈ 1e-12, rounding ≈ ε·|P|/H ≈ 1e-10).
            for j in 0..n {
                let (mut up, mut down) = (x.clone(), x.clone());
                up[j] += H;
                down[j] -= H;
                let fd = (chain.end_point(&up, q).coords.norm() - chain.end_point(&down, q).coords.norm()) / (2.0 * H);
                prop_assert!((grad[j][l] - fd).abs() <= 1e-8 + 1e-6 * fd.abs(), "lane {l}, param {j}: {} vs fd {fd}", grad[j][l]);
            }
        }
    }
}
