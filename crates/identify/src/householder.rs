//! Householder QR of a tall, narrow column-major matrix, in place, optionally with column
//! pivoting over a leading set of columns: the factorisation of each LM step.
//!
//! Source: G. H. Golub, C. F. Van Loan, *Matrix Computations*, 4th ed., 2013, Alg. 5.2.1
//! (Householder QR) and §5.4.2 (column pivoting, as MINPACK `qrfac`: the pivot is the
//! remaining column of largest norm). Unblocked: for the narrow matrices of a calibration
//! (tens of columns) each reflection is one dot product and one update per column, vectorised
//! here (8 accumulators; AVX-512 or AVX2 chosen at run time), with none of the set-up of a
//! blocked factorisation, which only pays beyond a few thousand rows.

/// A column-major `nrows × ncols` matrix (leading dimension `nrows`).
pub(crate) struct ColMajor {
    pub(crate) data: Vec<f64>,
    pub(crate) nrows: usize,
    pub(crate) ncols: usize,
}

impl ColMajor {
    pub(crate) fn zeros(nrows: usize, ncols: usize) -> Self {
        Self {
            data: vec![0.0; nrows * ncols],
            nrows,
            ncols,
        }
    }

    pub(crate) fn col(&self, j: usize) -> &[f64] {
        &self.data[j * self.nrows..(j + 1) * self.nrows]
    }

    pub(crate) fn col_mut(&mut self, j: usize) -> &mut [f64] {
        &mut self.data[j * self.nrows..(j + 1) * self.nrows]
    }

    pub(crate) fn at(&self, i: usize, j: usize) -> f64 {
        self.data[j * self.nrows + i]
    }
}

/// Reduces `a` to `R` in place: afterwards the upper triangle of its first `min(m, n)` rows
/// holds `R` with `A·Π = Q·R` (zeros below the diagonal), where `Π` permutes the first
/// `n_pivot` columns (the others keep their place and only receive the reflections).
/// `perm[k]` is the original index of column `k` (length `ncols`, identity beyond `n_pivot`).
///
/// Pivot `k` is the remaining pivot candidate of largest norm over rows `k..` (the first in
/// column order among equal norms). A zero column gets no reflection (`R_kk = 0`).
pub(crate) fn qr_in_place(a: &mut ColMajor, n_pivot: usize) -> Vec<usize> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F (checked just above).
            return unsafe { qr_avx512(a, n_pivot) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { qr_avx2(a, n_pivot) };
        }
    }
    qr_impl(a, n_pivot, dot)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
fn qr_avx512(a: &mut ColMajor, n_pivot: usize) -> Vec<usize> {
    qr_impl(a, n_pivot, |x, y| dot_avx512(x, y))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn qr_avx2(a: &mut ColMajor, n_pivot: usize) -> Vec<usize> {
    qr_impl(a, n_pivot, |x, y| dot_avx2(x, y))
}

/// As [`dot_avx2`] with one 8-wide AVX-512 accumulator per 8 entries (two per 16).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
fn dot_avx512(x: &[f64], y: &[f64]) -> f64 {
    use std::arch::x86_64::{
        _mm512_add_pd, _mm512_loadu_pd, _mm512_mul_pd, _mm512_reduce_add_pd, _mm512_setzero_pd,
    };
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &y[..n]);
    let (xc, xt) = x.as_chunks::<16>();
    let (yc, yt) = y.as_chunks::<16>();
    let mut a0 = _mm512_setzero_pd();
    let mut a1 = _mm512_setzero_pd();
    for (a, b) in xc.iter().zip(yc) {
        // SAFETY: each chunk holds 16 f64, read as two unaligned 8-lane loads.
        unsafe {
            a0 = _mm512_add_pd(
                a0,
                _mm512_mul_pd(_mm512_loadu_pd(a.as_ptr()), _mm512_loadu_pd(b.as_ptr())),
            );
            a1 = _mm512_add_pd(
                a1,
                _mm512_mul_pd(
                    _mm512_loadu_pd(a.as_ptr().add(8)),
                    _mm512_loadu_pd(b.as_ptr().add(8)),
                ),
            );
        }
    }
    // The tail (< 16 entries) by the AVX2 dot product.
    _mm512_reduce_add_pd(_mm512_add_pd(a0, a1)) + dot_avx2(xt, yt)
}

/// `Σ xᵢyᵢ` over `min(len)` entries with two 4-wide AVX accumulators (LLVM does not vectorise
/// a loop-carried partial-sum array by itself).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn dot_avx2(x: &[f64], y: &[f64]) -> f64 {
    use std::arch::x86_64::{
        _mm256_add_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_setzero_pd, _mm256_storeu_pd,
    };
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &y[..n]);
    let (xc, xt) = x.as_chunks::<8>();
    let (yc, yt) = y.as_chunks::<8>();
    let mut a0 = _mm256_setzero_pd();
    let mut a1 = _mm256_setzero_pd();
    for (a, b) in xc.iter().zip(yc) {
        // SAFETY: each chunk holds 8 f64, read as two unaligned 4-lane loads.
        unsafe {
            a0 = _mm256_add_pd(
                a0,
                _mm256_mul_pd(_mm256_loadu_pd(a.as_ptr()), _mm256_loadu_pd(b.as_ptr())),
            );
            a1 = _mm256_add_pd(
                a1,
                _mm256_mul_pd(
                    _mm256_loadu_pd(a.as_ptr().add(4)),
                    _mm256_loadu_pd(b.as_ptr().add(4)),
                ),
            );
        }
    }
    let mut lanes = [0.0; 4];
    // SAFETY: `lanes` holds 4 f64.
    unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), _mm256_add_pd(a0, a1)) };
    let mut tail = 0.0;
    for (a, b) in xt.iter().zip(yt) {
        tail += a * b;
    }
    ((lanes[0] + lanes[2]) + (lanes[1] + lanes[3])) + tail
}

