//! The calibration record read back as written, and refused in words where it is wrong.

use hapcal_contract::{
    CalibratedValue, Calibration, ContractError, Covariance, Frame, JointRange, ModelName,
    PointMass, Region, SCHEMA_VERSION, Torque, TorqueSource,
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
    let mut device = String::from("name = \"d\"\n");
    r.write_toml(Some("calibration"), &mut device);
    #[derive(serde::Deserialize)]
    struct File {
        #[allow(dead_code)]
        name: String,
        calibration: Calibration,
    }
    let file: File = toml::from_str(&device).expect("parses");
    file.calibration.check(&device, "d").expect("checks");
    assert_eq!(file.calibration, r);
    assert_eq!(r.covariance.as_ref().map(|c| c.get(0, 1)), Some(1e-13));
}

#[test]
fn a_newer_schema_is_refused_in_words() {
    let text = record()
        .to_sidecar_toml()
        .replace("schema_version = 1", "schema_version = 7");
    let e = refused(&text);
    assert!(e.message.contains("newer hapcal"), "{e}");
    assert_eq!(e.line, 2, "{e}");
}

#[test]
fn an_unknown_name_or_a_wrong_unit_is_refused_at_its_line() {
    let text = record().to_sidecar_toml();
    let line_of = |needle: &str| {
        text.lines()
            .position(|l| l.starts_with(needle))
            .map(|i| i + 1)
            .expect("present")
    };
    let bad = text.replace("\"left_1.rx\"", "\"left_1.rw\"");
    let e = refused(&bad);
    assert!(e.message.contains("unknown value name"), "{e}");
    assert_eq!(e.line, line_of("\"left_1.rx\""), "{e}");

    let bad = text.replace(
        "\"compliance.left_1\" = { value = 0.0001234567890123, std = 3e-6, unit = \"rad/(N·m)\"",
        "\"compliance.left_1\" = { value = 0.0001234567890123, std = 3e-6, unit = \"rad/m\"",
    );
    assert_ne!(bad, text, "the replaced line is in the record");
    let e = refused(&bad);
    assert!(e.message.contains("expected \"rad/(N·m)\""), "{e}");
    assert_eq!(e.line, line_of("\"compliance.left_1\""), "{e}");
    assert!(e.to_string().starts_with("robot.calibration.toml:"), "{e}");
}

#[test]
fn a_missing_key_is_refused_with_what_is_expected() {
    let text = record()
        .to_sidecar_toml()
        .replace("model = \"transversal-compliance\"\n", "");
    let e = refused(&text);
    assert!(e.message.contains("missing key model"), "{e}");

    let mut r = record();
    r.torque = None;
    let e = refused(&r.to_sidecar_toml());
    assert!(e.message.contains("no [torque] table"), "{e}");

    let text = record().to_sidecar_toml().replace("rows = 412\n", "");
    let e = refused(&text);
    assert!(e.message.contains("missing field `rows`"), "{e}");
    assert!(e.line > 0, "{e}");

    let text = record()
        .to_sidecar_toml()
        .replace("source = \"urdf-masses\"", "source = \"guessed\"");
    let e = refused(&text);
    assert!(e.message.contains("lumped-unit-weights"), "{e}");
}

#[test]
fn a_record_of_an_earlier_hapcal_reads_as_before() {
    let text = "# Identified by `hapcal calibrate` with the kinematics.\n\n[frames.instrument]\n\
                xyz_m = [1.0, 2.0, 3.0]\nrpy_rad = [0.0, 0.0, 0.0]\n\n[values]\n\
                \"compliance.joint_a2\" = { value = 1e-4, std = 1e-6, unit = \"rad/m\" }\n";
    let r = Calibration::from_sidecar_str(text, "old").expect("reads");
    assert!(r.is_legacy());
    assert_eq!(r.values.len(), 1);
    assert_eq!(r.frames.len(), 1);
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
