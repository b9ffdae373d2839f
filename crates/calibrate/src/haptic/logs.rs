//! Calibration from distance logs as named stages: the training rows, their winsorized copy, the ladder, the chosen rung's fit, the report.

use super::*;

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
/// nominal model on the raw readings against the calibrated device file as the runtime
/// evaluates it, which must give the calibrated model's own distances (`log_placements`).
///
/// # Errors
/// A device that is not the paper's kind ([`HapticDevice::new`]), `--model compliance` on a
/// device file without a handle mass ([`handle_mass_kg`]), too few rows, no more distinct
/// joint configurations than kept parameters ([`check_distinct_configurations`]), a failed
/// identification, or a calibrated device file that does not give the calibration
/// (`log_placements`).
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
pub(super) struct LogTraining {
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
pub(super) fn ladder_of_logs(
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
pub(super) fn transmissions_of(
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
pub(super) fn kept_parameters(id: &Identified) -> Vec<ParamReport> {
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
pub(super) fn no_ext_warning() -> String {
    format!(
        "the training logs have no external-encoder columns (ext1..ext{PARALLELOGRAM_JOINT}): \
         the transmissions are not identified and the kinematic deviations absorb their errors \
         (the paper's \"transmission errors left out\"); record the external encoders to \
         calibrate the transmissions"
    )
}

/// The final fit of a haptic calibration: what the report, the placements and the written
/// device file read.
pub(super) struct LogFit {
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
pub(super) fn fit_compliance(
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
pub(super) fn fit_transmissions(
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
pub(super) fn fit_geometric(
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
pub(super) fn distance_figures(residuals_m: &[f64]) -> Figures {
    Figures {
        mean_absolute_error_m: None,
        distance_error_m: None,
        distance_rms_m: Some(hapcal_metrics::rms(residuals_m)),
        pose: None,
    }
}

/// Largest difference, m, between a log row's distance as the calibration's own model
/// predicts it and as the runtime's model of the device file it writes gives it
/// (`log_placements`): both evaluate the same equations in double precision (the runtime's
/// folded chain against the library's parameterised one agree to rounding, far below a
/// nanometre), so a nanometre, four orders of magnitude below the cable encoder's noise, is a
/// difference of model, never of rounding.
pub const RUNTIME_AGREEMENT_M: f64 = 1e-9;

/// The placements stage of [`calibrate_logs`]: each log's distance RMS with the nominal model
/// on the raw readings and with the calibrated one. The calibrated figures are the runtime's
/// evaluation of the device file the calibration writes ([`crate::record::runtime_device`],
/// each row as `hapcal predict` evaluates it), checked row by row against the calibration's
/// own model (with the compliance, its transmissions and compliances; else the deviations on
/// the readings corrected by the transmissions) within [`RUNTIME_AGREEMENT_M`], on every log,
/// training and test.
///
/// # Errors
/// A device file the runtime refuses, a log the compliance model or the runtime cannot
/// evaluate (log and line), or a row whose distance the two models give farther apart than
/// [`RUNTIME_AGREEMENT_M`] (log, line and both distances).
pub(super) fn log_placements<'a>(
    haptic: &HapticDevice,
    fit: &LogFit,
    x_kin: &[f64],
    logs: impl Iterator<Item = (SetRole, &'a String, &'a [LogRow])>,
) -> Result<Vec<SetReport>> {
    let runtime = crate::record::runtime_device(&fit.calibrated)?;
    let zero = vec![0.0; haptic.chain.n_params()];
    let mut placements = Vec::new();
    for (role, name, rows) in logs {
        let library = match &fit.compliance {
            Some(c) => compliance_distance_residuals_m(haptic, c, rows)
                .with_context(|| format!("log {name}: the calibrated model"))?,
            None => kinematic_residuals_m(haptic, rows, x_kin, fit.transmissions.as_ref()),
        };
        let after = runtime_residuals_m(&runtime, name, rows, &library)?;
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

/// Distance residuals (model − measured, m, one per row) of the log `name`'s `rows` under
/// `runtime`, the runtime's model of the calibrated device file, each row as `hapcal predict`
/// evaluates it ([`crate::predict::handle_at`]); `library` the same residuals under the
/// calibration's own model, which they must equal within [`RUNTIME_AGREEMENT_M`].
///
/// # Errors
/// A reading the runtime refuses (log and line), or the row farthest from the library's
/// beyond the tolerance (log, line and both distances).
fn runtime_residuals_m(
    runtime: &hapcal_runtime::Model,
    name: &str,
    rows: &[LogRow],
    library: &[f64],
) -> Result<Vec<f64>> {
    let mut residuals = Vec::with_capacity(rows.len());
    // (difference, row)
    let mut worst: Option<(f64, usize)> = None;
    for (i, (row, lib)) in rows.iter().zip(library).enumerate() {
        let (_, error) = crate::predict::handle_at(runtime, &row.q, Some(row.distance_m))
            .with_context(|| {
                format!(
                    "log {name}, line {}: the calibrated device file as the runtime reads it",
                    row.line
                )
            })?;
        let e = error.unwrap_or(f64::NAN);
        let gap = (e - lib).abs();
        if worst.is_none_or(|(w, _)| gap > w || !gap.is_finite()) {
            worst = Some((gap, i));
        }
        residuals.push(e);
    }
    match worst {
        Some((gap, i)) if gap.is_nan() || gap > RUNTIME_AGREEMENT_M => {
            let (row, d) = (&rows[i], rows[i].distance_m);
            bail!(
                "the device file calibrate would write does not give its calibration: at line \
                 {} of log {name}, the handle lies {:.6} mm from the cable exit as the \
                 calibration predicts it and {:.6} mm when the device file is evaluated as \
                 hapcal predict evaluates it ({:.3e} m apart, more than {:.0e} m); nothing was \
                 reported or written (a value of the fit the device file does not record, or \
                 one the runtime evaluates otherwise)",
                row.line,
                (library[i] + d) * 1e3,
                (residuals[i] + d) * 1e3,
                gap,
                RUNTIME_AGREEMENT_M
            )
        }
        _ => Ok(residuals),
    }
}

/// One warning per test log the calibration made worse than the nominal model, in the order
/// of the logs.
pub(super) fn worse_logs(placements: &[SetReport]) -> Vec<String> {
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
pub(super) struct LogsChoice {
    /// The rungs' held-out scores (empty when the model was given).
    cross_validation: Vec<crate::report::CvReport>,
    /// The training rows the ladder judged when it judged a sample.
    cross_validated_rows: Option<usize>,
    /// √(rows / distinct rows), the factor the compliances' σ are judged with.
    std_scale: f64,
}

/// What the report of [`calibrate_logs`] lists beside the fit.
pub(super) struct LogsFindings {
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
pub(super) fn logs_report(
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
pub(super) enum Step1<'a> {
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
pub(super) fn choose_model(
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
pub(super) struct Winsorized {
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
pub(super) fn winsorize(
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

#[cfg(test)]
mod tests {
    use super::{RUNTIME_AGREEMENT_M, runtime_residuals_m};
    use std::path::Path;

    /// A library distance farther from the runtime's than [`RUNTIME_AGREEMENT_M`] on one row
    /// of the bundled reference log stops the report, naming the log and the row's line; half
    /// the tolerance passes and the figures are the runtime's.
    #[test]
    fn a_row_the_library_and_the_runtime_give_apart_stops_the_report() {
        let fixtures =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device");
        let runtime = hapcal_runtime::Model::load(&fixtures.join("calibrated.toml")).unwrap();
        let device = hapcal_io::read_device(&fixtures.join("device.toml")).unwrap();
        let rows = hapcal_io::read_log(&fixtures.join("log.csv"), &device)
            .unwrap()
            .rows;
        let exact: Vec<f64> = (rows.iter())
            .map(|r| {
                let (_, e) = crate::predict::handle_at(&runtime, &r.q, Some(r.distance_m)).unwrap();
                e.unwrap()
            })
            .collect();
        let k = 17;
        let mut library = exact.clone();
        library[k] += 0.5 * RUNTIME_AGREEMENT_M;
        let figures = runtime_residuals_m(&runtime, "log.csv", &rows, &library).unwrap();
        assert_eq!(figures, exact);
        library[k] = exact[k] + 2.0 * RUNTIME_AGREEMENT_M;
        let e = runtime_residuals_m(&runtime, "log.csv", &rows, &library).unwrap_err();
        let line = rows[k].line;
        assert!(
            e.to_string()
                .contains(&format!("at line {line} of log log.csv")),
            "{e}"
        );
        library[k] = f64::NAN;
        assert!(runtime_residuals_m(&runtime, "log.csv", &rows, &library).is_err());
    }
}
