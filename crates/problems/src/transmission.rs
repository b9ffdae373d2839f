//! Step 1 of the paper's procedure (Fig. 6): identification problems for the transmissions from
//! external-encoder data, implementing [`hapcal_identify::Problem`]. The models themselves
//! (paper eqs. 1 and 2, the Chebyshev polynomial) are `hapcal_transmission`'s.

use faer::{Col, ColMut, ColRef, Mat, MatMut};
use hapcal_contract::{CapstanField, ValueName};
use hapcal_identify::{
    EvalError, IdentifyConfig, ParamLayout, ParamSpec, Problem, RankConfigBase, Role, Unit,
};
use hapcal_transmission::{
    Capstan, CapstanParams, Chebyshev, Error as TransmissionError, JointRad, all_finite, positive,
};

/// Checks paired readings/measurements: non-empty, equal lengths, finite; and `sigma_rad > 0`.
fn check_data(theta: &[f64], ext: &[f64], sigma_rad: f64) -> Result<(), TransmissionError> {
    if theta.is_empty() {
        return Err(TransmissionError::Empty { name: "theta" });
    }
    if ext.len() != theta.len() {
        return Err(TransmissionError::LengthMismatch {
            name: "ext",
            expected: theta.len(),
            found: ext.len(),
        });
    }
    all_finite("theta", theta)?;
    all_finite("ext", ext)?;
    positive("sigma_rad", sigma_rad)?;
    Ok(())
}

/// A capstan drive's eq. 1 parameters in layout order (as [`CapstanProblem::params`] reads
/// them), with their units; every problem names them `capstan{j}.{name}` ([`capstan_param`]).
pub(crate) const CAPSTAN_PARAMS: [(CapstanField, Unit); 6] = [
    (CapstanField::C, Unit::Radian),
    (CapstanField::Re, Unit::Dimensionless),
    (CapstanField::ROut, Unit::Meter),
    (CapstanField::BetaOut, Unit::Radian),
    (CapstanField::RIn, Unit::Meter),
    (CapstanField::BetaIn, Unit::Radian),
];

/// The name of parameter `field` of the capstan on joint `joint` (1-based):
/// [`ValueName::Capstan`].
pub(crate) fn capstan_param(joint: usize, field: CapstanField) -> String {
    ValueName::Capstan { joint, field }.to_string()
}

/// The name of Chebyshev coefficient `k` of the polynomial on joint `joint` (1-based):
/// [`ValueName::Chebyshev`].
pub(crate) fn chebyshev_param(joint: usize, k: usize) -> String {
    ValueName::Chebyshev { joint, index: k }.to_string()
}

/// A model parameter's spec.
pub(crate) fn spec(name: String, unit: Unit) -> ParamSpec {
    ParamSpec {
        name,
        unit,
        role: Role::Model,
    }
}

/// Identification of one capstan drive's eq. 1 parameters from external-encoder data.
///
/// Residual `i` (dimensionless, `m = theta.len()` of them):
/// `(θ_i + Δθ(θ_i; p) − ext_i) / σ`, with θ_i the joint reading (motor angle / R, rad), ext_i
/// the external encoder's output angle (rad) and Δθ from [`Capstan::error_rad`] (paper eq. 1).
/// Residuals are already divided by σ, so identify with
/// `IdentifyConfig { sigma: Some(1.0), .. }`.
///
/// Parameters (`n = 6`, all [`Role::Model`]), in this order: `capstan{joint}.c` (rad),
/// `.re` (dimensionless), `.r_o` (m), `.beta_o` (rad), `.r_i` (m), `.beta_i` (rad).
///
/// Source: paper eq. 1 and Fig. 6, step 1.
///
/// ```
/// use hapcal_identify::identify;
/// use hapcal_problems::CapstanProblem;
/// use hapcal_transmission::{Capstan, CapstanParams, JointRad};
///
/// // Capstan 1 of the paper's Table 2 (R = 10, D = 60 mm).
/// let capstan = Capstan::try_new(10.0, 0.06)?;
/// let truth = CapstanParams {
///     c_rad: 0.0,
///     re: -0.025,
///     r_o_m: 0.2e-3,
///     beta_o_rad: (-105.0f64).to_radians(),
///     r_i_m: 0.005e-3,
///     beta_i_rad: (-15.0f64).to_radians(),
/// };
/// // Noise-free external-encoder readings over a full output turn.
/// let theta: Vec<f64> = (0..200).map(|i| -3.1 + 6.2 * i as f64 / 199.0).collect();
/// let ext = theta.iter().map(|&t| capstan.output_rad(&truth, JointRad(t))).collect();
/// let sigma_e = 2.0 * std::f64::consts::PI / 20000.0 / 3.0;
/// let problem = CapstanProblem::new(capstan, 1, theta, ext, sigma_e)?;
///
/// // σ = 1 (residuals are already divided by σ_e) and phases without a nominal value.
/// let id = identify(&problem, problem.initial_guess(), &CapstanProblem::identify_config())?;
/// assert!(id.identifiability.pruned.is_empty());
/// let p = CapstanProblem::params(id.fit.x.as_ref());
/// assert!((p.r_o_m - 0.2e-3).abs() < 1e-9);
/// assert!((p.re + 0.025).abs() < 1e-9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct CapstanProblem {
    capstan: Capstan,
    theta: Vec<f64>,
    ext: Vec<f64>,
    sigma_rad: f64,
    layout: ParamLayout,
}

