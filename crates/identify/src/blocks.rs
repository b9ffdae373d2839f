//! Streaming back end: the Jacobian is reduced to its R factor block by block, so the memory
//! of a linearisation does not grow with the number of residuals.
//!
//! Source: the tall-skinny QR (TSQR) of J. Demmel, L. Grigori, M. Hoemmen, J. Langou,
//! "Communication-optimal parallel and sequential QR and LU factorizations", SIAM J. Sci.
//! Comput. 34 (2012): each leaf reduces its rows to an `(n+1) × (n+1)` triangle by Householder
//! QR of `[R; J_b r_b]`, and the leaves' triangles are merged the same way. The normal
//! equations `JᵀJ` are never formed (their condition number is the square of `J`'s; Björck,
//! *Numerical Methods for Least Squares Problems*, 1996, §2.2).
//!
//! Determinism: the rows are split into [`N_LEAVES`] leaves whatever the number of threads,
//! each leaf is reduced sequentially, and the leaves are merged in index order, so the result
//! is bit-identical for any thread count.

use std::ops::Range;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::factor as qr_factor;
use faer::{Col, ColMut, ColRef, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::error::Error;
use crate::lm::{Fit, Linearised, LmConfig, ScaledQr, Termination, check_inputs, run};
use crate::problem::{EvalError, ParamLayout, Problem};

/// A problem whose residuals split into consecutive row blocks that can be evaluated
/// independently (and concurrently): what the streaming back end needs.
///
/// Block `b` covers the residual rows [`RowBlocks::block_rows`]`(b)`; the blocks are
/// consecutive, in order, and cover `0..m` exactly. Blocks of a few hundred rows amortise any
/// per-block set-up; the memory of a block evaluation is `len × n` values.
pub trait RowBlocks: Sync {
    /// Number of blocks.
    fn n_blocks(&self) -> usize;
    /// Residual rows of block `block` (a range of `0..m`).
    ///
    /// # Panics
    /// May panic if `block >= n_blocks()`.
    fn block_rows(&self, block: usize) -> Range<usize>;
    /// Writes the residuals of block `block` into `out` (length `block_rows(block).len()`),
    /// in the same units as [`Problem::residuals`](crate::Problem::residuals).
    ///
    /// # Errors
    /// [`EvalError`] when the model cannot be evaluated at `x`.
    fn block_residuals(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        out: ColMut<'_, f64>,
    ) -> Result<(), EvalError>;
    /// Writes the residuals (`r_out`, length `len`) and the Jacobian rows (`jac`, `len × n`,
    /// columns = layout entries) of block `block`, `len = block_rows(block).len()`.
    ///
    /// # Errors
    /// [`EvalError`] when the model cannot be evaluated at `x`.
    fn block_jacobian(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        r_out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError>;
}

/// Number of leaves of the reduction tree, fixed so that results do not depend on the
/// number of threads (enough to balance 2–16 threads).
pub const N_LEAVES: usize = 64;

/// What went wrong while streaming a linearisation.
#[derive(Debug)]
pub(crate) enum StreamError {
    /// The problem could not be evaluated.
    Eval(EvalError),
    /// A residual (row index) or a Jacobian entry (row, column) is not finite.
    NonFinite { row: usize, col: Option<usize> },
}

/// The linearisation of `r` at `x`: the upper-triangular `(n+1) × (n+1)` factor `R₊` of
/// `[J r]` (`R₊ᵀR₊ = [J r]ᵀ[J r]`), so `R₊[..n, ..n]` is an R factor of `J`, `R₊[..n, n]`
/// is `Q₁ᵀr` and `|R₊[n, n]|` the norm of the part of `r` outside the range of `J`.
pub(crate) struct Linearisation {
    /// `R₊`, `(n+1) × (n+1)`, upper triangular.
    pub(crate) r_aug: Mat<f64>,
    /// `‖r‖²`.
    pub(crate) r_norm_sq: f64,
}

fn leaf_ranges(n_blocks: usize) -> Vec<Range<usize>> {
    let n_leaves = N_LEAVES.min(n_blocks.max(1));
    (0..n_leaves)
        .map(|l| (l * n_blocks / n_leaves)..((l + 1) * n_blocks / n_leaves))
        .collect()
}

/// Reduces the rows of `stack` (`k × (n+1)`, `k ≥ n+1`) to their R factor in place: its top
/// `(n+1) × (n+1)` rows then hold `R` (zeros below the diagonal); the rows below are scratch.
pub(crate) fn triangularise(
    mut stack: MatMut<'_, f64>,
    q_coeff: MatMut<'_, f64>,
    buf: &mut MemBuffer,
) {
    qr_factor::qr_in_place(
        stack.as_mut(),
        q_coeff,
        Par::Seq,
        MemStack::new(buf),
        Default::default(),
    );
    // Only the triangle is read afterwards (rows below it are overwritten by the next rows or
    // dropped): zero the Householder vectors stored under its diagonal.
    let n1 = stack.ncols().min(stack.nrows());
    for j in 0..n1 {
        for i in (j + 1)..n1 {
            stack[(i, j)] = 0.0;
        }
    }
}

/// One leaf: its blocks folded in sequence into an `(n+1) × (n+1)` triangle, each block by the
/// structured Householder update of [`fold_rows`](crate::householder::fold_rows) while its
/// `[J_b | r_b]` is still in cache.
fn reduce_leaf(
    p: &dyn RowBlocks,
    x: ColRef<'_, f64>,
    n: usize,
    blocks: Range<usize>,
) -> Result<(Mat<f64>, f64), StreamError> {
    let n1 = n + 1;
    let max_len = blocks
        .clone()
        .map(|b| p.block_rows(b).len())
        .max()
        .unwrap_or(0);
    let mut tri = vec![0.0; n1 * n1];
    let mut rows = vec![0.0; max_len.max(1) * n1];
    let mut r_norm_sq = 0.0;
    for b in blocks {
        let range = p.block_rows(b);
        let len = range.len();
        if len == 0 {
            continue;
        }
        // The block writes `[J_b | r_b]` (len × n1, leading dimension max_len).
        let block = MatMut::from_column_major_slice_with_stride_mut(&mut rows, len, n1, max_len);
        let (jac, r_col) = block.split_at_col_mut(n);
        p.block_jacobian(x, b, r_col.col_mut(0), jac)
            .map_err(StreamError::Eval)?;
        let block = MatRef::from_column_major_slice_with_stride(&rows, len, n1, max_len);
        if !block.is_all_finite() {
            return Err(first_non_finite(block, n, range.start));
        }
        r_norm_sq += block.col(n).squared_norm_l2();
        crate::householder::fold_rows(&mut tri, n1, &mut rows, len, max_len);
    }
    Ok((Mat::from_fn(n1, n1, |i, j| tri[j * n1 + i]), r_norm_sq))
}

/// The first non-finite entry of a block's `[J_b | r_b]` (residual first, row by row), as a
/// [`StreamError::NonFinite`] with the global row index (`first_row` + local row).
fn first_non_finite(rows: MatRef<'_, f64>, n: usize, first_row: usize) -> StreamError {
    for i in 0..rows.nrows() {
        if !rows[(i, n)].is_finite() {
            return StreamError::NonFinite {
                row: first_row + i,
                col: None,
            };
        }
        if let Some(j) = (0..n).find(|&j| !rows[(i, j)].is_finite()) {
            return StreamError::NonFinite {
                row: first_row + i,
                col: Some(j),
            };
        }
    }
    StreamError::NonFinite {
        row: first_row,
        col: None,
    }
}

/// Streams `[J r]` at `x` through the blocks of `p` into its R factor (`n` parameters).
///
/// Work: `≈ 2(n+1)²` flops per residual for the QR updates, plus the problem's evaluation;
/// memory: [`N_LEAVES`] triangles plus one block per thread.
pub(crate) fn linearise(
    p: &dyn RowBlocks,
    x: ColRef<'_, f64>,
    n: usize,
) -> Result<Linearisation, StreamError> {
    let n1 = n + 1;
    let leaves = leaf_ranges(p.n_blocks());
    let reduced: Vec<Result<(Mat<f64>, f64), StreamError>> = leaves
        .into_par_iter()
        .map(|blocks| reduce_leaf(p, x, n, blocks))
        .collect();
    // Merge in index order: [R; R_leaf] → R.
    let mut stack = Mat::<f64>::zeros(2 * n1, n1);
    let block_size = qr_factor::recommended_block_size::<f64>(2 * n1, n1);
    let mut q_coeff = Mat::<f64>::zeros(block_size, n1);
    let mut buf = MemBuffer::new(qr_factor::qr_in_place_scratch::<f64>(
        2 * n1,
        n1,
        block_size,
        Par::Seq,
        Default::default(),
    ));
    let mut r_norm_sq = 0.0;
    for leaf in reduced {
        let (r_leaf, s) = leaf?;
        r_norm_sq += s;
        stack.as_mut().subrows_mut(n1, n1).copy_from(&r_leaf);
        triangularise(stack.as_mut(), q_coeff.as_mut(), &mut buf);
    }
    Ok(Linearisation {
        r_aug: stack.subrows(0, n1).to_owned(),
        r_norm_sq,
    })
}

/// `‖r(x)‖²` streamed through the blocks of `p` (deterministic like [`linearise`]).
pub(crate) fn residual_norm_sq(p: &dyn RowBlocks, x: ColRef<'_, f64>) -> Result<f64, StreamError> {
    let leaves = leaf_ranges(p.n_blocks());
    let sums: Vec<Result<f64, StreamError>> = leaves
        .into_par_iter()
        .map(|blocks| {
            let max_len = blocks
                .clone()
                .map(|b| p.block_rows(b).len())
                .max()
                .unwrap_or(0);
            let mut r = Col::<f64>::zeros(max_len);
            let mut sum = 0.0;
            for b in blocks {
                let range = p.block_rows(b);
                let len = range.len();
                p.block_residuals(x, b, r.as_mut().subrows_mut(0, len))
                    .map_err(StreamError::Eval)?;
                for i in 0..len {
                    if !r[i].is_finite() {
                        return Err(StreamError::NonFinite {
                            row: range.start + i,
                            col: None,
                        });
                    }
                    sum += r[i] * r[i];
                }
            }
            Ok(sum)
        })
        .collect();
    let mut total = 0.0;
    for s in sums {
        total += s?;
    }
    Ok(total)
}

/// The R factor `(k+1) × (k+1)` of `[J_S r]` for the column subset `cols` (length `k`) of a
/// linearisation: a QR of the `(n+1) × (k+1)` columns `cols ++ [n]` of `R₊`, which have the
/// same Gram matrix as `[J_S r]`.
pub(crate) fn restrict(lin: &Linearisation, cols: &[usize]) -> Mat<f64> {
    let n = lin.r_aug.nrows() - 1;
    let k = cols.len();
    let sub = Mat::from_fn(n + 1, k + 1, |i, c| {
        let j = if c < k { cols[c] } else { n };
        lin.r_aug[(i, j)]
    });
    let mut r = sub.qr().R().to_owned();
    // `qr().R()` of an (n+1) × (k+1) matrix is min(n+1, k+1) × (k+1): k+1 rows here.
    for j in 0..r.ncols() {
        for i in (j + 1)..r.nrows() {
            r[(i, j)] = 0.0;
        }
    }
    r
}

/// The streamed linearisation as the LM iteration sees it (free columns only).
pub(crate) struct Streaming<'a> {
    p: &'a dyn RowBlocks,
    n: usize,
    free: &'a [usize],
    /// R factor of `[J_f r]`, `(n_f+1) × (n_f+1)`.
    r_f: Mat<f64>,
    /// The last full linearisation (all `n` columns), at the current point.
    pub(crate) full: Linearisation,
}

impl<'a> Streaming<'a> {
    pub(crate) fn new(
        p: &'a dyn RowBlocks,
        n: usize,
        free: &'a [usize],
        full: Linearisation,
    ) -> Self {
        let r_f = restrict(&full, free);
        Self {
            p,
            n,
            free,
            r_f,
            full,
        }
    }
}

impl Linearised for Streaming<'_> {
    fn trial_norm(&mut self, x_trial: ColRef<'_, f64>, _may_continue: bool) -> f64 {
        residual_norm_sq(self.p, x_trial).map_or(f64::INFINITY, f64::sqrt)
    }
    fn accept(&mut self) {}
    fn relinearise(&mut self, x: ColRef<'_, f64>) -> Result<(), Termination> {
        let full = linearise(self.p, x, self.n).map_err(|e| match e {
            StreamError::Eval(e) => Termination::EvalFailed(e),
            StreamError::NonFinite { .. } => Termination::Numerical,
        })?;
        self.r_f = restrict(&full, self.free);
        self.full = full;
        Ok(())
    }
    fn col_norms(&self) -> Vec<f64> {
        (0..self.free.len())
            .map(|j| self.r_f.col(j).subrows(0, j + 1).norm_l2())
            .collect()
    }
    fn gradient_abs(&self, j: usize) -> f64 {
        let nf = self.free.len();
        (0..=j)
            .map(|i| self.r_f[(i, j)] * self.r_f[(i, nf)])
            .sum::<f64>()
            .abs()
    }
    type Subproblem = ScaledQr;
    fn subproblem(&mut self, diag: &[f64]) -> ScaledQr {
        ScaledQr::from_triangle(self.r_f.as_ref(), diag)
    }
}

