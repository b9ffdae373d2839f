//! Distances and distance gradients of [`LANES`] configurations at once.
//!
//! The same quantities as [`FrozenChain::distance_gradient`], on structure-of-arrays data:
//! every scalar (a coordinate of a point or direction, a joint sine or cosine) becomes a
//! `[f64; LANES]`, one entry per configuration, held in one AVX-512 register (two groups of
//! lanes at a time, to overlap two independent chains of operations) or two AVX2 registers,
//! with fused multiply–adds; the instruction set is chosen at run time
//! (`is_x86_feature_detected!`), and without AVX2 the same kernel runs as plain loops
//! (unfused). One kernel body is stamped out per instruction set by `lane_kernel!`.
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

/// Chains of at most this many runs (7 joints) take a kernel with a shorter array of end
/// points, which it fills at every call.
const SHORT_SEGMENTS: usize = 8;

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

/// The operations of the lane kernel on one [`Lane`] per vector value: [`Portable`] (plain
/// loops) and, on x86-64, one AVX-512 register or two AVX2 registers (`simd`); `Avx512x2`
/// holds two groups of lanes (two registers), so that two independent chains of operations
/// fill the pipeline. `load_at(src, first, stride)` reads group `g` of the value from
/// `src[first + g·stride]`, and `store_at` writes it there; `store_group(g, dst)` writes
/// group `g` to `dst`, and `from_groups(f)` builds a value from its groups `f(g)`, `g <
/// GROUPS`. Each kernel is
/// stamped out by `lane_kernel!` for one of them, inside a function compiled with its
/// instruction set, so that every operation is one instruction (or two) and the values stay in
/// registers (LLVM's own vectorisation of the plain loops mixed coordinates across lanes).
/// `a.mul_add(b, c)` is `a·b + c` and `a.neg_mul_add(b, c)` is `c − a·b`, fused where the
/// instruction set has it.
#[derive(Clone, Copy)]
struct Portable(Lane);

impl Portable {
    #[inline(always)]
    fn splat(v: f64) -> Self {
        Portable([v; LANES])
    }
    #[inline(always)]
    fn load_at(src: &[Lane], first: usize, _stride: usize) -> Self {
        Portable(src[first])
    }
    #[inline(always)]
    fn store_at(self, dst: &mut [Lane], first: usize, _stride: usize) {
        dst[first] = self.0;
    }
    const GROUPS: usize = 1;
    #[inline(always)]
    fn store_group(self, _group: usize, dst: &mut Lane) {
        *dst = self.0;
    }
    #[inline(always)]
    fn from_groups(mut f: impl FnMut(usize) -> Lane) -> Self {
        Portable(f(0))
    }
    #[inline(always)]
    fn map2(self, b: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        let mut o = self.0;
        for (x, y) in o.iter_mut().zip(b.0) {
            *x = f(*x, y);
        }
        Portable(o)
    }
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        self.map2(b, |x, y| x + y)
    }
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        self.map2(b, |x, y| x - y)
    }
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        self.map2(b, |x, y| x * y)
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        self.mul(b).add(c)
    }
    #[inline(always)]
    fn neg_mul_add(self, b: Self, c: Self) -> Self {
        c.sub(self.mul(b))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Portable(self.0.map(f64::sqrt))
    }
    /// `num / self`, and 0 where `self` is 0.
    #[inline(always)]
    fn recip_scaled_or_zero(self, num: f64) -> Self {
        Portable(self.0.map(|d| if d == 0.0 { 0.0 } else { num / d }))
    }
}

#[cfg(target_arch = "x86_64")]
mod simd {
    //! [`Portable`](super::Portable)'s operations in AVX-512 and AVX2 (+ FMA) registers. Each
    //! method carries its type's target features, so it may only be called (and is inlined)
    //! from a function compiled with them: the kernels of `lane_kernel!`,
    //! run after `is_x86_feature_detected!`.

    use super::{LANES, Lane};
    use std::arch::x86_64::*;

    /// Eight lanes in one AVX-512 register.
    #[derive(Clone, Copy)]
    pub(super) struct Avx512(__m512d);

