//! The calibration record (`hapcal-contract`) as `Robot::load_urdf` reads it: the region flag,
//! refusals at the record's line, lumped loads that need the calibration's tips, and
//! `Robot::with_value`.

use hapcal_runtime::{LoadError, Robot};

use crate::fixture;

fn iiwa() -> String {
    std::fs::read_to_string(fixture("mukca/urdf/iiwa14.urdf")).expect("fixture")
}

/// A schema-1 record of the iiwa: lumped compliance of joint_a2 and joint_a4, joint_a2's
/// offset, joint_a1's training range −1..1 rad over 50 rows.
fn record(extra_value: &str) -> String {
    format!(
        r#"schema_version = 1
model = "compliance"
tips = ["ball_link"]

[torque]
source = "lumped-unit-weights"
gravity_direction = [0.0, 0.0, -1.0]
gravity_m_s2 = 9.80665
tips = ["ball_link"]

[region]
rows = 50
joint = [{{ name = "joint_a1", min = -1.0, max = 1.0, unit = "rad" }}]

[values]
"joint_a2.offset" = {{ value = 0.002, std = 1e-4, unit = "rad" }}
"compliance.joint_a2" = {{ value = 0.003, std = 1e-4, unit = "rad/m" }}
"compliance.joint_a4" = {{ value = 0.002, std = 1e-4, unit = "rad/m" }}
{extra_value}"#
    )
}

fn load(record_text: &str, tips: &[&str]) -> Result<Robot, LoadError> {
    Robot::from_urdf_str(
        &iiwa(),
        "iiwa14.urdf",
        Some((record_text, "iiwa14.calibration.toml")),
        tips,
    )
}

#[test]
fn a_reading_past_the_training_range_is_flagged_with_its_joint_and_distance() {
    let robot = load(&record(""), &["ball_link"]).expect("valid");
    let mut q = [0.0, 0.5, 0.0, -1.0, 0.0, 0.5, 0.0];
    assert_eq!(robot.outside_region(&q).expect("valid"), None);
    // Within the 5 % slack (0.1 rad) of the 2 rad range: inside.
    q[0] = 1.09;
    assert_eq!(robot.outside_region(&q).expect("valid"), None);
    q[0] = -1.5;
    let (joint, past) = robot.outside_region(&q).expect("valid").expect("outside");
    assert_eq!(joint, 0);
    assert!((past + 0.5).abs() < 1e-12, "{past}");
    assert!(robot.outside_region(&q[..6]).is_err());
}

