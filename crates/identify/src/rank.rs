//! Which parameters the data determine: rank decision by column-pivoted QR with a
//! noise-derived tolerance, and the reason for every pruned parameter.
//!
//! Sources: G. H. Golub, C. F. Van Loan, *Matrix Computations*, 4th ed., 2013, §5.4.2
//! (QR with column pivoting, rank revealing) and §5.5.7 (numerical rank); the statistical
//! criterion (keep a parameter when its standard deviation is below its plausible deviation) is
//! the usual one in robot calibration, e.g. W. Khalil, E. Dombre, *Modeling, Identification
//! and Control of Robots*, 2002, §11.4 (identifiable parameters by QR of the observation matrix).

use std::fmt;

use faer::{Mat, MatRef};

use crate::problem::{ParamLayout, Role, Unit};

/// Priors and numerical floor of the rank decision, without the noise level.
///
/// Used by [`identify`](crate::identify), which supplies `sigma` itself; see [`RankConfig`]
/// for the meaning of each field.
#[derive(Clone, Debug, PartialEq)]
pub struct RankConfigBase {
    /// Plausible deviation of a length parameter, in m.
    pub prior_m: f64,
    /// Plausible deviation of an angle parameter, in rad.
    pub prior_rad: f64,
    /// Plausible deviation of a dimensionless parameter.
    pub prior_dimensionless: f64,
    /// Plausible value of a compliance under a torque, in rad/(N·m).
    pub prior_rad_per_n_m: f64,
    /// Plausible value of a compliance under a lever arm of unknown weight, in rad/m.
    pub prior_rad_per_m: f64,
    /// Numerical floor on `|R_kk|` of the unit-norm scaled columns.
    pub rel_tol: f64,
    /// Which of two tied candidates becomes the pivot (see [`TieBreak`]).
    pub tie_break: TieBreak,
}

/// Which candidate wins a near-tie of the pivot choice (exactly collinear parameters).
///
/// Either choice gives the same predictions; it only decides which name carries the shared
/// direction. A kinematic chain's layout runs from the base outwards, and the usual convention
/// (Baser & Konukseven fix `d0 = 0` of the rig row and keep `θ1`) gives a gauge freedom to the
/// base side: [`TieBreak::LaterInLayout`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TieBreak {
    /// The candidate earlier in the layout is kept (the default).
    #[default]
    EarlierInLayout,
    /// The candidate later in the layout is kept.
    LaterInLayout,
}

impl Default for RankConfigBase {
    /// `prior_m = 0.01` (1 cm: machining and assembly deviations of desktop haptic devices and
    /// small arms are millimetres), `prior_rad = 0.01` (≈ 0.6°, encoder zero offsets and
    /// axis misalignments), `prior_dimensionless = 1.0` (ratios, gains: order one),
    /// `prior_rad_per_n_m = 2e-3` (a compliance is a value, not a deviation from a nominal
    /// zero: a joint through a harmonic drive is of order 1e-4 rad/(N·m), a torsional
    /// stiffness of order 1e4 N·m/rad, and one through a cable or belt of order 1e-3; twice
    /// that, since the torques come from CAD masses that miss cables, markers and tools and a
    /// compliance per CAD torque grows by the missing share; docs/engine.md gives what 1e-3
    /// does to the bundled recordings), `prior_rad_per_m = 1e-2` (the lumped unit weights
    /// absorb an unknown weight, so no physical scale tightens it: the angle prior such
    /// parameters had before they had a unit of their own, 2e-3 rad/(N·m) under 5 N a point),
    /// `rel_tol = 1e-10` (columns closer than this to the span of the others are dependent at
    /// working precision: √ε ≈ 1.5e-8 would drop genuinely weak ones, ε·m noise is ≈ 1e-13).
    fn default() -> Self {
        Self {
            prior_m: 0.01,
            prior_rad: 0.01,
            prior_dimensionless: 1.0,
            prior_rad_per_n_m: 2e-3,
            prior_rad_per_m: 1e-2,
            rel_tol: 1e-10,
            tie_break: TieBreak::EarlierInLayout,
        }
    }
}

