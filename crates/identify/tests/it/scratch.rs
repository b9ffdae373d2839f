use faer::{Col, col};
use hapcal_identify::*;
use crate::problems::*;

#[test]
fn scratch() {
    let (a, b) = (2.5, -1.3);
    let t: Vec<f64> = (0..20).map(|i| 0.1 * i as f64).collect();
    let y = t.iter().map(|&t| a * (b * t).exp()).collect();
    let layout = ParamLayout::new(vec![spec("a", Unit::Dimensionless, Role::Model), spec("b", Unit::Dimensionless, Role::Model)]);
    let p = Exponential { layout, t, y };
    let fit = levenberg_marquardt(&p, col![1.0, 0.0], &[0, 1], &LmConfig::default()).unwrap();
    eprintln!("exp: {:?} {} {} {:e} {:e}", fit.termination, fit.n_evaluations, fit.n_jacobians, fit.x[0]-a, fit.x[1]-b);
    let mut rng = rng(1);
    let am = random_matrix(&mut rng, 50, 4);
    let y = Col::from_fn(50, |i| (i as f64 * 0.37).sin());
    let p = Linear { layout: meters(4), a: am, y };
    let fit = levenberg_marquardt(&p, Col::zeros(4), &[0, 1, 2, 3], &LmConfig::default()).unwrap();
    eprintln!("lin: {:?} {} {}", fit.termination, fit.n_evaluations, fit.n_jacobians);
    // exponential with noise, far start
    let t: Vec<f64> = (0..40).map(|i| 0.1 * i as f64).collect();
    let y = t.iter().enumerate().map(|(i, &t)| a * (b * t).exp() + 0.01*((i*7%5) as f64 - 2.0)).collect();
    let layout = ParamLayout::new(vec![spec("a", Unit::Dimensionless, Role::Model), spec("b", Unit::Dimensionless, Role::Model)]);
    let p = Exponential { layout, t, y };
    for x0 in [col![1.0, 0.0], col![10.0, 3.0], col![-5.0, -10.0], col![0.0, 0.0]] {
        let fit = levenberg_marquardt(&p, x0, &[0, 1], &LmConfig::default()).unwrap();
        eprintln!("expn: {:?} {} {} {:?} cost {:e}", fit.termination, fit.n_evaluations, fit.n_jacobians, fit.x, fit.cost);
    }
}
