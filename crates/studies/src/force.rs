//! `hapcal force`: what calibration does to rendered forces (paper Figs. 11–12), with the
//! calibrated device file that `hapcal calibrate` writes from a log of the device.
//!
//! The calibrated model comes from the paper's pipeline ([`crate::paper`]): step 1 identifies
//! the transmissions from the external encoders, step 2 the kinematic deviations from the cable
//! distances. [`calibrated_device`] stores both in one device file: kinematic deviations
//! applied to the D-H rows and listed in `[calibration.values]` with the transmission
//! parameters (`capstan{j}.c/re/r_o/beta_o/r_i/beta_i`, `joint4.cheb0..10`), which
//! [`ForceModel::calibrated`] reads back.

use crate::paper::{Reference, TransmissionFit, calibrated_device};
use anyhow::{Context, Result};
use hapcal_force::{
    Direction, ForceModel, SweepConfig, SweepErrors, WallConfig, WallSample, WrenchError,
    home_readings, quantile, sample_poses, sweep, virtual_wall,
};
use hapcal_identify::Identified;
use hapcal_io::{CalibratedValue, CalibrationMeta, Device};
use plotters::prelude::*;
use std::fmt::Write;

/// Settings of [`run`].
#[derive(Clone, Copy, Debug)]
pub struct ForcePlan {
    /// Force-feedback gain G of the closed-loop rows.
    pub gain: f64,
    /// Random-pose sweep.
    pub sweep: SweepConfig,
}

impl ForcePlan {
    /// The force report of the reference device (`hapcal force`'s defaults):
    /// [`SweepConfig::reference_device`] (200 poses, seed 4) and G = 10.
    pub fn reference_device() -> ForcePlan {
        ForcePlan {
            gain: 10.0,
            sweep: SweepConfig::reference_device(),
        }
    }
}

/// What [`run`] produced: a Markdown report and files to write.
pub struct ForceReport {
    /// Markdown: Fig. 12 at the paper's pose, the distributions, the floor explained.
    pub markdown: String,
    /// `(file name, content)`: `fig12_force.svg`, `fig12_force.csv`, `force_distributions.csv`.
    pub files: Vec<(String, String)>,
}

/// The model under test with the kinematic parameters that `calibrated` does not list (the
/// pruned, unidentifiable ones: α7, and row 0's gauge) set to the truth: what calibration
/// could reach if they were measured some other way.
fn with_true_unidentifiable(calibrated: &Device, truth: &hapcal_sim::Truth) -> Result<Device> {
    let listed: Vec<&str> = calibrated
        .calibration
        .iter()
        .flat_map(|c| c.values.iter().map(|v| v.name.as_str()))
        .collect();
    let chain = calibrated.chain()?;
    let extra: Vec<CalibratedValue> = truth
        .deviations
        .iter()
        .filter(|(name, _)| !listed.contains(&name.as_str()))
        .filter_map(|(name, v)| {
            let unit = chain.params()[chain.param_index(name)?].unit.symbol();
            Some(CalibratedValue {
                name: name.clone(),
                value: *v,
                std: 0.0,
                unit: unit.to_owned(),
            })
        })
        .collect();
    // Apply the extra deviations to the rows but keep the calibrated transmissions.
    let mut device = calibrated.with_calibration(&extra, CalibrationMeta::default())?;
    device.calibration = calibrated.calibration.clone();
    Ok(device)
}

/// Summary of one (model, gain) over the sweep: pooled force directions and pooled moment
/// directions, median and 95th percentile of |direction error| (deg) and |magnitude error| (%).
struct Pooled {
    force: [f64; 4],
    moment: [f64; 4],
}

fn pooled(e: &SweepErrors) -> Pooled {
    Pooled {
        force: direction_stats(e, &Direction::ALL[..3]),
        moment: direction_stats(e, &Direction::ALL[3..]),
    }
}