impl RankConfigBase {
    /// The full configuration for residual noise `sigma` (in residual units).
    pub fn with_sigma(&self, sigma: f64) -> RankConfig {
        RankConfig {
            sigma,
            prior_m: self.prior_m,
            prior_rad: self.prior_rad,
            prior_dimensionless: self.prior_dimensionless,
            prior_rad_per_n_m: self.prior_rad_per_n_m,
            prior_rad_per_m: self.prior_rad_per_m,
            rel_tol: self.rel_tol,
            tie_break: self.tie_break,
        }
    }
}

/// Configuration of [`identifiability`].
///
/// A parameter is kept when its standard deviation `sigma / (c_j·|R_kk|)` (given the parameters
/// kept before it) is at most its prior scale ([`RankConfig::prior_scale`]): the data then tell
/// more about it than we knew beforehand.
#[derive(Clone, Debug, PartialEq)]
pub struct RankConfig {
    /// Standard deviation of one residual, in residual units (`≥ 0`).
    pub sigma: f64,
    /// Plausible deviation of a length parameter, in m (default 0.01).
    pub prior_m: f64,
    /// Plausible deviation of an angle parameter, in rad (default 0.01).
    pub prior_rad: f64,
    /// Plausible deviation of a dimensionless parameter (default 1.0).
    pub prior_dimensionless: f64,
    /// Plausible value of a compliance under a torque, in rad/(N·m) (default 2e-3): a
    /// compliance whose standard deviation given the data exceeds it is pruned, since the data
    /// then tell less about it than the physics of joints does.
    pub prior_rad_per_n_m: f64,
    /// Plausible value of a compliance under a lever arm of unknown weight, in rad/m
    /// (default 1e-2).
    pub prior_rad_per_m: f64,
    /// Numerical floor (default 1e-10): a scaled column whose distance to the span of the kept
    /// columns, `|R_kk|`, is below `rel_tol` (relative to the unit norm of the scaled columns,
    /// which is `|R_00|` of their pivoted QR) is always pruned; so is a column whose norm is
    /// below `rel_tol` times the largest candidate column norm.
    pub rel_tol: f64,
    /// Which of two tied candidates becomes the pivot (default: the earlier in the layout).
    pub tie_break: TieBreak,
}

impl RankConfig {
    /// Plausible deviation of a parameter of `unit`, in that unit.
    pub fn prior_scale(&self, unit: Unit) -> f64 {
        match unit {
            Unit::Meter => self.prior_m,
            Unit::Radian => self.prior_rad,
            Unit::Dimensionless => self.prior_dimensionless,
            Unit::RadianPerNewtonMeter => self.prior_rad_per_n_m,
            Unit::RadianPerMeter => self.prior_rad_per_m,
        }
    }
}

/// Why a parameter was pruned.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum PruneReason {
    /// Its Jacobian column is zero, or below `rel_tol` times the largest candidate column norm:
    /// the measurements do not depend on it.
    NearZeroColumn,
    /// Its column is (nearly) a combination of kept columns. Each entry `(name, coefficient)`
    /// says that a change `δ` of the pruned parameter is reproduced by a change
    /// `coefficient·δ` of kept parameter `name` (coefficient in that parameter's unit per unit
    /// of the pruned one). Kept parameters whose scaled least-squares coefficient exceeds 0.05 in
    /// magnitude are listed, largest first, at most 6 (when the column is dependent at working
    /// precision but no coefficient exceeds 0.05, the 6 largest are listed).
    Dependent {
        /// `(kept parameter name, coefficient)`, by decreasing scaled magnitude.
        on: Vec<(String, f64)>,
    },
    /// Its column is nearly orthogonal to the kept ones (no scaled coefficient above 0.05) but
    /// too small for the noise: its standard deviation would exceed its prior.
    Insensitive,
    /// Held at its physical bound (a compliance at zero) while the others were fitted
    /// ([`identify_held`](crate::identify_held)): a fit with it free put it beyond the bound,
    /// by less than the noise allows.
    AtBound,
}

