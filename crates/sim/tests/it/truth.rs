//! The truth file: the fixture's values and the reader's errors.

use std::path::Path;

use hapcal_sim::{
    Error, NoiseModel, SimConfig, Truth, parse_truth, simulate, true_joint_angles, truth_deviations,
};
use hapcal_transmission::Joint4Transmission;

use crate::{paper_truth, reference};

#[test]
fn fixture_holds_table_3_deviations() {
    let (truth, device) = paper_truth();
    // Table 3 lists 30 assigned deviations: Δα0..7, Δa0..7, Δd1..7, Δθ1..7.
    assert_eq!(truth.deviations.len(), 30);
    let chain = device.chain().unwrap();
    assert_eq!(chain.n_params(), 32);
    let x = truth_deviations(&chain, &truth).unwrap();
    let names = |pred: &dyn Fn(f64) -> bool| -> Vec<&str> {
        (chain.params().iter().zip(&x))
            .filter(|(_, v)| pred(**v))
            .map(|(p, _)| p.name.as_str())
            .collect()
    };
    // Table 3 has no Δd0 and Δθ0.
    assert_eq!(names(&|v| v == 0.0), ["dd0", "dtheta0"]);
    let nonzero = names(&|v| v != 0.0);
    assert_eq!(nonzero.len(), 30);
    // 32 − 4 = 28 identifiable ones plus the unidentifiable Δα0 and Δα7.
    let identifiable: Vec<_> = (nonzero.iter())
        .filter(|n| !["dalpha0", "dalpha7"].contains(n))
        .collect();
    assert_eq!(identifiable.len(), 28);

    let value = |name: &str| x[chain.param_index(name).unwrap()];
    assert_eq!(value("dalpha0"), 1.5e-3); // mrad → rad
    assert_eq!(value("dalpha7"), 1.7e-3);
    assert_eq!(value("da0"), 1.9e-3); // mm → m
    assert_eq!(value("da7"), -1.3e-3);
    assert_eq!(value("dd4"), -1.3e-3);
    assert_eq!(value("dtheta3"), -1.3e-3);
    assert_eq!(value("dtheta7"), 1.1e-3);
}

#[test]
fn fixture_holds_table_2_transmissions() {
    let (truth, _) = paper_truth();
    let joints: Vec<usize> = truth.capstans.iter().map(|c| c.joint).collect();
    assert_eq!(joints, [1, 2, 3, 4]);
    let deg = f64::to_radians;
    let expected = [
        // (Re, r_o mm, r_i mm, β_o deg, β_i deg): Table 2 and the values printed below it.
        (-0.025, 0.200, 0.005, -105.0, -15.0),
        (-0.020, 0.250, 0.0025, -10.0, 140.0),
        (0.015, 0.200, 0.004, 150.0, -100.0),
        (0.02, 0.1, 0.002, -40.0, -120.0),
    ];
    for (c, (re, r_o_mm, r_i_mm, beta_o, beta_i)) in truth.capstans.iter().zip(expected) {
        let j = c.joint;
        assert_eq!(c.c_rad, 0.0, "joint {j}");
        assert_eq!(c.re, re, "joint {j}");
        assert!((c.r_o_m - r_o_mm * 1e-3).abs() < 1e-15, "joint {j}");
        assert!((c.r_i_m - r_i_mm * 1e-3).abs() < 1e-15, "joint {j}");
        assert!((c.beta_o_rad - deg(beta_o)).abs() < 1e-15, "joint {j}");
        assert!((c.beta_i_rad - deg(beta_i)).abs() < 1e-15, "joint {j}");
    }
    let p = truth
        .parallelogram
        .expect("the fixture has a [parallelogram]");
    assert_eq!(
        (p.dl1_m, p.dl2_m, p.dl3_m, p.dl4_m),
        (-0.5e-3, -0.7e-3, 0.0, 0.0)
    );
    let phi0 = Joint4Transmission::phi0_mid_range_rad(0.3, 1.8);
    assert!((p.phi0_rad - phi0).abs() < 1e-15);
}

