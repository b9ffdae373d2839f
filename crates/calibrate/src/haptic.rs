//! The paper's two-step calibration of a capstan-driven haptic device (Baser & Konukseven,
//! Fig. 6), on a measured log and nothing else: step 1 identifies each transmission from its
//! external encoder (capstan eq. 1, the parallelogram's polynomial), step 2 corrects the joint
//! readings and identifies the kinematic deviations from the cable distances; or both at once
//! ([`identify_jointly`]). [`calibrated_device`] writes the result as a device file.

use std::borrow::Borrow;

use anyhow::{Context, Result, bail};
use faer::Col;
use hapcal_contract::drives::{HapticDrives, JointDrive, haptic_drives};
use hapcal_contract::{
    Calibration, Covariance, JointRange, ModelName, Region, Torque, TorqueSource,
};
use hapcal_identify::{Identified, IdentifyConfig, Problem, identify};
use hapcal_io::{CalibratedValue, CalibrationMeta, Device, LogRow};
use hapcal_kinematics::{Chain, DhRow};
use hapcal_problems::{
    CalibrationProblem, CapstanProblem, DistanceLog, DistanceLogModel, DistanceLogProblem,
    DistanceLogState, EffectTerm, EffectTermKind, HANDLE_COMPLIANCE_UNIT, JointData, JointProblem,
    JointTransmissions, LogTransmission, Observations, PolynomialProblem, Row, RowKind, Weights,
};
use hapcal_sim::NoiseModel;
use hapcal_transmission::{Capstan, CapstanParams, Chebyshev, JointRad};

use crate::data::NamedLog;
use crate::model::ModelChoice;
use crate::report::{CalibrationReport, Figures, ParamReport, SetReport, SetRole};

mod ladder;
mod logs;
pub use ladder::*;
pub use logs::*;

/// Degree of the joint-4 polynomial (paper: tenth order).
pub const POLY_DEGREE: usize = 10;
/// The joint whose capstan feeds the parallelogram (1-based).
pub const PARALLELOGRAM_JOINT: usize = 4;

/// A capstan-driven haptic device as its device file describes it: the chain, the chain seen
/// from its base, and the noise of its sensors (paper section 4: encoder quantisation σ_e from
/// the counts per revolution, cable-encoder noise σ_m).
#[derive(Clone, Debug)]
pub struct HapticDevice {
    /// Nominal device.
    pub device: Device,
    /// Nominal chain (D-H rows 0..n, row 0 the rig → base transform).
    pub chain: Chain,
    /// Chain of rows 1..n (base frame → end effector), for validation in the base frame.
    pub base_chain: Chain,
    /// Noise model of the joint encoders and the cable encoder (the paper's).
    pub noise: NoiseModel,
}

impl HapticDevice {
    /// The haptic device of a device file.
    ///
    /// # Errors
    /// A device that is not a standard D-H chain without β with a fixed row 0, or has no
    /// `[cable_encoder]`.
    pub fn new(device: Device) -> Result<Self> {
        let chain = device.chain()?;
        let rows: Vec<DhRow> = device.dh_rows();
        if rows.len() < 2 || rows.iter().any(|r| r.beta_rad.is_some()) {
            bail!("the paper's pipeline expects standard D-H rows without beta, row 0 fixed");
        }
        let base_chain = Chain::from_dh(&rows[1..])?;
        let Some(cable) = device.cable_encoder.as_ref() else {
            bail!("the device has no [cable_encoder]")
        };
        let noise = NoiseModel::paper(cable);
        Ok(Self {
            device,
            chain,
            base_chain,
            noise,
        })
    }

    /// Capstans of the device by 1-based joint.
    fn capstan(&self, joint: usize) -> Result<Capstan> {
        let c = self
            .device
            .capstans
            .iter()
            .find(|c| c.joint == joint)
            .with_context(|| format!("no capstan on joint {joint}"))?;
        Ok(Capstan::try_new(c.ratio, c.drum_distance_m)?)
    }

    /// The x of `base_chain` from an x of `chain` (drops row 0's four parameters).
    pub fn base_x(&self, x: &[f64]) -> Vec<f64> {
        x[self.chain.n_params() - self.base_chain.n_params()..].to_vec()
    }
}

/// One identified capstan (paper eq. 1, Table 2).
#[derive(Clone, Debug)]
pub struct CapstanFit {
    /// Joint, 1-based.
    pub joint: usize,
    /// Geometry.
    pub capstan: Capstan,
    /// Identified parameters.
    pub params: CapstanParams,
    /// The identification (names, std, correlations, pruning).
    pub identified: Identified,
}

/// Identified transmissions: capstans of joints 1–3 and the joint-4 polynomial.
#[derive(Clone, Debug)]
pub struct TransmissionFit {
    /// Capstans 1–3.
    pub capstans: Vec<CapstanFit>,
    /// Joint-4 error polynomial (Chebyshev on the joint range).
    pub poly: Chebyshev,
    /// Its identification.
    pub poly_identified: Identified,
}

impl TransmissionFit {
    /// Corrected joint angles (rad) for readings `theta` (rad): capstan joints through their
    /// identified eq. 1, joint 4 plus the polynomial, direct joints unchanged.
    pub fn corrected(&self, theta: &[f64]) -> Vec<f64> {
        let mut q = theta.to_vec();
        for c in &self.capstans {
            if let Some(v) = q.get_mut(c.joint - 1) {
                *v = c.capstan.output_rad(&c.params, JointRad(*v));
            }
        }
        if let Some(v) = q.get_mut(PARALLELOGRAM_JOINT - 1) {
            *v += self.poly.eval(*v);
        }
        q
    }
}

