//! The first stage: the log checked (and sampled when long), the baseline fitted (the
//! transmissions from the external encoders when it is `transmissions`, then the kinematic
//! deviations), the floor decided, and the held-out gap above it.

use std::borrow::Cow;

use hapcal_calibrate::model::ModelName;
use hapcal_identify::{IdentifyConfig, identify};
use hapcal_io::{Device, LogRow};
use hapcal_problems::{CapstanProblem, PolynomialProblem};
use hapcal_transmission::Capstan;
use nalgebra::DMatrix;

use super::DiagnoseConfig;
use super::cv::Base;
use crate::Error;
use crate::model::{
    Data, Linear, POLY_DEGREE, RANK_TOL, Setup, State, Term, Trans, ext_available, log_data,
};
use crate::solve::refine;
use crate::stats::{chi2_sf, largest_column_norm, pivoted_basis, pivoted_basis_beside};

/// How the floor is found with the reading quantisation (the default).
const FLOOR_QUANTISED: &str = "spec: sigma_m = 2*pi*R_d*sigma_e, sigma_e = 2*pi/counts/3 (paper noise model), plus joint-reading quantisation rho^2/12 through dd/dq; held-out floor sigma^2*(1+h)";

/// How the floor is found once the residuals showed the quantisation is not in the data.
const FLOOR_UNQUANTISED: &str = "spec without quantisation: sigma_m = 2*pi*R_d*sigma_e, sigma_e = 2*pi/counts/3 (paper noise model); the residuals were significantly below the floor with reading quantisation, so the readings are not the quantisation-limited measurement here; held-out floor sigma^2*(1+h)";

/// The baseline stage's output: what the later stages start from and do not change.
pub(super) struct Baseline {
    /// The model of the (sampled) log, with the floor decided.
    pub(super) setup: Setup,
    pub(super) data: Data,
    pub(super) n_joints: usize,
    /// The baseline fitted: the one asked for, or geometric when the log lacks the external
    /// encoders' readings.
    pub(super) model: ModelName,
    /// How the floor was estimated.
    pub(super) floor_method: String,
    /// Identifiable baseline parameters.
    pub(super) n_params: usize,
    pub(super) gap: Gap,
    /// Notes about the log (sampling, the baseline's fallback).
    pub(super) notes: Vec<String>,
}

impl Baseline {
    /// Samples in the (sampled) log.
    pub(super) fn n(&self) -> usize {
        self.data.n_rows()
    }
}

/// The baseline's held-out gap above the floor.
pub(super) struct Gap {
    /// The in-sample weighted excess `RSS − dof`.
    pub(super) excess0: f64,
    /// Cross-validated mean squared distance error, m².
    pub(super) mse0: f64,
    /// Its floor, m².
    pub(super) floor0: f64,
    /// `mse0 − floor0`, m².
    pub(super) gap2: f64,
    /// `P(χ² > Σ e²/var)` of the held-out residuals.
    pub(super) p: f64,
    pub(super) significant: bool,
}

/// A fit the rounds build on: the state and the baseline at its linearisation.
pub(super) struct Fit {
    pub(super) state: State,
    pub(super) base: Base,
}

/// New terms beside a fit's baseline ([`Fit::beside`]): the linearisation, the terms'
/// columns, the basis of their part outside the baseline's span and each column's place in it.
type Beside = (Linear, DMatrix<f64>, DMatrix<f64>, Vec<Option<f64>>);

impl Fit {
    /// `terms`, added at 0 to this fit's state and linearised by `setup`, beside the
    /// baseline: the linearisation (the baseline's columns first), the terms' columns (one
    /// per term), and [`pivoted_basis_beside`] of those against the baseline at relative
    /// tolerance `rel_tol` with the baseline's largest column the reference (the basis of
    /// their part outside the baseline's span, and each column's place in it).
    ///
    /// # Errors
    /// A failed linearisation.
    pub(super) fn beside(
        &self,
        setup: &Setup,
        terms: Vec<Term>,
        rel_tol: f64,
    ) -> Result<Beside, hapcal_problems::Error> {
        let base = &self.base;
        let k = terms.len();
        let mut s = self.state.clone();
        s.terms.extend(terms.into_iter().map(|t| (t, 0.0)));
        let lin = setup.linearise(&s)?;
        let cols = lin.j.columns(base.lin.j.ncols(), k).into_owned();
        let reference = largest_column_norm(&base.lin.j);
        let (basis, picked) = pivoted_basis_beside(&cols, &base.q, rel_tol, reference);
        Ok((lin, cols, basis, picked))
    }
}

