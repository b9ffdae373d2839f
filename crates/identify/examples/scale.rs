//! The reference device (docs/design.md §2) with distance data at any size: writes a data file, or
//! reads one and calibrates it, printing timings and estimates as JSON. `cargo xtask bench`
//! drives it (and SciPy on the same files); `/usr/bin/time -v` around `solve` gives the peak
//! memory.
//!
//! ```text
//! scale write --poses N --seed S --out data.csv
//! scale solve --data data.csv [--repeat K] [--identify-only | --lm-only]
//!             [--factor F] [--max-rounds R]
//! scale peak
//! ```
//!
//! `data.csv`: header `q1,…,q7,distance_m`, one pose per line, shortest round-trip decimals.
//! `solve` prints one JSON object: sizes, the file-reading time, the minimum and median wall
//! times of K runs of (a) `levenberg_marquardt` on the 28 identifiable parameters from x = 0
//! (the problem SciPy solves, with MINPACK's tests and tolerances; the initial trust radius is
//! `--factor`, default ∞: the first step is the full Gauss–Newton step, see
//! `LmConfig::factor`; SciPy's MINPACK has `factor = 100`, which `--factor 100` reproduces)
//! and (b) the whole `identify` (pruning, fit, covariance; `factor = ∞`, the known noise σ = 1
//! in residual units, and `--max-rounds` fits, default 1: the pruning is decided once, at the
//! nominal, see `IdentifyConfig::max_rounds`), the termination, the evaluation counts, and the
//! estimates of (a) and (b) by name. `--lm-only` skips (b) (for instruction counts of (a)
//! alone). `peak` prints the measured peak FLOP rate and the FLOP count of one iteration at
//! 200 poses.
#![allow(missing_docs, clippy::print_stdout, clippy::unwrap_used)] // a command-line tool

use std::path::{Path, PathBuf};
use std::time::Instant;

use faer::Col;
use hapcal_identify::{
    IdentifyConfig, LmConfig, Problem, identify, levenberg_marquardt, levenberg_marquardt_streaming,
};
use hapcal_problems::{CalibrationProblem, Observations, Row, RowKind, Weights};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// σ_m = 2π·R_d·σ_e, σ_e = 2π/20000/3 rad, R_d = 0.015 m (docs/design.md §3), m.
fn sigma_m() -> f64 {
    let sigma_e = std::f64::consts::TAU / 20000.0 / 3.0;
    std::f64::consts::TAU * 0.015 * sigma_e
}

/// The 4 deviations that distance data cannot determine (docs/design.md §2), held at 0.
const HELD: [&str; 4] = ["dalpha0", "dd0", "dtheta0", "dalpha7"];

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn write(args: &[String]) -> Result<()> {
    let n: usize = arg(args, "--poses").ok_or("--poses N")?.parse()?;
    let seed: u64 = arg(args, "--seed").unwrap_or_else(|| "1".into()).parse()?;
    let out = PathBuf::from(arg(args, "--out").ok_or("--out FILE")?);
    let truth_path = root().join("fixtures/reference-device/truth.toml");
    let truth = hapcal_sim::read_truth(&truth_path)?;
    let device = truth.read_device(&truth_path)?;
    let s = hapcal_sim::distance_samples(&device, &truth, seed, n, sigma_m())?;
    let mut text = String::with_capacity(n * 180);
    let header: Vec<String> = (1..=s.n_joints).map(|j| format!("q{j}")).collect();
    text.push_str(&header.join(","));
    text.push_str(",distance_m\n");
    for k in 0..n {
        for v in s.q(k) {
            text.push_str(&format!("{v},"));
        }
        text.push_str(&format!("{}\n", s.distance_m[k]));
    }
    std::fs::write(&out, text)?;
    Ok(())
}

/// Reads `q1..q7,distance_m` into distance rows.
fn read(path: &Path, n_joints: usize) -> Result<Vec<Row>> {
    let text = std::fs::read_to_string(path)?;
    let mut rows = Vec::new();
    for line in text.lines().skip(1).filter(|l| !l.is_empty()) {
        let mut q = Vec::with_capacity(n_joints);
        let mut d = 0.0;
        for (k, cell) in line.split(',').enumerate() {
            let v: f64 = cell.parse()?;
            if k < n_joints {
                q.push(v);
            } else {
                d = v;
            }
        }
        rows.push(Row {
            q: q.into(),
            kind: RowKind::Distance { distance_m: d },
        });
    }
    Ok(rows)
}

