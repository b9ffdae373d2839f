//! `hapcal plan-poses`: choose the poses to measure before calibrating, and the Monte Carlo
//! study (`hapcal pose-study`) that checks the planned poses against random ones on the
//! simulated reference device.
//!
//! The robot-specific part lives here: each candidate pose becomes a block of rows of the
//! scaled identification Jacobian at the nominal model, which the generic
//! [`hapcal_identify::select_poses`] chooses from.
//!
//! A block holds, for one pose:
//! - the measurement rows (1 for a distance, 3 for a position), divided by the measurement σ, over
//!   the kinematic parameters the candidate set determines (pruned first with
//!   [`hapcal_identify::identifiability`], as `hapcal calibrate` would at the nominal);
//! - when the device has transmissions, one external-encoder row per transmission joint, divided
//!   by σ_e: for a capstan the linearised eq. 1 basis `[1, θ, sin θ, cos θ − 1, sin Rθ,
//!   cos Rθ − 1]` (the basis of `CapstanProblem::initial_guess`), for the parallelogram joint
//!   the Chebyshev basis of the degree-10 joint polynomial. These rows make the planner spread
//!   the transmission joints over their ranges, since step 1 identifies the transmissions from
//!   the same poses.
//!
//! The kinematic and transmission columns do not share rows, so `log det` of the information
//! matrix is the sum of the two parts' and D-optimality does not depend on the relative weight
//! of the two sensors, nor on the column scaling.
//!
//! When step 1 has its own external-encoder run (`--separate-transmission-run`; in the study
//! `--transmissions shared|noise-free`), a block is the distance row alone ([`distance_row`]),
//! optionally weighted by the joint angle errors that step 1 leaves at that pose
//! ([`transmission_variances`]) or that encoder quantisation adds ([`quantisation_variances`]).
//! `--refine` then moves the chosen poses off the candidates by coordinate exchange over the
//! joint box ([`coordinate_exchange`]).
//!
//! `hapcal pose-bound` (`hapcal_studies::pose_study::design_bound`) answers how well any `N` distance poses can do: the
//! continuous I-optimal design (multiplicative algorithm, [`hapcal_identify::i_optimal_weights`])
//! on uniform candidates, enlarged by column generation with the maxima of its sensitivity over
//! the joint box, and the equivalence-theorem certificate `Φ* ≥ Φ(ξ)²/sup d` that bounds every
//! `N`-pose design by `Φ*/N`; compared with the study's random reference sets.

use anyhow::{Context, Result, bail};
use faer::Mat;
use hapcal_identify::{
    Criterion, Design, DesignConfig, Observability, Problem, design_quality, identifiability,
    select_poses,
};
use hapcal_io::Device;

use crate::model::{DataKind, ModelChoice};
use hapcal_problems::{CalibrationProblem, Observations, Row, RowKind, Weights};
use hapcal_sim::NoiseModel;
use hapcal_transmission::{Capstan, Chebyshev, JointRad};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Degree of the parallelogram joint's error polynomial (as in [`crate::haptic::POLY_DEGREE`]).
const POLY_DEGREE: usize = crate::haptic::POLY_DEGREE;

/// What the rig measures at each pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Measurement {
    /// Distance from the rig origin to the end point (cable encoder, paper eq. 5).
    Distance,
    /// End point position in the rig frame (tracker).
    Position,
}

/// Settings of [`plan_poses`].
#[derive(Clone, Debug)]
pub struct PlanConfig {
    /// Measurement type.
    pub measurement: Measurement,
    /// Number of poses to choose.
    pub count: usize,
    /// Number of candidate poses sampled uniformly within the joint limits.
    pub n_candidates: usize,
    /// Seed of the candidate sampling (`ChaCha8Rng`).
    pub seed: u64,
    /// Criterion to maximise.
    pub criterion: Criterion,
    /// Measurement noise σ, m; `None`: the paper's σ_m of the device's cable encoder, or 10 µm.
    pub sigma_m: Option<f64>,
    /// Whether the external-encoder rows of the transmissions are part of each pose's block
    /// (step 1 identified from the same poses); false when step 1 has its own data and only the
    /// distance poses are planned.
    pub transmission_rows: bool,
    /// Refine the chosen poses by [`coordinate_exchange`] over the joint box (distance
    /// measurement without transmission rows, i-optimal or d-optimal).
    pub refine: bool,
    /// The model the poses are planned for, by its `--model` name ([`ModelChoice`]; see
    /// [`planned_model`]): its parameter families are the blocks' columns.
    pub model: ModelChoice,
}

