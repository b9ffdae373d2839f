//! The setup check of a haptic device's logs: the mistakes of
//! [`crate::setup_findings::MistakeClass`], for the joint readings, cable distances and external
//! encoders of the paper's device.
//!
//! The log's counterpart of the frames-only residual is the cable distance of the nominal
//! device, `d_i − |P(q_i)|` with the raw joint readings (transmissions ideal, kinematics
//! nominal) and one constant removed (the cable's zero, which no assembly gets exactly right):
//! its RMS is what manufacturing deviations and transmission errors leave, millimetres on
//! a right log. Each hypothesis of a mistake (distances in millimetres or centimetres,
//! joint readings in degrees, two joint columns swapped or all reversed, the joint rows out of
//! step with the distances) reads the log as it says, and the residual is compared with the
//! log's as given, relative to the spread of the distances (a hypothesis that shrinks the
//! distances shrinks their residual without explaining anything), with the factors and
//! severities of [`crate::setup_findings`]. The external encoders are checked against the joint
//! readings they measure: an encoder reads its joint's output angle, within the
//! transmission's error (milliradians), so a column that matches another joint, or its own in
//! degrees, is named. A joint column that never changes is found from the data. A log that
//! violates the device's joint limits is read again without them, so that degrees or swapped
//! columns are named instead of the first reading outside a limit.

use std::path::PathBuf;

use anyhow::{Context, Result};
use hapcal_io::{Device, LogRow};

use crate::noise::PLAUSIBLE_FRAMES_ONLY_RMS_M;
use crate::setup_families::{
    Layout, LengthGroup, MAX_ROW_SHIFT, SetupData, Tier, general_hypotheses, judge_with_fitted,
    row_hypotheses, shift_readings,
};
use crate::setup_findings::{
    Corrected, Finding, MAX_CHECK_ROWS, MistakeClass, OPEN_LIMIT, OVERWHELMING_FACTOR, Residual,
    ResidualOf, SetupReport, Severity, frozen_columns,
};

/// RMS difference (rad) between an external encoder and its joint's reading beyond which the
/// column cannot be that joint's output: the paper's capstan and parallelogram errors are
/// milliradians (docs/design.md §3), a swapped column or degrees read as radians tenths of a
/// radian to radians.
pub const PLAUSIBLE_EXT_RAD: f64 = 0.05;

