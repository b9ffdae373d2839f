use faer::{Col, Mat};
use hapcal_identify::Problem;

use super::*;

const SIGMA: f64 = 2.0 * std::f64::consts::PI / 20000.0 / 3.0;

fn truth() -> CapstanParams {
    CapstanParams {
        c_rad: 2e-3,
        re: -0.025,
        r_o_m: 0.2e-3,
        beta_o_rad: (-105.0f64).to_radians(),
        r_i_m: 0.005e-3,
        beta_i_rad: (-15.0f64).to_radians(),
    }
}

fn grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo + (hi - lo) * (i as f64 + 0.5) / n as f64)
        .collect()
}

fn exact_problem(lo: f64, hi: f64) -> CapstanProblem {
    let cap = Capstan::try_new(10.0, 0.06).unwrap();
    let theta = grid(lo, hi, 150);
    let ext = theta
        .iter()
        .map(|&t| cap.output_rad(&truth(), JointRad(t)))
        .collect();
    CapstanProblem::new(cap, 1, theta, ext, SIGMA).unwrap()
}

#[test]
fn layout_names_units_and_order() {
    let p = exact_problem(-1.0, 1.0);
    let names: Vec<&str> = p.layout().specs().iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "capstan1.c",
            "capstan1.re",
            "capstan1.r_o",
            "capstan1.beta_o",
            "capstan1.r_i",
            "capstan1.beta_i"
        ]
    );
    let units: Vec<Unit> = p.layout().specs().iter().map(|s| s.unit).collect();
    use Unit::{Dimensionless, Meter, Radian};
    assert_eq!(units, [Radian, Dimensionless, Meter, Radian, Meter, Radian]);
    assert!(p.layout().specs().iter().all(|s| s.role == Role::Model));
    assert_eq!(p.n_residuals(), 150);
}

#[test]
fn residuals_vanish_at_the_truth_and_jacobian_is_the_scaled_gradient() {
    let p = exact_problem(-1.0, 1.0);
    let x = CapstanProblem::col(&truth());
    assert_eq!(CapstanProblem::params(x.as_ref()), truth());
    let mut r = Col::zeros(150);
    p.residuals(x.as_ref(), r.as_mut()).unwrap();
    assert!(r.norm_max() < 1e-9, "{}", r.norm_max());
    let mut jac = Mat::zeros(150, 6);
    p.jacobian(x.as_ref(), jac.as_mut()).unwrap();
    let cap = Capstan::try_new(10.0, 0.06).unwrap();
    let g = cap.error_grad(&truth(), JointRad(p.theta[7]));
    for j in 0..6 {
        assert_eq!(jac[(7, j)], g[j] / SIGMA);
    }
}

#[test]
fn residuals_refuse_an_eccentricity_beyond_the_drum_distance() {
    let p = exact_problem(-1.0, 1.0);
    let mut x = CapstanProblem::col(&truth());
    x[2] = 0.07;
    let mut r = Col::zeros(150);
    let err = p.residuals(x.as_ref(), r.as_mut()).unwrap_err();
    assert_eq!(
        err.reason,
        "r_o_m = 0.07 m is not below the drum distance 0.06 m"
    );
    let mut jac = Mat::zeros(150, 6);
    assert!(p.jacobian(x.as_ref(), jac.as_mut()).is_err());
}

#[test]
fn initial_guess_is_close_on_exact_data() {
    // Exact data, full turn: only the second-order terms of atan separate the linear model
    // from eq. 1, (r_o/D)²/2 ≈ 6e-6 rad.
    let p = exact_problem(-3.1, 3.1);
    let x0 = CapstanProblem::params(p.initial_guess().as_ref());
    let t = truth();
    assert!((x0.c_rad - t.c_rad).abs() < 2e-5, "{x0:?}");
    assert!((x0.re - t.re).abs() < 2e-4, "{x0:?}");
    assert!((x0.r_o_m - t.r_o_m).abs() < 2e-6, "{x0:?}");
    assert!((x0.beta_o_rad - t.beta_o_rad).abs() < 2e-2, "{x0:?}");
    assert!((x0.r_i_m - t.r_i_m).abs() < 5e-7, "{x0:?}");
    assert!((x0.beta_i_rad - t.beta_i_rad).abs() < 0.1, "{x0:?}");
}