/// Options of step 1.
#[derive(Clone, Copy, Debug)]
pub struct Step1Options {
    /// Run the external-encoder identification over a full output revolution (±π) instead of
    /// the joint range (it decorrelates Re and r_o, which the joint range alone leaves correlated).
    pub full_revolution: bool,
}

fn ext<R: Borrow<LogRow>>(rows: &[R], joint: usize) -> Result<Vec<f64>> {
    rows_of(rows)
        .map(|r| {
            r.ext
                .get(joint - 1)
                .copied()
                .flatten()
                .with_context(|| format!("log line {}: no ext{joint}", r.line))
        })
        .collect()
}

/// The rows of `rows`, whether held (a log's rows) or borrowed (a fold's).
fn rows_of<R: Borrow<LogRow>>(rows: &[R]) -> impl Iterator<Item = &LogRow> + Clone {
    rows.iter().map(Borrow::borrow)
}

/// Identification settings of step 1: residuals are already divided by σ_e (so σ = 1), and the
/// plausible ranges are the transmission's, not the kinematic ones: an eccentricity phase may be
/// anywhere in (−π, π], an eccentricity up to 1 mm, a ratio error up to 0.1.
pub fn transmission_config() -> IdentifyConfig {
    // The capstan problem's own settings (σ = 1, phases anywhere), with the ranges of this
    // device's transmissions: eccentricities up to 1 mm, ratio errors up to 0.1.
    let mut cfg = CapstanProblem::identify_config();
    cfg.rank.prior_m = 1e-3;
    cfg.rank.prior_dimensionless = 0.1;
    cfg
}

/// Step 1's problem of capstan `capstan` on joint `joint` (1-based): its readings against its
/// external encoder `ext{joint}`, σ the external encoder's.
///
/// # Errors
/// A row without that ext reading, or the problem's own checks.
fn capstan_problem<R: Borrow<LogRow>>(
    r: &HapticDevice,
    rows: &[R],
    joint: usize,
    capstan: Capstan,
) -> Result<CapstanProblem> {
    let theta = rows_of(rows).map(|row| row.q[joint - 1]).collect();
    let sigma = r.noise.sigma_e_rad;
    Ok(CapstanProblem::new(
        capstan,
        joint,
        theta,
        ext(rows, joint)?,
        sigma,
    )?)
}

/// Step 1's problem of the parallelogram's polynomial (joint 4 against `ext4`, on the joint's
/// range), σ the external encoder's.
///
/// # Errors
/// A row without an `ext4` reading, or the problem's own checks.
fn polynomial_problem<R: Borrow<LogRow>>(
    r: &HapticDevice,
    rows: &[R],
) -> Result<PolynomialProblem> {
    let (lo, hi) = r.device.joint_limits()[PARALLELOGRAM_JOINT - 1];
    let theta = (rows_of(rows))
        .map(|row| row.q[PARALLELOGRAM_JOINT - 1])
        .collect();
    Ok(PolynomialProblem::new(
        PARALLELOGRAM_JOINT,
        POLY_DEGREE,
        lo,
        hi,
        theta,
        ext(rows, PARALLELOGRAM_JOINT)?,
        r.noise.sigma_e_rad,
    )?)
}

/// Step 1 (paper Fig. 6): each transmission from its external encoder.
///
/// # Errors
/// Missing ext columns, or an identification failure.
pub fn identify_transmissions(r: &HapticDevice, rows: &[LogRow]) -> Result<TransmissionFit> {
    let cfg = transmission_config();
    let mut capstans = Vec::new();
    for joint in 1..PARALLELOGRAM_JOINT {
        let capstan = r.capstan(joint)?;
        let problem = capstan_problem(r, rows, joint, capstan)?;
        let identified = identify(&problem, problem.initial_guess(), &cfg)
            .with_context(|| format!("identifying capstan {joint}"))?;
        let params = CapstanProblem::params(identified.fit.x.as_ref());
        capstans.push(CapstanFit {
            joint,
            capstan,
            params,
            identified,
        });
    }
    let problem = polynomial_problem(r, rows)?;
    let poly_identified = identify(&problem, problem.initial_guess(), &cfg)
        .context("identifying the joint-4 polynomial")?;
    let poly = problem.polynomial(poly_identified.fit.x.as_ref());
    Ok(TransmissionFit {
        capstans,
        poly,
        poly_identified,
    })
}

/// Step 2: kinematic deviations from cable distances, with joint readings corrected by
/// `transmissions` (or raw when `None`: the paper's "transmission errors left out").
///
/// # Errors
/// Inconsistent data or an identification failure.
pub fn identify_kinematics(
    r: &HapticDevice,
    rows: &[LogRow],
    transmissions: Option<&TransmissionFit>,
) -> Result<(CalibrationProblem, Identified)> {
    let problem = kinematics_problem(r, rows, transmissions)?;
    let x0: Col<f64> = problem.initial_guess();
    let identified = identify(&problem, x0, &crate::fit::identify_config(None))
        .context("identifying kinematic deviations")?;
    Ok((problem, identified))
}

