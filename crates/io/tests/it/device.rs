use std::path::Path;

use hapcal_io::{
    CalibratedValue, CalibrationMeta, DhConvention, Error, JointRef, parse_device, read_device,
    write_device,
};

use crate::{assert_contains, data, message, reference_device};

fn value(name: &str, value: f64, unit: &str) -> CalibratedValue {
    CalibratedValue {
        name: name.into(),
        value,
        std: 1e-5,
        unit: unit.into(),
    }
}

#[test]
fn reference_device_reads() {
    let device = read_device(&reference_device()).unwrap();
    assert_eq!(
        device.name.as_deref(),
        Some("reference 7-DOF haptic device")
    );
    assert_eq!(device.convention, DhConvention::Standard);
    assert_eq!(device.dh.len(), 8);
    assert_eq!(device.dh[0].joint, JointRef::Fixed);
    assert_eq!(device.dh[7].joint, JointRef::Joint(7));
    assert_eq!(device.dh[7].a_m, 0.03);
    assert_eq!(device.n_joints(), 7);
    assert_eq!(
        device.joint_limits(),
        [
            (-1.0, 1.0),
            (-0.3, 1.2),
            (-0.8, 0.8),
            (0.3, 1.8),
            (-2.0, 2.0),
            (-1.2, 1.2),
            (-2.5, 2.5)
        ]
    );
    assert_eq!(device.capstans.len(), 4);
    assert_eq!(device.capstans[2].ratio, 11.0);
    assert_eq!(device.parallelogram.map(|p| p.l2_m), Some(0.21));
    assert_eq!(device.cable_encoder.map(|c| c.counts_per_rev), Some(20000));
    assert_eq!(device.handle.map(|h| h.mass_kg), Some(0.2));
    assert!(device.calibration.is_none());

    let chain = device.chain().unwrap();
    assert_eq!(chain.n_joints(), 7);
    assert_eq!(chain.n_params(), 32); // 8 rows × (da, dalpha, dd, dtheta)
    let rows = device.dh_rows();
    assert_eq!(rows[0].joint, None);
    assert_eq!(rows[1].joint, Some(0));
    assert_eq!(rows[7].joint, Some(6));
}

#[test]
fn device_file_round_trips() {
    let device = read_device(&reference_device()).unwrap();
    let text = write_device(&device);
    let again = parse_device(&text, Path::new("written.toml")).unwrap();
    assert_eq!(again, device);
    assert_eq!(write_device(&again), text);
}

#[test]
fn calibrated_device_round_trips_and_applies_deviations() {
    let device = read_device(&reference_device()).unwrap();
    let values = [
        value("da0", 1e-3, "m"),
        value("dalpha1", -2e-3, "rad"),
        value("dd2", 3e-4, "m"),
        value("dtheta3", 0.1 + 0.2, "rad"), // not exactly 0.3
        value("dbeta4", 5e-3, "rad"),
        value("capstan1.c", 1.5e-3, "rad"),
        value("weird \"key\".é", 7.0, "1"),
    ];
    let meta = CalibrationMeta {
        date: Some("2025-05-01".into()),
        data_hash: Some("sha256:0123abcd".into()),
        notes: Some("two lines\nwith \"quotes\" and a \\ backslash".into()),
    };
    let calibrated = device.with_calibration(&values, meta.clone()).unwrap();
    assert_eq!(calibrated.dh[0].a_m, 0.35 + 1e-3);
    assert_eq!(
        calibrated.dh[1].alpha_rad,
        -std::f64::consts::FRAC_PI_2 - 2e-3
    );
    assert_eq!(calibrated.dh[2].d_m, 3e-4);
    assert_eq!(calibrated.dh[3].theta_rad, 0.1 + 0.2);
    assert_eq!(calibrated.dh[4].beta_rad, Some(5e-3));
    assert_eq!(calibrated.dh[5], device.dh[5]);
    let calibration = calibrated.calibration.as_ref().unwrap();
    assert_eq!(calibration.values, values);
    assert_eq!(calibration.notes, meta.notes);

    let text = write_device(&calibrated);
    assert_contains(
        &text,
        &["[calibration.values]\nda0 = { value = 0.001, std = 1e-5, unit = \"m\" }\n"],
    );
    let again = parse_device(&text, Path::new("calibrated.toml")).unwrap();
    assert_eq!(again, calibrated);
    // The order of the values is kept (not sorted by name).
    let again_values = again.calibration.map(|c| c.values).unwrap_or_default();
    let names: Vec<&str> = again_values.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names[..3], ["da0", "dalpha1", "dd2"]);
}