impl fmt::Display for PruneReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NearZeroColumn => f.write_str("near-zero column"),
            Self::Insensitive => f.write_str("insensitive"),
            Self::AtBound => f.write_str("held at its bound"),
            Self::Dependent { on } => {
                f.write_str("dependent on")?;
                for (k, (name, coefficient)) in on.iter().enumerate() {
                    let sep = if k == 0 { " " } else { ", " };
                    write!(f, "{sep}{name} (×{coefficient:.4})")?;
                }
                Ok(())
            }
        }
    }
}

/// One pruned parameter and the reason, in words and in numbers.
#[derive(Clone, Debug, PartialEq)]
pub struct Pruned {
    /// Index in the layout.
    pub index: usize,
    /// Name in the layout.
    pub name: String,
    /// Why it was pruned.
    pub reason: PruneReason,
    /// Its standard deviation, in its unit, if it were added to the kept set:
    /// `sigma / (c_j·ρ_j)` with `ρ_j` the distance of its unit-norm column to the span of the
    /// kept columns (`∞` when `ρ_j = 0`). For [`PruneReason::NearZeroColumn`], `sigma / c_j`
    /// (a lower bound). Compare with the prior of its unit.
    pub std_if_kept: f64,
}

/// Result of [`identifiability`].
#[derive(Clone, Debug, PartialEq)]
pub struct Identifiability {
    /// Layout indices of the kept parameters, ascending (pass as `free` to the solver).
    pub kept: Vec<usize>,
    /// The pruned candidates, by ascending layout index.
    pub pruned: Vec<Pruned>,
    /// `|R_kk|` of the unit-norm scaled columns in [`Identifiability::pivot_order`]: for the
    /// first `kept.len()` entries the diagonal of the QR of the kept columns (nuisance first),
    /// for the pruned ones `ρ_j` as in [`Pruned::std_if_kept`] (0 for near-zero columns).
    pub r_diag: Vec<f64>,
    /// Layout indices: kept nuisance parameters in pivot order, kept model parameters in pivot
    /// order, then the pruned ones by decreasing `ρ_j`.
    pub pivot_order: Vec<usize>,
}

impl Identifiability {
    /// Names of the pruned parameters, by ascending layout index.
    pub fn pruned_names(&self) -> Vec<&str> {
        self.pruned.iter().map(|p| p.name.as_str()).collect()
    }
    /// The pruned entry for parameter `name`, if it was pruned.
    pub fn find_pruned(&self, name: &str) -> Option<&Pruned> {
        self.pruned.iter().find(|p| p.name == name)
    }
}

/// Relative width of a near-tie between pivot candidates (see [`identifiability`]).
const TIE_REL: f64 = 1e-6;
/// Absolute width of a near-tie, on unit-norm columns: rounding after many reflections.
const TIE_ABS: f64 = 1e-13;
/// Relative width of a noise-level tie: candidates interchangeable at the noise level tie only
/// when their distances `ρ` to the kept span also agree this closely. Exactly collinear
/// parameters perturbed by small deviations differ by the deviations' relative size
/// (~1e-3 for Baser & Konukseven's d0 and θ1 at millimetre/milliradian deviations); a wider
/// tie lets a weaker column displace a strong one and leaves a near-collinear pair behind.
const TIE_NOISE_REL: f64 = 1e-2;

