//! Unit tests: reference values from hand-written matrix products, not from the factors.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Matrix4, Vector3};

use crate::{
    Chain, DhConvention, DhRow, Error, Factor, FkWorkspace, Isometry3, Motion, ParamInfo,
    ParamUnit, Placement, Point3, Unit,
};

// ---- hand-written homogeneous matrices -------------------------------------------------

fn trans(x: f64, y: f64, z: f64) -> Matrix4<f64> {
    #[rustfmt::skip]
    let m = Matrix4::new(
        1.0, 0.0, 0.0, x,
        0.0, 1.0, 0.0, y,
        0.0, 0.0, 1.0, z,
        0.0, 0.0, 0.0, 1.0,
    );
    m
}

fn rot_x(t: f64) -> Matrix4<f64> {
    let (s, c) = t.sin_cos();
    #[rustfmt::skip]
    let m = Matrix4::new(
        1.0, 0.0, 0.0, 0.0,
        0.0, c,   -s,  0.0,
        0.0, s,   c,   0.0,
        0.0, 0.0, 0.0, 1.0,
    );
    m
}

fn rot_y(t: f64) -> Matrix4<f64> {
    let (s, c) = t.sin_cos();
    #[rustfmt::skip]
    let m = Matrix4::new(
        c,   0.0, s,   0.0,
        0.0, 1.0, 0.0, 0.0,
        -s,  0.0, c,   0.0,
        0.0, 0.0, 0.0, 1.0,
    );
    m
}

fn rot_z(t: f64) -> Matrix4<f64> {
    let (s, c) = t.sin_cos();
    #[rustfmt::skip]
    let m = Matrix4::new(
        c,   -s,  0.0, 0.0,
        s,   c,   0.0, 0.0,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    );
    m
}

/// Rodrigues' formula for a unit axis `(ux, uy, uz)`.
fn rot_axis(u: [f64; 3], t: f64) -> Matrix4<f64> {
    let (s, c) = t.sin_cos();
    let [x, y, z] = u;
    let v = 1.0 - c;
    #[rustfmt::skip]
    let m = Matrix4::new(
        c + x * x * v,     x * y * v - z * s, x * z * v + y * s, 0.0,
        y * x * v + z * s, c + y * y * v,     y * z * v - x * s, 0.0,
        z * x * v - y * s, z * y * v + x * s, c + z * z * v,     0.0,
        0.0,               0.0,               0.0,               1.0,
    );
    m
}

/// Standard D-H link matrix in its closed form (Spong, Hutchinson & Vidyasagar 2006, eq. 3.10).
fn dh_closed_form(a: f64, alpha: f64, d: f64, theta: f64) -> Matrix4<f64> {
    let (st, ct) = theta.sin_cos();
    let (sa, ca) = alpha.sin_cos();
    #[rustfmt::skip]
    let m = Matrix4::new(
        ct,  -st * ca, st * sa,  a * ct,
        st,  ct * ca,  -ct * sa, a * st,
        0.0, sa,       ca,       d,
        0.0, 0.0,      0.0,      1.0,
    );
    m
}

fn origin_of(m: &Matrix4<f64>) -> Point3<f64> {
    Point3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)])
}

fn assert_close(a: Point3<f64>, b: Point3<f64>, tol: f64) {
    assert!((a - b).norm() <= tol, "{a} vs {b}");
}

fn assert_pose_close(a: &Isometry3<f64>, b: &Matrix4<f64>, tol: f64) {
    let diff = (a.to_homogeneous() - b).abs().max();
    assert!(diff <= tol, "max abs difference {diff}:\n{a}\nvs\n{b}");
}

// ---- the paper's reference device ------------------------------------------------------

/// (a_m, alpha_rad, d_m, joint) of docs/design.md §2 (paper Table 1); theta offsets are 0.
const PAPER_TABLE: [(f64, f64, f64, Option<usize>); 8] = [
    (0.35, -FRAC_PI_2, 0.0, None),
    (0.0, -FRAC_PI_2, 0.10, Some(0)),
    (0.0, FRAC_PI_2, 0.0, Some(1)),
    (0.0, -FRAC_PI_2, 0.21, Some(2)),
    (0.0, FRAC_PI_2, 0.0, Some(3)),
    (0.0, -FRAC_PI_2, 0.21, Some(4)),
    (0.0, FRAC_PI_2, 0.0, Some(5)),
    (0.03, 0.0, 0.05, Some(6)),
];

