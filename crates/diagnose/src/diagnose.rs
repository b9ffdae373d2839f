//! The diagnosis: baseline, gap against the floor, where, which, how far.

use hapcal_calibrate::model::ModelName;
use std::f64::consts::TAU;

use hapcal_identify::{IdentifyConfig, identify};
use hapcal_io::{Device, LogRow};
use hapcal_kinematics::Point3;
use hapcal_problems::{CapstanProblem, PolynomialProblem};
use hapcal_sim::EffectKind;
use hapcal_transmission::{Capstan, Chebyshev};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;

use hapcal_contract::Effect;

use crate::{Error, Verdict};

/// Smallest fraction of a candidate column's norm left after projecting out the baseline for
/// the column to count as visible (below: indistinguishable from the baseline).
const VISIBLE_TOL: f64 = 0.005;

/// Share of its round's held-out gap (what the effects accepted before it left, above the
/// floor) the last accepted effect must close, unless what it leaves is consistent with the
/// floor (or it closes [`SUFFICIENT_SHARE_IN_SAMPLE`] of the round's in-sample excess); below
/// it the effect is not named and the rule goes on with the one before it.
const SUFFICIENT_SHARE: f64 = 0.8;

/// The same on the in-sample weighted excess (an effect the baseline mostly absorbs is
/// estimated poorly on training folds, so its held-out share understates it).
const SUFFICIENT_SHARE_IN_SAMPLE: f64 = 0.9;
use crate::model::{
    Data, Linear, POLY_DEGREE, RANK_TOL, Setup, State, Term, TermKind, Trans, ext_available,
    log_data,
};
use crate::solve::{lstsq, refine};
use crate::stats::{chi2_sf, f_sf, holm, largest_column_norm, pivoted_basis, pivoted_basis_beside};

/// The model a haptic device's log is diagnosed against, by the name `--baseline` takes: one
/// of the two models `hapcal calibrate` fits to such a log ([`ModelName`], the one
/// definition of a model):
///
/// - `transmissions`: the transmissions (paper eq. 1 on the capstans, the joint-4 polynomial)
///   from the external encoders, plus the kinematic deviations: the paper's full calibration
///   (Fig. 6); `full` is read as this;
/// - `geometric`: the kinematic deviations alone on the raw readings; the paper's capstan and
///   parallelogram models join the candidates (`capstan`, `parallelogram`); `kinematics` is
///   read as this.
///
/// # Errors
/// [`Error::Config`] for any other name, in the user's words.
pub fn baseline_model(name: &str) -> Result<ModelName, Error> {
    match name.trim().to_ascii_lowercase().as_str() {
        "full" => return Ok(ModelName::Transmissions),
        "kinematics" => return Ok(ModelName::Geometric),
        _ => {}
    }
    match ModelName::from_name(name) {
        Some(m @ (ModelName::Transmissions | ModelName::Geometric)) => Ok(m),
        Some(m) => Err(Error::Config {
            message: format!(
                "baseline must be transmissions or geometric (full and kinematics are the same): \
                 a haptic device's log is diagnosed against one of the two, not {m}"
            ),
        }),
        None => Err(Error::Config {
            message: format!(
                "baseline must be transmissions or geometric (full and kinematics are the same), \
                 got {name:?}"
            ),
        }),
    }
}

/// Settings of [`diagnose`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiagnoseConfig {
    /// The baseline model: transmissions or geometric ([`baseline_model`]).
    pub baseline: ModelName,
    /// Number of cross-validation folds (time-contiguous blocks of samples), ≥ 2.
    pub folds: usize,
    /// Family-wise significance level of the candidate tests (Holm–Bonferroni) and of the
    /// gap test.
    pub alpha: f64,
    /// Largest number of effects added greedily (rounds go on while the cross-validated
    /// error is significantly above the floor and a candidate passes).
    pub max_effects: usize,
    /// Smallest share of its round's gap a winner must close, 0–1: the cross-validated error
    /// left by the effects accepted before it, above the floor.
    pub min_gap_share: f64,
    /// Most rows diagnosed: a longer log is diagnosed on every `s`-th row from its first,
    /// the smallest stride that leaves at most this many (`hapcal_calibrate::fit::ladder_sample`),
    /// and the diagnosis's notes say so. The candidates' columns take about 57 kB a row (567 MB
    /// peak at 10,000 rows of the reference device, `hapcal diagnose`, release build), so
    /// 10,000 keeps a day's log within 1 GB.
    pub max_rows: usize,
}

impl Default for DiagnoseConfig {
    /// Transmissions baseline, 5 folds, α = 0.01, up to 3 effects, each winner closes ≥ 20 % of the
    /// gap left by the effects before it (so that two effects of similar size, or a small one
    /// after a large one, can be found one after the other);
    /// together the accepted effects must close ≥ 80 % of the gap or leave a residual
    /// consistent with the floor, else the verdict is `none` (docs/diagnosis.md §3 (d)).
    fn default() -> DiagnoseConfig {
        DiagnoseConfig {
            baseline: ModelName::Transmissions,
            folds: 5,
            alpha: 0.01,
            max_effects: 3,
            min_gap_share: 0.2,
            max_rows: 10_000,
        }
    }
}

/// One identified parameter with its standard deviation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamValue {
    /// `effect.key`, e.g. `backlash.j2`.
    pub name: String,
    /// Value, in `unit`.
    pub value: f64,
    /// Standard deviation, in `unit`.
    pub std: f64,
    /// SI unit.
    pub unit: String,
}

/// One candidate effect, tested against the current baseline.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Candidate {
    /// The effect (docs/design.md §6; `capstan`/`parallelogram` with the geometric baseline),
    /// serialised by its name.
    pub effect: Effect,
    /// Greedy round (1 = against the baseline; 2 = after the first winner was added).
    pub round: usize,
    /// Cross-validated distance RMS of the round's baseline, m.
    #[serde(rename = "cv_rms_before_m")]
    pub heldout_rms_before_m: f64,
    /// Cross-validated distance RMS with this candidate's parameters added, m.
    #[serde(rename = "cv_rms_after_m")]
    pub heldout_rms_after_m: f64,
    /// Share of the round's held-out gap the candidate closes, %:
    /// `(MSE_before − MSE_after)/(MSE_before − floor)`.
    pub gap_closed_pct: f64,
    /// Whether it passed every test (see `reason`).
    pub accepted: bool,
    /// Why it was accepted or rejected.
    pub reason: String,
    /// Its parameters fitted with the baseline on all samples, ± std (σ from the spec, or
    /// from the residuals when they are larger).
    pub parameters: Vec<ParamValue>,
    /// F-test p-value of the added parameters (visible parts only), Holm-adjusted.
    pub p_value: f64,
    /// Number of visible (not absorbed) parameters.
    pub n_visible: usize,
    /// Fraction of the candidate's signature (in norm) left after projecting out the
    /// baseline's columns, per parameter.
    pub visible_fraction: Vec<f64>,
    /// Baseline parameters that absorb the candidate's invisible parameters.
    pub absorbed_by: Vec<String>,
    /// `ΔRSS − k·ln N` (weighted, spec σ): the BIC gain; > 0 beats the penalty.
    pub bic_gain: f64,
}

