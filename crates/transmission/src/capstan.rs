//! The capstan drive: ratio, drum distance and the transmission error of paper eq. 1.

#[cfg(feature = "std")]
use crate::error::{Error, positive};
use core::marker::PhantomData;

use crate::math::{DefaultFunctions, ElementaryFunctions};

/// `(sin x, cos x)` of the crate's own functions, x in rad.
fn sin_cos(x: f64) -> (f64, f64) {
    DefaultFunctions::sin_cos(x)
}

/// Joint-side angle (motor angle / R), rad: what the device reports as the joint reading.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd)]
pub struct JointRad(pub f64);

/// Parameters of the capstan transmission error, paper eq. 1.
///
/// `Default` is the ideal drive (all zero: no offset, exact ratio, concentric drums).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct CapstanParams {
    /// Joint offset `c`, rad.
    pub c_rad: f64,
    /// Transmission ratio error `Re` (dimensionless; the actual ratio is `R + Re`).
    pub re: f64,
    /// Output-drum eccentricity radius `r_o`, m.
    pub r_o_m: f64,
    /// Output-drum eccentricity phase `β_o`, rad.
    pub beta_o_rad: f64,
    /// Input-drum eccentricity radius `r_i`, m.
    pub r_i_m: f64,
    /// Input-drum eccentricity phase `β_i`, rad.
    pub beta_i_rad: f64,
}

/// Why eq. 1 is not defined for a capstan's parameters ([`Capstan::params_fault`]); each names
/// the field as a device file writes it under `[[capstan]]` and gives its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CapstanFault {
    /// A field (`c_rad`, `re`, `r_o_m`, `beta_o_rad`, `r_i_m`, `beta_i_rad`) is NaN or
    /// infinite.
    NotFinite {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// An eccentricity radius (`r_o_m` or `r_i_m`, m) is not below the drum distance `D`.
    EccentricityTooLarge {
        /// The field.
        name: &'static str,
        /// Its value, m.
        value: f64,
    },
    /// The actual ratio `R + Re` is not positive.
    RatioNotPositive {
        /// `R + Re`.
        value: f64,
    },
}

/// A capstan drive: nominal ratio `R` (> 0) and drum centre distance `D` (> 0, m).
///
/// Source: paper, "Capstan drive" section and eq. 1; docs/design.md §3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capstan {
    ratio: f64,
    drum_distance_m: f64,
}

/// One eccentricity term of eq. 1, `atan(r sin φ / (D − r cos φ))` (rad), and its
/// derivative with respect to its phase φ, rad/rad ([`ecc_grad_at`]).
#[inline]
fn ecc_and_dphi<F: ElementaryFunctions>(r: f64, d: f64, phi: f64) -> (f64, f64) {
    let (s, c) = F::sin_cos(phi);
    (F::atan(r * s / (d - r * c)), ecc_grad_at(r, d, s, c).1)
}

/// `(∂/∂r, ∂/∂φ)` of the eccentricity term `atan(r sin φ / (D − r cos φ))`:
/// `(D sin φ, r (D cos φ − r)) / (r² + D² − 2 r D cos φ)`, from `s = sin φ`, `c = cos φ`.
#[inline]
fn ecc_grad_at(r: f64, d: f64, s: f64, c: f64) -> (f64, f64) {
    let q = r * r + d * d - 2.0 * r * d * c;
    (d * s / q, r * (d * c - r) / q)
}

/// `∂Δθ_caps/∂θ` (rad/rad, eq. 1 differentiated) of a capstan of ratio `r` with ratio error
/// `re`, from each drum term's derivative with respect to its phase, `dbo` (output drum,
/// phase θ + β_o) and `dbi` (input drum, phase R·θ + β_i).
#[inline]
fn error_dtheta_of(r: f64, re: f64, dbo: f64, dbi: f64) -> f64 {
    -re / (re + r) + dbo + r * dbi
}

/// [`ecc_grad_at`] at phase `phi`, rad.
fn ecc_grad(r: f64, d: f64, phi: f64) -> (f64, f64) {
    let (s, c) = sin_cos(phi);
    ecc_grad_at(r, d, s, c)
}

