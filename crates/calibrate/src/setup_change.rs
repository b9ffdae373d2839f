//! The change-point family of the setup check
//! ([`crate::setup_families::Family::ChangePoint`]): one set of frames
//! holds before a row of a measurement file and another from that row on.
//!
//! An instrument (a tracker, a camera) knocked or moved between two rows, or a marker taken
//! off its link and mounted again, leaves two recordings in one file: the rows before the
//! change fit the nominal robot with one instrument frame and one marker frame, the rows from
//! it on with another. No single pair of frames fits both, and the frames-only residual of the
//! whole file is the size of the move (millimetres to centimetres).
//!
//! The change is found by a scan over the rows of each file: for a split before row `k`, the
//! rows on either side get frames of their own (instrument and markers, each part fitted in
//! closed form) and the split that leaves the least residual in all is the change point (a
//! coarse grid, then finer grids about the best split down to one row of the rows checked:
//! a few dozen closed-form fits per file). Two hypotheses are generated at it, and the judge
//! (`judge` in [`crate::setup_findings`]) tells which frame moved by which one explains the
//! data:
//!
//! - **the instrument moved**: the measurements from row `k` on, carried into the first
//!   part's instrument frame by the move the two parts' instrument frames differ by, fitted
//!   with one instrument and one marker frame; the finding gives the move of the instrument
//!   relative to the robot's base (degrees, millimetres);
//! - **a marker re-mounted**: the samples from row `k` on taken as those of another marker on
//!   the same tip, fitted with one instrument frame; the finding gives how far the marker's
//!   offset on its tip moved (millimetres).
//!
//! A real recording's residual drifts (warm-up, a slowly settling mount): a two-part fit of
//! a drift lowers the residual a little wherever the split lies. A change is a step: moving
//! the split by an eighth of the file's rows to either side must raise the residual left by
//! [`STEP_FACTOR`] or more, and the split must at least halve the residual of the whole file
//! ([`crate::setup_findings::SUGGESTIVE_FACTOR`]), or no hypothesis is generated; the
//! judge's rule ([`crate::setup_findings::OVERWHELMING_FACTOR`] with a plausible residual
//! left) makes one a finding.
//!
//! The scan runs when the data as given leave more than right data do (`Tier::Suspicious`)
//! or when the per-row residuals of the fit to every row jump from a row on
//! (`residuals_jump`, free: the residuals are the row families' own). Otherwise a file is
//! probed first (`probe`): the errors of the fit to every row, scanned for the share of them a
//! shift of the later samples takes (a marker's offset moved, the instrument turned and
//! translated; [`PROBE_SHARE`]), one closed-form fit against the few dozen of the scan. A
//! marker re-mounted by 18 mm halfway through a file leaves 9 mm, a residual right data can
//! leave, so that neither of the other gates opens for it; its shift takes nine tenths of the
//! residual. On right data the probe finds nothing and no hypothesis is added.
//!
//! The fixes are what a calibration supports: it fits one instrument frame, so data recorded
//! before and after the instrument moved are calibrated apart (the file split at the line
//! named); it fits one frame per marker and one marker per tip, so the samples after a
//! re-mount go to columns of a new marker on a link fixed to the same moving link as the tip
//! (`--tips`, `fixed_twin`), or, without such a link, the file is split as well.

use hapcal_io::MeasurementTable;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::setup_families::splits;
use crate::setup_findings::{Corrected, MistakeClass, SUGGESTIVE_FACTOR, mm};

/// Rows each part of a split holds at least: the frames of a part (6 of the instrument, 3 of
/// each marker's offset) from 3 coordinates per row, with as many rows again to spare.
pub const MIN_PART_ROWS: usize = 10;

/// Factor by which the residual left (the sum of squares of both parts, m²) must rise when
/// the split moves by an eighth of the file's rows to either side: a step in the frames puts
/// rows of one recording among the other's and raises it by the move's size squared per row
/// moved (tens to thousands of times for a move a finding can name); a drift raises it by a
/// few per cent.
pub const STEP_FACTOR: f64 = 2.0;

/// Splits tried per level of the scan: the first level spreads them over the file, each next
/// one over the two steps about the best split, until the step is one row.
const SCAN_SPLITS: usize = 16;

/// Rows a part holds at least in the neighbouring splits of the step test (the frames of a
/// part are determined from four rows of a tip that turns).
const MIN_NEIGHBOUR_ROWS: usize = 4;