fn paper_chain() -> Chain {
    let rows: Vec<DhRow> = PAPER_TABLE
        .iter()
        .map(|&(a_m, alpha_rad, d_m, joint)| DhRow::standard(a_m, alpha_rad, d_m, joint))
        .collect();
    Chain::from_dh(&rows).expect("the paper's table is valid")
}

/// A_0 ⋯ A_7 from the closed-form link matrix, with deviations `(da, dalpha, dd, dtheta)`.
fn paper_hand_product(q: &[f64; 7], dev: &[[f64; 4]; 8]) -> Matrix4<f64> {
    PAPER_TABLE
        .iter()
        .zip(dev)
        .fold(Matrix4::identity(), |t, (&(a, alpha, d, joint), x)| {
            let q_i = joint.map_or(0.0, |j| q[j]);
            t * dh_closed_form(a + x[0], alpha + x[1], d + x[2], q_i + x[3])
        })
}

#[test]
fn paper_device_has_32_params_and_7_joints() {
    let chain = paper_chain();
    assert_eq!(chain.n_params(), 32);
    assert_eq!(chain.n_joints(), 7);
    assert_eq!(
        chain.joint_names(),
        ["q1", "q2", "q3", "q4", "q5", "q6", "q7"]
    );
    assert_eq!(chain.element_names().len(), 8);
    assert_eq!(chain.element_names()[0], "row0");
    let names: Vec<&str> = chain.params()[..5]
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    assert_eq!(names, ["da0", "dalpha0", "dd0", "dtheta0", "da1"]);
    assert_eq!(
        chain.params()[31],
        ParamInfo {
            name: "dtheta7".into(),
            unit: ParamUnit::Radian,
            element: 7
        }
    );
    assert_eq!(chain.params()[2].unit, ParamUnit::Meter);
    assert_eq!(chain.param_index("dd3"), Some(14));
    assert_eq!(chain.param_index("dbeta3"), None);
}

#[test]
fn paper_device_end_point_at_zero_is_the_hand_product() {
    // At q = 0 every link is Trans(a, 0, d)·Rx(alpha); the rotations alternate between
    // Rx(-pi/2) and Rx(-pi), so each d (along z) lands on base +y:
    // p = (0.35 + 0.03, 0.10 + 0.21 + 0.21 + 0.05, 0).
    let by_hand = PAPER_TABLE
        .iter()
        .fold(Matrix4::identity(), |t, &(a, alpha, d, _)| {
            t * trans(a, 0.0, d) * rot_x(alpha)
        });
    let expected = Point3::new(0.38, 0.57, 0.0);
    assert_close(origin_of(&by_hand), expected, 1e-15);

    let chain = paper_chain();
    let p = chain.end_point(&[0.0; 32], &[0.0; 7]);
    assert_close(p, expected, 1e-14);
    assert!((p.coords.norm() - 0.4693f64.sqrt()).abs() < 1e-14);
}

#[test]
fn paper_device_with_deviations_matches_closed_form_product() {
    let chain = paper_chain();
    let q = [0.3, -0.2, 0.5, 1.1, -1.4, 0.7, 2.0];
    let mut dev = [[0.0; 4]; 8];
    let mut x = vec![0.0; 32];
    for (k, xk) in x.iter_mut().enumerate() {
        *xk = 1e-3 * ((k as f64) * 0.7).sin();
        dev[k / 4][k % 4] = *xk;
    }
    assert_pose_close(
        &chain.end_pose(&x, &q),
        &paper_hand_product(&q, &dev),
        1e-14,
    );
}

// ---- conventions -----------------------------------------------------------------------

fn row(convention: DhConvention, a_m: f64, alpha_rad: f64, joint: Option<usize>) -> DhRow {
    DhRow {
        convention,
        a_m,
        alpha_rad,
        d_m: 0.0,
        theta_rad: 0.0,
        beta_rad: None,
        joint,
    }
}

