//! Tail probabilities of the χ² and F distributions, Holm–Bonferroni, the mean, and the
//! small dense column selection the tests use (column-pivoted Gram–Schmidt); the solves are
//! in [`crate::solve`].
//!
//! Special functions: Press et al., *Numerical Recipes*, 3rd ed., 2007, §6.1 (Lanczos
//! log-gamma), §6.2 (incomplete gamma, series and continued fraction), §6.4 (incomplete
//! beta, continued fraction).

use nalgebra::{DMatrix, DVector};

fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 6] = [
        76.180_091_729_471_46,
        -86.505_320_329_416_77,
        24.014_098_240_830_91,
        -1.231_739_572_450_155,
        0.120_865_097_386_617_9e-2,
        -0.539_523_938_495_3e-5,
    ];
    let mut y = x;
    let tmp = x + 5.5;
    let tmp = tmp - (x + 0.5) * tmp.ln();
    let mut ser = 1.000_000_000_190_015;
    for g in G {
        y += 1.0;
        ser += g / y;
    }
    -tmp + (2.506_628_274_631_000_5 * ser / x).ln()
}

/// Regularised upper incomplete gamma `Q(a, x)`.
fn gamma_q(a: f64, x: f64) -> f64 {
    if x.is_nan() || a.is_nan() || x <= 0.0 || a <= 0.0 {
        return 1.0;
    }
    let gln = ln_gamma(a);
    if x < a + 1.0 {
        let (mut ap, mut sum) = (a, 1.0 / a);
        let mut del = sum;
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * (-x + a * x.ln() - gln).exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            let del = lentz_step(an, b, &mut c, &mut d, tiny);
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (-x + a * x.ln() - gln).exp() * h
    }
}

/// One term of a continued fraction `… + a/(b + …)` by the modified Lentz method (Numerical
/// Recipes): updates the ratios `c` and `d` with the term's numerator `a` and denominator
/// `b`, raising magnitudes below `tiny` to it, and returns the factor `c·d` the value changes by.
fn lentz_step(a: f64, b: f64, c: &mut f64, d: &mut f64, tiny: f64) -> f64 {
    *d = a * *d + b;
    if d.abs() < tiny {
        *d = tiny;
    }
    *c = b + a / *c;
    if c.abs() < tiny {
        *c = tiny;
    }
    *d = 1.0 / *d;
    *d * *c
}

fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < tiny {
        d = tiny;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..10_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        h *= lentz_step(aa, 1.0, &mut c, &mut d, tiny);
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        let del = lentz_step(aa, 1.0, &mut c, &mut d, tiny);
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Regularised incomplete beta `I_x(a, b)`.
fn beta_i(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let bt = (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        bt * beta_cf(a, b, x) / a
    } else {
        1.0 - bt * beta_cf(b, a, 1.0 - x) / b
    }
}

/// `P(χ²_k > x)`, the upper tail of a χ² variable with `k` degrees of freedom.
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    gamma_q(0.5 * k, 0.5 * x).clamp(0.0, 1.0)
}

/// `P(F(d1, d2) > f)`, the upper tail of an F variable.
pub fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if f.is_nan() || f <= 0.0 || d1 <= 0.0 || d2 <= 0.0 {
        return 1.0;
    }
    beta_i(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f)).clamp(0.0, 1.0)
}

/// Holm–Bonferroni adjusted p-values (Holm 1979), same order as `p`.
pub fn holm(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]));
    let mut adjusted = vec![1.0; m];
    let mut running: f64 = 0.0;
    for (rank, &i) in order.iter().enumerate() {
        running = running.max(((m - rank) as f64 * p[i]).min(1.0));
        adjusted[i] = running;
    }
    adjusted
}

/// Norm, relative to the largest column of the matrix, below which a column is rounding noise
/// of a structural zero and is never picked. The distance `|P|` does not change under a
/// rotation about an axis through the base origin (D-H `dalpha0`, `dtheta0`), a vertical joint
/// carries no gravity torque: such columns come out at 10⁻¹¹ where the smallest real column of
/// the reference device is 16 and the largest 3·10⁶ (weighted, SI units). Relative to its own
/// norm a noise column is as independent as any other, and a solve gives it a step of 10¹¹
/// rad, which an effect that does depend on it (the cable angle on the base twist) then
/// follows.
pub(crate) const NUMERICAL_ZERO_COLUMN: f64 = 1e-9;