/// Decides which of the `candidates` the Jacobian `jac` determines, given the noise level.
///
/// `jac` is `m × n` (row = residual, column = `layout` entry), evaluated at the estimate; only the
/// `candidates` columns are considered. A column whose norm `c_j` is zero or below
/// `rel_tol·max c` is pruned as [`PruneReason::NearZeroColumn`]; the others are scaled to unit
/// norm, so the decision does not depend on units, and factorised by a column-pivoted
/// Householder QR (Golub–Van Loan Alg. 5.4.1) with these pivot rules:
///
/// 1. **Nuisance first.** The nuisance candidates (`Role::Nuisance`) are pivoted first; one is
///    pruned only when numerically dependent on the nuisance columns before it
///    (`|R_kk| < rel_tol`, relative to the unit norm of the scaled columns, which is `|R_00|`).
///    The model columns receive the same reflections, i.e. they are projected on the
///    orthogonal complement of the kept nuisance columns.
/// 2. **Model candidates** are then pivoted. A model parameter is eligible at step `k` when its
///    distance to the span of the columns kept so far, `ρ_j = |R_kk|` if chosen, satisfies
///    `ρ_j ≥ rel_tol` and `sigma / (c_j·ρ_j) ≤ prior_scale(unit)` (its standard deviation given
///    the parameters before it is below its plausible deviation). The pivot is the eligible
///    column of largest `ρ_j`; a column that fails a test is pruned at once, since `ρ_j` only
///    decreases as columns are kept. Pivoting stops when no column is eligible.
/// 3. **Near-ties** go to the candidate earlier in the layout (or later, with
///    [`TieBreak::LaterInLayout`]), so exact duplicates are resolved the same way at every
///    estimate. Two candidates tie when their `ρ` agree within 1e-6 relative, or when they are
///    interchangeable at this noise level: whichever of the two is kept, the other's component
///    orthogonal to it fails the uncertainty test. (Baser & Konukseven's `d0` and `θ1` are
///    exactly collinear at the nominal model and nearly so at the estimate; the small
///    deviations must not decide which name is kept.)
/// 4. **Reasons.** For each pruned column the same factorisation gives its least-squares
///    coefficients on the kept columns, `R11·z = R12[:, j]` (unscaled to parameter units by
///    `c_j / c_i`), and its distance `ρ_j` to their span.
///
/// The `m × q` scaled columns are first reduced to their `q × q` R factor (faer's blocked
/// Householder QR, no pivoting), which has the same Gram matrix, so the pivoting costs `O(q³)`.
///
/// # Panics
/// If `jac.ncols() != layout.len()`, a candidate is out of range or repeated, `jac` has a
/// non-finite entry in a candidate column, `sigma` or `rel_tol` is negative or not finite,
/// or a prior is not positive and finite (misuse: [`identify`](crate::identify) validates its
/// configuration and Jacobian).
#[track_caller]
pub fn identifiability(
    jac: MatRef<'_, f64>,
    layout: &ParamLayout,
    candidates: &[usize],
    cfg: &RankConfig,
) -> Identifiability {
    let n = layout.len();
    assert!(
        jac.ncols() == n,
        "jacobian has {} columns, layout has {n}",
        jac.ncols()
    );
    let mut seen = vec![false; n];
    for &j in candidates {
        assert!(j < n, "candidate {j} is out of range for {n} parameters");
        assert!(!seen[j], "candidate {j} is repeated");
        seen[j] = true;
    }
    assert!(
        cfg.sigma.is_finite() && cfg.sigma >= 0.0,
        "sigma must be finite and >= 0"
    );
    assert!(
        cfg.rel_tol.is_finite() && cfg.rel_tol >= 0.0,
        "rel_tol must be finite and >= 0"
    );
    for prior in [
        cfg.prior_m,
        cfg.prior_rad,
        cfg.prior_dimensionless,
        cfg.prior_rad_per_n_m,
        cfg.prior_rad_per_m,
    ] {
        assert!(
            prior.is_finite() && prior > 0.0,
            "priors must be finite and > 0"
        );
    }
    for &j in candidates {
        assert!(
            jac.col(j).is_all_finite(),
            "jacobian column {j} is not finite"
        );
    }

    let m = jac.nrows();
    let mut sorted = candidates.to_vec();
    sorted.sort_unstable();
    let norm: Vec<f64> = (0..n)
        .map(|j| if seen[j] { jac.col(j).norm_l2() } else { 0.0 })
        .collect();
    let max_norm = norm.iter().copied().fold(0.0_f64, f64::max);
    let (zero_cols, cols): (Vec<usize>, Vec<usize>) = sorted
        .iter()
        .partition(|&&j| norm[j] == 0.0 || norm[j] < cfg.rel_tol * max_norm);

    // W: the R factor of the unit-norm columns (same Gram matrix), one Vec per column.
    let mut w: Vec<Vec<f64>> = if cols.is_empty() {
        Vec::new()
    } else {
        let scaled = Mat::from_fn(m, cols.len(), |i, k| jac[(i, cols[k])] / norm[cols[k]]);
        let r = scaled.qr().R().to_owned();
        (0..cols.len())
            .map(|k| (0..r.nrows()).map(|i| r[(i, k)]).collect())
            .collect()
    };
    let rows = w.first().map_or(0, Vec::len);
    let c: Vec<f64> = cols.iter().map(|&j| norm[j]).collect();
    let prior: Vec<f64> = cols
        .iter()
        .map(|&j| cfg.prior_scale(layout.spec(j).unit))
        .collect();
    let is_nuisance: Vec<bool> = cols
        .iter()
        .map(|&j| layout.spec(j).role == Role::Nuisance)
        .collect();

    let mut kept_pos: Vec<usize> = Vec::new();
    let mut open = vec![true; cols.len()];
    for nuisance_phase in [true, false] {
        loop {
            let k = kept_pos.len();
            let mut eligible: Vec<(usize, f64)> = Vec::new();
            for pos in 0..cols.len() {
                if !open[pos] || is_nuisance[pos] != nuisance_phase {
                    continue;
                }
                let rho = if k < rows { norm_l2(&w[pos][k..]) } else { 0.0 };
                let numerically_dependent = rho == 0.0 || rho < cfg.rel_tol;
                let too_uncertain = !nuisance_phase && cfg.sigma / (c[pos] * rho) > prior[pos];
                if numerically_dependent || too_uncertain {
                    open[pos] = false;
                } else {
                    eligible.push((pos, rho));
                }
            }
            let rho_max = eligible.iter().map(|e| e.1).fold(0.0_f64, f64::max);
            // The greedy pivot: the largest ρ (first in layout order among exact maxima).
            let greedy = eligible.iter().find(|e| e.1 == rho_max).map(|e| e.0);
            // A candidate ties with it when ρ is within rounding of the maximum, or (model phase)
            // when the two are interchangeable at this noise level: whichever is kept, the
            // other's remaining component fails the uncertainty test.
            let ties = |e: &&(usize, f64)| {
                e.1 >= rho_max * (1.0 - TIE_REL) - TIE_ABS
                    || (!nuisance_phase
                        && e.1 >= rho_max * (1.0 - TIE_NOISE_REL)
                        && greedy.is_some_and(|g| {
                            interchangeable(&w[g][k..], &w[e.0][k..], |perp_g, perp_e| {
                                cfg.sigma / (c[g] * perp_g) > prior[g]
                                    && cfg.sigma / (c[e.0] * perp_e) > prior[e.0]
                            })
                        }))
            };
            // Eligible entries are in layout order: the first (or last) tied one wins.
            let chosen = match cfg.tie_break {
                TieBreak::EarlierInLayout => eligible.iter().find(ties),
                TieBreak::LaterInLayout => eligible.iter().rev().find(ties),
            };
            let Some(&(pivot, _)) = chosen else {
                break;
            };
            open[pivot] = false;
            reflect(&mut w, k, pivot, |pos| {
                pos != pivot && !kept_pos.contains(&pos)
            });
            kept_pos.push(pivot);
        }
    }

    explain(&w, layout, cfg, &cols, &c, &kept_pos, &zero_cols, &norm)
}

