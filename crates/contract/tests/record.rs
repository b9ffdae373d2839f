//! The calibration record read back as written, and refused in words where it is wrong.

use hapcal_contract::{
    CalibratedValue, Calibration, ContractError, Covariance, Frame, JointRange, ModelName,
    PointMass, Region, SCHEMA_VERSION, Torque, TorqueSource, digest,
};

fn record() -> Calibration {
    Calibration {
        schema_version: Some(SCHEMA_VERSION),
        model: Some(ModelName::TransversalCompliance),
        notes: Some("a \"quoted\" note".into()),
        tips: vec!["l_hand".into(), "r_hand".into()],
        torque: Some(Torque {
            source: TorqueSource::UrdfMasses,
            gravity_direction: [0.0, 0.0, -1.0],
            gravity_m_s2: 9.806_65,
            equilibrium: true,
            tips: vec!["l_hand".into(), "r_hand".into()],
            masses: vec![PointMass {
                joint: "left_1".into(),
                mass_kg: 1.25,
                com_m: [0.1, -1e-17, 0.3],
            }],
            handle_mass_kg: None,
        }),
        region: Some(Region {
            rows: 412,
            joints: vec![JointRange {
                name: "left_1".into(),
                min: -2.9,
                max: 1.0,
                unit: "rad".into(),
            }],
        }),
        frames: [(
            "instrument".to_owned(),
            Frame {
                xyz_m: [1.0, 2.0, 3.0],
                rpy_rad: [0.1, 0.2, std::f64::consts::PI],
            },
        )]
        .into(),
        nominal: [(
            "left_1".to_owned(),
            Frame {
                xyz_m: [0.0, 0.1, 0.25],
                rpy_rad: [0.0, -1.5, 0.0],
            },
        )]
        .into(),
        values: vec![
            CalibratedValue {
                name: "compliance.left_1".into(),
                value: 1.234_567_890_123e-4,
                std: 3e-6,
                unit: "rad/(N·m)".into(),
            },
            CalibratedValue {
                name: "transversal.left_1".into(),
                value: -2e-5,
                std: 1e-6,
                unit: "rad/(N·m)".into(),
            },
            CalibratedValue {
                name: "left_1.rx".into(),
                value: 1e-3,
                std: 1e-4,
                unit: "rad".into(),
            },
        ],
        covariance: Some(Covariance::from_matrix(
            vec!["compliance.left_1".into(), "left_1.rx".into()],
            &[9e-12, 1e-13, 1e-13, 1e-8],
        )),
        ..Calibration::default()
    }
}

/// `r` written as a device file's `[calibration]` table, the file's text and the record read
/// back from it (not yet checked).
fn under_a_device_table(r: &Calibration) -> (String, Calibration) {
    let mut device = String::from("name = \"d\"\n");
    r.write_toml(Some("calibration"), &mut device);
    #[derive(serde::Deserialize)]
    struct File {
        #[allow(dead_code)]
        name: String,
        calibration: Calibration,
    }
    let file: File = toml::from_str(&device).expect("parses");
    (device, file.calibration)
}

/// The refusal of the record's sidecar with `from` (which it holds) replaced by `to`.
fn refused_edit(from: &str, to: &str) -> ContractError {
    let text = record().to_sidecar_toml();
    assert!(text.contains(from), "{from:?} is not in the record");
    refused(&text.replace(from, to))
}

/// The refusal of the record's sidecar with `from` replaced by `to`, asserted to hold `part` in
/// its message and to stand at the line of the unedited sidecar that starts with `needle`.
#[track_caller]
fn refused_at((from, to): (&str, &str), part: &str, needle: &str) -> ContractError {
    let e = refused_edit(from, to);
    assert!(e.message.contains(part), "{e}");
    assert_eq!(e.line, line_of(&record().to_sidecar_toml(), needle), "{e}");
    e
}

