//! The Huber loss that bounds gross errors in every kind of data (Huber 1981, *Robust
//! Statistics*, §7.8, metrically winsorized residuals): a fit, the robust scale of its
//! residuals from their median norm, and every sample beyond the corner pulled back onto it;
//! fitted again until the set of bounded samples no longer changes. Measurement files bound a
//! marker's position ([`crate::measured`]), socket folders a row's distance from its socket,
//! distance logs (a chain's and a haptic device's) a row's distance ([`crate::calibrate`],
//! [`crate::haptic`]); every workflow lists what it bounded with its file and line
//! ([`crate::report::Downweighted`]).

use faer::{Col, ColMut, ColRef, MatMut};
use hapcal_identify::{EvalError, ParamLayout, Problem};

use crate::report::Downweighted;

/// Corner of the Huber loss, in robust standard deviations per axis of a residual: a sample
/// whose residual (3-D for a marker or a socket row, 1-D for a distance) exceeds
/// `HUBER_CORNER·√d·s` pulls on the fit with a bounded force. `|e|²/s²` of a clean Gaussian
/// sample is χ² with `d` degrees of freedom, above 48 with probability 10⁻⁹ for `d = 3` (16:
/// 6·10⁻⁵ for `d = 1`): on Gaussian data the loss is least squares, sample for sample. Real
/// residuals carry model error and have heavier tails: at 3, three samples of the TIAGo
/// recording (the largest 6.7 mm) were bounded though nothing sets them apart from the rest;
/// at 4 none is.
pub const HUBER_CORNER: f64 = 4.0;

/// Residuals per parameter a fit needs before its residuals measure the noise well enough to
/// call a sample a gross error.
pub(crate) const MIN_REDUNDANCY: f64 = 4.0;

/// Samples a fit needs before the Huber loss judges any of them.
pub(crate) const MIN_SAMPLES: usize = 20;

/// Fits at most, until the set of bounded samples no longer changes.
const MAX_ROUNDS: usize = 10;

/// The dimension of one sample's residual.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Dim {
    /// A distance (cable encoder, draw wire): one residual.
    One,
    /// A position (marker, socket row): three residuals.
    Three,
}

impl Dim {
    /// √d.
    fn sqrt(self) -> f64 {
        match self {
            Dim::One => 1.0,
            Dim::Three => 3f64.sqrt(),
        }
    }

    /// Median of the χ distribution with `d` degrees of freedom: the median norm of an
    /// isotropic Gaussian error of unit standard deviation per axis.
    fn chi_median(self) -> f64 {
        match self {
            Dim::One => 0.674_49,
            Dim::Three => 1.538_2,
        }
    }
}

/// One fit as the Huber loss judges it.
pub(crate) struct Round {
    /// Every sample's residual norm, in one order for every round, m.
    pub norms: Vec<f64>,
    /// `√(m/(m − p))` of the fit's `m` residuals and `p` kept parameters ([`redundancy`]):
    /// residuals of a fit are smaller than the noise by its inverse. The first round's sets
    /// the corner.
    pub redundancy: f64,
}

/// A sample beyond the corner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Bound {
    /// Its index in [`Round::norms`].
    pub sample: usize,
    /// Its residual norm in the fit that bounded it, m.
    pub norm: f64,
    /// The corner, m: the residual the next fit sees instead.
    pub corner: f64,
}

impl Bound {
    /// The part of a residual `e` (of norm [`Bound::norm`]) beyond the corner: `e` less it
    /// is `e·corner/|e|`.
    pub(crate) fn excess(&self, e: &[f64]) -> Vec<f64> {
        let keep = self.corner / self.norm;
        e.iter().map(|v| v - v * keep).collect()
    }
}

/// `√(m/(m − p))` for a fit of `p` kept parameters from `m` residuals; `None` when there are
/// fewer than [`MIN_REDUNDANCY`] residuals per parameter: such a fit fits the noise itself,
/// and a gross error hides in it.
pub(crate) fn redundancy(n_residuals: usize, n_kept: usize) -> Option<f64> {
    let (m, p) = (n_residuals as f64, n_kept as f64);
    (m >= MIN_REDUNDANCY * p).then(|| (m / (m - p)).sqrt())
}

/// The samples the Huber loss bounds. `fit(bounds)` fits with the samples of `bounds` pulled
/// back onto the corner (metrically winsorized: the residual `e` the sample had in the fit
/// before replaced by `e·corner/|e|`; an empty list the first time) and returns its round,
/// or `None` when it cannot fit or judge (the iteration ends with the bounds of the last
/// round). The robust scale `s` is the first round's median residual norm over the median
/// of χ with `dim` degrees of freedom, times its [`Round::redundancy`]; the corner is
/// `HUBER_CORNER·√d·s`. Fitted again until the set of bounded samples no longer changes (at
/// most 10 fits); the least-squares fit of the winsorized samples is then the Huber
/// M-estimate. Nothing with fewer than [`MIN_SAMPLES`] samples (`fit` is not called).
pub(crate) fn bound_gross_errors(
    n_samples: usize,
    dim: Dim,
    mut fit: impl FnMut(&[Bound]) -> Option<Round>,
) -> Vec<Bound> {
    if n_samples < MIN_SAMPLES {
        return Vec::new();
    }
    let mut corner = None;
    let mut bounded: Vec<Bound> = Vec::new();
    for _ in 0..MAX_ROUNDS {
        let Some(round) = fit(&bounded) else {
            break;
        };
        if round.norms.is_empty() {
            break;
        }
        let c = *corner.get_or_insert_with(|| {
            let mut norms = round.norms.clone();
            norms.sort_by(f64::total_cmp);
            HUBER_CORNER * dim.sqrt() * round.redundancy * norms[norms.len() / 2] / dim.chi_median()
        });
        let now: Vec<Bound> = (round.norms.iter().enumerate())
            .filter(|&(_, &norm)| norm > c)
            .map(|(sample, &norm)| Bound {
                sample,
                norm,
                corner: c,
            })
            .collect();
        let same = now.len() == bounded.len()
            && now.iter().zip(&bounded).all(|(a, b)| a.sample == b.sample);
        bounded = now;
        if same {
            break;
        }
    }
    bounded
}

