//! `cargo xtask bench [--peers]`: the scale benchmarks, and with `--peers` the same problems
//! on the same data files with SciPy's `least_squares` (methods "lm" and "trf", analytic
//! Jacobian) in a virtual environment this task creates; writes docs/results/bench.md.
//!
//! One run, one machine: the data files are written once by hapcal
//! (`crates/identify/examples/scale.rs write`), then each size is solved by hapcal's release
//! example (`scale solve`) and by `xtask/peers/scipy_peer.py`; the fleet by `examples/fleet.rs`.
//! Peak memory comes from `/usr/bin/time -v`. Wall times are the minimum over repeats.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde_json::Value;
use xshell::{Shell, cmd};

/// Processes that read the peak FLOP rate (the largest reading is used).
const PEAK_PROCESSES: usize = 5;
/// Processes that time the 200-pose LM for the per-iteration cost (the fastest is used; as
/// many as read the peak, since both readings share the machine's process-level modes).
const LM_PROCESSES: usize = 5;
/// The last `cargo xtask bench --peers` with the hand-written AVX-512/AVX2 kernels, for the
/// comparison printed beside this run's figures (docs/results/simd.md).
const HAND_WRITTEN_RUN: &str = "commit 8c9fd35, 2026-11-22, Intel Xeon, 2 cores";
const HAND_WRITTEN_ITERATION_MS: f64 = 0.022;
const HAND_WRITTEN_LM_MS: f64 = 0.151;
const HAND_WRITTEN_SCIPY_LM_MS: f64 = 32.181;
const HAND_WRITTEN_SCIPY_TRF_MS: f64 = 74.207;
/// Pose counts of the table.
const SIZES: [usize; 4] = [200, 2_000, 20_000, 1_000_000];
/// Largest size the peers run at (their dense Jacobian at 1,000,000 poses is 224 MB per copy
/// and MINPACK's QR alone takes minutes).
const PEER_MAX: usize = 20_000;

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| PathBuf::from("target"), PathBuf::from)
}

fn repeats(n: usize) -> usize {
    // Sub-millisecond solves need many repeats for a stable minimum (caches, clock ramp-up).
    match n {
        0..=200 => 2_000,
        201..=2_000 => 50,
        2_001..=20_000 => 3,
        _ => 1,
    }
}

/// Runs `cmd` under `/usr/bin/time -v`; returns stdout and the peak RSS in MB.
fn timed(sh: &Shell, program: &Path, args: &[String]) -> Result<(String, f64)> {
    let out = cmd!(sh, "/usr/bin/time -v {program} {args...}")
        .ignore_status()
        .output()?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        bail!("{} failed:\n{stderr}", program.display());
    }
    let kb: f64 = stderr
        .lines()
        .find_map(|l| l.trim().strip_prefix("Maximum resident set size (kbytes):"))
        .context("no peak RSS in /usr/bin/time output")?
        .trim()
        .parse()?;
    Ok((String::from_utf8(out.stdout)?, kb / 1024.0))
}

fn f(v: &Value, path: &[&str]) -> f64 {
    let mut v = v;
    for p in path {
        v = &v[*p];
    }
    v.as_f64().unwrap_or(f64::NAN)
}

/// Largest |a − b| over the names of `a`'s `x`.
fn max_diff(a: &Value, b: &Value) -> f64 {
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else {
        return f64::NAN;
    };
    a.iter()
        .map(|(k, v)| (v.as_f64().unwrap_or(f64::NAN) - b[k].as_f64().unwrap_or(f64::NAN)).abs())
        .fold(0.0, f64::max)
}

fn ms(s: f64) -> String {
    if s >= 1.0 {
        format!("{:.2} s", s)
    } else {
        format!("{:.3} ms", s * 1e3)
    }
}

/// Runs the benchmarks (criterion unless `quick`), then the table with or without peers.
pub(crate) fn run(sh: &Shell, peers: bool, criterion: bool) -> Result<()> {
    let tools = build_tools(sh, peers)?;
    let machine = Machine::read(sh)?;
    let peak = read_peak(sh, &tools.scale)?;
    let mut md = String::new();
    write_header(&mut md, peers, &machine);
    let sizes = size_table(sh, &tools, &mut md)?;
    if let Some(lm) = &sizes.per_iteration {
        write_per_iteration(&mut md, &peak, lm, &sizes.row_200, &machine.cpu);
    }
    write_fleet(sh, &tools.fleet, &mut md)?;
    finish(sh, md, criterion)
}

