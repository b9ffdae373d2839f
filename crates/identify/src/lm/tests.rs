use faer::{ColMut, ColRef, MatMut, col};

use super::*;
use crate::problem::{EvalError, ParamSpec, Role, Unit};

fn layout(names: &[&str]) -> ParamLayout {
    ParamLayout::new(
        names
            .iter()
            .map(|&name| ParamSpec {
                name: name.to_owned(),
                unit: Unit::Dimensionless,
                role: Role::Model,
            })
            .collect(),
    )
}

/// Rosenbrock as least squares: r = [10(x2 − x1²), 1 − x1], minimum 0 at (1, 1)
/// (Moré, Garbow, Hillstrom, "Testing unconstrained optimization software", 1981, problem 1);
/// the sparse back end's tests give it a sparse Jacobian too.
pub(crate) struct Rosenbrock(ParamLayout);

impl Problem for Rosenbrock {
    fn layout(&self) -> &ParamLayout {
        &self.0
    }
    fn n_residuals(&self) -> usize {
        2
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        out[0] = 10.0 * (x[1] - x[0] * x[0]);
        out[1] = 1.0 - x[0];
        Ok(())
    }
    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        jac[(0, 0)] = -20.0 * x[0];
        jac[(0, 1)] = 10.0;
        jac[(1, 0)] = -1.0;
        jac[(1, 1)] = 0.0;
        Ok(())
    }
    fn sparse_jacobian(&self) -> Option<&dyn crate::SparseJacobian> {
        Some(self)
    }
}

pub(crate) fn rosenbrock() -> Rosenbrock {
    Rosenbrock(layout(&["x1", "x2"]))
}

#[test]
fn rosenbrock_reaches_the_minimum_from_the_standard_start() {
    let fit = levenberg_marquardt(
        &rosenbrock(),
        col![-1.2, 1.0],
        &[0, 1],
        &LmConfig::default(),
    )
    .expect("valid input");
    assert!(fit.termination.is_success(), "{:?}", fit.termination);
    assert!(
        (fit.x[0] - 1.0).abs() < 1e-10 && (fit.x[1] - 1.0).abs() < 1e-10,
        "{:?}",
        fit.x
    );
    assert!(fit.cost < 1e-20);
    assert!(fit.n_evaluations <= 200 && fit.n_jacobians >= 2);
}

#[test]
fn fixed_parameter_keeps_its_initial_value() {
    // Only x1 is free with x2 = 0.25: the minimum of 100(0.25 − x1²)² + (1 − x1)² is near 0.5.
    let fit = levenberg_marquardt(&rosenbrock(), col![-1.2, 0.25], &[0], &LmConfig::default())
        .expect("valid input");
    assert!(fit.termination.is_success(), "{:?}", fit.termination);
    assert_eq!(fit.x[1], 0.25);
    // Stationary in x1: d/dx1 ½‖r‖² = −200·x1·(0.25 − x1²) − (1 − x1) = 0. The residual is not
    // zero (cost ≈ 1.1), so the cost comparison limits x1 to ≈ √(ε·cost/J²) ≈ 1e-9, i.e. the
    // gradient to ≈ J²·1e-9 ≈ 1e-7.
    let g = -200.0 * fit.x[0] * (0.25 - fit.x[0] * fit.x[0]) - (1.0 - fit.x[0]);
    assert!(g.abs() < 1e-6, "gradient {g} at {:?}", fit.x);
}

#[test]
fn evaluation_budget_is_reported_as_a_termination() {
    let cfg = LmConfig {
        max_evaluations: 3,
        ..LmConfig::default()
    };
    let fit =
        levenberg_marquardt(&rosenbrock(), col![-1.2, 1.0], &[0, 1], &cfg).expect("valid input");
    assert_eq!(fit.termination, Termination::MaxEvaluations);
    assert!(!fit.termination.is_success());
    assert_eq!(fit.n_evaluations, 3);
}

/// A straight line through three points that it misses: `r = [x1 + x2·t − y]` at
/// `t = 0, 1, 2`, `y = 0, 2, 1`, least-squares solution (1/2, 1/2), residuals not zero.
struct Line(ParamLayout);

