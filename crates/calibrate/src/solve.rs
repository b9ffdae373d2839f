//! The fits of socket recordings and distance logs ([`DataSet`]): their observations, the
//! identification of one model from them, and its repeated blocked cross-validation. The
//! `hapcal calibrate` workflow of these data and the geometric baseline build on them.

use anyhow::{Context, Result, bail};
use hapcal_identify::{Identified, Problem, identify};
use hapcal_kinematics::{Chain, Tree};
use hapcal_problems::{CalibrationProblem, Observations, PointDistance, Row, RowKind, Weights};

use std::collections::HashMap;

use crate::data::DataSet;
use crate::fit::{HeldOut, folds_of_rows, identify_config};
use crate::inputs::Plan;
use crate::model::ModelName;
use crate::report::Downweighted;
use crate::robust::{Bound, Dim, Round, Weighted, bound_gross_errors, redundancy, residuals_at};

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
                                q: q[..].into(),
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
                            q: q[..].into(),
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
/// carries no link masses). `scale` ([`residual_scale`]) multiplies the rows' residuals and
/// Jacobian rows: `√w` of the rows the Huber loss bounded ([`winsorize`]); empty or all one,
/// the rows as measured.
pub(crate) fn solve(
    chain: &Chain,
    obs: Observations,
    choice: ModelName,
    sigma_m: Option<f64>,
    scale: &[f64],
) -> Result<(CalibrationProblem, Identified)> {
    let n_rows = obs.rows.len();
    let terms = crate::model::terms(choice, chain.joint_names(), &[])?;
    let problem =
        CalibrationProblem::on_tree(Tree::single(chain.clone()), obs, Weights::default(), terms)
            .context("building the calibration problem")?;
    let x0 = problem.initial_guess();
    let cfg = identify_config(sigma_m);
    let identified = if scale.iter().all(|&s| s == 1.0) {
        identify(&problem, x0, &cfg)
    } else {
        // The point-distance residuals follow the rows' and are never weighted.
        let mut full = scale.to_vec();
        full.resize(problem.n_residuals(), 1.0);
        let weighted = Weighted {
            inner: &problem,
            scale: &full,
        };
        identify(&weighted, x0, &cfg)
    }
    .with_context(|| format!("identifying parameters from {n_rows} configurations"))?;
    Ok((problem, identified))
}

/// A socket row or distance-log row the Huber loss bounded ([`winsorize`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RowBound {
    /// Its Huber weight, `corner/|e|` with `|e|` its residual norm in the judging fit, m/m
    /// ([`crate::robust::Bound::weight`]): every fit weights its residuals by it.
    pub weight: f64,
    /// The corner, m.
    pub corner_m: f64,
}

/// The Huber loss's bounds on socket rows and distance-log rows ([`winsorize`]), per row
/// `(set, socket, row)` (socket 0 for a log). Empty: nothing bounded.
pub(crate) type RowBounds = HashMap<(usize, usize, usize), RowBound>;

/// The rows of `sets` in [`observations`]' order: `(set, socket, row)` and the number of
/// residuals of the row (3 for a socket row, 1 for a distance).
fn row_ids(sets: &[DataSet]) -> Vec<((usize, usize, usize), usize)> {
    let mut ids = Vec::new();
    for (set_idx, set) in sets.iter().enumerate() {
        match set {
            DataSet::Sockets(p) => {
                for (socket_idx, socket) in p.sockets.iter().enumerate() {
                    ids.extend((0..socket.q.len()).map(|row| ((set_idx, socket_idx, row), 3)));
                }
            }
            DataSet::Distances { q, .. } => {
                ids.extend((0..q.len()).map(|row| ((set_idx, 0, row), 1)));
            }
        }
    }
    ids
}

/// The residual scale of the rows [`observations`] keeps with `keep`, for [`solve`]: the
/// rows' residuals in order, `√w` of `bounds`' weight on bounded rows and one elsewhere;
/// empty when `bounds` is.
pub(crate) fn residual_scale(
    sets: &[DataSet],
    bounds: &RowBounds,
    keep: &dyn Fn(usize, usize, usize) -> bool,
) -> Vec<f64> {
    if bounds.is_empty() {
        return Vec::new();
    }
    let mut scale = Vec::new();
    for (id, width) in row_ids(sets) {
        if keep(id.0, id.1, id.2) {
            let s = bounds.get(&id).map_or(1.0, |b| b.weight.sqrt());
            scale.extend(std::iter::repeat_n(s, width));
        }
    }
    scale
}

