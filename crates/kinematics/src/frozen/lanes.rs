//! Distances and distance gradients of [`LANES`] configurations at once.
//!
//! The same quantities as [`FrozenChain::distance_gradient`], on structure-of-arrays data:
//! every scalar (a coordinate of a point or direction, a joint sine or cosine) becomes a
//! `[f64; LANES]`, one entry per configuration, so that each arithmetic operation is one loop
//! over the lanes, which LLVM turns into SIMD instructions (8 lanes = one AVX-512 register or
//! two AVX2 registers). The instruction set is chosen at run time (`is_x86_feature_detected!`);
//! without AVX2 the same code runs as plain loops. No fused multiply–add is introduced (Rust
//! does not contract `a·b + c`).
//!
//! The kernel moves 3-vectors, not frames, along the chain (about a third of the operations of
//! composing the world frames):
//!
//! - backwards, the end point in the start frame of each constant run `k`,
//!   `T_k = F_k · J_k(q) · T_{k+1}` (`F_k` the run with its joint's offset folded in,
//!   `J_k` the joint rotation), so that `P = T_0`;
//! - forwards, the unit direction `u = P/|P|` in the same frames, `U_0 = u`,
//!   `U_{k+1} = J_k(q)ᵀ · F_kᵀ · U_k`.
//!
//! The distance gradient of each parameter screw of run `k` is then `a·(T_k × U_k) − U_k·c`
//! (rotation) or `U_k·a` (translation), as in [`FrozenChain::distance_gradient`]. The
//! operations differ from the scalar path's, so the two agree to rounding (a few ulps), not
//! bit for bit.

use super::{Axis, FrozenChain, Segment};
use crate::chain::Motion;

/// Number of configurations evaluated together by [`FrozenChain::distance_gradient_lanes`].
pub const LANES: usize = 8;

/// One value per configuration.
type Lane = [f64; LANES];

/// Longest chain (constant runs, i.e. joints + 1) the lane kernel takes; the end point in each
/// run's frame lives on the stack.
const MAX_SEGMENTS: usize = 16;

/// `[sin q_j, cos q_j]` of [`LANES`] configurations in the layout that
/// [`FrozenChain::distance_gradient_lanes`] takes: entry `j` holds joint `j`, its `[0][l]` the
/// sine and `[1][l]` the cosine of configuration `l` (angles in rad).
///
/// # Panics
///
/// If the configurations do not all have the same number of joints.
#[track_caller]
pub fn joint_trig_lanes(qs: [&[f64]; LANES]) -> Vec<[[f64; LANES]; 2]> {
    let n_joints = qs[0].len();
    assert!(
        qs.iter().all(|q| q.len() == n_joints),
        "the configurations have different numbers of joints"
    );
    (0..n_joints)
        .map(|j| {
            let mut t = [[0.0; LANES]; 2];
            for (l, q) in qs.iter().enumerate() {
                let (s, c) = q[j].sin_cos();
                t[0][l] = s;
                t[1][l] = c;
            }
            t
        })
        .collect()
}

#[inline(always)]
fn splat(v: f64) -> Lane {
    [v; LANES]
}

// Plain loops over the lanes (not `array::from_fn`, whose closures LLVM does not always
// inline into vector code).

#[inline(always)]
fn add(a: Lane, b: Lane) -> Lane {
    let mut o = [0.0; LANES];
    for l in 0..LANES {
        o[l] = a[l] + b[l];
    }
    o
}

#[inline(always)]
fn sub(a: Lane, b: Lane) -> Lane {
    let mut o = [0.0; LANES];
    for l in 0..LANES {
        o[l] = a[l] - b[l];
    }
    o
}

#[inline(always)]
fn mul(a: Lane, b: Lane) -> Lane {
    let mut o = [0.0; LANES];
    for l in 0..LANES {
        o[l] = a[l] * b[l];
    }
    o
}

/// `(a₀s₀ + a₁s₁) + a₂s₂` for a constant vector `s`.
#[inline(always)]
fn dot3_s(a: &[Lane; 3], s: [f64; 3]) -> Lane {
    let mut o = [0.0; LANES];
    for l in 0..LANES {
        o[l] = a[0][l] * s[0] + a[1][l] * s[1] + a[2][l] * s[2];
    }
    o
}

/// `(a₀s₀ + a₁s₁) + a₂s₂ + t` for a constant vector `s` and constant `t`.
#[inline(always)]
fn dot3_s_add(a: &[Lane; 3], s: [f64; 3], t: f64) -> Lane {
    let mut o = [0.0; LANES];
    for l in 0..LANES {
        o[l] = a[0][l] * s[0] + a[1][l] * s[1] + a[2][l] * s[2] + t;
    }
    o
}