/// Step 2's problem: the cable distances of `rows` on `r`'s nominal chain, the joint readings
/// corrected by `transmissions` (raw when `None`), residuals divided by the cable encoder's σ_m.
fn kinematics_problem<R: Borrow<LogRow>>(
    r: &HapticDevice,
    rows: &[R],
    transmissions: Option<&TransmissionFit>,
) -> Result<CalibrationProblem> {
    let obs = Observations {
        rows: rows_of(rows)
            .map(|row| Row {
                q: transmissions
                    .map_or_else(|| row.q.clone(), |t| t.corrected(&row.q))
                    .into(),
                kind: RowKind::Distance {
                    distance_m: row.distance_m,
                },
            })
            .collect(),
        point_distances: Vec::new(),
        n_points: 0,
    };
    let weights = Weights {
        sigma_distance_m: r.noise.sigma_m_m,
        ..Weights::default()
    };
    Ok(CalibrationProblem::new(
        r.chain.clone(),
        obs,
        weights,
        None,
    )?)
}

/// Step 2's covariance with step 1's uncertainty propagated (the two-step estimator's
/// covariance, Murphy & Topel 1985, "Estimation and inference in two-step econometric models",
/// J. Bus. Econ. Stat. 3(4), eq. 15 without the cross term, the two steps using independent
/// sensors):
///
/// `C = C₂ + G·C₁·Gᵀ`, `G = (AᵀA)⁻¹·AᵀB`,
///
/// with `C₂` step 2's own covariance (`kin.covariance`, kept kinematic parameters), `C₁` the
/// block-diagonal covariance of step 1's transmission parameters (each capstan's and the
/// joint-4 polynomial's kept parameters), `A` (`n × k`, m per kinematic unit) the distance
/// residuals' Jacobian w.r.t. the kept kinematic parameters and `B` (`n × t`, m per
/// transmission unit) w.r.t. the transmission parameters through the corrected joint angles,
/// both at the two-step estimate. `G` is how a transmission error moves the kinematic
/// estimate; without the `G·C₁·Gᵀ` term the confidence intervals of step 2 are too narrow.
/// `C₂`'s residual-estimated σ² is first reduced by the transmission errors' expected share of
/// step 2's residual sum of squares, `tr(C₁·EᵀE)` with `E = B − A·G`, so they are not counted
/// twice.
///
/// Returns the `k × k` matrix in the order of `kin.covariance.free`.
///
/// # Errors
/// Missing ext columns, or an evaluation failure of the joint problem.
pub fn propagate_transmission_covariance(
    r: &HapticDevice,
    rows: &[LogRow],
    t: &TransmissionFit,
    kin: &Identified,
) -> Result<faer::Mat<f64>> {
    let s = Sensitivity::at(r, rows, t, kin)?;
    let nt = s.b.ncols();
    // C₁: block diagonal over the capstans and the polynomial.
    let mut c1 = faer::Mat::<f64>::zeros(nt, nt);
    let blocks = (t.capstans.iter().enumerate())
        .map(|(c, fit)| (6 * c, &fit.identified.covariance))
        .chain(std::iter::once((
            6 * t.capstans.len(),
            &t.poly_identified.covariance,
        )));
    for (off, cov) in blocks {
        for (a_i, &fi) in cov.free.iter().enumerate() {
            for (b_i, &fj) in cov.free.iter().enumerate() {
                c1[(off + fi, off + fj)] = cov.matrix[(a_i, b_i)];
            }
        }
    }
    let g = &s.g;
    // C₂'s σ was estimated from step 2's residuals, which also carry the transmission errors
    // (their part outside A's span, E = B − A·G, expected sum of squares tr(C₁·EᵀE)). That
    // part is counted by G·C₁·Gᵀ, so it is taken out of C₂'s σ² rather than counted twice.
    let e = &s.b - &s.a * g;
    let ete = e.transpose() * &e;
    let trans_ss: f64 = (0..nt)
        .flat_map(|i| (0..nt).map(move |j| (i, j)))
        .map(|(i, j)| c1[(i, j)] * ete[(j, i)])
        .sum();
    let noise_share = if s.rss_m2 > 0.0 {
        ((s.rss_m2 - trans_ss) / s.rss_m2).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let mut c = &kin.covariance.matrix * faer::Scale(noise_share);
    c += g * &c1 * g.transpose();
    Ok(c)
}

/// How step 2's estimate depends on step 1's transmission parameters, at the two-step estimate
/// (see [`propagate_transmission_covariance`]).
#[derive(Clone, Debug)]
pub struct Sensitivity {
    /// `A`: distance residuals w.r.t. the kept kinematic parameters (`kin.covariance.free`
    /// order), `n × k`, m per m or rad.
    pub a: faer::Mat<f64>,
    /// `B`: distance residuals w.r.t. the transmission parameters, in [`JointProblem`]'s order
    /// (capstans 1–3, 6 each, then the joint-4 Chebyshev coefficients), `n × t`.
    pub b: faer::Mat<f64>,
    /// `G = (AᵀA)⁻¹AᵀB`, `k × t`: a transmission error `δp` moves the kinematic estimate by
    /// `−G·δp` (to first order).
    pub g: faer::Mat<f64>,
    /// Step 2's residual sum of squares, m².
    pub rss_m2: f64,
}

impl Sensitivity {
    /// Evaluates `A`, `B`, `G` at the two-step estimate (`t`, `kin`) on the log `rows`.
    ///
    /// # Errors
    /// Missing ext columns, or an evaluation failure of the joint problem.
    pub fn at(
        r: &HapticDevice,
        rows: &[LogRow],
        t: &TransmissionFit,
        kin: &Identified,
    ) -> Result<Self> {
        use faer::linalg::solvers::SolveLstsq;
        use hapcal_identify::Problem;
        let problem = joint_problem(r, rows)?;
        let x = joint_start(&problem, t, kin);
        let (n, nt) = (rows.len(), problem.n_trans());
        let mut jac = faer::Mat::zeros(problem.n_residuals(), problem.layout().len());
        problem
            .jacobian(x.as_ref(), jac.as_mut())
            .map_err(|e| anyhow::anyhow!("joint problem Jacobian: {}", e.reason))?;
        let mut res = faer::Col::zeros(problem.n_residuals());
        problem
            .residuals(x.as_ref(), res.as_mut())
            .map_err(|e| anyhow::anyhow!("joint problem residuals: {}", e.reason))?;
        // Distance rows, back in metres.
        let d0 = problem.distance_offset();
        let scale = problem.sigma_distance_m;
        let free = &kin.covariance.free;
        let a = faer::Mat::from_fn(n, free.len(), |i, k| jac[(d0 + i, nt + free[k])] * scale);
        let b = faer::Mat::from_fn(n, nt, |i, j| jac[(d0 + i, j)] * scale);
        let g = a.qr().solve_lstsq(b.as_ref());
        let rss_m2 = (0..n).map(|i| (res[d0 + i] * scale).powi(2)).sum();
        Ok(Self { a, b, g, rss_m2 })
    }
}

/// Names of the kinematic layout (for reports).
pub fn layout_names(p: &CalibrationProblem) -> Vec<String> {
    (0..p.layout().len())
        .map(|i| p.layout().name(i).to_string())
        .collect()
}

/// Both steps in one least-squares problem (docs/design.md §3, "one joint identification") on the
/// log `rows` with ext1..ext4: [`JointProblem`] with capstans 1–3 and the joint-4 polynomial of
/// degree [`POLY_DEGREE`] on q4's range, the device's nominal chain, and its sensor noise
/// (σ_e rad, σ_m m). `x = [capstan 1–3 (6 each) | joint-4 Chebyshev (degree+1) | kinematic
/// deviations]`.
///
/// # Errors
/// Missing ext columns or capstans, or data the problem rejects.
pub fn joint_problem(r: &HapticDevice, rows: &[LogRow]) -> Result<JointProblem> {
    let capstans = (1..PARALLELOGRAM_JOINT)
        .map(|joint| Ok((joint, r.capstan(joint)?)))
        .collect::<Result<Vec<_>>>()?;
    let ext = (1..=PARALLELOGRAM_JOINT)
        .map(|j| ext(rows, j))
        .collect::<Result<Vec<_>>>()?;
    let (lo, hi) = r.device.joint_limits()[PARALLELOGRAM_JOINT - 1];
    let transmissions = JointTransmissions {
        capstans,
        poly_joint: PARALLELOGRAM_JOINT,
        poly_degree: POLY_DEGREE,
        poly_lo_rad: lo,
        poly_hi_rad: hi,
    };
    let data = JointData {
        q: rows.iter().map(|row| row.q.clone()).collect(),
        ext,
        distance_m: rows.iter().map(|row| row.distance_m).collect(),
    };
    Ok(JointProblem::new(
        r.chain.clone(),
        transmissions,
        data,
        r.noise.sigma_e_rad,
        r.noise.sigma_m_m,
    )?)
}

/// Start vector of `problem` from a two-step solution: step 1's transmissions `t`, step 2's
/// kinematic deviations `kin`.
pub fn joint_start(problem: &JointProblem, t: &TransmissionFit, kin: &Identified) -> Col<f64> {
    let caps: Vec<CapstanParams> = t.capstans.iter().map(|c| c.params).collect();
    problem.start(&caps, &t.poly.coeffs, kin.fit.x.as_ref())
}

/// Settings of the joint identification: transmission priors (phases anywhere), distal
/// parameters kept on exact ties, residuals already divided by their sigmas.
pub fn joint_config() -> IdentifyConfig {
    let mut cfg = transmission_config();
    cfg.rank.prior_m = 0.01;
    cfg.rank.tie_break = hapcal_identify::TieBreak::LaterInLayout;
    cfg
}

/// Joint identification, started from the two-step solution. Each residual group's sigma is
/// re-estimated from the first fit (joint-reading quantisation adds to the cable noise, so the
/// nominal σ_m understates it) and the problem refitted with those sigmas, so the covariance
/// is honest for both groups.
///
/// # Errors
/// An identification failure.
pub fn identify_jointly(
    r: &HapticDevice,
    rows: &[LogRow],
    t: &TransmissionFit,
    kin: &Identified,
) -> Result<(JointProblem, Identified)> {
    let mut problem = joint_problem(r, rows)?;
    let mut x0 = joint_start(&problem, t, kin);
    let mut first =
        identify(&problem, x0.clone(), &joint_config()).context("joint identification")?;
    // A kinematic parameter the joint problem prunes is held where it starts. When the two-step
    // solution chose the other member of a gauge pair (d0 instead of θ1), that start is not the
    // nominal: restart with it at 0, the gauge of the frames (docs/design.md §2, d0 = 0), so the
    // kept member carries the deviation.
    let nt = problem.n_trans();
    let stale: Vec<usize> = (first.identifiability.pruned.iter())
        .map(|p| p.index)
        .filter(|&i| i >= nt && x0[i] != 0.0)
        .collect();
    if !stale.is_empty() {
        for i in stale {
            x0[i] = 0.0;
        }
        first = identify(&problem, x0, &joint_config()).context("joint identification")?;
    }
    let n = rows.len();
    let res = &first.fit.residuals;
    let group_rms = |from: usize, to: usize| {
        ((from..to).map(|i| res[i] * res[i]).sum::<f64>() / (to - from) as f64).sqrt()
    };
    let n_kept_kin = first
        .identifiability
        .kept
        .iter()
        .filter(|&&i| i >= problem.n_trans())
        .count();
    let n_kept_trans = first.identifiability.kept.len() - n_kept_kin;
    let ext_scale = group_rms(0, PARALLELOGRAM_JOINT * n)
        * ((PARALLELOGRAM_JOINT * n) as f64 / (PARALLELOGRAM_JOINT * n - n_kept_trans) as f64)
            .sqrt();
    let dist_scale = group_rms(PARALLELOGRAM_JOINT * n, (PARALLELOGRAM_JOINT + 1) * n)
        * (n as f64 / (n - n_kept_kin.min(n - 1)) as f64).sqrt();
    problem.sigma_ext_rad *= ext_scale;
    problem.sigma_distance_m *= dist_scale;
    let second = identify(&problem, first.fit.x.clone(), &joint_config())
        .context("joint identification (reweighted)")?;
    Ok((problem, second))
}

/// The handle's mass (kg) the gravity compliance's torques need, from the device file's
/// `[handle]`.
///
/// # Errors
/// No `[handle]`, or a mass of 0: the handle's gravity torque, which a compliance multiplies,
/// is then unknown or zero, and the data cannot determine a compliance in rad/(N·m).
pub fn handle_mass_kg(device: &Device) -> Result<f64> {
    match device.handle {
        Some(h) if h.mass_kg > 0.0 => Ok(h.mass_kg),
        Some(_) => bail!(
            "--model compliance needs the handle's weight, and the device file's [handle] has \
             mass_kg = 0: without a gravity torque there is no compliance to fit"
        ),
        None => bail!(
            "--model compliance needs the handle's weight, and the device file has no [handle] \
             section: add `[handle]` with `mass_kg = …` (the handle's mass in kg, a point mass at \
             the end point)"
        ),
    }
}

/// The distance-log model ([`DistanceLogModel`], the diagnosis's) of the log `rows` on `r`'s
/// nominal chain, with the device's encoder noise ([`hapcal_sim::distance_log_noise`]) and
/// handle mass ([`handle_mass_kg`]), the reading quantisation in its σs, and the external
/// encoders of `ext_joints` (0-based) as rows.
///
/// # Errors
/// A device without a handle mass, rows that do not form a log, or a missing ext reading.
pub fn log_model<R: Borrow<LogRow>>(
    r: &HapticDevice,
    rows: &[R],
    ext_joints: Vec<usize>,
) -> Result<DistanceLogModel> {
    let log = DistanceLog::new(
        rows_of(rows).map(|row| row.q.clone()).collect(),
        rows_of(rows).map(|row| row.t_s).collect(),
        rows_of(rows).map(|row| row.distance_m).collect(),
        rows_of(rows).map(|row| row.ext.clone()).collect(),
    )?;
    let mut model = DistanceLogModel::new(
        r.chain.clone(),
        log,
        hapcal_sim::distance_log_noise(&r.device),
        handle_mass_kg(&r.device)?,
    )?;
    model.set_ext_joints(ext_joints)?;
    Ok(model)
}

/// A calibration with the handle's gravity compliance ([`identify_with_compliance`]).
#[derive(Clone, Debug)]
pub struct ComplianceFit {
    /// The problem it solved (the training log's model and the parameters' layout).
    pub problem: DistanceLogProblem,
    /// The identification: names, values, std, pruning.
    pub identified: Identified,
    /// The fitted state: transmissions (empty without ext columns), kinematic deviations and
    /// one `joint_compliance.j{k}` coefficient (rad/(N·m)) per joint.
    pub state: DistanceLogState,
}

/// The transmissions of a two-step solution `t` as the distance-log model's: the capstans of
/// joints 1–3 and the joint-4 polynomial.
fn log_transmissions(t: &TransmissionFit) -> Vec<LogTransmission> {
    let mut out: Vec<LogTransmission> = (t.capstans.iter())
        .map(|c| LogTransmission::Capstan {
            joint: c.joint - 1,
            capstan: c.capstan,
            params: c.params,
        })
        .collect();
    out.push(LogTransmission::Polynomial {
        joint: PARALLELOGRAM_JOINT - 1,
        poly: t.poly.clone(),
    });
    out
}

/// The haptic device's calibration with the handle's gravity compliance
/// (`hapcal calibrate --model compliance` on its logs): the transmissions (when `t` is given:
/// the capstans of joints 1–3 and the joint-4 polynomial, with the external-encoder rows),
/// the kinematic deviations and one compliance per joint, all in one least-squares problem
/// over the diagnosis's measurement model ([`DistanceLogModel`] with the terms
/// [`EffectTerm::handle_compliance`]: joint `j`'s angle gains `c_j·τ_j(q)`, τ the handle's
/// gravity torque, [`hapcal_problems::handle_gravity_torques_nm`]), solved by
/// `hapcal-identify` from the two-step solution (`t`, `kin`) with the compliances at 0. Every
/// joint gets a candidate, as in the diagnosis; a joint the handle's weight does not load
/// (joint 1, whose axis is vertical) has a zero column and is pruned. σ is estimated from the
/// residuals (the rows are already divided by the encoder noise, quantisation included, so it
/// is ≈ 1 at the noise floor).
///
/// A parameter the identification prunes is held where it starts and written nowhere, i.e.
/// at its nominal value; when it starts away from 0 (the two-step solution chose the other
/// member of a gauge pair) the problem is refitted with it at 0, so the kept parameters carry
/// the whole correction.
///
/// # Errors
/// A device without a handle mass ([`handle_mass_kg`]), a log the model refuses, or a failed
/// identification.
pub fn identify_with_compliance(
    r: &HapticDevice,
    rows: &[LogRow],
    t: Option<&TransmissionFit>,
    kin: &Identified,
) -> Result<ComplianceFit> {
    let transmissions = t.map(log_transmissions).unwrap_or_default();
    let ext_joints = transmissions.iter().map(LogTransmission::joint).collect();
    let model = log_model(r, rows, ext_joints)?;
    let mut start = model.initial_state(transmissions);
    start.x_kin = kin.fit.x.iter().copied().collect();
    start.terms = (0..r.chain.n_joints())
        .map(|j| (EffectTerm::handle_compliance(j), 0.0))
        .collect();
    let problem = DistanceLogProblem::new(model, &start)?;
    let mut cfg = if t.is_some() {
        joint_config()
    } else {
        crate::fit::identify_config(None)
    };
    cfg.sigma = None;
    let mut x0 = problem.x_of(&start);
    let mut identified =
        identify(&problem, x0.clone(), &cfg).context("identification with the compliance")?;
    let stale: Vec<usize> = (identified.identifiability.pruned.iter())
        .map(|p| p.index)
        .filter(|&i| x0[i] != 0.0)
        .collect();
    if !stale.is_empty() {
        for i in stale {
            x0[i] = 0.0;
        }
        identified = identify(&problem, x0, &cfg).context("identification with the compliance")?;
    }
    let state = problem.state(identified.fit.x.as_ref());
    Ok(ComplianceFit {
        problem,
        identified,
        state,
    })
}

/// The unit of parameter `name` of a [`ComplianceFit`] as reports and device files write it:
/// [`HANDLE_COMPLIANCE_UNIT`] for a compliance, else the layout's (`m`, `rad`, `1`).
fn compliance_fit_unit(fit: &ComplianceFit, i: usize) -> &'static str {
    let name = &fit.identified.layout.spec(i).name;
    let is_compliance = (fit.state.terms.iter()).any(|(term, _)| {
        &term.name == name && matches!(term.kind, EffectTermKind::Compliance { .. })
    });
    if is_compliance {
        HANDLE_COMPLIANCE_UNIT
    } else {
        fit.identified.layout.spec(i).unit.symbol()
    }
}

