//! Small test problems and helpers shared by the integration tests.

use faer::{ColMut, ColRef, Mat, MatMut};
use hapcal_identify::{EvalError, ParamLayout, ParamSpec, Problem, Role, Unit};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

pub(crate) fn spec(name: &str, unit: Unit, role: Role) -> ParamSpec {
    ParamSpec {
        name: name.to_owned(),
        unit,
        role,
    }
}

/// `n` model parameters in m, named `p0`, `p1`, ….
pub(crate) fn meters(n: usize) -> ParamLayout {
    ParamLayout::numbered("p", n, Unit::Meter)
}

pub(crate) fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

pub(crate) fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// `nrows × ncols` matrix of independent standard normal entries.
pub(crate) fn random_matrix(rng: &mut ChaCha8Rng, nrows: usize, ncols: usize) -> Mat<f64> {
    let mut a = Mat::zeros(nrows, ncols);
    for j in 0..ncols {
        for i in 0..nrows {
            a[(i, j)] = normal(rng);
        }
    }
    a
}

pub(crate) use hapcal_identify::LinearProblem as Linear;

/// `y_i = f(x, t_i)` for a model `f` of two parameters: `r_i = f(x, t_i) − y_i`.
pub(crate) struct Curve {
    pub(crate) layout: ParamLayout,
    pub(crate) t: Vec<f64>,
    pub(crate) y: Vec<f64>,
    /// `f(x, t)` and its gradient in `x`.
    pub(crate) model: fn([f64; 2], f64) -> (f64, [f64; 2]),
}

impl Problem for Curve {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        for (i, (&t, &y)) in self.t.iter().zip(&self.y).enumerate() {
            out[i] = (self.model)([x[0], x[1]], t).0 - y;
        }
        Ok(())
    }
    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        for (i, &t) in self.t.iter().enumerate() {
            [jac[(i, 0)], jac[(i, 1)]] = (self.model)([x[0], x[1]], t).1;
        }
        Ok(())
    }
}

/// `a·exp(b·t)` and its gradient in `(a, b)`.
pub(crate) fn exponential([a, b]: [f64; 2], t: f64) -> (f64, [f64; 2]) {
    let e = (b * t).exp();
    (a * e, [e, a * t * e])
}

/// Asserts that the normalised errors `(x̂ − x*)/std` of each parameter `p{j}` (`errors[j]`, one
/// per trial, 500 trials) are standard normal: their sample standard deviation within 0.9–1.1
/// (±3/√(2·500) ≈ ±0.095 of 1, and room for a Student t's slightly wider spread) and their mean
/// within ±0.15 (±3/√500 ≈ ±0.13 of 0).
#[track_caller]
pub(crate) fn assert_standard_normal(errors: &[Vec<f64>]) {
    for (j, e) in errors.iter().enumerate() {
        let n = e.len() as f64;
        let mean = e.iter().sum::<f64>() / n;
        let sd = (e.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!(
            (0.9..=1.1).contains(&sd),
            "p{j}: std of normalised errors {sd}"
        );
        assert!(mean.abs() < 0.15, "p{j}: mean of normalised errors {mean}");
    }
}