/// The stage on `rows` of `device`: the context, and the baseline's fit.
///
/// # Errors
/// [`Error::Data`] for a log with fewer than 20 rows, rows that do not fit the device, or
/// fewer distinct configurations than parameters; [`Error::Baseline`] if the device has no
/// chain or the baseline cannot be fitted.
pub(super) fn baseline(
    device: &Device,
    rows: &[LogRow],
    cfg: &DiagnoseConfig,
) -> Result<(Baseline, Fit), Error> {
    let chain = device.chain().map_err(|e| Error::Baseline {
        message: e.to_string(),
    })?;
    let n_joints = chain.n_joints();
    check_rows(rows, n_joints)?;
    let mut notes = Vec::new();
    let rows = sampled(rows, cfg.max_rows, &mut notes);
    let data = log_data(&rows)?;
    let n = data.n_rows();
    let mut setup = Setup::new(device, chain, data.clone())?;
    let (model, trans) = transmissions(device, &data, &rows, &mut setup, cfg.baseline, &mut notes)?;
    let state0 = setup.initial_state(trans);
    let (state, lin) = refine(&setup, state0, 8).map_err(baseline_error)?;
    let n_base_cols = lin.j.ncols();
    let base = Base::new(lin, n_base_cols, cfg.folds, n);
    let (fit, floor_method) = floor(&mut setup, Fit { state, base }, cfg.folds, n)?;
    let n_params = fit.base.cols.len();
    check_distinct(&rows, n_params)?;
    let gap = gap(&fit.base, n, cfg.alpha);
    let b = Baseline {
        setup,
        data,
        n_joints,
        model,
        floor_method,
        n_params,
        gap,
        notes,
    };
    Ok((b, fit))
}

/// At least 20 rows, each with a reading per joint and a finite distance.
fn check_rows(rows: &[LogRow], n_joints: usize) -> Result<(), Error> {
    if rows.len() < 20 {
        return Err(Error::Data {
            message: format!("{} rows; the diagnosis needs at least 20", rows.len()),
        });
    }
    if let Some(r) = rows
        .iter()
        .find(|r| r.q.len() != n_joints || !r.distance_m.is_finite())
    {
        return Err(Error::Data {
            message: format!(
                "line {}: {} joint readings for a {n_joints}-joint device, distance {}",
                r.line,
                r.q.len(),
                r.distance_m
            ),
        });
    }
    Ok(())
}

/// The rows diagnosed: every `s`-th of a log longer than `max_rows`, which a note says.
fn sampled<'r>(rows: &'r [LogRow], max_rows: usize, notes: &mut Vec<String>) -> Cow<'r, [LogRow]> {
    match hapcal_calibrate::fit::ladder_sample(&[rows.len()], max_rows) {
        Some(sample) => {
            notes.push(format!(
                "the log's {} rows are diagnosed on {} of them, one row in {} from the first",
                rows.len(),
                sample.rows.len(),
                sample.stride
            ));
            Cow::Owned(sample.rows.iter().map(|&i| rows[i].clone()).collect())
        }
        None => Cow::Borrowed(rows),
    }
}

/// The baseline fitted (`asked`, or geometric when the log lacks the external encoders'
/// readings, which a note says) and its transmissions: fitted from the external encoders for
/// `transmissions`, none for `geometric`.
fn transmissions(
    device: &Device,
    data: &Data,
    rows: &[LogRow],
    setup: &mut Setup,
    asked: ModelName,
    notes: &mut Vec<String>,
) -> Result<(ModelName, Vec<Trans>), Error> {
    let trans_joints: Vec<usize> = device.capstans.iter().map(|c| c.joint - 1).collect();
    let mut model = asked;
    if model == ModelName::Transmissions
        && !trans_joints.is_empty()
        && !ext_available(rows, &trans_joints)
    {
        notes.push("the log lacks external-encoder readings for the transmissions: geometric baseline used".to_owned());
        model = ModelName::Geometric;
    }
    let trans = if model == ModelName::Transmissions {
        setup.set_ext_joints(trans_joints)?;
        fit_transmissions(device, data, setup.sigma_e_rad())?
    } else {
        Vec::new()
    };
    Ok((model, trans))
}

/// The floor: with quantisation unless the data are significantly quieter than that, in
/// which case `setup` drops it and the fit is refined without it.
fn floor(setup: &mut Setup, fit: Fit, folds: usize, n: usize) -> Result<(Fit, String), Error> {
    let lower = 1.0 - chi2_sf(fit.base.rss, fit.base.dof());
    if lower < 1e-3 {
        let n_base_cols = fit.base.lin.j.ncols();
        setup.set_quantisation(false);
        let (state, lin) = refine(setup, fit.state, 2).map_err(baseline_error)?;
        let base = Base::new(lin, n_base_cols, folds, n);
        return Ok((Fit { state, base }, FLOOR_UNQUANTISED.to_owned()));
    }
    Ok((fit, FLOOR_QUANTISED.to_owned()))
}

/// Copied rows add residuals but no information: the baseline needs a configuration per
/// parameter and one more for σ, or its held-out residual is a confident report of nothing.
fn check_distinct(rows: &[LogRow], n_params: usize) -> Result<(), Error> {
    let n_distinct = hapcal_calibrate::haptic::distinct_configurations(rows, None);
    if n_distinct <= n_params {
        return Err(Error::Data {
            message: format!(
                "the log holds {n_distinct} distinct joint configurations (in {} rows) for the \
                 baseline's {n_params} identifiable parameters: at least {} are needed; repeated \
                 rows add no information, measure more distinct poses",
                rows.len(),
                n_params + 1
            ),
        });
    }
    Ok(())
}