/// Whether two remaining columns `a`, `b` (same length) are interchangeable: `fails(ρ_a⊥b,
/// ρ_b⊥a)` with `ρ_a⊥b` the norm of `a`'s component orthogonal to `b` (and conversely).
fn interchangeable(a: &[f64], b: &[f64], fails: impl Fn(f64, f64) -> bool) -> bool {
    let (na, nb) = (norm_l2(a), norm_l2(b));
    if na == 0.0 || nb == 0.0 {
        return false;
    }
    // Components orthogonal to the other column, by projection (not √(1 − cos²), which loses
    // half the digits for nearly parallel columns).
    let ab = dot(a, b);
    let perp = |u: &[f64], v: &[f64], nv: f64| {
        let t = ab / (nv * nv);
        let r: Vec<f64> = u.iter().zip(v).map(|(x, y)| x - t * y).collect();
        norm_l2(&r)
    };
    fails(perp(a, b, nb), perp(b, a, na))
}

/// `‖x‖₂`: the plain sum of squares where it neither overflows nor underflows (the columns
/// of the decision are scaled to unit norm, so it almost always does neither), else scaled
/// like LAPACK's dnrm2.
fn norm_l2(x: &[f64]) -> f64 {
    let sum = dot(x, x);
    // Below 2⁻⁹⁰⁰ squares of small entries may have lost digits to underflow.
    if sum.is_finite() && sum > f64::from_bits(0x07b0_0000_0000_0000) {
        return sum.sqrt();
    }
    let scale = x.iter().fold(0.0_f64, |a, &v| a.max(v.abs()));
    if scale == 0.0 {
        return 0.0;
    }
    scale * x.iter().map(|&v| (v / scale).powi(2)).sum::<f64>().sqrt()
}