/// One bin of the residual map.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Bin {
    /// The binned signal (`q3`, `motor_phase2`, `distance`, `cable_angle`, `direction5`,
    /// `time`, `drum_phase`).
    pub signal: String,
    /// Bin edges in the signal's unit (rad, m, s; direction −1 or +1).
    pub lo: f64,
    /// Upper edge.
    pub hi: f64,
    /// Samples in the bin.
    pub n: usize,
    /// Held-out residual RMS in the bin, m.
    pub rms_m: f64,
    /// Held-out residual mean in the bin, m.
    pub mean_m: f64,
    /// The floor's RMS in the bin, m.
    pub floor_rms_m: f64,
    /// `P(χ²_n > Σ e²/var)`: the chance of this RMS from noise alone.
    pub p_value: f64,
    /// Significantly above the floor (Bonferroni over all bins at `alpha`).
    pub flagged: bool,
}

/// How strongly the residual depends on one signal.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SignalTest {
    /// The signal.
    pub signal: String,
    /// Between-bin F-test p-value on the squared standardised residuals.
    pub p_value: f64,
    /// Significant (Bonferroni over signals at `alpha`).
    pub significant: bool,
}

/// How much of the gap a free joint-angle error (a degree-6 polynomial of one joint's
/// reading) would explain: which joint the residual lives on.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JointProbe {
    /// Joint, 1-based.
    pub joint: usize,
    /// Share of the gap (in-sample weighted excess) it explains, %.
    pub explained_pct: f64,
    /// F-test p-value.
    pub p_value: f64,
}

/// One accepted effect and how far it shrinks the residual.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Step {
    /// The effect, serialised by its name.
    pub effect: Effect,
    /// Cross-validated distance RMS before adding it, m.
    #[serde(rename = "cv_rms_before_m")]
    pub heldout_rms_before_m: f64,
    /// Cross-validated distance RMS after adding it (nonlinear refit), m.
    #[serde(rename = "cv_rms_after_m")]
    pub heldout_rms_after_m: f64,
    /// Share of the original gap closed by this step, %.
    pub gap_closed_pct: f64,
    /// Identified parameters ± std.
    pub parameters: Vec<ParamValue>,
    /// Candidates whose signature resembles this one's (cosine > 0.9).
    pub confusable_with: Vec<Effect>,
}

/// The diagnosis of one log (see [`diagnose`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Diagnosis {
    /// The baseline used: transmissions or geometric ([`baseline_model`]).
    pub baseline: ModelName,
    /// Samples in the log.
    pub n_samples: usize,
    /// Identifiable baseline parameters.
    pub n_params: usize,
    /// How the floor was estimated.
    pub floor_method: String,
    /// σ of the cable distance from the spec, m.
    pub sigma_m_m: f64,
    /// σ of the external encoders from the spec, rad.
    pub sigma_e_rad: f64,
    /// Floor of the held-out distance RMS, m: `sqrt(mean(σ_i²·(1 + h_i)))`.
    pub floor_rms_m: f64,
    /// Cross-validated distance RMS of the baseline, m.
    #[serde(rename = "cv_rms_m")]
    pub heldout_rms_m: f64,
    /// The gap `sqrt(max(0, MSE_cv − floor²))`, m.
    pub gap_rms_m: f64,
    /// The gap in units of the floor.
    pub gap_in_floors: f64,
    /// `P(χ² > Σ e²/var)` of the held-out residuals: the chance of this gap from noise.
    pub gap_p_value: f64,
    /// Whether the gap is significant at `alpha`.
    pub gap_significant: bool,
    /// The residual map of the baseline (held-out residuals).
    #[serde(rename = "where")]
    pub where_: Vec<Bin>,
    /// Per signal: does the residual depend on it?
    pub signals: Vec<SignalTest>,
    /// Per joint: a free joint-angle error's share of the gap.
    pub joints: Vec<JointProbe>,
    /// Every candidate of every round.
    pub candidates: Vec<Candidate>,
    /// Accepted effects in order.
    pub steps: Vec<Step>,
    /// Cross-validated distance RMS after all accepted effects, m.
    #[serde(rename = "cv_rms_final_m")]
    pub heldout_rms_final_m: f64,
    /// Share of the held-out gap closed by all accepted effects, %.
    pub gap_closed_pct: f64,
    /// Share of the in-sample excess `RSS − dof` (weighted) closed by all accepted effects, %.
    pub gap_closed_in_sample_pct: f64,
    /// The effects named (`none`, or their names joined by `+` in the report).
    pub verdict: Verdict,
    /// Signals along which the final residual still varies (leads when nothing fits).
    pub leads: Vec<String>,
    /// Things the user should know (baseline fallbacks, untestable candidates).
    pub notes: Vec<String>,
}

/// Cross-validated distance residuals.
struct Cv {
    /// Held-out residual per sample, m.
    e: Vec<f64>,
    /// Its variance under the floor, m².
    var: Vec<f64>,
    /// σ_i² per sample (spec), m².
    sigma2: Vec<f64>,
}

impl Cv {
    fn mse(&self) -> f64 {
        mean(self.e.iter().map(|e| e * e))
    }
    fn floor(&self) -> f64 {
        mean(self.var.iter().copied())
    }
    fn chi2(&self) -> f64 {
        self.e
            .iter()
            .zip(&self.var)
            .map(|(e, v)| e * e / v.max(1e-300))
            .sum()
    }
}

fn mean(it: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = it.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { s / n as f64 }
}