impl Problem for Line {
    fn layout(&self) -> &ParamLayout {
        &self.0
    }
    fn n_residuals(&self) -> usize {
        3
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        for (i, y) in [0.0, 2.0, 1.0].into_iter().enumerate() {
            out[i] = x[0] + x[1] * i as f64 - y;
        }
        Ok(())
    }
    fn jacobian(&self, _: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        for i in 0..3 {
            jac[(i, 0)] = 1.0;
            jac[(i, 1)] = i as f64;
        }
        Ok(())
    }
}

#[test]
fn one_step_on_a_linear_problem_is_its_solution_without_a_second_jacobian() {
    let cfg = LmConfig {
        one_step: Some(1e-9),
        ..LmConfig::default()
    };
    let p = Line(layout(&["x1", "x2"]));
    let fit = levenberg_marquardt(&p, col![3.0, -1.0], &[0, 1], &cfg).expect("valid input");
    assert_eq!(fit.termination, Termination::OneStep);
    assert!(fit.termination.is_success());
    // The start's evaluation and the step's residuals, no Jacobian at the step.
    assert_eq!((fit.n_evaluations, fit.n_jacobians), (2, 1));
    // The linear model is exact: the step lands on the normal equations' solution, to the
    // rounding of a 2 × 2 QR (unit-sized entries).
    assert!(
        (fit.x[0] - 0.5).abs() < 1e-12 && (fit.x[1] - 0.5).abs() < 1e-12,
        "{:?}",
        fit.x
    );
}

#[test]
fn one_step_is_taken_only_where_the_linearisation_held() {
    // Rosenbrock from (0.9, 0.8): r = [−0.1, 0.1], J = [[−18, 10], [−1, 0]]. The Gauss–Newton
    // step p = −J⁻¹r = (0.1, 0.19) predicts a zero residual (relative reduction 1); at
    // (1, 0.99) the residual is [−0.1, 0], half the cost (actual reduction 0.5): accepted,
    // and a miss of 0.5.
    let p = rosenbrock();
    let x0 = col![0.9, 0.8];
    let plain = levenberg_marquardt(&p, x0.clone(), &[0, 1], &LmConfig::default()).unwrap();
    // A tolerance below the miss: the iteration goes on, with MINPACK's iterates.
    let strict = LmConfig {
        one_step: Some(0.4),
        ..LmConfig::default()
    };
    let fit = levenberg_marquardt(&p, x0.clone(), &[0, 1], &strict).unwrap();
    assert_eq!(fit.x, plain.x);
    assert_eq!(fit.termination, plain.termination);
    assert_ne!(fit.termination, Termination::OneStep);
    // A tolerance above it: the one Gauss–Newton step.
    let loose = LmConfig {
        one_step: Some(0.6),
        ..LmConfig::default()
    };
    let fit = levenberg_marquardt(&p, x0, &[0, 1], &loose).unwrap();
    assert_eq!(fit.termination, Termination::OneStep);
    assert_eq!(fit.n_evaluations, 2);
    assert!(
        (fit.x[0] - 1.0).abs() < 1e-12 && (fit.x[1] - 0.99).abs() < 1e-12,
        "{:?}",
        fit.x
    );
}

#[test]
fn empty_free_set_returns_x0() {
    let fit = levenberg_marquardt(&rosenbrock(), col![-1.2, 1.0], &[], &LmConfig::default())
        .expect("valid input");
    assert_eq!(fit.x, col![-1.2, 1.0]);
    assert_eq!(fit.termination, Termination::GtolReached);
    assert!((fit.cost - 0.5 * (4.4_f64.powi(2) + 2.2_f64.powi(2))).abs() < 1e-9);
}

