//! The elementary functions the evaluations are written over ([`ElementaryFunctions`]), and
//! the crate's own choice of them ([`DefaultFunctions`]).

/// The sine, cosine and arctangent an evaluation of eq. 1 uses ([`CapstanTransmission`]).
///
/// The standard library's and libm's differ in the last bit for about 3 % of sines and
/// cosines, and libm's `sincos` costs about half of the standard library's sine plus cosine:
/// the library keeps the standard library's (its numbers do not move), and `hapcal-runtime`
/// evaluates the same formula with its own, faster choice.
///
/// [`CapstanTransmission`]: crate::CapstanTransmission
pub trait ElementaryFunctions {
    /// `(sin x, cos x)`, x in rad.
    fn sin_cos(x: f64) -> (f64, f64);
    /// `atan x`, rad.
    fn atan(x: f64) -> f64;
}

/// The crate's elementary functions: the standard library's with `std`, libm's without.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DefaultFunctions;

#[cfg(feature = "std")]
impl ElementaryFunctions for DefaultFunctions {
    #[inline]
    fn sin_cos(x: f64) -> (f64, f64) {
        x.sin_cos()
    }

    #[inline]
    fn atan(x: f64) -> f64 {
        x.atan()
    }
}

#[cfg(not(feature = "std"))]
impl ElementaryFunctions for DefaultFunctions {
    #[inline]
    fn sin_cos(x: f64) -> (f64, f64) {
        libm::sincos(x)
    }

    #[inline]
    fn atan(x: f64) -> f64 {
        libm::atan(x)
    }
}