#[test]
fn standard_and_modified_dh_agree_on_a_planar_two_link_arm() {
    let (l1, l2) = (0.3, 0.2);
    let standard = Chain::from_dh(&[
        row(DhConvention::Standard, l1, 0.0, Some(0)),
        row(DhConvention::Standard, l2, 0.0, Some(1)),
    ])
    .expect("valid");
    // Craig: a link length sits before the next joint's rotation; the last one is a fixed
    // tool row.
    let modified = Chain::from_dh(&[
        row(DhConvention::Modified, 0.0, 0.0, Some(0)),
        row(DhConvention::Modified, l1, 0.0, Some(1)),
        row(DhConvention::Modified, l2, 0.0, None),
    ])
    .expect("valid");
    for q in [[0.0, 0.0], [0.4, -1.3], [2.5, 0.9], [-PI, 0.1]] {
        let expected = Point3::new(
            l1 * q[0].cos() + l2 * (q[0] + q[1]).cos(),
            l1 * q[0].sin() + l2 * (q[0] + q[1]).sin(),
            0.0,
        );
        assert_close(standard.end_point(&[0.0; 8], &q), expected, 1e-15);
        assert_close(modified.end_point(&[0.0; 12], &q), expected, 1e-15);
    }
}

#[test]
fn modified_dh_row_is_craig_product() {
    let r = DhRow {
        convention: DhConvention::Modified,
        a_m: 0.12,
        alpha_rad: 0.4,
        d_m: -0.07,
        theta_rad: 0.3,
        beta_rad: Some(0.02),
        joint: Some(0),
    };
    let chain = Chain::from_dh(&[r]).expect("valid");
    assert_eq!(chain.param_index("dbeta0"), Some(4));
    let x = [1e-3, -2e-3, 3e-3, 4e-3, -5e-3];
    let q = 0.8;
    let expected = rot_x(0.4 - 2e-3)
        * rot_y(0.02 - 5e-3)
        * trans(0.12 + 1e-3, 0.0, 0.0)
        * rot_z(0.3 + 4e-3 + q)
        * trans(0.0, 0.0, -0.07 + 3e-3);
    assert_pose_close(&chain.end_pose(&x, &[q]), &expected, 1e-15);
}

#[test]
fn hayati_beta_follows_the_standard_link() {
    let r = DhRow {
        convention: DhConvention::Standard,
        a_m: 0.25,
        alpha_rad: 0.0,
        d_m: 0.04,
        theta_rad: -0.2,
        beta_rad: Some(0.01),
        joint: Some(0),
    };
    let chain = Chain::from_dh(&[
        r,
        DhRow {
            joint: Some(1),
            ..r
        },
    ])
    .expect("valid");
    assert_eq!(chain.n_params(), 10);
    assert_eq!(chain.params()[9].name, "dbeta1");
    let q = [0.6, -0.9];
    let link = |q: f64| dh_closed_form(0.25, 0.0, 0.04, q - 0.2) * rot_y(0.01);
    assert_pose_close(
        &chain.end_pose(&[0.0; 10], &q),
        &(link(q[0]) * link(q[1])),
        1e-15,
    );
}

// ---- URDF placements -------------------------------------------------------------------

fn placement(name: &str, xyz_m: [f64; 3], rpy_rad: [f64; 3], axis: Option<[f64; 3]>) -> Placement {
    Placement {
        name: name.into(),
        xyz_m,
        rpy_rad,
        axis,
        prismatic: false,
    }
}

fn origin_by_hand(xyz: [f64; 3], rpy: [f64; 3]) -> Matrix4<f64> {
    trans(xyz[0], xyz[1], xyz[2]) * rot_z(rpy[2]) * rot_y(rpy[1]) * rot_x(rpy[0])
}

fn deviation_by_hand(d: [f64; 6]) -> Matrix4<f64> {
    trans(d[0], d[1], d[2]) * rot_x(d[3]) * rot_y(d[4]) * rot_z(d[5])
}

