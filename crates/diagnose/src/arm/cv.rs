//! Blocked cross-validation of a linear model about the estimate, and the column operations
//! the stages share (appending columns, the columns visible beside a baseline).

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::problem::Rows;
use super::{CV_REPEATS, VISIBLE_TOL};
use crate::solve::lstsq_leverage;
use crate::stats::{f_sf, largest_column_norm, mean, pivoted_basis_beside};

/// The fold of each configuration in each of [`CV_REPEATS`] repeats (contiguous blocks within
/// each group, repeat `r` shifting the boundaries by `r/CV_REPEATS` of a block,
/// [`hapcal_calibrate::calibrate`]'s scheme), and each configuration's block (group, fold) in
/// the first repeat: the independent units of the standard errors.
pub(super) fn folds_of(group: &[usize], k: usize) -> (Vec<Vec<usize>>, Vec<usize>) {
    let n_groups = group.iter().max().map_or(0, |g| g + 1);
    let mut size = vec![0usize; n_groups];
    for &g in group {
        size[g] += 1;
    }
    let mut folds: Vec<Vec<usize>> = (0..CV_REPEATS)
        .map(|_| Vec::with_capacity(group.len()))
        .collect();
    let mut block = Vec::with_capacity(group.len());
    let mut seen = vec![0usize; n_groups];
    for &g in group {
        let (pos, n) = (seen[g], size[g].max(1));
        seen[g] += 1;
        for (r, f) in folds.iter_mut().enumerate() {
            let shifted = (pos * k * CV_REPEATS + r * n) % (n * k * CV_REPEATS);
            f.push(shifted / (n * CV_REPEATS));
        }
        block.push(g * k + folds[0][folds[0].len() - 1]);
    }
    (folds, block)
}

/// Held-out results of one linear model, averaged over the repeats.
#[derive(Clone)]
pub(super) struct HeldOut {
    /// Per configuration: weighted squared held-out error (every residual kind).
    pub(super) score: Vec<f64>,
    /// Per configuration: squared 3-D position error, m².
    pub(super) position_m2: Vec<f64>,
    /// Per configuration: the floor of `position_m2` (σ²(1 + h) summed), m².
    pub(super) floor_m2: Vec<f64>,
}

impl HeldOut {
    pub(super) fn mse(&self) -> f64 {
        mean(&self.position_m2)
    }
}

/// Repeated blocked k-fold cross-validation of the linear model `a·δ ≈ r` (weighted
/// residuals); `folds[r][c]` is configuration `c`'s fold in repeat `r`. The fits of the folds
/// are independent and solved in parallel ([`lstsq_leverage`]); their held-out errors are
/// added up in the order of the folds, so the result does not depend on the threads.
pub(super) fn cross_validate(
    a: &DMatrix<f64>,
    r: &DVector<f64>,
    rows: &Rows,
    folds: &[Vec<usize>],
    k: usize,
    floor_var: Option<f64>,
) -> HeldOut {
    let n_c = rows.n_configurations();
    let mut out = HeldOut {
        score: vec![0.0; n_c],
        position_m2: vec![0.0; n_c],
        floor_m2: vec![0.0; n_c],
    };
    let w = 1.0 / folds.len().max(1) as f64;
    let jobs: Vec<(&[usize], usize)> = (folds.iter())
        .flat_map(|fold| (0..k).map(move |f| (fold.as_slice(), f)))
        .collect();
    let fits: Vec<Option<HeldOutFold>> = (jobs.par_iter())
        .map(|&(fold, f)| fit_fold(a, r, rows, fold, f, floor_var.is_some()))
        .collect();
    for fit in fits.iter().flatten() {
        for (p, &i) in fit.test.iter().enumerate() {
            let e = fit.e[p];
            let c = rows.res[i].1;
            out.score[c] += w * e * e;
            if let Some(sigma) = rows.res[i].0.length_sigma() {
                out.position_m2[c] += w * (e * sigma).powi(2);
                if let Some(v) = floor_var {
                    out.floor_m2[c] += w * v * (1.0 + fit.h[p].max(0.0));
                }
            }
        }
    }
    out
}

/// The held-out rows of one fold, their errors and (if asked) leverages.
struct HeldOutFold {
    test: Vec<usize>,
    e: Vec<f64>,
    h: Vec<f64>,
}

/// Fits `a·δ ≈ r` on the rows outside fold `f` (`fold[c]`: configuration `c`'s fold) and
/// predicts the rows in it; `None` when either set is empty.
fn fit_fold(
    a: &DMatrix<f64>,
    r: &DVector<f64>,
    rows: &Rows,
    fold: &[usize],
    f: usize,
    leverage: bool,
) -> Option<HeldOutFold> {
    let held = |i: usize| {
        let c = rows.res[i].1;
        c != usize::MAX && fold[c] == f
    };
    let train: Vec<usize> = (0..r.len()).filter(|&i| !held(i)).collect();
    let test: Vec<usize> = (0..r.len()).filter(|&i| held(i)).collect();
    if test.is_empty() || train.is_empty() {
        return None;
    }
    let at = a.select_rows(&train);
    let bt = DVector::from_iterator(train.len(), train.iter().map(|&i| r[i]));
    let a_test = a.select_rows(&test);
    let no_rows = DMatrix::zeros(0, a.ncols());
    let (x, h) = lstsq_leverage(&at, &bt, if leverage { &a_test } else { &no_rows });
    let predicted = &a_test * &x;
    let e = (test.iter().enumerate())
        .map(|(p, &i)| r[i] - predicted[p])
        .collect();
    Some(HeldOutFold { test, e, h })
}

/// One-sided p-value of a mean `m` with standard error `se` being ≤ 0, Student t with `dof`.
pub(super) fn one_sided_p(m: f64, se: f64, dof: f64) -> f64 {
    if !(se.is_finite() && se > 0.0) {
        return if m > 0.0 && se == 0.0 { 0.0 } else { 1.0 };
    }
    let t = m / se;
    let two = f_sf(t * t, 1.0, dof.max(1.0));
    if t > 0.0 { 0.5 * two } else { 1.0 - 0.5 * two }
}

/// `a` with the columns of `parts` appended, in order.
pub(super) fn beside(a: &DMatrix<f64>, parts: &[&DMatrix<f64>]) -> DMatrix<f64> {
    let n = a.ncols() + parts.iter().map(|p| p.ncols()).sum::<usize>();
    let mut out = DMatrix::zeros(a.nrows(), n);
    out.columns_mut(0, a.ncols()).copy_from(a);
    let mut at = a.ncols();
    for p in parts {
        out.columns_mut(at, p.ncols()).copy_from(*p);
        at += p.ncols();
    }
    out
}

/// The columns of a candidate `cols` visible beside the baseline `base` (`qb` its orthonormal
/// basis): pivoted against `qb` at [`VISIBLE_TOL`] of the baseline's largest column
/// ([`pivoted_basis_beside`]); returns their orthonormal basis and their indices.
pub(super) fn visible_columns(
    cols: &DMatrix<f64>,
    qb: &DMatrix<f64>,
    base: &DMatrix<f64>,
) -> (DMatrix<f64>, Vec<usize>) {
    let (qc, picked) = pivoted_basis_beside(cols, qb, VISIBLE_TOL, largest_column_norm(base));
    let visible = (0..cols.ncols()).filter(|&c| picked[c].is_some()).collect();
    (qc, visible)
}