/// The setup check of a haptic device's training logs `paths`, read with `units` (the unit
/// flags and column edits of the command line).
///
/// # Errors
/// A log that cannot be read even without the joint limits (file, line, column), or a device
/// whose chain does not compile.
pub fn check_logs(
    device: &Device,
    paths: &[PathBuf],
    units: &hapcal_io::Units,
) -> Result<SetupReport> {
    let chain = device
        .chain()
        .context("building the device's kinematic chain")?;
    // The hypotheses correct the stretch of rows the check judges (a row shift is a shift of
    // its rows): the logs are streamed and only that stretch is kept, each hypothesis holds a
    // copy of it, never of the whole log; the residuals are taken over at most
    // MAX_CHECK_ROWS of them.
    let lengths: Vec<usize> = paths.iter().map(|p| hapcal_io::count_log_rows(p)).collect();
    let stretch = judged_stretch(lengths.iter().sum());
    let mut rows = Vec::new();
    let mut outside_limits = None;
    let mut first = 0;
    for (path, length) in paths.iter().zip(&lengths) {
        let keep = stretch.start.saturating_sub(first)..stretch.end.saturating_sub(first);
        first += length;
        match read_stretch(path, device, units, keep.clone()) {
            Ok(kept) => rows.extend(kept),
            Err(e) => {
                // Read again without the limits: the check names what put the readings there.
                let kept = read_stretch(path, &unbounded(device), units, keep)
                    .with_context(|| format!("reading log {}", path.display()))?;
                outside_limits.get_or_insert_with(|| e.to_string());
                rows.extend(kept);
            }
        }
    }
    let residual = |rows: &[LogRow]| distance_residual(&chain, &thinned(rows.to_vec()));
    let as_given = residual(&rows);
    let n_joints = chain.n_joints();
    let given = LogRows(rows);
    // A distance residual costs microseconds a row: every family, whatever the residual; the
    // free scales and couplings when the residual is more than right data leave.
    let screen = |d: &LogRows| Some(residual(&d.0));
    let mut hypotheses = log_hypotheses(&chain, &given, paths);
    let layout = log_layout(n_joints);
    let judged = judge_with_fitted(as_given, &given, &layout, &mut hypotheses, &screen);
    let n_hypotheses = hypotheses.len();
    let mut findings: Vec<Finding> = judged.finding.into_iter().collect();
    // Readings out of step by a fraction of a row are a latency, which the diagnosis models.
    if let Some(f) = findings.first_mut()
        && f.class == MistakeClass::RowShift
        && let Some(latency) = latency(&chain, &given.0, &as_given)
    {
        *f = latency;
    }
    let rows = thinned(given.0);
    // The external encoders are judged against the joint readings as an error's correction
    // reads them: two joint columns swapped leave their encoders where they belong.
    let corrected = match judged.error_at.map(|i| &hypotheses[i]) {
        Some(h) if h.class != MistakeClass::LengthUnit => &h.data.0,
        _ => &rows,
    };
    let closest = judged.closest;
    findings.extend(frozen_joints(device, &rows));
    findings.extend(external_encoders(corrected, n_joints));
    if findings.iter().all(|f| f.severity != Severity::Error) {
        findings.extend(cable_zero(&chain, &rows, as_given));
    }
    SetupReport::add_implausible(
        &mut findings,
        as_given,
        format!(
            "the nominal device misses the cable distances by {} RMS, more than \
                     manufacturing deviations produce ({:.0} mm), and none of the {n_hypotheses} \
                     checked mistakes explains it: these logs do not come from this device (or \
                     the setup is wrong in a way not checked)",
            as_given.text(),
            PLAUSIBLE_FRAMES_ONLY_RMS_M * 1e3
        ),
        "check --device and the columns and units of the logs",
    );
    if findings.iter().all(|f| f.severity != Severity::Error)
        && let Some(limit) = &outside_limits
    {
        // Nothing explains the readings outside the limits: the reader's own words.
        let message = format!("{limit}, and none of the checked mistakes explains it");
        let fix = "check the log's columns and units against the device file";
        let finding = Finding::new(MistakeClass::NoHypothesis, Severity::Error, message, fix);
        findings.insert(0, finding.with_residuals(as_given, None));
    }
    findings.sort_by_key(|f| f.severity != Severity::Error);
    Ok(SetupReport {
        n_rows: rows.len(),
        as_given,
        n_hypotheses,
        closest,
        findings,
    })
}

/// Every hypothesis of a mistake for the log rows `given` (of the logs `paths`) on `chain`:
/// the general families, per column and per row too (a distance residual costs microseconds a
/// row).
fn log_hypotheses(
    chain: &hapcal_kinematics::Chain,
    given: &LogRows,
    paths: &[PathBuf],
) -> Vec<Corrected<LogRows>> {
    let layout = log_layout(chain.n_joints());
    let mut hypotheses = general_hypotheses(given, &layout, Tier::Always);
    hypotheses.extend(general_hypotheses(given, &layout, Tier::Suspicious));
    let checked = thinned(given.0.clone());
    let e = distance_errors(chain, &checked);
    let zero = median(e.clone());
    let per_row: Vec<(usize, u64, f64)> = (checked.iter().zip(&e))
        .map(|(r, e)| (0, r.line, (e - zero).abs()))
        .collect();
    let names = vec![log_names(paths)];
    hypotheses.extend(row_hypotheses(given, &layout, &per_row, &names, |drop| {
        let mut rows = checked.clone();
        rows.retain(|r| !drop.contains(&(0, r.line)));
        Some(LogRows(rows))
    }));
    hypotheses
}

/// The columns of a haptic device's log of `n_joints` joints, as the check's families see
/// them.
fn log_layout(n_joints: usize) -> Layout {
    Layout {
        lengths: vec![LengthGroup {
            label: "distance_m".to_owned(),
            words: "the cable distances (distance_m)".to_owned(),
        }],
        paired_rows: true,
        ..Layout::numbered(n_joints, |j| format!("joint {} (q{})", j + 1, j + 1))
    }
}

