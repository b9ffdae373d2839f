//! `cargo xtask bench --scale`: the command line on long recordings of both kinds. Each size's
//! haptic log is written by `hapcal simulate` (the reference device's truth, seed 7), each
//! size's marker file by the simulated two-arm humanoid (`sim_humanoid --rows N`, streamed,
//! seed 12); then `check`, `calibrate --model auto`, `predict` and `diagnose` run on it (on a
//! marker file also `compensate` and `plan-poses --data`, [`command_args`]) under
//! `/usr/bin/time -v`: wall time, CPU time and peak RSS, per row, and a straight line fitted
//! through the sizes (time and memory against rows). It writes the section "Commands on long
//! logs" of docs/results/bench.md (the rest of the page is `cargo xtask bench`'s). A
//! benchmark, never a test: the figures depend on the machine and its load, which the section
//! gives.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use xshell::{Shell, cmd};

/// The heading of the section this task writes in docs/results/bench.md.
pub(crate) const SECTION: &str = "## Commands on long logs";

/// What the section says below the haptic logs' table: where the time and the memory go.
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

/// What the section says below the marker files' table: where the time and the memory go.
const EXPLAINED_MARKERS: &str = "
On a marker file, `check` reads every row and checks it, and keeps every `s`-th row (at most
20,000, the ladder's sample, `hapcal_calibrate::fit::ladder_sample`) for the setup check to
judge, so its memory past the executable's is the repeat detector's hash table and the sample;
its findings still name file:line. `calibrate --model auto` judges its ladder on that sample
and fits the chosen model on every row, after the Huber loss has bounded the gross errors of
every row; the report says \"model choice by 5-fold cross-validation on N rows spread over the
training data\". Its memory past that is the file's rows as read (17 joint readings and two
markers: a few hundred bytes a row) and the fits on every row.
";

/// The simulated humanoid's URDF and tips (fixtures/sim-humanoid).
const HUMANOID: &str = "fixtures/sim-humanoid/humanoid.urdf";

/// Joint columns of the simulated humanoid's marker files (the first columns), then the left
/// hand's marker `x1, y1, z1`.
const HUMANOID_JOINTS: usize = 17;

/// Workspace configurations `plan-poses --data` plans for: the first rows' joint readings.
const WORKSPACE_ROWS: usize = 50;

/// A kind of recording the benchmark measures.
#[derive(Clone, Copy)]
enum Kind {
    /// A haptic log of the reference device (`hapcal simulate`).
    Haptic,
    /// A motion-capture marker file of the simulated humanoid (`sim_humanoid --rows`).
    Markers,
}

/// The commands measured on the recording `data` of `kind`, in the table's order: each one's
/// name in the table and its arguments; `n` names the files the commands write under `dir`.
/// `calibrate` writes the calibrated device that `predict` and `compensate` read. A haptic
/// device has no `compensate` (its commands are forces, `hapcal force`) and no `plan-poses
/// --data` (its poses are planned without data).
fn command_args(kind: Kind, data: &Path, dir: &Path, n: usize) -> Vec<(&'static str, Vec<String>)> {
    let s = |p: &Path| p.display().to_string();
    let v = |args: &[&str]| {
        args.iter()
            .map(|a| (*a).to_owned())
            .collect::<Vec<String>>()
    };
    let data = s(data);
    match kind {
        Kind::Haptic => {
            let device = "fixtures/reference-device/device.toml";
            let calibrated = s(&dir.join(format!("calibrated-{n}.toml")));
            let predicted = s(&dir.join(format!("predicted-{n}.csv")));
            vec![
                ("check", v(&["check", "--device", device, "--data", &data])),
                (
                    "calibrate --model auto",
                    v(&[
                        "calibrate",
                        "--device",
                        device,
                        "--data",
                        &data,
                        "--model",
                        "auto",
                        "--out",
                        &calibrated,
                    ]),
                ),
                (
                    "predict",
                    v(&[
                        "predict",
                        "--device",
                        &calibrated,
                        "--data",
                        &data,
                        "--out",
                        &predicted,
                    ]),
                ),
                (
                    "diagnose",
                    v(&["diagnose", "--device", device, "--data", &data]),
                ),
            ]
        }
        Kind::Markers => {
            let tips = ["--tip", "l_hand", "--tip", "r_hand"];
            let calibrated = s(&dir.join(format!("humanoid-calibrated-{n}.urdf")));
            let predicted = s(&dir.join(format!("humanoid-predicted-{n}.csv")));
            let commands = s(&dir.join(format!("humanoid-commands-{n}.csv")));
            let targets = s(&dir.join(format!("humanoid-targets-{n}.csv")));
            let one_marker = s(&dir.join(format!("humanoid-left-{n}.csv")));
            let workspace = s(&dir.join("humanoid-workspace.csv"));
            let with = |head: &[&str], tail: &[&str]| {
                let mut args = v(head);
                args.extend(v(&tips));
                args.extend(v(tail));
                args
            };
            vec![
                (
                    "check",
                    with(&["check", "--device", HUMANOID], &["--data", &data]),
                ),
                (
                    "calibrate --model auto",
                    with(
                        &["calibrate", "--device", HUMANOID],
                        &[
                            "--data",
                            &data,
                            "--test-last",
                            "0.3",
                            "--model",
                            "auto",
                            "--out",
                            &calibrated,
                        ],
                    ),
                ),
                (
                    "predict",
                    with(
                        &["predict", "--device", &calibrated],
                        &["--data", &data, "--out", &predicted],
                    ),
                ),
                (
                    "diagnose",
                    with(
                        &["diagnose", "--device", HUMANOID],
                        &["--data", &data, "--test-last", "0.3"],
                    ),
                ),
                (
                    "compensate",
                    v(&[
                        "compensate",
                        "--device",
                        &calibrated,
                        "--tip",
                        "l_hand",
                        "--other-tip",
                        "r_hand",
                        "--instrument-frame",
                        "--targets",
                        &targets,
                        "--out",
                        &commands,
                    ]),
                ),
                (
                    "plan-poses --data",
                    v(&[
                        "plan-poses",
                        "--device",
                        HUMANOID,
                        "--tip",
                        "l_hand",
                        "--data",
                        &one_marker,
                        "--workspace",
                        &workspace,
                        "--count",
                        "10",
                    ]),
                ),
            ]
        }
    }
}

