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
//! twice per four reflections rather than twice per reflection. The vector kernels are
//! written once, over `pulp`'s vectors, and run with the widest instruction set the CPU has
//! (AVX-512, AVX2 + FMA, NEON, or scalar code; `HAPCAL_SIMD=off` forces scalar code): fused
//! multiply–adds in a fixed order, so that every instruction set gives the same bits.

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

/// Entries per block of the vector kernels. Every dot product keeps `W` partial sums (entry
/// `i` of a column into sum `i mod W`, the sums added in one fixed tree) and every update is a
/// fused multiply–add per entry, whatever the instruction set: a block is one AVX-512
/// register, two AVX2 registers, four NEON registers or eight scalars, and all of them give
/// the same bits.
const W: usize = 8;

/// `W` entries of a column.
type Block = [f64; W];

/// The instruction set of the vector kernels: the widest one this CPU has
/// (`pulp::Arch::new()`), or plain scalar code when the environment variable `HAPCAL_SIMD` is
/// `off` (read once per process). Both give the same bits (see [`W`]).
pub(crate) fn arch() -> pulp::Arch {
    static ARCH: std::sync::OnceLock<pulp::Arch> = std::sync::OnceLock::new();
    *ARCH.get_or_init(|| {
        if std::env::var_os("HAPCAL_SIMD").is_some_and(|v| v == "off") {
            pulp::Arch::Scalar
        } else {
            pulp::Arch::new()
        }
    })
}

/// Reduces `a` to `R` in place: afterwards the upper triangle of its first `min(m, n)` rows
/// holds `R` with `A·Π = Q·R` (zeros below the diagonal), where `Π` permutes the first
/// `n_pivot` columns (the others keep their place and only receive the reflections).
/// `perm[k]` is the original index of column `k` (length `ncols`, identity beyond `n_pivot`).
///
/// Pivot `k` is the remaining pivot candidate of largest norm over rows `k..` (the first in
/// column order among equal norms). A zero column gets no reflection (`R_kk = 0`).
pub(crate) fn qr_in_place(a: &mut ColMajor, n_pivot: usize) -> Vec<usize> {
    qr_in_place_with(arch(), a, n_pivot)
}

/// [`qr_in_place`] with the kernels of `arch`.
fn qr_in_place_with(arch: pulp::Arch, a: &mut ColMajor, n_pivot: usize) -> Vec<usize> {
    struct Op<'a>(&'a mut ColMajor, usize);
    impl pulp::WithSimd for Op<'_> {
        type Output = Vec<usize>;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, simd: S) -> Vec<usize> {
            qr_impl(simd, self.0, self.1)
        }
    }
    arch.dispatch(Op(a, n_pivot))
}

/// `‖x‖` (vectorised, rescaled when the sum of squares under- or overflows).
pub(crate) fn norm2(x: &[f64]) -> f64 {
    struct Op<'a>(&'a [f64]);
    impl pulp::WithSimd for Op<'_> {
        type Output = f64;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, simd: S) -> f64 {
            norm(self.0, |a, b| dot_simd(simd, a, b))
        }
    }
    arch().dispatch(Op(x))
}

/// Whether every entry of `x` is finite: `Σ 0·xᵢ` is 0 unless some `xᵢ` is ±∞ or NaN, summed
/// with 8 partial sums (which the compiler vectorises for the instruction set of [`arch`],
/// where `f64::is_finite` entry by entry does not).
pub(crate) fn all_finite(x: &[f64]) -> bool {
    arch().dispatch(
        #[inline(always)]
        || all_finite_impl(x),
    )
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

/// `acc[i][c] ← v_i·y_c + acc[i][c]` for block `k` of the `v_i` and `y_c`, entry by entry,
/// fused, in vectors of `S`. (Plain loops here and below: `[T; N]::map` and
/// `std::array::from_fn` are not always inlined into the instruction set's function.)
#[inline(always)]
fn dots_step<S: pulp::Simd, const NB: usize, const C: usize>(
    simd: S,
    acc: &mut [[Block; C]; NB],
    v: &[&[Block]; NB],
    y: &[&[Block]; C],
    k: usize,
) {
    for i in 0..NB {
        let vi = S::as_simd_f64s(&v[i][k]).0;
        for c in 0..C {
            let yc = S::as_simd_f64s(&y[c][k]).0;
            let acc_ic = S::as_mut_simd_f64s(&mut acc[i][c]).0;
            for ((a, x), y) in acc_ic.iter_mut().zip(vi).zip(yc) {
                *a = simd.mul_add_f64s(*x, *y, *a);
            }
        }
    }
}

/// The sum of a block's partial sums, in a fixed order.
#[inline(always)]
fn sum_block(b: &Block) -> f64 {
    ((b[0] + b[4]) + (b[1] + b[5])) + ((b[2] + b[6]) + (b[3] + b[7]))
}

/// The first `n_blocks` blocks of each slice of `x`.
///
/// # Panics
/// If a slice is shorter than `n_blocks · W`.
#[inline(always)]
fn blocks_of<'a, const K: usize>(x: &[&'a [f64]; K], n_blocks: usize) -> [&'a [Block]; K] {
    let mut b: [&[Block]; K] = [&[]; K];
    for (b, x) in b.iter_mut().zip(x) {
        *b = &x.as_chunks::<W>().0[..n_blocks];
    }
    b
}