/// The programs of the run: hapcal's release examples, the data folder and, with peers, the
/// virtual environment's Python and the SciPy peer script.
struct Tools {
    /// `scale` example (write, peak, solve).
    scale: PathBuf,
    /// `fleet` example.
    fleet: PathBuf,
    /// Folder of the data files (`poses-<n>.csv`).
    data_dir: PathBuf,
    /// The Python with numpy and SciPy, when peers run.
    python: Option<PathBuf>,
    /// `xtask/peers/scipy_peer.py`.
    peer_script: PathBuf,
}

/// Builds hapcal's release examples, creates the data folder and, with `peers`, the virtual
/// environment with numpy and SciPy.
///
/// # Errors
/// A failed build, folder or installation.
fn build_tools(sh: &Shell, peers: bool) -> Result<Tools> {
    let target = target_dir();
    cmd!(
        sh,
        "cargo build --release --quiet -p hapcal-identify --examples"
    )
    .run()?;
    let examples = target.join("release/examples");
    let scale = examples.join("scale");
    let fleet = examples.join("fleet");
    let data_dir = target.join("bench-data");
    sh.create_dir(&data_dir)?;

    let python = if peers {
        let venv = target.join("bench-venv");
        let py = venv.join("bin/python");
        if !py.exists() {
            cmd!(sh, "python3.11 -m venv {venv}").run()?;
        }
        cmd!(sh, "{py} -m pip install --quiet numpy scipy").run()?;
        Some(py)
    } else {
        None
    };
    let peer_script = sh.current_dir().join("xtask/peers/scipy_peer.py");
    Ok(Tools {
        scale,
        fleet,
        data_dir,
        python,
        peer_script,
    })
}

/// The machine the run is on, as the report states it.
struct Machine {
    /// `uname -srm`.
    uname: String,
    /// The CPU's model name (empty if unknown).
    cpu: String,
    /// Available parallelism.
    cores: usize,
    /// `/proc/loadavg` at the start.
    load_before: String,
    /// UTC date and time of the start.
    date: String,
}

impl Machine {
    /// Reads the machine's description and load.
    ///
    /// # Errors
    /// A failed `uname` or `date`.
    fn read(sh: &Shell) -> Result<Machine> {
        let uname = cmd!(sh, "uname -srm").read()?;
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_owned())
            })
            .unwrap_or_default();
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let load_before = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
        let date = cmd!(sh, "date -u +%Y-%m-%dT%H:%MZ").read()?;
        Ok(Machine {
            uname,
            cpu,
            cores,
            load_before,
            date,
        })
    }
}

/// The peak FLOP rate: the largest reading (`scale peak`'s JSON) and every reading (GFLOP/s).
struct Peak {
    /// The reading with the largest `gflops`.
    best: Value,
    /// Every process's `gflops`, in order.
    readings: Vec<f64>,
}

/// The peak FLOP rate: the largest of PEAK_PROCESSES readings, each in its own process.
/// Readings come in two modes (about 37 and 53 GFLOP/s on the development machine) that
/// persist within a process, so one process may miss the peak, and a low peak would flatter
/// the per-iteration ratio.
///
/// # Errors
/// A failed `scale peak` or output that is not JSON.
fn read_peak(sh: &Shell, scale: &Path) -> Result<Peak> {
    let mut peak: Option<Value> = None;
    let mut peak_readings: Vec<f64> = Vec::new();
    for _ in 0..PEAK_PROCESSES {
        let reading: Value = serde_json::from_str(&cmd!(sh, "{scale} peak").read()?)?;
        peak_readings.push(f(&reading, &["gflops"]));
        if peak
            .as_ref()
            .is_none_or(|p| f(&reading, &["gflops"]) > f(p, &["gflops"]))
        {
            peak = Some(reading);
        }
    }
    Ok(Peak {
        best: peak.context("no peak reading")?,
        readings: peak_readings,
    })
}