/// `xᵀy` over the common length, in four partial sums (which the compiler vectorises; one
/// running sum it may not reorder).
fn dot(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &y[..n]);
    let mut acc = [0.0_f64; 4];
    let (xc, yc) = (x.chunks_exact(4), y.chunks_exact(4));
    let (xr, yr) = (xc.remainder(), yc.remainder());
    for (a, b) in xc.zip(yc) {
        for l in 0..4 {
            acc[l] += a[l] * b[l];
        }
    }
    let tail: f64 = xr.iter().zip(yr).map(|(a, b)| a * b).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Householder step `k` on column `pivot` (rows `k..`), applied to the columns `apply_to`
/// selects; afterwards `w[pivot]` holds `R[..=k, k]` with zeros below.
fn reflect(w: &mut [Vec<f64>], k: usize, pivot: usize, apply_to: impl Fn(usize) -> bool) {
    let x = &w[pivot][k..];
    let x_norm = norm_l2(x);
    let alpha = if x[0] > 0.0 { -x_norm } else { x_norm };
    let mut v = x.to_vec();
    v[0] -= alpha;
    let vtv = dot(&v, &v);
    for (pos, col) in w.iter_mut().enumerate() {
        if pos == pivot {
            col[k] = alpha;
            col[k + 1..].iter_mut().for_each(|a| *a = 0.0);
        } else if apply_to(pos) && vtv > 0.0 {
            let y = &mut col[k..];
            let f = 2.0 * dot(&v, y) / vtv;
            y.iter_mut().zip(&v).for_each(|(b, a)| *b -= f * a);
        }
    }
}

