//! Householder QR of a tall, narrow column-major matrix, in place, optionally with column
//! pivoting over a leading set of columns: the factorisation of each LM step.
//!
//! Source: G. H. Golub, C. F. Van Loan, *Matrix Computations*, 4th ed., 2013, Alg. 5.2.1
//! (Householder QR) and §5.4.2 (column pivoting, as MINPACK `qrfac`: the pivot is the
//! remaining column of largest norm, the norms downdated after each step). The pivoted QR of
//! a small triangle ([`qr_in_place`]) is unblocked: each reflection is one pass of dot
//! products and one of updates over four columns at a time. Folding rows into a triangle
//! ([`fold_rows`], the bulk of an LM step's flops) applies its reflections in blocks of four
//! (compact WY, Golub–Van Loan §5.2.3), so that each column of the block of rows is read
//! twice per four reflections rather than twice per reflection. The vector kernels use fused
//! multiply–adds, AVX-512 or AVX2 chosen at run time, with a portable reference.

/// A column-major `nrows × ncols` matrix (leading dimension `nrows`).
pub(crate) struct ColMajor {
    /// The entries, column after column (`nrows · ncols`).
    pub(crate) data: Vec<f64>,
    /// Number of rows.
    pub(crate) nrows: usize,
    /// Number of columns.
    pub(crate) ncols: usize,
}

impl ColMajor {
    /// The zero `nrows × ncols` matrix.
    pub(crate) fn zeros(nrows: usize, ncols: usize) -> Self {
        Self {
            data: vec![0.0; nrows * ncols],
            nrows,
            ncols,
        }
    }

    /// Column `j`.
    ///
    /// # Panics
    /// If `j >= ncols`.
    pub(crate) fn col(&self, j: usize) -> &[f64] {
        &self.data[j * self.nrows..(j + 1) * self.nrows]
    }

    /// Column `j`, mutable.
    ///
    /// # Panics
    /// If `j >= ncols`.
    pub(crate) fn col_mut(&mut self, j: usize) -> &mut [f64] {
        &mut self.data[j * self.nrows..(j + 1) * self.nrows]
    }

    /// Entry `(i, j)`.
    ///
    /// # Panics
    /// If `(i, j)` is outside the matrix.
    pub(crate) fn at(&self, i: usize, j: usize) -> f64 {
        self.data[j * self.nrows + i]
    }
}

/// The body of a function that runs `$f(args…, kernels)` with the widest kernel set the CPU
/// has: AVX-512 (with AVX2 and FMA), AVX2 with FMA, or scalar. `$f` is generic over
/// [`Kernels`], so its body is compiled once per instruction set, inside a
/// `#[target_feature]` function called only after the features were detected.
macro_rules! with_kernels {
    ($f:ident($($arg:ident: $ty:ty),*) -> $ret:ty) => {{
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx512f,avx2,fma")]
            fn wide($($arg: $ty),*) -> $ret {
                $f($($arg,)* Avx512(()))
            }
            #[target_feature(enable = "avx2,fma")]
            fn narrow($($arg: $ty),*) -> $ret {
                $f($($arg,)* Avx2(()))
            }
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU has AVX-512F, AVX2 and FMA (checked just above).
                return unsafe { wide($($arg),*) };
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                return unsafe { narrow($($arg),*) };
            }
        }
        $f($($arg,)* Scalar)
    }};
}

/// Reduces `a` to `R` in place: afterwards the upper triangle of its first `min(m, n)` rows
/// holds `R` with `A·Π = Q·R` (zeros below the diagonal), where `Π` permutes the first
/// `n_pivot` columns (the others keep their place and only receive the reflections).
/// `perm[k]` is the original index of column `k` (length `ncols`, identity beyond `n_pivot`).
///
/// Pivot `k` is the remaining pivot candidate of largest norm over rows `k..` (the first in
/// column order among equal norms). A zero column gets no reflection (`R_kk = 0`).
pub(crate) fn qr_in_place(a: &mut ColMajor, n_pivot: usize) -> Vec<usize> {
    with_kernels!(qr_impl(a: &mut ColMajor, n_pivot: usize) -> Vec<usize>)
}

/// `‖x‖` (vectorised, rescaled when the sum of squares under- or overflows).
pub(crate) fn norm2(x: &[f64]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F (checked just above).
            return norm(x, |a, b| unsafe { dot_avx512(a, b) });
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return norm(x, |a, b| unsafe { dot_avx2(a, b) });
        }
    }
    norm(x, dot)
}

/// Whether every entry of `x` is finite: `Σ 0·xᵢ` is 0 unless some `xᵢ` is ±∞ or NaN, summed
/// with 8 partial sums (which vectorises, where `f64::is_finite` entry by entry does not).
pub(crate) fn all_finite(x: &[f64]) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F (checked just above).
            return unsafe { all_finite_avx512(x) };
        }
    }
    all_finite_impl(x)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn all_finite_avx512(x: &[f64]) -> bool {
    all_finite_impl(x)
}

#[inline(always)]
fn all_finite_impl(x: &[f64]) -> bool {
    let (chunks, tail) = x.as_chunks::<8>();
    let mut acc = [0.0_f64; 8];
    for c in chunks {
        for l in 0..8 {
            acc[l] += c[l] * 0.0;
        }
    }
    acc.iter().all(|a| *a == 0.0) && tail.iter().all(|v| v.is_finite())
}

/// The vector kernels of the reflections, for one instruction set ([`Scalar`] is the
/// reference; the vectorised ones agree with it up to rounding).
trait Kernels: Copy {
    /// `Σ xᵢyᵢ` over `x.len()` entries.
    fn dot(self, x: &[f64], y: &[f64]) -> f64;
    /// `w[i][c] = v_i·y_c` for `NB` vectors and `C` columns, all of one length: one pass
    /// over the data, fused multiply–adds where the instruction set has them.
    fn dots<const NB: usize, const C: usize>(
        self,
        v: [&[f64]; NB],
        y: [&[f64]; C],
    ) -> [[f64; C]; NB];
    /// `y_c ← y_c − Σᵢ w[i][c]·v_i` (`i` in order), all of one length: one pass over the
    /// data, fused multiply–adds where the instruction set has them.
    fn update<const NB: usize, const C: usize>(
        self,
        v: [&[f64]; NB],
        w: [[f64; C]; NB],
        y: [&mut [f64]; C],
    );
}

