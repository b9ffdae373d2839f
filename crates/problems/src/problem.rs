//! The calibration problem: residuals and analytic Jacobian over kinematic deviations,
//! optional compliance, and unknown points.

use crate::{CalibratedModel, Error, GravityCompliance, JointHarmonics};
use faer::{Col, ColMut, ColRef, Mat, MatMut};
use hapcal_contract::ValueName;
use hapcal_identify::{EvalError, ParamLayout, ParamSpec, Problem, Role, RowBlocks, Unit};
use hapcal_kinematics::{
    Chain, FkWorkspace, FrozenChain, LANES, ParamUnit, Point3, UnitQuaternion, Vector3, joint_trig,
    joint_trig_lanes,
};
use nalgebra::{Isometry3, Quaternion};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::{Arc, Mutex};

mod blocks;
mod build;
use blocks::*;
pub(crate) use blocks::{along, length_and_direction};
use build::*;

/// What one configuration measured.
#[derive(Clone, Debug, PartialEq)]
pub enum RowKind {
    /// Distance from the chain's base origin to the end point, m (cable encoder, paper eq. 5).
    Distance {
        /// Measured distance δ, m.
        distance_m: f64,
    },
    /// End point position in the base (rig) frame, m (tracker).
    Position {
        /// Measured position, m.
        position_m: [f64; 3],
    },
    /// The end point is at unknown point `point` (a socket); 3 residuals.
    Point {
        /// Index of the unknown point, `0..n_points`.
        point: usize,
    },
    /// Origin of tip `tip`'s frame measured in the instrument frame, m (a laser tracker's
    /// or motion capture's marker; the tip chain carries the instrument and marker frames,
    /// [`hapcal_kinematics::Tree::with_frames`]); 3 residuals `(p − p_meas)/σ_position`.
    Marker {
        /// Index into the problem's tips ([`CalibrationProblem::on_tree`]).
        tip: usize,
        /// Measured position, m.
        position_m: [f64; 3],
    },
    /// Pose of tip `tip`'s frame measured in the instrument frame (a camera seeing a target);
    /// 6 residuals: `(p − p_meas)/σ_position` and `log(R_measᵀ·R)/σ_orientation` (the
    /// rotation vector of the relative rotation, tip frame, rad).
    Pose {
        /// Index into the problem's tips.
        tip: usize,
        /// Measured position, m.
        position_m: [f64; 3],
        /// Measured orientation, unit quaternion `[w, x, y, z]`.
        rotation: [f64; 4],
    },
}

impl RowKind {
    /// Number of residuals a row of this kind contributes.
    pub fn n_residuals(&self) -> usize {
        match self {
            RowKind::Distance { .. } => 1,
            RowKind::Position { .. } | RowKind::Point { .. } | RowKind::Marker { .. } => 3,
            RowKind::Pose { .. } => 6,
        }
    }
}

/// Model terms besides the kinematic deviations.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelTerms {
    /// Gravity compliance, if modelled.
    pub compliance: Option<GravityCompliance>,
    /// Transversal compliance: each revolute joint's frame tilts about the axes normal to
    /// its axis in proportion to the gravity moment about them ([`TransversalTerm`]); needs
    /// [`Self::compliance`] (its weights give the moments) and a robot whose joints carry
    /// rotation deviations (URDF placements: `{joint}.rx`, `.ry`, `.rz`).
    pub transversal: Transversal,
    /// Joint angle harmonics, if modelled.
    pub harmonics: Option<JointHarmonics>,
    /// The tips whose base frame gravity is expressed in, for the compliance loads (the
    /// robot without the instrument frame, every tip of its tree,
    /// [`GravityCompliance::joint_loads`]); `None` = the problem's own tips.
    pub torque_tips: Option<Vec<Chain>>,
    /// Per configuration of the observations ([`Observations::configurations`]), the joint
    /// angles at which the gravity loads are evaluated (the torque equilibrium of a previous
    /// estimate, [`CalibratedModel::load_angles`]), rad, row-major
    /// (`n_configurations × n_joints`; shared, so that a caller keeps them beside the problem
    /// without a copy); `None`: at the readings. With them, the model the problem describes
    /// solves the equilibrium ([`CalibratedModel::equilibrium`]).
    pub load_angles: Option<Arc<[f64]>>,
}

/// How many transversal compliances a revolute joint has ([`ModelTerms::transversal`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Transversal {
    /// None.
    #[default]
    None,
    /// One per joint, the same about both axes normal to the joint axis (a bearing that
    /// tilts alike in every direction): parameter `transversal.{joint}`.
    Isotropic,
    /// Two per joint, about the two axes of the joint's link frame normal to the joint axis
    /// (a link that bends more easily one way than the other; they turn with the joint):
    /// parameters `transversal.{joint}.u` and `transversal.{joint}.v`
    /// ([`TransversalTerm::direction`]).
    PerAxis,
}

/// One transversal compliance of a joint (Tenhumberg & Bäuml 2021, "Calibration of an
/// elastic humanoid upper body and efficient compensation for motion planning", arXiv
/// 2311.08333: the joint frame bends about the two axes normal to the joint axis under the
/// gravity moment about them).
///
/// With no [`Self::direction`] (isotropic) the tilt is the rotation vector `c·m⊥(q)`, `m⊥` the
/// transversal gravity moment in the joint's frame before its motion
/// ([`crate::JointLoad::transversal`], N·m, or m for the lumped unit weights). With a
/// direction `u` (a unit vector normal to the joint axis in the joint's frame after its
/// motion, so fixed to the link it moves), the tilt is `c·(u·m⊥′)·u`, `m⊥′` the same moment
/// in that frame: the bending about `u` alone. Either tilt, expressed in the frame before the
/// motion, is added to the joint placement's rotation deviations (`{joint}.rx`, `.ry`, `.rz`)
/// for that configuration ([`Self::tilt`]).
#[derive(Clone, Debug, PartialEq)]
pub struct TransversalTerm {
    /// The joint (0-based, the tree's numbering).
    pub joint: usize,
    /// The axis of this compliance in the joint's link frame (unit, normal to the joint axis);
    /// `None`: both axes alike.
    pub direction: Option<Vector3<f64>>,
    /// Indices of the joint's rotation deviations `rx`, `ry`, `rz` among the kinematic
    /// parameters.
    pub rotation_params: [usize; 3],
    /// Compliance `c`, rad/(N·m) (rad/m for the lumped unit weights); 0 in a problem's term
    /// list, the identified value in a [`CalibratedModel`].
    pub compliance: f64,
}

impl TransversalTerm {
    /// The tilt (rotation vector in the joint's frame before its motion, rad) per unit
    /// compliance under the gravity load `load` of this term's joint: `m⊥`, or `(u·m⊥′)·u`
    /// turned into the frame before the motion.
    pub fn tilt(&self, load: &crate::JointLoad) -> Vector3<f64> {
        match self.direction {
            None => load.transversal,
            Some(u) => {
                let in_link = load.turn.inverse() * load.transversal;
                load.turn * (u * u.dot(&in_link))
            }
        }
    }
}

/// The two axes normal to a revolute joint's `axis` (unit, in its frame) that the per-axis
/// transversal compliance bends about: `u = axis × e` with `e` the frame axis least aligned
/// with the joint axis (normalised), `v = axis × u`.
fn normal_axes(axis: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let e = (0..3)
        .min_by(|&a, &b| axis[a].abs().total_cmp(&axis[b].abs()))
        .map_or_else(Vector3::x, |k| Vector3::ith(k, 1.0));
    let u = axis.cross(&e).normalize();
    [u, axis.cross(&u)]
}