/// The frames-only fit (closed form) of one part of the rows.
#[derive(Clone, Debug)]
pub(crate) struct PartFit {
    /// The part's squared residual, m²: the mean over the rows checked of each row's squared
    /// position error (plus its weighted orientation term) times the part's rows.
    pub(crate) cost_m2: f64,
    /// The instrument's rotation `R₀` and translation `t` (m): a point `p` of the robot's base
    /// is seen at `R₀·p + t`.
    pub(crate) instrument: (Matrix3<f64>, Vector3<f64>),
    /// Each marker's offset on its tip, m, in the tip's frame.
    pub(crate) marker_offsets_m: Vec<Vector3<f64>>,
    /// Each marker sample checked, in the rows' order, with its error under these frames.
    pub(crate) samples: Vec<SampleResidual>,
}

/// One marker sample's position error under a part's frames, as the probe reads it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SampleResidual {
    /// The sample's file (index into the tables).
    pub(crate) file: usize,
    /// The sample's marker.
    pub(crate) marker: usize,
    /// The error (model − measured), m, in the instrument's frame.
    pub(crate) error_m: Vector3<f64>,
    /// The same error in the tip's frame (`(R₀·R_tip)ᵀ·e`), m: a marker mounted again moves
    /// every later sample's by the move of its offset.
    pub(crate) in_tip_m: Vector3<f64>,
    /// The measured position, m, in the instrument's frame.
    pub(crate) measured_m: Vector3<f64>,
}

/// The closed-form fit of tables with markers on the tips given (marker k on tip `tips[k]`);
/// `None` when the fit does not apply (distance rows, too few samples).
pub(crate) type PartFitFn<'a> =
    &'a (dyn Fn(&[MeasurementTable], &[usize]) -> Option<PartFit> + Sync);

/// Where the files of a check come from, as the change-point hypotheses name them.
pub(crate) struct ChangeInput<'a> {
    /// The training tables as read.
    pub(crate) tables: &'a [MeasurementTable],
    /// Each table's file name, as the findings name it (`data.csv`).
    pub(crate) file_names: &'a [String],
    /// The tip of each marker (index into `tip_names`); a marker past the end is on the last.
    pub(crate) marker_tips: &'a [usize],
    /// The tip links given (`--tip`, then `--tips`).
    pub(crate) tip_names: &'a [String],
    /// For each tip, a link of the description fixed to the same moving link and not given
    /// as a tip ([`fixed_twin`]): a second marker on the tip is given on it. `None` without a
    /// description that has one.
    pub(crate) twins: &'a [Option<String>],
    /// Whether the data already look wrong (`Tier::Suspicious`, or per-row residuals that jump,
    /// [`residuals_jump`]): then every file is scanned; otherwise only a file whose later
    /// samples a shift fits to [`PROBE_SHARE`] of the residual or more ([`probe`]).
    pub(crate) suspicious: bool,
    /// The fit to every row of every file (the tips of `marker_tips`), when it is at hand: the
    /// probe scans its residuals (fitted here when it is not).
    pub(crate) whole: Option<&'a PartFit>,
}

/// Share of the squared position residual of every sample (the fit to every row) that the
/// best shift of a file's later samples must take for the scan (`probe`). The shifts are
/// those a change leaves with the frames of the whole file held: each marker's error in its
/// tip's frame moved by a constant (a marker mounted again), or every error moved by a small
/// turn and translation of the instrument. Frames of their own for each part (the scan) take
/// at least as much, and a change the scan names takes most of the residual (0.88 to 0.97 of
/// it for the 18 mm re-mounts of `tests/change_point.rs`). On right data the best shift takes
/// the noise's share of a few coordinates out of hundreds, and a part of the robot's own
/// deviations where the rows sweep the joints in order: 0.01 to 0.10 on the bundled UR10,
/// TIAGo and simulated humanoid recordings, 0.20 on the positioner (3.8 mm of real kinematic
/// error, its rows ordered by axis).
pub const PROBE_SHARE: f64 = 0.4;

