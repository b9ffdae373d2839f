//! `cargo xtask blind-test-arm`: the blind test of the serial-arm diagnosis on simulated URDF
//! robots (crates/studies/src/arm_blind.rs, release build) into
//! docs/results/diagnose-arm-blind.md.

use anyhow::Result;
use xshell::{Shell, cmd};

/// Runs `cases` blind cases and writes the report.
pub(crate) fn run(sh: &Shell, cases: usize) -> Result<()> {
    let cases = cases.to_string();
    let md = cmd!(
        sh,
        "cargo run --release --quiet -p hapcal-studies --bin arm-blind -- --cases {cases}"
    )
    .read()?;
    sh.write_file("docs/results/diagnose-arm-blind.md", format!("{md}\n"))?;
    println!("wrote docs/results/diagnose-arm-blind.md");
    Ok(())
}
