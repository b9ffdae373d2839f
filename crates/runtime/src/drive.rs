//! Transmissions: the map from a joint reading θ to the joint angle q and its derivative,
//! evaluated by `hapcal-transmission` (the calibration library's own evaluation, with the
//! runtime's elementary functions).

/// Parameters of the capstan transmission error, paper eq. 1 (docs/design.md §3.2): the
/// calibration library's type. `Default` is the ideal drive (no offset, exact ratio,
/// concentric drums). The names are those of `[calibration.values]`: `capstan{j}.c`, `.re`,
/// `.r_o`, `.beta_o`, `.r_i`, `.beta_i`.
pub use hapcal_transmission::CapstanParams;
use hapcal_transmission::{
    Capstan, CapstanFault, CapstanTransmission, JointRad, chebyshev_derivative, chebyshev_value,
};

use crate::error::check_finite;
use crate::math::RuntimeFunctions;
use crate::{Error, MAX_COEFFS};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Direct,
    Capstan(CapstanTransmission<RuntimeFunctions>),
    Polynomial {
        lo: f64,
        hi: f64,
        n_coeffs: usize,
        coeffs: [f64; MAX_COEFFS],
    },
}

/// How one joint is driven: reading θ (motor angle / R, rad) → joint angle q (rad), and the
/// nominal ratio R (motor angle per unit reading).
///
/// Three kinds, as `hapcal calibrate` identifies them (docs/design.md §3.2–3.3): direct
/// (`q = θ`, R = 1), capstan (`q = θ + Δθ_caps(θ)`, paper eq. 1) and polynomial
/// (`q = θ + p(θ)`, `p` in the Chebyshev basis on the joint range: the paper's tenth-order
/// model of the capstan-plus-parallelogram joint 4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drive {
    ratio: f64,
    kind: Kind,
}

fn positive(what: &'static str, value: f64) -> Result<f64, Error> {
    check_finite(what, &[value])?;
    if value <= 0.0 {
        return Err(Error::Invalid {
            what,
            value,
            expected: "a positive number",
        });
    }
    Ok(value)
}

impl Drive {
    /// Direct drive: `q = θ`, R = 1.
    pub const DIRECT: Drive = Drive {
        ratio: 1.0,
        kind: Kind::Direct,
    };

    /// A capstan drive of nominal ratio `ratio` (> 0) and drum centre distance
    /// `drum_distance_m` (m, > 0) with transmission-error parameters `p` (paper eq. 1).
    ///
    /// # Errors
    /// [`Error::NotFinite`] for a NaN or infinite value (named `ratio`, `drum_distance_m`,
    /// `c_rad`, …); [`Error::Invalid`] for a non-positive ratio or drum distance, an
    /// eccentricity `|r_o_m|` or `|r_i_m|` ≥ D, or `R + Re ≤ 0` (eq. 1 is undefined there).
    pub fn capstan(ratio: f64, drum_distance_m: f64, p: CapstanParams) -> Result<Drive, Error> {
        let ratio = positive("ratio", ratio)?;
        let d = positive("drum_distance_m", drum_distance_m)?;
        let capstan = Capstan::new_unchecked(ratio, d);
        match capstan.params_fault(&p) {
            None => {}
            Some(CapstanFault::NotFinite { name, value }) => {
                return Err(Error::NotFinite {
                    what: name,
                    index: 0,
                    value,
                });
            }
            Some(CapstanFault::EccentricityTooLarge { name, value }) => {
                return Err(Error::Invalid {
                    what: name,
                    value,
                    expected: "|r| < drum_distance_m",
                });
            }
            Some(CapstanFault::RatioNotPositive { value }) => {
                return Err(Error::Invalid {
                    what: "ratio + re",
                    value,
                    expected: "a positive number",
                });
            }
        }
        Ok(Drive {
            ratio,
            kind: Kind::Capstan(CapstanTransmission::with_functions(capstan, p)),
        })
    }