/// Checks that `model` is one the planner can plan `device`'s poses for, in the user's words:
/// the models `hapcal calibrate` fits to the data of the planned measurement (a haptic device's
/// logs, distance logs, or measurement files), less those that are a choice or fit only
/// instrument frames: `auto` (plan for the richest model you will calibrate), `frames-only`
/// and `joint-offsets` (poses that determine the geometric model determine them), and, on a
/// haptic device, `compliance` (the handle's compliance is not a model of the planner).
///
/// # Errors
/// The refusal, naming the model as the user typed it.
pub fn planned_model(device: &Device, measurement: Measurement, model: ModelChoice) -> Result<()> {
    let haptic = !device.capstans.is_empty() || device.parallelogram.is_some();
    let kind = match (haptic, measurement) {
        (true, Measurement::Distance) => DataKind::HapticLogs,
        (false, Measurement::Distance) => DataKind::Distances,
        (_, Measurement::Position) => DataKind::Measurements,
    };
    match model {
        ModelChoice::Auto => bail!(
            "--model auto: the poses are planned for one model; give the richest you will \
             calibrate (geometric, compliance, …)"
        ),
        ModelChoice::FramesOnly | ModelChoice::JointOffsets => bail!(
            "--model {model}: plan for geometric: poses that determine every kinematic \
             parameter determine the {}",
            if model == ModelChoice::FramesOnly {
                "instrument frame"
            } else {
                "joint offsets"
            }
        ),
        _ => {}
    }
    // A haptic device's poses serve its transmissions and kinematics: geometric and
    // transmissions plan the same blocks (the transmission rows follow
    // --separate-transmission-run).
    if kind == DataKind::HapticLogs && model == ModelChoice::Geometric {
        return Ok(());
    }
    // `hapcal calibrate --model compliance` fits a haptic device's handle compliance with the
    // diagnosis's model (the handle's weight at the end point); the planner's compliance
    // blocks are lumped link weights, another model: it does not plan for it.
    if kind == DataKind::HapticLogs && model == ModelChoice::Compliance {
        bail!(
            "--model compliance: the pose planner has no model of a haptic device's handle \
             compliance; plan for transmissions (calibrate's compliance fits the logs of those \
             poses)"
        );
    }
    model.check_fits(kind)
}

/// Whether `model` frees no family beyond the kinematic deviations (and a haptic device's
/// transmissions, whose rows the blocks carry either way): the plain identification problem
/// plans it.
fn plans_kinematics_only(model: ModelChoice) -> bool {
    matches!(model, ModelChoice::Geometric | ModelChoice::Transmissions)
}

/// Result of [`plan_poses`].
#[derive(Clone, Debug)]
pub struct PosePlan {
    /// Chosen joint readings, rad (`count` rows of `n_joints`), in candidate order.
    pub readings: Vec<Vec<f64>>,
    /// The design (indices into the candidates, criterion value, O1–O5).
    pub design: Design,
    /// `log det` and O1–O5 of the first `count` candidates (a random set of the same size), for
    /// comparison.
    pub random: (f64, Observability),
    /// Names of the block columns: kinematic parameters determined by the candidates, then the
    /// transmission basis columns.
    pub columns: Vec<String>,
    /// Names of kinematic parameters the candidates cannot determine (left out of the design).
    pub undetermined: Vec<String>,
    /// The criterion after [`coordinate_exchange`] (smaller is better: `tr(W·M⁻¹)` in m², or
    /// `−log det`), when [`PlanConfig::refine`].
    pub refined_value: Option<f64>,
}

/// σ_m (m) and σ_e (rad) used to weight the rows.
fn sigmas(device: &Device, sigma_m: Option<f64>) -> (f64, f64) {
    let paper = device.cable_encoder.as_ref().map(NoiseModel::paper);
    let sigma_e = paper
        .unwrap_or_else(|| NoiseModel::paper(&hapcal_sim::REFERENCE_CABLE_ENCODER))
        .sigma_e_rad;
    (
        sigma_m.unwrap_or(paper.map_or(1e-5, |n| n.sigma_m_m)),
        sigma_e,
    )
}

/// Basis functions of one transmission joint's error, evaluated at a joint reading (rad).
type Basis = Box<dyn Fn(f64) -> Vec<f64>>;

/// The candidates of a plan: Jacobian blocks, column names, what they cannot determine, and the
/// weight of I-optimality.
#[derive(Clone, Debug)]
pub struct Candidates {
    /// One block per candidate pose (`rows × columns.len()`), rows divided by their σ.
    pub blocks: Vec<Mat<f64>>,
    /// Column names: kept kinematic parameters, then transmission basis coefficients.
    pub columns: Vec<String>,
    /// Kinematic parameters the candidates cannot determine (left out).
    pub undetermined: Vec<String>,
    /// Indices into the chain's parameters of the kinematic columns (`kept.len()` first
    /// columns).
    pub kept: Vec<usize>,
    /// `W = mean_c(G_cᵀG_c)`, `G_c` (3 × columns) the derivative of the end point (m) at
    /// candidate `c` with respect to the columns, in the device's base frame (the frame of the
    /// validation, the validation of the paper's study): the kinematic point Jacobian, with zero columns
    /// for the parameters of a fixed first D-H row (rig → base, which do not move the end
    /// point in the base frame), and for a transmission coefficient the joint's column of the
    /// geometric Jacobian times the basis function. With rows divided by σ,
    /// `trace(W·(JᵀJ)⁻¹)` is the mean end-point position variance (m²) over the candidates,
    /// the target of [`Criterion::IOptimal`].
    pub weight: Mat<f64>,
}

/// Per parameter of `chain`: whether it belongs to a fixed first D-H row of `device` (the rig →
/// base transform, invisible in the base frame).
pub fn fixed_base_row_params(device: &Device, chain: &hapcal_kinematics::Chain) -> Vec<bool> {
    let first_fixed = device.dh_rows().first().is_some_and(|r| r.joint.is_none());
    (chain.params().iter())
        .map(|p| first_fixed && p.element == 0)
        .collect()
}