/// Held-out residuals of the linear model with columns `cols` of `lin.j` and extra `cand`
/// columns, folds of time-contiguous samples.
fn cross_validate(
    lin: &Linear,
    cols: &[usize],
    cand: Option<&DMatrix<f64>>,
    folds: usize,
    n: usize,
) -> Cv {
    let base = lin.j.select_columns(cols);
    let a = match cand {
        Some(c) if c.ncols() > 0 => {
            let mut a = DMatrix::zeros(base.nrows(), base.ncols() + c.ncols());
            a.columns_mut(0, base.ncols()).copy_from(&base);
            a.columns_mut(base.ncols(), c.ncols()).copy_from(c);
            a
        }
        _ => base,
    };
    let fold_of = |s: usize| s * folds / n.max(1);
    let mut e = vec![0.0; n];
    let mut var = vec![0.0; n];
    let mut sigma2 = vec![0.0; n];
    for f in 0..folds {
        let train: Vec<usize> = (0..a.nrows())
            .filter(|&r| fold_of(lin.sample[r]) != f)
            .collect();
        if train.is_empty() {
            continue;
        }
        let at = a.select_rows(&train);
        let bt = DVector::from_iterator(train.len(), train.iter().map(|&r| lin.r[r]));
        let (x, cov) = lstsq(&at, &bt);
        for i in (0..n).filter(|&i| fold_of(i) == f) {
            let row = a.row(i);
            let pred = (row * &x)[0];
            let v = (row * &cov * row.transpose())[0];
            let sd = lin.sigma[i];
            e[i] = (lin.r[i] - pred) * sd;
            var[i] = sd * sd * (1.0 + v);
            sigma2[i] = sd * sd;
        }
    }
    Cv { e, var, sigma2 }
}

/// The candidate terms of an effect, or why it cannot be tested on this log.
fn candidate_terms(
    effect: Effect,
    device: &Device,
    data: &Data,
    n_joints: usize,
) -> Result<Vec<Term>, String> {
    let capstan_of = |j: usize| device.capstans.iter().find(|c| c.joint == j + 1);
    let need_t = || {
        if data.t_s().is_some() {
            Ok(())
        } else {
            Err("not testable: the log has no t_s column".to_owned())
        }
    };
    let joint_term = |name: String, joint: usize, g: Vec<f64>| Term {
        name,
        unit: "rad",
        kind: TermKind::Joint { joint, g },
    };
    let col = |j: usize, f: &dyn Fn(f64) -> f64| -> Vec<f64> {
        data.q()
            .iter()
            .map(|q| f(q.get(j).copied().unwrap_or(0.0)))
            .collect()
    };
    let mut terms = Vec::new();
    match effect {
        Effect::CableAngle => {
            // Eyelet wrap `k·(γ − sin γ)`. (Adding powers of cos γ for other laws made the
            // mostly absorbed columns nearly collinear and the refit unstable.)
            terms.push(Term {
                name: format!("{effect}.k"),
                unit: "m",
                kind: TermKind::CableAngle { power: 0 },
            });
        }
        Effect::GravityCompliance => {
            terms.extend((0..n_joints).map(Term::handle_compliance));
        }
        Effect::Backlash => {
            need_t()?;
            for j in 0..n_joints {
                let dir = data.direction(j).unwrap_or_default();
                terms.push(joint_term(
                    format!("{effect}.j{}", j + 1),
                    j,
                    dir.iter().map(|d| -d).collect(),
                ));
            }
        }
        Effect::FirstHarmonic => {
            for j in (0..n_joints).filter(|&j| capstan_of(j).is_none()) {
                terms.push(joint_term(
                    format!("{effect}.j{}_sin", j + 1),
                    j,
                    col(j, &f64::sin),
                ));
                terms.push(joint_term(
                    format!("{effect}.j{}_cos", j + 1),
                    j,
                    col(j, &f64::cos),
                ));
            }
        }
        Effect::CapstanHarmonic => {
            for j in 0..n_joints {
                let Some(c) = capstan_of(j) else { continue };
                let r = c.ratio;
                // Second harmonic of the motor drum, 2·R·θ. (The output drum's, 2·θ, is so
                // smooth over a joint range that it fits any slow joint error: not tested.)
                terms.push(joint_term(
                    format!("{effect}.j{}_sin", j + 1),
                    j,
                    col(j, &|q| (2.0 * r * q).sin()),
                ));
                terms.push(joint_term(
                    format!("{effect}.j{}_cos", j + 1),
                    j,
                    col(j, &|q| (2.0 * r * q).cos()),
                ));
            }
        }
        Effect::ThermalDrift => {
            need_t()?;
            terms.push(Term {
                name: format!("{effect}.k"),
                unit: "1/s",
                kind: TermKind::ThermalDrift { scale: true },
            });
            terms.push(Term {
                name: format!("{effect}.rate"),
                unit: "m/s",
                kind: TermKind::ThermalDrift { scale: false },
            });
        }
        Effect::Latency => {
            need_t()?;
            terms.push(Term {
                name: format!("{effect}.tau"),
                unit: "s",
                kind: TermKind::Latency,
            });
        }
        Effect::CableOffset => terms.push(Term {
            name: format!("{effect}.c"),
            unit: "m",
            kind: TermKind::Distance {
                h: vec![1.0; data.n_rows()],
            },
        }),
        Effect::Capstans => {
            // Paper eq. 1 to first order in r/D: offset (= dtheta), ratio error, output- and
            // input-drum eccentricity harmonics.
            for j in 0..n_joints {
                let Some(c) = capstan_of(j) else { continue };
                if device.parallelogram.is_some() && j + 1 == hapcal_sim::PARALLELOGRAM_JOINT {
                    continue;
                }
                let r = c.ratio;
                let n = j + 1;
                terms.push(joint_term(
                    format!("{effect}.j{n}_ratio"),
                    j,
                    col(j, &|q| q),
                ));
                terms.push(joint_term(
                    format!("{effect}.j{n}_out_sin"),
                    j,
                    col(j, &f64::sin),
                ));
                terms.push(joint_term(
                    format!("{effect}.j{n}_out_cos"),
                    j,
                    col(j, &f64::cos),
                ));
                terms.push(joint_term(
                    format!("{effect}.j{n}_in_sin"),
                    j,
                    col(j, &|q| (r * q).sin()),
                ));
                terms.push(joint_term(
                    format!("{effect}.j{n}_in_cos"),
                    j,
                    col(j, &|q| (r * q).cos()),
                ));
            }
        }
        Effect::Parallelogram => {
            let j = hapcal_sim::PARALLELOGRAM_JOINT - 1;
            let (lo, hi) = device.joint_limits().get(j).copied().unwrap_or((-1.0, 1.0));
            let probe = Chebyshev::try_new(lo, hi, vec![0.0; POLY_DEGREE + 1])
                .map_err(|e| e.to_string())?;
            let basis: Vec<Vec<f64>> = data
                .q()
                .iter()
                .map(|q| probe.basis(q.get(j).copied().unwrap_or(0.0)))
                .collect();
            for k in 1..=POLY_DEGREE {
                terms.push(joint_term(
                    format!("{effect}.cheb{k}"),
                    j,
                    basis
                        .iter()
                        .map(|b| b.get(k).copied().unwrap_or(0.0))
                        .collect(),
                ));
            }
        }
        other => {
            return Err(format!(
                "not a candidate of the haptic device's library: {other}"
            ));
        }
    }
    if terms.is_empty() {
        return Err("not testable: the device has no joint it applies to".to_owned());
    }
    Ok(terms)
}