#[test]
fn fixture_device_is_design_section_2() {
    let (truth, device) = paper_truth();
    assert_eq!(truth.device, Path::new("device.toml"));
    assert_eq!(
        truth.device_path(&reference("truth.toml")),
        reference("device.toml")
    );
    let half_pi = std::f64::consts::FRAC_PI_2;
    let rows: Vec<(f64, f64, f64)> = device
        .dh
        .iter()
        .map(|r| (r.a_m, r.alpha_rad, r.d_m))
        .collect();
    assert_eq!(
        rows,
        [
            (0.35, -half_pi, 0.0),
            (0.0, -half_pi, 0.10),
            (0.0, half_pi, 0.0),
            (0.0, -half_pi, 0.21),
            (0.0, half_pi, 0.0),
            (0.0, -half_pi, 0.21),
            (0.0, half_pi, 0.0),
            (0.03, 0.0, 0.05),
        ]
    );
    assert!(device.dh.iter().all(|r| r.theta_rad == 0.0));
    // Its joint limits are §2's: hapcal-io's test of the same file (`reference_device_reads`).
    assert!(
        device
            .joints
            .iter()
            .all(|j| j.counts_per_rev == Some(20_000))
    );
    let capstans: Vec<(usize, f64, f64)> = (device.capstans.iter())
        .map(|c| (c.joint, c.ratio, c.drum_distance_m))
        .collect();
    assert_eq!(
        capstans,
        [
            (1, 10.0, 0.06),
            (2, 12.0, 0.06),
            (3, 11.0, 0.06),
            (4, 12.0, 0.06)
        ]
    );
    let p = device.parallelogram.unwrap();
    assert_eq!((p.l1_m, p.l2_m, p.l3_m, p.l4_m), (0.05, 0.21, 0.05, 0.21));
    let cable = device.cable_encoder.unwrap();
    assert_eq!((cable.drum_radius_m, cable.counts_per_rev), (0.015, 20_000));
    assert_eq!(device.handle.unwrap().mass_kg, 0.2);
}

#[test]
fn truth_survives_a_toml_round_trip() {
    let (truth, _) = paper_truth();
    let text = toml::to_string(&truth).unwrap();
    let again = parse_truth(&text, Path::new("again.toml")).unwrap();
    assert_eq!(again, truth);
    // Order of the deviations is the file's (Table 3's), not alphabetical.
    assert_eq!(again.deviations.first().unwrap().0, "dalpha0");
}

/// The fixture's text with `from` replaced by `to` (which must occur).
fn edited(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(reference("truth.toml")).expect("the fixture is readable");
    assert!(text.contains(from), "{from:?} not in the fixture");
    text.replacen(from, to, 1)
}

fn parse_err(text: &str) -> String {
    parse_truth(text, Path::new("t.toml"))
        .expect_err("the edited text is invalid")
        .to_string()
}

/// 1-based line of the first occurrence of `needle` in `text`.
fn line_of(text: &str, needle: &str) -> usize {
    (text.lines().position(|l| l.contains(needle))).expect("the needle is in the text") + 1
}

/// The error of the fixture with `from` replaced by `to`, and the 1-based line of the first
/// occurrence of `needle` in the edited text.
fn error_at(from: &str, to: &str, needle: &str) -> (String, usize) {
    let text = edited(from, to);
    (parse_err(&text), line_of(&text, needle))
}

#[test]
fn reader_errors_name_file_line_and_column() {
    let (err, line) = error_at("dl3_m = 0.0", "dl3_mm = 0.0", "dl3_mm");
    assert!(
        err.starts_with(&format!("t.toml:{line}:1: unknown field `dl3_mm`")),
        "{err}"
    );

    let (err, line) = error_at("dd4 = -1.3e-3", "dd4 = nan", "dd4 = nan");
    assert_eq!(
        err,
        format!("t.toml:{line}:7: expected a finite number for \"dd4\", found NaN")
    );

    let (err, line) = error_at("dtheta3 = ", "dtheat3 = ", "dtheat3");
    assert!(
        err.starts_with(&format!(
            "t.toml:{line}:1: \"dtheat3\" is not a parameter name"
        )),
        "{err}"
    );

    let text = edited("joint = 3", "joint = 2");
    let line = (text.lines().enumerate())
        .filter(|(_, l)| *l == "joint = 2")
        .nth(1)
        .unwrap()
        .0
        + 1;
    assert_eq!(
        parse_err(&text),
        format!("t.toml:{line}:9: a second [[capstan]] for joint 2")
    );

    let (err, line) = error_at("joint = 1", "joint = 0", "joint = 0");
    assert_eq!(
        err,
        format!("t.toml:{line}:9: capstan joint numbers are 1-based; found 0")
    );

    let (err, line) = error_at("re = 0.015", "re = \"0.015\"", "re = \"0.015\"");
    assert!(err.starts_with(&format!("t.toml:{line}:6: ")), "{err}");

    let text = edited("device = \"device.toml\"", "");
    assert!(parse_err(&text).contains("missing field `device`"));

    let missing = hapcal_sim::read_truth(Path::new("no/such/truth.toml")).unwrap_err();
    assert!(matches!(missing, Error::Io { .. }), "{missing}");
    assert!(
        missing
            .to_string()
            .starts_with("cannot read no/such/truth.toml: ")
    );
}

