//! `cargo xtask haptic-heldout`: the paper's calibration of the reference haptic device from
//! its own logs (no truth file), held out in time. Each seed simulates a time-ordered log
//! (`hapcal simulate --motion`, no unmodelled effect), the first 70 % of its rows train and
//! the rest test, and `hapcal calibrate --device … --data train.csv --test test.csv` runs as a
//! user would run it (two steps, then `--joint`). Writes docs/results/haptic-heldout.md.

use anyhow::{Context, Result, bail};
use serde_json::Value;
use std::fmt::Write;
use xshell::{Shell, cmd};

/// Seeds of the study.
const SEEDS: std::ops::RangeInclusive<u64> = 1..=10;
/// Rows per simulated log.
const POSES: usize = 600;
/// Largest held-out distance RMS accepted, m (the cable encoder's noise is ≈ 10 µm).
const LIMIT_M: f64 = 20e-6;

/// Test distance RMS (m) of a `calibrate --json` report, before and after.
fn test_rms(v: &Value) -> Result<(f64, f64)> {
    let sets = v["placements"]
        .as_array()
        .context("no placements in the report")?;
    let test = (sets.iter())
        .find(|p| p["role"] == "test")
        .context("no test set in the report")?;
    let get = |when: &str| {
        test[when]["distance_rms_m"]
            .as_f64()
            .with_context(|| format!("no {when}.distance_rms_m"))
    };
    Ok((get("before")?, get("after")?))
}

/// Splits the log at `path` into the first 70 % and the rest of its rows.
fn split(text: &str) -> Result<(String, String)> {
    let mut lines = text.lines();
    let header = lines.next().context("empty log")?;
    let rows: Vec<&str> = lines.collect();
    let k = rows.len() * 7 / 10;
    let join = |part: &[&str]| {
        let mut s = String::from(header);
        s.push('\n');
        for r in part {
            s.push_str(r);
            s.push('\n');
        }
        s
    };
    Ok((join(&rows[..k]), join(&rows[k..])))
}

/// Runs the study; with `check`, only verifies the limit.
pub(crate) fn run(sh: &Shell, check: bool) -> Result<()> {
    cmd!(sh, "cargo build --release --quiet -p hapcal").run()?;
    let dir = sh.current_dir().join("target/haptic-heldout");
    sh.create_dir(&dir)?;
    let device = "fixtures/reference-device/device.toml";
    let truth = "fixtures/reference-device/truth.toml";
    let mut rows = Vec::new();
    for seed in SEEDS {
        let log = dir.join(format!("log{seed}.csv"));
        let seed_s = seed.to_string();
        let poses = POSES.to_string();
        cmd!(sh, "cargo run --release --quiet -p hapcal -- simulate --truth {truth} --seed {seed_s} --poses {poses} --motion --out {log}")
            .quiet()
            .run()?;
        let (train, test) = split(&sh.read_file(&log)?)?;
        let (train_path, test_path) = (
            dir.join(format!("train{seed}.csv")),
            dir.join(format!("test{seed}.csv")),
        );
        sh.write_file(&train_path, train)?;
        sh.write_file(&test_path, test)?;
        let mut figures = Vec::new();
        for joint in [None, Some("--joint")] {
            let out = cmd!(sh, "cargo run --release --quiet -p hapcal -- calibrate --device {device} --data {train_path} --test {test_path} --json {joint...}")
                .read()
                .with_context(|| format!("calibrating seed {seed}"))?;
            figures.push(test_rms(&serde_json::from_str(&out)?)?);
        }
        rows.push((seed, figures[0].0, figures[0].1, figures[1].1));
    }
    let worst = rows.iter().map(|r| r.2.max(r.3)).fold(0.0, f64::max);
    if worst > LIMIT_M {
        bail!(
            "held-out distance RMS {:.1} µm exceeds {:.0} µm",
            worst * 1e6,
            LIMIT_M * 1e6
        );
    }
    if check {
        println!(
            "haptic-heldout --check: worst held-out distance RMS {:.1} µm ≤ {:.0} µm",
            worst * 1e6,
            LIMIT_M * 1e6
        );
        return Ok(());
    }
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# The haptic device calibrated from its own logs, held out in time\n"
    );
    let _ = writeln!(
        md,
        "Written by `cargo xtask haptic-heldout` (release build). For each seed, `hapcal simulate --truth {truth} --seed <s> --poses {POSES} --motion` writes a time-ordered log of the reference device (no unmodelled effect); its first 70 % of rows are the training log, the rest the test log. Each is calibrated as a user would, without the truth file: `hapcal calibrate --device {device} --data train.csv --test test.csv` (the paper's two steps: transmissions from the external encoders, then kinematics from the cable distances) and the same with `--joint` (both steps in one problem). Distance RMS on the test rows, µm; the cable encoder's noise is about 10 µm.\n"
    );
    let _ = writeln!(md, "| seed | nominal | two steps | joint |");
    let _ = writeln!(md, "|---|---|---|---|");
    for (seed, before, two, joint) in &rows {
        let _ = writeln!(
            md,
            "| {seed} | {:.1} | {:.1} | {:.1} |",
            before * 1e6,
            two * 1e6,
            joint * 1e6
        );
    }
    let mean = |column: fn(&(u64, f64, f64, f64)) -> f64| {
        rows.iter().map(column).sum::<f64>() / rows.len() as f64
    };
    let _ = writeln!(
        md,
        "| mean | {:.1} | {:.1} | {:.1} |\n\nWorst held-out RMS: {:.1} µm (limit {:.0} µm). These are measured against the logged (noisy) cable distances. The paper pipeline's study on independent random poses (docs/results/paper/README.md, seed 0) gives 5.4 µm on fresh poses measured against the true, noise-free distance; with the cable noise of about 10 µm added in quadrature that is about 11 µm, the level seen here.",
        mean(|r| r.1) * 1e6,
        mean(|r| r.2) * 1e6,
        mean(|r| r.3) * 1e6,
        worst * 1e6,
        LIMIT_M * 1e6
    );
    sh.write_file("docs/results/haptic-heldout.md", md)?;
    println!(
        "wrote docs/results/haptic-heldout.md (worst {:.1} µm)",
        worst * 1e6
    );
    Ok(())
}
