//! A calibrated robot of URDF joints: a tree of revolute and prismatic joints with several
//! tips, link masses and joint compliances; poses, Jacobians and the deflection under its own
//! weight, with no allocation per call (the buffers live in a [`RobotWorkspace`]).

use crate::error::{check_finite, check_finite_parts, check_len};
use crate::math::{sin_cos, sin_cos_near};
use crate::model::farthest_outside;
use crate::pose::cross;
use crate::{Error, Pose};

/// Standard gravity, m/s² (CGPM 1901), as `hapcal-problems` uses it.
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// Most fixed-point iterations of the deflection `θ = q + k∘τ(θ)` ([`Robot::deflect`]), as the
/// calibration library's torque equilibrium (`hapcal_problems::EQUILIBRIUM_ITERATIONS`): each
/// multiplies the error by about `k·∂τ/∂θ` (10⁻³ for a stiff arm), so a handful suffice.
pub const DEFLECTION_ITERATIONS: usize = 20;

/// The deflection iterations stop once no joint moves by more than this, rad (the calibration
/// library's threshold).
pub const DEFLECTION_TOLERANCE_RAD: f64 = 1e-12;

/// One moving joint: its origin in its parent joint's frame (after that joint's motion; the
/// root link's frame for a joint without parent), through the fixed joints between them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RobotJoint {
    /// Index of the nearest moving joint above, if any.
    pub(crate) parent: Option<usize>,
    /// Joint frame at zero motion in the parent frame (URDF `<origin>`s composed).
    pub(crate) origin: Pose,
    /// Unit axis in the joint frame.
    pub(crate) axis: [f64; 3],
    /// Translation along the axis (m) instead of rotation about it (rad).
    pub(crate) prismatic: bool,
    /// The joint frame at zero motion at the nominal geometry (the calibration's deviations
    /// removed): where the calibration evaluated the gravity loads. `origin` without a record.
    pub(crate) nominal: Pose,
    /// The joint's identified deviation `x, y, z` (m), `rx, ry, rz` (rad) and offset (rad, m
    /// for a prismatic joint): `origin = nominal · Δ(x…rz) · motion(offset)`.
    pub(crate) deviation: [f64; 7],
    /// Whether a lumped unit weight sits at its origin (it lies on a load tip's path).
    pub(crate) weight: bool,
}

/// One transversal compliance term: the joint's rotation deviations grow by `c·tilt` under
/// the gravity load normal to its axis (`hapcal_problems::TransversalTerm`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TransversalJoint {
    /// The joint.
    pub(crate) joint: usize,
    /// Compliance `c`, rad/(N·m) (rad/m lumped).
    pub(crate) compliance: f64,
    /// The axis of a per-axis term in the joint's frame after its motion; `None`: isotropic.
    pub(crate) direction: Option<[f64; 3]>,
}

/// One joint harmonic term: the joint's angle grows by `coef·sin(h·q)` or `coef·cos(h·q)` of
/// its reading `q` (`hapcal_problems::JointHarmonics`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HarmonicTerm {
    /// The joint.
    pub(crate) joint: usize,
    /// Order h ≥ 1.
    pub(crate) order: u32,
    /// Sine (true) or cosine.
    pub(crate) sine: bool,
    /// Coefficient, rad.
    pub(crate) coef: f64,
}

/// One tip: a link's frame in the frame of the nearest moving joint above it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RobotTip {
    /// Index of the nearest moving joint above, if any (`None`: fixed to the root).
    pub(crate) parent: Option<usize>,
    /// The tip link's frame in that joint's frame (fixed joints composed), m.
    pub(crate) offset: Pose,
    /// A frame on the tip link (a marker), in the tip link's frame: the poses and Jacobians
    /// are of it; the gravity loads keep the tip link's origin. Identity by default.
    pub(crate) marker: Pose,
    /// `offset` at the nominal geometry (the tip element's deviation removed).
    pub(crate) nominal_offset: Pose,
    /// Whether the calibration's lumped unit weights hang at this tip (one of its tips).
    pub(crate) weight: bool,
}

/// A link's point mass, in the frame of the nearest moving joint above it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PointMass {
    /// The joint.
    pub(crate) joint: usize,
    /// Mass, kg.
    pub(crate) mass_kg: f64,
    /// Centre of mass in the joint's frame (after its motion), m.
    pub(crate) com_m: [f64; 3],
}

/// How the gravity load of a joint is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GravityModel {
    /// From the links' point masses (the URDF's `<inertial>`s): torques in N·m, compliances
    /// in rad/(N·m).
    Masses,
    /// Without masses, the calibration library's lumped unit weights at the origin of every
    /// joint below and at every tip below: "torques" in m, compliances in rad/m
    /// (`hapcal_problems::GravityCompliance`).
    Lumped,
}