/// Distance from a whole number of rows (rows) from which the lag that fits best may be a
/// latency, not rows out of step: a shifted export moves whole rows, a latency any fraction
/// (45 ms on a 20 Hz log is 0.9 row).
const FRACTIONAL_LAG: f64 = 0.1;

/// Factor by which the fractional lag's residual must lie below the nearest whole row's for a
/// latency: the noise of a RMS over the rows checked is a few per cent.
const WHOLE_ROW_GAIN: f64 = 0.9;

/// The latency finding of `rows` on `chain` (residual `as_given`), when the joint readings
/// fit the distances best interpolated a fraction of a row later or earlier (within ±3 rows,
/// on a grid of 0.05 row), that fraction lies [`FRACTIONAL_LAG`] or more from a whole row and
/// fits better than it ([`WHOLE_ROW_GAIN`]): a warning, since `diagnose` models a latency; `None` otherwise.
fn latency(
    chain: &hapcal_kinematics::Chain,
    rows: &[LogRow],
    as_given: &Residual,
) -> Option<Finding> {
    let n = rows.len();
    if n < 12 {
        return None;
    }
    let at = |lag: f64| -> Residual {
        let moved: Vec<LogRow> = (0..n)
            .filter_map(|i| {
                let x = i as f64 + lag;
                if x < 0.0 || x > (n - 1) as f64 {
                    return None;
                }
                let (lo, w) = (x.floor() as usize, x - x.floor());
                let hi = (lo + 1).min(n - 1);
                let mut row = rows[i].clone();
                for (j, q) in row.q.iter_mut().enumerate() {
                    *q = (1.0 - w) * rows[lo].q[j] + w * rows[hi].q[j];
                }
                Some(row)
            })
            .collect();
        distance_residual(chain, &thinned(moved))
    };
    let length = |r: &Residual| r.length_rms_m.unwrap_or(f64::INFINITY);
    let (lag, best) = (-60..=60)
        .map(|k| f64::from(k) * 0.05)
        .map(|lag| (lag, at(lag)))
        .min_by(|a, b| length(&a.1).total_cmp(&length(&b.1)))?;
    // A whole-row shift interpolates to itself: between rows, the fraction must fit better.
    let whole = at(lag.round());
    if (lag - lag.round()).abs() < FRACTIONAL_LAG - 1e-9
        || length(&best) > WHOLE_ROW_GAIN * length(&whole)
    {
        return None;
    }
    let period = {
        let t: Vec<f64> = rows.iter().filter_map(|r| r.t_s).collect();
        (t.len() == n && n > 1).then(|| (t[n - 1] - t[0]) / (n - 1) as f64)
    };
    let time = period
        .filter(|p| *p > 0.0 && p.is_finite())
        .map_or_else(String::new, |p| {
            format!(
                ", {:.0} ms at the log's {:.0} Hz",
                lag.abs() * p * 1e3,
                1.0 / p
            )
        });
    let (who, how) = if lag > 0.0 {
        ("the joint readings lag", "behind")
    } else {
        ("the joint readings lead", "ahead of")
    };
    let lag_rows = lag.abs();
    let message = format!(
        "{who} the cable distances by {lag_rows:.2} rows{time}: a latency (the readings fit \
         best {lag_rows:.2} rows {how} the distances, between whole rows), not rows out of step"
    );
    let fix = format!(
        "sample the joints and the cable together, or let hapcal diagnose model the {}",
        hapcal_contract::Effect::Latency.name()
    );
    let finding = Finding::new(MistakeClass::Latency, Severity::Warning, message, fix);
    Some(finding.with_residuals(*as_given, Some(best)))
}

/// A haptic device's log rows, as the general families correct them.
#[derive(Clone)]
struct LogRows(Vec<LogRow>);

impl SetupData for LogRows {
    fn with_joints(&self, f: &(dyn Fn(&mut [f64]) + Sync)) -> Self {
        LogRows(map(&self.0, |r| f(&mut r.q)))
    }

    fn with_lengths(&self, _group: Option<usize>, factor: f64) -> Self {
        LogRows(map(&self.0, |r| r.distance_m *= factor))
    }

    fn with_shift(&self, shift: isize, from: Option<(usize, u64)>) -> Option<Self> {
        let from = from.map_or(0, |(_, line)| line);
        let out = shift_readings(
            &self.0,
            shift,
            from,
            |r| r.line,
            |r, p| r.q.clone_from(&p.q),
        );
        (out.len() >= 6).then_some(LogRows(out))
    }
}