/// The report's title, the machine and what the problem, the data and the tolerances are,
/// and the head of the size table.
fn write_header(md: &mut String, peers: bool, m: &Machine) {
    let Machine {
        uname,
        cpu,
        cores,
        load_before,
        date,
    } = m;
    md.push_str("# Speed and scale against peers\n\n");
    md.push_str(&format!(
        "Written by `cargo xtask bench{}` on {date}: {cpu}, {cores} cores, {uname}; load average at the start {}. Problem: the reference device (docs/design.md §2) with distance data, 32 kinematic deviations of which the 28 identifiable ones are solved from x = 0 (`dalpha0`, `dd0`, `dtheta0`, `dalpha7` held at 0); data: joint angles uniform within the limits, distances of the paper's truth + σ_m noise (`hapcal_sim::distance_samples`, seed 1), written once by hapcal to `bench-data/` in the cargo target directory. Every solver reads the same file. Tolerances: ftol = xtol = gtol = 1e-12 (MINPACK tests) for hapcal and SciPy; SciPy gets `x_scale=\"jac\"` (MINPACK's column scaling, as hapcal) and the analytic Jacobian. hapcal's LM starts with the full Gauss–Newton step (`LmConfig::factor = ∞`: initial trust radius = the Gauss–Newton step's length) where SciPy's MINPACK starts with radius 100·‖D·x0‖ (100 at x = 0; `least_squares` does not expose `factor`); the iteration and its stopping tests are MINPACK's in both. `identify` knows σ and decides the pruning once, at the nominal (`IdentifyConfig::max_rounds = 1`; `pruning_converged` says whether the decision at the estimate agrees). Wall times: minimum over repeats, the solve only (file reading excluded for both). hapcal evaluates distance rows 8 poses at a time (SIMD lane kernel through pulp: one kernel body, AVX-512, AVX2, NEON or scalar chosen at run time, the same bits on each) and row blocks on all cores (rayon) from 4 blocks of 256 poses up, i.e. at 2,000 poses and more; SciPy's numpy may use several threads too.\n\n",
        if peers { " --peers" } else { "" },
        load_before.split_whitespace().take(3).collect::<Vec<_>>().join(" "),
    ));
    md.push_str("| poses | hapcal LM (28 params) | hapcal identify (prune + LM + covariance, σ known) | SciPy lm | hapcal/lm | max abs diff lm | SciPy trf | hapcal/trf | max abs diff trf | peak RSS hapcal |\n|---|---|---|---|---|---|---|---|---|---|\n");
}

/// hapcal's LM at 200 poses for the per-iteration cost: the fastest solve (s) and its
/// iteration, Jacobian and residual evaluation counts.
struct PerIteration {
    lm_s: f64,
    n_iter: f64,
    n_jac: f64,
    n_eval: f64,
}

/// The 200-pose figures printed beside the hand-written kernels' run: hapcal LM, SciPy lm and
/// SciPy trf wall times (`–` when not run).
struct Row200 {
    lm: String,
    scipy_lm: String,
    scipy_trf: String,
}

/// What the size table leaves for the sections after it.
struct SizeTable {
    /// The 200-pose LM's cost, once that size ran.
    per_iteration: Option<PerIteration>,
    /// The 200-pose wall times.
    row_200: Row200,
}

/// The size table: per pose count of [`SIZES`], hapcal's solve and, up to [`PEER_MAX`] with
/// peers, SciPy's on the same data file; then the table's notes.
///
/// # Errors
/// A failed data write, solve or peer run, or output that is not JSON.
fn size_table(sh: &Shell, tools: &Tools, md: &mut String) -> Result<SizeTable> {
    let mut per_iteration = None;
    let mut row_200 = Row200 {
        lm: "–".to_owned(),
        scipy_lm: "–".to_owned(),
        scipy_trf: "–".to_owned(),
    };
    for n in SIZES {
        let data = tools.data_dir.join(format!("poses-{n}.csv"));
        if !data.exists() {
            let (d, nn) = (data.display().to_string(), n.to_string());
            let scale = &tools.scale;
            cmd!(sh, "{scale} write --poses {nn} --seed 1 --out {d}").run()?;
        }
        let ours = solve_ours(sh, &tools.scale, &data, n)?;
        if n == 200 {
            per_iteration = Some(fastest_lm(sh, &tools.scale, &ours)?);
            row_200.lm = ms(ours.lm_s);
        }
        let mut cells = our_cells(n, &ours);
        for method in ["lm", "trf"] {
            match (&tools.python, n <= PEER_MAX) {
                (Some(py), true) => {
                    let peer = run_peer(sh, py, &tools.peer_script, &data, n, method, &ours)?;
                    if n == 200 {
                        let figure = ms(peer.min_s);
                        if method == "lm" {
                            row_200.scipy_lm = figure;
                        } else {
                            row_200.scipy_trf = figure;
                        }
                    }
                    cells.extend(peer.cells);
                }
                _ => cells.extend(["–".to_owned(), "–".to_owned(), "–".to_owned()]),
            }
        }
        cells.push(format!("{:.0} MB", ours.rss_mb));
        md.push_str(&format!("| {} |\n", cells.join(" | ")));
        println!("bench: {n} poses done");
    }
    md.push_str("\n`hapcal/peer` is the ratio of wall times (1/20 = hapcal 20 times faster). `fev`/`jev`: residual and Jacobian evaluations of the final fit; `pruning differs at the estimate`: the decision at the estimate differs from the nominal one that the fit used (`pruning_converged = false`). `max abs diff`: largest |hapcal − SciPy| over the 28 estimates (m or rad). Peak RSS: the whole `scale solve` process (data, problem, all repeats of both solves), from `/usr/bin/time -v`.\n\n");
    Ok(SizeTable {
        per_iteration,
        row_200,
    })
}

