//! The serial-arm blind test on a few fixed cases (positions data, fewer rows than the full
//! run so that it takes seconds): clean data and an outside effect must give `none`, gravity
//! compliance and backlash must be named; and on the full 200 rows, a drift carried to the
//! held-out rows, a second effect after a dominant first, and the report's names.

use hapcal_contract::Effect;
use hapcal_diagnose::Verdict;
use hapcal_diagnose::arm::{ArmConfig, ArmDiagnosis, diagnose_arm};
use hapcal_studies::arm_blind::{
    ArmCase, ArmCaseKind, ArmData, ArmRobot, Injected, N_POSITIONS, SIGMA_POSITION_M, load_setup,
    run_case, simulate_baseline,
};

/// Rows per case (the full run uses 200).
const ROWS: usize = 60;

fn case(seed: u64, robot: ArmRobot, kind: ArmCaseKind, injected: Injected) -> ArmCase {
    ArmCase {
        seed,
        robot,
        data: ArmData::Positions,
        kind,
        injected,
    }
}

#[test]
fn fixed_positions_cases_get_their_verdicts() {
    let iiwa = load_setup(ArmRobot::Iiwa14).expect("iiwa14 fixtures");
    let panda = load_setup(ArmRobot::Panda).expect("panda fixtures");
    let cases = [
        case(1, ArmRobot::Iiwa14, ArmCaseKind::None, Injected::None),
        case(2, ArmRobot::Panda, ArmCaseKind::None, Injected::None),
        case(
            3,
            ArmRobot::Iiwa14,
            ArmCaseKind::One,
            Injected::GravityCompliance { k: vec![3e-5; 7] },
        ),
        case(
            4,
            ArmRobot::Panda,
            ArmCaseKind::One,
            Injected::Backlash { b: vec![6e-4; 7] },
        ),
        case(
            5,
            ArmRobot::Iiwa14,
            ArmCaseKind::Outside,
            Injected::Coupling {
                j: 3,
                k: 1,
                c: 8e-4,
            },
        ),
        case(
            6,
            ArmRobot::Panda,
            ArmCaseKind::Outside,
            Injected::QuadraticDrift {
                v: [4e-4, -3e-4, 5e-4],
            },
        ),
    ];
    let mut wrong = Vec::new();
    for c in &cases {
        let setup = if c.robot == ArmRobot::Iiwa14 {
            &iiwa
        } else {
            &panda
        };
        let o = run_case(c, setup, ROWS).expect("the case runs");
        if !o.right {
            wrong.push(format!(
                "seed {} {}: expected {}, got {}",
                c.seed,
                c.injected.label(),
                c.expected(),
                o.verdict
                    .as_ref()
                    .map_or_else(|e| format!("error: {e}"), |v| v.to_string())
            ));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// Geometry, noise and the effects of `injected` on the iiwa 14's positions data (200 rows,
/// the last 30 % held out), diagnosed with the default settings.
fn diagnose_iiwa_positions(seed: u64, injected: Injected) -> ArmDiagnosis {
    let setup = load_setup(ArmRobot::Iiwa14).expect("iiwa14 fixtures");
    let kind = match injected {
        Injected::Pair(..) => ArmCaseKind::Two,
        _ => ArmCaseKind::One,
    };
    let c = case(seed, ArmRobot::Iiwa14, kind, injected);
    let baseline = simulate_baseline(&c, &setup, N_POSITIONS).expect("baseline");
    diagnose_arm(&baseline, &ArmConfig::default()).expect("diagnosis")
}

/// The floor of a 3-D position RMS: σ per axis on three axes.
fn floor_3d() -> f64 {
    SIGMA_POSITION_M * 3f64.sqrt()
}

#[test]
fn thermal_drift_fitted_on_the_training_rows_carries_to_the_later_test_rows() {
    // 1.1 mm over the recording: the held-out rows (the last 30 %, recorded after the
    // training rows) lie 0.2–0.5 mm beyond the training's mean position of the drift.
    let d = diagnose_iiwa_positions(
        11,
        Injected::ThermalDrift {
            v: [8e-4, -6e-4, 5e-4],
        },
    );
    assert_eq!(d.verdict, "thermal_drift", "{:#?}", d.candidates);
    let (geometric, named) = (d.test_rms_m[0], d.test_rms_final_m[0]);
    // 60 held-out rows × 3 axes: the RMS's relative standard error is 1/√360 ≈ 5 %; the
    // carried estimate adds its own prediction variance (140 training rows). 1.3 × the floor
    // is six standard errors; a drift referenced to the held-out rows' own time (or left at
    // the training's mean) leaves several floors.
    assert!(
        named < 1.3 * floor_3d(),
        "test RMS with the drift {named}, floor {}",
        floor_3d()
    );
    assert!(geometric > 3.0 * floor_3d(), "test RMS without {geometric}");
}

#[test]
fn a_second_effect_is_judged_by_the_gap_the_first_one_left() {
    // A dominant drift and a gear-ratio error that leaves a small share of the original gap
    // but most of what the drift leaves.
    let d = diagnose_iiwa_positions(
        12,
        Injected::Pair(
            Box::new(Injected::GearRatio {
                s: vec![1.2e-4, -1.2e-4, 1.2e-4, 1.2e-4, -1.2e-4, 1.2e-4, 6e-5],
            }),
            Box::new(Injected::ThermalDrift {
                v: [1.2e-3, -9e-4, 8e-4],
            }),
        ),
    );
    let cfg = ArmConfig::default();
    assert_eq!(d.steps.len(), 2, "{:#?}", d.candidates);
    assert_eq!(d.steps[0].effect, Effect::ThermalDrift);
    assert_eq!(d.steps[1].effect, Effect::GearRatio);
    // The case this is about: the second effect closes less than `min_gap_share` of the gap
    // before the first, and more of the gap the first left.
    assert!(
        d.steps[1].gap_closed_pct < 100.0 * cfg.min_gap_share,
        "{:?}",
        d.steps
    );
    assert!(d.steps[1].round_gap_closed_pct >= 100.0 * cfg.min_gap_share);
    assert_eq!(d.verdict, "thermal_drift+gear_ratio", "{:?}", d.notes);
    // Both named: what is left is the floor (the search stopped there).
    assert!(
        d.heldout_rms_final_m < 1.3 * floor_3d(),
        "{}",
        d.heldout_rms_final_m
    );
}

#[test]
fn the_report_names_cross_validated_and_test_figures_as_such() {
    let d = diagnose_iiwa_positions(13, Injected::None);
    let v = serde_json::to_value(&d).expect("json");
    for key in [
        "cv_rms_m",
        "test_rms_m",
        "cv_rms_final_m",
        "test_rms_final_m",
    ] {
        assert!(v.get(key).is_some(), "no {key}");
    }
    assert!(v.get("heldout_rms_m").is_none());
    let c = &v["candidates"][0];
    assert!(c.get("cv_rms_before_m").is_some() && c.get("cv_rms_after_m").is_some());
    assert_eq!(v["test_rms_m"].as_array().map(Vec::len), Some(1));
}

/// Stepwise revision, on two blind cases the greedy rounds got wrong. Seed 359 (iiwa 14
/// positions, second harmonic + gear ratio): the first round names the first harmonic, which
/// mimics a gear-ratio error over a joint's range; once the gear ratio is named beside it, it
/// no longer earns its place and is left out. Seed 975 (Panda positions, lumped compliance +
/// backlash): the first round names gravity compliance; beside backlash, the lumped torque
/// model predicts better and replaces it.
#[test]
fn effects_named_early_are_checked_again_beside_the_later_ones() {
    for (seed, left_out) in [
        (359, "first_harmonic left out"),
        (975, "gives way to lumped"),
    ] {
        let robot = ArmRobot::ALL[((seed / 8) % 2) as usize];
        let setup = load_setup(robot).expect("fixtures");
        let c = hapcal_studies::arm_blind::draw_case(seed, setup.robot.joint_names.len());
        let baseline = simulate_baseline(&c, &setup, N_POSITIONS).expect("baseline");
        let d = diagnose_arm(&baseline, &ArmConfig::default()).expect("diagnosis");
        assert!(
            c.is_right(&d.verdict),
            "seed {seed}: injected {}, named {} ({:#?})",
            c.injected.label(),
            d.verdict,
            d.notes
        );
        assert!(
            d.notes.iter().any(|n| n.contains(left_out)),
            "seed {seed}: {:#?}",
            d.notes
        );
    }
}

/// The results page's interval: at 0 of n it is `[0, z²/(n + z²)]` (nothing in the standard
/// error), at half it is symmetric about one half.
#[test]
fn the_wilson_interval_has_its_closed_forms() {
    use hapcal_studies::arm_blind::wilson_95;
    let (lo, hi) = wilson_95((0, 32));
    let z2 = 1.959_964f64.powi(2);
    assert!(
        lo == 0.0 && (hi - z2 / (32.0 + z2)).abs() < 1e-12,
        "{lo} {hi}"
    );
    let (lo, hi) = wilson_95((16, 32));
    assert!(
        (lo + hi - 1.0).abs() < 1e-12 && lo > 0.3 && hi < 0.7,
        "{lo} {hi}"
    );
    assert_eq!(wilson_95((0, 0)), (0.0, 1.0));
}

/// The compliance's torque model is named only where the data tell the two models apart. On
/// positions data (the tip moves through the workspace) gravity and lumped compliance predict
/// differently and each blind case names its own model with the other left out (seeds 2 and
/// 3, iiwa 14; seeds 13 and 14, Panda). With the ball held in a socket the tip does not move
/// and the two torques vary together: seed 316 (Panda sockets, lumped compliance) names
/// gravity compliance, by the one-standard-error rule's preference for the link masses, and
/// must say that the lumped model predicts as well.
#[test]
fn the_torque_model_is_named_only_where_the_data_tell_it() {
    for seed in [2, 3, 13, 14, 316] {
        let robot = ArmRobot::ALL[((seed / 8) % 2) as usize];
        let setup = load_setup(robot).expect("fixtures");
        let c = hapcal_studies::arm_blind::draw_case(seed, setup.robot.joint_names.len());
        let baseline = simulate_baseline(&c, &setup, N_POSITIONS).expect("baseline");
        let d = diagnose_arm(&baseline, &ArmConfig::default()).expect("diagnosis");
        let open: Vec<(Effect, Effect)> = (d.steps.iter())
            .flat_map(|s| s.alike.iter().map(|&a| (s.effect, a)))
            .collect();
        let label = c.injected.effect().expect("a library effect");
        if c.data == ArmData::Positions {
            assert_eq!(
                d.verdict.effects(),
                [label],
                "seed {seed}: {:#?}",
                d.candidates
            );
            assert!(open.is_empty(), "seed {seed}: {open:?}");
        } else {
            assert_eq!(
                label,
                Effect::LumpedCompliance,
                "seed {seed}: the draw changed"
            );
            assert_eq!(
                open,
                [(Effect::GravityCompliance, label)],
                "seed {seed}: {:#?}",
                d.candidates
            );
            assert!(!c.is_right(&d.verdict));
            assert!(c.is_right_with(&d.verdict, &open));
        }
    }
}

/// An open torque model stands for the other model of the same compliance, and for nothing
/// else: not for a missing second effect, not for a model the diagnosis did not leave open.
#[test]
fn an_open_torque_model_stands_for_the_other_model_only() {
    let c = ArmCase {
        seed: 0,
        robot: ArmRobot::Panda,
        data: ArmData::Sockets,
        kind: ArmCaseKind::Two,
        injected: Injected::Pair(
            Box::new(Injected::LumpedCompliance { k: vec![1e-3; 7] }),
            Box::new(Injected::Harmonic {
                h: 2,
                a: vec![1e-4; 7],
                b: vec![0.0; 7],
            }),
        ),
    };
    use Effect::{FirstHarmonic, GravityCompliance, LumpedCompliance, SecondHarmonic};
    let open = [(GravityCompliance, LumpedCompliance)];
    assert!(c.is_right(&Verdict::of(&[SecondHarmonic, LumpedCompliance])));
    assert!(!c.is_right(&Verdict::of(&[GravityCompliance, SecondHarmonic])));
    assert!(c.is_right_with(&Verdict::of(&[GravityCompliance, SecondHarmonic]), &open));
    assert!(!c.is_right_with(&Verdict::of(&[GravityCompliance]), &open));
    assert!(!c.is_right_with(&Verdict::of(&[GravityCompliance, FirstHarmonic]), &open));
    let reversed = [(LumpedCompliance, GravityCompliance)];
    assert!(!c.is_right_with(
        &Verdict::of(&[GravityCompliance, SecondHarmonic]),
        &reversed
    ));
}
