//! Gravity loads on a tree: every branch loads the joints above it and no other, the torque
//! is the derivative of the potential energy, and the transversal compliance's analytic
//! Jacobian agrees with central differences.

use super::{
    framed, pose_and_marker_weights, pose_or_marker_row, torso_and_two_arms, torso_configuration,
};
use faer::Col;
use hapcal_identify::Problem;
use hapcal_kinematics::{Chain, Factor, Isometry3, Point3, Tree, Vector3};
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, LinkMass, ModelTerms, Observations, Row, RowKind,
    Weights,
};

/// A torso that pitches (axis y, so that both arms load it) under two arms of two revolute
/// joints each, with a fixed tool.
fn torso_tree() -> Tree {
    torso_and_two_arms([0.0, 1.0, 0.0], false, [1.0, 0.0, 0.3])
}

/// A mass on every link, centres of mass off every axis.
fn masses(n_joints: usize) -> Vec<LinkMass> {
    (0..n_joints)
        .map(|joint| LinkMass {
            joint,
            mass_kg: 1.0 + joint as f64,
            com_m: Vector3::new(0.05, -0.02 * joint as f64, 0.1),
        })
        .collect()
}

/// World pose of each joint's link (after its motion) on the nominal tree.
fn link_poses(tree: &Tree, q: &[f64]) -> Vec<Isometry3<f64>> {
    let mut link = vec![Isometry3::identity(); tree.n_joints()];
    for chain in tree.tips() {
        let poses = chain.frame_poses(&vec![0.0; chain.n_params()], q);
        for (f, pose) in chain.factors().iter().zip(poses) {
            if let Factor::Screw { joint: Some(j), .. } = f {
                link[*j] = pose;
            }
        }
    }
    link
}

/// Potential energy `Σ m·g₀·z` of the masses (gravity along −z), J.
fn potential(tree: &Tree, masses: &[LinkMass], q: &[f64]) -> f64 {
    let link = link_poses(tree, q);
    (masses.iter())
        .map(|m| m.mass_kg * 9.806_65 * (link[m.joint] * Point3::from(m.com_m)).z)
        .sum()
}

#[test]
fn every_branch_loads_the_joints_above_it_and_no_other() {
    let tree = torso_tree();
    let model = GravityCompliance::from_link_masses(masses(tree.n_joints()), -Vector3::z());
    for q in [
        vec![0.3, -0.7, 0.4, 1.1, -0.2],
        vec![-0.5, 0.2, -1.3, 0.6, 0.9],
    ] {
        let loads = model.joint_loads(tree.tips(), &q);
        for j in 0..q.len() {
            // The torque gravity exerts about a joint is −∂U/∂q_j (virtual work).
            let h = 1e-6;
            let (mut qp, mut qm) = (q.clone(), q.clone());
            qp[j] += h;
            qm[j] -= h;
            let expected = -(potential(&tree, &model.masses, &qp)
                - potential(&tree, &model.masses, &qm))
                / (2.0 * h);
            // Central differences: O(h²·U''') ≈ 1e-11 N·m, rounding ≈ 1e-16·U/h ≈ 1e-9 N·m.
            assert!(
                (loads[j].torque - expected).abs() < 1e-6,
                "joint {}: {} vs {expected} N·m",
                tree.joint_names()[j],
                loads[j].torque
            );
        }
        // The right arm's masses do not load the left arm: the left arm's torques are those
        // of the left arm's masses alone.
        let left_only: Vec<LinkMass> = (masses(tree.n_joints()).into_iter())
            .filter(|m| m.joint <= 2)
            .collect();
        let left = GravityCompliance::from_link_masses(left_only, -Vector3::z());
        let alone = left.joint_loads(tree.tips(), &q);
        for j in 1..=2 {
            assert!((alone[j].torque - loads[j].torque).abs() < 1e-12);
        }
        // The torso carries both arms: more than either alone.
        assert!((alone[0].torque - loads[0].torque).abs() > 0.1);
    }
}

#[test]
fn one_chain_keeps_the_serial_torques() {
    // A single path of the tree: the tree's loads restricted to it are the serial ones.
    let tree = torso_tree();
    let left: &Chain = &tree.tips()[0];
    let left_masses: Vec<LinkMass> = (masses(tree.n_joints()).into_iter())
        .filter(|m| m.joint <= 2)
        .collect();
    let model = GravityCompliance::from_link_masses(left_masses, -Vector3::z());
    let q = [0.4, -0.3, 0.8, 0.0, 0.0];
    let serial = model.lumped_torques(left, &q);
    let tree_loads = model.joint_loads(tree.tips(), &q);
    for j in 0..3 {
        assert!((serial[j] - tree_loads[j].torque).abs() < 1e-12);
    }
    // The right arm's joints are on no path of the left chain: no torque there.
    assert_eq!(serial[3], 0.0);
    assert_eq!(serial[4], 0.0);
}

