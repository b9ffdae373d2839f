//! The serial-arm blind test on a few fixed cases (positions data, fewer rows than the full
//! run so that it takes seconds): clean data and an outside effect must give `none`, gravity
//! compliance and backlash must be named.

use hapcal_studies::arm_blind::{
    ArmCase, ArmCaseKind, ArmData, ArmRobot, Injected, load_setup, run_case,
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
            ));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}
