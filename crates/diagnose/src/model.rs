//! The measurement model the diagnosis linearises: transmissions (paper eq. 1, joint-4
//! polynomial), kinematic deviations (eqs. 3–5) and the terms of candidate effects, with
//! per-row standard deviations from the encoder specification.

use std::f64::consts::TAU;

use hapcal_io::{Device, LogRow, N_EXT};
use hapcal_kinematics::{Chain, FkWorkspace, Vector3};
use hapcal_transmission::{Capstan, CapstanParams, Chebyshev, JointRad};
use nalgebra::{DMatrix, DVector};

/// Relative tolerance below which a scaled column counts as dependent on the others.
pub(crate) const RANK_TOL: f64 = 1e-6;

/// Degree of the joint-4 polynomial (paper: tenth order).
pub(crate) const POLY_DEGREE: usize = 10;

/// The log, prepared: readings, times, velocities, distances, external encoders.
pub(crate) struct Data {
    pub n: usize,
    pub q: Vec<Vec<f64>>,
    pub t: Option<Vec<f64>>,
    /// Joint-reading velocities by central differences (rad/s), when the log has `t_s`.
    pub qdot: Option<Vec<Vec<f64>>>,
    pub dist: Vec<f64>,
    pub ext: Vec<Vec<Option<f64>>>,
}

impl Data {
    pub(crate) fn new(rows: &[LogRow]) -> Data {
        let n = rows.len();
        let q: Vec<Vec<f64>> = rows.iter().map(|r| r.q.clone()).collect();
        let t: Option<Vec<f64>> = rows.iter().map(|r| r.t_s).collect();
        let qdot = t.as_ref().map(|t| {
            (0..n)
                .map(|i| {
                    let (a, b) = (i.saturating_sub(1), (i + 1).min(n.saturating_sub(1)));
                    let dt = t[b] - t[a];
                    (0..q[i].len())
                        .map(|j| {
                            if dt > 0.0 {
                                (q[b][j] - q[a][j]) / dt
                            } else {
                                0.0
                            }
                        })
                        .collect()
                })
                .collect()
        });
        Data {
            n,
            q,
            t,
            qdot,
            dist: rows.iter().map(|r| r.distance_m).collect(),
            ext: rows.iter().map(|r| r.ext.clone()).collect(),
        }
    }

    /// Motion direction of joint `j` per sample (±1; a sample at rest keeps the previous sign).
    pub(crate) fn direction(&self, j: usize) -> Option<Vec<f64>> {
        let qdot = self.qdot.as_ref()?;
        let mut last = 1.0;
        Some(
            qdot.iter()
                .map(|v| {
                    let s = v.get(j).copied().unwrap_or(0.0);
                    if s != 0.0 {
                        last = s.signum();
                    }
                    last
                })
                .collect(),
        )
    }
}

/// One transmission of the baseline.
#[derive(Clone, Debug)]
pub(crate) enum Trans {
    /// A capstan drive (paper eq. 1) on `joint` (0-based).
    Capstan {
        joint: usize,
        capstan: Capstan,
        params: CapstanParams,
    },
    /// The joint-4 error polynomial (Chebyshev basis on the joint range).
    Poly { joint: usize, poly: Chebyshev },
}

impl Trans {
    fn joint(&self) -> usize {
        match self {
            Trans::Capstan { joint, .. } | Trans::Poly { joint, .. } => *joint,
        }
    }
    fn n_params(&self) -> usize {
        match self {
            Trans::Capstan { .. } => 6,
            Trans::Poly { poly, .. } => poly.coeffs.len(),
        }
    }
    fn names(&self) -> Vec<String> {
        match self {
            Trans::Capstan { joint, .. } => ["c", "re", "r_o", "beta_o", "r_i", "beta_i"]
                .iter()
                .map(|p| format!("capstan{}.{p}", joint + 1))
                .collect(),
            Trans::Poly { joint, poly } => (0..poly.coeffs.len())
                .map(|k| format!("joint{}.cheb{k}", joint + 1))
                .collect(),
        }
    }
    /// Output angle and its gradient w.r.t. the transmission's parameters.
    fn eval(&self, theta: f64) -> (f64, Vec<f64>) {
        match self {
            Trans::Capstan {
                capstan, params, ..
            } => (
                capstan.output_rad(params, JointRad(theta)),
                capstan.error_grad(params, JointRad(theta)).to_vec(),
            ),
            Trans::Poly { poly, .. } => (theta + poly.eval(theta), poly.basis(theta)),
        }
    }
    fn update(&mut self, delta: &[f64]) {
        match self {
            Trans::Capstan { params, .. } => {
                let d = |i: usize| delta.get(i).copied().unwrap_or(0.0);
                params.c_rad += d(0);
                params.re += d(1);
                params.r_o_m += d(2);
                params.beta_o_rad += d(3);
                params.r_i_m += d(4);
                params.beta_i_rad += d(5);
            }
            Trans::Poly { poly, .. } => {
                for (c, d) in poly.coeffs.iter_mut().zip(delta) {
                    *c += d;
                }
            }
        }
    }
}