/// The baseline's identifiable columns and orthonormal basis at a linearisation.
struct Base {
    lin: Linear,
    cols: Vec<usize>,
    q: DMatrix<f64>,
    r_perp: DVector<f64>,
    rss: f64,
    cv: Cv,
}

impl Base {
    fn new(lin: Linear, n_cols_base: usize, folds: usize, n: usize) -> Base {
        let jb = lin.j.columns(0, n_cols_base).into_owned();
        let (q, picked) = pivoted_basis(&jb, &DMatrix::zeros(jb.nrows(), 0), RANK_TOL);
        let cols: Vec<usize> = (0..picked.len()).filter(|&c| picked[c].is_some()).collect();
        let r_perp = &lin.r - &q * (q.transpose() * &lin.r);
        let rss = r_perp.norm_squared();
        let cv = cross_validate(&lin, &cols, None, folds, n);
        Base {
            lin,
            cols,
            q,
            r_perp,
            rss,
            cv,
        }
    }
    fn dof(&self) -> f64 {
        (self.lin.r.len() as f64 - self.cols.len() as f64).max(1.0)
    }
}

struct Tested {
    cand: Candidate,
    terms: Vec<Term>,
    fitted: DVector<f64>,
    p_raw: f64,
    cv_ok: bool,
    share: f64,
}

/// Tests one candidate against `base` (at `state`); `Err` with the reason if the model cannot
/// take its terms.
#[allow(clippy::too_many_arguments)] // the pieces of one round, kept apart for clarity
fn test_candidate(
    setup: &Setup,
    data: &Data,
    state: &State,
    base: &Base,
    effect: Effect,
    terms: Vec<Term>,
    round: usize,
    folds: usize,
) -> Result<Tested, String> {
    let n = data.n_rows();
    let n_base_cols = base.lin.j.ncols();
    let mut s = state.clone();
    s.terms.extend(terms.iter().cloned().map(|t| (t, 0.0)));
    let lin = setup.linearise(&s).map_err(|e| e.to_string())?;
    let k_all = terms.len();
    let c_all = lin.j.columns(n_base_cols, k_all).into_owned();
    let (qc, picked) = pivoted_basis_beside(
        &c_all,
        &base.q,
        VISIBLE_TOL,
        largest_column_norm(&base.lin.j),
    );
    let visible: Vec<usize> = (0..k_all).filter(|&c| picked[c].is_some()).collect();
    // Absorbed parts: which baseline parameters carry them.
    let mut absorbed_by = Vec::new();
    let visible_fraction: Vec<f64> = (0..k_all)
        .map(|c| {
            let col = c_all.column(c);
            let nrm = col.norm();
            if nrm == 0.0 {
                return 0.0;
            }
            let perp = col - &base.q * (base.q.transpose() * col);
            perp.norm() / nrm
        })
        .collect();
    for c in (0..k_all).filter(|c| picked[*c].is_none()) {
        if visible_fraction[c] == 0.0 && c_all.column(c).norm() == 0.0 {
            continue;
        }
        let jb = lin.j.select_columns(&base.cols);
        let (coef, _) = lstsq(&jb, &c_all.column(c).into_owned());
        let mut contrib: Vec<(f64, usize)> = (0..base.cols.len())
            .map(|k| (coef[k].abs() * jb.column(k).norm(), base.cols[k]))
            .collect();
        contrib.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (_, col) in contrib.iter().take(2) {
            let name = base.lin.names.get(*col).cloned().unwrap_or_default();
            if !absorbed_by.contains(&name) {
                absorbed_by.push(name);
            }
        }
    }
    let before = base.cv.mse().sqrt();
    let gap2 = base.cv.mse() - base.cv.floor();
    let mut cand = Candidate {
        effect,
        round,
        heldout_rms_before_m: before,
        heldout_rms_after_m: before,
        gap_closed_pct: 0.0,
        accepted: false,
        reason: String::new(),
        parameters: Vec::new(),
        p_value: 1.0,
        n_visible: visible.len(),
        visible_fraction: visible_fraction.clone(),
        absorbed_by: absorbed_by.clone(),
        bic_gain: 0.0,
    };
    let kept_terms: Vec<Term> = visible.iter().map(|&c| terms[c].clone()).collect();
    if visible.is_empty() {
        cand.reason = format!(
            "indistinguishable from baseline parameters {}",
            if absorbed_by.is_empty() {
                "(zero signature)".to_owned()
            } else {
                absorbed_by.join(", ")
            }
        );
        return Ok(Tested {
            cand,
            terms: kept_terms,
            fitted: DVector::zeros(n),
            p_raw: 1.0,
            cv_ok: false,
            share: 0.0,
        });
    }
    let k = visible.len() as f64;
    let proj = qc.transpose() * &base.r_perp;
    let fitted_all = &qc * proj;
    let fitted = DVector::from_iterator(n, (0..n).map(|i| fitted_all[i]));
    // Nonlinear refit with the visible terms: an effect the baseline mostly absorbs moves the
    // baseline's parameters far, and only a refit sees what is left.
    let mut s_vis = state.clone();
    s_vis
        .terms
        .extend(visible.iter().map(|&c| (terms[c].clone(), 0.0)));
    let (s_vis, lin) = refine(setup, s_vis, 10).map_err(|e| e.to_string())?;
    let mut cols = base.cols.clone();
    cols.extend((0..visible.len()).map(|c| n_base_cols + c));
    let a = lin.j.select_columns(&cols);
    let (x, cov) = lstsq(&a, &lin.r);
    let n_rows = base.lin.r.len() as f64;
    let rss_c = (&lin.r - &a * &x).norm_squared().max(1e-300);
    let drss = (base.rss - rss_c).max(0.0);
    let dof = (base.dof() - k).max(1.0);
    let f = (drss / k) / (rss_c / dof);
    let p_raw = f_sf(f, k, dof);
    cand.bic_gain = drss - k * n_rows.ln();
    let s2 = (rss_c / dof).max(1.0);
    cand.parameters = visible
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            let idx = base.cols.len() + i;
            let value = s_vis
                .terms
                .get(state.terms.len() + i)
                .map_or(0.0, |(_, v)| *v);
            ParamValue {
                name: terms[c].name.clone(),
                value: value + x[idx],
                std: (cov[(idx, idx)] * s2).sqrt(),
                unit: terms[c].unit.to_owned(),
            }
        })
        .collect();
    // Held-out check.
    let cvis = lin.j.columns(n_base_cols, visible.len()).into_owned();
    let cv = cross_validate(&lin, &base.cols, Some(&cvis), folds, n);
    cand.heldout_rms_after_m = cv.mse().sqrt();
    let d: Vec<f64> = (0..n)
        .map(|i| (base.cv.e[i].powi(2) - cv.e[i].powi(2)) / cv.sigma2[i].max(1e-300))
        .collect();
    let md = mean(d.iter().copied());
    let sd = (d.iter().map(|v| (v - md).powi(2)).sum::<f64>() / (n as f64 - 1.0).max(1.0)).sqrt();
    let cv_ok = md > sd / (n as f64).sqrt();
    let share = if gap2 > 0.0 {
        (base.cv.mse() - cv.mse()) / gap2
    } else {
        0.0
    };
    cand.gap_closed_pct = 100.0 * share.clamp(-9.99, 9.99);
    Ok(Tested {
        cand,
        terms: kept_terms,
        fitted,
        p_raw,
        cv_ok,
        share,
    })
}

