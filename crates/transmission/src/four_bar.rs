//! The planar four-bar (parallelogram) of joint 4 and joint 4's combined transmission.

use crate::capstan::{Capstan, CapstanParams, JointRad};
use crate::error::{Error, positive};

/// Planar four-bar linkage: crank, coupler, rocker and ground link lengths, m.
///
/// Geometry: the crank pivots at `A = (0, 0)`, the rocker at `B = (l4, 0)` (the ground link runs
/// from A to B). The crank end is `P = A + l1·(cos φ, sin φ)`, the rocker end
/// `Q = B + l3·(cos ψ, sin ψ)`, and the coupler closes the loop, `|Q − P| = l2`. Both angles
/// are measured from the ground link's direction A→B, counter-clockwise, so an ideal
/// parallelogram (`l1 = l3`, `l2 = l4`) has `ψ = φ`.
///
/// Source: paper eq. 2 (whose printed form lost the arccos and the square root; docs/design.md §3
/// asks for the law-of-cosines closure instead). Identifiability of the link deviations:
/// Schroer et al. 1997 (only one length of a planar parallelogram is identifiable from its
/// input–output angles), which is why joint 4 is identified as a polynomial
/// (`hapcal_problems::PolynomialProblem`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FourBar {
    /// Crank length `L1` (driven link, pivot A), m.
    pub l1_m: f64,
    /// Coupler length `L2`, m.
    pub l2_m: f64,
    /// Rocker length `L3` (output link, pivot B), m.
    pub l3_m: f64,
    /// Ground link length `L4` (A to B), m.
    pub l4_m: f64,
}

/// Closed configuration of a [`FourBar`] at one crank angle.
struct Closure {
    /// Rocker angle ψ, rad.
    psi: f64,
    /// Coupler vector `w = Q − P`, m.
    w: [f64; 2],
    /// `16·(area of the triangle B, P, Q)²`, m⁴; zero at a dead centre.
    area16_sq: f64,
}

impl FourBar {
    /// A four-bar with the given crank, coupler, rocker and ground lengths, m.
    ///
    /// # Errors
    /// [`Error::NotFinite`] or [`Error::NonPositive`] naming the first bad length.
    pub fn try_new(l1_m: f64, l2_m: f64, l3_m: f64, l4_m: f64) -> Result<FourBar, Error> {
        Ok(FourBar {
            l1_m: positive("l1_m", l1_m)?,
            l2_m: positive("l2_m", l2_m)?,
            l3_m: positive("l3_m", l3_m)?,
            l4_m: positive("l4_m", l4_m)?,
        })
    }

    /// Closes the loop at crank angle `phi` on the open branch.
    ///
    /// With the diagonal `d = P − B` (length `s`, direction `γ`) and the angle `λ ∈ [0, π]` of
    /// triangle B, P, Q at B (law of cosines, computed as `atan2(4·area, l3² + s² − l2²)` for
    /// accuracy near flat triangles), the open branch is `ψ = γ − λ`: the rocker end lies
    /// clockwise of the diagonal seen from B. For `φ ∈ (0, π)` that is the non-crossed
    /// quadrilateral A, P, Q, B, and this assembly mode is kept for every `φ` so that ψ is
    /// continuous wherever the loop closes.
    fn close(&self, phi: f64) -> Result<Closure, Error> {
        let (l1, l2, l3, l4) = (self.l1_m, self.l2_m, self.l3_m, self.l4_m);
        if !phi.is_finite() {
            return Err(Error::NotFinite {
                name: "phi".to_owned(),
                value: phi,
            });
        }
        let (sp, cp) = phi.sin_cos();
        let (dx, dy) = (l1 * cp - l4, l1 * sp);
        let s = dx.hypot(dy);
        let area16_sq = (l3 + s + l2) * (s + l2 - l3) * (l3 - s + l2) * (l3 + s - l2);
        if s == 0.0 || area16_sq < 0.0 {
            return Err(Error::NoClosure { phi });
        }
        let lambda = area16_sq.sqrt().atan2(l3 * l3 + s * s - l2 * l2);
        let psi = dy.atan2(dx) - lambda;
        let (ss, cs) = psi.sin_cos();
        let w = [l4 + l3 * cs - l1 * cp, l3 * ss - l1 * sp];
        Ok(Closure { psi, w, area16_sq })
    }

    /// Like [`FourBar::close`], but also rejects dead centres (coupler and rocker aligned),
    /// where ψ is not differentiable.
    fn close_regular(&self, phi: f64) -> Result<Closure, Error> {
        let c = self.close(phi)?;
        if c.area16_sq <= 0.0 {
            return Err(Error::NoClosure { phi });
        }
        Ok(c)
    }

    /// Output (rocker) angle ψ, rad, for input crank angle `phi`, rad, both measured from the
    /// ground link the same way (see [`FourBar`]); open branch, law of cosines (paper eq. 2 as
    /// corrected in docs/design.md §3).
    ///
    /// An ideal parallelogram (`l1 = l3`, `l2 = l4`) gives `ψ = φ` (to 1e-12) for `φ ∈ (0, π)`;
    /// at `φ = 0` and `φ = π` it folds flat and its branches meet. The result is not wrapped:
    /// it lies in `(−2π, π]`, within a few tenths of `φ` in the working range.
    ///
    /// # Errors
    /// [`Error::NoClosure`] where the loop cannot close: the diagonal `|P − B|` exceeds
    /// `l2 + l3`, is below `|l2 − l3|`, or is zero. [`Error::NotFinite`] for a non-finite `phi`.
    pub fn output_rad(&self, phi: f64) -> Result<f64, Error> {
        Ok(self.close(phi)?.psi)
    }

