//! A chain with its parameter deviations fixed: the fast path for many configurations.
//!
//! Between two joints, every factor of a [`Chain`] is constant once `x` is fixed (fixed
//! transforms and parameter screws). [`FrozenChain`] folds each such run into one rigid
//! transform (3 × 3 rotation matrix + translation), so a configuration costs one matrix
//! product per joint instead of one quaternion product per factor: a URDF placement has
//! 6 deviation screws and a fixed origin per joint, a D-H row 3 of its 4 screws. The
//! parameter Jacobian needs the world frame of every parameter screw; it is the world frame
//! at the start of its run times a constant local frame, precomputed here too.
//!
//! Source: the product-of-exponentials view of a serial chain (R. M. Murray, Z. Li,
//! S. S. Sastry, *A Mathematical Introduction to Robotic Manipulation*, 1994, §3.2): constant
//! factors between joints multiply out once.

use std::ops::Range;

use nalgebra::{Matrix3, Point3, Vector3};

use crate::chain::{Chain, Factor, FkWorkspace, Motion};

mod lanes;
#[cfg(test)]
pub(crate) use lanes::every_kernel;
pub use lanes::{LANES, joint_trig_lanes};

/// A rigid transform as a rotation matrix and a translation (m).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Rigid {
    rot: Matrix3<f64>,
    trans: Vector3<f64>,
}

impl Rigid {
    fn identity() -> Rigid {
        Rigid {
            rot: Matrix3::identity(),
            trans: Vector3::zeros(),
        }
    }

    /// `self · other`.
    #[inline]
    fn mul(&self, other: &Rigid) -> Rigid {
        Rigid {
            rot: self.rot * other.rot,
            trans: self.trans + self.rot * other.trans,
        }
    }
}

/// Axis of a joint screw, specialised when it is a coordinate axis (the usual case).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Axis {
    X,
    Y,
    Z,
    General(Vector3<f64>),
}

impl Axis {
    fn new(a: &Vector3<f64>) -> Axis {
        if *a == Vector3::x() {
            Axis::X
        } else if *a == Vector3::y() {
            Axis::Y
        } else if *a == Vector3::z() {
            Axis::Z
        } else {
            Axis::General(*a)
        }
    }

    fn vector(&self) -> Vector3<f64> {
        match self {
            Axis::X => Vector3::x(),
            Axis::Y => Vector3::y(),
            Axis::Z => Vector3::z(),
            Axis::General(a) => *a,
        }
    }
}

/// Right-multiplies the rotation `r` by the rotation of `angle` rad about `axis`, in place.
#[inline]
fn rotate_in_place(r: &mut Matrix3<f64>, axis: Axis, angle: f64) {
    let (s, c) = angle.sin_cos();
    rotate_in_place_sc(r, axis, s, c);
}

/// As [`rotate_in_place`], from the angle's sine `s` and cosine `c`.
#[inline]
fn rotate_in_place_sc(r: &mut Matrix3<f64>, axis: Axis, s: f64, c: f64) {
    // Columns i, j of R·Rot(e_k, θ) for the coordinate axes (i, j, k cyclic):
    // [c·rᵢ + s·rⱼ, −s·rᵢ + c·rⱼ].
    let (i, j) = match axis {
        Axis::X => (1, 2),
        Axis::Y => (2, 0),
        Axis::Z => (0, 1),
        Axis::General(a) => {
            // Rodrigues: Rot = c·I + s·[a]× + (1 − c)·a aᵀ.
            let k = 1.0 - c;
            let rot = Matrix3::new(
                c + k * a.x * a.x,
                k * a.x * a.y - s * a.z,
                k * a.x * a.z + s * a.y,
                k * a.y * a.x + s * a.z,
                c + k * a.y * a.y,
                k * a.y * a.z - s * a.x,
                k * a.z * a.x - s * a.y,
                k * a.z * a.y + s * a.x,
                c + k * a.z * a.z,
            );
            *r *= rot;
            return;
        }
    };
    let ri: Vector3<f64> = r.column(i).into();
    let rj: Vector3<f64> = r.column(j).into();
    r.set_column(i, &(ri * c + rj * s));
    r.set_column(j, &(rj * c - ri * s));
}

/// A joint screw: rotation about / translation along `axis` by `offset + q[joint]`.
#[derive(Clone, Debug, PartialEq)]
struct JointScrew {
    motion: Motion,
    axis: Axis,
    /// Nominal plus the parameter deviation at the frozen `x`, rad or m.
    offset: f64,
    joint: usize,
    /// The parameter of this screw, if any (its column is the joint's twist).
    param: Option<usize>,
    /// `sin(offset)`, `cos(offset)`, for joint angles given by their sine and cosine.
    sin_off: f64,
    cos_off: f64,
}