/// Candidate blocks of the scaled Jacobian for `readings` (see the module docs); with
/// `transmission_rows` false, only the measurement rows and the kinematic columns.
///
/// # Errors
/// An invalid device chain, readings of the wrong length, or a Jacobian evaluation failure.
pub fn candidate_blocks(
    device: &Device,
    readings: &[Vec<f64>],
    measurement: Measurement,
    sigma_m: Option<f64>,
    transmission_rows: bool,
) -> Result<Candidates> {
    candidate_blocks_for(
        device,
        readings,
        measurement,
        sigma_m,
        transmission_rows,
        ModelChoice::Geometric,
    )
}

/// [`candidate_blocks`] for `model`: the measurement rows span the columns of every parameter
/// family `model` frees that the candidates determine (kinematic, gravity compliance with
/// lumped unit weights or the published masses, transversal compliance, joint harmonics;
/// [`crate::model::terms`]). I-optimality weighs the end point's prediction through the
/// kinematic and transmission columns only (the weight matrix has zeros for the others).
///
/// # Errors
/// Those of [`candidate_blocks`], and a model whose terms the robot does not carry.
pub fn candidate_blocks_for(
    device: &Device,
    readings: &[Vec<f64>],
    measurement: Measurement,
    sigma_m: Option<f64>,
    transmission_rows: bool,
    model: ModelChoice,
) -> Result<Candidates> {
    let chain = device.chain().context("building the kinematic chain")?;
    let chain_for_weight = chain.clone();
    let (sigma_m, sigma_e) = sigmas(device, sigma_m);
    let kind = match measurement {
        Measurement::Distance => RowKind::Distance { distance_m: 0.0 },
        Measurement::Position => RowKind::Position {
            position_m: [0.0; 3],
        },
    };
    let rows_per_pose = match measurement {
        Measurement::Distance => 1,
        Measurement::Position => 3,
    };
    let obs = Observations {
        rows: readings
            .iter()
            .map(|q| Row {
                q: q.clone(),
                kind: kind.clone(),
            })
            .collect(),
        point_distances: Vec::new(),
        n_points: 0,
    };
    let weights = Weights {
        sigma_distance_m: sigma_m,
        sigma_position_m: sigma_m,
        ..Weights::default()
    };
    let problem = if plans_kinematics_only(model) {
        CalibrationProblem::new(chain, obs, weights, None)?
    } else {
        let names: Vec<String> = chain.joint_names().iter().map(|n| n.to_string()).collect();
        let terms = crate::model::terms(model, &names, &[])?;
        CalibrationProblem::on_tree(hapcal_kinematics::Tree::single(chain), obs, weights, terms)?
    };
    let layout = problem.layout().clone();
    let x0 = problem.initial_guess();
    let mut jac = Mat::<f64>::zeros(problem.n_residuals(), layout.len());
    problem
        .jacobian(x0.as_ref(), jac.as_mut())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    // Residuals are divided by σ, so σ = 1 in residual units.
    let rank = crate::fit::identify_config(None).rank.with_sigma(1.0);
    let candidates: Vec<usize> = (0..layout.len()).collect();
    let ident = identifiability(jac.as_ref(), &layout, &candidates, &rank);
    let kept = ident.kept.clone();
    let mut columns: Vec<String> = kept.iter().map(|&j| layout.name(j).to_owned()).collect();

    // Transmission basis columns: (joint index, basis function count, evaluator).
    let parallelogram = device
        .parallelogram
        .is_some()
        .then_some(crate::haptic::PARALLELOGRAM_JOINT);
    let limits = device.joint_limits();
    let mut transmissions: Vec<(usize, Basis)> = Vec::new();
    let capstans = if transmission_rows {
        device.capstans.as_slice()
    } else {
        &[]
    };
    for c in capstans {
        let j = c.joint - 1;
        if Some(c.joint) == parallelogram {
            let (lo, hi) = *limits
                .get(j)
                .with_context(|| format!("no limits for joint {}", c.joint))?;
            let cheb = Chebyshev::try_new(lo, hi, vec![0.0; POLY_DEGREE + 1])?;
            for k in 0..=POLY_DEGREE {
                columns.push(format!("joint{}.cheb{k}", c.joint));
            }
            transmissions.push((j, Box::new(move |t: f64| cheb.basis(t))));
        } else {
            // The capstan's own linearisation about a perfect drive (Cartesian eccentricity
            // coordinates: the paper's polar ones have no phase column at zero eccentricity).
            let capstan = Capstan::try_new(c.ratio, c.drum_distance_m)?;
            for name in ["c", "a", "sin", "cos", "sin_r", "cos_r"] {
                columns.push(format!("capstan{}.{name}", c.joint));
            }
            transmissions.push((
                j,
                Box::new(move |t: f64| capstan.linear_basis(JointRad(t)).to_vec()),
            ));
        }
    }
    let n_cols = columns.len();
    let n_rows = rows_per_pose + transmissions.len();
    let x0 = vec![0.0; chain_for_weight.n_params()];
    let mut weight = Mat::<f64>::zeros(n_cols, n_cols);
    let in_base_row = fixed_base_row_params(device, &chain_for_weight);
    for q in readings {
        let jp = chain_for_weight.point_jacobian_wrt_params(&x0, q);
        let jq = chain_for_weight.geometric_jacobian(&x0, q);
        let mut g = Mat::<f64>::zeros(3, n_cols);
        for a in 0..3 {
            for (k, &j) in kept.iter().enumerate() {
                // Kinematic parameters come first in the problem's layout.
                if j < chain_for_weight.n_params() && !in_base_row[j] {
                    g[(a, k)] = jp[(a, j)];
                }
            }
            let mut col = kept.len();
            for (joint, basis) in &transmissions {
                for v in basis(q[*joint]) {
                    g[(a, col)] = jq[(a, *joint)] * v;
                    col += 1;
                }
            }
        }
        weight += g.transpose() * &g;
    }
    weight /= readings.len().max(1) as f64;
    let blocks = readings
        .iter()
        .enumerate()
        .map(|(pose_idx, q)| {
            let mut b = Mat::<f64>::zeros(n_rows, n_cols);
            for r in 0..rows_per_pose {
                for (k, &j) in kept.iter().enumerate() {
                    b[(r, k)] = jac[(pose_idx * rows_per_pose + r, j)];
                }
            }
            let mut col = kept.len();
            for (t, (joint, basis)) in transmissions.iter().enumerate() {
                let values = basis(q[*joint]);
                for (k, v) in values.iter().enumerate() {
                    b[(rows_per_pose + t, col + k)] = v / sigma_e;
                }
                col += values.len();
            }
            b
        })
        .collect();
    Ok(Candidates {
        blocks,
        columns,
        undetermined: ident
            .pruned_names()
            .iter()
            .map(|s| (*s).to_owned())
            .collect(),
        kept,
        weight,
    })
}

