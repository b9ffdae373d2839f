//! Distances and distance gradients of [`LANES`] configurations at once.
//!
//! The same quantities as [`FrozenChain::distance_gradient`], on structure-of-arrays data:
//! every scalar (a coordinate of a point or direction, a joint sine or cosine) becomes a
//! `[f64; LANES]`, one entry per configuration. The kernel is written once, over `pulp`'s
//! vectors, and runs with the widest instruction set the CPU has (chosen at run time): one
//! AVX-512 register per group of lanes (two groups at a time, to overlap two independent
//! chains of operations), two AVX2 registers, four NEON registers, or eight scalars. The
//! environment variable `HAPCAL_SIMD=off` (read once per process) forces the scalar code.
//! Every operation is exact per entry (add, multiply, fused multiply–add, square root,
//! division), so every instruction set and grouping gives the same bits.
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

use pulp::Simd;

use super::{Axis, FrozenChain, Segment};
use crate::chain::Motion;

/// Number of configurations evaluated together by [`FrozenChain::distance_gradient_lanes`].
pub const LANES: usize = 8;

/// One value per configuration.
type Lane = [f64; LANES];

/// Longest chain (constant runs, i.e. joints + 1) the lane kernel takes; the end point in each
/// run's frame lives on the stack.
const MAX_SEGMENTS: usize = 16;

/// Chains of at most this many runs (7 joints) take a kernel with a shorter array of end
/// points, which it fills at every call.
const SHORT_SEGMENTS: usize = 8;

/// The instruction set of the lane kernel: the widest one this CPU has (`pulp::Arch::new()`),
/// or plain scalar code when the environment variable `HAPCAL_SIMD` is `off` (read once per
/// process). Both give the same bits (module docs).
fn arch() -> pulp::Arch {
    static ARCH: std::sync::OnceLock<pulp::Arch> = std::sync::OnceLock::new();
    *ARCH.get_or_init(|| {
        if std::env::var_os("HAPCAL_SIMD").is_some_and(|v| v == "off") {
            pulp::Arch::Scalar
        } else {
            pulp::Arch::new()
        }
    })
}

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

/// A value of the lane kernel: `G` groups of [`LANES`] configurations, held in the vectors of
/// `S`: group `g` is `v[g][..LANES / S::F64_LANES]` (`LANES` is a multiple of every
/// instruction set's width; the rest of `v[g]` is never touched, and the compiler drops it).
/// Holding vectors, not `[f64; LANES]`, keeps the values in registers. `a.mul_add(b, c)` is
/// `a·b + c` and `a.neg_mul_add(b, c)` is `c − a·b`, both fused.
#[derive(Clone, Copy)]
struct Pack<S: Simd, const G: usize> {
    v: [[S::f64s; LANES]; G],
    simd: S,
}

