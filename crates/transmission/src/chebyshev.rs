//! Polynomials in the Chebyshev basis on a joint range, with conversion to the paper's
//! monomial coefficients.

#[cfg(feature = "std")]
use crate::error::{Error, all_finite};

/// Polynomial `p(θ) = Σ_k c_k T_k(u)` on `[lo, hi]` (rad) in the Chebyshev basis, with
/// `u = (2θ − lo − hi)/(hi − lo)` mapping the range onto `[−1, 1]`; `p` is in rad.
///
/// The Chebyshev basis keeps the least-squares fit of a tenth-order polynomial well
/// conditioned, where the monomials `θ^k` the paper prints are nearly collinear; use
/// [`Chebyshev::to_monomial`] for the paper's `k0..k10`.
///
/// Source: L. N. Trefethen, *Approximation Theory and Approximation Practice*, SIAM 2013,
/// ch. 3 (Chebyshev polynomials and series) and ch. 4 (the three-term recurrence, Clenshaw).
#[cfg(feature = "std")]
#[derive(Clone, Debug, PartialEq)]
pub struct Chebyshev {
    /// Lower end of the domain, rad.
    pub lo: f64,
    /// Upper end of the domain, rad.
    pub hi: f64,
    /// Coefficients `c_0..c_n` (`degree + 1` entries), rad.
    pub coeffs: Vec<f64>,
}

#[cfg(feature = "std")]
impl Chebyshev {
    /// A polynomial on `[lo, hi]` (rad) with Chebyshev coefficients `coeffs` (rad, `degree + 1`
    /// entries).
    ///
    /// # Errors
    /// [`Error::Domain`] unless `lo < hi` are finite; [`Error::Empty`] for no coefficient;
    /// [`Error::NotFinite`] naming `coeffs[k]`.
    pub fn try_new(lo: f64, hi: f64, coeffs: Vec<f64>) -> Result<Chebyshev, Error> {
        check_domain(lo, hi)?;
        if coeffs.is_empty() {
            return Err(Error::Empty { name: "coeffs" });
        }
        all_finite("coeffs", &coeffs)?;
        Ok(Chebyshev { lo, hi, coeffs })
    }

    /// The polynomial `Σ_i k_i θ^i` (monomial coefficients `k_0..k_n` in rad/radⁱ, θ in rad)
    /// written in the Chebyshev basis on `[lo, hi]`; the inverse of [`Chebyshev::to_monomial`].
    ///
    /// Uses `u·T_k = (T_{k+1} + T_{|k−1|})/2` in a Horner scheme (Trefethen, ATAP ch. 3).
    ///
    /// # Errors
    /// As [`Chebyshev::try_new`] (with `k` in place of `coeffs`).
    pub fn from_monomial(lo: f64, hi: f64, k: &[f64]) -> Result<Chebyshev, Error> {
        check_domain(lo, hi)?;
        if k.is_empty() {
            return Err(Error::Empty { name: "k" });
        }
        all_finite("k", k)?;
        // θ = α·u + γ.
        let (alpha, gamma) = (0.5 * (hi - lo), 0.5 * (hi + lo));
        let n = k.len() - 1;
        let mut acc = vec![0.0; n + 1];
        acc[0] = k[n];
        for (deg, &kj) in k.iter().enumerate().rev().skip(1) {
            // acc ← acc·(α u + γ) + k_j; acc has degree n − deg − 1 before the step.
            let top = n - deg - 1;
            let mut next = vec![0.0; n + 1];
            for (i, &a) in acc.iter().enumerate().take(top + 1) {
                next[i] += gamma * a;
                next[i + 1] += 0.5 * alpha * a;
                if i == 0 {
                    next[1] += 0.5 * alpha * a;
                } else {
                    next[i - 1] += 0.5 * alpha * a;
                }
            }
            next[0] += kj;
            acc = next;
        }
        Ok(Chebyshev {
            lo,
            hi,
            coeffs: acc,
        })
    }

    /// Degree `n` (`coeffs.len() − 1`).
    pub fn degree(&self) -> usize {
        self.coeffs.len().saturating_sub(1)
    }

    /// `p(θ)`, rad, by Clenshaw's recurrence (Trefethen, ATAP ch. 3; [`chebyshev_value`]).
    /// Outside `[lo, hi]` the polynomial is extrapolated.
    pub fn eval(&self, theta: f64) -> f64 {
        chebyshev_value(self.lo, self.hi, &self.coeffs, theta)
    }

    /// `dp/dθ`, rad/rad: `Σ_k c_k k U_{k−1}(u) · 2/(hi − lo)` (`T_k' = k U_{k−1}`, Trefethen,
    /// ATAP ch. 3; [`chebyshev_derivative`]).
    pub fn derivative(&self, theta: f64) -> f64 {
        chebyshev_derivative(self.lo, self.hi, &self.coeffs, theta)
    }

    /// `T_k(u(θ))` for `k = 0..=degree` (length `degree + 1`): the Jacobian row of
    /// [`Chebyshev::eval`] with respect to `coeffs`, rad/rad.
    pub fn basis(&self, theta: f64) -> Vec<f64> {
        chebyshev_basis(unit_u(self.lo, self.hi, theta).0, self.coeffs.len())
    }

