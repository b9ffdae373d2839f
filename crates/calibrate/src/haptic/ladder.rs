//! The haptic ladder's rungs fitted on every training row, and their cross-validation by refits from the full fit.

use super::*;

/// A rung of the haptic ladder fitted on every training row: where its fold refits start
/// and over which parameters (the ones its identification kept).
// A few values built once per calibration: their sizes do not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum HapticRungFit {
    /// The kinematic deviations alone, on the raw joint readings ([`identify_kinematics`]
    /// without transmissions).
    Geometric(Identified),
    /// The paper's two steps: the transmissions ([`identify_transmissions`]), then the
    /// kinematic deviations on the corrected readings.
    Transmissions(TransmissionFit, Identified),
    /// The transmissions (when the logs have the ext columns), the kinematic deviations and
    /// the handle's compliances in one problem ([`identify_with_compliance`]), with the
    /// two steps' transmissions it started from (`None` without ext columns).
    Compliance(ComplianceFit, Option<TransmissionFit>),
}

impl HapticRungFit {
    /// The identification whose estimate is the rung's result (step 2's kinematic deviations
    /// for the transmissions, whose step 1 is judged by its own fits): what the plausibility
    /// check judges.
    pub fn identified(&self) -> &Identified {
        match self {
            HapticRungFit::Geometric(id) | HapticRungFit::Transmissions(_, id) => id,
            HapticRungFit::Compliance(fit, _) => &fit.identified,
        }
    }

    /// The rung's `--model` value.
    pub fn model(&self) -> crate::model::ModelName {
        use crate::model::ModelName as M;
        match self {
            HapticRungFit::Geometric(_) => M::Geometric,
            HapticRungFit::Transmissions(..) => M::Transmissions,
            HapticRungFit::Compliance(..) => M::Compliance,
        }
    }

    /// The rung refitted on `fit_rows` and its distance residuals (model − measured, m, one
    /// per row) on `held_rows`. The refit is Levenberg–Marquardt alone from this full-data
    /// estimate, over the parameters it kept, to a relative tolerance of
    /// `fit::FOLD_TOLERANCE` (10⁻⁶); the transmissions' refit is two-step (each capstan and
    /// the joint-4 polynomial from its external encoder, then the kinematics). The
    /// compliance's refit takes its transmissions from step 1 on the fold, as the
    /// transmissions rung does, and refits the kinematic deviations and the compliances on
    /// the cable distances: the comparison of the two rungs is then the compliance's alone.
    /// Fitted in one problem (as `--model compliance` delivers it) the transmissions gain what
    /// the joint identification gains over the two steps, which is no compliance: on one clean
    /// simulated log (no compliance, 300 rows) that gain alone beat the two steps by 2.9
    /// standard errors.
    ///
    /// # Errors
    /// Rows without the ext columns the rung needs, rows the model refuses, or a failed fit.
    pub fn refit_residuals_m<R: Borrow<LogRow> + Sync>(
        &self,
        r: &HapticDevice,
        fit_rows: &[R],
        held_rows: &[R],
    ) -> Result<Vec<f64>> {
        match self {
            HapticRungFit::Geometric(kin) => {
                let x = refit_kinematics(r, fit_rows, None, kin)?;
                Ok(kinematic_residuals_m(r, held_rows, &x, None))
            }
            HapticRungFit::Transmissions(t, kin) => {
                let t = refit_transmissions(r, fit_rows, t)?;
                let x = refit_kinematics(r, fit_rows, Some(&t), kin)?;
                Ok(kinematic_residuals_m(r, held_rows, &x, Some(&t)))
            }
            HapticRungFit::Compliance(fit, t) => {
                let mut start = fit.state.clone();
                if let Some(t) = t {
                    start.transmissions = log_transmissions(&refit_transmissions(r, fit_rows, t)?);
                }
                // The transmissions come first in the layout and are held.
                let n_trans: usize = (start.transmissions.iter())
                    .map(LogTransmission::n_params)
                    .sum();
                let free: Vec<usize> = (fit.identified.identifiability.kept.iter())
                    .copied()
                    .filter(|&i| i >= n_trans)
                    .collect();
                let model = log_model(r, fit_rows, Vec::new())?;
                let problem = DistanceLogProblem::new(model, &start)?;
                let refit = hapcal_identify::levenberg_marquardt(
                    &problem,
                    problem.x_of(&start),
                    &free,
                    &fold_lm(crate::fit::identify_config(None)),
                )
                .context("refitting the compliance model on a fold")?;
                state_distance_residuals_m(r, &problem.state(refit.x.as_ref()), held_rows)
            }
        }
    }
}