// Vector by vector rather than `copy_from_slice`, which goes through memory.
#[allow(clippy::manual_memcpy)]
impl<S: Simd, const G: usize> Pack<S, G> {
    /// Vectors per group.
    const N_VEC: usize = {
        assert!(LANES.is_multiple_of(S::F64_LANES));
        LANES / S::F64_LANES
    };
    /// Every lane `v`.
    #[inline(always)]
    fn splat(simd: S, v: f64) -> Self {
        Pack {
            v: [[simd.splat_f64s(v); LANES]; G],
            simd,
        }
    }
    /// The value whose group `g` is `f(g)`. (Plain loops here and below: `std::array::from_fn`
    /// and `[T; N]::map` are not always inlined into the instruction set's function.)
    #[inline(always)]
    fn from_groups(simd: S, mut f: impl FnMut(usize) -> Lane) -> Self {
        let mut out = Self::splat(simd, 0.0);
        for (g, out) in out.v.iter_mut().enumerate() {
            let lanes = f(g);
            let src = S::as_simd_f64s(&lanes).0;
            for p in 0..Self::N_VEC {
                out[p] = src[p];
            }
        }
        out
    }
    /// Group `g` from `src[first + g·stride]`.
    #[inline(always)]
    fn load_at(simd: S, src: &[Lane], first: usize, stride: usize) -> Self {
        Self::from_groups(simd, |g| src[first + g * stride])
    }
    /// Writes group `g` to `dst`.
    #[inline(always)]
    fn store_group(&self, g: usize, dst: &mut Lane) {
        let out = S::as_mut_simd_f64s(dst).0;
        for p in 0..Self::N_VEC {
            out[p] = self.v[g][p];
        }
    }
    /// `f` on every vector of `self` and the matching ones of `b` and `c`.
    #[inline(always)]
    fn map3(self, b: Self, c: Self, f: impl Fn(S, S::f64s, S::f64s, S::f64s) -> S::f64s) -> Self {
        let mut out = self;
        for g in 0..G {
            for p in 0..Self::N_VEC {
                out.v[g][p] = f(self.simd, self.v[g][p], b.v[g][p], c.v[g][p]);
            }
        }
        out
    }
    /// `self + b`.
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        self.map3(b, b, |s, x, y, _| s.add_f64s(x, y))
    }
    /// `self − b`.
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        self.map3(b, b, |s, x, y, _| s.sub_f64s(x, y))
    }
    /// `self · b`.
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        self.map3(b, b, |s, x, y, _| s.mul_f64s(x, y))
    }
    /// `self · b + c`, fused.
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        self.map3(b, c, |s, x, y, z| s.mul_add_f64s(x, y, z))
    }
    /// `c − self · b`, fused.
    #[inline(always)]
    fn neg_mul_add(self, b: Self, c: Self) -> Self {
        self.map3(b, c, |s, x, y, z| s.negate_mul_add_f64s(x, y, z))
    }
    /// `√self`.
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map3(self, self, |s, x, _, _| s.sqrt_f64s(x))
    }
    /// `num / self`, and 0 where `self` is 0.
    #[inline(always)]
    fn recip_scaled_or_zero(self, num: f64) -> Self {
        self.map3(self, self, |s, d, _, _| {
            let zero = s.splat_f64s(0.0);
            let q = s.div_f64s(s.splat_f64s(num), d);
            s.select_f64s(s.equal_f64s(d, zero), zero, q)
        })
    }
}

/// [`FrozenChain::supports_lanes`] for the runs `segments`.
pub(super) fn lanes_apply(segments: &[Segment]) -> bool {
    segments.len() <= MAX_SEGMENTS
        && segments.iter().all(|s| {
            s.joint
                .as_ref()
                .is_none_or(|j| j.motion == Motion::Rotation && !matches!(j.axis, Axis::General(_)))
        })
}

/// Where the lane kernel writes the gradient.
trait GradSink {
    /// The lanes of parameter `param` of group `group`.
    fn lanes(&mut self, param: usize, group: usize) -> &mut Lane;
}

/// `buf[group · n_params + param]`.
struct LaneBuf<'a> {
    buf: &'a mut [Lane],
    n_params: usize,
}

impl GradSink for LaneBuf<'_> {
    #[inline(always)]
    fn lanes(&mut self, param: usize, group: usize) -> &mut Lane {
        &mut self.buf[group * self.n_params + param]
    }
}

/// `columns[param][first_row + group · LANES..][..LANES]`.
struct Columns<'a, 'b> {
    columns: &'a mut [&'b mut [f64]],
    first_row: usize,
}

impl GradSink for Columns<'_, '_> {
    #[inline(always)]
    #[track_caller]
    fn lanes(&mut self, param: usize, group: usize) -> &mut Lane {
        self.columns[param][self.first_row + group * LANES..]
            .first_chunk_mut()
            .expect("every column holds the rows of the groups")
    }
}

impl FrozenChain {
    /// Whether [`FrozenChain::distance_gradient_lanes`] applies: every joint is revolute about a
    /// coordinate axis of its frame (all D-H chains; URDF joints with a general axis and
    /// prismatic joints take the scalar path) and the chain has at most 15 joints. It depends
    /// on the chain's structure only, not on the frozen `x`.
    pub fn supports_lanes(&self) -> bool {
        self.lanes
    }