    /// Transmission error of the four-bar, `ψ(φ) − φ`, rad.
    ///
    /// # Errors
    /// As [`FourBar::output_rad`].
    pub fn error_rad(&self, phi: f64) -> Result<f64, Error> {
        Ok(self.output_rad(phi)? - phi)
    }

    /// `dψ/dφ`, analytic (implicit differentiation of the closure `|Q − P|² = l2²`), rad/rad:
    /// `l1 (w · u'(φ)) / (l3 (w · u'(ψ)))` with `w = Q − P`, `u'(a) = (−sin a, cos a)`.
    ///
    /// # Errors
    /// As [`FourBar::output_rad`], and [`Error::NoClosure`] at a dead centre (coupler and
    /// rocker aligned), where the derivative is unbounded.
    pub fn d_output_d_input(&self, phi: f64) -> Result<f64, Error> {
        let c = self.close_regular(phi)?;
        let (ss, cs) = c.psi.sin_cos();
        let (sp, cp) = phi.sin_cos();
        let f_psi = self.l3_m * (c.w[1] * cs - c.w[0] * ss);
        let f_phi = self.l1_m * (c.w[1] * cp - c.w[0] * sp);
        Ok(f_phi / f_psi)
    }

    /// `∂ψ/∂(l1, l2, l3, l4)`, analytic (implicit differentiation of the closure), rad/m each.
    ///
    /// # Errors
    /// As [`FourBar::d_output_d_input`].
    pub fn d_output_d_lengths(&self, phi: f64) -> Result<[f64; 4], Error> {
        let c = self.close_regular(phi)?;
        let (ss, cs) = c.psi.sin_cos();
        let (sp, cp) = phi.sin_cos();
        let [wx, wy] = c.w;
        // F = |w|² − l2² with w = B + l3 u(ψ) − l1 u(φ); ∂ψ/∂l = −(∂F/∂l)/(∂F/∂ψ), the
        // common factor 2 cancels.
        let f_psi = self.l3_m * (wy * cs - wx * ss);
        Ok([
            (wx * cp + wy * sp) / f_psi,
            self.l2_m / f_psi,
            -(wx * cs + wy * ss) / f_psi,
            -wx / f_psi,
        ])
    }
}

/// Joint 4's combined transmission: capstan 4 drives the crank of the four-bar, and the joint
/// angle is the rocker's.
///
/// For a joint-4 reading θ (rad), the crank turns by the capstan's true output angle
/// `θ + Δθ_caps(θ)` (paper eq. 1) from its angle `phi0_rad` at θ = 0, and the true joint angle
/// is the rocker's turn from its own angle at θ = 0 in the ideal mechanism:
/// `ψ(φ0 + θ + Δθ_caps(θ)) − φ0`. The transmission error is that minus θ.
///
/// **Choice of φ0.** The ideal parallelogram folds flat at φ = 0 and φ = π, so `φ0 + θ` must
/// stay inside `(0, π)` over the whole joint range, with margin (a real four-bar with
/// `l1 + l4 > l2 + l3` cannot even close near π). [`Joint4Transmission::phi0_mid_range_rad`]
/// puts the crank perpendicular to the ground link at the middle of the joint range,
/// `φ0 = π/2 − (lo + hi)/2`; for docs/design.md's q4 ∈ [0.3, 1.8] rad that is φ0 ≈ 0.5208 rad and
/// φ ∈ [0.82, 2.32] rad. Then the diagonal `s² = l1² + l4² − 2 l1 l4 cos(π/2 + θ_a)` with
/// `θ_a = θ − (lo + hi)/2`, the paper's `s` (eq. 2, written with `cos(π/2 − θ_a)`) up to the
/// sense in which θ_a is counted; the paper's own choice, φ0 = π/2 with θ_a = θ, would reach
/// φ = π at θ = π/2 inside q4's range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint4Transmission {
    /// Capstan 4 (ratio and drum distance).
    pub capstan: Capstan,
    /// Capstan 4's eq. 1 parameters.
    pub params: CapstanParams,
    /// The parallelogram.
    pub four_bar: FourBar,
    /// Crank angle at reading θ = 0, rad (measured from the ground link, see [`FourBar`]).
    pub phi0_rad: f64,
}

impl Joint4Transmission {
    /// `φ0` that puts the crank perpendicular to the ground link at the middle of the joint
    /// range `[lo_rad, hi_rad]`: `π/2 − (lo + hi)/2`, rad. See [`Joint4Transmission`].
    pub fn phi0_mid_range_rad(lo_rad: f64, hi_rad: f64) -> f64 {
        std::f64::consts::FRAC_PI_2 - 0.5 * (lo_rad + hi_rad)
    }

    /// True joint-4 angle for reading `theta`: `ψ(φ0 + θ + Δθ_caps(θ)) − φ0`, rad (paper eqs. 1
    /// and 2).
    ///
    /// # Errors
    /// [`Error::NoClosure`] where the four-bar cannot close (see [`FourBar::output_rad`]).
    pub fn output_rad(&self, theta: JointRad) -> Result<f64, Error> {
        let phi = self.phi0_rad + self.capstan.output_rad(&self.params, theta);
        Ok(self.four_bar.output_rad(phi)? - self.phi0_rad)
    }

    /// Joint-4 transmission error, `output_rad(θ) − θ`, rad.
    ///
    /// # Errors
    /// As [`Joint4Transmission::output_rad`].
    pub fn error_rad(&self, theta: JointRad) -> Result<f64, Error> {
        Ok(self.output_rad(theta)? - theta.0)
    }
}

#[cfg(test)]
mod tests;
