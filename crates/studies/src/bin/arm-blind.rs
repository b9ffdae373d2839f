//! `arm-blind [--cases N] [--rows N] [--folds K] [--json FILE] [--setup-check]`: the blind test
//! of the serial-arm diagnosis ([`hapcal_studies::arm_blind`]); the Markdown report on stdout,
//! progress on stderr. With `--setup-check`, the setup check of every positions case of
//! `0..N` instead ([`hapcal_studies::arm_blind::setup_sweep`]): one line per case with a
//! finding, then the counts.
#![allow(clippy::print_stdout)] // a command-line report

use anyhow::Result;
use hapcal_studies::arm_blind;
use hapcal_studies::blind_cli::BlindArgs;

fn main() -> Result<()> {
    let args = BlindArgs::parse(std::env::args().skip(1), 256, arm_blind::N_POSITIONS, true)?;
    let (cases, rows) = (args.cases, args.rows);
    let mut cfg = hapcal_diagnose::arm::ArmConfig::default();
    if let Some(folds) = args.folds {
        cfg.folds = folds;
    }
    if args.setup_check {
        let sweep = arm_blind::setup_sweep(cases, rows)?;
        println!("{}", sweep.text());
        return Ok(());
    }
    let outcomes = args.run_cases(|progress| arm_blind::run(cases, rows, &cfg, progress))?;
    let machine = std::env::var("ARM_BLIND_MACHINE").unwrap_or_else(|_| "2 cores".into());
    let command = format!("cargo xtask blind-test-arm --cases {cases}");
    println!(
        "{}",
        arm_blind::report_markdown_with(&outcomes, &command, &machine, &cfg)
    );
    Ok(())
}