    /// [`FrozenChain::distance_gradient`] for groups of [`LANES`] configurations, `n_groups =
    /// distance_m.len()` of them: `trig[g · n_joints() + j]` holds the sines (`[0]`) and
    /// cosines (`[1]`) of joint `j` of the configurations of group `g` (see
    /// [`joint_trig_lanes`]). Writes the distance `|P|` of each configuration to
    /// `distance_m[g]` (m, base frame origin to end point) and, when `grad` is given (length
    /// `n_groups · n_params()`), `grad[g · n_params() + j][l] = grad_scale · ∂|P|/∂x_j` of
    /// configuration `l` of group `g` (`grad_scale` per m: m/m for lengths, m/rad for angles,
    /// times its unit; 0 where `P = 0`). The results do not depend on the grouping, and the
    /// distances not on whether `grad` is given; they agree with the scalar path to rounding.
    /// Two or more groups per call let the CPU overlap two groups' operations. The kernel runs
    /// with the widest instruction set of the CPU, chosen at run time (AVX-512, AVX2 with FMA,
    /// NEON, or scalar code; all give the same bits); the environment variable
    /// `HAPCAL_SIMD=off`, read once per process, forces the scalar code.
    ///
    /// Source: the distance gradient of [`FrozenChain::distance_gradient`] (paper eq. 5), with
    /// the end point and its direction carried through the runs' frames (module docs).
    ///
    /// # Panics
    ///
    /// If [`FrozenChain::supports_lanes`] is false, `trig.len() != n_groups · n_joints()`, or
    /// `grad.len() != n_groups · n_params()`.
    #[track_caller]
    pub fn distance_gradient_lanes(
        &self,
        trig: &[[[f64; LANES]; 2]],
        grad_scale: f64,
        distance_m: &mut [[f64; LANES]],
        grad: Option<&mut [[f64; LANES]]>,
    ) {
        let n_groups = distance_m.len();
        self.check_lanes(trig, n_groups);
        let n_params = self.n_params;
        match grad {
            Some(g) => {
                assert_eq!(
                    g.len(),
                    n_groups * n_params,
                    "grad has length {}, expected {n_groups} groups of {n_params} parameters",
                    g.len(),
                );
                let mut sink = LaneBuf { buf: g, n_params };
                dispatch::<true, _>(self, trig, grad_scale, distance_m, &mut sink);
            }
            None => {
                let mut sink = LaneBuf {
                    buf: &mut [],
                    n_params,
                };
                dispatch::<false, _>(self, trig, grad_scale, distance_m, &mut sink);
            }
        }
    }

    /// [`FrozenChain::distance_gradient_lanes`] with the gradient written into the columns of
    /// a column-major Jacobian: `columns[j][first_row + g · LANES + l] = grad_scale ·
    /// ∂|P|/∂x_j` of configuration `l` of group `g` (`columns` may be longer than
    /// `n_params()`; the rest is left alone). The same numbers, without a copy.
    ///
    /// # Panics
    ///
    /// As [`FrozenChain::distance_gradient_lanes`], or if there are fewer than `n_params()`
    /// columns or one is shorter than `first_row + n_groups · LANES`.
    #[track_caller]
    pub fn distance_gradient_lanes_into(
        &self,
        trig: &[[[f64; LANES]; 2]],
        grad_scale: f64,
        distance_m: &mut [[f64; LANES]],
        columns: &mut [&mut [f64]],
        first_row: usize,
    ) {
        let n_groups = distance_m.len();
        self.check_lanes(trig, n_groups);
        let end = first_row + n_groups * LANES;
        assert!(
            columns.len() >= self.n_params && columns.iter().all(|c| c.len() >= end),
            "the gradient needs {} columns of at least {end} rows",
            self.n_params
        );
        let mut sink = Columns {
            columns: &mut columns[..self.n_params],
            first_row,
        };
        dispatch::<true, _>(self, trig, grad_scale, distance_m, &mut sink);
    }

