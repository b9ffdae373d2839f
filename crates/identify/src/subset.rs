//! A problem with some parameters held at fixed values: the model ladder's rungs (frames
//! only, joint offsets, …) fit subsets of one problem's parameters.

use std::ops::Range;
use std::sync::Mutex;

use faer::{Col, ColMut, ColRef, Mat, MatMut, MatRef};

use crate::{EvalError, ParamLayout, Problem, RowBlocks};

/// `problem` restricted to the parameters `free`; the others stay at their values in `x_full`.
///
/// Its layout is the free parameters' specs in ascending index order; residuals are the
/// problem's; the Jacobian is the problem's free columns. It has the problem's row blocks
/// ([`Problem::row_blocks`]) when the problem has them, each block's Jacobian its free
/// columns, so a long problem's subset streams as the problem does.
#[derive(Debug)]
pub struct Subset<'a, P: Problem + ?Sized> {
    problem: &'a P,
    free: Vec<usize>,
    x_full: Col<f64>,
    layout: ParamLayout,
    /// `0..free.len()`: every column of the subset.
    all: Vec<usize>,
    /// The problem's whole Jacobian of the last evaluation, kept for the next one rather than
    /// allocated and zeroed again at every evaluation.
    scratch: Mutex<Mat<f64>>,
}

impl<'a, P: Problem + ?Sized> Subset<'a, P> {
    /// The subset of `problem` whose free parameters are `free` (indices into its layout;
    /// sorted, duplicates and indices past the layout dropped), the others fixed at
    /// `x_full` (length `problem.layout().len()`; shorter is padded with zeros).
    pub fn new(problem: &'a P, mut free: Vec<usize>, x_full: Col<f64>) -> Self {
        let n = problem.layout().len();
        free.retain(|&i| i < n);
        free.sort_unstable();
        free.dedup();
        let x_full = Col::from_fn(n, |i| if i < x_full.nrows() { x_full[i] } else { 0.0 });
        let layout = ParamLayout::new(
            free.iter()
                .map(|&i| problem.layout().spec(i).clone())
                .collect(),
        );
        Self {
            problem,
            all: (0..free.len()).collect(),
            free,
            x_full,
            layout,
            scratch: Mutex::new(Mat::new()),
        }
    }

    /// Indices of the free parameters in the full layout.
    pub fn free(&self) -> &[usize] {
        &self.free
    }

    /// The free parameters' values in `x_full` (the start of a fit).
    pub fn initial_free(&self) -> Col<f64> {
        Col::from_fn(self.free.len(), |k| self.x_full[self.free[k]])
    }

    /// The full parameter vector with the free entries set to `x_free`.
    ///
    /// # Panics
    /// If `x_free.nrows() != free().len()`.
    #[track_caller]
    pub fn full_x(&self, x_free: ColRef<'_, f64>) -> Col<f64> {
        assert_eq!(x_free.nrows(), self.free.len(), "free parameter count");
        let mut x = self.x_full.clone();
        for (k, &i) in self.free.iter().enumerate() {
            x[i] = x_free[k];
        }
        x
    }

    /// `f` with the kept whole-Jacobian buffer, or a new one while another evaluation holds
    /// it.
    fn with_scratch<T>(&self, f: impl FnOnce(&mut Mat<f64>) -> T) -> T {
        match self.scratch.try_lock() {
            Ok(mut scratch) => f(&mut scratch),
            Err(_) => f(&mut Mat::new()),
        }
    }

    /// Copies the free parameters' columns of the problem's Jacobian `full` (rows × all
    /// parameters) into `jac` (rows × free parameters).
    fn free_columns(&self, full: MatRef<'_, f64>, mut jac: MatMut<'_, f64>) {
        for (k, &i) in self.free.iter().enumerate() {
            jac.as_mut().col_mut(k).copy_from(full.col(i));
        }
    }

    fn full_checked(&self, x_free: ColRef<'_, f64>) -> Result<Col<f64>, EvalError> {
        if x_free.nrows() != self.free.len() {
            return Err(EvalError {
                reason: format!(
                    "x has {} entries, expected {} free parameters",
                    x_free.nrows(),
                    self.free.len()
                ),
            });
        }
        Ok(self.full_x(x_free))
    }
}

