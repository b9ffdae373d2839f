//! Studies of pose selection on the simulated reference device: planned against random poses
//! over seeds (`hapcal pose-study`, [`pose_study`]) and the optimal-design bound of any `N`
//! distance poses (`hapcal pose-bound`, [`design_bound`]). They need the truth file; the planner
//! itself is [`hapcal_calibrate::plan`].

use anyhow::{Context, Result};
use faer::Mat;
use hapcal_calibrate::plan::*;
use hapcal_identify::{Criterion, DesignConfig, select_poses};
use hapcal_io::{Device, LogRow, N_EXT};
use hapcal_sim::NoiseModel;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

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
    /// readings of step 1 (the study's original form, before step 1 was shared by the arms of a
    /// seed).
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
/// data: per seed `s`, the paper's two-step calibration from `n_random` random poses
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
                    model: hapcal_calibrate::model::ModelName::Geometric.into(),
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

/// The truth file of a study: `truth`, or the bundled reference truth.
fn truth_file(truth: Option<&std::path::PathBuf>) -> std::path::PathBuf {
    truth
        .cloned()
        .unwrap_or_else(|| crate::project_root().join("fixtures/reference-device/truth.toml"))
}

/// The files a study reads, which its report must not replace: the truth file (given or the
/// bundled one) and the device file it names.
fn study_inputs(truth: Option<&std::path::PathBuf>) -> Vec<std::path::PathBuf> {
    let truth = truth_file(truth);
    let device = hapcal_sim::read_truth(&truth)
        .ok()
        .map(|t| t.device_path(&truth));
    std::iter::once(truth).chain(device).collect()
}

/// Runs a study end to end: checks before it runs that its Markdown report `out` can be
/// written ([`hapcal_calibrate::calibrate::check_output`]), loads the reference device
/// (`truth`, or the bundled reference truth), runs `study` on it for the report's text, writes
/// that text atomically, never over one of the study's inputs, and returns it.
///
/// # Errors
/// An output that cannot be written, an unreadable truth, or `study`'s error.
fn run_and_write(
    out: &std::path::Path,
    truth: Option<&std::path::PathBuf>,
    study: impl FnOnce(&crate::paper::Reference) -> Result<String>,
) -> Result<String> {
    use hapcal_calibrate::calibrate::{check_extension, check_output, write_new};
    check_extension(out, &["md"], "the study's report", false)?;
    let inputs = study_inputs(truth);
    let inputs: Vec<&std::path::Path> = inputs.iter().map(|p| p.as_path()).collect();
    check_output(out, &inputs)?;
    let r = crate::paper::Reference::load(&truth_file(truth))?;
    let text = study(&r)?;
    write_new(out, &text, &inputs)?;
    Ok(text)
}

/// `counts` as the command line gives them: comma-separated.
fn count_list(counts: &[usize]) -> String {
    let counts: Vec<String> = counts.iter().map(usize::to_string).collect();
    counts.join(",")
}

/// Runs `hapcal pose-study`, writes the Markdown and returns it.
///
/// # Errors
/// Unreadable truth, a simulation or identification failure, or an unwritable output.
pub fn run_study(args: &StudyArgs, progress: &dyn Fn(u64)) -> Result<String> {
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
    let command = format!(
        "cargo run --release -p hapcal -- pose-study --seeds {} --counts {} --random {} --candidates {} --criterion {} --transmissions {}{}{} --out {}",
        args.seeds,
        count_list(&args.counts),
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
    run_and_write(&args.out, args.truth.as_ref(), |r| {
        let study = pose_study(r, &cfg, progress)?;
        Ok(study_markdown(&study, &cfg, &command))
    })
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

/// The optimal-design bound on planned poses (see `docs/results/pose-selection-bound.md`): how well
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
    let cfg = BoundConfig {
        n_candidates: args.candidates,
        seeds: args.seeds,
        n_random: args.random,
        counts: args.counts.clone(),
        noise: args.noise,
        rounds: args.rounds,
    };
    let command = format!(
        "cargo run --release -p hapcal -- pose-bound --candidates {} --seeds {} --random {} --counts {} --noise {} --rounds {} --out {}",
        args.candidates,
        args.seeds,
        args.random,
        count_list(&args.counts),
        args.noise.name(),
        args.rounds,
        args.out.display()
    );
    run_and_write(&args.out, args.truth.as_ref(), |r| {
        let b = design_bound(r, &cfg, progress)?;
        Ok(bound_markdown(&b, &cfg, &command))
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