    #[track_caller]
    fn check_lanes(&self, trig: &[[Lane; 2]], n_groups: usize) {
        assert!(
            self.supports_lanes(),
            "the lane kernel needs revolute joints about coordinate axes and at most {} joints",
            MAX_SEGMENTS - 1
        );
        assert_eq!(
            trig.len(),
            n_groups * self.n_joints,
            "trig has length {}, but {n_groups} groups of the chain have {} joints",
            trig.len(),
            n_groups * self.n_joints
        );
    }
}

/// The lane kernel on `G` groups of lanes in the vectors of `simd`, for chains of at most `N`
/// runs: `trig` (flattened: `[g][joint][sin, cos]`) and `distance_m` as in
/// [`FrozenChain::distance_gradient_lanes`], the gradient (when `GRAD`) to groups
/// `first_group + g` of `grad`.
#[allow(clippy::too_many_arguments)] // the kernel's inputs and outputs
#[inline(always)]
fn kernel<S: Simd, const G: usize, const GRAD: bool, Sk: GradSink, const N: usize>(
    simd: S,
    chain: &FrozenChain,
    trig: &[Lane],
    grad_scale: f64,
    distance_m: &mut [Lane],
    grad: &mut Sk,
    first_group: usize,
) {
    type V<S, const G: usize> = Pack<S, G>;
    let splat = |v: f64| V::<S, G>::splat(simd, v);
    let trig_stride = 2 * chain.n_joints;
    // `Rot(e_k, θ)·p` (or its transpose for `back`) for a coordinate axis `e_k`
    // (`i, j, k` cyclic: `p_i ↦ c·p_i − s·p_j`, `p_j ↦ s·p_i + c·p_j`), each axis
    // written out so that the coordinates stay in registers.
    macro_rules! rotate {
        ($p:expr, $axis:expr, $s:expr, $c:expr, $back:expr) => {{
            let [x, y, z]: [V<S, G>; 3] = $p;
            let (s, c): (V<S, G>, V<S, G>) = ($s, $c);
            let (i, j) = match $axis {
                Axis::X => (y, z),
                Axis::Y => (z, x),
                // General axes are excluded by `supports_lanes`.
                _ => (x, y),
            };
            let (ri, rj) = if $back {
                (c.mul_add(i, s.mul(j)), c.mul(j).sub(s.mul(i)))
            } else {
                (c.mul(i).sub(s.mul(j)), s.mul_add(i, c.mul(j)))
            };
            match $axis {
                Axis::X => [x, ri, rj],
                Axis::Y => [rj, y, ri],
                _ => [ri, rj, z],
            }
        }};
    }
    // `((a₀·s₀ + t) + a₁·s₁) + a₂·s₂` for constants `s`, `t`.
    let dot3_s_add = |a: &[V<S, G>; 3], s: [f64; 3], t: V<S, G>| -> V<S, G> {
        let d = a[0].mul_add(splat(s[0]), t);
        a[2].mul_add(splat(s[2]), a[1].mul_add(splat(s[1]), d))
    };
    // `(a₀·s₀ + a₁·s₁) + a₂·s₂` for constants `s`.
    let dot3_s = |a: &[V<S, G>; 3], s: [f64; 3]| -> V<S, G> {
        let d = a[0].mul(splat(s[0]));
        a[2].mul_add(splat(s[2]), a[1].mul_add(splat(s[1]), d))
    };
    let load_trig = |first: usize| V::<S, G>::load_at(simd, trig, first, trig_stride);
    let segments = &chain.segments;
    let Some((last, rest)) = segments.split_last() else {
        distance_m.fill([0.0; LANES]);
        return;
    };
    // Backwards: T_k = F_k · J_k(q) · T_{k+1}, the end point in the start frame of run
    // k, kept for every run when GRAD (the last run's is its translation).
    let t = &last.lane_fixed.trans;
    let mut p = [splat(t.x), splat(t.y), splat(t.z)];
    // Stored as lanes (`G·LANES` numbers per coordinate), not as `Pack`s, whose unused
    // vectors would be real memory in an array indexed at run time.
    let save = |p: &[V<S, G>; 3]| -> [[Lane; G]; 3] {
        let mut out = [[[0.0; LANES]; G]; 3];
        for (out, p) in out.iter_mut().zip(p) {
            for (g, out) in out.iter_mut().enumerate() {
                p.store_group(g, out);
            }
        }
        out
    };
    let mut tips = [[[[0.0; LANES]; G]; 3]; N];
    if GRAD {
        tips[rest.len()] = save(&p);
    }
    for (k, seg) in rest.iter().enumerate().rev() {
        if let Some(screw) = &seg.joint {
            let (s, c) = (load_trig(2 * screw.joint), load_trig(2 * screw.joint + 1));
            p = rotate!(p, screw.axis, s, c, false);
        }
        let f = &seg.lane_fixed;
        let r = &f.rot;
        p = [
            dot3_s_add(&p, [r[(0, 0)], r[(0, 1)], r[(0, 2)]], splat(f.trans.x)),
            dot3_s_add(&p, [r[(1, 0)], r[(1, 1)], r[(1, 2)]], splat(f.trans.y)),
            dot3_s_add(&p, [r[(2, 0)], r[(2, 1)], r[(2, 2)]], splat(f.trans.z)),
        ];
        if GRAD {
            tips[k] = save(&p);
        }
    }
    let norm = p[2]
        .mul_add(p[2], p[1].mul_add(p[1], p[0].mul(p[0])))
        .sqrt();
    for (g, d) in distance_m.iter_mut().enumerate().take(G) {
        norm.store_group(g, d);
    }
    if !GRAD {
        return;
    }
    if !chain.all_params_tapped {
        for param in 0..chain.n_params {
            for g in 0..G {
                *grad.lanes(param, first_group + g) = [0.0; LANES];
            }
        }
    }
    // Forwards: U_0 = grad_scale · P/|P| (0 where P = 0: then every term is 0), and
    // U_{k+1} = J_k(q)ᵀ · F_kᵀ · U_k.
    let f = norm.recip_scaled_or_zero(grad_scale);
    let mut ul = [p[0].mul(f), p[1].mul(f), p[2].mul(f)];
    for (seg, tl) in segments.iter().zip(&tips) {
        let load = |c: &[Lane; G]| V::<S, G>::from_groups(simd, |g| c[g]);
        let tl = [load(&tl[0]), load(&tl[1]), load(&tl[2])];
        if !seg.distance_taps.is_empty() {
            // v = T × U, both in the run's start frame.
            let v = [
                tl[1].mul(ul[2]).sub(tl[2].mul(ul[1])),
                tl[2].mul(ul[0]).sub(tl[0].mul(ul[2])),
                tl[0].mul(ul[1]).sub(tl[1].mul(ul[0])),
            ];
            for tap in &chain.distance_taps[seg.distance_taps.clone()] {
                let a = [tap.a.x, tap.a.y, tap.a.z];
                let term = if tap.rotation {
                    // v·a − ((U₀c₀ + U₁c₁) + U₂c₂), each product subtracted in turn.
                    let [c0, c1, c2] = [splat(tap.c.x), splat(tap.c.y), splat(tap.c.z)];
                    let va = dot3_s(&v, a);
                    ul[2].neg_mul_add(c2, ul[1].neg_mul_add(c1, ul[0].neg_mul_add(c0, va)))
                } else {
                    dot3_s(&ul, a)
                };
                let sum = if tap.first {
                    term
                } else {
                    V::<S, G>::from_groups(simd, |g| *grad.lanes(tap.param, first_group + g))
                        .add(term)
                };
                for g in 0..G {
                    sum.store_group(g, grad.lanes(tap.param, first_group + g));
                }
            }
        }
        if let Some(screw) = &seg.joint {
            let r = &seg.lane_fixed.rot;
            let w = [
                dot3_s(&ul, [r[(0, 0)], r[(1, 0)], r[(2, 0)]]),
                dot3_s(&ul, [r[(0, 1)], r[(1, 1)], r[(2, 1)]]),
                dot3_s(&ul, [r[(0, 2)], r[(1, 2)], r[(2, 2)]]),
            ];
            let (s, c) = (load_trig(2 * screw.joint), load_trig(2 * screw.joint + 1));
            ul = rotate!(w, screw.axis, s, c, true);
        }
    }
}