/// How a term of a candidate effect acts, per sample.
#[derive(Clone, Debug)]
pub(crate) enum TermKind {
    /// Adds `coef·g[i]` to joint `joint`'s angle (0-based), rad per unit coefficient.
    Joint { joint: usize, g: Vec<f64> },
    /// Adds `coef·h[i]` to the distance, m per unit coefficient.
    Distance { h: Vec<f64> },
    /// Adds `coef·ḋ` (the distance rate through the joint velocities), coefficient in s.
    Latency,
    /// Adds `coef·|P|·(t − t_0)` (coefficient in 1/s) when `scale`, else `coef·(t − t_0)`
    /// (m/s).
    ThermalDrift { scale: bool },
    /// Adds `coef·f(γ)`, γ the cable's angle from the rig z axis: `f = γ − sin γ` for
    /// `power` 0, else `cos^power γ`; coefficient in m.
    CableAngle { power: i32 },
    /// Adds `coef·τ_j(q)` to joint `joint`'s angle, τ the handle's gravity torque (N·m);
    /// coefficient in rad/(N·m).
    Compliance { joint: usize },
}

/// One parameter of a candidate effect.
#[derive(Clone, Debug)]
pub(crate) struct Term {
    pub name: String,
    pub unit: &'static str,
    pub kind: TermKind,
}

/// Everything the model needs besides the parameters.
pub(crate) struct Setup {
    pub chain: Chain,
    pub n_joints: usize,
    /// Joint-side resolution of each joint's reading, rad (0 when unknown).
    pub resolution_rad: Vec<f64>,
    pub sigma_m_m: f64,
    pub sigma_e_rad: f64,
    /// Whether the reading quantisation enters the floor.
    pub quantisation: bool,
    /// Joints (0-based) whose external encoder enters the fit.
    pub ext_joints: Vec<usize>,
    pub handle_mass_kg: f64,
}

/// The parameters: transmissions, kinematic deviations, effect coefficients.
#[derive(Clone, Debug)]
pub(crate) struct State {
    pub trans: Vec<Trans>,
    pub x_kin: Vec<f64>,
    pub terms: Vec<(Term, f64)>,
}

impl State {
    /// Adds `delta` (in the column order of [`Setup::linearise`]) to the parameters.
    pub(crate) fn apply(&mut self, delta: &[f64]) {
        let mut off = 0;
        for tr in &mut self.trans {
            let np = tr.n_params();
            tr.update(delta.get(off..off + np).unwrap_or(&[]));
            off += np;
        }
        for x in &mut self.x_kin {
            *x += delta.get(off).copied().unwrap_or(0.0);
            off += 1;
        }
        for (_, coef) in &mut self.terms {
            *coef += delta.get(off).copied().unwrap_or(0.0);
            off += 1;
        }
    }
}

/// The model linearised at a state: weighted residuals and Jacobian.
pub(crate) struct Linear {
    /// Weighted residuals (measured − model)/σ: the `n` distance rows, then the external
    /// encoder rows (joint by joint, `n` each).
    pub r: DVector<f64>,
    /// Weighted Jacobian of the model, one column per parameter of `names`.
    pub j: DMatrix<f64>,
    pub names: Vec<String>,
    /// σ of each row (m or rad).
    pub sigma: Vec<f64>,
    /// Sample of each row.
    pub sample: Vec<usize>,
    /// Per sample: end point in the rig frame, m.
    pub p: Vec<Vector3<f64>>,
}

