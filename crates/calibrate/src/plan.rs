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
//! After a calibration, [`plan_after`] (`hapcal plan-poses --data … --workspace …`) plans the
//! poses to add to the rows already measured: the same I-optimal criterion, with the measured
//! rows' information (and the identification's prior) as the design's prior `M₀`
//! ([`hapcal_identify::DesignConfig::prior`]) and the workspace the calibration will be used
//! in as the prediction set; the blocks are rows of the measured rows' own kind at the
//! calibrated estimate.
//!
//! `hapcal pose-bound` (`hapcal_studies::pose_study::design_bound`) answers how well any `N` distance poses can do: the
//! continuous I-optimal design (multiplicative algorithm, [`hapcal_identify::i_optimal_weights`])
//! on uniform candidates, enlarged by column generation with the maxima of its sensitivity over
//! the joint box, and the equivalence-theorem certificate `Φ* ≥ Φ(ξ)²/sup d` that bounds every
//! `N`-pose design by `Φ*/N`; compared with the study's random reference sets.

use crate::model::ModelName;
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

/// The model `choice` names, checked to be one the planner can plan `device`'s poses for, in
/// the user's words:
/// the models `hapcal calibrate` fits to the data of the planned measurement (a haptic device's
/// logs, distance logs, or measurement files), less those that are a choice or fit only
/// instrument frames: `auto` (plan for the richest model you will calibrate), `frames-only`
/// and `joint-offsets` (poses that determine the geometric model determine them), and, on a
/// haptic device, `compliance` (the handle's compliance is not a model of the planner).
///
/// # Errors
/// The refusal, naming the model as the user typed it.
pub fn planned_model(
    device: &Device,
    measurement: Measurement,
    choice: ModelChoice,
) -> Result<ModelName> {
    let haptic = device.has_transmissions();
    let kind = match (haptic, measurement) {
        (true, Measurement::Distance) => DataKind::HapticLogs,
        (false, Measurement::Distance) => DataKind::Distances,
        (_, Measurement::Position) => DataKind::Measurements,
    };
    let ModelChoice::Model(model) = choice else {
        bail!(
            "--model auto: the poses are planned for one model; give the richest you will \
             calibrate (geometric, compliance, …)"
        )
    };
    match model {
        ModelName::FramesOnly | ModelName::JointOffsets => bail!(
            "--model {model}: plan for geometric: poses that determine every kinematic \
             parameter determine the {}",
            if model == ModelName::FramesOnly {
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
    if kind == DataKind::HapticLogs && model == ModelName::Geometric {
        return Ok(model);
    }
    // `hapcal calibrate --model compliance` fits a haptic device's handle compliance with the
    // diagnosis's model (the handle's weight at the end point); the planner's compliance
    // blocks are lumped link weights, another model: it does not plan for it.
    if kind == DataKind::HapticLogs && model == ModelName::Compliance {
        bail!(
            "--model compliance: the pose planner has no model of a haptic device's handle \
             compliance; plan for transmissions (calibrate's compliance fits the logs of those \
             poses)"
        );
    }
    choice.check_fits(kind)?;
    Ok(model)
}

/// Whether `model` frees no family beyond the kinematic deviations (and a haptic device's
/// transmissions, whose rows the blocks carry either way): the plain identification problem
/// plans it.
fn plans_kinematics_only(model: ModelName) -> bool {
    matches!(model, ModelName::Geometric | ModelName::Transmissions)
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
        ModelName::Geometric,
    )
}

/// The transmission basis columns of [`candidate_blocks_for`] (when `transmission_rows`):
/// per transmission joint its index and the evaluator of its basis at a joint angle (rad) — a
/// capstan's linearisation about a perfect drive, the parallelogram joint's Chebyshev basis of
/// degree [`POLY_DEGREE`] — with the columns' names pushed onto `columns`.
///
/// # Errors
/// A parallelogram joint without limits, or a capstan or polynomial that cannot be built.
fn transmission_bases(
    device: &Device,
    transmission_rows: bool,
    columns: &mut Vec<String>,
) -> Result<Vec<(usize, Basis)>> {
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
    Ok(transmissions)
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
    model: ModelName,
) -> Result<Candidates> {
    let chain = device.chain().context("building the kinematic chain")?;
    let chain_for_weight = chain.clone();
    let (sigma_m, sigma_e) = sigmas(device, sigma_m);
    let (kind, rows_per_pose) = match measurement {
        Measurement::Distance => (RowKind::Distance { distance_m: 0.0 }, 1),
        Measurement::Position => (
            RowKind::Position {
                position_m: [0.0; 3],
            },
            3,
        ),
    };
    let obs = Observations {
        rows: readings
            .iter()
            .map(|q| Row {
                q: q[..].into(),
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

    let transmissions = transmission_bases(device, transmission_rows, &mut columns)?;
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
    check_count(cfg.count, cfg.n_candidates)?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let candidates = hapcal_sim::sample_readings(device, &mut rng, cfg.n_candidates);
    if cfg.refine && (cfg.measurement != Measurement::Distance || cfg.transmission_rows) {
        bail!(
            "refining the poses over the joint box needs distance measurements planned without the transmission rows"
        );
    }
    let model = planned_model(device, cfg.measurement, cfg.model)?;
    let kinematic_rows = cfg.measurement == Measurement::Distance && !cfg.transmission_rows;
    if kinematic_rows && !plans_kinematics_only(model) {
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
        model,
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
    let mut readings: Vec<Vec<f64>> = (design.selected.iter())
        .map(|&c| candidates[c].clone())
        .collect();
    let limits = device.joint_limits();
    let refined_value = (cfg.refine)
        .then(|| coordinate_exchange(&mut readings, &row, cfg.criterion, &weight, &limits, 50))
        .transpose()?;
    Ok(PosePlan {
        readings,
        design,
        random,
        columns,
        undetermined,
        refined_value,
    })
}

/// `Ok` when `count` poses can be chosen from `n_candidates`, else the error in words.
fn check_count(count: usize, n_candidates: usize) -> Result<()> {
    if count == 0 || count > n_candidates {
        bail!(
            "--count must be between 1 and the number of candidates ({n_candidates}), got {count}"
        );
    }
    Ok(())
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
    coordinate_exchange_after(poses, row, criterion, w, None, limits, max_sweeps)
}

/// [`coordinate_exchange`] of blocks of any number of rows (`r × n`) added to the information
/// already in hand `prior` (`M₀`, `n × n`; `None`: nothing): `M = M₀ + Σ BᵢᵀBᵢ`. A candidate
/// block `B` for pose `i` is scored by the Woodbury identity, with `S = I + B·N_i·Bᵀ`
/// (`r × r`): `tr(W(M_{−i} + BᵀB)⁻¹) = tr(W·N_i) − tr(S⁻¹·B·N_iWN_i·Bᵀ)` and
/// `log det(M_{−i} + BᵀB) = log det M_{−i} + log det S`.
///
/// # Errors
/// As [`coordinate_exchange`].
///
/// # Panics
/// If `prior` is not `n × n` (misuse).
#[track_caller]
pub fn coordinate_exchange_after(
    poses: &mut [Vec<f64>],
    row: &dyn Fn(&[f64]) -> Mat<f64>,
    criterion: Criterion,
    w: &Mat<f64>,
    prior: Option<&Mat<f64>>,
    limits: &[(f64, f64)],
    max_sweeps: usize,
) -> Result<f64> {
    if !matches!(criterion, Criterion::IOptimal | Criterion::DOptimal) {
        bail!("coordinate exchange supports i-optimal and d-optimal, not {criterion}");
    }
    use faer::linalg::solvers::DenseSolveCore;
    let n = w.nrows();
    if let Some(p) = prior {
        assert!(
            p.nrows() == n && p.ncols() == n,
            "the prior information is {} × {}, the weight {n} × {n}",
            p.nrows(),
            p.ncols()
        );
    }
    let info = |poses: &[Vec<f64>]| {
        let mut m = prior.cloned().unwrap_or_else(|| Mat::<f64>::zeros(n, n));
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
                let r = b.nrows();
                let s = Mat::<f64>::identity(r, r) + &b * &n_i * b.transpose();
                let Ok(s_llt) = s.llt(faer::Side::Lower) else {
                    return f64::INFINITY;
                };
                match criterion {
                    Criterion::IOptimal => {
                        let bab = &b * &a * b.transpose();
                        base - trace_of_product(&s_llt.inverse(), &bab)
                    }
                    _ => base - 2.0 * (0..r).map(|k| s_llt.L()[(k, k)].ln()).sum::<f64>(),
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

/// Settings of [`plan_after`]: the poses to add to rows already measured.
#[derive(Clone, Debug)]
pub struct AfterConfig {
    /// Number of poses to add.
    pub count: usize,
    /// Number of candidate poses sampled uniformly within the joint limits
    /// ([`candidate_limits`]).
    pub n_candidates: usize,
    /// Seed of the candidate sampling (`ChaCha8Rng`).
    pub seed: u64,
    /// [`Criterion::IOptimal`] (the workspace's mean predicted position variance) or
    /// [`Criterion::DOptimal`] (`log det` of the information, measured rows included).
    pub criterion: Criterion,
    /// The model the poses are planned for; [`ModelChoice::Auto`]: the one `hapcal calibrate`
    /// chooses on the measured rows.
    pub model: ModelChoice,
    /// Position (and distance) noise σ, m per axis, if known; else the calibration's estimate
    /// from the training residual.
    pub sigma_m: Option<f64>,
    /// Orientation noise σ of pose rows, rad, if known; else estimated as `calibrate` does.
    pub sigma_rad: Option<f64>,
    /// Refine the chosen poses by [`coordinate_exchange_after`] over the joint box.
    pub refine: bool,
}

/// Where the noise σ of [`AfterPlan::sigma_m`] comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SigmaSource {
    /// `--sigma-m`.
    Stated,
    /// The calibration's residual on the measured rows (its σ per axis).
    TrainingResidual,
}

/// Result of [`plan_after`].
#[derive(Clone, Debug)]
pub struct AfterPlan {
    /// The poses to measure next, rad (m for a prismatic joint), `count` rows in candidate
    /// order (moved off the candidates when refined).
    pub readings: Vec<Vec<f64>>,
    /// The model planned for.
    pub model: ModelName,
    /// Why the model planned for is not the one asked for, in words (auto kept frames only).
    pub model_note: Option<String>,
    /// The columns: parameters of the model that the measured rows and the candidates
    /// determine (the identification's pruning on both).
    pub columns: Vec<String>,
    /// Parameters of the model that neither the measured rows nor any candidate determine.
    pub undetermined: Vec<String>,
    /// Parameters the measured rows alone leave to the prior (pruned on them alone), which
    /// the new poses are rewarded for determining.
    pub unseen: Vec<String>,
    /// Measured rows (configurations) and workspace configurations.
    pub n_measured: usize,
    /// Workspace configurations the prediction is averaged over.
    pub n_workspace: usize,
    /// The noise σ the variances are scaled by, m per axis.
    pub sigma_m: f64,
    /// Where [`AfterPlan::sigma_m`] comes from.
    pub sigma_source: SigmaSource,
    /// RMS over the workspace of the predicted 3-D position σ (m) of the marker(s), base
    /// frame: from the measured rows alone, with the planned poses added, and with the first
    /// `count` candidates (a random set) added instead.
    pub rms_before_m: f64,
    /// As [`AfterPlan::rms_before_m`], the planned poses added.
    pub rms_after_m: f64,
    /// As [`AfterPlan::rms_before_m`], `count` random candidates added.
    pub rms_random_m: f64,
    /// The design over the candidates (before any refinement).
    pub design: Design,
    /// Whether the poses were refined over the joint box.
    pub refined: bool,
    /// Number of candidates.
    pub n_candidates: usize,
    /// The criterion.
    pub criterion: Criterion,
}

/// The box candidates are sampled in, per joint (rad, m for a prismatic joint): the joint's
/// limits, except that a revolute joint whose range spans more than a turn gets one turn
/// centred on its range (a continuous joint's ±1000 rad, a UR's ±2π): every orientation of
/// the joint, once.
pub fn candidate_limits(robot: &crate::data::Robot) -> Vec<(f64, f64)> {
    let turn = std::f64::consts::TAU;
    (robot.limits.iter().enumerate())
        .map(|(j, &(lo, hi))| {
            let prismatic = robot.prismatic.get(j).copied().unwrap_or(false);
            if !prismatic && hi - lo > turn {
                let mid = 0.5 * (lo + hi);
                (mid - 0.5 * turn, mid + 0.5 * turn)
            } else {
                (lo, hi)
            }
        })
        .collect()
}

/// What each planned pose measures, copied from the measured rows: a distance if any row has
/// one, and each marker (with its orientation if any row of it has one).
struct RowShape {
    distance: bool,
    /// Per marker index: whether it is measured with its orientation.
    orientation: Vec<bool>,
}

impl RowShape {
    fn of(tables: &[hapcal_io::MeasurementTable]) -> Self {
        let rows = || tables.iter().flat_map(|t| &t.rows);
        let n_markers = rows()
            .flat_map(|r| r.markers.iter().map(|m| m.marker + 1))
            .max()
            .unwrap_or(0);
        let mut orientation = vec![false; n_markers];
        for m in rows().flat_map(|r| &r.markers) {
            orientation[m.marker] |= m.rotation.is_some();
        }
        Self {
            distance: rows().any(|r| r.distance_m.is_some()),
            orientation,
        }
    }

    /// The row the calibrated `model` predicts at `q`: each sample where the model puts it
    /// (the orientation residual's Jacobian is the one at a zero residual).
    fn predicted(
        &self,
        model: &hapcal_problems::CalibratedModel,
        q: &[f64],
    ) -> hapcal_io::MeasuredRow {
        let tips: Vec<usize> = (0..self.orientation.len()).collect();
        let poses = model.end_poses_of(&tips, q);
        let markers = (self.orientation.iter().zip(poses).enumerate())
            .map(|(marker, (&oriented, pose))| hapcal_io::MarkerSample {
                marker,
                position_m: pose.translation.vector.into(),
                rotation: oriented.then(|| {
                    let c = pose.rotation.coords;
                    [c.w, c.x, c.y, c.z]
                }),
            })
            .collect();
        hapcal_io::MeasuredRow {
            line: 0,
            q: q.into(),
            t_s: None,
            markers,
            distance_m: self
                .distance
                .then(|| model.end_pose_of(0, q).translation.vector.norm()),
        }
    }
}

/// Observations of `rows` as the measured workflow builds them
/// ([`crate::measured::observations`]).
fn observations_of(rows: Vec<hapcal_io::MeasuredRow>, n_markers: usize) -> Observations {
    let table = hapcal_io::MeasurementTable::positions("", "", n_markers, rows);
    crate::measured::observations(
        crate::measured::Training::measured(std::slice::from_ref(&table)),
        &|_, _| true,
    )
}

/// Plans the `cfg.count` poses to measure next, given the rows already `measured`, so that
/// the calibration predicts best at the `workspace` configurations: a sequential I-optimal
/// design (Atkinson, Donev & Tobias, *Optimum Experimental Designs*, 2007, §11.5 and §10.6).
///
/// 1. The model is fitted to the measured rows as `hapcal calibrate --model …` fits it
///    ([`crate::measured::calibrate_measured`]; with [`ModelChoice::Auto`] the model its
///    ladder chooses, geometric when it keeps frames only).
/// 2. At the estimate, one identification Jacobian holds the measured rows, one block per
///    candidate (the rows of the measured rows' kind: distance, markers, poses, each where
///    the model predicts it) and the workspace's marker positions; rows divided by their σ.
/// 3. Columns: the model's parameters that the measured rows and all candidates together
///    determine (the identification's noise-derived pruning, [`identifiability`]).
/// 4. `M₀ = J_measᵀJ_meas + s²·diag(1/p_j²)`: the information of the measured rows plus the
///    identification's prior `p_j` (its plausible deviation per unit, 1 cm and 10 mrad), `s`
///    the noise σ over the rows' weight σ. Directions the measured rows do not see keep the
///    prior's variance, which the new poses are rewarded for reducing.
/// 5. `W = mean_w G_wᵀG_w`, `G_w` the marker positions' derivative (m) at workspace
///    configuration `w` in the robot's base frame (the instrument frame's columns zero).
/// 6. [`select_poses`] with the prior `M₀` chooses `count` candidates minimising
///    `trace(W·(M₀ + Σ BᵢᵀBᵢ)⁻¹)`; with `cfg.refine`, [`coordinate_exchange_after`] moves
///    them over the joint box.
///
/// The predicted variance is `s²·trace(W·M⁻¹)` (m²): `σ²` cancels in the ranking but scales
/// the RMS prediction σ reported before and after.
///
/// # Errors
/// A count of 0 or above the candidates, another criterion, an empty workspace, a model the
/// measurement files cannot determine (or frames only, which has no kinematic parameter to
/// plan for), and the calibration's errors on the measured rows.
pub fn plan_after(
    robot: &crate::data::Robot,
    measured: &[hapcal_io::MeasurementTable],
    workspace: &[Vec<f64>],
    cfg: &AfterConfig,
) -> Result<AfterPlan> {
    check_after(robot, workspace, cfg)?;
    let n_measured: usize = measured.iter().map(|t| t.rows.len()).sum();
    let (out, model_note) = calibrated_for_planning(robot, measured, workspace, cfg, n_measured)?;
    let planning = PlanningProblem::build(robot, measured, workspace, cfg, &out)?;
    let info = PlanningInformation::of(&planning, &out, workspace.len(), cfg.sigma_m)?;
    let design_cfg = DesignConfig {
        weight: Some(info.weight.clone()),
        prior: Some(info.prior.clone()),
        ..DesignConfig::new(cfg.criterion)
    };
    let design =
        select_poses(&info.blocks, cfg.count, &design_cfg).context("choosing the poses")?;
    let mut readings: Vec<Vec<f64>> = (design.selected.iter())
        .map(|&c| planning.candidates[c].clone())
        .collect();
    let x = &out.fitted.x;
    let row = |q: &[f64]| info.row_block(&planning, x, q);
    if cfg.refine {
        coordinate_exchange_after(
            &mut readings,
            &row,
            cfg.criterion,
            &info.weight,
            Some(&info.prior),
            &planning.limits,
            50,
        )?;
    }
    let planned: Vec<Mat<f64>> = readings.iter().map(|q| row(q)).collect();
    let random: Vec<Mat<f64>> = info.blocks.iter().take(cfg.count).cloned().collect();
    Ok(AfterPlan {
        rms_before_m: info.rms(&[]),
        rms_after_m: info.rms(&planned),
        rms_random_m: info.rms(&random),
        readings,
        model: out.rung,
        model_note,
        columns: info.columns,
        undetermined: info.undetermined,
        unseen: info.unseen,
        n_measured,
        n_workspace: workspace.len(),
        sigma_m: info.sigma_m,
        sigma_source: info.sigma_source,
        design,
        refined: cfg.refine,
        n_candidates: cfg.n_candidates,
        criterion: cfg.criterion,
    })
}

/// The checks of [`plan_after`]'s settings before any fit.
///
/// # Errors
/// A count outside 1..=candidates, a criterion other than i- or d-optimal, no workspace or a
/// workspace configuration of another length than the robot's joints, `--model frames-only`
/// or a model that does not fit measurement files.
fn check_after(
    robot: &crate::data::Robot,
    workspace: &[Vec<f64>],
    cfg: &AfterConfig,
) -> Result<()> {
    check_count(cfg.count, cfg.n_candidates)?;
    if !matches!(cfg.criterion, Criterion::IOptimal | Criterion::DOptimal) {
        bail!(
            "--criterion {}: poses added to measured rows are planned i-optimal (the \
             workspace's prediction, the default) or d-optimal",
            cfg.criterion
        );
    }
    if workspace.is_empty() {
        bail!(
            "--workspace: give the joint configurations where the calibration will be used; \
             the poses are planned to predict there"
        );
    }
    let n_joints = robot.joint_names.len();
    if let Some(w) = workspace.iter().find(|w| w.len() != n_joints) {
        bail!(
            "a workspace configuration has {} joint readings, the robot {n_joints}",
            w.len()
        );
    }
    if cfg.model == ModelName::FramesOnly {
        bail!(
            "--model frames-only fits only the instrument and marker frames: no kinematic \
             parameter to plan the poses for; plan for geometric"
        );
    }
    cfg.model.check_fits(DataKind::Measurements)
}

/// The calibration of the measured rows the poses are planned for, and a note of the model
/// when the plan did not name it: with `--model auto` the ladder's choice, geometric where
/// the ladder keeps frames only (the model the new rows are to determine).
///
/// # Errors
/// A calibration of the measured rows that fails.
fn calibrated_for_planning(
    robot: &crate::data::Robot,
    measured: &[hapcal_io::MeasurementTable],
    workspace: &[Vec<f64>],
    cfg: &AfterConfig,
    n_measured: usize,
) -> Result<(crate::measured::MeasuredOutcome, Option<String>)> {
    use crate::measured::{MeasuredConfig, calibrate_measured};
    let calibrate = |rung: Option<ModelName>| {
        let mcfg = MeasuredConfig {
            rung,
            folds: crate::fit::DEFAULT_FOLDS.min(n_measured).max(2),
            sigma_m: cfg.sigma_m,
            sigma_rad: cfg.sigma_rad,
            marker_tips: (0..robot.tree.tips().len()).collect(),
            workspace: workspace.to_vec(),
            ..MeasuredConfig::default()
        };
        calibrate_measured(robot, measured, &[], &mcfg)
            .context("calibrating the measured rows (the model the poses are planned for)")
    };
    let out = calibrate(cfg.model.model())?;
    if out.rung == ModelName::FramesOnly {
        let note = "on the measured rows the calibration keeps frames only (no model beat it \
                    held out): planned for geometric, the model the new rows are to determine";
        return Ok((
            calibrate(Some(ModelName::Geometric))?,
            Some(note.to_owned()),
        ));
    }
    let note = (cfg.model == ModelChoice::Auto).then(|| {
        format!(
            "the model the calibration chooses on the measured rows: {}",
            out.rung
        )
    });
    Ok((out, note))
}

/// One identification problem of [`plan_after`]: the measured rows, then the candidates'
/// rows (predicted by the calibrated model), then the workspace's markers, with its
/// Jacobian at the calibrated estimate.
struct PlanningProblem<'a> {
    /// The calibration the poses are planned for.
    out: &'a crate::measured::MeasuredOutcome,
    /// What each planned pose measures.
    shape: RowShape,
    /// Markers of the measured rows.
    n_markers: usize,
    /// Each joint's candidate range (rad or m).
    limits: Vec<(f64, f64)>,
    /// The candidate joint configurations, drawn uniformly in `limits`.
    candidates: Vec<Vec<f64>>,
    /// Rows of `jac` that carry the measured rows (its first rows): their residuals, or, for
    /// measured rows whose Jacobian would exceed [`hapcal_identify::STREAMING_AUTO_ENTRIES`]
    /// entries, the rows of its R factor (streamed in row blocks), which has the same Gram
    /// matrix and so the same identifiability and information.
    n_measured_residuals: usize,
    /// Residuals of one candidate pose.
    rows_per_pose: usize,
    /// The problem.
    problem: CalibrationProblem,
    /// Its layout (every parameter of the calibration, in its order).
    layout: hapcal_identify::ParamLayout,
    /// Its Jacobian at the calibrated estimate, residuals × parameters (the measured rows'
    /// part possibly reduced to its R factor: see `n_measured_residuals`).
    jac: Mat<f64>,
}

/// The R factor of the Jacobian of the rows `obs` at `x` over `layout`'s parameters
/// (`k × n`, `n = layout.len()`, `Rᵀ·R = Jᵀ·J`): their problem on `problem`'s model
/// (`CalibrationProblem::with_observations`), its Jacobian streamed in row blocks
/// ([`hapcal_identify::jacobian_r_factor`]), its columns placed by name (a parameter the rows
/// do not have, such as the frame of a marker they never see, is a zero column).
///
/// # Errors
/// Rows the model cannot build or evaluate.
fn measured_r_factor(
    problem: &CalibrationProblem,
    layout: &hapcal_identify::ParamLayout,
    x: &faer::Col<f64>,
    obs: Observations,
) -> Result<Mat<f64>> {
    let p = (problem.with_observations(obs)).context("building the measured rows' problem")?;
    let to_full = indices_in(layout, p.layout(), " in the planning problem")?;
    let x_rows = faer::Col::from_fn(to_full.len(), |k| x[to_full[k]]);
    let r = hapcal_identify::jacobian_r_factor(&p, x_rows.as_ref())
        .map_err(|e| anyhow::anyhow!("{e}"))
        .context("evaluating the measured rows' Jacobian")?;
    let mut full = Mat::<f64>::zeros(r.nrows(), layout.len());
    for (k, &c) in to_full.iter().enumerate() {
        full.as_mut().col_mut(c).copy_from(r.col(k));
    }
    Ok(full)
}

/// The index in `layout` of each parameter of `names`, in its order.
///
/// # Errors
/// A parameter `layout` does not hold: "no parameter {name}{where_}".
fn indices_in(
    layout: &hapcal_identify::ParamLayout,
    names: &hapcal_identify::ParamLayout,
    where_: &str,
) -> Result<Vec<usize>> {
    (0..names.len())
        .map(|k| {
            let name = names.name(k);
            (layout.index_of(name)).with_context(|| format!("no parameter {name}{where_}"))
        })
        .collect()
}

impl<'a> PlanningProblem<'a> {
    /// Builds the problem and its Jacobian.
    ///
    /// # Errors
    /// A problem that cannot be built, parameters that differ from the calibration's, or a
    /// Jacobian that cannot be evaluated.
    fn build(
        robot: &crate::data::Robot,
        measured: &[hapcal_io::MeasurementTable],
        workspace: &[Vec<f64>],
        cfg: &AfterConfig,
        out: &'a crate::measured::MeasuredOutcome,
    ) -> Result<Self> {
        let offsets_robot = crate::data::Robot {
            tree: robot.tree.with_joint_offsets(),
            ..robot.clone()
        };
        let terms = crate::measured::terms(out.rung, &offsets_robot)?;
        let shape = RowShape::of(measured);
        let n_markers = shape.orientation.len();
        let n_predicted = n_markers.max(1);
        let limits = candidate_limits(robot);
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let candidates: Vec<Vec<f64>> = (0..cfg.n_candidates)
            .map(|_| {
                (limits.iter())
                    .map(|&(lo, hi)| {
                        let u: f64 = rand::Rng::random(&mut rng);
                        (lo + (hi - lo) * u).clamp(lo, hi)
                    })
                    .collect()
            })
            .collect();
        let mut obs = crate::measured::observations(
            crate::measured::Training::measured(measured),
            &|_, _| true,
        );
        let n_measured_residuals: usize = obs.rows.iter().map(|r| r.kind.n_residuals()).sum();
        // Measured rows too many for one Jacobian are taken by their R factor, in row blocks.
        let n_layout = out.fitted.names.len();
        let blocked =
            n_measured_residuals.saturating_mul(n_layout) > hapcal_identify::STREAMING_AUTO_ENTRIES;
        let measured_obs = blocked.then(|| Observations {
            rows: std::mem::take(&mut obs.rows),
            ..Observations::default()
        });
        let cand = candidate_observations(&shape, out, n_markers, &candidates);
        let rows_per_pose: usize = cand
            .rows
            .iter()
            .map(|r| r.kind.n_residuals())
            .sum::<usize>()
            / candidates.len().max(1);
        obs.rows.extend(cand.rows);
        for q in workspace {
            let tips: Vec<usize> = (0..n_predicted).collect();
            for (tip, pose) in out.model.end_poses_of(&tips, q).into_iter().enumerate() {
                obs.rows.push(Row {
                    q: q[..].into(),
                    kind: RowKind::Marker {
                        tip,
                        position_m: pose.translation.vector.into(),
                    },
                });
            }
        }
        let problem = CalibrationProblem::on_tree(out.tree.clone(), obs, out.weights, terms)
            .context("building the planning problem")?;
        let layout = problem.layout().clone();
        let names: Vec<&str> = (0..layout.len()).map(|i| layout.name(i)).collect();
        if names != out.fitted.names {
            bail!("the planning problem's parameters differ from the calibration's");
        }
        let mut jac = Mat::<f64>::zeros(problem.n_residuals(), layout.len());
        problem
            .jacobian(out.fitted.x.as_ref(), jac.as_mut())
            .map_err(|e| anyhow::anyhow!("{e}"))
            .context("evaluating the identification Jacobian")?;
        let n_measured_residuals = match measured_obs {
            None => n_measured_residuals,
            Some(measured_obs) => {
                let r = measured_r_factor(&problem, &layout, &out.fitted.x, measured_obs)?;
                let k = r.nrows();
                jac = Mat::from_fn(k + jac.nrows(), layout.len(), |i, j| {
                    if i < k { r[(i, j)] } else { jac[(i - k, j)] }
                });
                k
            }
        };
        Ok(Self {
            out,
            shape,
            n_markers,
            limits,
            candidates,
            n_measured_residuals,
            rows_per_pose,
            problem,
            layout,
            jac,
        })
    }
}

/// The observations of candidate configurations `qs`: the rows of the measured rows' kind,
/// as the calibrated model predicts them.
fn candidate_observations(
    shape: &RowShape,
    out: &crate::measured::MeasuredOutcome,
    n_markers: usize,
    qs: &[Vec<f64>],
) -> Observations {
    observations_of(
        qs.iter().map(|q| shape.predicted(&out.model, q)).collect(),
        n_markers,
    )
}

/// Rows `start..start + nrows` of `jac` over the planned columns `kept` (indices of `free`,
/// the calibration's free parameters as columns of `jac`).
fn block_over(
    jac: &Mat<f64>,
    free: &[usize],
    kept: &[usize],
    start: usize,
    nrows: usize,
) -> Mat<f64> {
    Mat::from_fn(nrows, kept.len(), |i, k| jac[(start + i, free[kept[k]])])
}

/// W over the workspace's marker positions (rows from `ws_start` of the planning Jacobian),
/// m per parameter unit, base frame, over the planned columns (`free`, `kept` as in
/// [`block_over`]): the instrument frame's columns, which move no marker in the base frame,
/// left out.
fn workspace_weight(
    planning: &PlanningProblem<'_>,
    (free, kept): (&[usize], &[usize]),
    free_layout: &hapcal_identify::ParamLayout,
    ws_start: usize,
    n_workspace: usize,
) -> Mat<f64> {
    let n = kept.len();
    let n_predicted = planning.n_markers.max(1);
    let sigma_position_m = planning.out.weights.sigma_position_m;
    let instrument: Vec<bool> = (kept.iter())
        .map(|&k| free_layout.name(k).starts_with("instrument."))
        .collect();
    let mut weight = Mat::<f64>::zeros(n, n);
    for i in 0..n_workspace * n_predicted {
        let g = Mat::from_fn(3, n, |a, k| {
            if instrument[k] {
                0.0
            } else {
                sigma_position_m * planning.jac[(ws_start + 3 * i + a, free[kept[k]])]
            }
        });
        weight += g.transpose() * &g;
    }
    weight /= (n_workspace * n_predicted) as f64;
    weight
}

/// What [`plan_after`]'s design reads of the planning problem: the columns it plans for (the
/// calibration's free parameters the measured rows and candidates determine), the measured
/// rows' information as the prior, each candidate's block and the workspace's weight.
struct PlanningInformation {
    /// The calibration's free parameters, as indices of the planning layout.
    free: Vec<usize>,
    /// The columns planned for, as indices of `free`.
    kept: Vec<usize>,
    /// Their names.
    columns: Vec<String>,
    /// Columns the measured rows alone do not determine (frames left out).
    unseen: Vec<String>,
    /// Columns neither the measured rows nor the candidates determine (frames left out).
    undetermined: Vec<String>,
    /// The measurement σ, m.
    sigma_m: f64,
    /// Where `sigma_m` comes from.
    sigma_source: SigmaSource,
    /// `sigma_m` over the weights' σ: the scale of the scaled Jacobian's rows.
    s: f64,
    /// The measured rows' information plus the identification's prior, n × n.
    prior: Mat<f64>,
    /// Each candidate's rows over the planned columns.
    blocks: Vec<Mat<f64>>,
    /// W over the workspace's marker positions, m² per parameter unit², base frame.
    weight: Mat<f64>,
}

impl PlanningInformation {
    /// The design's inputs from the planning problem; `n_workspace` workspace configurations,
    /// `stated_sigma_m` the plan's σ if any.
    ///
    /// # Errors
    /// A free parameter of the calibration the planning layout does not hold.
    fn of(
        planning: &PlanningProblem<'_>,
        out: &crate::measured::MeasuredOutcome,
        n_workspace: usize,
        stated_sigma_m: Option<f64>,
    ) -> Result<Self> {
        let (jac, layout) = (&planning.jac, &planning.layout);
        let id = &out.fitted.identified;
        let free_layout = &id.layout;
        let free = indices_in(layout, free_layout, "")?;
        let n_measured_residuals = planning.n_measured_residuals;
        let n_candidate_residuals = planning.rows_per_pose * planning.candidates.len();
        let weights = out.weights;
        let sigma_w = if planning.shape.orientation.is_empty() {
            weights.sigma_distance_m
        } else {
            weights.sigma_position_m
        };
        let (sigma_m, sigma_source) = match stated_sigma_m {
            Some(s) => (s, SigmaSource::Stated),
            None => (sigma_w * id.sigma, SigmaSource::TrainingResidual),
        };
        let s = sigma_m / sigma_w;
        let rank = crate::fit::identify_config(None).rank.with_sigma(s);
        let all: Vec<usize> = (0..free.len()).collect();
        let n_residuals = n_measured_residuals + n_candidate_residuals;
        let stacked = block_over(jac, &free, &all, 0, n_residuals);
        let ident = identifiability(stacked.as_ref(), free_layout, &all, &rank);
        let measured_jac = block_over(jac, &free, &all, 0, n_measured_residuals);
        let seen = identifiability(measured_jac.as_ref(), free_layout, &all, &rank);
        let kept = ident.kept.clone();
        let columns: Vec<String> = (kept.iter())
            .map(|&k| free_layout.name(k).to_owned())
            .collect();
        let unseen: Vec<String> = (kept.iter())
            .filter(|k| !seen.kept.contains(k))
            .map(|&k| free_layout.name(k).to_owned())
            .filter(|name| !crate::report::is_frame_param(name))
            .collect();
        let undetermined: Vec<String> = (ident.pruned_names().into_iter())
            .filter(|name| !crate::report::is_frame_param(name))
            .map(str::to_owned)
            .collect();
        let block_of = |start: usize, nrows: usize| block_over(jac, &free, &kept, start, nrows);
        let mut prior = block_of(0, n_measured_residuals);
        prior = prior.transpose() * &prior;
        for (k, &j) in kept.iter().enumerate() {
            let p = rank.prior_scale(free_layout.spec(j).unit);
            prior[(k, k)] += (s / p).powi(2);
        }
        let blocks = (0..planning.candidates.len())
            .map(|c| {
                block_of(
                    n_measured_residuals + c * planning.rows_per_pose,
                    planning.rows_per_pose,
                )
            })
            .collect();
        let weight = workspace_weight(
            planning,
            (&free, &kept),
            free_layout,
            n_residuals,
            n_workspace,
        );
        Ok(Self {
            free,
            kept,
            columns,
            unseen,
            undetermined,
            sigma_m,
            sigma_source,
            s,
            prior,
            blocks,
            weight,
        })
    }

    /// The block of one configuration `q` off the candidates (coordinate exchange), at the
    /// calibrated estimate `x`; zeros where the model cannot evaluate it.
    fn row_block(&self, planning: &PlanningProblem<'_>, x: &faer::Col<f64>, q: &[f64]) -> Mat<f64> {
        let n = self.kept.len();
        let one = candidate_observations(
            &planning.shape,
            planning.out,
            planning.n_markers,
            std::slice::from_ref(&q.to_vec()),
        );
        let Ok(p) = planning.problem.with_observations(one) else {
            return Mat::zeros(planning.rows_per_pose, n);
        };
        let mut j = Mat::<f64>::zeros(p.n_residuals(), planning.layout.len());
        if p.jacobian(x.as_ref(), j.as_mut()).is_err() {
            return Mat::zeros(planning.rows_per_pose, n);
        }
        block_over(&j, &self.free, &self.kept, 0, p.n_residuals())
    }

    /// RMS prediction σ over the workspace, m, with the measured rows and `added` blocks.
    fn rms(&self, added: &[Mat<f64>]) -> f64 {
        use faer::linalg::solvers::DenseSolveCore;
        let mut m = self.prior.clone();
        for b in added {
            m += b.transpose() * b;
        }
        m.llt(faer::Side::Lower).map_or(f64::INFINITY, |llt| {
            self.s
                * trace_of_product(&self.weight, &llt.inverse())
                    .max(0.0)
                    .sqrt()
        })
    }
}

/// [`plan_after`] on files: the rows already measured in the measurement files `files`
/// (marker positions, poses or anchor distances, as calibrate reads them) on the robot of
/// `device` (read from `device_path`, a URDF with the tip link `tip`, or a D-H device file),
/// and the joint configurations of the CSV `workspace`, in `units`.
///
/// # Errors
/// A haptic device, no `workspace`, a file that is not a measurement file, unreadable files (file, line,
/// column), and as [`plan_after`].
pub fn plan_after_files(
    device_path: &std::path::Path,
    tip: &str,
    device: &Device,
    files: &[std::path::PathBuf],
    workspace: Option<&std::path::Path>,
    units: &hapcal_io::Units,
    cfg: &AfterConfig,
) -> Result<AfterPlan> {
    use crate::data;
    if device.has_transmissions() {
        bail!(
            "{}: --data plans poses to add to measurement files of a robot (marker positions, \
             poses, anchor distances); a haptic device's poses are planned without --data",
            device_path.display()
        );
    }
    let Some(workspace) = workspace else {
        bail!(
            "--workspace: give the joint configurations where the calibration will be used (a \
             CSV with the data's joint columns); the poses are planned to predict there"
        );
    };
    for path in files {
        data::check_csv_header(path)?;
        if !data::is_marker_file(path, device.cable_encoder.is_none()) {
            bail!(
                "{}: not a measurement file: --data takes marker positions (x,y,z), poses \
                 (qw,qx,qy,qz) or anchor distances (distance_m) with the joint columns",
                path.display()
            );
        }
    }
    let is_urdf = (device_path.extension()).is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    let robot = if is_urdf {
        data::robot_from_urdf(device_path, &[tip.to_owned()])?
    } else {
        data::robot_from_device(device)?
    };
    let measured = data::load_tables(files, &robot, units)?;
    let configurations = data::workspace_configurations(workspace, &robot, units)?;
    plan_after(&robot, &measured, &configurations, cfg)
}

/// Text summary of [`plan_after`]: the model, the columns, the noise σ and the workspace's
/// RMS prediction σ before and after (and after as many random poses).
pub fn after_summary(plan: &AfterPlan) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let d = &plan.design;
    let _ = writeln!(
        s,
        "planned {} poses to add to {} measured rows, for the {} model, from {} candidates by \
         {} over {} workspace configurations ({} exchanges{}{}); {} columns",
        plan.readings.len(),
        plan.n_measured,
        plan.model,
        plan.n_candidates,
        plan.criterion,
        plan.n_workspace,
        d.n_exchanges,
        if d.converged { "" } else { ", not converged" },
        if plan.refined {
            ", refined over the joint box"
        } else {
            ""
        },
        plan.columns.len()
    );
    if let Some(note) = &plan.model_note {
        let _ = writeln!(s, "model: {note}");
    }
    if !plan.undetermined.is_empty() {
        let _ = writeln!(
            s,
            "left out (pruned as the identification prunes them: collinear with the frames or kept parameters, or undetermined by any pose): {}",
            plan.undetermined.join(", ")
        );
    }
    if !plan.unseen.is_empty() {
        let _ = writeln!(
            s,
            "the measured rows alone do not determine: {}",
            plan.unseen.join(", ")
        );
    }
    let _ = writeln!(
        s,
        "predicted tip position σ over the workspace (RMS of the 3-D σ, base frame), noise σ \
         {:.4} mm per axis ({}):",
        plan.sigma_m * 1e3,
        match plan.sigma_source {
            SigmaSource::Stated => "--sigma-m",
            SigmaSource::TrainingResidual => "the calibration's residual on the measured rows",
        }
    );
    let n = plan.readings.len();
    for (label, value) in [
        ("the measured rows".to_owned(), plan.rms_before_m),
        (format!("+ the {n} planned poses"), plan.rms_after_m),
        (format!("+ {n} random poses"), plan.rms_random_m),
    ] {
        let _ = writeln!(s, "  {label:<26}{:>10.4} mm", value * 1e3);
    }
    s
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

    /// The workspace weight of the line `(1, q)` on `q` uniform in `[−1, 1]`:
    /// `W = ∫(1, q)ᵀ(1, q) dq/2 = diag(1, 1/3)`.
    fn line_workspace_weight() -> Mat<f64> {
        Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) => 1.0,
            (1, 1) => 1.0 / 3.0,
            _ => 0.0,
        })
    }

    #[test]
    fn coordinate_exchange_moves_a_line_design_to_the_ends_of_the_range() {
        // Straight line (1, q) on [−1, 1]: the D- and I-optimal 2-point designs are {−1, 1}
        // (I: W = ∫(1, q)ᵀ(1, q) dq/2 = diag(1, 1/3), tr(W M⁻¹) = (1 + 1/3)/2 there).
        let row = |q: &[f64]| Mat::from_fn(1, 2, |_, k| if k == 0 { 1.0 } else { q[0] });
        let w = line_workspace_weight();
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

    #[test]
    fn coordinate_exchange_after_a_prior_scores_blocks_of_several_rows() {
        // A pose measures the line (1, q) twice: the block [[1, q], [1, q]], information
        // 2·vvᵀ with v = (1, q). With the prior P = 10·I and W = diag(1, 1/3), adding one pose
        // lowers tr(W·M⁻¹) by 2·vᵀP⁻¹WP⁻¹v/(1 + 2·vᵀP⁻¹v) (Sherman–Morrison), which grows with
        // q² for P = p·I, p > 4: the pose goes to an end of [−1, 1].
        let row = |q: &[f64]| Mat::from_fn(2, 2, |_, k| if k == 0 { 1.0 } else { q[0] });
        let w = line_workspace_weight();
        let prior = Mat::<f64>::identity(2, 2) * 10.0;
        let mut poses = vec![vec![0.3]];
        let v = coordinate_exchange_after(
            &mut poses,
            &row,
            Criterion::IOptimal,
            &w,
            Some(&prior),
            &[(-1.0, 1.0)],
            20,
        )
        .expect("design");
        assert!((poses[0][0].abs() - 1.0).abs() < 1e-9, "{poses:?}");
        // M = 10·I + 2·(1, ±1)ᵀ(1, ±1) = [[12, ±2], [±2, 12]], M⁻¹ = [[12, ∓2], [∓2, 12]]/140:
        // tr(W·M⁻¹) = (12 + 12/3)/140.
        assert!((v - 16.0 / 140.0).abs() < 1e-12, "{v}");
    }

    #[test]
    fn the_measured_rows_r_factor_has_their_jacobians_gram_matrix() {
        // The iiwa's geometric problem on 50 marker rows: the R factor streamed in the
        // problem's row blocks against the Jacobian of all rows at once.
        let robot = crate::data::robot_from_device(&iiwa()).expect("robot");
        let terms = crate::measured::terms(ModelName::Geometric, &robot).expect("terms");
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let rows: Vec<Row> = (0..50)
            .map(|_| Row {
                q: (robot.limits.iter())
                    .map(|&(lo, hi)| rand::Rng::random_range(&mut rng, lo..hi))
                    .collect(),
                kind: RowKind::Marker {
                    tip: 0,
                    position_m: [0.0; 3],
                },
            })
            .collect();
        let obs = |rows: &[Row]| Observations {
            rows: rows.to_vec(),
            ..Observations::default()
        };
        let problem =
            CalibrationProblem::on_tree(robot.tree.clone(), obs(&rows), Weights::default(), terms)
                .expect("problem");
        let layout = problem.layout().clone();
        let x = faer::Col::<f64>::zeros(layout.len());
        let mut jac = Mat::<f64>::zeros(problem.n_residuals(), layout.len());
        problem
            .jacobian(x.as_ref(), jac.as_mut())
            .expect("jacobian");
        let r = measured_r_factor(&problem, &layout, &x, obs(&rows)).expect("r factor");
        assert_eq!((r.nrows(), r.ncols()), (layout.len(), layout.len()));
        let (gram, from_r) = (jac.transpose() * &jac, r.transpose() * &r);
        // Rounding of a QR over entries of order 1 (m per rad): relative to the largest entry.
        let scale = (0..gram.nrows())
            .map(|i| gram[(i, i)])
            .fold(0.0_f64, f64::max);
        for i in 0..gram.nrows() {
            for j in 0..gram.ncols() {
                let d = (gram[(i, j)] - from_r[(i, j)]).abs();
                assert!(
                    d <= 1e-12 * scale,
                    "({i}, {j}): {} vs {}",
                    gram[(i, j)],
                    from_r[(i, j)]
                );
            }
        }
    }

    fn iiwa() -> Device {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/mukca/urdf/iiwa14.urdf");
        crate::data::load_device(&path, "ball_link").expect("iiwa 14 URDF")
    }

    fn config(model: impl Into<ModelChoice>) -> PlanConfig {
        PlanConfig {
            measurement: Measurement::Position,
            count: 40,
            n_candidates: 300,
            seed: 3,
            criterion: Criterion::DOptimal,
            sigma_m: Some(5e-5),
            transmission_rows: true,
            refine: false,
            model: model.into(),
        }
    }

    #[test]
    fn poses_are_planned_for_the_model_asked_for() {
        let device = iiwa();
        let geometric = plan_poses(&device, &config(ModelName::Geometric)).expect("geometric");
        let compliance = plan_poses(&device, &config(ModelName::Compliance)).expect("compliance");
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
            (ModelName::FramesOnly.into(), "--model frames-only"),
            (ModelName::JointOffsets.into(), "--model joint-offsets"),
            (ModelName::Transmissions.into(), "--model transmissions"),
        ] {
            let err = plan_poses(&device, &config(model)).expect_err("refused");
            assert!(err.to_string().contains(words), "{err}");
        }
        let haptic = reference_device();
        let cfg = PlanConfig {
            measurement: Measurement::Distance,
            ..config(ModelName::Compliance)
        };
        let err = plan_poses(&haptic, &cfg).expect_err("refused on a haptic device");
        assert!(err.to_string().contains("haptic device"), "{err}");
    }
}
