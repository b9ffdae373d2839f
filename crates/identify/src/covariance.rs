//! Covariance of the estimate from the QR factor of the Jacobian, and the noise estimate.
//!
//! Source: Å. Björck, *Numerical Methods for Least Squares Problems*, SIAM 1996, §1.1.4 and
//! §2.8.3 (covariance `σ²(RᵀR)⁻¹ = σ²R⁻¹R⁻ᵀ` from the R factor, without forming `JᵀJ`, whose
//! condition number is the square of `J`'s), and §1.1.5 for the unbiased `σ̂²`.

use faer::{ColRef, Mat, MatRef};

use crate::error::{Error, check_config};
use crate::lm::{check_free, check_jacobian_finite};
use crate::problem::ParamLayout;

/// Covariance of the free parameters of a least-squares estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct Covariance {
    /// Layout indices of the rows and columns of [`Covariance::matrix`], in that order.
    pub free: Vec<usize>,
    /// Names of the same parameters.
    pub names: Vec<String>,
    /// `free.len() × free.len()` covariance; entry `(a, b)` in unit(a)·unit(b).
    pub matrix: Mat<f64>,
}

impl Covariance {
    /// Standard deviations, in the order of [`Covariance::free`], each in its parameter's unit.
    pub fn std(&self) -> Vec<f64> {
        (0..self.free.len())
            .map(|a| self.matrix[(a, a)].max(0.0).sqrt())
            .collect()
    }

    /// Standard deviation of parameter `name`, if it is free.
    pub fn std_of(&self, name: &str) -> Option<f64> {
        let a = self.names.iter().position(|n| n == name)?;
        Some(self.matrix[(a, a)].max(0.0).sqrt())
    }

    /// Correlation matrix `Cov_ab / (std_a·std_b)`, same order as [`Covariance::matrix`]
    /// (0 where a standard deviation is 0).
    pub fn correlation(&self) -> Mat<f64> {
        let std = self.std();
        Mat::from_fn(self.free.len(), self.free.len(), |a, b| {
            let s = std[a] * std[b];
            if s > 0.0 {
                self.matrix[(a, b)] / s
            } else {
                0.0
            }
        })
    }

    /// Pairs of free parameters with `|correlation| ≥ threshold`, as
    /// `(layout index, layout index, correlation)` with the first index's position in `free`
    /// before the second's, sorted by decreasing `|correlation|`.
    pub fn correlated_pairs(&self, threshold: f64) -> Vec<(usize, usize, f64)> {
        let corr = self.correlation();
        let nf = self.free.len();
        let mut pairs: Vec<(usize, usize, f64)> = (0..nf)
            .flat_map(|a| (a + 1..nf).map(move |b| (a, b)))
            .filter(|&(a, b)| corr[(a, b)].abs() >= threshold)
            .map(|(a, b)| (self.free[a], self.free[b], corr[(a, b)]))
            .collect();
        pairs.sort_by(|x, y| y.2.abs().total_cmp(&x.2.abs()));
        pairs
    }
}

