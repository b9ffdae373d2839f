//! `setup-hostile --hapcal BIN --work DIR [--half tuning|held-back|all] [--cases-per-family N]
//! [--jobs N] [--list]`: the hostile sweep of setup mistakes ([`hapcal_studies::setup_hostile`]).
//! Writes each case into `DIR`, runs `BIN calibrate … --out DIR/<case>/cal.toml` on it
//! (`--jobs` at a time, default 2), screens each mistake for visibility (the screening fit,
//! `--accept-setup --model …  --json`, of the mistaken data and of its correct twin, written
//! once per twin under `DIR/correct`), and prints the Markdown report on stdout; progress on
//! stderr. `--list` prints the cases' halves and identities instead.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line report

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use hapcal_studies::setup_hostile::{
    Case, CaseResult, DEFAULT_CASES_PER_FAMILY, FixApplied, Half, Residual, Sources, Visibility,
    cases, correct_twin, fix_flags, judge, report_markdown, screening_args, stop_fix, twin_key,
    what_was_said, with_fix, write_case,
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
    let started = Instant::now();
    // The correct twins first, once per key: the screening fit of the data without the
    // mistake.
    let mut twins: BTreeMap<String, Case> = BTreeMap::new();
    for c in selected.iter().filter(|c| !c.family.is_correct()) {
        twins.entry(twin_key(c)).or_insert_with(|| correct_twin(c));
    }
    let twins: Vec<Case> = twins.into_values().collect();
    let n_twins = twins.len();
    let twin_fits = parallel(&twins, jobs, "correct twins", started, |twin| {
        let dir = work.join("correct").join(twin.id.replace('/', "__"));
        let inv = write_case(twin, &sources, &dir, &|args: &[String]| {
            simulate(&hapcal, args)
        })
        .with_context(|| twin.id.clone())?;
        Ok(screen(twin, &inv.args, &dir, &hapcal, &root))
    })
    .context("writing the correct twins")?;
    let correct: BTreeMap<String, std::result::Result<Residual, String>> = (twins.iter())
        .map(|t| t.id.clone())
        .zip(twin_fits)
        .collect();
    let n = selected.len();
    let results = parallel(&selected, jobs, "cases", started, |case| {
        let dir = work.join(case.id.replace('/', "__"));
        let twin = correct
            .get(&twin_key(case))
            .cloned()
            .unwrap_or_else(|| Err("no correct twin".to_owned()));
        run_case(case, &sources, &dir, &hapcal, &root, &twin).with_context(|| case.id.clone())
    })?;
    let machine = std::env::var("SETUP_HOSTILE_MACHINE").unwrap_or_else(|_| "2 cores".into());
    let half_arg = half.map_or("all", Half::name);
    let command =
        format!("cargo xtask setup-hostile --half {half_arg} --cases-per-family {per_family}");
    let minutes = started.elapsed().as_secs_f64() / 60.0;
    let machine = format!(
        "{machine}; {n} cases and {n_twins} correct twins in {minutes:.1} min, {jobs} at a time"
    );
    println!("{}", report_markdown(&results, &command, &machine));
    Ok(())
}

/// Runs `f` on every item, `jobs` at a time, in item order; progress on standard error.
///
/// # Errors
/// Every item `f` failed on, one line each.
fn parallel<T: Sync, U: Send>(
    items: &[T],
    jobs: usize,
    what: &str,
    started: Instant,
    f: impl Fn(&T) -> Result<U> + Sync,
) -> Result<Vec<U>> {
    let n = items.len();
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<U>>> = Mutex::new((0..n).map(|_| None).collect());
    let errors: Mutex<Vec<String>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(item) = items.get(i) else { break };
                    match f(item) {
                        Ok(r) => {
                            if let Ok(mut v) = results.lock() {
                                v[i] = Some(r);
                            }
                        }
                        Err(e) => {
                            if let Ok(mut v) = errors.lock() {
                                v.push(format!("{e:#}"));
                            }
                        }
                    }
                    let k = done.fetch_add(1, Ordering::SeqCst) + 1;
                    eprint!("\r{k}/{n} {what}, {:.0} s", started.elapsed().as_secs_f64());
                }
            });
        }
    });
    eprintln!();
    let errors = errors.into_inner().unwrap_or_default();
    if !errors.is_empty() {
        bail!("{what} that could not be written:\n{}", errors.join("\n"));
    }
    Ok((results.into_inner().unwrap_or_default().into_iter())
        .flatten()
        .collect())
}