#[test]
fn unusable_input_is_an_error_with_a_message() {
    let p = rosenbrock();
    let cfg = LmConfig::default();
    let err = levenberg_marquardt(&p, col![1.0], &[0], &cfg).expect_err("wrong length");
    assert_eq!(
        err.to_string(),
        "x0 has 1 entries but the layout has 2 parameters"
    );
    let err = levenberg_marquardt(&p, col![1.0, 1.0], &[0, 2], &cfg).expect_err("out of range");
    assert_eq!(
        err,
        Error::FreeOutOfRange {
            index: 2,
            n_params: 2
        }
    );
    let err = levenberg_marquardt(&p, col![1.0, 1.0], &[1, 1], &cfg).expect_err("repeated");
    assert_eq!(
        err.to_string(),
        "parameter \"x2\" appears twice in the free set"
    );
    let err = levenberg_marquardt(&p, col![f64::NAN, 1.0], &[0], &cfg).expect_err("NaN");
    assert_eq!(err.to_string(), "residual 0 is not finite at x0");
    let bad = LmConfig {
        ftol: -1.0,
        ..LmConfig::default()
    };
    let err = levenberg_marquardt(&p, col![1.0, 1.0], &[0], &bad).expect_err("negative ftol");
    assert_eq!(
        err.to_string(),
        "ftol = -1 is invalid: it must be finite and non-negative"
    );
}

/// One residual, three parameters: always too few residuals for three free parameters.
struct Failing(ParamLayout);

impl Problem for Failing {
    fn layout(&self) -> &ParamLayout {
        &self.0
    }
    fn n_residuals(&self) -> usize {
        1
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        if x[0] < 0.0 {
            return Err(EvalError {
                reason: "x0 below zero".to_owned(),
            });
        }
        out[0] = x[0];
        Ok(())
    }
    fn jacobian(&self, _x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        jac.fill(1.0);
        Ok(())
    }
}

#[test]
fn evaluation_failure_and_too_few_residuals_are_errors() {
    let p = Failing(layout(&["a", "b", "c"]));
    let cfg = LmConfig::default();
    let err = levenberg_marquardt(&p, col![1.0, 0.0, 0.0], &[0, 1, 2], &cfg).expect_err("m < n");
    assert_eq!(
        err,
        Error::TooFewResiduals {
            n_residuals: 1,
            n_free: 3
        }
    );
    assert_eq!(
        err.to_string(),
        "1 residuals cannot determine 3 free parameters"
    );
    let err = levenberg_marquardt(&p, col![-1.0, 0.0, 0.0], &[0], &cfg).expect_err("eval");
    assert_eq!(err.to_string(), "at the initial guess x0");
    assert_eq!(
        std::error::Error::source(&err)
            .map(ToString::to_string)
            .as_deref(),
        Some("evaluation failed: x0 below zero")
    );
}

#[test]
fn trial_points_that_fail_to_evaluate_are_rejected() {
    // r = x, undefined below 0.5: the minimum over the domain is on its edge. Steps that leave
    // the domain must be rejected (larger damping), not abort the fit.
    struct Edge(ParamLayout);
    impl Problem for Edge {
        fn layout(&self) -> &ParamLayout {
            &self.0
        }
        fn n_residuals(&self) -> usize {
            1
        }
        fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
            if x[0] < 0.5 {
                return Err(EvalError {
                    reason: "outside the domain".to_owned(),
                });
            }
            out[0] = x[0];
            Ok(())
        }
        fn jacobian(&self, _x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
            jac[(0, 0)] = 1.0;
            Ok(())
        }
    }
    let fit = levenberg_marquardt(&Edge(layout(&["a"])), col![2.0], &[0], &LmConfig::default())
        .expect("valid input");
    assert!(
        fit.x[0] >= 0.5 && fit.x[0] < 0.5 + 1e-6,
        "{:?} {:?}",
        fit.x,
        fit.termination
    );
    assert!(fit.termination.is_success(), "{:?}", fit.termination);
}