/// The logs' file names, as the row findings name them (`log.csv`, or `a.csv+b.csv`).
fn log_names(paths: &[PathBuf]) -> String {
    (paths.iter())
        .map(|p| {
            p.file_name().map_or_else(
                || p.display().to_string(),
                |f| f.to_string_lossy().into_owned(),
            )
        })
        .collect::<Vec<_>>()
        .join("+")
}

/// The device with every joint's range opened: the readings of a log read as they are.
pub(crate) fn unbounded(device: &Device) -> Device {
    let mut open = device.clone();
    for joint in &mut open.joints {
        joint.lower_rad = -OPEN_LIMIT;
        joint.upper_rad = OPEN_LIMIT;
    }
    open
}

/// The rows of a log of `n_rows` rows the check judges (indices): the middle stretch of
/// [`MAX_CHECK_ROWS`] rows ([`thinned`]) and the [`MAX_ROW_SHIFT`] rows on either side that
/// a shift of the readings by whole rows moves into it; every row of a shorter log.
fn judged_stretch(n_rows: usize) -> std::ops::Range<usize> {
    middle_range(n_rows, MAX_CHECK_ROWS + 2 * MAX_ROW_SHIFT)
}

/// The rows of the log at `path` whose indices lie in `keep`, every row read and checked
/// as [`hapcal_io::read_log_in`] does, only those kept in memory.
///
/// # Errors
/// [`hapcal_io::read_log_in`]'s.
fn read_stretch(
    path: &std::path::Path,
    device: &Device,
    units: &hapcal_io::Units,
    keep: std::ops::Range<usize>,
) -> Result<Vec<LogRow>, hapcal_io::Error> {
    let mut reader = hapcal_io::LogReader::open(path, device, units)?;
    let mut rows = Vec::with_capacity(keep.len().min(MAX_CHECK_ROWS + 2 * MAX_ROW_SHIFT));
    let mut index = 0;
    while let Some(row) = reader.next_row()? {
        if keep.contains(&index) {
            rows.push(row);
        }
        index += 1;
    }
    reader.finish()?;
    Ok(rows)
}

/// At most [`MAX_CHECK_ROWS`] rows, evenly spaced (consecutive pairs kept for the row
/// shifts: the thinned log is a run of consecutive rows when the log is longer).
fn thinned(rows: Vec<LogRow>) -> Vec<LogRow> {
    // One contiguous stretch from the middle keeps the row order a shift needs, and a
    // haptic device's recording covers its workspace in any stretch of this length.
    middle(rows, MAX_CHECK_ROWS)
}

/// The indices of the `keep` rows in the middle of `n_rows` rows (from row
/// `(n_rows − keep)/2`), or of every row.
fn middle_range(n_rows: usize, keep: usize) -> std::ops::Range<usize> {
    let start = n_rows.saturating_sub(keep) / 2;
    start..n_rows.min(start + keep)
}

/// The `keep` rows in the middle of `rows` ([`middle_range`]).
fn middle(mut rows: Vec<LogRow>, keep: usize) -> Vec<LogRow> {
    let range = middle_range(rows.len(), keep);
    rows.truncate(range.end);
    rows.drain(..range.start);
    rows.shrink_to_fit();
    rows
}

/// `rows` with `edit` applied to each.
fn map(rows: &[LogRow], edit: impl Fn(&mut LogRow)) -> Vec<LogRow> {
    rows.iter()
        .cloned()
        .map(|mut r| {
            edit(&mut r);
            r
        })
        .collect()
}

/// Largest constant (m) by which a right log's cable distances may differ from the nominal
/// device's: the cable's zero and the link lengths it stands in for are assembled to a
/// real device's manufacturing tolerance (15 mm, as a link length); beyond it the calibration
/// would build the constant into a link length (a log whose distances are 50 mm long
/// moves dd1 by +31.6 mm, then stops as another device).
pub const CABLE_ZERO_MAX_M: f64 = 0.015;

