//! Compiles `examples/c/robot.c` against the static library, runs it on the calibrated test
//! robot (`tests/data/iiwa14_calibrated.urdf` and its sidecar of compliances), and compares
//! every printed number with `hapcal_runtime::Robot`'s.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use hapcal_runtime::{
    CompensationConfig, Pose, PredictionFrame, Predictor, Robot, Target, TipPrediction,
    UncertaintyBasis, compensate,
};

use crate::c_example::{assert_rows_bit_identical, compile, lib_dir, row, run};

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
    let record_path = robot_path().with_file_name("iiwa14_record.urdf");
    let robot = robot_path();
    let args = [
        robot.as_os_str(),
        OsStr::new("--record"),
        record_path.as_os_str(),
    ];
    let stdout = run(&exe, &args);

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
    let target = Target::Pose(pose);
    let c = compensate(&robot, 0, &target, &q, &cfg, &mut ws, &mut command).expect("valid");

    let (lower, upper): (Vec<f64>, Vec<f64>) = robot.limits().iter().copied().unzip();
    let mut theta = [0.0; 7];
    let theta_deflection = robot.deflect(&q, &mut ws, &mut theta).expect("valid");
    let mut deflected_jac = [[0.0; 6]; 7];
    let (deflected_jac_pose, jac_deflection) = robot
        .deflected_spatial_jacobian(0, &q, &mut ws, &mut deflected_jac)
        .expect("valid");
    let instrument = robot
        .frame("instrument")
        .expect("the sidecar's instrument frame");
    let marker = robot.frame("marker1").expect("the sidecar's marker1");
    assert_eq!(robot.frame("marker9"), None);
    let marked = robot.with_marker(0, &marker).expect("valid");
    let mut marked_ws = marked.workspace();
    let marked_pose = marked.tip_pose(0, &q, &mut marked_ws).expect("valid");
    let mut marked_deflected = [Pose::IDENTITY; 2];
    marked
        .deflected_tip_poses(&q, &mut marked_ws, &mut marked_deflected)
        .expect("valid");
    let predictor = Predictor::new(&robot, PredictionFrame::Instrument).expect("valid");
    let mut pws = predictor.workspace();
    let mut predicted = [TipPrediction::default(); 2];
    predictor
        .predict(&q, &mut pws, &mut predicted)
        .expect("valid");
    let record = Robot::load_urdf(&record_path, &["ball_link"]).expect("record robot");
    let record_predictor = Predictor::new(&record, PredictionFrame::Instrument).expect("valid");
    let mut record_ws = record_predictor.workspace();
    let mut record_predicted = [TipPrediction::default()];
    record_predictor
        .predict(&q, &mut record_ws, &mut record_predicted)
        .expect("valid");
    let sigma = |t: &TipPrediction| vec![t.sigma_m.expect("σ"), t.sigma_rad.expect("σ")];

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
        ("limits_lower", lower),
        ("limits_upper", upper),
        ("compliances", robot.compliances().to_vec()),
        ("deflected_theta_rad", theta.to_vec()),
        (
            "deflected_jacobian_pose_rotation",
            flat(&deflected_jac_pose).0,
        ),
        (
            "deflected_jacobian_pose_translation_m",
            flat(&deflected_jac_pose).1,
        ),
        (
            "deflected_spatial_jacobian",
            deflected_jac.as_flattened().to_vec(),
        ),
        ("frame_instrument_rotation", flat(&instrument).0),
        ("frame_instrument_translation_m", flat(&instrument).1),
        ("frame_marker1_rotation", flat(&marker).0),
        ("frame_marker1_translation_m", flat(&marker).1),
        ("marked_tip_pose_rotation", flat(&marked_pose).0),
        ("marked_tip_pose_translation_m", flat(&marked_pose).1),
        ("marked_deflected0_rotation", flat(&marked_deflected[0]).0),
        (
            "marked_deflected0_translation_m",
            flat(&marked_deflected[0]).1,
        ),
        ("predicted0_rotation", flat(&predicted[0].pose).0),
        ("predicted0_translation_m", flat(&predicted[0].pose).1),
        ("predicted1_rotation", flat(&predicted[1].pose).0),
        ("predicted1_translation_m", flat(&predicted[1].pose).1),
        (
            "record_predicted0_rotation",
            flat(&record_predicted[0].pose).0,
        ),
        (
            "record_predicted0_translation_m",
            flat(&record_predicted[0].pose).1,
        ),
        ("record_predicted0_sigma", sigma(&record_predicted[0])),
    ];
    let total = assert_rows_bit_identical(&stdout, &expected);
    assert_eq!(
        total,
        9 + 3 + 42 + 42 + 7 + 2 * 12 + 7 // rigid, deflected, compensated
            + 3 * 7 + 7 + 12 + 42 // limits, compliances, deflection, cycle
            + 2 * 12 + 2 * 12 // frames, marker
            + 2 * 12 + 12 + 2 // predictions, with σ on the record robot
    );
    assert_eq!(text(&stdout, "is_prismatic"), "0");
    assert_eq!(
        row(&stdout, "theta_deflection"),
        [
            theta_deflection.iterations as f64,
            theta_deflection.final_step_rad,
            1.0
        ]
    );
    assert_eq!(
        row(&stdout, "jacobian_deflection"),
        [jac_deflection.iterations as f64]
    );
    assert_eq!(text(&stdout, "frames_found"), "1 1 0");
    // The test robot's record (the compliances' stds, no covariance): σ from every value.
    assert_eq!(predictor.basis(), UncertaintyBasis::StdsOnly);
    assert_eq!(
        text(&stdout, "predictor"),
        format!("1 1 {}", predictor.n_values())
    );
    assert_eq!(predictor.n_values(), 7);
    assert_eq!(text(&stdout, "predicted0_has_sigma"), "1");
    assert_eq!(
        text(&stdout, "uncertainty_note"),
        predictor.uncertainty_note().expect("a note on stds only")
    );
    // The record robot (stds, no covariance): σ from every value; the region flag as Rust's.
    assert_eq!(record_predictor.basis(), UncertaintyBasis::StdsOnly);
    assert_eq!(
        text(&stdout, "record_predictor"),
        format!("1 1 {}", record_predictor.n_values())
    );
    let mut far = q;
    far[1] = 1.6;
    let (joint, past) = record
        .outside_region(&far)
        .expect("valid")
        .expect("outside");
    assert_eq!(row(&stdout, "record_region"), [joint as f64, past]);

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
    // The new calls mean what they say, independently of the C path: the cycle's pose is the
    // deflected tip 0 and its Jacobian the rigid one at the deflected angles; the marked
    // robot's tip is the tip link times marker1; the prediction in the instrument frame is
    // instrument · deflected tip · marker1 (as composed here); σ is a fraction of the sag.
    assert_eq!(deflected_jac_pose, deflected[0]);
    let mut at_theta = [[0.0; 6]; 7];
    let rigid_at_theta = robot
        .with_compliances(&[0.0; 7])
        .expect("valid")
        .spatial_jacobian(0, &theta, &mut ws, &mut at_theta)
        .expect("valid");
    for (a, b) in at_theta
        .as_flattened()
        .iter()
        .zip(deflected_jac.as_flattened())
    {
        assert!((a - b).abs() <= 1e-12, "{a:e} vs {b:e}");
    }
    for i in 0..3 {
        assert!((rigid_at_theta.translation_m[i] - deflected[0].translation_m[i]).abs() <= 1e-12);
    }
    assert!(
        (0..7).any(|j| (theta[j] - q[j]).abs() > 1e-5),
        "the arm sags"
    );
    let composed = |a: &Pose, b: &Pose| -> Pose {
        let mut out = Pose::IDENTITY;
        for i in 0..3 {
            for j in 0..3 {
                out.rotation[i][j] = (0..3).map(|k| a.rotation[i][k] * b.rotation[k][j]).sum();
            }
            out.translation_m[i] = a.translation_m[i]
                + (0..3)
                    .map(|k| a.rotation[i][k] * b.translation_m[k])
                    .sum::<f64>();
        }
        out
    };
    let close = |a: &Pose, b: &Pose, what: &str| {
        let (ra, ta) = flat(a);
        let (rb, tb) = flat(b);
        for (x, y) in ra.iter().chain(&ta).zip(rb.iter().chain(&tb)) {
            assert!((x - y).abs() <= 1e-12, "{what}: {x:e} vs {y:e}");
        }
    };
    close(&marked_pose, &composed(&pose, &marker), "marked tip");
    let expected0 = composed(&composed(&instrument, &deflected[0]), &marker);
    close(&predicted[0].pose, &expected0, "prediction 0");
    close(
        &predicted[1].pose,
        &composed(&instrument, &deflected[1]),
        "prediction 1 (no marker2: the tip link)",
    );
    let s0 = record_predicted[0].sigma_m.expect("σ");
    assert!(
        s0 > 0.0 && s0 < 1e-3,
        "σ {s0:e} m from stds of 1e-5 (m, rad, rad/m)"
    );

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
