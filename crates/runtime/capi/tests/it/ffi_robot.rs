//! The robot C ABI called from Rust: statuses and messages for every kind of bad input,
//! name queries, position targets, and no allocation per call.

use std::ffi::{CStr, CString, c_char};
use std::ptr;

use hapcal_runtime::{Pose, Robot};
use hapcal_runtime_c::*;

use crate::{fails_with, message, zero_pose};

use crate::c_robot::robot_path;
use crate::counting::allocations;

const Q: [f64; 7] = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];

const CONFIG: HapcalCompensationConfig = HapcalCompensationConfig {
    tolerance_m: 1e-9,
    tolerance_rad: 1e-9,
    max_iterations: 50,
    damping_m: 1e-3,
    orientation_scale_m: 0.1,
};

fn c_string(text: &str) -> CString {
    CString::new(text).expect("no NUL")
}

/// Loads `path` with `tips` through the ABI: the status and the handle.
fn load_with(path: &str, tips: &[&str]) -> (HapcalStatus, *mut HapcalRobot) {
    let path = c_string(path);
    let tips: Vec<CString> = tips.iter().map(|t| c_string(t)).collect();
    let ptrs: Vec<*const c_char> = tips.iter().map(|t| t.as_ptr()).collect();
    let mut robot = ptr::null_mut();
    // SAFETY: valid strings, array and out pointer.
    let status = unsafe { hapcal_robot_load(path.as_ptr(), ptrs.as_ptr(), ptrs.len(), &mut robot) };
    (status, robot)
}

fn load() -> *mut HapcalRobot {
    let (status, robot) = load_with(
        robot_path().to_str().expect("UTF-8 path"),
        &["ball_link", "tool0"],
    );
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    robot
}

#[test]
fn loading_failures_are_statuses_with_messages() {
    let path = robot_path();
    let path = path.to_str().expect("UTF-8 path");
    let (status, robot) = load_with("/no/such/robot.urdf", &["ball_link"]);
    assert_eq!(status, HapcalStatus::Io);
    assert!(
        message().starts_with("/no/such/robot.urdf: cannot read"),
        "{}",
        message()
    );
    assert!(robot.is_null(), "nothing stored on failure");
    let (status, _) = load_with(path, &["no_such_link"]);
    assert_eq!(status, HapcalStatus::InvalidModel);
    assert!(
        message().contains("no link \"no_such_link\""),
        "{}",
        message()
    );
    let (status, _) = load_with(path, &[]);
    assert_eq!(status, HapcalStatus::InvalidModel);
    assert!(message().ends_with("no tip link given"), "{}", message());
    let c_path = c_string(path);
    let tips = [c_string("ball_link").into_raw().cast_const(), ptr::null()];
    let mut out = ptr::null_mut();
    let not_utf8 = [0xffu8, 0xfe, 0];
    // SAFETY: every pointer is NULL or valid for the stated sizes.
    unsafe {
        assert_eq!(
            hapcal_robot_load(c_path.as_ptr(), tips.as_ptr(), 2, &mut out),
            HapcalStatus::NullPointer
        );
        assert_eq!(message(), "tips[1] is NULL");
        assert_eq!(
            hapcal_robot_load(c_path.as_ptr(), ptr::null(), 1, &mut out),
            HapcalStatus::NullPointer
        );
        assert_eq!(message(), "tips is NULL");
        assert_eq!(
            hapcal_robot_load(c_path.as_ptr(), tips.as_ptr(), 1, ptr::null_mut()),
            HapcalStatus::NullPointer
        );
        assert_eq!(message(), "out is NULL");
        let bad = [not_utf8.as_ptr().cast::<c_char>()];
        assert_eq!(
            hapcal_robot_load(c_path.as_ptr(), bad.as_ptr(), 1, &mut out),
            HapcalStatus::InvalidUtf8
        );
        assert_eq!(message(), "tips[0] is not UTF-8");
        drop(CString::from_raw(tips[0].cast_mut()));
    }
    assert!(out.is_null());
}