/// The kept parameters of `fit` with their std and unit (compliances in rad/(N·m)), in layout
/// order: what the report lists and the device file records.
pub fn compliance_values(fit: &ComplianceFit) -> Vec<CalibratedValue> {
    let id = &fit.identified;
    (id.covariance.free.iter().zip(id.covariance.std().iter()))
        .map(|(&i, &std)| CalibratedValue {
            name: id.layout.spec(i).name.clone(),
            value: id.fit.x[i],
            std,
            unit: compliance_fit_unit(fit, i).to_owned(),
        })
        .collect()
}

/// Distance residuals (model − measured, m, one per row) of the log `rows` under the fitted
/// state of `fit`: the readings through its transmissions and compliances, the chain at its
/// deviations (the same model as the fit; ext columns are not needed).
///
/// # Errors
/// Rows that do not form a log of the device.
pub fn compliance_distance_residuals_m(
    r: &HapticDevice,
    fit: &ComplianceFit,
    rows: &[LogRow],
) -> Result<Vec<f64>> {
    state_distance_residuals_m(r, &fit.state, rows)
}

/// Distance residuals (model − measured, m, one per row) of `rows` under the distance-log
/// state `state` on `r`'s nominal chain.
fn state_distance_residuals_m<R: Borrow<LogRow>>(
    r: &HapticDevice,
    state: &DistanceLogState,
    rows: &[R],
) -> Result<Vec<f64>> {
    let model = log_model(r, rows, Vec::new())?;
    Ok(model.distance_residuals_m(state)?)
}