/// Gravity compliance from [`masses`] on `tips`, with the transversal compliance `transversal`.
fn gravity_terms(
    n_joints: usize,
    tips: &[hapcal_kinematics::Chain],
    transversal: hapcal_problems::Transversal,
) -> ModelTerms {
    ModelTerms {
        compliance: Some(GravityCompliance::from_link_masses(
            masses(n_joints),
            -Vector3::z(),
        )),
        transversal,
        harmonics: None,
        torque_tips: Some(tips.to_vec()),
        load_angles: None,
    }
}

#[test]
fn transversal_compliance_jacobian_matches_central_differences() {
    transversal_jacobian_matches_central_differences(hapcal_problems::Transversal::Isotropic);
}

/// The per-axis form: two compliances per joint, about axes that turn with the joint.
#[test]
fn per_axis_transversal_compliance_jacobian_matches_central_differences() {
    transversal_jacobian_matches_central_differences(hapcal_problems::Transversal::PerAxis);
}

fn transversal_jacobian_matches_central_differences(transversal: hapcal_problems::Transversal) {
    let per_joint = if transversal == hapcal_problems::Transversal::PerAxis {
        2
    } else {
        1
    };
    let robot = torso_tree();
    let tree = framed(&robot);
    let mut obs = Observations::default();
    for i in 0..6 {
        let q = torso_configuration(i, 0.3);
        obs.rows.push(pose_or_marker_row(i, q));
    }
    let weights = pose_and_marker_weights();
    let n_joints = tree.n_joints();
    let problem = CalibrationProblem::on_tree(
        tree,
        obs,
        weights,
        gravity_terms(n_joints, robot.tips(), transversal),
    )
    .expect("valid problem");
    // Every joint revolute with rotation deviations: one (two) transversal parameters each.
    assert_eq!(problem.n_transversal(), per_joint * n_joints);
    assert_eq!(problem.transversal_kind(), transversal);
    let n = problem.layout().len();
    // Compliances of 1e-3 rad/(N·m) give tilts of tens of mrad: far from linear.
    let x = Col::from_fn(n, |i| 1e-3 * ((i * 7 % 11) as f64 - 5.0));
    // Residuals are O(1e3·30 N·m) per unit compliance; central differences at h = 1e-7 are
    // exact to O(h²·|r'''|), rounding ≈ 1e-16·|r|/h ≈ 1e-8.
    let worst = crate::worst_relative_jacobian_error(&problem, &x, 1e-7);
    assert!(worst < 1e-5, "largest relative Jacobian error {worst:e}");
    // The model predicts what the problem fits.
    let model = problem.model(x.as_ref());
    assert_eq!(model.transversal.len(), per_joint * n_joints);
    let mut r = Col::zeros(problem.n_residuals());
    problem
        .residuals(x.as_ref(), r.as_mut())
        .expect("residuals");
    let row = &problem.observations().rows[1];
    let RowKind::Marker { tip, position_m } = row.kind else {
        panic!("row 1 is a marker row")
    };
    let p = model.end_pose_of(tip, &row.q).translation.vector;
    // Row 0 is a pose row (6 residuals); row 1's position residuals follow.
    for k in 0..3 {
        assert!(((p[k] - position_m[k]) / 1e-3 - r[6 + k]).abs() < 1e-9);
    }
}

#[test]
fn transversal_compliance_needs_the_compliance_model() {
    let robot = torso_tree();
    let obs = Observations {
        rows: vec![Row {
            q: vec![0.0; 5].into(),
            kind: RowKind::Marker {
                tip: 0,
                position_m: [0.0; 3],
            },
        }],
        ..Observations::default()
    };
    let err = CalibrationProblem::on_tree(
        robot,
        obs,
        Weights::default(),
        ModelTerms {
            transversal: hapcal_problems::Transversal::Isotropic,
            ..ModelTerms::default()
        },
    )
    .expect_err("no compliance model");
    assert!(err.to_string().contains("gravity compliance"), "{err}");
}