/// The change-point hypotheses of `input` (see the module docs): for each file with
/// 2 × [`MIN_PART_ROWS`] rows or more whose best split is a step, the instrument moved and a
/// marker re-mounted from that row on. `fit` fits frames to a part, `make` builds the data of
/// a hypothesis from its tables and the tip of each of its markers.
pub(crate) fn change_hypotheses<D>(
    input: &ChangeInput<'_>,
    fit: PartFitFn<'_>,
    make: &dyn Fn(Vec<MeasurementTable>, Vec<usize>) -> D,
) -> Vec<Corrected<D>> {
    let mut out = Vec::new();
    // The fit to every row, which the probe scans, once for every file.
    let fitted = (!input.suspicious && input.whole.is_none())
        .then(|| fit(input.tables, input.marker_tips))
        .flatten();
    let whole = input.whole.or(fitted.as_ref());
    for f in 0..input.tables.len() {
        if !input.suspicious && !whole.is_some_and(|w| probe(input.tables, f, w)) {
            continue;
        }
        let Some(split) = find_step(input.tables, f, input.marker_tips, fit) else {
            continue;
        };
        out.extend(instrument_moved(input, f, &split, make));
        out.extend(marker_remounted(input, f, &split, fit, make));
    }
    out
}

/// A step found in file `f`: the first row of the second part (index into the file's rows)
/// and the two parts' own fits.
struct Split {
    at: usize,
    before: PartFit,
    after: PartFit,
}

/// The tables split before row `at` of file `f`: every row but file `f`'s from `at` on, and
/// those rows alone.
fn parts(
    tables: &[MeasurementTable],
    f: usize,
    at: usize,
) -> (Vec<MeasurementTable>, Vec<MeasurementTable>) {
    let mut before = tables.to_vec();
    let after = before.get_mut(f).map(|t| MeasurementTable {
        rows: t.rows.split_off(at.min(t.rows.len())),
        ..t.clone()
    });
    (before, after.into_iter().collect())
}

/// Whether a shift of file `f`'s samples from one of them on takes [`PROBE_SHARE`] or more
/// of the squared position residual of `whole`, the fit to every row of every file: a scan of
/// its residuals (sums over the samples before each split), against the few dozen fits of
/// the change-point scan.
fn probe(tables: &[MeasurementTable], f: usize, whole: &PartFit) -> bool {
    let n = tables.get(f).map_or(0, |t| t.rows.len());
    if n < 2 * MIN_PART_ROWS {
        return false;
    }
    let total: f64 = whole.samples.iter().map(|s| s.error_m.norm_squared()).sum();
    let file: Vec<SampleResidual> = (whole.samples.iter())
        .filter(|s| s.file == f)
        .copied()
        .collect();
    total > 0.0 && best_shift_m2(&file) >= PROBE_SHARE * total
}

/// The most of the squared position error of `samples` (one file's, in the rows' order) that a
/// shift of the samples after a split takes, each side [`MIN_PART_ROWS`] samples or more: for
/// each split the larger of
///
/// - the sum over markers of `n₁n₂/n·|ē₁ − ē₂|²`, the means `ē` of the errors in the tip's
///   frame before and after the split (each marker's offset of its own on either side), and
/// - `gᵀN⁻¹g` of the side that moves, for a small turn `ω` and translation `δ` of the
///   instrument (the error's derivative `[p − p̄]ₓ·ω − δ`, `N` and `g` its normal equations
///   and gradient over that side's samples).
///
/// m²; 0 with too few samples.
fn best_shift_m2(samples: &[SampleResidual]) -> f64 {
    use nalgebra::{Matrix3x6, Matrix6, Vector6};
    let n = samples.len();
    if n < 2 * MIN_PART_ROWS {
        return 0.0;
    }
    let n_markers = samples.iter().map(|s| s.marker + 1).max().unwrap_or(0);
    let centre = samples.iter().map(|s| s.measured_m).sum::<Vector3<f64>>() / n as f64;
    let jacobian = |s: &SampleResidual| {
        let mut j = Matrix3x6::zeros();
        j.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(s.measured_m - centre).cross_matrix());
        j.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-Matrix3::identity()));
        j
    };
    let mut normal_total = Matrix6::zeros();
    let mut gradient_total = Vector6::zeros();
    let mut tip_total = vec![(Vector3::zeros(), 0usize); n_markers];
    for s in samples {
        let j = jacobian(s);
        normal_total += j.tr_mul(&j);
        gradient_total += j.tr_mul(&s.error_m);
        tip_total[s.marker].0 += s.in_tip_m;
        tip_total[s.marker].1 += 1;
    }
    let taken = |normal: &Matrix6<f64>, gradient: &Vector6<f64>| {
        normal
            .cholesky()
            .map_or(0.0, |c| gradient.dot(&c.solve(gradient)))
    };
    let mut normal = Matrix6::zeros();
    let mut gradient = Vector6::zeros();
    let mut tip = vec![(Vector3::zeros(), 0usize); n_markers];
    let mut best = 0.0f64;
    for (i, s) in samples.iter().enumerate().take(n - MIN_PART_ROWS) {
        let j = jacobian(s);
        normal += j.tr_mul(&j);
        gradient += j.tr_mul(&s.error_m);
        tip[s.marker].0 += s.in_tip_m;
        tip[s.marker].1 += 1;
        if i + 1 < MIN_PART_ROWS {
            continue;
        }
        let remounted: f64 = (tip.iter().zip(&tip_total))
            .filter(|((_, n1), (_, n))| *n1 > 0 && n1 < n)
            .map(|((s1, n1), (s, n))| {
                let n2 = n - n1;
                let gap = s1 / *n1 as f64 - (s - s1) / n2 as f64;
                (*n1 * n2) as f64 / *n as f64 * gap.norm_squared()
            })
            .sum();
        let moved = taken(&normal, &gradient).max(taken(
            &(normal_total - normal),
            &(gradient_total - gradient),
        ));
        best = best.max(remounted).max(moved);
    }
    best
}

