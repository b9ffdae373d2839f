//! The paper's pipeline on the simulated reference device (Baser & Konukseven, Fig. 6):
//! step 1 identifies each transmission from external-encoder data, step 2 corrects the joint
//! readings and identifies the kinematic deviations from cable distances; validation on fresh
//! poses (Fig. 8) and a Monte Carlo over seeds.

use anyhow::{Context, Result};
use hapcal_identify::Identified;
use hapcal_metrics::{pose_error, rms};
use hapcal_sim::{SimConfig, Truth};
use rand::SeedableRng;
use std::path::Path;

pub use hapcal_calibrate::haptic::*;

/// The simulated reference device: the haptic device of its device file, and its truth.
///
/// Dereferences to the [`HapticDevice`], so the calibration steps take it as they take a real
/// device (they never read the truth).
#[derive(Clone, Debug)]
pub struct Reference {
    /// The device as the calibration sees it.
    pub haptic: HapticDevice,
    /// Truth (deviations and transmission parameters).
    pub truth: Truth,
    /// Truth deviation vector of `haptic.chain`.
    pub x_truth: Vec<f64>,
}

impl std::ops::Deref for Reference {
    type Target = HapticDevice;
    fn deref(&self) -> &HapticDevice {
        &self.haptic
    }
}

impl std::ops::DerefMut for Reference {
    fn deref_mut(&mut self) -> &mut HapticDevice {
        &mut self.haptic
    }
}

impl Reference {
    /// Reads the truth file and the device file it names.
    ///
    /// # Errors
    /// Unreadable or inconsistent files.
    pub fn load(truth_path: &Path) -> Result<Self> {
        let truth = hapcal_sim::read_truth(truth_path)
            .with_context(|| format!("reading truth {}", truth_path.display()))?;
        let device = truth.read_device(truth_path)?;
        let haptic = HapticDevice::new(device)?;
        let x_truth = hapcal_sim::truth_deviations(&haptic.chain, &truth)?;
        Ok(Self {
            haptic,
            truth,
            x_truth,
        })
    }
}

/// Accuracy on fresh poses (paper Fig. 8 and the distance RMS of eq. 9).
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Validation {
    /// End-effector position RMS in the base frame, nominal model, m.
    pub position_rms_before_m: f64,
    /// Same, calibrated model, m.
    pub position_rms_after_m: f64,
    /// Orientation RMS (angle of the relative rotation), nominal model, rad.
    pub orientation_rms_before_rad: f64,
    /// Same, calibrated model, rad.
    pub orientation_rms_after_rad: f64,
    /// Orientation RMS of the calibrated model once the unidentifiable parameters (α7 in the
    /// base frame) take their true values: what they alone leave, rad.
    pub orientation_rms_after_true_unidentifiable_rad: f64,
    /// Cable-distance RMS, nominal model, m.
    pub distance_rms_before_m: f64,
    /// Cable-distance RMS, full calibration (transmissions + kinematics), m.
    pub distance_rms_after_m: f64,
    /// Cable-distance RMS, kinematics calibrated on raw readings (transmissions left out), m.
    pub distance_rms_kinematics_only_m: f64,
}

/// Everything one seed produced.
#[derive(Clone, Debug)]
pub struct SeedResult {
    /// Step 1.
    pub transmissions: TransmissionFit,
    /// Step 2 (full calibration).
    pub kinematics: Identified,
    /// Step 2 without transmissions.
    pub kinematics_only: Identified,
    /// Joint identification of both steps; kinematic parameters start at `joint_offset`.
    pub joint: Identified,
    /// Index of the first kinematic parameter in `joint`'s layout.
    pub joint_offset: usize,
    /// Fresh-pose accuracy.
    pub validation: Validation,
    /// Per fresh pose: position error before/after (m), orientation error before/after (rad).
    pub pose_errors: [Vec<f64>; 4],
}

/// Selects `n_select` of the candidate joint readings (rad, one `Vec` per candidate) of the
/// reference device; returns their indices.
pub type PoseSelector<'a> =
    dyn Fn(&Reference, &[Vec<f64>], usize) -> Result<Vec<usize>> + Sync + 'a;

/// How the identification poses of one seed are chosen.
pub enum PoseChoice<'a> {
    /// `n_poses` poses uniform in the joint limits: the paper's "200 random pose
    /// measurements".
    Random,
    /// `n_poses` of `n_candidates` random poses, chosen by `select` from their joint readings
    /// alone (as a planner does before measuring; the measurements of the others are discarded).
    Planned {
        /// Candidate poses drawn per seed.
        n_candidates: usize,
        /// Name of the design, for reports (`d-optimal`).
        name: String,
        /// The selection.
        select: &'a PoseSelector<'a>,
    },
}