/// Converts a streaming failure at the initial guess into the dense path's error.
pub(crate) fn error_at_x0(e: StreamError, layout: &ParamLayout) -> Error {
    match e {
        StreamError::Eval(e) => Error::Eval(e),
        StreamError::NonFinite { row, col: None } => Error::NonFiniteResidual { index: row },
        StreamError::NonFinite { row, col: Some(j) } => Error::NonFiniteJacobian {
            row,
            name: layout.name(j).to_owned(),
        },
    }
}

/// [`levenberg_marquardt`](crate::levenberg_marquardt) on the streaming back end: the same
/// iteration (MINPACK `lmder`, Moré 1978), with `J` never stored: each linearisation streams
/// `[J r]` block by block into its `(n+1) × (n+1)` R factor (TSQR, see the module source),
/// and each trial point streams `‖r‖`. The QR of the scaled free columns is then taken from
/// that triangle, which has the same Gram matrix as `J_f`, as on the dense path
/// (unpivoted unless near singular), so the steps equal the dense path's up to rounding.
///
/// Memory: `O(n²)` per leaf ([`N_LEAVES`] leaves) plus one block per thread, independent of
/// `m`. [`Fit::residuals`] is empty (length 0); [`Fit::cost`] is `½‖r‖²` at the estimate.
/// Blocks are evaluated in parallel on rayon's global pool; the result does not depend on the
/// number of threads.
///
/// # Errors
/// [`Error::NoRowBlocks`] if the problem does not provide [`Problem::row_blocks`]; otherwise as
/// [`levenberg_marquardt`](crate::levenberg_marquardt).
pub fn levenberg_marquardt_streaming(
    p: &impl Problem,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
) -> Result<Fit, Error> {
    let blocks = p.row_blocks().ok_or(Error::NoRowBlocks)?;
    let layout = p.layout();
    let n = layout.len();
    check_inputs(p, x0.as_ref(), free, cfg)?;
    let lin = linearise(blocks, x0.as_ref(), n).map_err(|e| error_at_x0(e, layout))?;
    Ok(streaming_fit(blocks, n, x0, free, cfg, lin).0)
}