/// One measured configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Joint readings, rad (m for a prismatic joint; length `n_joints`). Shared, not copied,
    /// between the rows of one configuration (a file row's markers and distance) and with the
    /// table they were read from (the measurement reader's rows): a long marker file's rows
    /// hold one copy of each configuration's readings.
    pub q: Arc<[f64]>,
    /// What was measured.
    pub kind: RowKind,
}

impl Row {
    /// A row measuring `kind` at joint readings `q` (rad, m for a prismatic joint): a
    /// vector is moved into a shared slice, a shared slice ([`Row::q`]) is shared.
    pub fn new(q: impl Into<Arc<[f64]>>, kind: RowKind) -> Self {
        Row { q: q.into(), kind }
    }
}

/// A known distance between two unknown points (e.g. MUKCa's two sockets, 0.05 m apart).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointDistance {
    /// First point index.
    pub a: usize,
    /// Second point index.
    pub b: usize,
    /// Known distance, m.
    pub distance_m: f64,
}

/// All observations of one calibration.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Observations {
    /// Measured configurations.
    pub rows: Vec<Row>,
    /// Known distances between unknown points.
    pub point_distances: Vec<PointDistance>,
    /// Number of unknown points (3 nuisance parameters each).
    pub n_points: usize,
}

impl Observations {
    /// The configurations of the rows: each run of consecutive rows with equal joint readings
    /// (a file row's markers and distance), as a range of row indices, in row order. The
    /// gravity loads of a compliance model are evaluated once per configuration.
    pub fn configurations(&self) -> impl Iterator<Item = Range<usize>> + '_ {
        let mut start = 0;
        self.rows.chunk_by(|a, b| a.q == b.q).map(move |run| {
            let range = start..start + run.len();
            start = range.end;
            range
        })
    }
}

/// Standard deviations that weight each measurement type (residual = error / sigma).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weights {
    /// Cable or other distance measurement, m.
    pub sigma_distance_m: f64,
    /// Tracker position, per axis, m.
    pub sigma_position_m: f64,
    /// Point (socket) seating, per axis, m.
    pub sigma_point_m: f64,
    /// Known distance between points (tool manufacturing tolerance), m.
    pub sigma_point_distance_m: f64,
    /// Measured orientation (pose rows), per axis of the rotation vector, rad.
    pub sigma_orientation_rad: f64,
}

impl Default for Weights {
    /// All sigmas 1 m: residuals stay in metres, every measurement weighs the same per metre.
    /// Callers with a noise model (the simulator, docs/design.md §3) should pass it instead.
    fn default() -> Self {
        Self {
            sigma_distance_m: 1.0,
            sigma_position_m: 1.0,
            sigma_point_m: 1.0,
            sigma_point_distance_m: 1.0,
            sigma_orientation_rad: 1.0,
        }
    }
}

/// A calibration problem: `x = [kinematic deviations | compliance k | unknown points (3 each)]`.
#[derive(Debug)]
pub struct CalibrationProblem {
    chain: Chain,
    /// The chain of each tip (marker and pose rows); `[chain]` unless built on a tree.
    tips: Vec<Chain>,
    /// The tips of the compliance loads (the robot without instrument frame, every branch).
    torque_tips: Vec<Chain>,
    obs: Observations,
    weights: Weights,
    compliance: Option<GravityCompliance>,
    harmonics: Option<JointHarmonics>,
    /// Transversal compliance terms (parameters after the harmonics); empty without.
    transversal: Vec<TransversalTerm>,
    /// Whether the loads were evaluated at given angles (a torque equilibrium).
    equilibrium: bool,
    /// Per joint, the kinematic parameter added to its screw's value (a joint offset,
    /// `dtheta`), whose Jacobian column is the joint angle's; `None` for a joint whose screw
    /// has none. With one for every joint of an angle term, the angle terms' columns come
    /// from the pose Jacobian, without a second pass for the geometric Jacobian.
    joint_param: Vec<Option<usize>>,
    /// Tilt of each transversal term per configuration (row-major,
    /// `n_configurations × transversal.len()`), the transversal moment in the joint's frame
    /// ([`TransversalTerm`]).
    tilt_basis: Vec<[f64; 3]>,
    /// Joint-angle terms of the compliance and harmonic models: (joint, parameter index after
    /// the kinematic ones). Empty for a purely geometric problem.
    angle_terms: Vec<(usize, usize)>,
    /// Per angle parameter (index after the kinematic ones), its terms' indices in
    /// [`Self::angle_terms`]: a Jacobian column sums only its own terms.
    terms_of_param: Vec<Vec<usize>>,
    /// Basis value of each angle term per configuration (row-major,
    /// `n_configurations × angle_terms.len()`): gravity torque (m or N·m) for compliance
    /// terms, `sin`/`cos` for harmonic terms.
    angle_basis: Vec<f64>,
    /// Each row's configuration ([`Observations::configurations`]), the index of its bases;
    /// empty for a problem without angle or transversal terms.
    row_config: Vec<usize>,
    /// Whether the bases are kept (`angle_basis`, `tilt_basis`) rather than evaluated row by
    /// row: up to [`STORED_BASES_MAX`] values.
    stored_bases: bool,
    /// The joint angles of each configuration's loads (a torque equilibrium,
    /// [`ModelTerms::load_angles`]), kept to evaluate the bases row by row.
    load_angles: Option<Arc<[f64]>>,
    layout: ParamLayout,
    n_residuals: usize,
    /// `[sin q, cos q]` per joint of the distance rows outside [`Self::lane_groups`]
    /// (row-major over the rows outside the groups), without compliance (which moves the
    /// angles); empty otherwise.
    trig: Vec<[f64; 2]>,
    /// First row of each run of [`LANES`] distance rows that the lane kernel evaluates
    /// together (ascending; runs found greedily within each of [`Self::blocks`]); empty
    /// with compliance or harmonics, or for a chain the kernel does not take.
    lane_groups: Vec<usize>,
    /// Joint sines and cosines of each lane group, `n_joints` entries per group, as
    /// [`hapcal_kinematics::FrozenChain::distance_gradient_lanes`] takes them.
    lane_trig: Vec<[[f64; LANES]; 2]>,
    /// Measured distance of each lane group's rows, m.
    lane_distance_m: Vec<[f64; LANES]>,
    /// The chain frozen at the kinematic part of the last `x` evaluated
    /// ([`Self::frozen_at`]).
    frozen: Mutex<FrozenCache>,
    /// Row blocks for the streaming back end: (rows, residual rows); the last block also
    /// holds the point distances.
    blocks: Vec<(Range<usize>, Range<usize>)>,
}

/// The chain frozen at `x_kin` (`None` before the first evaluation).
#[derive(Debug, Default)]
struct FrozenCache {
    x_kin: Vec<f64>,
    chain: Option<Arc<Frozen>>,
}

/// The problem's chain and each tip's chain (a tree's marker rows) frozen at one `x_kin`.
#[derive(Debug)]
struct Frozen {
    chain: FrozenChain,
    tips: Vec<FrozenChain>,
}

/// Rows per block of the streaming back end: large enough to amortise the per-block set-up
/// (one frozen chain), small enough that a block's Jacobian stays in cache.
const ROWS_PER_BLOCK: usize = 256;

/// Most basis values (angle terms and three per transversal tilt, per configuration) a
/// problem keeps; past it each evaluation computes a configuration's bases as its rows come
/// (a gravity-load pass per configuration and evaluation, in place of 8 bytes a value held).
const STORED_BASES_MAX: usize = 4_000_000;

