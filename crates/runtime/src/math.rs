//! The few elementary functions the evaluation needs: the platform's with `std`, libm's
//! without (the same functions to within an ulp or so; the tests hold either to 1e-12).

#[cfg(feature = "std")]
#[inline]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    x.sin_cos()
}

#[cfg(not(feature = "std"))]
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