/// The damped step (Householder QR of `[R; √λ·I]`) solves the damped normal equations
/// `(RᵀR + λI) u = −Rᵀ·qtr` and
/// its `S` factors `RᵀR + λI`, for a well-conditioned `R` (entries O(1), diagonal ≥ 1): both
/// hold to a few hundred ulps of the O(10) entries, so 1e-12 absolute can only fail on a
/// wrong rotation or back substitution.
#[test]
fn damped_step_solves_the_damped_normal_equations() {
    let n = 6;
    let r = Mat::from_fn(n, n, |i, j| {
        if i == j {
            1.0 + i as f64
        } else if i < j {
            ((i * 7 + j * 3) % 5) as f64 / 5.0 - 0.4
        } else {
            0.0
        }
    });
    let qtr: Vec<f64> = (0..n).map(|i| (i as f64 - 2.5) / 3.0).collect();
    let upper = Upper {
        data: (0..n * n).map(|t| r[(t % n, t / n)]).collect(),
        n,
    };
    for lambda in [0.0, 1e-3, 0.7, 50.0] {
        let (u, s) = damped_step(&upper, &qtr, lambda);
        let s = Mat::from_fn(n, n, |i, j| s.at(i, j));
        let gram = r.transpose() * &r;
        let sts = s.transpose() * &s;
        for i in 0..n {
            for j in 0..n {
                let expected = gram[(i, j)] + if i == j { lambda } else { 0.0 };
                assert!(
                    (sts[(i, j)] - expected).abs() < 1e-12,
                    "λ = {lambda}: SᵀS[{i},{j}]"
                );
            }
            assert!(
                s.col(i).subrows(i + 1, n - i - 1).norm_l2() == 0.0,
                "S is upper triangular"
            );
            let lhs: f64 = (0..n).map(|j| gram[(i, j)] * u[j]).sum::<f64>() + lambda * u[i];
            let rhs: f64 = -(0..n).map(|k| r[(k, i)] * qtr[k]).sum::<f64>();
            assert!(
                (lhs - rhs).abs() < 1e-12,
                "λ = {lambda}: row {i}: {lhs} vs {rhs}"
            );
        }
    }
}

/// The triangle's products and solves invert each other: `T·(T⁻¹b) = b` (also for a leading
/// block) and `Tᵀ·(T⁻ᵀb) = b`, for a triangle with O(1) entries and diagonal ≥ 1, where rounding
/// stays within a few ulps of the O(1) results (1e-13 fails only on a wrong index or order).
#[test]
fn triangle_solves_invert_its_products() {
    let n = 7;
    let t = Upper {
        data: (0..n * n)
            .map(|k| {
                let (i, j) = (k % n, k / n);
                match i.cmp(&j) {
                    std::cmp::Ordering::Equal => 1.0 + 0.5 * i as f64,
                    std::cmp::Ordering::Less => ((i * 5 + j * 11) % 7) as f64 / 7.0 - 0.5,
                    std::cmp::Ordering::Greater => 0.0,
                }
            })
            .collect(),
        n,
    };
    let b: Vec<f64> = (0..n).map(|i| (i as f64 - 3.0) / 2.0).collect();
    let mut y = b.clone();
    t.solve_in_place(&mut y);
    for (got, want) in t.times(&y).iter().zip(&b) {
        assert!((got - want).abs() < 1e-13, "T·T⁻¹b: {got} vs {want}");
    }
    let mut y = b.clone();
    t.solve_transposed_in_place(&mut y);
    for (got, want) in t.transposed_times(&y).iter().zip(&b) {
        assert!((got - want).abs() < 1e-13, "Tᵀ·T⁻ᵀb: {got} vs {want}");
    }
    // The leading 4 × 4 block: row i of T·y with y zero beyond 4 is the block's product.
    let mut y = b[..4].to_vec();
    t.solve_in_place(&mut y);
    y.resize(n, 0.0);
    for (got, want) in t.times(&y).iter().zip(&b[..4]) {
        assert!((got - want).abs() < 1e-13, "block: {got} vs {want}");
    }
}

/// `R₊` (`(n+1) × (n+1)`, column-major) with O(1) entries, a diagonal ≥ 1, and the columns
/// `dependent` replaced by copies of column 0 (rank deficient when not empty).
fn triangle(n: usize, dependent: &[usize]) -> Mat<f64> {
    let mut t = Mat::from_fn(n + 1, n + 1, |i, j| match i.cmp(&j) {
        std::cmp::Ordering::Equal => 1.0 + 0.3 * i as f64,
        std::cmp::Ordering::Less => ((i * 7 + j * 5) % 9) as f64 / 9.0 - 0.45,
        std::cmp::Ordering::Greater => 0.0,
    });
    for &j in dependent {
        let c0 = t.col(0).to_owned();
        t.col_mut(j).copy_from(&c0);
    }
    t
}

