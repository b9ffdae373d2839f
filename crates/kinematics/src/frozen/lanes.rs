//! Distances and distance gradients of [`LANES`] configurations at once.
//!
//! The same operations as [`FrozenChain::distance_gradient`], on structure-of-arrays data:
//! every scalar of the forward kinematics (rotation entries, translation, joint sine and
//! cosine) becomes a `[f64; LANES]`, one entry per configuration, so that each arithmetic
//! operation is one loop over the lanes, which LLVM turns into SIMD instructions (8 lanes = one
//! AVX-512 register or two AVX2 registers). The instruction set is chosen at run time
//! (`is_x86_feature_detected!`); without AVX2 the same code runs as plain loops. No fused
//! multiply–add is introduced (Rust does not contract `a·b + c`), and every sum is taken in the
//! scalar path's order, so lanes and scalar path agree to rounding.

use std::mem::MaybeUninit;

use super::{Axis, FrozenChain};
use crate::chain::Motion;

/// Number of configurations evaluated together by [`FrozenChain::distance_gradient_lanes`].
pub const LANES: usize = 8;

/// One value per configuration.
type Lane = [f64; LANES];

/// Longest chain (constant runs, i.e. joints + 1) the lane kernel takes; its per-run frames
/// live on the stack.
const MAX_SEGMENTS: usize = 16;

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

/// `a·s` for a scalar `s`.
#[inline(always)]
fn scale(a: Lane, s: f64) -> Lane {
    let mut o = [0.0; LANES];
    for l in 0..LANES {
        o[l] = a[l] * s;
    }
    o
}

/// `(a₀b₀ + a₁b₁) + a₂b₂`.
#[inline(always)]
fn dot3(a: &[Lane; 3], b: &[Lane; 3]) -> Lane {
    let mut o = [0.0; LANES];
    for l in 0..LANES {
        o[l] = a[0][l] * b[0][l] + a[1][l] * b[1][l] + a[2][l] * b[2][l];
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

/// A rigid transform per lane: `rot[i][k]` is row `i`, column `k`.
#[derive(Clone, Copy)]
struct LaneRigid {
    rot: [[Lane; 3]; 3],
    trans: [Lane; 3],
}

impl LaneRigid {
    #[inline(always)]
    fn column(&self, k: usize) -> [Lane; 3] {
        [self.rot[0][k], self.rot[1][k], self.rot[2][k]]
    }
}

impl FrozenChain {
    /// Whether [`FrozenChain::distance_gradient_lanes`] applies: every joint is revolute about a
    /// coordinate axis of its frame (all D-H chains; URDF joints with a general axis and
    /// prismatic joints take the scalar path) and the chain has at most 15 joints.
    pub fn supports_lanes(&self) -> bool {
        self.segments.len() <= MAX_SEGMENTS
            && self.segments.iter().all(|s| {
                s.joint.as_ref().is_none_or(|j| {
                    j.motion == Motion::Rotation && !matches!(j.axis, Axis::General(_))
                })
            })
    }

    /// [`FrozenChain::distance_gradient`] for [`LANES`] configurations at once: `trig[l]` holds
    /// `[sin q_j, cos q_j]` of configuration `l` (see [`joint_trig`](crate::joint_trig)).
    /// Writes the distance `|P|` of each configuration to `distance_m` (m, base frame origin
    /// to end point) and, when `grad` is given (length `n_params()`), `grad[j][l] = ∂|P_l|/∂x_j`
    /// (m/m for lengths, m/rad for angles; 0 where `P = 0`). Agrees with the scalar path to
    /// rounding (the same operations in the same order).
    ///
    /// Source: the distance gradient of [`FrozenChain::distance_gradient`] (paper eq. 5),
    /// evaluated in structure-of-arrays form.
    ///
    /// # Panics
    ///
    /// If [`FrozenChain::supports_lanes`] is false, a `trig[l]` does not have `n_joints()`
    /// entries, or `grad.len() != n_params()`.
    #[track_caller]
    pub fn distance_gradient_lanes(
        &self,
        trig: [&[[f64; 2]]; LANES],
        distance_m: &mut [f64; LANES],
        grad: Option<&mut [[f64; LANES]]>,
    ) {
        assert!(
            self.supports_lanes(),
            "the lane kernel needs revolute joints about coordinate axes and at most {} joints",
            MAX_SEGMENTS - 1
        );
        for t in &trig {
            self.check_trig(t);
        }
        if let Some(g) = &grad {
            assert_eq!(
                g.len(),
                self.n_params,
                "grad has length {}, expected {} parameters",
                g.len(),
                self.n_params
            );
        }
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked just above).
                unsafe { kernel_avx512(self, &trig, distance_m, grad) };
                return;
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked just above).
                unsafe { kernel_avx2(self, &trig, distance_m, grad) };
                return;
            }
        }
        kernel(self, &trig, distance_m, grad);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
