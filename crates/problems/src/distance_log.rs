//! The measurement model of a haptic device's cable-encoder distance log (docs/design.md §6,
//! docs/diagnosis.md): transmissions (paper eq. 1, the joint-4 polynomial), kinematic
//! deviations (eqs. 3–5) and the terms of unmodelled effects, with per-row standard deviations
//! from the encoder specification; and the distance row that every cable-distance residual of
//! the crate shares ([`distance_row`]).

use std::f64::consts::TAU;

use hapcal_kinematics::{Chain, FkWorkspace, Matrix6xX, Point3, Vector3};
use hapcal_transmission::{Capstan, CapstanParams, Chebyshev, JointRad};
use nalgebra::{DMatrix, DVector};

use crate::Error;
use crate::compliance::handle_gravity_torques_nm;
use crate::fleet::cable_angle;
use crate::problem::{along, length_and_direction};
use crate::transmission::{CAPSTAN_PARAMS, capstan_param, chebyshev_param};

/// The end point `P` (rig frame, m), the distance `|P|` (paper eq. 5, m), its direction `u`
/// and `∂|P|/∂x_kin = uᵀ·∂P/∂x_kin` (one entry per chain parameter), at deviations `x_kin` and
/// joint angles `q`; `buf` (length `3·n_params`) holds `∂P/∂x_kin` afterwards, column by column.
pub(crate) fn distance_and_gradient(
    chain: &Chain,
    x_kin: &[f64],
    q: &[f64],
    ws: &mut FkWorkspace,
    buf: &mut [f64],
) -> (Vector3<f64>, f64, Vector3<f64>, Vec<f64>) {
    let p = chain.point_and_jacobian_in(x_kin, q, ws, buf).coords;
    let (norm, u) = length_and_direction(&p);
    let d_kin = (0..chain.n_params()).map(|k| along(&u, buf, k)).collect();
    (p, norm, u, d_kin)
}

/// The geometric Jacobian at `(x_kin, q)` and `∂|P|/∂q_j = uᵀ·J_v,j` for every joint (`u` the
/// distance's direction, [`distance_and_gradient`]).
pub(crate) fn distance_joint_gradient(
    chain: &Chain,
    x_kin: &[f64],
    q: &[f64],
    u: &Vector3<f64>,
) -> (Matrix6xX<f64>, Vec<f64>) {
    let jq = chain.geometric_jacobian(x_kin, q);
    let dd_dq = (0..chain.n_joints())
        .map(|j| (0..3).map(|a| u[a] * jq[(a, j)]).sum())
        .collect();
    (jq, dd_dq)
}

/// One cable-distance row of the identification Jacobian ([`distance_row`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceRow {
    /// The modelled distance `|P|` from the rig origin to the end point, m (paper eq. 5).
    pub distance_m: f64,
    /// `∂|P|/∂x` for every chain parameter (length `chain.n_params()`; 1 for a length, m/rad
    /// for an angle), unweighted.
    pub jacobian: Vec<f64>,
    /// `∂|P|/∂q_j` for every joint, m/rad (empty when no joint variance was given).
    pub joint_gradient: Vec<f64>,
    /// The row's standard deviation, m: `σ² = σ_m² + Σⱼ (∂|P|/∂qⱼ)²·var_j`.
    pub sigma_m: f64,
}

/// A cable-distance row (paper eq. 5, `δ = |P(x, q)|`, `P` the end point in the rig frame) at
/// deviations `x_kin` (m, rad; `chain.n_params()` entries) and joint angles `q` (rad,
/// `chain.n_joints()`): the distance, its gradient over the chain parameters and its standard
/// deviation `σ² = σ_m² + Σⱼ (∂|P|/∂qⱼ)²·joint_var_rad2[j]` (m²), the cable encoder's `sigma_m`
/// (m) plus joint-angle errors of variance `joint_var_rad2` (rad², one per joint, or empty for
/// none) propagated to first order. The same distance Jacobian as [`crate::JointProblem`]'s
/// and [`DistanceLogModel`]'s distance rows.
///
/// # Errors
/// [`Error::LengthMismatch`] for `x_kin` or a non-empty `joint_var_rad2` of the wrong length;
/// [`Error::JointCount`] for `q` of the wrong length; [`Error::NotFinite`] for a non-finite
/// angle, deviation or variance; [`Error::BadSigma`] for `sigma_m` not positive and finite or
/// a negative variance.
pub fn distance_row(
    chain: &Chain,
    x_kin: &[f64],
    q: &[f64],
    sigma_m: f64,
    joint_var_rad2: &[f64],
) -> Result<DistanceRow, Error> {
    let (n_params, n_joints) = (chain.n_params(), chain.n_joints());
    if x_kin.len() != n_params {
        return Err(Error::LengthMismatch {
            name: "x_kin",
            expected: n_params,
            found: x_kin.len(),
        });
    }
    Error::check_joint_count(0, n_joints, q.len())?;
    if !joint_var_rad2.is_empty() && joint_var_rad2.len() != n_joints {
        return Err(Error::LengthMismatch {
            name: "joint_var_rad2",
            expected: n_joints,
            found: joint_var_rad2.len(),
        });
    }
    if !x_kin.iter().chain(q).all(|v| v.is_finite()) {
        return Err(Error::NotFinite { row: 0 });
    }
    if !(sigma_m.is_finite() && sigma_m > 0.0) {
        return Err(Error::BadSigma {
            name: "sigma_m",
            value: sigma_m,
        });
    }
    if let Some(&value) = joint_var_rad2
        .iter()
        .find(|v| !(v.is_finite() && **v >= 0.0))
    {
        return Err(Error::BadSigma {
            name: "joint_var_rad2",
            value,
        });
    }
    let mut ws = FkWorkspace::new(chain);
    let mut buf = vec![0.0; 3 * n_params];
    let (_, norm, u, jacobian) = distance_and_gradient(chain, x_kin, q, &mut ws, &mut buf);
    let mut var = sigma_m * sigma_m;
    let mut joint_gradient = Vec::new();
    if joint_var_rad2.iter().any(|&v| v > 0.0) {
        let (_, dd_dq) = distance_joint_gradient(chain, x_kin, q, &u);
        for (dd, v) in dd_dq.iter().zip(joint_var_rad2) {
            var += dd * dd * v;
        }
        joint_gradient = dd_dq;
    }
    Ok(DistanceRow {
        distance_m: norm,
        jacobian,
        joint_gradient,
        sigma_m: var.sqrt(),
    })
}