/// A parameter screw as the distance gradient sees it, in its run's start frame: the
/// derivative of `|P|` is `a·(T × U) − U·c` for a rotation and `U·a` for a translation, with
/// `U`, `T` the unit end-point direction and the end point in that frame.
#[derive(Clone, Debug, PartialEq)]
struct DistanceTap {
    param: usize,
    rotation: bool,
    /// Screw axis.
    a: Vector3<f64>,
    /// `a × o`, `o` the screw frame's origin (m).
    c: Vector3<f64>,
    /// Whether this is the first tap of `param` (in segment order): the lane kernel writes
    /// its term instead of adding it.
    first: bool,
}

/// A parameter screw inside a constant run: its frame relative to the run's start.
#[derive(Clone, Debug, PartialEq)]
struct ParamTap {
    param: usize,
    motion: Motion,
    /// Screw axis in the run's start frame.
    axis_local: Vector3<f64>,
    /// Origin of the screw's frame in the run's start frame, m.
    origin_local: Vector3<f64>,
}

/// One constant run followed by at most one joint screw.
#[derive(Clone, Debug, PartialEq)]
struct Segment {
    fixed: Rigid,
    /// The run's parameter screws: a range of [`FrozenChain::taps`].
    taps: Range<usize>,
    joint: Option<JointScrew>,
    /// All parameter screws of the run and of its joint, for the distance gradient: a range of
    /// [`FrozenChain::distance_taps`].
    distance_taps: Range<usize>,
    /// `fixed` times the rotation of a revolute joint by its offset (so that the joint itself
    /// rotates by `q` alone), for the lane kernel; `fixed` otherwise.
    lane_fixed: Rigid,
}

impl Segment {
    /// The segment of run `fixed` with the parameter screws `taps[first_tap..]` and `joint`;
    /// appends its distance taps to `distance_taps`.
    fn new(
        fixed: Rigid,
        taps: &[ParamTap],
        first_tap: usize,
        joint: Option<JointScrew>,
        distance_taps: &mut Vec<DistanceTap>,
    ) -> Segment {
        let first_distance_tap = distance_taps.len();
        distance_taps.extend(taps[first_tap..].iter().map(|t| DistanceTap {
            param: t.param,
            rotation: t.motion == Motion::Rotation,
            a: t.axis_local,
            c: t.axis_local.cross(&t.origin_local),
            first: false,
        }));
        if let Some(JointScrew {
            motion,
            axis,
            param: Some(param),
            ..
        }) = &joint
        {
            let a = fixed.rot * axis.vector();
            distance_taps.push(DistanceTap {
                param: *param,
                rotation: *motion == Motion::Rotation,
                a,
                c: a.cross(&fixed.trans),
                first: false,
            });
        }
        let mut lane_fixed = fixed;
        if let Some(screw) = &joint
            && screw.motion == Motion::Rotation
        {
            rotate_in_place_sc(
                &mut lane_fixed.rot,
                screw.axis,
                screw.sin_off,
                screw.cos_off,
            );
        }
        Segment {
            fixed,
            taps: first_tap..taps.len(),
            joint,
            distance_taps: first_distance_tap..distance_taps.len(),
            lane_fixed,
        }
    }
}

/// A [`Chain`] with its deviations fixed at some `x`: forward kinematics and the parameter
/// Jacobian for many configurations `q`, with the same results as
/// [`Chain::end_point`] and [`Chain::point_and_jacobian_in`] up to rounding.
///
/// Build it with [`Chain::freeze`] once per `x` (a cost of about one forward kinematics),
/// then evaluate any number of configurations. It allocates nothing per configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct FrozenChain {
    segments: Vec<Segment>,
    /// Parameter screws of all runs, in order (each segment holds a range): one allocation
    /// per chain, not one per run.
    taps: Vec<ParamTap>,
    /// Distance taps of all segments, in order (each segment holds a range).
    distance_taps: Vec<DistanceTap>,
    n_params: usize,
    n_joints: usize,
    /// Whether every parameter has a distance tap (else the lane kernel zeroes the gradient
    /// first).
    all_params_tapped: bool,
    /// [`FrozenChain::supports_lanes`], decided once per freeze.
    lanes: bool,
}