/// The distance-log state a calibrated haptic device file carries, to evaluate with its
/// (calibrated) chain: the transmissions of `[calibration.values]` (`capstan{j}.*` on each
/// `[[capstan]]` joint, missing ones 0; `joint{j}.cheb*` as the polynomial on joint `j`'s
/// range, when any), zero kinematic deviations (the D-H rows already hold them) and one
/// [`EffectTerm::handle_compliance`] per `joint_compliance.j{k}` value (rad/(N·m)). With
/// [`log_model`] on the file's chain it reproduces the predictions of the fit that wrote the
/// file ([`identify_with_compliance`]); a file without such values gives ideal transmissions
/// where it names none.
///
/// # Errors
/// As [`haptic_drives`] (a value on a joint the device does not have, a gap in the
/// Chebyshev indices, a robot's value), or a capstan or polynomial the library refuses.
pub fn calibrated_log_state(device: &Device) -> Result<DistanceLogState> {
    let chain = device.chain()?;
    let HapticDrives {
        drives,
        handle_compliance,
    } = haptic_drives(
        &device.capstans,
        chain.n_joints(),
        device.dh.len(),
        device.calibration.as_ref(),
    )?;
    let limits = device.joint_limits();
    let mut transmissions = Vec::new();
    for (joint, drive) in drives.into_iter().enumerate() {
        transmissions.push(match drive {
            JointDrive::Direct => continue,
            JointDrive::Capstan {
                ratio,
                drum_distance_m,
                params,
            } => LogTransmission::Capstan {
                joint,
                capstan: Capstan::try_new(ratio, drum_distance_m)?,
                params,
            },
            JointDrive::Polynomial { coeffs, .. } => {
                let (lo, hi) = limits[joint];
                LogTransmission::Polynomial {
                    joint,
                    poly: Chebyshev::try_new(lo, hi, coeffs)?,
                }
            }
        });
    }
    let terms = (handle_compliance.into_iter().enumerate())
        .filter(|&(_, k)| k != 0.0)
        .map(|(joint, k)| (EffectTerm::handle_compliance(joint), k))
        .collect();
    Ok(DistanceLogState {
        transmissions,
        x_kin: vec![0.0; chain.n_params()],
        terms,
    })
}