#[test]
fn calibration_rejects_what_it_cannot_apply() {
    let device = read_device(&reference_device()).unwrap();
    let meta = CalibrationMeta::default();
    let cases = [
        (
            vec![value("da8", 1e-3, "m")],
            "parameter \"da8\": the D-H table has rows 0..8",
        ),
        (
            vec![value("dtheta2", 1e-3, "m")],
            "parameter \"dtheta2\": unit is \"m\", expected \"rad\"",
        ),
        (
            vec![value("da1", 1e-3, "m"), value("da1", 1e-3, "m")],
            "parameter \"da1\": appears twice",
        ),
        (
            vec![value("dd1", f64::NAN, "m")],
            "parameter \"dd1\": value NaN",
        ),
    ];
    for (values, expected) in cases {
        let msg = message(device.with_calibration(&values, meta.clone()));
        assert_contains(&msg, &[expected]);
    }
}

#[test]
fn each_bad_device_file_names_file_line_and_column() {
    let cases = [
        ("bad_syntax.toml", "bad_syntax.toml:12:"),
        (
            "bad_unknown_key.toml",
            "bad_unknown_key.toml:21:1: unknown field `uper_rad`",
        ),
        (
            "bad_limits.toml",
            "bad_limits.toml:25:13: joint \"elbow\": lower_rad = -2 must be below upper_rad = -2.5",
        ),
        (
            "bad_joint_numbers.toml",
            "bad_joint_numbers.toml:16:9: [[dh]] row 1 has joint 3, expected 2",
        ),
        (
            "bad_joint_count.toml",
            "bad_joint_count.toml:18: expected 2 joints (as the device has), found 1",
        ),
        (
            "bad_nan.toml",
            "bad_nan.toml:14:7: expected a finite number in \"dh[1].d_m\", found NaN",
        ),
    ];
    for (file, expected) in cases {
        let msg = message(read_device(&data(file)));
        assert_contains(&msg, &[expected]);
    }
    let err = read_device(&data("bad_syntax.toml")).unwrap_err();
    assert!(matches!(err, Error::Toml { line: 12, .. }), "{err:?}");
}

#[test]
fn semantic_checks_point_at_the_offending_value() {
    let planar = std::fs::read_to_string(data("planar.toml")).unwrap();
    let path = Path::new("edited.toml");
    let with = |extra: &str| format!("{planar}\n{extra}");
    let cases = [
        (
            with("[[capstan]]\njoint = 3\nratio = 10.0\ndrum_distance_m = 0.06\n"),
            "edited.toml:29:9: capstan joint = 3 does not exist: joints are 1..=2",
        ),
        (
            with("[[capstan]]\njoint = 1\nratio = -10.0\ndrum_distance_m = 0.06\n"),
            "edited.toml:30:9: ratio = -10 must be positive",
        ),
        (
            with("[cable_encoder]\ndrum_radius_m = 0.015\ncounts_per_rev = 0\n"),
            "edited.toml:30:18: counts_per_rev must be positive",
        ),
        (
            with("[handle]\nmass_kg = -0.2\n"),
            "edited.toml:29:11: mass_kg = -0.2 must not be negative",
        ),
        (
            // An earlier hapcal's record (no schema_version): its values are checked too.
            with("[calibration.values]\nda0 = { value = 0.001, std = -1.0, unit = \"m\" }\n"),
            "edited.toml:29:30: da0: value 0.001 with std -1: expected finite numbers, std ≥ 0",
        ),
        (
            with(
                "[[placement]]\nname = \"a\"\nxyz_m = [0.0, 0.0, 0.0]\nrpy_rad = [0.0, 0.0, 0.0]\n",
            ),
            "edited.toml:28:1: both [[dh]] and [[placement]] rows",
        ),
        (
            planar.replace("name = \"elbow\"", "name = \"shoulder\""),
            "edited.toml:24:8: joint name \"shoulder\" is used twice",
        ),
        (
            planar.replace("joint = 1", "joint = 0"),
            "edited.toml:9:9: joint number 0 is invalid",
        ),
        (
            planar.replace("joint = 1", "joint = \"fixd\""),
            "edited.toml:9:9: joint \"fixd\" is invalid",
        ),
        (
            planar.replace("name = \"planar\"", "convention = \"craig\""),
            "edited.toml:2:14: unknown convention \"craig\"",
        ),
        (
            "[[joint]]\nname = \"q1\"\nlower_rad = 0.0\nupper_rad = 1.0\n".to_owned(),
            "edited.toml:1:1: no kinematic chain",
        ),
        (
            planar
                .replace("joint = 1", "joint = \"fixed\"")
                .replace("joint = 2", "joint = \"fixed\""),
            "edited.toml:1:1: the kinematic chain has no joints",
        ),
    ];
    for (text, expected) in cases {
        let msg = message(parse_device(&text, path));
        assert_contains(&msg, &[expected]);
    }
}