/// Runs the pipeline for one seed: simulate `n_poses` (seed) with the identification poses
/// chosen by `choice`, identify, validate on `n_poses` fresh poses (seed + 1_000_000).
///
/// # Errors
/// Simulation, selection or identification failures.
pub fn run_seed_with(
    r: &Reference,
    seed: u64,
    n_poses: usize,
    choice: &PoseChoice<'_>,
) -> Result<SeedResult> {
    let rows = match choice {
        PoseChoice::Random => {
            let cfg = SimConfig::new(seed, n_poses).with_noise(r.noise);
            hapcal_sim::simulate(&r.device, &r.truth, &cfg)?
        }
        PoseChoice::Planned {
            n_candidates,
            select,
            ..
        } => {
            let cfg = SimConfig::new(seed, *n_candidates).with_noise(r.noise);
            let candidates = hapcal_sim::simulate(&r.device, &r.truth, &cfg)?;
            let readings: Vec<Vec<f64>> = candidates.iter().map(|row| row.q.clone()).collect();
            let chosen = select(r, &readings, n_poses)?;
            chosen
                .iter()
                .map(|&i| {
                    candidates.get(i).cloned().with_context(|| {
                        format!("pose selection returned {i} of {n_candidates} candidates")
                    })
                })
                .collect::<Result<Vec<_>>>()?
        }
    };
    let transmissions = identify_transmissions(r, &rows)?;
    let (_, mut kinematics) = identify_kinematics(r, &rows, Some(&transmissions))?;
    kinematics.covariance.matrix =
        propagate_transmission_covariance(r, &rows, &transmissions, &kinematics)?;
    let (_, kinematics_only) = identify_kinematics(r, &rows, None)?;
    let (validation, pose_errors) = validate(
        r,
        seed + 1_000_000,
        n_poses,
        &transmissions,
        &kinematics,
        &kinematics_only,
    )?;
    let (joint_problem, joint) = identify_jointly(r, &rows, &transmissions, &kinematics)?;
    let joint_offset = joint_problem.n_trans();
    Ok(SeedResult {
        transmissions,
        kinematics,
        kinematics_only,
        joint,
        joint_offset,
        validation,
        pose_errors,
    })
}

fn x_of(id: &Identified, n: usize) -> Vec<f64> {
    (0..n).map(|i| id.fit.x[i]).collect()
}

/// Validation on fresh poses drawn with `seed`.
///
/// # Errors
/// Simulation failures.
pub fn validate(
    r: &Reference,
    seed: u64,
    n_poses: usize,
    t: &TransmissionFit,
    kin: &Identified,
    kin_only: &Identified,
) -> Result<(Validation, [Vec<f64>; 4])> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let readings = hapcal_sim::sample_readings(&r.device, &mut rng, n_poses);
    let n = r.chain.n_params();
    let x_cal = x_of(kin, n);
    let x_only = x_of(kin_only, n);
    let zero = vec![0.0; n];
    let (xb_truth, xb_cal, xb_zero) = (r.base_x(&r.x_truth), r.base_x(&x_cal), r.base_x(&zero));
    // The calibrated model with the parameters the data cannot see set to their truth.
    let mut x_cal_true_unid = x_cal.clone();
    for pruned in &kin.identifiability.pruned {
        if pruned.index < n {
            x_cal_true_unid[pruned.index] = r.x_truth[pruned.index];
        }
    }
    let xb_cal_true_unid = r.base_x(&x_cal_true_unid);
    let (mut pb, mut pa, mut ob, mut oa, mut oau, mut db, mut da, mut dk) = (
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
    );
    for theta in &readings {
        let theta = hapcal_sim::quantise_readings(&r.device, theta);
        let q_true = hapcal_sim::true_joint_angles(&r.device, &r.truth, &theta)?;
        let q_cor = t.corrected(&theta);
        let truth = r.base_chain.end_pose(&xb_truth, &q_true);
        let before = pose_error(&truth, &r.base_chain.end_pose(&xb_zero, &theta));
        let after = pose_error(&truth, &r.base_chain.end_pose(&xb_cal, &q_cor));
        let after_u = pose_error(&truth, &r.base_chain.end_pose(&xb_cal_true_unid, &q_cor));
        pb.push(before.position_m);
        pa.push(after.position_m);
        ob.push(before.orientation_rad);
        oa.push(after.orientation_rad);
        oau.push(after_u.orientation_rad);
        let d_true = r.chain.end_point(&r.x_truth, &q_true).coords.norm();
        db.push(r.chain.end_point(&zero, &theta).coords.norm() - d_true);
        da.push(r.chain.end_point(&x_cal, &q_cor).coords.norm() - d_true);
        dk.push(r.chain.end_point(&x_only, &theta).coords.norm() - d_true);
    }
    let v = Validation {
        position_rms_before_m: rms(&pb),
        position_rms_after_m: rms(&pa),
        orientation_rms_before_rad: rms(&ob),
        orientation_rms_after_rad: rms(&oa),
        orientation_rms_after_true_unidentifiable_rad: rms(&oau),
        distance_rms_before_m: rms(&db),
        distance_rms_after_m: rms(&da),
        distance_rms_kinematics_only_m: rms(&dk),
    };
    Ok((v, [pb, pa, ob, oa]))
}

/// A kinematic parameter's outcome in one seed.
#[derive(Clone, Debug)]
pub struct ParamOutcome {
    /// Name (`da0`, `dtheta3`, …).
    pub name: String,
    /// Assigned (truth) deviation.
    pub assigned: f64,
    /// Identified deviation, `None` when pruned.
    pub identified: Option<f64>,
    /// Its standard deviation.
    pub std: Option<f64>,
}

/// Per-parameter outcomes of step 2 in one seed.
pub fn kinematic_outcomes(r: &Reference, kin: &Identified) -> Vec<ParamOutcome> {
    kinematic_outcomes_at(r, kin, 0)
}

/// Per-parameter outcomes of an identification whose kinematic parameters start at `offset`.
pub fn kinematic_outcomes_at(r: &Reference, kin: &Identified, offset: usize) -> Vec<ParamOutcome> {
    let stds = kin.covariance.std();
    r.chain
        .params()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let pos = kin.covariance.free.iter().position(|&f| f == offset + i);
            ParamOutcome {
                name: p.name.clone(),
                assigned: r.x_truth[i],
                identified: pos.map(|_| kin.fit.x[offset + i]),
                std: pos.map(|k| stds[k]),
            }
        })
        .collect()
}
