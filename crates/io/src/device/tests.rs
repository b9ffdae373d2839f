//! Unit tests of the device file: parameter names, number formatting, calibration.

use std::path::{Path, PathBuf};

use proptest::prelude::*;

use super::*;
use crate::{import_urdf, parse_device, write_device};

/// A file of the repository's `fixtures/`.
fn fixture(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(relative)
}

fn reference() -> Device {
    read_device(&fixture("reference-device/device.toml")).expect("the reference device is valid")
}

fn iiwa() -> Device {
    import_urdf(&fixture("mukca/urdf/iiwa14.urdf"), "ball_link").expect("iiwa14.urdf imports")
}

fn value(name: &str, value: f64, unit: &str) -> CalibratedValue {
    CalibratedValue {
        name: name.into(),
        value,
        std: 0.0,
        unit: unit.into(),
    }
}

#[test]
fn dh_parameter_names_parse_longest_prefix_first() {
    assert!(matches!(
        parse_dh_param("dalpha3"),
        Some((DhField::Alpha, 3))
    ));
    assert!(matches!(parse_dh_param("da12"), Some((DhField::A, 12))));
    assert!(matches!(parse_dh_param("dd0"), Some((DhField::D, 0))));
    assert!(matches!(
        parse_dh_param("dtheta7"),
        Some((DhField::Theta, 7))
    ));
    assert!(matches!(parse_dh_param("dbeta2"), Some((DhField::Beta, 2))));
    for other in [
        "da",
        "da01",
        "dalpha",
        "dax",
        "d3",
        "capstan1.c",
        "dtheta-1",
        "da 1",
    ] {
        assert!(parse_dh_param(other).is_none(), "{other}");
    }
}

#[test]
fn placement_parameter_names_split_at_the_last_dot() {
    assert_eq!(parse_placement_param("joint_a2.rx"), Some(("joint_a2", 3)));
    assert_eq!(parse_placement_param("a.b.z"), Some(("a.b", 2)));
    assert_eq!(parse_placement_param("joint_a2.c"), None);
    assert_eq!(parse_placement_param("da0"), None);
}

#[test]
fn placement_calibration_rejects_fixed_placements_and_wrong_units() {
    let device = iiwa();
    let meta = CalibrationMeta::default;
    for (name, refusal) in [
        // joint_a7-tool0 is fixed and folded into the tip element named after ball_joint.
        (
            "joint_a7-tool0.z",
            "parameter \"joint_a7-tool0.z\": no revolute or tip placement named \"joint_a7-tool0\" carries it",
        ),
        (
            "joint_a1.rx",
            "parameter \"joint_a1.rx\": unit is \"m\", expected \"rad\"",
        ),
    ] {
        let err = device
            .with_calibration(&[value(name, 1e-3, "m")], meta())
            .unwrap_err();
        assert_eq!(err.to_string(), refusal);
    }
    // Names that are not kinematic parameters are only recorded.
    let calibrated = device
        .with_calibration(&[value("socket0.c", 1.0, "1")], meta())
        .unwrap();
    assert_eq!(calibrated.placements, device.placements);
    assert_eq!(calibrated.calibration.map(|c| c.values.len()), Some(1));
}

#[test]
fn zero_deviation_leaves_a_placement_untouched() {
    let device = iiwa();
    let calibrated = device
        .with_calibration(&[value("joint_a2.x", 0.0, "m")], CalibrationMeta::default())
        .unwrap();
    assert_eq!(calibrated.placements, device.placements);
}

#[test]
fn toml_strings_and_keys_are_escaped() {
    let mut device = reference();
    device.name = Some("tab\there \"quoted\" back\\slash\nnewline \u{7} bell é".into());
    device.calibration = Some(Calibration {
        date: Some("2025-05-01".into()),
        data_hash: None,
        notes: None,
        values: vec![
            value("plain_key-1", 1.0, "1"),
            value("dotted.key", 2.0, "m"),
            value("", 3.0, "rad"),
            value("ü", 4.0, "rad"),
        ],
        ..Calibration::default()
    });
    let text = write_device(&device);
    let again = parse_device(&text, Path::new("escaped.toml")).unwrap();
    assert_eq!(again, device);
}