/// What every row of one evaluation of [`CalibrationProblem`] shares: the parameters `x`, the
/// chain frozen at them, and the problem's term counts.
#[derive(Clone, Copy)]
struct RowContext<'a> {
    /// The parameters.
    x: ColRef<'a, f64>,
    /// The chains frozen at `x`'s kinematic part.
    frozen: &'a Frozen,
    /// Kinematic parameters.
    n_kin: usize,
    /// Compliance and harmonic parameters.
    n_angle: usize,
    /// `n_angle` and the transversal compliances.
    n_comp: usize,
    /// Transversal tilts per row.
    n_tilts: usize,
    /// Whether the angle terms' columns come from their joints' parameter columns.
    angles_from_params: bool,
    /// Offset of the points' parameters.
    off: usize,
}

/// Scratch of the row-by-row evaluations, allocated on first use and reused row after row.
#[derive(Default)]
struct RowScratch {
    /// Forward-kinematics workspace.
    ws: Option<FkWorkspace>,
    /// A row's point or pose Jacobian over the kinematic parameters.
    buf: Vec<f64>,
    /// A row's effective joint angles.
    q_buf: Vec<f64>,
    /// A distance row's gradient.
    grad: Vec<f64>,
    /// The kinematic part of `x`.
    x_kin: Vec<f64>,
    /// A row's effective kinematic parameters.
    x_buf: Vec<f64>,
    /// The bases of the configuration last evaluated, when the problem does not keep them.
    bases: ConfigBases,
}

/// One configuration's bases, evaluated row by row when the problem does not keep them
/// ([`STORED_BASES_MAX`]).
#[derive(Default)]
struct ConfigBases {
    /// The configuration they are for.
    config: Option<usize>,
    /// Its angle terms' basis.
    angle: Vec<f64>,
    /// Its transversal terms' tilts.
    tilts: Vec<[f64; 3]>,
}

impl CalibrationProblem {
    /// Builds the problem.
    ///
    /// # Errors
    /// [`Error::JointCount`], [`Error::NoSuchPoint`], [`Error::NotFinite`] or [`Error::BadSigma`]
    /// for inconsistent observations.
    pub fn new(
        chain: Chain,
        obs: Observations,
        weights: Weights,
        compliance: Option<GravityCompliance>,
    ) -> Result<Self, Error> {
        Self::with_harmonics(chain, obs, weights, compliance, None)
    }

    /// Builds the problem with optional joint harmonic errors ([`JointHarmonics`]) besides the
    /// optional compliance: `x = [kinematic | compliance | harmonics | points]`.
    ///
    /// # Errors
    /// As [`Self::new`]; [`Error::NoSuchParam`] if a harmonic joint is not a joint of `chain`
    /// (index reported as the joint) or an order is 0.
    pub fn with_harmonics(
        chain: Chain,
        obs: Observations,
        weights: Weights,
        compliance: Option<GravityCompliance>,
        harmonics: Option<JointHarmonics>,
    ) -> Result<Self, Error> {
        Self::build(
            vec![chain],
            obs,
            weights,
            ModelTerms {
                compliance,
                transversal: Transversal::None,
                harmonics,
                torque_tips: None,
                load_angles: None,
            },
            None,
        )
    }

    /// Builds the problem on a kinematic tree: rows of kind [`RowKind::Marker`] and
    /// [`RowKind::Pose`] name the tip they measure, every other row measures the first tip.
    /// `x = [tree parameters | compliance | harmonics | points]`; the tree's frame parameters
    /// ([`hapcal_kinematics::Tree::frame_params`]) are nuisance parameters.
    ///
    /// # Errors
    /// As [`Self::with_harmonics`]; [`Error::NoSuchParam`] for a row naming a tip the tree
    /// does not have (index reported as the tip), or a torque chain whose joint count differs
    /// from the tree's.
    pub fn on_tree(
        tree: hapcal_kinematics::Tree,
        obs: Observations,
        weights: Weights,
        terms: ModelTerms,
    ) -> Result<Self, Error> {
        let mut problem = Self::build(tree.tips().to_vec(), obs, weights, terms, None)?;
        // The instrument and marker frames are nuisance parameters: identified, never pruned
        // as too uncertain (they start wherever the initial guess put them).
        let frames = tree.frame_params();
        let specs = (problem.layout.specs().iter().enumerate())
            .map(|(i, spec)| ParamSpec {
                role: if frames.contains(&i) {
                    Role::Nuisance
                } else {
                    spec.role
                },
                ..spec.clone()
            })
            .collect();
        problem.layout = ParamLayout::new(specs);
        Ok(problem)
    }

    /// The problem of `terms` on `obs` seen by `tips`; `bases`, the rows' bases when they
    /// are known already ([`Self::with_rows`]), else evaluated ([`row_bases`]).
    fn build(
        tips: Vec<Chain>,
        obs: Observations,
        weights: Weights,
        terms: ModelTerms,
        bases: Option<RowBases>,
    ) -> Result<Self, Error> {
        let ModelTerms {
            compliance,
            transversal,
            harmonics,
            torque_tips,
            load_angles,
        } = terms;
        if let Some(a) = &load_angles {
            let expected = obs.configurations().count() * tips.first().map_or(0, Chain::n_joints);
            if a.len() != expected {
                return Err(Error::JointCount {
                    row: 0,
                    expected,
                    found: a.len(),
                });
            }
        }
        let Some(chain) = tips.first().cloned() else {
            return Err(Error::NoSuchParam {
                index: 0,
                n_params: 0,
            });
        };
        let torque_tips = torque_tips.unwrap_or_else(|| tips.clone());
        check_torque_tips(&torque_tips, chain.n_joints())?;
        check_weights(&weights)?;
        let n_joints = chain.n_joints();
        let n_residuals = checked_residuals(&obs, n_joints, tips.len())?;
        let mut specs: Vec<ParamSpec> = chain
            .params()
            .iter()
            .map(|p| ParamSpec {
                name: p.name.clone(),
                unit: match p.unit {
                    ParamUnit::Meter => Unit::Meter,
                    ParamUnit::Radian => Unit::Radian,
                },
                role: Role::Model,
            })
            .collect();
        if let Some(h) = &harmonics {
            if let Some(&bad) = h.joints.iter().find(|&&j| j >= n_joints) {
                return Err(Error::NoSuchParam {
                    index: bad,
                    n_params: n_joints,
                });
            }
            if h.orders.contains(&0) {
                return Err(Error::NoSuchParam {
                    index: 0,
                    n_params: n_joints,
                });
            }
        }
        if let Some(model) = &compliance {
            specs.extend(compliance_specs(&chain, model));
        }
        let n_comp = compliance.as_ref().map_or(0, |c| c.n_params(n_joints));
        let mut angle_terms: Vec<(usize, usize)> = match &compliance {
            Some(c) => (0..n_joints).map(|j| (j, c.group(j))).collect(),
            None => Vec::new(),
        };
        if let Some(h) = &harmonics {
            specs.extend(
                h.names(chain.joint_names())
                    .into_iter()
                    .map(|name| ParamSpec {
                        name,
                        unit: Unit::Radian,
                        role: Role::Model,
                    }),
            );
            angle_terms.extend(
                h.terms()
                    .into_iter()
                    .enumerate()
                    .map(|(t, (j, _, _))| (j, n_comp + t)),
            );
        }
        let transversal_terms = if transversal == Transversal::None {
            Vec::new()
        } else {
            let Some(model) = &compliance else {
                return Err(Error::NoTransversal {
                    reason: "it needs the gravity compliance model",
                });
            };
            let terms = transversal_terms_of(&chain, &torque_tips, transversal)?;
            specs.extend(transversal_specs(&chain, model, &terms, transversal));
            terms
        };
        let joint_param = joint_params(&tips, n_joints);
        let basis_terms = BasisTerms {
            compliance: compliance.as_ref().map(|c| (c, torque_tips.as_slice())),
            harmonics: harmonics.as_ref(),
            transversal: &transversal_terms,
        };
        let bases = bases.unwrap_or_else(|| {
            row_bases(
                &obs,
                &basis_terms,
                load_angles.as_deref(),
                angle_terms.len(),
            )
        });
        let stored_bases = bases.stored;
        specs.extend((0..obs.n_points).flat_map(|point| {
            ["x", "y", "z"].map(|axis| ParamSpec {
                name: format!("point{point}.{axis}"),
                unit: Unit::Meter,
                role: Role::Nuisance,
            })
        }));
        let blocks = row_blocks(&obs);
        let plain = angle_terms.is_empty() && transversal_terms.is_empty();
        let lanes = DistanceLanes::of(&chain, &obs, &blocks, plain);
        Ok(Self {
            chain,
            tips,
            torque_tips,
            obs,
            weights,
            compliance,
            harmonics,
            transversal: transversal_terms,
            equilibrium: load_angles.is_some(),
            load_angles,
            joint_param,
            tilt_basis: bases.tilts,
            terms_of_param: terms_of_param(&angle_terms),
            angle_terms,
            angle_basis: bases.angle,
            row_config: bases.row_config,
            stored_bases,
            layout: ParamLayout::new(specs),
            n_residuals,
            trig: lanes.trig,
            lane_groups: lanes.groups,
            lane_trig: lanes.trig_lanes,
            lane_distance_m: lanes.distance_m,
            frozen: Mutex::default(),
            blocks,
        })
    }