/// The refusal of the sidecar text `bad`, asserted to hold `part` in its message and to stand
/// at line `line`.
#[track_caller]
fn refused_with(bad: &str, part: &str, line: usize) -> ContractError {
    let e = refused(bad);
    assert!(e.message.contains(part), "{e}");
    assert_eq!(e.line, line, "{e}");
    e
}

fn refused(text: &str) -> ContractError {
    Calibration::from_sidecar_str(text, "robot.calibration.toml").expect_err("refused")
}

#[test]
fn a_record_reads_back_bit_for_bit() {
    let r = record();
    let text = r.to_sidecar_toml();
    let again = Calibration::from_sidecar_str(&text, "x").expect("reads");
    assert_eq!(again, r);
    // Under a device file's table too.
    let (device, again) = under_a_device_table(&r);
    again.check(&device, "d").expect("checks");
    assert_eq!(again, r);
    assert_eq!(r.covariance.as_ref().map(|c| c.get(0, 1)), Some(1e-13));
}

#[test]
fn a_newer_schema_is_refused_in_words() {
    let e = refused_edit("schema_version = 1", "schema_version = 7");
    assert!(e.message.contains("newer hapcal"), "{e}");
    assert_eq!(e.line, 2, "{e}");
}

#[test]
fn an_unknown_name_or_a_wrong_unit_is_refused_at_its_line() {
    refused_at(
        ("\"left_1.rx\"", "\"left_1.rw\""),
        "unknown value name",
        "\"left_1.rx\"",
    );

    let e = refused_at(
        (
            "\"compliance.left_1\" = { value = 0.0001234567890123, std = 3e-6, unit = \"rad/(N·m)\"",
            "\"compliance.left_1\" = { value = 0.0001234567890123, std = 3e-6, unit = \"rad/m\"",
        ),
        "expected \"rad/(N·m)\"",
        "\"compliance.left_1\"",
    );
    assert!(e.to_string().starts_with("robot.calibration.toml:"), "{e}");
}

#[test]
fn a_missing_key_is_refused_with_what_is_expected() {
    let e = refused_edit("model = \"transversal-compliance\"\n", "");
    assert!(e.message.contains("missing key model"), "{e}");

    let mut r = record();
    r.torque = None;
    let e = refused(&r.to_sidecar_toml());
    assert!(e.message.contains("no [torque] table"), "{e}");

    let e = refused_edit("rows = 412\n", "");
    assert!(e.message.contains("missing field `rows`"), "{e}");
    assert!(e.line > 0, "{e}");

    let e = refused_edit("source = \"urdf-masses\"", "source = \"guessed\"");
    assert!(e.message.contains("lumped-unit-weights"), "{e}");
}

#[test]
fn a_sidecar_of_an_earlier_hapcal_is_refused() {
    let text = "# Identified by `hapcal calibrate` with the kinematics.\n\n[frames.instrument]\n\
                xyz_m = [1.0, 2.0, 3.0]\nrpy_rad = [0.0, 0.0, 0.0]\n\n[values]\n\
                \"compliance.joint_a2\" = { value = 1e-4, std = 1e-6, unit = \"rad/m\" }\n";
    let e = Calibration::from_sidecar_str(text, "old").expect_err("refused");
    assert_eq!((e.line, e.column), (1, 1), "{e}");
    assert!(
        e.message.starts_with("missing key schema_version")
            && e.message.contains("calibrate again"),
        "{e}"
    );
    // The same values in a device file's `[calibration]` still read (an earlier hapcal's).
    let r: Calibration = toml::from_str(text).expect("parses");
    assert!(r.is_legacy());
    r.check(text, "old").expect("an earlier hapcal's record");
}

#[test]
fn the_region_flags_readings_past_the_training_range() {
    let region = record().region.expect("a region");
    assert!(region.outside(&[0.0]).is_inside());
    // The slack: 5 % of the 3.9 rad range.
    assert!(region.outside(&[1.19]).is_inside());
    let out = region.outside(&[2.0]);
    assert_eq!(out.joints.len(), 1);
    assert!((out.joints[0].1 - 1.0).abs() < 1e-12);
    let out = region.outside(&[-3.5]);
    assert!((out.joints[0].1 + 0.6).abs() < 1e-12);
}

