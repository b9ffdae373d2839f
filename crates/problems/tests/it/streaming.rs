//! The streaming back end (row blocks reduced by TSQR) gives the dense back end's estimates.

use faer::Col;
use hapcal_identify::{Backend, Identified, IdentifyConfig, Problem, identify};
use hapcal_problems::{CalibrationProblem, Row, RowKind, Weights};

use crate::{chain_problem, lcg};

fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The reference device's chain with `n_rows` configurations (the log's, then random ones) and
/// distances of a truth with 1 mm / 1 mrad deviations plus 10 µm noise.
fn reference_distance_problem(n_rows: usize) -> CalibrationProblem {
    let dir = root().join("fixtures/reference-device");
    let device = hapcal_io::read_device(&dir.join("device.toml")).expect("device");
    let log = hapcal_io::read_log(&dir.join("log.csv"), &device).expect("log");
    let chain = device.chain().expect("chain");
    let mut state = 7;
    // Deviations on the 28 identifiable parameters only (docs/design.md §2): the other 4 only
    // move the gauge, which would leave the pruning a near-tie to decide.
    let held = ["dalpha0", "dd0", "dtheta0", "dalpha7"];
    let x_truth: Vec<f64> = chain
        .params()
        .iter()
        .map(|p| {
            let v = 1e-3 * lcg(&mut state);
            if held.contains(&p.name.as_str()) {
                0.0
            } else {
                v
            }
        })
        .collect();
    let limits = device.joint_limits();
    let rows = (0..n_rows)
        .map(|k| {
            // The log's configurations first, then fresh ones within the joint limits.
            let q = match log.rows.get(k) {
                Some(row) => row.q.clone(),
                None => limits
                    .iter()
                    .map(|&(lo, hi)| lo + (hi - lo) * 0.5 * (1.0 + lcg(&mut state)))
                    .collect(),
            };
            let d = chain.end_point(&x_truth, &q).coords.norm() + 1e-5 * lcg(&mut state);
            Row {
                q: q.into(),
                kind: RowKind::Distance { distance_m: d },
            }
        })
        .collect();
    let default_position = Weights::default().sigma_position_m;
    chain_problem(chain, rows, 1e-5, default_position)
}

fn with_backend(p: &CalibrationProblem, backend: Backend) -> Identified {
    let cfg = IdentifyConfig {
        backend,
        ..IdentifyConfig::default()
    };
    identify(p, p.initial_guess(), &cfg).expect("identifies")
}

fn assert_same(dense: &Identified, streaming: &Identified, p: &CalibrationProblem) {
    assert_eq!(dense.identifiability.kept, streaming.identifiability.kept);
    assert!(dense.fit.termination.is_success());
    assert!(streaming.fit.termination.is_success());
    // Both back ends stop on the same MINPACK tests, at points that differ by rounding along the
    // weakest directions: 1e-9 (m or rad), or 1e-4 of the parameter's standard deviation where
    // that is larger (far below anything the data can tell apart).
    let std_dense = dense.covariance.std();
    for i in 0..p.layout().len() {
        let (a, b) = (dense.fit.x[i], streaming.fit.x[i]);
        let std_i = (dense.covariance.free.iter())
            .position(|&f| f == i)
            .map_or(0.0, |k| std_dense[k]);
        assert!(
            (a - b).abs() <= 1e-9_f64.max(1e-4 * std_i),
            "{}: dense {a:e} vs streaming {b:e} (std {std_i:e})",
            p.layout().name(i)
        );
    }
    assert!((dense.fit.cost - streaming.fit.cost).abs() <= 1e-9 * dense.fit.cost.max(1.0));
    let (sd, ss) = (dense.covariance.std(), streaming.covariance.std());
    for (a, b) in sd.iter().zip(&ss) {
        // Standard deviations of nearly redundant parameters amplify rounding: 1e-6 relative.
        assert!((a - b).abs() <= 1e-6 * a.abs(), "std {a:e} vs {b:e}");
    }
    assert!((dense.sigma - streaming.sigma).abs() <= 1e-9 * dense.sigma);
}

#[test]
fn streaming_identify_matches_dense_on_distance_data() {
    // 600 rows: 3 blocks of 256 rows, the last one short.
    let p = reference_distance_problem(600);
    let dense = with_backend(&p, Backend::Dense);
    let streaming = with_backend(&p, Backend::Streaming);
    assert_eq!(dense.identifiability.kept.len(), 28);
    assert!(streaming.fit.residuals.nrows() == 0);
    assert_same(&dense, &streaming, &p);
}

#[test]
fn streaming_identify_matches_dense_on_points_and_positions() {
    // iiwa-like URDF chain: positions, distances, and two unknown points with a known
    // distance between them (the point distance sits in the last block).
    let chain = super::iiwa_like();
    let mut state = 11;
    let x_truth: Vec<f64> = (0..chain.n_params())
        .map(|_| 5e-4 * lcg(&mut state))
        .collect();
    let mut rows = Vec::new();
    for k in 0..600 {
        let q: Vec<f64> = (0..chain.n_joints())
            .map(|_| 2.0 * lcg(&mut state))
            .collect();
        let p = chain.end_point(&x_truth, &q);
        let kind = if k % 3 == 0 {
            RowKind::Distance {
                distance_m: p.coords.norm() + 1e-5 * lcg(&mut state),
            }
        } else {
            RowKind::Position {
                position_m: [
                    p.x + 1e-5 * lcg(&mut state),
                    p.y + 1e-5 * lcg(&mut state),
                    p.z + 1e-5 * lcg(&mut state),
                ],
            }
        };
        rows.push(Row { q: q.into(), kind });
    }
    let p = chain_problem(chain, rows, 1e-5, 1e-5);
    let dense = with_backend(&p, Backend::Dense);
    let streaming = with_backend(&p, Backend::Streaming);
    assert_same(&dense, &streaming, &p);
}

