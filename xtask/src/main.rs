//! Automation for the hapcal workspace (the cargo-xtask pattern): what CI runs, and the
//! reproduction runs that write `docs/results/`.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a task runner reports on the terminal

mod bench;
mod bench_scale;
mod deny;
mod diagnose_real;
mod haptic;
mod html_check;
mod mukca;
mod real_data;
mod setup_hostile;
mod tidy;

use anyhow::Result;
use clap::Parser;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use xshell::{Shell, cmd};

#[derive(Parser)]
enum Task {
    /// fmt, tidy, clippy, tests (and the vector-kernel crates' again on scalar code), the
    /// library example, docs, then `reproduce-tables --check`, `real-data --check` and
    /// `diagnose-real --check` with the release binary: what CI runs (the Python bindings are
    /// built and tested by .ci/run).
    Ci,
    /// Reproduce the paper's tables (release build) into docs/results/paper (100 seeds) and
    /// docs/results/paper/seeds-1000 (1000 seeds) and docs/results/paper/planned-d-optimal
    /// (D-optimal identification poses); `--check` compares the 100-seed run
    /// with fixtures/golden/ours/paper.csv instead (UPDATE_GOLDEN=1 rewrites it and fails).
    ReproduceTables {
        /// Compare instead of writing.
        #[arg(long)]
        check: bool,
    },
    /// Blind test of `hapcal diagnose` (release build): simulate `--cases` logs with a withheld
    /// effect (or none), diagnose them, write the confusion matrix and the paper's story to
    /// docs/results/diagnose.md.
    BlindTest {
        /// Number of cases.
        #[arg(long, default_value_t = 240)]
        cases: usize,
    },
    /// Blind test of the serial-arm diagnosis (release build): `--cases` simulated iiwa 14
    /// and Panda data sets (positions and sockets) with a withheld effect (or none), into
    /// docs/results/diagnose-arm-blind.md.
    BlindTestArm {
        /// Number of cases (≥ 100 for the report).
        #[arg(long, default_value_t = 256)]
        cases: usize,
        /// Run the setup check on every positions case instead and print its findings and
        /// counts (nothing is written).
        #[arg(long)]
        setup_check: bool,
    },
    /// Blind test of the serial-arm diagnosis on a two-arm tree (release build): `--cases`
    /// simulated humanoid recordings (crates/studies/src/tree_blind.rs) with a withheld
    /// effect (or none), into docs/results/diagnose-tree-blind.md.
    BlindTestTree {
        /// Number of cases (at least 16 per class: none, one, two, outside in turn).
        #[arg(long, default_value_t = 64)]
        cases: usize,
    },
    /// Calibrate every MUKCa split of docs/results/mukca.md with the release binary and write
    /// the table (ours beside MUKCa's own optimiser); `--check` only verifies the acceptance
    /// criteria against the committed reference figures.
    Mukca {
        /// Compare instead of writing.
        #[arg(long)]
        check: bool,
    },
    /// The reference haptic device calibrated from its own time-ordered logs (no truth file),
    /// first 70 % of the rows train, the rest test, into docs/results/haptic-heldout.md;
    /// `--check` only verifies the held-out limit.
    HapticHeldout {
        /// Verify instead of writing.
        #[arg(long)]
        check: bool,
    },
    /// `hapcal calibrate` on the real recordings in fixtures/ (70 % train, 30 % test in file
    /// order) into docs/results/real-data.md; `--check` verifies that no calibrated model is
    /// worse than frames only on its test rows, without writing.
    RealData {
        #[arg(long)]
        check: bool,
    },
    /// `hapcal diagnose` on the real recordings in fixtures/ (MUKCa units, UR10, TIAGo, the
    /// positioner) into docs/results/diagnose-real.md and the residual maps beside it;
    /// `--check` verifies the required verdicts (kuka_14: gravity compliance; panda_6,
    /// panda_7: none) without writing.
    DiagnoseReal {
        #[arg(long)]
        check: bool,
    },
    /// The HTML reports (`--report`) of the bundled calibrations, a diagnosis and a prediction
    /// opened in headless Chromium: fails on a console error, a figure of zero size, text that
    /// overflows its box, a missing figure, or kuka_14's figures differing from
    /// fixtures/golden/ours/html-kuka_14.json (UPDATE_GOLDEN=1 rewrites it and fails).
    HtmlCheck {
        /// Also write the README's PNGs (docs/figures/report-*.png).
        #[arg(long)]
        figures: bool,
    },
    /// The hostile sweep of setup mistakes (crates/studies/src/setup_hostile.rs): mistakes
    /// the setup check was not built on, written into the bundled and simulated recordings,
    /// run through the release `hapcal calibrate` and judged by its exit code and standard
    /// error, into docs/results/setup-hostile.md.
    SetupHostile {
        /// Which half of the cases: tuning, held-back or all.
        #[arg(long, default_value = "all", value_parser = ["tuning", "held-back", "all"])]
        half: String,
        /// Cases per mistake family (and per kind of correct data).
        #[arg(long, default_value_t = 16)]
        cases_per_family: usize,
        /// The report.
        #[arg(long, default_value = "docs/results/setup-hostile.md")]
        out: PathBuf,
    },
    /// `cargo deny check` (deny.toml): licences, sources, duplicate versions and, with network
    /// access, the RustSec advisories; installs cargo-deny on first use.
    Deny,
    /// The property tests with fresh random seeds (CI pins the seed): run it to look for
    /// failures CI cannot find; each failure is saved in its crate's proptest-regressions/.
    ProptestFresh,
    /// Checks over the tracked files: no absolute paths of the build machine, no development
    /// history (issue numbers and the like), real crate descriptions, relative
    /// Markdown links that resolve, no duplicated fixture or test data (see xtask/src/tidy.rs).
    Tidy,
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
        /// Instead, the command line on long haptic logs and marker files (`check`,
        /// `calibrate --model auto`, `predict`, `diagnose`): time and peak memory per row,
        /// into the section "Commands on long logs" of docs/results/bench.md
        /// (xtask/src/bench_scale.rs).
        #[arg(long)]
        scale: bool,
        /// With `--scale`: the numbers of rows of the logs and marker files.
        #[arg(long, value_delimiter = ',', default_value = "10000,100000,1000000")]
        rows: Vec<usize>,
    },
}