/// The file contract's name of a haptic rung (`--model geometric`, `transmissions`,
/// `compliance`); `None` for a model that is not a haptic rung.
pub fn model_name(model: ModelName) -> Option<ModelName> {
    use ModelName as M;
    matches!(model, M::Geometric | M::Transmissions | M::Compliance).then_some(model)
}

/// The region a haptic calibration was fitted on: each joint's range of readings over the
/// training rows `rows` (rad, named after the device's `[[joint]]`s), and the row count.
pub fn training_region(r: &HapticDevice, rows: &[LogRow]) -> Region {
    let ranges = crate::measured::reading_ranges(
        rows.iter().map(|row| row.q.as_slice()),
        r.device.joints.len(),
    );
    let joints = (r.device.joints.iter().zip(ranges))
        .map(|(spec, (min, max))| JointRange {
            name: spec.name.clone(),
            min,
            max,
            unit: "rad".to_owned(),
        })
        .collect();
    Region {
        rows: rows.len(),
        joints,
    }
}

/// The load the handle compliances were identified under: the handle's mass
/// ([`handle_mass_kg`]) at the end point, gravity [`hapcal_problems::GRAVITY_M_S2`] along
/// minus the axis of joint 1 at the deviations `x_kin` (the direction
/// [`hapcal_problems::handle_gravity_torques_nm`] takes, in the chain's base frame), at the
/// readings' angles (no equilibrium).
///
/// # Errors
/// A device without a handle mass; `x_kin` not of the chain's length.
pub fn handle_torque(r: &HapticDevice, x_kin: &[f64]) -> Result<Torque> {
    if x_kin.len() != r.chain.n_params() {
        bail!(
            "{} kinematic deviations for a chain of {} parameters",
            x_kin.len(),
            r.chain.n_params()
        );
    }
    let jac = r
        .chain
        .geometric_jacobian(x_kin, &vec![0.0; r.chain.n_joints()]);
    if jac.ncols() == 0 {
        bail!("the chain has no joint");
    }
    Ok(Torque {
        source: TorqueSource::HandleMass,
        gravity_direction: [-jac[(3, 0)], -jac[(4, 0)], -jac[(5, 0)]],
        gravity_m_s2: hapcal_problems::GRAVITY_M_S2,
        equilibrium: false,
        tips: Vec::new(),
        masses: Vec::new(),
        handle_mass_kg: Some(handle_mass_kg(&r.device)?),
    })
}