/// The portable kernels (the reference for the vectorised ones).
#[derive(Clone, Copy)]
struct Scalar;

impl Kernels for Scalar {
    #[inline(always)]
    fn dot(self, x: &[f64], y: &[f64]) -> f64 {
        dot(x, y)
    }
    #[inline(always)]
    fn dots<const NB: usize, const C: usize>(
        self,
        v: [&[f64]; NB],
        y: [&[f64]; C],
    ) -> [[f64; C]; NB] {
        let mut w = [[0.0; C]; NB];
        for (wi, vi) in w.iter_mut().zip(v) {
            for (wic, yc) in wi.iter_mut().zip(y) {
                *wic = dot(vi, yc);
            }
        }
        w
    }
    #[inline(always)]
    fn update<const NB: usize, const C: usize>(
        self,
        v: [&[f64]; NB],
        w: [[f64; C]; NB],
        y: [&mut [f64]; C],
    ) {
        for (c, yc) in y.into_iter().enumerate() {
            for (wi, vi) in w.iter().zip(v) {
                axpy(wi[c], vi, yc);
            }
        }
    }
}

/// Declares a zero-sized kernel set for one instruction set and implements [`Kernels`] by
/// forwarding to its `#[target_feature]` functions; a value exists only where the CPU has the
/// features (it is made in `#[target_feature]` functions that are called after detection).
#[cfg(target_arch = "x86_64")]
macro_rules! simd_kernels {
    ($(#[$attr:meta])* $ty:ident: $dot:ident, $dots:ident, $update:ident) => {
        $(#[$attr])*
        #[derive(Clone, Copy)]
        struct $ty(());

        impl Kernels for $ty {
            #[inline(always)]
            fn dot(self, x: &[f64], y: &[f64]) -> f64 {
                // SAFETY: a value of this type exists only where the CPU has the features of
                // the kernel (see the type).
                unsafe { $dot(x, y) }
            }
            #[inline(always)]
            fn dots<const NB: usize, const C: usize>(
                self,
                v: [&[f64]; NB],
                y: [&[f64]; C],
            ) -> [[f64; C]; NB] {
                // SAFETY: as above.
                unsafe { $dots(v, y) }
            }
            #[inline(always)]
            fn update<const NB: usize, const C: usize>(
                self,
                v: [&[f64]; NB],
                w: [[f64; C]; NB],
                y: [&mut [f64]; C],
            ) {
                // SAFETY: as above.
                unsafe { $update(v, w, y) }
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
simd_kernels! {
    /// AVX2 kernels; a value exists only where the CPU has AVX2 and FMA.
    Avx2: dot_avx2, dots_avx2, update_avx2
}

#[cfg(target_arch = "x86_64")]
simd_kernels! {
    /// AVX-512 kernels; a value exists only where the CPU has AVX-512F, AVX2 and FMA.
    Avx512: dot_avx512, dots_avx512, update_avx512
}

/// The common length of the slices of `v` and `y`.
///
/// # Panics
/// If they differ.
#[track_caller]
fn common_len(v: &[&[f64]], y: &[&[f64]]) -> usize {
    let n = v.first().or(y.first()).map_or(0, |s| s.len());
    assert!(
        v.iter().chain(y).all(|s| s.len() == n),
        "slices of different lengths"
    );
    n
}

/// The lanes `0..len` (`len < 4`) of a masked 4-lane load or store.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn mask4(len: usize) -> std::arch::x86_64::__m256i {
    let lane = |l: usize| if l < len { -1 } else { 0 };
    std::arch::x86_64::_mm256_setr_epi64x(lane(0), lane(1), lane(2), lane(3))
}

/// Stamps [`Kernels::dots`] for one instruction set from one body: `w_ic = v_iᵀy_c`, one
/// accumulator per pair, a masked tail. The arguments name the vector intrinsics (`zero`,
/// `load`, `fmadd`, `add`), the lane count, whether few pairs (`NB·C ≤ 2`) get a second set of
/// accumulators for the odd vectors (two FMA chains per pair hide the FMA latency), how the
/// tail's mask is built and used by a masked load, and how an accumulator is summed.
#[cfg(target_arch = "x86_64")]
macro_rules! dots_kernel {
    (
        $(#[$attr:meta])*
        fn $name:ident, lanes $w:literal, two_chains $two:literal,
        [$zero:ident, $load:ident, $fmadd:ident, $add:ident],
        mask($rem:ident) = $mask:expr,
        masked_load($lp:ident, $lk:ident) = $mload:expr,
        sum($acc:ident) = $sum:expr $(,)?
    ) => {
        $(#[$attr])*
        fn $name<const NB: usize, const C: usize>(
            v: [&[f64]; NB],
            y: [&[f64]; C],
        ) -> [[f64; C]; NB] {
            #[allow(clippy::wildcard_imports)]
            use std::arch::x86_64::*;
            let n = common_len(&v, &y);
            let mut acc = [[$zero(); C]; NB];
            let mut o = 0;
            if $two && NB * C <= 2 {
                let mut acc1 = [[$zero(); C]; NB];
                while o + 2 * $w <= n {
                    // SAFETY: entries `o..o + 2·lanes` of every slice are in bounds.
                    unsafe {
                        for i in 0..NB {
                            let v0 = $load(v[i].as_ptr().add(o));
                            let v1 = $load(v[i].as_ptr().add(o + $w));
                            for c in 0..C {
                                let y0 = $load(y[c].as_ptr().add(o));
                                let y1 = $load(y[c].as_ptr().add(o + $w));
                                acc[i][c] = $fmadd(v0, y0, acc[i][c]);
                                acc1[i][c] = $fmadd(v1, y1, acc1[i][c]);
                            }
                        }
                    }
                    o += 2 * $w;
                }
                for i in 0..NB {
                    for c in 0..C {
                        acc[i][c] = $add(acc[i][c], acc1[i][c]);
                    }
                }
            }
            while o + $w <= n {
                // SAFETY: entries `o..o + lanes` of every slice are in bounds (`o + lanes ≤ n`).
                unsafe {
                    let mut yv = [$zero(); C];
                    for c in 0..C {
                        yv[c] = $load(y[c].as_ptr().add(o));
                    }
                    for i in 0..NB {
                        let vv = $load(v[i].as_ptr().add(o));
                        for c in 0..C {
                            acc[i][c] = $fmadd(vv, yv[c], acc[i][c]);
                        }
                    }
                }
                o += $w;
            }
            if o < n {
                let $rem = n - o;
                let mask = $mask;
                // SAFETY: entries `o..n` of every slice are in bounds; the masked-off lanes are
                // not read.
                unsafe {
                    let mut yv = [$zero(); C];
                    for c in 0..C {
                        let ($lp, $lk) = (y[c].as_ptr().add(o), mask);
                        yv[c] = $mload;
                    }
                    for i in 0..NB {
                        let ($lp, $lk) = (v[i].as_ptr().add(o), mask);
                        let vv = $mload;
                        for c in 0..C {
                            acc[i][c] = $fmadd(vv, yv[c], acc[i][c]);
                        }
                    }
                }
            }
            let mut w = [[0.0; C]; NB];
            for i in 0..NB {
                for c in 0..C {
                    let $acc = acc[i][c];
                    w[i][c] = $sum;
                }
            }
            w
        }
    };
}

#[cfg(target_arch = "x86_64")]
dots_kernel! {
    /// [`Kernels::dots`] with AVX-512: one 8-lane accumulator per pair (two for one or two
    /// pairs), a masked tail.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    fn dots_avx512, lanes 8, two_chains true,
    [_mm512_setzero_pd, _mm512_loadu_pd, _mm512_fmadd_pd, _mm512_add_pd],
    mask(rem) = 0xff_u8 >> (8 - rem),
    masked_load(p, k) = _mm512_maskz_loadu_pd(k, p),
    sum(a) = _mm512_reduce_add_pd(a),
}

#[cfg(target_arch = "x86_64")]
dots_kernel! {
    /// [`Kernels::dots`] with AVX2 and FMA: one 4-lane accumulator per pair, a masked tail.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn dots_avx2, lanes 4, two_chains false,
    [_mm256_setzero_pd, _mm256_loadu_pd, _mm256_fmadd_pd, _mm256_add_pd],
    mask(rem) = mask4(rem),
    masked_load(p, k) = _mm256_maskload_pd(p, k),
    sum(a) = {
        let mut lanes = [0.0; 4];
        // SAFETY: `lanes` holds 4 f64.
        unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), a) };
        (lanes[0] + lanes[2]) + (lanes[1] + lanes[3])
    },
}

/// Stamps [`Kernels::update`] for one instruction set from one body: `y_c ← y_c − Σ_i w_ic·v_i`,
/// each `v_i` loaded once per vector of rows, a masked tail. The arguments name the vector
/// intrinsics (`zero`, `splat`, `load`, `store`, `fnmadd`), the lane count, and how the tail's
/// mask is built from the number of remaining rows and used by a masked load and store.
#[cfg(target_arch = "x86_64")]
macro_rules! update_kernel {
    (
        $(#[$attr:meta])*
        fn $name:ident, lanes $w:literal,
        [$zero:ident, $splat:ident, $load:ident, $store:ident, $fnmadd:ident],
        mask($rem:ident) = $mask:expr,
        masked_load($lp:ident, $lk:ident) = $mload:expr,
        masked_store($sp:ident, $sk:ident, $sv:ident) = $mstore:expr $(,)?
    ) => {
        $(#[$attr])*
        fn $name<const NB: usize, const C: usize>(
            v: [&[f64]; NB],
            w: [[f64; C]; NB],
            y: [&mut [f64]; C],
        ) {
            #[allow(clippy::wildcard_imports)]
            use std::arch::x86_64::*;
            let n = {
                let yr: [&[f64]; C] = std::array::from_fn(|c| &*y[c]);
                common_len(&v, &yr)
            };
            let mut wv = [[$zero(); C]; NB];
            for i in 0..NB {
                for c in 0..C {
                    wv[i][c] = $splat(w[i][c]);
                }
            }
            let mut o = 0;
            while o + $w <= n {
                // SAFETY: entries `o..o + lanes` of every slice are in bounds (`o + lanes ≤
                // n`); the `y_c` are distinct `&mut`, so the stores do not overlap the loads of
                // `v`.
                unsafe {
                    let mut vv = [$zero(); NB];
                    for i in 0..NB {
                        vv[i] = $load(v[i].as_ptr().add(o));
                    }
                    for c in 0..C {
                        let p = y[c].as_mut_ptr().add(o);
                        let mut a = $load(p);
                        for i in 0..NB {
                            a = $fnmadd(vv[i], wv[i][c], a);
                        }
                        $store(p, a);
                    }
                }
                o += $w;
            }
            if o < n {
                let $rem = n - o;
                let mask = $mask;
                // SAFETY: entries `o..n` of every slice are in bounds; the masked-off lanes are
                // neither read nor written.
                unsafe {
                    let mut vv = [$zero(); NB];
                    for i in 0..NB {
                        let ($lp, $lk) = (v[i].as_ptr().add(o), mask);
                        vv[i] = $mload;
                    }
                    for c in 0..C {
                        let p = y[c].as_mut_ptr().add(o);
                        let mut a = {
                            let ($lp, $lk) = (p.cast_const(), mask);
                            $mload
                        };
                        for i in 0..NB {
                            a = $fnmadd(vv[i], wv[i][c], a);
                        }
                        let ($sp, $sk, $sv) = (p, mask, a);
                        $mstore;
                    }
                }
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
update_kernel! {
    /// [`Kernels::update`] with AVX-512: each `v_i` loaded once per 8 rows, a masked tail.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    fn update_avx512, lanes 8,
    [_mm512_setzero_pd, _mm512_set1_pd, _mm512_loadu_pd, _mm512_storeu_pd, _mm512_fnmadd_pd],
    mask(rem) = 0xff_u8 >> (8 - rem),
    masked_load(p, k) = _mm512_maskz_loadu_pd(k, p),
    masked_store(p, k, a) = _mm512_mask_storeu_pd(p, k, a),
}

#[cfg(target_arch = "x86_64")]
update_kernel! {
    /// [`Kernels::update`] with AVX2 and FMA: each `v_i` loaded once per 4 rows, a masked tail.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn update_avx2, lanes 4,
    [_mm256_setzero_pd, _mm256_set1_pd, _mm256_loadu_pd, _mm256_storeu_pd, _mm256_fnmadd_pd],
    mask(rem) = mask4(rem),
    masked_load(p, k) = _mm256_maskload_pd(p, k),
    masked_store(p, k, a) = _mm256_maskstore_pd(p, k, a),
}

/// Splits the next `C` columns off `rest` (column-major, leading dimension `ld`), rows
/// `offset..offset + len` of each; `rest` then starts at the column after them. The last
/// column of `rest` may end early (at `offset + len`).
#[inline(always)]
fn take_cols<'a, const C: usize>(
    rest: &mut &'a mut [f64],
    ld: usize,
    offset: usize,
    len: usize,
) -> [&'a mut [f64]; C] {
    std::array::from_fn(|_| {
        let all = std::mem::take(rest);
        let (col, tail) = all.split_at_mut(ld.min(all.len()));
        *rest = tail;
        &mut col[offset..offset + len]
    })
}

/// Stamps a two-accumulator dot product `Σ xᵢyᵢ` over `min(len)` entries for one instruction
/// set (LLVM does not vectorise a loop-carried partial-sum array by itself): blocks of two
/// vectors of `lanes` entries, each vector into its own accumulator (a product, then a sum),
/// then `sum(acc)` of the two accumulators' sum plus `tail(x, y)` of the remaining entries.
#[cfg(target_arch = "x86_64")]
macro_rules! dot_kernel {
    (
        $(#[$attr:meta])*
        fn $name:ident, lanes $w:literal, [$zero:ident, $load:ident, $mul:ident, $add:ident],
        sum($acc:ident) = $sum:expr,
        tail($tx:ident, $ty:ident) = $tail:expr $(,)?
    ) => {
        $(#[$attr])*
        fn $name(x: &[f64], y: &[f64]) -> f64 {
            #[allow(clippy::wildcard_imports)]
            use std::arch::x86_64::*;
            let n = x.len().min(y.len());
            let (x, y) = (&x[..n], &y[..n]);
            let (xc, $tx) = x.as_chunks::<{ 2 * $w }>();
            let (yc, $ty) = y.as_chunks::<{ 2 * $w }>();
            let mut a0 = $zero();
            let mut a1 = $zero();
            for (a, b) in xc.iter().zip(yc) {
                // SAFETY: each chunk holds 2·lanes f64, read as two unaligned loads.
                unsafe {
                    a0 = $add(a0, $mul($load(a.as_ptr()), $load(b.as_ptr())));
                    a1 = $add(
                        a1,
                        $mul($load(a.as_ptr().add($w)), $load(b.as_ptr().add($w))),
                    );
                }
            }
            let $acc = $add(a0, a1);
            let sum: f64 = $sum;
            let tail: f64 = $tail;
            sum + tail
        }
    };
}

#[cfg(target_arch = "x86_64")]
dot_kernel! {
    /// As [`dot_avx2`] with one 8-wide AVX-512 accumulator per 8 entries (two per 16); the
    /// tail (< 16 entries) by the AVX2 dot product.
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn dot_avx512, lanes 8, [_mm512_setzero_pd, _mm512_loadu_pd, _mm512_mul_pd, _mm512_add_pd],
    sum(acc) = _mm512_reduce_add_pd(acc),
    tail(xt, yt) = dot_avx2(xt, yt),
}

#[cfg(target_arch = "x86_64")]
dot_kernel! {
    /// `Σ xᵢyᵢ` over `min(len)` entries with two 4-wide AVX accumulators, the tail (< 8
    /// entries) in scalar.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn dot_avx2, lanes 4, [_mm256_setzero_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_add_pd],
    sum(acc) = {
        let mut lanes = [0.0; 4];
        // SAFETY: `lanes` holds 4 f64.
        unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), acc) };
        (lanes[0] + lanes[2]) + (lanes[1] + lanes[3])
    },
    tail(xt, yt) = {
        let mut tail = 0.0;
        for (a, b) in xt.iter().zip(yt) {
            tail += a * b;
        }
        tail
    },
}

/// `Σ xᵢyᵢ` with 8 partial sums (vectorisable without reassociating a single sum).
#[inline(always)]
pub(crate) fn dot(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &y[..n]);
    let (xc, xt) = x.as_chunks::<8>();
    let (yc, yt) = y.as_chunks::<8>();
    let mut acc = [0.0; 8];
    for (a, b) in xc.iter().zip(yc) {
        for l in 0..8 {
            acc[l] += a[l] * b[l];
        }
    }
    let mut tail = 0.0;
    for (a, b) in xt.iter().zip(yt) {
        tail += a * b;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// `y ← y − f·v`.
#[inline(always)]
fn axpy(f: f64, v: &[f64], y: &mut [f64]) {
    for (yi, vi) in y.iter_mut().zip(v) {
        *yi -= f * vi;
    }
}

/// `‖x‖`, by the sum of squares, rescaled when that under- or overflows (LAPACK `dnrm2`'s
/// concern).
#[inline(always)]
fn norm(x: &[f64], dot: impl Fn(&[f64], &[f64]) -> f64) -> f64 {
    let ss = dot(x, x);
    if ss.is_finite() && ss > 1e-280 {
        return ss.sqrt();
    }
    let scale = x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return scale;
    }
    let ss: f64 = x.iter().map(|v| (v / scale) * (v / scale)).sum();
    scale * ss.sqrt()
}

#[inline(always)]
fn qr_impl(a: &mut ColMajor, n_pivot: usize, kern: impl Kernels) -> Vec<usize> {
    let dot = |x: &[f64], y: &[f64]| kern.dot(x, y);
    let (m, n) = (a.nrows, a.ncols);
    let n_pivot = n_pivot.min(n);
    let mut perm: Vec<usize> = (0..n).collect();
    // Squared norms of the pivot candidates over rows k.., downdated after each reflection
    // (`‖x‖² − x_k²`, MINPACK `qrfac`'s `‖x‖·√(1 − (x_k/‖x‖)²)` without its division and
    // square root) and recomputed once cancellation has cost them half their digits (MINPACK's
    // test `0.05·(‖x‖/‖x‖_ref)² ≤ ε`).
    let mut cand: Vec<f64> = (0..n_pivot).map(|j| norm(a.col(j), dot).powi(2)).collect();
    let mut cand_ref = cand.clone();
    for k in 0..m.min(n) {
        if k < n_pivot {
            let mut best = k;
            for j in k + 1..n_pivot {
                if cand[j] > cand[best] {
                    best = j;
                }
            }
            if best != k {
                let (lo, hi) = a.data.split_at_mut(best * m);
                lo[k * m..(k + 1) * m].swap_with_slice(&mut hi[..m]);
                perm.swap(k, best);
                cand.swap(k, best);
                cand_ref.swap(k, best);
            }
        }
        let (head, tail) = a.data.split_at_mut((k + 1) * m);
        let v = &mut head[k * m + k..(k + 1) * m];
        let x_norm = norm(v, dot);
        if x_norm != 0.0 {
            let x0 = v[0];
            let alpha = if x0 > 0.0 { -x_norm } else { x_norm };
            v[0] = x0 - alpha;
            // vᵀv = 2‖x‖(‖x‖ + |x₀|) for v = x − αe₁; column j gets y ← y − τ(vᵀy)·v, τ = 2/vᵀv.
            let vtv = 2.0 * x_norm * (x_norm + x0.abs());
            let tau = 2.0 / vtv;
            {
                let v = &*v;
                let mut rest = &mut tail[..];
                for _ in 0..(n - k - 1) / 4 {
                    let y = take_cols::<4>(&mut rest, m, k, m - k);
                    let [d] = kern.dots::<1, 4>([v], [&*y[0], &*y[1], &*y[2], &*y[3]]);
                    let f = [tau * d[0], tau * d[1], tau * d[2], tau * d[3]];
                    kern.update::<1, 4>([v], [f], y);
                }
                for _ in 0..(n - k - 1) % 4 {
                    let y = take_cols::<1>(&mut rest, m, k, m - k);
                    let [[d]] = kern.dots::<1, 1>([v], [&*y[0]]);
                    kern.update::<1, 1>([v], [[tau * d]], y);
                }
            }
            v[0] = alpha;
            v[1..].iter_mut().for_each(|e| *e = 0.0);
        }
        for j in k + 1..n_pivot {
            cand[j] = (cand[j] - a.at(k, j).powi(2)).max(0.0);
            if cand[j] <= 20.0 * f64::EPSILON * cand_ref[j] && cand_ref[j] != 0.0 {
                cand[j] = norm(&a.col(j)[k + 1..], dot).powi(2);
                cand_ref[j] = cand[j];
            }
        }
    }
    perm
}

/// Folds the rows `b` (`len × n1`, column-major with leading dimension `ldb ≥ len`) into the
/// upper-triangular `r` (`n1 × n1`, column-major): afterwards `r` is the R factor of `[r; b]`
/// (`RᵀR` grows by `bᵀb`), and `b` is scratch. See [`fold_cols`].
///
/// # Panics
/// If the slices are shorter than the shapes say.
pub(crate) fn fold_rows(r: &mut [f64], n1: usize, b: &mut [f64], len: usize, ldb: usize) {
    assert!(ldb >= len && (n1 == 0 || b.len() >= (n1 - 1) * ldb + len));
    if n1 == 0 || len == 0 {
        return;
    }
    let mut cols: Vec<&mut [f64]> = b.chunks_mut(ldb).take(n1).map(|c| &mut c[..len]).collect();
    fold_cols(r, &mut cols);
}

/// [`fold_rows`] with the columns of `B` given one by one (`n1 = cols.len()` slices of one
/// length, anywhere in memory): afterwards `r` is the R factor of `[r; B]`, and the columns
/// are scratch.
///
/// The Householder QR of `[R; B]` with its structure used (Golub–Van Loan §5.2.2 for the
/// update, the TSQR step of Demmel et al. 2012): reflection `k` touches row `k` of `R` and the
/// rows of `B` only, since `R` is zero below its diagonal. `≈ 2·len·n1²` flops on a working
/// set of one block, which stays in cache.
///
/// # Panics
/// If `r` is shorter than `n1²` or the columns differ in length.
pub(crate) fn fold_cols(r: &mut [f64], cols: &mut [&mut [f64]]) {
    let n1 = cols.len();
    assert!(r.len() >= n1 * n1, "r shorter than n1²");
    let len = cols.first().map_or(0, |c| c.len());
    assert!(
        cols.iter().all(|c| c.len() == len),
        "columns of different lengths"
    );
    with_kernels!(fold_impl(r: &mut [f64], cols: &mut [&mut [f64]]) -> ())
}

/// The Householder reflection `H = I − τ·v vᵀ` that maps `x = [x0; t]` (`‖t‖ = tail_norm`)
/// to `[α; 0]`: `α = −sign(x0)·‖x‖` (no cancellation in `v0`), `v = [x0 − α; t]`, `τ = 2/vᵀv`
/// with `vᵀv = 2‖x‖(‖x‖ + |x0|)` (Golub and Van Loan, Matrix Computations, §5.1.2). Returns
/// `(α, v0, τ)`; `tail_norm > 0` (else there is nothing to reflect).
pub(crate) fn reflector(x0: f64, tail_norm: f64) -> (f64, f64, f64) {
    let x_norm = x0.hypot(tail_norm);
    let alpha = if x0 > 0.0 { -x_norm } else { x_norm };
    let vtv = 2.0 * x_norm * (x_norm + x0.abs());
    (alpha, x0 - alpha, 2.0 / vtv)
}

/// Splits the next `C` columns off `rest`.
///
/// # Panics
/// If `rest` holds fewer than `C` columns.
#[inline(always)]
fn take_group<'a, const C: usize>(rest: &mut &'a mut [&mut [f64]]) -> [&'a mut [f64]; C] {
    let (group, tail) = std::mem::take(rest).split_at_mut(C);
    *rest = tail;
    let mut group = group.iter_mut();
    std::array::from_fn(|_| match group.next() {
        Some(c) => &mut **c,
        None => unreachable!("split_at_mut(C) gave C columns"),
    })
}

/// Reflections per block of the compact-WY update of [`fold_rows`].
const NB: usize = 4;

#[inline(always)]
fn fold_impl(r: &mut [f64], cols: &mut [&mut [f64]], kern: impl Kernels) {
    let n1 = cols.len();
    if cols.first().is_none_or(|c| c.is_empty()) {
        return;
    }
    let dot = |x: &[f64], y: &[f64]| kern.dot(x, y);
    let mut k0 = 0;
    while k0 < n1 {
        // Reflections k0..k1: each first applied to the later columns of its block only (all
        // later columns in a last, short block), then together to the columns after the block.
        let k1 = (k0 + NB).min(n1);
        let blocked = k1 - k0 == NB && k1 < n1;
        let j_end = if blocked { k1 } else { n1 };
        // H_k = I − τ_k v_k v_kᵀ, v_k = [v0_k at row k of R; B[:, k]] (τ_k = 0: no reflection).
        let mut tau = [0.0; NB];
        let mut v0 = [0.0; NB];
        for k in k0..k1 {
            // x = [R_kk; B[:, k]].
            let (head, tail) = cols.split_at_mut(k + 1);
            let bk = &*head[k];
            let bk_norm = norm(bk, dot);
            if bk_norm == 0.0 {
                continue;
            }
            let rkk = r[k * n1 + k];
            let (alpha, vk0, tau_k) = reflector(rkk, bk_norm);
            // Column j of [R; B] gets f = τ_k·(v0_k·R_kj + B_kᵀB_j), four columns at a time.
            let mut rest = &mut tail[..j_end - k - 1];
            let mut j = k + 1;
            while j < j_end {
                let reflect = |r: &mut [f64], d: f64, j: usize| {
                    let rkj = r[j * n1 + k];
                    let f = tau_k * (vk0 * rkj + d);
                    r[j * n1 + k] = rkj - f * vk0;
                    f
                };
                if j + 4 <= j_end {
                    let y = take_group::<4>(&mut rest);
                    let [d] = kern.dots::<1, 4>([bk], [&*y[0], &*y[1], &*y[2], &*y[3]]);
                    let f = [
                        reflect(r, d[0], j),
                        reflect(r, d[1], j + 1),
                        reflect(r, d[2], j + 2),
                        reflect(r, d[3], j + 3),
                    ];
                    kern.update::<1, 4>([bk], [f], y);
                    j += 4;
                } else if j + 2 <= j_end {
                    let y = take_group::<2>(&mut rest);
                    let [d] = kern.dots::<1, 2>([bk], [&*y[0], &*y[1]]);
                    let f = [reflect(r, d[0], j), reflect(r, d[1], j + 1)];
                    kern.update::<1, 2>([bk], [f], y);
                    j += 2;
                } else {
                    let y = take_group::<1>(&mut rest);
                    let [[d]] = kern.dots::<1, 1>([bk], [&*y[0]]);
                    let f = reflect(r, d, j);
                    kern.update::<1, 1>([bk], [[f]], y);
                    j += 1;
                }
            }
            r[k * n1 + k] = alpha;
            tau[k - k0] = tau_k;
            v0[k - k0] = vk0;
        }
        if blocked {
            apply_block(r, cols, k0, &tau, &v0, kern);
        }
        k0 = k1;
    }
}

/// Applies the block of reflections `k0..k0 + NB` of [`fold_impl`] (`τ`, `v0`, and their
/// `B` parts in the columns `k0..k0 + NB` of `cols`) to the columns `k0 + NB..n1` of `[R; B]`.
///
/// Compact WY (Schreiber and Van Loan 1989; LAPACK `dlarft`, forward, columnwise):
/// `H_0⋯H_{NB−1} = I − V T Vᵀ` with `T` upper triangular, `T_ii = τ_i` and
/// `T[..i, i] = −τ_i T[..i, ..i] Vᵀv_i`, so `Qᵀx = x − V Tᵀ (Vᵀx)`: one pass over a column
/// for the `NB` dot products and one for the update, in place of `NB` of each. The `R` parts
/// of the `v_i` lie in different rows (`v0_i` at row `k0 + i`), so `v_lᵀv_i = B_lᵀB_i`.
#[inline(always)]
fn apply_block(
    r: &mut [f64],
    cols: &mut [&mut [f64]],
    k0: usize,
    tau: &[f64; NB],
    v0: &[f64; NB],
    kern: impl Kernels,
) {
    let n1 = cols.len();
    let (head, tail) = cols.split_at_mut(k0 + NB);
    let v: [&[f64]; NB] = std::array::from_fn(|i| &*head[k0 + i]);
    let mut t = [[0.0; NB]; NB]; // t[l][i] = T_li
    for i in 0..NB {
        t[i][i] = tau[i];
        let mut g = [0.0; NB];
        for l in 0..i {
            g[l] = kern.dot(v[l], v[i]);
        }
        for (l, tl) in t.iter_mut().enumerate().take(i) {
            let s: f64 = (l..i).map(|m| tl[m] * g[m]).sum();
            tl[i] = -tau[i] * s;
        }
    }
    // Columns k0 + NB.., two at a time, then the last one alone.
    let mut rest = tail;
    let mut j = k0 + NB;
    while j + 2 <= n1 {
        let y = take_group::<2>(&mut rest);
        apply_block_to::<2>(r, n1, k0, j, &v, &t, v0, y, kern);
        j += 2;
    }
    if j < n1 {
        let y = take_group::<1>(&mut rest);
        apply_block_to::<1>(r, n1, k0, j, &v, &t, v0, y, kern);
    }
}

/// `x_c ← x_c − V Tᵀ Vᵀ x_c` for the `C` columns `x_c = [R[k0.., j + c]; y_c]` (see
/// [`apply_block`]).
#[allow(clippy::too_many_arguments)] // the block and the columns it acts on
#[inline(always)]
fn apply_block_to<const C: usize>(
    r: &mut [f64],
    n1: usize,
    k0: usize,
    j: usize,
    v: &[&[f64]; NB],
    t: &[[f64; NB]; NB],
    v0: &[f64; NB],
    y: [&mut [f64]; C],
    kern: impl Kernels,
) {
    let mut w = {
        let yr: [&[f64]; C] = std::array::from_fn(|c| &*y[c]);
        kern.dots::<NB, C>(*v, yr)
    };
    for c in 0..C {
        for l in 0..NB {
            w[l][c] += v0[l] * r[(j + c) * n1 + k0 + l];
        }
    }
    // Tᵀw: (Tᵀw)_i = Σ_{l ≤ i} T_li w_l.
    let mut tw = [[0.0; C]; NB];
    for i in 0..NB {
        for c in 0..C {
            tw[i][c] = (0..=i).map(|l| t[l][i] * w[l][c]).sum();
        }
    }
    for c in 0..C {
        for l in 0..NB {
            r[(j + c) * n1 + k0 + l] -= v0[l] * tw[l][c];
        }
    }
    kern.update::<NB, C>(*v, tw, y);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// QᵀQ = I is not observable without Q, but R must reproduce the Gram matrix of the
    /// permuted columns, `RᵀR = ΠᵀAᵀAΠ`, and be upper triangular with a non-increasing
    /// diagonal under pivoting. Entries O(1), 37 rows: rounding ≈ 1e-14, so 1e-12 fails only
    /// on a wrong reflection, swap or permutation.
    #[test]
    fn r_reproduces_the_gram_matrix_of_the_pivoted_columns() {
        let (m, n) = (37, 6);
        let original = ColMajor {
            data: (0..m * n)
                .map(|t| (((t * 7919) % 101) as f64 / 50.0 - 1.0) * (1.0 + (t / m) as f64))
                .collect(),
            nrows: m,
            ncols: n,
        };
        for n_pivot in [0, 4, n] {
            let mut a = ColMajor {
                data: original.data.clone(),
                nrows: m,
                ncols: n,
            };
            let perm = qr_in_place(&mut a, n_pivot);
            let mut sorted = perm.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..n).collect::<Vec<_>>());
            assert!(
                perm[n_pivot..]
                    .iter()
                    .enumerate()
                    .all(|(i, &p)| p == n_pivot + i)
            );
            for j in 0..n {
                for i in (j + 1)..m {
                    assert_eq!(a.at(i, j), 0.0, "below the diagonal at ({i}, {j})");
                }
                for i in 0..n {
                    let gram = dot(original.col(perm[i]), original.col(perm[j]));
                    let rtr: f64 = (0..=i.min(j)).map(|k| a.at(k, i) * a.at(k, j)).sum();
                    assert!(
                        (gram - rtr).abs() < 1e-12 * gram.abs().max(1.0),
                        "({i}, {j})"
                    );
                }
            }
            for k in 1..n_pivot {
                assert!(a.at(k, k).abs() <= a.at(k - 1, k - 1).abs() * (1.0 + 1e-12));
            }
        }
    }

    /// Folding rows into a triangle keeps the Gram matrix: `R'ᵀR' = RᵀR + BᵀB` (same entries
    /// and tolerance reasoning as above), with R below its diagonal untouched (zero).
    #[test]
    fn folding_rows_adds_their_gram_matrix() {
        let (n1, len, ldb) = (5, 13, 16);
        let mut r = vec![0.0; n1 * n1];
        for j in 0..n1 {
            for i in 0..=j {
                r[j * n1 + i] =
                    ((i * 3 + j * 5) % 7) as f64 / 3.0 - 1.0 + if i == j { 2.0 } else { 0.0 };
            }
        }
        let b: Vec<f64> = (0..n1 * ldb)
            .map(|t| ((t * 37) % 23) as f64 / 11.0 - 1.0)
            .collect();
        let gram = |i: usize, j: usize, r: &[f64]| -> f64 {
            (0..n1).map(|k| r[i * n1 + k] * r[j * n1 + k]).sum()
        };
        let expected: Vec<f64> = (0..n1 * n1)
            .map(|t| {
                let (i, j) = (t / n1, t % n1);
                gram(i, j, &r) + dot(&b[i * ldb..i * ldb + len], &b[j * ldb..j * ldb + len])
            })
            .collect();
        let mut folded = r.clone();
        let mut scratch = b.clone();
        fold_rows(&mut folded, n1, &mut scratch, len, ldb);
        for (t, want) in expected.iter().enumerate() {
            let (i, j) = (t / n1, t % n1);
            let got = gram(i, j, &folded);
            assert!(
                (got - *want).abs() < 1e-12 * want.abs().max(1.0),
                "({i}, {j}): {got} vs {}",
                *want
            );
            if j > i {
                assert_eq!(folded[i * n1 + j], 0.0, "below the diagonal");
            }
        }
    }

    /// Deterministic entries in [−1, 1) (a 64-bit LCG, Knuth's MMIX constants).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// `|a − b| ≤ 1e-12·scale`: the vectorised kernels sum in another order than the
    /// reference, so they agree to rounding (≈ 1e-15 relative for these sizes), not bit for bit.
    #[track_caller]
    fn assert_close(a: f64, b: f64, scale: f64, what: &str) {
        assert!(
            (a - b).abs() <= 1e-12 * scale.max(1.0),
            "{what}: {a} vs {b}"
        );
    }

    /// The kernels of the instruction set `fold_rows` picks on this CPU against [`Scalar`],
    /// for every length up to 40 (all tails of the 8- and 4-lane loops) and 200.
    fn kernels_agree_with_the_reference(kern: impl Kernels) {
        let mut state = 7;
        for n in (0..=40).chain([200]) {
            let v: Vec<Vec<f64>> = (0..4)
                .map(|_| (0..n).map(|_| lcg(&mut state)).collect())
                .collect();
            let y: Vec<Vec<f64>> = (0..2)
                .map(|_| (0..n).map(|_| lcg(&mut state)).collect())
                .collect();
            let vr = [&v[0][..], &v[1][..], &v[2][..], &v[3][..]];
            let yr = [&y[0][..], &y[1][..]];
            let got = kern.dots::<4, 2>(vr, yr);
            let want = Scalar.dots::<4, 2>(vr, yr);
            for i in 0..4 {
                for c in 0..2 {
                    assert_close(got[i][c], want[i][c], n as f64, &format!("dots n={n}"));
                }
                assert_close(kern.dot(vr[i], yr[0]), dot(vr[i], yr[0]), n as f64, "dot");
            }
            let w = [[0.5, -1.5], [2.0, 0.25], [-0.75, 1.0], [1.25, -2.0]];
            let (mut got0, mut got1) = (y[0].clone(), y[1].clone());
            kern.update::<4, 2>(vr, w, [&mut got0[..], &mut got1[..]]);
            let (mut want0, mut want1) = (y[0].clone(), y[1].clone());
            Scalar.update::<4, 2>(vr, w, [&mut want0[..], &mut want1[..]]);
            for r in 0..n {
                assert_close(got0[r], want0[r], 10.0, &format!("update n={n}"));
                assert_close(got1[r], want1[r], 10.0, &format!("update n={n}"));
            }
        }
    }

    #[test]
    fn vector_kernels_agree_with_the_scalar_reference() {
        kernels_agree_with_the_reference(Scalar);
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                kernels_agree_with_the_reference(Avx2(()));
            }
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                kernels_agree_with_the_reference(Avx512(()));
            }
        }
    }

    /// The blocked fold (compact WY) at the shapes that exercise it: fewer and more rows than
    /// columns, column counts below, at and across the block size, the LM's 200 × 29 in a
    /// 256-row buffer. Its `R'ᵀR'` must equal `RᵀR + BᵀB` (as above), and the vectorised
    /// path must agree with the scalar one.
    #[test]
    fn blocked_fold_keeps_the_gram_matrix_and_matches_the_scalar_path() {
        let mut state = 11;
        for (n1, len, ldb) in [
            (1, 5, 5),
            (4, 9, 9),
            (5, 3, 4),
            (9, 40, 41),
            (13, 17, 24),
            (29, 200, 256),
        ] {
            let mut r = vec![0.0; n1 * n1];
            for j in 0..n1 {
                for i in 0..=j {
                    r[j * n1 + i] = lcg(&mut state) + if i == j { 3.0 } else { 0.0 };
                }
            }
            let b: Vec<f64> = (0..n1 * ldb).map(|_| lcg(&mut state)).collect();
            let gram = |i: usize, j: usize, r: &[f64]| -> f64 {
                (0..n1).map(|k| r[i * n1 + k] * r[j * n1 + k]).sum()
            };
            let mut folded = r.clone();
            fold_rows(&mut folded, n1, &mut b.clone(), len, ldb);
            let mut reference = r.clone();
            let mut scratch = b.clone();
            let mut cols: Vec<&mut [f64]> =
                scratch.chunks_mut(ldb).map(|c| &mut c[..len]).collect();
            fold_impl(&mut reference, &mut cols, Scalar);
            let scale = len as f64 + n1 as f64 * 9.0;
            for i in 0..n1 {
                for j in 0..n1 {
                    let want = gram(i, j, &r)
                        + dot(&b[i * ldb..i * ldb + len], &b[j * ldb..j * ldb + len]);
                    let what = format!("{n1}×{len}: ({i}, {j})");
                    assert_close(gram(i, j, &folded), want, scale, &what);
                    assert_close(folded[j * n1 + i], reference[j * n1 + i], scale, &what);
                    if i > j {
                        assert_eq!(folded[j * n1 + i], 0.0, "below the diagonal, {what}");
                    }
                }
            }
        }
    }

    /// Rank deficiency: a zero column and a column equal to the sum of two others. The
    /// pivoted `R` (norms downdated) ends with two zero pivots at working precision, the
    /// others sorted down, and reproduces the Gram matrix of the pivoted columns.
    #[test]
    fn pivoting_puts_the_dependent_columns_last() {
        let (m, n) = (12, 6);
        let mut state = 3;
        let mut a = ColMajor::zeros(m, n);
        for j in [0, 2, 3, 5] {
            for i in 0..m {
                a.data[j * m + i] = lcg(&mut state);
            }
        }
        for i in 0..m {
            a.data[4 * m + i] = a.at(i, 0) + a.at(i, 3); // column 1 stays zero
        }
        let original = a.data.clone();
        let perm = qr_in_place(&mut a, n);
        let r00 = a.at(0, 0).abs();
        for k in 0..n {
            if k < 4 {
                assert!(a.at(k, k).abs() > 1e-3 * r00, "pivot {k}: {}", a.at(k, k));
            } else {
                assert!(a.at(k, k).abs() <= 1e-13 * r00, "pivot {k}: {}", a.at(k, k));
            }
            if k > 0 {
                assert!(a.at(k, k).abs() <= a.at(k - 1, k - 1).abs() * (1.0 + 1e-12));
            }
        }
        assert_eq!(perm[5], 1, "the zero column is the last pivot");
        for i in 0..n {
            for j in 0..n {
                let col = |c: usize| &original[perm[c] * m..(perm[c] + 1) * m];
                let want = dot(col(i), col(j));
                let got: f64 = (0..=i.min(j)).map(|k| a.at(k, i) * a.at(k, j)).sum();
                assert_close(got, want, 10.0, &format!("({i}, {j})"));
            }
        }
    }

    #[test]
    fn all_finite_finds_every_kind_of_non_finite_entry_anywhere() {
        for n in [0, 1, 7, 8, 9, 31, 200] {
            let x: Vec<f64> = (0..n).map(|i| i as f64 - 3.5).collect();
            assert!(all_finite(&x), "n={n}");
            for bad in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
                for at in 0..n {
                    let mut y = x.clone();
                    y[at] = bad;
                    assert!(!all_finite(&y), "n={n}, {bad} at {at}");
                }
            }
        }
        assert!(all_finite(&[
            f64::MAX,
            -f64::MAX,
            f64::MIN_POSITIVE,
            0.0,
            -0.0,
            1e-310,
            1.0,
            2.0
        ]));
    }
}