fn cosine(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    let d = a.norm() * b.norm();
    if d > 0.0 { (a.dot(b) / d).abs() } else { 0.0 }
}

/// Step 1 of the paper (Fig. 6): each transmission from its external encoder.
fn fit_transmissions(device: &Device, data: &Data, sigma_e: f64) -> Result<Vec<Trans>, Error> {
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
fn baseline_error(e: hapcal_problems::Error) -> Error {
    Error::Baseline {
        message: e.to_string(),
    }
}

/// A binned signal: name, value per sample, bin edges.
type Signal = (String, Vec<f64>, Vec<(f64, f64)>);

/// The residual map of held-out residuals `cv`.
fn residual_map(
    device: &Device,
    data: &Data,
    lin: &Linear,
    cv: &Cv,
    alpha: f64,
) -> (Vec<Bin>, Vec<SignalTest>) {
    let n = data.n_rows();
    let mut signals: Vec<Signal> = Vec::new();
    let quantile_edges = |v: &[f64], k: usize| -> Vec<(f64, f64)> {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let at = |f: f64| {
            s.get(((s.len() as f64 - 1.0) * f).round() as usize)
                .copied()
                .unwrap_or(0.0)
        };
        (0..k)
            .map(|b| (at(b as f64 / k as f64), at((b + 1) as f64 / k as f64)))
            .collect()
    };
    let phase_edges = |k: usize| {
        (0..k)
            .map(|b| (TAU * b as f64 / k as f64, TAU * (b + 1) as f64 / k as f64))
            .collect::<Vec<_>>()
    };
    for j in 0..data.q().first().map_or(0, Vec::len) {
        let v: Vec<f64> = data.q().iter().map(|q| q[j]).collect();
        let edges = quantile_edges(&v, 5);
        signals.push((format!("q{}", j + 1), v.clone(), edges));
        if let Some(c) = device.capstans.iter().find(|c| c.joint == j + 1) {
            let ph: Vec<f64> = v.iter().map(|q| (c.ratio * q).rem_euclid(TAU)).collect();
            signals.push((format!("motor_phase{}", j + 1), ph, phase_edges(8)));
        }
        if let Some(dir) = data.direction(j) {
            signals.push((
                format!("direction{}", j + 1),
                dir,
                vec![(-1.5, 0.0), (0.0, 1.5)],
            ));
        }
    }
    signals.push((
        "distance".into(),
        data.distance_m().to_vec(),
        quantile_edges(data.distance_m(), 5),
    ));
    let gamma: Vec<f64> = (lin.p.iter())
        .map(|p| hapcal_problems::cable_angle(&Point3::from(*p)).0)
        .collect();
    signals.push((
        Effect::CableAngle.name().into(),
        gamma.clone(),
        quantile_edges(&gamma, 5),
    ));
    if let Some(t) = data.t_s() {
        signals.push(("time".into(), t.to_vec(), quantile_edges(t, 5)));
    }
    let drum = (device.cable_encoder)
        .unwrap_or(hapcal_sim::REFERENCE_CABLE_ENCODER)
        .drum_radius_m;
    let ph: Vec<f64> = data
        .distance_m()
        .iter()
        .map(|d| (d / drum).rem_euclid(TAU))
        .collect();
    signals.push(("drum_phase".into(), ph, phase_edges(8)));

    let n_bins: usize = signals.iter().map(|s| s.2.len()).sum();
    let z2: Vec<f64> = (0..n)
        .map(|i| cv.e[i].powi(2) / cv.var[i].max(1e-300))
        .collect();
    let mut bins = Vec::new();
    let mut tests = Vec::new();
    let n_signals = signals.len() as f64;
    for (name, v, edges) in &signals {
        let last = edges.len().saturating_sub(1);
        let bin_of = |x: f64| {
            edges
                .iter()
                .position(|&(lo, hi)| x >= lo && x < hi)
                .unwrap_or(if x >= edges.last().map_or(0.0, |e| e.0) {
                    last
                } else {
                    0
                })
        };
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); edges.len()];
        for i in 0..n {
            members[bin_of(v[i])].push(i);
        }
        let groups = members.iter().filter(|m| !m.is_empty()).count();
        let anova = |z: &dyn Fn(usize) -> f64| {
            let grand = mean((0..n).map(z));
            let (mut between, mut within) = (0.0, 0.0);
            for m in members.iter().filter(|m| !m.is_empty()) {
                let mz = mean(m.iter().map(|&i| z(i)));
                between += m.len() as f64 * (mz - grand).powi(2);
                within += m.iter().map(|&i| (z(i) - mz).powi(2)).sum::<f64>();
            }
            let d1 = groups.saturating_sub(1) as f64;
            let d2 = (n as f64 - groups as f64).max(1.0);
            if d1 > 0.0 && within > 0.0 {
                f_sf((between / d1) / (within / d2), d1, d2)
            } else {
                1.0
            }
        };
        // Mean (a bias that changes sign) and mean square (a spread), Bonferroni over both.
        let p = (2.0 * anova(&|i| cv.e[i] / cv.var[i].max(1e-300).sqrt()).min(anova(&|i| z2[i])))
            .min(1.0);
        for (b, m) in members.iter().enumerate() {
            if m.is_empty() {
                continue;
            }
            let nb = m.len() as f64;
            let chi: f64 = m.iter().map(|&i| z2[i]).sum();
            let p = chi2_sf(chi, nb);
            bins.push(Bin {
                signal: name.clone(),
                lo: edges[b].0,
                hi: edges[b].1,
                n: m.len(),
                rms_m: mean(m.iter().map(|&i| cv.e[i].powi(2))).sqrt(),
                mean_m: mean(m.iter().map(|&i| cv.e[i])),
                floor_rms_m: mean(m.iter().map(|&i| cv.var[i])).sqrt(),
                p_value: p,
                flagged: p < alpha / n_bins as f64,
            });
        }
        tests.push(SignalTest {
            signal: name.clone(),
            p_value: p,
            significant: p < alpha / n_signals,
        });
    }
    (bins, tests)
}