/// A well-conditioned scaled triangle is used in its own column order, and its Gauss–Newton
/// step is the pivoted QR's (put back in column order) to rounding: the steps are O(1) and
/// the condition small, so 1e-12 fails only on a wrong scaling, permutation or right-hand
/// side.
#[test]
fn unpivoted_triangle_gives_the_pivoted_step() {
    let n = 9;
    let tri = triangle(n, &[]);
    // Later columns scaled up: the pivoted QR takes them first.
    let diag: Vec<f64> = (0..n).map(|j| 1.0 / (1.0 + 0.25 * j as f64)).collect();
    let fast = ScaledQr::from_triangle(tri.as_ref(), &diag);
    assert_eq!(fast.perm, (0..n).collect::<Vec<_>>(), "no pivoting");
    let scaled = Upper {
        data: (0..n * n)
            .map(|k| tri[(k % n, k / n)] / diag[k / n])
            .collect(),
        n,
    };
    let pivoted = ScaledQr::pivoted(&scaled, tri.col(n).subrows(0, n));
    assert_ne!(
        pivoted.perm, fast.perm,
        "the pivoted QR reorders this triangle"
    );
    let (u_fast, l_fast) = lmpar(&fast, f64::INFINITY, 0.0);
    let (u_piv, l_piv) = lmpar(&pivoted, f64::INFINITY, 0.0);
    assert_eq!((l_fast, l_piv), (0.0, 0.0), "Gauss–Newton steps");
    for (k, &pos) in pivoted.perm.iter().enumerate() {
        assert!(
            (u_piv[k] - u_fast[pos]).abs() < 1e-12,
            "column {pos}: {} vs {}",
            u_piv[k],
            u_fast[pos]
        );
    }
}

/// A rank-deficient triangle (two columns equal to the first) goes through the pivoted QR,
/// which finds two zero pivots and leaves their step components at 0.
#[test]
fn rank_deficient_triangle_is_pivoted() {
    let n = 9;
    let tri = triangle(n, &[3, 6]);
    let diag = vec![1.0; n];
    let qr = ScaledQr::from_triangle(tri.as_ref(), &diag);
    assert_eq!(qr.n_sing, n - 2, "numerical rank");
    let (u, _) = lmpar(&qr, f64::INFINITY, 0.0);
    assert!(u[n - 2..].iter().all(|&v| v == 0.0), "{u:?}");
}

#[test]
fn a_fit_from_given_residuals_and_jacobian_has_the_iterates_of_the_fit_that_evaluates_them() {
    let p = rosenbrock();
    let x0 = col![-1.2, 1.0];
    let (mut r0, mut jac0) = (Col::<f64>::zeros(2), Mat::<f64>::zeros(2, 2));
    p.residuals_and_jacobian(x0.as_ref(), r0.as_mut(), jac0.as_mut())
        .expect("evaluable");
    let cfg = LmConfig::default();
    let plain = levenberg_marquardt(&p, x0.clone(), &[0, 1], &cfg).expect("valid input");
    let given = levenberg_marquardt_from(&p, x0.clone(), &[0, 1], &cfg, r0.clone(), jac0.clone())
        .expect("valid input");
    assert_eq!(plain.x, given.x);
    assert_eq!(plain.n_iterations, given.n_iterations);
    assert_eq!(plain.n_evaluations, given.n_evaluations);
    assert_eq!(plain.termination, given.termination);
    // A start the caller got wrong is refused as the solver's own evaluation would be.
    r0[1] = f64::NAN;
    let err = levenberg_marquardt_from(&p, x0.clone(), &[0, 1], &cfg, r0, jac0.clone())
        .expect_err("a NaN residual");
    assert!(
        matches!(err, Error::NonFiniteResidual { index: 1 }),
        "{err:?}"
    );
    jac0[(0, 1)] = f64::INFINITY;
    let err = levenberg_marquardt_from(&p, x0, &[0, 1], &cfg, Col::zeros(2), jac0)
        .expect_err("an infinite Jacobian entry");
    assert!(
        matches!(&err, Error::NonFiniteJacobian { row: 0, name } if name == "x2"),
        "{err:?}"
    );
}