/// The compliance and transversal parameters carry the unit of their loads, which sets the
/// prior the rank decision holds them to: rad/(N·m) under link masses, rad/m under the lumped
/// unit weights; the joints' own parameters stay in m and rad.
#[test]
fn compliances_carry_the_unit_of_their_loads() {
    use hapcal_identify::Unit;
    let robot = torso_tree();
    let obs = || Observations {
        rows: vec![pose_or_marker_row(1, vec![0.1; 5])],
        ..Observations::default()
    };
    let n_joints = robot.n_joints();
    let units = |terms: ModelTerms| {
        let problem =
            CalibrationProblem::on_tree(framed(&robot), obs(), pose_and_marker_weights(), terms)
                .expect("valid problem");
        let unit_of = |prefix: &str| -> Vec<Unit> {
            (problem.layout().specs().iter())
                .filter(|s| s.name.starts_with(prefix))
                .map(|s| s.unit)
                .collect()
        };
        (unit_of("compliance."), unit_of("transversal."))
    };
    let per_axis = hapcal_problems::Transversal::PerAxis;
    let (axial, transversal) = units(gravity_terms(n_joints, robot.tips(), per_axis));
    assert_eq!(axial, vec![Unit::RadianPerNewtonMeter; n_joints]);
    assert_eq!(transversal, vec![Unit::RadianPerNewtonMeter; 2 * n_joints]);
    let lumped = ModelTerms {
        compliance: Some(GravityCompliance::default()),
        ..gravity_terms(n_joints, robot.tips(), per_axis)
    };
    let (axial, transversal) = units(lumped);
    assert_eq!(axial, vec![Unit::RadianPerMeter; n_joints]);
    assert_eq!(transversal, vec![Unit::RadianPerMeter; 2 * n_joints]);
}

#[test]
fn the_torque_equilibrium_is_a_fixed_point() {
    let tree = torso_tree();
    let n = tree.n_joints();
    let compliance = GravityCompliance::from_link_masses(masses(n), -Vector3::z());
    // An elastic robot: 2 mrad per N·m turns the torso by tens of mrad under its arms.
    let k = vec![2e-3; n];
    let model = hapcal_problems::CalibratedModel {
        tips: tree.tips().to_vec(),
        torque_tips: tree.tips().to_vec(),
        compliance: Some((compliance.clone(), k.clone())),
        equilibrium: true,
        ..hapcal_problems::CalibratedModel::nominal(tree.tips()[0].clone())
    };
    let q = [0.3, -0.7, 0.4, 1.1, -0.2];
    let (theta, iterations) = model.load_angles(&q);
    assert!(iterations > 1 && iterations < hapcal_problems::EQUILIBRIUM_ITERATIONS);
    let loads = compliance.joint_loads(tree.tips(), &theta);
    for j in 0..n {
        let gap = (theta[j] - (q[j] + k[j] * loads[j].torque)).abs();
        assert!(
            gap < 1e-11,
            "joint {j}: {gap:e} after {iterations} iterations"
        );
    }
    // The deflection with the equilibrium's loads is the equilibrium itself.
    let angles = model.effective_angles(&q);
    for j in 0..n {
        assert!((angles[j] - theta[j]).abs() < 1e-11);
    }
    // At the fixed point one more step moves nothing; from the undeflected loads it does.
    assert!(model.equilibrium_step_m(&q) < 1e-9);
    let one_step = hapcal_problems::CalibratedModel {
        equilibrium: false,
        ..model
    };
    assert!(one_step.equilibrium_step_m(&q) > 1e-5);
}

