//! `cargo xtask blind-test-arm`: the blind test of the serial-arm diagnosis on simulated URDF
//! robots (crates/studies/src/arm_blind.rs, release build) into
//! docs/results/diagnose-arm-blind.md; with `--setup-check`, the setup check of every
//! positions case, printed.

use anyhow::Result;
use xshell::{Shell, cmd};

/// Runs `cases` blind cases and writes the report; with `setup_check`, prints the setup
/// check's sweep over their positions cases instead.
pub(crate) fn run(sh: &Shell, cases: usize, setup_check: bool) -> Result<()> {
    let cases = cases.to_string();
    if setup_check {
        let text = cmd!(
            sh,
            "cargo run --release --quiet -p hapcal-studies --bin arm-blind -- --cases {cases} --setup-check"
        )
        .read()?;
        println!("{text}");
        return Ok(());
    }
    let md = cmd!(
        sh,
        "cargo run --release --quiet -p hapcal-studies --bin arm-blind -- --cases {cases}"
    )
    .read()?;
    sh.write_file("docs/results/diagnose-arm-blind.md", format!("{md}\n"))?;
    println!("wrote docs/results/diagnose-arm-blind.md");
    Ok(())
}
