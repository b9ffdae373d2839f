//! Observability indices O1–O5 of a (scaled) identification Jacobian: how well a set of
//! measurements determines the parameters, as one number each.
//!
//! All five are functions of the singular values `σ_1 ≥ … ≥ σ_n` of the `m × n` Jacobian `J`
//! (rows = residuals, each already divided by its noise standard deviation; columns = the
//! parameters, scaled by [`scale_by_priors`] so that a unit step of every column is a plausible
//! deviation). Larger is better for every index. Survey and comparison: Y. Sun,
//! J. M. Hollerbach, "Observability index selection for robot calibration", *IEEE ICRA* 2008,
//! pp. 831–836; A. Joubair, I. A. Bonev, "Comparison of the efficiency of five observability
//! indices for robot calibration", *Mechanism and Machine Theory* 70, 2013.
//!
//! Why scaling matters: the singular values of an unscaled Jacobian mix m/m and m/rad columns,
//! so the indices would change with the choice of units. Dividing each residual by its σ and
//! multiplying each column by its prior makes `σ_i` the factor by which the data shrink a
//! prior-sized uncertainty along singular direction `i` (`σ_i > 1`: the data know more than the
//! prior).

use faer::{Mat, MatRef};

use crate::problem::ParamLayout;
use crate::rank::RankConfigBase;

/// The five observability indices of one Jacobian, and its singular values.
///
/// Built by [`observability`]. Every index is dimensionless when the Jacobian is scaled as in
/// [`scale_by_priors`]; larger is better for all five.
#[derive(Clone, Debug, PartialEq)]
pub struct Observability {
    /// Singular values `σ_1 ≥ … ≥ σ_n` of `J` (length `min(m, n)`).
    pub singular_values: Vec<f64>,
    /// Number of poses `L` used to normalise [`Observability::o1`].
    pub n_poses: usize,
    /// O1, Borm & Menq: `(σ_1·σ_2·…·σ_n)^(1/n) / √L`, the geometric mean of the singular values
    /// per pose (J.-H. Borm, C.-H. Menq, "Determination of optimal measurement configurations
    /// for robot calibration based on observability measure", *Int. J. Robotics Research*
    /// 10(1), 1991). Maximising it for a fixed `L` is D-optimal design (`det JᵀJ = Π σ_i²`).
    /// 0 when `m < n` or `J` is rank deficient.
    pub o1: f64,
    /// O2, Driels & Pathre: the inverse condition number `σ_n / σ_1 = 1/κ(J)` in `[0, 1]`
    /// (M. R. Driels, U. S. Pathre, "Significance of observation strategy on the design of robot
    /// calibration experiments", *J. Robotic Systems* 7(2), 1990, who minimise `κ`; inverted
    /// here so that larger is better).
    pub o2: f64,
    /// O3, Nahvi, Hollerbach & Hayward: the minimum singular value `σ_n` (A. Nahvi,
    /// J. M. Hollerbach, V. Hayward, "Calibration of a parallel robot using multiple kinematic
    /// closed loops", *IEEE ICRA* 1994): the worst-determined direction.
    pub o3: f64,
    /// O4, Nahvi & Hollerbach's noise amplification index `σ_n² / σ_1 = σ_n / κ` (A. Nahvi,
    /// J. M. Hollerbach, "The noise amplification index for optimal pose selection in robot
    /// calibration", *IEEE ICRA* 1996).
    pub o4: f64,
    /// O5, Sun & Hollerbach: `1 / (1/σ_1 + … + 1/σ_n)`, related to A-optimality (Sun &
    /// Hollerbach 2008, above). 0 when a singular value is 0.
    pub o5: f64,
}

impl Observability {
    /// Condition number `κ = σ_1 / σ_n` (`∞` when `σ_n = 0`): Driels & Pathre's original form
    /// of O2; Schröer et al. ask for `κ < 100` (see Nahvi & Hollerbach 1996).
    pub fn condition_number(&self) -> f64 {
        if self.o2 > 0.0 {
            1.0 / self.o2
        } else {
            f64::INFINITY
        }
    }
}

