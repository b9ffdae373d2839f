//! `arm-blind [--cases N] [--rows N] [--folds K] [--json FILE] [--setup-check]`: the blind test
//! of the serial-arm diagnosis ([`hapcal_studies::arm_blind`]); the Markdown report on stdout,
//! progress on stderr. With `--setup-check`, the setup check of every positions case of
//! `0..N` instead ([`hapcal_studies::arm_blind::setup_sweep`]): one line per case with a
//! finding, then the counts.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line report

use anyhow::{Context, Result};
use hapcal_studies::arm_blind;

fn main() -> Result<()> {
    let mut cases: u64 = 256;
    let mut rows = arm_blind::N_POSITIONS;
    let mut json: Option<String> = None;
    let mut setup_check = false;
    let mut cfg = hapcal_diagnose::arm::ArmConfig::default();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--cases" => cases = value()?.parse().context("--cases")?,
            "--rows" => rows = value()?.parse().context("--rows")?,
            "--json" => json = Some(value()?),
            "--folds" => cfg.folds = value()?.parse().context("--folds")?,
            "--setup-check" => setup_check = true,
            other => anyhow::bail!("unknown argument {other:?}"),
        }
    }
    let total = cases as usize;
    if setup_check {
        let sweep = arm_blind::setup_sweep(cases, rows)?;
        println!("{}", sweep.text());
        return Ok(());
    }
    let outcomes = arm_blind::run(cases, rows, &cfg, &|done| {
        eprint!("\r{done}/{total} cases");
    })?;
    eprintln!();
    if let Some(path) = json {
        std::fs::write(&path, serde_json::to_string_pretty(&outcomes)?)
            .with_context(|| format!("writing {path}"))?;
    }
    let machine = std::env::var("ARM_BLIND_MACHINE").unwrap_or_else(|_| "2 cores".into());
    let command = format!("cargo xtask blind-test-arm --cases {cases}");
    println!(
        "{}",
        arm_blind::report_markdown_with(&outcomes, &command, &machine, &cfg)
    );
    Ok(())
}