/// A calibrated robot ready to evaluate: the moving joints of a URDF tree on the paths from
/// its root link to the chosen tip links, with the calibrated joint origins, the link masses
/// and one compliance per joint.
///
/// Joint angles `q` are in rad (m for a prismatic joint), in the order of
/// [`Robot::joint_names`] (moving joints in order of first appearance on the tips' paths, root
/// first, tip by tip: the order of `hapcal_kinematics::Tree::from_placement_paths` and of the
/// measurement files). Poses are of the tip links' frames in the root link's frame, m.
///
/// Built by [`Robot::load_urdf`] (with `std`); evaluation never allocates: every call takes a
/// [`RobotWorkspace`] made once by [`Robot::workspace`].
#[derive(Clone, Debug, PartialEq)]
pub struct Robot {
    pub(crate) joints: Vec<RobotJoint>,
    pub(crate) joint_names: Vec<String>,
    pub(crate) limits: Vec<(f64, f64)>,
    pub(crate) tips: Vec<RobotTip>,
    pub(crate) tip_names: Vec<String>,
    pub(crate) masses: Vec<PointMass>,
    /// Compliance per joint (0 = rigid), rad/(N·m) with masses, rad/m lumped.
    pub(crate) compliance: Vec<f64>,
    pub(crate) gravity: GravityModel,
    /// Unit vector of gravity in the root link's frame.
    pub(crate) gravity_dir: [f64; 3],
    /// Identified frames from the calibration's sidecar (`instrument`, `marker1`, …).
    pub(crate) frames: Vec<(String, Pose)>,
    /// The calibration record read from the sidecar, if any.
    pub(crate) record: Option<hapcal_contract::Calibration>,
    /// The training range of each joint the record's region names: (joint, min, max, slack),
    /// rad or m.
    pub(crate) region: Vec<(usize, f64, f64, f64)>,
    /// Gravitational acceleration of the link masses, m/s².
    pub(crate) gravity_m_s2: f64,
    /// Whether the loads are those of the deflected robot (`θ = q + k∘τ(θ)`) rather than of
    /// the robot at its readings.
    pub(crate) equilibrium: bool,
    /// Whether some joint's or tip's nominal frame differs from its calibrated one.
    pub(crate) nominal_differs: bool,
    /// Transversal compliance terms.
    pub(crate) transversal: Vec<TransversalJoint>,
    /// Joint harmonic terms.
    pub(crate) harmonics: Vec<HarmonicTerm>,
    /// Each tip's element name (the last fixed joint of its path, if it ends in fixed
    /// joints), whose deviation the tip's offset holds.
    pub(crate) tip_elements: Vec<Option<String>>,
    /// A D-H robot's nominal `[[dh]]` rows, from which a D-H deviation moves the joint
    /// origins ([`Robot::with_value`]); `None` for a URDF robot.
    pub(crate) dh: Option<crate::dh_table::DhTable>,
}

/// Buffers of [`Robot`]'s evaluation calls, sized for one robot ([`Robot::workspace`]).
#[derive(Clone, Debug)]
pub struct RobotWorkspace {
    /// Root-link frame of each joint after its motion.
    pub(crate) frames: Vec<Pose>,
    /// Joint angles of the deflection iterate, rad.
    pub(crate) theta: Vec<f64>,
    /// Gravity torques, N·m (m lumped).
    pub(crate) torque: Vec<f64>,
    /// Jacobian columns of one tip.
    pub(crate) jac: Vec<[f64; 6]>,
    /// A second joint vector (the compensation's trial command).
    pub(crate) trial: Vec<f64>,
    /// The compensation's accepted command.
    pub(crate) command: Vec<f64>,
    /// Joint frames at the nominal geometry (the gravity loads').
    pub(crate) nominal: Vec<Pose>,
    /// Gravity moment about each joint's origin, root frame (transversal compliance).
    pub(crate) moment: Vec<[f64; 3]>,
    /// Rotation deviation added to each joint by its transversal compliance, rad.
    pub(crate) tilt: Vec<[f64; 3]>,
    /// Joint angles where the gravity loads are evaluated.
    pub(crate) load_at: Vec<f64>,
    /// Each joint subtree's weight `W` and first moment `Σ w·c` about the root (the loads'
    /// one pass), N and N·m (1 and m lumped).
    pub(crate) sums: Vec<[f64; 4]>,
    /// Sine and cosine of each joint's reading in the last deflection (the angles near it
    /// take theirs from these, [`sin_cos_near`]).
    pub(crate) sin_cos: Vec<(f64, f64)>,
    /// Sine and cosine of each joint's load angle.
    pub(crate) load_sin_cos: Vec<(f64, f64)>,
    /// The gravity direction in each joint's frame at the load angles (nominal geometry).
    pub(crate) gravity_local: Vec<[f64; 3]>,
}

/// What [`Robot::deflect`] did: fixed-point iterations of `θ = q + k∘τ(θ)` and the last step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Deflection {
    /// Iterations taken (0 for a robot without compliance).
    pub iterations: usize,
    /// Largest joint change of the last iteration, rad (m for a prismatic joint).
    pub final_step_rad: f64,
    /// Whether the last step was at most [`DEFLECTION_TOLERANCE_RAD`] (true without
    /// compliance). False: the iterations hit [`DEFLECTION_ITERATIONS`] first (a compliance
    /// so large that `k·∂τ/∂θ` nears 1).
    pub converged: bool,
}

/// The pose `Rot(axis, angle)` or `Trans(axis · d)` of one joint's motion by `value` (rad,
/// or m for a prismatic joint).
#[inline]
pub(crate) fn joint_motion(joint: &RobotJoint, value: f64) -> Pose {
    let a = joint.axis;
    if joint.prismatic {
        return Pose {
            translation_m: [a[0] * value, a[1] * value, a[2] * value],
            ..Pose::IDENTITY
        };
    }
    let (s, c) = sin_cos(value);
    Pose {
        rotation: rodrigues(&a, s, c),
        translation_m: [0.0; 3],
    }
}

/// Rodrigues' rotation `R = c·I + s·[a]× + (1 − c)·a·aᵀ` about the unit axis `a` by the
/// angle of sine `s` and cosine `c`.
#[inline]
fn rodrigues(a: &[f64; 3], s: f64, c: f64) -> [[f64; 3]; 3] {
    let t = 1.0 - c;
    let [x, y, z] = *a;
    [
        [c + t * x * x, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, c + t * y * y, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, c + t * z * z],
    ]
}

/// `frame · motion(joint, value)` given the sine and cosine of a revolute joint's angle
/// (ignored for a prismatic joint): about a coordinate axis of the joint frame (the usual
/// URDF axes, either sign) by turning two columns, otherwise by composing Rodrigues'
/// rotation; along the axis by moving the translation.
#[inline(always)]
fn apply_motion(frame: &mut Pose, joint: &RobotJoint, value: f64, (s, c): (f64, f64)) {
    let a = &joint.axis;
    if joint.prismatic {
        let t = frame.rotate(&[a[0] * value, a[1] * value, a[2] * value]);
        for (x, d) in frame.translation_m.iter_mut().zip(t) {
            *x += d;
        }
        return;
    }
    // A unit axis along a coordinate axis has ±1 there: the sign turns the angle.
    if a[0] == 0.0 && a[1] == 0.0 {
        frame.then_turn::<0, 1>(a[2] * s, c);
    } else if a[2] == 0.0 && a[0] == 0.0 {
        frame.then_turn::<2, 0>(a[1] * s, c);
    } else if a[1] == 0.0 && a[2] == 0.0 {
        frame.then_turn::<1, 2>(a[0] * s, c);
    } else {
        *frame = frame.compose(&Pose {
            rotation: rodrigues(a, s, c),
            translation_m: [0.0; 3],
        });
    }
}