#[test]
fn evaluation_failures_are_statuses_with_messages() {
    let robot = load();
    let mut pose = zero_pose();
    let mut jac = [0.0; 42];
    let mut tau = [0.0; 7];
    let mut poses = [zero_pose(); 2];
    let nan = {
        let mut q = Q;
        q[6] = f64::INFINITY;
        q
    };
    // SAFETY: every pointer is NULL or valid for the stated sizes.
    unsafe {
        assert_eq!(hapcal_robot_n_joints(ptr::null()), 0);
        assert_eq!(hapcal_robot_n_tips(ptr::null()), 0);
        assert!(!hapcal_robot_has_link_masses(ptr::null()));
        hapcal_robot_free(ptr::null_mut());
        let s = hapcal_robot_tip_pose(ptr::null_mut(), 0, Q.as_ptr(), 7, &mut pose);
        fails_with(s, HapcalStatus::NullPointer, "robot is NULL");
        let s = hapcal_robot_tip_pose(robot, 0, Q.as_ptr(), 7, ptr::null_mut());
        fails_with(s, HapcalStatus::NullPointer, "pose_out is NULL");
        let s = hapcal_robot_gravity_torques(robot, ptr::null(), 7, tau.as_mut_ptr());
        fails_with(s, HapcalStatus::NullPointer, "q is NULL");
        let s = hapcal_robot_gravity_torques(robot, nan.as_ptr(), 7, tau.as_mut_ptr());
        fails_with(
            s,
            HapcalStatus::NotFinite,
            "joint angles[6] = inf is not finite",
        );
        let s = hapcal_robot_body_jacobian(robot, 0, Q.as_ptr(), 8, jac.as_mut_ptr(), &mut pose);
        fails_with(
            s,
            HapcalStatus::Length,
            "n_joints: expected 7 values, found 8",
        );
        for (q, n_tips, status, text) in [
            (
                Q,
                1,
                HapcalStatus::Length,
                "n_tips: expected 2 values, found 1",
            ),
            (
                nan,
                2,
                HapcalStatus::NotFinite,
                "joint angles[6] = inf is not finite",
            ),
        ] {
            let p = poses.as_mut_ptr();
            let s =
                hapcal_robot_deflected_tip_poses(robot, q.as_ptr(), 7, p, n_tips, ptr::null_mut());
            fails_with(s, status, text);
        }

        // Compensation: every number of the target and the settings is checked.
        let rigid = {
            let mut p = zero_pose();
            assert_eq!(
                hapcal_robot_tip_pose(robot, 0, Q.as_ptr(), 7, &mut p),
                HapcalStatus::Ok
            );
            p
        };
        let compensate_tip =
            |tip: usize, target: *const HapcalTarget, cfg: &HapcalCompensationConfig, q: &[f64]| {
                let mut out = [0.0; 7];
                hapcal_robot_compensate(
                    robot,
                    tip,
                    target,
                    q.as_ptr(),
                    7,
                    cfg,
                    out.as_mut_ptr(),
                    ptr::null_mut(),
                )
            };
        let compensate = |target: &HapcalTarget, cfg: &HapcalCompensationConfig, q: &[f64]| {
            compensate_tip(0, target, cfg, q)
        };
        let mut target = HapcalTarget {
            kind: HAPCAL_TARGET_POSE,
            pose: rigid,
        };
        target.pose.translation_m[1] = f64::NAN;
        assert_eq!(compensate(&target, &CONFIG, &Q), HapcalStatus::NotFinite);
        assert_eq!(message(), "target translation_m[1] = NaN is not finite");
        target.pose = rigid;
        target.pose.rotation[2][0] = f64::NEG_INFINITY;
        assert_eq!(compensate(&target, &CONFIG, &Q), HapcalStatus::NotFinite);
        assert_eq!(message(), "target rotation[6] = -inf is not finite");
        // A position target ignores the rotation.
        target.kind = HAPCAL_TARGET_POSITION;
        assert_eq!(compensate(&target, &CONFIG, &Q), HapcalStatus::Ok);
        target.kind = 7;
        fails_with(
            compensate(&target, &CONFIG, &Q),
            HapcalStatus::InvalidArgument,
            "target kind 7 is invalid: expected 0 (position) or 1 (pose)",
        );
        target = HapcalTarget {
            kind: HAPCAL_TARGET_POSE,
            pose: rigid,
        };
        let mut cfg = CONFIG;
        cfg.damping_m = f64::NAN;
        assert_eq!(compensate(&target, &cfg, &Q), HapcalStatus::NotFinite);
        assert!(
            message().ends_with("[2] = NaN is not finite"),
            "{}",
            message()
        );
        cfg.damping_m = -1e-3;
        fails_with(
            compensate(&target, &cfg, &Q),
            HapcalStatus::InvalidArgument,
            "damping_m = -0.001 is invalid: expected a finite, positive value",
        );
        assert_eq!(compensate(&target, &CONFIG, &nan), HapcalStatus::NotFinite);
        let s = compensate_tip(5, &target, &CONFIG, &Q);
        assert_eq!(s, HapcalStatus::InvalidArgument);
        let s = compensate_tip(0, ptr::null(), &CONFIG, &Q);
        fails_with(s, HapcalStatus::NullPointer, "target is NULL");

        // The region flag.
        let (mut joint, mut distance) = (0, 1.0);
        let s = hapcal_robot_outside_region(robot, nan.as_ptr(), 7, &mut joint, &mut distance);
        assert_eq!(s, HapcalStatus::NotFinite);
        let s = hapcal_robot_outside_region(robot, Q.as_ptr(), 7, ptr::null_mut(), &mut distance);
        assert_eq!(s, HapcalStatus::NullPointer);
        let s = hapcal_robot_outside_region(robot, Q.as_ptr(), 7, &mut joint, &mut distance);
        assert_eq!(s, HapcalStatus::Ok);
        // The test robot's sidecar records no region: inside.
        assert_eq!((joint, distance), (HAPCAL_INSIDE_REGION, 0.0));
        assert_eq!(HAPCAL_INSIDE_REGION, usize::MAX);
        hapcal_robot_free(robot);
    }
}