/// Covariance `σ²·(J_fᵀJ_f)⁻¹` of the parameters `free`, from the Jacobian at the estimate.
///
/// `jac` is `m × n` (columns = `layout` entries); `J_f` is its `free` columns. With
/// `D = diag(‖J_f,j‖)` and the Householder QR `J_f D⁻¹ = Q R` (no pivoting), the covariance is
/// `σ²·D⁻¹ R⁻¹ R⁻ᵀ D⁻¹`, with `R⁻¹` from a triangular solve; `JᵀJ` is never formed. `sigma` is
/// the standard deviation of one residual (residual units); entries are in parameter units
/// squared.
///
/// # Errors
/// - [`Error::FreeOutOfRange`], [`Error::DuplicateFree`] for a bad `free`;
/// - [`Error::TooFewResiduals`] if `m < free.len()`;
/// - [`Error::InvalidConfig`] if `sigma` is negative or not finite;
/// - [`Error::NonFiniteJacobian`] for a NaN or ∞ in a free column;
/// - [`Error::Singular`] if a free column is zero or `|R_kk| ≤ ε·max(m, n_free)` (dependent
///   at working precision), naming the parameter at position `k`.
///
/// # Panics
/// If `jac.ncols() != layout.len()`.
#[track_caller]
pub fn covariance(
    jac: MatRef<'_, f64>,
    layout: &ParamLayout,
    free: &[usize],
    sigma: f64,
) -> Result<Covariance, Error> {
    assert!(
        jac.ncols() == layout.len(),
        "jacobian has {} columns, layout has {}",
        jac.ncols(),
        layout.len()
    );
    check_free(free, layout)?;
    check_config("sigma", sigma, false)?;
    let m = jac.nrows();
    let nf = free.len();
    if m < nf {
        return Err(Error::TooFewResiduals {
            n_residuals: m,
            n_free: nf,
        });
    }
    let jf = Mat::from_fn(m, nf, |i, a| jac[(i, free[a])]);
    let names: Vec<String> = free.iter().map(|&j| layout.name(j).to_owned()).collect();
    let free_layout = ParamLayout::new(free.iter().map(|&j| layout.spec(j).clone()).collect());
    check_jacobian_finite(jf.as_ref(), &free_layout)?;
    let c: Vec<f64> = (0..nf).map(|a| jf.col(a).norm_l2()).collect();
    if let Some(a) = c.iter().position(|&ca| ca == 0.0) {
        return Err(Error::Singular {
            name: names[a].clone(),
        });
    }
    let scaled = Mat::from_fn(m, nf, |i, a| jf[(i, a)] / c[a]);
    let matrix = if nf == 0 {
        Mat::zeros(0, 0)
    } else {
        let qr = scaled.qr();
        let r = qr.R();
        let tiny = f64::EPSILON * m.max(nf) as f64;
        if let Some(k) = (0..nf).find(|&k| r[(k, k)].abs() <= tiny) {
            return Err(Error::Singular {
                name: names[k].clone(),
            });
        }
        let mut r_inv = Mat::<f64>::identity(nf, nf);
        r.solve_upper_triangular_in_place(r_inv.as_mut());
        let scaled_cov = &r_inv * r_inv.transpose();
        let s2 = sigma * sigma;
        Mat::from_fn(nf, nf, |a, b| s2 * scaled_cov[(a, b)] / (c[a] * c[b]))
    };
    Ok(Covariance {
        free: free.to_vec(),
        names,
        matrix,
    })
}

/// Unbiased estimate of the residual standard deviation, `√(‖r‖² / (m − n_free))`, in residual
/// units; `None` when `m ≤ n_free` (no degree of freedom left).
pub fn sigma_from_residuals(r: ColRef<'_, f64>, n_free: usize) -> Option<f64> {
    let m = r.nrows();
    (m > n_free).then(|| (r.squared_norm_l2() / (m - n_free) as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use faer::Col;

    use super::*;
    use crate::problem::Unit;

    fn layout(n: usize) -> ParamLayout {
        ParamLayout::numbered("p", n, Unit::Meter)
    }

    #[test]
    fn orthogonal_columns_give_diagonal_covariance() {
        // J = diag(2, 4) on 2 rows plus a zero row: Cov = σ² diag(1/4, 1/16).
        let jac = Mat::from_fn(3, 2, |i, j| if i == j { [2.0, 4.0][j] } else { 0.0 });
        let cov = covariance(jac.as_ref(), &layout(2), &[0, 1], 0.5).expect("full rank");
        assert!((cov.matrix[(0, 0)] - 0.25 / 4.0).abs() < 1e-15);
        assert!((cov.matrix[(1, 1)] - 0.25 / 16.0).abs() < 1e-15);
        assert_eq!(cov.matrix[(0, 1)], 0.0);
        assert_eq!(cov.std_of("p1"), Some(0.125));
    }

    #[test]
    fn duplicated_column_is_singular() {
        let jac = Mat::from_fn(4, 2, |i, _| i as f64 + 1.0);
        let err = covariance(jac.as_ref(), &layout(2), &[0, 1], 1.0).expect_err("rank 1");
        assert_eq!(
            err,
            Error::Singular {
                name: "p1".to_owned()
            }
        );
        assert_eq!(
            err.to_string(),
            "covariance is singular: parameter \"p1\" is not determined by the data"
        );
    }

    #[test]
    fn sigma_from_residuals_divides_by_degrees_of_freedom() {
        let r = Col::from_fn(5, |_| 2.0);
        assert_eq!(
            sigma_from_residuals(r.as_ref(), 1),
            Some((20.0_f64 / 4.0).sqrt())
        );
        assert_eq!(sigma_from_residuals(r.as_ref(), 5), None);
    }
}