/// Seed of the property tests in CI (`PROPTEST_RNG_SEED`).
const PROPTEST_CI_SEED: &str = "1122";

fn project_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn main() -> Result<()> {
    let sh = Shell::new()?;
    sh.change_dir(project_root());
    match Task::parse() {
        Task::Ci => ci(&sh),
        Task::Mukca { check } => mukca::run(&sh, check),
        Task::HapticHeldout { check } => haptic::run(&sh, check),
        Task::RealData { check } => real_data::run(&sh, check, None),
        Task::HtmlCheck { figures } => html_check::run(&sh, None, figures),
        Task::ProptestFresh => {
            cmd!(sh, "cargo test --workspace --release --quiet")
                .env_remove("PROPTEST_RNG_SEED")
                .run()?;
            Ok(())
        }
        Task::Tidy => tidy::run(&sh),
        Task::Deny => deny::run(&sh),
        Task::SetupHostile {
            half,
            cases_per_family,
            out,
        } => setup_hostile::run(&sh, &half, cases_per_family, &out),
        Task::DiagnoseReal { check } => diagnose_real::run(&sh, check, None),
        Task::Bench {
            scale: true, rows, ..
        } => bench_scale::run(&sh, &rows),
        Task::Bench {
            peers, criterion, ..
        } => bench::run(&sh, peers, criterion),
        Task::BlindTest { cases } => blind_test(&sh, cases),
        Task::BlindTestArm { cases, setup_check } => {
            let (cases, page) = (cases.to_string(), "docs/results/diagnose-arm-blind.md");
            let check = setup_check.then_some("--setup-check");
            study_page(&sh, "arm-blind", &["--cases", &cases], check, page)
        }
        Task::BlindTestTree { cases } => {
            let (cases, page) = (cases.to_string(), "docs/results/diagnose-tree-blind.md");
            study_page(&sh, "tree-blind", &["--cases", &cases], None, page)
        }
        Task::ReproduceTables { check } => reproduce_tables(&sh, check, None),
    }
}

/// The crates whose vector kernels also run on scalar code in CI (`HAPCAL_SIMD=off`).
const SCALAR_CRATES: [&str; 3] = ["hapcal-identify", "hapcal-kinematics", "hapcal-problems"];