/// Asserts that the device file `text` with its first `from` replaced by `to`, read
/// as `t.toml`, is refused with a message holding every one of `parts`.
#[track_caller]
fn refused_edit(text: &str, (from, to): (&str, &str), parts: &[&str]) {
    let edited = text.replacen(from, to, 1);
    assert_contains(&message(parse_device(&edited, Path::new("t.toml"))), parts);
}

/// Asserts that the device file `text` with its first `from` replaced by `to`, read as
/// `t.toml`, is refused at column 1 of the edited text's first line that starts with `needle`,
/// with a message that goes on with `start`.
#[track_caller]
fn refused_edit_at(text: &str, (from, to): (&str, &str), needle: &str, start: &str) {
    let edited = text.replacen(from, to, 1);
    let line = 1
        + (edited.lines().position(|l| l.starts_with(needle)))
            .unwrap_or_else(|| panic!("no line starts with {needle:?}"));
    let err = message(parse_device(&edited, Path::new("t.toml")));
    assert!(
        err.starts_with(&format!("t.toml:{line}:1: {start}")),
        "{err}"
    );
}

#[test]
fn missing_device_file_is_an_io_error() {
    let msg = message(read_device(&data("no_such_device.toml")));
    assert_contains(&msg, &["cannot read ", "no_such_device.toml: "]);
}

/// TIAGo's torso is a prismatic joint with limits 0 to 0.35 m: the device file must say so
/// (`prismatic = true`, `lower_m`/`upper_m`), and read back to the same prismatic joint.
#[test]
fn prismatic_joint_survives_the_device_file_with_its_unit() {
    let urdf = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/figaroh/tiago/tiago.urdf");
    let device = hapcal_io::import_urdf(&urdf, "arm_7_link").unwrap();
    assert_eq!(device.prismatic_joints().iter().filter(|p| **p).count(), 1);
    let text = write_device(&device);
    assert_contains(
        &text,
        &[
            "name = \"torso_lift_joint\"\nxyz_m = [0.0, 0.0, 0.597]\nrpy_rad = [0.0, 0.0, 0.0]\naxis = [0.0, 0.0, 1.0]\nprismatic = true\n",
            "name = \"torso_lift_joint\"\nlower_m = 0.0\nupper_m = 0.35\n",
            "name = \"arm_1_joint\"\nlower_rad = ",
        ],
    );
    let back = parse_device(&text, Path::new("tiago.toml")).unwrap();
    assert_eq!(back, device);
    assert_eq!(back.prismatic_joints(), device.prismatic_joints());

    // The limit keys name the unit and must match the joint.
    refused_edit(
        &text,
        (
            "lower_m = 0.0\nupper_m = 0.35",
            "lower_rad = 0.0\nupper_rad = 0.35",
        ),
        &[
            "t.toml:",
            "joint \"torso_lift_joint\" is a prismatic joint: its limits are lengths, expected lower_m (in m), found lower_rad",
        ],
    );
    refused_edit(
        &text,
        (
            "name = \"arm_1_joint\"\nlower_rad = ",
            "name = \"arm_1_joint\"\nlower_m = ",
        ),
        &[
            "joint \"arm_1_joint\" is a revolute joint: its limits are angles, expected lower_rad (in rad), found lower_m",
        ],
    );
    // A prismatic limit is a length: 2000 m is out of range.
    refused_edit(
        &text,
        ("upper_m = 0.35", "upper_m = 2000.0"),
        &["t.toml:70:11: joint[0].upper_m = 2e3 m is out of range"],
    );
}