/// Runs `hapcal simulate` with `args`.
fn simulate(hapcal: &Path, args: &[String]) -> Result<()> {
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
}

/// The message of a run for the report, with this machine's paths of the case's files
/// replaced by `<case>/` and the project root left out.
fn anonymous(text: &str, dir: &Path, root: &Path) -> String {
    (text.replace(&format!("{}/", dir.display()), "<case>/"))
        .replace(&format!("{}/", root.display()), "")
}

/// The screening fit of a written case ([`screening_args`]): its training residual, or the
/// first error line when the command gives no report.
fn screen(
    case: &Case,
    args: &[String],
    dir: &Path,
    hapcal: &Path,
    root: &Path,
) -> std::result::Result<Residual, String> {
    let out = Command::new(hapcal)
        .arg("calibrate")
        .args(args)
        .args(screening_args(case.recording))
        .output()
        .map_err(|e| format!("running {}: {e}", hapcal.display()))?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    let _ = std::fs::write(dir.join("screen-stderr.txt"), stderr.as_bytes());
    let _ = std::fs::write(dir.join("screen.json"), &out.stdout);
    // Without a report, the command's error (the setup lines before it were accepted).
    let error = (stderr.lines())
        .find_map(|l| l.split_once("error: ").map(|(_, e)| e.to_owned()))
        .unwrap_or_else(|| what_was_said(&stderr));
    Residual::from_report_json(&String::from_utf8_lossy(&out.stdout)).map_err(|e| {
        let why = if error.is_empty() {
            e.to_string()
        } else {
            error
        };
        anonymous(&why, dir, root)
    })
}

/// Writes and runs one case, then its screening fit; the case's folder is left for
/// inspection.
fn run_case(
    case: &Case,
    sources: &Sources,
    dir: &Path,
    hapcal: &Path,
    root: &Path,
    twin: &std::result::Result<Residual, String>,
) -> Result<CaseResult> {
    let inv = write_case(case, sources, dir, &|args: &[String]| {
        simulate(hapcal, args)
    })?;
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
    let stopped = code != Some(0) && code != Some(1);
    // Every flag a stop prints is applied and the command rerun: a fix that stops again
    // harms.
    let flags = stop_fix(&stderr).map(|f| fix_flags(&f)).unwrap_or_default();
    let applied = if stopped && !flags.is_empty() {
        let fixed_args = with_fix(&inv.args, &flags);
        let again = Command::new(hapcal)
            .arg("calibrate")
            .args(&fixed_args)
            .arg("--out")
            .arg(dir.join("cal-fixed.toml"))
            .output()
            .with_context(|| format!("running {}", hapcal.display()))?;
        std::fs::write(dir.join("fixed-args.txt"), fixed_args.join(" "))?;
        std::fs::write(dir.join("fixed-stderr.txt"), &again.stderr)?;
        if matches!(again.status.code(), Some(0 | 1)) {
            FixApplied::Ran
        } else {
            FixApplied::StoppedAgain
        }
    } else {
        FixApplied::NotApplicable
    };
    let output = format!("{stderr}\n{}", String::from_utf8_lossy(&out.stdout));
    let visibility = if case.family.is_correct() {
        Visibility::NotScreened
    } else {
        Visibility::screen(&screen(case, &inv.args, dir, hapcal, root), twin)
    };
    Ok(CaseResult {
        case: case.clone(),
        outcome: judge(
            case.family,
            (&inv.fix_words, &inv.locate_words),
            code,
            &output,
            applied,
        ),
        code,
        // Paths of the case's files are this machine's: the report names the case instead.
        said: anonymous(&what_was_said(&stderr), dir, root),
        seconds,
        visibility,
    })
}