/// `Σ xᵢyᵢ` with 8 partial sums (vectorisable without reassociating a single sum).
#[inline(always)]
fn dot(x: &[f64], y: &[f64]) -> f64 {
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
fn qr_impl(
    a: &mut ColMajor,
    n_pivot: usize,
    dot: impl Fn(&[f64], &[f64]) -> f64 + Copy,
) -> Vec<usize> {
    let (m, n) = (a.nrows, a.ncols);
    let n_pivot = n_pivot.min(n);
    let mut perm: Vec<usize> = (0..n).collect();
    for k in 0..m.min(n) {
        if k < n_pivot {
            let mut best = k;
            let mut best_norm = -1.0;
            for j in k..n_pivot {
                let c = norm(&a.col(j)[k..], dot);
                if c > best_norm {
                    best = j;
                    best_norm = c;
                }
            }
            if best != k {
                let (lo, hi) = a.data.split_at_mut(best * m);
                lo[k * m..(k + 1) * m].swap_with_slice(&mut hi[..m]);
                perm.swap(k, best);
            }
        }
        let (head, tail) = a.data.split_at_mut((k + 1) * m);
        let v = &mut head[k * m + k..(k + 1) * m];
        let x_norm = norm(v, dot);
        if x_norm == 0.0 {
            continue;
        }
        let x0 = v[0];
        let alpha = if x0 > 0.0 { -x_norm } else { x_norm };
        v[0] = x0 - alpha;
        // vᵀv = 2‖x‖(‖x‖ + |x₀|) for v = x − αe₁.
        let vtv = 2.0 * x_norm * (x_norm + x0.abs());
        for col in tail.chunks_exact_mut(m) {
            let y = &mut col[k..];
            let f = 2.0 * dot(v, y) / vtv;
            axpy(f, v, y);
        }
        v[0] = alpha;
        v[1..].iter_mut().for_each(|e| *e = 0.0);
    }
    perm
}

/// Folds the rows `b` (`len × n1`, column-major with leading dimension `ldb ≥ len`) into the
/// upper-triangular `r` (`n1 × n1`, column-major): afterwards `r` is the R factor of `[r; b]`
/// (`RᵀR` grows by `bᵀb`), and `b` is scratch.
///
/// The Householder QR of `[R; B]` with its structure used (Golub–Van Loan §5.2.2 for the
/// update, the TSQR step of Demmel et al. 2012): reflection `k` touches row `k` of `R` and the
/// rows of `B` only, since `R` is zero below its diagonal. `≈ 2·len·n1²` flops on a working
/// set of one block, which stays in cache.
///
/// # Panics
/// If the slices are shorter than the shapes say.
pub(crate) fn fold_rows(r: &mut [f64], n1: usize, b: &mut [f64], len: usize, ldb: usize) {
    assert!(r.len() >= n1 * n1 && ldb >= len && (n1 == 0 || b.len() >= (n1 - 1) * ldb + len));
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F (checked just above).
            return unsafe { fold_avx512(r, n1, b, len, ldb) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { fold_avx2(r, n1, b, len, ldb) };
        }
    }
    fold_impl(r, n1, b, len, ldb, dot);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
fn fold_avx512(r: &mut [f64], n1: usize, b: &mut [f64], len: usize, ldb: usize) {
    fold_impl(r, n1, b, len, ldb, |x, y| dot_avx512(x, y));
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn fold_avx2(r: &mut [f64], n1: usize, b: &mut [f64], len: usize, ldb: usize) {
    fold_impl(r, n1, b, len, ldb, |x, y| dot_avx2(x, y));
}

#[inline(always)]
fn fold_impl(
    r: &mut [f64],
    n1: usize,
    b: &mut [f64],
    len: usize,
    ldb: usize,
    dot: impl Fn(&[f64], &[f64]) -> f64 + Copy,
) {
    if len == 0 {
        return;
    }
    for k in 0..n1 {
        // x = [R_kk; B[:, k]].
        let (b_head, b_tail) = b.split_at_mut((k + 1) * ldb);
        let bk = &b_head[k * ldb..k * ldb + len];
        let bk_norm = norm(bk, dot);
        if bk_norm == 0.0 {
            continue;
        }
        let rkk = r[k * n1 + k];
        let x_norm = rkk.hypot(bk_norm);
        let alpha = if rkk > 0.0 { -x_norm } else { x_norm };
        let v0 = rkk - alpha;
        let vtv = 2.0 * x_norm * (x_norm + rkk.abs());
        for (j, bj) in b_tail.chunks_mut(ldb).enumerate() {
            let j = k + 1 + j;
            if j >= n1 {
                break;
            }
            let bj = &mut bj[..len];
            let rkj = r[j * n1 + k];
            let f = 2.0 * (v0 * rkj + dot(bk, bj)) / vtv;
            r[j * n1 + k] = rkj - f * v0;
            for (y, v) in bj.iter_mut().zip(bk) {
                *y -= f * v;
            }
        }
        r[k * n1 + k] = alpha;
    }
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
}