/// Two per-axis compliances of one value bend a joint as one isotropic compliance of that
/// value: the two axes and the joint axis are orthonormal, so `(u·m)u + (v·m)v` is the whole
/// transversal moment `m`.
#[test]
fn equal_per_axis_compliances_are_the_isotropic_one() {
    use hapcal_problems::Transversal;
    let tree = torso_tree();
    let n_joints = tree.n_joints();
    let obs = Observations {
        rows: vec![Row {
            q: vec![0.0; n_joints].into(),
            kind: RowKind::Marker {
                tip: 0,
                position_m: [0.0; 3],
            },
        }],
        ..Observations::default()
    };
    let model_of = |transversal| {
        let problem = CalibrationProblem::on_tree(
            tree.clone(),
            obs.clone(),
            Weights::default(),
            gravity_terms(n_joints, tree.tips(), transversal),
        )
        .expect("valid problem");
        let layout = problem.layout().clone();
        // 1e-3 rad/(N·m) per joint j·1e-4 apart; the same value for `.u` and `.v`.
        let x = Col::from_fn(layout.len(), |i| {
            let name = layout.name(i);
            let joint = name
                .strip_prefix("transversal.")
                .map(|j| j.trim_end_matches(".u").trim_end_matches(".v"));
            match joint {
                Some(j) => {
                    1e-3 + 1e-4
                        * (tree.joint_names().iter().position(|n| n == j).unwrap_or(0) as f64)
                }
                None if name.starts_with("compliance.") => 5e-4,
                None => 0.0,
            }
        });
        problem.model(x.as_ref())
    };
    let isotropic = model_of(Transversal::Isotropic);
    let per_axis = model_of(Transversal::PerAxis);
    for i in 0..5 {
        let t = f64::from(i);
        let q: Vec<f64> = (0..n_joints)
            .map(|j| (0.7 * t + 1.3 * j as f64).sin())
            .collect();
        for tip in 0..tree.tips().len() {
            let a = isotropic.end_pose_of(tip, &q);
            let b = per_axis.end_pose_of(tip, &q);
            let gap = (a.translation.vector - b.translation.vector).norm();
            assert!(gap < 1e-12, "tip {tip}, configuration {i}: {gap:e} m apart");
        }
    }
}

/// Residuals and Jacobian of `problem` at `x`.
fn evaluated(problem: &CalibrationProblem, x: &Col<f64>) -> (Col<f64>, faer::Mat<f64>) {
    let mut r = Col::zeros(problem.n_residuals());
    let mut j = faer::Mat::zeros(problem.n_residuals(), problem.layout().len());
    problem
        .residuals_and_jacobian(x.as_ref(), r.as_mut(), j.as_mut())
        .expect("evaluation");
    (r, j)
}

/// A problem that evaluates its configurations' bases row by row (as one past the bound of
/// kept values is built) gives the kept bases' residuals and Jacobian bit for bit: per-axis
/// transversal compliance on two markers a configuration, at the readings and at given load
/// angles, and compliance with harmonics on a chain's distance, position and point rows.
#[test]
fn bases_evaluated_row_by_row_equal_the_kept_ones() {
    let robot = torso_tree();
    let tree = framed(&robot);
    let mut obs = Observations::default();
    for i in 0..7 {
        let q = torso_configuration(i, 0.3);
        for tip in 0..2 {
            obs.rows.push(Row {
                q: q[..].into(),
                kind: RowKind::Marker {
                    tip,
                    position_m: [0.4, 0.1 * i as f64, 0.9 - 0.2 * tip as f64],
                },
            });
        }
    }
    let n_joints = tree.n_joints();
    let terms = gravity_terms(
        n_joints,
        robot.tips(),
        hapcal_problems::Transversal::PerAxis,
    );
    // Load angles 20 mrad off the readings: the loads, and so the bases, differ from theirs.
    let at: Vec<f64> = (obs.configurations())
        .flat_map(|rows| obs.rows[rows.start].q.iter().map(|q| q + 0.02))
        .collect();
    let at: std::sync::Arc<[f64]> = at.into();
    for load_angles in [None, Some(at)] {
        let terms = ModelTerms {
            load_angles,
            ..terms.clone()
        };
        let build = || {
            CalibrationProblem::on_tree(
                tree.clone(),
                obs.clone(),
                pose_and_marker_weights(),
                terms.clone(),
            )
            .expect("valid problem")
        };
        let kept = build();
        let x = Col::from_fn(kept.layout().len(), |i| 1e-3 * ((i * 7 % 11) as f64 - 5.0));
        let per_row = build().without_stored_bases();
        assert_eq!(evaluated(&kept, &x), evaluated(&per_row, &x));
    }
    let qs: Vec<Vec<f64>> = (0..12)
        .map(|i| {
            let t = i as f64;
            (0..7).map(|j| (0.3 * t + 0.7 * j as f64).sin()).collect()
        })
        .collect();
    let harmonics = hapcal_problems::JointHarmonics {
        joints: vec![1, 3],
        orders: vec![1, 2],
    };
    let chain = || {
        crate::problem_with_models(
            &qs,
            Some(GravityCompliance::default()),
            Some(harmonics.clone()),
        )
    };
    let kept = chain();
    let x = Col::from_fn(kept.layout().len(), |i| 1e-3 * ((i * 5 % 7) as f64 - 3.0));
    assert_eq!(
        evaluated(&kept, &x),
        evaluated(&chain().without_stored_bases(), &x)
    );
}
