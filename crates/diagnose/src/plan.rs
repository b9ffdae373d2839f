//! The diagnoses of files, as `hapcal diagnose` runs them: a haptic device's log read with its
//! device file ([`diagnose_log`]), or a serial arm's data as `hapcal
//! calibrate` reads them, on the geometric baseline of `hapcal_calibrate::baseline`
//! ([`diagnose_arm_data`]).

use std::path::Path;

use anyhow::{Context, Result};
use hapcal_calibrate::baseline::geometric_baseline;
use hapcal_calibrate::calibrate::Plan;

use crate::arm::{ArmConfig, ArmDiagnosis, diagnose_arm};
use crate::{DiagnoseConfig, Diagnosis, diagnose};

/// Reads the device file `device` and its log `data` (columns in `units`) and diagnoses the
/// log with `config`; returns the diagnosis and the log's warnings.
///
/// # Errors
/// Unreadable or invalid files (named with line and column), settings [`diagnose()`] refuses, or
/// a failed baseline fit.
pub fn diagnose_log(
    device: &Path,
    data: &Path,
    units: &hapcal_io::Units,
    config: &DiagnoseConfig,
) -> Result<(Diagnosis, Vec<String>)> {
    let device_file = hapcal_io::read_device(device)
        .with_context(|| format!("reading device {}", device.display()))?;
    let log = hapcal_io::read_log_in(data, &device_file, units)
        .with_context(|| format!("reading log {}", data.display()))?;
    let d = diagnose(&device_file, &log.rows, config)
        .with_context(|| format!("diagnosing {}", data.display()))?;
    Ok((d, log.warnings))
}

/// Marker rows a serial arm's diagnosis reads at most, in all: a longer recording is
/// diagnosed on every `s`-th row of each file, spread over it, and its warnings say so
/// (`hapcal_calibrate::calibrate::Plan::read_rows`). The diagnosis's candidate columns take
/// about 90 kB a row, so 5,000 rows keep it well under 1 GB; the bundled recordings have at
/// most 550 rows.
pub const ARM_MAX_ROWS: usize = 5_000;

/// Loads `plan`'s device and data (at most about [`ARM_MAX_ROWS`] marker rows), fits the
/// geometric baseline (with the kinematic ladder) and diagnoses it; returns the diagnosis and
/// the loaders' warnings.
///
/// # Errors
/// Unreadable or invalid files (named with line and column), too few configurations, a failed
/// baseline fit.
pub fn diagnose_arm_data(plan: &Plan, cfg: &ArmConfig) -> Result<(ArmDiagnosis, Vec<String>)> {
    let plan = Plan {
        read_rows: Some(ARM_MAX_ROWS),
        ..plan.clone()
    };
    let baseline = geometric_baseline(&plan, true)?;
    let d = diagnose_arm(&baseline, cfg).context("diagnosing the geometric baseline")?;
    Ok((d, baseline.warnings))
}

#[cfg(test)]
mod tests {
    use crate::baseline_model;
    use hapcal_contract::ModelName;

    #[test]
    fn baselines_are_the_two_models_by_any_of_their_names() {
        let err = baseline_model("everything").expect_err("unknown baseline");
        assert!(err.to_string().contains("baseline must be"), "{err}");
        // A model the haptic diagnosis does not start from is refused by its --model name.
        let err = baseline_model("mass-compliance").expect_err("not a baseline");
        assert!(
            err.to_string().contains(
                "baseline must be transmissions or geometric (full and kinematics are the \
                 same): a haptic device's log is diagnosed against one of the two, not \
                 mass-compliance"
            ),
            "{err}"
        );
        for (name, model) in [
            ("transmissions", ModelName::Transmissions),
            ("full", ModelName::Transmissions),
            ("geometric", ModelName::Geometric),
            ("kinematics", ModelName::Geometric),
            ("Full", ModelName::Transmissions),
            ("GEOMETRIC", ModelName::Geometric),
        ] {
            assert_eq!(baseline_model(name).expect("a baseline"), model, "{name}");
        }
    }
}