impl CapstanProblem {
    /// Builds the problem for capstan `joint` (1-based, used only in parameter names) from
    /// readings `theta` (rad) and external-encoder output angles `ext` (rad, same length), with
    /// encoder noise `sigma_rad` (rad, > 0; the paper's `σ_e = 2π/20000/3`).
    ///
    /// # Errors
    /// [`TransmissionError::Empty`] for no reading, [`TransmissionError::LengthMismatch`] if
    /// `ext.len() != theta.len()`, [`TransmissionError::NotFinite`] naming
    /// `theta[i]`/`ext[i]`/`sigma_rad`, [`TransmissionError::NonPositive`] for `sigma_rad ≤ 0`.
    pub fn new(
        capstan: Capstan,
        joint: usize,
        theta: Vec<f64>,
        ext: Vec<f64>,
        sigma_rad: f64,
    ) -> Result<CapstanProblem, TransmissionError> {
        check_data(&theta, &ext, sigma_rad)?;
        let layout = ParamLayout::new(
            (CAPSTAN_PARAMS.iter())
                .map(|&(p, unit)| spec(capstan_param(joint, p), unit))
                .collect(),
        );
        Ok(CapstanProblem {
            capstan,
            theta,
            ext,
            sigma_rad,
            layout,
        })
    }

    /// The parameters of a solution vector `x` (length 6, in the layout's order and units).
    ///
    /// # Panics
    /// If `x.nrows() != 6`.
    #[track_caller]
    pub fn params(x: ColRef<'_, f64>) -> CapstanParams {
        assert_eq!(x.nrows(), 6, "a capstan parameter vector has 6 entries");
        CapstanParams {
            c_rad: x[0],
            re: x[1],
            r_o_m: x[2],
            beta_o_rad: x[3],
            r_i_m: x[4],
            beta_i_rad: x[5],
        }
    }

    /// The configuration to pass to [`hapcal_identify::identify`] for this problem:
    /// `sigma = Some(1.0)` (the residuals are already divided by σ) and an angle prior of
    /// `prior_rad = π` instead of the default 0.01 rad; other fields default.
    ///
    /// The default priors describe deviations from a nominal value. The eccentricity phases
    /// `β_o`, `β_i` have no nominal: their plausible deviation is half a turn, and the offset
    /// `c`, the only other angle, is always well determined. With the default 0.01 rad, a phase
    /// the data determine only weakly is pruned and held at its noisy start, which biases the
    /// kept parameters beyond their covariance: for Table 2's capstan 1 over q1 ∈ [−1, 1] rad,
    /// `β_o` is pruned in 71 of 100 seeded simulations and `Re` then misses the truth by up to
    /// 44 standard deviations; with `prior_rad = π` nothing is pruned and every parameter stays
    /// within 3.6 standard deviations (tests/it/transmission/capstan.rs,
    /// `RUN_SLOW_TESTS=1`).
    pub fn identify_config() -> IdentifyConfig {
        IdentifyConfig {
            rank: RankConfigBase {
                prior_rad: std::f64::consts::PI,
                ..Default::default()
            },
            sigma: Some(1.0),
            ..Default::default()
        }
    }

    /// The solution vector (length 6, in the layout's order and units) of `p`; the inverse of
    /// [`CapstanProblem::params`].
    pub fn col(p: &CapstanParams) -> Col<f64> {
        let v = [p.c_rad, p.re, p.r_o_m, p.beta_o_rad, p.r_i_m, p.beta_i_rad];
        Col::from_fn(6, |j| v[j])
    }

