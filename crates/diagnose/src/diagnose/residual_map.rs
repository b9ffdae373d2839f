//! Where: the held-out residuals binned by signal (joint readings, motor and drum phases,
//! directions, distance, cable angle, time), each bin against the floor and each signal's
//! dependence tested.

use std::f64::consts::TAU;

use hapcal_contract::Effect;
use hapcal_io::Device;
use hapcal_kinematics::Point3;

use super::cv::Cv;
use super::{Bin, SignalTest};
use crate::model::{Data, Linear};
use crate::stats::mean;
use crate::stats::{chi2_sf, f_sf};

/// A binned signal: name, value per sample, bin edges.
type Signal = (String, Vec<f64>, Vec<(f64, f64)>);

/// The residual map of held-out residuals `cv`: its bins (Bonferroni over all bins at
/// `alpha`) and the tests of its signals (Bonferroni over signals).
pub(super) fn residual_map(
    device: &Device,
    data: &Data,
    lin: &Linear,
    cv: &Cv,
    alpha: f64,
) -> (Vec<Bin>, Vec<SignalTest>) {
    let n = data.n_rows();
    let signals = signals(device, data, lin);
    let n_bins: usize = signals.iter().map(|s| s.2.len()).sum();
    let bin_alpha = alpha / n_bins as f64;
    let z2: Vec<f64> = (0..n)
        .map(|i| cv.e[i].powi(2) / cv.var[i].max(1e-300))
        .collect();
    let mut bins = Vec::new();
    let mut tests = Vec::new();
    let n_signals = signals.len() as f64;
    for (name, v, edges) in &signals {
        let members = members(v, edges, n);
        // Mean (a bias that changes sign) and mean square (a spread), Bonferroni over both.
        let p = (2.0
            * anova(&members, n, &|i| cv.e[i] / cv.var[i].max(1e-300).sqrt()).min(anova(
                &members,
                n,
                &|i| z2[i],
            )))
        .min(1.0);
        bins.extend(signal_bins(name, edges, &members, cv, &z2, bin_alpha));
        tests.push(SignalTest {
            signal: name.clone(),
            p_value: p,
            significant: p < alpha / n_signals,
        });
    }
    (bins, tests)
}

/// The bins of signal `name` that hold samples (`members`), each against the floor, flagged
/// below `bin_alpha`.
fn signal_bins(
    name: &str,
    edges: &[(f64, f64)],
    members: &[Vec<usize>],
    cv: &Cv,
    z2: &[f64],
    bin_alpha: f64,
) -> Vec<Bin> {
    (members.iter().enumerate())
        .filter(|(_, m)| !m.is_empty())
        .map(|(b, m)| {
            let nb = m.len() as f64;
            let chi: f64 = m.iter().map(|&i| z2[i]).sum();
            let p = chi2_sf(chi, nb);
            Bin {
                signal: name.to_owned(),
                lo: edges[b].0,
                hi: edges[b].1,
                n: m.len(),
                rms_m: mean(m.iter().map(|&i| cv.e[i].powi(2))).sqrt(),
                mean_m: Some(mean(m.iter().map(|&i| cv.e[i]))),
                floor_rms_m: mean(m.iter().map(|&i| cv.var[i])).sqrt(),
                p_value: p,
                flagged: p < bin_alpha,
            }
        })
        .collect()
}

/// The signals binned: per joint its reading (quantile bins), its motor phase (a capstan
/// joint) and direction (a log with time); the distance, the cable angle, the time and the
/// cable drum's phase.
fn signals(device: &Device, data: &Data, lin: &Linear) -> Vec<Signal> {
    let mut signals: Vec<Signal> = Vec::new();
    for j in 0..data.q().first().map_or(0, Vec::len) {
        let v: Vec<f64> = data.q().iter().map(|q| q[j]).collect();
        let edges = quantile_edges(&v, 5);
        signals.push((format!("q{}", j + 1), v.clone(), edges));
        if let Some(c) = device.capstans.iter().find(|c| c.joint == j + 1) {
            let ph: Vec<f64> = v.iter().map(|q| (c.ratio * q).rem_euclid(TAU)).collect();
            signals.push((format!("motor_phase{}", j + 1), ph, phase_edges(8)));
        }
        if let Some(dir) = data.direction(j) {
            signals.push((
                format!("direction{}", j + 1),
                dir,
                vec![(-1.5, 0.0), (0.0, 1.5)],
            ));
        }
    }
    signals.push((
        "distance".into(),
        data.distance_m().to_vec(),
        quantile_edges(data.distance_m(), 5),
    ));
    let gamma: Vec<f64> = (lin.p.iter())
        .map(|p| hapcal_problems::cable_angle(&Point3::from(*p)).0)
        .collect();
    signals.push((
        Effect::CableAngle.name().into(),
        gamma.clone(),
        quantile_edges(&gamma, 5),
    ));
    if let Some(t) = data.t_s() {
        signals.push(("time".into(), t.to_vec(), quantile_edges(t, 5)));
    }
    let drum = (device.cable_encoder)
        .unwrap_or(hapcal_sim::REFERENCE_CABLE_ENCODER)
        .drum_radius_m;
    let ph: Vec<f64> = data
        .distance_m()
        .iter()
        .map(|d| (d / drum).rem_euclid(TAU))
        .collect();
    signals.push(("drum_phase".into(), ph, phase_edges(8)));
    signals
}

/// `k` bins between quantiles of `v`.
fn quantile_edges(v: &[f64], k: usize) -> Vec<(f64, f64)> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let at = |f: f64| {
        s.get(((s.len() as f64 - 1.0) * f).round() as usize)
            .copied()
            .unwrap_or(0.0)
    };
    (0..k)
        .map(|b| (at(b as f64 / k as f64), at((b + 1) as f64 / k as f64)))
        .collect()
}

/// `k` equal bins of a phase, 0 to 2π.
fn phase_edges(k: usize) -> Vec<(f64, f64)> {
    (0..k)
        .map(|b| (TAU * b as f64 / k as f64, TAU * (b + 1) as f64 / k as f64))
        .collect()
}

/// The samples of each bin of `edges` (values below the first edge in the first bin, above
/// the last in the last).
fn members(v: &[f64], edges: &[(f64, f64)], n: usize) -> Vec<Vec<usize>> {
    let last = edges.len().saturating_sub(1);
    let bin_of = |x: f64| {
        edges
            .iter()
            .position(|&(lo, hi)| x >= lo && x < hi)
            .unwrap_or(if x >= edges.last().map_or(0.0, |e| e.0) {
                last
            } else {
                0
            })
    };
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); edges.len()];
    for i in 0..n {
        members[bin_of(v[i])].push(i);
    }
    members
}

/// Between-bin F-test p-value of `z` over the bins `members`.
fn anova(members: &[Vec<usize>], n: usize, z: &dyn Fn(usize) -> f64) -> f64 {
    let groups = members.iter().filter(|m| !m.is_empty()).count();
    let grand = mean((0..n).map(z));
    let (mut between, mut within) = (0.0, 0.0);
    for m in members.iter().filter(|m| !m.is_empty()) {
        let mz = mean(m.iter().map(|&i| z(i)));
        between += m.len() as f64 * (mz - grand).powi(2);
        within += m.iter().map(|&i| (z(i) - mz).powi(2)).sum::<f64>();
    }
    let d1 = groups.saturating_sub(1) as f64;
    let d2 = (n as f64 - groups as f64).max(1.0);
    if d1 > 0.0 && within > 0.0 {
        f_sf((between / d1) / (within / d2), d1, d2)
    } else {
        1.0
    }
}