fn ci(sh: &Shell) -> Result<()> {
    cmd!(sh, "cargo fmt --all --check").run()?;
    tidy::run(sh)?;
    // The Python bindings are left out of clippy, tests and docs, as before they joined the
    // workspace: the Python step of .ci/run builds and tests them.
    cmd!(
        sh,
        "cargo clippy --workspace --exclude hapcal-py --all-targets --quiet -- -D warnings"
    )
    .run()?;
    // The runtime's `no_std` claim: its library without `std` (lints included), then inside
    // a `#![no_std]` crate with its own panic handler, which fails to build if std is linked
    // (its own workspace, so that no other member turns `std` back on; the same target
    // directory as the rest).
    cmd!(
        sh,
        "cargo clippy -p hapcal-runtime --no-default-features --lib --quiet -- -D warnings"
    )
    .run()?;
    let target_dir = std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(|| sh.current_dir().join("target"), PathBuf::from);
    cmd!(
        sh,
        "cargo build --locked --quiet --manifest-path crates/runtime/no-std-check/Cargo.toml --target-dir {target_dir}"
    )
    .run()?;
    // Property tests with a fixed seed: a red CI is a regression, never bad luck
    // (`cargo xtask proptest-fresh` runs them with fresh seeds).
    cmd!(sh, "cargo test --workspace --exclude hapcal-py --quiet")
        .env("PROPTEST_RNG_SEED", PROPTEST_CI_SEED)
        .run()?;
    // Every executable of that build (nothing is compiled again). Cargo resolves dependency
    // features over the packages a command selects, so `cargo test -p` of fewer packages, or
    // `cargo run -p`, would compile most dependencies a second time: the steps below run these
    // executables instead.
    let built = executables(
        &cmd!(
            sh,
            "cargo test --workspace --exclude hapcal-py --no-run --quiet --message-format=json-render-diagnostics"
        )
        .read()?,
    )?;
    // The same crates on scalar code (the vector kernels give the same bits; this runs the
    // scalar instantiation that machines without AVX2 or NEON take): their test executables as
    // `cargo test` runs them (from the package's directory), then the doctests.
    for exe in built
        .iter()
        .filter(|e| e.test && SCALAR_CRATES.contains(&e.package.as_str()))
    {
        let _dir = sh.push_dir(&exe.package_dir);
        let path = &exe.path;
        cmd!(sh, "{path} --quiet")
            .env("PROPTEST_RNG_SEED", PROPTEST_CI_SEED)
            .env("HAPCAL_SIMD", "off")
            .run()?;
    }
    cmd!(
        sh,
        "cargo test --workspace --exclude hapcal-py --doc --quiet"
    )
    .env("PROPTEST_RNG_SEED", PROPTEST_CI_SEED)
    .env("HAPCAL_SIMD", "off")
    .run()?;
    // The library example, from the test build (debug assertions on).
    let example = find(&built, "hapcal-calibrate", "example", "calibrate_urdf")?;
    cmd!(sh, "{example}").run()?;
    cmd!(
        sh,
        "cargo doc --workspace --exclude hapcal-py --no-deps --quiet"
    )
    .env("RUSTDOCFLAGS", "-D warnings")
    .run()?;
    // The release binary for the checks, with dependency features resolved together with the
    // Python bindings' (only the binary is built): the wheel that .ci/run builds next then
    // reuses every compiled dependency and compiles only PyO3 and the bindings.
    let release = executables(
        &cmd!(
            sh,
            "cargo build --release --quiet -p hapcal -p hapcal-py --bin hapcal --message-format=json-render-diagnostics"
        )
        .read()?,
    )?;
    let hapcal = find(&release, "hapcal", "bin", "hapcal")?;
    reproduce_tables(sh, true, Some(&hapcal))?;
    // The published recordings: no calibrated model worse than frames only held out.
    real_data::run(sh, true, Some(&hapcal))?;
    // The diagnosis of the real robots keeps its verdicts.
    diagnose_real::run(sh, true, Some(&hapcal))?;
    // The HTML reports open in a browser with every figure, kuka_14's figures unchanged.
    html_check::run(sh, Some(&hapcal), false)
}

/// An executable that cargo built: its package, target and path (from `--message-format=json`).
struct Executable {
    /// Package name.
    package: String,
    /// The package's directory (where `cargo test` runs its tests).
    package_dir: PathBuf,
    /// Target kind: `lib`, `bin`, `test`, `example`, `bench`.
    kind: String,
    /// Target name.
    name: String,
    /// Whether it is a test harness (unit or integration tests).
    test: bool,
    path: PathBuf,
}

