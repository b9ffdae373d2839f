//! Small test problems and helpers shared by the integration tests.

use faer::{Col, ColMut, ColRef, Mat, MatMut};
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
    ParamLayout::new(
        (0..n)
            .map(|j| spec(&format!("p{j}"), Unit::Meter, Role::Model))
            .collect(),
    )
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

/// Linear least squares: `r(x) = A·x − y`, `J = A`.
pub(crate) struct Linear {
    pub(crate) layout: ParamLayout,
    pub(crate) a: Mat<f64>,
    pub(crate) y: Col<f64>,
}

impl Problem for Linear {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        self.a.nrows()
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        out.copy_from(&self.a * x - &self.y);
        Ok(())
    }
    fn jacobian(&self, _x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        jac.copy_from(&self.a);
        Ok(())
    }
}

/// `y_i = a·exp(b·t_i)`: `r_i = a·exp(b·t_i) − y_i`.
pub(crate) struct Exponential {
    pub(crate) layout: ParamLayout,
    pub(crate) t: Vec<f64>,
    pub(crate) y: Vec<f64>,
}

impl Problem for Exponential {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        for (i, (&t, &y)) in self.t.iter().zip(&self.y).enumerate() {
            out[i] = x[0] * (x[1] * t).exp() - y;
        }
        Ok(())
    }
    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        for (i, &t) in self.t.iter().enumerate() {
            let e = (x[1] * t).exp();
            jac[(i, 0)] = e;
            jac[(i, 1)] = x[0] * t * e;
        }
        Ok(())
    }
}

/// Sample standard deviation and mean.
pub(crate) fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}
