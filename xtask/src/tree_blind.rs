//! `cargo xtask blind-test-tree`: the blind test of the serial-arm diagnosis on the simulated
//! two-arm humanoid (crates/studies/src/tree_blind.rs, release build) into
//! docs/results/diagnose-tree-blind.md.

use anyhow::Result;
use xshell::{Shell, cmd};

/// Runs `cases` blind cases and writes the report.
pub(crate) fn run(sh: &Shell, cases: usize) -> Result<()> {
    let cases = cases.to_string();
    let md = cmd!(
        sh,
        "cargo run --release --quiet -p hapcal-studies --bin tree-blind -- --cases {cases}"
    )
    .read()?;
    sh.write_file("docs/results/diagnose-tree-blind.md", format!("{md}\n"))?;
    println!("wrote docs/results/diagnose-tree-blind.md");
    Ok(())
}