/// The split of file `f` that leaves the least residual with frames of its own on each side,
/// when it is a step (module docs); `None` otherwise.
fn find_step(
    tables: &[MeasurementTable],
    f: usize,
    tips: &[usize],
    fit: PartFitFn<'_>,
) -> Option<Split> {
    let n = tables.get(f)?.rows.len();
    let cost = |at: usize| -> Option<f64> {
        let (a, b) = parts(tables, f, at);
        Some(fit(&a, tips)?.cost_m2 + fit(&b, tips)?.cost_m2)
    };
    let whole = fit(tables, tips)?.cost_m2;
    let at = step_at(n, whole, &cost)?;
    let (a, b) = parts(tables, f, at);
    Some(Split {
        at,
        before: fit(&a, tips)?,
        after: fit(&b, tips)?,
    })
}

/// The first row of the second part of the split of `n` rows that leaves the least residual
/// `cost(at)` (a sum of squares over both parts), each part [`MIN_PART_ROWS`] or more, when it
/// is a step: it divides the residual `whole` of the rows in one part by
/// [`SUGGESTIVE_FACTOR`]² or more, and the splits an eighth of the rows to either side leave
/// [`STEP_FACTOR`] times more. Coarse to fine: the best of [`SCAN_SPLITS`] splits spread over
/// the rows, then as many over the steps about it, down to one row.
pub(crate) fn step_at(
    n: usize,
    whole: f64,
    cost: &(dyn Fn(usize) -> Option<f64> + Sync),
) -> Option<usize> {
    if n < 2 * MIN_PART_ROWS {
        return None;
    }
    let (mut lo, mut hi) = (MIN_PART_ROWS, n - MIN_PART_ROWS);
    let mut best: Option<(usize, f64)> = None;
    loop {
        let step = ((hi - lo) / SCAN_SPLITS).max(1);
        let splits: Vec<usize> = (lo..=hi).step_by(step).collect();
        let scored: Vec<(usize, f64)> = (splits.par_iter())
            .filter_map(|&at| Some((at, cost(at)?)))
            .collect();
        for s in scored {
            if best.is_none_or(|b| s.1 < b.1 || (s.1 == b.1 && s.0 < b.0)) {
                best = Some(s);
            }
        }
        let (at, _) = best?;
        if step == 1 {
            break;
        }
        lo = at.saturating_sub(step).max(MIN_PART_ROWS);
        hi = (at + step).min(n - MIN_PART_ROWS);
    }
    let (at, least) = best?;
    // Most of the residual: at least the factor of a warning, in RMS.
    if least * SUGGESTIVE_FACTOR.powi(2) > whole {
        return None;
    }
    // A step, not a drift: the split moved by an eighth of the rows leaves far more.
    let w = (n / 8).max(2);
    let neighbours: Vec<usize> = [at.checked_sub(w), Some(at + w)]
        .into_iter()
        .flatten()
        .filter(|&k| k >= MIN_NEIGHBOUR_ROWS && k + MIN_NEIGHBOUR_ROWS <= n)
        .collect();
    let step = !neighbours.is_empty()
        && (neighbours.iter()).all(|&k| cost(k).is_some_and(|c| c >= STEP_FACTOR * least));
    step.then_some(at)
}

