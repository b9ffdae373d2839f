//! The setup check's scales and couplings on simulated tracker data of the KUKA LBR iiwa 14
//! (MUKCa's URDF): a joint column read on the motor side of its gear, in encoder counts,
//! through a gear ratio 5 % off, or coupled to another joint is named with its class, its
//! column and its factor or coefficient; the same data without the mistake give no finding.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hapcal_calibrate::measured::Robot;
use hapcal_calibrate::setup::{MistakeClass, SetupInput, SetupReport, check_setup};
use hapcal_io::MeasurementTable;
use rand::SeedableRng;
use rand_distr::Normal;

/// Tracker noise per axis, m.
const NOISE_M: f64 = 1e-4;
/// Rows simulated.
const N_ROWS: usize = 120;

/// Tolerance on an estimated factor or coefficient. Its standard error is about
/// σ / (lever · q_rms · √(3n)) ≈ 1e-4 m / (0.2 m · 1.3 rad · 19) ≈ 2e-5 (the wrist joints
/// move the ball by 0.1 to 0.4 m per rad, the joints sweep 0.8 of their ranges); the 1-D
/// search resolves 1.3e-5 in the factor's logarithm and 8.5e-5 in a coefficient; the flags print
/// three (coupling) and five (free scale) significant digits, at most 5e-4 of a coefficient
/// of 0.1 to 0.5 and 5e-6 of a factor. 2e-3 covers the sum more than three times.
const TOL: f64 = 2e-3;

#[path = "sim/tracker.rs"]
mod tracker;

use tracker::{iiwa as robot, iiwa_urdf as urdf};

/// `N_ROWS` marker positions of the nominal arm in a tracker frame, noise [`NOISE_M`], joint
/// readings edited by `edit` (the mistake).
fn table(robot: &Robot, seed: u64, edit: impl Fn(&mut [f64])) -> MeasurementTable {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let base = tracker::instrument([2.0, 0.3, -0.5], [0.1, -0.05, 2.9]);
    let marker = tracker::marker("marker1", 0.03, -0.02, 0.05);
    let framed = robot.tree.with_frames(&base, &[(0, marker)]).unwrap();
    let x = vec![0.0; framed.n_params()];
    let noise = Normal::new(0.0, NOISE_M).unwrap();
    let rows = (0..N_ROWS)
        .map(|i| {
            let mut q = tracker::within_limits(robot, &mut rng);
            let p = framed.tips()[0].end_point(&x, &q);
            edit(&mut q);
            let marker = tracker::sample(0, &p, &noise, &mut rng);
            tracker::row(i as u64 + 2, q, vec![marker])
        })
        .collect();
    MeasurementTable::positions(format!("seed{seed}"), "tracker.csv", 1, rows)
}

fn check(robot: &Robot, table: &MeasurementTable) -> SetupReport {
    check_setup(&SetupInput {
        robot,
        tables: std::slice::from_ref(table),
        urdf: Some(&urdf()),
        tips: &["ball_link".to_owned()],
        units: hapcal_io::Units::default(),
    })
    .unwrap()
}

/// The error of `report`, which must be of `class` with a fix starting `flag`; the number
/// after it (up to a `*`).
#[track_caller]
fn error_value(report: &SetupReport, class: MistakeClass, flag: &str) -> f64 {
    let f = report
        .overwhelming()
        .unwrap_or_else(|| panic!("{}", report.render()));
    assert_eq!(f.class, class, "{}", report.render());
    let value = f
        .fix
        .strip_prefix(flag)
        .unwrap_or_else(|| panic!("{}", f.fix));
    let value = value.split('*').next().unwrap();
    value.parse().unwrap_or_else(|_| panic!("{}", f.fix))
}

#[test]
fn a_joint_read_times_a_gear_ratio_or_in_encoder_counts_is_named_with_its_factor() {
    let robot = robot();
    let counts = 2f64.powi(17) / std::f64::consts::TAU;
    for (j, k, seed) in [(2, 100.0, 11), (3, counts, 12)] {
        let table = table(&robot, seed, |q| q[j] *= k);
        let report = check(&robot, &table);
        let flag = format!("--column-scale q{}=", j + 1);
        let factor = error_value(&report, MistakeClass::ColumnScale, &flag);
        assert!((factor * k - 1.0).abs() < 1e-9, "{factor} · {k}");
        let f = report.overwhelming().unwrap();
        let words = format!("q{} reads {:.0} × the joint angle", j + 1, k);
        assert!(f.message.contains(&words), "{}", f.message);
    }
}

#[test]
fn a_gear_ratio_five_per_cent_off_is_estimated() {
    let robot = robot();
    let table = table(&robot, 13, |q| q[1] *= 1.05);
    let report = check(&robot, &table);
    let factor = error_value(&report, MistakeClass::ColumnScale, "--column-scale q2=");
    assert!((factor * 1.05 - 1.0).abs() < TOL, "{factor}");
    let f = report.overwhelming().unwrap();
    assert!(
        f.message
            .contains("q2 reads 1.050 × the joint angle (a gear ratio 5.0 % off?)"),
        "{}",
        f.message
    );
}

#[test]
fn a_coupled_joint_is_named_with_its_coefficient_strong_or_weak() {
    let robot = robot();
    for (c, seed, words) in [
        (0.5, 14, "q6 reads q6 + 0.50·q5"),
        (-0.1, 15, "q6 reads q6 − 0.10·q5"),
    ] {
        let table = table(&robot, seed, |q| q[5] += c * q[4]);
        let report = check(&robot, &table);
        let coef = error_value(
            &report,
            MistakeClass::ColumnCoupling,
            "--column-coupling q6=",
        );
        assert!((coef + c).abs() < TOL, "{coef} for {c}");
        let f = report.overwhelming().unwrap();
        assert!(f.fix.ends_with("*q5"), "{}", f.fix);
        assert!(f.message.contains(words), "{}", f.message);
    }
}

#[test]
fn a_column_in_degrees_keeps_its_unit_class() {
    let robot = robot();
    let table = table(&robot, 16, |q| q[2] = q[2].to_degrees());
    let report = check(&robot, &table);
    let f = report.overwhelming().expect("an error");
    assert_eq!(f.class, MistakeClass::ColumnUnit, "{}", report.render());
    assert_eq!(f.fix, "--column-unit q3=deg");
}

#[test]
fn the_same_data_without_the_mistake_give_no_finding() {
    let robot = robot();
    for seed in 11..=16 {
        let table = table(&robot, seed, |_| {});
        tracker::assert_no_setup_finding(&robot, &table, &urdf(), &["ball_link".to_owned()]);
    }
}