/// Mean of `values` (0 for none).
pub(crate) fn mean<T: std::borrow::Borrow<f64>>(values: impl IntoIterator<Item = T>) -> f64 {
    let (sum, n) = (values.into_iter()).fold((0.0, 0usize), |(s, n), v| (s + v.borrow(), n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// Column-pivoted modified Gram–Schmidt on the columns `cols` of `a`, after projecting out the
/// orthonormal columns of `against` (N × p, may have 0 columns).
///
/// Returns the orthonormal basis (N × r) and, per input column, its remaining norm as a
/// fraction of its own norm when it was picked, or `None` when it was never picked (its
/// remaining fraction fell below `rel_tol`, or its norm is below [`NUMERICAL_ZERO_COLUMN`] of
/// the largest column's). Columns are picked largest remaining fraction first, so exact or
/// near dependencies drop the later-picked column.
pub(crate) fn pivoted_basis(
    a: &DMatrix<f64>,
    against: &DMatrix<f64>,
    rel_tol: f64,
) -> (DMatrix<f64>, Vec<Option<f64>>) {
    pivoted_basis_beside(a, against, rel_tol, 0.0)
}

/// The largest finite column norm of `a` (0 for no column).
pub(crate) fn largest_column_norm(a: &DMatrix<f64>) -> f64 {
    (0..a.ncols())
        .map(|j| a.column(j).norm())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
}

/// [`pivoted_basis`] of a candidate's columns `a` beside a baseline whose largest column norm
/// is `reference` (same units: weighted residual per parameter unit): a column is rounding
/// noise below [`NUMERICAL_ZERO_COLUMN`] of the larger of `reference` and `a`'s own largest,
/// so an effect made only of noise columns (a gravity torque about a vertical axis) is not
/// visible because its largest noise column is the largest of its own.
pub(crate) fn pivoted_basis_beside(
    a: &DMatrix<f64>,
    against: &DMatrix<f64>,
    rel_tol: f64,
    reference: f64,
) -> (DMatrix<f64>, Vec<Option<f64>>) {
    let n = a.nrows();
    let k = a.ncols();
    let mut norms: Vec<f64> = (0..k).map(|j| a.column(j).norm()).collect();
    let largest = largest_column_norm(a).max(reference);
    for v in &mut norms {
        if *v <= NUMERICAL_ZERO_COLUMN * largest {
            *v = 0.0;
        }
    }
    let mut work = a.clone();
    if against.ncols() > 0 {
        let proj = against.transpose() * &work;
        work -= against * proj;
    }
    let mut picked: Vec<Option<f64>> = vec![None; k];
    let mut basis: Vec<DVector<f64>> = Vec::new();
    // Remaining squared norms, downdated after each projection (`|w|² − (v·w)²`) and
    // recomputed when the downdate has cancelled most of the last exact value (LAPACK's
    // xGEQP3 rule), so that the pivot search costs O(k) per pick instead of O(n·k).
    let mut rem2: Vec<f64> = (0..k).map(|j| work.column(j).norm_squared()).collect();
    let mut exact2 = rem2.clone();
    loop {
        let mut best: Option<(usize, f64)> = None;
        for j in 0..k {
            if picked[j].is_some() || norms[j].is_nan() || norms[j] <= 0.0 {
                continue;
            }
            let frac = rem2[j].max(0.0).sqrt() / norms[j];
            if frac >= rel_tol && best.is_none_or(|(_, f)| frac > f) {
                best = Some((j, frac));
            }
        }
        let Some((j, _)) = best else { break };
        let nrm = work.column(j).norm();
        let frac = nrm / norms[j];
        if frac < rel_tol || nrm == 0.0 {
            // The downdated norm overstated it: exact now, and below the tolerance.
            rem2[j] = nrm * nrm;
            exact2[j] = rem2[j];
            if rem2[j] == 0.0 || frac < rel_tol {
                picked[j] = None;
                norms_skip(&mut rem2, j);
                continue;
            }
        }
        picked[j] = Some(frac);
        let v: DVector<f64> = work.column(j) / nrm;
        for c in 0..k {
            if picked[c].is_none() && rem2[c] >= 0.0 {
                let dot = v.dot(&work.column(c));
                let mut col = work.column_mut(c);
                col.axpy(-dot, &v, 1.0);
                rem2[c] -= dot * dot;
                if rem2[c] <= 1e-2 * exact2[c] {
                    rem2[c] = work.column(c).norm_squared();
                    exact2[c] = rem2[c];
                }
            }
        }
        basis.push(v);
    }
    let mut q = DMatrix::zeros(n, basis.len());
    for (j, v) in basis.iter().enumerate() {
        q.set_column(j, v);
    }
    (q, picked)
}

/// Marks column `j` as never to be picked (its remaining norm is below the tolerance).
fn norms_skip(rem2: &mut [f64], j: usize) {
    rem2[j] = -1.0;
}

/// `|cos|` of the angle between `a` and `b` (0 when either is zero): how alike two
/// candidates' fits of a residual are.
pub(crate) fn cosine(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    let d = a.norm() * b.norm();
    if d > 0.0 { (a.dot(b) / d).abs() } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tails_match_tabulated_values() {
        // χ²: 95th percentile of 1 and 10 d.o.f. (3.841, 18.307); F(3, 20) 95th: 3.098.
        assert!((chi2_sf(3.841_459, 1.0) - 0.05).abs() < 1e-5);
        assert!((chi2_sf(18.307_04, 10.0) - 0.05).abs() < 1e-5);
        assert!((f_sf(3.098_391, 3.0, 20.0) - 0.05).abs() < 1e-5);
        assert!((chi2_sf(1000.0, 1000.0) - 0.494).abs() < 0.01);
    }

    #[test]
    fn holm_adjusts_in_step_down_order() {
        let adj = holm(&[0.01, 0.04, 0.03]);
        assert!((adj[0] - 0.03).abs() < 1e-12);
        assert!((adj[2] - 0.06).abs() < 1e-12);
        assert!((adj[1] - 0.06).abs() < 1e-12);
    }

    #[test]
    fn pivoted_basis_drops_a_dependent_column() {
        let a = DMatrix::from_row_slice(3, 3, &[1.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
        let (q, picked) = pivoted_basis(&a, &DMatrix::zeros(3, 0), 1e-8);
        assert_eq!(q.ncols(), 2);
        assert_eq!(picked.iter().filter(|p| p.is_none()).count(), 1);
    }

    #[test]
    fn pivoted_basis_never_picks_rounding_noise() {
        // Two real columns and the rounding noise of a structural zero (10⁻¹⁷ of the largest,
        // as a rotation about the base origin leaves on the distance): relative to its own
        // norm the noise column is orthogonal to the others, and must still not be picked.
        let a = DMatrix::from_row_slice(
            4,
            3,
            &[
                1e5, 3.0, 2e-12, //
                -2e5, 1.0, -1e-12, //
                1e5, -4.0, 3e-12, //
                5e4, 2.0, 1e-12,
            ],
        );
        let (q, picked) = pivoted_basis(&a, &DMatrix::zeros(4, 0), 1e-8);
        assert_eq!(q.ncols(), 2);
        assert!(picked[0].is_some() && picked[1].is_some());
        assert!(
            picked[2].is_none(),
            "the noise column was picked: {picked:?}"
        );
        // The same column scaled up to a real size (10⁻³ of the largest) is picked.
        let mut b = a.clone();
        b.column_mut(2).scale_mut(1e14);
        let (_, picked) = pivoted_basis(&b, &DMatrix::zeros(4, 0), 1e-8);
        assert!(picked[2].is_some());
    }

    #[test]
    fn a_candidate_of_noise_alone_is_not_visible_beside_its_baseline() {
        // One column of rounding noise: alone it is its own largest column, beside a baseline
        // of columns 10¹⁶ times larger it is noise.
        let noise = DMatrix::from_column_slice(4, 1, &[2e-12, -1e-12, 3e-12, 1e-12]);
        let (_, alone) = pivoted_basis(&noise, &DMatrix::zeros(4, 0), 1e-8);
        assert!(alone[0].is_some());
        let (_, beside) = pivoted_basis_beside(&noise, &DMatrix::zeros(4, 0), 1e-8, 1e5);
        assert!(beside[0].is_none());
    }
}