/// The 1-based line of the first line of `text` that starts with `needle` (after spaces).
fn line_of(text: &str, needle: &str) -> usize {
    text.lines()
        .position(|l| l.trim_start().starts_with(needle))
        .map(|i| i + 1)
        .expect("present")
}

/// `text` with the first line that starts with `needle` replaced by `line`.
fn with_line(text: &str, needle: &str, line: &str) -> String {
    let k = line_of(text, needle) - 1;
    let lines: Vec<&str> = (text.lines().enumerate())
        .map(|(i, l)| if i == k { line } else { l })
        .collect();
    lines.join("\n") + "\n"
}

#[test]
fn the_digest_is_fnv1a_64() {
    // The published test vectors of FNV-1a 64 (Fowler, Noll & Vo): "" and "a".
    assert_eq!(digest(b""), "fnv1a64:cbf29ce484222325");
    assert_eq!(digest(b"a"), "fnv1a64:af63dc4c8601ec8c");
    assert_eq!(digest(b"foobar"), "fnv1a64:85944171f73967e8");
}

#[test]
fn a_record_beside_another_urdf_is_refused_in_words() {
    let urdf = b"<robot name=\"iiwa14\"></robot>\n";
    let mut r = record();
    r.urdf_digest = Some(digest(urdf));
    let text = r.to_sidecar_toml();
    let again = Calibration::from_sidecar_str(&text, "iiwa14.calibration.toml").expect("reads");
    assert_eq!(again.urdf_digest, r.urdf_digest);
    let ok = again.check_urdf(&text, "iiwa14.calibration.toml", urdf, "iiwa14.urdf");
    assert_eq!(ok, Ok(None));
    let other = b"<robot name=\"iiwa7\"></robot>\n";
    let e = (again.check_urdf(&text, "iiwa14.calibration.toml", other, "iiwa7.urdf"))
        .expect_err("another URDF");
    assert_eq!(e.line, line_of(&text, "urdf_digest"), "{e}");
    for words in [
        "iiwa7.urdf",
        &digest(urdf),
        &digest(other),
        "another robot description",
        "calibrate iiwa7.urdf again",
    ] {
        assert!(e.message.contains(words), "{words}: {e}");
    }
    // A record without a digest loads, with a note.
    let note =
        (record().check_urdf(&text, "old.calibration.toml", other, "iiwa7.urdf")).expect("loads");
    assert!(note.is_some_and(|n| n.contains("no digest")));
}

#[test]
fn a_missing_schema_version_is_refused_at_the_first_key_of_schema_1() {
    let bad = record()
        .to_sidecar_toml()
        .replace("schema_version = 1\n", "");
    let e = refused_with(&bad, "missing key schema_version", line_of(&bad, "model ="));
    assert!(!e.message.contains("unknown field"), "{e}");
}

#[test]
fn negative_masses_are_refused_at_their_own_line() {
    let text = record().to_sidecar_toml();
    let bad = with_line(&text, "mass_kg", "mass_kg = -1.25");
    refused_with(&bad, "non-negative mass", line_of(&bad, "mass_kg"));
    // A negative compliance is judged where it is estimated (calibrate stops on one beyond
    // negative_compliance_sigmas); the record reads what it holds.
    let negative = with_line(
        &text,
        "\"compliance.left_1\"",
        "\"compliance.left_1\" = { value = -1e-4, std = 3e-6, unit = \"rad/(N·m)\" }",
    );
    Calibration::from_sidecar_str(&negative, "x").expect("a record reads what it holds");
}