/// `[sin q_j, cos q_j]` for each joint angle (rad), the form [`FrozenChain::end_point_trig`]
/// and [`FrozenChain::distance_gradient`] take.
pub fn joint_trig(q: &[f64]) -> Vec<[f64; 2]> {
    q.iter()
        .map(|v| {
            let (s, c) = v.sin_cos();
            [s, c]
        })
        .collect()
}

impl Chain {
    /// The chain with its deviations fixed at `x` (length [`Chain::n_params`], m or rad).
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()`.
    #[track_caller]
    pub fn freeze(&self, x: &[f64]) -> FrozenChain {
        let mut frozen = FrozenChain {
            segments: Vec::with_capacity(self.n_joints() + 1),
            taps: Vec::with_capacity(self.n_params()),
            distance_taps: Vec::with_capacity(self.n_params()),
            n_params: self.n_params(),
            n_joints: self.n_joints(),
            all_params_tapped: true,
            lanes: false,
        };
        self.freeze_into(x, &mut frozen);
        frozen
    }

    /// [`Chain::freeze`] into `frozen` (which may come from another `x` or another chain),
    /// reusing its allocations: for callers that freeze at every evaluation.
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()`.
    #[track_caller]
    pub fn freeze_into(&self, x: &[f64], frozen: &mut FrozenChain) {
        self.check_params_len(x);
        let FrozenChain {
            segments,
            taps,
            distance_taps,
            ..
        } = frozen;
        segments.clear();
        taps.clear();
        distance_taps.clear();
        let mut run = Rigid::identity();
        let mut first_tap = 0;
        for factor in self.factors() {
            match factor {
                Factor::Fixed(t) => {
                    let m = Rigid {
                        rot: *t.rotation.to_rotation_matrix().matrix(),
                        trans: t.translation.vector,
                    };
                    run = run.mul(&m);
                }
                Factor::Screw {
                    motion,
                    axis,
                    nominal,
                    param,
                    joint: None,
                } => {
                    let axis = axis.into_inner();
                    if let Some(j) = *param {
                        taps.push(ParamTap {
                            param: j,
                            motion: *motion,
                            axis_local: run.rot * axis,
                            origin_local: run.trans,
                        });
                    }
                    let value = nominal + param.map_or(0.0, |j| x[j]);
                    if value != 0.0 {
                        match motion {
                            Motion::Rotation => {
                                rotate_in_place(&mut run.rot, Axis::new(&axis), value)
                            }
                            Motion::Translation => run.trans += run.rot * (axis * value),
                        }
                    }
                }
                Factor::Screw {
                    motion,
                    axis,
                    nominal,
                    param,
                    joint: Some(joint),
                } => {
                    let offset = nominal + param.map_or(0.0, |j| x[j]);
                    let (sin_off, cos_off) = offset.sin_cos();
                    segments.push(Segment::new(
                        run,
                        taps,
                        first_tap,
                        Some(JointScrew {
                            motion: *motion,
                            axis: Axis::new(&axis.into_inner()),
                            offset,
                            joint: *joint,
                            param: *param,
                            sin_off,
                            cos_off,
                        }),
                        distance_taps,
                    ));
                    first_tap = taps.len();
                    run = Rigid::identity();
                }
            }
        }
        segments.push(Segment::new(run, taps, first_tap, None, distance_taps));
        // Which parameters have a tap yet: bits of a u128 for up to 128 parameters (no
        // allocation), a vector beyond.
        let n_params = self.n_params();
        let mut bits = 0u128;
        let mut tapped = vec![false; if n_params > 128 { n_params } else { 0 }];
        let mut n_tapped = 0;
        for tap in distance_taps.iter_mut() {
            let seen = match tapped.get_mut(tap.param) {
                Some(t) => std::mem::replace(t, true),
                None => {
                    let bit = 1u128 << tap.param;
                    let seen = bits & bit != 0;
                    bits |= bit;
                    seen
                }
            };
            tap.first = !seen;
            n_tapped += usize::from(!seen);
        }
        frozen.n_params = n_params;
        frozen.n_joints = self.n_joints();
        frozen.all_params_tapped = n_tapped == n_params;
        frozen.lanes = lanes::lanes_apply(&frozen.segments);
    }
}

impl FrozenChain {
    /// Number of parameters of the chain it came from (`jac_out` has `3 ×` this many entries).
    pub fn n_params(&self) -> usize {
        self.n_params
    }

    /// Number of joints (the length of `q`).
    pub fn n_joints(&self) -> usize {
        self.n_joints
    }