#[test]
fn names_query_their_length_and_fill_a_buffer() {
    let robot = load();
    let mut buf = [0 as c_char; 16];
    let mut len = 0;
    // SAFETY: every pointer is NULL or valid for the stated sizes.
    unsafe {
        assert_eq!(
            hapcal_robot_tip_name(robot, 0, ptr::null_mut(), 0, &mut len),
            HapcalStatus::Ok
        );
        assert_eq!(len, "ball_link".len());
        assert_eq!(
            hapcal_robot_tip_name(robot, 0, buf.as_mut_ptr(), len + 1, ptr::null_mut()),
            HapcalStatus::Ok
        );
        assert_eq!(CStr::from_ptr(buf.as_ptr()).to_str(), Ok("ball_link"));
        assert_eq!(
            hapcal_robot_tip_name(robot, 1, buf.as_mut_ptr(), len, &mut len),
            HapcalStatus::Ok,
            "tool0 fits in 9 bytes"
        );
        assert_eq!(CStr::from_ptr(buf.as_ptr()).to_str(), Ok("tool0"));
        assert_eq!(
            hapcal_robot_joint_name(robot, 6, buf.as_mut_ptr(), buf.len(), &mut len),
            HapcalStatus::Ok
        );
        assert_eq!(
            (CStr::from_ptr(buf.as_ptr()).to_str(), len),
            (Ok("joint_a7"), 8)
        );
        fails_with(
            hapcal_robot_joint_name(robot, 7, buf.as_mut_ptr(), buf.len(), &mut len),
            HapcalStatus::InvalidArgument,
            "joint index 7 is past the last joint: the robot has 7",
        );
        assert_eq!(
            hapcal_robot_joint_name(robot, 0, ptr::null_mut(), 4, &mut len),
            HapcalStatus::NullPointer
        );
        hapcal_robot_free(robot);
    }
}

#[test]
fn a_position_target_is_reached_by_the_deflected_tip() {
    let robot = load();
    let lib = Robot::load_urdf(&robot_path(), &["ball_link", "tool0"]).expect("test robot");
    let mut ws = lib.workspace();
    // Tip 1 (tool0) 2 cm above where the rigid arm puts it at Q.
    let mut goal = lib.tip_pose(1, &Q, &mut ws).expect("valid");
    goal.translation_m[2] += 0.02;
    let target = HapcalTarget {
        kind: HAPCAL_TARGET_POSITION,
        pose: HapcalPose {
            rotation: [[f64::NAN; 3]; 3],
            translation_m: goal.translation_m,
        },
    };
    let mut command = [0.0; 7];
    let mut result = HapcalCompensation::default();
    // SAFETY: valid pointers of the stated sizes.
    let status = unsafe {
        hapcal_robot_compensate(
            robot,
            1,
            &target,
            Q.as_ptr(),
            7,
            &CONFIG,
            command.as_mut_ptr(),
            &mut result,
        )
    };
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    assert!(result.reached, "{result:?}");
    assert!(result.deflection.converged && result.deflection.iterations > 0);
    assert_eq!(result.orientation_error_rad, 0.0);
    let mut tips = [Pose::IDENTITY; 2];
    lib.deflected_tip_poses(&command, &mut ws, &mut tips)
        .expect("valid");
    for i in 0..3 {
        let gap = (tips[1].translation_m[i] - goal.translation_m[i]).abs();
        assert!(gap <= 1e-9, "axis {i}: {gap:e} m");
    }
    // SAFETY: a live handle, freed once.
    unsafe { hapcal_robot_free(robot) };
}