/// The deviation `Δ = Tx(x)·Ty(y)·Tz(z)·Rx(rx)·Ry(ry)·Rz(rz)` of `d = [x, y, z, rx, ry, rz]`
/// (m, rad), as the calibration library's placement chains compose it
/// (`hapcal_kinematics::Chain::from_placements`).
pub(crate) fn deviation_pose(d: &[f64; 6]) -> Pose {
    let (sx, cx) = sin_cos(d[3]);
    let (sy, cy) = sin_cos(d[4]);
    let (sz, cz) = sin_cos(d[5]);
    Pose::translation([d[0], d[1], d[2]])
        .compose(&Pose::rot_x(sx, cx))
        .compose(&Pose::rot_y(sy, cy))
        .compose(&Pose::rot_z(sz, cz))
}

/// A joint's origin `nominal · Δ(d) · motion(offset)` at the placement deviation `d = [x, y,
/// z, rx, ry, rz]` (m, rad; its own, or with its rotations grown by a transversal tilt) and
/// its recorded offset.
pub(crate) fn origin_at(joint: &RobotJoint, d: &[f64; 6]) -> Pose {
    (joint.nominal.compose(&deviation_pose(d))).compose(&joint_motion(joint, joint.deviation[6]))
}

/// `R·v`, or `Rᵀ·v` with `inverse`, for the rotation `R` of a revolute joint's motion by the
/// angle of sine `s` and cosine `c` (as [`apply_motion`] turns a frame): two components turn
/// for a coordinate axis.
#[inline(always)]
fn motion_rotate(a: &[f64; 3], (s, c): (f64, f64), v: &[f64; 3], inverse: bool) -> [f64; 3] {
    let turn = |i: usize, j: usize, s: f64| {
        let mut out = *v;
        out[i] = c * v[i] - s * v[j];
        out[j] = s * v[i] + c * v[j];
        out
    };
    let sign = if inverse { -1.0 } else { 1.0 };
    if a[0] == 0.0 && a[1] == 0.0 {
        turn(0, 1, sign * a[2] * s)
    } else if a[2] == 0.0 && a[0] == 0.0 {
        turn(2, 0, sign * a[1] * s)
    } else if a[1] == 0.0 && a[2] == 0.0 {
        turn(1, 2, sign * a[0] * s)
    } else {
        let r = Pose {
            rotation: rodrigues(a, s, c),
            translation_m: [0.0; 3],
        };
        if inverse {
            r.inverse_rotate(v)
        } else {
            r.rotate(v)
        }
    }
}

/// Adds a weight `w` at `c` to a subtree's sums `[Σw, Σw·c]`.
#[inline(always)]
fn add_weight(s: &mut [f64; 4], w: f64, c: &[f64; 3]) {
    s[0] += w;
    s[1] += w * c[0];
    s[2] += w * c[1];
    s[3] += w * c[2];
}

/// The unit axis `a` of a joint frame in the root frame, `frame`'s rotation times `a`: a
/// column of it, signed, for a coordinate axis (as [`apply_motion`] tells them apart).
#[inline(always)]
fn axis_in(frame: &Pose, a: &[f64; 3]) -> [f64; 3] {
    let r = &frame.rotation;
    let column = |j: usize, s: f64| [s * r[0][j], s * r[1][j], s * r[2][j]];
    if a[0] == 0.0 && a[1] == 0.0 {
        column(2, a[2])
    } else if a[2] == 0.0 && a[0] == 0.0 {
        column(1, a[1])
    } else if a[1] == 0.0 && a[2] == 0.0 {
        column(0, a[0])
    } else {
        frame.rotate(a)
    }
}

/// `pose` applied to the point `p`.
#[inline]
pub(crate) fn transform_point(pose: &Pose, p: &[f64; 3]) -> [f64; 3] {
    let r = pose.rotate(p);
    let t = pose.translation_m;
    [r[0] + t[0], r[1] + t[1], r[2] + t[2]]
}