/// A fold refit's Levenberg–Marquardt settings: `cfg`'s, stopped at
/// `fit::FOLD_TOLERANCE` (10⁻⁶).
pub(super) fn fold_lm(cfg: IdentifyConfig) -> hapcal_identify::LmConfig {
    hapcal_identify::LmConfig {
        ftol: crate::fit::FOLD_TOLERANCE,
        xtol: crate::fit::FOLD_TOLERANCE,
        ..cfg.lm
    }
}

/// The kinematic deviations refitted on `rows` (readings corrected by `t`) from `warm`, over
/// its kept parameters.
pub(super) fn refit_kinematics<R: Borrow<LogRow>>(
    r: &HapticDevice,
    rows: &[R],
    t: Option<&TransmissionFit>,
    warm: &Identified,
) -> Result<Vec<f64>> {
    let problem = kinematics_problem(r, rows, t)?;
    let fit = hapcal_identify::levenberg_marquardt(
        &problem,
        warm.fit.x.clone(),
        &warm.identifiability.kept,
        &fold_lm(crate::fit::identify_config(None)),
    )
    .context("refitting the kinematic deviations on a fold")?;
    Ok(fit.x.iter().copied().collect())
}

/// The transmissions refitted on `rows` from `warm`, each capstan and the polynomial over its
/// kept parameters (the identifications' covariances stay `warm`'s).
pub(super) fn refit_transmissions<R: Borrow<LogRow>>(
    r: &HapticDevice,
    rows: &[R],
    warm: &TransmissionFit,
) -> Result<TransmissionFit> {
    let lm = fold_lm(transmission_config());
    let mut out = warm.clone();
    for c in &mut out.capstans {
        let problem = capstan_problem(r, rows, c.joint, c.capstan)?;
        let fit = hapcal_identify::levenberg_marquardt(
            &problem,
            c.identified.fit.x.clone(),
            &c.identified.identifiability.kept,
            &lm,
        )
        .with_context(|| format!("refitting capstan {} on a fold", c.joint))?;
        c.params = CapstanProblem::params(fit.x.as_ref());
    }
    let problem = polynomial_problem(r, rows)?;
    let fit = hapcal_identify::levenberg_marquardt(
        &problem,
        warm.poly_identified.fit.x.clone(),
        &warm.poly_identified.identifiability.kept,
        &lm,
    )
    .context("refitting the joint-4 polynomial on a fold")?;
    out.poly = problem.polynomial(fit.x.as_ref());
    Ok(out)
}

/// Distance residuals (model − measured, m) of `rows` on `r`'s chain at deviations `x`, the
/// readings corrected by `t` (raw when `None`); the rows shared among the cores.
pub(super) fn kinematic_residuals_m<R: Borrow<LogRow> + Sync>(
    r: &HapticDevice,
    rows: &[R],
    x: &[f64],
    t: Option<&TransmissionFit>,
) -> Vec<f64> {
    use rayon::prelude::*;
    (rows.par_iter())
        .map(|row| {
            let row: &LogRow = row.borrow();
            let q = t.map_or_else(|| row.q.clone(), |t| t.corrected(&row.q));
            r.chain.end_point(x, &q).coords.norm() - row.distance_m
        })
        .collect()
}

/// The rungs of the haptic ladder ([`crate::model::ladder`]) the logs and the device carry,
/// simplest first, with each one's level: geometric always, transmissions when the training
/// logs have the external-encoder columns (`has_ext`), compliance when the device file has a
/// handle mass (`has_handle_mass`).
pub fn haptic_rungs(
    has_ext: bool,
    has_handle_mass: bool,
) -> (Vec<crate::model::ModelName>, Vec<usize>) {
    use crate::model::{DataKind, ModelName as M, ladder};
    let mut rungs = Vec::new();
    let mut levels = Vec::new();
    for (l, level) in ladder(DataKind::HapticLogs, false).into_iter().enumerate() {
        for m in level {
            let carried = match m {
                M::Transmissions => has_ext,
                M::Compliance => has_handle_mass,
                _ => true,
            };
            if carried {
                rungs.push(m);
                levels.push(l);
            }
        }
    }
    (rungs, levels)
}

