//! Where: the residual map of the baseline's held-out residuals, binned by signal.

use nalgebra::Vector3;

use super::cv::HeldOut;
use super::problem::{Context, Rows};
use super::{ArmConfig, WORKSPACE_SPREAD_M};
use crate::Bin;
use crate::stats::{chi2_sf, holm};

/// The residual map: held-out position RMS in quantile bins of each signal (joint readings,
/// time, gravity torques, reach, height, azimuth), against the floor (or the overall RMS
/// without one), Holm over every bin.
pub(super) fn residual_map(
    ctx: &Context<'_>,
    rows: &Rows,
    held: &HeldOut,
    floor_var: Option<f64>,
    cfg: &ArmConfig,
) -> Vec<Bin> {
    let n_c = rows.n_configurations();
    let names = &ctx.baseline.robot.joint_names;
    let mut signals: Vec<(String, Vec<f64>)> = Vec::new();
    for (j, _) in names.iter().enumerate() {
        signals.push((format!("q{}", j + 1), rows.q.iter().map(|q| q[j]).collect()));
    }
    signals.push(("time".into(), rows.time.clone()));
    if let Some(m) = &ctx.masses {
        let t: Vec<Vec<f64>> = (rows.q.iter())
            .map(|q| {
                (m.joint_loads(&ctx.baseline.torque_tips, q).iter())
                    .map(|l| l.torque)
                    .collect::<Vec<f64>>()
            })
            .collect();
        for j in 0..names.len() {
            let v: Vec<f64> = t.iter().map(|t| t[j]).collect();
            if v.iter().any(|x| x.abs() > 1e-9) {
                signals.push((format!("torque{}", j + 1), v));
            }
        }
    }
    // The workspace, when the tip moves through it (not at sockets).
    let tips: Vec<Vector3<f64>> = rows.q.iter().map(|q| ctx.tip(q)).collect();
    let spread = |f: &dyn Fn(&Vector3<f64>) -> f64| {
        let v: Vec<f64> = tips.iter().map(f).collect();
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
                (l.min(*x), h.max(*x))
            });
        (v, hi - lo)
    };
    let (reach, reach_spread) = spread(&|p| (p.x * p.x + p.y * p.y).sqrt());
    let (height, height_spread) = spread(&|p| p.z);
    if reach_spread.max(height_spread) > WORKSPACE_SPREAD_M {
        signals.push(("reach".into(), reach));
        signals.push(("height".into(), height));
        signals.push((
            "azimuth".into(),
            tips.iter().map(|p| p.y.atan2(p.x)).collect(),
        ));
    }
    // Per configuration: number of position residuals.
    let mut n_pos = vec![0usize; n_c];
    for (kind, c) in &rows.res {
        if kind.length_sigma().is_some() && *c != usize::MAX {
            n_pos[*c] += 1;
        }
    }
    let overall = held.mse();
    let mut bins = Vec::new();
    let mut p_raw = Vec::new();
    for (name, v) in &signals {
        let mut order: Vec<usize> = (0..n_c).collect();
        order.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
        let lo_all = v[order[0]];
        let hi_all = v[order[n_c - 1]];
        if hi_all <= lo_all || hi_all.is_nan() || lo_all.is_nan() {
            continue;
        }
        let k = cfg.bins.min(n_c).max(1);
        for b in 0..k {
            let members = &order[b * n_c / k..(b + 1) * n_c / k];
            if members.is_empty() {
                continue;
            }
            let ss: f64 = members.iter().map(|&c| held.position_m2[c]).sum();
            let floor_ss: f64 = match floor_var {
                Some(_) => members.iter().map(|&c| held.floor_m2[c]).sum(),
                None => overall * members.len() as f64,
            };
            let dof: f64 = match floor_var {
                Some(_) => members.iter().map(|&c| n_pos[c] as f64).sum(),
                None => members.len() as f64 * 3.0,
            };
            let per_axis = floor_ss / dof.max(1.0);
            let p = if per_axis > 0.0 {
                chi2_sf(ss / per_axis, dof)
            } else {
                1.0
            };
            p_raw.push(p);
            bins.push(Bin {
                signal: name.clone(),
                lo: v[members[0]],
                hi: v[*members.last().unwrap_or(&members[0])],
                n: members.len(),
                rms_m: (ss / members.len() as f64).sqrt(),
                mean_m: None,
                floor_rms_m: (floor_ss / members.len() as f64).sqrt(),
                p_value: p,
                flagged: false,
            });
        }
    }
    let adj = holm(&p_raw);
    for (b, p) in bins.iter_mut().zip(adj) {
        b.p_value = p;
        b.flagged = p < cfg.alpha;
    }
    bins
}