    /// A start for the fit (length 6, layout order), robust to the phases' non-convexity.
    ///
    /// `r·sin(θ + β)` is not convex in `(r, β)` but linear in `(r cos β, r sin β)`, and for
    /// `r/D ≪ 1` each eccentricity term of eq. 1 is `(r/D)(sin(φ + β) − sin β)` to first order
    /// (the next term is `(r/D)²/2 ≈ 1e-5 rad` for `r = 0.3 mm`, `D = 60 mm`). So
    /// `ext − θ ≈ c + a·θ + A sin θ + B (cos θ − 1) + C sin Rθ + E (cos Rθ − 1)` is fitted by
    /// linear least squares (SVD of the column-scaled matrix, dropping singular values below
    /// 1e-10 of the largest, so narrow or aliased data give the minimum-norm answer instead of
    /// a blow-up), and converted: `Re = −aR/(1 + a)`, `r_o = D·hypot(A, B)`,
    /// `β_o = atan2(B, A)`, likewise `(r_i, β_i)` from `(C, E)`. Radii are capped at `D/2` so
    /// that eq. 1 is defined at the start.
    pub fn initial_guess(&self) -> Col<f64> {
        let (r, d) = (self.capstan.ratio(), self.capstan.drum_distance_m());
        let m = self.theta.len();
        let a = Mat::from_fn(m, 6, |i, j| {
            let t = self.theta[i];
            match j {
                0 => 1.0,
                1 => t,
                2 => t.sin(),
                3 => t.cos() - 1.0,
                4 => (r * t).sin(),
                _ => (r * t).cos() - 1.0,
            }
        });
        let y: Vec<f64> = self
            .ext
            .iter()
            .zip(&self.theta)
            .map(|(e, t)| e - t)
            .collect();
        let z = truncated_lstsq(a, &y);
        let slope = z[1];
        let re = if 1.0 + slope > 0.0 {
            -slope * r / (1.0 + slope)
        } else {
            0.0
        };
        let polar = |s: f64, c: f64| ((d * s.hypot(c)).min(0.5 * d), c.atan2(s));
        let (r_o, beta_o) = polar(z[2], z[3]);
        let (r_i, beta_i) = polar(z[4], z[5]);
        CapstanProblem::col(&CapstanParams {
            c_rad: z[0],
            re,
            r_o_m: r_o,
            beta_o_rad: beta_o,
            r_i_m: r_i,
            beta_i_rad: beta_i,
        })
    }

    /// The eq. 1 parameters of `x` after checking that eq. 1 is defined there.
    fn checked(&self, x: ColRef<'_, f64>) -> Result<CapstanParams, EvalError> {
        let p = CapstanProblem::params(x);
        self.capstan
            .check_params(&p)
            .map_err(|e| EvalError {
                reason: e.to_string(),
            })
            .map(|()| p)
    }
}

/// Minimum-norm least-squares solution of `a z ≈ y` by SVD of the column-scaled `a`, ignoring
/// singular values below 1e-10 of the largest; zeros if the SVD fails.
fn truncated_lstsq(mut a: Mat<f64>, y: &[f64]) -> Vec<f64> {
    let n = a.ncols();
    let scale: Vec<f64> = (0..n)
        .map(|j| {
            let norm = a.col(j).norm_l2();
            if norm > 0.0 { norm } else { 1.0 }
        })
        .collect();
    for (j, s) in scale.iter().enumerate() {
        for v in a.col_mut(j).iter_mut() {
            *v /= s;
        }
    }
    let Ok(svd) = a.thin_svd() else {
        return vec![0.0; n];
    };
    let (u, s, v) = (svd.U(), svd.S().column_vector(), svd.V());
    let s_max = (0..s.nrows()).map(|k| s[k]).fold(0.0, f64::max);
    let mut z = vec![0.0; n];
    for k in 0..s.nrows() {
        if s[k] <= 1e-10 * s_max || s[k] == 0.0 {
            continue;
        }
        let uty: f64 = (0..y.len()).map(|i| u[(i, k)] * y[i]).sum();
        for (j, zj) in z.iter_mut().enumerate() {
            *zj += v[(j, k)] * uty / s[k];
        }
    }
    z.iter().zip(&scale).map(|(zj, s)| zj / s).collect()
}

impl Problem for CapstanProblem {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    fn n_residuals(&self) -> usize {
        self.theta.len()
    }

    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        let p = self.checked(x)?;
        for (i, (&t, &e)) in self.theta.iter().zip(&self.ext).enumerate() {
            out[i] = (self.capstan.output_rad(&p, JointRad(t)) - e) / self.sigma_rad;
        }
        Ok(())
    }

    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        let p = self.checked(x)?;
        for (i, &t) in self.theta.iter().enumerate() {
            let g = self.capstan.error_grad(&p, JointRad(t));
            for (j, gj) in g.iter().enumerate() {
                jac[(i, j)] = gj / self.sigma_rad;
            }
        }
        Ok(())
    }
}