#[test]
fn placements_fold_fixed_joints_and_match_the_matrix_product() {
    let s = 1.0 / 3f64.sqrt();
    let ps = [
        placement("mount", [0.1, 0.0, 0.05], [0.0, 0.0, 0.3], None),
        placement(
            "j1",
            [0.0, 0.0, 0.12],
            [0.1, -0.2, 0.3],
            Some([0.0, 0.0, 2.0]),
        ),
        placement("spacer", [0.05, 0.01, 0.0], [FRAC_PI_2, 0.0, 0.0], None),
        placement("j2", [0.2, 0.0, 0.0], [0.0, 0.4, 0.0], Some([s, -s, s])),
        placement("handle", [0.0, 0.03, 0.1], [0.0, 0.0, -0.5], None),
        placement("ball_joint", [0.0, 0.0, 0.02], [0.2, 0.0, 0.0], None),
    ];
    let chain = Chain::from_placements(&ps).expect("valid");
    assert_eq!(chain.joint_names(), ["j1", "j2"]);
    assert_eq!(chain.element_names(), ["j1", "j2", "ball_joint"]);
    assert_eq!(chain.n_params(), 18);
    let names: Vec<&str> = chain.params()[12..]
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    assert_eq!(
        names,
        [
            "ball_joint.x",
            "ball_joint.y",
            "ball_joint.z",
            "ball_joint.rx",
            "ball_joint.ry",
            "ball_joint.rz"
        ]
    );
    assert_eq!(chain.params()[3].unit, ParamUnit::Radian);
    assert_eq!(chain.params()[8].unit, ParamUnit::Meter);
    assert_eq!(chain.params()[15].element, 2);

    let o = |i: usize| origin_by_hand(ps[i].xyz_m, ps[i].rpy_rad);
    let q = [0.7, -1.1];
    let x: Vec<f64> = (0..18)
        .map(|k| 2e-3 * ((k as f64) * 1.3 + 0.4).cos())
        .collect();
    let dev = |e: usize| {
        deviation_by_hand([
            x[6 * e],
            x[6 * e + 1],
            x[6 * e + 2],
            x[6 * e + 3],
            x[6 * e + 4],
            x[6 * e + 5],
        ])
    };
    let expected = o(0)
        * o(1)
        * dev(0)
        * rot_axis([0.0, 0.0, 1.0], q[0])
        * o(2)
        * o(3)
        * dev(1)
        * rot_axis([s, -s, s], q[1])
        * o(4)
        * o(5)
        * dev(2);
    assert_pose_close(&chain.end_pose(&x, &q), &expected, 1e-14);

    let nominal =
        o(0) * o(1) * rot_z(q[0]) * o(2) * o(3) * rot_axis([s, -s, s], q[1]) * o(4) * o(5);
    assert_pose_close(&chain.end_pose(&[0.0; 18], &q), &nominal, 1e-14);
}

#[test]
fn placements_without_trailing_fixed_joint_end_at_the_last_joint() {
    let ps = [
        placement("j1", [0.0, 0.0, 0.1], [0.0; 3], Some([0.0, 0.0, 1.0])),
        placement("j2", [0.3, 0.0, 0.0], [0.0; 3], Some([0.0, 1.0, 0.0])),
    ];
    let chain = Chain::from_placements(&ps).expect("valid");
    assert_eq!(chain.n_params(), 12);
    assert_eq!(chain.element_names(), ["j1", "j2"]);
    let p = chain.end_point(&[0.0; 12], &[FRAC_PI_2, 0.4]);
    assert_close(p, Point3::new(0.0, 0.3, 0.1), 1e-15);
}

// ---- evaluation API --------------------------------------------------------------------

#[test]
fn workspace_variant_matches_allocating_functions_and_is_reusable() {
    let paper = paper_chain();
    let planar = Chain::from_dh(&[row(DhConvention::Standard, 0.3, 0.0, Some(0))]).expect("valid");
    let mut ws = FkWorkspace::new(&planar);
    let x: Vec<f64> = (0..32).map(|k| 1e-3 * (k as f64).sin()).collect();
    let q = [0.3, 0.2, -0.5, 1.0, 0.4, -0.6, 1.5];
    for _ in 0..2 {
        let mut jac = vec![f64::NAN; 3 * 32];
        let p = paper.point_and_jacobian_in(&x, &q, &mut ws, &mut jac);
        assert_eq!(p, paper.end_point(&x, &q));
        assert_eq!(
            jac.as_slice(),
            paper.point_jacobian_wrt_params(&x, &q).as_slice()
        );
        let pose_jac = paper.pose_jacobian_wrt_params(&x, &q);
        assert_eq!(
            pose_jac.fixed_rows::<3>(0),
            paper.point_jacobian_wrt_params(&x, &q)
        );

        let mut jac = [1.0; 12];
        let p = planar.point_and_jacobian_in(&[0.0; 4], &[FRAC_PI_2], &mut ws, &mut jac);
        assert_close(p, Point3::new(0.0, 0.3, 0.0), 1e-15);
        // Columns da0, dalpha0, dd0, dtheta0: along the link (+y), 0 (x axis through the tip),
        // +z, and z × p = −0.3 x.
        let expected = [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, -0.3, 0.0, 0.0];
        for (a, e) in jac.iter().zip(expected) {
            assert!((a - e).abs() < 1e-15, "{jac:?}");
        }
    }
}