    /// The same problem (tips, weights, model terms, parameter roles) on other observations:
    /// the rows of a held-out set, or the rows with perturbed joint readings (a derivative with
    /// respect to the readings).
    ///
    /// # Errors
    /// As [`Self::new`] for the new observations.
    pub fn with_observations(&self, obs: Observations) -> Result<Self, Error> {
        let mut problem = Self::build(self.tips.clone(), obs, self.weights, self.terms(), None)?;
        if problem.layout.len() == self.layout.len() {
            problem.layout = self.layout.clone();
        }
        Ok(problem)
    }

    /// The same problem on the rows `keep` selects (one flag per row of
    /// [`Self::observations`], in their order; the point distances kept): a cross-validation
    /// fold's training rows. Its residuals and Jacobian are, bit for bit, those of the
    /// problem built on the kept rows ([`Self::with_observations`]), and so are its layout
    /// and its parameter roles, but each kept configuration's compliance and harmonic bases
    /// (its gravity loads) are taken from this problem's instead of being evaluated again:
    /// on a 20-joint two-arm tree that evaluation was the larger part of building a fold.
    /// A problem whose loads were evaluated at a torque equilibrium, or that evaluates its
    /// bases row by row, builds the kept rows' problem anew.
    ///
    /// # Errors
    /// As [`Self::with_observations`].
    ///
    /// # Panics
    /// If `keep` does not have one flag per row.
    #[track_caller]
    pub fn with_rows(&self, keep: &[bool]) -> Result<Self, Error> {
        assert_eq!(
            keep.len(),
            self.obs.rows.len(),
            "one flag per row of the problem"
        );
        let kept: Vec<usize> = (0..keep.len()).filter(|&i| keep[i]).collect();
        let obs = Observations {
            rows: kept.iter().map(|&i| self.obs.rows[i].clone()).collect(),
            point_distances: self.obs.point_distances.clone(),
            n_points: self.obs.n_points,
        };
        let bases = (self.stored_bases && !self.row_config.is_empty() && !self.equilibrium)
            .then(|| self.kept_bases(&obs, &kept));
        let mut problem = Self::build(self.tips.clone(), obs, self.weights, self.terms(), bases)?;
        problem.layout = self.layout.clone();
        Ok(problem)
    }

    /// The stored bases of the rows `obs` holds (`kept`: each one's row in this problem), a
    /// configuration's being those of this problem's configuration of its first row (rows
    /// of one configuration share their joint readings, and with them their bases).
    fn kept_bases(&self, obs: &Observations, kept: &[usize]) -> RowBases {
        let n_terms = self.angle_terms.len();
        let n_transversal = self.transversal.len();
        let mut bases = RowBases {
            angle: Vec::new(),
            tilts: Vec::new(),
            row_config: Vec::with_capacity(kept.len()),
            stored: true,
        };
        for (c, rows) in obs.configurations().enumerate() {
            bases.row_config.extend(std::iter::repeat_n(c, rows.len()));
            let from = self.row_config[kept[rows.start]];
            (bases.angle).extend_from_slice(&self.angle_basis[from * n_terms..][..n_terms]);
            (bases.tilts)
                .extend_from_slice(&self.tilt_basis[from * n_transversal..][..n_transversal]);
        }
        bases
    }

    /// The model terms this problem was built with, the loads at the readings (not at a
    /// torque equilibrium's angles).
    fn terms(&self) -> ModelTerms {
        ModelTerms {
            compliance: self.compliance.clone(),
            transversal: self.transversal_kind(),
            harmonics: self.harmonics.clone(),
            torque_tips: Some(self.torque_tips.clone()),
            load_angles: None,
        }
    }

    /// The same problem evaluating each configuration's compliance and harmonic bases (its
    /// gravity loads) as its rows come instead of keeping them: the same residuals and
    /// Jacobian, bit for bit, for a gravity-load pass per configuration and evaluation in
    /// place of 8 bytes per basis value held. A problem of more than 4,000,000 basis values is
    /// built this way.
    pub fn without_stored_bases(mut self) -> Self {
        if !self.row_config.is_empty() {
            self.stored_bases = false;
            self.angle_basis = Vec::new();
            self.tilt_basis = Vec::new();
        }
        self
    }

    /// The weights of the residuals.
    pub fn weights(&self) -> &Weights {
        &self.weights
    }

    /// The chain (the first tip's).
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// The chain of every tip (`[chain]` unless built by [`Self::on_tree`]).
    pub fn tips(&self) -> &[Chain] {
        &self.tips
    }

    /// The observations.
    pub fn observations(&self) -> &Observations {
        &self.obs
    }

    /// Number of compliance parameters (0 without compliance, else one per joint or per
    /// actuator group, [`GravityCompliance::n_params`]).
    pub fn n_compliance(&self) -> usize {
        self.compliance
            .as_ref()
            .map_or(0, |c| c.n_params(self.chain.n_joints()))
    }

    /// Number of harmonic parameters (0 without them, [`JointHarmonics::n_params`] otherwise).
    pub fn n_harmonics(&self) -> usize {
        self.harmonics.as_ref().map_or(0, JointHarmonics::n_params)
    }

    /// The transversal compliance the problem models.
    pub fn transversal_kind(&self) -> Transversal {
        match self.transversal.first() {
            None => Transversal::None,
            Some(t) if t.direction.is_some() => Transversal::PerAxis,
            Some(_) => Transversal::Isotropic,
        }
    }

    /// Number of transversal compliance parameters (0 without them, else one per revolute
    /// joint with rotation deviations, [`TransversalTerm`]).
    pub fn n_transversal(&self) -> usize {
        self.transversal.len()
    }

    /// Index of the first unknown-point parameter in `x`.
    pub fn points_offset(&self) -> usize {
        self.chain.n_params() + self.n_compliance() + self.n_harmonics() + self.n_transversal()
    }

    /// Start vector: zero deviations and compliance, each unknown point at the mean of the nominal
    /// end points of its rows (origin if it has none). Length `layout().len()`.
    pub fn initial_guess(&self) -> Col<f64> {
        let mut x = Col::<f64>::zeros(self.layout.len());
        let x_kin = vec![0.0; self.chain.n_params()];
        let mut sums = vec![(Vector3::zeros(), 0usize); self.obs.n_points];
        for row in &self.obs.rows {
            if let RowKind::Point { point } = row.kind {
                let p = self.chain.end_point(&x_kin, &row.q);
                sums[point].0 += p.coords;
                sums[point].1 += 1;
            }
        }
        let off = self.points_offset();
        for (point, (sum, n)) in sums.iter().enumerate() {
            let mean = if *n > 0 {
                sum / *n as f64
            } else {
                Vector3::zeros()
            };
            for k in 0..3 {
                x[off + 3 * point + k] = mean[k];
            }
        }
        x
    }