/// Gross errors of socket folders and distance logs bounded by the Huber loss
/// ([`crate::robust::bound_gross_errors`]): the geometric model fitted to every training row,
/// a row whose residual (its end point's distance from its socket point; a log's distance
/// error) lies beyond the corner down-weighted to `corner/|e|` (iteratively reweighted least
/// squares, [`crate::robust::Weighted`]), until the set of bounded rows and the scale no
/// longer change. Returns the weights every fit then gives the bounded rows ([`RowBounds`])
/// and the bounded rows with their file and line. Nothing when the geometric model cannot be
/// fitted, with fewer than 20 rows, or when the sets mix sockets and logs (their residuals
/// have no common scale).
pub(crate) fn winsorize(
    chain: &Chain,
    sets: &[DataSet],
    plan: &Plan,
) -> (RowBounds, Vec<Downweighted>) {
    let sockets = sets.iter().all(|s| matches!(s, DataSet::Sockets(_)));
    let logs = sets.iter().all(|s| matches!(s, DataSet::Distances { .. }));
    let (dim, width) = match (sockets, logs) {
        (true, false) => (Dim::Three, 3),
        (false, true) => (Dim::One, 1),
        _ => return (RowBounds::new(), Vec::new()),
    };
    let all = |_: usize, _: usize, _: usize| true;
    let ids = row_ids(sets);
    let n_row_residuals = ids.len() * width;
    let row_bounds = |bounds: &[Bound]| -> RowBounds {
        (bounds.iter())
            .map(|b| {
                let bound = RowBound {
                    weight: b.weight(),
                    corner_m: b.corner,
                };
                (ids[b.sample].0, bound)
            })
            .collect()
    };
    let bounds = bound_gross_errors(ids.len(), dim, |bounds| {
        let obs = observations(sets, plan.socket_distance_m, &all);
        let scale = residual_scale(sets, &row_bounds(bounds), &all);
        let (problem, identified) =
            solve(chain, obs, ModelName::Geometric, plan.sigma_m, &scale).ok()?;
        let redundancy = redundancy(problem.n_residuals(), identified.identifiability.kept.len())?;
        // The rows' residuals as measured.
        let r = residuals_at(&problem, identified.fit.x.as_ref()).ok()?;
        let rows: Vec<f64> = (0..n_row_residuals).map(|i| r[i]).collect();
        Some(Round {
            norms: (rows.chunks(width))
                .map(|e| e.iter().map(|v| v * v).sum::<f64>().sqrt())
                .collect(),
            redundancy,
        })
    });
    let listed = (bounds.iter())
        .map(|b| {
            let (set, socket, row) = ids[b.sample].0;
            let (file, line) = match &sets[set] {
                DataSet::Sockets(p) => (
                    &p.sockets[socket].file,
                    p.sockets[socket].line_numbers.get(row).copied(),
                ),
                DataSet::Distances { file, lines, .. } => (file, lines.get(row).copied()),
            };
            Downweighted {
                file: file.display().to_string(),
                line: line.unwrap_or(row as u64 + 1),
                marker: None,
                residual_m: b.norm,
                bound_m: b.corner,
            }
        })
        .collect();
    (row_bounds(&bounds), listed)
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
/// ([`crate::fit::folds_of_rows`]). Every fold's fit weights its bounded rows by `bounds`
/// ([`winsorize`]); a bounded row's held-out error is winsorized at its corner
/// ([`RowBound::corner_m`]), as the haptic and measurement workflows hold out their
/// winsorized rows.
pub(crate) fn cross_validate(
    chain: &Chain,
    sets: &[DataSet],
    plan: &Plan,
    choice: ModelName,
    repeats: usize,
    bounds: &RowBounds,
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
    // A bounded row's held-out error is winsorized at its corner, as its residual is in the
    // fits: as measured (tens of mm for a glitch) it would outweigh every other row's and
    // decide the comparison of the rungs by how each extrapolates to a wrong reading.
    let held_out = |set: usize, socket: usize, row: usize, sq: f64| -> f64 {
        bounds
            .get(&(set, socket, row))
            .map_or(sq, |b| sq.min(b.corner_m * b.corner_m))
    };
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
            let keep = |s: usize, sk: usize, row: usize| block(r, s, sk, row) != fold;
            let obs = observations(sets, plan.socket_distance_m, &keep);
            let scale = residual_scale(sets, bounds, &keep);
            let (problem, identified) = solve(chain, obs, choice, plan.sigma_m, &scale)?;
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
                                    let e = model.end_point(q) - points[point_base + socket_idx];
                                    sq_sum[idx] +=
                                        held_out(set_idx, socket_idx, row_idx, e.norm_squared());
                                }
                                idx += 1;
                            }
                        }
                        point_base += p.sockets.len();
                    }
                    DataSet::Distances { q, distance_m, .. } => {
                        for (row_idx, (q, d)) in q.iter().zip(distance_m).enumerate() {
                            if block(r, set_idx, 0, row_idx) == fold {
                                let e = model.end_point(q).coords.norm() - d;
                                sq_sum[idx] += held_out(set_idx, 0, row_idx, e * e);
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
