//! `tree-blind [--cases N] [--rows N] [--json FILE]`: the blind test of the serial-arm
//! diagnosis on the simulated two-arm humanoid ([`hapcal_studies::tree_blind`]); the Markdown
//! report on stdout, progress on stderr.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line report

use anyhow::{Context, Result};
use hapcal_studies::tree_blind;

fn main() -> Result<()> {
    let mut cases: u64 = 64;
    let mut rows = tree_blind::N_ROWS;
    let mut json: Option<String> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--cases" => cases = value()?.parse().context("--cases")?,
            "--rows" => rows = value()?.parse().context("--rows")?,
            "--json" => json = Some(value()?),
            other => anyhow::bail!("unknown argument {other:?}"),
        }
    }
    let total = cases as usize;
    let outcomes = tree_blind::run(cases, rows, &|done| {
        eprint!("\r{done}/{total} cases");
    })?;
    eprintln!();
    if let Some(path) = json {
        std::fs::write(&path, serde_json::to_string_pretty(&outcomes)?)
            .with_context(|| format!("writing {path}"))?;
    }
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
