//! `cargo xtask deny`: `cargo deny check` (deny.toml) over the workspace: licences, sources,
//! duplicate versions, and the RustSec advisories when their database can be fetched.
//! Installs `cargo-deny` (`cargo install --locked`) on first use; not part of `cargo xtask ci`,
//! whose time budget the installation would exceed on a fresh machine.

use anyhow::{Context, Result};
use xshell::{Shell, cmd};

/// Runs the checks; the advisories check is skipped, and said so, when it cannot fetch the
/// database (no network).
pub(crate) fn run(sh: &Shell) -> Result<()> {
    if cmd!(sh, "cargo deny --version")
        .quiet()
        .ignore_stderr()
        .read()
        .is_err()
    {
        println!("deny: installing cargo-deny");
        cmd!(sh, "cargo install --locked cargo-deny")
            .run()
            .context("installing cargo-deny")?;
    }
    cmd!(sh, "cargo deny --all-features check licenses bans sources")
        .run()
        .context("cargo deny: licences, bans or sources")?;
    if cmd!(sh, "cargo deny check advisories").run().is_err() {
        println!(
            "deny: the advisories check failed or could not fetch the RustSec database \
             (see above); rerun with network access"
        );
    }
    Ok(())
}