    /// A drive of nominal ratio `ratio` (> 0) whose joint angle is `q = θ + p(θ)`, with
    /// `p(θ) = Σ_k coeffs[k]·T_k(u)`, `u = (2θ − lo − hi)/(hi − lo)` (rad; Chebyshev basis
    /// on `[lo, hi]`, the joint range; docs/design.md §3.3). Outside the range `p` is
    /// extrapolated.
    ///
    /// # Errors
    /// [`Error::NotFinite`] for a NaN or infinite value; [`Error::Invalid`] for a
    /// non-positive ratio, `lo ≥ hi` or no coefficient; [`Error::TooMany`] for more than
    /// [`MAX_COEFFS`] coefficients.
    pub fn polynomial(ratio: f64, lo: f64, hi: f64, coeffs: &[f64]) -> Result<Drive, Error> {
        let ratio = positive("ratio", ratio)?;
        check_finite("domain", &[lo, hi])?;
        if lo >= hi {
            return Err(Error::Invalid {
                what: "domain",
                value: lo,
                expected: "lo < hi",
            });
        }
        if coeffs.is_empty() {
            return Err(Error::Invalid {
                what: "coefficients",
                value: 0.0,
                expected: "at least one",
            });
        }
        if coeffs.len() > MAX_COEFFS {
            return Err(Error::TooMany {
                what: "coefficients",
                found: coeffs.len(),
                max: MAX_COEFFS,
            });
        }
        check_finite("coeffs", coeffs)?;
        let mut stored = [0.0; MAX_COEFFS];
        stored[..coeffs.len()].copy_from_slice(coeffs);
        Ok(Drive {
            ratio,
            kind: Kind::Polynomial {
                lo,
                hi,
                n_coeffs: coeffs.len(),
                coeffs: stored,
            },
        })
    }

    /// `Ok` when the model holds at reading `theta` (rad): always, except for a polynomial,
    /// whose domain `[lo, hi]` it may leave by at most [`crate::DOMAIN_MARGIN`] of its width.
    ///
    /// # Errors
    /// [`Error::OutsideDomain`] (`index` is the caller's joint index).
    pub fn check_reading(&self, index: usize, theta: f64) -> Result<(), Error> {
        if let Kind::Polynomial { lo, hi, .. } = self.kind {
            let margin = crate::DOMAIN_MARGIN * (hi - lo);
            if !(lo - margin..=hi + margin).contains(&theta) {
                return Err(Error::OutsideDomain {
                    what: "joint readings",
                    index,
                    value: theta,
                    lo,
                    hi,
                });
            }
        }
        Ok(())
    }

    /// Nominal ratio R between the motor angle and the reading (1 for a direct drive).
    pub fn ratio(&self) -> f64 {
        self.ratio
    }

    /// Joint angle q (rad) and `dq/dθ` (rad/rad) at reading `theta` (rad), analytic:
    /// `1 + ∂Δθ_caps/∂θ` for a capstan (paper eq. 1 differentiated,
    /// `hapcal_transmission::CapstanTransmission::error_and_dtheta`), `1 + p'(θ)` for a
    /// polynomial (`T_k' = k·U_{k−1}`; Trefethen, *Approximation Theory and Approximation
    /// Practice*, 2013, ch. 3; `hapcal_transmission::chebyshev_value` and
    /// `chebyshev_derivative`). No allocation.
    #[inline]
    pub fn angle_and_derivative(&self, theta: f64) -> (f64, f64) {
        match &self.kind {
            Kind::Direct => (theta, 1.0),
            Kind::Capstan(transmission) => {
                let (error, derror) = transmission.error_and_dtheta(JointRad(theta));
                (theta + error, 1.0 + derror)
            }
            Kind::Polynomial {
                lo,
                hi,
                n_coeffs,
                coeffs,
            } => {
                let coeffs = coeffs.get(..*n_coeffs).unwrap_or(&[]);
                (
                    theta + chebyshev_value(*lo, *hi, coeffs, theta),
                    1.0 + chebyshev_derivative(*lo, *hi, coeffs, theta),
                )
            }
        }
    }
}
