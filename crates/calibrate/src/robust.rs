//! The Huber loss that bounds gross errors in every kind of data (Huber 1981, *Robust
//! Statistics*, §7.8, metrically winsorized residuals): a fit, the robust scale of its
//! residuals from their median norm, and every sample beyond the corner pulled back onto it;
//! fitted again, the scale estimated again from each fit, until the set of bounded samples
//! and the scale no longer change. Measurement files bound a
//! marker's position (the measurement workflow), socket folders a row's distance from its socket,
//! distance logs (a chain's and a haptic device's) a row's distance (`calibrate::run`,
//! the haptic workflow); every workflow lists what it bounded with its file and line
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

/// Corners beyond which a socket row or chain distance-log row (`solve::winsorize`)
/// is left out of the fits rather than bounded (weight 0, [`Bound::weight`]): the outer
/// point of a redescending loss (Hampel's three-part redescending ψ, Hampel, Ronchetti,
/// Rousseeuw & Stahel 1986, *Robust Statistics: The Approach Based on Influence Functions*,
/// on redescending M-estimators), here at twice the corner. The Huber loss bounds a row's pull by the corner but not
/// its leverage: a row whose joint reading glitched sits where no other row is, the fit can
/// follow it, and the corner's force alone moved parameters of the kuka_14 front placement
/// by 15 to 36 of their standard deviations (0.2 rad on joint_a2 in one row of 62,
/// `tests/gross_errors.rs`, with the geometric and the mass-compliance model judging). Left
/// out, it moves none by more than 0.1 of one. A clean row lies beyond `2·4·√d` robust
/// standard deviations with probability below 10⁻¹⁴. Marker files and haptic logs move a
/// bounded sample onto the corner instead (the measurement and haptic workflows).
pub(crate) const REJECTION: f64 = 2.0;

/// Fits at most, until the set of bounded samples and the corner no longer change.
const MAX_ROUNDS: usize = 10;

