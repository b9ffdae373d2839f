//! A calibration record binds to its robot through the C ABI: refused beside another URDF,
//! for tips it was not made for, with a region joint the robot lacks; a robot reports the
//! tips it was given; a target rotation must be a rotation.

use std::ffi::{CString, c_char};
use std::path::{Path, PathBuf};
use std::ptr;

use hapcal_runtime::{Pose, Robot};
use hapcal_runtime_c::*;

use crate::{message, zero_pose};

/// A copy of the test robot with the record schema 1 (`iiwa14_record`) in a folder of its
/// own, the sidecar's text changed by `edit`; returns the URDF's path.
fn robot_with(name: &str, edit: impl Fn(&str) -> String) -> PathBuf {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let dir = std::env::temp_dir().join(format!("hapcal-capi-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a scratch folder");
    let urdf = dir.join("iiwa14_record.urdf");
    std::fs::copy(data.join("iiwa14_record.urdf"), &urdf).expect("copied");
    let sidecar =
        std::fs::read_to_string(data.join("iiwa14_record.calibration.toml")).expect("readable");
    let edited = edit(&sidecar);
    std::fs::write(dir.join("iiwa14_record.calibration.toml"), edited).expect("written");
    urdf
}

/// Loads `path` with `tips` through the ABI: the status and the handle.
fn load_with(path: &Path, tips: &[&str]) -> (HapcalStatus, *mut HapcalRobot) {
    let path = CString::new(path.to_str().expect("UTF-8")).expect("no NUL");
    let tips: Vec<CString> = (tips.iter())
        .map(|t| CString::new(*t).expect("no NUL"))
        .collect();
    let ptrs: Vec<*const c_char> = tips.iter().map(|t| t.as_ptr()).collect();
    let mut robot = ptr::null_mut();
    // SAFETY: valid strings, array and out pointer.
    let status = unsafe { hapcal_robot_load(path.as_ptr(), ptrs.as_ptr(), ptrs.len(), &mut robot) };
    (status, robot)
}

/// The 1-based line of the first line of `text` that starts with `needle`.
fn line_of(text: &str, needle: &str) -> usize {
    text.lines()
        .position(|l| l.starts_with(needle))
        .map(|i| i + 1)
        .expect("present")
}

const Q: [f64; 7] = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];