/// Plans `cfg.count` poses: samples `cfg.n_candidates` readings uniformly within the joint limits
/// (seed `cfg.seed`), builds their blocks for `cfg.model` ([`candidate_blocks_for`]) and chooses with
/// [`select_poses`].
///
/// # Errors
/// A count of 0 or above the candidates, too few poses to determine the parameters, or the
/// errors of [`candidate_blocks`].
pub fn plan_poses(device: &Device, cfg: &PlanConfig) -> Result<PosePlan> {
    plan_poses_weighted(device, cfg, None)
}

/// Per joint, the variance (rad²) of the joint angle error at a reading (rad), e.g.
/// [`transmission_variances`].
pub type JointVariance<'a> = dyn Fn(&[f64]) -> Vec<f64> + 'a;

/// [`plan_poses`] with the distance rows weighted by the joint angle errors `joint_var(q)`
/// (rad² per joint at reading `q`, e.g. [`transmission_variances`] of a step 1 done before
/// planning): with [`PlanConfig::transmission_rows`] false and distance measurements, every
/// candidate's row is [`distance_row`] with those variances (noise-weighted rows); otherwise
/// `joint_var` must be `None`.
///
/// # Errors
/// Those of [`plan_poses`]; `joint_var` with transmission rows or position measurements.
pub fn plan_poses_weighted(
    device: &Device,
    cfg: &PlanConfig,
    joint_var: Option<&JointVariance<'_>>,
) -> Result<PosePlan> {
    if cfg.count == 0 || cfg.count > cfg.n_candidates {
        bail!(
            "--count must be between 1 and the number of candidates ({}), got {}",
            cfg.n_candidates,
            cfg.count
        );
    }
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let candidates = hapcal_sim::sample_readings(device, &mut rng, cfg.n_candidates);
    if cfg.refine && (cfg.measurement != Measurement::Distance || cfg.transmission_rows) {
        bail!(
            "refining the poses over the joint box needs distance measurements planned without the transmission rows"
        );
    }
    planned_model(device, cfg.measurement, cfg.model)?;
    let kinematic_rows = cfg.measurement == Measurement::Distance && !cfg.transmission_rows;
    if kinematic_rows && !plans_kinematics_only(cfg.model) {
        bail!(
            "--model {}: a separate transmission run plans the kinematic rows of the geometric \
             model; plan for geometric, or without --separate-transmission-run",
            cfg.model
        );
    }
    if joint_var.is_some() && !kinematic_rows {
        bail!(
            "noise-weighted rows need distance measurements planned without the transmission rows"
        );
    }
    let Candidates {
        blocks,
        columns,
        undetermined,
        weight,
        kept,
    } = candidate_blocks_for(
        device,
        &candidates,
        cfg.measurement,
        cfg.sigma_m,
        cfg.transmission_rows,
        cfg.model,
    )?;
    let chain = device.chain()?;
    let (sigma_m, _) = sigmas(device, cfg.sigma_m);
    let zero = vec![0.0; chain.n_joints()];
    let row = |q: &[f64]| match joint_var {
        Some(f) => distance_row(&chain, &kept, q, sigma_m, &f(q)),
        None => distance_row(&chain, &kept, q, sigma_m, &zero),
    };
    let blocks = if kinematic_rows {
        candidates.iter().map(|q| row(q)).collect()
    } else {
        blocks
    };
    let design_cfg = DesignConfig {
        weight: Some(weight.clone()),
        ..DesignConfig::new(cfg.criterion)
    };
    let design = select_poses(&blocks, cfg.count, &design_cfg).context("choosing the poses")?;
    let first: Vec<usize> = (0..cfg.count).collect();
    let random =
        design_quality(&blocks, &first).context("scoring a random set of the same size")?;
    let mut readings: Vec<Vec<f64>> = design
        .selected
        .iter()
        .map(|&c| candidates[c].clone())
        .collect();
    let refined_value = if cfg.refine {
        Some(coordinate_exchange(
            &mut readings,
            &row,
            cfg.criterion,
            &weight,
            &device.joint_limits(),
            50,
        )?)
    } else {
        None
    };
    Ok(PosePlan {
        readings,
        design,
        random,
        columns,
        undetermined,
        refined_value,
    })
}