#[test]
fn frame_poses_end_at_end_pose_and_geometric_jacobian_is_the_planar_one() {
    let chain = Chain::from_dh(&[
        row(DhConvention::Standard, 0.3, 0.0, Some(0)),
        row(DhConvention::Standard, 0.2, 0.0, Some(1)),
    ])
    .expect("valid");
    let q = [0.5, 0.7];
    let poses = chain.frame_poses(&[0.0; 8], &q);
    assert_eq!(poses.len(), chain.factors().len());
    assert_eq!(poses.last(), Some(&chain.end_pose(&[0.0; 8], &q)));

    let jac = chain.geometric_jacobian(&[0.0; 8], &q);
    let (s1, c1, s12, c12) = (
        q[0].sin(),
        q[0].cos(),
        (q[0] + q[1]).sin(),
        (q[0] + q[1]).cos(),
    );
    #[rustfmt::skip]
    let expected = [
        [-0.3 * s1 - 0.2 * s12, -0.2 * s12],
        [0.3 * c1 + 0.2 * c12,  0.2 * c12],
        [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [1.0, 1.0],
    ];
    for (r, row) in expected.iter().enumerate() {
        for (c, e) in row.iter().enumerate() {
            assert!(
                (jac[(r, c)] - e).abs() < 1e-15,
                "({r}, {c}): {} vs {e}",
                jac[(r, c)]
            );
        }
    }
}

// ---- errors ----------------------------------------------------------------------------

#[test]
fn invalid_descriptions_are_errors_with_messages() {
    assert_eq!(Chain::from_dh(&[]), Err(Error::EmptyChain));
    assert_eq!(Chain::from_placements(&[]), Err(Error::EmptyChain));

    let gap = Chain::from_dh(&[
        row(DhConvention::Standard, 0.1, 0.0, Some(0)),
        row(DhConvention::Standard, 0.1, 0.0, Some(2)),
    ])
    .expect_err("joint 1 is missing");
    assert_eq!(
        gap.to_string(),
        "joint indices must be 0..n, each used once; found [0, 2]"
    );
    let twice = Chain::from_dh(&[
        row(DhConvention::Standard, 0.1, 0.0, Some(0)),
        row(DhConvention::Standard, 0.1, 0.0, Some(0)),
    ]);
    assert_eq!(twice, Err(Error::JointIndices { found: vec![0, 0] }));

    let nan = Chain::from_dh(&[row(DhConvention::Modified, f64::NAN, 0.0, None)]).expect_err("nan");
    assert_eq!(nan.to_string(), "row0: a_m is not finite (NaN)");

    let zero = Chain::from_placements(&[placement("elbow", [0.0; 3], [0.0; 3], Some([0.0; 3]))])
        .expect_err("zero axis");
    assert_eq!(
        zero.to_string(),
        "elbow: joint axis [0.0, 0.0, 0.0] has zero length"
    );
    let inf =
        Chain::from_placements(&[placement("tool", [0.0, f64::INFINITY, 0.0], [0.0; 3], None)])
            .expect_err("infinite");
    assert_eq!(inf.to_string(), "tool: xyz_m[1] is not finite (inf)");
    let dup = Chain::from_placements(&[
        placement("j", [0.0; 3], [0.0; 3], Some([1.0, 0.0, 0.0])),
        placement("j", [0.0; 3], [0.0; 3], Some([1.0, 0.0, 0.0])),
    ])
    .expect_err("duplicate");
    assert_eq!(dup.to_string(), "duplicate parameter name \"j.x\"");

    let screw = |axis: Vector3<f64>, param, joint| Factor::Screw {
        motion: Motion::Rotation,
        axis: Unit::new_unchecked(axis),
        nominal: 0.0,
        param,
        joint,
    };
    let info = ParamInfo {
        name: "p".into(),
        unit: ParamUnit::Radian,
        element: 0,
    };
    let build = |f: Factor, element: usize| {
        Chain::from_factors(
            vec![Factor::Fixed(Isometry3::identity()), f],
            vec![ParamInfo {
                element,
                ..info.clone()
            }],
            vec!["q1".into()],
            vec!["link".into()],
        )
    };
    assert!(build(screw(Vector3::z(), Some(0), Some(0)), 0).is_ok());
    assert_eq!(
        build(screw(Vector3::z(), Some(1), None), 0).map_err(|e| e.to_string()),
        Err("factor 1: parameter index 1 is out of range (1 parameters)".into())
    );
    assert_eq!(
        build(screw(Vector3::z(), None, Some(1)), 0),
        Err(Error::JointOutOfRange {
            factor: 1,
            index: 1,
            n_joints: 1
        })
    );
    assert_eq!(
        build(screw(Vector3::new(0.0, 0.0, 2.0), None, None), 0),
        Err(Error::AxisNotUnit {
            factor: 1,
            norm: 2.0
        })
    );
    assert_eq!(
        build(screw(Vector3::z(), None, None), 1).map_err(|e| e.to_string()),
        Err("parameter p: element index 1 is out of range (1 elements)".into())
    );
    assert_eq!(
        Chain::from_factors(vec![], vec![], vec![], vec![]),
        Err(Error::EmptyChain)
    );
}

#[test]
fn param_units_have_si_symbols() {
    assert_eq!(ParamUnit::Meter.symbol(), "m");
    assert_eq!(ParamUnit::Radian.symbol(), "rad");
}

#[test]
fn factor_transform_matches_hand_matrices() {
    let f = Factor::Screw {
        motion: Motion::Translation,
        axis: Vector3::y_axis(),
        nominal: 0.2,
        param: Some(0),
        joint: Some(0),
    };
    assert_pose_close(&f.transform(&[0.01], &[0.3]), &trans(0.0, 0.51, 0.0), 1e-15);
}

#[test]
fn every_lane_kernel_agrees_with_the_scalar_distance_gradient() {
    use crate::{LANES, frozen::every_kernel};
    let chain = paper_chain();
    let n = chain.n_params();
    let x: Vec<f64> = (0..n).map(|j| 1e-3 * ((j * 7 % 11) as f64 - 5.0)).collect();
    let frozen = chain.freeze(&x);
    // Two groups of LANES configurations.
    let qs: Vec<Vec<f64>> = (0..2 * LANES)
        .map(|l| {
            (0..7)
                .map(|j| ((l * 7 + j * 3) % 13) as f64 * 0.4 - 2.4)
                .collect()
        })
        .collect();
    let mut trig = crate::joint_trig_lanes(std::array::from_fn(|l| qs[l].as_slice()));
    trig.extend(crate::joint_trig_lanes(std::array::from_fn(|l| {
        qs[LANES + l].as_slice()
    })));
    let results = every_kernel(&frozen, &trig, 2.0);
    assert!(results.iter().any(|(name, ..)| *name == "portable"));
    let mut ws = FkWorkspace::new(&chain);
    let mut scalar = vec![0.0; n];
    for (name, dist, grad) in &results {
        for (k, q) in qs.iter().enumerate() {
            let (g, l) = (k / LANES, k % LANES);
            let p = frozen.distance_gradient(q, None, &mut scalar, &mut ws);
            // Other operations than the scalar path's (and fused where the CPU has FMA):
            // a few ulps of |P| ≈ 1 m and of the gradient entries (≤ ~2 m/rad).
            assert!(
                (dist[g][l] - p.coords.norm()).abs() < 1e-14,
                "{name}, pose {k}"
            );
            for (j, s) in scalar.iter().enumerate() {
                let lane = grad[g * n + j][l];
                assert!(
                    (lane - 2.0 * s).abs() < 1e-13,
                    "{name}, pose {k}, param {j}"
                );
            }
        }
    }
    // The SIMD kernels run the same fused operations in the same order.
    let simd: Vec<_> = results
        .iter()
        .filter(|(name, ..)| *name != "portable")
        .collect();
    for pair in simd.windows(2) {
        assert_eq!(pair[0].1, pair[1].1, "{} vs {}", pair[0].0, pair[1].0);
        assert_eq!(pair[0].2, pair[1].2, "{} vs {}", pair[0].0, pair[1].0);
    }
}

#[test]
fn freeze_into_reuses_a_frozen_chain_of_any_x_or_chain() {
    let chain = paper_chain();
    let n = chain.n_params();
    let x1: Vec<f64> = (0..n).map(|j| 1e-3 * (j as f64 - 16.0)).collect();
    let x2: Vec<f64> = (0..n).map(|j| 2e-3 * ((j * 5 % 7) as f64 - 3.0)).collect();
    let mut frozen = chain.freeze(&x1);
    chain.freeze_into(&x2, &mut frozen);
    assert_eq!(frozen, chain.freeze(&x2));
    // From a frozen chain of another (shorter) chain.
    let short = Chain::from_dh(&[row(DhConvention::Standard, 0.3, 0.0, Some(0))])
        .expect("one revolute row");
    let mut other = short.freeze(&vec![0.0; short.n_params()]);
    chain.freeze_into(&x1, &mut other);
    assert_eq!(other, chain.freeze(&x1));
    assert!(other.supports_lanes());
}
