//! Marker and pose rows on a kinematic tree with instrument and marker frames: the analytic
//! Jacobian against central differences, and frames recovered from exact data.

use super::{
    framed, pose_and_marker_weights, pose_or_marker_row, torso_and_two_arms, torso_configuration,
};
use faer::Col;
use hapcal_identify::{IdentifyConfig, Problem, Subset, identify};
use hapcal_kinematics::Tree;
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, ModelTerms, Observations, Row, RowKind, Weights,
};

/// A torso (prismatic) under two arms of two revolute joints each, with a fixed tool.
fn two_arm_tree() -> Tree {
    torso_and_two_arms([0.0, 0.0, 1.0], true, [0.0, 0.0, 1.0])
}

/// `n` configurations of the tree, the torso's within ±0.1 m.
fn configurations(n: usize) -> Vec<Vec<f64>> {
    (0..n).map(|i| torso_configuration(i, 0.1)).collect()
}

#[test]
fn tree_shares_the_torso() {
    let tree = two_arm_tree();
    assert_eq!(tree.tips().len(), 2);
    assert_eq!(
        tree.joint_names(),
        ["torso", "left_1", "left_2", "right_1", "right_2"]
    );
    // 6 per moving joint and per tool element.
    assert_eq!(tree.n_params(), 6 * 5 + 6 * 2);
    let offsets = tree.with_joint_offsets();
    assert_eq!(offsets.n_params(), tree.n_params() + 5);
    assert!(offsets.joint_offset_params().iter().all(Option::is_some));
}

#[test]
fn pose_rows_jacobian_matches_central_differences() {
    let tree = framed(&two_arm_tree());
    let mut obs = Observations::default();
    for (i, q) in configurations(6).into_iter().enumerate() {
        obs.rows.push(pose_or_marker_row(i, q));
    }
    let weights = pose_and_marker_weights();
    let n_joints = tree.n_joints();
    let torque = two_arm_tree().tips().to_vec();
    let problem = CalibrationProblem::on_tree(
        tree,
        obs,
        weights,
        ModelTerms {
            compliance: Some(GravityCompliance::default()),
            transversal: hapcal_problems::Transversal::None,
            harmonics: None,
            torque_tips: Some(torque),
            load_angles: None,
        },
    )
    .expect("valid problem");
    let n = problem.layout().len();
    assert_eq!(n, 6 + 42 + 5 + 12 + n_joints);
    assert_eq!(problem.n_residuals(), 3 * 6 + 3 * 3);
    let x = Col::from_fn(n, |i| 1e-3 * ((i * 7 % 11) as f64 - 5.0));
    // Residuals are O(1e3) per unit parameter (σ = 1e-3); central differences at h = 1e-6
    // are exact to O(h²·|r'''|) ≈ 1e-9 of that, rounding ≈ 1e-16·|r|/h.
    let worst = crate::worst_relative_jacobian_error(&problem, &x, 1e-6);
    assert!(worst < 1e-5, "largest relative Jacobian error {worst:e}");
}