impl Capstan {
    /// A capstan of nominal ratio `ratio` (motor turns per output turn, > 0) and drum centre
    /// distance `drum_distance_m` (m, > 0).
    ///
    /// # Errors
    /// [`Error::NotFinite`] or [`Error::NonPositive`] naming `ratio` or `drum_distance_m`.
    #[cfg(feature = "std")]
    pub fn try_new(ratio: f64, drum_distance_m: f64) -> Result<Capstan, Error> {
        Ok(Capstan {
            ratio: positive("ratio", ratio)?,
            drum_distance_m: positive("drum_distance_m", drum_distance_m)?,
        })
    }

    /// A capstan of nominal ratio `ratio` and drum centre distance `drum_distance_m` (m),
    /// unchecked: for a caller that has checked both are finite and positive with errors of
    /// its own (`hapcal-runtime`, also without `std`, where [`Error`] does not exist).
    /// Otherwise eq. 1 evaluates to NaN or ∞, or to numbers without meaning.
    pub fn new_unchecked(ratio: f64, drum_distance_m: f64) -> Capstan {
        Capstan {
            ratio,
            drum_distance_m,
        }
    }

    /// Nominal ratio `R` (dimensionless).
    pub fn ratio(&self) -> f64 {
        self.ratio
    }

    /// Drum centre distance `D`, m.
    pub fn drum_distance_m(&self) -> f64 {
        self.drum_distance_m
    }

    /// The first reason eq. 1 is not defined for `p` on this capstan, or `None`: a field that
    /// is not finite, `|r_o| ≥ D` or `|r_i| ≥ D`, or `R + Re ≤ 0`. Without `std`, for callers
    /// that report it with errors of their own (`hapcal-runtime`); [`Self::check_params`]
    /// reports it as an [`Error`] with `std`.
    pub fn params_fault(&self, p: &CapstanParams) -> Option<CapstanFault> {
        let fields = [
            ("c_rad", p.c_rad),
            ("re", p.re),
            ("r_o_m", p.r_o_m),
            ("beta_o_rad", p.beta_o_rad),
            ("r_i_m", p.r_i_m),
            ("beta_i_rad", p.beta_i_rad),
        ];
        if let Some(&(name, value)) = fields.iter().find(|(_, v)| !v.is_finite()) {
            return Some(CapstanFault::NotFinite { name, value });
        }
        for (name, value) in [("r_o_m", p.r_o_m), ("r_i_m", p.r_i_m)] {
            if value.abs() >= self.drum_distance_m {
                return Some(CapstanFault::EccentricityTooLarge { name, value });
            }
        }
        let ratio = self.ratio + p.re;
        (ratio <= 0.0).then_some(CapstanFault::RatioNotPositive { value: ratio })
    }

    /// Checks that eq. 1 is defined for `p`: finite fields, `|r_o|, |r_i| < D`, `R + Re > 0`
    /// ([`Self::params_fault`]).
    ///
    /// # Errors
    /// [`Error::NotFinite`] naming the field, [`Error::EccentricityTooLarge`] for `r_o_m` or
    /// `r_i_m`, [`Error::NonPositive`] named `ratio + re` when `R + Re ≤ 0`.
    #[cfg(feature = "std")]
    pub fn check_params(&self, p: &CapstanParams) -> Result<(), Error> {
        match self.params_fault(p) {
            None => Ok(()),
            Some(CapstanFault::NotFinite { name, value }) => Err(Error::NotFinite {
                name: name.to_owned(),
                value,
            }),
            Some(CapstanFault::EccentricityTooLarge { name, value }) => {
                Err(Error::EccentricityTooLarge {
                    name,
                    value,
                    drum_distance_m: self.drum_distance_m,
                })
            }
            Some(CapstanFault::RatioNotPositive { value }) => Err(Error::NonPositive {
                name: "ratio + re",
                value,
            }),
        }
    }