    /// The model that `x` describes (deviations and compliance; points are dropped).
    ///
    /// # Panics
    /// If `x.nrows() != layout().len()`.
    #[track_caller]
    pub fn model(&self, x: ColRef<'_, f64>) -> CalibratedModel {
        assert_eq!(x.nrows(), self.layout.len(), "parameter vector length");
        let n = self.chain.n_params();
        let x_kin: Vec<f64> = (0..n).map(|i| x[i]).collect();
        let compliance = self.compliance.as_ref().map(|c| {
            (
                c.clone(),
                (0..self.chain.n_joints())
                    .map(|j| x[n + c.group(j)])
                    .collect::<Vec<_>>(),
            )
        });
        let n_comp = self.n_compliance();
        let harmonics = self.harmonics.as_ref().map(|h| {
            (
                h.clone(),
                (0..h.n_params()).map(|t| x[n + n_comp + t]).collect(),
            )
        });
        let n_harm = self.n_harmonics();
        let transversal = (self.transversal.iter().enumerate())
            .map(|(t, term)| TransversalTerm {
                compliance: x[n + n_comp + n_harm + t],
                ..term.clone()
            })
            .collect();
        let own_tips = self.torque_tips == self.tips;
        CalibratedModel {
            chain: self.chain.clone(),
            tips: if self.tips.len() > 1 || !own_tips {
                self.tips.clone()
            } else {
                Vec::new()
            },
            torque_tips: if own_tips && self.tips.len() == 1 {
                Vec::new()
            } else {
                self.torque_tips.clone()
            },
            x_kin,
            compliance,
            harmonics,
            transversal,
            equilibrium: self.equilibrium,
        }
    }

    /// The unknown points that `x` holds (m).
    ///
    /// # Panics
    /// If `x.nrows() != layout().len()`.
    #[track_caller]
    pub fn points(&self, x: ColRef<'_, f64>) -> Vec<Point3<f64>> {
        assert_eq!(x.nrows(), self.layout.len(), "parameter vector length");
        let off = self.points_offset();
        (0..self.obs.n_points)
            .map(|p| Point3::new(x[off + 3 * p], x[off + 3 * p + 1], x[off + 3 * p + 2]))
            .collect()
    }