#[test]
fn frames_recovered_from_exact_poses() {
    let tree = framed(&two_arm_tree());
    let n_robot = two_arm_tree().with_joint_offsets().n_params();
    // The truth: the instrument and marker frames moved from their nominal values.
    let mut truth = vec![0.0; tree.n_params()];
    for (k, v) in [0.01, -0.02, 0.015, 0.02, -0.01, 0.03]
        .into_iter()
        .enumerate()
    {
        truth[k] = v;
        truth[6 + n_robot + k] = 0.5 * v;
        truth[12 + n_robot + k] = -0.7 * v;
    }
    let mut obs = Observations::default();
    for q in configurations(20) {
        for tip in 0..2 {
            let pose = tree.tips()[tip].end_pose(&truth, &q);
            let r = pose.rotation.quaternion();
            obs.rows.push(Row {
                q: q[..].into(),
                kind: RowKind::Pose {
                    tip,
                    position_m: pose.translation.vector.into(),
                    rotation: [r.w, r.i, r.j, r.k],
                },
            });
        }
    }
    let problem = CalibrationProblem::on_tree(tree, obs, Weights::default(), ModelTerms::default())
        .expect("valid problem");
    let frames: Vec<usize> = (0..6).chain(6 + n_robot..18 + n_robot).collect();
    let subset = Subset::new(&problem, frames.clone(), problem.initial_guess());
    let id = identify(&subset, subset.initial_free(), &IdentifyConfig::default()).expect("fit");
    let x = subset.full_x(id.fit.x.as_ref());
    for &i in &frames {
        assert!(
            (x[i] - truth[i]).abs() < 1e-9,
            "{}: {} vs {}",
            problem.layout().name(i),
            x[i],
            truth[i]
        );
    }
    let model = problem.model(x.as_ref());
    let q = &configurations(3)[2];
    let a = model.end_pose_of(1, q);
    let b = problem.tips()[1].end_pose(&truth, q);
    assert!((a.translation.vector - b.translation.vector).norm() < 1e-9);
    assert!(a.rotation.angle_to(&b.rotation) < 1e-9);
}

/// The rows of one configuration (two markers at one reading) share its gravity loads: every
/// row's residuals and Jacobian row on the whole observations equal those of a problem on that
/// row alone, and loads given per configuration at the readings reproduce the readings' own.
#[test]
fn a_configurations_rows_share_its_loads() {
    let tree = framed(&two_arm_tree());
    let mut obs = Observations::default();
    for (i, q) in configurations(5).into_iter().enumerate() {
        // Two markers per configuration, a single one for every third.
        for tip in 0..if i % 3 == 0 { 1 } else { 2 } {
            let position_m = [0.5 + 0.1 * tip as f64, 0.4, 0.3 - 0.05 * i as f64];
            obs.rows.push(Row {
                q: q[..].into(),
                kind: RowKind::Marker { tip, position_m },
            });
        }
    }
    let n_configurations = obs.configurations().count();
    assert_eq!(n_configurations, 5);
    let terms = ModelTerms {
        compliance: Some(GravityCompliance::default()),
        torque_tips: Some(two_arm_tree().tips().to_vec()),
        ..ModelTerms::default()
    };
    let weights = pose_and_marker_weights();
    let problem = CalibrationProblem::on_tree(tree.clone(), obs.clone(), weights, terms.clone())
        .expect("valid problem");
    let n = problem.layout().len();
    // Compliance values of 1e-2 per unit load: the loads move every marker by millimetres.
    let x = Col::from_fn(n, |i| 1e-2 * ((i * 7 % 11) as f64 - 5.0) / 5.0);
    let mut all = Col::zeros(problem.n_residuals());
    problem
        .residuals(x.as_ref(), all.as_mut())
        .expect("residuals");
    for (r, row) in obs.rows.iter().enumerate() {
        let alone = problem
            .with_observations(Observations {
                rows: vec![row.clone()],
                ..Observations::default()
            })
            .expect("one row");
        let mut one = Col::zeros(3);
        alone
            .residuals(x.as_ref(), one.as_mut())
            .expect("residuals");
        for k in 0..3 {
            assert_eq!(all[3 * r + k], one[k], "row {r}, residual {k}");
        }
    }
    // The equilibrium's angles given per configuration, here the readings themselves.
    let at: Vec<f64> = obs
        .configurations()
        .flat_map(|rows| obs.rows[rows.start].q.iter().copied())
        .collect();
    let at_readings = CalibrationProblem::on_tree(
        tree.clone(),
        obs.clone(),
        weights,
        ModelTerms {
            load_angles: Some(at.clone().into()),
            ..terms.clone()
        },
    )
    .expect("valid problem");
    let mut given = Col::zeros(problem.n_residuals());
    at_readings
        .residuals(x.as_ref(), given.as_mut())
        .expect("residuals");
    assert_eq!(given, all);
    // One angle per row (the former layout) is refused.
    let per_row: Vec<f64> = obs.rows.iter().flat_map(|r| r.q.iter().copied()).collect();
    let wrong = CalibrationProblem::on_tree(
        tree,
        obs,
        weights,
        ModelTerms {
            load_angles: Some(per_row.into()),
            ..terms
        },
    );
    assert!(wrong.is_err());
}

