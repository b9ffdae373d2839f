//! The fits of socket recordings and distance logs ([`DataSet`]): their observations, the
//! identification of one model from them, and its repeated blocked cross-validation. The
//! `hapcal calibrate` workflow of these data and the geometric baseline build on them.

use anyhow::{Context, Result, bail};
use hapcal_identify::{Identified, identify};
use hapcal_kinematics::{Chain, Tree};
use hapcal_problems::{CalibrationProblem, Observations, PointDistance, Row, RowKind, Weights};

use crate::data::DataSet;
use crate::fit::{HeldOut, folds_of_rows, identify_config};
use crate::inputs::Plan;
use crate::model::ModelName;

/// Observations of `sets`; `keep(set, socket, row)` selects rows (for cross-validation).
pub(crate) fn observations(
    sets: &[DataSet],
    socket_distance_m: f64,
    keep: &dyn Fn(usize, usize, usize) -> bool,
) -> Observations {
    let mut obs = Observations::default();
    for (set_idx, set) in sets.iter().enumerate() {
        match set {
            DataSet::Sockets(p) => {
                let first = obs.n_points;
                for (socket_idx, socket) in p.sockets.iter().enumerate() {
                    let point = obs.n_points;
                    obs.n_points += 1;
                    for (row_idx, q) in socket.q.iter().enumerate() {
                        if keep(set_idx, socket_idx, row_idx) {
                            obs.rows.push(Row {
                                q: q.clone(),
                                kind: RowKind::Point { point },
                            });
                        }
                    }
                }
                if p.sockets.len() == 2 {
                    obs.point_distances.push(PointDistance {
                        a: first,
                        b: first + 1,
                        distance_m: socket_distance_m,
                    });
                }
            }
            DataSet::Distances { q, distance_m, .. } => {
                for (row_idx, (q, d)) in q.iter().zip(distance_m).enumerate() {
                    if keep(set_idx, 0, row_idx) {
                        obs.rows.push(Row {
                            q: q.clone(),
                            kind: RowKind::Distance { distance_m: *d },
                        });
                    }
                }
            }
        }
    }
    obs
}

/// Identifies `choice` from `obs` on `chain` at unit weights (residuals in metres), with the
/// model terms of [`crate::model::terms`] (lumped link weights for `compliance`: a device file
/// carries no link masses).
pub(crate) fn solve(
    chain: &Chain,
    obs: Observations,
    choice: ModelName,
    sigma_m: Option<f64>,
) -> Result<(CalibrationProblem, Identified)> {
    let n_rows = obs.rows.len();
    let terms = crate::model::terms(choice, chain.joint_names(), &[])?;
    let problem =
        CalibrationProblem::on_tree(Tree::single(chain.clone()), obs, Weights::default(), terms)
            .context("building the calibration problem")?;
    let x0 = problem.initial_guess();
    let identified = identify(&problem, x0, &identify_config(sigma_m))
        .with_context(|| format!("identifying parameters from {n_rows} configurations"))?;
    Ok((problem, identified))
}

/// The original of every row of every socket (every log) of `sets`
/// ([`crate::fit::originals`]): the rows' values as the fit sees them (joint readings, and a
/// log's distance), bit for bit with −0 as +0, as the readers compare rows for repeats.
pub(crate) fn set_originals(sets: &[DataSet]) -> Vec<Vec<Vec<usize>>> {
    let bits = |v: &[f64]| v.iter().map(|x| (x + 0.0).to_bits()).collect::<Vec<u64>>();
    (sets.iter())
        .map(|s| match s {
            DataSet::Sockets(p) => (p.sockets.iter())
                .map(|s| crate::fit::originals(s.q.iter().map(|q| bits(q))))
                .collect(),
            DataSet::Distances { q, distance_m, .. } => {
                vec![crate::fit::originals(q.iter().zip(distance_m).map(
                    |(q, d)| {
                        let mut key = bits(q);
                        key.push((d + 0.0).to_bits());
                        key
                    },
                ))]
            }
        })
        .collect()
}

