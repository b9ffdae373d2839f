//! A calibrated model: the chain with identified deviations and compliance.

use crate::{GravityCompliance, JointHarmonics};
use hapcal_kinematics::{Chain, Isometry3, Point3};

/// A chain plus identified parameter deviations, ready to predict end points.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibratedModel {
    /// The nominal chain (the first tip's).
    pub chain: Chain,
    /// The chain of every tip of a tree ([`crate::CalibrationProblem::on_tree`]); empty for
    /// one chain.
    pub tips: Vec<Chain>,
    /// The chain whose base frame gravity is expressed in (the robot without an instrument
    /// frame), if not `chain`.
    pub torque_chain: Option<Chain>,
    /// Kinematic deviations (length `chain.n_params()`, m or rad; zeros = nominal).
    pub x_kin: Vec<f64>,
    /// Compliance model and its `k_j` (length `n_joints`, rad/m), if modelled.
    pub compliance: Option<(GravityCompliance, Vec<f64>)>,
    /// Joint harmonic model and its coefficients (length [`JointHarmonics::n_params`], rad),
    /// if modelled.
    pub harmonics: Option<(JointHarmonics, Vec<f64>)>,
}

impl CalibratedModel {
    /// The nominal model of `chain` (no deviation, no compliance).
    pub fn nominal(chain: Chain) -> Self {
        let x_kin = vec![0.0; chain.n_params()];
        Self {
            chain,
            tips: Vec::new(),
            torque_chain: None,
            x_kin,
            compliance: None,
            harmonics: None,
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

    fn compliant_angles(&self, q: &[f64]) -> Vec<f64> {
        match &self.compliance {
            None => q.to_vec(),
            Some((model, k)) => {
                let tau =
                    model.lumped_torques(self.torque_chain.as_ref().unwrap_or(&self.chain), q);
                q.iter()
                    .zip(k)
                    .zip(&tau)
                    .map(|((q, k), t)| q + k * t)
                    .collect()
            }
        }
    }

    /// End point (m, base frame) for joint readings `q` (rad).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn end_point(&self, q: &[f64]) -> Point3<f64> {
        self.chain.end_point(&self.x_kin, &self.effective_angles(q))
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
        chain.end_pose(&self.x_kin, &self.effective_angles(q))
    }
}