/// The indices O1–O5 ([`Observability`]) from singular values `sv` (any order, each `≥ 0`),
/// for a Jacobian with `n_params` columns built from `n_poses` poses.
///
/// When fewer singular values than parameters are given (fewer residuals than parameters),
/// the missing ones are 0, so O1–O5 are 0 except O2's `σ_n/σ_1` which is 0 too.
///
/// # Panics
/// If a singular value is negative or not finite, or `n_poses` is 0 (misuse).
#[track_caller]
pub fn observability_from_singular_values(
    sv: &[f64],
    n_params: usize,
    n_poses: usize,
) -> Observability {
    assert!(
        sv.iter().all(|s| s.is_finite() && *s >= 0.0),
        "singular values must be finite and >= 0"
    );
    assert!(n_poses > 0, "n_poses must be positive");
    let mut s = sv.to_vec();
    s.sort_by(|a, b| b.total_cmp(a));
    s.resize(n_params.max(s.len()), 0.0);
    s.truncate(n_params.max(1).min(s.len()));
    let n = s.len();
    let (max, min) = (
        s.first().copied().unwrap_or(0.0),
        s.last().copied().unwrap_or(0.0),
    );
    let o1 = if min > 0.0 {
        (s.iter().map(|v| v.ln()).sum::<f64>() / n as f64).exp() / (n_poses as f64).sqrt()
    } else {
        0.0
    };
    let o2 = if max > 0.0 { min / max } else { 0.0 };
    let o4 = if max > 0.0 { min * min / max } else { 0.0 };
    let o5 = if min > 0.0 {
        1.0 / s.iter().map(|v| 1.0 / v).sum::<f64>()
    } else {
        0.0
    };
    Observability {
        singular_values: s,
        n_poses,
        o1,
        o2,
        o3: min,
        o4,
        o5,
    }
}

/// Observability indices O1–O5 of the `m × n` Jacobian `jac` built from `n_poses` poses.
///
/// `jac` should already be scaled: residuals divided by their noise σ (the `Problem`
/// convention) and columns multiplied by their priors ([`scale_by_priors`]). The singular
/// values come from faer's SVD (Golub–Van Loan §8.6).
///
/// # Errors
/// Returns `None` if the SVD does not converge (not seen for finite input).
///
/// # Panics
/// If `jac` has a non-finite entry or `n_poses` is 0 (misuse).
#[track_caller]
pub fn observability(jac: MatRef<'_, f64>, n_poses: usize) -> Option<Observability> {
    assert!(jac.is_all_finite(), "jacobian must be finite");
    let sv = if jac.nrows() == 0 || jac.ncols() == 0 {
        Vec::new()
    } else {
        jac.singular_values().ok()?
    };
    Some(observability_from_singular_values(
        &sv,
        jac.ncols(),
        n_poses,
    ))
}

