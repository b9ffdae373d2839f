//! Levenberg–Marquardt on problems with known minima.

use faer::linalg::solvers::SolveLstsq;
use faer::{Col, Mat, col};
use hapcal_identify::{LmConfig, ParamLayout, Role, Unit, levenberg_marquardt};

use crate::problems::{Curve, Linear, exponential, meters, random_matrix, rng, spec};

#[test]
fn exponential_fit_on_exact_data_recovers_the_parameters() {
    let (a, b) = (2.5, -1.3);
    let t: Vec<f64> = (0..20).map(|i| 0.1 * i as f64).collect();
    let y = t.iter().map(|&t| a * (b * t).exp()).collect();
    let layout = ParamLayout::new(vec![
        spec("a", Unit::Dimensionless, Role::Model),
        spec("b", Unit::Dimensionless, Role::Model),
    ]);
    let p = Curve {
        layout,
        t,
        y,
        model: exponential,
    };
    let fit =
        levenberg_marquardt(&p, col![1.0, 0.0], &[0, 1], &LmConfig::default()).expect("valid");
    assert!(fit.termination.is_success(), "{:?}", fit.termination);
    assert!(
        (fit.x[0] - a).abs() < 1e-10 && (fit.x[1] - b).abs() < 1e-10,
        "{:?}",
        fit.x
    );
}

#[test]
fn linear_least_squares_equals_the_direct_qr_solution() {
    let mut rng = rng(1);
    let a = random_matrix(&mut rng, 50, 4);
    let y = Col::from_fn(50, |i| (i as f64 * 0.37).sin());
    let x_qr = a.qr().solve_lstsq(&y);
    let p = Linear {
        layout: meters(4),
        a,
        y,
    };
    let fit =
        levenberg_marquardt(&p, Col::zeros(4), &[0, 1, 2, 3], &LmConfig::default()).expect("valid");
    assert!(fit.termination.is_success(), "{:?}", fit.termination);
    for j in 0..4 {
        assert!(
            (fit.x[j] - x_qr[j]).abs() < 1e-12,
            "x{j}: {} vs {}",
            fit.x[j],
            x_qr[j]
        );
    }
}

#[test]
fn parameters_outside_the_free_set_are_untouched() {
    let mut rng = rng(2);
    let a = random_matrix(&mut rng, 30, 4);
    let y = Col::from_fn(30, |i| (i as f64 * 0.21).cos());
    let x0 = col![0.7, -0.3, 1.1, 0.25];
    let free = [0, 2];
    // Reference: least squares in the free columns after moving the fixed ones to the right side.
    let fixed_part = &a * col![0.0, x0[1], 0.0, x0[3]];
    let a_free = Mat::from_fn(30, 2, |i, k| a[(i, free[k])]);
    let x_ref = a_free.qr().solve_lstsq(&(&y - &fixed_part));
    let p = Linear {
        layout: meters(4),
        a,
        y,
    };
    let fit = levenberg_marquardt(&p, x0.clone(), &free, &LmConfig::default()).expect("valid");
    assert_eq!((fit.x[1], fit.x[3]), (x0[1], x0[3]));
    assert!((fit.x[0] - x_ref[0]).abs() < 1e-12 && (fit.x[2] - x_ref[1]).abs() < 1e-12);
}

#[test]
fn rank_deficient_jacobian_still_converges() {
    // Columns 2 and 3 are equal: the damping keeps the steps finite and the cost reaches the
    // least-squares minimum (that of the 3-column problem).
    let mut rng = rng(3);
    let base = random_matrix(&mut rng, 25, 3);
    let a = Mat::from_fn(25, 4, |i, j| base[(i, [0, 1, 2, 2][j])]);
    let y = Col::from_fn(25, |i| (i as f64 * 0.5).sin());
    let x_min = base.qr().solve_lstsq(&y);
    let cost_min = 0.5 * (&base * &x_min - &y).squared_norm_l2();
    let p = Linear {
        layout: meters(4),
        a,
        y,
    };
    let fit =
        levenberg_marquardt(&p, Col::zeros(4), &[0, 1, 2, 3], &LmConfig::default()).expect("valid");
    assert!(fit.termination.is_success(), "{:?}", fit.termination);
    assert!(
        (fit.cost - cost_min).abs() < 1e-12 * cost_min.max(1.0),
        "{} vs {cost_min}",
        fit.cost
    );
}