/// A two-arm tree (`[[branch]]` per further tip) survives the device file, and a branch that
/// hangs from no placement above it is refused at its line.
#[test]
fn placement_tree_survives_the_device_file() {
    let urdf = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/sim-humanoid/humanoid.urdf");
    let tips = ["l_hand".to_owned(), "r_hand".to_owned()];
    let device = hapcal_io::import_urdf_tree(&urdf, &tips).unwrap();
    // Three torso joints and two seven-joint arms.
    assert_eq!(device.n_joints(), 17);
    assert_eq!(device.joints.len(), 17);
    assert_eq!(device.branches.len(), 1);
    let tree = hapcal_io::import_urdf_tips(&urdf, &tips).unwrap();
    let names: Vec<&str> = device.joints.iter().map(|j| j.name.as_str()).collect();
    let want: Vec<&str> = tree.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, want);
    assert_eq!(device.placement_paths().unwrap(), tree.paths);

    let text = write_device(&device);
    assert_contains(
        &text,
        &[
            "[[branch]]\nfrom = \"torso_3\"\n",
            "[[branch.placement]]\nname = \"r_1\"",
        ],
    );
    let back = parse_device(&text, Path::new("humanoid.toml")).unwrap();
    assert_eq!(back, device);

    refused_edit(
        &text,
        ("from = \"torso_3\"", "from = \"r_3\""),
        &[
            "t.toml:",
            "branch from = \"r_3\": no placement of the main chain or of an earlier branch has that name",
        ],
    );
    refused_edit(
        &text,
        ("from = \"torso_3\"", "from = \"torso_9\""),
        &["torso_9"],
    );
}

/// A device file's `[calibration]` of schema 1 is the contract's record: it reads back whole,
/// and the contract's refusals come at the file's line, while an earlier hapcal's record
/// (no `schema_version`) reads as before.
#[test]
fn a_calibration_record_is_checked_at_its_line() {
    let path = reference_device().with_file_name("compliance-calibrated.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let device = parse_device(&text, &path).unwrap();
    let record = device.calibration.as_ref().unwrap();
    assert_eq!(record.schema_version, Some(1));
    assert!(record.region.is_some() && record.covariance.is_some());
    // Written again, it reads back equal.
    assert_eq!(
        parse_device(&write_device(&device), Path::new("again.toml")).unwrap(),
        device
    );
    refused_edit_at(
        &text,
        ("\"joint_compliance.j3\"", "\"joint_compliance.k3\""),
        "\"joint_compliance.k3\"",
        "[calibration]: \"joint_compliance.k3\": unknown value name",
    );
    refused_edit_at(
        &text,
        ("schema_version = 1", "schema_version = 2"),
        "schema_version",
        "[calibration]: schema_version = 2",
    );
    refused_edit(
        &text,
        ("model = \"compliance\"\n", ""),
        &["missing key model"],
    );
    // An earlier hapcal's record (no schema_version, model, region: notes and values) reads
    // as before.
    let device_part = &text[..text.find("[calibration]").expect("a calibration table")];
    let legacy_text = format!(
        "{device_part}[calibration]\nnotes = \"an earlier hapcal\"\n\n[calibration.values]\n\"dd3\" = {{ value = 1e-4, std = 1e-5, unit = \"m\" }}\n"
    );
    let legacy = parse_device(&legacy_text, Path::new("legacy.toml")).unwrap();
    let record = legacy.calibration.unwrap();
    assert!(record.is_legacy());
    assert_eq!(record.values.len(), 1);
}