/// Median and 95th percentile of |direction error| (deg), then of |magnitude error| (%), over
/// the sweep's wrenches along the directions `dirs` together.
fn direction_stats(e: &SweepErrors, dirs: &[Direction]) -> [f64; 4] {
    let pooled = |of: fn(&WrenchError) -> f64| -> Vec<f64> {
        (dirs.iter())
            .flat_map(|d| e.errors[d.index()].iter().map(of))
            .collect()
    };
    let dir = pooled(|w| w.direction_deg.abs());
    let mag = pooled(|w| w.magnitude_pct.abs());
    [
        quantile(&dir, 0.5),
        quantile(&dir, 0.95),
        quantile(&mag, 0.5),
        quantile(&mag, 0.95),
    ]
}

/// The force experiment: Fig. 12 at the paper's pose (the home readings, joint 3 locked) and
/// the sweep over random poses, for the nominal model of `device`, the calibrated model of
/// `calibrated` and that model with the unidentifiable parameters at their truth, open loop
/// and with gain `plan.gain`; the device is `truth`.
///
/// # Errors
/// Inconsistent files (the caller adds their names) or a singular pose.
pub fn run(
    device: &Device,
    truth: &hapcal_sim::Truth,
    calibrated: &Device,
    plan: &ForcePlan,
) -> Result<ForceReport> {
    let bench = ForceBench::build(device, truth, calibrated, plan)?;
    let mut md = String::new();
    let wall = wall_section(&bench, plan, &mut md)?;
    write_at_home(&bench, &mut md)?;
    let swept = sweep_section(&bench, plan, &mut md)?;
    write_quantisation_share(&bench, &swept.poses, &mut md)?;
    write_reductions(&swept.p95_force, plan.gain, &mut md)?;
    write_floor(device, truth, calibrated, &mut md)?;
    let svg = fig12_svg(&wall.curves)?;
    Ok(ForceReport {
        markdown: md,
        files: vec![
            ("fig12_force.svg".into(), svg),
            ("fig12_force.csv".into(), wall.csv),
            ("force_distributions.csv".into(), swept.distributions_csv),
        ],
    })
}

