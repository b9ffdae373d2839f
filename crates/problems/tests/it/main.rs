//! Integration tests of hapcal-problems: analytic Jacobians against central differences, and
//! the step-1 transmission problems' identification round trips (`transmission`).

mod crosscheck;
mod fleet;
mod gravity;
mod identifiability;
mod streaming;
mod transmission;
mod tree;

use faer::{Col, Mat};
use hapcal_identify::Problem;
use hapcal_kinematics::{Chain, FrameSpec, Isometry3, Placement, Tree, Vector3};
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, JointHarmonics, LinkMass, Observations, PointDistance,
    Row, RowKind, Weights,
};
use proptest::prelude::*;

/// A joint origin at `xyz_m` (m) tilted by the same roll, pitch and yaw (rad) for every
/// joint, moving along or about `axis`.
fn tilted_placement(name: &str, xyz_m: [f64; 3], axis: [f64; 3], prismatic: bool) -> Placement {
    Placement {
        name: name.into(),
        xyz_m,
        rpy_rad: [0.1, -0.2, 0.05],
        axis: Some(axis),
        prismatic,
    }
}

/// A torso joint about (or, `prismatic`, along) `torso_axis` under two arms, `left` and
/// `right`, of two revolute joints each (about y, then about `second_axis`) and a fixed tool.
fn torso_and_two_arms(torso_axis: [f64; 3], prismatic: bool, second_axis: [f64; 3]) -> Tree {
    let torso = tilted_placement("torso", [0.0, 0.0, 0.4], torso_axis, prismatic);
    let arm = |side: &str, y: f64| {
        vec![
            torso.clone(),
            tilted_placement(&format!("{side}_1"), [0.1, y, 0.2], [0.0, 1.0, 0.0], false),
            tilted_placement(&format!("{side}_2"), [0.3, 0.0, 0.0], second_axis, false),
            Placement {
                name: format!("{side}_tool"),
                xyz_m: [0.2, 0.0, 0.05],
                rpy_rad: [0.0; 3],
                axis: None,
                prismatic: false,
            },
        ]
    };
    Tree::from_placement_paths(&[arm("left", 0.2), arm("right", -0.2)]).expect("valid tree")
}

/// Configuration `i` of the five joints of [`torso_and_two_arms`] (rad; the torso's in m when
/// prismatic), spread over their ranges, the torso's within ±`torso`.
fn torso_configuration(i: usize, torso: f64) -> Vec<f64> {
    let t = i as f64;
    vec![
        torso * (0.7 * t).sin(),
        (1.3 * t).sin(),
        (0.9 * t + 1.0).cos(),
        (0.4 * t).sin() * 1.5,
        (1.7 * t + 0.3).cos(),
    ]
}

/// `tree` with joint offsets, an instrument frame and a marker frame on each of its first two
/// tips.
fn framed(tree: &Tree) -> Tree {
    let base = FrameSpec {
        name: "instrument".into(),
        nominal: Isometry3::new(Vector3::new(1.0, -0.5, 0.3), Vector3::new(0.2, 0.1, -0.4)),
    };
    let marker = |name: &str| FrameSpec {
        name: name.into(),
        nominal: Isometry3::new(Vector3::new(0.02, 0.01, 0.03), Vector3::new(-0.1, 0.3, 0.2)),
    };
    tree.with_joint_offsets()
        .with_frames(&base, &[(0, marker("marker1")), (1, marker("marker2"))])
        .expect("valid frames")
}

/// Row `i` of the mixed observations on a two-tip tree, at configuration `q` (rad): on even
/// rows a pose of tip `i % 3 % 2` (position m, unit-free quaternion `w, x, y, z`), on odd rows a
/// marker position of tip 1 (m).
fn pose_or_marker_row(i: usize, q: Vec<f64>) -> Row {
    let kind = if i.is_multiple_of(2) {
        RowKind::Pose {
            tip: i % 3 % 2,
            position_m: [1.0, 0.2, -0.1],
            rotation: [0.9, 0.1, -0.3, 0.2],
        }
    } else {
        RowKind::Marker {
            tip: 1,
            position_m: [0.5, 0.4, 0.3],
        }
    };
    Row { q: q.into(), kind }
}

/// Weights of [`pose_or_marker_row`]'s rows: position σ 1 mm, orientation σ 2 mrad.
fn pose_and_marker_weights() -> Weights {
    Weights {
        sigma_position_m: 1e-3,
        sigma_orientation_rad: 2e-3,
        ..Weights::default()
    }
}

