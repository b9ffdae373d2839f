//! `hapcal reproduce`: the paper's Tables 2 and 3, the joint-4 polynomial (Fig. 7) and the
//! validation (Fig. 8) on the simulated reference device, for one seed and as a Monte Carlo.

use crate::paper::{self, Reference, SeedResult};
use anyhow::{Context, Result, bail};
use hapcal_force::quantile;
use hapcal_identify::identify;
use hapcal_metrics::{accuracy_improvement_pct, parameter_improvement_pct};
use hapcal_problems::CapstanProblem;
use hapcal_transmission::JointRad;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::fmt::Write;
use std::path::Path;

/// z of a two-sided 95 % interval.
const Z95: f64 = 1.959_963_984_540_054;

/// Sample standard deviation (n − 1), NaN with fewer than two values.
fn sample_sd(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return f64::NAN;
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// A CSV cell: empty for a value that is not defined (NaN, e.g. a standard deviation over one
/// seed).
fn csv_number(v: f64) -> String {
    if v.is_nan() {
        String::new()
    } else {
        v.to_string()
    }
}

/// Unit conversion for reports: (factor, unit) from SI.
fn display_unit(name: &str) -> (f64, &'static str) {
    if name.contains("alpha") || name.contains("theta") || name.ends_with(".c") {
        (1e3, "mrad")
    } else if name.contains("beta") {
        (180.0 / std::f64::consts::PI, "deg")
    } else if name.ends_with(".re") {
        (1.0, "1")
    } else {
        (1e3, "mm")
    }
}

/// One golden value: key, value, tolerance, unit.
pub type Golden = (String, f64, f64, &'static str);

/// Output of [`run`]: files to write (relative name, content) and golden values.
pub struct Reproduction {
    /// (file name, CSV or Markdown text).
    pub files: Vec<(String, String)>,
    /// Values compared by `--check`.
    pub golden: Vec<Golden>,
    /// The Markdown summary (also in `files`).
    pub summary: String,
}

/// Runs the reproduction: `n_seeds` seeds of `n_poses` poses each (seed 0 is the "one seed").
///
/// # Errors
/// Unreadable fixtures or a failed identification.
pub fn run(
    truth_path: &Path,
    n_seeds: usize,
    n_poses: usize,
    choice: &paper::PoseChoice<'_>,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Reproduction> {
    let r = Reference::load(truth_path)?;
    let seeds = run_seeds(&r, n_seeds, n_poses, choice, progress)?;
    let mut draft = Draft {
        files: Vec::new(),
        golden: Vec::new(),
        md: String::new(),
    };
    write_header(&r, n_seeds, n_poses, choice, &mut draft.md)?;
    let two_step = table3_two_step(&r, &seeds, &mut draft)?;
    table3_joint(&r, &seeds, &two_step, &mut draft)?;
    table2_capstans(&r, &seeds, &mut draft)?;
    table2_full_revolution(&r, &seeds[0], n_poses, &mut draft)?;
    fig7_polynomial(&r, &seeds[0], &mut draft)?;
    fig8_validation(&seeds, n_poses, &mut draft)?;
    // ---- Force control (paper Figs. 11–12) with seed 0's calibrated model.
    let s0 = &seeds[0];
    crate::force::append_to_reproduction(
        &r,
        &s0.transmissions,
        &s0.kinematics,
        &mut draft.files,
        &mut draft.md,
    )?;
    draft.files.push(("README.md".into(), draft.md.clone()));
    Ok(Reproduction {
        files: draft.files,
        golden: draft.golden,
        summary: draft.md,
    })
}

/// The reproduction while its stages write it: each stage appends its files, golden values and
/// Markdown section, in the order of the report.
struct Draft {
    /// (file name, CSV, SVG or Markdown text), in writing order.
    files: Vec<(String, String)>,
    /// Values compared by `--check`, in writing order.
    golden: Vec<Golden>,
    /// The Markdown summary so far.
    md: String,
}

/// Runs the `n_seeds` seeds in parallel (rayon), calling `progress` with the number done; each
/// seed is computed alone from its own RNG and `collect` keeps seed order, so the result does
/// not depend on the number of threads.
///
/// # Errors
/// A failed seed (the first in seed order), or no seed at all.
fn run_seeds(
    r: &Reference,
    n_seeds: usize,
    n_poses: usize,
    choice: &paper::PoseChoice<'_>,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<SeedResult>> {
    let seeds: Vec<SeedResult> = crate::par_map_counted(0..n_seeds as u64, progress, |seed| {
        paper::run_seed_with(r, seed, n_poses, choice).with_context(|| format!("seed {seed}"))
    })
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    if seeds.is_empty() {
        bail!("--seeds must be at least 1");
    }
    Ok(seeds)
}

/// The summary's title and its paragraphs on the setup (and on the planned poses, if any).
fn write_header(
    r: &Reference,
    n_seeds: usize,
    n_poses: usize,
    choice: &paper::PoseChoice<'_>,
    md: &mut String,
) -> Result<()> {
    writeln!(
        md,
        "# Reproduction of Baser & Konukseven on the simulated reference device\n"
    )?;
    writeln!(
        md,
        "Written by `cargo xtask reproduce-tables` (`hapcal reproduce --seeds {n_seeds} --poses {n_poses}`): fixtures/reference-device (device, truth = the paper's assigned values), paper noise model (σ_e = 2π/20000/3 rad, σ_m = 2π·R_d·σ_e = {:.3} µm), joint readings quantised at the joint side. Seed 0 is the single-seed run; the Monte Carlo uses seeds 0..{}.\n",
        r.noise.sigma_m_m * 1e6,
        n_seeds - 1
    )?;
    if let paper::PoseChoice::Planned {
        n_candidates, name, ..
    } = choice
    {
        writeln!(
            md,
            "**Planned poses:** the {n_poses} identification poses of each seed are chosen {name} from {n_candidates} random candidates by their joint readings alone (`--design {name} --candidates {n_candidates}`), instead of the paper's {n_poses} random poses; validation poses stay random.\n"
        )?;
    }
    Ok(())
}

/// Names of the reference chain's kinematic parameters, in layout order.
fn param_names(r: &Reference) -> Vec<String> {
    r.chain.params().iter().map(|p| p.name.clone()).collect()
}

/// What the seeds say about kinematic parameter `i` (assigned value `assigned`, SI): over the
/// seeds that kept it, its improvements, normalised errors, variances and 95 % coverage.
struct SeedSpread {
    /// I% (eq. 8) per seed that kept it; empty when `assigned` is 0 (I% undefined).
    imp: Vec<f64>,
    /// (identified − assigned)/std per seed that kept it.
    z: Vec<f64>,
    /// Sum of std² over the seeds that kept it (SI unit squared).
    var_sum: f64,
    /// Seeds whose 95 % interval holds `assigned`.
    covered: usize,
    /// Seeds that kept it (not pruned).
    kept: usize,
}

impl SeedSpread {
    /// Collects parameter `i` over `outcomes` (one `Vec` of parameter outcomes per seed).
    fn of(outcomes: &[Vec<paper::ParamOutcome>], i: usize, assigned: f64) -> Result<Self> {
        let mut spread = Self {
            imp: Vec::new(),
            z: Vec::new(),
            var_sum: 0.0,
            covered: 0,
            kept: 0,
        };
        for o in outcomes {
            if let (Some(v), Some(s)) = (o[i].identified, o[i].std) {
                spread.kept += 1;
                if assigned != 0.0 {
                    spread
                        .imp
                        .push(parameter_improvement_pct(assigned, v, 0.0)?);
                }
                if (v - assigned).abs() <= Z95 * s {
                    spread.covered += 1;
                }
                spread.z.push((v - assigned) / s);
                spread.var_sum += s * s;
            }
        }
        Ok(spread)
    }

    /// Percentage of the seeds that kept it whose 95 % interval holds the assigned value.
    fn coverage_pct(&self) -> f64 {
        100.0 * self.covered as f64 / self.kept as f64
    }

    /// Percentage of the `n_seeds` seeds that kept it.
    fn kept_pct(&self, n_seeds: usize) -> f64 {
        100.0 * self.kept as f64 / n_seeds as f64
    }
}

/// The improvement bars of Table 3's figure: per parameter with a defined I%, its median, 5th
/// and 95th percentile over the seeds and the paper's value.
#[derive(Default)]
struct ImprovementBars {
    names: Vec<String>,
    med: Vec<f64>,
    p5: Vec<f64>,
    p95: Vec<f64>,
    paper: Vec<Option<f64>>,
}

/// Table 3 (step 2, two-step identification): table3.csv, its figure, the Markdown table with
/// its golden values, and seed 0's pruned parameters. Returns the per-seed parameter outcomes.
///
/// # Errors
/// An unreadable paper table or a failed figure.
fn table3_two_step(
    r: &Reference,
    seeds: &[SeedResult],
    draft: &mut Draft,
) -> Result<Vec<Vec<paper::ParamOutcome>>> {
    let n_seeds = seeds.len();
    let outcomes: Vec<Vec<paper::ParamOutcome>> = seeds
        .iter()
        .map(|s| paper::kinematic_outcomes(r, &s.kinematics))
        .collect();
    let paper3 = read_paper_table(&crate::project_root().join("fixtures/golden/paper/table3.csv"))?;
    let mut t3 = String::from(
        "param,assigned,identified_seed0,std_seed0,ci95_lo_seed0,ci95_hi_seed0,median_improvement_pct,p5_improvement_pct,p95_improvement_pct,coverage95_pct,normalised_error_sd,bound_median_improvement_pct,kept_pct,paper_improvement_pct,unit\n",
    );
    let md = &mut draft.md;
    writeln!(md, "## Table 3: kinematic parameters (step 2)\n")?;
    writeln!(
        md,
        "The standard deviations carry step 1's transmission uncertainty (two-step covariance of Murphy & Topel 1985, `paper::propagate_transmission_covariance`). *Normalised error SD* is the standard deviation over the seeds of (identified − assigned)/std: 1 when the reported uncertainty is honest (with {n} seeds its own sampling error is ±{se:.2}). *Noise bound* is the median I% that an unbiased estimator with exactly these standard deviations would reach, 100·(1 − 0.674·RMS(std)/|assigned|): the data's limit, not the estimator's.\n",
        n = n_seeds,
        se = 1.0 / (2.0 * (n_seeds.max(2) - 1) as f64).sqrt()
    )?;
    writeln!(
        md,
        "| param | assigned | seed 0: identified ± std | median I% (5th–95th) | noise bound | paper I% | 95 % CI coverage | normalised error SD | kept |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|")?;
    let mut bars = ImprovementBars::default();
    for (i, name) in param_names(r).iter().enumerate() {
        let assigned = r.x_truth[i];
        let spread = SeedSpread::of(&outcomes, i, assigned)?;
        let paper_imp = paper3.iter().find(|(n, _)| n == name).map(|(_, v)| *v);
        let row = Table3Row {
            name,
            assigned,
            seed0: &outcomes[0][i],
            paper_imp,
            n_seeds,
        };
        if spread.kept == 0 {
            write_table3_pruned_row(&row, &mut t3, &mut draft.md)?;
            continue;
        }
        let coverage = spread.coverage_pct();
        let Some((med, p5, p95, _)) = write_table3_row(&row, &spread, &mut t3, &mut draft.md)?
        else {
            continue;
        };
        bars.names.push(name.clone());
        bars.med.push(med);
        bars.p5.push(p5);
        bars.p95.push(p95);
        bars.paper.push(paper_imp);
        draft.golden.push((
            format!("table3.{name}.median_improvement_pct"),
            med,
            0.05,
            "%",
        ));
        draft
            .golden
            .push((format!("table3.{name}.coverage95_pct"), coverage, 0.5, "%"));
    }
    draft.files.push(("table3.csv".into(), t3));
    draft.files.push((
        "table3_improvement.svg".into(),
        crate::figures::improvement_bars(&bars.names, &bars.med, &bars.p5, &bars.p95, &bars.paper)?,
    ));
    // Which parameters the pruning removed in seed 0, and why.
    let md = &mut draft.md;
    writeln!(
        md,
        "\nPruned by the rank test (seed 0; not a hand-written list):\n"
    )?;
    for p in &seeds[0].kinematics.identifiability.pruned {
        writeln!(md, "- `{}`: {}", p.name, p.reason)?;
    }
    writeln!(md)?;
    Ok(outcomes)
}

/// One parameter of Table 3, the same for its CSV and Markdown rows.
struct Table3Row<'a> {
    /// Parameter name.
    name: &'a str,
    /// Assigned (truth) deviation, SI.
    assigned: f64,
    /// Seed 0's outcome for it.
    seed0: &'a paper::ParamOutcome,
    /// The paper's I%, if it printed one.
    paper_imp: Option<f64>,
    /// Number of seeds.
    n_seeds: usize,
}

/// The rows of a parameter that every seed pruned.
fn write_table3_pruned_row(row: &Table3Row<'_>, t3: &mut String, md: &mut String) -> Result<()> {
    let Table3Row {
        name,
        assigned,
        paper_imp,
        ..
    } = *row;
    let (f, unit) = display_unit(name);
    writeln!(
        t3,
        "{name},{},,,,,,,,,,,0,{},{unit}",
        assigned * f,
        paper_imp.map_or(String::new(), |v| v.to_string())
    )?;
    writeln!(
        md,
        "| {name} | {:.3} {unit} | pruned | – | – | {} | – | – | 0 % |",
        assigned * f,
        paper_imp.map_or("–".into(), |v| format!("{v:.2}"))
    )?;
    Ok(())
}

/// The rows of a parameter that some seed kept; returns its (median, 5th, 95th percentile I%,
/// noise bound), `None` when I% is undefined (assigned 0).
fn write_table3_row(
    row: &Table3Row<'_>,
    spread: &SeedSpread,
    t3: &mut String,
    md: &mut String,
) -> Result<Option<(f64, f64, f64, f64)>> {
    let Table3Row {
        name,
        assigned,
        seed0: s0,
        paper_imp,
        n_seeds,
    } = *row;
    let (f, unit) = display_unit(name);
    let (v0, sd0) = (
        s0.identified.unwrap_or(f64::NAN),
        s0.std.unwrap_or(f64::NAN),
    );
    let coverage = spread.coverage_pct();
    let kept_pct = spread.kept_pct(n_seeds);
    let z_sd = sample_sd(&spread.z);
    let seed0 = if s0.identified.is_some() {
        format!("{:.4} ± {:.4}", v0 * f, sd0 * f)
    } else {
        "pruned".to_owned()
    };
    // I% (eq. 8) is undefined for a zero deviation.
    let improvement = (assigned != 0.0).then(|| {
        let med = quantile(&spread.imp, 0.5);
        let p5 = quantile(&spread.imp, 0.05);
        let p95 = quantile(&spread.imp, 0.95);
        let bound =
            100.0 * (1.0 - 0.674 * (spread.var_sum / spread.kept as f64).sqrt() / assigned.abs());
        (med, p5, p95, bound)
    });
    let (csv_med, csv_bound) = improvement.map_or((",,".to_owned(), String::new()), |i| {
        (format!("{},{},{}", i.0, i.1, i.2), i.3.to_string())
    });
    writeln!(
        t3,
        "{name},{},{},{},{},{},{csv_med},{coverage},{},{csv_bound},{kept_pct},{},{unit}",
        assigned * f,
        v0 * f,
        sd0 * f,
        (v0 - Z95 * sd0) * f,
        (v0 + Z95 * sd0) * f,
        csv_number(z_sd),
        paper_imp.map_or(String::new(), |v| v.to_string())
    )?;
    let (md_improvement, md_bound) = improvement.map_or(
        ("undefined (assigned 0)".to_owned(), "–".to_owned()),
        |(med, p5, p95, bound)| {
            (
                format!("{med:.2} ({p5:.2}–{p95:.2})"),
                format!("{bound:.2}"),
            )
        },
    );
    writeln!(
        md,
        "| {name} | {:.3} {unit} | {seed0} | {md_improvement} | {md_bound} | {} | {coverage:.0} % | {} | {kept_pct:.0} % |",
        assigned * f,
        paper_imp.map_or("–".into(), |v| format!("{v:.2}")),
        if spread.z.len() > 1 {
            format!("{z_sd:.2}")
        } else {
            "–".into()
        }
    )?;
    Ok(improvement)
}

/// Table 3 again, from the joint identification (both steps in one problem): table3_joint.csv,
/// the Markdown table beside the two-step median (`two_step`: per-seed outcomes of
/// [`table3_two_step`]) and its golden values.
fn table3_joint(
    r: &Reference,
    seeds: &[SeedResult],
    two_step: &[Vec<paper::ParamOutcome>],
    draft: &mut Draft,
) -> Result<()> {
    let joint_out: Vec<Vec<paper::ParamOutcome>> = seeds
        .iter()
        .map(|s| paper::kinematic_outcomes_at(r, &s.joint, s.joint_offset))
        .collect();
    let mut t3j = String::from(
        "param,assigned,median_improvement_pct,p5_improvement_pct,p95_improvement_pct,coverage95_pct,normalised_error_sd,kept_pct,unit\n",
    );
    let md = &mut draft.md;
    writeln!(
        md,
        "## Table 3, joint identification (transmissions and kinematics in one problem)\n"
    )?;
    writeln!(
        md,
        "Residual sigmas re-estimated per group (external encoders, cable) from a first fit; the transmission uncertainty now reaches the kinematic covariance.\n"
    )?;
    writeln!(
        md,
        "| param | median I% (5th–95th) | two-step median I% | 95 % CI coverage | normalised error SD | kept |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|")?;
    for (i, name) in param_names(r).iter().enumerate() {
        let (_, unit) = display_unit(name);
        let assigned = r.x_truth[i];
        if assigned == 0.0 {
            continue;
        }
        let spread = SeedSpread::of(&joint_out, i, assigned)?;
        let mut imp2 = Vec::new();
        for o2 in two_step {
            if let Some(v) = o2[i].identified {
                imp2.push(parameter_improvement_pct(assigned, v, 0.0)?);
            }
        }
        let md = &mut draft.md;
        if spread.kept == 0 {
            writeln!(md, "| {name} | pruned | – | – | – | 0 % |")?;
            continue;
        }
        let imp = &spread.imp;
        let med = quantile(imp, 0.5);
        let (p5, p95) = (quantile(imp, 0.05), quantile(imp, 0.95));
        let med2 = quantile(&imp2, 0.5);
        let coverage = spread.coverage_pct();
        let kept_pct = spread.kept_pct(seeds.len());
        let z_sd = sample_sd(&spread.z);
        writeln!(
            t3j,
            "{name},{},{med},{p5},{p95},{coverage},{},{kept_pct},{unit}",
            assigned,
            csv_number(z_sd)
        )?;
        writeln!(
            md,
            "| {name} | {med:.2} ({p5:.2}–{p95:.2}) | {med2:.2} | {coverage:.0} % | {} | {kept_pct:.0} % |",
            if z_sd.is_nan() {
                "–".to_owned()
            } else {
                format!("{z_sd:.2}")
            }
        )?;
        draft.golden.push((
            format!("table3_joint.{name}.median_improvement_pct"),
            med,
            0.05,
            "%",
        ));
        draft.golden.push((
            format!("table3_joint.{name}.coverage95_pct"),
            coverage,
            0.5,
            "%",
        ));
    }
    draft.files.push(("table3_joint.csv".into(), t3j));
    writeln!(draft.md)?;
    Ok(())
}

/// A capstan's parameter `k` in SI: 0 c, 1 re, 2 r_o, 3 beta_o, 4 r_i, 5 beta_i (the order of
/// [`CAPSTAN_SHORT`]).
fn capstan_field(p: &hapcal_transmission::CapstanParams, k: usize) -> f64 {
    [p.c_rad, p.re, p.r_o_m, p.beta_o_rad, p.r_i_m, p.beta_i_rad][k]
}

/// Short names of a capstan's parameters, in [`capstan_field`]'s order.
const CAPSTAN_SHORT: [&str; 6] = ["c", "re", "r_o", "beta_o", "r_i", "beta_i"];

/// The truth's parameters of the capstan at `joint`.
///
/// # Errors
/// No capstan at `joint` in the truth.
fn truth_capstan(r: &Reference, joint: usize) -> Result<hapcal_transmission::CapstanParams> {
    Ok(r.truth
        .capstans
        .iter()
        .find(|c| c.joint == joint)
        .context("truth capstan")?
        .params())
}

/// Table 2 (step 1, capstan drives over the joint range): table2.csv, the Markdown table with
/// its golden values, and the median correlation of the ratio error with the output-drum
/// eccentricity.
fn table2_capstans(r: &Reference, seeds: &[SeedResult], draft: &mut Draft) -> Result<()> {
    let paper2 = read_paper_table(&crate::project_root().join("fixtures/golden/paper/table2.csv"))?;
    let mut t2 = String::from(
        "param,assigned,identified_seed0,std_seed0,median_improvement_pct,p5_improvement_pct,p95_improvement_pct,coverage95_pct,median_abs_corr_re_r_o,paper_improvement_pct,unit\n",
    );
    let md = &mut draft.md;
    writeln!(
        md,
        "## Table 2: capstan drives (step 1, external encoders over the joint range)\n"
    )?;
    writeln!(
        md,
        "| param | assigned | seed 0: identified ± std | median I% (5th–95th) | paper I% | 95 % CI coverage |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|")?;
    let mut corr_notes = String::new();
    for (ci, fit0) in seeds[0].transmissions.capstans.iter().enumerate() {
        let joint = fit0.joint;
        let truth = truth_capstan(r, joint)?;
        for (k, short_name) in CAPSTAN_SHORT.iter().enumerate().skip(1) {
            let name = format!("capstan{joint}.{short_name}");
            let (f, unit) = display_unit(&name);
            let assigned = capstan_field(&truth, k);
            let spread = CapstanSpread::of(seeds, ci, k, &name, assigned)?;
            let v0 = capstan_field(&fit0.params, k);
            let sd0 = fit0.identified.std(&name).unwrap_or(f64::NAN);
            let med = quantile(&spread.imp, 0.5);
            let (p5, p95) = (quantile(&spread.imp, 0.05), quantile(&spread.imp, 0.95));
            let coverage = 100.0 * spread.covered as f64 / seeds.len() as f64;
            let mcorr = quantile(&spread.corr, 0.5);
            let paper_imp = paper2.iter().find(|(n, _)| *n == name).map(|(_, v)| *v);
            writeln!(
                t2,
                "{name},{},{},{},{med},{p5},{p95},{coverage},{mcorr},{},{unit}",
                assigned * f,
                v0 * f,
                sd0 * f,
                paper_imp.map_or(String::new(), |v| v.to_string())
            )?;
            writeln!(
                draft.md,
                "| {name} | {:.4} {unit} | {:.5} ± {:.5} | {med:.2} ({p5:.2}–{p95:.2}) | {} | {coverage:.0} % |",
                assigned * f,
                v0 * f,
                sd0 * f,
                paper_imp.map_or("–".into(), |v| format!("{v:.2}"))
            )?;
            draft.golden.push((
                format!("table2.{name}.median_improvement_pct"),
                med,
                0.05,
                "%",
            ));
            if k == 1 {
                writeln!(
                    corr_notes,
                    "- capstan {joint}: median |corr(Re, r_o)| = {mcorr:.3}"
                )?;
            }
        }
    }
    draft.files.push(("table2.csv".into(), t2));
    writeln!(
        draft.md,
        "\nCorrelation of the ratio error with the output-drum eccentricity within the joint range:\n\n{corr_notes}"
    )?;
    Ok(())
}

/// What the seeds say about one capstan parameter: improvements, 95 % coverage and the
/// correlation of the ratio error with the output-drum eccentricity.
struct CapstanSpread {
    /// I% (eq. 8) per seed.
    imp: Vec<f64>,
    /// Seeds whose 95 % interval holds the assigned value.
    covered: usize,
    /// |corr(re, r_o)| per seed where both are free.
    corr: Vec<f64>,
}

impl CapstanSpread {
    /// Collects parameter `k` ([`capstan_field`]) named `name` of capstan fit `ci` over `seeds`
    /// (`assigned` in SI).
    fn of(seeds: &[SeedResult], ci: usize, k: usize, name: &str, assigned: f64) -> Result<Self> {
        let mut imp = Vec::new();
        let mut covered = 0;
        let mut corr = Vec::new();
        for s in seeds {
            let fit = &s.transmissions.capstans[ci];
            let v = capstan_field(&fit.params, k);
            let std = fit.identified.std(name).unwrap_or(f64::NAN);
            imp.push(parameter_improvement_pct(assigned, v, 0.0)?);
            if (v - assigned).abs() <= Z95 * std {
                covered += 1;
            }
            let c = fit.identified.covariance.correlation();
            let ia = fit.identified.covariance.free.iter().position(|&i| i == 1);
            let ib = fit.identified.covariance.free.iter().position(|&i| i == 2);
            if let (Some(a), Some(b)) = (ia, ib) {
                corr.push(c[(a, b)].abs());
            }
        }
        Ok(Self { imp, covered, corr })
    }
}

/// The documented option: seed 0's capstans identified again from `n_poses` external-encoder
/// samples over a full output revolution (θ ∈ [−π, π]): table2_full_revolution.csv and the
/// Markdown table beside the joint-range fit.
fn table2_full_revolution(
    r: &Reference,
    seed0: &SeedResult,
    n_poses: usize,
    draft: &mut Draft,
) -> Result<()> {
    let md = &mut draft.md;
    writeln!(
        md,
        "### Option: external-encoder run over a full output revolution (θ ∈ [−π, π], 200 samples, seed 0)\n"
    )?;
    writeln!(
        md,
        "| param | assigned | identified ± std (joint range) | identified ± std (full revolution) |"
    )?;
    writeln!(md, "|---|---|---|---|")?;
    let mut full_csv = String::from("param,assigned,identified,std,unit\n");
    for fit0 in &seed0.transmissions.capstans {
        let joint = fit0.joint;
        let truth = truth_capstan(r, joint)?;
        let full = identify_full_revolution(r, fit0, &truth, n_poses)?;
        let p_full = CapstanProblem::params(full.fit.x.as_ref());
        for (k, short_name) in CAPSTAN_SHORT.iter().enumerate().skip(1) {
            let name = format!("capstan{joint}.{short_name}");
            let (f, unit) = display_unit(&name);
            let sd_full = full.std(&name).unwrap_or(f64::NAN);
            writeln!(
                full_csv,
                "{name},{},{},{},{unit}",
                capstan_field(&truth, k) * f,
                capstan_field(&p_full, k) * f,
                sd_full * f
            )?;
            writeln!(
                draft.md,
                "| {name} | {:.5} {unit} | {:.5} ± {:.5} | {:.5} ± {:.5} |",
                capstan_field(&truth, k) * f,
                capstan_field(&fit0.params, k) * f,
                fit0.identified.std(&name).unwrap_or(f64::NAN) * f,
                capstan_field(&p_full, k) * f,
                sd_full * f
            )?;
        }
    }
    draft
        .files
        .push(("table2_full_revolution.csv".into(), full_csv));
    Ok(())
}

/// Simulates `n_poses` evenly spaced joint angles over [−π, π] with the true capstan `truth`
/// and encoder noise (RNG seeded by the joint), and identifies the capstan of `fit0` from them.
///
/// # Errors
/// An invalid noise level or a failed identification.
fn identify_full_revolution(
    r: &Reference,
    fit0: &paper::CapstanFit,
    truth: &hapcal_transmission::CapstanParams,
    n_poses: usize,
) -> Result<hapcal_identify::Identified> {
    let joint = fit0.joint;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(joint as u64);
    let noise = Normal::new(0.0, r.noise.sigma_e_rad)?;
    let theta: Vec<f64> = (0..n_poses)
        .map(|k| {
            -std::f64::consts::PI + 2.0 * std::f64::consts::PI * (k as f64 + 0.5) / n_poses as f64
        })
        .collect();
    let ext: Vec<f64> = theta
        .iter()
        .map(|&t| fit0.capstan.output_rad(truth, JointRad(t)) + noise.sample(&mut rng))
        .collect();
    let problem = CapstanProblem::new(fit0.capstan, joint, theta, ext, r.noise.sigma_e_rad)?;
    Ok(identify(
        &problem,
        problem.initial_guess(),
        &paper::transmission_config(),
    )?)
}

/// Fig. 7 (seed 0's joint-4 polynomial against the true transmission error over the joint
/// range, 201 samples): its CSV and SVG, the Markdown section and the golden RMS.
fn fig7_polynomial(r: &Reference, seed0: &SeedResult, draft: &mut Draft) -> Result<()> {
    let poly = &seed0.transmissions.poly;
    let (lo, hi) = r.device.joint_limits()[paper::PARALLELOGRAM_JOINT - 1];
    let mut fig7 = String::from("theta_rad,true_error_rad,polynomial_rad\n");
    let mut fit_err = Vec::new();
    for k in 0..=200 {
        let t = lo + (hi - lo) * k as f64 / 200.0;
        let mut theta = vec![0.0; r.chain.n_joints()];
        let limits = r.device.joint_limits();
        for (j, th) in theta.iter_mut().enumerate() {
            *th = 0.5 * (limits[j].0 + limits[j].1);
        }
        theta[paper::PARALLELOGRAM_JOINT - 1] = t;
        let q = hapcal_sim::true_joint_angles(&r.device, &r.truth, &theta)?;
        let e = q[paper::PARALLELOGRAM_JOINT - 1] - t;
        writeln!(fig7, "{t},{e},{}", poly.eval(t))?;
        fit_err.push(poly.eval(t) - e);
    }
    draft.files.push(("fig7_polynomial.csv".into(), fig7));
    {
        let (mut th, mut te, mut tp) = (vec![], vec![], vec![]);
        for (k, err) in fit_err.iter().enumerate() {
            let t = lo + (hi - lo) * k as f64 / 200.0;
            th.push(t);
            tp.push(poly.eval(t));
            te.push(poly.eval(t) - err);
        }
        draft.files.push((
            "fig7_polynomial.svg".into(),
            crate::figures::fig7_polynomial(&th, &te, &tp, &[])?,
        ));
    }
    let poly_rms = hapcal_metrics::rms(&fit_err);
    let k = poly.to_monomial();
    let md = &mut draft.md;
    writeln!(
        md,
        "## Fig. 7: joint-4 transmission error, 10th-order polynomial (seed 0)\n"
    )?;
    writeln!(
        md,
        "RMS of (polynomial − true joint-4 error) over the joint range: {:.3} µrad = {:.2} σ_e (requirement ≤ 2 σ_e).\n",
        poly_rms * 1e6,
        poly_rms / r.noise.sigma_e_rad
    )?;
    writeln!(
        md,
        "Monomial coefficients in θ (rad): {}\n",
        k.iter()
            .enumerate()
            .map(|(i, v)| format!("k{i} = {v:.6e}"))
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    draft.golden.push((
        "fig7.poly_rms_over_sigma_e".into(),
        poly_rms / r.noise.sigma_e_rad,
        0.05,
        "1",
    ));
    Ok(())
}

/// Accuracy improvement in % (eq. 9), NaN when the baseline is zero.
fn accuracy_pct(after: f64, before: f64) -> f64 {
    accuracy_improvement_pct(after, before).unwrap_or(f64::NAN)
}

/// (median, 5th, 95th percentile) of a per-seed figure.
fn spread(v: &[f64]) -> (f64, f64, f64) {
    (quantile(v, 0.5), quantile(v, 0.05), quantile(v, 0.95))
}

/// Per-seed improvements (%, eq. 9) of the validation on fresh poses, each as (median, 5th,
/// 95th percentile) over the seeds.
struct ValidationSpread {
    /// Position RMS.
    position: (f64, f64, f64),
    /// Orientation RMS.
    orientation: (f64, f64, f64),
    /// Cable distance, full calibration.
    distance_full: (f64, f64, f64),
    /// Cable distance, kinematics only (transmissions left out).
    distance_kinematics: (f64, f64, f64),
    /// Median over the seeds of the orientation RMS the pruned parameters explain (rad).
    orientation_left_median_rad: f64,
}

impl ValidationSpread {
    /// Collects the validations of `seeds`.
    fn of(seeds: &[SeedResult]) -> Self {
        // One figure per seed, from its validation.
        let per_seed = |f: &dyn Fn(&crate::paper::Validation) -> f64| -> Vec<f64> {
            seeds.iter().map(|s| f(&s.validation)).collect()
        };
        let pos_i = per_seed(&|v| accuracy_pct(v.position_rms_after_m, v.position_rms_before_m));
        let ori_i =
            per_seed(&|v| accuracy_pct(v.orientation_rms_after_rad, v.orientation_rms_before_rad));
        let dist_full =
            per_seed(&|v| accuracy_pct(v.distance_rms_after_m, v.distance_rms_before_m));
        let dist_kin =
            per_seed(&|v| accuracy_pct(v.distance_rms_kinematics_only_m, v.distance_rms_before_m));
        let ori_left = per_seed(&|v| {
            v.orientation_rms_after_rad - v.orientation_rms_after_true_unidentifiable_rad
        });
        Self {
            position: spread(&pos_i),
            orientation: spread(&ori_i),
            distance_full: spread(&dist_full),
            distance_kinematics: spread(&dist_kin),
            orientation_left_median_rad: quantile(&ori_left, 0.5),
        }
    }
}

/// Fig. 8 (validation on `n_poses` fresh poses) and the transmissions' effect on accuracy: the
/// Markdown sections, fig8_validation.csv and .svg, and their golden values.
fn fig8_validation(seeds: &[SeedResult], n_poses: usize, draft: &mut Draft) -> Result<()> {
    let n_seeds = seeds.len();
    let v0 = seeds[0].validation;
    let s = ValidationSpread::of(seeds);
    let (pos_med, pos_lo, pos_hi) = s.position;
    let (ori_med, ori_lo, ori_hi) = s.orientation;
    let md = &mut draft.md;
    writeln!(
        md,
        "## Fig. 8: validation on {n_poses} fresh poses, device base frame\n"
    )?;
    writeln!(
        md,
        "| | before | after | I% (eq. 9) seed 0 | median I% (5th–95th), {n_seeds} seeds |"
    )?;
    writeln!(md, "|---|---|---|---|---|")?;
    writeln!(
        md,
        "| position RMS | {:.3} mm | {:.4} mm | {:.2} | {:.2} ({:.2}–{:.2}) |",
        v0.position_rms_before_m * 1e3,
        v0.position_rms_after_m * 1e3,
        accuracy_pct(v0.position_rms_after_m, v0.position_rms_before_m),
        pos_med,
        pos_lo,
        pos_hi
    )?;
    writeln!(
        md,
        "| orientation RMS | {:.3} mrad | {:.3} mrad | {:.2} | {:.2} ({:.2}–{:.2}) |",
        v0.orientation_rms_before_rad * 1e3,
        v0.orientation_rms_after_rad * 1e3,
        accuracy_pct(v0.orientation_rms_after_rad, v0.orientation_rms_before_rad),
        ori_med,
        ori_lo,
        ori_hi
    )?;
    writeln!(
        md,
        "\nOrientation is limited by what distances cannot see: with the pruned parameters (α7, and the gauge of row 0) set to their true values the orientation RMS after calibration would be {:.4} mrad instead of {:.4} mrad; they explain {:.4} mrad (median over seeds {:.4} mrad). α7 (1.7 mrad assigned) is a pure rotation about the tool's own x axis, invisible to a distance measurement at the tool point.\n",
        v0.orientation_rms_after_true_unidentifiable_rad * 1e3,
        v0.orientation_rms_after_rad * 1e3,
        (v0.orientation_rms_after_rad - v0.orientation_rms_after_true_unidentifiable_rad) * 1e3,
        s.orientation_left_median_rad * 1e3
    )?;
    write_transmission_effect(&v0, &s, n_seeds, md)?;
    draft
        .files
        .push(("fig8_validation.csv".into(), fig8_csv(seeds)?));
    let [pb, pa, ob, oa] = &seeds[0].pose_errors;
    draft.files.push((
        "fig8_validation.svg".into(),
        crate::figures::fig8_validation(pb, pa, ob, oa)?,
    ));
    draft.golden.push((
        "fig8.median_position_improvement_pct".into(),
        pos_med,
        0.01,
        "%",
    ));
    draft.golden.push((
        "distance.median_improvement_full_pct".into(),
        s.distance_full.0,
        0.01,
        "%",
    ));
    draft.golden.push((
        "distance.median_improvement_kinematics_only_pct".into(),
        s.distance_kinematics.0,
        0.05,
        "%",
    ));
    Ok(())
}

/// The section on the transmissions' effect on accuracy: seed 0's cable-distance RMS (`v0`) and
/// the improvements over the `n_seeds` seeds with and without the transmissions.
fn write_transmission_effect(
    v0: &crate::paper::Validation,
    s: &ValidationSpread,
    n_seeds: usize,
    md: &mut String,
) -> Result<()> {
    let (full_med, full_lo, full_hi) = s.distance_full;
    let (kin_med, kin_lo, kin_hi) = s.distance_kinematics;
    writeln!(
        md,
        "## Transmissions' effect on accuracy (the paper's 96.6 % vs 44.7 %, real device)\n"
    )?;
    writeln!(
        md,
        "Cable-distance RMS on fresh poses: nominal {:.3} mm, full calibration {:.4} mm, kinematics only (transmission errors left out) {:.3} mm (seed 0).\n",
        v0.distance_rms_before_m * 1e3,
        v0.distance_rms_after_m * 1e3,
        v0.distance_rms_kinematics_only_m * 1e3
    )?;
    writeln!(
        md,
        "Median I% (eq. 9) over {n_seeds} seeds: full calibration {:.2} % (5th–95th {:.2}–{:.2}), transmissions left out {:.2} % ({:.2}–{:.2}).\n",
        full_med, full_lo, full_hi, kin_med, kin_lo, kin_hi
    )?;
    Ok(())
}

/// fig8_validation.csv: each seed's validation RMS values (m, rad).
fn fig8_csv(seeds: &[SeedResult]) -> Result<String> {
    let mut fig8 = String::from(
        "seed,position_rms_before_m,position_rms_after_m,orientation_rms_before_rad,orientation_rms_after_rad,orientation_rms_after_true_unidentifiable_rad,distance_rms_before_m,distance_rms_after_m,distance_rms_kinematics_only_m\n",
    );
    for (seed, s) in seeds.iter().enumerate() {
        let v = s.validation;
        writeln!(
            fig8,
            "{seed},{},{},{},{},{},{},{},{}",
            v.position_rms_before_m,
            v.position_rms_after_m,
            v.orientation_rms_before_rad,
            v.orientation_rms_after_rad,
            v.orientation_rms_after_true_unidentifiable_rad,
            v.distance_rms_before_m,
            v.distance_rms_after_m,
            v.distance_rms_kinematics_only_m
        )?;
    }
    Ok(fig8)
}

fn read_paper_table(path: &Path) -> Result<Vec<(String, f64)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(text
        .lines()
        .skip(1)
        .filter_map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            let v = cells.get(3)?.trim().parse().ok()?;
            Some((cells.first()?.to_string(), v))
        })
        .collect())
}