#[test]
fn streaming_result_does_not_depend_on_the_thread_count() {
    let p = reference_distance_problem(300);
    let run = |threads: usize| -> Col<f64> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| with_backend(&p, Backend::Streaming)).fit.x
    };
    let one = run(1);
    for threads in [2, 3] {
        let x = run(threads);
        for i in 0..one.nrows() {
            assert_eq!(
                one[i].to_bits(),
                x[i].to_bits(),
                "{threads} threads, entry {i}"
            );
        }
    }
}

#[test]
fn auto_backend_streams_only_large_problems() {
    // 200 rows × 32 parameters is far below the streaming threshold: dense, with residuals.
    let p = reference_distance_problem(200);
    let id = with_backend(&p, Backend::Auto);
    assert_eq!(id.fit.residuals.nrows(), p.n_residuals());
}

/// A cross-validation fold's refit started from the triangles of the blocks of rows it trains
/// on ([`hapcal_identify::rows_r_factor`], stacked by [`hapcal_identify::stacked_r_factor`])
/// has the Gram matrix of the fold's rows and reaches the refit that evaluates the fold's
/// Jacobian itself.
#[test]
fn a_fold_started_from_its_blocks_triangles_is_the_folds_refit() {
    let p = reference_distance_problem(600);
    let full = with_backend(&p, Backend::Dense);
    let free = full.identifiability.kept.clone();
    let (m, n) = (p.n_residuals(), p.layout().len());
    // Moved off the full-data estimate, as a fold's start lies off the fold's own minimum.
    let x0 = Col::from_fn(n, |i| full.fit.x[i] + 1e-5 * ((i % 5) as f64 - 2.0));
    let (mut r, mut jac) = (Col::zeros(m), faer::Mat::zeros(m, n));
    p.residuals_and_jacobian(x0.as_ref(), r.as_mut(), jac.as_mut())
        .expect("evaluated");
    // The fold holds out rows 200..300 (one residual per distance row) and trains on the
    // blocks before and after them.
    let before: Vec<usize> = (0..200).collect();
    let after: Vec<usize> = (300..600).collect();
    let blocks = [
        hapcal_identify::rows_r_factor(jac.as_ref(), r.as_ref(), &before, &free),
        hapcal_identify::rows_r_factor(jac.as_ref(), r.as_ref(), &after, &free),
    ];
    let tri = hapcal_identify::stacked_r_factor(&[blocks[0].as_ref(), blocks[1].as_ref()]);
    let rows: Vec<usize> = before.iter().chain(&after).copied().collect();
    let aug = faer::Mat::from_fn(rows.len(), free.len() + 1, |i, c| match free.get(c) {
        Some(&j) => jac[(rows[i], j)],
        None => r[rows[i]],
    });
    let (gram, gram_tri) = (aug.transpose() * &aug, tri.transpose() * &tri);
    let scale = (0..gram.nrows())
        .map(|i| gram[(i, i)])
        .fold(0.0_f64, f64::max);
    for i in 0..gram.nrows() {
        for j in 0..gram.ncols() {
            // Rounding of two Householder reductions of 500 rows: 1e-12 of the largest entry.
            assert!(
                (gram[(i, j)] - gram_tri[(i, j)]).abs() <= 1e-12 * scale,
                "Gram entry ({i}, {j}): {:e} vs {:e}",
                gram[(i, j)],
                gram_tri[(i, j)]
            );
        }
    }
    let keep: Vec<bool> = (0..600).map(|k| !(200..300).contains(&k)).collect();
    let fold = p.with_rows(&keep).expect("the fold's rows");
    let r0 = Col::from_fn(rows.len(), |i| r[rows[i]]);
    let cfg = hapcal_identify::LmConfig::default();
    let started = hapcal_identify::levenberg_marquardt_from_triangle(
        &fold,
        x0.clone(),
        &free,
        &cfg,
        r0,
        tri.as_ref(),
    )
    .expect("refit from the triangles");
    let evaluated =
        hapcal_identify::levenberg_marquardt(&fold, x0, &free, &cfg).expect("refit evaluating J");
    assert!(started.termination.is_success() && evaluated.termination.is_success());
    let std = full.covariance.std();
    for &i in &free {
        let (a, b) = (started.x[i], evaluated.x[i]);
        let std_i = (full.covariance.free.iter())
            .position(|&f| f == i)
            .map_or(0.0, |k| std[k]);
        // As the streaming and dense back ends: the same MINPACK tests, points apart by
        // rounding along the weakest directions.
        assert!(
            (a - b).abs() <= 1e-9_f64.max(1e-4 * std_i),
            "{}: from the triangles {a:e} vs evaluated {b:e} (std {std_i:e})",
            p.layout().name(i)
        );
    }
    assert!(started.n_iterations >= 1 && started.x != full.fit.x);
    // A second linearisation evaluated the fold's Jacobian itself.
    assert!(
        started.n_jacobians >= 1,
        "{} Jacobians",
        started.n_jacobians
    );
}
