//! `tree-blind [--cases N] [--rows N] [--json FILE]`: the blind test of the serial-arm
//! diagnosis on the simulated two-arm humanoid ([`hapcal_studies::tree_blind`]); the Markdown
//! report on stdout, progress on stderr.
#![allow(clippy::print_stdout)] // a command-line report

use anyhow::Result;
use hapcal_studies::blind_cli::BlindArgs;
use hapcal_studies::tree_blind;

fn main() -> Result<()> {
    let args = BlindArgs::parse(std::env::args().skip(1), 64, tree_blind::N_ROWS, false)?;
    let (cases, rows) = (args.cases, args.rows);
    let outcomes = args.run_cases(|progress| tree_blind::run(cases, rows, progress))?;
    let machine = std::env::var("TREE_BLIND_MACHINE").unwrap_or_else(|_| "2 cores".into());
    let rows_flag = if rows == tree_blind::N_ROWS {
        String::new()
    } else {
        format!(" --rows {rows}")
    };
    let command = format!("cargo xtask blind-test-tree --cases {cases}{rows_flag}");
    // The arms' limits (the widest joints of the humanoid).
    let setup = tree_blind::load_setup()?;
    let arm_limit_rad = (setup.robot.limits.iter())
        .map(|(lo, hi)| lo.abs().max(hi.abs()))
        .fold(0.0, f64::max);
    println!(
        "{}",
        tree_blind::report_markdown(&outcomes, arm_limit_rad, &command, &machine, rows)
    );
    Ok(())
}