/// Golden file text: `key,value,tol,unit`.
pub fn golden_csv(golden: &[Golden]) -> String {
    let mut s = String::from("key,value,tol,unit\n");
    for (k, v, t, u) in golden {
        let _ = writeln!(s, "{k},{v},{t},{u}");
    }
    s
}

/// Compares `golden` with the committed file; returns the mismatches.
///
/// # Errors
/// An unreadable or malformed golden file.
pub fn check_golden(golden: &[Golden], path: &Path) -> Result<Vec<String>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut expected = std::collections::HashMap::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        let (Some(k), Some(v), Some(t)) = (cells.first(), cells.get(1), cells.get(2)) else {
            bail!("{}:{}: expected key,value,tol,unit", path.display(), n + 1);
        };
        let v: f64 = v
            .parse()
            .with_context(|| format!("{}:{}:2: not a number", path.display(), n + 1))?;
        let t: f64 = t
            .parse()
            .with_context(|| format!("{}:{}:3: not a number", path.display(), n + 1))?;
        expected.insert(k.to_string(), (v, t));
    }
    let mut bad = Vec::new();
    for (k, v, _, u) in golden {
        match expected.get(k) {
            None => bad.push(format!("{k}: not in the golden file")),
            Some((e, t)) if !((v - e).abs() <= *t || (v.is_nan() && e.is_nan())) => {
                bad.push(format!("{k}: {v} {u}, golden {e} ± {t}"));
            }
            _ => {}
        }
    }
    Ok(bad)
}