/// The file name and the lines of the last row before the split and the first after it.
fn place(input: &ChangeInput<'_>, f: usize, at: usize) -> Option<(String, u64, u64)> {
    let rows = &input.tables.get(f)?.rows;
    let file = input
        .file_names
        .get(f)
        .map_or("?", String::as_str)
        .to_owned();
    Some((file, rows.get(at.checked_sub(1)?)?.line, rows.get(at)?.line))
}

/// The hypothesis that the instrument moved before row `split.at` of file `f`: the
/// measurements from it on carried into the first part's instrument frame.
fn instrument_moved<D>(
    input: &ChangeInput<'_>,
    f: usize,
    split: &Split,
    make: &dyn Fn(Vec<MeasurementTable>, Vec<usize>) -> D,
) -> Option<Corrected<D>> {
    let (file, last, line) = place(input, f, split.at)?;
    let pose = |(r, t): (Matrix3<f64>, Vector3<f64>)| {
        Isometry3::from_parts(
            Translation3::from(t),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
        )
    };
    let (a, b) = (pose(split.before.instrument), pose(split.after.instrument));
    // A point seen at p after the move was seen at a·b⁻¹·p before it.
    let map = a * b.inverse();
    // The instrument's origin in the base frame, before and after.
    let moved_m = (a.inverse().translation.vector - b.inverse().translation.vector).norm();
    let turned_deg = map.rotation.angle().to_degrees();
    let mut tables = input.tables.to_vec();
    if let Some(t) = tables.get_mut(f) {
        for row in t.rows.iter_mut().skip(split.at) {
            for m in &mut row.markers {
                m.position_m = (map * nalgebra::Point3::from(m.position_m)).coords.into();
                if let Some([w, x, y, z]) = m.rotation {
                    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
                    let r = map.rotation * q;
                    m.rotation = Some([r.w, r.i, r.j, r.k]);
                }
            }
        }
    }
    let n_markers = input.tables.iter().map(|t| t.n_markers).max().unwrap_or(1);
    let tips = (0..n_markers).map(|k| tip_of(input, k)).collect();
    Some(Corrected::new(
        MistakeClass::ChangePoint,
        format!(
            "the instrument moved between {file}:{last} and {file}:{line}, by {turned_deg:.1}° \
             and {} mm (its origin relative to the robot's base): the rows from {file}:{line} \
             on fit the nominal robot with an instrument frame of their own",
            mm(moved_m)
        ),
        format!(
            "a calibration fits one instrument frame: split {file} at line {line} (the rows \
             before it in one file, the rows from it on in another) and calibrate each part on \
             its own, or record again with the instrument held still"
        ),
        make(tables, tips),
    ))
}