/// The warning of a calibration whose fit bounded `bounded` (`what`: "training samples",
/// "socket rows", …) with the Huber loss evaluated on the `judge` model: how many, the
/// corner, the largest and where it is; `None` when none was bounded.
pub(crate) fn bounded_warning(bounded: &[Downweighted], what: &str, judge: &str) -> Option<String> {
    let first = bounded.first()?;
    let worst = (bounded.iter()).max_by(|a, b| a.residual_m.total_cmp(&b.residual_m))?;
    Some(format!(
        "{} {what} lie beyond {:.2} mm ({HUBER_CORNER} robust standard deviations per axis) \
         from the {judge} model and were bounded there by the Huber loss (the largest, {:.2} \
         mm, at {}); each is listed with its residual",
        bounded.len(),
        first.bound_m * 1e3,
        worst.residual_m * 1e3,
        worst.place(),
    ))
}

/// A least-squares problem with fixed amounts taken off some of its residuals: the
/// winsorized form of a problem whose measured values cannot be edited (a socket row's
/// measurement is its joint readings; the excess of its residual comes off instead).
/// Jacobian unchanged; evaluated dense (no row blocks).
pub(crate) struct Shifted<'a, P: Problem> {
    /// The problem.
    pub inner: &'a P,
    /// Per residual, the amount taken off (length `inner.n_residuals()`).
    pub shift: &'a [f64],
}

impl<P: Problem> Shifted<'_, P> {
    fn take_off(&self, mut out: ColMut<'_, f64>) {
        for (i, s) in self.shift.iter().enumerate() {
            out[i] -= s;
        }
    }
}

impl<P: Problem> Problem for Shifted<'_, P> {
    fn layout(&self) -> &ParamLayout {
        self.inner.layout()
    }

    fn n_residuals(&self) -> usize {
        self.inner.n_residuals()
    }

    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        self.inner.residuals(x, out.as_mut())?;
        self.take_off(out);
        Ok(())
    }

    fn jacobian(&self, x: ColRef<'_, f64>, jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.inner.jacobian(x, jac)
    }

    fn residuals_and_jacobian(
        &self,
        x: ColRef<'_, f64>,
        mut out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.inner.residuals_and_jacobian(x, out.as_mut(), jac)?;
        self.take_off(out);
        Ok(())
    }
}

/// The residuals of `problem` at `x`, as measured (unshifted).
///
/// # Errors
/// The problem cannot be evaluated at `x`.
pub(crate) fn residuals_at(
    problem: &impl Problem,
    x: ColRef<'_, f64>,
) -> Result<Col<f64>, EvalError> {
    let mut r = Col::<f64>::zeros(problem.n_residuals());
    problem.residuals(x, r.as_mut())?;
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::{Bound, Dim, Round, bound_gross_errors};

    /// 40 samples of residual ±1 (median 1, corner `4·1/0.67449 = 5.93` in 1-D) and one of
    /// 50: the 50 is bounded, and stays bounded when the next fit has moved nothing.
    #[test]
    fn a_gross_sample_is_bounded_and_the_rounds_stop_when_the_set_is_stable() {
        let mut norms: Vec<f64> = vec![1.0; 40];
        norms.push(50.0);
        let mut calls = 0;
        let bounds = bound_gross_errors(norms.len(), Dim::One, |_: &[Bound]| {
            calls += 1;
            Some(Round {
                norms: norms.clone(),
                redundancy: 1.0,
            })
        });
        assert_eq!(calls, 2);
        assert_eq!(bounds.len(), 1);
        assert_eq!(bounds[0].sample, 40);
        assert!((bounds[0].corner - 4.0 / 0.674_49).abs() < 1e-12);
        let excess = bounds[0].excess(&[-50.0]);
        assert!((excess[0] + 50.0 - bounds[0].corner).abs() < 1e-12);
    }

    /// Too few samples, or nothing beyond the corner: nothing bounded.
    #[test]
    fn clean_or_small_data_are_left_alone() {
        let norms: Vec<f64> = (0..30).map(|i| 1.0 + 0.1 * f64::from(i % 7)).collect();
        let fit = |_: &[Bound]| {
            Some(Round {
                norms: norms.clone(),
                redundancy: 1.1,
            })
        };
        assert!(bound_gross_errors(norms.len(), Dim::Three, fit).is_empty());
        assert!(bound_gross_errors(19, Dim::One, |_: &[Bound]| None).is_empty());
    }
}