    #[track_caller]
    fn check_q(&self, q: &[f64]) {
        assert_eq!(
            q.len(),
            self.n_joints,
            "q has length {}, but the chain has {} joints",
            q.len(),
            self.n_joints
        );
    }

    /// Applies the joint screw of `seg` to `pose`.
    #[inline]
    fn apply_joint(pose: &mut Rigid, screw: &JointScrew, q: &[f64]) {
        let value = screw.offset + q[screw.joint];
        match screw.motion {
            Motion::Rotation => rotate_in_place(&mut pose.rot, screw.axis, value),
            Motion::Translation => pose.trans += pose.rot * (screw.axis.vector() * value),
        }
    }

    /// Forward pass: clears `starts` and pushes, per segment, the world frame at its start
    /// (rotation columns, then translation, m); returns the end point's position (m, base
    /// frame). `trig` as in [`FrozenChain::end_point_trig`], or `None` to evaluate the sines.
    /// Shared by [`FrozenChain::distance_gradient`] and [`FrozenChain::point_and_jacobian`].
    fn forward_with_starts(
        &self,
        q: &[f64],
        trig: Option<&[[f64; 2]]>,
        starts: &mut Vec<[Vector3<f64>; 4]>,
    ) -> Vector3<f64> {
        starts.clear();
        let mut pose = Rigid::identity();
        for seg in &self.segments {
            starts.push([
                pose.rot.column(0).into(),
                pose.rot.column(1).into(),
                pose.rot.column(2).into(),
                pose.trans,
            ]);
            pose = pose.mul(&seg.fixed);
            if let Some(screw) = &seg.joint {
                match trig {
                    Some(t) => Self::apply_joint_trig(&mut pose, screw, q, t),
                    None => Self::apply_joint(&mut pose, screw, q),
                }
            }
        }
        pose.trans
    }

    /// As [`FrozenChain::apply_joint`], a revolute joint's angle given by `[sin q, cos q]`.
    #[inline]
    fn apply_joint_trig(pose: &mut Rigid, screw: &JointScrew, q: &[f64], trig: &[[f64; 2]]) {
        match screw.motion {
            Motion::Rotation => {
                let [sq, cq] = trig[screw.joint];
                let s = screw.sin_off * cq + screw.cos_off * sq;
                let c = screw.cos_off * cq - screw.sin_off * sq;
                rotate_in_place_sc(&mut pose.rot, screw.axis, s, c);
            }
            Motion::Translation => {
                let value = screw.offset + q[screw.joint];
                pose.trans += pose.rot * (screw.axis.vector() * value);
            }
        }
    }

    #[track_caller]
    fn check_trig(&self, trig: &[[f64; 2]]) {
        assert_eq!(
            trig.len(),
            self.n_joints,
            "trig has length {}, but the chain has {} joints",
            trig.len(),
            self.n_joints
        );
    }

    /// End point (m, base frame) for joint angles `q` (rad) whose sines and cosines are given
    /// in `trig` (`trig[j] = [sin q_j, cos q_j]`, see [`joint_trig`]): the same result as
    /// [`FrozenChain::end_point`] up to rounding, without evaluating a sine per joint, for
    /// callers that evaluate the same configurations many times.
    ///
    /// # Panics
    ///
    /// If `q.len()` or `trig.len()` differs from `n_joints()`.
    #[track_caller]
    pub fn end_point_trig(&self, q: &[f64], trig: &[[f64; 2]]) -> Point3<f64> {
        self.check_q(q);
        self.check_trig(trig);
        let mut pose = Rigid::identity();
        for seg in &self.segments {
            pose = pose.mul(&seg.fixed);
            if let Some(screw) = &seg.joint {
                Self::apply_joint_trig(&mut pose, screw, q, trig);
            }
        }
        Point3::from(pose.trans)
    }