#[test]
fn frames_markers_values_and_predictors_fail_with_statuses_and_messages() {
    let robot = load();
    let name = c_string("marker1");
    let mut pose = zero_pose();
    let mut found = false;
    let mut out = ptr::null_mut();
    let nan_marker = HapcalPose {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, f64::NAN]],
        translation_m: [0.0; 3],
    };
    // SAFETY: every pointer is NULL or valid for the stated sizes.
    unsafe {
        let s = hapcal_robot_frame(robot, ptr::null(), &mut pose, &mut found);
        fails_with(s, HapcalStatus::NullPointer, "name is NULL");
        let s = hapcal_robot_frame(robot, name.as_ptr(), &mut pose, ptr::null_mut());
        fails_with(s, HapcalStatus::NullPointer, "found_out is NULL");
        let s = hapcal_robot_with_marker(robot, 2, &pose, &mut out);
        fails_with(
            s,
            HapcalStatus::InvalidArgument,
            "tip = 2 is invalid: expected a tip index below the number of tips",
        );
        let s = hapcal_robot_with_marker(robot, 0, &nan_marker, &mut out);
        fails_with(s, HapcalStatus::NotFinite, "marker[8] = NaN is not finite");
        let s = hapcal_robot_with_marker(robot, 0, ptr::null(), &mut out);
        fails_with(s, HapcalStatus::NullPointer, "marker is NULL");
        let s = hapcal_robot_with_compliances(robot, [0.0; 6].as_ptr(), 6, &mut out);
        assert_eq!(s, HapcalStatus::Length);
        let unknown = c_string("compliance.no_such_joint");
        let s = hapcal_robot_with_value(robot, unknown.as_ptr(), 1e-4, &mut out);
        assert_eq!(s, HapcalStatus::InvalidArgument);
        assert!(
            message().starts_with("\"compliance.no_such_joint\": value = 0.0001 is invalid"),
            "{}",
            message()
        );
        assert!(out.is_null(), "nothing stored on failure");
        let mut a = [zero_pose(); 2];
        let n = ptr::null_mut();
        assert_eq!(
            hapcal_robot_deflected_tip_poses(robot, Q.as_ptr(), 7, a.as_mut_ptr(), 2, n),
            HapcalStatus::Ok
        );

        let mut predictor = ptr::null_mut();
        let s = hapcal_predictor_new(robot, 2, &mut predictor);
        fails_with(
            s,
            HapcalStatus::InvalidArgument,
            "frame 2 is invalid: expected 0 (root link) or 1 (instrument)",
        );
        let s = hapcal_predictor_new(robot, HAPCAL_FRAME_ROOT, &mut predictor);
        assert_eq!(s, HapcalStatus::Ok);
        let mut tips = [HapcalTipPrediction {
            pose: zero_pose(),
            sigma_m: 0.0,
            sigma_rad: 0.0,
            has_sigma: false,
        }; 2];
        let s = hapcal_predictor_predict(predictor, Q.as_ptr(), 7, tips.as_mut_ptr(), 1);
        fails_with(
            s,
            HapcalStatus::Length,
            "n_tips: expected 2 values, found 1",
        );
        let s = hapcal_predictor_predict(predictor, Q.as_ptr(), 7, tips.as_mut_ptr(), 2);
        assert_eq!(s, HapcalStatus::Ok);
        // In the root frame the prediction is the deflected tip link.
        assert_eq!(tips[0].pose, a[0]);
        // The test robot's record holds the compliances' stds, no covariance: σ from them.
        assert!(tips[0].has_sigma && tips[0].sigma_m > 0.0);
        assert_eq!(
            hapcal_predictor_basis(predictor),
            HapcalUncertaintyBasis::StdsOnly
        );
        let mut len = 0;
        let s = hapcal_predictor_uncertainty_note(predictor, ptr::null_mut(), 0, &mut len);
        assert_eq!(s, HapcalStatus::Ok);
        assert!(len > 0, "stds only: a note");
        let mut small = [0 as c_char; 8];
        let s = hapcal_predictor_uncertainty_note(predictor, small.as_mut_ptr(), 8, &mut len);
        assert_eq!(s, HapcalStatus::Length);
        let (mut joint, mut distance) = (0, 1.0);
        let s =
            hapcal_predictor_outside_region(predictor, Q.as_ptr(), 7, &mut joint, &mut distance);
        assert_eq!(
            (s, joint, distance),
            (HapcalStatus::Ok, HAPCAL_INSIDE_REGION, 0.0)
        );
        hapcal_predictor_free(predictor);
        assert_eq!(hapcal_predictor_n_values(ptr::null()), 0);
        assert_eq!(
            hapcal_predictor_basis(ptr::null()),
            HapcalUncertaintyBasis::NoRecord
        );
        hapcal_predictor_free(ptr::null_mut());
        hapcal_robot_free(robot);
    }

    // The record robot: a recorded value moves the deflected tip, the original handle
    // unchanged; its predictions carry σ.
    let record = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/iiwa14_record.urdf");
    let (status, robot) = load_with(record, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    // SAFETY: a live handle and valid pointers of the stated sizes.
    unsafe {
        let known = c_string("compliance.joint_a2");
        let s = hapcal_robot_with_value(robot, known.as_ptr(), 4.2e-3, &mut out);
        assert_eq!(s, HapcalStatus::Ok, "{}", message());
        let (mut a, mut b) = ([zero_pose()], [zero_pose()]);
        let n = ptr::null_mut();
        assert_eq!(
            hapcal_robot_deflected_tip_poses(robot, Q.as_ptr(), 7, a.as_mut_ptr(), 1, n),
            HapcalStatus::Ok
        );
        assert_eq!(
            hapcal_robot_deflected_tip_poses(out, Q.as_ptr(), 7, b.as_mut_ptr(), 1, n),
            HapcalStatus::Ok
        );
        let gap = (0..3)
            .map(|i| (a[0].translation_m[i] - b[0].translation_m[i]).abs())
            .fold(0.0, f64::max);
        assert!(
            gap > 1e-6,
            "doubling one compliance moves the tip: {gap:e} m"
        );
        hapcal_robot_free(out);
        let mut predictor = ptr::null_mut();
        let s = hapcal_predictor_new(robot, HAPCAL_FRAME_INSTRUMENT, &mut predictor);
        assert_eq!(s, HapcalStatus::Ok, "{}", message());
        assert!(hapcal_predictor_has_uncertainty(predictor));
        assert!(hapcal_predictor_n_values(predictor) > 0);
        let mut tip = [HapcalTipPrediction {
            pose: zero_pose(),
            sigma_m: 0.0,
            sigma_rad: 0.0,
            has_sigma: false,
        }];
        let s = hapcal_predictor_predict(predictor, Q.as_ptr(), 7, tip.as_mut_ptr(), 1);
        assert_eq!(s, HapcalStatus::Ok);
        assert!(tip[0].has_sigma && tip[0].sigma_m > 0.0 && tip[0].sigma_rad > 0.0);
        hapcal_predictor_free(predictor);
        hapcal_robot_free(robot);
    }

    // A robot without a calibration: no instrument frame, no σ.
    let plain = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../fixtures/mukca/urdf/iiwa14.urdf"
    );
    let (status, robot) = load_with(plain, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    let mut predictor = ptr::null_mut();
    // SAFETY: a live handle and valid out pointers.
    unsafe {
        let s = hapcal_robot_frame(robot, name.as_ptr(), &mut pose, &mut found);
        assert_eq!((s, found), (HapcalStatus::Ok, false));
        let s = hapcal_predictor_new(robot, HAPCAL_FRAME_INSTRUMENT, &mut predictor);
        assert_eq!(s, HapcalStatus::InvalidArgument);
        assert!(message().starts_with("instrument frame"), "{}", message());
        let s = hapcal_predictor_new(robot, HAPCAL_FRAME_ROOT, &mut predictor);
        assert_eq!(s, HapcalStatus::Ok);
        assert_eq!(
            hapcal_predictor_basis(predictor),
            HapcalUncertaintyBasis::NoRecord
        );
        assert!(!hapcal_predictor_has_uncertainty(predictor));
        let mut tip = [HapcalTipPrediction {
            pose: zero_pose(),
            sigma_m: 0.0,
            sigma_rad: 0.0,
            has_sigma: true,
        }];
        let s = hapcal_predictor_predict(predictor, Q.as_ptr(), 7, tip.as_mut_ptr(), 1);
        assert_eq!(s, HapcalStatus::Ok);
        assert!(!tip[0].has_sigma && tip[0].sigma_m.is_nan());
        hapcal_predictor_free(predictor);
        hapcal_robot_free(robot);
    }
}

