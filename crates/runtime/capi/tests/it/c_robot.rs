//! Compiles `examples/c/robot.c` against the static library, runs it on the calibrated test
//! robot (`tests/data/iiwa14_calibrated.urdf` and its sidecar of compliances), and compares
//! every printed number with `hapcal_runtime::Robot`'s.

use std::path::{Path, PathBuf};

use hapcal_runtime::{CompensationConfig, Pose, Robot, Target, compensate};

use crate::c_example::{compile, lib_dir, row, run};

pub(crate) fn robot_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/iiwa14_calibrated.urdf")
}

/// The rest of the line after `key`.
fn text<'a>(stdout: &'a str, key: &str) -> &'a str {
    (stdout.lines())
        .find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix(' ')))
        .unwrap_or_else(|| panic!("no line {key:?} in\n{stdout}"))
}

fn flat(pose: &Pose) -> (Vec<f64>, Vec<f64>) {
    (
        pose.rotation.as_flattened().to_vec(),
        pose.translation_m.to_vec(),
    )
}

#[test]
fn c_robot_example_prints_the_library_numbers() {
    let lib = lib_dir().join("libhapcal_runtime_c.a");
    assert!(lib.exists(), "{} was not built", lib.display());
    let exe = compile("robot.c", "robot_static", &[lib.display().to_string()]);
    let stdout = run(&exe, &robot_path());

    let robot = Robot::load_urdf(&robot_path(), &["ball_link", "tool0"]).expect("test robot");
    assert!(robot.has_compliance());
    let mut ws = robot.workspace();
    let q = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];
    let pose = robot.tip_pose(0, &q, &mut ws).expect("valid");
    let (mut spatial, mut body) = ([[0.0; 6]; 7], [[0.0; 6]; 7]);
    robot
        .spatial_jacobian(0, &q, &mut ws, &mut spatial)
        .expect("valid");
    robot
        .body_jacobian(0, &q, &mut ws, &mut body)
        .expect("valid");
    let mut tau = [0.0; 7];
    robot.gravity_torques(&q, &mut ws, &mut tau).expect("valid");
    let mut deflected = [Pose::IDENTITY; 2];
    let deflection = robot
        .deflected_tip_poses(&q, &mut ws, &mut deflected)
        .expect("valid");
    let cfg = CompensationConfig {
        tolerance_m: 1e-9,
        tolerance_rad: 1e-9,
        max_iterations: 50,
        damping_m: 1e-3,
        orientation_scale_m: 0.1,
    };
    let mut command = [0.0; 7];
    let c = compensate(
        &robot,
        0,
        &Target::Pose(pose),
        &q,
        &cfg,
        &mut ws,
        &mut command,
    )
    .expect("valid");

    let (rotation, translation) = flat(&pose);
    let (d0_rotation, d0_translation) = flat(&deflected[0]);
    let (d1_rotation, d1_translation) = flat(&deflected[1]);
    let expected = [
        ("tip_pose_rotation", rotation),
        ("tip_pose_translation_m", translation),
        ("spatial_jacobian", spatial.as_flattened().to_vec()),
        ("body_jacobian", body.as_flattened().to_vec()),
        ("gravity_torques_nm", tau.to_vec()),
        ("deflected0_rotation", d0_rotation),
        ("deflected0_translation_m", d0_translation),
        ("deflected1_rotation", d1_rotation),
        ("deflected1_translation_m", d1_translation),
        ("command_rad", command.to_vec()),
    ];
    let (mut identical, mut total) = (0, 0);
    for (key, want) in expected {
        let got = row(&stdout, key);
        assert_eq!(got.len(), want.len(), "{key}");
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= 1e-12, "{key}: C {g:e} vs Rust {w:e}");
            identical += usize::from(g.to_bits() == w.to_bits());
            total += 1;
        }
    }
    // The static library is the same compiled code as the library the test links.
    assert_eq!(
        identical, total,
        "{identical} of {total} numbers bit-identical"
    );
    assert_eq!(total, 9 + 3 + 42 + 42 + 7 + 2 * 12 + 7);

    assert_eq!(
        text(&stdout, "joint_names"),
        "joint_a1 joint_a2 joint_a3 joint_a4 joint_a5 joint_a6 joint_a7"
    );
    assert_eq!(text(&stdout, "tip_names"), "ball_link tool0");
    assert_eq!(text(&stdout, "has_link_masses"), "1");
    let d = row(&stdout, "deflection");
    assert_eq!(d[0], deflection.iterations as f64);
    assert_eq!(d[1], deflection.final_step_rad);
    assert_eq!(d[2], 1.0, "converged");
    let region = match robot.outside_region(&q).expect("valid") {
        None => "inside".to_owned(),
        Some((j, distance)) => format!("outside {j} {distance:e}"),
    };
    let printed = text(&stdout, "region");
    if region == "inside" {
        assert_eq!(printed, "inside");
    } else {
        let fields: Vec<&str> = printed.split(' ').collect();
        let distance: f64 = fields[2].parse().expect("number");
        assert_eq!(format!("{} {} {distance:e}", fields[0], fields[1]), region);
    }
    let comp = row(&stdout, "compensation");
    assert_eq!(
        comp,
        [
            1.0,
            c.iterations as f64,
            c.position_error_m,
            c.orientation_error_rad,
            c.deflection.iterations as f64
        ]
    );

    // The numbers mean what they say, independently of the C path: the compliance sags the
    // tips by more than 0.1 mm at this configuration, and at the C command the deflected
    // tip 0 is within the tolerance (1e-9 m, 1e-9 rad) of the rigid pose at q.
    let sag: f64 = (0..3)
        .map(|i| (deflected[0].translation_m[i] - pose.translation_m[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(sag > 1e-4, "sag {sag:e} m");
    let command = row(&stdout, "command_rad");
    robot
        .deflected_tip_poses(&command, &mut ws, &mut deflected)
        .expect("valid");
    for i in 0..3 {
        let gap = (deflected[0].translation_m[i] - pose.translation_m[i]).abs();
        assert!(gap <= 1e-9, "compensated tip {i} off by {gap:e} m");
        for j in 0..3 {
            let gap = (deflected[0].rotation[i][j] - pose.rotation[i][j]).abs();
            assert!(gap <= 2e-9, "compensated rotation[{i}][{j}] off by {gap:e}");
        }
    }

    for (key, want) in [
        (
            "nan_status",
            "3 joint angles[3] = NaN is not finite".to_owned(),
        ),
        (
            "wrong_length_status",
            "2 n_joints: expected 7 values, found 6".to_owned(),
        ),
        (
            "bad_tip_status",
            "9 tip = 2 is invalid: expected a tip index below the number of tips".to_owned(),
        ),
        (
            "small_buffer_status",
            "2 8 buf: 4 bytes cannot hold the joint name \"joint_a1\" (9 bytes with its NUL)"
                .to_owned(),
        ),
    ] {
        assert_eq!(text(&stdout, key), want, "{key}");
    }
}
