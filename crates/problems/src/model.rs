//! A calibrated model: the chain with identified deviations and compliance.

use crate::{GravityCompliance, JointHarmonics, TransversalTerm};
use hapcal_kinematics::{Chain, Isometry3, Point3};

/// A chain plus identified parameter deviations, ready to predict end points.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibratedModel {
    /// The nominal chain (the first tip's).
    pub chain: Chain,
    /// The chain of every tip of a tree ([`crate::CalibrationProblem::on_tree`]); empty for
    /// one chain.
    pub tips: Vec<Chain>,
    /// The tips whose base frame gravity is expressed in, for the compliance loads (the robot
    /// without an instrument frame, every branch of its tree); empty: `[chain]`.
    pub torque_tips: Vec<Chain>,
    /// Kinematic deviations (length `chain.n_params()`, m or rad; zeros = nominal).
    pub x_kin: Vec<f64>,
    /// Compliance model and its `k_j` (length `n_joints`, rad/m), if modelled.
    pub compliance: Option<(GravityCompliance, Vec<f64>)>,
    /// Joint harmonic model and its coefficients (length [`JointHarmonics::n_params`], rad),
    /// if modelled.
    pub harmonics: Option<(JointHarmonics, Vec<f64>)>,
    /// Transversal compliance of each joint that has it, with its identified value (loads
    /// from [`Self::compliance`]'s model); empty without.
    pub transversal: Vec<TransversalTerm>,
}

impl CalibratedModel {
    /// The nominal model of `chain` (no deviation, no compliance).
    pub fn nominal(chain: Chain) -> Self {
        let x_kin = vec![0.0; chain.n_params()];
        Self {
            chain,
            tips: Vec::new(),
            torque_tips: Vec::new(),
            x_kin,
            compliance: None,
            harmonics: None,
            transversal: Vec::new(),
        }
    }

    /// Joint angles the chain actually takes for readings `q` (rad): `q + k∘τ̂(q)` plus the
    /// harmonic corrections ([`JointHarmonics::corrections`]).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn effective_angles(&self, q: &[f64]) -> Vec<f64> {
        let mut out = self.compliant_angles(q);
        if let Some((h, coef)) = &self.harmonics {
            for (o, c) in out.iter_mut().zip(h.corrections(q, coef)) {
                *o += c;
            }
        }
        out
    }

    fn torque_tips(&self) -> &[Chain] {
        if self.torque_tips.is_empty() {
            std::slice::from_ref(&self.chain)
        } else {
            &self.torque_tips
        }
    }

    fn compliant_angles(&self, q: &[f64]) -> Vec<f64> {
        match &self.compliance {
            None => q.to_vec(),
            Some((model, k)) => {
                let loads = model.joint_loads(self.torque_tips(), q);
                q.iter()
                    .zip(k)
                    .zip(&loads)
                    .map(|((q, k), l)| q + k * l.torque)
                    .collect()
            }
        }
    }

    /// Kinematic deviations for readings `q`: [`Self::x_kin`] with the transversal tilts
    /// added to their joints' rotation deviations ([`TransversalTerm`]).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn effective_deviations(&self, q: &[f64]) -> std::borrow::Cow<'_, [f64]> {
        let Some((model, _)) = self
            .compliance
            .as_ref()
            .filter(|_| !self.transversal.is_empty())
        else {
            return std::borrow::Cow::Borrowed(&self.x_kin);
        };
        let loads = model.joint_loads(self.torque_tips(), q);
        let mut x = self.x_kin.clone();
        for t in &self.transversal {
            let v = loads[t.joint].transversal;
            for (&i, v) in t.rotation_params.iter().zip(v.iter()) {
                x[i] += t.compliance * v;
            }
        }
        std::borrow::Cow::Owned(x)
    }

    /// How far one more fixed-point step of the torque equilibrium would move the tips, m:
    /// the model deflects the joints under the gravity loads of the *undeflected* robot
    /// (`q + k∘τ(q)`); the loads of the deflected robot, `τ(q + k∘τ(q))`, give the next
    /// iterate of `θ = q + k∘τ(θ)`. The largest tip displacement between the two (every tip,
    /// axial and transversal compliance), 0 without compliance. Small against the noise, the
    /// equilibrium needs no iteration.
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn equilibrium_step_m(&self, q: &[f64]) -> f64 {
        let Some((model, k)) = &self.compliance else {
            return 0.0;
        };
        let harmonic = |angles: &mut Vec<f64>| {
            if let Some((h, coef)) = &self.harmonics {
                for (o, c) in angles.iter_mut().zip(h.corrections(q, coef)) {
                    *o += c;
                }
            }
        };
        let step = |loads: &[crate::JointLoad]| {
            let mut angles: Vec<f64> = (q.iter().zip(k).zip(loads))
                .map(|((q, k), l)| q + k * l.torque)
                .collect();
            harmonic(&mut angles);
            let mut x = self.x_kin.clone();
            for t in &self.transversal {
                let v = loads[t.joint].transversal;
                for (&i, v) in t.rotation_params.iter().zip(v.iter()) {
                    x[i] += t.compliance * v;
                }
            }
            (x, angles)
        };
        let first = model.joint_loads(self.torque_tips(), q);
        let deflected: Vec<f64> = (q.iter().zip(k).zip(&first))
            .map(|((q, k), l)| q + k * l.torque)
            .collect();
        let second = model.joint_loads(self.torque_tips(), &deflected);
        let (x1, q1) = step(&first);
        let (x2, q2) = step(&second);
        let tips: Vec<&Chain> = if self.tips.is_empty() {
            vec![&self.chain]
        } else {
            self.tips.iter().collect()
        };
        (tips.iter())
            .map(|c| (c.end_point(&x1, &q1) - c.end_point(&x2, &q2)).norm())
            .fold(0.0, f64::max)
    }

    /// End point (m, base frame) for joint readings `q` (rad).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn end_point(&self, q: &[f64]) -> Point3<f64> {
        self.chain
            .end_point(&self.effective_deviations(q), &self.effective_angles(q))
    }

    /// Pose of tip `tip`'s frame (m; in the instrument frame for a tree with frames) for
    /// joint readings `q` (rad or m); tip 0 is [`Self::chain`].
    ///
    /// # Panics
    /// If `tip` is not a tip of the model or `q.len()` differs from the joint count.
    #[track_caller]
    pub fn end_pose_of(&self, tip: usize, q: &[f64]) -> Isometry3<f64> {
        let chain = if self.tips.is_empty() && tip == 0 {
            &self.chain
        } else {
            &self.tips[tip]
        };
        chain.end_pose(&self.effective_deviations(q), &self.effective_angles(q))
    }
}