#[test]
fn robot_calls_do_not_allocate() {
    let robot = load();
    let mut pose = zero_pose();
    let mut poses = [zero_pose(); 2];
    let (mut jac, mut tau, mut command) = ([0.0; 42], [0.0; 7], [0.0; 7]);
    let mut buf = [0 as c_char; 16];
    let (mut joint, mut distance, mut len) = (0, 0.0, 0);
    let mut result = HapcalCompensation::default();
    let (mut theta, mut lower, mut upper) = ([0.0; 7], [0.0; 7], [0.0; 7]);
    let mut deflection = HapcalDeflection::default();
    let mut found = false;
    let marker1 = c_string("marker1");
    // The record robot's predictor: σ from its values.
    let record = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/iiwa14_record.urdf");
    let (status, record) = load_with(record, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Ok);
    let mut predictor = ptr::null_mut();
    // SAFETY: a live handle and a valid out pointer.
    let status = unsafe { hapcal_predictor_new(record, HAPCAL_FRAME_INSTRUMENT, &mut predictor) };
    assert_eq!(status, HapcalStatus::Ok);
    let mut predicted = [HapcalTipPrediction {
        pose: zero_pose(),
        sigma_m: 0.0,
        sigma_rad: 0.0,
        has_sigma: false,
    }];
    // SAFETY: a live handle and arrays of the stated sizes.
    let target = unsafe {
        assert_eq!(
            hapcal_robot_tip_pose(robot, 0, Q.as_ptr(), 7, &mut pose),
            HapcalStatus::Ok
        );
        HapcalTarget {
            kind: HAPCAL_TARGET_POSE,
            pose,
        }
    };
    let before = allocations();
    for _ in 0..10 {
        // SAFETY: as above.
        let statuses = unsafe {
            [
                hapcal_robot_tip_pose(robot, 0, Q.as_ptr(), 7, &mut pose),
                hapcal_robot_spatial_jacobian(robot, 0, Q.as_ptr(), 7, jac.as_mut_ptr(), &mut pose),
                hapcal_robot_body_jacobian(robot, 1, Q.as_ptr(), 7, jac.as_mut_ptr(), &mut pose),
                hapcal_robot_gravity_torques(robot, Q.as_ptr(), 7, tau.as_mut_ptr()),
                hapcal_robot_deflected_tip_poses(
                    robot,
                    Q.as_ptr(),
                    7,
                    poses.as_mut_ptr(),
                    2,
                    ptr::null_mut(),
                ),
                hapcal_robot_compensate(
                    robot,
                    0,
                    &target,
                    Q.as_ptr(),
                    7,
                    &CONFIG,
                    command.as_mut_ptr(),
                    &mut result,
                ),
                hapcal_robot_outside_region(robot, Q.as_ptr(), 7, &mut joint, &mut distance),
                hapcal_robot_joint_name(robot, 0, buf.as_mut_ptr(), buf.len(), &mut len),
                hapcal_robot_deflect(robot, Q.as_ptr(), 7, theta.as_mut_ptr(), &mut deflection),
                hapcal_robot_deflected_spatial_jacobian(
                    robot,
                    1,
                    Q.as_ptr(),
                    7,
                    jac.as_mut_ptr(),
                    &mut pose,
                    &mut deflection,
                ),
                hapcal_robot_frame(robot, marker1.as_ptr(), &mut pose, &mut found),
                hapcal_robot_limits(robot, lower.as_mut_ptr(), upper.as_mut_ptr(), 7),
                hapcal_robot_compliances(robot, tau.as_mut_ptr(), 7),
                hapcal_predictor_predict(predictor, Q.as_ptr(), 7, predicted.as_mut_ptr(), 1),
                hapcal_predictor_marker_poses(predictor, Q.as_ptr(), 7, poses.as_mut_ptr(), 2),
            ]
        };
        assert!(statuses.iter().all(|s| *s == HapcalStatus::Ok));
    }
    assert_eq!(allocations() - before, 0);
    assert!(result.reached && found && predicted[0].has_sigma);
    // SAFETY: live handles, freed once.
    unsafe {
        hapcal_predictor_free(predictor);
        hapcal_robot_free(record);
        hapcal_robot_free(robot);
    }
}