/// The hypothesis that the markers were re-mounted before row `split.at` of file `f`: the
/// samples from it on as those of new markers on the same tips.
fn marker_remounted<D>(
    input: &ChangeInput<'_>,
    f: usize,
    split: &Split,
    fit: PartFitFn<'_>,
    make: &dyn Fn(Vec<MeasurementTable>, Vec<usize>) -> D,
) -> Option<Corrected<D>> {
    let (file, last, line) = place(input, f, split.at)?;
    let n_markers = input.tables.iter().map(|t| t.n_markers).max()?.max(1);
    let mut tables = input.tables.to_vec();
    let t = tables.get_mut(f)?;
    for row in t.rows.iter_mut().skip(split.at) {
        for m in &mut row.markers {
            m.marker += n_markers;
        }
    }
    t.n_markers = 2 * n_markers;
    let tips: Vec<usize> = (0..2 * n_markers)
        .map(|k| tip_of(input, k % n_markers))
        .collect();
    // How far each marker moved on its tip, with one instrument frame for both parts: the
    // marker that moved most is named.
    let both = fit(&tables, &tips)?;
    let (k, moved_m) = (0..n_markers)
        .filter_map(|k| {
            let (a, b) = (
                both.marker_offsets_m.get(k)?,
                both.marker_offsets_m.get(k + n_markers)?,
            );
            Some((k, (b - a).norm()))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let tip = (input.tip_names.get(tips.get(k).copied().unwrap_or(0)))
        .map_or("?", String::as_str)
        .to_owned();
    let new = n_markers + k + 1;
    let renamed = if n_markers == 1 {
        " (the first marker's columns named x1, y1, z1)"
    } else {
        ""
    };
    let fix = match input.twins.get(tips.get(k).copied().unwrap_or(0)) {
        Some(Some(twin)) => format!(
            "from {file}:{line} on, move marker {}'s columns to new columns x{new}, y{new}, \
             z{new}{renamed} (orientation columns likewise) and add a tip on the same link for \
             them (--tips {twin}: {twin} is fixed to the link of {tip}): the calibration then \
             fits the two mountings as two markers",
            k + 1
        ),
        _ => format!(
            "a calibration fits one frame per marker: split {file} at line {line} (the rows \
             before it in one file, the rows from it on in another) and calibrate each part on \
             its own"
        ),
    };
    Some(Corrected::new(
        MistakeClass::ChangePoint,
        format!(
            "marker {} was mounted again between {file}:{last} and {file}:{line}: its offset on \
             {tip} moved by {} mm, and the rows from {file}:{line} on fit the nominal robot \
             with a marker frame of their own",
            k + 1,
            mm(moved_m)
        ),
        fix,
        make(tables, tips),
    ))
}

/// The tip of marker `k` (index into the tip names): its own, else the last given.
fn tip_of(input: &ChangeInput<'_>, k: usize) -> usize {
    (input.marker_tips.get(k))
        .or(input.marker_tips.last())
        .copied()
        .unwrap_or(0)
}

/// Factor by which the mean per-row residual of one part of a file must exceed the other's
/// for `residuals_jump`: the per-row residuals of right data stay within about 4 medians of
/// one another row by row, and a mean over [`MIN_PART_ROWS`] rows or more within far less.
pub const JUMP_FACTOR: f64 = 4.0;

/// Whether the per-row residuals `per_row` (file index, line, residual in m) of a fit to every
/// row jump from a row of a file on: the mean residual of the rows on one side of a split,
/// [`MIN_PART_ROWS`] or more on each, [`JUMP_FACTOR`] times the other side's. A move that the
/// frames of the whole file absorb to a residual right data can leave (an 18 mm re-mount of
/// a marker leaves 9 mm) shows this way: the frames follow the larger part, and the other
/// part's rows stand out.
pub(crate) fn residuals_jump(per_row: &[(usize, u64, f64)]) -> bool {
    let n_files = per_row.iter().map(|r| r.0 + 1).max().unwrap_or(0);
    (0..n_files).any(|f| {
        let e: Vec<f64> = per_row.iter().filter(|r| r.0 == f).map(|r| r.2).collect();
        if e.len() < 2 * MIN_PART_ROWS {
            return false;
        }
        splits(&e, MIN_PART_ROWS, MIN_PART_ROWS).any(|(_, before, after)| {
            before.max(after) >= JUMP_FACTOR * before.min(after).max(f64::MIN_POSITIVE)
        })
    })
}

/// The links of `urdf` joined to `link` by one fixed joint (its parent or its child), in the
/// file's order of the joints.
pub(crate) fn fixed_neighbours<'a>(
    urdf: &'a urdf_rs::Robot,
    link: &'a str,
) -> impl Iterator<Item = &'a String> + 'a {
    (urdf.joints.iter())
        .filter(|j| matches!(j.joint_type, urdf_rs::JointType::Fixed))
        .filter_map(move |j| {
            if j.child.link == link {
                Some(&j.parent.link)
            } else if j.parent.link == link {
                Some(&j.child.link)
            } else {
                None
            }
        })
}

/// A link of `urdf` joined to `tip` by fixed joints only (the same rigid body: the tool
/// flange above a ball, a frame below it), the nearest first, that is not in `taken`; `None`
/// when the tip's moving link has no other.
pub(crate) fn fixed_twin(urdf: &urdf_rs::Robot, tip: &str, taken: &[String]) -> Option<String> {
    let mut seen = vec![tip.to_owned()];
    let mut frontier = std::collections::VecDeque::from([tip.to_owned()]);
    while let Some(link) = frontier.pop_front() {
        for other in fixed_neighbours(urdf, &link) {
            if seen.contains(other) {
                continue;
            }
            if !taken.contains(other) {
                return Some(other.clone());
            }
            seen.push(other.clone());
            frontier.push_back(other.clone());
        }
    }
    None
}
