//! The capstan drive: ratio, drum distance and the transmission error of paper eq. 1.

use crate::error::{Error, positive};

/// Joint-side angle (motor angle / R), rad: what the device reports as the joint reading.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd)]
pub struct JointRad(pub f64);

/// Motor-side angle, rad (the motor encoder's angle, R times the joint-side angle).
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd)]
pub struct MotorRad(pub f64);

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

impl CapstanParams {
    /// The parameter a device file's `[calibration.values]` names `capstan{j}.{name}` (`c`,
    /// `re`, `r_o`, `beta_o`, `r_i`, `beta_i`), with the unit it is written in (`rad`, `1`,
    /// `m`); `None` for any other name.
    pub fn field_mut(&mut self, name: &str) -> Option<(&mut f64, &'static str)> {
        Some(match name {
            "c" => (&mut self.c_rad, "rad"),
            "re" => (&mut self.re, "1"),
            "r_o" => (&mut self.r_o_m, "m"),
            "beta_o" => (&mut self.beta_o_rad, "rad"),
            "r_i" => (&mut self.r_i_m, "m"),
            "beta_i" => (&mut self.beta_i_rad, "rad"),
            _ => return None,
        })
    }
}

/// A capstan drive: nominal ratio `R` (> 0) and drum centre distance `D` (> 0, m).
///
/// Source: paper, "Capstan drive" section and eq. 1; docs/design.md §3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capstan {
    ratio: f64,
    drum_distance_m: f64,
}

/// One eccentricity term of eq. 1, `atan(r sin φ / (D − r cos φ))`, rad.
fn ecc(r: f64, d: f64, phi: f64) -> f64 {
    (r * phi.sin() / (d - r * phi.cos())).atan()
}

/// `(∂/∂r, ∂/∂φ)` of [`ecc`]: `(D sin φ, r (D cos φ − r)) / (r² + D² − 2 r D cos φ)`.
fn ecc_grad(r: f64, d: f64, phi: f64) -> (f64, f64) {
    let (s, c) = phi.sin_cos();
    let q = r * r + d * d - 2.0 * r * d * c;
    (d * s / q, r * (d * c - r) / q)
}

impl Capstan {
    /// A capstan of nominal ratio `ratio` (motor turns per output turn, > 0) and drum centre
    /// distance `drum_distance_m` (m, > 0).
    ///
    /// # Errors
    /// [`Error::NotFinite`] or [`Error::NonPositive`] naming `ratio` or `drum_distance_m`.
    pub fn try_new(ratio: f64, drum_distance_m: f64) -> Result<Capstan, Error> {
        Ok(Capstan {
            ratio: positive("ratio", ratio)?,
            drum_distance_m: positive("drum_distance_m", drum_distance_m)?,
        })
    }

    /// Nominal ratio `R` (dimensionless).
    pub fn ratio(&self) -> f64 {
        self.ratio
    }

    /// Drum centre distance `D`, m.
    pub fn drum_distance_m(&self) -> f64 {
        self.drum_distance_m
    }

    /// Joint-side reading of a motor angle: `m / R`, rad.
    pub fn joint_from_motor(&self, m: MotorRad) -> JointRad {
        JointRad(m.0 / self.ratio)
    }

    /// Checks that eq. 1 is defined for `p`: finite fields, `|r_o|, |r_i| < D`, `R + Re > 0`.
    ///
    /// # Errors
    /// [`Error::NotFinite`] naming the field, [`Error::EccentricityTooLarge`] for `r_o_m` or
    /// `r_i_m`, [`Error::NonPositive`] named `ratio + re` when `R + Re ≤ 0`.
    pub fn check_params(&self, p: &CapstanParams) -> Result<(), Error> {
        let fields = [
            ("c_rad", p.c_rad),
            ("re", p.re),
            ("r_o_m", p.r_o_m),
            ("beta_o_rad", p.beta_o_rad),
            ("r_i_m", p.r_i_m),
            ("beta_i_rad", p.beta_i_rad),
        ];
        if let Some(&(name, value)) = fields.iter().find(|(_, v)| !v.is_finite()) {
            return Err(Error::NotFinite {
                name: name.to_owned(),
                value,
            });
        }
        for (name, value) in [("r_o_m", p.r_o_m), ("r_i_m", p.r_i_m)] {
            if value.abs() >= self.drum_distance_m {
                return Err(Error::EccentricityTooLarge {
                    name,
                    value,
                    drum_distance_m: self.drum_distance_m,
                });
            }
        }
        if self.ratio + p.re <= 0.0 {
            return Err(Error::NonPositive {
                name: "ratio + re",
                value: self.ratio + p.re,
            });
        }
        Ok(())
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
    /// [`Capstan::check_params`] accepts `p` (otherwise it may be NaN or ∞).
    pub fn error_rad(&self, p: &CapstanParams, theta: JointRad) -> f64 {
        let (r, d, t) = (self.ratio, self.drum_distance_m, theta.0);
        // Each eccentricity difference is formed first, so that θ = 0 gives exactly `c`.
        let output_ecc = ecc(p.r_o_m, d, t + p.beta_o_rad) - ecc(p.r_o_m, d, p.beta_o_rad);
        let input_ecc = ecc(p.r_i_m, d, r * t + p.beta_i_rad) - ecc(p.r_i_m, d, p.beta_i_rad);
        p.c_rad - p.re / (p.re + r) * t + output_ecc + input_ecc
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
        [
            1.0,
            t,
            t.sin(),
            t.cos() - 1.0,
            (r * t).sin(),
            (r * t).cos() - 1.0,
        ]
    }

    /// `∂Δθ/∂θ` (paper eq. 1), analytic, rad/rad.
    pub fn error_dtheta(&self, p: &CapstanParams, theta: JointRad) -> f64 {
        let (r, d, t) = (self.ratio, self.drum_distance_m, theta.0);
        let (_, dbo) = ecc_grad(p.r_o_m, d, t + p.beta_o_rad);
        let (_, dbi) = ecc_grad(p.r_i_m, d, r * t + p.beta_i_rad);
        -p.re / (p.re + r) + dbo + r * dbi
    }
}

#[cfg(test)]
mod tests;