/// The files the marker commands read beside the marker file `data` (`n` rows), written
/// from it under `dir` unless they exist: `compensate`'s targets (each row's joint readings,
/// its start, and the left hand's marker as the target `x, y, z`, in the instrument frame),
/// `plan-poses --data`'s one-marker file (the joint readings and the left hand's marker: it
/// plans for one tip) and its workspace (the first rows' joint readings).
fn write_marker_inputs(data: &Path, dir: &Path, n: usize) -> Result<()> {
    use std::io::{BufRead, BufWriter, Write};
    let targets = dir.join(format!("humanoid-targets-{n}.csv"));
    let one_marker = dir.join(format!("humanoid-left-{n}.csv"));
    let workspace = dir.join("humanoid-workspace.csv");
    if targets.exists() && one_marker.exists() && workspace.exists() {
        return Ok(());
    }
    let reader = std::io::BufReader::new(std::fs::File::open(data)?);
    let mut t = BufWriter::new(std::fs::File::create(&targets)?);
    let mut o = BufWriter::new(std::fs::File::create(&one_marker)?);
    let mut w = BufWriter::new(std::fs::File::create(&workspace)?);
    for (i, line) in reader.lines().enumerate() {
        let line = line?;
        let cells: Vec<&str> = line.split(',').collect();
        if cells.len() < HUMANOID_JOINTS + 3 {
            bail!(
                "{}:{}: fewer than {} columns",
                data.display(),
                i + 1,
                HUMANOID_JOINTS + 3
            );
        }
        let (joints, marker) = (
            &cells[..HUMANOID_JOINTS],
            &cells[HUMANOID_JOINTS..HUMANOID_JOINTS + 3],
        );
        let target = if i == 0 {
            vec!["x", "y", "z"]
        } else {
            marker.to_vec()
        };
        writeln!(t, "{},{}", joints.join(","), target.join(","))?;
        writeln!(o, "{},{}", joints.join(","), marker.join(","))?;
        if i <= WORKSPACE_ROWS {
            writeln!(w, "{}", joints.join(","))?;
        }
    }
    for mut f in [t, o, w] {
        f.flush()?;
    }
    Ok(())
}

/// Writes the recording of `kind` with `n` data rows to `path`, unless it exists.
fn write_recording(
    sh: &Shell,
    kind: Kind,
    hapcal: &Path,
    generator: &Path,
    path: &Path,
    n: usize,
) -> Result<()> {
    if path.exists() {
        return Ok(());
    }
    let rows = n.to_string();
    match kind {
        Kind::Haptic => {
            let truth = "fixtures/reference-device/truth.toml";
            cmd!(
                sh,
                "{hapcal} simulate --truth {truth} --seed 7 --poses {rows} --out {path}"
            )
            .quiet()
            .run()?;
        }
        Kind::Markers => {
            let folder = path.with_extension("d");
            cmd!(sh, "{generator} --rows {rows} {folder}")
                .quiet()
                .run()?;
            std::fs::rename(folder.join("mocap.csv"), path)?;
            std::fs::remove_dir_all(&folder)?;
        }
    }
    Ok(())
}