    /// End point `P` (m, base frame) and the gradient of its distance from the base origin,
    /// `∂|P|/∂x_j`, written to `grad` (length `n_params()`; m/m for lengths, m/rad for angles):
    /// the cable-encoder measurement of paper eq. 5 and its Jacobian row, in fewer operations
    /// than projecting [`FrozenChain::point_and_jacobian`] (each screw costs one 3-vector dot
    /// product or two, in its run's frame). `trig` as in [`FrozenChain::end_point_trig`], or
    /// `None` to evaluate the sines. At `P = 0` the gradient is 0.
    ///
    /// # Panics
    ///
    /// If `q.len()` or `trig.len()` differs from `n_joints()`, or
    /// `grad.len() != n_params()`.
    #[track_caller]
    pub fn distance_gradient(
        &self,
        q: &[f64],
        trig: Option<&[[f64; 2]]>,
        grad: &mut [f64],
        ws: &mut FkWorkspace,
    ) -> Point3<f64> {
        self.check_q(q);
        if let Some(t) = trig {
            self.check_trig(t);
        }
        assert_eq!(
            grad.len(),
            self.n_params,
            "grad has length {}, expected {} parameters",
            grad.len(),
            self.n_params
        );
        let starts = &mut ws.starts;
        let tip = self.forward_with_starts(q, trig, starts);
        grad.fill(0.0);
        let norm = tip.norm();
        if norm == 0.0 {
            return Point3::from(tip);
        }
        let u = tip / norm;
        for (seg, start) in self.segments.iter().zip(starts.iter()) {
            if seg.distance_taps.is_empty() {
                continue;
            }
            // U and T in the run's start frame: Rᵀu and Rᵀ(P − t).
            let d = tip - start[3];
            let ul = Vector3::new(start[0].dot(&u), start[1].dot(&u), start[2].dot(&u));
            let tl = Vector3::new(start[0].dot(&d), start[1].dot(&d), start[2].dot(&d));
            let v = tl.cross(&ul);
            for tap in &self.distance_taps[seg.distance_taps.clone()] {
                grad[tap.param] += if tap.rotation {
                    tap.a.dot(&v) - ul.dot(&tap.c)
                } else {
                    ul.dot(&tap.a)
                };
            }
        }
        Point3::from(tip)
    }

    /// End point (tip origin) in the base frame, m, for joint angles `q` (rad).
    ///
    /// # Panics
    ///
    /// If `q.len() != n_joints()`.
    #[track_caller]
    pub fn end_point(&self, q: &[f64]) -> Point3<f64> {
        self.check_q(q);
        let mut pose = Rigid::identity();
        for seg in &self.segments {
            pose = pose.mul(&seg.fixed);
            if let Some(screw) = &seg.joint {
                Self::apply_joint(&mut pose, screw, q);
            }
        }
        Point3::from(pose.trans)
    }

    /// End point (m, base frame) and its Jacobian with respect to `x`, written to `jac_out`
    /// (length `3 · n_params()`, column-major 3 × `n_params()`, `jac_out[3*j + k] = ∂p_k/∂x_j`,
    /// m/m for lengths and m/rad for angles), as [`Chain::point_and_jacobian_in`].
    ///
    /// `ws` holds the world frame at the start of each constant run; it grows to the chain
    /// once and is reused, so nothing is allocated per call.
    ///
    /// # Panics
    ///
    /// If `q.len() != n_joints()` or `jac_out.len() != 3 * n_params()`.
    #[track_caller]
    pub fn point_and_jacobian(
        &self,
        q: &[f64],
        jac_out: &mut [f64],
        ws: &mut FkWorkspace,
    ) -> Point3<f64> {
        let starts = &mut ws.starts;
        self.check_q(q);
        assert_eq!(
            jac_out.len(),
            3 * self.n_params,
            "jac_out has length {}, expected 3 × {} parameters",
            jac_out.len(),
            self.n_params
        );
        // Per segment: world rotation columns and translation at its start, then the world
        // frame just before its joint screw is start·fixed (recomputed below).
        let tip = self.forward_with_starts(q, None, starts);
        jac_out.fill(0.0);
        for (seg, start) in self.segments.iter().zip(starts.iter()) {
            let rot = Matrix3::from_columns(&start[..3]);
            let origin = start[3];
            for tap in &self.taps[seg.taps.clone()] {
                let w = rot * tap.axis_local;
                let col = match tap.motion {
                    Motion::Rotation => w.cross(&(tip - (origin + rot * tap.origin_local))),
                    Motion::Translation => w,
                };
                let j = tap.param;
                for (out, c) in jac_out[3 * j..3 * j + 3].iter_mut().zip(col.iter()) {
                    *out += c;
                }
            }
            if let Some(JointScrew {
                motion,
                axis,
                param: Some(j),
                ..
            }) = &seg.joint
            {
                // The world frame just before the joint screw: start · fixed. A rotation
                // leaves its axis and origin in place, so before and after agree.
                let w = rot * (seg.fixed.rot * axis.vector());
                let col = match motion {
                    Motion::Rotation => w.cross(&(tip - (origin + rot * seg.fixed.trans))),
                    Motion::Translation => w,
                };
                for (out, c) in jac_out[3 * j..3 * j + 3].iter_mut().zip(col.iter()) {
                    *out += c;
                }
            }
        }
        Point3::from(tip)
    }
}