/// The covariance of the identifications `ids`, block diagonal (each one's covariance over
/// its free parameters, in order; no covariance between them): the record's `[covariance]`.
pub fn block_covariance(ids: &[&hapcal_identify::Covariance]) -> Covariance {
    let names: Vec<String> = ids.iter().flat_map(|c| c.names.iter().cloned()).collect();
    let n = names.len();
    let mut matrix = vec![0.0; n * n];
    let mut off = 0;
    for c in ids {
        let k = c.names.len();
        for a in 0..k {
            for b in 0..k {
                matrix[(off + a) * n + off + b] = c.matrix[(a, b)];
            }
        }
        off += k;
    }
    Covariance::from_matrix(names, &matrix)
}

/// The calibration record (schema 1) of a haptic calibration on the training rows `rows`:
/// the model's name, `values`, their `covariance`, the training region
/// ([`training_region`]), the handle's load `torque` (for the compliance model) and `notes`.
pub fn haptic_record(
    r: &HapticDevice,
    rows: &[LogRow],
    model: ModelName,
    values: Vec<CalibratedValue>,
    covariance: Option<Covariance>,
    torque: Option<Torque>,
    notes: String,
) -> Calibration {
    Calibration {
        schema_version: Some(hapcal_contract::SCHEMA_VERSION),
        model: Some(model),
        notes: Some(notes),
        torque,
        region: Some(training_region(r, rows)),
        values,
        covariance,
        ..Calibration::default()
    }
}

/// The calibrated device file of `--model compliance` on the training rows `rows`: `r`'s
/// nominal device with the kept kinematic deviations of `fit` applied to its D-H rows, and
/// `[calibration]` the full record ([`Device::with_record`]): model `compliance`, every kept
/// parameter of `fit` ([`compliance_values`]: transmissions, kinematic deviations,
/// `joint_compliance.j{k}` in rad/(N·m)) with its σ, their covariance (the identification's,
/// over the kept parameters), the handle's load ([`handle_torque`] at the fitted
/// deviations) and the training region.
///
/// # Errors
/// A device without a handle mass, or a value the device file rejects.
pub fn compliance_device(
    r: &HapticDevice,
    rows: &[LogRow],
    fit: &ComplianceFit,
    notes: String,
) -> Result<Device> {
    let cov = &fit.identified.covariance;
    let record = haptic_record(
        r,
        rows,
        ModelName::Compliance,
        compliance_values(fit),
        Some(block_covariance(&[cov])),
        Some(handle_torque(r, &fit.state.x_kin)?),
        notes,
    );
    Ok(r.device.with_record(record)?)
}