/// What every part of the force experiment runs on: the device, its truth model, the three
/// models under test and the two wall controllers.
struct ForceBench<'a> {
    /// The nominal device file.
    device: &'a Device,
    /// The device itself (truth).
    truth_model: ForceModel,
    /// (name, model): nominal, calibrated, calibrated with the pruned parameters at their truth.
    models: [(&'static str, ForceModel); 3],
    /// The paper's open-loop wall.
    open: WallConfig,
    /// The same wall with the force-feedback gain.
    closed: WallConfig,
}

impl<'a> ForceBench<'a> {
    /// Builds the models of [`run`].
    ///
    /// # Errors
    /// A model that cannot be built from its file.
    fn build(
        device: &'a Device,
        truth: &hapcal_sim::Truth,
        calibrated: &Device,
        plan: &ForcePlan,
    ) -> Result<Self> {
        let truth_model = ForceModel::truth(device, truth).context("building the truth model")?;
        let floor_device = with_true_unidentifiable(calibrated, truth)?;
        let models = [
            (
                "nominal",
                ForceModel::nominal(device).context("building the nominal model")?,
            ),
            (
                "calibrated",
                ForceModel::calibrated(calibrated).context("building the calibrated model")?,
            ),
            (
                "calibrated, true pruned",
                ForceModel::calibrated(&floor_device).context(
                    "building the calibrated model with the true unidentifiable parameters",
                )?,
            ),
        ];
        let open = WallConfig::paper();
        let closed = open.with_gain(plan.gain);
        Ok(Self {
            device,
            truth_model,
            models,
            open,
            closed,
        })
    }
}

/// The virtual wall at the Fig. 12 pose: its CSV (every model, gain and travel step) and the
/// open-loop curves of each model for the figure.
struct WallSection {
    /// `fig12_force.csv`.
    csv: String,
    /// (model name, open-loop wall samples).
    curves: Vec<(String, Vec<WallSample>)>,
}

/// Fig. 12 at the paper's pose: the section's text with the pose's condition numbers and the
/// table of the final wrench of each model and gain.
///
/// # Errors
/// A singular pose or a failed wall experiment.
fn wall_section(bench: &ForceBench<'_>, plan: &ForcePlan, md: &mut String) -> Result<WallSection> {
    let (device, open) = (bench.device, bench.open);
    let pose = fig12_pose(device);
    let pose_cond = hapcal_force::condition_number(
        &bench.truth_model,
        &pose,
        Some(open.locked_joint),
        plan.sweep.length_m,
    )?;
    let exact_home_cond = hapcal_force::condition_number(
        &bench.truth_model,
        &home_readings(device),
        Some(open.locked_joint),
        plan.sweep.length_m,
    )?;
    writeln!(
        md,
        "## Force control: virtual wall (paper Figs. 11–12)\n\nHandle fixed at readings ({}) rad: home (mid-range) except the wrist joint 6 at half its upper limit, because at home (q6 = 0) joints 5 and 7 are collinear and the fixed-handle statics is singular (truth condition number {:.0} there, {:.1} here; linear rows / {} m). Joint {} locked at home, wall K = {} N/m moved {} mm along the tip z axis (desired force 2 N along z at the end). Controller readings quantised to the encoders; device = truth. Forces in the handle (sensor) frame at 20 mm; transverse = |(Fx, Fy)|/|Fz|.\n",
        pose.iter()
            .map(|v| format!("{v:.3}"))
            .collect::<Vec<_>>()
            .join(", "),
        exact_home_cond,
        pose_cond,
        plan.sweep.length_m,
        open.locked_joint,
        open.stiffness_n_per_m,
        open.travel_m * 1e3
    )?;
    writeln!(
        md,
        "| model | G | Fx (mN) | Fy (mN) | Fz − 2 N (mN) | transverse (% of Fz) | direction error (deg) |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|")?;
    let mut curves: Vec<(String, Vec<WallSample>)> = Vec::new();
    let mut csv = String::from("model,gain,travel_m,desired_n,fx_n,fy_n,fz_n,mx_nm,my_nm,mz_nm\n");
    for (name, model) in &bench.models {
        for cfg in [open, bench.closed] {
            let wall = virtual_wall(device, model, &bench.truth_model, &pose, &cfg)
                .with_context(|| format!("wall experiment, {name} model"))?;
            for s in &wall {
                let w = s.wrench;
                writeln!(
                    csv,
                    "{name},{},{},{},{},{},{},{},{},{}",
                    cfg.gain, s.travel_m, s.desired_n, w[0], w[1], w[2], w[3], w[4], w[5]
                )?;
            }
            let Some(last) = wall.last() else { continue };
            write_wall_row(name, cfg.gain, last, md)?;
            if cfg.gain == 0.0 {
                curves.push((name.to_string(), wall));
            }
        }
    }
    Ok(WallSection { csv, curves })
}

/// The wall table's row of model `name` at gain `gain`: its `last` sample's wrench.
fn write_wall_row(name: &str, gain: f64, last: &WallSample, md: &mut String) -> Result<()> {
    let w = last.wrench;
    let transverse = w[0].hypot(w[1]) / w[2].abs() * 100.0;
    let dir_deg = w[0].hypot(w[1]).atan2(w[2]).to_degrees();
    writeln!(
        md,
        "| {name} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.4} |",
        gain,
        w[0] * 1e3,
        w[1] * 1e3,
        (w[2] - last.desired_n) * 1e3,
        transverse,
        dir_deg
    )?;
    Ok(())
}

/// The exact home pose, for comparison: singular, so every error is amplified. The open-loop
/// transverse force of the nominal and the calibrated model there.
///
/// # Errors
/// A failed wall experiment.
fn write_at_home(bench: &ForceBench<'_>, md: &mut String) -> Result<()> {
    let device = bench.device;
    let at_home = |model: &ForceModel| -> Result<f64> {
        let wall = virtual_wall(
            device,
            model,
            &bench.truth_model,
            &home_readings(device),
            &bench.open,
        )?;
        Ok(wall.last().map_or(f64::NAN, |s| {
            s.wrench[0].hypot(s.wrench[1]) / s.wrench[2].abs() * 100.0
        }))
    };
    writeln!(
        md,
        "\nAt the exact home pose (q6 = 0, singular) the open-loop transverse force is {:.3} % of Fz with the nominal model and {:.3} % with the calibrated one.",
        at_home(&bench.models[0].1)?,
        at_home(&bench.models[1].1)?
    )?;
    Ok(())
}

/// The sweep over random poses: the poses drawn, `force_distributions.csv` and each (model,
/// gain)'s pooled 95th-percentile force direction error (deg).
struct SweepSection {
    /// The readings of the random poses (rad).
    poses: Vec<Vec<f64>>,
    /// `force_distributions.csv`.
    distributions_csv: String,
    /// (model name, gain, pooled force direction p95 in deg).
    p95_force: Vec<(String, f64, f64)>,
}

/// Random poses, six wrench directions: the section's text, the pooled table of each model and
/// gain, and the per-direction table.
///
/// # Errors
/// No valid random pose or a failed sweep.
fn sweep_section(
    bench: &ForceBench<'_>,
    plan: &ForcePlan,
    md: &mut String,
) -> Result<SweepSection> {
    let (device, open) = (bench.device, bench.open);
    let (poses, drawn) = sample_poses(device, &bench.truth_model, open.locked_joint, &plan.sweep)
        .context("drawing random poses")?;
    writeln!(
        md,
        "\n### {} random poses, six wrench directions\n\nReadings uniform within the joint limits (seed {}), joint {} at home; {} draws, poses with a truth-Jacobian condition number above {} (linear rows / {} m) redrawn. Per direction the desired wrench is a unit force (moment) along the tip axis; errors are |angle| between rendered and desired force (moment) and |magnitude error|. Pooled over the three force (moment) directions:\n",
        poses.len(),
        plan.sweep.seed,
        open.locked_joint,
        drawn,
        plan.sweep.max_condition,
        plan.sweep.length_m
    )?;
    writeln!(
        md,
        "| model | G | force dir. median (deg) | force dir. p95 (deg) | force mag. median (%) | force mag. p95 (%) | moment dir. median (deg) | moment dir. p95 (deg) | moment mag. median (%) | moment mag. p95 (%) |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    let mut dist = String::from(
        "model,gain,direction,direction_median_deg,direction_p95_deg,magnitude_median_pct,magnitude_p95_pct\n",
    );
    let mut p95_force = Vec::new();
    let mut per_direction = String::from(
        "\nPer direction (|direction error| in deg, |magnitude error| in %, median / 95th percentile):\n\n| model | G | direction | dir. median | dir. p95 | mag. median | mag. p95 |\n|---|---|---|---|---|---|---|\n",
    );
    for (name, model) in &bench.models {
        for cfg in [open, bench.closed] {
            let e = sweep(device, model, &bench.truth_model, &poses, &cfg)
                .with_context(|| format!("sweep, {name} model"))?;
            let p = pooled(&e);
            writeln!(
                md,
                "| {name} | {} | {:.4} | {:.4} | {:.3} | {:.3} | {:.4} | {:.4} | {:.3} | {:.3} |",
                cfg.gain,
                p.force[0],
                p.force[1],
                p.force[2],
                p.force[3],
                p.moment[0],
                p.moment[1],
                p.moment[2],
                p.moment[3]
            )?;
            write_per_direction(name, cfg.gain, &e, &mut per_direction, &mut dist)?;
            p95_force.push((name.to_string(), cfg.gain, p.force[1]));
        }
    }
    md.push_str(&per_direction);
    Ok(SweepSection {
        poses,
        distributions_csv: dist,
        p95_force,
    })
}

/// The rows of model `name` at gain `gain` in the per-direction table (`per_direction`) and in
/// `force_distributions.csv` (`dist`): median and 95th percentile of |direction error| (deg)
/// and |magnitude error| (%) of each wrench direction of the sweep `e`.
fn write_per_direction(
    name: &str,
    gain: f64,
    e: &SweepErrors,
    per_direction: &mut String,
    dist: &mut String,
) -> Result<()> {
    for d in Direction::ALL {
        let q = direction_stats(e, &[d]);
        let d = d.name();
        writeln!(
            per_direction,
            "| {name} | {gain} | {d} | {:.4} | {:.4} | {:.3} | {:.3} |",
            q[0], q[1], q[2], q[3]
        )?;
        writeln!(
            dist,
            "{name},{gain},{d},{},{},{},{}",
            q[0], q[1], q[2], q[3]
        )?;
    }
    Ok(())
}

/// The quantisation share of the floor: the best model ("calibrated, true pruned") swept again
/// over `poses` with exact readings, open loop.
///
/// # Errors
/// A failed sweep.
fn write_quantisation_share(
    bench: &ForceBench<'_>,
    poses: &[Vec<f64>],
    md: &mut String,
) -> Result<()> {
    let exact = WallConfig {
        quantise: false,
        ..bench.open
    };
    let (_, best) = &bench.models[2];
    let e = sweep(bench.device, best, &bench.truth_model, poses, &exact)
        .context("sweep, exact readings")?;
    let p = pooled(&e);
    writeln!(
        md,
        "\nWithout quantising the controller's readings, the \"calibrated, true pruned\" model's force direction error is {:.4}° median, {:.4}° p95 (G = 0): the rest of its error is the estimation noise of the calibration.",
        p.force[0], p.force[1]
    )?;
    Ok(())
}

/// The reductions of the 95th-percentile force direction error between models, from
/// `p95_force` ((model name, gain, p95 in deg) of the sweep), open loop and at `gain`.
fn write_reductions(p95_force: &[(String, f64, f64)], gain: f64, md: &mut String) -> Result<()> {
    let ratio = |a: &str, b: &str, g: f64| {
        let find = |n: &str| {
            p95_force
                .iter()
                .find(|(m, gg, _)| m == n && *gg == g)
                .map(|x| x.2)
        };
        match (find(a), find(b)) {
            (Some(x), Some(y)) => x / y,
            _ => f64::NAN,
        }
    };
    writeln!(
        md,
        "\nReduction of the 95th-percentile force direction error, nominal / calibrated: {:.1}× open loop, {:.1}× with G = {}; nominal / (calibrated with the pruned parameters at their truth): {:.1}× open loop.\n",
        ratio("nominal", "calibrated", 0.0),
        ratio("nominal", "calibrated", gain),
        gain,
        ratio("nominal", "calibrated, true pruned", 0.0),
    )?;
    Ok(())
}

/// What the calibrated model cannot know: truth deviations it does not list that act on the
/// handle frame (row 0 only moves the base, which body-frame wrenches do not see), each with
/// the force-direction floor it sets.
///
/// # Errors
/// An invalid chain in `device`.
fn write_floor(
    device: &Device,
    truth: &hapcal_sim::Truth,
    calibrated: &Device,
    md: &mut String,
) -> Result<()> {
    let listed: Vec<&str> = (calibrated.calibration.iter())
        .flat_map(|c| c.values.iter().map(|v| v.name.as_str()))
        .collect();
    let chain = device.chain()?;
    let unseen: Vec<(String, f64)> = (truth.deviations.iter())
        .filter(|(n, _)| !listed.contains(&n.as_str()))
        .filter(|(n, _)| {
            chain
                .param_index(n)
                .is_some_and(|i| chain.params()[i].element != 0)
        })
        .cloned()
        .collect();
    for (name, v) in &unseen {
        writeln!(
            md,
            "Floor: `{name}` = {:.3} mrad of the truth is not identifiable from cable distances (pruned, so 0 in the calibrated model). It turns the handle (sensor) frame relative to the model's tip frame, so the calibrated model commands forces turned by {:.4}° in the sensor's frame: a transverse floor of sin({name}) = {:.3} % for a force along z, and the calibrated median force-direction error above. With `{name}` at its truth (rows \"calibrated, true pruned\") what remains is estimation noise and the encoder quantisation of the controller's readings. Force feedback removes the floor as well, because the sensor measures in the true handle frame.\n",
            v * 1e3,
            v.abs().to_degrees(),
            v.abs().sin() * 100.0
        )?;
    }
    Ok(())
}

/// The pose of the Fig. 12 experiment (readings, rad): the home readings (mid-range) with
/// joint 6 at half its upper limit. The paper does not give its handle pose; at home itself
/// (q6 = 0) the wrist axes 5 and 7 are collinear and the fixed-handle statics is singular.
pub fn fig12_pose(device: &Device) -> Vec<f64> {
    let mut theta = home_readings(device);
    if let (Some(slot), Some((_, hi))) = (theta.get_mut(5), device.joint_limits().get(5)) {
        *slot = 0.5 * hi;
    }
    theta
}

/// Fig. 12(b)-style plot: three stacked panels, Fx, Fy and Fz − Fd (mN; Fd = K·s, so the last
/// point is Fz − 2 N) against the wall travel (mm), one colour per model, open loop.
fn fig12_svg(curves: &[(String, Vec<WallSample>)]) -> Result<String> {
    let colours = [
        RGBColor(213, 94, 0),
        RGBColor(0, 114, 178),
        RGBColor(0, 158, 115),
    ];
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 900)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(
            "Virtual wall, handle fixed, open loop (cf. paper Fig. 12)",
            ("sans-serif", 22),
        )?;
        let panels = root.split_evenly((3, 1));
        let names = ["Fx (mN)", "Fy (mN)", "Fz − Fd (mN), Fd = K·s"];
        for (c, area) in panels.iter().enumerate() {
            let series: Vec<(&str, Vec<(f64, f64)>)> = curves
                .iter()
                .map(|(name, wall)| {
                    let pts = wall
                        .iter()
                        .map(|s| {
                            let v = if c == 2 {
                                s.wrench[2] - s.desired_n
                            } else {
                                s.wrench[c]
                            };
                            (s.travel_m * 1e3, v * 1e3)
                        })
                        .filter(|p| p.1.is_finite())
                        .collect();
                    (name.as_str(), pts)
                })
                .collect();
            let (mut lo, mut hi) = (0.0f64, 0.0f64);
            for (_, pts) in &series {
                for &(_, y) in pts {
                    lo = lo.min(y);
                    hi = hi.max(y);
                }
            }
            let pad = 0.08 * (hi - lo).max(1e-3);
            let x_max = (series.iter())
                .flat_map(|(_, p)| p.iter().map(|q| q.0))
                .fold(1e-3, f64::max);
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0.0..x_max, (lo - pad)..(hi + pad))?;
            chart
                .configure_mesh()
                .x_desc("wall travel s (mm)")
                .y_desc(names[c])
                .label_style(("sans-serif", 14))
                .light_line_style(WHITE)
                .draw()?;
            // Last model first and widest, so that lines that coincide all stay visible.
            for (m, (name, pts)) in series.into_iter().enumerate().rev() {
                let colour = colours[m % colours.len()];
                let width = if m == 0 {
                    2
                } else {
                    2 + 3 * u32::try_from(m).unwrap_or(1)
                };
                chart
                    .draw_series(LineSeries::new(pts, colour.mix(0.85).stroke_width(width)))?
                    .label(name.to_owned())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(3))
                    });
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .position(SeriesLabelPosition::LowerLeft)
                .label_font(("sans-serif", 13))
                .draw()?;
        }
        root.present()?;
    }
    Ok(svg)
}

/// The force section of `cargo xtask reproduce-tables`: runs [`run`] with the calibrated model
/// of the reproduction's seed 0 (transmissions `t`, kinematics `kin`) and appends its report
/// to `md` and its files to `files`.
///
/// # Errors
/// As [`run`].
pub fn append_to_reproduction(
    r: &Reference,
    t: &TransmissionFit,
    kin: &Identified,
    files: &mut Vec<(String, String)>,
    md: &mut String,
) -> Result<()> {
    let calibrated = calibrated_device(r, t, kin, "reproduction seed 0".into())?;
    let report = run(
        &r.device,
        &r.truth,
        &calibrated,
        &ForcePlan::reference_device(),
    )?;
    md.push_str(&report.markdown);
    files.extend(report.files);
    Ok(())
}