/// `trace(a·b)` of two square matrices of the same size.
pub fn trace_of_product(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    (0..a.nrows())
        .map(|i| (0..a.ncols()).map(|j| a[(i, j)] * b[(j, i)]).sum::<f64>())
        .sum()
}

/// Refines an exact `N`-pose design by coordinate exchange over the joint box (R. K. Meyer &
/// C. J. Nachtsheim, "The coordinate-exchange algorithm for constructing exact optimal
/// experimental designs", *Technometrics* 37(1), 1995): for each pose and each joint, the
/// joint takes the best of 21 values evenly spread over its limits and of a compass search
/// around the best (steps from half the grid spacing down to 1e-4 rad), the other poses held;
/// sweeps repeat until one improves the criterion by less than 1e-6 (relative) or after
/// `max_sweeps`. The poses may leave the candidates; they stay within `limits` (rad).
///
/// `row(q)` is the pose's block (`1 × n`, divided by σ; [`distance_row`]). The criterion is
/// [`Criterion::IOptimal`] with weight `w` (`n × n`; minimise `tr(W·M⁻¹)`, `M = Σ rowᵀrow`)
/// or [`Criterion::DOptimal`] (maximise `log det M`); a candidate row `b` for pose `i` is
/// scored from `N_i = (M − b_iᵀb_i)⁻¹` (plus a tiny ridge when singular) by Sherman–Morrison:
/// `tr(W(M_{−i} + bᵀb)⁻¹) = tr(W·N_i) − b·N_iWN_i·bᵀ/(1 + b·N_i·bᵀ)` and
/// `log det(M_{−i} + bᵀb) = log det M_{−i} + ln(1 + b·N_i·bᵀ)`.
///
/// Returns the value of the criterion (`tr(W·M⁻¹)`, or `−log det M`: smaller is better).
///
/// # Errors
/// Another criterion, or a singular information matrix.
pub fn coordinate_exchange(
    poses: &mut [Vec<f64>],
    row: &dyn Fn(&[f64]) -> Mat<f64>,
    criterion: Criterion,
    w: &Mat<f64>,
    limits: &[(f64, f64)],
    max_sweeps: usize,
) -> Result<f64> {
    if !matches!(criterion, Criterion::IOptimal | Criterion::DOptimal) {
        bail!("coordinate exchange supports i-optimal and d-optimal, not {criterion}");
    }
    use faer::linalg::solvers::DenseSolveCore;
    let n = w.nrows();
    let info = |poses: &[Vec<f64>]| {
        let mut m = Mat::<f64>::zeros(n, n);
        for q in poses {
            let b = row(q);
            m += b.transpose() * &b;
        }
        m
    };
    let value_of = |m: &Mat<f64>| -> Result<f64> {
        let llt = m
            .llt(faer::Side::Lower)
            .map_err(|e| anyhow::anyhow!("singular information matrix ({e:?})"))?;
        Ok(match criterion {
            Criterion::IOptimal => trace_of_product(w, &llt.inverse()),
            _ => -2.0 * (0..n).map(|i| llt.L()[(i, i)].ln()).sum::<f64>(),
        })
    };
    let mut m = info(poses);
    let mut value = value_of(&m)?;
    for _ in 0..max_sweeps {
        let before = value;
        for pose in poses.iter_mut() {
            let b_old = row(pose);
            let m_minus = &m - b_old.transpose() * &b_old;
            // With N = n poses M_{−i} is singular: a ridge of 1e-9 of the mean diagonal keeps
            // the scores finite (the direction pose i must fill then dominates them).
            let ridge = 1e-9 * (0..n).map(|k| m[(k, k)]).sum::<f64>() / n as f64;
            let Ok(llt) = m_minus.llt(faer::Side::Lower).or_else(|_| {
                (&m_minus + Mat::<f64>::identity(n, n) * ridge).llt(faer::Side::Lower)
            }) else {
                continue;
            };
            let n_i = llt.inverse();
            let a = &n_i * w * &n_i;
            let base = match criterion {
                Criterion::IOptimal => trace_of_product(w, &n_i),
                _ => -2.0 * (0..n).map(|k| llt.L()[(k, k)].ln()).sum::<f64>(),
            };
            let score = |q: &[f64]| {
                let b = row(q);
                let bn = &b * &n_i;
                let s: f64 = (0..n).map(|k| bn[(0, k)] * b[(0, k)]).sum();
                match criterion {
                    Criterion::IOptimal => {
                        let ba = &b * &a;
                        let t: f64 = (0..n).map(|k| ba[(0, k)] * b[(0, k)]).sum();
                        base - t / (1.0 + s)
                    }
                    _ => base - (1.0 + s).ln(),
                }
            };
            let mut q = pose.clone();
            let mut best = score(&q);
            for (j, &(lo, hi)) in limits.iter().enumerate().take(q.len()) {
                let spacing = (hi - lo) / 20.0;
                let mut best_v = q[j];
                for k in 0..=20 {
                    let mut t = q.clone();
                    t[j] = lo + spacing * f64::from(k);
                    let v = score(&t);
                    if v < best {
                        (best, best_v) = (v, t[j]);
                    }
                }
                q[j] = best_v;
                let mut step = spacing / 2.0;
                while step > 1e-4 {
                    let mut moved = false;
                    for sign in [1.0, -1.0] {
                        let mut t = q.clone();
                        t[j] = (t[j] + sign * step).clamp(lo, hi);
                        let v = score(&t);
                        if v < best {
                            (best, q) = (v, t);
                            moved = true;
                        }
                    }
                    if !moved {
                        step /= 2.0;
                    }
                }
            }
            let b_new = row(&q);
            m = m_minus + b_new.transpose() * &b_new;
            *pose = q;
        }
        // Recompute from scratch: the updates accumulate rounding.
        m = info(poses);
        value = value_of(&m)?;
        if value > before - 1e-6 * before.abs() {
            break;
        }
    }
    Ok(value)
}