/// The baseline's in-sample distance residuals (measured − model, m, one per row of
/// `rows`) after fitting `cfg.baseline` (with the same fallbacks as [`diagnose`]). The blind
/// test sizes effects with it: the difference between the residuals of a log with and
/// without an effect (same seed, same noise) is the part of the effect the baseline cannot
/// absorb, `P⊥·effect` (docs/diagnosis.md §5).
///
/// # Errors
/// As [`diagnose`].
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

/// Diagnoses a log: the gap between the calibrated model and the floor, where it lies,
/// which library effect explains it, and how far it shrinks (docs/design.md §6, docs/diagnosis.md).
///
/// `device` is the nominal device file; `rows` a log in docs/design.md §5 format (time order
/// when `t_s` is given). No truth is used.
///
/// **Floor.** From the encoder specification: the paper's noise model (docs/design.md §3) with
/// the cable encoder's counts and drum radius, `σ_e = 2π/counts/3`, `σ_m = 2π·R_d·σ_e`, plus
/// each joint reading's quantisation `ρ_j²/12` (`ρ_j = 2π/(counts·R_j)`) propagated through
/// `∂d/∂q_j`; the held-out floor adds each prediction's variance (`σ²·(1 + h)`,
/// docs/diagnosis.md §1). If the baseline's residuals are significantly *below* that floor (as
/// in logs simulated with the truth computed from the quantised reading), the quantisation
/// term is dropped, and [`Diagnosis::floor_method`] says so.
///
/// **Which.** Every candidate is linearised at the baseline estimate; its columns are
/// projected on the orthogonal complement of the baseline's (absorbed columns are reported
/// with the baseline parameters that absorb them); an F-test (Holm–Bonferroni over the
/// library), a BIC penalty, k-fold cross-validation over time-contiguous blocks (held-out
/// improvement > 1 standard error) and a share of the gap ≥ `min_gap_share` decide. The
/// best accepted candidate is refitted with the baseline (Levenberg–Marquardt) and the next
/// round starts from there, up to `max_effects`.
///
/// # Errors
/// [`Error::Config`] for bad settings; [`Error::Data`] for a log with fewer than 20 rows or
/// rows that do not fit the device; [`Error::Baseline`] if the device has no chain or the
/// transmissions cannot be fitted.
pub fn diagnose(
    device: &Device,
    rows: &[LogRow],
    cfg: &DiagnoseConfig,
) -> Result<Diagnosis, Error> {
    if cfg.folds < 2 || !(cfg.alpha > 0.0 && cfg.alpha < 1.0) || cfg.max_effects == 0 {
        return Err(Error::Config {
            message: format!(
                "need folds ≥ 2 (got {}), 0 < alpha < 1 (got {}), max_effects ≥ 1",
                cfg.folds, cfg.alpha
            ),
        });
    }
    let chain = device.chain().map_err(|e| Error::Baseline {
        message: e.to_string(),
    })?;
    let n_joints = chain.n_joints();
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
    let mut notes = Vec::new();
    let sampled: Vec<LogRow>;
    let rows = match hapcal_calibrate::fit::ladder_sample(&[rows.len()], cfg.max_rows) {
        Some(sample) => {
            notes.push(format!(
                "the log's {} rows are diagnosed on {} of them, one row in {} from the first",
                rows.len(),
                sample.rows.len(),
                sample.stride
            ));
            sampled = sample.rows.iter().map(|&i| rows[i].clone()).collect();
            &sampled[..]
        }
        None => rows,
    };
    let data = log_data(rows)?;
    let n = data.n_rows();
    let mut setup = Setup::new(device, chain, data.clone())?;
    let trans_joints: Vec<usize> = device.capstans.iter().map(|c| c.joint - 1).collect();
    let mut baseline = cfg.baseline;
    if baseline == ModelName::Transmissions
        && !trans_joints.is_empty()
        && !ext_available(rows, &trans_joints)
    {
        notes.push("the log lacks external-encoder readings for the transmissions: geometric baseline used".to_owned());
        baseline = ModelName::Geometric;
    }
    let trans = if baseline == ModelName::Transmissions {
        setup.set_ext_joints(trans_joints.clone())?;
        fit_transmissions(device, &data, setup.sigma_e_rad())?
    } else {
        Vec::new()
    };
    let state0 = setup.initial_state(trans);
    let (mut state, lin) = refine(&setup, state0, 8).map_err(baseline_error)?;
    let mut n_base_cols = lin.j.ncols();
    let mut base = Base::new(lin, n_base_cols, cfg.folds, n);
    let base_rss_excess = |b: &Base| b.rss - b.dof();
    // The floor: with quantisation unless the data are significantly quieter than that.
    let mut floor_method = "spec: sigma_m = 2*pi*R_d*sigma_e, sigma_e = 2*pi/counts/3 (paper noise model), plus joint-reading quantisation rho^2/12 through dd/dq; held-out floor sigma^2*(1+h)".to_owned();
    let lower = 1.0 - chi2_sf(base.rss, base.dof());
    if lower < 1e-3 {
        setup.set_quantisation(false);
        let (s, lin) = refine(&setup, state.clone(), 2).map_err(baseline_error)?;
        state = s;
        base = Base::new(lin, n_base_cols, cfg.folds, n);
        floor_method = "spec without quantisation: sigma_m = 2*pi*R_d*sigma_e, sigma_e = 2*pi/counts/3 (paper noise model); the residuals were significantly below the floor with reading quantisation, so the readings are not the quantisation-limited measurement here; held-out floor sigma^2*(1+h)".to_owned();
    }
    let n_params = base.cols.len();
    // Copied rows add residuals but no information: the baseline needs a configuration per
    // parameter and one more for σ, or its held-out residual is a confident report of nothing.
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
    let excess0 = base_rss_excess(&base);
    let mse0 = base.cv.mse();
    let floor0 = base.cv.floor();
    let gap2 = mse0 - floor0;
    let chi = base.cv.chi2();
    let gap_p = chi2_sf(chi, n as f64);
    let gap_significant = gap_p < cfg.alpha;
    let (where_, signals) = residual_map(device, &data, &base.lin, &base.cv, cfg.alpha);

    // Which joint's angle the residual lives on (the joints in parallel, collected in order).
    let probe_joint = |j: usize| -> Option<JointProbe> {
        let (lo, hi) = device.joint_limits().get(j).copied().unwrap_or((-1.0, 1.0));
        let probe = Chebyshev::try_new(lo, hi, vec![0.0; 7]).ok()?;
        let terms: Vec<Term> = (1..=6)
            .map(|k| Term {
                name: format!("probe.j{}_cheb{k}", j + 1),
                unit: "rad",
                kind: TermKind::Joint {
                    joint: j,
                    g: data
                        .q()
                        .iter()
                        .map(|q| probe.basis(q[j]).get(k).copied().unwrap_or(0.0))
                        .collect(),
                },
            })
            .collect();
        let mut s = state.clone();
        s.terms.extend(terms.into_iter().map(|t| (t, 0.0)));
        let lin = setup.linearise(&s).ok()?;
        let c = lin.j.columns(n_base_cols, 6).into_owned();
        let (qc, _) = pivoted_basis_beside(&c, &base.q, 0.02, largest_column_norm(&base.lin.j));
        let k = qc.ncols() as f64;
        let drss = (qc.transpose() * &base.r_perp).norm_squared();
        let excess = base.rss - base.dof();
        let p = if k > 0.0 {
            f_sf(
                (drss / k) / ((base.rss - drss).max(1e-300) / (base.dof() - k).max(1.0)),
                k,
                (base.dof() - k).max(1.0),
            )
        } else {
            1.0
        };
        Some(JointProbe {
            joint: j + 1,
            explained_pct: if excess > 0.0 {
                100.0 * ((drss - k) / excess).clamp(0.0, 1.0)
            } else {
                0.0
            },
            p_value: p,
        })
    };
    let joints: Vec<JointProbe> = (0..n_joints)
        .into_par_iter()
        .map(probe_joint)
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();

    let mut library: Vec<Effect> = EffectKind::LIBRARY.iter().map(|k| k.effect()).collect();
    if baseline == ModelName::Geometric && !device.capstans.is_empty() {
        library.push(Effect::Capstans);
        if device.parallelogram.is_some() {
            library.push(Effect::Parallelogram);
        }
    }
    let mut candidates = Vec::new();
    let mut steps: Vec<Step> = Vec::new();
    // Per accepted effect: its share of its round's held-out gap and of its round's in-sample
    // excess, and whether a significant gap remains after it.
    let mut round_shares: Vec<(f64, f64, bool)> = Vec::new();
    let mut accepted_names: Vec<Effect> = Vec::new();
    let mut round_gap_significant = gap_significant;
    for round in 1..=cfg.max_effects {
        // The candidates of a round are independent: tested in parallel (rayon), collected in
        // library order, so the result does not depend on the number of threads.
        let outcomes: Vec<(Effect, Result<Tested, String>)> = library
            .par_iter()
            .filter(|e| !accepted_names.contains(e))
            .map(|&effect| {
                let tested = candidate_terms(effect, device, &data, n_joints).and_then(|terms| {
                    test_candidate(
                        &setup, &data, &state, &base, effect, terms, round, cfg.folds,
                    )
                });
                (effect, tested)
            })
            .collect();
        let mut tested: Vec<Tested> = Vec::new();
        for (effect, outcome) in outcomes {
            match outcome {
                Ok(t) => tested.push(t),
                Err(reason) => {
                    if round == 1 {
                        notes.push(format!("{effect}: {reason}"));
                    }
                }
            }
        }
        let adjusted = holm(&tested.iter().map(|t| t.p_raw).collect::<Vec<_>>());
        for (t, p) in tested.iter_mut().zip(&adjusted) {
            t.cand.p_value = *p;
            if t.cand.n_visible == 0 {
                continue;
            }
            let reason = if !round_gap_significant {
                "no significant gap to explain".to_owned()
            } else if *p >= cfg.alpha {
                format!("not significant (Holm-adjusted p = {p:.2e})")
            } else if t.cand.bic_gain <= 0.0 {
                format!(
                    "does not beat the BIC penalty (gain {:.1})",
                    t.cand.bic_gain
                )
            } else if !t.cv_ok {
                "held-out RMS not better than the baseline by one standard error".to_owned()
            } else if t.share < cfg.min_gap_share {
                format!("closes only {:.0} % of the gap", 100.0 * t.share)
            } else {
                String::new()
            };
            t.cand.accepted = reason.is_empty();
            t.cand.reason = if reason.is_empty() {
                format!(
                    "significant (p = {p:.1e}), beats BIC and the held-out baseline, closes {:.0} % of the gap",
                    100.0 * t.share
                )
            } else {
                reason
            };
        }
        let winner = tested
            .iter()
            .enumerate()
            .filter(|(_, t)| t.cand.accepted)
            .max_by(|a, b| a.1.cand.bic_gain.total_cmp(&b.1.cand.bic_gain))
            .map(|(i, _)| i);
        let confusable: Vec<Effect> = winner
            .map(|w| {
                tested
                    .iter()
                    .enumerate()
                    .filter(|(i, t)| {
                        *i != w
                            && t.cand.n_visible > 0
                            && cosine(&t.fitted, &tested[w].fitted) > 0.9
                    })
                    .map(|(_, t)| t.cand.effect)
                    .collect()
            })
            .unwrap_or_default();
        for (i, t) in tested.iter_mut().enumerate() {
            if Some(i) != winner && t.cand.accepted {
                t.cand.accepted = false;
                t.cand.reason = format!("passes, but ranks below the winner ({})", t.cand.reason);
            }
        }
        let Some(w) = winner else {
            candidates.extend(tested.into_iter().map(|t| t.cand));
            break;
        };
        let win = &tested[w];
        let mut s = state.clone();
        s.terms.extend(win.terms.iter().cloned().map(|t| (t, 0.0)));
        let (s, lin) = refine(&setup, s, 10).map_err(baseline_error)?;
        state = s;
        n_base_cols = lin.j.ncols();
        let before = base.cv.mse().sqrt();
        let new_base = Base::new(lin, n_base_cols, cfg.folds, n);
        // Parameters ± std at the refined estimate.
        let a = new_base.lin.j.select_columns(&new_base.cols);
        let (_, cov) = lstsq(&a, &new_base.lin.r);
        let s2 = (new_base.rss / new_base.dof()).max(1.0);
        let n_prev = n_base_cols - win.terms.len();
        let parameters = win
            .terms
            .iter()
            .enumerate()
            .map(|(k, term)| {
                let col = n_prev + k;
                let pos = new_base.cols.iter().position(|&c| c == col);
                ParamValue {
                    name: term.name.clone(),
                    value: state
                        .terms
                        .iter()
                        .find(|(t, _)| t.name == term.name)
                        .map_or(0.0, |(_, v)| *v),
                    std: pos.map_or(f64::NAN, |p| (cov[(p, p)] * s2).sqrt()),
                    unit: term.unit.to_owned(),
                }
            })
            .collect();
        let after = new_base.cv.mse().sqrt();
        steps.push(Step {
            effect: win.cand.effect,
            heldout_rms_before_m: before,
            heldout_rms_after_m: after,
            gap_closed_pct: if gap2 > 0.0 {
                100.0 * (before * before - after * after) / gap2
            } else {
                0.0
            },
            parameters,
            confusable_with: confusable,
        });
        accepted_names.push(win.cand.effect);
        candidates.extend(tested.into_iter().map(|t| t.cand));
        let (mse_b, floor_b, excess_b) = (base.cv.mse(), base.cv.floor(), base_rss_excess(&base));
        base = new_base;
        round_gap_significant = chi2_sf(base.cv.chi2(), n as f64) < cfg.alpha;
        let share = |b: f64, a: f64, gap: f64| if gap > 0.0 { (b - a) / gap } else { 1.0 };
        round_shares.push((
            share(mse_b, base.cv.mse(), mse_b - floor_b),
            share(excess_b, base_rss_excess(&base), excess_b),
            round_gap_significant,
        ));
        // Another round while what is left is significantly above the floor: a second
        // effect is judged by the gap the first one left, however small a share of the
        // original gap that is.
        if !round_gap_significant {
            break;
        }
    }
    let final_mse = base.cv.mse();
    let (_, final_signals) = residual_map(device, &data, &base.lin, &base.cv, cfg.alpha);
    let mut leads: Vec<&SignalTest> = final_signals.iter().filter(|s| s.significant).collect();
    leads.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
    let leads: Vec<String> = leads
        .iter()
        .take(6)
        .map(|s| format!("{} (p = {:.1e})", s.signal, s.p_value))
        .collect();
    let floor_rms = floor0.sqrt();
    let gap_rms = gap2.max(0.0).sqrt();
    let closed_in_sample = if excess0 > 0.0 {
        (excess0 - base_rss_excess(&base)) / excess0
    } else {
        0.0
    };
    // Sufficiency, from the last accepted effect back: one that closes less than
    // SUFFICIENT_SHARE of its round's held-out gap (what the effects before it left) and less
    // than SUFFICIENT_SHARE_IN_SAMPLE of its round's in-sample excess, leaving a significant
    // gap, explains a part of something else; it is not named, and the rule goes on with the
    // one before it.
    let mut named = accepted_names.len();
    while named > 0 {
        let (cv, in_sample, significant) = round_shares[named - 1];
        if cv >= SUFFICIENT_SHARE || in_sample >= SUFFICIENT_SHARE_IN_SAMPLE || !significant {
            break;
        }
        notes.push(format!(
            "{} explains {:.0} % of the held-out gap left before it ({:.0} % in-sample) and a \
             significant residual remains: not enough to name it",
            accepted_names[named - 1],
            100.0 * cv,
            100.0 * in_sample
        ));
        named -= 1;
    }
    let verdict = Verdict::of(&accepted_names[..named]);
    if named > 0 && round_shares[named - 1].2 {
        let final_mse = steps[named - 1].heldout_rms_after_m.powi(2);
        let why = if named >= cfg.max_effects {
            format!(
                "the search stops at {} effects (max_effects)",
                cfg.max_effects
            )
        } else {
            "no further candidate of the library passes".to_owned()
        };
        notes.push(format!(
            "after {verdict} the cross-validated RMS is {:.1} µm, {:.1}× the floor's {:.1} µm, a \
             significant residual: another effect is at work that the verdict does not name \
             ({why})",
            final_mse.sqrt() * 1e6,
            (final_mse / floor0).sqrt(),
            floor_rms * 1e6
        ));
    }
    Ok(Diagnosis {
        baseline,
        n_samples: n,
        n_params,
        floor_method,
        sigma_m_m: setup.sigma_m_m(),
        sigma_e_rad: setup.sigma_e_rad(),
        floor_rms_m: floor_rms,
        heldout_rms_m: mse0.sqrt(),
        gap_rms_m: gap_rms,
        gap_in_floors: if floor_rms > 0.0 {
            gap_rms / floor_rms
        } else {
            0.0
        },
        gap_p_value: gap_p,
        gap_significant,
        where_,
        signals,
        joints,
        candidates,
        steps,
        heldout_rms_final_m: final_mse.sqrt(),
        gap_closed_pct: if gap2 > 0.0 {
            100.0 * (mse0 - final_mse) / gap2
        } else {
            0.0
        },
        gap_closed_in_sample_pct: 100.0 * closed_in_sample,
        verdict,
        leads,
        notes,
    })
}

#[cfg(test)]
mod tests;