    /// Monomial coefficients `k_0..k_n` (rad/radⁱ) of the same polynomial in θ (rad):
    /// `p(θ) = Σ_i k_i θ^i`, the paper's `k0..k10` (Table 2).
    ///
    /// Clenshaw's recurrence run on polynomials in θ, with `u = a θ + b`. Evaluating the
    /// monomial form loses accuracy as `Σ_i |k_i| |θ|^i` grows (the reason to fit in the
    /// Chebyshev basis); on joint ranges within ±π it agrees with [`Chebyshev::eval`] to ~1e-12
    /// for coefficients of order one.
    pub fn to_monomial(&self) -> Vec<f64> {
        let n = self.degree();
        let w = self.hi - self.lo;
        let (a, b) = (2.0 / w, -(self.lo + self.hi) / w);
        // b_k as polynomials in θ: b_k = c_k + 2(aθ + b) b_{k+1} − b_{k+2}.
        let mut b1 = vec![0.0; n + 2];
        let mut b2 = vec![0.0; n + 2];
        for &c in self.coeffs.iter().skip(1).rev() {
            let mut b0 = vec![0.0; n + 2];
            for i in 0..=n {
                b0[i] += 2.0 * b * b1[i] - b2[i];
                b0[i + 1] += 2.0 * a * b1[i];
            }
            b0[0] += c;
            b2 = b1;
            b1 = b0;
        }
        // p = c_0 + (aθ + b) b_1 − b_2.
        let mut p = vec![0.0; n + 1];
        for i in 0..=n {
            p[i] += b * b1[i] - b2[i];
            if i < n {
                p[i + 1] += a * b1[i];
            }
        }
        if let Some(c0) = self.coeffs.first() {
            p[0] += c0;
        }
        p
    }
}

/// `u(θ) = (2θ − lo − hi)/(hi − lo)`, and `du/dθ`, 1/rad.
#[inline]
fn unit_u(lo: f64, hi: f64, theta: f64) -> (f64, f64) {
    let w = hi - lo;
    ((2.0 * theta - lo - hi) / w, 2.0 / w)
}

/// `p(θ) = Σ_k coeffs[k]·T_k(u)` (rad) with `u = (2θ − lo − hi)/(hi − lo)`: the polynomial
/// of [`Chebyshev::eval`] on `[lo, hi]` (rad) from a coefficient slice (rad, any length; 0
/// when empty), by Clenshaw's recurrence (Trefethen, ATAP ch. 3). No allocation; unchecked
/// (NaN or ∞ unless `lo < hi`). Outside `[lo, hi]` the polynomial is extrapolated.
#[inline]
pub fn chebyshev_value(lo: f64, hi: f64, coeffs: &[f64], theta: f64) -> f64 {
    let (u, _) = unit_u(lo, hi, theta);
    let (mut b1, mut b2) = (0.0, 0.0);
    for &c in coeffs.iter().skip(1).rev() {
        let b0 = c + 2.0 * u * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    coeffs.first().copied().unwrap_or(0.0) + u * b1 - b2
}

/// `dp/dθ` (rad/rad) of [`chebyshev_value`]'s polynomial:
/// `Σ_k coeffs[k]·k·U_{k−1}(u) · 2/(hi − lo)` (`T_k' = k U_{k−1}`, Trefethen, ATAP ch. 3).
/// No allocation; unchecked, as [`chebyshev_value`].
#[inline]
pub fn chebyshev_derivative(lo: f64, hi: f64, coeffs: &[f64], theta: f64) -> f64 {
    let (u, du) = unit_u(lo, hi, theta);
    // U_{k−1} for k = 1, 2, …: U_0 = 1, U_1 = 2u, U_{k+1} = 2u U_k − U_{k−1}.
    let (mut u_prev, mut u_cur) = (0.0, 1.0);
    let mut sum = 0.0;
    for (k, &c) in coeffs.iter().enumerate().skip(1) {
        sum += c * k as f64 * u_cur;
        let next = 2.0 * u * u_cur - u_prev;
        u_prev = u_cur;
        u_cur = next;
    }
    sum * du
}

/// `[T_0(u), …, T_{len−1}(u)]` by the three-term recurrence.
#[cfg(feature = "std")]
pub(crate) fn chebyshev_basis(u: f64, len: usize) -> Vec<f64> {
    let mut t = Vec::with_capacity(len);
    for k in 0..len {
        let next = match k {
            0 => 1.0,
            1 => u,
            _ => 2.0 * u * t[k - 1] - t[k - 2],
        };
        t.push(next);
    }
    t
}

/// `Ok(())` if `lo < hi` are finite, else [`Error::Domain`].
#[cfg(feature = "std")]
pub(crate) fn check_domain(lo: f64, hi: f64) -> Result<(), Error> {
    if lo.is_finite() && hi.is_finite() && lo < hi {
        Ok(())
    } else {
        Err(Error::Domain { lo, hi })
    }
}

#[cfg(test)]
mod tests;