/// The poses as CSV: a header of joint names, then one row of readings (rad) per pose.
pub fn poses_csv(joint_names: &[String], readings: &[Vec<f64>]) -> String {
    let mut s = joint_names.join(",");
    s.push('\n');
    for q in readings {
        let cells: Vec<String> = q.iter().map(|v| format!("{v:.9}")).collect();
        s.push_str(&cells.join(","));
        s.push('\n');
    }
    s
}

/// Text summary of a plan: criterion, indices of the plan and of a random set of the same size.
pub fn summary(plan: &PosePlan, cfg: &PlanConfig) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let d = &plan.design;
    let _ = writeln!(
        s,
        "planned {} poses from {} candidates by {} ({} exchanges{}); {} columns",
        d.selected.len(),
        cfg.n_candidates,
        cfg.criterion,
        d.n_exchanges,
        if d.converged { "" } else { ", not converged" },
        plan.columns.len()
    );
    if !plan.undetermined.is_empty() {
        let _ = writeln!(
            s,
            "left out (the candidates cannot determine them): {}",
            plan.undetermined.join(", ")
        );
    }
    let row = |name: &str, ld: f64, o: &Observability| {
        format!(
            "  {name:<8} {ld:>10.2} {:>10.4e} {:>10.4e} {:>10.4e} {:>10.4e} {:>10.4e}\n",
            o.o1, o.o2, o.o3, o.o4, o.o5
        )
    };
    let _ = writeln!(
        s,
        "  {:<8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "set", "log det", "O1", "O2", "O3", "O4", "O5"
    );
    s.push_str(&row("planned", d.log_det, &d.observability));
    s.push_str(&row("random", plan.random.0, &plan.random.1));
    if let Some(v) = plan.refined_value {
        let _ = writeln!(
            s,
            "refined by coordinate exchange over the joint box: criterion {v:.6e} (smaller is better; tr(W·M⁻¹) in m² for i-optimal, −log det for d-optimal)"
        );
    }
    s
}

/// How the rows of the bound are weighted (the distance noise per pose).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RowNoise {
    /// σ_m on every distance: the noise of [`hapcal_sim::simulate`], whose true joint angles
    /// start from the quantised readings (no quantisation error reaches the distance).
    Simulator,
    /// σ_m² plus the joint readings' quantisation error propagated through the Jacobian,
    /// `σᵢ² = σ_m² + Σⱼ (∂δ/∂qⱼ)²·resⱼ²/12` (uniform rounding error of resolution `resⱼ`,
    /// [`hapcal_sim::joint_resolutions_rad`]): a rig where the encoders truly quantise. Poses
    /// where the distance is less sensitive to the joints are less noisy.
    Quantised,
}

impl RowNoise {
    /// The flag value.
    pub fn name(self) -> &'static str {
        match self {
            RowNoise::Simulator => "simulator",
            RowNoise::Quantised => "quantised",
        }
    }
}

/// Per joint, the variance (rad²) of the joint angle error that `noise` adds at any reading:
/// `res²/12` for [`RowNoise::Quantised`] (uniform rounding to the resolution `res`,
/// [`hapcal_sim::joint_resolutions_rad`]), 0 for [`RowNoise::Simulator`].
pub fn quantisation_variances(device: &Device, noise: RowNoise) -> Vec<f64> {
    hapcal_sim::joint_resolutions_rad(device)
        .iter()
        .map(|res| match (noise, res) {
            (RowNoise::Quantised, Some(res)) => res * res / 12.0,
            _ => 0.0,
        })
        .collect()
}

/// Per joint, the variance (rad²) of the corrected joint angle at reading `q` (rad) that step
/// 1's estimate leaves: `gᵀ·C·g`, `C` the covariance of the transmission's identified
/// parameters and `g` the derivative of the corrected angle with respect to them (central
/// differences, step 1e-7, for a capstan's eq. 1; the Chebyshev basis for the joint-4
/// polynomial). 0 for joints without a transmission. The delta method (first order).
pub fn transmission_variances(t: &crate::haptic::TransmissionFit, q: &[f64]) -> Vec<f64> {
    use hapcal_problems::CapstanProblem;
    use hapcal_transmission::JointRad;
    let mut var = vec![0.0; q.len()];
    let quad = |g: &[f64], cov: &hapcal_identify::Covariance| {
        let f = &cov.free;
        (0..f.len())
            .flat_map(|a| (0..f.len()).map(move |b| (a, b)))
            .map(|(a, b)| g[f[a]] * cov.matrix[(a, b)] * g[f[b]])
            .sum::<f64>()
    };
    for c in &t.capstans {
        let Some(&theta) = q.get(c.joint - 1) else {
            continue;
        };
        let x = &c.identified.fit.x;
        let g: Vec<f64> = (0..x.nrows())
            .map(|k| {
                let h = 1e-7;
                let mut up = x.clone();
                let mut down = x.clone();
                up[k] += h;
                down[k] -= h;
                let out = |x: &faer::Col<f64>| {
                    c.capstan
                        .output_rad(&CapstanProblem::params(x.as_ref()), JointRad(theta))
                };
                (out(&up) - out(&down)) / (2.0 * h)
            })
            .collect();
        var[c.joint - 1] = quad(&g, &c.identified.covariance);
    }
    if let Some(&theta) = q.get(crate::haptic::PARALLELOGRAM_JOINT - 1) {
        let g = t.poly.basis(theta);
        var[crate::haptic::PARALLELOGRAM_JOINT - 1] = quad(&g, &t.poly_identified.covariance);
    }
    var
}