/// The cable distances' zero when it lies beyond [`CABLE_ZERO_MAX_M`] and the residual about
/// it (`as_given`) is what right logs leave ([`Residual::is_clean`], 10 mm; the reference log
/// leaves 2.4 mm): the median of
/// `d − |P(q)|` of the nominal device over `rows`, as a finding whose fix is the column offset
/// that removes it (`--column-offset distance_m=…`); `None` otherwise.
fn cable_zero(
    chain: &hapcal_kinematics::Chain,
    rows: &[LogRow],
    as_given: Residual,
) -> Option<Finding> {
    // A constant explains the distances only when what it leaves is what right logs leave:
    // a device with longer links is tens of millimetres long in a way that varies with the
    // configuration (the hostile sweep's links 51 to 78 mm longer leave 11 to 15 mm).
    let zero = nominal_cable_zero(chain, rows);
    if zero.is_nan() || zero.abs() <= CABLE_ZERO_MAX_M || !as_given.is_clean() {
        return None;
    }
    let message = format!(
        "the cable distances are {:.1} mm {} than the nominal device's in every row (the median \
         of {} rows; their residual about it is {}): the cable encoder's zero is off, a constant \
         no link length has",
        zero.abs() * 1e3,
        if zero > 0.0 { "longer" } else { "shorter" },
        rows.len(),
        as_given.text()
    );
    let fix = format!("--column-offset distance_m={:.4}", -zero);
    let finding = Finding::new(MistakeClass::ColumnZero, Severity::Error, message, fix);
    Some(finding.with_residuals(as_given, None))
}

/// The nominal device's cable-distance errors of `rows`: `d − |P(q)|` per row, m.
fn distance_errors(chain: &hapcal_kinematics::Chain, rows: &[LogRow]) -> Vec<f64> {
    let x0 = vec![0.0; chain.n_params()];
    (rows.iter())
        .map(|r| r.distance_m - chain.end_point(&x0, &r.q).coords.norm())
        .collect()
}

/// The nominal device's cable zero of `rows`: the median of [`distance_errors`], m.
fn nominal_cable_zero(chain: &hapcal_kinematics::Chain, rows: &[LogRow]) -> f64 {
    median(distance_errors(chain, rows))
}

/// The nominal device's cable-distance residual of `rows`: the RMS of `d − |P(q)|` about its
/// median with the farthest [`TRIMMED_SHARE`] of the rows set aside ([`trimmed_rms`]), and the
/// robust spread of the distances about theirs ([`about_median`]): one mistyped row leaves
/// both nearly where they were, while a tenth of the rows whose distances belong to other
/// joint readings raises the residual.
fn distance_residual(chain: &hapcal_kinematics::Chain, rows: &[LogRow]) -> Residual {
    let e = distance_errors(chain, rows);
    let d: Vec<f64> = rows.iter().map(|r| r.distance_m).collect();
    Residual {
        of: ResidualOf::CableDistance,
        length_rms_m: trimmed_rms(e),
        orientation_rms_rad: None,
        spread_m: about_median(d),
    }
}

/// Share of the rows, farthest from the median, that [`trimmed_rms`] sets aside: a mistyped
/// reading or two in a log of a hundred rows, not the tenth of a log whose rows were mixed up.
const TRIMMED_SHARE: f64 = 0.02;

/// RMS of `v` about its median over all but its [`TRIMMED_SHARE`] farthest values (at least
/// one once `v` holds 20 values); `None` when empty or not finite.
fn trimmed_rms(v: Vec<f64>) -> Option<f64> {
    let m = median(v.clone());
    let mut sq: Vec<f64> = v.iter().map(|x| (x - m).powi(2)).collect();
    sq.sort_by(f64::total_cmp);
    let kept = sq.len() - (TRIMMED_SHARE * sq.len() as f64).round() as usize;
    let rms = (sq[..kept].iter().sum::<f64>() / kept.max(1) as f64).sqrt();
    (kept > 0 && rms.is_finite()).then_some(rms)
}

/// Robust RMS of `v` about its median: `√(median((v − m)²)/0.4549)`, 0.4549 the median of χ²
/// with one degree of freedom, so that Gaussian values give their standard deviation while a
/// few gross rows (a mistyped reading) move it by little; `None` when empty or not finite.
fn about_median(v: Vec<f64>) -> Option<f64> {
    let m = median(v.clone());
    let rms = (median(v.iter().map(|x| (x - m).powi(2)).collect()) / 0.454_936).sqrt();
    rms.is_finite().then_some(rms)
}