/// The record's loads hang at two tips (its torque tips), the caller gives one: the runtime
/// loads the other after it to load the joints (why the robot had 2 tips), and the ABI counts,
/// names and writes the one given.
#[test]
fn a_robot_reports_the_tips_it_was_given() {
    let urdf = robot_with("given-tips", |text| {
        let torque = text.find("[torque]").expect("a torque table");
        let (head, tail) = text.split_at(torque);
        format!(
            "{head}{}",
            tail.replacen(
                "tips = [\"ball_link\"]",
                "tips = [\"ball_link\", \"tool0\"]",
                1
            )
        )
    });
    let rust = Robot::load_urdf(&urdf, &["ball_link"]).expect("valid");
    assert_eq!(
        rust.tip_names(),
        ["ball_link", "tool0"],
        "the load tip after"
    );
    let (status, robot) = load_with(&urdf, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    // SAFETY: a live handle; arrays of the stated lengths.
    unsafe {
        assert_eq!(hapcal_robot_n_tips(robot), 1);
        let mut len = 0;
        let s = hapcal_robot_tip_name(robot, 1, ptr::null_mut(), 0, &mut len);
        assert_eq!(s, HapcalStatus::InvalidArgument);
        assert!(message().contains("the robot has 1"), "{}", message());
        let mut pose = zero_pose();
        let s = hapcal_robot_tip_pose(robot, 1, Q.as_ptr(), 7, &mut pose);
        assert_eq!(s, HapcalStatus::InvalidArgument, "{}", message());
        let mut poses = [zero_pose(); 2];
        let n = ptr::null_mut();
        let s = hapcal_robot_deflected_tip_poses(robot, Q.as_ptr(), 7, poses.as_mut_ptr(), 2, n);
        assert_eq!(s, HapcalStatus::Length);
        assert_eq!(message(), "n_tips: expected 1 values, found 2");
        let s = hapcal_robot_deflected_tip_poses(robot, Q.as_ptr(), 7, poses.as_mut_ptr(), 1, n);
        assert_eq!(s, HapcalStatus::Ok, "{}", message());
        // The tip given is the Rust robot's first, loads of both tips included.
        let mut ws = rust.workspace();
        let mut ours = [Pose::IDENTITY; 2];
        rust.deflected_tip_poses(&Q, &mut ws, &mut ours)
            .expect("valid");
        assert_eq!(poses[0].translation_m, ours[0].translation_m);
        assert_eq!(
            poses[1].translation_m, [0.0; 3],
            "nothing past the tips given"
        );
        let mut predictor = ptr::null_mut();
        let s = hapcal_predictor_new(robot, HAPCAL_FRAME_ROOT, &mut predictor);
        assert_eq!(s, HapcalStatus::Ok, "{}", message());
        let mut tips = [HapcalTipPrediction {
            pose: zero_pose(),
            sigma_m: 0.0,
            sigma_rad: 0.0,
            has_sigma: false,
        }; 1];
        let s = hapcal_predictor_predict(predictor, Q.as_ptr(), 7, tips.as_mut_ptr(), 1);
        assert_eq!(s, HapcalStatus::Ok, "{}", message());
        assert_eq!(tips[0].pose.translation_m, ours[0].translation_m);
        hapcal_predictor_free(predictor);
        hapcal_robot_free(robot);
    }
}

#[test]
fn a_record_beside_another_urdf_is_refused_in_words() {
    let other = "fnv1a64:0123456789abcdef";
    let urdf = robot_with("other-urdf", |text| {
        text.replacen(
            "tips = [\"ball_link\"]",
            &format!("tips = [\"ball_link\"]\nurdf_digest = \"{other}\""),
            1,
        )
    });
    let (status, robot) = load_with(&urdf, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Parse);
    assert!(robot.is_null(), "nothing stored on failure");
    let found = hapcal_contract::digest(&std::fs::read(&urdf).expect("readable"));
    let text = message();
    assert!(text.contains(".calibration.toml:4:"), "its line: {text}");
    for words in [
        other,
        found.as_str(),
        "iiwa14_record.urdf",
        "another robot",
        "calibrate",
    ] {
        assert!(text.contains(words), "{words}: {text}");
    }
    // The digest of the URDF beside it: the record loads.
    let urdf = robot_with("same-urdf", |text| {
        text.replacen(
            "tips = [\"ball_link\"]",
            &format!("tips = [\"ball_link\"]\nurdf_digest = \"{found}\""),
            1,
        )
    });
    let (status, robot) = load_with(&urdf, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    // SAFETY: a live handle.
    unsafe { hapcal_robot_free(robot) };
}

#[test]
fn tips_and_region_joints_the_calibration_was_not_made_for_are_refused_at_their_line() {
    let urdf = robot_with("other-tip", str::to_owned);
    let sidecar =
        std::fs::read_to_string(urdf.with_extension("calibration.toml")).expect("readable");
    let (status, _) = load_with(&urdf, &["tool0"]);
    assert_eq!(status, HapcalStatus::Parse);
    let text = message();
    let line = line_of(&sidecar, "tips = ");
    assert!(
        text.contains(&format!(":{line}:1: tips = [\"ball_link\"]")),
        "{text}"
    );
    assert!(text.contains("\"tool0\""), "{text}");

    let urdf = robot_with("region-joint", |text| {
        text.replacen("name = \"joint_a3\"", "name = \"joint_a9\"", 1)
    });
    let sidecar =
        std::fs::read_to_string(urdf.with_extension("calibration.toml")).expect("readable");
    let (status, _) = load_with(&urdf, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Parse, "{}", message());
    let text = message();
    let line = line_of(&sidecar, "name = \"joint_a9\"");
    assert!(
        text.contains(&format!(":{line}:1: [region] joint \"joint_a9\"")),
        "{text}"
    );
}

#[test]
fn a_target_rotation_must_be_a_rotation() {
    let urdf = robot_with("rotation", str::to_owned);
    let (status, robot) = load_with(&urdf, &["ball_link"]);
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    let cfg = HapcalCompensationConfig {
        tolerance_m: 1e-9,
        tolerance_rad: 1e-9,
        max_iterations: 50,
        damping_m: 1e-3,
        orientation_scale_m: 0.1,
    };
    // SAFETY: a live handle; arrays of the stated lengths.
    unsafe {
        let mut pose = zero_pose();
        let s = hapcal_robot_tip_pose(robot, 0, Q.as_ptr(), 7, &mut pose);
        assert_eq!(s, HapcalStatus::Ok);
        let compensate = |target: &HapcalTarget| {
            let (mut command, mut result) = ([0.0; 7], HapcalCompensation::default());
            let q = Q.as_ptr();
            hapcal_robot_compensate(
                robot,
                0,
                target,
                q,
                7,
                &cfg,
                command.as_mut_ptr(),
                &mut result,
            )
        };
        let mut target = HapcalTarget {
            kind: HAPCAL_TARGET_POSE,
            pose,
        };
        // The tip's own pose is a rotation: reachable.
        assert_eq!(compensate(&target), HapcalStatus::Ok, "{}", message());
        // Twice the rotation, and a reflection: refused.
        let twice = pose.rotation.map(|row| row.map(|x| 2.0 * x));
        let mut reflection = pose.rotation;
        reflection[2] = reflection[2].map(|x| -x);
        for (r, words) in [(twice, "|RᵀR − I|"), (reflection, "not a reflection")] {
            target.pose.rotation = r;
            let s = compensate(&target);
            assert_eq!(s, HapcalStatus::InvalidArgument, "{}", message());
            assert!(message().contains(words), "{words}: {}", message());
        }
        hapcal_robot_free(robot);
    }
}