/// [`transmission_variances`] tabulated on a grid of each joint's range and interpolated
/// linearly: the variance at joint `j` depends on that joint's reading alone, so a table of
/// `n_grid` readings per joint replaces the per-pose finite differences in the planner's inner
/// loops.
#[derive(Clone, Debug)]
pub struct VarianceTable {
    /// Per joint: `(lower, upper, values)`, values (rad²) at `n_grid` evenly spaced readings.
    joints: Vec<(f64, f64, Vec<f64>)>,
}

impl VarianceTable {
    /// Tabulates [`transmission_variances`] of `t` over `limits` (rad) at `n_grid ≥ 2` readings
    /// per joint.
    pub fn new(t: &crate::haptic::TransmissionFit, limits: &[(f64, f64)], n_grid: usize) -> Self {
        let n_grid = n_grid.max(2);
        let joints = (0..limits.len())
            .map(|j| {
                let (lo, hi) = limits[j];
                let values = (0..n_grid)
                    .map(|k| {
                        let mut q: Vec<f64> = limits.iter().map(|l| 0.5 * (l.0 + l.1)).collect();
                        q[j] = lo + (hi - lo) * k as f64 / (n_grid - 1) as f64;
                        transmission_variances(t, &q)[j]
                    })
                    .collect();
                (lo, hi, values)
            })
            .collect();
        Self { joints }
    }

    /// Per joint, the interpolated variance (rad²) at reading `q` (rad; clamped to the range).
    pub fn eval(&self, q: &[f64]) -> Vec<f64> {
        self.joints
            .iter()
            .zip(q)
            .map(|((lo, hi, v), &x)| {
                let n = v.len() - 1;
                let u = ((x - lo) / (hi - lo)).clamp(0.0, 1.0) * n as f64;
                let k = (u.floor() as usize).min(n - 1);
                let f = u - k as f64;
                v[k] * (1.0 - f) + v[k + 1] * f
            })
            .collect()
    }
}