/// hapcal's solve of one data file (`scale solve`'s JSON and what the table takes from it).
struct OurSolve {
    /// The arguments of `scale` that solved it.
    args: Vec<String>,
    /// `scale solve`'s JSON.
    json: Value,
    /// Peak RSS of the process (MB).
    rss_mb: f64,
    /// Fastest LM solve (s; NaN with `--identify-only`).
    lm_s: f64,
    /// Fastest `identify` (s).
    id_s: f64,
}

/// Solves `data` (`n` poses) with hapcal's `scale solve` under `/usr/bin/time -v`: LM and
/// `identify`, or past [`PEER_MAX`] (no peer to compare with) the calibration alone.
///
/// # Errors
/// A failed solve or output that is not JSON.
fn solve_ours(sh: &Shell, scale: &Path, data: &Path, n: usize) -> Result<OurSolve> {
    let mut args = vec![
        "solve".to_owned(),
        "--data".to_owned(),
        data.display().to_string(),
        "--repeat".to_owned(),
        repeats(n).to_string(),
    ];
    if n > PEER_MAX {
        // No peer to compare with: the calibration alone (and one peak-memory figure).
        args.push("--identify-only".to_owned());
    }
    let (out, rss_mb) = timed(sh, scale, &args)?;
    let ours: Value = serde_json::from_str(&out).context("scale solve output")?;
    let lm_s = f(&ours, &["lm", "min_s"]);
    let id_s = f(&ours, &["identify", "min_s"]);
    Ok(OurSolve {
        args,
        json: ours,
        rss_mb,
        lm_s,
        id_s,
    })
}

/// The per-iteration cost: the fastest LM of `ours`' process and LM_PROCESSES − 1 more (the
/// same modes as the peak's), with the same evaluation counts.
///
/// # Errors
/// A failed solve or output that is not JSON.
fn fastest_lm(sh: &Shell, scale: &Path, ours: &OurSolve) -> Result<PerIteration> {
    let mut lm_best = ours.lm_s;
    for _ in 1..LM_PROCESSES {
        let mut again = ours.args.clone();
        again.push("--lm-only".to_owned());
        let out: Value = serde_json::from_str(&cmd!(sh, "{scale} {again...}").read()?)?;
        lm_best = lm_best.min(f(&out, &["lm", "min_s"]));
    }
    let json = &ours.json;
    Ok(PerIteration {
        lm_s: lm_best,
        n_iter: f(json, &["lm", "n_iterations"]),
        n_jac: f(json, &["lm", "n_jacobians"]),
        n_eval: f(json, &["lm", "n_evaluations"]),
    })
}