/// A time-ordered distance log, validated: joint readings, optional sample times, cable
/// distances and external-encoder readings (docs/design.md §5), with the joint velocities the
/// latency term needs.
#[derive(Clone, Debug)]
pub struct DistanceLog {
    q: Vec<Vec<f64>>,
    t: Option<Vec<f64>>,
    qdot: Option<Vec<Vec<f64>>>,
    distance_m: Vec<f64>,
    ext: Vec<Vec<Option<f64>>>,
}

impl DistanceLog {
    /// A log of `q.len()` rows: joint readings `q` (rad, one row of `n_joints` angles per
    /// sample), sample times `t_s` (s, one per row, or `None`), cable distances `distance_m`
    /// (m, one per row) and external-encoder readings `ext` (rad, one row per sample, one
    /// entry per joint from joint 1, `None` where the log has none).
    ///
    /// # Errors
    /// [`Error::JointCount`] for a reading row of another length than the first;
    /// [`Error::LengthMismatch`] for `t_s`, `distance_m` or `ext` not of one entry per row;
    /// [`Error::NotFinite`] for a non-finite reading, time, distance or external reading.
    pub fn new(
        q: Vec<Vec<f64>>,
        t_s: Option<Vec<f64>>,
        distance_m: Vec<f64>,
        ext: Vec<Vec<Option<f64>>>,
    ) -> Result<Self, Error> {
        let n = q.len();
        let n_joints = q.first().map_or(0, Vec::len);
        for (name, found) in [
            ("t_s", t_s.as_ref().map_or(n, Vec::len)),
            ("distance_m", distance_m.len()),
            ("ext", ext.len()),
        ] {
            if found != n {
                return Err(Error::LengthMismatch {
                    name,
                    expected: n,
                    found,
                });
            }
        }
        for (row, r) in q.iter().enumerate() {
            Error::check_joint_count(row, n_joints, r.len())?;
            let finite = r.iter().all(|v| v.is_finite())
                && distance_m[row].is_finite()
                && t_s.as_ref().is_none_or(|t| t[row].is_finite())
                && ext[row].iter().flatten().all(|v| v.is_finite());
            if !finite {
                return Err(Error::NotFinite { row });
            }
        }
        // Joint-reading velocities by central differences (one-sided at the ends), rad/s.
        let qdot = t_s.as_ref().map(|t| {
            (0..n)
                .map(|i| {
                    let (a, b) = (i.saturating_sub(1), (i + 1).min(n.saturating_sub(1)));
                    let dt = t[b] - t[a];
                    (0..n_joints)
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
        Ok(Self {
            q,
            t: t_s,
            qdot,
            distance_m,
            ext,
        })
    }

    /// Number of rows (samples).
    pub fn n_rows(&self) -> usize {
        self.q.len()
    }

    /// Joint readings, rad: one row of `n_joints` angles per sample.
    pub fn q(&self) -> &[Vec<f64>] {
        &self.q
    }

    /// Sample times, s (one per row), if the log has them.
    pub fn t_s(&self) -> Option<&[f64]> {
        self.t.as_deref()
    }

    /// Joint-reading velocities by central differences (one-sided at the ends), rad/s, one row
    /// per sample, if the log has times; 0 between samples of equal time.
    pub fn qdot(&self) -> Option<&[Vec<f64>]> {
        self.qdot.as_deref()
    }

    /// Cable distances, m (one per row).
    pub fn distance_m(&self) -> &[f64] {
        &self.distance_m
    }

    /// External-encoder readings, rad: one row per sample, one entry per joint from joint 1
    /// (`None` where the log has none).
    pub fn ext(&self) -> &[Vec<Option<f64>>] {
        &self.ext
    }

    /// Motion direction of joint `j` (0-based) per sample, ±1 from the sign of
    /// [`Self::qdot`] (a sample at rest keeps the previous sign, the first one +1); `None`
    /// without times.
    pub fn direction(&self, j: usize) -> Option<Vec<f64>> {
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

/// One transmission of a [`DistanceLogModel`]: the map from a joint's reading `θ` to its
/// angle, with the gradient over its parameters.
///
/// Source: paper eq. 1 and the parallelogram section; docs/design.md, "Capstan drive (paper
/// eq. 1)" and "Parallelogram (paper eq. 2) and the joint-4 polynomial".
#[derive(Clone, Debug, PartialEq)]
pub enum LogTransmission {
    /// A capstan drive (paper eq. 1) on `joint` (0-based): parameters `c` (rad), `re` (1),
    /// `r_o` (m), `beta_o` (rad), `r_i` (m), `beta_i` (rad), as
    /// [`crate::CapstanProblem`].
    Capstan {
        /// The joint, 0-based.
        joint: usize,
        /// The drive's geometry (ratio, drum distance).
        capstan: Capstan,
        /// Its eq. 1 parameters.
        params: CapstanParams,
    },
    /// A joint whose angle is `θ + p(θ)`, `p` a Chebyshev polynomial on the joint's range (the
    /// paper's joint 4, capstan + parallelogram, tenth order); its coefficients (rad) are the
    /// parameters.
    Polynomial {
        /// The joint, 0-based.
        joint: usize,
        /// The polynomial.
        poly: Chebyshev,
    },
}

impl LogTransmission {
    /// The joint it drives, 0-based.
    pub fn joint(&self) -> usize {
        match self {
            Self::Capstan { joint, .. } | Self::Polynomial { joint, .. } => *joint,
        }
    }

    /// Number of parameters: 6 for a capstan, `degree + 1` for a polynomial.
    pub fn n_params(&self) -> usize {
        match self {
            Self::Capstan { .. } => 6,
            Self::Polynomial { poly, .. } => poly.coeffs.len(),
        }
    }

    /// Parameter names, as [`crate::JointProblem`] names them (joints 1-based):
    /// `capstan{j}.c … .beta_i`, `joint{j}.cheb0 … cheb{degree}`.
    pub fn names(&self) -> Vec<String> {
        match self {
            Self::Capstan { joint, .. } => (CAPSTAN_PARAMS.iter())
                .map(|&(p, _)| capstan_param(joint + 1, p))
                .collect(),
            Self::Polynomial { joint, poly } => (0..poly.coeffs.len())
                .map(|k| chebyshev_param(joint + 1, k))
                .collect(),
        }
    }

    /// The joint angle at reading `theta` (rad) and its gradient over the parameters
    /// ([`Self::n_params`] entries, rad per unit parameter).
    pub fn eval(&self, theta: f64) -> (f64, Vec<f64>) {
        match self {
            Self::Capstan {
                capstan, params, ..
            } => (
                capstan.output_rad(params, JointRad(theta)),
                capstan.error_grad(params, JointRad(theta)).to_vec(),
            ),
            Self::Polynomial { poly, .. } => (theta + poly.eval(theta), poly.basis(theta)),
        }
    }

    /// The parameters' values, in [`Self::names`]' order (a capstan's `c` rad, `re` 1, `r_o`
    /// m, `beta_o` rad, `r_i` m, `beta_i` rad; a polynomial's coefficients, rad).
    pub fn values(&self) -> Vec<f64> {
        match self {
            Self::Capstan { params: p, .. } => {
                vec![p.c_rad, p.re, p.r_o_m, p.beta_o_rad, p.r_i_m, p.beta_i_rad]
            }
            Self::Polynomial { poly, .. } => poly.coeffs.clone(),
        }
    }

    /// Adds `delta` (in [`Self::names`]' order; missing entries 0) to the parameters.
    pub fn update(&mut self, delta: &[f64]) {
        match self {
            Self::Capstan { params, .. } => {
                let d = |i: usize| delta.get(i).copied().unwrap_or(0.0);
                params.c_rad += d(0);
                params.re += d(1);
                params.r_o_m += d(2);
                params.beta_o_rad += d(3);
                params.r_i_m += d(4);
                params.beta_i_rad += d(5);
            }
            Self::Polynomial { poly, .. } => {
                for (c, d) in poly.coeffs.iter_mut().zip(delta) {
                    *c += d;
                }
            }
        }
    }
}

/// How one effect term of a [`DistanceLogModel`] acts, per sample (docs/design.md §6, the
/// effect library; docs/diagnosis.md §3).
#[derive(Clone, Debug, PartialEq)]
pub enum EffectTermKind {
    /// Adds `coef·g[i]` to joint `joint`'s angle (0-based) at sample `i`; `g` one value per
    /// row, rad per unit coefficient.
    Joint {
        /// The joint, 0-based.
        joint: usize,
        /// The term's shape, one value per row.
        g: Vec<f64>,
    },
    /// Adds `coef·h[i]` to the distance at sample `i`; `h` one value per row, m per unit
    /// coefficient.
    Distance {
        /// The term's shape, one value per row.
        h: Vec<f64>,
    },
    /// Latency: adds `coef·ḋ`, `ḋ = Σⱼ (∂|P|/∂qⱼ)·q̇ⱼ` the distance rate through the joint
    /// velocities ([`DistanceLog::qdot`]); coefficient in s. Needs times.
    Latency,
    /// Thermal drift: adds `coef·|P|·(t − t₀)` (coefficient in 1/s) when `scale`, else
    /// `coef·(t − t₀)` (m/s), `t₀` the first sample's time. Needs times.
    ThermalDrift {
        /// Whether the drift scales with the distance.
        scale: bool,
    },
    /// Cable angle: adds `coef·f(γ)`, γ the cable's angle from the rig z axis
    /// ([`crate::cable_angle`]): `f = γ − sin γ` for `power` 0, else `cos^power γ`;
    /// coefficient in m. Its derivative through `P` enters every column.
    CableAngle {
        /// 0 for `γ − sin γ`, else the power of `cos γ`.
        power: i32,
    },
    /// Gravity compliance of the handle: adds `coef·τ_j(q)` to joint `joint`'s angle
    /// (0-based), τ the handle's gravity torque ([`crate::handle_gravity_torques_nm`], N·m, at
    /// the transmission-corrected angles and the current deviations); coefficient in
    /// rad/(N·m).
    Compliance {
        /// The joint, 0-based.
        joint: usize,
    },
}

/// One parameter of an effect: its name, its unit (as the report prints it, e.g. `rad`,
/// `m/s`, `rad/(N·m)`) and how it acts.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectTerm {
    /// Parameter name, e.g. `latency.tau`.
    pub name: String,
    /// Unit of the coefficient.
    pub unit: &'static str,
    /// How it acts.
    pub kind: EffectTermKind,
}

/// The parameters of a [`DistanceLogModel`]: transmissions, kinematic deviations, effect
/// coefficients, in that (column) order.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceLogState {
    /// The transmissions (their parameters first, in this order).
    pub transmissions: Vec<LogTransmission>,
    /// The chain's deviations, m or rad (`chain.n_params()` entries).
    pub x_kin: Vec<f64>,
    /// The effect terms and their coefficients.
    pub terms: Vec<(EffectTerm, f64)>,
}

impl DistanceLogState {
    /// Number of parameters (columns of [`DistanceLogModel::linearise`]).
    pub fn n_params(&self) -> usize {
        self.transmissions
            .iter()
            .map(LogTransmission::n_params)
            .sum::<usize>()
            + self.x_kin.len()
            + self.terms.len()
    }

    /// Every parameter's value, in the column order of [`DistanceLogModel::linearise`]
    /// (length [`Self::n_params`]; units as [`LogTransmission::values`], the chain's m or rad,
    /// each term's [`EffectTerm::unit`]).
    pub fn values(&self) -> Vec<f64> {
        let mut v: Vec<f64> = (self.transmissions.iter())
            .flat_map(LogTransmission::values)
            .collect();
        v.extend(&self.x_kin);
        v.extend(self.terms.iter().map(|(_, c)| *c));
        v
    }

    /// Adds `delta` (in the column order of [`DistanceLogModel::linearise`]; missing entries
    /// 0) to the parameters.
    pub fn apply(&mut self, delta: &[f64]) {
        let mut off = 0;
        for tr in &mut self.transmissions {
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

/// The noise of a distance log from the encoder specification.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceLogNoise {
    /// Cable-encoder standard deviation σ_m, m.
    pub sigma_m_m: f64,
    /// External-encoder standard deviation σ_e, rad.
    pub sigma_e_rad: f64,
    /// Joint-side resolution of each joint's reading, rad (0 when unknown), one per joint.
    pub resolution_rad: Vec<f64>,
}

impl DistanceLogNoise {
    /// The paper's noise model (docs/design.md §3): `σ_e = 2π/counts/3` (a third of an
    /// encoder count), `σ_m = 2π·R_d·σ_e`, for a cable encoder of `counts_per_rev` counts on a
    /// drum of radius `drum_radius_m` (m), with the joints' reading resolutions
    /// `resolution_rad` (rad). An encoder of 0 counts gives infinite σs, which
    /// [`DistanceLogModel::new`] refuses.
    pub fn paper(counts_per_rev: u32, drum_radius_m: f64, resolution_rad: Vec<f64>) -> Self {
        let sigma_e_rad = TAU / f64::from(counts_per_rev) / 3.0;
        Self {
            sigma_m_m: TAU * drum_radius_m * sigma_e_rad,
            sigma_e_rad,
            resolution_rad,
        }
    }
}

/// The model linearised at a state ([`DistanceLogModel::linearise`]).
#[derive(Clone, Debug)]
pub struct DistanceLogLinearisation {
    /// Weighted residuals `(model − measured)/σ`: the `n` distance rows, then the
    /// external-encoder rows, `n` per joint of [`DistanceLogModel::ext_joints`] in its order.
    pub residuals: DVector<f64>,
    /// Weighted Jacobian of the model (`rows × n_params`), one column per entry of `names`.
    pub jacobian: DMatrix<f64>,
    /// Parameter names: the transmissions', the chain's, the terms'.
    pub names: Vec<String>,
    /// σ of each row, m (distance rows) or rad (external-encoder rows).
    pub sigma: Vec<f64>,
    /// Sample (log row) of each row.
    pub sample: Vec<usize>,
    /// Per sample: the end point in the rig frame, m.
    pub points: Vec<Vector3<f64>>,
}

/// The measurement model of a haptic device's distance log (docs/diagnosis.md §1–3): each
/// sample's joint readings pass through the transmissions (paper eq. 1 on the capstans, the
/// joint-4 polynomial) and the joint effect terms to joint angles `q`; the modelled distance is
/// `|P(x_kin, q)|` (paper eq. 5) plus the distance effect terms.
///
/// Rows, weighted by their σ: the `n` cable distances, `σ² = σ_m² + Σⱼ (∂|P|/∂qⱼ·ρⱼ)²/12`
/// (the reading quantisation `ρⱼ²/12` propagated, when [`Self::quantisation`] is on, else
/// `σ_m²`); then, for each joint of [`Self::ext_joints`], its external-encoder reading against
/// the modelled joint angle, `σ² = σ_e² (+ ρⱼ²/12)`. The Jacobian is analytic, including the
/// distance rows' dependence on the transmissions through the corrected angles and, for a
/// cable-angle term or a scaled thermal drift, every column's through γ or `|P|`; two
/// second-order products are left out (a Gauss–Newton Jacobian of the effect terms about the
/// baseline): the dependence of a latency's distance rate and of a compliance's gravity torque
/// on the kinematic and transmission parameters, each a coefficient times a second
/// derivative of the chain. Restricted to the transmissions and the
/// kinematics without quantisation it is [`crate::JointProblem`] (rows and columns permuted).
///
/// Source: Baser & Konukseven, Fig. 6, eqs. 1 and 5; docs/design.md §3 (noise) and §6
/// (effects); docs/diagnosis.md.
#[derive(Clone, Debug)]
pub struct DistanceLogModel {
    chain: Chain,
    log: DistanceLog,
    noise: DistanceLogNoise,
    /// Whether the reading quantisation enters the rows' σ.
    pub quantisation: bool,
    ext_joints: Vec<usize>,
    handle_mass_kg: f64,
}

impl DistanceLogModel {
    /// The model of `log` on `chain` (nominal chain, rig → end point) with `noise`, the
    /// quantisation on, no external-encoder rows, and a handle of `handle_mass_kg` (kg) for the
    /// compliance terms.
    ///
    /// # Errors
    /// [`Error::JointCount`] for readings of another length than the chain's joints;
    /// [`Error::LengthMismatch`] for a `resolution_rad` not of one per joint;
    /// [`Error::BadSigma`] for a σ not positive and finite; [`Error::OutOfRange`] for a
    /// resolution or a handle mass negative or not finite.
    pub fn new(
        chain: Chain,
        log: DistanceLog,
        noise: DistanceLogNoise,
        handle_mass_kg: f64,
    ) -> Result<Self, Error> {
        let n_joints = chain.n_joints();
        for (row, q) in log.q.iter().enumerate() {
            Error::check_joint_count(row, n_joints, q.len())?;
        }
        if noise.resolution_rad.len() != n_joints {
            return Err(Error::LengthMismatch {
                name: "resolution_rad",
                expected: n_joints,
                found: noise.resolution_rad.len(),
            });
        }
        for (name, value) in [
            ("sigma_m_m", noise.sigma_m_m),
            ("sigma_e_rad", noise.sigma_e_rad),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::BadSigma { name, value });
            }
        }
        if let Some(&value) = (noise.resolution_rad.iter()).find(|v| !(v.is_finite() && **v >= 0.0))
        {
            return Err(Error::OutOfRange {
                name: "resolution_rad",
                value,
                expected: "a finite resolution ≥ 0 (0: unknown)",
            });
        }
        if !(handle_mass_kg.is_finite() && handle_mass_kg >= 0.0) {
            return Err(Error::OutOfRange {
                name: "handle_mass_kg",
                value: handle_mass_kg,
                expected: "a finite mass ≥ 0",
            });
        }
        Ok(Self {
            chain,
            log,
            noise,
            quantisation: true,
            ext_joints: Vec::new(),
            handle_mass_kg,
        })
    }

    /// The chain.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// The log.
    pub fn log(&self) -> &DistanceLog {
        &self.log
    }

    /// The noise model.
    pub fn noise(&self) -> &DistanceLogNoise {
        &self.noise
    }

    /// Joints (0-based) whose external-encoder readings are rows of the model, in row order.
    pub fn ext_joints(&self) -> &[usize] {
        &self.ext_joints
    }

    /// Makes the external-encoder readings of `joints` (0-based) rows of the model, in that
    /// order (empty: none).
    ///
    /// # Errors
    /// [`Error::NoSuchJoint`] for a joint the chain does not have; [`Error::MissingReading`]
    /// for a row without that joint's external reading.
    pub fn set_ext_joints(&mut self, joints: Vec<usize>) -> Result<(), Error> {
        let n_joints = self.chain.n_joints();
        for &joint in &joints {
            if joint >= n_joints {
                return Err(Error::NoSuchJoint {
                    joint: joint + 1,
                    n_joints,
                });
            }
            if let Some(row) =
                (self.log.ext.iter()).position(|e| e.get(joint).copied().flatten().is_none())
            {
                return Err(Error::MissingReading {
                    row,
                    joint: joint + 1,
                });
            }
        }
        self.ext_joints = joints;
        Ok(())
    }

    /// The state with `transmissions`, zero deviations and no effect terms.
    pub fn initial_state(&self, transmissions: Vec<LogTransmission>) -> DistanceLogState {
        DistanceLogState {
            transmissions,
            x_kin: vec![0.0; self.chain.n_params()],
            terms: Vec::new(),
        }
    }

    /// Checks that `s` fits the chain and the log.
    fn check(&self, s: &DistanceLogState) -> Result<(), Error> {
        let (n, n_joints) = (self.log.n_rows(), self.chain.n_joints());
        if s.x_kin.len() != self.chain.n_params() {
            return Err(Error::LengthMismatch {
                name: "x_kin",
                expected: self.chain.n_params(),
                found: s.x_kin.len(),
            });
        }
        let no_joint = |joint: usize| {
            (joint >= n_joints).then_some(Error::NoSuchJoint {
                joint: joint + 1,
                n_joints,
            })
        };
        if let Some(e) = s.transmissions.iter().find_map(|t| no_joint(t.joint())) {
            return Err(e);
        }
        // One transmission per joint: a second would correct the reading again from θ.
        for (k, t) in s.transmissions.iter().enumerate() {
            if s.transmissions[..k].iter().any(|o| o.joint() == t.joint()) {
                return Err(Error::OutOfRange {
                    name: "transmissions on one joint",
                    value: (t.joint() + 1) as f64,
                    expected: "at most one transmission per joint",
                });
            }
        }
        for (term, _) in &s.terms {
            let samples = |v: &Vec<f64>| {
                (v.len() != n).then_some(Error::LengthMismatch {
                    name: "effect term samples",
                    expected: n,
                    found: v.len(),
                })
            };
            let needs_times = || {
                self.log.t.is_none().then(|| Error::NoSampleTimes {
                    term: term.name.clone(),
                })
            };
            let problem = match &term.kind {
                EffectTermKind::Joint { joint, g } => no_joint(*joint).or_else(|| samples(g)),
                EffectTermKind::Distance { h } => samples(h),
                EffectTermKind::Compliance { joint } => no_joint(*joint),
                EffectTermKind::Latency | EffectTermKind::ThermalDrift { .. } => needs_times(),
                EffectTermKind::CableAngle { .. } => None,
            };
            if let Some(e) = problem {
                return Err(e);
            }
        }
        Ok(())
    }

    /// Linearises the model at `s`: weighted residuals and Jacobian, in the column order
    /// transmissions (in `s`' order), chain parameters, effect terms.
    ///
    /// # Errors
    /// [`Error::LengthMismatch`] for deviations not of the chain's length or a term's samples
    /// not of one per row; [`Error::NoSuchJoint`] for a transmission or term on a joint the
    /// chain does not have; [`Error::OutOfRange`] for two transmissions on one joint;
    /// [`Error::NoSampleTimes`] for a latency or thermal-drift term on a log without times.
    pub fn linearise(&self, s: &DistanceLogState) -> Result<DistanceLogLinearisation, Error> {
        self.check(s)?;
        let n = self.log.n_rows();
        let lay = SampleLayout::new(self, s);
        let n_ext = self.ext_joints.len();
        let nrows = n * (1 + n_ext);
        let mut r = DVector::zeros(nrows);
        let mut j = DMatrix::zeros(nrows, lay.ncols);
        let mut sigma = vec![0.0; nrows];
        let mut sample = vec![0; nrows];
        let mut p_all = Vec::with_capacity(n);
        let mut scratch = SampleScratch::new(self, &lay);
        for i in 0..n {
            let rows = self.sample_rows(s, &lay, i, &mut scratch)?;
            r[i] = rows.residual;
            for (c, v) in scratch.row_j.iter().enumerate() {
                j[(i, c)] = v / rows.sigma;
            }
            sigma[i] = rows.sigma;
            sample[i] = i;
            // External-encoder rows: modelled joint angle − measured output angle.
            for (e, &jt) in self.ext_joints.iter().enumerate() {
                let row = n * (1 + e) + i;
                let (res, sd) = scratch.ext[e];
                r[row] = res;
                for &(jq_, c, g) in &scratch.dq {
                    if jq_ == jt {
                        j[(row, c)] += g / sd;
                    }
                }
                sigma[row] = sd;
                sample[row] = i;
            }
            p_all.push(rows.point);
        }
        Ok(DistanceLogLinearisation {
            residuals: r,
            jacobian: j,
            names: self.names(s),
            sigma,
            sample,
            points: p_all,
        })
    }

    /// The parameter names of a linearisation at `s` ([`DistanceLogLinearisation::names`]):
    /// the transmissions', the chain's, the terms'.
    pub fn names(&self, s: &DistanceLogState) -> Vec<String> {
        let mut names: Vec<String> = s
            .transmissions
            .iter()
            .flat_map(LogTransmission::names)
            .collect();
        names.extend(self.chain.params().iter().map(|p| p.name.clone()));
        names.extend(s.terms.iter().map(|(t, _)| t.name.clone()));
        names
    }

    /// Number of rows of a linearisation: one per sample, and one per sample for each
    /// joint of [`Self::ext_joints`].
    pub fn n_rows(&self) -> usize {
        self.log.n_rows() * (1 + self.ext_joints.len())
    }

    /// The distance residuals (model − measured, m, one per sample) at `s`: the distance
    /// rows of [`Self::linearise`] times their σ, without forming the Jacobian's matrix
    /// (memory of one sample's row, whatever the log's length).
    ///
    /// # Errors
    /// As [`Self::linearise`].
    pub fn distance_residuals_m(&self, s: &DistanceLogState) -> Result<Vec<f64>, Error> {
        self.check(s)?;
        let lay = SampleLayout::new(self, s);
        let mut scratch = SampleScratch::new(self, &lay);
        (0..self.log.n_rows())
            .map(|i| {
                let rows = self.sample_rows(s, &lay, i, &mut scratch)?;
                Ok(rows.residual * rows.sigma)
            })
            .collect()
    }

    /// The rows of samples `samples` at `s`, sample by sample (each sample's distance row,
    /// then its external-encoder rows in [`Self::ext_joints`] order): the rows of
    /// [`Self::linearise`] in another order, written into `r_out` (weighted residuals) and
    /// `jac` (weighted Jacobian, `rows × columns` in the column order of
    /// [`Self::linearise`]; cleared first), both of `samples.len() × (1 + ext joints)` rows.
    ///
    /// # Errors
    /// As [`Self::linearise`].
    pub fn linearise_samples(
        &self,
        s: &DistanceLogState,
        samples: std::ops::Range<usize>,
        mut r_out: faer::ColMut<'_, f64>,
        mut jac: Option<faer::MatMut<'_, f64>>,
    ) -> Result<(), Error> {
        self.check(s)?;
        let lay = SampleLayout::new(self, s);
        let mut scratch = SampleScratch::new(self, &lay);
        let per = 1 + self.ext_joints.len();
        if let Some(jac) = jac.as_mut() {
            jac.fill(0.0);
        }
        for (k, i) in samples.enumerate() {
            let rows = self.sample_rows(s, &lay, i, &mut scratch)?;
            let row = k * per;
            r_out[row] = rows.residual;
            if let Some(jac) = jac.as_mut() {
                for (c, v) in scratch.row_j.iter().enumerate() {
                    jac[(row, c)] = v / rows.sigma;
                }
            }
            for (e, &jt) in self.ext_joints.iter().enumerate() {
                let (res, sd) = scratch.ext[e];
                r_out[row + 1 + e] = res;
                if let Some(jac) = jac.as_mut() {
                    for &(jq_, c, g) in &scratch.dq {
                        if jq_ == jt {
                            jac[(row + 1 + e, c)] += g / sd;
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Sample `i`'s rows at `s`: its weighted distance residual, σ and end point; its
    /// unweighted distance Jacobian row in `scratch.row_j`, its external-encoder rows'
    /// weighted residuals and σ in `scratch.ext`, and ∂q/∂(column) in `scratch.dq`.
    fn sample_rows(
        &self,
        s: &DistanceLogState,
        lay: &SampleLayout,
        i: usize,
        scratch: &mut SampleScratch,
    ) -> Result<SampleRows, Error> {
        let data = &self.log;
        let nj = self.chain.n_joints();
        let (n_trans, n_kin, t0) = (lay.n_trans, lay.n_kin, lay.t0);
        let SampleScratch {
            ws,
            buf,
            dq,
            row_j,
            ext,
        } = scratch;
        dq.clear();
        row_j.fill(0.0);
        ext.clear();
        let theta = &data.q[i];
        let mut q = theta.clone();
        // ∂q_joint/∂(column) for the transmissions and joint terms.
        let mut col = 0;
        for tr in &s.transmissions {
            let jt = tr.joint();
            let (out, grad) = tr.eval(theta[jt]);
            q[jt] = out;
            for (k, g) in grad.iter().enumerate() {
                dq.push((jt, col + k, *g));
            }
            col += tr.n_params();
        }
        // Gravity torques at the transmission-corrected angles (small terms: no iteration).
        let torques = if lay.needs_torque {
            handle_gravity_torques_nm(&self.chain, &s.x_kin, &q, self.handle_mass_kg)?
        } else {
            Vec::new()
        };
        for (k, (term, coef)) in s.terms.iter().enumerate() {
            let c = n_trans + n_kin + k;
            let (jt, g) = match &term.kind {
                EffectTermKind::Joint { joint, g } => (*joint, g[i]),
                EffectTermKind::Compliance { joint } => (*joint, torques[*joint]),
                _ => continue,
            };
            q[jt] += coef * g;
            dq.push((jt, c, g));
        }
        let (p, norm, u, d_kin) = distance_and_gradient(&self.chain, &s.x_kin, &q, ws, buf);
        let (jq, dd_dq) = distance_joint_gradient(&self.chain, &s.x_kin, &q, &u);
        // Distance model and its column entries.
        let mut d_model = norm;
        row_j[n_trans..n_trans + n_kin].copy_from_slice(&d_kin);
        for &(jt, c, g) in dq.iter() {
            row_j[c] += dd_dq[jt] * g;
        }
        // A cable-angle term `coef·f(γ)` moves with P: its derivative through γ
        // ([`cable_angle`]'s gradient), `f′ = 1 − cos γ` for `γ − sin γ`, else
        // `−power·cos^(power−1) γ·sin γ`.
        let (gamma, dgamma) = cable_angle(&Point3::from(p));
        let df_dgamma: f64 = (s.terms.iter())
            .filter_map(|(term, coef)| match term.kind {
                EffectTermKind::CableAngle { power: 0 } => Some(coef * (1.0 - gamma.cos())),
                EffectTermKind::CableAngle { power } => {
                    Some(-coef * f64::from(power) * gamma.cos().powi(power - 1) * gamma.sin())
                }
                _ => None,
            })
            .sum();
        let grad_c = dgamma * df_dgamma;
        // A scaled drift `coef·|P|·(t − t₀)` moves with |P|: every column's derivative of
        // the distance, times `Σ coef·(t − t₀)`.
        let t_i = data.t.as_ref().map_or(0.0, |t| t[i]);
        let drift_scale: f64 = (s.terms.iter())
            .filter(|(t, _)| matches!(t.kind, EffectTermKind::ThermalDrift { scale: true }))
            .map(|(_, coef)| coef * (t_i - t0))
            .sum();
        if drift_scale != 0.0 {
            for k in 0..n_kin {
                row_j[n_trans + k] += drift_scale * d_kin[k];
            }
            for &(jt, c, g) in dq.iter() {
                row_j[c] += drift_scale * dd_dq[jt] * g;
            }
        }
        if df_dgamma != 0.0 {
            for k in 0..n_kin {
                row_j[n_trans + k] += along(&grad_c, buf, k);
            }
            for &(jt, c, g) in dq.iter() {
                let jv = Vector3::new(jq[(0, jt)], jq[(1, jt)], jq[(2, jt)]);
                row_j[c] += grad_c.dot(&jv) * g;
            }
        }
        for (k, (term, coef)) in s.terms.iter().enumerate() {
            let c = n_trans + n_kin + k;
            let h = match &term.kind {
                EffectTermKind::Distance { h } => h[i],
                EffectTermKind::Latency => match data.qdot.as_ref() {
                    Some(qd) => (0..nj).map(|jj| dd_dq[jj] * qd[i][jj]).sum(),
                    None => 0.0,
                },
                EffectTermKind::ThermalDrift { scale } => {
                    if *scale {
                        norm * (t_i - t0)
                    } else {
                        t_i - t0
                    }
                }
                EffectTermKind::CableAngle { power } => {
                    if *power == 0 {
                        gamma - gamma.sin()
                    } else {
                        gamma.cos().powi(*power)
                    }
                }
                _ => continue,
            };
            d_model += coef * h;
            row_j[c] += h;
        }
        let mut var = self.noise.sigma_m_m.powi(2);
        if self.quantisation {
            for (dd, res) in dd_dq.iter().zip(&self.noise.resolution_rad) {
                var += (dd * res).powi(2) / 12.0;
            }
        }
        let sd = var.sqrt().max(1e-12);
        // External-encoder rows: modelled joint angle − measured output angle.
        for &jt in &self.ext_joints {
            let res = self.noise.resolution_rad[jt];
            let mut var = self.noise.sigma_e_rad.powi(2);
            if self.quantisation {
                var += res * res / 12.0;
            }
            let sd = var.sqrt().max(1e-15);
            let meas = data.ext[i].get(jt).copied().flatten().unwrap_or(q[jt]);
            ext.push(((q[jt] - meas) / sd, sd));
        }
        Ok(SampleRows {
            residual: (d_model - data.distance_m[i]) / sd,
            sigma: sd,
            point: p,
        })
    }
}

/// The column layout of a linearisation at one state, shared by its samples.
struct SampleLayout {
    n_trans: usize,
    n_kin: usize,
    ncols: usize,
    /// The log's first time, s (0 without times).
    t0: f64,
    /// Whether a compliance term needs the gravity torques.
    needs_torque: bool,
}

impl SampleLayout {
    fn new(model: &DistanceLogModel, s: &DistanceLogState) -> Self {
        let n_trans: usize = s.transmissions.iter().map(LogTransmission::n_params).sum();
        let n_kin = model.chain.n_params();
        let t0 = (model.log.t.as_ref())
            .and_then(|t| t.first().copied())
            .unwrap_or(0.0);
        let needs_torque = s
            .terms
            .iter()
            .any(|(t, _)| matches!(t.kind, EffectTermKind::Compliance { .. }));
        Self {
            n_trans,
            n_kin,
            ncols: n_trans + n_kin + s.terms.len(),
            t0,
            needs_torque,
        }
    }
}

/// The buffers of one sample's rows, reused from sample to sample.
struct SampleScratch {
    ws: FkWorkspace,
    buf: Vec<f64>,
    /// ∂q_joint/∂(column): (joint, column, derivative).
    dq: Vec<(usize, usize, f64)>,
    /// The distance row's Jacobian, unweighted.
    row_j: Vec<f64>,
    /// Each external-encoder row's weighted residual and σ.
    ext: Vec<(f64, f64)>,
}

impl SampleScratch {
    fn new(model: &DistanceLogModel, lay: &SampleLayout) -> Self {
        Self {
            ws: FkWorkspace::new(&model.chain),
            buf: vec![0.0; 3 * lay.n_kin],
            dq: Vec::new(),
            row_j: vec![0.0; lay.ncols],
            ext: Vec::new(),
        }
    }
}

/// One sample's distance row ([`DistanceLogModel::sample_rows`]).
struct SampleRows {
    /// Weighted residual `(model − measured)/σ`.
    residual: f64,
    /// σ, m.
    sigma: f64,
    /// The end point in the rig frame, m.
    point: Vector3<f64>,
}

#[cfg(test)]
mod tests;