    impl Avx512 {
        /// Every lane `v`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn splat(v: f64) -> Self {
            Avx512(_mm512_set1_pd(v))
        }
        /// The lanes of `src[first]`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn load_at(src: &[Lane], first: usize, _stride: usize) -> Self {
            Avx512(load512(&src[first]))
        }
        /// Writes the lanes to `dst[first]`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn store_at(self, dst: &mut [Lane], first: usize, _stride: usize) {
            store512(self.0, &mut dst[first]);
        }
        /// Groups of lanes per value.
        pub(super) const GROUPS: usize = 1;
        /// Writes group `group` (0) of the lanes to `dst`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn store_group(self, _group: usize, dst: &mut Lane) {
            store512(self.0, dst);
        }
        /// The value whose group `g` is `f(g)`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn from_groups(mut f: impl FnMut(usize) -> Lane) -> Self {
            Avx512(load512(&f(0)))
        }
        /// `self + b`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn add(self, b: Self) -> Self {
            Avx512(_mm512_add_pd(self.0, b.0))
        }
        /// `self − b`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn sub(self, b: Self) -> Self {
            Avx512(_mm512_sub_pd(self.0, b.0))
        }
        /// `self · b`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn mul(self, b: Self) -> Self {
            Avx512(_mm512_mul_pd(self.0, b.0))
        }
        /// `self · b + c`, fused.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn mul_add(self, b: Self, c: Self) -> Self {
            Avx512(_mm512_fmadd_pd(self.0, b.0, c.0))
        }
        /// `c − self · b`, fused.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn neg_mul_add(self, b: Self, c: Self) -> Self {
            Avx512(_mm512_fnmadd_pd(self.0, b.0, c.0))
        }
        /// `√self`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn sqrt(self) -> Self {
            Avx512(_mm512_sqrt_pd(self.0))
        }
        /// `num / self`, and 0 where `self` is 0.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn recip_scaled_or_zero(self, num: f64) -> Self {
            let nonzero = _mm512_cmp_pd_mask::<_CMP_NEQ_OQ>(self.0, _mm512_setzero_pd());
            Avx512(_mm512_maskz_div_pd(nonzero, _mm512_set1_pd(num), self.0))
        }
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn load512(a: &Lane) -> __m512d {
        // SAFETY: `a` is LANES = 8 readable f64 (an unaligned load); AVX-512F is enabled.
        unsafe { _mm512_loadu_pd(a.as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn store512(v: __m512d, a: &mut Lane) {
        // SAFETY: `a` is LANES = 8 writable f64 (an unaligned store); AVX-512F is enabled.
        unsafe { _mm512_storeu_pd(a.as_mut_ptr(), v) }
    }

    /// Two groups of eight lanes in two AVX-512 registers.
    #[derive(Clone, Copy)]
    pub(super) struct Avx512x2([__m512d; 2]);

    impl Avx512x2 {
        #[inline]
        #[target_feature(enable = "avx512f")]
        fn map2(self, b: Self, f: impl Fn(__m512d, __m512d) -> __m512d) -> Self {
            Avx512x2([f(self.0[0], b.0[0]), f(self.0[1], b.0[1])])
        }
        /// Every lane `v`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn splat(v: f64) -> Self {
            Avx512x2([_mm512_set1_pd(v); 2])
        }
        /// The lanes of `src[first]` and `src[first + stride]`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn load_at(src: &[Lane], first: usize, stride: usize) -> Self {
            Avx512x2([load512(&src[first]), load512(&src[first + stride])])
        }
        /// Writes the lanes to `dst[first]` and `dst[first + stride]`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn store_at(self, dst: &mut [Lane], first: usize, stride: usize) {
            store512(self.0[0], &mut dst[first]);
            store512(self.0[1], &mut dst[first + stride]);
        }
        /// Groups of lanes per value.
        pub(super) const GROUPS: usize = 2;
        /// Writes group `group` (0 or 1) of the lanes to `dst`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn store_group(self, group: usize, dst: &mut Lane) {
            store512(self.0[group], dst);
        }
        /// The value whose group `g` is `f(g)`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn from_groups(mut f: impl FnMut(usize) -> Lane) -> Self {
            Avx512x2([load512(&f(0)), load512(&f(1))])
        }
        /// `self + b`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn add(self, b: Self) -> Self {
            self.map2(b, |x, y| _mm512_add_pd(x, y))
        }
        /// `self − b`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn sub(self, b: Self) -> Self {
            self.map2(b, |x, y| _mm512_sub_pd(x, y))
        }
        /// `self · b`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn mul(self, b: Self) -> Self {
            self.map2(b, |x, y| _mm512_mul_pd(x, y))
        }
        /// `self · b + c`, fused.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn mul_add(self, b: Self, c: Self) -> Self {
            Avx512x2([
                _mm512_fmadd_pd(self.0[0], b.0[0], c.0[0]),
                _mm512_fmadd_pd(self.0[1], b.0[1], c.0[1]),
            ])
        }
        /// `c − self · b`, fused.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn neg_mul_add(self, b: Self, c: Self) -> Self {
            Avx512x2([
                _mm512_fnmadd_pd(self.0[0], b.0[0], c.0[0]),
                _mm512_fnmadd_pd(self.0[1], b.0[1], c.0[1]),
            ])
        }
        /// `√self`.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn sqrt(self) -> Self {
            Avx512x2([_mm512_sqrt_pd(self.0[0]), _mm512_sqrt_pd(self.0[1])])
        }
        /// `num / self`, and 0 where `self` is 0.
        #[inline]
        #[target_feature(enable = "avx512f")]
        pub(super) fn recip_scaled_or_zero(self, num: f64) -> Self {
            let f = |d: __m512d| {
                let nonzero = _mm512_cmp_pd_mask::<_CMP_NEQ_OQ>(d, _mm512_setzero_pd());
                _mm512_maskz_div_pd(nonzero, _mm512_set1_pd(num), d)
            };
            Avx512x2([f(self.0[0]), f(self.0[1])])
        }
    }

    /// Eight lanes in two AVX2 registers.
    #[derive(Clone, Copy)]
    pub(super) struct Avx2([__m256d; 2]);

    impl Avx2 {
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        fn map2(self, b: Self, f: impl Fn(__m256d, __m256d) -> __m256d) -> Self {
            Avx2([f(self.0[0], b.0[0]), f(self.0[1], b.0[1])])
        }
        /// Every lane `v`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn splat(v: f64) -> Self {
            Avx2([_mm256_set1_pd(v); 2])
        }
        /// The lanes of `src[first]`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn load_at(src: &[Lane], first: usize, _stride: usize) -> Self {
            let (lo, hi) = src[first].split_at(LANES / 2);
            // SAFETY: `lo` and `hi` are 4 readable f64 each (unaligned loads); AVX is enabled.
            Avx2(unsafe { [_mm256_loadu_pd(lo.as_ptr()), _mm256_loadu_pd(hi.as_ptr())] })
        }
        /// Writes the lanes to `dst[first]`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn store_at(self, dst: &mut [Lane], first: usize, _stride: usize) {
            self.store_group(0, &mut dst[first]);
        }
        /// Groups of lanes per value.
        pub(super) const GROUPS: usize = 1;
        /// Writes group `group` (0) of the lanes to `dst`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn store_group(self, _group: usize, dst: &mut Lane) {
            let (lo, hi) = dst.split_at_mut(LANES / 2);
            // SAFETY: `lo` and `hi` are 4 writable f64 each (unaligned stores); AVX is enabled.
            unsafe {
                _mm256_storeu_pd(lo.as_mut_ptr(), self.0[0]);
                _mm256_storeu_pd(hi.as_mut_ptr(), self.0[1]);
            }
        }
        /// The value whose group `g` is `f(g)`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn from_groups(mut f: impl FnMut(usize) -> Lane) -> Self {
            Self::load_at(&[f(0)], 0, 0)
        }
        /// `self + b`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn add(self, b: Self) -> Self {
            self.map2(b, |x, y| _mm256_add_pd(x, y))
        }
        /// `self − b`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn sub(self, b: Self) -> Self {
            self.map2(b, |x, y| _mm256_sub_pd(x, y))
        }
        /// `self · b`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn mul(self, b: Self) -> Self {
            self.map2(b, |x, y| _mm256_mul_pd(x, y))
        }
        /// `self · b + c`, fused.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn mul_add(self, b: Self, c: Self) -> Self {
            Avx2([
                _mm256_fmadd_pd(self.0[0], b.0[0], c.0[0]),
                _mm256_fmadd_pd(self.0[1], b.0[1], c.0[1]),
            ])
        }
        /// `c − self · b`, fused.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn neg_mul_add(self, b: Self, c: Self) -> Self {
            Avx2([
                _mm256_fnmadd_pd(self.0[0], b.0[0], c.0[0]),
                _mm256_fnmadd_pd(self.0[1], b.0[1], c.0[1]),
            ])
        }
        /// `√self`.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn sqrt(self) -> Self {
            Avx2([_mm256_sqrt_pd(self.0[0]), _mm256_sqrt_pd(self.0[1])])
        }
        /// `num / self`, and 0 where `self` is 0.
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        pub(super) fn recip_scaled_or_zero(self, num: f64) -> Self {
            let f = |d: __m256d| {
                let nonzero = _mm256_cmp_pd::<_CMP_NEQ_OQ>(d, _mm256_setzero_pd());
                _mm256_and_pd(_mm256_div_pd(_mm256_set1_pd(num), d), nonzero)
            };
            Avx2([f(self.0[0]), f(self.0[1])])
        }
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
    /// Two or more groups per call let the CPU overlap two groups' operations.
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