/// `Rot(e_k, θ) · p` for the coordinate axis `e_k` (`i, j, k` cyclic: `p_i ↦ c·p_i − s·p_j`,
/// `p_j ↦ s·p_i + c·p_j`), from `s = sin θ`, `c = cos θ`. Each axis is written out, so that
/// the coordinates stay in registers.
#[inline(always)]
fn rotate(p: [Lane; 3], axis: Axis, s: Lane, c: Lane) -> [Lane; 3] {
    let [x, y, z] = p;
    match axis {
        Axis::X => [x, sub(mul(c, y), mul(s, z)), add(mul(s, y), mul(c, z))],
        Axis::Y => [add(mul(s, z), mul(c, x)), y, sub(mul(c, z), mul(s, x))],
        // General axes are excluded by `supports_lanes`.
        _ => [sub(mul(c, x), mul(s, y)), add(mul(s, x), mul(c, y)), z],
    }
}

/// `Rot(e_k, θ)ᵀ · p`, as [`rotate`] by `−θ`.
#[inline(always)]
fn rotate_back(p: [Lane; 3], axis: Axis, s: Lane, c: Lane) -> [Lane; 3] {
    let [x, y, z] = p;
    match axis {
        Axis::X => [x, add(mul(c, y), mul(s, z)), sub(mul(c, z), mul(s, y))],
        Axis::Y => [sub(mul(c, x), mul(s, z)), y, add(mul(c, z), mul(s, x))],
        _ => [add(mul(c, x), mul(s, y)), sub(mul(c, y), mul(s, x)), z],
    }
}

impl FrozenChain {
    /// Whether [`FrozenChain::distance_gradient_lanes`] applies: every joint is revolute about a
    /// coordinate axis of its frame (all D-H chains; URDF joints with a general axis and
    /// prismatic joints take the scalar path) and the chain has at most 15 joints. It depends
    /// on the chain's structure only, not on the frozen `x`.
    pub fn supports_lanes(&self) -> bool {
        self.segments.len() <= MAX_SEGMENTS
            && self.segments.iter().all(|s| {
                s.joint.as_ref().is_none_or(|j| {
                    j.motion == Motion::Rotation && !matches!(j.axis, Axis::General(_))
                })
            })
    }

    /// [`FrozenChain::distance_gradient`] for [`LANES`] configurations at once: `trig[j]` holds
    /// the sines (`[0]`) and cosines (`[1]`) of joint `j` of the configurations (see
    /// [`joint_trig_lanes`]). Writes the distance `|P|` of each configuration to `distance_m`
    /// (m, base frame origin to end point) and, when `grad` is given (length `n_params()`),
    /// `grad[j][l] = grad_scale · ∂|P_l|/∂x_j` (`grad_scale` per m: m/m for lengths, m/rad for
    /// angles, times its unit; 0 where `P = 0`). The distances are the same whether or not
    /// `grad` is given; both agree with the scalar path to rounding.
    ///
    /// Source: the distance gradient of [`FrozenChain::distance_gradient`] (paper eq. 5), with
    /// the end point and its direction carried through the runs' frames (module docs).
    ///
    /// # Panics
    ///
    /// If [`FrozenChain::supports_lanes`] is false, `trig.len() != n_joints()`, or
    /// `grad.len() != n_params()`.
    #[track_caller]
    pub fn distance_gradient_lanes(
        &self,
        trig: &[[[f64; LANES]; 2]],
        grad_scale: f64,
        distance_m: &mut [f64; LANES],
        grad: Option<&mut [[f64; LANES]]>,
    ) {
        assert!(
            self.supports_lanes(),
            "the lane kernel needs revolute joints about coordinate axes and at most {} joints",
            MAX_SEGMENTS - 1
        );
        assert_eq!(
            trig.len(),
            self.n_joints,
            "trig has length {}, but the chain has {} joints",
            trig.len(),
            self.n_joints
        );
        match grad {
            Some(g) => {
                assert_eq!(
                    g.len(),
                    self.n_params,
                    "grad has length {}, expected {} parameters",
                    g.len(),
                    self.n_params
                );
                dispatch::<true>(self, trig, grad_scale, distance_m, g);
            }
            None => dispatch::<false>(self, trig, grad_scale, distance_m, &mut []),
        }
    }
}

/// Runs [`kernel`] compiled for the best instruction set of this CPU.
#[inline(always)]
fn dispatch<const GRAD: bool>(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
    distance_m: &mut Lane,
    grad: &mut [Lane],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F (checked just above).
            unsafe { kernel_avx512::<GRAD>(chain, trig, grad_scale, distance_m, grad) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            unsafe { kernel_avx2::<GRAD>(chain, trig, grad_scale, distance_m, grad) };
            return;
        }
    }
    kernel::<GRAD>(chain, trig, grad_scale, distance_m, grad);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