#[test]
fn initial_guess_survives_degenerate_data() {
    // All readings equal: only the offset is determined; the rest must stay finite and valid.
    let cap = Capstan::try_new(10.0, 0.06).unwrap();
    let p = CapstanProblem::new(cap, 2, vec![0.3; 20], vec![0.301; 20], SIGMA).unwrap();
    let x0 = p.initial_guess();
    assert!(x0.iter().all(|v| v.is_finite()), "{x0:?}");
    let params = CapstanProblem::params(x0.as_ref());
    assert_eq!(cap.check_params(&params), Ok(()));
    let mut r = Col::zeros(20);
    p.residuals(x0.as_ref(), r.as_mut()).unwrap();
    // Within 1 % of the 1 mrad offset: the linearisation's second-order terms remain.
    assert!(r.norm_max() * SIGMA < 1e-5, "{}", r.norm_max());
}

#[test]
fn capstan_problem_validates_its_data() {
    let cap = Capstan::try_new(10.0, 0.06).unwrap();
    let new = |t: Vec<f64>, e: Vec<f64>, s: f64| CapstanProblem::new(cap, 1, t, e, s);
    assert_eq!(
        new(vec![0.0, 1.0], vec![0.0], SIGMA)
            .unwrap_err()
            .to_string(),
        "ext has 1 entries, expected 2"
    );
    assert_eq!(
        new(vec![], vec![], SIGMA).unwrap_err(),
        TransmissionError::Empty { name: "theta" }
    );
    assert_eq!(
        new(vec![0.0, 1.0], vec![0.0, f64::NAN], SIGMA)
            .unwrap_err()
            .to_string(),
        "ext[1] = NaN is not finite"
    );
    assert_eq!(
        new(vec![0.0], vec![0.0], 0.0).unwrap_err().to_string(),
        "sigma_rad must be positive, found 0"
    );
}

#[test]
fn polynomial_problem_layout_residuals_and_jacobian() {
    let theta = grid(0.3, 1.8, 40);
    let poly = Chebyshev::try_new(0.3, 1.8, vec![1e-3, -2e-3, 5e-4, 1e-4]).unwrap();
    let ext: Vec<f64> = theta.iter().map(|&t| t + poly.eval(t)).collect();
    let p = PolynomialProblem::new(4, 3, 0.3, 1.8, theta.clone(), ext, SIGMA).unwrap();
    let names: Vec<&str> = p.layout().specs().iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "joint4.cheb0",
            "joint4.cheb1",
            "joint4.cheb2",
            "joint4.cheb3"
        ]
    );
    let x = Col::from_fn(4, |k| poly.coeffs[k]);
    assert_eq!(p.polynomial(x.as_ref()), poly);
    let mut r = Col::zeros(40);
    p.residuals(x.as_ref(), r.as_mut()).unwrap();
    assert!(r.norm_max() < 1e-10);
    let mut jac = Mat::zeros(40, 4);
    p.jacobian(x.as_ref(), jac.as_mut()).unwrap();
    let b = poly.basis(theta[5]);
    for k in 0..4 {
        assert!((jac[(5, k)] - b[k] / SIGMA).abs() < 1e-9);
    }
    assert_eq!(p.initial_guess(), Col::<f64>::zeros(4));
}

#[test]
fn polynomial_problem_validates_its_domain_and_data() {
    let err = PolynomialProblem::new(4, 3, 1.8, 0.3, vec![1.0], vec![1.0], SIGMA).unwrap_err();
    assert_eq!(err, TransmissionError::Domain { lo: 1.8, hi: 0.3 });
    let err = PolynomialProblem::new(4, 3, 0.3, 1.8, vec![1.0], vec![], SIGMA).unwrap_err();
    assert_eq!(
        err,
        TransmissionError::LengthMismatch {
            name: "ext",
            expected: 1,
            found: 0
        }
    );
}