/// Defines the lane kernel `$name::<GRAD, _, N>(chain, trig, grad_scale, distance_m, grad,
/// first_group)` on the vector type `$v` (see [`Portable`]), with the attributes given (its
/// target features), for as many groups of lanes as `$v` holds and chains of at most `N`
/// runs: `trig` (flattened: `[g][joint][sin, cos]`) and `distance_m` as in
/// [`FrozenChain::distance_gradient_lanes`], the gradient (when `GRAD`) to groups
/// `first_group + g` of `grad`. A macro rather than a generic function: the
/// operations of `$v` may only be called from a function compiled with its instruction set.
macro_rules! lane_kernel {
    ($(#[$attr:meta])* $name:ident, $v:ty) => {
        $(#[$attr])*
        fn $name<const GRAD: bool, S: GradSink, const N: usize>(
            chain: &FrozenChain,
            trig: &[Lane],
            grad_scale: f64,
            distance_m: &mut [Lane],
            grad: &mut S,
            first_group: usize,
        ) {
            type V = $v;
            let trig_stride = 2 * chain.n_joints;
            // `Rot(e_k, θ)·p` (or its transpose for `back`) for a coordinate axis `e_k`
            // (`i, j, k` cyclic: `p_i ↦ c·p_i − s·p_j`, `p_j ↦ s·p_i + c·p_j`), each axis
            // written out so that the coordinates stay in registers.
            macro_rules! rotate {
                ($p:expr, $axis:expr, $s:expr, $c:expr, $back:expr) => {{
                    let [x, y, z]: [V; 3] = $p;
                    let (s, c): (V, V) = ($s, $c);
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
            let dot3_s_add = |a: &[V; 3], s: [f64; 3], t: V| -> V {
                let d = a[0].mul_add(V::splat(s[0]), t);
                a[2].mul_add(V::splat(s[2]), a[1].mul_add(V::splat(s[1]), d))
            };
            // `(a₀·s₀ + a₁·s₁) + a₂·s₂` for constants `s`.
            let dot3_s = |a: &[V; 3], s: [f64; 3]| -> V {
                let d = a[0].mul(V::splat(s[0]));
                a[2].mul_add(V::splat(s[2]), a[1].mul_add(V::splat(s[1]), d))
            };
            let segments = &chain.segments;
            let Some((last, rest)) = segments.split_last() else {
                distance_m.fill([0.0; LANES]);
                return;
            };
            // Backwards: T_k = F_k · J_k(q) · T_{k+1}, the end point in the start frame of run
            // k, kept for every run when GRAD (the array starts as copies of the last run's,
            // its last entry, rather than zeros).
            let t = &last.lane_fixed.trans;
            let mut p = [V::splat(t.x), V::splat(t.y), V::splat(t.z)];
            let mut tips = [p; N];
            for (k, seg) in rest.iter().enumerate().rev() {
                if let Some(screw) = &seg.joint {
                    let s = V::load_at(trig, 2 * screw.joint, trig_stride);
                    let c = V::load_at(trig, 2 * screw.joint + 1, trig_stride);
                    p = rotate!(p, screw.axis, s, c, false);
                }
                let f = &seg.lane_fixed;
                let r = &f.rot;
                p = [
                    dot3_s_add(&p, [r[(0, 0)], r[(0, 1)], r[(0, 2)]], V::splat(f.trans.x)),
                    dot3_s_add(&p, [r[(1, 0)], r[(1, 1)], r[(1, 2)]], V::splat(f.trans.y)),
                    dot3_s_add(&p, [r[(2, 0)], r[(2, 1)], r[(2, 2)]], V::splat(f.trans.z)),
                ];
                if GRAD {
                    tips[k] = p;
                }
            }
            let norm = p[2].mul_add(p[2], p[1].mul_add(p[1], p[0].mul(p[0]))).sqrt();
            norm.store_at(distance_m, 0, 1);
            if !GRAD {
                return;
            }
            if !chain.all_params_tapped {
                for param in 0..chain.n_params {
                    for g in 0..V::GROUPS {
                        *grad.lanes(param, first_group + g) = [0.0; LANES];
                    }
                }
            }
            // Forwards: U_0 = grad_scale · P/|P| (0 where P = 0: then every term is 0), and
            // U_{k+1} = J_k(q)ᵀ · F_kᵀ · U_k.
            let f = norm.recip_scaled_or_zero(grad_scale);
            let mut ul = [p[0].mul(f), p[1].mul(f), p[2].mul(f)];
            for (seg, tl) in segments.iter().zip(&tips) {
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
                            let [c0, c1, c2] = [V::splat(tap.c.x), V::splat(tap.c.y), V::splat(tap.c.z)];
                            let va = dot3_s(&v, a);
                            ul[2].neg_mul_add(c2, ul[1].neg_mul_add(c1, ul[0].neg_mul_add(c0, va)))
                        } else {
                            dot3_s(&ul, a)
                        };
                        let sum = if tap.first {
                            term
                        } else {
                            V::from_groups(|g| *grad.lanes(tap.param, first_group + g)).add(term)
                        };
                        for g in 0..V::GROUPS {
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
                    let s = V::load_at(trig, 2 * screw.joint, trig_stride);
                    let c = V::load_at(trig, 2 * screw.joint + 1, trig_stride);
                    ul = rotate!(w, screw.axis, s, c, true);
                }
            }
        }
    };
}
lane_kernel!(
    /// The kernel in plain loops over the lanes.
    kernel_portable,
    Portable
);

#[cfg(target_arch = "x86_64")]
lane_kernel!(
    /// The kernel in AVX-512 registers.
    #[target_feature(enable = "avx512f")]
    kernel_avx512,
    simd::Avx512
);

#[cfg(target_arch = "x86_64")]
lane_kernel!(
    /// The kernel in AVX-512 registers, two groups at once.
    #[target_feature(enable = "avx512f")]
    kernel_avx512x2,
    simd::Avx512x2
);

#[cfg(target_arch = "x86_64")]
lane_kernel!(
    /// The kernel in AVX2 registers, with FMA.
    #[target_feature(enable = "avx2,fma")]
    kernel_avx2,
    simd::Avx2
);

/// The results `(kernel, distances, gradient)` of every kernel this CPU runs on two groups
/// (`trig` of `2 · n_joints()` entries), with the gradient, for tests; the gradient-free
/// runs must give the same distances (checked here).
#[cfg(test)]
pub(crate) fn every_kernel(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
) -> Vec<(&'static str, Vec<Lane>, Vec<Lane>)> {
    type Kernel<'a> = &'a dyn Fn(&[Lane], &mut [Lane], &mut LaneBuf<'_>, bool);
    let (trig, nt, np) = (trig.as_flattened(), 2 * chain.n_joints, chain.n_params);
    let mut results = Vec::new();
    // `per_group`: the kernel takes one group at a time, else both.
    let mut run = |name, per_group: bool, f: Kernel<'_>| {
        let mut dist = vec![[0.0; LANES]; 2];
        let mut grad = vec![[f64::NAN; LANES]; 2 * np];
        let mut dist_only = vec![[0.0; LANES]; 2];
        fn sink(buf: &mut [Lane], n_params: usize) -> LaneBuf<'_> {
            LaneBuf { buf, n_params }
        }
        if per_group {
            for g in 0..2 {
                let t = &trig[g * nt..(g + 1) * nt];
                let group_grad = &mut grad[g * np..(g + 1) * np];
                f(t, &mut dist[g..g + 1], &mut sink(group_grad, np), true);
                f(t, &mut dist_only[g..g + 1], &mut sink(&mut [], np), false);
            }
        } else {
            f(trig, &mut dist, &mut sink(&mut grad, np), true);
            f(trig, &mut dist_only, &mut sink(&mut [], np), false);
        }
        assert_eq!(
            dist, dist_only,
            "{name}: distances with and without the gradient"
        );
        results.push((name, dist, grad));
    };
    run("portable", true, &|t, d, g, with_grad| {
        if with_grad {
            kernel_portable::<true, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
        } else {
            kernel_portable::<false, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
        }
    });
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            run("avx2", true, &|t, d, g, with_grad| {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                unsafe {
                    if with_grad {
                        kernel_avx2::<true, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
                    } else {
                        kernel_avx2::<false, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
                    }
                }
            });
        }
        if std::arch::is_x86_feature_detected!("avx512f") {
            run("avx512", true, &|t, d, g, with_grad| {
                // SAFETY: the CPU has AVX-512F (checked just above).
                unsafe {
                    if with_grad {
                        kernel_avx512::<true, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
                    } else {
                        kernel_avx512::<false, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
                    }
                }
            });
            run("avx512x2", false, &|t, d, g, with_grad| {
                // SAFETY: the CPU has AVX-512F (checked just above).
                unsafe {
                    if with_grad {
                        kernel_avx512x2::<true, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
                    } else {
                        kernel_avx512x2::<false, _, MAX_SEGMENTS>(chain, t, grad_scale, d, g, 0)
                    }
                }
            });
        }
    }
    results
}

/// Runs the lane kernel compiled for the best instruction set of this CPU on every group
/// (two at a time where the registers allow).
#[inline(always)]
fn dispatch<const GRAD: bool, S: GradSink>(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
    distance_m: &mut [Lane],
    grad: &mut S,
) {
    if chain.segments.len() <= SHORT_SEGMENTS {
        dispatch_n::<GRAD, S, SHORT_SEGMENTS>(chain, trig, grad_scale, distance_m, grad);
    } else {
        dispatch_n::<GRAD, S, MAX_SEGMENTS>(chain, trig, grad_scale, distance_m, grad);
    }
}

/// [`dispatch`] for chains of at most `N` runs.
#[inline(always)]
fn dispatch_n<const GRAD: bool, S: GradSink, const N: usize>(
    chain: &FrozenChain,
    trig: &[[Lane; 2]],
    grad_scale: f64,
    distance_m: &mut [Lane],
    grad: &mut S,
) {
    let trig = trig.as_flattened();
    let nt = 2 * chain.n_joints;
    // Groups `g..g + k` of the arguments.
    let mut g = 0;
    while g < distance_m.len() {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                let k = if g + 2 <= distance_m.len() { 2 } else { 1 };
                let (t, d) = (&trig[g * nt..(g + k) * nt], &mut distance_m[g..g + k]);
                if k == 2 {
                    // SAFETY: the CPU has AVX-512F (checked just above).
                    unsafe { kernel_avx512x2::<GRAD, S, N>(chain, t, grad_scale, d, grad, g) };
                } else {
                    // SAFETY: the CPU has AVX-512F (checked just above).
                    unsafe { kernel_avx512::<GRAD, S, N>(chain, t, grad_scale, d, grad, g) };
                }
                g += k;
                continue;
            }
        }
        let (t, d) = (&trig[g * nt..(g + 1) * nt], &mut distance_m[g..g + 1]);
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                unsafe { kernel_avx2::<GRAD, S, N>(chain, t, grad_scale, d, grad, g) };
                g += 1;
                continue;
            }
        }
        kernel_portable::<GRAD, S, N>(chain, t, grad_scale, d, grad, g);
        g += 1;
    }
}