/// The entries of each slice of `x` after its first `n_blocks` blocks, zero-padded to one
/// block (each holds fewer than `W` more).
#[inline(always)]
fn padded_tails<const K: usize>(x: &[&[f64]; K], n_blocks: usize) -> [[Block; 1]; K] {
    let mut b = [[[0.0; W]]; K];
    for (b, x) in b.iter_mut().zip(x) {
        let t = &x[n_blocks * W..];
        b[0][..t.len()].copy_from_slice(t);
    }
    b
}

/// `w[i][c] = v_iᵀy_c` for `NB` vectors and `C` columns, all of one length: one pass over the
/// data, `W` partial sums per pair (see [`W`]), and for few pairs (`NB·C ≤ 2`) a second set
/// for the odd blocks (two chains of fused multiply–adds per pair hide their latency).
///
/// # Panics
/// If the slices differ in length.
#[inline(always)]
fn dots<S: pulp::Simd, const NB: usize, const C: usize>(
    simd: S,
    v: [&[f64]; NB],
    y: [&[f64]; C],
) -> [[f64; C]; NB] {
    let n = common_len(&v, &y);
    let n_blocks = n / W;
    let vb = blocks_of(&v, n_blocks);
    let yb = blocks_of(&y, n_blocks);
    let mut acc = [[[0.0; W]; C]; NB];
    let mut k = 0;
    if NB * C <= 2 {
        let mut acc1 = [[[0.0; W]; C]; NB];
        while k + 2 <= n_blocks {
            dots_step(simd, &mut acc, &vb, &yb, k);
            dots_step(simd, &mut acc1, &vb, &yb, k + 1);
            k += 2;
        }
        for (a, a1) in acc.as_flattened_mut().iter_mut().zip(acc1.as_flattened()) {
            for (e, e1) in a.iter_mut().zip(a1) {
                *e += e1;
            }
        }
    }
    while k < n_blocks {
        dots_step(simd, &mut acc, &vb, &yb, k);
        k += 1;
    }
    if !n.is_multiple_of(W) {
        let (vt, yt) = (padded_tails(&v, n_blocks), padded_tails(&y, n_blocks));
        let mut vr: [&[Block]; NB] = [&[]; NB];
        for (r, t) in vr.iter_mut().zip(&vt) {
            *r = t;
        }
        let mut yr: [&[Block]; C] = [&[]; C];
        for (r, t) in yr.iter_mut().zip(&yt) {
            *r = t;
        }
        dots_step(simd, &mut acc, &vr, &yr, 0);
    }
    let mut w = [[0.0; C]; NB];
    for (w, acc) in w.iter_mut().zip(&acc) {
        for (w, acc) in w.iter_mut().zip(acc) {
            *w = sum_block(acc);
        }
    }
    w
}

/// `Σ xᵢyᵢ` over entries of one length ([`dots`] of one pair).
///
/// # Panics
/// If the lengths differ.
#[inline(always)]
fn dot_simd<S: pulp::Simd>(simd: S, x: &[f64], y: &[f64]) -> f64 {
    let [[d]] = dots::<S, 1, 1>(simd, [x], [y]);
    d
}

