//! Automation for the hapcal workspace (the cargo-xtask pattern): what CI runs, and the
//! reproduction runs that write `docs/results/`.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a task runner reports on the terminal

mod bench;
mod mukca;

use anyhow::Result;
use clap::Parser;
use std::path::PathBuf;
use xshell::{Shell, cmd};

#[derive(Parser)]
enum Task {
    /// fmt, clippy, tests, docs, one release `reproduce-tables --check`: what CI runs.
    Ci,
    /// Reproduce the paper's tables (release build) into docs/results/paper; `--check` compares
    /// with fixtures/golden/ours/paper.csv instead (UPDATE_GOLDEN=1 rewrites it and fails).
    ReproduceTables {
        /// Compare instead of writing.
        #[arg(long)]
        check: bool,
    },
    /// Calibrate every MUKCa split of docs/results/mukca.md with the release binary and write
    /// the table (ours beside MUKCa's own optimiser); `--check` only verifies the acceptance
    /// criteria against the committed reference figures.
    Mukca {
        /// Compare instead of writing.
        #[arg(long)]
        check: bool,
    },
    /// Scale benchmarks (reference device at 200 to 1,000,000 poses, the 1,000-device fleet)
    /// into docs/results/bench.md; `--peers` adds SciPy least_squares (lm, trf) on the same
    /// data files, in a virtual environment under the target directory.
    Bench {
        /// Also run SciPy on the same problems.
        #[arg(long)]
        peers: bool,
        /// Also run the criterion benchmarks (`cargo bench -p hapcal-identify --bench scale`).
        #[arg(long)]
        criterion: bool,
    },
}

fn project_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn main() -> Result<()> {
    let sh = Shell::new()?;
    sh.change_dir(project_root());
    match Task::parse() {
        Task::Ci => ci(&sh),
        Task::Mukca { check } => mukca::run(&sh, check),
        Task::Bench { peers, criterion } => bench::run(&sh, peers, criterion),
        Task::ReproduceTables { check } => reproduce_tables(&sh, check),
    }
}

fn ci(sh: &Shell) -> Result<()> {
    cmd!(sh, "cargo fmt --all --check").run()?;
    cmd!(
        sh,
        "cargo clippy --workspace --all-targets --quiet -- -D warnings"
    )
    .run()?;
    cmd!(sh, "cargo test --workspace --quiet").run()?;
    cmd!(sh, "cargo doc --workspace --no-deps --quiet")
        .env("RUSTDOCFLAGS", "-D warnings")
        .run()?;
    reproduce_tables(sh, true)
}

fn reproduce_tables(sh: &Shell, check: bool) -> Result<()> {
    if check {
        cmd!(
            sh,
            "cargo run --release --quiet -p hapcal -- reproduce --check"
        )
        .run()?;
    } else {
        cmd!(
            sh,
            "cargo run --release --quiet -p hapcal -- reproduce --out docs/results/paper"
        )
        .run()?;
    }
    Ok(())
}