impl Setup {
    pub(crate) fn new(device: &Device, chain: Chain, quantisation: bool) -> Setup {
        let cable = device.cable_encoder;
        let counts = cable.map_or(20_000, |c| c.counts_per_rev);
        let drum = cable.map_or(0.015, |c| c.drum_radius_m);
        // The paper's noise model (docs/design.md §3): σ_e a third of an encoder count, σ_m = 2π·R_d·σ_e.
        let sigma_e_rad = TAU / f64::from(counts.max(1)) / 3.0;
        Setup {
            n_joints: chain.n_joints(),
            chain,
            resolution_rad: hapcal_sim::joint_resolutions_rad(device)
                .into_iter()
                .map(|r| r.unwrap_or(0.0))
                .collect(),
            sigma_m_m: TAU * drum * sigma_e_rad,
            sigma_e_rad,
            quantisation,
            ext_joints: Vec::new(),
            handle_mass_kg: device
                .handle
                .map_or(hapcal_sim::DEFAULT_HANDLE_MASS_KG, |h| h.mass_kg),
        }
    }

    /// Linearises the model at `s`.
    pub(crate) fn linearise(&self, data: &Data, s: &State) -> Linear {
        let n = data.n;
        let nj = self.n_joints;
        let n_trans: usize = s.trans.iter().map(Trans::n_params).sum();
        let n_kin = self.chain.n_params();
        let n_terms = s.terms.len();
        let ncols = n_trans + n_kin + n_terms;
        let n_ext = self.ext_joints.len();
        let nrows = n * (1 + n_ext);
        let mut r = DVector::zeros(nrows);
        let mut j = DMatrix::zeros(nrows, ncols);
        let mut sigma = vec![0.0; nrows];
        let mut sample = vec![0; nrows];
        let mut p_all = Vec::with_capacity(n);
        let mut names: Vec<String> = s.trans.iter().flat_map(Trans::names).collect();
        names.extend(self.chain.params().iter().map(|p| p.name.clone()));
        names.extend(s.terms.iter().map(|(t, _)| t.name.clone()));
        let t0 = data
            .t
            .as_ref()
            .and_then(|t| t.first().copied())
            .unwrap_or(0.0);
        let mut ws = FkWorkspace::new(&self.chain);
        let mut buf = vec![0.0; 3 * n_kin];
        for i in 0..n {
            let theta = &data.q[i];
            let mut q = theta.clone();
            // ∂q_joint/∂(column) for the transmissions and joint terms.
            let mut dq: Vec<(usize, usize, f64)> = Vec::new();
            let mut col = 0;
            for tr in &s.trans {
                let jt = tr.joint();
                let (out, grad) = tr.eval(theta.get(jt).copied().unwrap_or(0.0));
                if let Some(v) = q.get_mut(jt) {
                    *v = out;
                }
                for (k, g) in grad.iter().enumerate() {
                    dq.push((jt, col + k, *g));
                }
                col += tr.n_params();
            }
            // Gravity torques at the transmission-corrected angles (small terms: no iteration).
            let needs_torque = s
                .terms
                .iter()
                .any(|(t, _)| matches!(t.kind, TermKind::Compliance { .. }));
            let torques = if needs_torque {
                hapcal_sim::handle_gravity_torques_nm(
                    &self.chain,
                    &s.x_kin,
                    &q,
                    self.handle_mass_kg,
                )
            } else {
                Vec::new()
            };
            for (k, (term, coef)) in s.terms.iter().enumerate() {
                let c = n_trans + n_kin + k;
                let (jt, g) = match &term.kind {
                    TermKind::Joint { joint, g } => (*joint, g.get(i).copied().unwrap_or(0.0)),
                    TermKind::Compliance { joint } => {
                        (*joint, torques.get(*joint).copied().unwrap_or(0.0))
                    }
                    _ => continue,
                };
                if let Some(v) = q.get_mut(jt) {
                    *v += coef * g;
                }
                dq.push((jt, c, g));
            }
            let p = self
                .chain
                .point_and_jacobian_in(&s.x_kin, &q, &mut ws, &mut buf)
                .coords;
            let norm = p.norm();
            let u = if norm > 0.0 {
                p / norm
            } else {
                Vector3::zeros()
            };
            let jq = self.chain.geometric_jacobian(&s.x_kin, &q);
            let dd_dq: Vec<f64> = (0..nj)
                .map(|jj| (0..3).map(|a| u[a] * jq[(a, jj)]).sum())
                .collect();
            // Distance model and its column entries.
            let mut d_model = norm;
            let mut row_j = vec![0.0; ncols];
            for k in 0..n_kin {
                row_j[n_trans + k] =
                    u[0] * buf[3 * k] + u[1] * buf[3 * k + 1] + u[2] * buf[3 * k + 2];
            }
            for &(jt, c, g) in &dq {
                row_j[c] += dd_dq.get(jt).copied().unwrap_or(0.0) * g;
            }
            // A cable-angle term moves with P: its derivative through γ (cos γ = P_z/|P|).
            let grad_c = if norm > 0.0 {
                (Vector3::z() - u * u[2]) / norm
            } else {
                Vector3::zeros()
            };
            let cos_g = u[2].clamp(-1.0, 1.0);
            let mut dh_dc = 0.0;
            for (term, coef) in &s.terms {
                if let TermKind::CableAngle { power } = term.kind {
                    let sin_g = (1.0 - cos_g * cos_g).sqrt().max(1e-9);
                    dh_dc += coef
                        * if power == 0 {
                            -(1.0 - cos_g) / sin_g
                        } else {
                            f64::from(power) * cos_g.powi(power - 1)
                        };
                }
            }
            if dh_dc != 0.0 {
                for k in 0..n_kin {
                    let dp = Vector3::new(buf[3 * k], buf[3 * k + 1], buf[3 * k + 2]);
                    row_j[n_trans + k] += dh_dc * grad_c.dot(&dp);
                }
                for &(jt, c, g) in &dq {
                    let jv = Vector3::new(jq[(0, jt)], jq[(1, jt)], jq[(2, jt)]);
                    row_j[c] += dh_dc * grad_c.dot(&jv) * g;
                }
            }
            for (k, (term, coef)) in s.terms.iter().enumerate() {
                let c = n_trans + n_kin + k;
                let h = match &term.kind {
                    TermKind::Distance { h } => h.get(i).copied().unwrap_or(0.0),
                    TermKind::Latency => match data.qdot.as_ref() {
                        Some(qd) => (0..nj).map(|jj| dd_dq[jj] * qd[i][jj]).sum(),
                        None => 0.0,
                    },
                    TermKind::ThermalDrift { scale } => {
                        let t = data.t.as_ref().map_or(0.0, |t| t[i]);
                        if *scale { norm * (t - t0) } else { t - t0 }
                    }
                    TermKind::CableAngle { power } => {
                        let g = hapcal_sim::cable_angle_rad(&p);
                        if *power == 0 {
                            g - g.sin()
                        } else {
                            g.cos().powi(*power)
                        }
                    }
                    _ => continue,
                };
                d_model += coef * h;
                row_j[c] += h;
            }
            let mut var = self.sigma_m_m.powi(2);
            if self.quantisation {
                for (jj, dd) in dd_dq.iter().enumerate() {
                    let res = self.resolution_rad.get(jj).copied().unwrap_or(0.0);
                    var += (dd * res).powi(2) / 12.0;
                }
            }
            let sd = var.sqrt().max(1e-12);
            r[i] = (data.dist[i] - d_model) / sd;
            for (c, v) in row_j.iter().enumerate() {
                j[(i, c)] = v / sd;
            }
            sigma[i] = sd;
            sample[i] = i;
            // External encoder rows: measured output angle − modelled joint angle.
            for (e, &jt) in self.ext_joints.iter().enumerate() {
                let row = n * (1 + e) + i;
                let res = self.resolution_rad.get(jt).copied().unwrap_or(0.0);
                let mut var = self.sigma_e_rad.powi(2);
                if self.quantisation {
                    var += res * res / 12.0;
                }
                let sd = var.sqrt().max(1e-15);
                let meas = data.ext[i].get(jt).copied().flatten().unwrap_or(q[jt]);
                r[row] = (meas - q[jt]) / sd;
                for &(jq_, c, g) in &dq {
                    if jq_ == jt {
                        j[(row, c)] += g / sd;
                    }
                }
                sigma[row] = sd;
                sample[row] = i;
            }
            p_all.push(p);
        }
        Linear {
            r,
            j,
            names,
            sigma,
            sample,
            p: p_all,
        }
    }

    /// Fits the model from `s` by `hapcal-identify`'s Levenberg–Marquardt
    /// ([`crate::solve::fit_model`]) on the identifiable columns ([`RANK_TOL`], re-picked when
    /// they change at the estimate), within a budget of `iters` Gauss–Newton iterations;
    /// returns the refined state and the linearisation there.
    pub(crate) fn refine(&self, data: &Data, s: State, iters: usize) -> (State, Linear) {
        crate::solve::fit_model(self, data, s, iters, RANK_TOL)
    }
}

/// Whether the log has every external encoder the device's transmissions need.
pub(crate) fn ext_available(rows: &[LogRow], joints: &[usize]) -> bool {
    !rows.is_empty()
        && joints.iter().all(|&j| {
            j < N_EXT
                && rows
                    .iter()
                    .all(|r| r.ext.get(j).copied().flatten().is_some())
        })
}