/// Asserts that the message of `err` starts with `start`.
#[track_caller]
fn assert_starts(err: &impl std::fmt::Display, start: &str) {
    let text = err.to_string();
    assert!(text.starts_with(start), "{text}");
}

#[test]
fn truth_must_match_the_device() {
    let (truth, device) = paper_truth();
    let cfg = SimConfig::new(1, 3).with_noise(NoiseModel::none());
    let theta = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];

    let mut t = truth.clone();
    t.deviations.push(("da9".to_owned(), 1e-3));
    let err = simulate(&device, &t, &cfg).unwrap_err();
    assert_starts(
        &err,
        "deviation \"da9\" is not a parameter of the chain; the chain has da0, dalpha0, dd0, dtheta0, da1",
    );

    let mut t = truth.clone();
    t.capstans.retain(|c| c.joint != 2);
    let err = true_joint_angles(&device, &t, &theta).unwrap_err();
    assert_eq!(
        err.to_string(),
        "the device has a capstan on joint 2 but the truth has no [[capstan]] for it"
    );

    let mut t = truth.clone();
    let mut extra = t.capstans[0];
    extra.joint = 5;
    t.capstans.push(extra);
    let err = simulate(&device, &t, &cfg).unwrap_err();
    assert_eq!(
        err.to_string(),
        "the truth has a [[capstan]] for joint 5 but the device has no capstan there"
    );

    let mut t = truth.clone();
    t.parallelogram = None;
    let err = simulate(&device, &t, &cfg).unwrap_err();
    assert_eq!(
        err.to_string(),
        "parallelogram on joint 4: the truth has no [parallelogram]"
    );

    let mut t = truth.clone();
    t.capstans[2].r_o_m = 0.07; // beyond the 0.06 m drum distance
    let err = simulate(&device, &t, &cfg).unwrap_err();
    assert_starts(&err, "transmission of joint 3: r_o_m = 0.07 m");

    // A crank of 0.2 m on a 0.21 m ground cannot reach round with a 0.05 m rocker.
    let mut t = truth.clone();
    t.parallelogram.as_mut().unwrap().dl1_m = 0.15;
    let err = true_joint_angles(&device, &t, &theta).unwrap_err();
    assert_starts(
        &err,
        "transmission of joint 4: the four-bar loop cannot close",
    );

    let err = true_joint_angles(&device, &truth, &theta[..6]).unwrap_err();
    assert_eq!(
        err.to_string(),
        "expected 7 joint readings (as the device has joints), found 6"
    );
}

#[test]
fn nominal_truth_has_no_errors() {
    let (_, device) = paper_truth();
    let truth = Truth::nominal("device.toml".into(), &device);
    assert!(truth.deviations.is_empty());
    assert_eq!(truth.capstans.len(), 4);
    let p = truth.parallelogram.unwrap();
    assert_eq!(p.phi0_rad, Joint4Transmission::phi0_mid_range_rad(0.3, 1.8));
    let theta = [0.5, 0.2, -0.3, 1.7, 1.0, -1.0, 2.0];
    let q = true_joint_angles(&device, &truth, &theta).unwrap();
    for (a, b) in q.iter().zip(theta) {
        assert!((a - b).abs() < 1e-12, "{q:?} vs {theta:?}");
    }
}
