//! The few elementary functions the evaluation needs: libm's `sincos` in every build (one
//! call for both), the platform's `atan` with `std` and libm's without (the same functions
//! to within an ulp or so; the tests hold either to 1e-12), and sine and cosine of an angle
//! near one whose sine and cosine are known. The transmissions' formulas are
//! `hapcal-transmission`'s, evaluated with these functions ([`RuntimeFunctions`]).

/// Sine and cosine of `x` (rad) in one call (libm's, with or without `std`: the standard
/// library computes them apart).
#[inline]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

/// Largest `|x − base|` (rad) for which [`sin_cos_near`] sums its series: the first term left
/// out, `δ¹¹/11!` of the sine, is 2.5e-19 at 0.1 rad, far below an ulp of a sine near 1.
#[cfg(feature = "std")]
pub(crate) const NEAR_RAD: f64 = 0.1;

/// Sine and cosine of `x` (rad) from those of `base` (`(sin base, cos base)`) by the angle
/// sum `sin(b + δ) = sin b + (sin b·(cos δ − 1) + cos b·sin δ)` with `sin δ` and `cos δ − 1`
/// from their Taylor series (to `δ⁹` and `δ¹⁰`; Abramowitz & Stegun 4.3.65–66) when
/// `|δ| ≤ NEAR_RAD`, otherwise [`sin_cos`]: for a deflected angle next to the reading, a
/// few multiplications instead of a libm call, within two ulps of it.
#[cfg(feature = "std")]
#[inline(always)]
pub(crate) fn sin_cos_near(x: f64, base: f64, (s0, c0): (f64, f64)) -> (f64, f64) {
    let d = x - base;
    if d == 0.0 {
        return (s0, c0);
    }
    // Also for a NaN difference: libm then says what the angle is.
    if d.abs() > NEAR_RAD || d.is_nan() {
        return sin_cos(x);
    }
    let d2 = d * d;
    let sin_d = d
        * (1.0
            - d2 * (1.0 / 6.0)
                * (1.0
                    - d2 * (1.0 / 20.0) * (1.0 - d2 * (1.0 / 42.0) * (1.0 - d2 * (1.0 / 72.0)))));
    let cos_d_m1 = -0.5
        * d2
        * (1.0
            - d2 * (1.0 / 12.0)
                * (1.0
                    - d2 * (1.0 / 30.0) * (1.0 - d2 * (1.0 / 56.0) * (1.0 - d2 * (1.0 / 90.0)))));
    (
        s0 + (s0 * cos_d_m1 + c0 * sin_d),
        c0 + (c0 * cos_d_m1 - s0 * sin_d),
    )
}

#[cfg(feature = "std")]
#[inline]
pub(crate) fn atan(x: f64) -> f64 {
    x.atan()
}

#[cfg(not(feature = "std"))]
#[inline]
pub(crate) fn atan(x: f64) -> f64 {
    libm::atan(x)
}

/// The runtime's elementary functions as `hapcal-transmission` takes them: the capstans'
/// eq. 1 is the library's formula, evaluated with [`sin_cos`] and [`atan`] (libm's `sincos`
/// is about half the cost of the standard library's sine plus cosine).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct RuntimeFunctions;

impl hapcal_transmission::ElementaryFunctions for RuntimeFunctions {
    #[inline]
    fn sin_cos(x: f64) -> (f64, f64) {
        sin_cos(x)
    }

    #[inline]
    fn atan(x: f64) -> f64 {
        atan(x)
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::{NEAR_RAD, sin_cos, sin_cos_near};

    #[test]
    fn sine_and_cosine_near_a_known_angle_agree_with_libm_to_two_ulps() {
        for base in [-3.0, -1.2, 0.0, 0.4, std::f64::consts::FRAC_PI_2, 2.9] {
            let sc = sin_cos(base);
            for d in [
                0.0, 1e-12, -3e-7, 2e-4, -0.013, 0.05, -0.0999, NEAR_RAD, 0.3, -1.0,
            ] {
                let (s, c) = sin_cos_near(base + d, base, sc);
                let (s_ref, c_ref) = sin_cos(base + d);
                // Two ulps of a number of magnitude at most 1, and the rounding of base + d.
                let tol = 4.5e-16;
                assert!((s - s_ref).abs() <= tol, "{base} {d}: {s} {s_ref}");
                assert!((c - c_ref).abs() <= tol, "{base} {d}: {c} {c_ref}");
            }
        }
    }
}
