//! `cargo xtask bench --scale`: the command line on long haptic logs. Each size's log is
//! written by `hapcal simulate` (the reference device's truth, seed 7), then `check`,
//! `calibrate --model auto`, `predict` and `diagnose` run on it under `/usr/bin/time -v`:
//! wall time, CPU time and peak RSS, per row, and a straight line fitted through the sizes
//! (time and memory against rows). It writes the section "Commands on long logs" of
//! docs/results/bench.md (the rest of the page is `cargo xtask bench`'s). A benchmark, never a
//! test: the figures depend on the machine and its load, which the section gives.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use xshell::{Shell, cmd};

/// The heading of the section this task writes in docs/results/bench.md.
pub(crate) const SECTION: &str = "## Commands on long logs";

/// What the section says below its table: where the time and the memory go.
const EXPLAINED: &str = "
`check` reads the log as a stream and keeps only the rows it judges; its memory past the
executable's is the repeat detector's hash table. `calibrate --model auto` judges its ladder
on at most 20,000 rows spread over a longer log (`hapcal_calibrate::fit::LADDER_ROWS`,
docs/engine.md \"Long logs\") and fits the chosen model on every row; its memory past that
is the log's rows as read and their winsorized copy, and the fits stream their Jacobians in
row blocks past 4,000,000 entries. `diagnose` diagnoses at most 10,000 rows, one in `s`
(`hapcal_diagnose::DiagnoseConfig::max_rows`; its candidates' columns take about 57 kB a
row), and says so in its notes. Wall time is CPU time stretched by the load given above.
";

/// One command's run: wall and CPU seconds, peak resident memory in MB.
struct Run {
    wall_s: f64,
    cpu_s: f64,
    peak_mb: f64,
}

/// Runs `program args` under `/usr/bin/time -v`, its output to `log`.
fn measured(sh: &Shell, program: &Path, args: &[String], log: &Path) -> Result<Run> {
    let out = cmd!(sh, "/usr/bin/time -v {program} {args...}")
        .ignore_status()
        .output()?;
    std::fs::write(log, &out.stdout)?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        bail!("{} {} failed:\n{stderr}", program.display(), args.join(" "));
    }
    let field = |name: &str| {
        stderr
            .lines()
            .find_map(|l| l.trim().strip_prefix(name))
            .map(str::trim)
            .with_context(|| format!("no \"{name}\" in the output of /usr/bin/time -v"))
    };
    let seconds = |name: &str| -> Result<f64> { Ok(field(name)?.parse()?) };
    // "Elapsed (wall clock) time (h:mm:ss or m:ss): 0:01.23"
    let wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss):")?;
    let wall_s = wall
        .split(':')
        .try_fold(0.0, |acc, part| part.parse::<f64>().map(|v| acc * 60.0 + v))?;
    Ok(Run {
        wall_s,
        cpu_s: seconds("User time (seconds):")? + seconds("System time (seconds):")?,
        peak_mb: field("Maximum resident set size (kbytes):")?.parse::<f64>()? / 1024.0,
    })
}