/// The median of `v` (NaN for an empty `v`).
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Joint columns that never change while the device lets the joint move.
fn frozen_joints(device: &Device, rows: &[LogRow]) -> Vec<Finding> {
    let limits = device.joint_limits();
    let q: Vec<&[f64]> = rows.iter().map(|r| &r.q[..]).collect();
    if rows.len() <= 2 {
        return Vec::new();
    }
    (frozen_columns(&q, &limits, limits.len()).into_iter())
        .map(|(j, lo)| {
            let message = format!(
                "q{} reads {lo} on every row while the device lets the joint move: a \
                 disconnected or frozen encoder column",
                j + 1
            );
            let fix = format!(
                "check the encoder of joint {} and the column q{}",
                j + 1,
                j + 1
            );
            Finding::new(MistakeClass::FrozenJoint, Severity::Error, message, fix)
        })
        .collect()
}

/// External-encoder columns that cannot be their joint's output: one that matches another
/// joint's readings, or its own in degrees.
fn external_encoders(rows: &[LogRow], n_joints: usize) -> Vec<Finding> {
    let n_ext = rows.iter().map(|r| r.ext.len()).max().unwrap_or(0);
    let rms_against = |k: usize, j: usize, scale: f64| {
        let d: Vec<f64> = (rows.iter())
            .filter_map(|r| Some(r.ext.get(k).copied().flatten()? * scale - *r.q.get(j)?))
            .collect();
        let n = d.len();
        (n > 0).then(|| (d.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt())
    };
    let mut findings = Vec::new();
    for k in 0..n_ext.min(n_joints) {
        let Some(own) = rms_against(k, k, 1.0) else {
            continue;
        };
        if own <= PLAUSIBLE_EXT_RAD {
            continue;
        }
        let degrees = rms_against(k, k, 1f64.to_radians()).filter(|&e| e <= PLAUSIBLE_EXT_RAD);
        let other = (0..n_joints)
            .filter(|&j| j != k)
            .filter_map(|j| Some((j, rms_against(k, j, 1.0)?)))
            .filter(|&(_, e)| e <= PLAUSIBLE_EXT_RAD && e * OVERWHELMING_FACTOR <= own)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let n = k + 1;
        let (class, message, fix) = match (degrees, other) {
            (Some(e), _) => (
                MistakeClass::AngleUnit,
                format!(
                    "ext{n} looks like degrees read as radians: it differs from q{n} by {own:.3} \
                     rad RMS as given, {e:.4} rad read as degrees"
                ),
                format!("write ext{n} in radians (multiply by π/180)"),
            ),
            (None, Some((j, e))) => (
                MistakeClass::JointOrder,
                format!(
                    "ext{n} follows joint {} (RMS {e:.4} rad from q{}), not joint {n} ({own:.3} \
                     rad from q{n}): the external-encoder columns look swapped",
                    j + 1,
                    j + 1,
                ),
                format!("put joint {n}'s external encoder in column ext{n}"),
            ),
            (None, None) => continue,
        };
        findings.push(Finding::new(class, Severity::Error, message, fix));
    }
    findings
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference device and the path of its bundled log.
    fn reference() -> (Device, PathBuf) {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
        let device =
            hapcal_io::read_device(&root.join("reference-device/device.toml")).expect("device");
        (device, root.join("reference-device/log.csv"))
    }

    #[test]
    fn the_log_check_generates_every_family_of_its_kind() {
        let (device, log) = reference();
        let rows = hapcal_io::read_log(&log, &device).expect("log").rows;
        let chain = device.chain().expect("chain");
        let hypotheses = log_hypotheses(&chain, &LogRows(rows), &[log]);
        crate::setup_families::assert_families(
            crate::setup_families::DataKind::HapticLogs,
            &hypotheses,
            &[MistakeClass::ColumnSign],
        );
    }

    #[test]
    fn a_tenth_of_the_rows_with_other_rows_distances_do_not_belong() {
        // The reference log with the distances of every tenth row passed round a cycle of
        // those rows (the joint readings stay): the nominal residual of the other rows is
        // millimetres, theirs the spread of the distances, tens of millimetres.
        let (device, log) = reference();
        let text = std::fs::read_to_string(log).expect("log");
        let mut lines: Vec<Vec<String>> = (text.lines())
            .map(|l| l.split(',').map(str::to_owned).collect())
            .collect();
        let column = (lines[0].iter().position(|c| c == "distance_m")).expect("distance_m");
        let picked: Vec<usize> = (1..lines.len()).filter(|i| i % 10 == 3).collect();
        let distances: Vec<String> = picked.iter().map(|&i| lines[i][column].clone()).collect();
        for (k, &i) in picked.iter().enumerate() {
            lines[i][column] = distances[(k + 1) % distances.len()].clone();
        }
        let dir = std::env::temp_dir().join(format!("hapcal-mixed-log-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a scratch directory");
        let path = dir.join("log.csv");
        let csv: Vec<String> = lines.iter().map(|l| l.join(",")).collect();
        std::fs::write(&path, csv.join("\n") + "\n").expect("the mixed log");
        let report = check_logs(
            &device,
            std::slice::from_ref(&path),
            &hapcal_io::Units::default(),
        );
        let _ = std::fs::remove_dir_all(&dir);
        let report = report.expect("the check runs");
        let f = report.overwhelming().expect("an error finding");
        assert_eq!(f.class, MistakeClass::RowMismatch, "{}", f.text());
        // The rows set aside are mixed ones: most of them (a few got a distance near their
        // own), the first one named by its line.
        let flagged: usize = (f.message.split(' ').next())
            .and_then(|n| n.parse().ok())
            .expect("the count of rows set aside");
        assert!(
            2 * flagged >= picked.len() && flagged <= picked.len(),
            "{} of {}: {}",
            flagged,
            picked.len(),
            f.text()
        );
        assert!(f.message.contains("log.csv:4,"), "{}", f.text());
    }

    #[test]
    fn a_cable_zero_beyond_tolerance_is_named_with_the_offset_that_removes_it() {
        // The reference log with every distance 50 mm longer: the nominal device's cable
        // zero on the log as recorded is millimetres, so the median names the 50 mm to the
        // residual's RMS about it (2.4 mm); 10 mm longer is within tolerance.
        let (device, log) = reference();
        let rows = hapcal_io::read_log(&log, &device).expect("log").rows;
        let chain = device.chain().expect("chain");
        let rows = thinned(rows);
        let as_given = distance_residual(&chain, &rows);
        let noise = as_given.length_rms_m.expect("a residual");
        let longer = |extra: f64| -> Vec<LogRow> {
            (rows.iter().cloned())
                .map(|mut r| {
                    r.distance_m += extra;
                    r
                })
                .collect()
        };
        assert!(cable_zero(&chain, &rows, as_given).is_none());
        assert!(cable_zero(&chain, &longer(0.010), as_given).is_none());
        let f = cable_zero(&chain, &longer(0.050), as_given).expect("a finding");
        assert_eq!(f.class, MistakeClass::ColumnZero);
        assert_eq!(f.severity, Severity::Error);
        let offset: f64 = (f.fix.strip_prefix("--column-offset distance_m="))
            .and_then(|v| v.parse().ok())
            .expect("the fix is the column offset");
        let zero = nominal_cable_zero(&chain, &rows);
        assert!(
            (offset + 0.050 + zero).abs() < 1e-4,
            "{offset} against −(50 mm + the log's own zero {zero}); {noise}"
        );
    }

    #[test]
    fn the_trimmed_rms_sets_aside_a_mistyped_row_but_not_a_tenth() {
        // ±1 mm alternating: RMS 1 mm about the median; one row at 1 m is set aside, ten of a
        // hundred are not.
        let base: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1e-3 } else { -1e-3 })
            .collect();
        let rms = |v: Vec<f64>| trimmed_rms(v).expect("finite");
        assert!((rms(base.clone()) - 1e-3).abs() < 1e-12);
        let mut one = base.clone();
        one[10] = 1.0;
        assert!((rms(one) - 1e-3).abs() < 1e-4);
        let mut tenth = base;
        for v in tenth.iter_mut().step_by(10) {
            *v = 0.05;
        }
        assert!(rms(tenth) > 10e-3);
    }
}
