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
//! `hapcal pose-bound` ([`design_bound`]) answers how well any `N` distance poses can do: the
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
use hapcal_io::{Device, LogRow, N_EXT};
use hapcal_problems::{CalibrationProblem, Observations, Row, RowKind, Weights};
use hapcal_sim::NoiseModel;
use hapcal_transmission::Chebyshev;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Degree of the parallelogram joint's error polynomial (as in [`crate::paper::POLY_DEGREE`]).
const POLY_DEGREE: usize = crate::paper::POLY_DEGREE;

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
    let sigma_e = paper.map_or(std::f64::consts::TAU / 20_000.0 / 3.0, |n| n.sigma_e_rad);
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
    /// validation, [`crate::paper::validate`]): the kinematic point Jacobian, with zero columns
    /// for the parameters of a fixed first D-H row (rig → base, which do not move the end
    /// point in the base frame), and for a transmission coefficient the joint's column of the
    /// geometric Jacobian times the basis function. With rows divided by σ,
    /// `trace(W·(JᵀJ)⁻¹)` is the mean end-point position variance (m²) over the candidates,
    /// the target of [`Criterion::IOptimal`].
    pub weight: Mat<f64>,
}

/// Per parameter of `chain`: whether it belongs to a fixed first D-H row of `device` (the rig →
/// base transform, invisible in the base frame).
fn fixed_base_row_params(device: &Device, chain: &hapcal_kinematics::Chain) -> Vec<bool> {
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
    let problem = CalibrationProblem::new(chain, obs, weights, None)?;
    let layout = problem.layout().clone();
    let x0 = problem.initial_guess();
    let mut jac = Mat::<f64>::zeros(problem.n_residuals(), layout.len());
    problem
        .jacobian(x0.as_ref(), jac.as_mut())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    // Residuals are divided by σ, so σ = 1 in residual units.
    let rank = crate::calibrate::identify_config(None).rank.with_sigma(1.0);
    let candidates: Vec<usize> = (0..layout.len()).collect();
    let ident = identifiability(jac.as_ref(), &layout, &candidates, &rank);
    let kept = ident.kept.clone();
    let mut columns: Vec<String> = kept.iter().map(|&j| layout.name(j).to_owned()).collect();

    // Transmission basis columns: (joint index, basis function count, evaluator).
    let parallelogram = device
        .parallelogram
        .is_some()
        .then_some(crate::paper::PARALLELOGRAM_JOINT);
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
            let ratio = c.ratio;
            for name in ["c", "a", "sin", "cos", "sin_r", "cos_r"] {
                columns.push(format!("capstan{}.{name}", c.joint));
            }
            transmissions.push((
                j,
                Box::new(move |t: f64| {
                    vec![
                        1.0,
                        t,
                        t.sin(),
                        t.cos() - 1.0,
                        (ratio * t).sin(),
                        (ratio * t).cos() - 1.0,
                    ]
                }),
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
/// (seed `cfg.seed`), builds their blocks ([`candidate_blocks`]) and chooses with
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
    let kinematic_rows = cfg.measurement == Measurement::Distance && !cfg.transmission_rows;
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
    } = candidate_blocks(
        device,
        &candidates,
        cfg.measurement,
        cfg.sigma_m,
        cfg.transmission_rows,
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
fn trace_of_product(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
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

/// Simulates the truth device at given readings: the planned-pose counterpart of
/// [`hapcal_sim::simulate`], with the same noise and quantisation (per pose, one standard normal
/// for the distance, then one per external encoder, from `ChaCha8Rng::seed_from_u64(seed)`).
///
/// # Errors
/// The errors of the truth transmissions ([`hapcal_sim::true_joint_angles`]).
pub fn simulate_at(
    r: &crate::paper::Reference,
    readings: &[Vec<f64>],
    seed: u64,
) -> Result<Vec<LogRow>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let has_ext: Vec<bool> = (0..N_EXT)
        .map(|k| r.device.capstans.iter().any(|c| c.joint == k + 1))
        .collect();
    readings
        .iter()
        .enumerate()
        .map(|(pose_idx, theta)| {
            let q = hapcal_sim::quantise_readings(&r.device, theta);
            let q_true = hapcal_sim::true_joint_angles(&r.device, &r.truth, &q)?;
            let p = r.chain.end_point(&r.x_truth, &q_true);
            let z_m: f64 = rng.sample(StandardNormal);
            let ext = (0..N_EXT)
                .map(|k| {
                    let z_e: f64 = rng.sample(StandardNormal);
                    has_ext[k].then(|| q_true[k] + r.noise.sigma_e_rad * z_e)
                })
                .collect();
            Ok(LogRow {
                q,
                distance_m: p.coords.norm() + r.noise.sigma_m_m * z_m,
                ext,
                t_s: None,
                line: pose_idx as u64 + 2,
            })
        })
        .collect()
}

/// Validation position RMS (m, base frame, 200 fresh poses from `validation_seed`) after the
/// paper's two-step calibration on `rows`; step 1 uses `shared` when given, else `rows`' own
/// external encoders.
fn calibrate_and_validate(
    r: &crate::paper::Reference,
    rows: &[LogRow],
    shared: Option<&crate::paper::TransmissionFit>,
    validation_seed: u64,
) -> Result<f64> {
    let own;
    let t = match shared {
        Some(t) => t,
        None => {
            own = crate::paper::identify_transmissions(r, rows)?;
            &own
        }
    };
    let (_, kin) = crate::paper::identify_kinematics(r, rows, Some(t))?;
    let (v, _) = crate::paper::validate(r, validation_seed, 200, t, &kin, &kin)?;
    Ok(v.position_rms_after_m)
}

/// Where step 1 of the study (the transmission identification, paper Fig. 6) gets its
/// external-encoder data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TransmissionData {
    /// Each calibration's own poses: planning `N` poses also decides the `N` external-encoder
    /// readings of step 1 (the study before issue #5's decomposition).
    SamePoses,
    /// One external-encoder run shared by every arm of a seed: the seed's `n_random`-pose
    /// random log (the reference's own step 1). Only the distance poses of step 2 are planned
    /// or random. The paper identifies the transmissions in a separate step with encoders
    /// mounted for it (simulation section: 200 poses "for each transmission mechanism and
    /// end-effector").
    Shared,
    /// Step 1 from a noise-free external-encoder run of [`NOISE_FREE_EXT_POSES`] random poses:
    /// the transmissions as well as the models can know them (the joint-4 polynomial's
    /// approximation error stays), to isolate step 2.
    NoiseFree,
}

impl TransmissionData {
    /// The flag value (`same-poses`, `shared`, `noise-free`).
    pub fn name(self) -> &'static str {
        match self {
            TransmissionData::SamePoses => "same-poses",
            TransmissionData::Shared => "shared",
            TransmissionData::NoiseFree => "noise-free",
        }
    }
}

/// Poses of the noise-free external-encoder run of [`TransmissionData::NoiseFree`].
pub const NOISE_FREE_EXT_POSES: usize = 2000;

/// Settings of [`pose_study`].
#[derive(Clone, Debug)]
pub struct StudyConfig {
    /// Seeds `0..seeds`.
    pub seeds: u64,
    /// Planned (and random) pose counts to compare.
    pub counts: Vec<usize>,
    /// Size of the random reference set (the paper's 200).
    pub n_random: usize,
    /// Candidates per plan.
    pub n_candidates: usize,
    /// Criterion of the plan.
    pub criterion: Criterion,
    /// Step 1's data.
    pub transmissions: TransmissionData,
    /// Refine each plan by [`coordinate_exchange`] over the joint box.
    pub refine: bool,
    /// Weight each candidate's distance row by the shared step 1's transmission uncertainty at
    /// that pose ([`transmission_variances`], [`plan_poses_weighted`]).
    pub weight_rows: bool,
}

/// Per-count medians of the study.
#[derive(Clone, Debug)]
pub struct StudyRow {
    /// Number of poses.
    pub count: usize,
    /// Median validation position RMS with planned poses, m.
    pub planned_m: f64,
    /// Median with the same number of random poses, m.
    pub random_m: f64,
    /// Seeds where the planned poses beat that seed's `n_random` random poses.
    pub planned_wins: usize,
}

/// Result of [`pose_study`].
#[derive(Clone, Debug)]
pub struct Study {
    /// Median validation position RMS with `n_random` random poses, m.
    pub reference_m: f64,
    /// One row per count.
    pub rows: Vec<StudyRow>,
    /// Per seed: the `n_random` reference, then per count (planned, random), m.
    pub per_seed: Vec<(f64, Vec<(f64, f64)>)>,
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Monte Carlo comparison of planned and random poses on the reference device with distance
/// data (issue #5): per seed `s`, the paper's two-step calibration from `n_random` random poses
/// (`hapcal_sim::simulate`, seed `s`) and, for each count `N`, from `N` planned poses (candidates
/// from seed `s + 2_000_000`, noise from seed `s + 3_000_000`) and from `N` random poses (seed
/// `s`); every calibration is validated on the same 200 fresh poses (seed `s + 1_000_000`).
///
/// # Errors
/// Simulation or identification failures.
pub fn pose_study(
    r: &crate::paper::Reference,
    cfg: &StudyConfig,
    progress: &dyn Fn(u64),
) -> Result<Study> {
    let mut per_seed = Vec::new();
    for seed in 0..cfg.seeds {
        let validation_seed = seed + 1_000_000;
        let sim = |n: usize| {
            let c = hapcal_sim::SimConfig::new(seed, n).with_noise(r.noise);
            hapcal_sim::simulate(&r.device, &r.truth, &c)
        };
        let reference_rows = sim(cfg.n_random)?;
        let shared = match cfg.transmissions {
            TransmissionData::SamePoses => None,
            TransmissionData::Shared => {
                Some(crate::paper::identify_transmissions(r, &reference_rows)?)
            }
            TransmissionData::NoiseFree => {
                let c = hapcal_sim::SimConfig::new(seed + 4_000_000, NOISE_FREE_EXT_POSES)
                    .with_noise(NoiseModel::new(0.0, r.noise.sigma_m_m));
                let rows = hapcal_sim::simulate(&r.device, &r.truth, &c)?;
                Some(crate::paper::identify_transmissions(r, &rows)?)
            }
        };
        let reference =
            calibrate_and_validate(r, &reference_rows, shared.as_ref(), validation_seed)
                .with_context(|| format!("seed {seed}: {} random poses", cfg.n_random))?;
        let table = shared
            .as_ref()
            .map(|t| VarianceTable::new(t, &r.device.joint_limits(), 2001));
        let joint_var = table.as_ref().map(|table| move |q: &[f64]| table.eval(q));
        let mut by_count = Vec::new();
        for &count in &cfg.counts {
            let plan = plan_poses_weighted(
                &r.device,
                &PlanConfig {
                    measurement: Measurement::Distance,
                    count,
                    n_candidates: cfg.n_candidates,
                    seed: seed + 2_000_000,
                    criterion: cfg.criterion,
                    sigma_m: Some(r.noise.sigma_m_m),
                    transmission_rows: cfg.transmissions == TransmissionData::SamePoses,
                    refine: cfg.refine,
                },
                joint_var
                    .as_ref()
                    .filter(|_| cfg.weight_rows)
                    .map(|f| f as &JointVariance<'_>),
            )?;
            let rows = simulate_at(r, &plan.readings, seed + 3_000_000)?;
            let planned = calibrate_and_validate(r, &rows, shared.as_ref(), validation_seed)
                .with_context(|| format!("seed {seed}: {count} planned poses"))?;
            let random = calibrate_and_validate(r, &sim(count)?, shared.as_ref(), validation_seed)
                .with_context(|| format!("seed {seed}: {count} random poses"))?;
            by_count.push((planned, random));
        }
        per_seed.push((reference, by_count));
        progress(seed + 1);
    }
    let reference_m = median(&per_seed.iter().map(|s| s.0).collect::<Vec<_>>());
    let rows = cfg
        .counts
        .iter()
        .enumerate()
        .map(|(k, &count)| StudyRow {
            count,
            planned_m: median(&per_seed.iter().map(|s| s.1[k].0).collect::<Vec<_>>()),
            random_m: median(&per_seed.iter().map(|s| s.1[k].1).collect::<Vec<_>>()),
            planned_wins: per_seed.iter().filter(|s| s.1[k].0 <= s.0).count(),
        })
        .collect();
    Ok(Study {
        reference_m,
        rows,
        per_seed,
    })
}

/// The study as Markdown (`docs/results/pose-selection.md`), with the command that made it.
pub fn study_markdown(study: &Study, cfg: &StudyConfig, command: &str) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Pose selection: planned vs random poses (reference device, distance data)\n"
    );
    let _ = writeln!(s, "Written by `{command}`.\n");
    let step1 = match cfg.transmissions {
        TransmissionData::SamePoses => {
            "Step 1 (transmissions) is fitted from the external encoders read at each \
             calibration's own poses, so the plan also covers the linearised transmission rows."
                .to_owned()
        }
        TransmissionData::Shared => format!(
            "Step 1 (transmissions) is fitted once per seed from the external encoders of the \
             seed's {}-pose random log and shared by every calibration of that seed; only the \
             cable-distance poses of step 2 are planned or random, and the plan uses the \
             kinematic distance rows alone.",
            cfg.n_random
        ),
        TransmissionData::NoiseFree => format!(
            "Step 1 (transmissions) is fitted once per seed from a noise-free external-encoder \
             run of {NOISE_FREE_EXT_POSES} random poses (transmissions known up to the joint-4 \
             polynomial's approximation error) and shared by every calibration; only the \
             cable-distance poses of step 2 are planned or random."
        ),
    };
    let _ = writeln!(
        s,
        "Paper pipeline (step 1 transmissions from the external encoders, step 2 kinematics from \
         cable distances) on the simulated reference device (fixtures/reference-device, paper \
         noise), validated on 200 fresh poses per seed (position RMS in the device base frame). \
         {step1} Planned poses: {} by greedy start + DETMAX exchange over {} candidates sampled \
         uniformly within the joint limits{}, using the Jacobian at the nominal model (see \
         `crates/cli/src/plan.rs`). Seeds 0..{}.\n",
        cfg.criterion,
        cfg.n_candidates,
        match (cfg.refine, cfg.weight_rows) {
            (true, true) => {
                ", then coordinate exchange over the joint box, with each distance row weighted by \
                 the shared step 1's transmission uncertainty at its pose"
            }
            (true, false) => ", then coordinate exchange over the joint box",
            (false, true) => {
                ", with each distance row weighted by the shared step 1's transmission \
                 uncertainty at its pose"
            }
            (false, false) => "",
        },
        cfg.seeds
    );
    let _ = writeln!(
        s,
        "Median validation position RMS with {} random poses: **{:.4} mm**.\n",
        cfg.n_random,
        study.reference_m * 1e3
    );
    let _ = writeln!(
        s,
        "| poses | planned: median RMS (mm) | random: median RMS (mm) | planned ≤ {} random (median) | seeds where planned ≤ that seed's {} random |",
        cfg.n_random, cfg.n_random
    );
    let _ = writeln!(s, "|---|---|---|---|---|");
    for row in &study.rows {
        let _ = writeln!(
            s,
            "| {} | {:.4} | {:.4} | {} | {}/{} |",
            row.count,
            row.planned_m * 1e3,
            row.random_m * 1e3,
            if row.planned_m <= study.reference_m {
                "yes"
            } else {
                "no"
            },
            row.planned_wins,
            cfg.seeds
        );
    }
    let _ = writeln!(
        s,
        "\nPer seed, validation position RMS (mm): {} random | planned, random for each count",
        cfg.n_random
    );
    let _ = writeln!(s);
    let mut header = format!("| seed | {} random |", cfg.n_random);
    for c in &cfg.counts {
        let _ = write!(header, " {c} planned | {c} random |");
    }
    let _ = writeln!(s, "{header}");
    let _ = writeln!(s, "|{}", "---|".repeat(2 + 2 * cfg.counts.len()));
    for (seed, (reference, by_count)) in study.per_seed.iter().enumerate() {
        let mut line = format!("| {seed} | {:.4} |", reference * 1e3);
        for (planned, random) in by_count {
            let _ = write!(line, " {:.4} | {:.4} |", planned * 1e3, random * 1e3);
        }
        let _ = writeln!(s, "{line}");
    }
    let fewest = study
        .rows
        .iter()
        .filter(|r| r.planned_m <= study.reference_m)
        .map(|r| r.count)
        .min();
    let _ = writeln!(
        s,
        "\nFewest planned poses (of the counts tried) whose median reaches the {}-random median: {}.",
        cfg.n_random,
        fewest.map_or_else(|| "none".to_owned(), |n| n.to_string())
    );
    s
}

/// Flags of `hapcal plan-poses`.
#[derive(Clone, Debug, clap::Args)]
pub struct PlanArgs {
    /// Device file (.toml) or URDF (.urdf, with --tip).
    #[arg(long)]
    pub device: std::path::PathBuf,
    /// Tip link when the device is a URDF.
    #[arg(long, default_value = "ball_link")]
    pub tip: String,
    /// What the rig measures.
    #[arg(long, value_enum, default_value_t = Measurement::Distance)]
    pub measurement: Measurement,
    /// Number of poses to choose.
    #[arg(long, default_value_t = 30)]
    pub count: usize,
    /// Candidate poses sampled uniformly within the joint limits.
    #[arg(long, default_value_t = 1000)]
    pub candidates: usize,
    /// Seed of the candidate sampling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Criterion: d-optimal (= o1 for a fixed count), o3, o4 or o5.
    #[arg(long, default_value = "d-optimal")]
    pub criterion: Criterion,
    /// Measurement noise σ, m (default: the paper's σ_m of the cable encoder, else 10 µm).
    #[arg(long)]
    pub sigma_m: Option<f64>,
    /// The transmissions are identified from a separate external-encoder run: plan the
    /// measurement poses alone (without the external-encoder rows).
    #[arg(long)]
    pub separate_transmission_run: bool,
    /// Refine the chosen poses by coordinate exchange over the joint box (distance, with
    /// --separate-transmission-run; i-optimal or d-optimal).
    #[arg(long)]
    pub refine: bool,
    /// Output CSV (joint readings, rad, one pose per row).
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// Runs `hapcal plan-poses`: returns the summary to print and the path written.
///
/// # Errors
/// Unreadable device, invalid flags, a design failure, or an unwritable output.
pub fn run_plan(args: &PlanArgs) -> Result<(String, std::path::PathBuf)> {
    if let Some(s) = args.sigma_m
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--sigma-m must be a positive length, got {s}");
    }
    let device = crate::calibrate::load_device(&args.device, &args.tip)?;
    let cfg = PlanConfig {
        measurement: args.measurement,
        count: args.count,
        n_candidates: args.candidates,
        seed: args.seed,
        criterion: args.criterion,
        sigma_m: args.sigma_m,
        transmission_rows: !args.separate_transmission_run,
        refine: args.refine,
    };
    let plan = plan_poses(&device, &cfg)?;
    let names: Vec<String> = device
        .chain()?
        .joint_names()
        .iter()
        .map(|n| n.to_owned())
        .collect();
    std::fs::write(&args.out, poses_csv(&names, &plan.readings))
        .with_context(|| format!("writing {}", args.out.display()))?;
    Ok((summary(&plan, &cfg), args.out.clone()))
}

/// Flags of `hapcal pose-study`.
#[derive(Clone, Debug, clap::Args)]
pub struct StudyArgs {
    /// Truth file (its device file is named inside).
    #[arg(long)]
    pub truth: Option<std::path::PathBuf>,
    /// Monte Carlo seeds.
    #[arg(long, default_value_t = 20)]
    pub seeds: u64,
    /// Planned pose counts (comma separated).
    #[arg(long, value_delimiter = ',', default_values_t = vec![30, 40, 60])]
    pub counts: Vec<usize>,
    /// Random reference set size.
    #[arg(long, default_value_t = 200)]
    pub random: usize,
    /// Candidates per plan.
    #[arg(long, default_value_t = 1000)]
    pub candidates: usize,
    /// Criterion of the plan.
    #[arg(long, default_value = "d-optimal")]
    pub criterion: Criterion,
    /// Step 1's external-encoder data.
    #[arg(long, value_enum, default_value_t = TransmissionData::SamePoses)]
    pub transmissions: TransmissionData,
    /// Refine each plan by coordinate exchange over the joint box (needs --transmissions
    /// shared or noise-free).
    #[arg(long)]
    pub refine: bool,
    /// Weight each candidate's distance row by the shared step 1's transmission uncertainty at
    /// that pose (needs --transmissions shared or noise-free).
    #[arg(long)]
    pub weight_rows: bool,
    /// Output Markdown file.
    #[arg(long, default_value = "docs/results/pose-selection.md")]
    pub out: std::path::PathBuf,
}

/// The reference device of a study: `truth`, or the bundled reference truth.
fn reference_from(truth: Option<&std::path::PathBuf>) -> Result<crate::paper::Reference> {
    let truth = truth
        .cloned()
        .unwrap_or_else(|| crate::project_root().join("fixtures/reference-device/truth.toml"));
    crate::paper::Reference::load(&truth)
}

/// Runs `hapcal pose-study`, writes the Markdown and returns it.
///
/// # Errors
/// Unreadable truth, a simulation or identification failure, or an unwritable output.
pub fn run_study(args: &StudyArgs, progress: &dyn Fn(u64)) -> Result<String> {
    let r = reference_from(args.truth.as_ref())?;
    let cfg = StudyConfig {
        seeds: args.seeds,
        counts: args.counts.clone(),
        n_random: args.random,
        n_candidates: args.candidates,
        criterion: args.criterion,
        transmissions: args.transmissions,
        refine: args.refine,
        weight_rows: args.weight_rows,
    };
    let study = pose_study(&r, &cfg, progress)?;
    let counts: Vec<String> = args.counts.iter().map(usize::to_string).collect();
    let command = format!(
        "cargo run --release -p hapcal -- pose-study --seeds {} --counts {} --random {} --candidates {} --criterion {} --transmissions {}{}{} --out {}",
        args.seeds,
        counts.join(","),
        args.random,
        args.candidates,
        args.criterion,
        args.transmissions.name(),
        if args.refine { " --refine" } else { "" },
        if args.weight_rows {
            " --weight-rows"
        } else {
            ""
        },
        args.out.display()
    );
    let text = study_markdown(&study, &cfg, &command);
    std::fs::write(&args.out, &text).with_context(|| format!("writing {}", args.out.display()))?;
    Ok(text)
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
pub fn transmission_variances(t: &crate::paper::TransmissionFit, q: &[f64]) -> Vec<f64> {
    use hapcal_transmission::{CapstanProblem, JointRad};
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
    if let Some(&theta) = q.get(crate::paper::PARALLELOGRAM_JOINT - 1) {
        let g = t.poly.basis(theta);
        var[crate::paper::PARALLELOGRAM_JOINT - 1] = quad(&g, &t.poly_identified.covariance);
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
    pub fn new(t: &crate::paper::TransmissionFit, limits: &[(f64, f64)], n_grid: usize) -> Self {
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
/// [`quantisation_variances`], [`transmission_variances`]).
///
/// # Panics
/// If `q` has the wrong length or an index of `kept` is out of range (misuse).
#[track_caller]
pub fn distance_row(
    chain: &hapcal_kinematics::Chain,
    kept: &[usize],
    q: &[f64],
    sigma_m: f64,
    joint_var_rad2: &[f64],
) -> Mat<f64> {
    let x0 = vec![0.0; chain.n_params()];
    let p = chain.end_point(&x0, q).coords;
    let u = p / p.norm();
    let jp = chain.point_jacobian_wrt_params(&x0, q);
    let mut var = sigma_m * sigma_m;
    if joint_var_rad2.iter().any(|&v| v > 0.0) {
        let jq = chain.geometric_jacobian(&x0, q);
        for (j, v) in joint_var_rad2.iter().enumerate().take(chain.n_joints()) {
            let dd_dq = (0..3).map(|a| u[a] * jq[(a, j)]).sum::<f64>();
            var += dd_dq * dd_dq * v;
        }
    }
    let sigma = var.sqrt();
    Mat::from_fn(1, kept.len(), |_, k| {
        (0..3).map(|a| u[a] * jp[(a, kept[k])]).sum::<f64>() / sigma
    })
}

/// `W_S = mean over readings of G_qᵀG_q`, `G_q` the 3 × `kept.len()` end-point Jacobian (m per
/// unit parameter) in the base frame (columns of a fixed rig → base row are zero): the weight
/// of the validation position mean square, [`Candidates::weight`] without transmissions.
fn validation_weight(device: &Device, kept: &[usize], readings: &[Vec<f64>]) -> Result<Mat<f64>> {
    let chain = device.chain()?;
    let x0 = vec![0.0; chain.n_params()];
    let k = kept.len();
    let mut w = Mat::<f64>::zeros(k, k);
    let in_base_row = fixed_base_row_params(device, &chain);
    for q in readings {
        let jp = chain.point_jacobian_wrt_params(&x0, q);
        let g = Mat::from_fn(3, k, |a, c| {
            if in_base_row[kept[c]] {
                0.0
            } else {
                jp[(a, kept[c])]
            }
        });
        w += g.transpose() * &g;
    }
    w /= readings.len().max(1) as f64;
    Ok(w)
}

/// Settings of [`design_bound`].
#[derive(Clone, Debug)]
pub struct BoundConfig {
    /// Candidate poses of the continuous design (uniform in the joint limits).
    pub n_candidates: usize,
    /// Seeds `0..seeds` of the random reference sets (as in [`pose_study`]).
    pub seeds: u64,
    /// Size of the random reference set.
    pub n_random: usize,
    /// Pose counts to report the bound at (and to plan exactly, I-optimal, from the pool).
    pub counts: Vec<usize>,
    /// Row weights.
    pub noise: RowNoise,
    /// Most rounds of column generation (optimise the weights, add the maxima of the
    /// sensitivity over the joint box to the candidates).
    pub rounds: usize,
}

/// One row of [`Bound::rows`].
#[derive(Clone, Debug)]
pub struct BoundRow {
    /// Number of poses `N`.
    pub count: usize,
    /// `√(lower_bound/N)`: no `N` poses in the joint limits give a smaller root expected mean
    /// square validation position error, m.
    pub bound_rms_m: f64,
    /// `√(tr(W(ΣBᵀB)⁻¹))` of an exact I-optimal `N`-pose design from the pool (greedy +
    /// exchange, [`select_poses`]), m.
    pub planned_rms_m: f64,
    /// The same after [`coordinate_exchange`] over the joint box, m.
    pub refined_rms_m: f64,
    /// Median validation RMS of the linear model for the refined design (200 draws of
    /// `δx ~ N(0, M⁻¹)` with each seed's validation poses), m: the counterpart of
    /// [`Bound::random_median_rms_m`].
    pub refined_median_rms_m: f64,
}

/// For a design with information `m` (rows divided by σ, `n × n`): `tr(W·m⁻¹)`,
/// `tr(W_v·m⁻¹)` (m²) and 200 draws of the validation RMS `√(δxᵀW_vδx)` (m) with
/// `δx ~ N(0, m⁻¹)` (`ChaCha8Rng` seeded with `seed`): the linearised validation error.
fn linear_outcomes(
    m: &Mat<f64>,
    w: &Mat<f64>,
    wv: &Mat<f64>,
    seed: u64,
) -> Result<(f64, f64, Vec<f64>)> {
    let llt = m
        .llt(faer::Side::Lower)
        .map_err(|e| anyhow::anyhow!("singular information ({e:?})"))?;
    let minv = faer::linalg::solvers::DenseSolveCore::inverse(&llt);
    let mut zrng = ChaCha8Rng::seed_from_u64(seed);
    let draws = (0..200)
        .map(|_| {
            let mut z = Mat::from_fn(m.nrows(), 1, |_, _| zrng.sample::<f64, _>(StandardNormal));
            llt.L()
                .transpose()
                .solve_upper_triangular_in_place(z.as_mut());
            (z.transpose() * wv * &z)[(0, 0)].max(0.0).sqrt()
        })
        .collect();
    Ok((
        trace_of_product(w, &minv),
        trace_of_product(wv, &minv),
        draws,
    ))
}

/// Result of [`design_bound`]. All mean squares are of the end-point position error over
/// uniform validation poses (base frame), linearised at the nominal model, from the distance
/// noise alone (step 1's transmissions known): `E = tr(W·C)`, `C` the parameter covariance.
#[derive(Clone, Debug)]
pub struct Bound {
    /// Kinematic parameters of the design (columns).
    pub n_params: usize,
    /// `Φ_U = tr(W·M_U⁻¹)`, `M_U` the mean information of a uniform random pose: `Φ_U/N` is the
    /// large-`N` mean square of `N` random poses, m².
    pub uniform_value: f64,
    /// The continuous design found ([`hapcal_identify::i_optimal_weights`]).
    pub design: hapcal_identify::ContinuousDesign,
    /// Candidates with weight above 1e-4.
    pub support: usize,
    /// Rounds of column generation done.
    pub rounds: usize,
    /// Candidates at the end (the uniform pool plus the sensitivity maxima added).
    pub n_pool: usize,
    /// Largest sensitivity found over the joint box (candidates, extra random points, and
    /// compass search from the best of them), m².
    pub sup_sensitivity: f64,
    /// `Φ(ξ)²/sup_sensitivity`: lower bound of `Φ*` over every design in the joint limits, m².
    pub lower_bound: f64,
    /// Per seed: `tr(W·M_s⁻¹)` of the seed's `n_random` random poses (the expected mean square
    /// over uniform validation poses), m².
    pub random_ms: Vec<f64>,
    /// Per seed: `tr(W_v·M_s⁻¹)` with the seed's own 200 validation poses, m².
    pub random_ms_validation: Vec<f64>,
    /// Median over seeds and noise draws of the linear model's validation RMS with `n_random`
    /// random poses (200 draws of `δx ~ N(0, M_s⁻¹)` per seed), m.
    pub random_median_rms_m: f64,
    /// Mean over seeds of `random_ms`: the target mean square, m².
    pub target_ms: f64,
    /// Smallest `N` with `lower_bound/N ≤ target_ms`.
    pub n_min: usize,
    /// One row per count.
    pub rows: Vec<BoundRow>,
}

/// Supremum of the sensitivity `d_q(ξ)` of `design` over the joint box (limits `limits`,
/// rad) and the local maxima found: the candidates `pool`, 20 000 points drawn uniformly and
/// 20 000 with each joint at a limit with probability 2/3 (`rng`), then a compass search
/// (step 0.2 rad halved down to 1e-5 rad) from the 40 best. Returns `(sup, maxima)`.
fn sensitivity_maxima(
    design: &hapcal_identify::ContinuousDesign,
    pool: &[Vec<f64>],
    limits: &[(f64, f64)],
    row: &dyn Fn(&[f64]) -> Mat<f64>,
    device: &Device,
    rng: &mut ChaCha8Rng,
) -> (f64, Vec<Vec<f64>>) {
    let d_at = |q: &[f64]| design.sensitivity_of(row(q).as_ref());
    let mut starts: Vec<(f64, Vec<f64>)> = pool
        .iter()
        .zip(&design.sensitivity)
        .map(|(q, &d)| (d, q.clone()))
        .collect();
    for q in hapcal_sim::sample_readings(device, rng, 20_000) {
        starts.push((d_at(&q), q));
    }
    for mut q in hapcal_sim::sample_readings(device, rng, 20_000) {
        for (j, v) in q.iter_mut().enumerate() {
            let u: f64 = rng.random();
            let (lo, hi) = limits[j];
            if u < 1.0 / 3.0 {
                *v = lo;
            } else if u < 2.0 / 3.0 {
                *v = hi;
            }
        }
        starts.push((d_at(&q), q));
    }
    starts.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut sup = starts.first().map_or(0.0, |s| s.0);
    let mut maxima = Vec::new();
    for (d0, q0) in starts.iter().take(40) {
        let (mut q, mut d) = (q0.clone(), *d0);
        let mut step = 0.2;
        while step > 1e-5 {
            let mut improved = false;
            for j in 0..q.len() {
                for sign in [1.0, -1.0] {
                    let mut t = q.clone();
                    let (lo, hi) = limits[j];
                    t[j] = (t[j] + sign * step).clamp(lo, hi);
                    let dt = d_at(&t);
                    if dt > d {
                        (q, d) = (t, dt);
                        improved = true;
                    }
                }
            }
            if !improved {
                step /= 2.0;
            }
        }
        sup = sup.max(d);
        maxima.push(q);
    }
    (sup, maxima)
}

/// The optimal-design bound of issue #5 (see `docs/results/pose-selection-bound.md`): how well
/// any `N` distance poses can do, against `n_random` random poses, with the transmissions
/// known.
///
/// For `N` poses with blocks `B_c` (rows divided by σ) the linearised covariance is
/// `(Σ B_cᵀB_c)⁻¹ = M(ξ_N)⁻¹/N` and the expected validation mean square is
/// `tr(W·M(ξ_N)⁻¹)/N ≥ Φ*/N` ([`hapcal_identify::ContinuousDesign`]). `Φ*` is bracketed by the
/// multiplicative algorithm on `n_candidates` uniform candidates and the certificate
/// `Φ(ξ)²/sup_x d_x(ξ)`, with the supremum searched over the whole joint box.
///
/// # Errors
/// Device or design failures.
pub fn design_bound(
    r: &crate::paper::Reference,
    cfg: &BoundConfig,
    progress: &dyn Fn(&str),
) -> Result<Bound> {
    let device = &r.device;
    let sigma_m = r.noise.sigma_m_m;
    let mut rng = ChaCha8Rng::seed_from_u64(5_000_000);
    let pool = hapcal_sim::sample_readings(device, &mut rng, cfg.n_candidates);
    let c = candidate_blocks(device, &pool, Measurement::Distance, Some(sigma_m), false)?;
    let kept = c.kept.clone();
    let chain = device.chain()?;
    let joint_var = quantisation_variances(device, cfg.noise);
    let row = |q: &[f64]| distance_row(&chain, &kept, q, sigma_m, &joint_var);
    let blocks: Vec<Mat<f64>> = pool.iter().map(|q| row(q)).collect();
    let w = c.weight;
    let uniform_value = hapcal_identify::i_optimal_weights(
        &blocks,
        &w,
        &hapcal_identify::ContinuousConfig {
            max_iterations: 0,
            tolerance: 0.0,
        },
    )?
    .value;
    let limits = device.joint_limits();
    let (mut pool, mut blocks) = (pool, blocks);
    let mut extra_rng = ChaCha8Rng::seed_from_u64(6_000_000);
    let mut rounds = 0;
    let (design, sup) = loop {
        rounds += 1;
        progress(&format!(
            "continuous design, round {rounds}, {} candidates",
            pool.len()
        ));
        let design = hapcal_identify::i_optimal_weights(
            &blocks,
            &w,
            &hapcal_identify::ContinuousConfig::new(),
        )?;
        let (sup, maxima) =
            sensitivity_maxima(&design, &pool, &limits, &row, device, &mut extra_rng);
        if sup <= design.value * (1.0 + 1e-3) || rounds >= cfg.rounds {
            break (design, sup);
        }
        for q in maxima {
            blocks.push(row(&q));
            pool.push(q);
        }
    };
    let lower_bound = design.lower_bound_given(sup);
    let support = design.weights.iter().filter(|&&x| x > 1e-4).count();

    // The validation weights of the study's seeds (200 fresh poses each).
    let validation_weights = (0..cfg.seeds)
        .map(|seed| {
            let mut vrng = ChaCha8Rng::seed_from_u64(seed + 1_000_000);
            let validation: Vec<Vec<f64>> = hapcal_sim::sample_readings(device, &mut vrng, 200)
                .iter()
                .map(|q| hapcal_sim::quantise_readings(device, q))
                .collect();
            validation_weight(device, &kept, &validation)
        })
        .collect::<Result<Vec<_>>>()?;
    let info_of = |poses: &[Vec<f64>]| {
        let mut m = Mat::<f64>::zeros(kept.len(), kept.len());
        for q in poses {
            let b = row(&hapcal_sim::quantise_readings(device, q));
            m += b.transpose() * &b;
        }
        m
    };
    // The random reference sets of the study, seed by seed.
    progress("random reference sets");
    let (mut random_ms, mut random_ms_validation, mut draws) = (vec![], vec![], vec![]);
    for seed in 0..cfg.seeds {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let m = info_of(&hapcal_sim::sample_readings(device, &mut rng, cfg.n_random));
        let wv = &validation_weights[seed as usize];
        let (ms, ms_v, d) = linear_outcomes(&m, &w, wv, seed + 7_000_000)?;
        random_ms.push(ms);
        random_ms_validation.push(ms_v);
        draws.extend(d);
    }
    let target_ms = random_ms.iter().sum::<f64>() / random_ms.len().max(1) as f64;
    let n_min = (lower_bound / target_ms).ceil() as usize;

    let mut rows = Vec::new();
    for &count in &cfg.counts {
        progress(&format!("planning {count} poses"));
        let dcfg = DesignConfig {
            weight: Some(w.clone()),
            ..DesignConfig::new(Criterion::IOptimal)
        };
        let d = select_poses(&blocks, count, &dcfg)?;
        let mut poses: Vec<Vec<f64>> = d.selected.iter().map(|&c| pool[c].clone()).collect();
        let refined = coordinate_exchange(&mut poses, &row, Criterion::IOptimal, &w, &limits, 50)?;
        let m = info_of(&poses);
        let mut planned_draws = Vec::new();
        for (seed, wv) in validation_weights.iter().enumerate() {
            planned_draws.extend(linear_outcomes(&m, &w, wv, seed as u64 + 8_000_000)?.2);
        }
        rows.push(BoundRow {
            count,
            bound_rms_m: (lower_bound / count as f64).sqrt(),
            planned_rms_m: (-d.value).sqrt(),
            refined_rms_m: refined.sqrt(),
            refined_median_rms_m: median(&planned_draws),
        });
    }
    Ok(Bound {
        n_params: kept.len(),
        uniform_value,
        design,
        support,
        rounds,
        n_pool: pool.len(),
        sup_sensitivity: sup,
        lower_bound,
        random_median_rms_m: median(&draws),
        random_ms,
        random_ms_validation,
        target_ms,
        n_min,
        rows,
    })
}

/// The bound as Markdown, with the command that made it.
pub fn bound_markdown(b: &Bound, cfg: &BoundConfig, command: &str) -> String {
    use std::fmt::Write;
    let mm = |m2: f64| m2.sqrt() * 1e3;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Pose selection: the optimal-design bound (reference device, distance data)\n"
    );
    let _ = writeln!(s, "Written by `{command}`.\n");
    let _ = writeln!(
        s,
        "Linearised at the nominal model, transmissions known, rows weighted by the `{}` noise \
         model, {} kinematic parameters. Mean squares are of the end-point position error over \
         uniform validation poses in the base frame (m² shown as their root in mm).\n",
        cfg.noise.name(),
        b.n_params
    );
    let d = &b.design;
    let _ = writeln!(s, "| quantity | value |\n|---|---|");
    let rows = [
        (
            format!(
                "continuous I-optimal design on the candidates ({} uniform + maxima): √Φ(ξ̂) (mm·√pose)",
                cfg.n_candidates
            ),
            format!("{:.4}", mm(d.value)),
        ),
        (
            "rounds of column generation; candidates at the end".to_owned(),
            format!("{}; {}", b.rounds, b.n_pool),
        ),
        (
            "multiplicative iterations (last round), converged, support (w > 1e-4)".to_owned(),
            format!("{}, {}, {}", d.iterations, d.converged, b.support),
        ),
        (
            "√max sensitivity on the candidates; √sup over the joint box (mm·√pose)".to_owned(),
            format!("{:.4}; {:.4}", mm(d.max_sensitivity), mm(b.sup_sensitivity)),
        ),
        (
            "certified lower bound √Φ* ≥ √(Φ(ξ̂)²/sup d) (mm·√pose)".to_owned(),
            format!("{:.4}", mm(b.lower_bound)),
        ),
        (
            "uniform random poses √Φ_U (mm·√pose)".to_owned(),
            format!("{:.4}", mm(b.uniform_value)),
        ),
        (
            "I-efficiency of uniform random poses Φ*/Φ_U, at most".to_owned(),
            format!("{:.3}", d.value / b.uniform_value),
        ),
        (
            format!(
                "{} random poses, √(mean over seeds of tr(W·M⁻¹)) (mm)",
                cfg.n_random
            ),
            format!("{:.4}", mm(b.target_ms)),
        ),
        (
            format!(
                "{} random poses, median over seeds of √tr(W_val·M⁻¹) with each seed's 200 validation poses (mm)",
                cfg.n_random
            ),
            format!("{:.4}", mm(median(&b.random_ms_validation))),
        ),
        (
            format!(
                "{} random poses, median validation RMS of the linear model (200 noise draws per seed) (mm)",
                cfg.n_random
            ),
            format!("{:.4}", b.random_median_rms_m * 1e3),
        ),
        (
            format!(
                "smallest N whose bound allows the {}-random mean square: ⌈Φ*_lb / target⌉",
                cfg.n_random
            ),
            format!("{}", b.n_min),
        ),
    ];
    for (k, v) in rows {
        let _ = writeln!(s, "| {k} | {v} |");
    }
    let _ = writeln!(
        s,
        "\n| N | bound: √(Φ*_lb/N) (mm) | continuous design spread over N: √(Φ(ξ̂)/N) (mm) | I-optimal exact design from the final candidates: √tr(W·M⁻¹) (mm) | same, then coordinate exchange over the box (mm) | its median validation RMS, linear model (mm) | {} random: √target (mm) |\n|---|---|---|---|---|---|---|",
        cfg.n_random
    );
    for r in &b.rows {
        let _ = writeln!(
            s,
            "| {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
            r.count,
            r.bound_rms_m * 1e3,
            mm(d.value / r.count as f64),
            r.planned_rms_m * 1e3,
            r.refined_rms_m * 1e3,
            r.refined_median_rms_m * 1e3,
            mm(b.target_ms)
        );
    }
    s
}

/// Flags of `hapcal pose-bound`.
#[derive(Clone, Debug, clap::Args)]
pub struct BoundArgs {
    /// Truth file (its device file is named inside).
    #[arg(long)]
    pub truth: Option<std::path::PathBuf>,
    /// Candidate poses of the continuous design.
    #[arg(long, default_value_t = 20_000)]
    pub candidates: usize,
    /// Seeds of the random reference sets.
    #[arg(long, default_value_t = 20)]
    pub seeds: u64,
    /// Random reference set size.
    #[arg(long, default_value_t = 200)]
    pub random: usize,
    /// Pose counts to report (comma separated).
    #[arg(long, value_delimiter = ',', default_values_t = vec![30, 60, 100])]
    pub counts: Vec<usize>,
    /// Row weights.
    #[arg(long, value_enum, default_value_t = RowNoise::Simulator)]
    pub noise: RowNoise,
    /// Most rounds of column generation.
    #[arg(long, default_value_t = 30)]
    pub rounds: usize,
    /// Output Markdown file.
    #[arg(long, default_value = "docs/results/pose-selection-bound.md")]
    pub out: std::path::PathBuf,
}

/// Runs `hapcal pose-bound`, writes the Markdown and returns it.
///
/// # Errors
/// Unreadable truth, a design failure, or an unwritable output.
pub fn run_bound(args: &BoundArgs, progress: &dyn Fn(&str)) -> Result<String> {
    let r = reference_from(args.truth.as_ref())?;
    let cfg = BoundConfig {
        n_candidates: args.candidates,
        seeds: args.seeds,
        n_random: args.random,
        counts: args.counts.clone(),
        noise: args.noise,
        rounds: args.rounds,
    };
    let b = design_bound(&r, &cfg, progress)?;
    let counts: Vec<String> = args.counts.iter().map(usize::to_string).collect();
    let command = format!(
        "cargo run --release -p hapcal -- pose-bound --candidates {} --seeds {} --random {} --counts {} --noise {} --rounds {} --out {}",
        args.candidates,
        args.seeds,
        args.random,
        counts.join(","),
        args.noise.name(),
        args.rounds,
        args.out.display()
    );
    let text = bound_markdown(&b, &cfg, &command);
    std::fs::write(&args.out, &text).with_context(|| format!("writing {}", args.out.display()))?;
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference_device() -> Device {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/reference-device/device.toml");
        crate::calibrate::load_device(&path, "ball_link").expect("reference device")
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
    fn transmission_variances_are_tabulated_faithfully_and_largest_at_the_range_ends() {
        let truth = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/reference-device/truth.toml");
        let r = crate::paper::Reference::load(&truth).expect("reference");
        let cfg = hapcal_sim::SimConfig::new(0, 200).with_noise(r.noise);
        let rows = hapcal_sim::simulate(&r.device, &r.truth, &cfg).expect("log");
        let t = crate::paper::identify_transmissions(&r, &rows).expect("step 1");
        let limits = r.device.joint_limits();
        let table = VarianceTable::new(&t, &limits, 2001);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for q in hapcal_sim::sample_readings(&r.device, &mut rng, 20) {
            let (direct, tabulated) = (transmission_variances(&t, &q), table.eval(&q));
            for j in 0..7 {
                assert!(
                    (direct[j] - tabulated[j]).abs() <= 1e-3 * direct[j] + 1e-16,
                    "joint {}: {} vs {}",
                    j + 1,
                    direct[j],
                    tabulated[j]
                );
                // Joints 5–7 are direct drive: step 1 leaves them exact.
                assert_eq!(direct[j] == 0.0, j >= 4, "joint {}", j + 1);
            }
        }
        // The joint-4 polynomial, fitted to uniform readings, is least known at its range ends.
        let (lo, hi) = limits[3];
        let at = |x: f64| {
            let mut q: Vec<f64> = limits.iter().map(|l| 0.5 * (l.0 + l.1)).collect();
            q[3] = x;
            transmission_variances(&t, &q)[3]
        };
        assert!(
            at(hi) > 2.0 * at(0.5 * (lo + hi)),
            "{} vs {}",
            at(hi),
            at(0.5 * (lo + hi))
        );
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
}
