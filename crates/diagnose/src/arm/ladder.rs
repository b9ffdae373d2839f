//! The ladder: the baseline's kinematic rungs, then each named effect, cross-validated on the
//! training rows and carried to every held-out set.

use hapcal_calibrate::baseline::{GeometricBaseline, HeldOutSet};
use hapcal_contract::Effect;
use hapcal_identify::Problem;
use nalgebra::{DMatrix, DVector};

use super::baseline::Baseline;
use super::columns::effect_columns;
use super::cv::{beside, cross_validate};
use super::problem::{
    Context, Derivatives, Rows, jacobian_sets, reading_derivatives, residuals, rotation_params,
};
use super::revise::Named;
use super::{ArmConfig, ArmLadderRung, ArmRung};
use crate::Error;
use crate::solve::lstsq;
use crate::stats::mean;

/// The ladder stage's output.
pub(super) struct Ladder {
    /// The rungs: kinematic, then each named effect.
    pub(super) rungs: Vec<ArmRung>,
    /// The geometric estimate's 3-D RMS on every held-out set, m.
    pub(super) geometric_test_rms: Vec<f64>,
}

/// The ladder: the baseline's kinematic rungs, then each accepted effect with its
/// cross-validated error on the training rows and its error on every held-out set; and the
/// geometric estimate's error on every held-out set (at the linearisation point, as the
/// effects' rungs).
pub(super) fn ladder(
    b: &Baseline<'_>,
    effects: &[Named],
    cfg: &ArmConfig,
) -> Result<Ladder, Error> {
    let (baseline, ctx, rows, r, jb, folds) =
        (b.ctx.baseline, &b.ctx, &b.rows, &b.r, &b.jb, &b.folds);
    let mut out: Vec<ArmRung> = (baseline.ladder.iter())
        .map(|k| ArmRung {
            rung: ArmLadderRung::Kinematic(k.rung),
            cv_rms_m: k.cv_rms_m,
            test_rms_m: k.test_rms_m.clone(),
        })
        .collect();
    // Held-out sets: their residuals, shared-parameter columns, own nuisance columns and
    // derivatives at the training estimate.
    struct Test {
        rows: Rows,
        r: DVector<f64>,
        shared: DMatrix<f64>,
        own: DMatrix<f64>,
        d: Derivatives,
    }
    let n_joints = ctx.n_joints();
    let shared_kept: Vec<usize> = (baseline.kept.iter().enumerate())
        .filter(|(_, i)| **i < baseline.n_shared)
        .map(|(k, _)| k)
        .collect();
    let mut tests = Vec::new();
    for t in &baseline.tests {
        tests.push(test_of(t, baseline, ctx, n_joints)?);
    }
    fn test_of(
        t: &HeldOutSet,
        b: &GeometricBaseline,
        ctx: &Context<'_>,
        n_joints: usize,
    ) -> Result<Test, Error> {
        let n_c = t.configuration.iter().max().map_or(0, |m| m + 1);
        let q: Vec<Vec<f64>> = {
            let mut q = vec![Vec::new(); n_c];
            for (row, &c) in t.problem.observations().rows.iter().zip(&t.configuration) {
                q[c] = row.q.to_vec();
            }
            q
        };
        // The set's own times where they continue the training's clock, else the training's
        // clock continued at its median step.
        let time = (t.time.clone())
            .filter(|time| time.len() == n_c)
            .unwrap_or_else(|| ctx.held_out_times(n_c));
        let rows = Rows::new(&t.problem, &t.configuration, q, vec![0; n_c], time);
        let r = -residuals(&t.problem, &t.x)?;
        let shared_idx: Vec<Option<usize>> = (b.kept.iter().copied())
            .filter(|&i| i < b.n_shared)
            .map(Some)
            .collect();
        let own_idx: Vec<Option<usize>> =
            (b.n_shared..t.problem.layout().len()).map(Some).collect();
        let rotation_idx = rotation_params(&t.problem, &b.robot.joint_names);
        let [shared, own, rotation] =
            jacobian_sets(&t.problem, &t.x, [&shared_idx, &own_idx, &rotation_idx])?;
        let d = Derivatives {
            dq: reading_derivatives(&t.problem, &t.x, n_joints)?,
            rotation,
        };
        Ok(Test {
            rows,
            r,
            shared,
            own,
            d,
        })
    }
    // The training coefficients of the shared columns (and the effects' after them) carried
    // to a held-out set, then the set's own nuisance parameters (socket points) re-fitted.
    let test_rms = |t: &Test, cols: &DMatrix<f64>, coef: Vec<f64>| {
        let mut e = &t.r - cols * DVector::from_vec(coef);
        if t.own.ncols() > 0 {
            let (y, _) = lstsq(&t.own, &e);
            e -= &t.own * y;
        }
        position_rms(&t.rows, &e)
    };
    let (x0, _) = lstsq(jb, r);
    let geometric: Vec<f64> = (tests.iter())
        .map(|t| test_rms(t, &t.shared, shared_kept.iter().map(|&k| x0[k]).collect()))
        .collect();
    let mut a = jb.clone();
    let mut test_cols: Vec<DMatrix<f64>> = tests.iter().map(|t| t.shared.clone()).collect();
    let mut named_so_far: Vec<Effect> = Vec::new();
    for (effect, cols, visible) in effects {
        a = beside(&a, &[cols]);
        let held = cross_validate(&a, r, rows, folds, cfg.folds, None);
        let (x, _) = lstsq(&a, r);
        let mut rms = Vec::new();
        for (t, tc) in tests.iter().zip(&mut test_cols) {
            let (c, _) = effect_columns(*effect, ctx, &t.rows, &t.d, &named_so_far)
                .unwrap_or_else(|_| (DMatrix::zeros(t.r.len(), visible.len().max(1)), Vec::new()));
            let c_vis = if c.ncols() >= visible.iter().max().map_or(0, |m| m + 1) {
                c.select_columns(visible)
            } else {
                DMatrix::zeros(t.r.len(), visible.len())
            };
            *tc = beside(tc, &[&c_vis]);
            let coef: Vec<f64> = (shared_kept.iter().copied())
                .chain(jb.ncols()..a.ncols())
                .map(|k| x[k])
                .collect();
            rms.push(test_rms(t, tc, coef));
        }
        named_so_far.push(*effect);
        out.push(ArmRung {
            rung: ArmLadderRung::Effects(named_so_far.clone()),
            cv_rms_m: held.mse().sqrt(),
            test_rms_m: rms,
        });
    }
    Ok(Ladder {
        rungs: out,
        geometric_test_rms: geometric,
    })
}

/// RMS of the 3-D position error per configuration, m, of weighted residuals `e`.
fn position_rms(rows: &Rows, e: &DVector<f64>) -> f64 {
    let mut per = vec![0.0; rows.n_configurations()];
    for (i, (kind, c)) in rows.res.iter().enumerate() {
        if let Some(sigma) = kind.length_sigma()
            && *c != usize::MAX
        {
            per[*c] += (e[i] * sigma).powi(2);
        }
    }
    mean(&per).sqrt()
}