fn solve(args: &[String]) -> Result<()> {
    let data = PathBuf::from(arg(args, "--data").ok_or("--data FILE")?);
    let repeat: usize = arg(args, "--repeat")
        .unwrap_or_else(|| "1".into())
        .parse()?;
    let identify_only = args.iter().any(|a| a == "--identify-only");
    let max_rounds: usize = arg(args, "--max-rounds")
        .unwrap_or_else(|| "1".into())
        .parse()?;
    let lm_factor: f64 = arg(args, "--factor")
        .unwrap_or_else(|| "inf".into())
        .parse()?;
    let device = hapcal_io::read_device(&root().join("fixtures/reference-device/device.toml"))?;
    let chain = device.chain()?;
    let t0 = Instant::now();
    let rows = read(&data, chain.n_joints())?;
    let obs = Observations {
        rows,
        ..Observations::default()
    };
    let weights = Weights {
        sigma_distance_m: sigma_m(),
        ..Weights::default()
    };
    let p = CalibrationProblem::new(chain, obs, weights, None)?;
    let read_s = t0.elapsed().as_secs_f64();
    let layout = p.layout().clone();
    let free: Vec<usize> = (0..layout.len())
        .filter(|&i| !HELD.contains(&layout.name(i)))
        .collect();
    // Both runs start with the full Gauss–Newton step (factor ∞: the nominal is close to the
    // solution, and the problem has small residuals), with MINPACK's stopping tests. The
    // calibration knows the noise: residuals are in units of σ_m (the paper's noise model), so
    // σ = 1; it decides the pruning once, at the nominal, and reports whether the decision at
    // the estimate agrees (`pruning_converged`). With the default tie-break (earlier in the
    // layout) the nominal kept d0 and the estimate θ1 from 2,000 poses up; with the paper's
    // gauge (below) both keep θ1 at every size.
    let cfg = IdentifyConfig {
        lm: LmConfig {
            factor: lm_factor,
            ..LmConfig::default()
        },
        ..IdentifyConfig::default()
    };
    let mut cfg_identify = IdentifyConfig {
        lm: LmConfig {
            factor: f64::INFINITY,
            ..LmConfig::default()
        },
        sigma: Some(1.0),
        max_rounds,
        ..IdentifyConfig::default()
    };
    // The gauge convention of the paper and of `hapcal` (d0 = 0, θ1 kept): the exactly tied
    // base parameters go to the later one in the layout, as in `hapcal reproduce`.
    cfg_identify.rank.tie_break = hapcal_identify::TieBreak::LaterInLayout;
    let streaming = p.n_residuals() * layout.len() > hapcal_identify::STREAMING_AUTO_ENTRIES;

    let mut lm_times = Vec::new();
    let mut lm_fit = None;
    if !identify_only {
        for _ in 0..repeat {
            let t = Instant::now();
            let x0 = Col::zeros(layout.len());
            let fit = if streaming {
                levenberg_marquardt_streaming(&p, x0, &free, &cfg.lm)?
            } else {
                levenberg_marquardt(&p, x0, &free, &cfg.lm)?
            };
            lm_times.push(t.elapsed().as_secs_f64());
            lm_fit = Some(fit);
        }
    }
    let mut id_times = Vec::new();
    let mut id = None;
    // `--lm-only` (for instruction counts of the LM alone) skips `identify`.
    let id_repeat = if args.iter().any(|a| a == "--lm-only") {
        0
    } else {
        repeat
    };
    for _ in 0..id_repeat {
        let t = Instant::now();
        let fit = identify(&p, p.initial_guess(), &cfg_identify)?;
        id_times.push(t.elapsed().as_secs_f64());
        id = Some(fit);
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            (f64::NAN, f64::NAN)
        } else {
            (v[0], v[v.len() / 2])
        }
    };
    let (lm_min, lm_median) = stats(&mut lm_times);
    let (id_min, id_median) = stats(&mut id_times);
    let named = |x: &Col<f64>, which: &[usize]| {
        which
            .iter()
            .map(|&i| format!("\"{}\": {:e}", layout.name(i), x[i]))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let lm_json = match &lm_fit {
        Some(f) => format!(
            "{{\"min_s\": {lm_min:e}, \"median_s\": {lm_median:e}, \"termination\": \"{:?}\", \"n_evaluations\": {}, \"n_jacobians\": {}, \"n_iterations\": {}, \"cost\": {:e}, \"x\": {{{}}}}}",
            f.termination,
            f.n_evaluations,
            f.n_jacobians,
            f.n_iterations,
            f.cost,
            named(&f.x, &free)
        ),
        None => "null".to_owned(),
    };
    let Some(id) = id else {
        println!(
            "{{\"n_poses\": {}, \"lm\": {lm_json}, \"identify\": null}}",
            p.n_residuals()
        );
        return Ok(());
    };
    let std = id.covariance.std();
    let stds = id
        .covariance
        .free
        .iter()
        .zip(&std)
        .map(|(&i, s)| format!("\"{}\": {s:e}", layout.name(i)))
        .collect::<Vec<_>>()
        .join(", ");
    println!(
        "{{\"n_poses\": {}, \"n_params\": {}, \"n_free\": {}, \"backend\": \"{}\", \"threads\": {}, \"read_s\": {read_s:e}, \"lm\": {lm_json}, \"identify\": {{\"min_s\": {id_min:e}, \"median_s\": {id_median:e}, \"termination\": \"{:?}\", \"n_evaluations\": {}, \"n_jacobians\": {}, \"rounds\": {}, \"pruning_converged\": {}, \"pruned\": {:?}, \"x\": {{{}}}, \"std\": {{{stds}}}}}, \"free\": {:?}}}",
        p.n_residuals(),
        layout.len(),
        free.len(),
        if streaming { "streaming" } else { "dense" },
        rayon_threads(),
        id.fit.termination,
        id.fit.n_evaluations,
        id.fit.n_jacobians,
        id.rounds,
        id.pruning_converged,
        id.identifiability.pruned_names(),
        named(&id.fit.x, &id.identifiability.kept),
        free.iter().map(|&i| layout.name(i)).collect::<Vec<_>>(),
    );
    Ok(())
}