/// The commands measured on recordings of `kind` ([`command_args`]) and their runs
/// (`runs[c][s]`: command `c` at size `s`).
fn measure_kind(
    sh: &Shell,
    kind: Kind,
    (hapcal, generator): (&Path, &Path),
    dir: &Path,
    rows: &[usize],
) -> Result<(Vec<&'static str>, Vec<Vec<Run>>)> {
    let mut runs: Vec<Vec<Run>> = Vec::new();
    let mut names = Vec::new();
    let stem = match kind {
        Kind::Haptic => "log",
        Kind::Markers => "humanoid",
    };
    for &n in rows {
        let data = dir.join(format!("{stem}-{n}.csv"));
        write_recording(sh, kind, hapcal, generator, &data, n)?;
        if let Kind::Markers = kind {
            write_marker_inputs(&data, dir, n)?;
        }
        let commands = command_args(kind, &data, dir, n);
        runs.resize_with(commands.len(), Vec::new);
        names = commands.iter().map(|(name, _)| *name).collect();
        for (c, (name, args)) in commands.iter().enumerate() {
            let out = dir.join(format!("{stem}-{}-{n}.txt", args[0]));
            let run = measured(sh, hapcal, args, &out)?;
            println!(
                "{stem}, {n} rows, {name}: {:.2} s wall, {:.2} s CPU, {:.0} MB",
                run.wall_s, run.cpu_s, run.peak_mb
            );
            runs[c].push(run);
        }
    }
    Ok((names, runs))
}

/// The table of `runs` at `rows`: each command at each size, and the slopes of the lines
/// fitted through the sizes.
fn table(rows: &[usize], (names, runs): &(Vec<&str>, Vec<Vec<Run>>)) -> String {
    let mut md = String::from(
        "| command | rows | wall | CPU | peak RSS | bytes a row | µs a row (wall) | slope: µs a row | slope: bytes a row |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for (c, command) in names.iter().enumerate() {
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
    md
}

/// Runs the scale benchmark at `rows` (data rows of each recording) and writes its section of
/// docs/results/bench.md.
pub(crate) fn run(sh: &Shell, rows: &[usize]) -> Result<()> {
    let target =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| PathBuf::from("target"), PathBuf::from);
    cmd!(sh, "cargo build --release --quiet -p hapcal --bin hapcal").run()?;
    cmd!(
        sh,
        "cargo build --release --quiet -p hapcal-calibrate --example sim_humanoid"
    )
    .run()?;
    let hapcal = sh.current_dir().join(target.join("release/hapcal"));
    let generator = sh
        .current_dir()
        .join(target.join("release/examples/sim_humanoid"));
    let dir = sh.current_dir().join(target.join("bench-scale"));
    sh.create_dir(&dir)?;
    let load_before = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let date = cmd!(sh, "date -u +%Y-%m-%dT%H:%MZ").read()?;
    let programs = (hapcal.as_path(), generator.as_path());
    let haptic = measure_kind(sh, Kind::Haptic, programs, &dir, rows)?;
    let markers = measure_kind(sh, Kind::Markers, programs, &dir, rows)?;
    let load_after = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = |s: &str| s.split_whitespace().take(3).collect::<Vec<_>>().join(" ");
    let sizes: Vec<String> = rows.iter().map(usize::to_string).collect();
    let md = format!(
        "{SECTION}\n\n`cargo xtask bench --scale --rows {}` ({date}, {cores} cores, load {} before \
         and {} after): each command of the release `hapcal` run once under `/usr/bin/time -v` \
         (wall and CPU time, peak resident memory). `calibrate` writes the calibrated device \
         `predict` then reads. The last two columns are the slope of a straight line fitted \
         through the sizes: what one more row costs.\n\n\
         ### Haptic logs\n\n\
         Logs of the reference device written by `hapcal simulate --truth \
         fixtures/reference-device/truth.toml --seed 7 --poses N` (13 columns, about 234 bytes a \
         row).\n\n{}{EXPLAINED}\n\
         ### Marker files\n\n\
         Motion-capture files of the simulated two-arm humanoid written by `cargo run --release \
         -p hapcal-calibrate --example sim_humanoid -- --rows N <folder>` (17 joint readings and \
         two markers, 23 columns, about 280 bytes a row; fixtures/sim-humanoid), the commands \
         with `--device {HUMANOID} --tip l_hand --tip r_hand`, `calibrate` and `diagnose` with \
         `--test-last 0.3`; `compensate` with the calibrated URDF, `--tip l_hand --other-tip \
         r_hand --instrument-frame`, its targets each row's left-hand marker (the row's joint \
         readings its start); `plan-poses --data` on the joint readings and the left hand's \
         marker alone, `--tip l_hand --count 10`, for the first {WORKSPACE_ROWS} rows' \
         configurations as the workspace.\n\n{}{EXPLAINED_MARKERS}",
        sizes.join(","),
        load(&load_before),
        load(&load_after),
        table(rows, &haptic),
        table(rows, &markers),
    );
    let page = sh.current_dir().join("docs/results/bench.md");
    let before = std::fs::read_to_string(&page).unwrap_or_default();
    let kept = before
        .find(SECTION)
        .map_or(before.as_str(), |i| &before[..i]);
    std::fs::write(&page, format!("{}\n\n{md}", kept.trim_end()))?;
    println!("wrote {}", page.display());
    Ok(())
}
