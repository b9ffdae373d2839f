//! Runs blind arm cases and prints every candidate of every round: `cargo run --release -p
//! hapcal-studies --example arm_cases -- SEED [SEED …]`.
#![allow(clippy::print_stdout)] // an example prints its results

use hapcal_diagnose::arm::{ArmConfig, diagnose_arm};
use hapcal_studies::arm_blind::{self, ArmRobot};

fn main() -> anyhow::Result<()> {
    let seeds: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let setups = (ArmRobot::ALL.iter())
        .map(|&r| arm_blind::load_setup(r))
        .collect::<anyhow::Result<Vec<_>>>()?;
    for i in seeds {
        let robot = ArmRobot::ALL[((i / 8) % 2) as usize];
        let setup = &setups[robot as usize];
        let case = arm_blind::draw_case(i, setup.robot.joint_names.len());
        let baseline = arm_blind::simulate_baseline(&case, setup, arm_blind::N_POSITIONS)?;
        let d = diagnose_arm(&baseline, &ArmConfig::default())?;
        println!(
            "seed {i} {} {:?}: injected {} -> {} (held-out {:.1} µm, floor {:.1} µm, final {:.1} µm)",
            robot.name(),
            case.data,
            case.injected.label(),
            d.verdict,
            d.heldout_rms_m * 1e6,
            d.floor_rms_m.unwrap_or(f64::NAN) * 1e6,
            d.heldout_rms_final_m * 1e6
        );
        for c in &d.candidates {
            println!(
                "  r{} {:20} acc {:5} vis {:2} {:8.1} -> {:8.1} µm  z {:6.1} closed {:6.1} % : {}",
                c.round,
                c.effect,
                c.accepted,
                c.n_visible,
                c.heldout_rms_before_m * 1e6,
                c.heldout_rms_after_m * 1e6,
                c.heldout_improvement.0 / c.heldout_improvement.1,
                c.gap_closed_pct,
                c.reason
            );
            if c.effect.is_joint_compliance() && std::env::var_os("PARAMS").is_some() {
                let z: Vec<String> = (c.parameters.iter())
                    .map(|p| format!("{:.1}", p.value / p.std))
                    .collect();
                println!("       value/std: {}", z.join(" "));
            }
        }
        for n in &d.notes {
            println!("  note: {n}");
        }
    }
    Ok(())
}