/// iiwa-like chain from URDF placements (MUKCa `iiwa14.urdf` joint origins).
fn iiwa_like() -> Chain {
    let rev = |name: &str, xyz: [f64; 3], axis: [f64; 3]| Placement {
        name: name.into(),
        xyz_m: xyz,
        rpy_rad: [0.0; 3],
        axis: Some(axis),
        prismatic: false,
    };
    Chain::from_placements(&[
        rev("j1", [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        rev("j2", [-0.00043624, 0.0, 0.36], [0.0, 1.0, 0.0]),
        rev("j3", [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        rev("j4", [0.00043624, 0.0, 0.42], [0.0, -1.0, 0.0]),
        rev("j5", [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        rev("j6", [0.0, 0.0, 0.4], [0.0, 1.0, 0.0]),
        rev("j7", [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        Placement {
            name: "tool".into(),
            xyz_m: [0.0, 0.0, 0.126],
            rpy_rad: [0.0; 3],
            axis: None,
            prismatic: false,
        },
        Placement {
            name: "ball".into(),
            xyz_m: [0.0, 0.0, 0.04],
            rpy_rad: [0.0; 3],
            axis: None,
            prismatic: false,
        },
    ])
    .expect("valid chain")
}

/// Point masses on every link (iiwa-like magnitudes) and one compliance per actuator group.
fn massive_grouped() -> GravityCompliance {
    GravityCompliance {
        masses: (0..7)
            .map(|joint| LinkMass {
                joint,
                mass_kg: 5.0 - 0.5 * joint as f64,
                com_m: Vector3::new(0.01 * joint as f64, -0.03, 0.1),
            })
            .collect(),
        groups: vec![0, 0, 1, 1, 2, 3, 3],
        ..GravityCompliance::default()
    }
}

fn problem_with(qs: &[Vec<f64>], compliance: bool) -> CalibrationProblem {
    problem_with_model(qs, compliance.then(GravityCompliance::default))
}

fn problem_with_model(
    qs: &[Vec<f64>],
    compliance: Option<GravityCompliance>,
) -> CalibrationProblem {
    problem_with_models(qs, compliance, None)
}

fn problem_with_models(
    qs: &[Vec<f64>],
    compliance: Option<GravityCompliance>,
    harmonics: Option<JointHarmonics>,
) -> CalibrationProblem {
    let mut rows = Vec::new();
    for (i, q) in qs.iter().enumerate() {
        let kind = match i % 4 {
            0 => RowKind::Distance { distance_m: 0.9 },
            1 => RowKind::Position {
                position_m: [0.1, 0.2, 0.8],
            },
            2 => RowKind::Point { point: 0 },
            _ => RowKind::Point { point: 1 },
        };
        rows.push(Row {
            q: q[..].into(),
            kind,
        });
    }
    let obs = Observations {
        rows,
        point_distances: vec![PointDistance {
            a: 0,
            b: 1,
            distance_m: 0.05,
        }],
        n_points: 2,
    };
    let weights = Weights {
        sigma_distance_m: 1e-5,
        sigma_position_m: 2e-5,
        sigma_point_m: 5e-5,
        sigma_point_distance_m: 1e-4,
        sigma_orientation_rad: 1.0,
    };
    CalibrationProblem::with_harmonics(iiwa_like(), obs, weights, compliance, harmonics)
        .expect("valid")
}

/// The reference device (docs/design.md §2, standard D-H: every joint revolute about z, so the
/// lane kernel applies).
fn reference_chain() -> Chain {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/reference-device/device.toml");
    hapcal_io::read_device(&path)
        .expect("reference device")
        .chain()
        .expect("valid chain")
}

/// Distance rows in runs of 17 and 8 between position rows: the lane kernel takes each run
/// of 8 consecutive distance rows (`hapcal_kinematics::LANES`), the scalar path the rest.
fn distance_runs_problem(qs: &[Vec<f64>]) -> CalibrationProblem {
    let rows = qs
        .iter()
        .enumerate()
        .map(|(i, q)| Row {
            q: q[..].into(),
            kind: if matches!(i, 0 | 1 | 19) {
                RowKind::Position {
                    position_m: [0.1, 0.2, 0.8],
                }
            } else {
                RowKind::Distance {
                    distance_m: 0.9 + 0.001 * i as f64,
                }
            },
        })
        .collect();
    chain_problem(reference_chain(), rows, 1e-5, 2e-5)
}

/// The calibration problem of `chain` on `rows`, with σ `sigma_distance_m` (m) for each
/// distance and `sigma_position_m` (m) for each position coordinate.
fn chain_problem(
    chain: Chain,
    rows: Vec<Row>,
    sigma_distance_m: f64,
    sigma_position_m: f64,
) -> CalibrationProblem {
    let obs = Observations {
        rows,
        ..Observations::default()
    };
    let weights = Weights {
        sigma_distance_m,
        sigma_position_m,
        ..Weights::default()
    };
    CalibrationProblem::new(chain, obs, weights, None).expect("valid")
}

/// Deterministic numbers in [−1, 1) (64-bit LCG, Knuth's MMIX constants).
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// The Jacobian of the residuals of `problem` at `x` (`m × n`) by central differences with
/// step `h`.
fn central_difference_jacobian(problem: &CalibrationProblem, x: &Col<f64>, h: f64) -> Mat<f64> {
    let (m, n) = (problem.n_residuals(), problem.layout().len());
    let (mut up, mut down) = (Col::<f64>::zeros(m), Col::<f64>::zeros(m));
    let mut fd = Mat::zeros(m, n);
    for col in 0..n {
        let (mut xp, mut xm) = (x.clone(), x.clone());
        xp[col] += h;
        xm[col] -= h;
        problem
            .residuals(xp.as_ref(), up.as_mut())
            .expect("residuals at x + h");
        problem
            .residuals(xm.as_ref(), down.as_mut())
            .expect("residuals at x − h");
        for row in 0..m {
            fd[(row, col)] = (up[row] - down[row]) / (2.0 * h);
        }
    }
    fd
}

/// The largest error of the analytic Jacobian of `problem` at `x` against central differences
/// of its residuals with step `h`, relative to `1 + |entry|`.
fn worst_relative_jacobian_error(problem: &CalibrationProblem, x: &Col<f64>, h: f64) -> f64 {
    let (m, n) = (problem.n_residuals(), problem.layout().len());
    let mut jac = Mat::zeros(m, n);
    problem
        .jacobian(x.as_ref(), jac.as_mut())
        .expect("jacobian");
    let fd = central_difference_jacobian(problem, x, h);
    let mut worst: f64 = 0.0;
    for c in 0..n {
        for r in 0..m {
            worst = worst.max((fd[(r, c)] - jac[(r, c)]).abs() / (1.0 + jac[(r, c)].abs()));
        }
    }
    worst
}

/// Every entry of the analytic `jac` (`m × n`, at `x`) against central differences of the
/// residuals with step 1e-6. Residuals are divided by σ ~ 1e-5 m, so entries are ~1e5 per unit;
/// the central difference's truncation and rounding stay below 1e-3 absolute + 1e-6 relative.
fn jacobian_agrees_with_central_differences(
    problem: &CalibrationProblem,
    x: &Col<f64>,
    jac: &Mat<f64>,
) -> Result<(), TestCaseError> {
    let fd = central_difference_jacobian(problem, x, 1e-6);
    for col in 0..jac.ncols() {
        for row in 0..jac.nrows() {
            let (a, fd) = (jac[(row, col)], fd[(row, col)]);
            prop_assert!(
                (a - fd).abs() <= 1e-3 + 1e-6 * fd.abs(),
                "{}: row {row}: analytic {a} vs central difference {fd}",
                problem.layout().name(col)
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]
    #[test]
    fn lane_rows_match_the_chain_and_central_differences(
        qs in prop::collection::vec(prop::collection::vec(-2.0..2.0f64, 7), 28),
        dev in prop::collection::vec(-1e-2..1e-2f64, 32),
    ) {
        let problem = distance_runs_problem(&qs);
        let n = problem.layout().len();
        let m = problem.n_residuals();
        let x = Col::from_fn(n, |i| dev[i % dev.len()]);
        let x_kin: Vec<f64> = (0..n).map(|i| x[i]).collect();
        prop_assert!(problem.chain().freeze(&x_kin).supports_lanes(), "the lane path must be exercised");
        let mut r = Col::<f64>::zeros(m);
        problem.residuals(x.as_ref(), r.as_mut()).unwrap();
        let mut jac = Mat::<f64>::zeros(m, n);
        problem.jacobian(x.as_ref(), jac.as_mut()).unwrap();
        // Residuals against the chain's own forward kinematics: (|P| − δ)/σ, rounding of |P|
        // (~1e-16 m) over σ = 1e-5 m gives ~1e-11; 1e-9 fails on any wrong lane.
        let mut row = 0;
        for (i, q) in qs.iter().enumerate() {
            let p = problem.chain().end_point(&x_kin, q);
            if matches!(i, 0 | 1 | 19) {
                row += 3;
                continue;
            }
            let expected = (p.coords.norm() - (0.9 + 0.001 * i as f64)) / 1e-5;
            prop_assert!((r[row] - expected).abs() <= 1e-9, "row {row}: {} vs {expected}", r[row]);
            row += 1;
        }
        prop_assert_eq!(row, m);
        jacobian_agrees_with_central_differences(&problem, &x, &jac)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn jacobian_matches_central_differences(
        qs in prop::collection::vec(prop::collection::vec(-2.0..2.0f64, 7), 8),
        dev in prop::collection::vec(-1e-2..1e-2f64, 120),
        compliance in 0..5usize,
    ) {
        let model = match compliance {
            0 | 3 => None,
            1 | 4 => Some(GravityCompliance::default()),
            // Torques are ~10–100 N·m here: keep k·τ at the size of the lumped case.
            _ => Some(massive_grouped()),
        };
        // 3: harmonics alone (first and second order on a subset), 4: with lumped compliance.
        let harmonics = match compliance {
            3 => Some(JointHarmonics { joints: vec![1, 3, 6], orders: vec![1, 2] }),
            4 => Some(JointHarmonics::first_order(7)),
            _ => None,
        };
        let scale = if compliance == 2 { 0.01 } else { 1.0 };
        let problem = problem_with_models(&qs, model, harmonics);
        let n = problem.layout().len();
        let m = problem.n_residuals();
        let mut x = problem.initial_guess();
        let n_kin = problem.chain().n_params();
        for i in 0..n {
            x[i] += dev[i % dev.len()] * if i < n_kin { 1.0 } else if i < problem.points_offset() { scale } else { 0.1 };
        }
        let mut jac = Mat::<f64>::zeros(m, n);
        problem.jacobian(x.as_ref(), jac.as_mut()).unwrap();
        jacobian_agrees_with_central_differences(&problem, &x, &jac)?;
    }
}

#[test]
fn residual_counts_and_names() {
    let qs = vec![vec![0.1; 7]; 8];
    let p = problem_with(&qs, true);
    // 2 distances + 2 positions ×3 + 4 points ×3 + 1 point distance.
    assert_eq!(p.n_residuals(), 2 + 6 + 12 + 1);
    // 7 joints + tip, 6 each, then 7 compliance, then 2 points ×3.
    assert_eq!(p.layout().len(), 48 + 7 + 6);
    assert_eq!(p.layout().name(48), "compliance.j1");
    assert_eq!(p.layout().name(55), "point0.x");
}

#[test]
fn harmonic_parameters_follow_the_compliance_in_the_layout() {
    let qs = vec![vec![0.1; 7]; 8];
    let harmonics = JointHarmonics {
        joints: vec![0, 3],
        orders: vec![1, 2],
    };
    let p = problem_with_models(&qs, Some(GravityCompliance::default()), Some(harmonics));
    assert_eq!(p.n_harmonics(), 8);
    // 48 kinematic, 7 compliance, 8 harmonic, 6 point coordinates.
    assert_eq!(p.layout().len(), 48 + 7 + 8 + 6);
    let names: Vec<&str> = (55..63).map(|i| p.layout().name(i)).collect();
    assert_eq!(
        names,
        [
            "harmonic.j1.sin1",
            "harmonic.j1.cos1",
            "harmonic.j1.sin2",
            "harmonic.j1.cos2",
            "harmonic.j4.sin1",
            "harmonic.j4.cos1",
            "harmonic.j4.sin2",
            "harmonic.j4.cos2",
        ]
    );
    assert_eq!(p.points_offset(), 63);
    assert_eq!(p.layout().name(63), "point0.x");
}

#[test]
fn harmonic_model_moves_the_joint_by_its_eccentricity() {
    // θ_j = q_j + a·sin(q_j) + b·cos(q_j): with a = 1e-3, b = 2e-3 at q_2 = 0.5 the model's
    // angles are the readings plus 1e-3·sin 0.5 + 2e-3·cos 0.5 on joint 2 only.
    let qs = vec![vec![0.2, 0.5, -0.1, 0.3, 0.0, 0.4, 0.1]; 4];
    let harmonics = JointHarmonics {
        joints: vec![1],
        orders: vec![1],
    };
    let p = problem_with_models(&qs, None, Some(harmonics));
    let mut x = p.initial_guess();
    let off = p.chain().n_params();
    x[off] = 1e-3;
    x[off + 1] = 2e-3;
    let angles = p.model(x.as_ref()).effective_angles(&qs[0]);
    let expected = 0.5 + 1e-3 * 0.5f64.sin() + 2e-3 * 0.5f64.cos();
    assert!((angles[1] - expected).abs() < 1e-15, "{angles:?}");
    for j in [0, 2, 3, 4, 5, 6] {
        assert_eq!(angles[j], qs[0][j]);
    }
    // The residual the solver sees is the calibrated model's end point minus the socket point
    // (row 2 of `problem_with_models` is a point row on point 0; sigma_point_m = 5e-5).
    let mut r = Col::<f64>::zeros(p.n_residuals());
    p.residuals(x.as_ref(), r.as_mut()).unwrap();
    let tip = p.model(x.as_ref()).end_point(&qs[2]);
    let point = p.points(x.as_ref())[0];
    // Rows: distance (1), position (3), then the point row.
    for k in 0..3 {
        let expected = (tip[k] - point[k]) / 5e-5;
        assert!(
            (r[4 + k] - expected).abs() < 1e-9,
            "{k}: {} vs {expected}",
            r[4 + k]
        );
    }
}

#[test]
fn harmonic_joint_outside_the_chain_is_an_error() {
    let obs = Observations::default();
    let err = CalibrationProblem::with_harmonics(
        iiwa_like(),
        obs,
        Weights::default(),
        None,
        Some(JointHarmonics {
            joints: vec![7],
            orders: vec![1],
        }),
    )
    .unwrap_err();
    assert!(
        matches!(err, hapcal_problems::Error::NoSuchParam { index: 7, .. }),
        "{err}"
    );
}

#[test]
fn vertical_first_axis_has_no_gravity_torque() {
    let chain = iiwa_like();
    let tau =
        GravityCompliance::default().lumped_torques(&chain, &[0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1]);
    assert!(tau[0].abs() < 1e-12, "{tau:?}");
    // Joint 2 (axis y) carries the whole lumped arm: a clearly non-zero lever arm.
    assert!(tau[1].abs() > 0.1, "{tau:?}");
}

#[test]
fn wrong_joint_count_is_an_error() {
    let obs = Observations {
        rows: vec![Row {
            q: vec![0.0; 6].into(),
            kind: RowKind::Point { point: 0 },
        }],
        point_distances: vec![],
        n_points: 1,
    };
    let err = CalibrationProblem::new(iiwa_like(), obs, Weights::default(), None).unwrap_err();
    assert_eq!(
        err.to_string(),
        "observation 0 has 6 joint angles, the chain has 7 joints"
    );
}

/// Real socket data (MUKCa kuka_14 `front`, fixtures/mukca) as point observations.
fn kuka_front() -> Observations {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/mukca/data/kuka_14/front");
    let mut obs = Observations {
        n_points: 2,
        ..Observations::default()
    };
    for point in 0..2 {
        let text = std::fs::read_to_string(dir.join(format!("hole_{point}.csv"))).expect("fixture");
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let q: Vec<f64> = line
                .split(',')
                .map(|v| v.trim().parse().expect("number"))
                .collect();
            obs.rows.push(Row {
                q: q.into(),
                kind: RowKind::Point { point },
            });
        }
    }
    obs.point_distances.push(PointDistance {
        a: 0,
        b: 1,
        distance_m: 0.05,
    });
    obs
}

#[test]
fn a_deliberately_duplicated_parameter_is_pruned() {
    use hapcal_identify::{IdentifyConfig, PruneReason, identify};
    use hapcal_kinematics::{Factor, Motion, ParamInfo, ParamUnit, Unit, Vector3};
    let chain = iiwa_like();
    let j4x = chain.param_index("j4.x").expect("j4.x exists");
    // Insert, right after the factor of `j4.x`, a second translation along the same axis with a
    // parameter of its own: an exact duplicate under another name.
    let mut factors = chain.factors().to_vec();
    let at = factors
        .iter()
        .position(|f| matches!(f, Factor::Screw { param: Some(p), .. } if *p == j4x))
        .expect("factor of j4.x");
    let mut params = chain.params().to_vec();
    params.push(ParamInfo {
        name: "duplicate_of_j4.x".into(),
        unit: ParamUnit::Meter,
        element: 3,
    });
    factors.insert(
        at + 1,
        Factor::Screw {
            motion: Motion::Translation,
            axis: Unit::new_normalize(Vector3::x()),
            nominal: 0.0,
            param: Some(params.len() - 1),
            joint: None,
        },
    );
    let dup = Chain::from_factors(
        factors,
        params,
        chain.joint_names().to_vec(),
        chain.element_names().to_vec(),
    )
    .expect("valid chain");
    let problem =
        CalibrationProblem::new(dup, kuka_front(), Weights::default(), None).expect("valid");
    let fit = identify(
        &problem,
        problem.initial_guess(),
        &IdentifyConfig::default(),
    )
    .expect("identifies");
    let pruned = fit
        .identifiability
        .find_pruned("duplicate_of_j4.x")
        .or_else(|| fit.identifiability.find_pruned("j4.x"));
    let pruned = pruned.expect("one of the two duplicates is pruned");
    match &pruned.reason {
        PruneReason::Dependent { on } => {
            let (name, coef) = &on[0];
            assert!(name == "j4.x" || name == "duplicate_of_j4.x", "{on:?}");
            assert!((coef - 1.0).abs() < 1e-6, "{on:?}");
        }
        other => panic!("expected a dependence on its twin, got {other:?}"),
    }
    // The other twin is kept: the pair carries information, only the split is arbitrary.
    let kept: Vec<&str> = fit
        .identifiability
        .kept
        .iter()
        .map(|&i| problem.layout().name(i))
        .collect();
    assert!(
        kept.contains(&"j4.x") != kept.contains(&"duplicate_of_j4.x"),
        "{kept:?}"
    );
}

#[test]
fn grouped_compliance_shares_one_parameter_per_actuator() {
    let qs = vec![vec![0.1; 7]; 8];
    let p = problem_with_model(&qs, Some(massive_grouped()));
    assert_eq!(p.n_compliance(), 4);
    assert_eq!(p.layout().name(48), "compliance.j1+j2");
    assert_eq!(p.layout().name(51), "compliance.j6+j7");
    assert_eq!(p.layout().name(52), "point0.x");
}

#[test]
fn a_point_mass_gives_its_hand_computed_torque() {
    // 2 kg at 0.1 m along x of joint 2's link (axis y), arm upright: τ₂ = 0.1 m · 2 kg · g₀.
    let model = GravityCompliance {
        masses: vec![LinkMass {
            joint: 1,
            mass_kg: 2.0,
            com_m: Vector3::new(0.1, 0.0, 0.0),
        }],
        ..GravityCompliance::default()
    };
    let tau = model.lumped_torques(&iiwa_like(), &[0.0; 7]);
    assert!((tau[1] - 0.1 * 2.0 * 9.806_65).abs() < 1e-9, "{tau:?}");
    assert!(
        tau[0].abs() < 1e-12 && tau[2..].iter().all(|t| t.abs() < 1e-12),
        "{tau:?}"
    );
}

#[test]
fn published_masses_are_known_for_the_panda_and_the_iiwa_only() {
    let names = |f: &dyn Fn(usize) -> String| (1..=7).map(f).collect::<Vec<_>>();
    let panda = GravityCompliance::published(&names(&|i| format!("panda_joint{i}"))).unwrap();
    // Seven links plus the Franka Hand: 16.79 kg.
    assert_eq!(panda.masses.len(), 8);
    let total: f64 = panda.masses.iter().map(|m| m.mass_kg).sum();
    assert!((total - 16.792).abs() < 1e-3, "{total}");
    let iiwa = GravityCompliance::published_by_actuator(&names(&|i| format!("joint_a{i}")));
    assert_eq!(iiwa.unwrap().groups, vec![0, 0, 1, 1, 2, 3, 3]);
    assert!(GravityCompliance::published(&names(&|i| format!("j{i}"))).is_none());
}