/// Builds the result from the factorised columns: kept set, reasons, `ρ_j`.
#[allow(clippy::too_many_arguments)] // private helper; the arguments are the factorisation state
fn explain(
    w: &[Vec<f64>],
    layout: &ParamLayout,
    cfg: &RankConfig,
    cols: &[usize],
    c: &[f64],
    kept_pos: &[usize],
    zero_cols: &[usize],
    norm: &[f64],
) -> Identifiability {
    let nk = kept_pos.len();
    let rows = w.first().map_or(0, Vec::len);
    let r11 = Mat::from_fn(nk, nk, |i, l| if i <= l { w[kept_pos[l]][i] } else { 0.0 });
    let mut r_diag: Vec<f64> = (0..nk).map(|k| r11[(k, k)].abs()).collect();
    let mut pivot_order: Vec<usize> = kept_pos.iter().map(|&pos| cols[pos]).collect();
    let dependent: Vec<usize> = (0..cols.len())
        .filter(|pos| !kept_pos.contains(pos))
        .collect();
    // z = R11⁻¹ R12, one column per dependent parameter.
    let mut z = Mat::from_fn(nk, dependent.len(), |i, t| w[dependent[t]][i]);
    r11.solve_upper_triangular_in_place(z.as_mut());

    let mut pruned = Vec::new();
    let mut by_rho = Vec::new();
    for (t, &pos) in dependent.iter().enumerate() {
        let j = cols[pos];
        let rho = if nk < rows {
            norm_l2(&w[pos][nk..])
        } else {
            0.0
        };
        let mut coefficients: Vec<(usize, f64)> = (0..nk).map(|i| (i, z[(i, t)])).collect();
        coefficients.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        // Listed: |z_i| > 0.05; for a column dependent at working precision, at least the
        // largest ones (a combination of many small contributions).
        let n_large = coefficients
            .iter()
            .take_while(|(_, zi)| zi.abs() > 0.05)
            .count();
        let n_listed = if n_large == 0 && rho < cfg.rel_tol {
            nk
        } else {
            n_large
        };
        let on: Vec<(String, f64)> = coefficients
            .iter()
            .take(n_listed.min(6))
            .map(|&(i, zi)| {
                (
                    layout.name(cols[kept_pos[i]]).to_owned(),
                    zi * c[pos] / c[kept_pos[i]],
                )
            })
            .collect();
        let reason = if on.is_empty() {
            PruneReason::Insensitive
        } else {
            PruneReason::Dependent { on }
        };
        let std_if_kept = if rho > 0.0 {
            cfg.sigma / (c[pos] * rho)
        } else {
            f64::INFINITY
        };
        pruned.push(Pruned {
            index: j,
            name: layout.name(j).to_owned(),
            reason,
            std_if_kept,
        });
        by_rho.push((j, rho));
    }
    for &j in zero_cols {
        let std_if_kept = if norm[j] > 0.0 {
            cfg.sigma / norm[j]
        } else {
            f64::INFINITY
        };
        pruned.push(Pruned {
            index: j,
            name: layout.name(j).to_owned(),
            reason: PruneReason::NearZeroColumn,
            std_if_kept,
        });
        by_rho.push((j, 0.0));
    }
    by_rho.sort_by(|a, b| b.1.total_cmp(&a.1));
    for (j, rho) in by_rho {
        pivot_order.push(j);
        r_diag.push(rho);
    }
    pruned.sort_by_key(|p| p.index);
    let mut kept: Vec<usize> = kept_pos.iter().map(|&pos| cols[pos]).collect();
    kept.sort_unstable();
    Identifiability {
        kept,
        pruned,
        r_diag,
        pivot_order,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::ParamSpec;

    fn layout(names: &[(&str, Role)]) -> ParamLayout {
        ParamLayout::new(
            names
                .iter()
                .map(|&(name, role)| ParamSpec {
                    name: name.to_owned(),
                    unit: Unit::Meter,
                    role,
                })
                .collect(),
        )
    }

    #[test]
    fn pivots_are_the_most_independent_remaining_columns() {
        // A generic 8 × 5 matrix; sigma = 0 keeps every column. All unit-norm columns tie at
        // step 0 (the first in the layout wins); after that each pivot must be the column
        // farthest from the span of the previous pivots, |R_kk| being that distance, checked
        // with faer's QR of [previous pivots | candidate].
        let jac = Mat::from_fn(8, 5, |i, j| {
            ((i * i * 7 + j * j * 13 + i * j) as f64 * 0.7).sin() * (j + 1) as f64
        });
        let names = ["a", "b", "c", "d", "e"].map(|n| (n, Role::Model));
        let cfg = RankConfigBase::default().with_sigma(0.0);
        let id = identifiability(jac.as_ref(), &layout(&names), &[0, 1, 2, 3, 4], &cfg);
        assert_eq!(id.kept, [0, 1, 2, 3, 4]);
        assert_eq!(id.pivot_order[0], 0);
        let scaled = Mat::from_fn(8, 5, |i, j| jac[(i, j)] / jac.col(j).norm_l2());
        let distance = |prefix: &[usize], j: usize| {
            let cols: Vec<usize> = prefix.iter().copied().chain([j]).collect();
            let sub = Mat::from_fn(8, cols.len(), |i, k| scaled[(i, cols[k])]);
            sub.qr().R()[(prefix.len(), prefix.len())].abs()
        };
        for k in 1..5 {
            let prefix = &id.pivot_order[..k];
            let chosen = distance(prefix, id.pivot_order[k]);
            assert!(
                (id.r_diag[k] - chosen).abs() < 1e-13,
                "k = {k}: {} vs {chosen}",
                id.r_diag[k]
            );
            for j in (0..5).filter(|j| !prefix.contains(j)) {
                assert!(
                    chosen >= distance(prefix, j) - 1e-13,
                    "k = {k}: {j} is farther"
                );
            }
        }
    }

    #[test]
    fn weak_independent_parameter_does_not_prune_later_pivots() {
        // Column 0 is orthogonal to the others but tiny (std 1 m at sigma 1e-3 > prior 0.01 m);
        // columns 1, 2 are correlated but strong. Scaled pivoting picks column 0 first.
        let jac = Mat::from_fn(3, 3, |i, j| match (i, j) {
            (0, 0) => 1e-3,
            (1, 1) | (1, 2) | (2, 1) => 1.0,
            (2, 2) => 0.5,
            _ => 0.0,
        });
        let l = layout(&[
            ("weak", Role::Model),
            ("a", Role::Model),
            ("b", Role::Model),
        ]);
        let cfg = RankConfigBase::default().with_sigma(1e-3);
        let id = identifiability(jac.as_ref(), &l, &[0, 1, 2], &cfg);
        assert_eq!(id.kept, [1, 2]);
        assert_eq!(id.pruned_names(), ["weak"]);
        assert_eq!(id.pruned[0].reason, PruneReason::Insensitive);
        assert!((id.pruned[0].std_if_kept - 1.0).abs() < 1e-12);
    }

    #[test]
    fn columns_interchangeable_at_the_noise_level_follow_the_tie_break() {
        // After the nuisance column c is projected out, d0 keeps ρ = 0.70711 and theta1
        // ρ = 0.70675: 5e-4 apart (far beyond the rounding tie), so the greedy pivot is d0. Their
        // remaining parts are 1e-3 rad apart, so whichever is kept, the other's std would be
        // ≈ 1e-4 / (1.41 · 7.1e-4) ≈ 0.1 m > the 0.01 m prior: interchangeable at sigma = 1e-4,
        // and the tie-break, not the greedy pivot, must decide.
        let cols = [
            [1.0, 0.0, 0.0, 0.0],
            [1.0, 1.0, 0.0, 0.0],
            [1.001, 1.0, 0.001, 0.0],
        ];
        let jac = Mat::from_fn(4, 3, |i, j| cols[j][i]);
        let l = layout(&[
            ("c", Role::Nuisance),
            ("d0", Role::Model),
            ("theta1", Role::Model),
        ]);
        let mut base = RankConfigBase::default();
        let earlier = identifiability(jac.as_ref(), &l, &[0, 1, 2], &base.with_sigma(1e-4));
        assert_eq!(earlier.pruned_names(), ["theta1"]);
        base.tie_break = TieBreak::LaterInLayout;
        let later = identifiability(jac.as_ref(), &l, &[0, 1, 2], &base.with_sigma(1e-4));
        assert_eq!(later.pruned_names(), ["d0"]);
        // Without noise they are distinguishable: both kept.
        let exact = identifiability(jac.as_ref(), &l, &[0, 1, 2], &base.with_sigma(0.0));
        assert!(exact.pruned.is_empty(), "{:?}", exact.pruned);
    }

    #[test]
    fn reason_display_lists_coefficients() {
        let reason = PruneReason::Dependent {
            on: vec![("da1".to_owned(), 2.0), ("dd1".to_owned(), -0.5)],
        };
        assert_eq!(
            reason.to_string(),
            "dependent on da1 (×2.0000), dd1 (×-0.5000)"
        );
        assert_eq!(PruneReason::NearZeroColumn.to_string(), "near-zero column");
    }
}