/// The upper-triangular `(k+1) × (k+1)` R factor `R₊` of `[J_S r]` over the rows `rows` of
/// `jac` (`m × n`) and `r` (length `m`), `J_S` the columns `cols` (length `k`, in that order):
/// `R₊ᵀR₊ = [J_S r]ᵀ[J_S r]` over those rows, folded 256 rows at a time
/// by the structured Householder update (TSQR, see the module source). The triangles of
/// disjoint blocks of rows, stacked ([`stacked_r_factor`]), give the R factor of their union.
///
/// # Panics
/// If a row or column index is out of range.
pub fn rows_r_factor(
    jac: MatRef<'_, f64>,
    r: ColRef<'_, f64>,
    rows: &[usize],
    cols: &[usize],
) -> Mat<f64> {
    let n1 = cols.len() + 1;
    let chunk = crate::lm::FOLD_ROWS.min(rows.len()).max(1);
    let mut tri = vec![0.0; n1 * n1];
    let mut block = vec![0.0; chunk * n1];
    for part in rows.chunks(chunk) {
        let len = part.len();
        for (c, dst) in block.chunks_exact_mut(len).take(n1).enumerate() {
            match cols.get(c) {
                Some(&j) => {
                    let col = jac.col(j);
                    for (d, &i) in dst.iter_mut().zip(part) {
                        *d = col[i];
                    }
                }
                None => {
                    for (d, &i) in dst.iter_mut().zip(part) {
                        *d = r[i];
                    }
                }
            }
        }
        crate::householder::fold_rows(&mut tri, n1, &mut block, len, len);
    }
    Mat::from_fn(n1, n1, |i, j| tri[j * n1 + i])
}