/// The size table's first cells of `n` poses: the pose count, hapcal's LM and its `identify`.
fn our_cells(n: usize, ours: &OurSolve) -> Vec<String> {
    let (json, lm_s, id_s) = (&ours.json, ours.lm_s, ours.id_s);
    vec![
        n.to_string(),
        if lm_s.is_nan() {
            "–".to_owned()
        } else {
            format!(
                "{} ({} fev, {} jev)",
                ms(lm_s),
                json["lm"]["n_evaluations"],
                json["lm"]["n_jacobians"]
            )
        },
        format!(
            "{} ({}, {} fev, {} jev, pruning {})",
            ms(id_s),
            json["backend"].as_str().unwrap_or("?"),
            json["identify"]["n_evaluations"],
            json["identify"]["n_jacobians"],
            if json["identify"]["pruning_converged"].as_bool() == Some(true) {
                "converged"
            } else {
                "differs at the estimate"
            }
        ),
    ]
}

/// A SciPy peer's solve: its fastest wall time (s) and its three cells of the size table.
struct PeerSolve {
    min_s: f64,
    /// Wall time with evaluations, hapcal/peer ratio, max abs difference of the estimates.
    cells: [String; 3],
}

/// Solves `data` (`n` poses) with SciPy's `least_squares` (`method` "lm" or "trf") on the
/// parameters `ours` freed, and compares its estimates with hapcal's LM.
///
/// # Errors
/// A failed peer run or output that is not JSON.
fn run_peer(
    sh: &Shell,
    py: &Path,
    peer_script: &Path,
    data: &Path,
    n: usize,
    method: &str,
    ours: &OurSolve,
) -> Result<PeerSolve> {
    let free: Vec<String> = ours.json["free"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_str().map(str::to_owned))
                .collect()
        })
        .unwrap_or_default();
    let (d, fr, rep) = (
        data.display().to_string(),
        free.join(","),
        repeats(n).min(5).to_string(),
    );
    let out = cmd!(
        sh,
        "{py} {peer_script} --data {d} --method {method} --free {fr} --repeat {rep}"
    )
    .read()?;
    let peer: Value = serde_json::from_str(&out).context("peer output")?;
    let peer_s = f(&peer, &["min_s"]);
    let diff = max_diff(&ours.json["lm"]["x"], &peer["x"]);
    Ok(PeerSolve {
        min_s: peer_s,
        cells: [
            format!("{} ({} fev)", ms(peer_s), peer["nfev"]),
            format!("1/{:.1}", peer_s / ours.lm_s),
            format!("{diff:.1e}"),
        ],
    })
}

/// The per-iteration cost at 200 poses against the FLOP bound at the measured peak, and the
/// same figures beside the last run with hand-written kernels (`cpu`: this machine's).
fn write_per_iteration(
    md: &mut String,
    peak: &Peak,
    it: &PerIteration,
    row_200: &Row200,
    cpu: &str,
) {
    let PerIteration {
        lm_s,
        n_iter,
        n_jac,
        n_eval,
    } = *it;
    let (peak_readings, peak) = (&peak.readings, &peak.best);
    let gflops = f(peak, &["gflops"]);
    let flops = f(peak, &["flops_per_iteration_200"]);
    let iteration_s = lm_s / n_iter;
    let bound_s = flops / (gflops * 1e9);
    md.push_str(&format!(
        "## Per-iteration cost at 200 poses\n\nhapcal's LM at 200 poses: {} for {n_iter} iterations ({n_eval} residual evaluations, {n_jac} of them with the Jacobian), i.e. {} per iteration: the whole solve divided by the iterations, so the evaluation at x0 and any rejected trial are included (the solver leaves the Jacobian out at a trial point whose predicted reduction already meets ftol, where the iteration usually stops, and evaluates it afterwards if it goes on). FLOP count of one Jacobian evaluation plus one QR: {:.0} kflop ({}); at the measured peak of {gflops:.1} GFLOP/s (one core, {}; the largest of {PEAK_PROCESSES} processes' readings {}) that is {}. The solve time is the fastest of {LM_PROCESSES} processes. Ratio: {:.1}×.\n\n",
        ms(lm_s),
        ms(iteration_s),
        flops / 1e3,
        peak["flops_note"].as_str().unwrap_or(""),
        peak["peak_note"].as_str().unwrap_or(""),
        peak_readings
            .iter()
            .map(|g| format!("{g:.1}"))
            .collect::<Vec<_>>()
            .join(", "),
        ms(bound_s),
        iteration_s / bound_s
    ));
    let Row200 {
        lm: lm200,
        scipy_lm: scipy_lm200,
        scipy_trf: scipy_trf200,
    } = row_200;
    md.push_str(&format!(
        "### Beside the hand-written kernels

The last run with hand-written AVX-512/AVX2 kernels ({HAND_WRITTEN_RUN}): {HAND_WRITTEN_ITERATION_MS} ms per iteration, LM at 200 poses {HAND_WRITTEN_LM_MS} ms, SciPy lm {HAND_WRITTEN_SCIPY_LM_MS} ms, SciPy trf {HAND_WRITTEN_SCIPY_TRF_MS} ms. This run ({cpu}): {} per iteration ({:.2}× that figure, on another machine), LM at 200 poses {lm200}, SciPy lm {scipy_lm200}, SciPy trf {scipy_trf200}. docs/results/simd.md compares the two kernels on one machine, interleaved.\n\n",
        ms(iteration_s),
        iteration_s * 1e3 / HAND_WRITTEN_ITERATION_MS,
    ));
}

