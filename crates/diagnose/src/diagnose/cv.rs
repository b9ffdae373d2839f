//! Cross-validation over time-contiguous folds, and the baseline a round tests against: its
//! identifiable columns, their orthonormal basis and its held-out residuals.

use nalgebra::{DMatrix, DVector};

use crate::model::{Linear, RANK_TOL};
use crate::solve::lstsq;
use crate::stats::{mean, pivoted_basis};

/// Cross-validated distance residuals.
pub(super) struct Cv {
    /// Held-out residual per sample, m.
    pub(super) e: Vec<f64>,
    /// Its variance under the floor, m².
    pub(super) var: Vec<f64>,
    /// σ_i² per sample (spec), m².
    pub(super) sigma2: Vec<f64>,
}

impl Cv {
    pub(super) fn mse(&self) -> f64 {
        mean(self.e.iter().map(|e| e * e))
    }
    pub(super) fn floor(&self) -> f64 {
        mean(self.var.iter().copied())
    }
    pub(super) fn chi2(&self) -> f64 {
        self.e
            .iter()
            .zip(&self.var)
            .map(|(e, v)| e * e / v.max(1e-300))
            .sum()
    }
}

/// Held-out residuals of the linear model with columns `cols` of `lin.j` and extra `cand`
/// columns, folds of time-contiguous samples.
pub(super) fn cross_validate(
    lin: &Linear,
    cols: &[usize],
    cand: Option<&DMatrix<f64>>,
    folds: usize,
    n: usize,
) -> Cv {
    let base = lin.j.select_columns(cols);
    let a = match cand {
        Some(c) if c.ncols() > 0 => {
            let mut a = DMatrix::zeros(base.nrows(), base.ncols() + c.ncols());
            a.columns_mut(0, base.ncols()).copy_from(&base);
            a.columns_mut(base.ncols(), c.ncols()).copy_from(c);
            a
        }
        _ => base,
    };
    let fold_of = |s: usize| s * folds / n.max(1);
    let mut e = vec![0.0; n];
    let mut var = vec![0.0; n];
    let mut sigma2 = vec![0.0; n];
    for f in 0..folds {
        let train: Vec<usize> = (0..a.nrows())
            .filter(|&r| fold_of(lin.sample[r]) != f)
            .collect();
        if train.is_empty() {
            continue;
        }
        let at = a.select_rows(&train);
        let bt = DVector::from_iterator(train.len(), train.iter().map(|&r| lin.r[r]));
        let (x, cov) = lstsq(&at, &bt);
        for i in (0..n).filter(|&i| fold_of(i) == f) {
            let row = a.row(i);
            let pred = (row * &x)[0];
            let v = (row * &cov * row.transpose())[0];
            let sd = lin.sigma[i];
            e[i] = (lin.r[i] - pred) * sd;
            var[i] = sd * sd * (1.0 + v);
            sigma2[i] = sd * sd;
        }
    }
    Cv { e, var, sigma2 }
}

/// The baseline's identifiable columns and orthonormal basis at a linearisation.
pub(super) struct Base {
    pub(super) lin: Linear,
    pub(super) cols: Vec<usize>,
    pub(super) q: DMatrix<f64>,
    pub(super) r_perp: DVector<f64>,
    pub(super) rss: f64,
    pub(super) cv: Cv,
}

impl Base {
    pub(super) fn new(lin: Linear, n_cols_base: usize, folds: usize, n: usize) -> Base {
        let jb = lin.j.columns(0, n_cols_base).into_owned();
        let (q, picked) = pivoted_basis(&jb, &DMatrix::zeros(jb.nrows(), 0), RANK_TOL);
        let cols: Vec<usize> = (0..picked.len()).filter(|&c| picked[c].is_some()).collect();
        let r_perp = &lin.r - &q * (q.transpose() * &lin.r);
        let rss = r_perp.norm_squared();
        let cv = cross_validate(&lin, &cols, None, folds, n);
        Base {
            lin,
            cols,
            q,
            r_perp,
            rss,
            cv,
        }
    }
    pub(super) fn dof(&self) -> f64 {
        (self.lin.r.len() as f64 - self.cols.len() as f64).max(1.0)
    }
    /// The in-sample weighted excess `RSS − dof`.
    pub(super) fn excess(&self) -> f64 {
        self.rss - self.dof()
    }
}