/// Measured peak FLOP rate of one core (faer's matrix product, 512 × 512, best of 200 spread
/// over about a second: a busy neighbour on the host lowers single readings), and the
/// FLOP count of one LM iteration's linear algebra at 200 poses: one Jacobian evaluation plus
/// one Householder QR of the 200 × 28 Jacobian.
fn peak() -> Result<()> {
    let n = 512;
    let a = faer::Mat::<f64>::from_fn(n, n, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
    let b = a.transpose().to_owned();
    let mut c = faer::Mat::<f64>::zeros(n, n);
    let mut best = f64::INFINITY;
    for _ in 0..200 {
        let t = Instant::now();
        faer::linalg::matmul::matmul(
            c.as_mut(),
            faer::Accum::Replace,
            a.as_ref(),
            b.as_ref(),
            1.0,
            faer::Par::Seq,
        );
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(&c);
    let gflops = 2.0 * (n * n * n) as f64 / best / 1e9;
    // Per pose of the reference chain (8 constant runs, 7 revolute joints, 32 parameters:
    // 16 rotation and 16 translation screws, each the first of its parameter), counting the
    // multiplications, additions, divisions and square roots of the lane kernel
    // (FrozenChain::distance_gradient_lanes, crates/kinematics/src/frozen/lanes.rs; a fused
    // multiply–add counts 2) and the residual written by CalibrationProblem:
    // end point backwards through the runs, per joint: joint rotation 6 (4 mul, 2 add) + run
    // F·p + t 18 = 24, × 7 = 168 (the last run's F·0 is its translation, 0);
    // |P| 6 (3 mul, 2 add, 1 sqrt); residual (|P| − δ)/σ 2;
    // U = P · (1/σ)/|P| 4 (1 div, 3 mul; 1/σ folded into the row here);
    // per run with taps T × U 9, × 8 = 72; screws: rotation a·(T × U) − U·c 11 × 16 = 176,
    // translation U·a 5 × 16 = 80; U forwards into the next run, per joint: Fᵀ·U 15 + joint
    // rotation 6 = 21, × 7 = 147.
    // Total 168 + 6 + 2 + 4 + 72 + 176 + 80 + 147 = 655 flops per pose. (The lane kernel that
    // composed the world frames counted 1339, the scalar point-Jacobian path 2496.)
    let (m, nf) = (200.0, 28.0);
    let jacobian = 655.0 * m;
    let qr = 2.0 * m * nf * nf - 2.0 * nf * nf * nf / 3.0;
    println!(
        "{{\"gflops\": {gflops:.2}, \"peak_note\": \"faer matmul {n}x{n}, one thread, best of 200\", \"flops_per_iteration_200\": {:.0}, \"flops_note\": \"Jacobian {:.0} kflop (655 per pose for the lane kernel, counted by hand in examples/scale.rs) + Householder QR 2mn^2 - 2n^3/3 = {:.0} kflop\"}}",
        jacobian + qr,
        jacobian / 1e3,
        qr / 1e3
    );
    Ok(())
}

fn rayon_threads() -> usize {
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("write") => write(&args),
        Some("solve") => solve(&args),
        Some("peak") => peak(),
        _ => Err("usage: scale write --poses N --seed S --out FILE | scale solve --data FILE [--repeat K] [--identify-only]".into()),
    }
}