/// The fleet section: 1000 devices on one rig solved by the sparse back end (`fleet`'s JSON).
///
/// # Errors
/// A failed `fleet` run or output that is not JSON.
fn write_fleet(sh: &Shell, fleet: &Path, md: &mut String) -> Result<()> {
    let (out, rss_mb) = timed(sh, fleet, &[])?;
    let fl: Value = serde_json::from_str(&out).context("fleet output")?;
    md.push_str(&format!(
        "## Fleet: {} devices on one rig (sparse back end)\n\n{} residuals, {} parameters ({} per device + 2 shared). The dense back end refuses: \"{}\". The sparse back end (chosen by `identify` from the Jacobian's structure) solves it in {} ({}, {} iterations, {} residual evaluations; the dense back end's Levenberg–Marquardt iteration with each trust-region subproblem factorised by sparse QR, started with the full Gauss–Newton step), peak RSS {rss_mb:.0} MB (whole process, simulation included). Shared rig parameters:\n\n| parameter | truth | estimate ± std | (estimate − truth)/std |\n|---|---|---|---|\n| cable zero offset (m) | {:.3e} | {:.4e} ± {:.1e} | {:.2} |\n| cable-angle coefficient (m/rad) | {:.3e} | {:.4e} ± {:.1e} | {:.2} |\n\nRMS error of the 28,000 per-device deviations: {:.2e} (m or rad). Command: `cargo run --release -p hapcal-identify --example fleet -- --devices 1000 --poses 200 --seed 1`.\n\n",
        fl["n_devices"],
        fl["n_residuals"],
        fl["n_params"],
        28,
        fl["dense"].as_str().unwrap_or(""),
        ms(f(&fl, &["solve_s"])),
        fl["termination"].as_str().unwrap_or(""),
        fl["n_iterations"],
        fl["n_evaluations"],
        f(&fl, &["cable_offset", "truth"]),
        f(&fl, &["cable_offset", "estimate"]),
        f(&fl, &["cable_offset", "std"]),
        f(&fl, &["cable_offset", "z"]),
        f(&fl, &["cable_angle", "truth"]),
        f(&fl, &["cable_angle", "estimate"]),
        f(&fl, &["cable_angle", "std"]),
        f(&fl, &["cable_angle", "z"]),
        f(&fl, &["device_deviation_rms_error"]),
    ));
    Ok(())
}

/// The criterion benchmarks (when `criterion`) and the load at the end; writes
/// docs/results/bench.md, keeping the section `cargo xtask bench --scale` wrote.
///
/// # Errors
/// A failed `cargo bench` or an unwritable report.
fn finish(sh: &Shell, mut md: String, criterion: bool) -> Result<()> {
    if criterion {
        md.push_str("## Criterion\n\n`cargo bench -p hapcal-identify --bench scale` (one group per operation, size as the parameter) ran in this task; its report is in `target/criterion/`.\n");
        cmd!(sh, "cargo bench -p hapcal-identify --bench scale").run()?;
    }
    let load_after = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    md.push_str(&format!(
        "\nLoad average at the end: {}.\n",
        load_after
            .split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    ));
    let out = sh.current_dir().join("docs/results/bench.md");
    // The section `cargo xtask bench --scale` writes is kept.
    let before = std::fs::read_to_string(&out).unwrap_or_default();
    if let Some(i) = before.find(crate::bench_scale::SECTION) {
        md.push('\n');
        md.push_str(&before[i..]);
    }
    std::fs::write(&out, md)?;
    println!("wrote {}", out.display());
    Ok(())
}