    /// Row `row_idx`'s angle terms' basis (`angle_terms.len()` values) and transversal
    /// terms' tilts (`transversal.len()` vectors): its configuration's, kept by the problem or,
    /// past [`STORED_BASES_MAX`], evaluated into `scratch` once for the rows of its
    /// configuration that follow each other.
    fn bases_of<'a>(
        &'a self,
        row_idx: usize,
        scratch: &'a mut ConfigBases,
    ) -> (&'a [f64], &'a [[f64; 3]]) {
        let c = self.row_config.get(row_idx).copied().unwrap_or(0);
        let (n, n_tilts) = (self.angle_terms.len(), self.transversal.len());
        if !self.stored_bases {
            if scratch.config != Some(c) {
                scratch.angle.clear();
                scratch.tilts.clear();
                let q = &self.obs.rows[row_idx].q;
                let at = (self.load_angles.as_deref()).map(|a| &a[c * q.len()..(c + 1) * q.len()]);
                self.terms_of()
                    .bases(q, at, &mut scratch.angle, &mut scratch.tilts);
                scratch.config = Some(c);
            }
            return (&scratch.angle, &scratch.tilts);
        }
        (
            &self.angle_basis[c * n..(c + 1) * n],
            &self.tilt_basis[c * n_tilts..(c + 1) * n_tilts],
        )
    }

    /// The model terms that give a configuration's bases.
    fn terms_of(&self) -> BasisTerms<'_> {
        BasisTerms {
            compliance: (self.compliance.as_ref()).map(|c| (c, self.torque_tips.as_slice())),
            harmonics: self.harmonics.as_ref(),
            transversal: &self.transversal,
        }
    }

    /// The joint angles the chain sees in row `row_idx`: the readings, deflected by the
    /// compliance when there is one (its angle terms' `basis`; written to `buf`).
    fn effective_q<'a>(
        &'a self,
        row_idx: usize,
        basis: &[f64],
        x: ColRef<'_, f64>,
        buf: &'a mut Vec<f64>,
    ) -> &'a [f64] {
        let q = &self.obs.rows[row_idx].q;
        if self.angle_terms.is_empty() {
            return q;
        }
        let n = self.chain.n_params();
        buf.clear();
        buf.extend_from_slice(q);
        for (&(j, param), b) in self.angle_terms.iter().zip(basis) {
            buf[j] += x[n + param] * b;
        }
        buf
    }

    /// Entry `k` of the Jacobian column `col` of one measured point or pose: a kinematic
    /// parameter's from `buf` (the forward kinematics' Jacobian, `rows` entries per column); an
    /// angle term's (compliance, harmonic) as its joints' angle derivatives times the row's
    /// `basis`, from the geometric Jacobian `jq` or, without it, from the joints' parameter
    /// columns; a transversal term's as its rotation parameters' columns times the row's
    /// `tilts`.
    #[allow(clippy::too_many_arguments)]
    fn column(
        &self,
        buf: &[f64],
        rows: usize,
        k: usize,
        col: usize,
        jq: Option<&hapcal_kinematics::Matrix6xX<f64>>,
        basis: &[f64],
        tilts: &[[f64; 3]],
    ) -> f64 {
        let n_kin = self.chain.n_params();
        let n_angle = self.n_compliance() + self.n_harmonics();
        if col < n_kin {
            buf[rows * col + k]
        } else if col < n_kin + n_angle {
            let g = col - n_kin;
            let terms = (self.terms_of_param.get(g).into_iter().flatten())
                .map(|&t| (self.angle_terms[t].0, basis[t]));
            match jq {
                Some(m) => terms.map(|(j, b)| m[(k, j)] * b).sum(),
                None => terms
                    .filter_map(|(j, b)| Some(buf[rows * self.joint_param[j]? + k] * b))
                    .sum(),
            }
        } else {
            let t = col - n_kin - n_angle;
            (self.transversal[t].rotation_params.iter())
                .zip(&tilts[t])
                .map(|(&i, v)| buf[rows * i + k] * v)
                .sum()
        }
    }

    /// The Jacobian rows `r..r + 3` of a position residual (`/ s`): column by column, the
    /// three rows together; the kinematic columns straight from the point or pose Jacobian
    /// `buf` (`stride` rows per parameter: 3 for a point, 6 for a pose, position first), the
    /// model columns (compliance, harmonics, transversal) from `d(k, col)`.
    #[allow(clippy::too_many_arguments)]
    fn position_columns(
        &self,
        jac: &mut [&mut [f64]],
        r: usize,
        s: f64,
        buf: &[f64],
        stride: usize,
        n_comp: usize,
        d: &dyn Fn(usize, usize) -> f64,
    ) {
        let n_kin = self.chain.n_params();
        let (kin, model) = jac[..n_kin + n_comp].split_at_mut(n_kin);
        for (col, c) in kin.iter_mut().enumerate() {
            let b = &buf[stride * col..stride * col + 3];
            for k in 0..3 {
                c[r + k] = b[k] / s;
            }
        }
        for (col, c) in (n_kin..).zip(model.iter_mut()) {
            for k in 0..3 {
                c[r + k] = d(k, col) / s;
            }
        }
    }

    /// The kinematic deviations the chain sees in a row: `x_kin` with its transversal
    /// tilts (`basis`) added to their joints' rotation deviations (written to `buf`), or `x_kin` itself
    /// without transversal compliance.
    fn effective_x<'a>(
        &'a self,
        basis: &[[f64; 3]],
        x: ColRef<'_, f64>,
        x_kin: &'a [f64],
        buf: &'a mut Vec<f64>,
    ) -> &'a [f64] {
        if self.transversal.is_empty() {
            return x_kin;
        }
        let first = self.chain.n_params() + self.n_compliance() + self.n_harmonics();
        buf.clear();
        buf.extend_from_slice(x_kin);
        for (t, (term, v)) in self.transversal.iter().zip(basis).enumerate() {
            let c = x[first + t];
            for (&i, v) in term.rotation_params.iter().zip(v) {
                buf[i] += c * v;
            }
        }
        buf
    }

    /// Residuals and, if `jac` is given, the Jacobian; one pass shares the forward kinematics.
    fn eval(&self, x: ColRef<'_, f64>, out: Option<ColMut<'_, f64>>, jac: Option<MatMut<'_, f64>>) {
        if self.blocks.len() < 2 {
            self.eval_rows(x, 0..self.obs.rows.len(), true, out, jac);
            return;
        }
        // More than one block: the row blocks in parallel (rayon), each on its own rows of
        // `out` and `jac`. Every row is computed the same way whatever the thread, so the
        // result does not depend on the number of threads. From two blocks on (512 rows), not
        // four: a fit of a few hundred rows that runs alone (the measured ladder's per-axis
        // transversal fit, on its critical path) then takes an idle core, and where every core
        // is busy the blocks run on the calling thread for a few microseconds of rayon.
        let mut tasks = Vec::with_capacity(self.blocks.len());
        let (mut out, mut jac) = (out, jac);
        for (b, (rows, res)) in self.blocks.iter().enumerate() {
            let len = res.len();
            let o = out.take().map(|o| {
                let (head, tail) = o.split_at_row_mut(len);
                out = Some(tail);
                head
            });
            let j = jac.take().map(|j| {
                let (head, tail) = j.split_at_row_mut(len);
                jac = Some(tail);
                head
            });
            tasks.push((rows.clone(), b + 1 == self.blocks.len(), o, j));
        }
        tasks
            .into_par_iter()
            .for_each(|(rows, last, o, j)| self.eval_rows(x, rows, last, o, j));
    }

    /// Residuals and, if `jac` is given, the Jacobian of the rows `rows` (and of the point
    /// distances when `with_point_distances`), written from row 0 of `out` / `jac`.
    fn eval_rows(
        &self,
        x: ColRef<'_, f64>,
        rows: Range<usize>,
        with_point_distances: bool,
        out: Option<ColMut<'_, f64>>,
        jac: Option<MatMut<'_, f64>>,
    ) {
        // The residuals as a slice: `out` itself when its rows are contiguous (row stride 1),
        // else a copy written back at the end.
        let mut strided = None;
        let mut out_copy = Vec::new();
        let out = match out {
            Some(o) if o.row_stride() == 1 => o.try_as_col_major_mut().map(|o| o.as_slice_mut()),
            Some(o) => {
                out_copy.resize(o.nrows(), 0.0);
                strided = Some(o);
                Some(out_copy.as_mut_slice())
            }
            None => None,
        };
        match jac {
            None => self.eval_rows_in(x, rows, with_point_distances, out, None),
            Some(mut jac) => {
                if let Some(j) = jac.as_mut().try_as_col_major_mut() {
                    let mut cols: Vec<&mut [f64]> =
                        j.col_iter_mut().map(|c| c.as_slice_mut()).collect();
                    self.eval_rows_in(x, rows, with_point_distances, out, Some(&mut cols));
                } else {
                    // A Jacobian view without contiguous columns: through a column-major copy.
                    let mut tmp = Mat::<f64>::zeros(jac.nrows(), jac.ncols());
                    if let Some(t) = tmp.as_mut().try_as_col_major_mut() {
                        let mut cols: Vec<&mut [f64]> =
                            t.col_iter_mut().map(|c| c.as_slice_mut()).collect();
                        self.eval_rows_in(x, rows, with_point_distances, out, Some(&mut cols));
                    }
                    jac.copy_from(&tmp);
                }
            }
        }
        if let Some(mut o) = strided {
            for (i, v) in out_copy.iter().enumerate() {
                o[i] = *v;
            }
        }
    }

    /// [`Self::eval_rows`] with the residuals as a slice and the Jacobian as its columns
    /// (`jac[col][row]`).
    fn eval_rows_in(
        &self,
        x: ColRef<'_, f64>,
        rows: Range<usize>,
        with_point_distances: bool,
        mut out: Option<&mut [f64]>,
        mut jac: Option<&mut [&mut [f64]]>,
    ) {
        let n_kin = self.chain.n_params();
        let n_angle = self.n_compliance() + self.n_harmonics();
        let n_comp = n_angle + self.n_transversal();
        let n_tilts = self.transversal.len();
        // The angle terms' Jacobian columns from their joints' parameter columns (exact: the
        // parameter adds to the joint's value), when every such joint has one.
        let angles_from_params =
            (self.angle_terms.iter()).all(|(j, _)| self.joint_param[*j].is_some());
        let off = self.points_offset();
        let point_distances: &[PointDistance] = if with_point_distances {
            &self.obs.point_distances
        } else {
            &[]
        };
        // Constant factors between joints folded once for this x (FrozenChain).
        let frozen = self.frozen_at(x);
        // Every row writes all kinematic, compliance and harmonic columns; only the columns of
        // the unknown points and the point-distance rows need zeros first.
        if let Some(j) = jac.as_mut() {
            let n_rows = j.first().map_or(0, |c| c.len());
            let pd_rows = n_rows - point_distances.len()..n_rows;
            for (col, c) in j.iter_mut().enumerate() {
                if col >= off {
                    c.fill(0.0);
                } else {
                    c[pd_rows.clone()].fill(0.0);
                }
            }
        }
        // Scratch of the row-by-row paths, allocated on first use.
        let mut scratch = RowScratch::default();
        let ctx = RowContext {
            x,
            frozen: &frozen,
            n_kin,
            n_angle,
            n_comp,
            n_tilts,
            angles_from_params,
            off,
        };
        let n_joints = self.chain.n_joints();
        let s_distance = self.weights.sigma_distance_m;
        let inv_s_distance = 1.0 / s_distance;
        let mut r = 0usize;
        // The next lane group (FrozenChain::distance_gradient_lanes, LANES poses per SIMD
        // instruction) at or after the current row.
        let mut group = self.lane_groups.partition_point(|&g| g < rows.start);
        let mut next_row = rows.start;
        while next_row < rows.end {
            // A lane group moves `next_row` past all its rows.
            let row_idx = next_row;
            next_row += 1;
            let row = &self.obs.rows[row_idx];
            if self.lane_groups.get(group) == Some(&row_idx) && row_idx + LANES <= rows.end {
                // This group and the next if it follows directly: one kernel call overlaps
                // the two groups' operations.
                let n_groups = if self.lane_groups.get(group + 1) == Some(&(row_idx + LANES))
                    && row_idx + 2 * LANES <= rows.end
                {
                    2
                } else {
                    1
                };
                let n_rows = n_groups * LANES;
                let trig = &self.lane_trig[group * n_joints..(group + n_groups) * n_joints];
                let mut dist = [[0.0; LANES]; 2];
                let dist = &mut dist[..n_groups];
                match jac.as_mut() {
                    // The Jacobian rows are ∂|P|/∂x / σ: 1/σ folded into the kernel (within
                    // an ulp of the division; the residuals keep the division), written
                    // straight into the kinematic columns.
                    Some(j) => {
                        frozen
                            .chain
                            .distance_gradient_lanes_into(trig, inv_s_distance, dist, j, r)
                    }
                    None => frozen.chain.distance_gradient_lanes(trig, 1.0, dist, None),
                }
                if let Some(o) = out.as_mut() {
                    let o = o[r..r + n_rows].chunks_exact_mut(LANES);
                    for ((o, d), measured) in o.zip(&*dist).zip(&self.lane_distance_m[group..]) {
                        for l in 0..LANES {
                            o[l] = (d[l] - measured[l]) / s_distance;
                        }
                    }
                }
                group += n_groups;
                r += n_rows;
                next_row = row_idx + n_rows;
                continue;
            }
            if self.lane_groups.get(group) == Some(&row_idx) {
                // A group that runs past `rows` (not with the blocks' ranges): row by row.
                group += 1;
            }
            // Distance rows without compliance: the distance gradient directly, joint
            // angles by their precomputed sines and cosines (the fast path at scale).
            if n_comp == 0
                && let RowKind::Distance { distance_m } = &row.kind
            {
                let trig = self.row_trig(row_idx);
                let p = match (jac.as_mut(), trig) {
                    (Some(j), _) => {
                        let RowScratch { ws, grad, .. } = &mut scratch;
                        grad.resize(n_kin, 0.0);
                        let ws = ws.get_or_insert_with(|| FkWorkspace::new(&self.chain));
                        let p = frozen.chain.distance_gradient(&row.q, trig, grad, ws);
                        for (c, g) in j.iter_mut().zip(grad.iter()) {
                            c[r] = g / s_distance;
                        }
                        p
                    }
                    (None, Some(t)) => frozen.chain.end_point_trig(&row.q, t),
                    (None, None) => frozen.chain.end_point(&row.q),
                };
                if let Some(o) = out.as_mut() {
                    o[r] = (p.coords.norm() - distance_m) / s_distance;
                }
                r += 1;
                continue;
            }
            if matches!(row.kind, RowKind::Marker { .. } | RowKind::Pose { .. }) {
                let (o, j) = (out.as_deref_mut(), jac.as_deref_mut());
                r += self.eval_tip_row(&ctx, row_idx, &mut scratch, r, o, j);
                continue;
            }
            let (o, j) = (out.as_deref_mut(), jac.as_deref_mut());
            r += self.eval_chain_row(&ctx, row_idx, &mut scratch, r, o, j);
        }
        self.eval_point_distances(x, point_distances, r, out, jac);
    }

    /// One marker or pose row on its tip's chain (`RowKind::Marker`, `RowKind::Pose`): its
    /// residuals from row `r` of `out` and its Jacobian rows in `jac`; returns the residuals
    /// written (3, or 6 for a pose; 0 for a row of another kind).
    fn eval_tip_row(
        &self,
        ctx: &RowContext<'_>,
        row_idx: usize,
        scratch: &mut RowScratch,
        r: usize,
        mut out: Option<&mut [f64]>,
        mut jac: Option<&mut [&mut [f64]]>,
    ) -> usize {
        let RowContext {
            x,
            frozen,
            n_kin,
            n_angle,
            n_comp,
            n_tilts,
            angles_from_params,
            ..
        } = *ctx;
        let RowScratch {
            ws,
            buf,
            q_buf,
            x_kin,
            x_buf,
            bases,
            ..
        } = scratch;
        let row = &self.obs.rows[row_idx];
        let start = r;
        let mut r = r;
        let (basis, tilts) = self.bases_of(row_idx, bases);
        let (RowKind::Marker { tip, position_m }
        | RowKind::Pose {
            tip, position_m, ..
        }) = &row.kind
        else {
            return 0;
        };
        let q_eff = self.effective_q(row_idx, basis, x, q_buf);
        let chain = &self.tips[*tip];
        if x_kin.is_empty() {
            x_kin.extend((0..n_kin).map(|i| x[i]));
        }
        let x_eff = self.effective_x(tilts, x, x_kin, x_buf);
        // A marker without transversal tilts needs only the tip's point: the tip's chain
        // frozen at x (the constant factors between joints folded once), 3 Jacobian rows
        // per parameter. A pose, or tilts that change the deviations row by row: the
        // chain itself, 6 rows per parameter (position first).
        let frozen_tip = match row.kind {
            RowKind::Marker { .. } if n_tilts == 0 => frozen.tips.get(*tip),
            _ => None,
        };
        let (pose, stride) = match (frozen_tip, jac.is_some()) {
            (Some(f), true) => {
                buf.resize(3 * n_kin, 0.0);
                let ws = ws.get_or_insert_with(|| FkWorkspace::new(chain));
                let p = f.point_and_jacobian(q_eff, buf, ws);
                (Isometry3::translation(p.x, p.y, p.z), 3)
            }
            (Some(f), false) => {
                let p = f.end_point(q_eff);
                (Isometry3::translation(p.x, p.y, p.z), 3)
            }
            (None, true) => {
                buf.resize(6 * n_kin, 0.0);
                let ws = ws.get_or_insert_with(|| FkWorkspace::new(chain));
                (chain.pose_and_jacobian_in(x_eff, q_eff, ws, buf), 6)
            }
            (None, false) => (chain.end_pose(x_eff, q_eff), 6),
        };
        let jq = (n_angle > 0 && jac.is_some() && !angles_from_params)
            .then(|| chain.geometric_jacobian(x_eff, q_eff));
        // Row k of the pose Jacobian (0–2 position, 3–5 rotation vector) at column col.
        let dpose = |k: usize, col: usize| -> f64 {
            self.column(buf, stride, k, col, jq.as_ref(), basis, tilts)
        };
        let s = self.weights.sigma_position_m;
        let p = pose.translation.vector;
        if let Some(o) = out.as_mut() {
            for k in 0..3 {
                o[r + k] = (p[k] - position_m[k]) / s;
            }
        }
        if let Some(j) = jac.as_mut() {
            self.position_columns(j, r, s, buf, stride, n_comp, &dpose);
        }
        r += 3;
        if let RowKind::Pose { rotation, .. } = &row.kind {
            let s = self.weights.sigma_orientation_rad;
            let [w, qx, qy, qz] = *rotation;
            let measured = UnitQuaternion::from_quaternion(Quaternion::new(w, qx, qy, qz));
            let phi = (measured.inverse() * pose.rotation).scaled_axis();
            // dφ = J_r⁻¹(φ)·Rᵀ·ω for a base-frame rotation ω of the tip.
            let to_phi = right_jacobian_inverse(&phi)
                * pose.rotation.inverse().to_rotation_matrix().matrix();
            if let Some(o) = out.as_mut() {
                for k in 0..3 {
                    o[r + k] = phi[k] / s;
                }
            }
            if let Some(j) = jac.as_mut() {
                for (col, c) in j.iter_mut().enumerate().take(n_kin + n_comp) {
                    let omega = Vector3::new(dpose(3, col), dpose(4, col), dpose(5, col));
                    let d = to_phi * omega;
                    for k in 0..3 {
                        c[r + k] = d[k] / s;
                    }
                }
            }
            r += 3;
        }
        r - start
    }

    /// One row on the first tip's chain (a distance with angle or transversal terms, a
    /// position, a point): its residuals from row `r` of `out` and its Jacobian rows in `jac`;
    /// returns the residuals written (1 or 3; 0 for a marker or pose, evaluated on its tip's
    /// chain by [`Self::eval_tip_row`]).
    fn eval_chain_row(
        &self,
        ctx: &RowContext<'_>,
        row_idx: usize,
        scratch: &mut RowScratch,
        r: usize,
        mut out: Option<&mut [f64]>,
        mut jac: Option<&mut [&mut [f64]]>,
    ) -> usize {
        let RowContext {
            x,
            frozen,
            n_kin,
            n_angle,
            n_comp,
            n_tilts,
            angles_from_params,
            off,
        } = *ctx;
        let RowScratch {
            ws,
            buf,
            q_buf,
            x_kin,
            x_buf,
            bases,
            ..
        } = scratch;
        let row = &self.obs.rows[row_idx];
        let start = r;
        let mut r = r;
        let (basis, tilts) = self.bases_of(row_idx, bases);
        let q_eff = self.effective_q(row_idx, basis, x, q_buf);
        let p = if n_tilts > 0 {
            // Transversal tilts change the deviations row by row: the chain itself.
            if x_kin.is_empty() {
                x_kin.extend((0..n_kin).map(|i| x[i]));
            }
            let x_eff = self.effective_x(tilts, x, x_kin, x_buf);
            if jac.is_some() {
                buf.resize(3 * n_kin, 0.0);
                let ws = ws.get_or_insert_with(|| FkWorkspace::new(&self.chain));
                self.chain.point_and_jacobian_in(x_eff, q_eff, ws, buf)
            } else {
                self.chain.end_point(x_eff, q_eff)
            }
        } else if jac.is_some() {
            buf.resize(3 * n_kin, 0.0);
            let ws = ws.get_or_insert_with(|| FkWorkspace::new(&self.chain));
            frozen.chain.point_and_jacobian(q_eff, buf, ws)
        } else {
            frozen.chain.end_point(q_eff)
        };
        // ∂p/∂k_j = (∂p/∂q_j)·τ̂_j (and ∂p/∂a_jh = (∂p/∂q_j)·sin(h·q_j), …), from the
        // geometric Jacobian's linear rows.
        let jq = if n_angle > 0 && jac.is_some() && !angles_from_params {
            if x_kin.is_empty() {
                x_kin.extend((0..n_kin).map(|i| x[i]));
            }
            let x_eff = self.effective_x(tilts, x, x_kin, x_buf);
            Some(self.chain.geometric_jacobian(x_eff, q_eff))
        } else {
            None
        };
        let dp = |k: usize, col: usize| -> f64 {
            self.column(buf, 3, k, col, jq.as_ref(), basis, tilts)
        };
        match &row.kind {
            RowKind::Distance { distance_m } => {
                let s = self.weights.sigma_distance_m;
                let (norm, u) = length_and_direction(&p.coords);
                if let Some(o) = out.as_mut() {
                    o[r] = (norm - distance_m) / s;
                }
                if let Some(j) = jac.as_mut() {
                    for (col, c) in j.iter_mut().enumerate().take(n_kin + n_comp) {
                        c[r] = (0..3).map(|k| u[k] * dp(k, col)).sum::<f64>() / s;
                    }
                }
                r += 1;
            }
            RowKind::Position { position_m } => {
                let s = self.weights.sigma_position_m;
                if let Some(o) = out.as_mut() {
                    for k in 0..3 {
                        o[r + k] = (p[k] - position_m[k]) / s;
                    }
                }
                if let Some(j) = jac.as_mut() {
                    self.position_columns(j, r, s, buf, 3, n_comp, &dp);
                }
                r += 3;
            }
            RowKind::Point { point } => {
                let s = self.weights.sigma_point_m;
                if let Some(o) = out.as_mut() {
                    for k in 0..3 {
                        o[r + k] = (p[k] - x[off + 3 * point + k]) / s;
                    }
                }
                if let Some(j) = jac.as_mut() {
                    self.position_columns(j, r, s, buf, 3, n_comp, &dp);
                    for k in 0..3 {
                        j[off + 3 * point + k][r + k] = -1.0 / s;
                    }
                }
                r += 3;
            }
            // Evaluated on their tip's chain above.
            RowKind::Marker { .. } | RowKind::Pose { .. } => {}
        }
        r - start
    }

    /// The point-distance rows `point_distances` from row `r` of `out`: `|p_a − p_b|` of the
    /// points' parameters (from offset [`Self::points_offset`] of `x`) against the measured
    /// distance, divided by σ, with their Jacobian rows in `jac`.
    fn eval_point_distances(
        &self,
        x: ColRef<'_, f64>,
        point_distances: &[PointDistance],
        mut r: usize,
        mut out: Option<&mut [f64]>,
        mut jac: Option<&mut [&mut [f64]]>,
    ) {
        let off = self.points_offset();
        let s = self.weights.sigma_point_distance_m;
        for pd in point_distances {
            let d = Vector3::from_fn(|k, _| x[off + 3 * pd.a + k] - x[off + 3 * pd.b + k]);
            let (norm, u) = length_and_direction(&d);
            if let Some(o) = out.as_mut() {
                o[r] = (norm - pd.distance_m) / s;
            }
            if let Some(j) = jac.as_mut() {
                for k in 0..3 {
                    j[off + 3 * pd.a + k][r] = u[k] / s;
                    j[off + 3 * pd.b + k][r] = -u[k] / s;
                }
            }
            r += 1;
        }
    }

    /// The chain frozen at the kinematic part of `x`: the cached one while `x` does not change
    /// (LM evaluates the Jacobian at the point whose residuals it accepted; the row blocks of
    /// one evaluation, in parallel or streamed, share it), else frozen again into the cached
    /// one's allocations when no evaluation still holds it. Bit-for-bit the chain
    /// [`Chain::freeze`] gives.
    fn frozen_at(&self, x: ColRef<'_, f64>) -> Arc<Frozen> {
        let n_kin = self.chain.n_params();
        let x_kin = (0..n_kin).map(|i| x[i]);
        let freeze = |x_kin: &[f64]| Frozen {
            chain: self.chain.freeze(x_kin),
            tips: self.tips.iter().map(|t| t.freeze(x_kin)).collect(),
        };
        let Ok(mut cache) = self.frozen.lock() else {
            // A thread panicked while freezing: leave the cache alone.
            return Arc::new(freeze(&x_kin.collect::<Vec<_>>()));
        };
        let cache = &mut *cache;
        if let Some(frozen) = &cache.chain
            && cache.x_kin.len() == n_kin
            && cache
                .x_kin
                .iter()
                .zip(x_kin.clone())
                .all(|(a, b)| a.to_bits() == b.to_bits())
        {
            return Arc::clone(frozen);
        }
        cache.x_kin.clear();
        cache.x_kin.extend(x_kin);
        match cache.chain.as_mut().and_then(Arc::get_mut) {
            Some(frozen) => {
                self.chain.freeze_into(&cache.x_kin, &mut frozen.chain);
                for (tip, f) in self.tips.iter().zip(&mut frozen.tips) {
                    tip.freeze_into(&cache.x_kin, f);
                }
            }
            None => cache.chain = Some(Arc::new(freeze(&cache.x_kin))),
        }
        match &cache.chain {
            Some(frozen) => Arc::clone(frozen),
            None => Arc::new(freeze(&cache.x_kin)),
        }
    }

    /// `[sin q, cos q]` per joint of row `row_idx` if it is precomputed (a distance row outside
    /// the lane groups, without compliance).
    fn row_trig(&self, row_idx: usize) -> Option<&[[f64; 2]]> {
        if self.trig.is_empty() {
            return None;
        }
        let before = self.lane_groups.partition_point(|&g| g <= row_idx);
        if before > 0 && self.lane_groups[before - 1] + LANES > row_idx {
            return None;
        }
        let n_joints = self.chain.n_joints();
        let start = (row_idx - LANES * before) * n_joints;
        self.trig.get(start..start + n_joints)
    }
}