/// The upper-triangular R factor of the triangles `parts` stacked (each `n1 × n1`, upper
/// triangular, the R factor of a block of rows): `RᵀR = Σ TᵀT`, the R factor of the union of
/// their rows ([`rows_r_factor`]): the first triangle, and each later one folded into it by
/// the structured Householder update.
///
/// # Panics
/// If the parts are not all `n1 × n1` (`n1` the first one's), or the first is not upper
/// triangular.
pub fn stacked_r_factor(parts: &[MatRef<'_, f64>]) -> Mat<f64> {
    let n1 = parts.first().map_or(0, |t| t.nrows());
    let mut tri = vec![0.0; n1 * n1];
    let mut block = vec![0.0; n1 * n1];
    for (p, t) in parts.iter().enumerate() {
        assert!(
            t.nrows() == n1 && t.ncols() == n1,
            "triangle {} × {}, expected {n1} × {n1}",
            t.nrows(),
            t.ncols()
        );
        // The first is an R factor already: the others fold into it.
        let dst = if p == 0 { &mut tri } else { &mut block };
        for j in 0..n1 {
            for i in 0..n1 {
                dst[j * n1 + i] = t[(i, j)];
            }
        }
        if p == 0 {
            assert!(
                (0..n1).all(|j| (j + 1..n1).all(|i| tri[j * n1 + i] == 0.0)),
                "the first triangle is not upper triangular"
            );
        } else {
            crate::householder::fold_rows(&mut tri, n1, &mut block, n1, n1);
        }
    }
    Mat::from_fn(n1, n1, |i, j| tri[j * n1 + i])
}

/// The R factor (`n × n`, `n = p.layout().len()`) of the Jacobian of `p` at `x`, streamed
/// through its row blocks as [`levenberg_marquardt_streaming`] linearises (TSQR, see the module
/// source): `Rᵀ·R = Jᵀ·J`, so it carries the rows' identifiability and information at the
/// memory of [`N_LEAVES`] triangles and one block per thread, never `J`.
///
/// # Errors
/// [`Error::NoRowBlocks`] if the problem does not provide [`Problem::row_blocks`]; an evaluation
/// error or a non-finite entry of `J` or `r`, as [`levenberg_marquardt_streaming`] at `x0`.
pub fn jacobian_r_factor(p: &impl Problem, x: ColRef<'_, f64>) -> Result<Mat<f64>, Error> {
    let blocks = p.row_blocks().ok_or(Error::NoRowBlocks)?;
    let n = p.layout().len();
    let lin = linearise(blocks, x, n).map_err(|e| error_at_x0(e, p.layout()))?;
    // The first n columns of the R of [J r] are the R of J: the QR of a column never touches
    // the columns before it.
    Ok(lin.r_aug.submatrix(0, 0, n, n).to_owned())
}

/// The LM iteration on a linearisation at `x0`; returns the fit and the last linearisation
/// (at the fit's estimate, or at the point before the last accepted step when the stopping
/// test fired right after it).
pub(crate) fn streaming_fit(
    blocks: &dyn RowBlocks,
    n: usize,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
    lin: Linearisation,
) -> (Fit, Linearisation, bool) {
    let f_norm = lin.r_norm_sq.sqrt();
    if free.is_empty() {
        let cost = 0.5 * lin.r_norm_sq;
        return (Fit::nothing_free(x0, cost, Col::zeros(0)), lin, true);
    }
    let mut s = Streaming::new(blocks, n, free, lin);
    let run = run(&mut s, x0, free, cfg, f_norm);
    let current = run.linearised_at_x;
    let cost = 0.5 * run.f_norm * run.f_norm;
    (
        Fit {
            x: run.x,
            termination: run.termination,
            n_evaluations: run.n_evaluations,
            n_jacobians: run.n_jacobians,
            n_iterations: run.n_iterations,
            cost,
            residuals: Col::zeros(0),
        },
        s.full,
        current,
    )
}