/// The lane kernel over every group of `distance_m`, as one `pulp` operation: `pairs` says
/// whether groups go two at a time (`None`: where a group is one register of the instruction
/// set, so that the two groups' values stay in registers).
struct Groups<'a, 'b, Sk, const GRAD: bool> {
    chain: &'a FrozenChain,
    trig: &'a [[Lane; 2]],
    grad_scale: f64,
    distance_m: &'a mut [Lane],
    grad: &'b mut Sk,
    pairs: Option<bool>,
}

impl<Sk: GradSink, const GRAD: bool> pulp::WithSimd for Groups<'_, '_, Sk, GRAD> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        if self.chain.segments.len() <= SHORT_SEGMENTS {
            self.run::<S, SHORT_SEGMENTS>(simd);
        } else {
            self.run::<S, MAX_SEGMENTS>(simd);
        }
    }
}

impl<Sk: GradSink, const GRAD: bool> Groups<'_, '_, Sk, GRAD> {
    /// [`Groups`] for chains of at most `N` runs.
    #[inline(always)]
    fn run<S: Simd, const N: usize>(self, simd: S) {
        let Groups {
            chain,
            trig,
            grad_scale,
            distance_m,
            grad,
            pairs,
        } = self;
        let pairs = pairs.unwrap_or(S::F64_LANES >= LANES);
        let trig = trig.as_flattened();
        let nt = 2 * chain.n_joints;
        let n_groups = distance_m.len();
        let mut g = 0;
        while g < n_groups {
            if pairs && g + 2 <= n_groups {
                let (t, d) = (&trig[g * nt..(g + 2) * nt], &mut distance_m[g..g + 2]);
                kernel::<S, 2, GRAD, Sk, N>(simd, chain, t, grad_scale, d, grad, g);
                g += 2;
            } else {
                let (t, d) = (&trig[g * nt..(g + 1) * nt], &mut distance_m[g..g + 1]);
                kernel::<S, 1, GRAD, Sk, N>(simd, chain, t, grad_scale, d, grad, g);
                g += 1;
            }
        }
    }
}

