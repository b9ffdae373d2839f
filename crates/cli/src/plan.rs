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
    /// `W = mean_c(G_cᵀG_c)`, `G_c` (3 × columns) the derivative of the end point (m, rig
    /// frame) at candidate `c` with respect to the columns: the kinematic point Jacobian, and
    /// for a transmission coefficient the joint's column of the geometric Jacobian times the
    /// basis function. `trace(W·(JᵀJ)⁻¹)·σ²`-like: the mean end-point variance over the
    /// candidates, the target of [`Criterion::IOptimal`].
    pub weight: Mat<f64>,
}

/// Candidate blocks of the scaled Jacobian for `readings` (see the module docs).
///
/// # Errors
/// An invalid device chain, readings of the wrong length, or a Jacobian evaluation failure.
pub fn candidate_blocks(
    device: &Device,
    readings: &[Vec<f64>],
    measurement: Measurement,
    sigma_m: Option<f64>,
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
    for c in &device.capstans {
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
    for q in readings {
        let jp = chain_for_weight.point_jacobian_wrt_params(&x0, q);
        let jq = chain_for_weight.geometric_jacobian(&x0, q);
        let mut g = Mat::<f64>::zeros(3, n_cols);
        for a in 0..3 {
            for (k, &j) in kept.iter().enumerate() {
                // Kinematic parameters come first in the problem's layout.
                if j < chain_for_weight.n_params() {
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
    if cfg.count == 0 || cfg.count > cfg.n_candidates {
        bail!(
            "--count must be between 1 and the number of candidates ({}), got {}",
            cfg.n_candidates,
            cfg.count
        );
    }
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let candidates = hapcal_sim::sample_readings(device, &mut rng, cfg.n_candidates);
    let Candidates {
        blocks,
        columns,
        undetermined,
        weight,
    } = candidate_blocks(device, &candidates, cfg.measurement, cfg.sigma_m)?;
    let design_cfg = DesignConfig {
        weight: Some(weight),
        ..DesignConfig::new(cfg.criterion)
    };
    let design = select_poses(&blocks, cfg.count, &design_cfg).context("choosing the poses")?;
    let first: Vec<usize> = (0..cfg.count).collect();
    let random =
        design_quality(&blocks, &first).context("scoring a random set of the same size")?;
    let readings = design
        .selected
        .iter()
        .map(|&c| candidates[c].clone())
        .collect();
    Ok(PosePlan {
        readings,
        design,
        random,
        columns,
        undetermined,
    })
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
/// paper's two-step calibration on `rows`.
fn calibrate_and_validate(
    r: &crate::paper::Reference,
    rows: &[LogRow],
    validation_seed: u64,
) -> Result<f64> {
    let t = crate::paper::identify_transmissions(r, rows)?;
    let (_, kin) = crate::paper::identify_kinematics(r, rows, Some(&t))?;
    let (v, _) = crate::paper::validate(r, validation_seed, 200, &t, &kin, &kin)?;
    Ok(v.position_rms_after_m)
}

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
        let reference = calibrate_and_validate(r, &sim(cfg.n_random)?, validation_seed)
            .with_context(|| format!("seed {seed}: {} random poses", cfg.n_random))?;
        let mut by_count = Vec::new();
        for &count in &cfg.counts {
            let plan = plan_poses(
                &r.device,
                &PlanConfig {
                    measurement: Measurement::Distance,
                    count,
                    n_candidates: cfg.n_candidates,
                    seed: seed + 2_000_000,
                    criterion: cfg.criterion,
                    sigma_m: Some(r.noise.sigma_m_m),
                },
            )?;
            let rows = simulate_at(r, &plan.readings, seed + 3_000_000)?;
            let planned = calibrate_and_validate(r, &rows, validation_seed)
                .with_context(|| format!("seed {seed}: {count} planned poses"))?;
            let random = calibrate_and_validate(r, &sim(count)?, validation_seed)
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
    let _ = writeln!(
        s,
        "Paper pipeline (step 1 transmissions from the external encoders, step 2 kinematics from \
         cable distances) on the simulated reference device (fixtures/reference-device, paper \
         noise), validated on 200 fresh poses per seed (position RMS in the device base frame). \
         Planned poses: {} by greedy start + DETMAX exchange over {} candidates sampled uniformly \
         within the joint limits, using the Jacobian at the nominal model (kinematic distance rows \
         and the linearised transmission rows, see `crates/cli/src/plan.rs`). Seeds 0..{}.\n",
        cfg.criterion, cfg.n_candidates, cfg.seeds
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
    /// Output Markdown file.
    #[arg(long, default_value = "docs/results/pose-selection.md")]
    pub out: std::path::PathBuf,
}

/// Runs `hapcal pose-study`, writes the Markdown and returns it.
///
/// # Errors
/// Unreadable truth, a simulation or identification failure, or an unwritable output.
pub fn run_study(args: &StudyArgs, progress: &dyn Fn(u64)) -> Result<String> {
    let root = crate::project_root();
    let truth = args
        .truth
        .clone()
        .unwrap_or_else(|| root.join("fixtures/reference-device/truth.toml"));
    let r = crate::paper::Reference::load(&truth)?;
    let cfg = StudyConfig {
        seeds: args.seeds,
        counts: args.counts.clone(),
        n_random: args.random,
        n_candidates: args.candidates,
        criterion: args.criterion,
    };
    let study = pose_study(&r, &cfg, progress)?;
    let counts: Vec<String> = args.counts.iter().map(usize::to_string).collect();
    let command = format!(
        "cargo run --release -p hapcal -- pose-study --seeds {} --counts {} --random {} --candidates {} --criterion {} --out {}",
        args.seeds,
        counts.join(","),
        args.random,
        args.candidates,
        args.criterion,
        args.out.display()
    );
    let text = study_markdown(&study, &cfg, &command);
    std::fs::write(&args.out, &text).with_context(|| format!("writing {}", args.out.display()))?;
    Ok(text)
}