/// The golden file of the reproduction below the project's root: the values `reproduce
/// --check` compares with.
pub const GOLDEN_FILE: &str = "fixtures/golden/ours/paper.csv";

/// The reproduction `result` against the golden file `path`: the line to print when every
/// value lies within its tolerance. With `update`, the golden file is rewritten from `result`
/// (never over one of `inputs`) and the check fails, asking for a review.
///
/// # Errors
/// Values outside their tolerance (each named), an unreadable or malformed golden file; with
/// `update`, always.
pub fn check_against_golden(
    result: &Reproduction,
    path: &Path,
    inputs: &[&Path],
    update: bool,
) -> Result<String> {
    if update {
        hapcal_calibrate::calibrate::write_new(path, &golden_csv(&result.golden), inputs)?;
        bail!(
            "UPDATE_GOLDEN: rewrote {}; review the diff and run again without it",
            path.display()
        );
    }
    let bad = check_golden(&result.golden, path)?;
    if !bad.is_empty() {
        bail!(
            "reproduction differs from {}:\n{}",
            path.display(),
            bad.join("\n")
        );
    }
    Ok(format!(
        "reproduce --check: {} values within tolerance of {}\n",
        result.golden.len(),
        path.display()
    ))
}

/// The `n` poses `reproduce --design` identifies from: chosen among the candidate `readings`
/// (rad, one per candidate) by `criterion` on the distance Jacobian at the nominal model of
/// `reference`, weighted by its distance noise; their indices.
///
/// # Errors
/// A candidate the Jacobian cannot be evaluated at, or a failed selection.
pub fn planned_poses(
    reference: &Reference,
    readings: &[Vec<f64>],
    n: usize,
    criterion: hapcal_identify::Criterion,
) -> Result<Vec<usize>> {
    let c = hapcal_calibrate::plan::candidate_blocks(
        &reference.device,
        readings,
        hapcal_calibrate::plan::Measurement::Distance,
        Some(reference.noise.sigma_m_m),
        true,
    )?;
    let mut cfg = hapcal_identify::DesignConfig::new(criterion);
    cfg.weight = Some(c.weight);
    Ok(hapcal_identify::select_poses(&c.blocks, n, &cfg)?.selected)
}
