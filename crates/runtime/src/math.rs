//! The few elementary functions the evaluation needs: libm's `sincos` in every build (one
//! call for both), the platform's `atan` with `std` and libm's without (the same functions
//! to within an ulp or so; the tests hold either to 1e-12).

/// Sine and cosine of `x` (rad) in one call (libm's, with or without `std`: the standard
/// library computes them apart).
#[inline]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    libm::sincos(x)
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