/// Held-out errors of each rung of `fits` by repeated blocked cross-validation of the
/// training logs (`lengths[i]` rows of log `i`, concatenated in `rows`): each log's rows cut
/// into `k` contiguous blocks in row order, [`crate::fit::CV_REPEATS`] times shifted, a row
/// that repeats an earlier row of its log ([`LogRow::repeat_key`]) held out with it
/// ([`crate::fit::folds_of_rows`]); each rung refitted on each fold's training rows
/// ([`HapticRungFit::refit_residuals_m`]) and its squared distance residual (m²) on the
/// held-out rows averaged over the repeats. One entry per rung, rows in `rows`' order, blocks
/// `log · k + fold` of the first repeat. Every row has the cable encoder's σ_m, so the squared
/// residual divided by σ_m² (the fit's weighted score) orders and tests the rungs the same.
///
/// # Errors
/// `lengths` not summing to `rows.len()`, or a failed refit.
pub fn cross_validate_rungs(
    r: &HapticDevice,
    rows: &[LogRow],
    lengths: &[usize],
    fits: &[HapticRungFit],
    k: usize,
) -> Result<Vec<crate::fit::HeldOut>> {
    use rayon::prelude::*;
    let n = rows.len();
    if lengths.iter().sum::<usize>() != n {
        bail!("cross-validation: the logs' lengths do not sum to the rows");
    }
    // A row that repeats an earlier row of its log is held out with it.
    let originals: Vec<Vec<usize>> = (lengths.iter())
        .scan(0, |start, &len| {
            let log = &rows[*start..*start + len];
            *start += len;
            Some(crate::fit::originals(log.iter().map(LogRow::repeat_key)))
        })
        .collect();
    let masks: Vec<Vec<bool>> = (crate::fit::blocked_folds(&originals, k).into_iter())
        .map(|fold| fold.into_iter().flatten().collect())
        .collect();
    let jobs: Vec<(usize, usize)> = (0..fits.len())
        .flat_map(|i| (0..masks.len()).map(move |f| (i, f)))
        .collect();
    let results: Vec<(usize, Vec<(usize, f64)>)> = (jobs.par_iter())
        .map(|&(i, f)| {
            let held = &masks[f];
            let held_idx: Vec<usize> = (0..n).filter(|&j| held[j]).collect();
            if held_idx.is_empty() {
                return Ok((i, Vec::new()));
            }
            // The fold's rows borrowed, never copied.
            let fit_rows: Vec<&LogRow> = (rows.iter().zip(held))
                .filter(|(_, h)| !**h)
                .map(|(row, _)| row)
                .collect();
            let held_rows: Vec<&LogRow> = held_idx.iter().map(|&j| &rows[j]).collect();
            let res = fits[i]
                .refit_residuals_m(r, &fit_rows, &held_rows)
                .with_context(|| format!("cross-validating the {} model", fits[i].model()))?;
            Ok((
                i,
                held_idx
                    .into_iter()
                    .zip(res)
                    .map(|(j, e)| (j, e * e))
                    .collect(),
            ))
        })
        .collect::<Result<_>>()?;
    let block = crate::fit::first_repeat_blocks(&originals, k);
    let mut held = vec![
        crate::fit::HeldOut {
            sq_errors: vec![0.0; n],
            block,
        };
        fits.len()
    ];
    for (i, errors) in results {
        for (j, e2) in errors {
            held[i].sq_errors[j] += e2 / crate::fit::CV_REPEATS as f64;
        }
    }
    Ok(held)
}

/// The record's values of the report's parameters (the same names, values, σ and units).
pub(super) fn report_values(parameters: &[crate::report::ParamReport]) -> Vec<CalibratedValue> {
    (parameters.iter())
        .map(|p| CalibratedValue {
            name: p.name.clone(),
            value: p.value,
            std: p.std,
            unit: p.unit.to_owned(),
        })
        .collect()
}