/// The calibrated device file of the paper's pipeline: `r`'s nominal device with the kept
/// kinematic deviations of `kin` applied to its D-H rows ([`Device::with_calibration`]) and
/// `[calibration.values]` holding those deviations (m, rad) and every identified transmission
/// parameter of `t` (capstans 1–3: `capstan{j}.c` rad, `.re` 1, `.r_o` m, `.beta_o` rad,
/// `.r_i` m, `.beta_i` rad; joint 4: `joint4.cheb0..10`, rad, Chebyshev basis on q4's range),
/// each with its standard deviation. Pruned (unidentifiable) parameters are left out, i.e. at
/// their nominal value.
///
/// # Errors
/// A value the device file rejects (non-finite, wrong unit).
pub fn calibrated_device(
    r: &HapticDevice,
    t: &TransmissionFit,
    kin: &Identified,
    notes: String,
) -> Result<Device> {
    let mut values = Vec::new();
    let mut push_kept = |id: &Identified| {
        for &i in &id.identifiability.kept {
            let spec = id.layout.spec(i);
            values.push(CalibratedValue {
                name: spec.name.clone(),
                value: id.fit.x[i],
                std: id.std(&spec.name).unwrap_or(0.0),
                unit: spec.unit.symbol().to_owned(),
            });
        }
    };
    for c in &t.capstans {
        push_kept(&c.identified);
    }
    push_kept(&t.poly_identified);
    push_kept(kin);
    let meta = CalibrationMeta {
        date: None,
        data_hash: None,
        notes: Some(notes),
    };
    Ok(r.device.with_calibration(&values, meta)?)
}

/// Number of distinct joint-reading vectors among `rows`, or of distinct readings of joint
/// `joint` (1-based) alone (bit patterns, −0 counted as +0).
pub fn distinct_configurations(rows: &[LogRow], joint: Option<usize>) -> usize {
    let mut seen = std::collections::HashSet::new();
    for row in rows {
        let q = match joint {
            Some(j) => row.q.get(j - 1..j).unwrap_or(&[]),
            None => &row.q[..],
        };
        seen.insert(q.iter().map(|v| (v + 0.0).to_bits()).collect::<Vec<u64>>());
    }
    seen.len()
}

/// `Err` unless the rows an identification used hold more distinct configurations than the
/// parameters it kept: for each capstan and the joint-4 polynomial (step 1) the distinct
/// readings of its joint, for the kinematics (step 2) the distinct joint-reading vectors.
///
/// A copied row adds a residual but no information: 200 copies of one pose fit one parameter
/// per step exactly, and the residual-based σ (residuals / (rows − kept)) comes out 0, a
/// confident report of nothing. Each kept parameter needs a configuration of its own, and σ
/// one more (a degree of freedom).
///
/// # Errors
/// Naming the step, both counts and the number of rows when `distinct ≤ kept`.
pub fn check_distinct_configurations(
    rows: &[LogRow],
    transmissions: Option<&TransmissionFit>,
    kin: &Identified,
) -> Result<()> {
    let mut steps: Vec<(String, Option<usize>, usize)> = Vec::new();
    if let Some(t) = transmissions {
        for c in &t.capstans {
            let kept = c.identified.identifiability.kept.len();
            steps.push((format!("capstan {}", c.joint), Some(c.joint), kept));
        }
        let kept = t.poly_identified.identifiability.kept.len();
        steps.push((
            format!("the joint-{PARALLELOGRAM_JOINT} polynomial"),
            Some(PARALLELOGRAM_JOINT),
            kept,
        ));
    }
    steps.push((
        "the kinematics".to_owned(),
        None,
        kin.identifiability.kept.len(),
    ));
    for (what, joint, n_kept) in steps {
        let n_distinct = distinct_configurations(rows, joint);
        if n_distinct <= n_kept {
            let of = joint.map_or_else(
                || "distinct joint configurations".to_owned(),
                |j| format!("distinct readings of joint {j}"),
            );
            bail!(
                "{what}: the training logs hold {n_distinct} {of} (in {} rows) for {n_kept} kept \
                 parameters: at least {} are needed (one per parameter and one to estimate σ); \
                 repeated rows add no information, measure more distinct poses",
                rows.len(),
                n_kept + 1
            );
        }
    }
    Ok(())
}

/// The transmissions and kinematics of a joint identification, in the two steps' types (so the
/// report and the device file are written the same way): each capstan's and the polynomial's
/// parameters take the joint estimate; their covariances stay step 1's (the joint covariance of
/// the kinematic parameters is `joint`'s, through `kin`'s layout).
fn split_joint(
    problem: &JointProblem,
    joint: &Identified,
    mut t: TransmissionFit,
    mut kin: Identified,
) -> Result<(TransmissionFit, Identified)> {
    let nt = problem.n_trans();
    let x = &joint.fit.x;
    let mut offset = 0;
    for c in &mut t.capstans {
        let n = c.identified.fit.x.nrows();
        for k in 0..n {
            c.identified.fit.x[k] = x[offset + k];
        }
        c.params = CapstanProblem::params(c.identified.fit.x.as_ref());
        offset += n;
    }
    let n_poly = t.poly_identified.fit.x.nrows();
    for k in 0..n_poly {
        t.poly_identified.fit.x[k] = x[offset + k];
    }
    t.poly = Chebyshev::try_new(
        t.poly.lo,
        t.poly.hi,
        (0..n_poly).map(|k| x[offset + k]).collect(),
    )?;
    offset += n_poly;
    if offset != nt {
        bail!("joint problem layout: {offset} transmission parameters, expected {nt}");
    }
    for k in 0..kin.fit.x.nrows() {
        kin.fit.x[k] = x[nt + k];
    }
    Ok((t, kin))
}
