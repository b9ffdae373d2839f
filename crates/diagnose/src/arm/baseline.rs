//! The first stage: the geometric baseline as the diagnosis sees it (its rows, residuals and
//! derivatives at the estimate, the cross-validation folds and its held-out error), the floor
//! and the gap above it.

use hapcal_calibrate::baseline::{DataKind, GeometricBaseline};
use hapcal_problems::GravityCompliance;
use nalgebra::{DMatrix, DVector, Vector3};

use super::columns::library_transversal;
use super::cv::{HeldOut, cross_validate, folds_of};
use super::problem::{
    Context, Derivatives, Rows, jacobian_sets, median_step, reading_derivatives, residuals,
    rotation_params,
};
use super::{ArmConfig, FloorSource, REPEAT_TOLERANCE};
use crate::Error;
use crate::stats::chi2_sf;
use crate::stats::mean;

/// The floor: per-axis position variance, and where it came from.
pub(super) struct Floor {
    /// Per-axis position variance (per distance on a distance log), m² (`None`: no floor).
    pub(super) var: Option<f64>,
    pub(super) source: FloorSource,
    /// How it was found, in words.
    pub(super) method: String,
}

/// The baseline stage's output: everything the later stages start from.
pub(super) struct Baseline<'a> {
    pub(super) ctx: Context<'a>,
    pub(super) rows: Rows,
    /// Weighted residuals of the training rows at the estimate, measured − model.
    pub(super) r: DVector<f64>,
    /// The baseline's Jacobian columns (its kept parameters), weighted.
    pub(super) jb: DMatrix<f64>,
    pub(super) d: Derivatives,
    pub(super) floor: Floor,
    /// Each configuration's fold in each cross-validation repeat, and its block.
    pub(super) folds: Vec<Vec<usize>>,
    pub(super) block: Vec<usize>,
    /// The baseline's cross-validated errors.
    pub(super) held: HeldOut,
    /// Its cross-validated mean squared 3-D error, m².
    pub(super) mse0: f64,
    /// The floor of that, m² (`None` without a floor).
    pub(super) floor0: Option<f64>,
    /// `P(χ² > Σe²/var)` of the held-out residuals under the floor, and whether it is known
    /// (a floor exists).
    pub(super) gap_p: f64,
    pub(super) chi_known: bool,
    /// Floor units per weighted squared residual (1 without a floor).
    pub(super) floor_units: f64,
    /// Notes about the data.
    pub(super) notes: Vec<String>,
}

impl<'a> Baseline<'a> {
    /// The stage on `baseline` with the folds of `cfg`.
    ///
    /// # Errors
    /// [`Error::Data`] for fewer than 2 folds' worth of configurations; [`Error::Baseline`] if
    /// the problem cannot be evaluated.
    pub(super) fn new(baseline: &'a GeometricBaseline, cfg: &ArmConfig) -> Result<Self, Error> {
        let problem = &baseline.train;
        let n_c = baseline.q.len();
        if n_c < 2 * cfg.folds {
            return Err(Error::Data {
                message: format!(
                    "{n_c} training configurations; the diagnosis needs at least {} for {} folds",
                    2 * cfg.folds,
                    cfg.folds
                ),
            });
        }
        let n_joints = baseline.robot.joint_names.len();
        let rows = Rows::new(
            problem,
            &baseline.configuration,
            baseline.q.clone(),
            baseline.group.clone(),
            baseline.time.clone(),
        );
        let r = -residuals(problem, &baseline.x)?;
        let kept: Vec<Option<usize>> = baseline.kept.iter().copied().map(Some).collect();
        let rotation = rotation_params(problem, &baseline.robot.joint_names);
        let [jb, rotation] = jacobian_sets(problem, &baseline.x, [&kept, &rotation])?;
        let d = Derivatives {
            dq: reading_derivatives(problem, &baseline.x, n_joints)?,
            rotation,
        };
        let ctx = context(baseline);
        let (var, source, method) = floor(baseline, &rows, &r);
        let (folds, block) = folds_of(&rows.group, cfg.folds);
        let mut notes = Vec::new();
        if !baseline.time_from_data {
            notes.push(
                "no time column: time is the row order (thermal drift and backlash assume the \
                 rows were recorded in file order)"
                    .to_owned(),
            );
        }
        // Round 0: the geometric baseline.
        let held = cross_validate(&jb, &r, &rows, &folds, cfg.folds, var);
        let mse0 = held.mse();
        let floor0 = var.map(|_| mean(&held.floor_m2));
        let (gap_p, chi_known) = match var {
            Some(_) => (gap_p_value(&rows, &held), true),
            None => (1.0, false),
        };
        let floor_units = match (
            var,
            rows.res.iter().find_map(|(kind, _)| kind.length_sigma()),
        ) {
            (Some(v), Some(s)) if v > 0.0 => s * s / v,
            _ => 1.0,
        };
        Ok(Baseline {
            ctx,
            rows,
            r,
            jb,
            d,
            floor: Floor {
                var,
                source,
                method,
            },
            folds,
            block,
            held,
            mse0,
            floor0,
            gap_p,
            chi_known,
            floor_units,
            notes,
        })
    }
}