/// The gap between `device`'s nominal chain moved by `deltas` (one per parameter) and the
/// chain of the device calibrated with them at joint angles `q`: position (m) and rotation
/// (rad).
fn deviated_gap(device: &Device, deltas: &[f64], q: &[f64]) -> (f64, f64) {
    let nominal = device.chain().unwrap();
    assert_eq!(nominal.n_params(), deltas.len());
    let values: Vec<CalibratedValue> = (nominal.params().iter().zip(deltas))
        .map(|(p, d)| value(&p.name, *d, p.unit.symbol()))
        .collect();
    let calibrated = device
        .with_calibration(&values, CalibrationMeta::default())
        .unwrap()
        .chain()
        .unwrap();
    let want = nominal.end_pose(deltas, q);
    let got = calibrated.end_pose(&vec![0.0; deltas.len()], q);
    (
        (want.translation.vector - got.translation.vector).norm(),
        want.rotation.angle_to(&got.rotation),
    )
}

proptest! {
    #[test]
    fn every_finite_number_survives_the_round_trip(
        a in prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL | prop::num::f64::ZERO,
        alpha in -10.0..10.0f64,
        tiny in -1e-300..1e-300f64,
        huge in prop::num::f64::POSITIVE | prop::num::f64::NORMAL,
    ) {
        // Angles within ±MAX_MAGNITUDE rad and lengths within ±MAX_LENGTH_M m, both 1000 (a
        // larger one is refused, below).
        let max = crate::MAX_LENGTH_M;
        let mut device = reference();
        device.dh[3].theta_rad = a.clamp(-max, max);
        device.dh[3].a_m = a.clamp(-max, max);
        device.dh[3].alpha_rad = alpha;
        device.dh[3].beta_rad = Some(tiny);
        device.cable_encoder = device.cable_encoder.map(|c| CableEncoder { drum_radius_m: huge.min(max), ..c });
        prop_assume!(huge.is_finite() && huge > 0.0);
        let again = parse_device(&write_device(&device), Path::new("p.toml")).unwrap();
        prop_assert_eq!(again.dh[3].theta_rad.to_bits(), a.clamp(-max, max).to_bits());
        prop_assert_eq!(again.dh[3].a_m.to_bits(), a.clamp(-max, max).to_bits());
        prop_assert_eq!(&again, &device);
        if a.abs() > max {
            device.dh[3].a_m = a;
            let refused = parse_device(&write_device(&device), Path::new("p.toml"));
            prop_assert!(
                matches!(refused, Err(crate::Error::LengthOutOfRange { .. })),
                "{refused:?}"
            );
            device.dh[3].a_m = 0.0;
            device.dh[3].theta_rad = a;
            let refused = parse_device(&write_device(&device), Path::new("p.toml"));
            prop_assert!(
                matches!(&refused, Err(crate::Error::InvalidDevice { message, .. })
                    if message.contains("an angle must lie within ±1000 rad")),
                "{refused:?}"
            );
        }
    }

    /// The calibrated device's nominal chain is the nominal chain moved by the deviations:
    /// the placement composition agrees with the kinematics crate's parameterisation.
    #[test]
    fn calibrated_placements_equal_the_deviated_chain(
        deltas in prop::collection::vec(-0.05..0.05f64, 48),
        q in prop::collection::vec(-2.0..2.0f64, 7),
    ) {
        let (dp, dr) = deviated_gap(&iiwa(), &deltas, &q);
        prop_assert!(dp < 1e-12 && dr < 1e-12, "{} m, {} rad", dp, dr);
    }

    /// The D-H deviations agree with the kinematics crate's parameterisation too.
    #[test]
    fn calibrated_dh_rows_equal_the_deviated_chain(
        deltas in prop::collection::vec(-0.05..0.05f64, 32),
        q in prop::collection::vec(-1.0..1.0f64, 7),
    ) {
        let (dp, _) = deviated_gap(&reference(), &deltas, &q);
        prop_assert!(dp < 1e-12, "{} m", dp);
    }
}