    /// Capstan transmission error Δθ_caps(θ), rad (paper eq. 1, as written in docs/design.md §3):
    ///
    /// ```text
    /// Δθ = c − Re/(Re+R)·θ
    ///    + atan(r_o sin(θ+β_o) / (D − r_o cos(θ+β_o))) − atan(r_o sin β_o / (D − r_o cos β_o))
    ///    + atan(r_i sin(Rθ+β_i) / (D − r_i cos(Rθ+β_i))) − atan(r_i sin β_i / (D − r_i cos β_i))
    /// ```
    ///
    /// `theta` is the joint reading (motor angle / R); offset + ratio error + output-drum and
    /// input-drum eccentricity. `Δθ(0) = c` exactly. The value is only meaningful where
    /// [`Capstan::check_params`] accepts `p` (otherwise it may be NaN or ∞). Evaluated by
    /// [`CapstanTransmission::error_and_dtheta`].
    pub fn error_rad(&self, p: &CapstanParams, theta: JointRad) -> f64 {
        CapstanTransmission::new(*self, *p)
            .error_and_dtheta(theta)
            .0
    }

    /// The true output angle for reading `theta`: `θ + Δθ(θ)`, rad ([`Capstan::error_rad`],
    /// paper eq. 1).
    pub fn output_rad(&self, p: &CapstanParams, theta: JointRad) -> f64 {
        theta.0 + self.error_rad(p, theta)
    }

    /// Gradient of Δθ (paper eq. 1) with respect to `(c, re, r_o, beta_o, r_i, beta_i)`, analytic.
    ///
    /// Units: rad/rad, rad (per unit `Re`), rad/m, rad/rad, rad/m, rad/rad — the order and units
    /// of `hapcal_problems::CapstanProblem`'s layout.
    pub fn error_grad(&self, p: &CapstanParams, theta: JointRad) -> [f64; 6] {
        let (r, d, t) = (self.ratio, self.drum_distance_m, theta.0);
        let (dro_t, dbo_t) = ecc_grad(p.r_o_m, d, t + p.beta_o_rad);
        let (dro_0, dbo_0) = ecc_grad(p.r_o_m, d, p.beta_o_rad);
        let (dri_t, dbi_t) = ecc_grad(p.r_i_m, d, r * t + p.beta_i_rad);
        let (dri_0, dbi_0) = ecc_grad(p.r_i_m, d, p.beta_i_rad);
        let sum = p.re + r;
        [
            1.0,
            -r / (sum * sum) * t,
            dro_t - dro_0,
            dbo_t - dbo_0,
            dri_t - dri_0,
            dbi_t - dbi_0,
        ]
    }

    /// The linearisation of Δθ (paper eq. 1) about a perfect drive (`Re = 0`, no eccentricity),
    /// in Cartesian eccentricity coordinates: for small `r_o`, `r_i`, `Re`,
    ///
    /// ```text
    /// Δθ(θ) ≈ c − (Re/R)·θ + a_o·sin θ + b_o·(cos θ − 1) + a_i·sin Rθ + b_i·(cos Rθ − 1)
    /// ```
    ///
    /// with `a_o = (r_o/D)·cos β_o`, `b_o = (r_o/D)·sin β_o` (and alike for the input drum), since
    /// `atan(r sin φ / (D − r cos φ)) ≈ (r/D)·sin φ`. Returns the six basis functions
    /// `[1, θ, sin θ, cos θ − 1, sin Rθ, cos Rθ − 1]` (rad per unit coefficient) at reading
    /// `theta`. The paper's polar parameters `(r, β)` are singular where the eccentricity is
    /// zero ([`Capstan::error_grad`] has no `β` column there); these coordinates are not, which
    /// is what a design criterion evaluated at the nominal drive needs.
    pub fn linear_basis(&self, theta: JointRad) -> [f64; 6] {
        let (t, r) = (theta.0, self.ratio);
        let ((s, c), (sr, cr)) = (sin_cos(t), sin_cos(r * t));
        [1.0, t, s, c - 1.0, sr, cr - 1.0]
    }

