//! The paper's two-step calibration of a capstan-driven haptic device (Baser & Konukseven,
//! Fig. 6), on a measured log and nothing else: step 1 identifies each transmission from its
//! external encoder (capstan eq. 1, the parallelogram's polynomial), step 2 corrects the joint
//! readings and identifies the kinematic deviations from the cable distances; or both at once
//! ([`identify_jointly`]). [`calibrated_device`] writes the result as a device file.

use std::borrow::Borrow;

use anyhow::{Context, Result, bail};
use faer::Col;
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
                q: transmissions.map_or_else(|| row.q.clone(), |t| t.corrected(&row.q)),
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
/// A value of an unknown capstan field, a wrong unit, a joint the device does not have, or a
/// gap in the Chebyshev indices.
pub fn calibrated_log_state(device: &Device) -> Result<DistanceLogState> {
    let chain = device.chain()?;
    let values = (device.calibration.as_ref()).map_or(&[][..], |c| &c.values[..]);
    let n_joints = chain.n_joints();
    let mut capstans: Vec<(usize, Capstan, CapstanParams)> = (device.capstans.iter())
        .map(|c| {
            Ok((
                c.joint,
                Capstan::try_new(c.ratio, c.drum_distance_m)?,
                CapstanParams::default(),
            ))
        })
        .collect::<Result<_>>()?;
    let mut cheb: Vec<(usize, usize, f64)> = Vec::new();
    let mut terms = Vec::new();
    for v in values {
        let unit = |expected: &str| {
            if v.unit == expected {
                Ok(())
            } else {
                Err(anyhow::anyhow!(
                    "[calibration.values] {}: unit is {:?}, expected {expected:?}",
                    v.name,
                    v.unit
                ))
            }
        };
        let Some((element, field)) = v.name.split_once('.') else {
            continue; // a kinematic deviation, already in the rows
        };
        let joint_of = |prefix: &str| {
            (element.strip_prefix(prefix))
                .and_then(|d| d.parse::<usize>().ok())
                .filter(|&j| (1..=n_joints).contains(&j))
        };
        if element == "joint_compliance" {
            let joint = (field.strip_prefix('j'))
                .and_then(|d| d.parse::<usize>().ok())
                .filter(|&j| (1..=n_joints).contains(&j))
                .with_context(|| format!("[calibration.values] {}: no such joint", v.name))?;
            unit(HANDLE_COMPLIANCE_UNIT)?;
            terms.push((EffectTerm::handle_compliance(joint - 1), v.value));
        } else if element.starts_with("capstan") {
            let joint = joint_of("capstan")
                .with_context(|| format!("[calibration.values] {}: no such joint", v.name))?;
            let (_, _, p) = (capstans.iter_mut())
                .find(|(j, _, _)| *j == joint)
                .with_context(|| {
                    format!(
                        "[calibration.values] {}: no capstan on joint {joint}",
                        v.name
                    )
                })?;
            let Some((target, u)) = p.field_mut(field) else {
                bail!(
                    "[calibration.values] {}: unknown capstan parameter {field:?}",
                    v.name
                );
            };
            unit(u)?;
            *target = v.value;
        } else if let Some(joint) = joint_of("joint") {
            let k = (field.strip_prefix("cheb"))
                .and_then(|d| d.parse::<usize>().ok())
                .with_context(|| {
                    format!(
                        "[calibration.values] {}: expected joint{{j}}.cheb{{k}}",
                        v.name
                    )
                })?;
            unit("rad")?;
            cheb.push((joint, k, v.value));
        }
    }
    let mut transmissions: Vec<LogTransmission> = (capstans.into_iter())
        .filter(|(j, _, _)| !cheb.iter().any(|(pj, _, _)| pj == j))
        .map(|(joint, capstan, params)| LogTransmission::Capstan {
            joint: joint - 1,
            capstan,
            params,
        })
        .collect();
    let limits = device.joint_limits();
    let mut poly_joints: Vec<usize> = cheb.iter().map(|(j, _, _)| *j).collect();
    poly_joints.sort_unstable();
    poly_joints.dedup();
    for joint in poly_joints {
        let n = cheb
            .iter()
            .filter(|(j, _, _)| *j == joint)
            .map(|(_, k, _)| k + 1)
            .max()
            .unwrap_or(0);
        let mut coeffs = vec![None; n];
        for (_, k, c) in cheb.iter().filter(|(j, _, _)| *j == joint) {
            coeffs[*k] = Some(*c);
        }
        let coeffs = coeffs
            .into_iter()
            .enumerate()
            .map(|(k, c)| c.with_context(|| format!("joint{joint}.cheb{k} is missing")))
            .collect::<Result<Vec<f64>>>()?;
        let (lo, hi) = limits[joint - 1];
        transmissions.push(LogTransmission::Polynomial {
            joint: joint - 1,
            poly: Chebyshev::try_new(lo, hi, coeffs)?,
        });
    }
    transmissions.sort_by_key(LogTransmission::joint);
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
fn fold_lm(cfg: IdentifyConfig) -> hapcal_identify::LmConfig {
    hapcal_identify::LmConfig {
        ftol: crate::fit::FOLD_TOLERANCE,
        xtol: crate::fit::FOLD_TOLERANCE,
        ..cfg.lm
    }
}

/// The kinematic deviations refitted on `rows` (readings corrected by `t`) from `warm`, over
/// its kept parameters.
fn refit_kinematics<R: Borrow<LogRow>>(
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
fn refit_transmissions<R: Borrow<LogRow>>(
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
fn kinematic_residuals_m<R: Borrow<LogRow> + Sync>(
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
fn report_values(parameters: &[crate::report::ParamReport]) -> Vec<CalibratedValue> {
    (parameters.iter())
        .map(|p| CalibratedValue {
            name: p.name.clone(),
            value: p.value,
            std: p.std,
            unit: p.unit.to_owned(),
        })
        .collect()
}

/// The paper's calibration of a haptic device from its own logs, as `hapcal calibrate` runs it
/// on a device file with transmissions: step 1 (each capstan's eq. 1 and the parallelogram's
/// polynomial from the external encoders `ext1..ext4`) and step 2 (kinematic deviations from
/// the cable distances of the corrected readings), or both in one problem when `plan.joint`
/// ([`identify_jointly`]). `--model auto` chooses among geometric, transmissions (when every
/// training log has the external-encoder columns) and compliance (when the device file has a
/// handle mass) by repeated blocked cross-validation with `plan.folds` folds
/// ([`cross_validate_rungs`], [`crate::model::climb`]) and reports every rung's held-out
/// figures in `cross_validation`; an explicit model is fitted without it. A log without
/// external-encoder columns cannot give the transmissions, with a warning. `--model compliance` adds the handle's gravity compliance of each joint,
/// fitted with the transmissions and the kinematics in one problem
/// ([`identify_with_compliance`]; `plan.joint` changes nothing there), the compliances
/// reported and written in rad/(N·m). Figures: distance RMS of every training and test log,
/// nominal model on the raw readings against the calibrated model (with its compliances) on
/// the corrected ones.
///
/// # Errors
/// A device that is not the paper's kind ([`HapticDevice::new`]), `--model compliance` on a
/// device file without a handle mass ([`handle_mass_kg`]), too few rows, no more distinct
/// joint configurations than kept parameters ([`check_distinct_configurations`]), or a failed
/// identification.
pub fn calibrate_logs(
    plan: &crate::inputs::Plan,
    device: Device,
    mut train: Vec<NamedLog>,
    test: Vec<NamedLog>,
    start: std::time::Instant,
) -> Result<crate::report::Outcome> {
    let haptic = HapticDevice::new(device)?;
    let mut warnings: Vec<String> = (train.iter().chain(&test))
        .flat_map(|log| log.warnings.iter().cloned())
        .collect();
    let training = LogTraining::of(plan, &haptic, &mut train)?;
    // Gross errors bounded by the Huber loss: every fit below sees the winsorized distances;
    // the figures are of the logs as measured.
    let Winsorized {
        rows,
        downweighted,
        judge,
        transmissions: step1,
    } = winsorize(
        &haptic,
        &train,
        &training.lengths,
        &training.raw,
        training.has_ext,
    );
    let rows: &[LogRow] = rows.as_deref().unwrap_or(&training.raw);
    warnings.extend(crate::robust::bounded_warning(
        &downweighted,
        "log rows",
        &judge.to_string(),
    ));
    let (chosen, mut cross_validation, cross_validated_rows) = ladder_of_logs(
        plan,
        &haptic,
        rows,
        &training,
        step1.as_ref(),
        &mut warnings,
    )?;
    let step1 = Step1::of(training.has_ext, step1.as_ref());
    let fit = match chosen {
        ModelName::Compliance => fit_compliance(&haptic, rows, step1, &mut warnings)?,
        m if m != ModelName::Geometric && training.has_ext => {
            fit_transmissions(plan, &haptic, rows, step1)?
        }
        _ => fit_geometric(&haptic, rows, training.has_ext, &mut warnings)?,
    };
    check_distinct_configurations(rows, fit.transmissions.as_ref(), &fit.kin)?;
    if let Some(cv) = cross_validation.iter_mut().find(|cv| cv.model == fit.model) {
        cv.n_kept = fit.parameters.len();
    }
    let x_kin: Vec<f64> = match &fit.compliance {
        Some(c) => c.state.x_kin.clone(),
        None => fit.kin.fit.x.iter().copied().collect(),
    };
    let train_logs = (train.iter().zip(crate::fit::log_ranges(&training.lengths)))
        .map(|(log, range)| (SetRole::Train, &log.name, &training.raw[range]));
    let test_logs = (test.iter()).map(|log| (SetRole::Test, &log.name, &log.rows[..]));
    let placements = log_placements(&haptic, &fit, &x_kin, train_logs.chain(test_logs))?;
    for warning in worse_logs(&placements) {
        warnings.insert(0, warning);
    }
    let choice = LogsChoice {
        cross_validation,
        cross_validated_rows,
        std_scale: training.copies.1,
    };
    let findings = LogsFindings {
        placements,
        downweighted,
        warnings,
    };
    let report = logs_report(plan, &haptic, &fit, choice, findings, start);
    let kin_model = hapcal_problems::CalibratedModel {
        x_kin,
        ..hapcal_problems::CalibratedModel::nominal(haptic.chain.clone())
    };
    Ok(crate::report::Outcome {
        report,
        device: haptic.device.clone(),
        device_path: plan.device.clone(),
        model: kin_model,
        calibrated: Some(fit.calibrated),
        record: None,
    })
}

/// The training rows of a haptic calibration, one log after the other, moved out of their
/// logs: a long log is held once as measured (and once more where the Huber loss bounds a row).
struct LogTraining {
    /// Rows of each training log, in order.
    lengths: Vec<usize>,
    /// Every training row as measured.
    raw: Vec<LogRow>,
    /// Whether every training row has the external encoders the transmissions need.
    has_ext: bool,
    /// Rows repeating an earlier row of their log, and the factor √(rows / distinct rows) by
    /// which the fit's covariance understates the compliances' σ.
    copies: (usize, f64),
}

impl LogTraining {
    /// The load stage of [`calibrate_logs`]: takes the rows out of `train`.
    ///
    /// # Errors
    /// No training row; `--model transmissions` on logs without the external encoders.
    fn of(
        plan: &crate::inputs::Plan,
        haptic: &HapticDevice,
        train: &mut [NamedLog],
    ) -> Result<Self> {
        let lengths: Vec<usize> = train.iter().map(|log| log.rows.len()).collect();
        let raw: Vec<LogRow> = (train.iter_mut())
            .flat_map(|log| std::mem::take(&mut log.rows))
            .collect();
        if raw.is_empty() {
            bail!("the training logs have no row");
        }
        let has_ext = (1..=PARALLELOGRAM_JOINT).all(|j| {
            let needed =
                j == PARALLELOGRAM_JOINT || haptic.device.capstans.iter().any(|c| c.joint == j);
            !needed
                || raw
                    .iter()
                    .all(|r| r.ext.get(j - 1).copied().flatten().is_some())
        });
        if plan.model == ModelChoice::Model(ModelName::Transmissions) && !has_ext {
            bail!(
                "--model transmissions needs the external-encoder columns (ext1..ext{PARALLELOGRAM_JOINT}) \
                 in every training log; ask for --model geometric (or auto) on logs without them"
            );
        }
        // A row that repeats an earlier row of its log adds no information, but the fit's
        // covariance counts it: the compliances' σ, judged for plausibility, grows back by
        // √(rows / distinct rows).
        let n_copies: usize = (crate::fit::log_ranges(&lengths))
            .map(|range| crate::fit::originals(raw[range].iter().map(LogRow::repeat_key)))
            .map(|o| crate::fit::n_copies(&o))
            .sum();
        let std_scale =
            (raw.len() as f64 / raw.len().saturating_sub(n_copies).max(1) as f64).sqrt();
        Ok(Self {
            lengths,
            raw,
            has_ext,
            copies: (n_copies, std_scale),
        })
    }
}

/// The ladder stage of [`calibrate_logs`]: the plan's model, or with `--model auto` the ladder
/// geometric → transmissions → compliance, each rung the logs and the device carry, climbed by
/// the rule of every workflow ([`crate::model::climb`]) on the rungs' held-out errors. A long
/// log's model is chosen on a sample spread over it: the choice needs far fewer rows than the
/// parameters' precision (docs/engine.md, "Long logs"). Returns the model, the rungs' reports
/// and the rows judged when a sample was.
///
/// # Errors
/// A rung's cross-validation fit that fails.
fn ladder_of_logs(
    plan: &crate::inputs::Plan,
    haptic: &HapticDevice,
    rows: &[LogRow],
    training: &LogTraining,
    step1: Option<&TransmissionFit>,
    warnings: &mut Vec<String>,
) -> Result<(ModelName, Vec<crate::report::CvReport>, Option<usize>)> {
    if let ModelChoice::Model(chosen) = plan.model {
        return Ok((chosen, Vec::new(), None));
    }
    let sample = crate::fit::ladder_sample(&training.lengths, plan.ladder_rows);
    let (chosen, reports) = match &sample {
        Some(sample) => {
            let rows: Vec<LogRow> = sample.rows.iter().map(|&i| rows[i].clone()).collect();
            choose_model(
                haptic,
                &rows,
                &sample.lengths,
                Step1::of(training.has_ext, None),
                plan.folds,
                training.copies,
                warnings,
            )?
        }
        None => choose_model(
            haptic,
            rows,
            &training.lengths,
            Step1::of(training.has_ext, step1),
            plan.folds,
            training.copies,
            warnings,
        )?,
    };
    Ok((chosen, reports, sample.map(|s| s.rows.len())))
}

/// Step 1 on every row: the fit the Huber loss's judge already made, or a new one. Step 1
/// reads the joint and external encoders, never the distances the Huber loss bounds: its fit on
/// the logs as measured is its fit on the winsorized rows.
///
/// # Errors
/// A failed identification of the transmissions.
fn transmissions_of(
    haptic: &HapticDevice,
    rows: &[LogRow],
    step1: Step1<'_>,
) -> Result<TransmissionFit> {
    match step1 {
        Step1::Fitted(t) => Ok(t.clone()),
        _ => identify_transmissions(haptic, rows).context("step 1 (transmissions)"),
    }
}

/// The kept parameters of one identification as the report lists them.
fn kept_parameters(id: &Identified) -> Vec<ParamReport> {
    (id.covariance.free.iter().zip(id.covariance.std().iter()))
        .map(|(&i, &std)| {
            let spec = id.layout.spec(i);
            ParamReport {
                name: spec.name.clone(),
                value: id.fit.x[i],
                std,
                unit: spec.unit.symbol(),
            }
        })
        .collect()
}

/// The warning of logs without the external encoders.
fn no_ext_warning() -> String {
    format!(
        "the training logs have no external-encoder columns (ext1..ext{PARALLELOGRAM_JOINT}): \
         the transmissions are not identified and the kinematic deviations absorb their errors \
         (the paper's \"transmission errors left out\"); record the external encoders to \
         calibrate the transmissions"
    )
}

/// The final fit of a haptic calibration: what the report, the placements and the written
/// device file read.
struct LogFit {
    /// Step 1's transmissions (`None` for kinematics alone).
    transmissions: Option<TransmissionFit>,
    /// Step 2's identification (the compliance fit's joint problem with the compliance model).
    kin: Identified,
    /// The model fitted.
    model: ModelName,
    /// The device file of the calibration.
    calibrated: Device,
    /// The compliance fit (`--model compliance`).
    compliance: Option<ComplianceFit>,
    /// The report's parameters, in the order of the record.
    parameters: Vec<ParamReport>,
}

/// The final fit of `--model compliance`: both steps as the start, then the transmissions
/// (when the logs have the ext columns), the kinematics and the handle's compliances in one
/// problem.
///
/// # Errors
/// A device file without a handle mass, or a failed identification.
fn fit_compliance(
    haptic: &HapticDevice,
    rows: &[LogRow],
    step1: Step1<'_>,
    warnings: &mut Vec<String>,
) -> Result<LogFit> {
    handle_mass_kg(&haptic.device)?;
    let t = if matches!(step1, Step1::NoEncoders) {
        warnings.push(no_ext_warning());
        None
    } else {
        Some(transmissions_of(haptic, rows, step1)?)
    };
    let (_, kin) = identify_kinematics(haptic, rows, t.as_ref()).context("step 2 (kinematics)")?;
    let fit = identify_with_compliance(haptic, rows, t.as_ref(), &kin)?;
    let values = compliance_values(&fit);
    let parameters = (values.iter().zip(&fit.identified.covariance.free))
        .map(|(v, &i)| ParamReport {
            name: v.name.clone(),
            value: v.value,
            std: v.std,
            unit: compliance_fit_unit(&fit, i),
        })
        .collect();
    let notes = format!(
        "{} with the handle's gravity compliance (joint_compliance.j*, rad/(N·m), a joint \
         angle gains c·τ, τ the gravity torque of the [handle] mass) on {} rows; written by \
         `hapcal calibrate --model compliance`",
        if t.is_some() {
            "transmissions, kinematic deviations"
        } else {
            "kinematic deviations"
        },
        rows.len()
    );
    let calibrated = compliance_device(haptic, rows, &fit, notes)?;
    Ok(LogFit {
        transmissions: t,
        kin: fit.identified.clone(),
        model: ModelName::Compliance,
        calibrated,
        compliance: Some(fit),
        parameters,
    })
}

/// The final fit of the transmissions model: the paper's two steps, or both in one problem
/// when `plan.joint` (whose covariance carries both steps' uncertainty; the two steps' sensors
/// are independent, so otherwise each step's own covariance is its block).
///
/// # Errors
/// A failed identification or a record the device cannot take.
fn fit_transmissions(
    plan: &crate::inputs::Plan,
    haptic: &HapticDevice,
    rows: &[LogRow],
    step1: Step1<'_>,
) -> Result<LogFit> {
    let t = transmissions_of(haptic, rows, step1)?;
    let (_, kin) = identify_kinematics(haptic, rows, Some(&t)).context("step 2 (kinematics)")?;
    let mut parameters = Vec::new();
    let (t, kin, covariance) = if plan.joint {
        let (problem, joint) = identify_jointly(haptic, rows, &t, &kin)?;
        parameters.extend(kept_parameters(&joint));
        let covariance = block_covariance(&[&joint.covariance]);
        let (t, kin) = split_joint(&problem, &joint, t, kin)?;
        (t, kin, covariance)
    } else {
        for c in &t.capstans {
            parameters.extend(kept_parameters(&c.identified));
        }
        parameters.extend(kept_parameters(&t.poly_identified));
        parameters.extend(kept_parameters(&kin));
        let mut blocks: Vec<&hapcal_identify::Covariance> = (t.capstans.iter())
            .map(|c| &c.identified.covariance)
            .collect();
        blocks.push(&t.poly_identified.covariance);
        blocks.push(&kin.covariance);
        let covariance = block_covariance(&blocks);
        (t, kin, covariance)
    };
    let notes = format!(
        "the paper's {} on {} rows; written by `hapcal calibrate`",
        if plan.joint {
            "joint identification"
        } else {
            "two steps"
        },
        rows.len()
    );
    let record = haptic_record(
        haptic,
        rows,
        ModelName::Transmissions,
        report_values(&parameters),
        Some(covariance),
        None,
        notes,
    );
    let calibrated = haptic.device.with_record(record)?;
    Ok(LogFit {
        transmissions: Some(t),
        kin,
        model: ModelName::Transmissions,
        calibrated,
        compliance: None,
        parameters,
    })
}

/// The final fit of `--model geometric` (or of logs without external encoders): the kinematic
/// deviations alone, whether or not the logs could carry the transmissions.
///
/// # Errors
/// A failed identification or a record the device cannot take.
fn fit_geometric(
    haptic: &HapticDevice,
    rows: &[LogRow],
    has_ext: bool,
    warnings: &mut Vec<String>,
) -> Result<LogFit> {
    if !has_ext {
        warnings.push(no_ext_warning());
    }
    let (_, kin) = identify_kinematics(haptic, rows, None).context("kinematics")?;
    let parameters = kept_parameters(&kin);
    let record = haptic_record(
        haptic,
        rows,
        ModelName::Geometric,
        report_values(&parameters),
        Some(block_covariance(&[&kin.covariance])),
        None,
        format!(
            "kinematics only (no external encoders) on {} rows; written by `hapcal calibrate`",
            rows.len()
        ),
    );
    let calibrated = haptic.device.with_record(record)?;
    Ok(LogFit {
        transmissions: None,
        kin,
        model: ModelName::Geometric,
        calibrated,
        compliance: None,
        parameters,
    })
}

/// Distance RMS figures of one log's residuals.
fn distance_figures(residuals_m: &[f64]) -> Figures {
    Figures {
        mean_absolute_error_m: None,
        distance_error_m: None,
        distance_rms_m: Some(hapcal_metrics::rms(residuals_m)),
        pose: None,
    }
}

/// The placements stage of [`calibrate_logs`]: each log's distance RMS with the nominal model
/// on the raw readings and with the calibrated one (with the compliance, its transmissions and
/// compliances on every log, training and test).
///
/// # Errors
/// A log the compliance model cannot evaluate.
fn log_placements<'a>(
    haptic: &HapticDevice,
    fit: &LogFit,
    x_kin: &[f64],
    logs: impl Iterator<Item = (SetRole, &'a String, &'a [LogRow])>,
) -> Result<Vec<SetReport>> {
    let zero = vec![0.0; haptic.chain.n_params()];
    let mut placements = Vec::new();
    for (role, name, rows) in logs {
        let after = match &fit.compliance {
            Some(c) => compliance_distance_residuals_m(haptic, c, rows)
                .with_context(|| format!("log {name}: the calibrated model"))?,
            None => kinematic_residuals_m(haptic, rows, x_kin, fit.transmissions.as_ref()),
        };
        placements.push(SetReport {
            name: name.clone(),
            role,
            n_rows: rows.len(),
            before: distance_figures(&kinematic_residuals_m(haptic, rows, &zero, None)),
            after: distance_figures(&after),
            errors: None,
        });
    }
    Ok(placements)
}

/// One warning per test log the calibration made worse than the nominal model, in the order
/// of the logs.
fn worse_logs(placements: &[SetReport]) -> Vec<String> {
    (placements.iter().filter(|p| p.role == SetRole::Test))
        .filter_map(
            |p| match (p.before.distance_rms_m, p.after.distance_rms_m) {
                (Some(before), Some(after)) if after > before => Some(format!(
                    "test log {}: the calibrated model is worse than the nominal one (distance RMS \
                 {:.1} → {:.1} µm): do not use this calibration there",
                    p.name,
                    before * 1e6,
                    after * 1e6
                )),
                _ => None,
            },
        )
        .collect()
}

/// What the ladder stage gives the report of [`calibrate_logs`].
struct LogsChoice {
    /// The rungs' held-out scores (empty when the model was given).
    cross_validation: Vec<crate::report::CvReport>,
    /// The training rows the ladder judged when it judged a sample.
    cross_validated_rows: Option<usize>,
    /// √(rows / distinct rows), the factor the compliances' σ are judged with.
    std_scale: f64,
}

/// What the report of [`calibrate_logs`] lists beside the fit.
struct LogsFindings {
    /// Each training and test log's figures.
    placements: Vec<SetReport>,
    /// The rows the Huber loss bounded.
    downweighted: Vec<crate::report::Downweighted>,
    /// The warnings so far, in the order they are shown.
    warnings: Vec<String>,
}

/// The report stage of [`calibrate_logs`]: pruned and correlated parameters, the cable
/// residual against the encoder's noise, what no real device has (an unconverged fit,
/// compliances below zero beyond the bound).
fn logs_report(
    plan: &crate::inputs::Plan,
    haptic: &HapticDevice,
    fit: &LogFit,
    choice: LogsChoice,
    findings: LogsFindings,
    start: std::time::Instant,
) -> CalibrationReport {
    let LogsFindings {
        placements,
        downweighted,
        mut warnings,
    } = findings;
    let kin = &fit.kin;
    let pruned = crate::fit::pruned_report(kin);
    let correlated = (kin.covariance.correlated_pairs(0.95).into_iter())
        .map(|(a, b, c)| {
            (
                kin.layout.name(a).to_string(),
                kin.layout.name(b).to_string(),
                c,
            )
        })
        .collect();
    // Step 2's residuals are divided by the cable encoder's σ_m: its σ is a multiple of it.
    let floor_m = haptic.noise.sigma_m_m;
    let sigma_m = kin.sigma * floor_m;
    if kin.sigma > 3.0 {
        warnings.push(format!(
            "the cable-distance residual σ = {:.1} µm is {:.0}× the cable encoder's noise \
             (σ_m = {:.1} µm): an effect the model lacks, or a wrong nominal model",
            sigma_m * 1e6,
            kin.sigma,
            floor_m * 1e6
        ));
    }
    let given = matches!(plan.model, ModelChoice::Model(_));
    let implausible = match &fit.compliance {
        Some(c) => crate::fit::implausible_estimates(
            &c.identified,
            fit.model,
            given,
            HANDLE_COMPLIANCE_UNIT,
            choice.std_scale,
        ),
        None => crate::fit::unconverged(kin, fit.model, given)
            .into_iter()
            .collect(),
    };
    CalibrationReport {
        device: plan.device.display().to_string(),
        model: fit.model,
        folds: plan.folds,
        cross_validation: choice.cross_validation,
        cross_validated_rows: choice.cross_validated_rows,
        ladder: Vec::new(),
        frames: Vec::new(),
        sigma_m,
        sigma_source: kin.sigma_source.name(),
        parameters: fit.parameters.clone(),
        pruned,
        correlated,
        observability: None,
        warnings,
        termination: kin.fit.termination.clone(),
        backend: crate::fit::backend_of(kin),
        n_evaluations: kin.fit.n_evaluations,
        n_jacobians: kin.fit.n_jacobians,
        rounds: kin.rounds,
        placements,
        elapsed_s: start.elapsed().as_secs_f64(),
        downweighted,
        range_folds: Vec::new(),
        coverage: None,
        equilibrium_step_m: None,
        equilibrium_refits: 0,
        implausible,
        refitted_lengths: Vec::new(),
        origins: Vec::new(),
    }
}

/// Step 1 of a set of training rows: what the ladder knows of it before it starts.
#[derive(Clone, Copy)]
enum Step1<'a> {
    /// The rows lack the external-encoder columns: no transmissions rung.
    NoEncoders,
    /// The rows carry them; step 1 is still to be fitted on them.
    ToFit,
    /// Step 1 fitted on the rows.
    Fitted(&'a TransmissionFit),
}

impl<'a> Step1<'a> {
    /// The step 1 of rows that carry the external encoders or not (`has_ext`), `fitted` on
    /// them or not.
    fn of(has_ext: bool, fitted: Option<&'a TransmissionFit>) -> Self {
        match (has_ext, fitted) {
            (false, _) => Step1::NoEncoders,
            (true, None) => Step1::ToFit,
            (true, Some(t)) => Step1::Fitted(t),
        }
    }
}

/// The model `--model auto` takes on the training `rows` (`lengths[i]` rows of log `i`, one
/// after the other, gross errors already bounded): the haptic ladder geometric →
/// transmissions (when the logs have the external-encoder columns, `step1`) → compliance
/// (when the device file has a handle mass), each rung fitted on every row of `rows`, judged
/// by repeated blocked cross-validation with `folds` folds ([`cross_validate_rungs`]) and
/// climbed by the rule of every workflow ([`crate::fit::choose`]); a chosen rung with an
/// implausible estimate ([`crate::fit::implausible_estimates`]) gives way to the best rung
/// below it. `step1` says whether the logs carry the external encoders and whether step 1 is
/// already fitted on `rows`. `copies` is every training row's count of rows that repeat an earlier row of
/// their log and the factor `√(rows / distinct rows)` the fits' σ are scaled by when judged
/// ([`crate::fit::copies_warning`]), also when `rows` is a sample of them. Returns the model
/// and every judged rung's held-out figures; what the report must say (a rung not tried, a
/// rung left out, the copies, the transmissions not beating the deviations alone) is pushed
/// to `warnings`.
///
/// # Errors
/// A failed identification of the transmissions or the deviations on every row.
fn choose_model(
    haptic: &HapticDevice,
    rows: &[LogRow],
    lengths: &[usize],
    step1: Step1<'_>,
    folds: usize,
    copies: (usize, f64),
    warnings: &mut Vec<String>,
) -> Result<(ModelName, Vec<crate::report::CvReport>)> {
    let (n_copies, std_scale) = copies;
    let has_ext = !matches!(step1, Step1::NoEncoders);
    let mut cross_validation = Vec::new();
    let has_mass = haptic.device.handle.is_some_and(|h| h.mass_kg > 0.0);
    let (rungs, levels) = haptic_rungs(has_ext, has_mass);
    let geometric = identify_kinematics(haptic, rows, None)
        .context("kinematics")?
        .1;
    let two_steps = if has_ext {
        let t = match step1 {
            Step1::Fitted(t) => t.clone(),
            _ => identify_transmissions(haptic, rows).context("step 1 (transmissions)")?,
        };
        let (_, kin) =
            identify_kinematics(haptic, rows, Some(&t)).context("step 2 (kinematics)")?;
        Some((t, kin))
    } else {
        None
    };
    // A rung whose identification fails on every training row (the compliance of a
    // device whose logs cannot tell it from the deviations: a singular covariance) is
    // left out of the climb, and the report says so.
    let mut fits = Vec::new();
    let (mut tried, mut tried_levels) = (Vec::new(), Vec::new());
    for (&m, &level) in rungs.iter().zip(&levels) {
        let fit = match m {
            ModelName::Transmissions => {
                let (t, kin) = two_steps.clone().context("no transmissions fitted")?;
                HapticRungFit::Transmissions(t, kin)
            }
            ModelName::Compliance => {
                let (t, kin) = match &two_steps {
                    Some((t, kin)) => (Some(t), kin),
                    None => (None, &geometric),
                };
                match identify_with_compliance(haptic, rows, t, kin) {
                    Ok(fit) => HapticRungFit::Compliance(fit, t.cloned()),
                    Err(e) => {
                        warnings.push(format!(
                            "the {m} model was not tried: {e:#}; the ladder stops below it"
                        ));
                        continue;
                    }
                }
            }
            _ => HapticRungFit::Geometric(geometric.clone()),
        };
        fits.push(fit);
        tried.push(m);
        tried_levels.push(level);
    }
    // A rung that a cross-validation fold's training rows cannot fit (few rows: the fold
    // keeps four fifths of them) cannot be judged: the ladder stops below it and says so;
    // when not even the first rung can be judged, it is taken without cross-validation.
    let mut held = Vec::new();
    let mut unjudged = None;
    for fit in &fits {
        match cross_validate_rungs(haptic, rows, lengths, std::slice::from_ref(fit), folds) {
            Ok(h) => held.extend(h),
            Err(e) => {
                let why = format!(
                    "{e:#} ({} training rows, {}-fold cross-validation)",
                    rows.len(),
                    folds
                );
                if held.is_empty() {
                    unjudged = Some(why);
                } else {
                    warnings.push(format!(
                        "the {} model was not tried: {why}; the ladder stops below it",
                        fit.model()
                    ));
                }
                break;
            }
        }
    }
    let judged = held.len();
    let (rungs, levels) = (&tried[..judged], &tried_levels[..judged]);
    let choice = if let Some(why) = unjudged {
        let first = *tried.first().context("no model could be fitted")?;
        warnings.push(format!(
            "cross-validation cannot judge any model on these rows: {why}; the {first} \
             model is taken without it (record more rows for the ladder to compare models)"
        ));
        first
    } else {
        let (mut choice, reports) = crate::fit::choose(rungs, levels, &held);
        cross_validation = reports;
        // A chosen rung whose estimate no real device has (compliances below zero beyond
        // the bound, an unconverged fit) is never the result: the ladder keeps the best of
        // the rungs below it, and says why.
        while let Some(k) = rungs.iter().position(|&r| r == choice)
            && k > 0
            && let Some(i) = crate::fit::implausible_estimates(
                fits[k].identified(),
                choice,
                false,
                HANDLE_COMPLIANCE_UNIT,
                std_scale,
            )
            .into_iter()
            .next()
        {
            let (below, _) = crate::fit::choose(&rungs[..k], &levels[..k], &held[..k]);
            warnings.push(format!(
                "the {choice} model predicted the held-out rows best but was left out: {}; \
                 the ladder keeps the {below} model",
                i.message
            ));
            choice = below;
        }
        choice
    };
    warnings.extend(crate::fit::copies_warning(n_copies));
    if choice == ModelName::Geometric && has_ext && rungs.contains(&ModelName::Transmissions) {
        warnings.push(
            "the transmissions did not beat the kinematic deviations alone on held-out \
             training rows: they are not identified (ask for --model transmissions to fit \
             them anyway)"
                .to_owned(),
        );
    }
    if choice == ModelName::Compliance && !has_ext {
        warnings.push(
            "the compliance model predicted the held-out training rows best, but without \
             the external-encoder columns its compliances also absorb the transmission \
             errors: they are not the handle's alone (record the external encoders to tell \
             them apart)"
                .to_owned(),
        );
    }
    Ok((choice, cross_validation))
}

/// The training rows as the Huber loss sees them ([`winsorize`]).
struct Winsorized {
    /// The rows, each distance beyond the corner pulled back onto it; `None` when none lies
    /// beyond it (the rows as measured).
    rows: Option<Vec<LogRow>>,
    /// The bounded rows, with their log and line.
    downweighted: Vec<crate::report::Downweighted>,
    /// The model that judged them.
    judge: ModelName,
    /// Step 1's transmissions fitted on the rows (`None` without the external encoders, or
    /// when they cannot be fitted).
    transmissions: Option<TransmissionFit>,
}

/// The training rows as the Huber loss sees them ([`crate::robust::bound_gross_errors`]):
/// step 2's kinematic deviations fitted to the cable distances (the readings corrected by
/// step 1's transmissions when the logs carry the external encoders: the transmissions
/// model, else the geometric one), and every row whose distance error `e` (measured −
/// modelled) lies beyond the corner given the distance `model + e·c/|e|`, until the set of
/// bounded rows no longer changes. Returns the rows, the bounded ones listed with their log
/// (`logs`, whose rows `rows` are, in order) and line, and the model that judged them. Rows
/// unchanged and none listed when nothing lies beyond the corner, with fewer than 20 rows,
/// or when the model cannot be fitted.
fn winsorize(
    r: &HapticDevice,
    logs: &[NamedLog],
    lengths: &[usize],
    rows: &[LogRow],
    has_ext: bool,
) -> Winsorized {
    use crate::robust::{Dim, Round, bound_gross_errors, redundancy};
    let transmissions = if has_ext {
        identify_transmissions(r, rows).ok()
    } else {
        None
    };
    let judge = if transmissions.is_some() {
        ModelName::Transmissions
    } else {
        ModelName::Geometric
    };
    // Every row's distance error and modelled distance under the last fit, m.
    let mut last: Vec<(f64, f64)> = Vec::new();
    let winsorized = |last: &[(f64, f64)], bounds: &[crate::robust::Bound]| {
        let mut out = rows.to_vec();
        for b in bounds {
            let (e, model) = last[b.sample];
            out[b.sample].distance_m = model + e * (b.corner / b.norm);
        }
        out
    };
    let bounds = bound_gross_errors(rows.len(), Dim::One, |bounds| {
        let fitted = winsorized(&last, bounds);
        let (_, kin) = identify_kinematics(r, &fitted, transmissions.as_ref()).ok()?;
        let redundancy = redundancy(kin.n_residuals, kin.identifiability.kept.len())?;
        let x: Vec<f64> = kin.fit.x.iter().copied().collect();
        last = (rows.iter())
            .map(|row| {
                let q = transmissions
                    .as_ref()
                    .map_or_else(|| row.q.clone(), |t| t.corrected(&row.q));
                let model = r.chain.end_point(&x, &q).coords.norm();
                (row.distance_m - model, model)
            })
            .collect();
        Some(Round {
            norms: last.iter().map(|(e, _)| e.abs()).collect(),
            redundancy,
        })
    });
    if bounds.is_empty() {
        return Winsorized {
            rows: None,
            downweighted: Vec::new(),
            judge,
            transmissions,
        };
    }
    let files: Vec<&std::path::Path> = (logs.iter().zip(lengths))
        .flat_map(|(log, &len)| std::iter::repeat_n(log.path.as_path(), len))
        .collect();
    let listed = (bounds.iter())
        .map(|b| crate::report::Downweighted {
            file: files
                .get(b.sample)
                .map_or_else(String::new, |f| f.display().to_string()),
            line: rows[b.sample].line,
            marker: None,
            residual_m: b.norm,
            bound_m: b.corner,
        })
        .collect();
    Winsorized {
        rows: Some(winsorized(&last, &bounds)),
        downweighted: listed,
        judge,
        transmissions,
    }
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