#[inline]
fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl Robot {
    /// Number of moving joints n.
    pub fn n_joints(&self) -> usize {
        self.joints.len()
    }

    /// Joint names (URDF `<joint name>`), in the order of `q`.
    pub fn joint_names(&self) -> &[String] {
        &self.joint_names
    }

    /// Joint limits `(lower, upper)`, rad (m for a prismatic joint); infinite for a
    /// continuous joint.
    pub fn limits(&self) -> &[(f64, f64)] {
        &self.limits
    }

    /// Whether joint `j` is prismatic (its `q` in m).
    ///
    /// # Panics
    /// If `j ≥ n_joints()`.
    #[track_caller]
    pub fn is_prismatic(&self, j: usize) -> bool {
        self.joints[j].prismatic
    }

    /// The tip link names, in the order of the tip indices.
    pub fn tip_names(&self) -> &[String] {
        &self.tip_names
    }

    /// The index of the tip link `name`, if it is a tip.
    pub fn tip_index(&self, name: &str) -> Option<usize> {
        self.tip_names.iter().position(|t| t == name)
    }

    /// The compliance of each joint (0 = rigid): rad/(N·m) under [`GravityModel::Masses`],
    /// rad/m under [`GravityModel::Lumped`].
    pub fn compliances(&self) -> &[f64] {
        &self.compliance
    }

    /// How the gravity loads are computed.
    pub fn gravity_model(&self) -> GravityModel {
        self.gravity
    }

    /// Whether any joint is compliant (the deflection is not the identity).
    pub fn has_compliance(&self) -> bool {
        self.compliance.iter().any(|&k| k != 0.0)
    }

    /// An identified frame of the calibration's sidecar by name: `instrument` (the robot's
    /// root frame in the instrument's frame) or `marker1`, `marker2`, … (a marker's frame in
    /// its tip's frame); `None` if the calibration identified none of that name.
    pub fn frame(&self, name: &str) -> Option<Pose> {
        (self.frames.iter())
            .find(|(n, _)| n == name)
            .map(|(_, p)| *p)
    }

    /// The calibration record of the sidecar (`hapcal-contract`), if the robot has one: the
    /// model's name, every value with its σ, the covariance, the torque source, the region.
    pub fn calibration(&self) -> Option<&hapcal_contract::Calibration> {
        self.record.as_ref()
    }

    /// Whether the readings `q` (rad, m for a prismatic joint) lie outside the region the
    /// calibration was fitted on (the record's `[region]`: a joint more than
    /// `hapcal_contract::REGION_SLACK_SHARE` of its training range past it): the joint
    /// farthest past its range (by share of the range) and by how much (rad or m; positive
    /// above the range, negative below); `None` inside, or without a recorded region.
    /// Allocation-free.
    ///
    /// # Errors
    /// [`Error::Length`] unless `q` has n entries; [`Error::NotFinite`] for a NaN or infinite
    /// reading.
    pub fn outside_region(&self, q: &[f64]) -> Result<Option<(usize, f64)>, Error> {
        self.check_joints("joint angles", q)?;
        Ok(farthest_outside(
            (self.region.iter()).map(|&(j, min, max, slack)| (j, q[j], min, max, slack)),
        ))
    }

    /// The same robot with compliances `k` (one per joint; rad/(N·m) or rad/m as
    /// [`Robot::gravity_model`]), e.g. a rigid copy with zeros.
    ///
    /// # Errors
    /// [`Error::Length`] unless `k` has n entries; [`Error::NotFinite`] for a NaN or infinite
    /// compliance.
    pub fn with_compliances(&self, k: &[f64]) -> Result<Robot, Error> {
        check_len("compliances", self.n_joints(), k.len())?;
        check_finite("compliances", k)?;
        let mut robot = self.clone();
        robot.compliance.copy_from_slice(k);
        Ok(robot)
    }

    /// Buffers for this robot's evaluation calls (allocates; make it once).
    pub fn workspace(&self) -> RobotWorkspace {
        let n = self.n_joints();
        RobotWorkspace {
            frames: vec![Pose::IDENTITY; n],
            theta: vec![0.0; n],
            torque: vec![0.0; n],
            jac: vec![[0.0; 6]; n],
            trial: vec![0.0; n],
            command: vec![0.0; n],
            nominal: vec![Pose::IDENTITY; n],
            moment: vec![[0.0; 3]; n],
            tilt: vec![[0.0; 3]; n],
            load_at: vec![0.0; n],
            sums: vec![[0.0; 4]; n],
            sin_cos: vec![(0.0, 1.0); n],
            load_sin_cos: vec![(0.0, 1.0); n],
            gravity_local: vec![[0.0; 3]; n],
        }
    }

    pub(crate) fn check_joints(&self, what: &'static str, q: &[f64]) -> Result<(), Error> {
        check_len(what, self.n_joints(), q.len())?;
        check_finite(what, q)
    }

    pub(crate) fn check_tip(&self, tip: usize) -> Result<(), Error> {
        if tip < self.tips.len() {
            Ok(())
        } else {
            Err(Error::Invalid {
                what: "tip",
                value: tip as f64,
                expected: "a tip index below the number of tips",
            })
        }
    }

    #[track_caller]
    pub(crate) fn check_workspace(&self, ws: &RobotWorkspace) {
        assert_eq!(
            ws.frames.len(),
            self.n_joints(),
            "a workspace of another robot"
        );
    }

    /// One forward pass: each joint's frame after its motion at `q` into `frames` (root
    /// frame; parents come before their children), from each joint's origin `origin(k)` and
    /// the sine and cosine `sin_cos(k)` of a revolute joint's angle `q[k]`.
    #[inline(always)]
    fn pass(
        &self,
        q: &[f64],
        frames: &mut [Pose],
        origin: impl Fn(usize) -> Pose,
        sin_cos: impl Fn(usize) -> (f64, f64),
    ) {
        for (k, (joint, &value)) in self.joints.iter().zip(q).enumerate() {
            let o = origin(k);
            let mut frame = match joint.parent {
                Some(p) => frames[p].compose_fast(&o),
                None => o,
            };
            let sc = if joint.prismatic {
                (0.0, 1.0)
            } else {
                sin_cos(k)
            };
            apply_motion(&mut frame, joint, value, sc);
            frames[k] = frame;
        }
    }

    /// Joint frames after their motion at `q` into `frames` (q checked by the caller).
    fn forward(&self, q: &[f64], frames: &mut [Pose]) {
        self.pass(q, frames, |k| self.joints[k].origin, |k| sin_cos(q[k]));
    }

    /// Joint frames at `q` of the nominal geometry, where the calibration evaluated the
    /// gravity loads; the sines and cosines from those of the readings `near` (`near_sc`).
    fn forward_nominal(
        &self,
        q: &[f64],
        near: &[f64],
        near_sc: &[(f64, f64)],
        frames: &mut [Pose],
    ) {
        self.pass(
            q,
            frames,
            |k| self.joints[k].nominal,
            |k| sin_cos_near(q[k], near[k], near_sc[k]),
        );
    }

    /// Joint frames at the deflected angles `theta` (the sines and cosines from those of
    /// the readings `near`, `near_sc`), with each joint's rotation deviations grown by its
    /// transversal tilt (`tilt`, rad; zero for a joint without transversal compliance) if
    /// given.
    fn forward_deflected(
        &self,
        theta: &[f64],
        near: &[f64],
        near_sc: &[(f64, f64)],
        tilt: Option<&[[f64; 3]]>,
        frames: &mut [Pose],
    ) {
        let sc = |k: usize| sin_cos_near(theta[k], near[k], near_sc[k]);
        match tilt {
            None => self.pass(theta, frames, |k| self.joints[k].origin, sc),
            Some(tilt) => self.pass(
                theta,
                frames,
                |k| {
                    let (joint, t) = (&self.joints[k], &tilt[k]);
                    if *t == [0.0; 3] {
                        joint.origin
                    } else {
                        let d = &joint.deviation;
                        let d = [d[0], d[1], d[2], d[3] + t[0], d[4] + t[1], d[5] + t[2]];
                        origin_at(joint, &d)
                    }
                },
                sc,
            ),
        }
    }

    /// The pose of tip `tip` (its marker frame on the tip link) from the joint frames.
    #[inline]
    pub(crate) fn tip_from(&self, tip: usize, frames: &[Pose]) -> Pose {
        let t = &self.tips[tip];
        let link = match t.parent {
            Some(p) => frames[p].compose_fast(&t.offset),
            None => t.offset,
        };
        link.compose_fast(&t.marker)
    }

    /// The same robot with a frame `marker` on tip `tip`'s link (in the link's frame, e.g.
    /// the sidecar's `marker1`, [`Robot::frame`]): poses and Jacobians of that tip are then
    /// of the marker frame; the gravity loads are unchanged (the calibration's loads hang at
    /// the tip links).
    ///
    /// # Errors
    /// [`Error::Invalid`] named `tip` for a tip index past the last tip; [`Error::NotFinite`]
    /// for a non-finite pose entry.
    pub fn with_marker(&self, tip: usize, marker: &Pose) -> Result<Robot, Error> {
        self.check_tip(tip)?;
        let parts = [marker.rotation.as_flattened(), &marker.translation_m];
        check_finite_parts("marker", &parts)?;
        let mut robot = self.clone();
        robot.tips[tip].marker = *marker;
        Ok(robot)
    }

    /// Pose of every tip (in the order of [`Robot::tip_names`]) at joint angles `q` (rad, m
    /// for a prismatic joint) of the rigid robot (no deflection), in the root link's frame.
    ///
    /// # Errors
    /// [`Error::Length`] unless `q` has n entries and `out` one per tip; [`Error::NotFinite`]
    /// for a NaN or infinite angle.
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn tip_poses(
        &self,
        q: &[f64],
        ws: &mut RobotWorkspace,
        out: &mut [Pose],
    ) -> Result<(), Error> {
        self.check_workspace(ws);
        self.check_joints("joint angles", q)?;
        check_len("tip poses", self.tips.len(), out.len())?;
        self.forward(q, &mut ws.frames);
        for (tip, pose) in out.iter_mut().enumerate() {
            *pose = self.tip_from(tip, &ws.frames);
        }
        Ok(())
    }

    /// Pose of tip `tip` at joint angles `q` of the rigid robot (see [`Robot::tip_poses`]).
    ///
    /// # Errors
    /// As [`Robot::tip_poses`], and [`Error::Invalid`] named `tip` for a tip index past the
    /// last tip.
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn tip_pose(&self, tip: usize, q: &[f64], ws: &mut RobotWorkspace) -> Result<Pose, Error> {
        self.check_workspace(ws);
        self.check_tip(tip)?;
        self.check_joints("joint angles", q)?;
        self.forward(q, &mut ws.frames);
        Ok(self.tip_from(tip, &ws.frames))
    }

    /// Spatial Jacobian of tip `tip` at joint angles `q` of the rigid robot, and the tip pose.
    ///
    /// `jac` has one column of 6 per joint: for a revolute joint `(w_k × (p − o_k), w_k)`,
    /// for a prismatic one `(w_k, 0)`, with `w_k`, `o_k` the joint's axis and origin and `p`
    /// the tip's origin, all in the root link's frame; zero for a joint not on the tip's path.
    /// Rows 0–2: tip-origin velocity, m/rad (m/m); rows 3–5: angular velocity, rad/rad
    /// (Siciliano et al., *Robotics*, 2009, §3.1.3; the calibration library's
    /// `Chain::geometric_jacobian`).
    ///
    /// # Errors
    /// As [`Robot::tip_pose`], and [`Error::Length`] unless `jac` has n columns.
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn spatial_jacobian(
        &self,
        tip: usize,
        q: &[f64],
        ws: &mut RobotWorkspace,
        jac: &mut [[f64; 6]],
    ) -> Result<Pose, Error> {
        self.check_workspace(ws);
        self.check_tip(tip)?;
        self.check_joints("joint angles", q)?;
        check_len("jacobian columns", self.n_joints(), jac.len())?;
        self.forward(q, &mut ws.frames);
        Ok(self.jacobian_from(tip, &ws.frames, jac, false))
    }

    /// Body Jacobian of tip `tip` at joint angles `q` of the rigid robot, and the tip pose:
    /// the spatial Jacobian's columns expressed in the tip frame, `diag(Rᵀ, Rᵀ)·J_s` (see
    /// [`Robot::spatial_jacobian`]; rows and units alike).
    ///
    /// # Errors
    /// As [`Robot::spatial_jacobian`].
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn body_jacobian(
        &self,
        tip: usize,
        q: &[f64],
        ws: &mut RobotWorkspace,
        jac: &mut [[f64; 6]],
    ) -> Result<Pose, Error> {
        self.check_workspace(ws);
        self.check_tip(tip)?;
        self.check_joints("joint angles", q)?;
        check_len("jacobian columns", self.n_joints(), jac.len())?;
        self.forward(q, &mut ws.frames);
        Ok(self.jacobian_from(tip, &ws.frames, jac, true))
    }

    /// Jacobian columns of `tip` from the joint frames; returns the tip pose.
    fn jacobian_from(&self, tip: usize, frames: &[Pose], jac: &mut [[f64; 6]], body: bool) -> Pose {
        let pose = self.tip_from(tip, frames);
        self.columns_from(tip, frames, &pose, jac, body);
        pose
    }

    /// Jacobian columns of `tip`, whose pose is `pose`, from the joint frames (at the
    /// deflected angles θ, the rigid Jacobian at θ: the compliance's own
    /// `∂θ/∂q = (I − K·∂τ/∂θ)⁻¹`, a relative change of about `k·∂τ/∂θ`, is left out).
    pub(crate) fn columns_from(
        &self,
        tip: usize,
        frames: &[Pose],
        pose: &Pose,
        jac: &mut [[f64; 6]],
        body: bool,
    ) {
        let p = pose.translation_m;
        for col in jac.iter_mut() {
            *col = [0.0; 6];
        }
        let mut on_path = self.tips[tip].parent;
        while let Some(k) = on_path {
            let joint = &self.joints[k];
            let w = axis_in(&frames[k], &joint.axis);
            let (lin, ang) = if joint.prismatic {
                (w, [0.0; 3])
            } else {
                (cross(&w, &sub(&p, &frames[k].translation_m)), w)
            };
            let (lin, ang) = if body {
                (pose.inverse_rotate(&lin), pose.inverse_rotate(&ang))
            } else {
                (lin, ang)
            };
            jac[k] = [lin[0], lin[1], lin[2], ang[0], ang[1], ang[2]];
            on_path = joint.parent;
        }
    }

    /// Gravity torque of every joint at joint angles `q` (no deflection), into `tau`: N·m
    /// under [`GravityModel::Masses`], m under [`GravityModel::Lumped`]; 0 for a prismatic
    /// joint.
    ///
    /// `τ_j = w_j · Σ_{i ⪰ j} (c_i − o_j) × (m_i·g₀·ĝ)` over the masses on links below joint
    /// `j` (Siciliano et al., *Robotics*, 2009, §7.2; summed over the subtree, Featherstone,
    /// *Rigid Body Dynamics Algorithms*, 2008, §4.1), or with lumped unit weights at the
    /// origin of every joint below and every tip below, `τ̂_j = w_j · Σ (o_i − o_j) × ĝ`
    /// (`hapcal_problems::GravityCompliance::joint_loads`).
    ///
    /// # Errors
    /// [`Error::Length`] unless `q` and `tau` have n entries; [`Error::NotFinite`] for a NaN
    /// or infinite angle.
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn gravity_torques(
        &self,
        q: &[f64],
        ws: &mut RobotWorkspace,
        tau: &mut [f64],
    ) -> Result<(), Error> {
        self.check_workspace(ws);
        self.check_joints("joint angles", q)?;
        check_len("gravity torques", self.n_joints(), tau.len())?;
        self.forward(q, &mut ws.frames);
        self.loads_from(&ws.frames, false, tau, None, &mut ws.sums);
        Ok(())
    }

    /// The gravity torques of the nominal geometry at the load angles `ws.load_at` into
    /// `ws.torque` (the sines and cosines from those of the readings `near`, `ws.sin_cos`),
    /// without the joints' frames in the root: two passes of three- and four-vectors in the
    /// joints' own frames. Forward, gravity's direction in each joint frame `g_j = R_jᵀ·ĝ` (one rotation by the
    /// joint's origin and motion); backward, each subtree's weight `W_j` and first moment
    /// `C_j = Σ w·c` in joint `j`'s frame (a child's moved into its parent's frame by its
    /// origin and motion), and `τ_j = a_j · (C_j × g_j)` (the moment `(C − W·o_j) × ĝ` of
    /// [`Robot::loads_from`] in the joint's frame, Featherstone, *Rigid Body Dynamics
    /// Algorithms*, 2008, §4.1). Linear in the joint count.
    fn nominal_torques(&self, near: &[f64], ws: &mut RobotWorkspace) {
        let RobotWorkspace {
            load_at: at,
            sin_cos: near_sc,
            load_sin_cos: ws_sc,
            gravity_local: g_local,
            sums,
            torque: tau,
            ..
        } = ws;
        // The translation of joint k's frame in its parent's (origin and motion).
        let local_t = |k: usize| {
            let joint = &self.joints[k];
            let t = joint.nominal.translation_m;
            if joint.prismatic {
                let a = joint.axis;
                let v = at[k];
                let d = joint.nominal.rotate(&[a[0] * v, a[1] * v, a[2] * v]);
                [t[0] + d[0], t[1] + d[1], t[2] + d[2]]
            } else {
                t
            }
        };
        for (k, joint) in self.joints.iter().enumerate() {
            let sc = if joint.prismatic {
                (0.0, 1.0)
            } else {
                sin_cos_near(at[k], near[k], near_sc[k])
            };
            ws_sc[k] = sc;
            let g = match joint.parent {
                Some(p) => g_local[p],
                None => self.gravity_dir,
            };
            let r = &joint.nominal;
            let g = if r.has_identity_rotation() {
                g
            } else {
                r.inverse_rotate(&g)
            };
            g_local[k] = if joint.prismatic {
                g
            } else {
                motion_rotate(&joint.axis, sc, &g, true)
            };
        }
        self.hang_weights(sums, true, |_, c| *c, local_t);
        for j in (0..self.joints.len()).rev() {
            let joint = &self.joints[j];
            let [w, cx, cy, cz] = sums[j];
            let c = [cx, cy, cz];
            tau[j] = if joint.prismatic {
                0.0
            } else {
                dot(&joint.axis, &cross(&c, &g_local[j]))
            };
            if let Some(p) = joint.parent {
                // C_j in the parent's frame: R_origin·R_motion·C_j + W_j·t.
                let c = if joint.prismatic {
                    c
                } else {
                    motion_rotate(&joint.axis, ws_sc[j], &c, false)
                };
                let r = &joint.nominal;
                let c = if r.has_identity_rotation() {
                    c
                } else {
                    r.rotate(&c)
                };
                let t = local_t(j);
                let s = &mut sums[p];
                s[0] += w;
                s[1] += c[0] + w * t[0];
                s[2] += c[1] + w * t[1];
                s[3] += c[2] + w * t[2];
            }
        }
    }

    /// Sets each joint's `sums` to the weight `w` and first moment `w·c` hung on it alone (the
    /// subtrees not yet summed): the link masses' `m·g₀` at their centres, or the lumped unit
    /// weights at the origin of every loaded joint below it (`joint_origin(i)` for joint i)
    /// and at every loaded tip (its offset, the nominal one with `nominal`), a point `c` of
    /// joint `j`'s frame placed by `place(j, c)` in the frame the sums are kept in.
    #[inline(always)]
    fn hang_weights(
        &self,
        sums: &mut [[f64; 4]],
        nominal: bool,
        place: impl Fn(usize, &[f64; 3]) -> [f64; 3],
        joint_origin: impl Fn(usize) -> [f64; 3],
    ) {
        sums.fill([0.0; 4]);
        match self.gravity {
            GravityModel::Masses => {
                for m in &self.masses {
                    let c = place(m.joint, &m.com_m);
                    add_weight(&mut sums[m.joint], m.mass_kg * self.gravity_m_s2, &c);
                }
            }
            GravityModel::Lumped => {
                for (i, joint) in self.joints.iter().enumerate() {
                    if let (true, Some(p)) = (joint.weight, joint.parent) {
                        add_weight(&mut sums[p], 1.0, &joint_origin(i));
                    }
                }
                for tip in &self.tips {
                    if let (true, Some(p)) = (tip.weight, tip.parent) {
                        let offset = match nominal {
                            true => &tip.nominal_offset,
                            false => &tip.offset,
                        };
                        add_weight(&mut sums[p], 1.0, &place(p, &offset.translation_m));
                    }
                }
            }
        }
    }

    /// The gravity torques (and with `moment` the moment vectors about each joint's origin,
    /// root frame) of the joints whose frames are `frames`; the tips' nominal offsets with
    /// `nominal`. One pass: every load is a weight `w` along the one gravity direction `ĝ`,
    /// so each joint's subtree needs only its weight `W = Σ w` and first moment `C = Σ w·c`
    /// about the root (children follow their parents in the joint order, so the sums run
    /// backward), and `m_j = (C_j − W_j·o_j) × ĝ`, `τ_j = w_j · m_j` (Featherstone, *Rigid
    /// Body Dynamics Algorithms*, 2008, §4.1), linear in the joint count.
    fn loads_from(
        &self,
        frames: &[Pose],
        nominal: bool,
        tau: &mut [f64],
        mut moment: Option<&mut [[f64; 3]]>,
        sums: &mut [[f64; 4]],
    ) {
        let place = |j: usize, c: &[f64; 3]| transform_point(&frames[j], c);
        self.hang_weights(sums, nominal, place, |i| frames[i].translation_m);
        for j in (0..self.joints.len()).rev() {
            if let Some(p) = self.joints[j].parent {
                let s = sums[j];
                for (a, b) in sums[p].iter_mut().zip(s) {
                    *a += b;
                }
            }
        }
        let g = &self.gravity_dir;
        for (j, joint) in self.joints.iter().enumerate() {
            let [w, cx, cy, cz] = sums[j];
            let o = &frames[j].translation_m;
            let m = if joint.prismatic {
                [0.0; 3]
            } else {
                cross(&[cx - w * o[0], cy - w * o[1], cz - w * o[2]], g)
            };
            tau[j] = dot(&axis_in(&frames[j], &joint.axis), &m);
            if let Some(moment) = moment.as_deref_mut() {
                moment[j] = m;
            }
        }
    }

    /// The joint angles θ the calibrated robot takes when commanded `q` (rad, m for a
    /// prismatic joint), into `theta`, as the calibration library predicts them
    /// (`hapcal_problems::CalibratedModel`): `θ = q + k∘τ(θ_L) + h(q)` with the gravity
    /// torques τ ([`Robot::gravity_torques`], evaluated on the nominal geometry as the
    /// calibration evaluated them) at `θ_L = q`, or with the record's torque equilibrium at
    /// the fixed point `θ_L = q + k∘τ(θ_L)`, iterated from `q` until no joint moves by more
    /// than [`DEFLECTION_TOLERANCE_RAD`] or [`DEFLECTION_ITERATIONS`] (Judd & Knasinski 1990
    /// for the compliance model), and `h` the joint harmonics. A transversal compliance tilts
    /// its joint's origin (`c·m⊥` added to its rotation deviations); the tilted frames are
    /// those [`Robot::deflected_tip_poses`] evaluates. `theta = q` without compliance or
    /// harmonics.
    ///
    /// # Errors
    /// [`Error::Length`] unless `q` and `theta` have n entries; [`Error::NotFinite`] for a
    /// NaN or infinite angle.
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn deflect(
        &self,
        q: &[f64],
        ws: &mut RobotWorkspace,
        theta: &mut [f64],
    ) -> Result<Deflection, Error> {
        self.check_workspace(ws);
        self.check_joints("joint angles", q)?;
        check_len("deflected joint angles", self.n_joints(), theta.len())?;
        Ok(self.deflect_unchecked(q, ws, theta))
    }

    /// [`Robot::deflect`] on checked inputs; leaves `ws.frames` at the joint frames of θ.
    /// The sines and cosines of the readings come from libm once (into `ws.sin_cos`); those
    /// of the load angles and of θ, which differ from the readings by the deflection, from
    /// them ([`sin_cos_near`]).
    pub(crate) fn deflect_unchecked(
        &self,
        q: &[f64],
        ws: &mut RobotWorkspace,
        theta: &mut [f64],
    ) -> Deflection {
        theta.copy_from_slice(q);
        let mut out = Deflection {
            iterations: 0,
            final_step_rad: 0.0,
            converged: true,
        };
        for ((sc, &value), joint) in ws.sin_cos.iter_mut().zip(q).zip(&self.joints) {
            if !joint.prismatic {
                *sc = sin_cos(value);
            }
        }
        let tilted = !self.transversal.is_empty();
        if self.has_compliance() || tilted {
            // Where the loads are evaluated: the readings, or the torque equilibrium
            // θ = q + k∘τ(θ) iterated from them (`CalibratedModel::load_angles`).
            ws.load_at.copy_from_slice(q);
            if self.equilibrium && self.has_compliance() {
                for iteration in 1..=DEFLECTION_ITERATIONS {
                    self.nominal_torques(q, ws);
                    let mut step: f64 = 0.0;
                    let values = q.iter().zip(&self.compliance).zip(&ws.torque);
                    for (t, ((q, k), tau)) in ws.load_at.iter_mut().zip(values) {
                        let next = q + k * tau;
                        step = step.max((next - *t).abs());
                        *t = next;
                    }
                    out = Deflection {
                        iterations: iteration,
                        final_step_rad: step,
                        converged: step <= DEFLECTION_TOLERANCE_RAD,
                    };
                    if out.converged {
                        break;
                    }
                }
            }
            if tilted {
                // The tilts need the moment vectors and the nominal frames in the root.
                self.forward_nominal(&ws.load_at, q, &ws.sin_cos, &mut ws.nominal);
                let moment = Some(&mut ws.moment[..]);
                self.loads_from(&ws.nominal, true, &mut ws.torque, moment, &mut ws.sums);
            } else {
                self.nominal_torques(q, ws);
            }
            let values = q.iter().zip(&self.compliance).zip(&ws.torque);
            for (t, ((q, k), tau)) in theta.iter_mut().zip(values) {
                *t = q + k * tau;
            }
            if tilted {
                self.tilts(&ws.nominal, &ws.torque, &ws.moment, &mut ws.tilt);
            }
        }
        for h in &self.harmonics {
            let (s, c) = sin_cos(f64::from(h.order) * q[h.joint]);
            theta[h.joint] += h.coef * if h.sine { s } else { c };
        }
        let tilt = if tilted { Some(&ws.tilt[..]) } else { None };
        self.forward_deflected(theta, q, &ws.sin_cos, tilt, &mut ws.frames);
        out
    }

    /// Each joint's rotation deviation added by its transversal compliance, rad, from the
    /// nominal frames at the load angles, their torques and moment vectors:
    /// `c·m⊥` in the joint's frame before its motion, or for a per-axis term `c·(u·m⊥)·u`
    /// (`hapcal_problems::TransversalTerm::tilt`).
    fn tilts(&self, frames: &[Pose], tau: &[f64], moment: &[[f64; 3]], tilt: &mut [[f64; 3]]) {
        tilt.fill([0.0; 3]);
        for t in &self.transversal {
            let j = t.joint;
            let joint = &self.joints[j];
            let w = frames[j].rotate(&joint.axis);
            let m = moment[j];
            let normal = [
                m[0] - tau[j] * w[0],
                m[1] - tau[j] * w[1],
                m[2] - tau[j] * w[2],
            ];
            let bent = match t.direction {
                None => normal,
                Some(u) => {
                    let u = frames[j].rotate(&u);
                    let along = dot(&u, &normal);
                    [u[0] * along, u[1] * along, u[2] * along]
                }
            };
            // The frame before the joint's motion: its parent's frame times its origin.
            let before =
                (joint.parent.map_or(Pose::IDENTITY, |p| frames[p])).compose(&joint.nominal);
            let local = before.inverse_rotate(&bent);
            for (a, b) in tilt[j].iter_mut().zip(local) {
                *a += t.compliance * b;
            }
        }
    }

    /// Pose of every tip of the calibrated robot commanded `q`: deflected under its own
    /// weight, tilted by its transversal compliances, with its joint harmonics (see
    /// [`Robot::deflect`] and [`Robot::tip_poses`]): the calibration's prediction, with the
    /// iterations taken.
    ///
    /// # Errors
    /// As [`Robot::tip_poses`].
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn deflected_tip_poses(
        &self,
        q: &[f64],
        ws: &mut RobotWorkspace,
        out: &mut [Pose],
    ) -> Result<Deflection, Error> {
        self.check_workspace(ws);
        self.check_joints("joint angles", q)?;
        check_len("tip poses", self.tips.len(), out.len())?;
        let deflection = self.deflect_frames(q, ws);
        for (tip, pose) in out.iter_mut().enumerate() {
            *pose = self.tip_from(tip, &ws.frames);
        }
        Ok(deflection)
    }

    /// The calibrated pose of tip `tip` at the command `q` (deflected, tilted, with
    /// harmonics: [`Robot::deflected_tip_poses`]) and its spatial Jacobian at the deflected
    /// angles (as [`Robot::spatial_jacobian`] at θ; the compliance's own
    /// `∂θ/∂q = (I − K·∂τ/∂θ)⁻¹`, a relative change of about `k·∂τ/∂θ`, left out): what a
    /// controller needs per cycle, from one deflection.
    ///
    /// # Errors
    /// As [`Robot::spatial_jacobian`].
    ///
    /// # Panics
    /// If `ws` was made for another robot.
    #[track_caller]
    pub fn deflected_spatial_jacobian(
        &self,
        tip: usize,
        q: &[f64],
        ws: &mut RobotWorkspace,
        jac: &mut [[f64; 6]],
    ) -> Result<(Pose, Deflection), Error> {
        self.check_workspace(ws);
        self.check_tip(tip)?;
        self.check_joints("joint angles", q)?;
        check_len("jacobian columns", self.n_joints(), jac.len())?;
        let deflection = self.deflect_frames(q, ws);
        let pose = self.jacobian_from(tip, &ws.frames, jac, false);
        Ok((pose, deflection))
    }

    /// [`Robot::deflect`] at the command `q` (checked by the caller) into `ws.theta`, leaving
    /// `ws.frames` at the deflected joint frames (for [`Robot::tip_from`] and
    /// [`Robot::columns_from`]).
    pub(crate) fn deflect_frames(&self, q: &[f64], ws: &mut RobotWorkspace) -> Deflection {
        let mut theta = core::mem::take(&mut ws.theta);
        let deflection = self.deflect_unchecked(q, ws, &mut theta);
        ws.theta = theta;
        deflection
    }
}