/// The executables among cargo's JSON messages (one JSON object a line; other lines skipped).
fn executables(messages: &str) -> Result<Vec<Executable>> {
    let mut out = Vec::new();
    for line in messages.lines().filter(|l| l.starts_with('{')) {
        let m: serde_json::Value = serde_json::from_str(line)?;
        let (Some(path), Some(manifest)) = (m["executable"].as_str(), m["manifest_path"].as_str())
        else {
            continue;
        };
        // `path+file:///…/crates/identify#hapcal-identify@0.1.0`, or `…/xtask#0.1.0` when the
        // directory is named after the package.
        let id = m["package_id"].as_str().unwrap_or_default();
        let (url, fragment) = id.rsplit_once('#').unwrap_or((id, ""));
        let package = match fragment.split_once('@') {
            Some((name, _)) => name,
            None => url.rsplit('/').next().unwrap_or_default(),
        };
        out.push(Executable {
            package: package.to_owned(),
            package_dir: PathBuf::from(manifest)
                .parent()
                .map(PathBuf::from)
                .unwrap_or_default(),
            kind: m["target"]["kind"][0]
                .as_str()
                .unwrap_or_default()
                .to_owned(),
            name: m["target"]["name"].as_str().unwrap_or_default().to_owned(),
            test: m["profile"]["test"].as_bool().unwrap_or(false),
            path: PathBuf::from(path),
        });
    }
    Ok(out)
}

/// The path of `package`'s `kind` target `name` among `built`.
fn find(built: &[Executable], package: &str, kind: &str, name: &str) -> Result<PathBuf> {
    built
        .iter()
        .find(|e| e.package == package && e.kind == kind && e.name == name && !e.test)
        .map(|e| e.path.clone())
        .ok_or_else(|| anyhow::anyhow!("cargo built no {kind} {name} of {package}"))
}

/// How the xtask runs the `hapcal` tool: a program and the arguments before hapcal's own;
/// `bin` when given (CI passes the binary it built), else the binary `HAPCAL_BIN` names, else
/// `cargo run --release -p hapcal --`.
fn hapcal_cmd(bin: Option<&Path>) -> (OsString, Vec<OsString>) {
    let from_env = std::env::var_os("HAPCAL_BIN").map(PathBuf::from);
    match bin.map(Path::to_path_buf).or(from_env) {
        Some(bin) => (bin.into(), Vec::new()),
        None => (
            "cargo".into(),
            ["run", "--release", "--quiet", "-p", "hapcal", "--"]
                .map(OsString::from)
                .to_vec(),
        ),
    }
}

/// Runs the release binary `bin` of hapcal-studies with `args` and writes its Markdown report
/// to `page`; with `print_flag` added to `args` instead, prints what it says (nothing is
/// written).
fn study_page(
    sh: &Shell,
    bin: &str,
    args: &[&str],
    print_flag: Option<&str>,
    page: &str,
) -> Result<()> {
    let text = cmd!(
        sh,
        "cargo run --release --quiet -p hapcal-studies --bin {bin} -- {args...} {print_flag...}"
    )
    .read()?;
    if print_flag.is_some() {
        println!("{text}");
    } else {
        sh.write_file(page, format!("{text}\n"))?;
        println!("wrote {page}");
    }
    Ok(())
}

fn blind_test(sh: &Shell, cases: usize) -> Result<()> {
    let cases = cases.to_string();
    let md = cmd!(
        sh,
        "cargo run --release --quiet -p hapcal -- blind-test --cases {cases}"
    )
    .read()?;
    let mukca = "\n## Real robots\n\nSee docs/results/diagnose-real.md (`cargo xtask \
                 diagnose-real`: the MUKCa units and the published marker and pose data).\n";
    sh.write_file("docs/results/diagnose.md", format!("{md}{mukca}"))?;
    println!("wrote docs/results/diagnose.md");
    Ok(())
}

fn reproduce_tables(sh: &Shell, check: bool, bin: Option<&Path>) -> Result<()> {
    if check {
        let (hapcal, pre) = hapcal_cmd(bin);
        cmd!(sh, "{hapcal} {pre...} reproduce --check").run()?;
    } else {
        cmd!(
            sh,
            "cargo run --release --quiet -p hapcal -- reproduce --out docs/results/paper"
        )
        .run()?;
        // The same study over 1000 seeds: coverage and normalised-error SD resolved to ±1.4 %
        // and ±0.02 instead of ±2.2 % and ±0.07 (the honesty of the reported uncertainty).
        cmd!(
            sh,
            "cargo run --release --quiet -p hapcal -- reproduce --seeds 1000 --out docs/results/paper/seeds-1000"
        )
        .run()?;
        // Beyond the paper: the 200 identification poses chosen D-optimally from 2000 random
        // candidates (their joint readings only) instead of taken at random.
        cmd!(
            sh,
            "cargo run --release --quiet -p hapcal -- reproduce --design d-optimal --candidates 2000 --out docs/results/paper/planned-d-optimal"
        )
        .run()?;
    }
    Ok(())
}
