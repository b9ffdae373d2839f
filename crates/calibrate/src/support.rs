//! What the data support: observability indices of the calibration and plain-language
//! warnings about parameters the data cannot determine, for `hapcal calibrate`.

use faer::Mat;
use hapcal_identify::{
    Identified, Problem, PruneReason, RankConfigBase, observability, scale_by_priors,
};
use serde::Serialize;

/// Observability indices O1–O5 of the scaled Jacobian at the estimate (see
/// [`hapcal_identify::Observability`] for formulas and sources).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ObservabilityReport {
    /// O1 (Borm & Menq): geometric mean of the singular values per √pose.
    pub o1: f64,
    /// O2 (Driels & Pathre): inverse condition number σ_min/σ_max.
    pub o2: f64,
    /// O3 (Nahvi et al.): minimum singular value.
    pub o3: f64,
    /// O4 (Nahvi & Hollerbach): noise amplification index σ_min²/σ_max.
    pub o4: f64,
    /// O5 (Sun & Hollerbach): 1/Σ(1/σ_i).
    pub o5: f64,
    /// Condition number σ_max/σ_min.
    pub condition_number: f64,
    /// Kept parameters (columns).
    pub n_params: usize,
    /// Configurations (poses).
    pub n_poses: usize,
}

/// Indices of the kept parameters of `identified`: the Jacobian of `problem` at the estimate,
/// residuals divided by the noise σ, columns multiplied by their priors (so a singular value
/// above 1 means the data know that direction better than the prior). `None` if nothing is kept,
/// the Jacobian cannot be evaluated, or the SVD fails.
pub fn observability_report(
    problem: &impl Problem,
    identified: &Identified,
    priors: &RankConfigBase,
    n_poses: usize,
) -> Option<ObservabilityReport> {
    let kept = &identified.identifiability.kept;
    if kept.is_empty() || n_poses == 0 || identified.sigma.is_nan() || identified.sigma <= 0.0 {
        return None;
    }
    let layout = problem.layout();
    let mut jac = Mat::<f64>::zeros(problem.n_residuals(), layout.len());
    problem
        .jacobian(identified.fit.x.as_ref(), jac.as_mut())
        .ok()?;
    if !jac.is_all_finite() {
        return None;
    }
    let scaled = scale_by_priors(jac.as_ref(), layout, kept, priors) / identified.sigma;
    let o = observability(scaled.as_ref(), n_poses)?;
    Some(ObservabilityReport {
        o1: o.o1,
        o2: o.o2,
        o3: o.o3,
        o4: o.o4,
        o5: o.o5,
        condition_number: o.condition_number(),
        n_params: kept.len(),
        n_poses,
    })
}

/// Plain-language warnings about what the data cannot support, for the parameters whose layout
/// index is below `n_model` (nuisance points are left out):
/// - the pruned parameters without effect or indistinguishable from kept ones, in one line (the
///   report's `pruned` table names each one's dependency), and each parameter pruned because
///   the noise hides it, with the standard deviation it would have;
/// - kept parameters whose standard deviation exceeds a quarter of their prior;
/// - kept pairs with |correlation| above `corr_threshold`;
/// - a condition number above 100 (Schröer's rule of thumb, see Nahvi & Hollerbach 1996).
pub fn warnings(
    identified: &Identified,
    priors: &RankConfigBase,
    n_model: usize,
    corr_threshold: f64,
    obs: Option<&ObservabilityReport>,
) -> Vec<String> {
    let layout = &identified.layout;
    let cfg = priors.with_sigma(identified.sigma);
    let mut out = Vec::new();
    // Redundant parameters (no effect, or the same effect as kept ones) are a property of the
    // model and the poses together; one line names them all, the `pruned` table gives each
    // one's dependency. Parameters the noise hides get a line each: more poses would help them.
    let mut redundant = Vec::new();
    for p in identified
        .identifiability
        .pruned
        .iter()
        .filter(|p| p.index < n_model)
    {
        let unit = layout.spec(p.index).unit.symbol();
        match &p.reason {
            PruneReason::NearZeroColumn | PruneReason::Dependent { .. } => {
                redundant.push(p.name.as_str());
            }
            PruneReason::Insensitive => out.push(format!(
                "the data cannot support {}: its effect is too small for the noise: it would be \
                 known only to ±{:.3e} {unit}, more than its plausible range of {:.3e} {unit}; \
                 it keeps its nominal value",
                p.name,
                p.std_if_kept,
                cfg.prior_scale(layout.spec(p.index).unit)
            )),
            PruneReason::AtBound => out.push(format!(
                "{} is held at zero: fitted free it fell below zero, within the noise, and no \
                 joint bends against its load; the other parameters were fitted with it at zero",
                p.name
            )),
            _ => out.push(format!(
                "the data cannot support {}: it is not determined; it keeps its nominal value",
                p.name
            )),
        }
    }
    if !redundant.is_empty() {
        out.insert(
            0,
            format!(
                "the data cannot support {} parameter(s) separately, because their effect on the \
                 measurements is none or (nearly) that of kept parameters (see `pruned` for \
                 each one's dependency); they keep their nominal values: {}",
                redundant.len(),
                redundant.join(", ")
            ),
        );
    }
    let stds = identified.covariance.std();
    for (&j, &std) in identified.covariance.free.iter().zip(&stds) {
        if j >= n_model {
            continue;
        }
        let prior = cfg.prior_scale(layout.spec(j).unit);
        if std > 0.25 * prior {
            out.push(format!(
                "{} is poorly determined: ±{std:.3e} {} is more than a quarter of its plausible \
                 range ({prior:.3e}); add poses that move it",
                layout.name(j),
                layout.spec(j).unit.symbol()
            ));
        }
    }
    for (a, b, c) in identified.covariance.correlated_pairs(corr_threshold) {
        if a < n_model && b < n_model {
            out.push(format!(
                "{} and {} are correlated ({c:+.3}): the data determine mainly their combination, \
                 each value alone is less certain than the table suggests",
                layout.name(a),
                layout.name(b)
            ));
        }
    }
    if let Some(o) = obs
        && o.condition_number > 100.0
    {
        out.push(format!(
            "the scaled identification Jacobian is ill-conditioned (condition number {:.0} > 100): \
             choose better spread poses, e.g. with `hapcal plan-poses`",
            o.condition_number
        ));
    }
    out
}
