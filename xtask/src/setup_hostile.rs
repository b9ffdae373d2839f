//! `cargo xtask setup-hostile`: the hostile sweep of setup mistakes
//! (crates/studies/src/setup_hostile.rs) run through the release `hapcal calibrate`, each
//! mistake screened for visibility by a frames-only fit of it and of its correct twin, into
//! docs/results/setup-hostile.md (or `--out`). Builds in `CARGO_TARGET_DIR` when it is set.

use std::path::{Path, PathBuf};

use anyhow::Result;
use xshell::{Shell, cmd};

/// Builds the release `hapcal`, runs the sweep on `half` (`tuning`, `held-back` or `all`)
/// with `per_family` cases per family, two at a time, and writes the report to `out`.
pub(crate) fn run(sh: &Shell, half: &str, per_family: usize, out: &Path) -> Result<()> {
    cmd!(sh, "cargo build --release --quiet -p hapcal --bin hapcal").run()?;
    let target_dir = std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(|| sh.current_dir().join("target"), PathBuf::from);
    let hapcal = target_dir.join("release").join("hapcal");
    let work = target_dir.join("setup-hostile");
    let per_family = per_family.to_string();
    let md = cmd!(
        sh,
        "cargo run --release --quiet -p hapcal-studies --bin setup-hostile -- --hapcal {hapcal} --work {work} --half {half} --cases-per-family {per_family}"
    )
    .read()?;
    sh.write_file(out, format!("{md}\n"))?;
    println!("wrote {} (cases in {})", out.display(), work.display());
    Ok(())
}
