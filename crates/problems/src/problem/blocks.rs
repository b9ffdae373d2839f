//! The problem as the identification sees it: residuals and Jacobian whole or by row blocks, and the small geometric helpers of the evaluation.

use super::*;

impl Problem for CalibrationProblem {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    fn n_residuals(&self) -> usize {
        self.n_residuals
    }

    fn residuals(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) -> Result<(), EvalError> {
        check_shape(x.nrows(), self.layout.len(), out.nrows(), self.n_residuals)?;
        self.eval(x, Some(out), None);
        Ok(())
    }

    fn jacobian(&self, x: ColRef<'_, f64>, jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.check_jacobian_shape(x.nrows(), jac.nrows(), jac.ncols())?;
        self.eval(x, None, Some(jac));
        Ok(())
    }

    /// One pass of the forward kinematics gives both (the Jacobian kernels compute the
    /// distances on the way).
    fn residuals_and_jacobian(
        &self,
        x: ColRef<'_, f64>,
        out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        check_shape(x.nrows(), self.layout.len(), out.nrows(), self.n_residuals)?;
        self.check_jacobian_shape(x.nrows(), jac.nrows(), jac.ncols())?;
        self.eval(x, Some(out), Some(jac));
        Ok(())
    }

    fn row_blocks(&self) -> Option<&dyn RowBlocks> {
        Some(self)
    }
}

impl RowBlocks for CalibrationProblem {
    fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    fn block_rows(&self, block: usize) -> Range<usize> {
        self.blocks[block].1.clone()
    }

    fn block_residuals(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        out: ColMut<'_, f64>,
    ) -> Result<(), EvalError> {
        let (rows, res) = self.block(block)?;
        check_shape(x.nrows(), self.layout.len(), out.nrows(), res.len())?;
        let last = block + 1 == self.blocks.len();
        self.eval_rows(x, rows, last, Some(out), None);
        Ok(())
    }

    fn block_jacobian(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        r_out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        let (rows, res) = self.block(block)?;
        check_shape(x.nrows(), self.layout.len(), r_out.nrows(), res.len())?;
        if jac.nrows() != res.len() || jac.ncols() != self.layout.len() {
            return Err(EvalError {
                reason: format!(
                    "block jacobian is {} x {}, expected {} x {}",
                    jac.nrows(),
                    jac.ncols(),
                    res.len(),
                    self.layout.len()
                ),
            });
        }
        let last = block + 1 == self.blocks.len();
        self.eval_rows(x, rows, last, Some(r_out), Some(jac));
        Ok(())
    }
}

impl CalibrationProblem {
    /// `x` of the layout's length and a Jacobian of `n_residuals × layout` entries.
    fn check_jacobian_shape(&self, nx: usize, nr: usize, nc: usize) -> Result<(), EvalError> {
        check_shape(nx, self.layout.len(), nr, self.n_residuals)?;
        if nc != self.layout.len() {
            return Err(EvalError {
                reason: format!("jacobian has {nc} columns, expected {}", self.layout.len()),
            });
        }
        Ok(())
    }

    fn block(&self, block: usize) -> Result<(Range<usize>, Range<usize>), EvalError> {
        self.blocks.get(block).cloned().ok_or_else(|| EvalError {
            reason: format!("block {block} of {}", self.blocks.len()),
        })
    }
}

/// The length `|d|` of a vector (m) and its gradient `d/|d|` with respect to `d` (the unit
/// direction; zero at the origin, where the length has no gradient): the measurement model of
/// every distance row (cable encoder, paper eq. 5; anchor distances; the socket distance), with
/// the chain rule through the point's Jacobian left to the caller.
pub(crate) fn length_and_direction(d: &Vector3<f64>) -> (f64, Vector3<f64>) {
    let norm = d.norm();
    let u = if norm > 0.0 {
        d / norm
    } else {
        Vector3::zeros()
    };
    (norm, u)
}

/// `wᵀ·∂P/∂x_k`: the derivative along `w` of the end point's column `k` of `buf` (`∂P/∂x`
/// column by column, 3 entries per parameter, as `Chain::point_and_jacobian_in` and
/// `FrozenChain::point_and_jacobian` write it). With `w` the direction of
/// [`length_and_direction`] it is a distance row's `∂|P|/∂x_k` (paper eq. 5); with a cable
/// angle's gradient folded into `w`, that term's.
///
/// # Panics
/// If `buf` holds fewer than `3·(k + 1)` entries (misuse).
pub(crate) fn along(w: &Vector3<f64>, buf: &[f64], k: usize) -> f64 {
    w[0] * buf[3 * k] + w[1] * buf[3 * k + 1] + w[2] * buf[3 * k + 2]
}

/// The inverse right Jacobian of SO(3) at the rotation vector `phi`:
/// `log(exp([φ]×)·exp([δ]×)) ≈ φ + J_r⁻¹(φ)·δ`,
/// `J_r⁻¹(φ) = I + ½[φ]× + (1/θ² − (1 + cos θ)/(2θ sin θ))·[φ]×²`, θ = |φ| (Barfoot,
/// *State Estimation for Robotics*, 2017, eq. 7.95); the series `1/12 + θ²/720` below 1e-4.
pub(super) fn right_jacobian_inverse(phi: &Vector3<f64>) -> nalgebra::Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    let c = if theta < 1e-4 {
        1.0 / 12.0 + theta * theta / 720.0
    } else {
        1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
    };
    nalgebra::Matrix3::identity() + 0.5 * k + c * k * k
}

pub(super) fn check_shape(nx: usize, n: usize, nr: usize, m: usize) -> Result<(), EvalError> {
    if nx != n || nr != m {
        return Err(EvalError {
            reason: format!(
                "shape mismatch: x has {nx} entries (expected {n}), output {nr} rows (expected {m})"
            ),
        });
    }
    Ok(())
}