/// One pose's distance row of the scaled identification Jacobian at the nominal model:
/// `(∂δ/∂x_k)/σᵢ` over the chain parameters `kept` (length `kept.len()`, 1/m·m or 1/m·m/rad
/// per column), with `δ = |P|` (paper eq. 5, `P` the end point in the rig frame) and
/// `σᵢ² = σ_m² + Σⱼ (∂δ/∂qⱼ)²·joint_var_rad2[j]` (m²): the distance noise plus the joint
/// angle errors propagated through the Jacobian (first order; e.g.
/// [`quantisation_variances`], [`transmission_variances`]); joints past the end of
/// `joint_var_rad2` have none. The row is [`hapcal_problems::distance_row`]'s, the distance
/// Jacobian of the identification problems.
///
/// A negative variance (a quadratic form rounded below zero) counts as zero.
///
/// # Panics
/// If `q` has the wrong length or an index of `kept` is out of range (misuse), or if `sigma_m`
/// is not positive and finite (validated by the callers' problems).
#[track_caller]
pub fn distance_row(
    chain: &hapcal_kinematics::Chain,
    kept: &[usize],
    q: &[f64],
    sigma_m: f64,
    joint_var_rad2: &[f64],
) -> Mat<f64> {
    let x0 = vec![0.0; chain.n_params()];
    let joint_var: Vec<f64> = (0..chain.n_joints())
        .map(|j| joint_var_rad2.get(j).copied().unwrap_or(0.0).max(0.0))
        .collect();
    let row = match hapcal_problems::distance_row(chain, &x0, q, sigma_m, &joint_var) {
        Ok(row) => row,
        Err(e) => panic!("distance_row: {e}"),
    };
    Mat::from_fn(1, kept.len(), |_, k| row.jacobian[kept[k]] / row.sigma_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference_device() -> Device {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/reference-device/device.toml");
        crate::data::load_device(&path, "ball_link").expect("reference device")
    }

    #[test]
    fn distance_row_matches_the_identification_jacobian() {
        let device = reference_device();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let readings = hapcal_sim::sample_readings(&device, &mut rng, 50);
        let c = candidate_blocks(&device, &readings, Measurement::Distance, Some(1e-5), false)
            .expect("blocks");
        assert_eq!(c.kept.len(), 28);
        assert_eq!(c.undetermined, ["dalpha0", "dd0", "dtheta0", "dalpha7"]);
        let chain = device.chain().expect("chain");
        let none = quantisation_variances(&device, RowNoise::Simulator);
        let quantised = quantisation_variances(&device, RowNoise::Quantised);
        assert!(none.iter().all(|&v| v == 0.0) && quantised.iter().all(|&v| v > 0.0));
        for (q, b) in readings.iter().zip(&c.blocks) {
            let r = distance_row(&chain, &c.kept, q, 1e-5, &none);
            // The residual's sign convention may differ; the information does not.
            let sign = if r[(0, 0)] * b[(0, 0)] < 0.0 {
                -1.0
            } else {
                1.0
            };
            for k in 0..c.kept.len() {
                assert!(
                    (sign * r[(0, k)] - b[(0, k)]).abs() <= 1e-9 * b[(0, k)].abs().max(1.0),
                    "{}: {} vs {}",
                    c.columns[k],
                    r[(0, k)],
                    b[(0, k)]
                );
            }
            // Quantisation noise only adds: the quantised row is never longer.
            let rq = distance_row(&chain, &c.kept, q, 1e-5, &quantised);
            assert!(rq[(0, 3)].abs() <= r[(0, 3)].abs());
        }
        // The base-frame weight ignores the rig → base row: da0 has no weight.
        let da0 = c.columns.iter().position(|n| n == "da0").expect("da0 kept");
        assert_eq!(c.weight[(da0, da0)], 0.0);
        assert!(c.weight[(da0 + 1, da0 + 1)] > 0.0);
    }

    #[test]
    fn coordinate_exchange_moves_a_line_design_to_the_ends_of_the_range() {
        // Straight line (1, q) on [−1, 1]: the D- and I-optimal 2-point designs are {−1, 1}
        // (I: W = ∫(1, q)ᵀ(1, q) dq/2 = diag(1, 1/3), tr(W M⁻¹) = (1 + 1/3)/2 there).
        let row = |q: &[f64]| Mat::from_fn(1, 2, |_, k| if k == 0 { 1.0 } else { q[0] });
        let w = Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) => 1.0,
            (1, 1) => 1.0 / 3.0,
            _ => 0.0,
        });
        for criterion in [Criterion::IOptimal, Criterion::DOptimal] {
            let mut poses = vec![vec![-0.3], vec![0.5]];
            let v = coordinate_exchange(&mut poses, &row, criterion, &w, &[(-1.0, 1.0)], 20)
                .expect("design");
            let mut ends: Vec<f64> = poses.iter().map(|q| q[0]).collect();
            ends.sort_by(f64::total_cmp);
            assert!(
                (ends[0] + 1.0).abs() < 1e-9 && (ends[1] - 1.0).abs() < 1e-9,
                "{ends:?}"
            );
            let expected = match criterion {
                Criterion::IOptimal => 2.0 / 3.0,
                _ => -(4.0_f64).ln(),
            };
            assert!((v - expected).abs() < 1e-9, "{criterion}: {v}");
        }
        let err = coordinate_exchange(&mut [vec![0.0]], &row, Criterion::O3, &w, &[(-1.0, 1.0)], 1)
            .expect_err("o3 is not supported");
        assert_eq!(
            err.to_string(),
            "coordinate exchange supports i-optimal and d-optimal, not o3"
        );
    }

    fn iiwa() -> Device {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/mukca/urdf/iiwa14.urdf");
        crate::data::load_device(&path, "ball_link").expect("iiwa 14 URDF")
    }

    fn config(model: ModelChoice) -> PlanConfig {
        PlanConfig {
            measurement: Measurement::Position,
            count: 40,
            n_candidates: 300,
            seed: 3,
            criterion: Criterion::DOptimal,
            sigma_m: Some(5e-5),
            transmission_rows: true,
            refine: false,
            model,
        }
    }

    #[test]
    fn poses_are_planned_for_the_model_asked_for() {
        let device = iiwa();
        let geometric = plan_poses(&device, &config(ModelChoice::Geometric)).expect("geometric");
        let compliance = plan_poses(&device, &config(ModelChoice::Compliance)).expect("compliance");
        let is_compliance = |c: &String| c.starts_with("compliance.");
        assert!(!geometric.columns.iter().any(is_compliance));
        // The iiwa's five loaded joints (a1 and a7 turn about the vertical and the tool
        // axis: no gravity torque) are columns the planned poses must determine.
        let n = compliance
            .columns
            .iter()
            .filter(|c| is_compliance(c))
            .count();
        assert_eq!(n, 5, "{:?}", compliance.columns);
        // The kinematic columns are the same: the model adds its families, nothing else.
        let kinematic = |p: &PosePlan| -> Vec<String> {
            (p.columns.iter())
                .filter(|c| !is_compliance(c))
                .cloned()
                .collect()
        };
        assert_eq!(kinematic(&geometric), kinematic(&compliance));
        // The planned set determines them better than a random one of the same size.
        assert!(compliance.design.log_det > compliance.random.0);
    }

    #[test]
    fn models_the_planner_cannot_plan_for_are_refused_in_words() {
        let device = iiwa();
        for (model, words) in [
            (ModelChoice::Auto, "--model auto"),
            (ModelChoice::FramesOnly, "--model frames-only"),
            (ModelChoice::JointOffsets, "--model joint-offsets"),
            (ModelChoice::Transmissions, "--model transmissions"),
        ] {
            let err = plan_poses(&device, &config(model)).expect_err("refused");
            assert!(err.to_string().contains(words), "{err}");
        }
        let haptic = reference_device();
        let cfg = PlanConfig {
            measurement: Measurement::Distance,
            ..config(ModelChoice::Compliance)
        };
        let err = plan_poses(&haptic, &cfg).expect_err("refused on a haptic device");
        assert!(err.to_string().contains("haptic device"), "{err}");
    }
}
