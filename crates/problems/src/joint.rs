//! Both steps of the paper's procedure (Fig. 6) in one problem: the external-encoder residuals
//! of every transmission and the cable-distance residuals of the corrected chain, sharing the
//! transmission parameters (docs/design.md, "Identification": one joint identification).

use faer::{Col, ColMut, ColRef, MatMut};
use hapcal_identify::{EvalError, ParamLayout, Problem, Unit};
use hapcal_kinematics::{Chain, FkWorkspace, ParamUnit};
use hapcal_transmission::{Capstan, CapstanParams, Chebyshev, Error as TransmissionError};

use crate::Error;
use crate::distance_log::{LogTransmission, distance_and_gradient, distance_joint_gradient};
use crate::transmission::{CAPSTAN_PARAMS, CapstanProblem, capstan_param, chebyshev_param, spec};

/// The transmissions of a [`JointProblem`]: capstan drives (paper eq. 1) on some joints and one
/// joint whose transmission error is a Chebyshev polynomial of its reading (the paper's
/// joint 4, capstan + parallelogram, tenth order).
///
/// Source: paper eq. 1, Table 2 and the parallelogram section; docs/design.md, "Capstan drive
/// (paper eq. 1)" and "Parallelogram (paper eq. 2) and the joint-4 polynomial".
#[derive(Clone, Debug)]
pub struct JointTransmissions {
    /// Capstan drives in layout order: `(joint, geometry)`, the joint 1-based (the paper's
    /// joints 1–3).
    pub capstans: Vec<(usize, Capstan)>,
    /// The joint (1-based) whose error is the polynomial (the paper's joint 4).
    pub poly_joint: usize,
    /// Degree of the polynomial (the paper's 10).
    pub poly_degree: usize,
    /// Lower end of the polynomial's domain, rad (the joint's lower limit).
    pub poly_lo_rad: f64,
    /// Upper end of the polynomial's domain, rad (the joint's upper limit).
    pub poly_hi_rad: f64,
}

/// The measurements of a [`JointProblem`], `n_rows` rows.
#[derive(Clone, Debug, Default)]
pub struct JointData {
    /// Joint readings (motor angle / ratio), rad: `n_rows` rows of `chain.n_joints()` angles.
    pub q: Vec<Vec<f64>>,
    /// External-encoder output angles, rad: one column per transmission, the capstans in
    /// [`JointTransmissions::capstans`]' order, then the polynomial joint's (`n_caps + 1`
    /// columns of `n_rows`).
    pub ext: Vec<Vec<f64>>,
    /// Cable-encoder distances from the rig origin to the end point, m (`n_rows`).
    pub distance_m: Vec<f64>,
}

/// Both steps of the paper's calibration in one least-squares problem (docs/design.md,
/// "Identification": one joint identification): the external-encoder residuals of every transmission and the
/// cable-distance residuals of the corrected chain share the transmission parameters, so the
/// transmission uncertainty reaches the kinematic covariance.
///
/// Parameters (all [`Role::Model`](hapcal_identify::Role::Model)),
/// `x = [capstans (6 each, `capstan{j}.c` rad, `.re` 1, `.r_o` m, `.beta_o` rad, `.r_i` m,
/// `.beta_i` rad, as [`CapstanProblem`]) | polynomial (`joint{j}.cheb0..cheb{degree}`, rad) |
/// kinematic deviations (the chain's parameters, m or rad)]`; the first
/// [`JointProblem::n_trans`] are the transmissions'.
///
/// Residuals (dimensionless, `(n_caps + 2)·n_rows`), in blocks of `n_rows`: for each capstan
/// `c` on joint `j`, `(θ_j + Δθ_c(θ_j) − ext_c)/σ_ext` (paper eq. 1); for the polynomial joint
/// `j`, `(θ_j + p(θ_j) − ext)/σ_ext`; then, from [`JointProblem::distance_offset`], the cable
/// distances `(|P(x_kin, q)| − δ)/σ_distance` (paper eq. 5) with `q` the readings corrected by
/// the transmissions. The Jacobian is analytic, including the distance rows' dependence on the
/// transmission parameters through the corrected angles.
///
/// Source: Baser & Konukseven, Fig. 6 (steps 1 and 2), eqs. 1 and 5; docs/design.md,
/// "Identification".
#[derive(Clone, Debug)]
pub struct JointProblem {
    chain: Chain,
    capstans: Vec<(usize, Capstan)>,
    poly_joint: usize,
    degree: usize,
    lo: f64,
    hi: f64,
    theta: Vec<Vec<f64>>,
    ext: Vec<Vec<f64>>,
    distance_m: Vec<f64>,
    /// Standard deviation of the external-encoder residuals, rad (> 0; may be rescaled between
    /// fits).
    pub sigma_ext_rad: f64,
    /// Standard deviation of the distance residuals, m (> 0; may be rescaled between fits).
    pub sigma_distance_m: f64,
    layout: ParamLayout,
}