/// Least-squares line `y = a + b·x`: (a, b).
fn line(points: &[(f64, f64)]) -> (f64, f64) {
    let n = points.len() as f64;
    let (sx, sy) = points
        .iter()
        .fold((0.0, 0.0), |(sx, sy), (x, y)| (sx + x, sy + y));
    let (mx, my) = (sx / n, sy / n);
    let sxx: f64 = points.iter().map(|(x, _)| (x - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { f64::NAN };
    (my - b * mx, b)
}

/// Runs the scale benchmark at `rows` (data rows of each log) and writes its section of
/// docs/results/bench.md.
pub(crate) fn run(sh: &Shell, rows: &[usize]) -> Result<()> {
    let target =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| PathBuf::from("target"), PathBuf::from);
    cmd!(sh, "cargo build --release --quiet -p hapcal --bin hapcal").run()?;
    let hapcal = sh.current_dir().join(target.join("release/hapcal"));
    let dir = sh.current_dir().join(target.join("bench-scale"));
    sh.create_dir(&dir)?;
    let device = "fixtures/reference-device/device.toml";
    let truth = "fixtures/reference-device/truth.toml";
    let load_before = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let date = cmd!(sh, "date -u +%Y-%m-%dT%H:%MZ").read()?;
    let commands = ["check", "calibrate --model auto", "predict", "diagnose"];
    // runs[c][s]: command c at size s.
    let mut runs: Vec<Vec<Run>> = commands.iter().map(|_| Vec::new()).collect();
    for &n in rows {
        let log = dir.join(format!("log-{n}.csv"));
        if !log.exists() {
            let poses = n.to_string();
            cmd!(
                sh,
                "{hapcal} simulate --truth {truth} --seed 7 --poses {poses} --out {log}"
            )
            .quiet()
            .run()?;
        }
        let calibrated = dir.join(format!("calibrated-{n}.toml"));
        let _ = std::fs::remove_file(&calibrated);
        let s = |p: &Path| p.display().to_string();
        let args: [Vec<String>; 4] = [
            vec![
                "check".into(),
                "--device".into(),
                device.into(),
                "--data".into(),
                s(&log),
            ],
            vec![
                "calibrate".into(),
                "--device".into(),
                device.into(),
                "--data".into(),
                s(&log),
                "--model".into(),
                "auto".into(),
                "--out".into(),
                s(&calibrated),
            ],
            vec![
                "predict".into(),
                "--device".into(),
                s(&calibrated),
                "--data".into(),
                s(&log),
                "--out".into(),
                s(&dir.join(format!("predicted-{n}.csv"))),
            ],
            vec![
                "diagnose".into(),
                "--device".into(),
                device.into(),
                "--data".into(),
                s(&log),
            ],
        ];
        for (c, args) in args.iter().enumerate() {
            let out = dir.join(format!("{}-{n}.txt", args[0]));
            let run = measured(sh, &hapcal, args, &out)?;
            println!(
                "{n} rows, {}: {:.2} s wall, {:.2} s CPU, {:.0} MB",
                commands[c], run.wall_s, run.cpu_s, run.peak_mb
            );
            runs[c].push(run);
        }
    }
    let load_after = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = |s: &str| s.split_whitespace().take(3).collect::<Vec<_>>().join(" ");
    let sizes: Vec<String> = rows.iter().map(usize::to_string).collect();
    let mut md = format!(
        "{SECTION}\n\n`cargo xtask bench --scale --rows {}` ({date}, {cores} cores, load {} before \
         and {} after): logs of the reference device written by `hapcal simulate --truth {truth} \
         --seed 7 --poses N` (13 columns, about 234 bytes a row), each command of the release \
         `hapcal` run once under `/usr/bin/time -v` (wall and CPU time, peak resident memory). \
         `calibrate` writes the device file `predict` then reads. The last two columns are the \
         slope of a straight line fitted through the sizes: what one more row costs.\n\n\
         | command | rows | wall | CPU | peak RSS | bytes a row | µs a row (wall) | slope: µs a row | slope: bytes a row |\n\
         |---|---|---|---|---|---|---|---|---|\n",
        sizes.join(","),
        load(&load_before),
        load(&load_after)
    );
    for (c, command) in commands.iter().enumerate() {
        let time = line(
            &(rows.iter().zip(&runs[c]))
                .map(|(&n, r)| (n as f64, r.wall_s))
                .collect::<Vec<_>>(),
        );
        let memory = line(
            &(rows.iter().zip(&runs[c]))
                .map(|(&n, r)| (n as f64, r.peak_mb * 1024.0 * 1024.0))
                .collect::<Vec<_>>(),
        );
        for (i, (&n, r)) in rows.iter().zip(&runs[c]).enumerate() {
            let slopes = if i == 0 {
                format!("{:.1} | {:.0}", time.1 * 1e6, memory.1)
            } else {
                "|".to_owned()
            };
            md.push_str(&format!(
                "| `{command}` | {n} | {:.2} s | {:.2} s | {:.0} MB | {:.0} | {:.1} | {slopes} |\n",
                r.wall_s,
                r.cpu_s,
                r.peak_mb,
                r.peak_mb * 1024.0 * 1024.0 / n as f64,
                r.wall_s * 1e6 / n as f64,
            ));
        }
    }
    md.push_str(EXPLAINED);
    let page = sh.current_dir().join("docs/results/bench.md");
    let before = std::fs::read_to_string(&page).unwrap_or_default();
    let kept = before
        .find(SECTION)
        .map_or(before.as_str(), |i| &before[..i]);
    std::fs::write(&page, format!("{}\n\n{md}", kept.trim_end()))?;
    println!("wrote {}", page.display());
    Ok(())
}