#[test]
fn an_unknown_value_or_a_wrong_unit_is_refused_at_its_line() {
    let e = load(
        &record(r#""compliance.joint_a9" = { value = 0.001, std = 1e-4, unit = "rad/m" }"#),
        &["ball_link"],
    )
    .expect_err("no joint_a9");
    assert!(e.to_string().contains("joint_a9"), "{e}");
    let e = load(
        &record(r#""harmonic.joint_a1.sine1" = { value = 0.001, std = 1e-4, unit = "rad" }"#),
        &["ball_link"],
    )
    .expect_err("misspelt");
    let LoadError::Parse { line, .. } = e else {
        panic!("{e}");
    };
    assert_eq!(line, 19, "the value's line");
    let e = load(
        &record(r#""transversal.joint_a3" = { value = 0.001, std = 1e-4, unit = "rad/(N·m)" }"#),
        &["ball_link"],
    )
    .expect_err("unit of the lumped loads is rad/m");
    assert!(e.to_string().contains("rad/m"), "{e}");
}

/// The record's lumped loads hang at its load tips (`torque.tips`, here `ball_link`, the
/// calibration made for `link_7`): asked for `link_7` alone, the robot loads `ball_link` as a
/// further tip after it, and deflects as the robot asked for both.
#[test]
fn lumped_loads_hang_at_the_calibrations_tips_loaded_from_the_record() {
    // A calibration made for `link_7` whose loads hang at `ball_link`.
    let made_for_link_7 = record("").replacen("tips = [\"ball_link\"]", "tips = [\"link_7\"]", 1);
    let alone = load(&made_for_link_7, &["link_7"]).expect("valid");
    assert_eq!(alone.tip_names(), ["link_7", "ball_link"]);
    let both = load(&made_for_link_7, &["link_7", "ball_link"]).expect("valid");
    let q = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];
    let poses = |robot: &Robot| {
        let mut ws = robot.workspace();
        let mut out = [hapcal_runtime::Pose::IDENTITY; 2];
        robot
            .deflected_tip_poses(&q, &mut ws, &mut out)
            .expect("valid");
        out.map(|p| p.translation_m)
    };
    assert_eq!(poses(&alone), poses(&both));
}

#[test]
fn with_value_moves_the_tip_as_the_record_with_that_value_does() {
    let q = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];
    let pose = |robot: &Robot| {
        let mut ws = robot.workspace();
        let mut out = [hapcal_runtime::Pose::IDENTITY];
        robot
            .deflected_tip_poses(&q, &mut ws, &mut out)
            .expect("valid");
        out[0].translation_m
    };
    let robot = load(&record(""), &["ball_link"]).expect("valid");
    for (name, value) in [("compliance.joint_a4", 0.004), ("joint_a2.offset", 0.005)] {
        let changed = robot.with_value(name, value).expect("recorded");
        // The same record with the value written in: the URDF's origin then holds the same
        // offset (nominal · motion(offset)), so only the record's values differ.
        let text = record("").replace(
            &format!(
                "\"{name}\" = {{ value = {}",
                robot
                    .calibration()
                    .expect("record")
                    .value(name)
                    .expect("value")
                    .value
            ),
            &format!("\"{name}\" = {{ value = {value}"),
        );
        let reloaded = load(&text, &["ball_link"]).expect("valid");
        let (a, b, c) = (pose(&changed), pose(&reloaded), pose(&robot));
        let moved = ((a[0] - c[0]).powi(2) + (a[1] - c[1]).powi(2) + (a[2] - c[2]).powi(2)).sqrt();
        assert!(moved > 1e-4, "{name}: moved {moved}");
        if name.starts_with("compliance") {
            // The origins are untouched: the reloaded record is the same robot.
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-12, "{name}: {a:?} {b:?}");
            }
        }
    }
    assert!(robot.with_value("compliance.joint_a9", 1.0).is_err());
}

#[test]
fn with_value_moves_an_identified_frame_by_its_deviation() {
    // The instrument frame is nominal · Δ(d) with d = (x 0.001 m, rz 0.002 rad); setting x
    // to 0.003 m moves it by 2 mm along the nominal · Rx…Rz-turned x axis, i.e. along the
    // frame's own x axis turned back by rz: `frame · Δ(d)⁻¹ · Δ(d')`.
    let text = format!(
        "{}\"instrument.x\" = {{ value = 0.001, std = 1e-4, unit = \"m\" }}\n\"instrument.rz\" = {{ value = 0.002, std = 1e-4, unit = \"rad\" }}\n",
        record("").replacen(
            "[values]",
            "[frames.instrument]\nxyz_m = [2.0, 0.5, -0.3]\nrpy_rad = [0.0, 0.0, 1.0]\n\n[values]",
            1
        )
    );
    let robot = load(&text, &["ball_link"]).expect("valid");
    let before = robot.frame("instrument").expect("frame");
    let moved = robot.with_value("instrument.x", 0.003).expect("recorded");
    let after = moved.frame("instrument").expect("frame");
    // Δ(d) = Tx(0.001)·Rz(0.002): the translation part sits before the rotation, so the
    // change of x moves the origin along the nominal frame's x axis, the frame's turned back
    // by rz: yaw 1.0 − 0.002 rad in the root frame.
    let yaw: f64 = 1.0 - 0.002;
    let expected = [
        before.translation_m[0] + 0.002 * yaw.cos(),
        before.translation_m[1] + 0.002 * yaw.sin(),
        before.translation_m[2],
    ];
    for k in 0..3 {
        assert!(
            (after.translation_m[k] - expected[k]).abs() < 1e-12,
            "{:?} {expected:?}",
            after.translation_m
        );
    }
    for (a, b) in after
        .rotation
        .as_flattened()
        .iter()
        .zip(before.rotation.as_flattened())
    {
        assert!((a - b).abs() < 1e-15, "{a} {b}");
    }
}