#[test]
fn a_region_with_min_above_max_is_refused_at_its_line() {
    let text = record().to_sidecar_toml();
    let bad = with_line(&text, "max = 1.0", "max = -3.0");
    refused_with(&bad, "min ≤ max", line_of(&bad, "max = -3.0"));
    // The inline form of the documentation, and under a device file's [calibration].
    let inline = "schema_version = 1\nmodel = \"geometric\"\n\n[region]\nrows = 3\n\
                  joint = [{ name = \"a\", min = 0.5, max = 0.1, unit = \"rad\" }]\n";
    let e = refused(inline);
    assert_eq!(e.line, 6, "{e}");
    let mut r = record();
    if let Some(region) = &mut r.region {
        region.joints[0].max = -3.0;
    }
    let (device, again) = under_a_device_table(&r);
    let e = again.check(&device, "d.toml").expect_err("refused");
    assert_eq!(e.line, line_of(&device, "max = -3.0"), "{e}");
}

#[test]
fn the_model_constrains_the_values_its_record_holds() {
    // A geometric record with compliance values.
    refused_at(
        (
            "model = \"transversal-compliance\"",
            "model = \"geometric\"",
        ),
        "identifies no compliance",
        "\"compliance.left_1\"",
    );
    // A compliance record with a transversal compliance.
    refused_at(
        (
            "model = \"transversal-compliance\"",
            "model = \"compliance\"",
        ),
        "no transversal",
        "\"transversal.left_1\"",
    );
    // A haptic device's model on a URDF's sidecar.
    let mut r = record();
    r.model = Some(ModelName::Transmissions);
    r.values.retain(|v| v.name == "left_1.rx");
    r.covariance = None;
    let bad = r.to_sidecar_toml();
    refused_with(&bad, "haptic device", line_of(&bad, "model ="));
    // A second-order harmonic on a first-order harmonic model.
    let mut r = record();
    r.model = Some(ModelName::Harmonic);
    r.torque = None;
    r.covariance = None;
    r.values = vec![CalibratedValue {
        name: "harmonic.left_1.sin2".into(),
        value: 1e-4,
        std: 1e-6,
        unit: "rad".into(),
    }];
    let e = refused(&r.to_sidecar_toml());
    assert!(e.message.contains("first-order"), "{e}");
}

#[test]
fn a_misnamed_value_is_refused_at_its_own_line() {
    let text = record().to_sidecar_toml();
    let bad = text.replace("\"left_1.rx\" =", "\"left_9.rx\" =");
    let e = refused_with(&bad, "misnamed", line_of(&bad, "\"left_9.rx\""));
    assert!(e.message.contains("left_1.rx"), "{e}");
}

#[test]
fn no_refusal_of_a_record_points_at_line_zero() {
    let text = record().to_sidecar_toml();
    let cases = [
        with_line(&text, "mass_kg", "mass_kg = -1.25"),
        with_line(&text, "com_m", "com_m = [nan, 0.0, 0.0]"),
        with_line(
            &text,
            "source",
            "source = \"urdf-masses\"\nhandle_mass_kg = 1.0",
        )
        .replace(
            "[[torque.mass]]\njoint = \"left_1\"\nmass_kg = 1.25\ncom_m = [0.1, -1e-17, 0.3]\n",
            "",
        ),
        with_line(&text, "unit = \"rad\"", "unit = \"deg\""),
        with_line(&text, "max = 1.0", "max = -3.0"),
        with_line(&text, "gravity_m_s2", "gravity_m_s2 = -1.0"),
        text.replace("xyz_m = [0.0, 0.1, 0.25]", "xyz_m = [0.0, nan, 0.25]"),
        text.replace("schema_version = 1\n", ""),
        text.replace("\"left_1.rx\" =", "\"left_9.rx\" ="),
    ];
    for (k, case) in cases.iter().enumerate() {
        assert_ne!(*case, text, "case {k} changes the record");
        let e = refused(case);
        assert!(e.line > 0 && e.column > 0, "case {k}: {e}");
    }
}