    /// `∂Δθ/∂θ` (paper eq. 1), analytic, rad/rad: the derivative of
    /// [`CapstanTransmission::error_and_dtheta`], without its arctangents (the derivative
    /// needs only each drum's sine and cosine).
    pub fn error_dtheta(&self, p: &CapstanParams, theta: JointRad) -> f64 {
        let (r, d, t) = (self.ratio, self.drum_distance_m, theta.0);
        let (_, dbo) = ecc_grad(p.r_o_m, d, t + p.beta_o_rad);
        let (_, dbi) = ecc_grad(p.r_i_m, d, r * t + p.beta_i_rad);
        error_dtheta_of(r, p.re, dbo, dbi)
    }
}

/// A capstan with its eq. 1 parameters, ready to evaluate at many readings: the two
/// eccentricity terms at θ = 0 are computed once. The one evaluation of eq. 1:
/// [`Capstan::error_rad`] goes through it, [`Capstan::error_dtheta`] shares its derivative's
/// formula, and `hapcal-runtime` holds one per capstan joint. No allocation.
///
/// `F` gives the sine, cosine and arctangent ([`ElementaryFunctions`]): the crate's own by
/// default; the runtime passes its own.
///
/// Source: paper eq. 1; docs/design.md §3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CapstanTransmission<F = DefaultFunctions> {
    functions: PhantomData<F>,
    capstan: Capstan,
    params: CapstanParams,
    /// `atan(r_o sin β_o / (D − r_o cos β_o))`, the output-drum term at θ = 0, rad.
    output_ecc_at_zero: f64,
    /// `atan(r_i sin β_i / (D − r_i cos β_i))`, the input-drum term at θ = 0, rad.
    input_ecc_at_zero: f64,
}

impl CapstanTransmission {
    /// `capstan` with parameters `params`, evaluated with the crate's own functions
    /// ([`DefaultFunctions`]). The numbers are only meaningful where
    /// [`Capstan::check_params`] accepts `params` (otherwise they may be NaN or ∞).
    #[inline]
    pub fn new(capstan: Capstan, params: CapstanParams) -> CapstanTransmission {
        CapstanTransmission::with_functions(capstan, params)
    }
}

impl<F: ElementaryFunctions> CapstanTransmission<F> {
    /// As [`CapstanTransmission::new`], evaluated with the functions of `F`.
    #[inline]
    pub fn with_functions(capstan: Capstan, params: CapstanParams) -> CapstanTransmission<F> {
        let d = capstan.drum_distance_m;
        CapstanTransmission {
            functions: PhantomData,
            capstan,
            params,
            output_ecc_at_zero: ecc_and_dphi::<F>(params.r_o_m, d, params.beta_o_rad).0,
            input_ecc_at_zero: ecc_and_dphi::<F>(params.r_i_m, d, params.beta_i_rad).0,
        }
    }

    /// The capstan (ratio and drum distance).
    pub fn capstan(&self) -> Capstan {
        self.capstan
    }

    /// The eq. 1 parameters.
    pub fn params(&self) -> &CapstanParams {
        &self.params
    }

    /// Transmission error Δθ_caps(θ) (rad, paper eq. 1; see [`Capstan::error_rad`]) and its
    /// derivative `∂Δθ_caps/∂θ` (rad/rad, eq. 1 differentiated) at reading `theta`: one
    /// sine, cosine and arctangent per drum. `Δθ_caps(0) = c` exactly.
    #[inline]
    pub fn error_and_dtheta(&self, theta: JointRad) -> (f64, f64) {
        let (r, d, t, p) = (
            self.capstan.ratio,
            self.capstan.drum_distance_m,
            theta.0,
            &self.params,
        );
        let (eo, dbo) = ecc_and_dphi::<F>(p.r_o_m, d, t + p.beta_o_rad);
        let (ei, dbi) = ecc_and_dphi::<F>(p.r_i_m, d, r * t + p.beta_i_rad);
        // Each eccentricity difference first, so that θ = 0 gives exactly `c`.
        let error = p.c_rad - p.re / (p.re + r) * t
            + (eo - self.output_ecc_at_zero)
            + (ei - self.input_ecc_at_zero);
        (error, error_dtheta_of(r, p.re, dbo, dbi))
    }
}

#[cfg(test)]
mod tests;
