//! `setup-hostile --hapcal BIN --work DIR [--half tuning|held-back|all] [--cases-per-family N]
//! [--jobs N] [--list]`: the hostile sweep of setup mistakes ([`hapcal_studies::setup_hostile`]).
//! Writes each case into `DIR`, runs `BIN calibrate … --out DIR/<case>/cal.toml` on it
//! (`--jobs` at a time, default 2), and prints the Markdown report on stdout; progress on
//! stderr. `--list` prints the cases' halves and identities instead.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line report

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use hapcal_studies::setup_hostile::{
    CaseResult, DEFAULT_CASES_PER_FAMILY, Half, Sources, cases, judge, report_markdown,
    what_was_said, write_case,
};

fn main() -> Result<()> {
    let mut hapcal: Option<PathBuf> = None;
    let mut work: Option<PathBuf> = None;
    let mut half: Option<Half> = None;
    let mut per_family = DEFAULT_CASES_PER_FAMILY;
    let mut jobs = 2usize;
    let mut list = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--hapcal" => hapcal = Some(value()?.into()),
            "--work" => work = Some(value()?.into()),
            "--half" => {
                half = match value()?.as_str() {
                    "tuning" => Some(Half::Tuning),
                    "held-back" => Some(Half::HeldBack),
                    "all" => None,
                    other => bail!("--half: expected tuning, held-back or all, found {other:?}"),
                }
            }
            "--cases-per-family" => {
                per_family = value()?.parse().context("--cases-per-family")?;
            }
            "--jobs" => jobs = value()?.parse().context("--jobs")?,
            "--list" => list = true,
            other => bail!("unknown argument {other:?}"),
        }
    }
    if list {
        for c in cases(per_family)
            .iter()
            .filter(|c| half.is_none_or(|h| c.half == h))
        {
            println!("{} {}", c.half.name(), c.id);
        }
        return Ok(());
    }
    let hapcal = hapcal.context("--hapcal BIN is required")?;
    let work = work.context("--work DIR is required")?;
    // Absolute, so that the report can name the files relative to it.
    let root = hapcal_studies::project_root();
    let root = if root.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        root
    };
    let root = std::fs::canonicalize(&root).with_context(|| format!("{}", root.display()))?;
    let sources = Sources::load(&root)?;
    let selected: Vec<_> = (cases(per_family).into_iter())
        .filter(|c| half.is_none_or(|h| c.half == h))
        .collect();
    if work.exists() {
        std::fs::remove_dir_all(&work).with_context(|| format!("clearing {}", work.display()))?;
    }
    let n = selected.len();
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<CaseResult>>> = Mutex::new(vec![None; n]);
    let errors: Mutex<Vec<String>> = Mutex::new(Vec::new());
    let started = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(case) = selected.get(i) else { break };
                    let dir = work.join(case.id.replace('/', "__"));
                    match run_case(case, &sources, &dir, &hapcal, &root) {
                        Ok(r) => {
                            if let Ok(mut v) = results.lock() {
                                v[i] = Some(r);
                            }
                        }
                        Err(e) => {
                            if let Ok(mut v) = errors.lock() {
                                v.push(format!("{}: {e:#}", case.id));
                            }
                        }
                    }
                    let k = done.fetch_add(1, Ordering::SeqCst) + 1;
                    eprint!("\r{k}/{n} cases, {:.0} s", started.elapsed().as_secs_f64());
                }
            });
        }
    });
    eprintln!();
    let errors = errors.into_inner().unwrap_or_default();
    if !errors.is_empty() {
        bail!("cases that could not be written:\n{}", errors.join("\n"));
    }
    let results: Vec<CaseResult> = (results.into_inner().unwrap_or_default().into_iter())
        .flatten()
        .collect();
    let machine = std::env::var("SETUP_HOSTILE_MACHINE").unwrap_or_else(|_| "2 cores".into());
    let half_arg = half.map_or("all", Half::name);
    let command =
        format!("cargo xtask setup-hostile --half {half_arg} --cases-per-family {per_family}");
    let minutes = started.elapsed().as_secs_f64() / 60.0;
    let machine = format!("{machine}; {n} cases in {minutes:.1} min, {jobs} at a time");
    println!("{}", report_markdown(&results, &command, &machine));
    Ok(())
}

/// Writes and runs one case; the case's folder is left for inspection.
fn run_case(
    case: &hapcal_studies::setup_hostile::Case,
    sources: &Sources,
    dir: &Path,
    hapcal: &Path,
    root: &Path,
) -> Result<CaseResult> {
    let simulate = |args: &[String]| -> Result<()> {
        let out = Command::new(hapcal)
            .arg("simulate")
            .args(args)
            .output()
            .with_context(|| format!("running {}", hapcal.display()))?;
        if !out.status.success() {
            bail!(
                "hapcal simulate {}: {}",
                args.join(" "),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        Ok(())
    };
    let inv = write_case(case, sources, dir, &simulate)?;
    let t0 = Instant::now();
    let out = Command::new(hapcal)
        .arg("calibrate")
        .args(&inv.args)
        .arg("--out")
        .arg(dir.join("cal.toml"))
        .output()
        .with_context(|| format!("running {}", hapcal.display()))?;
    let seconds = t0.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&out.stderr);
    std::fs::write(dir.join("stderr.txt"), stderr.as_bytes())?;
    std::fs::write(dir.join("args.txt"), inv.args.join(" "))?;
    let code = out.status.code();
    // Paths of the case's files are this machine's: the report names the case instead.
    let root = format!("{}/", root.display());
    let said = (what_was_said(&stderr).replace(&format!("{}/", dir.display()), "<case>/"))
        .replace(&root, "");
    Ok(CaseResult {
        case: case.clone(),
        outcome: judge(case.family, &inv.fix_words, code, &stderr),
        code,
        said,
        seconds,
    })
}