impl JointProblem {
    /// The joint problem of `chain` (nominal chain, rig → end point) with `transmissions`, on
    /// `data`, with external-encoder noise `sigma_ext_rad` (rad, the paper's σ_e) and
    /// cable-encoder noise `sigma_distance_m` (m, the paper's σ_m).
    ///
    /// # Errors
    /// [`Error::JointCount`] for a reading of the wrong length; [`Error::NoSuchJoint`] for a
    /// transmission joint outside the chain; [`Error::LengthMismatch`] for a number of ext
    /// columns other than `n_caps + 1`, or a column or the distances not of `n_rows`;
    /// [`Error::NotFinite`] for a non-finite reading, ext angle or distance; [`Error::BadSigma`]
    /// for a sigma that is not positive and finite; [`Error::Transmission`] for a polynomial
    /// domain that is not finite with `lo < hi`.
    pub fn new(
        chain: Chain,
        transmissions: JointTransmissions,
        data: JointData,
        sigma_ext_rad: f64,
        sigma_distance_m: f64,
    ) -> Result<Self, Error> {
        let JointTransmissions {
            capstans,
            poly_joint,
            poly_degree: degree,
            poly_lo_rad: lo,
            poly_hi_rad: hi,
        } = transmissions;
        let JointData {
            q: theta,
            ext,
            distance_m,
        } = data;
        for (name, value) in [
            ("sigma_ext_rad", sigma_ext_rad),
            ("sigma_distance_m", sigma_distance_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::BadSigma { name, value });
            }
        }
        Chebyshev::try_new(lo, hi, vec![0.0; degree + 1])?;
        let n_joints = chain.n_joints();
        for joint in (capstans.iter().map(|(j, _)| *j)).chain(std::iter::once(poly_joint)) {
            if joint == 0 || joint > n_joints {
                return Err(Error::NoSuchJoint { joint, n_joints });
            }
        }
        let n_rows = theta.len();
        let mismatch = |name, expected, found| {
            (expected != found).then_some(Error::LengthMismatch {
                name,
                expected,
                found,
            })
        };
        let lengths = std::iter::once(mismatch("ext", capstans.len() + 1, ext.len()))
            .chain(
                ext.iter()
                    .map(|col| mismatch("ext column", n_rows, col.len())),
            )
            .chain(std::iter::once(mismatch(
                "distance_m",
                n_rows,
                distance_m.len(),
            )));
        if let Some(err) = lengths.flatten().next() {
            return Err(err);
        }
        for (row, q) in theta.iter().enumerate() {
            Error::check_joint_count(row, n_joints, q.len())?;
            let finite = q
                .iter()
                .chain(ext.iter().map(|col| &col[row]))
                .all(|v| v.is_finite())
                && distance_m[row].is_finite();
            if !finite {
                return Err(Error::NotFinite { row });
            }
        }
        let mut specs = Vec::new();
        for (joint, _) in &capstans {
            for (n, unit) in CAPSTAN_PARAMS {
                specs.push(spec(capstan_param(*joint, n), unit));
            }
        }
        for k in 0..=degree {
            specs.push(spec(chebyshev_param(poly_joint, k), Unit::Radian));
        }
        for p in chain.params() {
            let unit = match p.unit {
                ParamUnit::Meter => Unit::Meter,
                ParamUnit::Radian => Unit::Radian,
            };
            specs.push(spec(p.name.clone(), unit));
        }
        Ok(Self {
            chain,
            capstans,
            poly_joint,
            degree,
            lo,
            hi,
            theta,
            ext,
            distance_m,
            sigma_ext_rad,
            sigma_distance_m,
            layout: ParamLayout::new(specs),
        })
    }

    /// Number of transmission parameters, the first entries of `x`: `6·n_caps + degree + 1`.
    pub fn n_trans(&self) -> usize {
        6 * self.capstans.len() + self.degree + 1
    }

    /// Index of the first distance residual, `(n_caps + 1)·n_rows` (the external-encoder
    /// residuals come first).
    pub fn distance_offset(&self) -> usize {
        (self.capstans.len() + 1) * self.theta.len()
    }

    /// The transmissions that `x` describes: each capstan's eq. 1 parameters (layout order) and
    /// the polynomial (Chebyshev coefficients, rad, on the joint's domain).
    ///
    /// # Errors
    /// [`TransmissionError::NotFinite`] for a non-finite polynomial coefficient.
    ///
    /// # Panics
    /// If `x` is shorter than [`JointProblem::n_trans`].
    pub fn transmissions(
        &self,
        x: ColRef<'_, f64>,
    ) -> Result<(Vec<CapstanParams>, Chebyshev), TransmissionError> {
        let caps = (0..self.capstans.len())
            .map(|c| CapstanProblem::params(x.subrows(6 * c, 6)))
            .collect();
        let off = 6 * self.capstans.len();
        let poly = Chebyshev::try_new(
            self.lo,
            self.hi,
            (0..=self.degree).map(|k| x[off + k]).collect(),
        )?;
        Ok((caps, poly))
    }

    /// A start vector (length `layout().len()`): the capstans' parameters `capstans` (one per
    /// capstan, layout order), the polynomial's Chebyshev coefficients `poly_coeffs` (rad, at
    /// most `degree + 1`, missing ones 0) and the kinematic deviations `x_kin` (m, rad; at least
    /// `chain.n_params()` entries, the first used) — typically the two-step solution.
    ///
    /// # Panics
    /// On more capstans or coefficients than the problem has, or a short `x_kin`.
    pub fn start(
        &self,
        capstans: &[CapstanParams],
        poly_coeffs: &[f64],
        x_kin: ColRef<'_, f64>,
    ) -> Col<f64> {
        let mut x = Col::zeros(self.layout.len());
        for (c, params) in capstans.iter().enumerate() {
            x.subrows_mut(6 * c, 6)
                .copy_from(CapstanProblem::col(params));
        }
        let off = 6 * self.capstans.len();
        for (k, v) in poly_coeffs.iter().enumerate() {
            x[off + k] = *v;
        }
        for i in 0..self.chain.n_params() {
            x[self.n_trans() + i] = x_kin[i];
        }
        x
    }

    fn eval(
        &self,
        x: ColRef<'_, f64>,
        mut out: Option<ColMut<'_, f64>>,
        mut jac: Option<MatMut<'_, f64>>,
    ) -> Result<(), EvalError> {
        let bad = |e: &dyn std::fmt::Display| EvalError {
            reason: e.to_string(),
        };
        let (caps, poly) = self.transmissions(x).map_err(|e| bad(&e))?;
        let nt = self.n_trans();
        let n_kin = self.chain.n_params();
        let x_kin: Vec<f64> = (0..n_kin).map(|i| x[nt + i]).collect();
        let n_rows = self.theta.len();
        if let Some(j) = jac.as_mut() {
            j.fill(0.0);
        }
        // The transmissions as the distance-log model holds them: the same eq. 1 and
        // polynomial evaluation, the capstans first.
        let trans: Vec<LogTransmission> = (self.capstans.iter().zip(caps))
            .map(|((joint, capstan), params)| LogTransmission::Capstan {
                joint: joint - 1,
                capstan: *capstan,
                params,
            })
            .chain(std::iter::once(LogTransmission::Polynomial {
                joint: self.poly_joint - 1,
                poly,
            }))
            .collect();
        let n_ext = trans.len();
        let mut buf = vec![0.0; 3 * n_kin];
        let mut ws = FkWorkspace::new(&self.chain);
        for k in 0..n_rows {
            let theta = &self.theta[k];
            let mut q = theta.clone();
            // dq_j/d(transmission parameter) for the corrected joints.
            let mut dq: Vec<(usize, usize, f64)> = Vec::new();
            let mut col = 0;
            for (c, tr) in trans.iter().enumerate() {
                let jt = tr.joint();
                let (out_angle, grad) = tr.eval(theta[jt]);
                q[jt] = out_angle;
                let row = c * n_rows + k;
                if let Some(o) = out.as_mut() {
                    o[row] = (q[jt] - self.ext[c][k]) / self.sigma_ext_rad;
                }
                for (p, gp) in grad.iter().enumerate() {
                    dq.push((jt, col + p, *gp));
                    if let Some(jm) = jac.as_mut() {
                        jm[(row, col + p)] = gp / self.sigma_ext_rad;
                    }
                }
                col += tr.n_params();
            }
            let drow = n_ext * n_rows + k;
            if let Some(jm) = jac.as_mut() {
                let (_, norm, u, d_kin) =
                    distance_and_gradient(&self.chain, &x_kin, &q, &mut ws, &mut buf);
                if let Some(o) = out.as_mut() {
                    o[drow] = (norm - self.distance_m[k]) / self.sigma_distance_m;
                }
                for (i, d) in d_kin.iter().enumerate() {
                    jm[(drow, nt + i)] = d / self.sigma_distance_m;
                }
                let (_, dd_dq) = distance_joint_gradient(&self.chain, &x_kin, &q, &u);
                for (joint, col, dqdp) in dq {
                    jm[(drow, col)] += dd_dq[joint] * dqdp / self.sigma_distance_m;
                }
            } else if let Some(o) = out.as_mut() {
                let p = self.chain.end_point(&x_kin, &q);
                let (norm, _) = crate::problem::length_and_direction(&p.coords);
                o[drow] = (norm - self.distance_m[k]) / self.sigma_distance_m;
            }
        }
        Ok(())
    }
}

impl Problem for JointProblem {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        (self.capstans.len() + 2) * self.theta.len()
    }
    fn residuals(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) -> Result<(), EvalError> {
        self.eval(x, Some(out), None)
    }
    fn jacobian(&self, x: ColRef<'_, f64>, jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.eval(x, None, Some(jac))
    }
}

#[cfg(test)]
mod tests;