/// Runs the lane kernel with the instruction set of [`arch`] on every group.
fn dispatch<const GRAD: bool, Sk: GradSink>(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
    distance_m: &mut [Lane],
    grad: &mut Sk,
) {
    arch().dispatch(Groups::<Sk, GRAD> {
        chain,
        trig,
        grad_scale,
        distance_m,
        grad,
        pairs: None,
    });
}

/// The results `(kernel, distances, gradient)` on two groups (`trig` of `2 · n_joints()`
/// entries) of the kernel in scalar code (`"portable"`) and with the widest instruction set of
/// this CPU, one group at a time and two at a time, with the gradient, for tests; the
/// gradient-free runs must give the same distances (checked here).
#[cfg(test)]
pub(crate) fn every_kernel(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
) -> Vec<(&'static str, Vec<Lane>, Vec<Lane>)> {
    let np = chain.n_params;
    let mut results = Vec::new();
    for (name, arch, pairs) in [
        ("portable", pulp::Arch::Scalar, false),
        ("vector", pulp::Arch::new(), false),
        ("vector, two groups at a time", pulp::Arch::new(), true),
    ] {
        let mut dist = vec![[0.0; LANES]; 2];
        let mut grad = vec![[f64::NAN; LANES]; 2 * np];
        let mut dist_only = vec![[0.0; LANES]; 2];
        arch.dispatch(Groups::<_, true> {
            chain,
            trig,
            grad_scale,
            distance_m: &mut dist,
            grad: &mut LaneBuf {
                buf: &mut grad,
                n_params: np,
            },
            pairs: Some(pairs),
        });
        arch.dispatch(Groups::<_, false> {
            chain,
            trig,
            grad_scale,
            distance_m: &mut dist_only,
            grad: &mut LaneBuf {
                buf: &mut [],
                n_params: np,
            },
            pairs: Some(pairs),
        });
        assert_eq!(
            dist, dist_only,
            "{name}: distances with and without the gradient"
        );
        results.push((name, dist, grad));
    }
    results
}