/// The columns `cols` of `jac` (`m × layout.len()`), each multiplied by the prior of its unit
/// (`prior_m`, `prior_rad`, `prior_dimensionless`, `prior_rad_per_n_m` or `prior_rad_per_m`
/// of `priors`): an `m × cols.len()` matrix whose
/// unit column step is a plausible parameter deviation.
///
/// Source of the scaling: J. M. Hollerbach, C. W. Wampler, "The calibration index and taxonomy
/// for robot kinematic calibration methods", *Int. J. Robotics Research* 15(6), 1996, §4 (scale
/// each parameter by its expected variation so that the singular values compare like with
/// like).
///
/// # Panics
/// If `jac.ncols() != layout.len()` or a column index is out of range (misuse).
#[track_caller]
pub fn scale_by_priors(
    jac: MatRef<'_, f64>,
    layout: &ParamLayout,
    cols: &[usize],
    priors: &RankConfigBase,
) -> Mat<f64> {
    assert_eq!(jac.ncols(), layout.len(), "jacobian columns vs layout");
    let cfg = priors.with_sigma(1.0);
    let scale: Vec<f64> = cols
        .iter()
        .map(|&j| cfg.prior_scale(layout.spec(j).unit))
        .collect();
    Mat::from_fn(jac.nrows(), cols.len(), |i, k| jac[(i, cols[k])] * scale[k])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::{ParamSpec, Role, Unit};

    /// `U·diag(s)·Vᵀ` with orthogonal `U` (m × n, Householder of a fixed vector) and `V`.
    fn with_singular_values(m: usize, s: &[f64]) -> Mat<f64> {
        let n = s.len();
        let householder = |k: usize| {
            let v: Vec<f64> = (0..k).map(|i| 1.0 + (i as f64 * 0.7).sin()).collect();
            let vtv: f64 = v.iter().map(|a| a * a).sum();
            Mat::from_fn(k, k, |i, j| {
                f64::from(u8::from(i == j)) - 2.0 * v[i] * v[j] / vtv
            })
        };
        let (u, v) = (householder(m), householder(n));
        let d = Mat::from_fn(m, n, |i, j| if i == j { s[i] } else { 0.0 });
        &u * &d * v.transpose()
    }

    #[test]
    fn indices_of_known_singular_values() {
        // σ = (4, 2, 1) on 5 rows from L = 4 poses.
        let jac = with_singular_values(5, &[2.0, 4.0, 1.0]);
        let o = observability(jac.as_ref(), 4).expect("svd");
        for (got, want) in o.singular_values.iter().zip([4.0, 2.0, 1.0]) {
            assert!((got - want).abs() < 1e-13, "{:?}", o.singular_values);
        }
        assert!(
            (o.o1 - 8.0_f64.powf(1.0 / 3.0) / 2.0).abs() < 1e-13,
            "{}",
            o.o1
        );
        assert!((o.o2 - 0.25).abs() < 1e-14);
        assert!((o.o3 - 1.0).abs() < 1e-13);
        assert!((o.o4 - 0.25).abs() < 1e-13);
        assert!((o.o5 - 1.0 / (0.25 + 0.5 + 1.0)).abs() < 1e-13);
        assert!((o.condition_number() - 4.0).abs() < 1e-12);
    }

    #[test]
    fn rank_deficient_and_short_jacobians_score_zero() {
        let jac = with_singular_values(4, &[3.0, 0.0, 1.0]);
        let o = observability(jac.as_ref(), 2).expect("svd");
        assert!(o.o3 < 1e-14 && o.o2 < 1e-14 && o.o4 < 1e-14, "{o:?}");
        // 2 residuals for 3 parameters: the third singular value is 0.
        let short = Mat::from_fn(2, 3, |i, j| if i == j { 1.0 } else { 0.0 });
        let o = observability(short.as_ref(), 2).expect("svd");
        assert_eq!(o.singular_values.len(), 3);
        assert_eq!((o.o1, o.o3, o.o5), (0.0, 0.0, 0.0));
        assert_eq!(o.condition_number(), f64::INFINITY);
    }

    #[test]
    fn scaling_multiplies_each_column_by_its_prior() {
        let layout = ParamLayout::new(vec![
            ParamSpec {
                name: "a".into(),
                unit: Unit::Meter,
                role: Role::Model,
            },
            ParamSpec {
                name: "t".into(),
                unit: Unit::Radian,
                role: Role::Model,
            },
            ParamSpec {
                name: "k".into(),
                unit: Unit::Dimensionless,
                role: Role::Model,
            },
        ]);
        let jac = Mat::from_fn(2, 3, |i, j| (i + 1) as f64 * (j + 1) as f64);
        let priors = RankConfigBase {
            prior_m: 0.5,
            prior_rad: 0.25,
            ..RankConfigBase::default()
        };
        let s = scale_by_priors(jac.as_ref(), &layout, &[2, 0], &priors);
        assert_eq!((s.nrows(), s.ncols()), (2, 2));
        assert_eq!(s[(1, 0)], 6.0 * 1.0);
        assert_eq!(s[(1, 1)], 2.0 * 0.5);
    }
}