/// A fold's problem taken from the whole problem's rows ([`CalibrationProblem::with_rows`])
/// is the problem built on those rows, bit for bit: residuals, Jacobian and layout, with
/// compliance, per-axis transversal compliance and harmonics, a configuration's rows kept or
/// dropped together and apart, and two configurations of equal readings made adjacent by the
/// rows dropped between them.
#[test]
fn a_problem_on_some_rows_is_the_problem_built_on_them() {
    let tree = framed(&two_arm_tree());
    let qs = configurations(6);
    let mut obs = Observations::default();
    // Configuration 4 repeats configuration 2's readings.
    for (i, q) in [0, 1, 2, 3, 2, 5].into_iter().map(|k| &qs[k]).enumerate() {
        for tip in 0..2 {
            let position_m = [0.5 + 0.1 * tip as f64, 0.4, 0.3 - 0.05 * i as f64];
            obs.rows.push(Row {
                q: q[..].into(),
                kind: RowKind::Marker { tip, position_m },
            });
        }
    }
    let terms = ModelTerms {
        compliance: Some(GravityCompliance::default()),
        transversal: hapcal_problems::Transversal::PerAxis,
        harmonics: Some(hapcal_problems::JointHarmonics::first_order(
            tree.n_joints(),
        )),
        torque_tips: Some(two_arm_tree().tips().to_vec()),
        load_angles: None,
    };
    let weights = pose_and_marker_weights();
    let whole = CalibrationProblem::on_tree(tree.clone(), obs.clone(), weights, terms.clone())
        .expect("valid problem");
    let n = whole.layout().len();
    let x = Col::from_fn(n, |i| 1e-2 * ((i * 7 % 11) as f64 - 5.0) / 5.0);
    for keep in [
        // Configuration 3 dropped: 2 and its repeat become adjacent, one configuration.
        vec![
            true, true, true, true, true, true, false, false, true, true, true, true,
        ],
        // One marker of configurations 1 and 4 dropped, the whole of 5.
        vec![
            true, true, false, true, true, true, true, true, true, false, false, false,
        ],
    ] {
        let rows: Vec<Row> = (obs.rows.iter().zip(&keep))
            .filter(|(_, k)| **k)
            .map(|(r, _)| r.clone())
            .collect();
        let built = CalibrationProblem::on_tree(
            tree.clone(),
            Observations {
                rows,
                ..Observations::default()
            },
            weights,
            terms.clone(),
        )
        .expect("valid problem");
        let taken = whole.with_rows(&keep).expect("valid rows");
        assert_eq!(taken.layout(), built.layout());
        let m = built.n_residuals();
        assert_eq!(taken.n_residuals(), m);
        let (mut r_built, mut r_taken) = (Col::zeros(m), Col::zeros(m));
        let (mut j_built, mut j_taken) = (faer::Mat::zeros(m, n), faer::Mat::zeros(m, n));
        (built.residuals_and_jacobian(x.as_ref(), r_built.as_mut(), j_built.as_mut()))
            .expect("evaluated");
        (taken.residuals_and_jacobian(x.as_ref(), r_taken.as_mut(), j_taken.as_mut()))
            .expect("evaluated");
        assert_eq!(r_taken, r_built, "residuals, keeping {keep:?}");
        assert_eq!(j_taken, j_built, "Jacobian, keeping {keep:?}");
    }
}