/// Identification of a transmission error as a polynomial of the joint reading in the Chebyshev
/// basis on `[lo, hi]` (the paper's tenth-order polynomial for joint 4, Table 2).
///
/// Residual `i` (dimensionless, `m = theta.len()` of them): `(θ_i + p(θ_i) − ext_i) / σ`, with
/// `p` the [`Chebyshev`] polynomial of the parameters; linear in them (the Jacobian row is
/// [`Chebyshev::basis`]`/σ`). Identify with `IdentifyConfig { sigma: Some(1.0), .. }` from
/// [`PolynomialProblem::initial_guess`] (zeros).
///
/// Parameters (`n = degree + 1`, all [`Role::Model`], rad): `joint{joint}.cheb0` …
/// `joint{joint}.cheb{degree}`.
///
/// Source: paper, parallelogram section (polynomial model of the joint-4 error; the link
/// deviations of a planar four-bar are mostly unidentifiable, Schroer et al. 1997); basis:
/// Trefethen, *Approximation Theory and Approximation Practice*, ch. 3–4.
#[derive(Clone, Debug)]
pub struct PolynomialProblem {
    lo: f64,
    hi: f64,
    degree: usize,
    /// Chebyshev basis at each reading, row-major `m × (degree + 1)`.
    basis: Vec<f64>,
    theta: Vec<f64>,
    ext: Vec<f64>,
    sigma_rad: f64,
    layout: ParamLayout,
}

impl PolynomialProblem {
    /// Builds the problem for joint `joint` (1-based, used only in parameter names): a
    /// polynomial of degree `degree` on `[lo, hi]` (rad; the joint range), readings `theta`
    /// (rad), external-encoder output angles `ext` (rad, same length) and noise `sigma_rad`
    /// (rad, > 0). Readings outside `[lo, hi]` are allowed (the polynomial extrapolates).
    ///
    /// # Errors
    /// [`TransmissionError::Domain`] unless `lo < hi` are finite; otherwise as
    /// [`CapstanProblem::new`].
    pub fn new(
        joint: usize,
        degree: usize,
        lo: f64,
        hi: f64,
        theta: Vec<f64>,
        ext: Vec<f64>,
        sigma_rad: f64,
    ) -> Result<PolynomialProblem, TransmissionError> {
        // The zero polynomial of this degree on [lo, hi]: checks the domain, gives the basis.
        let zero = Chebyshev::try_new(lo, hi, vec![0.0; degree + 1])?;
        check_data(&theta, &ext, sigma_rad)?;
        let layout = ParamLayout::new(
            (0..=degree)
                .map(|k| spec(chebyshev_param(joint, k), Unit::Radian))
                .collect(),
        );
        let basis = theta.iter().flat_map(|&t| zero.basis(t)).collect();
        Ok(PolynomialProblem {
            lo,
            hi,
            degree,
            basis,
            theta,
            ext,
            sigma_rad,
            layout,
        })
    }

    /// The polynomial of a solution vector `x` (length `degree + 1`, rad).
    ///
    /// # Panics
    /// If `x.nrows() != degree + 1`.
    #[track_caller]
    pub fn polynomial(&self, x: ColRef<'_, f64>) -> Chebyshev {
        assert_eq!(
            x.nrows(),
            self.degree + 1,
            "a degree-{} polynomial has {} coefficients",
            self.degree,
            self.degree + 1
        );
        Chebyshev {
            lo: self.lo,
            hi: self.hi,
            coeffs: (0..x.nrows()).map(|k| x[k]).collect(),
        }
    }

    /// The start for the fit: zeros (length `degree + 1`; the problem is linear, so one
    /// Levenberg–Marquardt step solves it, and pruned coefficients stay at zero).
    pub fn initial_guess(&self) -> Col<f64> {
        Col::zeros(self.degree + 1)
    }
}

impl Problem for PolynomialProblem {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    fn n_residuals(&self) -> usize {
        self.theta.len()
    }

    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        let n = self.degree + 1;
        for (i, (row, (&t, &e))) in self
            .basis
            .chunks_exact(n)
            .zip(self.theta.iter().zip(&self.ext))
            .enumerate()
        {
            let p: f64 = row.iter().enumerate().map(|(k, b)| b * x[k]).sum();
            out[i] = (t + p - e) / self.sigma_rad;
        }
        Ok(())
    }

    fn jacobian(&self, _x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        let n = self.degree + 1;
        for (i, row) in self.basis.chunks_exact(n).enumerate() {
            for (k, b) in row.iter().enumerate() {
                jac[(i, k)] = b / self.sigma_rad;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