/// `y_c ← y_c − Σ_i w_ic·v_i` (`i` in order, each term a fused multiply–add), all of one
/// length: one pass over the data, each block of `v_i` loaded once.
///
/// # Panics
/// If the slices differ in length.
#[inline(always)]
fn update<S: pulp::Simd, const NB: usize, const C: usize>(
    simd: S,
    v: [&[f64]; NB],
    w: [[f64; C]; NB],
    mut y: [&mut [f64]; C],
) {
    let n = v.first().map_or(0, |s| s.len());
    assert!(
        v.iter().all(|s| s.len() == n) && y.iter().all(|s| s.len() == n),
        "slices of different lengths"
    );
    let n_blocks = n / W;
    let mut ws = [[simd.splat_f64s(0.0); C]; NB];
    for (ws, w) in ws.iter_mut().zip(&w) {
        for (ws, w) in ws.iter_mut().zip(w) {
            *ws = simd.splat_f64s(*w);
        }
    }
    let vb = blocks_of(&v, n_blocks);
    for k in 0..n_blocks {
        // Block k of every v_i, loaded once for all columns (vector p of v_i at [i][p]).
        let mut vk = [[simd.splat_f64s(0.0); W]; NB];
        for (vk, vi) in vk.iter_mut().zip(&vb) {
            for (vk, v) in vk.iter_mut().zip(S::as_simd_f64s(&vi[k]).0) {
                *vk = *v;
            }
        }
        for (c, yc) in y.iter_mut().enumerate() {
            let yk = S::as_mut_simd_f64s(&mut yc[k * W..(k + 1) * W]).0;
            for (p, a) in yk.iter_mut().enumerate() {
                let mut t = *a;
                for (vi, wi) in vk.iter().zip(&ws) {
                    t = simd.negate_mul_add_f64s(vi[p], wi[c], t);
                }
                *a = t;
            }
        }
    }
    for (c, yc) in y.iter_mut().enumerate() {
        for r in n_blocks * W..n {
            let mut t = yc[r];
            for (vi, wi) in v.iter().zip(&w) {
                t = (-vi[r]).mul_add(wi[c], t);
            }
            yc[r] = t;
        }
    }
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
fn qr_impl<S: pulp::Simd>(simd: S, a: &mut ColMajor, n_pivot: usize) -> Vec<usize> {
    let dot = |x: &[f64], y: &[f64]| dot_simd(simd, x, y);
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
                    let [d] = dots::<S, 1, 4>(simd, [v], [&*y[0], &*y[1], &*y[2], &*y[3]]);
                    let f = [tau * d[0], tau * d[1], tau * d[2], tau * d[3]];
                    update::<S, 1, 4>(simd, [v], [f], y);
                }
                for _ in 0..(n - k - 1) % 4 {
                    let y = take_cols::<1>(&mut rest, m, k, m - k);
                    let [[d]] = dots::<S, 1, 1>(simd, [v], [&*y[0]]);
                    update::<S, 1, 1>(simd, [v], [[tau * d]], y);
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
    fold_cols_with(arch(), r, cols);
}

/// [`fold_cols`] with the kernels of `arch`.
fn fold_cols_with(arch: pulp::Arch, r: &mut [f64], cols: &mut [&mut [f64]]) {
    struct Op<'a, 'b, 'c>(&'a mut [f64], &'b mut [&'c mut [f64]]);
    impl pulp::WithSimd for Op<'_, '_, '_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, simd: S) {
            fold_impl(simd, self.0, self.1);
        }
    }
    arch.dispatch(Op(r, cols));
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
fn fold_impl<S: pulp::Simd>(simd: S, r: &mut [f64], cols: &mut [&mut [f64]]) {
    let n1 = cols.len();
    if cols.first().is_none_or(|c| c.is_empty()) {
        return;
    }
    let dot = |x: &[f64], y: &[f64]| dot_simd(simd, x, y);
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
                    let [d] = dots::<S, 1, 4>(simd, [bk], [&*y[0], &*y[1], &*y[2], &*y[3]]);
                    let f = [
                        reflect(r, d[0], j),
                        reflect(r, d[1], j + 1),
                        reflect(r, d[2], j + 2),
                        reflect(r, d[3], j + 3),
                    ];
                    update::<S, 1, 4>(simd, [bk], [f], y);
                    j += 4;
                } else if j + 2 <= j_end {
                    let y = take_group::<2>(&mut rest);
                    let [d] = dots::<S, 1, 2>(simd, [bk], [&*y[0], &*y[1]]);
                    let f = [reflect(r, d[0], j), reflect(r, d[1], j + 1)];
                    update::<S, 1, 2>(simd, [bk], [f], y);
                    j += 2;
                } else {
                    let y = take_group::<1>(&mut rest);
                    let [[d]] = dots::<S, 1, 1>(simd, [bk], [&*y[0]]);
                    let f = reflect(r, d, j);
                    update::<S, 1, 1>(simd, [bk], [[f]], y);
                    j += 1;
                }
            }
            r[k * n1 + k] = alpha;
            tau[k - k0] = tau_k;
            v0[k - k0] = vk0;
        }
        if blocked {
            apply_block(simd, r, cols, k0, &tau, &v0);
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
fn apply_block<S: pulp::Simd>(
    simd: S,
    r: &mut [f64],
    cols: &mut [&mut [f64]],
    k0: usize,
    tau: &[f64; NB],
    v0: &[f64; NB],
) {
    let n1 = cols.len();
    let (head, tail) = cols.split_at_mut(k0 + NB);
    let v: [&[f64]; NB] = std::array::from_fn(|i| &*head[k0 + i]);
    let mut t = [[0.0; NB]; NB]; // t[l][i] = T_li
    for i in 0..NB {
        t[i][i] = tau[i];
        let mut g = [0.0; NB];
        for l in 0..i {
            g[l] = dot_simd(simd, v[l], v[i]);
        }
        for (l, tl) in t.iter_mut().enumerate().take(i) {
            let s: f64 = (l..i).map(|m| tl[m] * g[m]).sum();
            tl[i] = -tau[i] * s;
        }
    }
    // Columns k0 + NB.., two at a time where a block is one register (the NB·2 accumulators of
    // `dots` then fit in the registers; the columns do not interact, so the grouping does not
    // change the result), then the last one alone.
    let pairs = S::F64_LANES >= W;
    let mut rest = tail;
    let mut j = k0 + NB;
    while pairs && j + 2 <= n1 {
        let y = take_group::<2>(&mut rest);
        apply_block_to::<S, 2>(simd, r, n1, k0, j, &v, &t, v0, y);
        j += 2;
    }
    while j < n1 {
        let y = take_group::<1>(&mut rest);
        apply_block_to::<S, 1>(simd, r, n1, k0, j, &v, &t, v0, y);
        j += 1;
    }
}

/// `x_c ← x_c − V Tᵀ Vᵀ x_c` for the `C` columns `x_c = [R[k0.., j + c]; y_c]` (see
/// [`apply_block`]).
#[allow(clippy::too_many_arguments)] // the block and the columns it acts on
#[inline(always)]
fn apply_block_to<S: pulp::Simd, const C: usize>(
    simd: S,
    r: &mut [f64],
    n1: usize,
    k0: usize,
    j: usize,
    v: &[&[f64]; NB],
    t: &[[f64; NB]; NB],
    v0: &[f64; NB],
    y: [&mut [f64]; C],
) {
    let mut w = {
        let yr: [&[f64]; C] = std::array::from_fn(|c| &*y[c]);
        dots::<S, NB, C>(simd, *v, yr)
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
    update::<S, NB, C>(simd, *v, tw, y);
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

    /// `|a − b| ≤ 1e-12·scale`: the kernels sum in another order than the naive references
    /// below, so they agree with them to rounding (≈ 1e-15 relative for these sizes).
    #[track_caller]
    fn assert_close(a: f64, b: f64, scale: f64, what: &str) {
        assert!(
            (a - b).abs() <= 1e-12 * scale.max(1.0),
            "{what}: {a} vs {b}"
        );
    }

    /// The widest instruction set of this CPU (whatever `HAPCAL_SIMD` says) and plain scalar
    /// code.
    fn both_archs() -> [(&'static str, pulp::Arch); 2] {
        [
            ("vector", pulp::Arch::new()),
            ("scalar", pulp::Arch::Scalar),
        ]
    }

    /// [`dots`] and [`update`] of 4 vectors and 2 columns with the kernels of `arch`.
    fn dots_and_update_in(
        arch: pulp::Arch,
        v: [&[f64]; 4],
        w: [[f64; 2]; 4],
        y: [&mut [f64]; 2],
    ) -> ([[f64; 2]; 4], [f64; 4]) {
        struct Op<'a, 'b>([&'a [f64]; 4], [[f64; 2]; 4], [&'b mut [f64]; 2]);
        impl pulp::WithSimd for Op<'_, '_> {
            type Output = ([[f64; 2]; 4], [f64; 4]);
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, simd: S) -> Self::Output {
                let Op(v, w, y) = self;
                let d = dots::<S, 4, 2>(simd, v, [&*y[0], &*y[1]]);
                let single = v.map(|vi| dot_simd(simd, vi, y[0]));
                update::<S, 4, 2>(simd, v, w, y);
                (d, single)
            }
        }
        arch.dispatch(Op(v, w, y))
    }

    /// The kernels with the vector instructions of this CPU and with scalar code give the same
    /// bits, for every length up to 40 (every tail of the 8-entry blocks and both chains of
    /// the dot products) and 200, and agree with naive loops to rounding.
    #[test]
    fn vector_and_scalar_kernels_give_the_same_bits() {
        let mut state = 7;
        for n in (0..=40).chain([200]) {
            let v: Vec<Vec<f64>> = (0..4)
                .map(|_| (0..n).map(|_| lcg(&mut state)).collect())
                .collect();
            let y: Vec<Vec<f64>> = (0..2)
                .map(|_| (0..n).map(|_| lcg(&mut state)).collect())
                .collect();
            let vr = [&v[0][..], &v[1][..], &v[2][..], &v[3][..]];
            let w = [[0.5, -1.5], [2.0, 0.25], [-0.75, 1.0], [1.25, -2.0]];
            let results = both_archs().map(|(name, arch)| {
                let (mut y0, mut y1) = (y[0].clone(), y[1].clone());
                let (d, single) = dots_and_update_in(arch, vr, w, [&mut y0[..], &mut y1[..]]);
                (name, d, single, y0, y1)
            });
            let [vector, scalar] = &results;
            assert_eq!(
                (vector.1, vector.2, &vector.3, &vector.4),
                (scalar.1, scalar.2, &scalar.3, &scalar.4),
                "n={n}"
            );
            for (name, d, single, y0, y1) in &results {
                for i in 0..4 {
                    for c in 0..2 {
                        let naive: f64 = vr[i].iter().zip(&y[c]).map(|(a, b)| a * b).sum();
                        assert_close(d[i][c], naive, n as f64, &format!("{name} dots n={n}"));
                    }
                    assert_close(single[i], d[i][0], n as f64, &format!("{name} dot n={n}"));
                }
                for r in 0..n {
                    for (c, got) in [(0, y0), (1, y1)] {
                        let naive = y[c][r] - (0..4).map(|i| w[i][c] * v[i][r]).sum::<f64>();
                        assert_close(got[r], naive, 10.0, &format!("{name} update n={n}"));
                    }
                }
            }
        }
    }

    /// The blocked fold (compact WY) at the shapes that exercise it: fewer and more rows than
    /// columns, column counts below, at and across the block size, the LM's 200 × 29 in a
    /// 256-row buffer. Its `R'ᵀR'` must equal `RᵀR + BᵀB` (as above), and the vector and
    /// scalar kernels must give the same bits.
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
            let [folded, reference] = both_archs().map(|(_, arch)| {
                let mut folded = r.clone();
                let mut scratch = b.clone();
                let mut cols: Vec<&mut [f64]> =
                    scratch.chunks_mut(ldb).map(|c| &mut c[..len]).collect();
                fold_cols_with(arch, &mut folded, &mut cols);
                folded
            });
            assert_eq!(folded, reference, "{n1}×{len}: vector vs scalar");
            let scale = len as f64 + n1 as f64 * 9.0;
            for i in 0..n1 {
                for j in 0..n1 {
                    let want = gram(i, j, &r)
                        + dot(&b[i * ldb..i * ldb + len], &b[j * ldb..j * ldb + len]);
                    let what = format!("{n1}×{len}: ({i}, {j})");
                    assert_close(gram(i, j, &folded), want, scale, &what);
                    if i > j {
                        assert_eq!(folded[j * n1 + i], 0.0, "below the diagonal, {what}");
                    }
                }
            }
        }
    }

    /// An LM step's factorisation on a Jacobian of the LM's shape (200 rows, 28 parameter
    /// columns and the residual; columns scaled over six decades, as lengths and angles of a
    /// calibration are): fold the rows into a triangle, then the pivoted QR of the triangle.
    /// Vector and scalar kernels give the same bits, so an LM solve takes the same steps and
    /// stops for the same reason on either.
    #[test]
    fn lm_shaped_factorisation_is_the_same_on_vector_and_scalar_kernels() {
        let (m, n1) = (200, 29);
        let mut state = 5;
        let jac: Vec<f64> = (0..m * n1)
            .map(|t| lcg(&mut state) * 10f64.powi((t / m % 7) as i32 - 3))
            .collect();
        let results = both_archs().map(|(_, arch)| {
            let mut tri = vec![0.0; n1 * n1];
            let mut scratch = jac.clone();
            for rows in [0..128, 128..m] {
                let mut cols: Vec<&mut [f64]> = scratch
                    .chunks_mut(m)
                    .map(|c| &mut c[rows.clone()])
                    .collect();
                fold_cols_with(arch, &mut tri, &mut cols);
            }
            let mut a = ColMajor {
                data: tri.clone(),
                nrows: n1,
                ncols: n1,
            };
            let perm = qr_in_place_with(arch, &mut a, n1 - 1);
            (tri, a.data, perm)
        });
        assert_eq!(results[0], results[1]);
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
