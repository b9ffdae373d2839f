//! Scale benchmarks on the reference device (docs/design.md §2) with distance data: 32 kinematic
//! deviations, of which identification keeps the 28 identifiable ones. Data: joint angles
//! uniform within the limits, distances of the paper's truth plus σ_m noise
//! (`hapcal_sim::distance_samples`, seed 1). Sizes: 200, 2,000, 20,000 and 1,000,000 poses
//! (`HAPCAL_BENCH_SIZES=200,2000` runs a subset). Groups, one size per parameter:
//! - `forward_kinematics`: the end point of every pose (one thread);
//! - `jacobian`: residuals and Jacobian of every pose, row block by row block (one thread,
//!   constant memory);
//! - `lm_step`: one Levenberg–Marquardt step from the nominal on the 28 parameters (the
//!   residual at x0, one linearisation and its QR, one trial point: the full Gauss–Newton
//!   step, `LmConfig::factor = ∞`), the back end
//!   [`Backend::Auto`](hapcal_identify::Backend) picks (dense up to 20,000, streaming at
//!   1,000,000; streaming runs on all cores);
//! - `calibration`: the whole `identify` (pruning decided once at the nominal,
//!   `IdentifyConfig::max_rounds = 1`, and checked at the estimate; LM starting with the full
//!   Gauss–Newton step, `LmConfig::factor = ∞`; covariance; the noise is known, σ = 1 in
//!   residual units), as `cargo xtask bench` runs it.
#![allow(missing_docs, clippy::unwrap_used)] // criterion's macros generate undocumented items

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use faer::{Col, Mat};
use hapcal_identify::{
    IdentifyConfig, LmConfig, Problem, RowBlocks, STREAMING_AUTO_ENTRIES, identify,
    levenberg_marquardt, levenberg_marquardt_streaming,
};
use hapcal_kinematics::FrozenChain;
use hapcal_problems::{CalibrationProblem, Observations, Row, RowKind, Weights};

const HELD: [&str; 4] = ["dalpha0", "dd0", "dtheta0", "dalpha7"];

fn sizes() -> Vec<usize> {
    std::env::var("HAPCAL_BENCH_SIZES")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![200, 2_000, 20_000, 1_000_000])
}

fn sigma_m() -> f64 {
    let sigma_e = std::f64::consts::TAU / 20000.0 / 3.0;
    std::f64::consts::TAU * 0.015 * sigma_e
}

struct Case {
    problem: CalibrationProblem,
    frozen: FrozenChain,
    q: Vec<Vec<f64>>,
    free: Vec<usize>,
}

fn case(n_poses: usize) -> Case {
    let truth_path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/reference-device/truth.toml");
    let truth = hapcal_sim::read_truth(&truth_path).unwrap();
    let device = truth.read_device(&truth_path).unwrap();
    let s = hapcal_sim::distance_samples(&device, &truth, 1, n_poses, sigma_m()).unwrap();
    let chain = device.chain().unwrap();
    let x_truth = hapcal_sim::truth_deviations(&chain, &truth).unwrap();
    let frozen = chain.freeze(&x_truth);
    let q: Vec<Vec<f64>> = (0..n_poses).map(|k| s.q(k).to_vec()).collect();
    let rows = (0..n_poses)
        .map(|k| Row {
            q: s.q(k).into(),
            kind: RowKind::Distance {
                distance_m: s.distance_m[k],
            },
        })
        .collect();
    let obs = Observations {
        rows,
        ..Observations::default()
    };
    let weights = Weights {
        sigma_distance_m: sigma_m(),
        ..Weights::default()
    };
    let problem = CalibrationProblem::new(chain, obs, weights, None).unwrap();
    let layout = problem.layout();
    let free = (0..layout.len())
        .filter(|&i| !HELD.contains(&layout.name(i)))
        .collect();
    Case {
        problem,
        frozen,
        q,
        free,
    }
}

fn bench(c: &mut Criterion) {
    for n_poses in sizes() {
        let big = n_poses >= 100_000;
        let case = case(n_poses);
        let p = &case.problem;
        let n = p.layout().len();
        let streaming = p.n_residuals() * n > STREAMING_AUTO_ENTRIES;
        let configure = |g: &mut criterion::BenchmarkGroup<'_, _>| {
            if big {
                g.sample_size(10).measurement_time(Duration::from_secs(20));
            }
        };

        let mut g = c.benchmark_group("forward_kinematics");
        configure(&mut g);
        g.bench_with_input(BenchmarkId::from_parameter(n_poses), &case, |b, case| {
            b.iter(|| {
                let mut sum = 0.0;
                for q in &case.q {
                    sum += case.frozen.end_point(black_box(q)).coords.norm();
                }
                sum
            })
        });
        g.finish();

        let mut g = c.benchmark_group("jacobian");
        configure(&mut g);
        let x = p.initial_guess();
        g.bench_with_input(BenchmarkId::from_parameter(n_poses), &case, |b, case| {
            let p = &case.problem;
            let max_len = (0..p.n_blocks())
                .map(|k| p.block_rows(k).len())
                .max()
                .unwrap();
            let mut r = Col::<f64>::zeros(max_len);
            let mut jac = Mat::<f64>::zeros(max_len, n);
            b.iter(|| {
                for k in 0..p.n_blocks() {
                    let len = p.block_rows(k).len();
                    p.block_jacobian(
                        black_box(x.as_ref()),
                        k,
                        r.as_mut().subrows_mut(0, len),
                        jac.as_mut().subrows_mut(0, len),
                    )
                    .unwrap();
                }
                r[0]
            })
        });
        g.finish();

        let mut g = c.benchmark_group("lm_step");
        configure(&mut g);
        let one_step = LmConfig {
            max_evaluations: 2,
            factor: f64::INFINITY,
            ..LmConfig::default()
        };
        g.bench_with_input(BenchmarkId::from_parameter(n_poses), &case, |b, case| {
            let p = &case.problem;
            b.iter(|| {
                let x0 = Col::zeros(n);
                if streaming {
                    levenberg_marquardt_streaming(p, x0, &case.free, &one_step).unwrap()
                } else {
                    levenberg_marquardt(p, x0, &case.free, &one_step).unwrap()
                }
            })
        });
        g.finish();

        let mut g = c.benchmark_group("calibration");
        configure(&mut g);
        g.bench_with_input(BenchmarkId::from_parameter(n_poses), &case, |b, case| {
            let p = &case.problem;
            let cfg = IdentifyConfig {
                lm: LmConfig {
                    factor: f64::INFINITY,
                    ..LmConfig::default()
                },
                // Residuals are in units of σ_m: the noise is known.
                sigma: Some(1.0),
                max_rounds: 1,
                ..IdentifyConfig::default()
            };
            b.iter(|| identify(p, p.initial_guess(), &cfg).unwrap())
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