/// What the effects need to know about the robot of `baseline`.
fn context(baseline: &GeometricBaseline) -> Context<'_> {
    let masses = if baseline.robot.masses.is_empty() {
        GravityCompliance::published(&baseline.robot.joint_names)
    } else {
        Some(GravityCompliance::from_link_masses(
            baseline.robot.masses.clone(),
            -Vector3::z(),
        ))
    };
    let t_min = baseline.time.iter().copied().fold(f64::INFINITY, f64::min);
    let t_max = (baseline.time.iter().copied()).fold(f64::NEG_INFINITY, f64::max);
    let mut ctx = Context {
        baseline,
        masses,
        gravity: baseline.base_to_measurement * -Vector3::z(),
        reach_max: 1.0,
        time_origin: if t_min.is_finite() { t_min } else { 0.0 },
        time_span: (t_max - t_min).max(0.0),
        time_step: median_step(&baseline.time),
        transversal: library_transversal(&baseline.robot.tree),
    };
    ctx.reach_max = (baseline.q.iter())
        .map(|q| ctx.reach(q))
        .fold(0.0, f64::max)
        .max(1e-3);
    ctx
}

/// The floor: per-axis position variance (m²) and its source.
fn floor(
    baseline: &GeometricBaseline,
    rows: &Rows,
    r: &DVector<f64>,
) -> (Option<f64>, FloorSource, String) {
    if let Some(s) = baseline.stated_sigma_m {
        let per = if baseline.kind == DataKind::Distances {
            "per distance"
        } else {
            "per axis"
        };
        return (
            Some(s * s),
            FloorSource::Stated,
            format!("stated instrument σ = {:.4} mm {per}", s * 1e3),
        );
    }
    // Residuals (m) of the position residuals per configuration, axis order.
    let n_c = rows.n_configurations();
    let mut pos: Vec<Vec<f64>> = vec![Vec::new(); n_c];
    for (i, (kind, c)) in rows.res.iter().enumerate() {
        if let Some(sigma) = kind.length_sigma() {
            pos[*c].push(r[i] * sigma);
        }
    }
    // Repeated poses.
    let q = &rows.q;
    let same = |a: usize, b: usize| {
        q[a].iter()
            .zip(&q[b])
            .all(|(x, y)| (x - y).abs() < REPEAT_TOLERANCE)
    };
    let mut label = vec![usize::MAX; n_c];
    let mut n_labels = 0;
    for a in 0..n_c {
        if label[a] != usize::MAX {
            continue;
        }
        label[a] = n_labels;
        for b in a + 1..n_c {
            if label[b] == usize::MAX && same(a, b) && pos[a].len() == pos[b].len() {
                label[b] = n_labels;
            }
        }
        n_labels += 1;
    }
    let mut ss = 0.0;
    let mut dof = 0usize;
    for l in 0..n_labels {
        let members: Vec<usize> = (0..n_c).filter(|&c| label[c] == l).collect();
        if members.len() < 2 || pos[members[0]].is_empty() {
            continue;
        }
        #[allow(clippy::needless_range_loop)] // k indexes the residual of every member
        for k in 0..pos[members[0]].len() {
            let m = members.iter().map(|&c| pos[c][k]).sum::<f64>() / members.len() as f64;
            ss += members
                .iter()
                .map(|&c| (pos[c][k] - m).powi(2))
                .sum::<f64>();
            dof += members.len() - 1;
        }
    }
    if dof >= 10 {
        return (
            Some(ss / dof as f64),
            FloorSource::RepeatedPoses { dof },
            format!(
                "repeatability: pooled scatter of the residuals of repeated poses (readings within \
                 {REPEAT_TOLERANCE} of each other), {dof} degrees of freedom"
            ),
        );
    }
    if baseline.kind == DataKind::Sockets {
        let mut ss = 0.0;
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        for a in 0..n_c {
            let nearest = (0..n_c)
                .filter(|&b| b != a && rows.group[b] == rows.group[a])
                .min_by(|&b, &c| {
                    let d = |x: usize| -> f64 {
                        q[a].iter().zip(&q[x]).map(|(u, v)| (u - v).powi(2)).sum()
                    };
                    d(b).total_cmp(&d(c))
                });
            if let Some(b) = nearest {
                let pair = (a.min(b), a.max(b));
                if !pairs.contains(&pair) {
                    pairs.push(pair);
                    ss += (pos[a].iter().zip(&pos[b]))
                        .map(|(x, y)| (x - y).powi(2))
                        .sum::<f64>();
                }
            }
        }
        if pairs.len() >= 5 {
            let var = ss / (2.0 * 3.0 * pairs.len() as f64);
            return (
                Some(var),
                FloorSource::SocketReplicates { pairs: pairs.len() },
                format!(
                    "socket replicates: half the mean squared residual difference of each \
                     configuration and its nearest configuration at the same socket ({} pairs); \
                     an upper bound of the seating noise (model error that changes between \
                     neighbours adds to it), so the gap is a lower bound",
                    pairs.len()
                ),
            );
        }
    }
    (
        None,
        FloorSource::None,
        "no floor: no stated σ, no repeated pose, no socket replicates; gaps are relative to the \
         best model found"
            .to_owned(),
    )
}

/// `P(χ²_k > Σ e²/var)` of the held-out position residuals under the floor (pooled variance
/// `Σ floor / k`, k position residuals).
pub(super) fn gap_p_value(rows: &Rows, held: &HeldOut) -> f64 {
    let k = (rows.res.iter())
        .filter(|(kind, c)| kind.length_sigma().is_some() && *c != usize::MAX)
        .count() as f64;
    let floor: f64 = held.floor_m2.iter().sum();
    let ss: f64 = held.position_m2.iter().sum();
    if floor > 0.0 && k > 0.0 {
        chi2_sf(ss / (floor / k), k)
    } else {
        1.0
    }
}