/// Repeated k-fold cross-validation with time-contiguous blocks per socket: repeat `r` of
/// `repeats` shifts every block boundary by `r/repeats` of a block (a circular shift of the
/// rows), so that each row is held out once per repeat with different neighbours; a row that
/// repeats an earlier row of its socket or log is held out with it
/// ([`crate::fit::folds_of_rows`]).
pub(crate) fn cross_validate(
    chain: &Chain,
    sets: &[DataSet],
    plan: &Plan,
    choice: ModelName,
    repeats: usize,
) -> Result<HeldOut> {
    let lens: Vec<Vec<usize>> = sets
        .iter()
        .map(|s| match s {
            DataSet::Sockets(p) => p.sockets.iter().map(|s| s.q.len()).collect(),
            DataSet::Distances { q, .. } => vec![q.len()],
        })
        .collect();
    let k = plan.folds;
    let repeats = repeats.max(1);
    // A row that repeats an earlier row of its socket or log (the same values, bit for bit)
    // is held out with it: per repeat, set, socket, the fold of each row.
    let originals = set_originals(sets);
    let folds: Vec<Vec<Vec<Vec<usize>>>> = (0..repeats)
        .map(|r| {
            (originals.iter())
                .map(|set| {
                    (set.iter())
                        .map(|socket| folds_of_rows(socket, k, r, repeats))
                        .collect()
                })
                .collect()
        })
        .collect();
    let block = |r: usize, set: usize, socket: usize, row: usize| folds[r][set][socket][row];
    // Row order: sets, sockets, rows, as the evaluation loop below visits them.
    // Blocks of the first repeat, numbered (set, socket, fold) in that order.
    let mut sq_sum: Vec<f64> = Vec::new();
    let mut block_id: Vec<usize> = Vec::new();
    let mut first_block = 0;
    for (set, socket_lens) in lens.iter().enumerate() {
        for (socket, &n) in socket_lens.iter().enumerate() {
            for row in 0..n {
                block_id.push(first_block + block(0, set, socket, row));
                sq_sum.push(0.0);
            }
            first_block += k;
        }
    }
    for r in 0..repeats {
        for fold in 0..k {
            let obs = observations(sets, plan.socket_distance_m, &|s, sk, row| {
                block(r, s, sk, row) != fold
            });
            let (problem, identified) = solve(chain, obs, choice, plan.sigma_m)?;
            let model = problem.model(identified.fit.x.as_ref());
            let points = problem.points(identified.fit.x.as_ref());
            let mut point_base = 0;
            let mut idx = 0;
            for (set_idx, set) in sets.iter().enumerate() {
                match set {
                    DataSet::Sockets(p) => {
                        for (socket_idx, socket) in p.sockets.iter().enumerate() {
                            for (row_idx, q) in socket.q.iter().enumerate() {
                                if block(r, set_idx, socket_idx, row_idx) == fold {
                                    sq_sum[idx] += (model.end_point(q)
                                        - points[point_base + socket_idx])
                                        .norm_squared();
                                }
                                idx += 1;
                            }
                        }
                        point_base += p.sockets.len();
                    }
                    DataSet::Distances { q, distance_m, .. } => {
                        for (row_idx, (q, d)) in q.iter().zip(distance_m).enumerate() {
                            if block(r, set_idx, 0, row_idx) == fold {
                                sq_sum[idx] += (model.end_point(q).coords.norm() - d).powi(2);
                            }
                            idx += 1;
                        }
                    }
                }
            }
        }
    }
    if sq_sum.is_empty() {
        bail!("cross-validation held out no row");
    }
    Ok(HeldOut {
        sq_errors: sq_sum.iter().map(|v| v / repeats as f64).collect(),
        block: block_id,
    })
}