fn kernel_avx512(
    chain: &FrozenChain,
    trig: &[&[[f64; 2]]; LANES],
    distance_m: &mut [f64; LANES],
    grad: Option<&mut [Lane]>,
) {
    kernel(chain, trig, distance_m, grad);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn kernel_avx2(
    chain: &FrozenChain,
    trig: &[&[[f64; 2]]; LANES],
    distance_m: &mut [f64; LANES],
    grad: Option<&mut [Lane]>,
) {
    kernel(chain, trig, distance_m, grad);
}

/// The lane kernel; `#[inline(always)]` so that each caller above compiles it for its
/// instruction set.
#[inline(always)]
fn kernel(
    chain: &FrozenChain,
    trig: &[&[[f64; 2]]; LANES],
    distance_m: &mut [f64; LANES],
    grad: Option<&mut [Lane]>,
) {
    let zero = splat(0.0);
    let one = splat(1.0);
    let mut pose = LaneRigid {
        rot: [[one, zero, zero], [zero, one, zero], [zero, zero, one]],
        trans: [zero; 3],
    };
    let with_grad = grad.is_some();
    // The world frame at the start of each run, written for runs 0..segments.len() (not
    // initialised beyond: a 12 KB fill would cost as much as the kinematics).
    let mut starts = [const { MaybeUninit::<LaneRigid>::uninit() }; MAX_SEGMENTS];
    for (k, seg) in chain.segments.iter().enumerate() {
        if with_grad {
            starts[k].write(pose);
        }
        // pose ← pose · fixed (as Rigid::mul: rot·rot', trans + rot·trans').
        let f = &seg.fixed;
        let ft = [f.trans.x, f.trans.y, f.trans.z];
        let fc = [
            [f.rot[(0, 0)], f.rot[(1, 0)], f.rot[(2, 0)]],
            [f.rot[(0, 1)], f.rot[(1, 1)], f.rot[(2, 1)]],
            [f.rot[(0, 2)], f.rot[(1, 2)], f.rot[(2, 2)]],
        ];
        for i in 0..3 {
            let row = pose.rot[i];
            pose.trans[i] = add(pose.trans[i], dot3_s(&row, ft));
            for (j, col) in fc.iter().enumerate() {
                pose.rot[i][j] = dot3_s(&row, *col);
            }
        }
        if let Some(screw) = &seg.joint {
            let mut sq = [0.0; LANES];
            let mut cq = [0.0; LANES];
            for l in 0..LANES {
                let [s, c] = trig[l][screw.joint];
                sq[l] = s;
                cq[l] = c;
            }
            // sin and cos of offset + q (as FrozenChain::apply_joint_trig).
            let s = add(scale(cq, screw.sin_off), scale(sq, screw.cos_off));
            let c = sub(scale(cq, screw.cos_off), scale(sq, screw.sin_off));
            let (ci, cj) = match screw.axis {
                Axis::X => (1, 2),
                Axis::Y => (2, 0),
                // General axes are excluded by `supports_lanes`.
                _ => (0, 1),
            };
            for row in &mut pose.rot {
                let (ri, rj) = (row[ci], row[cj]);
                row[ci] = add(mul(ri, c), mul(rj, s));
                row[cj] = sub(mul(rj, c), mul(ri, s));
            }
        }
    }
    let tip = pose.trans;
    let mut norm = dot3(&tip, &tip);
    for v in &mut norm {
        *v = v.sqrt();
    }
    *distance_m = norm;
    let Some(grad) = grad else {
        return;
    };
    grad.fill(zero);
    // u = P/|P|, and 0 where P = 0 (then every term below is 0, as in the scalar path).
    let mut u = [zero; 3];
    for (ui, ti) in u.iter_mut().zip(&tip) {
        for l in 0..LANES {
            ui[l] = if norm[l] == 0.0 { 0.0 } else { ti[l] / norm[l] };
        }
    }
    for (seg, start) in chain.segments.iter().zip(&starts) {
        if seg.distance_taps.is_empty() {
            continue;
        }
        // SAFETY: the loop above wrote `starts[k]` for every `k < segments.len()` (with_grad
        // is true here), and `zip` stops at `segments.len()` (≤ MAX_SEGMENTS, checked by
        // `supports_lanes`).
        let start = unsafe { start.assume_init_ref() };
        // U and T in the run's start frame: Rᵀu and Rᵀ(P − t).
        let d = [
            sub(tip[0], start.trans[0]),
            sub(tip[1], start.trans[1]),
            sub(tip[2], start.trans[2]),
        ];
        let mut ul = [zero; 3];
        let mut tl = [zero; 3];
        for k in 0..3 {
            let col = start.column(k);
            ul[k] = dot3(&col, &u);
            tl[k] = dot3(&col, &d);
        }
        // v = tl × ul.
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
            *g = add(*g, term);
        }
    }
}