/// The held-out gap of `base` above its floor, significant at `alpha`.
fn gap(base: &Base, n: usize, alpha: f64) -> Gap {
    let mse0 = base.cv.mse();
    let floor0 = base.cv.floor();
    let p = chi2_sf(base.cv.chi2(), n as f64);
    Gap {
        excess0: base.excess(),
        mse0,
        floor0,
        gap2: mse0 - floor0,
        p,
        significant: p < alpha,
    }
}

/// Step 1 of the paper (Fig. 6): each transmission from its external encoder.
pub(super) fn fit_transmissions(
    device: &Device,
    data: &Data,
    sigma_e: f64,
) -> Result<Vec<Trans>, Error> {
    let mut cfg: IdentifyConfig = CapstanProblem::identify_config();
    cfg.rank.prior_m = 1e-3;
    cfg.rank.prior_dimensionless = 0.1;
    let mut out = Vec::new();
    for c in &device.capstans {
        let j = c.joint - 1;
        let theta: Vec<f64> = data
            .q()
            .iter()
            .map(|q| q.get(j).copied().unwrap_or(0.0))
            .collect();
        let ext: Vec<f64> = data
            .ext()
            .iter()
            .map(|e| e.get(j).copied().flatten().unwrap_or(0.0))
            .collect();
        let fail = |message: String| Error::Baseline {
            message: format!("joint {}: {message}", c.joint),
        };
        if device.parallelogram.is_some() && c.joint == hapcal_sim::PARALLELOGRAM_JOINT {
            let (lo, hi) = device.joint_limits().get(j).copied().unwrap_or((-1.0, 1.0));
            let p = PolynomialProblem::new(c.joint, POLY_DEGREE, lo, hi, theta, ext, sigma_e)
                .map_err(|e| fail(e.to_string()))?;
            let id = identify(&p, p.initial_guess(), &cfg).map_err(|e| fail(e.to_string()))?;
            out.push(Trans::Polynomial {
                joint: j,
                poly: p.polynomial(id.fit.x.as_ref()),
            });
        } else {
            let capstan =
                Capstan::try_new(c.ratio, c.drum_distance_m).map_err(|e| fail(e.to_string()))?;
            let p = CapstanProblem::new(capstan, c.joint, theta, ext, sigma_e)
                .map_err(|e| fail(e.to_string()))?;
            let id = identify(&p, p.initial_guess(), &cfg).map_err(|e| fail(e.to_string()))?;
            out.push(Trans::Capstan {
                joint: j,
                capstan,
                params: CapstanProblem::params(id.fit.x.as_ref()),
            });
        }
    }
    Ok(out)
}

/// A model error of the baseline's fit as [`Error::Baseline`].
pub(super) fn baseline_error(e: hapcal_problems::Error) -> Error {
    Error::Baseline {
        message: e.to_string(),
    }
}

/// The baseline's in-sample distance residuals (measured − model, m, one per row of
/// `rows`) after fitting `cfg.baseline` (with the same fallbacks as [`super::diagnose`]). The
/// blind test sizes effects with it: the difference between the residuals of a log with and
/// without an effect (same seed, same noise) is the part of the effect the baseline cannot
/// absorb, `P⊥·effect` (docs/diagnosis.md §5).
///
/// # Errors
/// As [`super::diagnose`].
pub fn baseline_residuals_m(
    device: &Device,
    rows: &[LogRow],
    cfg: &DiagnoseConfig,
) -> Result<Vec<f64>, Error> {
    let chain = device.chain().map_err(|e| Error::Baseline {
        message: e.to_string(),
    })?;
    if rows.len() < 20 || rows.iter().any(|r| r.q.len() != chain.n_joints()) {
        return Err(Error::Data {
            message: "the log does not fit the device or has fewer than 20 rows".to_owned(),
        });
    }
    let data = log_data(rows)?;
    let mut setup = Setup::new(device, chain, data.clone())?;
    let trans_joints: Vec<usize> = device.capstans.iter().map(|c| c.joint - 1).collect();
    let full = cfg.baseline == ModelName::Transmissions
        && !trans_joints.is_empty()
        && ext_available(rows, &trans_joints);
    let trans = if full {
        setup.set_ext_joints(trans_joints)?;
        fit_transmissions(device, &data, setup.sigma_e_rad())?
    } else {
        Vec::new()
    };
    let state0 = setup.initial_state(trans);
    let (_, lin) = refine(&setup, state0, 8).map_err(baseline_error)?;
    let (q, _) = pivoted_basis(&lin.j, &DMatrix::zeros(lin.j.nrows(), 0), RANK_TOL);
    let r_perp = &lin.r - &q * (q.transpose() * &lin.r);
    Ok((0..data.n_rows())
        .map(|i| r_perp[i] * lin.sigma[i])
        .collect())
}