impl<P: Problem + Sync + ?Sized> Problem for Subset<'_, P> {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    fn n_residuals(&self) -> usize {
        self.problem.n_residuals()
    }

    fn residuals(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) -> Result<(), EvalError> {
        let x = self.full_checked(x)?;
        self.problem.residuals(x.as_ref(), out)
    }

    fn jacobian(&self, x: ColRef<'_, f64>, jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.with_scratch(|scratch| {
            self.residuals_and_jacobian_columns(x, None, &self.all, jac, scratch)
        })
    }

    fn residuals_and_jacobian(
        &self,
        x: ColRef<'_, f64>,
        out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.with_scratch(|scratch| {
            self.residuals_and_jacobian_columns(x, Some(out), &self.all, jac, scratch)
        })
    }

    fn residuals_and_jacobian_columns(
        &self,
        x: ColRef<'_, f64>,
        out: Option<ColMut<'_, f64>>,
        cols: &[usize],
        jac: MatMut<'_, f64>,
        scratch: &mut Mat<f64>,
    ) -> Result<(), EvalError> {
        let x = self.full_checked(x)?;
        // The subset's column k is the problem's column free[k].
        let cols: Vec<usize> = cols.iter().map(|&k| self.free[k]).collect();
        (self.problem).residuals_and_jacobian_columns(x.as_ref(), out, &cols, jac, scratch)
    }

    fn row_blocks(&self) -> Option<&dyn RowBlocks> {
        self.problem.row_blocks().map(|_| self as &dyn RowBlocks)
    }
}

impl<P: Problem + ?Sized> Subset<'_, P> {
    /// The problem's row blocks (present whenever [`Problem::row_blocks`] of the subset is).
    fn blocks(&self) -> Result<&dyn RowBlocks, EvalError> {
        self.problem.row_blocks().ok_or_else(|| EvalError {
            reason: "the problem has no row blocks".to_owned(),
        })
    }
}

impl<P: Problem + Sync + ?Sized> RowBlocks for Subset<'_, P> {
    fn n_blocks(&self) -> usize {
        self.problem.row_blocks().map_or(0, RowBlocks::n_blocks)
    }

    fn block_rows(&self, block: usize) -> Range<usize> {
        self.problem
            .row_blocks()
            .map_or(0..0, |b| b.block_rows(block))
    }

    fn block_residuals(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        out: ColMut<'_, f64>,
    ) -> Result<(), EvalError> {
        let x = self.full_checked(x)?;
        self.blocks()?.block_residuals(x.as_ref(), block, out)
    }

    fn block_jacobian(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        r_out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        let x = self.full_checked(x)?;
        let blocks = self.blocks()?;
        let mut full = Mat::<f64>::zeros(blocks.block_rows(block).len(), x.nrows());
        blocks.block_jacobian(x.as_ref(), block, r_out, full.as_mut())?;
        self.free_columns(full.as_ref(), jac);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use faer::{Col, Mat};

    use super::Subset;
    use crate::{LinearProblem, ParamLayout, Problem, Unit};

    #[test]
    fn a_subset_of_a_subset_evaluates_the_problems_columns_again_and_again() {
        // r(x) = A·x, each entry of A distinct.
        let p = LinearProblem {
            layout: ParamLayout::numbered("p", 6, Unit::Meter),
            a: Mat::from_fn(9, 6, |i, j| (10 * i + j) as f64 + 0.5),
            y: Col::zeros(9),
        };
        let outer = Subset::new(&p, vec![0, 2, 3, 5], Col::from_fn(6, |i| i as f64));
        // Of the outer subset's parameters 0, 2, 3 (p0, p3, p5).
        let inner = Subset::new(&outer, vec![0, 2, 3], outer.initial_free());
        let x = Col::from_fn(3, |k| [0.25, -1.0, 2.0][k]);
        for _ in 0..2 {
            // Twice: the second evaluation reuses the first's buffer.
            let (mut r, mut jac) = (Col::zeros(9), Mat::from_fn(9, 3, |_, _| f64::NAN));
            inner
                .residuals_and_jacobian(x.as_ref(), r.as_mut(), jac.as_mut())
                .expect("evaluates");
            for (k, j) in [0, 3, 5].into_iter().enumerate() {
                for i in 0..9 {
                    assert_eq!(jac[(i, k)], p.a[(i, j)]);
                }
            }
            // p1 and p4 at the outer subset's start (1, 4), p2 at the inner one's (2).
            let full = Col::from_fn(6, |i| [0.25, 1.0, 2.0, -1.0, 4.0, 2.0][i]);
            let expected = &p.a * &full;
            for i in 0..9 {
                assert_eq!(r[i], expected[i]);
            }
        }
    }
}