fn kernel_avx512<const GRAD: bool>(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
    distance_m: &mut Lane,
    grad: &mut [Lane],
) {
    kernel::<GRAD>(chain, trig, grad_scale, distance_m, grad);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn kernel_avx2<const GRAD: bool>(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
    distance_m: &mut Lane,
    grad: &mut [Lane],
) {
    kernel::<GRAD>(chain, trig, grad_scale, distance_m, grad);
}

/// `F · (J(q) · p)` for the run `seg` (its joint's offset folded into `F`), or `F · 0` when
/// `p` is `None` (the tip's own origin).
#[inline(always)]
fn run_times_point(seg: &Segment, trig: &[[Lane; 2]], p: Option<[Lane; 3]>) -> [Lane; 3] {
    let f = &seg.lane_fixed;
    let Some(mut p) = p else {
        return [splat(f.trans.x), splat(f.trans.y), splat(f.trans.z)];
    };
    if let Some(screw) = &seg.joint {
        let [s, c] = trig[screw.joint];
        p = rotate(p, screw.axis, s, c);
    }
    let r = &f.rot;
    [
        dot3_s_add(&p, [r[(0, 0)], r[(0, 1)], r[(0, 2)]], f.trans.x),
        dot3_s_add(&p, [r[(1, 0)], r[(1, 1)], r[(1, 2)]], f.trans.y),
        dot3_s_add(&p, [r[(2, 0)], r[(2, 1)], r[(2, 2)]], f.trans.z),
    ]
}

/// The lane kernel; `#[inline(always)]` so that each caller above compiles it for its
/// instruction set. `grad` is empty unless `GRAD`.
#[inline(always)]
fn kernel<const GRAD: bool>(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
    distance_m: &mut Lane,
    grad: &mut [Lane],
) {
    let zero = splat(0.0);
    let segments = &chain.segments;
    // T_k, the end point in the start frame of run k (written for every run when GRAD; the
    // array starts as copies of the last run's, which is its last entry, rather than zeros).
    let Some((last, rest)) = segments.split_last() else {
        *distance_m = zero;
        return;
    };
    let mut p = run_times_point(last, trig, None);
    let mut tips = [p; MAX_SEGMENTS];
    for (k, seg) in rest.iter().enumerate().rev() {
        p = run_times_point(seg, trig, Some(p));
        if GRAD {
            tips[k] = p;
        }
    }
    let tip = p;
    let mut norm = [0.0; LANES];
    for l in 0..LANES {
        norm[l] = (tip[0][l] * tip[0][l] + tip[1][l] * tip[1][l] + tip[2][l] * tip[2][l]).sqrt();
    }
    *distance_m = norm;
    if !GRAD {
        return;
    }
    if !chain.all_params_tapped {
        grad.fill(zero);
    }
    // u = grad_scale · P/|P|, and 0 where P = 0 (then every term below is 0).
    let mut f = [0.0; LANES];
    for l in 0..LANES {
        f[l] = if norm[l] == 0.0 {
            0.0
        } else {
            grad_scale / norm[l]
        };
    }
    let mut ul = [mul(tip[0], f), mul(tip[1], f), mul(tip[2], f)];
    for (seg, tl) in segments.iter().zip(&tips) {
        if !seg.distance_taps.is_empty() {
            // v = T × U, both in the run's start frame.
            let v = [
                sub(mul(tl[1], ul[2]), mul(tl[2], ul[1])),
                sub(mul(tl[2], ul[0]), mul(tl[0], ul[2])),
                sub(mul(tl[0], ul[1]), mul(tl[1], ul[0])),
            ];
            for tap in &seg.distance_taps {
                let a = [tap.a.x, tap.a.y, tap.a.z];
                let term = if tap.rotation {
                    let c = [tap.c.x, tap.c.y, tap.c.z];
                    sub(dot3_s(&v, a), dot3_s(&ul, c))
                } else {
                    dot3_s(&ul, a)
                };
                let g = &mut grad[tap.param];
                *g = if tap.first { term } else { add(*g, term) };
            }
        }
        // U in the next run's start frame: J(q)ᵀ · Fᵀ · U.
        if let Some(screw) = &seg.joint {
            let r = &seg.lane_fixed.rot;
            let w = [
                dot3_s(&ul, [r[(0, 0)], r[(1, 0)], r[(2, 0)]]),
                dot3_s(&ul, [r[(0, 1)], r[(1, 1)], r[(2, 1)]]),
                dot3_s(&ul, [r[(0, 2)], r[(1, 2)], r[(2, 2)]]),
            ];
            let [s, c] = trig[screw.joint];
            ul = rotate_back(w, screw.axis, s, c);
        }
    }
}