/// Relative change of the corner between two fits below which the Huber iteration has
/// converged (with the same samples bounded): 1 %, well inside the corner's own sampling
/// error (a median of a few hundred residual norms varies by several per cent).
const CORNER_TOLERANCE: f64 = 0.01;

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
    /// residuals of a fit are smaller than the noise by its inverse.
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
    /// The sample's weight in the iteratively reweighted fits of [`Weighted`]: the Huber
    /// loss's `corner/norm` (below 1; its residual `e` then pulls with `w·|e|`, the corner's
    /// force), or 0 beyond [`REJECTION`] corners, where the sample is left out.
    pub(crate) fn weight(&self) -> f64 {
        if self.rejected() {
            0.0
        } else {
            self.corner / self.norm
        }
    }

    /// Whether the sample lies beyond [`REJECTION`] corners ([`Bound::weight`] 0).
    pub(crate) fn rejected(&self) -> bool {
        self.norm > REJECTION * self.corner
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
/// round). Every round sets its own corner `HUBER_CORNER·√d·s` from its robust scale `s`:
/// its median residual norm over the median of χ with `dim` degrees of freedom, times its
/// [`Round::redundancy`]. Fitted again until the set of bounded samples no longer changes and
/// the corner moved by less than [`CORNER_TOLERANCE`] of itself (at most [`MAX_ROUNDS`]
/// fits); the least-squares fit of the winsorized samples is then the Huber M-estimate with
/// its scale. Nothing with fewer than [`MIN_SAMPLES`] samples (`fit` is not called).
///
/// The scale is estimated again from every fit, not kept from the first: the first fit is
/// least squares on the samples as measured, and a gross error leaks into every other
/// residual through it (five gross distances of 2 to 40 mm among 300 rows of a simulated
/// haptic log put its median residual at 357 µm, the next fit's at 67 µm, the clean log's
/// at 6.6 µm), so its median overstates the scale and a corner set there (2.19 mm) lets
/// smaller gross errors through. The median of the next, winsorized fit's residuals no longer carries
/// them. statsmodels' `RLM.fit` (`scale_est="mad", update_scale=True`) updates its MAD
/// scale in every iteration for the same reason (Holland & Welsch 1977, "Robust regression
/// using iteratively reweighted least-squares", Commun. Stat. Theory Methods 6(9)).
pub(crate) fn bound_gross_errors(
    n_samples: usize,
    dim: Dim,
    mut fit: impl FnMut(&[Bound]) -> Option<Round>,
) -> Vec<Bound> {
    if n_samples < MIN_SAMPLES {
        return Vec::new();
    }
    let mut corner: Option<f64> = None;
    let mut bounded: Vec<Bound> = Vec::new();
    for _ in 0..MAX_ROUNDS {
        let Some(round) = fit(&bounded) else {
            break;
        };
        if round.norms.is_empty() {
            break;
        }
        let mut norms = round.norms.clone();
        norms.sort_by(f64::total_cmp);
        let c = HUBER_CORNER * dim.sqrt() * round.redundancy * norms[norms.len() / 2]
            / dim.chi_median();
        let now: Vec<Bound> = (round.norms.iter().enumerate())
            .filter(|&(_, &norm)| norm > c)
            .map(|(sample, &norm)| Bound {
                sample,
                norm,
                corner: c,
            })
            .collect();
        let same = now.len() == bounded.len()
            && now.iter().zip(&bounded).all(|(a, b)| a.sample == b.sample)
            && corner.is_none_or(|before| (c - before).abs() <= CORNER_TOLERANCE * before);
        bounded = now;
        corner = Some(c);
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

/// A least-squares problem with some of its residuals down-weighted: the Huber loss's
/// iteratively reweighted form (Holland & Welsch 1977, "Robust regression using iteratively
/// reweighted least-squares", Commun. Stat. Theory Methods 6(9)), for a problem whose
/// measured values cannot be edited (a socket row's measurement is its joint readings).
/// Residual `i` and row `i` of the Jacobian are multiplied by `scale[i]`: `√w` of a sample
/// bounded at corner `c` with residual norm `|e|` in the fit before ([`Bound::weight`]),
/// whose pull on the fit is then `w·|e| = c`, the Huber loss's at the corner, while its
/// Jacobian row no longer counts as a full observation: a glitch in a row's joint readings
/// neither anchors the fit at the reading nor identifies a parameter the other rows do not.
/// Evaluated dense (no row blocks).
pub(crate) struct Weighted<'a, P: Problem> {
    /// The problem.
    pub inner: &'a P,
    /// Per residual, the factor on it and on its Jacobian row (length `inner.n_residuals()`).
    pub scale: &'a [f64],
}

impl<P: Problem> Weighted<'_, P> {
    fn scale_residuals(&self, mut out: ColMut<'_, f64>) {
        for (i, s) in self.scale.iter().enumerate() {
            out[i] *= s;
        }
    }

    fn scale_rows(&self, mut jac: MatMut<'_, f64>) {
        for (i, &s) in self.scale.iter().enumerate() {
            if s != 1.0 {
                for j in 0..jac.ncols() {
                    jac[(i, j)] *= s;
                }
            }
        }
    }
}

impl<P: Problem> Problem for Weighted<'_, P> {
    fn layout(&self) -> &ParamLayout {
        self.inner.layout()
    }

    fn n_residuals(&self) -> usize {
        self.inner.n_residuals()
    }

    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        self.inner.residuals(x, out.as_mut())?;
        self.scale_residuals(out);
        Ok(())
    }

    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.inner.jacobian(x, jac.as_mut())?;
        self.scale_rows(jac);
        Ok(())
    }

    fn residuals_and_jacobian(
        &self,
        x: ColRef<'_, f64>,
        mut out: ColMut<'_, f64>,
        mut jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.inner
            .residuals_and_jacobian(x, out.as_mut(), jac.as_mut())?;
        self.scale_residuals(out);
        self.scale_rows(jac);
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
        // 50 is beyond twice the corner: left out.
        assert!(bounds[0].rejected());
        assert_eq!(bounds[0].weight(), 0.0);
        let near = Bound {
            norm: 1.5 * bounds[0].corner,
            ..bounds[0]
        };
        assert!((near.weight() - 1.0 / 1.5).abs() < 1e-12);
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
